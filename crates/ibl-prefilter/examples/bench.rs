//! Time against error for the prefilter bake: `cargo run --release -p ibl-prefilter --example
//! bench -- [--quick]`. Sweeps the tree method's `--quality` and filtered importance sampling's
//! `--samples` on the small fixtures, compares every level with the brute-force reference
//! (`--reference`), and writes bench/prefilter.md and bench/prefilter.svg at the workspace root.
//! With /work/shared/fixtures present it also times the real binary on the speed-goal job
//! (1024×512 equirect → 256² faces, 5 levels) and measures its error at probe texels. Then the
//! engine-lookup frontier: runtime error against chain bytes per `--target` (bench/runtime.md,
//! bench/runtime.svg; `-- --runtime-only` runs just that).

use ibl_core::cube::texel_direction;
use ibl_core::envmap::{load_environment, Environment};
use ibl_core::equirect::Filter;
use ibl_core::luminance;
use ibl_core::progress::NoProgress;
use ibl_prefilter::bake::{
    bake_chain, probe_texels, source_face_size, ErrorStats, Method, Params, Quality,
};
use ibl_prefilter::kernel::SourceTexels;
use ibl_target::Target;
use rayon::prelude::*;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// One configuration of the sweep.
#[derive(Clone)]
struct Config {
    label: String,
    series: &'static str,
    params: Params,
}

/// One level of one run.
struct Row {
    fixture: String,
    size: usize,
    config: String,
    level: usize,
    roughness: f32,
    texels: usize,
    seconds: f64,
    work: u64,
    err: ErrorStats,
}

/// The filters compared against `--reference` and against peers: exact levels, each the GGX
/// kernel at its own roughness (`fit_lookup: false`), since that is what both measure; the
/// fit to an engine's lookup is measured by the runtime table.
fn configs(quick: bool) -> Vec<Config> {
    let exact = Params {
        fit_lookup: Some(false),
        ..Default::default()
    };
    let mut v = Vec::new();
    for q in [Quality::Draft, Quality::Default, Quality::High] {
        v.push(Config {
            label: format!("tree {}", q.name()),
            series: "tree",
            params: Params {
                quality: q,
                ..exact.clone()
            },
        });
    }
    let samples: &[u32] = if quick {
        &[64, 256, 1024]
    } else {
        &[16, 64, 256, 1024, 4096]
    };
    for &s in samples {
        v.push(Config {
            label: format!("fis {s}"),
            series: "fis",
            params: Params {
                method: Method::Fis,
                samples: Some(s),
                ..exact.clone()
            },
        });
    }
    v
}

