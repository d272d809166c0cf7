//! End-to-end tests of the `shexp-fit` binary on generated environments and a fixture.

use ibl_core::io::{write_image, WriteOptions};
use ibl_core::Image;
use ibl_shexp::Coeffs;
use ibl_testkit::Bin;
use std::path::{Path, PathBuf};

const BIN: Bin = Bin::new(env!("CARGO_BIN_EXE_shexp-fit"), "shexp-fit");

/// A 64×32 equirect: a sky gradient, a warm sun and a dark ground.
fn write_env(path: &Path, nan: bool) {
    let (w, h) = (64, 32);
    let mut img = Image::new(w, h, 3);
    let sun = glam::Vec3::new(0.5, 0.6, 0.3).normalize();
    for j in 0..h {
        for i in 0..w {
            let d = ibl_core::equirect::pixel_direction(i, j, w, h);
            let s = (40.0 * (d.dot(sun) - 1.0)).exp() * 50.0;
            let sky = if d.y > 0.0 { 0.5 + d.y } else { 0.05 };
            img.texel_mut(i, j)
                .copy_from_slice(&[sky + s, sky + 0.8 * s, sky * 1.2 + 0.5 * s]);
        }
    }
    if nan {
        img.texel_mut(3, 3)[1] = f32::NAN;
    }
    write_image(path, &img, &WriteOptions::default()).unwrap();
}

/// The small fit the tests run: 16 normals × 16 views, 64 samples.
const SMALL: [&str; 6] = ["--normals", "16", "--views", "16", "--samples", "64"];

/// Fits `dir`/env.exr (written on first use) into `dir`/`name` with the small settings and
/// `extra` flags; returns the output path and the probe read back.
fn fit_ok(dir: &Path, name: &str, extra: &[&str]) -> (PathBuf, Coeffs) {
    let env = dir.join("env.exr");
    if !env.exists() {
        write_env(&env, false);
    }
    let out = dir.join(name);
    BIN.bake(&env, &out, &[extra, &SMALL, &["--quiet"]].concat());
    let c: Coeffs = ibl_core::io::data::read(&out).unwrap();
    (out, c)
}

#[test]
fn fits_and_writes_coefficients_and_shaders() {
    let dir = tempfile::tempdir().unwrap();
    let env = dir.path().join("env.exr");
    let (out, c) = fit_ok(dir.path(), "probe.json", &["--emit-shader"]);
    c.validate(&out).unwrap();
    assert_eq!((c.p_order, c.q_order, c.p.len(), c.q.len()), (4, 2, 25, 8));
    assert_eq!(c.alphas, vec![0.2, 0.4667, 0.7333, 1.0]);
    assert_eq!(c.rows, 16 * 16 * 4);
    assert!(c.residual.is_finite() && c.residual > 0.0 && c.condition_number >= 1.0);
    // The raw JSON has the documented keys.
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
    for k in ["p_order", "q_order", "alphas", "p", "q", "residual"] {
        assert!(v.get(k).is_some(), "missing {k}");
    }
    let glsl = std::fs::read_to_string(out.with_extension("glsl")).unwrap();
    let hlsl = std::fs::read_to_string(out.with_extension("hlsl")).unwrap();
    assert!(glsl.contains("vec3 shexp_e0(") && hlsl.contains("float3 shexp_e0("));
    // The probe reconstructs E0 of this environment: compare eq. 11 with an exact summation
    // facing the sky (log error, the quantity the fit minimises).
    let cube = ibl_core::envmap::load_environment(&env, false)
        .unwrap()
        .env
        .to_cube(
            16,
            ibl_core::equirect::Filter::Area,
            0.0,
            &ibl_core::progress::NoProgress,
        );
    let truth = ibl_shexp::truth::TexelSet::from_cube(&cube);
    let mut rms = 0.0f64;
    let mut k = 0;
    for i in 0..64 {
        let n = ibl_shexp::basis::fibonacci_sphere(i, 64);
        let v = (n + glam::Vec3::new(0.2, 0.1, -0.3)).normalize();
        if n.dot(v) < 0.2 {
            continue;
        }
        let e = c.e0(n, v, 0.5);
        let t = truth.e0(n, v, 0.5);
        rms += ((e[0] as f64) / t[0]).ln().powi(2);
        k += 1;
    }
    let rms = (rms / k as f64).sqrt();
    eprintln!(
        "log RMS of eq. 11 against exact E0 on {k} samples: {rms:.3} (fit residual {:.3})",
        c.residual
    );
    assert!(rms < 2.0 * c.residual + 0.05, "{rms}");
}

#[test]
fn the_objective_is_chosen_by_flag_and_recorded() {
    use ibl_shexp::coeffs::Objective;
    let dir = tempfile::tempdir().unwrap();
    let env = dir.path().join("env.exr");
    let mut fitted = Vec::new();
    for (flags, want) in [
        (&[][..], Objective::Relative),
        (&["--objective", "log"][..], Objective::Log),
    ] {
        let (_, c) = fit_ok(dir.path(), &format!("{want:?}.json"), flags);
        assert_eq!(c.objective, want);
        fitted.push(c);
    }
    // The refinement moves the solution (it starts from the log fit and must change it here).
    assert_ne!(fitted[0].p, fitted[1].p);
    let out = dir.path().join("bad.json");
    BIN.refused_bake(&env, &out, &["--objective", "linear"], 2, "");
    assert!(!out.exists());
}

