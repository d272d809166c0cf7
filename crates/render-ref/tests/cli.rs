//! End to end: `render-ref` writes the orientation panorama, renders it (PFM rows bottom
//! first, a PNG, the estimate in --json), checks the render's orientation, compares renders,
//! and refuses bad input with one-line errors.

use ibl_testkit::{assert_one_line_error, stdout_json, Bin};
use std::path::Path;

const BIN: Bin = Bin::new(env!("CARGO_BIN_EXE_render-ref"), "render-ref");

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// The PFM header and the float at (column x, row y from the top) of a 768×256 RGB file.
fn pfm_pixel(bytes: &[u8], x: usize, y_top: usize) -> [f32; 3] {
    let header = b"PF\n768 256\n-1.0\n";
    assert!(bytes.starts_with(header), "header");
    assert_eq!(bytes.len(), header.len() + 768 * 256 * 12);
    let row_stored = 255 - y_top; // rows bottom first
    let o = header.len() + (row_stored * 768 + x) * 12;
    std::array::from_fn(|k| f32::from_le_bytes(bytes[o + 4 * k..o + 4 * k + 4].try_into().unwrap()))
}

#[test]
fn panorama_render_check_and_compare() {
    let dir = tempfile::tempdir().unwrap();
    let pano = dir.path().join("pano.exr");
    BIN.run_ok(&[
        "--orientation-panorama",
        "-o",
        s(&pano),
        "--width",
        "128",
        "-q",
    ]);
    let out = dir.path().join("ref.pfm");
    let png = dir.path().join("ref.png");
    let o = BIN.run_ok(&[
        s(&pano),
        "-o",
        s(&out),
        "--png",
        s(&png),
        "--engine",
        "exact",
        "--probes",
        "4",
        "--json",
    ]);
    let j = stdout_json(&o);
    assert_eq!(j["details"]["scene"], "sphere-rows v1");
    assert_eq!(
        j["details"]["estimated_error"].as_array().unwrap().len(),
        12
    );
    assert!(j["details"]["worst_specular_mean_rel"].as_f64().unwrap() < 0.05);
    assert!(png.is_file());
    let bytes = std::fs::read(&out).unwrap();
    // Row 0 (top) is background; the mirror sphere's centre (pixel 63/64, row 63) reflects +Z
    // (blue), its right part +X (red), its top +Y (green): the file stores rows bottom first.
    assert_eq!(pfm_pixel(&bytes, 5, 0), [0.0; 3]);
    let centre = pfm_pixel(&bytes, 63, 63);
    assert!(centre[2] > 0.8 && centre[0] < 0.1, "{centre:?}");
    let top = pfm_pixel(&bytes, 63, 63 - 40);
    assert!(top[1] > 0.8 && top[0] < 0.1, "{top:?}");
    // Every engine in one run: seven files, `exact`'s the same bytes as the run above.
    let all = dir.path().join("all.pfm");
    BIN.run_ok(&[
        s(&pano),
        "-o",
        s(&all),
        "--all-engines",
        "--probes",
        "0",
        "-q",
    ]);
    for e in [
        "gltf", "three", "babylon", "filament", "bevy", "unity", "exact",
    ] {
        assert!(dir.path().join(format!("all-{e}.pfm")).is_file(), "{e}");
    }
    assert!(!all.exists());
    assert_eq!(
        std::fs::read(dir.path().join("all-exact.pfm")).unwrap(),
        bytes
    );
    let o = BIN.run_ok(&["--check-orientation", s(&out), "--json"]);
    let j = stdout_json(&o);
    assert_eq!(j["details"]["verdict"], "correct");
    assert_eq!(j["details"]["correct"], true);
    // A render compared with itself: zero error on every sphere.
    let o = BIN.run_ok(&["--compare", s(&out), "--reference", s(&out), "--json"]);
    let j = stdout_json(&o);
    assert_eq!(j["details"]["spheres"].as_array().unwrap().len(), 12);
    assert_eq!(j["details"]["metal_rough"], 0.0);
}

