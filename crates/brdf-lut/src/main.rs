//! `brdf-lut`: parse, call the `ibl_lut` bake, write atomically, report.

use clap::{Args, Parser, Subcommand};
use ibl_lut::{as_size_bias, dfg, fresnel_tail};
use std::path::PathBuf;

/// BRDF lookup tables at texel centres (docs/CONVENTIONS.md): the split-sum DFG table, the
/// Ashikhmin-Shirley size/bias table, and the Fresnel-tail table of the SH-exponential
/// probes. The output format follows the extension: .exr (float), .png (16-bit), .json/.ron.
#[derive(Parser)]
#[command(version, about)]
struct Cli {
    #[command(subcommand)]
    table: Table,
}

#[derive(Subcommand)]
enum Table {
    /// Split-sum DFG (Karis 2013): R = A, G = B, specular = F0·A + B; with --multiscatter a
    /// third channel B(lue) = E_ss = A + B.
    ///
    /// Axes: column s = n·v, row t = perceptual roughness r, both at texel centres
    /// ((i + 0.5)/N), row 0 (r ≈ 0) stored first. BRDF: GGX with α = r², masking-shadowing by
    /// the height-correlated Smith G2 (Heitz 2014), V = G2/(4 n·v n·l).
    Dfg(Bake<dfg::Params>),
    /// Ashikhmin-Shirley size/bias (Marcolongo 2020 §4.3.3): s = (2/π)atan(|b·v|/|t·v|),
    /// t = √(n·v); R = size, G = bias.
    AsSizeBias(Bake<as_size_bias::Params>),
    /// Fresnel tail (Silvennoinen et al. 2025 eq. 15): s = n·v, t = roughness; R = ∫f_DV(1−v·h)⁵(n·l)dl,
    /// G = R / ∫f_DV(n·l)dl.
    FresnelTail(Bake<fresnel_tail::Params>),
}

#[derive(Args)]
struct Bake<P: Args> {
    /// Output file (.exr, .png, .json or .ron); for as-size-bias with --thesis-names, a
    /// folder.
    #[arg(short, long)]
    output: PathBuf,
    #[command(flatten)]
    params: P,
    #[command(flatten)]
    common: ibl_cli::CommonArgs,
}

/// A bake waiting for the CLI context (thread pool, progress).
type Job = Box<dyn FnOnce(&ibl_cli::Ctx) -> ibl_lut::Result<ibl_lut::Baked>>;

fn main() {
    let cli = ibl_cli::parse::<Cli>("brdf-lut");
    let file = ibl_cli::OutputKind::File;
    let (common, run): (ibl_cli::CommonArgs, Job) = match cli.table {
        Table::Dfg(b) => (
            b.common,
            Box::new(move |ctx| {
                ibl_cli::check_output(&b.output, file)?;
                dfg::run(&b.params, &b.output, ctx.progress())
            }),
        ),
        Table::AsSizeBias(b) => (
            b.common,
            Box::new(move |ctx| {
                let kind = if b.params.thesis_names {
                    ibl_cli::OutputKind::Folder
                } else {
                    file
                };
                ibl_cli::check_output(&b.output, kind)?;
                as_size_bias::run(&b.params, &b.output, ctx.progress())
            }),
        ),
        Table::FresnelTail(b) => (
            b.common,
            Box::new(move |ctx| {
                ibl_cli::check_output(&b.output, file)?;
                fresnel_tail::run(&b.params, &b.output, ctx.progress())
            }),
        ),
    };
    ibl_cli::run("brdf-lut", common.clone(), |ctx| {
        let baked = run(ctx)?;
        let outputs = ibl_cli::write_outputs(&baked.files)?;
        Ok::<_, ibl_lut::Error>((outputs, baked.details))
    })
}

#[cfg(test)]
mod tests {
    #[test]
    fn help_has_no_rustdoc_links_or_file_citations() {
        let problems = ibl_cli::help_problems(<super::Cli as clap::CommandFactory>::command());
        assert!(problems.is_empty(), "{problems:#?}");
    }
}
