//! End-to-end tests of the `shexp-eval` binary (with `shexp-fit` coefficients when both are built).

use ibl_core::io::{write_image, WriteOptions};
use ibl_core::Image;
use ibl_testkit::Bin;
use std::path::Path;
use std::process::Output;

const BIN: Bin = Bin::new(env!("CARGO_BIN_EXE_shexp-eval"), "shexp-eval");

fn write_env(path: &Path) {
    let (w, h) = (64, 32);
    let mut img = Image::new(w, h, 3);
    let sun = glam::Vec3::new(-0.4, 0.7, 0.5).normalize();
    for j in 0..h {
        for i in 0..w {
            let d = ibl_core::equirect::pixel_direction(i, j, w, h);
            let s = (30.0 * (d.dot(sun) - 1.0)).exp() * 20.0;
            let sky = if d.y > 0.0 {
                0.4 + d.y
            } else {
                0.1 + 0.05 * d.x.abs()
            };
            img.texel_mut(i, j)
                .copy_from_slice(&[sky + s, sky + 0.9 * s, sky * 1.3 + 0.6 * s]);
        }
    }
    write_image(path, &img, &WriteOptions::default()).unwrap();
}

fn run(args: &[&str]) -> Output {
    BIN.run(args)
}

const SMALL: [&str; 12] = [
    "--sphere-size",
    "12",
    "--truth-size",
    "8",
    "--ss-size",
    "16",
    "--roughness",
    "0.5,1",
    "--views",
    "0,180",
    "--truth-check-stride",
    "3",
];

#[test]
fn evaluates_and_writes_report_images_and_json() {
    let dir = tempfile::tempdir().unwrap();
    let env = dir.path().join("sky.exr");
    write_env(&env);
    let fit_params = dir.path().join("fit.ron");
    std::fs::write(&fit_params, "(normals: 12, views: 12, samples: 64)").unwrap();
    let out = dir.path().join("report");
    let mut args = vec![
        env.to_str().unwrap(),
        "--fit-params",
        fit_params.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--json",
    ];
    args.extend(SMALL);
    let o = run(&args);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(v["details"]["cases"], 2 * 2 * 2);
    let env0 = &v["details"]["environments"][0];
    for c in env0["cases"].as_array().unwrap() {
        let (a, b) = (
            c["mse_split_sum"].as_f64().unwrap(),
            c["mse_shexp"].as_f64().unwrap(),
        );
        assert!(a.is_finite() && b.is_finite() && a >= 0.0 && b >= 0.0);
        assert_eq!(c["shexp_wins"].as_bool().unwrap(), b < a);
    }
    assert_eq!(env0["memory"]["shexp_bytes"], 396);
    for f in [
        "report.md",
        "report.json",
        "sky_chrome.png",
        "sky_dielectric.png",
    ] {
        assert!(out.join(f).is_file(), "{f}");
    }
    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(md.contains("| chrome |") && md.contains("| dielectric |"));
    let png = ibl_core::io::read_image(
        &out.join("sky_chrome.png"),
        ibl_core::io::ColorSpace::Linear,
    )
    .unwrap();
    assert_eq!((png.width, png.height), (2 * 5 * 12, 2 * 12));
}

#[test]
fn uses_given_coefficients_and_prefiltered_chain() {
    let dir = tempfile::tempdir().unwrap();
    let env = dir.path().join("sky.exr");
    write_env(&env);
    // Coefficients from the library (same format shexp-fit writes) and a chain folder in the
    // m{l}_<face>.exr layout `prefilter` writes.
    let loaded = ibl_core::envmap::load_environment(&env, false).unwrap();
    let cube = ibl_shexp::fit::working_cube(&loaded.env, None, &ibl_core::progress::NoProgress);
    let fp = ibl_shexp::fit::Params {
        normals: 12,
        views: 12,
        samples: 64,
        alpha_knots: vec![0.2, 1.0],
        ..Default::default()
    };
    let coeffs = ibl_shexp::fit::fit_cube(&fp, &cube, &ibl_core::progress::NoProgress)
        .unwrap()
        .coeffs;
    let cpath = dir.path().join("c.json");
    ibl_core::io::data::write(&cpath, &coeffs).unwrap();
    let chain = ibl_shexp::splitsum::prefilter_chain(&cube, 16, 2, 1, 64);
    let cdir = dir.path().join("chain");
    std::fs::create_dir_all(&cdir).unwrap();
    let encoded = ibl_core::output::encode_cube(
        &cdir,
        &chain,
        &ibl_core::output::Encoding::default(),
        "prefilter",
        &[],
    )
    .unwrap();
    ibl_core::io::write_many_atomic(&encoded.files).unwrap();
    let out = dir.path().join("r");
    let mut args = vec![
        env.to_str().unwrap(),
        "--coeffs",
        cpath.to_str().unwrap(),
        "--prefiltered",
        cdir.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--json",
    ];
    args.extend(SMALL);
    let o = run(&args);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let mem = &v["details"]["environments"][0]["memory"];
    assert_eq!(mem["split_sum_sizes"], serde_json::json!([16, 8]));
    assert_eq!(mem["split_sum_bytes_rgb32f"], 6 * (256 + 64) * 12);
    // The probe carries α knots: the evaluator scores and sizes what it reconstructs.
    assert_eq!(mem["shexp_bytes"], 2 * 33 * 3 * 4);
    let rep = v["details"]["environments"][0]["representation"]
        .as_str()
        .unwrap();
    assert!(rep.contains("α knots [0.2, 1.0]"), "{rep}");
    // ... and the same file's eq. 11 p, q are scored beside it.
    let eq11 = &v["details"]["environments"][0]["wins_eq11"];
    assert!(eq11.as_u64().is_some_and(|w| w <= 8), "{eq11}");
    // It is exactly what the eq. 11 probe alone scores.
    let c11 = dir.path().join("c11.json");
    ibl_core::io::data::write(&c11, &coeffs.eq11()).unwrap();
    let pos = args
        .iter()
        .position(|a| *a == cpath.to_str().unwrap())
        .unwrap();
    args[pos] = c11.to_str().unwrap();
    let o = run(&args);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v11: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let env11 = &v11["details"]["environments"][0];
    assert_eq!(env11["wins"], *eq11);
    assert!(env11["wins_eq11"].is_null());
    assert_eq!(env11["memory"]["shexp_bytes"], 33 * 3 * 4);
}

