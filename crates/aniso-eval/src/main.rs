//! `aniso-eval`: anisotropic GGX spheres under an environment — a Monte Carlo ground truth
//! with its error, and the runtime methods reading our baked chain (isotropic split-sum, bent
//! normals, major-axis sampling, VNDF filtered importance sampling) — with per-pixel errors,
//! win shares, taps per pixel, EXR/PNG outputs and a markdown/JSON report.

use clap::Parser;
use ibl_aniso::eval::{self, Env, Params};
use ibl_core::equirect::Filter;
use std::path::PathBuf;

/// Renders anisotropic GGX spheres (r × η × views) under each environment: the Monte Carlo
/// ground truth (visible-normal sampling over the environment at its own resolution, with its
/// standard error) and every method of --methods, each reading the prefiltered chain through
/// the target engine's lookup and through the exact kernel (the oracle), so the method's error
/// and the chain's are reported apart. Writes OUT/report.md, OUT/report.json and one folder per
/// case with the frames, the truth and each method's radiance as EXR, and a montage PNG.
#[derive(Parser)]
#[command(version, about)]
struct Cli {
    /// Input environments (.exr/.hdr equirect or cross, face folders, .ktx2/.ktx/.dds cubes).
    #[arg(required_unless_present = "emit_shader")]
    inputs: Vec<PathBuf>,
    /// Write the shipped methods into this folder and exit: anisotropic GGX (VNDF filtered
    /// importance sampling, 16 taps, blended into the engine's isotropic split sum as the
    /// anisotropy vanishes) as aniso_fis.glsl, .hlsl, .wgsl, the same constants and steps as
    /// the evaluator's fisb-16; Ashikhmin–Shirley (the `hv-lut` table read on a grid of
    /// equal-mass cells shaped to the lobe, ≤ 32 taps) as aniso_as.glsl, .hlsl, .wgsl, the
    /// evaluator's as-grid-32.
    #[arg(long, value_name = "DIR", conflicts_with = "inputs")]
    emit_shader: Option<PathBuf>,
    /// Prefiltered chain (a folder of m{l}_<face> images or a .ktx2/.ktx/.dds) written by `prefilter`
    /// for --target (one environment only); default: bake one at --chain-size.
    #[arg(long)]
    prefiltered: Option<PathBuf>,
    /// Output folder.
    #[arg(long, default_value = "report")]
    out: PathBuf,
    #[command(flatten)]
    params: Params,
    #[command(flatten)]
    common: ibl_cli::CommonArgs,
}

fn main() {
    let cli = ibl_cli::parse::<Cli>("aniso-eval");
    ibl_cli::run("aniso-eval", cli.common.clone(), |ctx| {
        if let Some(dir) = &cli.emit_shader {
            ibl_cli::check_output(dir, ibl_cli::OutputKind::Folder)?;
            let files: Vec<(PathBuf, Vec<u8>)> = ibl_aniso::ship::Lang::ALL
                .iter()
                .flat_map(|(lang, ext)| {
                    [
                        (
                            dir.join(format!("aniso_fis.{ext}")),
                            ibl_aniso::ship::emit(*lang).into_bytes(),
                        ),
                        (
                            dir.join(format!("aniso_as.{ext}")),
                            ibl_aniso::ship_as::emit(*lang).into_bytes(),
                        ),
                    ]
                })
                .collect();
            let outputs = ibl_cli::write_outputs(&files)?;
            let details = serde_json::json!({
                "shipped": ibl_aniso::ship::SHIPPED,
                "shipped_as": {
                    "taps": ibl_aniso::ship_as::SHIPPED_AS.taps,
                    "lod_bias": ibl_aniso::ship_as::SHIPPED_AS.lod_bias,
                },
            });
            return Ok::<_, ibl_aniso::Error>((outputs, details));
        }
        let (methods, preset) = cli.params.validate()?;
        if cli.inputs.len() > 1 && cli.prefiltered.is_some() {
            return Err(ibl_aniso::Error::Core(ibl_core::Error::param(
                "--prefiltered applies to a single environment",
            )));
        }
        ibl_cli::check_output(&cli.out, ibl_cli::OutputKind::Folder)?;
        let chain = match &cli.prefiltered {
            Some(p) => Some(ibl_core::envmap::read_cube_chain(p)?),
            None => None,
        };
        // Load every input first: a bad file fails before any work.
        let mut loaded = Vec::new();
        for input in &cli.inputs {
            loaded.push(ctx.load_environment(input, cli.params.sanitize)?);
        }
        let mut all_cases = Vec::new();
        let mut all_images = Vec::new();
        let mut sources = Vec::new();
        let mut cubes = Vec::new();
        for (input, env) in cli.inputs.iter().zip(&loaded) {
            let name = input
                .file_stem()
                .and_then(|s| s.to_str())
                .unwrap_or("env")
                .to_string();
            let size = cli.params.size.unwrap_or(env.env.natural_face_size());
            let cube = env.env.to_cube(size, Filter::Area, 0.0, ctx.progress());
            let (mips, source) = match &chain {
                Some(m) => (
                    m.clone(),
                    format!(
                        "{}: {} ({} levels), read by the {} lookup",
                        name,
                        cli.prefiltered.as_ref().unwrap().display(),
                        m.levels.len(),
                        cli.params.target.name()
                    ),
                ),
                None => {
                    let chain_size = cli.params.chain_size.unwrap_or(size.clamp(8, 256));
                    let p = ibl_prefilter::Params {
                        size: chain_size,
                        target: cli.params.target,
                        ..Default::default()
                    };
                    let baked = ibl_prefilter::bake::bake_chain(&p, &env.env, ctx.progress())
                        .map_err(|e| ibl_core::Error::param(format!("prefilter: {e}")))?;
                    let n = baked.mips.levels.len();
                    (
                        baked.mips,
                        format!(
                            "{name}: prefilter --target {} --size {} ({n} levels, fitted to the lookup), truth cube {size}²",
                            cli.params.target.name(),
                            chain_size
                        ),
                    )
                }
            };
            let e = Env::new(name.clone(), cube, &mips, source.clone(), &cli.params);
            let t0 = std::time::Instant::now();
            let (cases, images) = eval::evaluate(&e, &cli.params, &methods, &preset);
            ctx.info(format!(
                "{name}: {} cases in {:.1} s",
                cases.len(),
                t0.elapsed().as_secs_f64()
            ));
            sources.push(source);
            cubes.push((name.clone(), e.cube));
            all_cases.extend(cases);
            all_images.extend(images);
        }
        let summary = eval::summarize(&all_cases);
        let files = eval::encode_outputs(
            &cli.out,
            &cli.params,
            &all_cases,
            &all_images,
            &summary,
            &sources,
            &cubes
                .iter()
                .map(|(n, c)| (n.clone(), c))
                .collect::<Vec<_>>(),
        )?;
        let outputs = ibl_cli::write_outputs(&files)?;
        if !cli.common.quiet && !cli.common.json {
            print!("{}", eval::markdown(&all_cases, &summary, &sources));
        }
        let details = serde_json::json!({
            "cases": all_cases.len(),
            "scored": all_cases.iter().filter(|c| c.scored).count(),
            "summary": summary,
        });
        Ok::<_, ibl_aniso::Error>((outputs, details))
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
