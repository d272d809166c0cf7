//! `prefilter`: parse, call `ibl_prefilter::run`, write atomically, report.

use clap::Parser;
use ibl_prefilter::bake::{run, Params};
use std::path::PathBuf;

/// GGX prefiltered specular mip chain (split-sum radiance term): level l of N holds the
/// environment convolved with the GGX lobe of roughness l/(N−1). Writes DIR/m{l}_{face}.exr
/// (or DIR/prefilter.ktx2 with --layout ktx2) and DIR/prefilter.json.
#[derive(Parser)]
#[command(version, about)]
struct Cli {
    /// Input environment: .exr/.hdr equirect or cross, a folder of faces, or a .ktx2 cube.
    input: PathBuf,
    /// Output folder.
    #[arg(short, long, value_name = "DIR")]
    output: PathBuf,
    #[command(flatten)]
    params: Params,
    #[command(flatten)]
    common: ibl_cli::CommonArgs,
}

fn main() {
    let cli = ibl_cli::parse::<Cli>("prefilter");
    ibl_cli::run("prefilter", cli.common.clone(), |ctx| {
        cli.params.validate()?;
        ibl_cli::check_output(&cli.output, ibl_cli::OutputKind::Folder)?;
        let env = ctx.load_environment(&cli.input, cli.params.sanitize)?;
        let baked = run(&cli.params, &env, &cli.output, ctx.progress())?;
        let outputs =
            ibl_cli::write_cube_outputs(ctx, &cli.output, cli.params.chain_name(), &baked.files)?;
        baked
            .chain
            .warnings
            .iter()
            .for_each(|w| ctx.warn(w.clone()));
        let report = &baked.chain.report;
        if let Some(note) = &report.note {
            ctx.info(note);
        }
        let details = serde_json::json!({
            "report": report,
            "resample_seconds": baked.chain.resample_seconds,
            "source_seconds": baked.chain.source_seconds,
            "estimate_seconds": baked.chain.estimate_seconds,
            "runtime_seconds": baked.chain.runtime_seconds,
            "level_seconds": baked.chain.level_seconds,
            "encoding": ibl_cli::encoding_details(&baked.encoding),
        });
        Ok::<_, ibl_prefilter::Error>((outputs, details))
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
