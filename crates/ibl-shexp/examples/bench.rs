//! Benchmark of the SH-exp fit and evaluator (writes bench/shexp.md under the workspace root):
//! fit time breakdown, the §5.1 win-rate table on the fixtures, the ablation of what was tried
//! to lift it, and MSE for P orders 2–6 × Q orders 1–3 (Silvennoinen et al. 2025 Fig. 8).
//!
//! cargo run --release -p ibl-shexp --example bench-ibl-shexp -- [--quick]

use ibl_core::envmap::load_environment;
use ibl_core::progress::NoProgress;
use ibl_core::Cubemap;
use ibl_shexp::coeffs::{Objective, Target};
use ibl_shexp::eval::{self, EnvReport, Truth};
use ibl_shexp::fit::{self, EstimatorKind, Params, Rows, Timings};
use ibl_shexp::splitsum::SplitSum;
use std::fmt::Write;
use std::path::PathBuf;
use std::time::Instant;

struct Env {
    name: String,
    cube: Cubemap,
    truth: Truth,
    ss: SplitSum,
    floor: [f64; 3],
}

/// The bench/ folder at the workspace root.
fn out_dir_for_chart() -> std::path::PathBuf {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../bench");
    std::fs::create_dir_all(&dir).expect("create bench/");
    dir
}

