//! The runtime error of a baked chain recomputed against the brute-force kernel: an independent
//! check of `prefilter.json`'s `runtime` block, whose own reference is the cell tree (the
//! method the bake itself uses, so its errors and the levels' can correlate). Used by
//! `scripts/speed-bench.sh` to compare two builds' chains on one footing.
//!
//! `runtime-check SOURCE CHAIN_DIR` (CHAIN_DIR holds the faces and prefilter.json) prints
//! `{"roughness": [...], "mean_abs_rel": [...], "p99_abs_rel": [...]}`.

use ibl_core::envmap::{load_environment, read_cube_chain};
use ibl_core::equirect::Filter;
use ibl_core::progress::NoProgress;
use ibl_prefilter::kernel::SourceTexels;
use ibl_prefilter::runtime::{evaluate_with, Reference, REPORT_DIRECTIONS};
use ibl_target::Target;
use std::path::Path;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.len() != 2 {
        eprintln!("usage: runtime-check SOURCE CHAIN_DIR");
        std::process::exit(2);
    }
    if let Err(e) = run(Path::new(&args[0]), Path::new(&args[1])) {
        eprintln!("runtime-check: {e}");
        std::process::exit(1);
    }
}

fn run(source: &Path, chain: &Path) -> Result<(), Box<dyn std::error::Error>> {
    let sidecar: serde_json::Value =
        serde_json::from_slice(&std::fs::read(chain.join("prefilter.json"))?)?;
    let field = |k: &str| {
        sidecar
            .get(k)
            .cloned()
            .ok_or_else(|| format!("{}: no `{k}`", chain.display()))
    };
    let target: Target = serde_json::from_value(field("target")?)?;
    let src_size = field("source_size")?.as_u64().ok_or("source_size")? as usize;
    let rotate = field("rotate")?.as_f64().unwrap_or(0.0) as f32;
    if target == Target::Custom {
        return Err("the custom target's lookup constants are not read here".into());
    }
    let env = load_environment(source, false)?.env;
    let cube = env.to_cube(src_size, Filter::Area, rotate, &NoProgress);
    let texels = SourceTexels::new(&cube);
    let mips = read_cube_chain(chain)?;
    let reference = Reference::Brute {
        texels: &texels,
        source: &cube,
    };
    let report = evaluate_with(
        &mips,
        target,
        target.spec().lod,
        REPORT_DIRECTIONS,
        &reference,
    );
    println!(
        "{}",
        serde_json::json!({
            "roughness": report.roughness,
            "mean_abs_rel": report.mean_abs_rel,
            "p99_abs_rel": report.p99_abs_rel,
            "reference": report.reference,
        })
    );
    Ok(())
}
