//! `equirect-to-cube`: parse, call `ibl_env::equirect_to_cube`, write, report.

use clap::Parser;
use ibl_env::equirect_to_cube::{run, Params};
use std::path::PathBuf;

/// Latitude-longitude HDR (or a cross, strip, face folder or KTX2 cube) to an area-filtered
/// cubemap: DIR/px.exr … DIR/nz.exr, or DIR/cube.ktx2 with --layout ktx2.
#[derive(Parser)]
#[command(version, about)]
struct Cli {
    /// Input environment: .exr/.hdr/.png equirect or cross, a folder of faces, or a .ktx2 cube.
    input: PathBuf,
    /// Output folder (or file with --to-equirect).
    #[arg(short, long)]
    output: PathBuf,
    #[command(flatten)]
    params: Params,
    #[command(flatten)]
    common: ibl_cli::CommonArgs,
}

fn main() {
    let cli = ibl_cli::parse::<Cli>("equirect-to-cube");
    ibl_cli::run("equirect-to-cube", cli.common.clone(), |ctx| {
        cli.params.validate()?;
        // --to-equirect writes a file, or DIR/equirect.exr when -o has no extension.
        let kind = if cli.params.to_equirect && cli.output.extension().is_some() {
            ibl_cli::OutputKind::File
        } else {
            ibl_cli::OutputKind::Folder
        };
        ibl_cli::check_output(&cli.output, kind)?;
        let env = ctx.load_environment(&cli.input, cli.params.sanitize)?;
        let baked = run(&cli.params, &env, &cli.output, ctx.progress())?;
        baked.warnings.iter().for_each(|w| ctx.warn(w.clone()));
        let outputs = if cli.params.to_equirect {
            ibl_cli::write_outputs(&baked.files)?
        } else {
            ibl_cli::write_cube_outputs(ctx, &cli.output, cli.params.cube_name(), &baked.files)?
        };
        Ok::<_, ibl_core::Error>((
            outputs,
            serde_json::json!({
                "face_size": baked.face_size,
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
