//! `quat-map`: parse, call `ibl_material::quat_map` for one file or `ibl_material::batch` for a
//! folder of materials, write, report.

use clap::Parser;
use ibl_material::{batch, normal, quat_map, MaterialError};
use std::path::PathBuf;

/// Normal map → quaternion map (Marcolongo 2020 §3.4): per texel the unit quaternion
/// q = a + b·i + c·j (no k part) of the shortest rotation from +z to the normal, stored as
/// RGB = (a, b, c)·0.5 + 0.5 (16-bit PNG by default, or EXR).
///
/// Convention: q rotates a vector v as q̄·v·q (conjugate first), so the normal is
/// n' = q̄·(0, 0, 1)·q. A shader decodes (a, b, c) = 2·RGB − 1 and rebuilds the whole perturbed
/// frame: t' = (a²+b²−c², 2bc, 2ac), b' = (2bc, a²−b²+c², −2ab), n' = (−2ac, 2ab, a²−b²−c²).
/// A quaternion library rotates as q·v·q̄ instead (glam's Quat::mul_vec3, three.js
/// applyQuaternion, Eigen): give it the conjugate, e.g. glam Quat::from_xyzw(−b, −c, 0, a);
/// passing (b, c, 0, a) unchanged mirrors the normals (x and y negated).
///
/// With --batch DIR every folder under DIR holding normal.* gets quaternion.png beside it;
/// outputs that are newer than their input and made with the same options are skipped
/// (recorded in a hidden sidecar .quaternion.png.opts).
#[derive(Parser)]
#[command(version, about)]
struct Cli {
    /// Input normal map (.png 8/16-bit, .jpg, .exr), read as linear data.
    #[arg(required_unless_present = "batch", conflicts_with = "batch")]
    input: Option<PathBuf>,
    /// Output quaternion map (.png or .exr).
    #[arg(
        short,
        long,
        required_unless_present = "batch",
        conflicts_with = "batch"
    )]
    output: Option<PathBuf>,
    /// Convert every material folder under DIR (material/normal.* → material/quaternion.png).
    #[arg(long, value_name = "DIR")]
    batch: Option<PathBuf>,
    #[command(flatten)]
    params: quat_map::Params,
    #[command(flatten)]
    common: ibl_cli::CommonArgs,
}

fn main() {
    let cli = ibl_cli::parse::<Cli>("quat-map");
    ibl_cli::run(
        "quat-map",
        cli.common.clone(),
        |ctx| -> Result<_, MaterialError> {
            let params = &cli.params;
            if let Some(root) = &cli.batch {
                let start = std::time::Instant::now();
                let report = batch::run(params, root, ctx.progress())?;
                let mut warnings = Vec::new();
                for c in &report.converted {
                    for w in &c.warnings {
                        ctx.warn(w.clone());
                        warnings.push(w.clone());
                    }
                    if let Some(check) = &c.check {
                        ctx.info(format!("{}: {}", c.output.display(), check.summary()));
                    }
                }
                for f in &report.failed {
                    eprintln!("quat-map: failed: {}", f.error);
                }
                ctx.info(report.summary());
                let outputs: Vec<String> = report
                    .converted
                    .iter()
                    .map(|c| c.output.display().to_string())
                    .collect();
                let details = serde_json::to_value(&report).unwrap_or_default();
                if let Some(e) = report.error() {
                    // The same summary as on success (ibl_cli prints none for an error), so
                    // scripts read converted / skipped / failed in one place either way.
                    if ctx.common.json {
                        let summary = ibl_cli::Summary {
                            tool: "quat-map".into(),
                            version: ibl_core::TOOL_VERSION.into(),
                            outputs,
                            seconds: start.elapsed().as_secs_f64(),
                            warnings,
                            details,
                        };
                        ctx.print_json_summary(&summary);
                    }
                    return Err(e);
                }
                return Ok((outputs, details));
            }
            if !params.batch_fields_are_default() {
                return Err(ibl_core::Error::param(
                    "--input-name, --output-name and --force apply to --batch only",
                )
                .into());
            }
            let (Some(input), Some(output)) = (&cli.input, &cli.output) else {
                return Err(ibl_core::Error::param("give NORMAL -o OUT, or --batch DIR").into());
            };
            params.validate_output(output)?;
            ibl_cli::check_output(output, ibl_cli::OutputKind::File)?;
            let normal = normal::load(input)?;
            let baked = quat_map::run(params, &normal, output, ctx.progress())?;
            baked
                .stats
                .warnings(input)
                .into_iter()
                .for_each(|w| ctx.warn(w));
            ibl_core::io::write_many_atomic(&baked.files)?;
            if let Some(check) = &baked.check {
                if check.within_bounds() {
                    ctx.info(check.summary());
                } else {
                    ctx.warn(format!(
                        "{}: outside the quantisation bound: {}",
                        output.display(),
                        check.summary()
                    ));
                }
            }
            let outputs = baked
                .files
                .iter()
                .map(|f| f.0.display().to_string())
                .collect();
            Ok((
                outputs,
                serde_json::json!({ "stats": baked.stats, "check": baked.check }),
            ))
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