fn main() {
    let quick = std::env::args().any(|a| a == "--quick");
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..");
    let fixtures = ["city_512", "studio_256", "sunset_256", "interior_256"];
    let eparams = if quick {
        eval::Params {
            sphere_size: 32,
            truth_check_stride: 0,
            ..Default::default()
        }
    } else {
        eval::Params::default()
    };
    let t_all = Instant::now();
    let mut md = String::new();
    let _ = writeln!(
        md,
        "# SH-exponential glossy reflections (Silvennoinen et al. 2025): benchmark\n"
    );
    let _ = writeln!(
        md,
        "`cargo run --release -p ibl-shexp --example bench-ibl-shexp{}` on {} thread(s). Fixtures: {} (equirect → natural cube size). Cases: 2 materials × {} views × {} roughnesses r = {:?} (α = r²) per environment; sphere {}², ground truth by exact summation over a {}² cube.\n",
        if quick { " -- --quick" } else { "" },
        rayon::current_num_threads(),
        fixtures.join(", "),
        eparams.views.len(),
        eparams.roughness.len(),
        eparams.roughness,
        eparams.sphere_size,
        eparams.truth_size
    );

    // ---- Fit timing -------------------------------------------------------------------------
    let _ = writeln!(md, "## Fit time per probe\n");
    let _ = writeln!(md, "Default settings: 64 normals × 64 views × 4 α = 16,384 rows × 1024 VNDF samples (filtered importance sampling), P order 4, Q order 2. Work = rows × samples trilinear lookups. The α-knot rows solve eq. 11 and the knot model from the same rows (the log RMS residual is eq. 11's).\n");
    let _ = writeln!(md, "| environment | cube | prepare s | tables s | E0 s | solve s | total s | E0 share | lookups/s | log RMS residual | κ |");
    let _ = writeln!(
        md,
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"
    );
    let mut timing_inputs: Vec<(String, PathBuf, Option<usize>)> = fixtures
        .iter()
        .map(|f| {
            (
                f.to_string(),
                root.join(format!("fixtures/hdri/{f}.exr")),
                None,
            )
        })
        .collect();
    // A full-size source (e.g. city.exr of Debian's blender-data) when IBL_BENCH_HDRI names one.
    let big = std::env::var_os("IBL_BENCH_HDRI").map(std::path::PathBuf::from);
    if let Some(big) = big.filter(|b| b.exists() && !quick) {
        timing_inputs.push(("IBL_BENCH_HDRI at 256²".into(), big, Some(256)));
    } else {
        timing_inputs.push((
            "city_512 resampled to 256²".into(),
            root.join("fixtures/hdri/city_512.exr"),
            Some(256),
        ));
    }
    let reps = if quick { 1 } else { 3 };
    let mut timing_runs: Vec<(String, PathBuf, Option<usize>, Params)> = timing_inputs
        .into_iter()
        .map(|(n, p, s)| (n, p, s, Params::default()))
        .collect();
    let city = root.join("fixtures/hdri/city_512.exr");
    timing_runs.push((
        "city_512, α knots 0.2, 1 (+ n·v, λ = 0)".into(),
        city.clone(),
        None,
        Params {
            alpha_knots: vec![0.2, 1.0],
            cosine_weight: true,
            log_weight: 0.0,
            ..Params::default()
        },
    ));
    timing_runs.push((
        "city_512, α knots 0.2, 0.5, 1 + 8 α (32,768 rows)".into(),
        city,
        None,
        Params {
            alpha_knots: vec![0.2, 0.5, 1.0],
            alphas: (0..8).map(|i| 0.2 + 0.8 * i as f32 / 7.0).collect(),
            cosine_weight: true,
            log_weight: 0.0,
            ..Params::default()
        },
    ));
    for (name, path, size, params) in &timing_runs {
        let env = load_environment(path, false).expect("fixture loads");
        let cube = fit::working_cube(&env.env, *size, &NoProgress);
        let mut best: Option<(Timings, ibl_shexp::Coeffs)> = None;
        for _ in 0..reps {
            let f = fit::fit_cube(params, &cube, &NoProgress).expect("fit");
            if best
                .as_ref()
                .is_none_or(|b| f.timings.total() < b.0.total())
            {
                best = Some((f.timings, f.coeffs));
            }
        }
        let (t, c) = best.unwrap();
        let work = (c.rows * params.samples) as f64;
        let _ = writeln!(
            md,
            "| {name} | {}² | {:.3} | {:.3} | {:.3} | {:.3} | **{:.3}** | {:.0}% | {:.1} M | {:.4} | {:.1} |",
            cube.size,
            t.prepare,
            t.tables,
            t.estimate,
            t.solve,
            t.total(),
            100.0 * t.estimate / t.total(),
            work / t.estimate / 1e6,
            c.residual,
            c.condition_number
        );
    }
    let _ = writeln!(
        md,
        "\nBest of {reps} run(s). Paper: 0.328 ms on an RTX A6000 (CUDA).\n"
    );

    // ---- Environments, truth and split-sum ----------------------------------------------------
    let mut envs = Vec::new();
    for f in fixtures {
        let env = load_environment(&root.join(format!("fixtures/hdri/{f}.exr")), false)
            .expect("fixture loads");
        let cube = fit::working_cube(&env.env, None, &NoProgress);
        let truth = eval::compute_truth(&cube, &eparams, &NoProgress);
        let ss = eval::default_split_sum(&cube, eparams.ss_size).expect("split-sum chain");
        let floor = fit::floor_for(&cube, Params::default().floor).unwrap();
        eprintln!("{f}: truth in {:.2} s", truth.seconds);
        envs.push(Env {
            name: f.to_string(),
            cube,
            truth,
            ss,
            floor,
        });
    }

    // ---- Variants -------------------------------------------------------------------------------
    // The paper's procedure (plain log-space least squares); the default adds the relative
    // linear refinement.
    let base = Params {
        objective: Objective::Log,
        ..Params::default()
    };
    let default = Params::default();
    let norm = Params {
        target: Target::E0OverAlbedo,
        ..base.clone()
    };
    let perceptual_alphas: Vec<f32> = (0..4)
        .map(|i| (0.2f32.sqrt() + (1.0 - 0.2f32.sqrt()) * i as f32 / 3.0).powi(2))
        .collect();
    let eight_alphas: Vec<f32> = (0..8).map(|i| 0.2 + 0.8 * i as f32 / 7.0).collect();
    // Beyond eq. 11: coefficients linear in α between knots (`--alpha-knots`), with rows weighted
    // by n·v (a rendered surface's projected area) and the linear error alone.
    let knots2 = Params {
        alpha_knots: vec![0.2, 1.0],
        cosine_weight: true,
        log_weight: 0.0,
        ..default.clone()
    };
    let knots3 = Params {
        alpha_knots: vec![0.2, 0.5, 1.0],
        alphas: eight_alphas.clone(),
        ..knots2.clone()
    };
    let mut variants: Vec<(&str, Params)> = vec![
        (
            "paper: 64×64×4 rows, 1024 samples, plain log LS",
            base.clone(),
        ),
        (
            "default: + relative linear refinement (λ = 0.3)",
            default.clone(),
        ),
        ("target E0/(A+B) (DFG albedo divided out)", norm.clone()),
        (
            "beyond eq. 11: α knots 0.2, 1 (2×33/channel) + n·v weights, λ = 0",
            knots2.clone(),
        ),
        (
            "weights ∝ E0² (linear-MSE proxy)",
            Params {
                weight_power: 2.0,
                ..base.clone()
            },
        ),
    ];
    if !quick {
        variants.extend([
            (
                "relative linear refinement, λ = 0 (linear error only)",
                Params {
                    log_weight: 0.0,
                    ..default.clone()
                },
            ),
            (
                "beyond eq. 11: α knots 0.2, 1, default objective",
                Params {
                    alpha_knots: vec![0.2, 1.0],
                    ..default.clone()
                },
            ),
            (
                "beyond eq. 11: α knots 0.2, 0.5, 1 (3×33/channel) + 8 α + n·v weights, λ = 0",
                knots3.clone(),
            ),
            (
                "relative linear refinement + n·v weights, λ = 0 (eq. 11)",
                Params {
                    cosine_weight: true,
                    log_weight: 0.0,
                    ..default.clone()
                },
            ),
            (
                "relative linear refinement, λ = 1",
                Params {
                    log_weight: 1.0,
                    ..default.clone()
                },
            ),
            (
                "relative linear refinement + rows weighted by n·v",
                Params {
                    cosine_weight: true,
                    ..default.clone()
                },
            ),
            (
                "relative linear refinement + 8 α",
                Params {
                    alphas: eight_alphas.clone(),
                    ..default.clone()
                },
            ),
            (
                "relative linear refinement + E0/(A+B)",
                Params {
                    target: Target::E0OverAlbedo,
                    ..default.clone()
                },
            ),
            (
                "weights ∝ E0",
                Params {
                    weight_power: 1.0,
                    ..base.clone()
                },
            ),
            (
                "weights ∝ E0² · n·v",
                Params {
                    weight_power: 2.0,
                    cosine_weight: true,
                    ..base.clone()
                },
            ),
            (
                "exact E0 (32² summation)",
                Params {
                    estimator: EstimatorKind::Exact,
                    ..base.clone()
                },
            ),
            (
                "lod bias 0",
                Params {
                    lod_bias: 0.0,
                    ..base.clone()
                },
            ),
            (
                "32×32×4 rows",
                Params {
                    normals: 32,
                    views: 32,
                    ..base.clone()
                },
            ),
            (
                "128×64×4 rows",
                Params {
                    normals: 128,
                    ..base.clone()
                },
            ),
            (
                "8 α in [0.2, 1]",
                Params {
                    alphas: eight_alphas.clone(),
                    ..base.clone()
                },
            ),
            (
                "4 α uniform in r over [√0.2, 1]",
                Params {
                    alphas: perceptual_alphas.clone(),
                    ..base.clone()
                },
            ),
            (
                "P order 6",
                Params {
                    p_order: 6,
                    ..base.clone()
                },
            ),
            (
                "E0/(A+B) + weights ∝ E0",
                Params {
                    weight_power: 1.0,
                    ..norm.clone()
                },
            ),
            (
                "E0/(A+B) + weights ∝ E0²",
                Params {
                    weight_power: 2.0,
                    ..norm.clone()
                },
            ),
            (
                "E0/(A+B) + 8 α",
                Params {
                    alphas: eight_alphas.clone(),
                    ..norm.clone()
                },
            ),
            (
                "E0/(A+B) + 4 α uniform in r",
                Params {
                    alphas: perceptual_alphas.clone(),
                    ..norm.clone()
                },
            ),
            (
                "E0/(A+B) + P order 6",
                Params {
                    p_order: 6,
                    ..norm.clone()
                },
            ),
            (
                "E0/(A+B) + P order 6 + 8 α",
                Params {
                    p_order: 6,
                    alphas: eight_alphas.clone(),
                    ..norm.clone()
                },
            ),
        ]);
    }
    let _ = writeln!(md, "## Ablation: share of cases SH-exp beats split-sum\n");
    let _ = writeln!(md, "Each row refits every fixture with one change from the paper's settings; the same ground truth and split-sum chain are used throughout. Wins per environment out of {}; gm ratio = geometric mean of MSE(SH-exp)/MSE(split-sum).\n", 2 * eparams.views.len() * eparams.roughness.len());
    let mut hdr = String::from("| variant |");
    for e in &envs {
        let _ = write!(hdr, " {} |", e.name);
    }
    hdr.push_str(" wins | share | share (display) | gm ratio | gm ratio r=0.5 | gm ratio r=1 | fit s (all) |");
    let _ = writeln!(md, "{hdr}");
    let _ = writeln!(
        md,
        "|---|{}---:|---:|---:|---:|---:|---:|---:|",
        "---:|".repeat(envs.len())
    );
    // (name, wins, cases) of every row, for the summary after the table.
    let mut shares: Vec<(String, usize, usize)> = Vec::new();
    let mut paper_reports: Vec<EnvReport> = Vec::new();
    let mut best_variant: Option<(usize, String, Vec<EnvReport>)> = None;
    for (vi, (name, params)) in variants.iter().enumerate() {
        let t0 = Instant::now();
        let mut reports = Vec::new();
        for e in &envs {
            let coeffs = fit::fit_cube(params, &e.cube, &NoProgress)
                .expect("fit")
                .coeffs;
            let (rep, _) = eval::score(&e.name, &e.truth, &coeffs, &e.ss, &eparams, false);
            reports.push(rep);
        }
        let secs = t0.elapsed().as_secs_f64();
        let wins: usize = reports.iter().map(|r| r.wins).sum();
        let total: usize = reports.iter().map(|r| r.cases.len()).sum();
        let wins_d: usize = reports.iter().map(|r| r.wins_display).sum();
        let gm = |f: &dyn Fn(&eval::Case) -> bool| {
            let v: Vec<f64> = reports
                .iter()
                .flat_map(|r| r.cases.iter())
                .filter(|c| f(c))
                .map(|c| c.ratio.max(1e-30).ln())
                .collect();
            (v.iter().sum::<f64>() / v.len().max(1) as f64).exp()
        };
        let mut row = format!("| {name} |");
        for r in &reports {
            let _ = write!(row, " {} |", r.wins);
        }
        let rmin = eparams
            .roughness
            .iter()
            .cloned()
            .fold(f32::INFINITY, f32::min);
        let rmax = eparams.roughness.iter().cloned().fold(0.0, f32::max);
        let _ = write!(
            row,
            " {wins}/{total} | **{:.0}%** | {:.0}% | {:.3} | {:.3} | {:.3} | {secs:.1} |",
            100.0 * wins as f64 / total as f64,
            100.0 * wins_d as f64 / total as f64,
            gm(&|_| true),
            gm(&|c| c.roughness == rmin),
            gm(&|c| c.roughness == rmax)
        );
        let _ = writeln!(md, "{row}");
        eprintln!("{row}");
        shares.push((name.to_string(), wins, total));
        if vi == 0 {
            paper_reports = reports.clone();
        }
        if best_variant.as_ref().is_none_or(|b| wins > b.0) {
            best_variant = Some((wins, name.to_string(), reports));
        }
    }

    // ---- Per-α oracles: the model's ceiling at each evaluated roughness ----------------------------
    if !quick {
        let oracles: Vec<(&str, Params)> = vec![
            (
                "per-α oracle, paper target, P4/Q2",
                Params {
                    normals: 48,
                    views: 48,
                    ..base.clone()
                },
            ),
            (
                "per-α oracle, relative refinement, P4/Q2",
                Params {
                    normals: 48,
                    views: 48,
                    ..default.clone()
                },
            ),
            (
                "per-α oracle, relative refinement λ = 0, P4/Q2",
                Params {
                    normals: 48,
                    views: 48,
                    log_weight: 0.0,
                    refine_iterations: 100,
                    ..default.clone()
                },
            ),
            (
                "per-α oracle, E0/(A+B), P4/Q2",
                Params {
                    normals: 48,
                    views: 48,
                    ..norm.clone()
                },
            ),
            (
                "per-α oracle, E0/(A+B), P8/Q2",
                Params {
                    normals: 48,
                    views: 48,
                    p_order: 8,
                    ..norm.clone()
                },
            ),
        ];
        for (name, params) in oracles {
            let t0 = Instant::now();
            let mut per_env = Vec::new();
            let (mut wins, mut total, mut wins_d, mut logs) = (0usize, 0usize, 0usize, Vec::new());
            for e in &envs {
                let mut w_env = 0;
                for &r in &eparams.roughness {
                    let p = Params {
                        alphas: vec![r * r],
                        ..params.clone()
                    };
                    let coeffs = fit::fit_cube(&p, &e.cube, &NoProgress).expect("fit").coeffs;
                    let ep = eval::Params {
                        roughness: vec![r],
                        ..eparams.clone()
                    };
                    let (rep, _) = eval::score(
                        &e.name,
                        &restrict_truth(&e.truth, &eparams, r),
                        &coeffs,
                        &e.ss,
                        &ep,
                        false,
                    );
                    w_env += rep.wins;
                    wins_d += rep.wins_display;
                    total += rep.cases.len();
                    logs.extend(
                        rep.cases
                            .iter()
                            .map(|c| (c.roughness, c.ratio.max(1e-30).ln())),
                    );
                }
                wins += w_env;
                per_env.push(w_env);
            }
            let gm = |f: &dyn Fn(f32) -> bool| {
                let v: Vec<f64> = logs
                    .iter()
                    .filter(|(r, _)| f(*r))
                    .map(|(_, l)| *l)
                    .collect();
                (v.iter().sum::<f64>() / v.len().max(1) as f64).exp()
            };
            shares.push((name.to_string(), wins, total));
            let mut row = format!("| {name} (6 probes) |");
            for w in per_env {
                let _ = write!(row, " {w} |");
            }
            let _ = write!(
                row,
                " {wins}/{total} | **{:.0}%** | {:.0}% | {:.3} | {:.3} | {:.3} | {:.1} |",
                100.0 * wins as f64 / total as f64,
                100.0 * wins_d as f64 / total as f64,
                gm(&|_| true),
                gm(&|r| r == eparams.roughness[0]),
                gm(&|r| r == *eparams.roughness.last().unwrap()),
                t0.elapsed().as_secs_f64()
            );
            let _ = writeln!(md, "{row}");
            eprintln!("{row}");
        }
    }

    // ---- Why one eq. 11 probe stops near 60%, and what lifts it -------------------------------------
    if !quick {
        let _ = writeln!(
            md,
            "\n## Why one eq. 11 probe stops near 60%, and what lifts it\n"
        );
        let _ = writeln!(md, "Ceilings of eq. 11 (P4/Q2, 33 coefficients per channel) with more freedom than one probe has, against the coefficient sets that vary with α (`--alpha-knots`, beyond the paper). \"Scored pixels\": for every environment, roughness and material, eq. 11 fitted to the very sphere pixels it is scored on (log fit; then Gauss–Newton on the linear MSE of E = E0 × Fresnel factor, each view normalised by its own energy, the per-case relative MSE the win count reads) — no eq. 11 coefficients can do much better, short of the optimiser's local minimum.\n");
        let template = fit::fit_cube(&base, &envs[0].cube, &NoProgress)
            .expect("fit")
            .coeffs;
        for refine in [false, true] {
            let t0 = Instant::now();
            let (mut wins, mut total) = (0usize, 0usize);
            let mut per_env = Vec::new();
            let mut by_r: Vec<(usize, usize)> = vec![(0, 0); eparams.roughness.len()];
            for e in &envs {
                let mut w_env = 0;
                for (ri, &r) in eparams.roughness.iter().enumerate() {
                    let ep = eval::Params {
                        roughness: vec![r],
                        ..eparams.clone()
                    };
                    let truth = restrict_truth(&e.truth, &eparams, r);
                    for &(mat, f0) in &eval::MATERIALS {
                        let coeffs =
                            pixel_oracle(&template, &truth, &e.ss, &ep, f0, e.floor, refine);
                        let (rep, _) = eval::score(&e.name, &truth, &coeffs, &e.ss, &ep, false);
                        for c in rep.cases.iter().filter(|c| c.material == mat) {
                            total += 1;
                            by_r[ri].1 += 1;
                            if c.shexp_wins {
                                wins += 1;
                                w_env += 1;
                                by_r[ri].0 += 1;
                            }
                        }
                    }
                }
                per_env.push(w_env);
            }
            let name = if refine {
                "eq. 11 per roughness and material, fitted to the scored pixels, linear refinement"
            } else {
                "eq. 11 per roughness and material, fitted to the scored pixels, log fit"
            };
            let by_r = eparams
                .roughness
                .iter()
                .zip(&by_r)
                .map(|(r, (w, t))| format!("{r}: {w}/{t}"))
                .collect::<Vec<_>>()
                .join(", ");
            let _ = (per_env, t0);
            shares.push((format!("{name} (by r: {by_r})"), wins, total));
            eprintln!("scored-pixel oracle (refine {refine}): {wins}/{total}");
        }
        let pick = |prefix: &str| {
            shares
                .iter()
                .find(|(n, ..)| n.starts_with(prefix))
                .map(|(n, w, t)| (n.clone(), *w, *t))
        };
        let _ = writeln!(
            md,
            "| model | coefficient sets | wins | share |\n|---|---:|---:|---:|"
        );
        for (prefix, sets) in [
            ("default:", "1"),
            ("per-α oracle, paper target, P4/Q2", "6"),
            ("per-α oracle, relative refinement, P4/Q2", "6"),
            (
                "eq. 11 per roughness and material, fitted to the scored pixels, log fit",
                "48 per environment",
            ),
            (
                "eq. 11 per roughness and material, fitted to the scored pixels, linear refinement",
                "48 per environment",
            ),
            (
                "beyond eq. 11: α knots 0.2, 1 (2×33/channel)",
                "2, lerped in α",
            ),
            ("beyond eq. 11: α knots 0.2, 0.5, 1", "3, lerped in α"),
        ] {
            if let Some((n, w, t)) = pick(prefix) {
                let _ = writeln!(
                    md,
                    "| {n} | {sets} | {w}/{t} | **{:.0}%** |",
                    100.0 * w as f64 / t as f64
                );
            }
        }
        let _ = writeln!(md, "\nAt one roughness, eq. 11's 33 coefficients hold enough: fitted per roughness they win most cases, and fitted to the scored pixels nearly all. What one probe cannot do is serve every α with one coefficient set: its only α dependence is the vMF damping (eq. 12), so its undamped DC cannot follow the directional albedo's fall with α (`fit::tests::knots_follow_the_albedo_that_eq_11_cannot`: log residual on a constant environment), and each band must fade exactly as exp(−l(l+1)α/2). Letting the coefficients move linearly in α between two or three knots removes that constraint at 2–3× the memory (still ~1000× below the split-sum chain) and one lerp of the coefficients before the same eq. 11 evaluation per pixel. The knots are an extension: `p` and `q` in the same file stay the eq. 11 fit, so eq. 11 readers (and the paper's comparison) are unaffected. An independent numpy implementation (`bench/crosscheck/shexp.md`: own SH, equirect ground truth, an ideal split-sum prefiltered at the exact α) finds the same on `sunsky`: one eq. 11 probe loses below α ≈ 0.5 however it is fitted, and knots with the linear refinement win the most cases.");
    }

    // ---- Held-out environments and a paper-like split-sum ---------------------------------------
    let _ = writeln!(
        md,
        "\n## Held-out environments and a paper-like split-sum baseline\n"
    );
    let _ = writeln!(md, "No setting was chosen on these (the α-knot settings were chosen on the fixtures). `sunsky`: a synthetic 64² sky (gradient, warm ground) with a 2·10⁴ sun of 3.6° diameter; `city_tilted`: city_512 turned 52° about a skew axis (its content off the fixed camera and row axes); `softbox`: a synthetic dim room with two bright rectangular softboxes (studio-like). Wins out of {}.\n", 2 * eparams.views.len() * eparams.roughness.len());
    let _ = writeln!(
        md,
        "| environment | fit | wins | wins (display) | gm ratio | gm ratio r=0.5 |"
    );
    let _ = writeln!(md, "|---|---|---:|---:|---:|---:|");
    let held_out = held_out_environments(&envs[0].cube);
    for (name, cube) in &held_out {
        let truth = eval::compute_truth(cube, &eparams, &NoProgress);
        let ss = eval::default_split_sum(cube, eparams.ss_size).expect("split-sum chain");
        for (fit_name, params) in [
            ("paper (log)", &base),
            ("default", &default),
            ("α knots 0.2, 1 (beyond eq. 11)", &knots2),
            ("α knots 0.2, 0.5, 1 (beyond eq. 11)", &knots3),
        ] {
            let coeffs = fit::fit_cube(params, cube, &NoProgress)
                .expect("fit")
                .coeffs;
            let (rep, _) = eval::score(name, &truth, &coeffs, &ss, &eparams, false);
            let _ = writeln!(
                md,
                "| {name} | {fit_name} | {}/{} | {} | {:.3} | {:.3} |",
                rep.wins,
                rep.cases.len(),
                rep.wins_display,
                gm_ratio(&rep.cases, None),
                gm_ratio(&rep.cases, Some(eparams.roughness[0]))
            );
        }
    }
    let _ = writeln!(md, "\nThe paper's baseline was weaker than ours on paper: 1024 directional samples per texel and mips clamped to 32² (§5.1). The same fixtures scored against such a chain (`splitsum::prefilter_chain`: GGX filtered importance sampling, 1024 samples, 5 levels from 128², none below 32²):\n");
    let _ = writeln!(
        md,
        "| fit | wins vs ibl-prefilter chain | wins vs paper-like chain |"
    );
    let _ = writeln!(md, "|---|---:|---:|");
    for (fit_name, params) in [("paper (log)", &base), ("default", &default)] {
        let (mut w_ours, mut w_paper, mut total) = (0, 0, 0);
        for e in &envs {
            let coeffs = fit::fit_cube(params, &e.cube, &NoProgress)
                .expect("fit")
                .coeffs;
            let paper_chain = ibl_shexp::splitsum::prefilter_chain(&e.cube, 128, 5, 32, 1024);
            let paper_ss = SplitSum::new(&paper_chain, eval::default_dfg(), "paper-like");
            let (a, _) = eval::score(&e.name, &e.truth, &coeffs, &e.ss, &eparams, false);
            let (b, _) = eval::score(&e.name, &e.truth, &coeffs, &paper_ss, &eparams, false);
            w_ours += a.wins;
            w_paper += b.wins;
            total += a.cases.len();
        }
        let _ = writeln!(md, "| {fit_name} | {w_ours}/{total} | {w_paper}/{total} |");
    }
    let _ = writeln!(md, "\nThe two chains score alike, so the baseline's sample count does not explain the paper's 95%.");

    // ---- Beyond eqs. 11 and 15: a second probe for E1 -----------------------------------------
    if !quick {
        let _ = writeln!(
            md,
            "\n## Beyond eqs. 11 and 15: a second probe for E1 (not the paper's representation)\n"
        );
        let _ = writeln!(md, "Eq. 15 derives E1 from E0 (constant-environment assumption); here E1 gets its own 33-coefficient probe fitted on E1/B (B of the DFG table), so E = F0·E0 + (1−F0)·B·exp(P₁·Q₁): 66×3 floats per probe. Rows from exact 32² summation (E0 and E1 alike). Wins out of 192 on the fixtures.\n");
        let _ = writeln!(
            md,
            "| E0 probe | E1 | objective | wins | share | dielectric wins |"
        );
        let _ = writeln!(md, "|---|---|---|---:|---:|---:|");
        let mut e1_comparisons: Vec<(usize, usize)> = Vec::new();
        for (target, e0_name) in [
            (Target::E0, "E0 (eq. 11)"),
            (Target::E0OverAlbedo, "E0/(A+B)"),
        ] {
            for objective in [Objective::Log, Objective::Relative] {
                let p0 = Params {
                    estimator: EstimatorKind::Exact,
                    target,
                    objective,
                    ..Params::default()
                };
                let (mut wins_eq15, mut wins_two, mut diel_eq15, mut diel_two, mut total) =
                    (0, 0, 0, 0, 0);
                for e in &envs {
                    let mut t = Timings::default();
                    let rows = fit::estimate_rows(&p0, &e.cube, &mut t, &NoProgress);
                    let probe0 = fit::coeffs_from_rows(&p0, &rows, e.floor).expect("solve");
                    let rows1 = e1_rows_over_tail(&p0, &e.cube, &rows);
                    let p1 = Params {
                        target: Target::E0OverAlbedo,
                        ..p0.clone()
                    };
                    let probe1 = fit::coeffs_from_rows(&p1, &rows1, e.floor).expect("solve");
                    let (rep, _) = eval::score(&e.name, &e.truth, &probe0, &e.ss, &eparams, false);
                    wins_eq15 += rep.wins;
                    diel_eq15 += rep
                        .cases
                        .iter()
                        .filter(|c| c.f0 < 1.0 && c.shexp_wins)
                        .count();
                    let (w, d, n) = score_two_probes(&e.truth, &e.ss, &probe0, &probe1, &eparams);
                    wins_two += w;
                    diel_two += d;
                    total += n;
                }
                e1_comparisons.push((diel_eq15, diel_two));
                let obj = if objective == Objective::Log {
                    "log"
                } else {
                    "relative"
                };
                for (e1_name, w, d) in [
                    ("eq. 15, B/(A+B)", wins_eq15, diel_eq15),
                    ("own probe, E1/B", wins_two, diel_two),
                ] {
                    let _ = writeln!(
                        md,
                        "| {e0_name} | {e1_name} | {obj} | {w}/{total} | **{:.0}%** | {d}/{} |",
                        100.0 * w as f64 / total as f64,
                        total / 2
                    );
                }
            }
        }
        let worse = e1_comparisons
            .iter()
            .filter(|(eq15, two)| two < eq15)
            .count();
        let _ = writeln!(
            md,
            "\nWith its own probe E1 loses more dielectric cases than with eq. 15 (E1 = E0·B/(A+B)) in {worse} of {} configurations.",
            e1_comparisons.len()
        );
    }

    // ---- Win rate of the paper's settings, by roughness, and Fresnel tail choice ----------------
    let _ = writeln!(
        md,
        "\n## Paper settings: wins by roughness (all fixtures, both materials, all views)\n"
    );
    let _ = writeln!(md, "| r | α | wins | geometric-mean MSE ratio SH/SS |");
    let _ = writeln!(md, "|---:|---:|---:|---:|");
    for (r, w, n, g) in eval::wins_by_roughness(&paper_reports) {
        let _ = writeln!(md, "| {r:.2} | {:.3} | {w}/{n} | {g:.3} |", r * r);
    }
    if let Some((_, name, reports)) = &best_variant {
        let _ = writeln!(md, "\nBest variant ({name}):\n");
        let _ = writeln!(md, "| r | α | wins | geometric-mean MSE ratio SH/SS |");
        let _ = writeln!(md, "|---:|---:|---:|---:|");
        for (r, w, n, g) in eval::wins_by_roughness(reports) {
            let _ = writeln!(md, "| {r:.2} | {:.3} | {w}/{n} | {g:.3} |", r * r);
        }
    }
    let _ = writeln!(
        md,
        "\n## Fresnel tail (eq. 15): dielectric cases, paper settings\n"
    );
    let _ = writeln!(md, "| environment | mean rel. MSE, eq. 15 as printed (E0·B) | mean rel. MSE, E0·B/(A+B) | cases where B/(A+B) is better | mean rel. MSE, exact E0 × B/(A+B) (eq. 15's floor) | cases where even exact E0 × B/(A+B) loses to split-sum |");
    let _ = writeln!(md, "|---|---:|---:|---:|---:|---:|");
    for r in &paper_reports {
        let d: Vec<&eval::Case> = r.cases.iter().filter(|c| c.f0 < 1.0).collect();
        let rel = |f: &dyn Fn(&eval::Case) -> f64| {
            d.iter().map(|c| f(c) / c.gt_mean_square).sum::<f64>() / d.len() as f64
        };
        let better = d
            .iter()
            .filter(|c| c.mse_shexp_ratio < c.mse_shexp_printed)
            .count();
        let floor_loses = d
            .iter()
            .filter(|c| c.mse_exact_e0_fresnel >= c.mse_split_sum)
            .count();
        let _ = writeln!(
            md,
            "| {} | {:.3e} | {:.3e} | {better}/{} | {:.3e} | {floor_loses}/{} |",
            r.name,
            rel(&|c| c.mse_shexp_printed),
            rel(&|c| c.mse_shexp_ratio),
            d.len(),
            rel(&|c| c.mse_exact_e0_fresnel),
            d.len()
        );
    }
    if let Some(r) = paper_reports.first() {
        let m = &r.memory;
        let _ = writeln!(
            md,
            "\nMemory per probe: SH-exp {} B (33×3 f32); split-sum chain {:?} = {} B as RGBA16F ({:.0}×), {} B as RGB32F ({:.0}×).\n",
            m.shexp_bytes, m.split_sum_sizes, m.split_sum_bytes_rgba16f, m.ratio_rgba16f, m.split_sum_bytes_rgb32f, m.ratio_rgb32f
        );
    }

    // ---- Fig. 8: P orders × Q orders -------------------------------------------------------------
    let orders_p: Vec<usize> = if quick {
        vec![2, 4, 6]
    } else {
        vec![2, 3, 4, 5, 6]
    };
    let orders_q: Vec<usize> = if quick { vec![1, 2] } else { vec![1, 2, 3] };
    let _ = writeln!(md, "## Fig. 8 ablation: MSE at r = 0.5 (α = 0.25) by SH order, normalised to the order-(0,0) fit\n");
    let _ = writeln!(md, "Chrome spheres, all views; MSE summed over the fixtures then divided by the same for a DC-only fit (paper's normalisation). Paper-setting rows (E0 estimated once per environment, then solved for each order pair).\n");
    let mut hdr = String::from("| P \\ Q |");
    for q in &orders_q {
        let _ = write!(hdr, " {q} |");
    }
    let _ = writeln!(md, "{hdr}");
    let _ = writeln!(md, "|---:|{}", "---:|".repeat(orders_q.len()));
    let fig8_params = eval::Params {
        roughness: vec![0.5],
        ..eparams.clone()
    };
    let mut rows_per_env: Vec<Rows> = Vec::new();
    for e in &envs {
        let mut t = Timings::default();
        rows_per_env.push(fit::estimate_rows(&base, &e.cube, &mut t, &NoProgress));
    }
    let chrome_mse = |p: usize, q: usize| -> (f64, f64) {
        let (mut total, mut total_ss) = (0.0, 0.0);
        for (e, rows) in envs.iter().zip(&rows_per_env) {
            let r = rows.with_orders(p, q);
            let coeffs = fit::coeffs_from_rows(
                &Params {
                    p_order: p,
                    q_order: q,
                    ..base.clone()
                },
                &r,
                e.floor,
            )
            .expect("solve");
            let truth = restrict_truth(&e.truth, &eparams, 0.5);
            let (rep, _) = eval::score(&e.name, &truth, &coeffs, &e.ss, &fig8_params, false);
            total += rep
                .cases
                .iter()
                .filter(|c| c.f0 == 1.0)
                .map(|c| c.mse_shexp)
                .sum::<f64>();
            total_ss += rep
                .cases
                .iter()
                .filter(|c| c.f0 == 1.0)
                .map(|c| c.mse_split_sum)
                .sum::<f64>();
        }
        (total, total_ss)
    };
    let (dc, ss_total) = chrome_mse(0, 0);
    let mut series: Vec<ibl_plot::Series> = orders_q
        .iter()
        .map(|q| ibl_plot::Series {
            label: format!("Q order {q}"),
            ..Default::default()
        })
        .collect();
    for p in &orders_p {
        let mut row = format!("| {p} |");
        for (k, q) in orders_q.iter().enumerate() {
            let mse = chrome_mse(*p, *q).0 / dc;
            let _ = write!(row, " {mse:.4} |");
            // Coefficients per channel: (P+1)² for P, (Q+1)² − 1 for Q without its DC term.
            let coeffs = ((p + 1) * (p + 1) + (q + 1) * (q + 1) - 1) as f64;
            if *p == 4 && *q == 2 {
                series[k].default = Some(series[k].points.len());
            }
            series[k].points.push((coeffs, mse));
        }
        let _ = writeln!(md, "{row}");
    }
    let chart = ibl_plot::Chart {
        title: "shexp-fit: normalised chrome MSE at r = 0.5 against SH orders".into(),
        x_label: "coefficients per channel".into(),
        y_label: "MSE / MSE of DC-only fit".into(),
        series,
        targets: vec![(ss_total / dc, "split-sum".into())],
    };
    std::fs::write(out_dir_for_chart().join("shexp.svg"), chart.to_svg()).expect("write shexp.svg");
    let _ = writeln!(md, "\n![MSE against SH orders](shexp.svg)");
    let _ = writeln!(
        md,
        "\nSplit-sum at the same cases, same normalisation: {:.4}\n",
        ss_total / dc
    );
    let _ = writeln!(
        md,
        "Total bench time {:.1} s.",
        t_all.elapsed().as_secs_f64()
    );
    let out = root.join("bench");
    std::fs::create_dir_all(&out).expect("bench folder");
    let path = out.join("shexp.md");
    ibl_core::io::write_atomic(&path, md.as_bytes()).expect("write bench/shexp.md");
    println!("{md}");
    eprintln!("wrote {}", path.display());
}

