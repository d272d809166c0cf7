//! Benchmark of `quat-map` on a synthetic 4096² 16-bit normal map (1024² with `--quick`):
//! the whole process through the real code path (read + PNG decode, convert, encode, atomic
//! write), the share of each stage, and the error of n' decoded from the written map against
//! the input normal (and against the analytic normal of the synthetic surface).
//!
//! `cargo run --release -p ibl-material --example bench-ibl-material -- [--quick]` → bench/material.md

use ibl_core::io::{self, ColorSpace, WriteOptions};
use ibl_core::progress::NoProgress;
use ibl_core::sampling::Pcg32;
use ibl_core::Image;
use ibl_material::normal::{self, Decoder, NormalImage};
use ibl_material::quat_map::{self, Params};
use ibl_material::quaternion::{angle_between, decode_quat, frame_from_quat};
use rayon::prelude::*;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// A sum of sines h(x, y) = Σ a·sin(2π(f·p) + φ): smooth, with tilts up to ~70°, and its
/// analytic normal (−∂h/∂x, −∂h/∂y, 1)/‖·‖, the independent reference.
struct Surface {
    waves: Vec<([f64; 2], f64, f64)>,
}

impl Surface {
    fn new() -> Surface {
        let mut rng = Pcg32::new(2024, 5);
        let waves = (0..24)
            .map(|_| {
                let f = [
                    (rng.next_f64() * 2.0 - 1.0) * 96.0,
                    (rng.next_f64() * 2.0 - 1.0) * 96.0,
                ];
                let len = f[0].hypot(f[1]).max(1.0);
                (
                    f,
                    0.06 / len * rng.next_f64(),
                    rng.next_f64() * std::f64::consts::TAU,
                )
            })
            .collect();
        Surface { waves }
    }

    fn normal(&self, u: f64, v: f64) -> [f64; 3] {
        let (mut gx, mut gy) = (0.0, 0.0);
        for (f, a, phi) in &self.waves {
            let c = (std::f64::consts::TAU * (f[0] * u + f[1] * v) + phi).cos()
                * a
                * std::f64::consts::TAU;
            gx += c * f[0];
            gy += c * f[1];
        }
        let l = (gx * gx + gy * gy + 1.0).sqrt();
        [-gx / l, -gy / l, 1.0 / l]
    }
}

fn synthetic(n: usize, s: &Surface) -> Image {
    let mut img = Image::new(n, n, 3);
    img.data
        .par_chunks_mut(n * 3)
        .enumerate()
        .for_each(|(j, row)| {
            for (i, px) in row.chunks_exact_mut(3).enumerate() {
                let nn = s.normal((i as f64 + 0.5) / n as f64, (j as f64 + 0.5) / n as f64);
                for k in 0..3 {
                    px[k] = (nn[k] * 0.5 + 0.5) as f32;
                }
            }
        });
    img
}

struct Row {
    label: String,
    threads: usize,
    read: f64,
    convert: f64,
    integrability: f64,
    encode: f64,
    write: f64,
    bytes: usize,
    err_input: f64,
    err_analytic: f64,
    bound: f64,
}

impl Row {
    fn total(&self) -> f64 {
        self.read + self.convert + self.integrability + self.encode + self.write
    }
}

/// Max angle of n' (from the written file) against the input normal and the analytic one.
fn errors(normal: &NormalImage, written: &Path, s: &Surface) -> (f64, f64) {
    let stored = io::read_image(written, ColorSpace::Linear).unwrap();
    let dec = Decoder::new(Params::default().decoding(), normal).unwrap();
    let (w, h) = (stored.width, stored.height);
    let rows: Vec<(f64, f64)> = (0..h)
        .into_par_iter()
        .map(|j| {
            let mut m = (0.0f64, 0.0f64);
            for i in 0..w {
                let np = frame_from_quat(decode_quat(stored.texel(i, j)))[2];
                if let normal::Texel::Unit { n, .. } = dec.decode(normal.image.texel(i, j)) {
                    m.0 = m.0.max(angle_between(np, n));
                }
                let exact = s.normal((i as f64 + 0.5) / w as f64, (j as f64 + 0.5) / h as f64);
                m.1 = m.1.max(angle_between(np, exact));
            }
            m
        })
        .collect();
    rows.into_iter()
        .fold((0.0, 0.0), |a, b| (a.0.max(b.0), a.1.max(b.1)))
}

