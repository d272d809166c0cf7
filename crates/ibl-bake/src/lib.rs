//! The one definition of a bake: the [`Bake`] trait that each bake library implements once and
//! that both front-ends read, the command-line tools (`ibl-cli` builds each binary's clap
//! command and its whole `main` from it) and the pipeline runner (`ibl-pipeline`'s table of
//! stage kinds is the same list of bakes).
//!
//! A bake says what it is called, its `Params` (the one struct deriving clap and serde), what it
//! reads, what it writes (known before running), how it validates its parameters, and `run`,
//! which returns the encoded files (not yet written), warnings, information lines and the
//! details a `--json` summary prints. Writing, stale files, progress and printing belong to the
//! front-ends.

#![warn(missing_docs)]

use ibl_core::error::{Classify, ErrorClass};
use ibl_core::progress::Progress;
use serde::{de::DeserializeOwned, Serialize};
use std::fmt;
use std::path::{Path, PathBuf};

pub use ibl_core::io::OutputKind;

/// What a `Params` struct must be to serve a bake: the CLI's clap struct, the RON keys via
/// serde, with clap's defaults as `Default` (`ibl_core::params::clap_defaults`).
pub trait BakeParams:
    clap::Args
    + clap::FromArgMatches
    + Serialize
    + DeserializeOwned
    + Default
    + Clone
    + fmt::Debug
    + Send
    + Sync
    + 'static
{
}
impl<T> BakeParams for T where
    T: clap::Args
        + clap::FromArgMatches
        + Serialize
        + DeserializeOwned
        + Default
        + Clone
        + fmt::Debug
        + Send
        + Sync
        + 'static
{
}

/// How many sources a bake reads as a pipeline stage, and what they are.
#[derive(Clone, Copy, Debug)]
pub struct Arity {
    /// The fewest sources.
    pub min: usize,
    /// The most sources (`usize::MAX`: any number).
    pub max: usize,
    /// What each source is, for messages ("an environment: equirect, cube folder or KTX2").
    pub what: &'static str,
}

impl Arity {
    /// A bake that reads nothing (a table computed from its parameters alone).
    pub const NONE: Arity = Arity {
        min: 0,
        max: 0,
        what: "nothing",
    };
    /// A bake that reads exactly one source.
    pub const fn one(what: &'static str) -> Arity {
        Arity {
            min: 1,
            max: 1,
            what,
        }
    }
    /// "reads exactly 1 (...)", for messages.
    pub fn describe(&self) -> String {
        match (self.min, self.max) {
            (0, 0) => "reads nothing".to_string(),
            (a, b) if a == b => format!("reads exactly {a} ({})", self.what),
            (a, usize::MAX) => format!("reads at least {a} ({})", self.what),
            (a, b) => format!("reads {a} to {b} ({})", self.what),
        }
    }
}

/// What a bake reads: as a pipeline stage, and on its command line.
#[derive(Clone, Copy, Debug)]
pub struct Reads {
    /// The sources of a stage.
    pub arity: Arity,
    /// The help of the command line's one positional input; `None` when the command line takes
    /// no positional input (tables, or maps named by flags of `Params`).
    pub cli_input: Option<&'static str>,
}

/// An environment input: an equirect image, a cross or strip, a folder of faces, a KTX2 cube.
pub const ENVIRONMENT: &str =
    "an environment: equirect, cross, face folder or KTX2, DDS or KTX1 cube";

/// The command-line help of an environment bake's input.
pub const ENVIRONMENT_HELP: &str =
    "Input environment: .exr/.hdr equirect or cross, a folder of faces, or a .ktx2, .dds or .ktx cube";

impl Reads {
    /// An environment bake: one environment, the command line's positional input.
    pub const ENVIRONMENT: Reads = Reads {
        arity: Arity::one(ENVIRONMENT),
        cli_input: Some(ENVIRONMENT_HELP),
    };
    /// A bake that reads nothing.
    pub const NOTHING: Reads = Reads {
        arity: Arity::NONE,
        cli_input: None,
    };
}

/// What a bake writes: the command line's `-o`.
#[derive(Clone, Copy, Debug)]
pub struct Writes {
    /// The help of `-o`.
    pub help: &'static str,
    /// The value's name in the usage line (`DIR`), or clap's default (`OUTPUT`).
    pub value_name: Option<&'static str>,
    /// The folder given a stage writes into it (`-o DIR`); otherwise the bake writes the file
    /// [`Bake::stage_out`] names in it.
    pub stage_folder: bool,
}

impl Writes {
    /// `-o DIR`: a folder, the stage's own.
    pub const fn folder(help: &'static str) -> Writes {
        Writes {
            help,
            value_name: None,
            stage_folder: true,
        }
    }
    /// `-o FILE`: a file in the stage's folder ([`Bake::stage_out`] names it).
    pub const fn file(help: &'static str) -> Writes {
        Writes {
            help,
            value_name: None,
            stage_folder: false,
        }
    }
}

