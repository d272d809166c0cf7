//! Fits the shipped method's blend rule (issue 23 item 6, goals G1 and G2) and writes
//! bench/aniso-blend.md: w = max(clamp(|η|/η₁, 0, 1)^p, clamp((r − r₀)/Δr, 0, 1)) mixes the
//! isotropic split sum (w = 0, exactly the floor) into VNDF filtered importance sampling
//! (w = 1). The rule is chosen on the training environments only: the family (η₁ constant, or
//! η₁(r) = a + b·r; each with or without the roughness ramp) by leave-one-environment-out
//! cross-validation, its constants by the score over every training case among the rules that
//! keep goal G2 on training (every gated η = 0 case at most 1.05× the floor's MSE); the
//! held-out environments are scored once, with `ibl_aniso::ship::fis_weight` (the function the
//! emulation and the snippets carry). The run fails unless `ibl_aniso::ship::SHIPPED` is that
//! training optimum.
//!
//! cargo run --release -p ibl-aniso --example fit-ibl-aniso-blend -- [--quick] [--dump FILE]
//! [--load FILE] (`--load` reads a `--dump` of the same grid instead of rendering it again)

use ibl_aniso::eval::{self, Env, LookupChoice, Params};
use ibl_aniso::material::Material;
use ibl_core::envmap::load_environment;
use ibl_core::equirect::Filter;
use ibl_core::progress::NoProgress;
use std::fmt::Write;
use std::path::PathBuf;
use std::time::Instant;

/// One case at one F0: the blend's MSE as a quadratic in w, MSE(w) = uu + 2·uv·w + vv·w²
/// (per pixel and channel, f64; w = 1 is FIS at the shipped lod bias), the LG18 bent normal's
/// MSE, the published FIS's (Křivánek & Colbert's +1 bias, goal G3's baseline) and the truth's
/// mean squared standard error.
#[derive(Clone, Copy, Default)]
struct Quad {
    uu: f64,
    uv: f64,
    vv: f64,
    bent: f64,
    kc: f64,
    truth: f64,
}

/// The evaluator's name of FIS at the shipped taps and lod bias (`fis-16-b0`; `fis-16` when
/// the shipped bias is the published +1).
fn shipped_fis() -> String {
    let s = ibl_aniso::ship::SHIPPED;
    ibl_aniso::methods::Method::Fis {
        taps: s.taps as usize,
        lod_bias: s.lod_bias,
    }
    .name()
}

/// One case: where it is and its two F0 (1, 0.04).
struct Data {
    env: String,
    r: f32,
    eta: f32,
    azimuth: f32,
    q: [Quad; 2],
}

/// The F0 values, in `Data::q` order.
const F0S: [f64; 2] = [1.0, 0.04];

/// MSE of iso + (fis − iso)·w at F0 index `f` (the blend is linear in w, so exact).
fn mse(d: &Data, w: f32, f: usize) -> f64 {
    let (q, w) = (&d.q[f], w as f64);
    q.uu + 2.0 * q.uv * w + q.vv * w * w
}

/// A candidate rule: η₁(r) = eta1 + slope·r (floored at 10⁻³), w = clamp(|η|/η₁, 0, 1)^p
/// (0 at η = 0), raised to the roughness ramp clamp((r − r0)/dr, 0, 1) (none: r0 = ∞).
#[derive(Clone, Copy, Debug, PartialEq)]
struct Rule {
    eta1: f32,
    slope: f32,
    p: f32,
    r0: f32,
    dr: f32,
}

impl Rule {
    fn weight(&self, r: f32, eta: f32) -> f32 {
        let ramp = if self.r0.is_finite() {
            ((r - self.r0) / self.dr).clamp(0.0, 1.0)
        } else {
            0.0
        };
        if eta == 0.0 {
            return ramp;
        }
        let e1 = (self.eta1 + self.slope * r).max(1e-3);
        (eta.abs() / e1).clamp(0.0, 1.0).powf(self.p).max(ramp)
    }
}

/// Goal G2's bound: MSE / the isotropic floor's at η = 0.
const G2_BOUND: f64 = 1.05;

