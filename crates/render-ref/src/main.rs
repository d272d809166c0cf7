//! `render-ref`: parse, call `ibl_render`, write atomically, report. Three modes: the
//! reference render of an environment (PFM, optional PNG), the orientation panorama, and the
//! orientation check of a render; plus the contract's comparison of two renders.

use clap::Parser;
use ibl_core::io::{self, WriteOptions};
use ibl_core::Error;
use ibl_render::{orientation, pfm, Engine};
use std::path::{Path, PathBuf};

/// The CPU reference render of the scene "sphere-rows v1" (768×256, two rows of six spheres,
/// roughness 0…1, metallic above, dielectric below): every pixel the engine's split sum with
/// the exact GGX-prefiltered radiance and irradiance of the source, written as PFM (rows bottom
/// first). Also writes the orientation panorama, checks a render of it, and compares renders.
#[derive(Parser)]
#[command(version, about)]
struct Cli {
    /// The environment to render (equirect, cross, face folder or KTX2 cube).
    env: Option<PathBuf>,
    /// Output: the render (.pfm), or the panorama (.exr, .hdr or .pfm) with
    /// --orientation-panorama.
    #[arg(short, long)]
    output: Option<PathBuf>,
    /// Whose BRDF terms (DFG table or fit, diffuse modifiers) the render uses.
    #[arg(long, value_enum, default_value_t = Engine::Gltf)]
    engine: Engine,
    /// Render every engine's BRDF terms in one run (the lighting is evaluated once): -o
    /// city.pfm writes city-gltf.pfm, city-three.pfm, … city-exact.pfm.
    #[arg(long)]
    all_engines: bool,
    /// Also write a tone-mapped PNG of the render (ACES, sRGB; exposure from the spheres), of
    /// --engine's with --all-engines.
    #[arg(long, value_name = "PNG")]
    png: Option<PathBuf>,
    /// Probe pixels per sphere at which the reference is checked against the brute-force sum
    /// over every source texel (0: no estimate).
    #[arg(long, default_value_t = 24, value_name = "N")]
    probes: usize,
    /// Write the orientation panorama (coloured patches on ±X ±Y ±Z, a chirality mark) to -o.
    #[arg(long)]
    orientation_panorama: bool,
    /// Width of the panorama (height = width/2).
    #[arg(long, default_value_t = 512, value_name = "W")]
    width: usize,
    /// Check a render (PFM or EXR) of the orientation panorama: which patch the mirror sphere
    /// shows where it reflects ±X, ±Y, +Z, and the flip or turn that explains it.
    #[arg(long, value_name = "IMAGE")]
    check_orientation: Option<PathBuf>,
    /// Compare a render (PFM) with --reference: per sphere mean and 95th percentile relative
    /// error of luminance over the contract's mask.
    #[arg(long, value_name = "RENDER", requires = "reference")]
    compare: Option<PathBuf>,
    /// The reference render --compare is measured against (PFM).
    #[arg(long, value_name = "REF", requires = "compare")]
    reference: Option<PathBuf>,
    /// Set NaN/Inf input texels to 0 instead of refusing the input.
    #[arg(long)]
    sanitize: bool,
    #[command(flatten)]
    common: ibl_cli::CommonArgs,
}

/// Reads a render: PFM by our reader, anything else by the core's image reader.
fn read_render(path: &Path) -> Result<ibl_core::Image, Error> {
    if io::extension(path) == "pfm" {
        pfm::read(path)
    } else {
        io::read_image(path, io::ColorSpace::Linear)
    }
}