#[test]
fn bad_input_gets_one_line_errors() {
    let dir = tempfile::tempdir().unwrap();
    let p = |n: &str| dir.path().join(n);
    let missing = p("missing.exr");
    let out = p("o.pfm");
    assert_one_line_error(&BIN.run(&[s(&missing), "-o", s(&out)]), 4, "missing.exr");
    assert!(!out.exists());
    // Wrong output extension, checked before the input is read.
    assert_one_line_error(
        &BIN.run(&[s(&missing), "-o", s(&p("o.png"))]),
        2,
        "must be a .pfm",
    );
    assert_one_line_error(
        &BIN.run(&["--orientation-panorama", "-o", s(&p("x.png"))]),
        2,
        ".exr, .hdr or .pfm",
    );
    assert_one_line_error(
        &BIN.run(&[
            "--orientation-panorama",
            "-o",
            s(&p("x.exr")),
            "--width",
            "7",
        ]),
        2,
        "--width 7",
    );
    // Two modes at once, or none.
    assert_one_line_error(
        &BIN.run(&[s(&missing), "--orientation-panorama", "-o", s(&out)]),
        2,
        "exactly one of",
    );
    assert_one_line_error(&BIN.run(&["-o", s(&out)]), 2, "exactly one of");
    // Truncated and garbled PFMs.
    let bad = p("bad.pfm");
    std::fs::write(&bad, b"PF\n768 256\n-1.0\n\0\0\0\0").unwrap();
    assert_one_line_error(&BIN.run(&["--check-orientation", s(&bad)]), 2, "bad.pfm");
    std::fs::write(&bad, b"P6\n1 1\n255\n\0\0\0").unwrap();
    assert_one_line_error(&BIN.run(&["--check-orientation", s(&bad)]), 2, "PF or Pf");
    // A well-formed PFM of the wrong size.
    let small = p("small.pfm");
    let mut b = b"PF\n2 1\n-1.0\n".to_vec();
    b.extend(std::iter::repeat_n(0u8, 24));
    std::fs::write(&small, &b).unwrap();
    assert_one_line_error(
        &BIN.run(&["--check-orientation", s(&small)]),
        2,
        "the scene is 768",
    );
    assert_one_line_error(
        &BIN.run(&["--compare", s(&small), "--reference", s(&small)]),
        2,
        "768",
    );
    // A garbled environment.
    let env = p("env.exr");
    std::fs::write(&env, b"not an exr at all").unwrap();
    assert_one_line_error(&BIN.run(&[s(&env), "-o", s(&out)]), 2, "env.exr");
    assert!(!out.exists());
}

/// NaN/Inf texels are refused (exit 2, one line, nothing written) unless --sanitize.
#[test]
fn non_finite_input_is_refused_unless_sanitized() {
    use ibl_core::io::{write_image, WriteOptions};
    let dir = tempfile::tempdir().unwrap();
    let env = dir.path().join("nan.exr");
    let mut img = ibl_core::Image::new(16, 8, 3);
    img.data.iter_mut().for_each(|v| *v = 0.5);
    img.data[40] = f32::NAN;
    write_image(&env, &img, &WriteOptions::default()).unwrap();
    let out = dir.path().join("o.pfm");
    assert_one_line_error(&BIN.run(&[s(&env), "-o", s(&out)]), 2, "NaN/Inf");
    assert!(!out.exists());
    let o = BIN.run_ok(&[
        s(&env),
        "-o",
        s(&out),
        "--sanitize",
        "--probes",
        "2",
        "--engine",
        "unity",
        "--json",
    ]);
    let j = stdout_json(&o);
    assert_eq!(j["details"]["engine"], "unity");
    assert!(j["details"]["brdf_source"]
        .as_str()
        .unwrap()
        .contains("Unity-Technologies/Graphics"));
    assert!(out.is_file());
}
