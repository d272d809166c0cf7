//! The stage-kind registry: each kind is a small adapter from a kind name to a bake's `Params`
//! type (the very struct its CLI parses), what it reads, where it writes, and a call to the
//! bake library's pure `run`, whose encoded files the executor writes atomically.
//!
//! Adding a bake is one `static` [`Adapter`] in one of the submodules and one line in [`all`].

pub mod cli;
mod env;
#[cfg(feature = "lut")]
mod lut;
#[cfg(feature = "material")]
mod material;
#[cfg(feature = "prefilter")]
mod prefilter;
#[cfg(feature = "shexp")]
mod shexp;

use ibl_core::error::{Classify, ErrorClass};
use ibl_core::progress::Progress;
use serde::{de::DeserializeOwned, Serialize};
use std::any::Any;
use std::fmt;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Every stage kind this build of the runner knows, in the order `bake kinds` lists them.
pub fn all() -> Vec<&'static dyn Kind> {
    #[allow(unused_mut)] // without the optional bakes nothing is pushed
    let mut kinds: Vec<&'static dyn Kind> = vec![&env::EQUIRECT_TO_CUBE, &env::IRRADIANCE];
    #[cfg(feature = "prefilter")]
    kinds.push(&prefilter::PREFILTER);
    #[cfg(feature = "shexp")]
    kinds.push(&shexp::SHEXP_FIT);
    #[cfg(feature = "lut")]
    kinds.extend([
        &lut::DFG as &dyn Kind,
        &lut::FRESNEL_TAIL,
        &lut::HV_LUT,
        &lut::AS_SIZE_BIAS,
    ]);
    #[cfg(feature = "material")]
    kinds.extend([&material::QUAT_MAP as &dyn Kind, &material::TPR_MAP]);
    kinds
}

/// The kind called `name`.
pub fn find(name: &str) -> Option<&'static dyn Kind> {
    all().into_iter().find(|k| k.name() == name)
}

/// Names of all kinds, for error messages.
pub fn names() -> Vec<&'static str> {
    all().iter().map(|k| k.name()).collect()
}

/// What a `Params` struct must be to serve as a stage's parameters: the CLI's clap struct, the
/// RON keys via serde, with clap's defaults as `Default`.
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

/// A stage's parameters with their type erased (the kind that parsed them knows it).
pub type AnyParams = Arc<dyn ParamsObj>;

/// What the runner needs of parameters without knowing their type.
pub trait ParamsObj: Any + Send + Sync + fmt::Debug {
    /// The parameters as `Any`, for the kind that knows their type.
    fn as_any(&self) -> &dyn Any;
    /// Canonical form for cache keys: JSON with object keys sorted, every field present.
    fn canonical(&self) -> serde_json::Value;
    /// Command-line flags that make the CLI parse these parameters (non-defaults only).
    fn cli_args(&self) -> Result<Vec<String>, String>;
}

impl<P: BakeParams> ParamsObj for P {
    fn as_any(&self) -> &dyn Any {
        self
    }
    fn canonical(&self) -> serde_json::Value {
        // serde_json's map is a BTreeMap (no `preserve_order`), so keys come out sorted;
        // f32 values as the user wrote them (0.2, not 0.20000000298023224).
        let mut v = serde_json::to_value(self).expect("Params serialise to JSON");
        ibl_core::io::data::shortest_f32(&mut v);
        v
    }
    fn cli_args(&self) -> Result<Vec<String>, String> {
        cli::to_args(self)
    }
}

impl<P: BakeParams> Adapter<P> {
    fn in_ron_terms(&self, e: BakeError) -> BakeError {
        BakeError {
            message: ron_terms(&e.message, &self.param_names()),
            ..e
        }
    }
}

