//! `quat-map`: the command line of the [`ibl_material::QUAT_MAP`] bake, and its `--batch DIR`
//! mode over a folder of materials (`ibl_material::batch`: skips what is up to date, converts
//! the rest, reports per material).

use ibl_material::{batch, quat_map};
use std::path::Path;

fn main() {
    ibl_cli::main_with(
        &ibl_material::QUAT_MAP,
        ibl_cli::Alternative {
            arg: || {
                clap::Arg::new("batch")
                    .long("batch")
                    .value_name("DIR")
                    .value_parser(clap::value_parser!(std::path::PathBuf))
                    .help("Convert every material folder under DIR (material/normal.* → material/quaternion.png)")
            },
            run: run_batch,
        },
    )
}

/// `--batch DIR`: every material folder under `root`, each failure reported, the counts in
/// the summary whether or not one failed.
fn run_batch(root: &Path, params: &quat_map::Params, ctx: &ibl_cli::Ctx) -> ibl_cli::Outcome {
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
        // The same summary as on success (ibl_cli prints none for an error), so scripts read
        // converted / skipped / failed in one place either way.
        if ctx.common.json {
            ctx.print_json_summary(&ibl_cli::Summary {
                tool: "quat-map".into(),
                version: ibl_core::TOOL_VERSION.into(),
                outputs,
                seconds: start.elapsed().as_secs_f64(),
                warnings,
                details,
            });
        }
        return Err(e.into());
    }
    Ok((outputs, details))
}