fn main() {
    let quick = std::env::args().any(|a| a == "--quick");
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..");
    // `-- --runtime-only`: just the engine-lookup frontier (bench/runtime.md).
    if std::env::args().any(|a| a == "--runtime-only") {
        runtime_frontier(&root, quick, false);
        return;
    }
    // `-- --custom-design`: the custom lookup's α₀ × level-count sweep on the design fixtures
    // (printed); `-- --custom-only`: just the custom section of bench/runtime.md.
    if std::env::args().any(|a| a == "--custom-design") {
        custom_design(&root);
        return;
    }
    // `-- --sun-only`: the sun's power per roughness of every target's default chain (stderr).
    if std::env::args().any(|a| a == "--sun-only") {
        for target in [
            Target::Gltf,
            Target::Filament,
            Target::Unity,
            Target::Babylon,
            Target::Custom,
        ] {
            let p = Params {
                target,
                ..Default::default()
            };
            println!(
                "{}: worst {:.3}%",
                target.name(),
                100.0 * sun_power_error(&p)
            );
        }
        return;
    }
    if std::env::args().any(|a| a == "--custom-only") {
        custom_section(&root, quick);
        return;
    }
    // `-- --fit-only`: just the lookup-fitted chains against the exact ones (printed).
    if std::env::args().any(|a| a == "--fit-only") {
        runtime_frontier(&root, quick, true);
        return;
    }
    let fixtures: Vec<&str> = if quick {
        vec!["studio_256.exr", "city_512.exr"]
    } else {
        vec![
            "studio_256.exr",
            "sunset_256.exr",
            "interior_256.exr",
            "city_512.exr",
        ]
    };
    let shapes: Vec<(usize, usize)> = if quick {
        vec![(32, 5)]
    } else {
        vec![(32, 5), (64, 6)]
    };
    let threads = rayon::current_num_threads();
    let mut rows = Vec::new();
    let t_all = Instant::now();
    for name in &fixtures {
        let path = root.join("fixtures/hdri").join(name);
        let env = load_environment(&path, false).expect("fixture loads").env;
        for &(size, levels) in &shapes {
            let base = Params {
                size,
                levels: Some(levels),
                ..Default::default()
            };
            let t = Instant::now();
            let reference = bake_chain(
                &Params {
                    reference: true,
                    ..base.clone()
                },
                &env,
                &NoProgress,
            )
            .unwrap();
            eprintln!(
                "{name} {size}² × {levels}: reference in {:.2} s",
                t.elapsed().as_secs_f64()
            );
            for c in configs(quick) {
                let p = Params {
                    size,
                    levels: Some(levels),
                    ..c.params.clone()
                };
                let chain = bake_chain(&p, &env, &NoProgress).unwrap();
                for l in 1..levels {
                    let n = chain.mips.levels[l].size;
                    rows.push(Row {
                        fixture: name.to_string(),
                        size,
                        config: c.label.clone(),
                        level: l,
                        roughness: chain.report.level[l].roughness,
                        texels: 6 * n * n,
                        seconds: chain.level_seconds[l],
                        work: chain.level_work[l],
                        err: ErrorStats::between(&chain.mips.levels[l], &reference.mips.levels[l]),
                    });
                }
            }
        }
    }
    let sweep_seconds = t_all.elapsed().as_secs_f64();
    let speed = speed_goal(&root, quick);

    let mut md = String::new();
    writeln!(md, "# prefilter: time against error\n").unwrap();
    writeln!(
        md,
        "Generated by `cargo run --release -p ibl-prefilter --example bench-ibl-prefilter{}` ({} threads; the machine is shared, so times are wall-clock under whatever else ran). \
         Error: per-texel relative error of luminance against `--reference` (the exact kernel D_GGX(n·h)·max(n·l,0) summed over every source texel), \
         as mean absolute (MARE), RMS and max. Work = texels × kernel evaluations per texel (tree cells, or FIS samples above the horizon).\n",
        if quick { " -- --quick" } else { "" },
        threads
    )
    .unwrap();
    if let Some(s) = &speed {
        md.push_str(s);
    }
    writeln!(
        md,
        "## Worst level error over the fixtures, per configuration\n"
    )
    .unwrap();
    writeln!(
        md,
        "Fixtures: {}; chains {}.\n",
        fixtures.join(", "),
        shapes
            .iter()
            .map(|(s, l)| format!("{s}² × {l} levels"))
            .collect::<Vec<_>>()
            .join(" and ")
    )
    .unwrap();
    writeln!(md, "| configuration | worst MARE % | worst RMS % | worst max % | total time s | work | evaluations/s |").unwrap();
    writeln!(md, "|---|---:|---:|---:|---:|---:|---:|").unwrap();
    let mut points: Vec<(String, &'static str, f64, f64)> = Vec::new();
    for c in configs(quick) {
        let rs: Vec<&Row> = rows.iter().filter(|r| r.config == c.label).collect();
        let mare = rs.iter().map(|r| r.err.mean_abs_rel).fold(0.0, f64::max);
        let rms = rs.iter().map(|r| r.err.rms_rel).fold(0.0, f64::max);
        let mx = rs.iter().map(|r| r.err.max_abs_rel).fold(0.0, f64::max);
        let secs: f64 = rs.iter().map(|r| r.seconds).sum();
        let work: u64 = rs.iter().map(|r| r.work).sum();
        writeln!(
            md,
            "| {} | {:.4} | {:.4} | {:.3} | {:.3} | {:.3e} | {:.3e} |",
            c.label,
            100.0 * mare,
            100.0 * rms,
            100.0 * mx,
            secs,
            work as f64,
            work as f64 / secs.max(1e-9)
        )
        .unwrap();
        points.push((c.label.clone(), c.series, secs, 100.0 * mare));
    }
    writeln!(md, "\n![time against error](prefilter.svg)\n").unwrap();
    writeln!(
        md,
        "## Per level: error and time, by roughness (worst fixture)\n"
    )
    .unwrap();
    writeln!(md, "| configuration | size | level | r | texels | MARE % | RMS % | max % | time ms | work | evaluations/s |").unwrap();
    writeln!(
        md,
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"
    )
    .unwrap();
    for c in configs(quick) {
        for &(size, levels) in &shapes {
            for l in 1..levels {
                let rs: Vec<&Row> = rows
                    .iter()
                    .filter(|r| r.config == c.label && r.size == size && r.level == l)
                    .collect();
                let worst = rs
                    .iter()
                    .max_by(|a, b| a.err.mean_abs_rel.total_cmp(&b.err.mean_abs_rel))
                    .unwrap();
                let secs: f64 = rs.iter().map(|r| r.seconds).sum();
                let work: u64 = rs.iter().map(|r| r.work).sum();
                writeln!(
                    md,
                    "| {} | {size} | {l} | {:.3} | {} | {:.4} ({}) | {:.4} | {:.3} | {:.2} | {:.3e} | {:.3e} |",
                    c.label,
                    worst.roughness,
                    worst.texels,
                    100.0 * worst.err.mean_abs_rel,
                    worst.fixture.trim_end_matches(".exr"),
                    100.0 * worst.err.rms_rel,
                    100.0 * worst.err.max_abs_rel,
                    1e3 * secs / rs.len() as f64,
                    work as f64 / rs.len() as f64,
                    work as f64 / secs.max(1e-9)
                )
                .unwrap();
            }
        }
    }
    writeln!(md, "\n## Every run\n").unwrap();
    writeln!(
        md,
        "| fixture | size | configuration | level | r | MARE % | RMS % | max % | time ms | work |"
    )
    .unwrap();
    writeln!(md, "|---|---:|---|---:|---:|---:|---:|---:|---:|---:|").unwrap();
    for r in &rows {
        writeln!(
            md,
            "| {} | {} | {} | {} | {:.3} | {:.4} | {:.4} | {:.3} | {:.2} | {:.3e} |",
            r.fixture,
            r.size,
            r.config,
            r.level,
            r.roughness,
            100.0 * r.err.mean_abs_rel,
            100.0 * r.err.rms_rel,
            100.0 * r.err.max_abs_rel,
            1e3 * r.seconds,
            r.work as f64
        )
        .unwrap();
    }
    writeln!(md, "\nSweep wall time {sweep_seconds:.1} s.").unwrap();
    let dir = root.join("bench");
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join("prefilter.md"), &md).unwrap();
    std::fs::write(dir.join("prefilter.svg"), svg(&points)).unwrap();
    println!("{md}");
    eprintln!(
        "wrote {} and prefilter.svg",
        dir.join("prefilter.md").display()
    );
    runtime_frontier(&root, quick, false);
}