/// Rewrites a bake's message for a pipeline, whose user writes RON keys, not CLI flags:
/// "pass --y-down" becomes "set y_down: true", "drop --y-down" "set y_down: false", and any
/// other "--max-roughness" of the kind's parameters "max_roughness". The libraries word
/// their messages for the CLIs they share with the pipeline.
pub fn ron_terms(message: &str, names: &[String]) -> String {
    let mut out = message.to_string();
    // Longest first, so that --size does not rewrite the front of --size-bias.
    let mut names: Vec<&String> = names.iter().collect();
    names.sort_by_key(|n| std::cmp::Reverse(n.len()));
    for name in names {
        let flag = format!("--{}", name.replace('_', "-"));
        if !out.contains(&flag) {
            continue;
        }
        for (verb, value) in [("pass ", "true"), ("use ", "true"), ("drop ", "false")] {
            out = out.replace(&format!("{verb}{flag}"), &format!("set {name}: {value}"));
        }
        // Whole flags only: the next character must not continue the flag's name.
        let mut rewritten = String::with_capacity(out.len());
        let mut rest = out.as_str();
        while let Some(at) = rest.find(&flag) {
            let after = &rest[at + flag.len()..];
            rewritten.push_str(&rest[..at]);
            if after.starts_with(|c: char| c.is_ascii_alphanumeric() || c == '-') {
                rewritten.push_str(&flag);
            } else {
                rewritten.push_str(name);
            }
            rest = after;
        }
        rewritten.push_str(rest);
        out = rewritten;
    }
    out
}

/// The canonical text of parameters hashed into cache keys.
pub fn canonical_text(p: &AnyParams) -> String {
    serde_json::to_string(&p.canonical()).expect("JSON value prints")
}

/// How many sources a kind reads, and what they are.
#[derive(Clone, Copy, Debug)]
pub struct Arity {
    /// The fewest sources.
    pub min: usize,
    /// The most sources (`usize::MAX`: no limit).
    pub max: usize,
    /// What each source is, for messages ("an environment: equirect, cube folder or KTX2").
    pub what: &'static str,
}

impl Arity {
    /// Reads nothing.
    pub const NONE: Arity = Arity {
        min: 0,
        max: 0,
        what: "nothing",
    };
    /// Exactly one source, of the kind `what` says.
    pub const fn one(what: &'static str) -> Arity {
        Arity {
            min: 1,
            max: 1,
            what,
        }
    }
    /// "reads exactly 1 (an environment ...)", for messages.
    pub fn describe(&self) -> String {
        match (self.min, self.max) {
            (0, 0) => "reads nothing".to_string(),
            (a, b) if a == b => format!("reads exactly {a} ({})", self.what),
            (a, usize::MAX) => format!("reads at least {a} ({})", self.what),
            (a, b) => format!("reads {a} to {b} ({})", self.what),
        }
    }
}

/// A bake's failure as the runner keeps it: its one-line message and exit-code class.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct BakeError {
    /// One line, naming the file and the problem.
    pub message: String,
    /// Its exit-code class.
    pub class: ErrorClass,
}

impl<E: Classify + 'static> From<E> for BakeError {
    fn from(e: E) -> Self {
        BakeError {
            message: crate::error::error_chain(&e),
            class: e.class(),
        }
    }
}

impl fmt::Display for BakeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.message)
    }
}

/// What a bake produced: encoded files (not yet written) and warnings for the log.
#[derive(Default)]
pub struct Baked {
    /// (path, bytes) of every file, under the stage's folder.
    pub files: Vec<(PathBuf, Vec<u8>)>,
    /// Warnings for the log.
    pub warnings: Vec<String>,
}