/// Times each stage `reps` times and keeps each stage's fastest run (the machine is shared).
fn bench(
    input: &Path,
    out: &Path,
    p: &Params,
    threads: usize,
    label: &str,
    s: &Surface,
    reps: usize,
) -> Row {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    pool.install(|| {
        let opts = WriteOptions {
            png_bits: p.bits,
            float: if p.half {
                io::FloatDepth::F16
            } else {
                io::FloatDepth::F32
            },
            ..Default::default()
        };
        let mut row = Row {
            label: label.into(),
            threads,
            read: f64::MAX,
            convert: f64::MAX,
            integrability: f64::MAX,
            encode: f64::MAX,
            write: f64::MAX,
            bytes: 0,
            err_input: 0.0,
            err_analytic: 0.0,
            bound: 0.0,
        };
        let mut last = None;
        for _ in 0..reps {
            let t = Instant::now();
            let normal = normal::load(input).unwrap();
            row.read = row.read.min(t.elapsed().as_secs_f64());
            let dec = Decoder::new(p.decoding(), &normal).unwrap();
            let t = Instant::now();
            let (img, _stats) = quat_map::convert(&dec, &normal.image, &NoProgress);
            row.convert = row.convert.min(t.elapsed().as_secs_f64());
            let t = Instant::now();
            std::hint::black_box(normal::convention_check(&dec, &normal.image));
            row.integrability = row.integrability.min(t.elapsed().as_secs_f64());
            let t = Instant::now();
            let bytes = io::encode_image(out, &img, &opts).unwrap();
            row.encode = row.encode.min(t.elapsed().as_secs_f64());
            drop(img);
            let t = Instant::now();
            io::write_atomic(out, &bytes).unwrap();
            row.write = row.write.min(t.elapsed().as_secs_f64());
            row.bytes = bytes.len();
            last = Some(normal);
        }
        let (e_in, e_an) = errors(&last.expect("reps > 0"), out, s);
        row.err_input = e_in;
        row.err_analytic = e_an;
        row.bound = ibl_material::quaternion::quantisation_bound(
            ibl_material::quaternion::storage_eps(p.storage(out)),
        );
        row
    })
}

/// Accuracy on the real normal maps in fixtures/normals: what the
/// check reports at 16 and 8 bits, and what the input holds.
fn real_maps(root: &Path, md: &mut String) {
    let dir = root.join("fixtures/normals");
    let Ok(entries) = std::fs::read_dir(&dir) else {
        return;
    };
    let mut files: Vec<PathBuf> = entries
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| io::extension(p) == "png")
        .collect();
    files.sort();
    let _ = writeln!(
        md,
        "\n## Real normal maps (`fixtures/normals`, 8-bit lossy sources)\n"
    );
    let _ = writeln!(md, "| map | size | decoded length min–max | z < 0 | degenerate | y-up agreement | max n' err 16-bit (rad) | max n' err 8-bit (rad) | max Gram err 8-bit | left-handed |");
    let _ = writeln!(md, "|---|---|---|---|---|---|---|---|---|---|");
    for f in files {
        let Ok(normal) = normal::load(&f) else {
            continue;
        };
        let p16 = Params {
            check: true,
            ..Default::default()
        };
        let p8 = Params {
            check: true,
            bits: 8,
            ..Default::default()
        };
        let (Ok(a), Ok(b)) = (
            quat_map::run(&p16, &normal, Path::new("q.png"), &NoProgress),
            quat_map::run(&p8, &normal, Path::new("q.png"), &NoProgress),
        ) else {
            continue;
        };
        let (c16, c8) = (a.check.unwrap(), b.check.unwrap());
        let s = &a.stats;
        let agreement = s.convention.as_ref().map(|c| c.agreement).unwrap_or(0.0);
        let _ = writeln!(
            md,
            "| {} | {}×{} | {:.3}–{:.3} | {} | {} | {:+.2} | {:.2e} | {:.2e} | {:.2e} | {} |",
            f.file_name().unwrap().to_string_lossy(),
            normal.image.width,
            normal.image.height,
            s.min_length,
            s.max_length,
            s.back_facing,
            s.degenerate,
            agreement,
            c16.max_angle_error_rad,
            c8.max_angle_error_rad,
            c8.max_orthonormality_error,
            c16.left_handed + c8.left_handed
        );
    }
    let _ = writeln!(
        md,
        "\nBounds: 16-bit 5.29e-5 rad, 8-bit 1.36e-2 rad (n'), 8-bit Gram 2.75e-2. \"y-up agreement\" is the correlation of ∂p/∂y with \
         ∂q/∂x of the slopes read as y-up: +1 a y-up (OpenGL) height field, −1 a y-down (DirectX) one; quat-map warns below −0.25."
    );
}

