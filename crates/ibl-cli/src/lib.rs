//! What every binary shares: the common flags, the thread pool, a terminal progress bar,
//! warnings, the `--json` summary, and printing an error's whole chain with its exit code;
//! and, from a bake's one definition ([`ibl_bake::Bake`]), each bake binary's whole `main`
//! ([`main`], [`main_with`], [`main_subcommands`]).

#![warn(missing_docs)]

mod bake;

pub use bake::{command, main, main_subcommands, main_with, Alternative, Outcome, Subcommand};
use ibl_bake::BakeError;
use ibl_core::error::{Classify, ErrorClass};
use ibl_core::progress::Progress;
use serde::Serialize;
use std::io::IsTerminal;
use std::time::Instant;

/// Flags every binary takes.
#[derive(Clone, Debug, Default, clap::Args)]
pub struct CommonArgs {
    /// Worker threads (default: all cores).
    #[arg(long, value_name = "N")]
    pub threads: Option<usize>,
    /// No progress bar and no warnings on stderr.
    #[arg(long, short)]
    pub quiet: bool,
    /// Print a machine-readable JSON summary on stdout.
    #[arg(long)]
    pub json: bool,
    /// Memory the inputs may take once decoded (512M, 8G, ...): a file whose header declares
    /// more is refused before it is decoded [default: min(4 GiB, half the machine's memory),
    /// or $IBL_MAX_MEMORY].
    #[arg(long, value_name = "SIZE", value_parser = ibl_core::io::budget::parse_size)]
    pub max_memory: Option<u64>,
    /// Replace output files this tool did not write, or that changed since it wrote them
    /// (otherwise refused before any work; see the `.ibl-outputs.json` beside the outputs).
    #[arg(long)]
    pub overwrite: bool,
}

/// Exit codes: 0 success, 2 invalid input or parameters (also clap's usage errors),
/// 3 unsupported input, 4 file-system errors.
pub fn exit_code(class: ErrorClass) -> i32 {
    match class {
        ErrorClass::InvalidInput => 2,
        ErrorClass::Unsupported => 3,
        ErrorClass::Io => 4,
    }
}

/// A summary the binary prints: human lines on stderr, the JSON value with `--json`.
#[derive(Debug, Default, Serialize)]
pub struct Summary {
    /// The binary's name.
    pub tool: String,
    /// Its version.
    pub version: String,
    /// The files written.
    pub outputs: Vec<String>,
    /// Wall-clock time of the body.
    pub seconds: f64,
    /// Every warning printed.
    pub warnings: Vec<String>,
    /// Bake-specific details (error estimates, sample counts, ...).
    pub details: serde_json::Value,
}

/// Context handed to a binary's body.
pub struct Ctx {
    /// The flags every binary takes.
    pub common: CommonArgs,
    progress: TerminalProgress,
    warnings: std::sync::Mutex<Vec<String>>,
    json_printed: std::sync::atomic::AtomicBool,
}

impl Ctx {
    /// The progress bar (silent unless stderr is a terminal).
    pub fn progress(&self) -> &dyn Progress {
        &self.progress
    }
    /// Prints a warning (unless `--quiet`) and records it for the summary.
    pub fn warn(&self, msg: impl Into<String>) {
        let msg = msg.into();
        if !self.common.quiet {
            eprintln!("warning: {msg}");
        }
        self.warnings.lock().unwrap().push(msg);
    }
    /// Prints a `--json` summary now (a batch that failed part-way reports its counts): the
    /// error object [`run`] would print is then left out, so stdout holds one JSON document.
    pub fn print_json_summary(&self, summary: &Summary) {
        self.json_printed
            .store(true, std::sync::atomic::Ordering::Relaxed);
        print_stdout(&format!(
            "{}\n",
            serde_json::to_string_pretty(summary).expect("summary serialises")
        ));
    }
    /// Prints an informational line unless `--quiet` or `--json`.
    pub fn info(&self, msg: impl AsRef<str>) {
        if !self.common.quiet && !self.common.json {
            eprintln!("{}", msg.as_ref());
        }
    }
    /// Loads an environment bake's input (equirect, cross, face folder or KTX2) and reports
    /// what the input policy did to it (sanitised or clamped texels) as warnings.
    pub fn load_environment(
        &self,
        input: &std::path::Path,
        sanitize: bool,
    ) -> Result<ibl_core::envmap::LoadedEnvironment, ibl_core::Error> {
        let env = ibl_core::envmap::load_environment(input, sanitize)?;
        env.warnings().into_iter().for_each(|w| self.warn(w));
        Ok(env)
    }
}