#[test]
fn bad_inputs_fail_cleanly() {
    let dir = tempfile::tempdir().unwrap();
    let env = dir.path().join("sky.exr");
    write_env(&env);
    let bad_json = dir.path().join("bad.json");
    std::fs::write(&bad_json, "{\"p_order\": 4").unwrap();
    let short = dir.path().join("short.json");
    std::fs::write(
        &short,
        r#"{"p_order": 4, "q_order": 2, "alphas": [0.5], "p": [[0,0,0]], "q": [], "residual": 0}"#,
    )
    .unwrap();
    let out = dir.path().join("never");
    let (e, o) = (env.to_str().unwrap(), out.to_str().unwrap());
    let missing = dir.path().join("none.exr");
    let cases: Vec<(Vec<&str>, i32, &str)> = vec![
        (vec![missing.to_str().unwrap(), "--out", o], 4, "none.exr"),
        (
            vec![e, "--coeffs", bad_json.to_str().unwrap(), "--out", o],
            2,
            "bad.json",
        ),
        (
            vec![e, "--coeffs", short.to_str().unwrap(), "--out", o],
            2,
            "coefficients",
        ),
        (
            vec![e, e, "--coeffs", short.to_str().unwrap(), "--out", o],
            2,
            "single environment",
        ),
        (vec![e, "--roughness", "0", "--out", o], 2, "roughness"),
        (vec![e, "--sphere-size", "x", "--out", o], 2, "sphere-size"),
    ];
    for (args, code, needle) in cases {
        let r = run(&args);
        let err = String::from_utf8_lossy(&r.stderr).to_string();
        eprintln!("{args:?} → {:?}: {}", r.status.code(), err.trim());
        assert_eq!(r.status.code(), Some(code), "{err}");
        assert_eq!(err.trim().lines().count(), 1, "{err}");
        assert!(err.contains(needle), "{err}");
        assert!(!out.exists());
    }
}

#[test]
fn reports_are_identical_for_any_thread_count() {
    let dir = tempfile::tempdir().unwrap();
    let env = dir.path().join("sky.exr");
    write_env(&env);
    let fit_params = dir.path().join("fit.ron");
    std::fs::write(&fit_params, "(normals: 10, views: 10, samples: 32)").unwrap();
    let mut reports = Vec::new();
    for t in ["1", "2"] {
        let out = dir.path().join(format!("r{t}"));
        let mut args = vec![
            env.to_str().unwrap(),
            "--fit-params",
            fit_params.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--threads",
            t,
            "--quiet",
        ];
        args.extend(SMALL);
        let o = run(&args);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        reports.push((
            std::fs::read(out.join("report.json")).unwrap(),
            std::fs::read(out.join("report.md")).unwrap(),
            std::fs::read(out.join("sky_chrome.png")).unwrap(),
        ));
    }
    assert!(
        reports[0] == reports[1],
        "reports differ between 1 and 2 threads"
    );
}

#[test]
fn negative_list_values_reach_the_range_check_and_other_files_are_named() {
    let dir = tempfile::tempdir().unwrap();
    let env = dir.path().join("env.exr");
    write_env(&env);
    let o = run(&[env.to_str().unwrap(), "--roughness", "-0.1,0.5"]);
    let e = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{e}");
    assert!(e.contains("--roughness needs values in (0, 1]"), "{e}");
    // Another tool's JSON sidecar handed over as coefficients.
    let hv = dir.path().join("hv.json");
    std::fs::write(&hv, r#"{"table": "hv", "nu": 100.0, "nv": 10.0}"#).unwrap();
    let out = dir.path().join("report");
    let o = run(&[
        env.to_str().unwrap(),
        "--coeffs",
        hv.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    let e = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{e}");
    assert!(e.contains("hv.json: not an SH-exp coefficient file"), "{e}");
}
