//! End-to-end: the real `quat-map` binary on the fixtures and on generated material folders.

use ibl_core::io::{read_image, ColorSpace};
use ibl_testkit::{stderr, Bin};
use std::path::{Path, PathBuf};
use std::process::Output;

const BIN: Bin = Bin::new(env!("CARGO_BIN_EXE_quat-map"), "quat-map");

fn fixture(name: &str) -> PathBuf {
    ibl_testkit::fixture(&format!("normals/{name}"))
}

fn png_bit_depth(p: &Path) -> u8 {
    std::fs::read(p).unwrap()[24]
}

/// The thesis's n' = (−2ac, 2ab, a²−b²−c²) and the erratum-corrected b', computed here
/// independently of the library from the decoded texels.
fn frame(q: [f64; 3]) -> [[f64; 3]; 3] {
    let [a, b, c] = q;
    [
        [a * a + b * b - c * c, 2.0 * b * c, 2.0 * a * c],
        [2.0 * b * c, a * a - b * b + c * c, -2.0 * a * b],
        [-2.0 * a * c, 2.0 * a * b, a * a - b * b - c * c],
    ]
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// (max angle between n' and the input normal, max Gram error, min det) over all texels.
fn measure(input: &Path, output: &Path, y_down: bool) -> (f64, f64, f64) {
    let n_img = read_image(input, ColorSpace::Linear).unwrap();
    let q_img = read_image(output, ColorSpace::Linear).unwrap();
    assert_eq!((n_img.width, n_img.height), (q_img.width, q_img.height));
    let (mut max_angle, mut max_gram, mut min_det) = (0.0f64, 0.0f64, f64::MAX);
    for (t, s) in n_img
        .data
        .chunks(n_img.channels)
        .zip(q_img.data.chunks(q_img.channels))
    {
        let mut n = [0, 1, 2].map(|k| 2.0 * t[k] as f64 - 1.0);
        if y_down {
            n[1] = -n[1];
        }
        let len = dot(n, n).sqrt();
        if len < 0.01 {
            continue;
        }
        let q = [0, 1, 2].map(|k| 2.0 * s[k] as f64 - 1.0);
        let f = frame(q);
        let np = f[2];
        let cos = dot(np, n) / (dot(np, np).sqrt() * len);
        let cr = [
            np[1] * n[2] - np[2] * n[1],
            np[2] * n[0] - np[0] * n[2],
            np[0] * n[1] - np[1] * n[0],
        ];
        let sin = dot(cr, cr).sqrt() / (dot(np, np).sqrt() * len);
        max_angle = max_angle.max(sin.atan2(cos));
        for i in 0..3 {
            for j in 0..3 {
                let want = if i == j { 1.0 } else { 0.0 };
                max_gram = max_gram.max((dot(f[i], f[j]) - want).abs());
            }
        }
        let c = [
            f[0][1] * f[1][2] - f[0][2] * f[1][1],
            f[0][2] * f[1][0] - f[0][0] * f[1][2],
            f[0][0] * f[1][1] - f[0][1] * f[1][0],
        ];
        min_det = min_det.min(dot(c, f[2]));
    }
    (max_angle, max_gram, min_det)
}

#[test]
fn converts_fixtures_within_the_bit_depth_bound() {
    let dir = tempfile::tempdir().unwrap();
    for (bits, bound) in [(16u8, 5.286e-5), (8, 1.3585e-2)] {
        for name in ["0000.png", "0003_256.png", "0008_128.png"] {
            let out = dir.path().join(format!("{name}.{bits}.png"));
            BIN.bake(
                fixture(name),
                &out,
                &["--bits", &bits.to_string(), "--quiet"],
            );
            assert_eq!(png_bit_depth(&out), bits);
            let (angle, gram, det) = measure(&fixture(name), &out, false);
            eprintln!("{name} {bits}-bit: n' max error {angle:.3e} rad (bound {bound:.3e}), Gram error {gram:.3e}, min det {det:.6}");
            assert!(angle <= bound + 1e-6, "{angle}");
            // Gram error of the raw |q|²·R frame: (1 + √3·eps)⁴ − 1.
            let eps = 1.0 / ((1u32 << bits) - 1) as f64;
            assert!(
                gram <= (1.0 + 3f64.sqrt() * eps).powi(4) - 1.0 + 1e-6,
                "{gram}"
            );
            assert!(det > 0.9);
        }
    }
}

#[test]
fn check_json_exr_and_y_down() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("q.exr");
    let o = BIN.bake(
        fixture("0008_128.png"),
        &out,
        &["--check", "--json", "--half"],
    );
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let check = &j["details"]["check"];
    let (err, bound) = (
        check["max_angle_error_rad"].as_f64().unwrap(),
        check["angle_bound_rad"].as_f64().unwrap(),
    );
    eprintln!("--check on half EXR: {err:.3e} rad, bound {bound:.3e}");
    assert!(err <= bound && check["left_handed"] == 0);
    assert_eq!(j["details"]["stats"]["texels"], 128 * 128);
    let (angle, _, _) = measure(&fixture("0008_128.png"), &out, false);
    assert!(
        (angle - err).abs() < 1e-6,
        "independent {angle} vs --check {err}"
    );
    // --y-down: measured against the flipped normal it is as accurate.
    let down = dir.path().join("d.png");
    BIN.bake(fixture("0008_128.png"), &down, &["--y-down", "-q"]);
    let (angle, _, _) = measure(&fixture("0008_128.png"), &down, true);
    assert!(angle <= 5.3e-5, "{angle}");
}