/// Where outputs go, checked before any input is read (`ibl_core::io::check_output`).
pub use ibl_core::io::{check_output, OutputKind};

/// Writes a bake's encoded files as one atomic set and returns their paths for the summary.
pub fn write_outputs(
    files: &[(std::path::PathBuf, Vec<u8>)],
) -> Result<Vec<String>, ibl_core::Error> {
    ibl_core::io::write_many_atomic(files)?;
    Ok(files.iter().map(|f| f.0.display().to_string()).collect())
}

/// After a cube bake wrote `files`, removes what an earlier run of the same bake left in `dir`
/// that this one did not write (another layout's container or faces, levels of a longer
/// chain; see [`ibl_core::output::stale_cube_files`]), each with a warning, so the folder holds
/// exactly this run's result. Only files the folder's record
/// ([`ibl_core::ownership::Record`]) says a tool wrote, bytes unchanged, are removed; any other
/// file of such a name is left in place with a warning.
pub fn stale_cleanup(
    ctx: &Ctx,
    dir: &std::path::Path,
    name: &str,
    files: &[(std::path::PathBuf, Vec<u8>)],
) -> Result<(), ibl_core::Error> {
    let written: Vec<std::path::PathBuf> = files.iter().map(|f| f.0.clone()).collect();
    let stale = ibl_core::output::stale_cube_files(dir, name, &written);
    let (ours, not_ours) = ibl_core::ownership::split_owned(dir, stale);
    let mut record = ibl_core::ownership::Record::load(dir);
    for stale in &ours {
        std::fs::remove_file(stale).map_err(|e| ibl_core::Error::io(stale, e))?;
        record.remove(dir, stale);
        ctx.warn(format!(
            "removed {} (written by an earlier run with another layout or a longer chain)",
            stale.display()
        ));
    }
    if !ours.is_empty() {
        record.save(dir)?;
    }
    for kept in not_ours {
        ctx.warn(format!(
            "left {} in place: named like an output of another layout, but not written by this \
             tool or changed since (remove it yourself if it is stale)",
            kept.display()
        ));
    }
    Ok(())
}

/// The folder whose record lists the outputs of a run writing to `out`: `out` itself, or the
/// folder of the one output file.
pub fn record_dir(out: &std::path::Path, kind: OutputKind) -> std::path::PathBuf {
    match kind {
        OutputKind::Folder => out.to_path_buf(),
        OutputKind::File => match out.parent() {
            Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
            _ => std::path::PathBuf::from("."),
        },
    }
}

/// Records `files` as written by `tool` in `dir`'s record (after they were written).
pub fn record_outputs(
    tool: &str,
    dir: &std::path::Path,
    files: &[(std::path::PathBuf, Vec<u8>)],
) -> Result<(), ibl_core::Error> {
    let mut record = ibl_core::ownership::Record::load(dir);
    record.add(dir, tool, files);
    record.save(dir)
}

/// Runs a binary's body: builds the thread pool, times it, prints the summary or the error
/// chain, and exits with the right code. Never returns.
pub fn run<E, F>(tool: &str, common: CommonArgs, body: F) -> !
where
    E: Classify + 'static,
    F: FnOnce(&Ctx) -> Result<(Vec<String>, serde_json::Value), E>,
{
    run_body(tool, common, |ctx| body(ctx).map_err(BakeError::from))
}

