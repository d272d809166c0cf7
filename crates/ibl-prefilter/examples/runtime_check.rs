//! The runtime error of a baked chain recomputed against the brute-force kernel: an independent
//! check of `prefilter.json`'s `runtime` block, whose own reference is the cell tree (the
//! method the bake itself uses, so its errors and the levels' can correlate). Used by
//! `scripts/speed-bench.sh` to compare two builds' chains on one footing, and by
//! `scripts/peer-bench.sh` to measure the peers' chains with ours.
//!
//! `runtime-check SOURCE CHAIN_DIR [DIRECTIONS]` (CHAIN_DIR holds prefilter.json and the faces
//! or `prefilter.ktx2`, which is read when present: a peer's KTX2 can be checked under our
//! sidecar; DIRECTIONS defaults to the report's 128) prints
//! `{"roughness": [...], "mean_abs_rel": [...], "p99_abs_rel": [...]}`. A `--target custom`
//! chain is read through its own lookup: the constants rebuilt from the sidecar's α₀ and the
//! chain's shape, the alpha channel from `prefilter.ktx2`.

use ibl_core::envmap::{load_environment, read_cube_chain, read_cube_chain_alpha};
use ibl_core::equirect::Filter;
use ibl_core::progress::NoProgress;
use ibl_prefilter::custom::{CustomChain, CustomLookup};
use ibl_prefilter::kernel::SourceTexels;
use ibl_prefilter::runtime::{evaluate_custom, evaluate_with, Reference, REPORT_DIRECTIONS};
use ibl_target::Target;
use std::path::Path;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let dirs = match args.get(2).map(|s| s.parse::<usize>()) {
        None => Some(REPORT_DIRECTIONS),
        Some(Ok(n)) if n > 0 => Some(n),
        _ => None,
    };
    let (2 | 3, Some(dirs)) = (args.len(), dirs) else {
        eprintln!("usage: runtime-check SOURCE CHAIN_DIR [DIRECTIONS]");
        std::process::exit(2);
    };
    if let Err(e) = run(Path::new(&args[0]), Path::new(&args[1]), dirs) {
        eprintln!("runtime-check: {e}");
        std::process::exit(1);
    }
}

fn run(source: &Path, chain: &Path, dirs: usize) -> Result<(), Box<dyn std::error::Error>> {
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
    let env = load_environment(source, false)?.env;
    let cube = env.to_cube(src_size, Filter::Area, rotate, &NoProgress);
    let texels = SourceTexels::new(&cube);
    let reference = Reference::Brute {
        texels: &texels,
        source: &cube,
    };
    let report = if target == Target::Custom {
        let file = chain.join("prefilter.ktx2");
        let mips = read_cube_chain(&file)?;
        let alpha = read_cube_chain_alpha(&file)?.ok_or("prefilter.ktx2 has no alpha channel")?;
        let a0 = field("custom_lookup")?["alpha0"]
            .as_f64()
            .ok_or("custom_lookup.alpha0")? as f32;
        let mut lk = CustomLookup::new(a0, mips.levels.len(), mips.levels[0].size);
        lk.power = serde_json::from_value(field("custom_lookup")?["power"].clone())?;
        evaluate_custom(&CustomChain::new(&mips, &alpha), &lk, dirs, &reference)
    } else {
        // The files hold the engine's orientation (Filament's and Unity's differ from ours);
        // the lookup is emulated in our frame.
        let spec = target.spec();
        let ktx2 = chain.join("prefilter.ktx2");
        let file = if ktx2.is_file() {
            ktx2
        } else {
            chain.to_path_buf()
        };
        let mips = spec
            .orientation
            .inverse()
            .apply_mips(&read_cube_chain(&file)?);
        evaluate_with(&mips, target, spec.lod, dirs, &reference)
    };
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