/// A stage kind, type-erased: everything the planner, executor and ninja emitter ask of it.
pub trait Kind: Send + Sync {
    /// The name used in pipelines (`kind: "prefilter"`).
    fn name(&self) -> &'static str;
    /// One line for `bake kinds`.
    fn summary(&self) -> &'static str;
    /// The CLI that runs the same bake: binary name, then subcommand if any.
    fn command(&self) -> &'static [&'static str];
    /// The cargo package that builds that binary.
    fn package(&self) -> &'static str;
    /// The library crate the bake lives in: its fingerprint is the tool part of the stage keys
    /// (`cache::tool_for`).
    fn library(&self) -> &'static str;
    /// How many sources it reads, and what they are.
    fn reads(&self) -> Arity;
    /// The RON keys (= long flags with `_` for `-`) this kind's parameters accept.
    fn param_names(&self) -> Vec<String>;
    /// Parses the RON text of `params: (...)` (missing keys take their defaults).
    fn parse(&self, ron: &str) -> Result<AnyParams, ron::error::SpannedError>;
    /// Its parameters at their defaults (clap's).
    fn default_params(&self) -> AnyParams;
    /// Non-default parameters exercising every kind of field (tests round-trip them).
    fn example_params(&self) -> AnyParams;
    /// `p` with `key` set to `value` (the scene's overrides: max roughness, n_u and n_v).
    fn with(&self, p: &AnyParams, key: &str, value: serde_json::Value)
        -> Result<AnyParams, String>;
    /// The bake's own validation of its parameters (before any work).
    fn validate(&self, p: &AnyParams) -> Result<(), BakeError>;
    /// The `-o` argument for a stage writing into `dir`.
    fn out_arg(&self, p: &AnyParams, dir: &Path) -> PathBuf;
    /// What a downstream stage reads of this stage's outputs (the cube folder, the KTX2 file...).
    fn product(&self, p: &AnyParams, dir: &Path) -> PathBuf;
    /// The files a run will write, known before running (for ninja and for `plan`).
    fn outputs(
        &self,
        p: &AnyParams,
        inputs: &[PathBuf],
        dir: &Path,
    ) -> Result<Vec<PathBuf>, BakeError>;
    /// Runs the bake in-process; nothing is written.
    fn run(
        &self,
        p: &AnyParams,
        inputs: &[PathBuf],
        dir: &Path,
        progress: &dyn Progress,
    ) -> Result<Baked, BakeError>;
    /// The CLI commands (argv, binary name first) that run the same bake; `rel` writes a path
    /// as the command line should name it.
    fn argv(
        &self,
        p: &AnyParams,
        inputs: &[PathBuf],
        dir: &Path,
        rel: &dyn Fn(&Path) -> PathBuf,
    ) -> Result<Vec<Vec<String>>, String>;
    /// Checks that `p` survives `Params → CLI args → clap → Params` unchanged.
    fn cli_round_trip(&self, p: &AnyParams) -> Result<Vec<String>, String>;
    /// The stage's work split into independent items, each baked by `run(p, &item.inputs,
    /// &item.dir)`; `None` when the kind bakes its inputs as one piece.
    fn items(
        &self,
        p: &AnyParams,
        inputs: &[PathBuf],
        dir: &Path,
    ) -> Option<Result<Vec<Item>, BakeError>>;
}

/// Lists the files a run writes, given the resolved inputs and the `-o` path.
pub type OutputsFn<P> = fn(&P, &[PathBuf], &Path) -> Result<Vec<PathBuf>, BakeError>;
/// Runs the bake in-process, given the resolved inputs and the `-o` path.
pub type RunFn<P> = fn(&P, &[PathBuf], &Path, &dyn Progress) -> Result<Baked, BakeError>;
/// Writes the CLI commands of a stage: inputs, stage folder, how to write a path.
pub type ArgvFn<P> =
    fn(&P, &[PathBuf], &Path, &dyn Fn(&Path) -> PathBuf) -> Result<Vec<Vec<String>>, String>;

/// Splits a stage's work into items, given the resolved inputs and the stage folder.
pub type ItemsFn<P> = fn(&P, &[PathBuf], &Path) -> Result<Vec<Item>, BakeError>;

/// One independent piece of a stage's work (one material of a folder of materials): the
/// runner gives it its own cache key, so one changed file re-bakes one item. Running the
/// kind on `inputs` into `dir` bakes exactly this item's outputs.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Item {
    /// The files it reads (its key hashes them), given to the bake as its inputs.
    pub inputs: Vec<PathBuf>,
    /// The folder its run writes into, inside the stage's folder.
    pub dir: PathBuf,
}