/// The worst MSE(rule) / MSE(iso) over the η = 0 cases of `cases` and both F0 (1 when none).
fn worst_at_eta0(cases: &[&Data], weight: impl Fn(&Data) -> f32) -> f64 {
    cases
        .iter()
        .filter(|d| d.eta == 0.0)
        .flat_map(|d| {
            let w = weight(d);
            (0..2).map(move |f| mse(d, w, f) / mse(d, 0.0, f))
        })
        .fold(1.0, f64::max)
}

/// The shipped weight of the case's lobe: `ship::fis_weight` of its (α_t, α_b).
fn shipped_weight(d: &Data) -> f32 {
    let (at, ab) = Material::ggx_kc(d.r, d.eta)
        .ggx_alphas()
        .expect("a GGX lobe");
    ibl_aniso::ship::fis_weight(at, ab)
}

/// Whether the truth's error is below 1% of the better of iso and fis at both F0 (the
/// evaluator's gate).
fn gated(d: &Data) -> bool {
    (0..2).all(|f| d.q[f].truth < 0.01 * mse(d, 0.0, f).min(mse(d, 1.0, f)))
}

/// Geometric mean over `cases` and both F0 of MSE(weight)/MSE(FIS at the shipped bias).
fn score(cases: &[&Data], weight: impl Fn(&Data) -> f32) -> f64 {
    let mut lg = 0.0;
    let mut n = 0;
    for d in cases {
        let w = weight(d);
        for f in 0..2 {
            lg += ((mse(d, w, f) + 1e-30) / (mse(d, 1.0, f) + 1e-30)).ln();
            n += 1;
        }
    }
    (lg / n.max(1) as f64).exp()
}

/// The exponents and constant η₁ of the grid (also the table's rows and columns).
const PS: [f32; 9] = [0.15, 0.2, 0.25, 0.3, 0.4, 0.5, 0.75, 1.0, 2.0];
const ETA1S: [f32; 13] = [
    0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 1.0, 1.2, 1.5, 2.0,
];

/// The roughness ramps' starts r₀ and widths Δr (a step, Δr = 0, would show as a seam on a
/// roughness-textured surface).
const R0S: [f32; 17] = [
    0.2, 0.25, 0.3, 0.35, 0.4, 0.45, 0.5, 0.55, 0.6, 0.65, 0.7, 0.75, 0.8, 0.85, 0.9, 0.95, 1.0,
];
const DRS: [f32; 4] = [0.1, 0.2, 0.3, 0.4];

/// No roughness ramp, and every ramp of the grid.
fn ramps() -> Vec<(f32, f32)> {
    let mut v = vec![(f32::INFINITY, 1.0)];
    v.extend(
        R0S.iter()
            .flat_map(|&r0| DRS.iter().map(move |&dr| (r0, dr))),
    );
    v
}

/// Every rule of a family: η₁ constant (`linear` false) or η₁(r) = a + b·r, a ∈ 0.05…2,
/// b ∈ −1.6…1.6 in steps of 0.05; each with every ramp of [`ramps`].
fn family(linear: bool) -> Vec<Rule> {
    let mut out = Vec::new();
    for (r0, dr) in ramps() {
        for &p in &PS {
            if linear {
                for i in 1..=40 {
                    for j in -32..=32 {
                        out.push(Rule {
                            eta1: i as f32 * 0.05,
                            slope: j as f32 * 0.05,
                            p,
                            r0,
                            dr,
                        });
                    }
                }
            } else {
                for &eta1 in &ETA1S {
                    out.push(Rule {
                        eta1,
                        slope: 0.0,
                        p,
                        r0,
                        dr,
                    });
                }
            }
        }
    }
    out
}

/// The rule of `rules` with the lowest training score on `cases` among those within goal G2
/// on them ([`G2_BOUND`]; the first on ties).
fn best(cases: &[&Data], rules: &[Rule]) -> (Rule, f64) {
    rules
        .iter()
        .filter(|r| worst_at_eta0(cases, |d| r.weight(d.r, d.eta)) <= G2_BOUND)
        .map(|r| (*r, score(cases, |d| r.weight(d.r, d.eta))))
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .expect("a family")
}