#[test]
fn bad_inputs_fail_with_one_line_and_the_right_code() {
    let dir = tempfile::tempdir().unwrap();
    let truncated = dir.path().join("broken.png");
    let bytes = std::fs::read(fixture("0008_128.png")).unwrap();
    std::fs::write(&truncated, &bytes[..bytes.len() / 3]).unwrap();
    let grey = dir.path().join("grey.png");
    ibl_core::io::write_image(&grey, &ibl_core::Image::new(4, 4, 1), &Default::default()).unwrap();
    let out = dir.path().join("q.png");
    let fx = fixture("0008_128.png");
    let missing = Path::new("/nonexistent/normal.png");
    let cases: [(&Path, &Path, &[&str], i32, &str); 6] = [
        (&truncated, &out, &[], 2, "broken.png"),
        (missing, &out, &[], 4, "/nonexistent/normal.png"),
        (&grey, &out, &[], 3, "single channel"),
        (&fx, &out, &["--bits", "12"], 2, "--bits 12"),
        (&fx, Path::new("q.hdr"), &[], 3, ".png or .exr"),
        (&fx, &out, &["--force"], 2, "--batch only"),
    ];
    for (input, to, flags, code, needle) in cases {
        BIN.refused_bake(input, to, flags, code, needle);
    }
    // No -o at all: clap's usage error, which takes several lines.
    let r = BIN.cmd().arg(&fx).output().unwrap();
    let e = stderr(&r);
    eprintln!("[{fx:?}] → {} {}", r.status.code().unwrap_or(-1), e.trim());
    assert_eq!(r.status.code(), Some(2), "{e}");
    assert!(e.contains("--output") && !e.contains("panicked"), "{e}");
    assert!(!out.exists());
}

fn batch_json(root: &Path, extra: &[&str]) -> (Output, serde_json::Value) {
    let mut args = vec!["--batch", root.to_str().unwrap(), "--json", "-q"];
    args.extend_from_slice(extra);
    let o = BIN.run(&args);
    let j = serde_json::from_slice(&o.stdout).unwrap_or(serde_json::Value::Null);
    (o, j)
}

/// (converted, skipped, failed) from the `--json` summary, which has the same wrapper
/// whether the batch succeeded or not.
fn counts(j: &serde_json::Value) -> [usize; 3] {
    assert_eq!(j["tool"], "quat-map", "not the summary wrapper: {j}");
    assert!(
        j["version"].is_string() && j["outputs"].is_array() && j["warnings"].is_array(),
        "not the summary wrapper: {j}"
    );
    let r = &j["details"];
    ["converted", "skipped", "failed"]
        .map(|k| r[k].as_array().map(|a| a.len()).unwrap_or(usize::MAX))
}