/// The adapter behind every kind: plain functions over the bake's own `Params` type.
pub struct Adapter<P> {
    /// The kind's name in pipelines.
    pub name: &'static str,
    /// One line for `bake kinds`.
    pub summary: &'static str,
    /// The CLI running the same bake: binary, then subcommand if any.
    pub command: &'static [&'static str],
    /// The cargo package building that binary.
    pub package: &'static str,
    /// The library crate whose `run` the bake is (see [`Kind::library`]).
    pub library: &'static str,
    /// How many sources it reads.
    pub reads: Arity,
    /// The `-o` argument given the stage's folder (the folder itself, or a file in it).
    pub out: fn(&P, &Path) -> PathBuf,
    /// What a downstream stage reads, given the `-o` path.
    pub product: fn(&P, &Path) -> PathBuf,
    /// Outputs of a run given the resolved inputs and the `-o` path.
    pub outputs: OutputsFn<P>,
    /// The in-process bake given the resolved inputs and the `-o` path.
    pub run: RunFn<P>,
    /// The bake's validation of its parameters.
    pub validate: fn(&P) -> Result<(), BakeError>,
    /// Non-default example parameters (for tests).
    pub example: fn() -> P,
    /// The CLI commands (argv, binary first) doing the same work, given the inputs, the stage
    /// folder, and how to write a path for the command line (relative to the ninja file);
    /// `None`: one command,
    /// `BIN [SUB] INPUTS... -o OUT FLAGS... --quiet`.
    pub argv: Option<ArgvFn<P>>,
    /// The stage's work as independent items (see [`Kind::items`]); `None`: one piece.
    pub items: Option<ItemsFn<P>>,
}

/// `-o DIR`: the CLI writes into the stage's folder.
pub fn in_dir<P>(_: &P, dir: &Path) -> PathBuf {
    dir.to_path_buf()
}

/// The single command most CLIs take: `BIN [SUB] INPUTS... -o OUT FLAGS... --quiet`.
pub fn standard_argv(
    command: &[&str],
    inputs: &[PathBuf],
    out: &Path,
    flags: Vec<String>,
) -> Vec<String> {
    let mut args: Vec<String> = command.iter().map(|s| s.to_string()).collect();
    args.extend(inputs.iter().map(|p| p.display().to_string()));
    args.push("-o".into());
    args.push(out.display().to_string());
    args.extend(flags);
    args.push("--quiet".into());
    args
}

impl<P: BakeParams> Adapter<P> {
    fn typed<'a>(&self, p: &'a AnyParams) -> &'a P {
        p.as_any()
            .downcast_ref::<P>()
            .unwrap_or_else(|| panic!("parameters of another kind given to '{}'", self.name))
    }
}

/// RON as pipelines are written: `size: 64` for an `Option` field, no `Some(...)` needed.
pub fn ron_options() -> ron::Options {
    ron::Options::default().with_default_extension(ron::extensions::Extensions::IMPLICIT_SOME)
}

