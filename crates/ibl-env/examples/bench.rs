//! Benchmark of the foundation bakes: equirect → cube (area vs bilinear, time against error
//! to a dense reference), SH projection and the exact irradiance convolution, with the work
//! counted and throughput set beside the memory-bandwidth bound.
//! `cargo run --release -p ibl-env --example bench-ibl-env -- [--quick]` → bench/foundation.md

use ibl_core::cube::Face;
use ibl_core::equirect::{self, Filter};
use ibl_core::io::{self, ColorSpace};
use ibl_core::progress::NoProgress;
use ibl_core::{Cubemap, Image};
use ibl_env::irradiance;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// Median wall time of `runs` calls.
fn time<T>(runs: usize, mut f: impl FnMut() -> T) -> (f64, T) {
    let mut times = Vec::new();
    let mut last = None;
    for _ in 0..runs {
        let t = Instant::now();
        last = Some(f());
        times.push(t.elapsed().as_secs_f64());
    }
    times.sort_by(|a, b| a.partial_cmp(b).unwrap());
    (times[times.len() / 2], last.unwrap())
}

/// Streaming read bandwidth in bytes/s (sum over a 256 MiB buffer, both cores).
fn memory_bandwidth() -> f64 {
    use rayon::prelude::*;
    let buf = vec![1.0f32; 64 << 20];
    let (t, s) = time(5, || {
        buf.par_chunks(1 << 16)
            .map(|c| c.iter().sum::<f32>())
            .sum::<f32>()
    });
    assert!(s > 0.0);
    (buf.len() * 4) as f64 / t
}

fn load_source(quick: bool) -> (String, Image) {
    // A full-size source (e.g. city.exr of Debian's blender-data) when IBL_BENCH_HDRI names
    // one; the repository's own fixture otherwise.
    let full = std::env::var_os("IBL_BENCH_HDRI").map(std::path::PathBuf::from);
    let path = if let Some(full) = full.filter(|f| f.exists() && !quick) {
        full
    } else {
        root().join("fixtures/hdri/city_512.exr")
    };
    let mut img = io::read_image(&path, ColorSpace::Linear).expect("fixture");
    ibl_core::image::check_texels(&mut img, &path, false).expect("finite");
    (path.display().to_string(), img)
}

/// Nearest-neighbour 2× upscale (to make the 2048×1024 case from a 1024×512 fixture).
fn upscale2(img: &Image) -> Image {
    let mut out = Image::new(img.width * 2, img.height * 2, 3);
    for j in 0..out.height {
        for i in 0..out.width {
            out.texel_mut(i, j).copy_from_slice(&img.rgb(i / 2, j / 2));
        }
    }
    out
}

/// (mean over texels of |x − ref| / ref on luminance, Σ|x − ref| / Σ ref): the first is what
/// a viewer sees, the second is dominated by the sun's texels.
fn rel_errors(cube: &Cubemap, src: &Image) -> (f64, f64) {
    let n = cube.size;
    let (mut per_texel, mut count, mut num, mut den) = (0.0, 0, 0.0, 0.0);
    let stride = (n / 24).max(1);
    for face in Face::ALL {
        for j in (0..n).step_by(stride) {
            for i in (0..n).step_by(stride) {
                let r = equirect::dense_footprint_mean(src, face, i, j, n, 48);
                let g = cube.texel(face, i, j);
                let lr = 0.2126 * r[0] + 0.7152 * r[1] + 0.0722 * r[2];
                let lg = ibl_core::luminance(g) as f64;
                if lr > 0.0 {
                    per_texel += (lg - lr).abs() / lr;
                    count += 1;
                }
                num += (lg - lr).abs();
                den += lr;
            }
        }
    }
    (per_texel / count as f64, num / den)
}

/// Relative error of the cube's mean radiance (luminance) against the source's.
fn energy_error(cube: &Cubemap, src: &Image) -> f64 {
    let mut e = 0.0f64;
    for j in 0..src.height {
        let sa = equirect::row_solid_angle(j, src.width, src.height);
        for i in 0..src.width {
            e += ibl_core::luminance(src.rgb(i, j)) as f64 * sa;
        }
    }
    let m = cube.mean_radiance();
    let c = 0.2126 * m[0] + 0.7152 * m[1] + 0.0722 * m[2];
    c / (e / (4.0 * std::f64::consts::PI)) - 1.0
}

