//! What every binary shares: the common flags, the thread pool, a terminal progress bar,
//! warnings, the `--json` summary, and printing an error's whole chain with its exit code.

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
    pub tool: String,
    pub version: String,
    pub outputs: Vec<String>,
    pub seconds: f64,
    pub warnings: Vec<String>,
    /// Bake-specific details (error estimates, sample counts, ...).
    pub details: serde_json::Value,
}

/// Context handed to a binary's body.
pub struct Ctx {
    pub common: CommonArgs,
    progress: TerminalProgress,
    warnings: std::sync::Mutex<Vec<String>>,
}

impl Ctx {
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

/// Writes a bake's encoded files as one atomic set and returns their paths for the summary.
pub fn write_outputs(
    files: &[(std::path::PathBuf, Vec<u8>)],
) -> Result<Vec<String>, ibl_core::Error> {
    ibl_core::io::write_many_atomic(files)?;
    Ok(files.iter().map(|f| f.0.display().to_string()).collect())
}

/// Writes a cube bake's files as one atomic set, then removes what an earlier run of the same
/// bake left in `dir` that this one did not write (another layout's container or faces, levels
/// of a longer chain; see [`ibl_core::output::stale_cube_files`]), each with a warning, so the
/// folder holds exactly this run's result.
pub fn write_cube_outputs(
    ctx: &Ctx,
    dir: &std::path::Path,
    name: &str,
    files: &[(std::path::PathBuf, Vec<u8>)],
) -> Result<Vec<String>, ibl_core::Error> {
    let outputs = write_outputs(files)?;
    let written: Vec<std::path::PathBuf> = files.iter().map(|f| f.0.clone()).collect();
    for stale in ibl_core::output::stale_cube_files(dir, name, &written) {
        std::fs::remove_file(&stale).map_err(|e| ibl_core::Error::io(&stale, e))?;
        ctx.warn(format!(
            "removed {} (left by an earlier run with another layout or a longer chain)",
            stale.display()
        ));
    }
    Ok(outputs)
}

/// The `encoding` details of a `--json` summary: the sidecar's numbers and each level's
/// encode time.
pub fn encoding_details(levels: &[ibl_core::io::texture::LevelEncoding]) -> serde_json::Value {
    serde_json::json!({
        "levels": levels,
        "seconds": levels.iter().map(|l| l.seconds).collect::<Vec<f64>>(),
    })
}

/// Runs a binary's body: builds the thread pool, times it, prints the summary or the error
/// chain, and exits with the right code. Never returns.
pub fn run<E, F>(tool: &str, common: CommonArgs, body: F) -> !
where
    E: Classify,
    F: FnOnce(&Ctx) -> Result<(Vec<String>, serde_json::Value), E>,
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
    let show = !common.quiet && std::io::stderr().is_terminal();
    let ctx = Ctx {
        progress: TerminalProgress::new(show),
        common,
        warnings: Default::default(),
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
                details,
            };
            if ctx.common.json {
                println!(
                    "{}",
                    serde_json::to_string_pretty(&summary).expect("summary serialises")
                );
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
            eprintln!("{tool}: error: {}", error_chain(&e));
            std::process::exit(exit_code(e.class()))
        }
    }
}

/// "outer: cause: root cause" on one line (`ibl_core::error::chain`).
pub use ibl_core::error::chain as error_chain;

/// An indicatif bar on stderr when it is a terminal; silent otherwise.
pub struct TerminalProgress {
    bar: Option<indicatif::ProgressBar>,
}

impl TerminalProgress {
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
pub fn parse<P: clap::Parser>(tool: &str) -> P {
    match P::try_parse() {
        Ok(p) => p,
        Err(e) => {
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
    }
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

    #[test]
    fn usage_errors_fold_to_one_line() {
        let text = "error: unexpected argument '--sise' found\n\n  tip: a similar argument exists: '--size'\n\nUsage: x [OPTIONS]\n\nFor more information, try '--help'.\n";
        assert_eq!(
            usage_error_line(text),
            "error: unexpected argument '--sise' found tip: a similar argument exists: '--size'"
        );
    }
}