/// The truth restricted to one roughness of `params.roughness`.
fn restrict_truth(t: &Truth, params: &eval::Params, r: f32) -> Truth {
    let ai = params
        .roughness
        .iter()
        .position(|x| (*x - r).abs() < 1e-6)
        .expect("roughness in the list");
    Truth {
        views: t
            .views
            .iter()
            .map(|(v, px)| {
                (
                    *v,
                    px.iter()
                        .map(|p| eval::TruthPixel {
                            idx: p.idx,
                            n: p.n,
                            gt: vec![p.gt[ai]],
                            gt2: p.gt2.as_ref().map(|g| vec![g[ai]]),
                        })
                        .collect(),
                )
            })
            .collect(),
        seconds: t.seconds,
        face_size: t.face_size,
    }
}

/// Eq. 11 fitted to the scored pixels of `truth` (one roughness, one material): log-space
/// least squares on E/k, then the relative linear refinement on E with one group per view, where
/// k is the Fresnel factor of `template`'s tail. The returned probe has `template`'s metadata.
fn pixel_oracle(
    template: &ibl_shexp::Coeffs,
    truth: &Truth,
    ss: &SplitSum,
    ep: &eval::Params,
    f0: f32,
    floor: [f64; 3],
    refine: bool,
) -> ibl_shexp::Coeffs {
    use ibl_shexp::basis::{self, Features};
    let (po, qo) = (template.p_order, template.q_order);
    let k = basis::num_unknowns(po, qo);
    let r = ep.roughness[0];
    let vmf = basis::vmf_factors(po.max(qo), r * r);
    let (mut a, mut group, mut fac, mut e) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for (vi, (v, pixels)) in truth.views.iter().enumerate() {
        for p in pixels {
            let mut f = Features::new(po, qo);
            f.eval(p.n, *v);
            let mut row = vec![0.0f64; k];
            f.row(&vmf, &mut row);
            a.extend(row);
            group.push(vi);
            let kf = ss
                .dfg
                .shexp_fresnel_factor(p.n.dot(*v).max(0.0), r, f0, template.fresnel)
                as f64;
            fac.push(kf.max(1e-6));
            let (g0, g1) = &p.gt[0];
            e.push(std::array::from_fn::<f64, 3, _>(|c| {
                f0 as f64 * g0[c] + (1.0 - f0 as f64) * g1[c]
            }));
        }
    }
    let m = group.len();
    let rhs: Vec<Vec<f64>> = (0..3)
        .map(|c| {
            (0..m)
                .map(|i| (e[i][c] / fac[i]).max(floor[c]).ln())
                .collect()
        })
        .collect();
    let start = ibl_shexp::solve::least_squares(&a, m, k, &rhs).expect("full rank");
    let weight: Vec<f64> = fac.iter().map(|f| f * f).collect();
    let x: Vec<Vec<f64>> = (0..3)
        .map(|c| {
            let target: Vec<f64> = (0..m).map(|i| e[i][c] / fac[i]).collect();
            let problem = ibl_shexp::refine::RelativeProblem {
                a: &a,
                m,
                k,
                target: &target,
                weight: &weight,
                group: &group,
                log_weight: 0.0,
            };
            if refine {
                problem.refine(&start.x[c], 100, 1e-9).0
            } else {
                start.x[c].clone()
            }
        })
        .collect();
    let np = basis::coeffs_of_order(po);
    let mut out = template.clone();
    out.alphas = vec![r * r];
    out.p = (0..np)
        .map(|i| std::array::from_fn(|c| x[c][i] as f32))
        .collect();
    out.q = (np..k)
        .map(|i| std::array::from_fn(|c| x[c][i] as f32))
        .collect();
    out
}

