//! `contact-sheet`: parse, read the baked outputs, lay them out with `ibl_preview`, write
//! the PNG atomically (only over a sheet it wrote: `ibl_core::ownership`), report.

use clap::Parser;
use ibl_core::io::{self, OutputKind, WriteOptions};
use ibl_core::{ownership, Error};
use std::path::PathBuf;

/// A labelled PNG contact sheet of baked outputs: the environment cube as a horizontal cross,
/// every prefiltered level (with its roughness), the irradiance cube and the DFG LUT, tone
/// mapped with one exposure taken from the environment.
#[derive(Parser)]
#[command(version, about)]
struct Cli {
    /// Baked outputs: a pipeline's output folder (e.g. out/probe), a bake's folder, a
    /// .ktx2/.ktx/.dds cube or a LUT image.
    #[arg(required = true)]
    inputs: Vec<PathBuf>,
    /// The sheet (.png). An existing file is replaced only if contact-sheet wrote it, bytes
    /// unchanged (the `.ibl-outputs.json` beside it records it), or with `--overwrite`.
    #[arg(short, long)]
    output: PathBuf,
    /// Exposure in stops on top of the automatic one (log-average luminance → 0.18).
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    exposure: f32,
    /// Height in pixels of every tile.
    #[arg(long, default_value_t = 192)]
    height: usize,
    /// Leave out the sphere rows (the probe on the scene's spheres as glTF reads the baked
    /// chain, beside the reference render).
    #[arg(long)]
    no_spheres: bool,
    #[command(flatten)]
    common: ibl_cli::CommonArgs,
}

fn main() {
    let cli = ibl_cli::parse::<Cli>("contact-sheet");
    ibl_cli::run("contact-sheet", cli.common.clone(), |ctx| {
        if io::extension(&cli.output) != "png" {
            return Err(Error::param(format!(
                "--output {} must be a .png",
                cli.output.display()
            )));
        }
        if !cli.exposure.is_finite() || cli.exposure.abs() > 30.0 {
            return Err(Error::param("--exposure must be within ±30 stops"));
        }
        if !(16..=2048).contains(&cli.height) {
            return Err(Error::param("--height must be within 16..=2048"));
        }
        // Before any work: the sheet's folder is a place for outputs, and the sheet is ours to
        // replace (absent, or written by us with its bytes unchanged) unless --overwrite.
        let dir = ibl_cli::record_dir(&cli.output, OutputKind::File);
        ownership::check_output_folder(&dir, "-o", false)?;
        io::check_output(&cli.output, OutputKind::File)?;
        ownership::check_writes(
            &dir,
            std::slice::from_ref(&cli.output),
            cli.common.overwrite,
        )?;
        let mut assets = Vec::new();
        for input in &cli.inputs {
            assets.extend(ibl_preview::assets::discover(input)?);
        }
        let exposure = ibl_preview::sheet::exposure_for(&assets, cli.exposure);
        let mut rows = ibl_preview::sheet::rows(&assets, exposure, cli.height);
        let mut spheres = None;
        if !cli.no_spheres {
            if let Some((r, c)) =
                ibl_preview::sheet::sphere_rows(&assets, exposure, cli.height, ctx.progress())
            {
                rows.extend(r);
                spheres = Some(c);
            }
        }
        let footer = format!(
            "ACES tone map, sRGB; exposure {:+.1} EV: log-average luminance {:.3} -> 0.18; LUT as stored",
            cli.exposure, exposure.mean_luminance
        );
        let sheet = ibl_preview::sheet::compose(&rows, &footer);
        let opts = WriteOptions {
            png_bits: 8,
            ..WriteOptions::default()
        };
        let bytes = io::encode_image(&cli.output, &sheet, &opts)?;
        io::write_atomic(&cli.output, &bytes)?;
        ibl_cli::record_outputs("contact-sheet", &dir, &[(cli.output.clone(), bytes)])?;
        Ok::<_, Error>((
            vec![cli.output.display().to_string()],
            serde_json::json!({
                "width": sheet.width,
                "height": sheet.height,
                "rows": rows.iter().map(|r| serde_json::json!({
                    "title": r.title,
                    "tiles": r.tiles.iter().map(|t| &t.caption).collect::<Vec<_>>(),
                })).collect::<Vec<_>>(),
                "mean_luminance": exposure.mean_luminance,
                "spheres": spheres,
                "exposure_scale": exposure.scale,
            }),
        ))
    })
}