fn main() {
    let quick = std::env::args().any(|a| a == "--quick");
    let n = if quick { 1024 } else { 4096 };
    let reps = if quick { 5 } else { 3 };
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let dir = tempfile::tempdir().expect("temp dir");
    let input = dir.path().join("normal.png");
    let surface = Surface::new();
    let t = Instant::now();
    let img = synthetic(n, &surface);
    io::write_image(&input, &img, &WriteOptions::default()).unwrap();
    drop(img);
    let setup = t.elapsed().as_secs_f64();
    let in_bytes = std::fs::metadata(&input).unwrap().len();
    eprintln!(
        "synthetic {n}² 16-bit normal map: {:.1} MB, made in {setup:.2} s",
        in_bytes as f64 / 1e6
    );

    let cores = std::thread::available_parallelism()
        .map(|c| c.get())
        .unwrap_or(1);
    let mut rows = Vec::new();
    let configs: Vec<(&str, &str, Params)> = vec![
        ("PNG 16-bit", "q16.png", Params::default()),
        (
            "PNG 8-bit",
            "q8.png",
            Params {
                bits: 8,
                ..Default::default()
            },
        ),
        (
            "EXR half",
            "qh.exr",
            Params {
                half: true,
                ..Default::default()
            },
        ),
    ];
    for (label, name, p) in &configs {
        let mut threads = vec![cores];
        if *name == "q16.png" && cores > 1 {
            threads.insert(0, 1);
        }
        for t in threads {
            let r = bench(&input, &dir.path().join(name), p, t, label, &surface, reps);
            eprintln!(
                "{label:11} {t} thr: read+decode {:.3} s, convert {:.3} s, y-check {:.3} s, encode {:.3} s, write {:.3} s, n' err {:.2e} (bound {:.2e})",
                r.read, r.convert, r.integrability, r.encode, r.write, r.err_input, r.bound
            );
            rows.push(r);
        }
    }

    // The binary end to end (process start, flags, the same path), when it has been built.
    let bin: PathBuf = root.join("target/release/quat-map");
    let whole = bin.is_file().then(|| {
        let out = dir.path().join("bin.png");
        let t = Instant::now();
        let st = std::process::Command::new(&bin)
            .arg(&input)
            .arg("-o")
            .arg(&out)
            .arg("-q")
            .status()
            .unwrap();
        assert!(st.success());
        t.elapsed().as_secs_f64()
    });

    let texels = (n * n) as f64;
    let mut md = String::new();
    let _ = writeln!(
        md,
        "# quat-map benchmark ({n}²{})\n",
        if quick { ", --quick" } else { "" }
    );
    let _ = writeln!(
        md,
        "Synthetic {n}×{n} 16-bit RGB normal map ({:.1} MB PNG; a sum of 24 sines, tilts up to ~70°) → quaternion map, \
         through the real code path: `normal::load` (file read + PNG decode to f32), `quat_map::convert`, \
         the y-convention check (`normal::convention_check`, ≤ 2^18 samples), `io::encode_image`, `io::write_atomic` (with fsync). {cores} core(s) shared with other work; each stage's fastest of {reps} runs. \
         Work = {:.1} M texels per run.\n",
        in_bytes as f64 / 1e6,
        texels / 1e6
    );
    let _ = writeln!(md, "| output | threads | read+decode s | convert s | y-check s | encode s | write s | total s | decode % | convert+check % | encode+write % | Mtexel/s | out MB | max n' err vs input (rad) | bound (rad) | max n' err vs analytic (rad) |");
    let _ = writeln!(
        md,
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"
    );
    for r in &rows {
        let tot = r.total();
        let _ = writeln!(
            md,
            "| {} | {} | {:.3} | {:.3} | {:.3} | {:.3} | {:.3} | {:.3} | {:.0} | {:.0} | {:.0} | {:.1} | {:.1} | {:.2e} | {:.2e} | {:.2e} |",
            r.label,
            r.threads,
            r.read,
            r.convert,
            r.integrability,
            r.encode,
            r.write,
            tot,
            100.0 * r.read / tot,
            100.0 * (r.convert + r.integrability) / tot,
            100.0 * (r.encode + r.write) / tot,
            texels / tot / 1e6,
            r.bytes as f64 / 1e6,
            r.err_input,
            r.bound,
            r.err_analytic
        );
    }
    if let Some(s) = whole {
        let _ = writeln!(md, "\nWhole `target/release/quat-map` process (16-bit PNG in and out): {s:.3} s ({:.1} Mtexel/s).", texels / s / 1e6);
    } else {
        let _ = writeln!(md, "\n(`target/release/quat-map` not built: whole-process row skipped; `cargo build --release -p quat-map`.)");
    }
    let _ = writeln!(
        md,
        "\nThe bound is 2·asin(√3·eps), eps = 1/(2^bits − 1) for PNG and 2^-11 for half floats (see `quaternion::quantisation_bound`). \
         The error against the analytic normal adds the input's own 16-bit quantisation."
    );
    // One point per output encoding (the knob): time against the decoded n' error; 16-bit PNG
    // is the default.
    let chart = ibl_plot::Chart {
        title: "quat-map: whole conversion time vs max n' error, by output encoding".into(),
        x_label: "time (s)".into(),
        y_label: "max n' error (rad)".into(),
        series: rows
            .iter()
            .filter(|r| r.threads == rows.iter().map(|q| q.threads).max().unwrap_or(1))
            .map(|r| ibl_plot::Series {
                label: r.label.to_string(),
                points: vec![(r.total(), r.err_input)],
                default: (r.label == "PNG 16-bit").then_some(0),
            })
            .collect(),
        targets: vec![],
    };
    let _ = writeln!(md, "\n![time against error](material.svg)");
    real_maps(&root, &mut md);
    print!("{md}");
    let out_dir = root.join("bench");
    std::fs::create_dir_all(&out_dir).unwrap();
    std::fs::write(out_dir.join("material.md"), &md).unwrap();
    std::fs::write(out_dir.join("material.svg"), chart.to_svg()).unwrap();
    eprintln!("wrote {}", out_dir.join("material.md").display());
}