/// Environments no setting was chosen on: a synthetic sky with a strong sun, the city turned
/// about a skew axis, and a synthetic softbox studio.
fn held_out_environments(city: &Cubemap) -> Vec<(String, Cubemap)> {
    use glam::{Quat, Vec3};
    let sun = Vec3::new(0.3, 0.5, -0.6).normalize();
    let sunsky = Cubemap::from_fn(64, |d| {
        let sky = if d.y > 0.0 {
            [0.3 + 0.5 * (1.0 - d.y), 0.5 + 0.4 * (1.0 - d.y), 1.0]
        } else {
            [0.25, 0.2, 0.15]
        };
        let s = if d.dot(sun) > 0.9995 { 2e4 } else { 0.0 };
        [sky[0] + s, sky[1] + s * 0.95, sky[2] + s * 0.85]
    });
    let rot = Quat::from_axis_angle(Vec3::new(1.0, 0.2, 0.3).normalize(), 0.9);
    let tilted = Cubemap::from_fn(64, |d| city.sample_bilinear(rot * d));
    // A dim room lit by two rectangular softboxes and a warm floor patch (studio-like: small,
    // bright, hard-edged lights, the hardest case among the fixtures).
    let boxes = [
        (Vec3::new(1.0, 0.6, 0.3), 0.35, 0.25, [40.0, 38.0, 35.0]),
        (Vec3::new(-0.8, 0.3, -0.7), 0.15, 0.4, [15.0, 16.0, 18.0]),
        (Vec3::new(0.1, -1.0, 0.2), 0.5, 0.5, [0.3, 0.25, 0.2]),
    ];
    let softbox = Cubemap::from_fn(64, |d| {
        let mut c = [0.05, 0.05, 0.06].map(|v| v * (1.0 + 0.5 * d.y));
        for (centre, half_w, half_h, value) in boxes {
            let n = centre.normalize();
            let right = Vec3::Y.cross(n).normalize();
            let up = n.cross(right);
            let dn = d.dot(n);
            if dn > 0.0 && (d.dot(right) / dn).abs() < half_w && (d.dot(up) / dn).abs() < half_h {
                for k in 0..3 {
                    c[k] += value[k];
                }
            }
        }
        c
    });
    vec![
        ("sunsky".into(), sunsky),
        ("city_tilted".into(), tilted),
        ("softbox".into(), softbox),
    ]
}

