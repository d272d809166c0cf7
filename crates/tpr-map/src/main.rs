//! `tpr-map`: parse, call `ibl_material::tpr_map`, write, report.

use clap::Parser;
use ibl_material::{tpr_map, MaterialError};
use std::path::PathBuf;

/// Tangent-plane rotation map (Marcolongo 2020 §3.5): RGBA with RG = the rotated tangent
/// (x, y)·0.5 + 0.5 in tangent space (b = n × t) and BA = perceptual roughness along t and b
/// (α = r²; --store-alpha stores α). Directions come from a preset, an angle/direction map
/// or expressions in u, v (texel centres (i+0.5)/W, (j+0.5)/H, row 0 first); zero-length or
/// non-finite ones become +x and are counted.
///
/// Examples: tpr-map -o pan.png --size 1024 --preset radial:0.5,0.5 --roughness 0.2,0.6;
/// tpr-map -o wave.png --size 512 --expr "x = cos(pi*v); y = sin(pi*v)".
#[derive(Parser)]
#[command(version, about)]
struct Cli {
    /// Output map (.png or .exr).
    #[arg(short, long)]
    output: PathBuf,
    #[command(flatten)]
    params: tpr_map::Params,
    #[command(flatten)]
    common: ibl_cli::CommonArgs,
}

fn main() {
    let cli = ibl_cli::parse::<Cli>("tpr-map");
    ibl_cli::run(
        "tpr-map",
        cli.common.clone(),
        |ctx| -> Result<_, MaterialError> {
            cli.params.validate_output(&cli.output)?;
            ibl_cli::check_output(&cli.output, ibl_cli::OutputKind::File)?;
            cli.params.compile()?;
            let inputs = tpr_map::load_inputs(&cli.params)?;
            let baked = tpr_map::run(&cli.params, &inputs, &cli.output, ctx.progress())?;
            baked.stats.warnings().into_iter().for_each(|w| ctx.warn(w));
            ibl_core::io::write_many_atomic(&baked.files)?;
            let outputs = baked
                .files
                .iter()
                .map(|f| f.0.display().to_string())
                .collect();
            Ok((outputs, serde_json::json!({ "stats": baked.stats })))
        },
    )
}

#[cfg(test)]
mod tests {
    #[test]
    fn help_has_no_rustdoc_links_or_file_citations() {
        let problems = ibl_cli::help_problems(<super::Cli as clap::CommandFactory>::command());
        assert!(problems.is_empty(), "{problems:#?}");
    }
}
