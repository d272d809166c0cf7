//! Fits the shipped method's blend rule (issue 23 item 6, goal G2) and writes
//! bench/aniso-blend.md: w(η) = clamp(|η|/η₁, 0, 1)^p mixes the isotropic split sum (w = 0,
//! exactly the floor at η = 0) into VNDF filtered importance sampling (w = 1). (η₁, p) are
//! chosen on the training environments only; the held-out environments are scored once with
//! the chosen rule and with the constants `ibl_aniso::ship::SHIPPED` carries.
//!
//! cargo run --release -p ibl-aniso --example fit-ibl-aniso-blend -- [--quick]

use ibl_aniso::eval::{self, Env, LookupChoice, Params};
use ibl_aniso::methods::E01;
use ibl_aniso::truth::TruthValue;
use ibl_core::envmap::load_environment;
use ibl_core::equirect::Filter;
use ibl_core::progress::NoProgress;
use std::fmt::Write;
use std::path::PathBuf;
use std::time::Instant;

/// One case's per-pixel data: the truth, the floor and fis-16.
struct Data {
    env: String,
    r: f32,
    eta: f32,
    truth: Vec<TruthValue>,
    iso: Vec<E01>,
    fis: Vec<E01>,
    bent: Vec<E01>,
}

/// MSE per pixel and channel of (1−w)·iso + w·fis against the truth at F0, and the truth's
/// own mean squared standard error.
fn mse(d: &Data, w: f32, f0: f64) -> (f64, f64) {
    let (mut se, mut te) = (0.0f64, 0.0f64);
    for ((t, a), b) in d.truth.iter().zip(&d.iso).zip(&d.fis) {
        let c = t.radiance(f0);
        let s = t.radiance_se(f0);
        for k in 0..3 {
            // The shipped blend's form: iso + (fis − iso)·w, per E0 and E1.
            let e0 = a.0[k] + (b.0[k] - a.0[k]) * w;
            let e1 = a.1[k] + (b.1[k] - a.1[k]) * w;
            let m = f0 * e0 as f64 + (1.0 - f0) * e1 as f64;
            se += (m - c[k]).powi(2);
            te += s[k] * s[k];
        }
    }
    let n = (3 * d.truth.len()).max(1) as f64;
    (se / n, te / n)
}

fn rule(eta: f32, eta1: f32, p: f32) -> f32 {
    (eta.abs() / eta1).clamp(0.0, 1.0).powf(p)
}

/// Whether the truth's error is below 1% of the better of iso and fis at both F0 (the
/// evaluator's gate).
fn gated(d: &Data) -> bool {
    [1.0, 0.04].iter().all(|&f0| {
        let (a, t) = mse(d, 0.0, f0);
        let (b, _) = mse(d, 1.0, f0);
        t < 0.01 * a.min(b)
    })
}

/// Geometric mean over `cases` and both F0 of MSE(rule)/MSE(fis-16).
fn score(cases: &[&Data], eta1: f32, p: f32) -> f64 {
    let mut lg = 0.0;
    let mut n = 0;
    for d in cases {
        for f0 in [1.0, 0.04] {
            let (a, _) = mse(d, rule(d.eta, eta1, p), f0);
            let (b, _) = mse(d, 1.0, f0);
            lg += ((a + 1e-30) / (b + 1e-30)).ln();
            n += 1;
        }
    }
    (lg / n.max(1) as f64).exp()
}