#[test]
fn batch_converts_skips_and_isolates_a_broken_file() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path().join("textures");
    let good = [
        ("brick", "0000.png"),
        ("metal", "0003_256.png"),
        ("cloth/worn", "0008_128.png"),
    ];
    for (m, f) in good {
        std::fs::create_dir_all(root.join(m)).unwrap();
        std::fs::copy(fixture(f), root.join(m).join("normal.png")).unwrap();
        std::fs::write(root.join(m).join("albedo.jpg"), b"not looked at").unwrap();
    }
    // A material whose normal map is truncated, and an environment folder without one.
    std::fs::create_dir_all(root.join("broken")).unwrap();
    let bytes = std::fs::read(fixture("0003_256.png")).unwrap();
    std::fs::write(root.join("broken/Normal.PNG"), &bytes[..bytes.len() / 2]).unwrap();
    std::fs::create_dir_all(root.join("studio_env")).unwrap();

    let (o, j) = batch_json(&root, &[]);
    eprintln!("first run: {}", stderr(&o));
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert_eq!(counts(&j), [3, 0, 1]);
    let err = stderr(&o);
    assert!(
        err.contains("failed:") && err.contains("broken/Normal.PNG"),
        "{err}"
    );
    assert!(
        err.lines()
            .last()
            .unwrap()
            .contains("1 of 4 material(s) failed"),
        "{err}"
    );
    for (m, f) in good {
        let q = root.join(m).join("quaternion.png");
        assert!(q.is_file() && root.join(m).join(".quaternion.png.opts").is_file());
        let (angle, _, _) = measure(&fixture(f), &q, false);
        assert!(angle <= 5.3e-5, "{m}: {angle}");
    }
    assert!(!root.join("broken/quaternion.png").exists());
    assert!(!root.join("studio_env/quaternion.png").exists());

    // Second run: the good ones are skipped, the broken one fails again.
    let before = std::fs::metadata(root.join("brick/quaternion.png"))
        .unwrap()
        .modified()
        .unwrap();
    let (o, j) = batch_json(&root, &[]);
    assert_eq!(o.status.code(), Some(2));
    assert_eq!(counts(&j), [0, 3, 1]);
    assert_eq!(
        std::fs::metadata(root.join("brick/quaternion.png"))
            .unwrap()
            .modified()
            .unwrap(),
        before
    );

    // Repair the broken file: only it converts; then everything is skipped and the run succeeds.
    std::fs::copy(fixture("0003_256.png"), root.join("broken/Normal.PNG")).unwrap();
    let (o, j) = batch_json(&root, &[]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(counts(&j), [1, 3, 0]);
    let (o, j) = batch_json(&root, &[]);
    assert!(o.status.success());
    assert_eq!(counts(&j), [0, 4, 0]);

    // Other options convert everything again (and the sidecar records them).
    let (o, j) = batch_json(&root, &["--bits", "8"]);
    assert!(o.status.success());
    assert_eq!(counts(&j), [4, 0, 0]);
    assert_eq!(png_bit_depth(&root.join("metal/quaternion.png")), 8);
    let side: serde_json::Value =
        serde_json::from_slice(&std::fs::read(root.join("metal/.quaternion.png.opts")).unwrap())
            .unwrap();
    assert_eq!(side["options"]["bits"], 8);
    // Nothing but outputs and sidecars was added; no temporary files left behind.
    let names: Vec<String> = std::fs::read_dir(root.join("metal"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert_eq!(names.len(), 4, "{names:?}");
}

#[test]
fn batch_root_errors() {
    // A missing root is the file system's answer: I/O (4), one line naming it.
    let (o, _) = batch_json(Path::new("/nonexistent/textures"), &[]);
    let e = stderr(&o);
    assert_eq!(o.status.code(), Some(4), "{e}");
    assert_eq!(e.trim().lines().count(), 1, "{e}");
    assert!(e.contains("/nonexistent/textures"), "{e}");
    // A file given as the root: invalid input (2).
    let (o, _) = batch_json(&fixture("0000.png"), &[]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("not a folder"));
    let dir = tempfile::tempdir().unwrap();
    let (o, _) = batch_json(dir.path(), &["--output-name", "q.tga"]);
    assert_eq!(o.status.code(), Some(3), "{}", stderr(&o));
}

#[test]
fn a_batch_where_nothing_matches_fails_naming_the_input_name() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::create_dir_all(dir.path().join("brick")).unwrap();
    std::fs::copy(fixture("0000.png"), dir.path().join("brick/brick_n.png")).unwrap();
    let (o, _) = batch_json(dir.path(), &[]);
    let e = stderr(&o);
    assert_eq!(o.status.code(), Some(2), "{e}");
    assert_eq!(e.trim().lines().count(), 1, "{e}");
    assert!(e.contains("--input-name") && e.contains("normal.*"), "{e}");
    assert!(!dir.path().join("brick/quaternion.png").exists());
    // With the right pattern the same folder converts.
    let (o, j) = batch_json(dir.path(), &["--input-name", "*_n.png"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(counts(&j), [1, 0, 0]);
}

/// A two-channel map holding a 45° tilt towards +y: refused without `--two-channel` (one
/// line, exit 3, no panic, nothing written), converted with it to a = cos 22.5°, b = sin 22.5°.
fn two_channel_needs_the_flag(input: &Path, tol: f64) {
    let out = input.with_file_name("q.exr");
    let e = BIN.refused_bake(input, &out, &[], 3, "--two-channel");
    let name = input.file_name().unwrap().to_str().unwrap();
    assert!(e.contains(name), "{e}");
    assert!(!out.exists());
    BIN.bake(input, &out, &["--two-channel", "-q"]);
    let q = read_image(&out, ColorSpace::Linear).unwrap();
    let q = [0, 1, 2].map(|k| 2.0 * q.data[k] as f64 - 1.0);
    let (sn, cs) = 22.5f64.to_radians().sin_cos();
    assert!(
        (q[0] - cs).abs() < tol && (q[1] - sn).abs() < tol && q[2].abs() < tol,
        "{q:?}"
    );
}

#[test]
fn two_channel_grey_alpha_png() {
    // x in grey, y in alpha (a BC5 map saved as grey+alpha), quantised to 8 bits.
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("bc5.png");
    let s = std::f32::consts::FRAC_1_SQRT_2;
    let img = ibl_core::Image::from_data(1, 1, 2, vec![0.5, s * 0.5 + 0.5]).unwrap();
    ibl_core::io::write_image(&input, &img, &Default::default()).unwrap();
    two_channel_needs_the_flag(&input, 1e-4);
}

#[test]
fn every_fixture_is_byte_identical_with_one_and_two_threads() {
    let dir = tempfile::tempdir().unwrap();
    for name in ["0000.png", "0003_256.png", "0008_128.png"] {
        let outs: Vec<Vec<u8>> = ["1", "2"]
            .iter()
            .map(|t| {
                let out = dir.path().join(format!("{t}_{name}"));
                BIN.bake(fixture(name), &out, &["--threads", t, "--quiet"]);
                std::fs::read(&out).unwrap()
            })
            .collect();
        assert!(outs[0] == outs[1], "{name}");
    }
}

/// A two-channel EXR (R, G only: ibl-core keeps both channels), a 45° tilt towards +y.
fn write_two_channel_exr(path: &Path) {
    let s = std::f32::consts::FRAC_1_SQRT_2;
    let img = ibl_core::Image::from_data(2, 1, 2, vec![0.5, s * 0.5 + 0.5, 0.5, 0.5]).unwrap();
    ibl_core::io::write_image(path, &img, &Default::default()).unwrap();
    assert_eq!(read_image(path, ColorSpace::Linear).unwrap().channels, 2);
}

#[test]
fn two_channel_exr_needs_the_flag_and_never_panics() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("rg.exr");
    write_two_channel_exr(&input);
    two_channel_needs_the_flag(&input, 1e-6);
}

#[test]
fn batch_records_a_two_channel_exr_as_one_failure() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path().join("textures");
    std::fs::create_dir_all(root.join("a_good")).unwrap();
    std::fs::copy(fixture("0008_128.png"), root.join("a_good/normal.png")).unwrap();
    std::fs::create_dir_all(root.join("b_rg")).unwrap();
    write_two_channel_exr(&root.join("b_rg/normal.exr"));
    let (o, j) = batch_json(&root, &[]);
    let e = stderr(&o);
    assert!(!e.contains("panicked"), "{e}");
    assert_eq!(o.status.code(), Some(3), "{e}");
    assert_eq!(counts(&j), [1, 0, 1], "{j}");
    assert!(
        e.contains("b_rg/normal.exr") && e.contains("--two-channel"),
        "{e}"
    );
    assert!(root.join("a_good/quaternion.png").is_file());
    assert!(!root.join("b_rg/quaternion.png").exists());
}

#[test]
fn refuses_to_overwrite_its_input() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::create_dir_all(dir.path().join("sub")).unwrap();
    let input = dir.path().join("n.png");
    std::fs::copy(fixture("0008_128.png"), &input).unwrap();
    let before = std::fs::read(&input).unwrap();
    let same = input.to_str().unwrap().to_string();
    // The same file spelt differently: through "sub/..", and relative to the working folder.
    let dotted = dir.path().join("sub/../n.png");
    for out in [same.as_str(), dotted.to_str().unwrap(), "n.png"] {
        let o = BIN
            .cmd()
            .current_dir(dir.path())
            .args([same.as_str(), "-o", out])
            .output()
            .unwrap();
        let e = stderr(&o);
        assert_eq!(o.status.code(), Some(2), "{out}: {e}");
        assert_eq!(e.trim().lines().count(), 1, "{e}");
        // The input named as the output: refused as the input, or (a file the tool did not
        // write) by the ownership check that comes first.
        assert!(
            (e.contains("is the input") || e.contains("was not written by this tool"))
                && !e.contains("panicked"),
            "{e}"
        );
        assert_eq!(std::fs::read(&input).unwrap(), before, "{out}");
    }
}