/// A bake's failure as both front-ends keep it: its one-line message and exit-code class.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct BakeError {
    /// "outer: cause: root cause" on one line.
    pub message: String,
    /// Which exit code it maps to.
    pub class: ErrorClass,
}

impl BakeError {
    /// An invalid-input error of the bake's own (wrong number of inputs reaching `run`).
    pub fn input(kind: &str, why: impl Into<String>) -> BakeError {
        BakeError {
            message: format!("{kind}: {}", why.into()),
            class: ErrorClass::InvalidInput,
        }
    }
}

impl<E: Classify + 'static> From<E> for BakeError {
    fn from(e: E) -> Self {
        BakeError {
            message: ibl_core::error::chain(&e),
            class: e.class(),
        }
    }
}

impl fmt::Display for BakeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.message)
    }
}

/// What a run produced, before anything is written.
#[derive(Debug, Default)]
pub struct Baked {
    /// Encoded files, written by the front-end as one atomic set.
    pub files: Vec<(PathBuf, Vec<u8>)>,
    /// What the user must know (both front-ends report them).
    pub warnings: Vec<String>,
    /// Informational lines the command line prints (unless `--quiet` or `--json`).
    pub info: Vec<String>,
    /// Bake-specific details of the `--json` summary (error estimates, timings, ...).
    pub details: serde_json::Value,
}

/// One run of a bake within a stage: a stage that converts several sources (quat-map over a
/// folder of materials) is several runs, each what one command line does.
#[derive(Clone, Debug)]
pub struct Job<P> {
    /// The parameters of this run (a stage may set a few from its reads).
    pub params: P,
    /// The positional inputs of this run.
    pub inputs: Vec<PathBuf>,
    /// The `-o` of this run.
    pub out: PathBuf,
}

/// One bake, defined once: the command-line tool and the pipeline's stage kind both come from
/// it. A bake library implements it on a unit struct and exports a `static` of it.
pub trait Bake: Send + Sync + 'static {
    /// The one struct deriving clap and serde: CLI flags and RON keys.
    type Params: BakeParams;

    /// The name pipelines use (`kind: "prefilter"`), and a multi-bake binary's subcommand.
    const NAME: &'static str;
    /// One line for `bake kinds` and the command line's `-h`.
    const SUMMARY: &'static str;
    /// The command line's `--help`: what it computes, which conventions, what it writes.
    const ABOUT: &'static str;
    /// The CLI that runs the same bake: binary name, then subcommand if any.
    const COMMAND: &'static [&'static str];
    /// The library crate the bake lives in (the runner fingerprints its code into cache keys).
    const LIBRARY: &'static str;
    /// What it reads.
    const READS: Reads;
    /// What `-o` is.
    const WRITES: Writes;
    /// Whether a stage's [`Bake::jobs`] are independent items the runner may key and re-bake
    /// one by one (quat-map over a folder of materials: one changed normal map, one re-bake).
    const ITEMIZED: bool = false;

    /// [`Bake::NAME`].
    fn name(&self) -> &'static str {
        Self::NAME
    }
    /// The cargo package that builds the binary: the command's first word.
    fn package(&self) -> &'static str {
        Self::COMMAND[0]
    }
    /// Whether `-o out` names a file or a folder for these parameters (checked before any
    /// input is read).
    fn output_kind(&self, _p: &Self::Params, _out: &Path) -> OutputKind {
        if Self::WRITES.stage_folder {
            OutputKind::Folder
        } else {
            OutputKind::File
        }
    }
    /// The `-o` of a stage writing into `dir`.
    fn stage_out(&self, _p: &Self::Params, dir: &Path) -> PathBuf {
        dir.to_path_buf()
    }
    /// What a downstream stage reads of a run writing to `out` (the cube folder, the KTX2 file).
    fn product(&self, _p: &Self::Params, out: &Path) -> PathBuf {
        out.to_path_buf()
    }
    /// The files a run writes to `out`, known before running.
    fn outputs(
        &self,
        p: &Self::Params,
        inputs: &[PathBuf],
        out: &Path,
    ) -> Result<Vec<PathBuf>, BakeError>;
    /// The name of the cube whose files an earlier run may have left in `out` that this run
    /// does not write (another layout, a longer chain): the CLI removes them.
    fn stale_cube(&self, _p: &Self::Params) -> Option<&'static str> {
        None
    }
    /// Checks the parameters for a run writing to `out`, before any input is read.
    fn validate(&self, p: &Self::Params, out: &Path) -> Result<(), BakeError>;
    /// Checks a stage's parameters (before any stage runs); by default as for a run into `.`.
    fn validate_stage(&self, p: &Self::Params) -> Result<(), BakeError> {
        self.validate(p, &self.stage_out(p, Path::new(".")))
    }
    /// Runs the bake; nothing is written.
    fn run(
        &self,
        p: &Self::Params,
        inputs: &[PathBuf],
        out: &Path,
        progress: &dyn Progress,
    ) -> Result<Baked, BakeError>;
    /// Non-default parameters exercising every kind of field (tests round-trip them).
    fn example(&self) -> Self::Params;
    /// The runs of a stage reading `inputs` into `dir`: by default one run of them all.
    fn jobs(
        &self,
        p: &Self::Params,
        inputs: &[PathBuf],
        dir: &Path,
    ) -> Result<Vec<Job<Self::Params>>, BakeError> {
        Ok(vec![Job {
            params: p.clone(),
            inputs: inputs.to_vec(),
            out: self.stage_out(p, dir),
        }])
    }
    /// The runs of a stage as command lines name them: every path through `rel` (relative to a
    /// ninja file).
    fn cli_jobs(
        &self,
        p: &Self::Params,
        inputs: &[PathBuf],
        dir: &Path,
        rel: &dyn Fn(&Path) -> PathBuf,
    ) -> Result<Vec<Job<Self::Params>>, BakeError> {
        Ok(self
            .jobs(p, inputs, dir)?
            .into_iter()
            .map(|j| Job {
                inputs: j.inputs.iter().map(|i| rel(i)).collect(),
                out: rel(&j.out),
                params: j.params,
            })
            .collect())
    }
}