fn main() {
    let quick = std::env::args().any(|a| a == "--quick");
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..");
    let (train, test): (&[&str], &[&str]) = if quick {
        (&["sunset_256"], &["interior_256"])
    } else {
        (&["sunset_256", "interior_256"], &["city_512", "studio_256"])
    };
    let params = Params {
        sphere_size: if quick { 12 } else { 16 },
        roughness: if quick {
            vec![0.2, 0.6]
        } else {
            vec![0.2, 0.4, 0.6, 0.8, 1.0]
        },
        eta: if quick {
            vec![0.0, 0.1, 0.5]
        } else {
            vec![0.0, 0.1, 0.2, 0.35, 0.5, 0.8]
        },
        views: vec![30.0],
        elevations: vec![15.0],
        methods: vec!["iso".into(), "fis-16".into(), "bent-lg18".into()],
        lookup: LookupChoice::Engine,
        truth_samples: if quick { 16384 } else { 32768 },
        no_pixels: true,
        ..Default::default()
    };
    let (parsed, preset) = params.validate().expect("fit parameters");
    let t_all = Instant::now();
    let mut data: Vec<Data> = Vec::new();
    for name in train.iter().chain(test) {
        let path = root.join(format!("fixtures/hdri/{name}.exr"));
        let loaded = load_environment(&path, false).expect("fixture");
        let size = loaded.env.natural_face_size();
        let cube = loaded.env.to_cube(size, Filter::Area, 0.0, &NoProgress);
        let pp = ibl_prefilter::Params {
            size: size.clamp(8, 256),
            ..Default::default()
        };
        let chain = ibl_prefilter::bake::bake_chain(&pp, &loaded.env, &NoProgress).expect("chain");
        let env = Env::new(name.to_string(), cube, &chain.mips, String::new(), &params);
        let t0 = Instant::now();
        let (cases, images) = eval::evaluate(&env, &params, &parsed, &preset);
        eprintln!(
            "{name}: {} cases in {:.1} s",
            cases.len(),
            t0.elapsed().as_secs_f64()
        );
        for (c, im) in cases.iter().zip(images) {
            let get = |m: &str| {
                im.methods
                    .iter()
                    .find(|x| x.0 == m)
                    .map(|x| x.2.clone())
                    .expect("method ran")
            };
            data.push(Data {
                env: c.env.clone(),
                r: c.r,
                eta: c.eta,
                iso: get("iso"),
                fis: get("fis-16"),
                bent: get("bent-lg18"),
                truth: im.truth,
            });
        }
    }
    let tr: Vec<&Data> = data
        .iter()
        .filter(|d| train.contains(&d.env.as_str()) && gated(d))
        .collect();
    let te: Vec<&Data> = data
        .iter()
        .filter(|d| test.contains(&d.env.as_str()) && gated(d))
        .collect();
    let eta1s = [0.02f32, 0.05, 0.1, 0.15, 0.2, 0.3, 0.4, 0.5, 0.6, 0.8, 1.0];
    let ps = [0.5f32, 1.0, 2.0];
    let mut grid: Vec<(f32, f32, f64)> = Vec::new();
    for &e in &eta1s {
        for &p in &ps {
            grid.push((e, p, score(&tr, e, p)));
        }
    }
    let best = *grid
        .iter()
        .min_by(|a, b| a.2.total_cmp(&b.2))
        .expect("a grid");
    let shipped = ibl_aniso::ship::SHIPPED;
    let mut md = String::new();
    let _ = writeln!(
        md,
        "# Anisotropic IBL: the shipped blend rule (issue 23 G2)\n\n\
         Generated by `cargo run --release -p ibl-aniso --example fit-ibl-aniso-blend{}` in {:.0} s \
         ({} cores, shared with other jobs: timings are indicative only). Spheres of {}² px, r {:?}, \
         η {:?}, azimuth 30°, elevation 15°, truth {} MC samples, gltf chain (engine lookup). \
         Rule: specular = iso + (fis-16 − iso)·w, w = clamp(|η|/η₁, 0, 1)^p; w = 0 reads only \
         the isotropic split sum (exactly the floor at η = 0). Fitted on {train:?} ({} gated \
         cases), scored on {test:?} ({} gated cases). Score: geometric mean over cases and \
         F0 ∈ {{1, 0.04}} of MSE(rule) / MSE(fis-16).\n",
        if quick { " -- --quick" } else { "" },
        t_all.elapsed().as_secs_f64(),
        std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1),
        params.sphere_size,
        params.roughness,
        params.eta,
        params.truth_samples,
        tr.len(),
        te.len(),
    );
    let _ = writeln!(
        md,
        "## Training score\n\n| η₁ \\ p | {} |",
        ps.map(|p| p.to_string()).join(" | ")
    );
    let _ = writeln!(md, "|---|{}", "---|".repeat(ps.len()));
    for &e in &eta1s {
        let row: Vec<String> = ps
            .iter()
            .map(|&p| {
                let s = grid.iter().find(|g| g.0 == e && g.1 == p).unwrap().2;
                format!("{s:.4}")
            })
            .collect();
        let _ = writeln!(md, "| {e} | {} |", row.join(" | "));
    }
    assert!(
        best.0 == shipped.blend_eta && best.1 == shipped.blend_power || quick,
        "SHIPPED ({}, {}) is not the training optimum ({}, {}): update ship.rs",
        shipped.blend_eta,
        shipped.blend_power,
        best.0,
        best.1
    );
    let _ = writeln!(
        md,
        "\nChosen on training: **η₁ = {}, p = {}** (score {:.4}). Shipped (`ibl_aniso::ship::SHIPPED`): \
         η₁ = {}, p = {}.\n",
        best.0, best.1, best.2, shipped.blend_eta, shipped.blend_power
    );
    let _ = writeln!(
        md,
        "## Held-out, per η (F0 = 1): geometric-mean MSE ratio, and worst MSE / iso\n\n\
         | η | cases | shipped / fis-16 (gm) | shipped / iso (gm) | worst shipped / iso | worst fis-16 / iso | shipped wins vs fis-16 |\n\
         |---|---|---|---|---|---|---|"
    );
    for &e in &params.eta {
        let cs: Vec<&&Data> = te.iter().filter(|d| d.eta == e).collect();
        if cs.is_empty() {
            let _ = writeln!(md, "| {e} | 0 | | | | | |");
            continue;
        }
        let (mut lf, mut li, mut wi, mut wf, mut wins) = (0.0, 0.0, 0.0f64, 0.0f64, 0);
        for d in &cs {
            let w = rule(d.eta, shipped.blend_eta, shipped.blend_power);
            let (s, _) = mse(d, w, 1.0);
            let (i, _) = mse(d, 0.0, 1.0);
            let (f, _) = mse(d, 1.0, 1.0);
            lf += (s / f).ln();
            li += (s / i).ln();
            wi = wi.max(s / i);
            wf = wf.max(f / i);
            wins += usize::from(s < f);
        }
        let n = cs.len() as f64;
        let _ = writeln!(
            md,
            "| {e} | {} | {:.3} | {:.3} | {wi:.3} | {wf:.3} | {wins}/{} |",
            cs.len(),
            (lf / n).exp(),
            (li / n).exp(),
            cs.len()
        );
    }
    // The goals on the held-out gated cases, F0 = 1: G1 wins vs the LG18 bent normal, G3 wins
    // vs fis-16, and the floor.
    let mse_of = |d: &Data, est: &[E01]| -> f64 {
        let mut se = 0.0f64;
        for (t, e) in d.truth.iter().zip(est) {
            let c = t.radiance(1.0);
            for (x, y) in e.0.iter().zip(c) {
                se += (*x as f64 - y).powi(2);
            }
        }
        se / (3 * d.truth.len()).max(1) as f64
    };
    let (mut g1, mut g3, mut gi, mut n) = (0, 0, 0, 0);
    for d in &te {
        let w = rule(d.eta, shipped.blend_eta, shipped.blend_power);
        let s = mse(d, w, 1.0).0;
        g1 += usize::from(s < mse_of(d, &d.bent));
        g3 += usize::from(s < mse(d, 1.0, 1.0).0);
        gi += usize::from(s <= mse(d, 0.0, 1.0).0);
        n += 1;
    }
    let (mut f1, mut fi) = (0, 0);
    for d in &te {
        f1 += usize::from(mse(d, 1.0, 1.0).0 < mse_of(d, &d.bent));
        fi += usize::from(mse(d, 1.0, 1.0).0 <= mse(d, 0.0, 1.0).0);
    }
    let _ = writeln!(
        md,
        "\nHeld-out, every η (F0 = 1, {n} gated cases): the shipped fisb-16 beats the LG18 bent \
         normal in {g1}/{n} (fis-16: {f1}/{n}), is at or below the isotropic floor in {gi}/{n} \
         (fis-16: {fi}/{n}), and beats fis-16 in {g3}/{n} (equal to it from |η| ≥ η₁)."
    );
    let all: Vec<&Data> = data.iter().filter(|d| gated(d) && d.eta == 0.0).collect();
    let worst = all
        .iter()
        .map(|d| {
            let w = rule(d.eta, shipped.blend_eta, shipped.blend_power);
            (
                mse(d, w, 1.0).0 / mse(d, 0.0, 1.0).0,
                mse(d, 1.0, 1.0).0 / mse(d, 0.0, 1.0).0,
                d,
            )
        })
        .fold((0.0f64, 0.0f64, String::new()), |acc, (s, f, d)| {
            let tag = if f > acc.1 {
                format!("{} r {}", d.env, d.r)
            } else {
                acc.2.clone()
            };
            (acc.0.max(s), acc.1.max(f), tag)
        });
    let _ = writeln!(
        md,
        "\nEvery environment (training too), η = 0, gated cases: worst MSE / iso shipped {:.3}, \
         fis-16 {:.3} ({}).",
        worst.0, worst.1, worst.2
    );
    let out = root.join("bench").join(if quick {
        "aniso-blend-quick.md"
    } else {
        "aniso-blend.md"
    });
    std::fs::write(&out, md).unwrap();
    eprintln!(
        "wrote {} in {:.1} s",
        out.display(),
        t_all.elapsed().as_secs_f64()
    );
}
