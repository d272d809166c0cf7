//! End-to-end tests of `hv-lut`: the LUT against an independent implementation of the
//! thesis formulas (Marcolongo 2020 §4.3.2), the sidecar, PNG 8/16-bit and thesis file names,
//! finiteness over the exponent range, and one-line errors with no output.

use ibl_core::io::{read_image, ColorSpace};
use ibl_testkit::Bin;
use std::f64::consts::{FRAC_PI_2, PI};
use std::path::Path;

const BIN: Bin = Bin::new(env!("CARGO_BIN_EXE_hv-lut"), "hv-lut");

/// The thesis's formulas as printed (tan form, with the quadrant cases), written again here
/// without the library: (h, p_h(h)/p_h(n)) at (ξ1, ξ2) strictly inside the unit square.
fn thesis_half_vector(nu: f64, nv: f64, xi1: f64, xi2: f64) -> ([f64; 3], f64) {
    let phi_red = |t: f64| (((nu + 1.0) / (nv + 1.0)).sqrt() * (FRAC_PI_2 * t).tan()).atan();
    let phi = if xi1 < 0.25 {
        phi_red(4.0 * xi1)
    } else if xi1 < 0.5 {
        PI - phi_red(2.0 - 4.0 * xi1)
    } else if xi1 < 0.75 {
        PI + phi_red(4.0 * xi1 - 2.0)
    } else {
        2.0 * PI - phi_red(4.0 - 4.0 * xi1)
    };
    let e = nu * phi.cos().powi(2) + nv * phi.sin().powi(2);
    let theta = (1.0 - xi2).powf(1.0 / (e + 1.0)).acos();
    let h = [
        theta.sin() * phi.cos(),
        theta.sin() * phi.sin(),
        theta.cos(),
    ];
    // p_h(h)/p_h(n) = (n·h)^{(n_u (t·h)² + n_v (b·h)²)/(1 − (n·h)²)} (§2.4).
    let expo = (nu * h[0] * h[0] + nv * h[1] * h[1]) / (1.0 - h[2] * h[2]);
    (h, h[2].powf(expo))
}

#[test]
fn exr_lut_matches_the_thesis_formulas_and_sidecar_restores_the_pdf() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("hv.exr");
    let (nu, nv) = (200.0, 30.0);
    BIN.generate(&out, &["--nu", "200", "--nv", "30", "--size", "32", "-q"]);
    let img = read_image(&out, ColorSpace::Linear).unwrap();
    assert_eq!((img.width, img.height, img.channels), (32, 32, 4));
    let side: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.path().join("hv.json")).unwrap()).unwrap();
    assert_eq!(
        (side["nu"].as_f64(), side["nv"].as_f64()),
        (Some(nu), Some(nv))
    );
    let p_h_n = side["p_h_n"].as_f64().unwrap();
    assert!((p_h_n - ((nu + 1.0) * (nv + 1.0)).sqrt() / (2.0 * PI)).abs() < 1e-12);
    let (mut worst_h, mut worst_a) = (0.0f64, 0.0f64);
    for j in 0..32 {
        for i in 0..32 {
            let (xi1, xi2) = ((i as f64 + 0.5) / 32.0, (j as f64 + 0.5) / 32.0);
            let (h, ratio) = thesis_half_vector(nu, nv, xi1, xi2);
            let t = img.texel(i, j);
            for c in 0..3 {
                worst_h = worst_h.max((2.0 * t[c] as f64 - 1.0 - h[c]).abs());
            }
            worst_a = worst_a.max((t[3] as f64 - ratio).abs());
        }
    }
    eprintln!(
        "hv-lut (200, 30) vs the thesis formulas: max |Δh| {worst_h:.2e}, max |ΔA| {worst_a:.2e}"
    );
    assert!(worst_h < 1e-6 && worst_a < 1e-5);
}

#[test]
fn png_bits_and_thesis_names() {
    let dir = tempfile::tempdir().unwrap();
    let lobe = ["--nu", "20000", "--nv", "70"];
    let thesis = ["--thesis-names", "--bits", "8", "--size", "16", "-q"];
    BIN.generate(dir.path(), &[&lobe[..], &thesis].concat());
    let png = dir.path().join("halfVectorSampling[20000,70].png");
    let img = read_image(&png, ColorSpace::Linear).unwrap();
    assert_eq!((img.width, img.channels), (16, 4));
    let side: serde_json::Value = serde_json::from_slice(
        &std::fs::read(dir.path().join("halfVectorSampling[20000,70].json")).unwrap(),
    )
    .unwrap();
    assert_eq!(side["image"], "halfVectorSampling[20000,70].png");
    // 8-bit: every value is a multiple of 1/255, within half a step of the formulas.
    let mut worst = 0.0f64;
    for j in 0..16 {
        for i in 0..16 {
            let (h, _) = thesis_half_vector(
                20000.0,
                70.0,
                (i as f64 + 0.5) / 16.0,
                (j as f64 + 0.5) / 16.0,
            );
            let t = img.texel(i, j);
            for c in 0..3 {
                assert!(((t[c] * 255.0).round() - t[c] * 255.0).abs() < 1e-3);
                worst = worst.max((t[c] as f64 - (0.5 * h[c] + 0.5)).abs());
            }
        }
    }
    assert!(worst <= 0.5 / 255.0 + 1e-6, "{worst}");
    let p16 = dir.path().join("hv16.png");
    BIN.generate(&p16, &[&lobe[..], &["--size", "16", "-q"]].concat());
    let img16 = read_image(&p16, ColorSpace::Linear).unwrap();
    assert!(
        img16
            .data
            .iter()
            .any(|v| ((v * 255.0).round() - v * 255.0).abs() > 1e-3),
        "16-bit values"
    );
}