/// A real JPEG of a fixture normal map (quality 95), and the same bytes cut short.
fn jpeg_of(png: &Path) -> Vec<u8> {
    let img = image::open(png).unwrap().to_rgb8();
    let mut out = Vec::new();
    image::codecs::jpeg::JpegEncoder::new_with_quality(&mut out, 95)
        .encode_image(&img)
        .unwrap();
    out
}

#[test]
fn truncated_jpegs_are_refused_with_one_line_and_no_output() {
    let dir = tempfile::tempdir().unwrap();
    let bytes = jpeg_of(&fixture("0008_128.png"));
    let whole = dir.path().join("n.jpg");
    std::fs::write(&whole, &bytes).unwrap();
    let q = dir.path().join("q.png");
    BIN.bake(&whole, &q, &["--quiet"]);
    for f in [0.2, 0.5, 0.8, 0.97] {
        let cut = (bytes.len() as f64 * f) as usize;
        let t = dir.path().join(format!("t{cut}.jpg"));
        std::fs::write(&t, &bytes[..cut]).unwrap();
        let out = dir.path().join(format!("q{cut}.png"));
        let e = BIN.refused_bake(&t, &out, &[], 2, "truncated JPEG");
        assert!(e.contains(&format!("t{cut}.jpg")), "cut {cut}: {e}");
        assert!(!out.exists());
    }
}

