//! Benchmark of the shipping containers and pixel formats: for every container × format, the
//! bytes of a prefiltered 256² chain (5 and 9 levels) and of a 32² irradiance cube, the encode
//! time, and the error against the float bake (the sidecars' metric).
//! `cargo run --release -p ibl-env --example bench-containers -- [--quick]` → bench/containers.md

use ibl_core::envmap::load_environment;
use ibl_core::io::format::{Bc6hQuality, PixelFormat};
use ibl_core::output::{encode_cube, Encoding, Layout};
use ibl_core::progress::NoProgress;
use ibl_core::CubeMips;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

struct Row {
    asset: String,
    container: &'static str,
    format: PixelFormat,
    bytes: usize,
    seconds: f64,
    mean: f64,
    max: f64,
}

fn main() {
    let quick = std::env::args().any(|a| a == "--quick");
    let env_path = root().join("fixtures/hdri/city_512.exr");
    let env = load_environment(&env_path, false).expect("fixture");
    let size = if quick { 64 } else { 256 };
    let mut assets: Vec<(String, CubeMips)> = Vec::new();
    // 5 and 9 levels (the full chain of 256²; --quick's 64² holds 7).
    let full = ibl_prefilter::bake::max_levels(size);
    for levels in [5usize, 9.min(full)] {
        let p = ibl_prefilter::bake::Params {
            size,
            levels: Some(levels),
            ..Default::default()
        };
        let chain = ibl_prefilter::bake::bake_chain(&p, &env.env, &NoProgress).expect("chain");
        assets.push((format!("chain, {levels} levels"), chain.mips));
    }
    let irr = ibl_env::irradiance::Params {
        size: 32,
        ..Default::default()
    };
    // The irradiance cube as the bake encodes it by default: float EXR faces, decoded exactly.
    let baked =
        ibl_env::irradiance::run(&irr, env, Path::new("."), &NoProgress).expect("irradiance");
    let faces: Vec<ibl_core::Image> = baked
        .files
        .iter()
        .filter(|(p, _)| ibl_core::io::extension(p) == "exr")
        .map(|(p, b)| {
            ibl_core::io::decode_image(p, b, ibl_core::io::ColorSpace::Linear).expect("face")
        })
        .collect();
    let cube = ibl_core::Cubemap::from_faces(faces.try_into().expect("six faces")).expect("cube");
    assets.push(("irradiance 32²".into(), CubeMips { levels: vec![cube] }));

    let mut rows = Vec::new();
    for (asset, mips) in &assets {
        for (container, layout, zstd) in [
            ("KTX2", Layout::Ktx2, None),
            ("KTX2 + zstd 19", Layout::Ktx2, Some(19)),
            ("DDS", Layout::Dds, None),
            ("KTX1", Layout::Ktx1, None),
        ] {
            for format in PixelFormat::ALL {
                let enc = Encoding {
                    layout,
                    format,
                    zstd,
                    bc6h_quality: Bc6hQuality::Basic,
                };
                let t = Instant::now();
                let out = encode_cube(Path::new("."), mips, &enc, "x", &[]).expect("encode");
                let seconds = t.elapsed().as_secs_f64();
                let worst = out.levels.iter().fold((0.0f64, 0.0f64), |(m, x), l| {
                    (m.max(l.mean_rel), x.max(l.max_rel))
                });
                rows.push(Row {
                    asset: asset.clone(),
                    container,
                    format,
                    bytes: out.files.iter().map(|f| f.1.len()).sum(),
                    seconds,
                    mean: worst.0,
                    max: worst.1,
                });
            }
        }
    }

    let mut md = String::new();
    writeln!(
        md,
        "## Containers and pixel formats: bytes, encode time, error\n"
    )
    .unwrap();
    writeln!(md, "Source `fixtures/hdri/city_512.exr`: the default GGX chain at {size}² (5 and 9 levels) and the 3-band SH irradiance cube at 32². Error: against the float bake, per level, {} (the worst level is shown). Time: encoding and framing the whole file on {} thread(s), measurement included (one decode of the result).\n", ibl_core::io::texture::ERROR_METRIC, rayon::current_num_threads()).unwrap();
    writeln!(md, "| asset | container | format | bytes | vs RGBA32F | encode (ms) | worst level: mean rel. error | max rel. error |").unwrap();
    writeln!(md, "|---|---|---|---:|---:|---:|---:|---:|").unwrap();
    for r in &rows {
        let base = rows
            .iter()
            .find(|b| {
                b.asset == r.asset && b.container == "KTX2" && b.format == PixelFormat::Rgba32f
            })
            .map_or(1, |b| b.bytes);
        writeln!(
            md,
            "| {} | {} | {} | {} | {:.3} | {:.1} | {:.2e} | {:.2e} |",
            r.asset,
            r.container,
            r.format.name(),
            r.bytes,
            r.bytes as f64 / base as f64,
            r.seconds * 1e3,
            r.mean,
            r.max
        )
        .unwrap();
    }
    let series = PixelFormat::ALL
        .iter()
        .filter(|f| !f.is_lossless())
        .map(|f| ibl_plot::Series {
            label: f.name().into(),
            points: rows
                .iter()
                .filter(|r| r.format == *f && r.asset == format!("chain, {} levels", 9.min(full)))
                .map(|r| (r.bytes as f64, r.mean))
                .collect(),
            default: None,
        })
        .collect();
    let chart = ibl_plot::Chart {
        title: format!(
            "{size}² {}-level chain: bytes vs worst-level mean relative error (KTX2, KTX2+zstd, DDS, KTX1)",
            9.min(full)
        ),
        x_label: "bytes".into(),
        y_label: "mean relative error".into(),
        series,
        targets: vec![(0.03, "BC6H bound 3%".into())],
    };
    writeln!(md, "\n![bytes against error](containers.svg)\n").unwrap();
    std::fs::create_dir_all(root().join("bench")).unwrap();
    std::fs::write(root().join("bench/containers.md"), md).unwrap();
    std::fs::write(root().join("bench/containers.svg"), chart.to_svg()).unwrap();
    println!("wrote bench/containers.md");
}