/// The one input of a bake that reads exactly one.
pub fn one_input<'a>(kind: &str, inputs: &'a [PathBuf]) -> Result<&'a Path, BakeError> {
    match inputs {
        [p] => Ok(p),
        _ => Err(BakeError::input(
            kind,
            format!("expected one input, got {}", inputs.len()),
        )),
    }
}

/// The environment of a bake that reads exactly one, opened under its `--sanitize` policy
/// (negative texels clamped, reported in the warnings): a large equirect whose format reads row
/// by row is left open as a stream (`ibl_core::envmap::open_environment_with`).
pub fn open_environment(
    kind: &str,
    inputs: &[PathBuf],
    sanitize: bool,
) -> Result<ibl_core::envmap::Opened, BakeError> {
    Ok(ibl_core::envmap::open_environment_with(
        one_input(kind, inputs)?,
        ibl_core::envmap::EnvPolicy {
            sanitize,
            negative: ibl_core::envmap::Negative::Clamp,
        },
    )?)
}

/// Where a cube (or chain) written into `out` is read from by the next stage (parameters are
/// validated before any product is asked for; an invalid encoding reads as the default).
pub fn cube_product<E>(
    out: &Path,
    enc: Result<ibl_core::output::Encoding, E>,
    name: &str,
) -> PathBuf {
    enc.unwrap_or_default()
        .layout
        .container_path(out, name)
        .unwrap_or_else(|| out.to_path_buf())
}

/// RON as pipelines are written: `size: 64` for an `Option` field, no `Some(...)` needed.
pub fn ron_options() -> ron::Options {
    ron::Options::default().with_default_extension(ron::extensions::Extensions::IMPLICIT_SOME)
}

/// A bake's example parameters from RON text as pipelines write it (a typo fails the kinds'
/// tests).
pub fn example<P: BakeParams>(ron_text: &str) -> P {
    ron_options()
        .from_str(ron_text)
        .unwrap_or_else(|e| panic!("example parameters {ron_text}: {e}"))
}

/// The `encoding` details of a `--json` summary: the sidecar's numbers and each level's
/// encode time.
pub fn encoding_details(levels: &[ibl_core::io::texture::LevelEncoding]) -> serde_json::Value {
    serde_json::json!({
        "levels": levels,
        "seconds": levels.iter().map(|l| l.seconds).collect::<Vec<f64>>(),
    })
}

/// The command line of `bake`, without the flags every binary shares (`ibl-cli` adds those):
/// named after its subcommand (or its binary), its help from [`Bake::about`], the positional
/// input [`Reads::cli_input`] names, `-o`, then the flattened `Params`.
pub fn command<B: Bake>(_bake: &B) -> clap::Command {
    use clap::{Arg, Args};
    let mut cmd = clap::Command::new(*B::COMMAND.last().expect("a command"));
    if let Some(help) = B::READS.cli_input {
        cmd = cmd.arg(
            Arg::new("input")
                .value_name("INPUT")
                .required(true)
                .value_parser(clap::value_parser!(PathBuf))
                .help(help),
        );
    }
    let writes = B::WRITES;
    let output = Arg::new("output")
        .short('o')
        .long("output")
        .required(true)
        .value_parser(clap::value_parser!(PathBuf))
        .value_name(writes.value_name.unwrap_or("OUTPUT"))
        .help(writes.help);
    with_about::<B>(B::Params::augment_args(cmd.arg(output)))
}

/// `cmd` with the help of bake `B`: its summary for `-h` and the list of subcommands, its about
/// for `--help`. Set last: a flattened struct's doc comment would otherwise replace it.
pub fn with_about<B: Bake>(cmd: clap::Command) -> clap::Command {
    // `bake kinds` lists summaries in lower case; a help text starts a sentence.
    let summary = B::SUMMARY;
    let mut chars = summary.chars();
    let first: String = chars
        .next()
        .into_iter()
        .flat_map(char::to_uppercase)
        .collect();
    cmd.about(first + chars.as_str()).long_about(B::ABOUT)
}