#[test]
fn output_problems_are_found_before_the_input_is_read() {
    let dir = tempfile::tempdir().unwrap();
    let in_the_way = dir.path().join("notes.txt");
    std::fs::write(&in_the_way, "x").unwrap();
    let input = fixture("0008_128.png");
    // A folder where the output file should go, and a file in the way of its folder.
    let folder = dir.path().join("out.png");
    std::fs::create_dir(&folder).unwrap();
    for (out, says, code) in [
        (folder.clone(), "is an existing folder", 2),
        (in_the_way.join("q.png"), "a file in the way", 2),
    ] {
        let o = BIN.run_bake(&input, &out, &[]);
        let e = stderr(&o);
        assert_eq!(o.status.code(), Some(code), "{e}");
        assert!(e.contains(says), "{e}");
    }
    // A negative value reaches the range check instead of clap's "unexpected argument".
    let o = BIN.run_bake(&input, "q.png", &["--min-length", "-1"]);
    let e = stderr(&o);
    assert_eq!(o.status.code(), Some(2), "{e}");
    assert!(e.contains("--min-length -1 is out of range"), "{e}");
    // Checked first: a missing input is not even opened.
    let o = BIN.run_bake("missing.png", &folder, &[]);
    assert!(
        stderr(&o).contains("is an existing folder"),
        "{}",
        stderr(&o)
    );
}