/// One chain shape of the runtime-error frontier.
struct Shape {
    target: Target,
    size: usize,
    levels: Option<usize>,
    /// --fit-lookup.
    fit: bool,
}

/// Error the engines' own lookups see (the `"runtime"` block of prefilter.json) against the
/// chain's bytes, per target and chain shape: bench/runtime.md and bench/runtime.svg.
fn runtime_frontier(root: &Path, quick: bool, fit_only: bool) {
    let fixtures: Vec<&str> = if quick {
        vec!["city_512.exr"]
    } else {
        vec![
            "city_512.exr",
            "sunset_256.exr",
            "interior_256.exr",
            "studio_256.exr",
        ]
    };
    let sizes: &[usize] = if quick { &[128] } else { &[128, 256] };
    let mut shapes = Vec::new();
    for &size in sizes {
        for n in 5..=8 {
            for target in [Target::Gltf, Target::Filament] {
                shapes.push(Shape {
                    target,
                    size,
                    levels: Some(n),
                    fit: false,
                });
            }
        }
        shapes.push(Shape {
            target: Target::Unity,
            size,
            levels: Some(7),
            fit: false,
        });
        shapes.push(Shape {
            target: Target::Babylon,
            size,
            levels: None,
            fit: false,
        });
    }
    // The lookup-fitted chains (crate::fit) beside the exact ones they come from, on the
    // largest size.
    let fit_size = *sizes.last().unwrap();
    // Bevy reads as gltf does (lod = r(N−1)): the gltf rows are its rows.
    let fitted = [
        (Target::Gltf, Some(6)),
        (Target::Gltf, Some(7)),
        (Target::Gltf, Some(8)),
        (Target::Filament, Some(6)),
        (Target::Unity, Some(7)),
        (Target::Babylon, None),
    ];
    if fit_only {
        shapes.clear();
        for &(target, n) in &fitted {
            shapes.push(Shape {
                target,
                size: fit_size,
                levels: n,
                fit: false,
            });
        }
    }
    for &(target, n) in &fitted {
        shapes.push(Shape {
            target,
            size: fit_size,
            levels: n,
            fit: true,
        });
    }
    let envs: Vec<(String, Environment)> = fixtures
        .iter()
        .map(|f| {
            let p = root.join("fixtures/hdri").join(f);
            (
                f.to_string(),
                load_environment(&p, false).expect("fixture loads").env,
            )
        })
        .collect();
    let mut md = String::new();
    writeln!(
        md,
        "# Runtime lookup error against bytes, per engine target\n"
    )
    .unwrap();
    writeln!(
        md,
        "Generated by `cargo run --release -p ibl-prefilter --example bench-ibl-prefilter{}`. Each chain is baked for the target (its level roughness), \
         then read as the engine reads it (its lod mapping, seamless bilinear within a level, linear between levels) at 33 roughness values \
         and {} low-discrepancy directions between texel centres, against the exact GGX kernel: the `runtime` block of prefilter.json. \
         Error: mean absolute relative error of luminance at one roughness; columns give the worst roughness in each range, per fixture ({}) and then over all of them. \
         Bytes: the chain at RGBA16F (8 bytes a texel; RGB9E5 / B10G11R11 halve it). \
         `fit`: `exact` levels are the kernel at their own roughness; `fitted` levels are fitted to the lookup (`--fit-lookup`, \
         the default for every target but three: each inner level minimises the lookup's worst relative error over its roughness range keeping the level's power, see `ibl_prefilter::fit`, \
         and levels of at most 8² texels a face are fitted to their bilinear read, see `ibl_prefilter::spatial`). Bevy reads as gltf does (its rows). \
         `% at r = 1`: where the lookup reads the last level alone, the error of that level's own bilinear read. \
         `bake s`: seconds to bake the four chains (levels and fit, without the runtime evaluation) on a shared 2-core machine.\n",
        if quick { " -- --quick" } else { "" },
        ibl_prefilter::runtime::REPORT_DIRECTIONS,
        fixtures.join(", ")
    )
    .unwrap();
    writeln!(
        md,
        "| target | lookup | size | levels | fit | bytes | worst % r ∈ [0.25, 1] per fixture | worst % r ∈ [0.1, 0.25) per fixture | mean % r ∈ [0.25, 1] | % at r = 1 per fixture | bake s |"
    )
    .unwrap();
    writeln!(md, "|---|---|---:|---:|---|---:|---|---|---:|---|---:|").unwrap();
    let mut points: Vec<(Target, f64, f64)> = Vec::new();
    for sh in &shapes {
        let p = Params {
            size: sh.size,
            levels: sh.levels,
            target: sh.target,
            fit_lookup: Some(sh.fit),
            ..Default::default()
        };
        let (mut hi, mut mean, mut levels, mut seconds) = (0.0f64, 0.0f64, 0, 0.0f64);
        let (mut his, mut los, mut ones) = (Vec::new(), Vec::new(), Vec::new());
        for (_, env) in &envs {
            let chain = bake_chain(&p, env, &NoProgress).unwrap();
            levels = chain.mips.levels.len();
            seconds += chain.level_seconds.iter().sum::<f64>() + chain.fit_seconds;
            let rt = chain.report.runtime.as_ref().unwrap();
            let pick = |a: f32, b: f32| {
                rt.roughness
                    .iter()
                    .zip(&rt.mean_abs_rel)
                    .filter(move |(r, _)| **r >= a && **r <= b)
                    .map(|(_, e)| *e)
            };
            if fit_only {
                // The whole profile over r = k/32, to see where the worst error sits.
                let prof: Vec<String> = rt
                    .mean_abs_rel
                    .iter()
                    .map(|e| format!("{:.1}", 100.0 * e))
                    .collect();
                eprintln!("  % at r = k/32: {}", prof.join(" "));
            }
            let h = pick(0.25, 1.0).fold(0.0, f64::max);
            hi = hi.max(h);
            his.push(format!("{:.1}", 100.0 * h));
            // At r = 1 the lookup reads the last level alone: what is left is that level's own
            // read (bilinear on its small faces), not the blend.
            ones.push(format!("{:.1}", 100.0 * rt.mean_abs_rel.last().unwrap()));
            los.push(format!(
                "{:.1}",
                100.0 * pick(0.1, 0.2499).fold(0.0, f64::max)
            ));
            let v: Vec<f64> = pick(0.25, 1.0).collect();
            mean += v.iter().sum::<f64>() / v.len() as f64 / envs.len() as f64;
        }
        let bytes: usize = (0..levels)
            .map(|l| 6 * 8 * (sh.size >> l).max(1).pow(2))
            .sum();
        writeln!(
            md,
            "| {} | {} | {} | {} | {} | {} | {} | {} | {:.2} | {} | {:.1} |",
            sh.target.name(),
            sh.target.spec().lod.name(),
            sh.size,
            levels,
            if sh.fit { "fitted" } else { "exact" },
            bytes,
            his.join(" / "),
            los.join(" / "),
            100.0 * mean,
            ones.join(" / "),
            seconds
        )
        .unwrap();
        eprintln!(
            "runtime frontier: {} {}² × {levels}{}: {} | {} ({seconds:.1} s)",
            sh.target.name(),
            sh.size,
            if sh.fit { " fitted" } else { "" },
            his.join(" / "),
            los.join(" / "),
        );
        if !sh.fit {
            points.push((sh.target, bytes as f64, 100.0 * hi));
        }
    }
    if fit_only {
        println!("{md}");
        return;
    }
    let series = [
        Target::Gltf,
        Target::Filament,
        Target::Unity,
        Target::Babylon,
    ]
    .iter()
    .map(|&t| {
        let pts: Vec<(f64, f64)> = points
            .iter()
            .filter(|p| p.0 == t)
            .map(|p| (p.1, p.2))
            .collect();
        let spec = t.spec();
        ibl_plot::Series {
            label: format!("{} ({})", t.name(), spec.lod.name()),
            default: points.iter().filter(|p| p.0 == t).position(|p| {
                p.1 as usize
                    == (0..spec.levels)
                        .map(|l| 6 * 8 * (spec.size >> l).max(1).pow(2))
                        .sum::<usize>()
            }),
            points: pts,
        }
    })
    .collect();
    let svg = ibl_plot::Chart {
        title: "engine lookups: worst error over r in [0.25, 1] vs chain bytes".into(),
        x_label: "chain bytes (RGBA16F)".into(),
        y_label: "worst runtime MARE (%)".into(),
        series,
        targets: vec![(3.0, "goal 3%".into())],
    }
    .to_svg();
    writeln!(md, "\n![runtime error against bytes](runtime.svg)\n").unwrap();
    writeln!(md, "{}", floor_section()).unwrap();
    let dir = root.join("bench");
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join("runtime.md"), &md).unwrap();
    std::fs::write(dir.join("runtime.svg"), svg).unwrap();
    println!("{md}");
    custom_section(root, quick);
}

