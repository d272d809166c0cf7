//! `hv-lut`: parse, call `ibl_lut::hv`, write the LUT and its sidecar atomically, report.

use clap::Parser;
use ibl_lut::hv::{run, Params};
use std::path::PathBuf;

/// The Ashikhmin-Shirley half-vector LUT of Marcolongo 2020 §4.3.2: texel (ξ1, ξ2) at texel
/// centres → h; RGB = h·0.5+0.5 (tangent space), A = p_h(h)/p_h(n). A JSON sidecar next to
/// the image, named after it (-o hv.exr writes hv.json), records n_u, n_v and p_h(n). EXR float by default, PNG 8/16-bit by extension.
#[derive(Parser)]
#[command(version, about)]
struct Cli {
    /// Output image (.exr or .png), or a folder with --thesis-names.
    #[arg(short, long)]
    output: PathBuf,
    #[command(flatten)]
    params: Params,
    #[command(flatten)]
    common: ibl_cli::CommonArgs,
}

fn main() {
    let cli = ibl_cli::parse::<Cli>("hv-lut");
    ibl_cli::run("hv-lut", cli.common.clone(), |ctx| {
        let kind = if cli.params.thesis_names {
            ibl_cli::OutputKind::Folder
        } else {
            ibl_cli::OutputKind::File
        };
        ibl_cli::check_output(&cli.output, kind)?;
        let baked = run(&cli.params, &cli.output, ctx.progress())?;
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