#[test]
fn json_failure_prints_an_error_object_and_a_closed_stdout_is_quiet() {
    let dir = tempfile::tempdir().unwrap();
    let o = BIN.run_bake("missing.png", "q.png", &["--json"]);
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).expect("JSON on stdout");
    assert_eq!(v["exit_code"], 4);
    assert!(v["error"].as_str().unwrap().contains("missing.png"));
    // stdout closed before the summary is printed: no panic, no backtrace.
    let q = dir.path().join("q.png");
    let (reader, writer) = std::io::pipe().unwrap();
    drop(reader);
    let o = BIN
        .cmd()
        .args([fixture("0008_128.png").to_str().unwrap(), "-o"])
        .arg(&q)
        .args(["--json", "--quiet"])
        .stdout(writer)
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(!stderr(&o).contains("panicked"), "{}", stderr(&o));
}

#[test]
fn help_convention_holds_for_a_shader_and_for_a_quaternion_library() {
    // The written map decoded both ways --help states: the shader's n' = (−2ac, 2ab,
    // a²−b²−c²), and glam (q·v·q̄) given the conjugate (−b, −c, 0, a). Passing (b, c, 0, a)
    // unchanged must give the mirror image, as the help warns.
    let dir = tempfile::tempdir().unwrap();
    let input = fixture("0008_128.png");
    let out = dir.path().join("q.exr");
    BIN.bake(&input, &out, &["--quiet"]);
    let help = ibl_testkit::stdout(&BIN.run(&["--help"]));
    assert!(help.contains("Quat::from_xyzw(−b, −c, 0, a)"), "{help}");
    let n_img = read_image(&input, ColorSpace::Linear).unwrap();
    let q_img = read_image(&out, ColorSpace::Linear).unwrap();
    let (mut shader, mut library, mut mirrored, mut count) = (0.0f64, 0.0f64, 0.0f64, 0);
    for (t, s) in n_img
        .data
        .chunks(n_img.channels)
        .zip(q_img.data.chunks(q_img.channels))
    {
        let n = glam::DVec3::from_array([0, 1, 2].map(|k| 2.0 * t[k] as f64 - 1.0));
        if n.length() < 0.5 {
            continue;
        }
        let n = n.normalize();
        let [a, b, c] = [0, 1, 2].map(|k| 2.0 * s[k] as f64 - 1.0);
        let np = glam::DVec3::new(-2.0 * a * c, 2.0 * a * b, a * a - b * b - c * c);
        shader = shader.max((np - n).length());
        let lib = glam::DQuat::from_xyzw(-b, -c, 0.0, a).normalize() * glam::DVec3::Z;
        library = library.max((lib - n).length());
        let naive = glam::DQuat::from_xyzw(b, c, 0.0, a).normalize() * glam::DVec3::Z;
        mirrored = mirrored.max((naive - glam::DVec3::new(-n.x, -n.y, n.z)).length());
        count += 1;
    }
    assert!(count > 1000);
    // The EXR holds q in float32: both decodes agree with the input to its precision.
    assert!(shader < 1e-5 && library < 1e-5, "{shader} {library}");
    assert!(mirrored < 1e-5, "{mirrored}");
}

#[test]
fn a_flat_folder_converts_with_stem_output_names() {
    let dir = tempfile::tempdir().unwrap();
    for name in ["0003_256.png", "0008_128.png"] {
        let stem = name.trim_end_matches(".png");
        std::fs::copy(fixture(name), dir.path().join(format!("{stem}_normal.png"))).unwrap();
    }
    let args = [
        "--batch",
        dir.path().to_str().unwrap(),
        "--input-name",
        "*.png",
        "--output-name",
        "{stem}_quat.png",
        "--quiet",
    ];
    BIN.run_ok(&args);
    for stem in ["0003_256", "0008_128"] {
        let out = dir.path().join(format!("{stem}_normal_quat.png"));
        let (angle, _, _) = measure(&dir.path().join(format!("{stem}_normal.png")), &out, false);
        assert!(angle < 5.3e-5, "{stem}: {angle}");
    }
    // The outputs fit "*.png" too, but are never taken as inputs: a second run has nothing
    // new to convert and writes no *_quat_quat.png.
    let o = BIN.run(&[&args[..], &["--json"]].concat());
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(v["details"]["skipped"].as_array().unwrap().len(), 2, "{v}");
    assert!(!dir.path().join("0003_256_normal_quat_quat.png").exists());
}