fn main() {
    let cli = ibl_cli::parse::<Cli>("render-ref");
    ibl_cli::run("render-ref", cli.common.clone(), |ctx| {
        let modes = [
            cli.env.is_some(),
            cli.orientation_panorama,
            cli.check_orientation.is_some(),
            cli.compare.is_some(),
        ];
        if modes.iter().filter(|&&m| m).count() != 1 {
            return Err(Error::param(
                "give exactly one of: ENV -o OUT.pfm, --orientation-panorama -o PANO.exr, --check-orientation IMAGE, --compare RENDER --reference REF",
            ));
        }
        if let Some(path) = &cli.check_orientation {
            let img = read_render(path)?;
            let report = orientation::check(&img).map_err(|e| Error::invalid(path, e))?;
            ctx.info(format!("{}: {}", path.display(), report.verdict));
            return Ok((
                Vec::new(),
                serde_json::to_value(&report).unwrap_or_default(),
            ));
        }
        if let (Some(a), Some(b)) = (&cli.compare, &cli.reference) {
            let (x, y) = (read_render(a)?, read_render(b)?);
            let c = ibl_render::compare::compare(&x, &y).map_err(|e| Error::invalid(a, e))?;
            ctx.info(format!(
                "{}: mean relative error metal mirror {:.4}, metal rough {:.4}, dielectric mirror {:.4}, dielectric rough {:.4}",
                a.display(),
                c.metal_mirror,
                c.metal_rough,
                c.dielectric_mirror,
                c.dielectric_rough
            ));
            return Ok((Vec::new(), serde_json::to_value(&c).unwrap_or_default()));
        }
        let out = cli
            .output
            .as_ref()
            .ok_or_else(|| Error::param("-o OUT is required"))?;
        ibl_cli::check_output(out, ibl_cli::OutputKind::File)?;
        if cli.orientation_panorama {
            if !(16..=16384).contains(&cli.width) || !cli.width.is_multiple_of(2) {
                return Err(Error::param(format!(
                    "--width {} must be even and within 16..=16384",
                    cli.width
                )));
            }
            let img = orientation::panorama(cli.width);
            let bytes = match io::extension(out).as_str() {
                "pfm" => pfm::encode(&img),
                "exr" | "hdr" => io::encode_image(out, &img, &WriteOptions::default())?,
                _ => {
                    return Err(Error::param(format!(
                        "-o {} must be .exr, .hdr or .pfm",
                        out.display()
                    )))
                }
            };
            io::write_atomic(out, &bytes)?;
            return Ok((
                vec![out.display().to_string()],
                serde_json::json!({"width": img.width, "height": img.height,
                    "patches": orientation::PATCHES.iter().map(|p| serde_json::json!({"axis": p.1, "rgb": p.2})).collect::<Vec<_>>(),
                    "patch_radius_deg": orientation::PATCH_RADIUS_DEG}),
            ));
        }
        if io::extension(out) != "pfm" {
            return Err(Error::param(format!("-o {} must be a .pfm", out.display())));
        }
        if let Some(png) = &cli.png {
            if io::extension(png) != "png" {
                return Err(Error::param(format!(
                    "--png {} must be a .png",
                    png.display()
                )));
            }
            ibl_cli::check_output(png, ibl_cli::OutputKind::File)?;
        }
        if cli.probes > 4096 {
            return Err(Error::param("--probes must be at most 4096"));
        }
        let input = cli.env.as_ref().expect("checked above");
        let env = ctx.load_environment(input, cli.sanitize)?;
        let t0 = std::time::Instant::now();
        let lighting = ibl_render::Lighting::new(&env.env, ctx.progress());
        let prepare = t0.elapsed().as_secs_f64();
        let t1 = std::time::Instant::now();
        let engines: Vec<Engine> = if cli.all_engines {
            Engine::ALL.to_vec()
        } else {
            vec![cli.engine]
        };
        let images = ibl_render::render_engines(
            &lighting,
            &engines,
            &ibl_render::ALL_SPHERES,
            1,
            ctx.progress(),
        );
        let shown = engines.iter().position(|&e| e == cli.engine).unwrap_or(0);
        let img = &images[shown];
        let render_seconds = t1.elapsed().as_secs_f64();
        let t2 = std::time::Instant::now();
        let estimate = (cli.probes > 0).then(|| {
            let brute = ibl_render::lighting::BruteForce::new(&env.env);
            lighting.estimate(&brute, cli.probes)
        });
        let estimate_seconds = t2.elapsed().as_secs_f64();
        let mut files: Vec<(PathBuf, Vec<u8>)> = if cli.all_engines {
            let stem = out.file_stem().and_then(|s| s.to_str()).unwrap_or("render");
            engines
                .iter()
                .zip(&images)
                .map(|(e, im)| {
                    (
                        out.with_file_name(format!("{stem}-{}.pfm", e.name())),
                        pfm::encode(im),
                    )
                })
                .collect()
        } else {
            vec![(out.clone(), pfm::encode(img))]
        };
        if let Some(png) = &cli.png {
            let scale = ibl_preview::tonemap::exposure_scale(
                ibl_preview::tonemap::image_log_average(img),
                0.0,
            );
            let shown = ibl_preview::tonemap::display_image(img, scale);
            let opts = WriteOptions {
                png_bits: 8,
                ..WriteOptions::default()
            };
            files.push((png.clone(), io::encode_image(png, &shown, &opts)?));
        }
        let outputs = ibl_cli::write_outputs(&files)?;
        let worst = |f: fn(&ibl_render::lighting::Estimate) -> f64| {
            estimate
                .as_ref()
                .map(|e| e.iter().map(f).fold(0.0f64, f64::max))
        };
        let worst_spec = worst(|e| e.specular_mean_rel);
        let worst_irr = worst(|e| e.irradiance_mean_rel.unwrap_or(0.0));
        if let (Some(s), Some(i)) = (worst_spec, worst_irr) {
            ctx.info(format!(
                "reference error against the brute force over every source texel: specular worst sphere mean {:.4}%, irradiance {:.4}%",
                100.0 * s,
                100.0 * i
            ));
        }
        Ok((
            outputs,
            serde_json::json!({
                "scene": "sphere-rows v1",
                "engine": cli.engine.name(),
                "brdf_source": cli.engine.source(),
                "engines": engines.iter().map(|e| serde_json::json!({"engine": e.name(), "brdf_source": e.source()})).collect::<Vec<_>>(),
                "width": img.width,
                "height": img.height,
                "tree_face_size": lighting.tree_size(),
                "irradiance_face_size": ibl_render::lighting::IRRADIANCE_SIZE,
                "seconds": {"prepare": prepare, "render": render_seconds, "estimate": estimate_seconds},
                "estimated_error": estimate,
                "worst_specular_mean_rel": worst_spec,
                "worst_irradiance_mean_rel": worst_irr,
            }),
        ))
    })
}
