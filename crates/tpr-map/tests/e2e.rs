//! End-to-end: the real `tpr-map` binary, its outputs checked against closed forms.

use ibl_core::io::{read_image, write_image, ColorSpace, WriteOptions};
use ibl_core::Image;
use ibl_testkit::{stderr, Bin};
use std::f64::consts::PI;
use std::path::Path;

const BIN: Bin = Bin::new(env!("CARGO_BIN_EXE_tpr-map"), "tpr-map");

fn tangent(img: &Image, i: usize, j: usize) -> [f64; 2] {
    let t = img.texel(i, j);
    [2.0 * t[0] as f64 - 1.0, 2.0 * t[1] as f64 - 1.0]
}

#[test]
fn radial_preset_against_circle_tangents() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("pan.png");
    let preset = ["--preset", "radial:0.25,0.5", "--roughness", "0.2,0.6"];
    BIN.generate(&out, &[&["--size", "64x32", "-q"][..], &preset].concat());
    let img = read_image(&out, ColorSpace::Linear).unwrap();
    assert_eq!((img.width, img.height, img.channels), (64, 32, 4));
    assert_eq!(std::fs::read(&out).unwrap()[24], 16, "16-bit PNG");
    let mut worst = 0.0f64;
    for j in 0..32 {
        for i in 0..64 {
            // Offset from the centre in pixels, +y up the image.
            let (px, py) = (i as f64 + 0.5 - 16.0, -(j as f64 + 0.5 - 16.0));
            let r = px.hypot(py);
            let want = [-py / r, px / r];
            let t = tangent(&img, i, j);
            worst = worst
                .max((t[0] - want[0]).abs())
                .max((t[1] - want[1]).abs());
            let rough = img.texel(i, j);
            assert!((rough[2] - 0.2).abs() < 1e-4 && (rough[3] - 0.6).abs() < 1e-4);
        }
    }
    eprintln!(
        "radial: max |t − closed form| = {worst:.2e} (16-bit step {:.2e})",
        1.0 / 65535.0
    );
    assert!(worst <= 1.0 / 65535.0 + 1e-6);
}

#[test]
fn wave_preset_equals_the_thesis_expression_and_its_closed_form() {
    let dir = tempfile::tempdir().unwrap();
    let a = dir.path().join("a.exr");
    let b = dir.path().join("b.exr");
    BIN.generate(&a, &["--size", "16x24", "--preset", "wave", "-q"]);
    let expr = "x = cos(pi*v); y = sin(pi*v)";
    BIN.generate(&b, &["--size", "16x24", "--expr", expr, "-q"]);
    assert_eq!(std::fs::read(&a).unwrap(), std::fs::read(&b).unwrap());
    let img = read_image(&a, ColorSpace::Linear).unwrap();
    let mut worst = 0.0f64;
    for j in 0..24 {
        let v = (j as f64 + 0.5) / 24.0;
        for i in 0..16 {
            let t = tangent(&img, i, j);
            worst = worst
                .max((t[0] - (PI * v).cos()).abs())
                .max((t[1] - (PI * v).sin()).abs());
        }
    }
    eprintln!("wave (EXR float): max error {worst:.2e}");
    assert!(worst < 1e-6);
}

#[test]
fn angle_map_and_roughness_map() {
    let dir = tempfile::tempdir().unwrap();
    let angles = dir.path().join("angles.png");
    let mut a = Image::new(8, 4, 1);
    for (k, v) in a.data.iter_mut().enumerate() {
        *v = (k * 8) as f32 / 255.0;
    }
    write_image(
        &angles,
        &a,
        &WriteOptions {
            png_bits: 8,
            ..Default::default()
        },
    )
    .unwrap();
    let rough = dir.path().join("rough.png");
    write_image(
        &rough,
        &Image::from_data(1, 1, 3, vec![0.25, 0.75, 0.0]).unwrap(),
        &WriteOptions::default(),
    )
    .unwrap();
    let out = dir.path().join("t.exr");
    let (a, r) = (angles.to_str().unwrap(), rough.to_str().unwrap());
    let o = BIN.generate(&out, &["--angle-map", a, "--roughness-map", r, "--json"]);
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(j["details"]["stats"]["width"], 8);
    let img = read_image(&out, ColorSpace::Linear).unwrap();
    for k in 0..32 {
        let theta = (k * 8) as f64 / 255.0 * PI;
        let t = tangent(&img, k % 8, k / 8);
        assert!(
            (t[0] - theta.cos()).abs() < 1e-6 && (t[1] - theta.sin()).abs() < 1e-6,
            "{k}"
        );
        let r = img.texel(k % 8, k / 8);
        assert!((r[2] - 0.25).abs() < 1e-4 && (r[3] - 0.75).abs() < 1e-4);
    }
}