/// [`run`] with the error already one line and a class (a bake's [`BakeError`]).
fn run_body<F>(tool: &str, common: CommonArgs, body: F) -> !
where
    F: FnOnce(&Ctx) -> Result<(Vec<String>, serde_json::Value), BakeError>,
{
    if let Some(n) = common.threads {
        if n == 0 {
            eprintln!("{tool}: error: --threads must be at least 1");
            std::process::exit(2);
        }
        let _ = rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build_global();
    }
    if let Some(bytes) = common.max_memory {
        ibl_core::io::budget::set_max_memory(bytes);
    }
    let show = !common.quiet && std::io::stderr().is_terminal();
    let ctx = Ctx {
        progress: TerminalProgress::new(show),
        common,
        warnings: Default::default(),
        json_printed: Default::default(),
    };
    let start = Instant::now();
    match body(&ctx) {
        Ok((outputs, details)) => {
            let summary = Summary {
                tool: tool.to_string(),
                version: ibl_core::TOOL_VERSION.to_string(),
                outputs,
                seconds: start.elapsed().as_secs_f64(),
                warnings: ctx.warnings.into_inner().unwrap(),
                details: {
                    let mut d = details;
                    ibl_core::io::data::shortest_f32(&mut d);
                    d
                },
            };
            if ctx.common.json {
                print_stdout(&format!(
                    "{}\n",
                    serde_json::to_string_pretty(&summary).expect("summary serialises")
                ));
            } else if !ctx.common.quiet {
                eprintln!(
                    "{tool}: wrote {} file(s) in {:.3} s",
                    summary.outputs.len(),
                    summary.seconds
                );
                for o in &summary.outputs {
                    eprintln!("  {o}");
                }
            }
            std::process::exit(0)
        }
        Err(e) => {
            let code = exit_code(e.class);
            eprintln!("{tool}: error: {}", e.message);
            if ctx.common.json && !ctx.json_printed.into_inner() {
                let warnings = ctx.warnings.into_inner().unwrap();
                print_stdout(&json_error(tool, &e.message, code, &warnings));
            }
            std::process::exit(code)
        }
    }
}

/// The JSON object a `--json` run prints on stdout when it fails, so that a script reading
/// stdout gets an answer either way: `{"tool", "version", "error", "exit_code", "warnings"}`.
pub fn json_error(tool: &str, error: &str, exit_code: i32, warnings: &[String]) -> String {
    let v = serde_json::json!({
        "tool": tool,
        "version": ibl_core::TOOL_VERSION,
        "error": error,
        "exit_code": exit_code,
        "warnings": warnings,
    });
    format!(
        "{}\n",
        serde_json::to_string_pretty(&v).expect("error serialises")
    )
}

/// Writes to stdout; a reader that went away (`| head -1`) ends the process quietly with
/// exit 0 instead of the panic `println!` gives on a closed pipe.
pub fn print_stdout(text: &str) {
    use std::io::Write;
    let mut out = std::io::stdout().lock();
    if let Err(e) = out.write_all(text.as_bytes()).and_then(|()| out.flush()) {
        if e.kind() == std::io::ErrorKind::BrokenPipe {
            std::process::exit(0);
        }
        eprintln!("error: cannot write to stdout: {e}");
        std::process::exit(4);
    }
}

/// Makes `println!` on a closed stdout end the process quietly (exit 0) instead of printing a
/// panic and a backtrace: the standard library panics with "failed printing to stdout" when
/// the reader of a pipe went away (`bake kinds | head -1`). [`parse`] installs it, so every
/// binary has it before it prints anything.
pub fn exit_quietly_on_closed_stdout() {
    let previous = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        let msg = info
            .payload()
            .downcast_ref::<String>()
            .map(String::as_str)
            .or_else(|| info.payload().downcast_ref::<&str>().copied())
            .unwrap_or("");
        if msg.starts_with("failed printing to stdout") && msg.contains("Broken pipe") {
            std::process::exit(0);
        }
        previous(info)
    }));
}

/// "outer: cause: root cause" on one line (`ibl_core::error::chain`).
pub use ibl_core::error::chain as error_chain;

/// An indicatif bar on stderr when it is a terminal; silent otherwise.
pub struct TerminalProgress {
    bar: Option<indicatif::ProgressBar>,
}

