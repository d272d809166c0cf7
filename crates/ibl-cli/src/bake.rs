//! Each bake binary's whole `main`, built from the bake's one definition: the clap command
//! (positional input, `-o`, the flattened `Params`, the common flags), validation before any
//! input is read, the output check before the work, the atomic write that also removes stale
//! files, and the warnings, information lines and `--json` summary.

use crate::{
    check_output, negative_values, record_dir, record_outputs, run_body, stale_cleanup, usage_exit,
    write_outputs, OutputKind,
};
use crate::{CommonArgs, Ctx};
use clap::{Args, FromArgMatches};
use ibl_bake::{Bake, BakeError};
use ibl_core::ownership;
use std::path::{Path, PathBuf};

/// The clap command of `bake` as its binary (or subcommand) takes it: [`ibl_bake::command`]
/// with the common flags.
pub fn command<B: Bake>(bake: &B) -> clap::Command {
    ibl_bake::with_about::<B>(CommonArgs::augment_args(ibl_bake::command(bake)))
}

/// What a run of a binary's body gives: the files written and the `--json` details.
pub type Outcome = Result<(Vec<String>, serde_json::Value), BakeError>;

/// Another way to run a bake's binary, chosen by a flag of its own (`quat-map --batch DIR`):
/// the bake's positional input and `-o` are then neither required nor allowed.
pub struct Alternative<P> {
    /// The flag; its id names the mode.
    pub arg: fn() -> clap::Arg,
    /// Runs the mode given the flag's value and the parsed parameters.
    pub run: fn(&Path, &P, &Ctx) -> Outcome,
}

/// A bake as a binary's subcommand (`brdf-lut dfg`): every [`Bake`] is one.
pub trait Subcommand: Sync {
    /// Its clap command.
    fn clap_command(&self) -> clap::Command;
    /// Runs it from its matches and exits.
    fn run_matches(&self, tool: &str, m: &clap::ArgMatches) -> !;
}

impl<B: Bake> Subcommand for B {
    fn clap_command(&self) -> clap::Command {
        command(self)
    }
    fn run_matches(&self, tool: &str, m: &clap::ArgMatches) -> ! {
        let (params, common) = parsed::<B>(tool, m);
        let path = |id: &str| m.get_one::<PathBuf>(id).cloned();
        let inputs: Vec<PathBuf> = path("input").into_iter().collect();
        let out = path("output").expect("-o is required");
        run_body(tool, common, |ctx| {
            bake_once(self, &params, &inputs, &out, ctx)
        })
    }
}

/// The whole `main` of a binary that runs one bake.
pub fn main<B: Bake>(bake: &B) -> ! {
    let tool = B::COMMAND[0];
    let m = matches(tool, top(command(bake), tool));
    bake.run_matches(tool, &m)
}

/// [`main`] with an [`Alternative`] mode.
pub fn main_with<B: Bake>(bake: &B, alt: Alternative<B::Params>) -> ! {
    let tool = B::COMMAND[0];
    let flag = (alt.arg)();
    let id = flag.get_id().clone();
    let cmd = top(command(bake), tool).mut_args(|a| match a.get_id().as_str() {
        "input" | "output" => a
            .required(false)
            .required_unless_present(&id)
            .conflicts_with(&id),
        _ => a,
    });
    let m = matches(tool, cmd.arg(flag));
    match m.get_one::<PathBuf>(id.as_str()) {
        Some(dir) => {
            let (params, common) = parsed::<B>(tool, &m);
            run_body(tool, common, |ctx| (alt.run)(dir, &params, ctx))
        }
        None => bake.run_matches(tool, &m),
    }
}

/// The whole `main` of a binary whose subcommands are bakes (`brdf-lut dfg|as-size-bias|...`).
pub fn main_subcommands(
    tool: &'static str,
    summary: &'static str,
    about: &'static str,
    bakes: &[&dyn Subcommand],
) -> ! {
    let mut cmd = top(clap::Command::new(tool), tool)
        .about(summary)
        .long_about(about)
        .subcommand_required(true)
        .arg_required_else_help(true);
    for b in bakes {
        cmd = cmd.subcommand(b.clap_command());
    }
    let m = matches(tool, cmd);
    let (name, sub) = m.subcommand().expect("a subcommand is required");
    let bake = bakes
        .iter()
        .find(|b| b.clap_command().get_name() == name)
        .expect("clap knows only these subcommands");
    bake.run_matches(tool, sub)
}

/// The binary's top-level command: its name and version.
fn top(cmd: clap::Command, tool: &'static str) -> clap::Command {
    cmd.name(tool).version(ibl_core::TOOL_VERSION)
}

/// Parses the process's arguments as [`crate::parse`] does.
fn matches(tool: &str, cmd: clap::Command) -> clap::ArgMatches {
    crate::exit_quietly_on_closed_stdout();
    negative_values(cmd)
        .try_get_matches_from(std::env::args_os())
        .unwrap_or_else(|e| usage_exit(tool, e))
}

/// The bake's parameters and the common flags from `m`.
fn parsed<B: Bake>(tool: &str, m: &clap::ArgMatches) -> (B::Params, CommonArgs) {
    let params = B::Params::from_arg_matches(m).unwrap_or_else(|e| usage_exit(tool, e));
    let common = CommonArgs::from_arg_matches(m).unwrap_or_else(|e| usage_exit(tool, e));
    (params, common)
}

/// One run as a command line does it: validate, check `-o` and that every output it will
/// write is ours to write (inside `-o`, not a user's file: `ibl_core::ownership`), bake, warn,
/// write (removing what an earlier run left), record what was written, inform.
fn bake_once<B: Bake>(
    bake: &B,
    params: &B::Params,
    inputs: &[PathBuf],
    out: &Path,
    ctx: &Ctx,
) -> Outcome {
    bake.validate(params, out)?;
    let kind = bake.output_kind(params, out);
    // Where first (a system folder is refused as such, before any probe is written there).
    let dir = record_dir(out, kind);
    ownership::check_output_folder(&dir, "-o", kind == OutputKind::Folder)?;
    check_output(out, kind)?;
    let overwrite = ctx.common.overwrite;
    let planned = bake.outputs(params, inputs, out)?;
    ownership::check_writes(&dir, &planned, overwrite)?;
    let baked = bake.run(params, inputs, out, ctx.progress())?;
    // What the bake encoded, checked again (a file `outputs` did not foresee).
    let paths: Vec<PathBuf> = baked.files.iter().map(|f| f.0.clone()).collect();
    ownership::check_writes(&dir, &paths, overwrite)?;
    baked.warnings.into_iter().for_each(|w| ctx.warn(w));
    let outputs = write_outputs(&baked.files)?;
    record_outputs(B::COMMAND[0], &dir, &baked.files)?;
    if let Some(name) = bake.stale_cube(params) {
        stale_cleanup(ctx, &dir, name, &baked.files)?;
    }
    baked.info.iter().for_each(|i| ctx.info(i));
    Ok((outputs, baked.details))
}