#[test]
fn alpha_knots_are_fitted_beside_eq_11() {
    let dir = tempfile::tempdir().unwrap();
    let (out, c) = fit_ok(
        dir.path(),
        "knots.json",
        &["--alpha-knots", "0.2,1", "--emit-shader"],
    );
    c.validate(&out).unwrap();
    // The eq. 11 sets are still there for eq. 11 readers; the knots sit beside them.
    assert_eq!((c.p.len(), c.q.len()), (25, 8));
    let k = c.alpha_knots.as_ref().expect("alpha_knots written");
    assert_eq!(k.alphas, vec![0.2, 1.0]);
    assert_eq!((k.p.len(), k.p[0].len(), k.q[1].len()), (2, 25, 8));
    assert!(
        k.residual.is_finite() && k.residual < c.residual,
        "{} vs {}",
        k.residual,
        c.residual
    );
    let glsl = std::fs::read_to_string(out.with_extension("glsl")).unwrap();
    assert!(glsl.contains("SHEXP_KNOTS[2]") && glsl.contains("mix(SHEXP_P[bp + 0]"));
}

#[test]
fn output_is_identical_for_any_thread_count_and_ron_by_extension() {
    let dir = tempfile::tempdir().unwrap();
    let env = dir.path().join("env.exr");
    write_env(&env, false);
    let outs: Vec<PathBuf> = ["1", "2"]
        .iter()
        .map(|t| dir.path().join(format!("c{t}.json")))
        .collect();
    for (t, out) in ["1", "2"].iter().zip(&outs) {
        BIN.bake(
            &env,
            out,
            &[&["--threads", t], &SMALL[..], &["--quiet"]].concat(),
        );
    }
    assert_eq!(
        std::fs::read(&outs[0]).unwrap(),
        std::fs::read(&outs[1]).unwrap()
    );
    let ron = dir.path().join("c.ron");
    BIN.bake(&env, &ron, &[&SMALL[..], &["--quiet"]].concat());
    let a: Coeffs = ibl_core::io::data::read(&ron).unwrap();
    let b: Coeffs = ibl_core::io::data::read(&outs[0]).unwrap();
    assert_eq!(a.p, b.p);
}

#[test]
fn fixture_fit_reports_json_summary() {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/hdri/sunset_256.exr");
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("sunset.json");
    let o = BIN.bake(&root, &out, &[&SMALL[..], &["--json"]].concat());
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(v["details"]["rows"], 1024);
    assert!(v["details"]["timings"]["estimate"].as_f64().unwrap() >= 0.0);
    eprintln!(
        "sunset_256 fit: residual {}, κ {}",
        v["details"]["residual"], v["details"]["condition_number"]
    );
}

/// Bad inputs: one line on stderr, non-zero exit, nothing written.
#[test]
fn bad_inputs_fail_cleanly() {
    let dir = tempfile::tempdir().unwrap();
    let env = dir.path().join("env.exr");
    write_env(&env, false);
    let nan = dir.path().join("nan.exr");
    write_env(&nan, true);
    let out = dir.path().join("never.json");
    let missing = dir.path().join("missing.exr");
    let (e, n) = (&env, &nan);
    let knots = "--alpha-knots";
    let cases: Vec<(&Path, Vec<&str>, i32, &str)> = vec![
        (&missing, vec![], 4, "missing.exr"),
        (n, vec![], 2, "NaN"),
        (e, vec!["--p-order", "0"], 2, "p-order"),
        (e, vec!["--alphas", ""], 2, "alphas"),
        (e, vec!["--alphas", "0.5,1.5"], 2, "alphas"),
        (
            e,
            vec!["--normals", "2", "--views", "2", "--alphas", "0.5"],
            2,
            "unknowns",
        ),
        (e, vec!["--samples", "zero"], 2, "samples"),
        (e, vec![knots, "0.5"], 2, "alpha-knots"),
        (e, vec![knots, "0.6,0.3"], 2, "alpha-knots"),
        (e, vec![knots, "0.2,2"], 2, "alpha-knots"),
        (e, vec![knots, "0.2,0.3,0.4,1"], 2, "alpha-knots"),
    ];
    for (input, flags, code, needle) in cases {
        BIN.refused_bake(input, &out, &flags, code, needle);
        assert!(!out.exists());
    }
    // --sanitize accepts the NaN environment.
    let tiny = ["--normals", "8", "--views", "8", "--samples", "32"];
    BIN.bake(
        n,
        &out,
        &[&["--sanitize"], &tiny[..], &["--quiet"]].concat(),
    );
    assert!(out.exists());
}