impl TerminalProgress {
    /// A bar when `show`, otherwise silence.
    pub fn new(show: bool) -> Self {
        let bar = show.then(|| {
            let b = indicatif::ProgressBar::new(0);
            b.set_style(
                indicatif::ProgressStyle::with_template("{msg:>12} [{bar:40}] {percent:>3}% {eta}")
                    .expect("static template")
                    .progress_chars("=> "),
            );
            b
        });
        TerminalProgress { bar }
    }
}

impl Progress for TerminalProgress {
    fn start(&self, label: &str, total: u64) {
        if let Some(b) = &self.bar {
            b.reset();
            b.set_length(total);
            b.set_message(label.to_string());
        }
    }
    fn inc(&self, n: u64) {
        if let Some(b) = &self.bar {
            b.inc(n);
        }
    }
    fn finish(&self) {
        if let Some(b) = &self.bar {
            b.finish_and_clear();
        }
    }
}

/// Parses the command line; usage errors become one line `tool: …` on stderr and exit code 2
/// (`--help` and `--version` print as usual). Every binary parses through this.
///
/// Every argument that takes a value accepts negative numbers (`--max-roughness -0.5` reaches
/// the parameter's range check instead of clap's "unexpected argument '-0'"), lists too
/// (`--roughness -0.1,0.5`).
pub fn parse<P: clap::Parser>(tool: &str) -> P {
    exit_quietly_on_closed_stdout();
    try_parse_from::<P, _, _>(std::env::args_os()).unwrap_or_else(|e| usage_exit(tool, e))
}

/// Ends the process for a clap error: `--help` and `--version` print as usual, a usage error
/// is one line `tool: …` on stderr and exit code 2.
fn usage_exit(tool: &str, e: clap::Error) -> ! {
    use clap::error::ErrorKind;
    if matches!(
        e.kind(),
        ErrorKind::DisplayHelp
            | ErrorKind::DisplayVersion
            | ErrorKind::DisplayHelpOnMissingArgumentOrSubcommand
    ) {
        e.exit();
    }
    eprintln!("{tool}: {}", usage_error_line(&e.to_string()));
    std::process::exit(2);
}

/// Parses `args` (program name first) with negative values allowed, as [`parse`] does.
pub fn try_parse_from<P, I, T>(args: I) -> Result<P, clap::Error>
where
    P: clap::Parser,
    I: IntoIterator<Item = T>,
    T: Into<std::ffi::OsString> + Clone,
{
    let mut cmd = negative_values(P::command());
    let mut matches = cmd.try_get_matches_from_mut(args)?;
    P::from_arg_matches_mut(&mut matches).map_err(|e| e.format(&mut cmd))
}

/// Lets every value-taking argument of `cmd` (and of its subcommands) take a value that
/// starts with '-' when it is a number, or, for comma lists, any value: clap otherwise reads
/// `-0.5` as a flag.
pub fn negative_values(cmd: clap::Command) -> clap::Command {
    cmd.mut_args(|a| {
        if !a.get_action().takes_values() || a.is_positional() {
            return a;
        }
        // A list, split by clap or parsed whole (`--roughness RX,RY`): `-0.1,0.5` is no number,
        // and clap would read `-0` as a flag.
        let list = a.get_value_delimiter().is_some()
            || a.get_value_names()
                .is_some_and(|n| n.iter().any(|s| s.contains(',')));
        if list {
            a.allow_hyphen_values(true)
        } else {
            a.allow_negative_numbers(true)
        }
    })
    .mut_subcommands(negative_values)
}

/// What must not appear in `--help`: rustdoc link syntax (doc comments become help text, and
/// "see [`crate::area`]" means nothing to a user) and citations by file number instead of by
/// author and year (docs/BIBLIOGRAPHY.md).
pub fn help_problems(cmd: clap::Command) -> Vec<String> {
    let mut cmd = cmd;
    cmd.build();
    let mut problems = Vec::new();
    let mut stack = vec![cmd];
    while let Some(mut c) = stack.pop() {
        let help = c.render_long_help().to_string();
        let name = c.get_name().to_string();
        for line in help.lines() {
            let bad = [
                "[`",
                "`]",
                "](",
                "crate::",
                "super::",
                "paper 00",
                "thesis 00",
            ]
            .iter()
            .any(|k| line.contains(k))
                || line.contains(concat!("..", "/shared"));
            if bad {
                problems.push(format!("{name}: {}", line.trim()));
            }
        }
        stack.extend(
            c.get_subcommands()
                .filter(|s| s.get_name() != "help")
                .cloned(),
        );
    }
    problems
}