/// Geometric mean of MSE(SH-exp)/MSE(split-sum), over all cases or one roughness.
fn gm_ratio(cases: &[eval::Case], roughness: Option<f32>) -> f64 {
    let v: Vec<f64> = cases
        .iter()
        .filter(|c| roughness.is_none_or(|r| c.roughness == r))
        .map(|c| c.ratio.max(1e-30).ln())
        .collect();
    (v.iter().sum::<f64>() / v.len().max(1) as f64).exp()
}

/// The rows of `rows` (estimated for `params`) with E1·(A+B)/B in place of E0, so that a fit
/// with target E0/(A+B) reconstructs E1/B. E1 by exact summation over the same
/// `exact_size` cube the exact E0 estimator uses, in the same row order (normal, view, α).
fn e1_rows_over_tail(params: &Params, cube: &Cubemap, rows: &Rows) -> Rows {
    use ibl_core::envmap::Environment;
    use ibl_core::equirect::Filter;
    let small = Environment::Cube(cube.clone()).to_cube(
        params.exact_size.min(cube.size),
        Filter::Area,
        0.0,
        &NoProgress,
    );
    let set = ibl_shexp::truth::TexelSet::from_cube(&small);
    let views: Vec<glam::Vec3> = (0..rows.views)
        .map(|k| ibl_shexp::basis::fibonacci_hemisphere(k, rows.views))
        .collect();
    let dfg = ibl_shexp::dfg::Dfg::standard();
    let na = rows.alphas.len();
    let mut out = vec![([0.0; 3], [0.0; 3]); na];
    let mut e1 = Vec::with_capacity(rows.e0.len());
    for i in 0..rows.normals {
        let (frame, world) = fit::row_geometry(i, rows.normals, &views);
        for v in world {
            set.e0_e1(frame.2, v, &rows.alphas, &mut out);
            let nv = frame.2.dot(v);
            for (a, o) in rows.alphas.iter().zip(&out) {
                let (da, db) = dfg.ab(nv, a.sqrt());
                let k = ((da + db) / db.max(1e-6)) as f64;
                e1.push(o.1.map(|c| c * k));
            }
        }
    }
    let mut r = rows.with_orders(rows.p_order, rows.q_order);
    r.e0 = e1;
    r
}