/// Cases of a `--dump` file: each case's rows at every F0 of [`F0S`], in that order, with the
/// same env, azimuth, r and η. Anything else (a short or non-numeric row, a missing or
/// out-of-order F0) is refused with the file and line, not filled in.
fn load_dump(path: &str) -> Result<Vec<Data>, String> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("{path}: {e}"))?;
    let mut out: Vec<Data> = Vec::new();
    let mut lines = text.lines().enumerate().skip(1).peekable();
    while lines.peek().is_some() {
        let mut case: Option<Data> = None;
        for (f, &f0) in F0S.iter().enumerate() {
            let (k, line) = lines
                .next()
                .ok_or_else(|| format!("{path}: ends inside a case (no F0 = {f0} row)"))?;
            let at = format!("{path}:{}", k + 1);
            let c: Vec<&str> = line.split('\t').collect();
            if c.len() != 13 {
                return Err(format!("{at}: {} columns, expected 13", c.len()));
            }
            let num = |k: usize| -> Result<f64, String> {
                c[k].parse()
                    .map_err(|_| format!("{at}: column {} is not a number: {:?}", k + 1, c[k]))
            };
            if num(4)? != f0 {
                return Err(format!("{at}: F0 {} where {f0} was expected", c[4]));
            }
            let q = Quad {
                uu: num(6)?,
                uv: num(7)?,
                vv: num(8)?,
                bent: num(10)?,
                kc: num(11)?,
                truth: num(12)?,
            };
            let (azimuth, r, eta) = (num(1)? as f32, num(2)? as f32, num(3)? as f32);
            match &mut case {
                None => {
                    case = Some(Data {
                        env: c[0].to_string(),
                        azimuth,
                        r,
                        eta,
                        q: [q, Quad::default()],
                    })
                }
                Some(d) => {
                    if (d.env.as_str(), d.azimuth, d.r, d.eta) != (c[0], azimuth, r, eta) {
                        return Err(format!("{at}: not the same case as the row before"));
                    }
                    d.q[f] = q;
                }
            }
        }
        out.extend(case);
    }
    Ok(out)
}

