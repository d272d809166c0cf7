//! `irradiance`: parse, call `ibl_env::irradiance`, write, report.

use clap::Parser;
use ibl_env::irradiance::{run, Params};
use std::path::PathBuf;

/// Diffuse irradiance of an environment: DIR/sh.json (radiance projection and E/π
/// coefficients) and the irradiance cube DIR/px.exr … nz.exr (E/π).
#[derive(Parser)]
#[command(version, about)]
struct Cli {
    /// Input environment: .exr/.hdr equirect or cross, a folder of faces, or a .ktx2 cube.
    input: PathBuf,
    /// Output folder.
    #[arg(short, long)]
    output: PathBuf,
    #[command(flatten)]
    params: Params,
    #[command(flatten)]
    common: ibl_cli::CommonArgs,
}

fn main() {
    let cli = ibl_cli::parse::<Cli>("irradiance");
    ibl_cli::run("irradiance", cli.common.clone(), |ctx| {
        cli.params.validate()?;
        ibl_cli::check_output(&cli.output, ibl_cli::OutputKind::Folder)?;
        let env = ctx.load_environment(&cli.input, cli.params.sanitize)?;
        let baked = run(&cli.params, &env, &cli.output, ctx.progress())?;
        if baked.negative_clamped > 0 {
            ctx.warn(format!(
                "SH ringing: clamped {} negative irradiance values to 0 (try --window or --exact)",
                baked.negative_clamped
            ));
        }
        baked.warnings.iter().for_each(|w| ctx.warn(w.clone()));
        let outputs =
            ibl_cli::write_cube_outputs(ctx, &cli.output, cli.params.cube_name(), &baked.files)?;
        // Two different clamps, named apart: the input's negative texels (the input
        // policy's warning) and the output's negative irradiance (SH ringing).
        Ok::<_, ibl_core::Error>((
            outputs,
            serde_json::json!({
                "coefficients": baked.coefficients,
                "input_negative_clamped": env.report.negative_clamped,
                "ringing_negative_clamped": baked.negative_clamped,
                "encoding": ibl_cli::encoding_details(&baked.encoding),
            }),
        ))
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