impl<P: BakeParams> Kind for Adapter<P> {
    fn name(&self) -> &'static str {
        self.name
    }
    fn summary(&self) -> &'static str {
        self.summary
    }
    fn command(&self) -> &'static [&'static str] {
        self.command
    }
    fn package(&self) -> &'static str {
        self.package
    }
    fn library(&self) -> &'static str {
        self.library
    }
    fn reads(&self) -> Arity {
        self.reads
    }
    fn param_names(&self) -> Vec<String> {
        cli::fields(&P::default())
            .map(|f| f.into_iter().map(|(n, _)| n).collect())
            .unwrap_or_default()
    }
    fn parse(&self, ron: &str) -> Result<AnyParams, ron::error::SpannedError> {
        let p: P = ron_options().from_str(ron)?;
        Ok(Arc::new(p))
    }
    fn default_params(&self) -> AnyParams {
        Arc::new(P::default())
    }
    fn example_params(&self) -> AnyParams {
        Arc::new((self.example)())
    }
    fn with(
        &self,
        p: &AnyParams,
        key: &str,
        value: serde_json::Value,
    ) -> Result<AnyParams, String> {
        let mut v = serde_json::to_value(self.typed(p)).map_err(|e| e.to_string())?;
        let obj = v.as_object_mut().ok_or("parameters are not a struct")?;
        if !obj.contains_key(key) {
            return Err(format!("'{}' has no parameter '{key}'", self.name));
        }
        obj.insert(key.to_string(), value);
        let p: P = serde_json::from_value(v)
            .map_err(|e| format!("'{}' parameter '{key}': {e}", self.name))?;
        Ok(Arc::new(p))
    }
    fn validate(&self, p: &AnyParams) -> Result<(), BakeError> {
        (self.validate)(self.typed(p)).map_err(|e| self.in_ron_terms(e))
    }
    fn out_arg(&self, p: &AnyParams, dir: &Path) -> PathBuf {
        (self.out)(self.typed(p), dir)
    }
    fn product(&self, p: &AnyParams, dir: &Path) -> PathBuf {
        (self.product)(self.typed(p), &self.out_arg(p, dir))
    }
    fn outputs(
        &self,
        p: &AnyParams,
        inputs: &[PathBuf],
        dir: &Path,
    ) -> Result<Vec<PathBuf>, BakeError> {
        (self.outputs)(self.typed(p), inputs, &self.out_arg(p, dir))
    }
    fn run(
        &self,
        p: &AnyParams,
        inputs: &[PathBuf],
        dir: &Path,
        progress: &dyn Progress,
    ) -> Result<Baked, BakeError> {
        let mut baked = (self.run)(self.typed(p), inputs, &self.out_arg(p, dir), progress)
            .map_err(|e| self.in_ron_terms(e))?;
        let names = self.param_names();
        for w in &mut baked.warnings {
            *w = ron_terms(w, &names);
        }
        Ok(baked)
    }
    fn argv(
        &self,
        p: &AnyParams,
        inputs: &[PathBuf],
        dir: &Path,
        rel: &dyn Fn(&Path) -> PathBuf,
    ) -> Result<Vec<Vec<String>>, String> {
        match self.argv {
            Some(f) => f(self.typed(p), inputs, dir, rel),
            None => {
                let inputs: Vec<PathBuf> = inputs.iter().map(|i| rel(i)).collect();
                Ok(vec![standard_argv(
                    self.command,
                    &inputs,
                    &rel(&self.out_arg(p, dir)),
                    self.typed(p).cli_args()?,
                )])
            }
        }
    }
    fn items(
        &self,
        p: &AnyParams,
        inputs: &[PathBuf],
        dir: &Path,
    ) -> Option<Result<Vec<Item>, BakeError>> {
        let items = self.items?;
        Some(items(self.typed(p), inputs, &self.out_arg(p, dir)))
    }
    fn cli_round_trip(&self, p: &AnyParams) -> Result<Vec<String>, String> {
        let p = self.typed(p);
        let args = cli::to_args(p)?;
        let back: P = cli::from_args(&args)?;
        let (a, b) = (
            serde_json::to_value(p).unwrap(),
            serde_json::to_value(&back).unwrap(),
        );
        if a != b {
            return Err(format!(
                "'{}': {args:?} parse back to {b} instead of {a}",
                self.name
            ));
        }
        Ok(args)
    }
}

/// An adapter's example parameters from RON text (a typo fails the kinds' tests).
pub(crate) fn example<P: BakeParams>(ron: &str) -> P {
    ron_options()
        .from_str(ron)
        .unwrap_or_else(|e| panic!("example parameters {ron}: {e}"))
}