#[test]
fn extreme_exponents_give_finite_texels() {
    let dir = tempfile::tempdir().unwrap();
    for (nu, nv) in [("1", "1"), ("1e6", "1"), ("1e6", "1e6"), ("1", "1e6")] {
        let out = dir.path().join(format!("hv_{nu}_{nv}.exr"));
        BIN.generate(&out, &["--nu", nu, "--nv", nv, "--size", "64", "-q"]);
        let img = read_image(&out, ColorSpace::Linear).unwrap();
        assert!(
            img.data
                .iter()
                .all(|v| v.is_finite() && (0.0..=1.0).contains(v)),
            "{nu} {nv}"
        );
    }
}

/// `-o out flags…` refused with `code` in one line, and nothing added to `dir`.
fn refused(out: &Path, flags: &[&str], dir: &Path, code: i32) {
    BIN.refused_generate(out, flags, code, "");
    assert_eq!(ibl_testkit::files_in(dir).len(), 1, "{flags:?} left output");
}

#[test]
fn bad_parameters_are_one_line_errors_with_no_output() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("file"), b"x").unwrap();
    let o = &d.join("hv.exr");
    refused(o, &["--nu", "0", "--nv", "70"], d, 2);
    refused(o, &["--nu", "-3", "--nv", "70"], d, 2);
    refused(o, &["--nu", "10"], d, 2);
    refused(o, &["--nu", "10", "--nv", "10", "--size", "0"], d, 2);
    refused(o, &["--nu", "10", "--nv", "10", "--bits", "12"], d, 2);
    refused(&d.join("hv.json"), &["--nu", "10", "--nv", "10"], d, 3);
    let small = ["--nu", "10", "--nv", "10", "--size", "4"];
    refused(&d.join("file/hv.exr"), &small, d, 2);
}

#[test]
fn a_blocked_sidecar_leaves_the_previous_image_untouched() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let lut = d.join("lut.exr");
    let side = d.join("lut.json");
    BIN.generate(&lut, &["--nu", "10", "--nv", "10", "--size", "8", "-q"]);
    assert!(side.is_file(), "the first run writes the sidecar");
    let first = std::fs::read(&lut).unwrap();
    // A directory where the sidecar goes: the second run must fail before renaming anything.
    std::fs::remove_file(&side).unwrap();
    std::fs::create_dir(&side).unwrap();
    let second_run = ["--nu", "20", "--nv", "10", "--size", "8", "-q"];
    BIN.refused_generate(&lut, &second_run, 2, "");
    assert_eq!(std::fs::read(&lut).unwrap(), first, "lut.exr was replaced");
    assert!(side.is_dir());
    // The check has teeth: the second run's image differs from the first.
    let other = dir.path().join("other");
    std::fs::create_dir(&other).unwrap();
    let second = other.join("lut.exr");
    BIN.generate(&second, &second_run);
    assert_ne!(std::fs::read(&second).unwrap(), first);
    std::fs::remove_dir_all(&other).unwrap();
    assert_eq!(
        ibl_testkit::files_in(d),
        ["lut.exr", "lut.json"],
        "no temporaries left"
    );
}

#[test]
fn outputs_that_are_not_images_name_the_image_formats_only() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("file"), b"x").unwrap();
    for (name, shown) in [
        ("a", "no extension"),
        ("a.json", "'.json'"),
        ("a.txt", "'.txt'"),
    ] {
        let out = BIN.run_generate(d.join(name), &["--nu", "10", "--nv", "10"]);
        let err = String::from_utf8_lossy(&out.stderr);
        eprintln!("-o {name} -> {}", err.trim_end());
        assert_eq!(out.status.code(), Some(3), "{err}");
        assert!(
            err.contains(&format!("unsupported output: {shown} ("))
                && err.contains("write .exr or .png)")
                && !err.contains(".ron"),
            "{err}"
        );
        assert_eq!(
            std::fs::read_dir(d).unwrap().count(),
            1,
            "-o {name} left output"
        );
    }
}