#[test]
fn fallbacks_are_reported_and_errors_are_one_line() {
    let dir = tempfile::tempdir().unwrap();
    let o = &dir.path().join("t.png");
    // 5×5 radial: the centre texel has no direction.
    let r = BIN.generate(o, &["--size", "5", "--preset", "radial", "--json"]);
    let j: serde_json::Value = serde_json::from_slice(&r.stdout).unwrap();
    assert_eq!(j["details"]["stats"]["zero_length"], 1);
    assert!(j["warnings"][0].as_str().unwrap().contains("zero-length"));
    let missing = Path::new("/nonexistent/a.png");
    let wave = ["--size", "8", "--preset", "wave"];
    let rough_expr = ["--roughness-expr", "rx = 0.5; ry = q"];
    let cases: [(&Path, Vec<&str>, i32, &str); 7] = [
        (
            o,
            vec!["--size", "8", "--expr", "x = cos(pi*v; y = 0"],
            2,
            "--expr: column 13",
        ),
        (
            o,
            [&wave[..], &rough_expr].concat(),
            2,
            "--roughness-expr: column 16",
        ),
        (o, vec!["--size", "8"], 2, "exactly one direction source"),
        (o, vec!["--preset", "wave"], 2, "--size"),
        (
            o,
            vec!["--size", "8", "--preset", "swirl"],
            2,
            "unknown preset",
        ),
        (
            o,
            vec!["--angle-map", missing.to_str().unwrap()],
            4,
            "/nonexistent/a.png",
        ),
        (Path::new("t.jpg"), wave.to_vec(), 3, ".png or .exr"),
    ];
    for (out, flags, code, needle) in cases {
        BIN.refused_generate(out, &flags, code, needle);
    }
}

#[test]
fn presets_and_expressions_are_byte_identical_with_one_and_two_threads() {
    let dir = tempfile::tempdir().unwrap();
    for source in [
        ["--preset", "spiral:0.5,0.5,3"],
        ["--expr", "x = cos(pi*v); y = sin(pi*u)"],
    ] {
        let outs: Vec<Vec<u8>> = ["1", "2"]
            .iter()
            .map(|t| {
                let out = dir.path().join(format!("{t}.png"));
                let flags = ["--size", "96x64", source[0], source[1]];
                BIN.generate(&out, &[&flags[..], &["--threads", t, "--quiet"]].concat());
                std::fs::read(&out).unwrap()
            })
            .collect();
        assert!(outs[0] == outs[1], "{source:?}");
    }
}

#[test]
fn two_channel_exr_is_a_direction_map_and_grey_is_not() {
    let dir = tempfile::tempdir().unwrap();
    // R, G only (ibl-core keeps both channels of such an EXR): (1, 1) is the diagonal (R = G,
    // as a grey texel would be), (0.5, 1) is +y.
    let rg = dir.path().join("rg.exr");
    write_image(
        &rg,
        &Image::from_data(2, 1, 2, vec![1.0, 1.0, 0.5, 1.0]).unwrap(),
        &WriteOptions::default(),
    )
    .unwrap();
    assert_eq!(read_image(&rg, ColorSpace::Linear).unwrap().channels, 2);
    let out = dir.path().join("t.exr");
    for kind in ["auto", "direction"] {
        let map = [
            "--angle-map",
            rg.to_str().unwrap(),
            "--angle-map-kind",
            kind,
        ];
        let o = BIN.run_generate(&out, &[&map[..], &["-q"]].concat());
        let e = stderr(&o);
        assert!(o.status.success() && !e.contains("panicked"), "{kind}: {e}");
        let img = read_image(&out, ColorSpace::Linear).unwrap();
        let (a, b) = (tangent(&img, 0, 0), tangent(&img, 1, 0));
        let s = std::f64::consts::FRAC_1_SQRT_2;
        assert!(
            (a[0] - s).abs() < 1e-6 && (a[1] - s).abs() < 1e-6,
            "{kind}: {a:?}"
        );
        assert!(
            b[0].abs() < 1e-6 && (b[1] - 1.0).abs() < 1e-6,
            "{kind}: {b:?}"
        );
    }
    // A single channel has no (x, y): as a direction map it is an error, not +x everywhere.
    let grey = dir.path().join("grey.exr");
    write_image(
        &grey,
        &Image::from_data(2, 1, 1, vec![0.25, 0.5]).unwrap(),
        &WriteOptions::default(),
    )
    .unwrap();
    let bad = dir.path().join("bad.exr");
    let map = [
        "--angle-map",
        grey.to_str().unwrap(),
        "--angle-map-kind",
        "direction",
    ];
    let e = BIN.refused_generate(&bad, &map, 3, "single channel");
    assert!(e.contains("grey.exr"), "{e}");
    assert!(!bad.exists());
}