/// The speed goal with the real binary, plus the error of its levels at probe texels against
/// the brute force over the whole 256² source. None when the shared fixture is absent.
fn speed_goal(root: &Path, quick: bool) -> Option<String> {
    let input = PathBuf::from("/work/shared/fixtures/hdri/city.exr");
    let exe = root.join("target/release/prefilter");
    if !input.exists() {
        eprintln!("speed goal skipped: {} absent", input.display());
        return None;
    }
    let mut s = String::new();
    writeln!(
        s,
        "## Speed goal: {} (1024×512) → 256² faces, 5 levels (256…16), default quality\n",
        input.display()
    )
    .unwrap();
    if exe.exists() {
        let out = std::env::temp_dir().join(format!("prefilter-bench-{}", std::process::id()));
        // Exact levels are what peers (cmgen, glTF-IBL-Sampler) write and what the speed goal
        // was set for; gltf's default also fits its levels to the lookup (2.5–3× the work).
        for (what, extra) in [
            ("exact levels", &["--fit-lookup", "false"][..]),
            ("the default: gltf, levels fitted to its lookup", &[][..]),
        ] {
            let mut times = Vec::new();
            for _ in 0..if quick { 2 } else { 5 } {
                let t = Instant::now();
                let st = std::process::Command::new(&exe)
                    .args([
                        input.to_str().unwrap(),
                        "-o",
                        out.to_str().unwrap(),
                        "--size",
                        "256",
                        "--levels",
                        "5",
                        "-q",
                    ])
                    .args(extra)
                    .status()
                    .unwrap();
                assert!(st.success());
                times.push(t.elapsed().as_secs_f64());
            }
            times.sort_by(f64::total_cmp);
            writeln!(
                s,
                "Whole process, {what} (`{} {} -o DIR --size 256 --levels 5{}`, load + resample + filter + estimate + EXR encode + write): best {:.3} s, median {:.3} s over {} runs.\n",
                exe.strip_prefix(root).unwrap_or(&exe).display(),
                input.display(),
                extra.iter().map(|a| format!(" {a}")).collect::<String>(),
                times[0],
                times[times.len() / 2],
                times.len()
            )
            .unwrap();
        }
        let _ = std::fs::remove_dir_all(&out);
    } else {
        writeln!(
            s,
            "(build `cargo build --release -p prefilter` to time the whole process)\n"
        )
        .unwrap();
    }
    let env: Environment = load_environment(&input, false).unwrap().env;
    let src_size = source_face_size(env.natural_face_size(), 256);
    let source = env.to_cube(src_size, Filter::Area, 0.0, &NoProgress);
    let texels = SourceTexels::new(&source);
    writeln!(s, "Error at {} probe texels per level against the brute force over all {} source texels; library timings per level:\n", probe_texels(128, 4).len(), texels.len()).unwrap();
    writeln!(
        s,
        "| configuration | level | r | time ms | work | evaluations/s | MARE % | RMS % | max % |"
    )
    .unwrap();
    writeln!(s, "|---|---:|---:|---:|---:|---:|---:|---:|---:|").unwrap();
    let cfgs: Vec<Config> = configs(quick)
        .into_iter()
        .filter(|c| c.label != "fis 16" && c.label != "fis 4096")
        .collect();
    for c in cfgs {
        let p = Params {
            size: 256,
            levels: Some(5),
            ..c.params.clone()
        };
        let chain = bake_chain(&p, &env, &NoProgress).unwrap();
        for l in 1..5 {
            let level = &chain.mips.levels[l];
            let r = chain.report.level[l].roughness;
            let probes = probe_texels(level.size, 4);
            let pairs: Vec<(f64, f64)> = probes
                .par_iter()
                .map(|&(f, i, j)| {
                    (
                        luminance(level.texel(f, i, j)) as f64,
                        luminance(texels.convolve(texel_direction(f, i, j, level.size), r * r))
                            as f64,
                    )
                })
                .collect();
            let e = ErrorStats::from_pairs(pairs);
            writeln!(
                s,
                "| {} | {l} | {r:.2} | {:.1} | {:.3e} | {:.3e} | {:.4} | {:.4} | {:.3} |",
                c.label,
                1e3 * chain.level_seconds[l],
                chain.level_work[l] as f64,
                chain.level_work[l] as f64 / chain.level_seconds[l].max(1e-9),
                100.0 * e.mean_abs_rel,
                100.0 * e.rms_rel,
                100.0 * e.max_abs_rel
            )
            .unwrap();
        }
        writeln!(
            s,
            "| {} | resample / source structures / estimates | | {:.1} / {:.1} / {:.1} | | | | | |",
            c.label,
            1e3 * chain.resample_seconds,
            1e3 * chain.source_seconds,
            1e3 * chain.estimate_seconds
        )
        .unwrap();
    }
    s.push('\n');
    Some(s)
}