/// Wins of E = F0·E0 + (1−F0)·E1 with E0 from `probe0` and E1 = B·exp(P₁·Q₁) from `probe1`
/// against the split-sum: (wins, dielectric wins, cases).
fn score_two_probes(
    truth: &Truth,
    ss: &SplitSum,
    probe0: &ibl_shexp::Coeffs,
    probe1: &ibl_shexp::Coeffs,
    ep: &eval::Params,
) -> (usize, usize, usize) {
    let (mut wins, mut diel, mut cases) = (0, 0, 0);
    for &(_, f0) in eval::MATERIALS.iter() {
        for (v, pixels) in &truth.views {
            for (ai, &r) in ep.roughness.iter().enumerate() {
                let alpha = r * r;
                let (mut e_ss, mut e_sh) = (0.0f64, 0.0f64);
                for px in pixels {
                    let nv = px.n.dot(*v).max(0.0);
                    let (a, b) = ss.dfg.ab(nv, r);
                    let scale0 = match probe0.target {
                        Target::E0 => 1.0,
                        Target::E0OverAlbedo => a + b,
                    };
                    let e0 = probe0.e0(px.n, *v, alpha);
                    let e1 = probe1.e0(px.n, *v, alpha);
                    let ssv = ss.specular(px.n, *v, r, f0);
                    let (g0, g1) = px.gt[ai];
                    for k in 0..3 {
                        let gt = f0 as f64 * g0[k] + (1.0 - f0 as f64) * g1[k];
                        let sh = f0 * scale0 * e0[k] + (1.0 - f0) * b * e1[k];
                        e_ss += (ssv[k] as f64 - gt).powi(2);
                        e_sh += (sh as f64 - gt).powi(2);
                    }
                }
                let win = e_sh < e_ss;
                wins += usize::from(win);
                diel += usize::from(win && f0 < 1.0);
                cases += 1;
            }
        }
    }
    (wins, diel, cases)
}