#[test]
fn non_finite_maps_are_refused_unless_sanitized_and_inputs_are_not_overwritten() {
    let dir = tempfile::tempdir().unwrap();
    let angles = dir.path().join("angles.exr");
    write_image(
        &angles,
        &Image::from_data(2, 1, 1, vec![f32::NAN, 0.5]).unwrap(),
        &WriteOptions::default(),
    )
    .unwrap();
    let rough = dir.path().join("rough.exr");
    write_image(
        &rough,
        &Image::from_data(1, 1, 3, vec![-0.25, 0.5, 0.0]).unwrap(),
        &WriteOptions::default(),
    )
    .unwrap();
    let out = dir.path().join("t.exr");
    let (a, r) = (angles.to_str().unwrap(), rough.to_str().unwrap());
    let maps = ["--angle-map", a, "--roughness-map", r];
    let e = BIN.refused_generate(&out, &maps, 2, "1 NaN/Inf");
    assert!(e.contains("angles.exr"), "{e}");
    assert!(!out.exists());
    let o = BIN.generate(&out, &[&maps[..], &["--sanitize", "--json"]].concat());
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let warnings: Vec<&str> = j["warnings"]
        .as_array()
        .unwrap()
        .iter()
        .map(|w| w.as_str().unwrap())
        .collect();
    assert!(
        warnings
            .iter()
            .any(|w| w.contains("angles.exr") && w.contains("1 NaN/Inf")),
        "{warnings:?}"
    );
    assert!(
        warnings
            .iter()
            .any(|w| w.contains("rough.exr") && w.contains("clamped 1 negative")),
        "{warnings:?}"
    );
    // The NaN angle became 0 (+x); the negative roughness 0.
    let img = read_image(&out, ColorSpace::Linear).unwrap();
    let t = tangent(&img, 0, 0);
    assert!((t[0] - 1.0).abs() < 1e-6 && t[1].abs() < 1e-6, "{t:?}");
    assert_eq!(img.texel(0, 0)[2], 0.0);
    // Writing over an input map is refused and leaves it as it was.
    let before = std::fs::read(&rough).unwrap();
    let over = ["--preset", "wave", "--size", "4", "--roughness-map", r];
    // The ownership check (a file the tool did not write) comes first; with --overwrite the
    // input check still refuses it.
    BIN.refused_generate(&rough, &over, 2, "was not written by this tool");
    let mut forced = over.to_vec();
    forced.push("--overwrite");
    BIN.refused_generate(&rough, &forced, 2, "is the input");
    assert_eq!(std::fs::read(&rough).unwrap(), before);
}

#[test]
fn truncated_jpeg_angle_maps_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let mut grey = image::GrayImage::new(64, 64);
    for (i, p) in grey.pixels_mut().enumerate() {
        p.0 = [(i * 37 % 251) as u8];
    }
    let mut bytes = Vec::new();
    image::codecs::jpeg::JpegEncoder::new_with_quality(&mut bytes, 95)
        .encode_image(&grey)
        .unwrap();
    let out = dir.path().join("t.png");
    for cut in [bytes.len() / 3, bytes.len() * 2 / 3, bytes.len() - 2] {
        let t = dir.path().join("a.jpg");
        std::fs::write(&t, &bytes[..cut]).unwrap();
        let o = BIN.run_generate(&out, &["--angle-map", t.to_str().unwrap()]);
        let e = stderr(&o);
        assert_eq!(o.status.code(), Some(2), "cut {cut}: {e}");
        assert!(e.contains("a.jpg: truncated JPEG"), "{e}");
        assert!(!out.exists());
    }
}