/// The first paragraph of a clap error, joined into one line.
fn usage_error_line(text: &str) -> String {
    let lines: Vec<&str> = text
        .lines()
        .map(str::trim)
        .take_while(|l| !l.starts_with("Usage:") && !l.starts_with("For more information"))
        .filter(|l| !l.is_empty())
        .collect();
    lines.join(" ")
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Parser, Debug)]
    struct T {
        #[arg(long)]
        x: Option<f32>,
        #[arg(long, value_delimiter = ',')]
        list: Vec<f32>,
        #[arg(long, value_name = "A,B")]
        pair: Option<String>,
        #[arg(long)]
        flag: bool,
        #[command(subcommand)]
        sub: Option<Sub>,
    }
    #[derive(clap::Subcommand, Debug)]
    enum Sub {
        S {
            #[arg(long)]
            n: Option<i64>,
        },
    }

    #[test]
    fn negative_numbers_are_values_not_flags() {
        let t: T = try_parse_from(["t", "--x", "-0.5", "--list", "-0.1,0.5", "--flag"]).unwrap();
        assert_eq!(t.x, Some(-0.5));
        assert_eq!(t.list, vec![-0.1, 0.5]);
        assert!(t.flag);
        // A pair parsed whole (tpr-map's --roughness RX,RY) takes a leading minus too.
        let t: T = try_parse_from(["t", "--pair", "-0.1,0.5"]).unwrap();
        assert_eq!(t.pair.as_deref(), Some("-0.1,0.5"));
        let t: T = try_parse_from(["t", "s", "--n", "-1"]).unwrap();
        assert!(matches!(t.sub, Some(Sub::S { n: Some(-1) })));
        // A real flag after a numeric option is still a flag, and a word still an error.
        assert!(try_parse_from::<T, _, _>(["t", "--x", "--flag"]).is_err());
        let e = try_parse_from::<T, _, _>(["t", "--x", "-abc"]).unwrap_err();
        assert!(e.to_string().contains("unexpected argument"), "{e}");
    }

    #[test]
    fn outputs_are_checked_before_the_bake() {
        let dir = std::env::temp_dir().join(format!("ibl-cli-out-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let file = dir.join("notes.txt");
        std::fs::write(&file, "x").unwrap();
        let msg = |p: &std::path::Path, k| check_output(p, k).unwrap_err().to_string();
        assert!(msg(&file, OutputKind::Folder).contains("is an existing file"));
        assert!(msg(&dir, OutputKind::File).contains("is an existing folder"));
        assert!(msg(&file.join("cube"), OutputKind::Folder).contains("a file in the way"));
        assert!(msg(&file.join("a.exr"), OutputKind::File).contains("a file in the way"));
        check_output(&dir.join("new/deeper"), OutputKind::Folder).unwrap();
        check_output(&dir.join("a.exr"), OutputKind::File).unwrap();
        check_output(&file, OutputKind::File).unwrap();
        assert!(!dir
            .join(format!(".ibl-write-probe-{}", std::process::id()))
            .exists());
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn json_errors_are_one_object() {
        let v: serde_json::Value =
            serde_json::from_str(&json_error("t", "a.png: truncated", 2, &[])).unwrap();
        assert_eq!(v["error"], "a.png: truncated");
        assert_eq!(v["exit_code"], 2);
    }

    #[test]
    fn usage_errors_fold_to_one_line() {
        let text = "error: unexpected argument '--sise' found\n\n  tip: a similar argument exists: '--size'\n\nUsage: x [OPTIONS]\n\nFor more information, try '--help'.\n";
        assert_eq!(
            usage_error_line(text),
            "error: unexpected argument '--sise' found tip: a similar argument exists: '--size'"
        );
    }
}