/// Log-log plot of chain time against worst-level MARE, one curve per method, the default
/// quality ringed and the preset bounds drawn.
fn svg(points: &[(String, &'static str, f64, f64)]) -> String {
    let series = ["tree", "fis"]
        .iter()
        .map(|m| {
            let pts: Vec<&(String, &str, f64, f64)> = points.iter().filter(|p| p.1 == *m).collect();
            ibl_plot::Series {
                label: format!("--method {m}"),
                points: pts.iter().map(|p| (p.2, p.3)).collect(),
                default: pts.iter().position(|p| p.0.contains("default")),
            }
        })
        .collect();
    ibl_plot::Chart {
        title: "prefilter: chain time vs worst-level mean abs relative error".into(),
        x_label: "time (s)".into(),
        y_label: "worst-level MARE (%)".into(),
        series,
        targets: vec![
            (1.0, "default bound 1%".into()),
            (0.3, "high bound 0.3%".into()),
        ],
    }
    .to_svg()
}

/// The floor a linear-in-lod lookup sets on a small bright source: the peak of its prefiltered
/// radiance goes as 1/α² = r⁻⁴ (P(r) = (r² + s²)⁻², a source of width s = 0.05 in r), and the
/// engine blends two levels linearly in lod between their roughness. Worst relative error over
/// r ∈ [0.25, 1] of that blend with exact levels and with levels fitted as the bake fits them
/// (ibl_prefilter::fit on a 1×1 cube), for the linear (gltf) and Filament mappings.
fn floor_section() -> String {
    use ibl_core::cube::Cubemap;
    use ibl_prefilter::fit;
    use ibl_target::LodMapping;
    let p = |r: f32| ((r as f64 * r as f64 + 0.0025).powi(-2)) as f32;
    let cube = |v: f32| {
        let mut c = Cubemap::new(1);
        c.faces.iter_mut().for_each(|f| f.data.fill(v));
        c
    };
    let mut out = String::from(
        "## The floor the lookup sets on small bright sources\n\n\
         The peak of a small source's prefiltered radiance goes as 1/α² = r⁻⁴ (here P(r) = (r² + 0.05²)⁻²); \
         an engine blends two levels linearly in lod, and the blend of a convex function's two values overshoots between them. \
         Worst relative error of the blend over r ∈ [0.25, 1] (and where it is), with levels exact at their roughness and with levels fitted \
         to the lookup as `--fit-lookup` fits them (the worst relative error minimised, one level at a time fine to coarse, two sweeps, see `ibl_prefilter::fit`; one texel alone, so without the power the bake keeps, which no single texel can). \
         This is the part of studio's error no level can remove while the engine's mapping is fixed: a level holds one value per texel for a whole range of roughness (on studio, averaged over directions, it leaves 9.6% at 7 fitted levels). The other floor is the last level's own read: at r = 1 the lookup reads it alone, and on 4×4 faces its bilinear read costs 2.5–5.4% with the level's own values (column `% at r = 1`, exact rows), which 8×8 faces bring to 0.5–1.2%; fitted to the read (`ibl_prefilter::spatial`, the fitted rows) the 4×4 level costs 0.8–2.8%.\n\n\
         | lookup | levels | exact levels: worst % (at r) | fitted levels: worst % (at r) |\n|---|---:|---|---|\n",
    );
    for (mapping, n) in [
        (LodMapping::Linear, 5),
        (LodMapping::Linear, 6),
        (LodMapping::Linear, 7),
        (LodMapping::Linear, 8),
        (LodMapping::Filament, 6),
    ] {
        let rs = mapping.level_roughnesses(n, 256);
        let exact: Vec<f32> = rs.iter().map(|&r| p(r)).collect();
        let mut fitted = exact.clone();
        // As the bake does: fine to coarse, the finer neighbour as fitted, the last level
        // exact; the coarser one following in the first sweep, as stored in later ones.
        for sweep in 0..fit::SWEEPS {
            for l in 1..n - 1 {
                let plan = fit::plan(mapping, l, n, 256, fit::FIT_NODES);
                let nodes: Vec<Cubemap> = plan.nodes.iter().map(|q| cube(p(q.roughness))).collect();
                let (hi, coarser) = if sweep == 0 {
                    (plan.hi.map(|h| cube(p(h))), fit::Coarser::Follows)
                } else {
                    (Some(cube(fitted[l + 1])), fit::Coarser::Fixed)
                };
                let f = fit::fit_level(
                    &plan,
                    &cube(exact[l]),
                    &cube(fitted[l - 1]),
                    hi.as_ref(),
                    &nodes,
                    coarser,
                    fit::Power::Free,
                );
                fitted[l] = f.faces[0].data[0];
            }
        }
        let worst = |levels: &[f32]| {
            (0..=3000)
                .map(|k| 0.25 + 0.75 * k as f32 / 3000.0)
                .map(|r| {
                    let x: f64 = (0..n)
                        .map(|j| fit::blend_weight(mapping, r, n, 256, j) * levels[j] as f64)
                        .sum();
                    ((x / p(r) as f64 - 1.0).abs(), r)
                })
                .fold((0.0f64, 0.0f32), |a, b| if b.0 > a.0 { b } else { a })
        };
        let (e, er) = worst(&exact);
        let (f, fr) = worst(&fitted);
        out += &format!(
            "| {} | {n} | {:.1} ({er:.2}) | {:.1} ({fr:.2}) |\n",
            mapping.name(),
            100.0 * e,
            100.0 * f
        );
    }
    out
}

/// The custom target's design fixtures: α₀ and the level count are chosen on these only; the
/// others are scored ([`custom_section`]).
const CUSTOM_DESIGN: [&str; 2] = ["city_512.exr", "interior_256.exr"];

/// The custom lookup's α₀ × level-count sweep on the design fixtures, printed: worst mean and
/// worst 99th percentile over r ∈ [0.1, 1], the profile over r = k/32.
fn custom_design(root: &Path) {
    let args: Vec<String> = std::env::args().collect();
    let get = |k: &str| {
        args.iter()
            .position(|a| a == k)
            .and_then(|i| args.get(i + 1))
            .map(|v| {
                v.split(',')
                    .map(|x| x.parse::<f64>().unwrap())
                    .collect::<Vec<_>>()
            })
    };
    let a0s = get("--a0").unwrap_or(vec![0.003, 0.01, 0.03, 0.1]);
    let ns = get("--n").unwrap_or(vec![6.0, 7.0]);
    let envs: Vec<(String, Environment)> = CUSTOM_DESIGN
        .iter()
        .map(|f| {
            let p = root.join("fixtures/hdri").join(f);
            (f.to_string(), load_environment(&p, false).unwrap().env)
        })
        .collect();
    for &n in &ns {
        for &a0 in &a0s {
            let p = Params {
                target: Target::Custom,
                levels: Some(n as usize),
                custom_alpha0: Some(a0 as f32),
                ..Default::default()
            };
            for (name, env) in &envs {
                let t = Instant::now();
                let chain = bake_chain(&p, env, &NoProgress).unwrap();
                let rt = chain.report.runtime.as_ref().unwrap();
                let worst = |v: &[f64]| {
                    rt.roughness
                        .iter()
                        .zip(v)
                        .filter(|(r, _)| **r >= 0.1)
                        .map(|(_, e)| *e)
                        .fold(0.0, f64::max)
                };
                let prof: Vec<String> = rt
                    .mean_abs_rel
                    .iter()
                    .map(|e| format!("{:.1}", 100.0 * e))
                    .collect();
                let (fine, fine_r, _) = fine_worst(&p, env, &chain);
                println!(
                    "custom N {n} a0 {a0} {name}: worst mean {:.2}% (r = 0.10, 0.11, …: {:.2}% at r {fine_r}) worst p99 {:.1}% r=1 {:.2}% levels r {:?} ({:.1} s)\n   {}",
                    100.0 * worst(&rt.mean_abs_rel),
                    100.0 * fine,
                    100.0 * worst(&rt.p99_abs_rel),
                    100.0 * rt.mean_abs_rel.last().unwrap(),
                    chain.report.level_roughness.iter().map(|r| (r * 1000.0).round() / 1000.0).collect::<Vec<_>>(),
                    t.elapsed().as_secs_f64(),
                    prof.join(" ")
                );
            }
        }
    }
}

/// Every roughness r = 0.10, 0.11, …, 1.00: the goal's "every r ≥ 0.1" more finely than the
/// report's 33 values k/32 (which skip r ∈ (0.094, 0.125), where the first interval was).
fn fine_roughness() -> Vec<f32> {
    (10..=100).map(|k| k as f32 / 100.0).collect()
}

/// Directions of [`fine_worst`].
const FINE_DIRECTIONS: usize = 256;

/// The custom chain's read ([`CustomLookup::read`](ibl_prefilter::custom::CustomLookup::read))
/// against the exact kernel (the cell tree at the runtime report's knobs, on the source cube
/// the bake filtered) at every [`fine_roughness`] and [`FINE_DIRECTIONS`] directions: (worst
/// mean, its r, worst p99).
fn fine_worst(
    p: &Params,
    env: &Environment,
    chain: &ibl_prefilter::bake::Chain,
) -> (f64, f32, f64) {
    use ibl_prefilter::custom::CustomChain;
    use ibl_prefilter::runtime::{abs_rel_stats_of, probe_directions, Reference};
    let source = env.to_cube(
        chain.report.source_size,
        Filter::Area,
        p.rotate,
        &NoProgress,
    );
    let tree = ibl_prefilter::tree::CellTree::new(&source);
    let reference = Reference::Tree {
        tree: &tree,
        source: &source,
        params: ibl_prefilter::bake::RUNTIME_REFERENCE,
    };
    let lk = chain.report.custom_lookup.clone().expect("a custom chain");
    let cc = CustomChain::new(&chain.mips, chain.correction.as_ref().unwrap());
    let rs = fine_roughness();
    let st = abs_rel_stats_of(
        &|d, r| lk.read(&cc, d, r),
        &rs,
        &probe_directions(FINE_DIRECTIONS),
        &reference,
    );
    let (mut worst, mut at, mut p99) = (0.0f64, 0.0f32, 0.0f64);
    for (s, &r) in st.iter().zip(&rs) {
        if s.mean > worst {
            (worst, at) = (s.mean, r);
        }
        p99 = p99.max(s.p99);
    }
    (worst, at, p99)
}

/// Where [`custom_section`] starts in bench/runtime.md (everything after it is replaced).
const CUSTOM_MARKER: &str = "## Custom lookup against every engine's";

/// The fixtures [`custom_section`] scores: the design ones, then the held-out ones (never used
/// to choose α₀ or the level count). The damaged ones' negative texels are set to 0.
fn custom_envs(root: &Path, quick: bool) -> Vec<(String, bool, Environment)> {
    let mut v = Vec::new();
    for f in CUSTOM_DESIGN {
        let p = root.join("fixtures/hdri").join(f);
        v.push((
            f.to_string(),
            true,
            load_environment(&p, false).unwrap().env,
        ));
    }
    let held: &[&str] = if quick {
        &["hdri/studio_256.exr"]
    } else {
        &[
            "hdri/sunset_256.exr",
            "hdri/studio_256.exr",
            "hdri-damaged/esplanade.exr",
            "hdri-damaged/park.exr",
        ]
    };
    for f in held {
        let p = root.join("fixtures").join(f);
        match load_environment(&p, true) {
            Ok(l) => {
                let mut cube = l.env.to_cube(256, Filter::Area, 0.0, &NoProgress);
                for face in &mut cube.faces {
                    for x in &mut face.data {
                        *x = x.max(0.0);
                    }
                }
                let name = Path::new(f)
                    .file_name()
                    .unwrap()
                    .to_string_lossy()
                    .to_string();
                v.push((name, false, Environment::Cube(cube)));
            }
            Err(e) => eprintln!("custom section: {f} skipped: {e}"),
        }
    }
    v
}

/// A 10⁵ one-texel sun over a dim sky: the largest relative change of the lookup's power
/// (∫ lookup dω by the midpoint rule on a 512² grid a face: twice the 256² level 0's
/// resolution, so the read's kinks fall on cell edges; a 128² grid undersampled level 0) from
/// the source's, over the 65 roughness values k/64 (each printed to stderr).
fn sun_power_error(p: &Params) -> f64 {
    use ibl_core::bordered::BorderedMips;
    use ibl_core::cube::{texel_solid_angle, Cubemap, Face};
    let n = 256;
    let mut src = Cubemap::constant(n, [0.05, 0.05, 0.05]);
    let k = 3 * (101 * n + 157);
    src.faces[2].data[k..k + 3].copy_from_slice(&[1e5, 1e5, 1e5]);
    let power = |m: usize, f: &dyn Fn(Face, usize, usize) -> [f32; 3]| {
        let mut s = 0.0f64;
        for face in Face::ALL {
            for j in 0..m {
                for i in 0..m {
                    s += luminance(f(face, i, j)) as f64 * texel_solid_angle(i, j, m);
                }
            }
        }
        s
    };
    let want = power(n, &|f, i, j| src.texel(f, i, j));
    let chain = bake_chain(p, &Environment::Cube(src), &NoProgress).unwrap();
    let b = BorderedMips::new(&chain.mips);
    let m = p.lookup();
    let (levels, size) = (chain.mips.levels.len(), p.size);
    // The custom lookup reads its two taps and the alpha channel; the others one trilinear tap.
    let custom = chain.report.custom_lookup.clone().map(|lk| {
        let alpha = chain
            .correction
            .as_ref()
            .expect("custom chains have an alpha");
        (
            lk,
            ibl_prefilter::custom::CustomChain::new(&chain.mips, alpha),
        )
    });
    let read = |d, r: f32| match &custom {
        Some((lk, cc)) => lk.read(cc, d, r),
        None => b.sample(d, m.lod(r, levels, size)),
    };
    let per_r = (0..=64)
        .into_par_iter()
        .map(|k| {
            let r = k as f32 / 64.0;
            let got = power(512, &|f, i, j| read(texel_direction(f, i, j, 512), r));
            (got - want) / want
        })
        .collect::<Vec<f64>>();
    eprintln!(
        "sun power {} (% per r = k/64): {}",
        p.target.name(),
        per_r
            .iter()
            .map(|e| format!("{:+.3}", 100.0 * e))
            .collect::<Vec<_>>()
            .join(" ")
    );
    per_r.into_iter().map(f64::abs).fold(0.0, f64::max)
}

/// The `custom` target beside every engine target at today's default bytes (256², RGBA16F,
/// each target's default chain, levels fitted to its lookup): worst mean and worst 99th
/// percentile over r ∈ [0.1, 1] per fixture, design and held-out, and a sun's power. Appended
/// to bench/runtime.md (replacing an earlier custom section).
fn custom_section(root: &Path, quick: bool) {
    let envs = custom_envs(root, quick);
    let mut md = String::new();
    writeln!(md, "{CUSTOM_MARKER} lookup (`--target custom`)\n").unwrap();
    writeln!(
        md,
        "Generated by `cargo run --release -p ibl-prefilter --example bench-ibl-prefilter -- --custom-only{}`. \
         Each target's default chain at 256² (levels fitted to its lookup, the default), read as its engine reads it, \
         against the exact GGX kernel at 33 roughness values and {} directions (the `runtime` block of prefilter.json). \
         Per fixture: the worst over r ∈ [0.1, 1] of the mean absolute relative error of luminance, and of its 99th percentile \
         over the directions (p99, the worst direction a mean hides). `custom`'s α₀ and level count were chosen on the design fixtures \
         ({}) only (`-- --custom-design` prints the sweep); the others are held out (hdri-damaged: negative texels set to 0). \
         `sun power`: a one-texel 10⁵ sun on a dim sky, the largest change of the lookup's power (∫ lookup dω) from the source's over the 65 roughness values k/64.\n",
        if quick { " --quick" } else { "" },
        ibl_prefilter::runtime::REPORT_DIRECTIONS,
        CUSTOM_DESIGN.join(", ")
    )
    .unwrap();
    let names: Vec<String> = envs
        .iter()
        .map(|(n, d, _)| {
            format!(
                "{}{}",
                n.trim_end_matches(".exr"),
                if *d { "*" } else { "" }
            )
        })
        .collect();
    writeln!(
        md,
        "| target | lookup | levels | bytes | worst mean % r ∈ [0.1, 1] ({}) | worst p99 % r ∈ [0.1, 1] | worst mean %, design / held-out | sun power % |",
        names.join(" / ")
    )
    .unwrap();
    writeln!(md, "|---|---|---:|---:|---|---|---|---:|").unwrap();
    let mut fine = Vec::new();
    for target in [
        Target::Gltf,
        Target::Filament,
        Target::Unity,
        Target::Babylon,
        Target::Custom,
    ] {
        let p = Params {
            target,
            ..Default::default()
        };
        let (mut means, mut p99s) = (Vec::new(), Vec::new());
        let (mut design, mut held) = (0.0f64, 0.0f64);
        let mut levels = 0;
        for (name, is_design, env) in &envs {
            let t = Instant::now();
            let chain = bake_chain(&p, env, &NoProgress).unwrap();
            levels = chain.mips.levels.len();
            let rt = chain.report.runtime.as_ref().unwrap();
            let worst = |v: &[f64]| {
                rt.roughness
                    .iter()
                    .zip(v)
                    .filter(|(r, _)| **r >= 0.1 - 1e-6)
                    .map(|(_, e)| *e)
                    .fold(0.0, f64::max)
            };
            let (m, q) = (worst(&rt.mean_abs_rel), worst(&rt.p99_abs_rel));
            eprintln!(
                "custom section: {} {name}: mean {:.2}% p99 {:.1}% ({:.1} s)\n   {}",
                target.name(),
                100.0 * m,
                100.0 * q,
                t.elapsed().as_secs_f64(),
                rt.mean_abs_rel
                    .iter()
                    .map(|e| format!("{:.1}", 100.0 * e))
                    .collect::<Vec<_>>()
                    .join(" ")
            );
            means.push(format!("{:.1}", 100.0 * m));
            p99s.push(format!("{:.0}", 100.0 * q));
            if *is_design {
                design = design.max(m);
            } else {
                held = held.max(m);
            }
        }
        if target == Target::Custom {
            for (name, _, env) in &envs {
                let chain = bake_chain(&p, env, &NoProgress).unwrap();
                fine.push((name.clone(), fine_worst(&p, env, &chain)));
            }
        }
        let sun = sun_power_error(&p);
        let bytes: usize = (0..levels)
            .map(|l| 6 * 8 * (p.size >> l).max(1).pow(2))
            .sum();
        writeln!(
            md,
            "| {} | {} | {levels} | {bytes} | {} | {} | {:.1} / {:.1} | {:.3} |",
            target.name(),
            p.lookup().name(),
            means.join(" / "),
            p99s.join(" / "),
            100.0 * design,
            100.0 * held,
            100.0 * sun
        )
        .unwrap();
    }
    writeln!(
        md,
        "\n`custom` at every r = 0.10, 0.11, …, 1.00 ({FINE_DIRECTIONS} directions, the same reference; the table's 33 values k/32 skip r ∈ (0.094, 0.125)):\n\n| fixture | worst mean % | at r | worst p99 % |\n|---|---:|---:|---:|"
    )
    .unwrap();
    for (name, (m, r, q)) in &fine {
        writeln!(
            md,
            "| {name} | {:.2} | {r:.2} | {:.1} |",
            100.0 * m,
            100.0 * q
        )
        .unwrap();
    }
    let path = root.join("bench/runtime.md");
    let old = std::fs::read_to_string(&path).unwrap_or_default();
    let keep = match old.find(CUSTOM_MARKER) {
        Some(i) => old[..i].to_string(),
        None => format!("{}\n\n", old.trim_end()),
    };
    std::fs::write(&path, format!("{keep}{md}")).unwrap();
    println!("{md}");
}