fn main() {
    let quick = std::env::args().any(|a| a == "--quick");
    let runs = if quick { 1 } else { 5 };
    let bw = memory_bandwidth();
    let (src_name, src) = load_source(quick);
    let mut md = String::new();
    writeln!(
        md,
        "## Foundation: equirect → cube, SH projection, exact irradiance\n"
    )
    .unwrap();
    writeln!(md, "Source `{src_name}` ({}×{}); measured streaming read bandwidth {:.1} GB/s; {} thread(s).\n", src.width, src.height, bw / 1e9, rayon::current_num_threads()).unwrap();

    writeln!(md, "### equirect → cube: time against error\n").unwrap();
    writeln!(md, "Errors on luminance against a 48×48-grid area reference (whose own error is about 0.1–0.2%): mean over texels of the relative error, and Σ|error| / Σ reference (dominated by the sun's texels); energy: the cube's mean radiance against the source's.\n").unwrap();
    writeln!(md, "| source | face | filter | time (ms) | Mtexel/s | bandwidth bound (Mtexel/s) | mean rel. error | Σ-relative error | energy error | output MiB (RGB32F) |").unwrap();
    writeln!(md, "|---|---|---|---|---|---|---|---|---|---|").unwrap();
    let big = if quick { src.clone() } else { upscale2(&src) };
    let mut chart_points: Vec<(Filter, usize, f64, f64)> = Vec::new();
    let cases: Vec<(&Image, usize)> = if quick {
        vec![(&src, 64), (&src, 128)]
    } else {
        vec![(&src, 128), (&src, 256), (&big, 512)]
    };
    for (img, n) in cases {
        for filter in [Filter::Area, Filter::Bilinear] {
            let (t, cube) = time(runs, || {
                equirect::equirect_to_cube(img, n, filter, 0.0, &NoProgress)
            });
            let err = if n <= 256 {
                let (a, b) = rel_errors(&cube, img);
                chart_points.push((filter, n, t, a));
                format!("{a:.4} | {b:.4}")
            } else {
                "— | —".into()
            };
            let energy = energy_error(&cube, img);
            let texels = 6 * n * n;
            // Bytes the conversion must at least move: read the source once, write the faces.
            let bytes = (img.width * img.height * 12 + texels * 12) as f64;
            let bound = texels as f64 / (bytes / bw) / 1e6;
            let label = if filter == Filter::Area {
                "area (exact, default)"
            } else {
                "bilinear (1 tap)"
            };
            writeln!(
                md,
                "| {}×{} | {n}² | {label} | {:.1} | {:.2} | {bound:.0} | {err} | {energy:+.2e} | {:.1} |",
                img.width,
                img.height,
                t * 1e3,
                texels as f64 / t / 1e6,
                (texels * 12) as f64 / 1048576.0
            )
            .unwrap();
        }
    }

    let series = [Filter::Area, Filter::Bilinear]
        .iter()
        .map(|f| {
            let pts: Vec<&(Filter, usize, f64, f64)> =
                chart_points.iter().filter(|p| p.0 == *f).collect();
            ibl_plot::Series {
                label: format!("{f:?} filter").to_lowercase(),
                points: pts.iter().map(|p| (p.2, p.3)).collect(),
                default: if *f == Filter::Area {
                    pts.iter().position(|p| p.1 == src.width / 4).or(Some(0))
                } else {
                    None
                },
            }
        })
        .collect();
    let chart = ibl_plot::Chart {
        title: "equirect-to-cube: time vs mean relative error (per face size)".into(),
        x_label: "time (s)".into(),
        y_label: "mean relative error".into(),
        series,
        targets: vec![(0.01, "goal 1%".into())],
    };
    writeln!(md, "\n![time against error](foundation.svg)\n").unwrap();

    writeln!(md, "\n### SH projection (radiance) of a 6×256² cube\n").unwrap();
    writeln!(
        md,
        "| bands | time (ms) | Mtexel/s | bandwidth bound (Mtexel/s) |"
    )
    .unwrap();
    writeln!(md, "|---|---|---|---|").unwrap();
    let cube = equirect::equirect_to_cube(&src, 256, Filter::Area, 0.0, &NoProgress);
    for bands in [3, 5, 8] {
        let (t, _) = time(runs.max(3), || irradiance::project_cube(&cube, bands, 0.0));
        let texels = 6 * 256 * 256;
        let bound = bw / 12.0 / 1e6;
        writeln!(
            md,
            "| {bands} | {:.2} | {:.0} | {bound:.0} |",
            t * 1e3,
            texels as f64 / t / 1e6
        )
        .unwrap();
    }

    writeln!(
        md,
        "\n### Exact irradiance (brute-force cosine convolution)\n"
    )
    .unwrap();
    writeln!(md, "| source texels | output | time (s) | Gmac/s |").unwrap();
    writeln!(md, "|---|---|---|---|").unwrap();
    let src_cube = ibl_core::envmap::Environment::Cube(equirect::equirect_to_cube(
        &src,
        if quick { 64 } else { 128 },
        Filter::Area,
        0.0,
        &NoProgress,
    ));
    let out = if quick { 16 } else { 32 };
    let (t, _) = time(1, || {
        irradiance::convolve_cosine_exact(&src_cube, out, 0, 0.0, &NoProgress)
    });
    let n_src = match &src_cube {
        ibl_core::envmap::Environment::Cube(c) => 6 * c.size * c.size,
        _ => unreachable!(),
    };
    let macs = (n_src * 6 * out * out) as f64;
    writeln!(
        md,
        "| {n_src} | 6×{out}² | {t:.3} | {:.2} |",
        macs / t / 1e9
    )
    .unwrap();

    print!("{md}");
    let out_dir = root().join("bench");
    std::fs::create_dir_all(&out_dir).unwrap();
    io::write_atomic(&out_dir.join("foundation.md"), md.as_bytes()).unwrap();
    io::write_atomic(&out_dir.join("foundation.svg"), chart.to_svg().as_bytes()).unwrap();
}