/// Errors of adapters themselves (wrong number of inputs reaching `run`).
pub(crate) fn input_error(kind: &str, why: impl Into<String>) -> BakeError {
    BakeError {
        message: format!("{kind}: {}", why.into()),
        class: ErrorClass::InvalidInput,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pipeline_messages_name_ron_keys() {
        let names: Vec<String> = ["y_down", "size", "size_bias", "sanitize", "max_roughness"]
            .map(String::from)
            .to_vec();
        assert_eq!(
            ron_terms("leans y-down (DirectX): pass --y-down", &names),
            "leans y-down (DirectX): set y_down: true"
        );
        assert_eq!(ron_terms("drop --y-down", &names), "set y_down: false");
        assert_eq!(
            ron_terms(
                "--size 9 and --size-bias 2; --max-roughness -1 (--sanitize)",
                &names
            ),
            "size 9 and size_bias 2; max_roughness -1 (sanitize)"
        );
        // Flags of other tools stay as they are.
        assert_eq!(ron_terms("--other", &names), "--other");
    }

    #[test]
    fn every_kind_round_trips_its_parameters_through_its_cli() {
        for k in all() {
            for p in [k.default_params(), k.example_params()] {
                let args = k
                    .cli_round_trip(&p)
                    .unwrap_or_else(|e| panic!("{}: {e}", k.name()));
                eprintln!("{}: {args:?}", k.name());
            }
            assert!(
                !k.cli_round_trip(&k.example_params()).unwrap().is_empty(),
                "{}: the example must differ from the defaults",
                k.name()
            );
        }
    }

    #[test]
    fn empty_params_are_the_defaults_and_unknown_keys_are_refused_with_the_valid_names() {
        for k in all() {
            let p = k.parse("()").unwrap();
            assert_eq!(
                canonical_text(&p),
                canonical_text(&k.default_params()),
                "{}",
                k.name()
            );
            let e = k
                .parse("(no_such_key: 1)")
                .err()
                .unwrap_or_else(|| panic!("{} accepted an unknown key", k.name()));
            let msg = e.code.to_string();
            let first = &k.param_names()[0];
            assert!(
                msg.contains(first.as_str()),
                "{}: message should list valid names: {msg}",
                k.name()
            );
        }
    }

    /// Values to try for a field that currently holds `v` (the example's value first).
    fn other_values(
        v: &serde_json::Value,
        example: Option<&serde_json::Value>,
    ) -> Vec<serde_json::Value> {
        use serde_json::{json, Value};
        let mut out: Vec<Value> = example.into_iter().cloned().collect();
        match v {
            Value::Bool(b) => out.push(json!(!b)),
            Value::Number(n) => {
                let x = n.as_f64().unwrap_or(0.0);
                out.extend([json!(x as i64 + 1), json!(x * 2.0 + 1.0), json!(x / 2.0)]);
            }
            Value::String(t) => out.extend([json!(format!("{t}x")), json!("1")]),
            Value::Array(a) => {
                out.push(json!([]));
                if let Some(first) = a.first() {
                    out.push(Value::Array(vec![first.clone()]));
                }
            }
            _ => {}
        }
        // Options that are unset, and anything else: common shapes.
        out.extend([
            json!(1),
            json!(0.5),
            json!("x"),
            json!(true),
            json!("8x8"),
            json!("radial"),
            Value::Null,
        ]);
        out
    }

    #[test]
    fn canonical_text_is_stable_and_changes_with_any_field() {
        for k in all() {
            let (d, e) = (k.default_params(), k.example_params());
            assert_eq!(canonical_text(&d), canonical_text(&k.default_params()));
            assert_ne!(canonical_text(&d), canonical_text(&e), "{}", k.name());
            let (dv, ev) = (d.canonical(), e.canonical());
            for name in k.param_names() {
                let current = &dv[&name];
                // For an enum, serde's refusal of "x" lists its variants.
                let variants: Vec<serde_json::Value> = match k.with(&d, &name, "x".into()) {
                    Err(e) => e.split('`').skip(3).step_by(2).map(|v| v.into()).collect(),
                    Ok(_) => vec![],
                };
                let changed = other_values(current, ev.get(&name))
                    .into_iter()
                    .chain(variants)
                    .filter(|v| v != current)
                    .find_map(|v| k.with(&d, &name, v).ok())
                    .unwrap_or_else(|| {
                        panic!("{}: no other value for '{name}' (now {current})", k.name())
                    });
                assert_ne!(
                    canonical_text(&changed),
                    canonical_text(&d),
                    "{}: changing '{name}' does not change the canonical text",
                    k.name()
                );
                assert_ne!(
                    changed.canonical()[&name],
                    *current,
                    "{}: '{name}'",
                    k.name()
                );
            }
        }
    }
}