/// The per-pixel sums of one case at F0 `f0`.
fn quad(im: &eval::CaseImages, f0: f64) -> Quad {
    let get = |m: &str| &im.methods.iter().find(|x| x.0 == m).expect("method ran").2;
    let fis_name = shipped_fis();
    let (iso, fis, bent) = (get("iso"), get(&fis_name), get("bent-lg18"));
    let kc = get("fis-16");
    let mut q = Quad::default();
    for ((((t, a), b), g), h) in im.truth.iter().zip(iso).zip(fis).zip(bent).zip(kc) {
        let c = t.radiance(f0);
        let s = t.radiance_se(f0);
        for k in 0..3 {
            // The shipped blend iso + (fis − iso)·w, per E0 and E1, then Schlick at F0.
            let ma = f0 * a.0[k] as f64 + (1.0 - f0) * a.1[k] as f64;
            let mb = f0 * b.0[k] as f64 + (1.0 - f0) * b.1[k] as f64;
            let mg = f0 * g.0[k] as f64 + (1.0 - f0) * g.1[k] as f64;
            let mh = f0 * h.0[k] as f64 + (1.0 - f0) * h.1[k] as f64;
            let (u, v) = (ma - c[k], mb - ma);
            q.uu += u * u;
            q.uv += u * v;
            q.vv += v * v;
            q.bent += (mg - c[k]).powi(2);
            q.kc += (mh - c[k]).powi(2);
            q.truth += s[k] * s[k];
        }
    }
    let n = (3 * im.truth.len()).max(1) as f64;
    for x in [
        &mut q.uu,
        &mut q.uv,
        &mut q.vv,
        &mut q.bent,
        &mut q.kc,
        &mut q.truth,
    ] {
        *x /= n;
    }
    q
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let quick = args.iter().any(|a| a == "--quick");
    let dump = args
        .iter()
        .position(|a| a == "--dump")
        .map(|i| args.get(i + 1).expect("--dump FILE").clone());
    let load = args
        .iter()
        .position(|a| a == "--load")
        .map(|i| args.get(i + 1).expect("--load FILE").clone());
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
        methods: {
            let mut m: Vec<String> = vec!["iso".into(), "fis-16".into(), "bent-lg18".into()];
            if shipped_fis() != "fis-16" {
                m.push(shipped_fis());
            }
            m
        },
        lookup: LookupChoice::Engine,
        truth_samples: if quick { 16384 } else { 32768 },
        no_pixels: true,
        ..Default::default()
    };
    // Training sees each environment from three azimuths and with a 4× truth: at 32768 samples
    // the truth's error kept every r ≥ 0.4, η ≤ 0.2 training case out of the gate, so the rule
    // was unconstrained exactly where it lost held out (docs/notes/aniso-g1.md). The held-out
    // grid stays the one the previous rule was scored on.
    let train_params = Params {
        views: if quick {
            params.views.clone()
        } else {
            vec![30.0, 150.0, 270.0]
        },
        truth_samples: if quick {
            params.truth_samples
        } else {
            4 * params.truth_samples
        },
        ..params.clone()
    };
    let (parsed, preset) = params.validate().expect("fit parameters");
    let t_all = Instant::now();
    let mut data: Vec<Data> = match load.as_deref().map(load_dump).transpose() {
        Ok(d) => d.unwrap_or_default(),
        Err(e) => {
            eprintln!("fit-ibl-aniso-blend: {e}");
            std::process::exit(2);
        }
    };
    for name in train.iter().chain(test).filter(|_| load.is_none()) {
        let path = root.join(format!("fixtures/hdri/{name}.exr"));
        let loaded = load_environment(&path, false).expect("fixture");
        let size = loaded.env.natural_face_size();
        let cube = loaded.env.to_cube(size, Filter::Area, 0.0, &NoProgress);
        let pp = ibl_prefilter::Params {
            size: size.clamp(8, 256),
            ..Default::default()
        };
        let chain = ibl_prefilter::bake::bake_chain(&pp, &loaded.env, &NoProgress).expect("chain");
        let ps = if train.contains(name) {
            &train_params
        } else {
            &params
        };
        let env = Env::new(name.to_string(), cube, &chain.mips, String::new(), ps);
        let t0 = Instant::now();
        let (cases, images) = eval::evaluate(&env, ps, &parsed, &preset);
        eprintln!(
            "{name}: {} cases in {:.1} s",
            cases.len(),
            t0.elapsed().as_secs_f64()
        );
        for (c, im) in cases.iter().zip(images) {
            data.push(Data {
                env: c.env.clone(),
                r: c.r,
                eta: c.eta,
                azimuth: c.azimuth,
                q: F0S.map(|f0| quad(&im, f0)),
            });
        }
    }
    if let Some(file) = &dump {
        // Per case and F0 the quadratic's coefficients, to study other rules offline.
        let mut out =
            String::from("env\tazimuth\tr\teta\tf0\tgated\tuu\tuv\tvv\tn\tbent\tkc\ttruth\n");
        for d in &data {
            for (q, f0) in d.q.iter().zip(F0S) {
                let _ = writeln!(
                    out,
                    "{}\t{}\t{}\t{}\t{f0}\t{}\t{:e}\t{:e}\t{:e}\t1\t{:e}\t{:e}\t{:e}",
                    d.env,
                    d.azimuth,
                    d.r,
                    d.eta,
                    u8::from(gated(d)),
                    q.uu,
                    q.uv,
                    q.vv,
                    q.bent,
                    q.kc,
                    q.truth
                );
            }
        }
        std::fs::write(file, out).expect("dump");
    }
    let tr: Vec<&Data> = data
        .iter()
        .filter(|d| train.contains(&d.env.as_str()) && gated(d))
        .collect();
    let te: Vec<&Data> = data
        .iter()
        .filter(|d| test.contains(&d.env.as_str()) && gated(d))
        .collect();
    // The family, by leave-one-training-environment-out cross-validation (training only).
    let (constant, linear) = (family(false), family(true));
    let mut cv = [0.0f64; 2];
    let mut cv_rows = String::new();
    if train.len() > 1 {
        for (k, rules) in [&constant, &linear].into_iter().enumerate() {
            for out in train {
                let fit: Vec<&Data> = tr.iter().copied().filter(|d| d.env != *out).collect();
                let held: Vec<&Data> = tr.iter().copied().filter(|d| d.env == *out).collect();
                let (r, s) = best(&fit, rules);
                let h = score(&held, |d| r.weight(d.r, d.eta));
                cv[k] += h.ln() / train.len() as f64;
                let _ = writeln!(
                    cv_rows,
                    "| {} | {out} | η₁ = {} + {}·r, p = {}, {} | {s:.4} | {h:.4} |",
                    ["η₁ constant", "η₁ = a + b·r"][k],
                    r.eta1,
                    r.slope,
                    r.p,
                    if r.r0.is_finite() {
                        format!("r₀ = {}, Δr = {}", r.r0, r.dr)
                    } else {
                        "no ramp".to_string()
                    }
                );
            }
        }
    }
    let cv = cv.map(f64::exp);
    let use_linear = cv[1] < cv[0];
    let (best_const, best_const_s) = best(&tr, &constant);
    let (best_lin, best_lin_s) = best(&tr, &linear);
    let chosen = if use_linear { best_lin } else { best_const };
    let shipped = ibl_aniso::ship::SHIPPED;
    let shipped_rule = Rule {
        eta1: shipped.blend_eta,
        slope: 0.0,
        p: shipped.blend_power,
        r0: shipped.blend_r0,
        dr: shipped.blend_r_width,
    };
    let mut md = String::new();
    let _ = writeln!(
        md,
        "# Anisotropic IBL: the shipped blend rule (issue 23 G1, G2)\n\n\
         Generated by `cargo run --release -p ibl-aniso --example fit-ibl-aniso-blend{}` in {:.0} s \
         ({} cores, shared with other jobs: timings are indicative only). Spheres of {}² px, r {:?}, \
         η {:?}, elevation 15°, gltf chain (engine lookup). Rule: specular = iso + (fis − iso)·w, \
         w = max(clamp(|η|/η₁, 0, 1)^p, clamp((r − r₀)/Δr, 0, 1)) (the second term: the \
         roughness ramp, or none); w = 0 reads only the isotropic split sum (exactly the floor). \
         Only rules within goal G2 on training (every gated η = 0 training case at most {G2_BOUND}× \
         the floor's MSE at both F0) are candidates. Fitted on {train:?} (azimuths {:?}, truth {} MC samples: {} gated cases), scored \
         on {test:?} (azimuth {:?}, truth {} samples: {} gated cases). Score: geometric mean over \
         cases and F0 ∈ {{1, 0.04}} of MSE(rule) / MSE(fis); lower is better. fis = `{}`: VNDF \
         FIS at the shipped lod bias {} (`ibl_aniso::ship::SHIPPED`); `fis-16` is the published \
         FIS (Křivánek & Colbert's +1 bias), goal G3's baseline.\n",
        match (quick, &load) {
            (true, _) => " -- --quick".to_string(),
            (false, Some(f)) => format!(" -- --load {f}` from the cases of an earlier `--dump"),
            (false, None) => String::new(),
        },
        t_all.elapsed().as_secs_f64(),
        std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1),
        params.sphere_size,
        params.roughness,
        params.eta,
        train_params.views,
        train_params.truth_samples,
        tr.len(),
        params.views,
        params.truth_samples,
        te.len(),
        shipped_fis(),
        shipped.lod_bias,
    );
    let _ = writeln!(
        md,
        "## Training score, η₁ constant, no roughness ramp\n\n| η₁ \\ p | {} |",
        PS.map(|p| p.to_string()).join(" | ")
    );
    let _ = writeln!(md, "|---|{}", "---|".repeat(PS.len()));
    for &e in &ETA1S {
        let row: Vec<String> = PS
            .iter()
            .map(|&p| {
                let r = Rule {
                    eta1: e,
                    slope: 0.0,
                    p,
                    r0: f32::INFINITY,
                    dr: 1.0,
                };
                format!("{:.4}", score(&tr, |d| r.weight(d.r, d.eta)))
            })
            .collect();
        let _ = writeln!(md, "| {e} | {} |", row.join(" | "));
    }
    // The ramp's table at the best constant (η₁, p): training score, and the worst η = 0
    // ratio to the floor (G2; over the bound: not a candidate).
    let _ = writeln!(
        md,
        "\n## Training score of the roughness ramp at η₁ = {}, p = {}: score (worst η = 0 MSE / iso)\n\n\
         | r₀ \\ Δr | {} |\n|---|{}",
        best_const.eta1,
        best_const.p,
        DRS.map(|d| d.to_string()).join(" | "),
        "---|".repeat(DRS.len())
    );
    for &r0 in &R0S {
        let row: Vec<String> = DRS
            .iter()
            .map(|&dr| {
                let r = Rule {
                    r0,
                    dr,
                    ..best_const
                };
                let wt = |d: &Data| r.weight(d.r, d.eta);
                format!("{:.4} ({:.3})", score(&tr, wt), worst_at_eta0(&tr, wt))
            })
            .collect();
        let _ = writeln!(md, "| {r0} | {} |", row.join(" | "));
    }
    let ramp_text = |r: &Rule| {
        if r.r0.is_finite() {
            format!("r₀ = {}, Δr = {}", r.r0, r.dr)
        } else {
            "no ramp".to_string()
        }
    };
    let _ = writeln!(
        md,
        "\nBest with η₁ constant: η₁ = {}, p = {}, {} ({best_const_s:.4}); best with η₁(r) = a + b·r \
         (a 0.05…2, b −1.6…1.6, steps 0.05, same p and ramps): a = {}, b = {}, p = {}, {} \
         ({best_lin_s:.4}).\n",
        best_const.eta1,
        best_const.p,
        ramp_text(&best_const),
        best_lin.eta1,
        best_lin.slope,
        best_lin.p,
        ramp_text(&best_lin)
    );
    if train.len() > 1 {
        let _ = writeln!(
            md,
            "## Which family: leave one training environment out\n\n\
             | family | left out | fitted on the other | its score there | score on the left-out |\n\
             |---|---|---|---|---|\n{cv_rows}\n\
             Cross-validated score (geometric mean over the left-out environments): η₁ constant \
             {:.4}, η₁ = a + b·r {:.4}: **{}**.\n",
            cv[0],
            cv[1],
            if use_linear {
                "η₁ = a + b·r generalises better"
            } else {
                "the roughness term does not generalise across the training environments; η₁ \
                 stays constant"
            }
        );
    }
    assert!(
        quick || (!use_linear && chosen == shipped_rule),
        "SHIPPED ({shipped_rule:?}) is not the training optimum ({chosen:?}, linear: \
         {use_linear}): update ship.rs",
    );
    let _ = writeln!(
        md,
        "Chosen on training: **η₁ = {}{}, p = {}, {}**. Shipped (`ibl_aniso::ship::SHIPPED`): \
         η₁ = {}, p = {}, r₀ = {}, Δr = {}.\n",
        chosen.eta1,
        if use_linear {
            format!(" + {}·r", chosen.slope)
        } else {
            String::new()
        },
        chosen.p,
        ramp_text(&chosen),
        shipped.blend_eta,
        shipped.blend_power,
        shipped.blend_r0,
        shipped.blend_r_width
    );
    let _ = writeln!(
        md,
        "## Held-out, per η (F0 = 1): geometric-mean MSE ratio, and worst MSE / iso\n\n\
         fis = `{}`, fis-16 = the published FIS (+1 bias).\n\n\
         | η | cases | shipped / fis (gm) | shipped / iso (gm) | worst shipped / iso | worst fis / iso | shipped wins vs fis | shipped wins vs fis-16 |\n\
         |---|---|---|---|---|---|---|---|",
        shipped_fis()
    );
    for &e in &params.eta {
        let cs: Vec<&&Data> = te.iter().filter(|d| d.eta == e).collect();
        if cs.is_empty() {
            let _ = writeln!(md, "| {e} | 0 | | | | | | |");
            continue;
        }
        let (mut lf, mut li, mut wi, mut wf, mut wins, mut wins_kc) =
            (0.0, 0.0, 0.0f64, 0.0f64, 0, 0);
        for d in &cs {
            let s = mse(d, shipped_weight(d), 0);
            let (i, f) = (mse(d, 0.0, 0), mse(d, 1.0, 0));
            lf += (s / f).ln();
            li += (s / i).ln();
            wi = wi.max(s / i);
            wf = wf.max(f / i);
            wins += usize::from(s < f);
            wins_kc += usize::from(s < d.q[0].kc);
        }
        let n = cs.len() as f64;
        let _ = writeln!(
            md,
            "| {e} | {} | {:.3} | {:.3} | {wi:.3} | {wf:.3} | {wins}/{} | {wins_kc}/{} |",
            cs.len(),
            (lf / n).exp(),
            (li / n).exp(),
            cs.len(),
            cs.len()
        );
    }
    // The goals on the held-out gated cases, F0 = 1. Against the LG18 bent normal a case is a
    // tie when the two agree within 10⁻⁵ relative: at η = 0 the bent normal is the isotropic
    // split sum (stretch |η|·… = 0), which the shipped rule returns untouched, and only f32
    // rounding in their sums tells them apart.
    let verdict = |s: f64, b: f64| -> usize {
        if (s - b).abs() <= 1e-5 * b {
            1
        } else if s < b {
            0
        } else {
            2
        }
    };
    let (mut g1, mut f1, mut g3, mut gf, mut gi, mut fi) = ([0usize; 3], [0usize; 3], 0, 0, 0, 0);
    let _ = writeln!(
        md,
        "\n## Held-out, every case (F0 = 1): MSE per pixel and channel\n\n\
         | env | r | η | w | shipped | fis | fis-16 | bent-lg18 | iso | shipped vs bent |\n\
         |---|---|---|---|---|---|---|---|---|---|"
    );
    for d in &te {
        let w = shipped_weight(d);
        let s = mse(d, w, 0);
        let (i, f, b) = (mse(d, 0.0, 0), mse(d, 1.0, 0), d.q[0].bent);
        let v = verdict(s, b);
        g1[v] += 1;
        f1[verdict(f, b)] += 1;
        g3 += usize::from(s < d.q[0].kc);
        gf += usize::from(s < f);
        gi += usize::from(s <= i);
        fi += usize::from(f <= i);
        let _ = writeln!(
            md,
            "| {} | {} | {} | {w:.3} | {s:.4e} | {f:.4e} | {:.4e} | {b:.4e} | {i:.4e} | {} |",
            d.env,
            d.r,
            d.eta,
            d.q[0].kc,
            ["win", "tie", "**loss**"][v]
        );
    }
    let n = te.len();
    let _ = writeln!(
        md,
        "\nHeld-out, every η (F0 = 1, {n} gated cases): the shipped fisb-16 beats the LG18 bent \
         normal in {}/{n}, ties it in {} (η = 0 below the ramp, where both are the isotropic split sum), loses \
         in {} (fis: {} wins, {} ties, {} losses); it is at or below the isotropic floor in {gi}/{n} (fis: \
         {fi}/{n}), beats fis in {gf}/{n} and beats the published fis-16 (goal G3) in {g3}/{n}.",
        g1[0], g1[1], g1[2], f1[0], f1[1], f1[2]
    );
    let all: Vec<&Data> = data.iter().filter(|d| gated(d) && d.eta == 0.0).collect();
    let (mut ws, mut wfis, mut tag) = (0.0f64, 0.0f64, String::new());
    for d in &all {
        let i = mse(d, 0.0, 0);
        ws = ws.max(mse(d, shipped_weight(d), 0) / i);
        let f = mse(d, 1.0, 0) / i;
        if f > wfis {
            wfis = f;
            tag = format!("{} r {}", d.env, d.r);
        }
    }
    let _ = writeln!(
        md,
        "\nEvery environment (training too), η = 0, gated cases: worst MSE / iso shipped {ws:.3}, \
         fis {wfis:.3} ({tag})."
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
