//! End-to-end tests of the `aniso-eval` binary: a tiny grid with every method and both
//! lookups, the report folder an independent script can recompute pixels from, determinism
//! across thread counts, and one-line errors on malformed input.

use ibl_core::io::{write_image, WriteOptions};
use ibl_core::Image;
use ibl_testkit::{assert_one_line_error, Bin};
use std::path::Path;

const BIN: Bin = Bin::new(env!("CARGO_BIN_EXE_aniso-eval"), "aniso-eval");

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

const SMALL: [&str; 12] = [
    "--sphere-size",
    "16",
    "--roughness",
    "0.5",
    "--eta",
    "0,0.8,-0.8",
    "--views",
    "30",
    "--elevations",
    "20",
    "--truth-samples",
    "1024",
];

#[test]
fn evaluates_every_method_and_writes_the_report_folder() {
    let dir = tempfile::tempdir().unwrap();
    let env = dir.path().join("sky.exr");
    write_env(&env);
    let out = dir.path().join("report");
    let mut args = vec![
        env.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--json",
    ];
    args.extend(SMALL);
    let o = BIN.run(&args);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(v["details"]["cases"], 3);
    let rep = ibl_testkit::read_json(&out.join("report.json"));
    let cases = rep["cases"].as_array().unwrap();
    assert_eq!(cases.len(), 3);
    for c in cases {
        // 5 chain methods × 2 lookups + FIS, × 2 F0.
        let scores = c["scores"].as_array().unwrap();
        assert_eq!(scores.len(), 2 * 11, "{c}");
        for s in scores {
            let (e, m) = (
                s["rel_rmse"].as_f64().unwrap(),
                s["mean_rel"].as_f64().unwrap(),
            );
            assert!(
                e.is_finite() && e >= 0.0 && m.is_finite() && m >= 0.0,
                "{s}"
            );
        }
        // η = 0: every bent normal is the isotropic split sum.
        if c["eta"].as_f64().unwrap() == 0.0 {
            let mse = |name: &str| {
                scores
                    .iter()
                    .find(|s| s["method"] == name && s["lookup"] == "engine" && s["f0"] == 1.0)
                    .unwrap()["mse"]
                    .as_f64()
                    .unwrap()
            };
            // (up to the rounding of normalize(lerp(n, g, 0))).
            for m in ["bent-lg18", "bent-filament", "bent-khr"] {
                assert!((mse("iso") - mse(m)).abs() <= 1e-5 * mse("iso"), "{m}");
            }
        }
    }
    let case0 = out.join("case000_sky");
    for f in [
        "case.json",
        "frame_n.exr",
        "frame_t.exr",
        "truth_e0.exr",
        "truth_se0.exr",
        "major-16_engine_e0.exr",
        "major-16_oracle_e1.exr",
        "fis-16_none_e0.exr",
        "montage.png",
    ] {
        assert!(case0.join(f).is_file(), "{f}");
    }
    // The report is enough to recompute a pixel: its frame, the view and the material.
    let meta = ibl_testkit::read_json(&case0.join("case.json"));
    assert_eq!(
        meta["pixels"].as_array().unwrap().len() as u64,
        cases[0]["pixels"].as_u64().unwrap()
    );
    let truth = ibl_core::io::read_image(
        &case0.join("truth_e0.exr"),
        ibl_core::io::ColorSpace::Linear,
    )
    .unwrap();
    assert_eq!((truth.width, truth.height), (16, 16));
    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(
        md.contains("| major-16 | engine |") && md.contains("| fis-16 | none |"),
        "{md}"
    );
}

#[test]
fn renders_the_plate_with_a_radial_tangent_field() {
    let dir = tempfile::tempdir().unwrap();
    let env = dir.path().join("sky.exr");
    write_env(&env);
    let out = dir.path().join("plate");
    let args = [
        env.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--json",
        "--scene",
        "plate",
        "--tangent",
        "radial",
        "--sphere-size",
        "16",
        "--roughness",
        "0.4",
        "--eta",
        "0.8",
        "--views",
        "0",
        "--elevations",
        "40",
        "--truth-samples",
        "512",
        "--methods",
        "iso,bent-lg18,major-8",
        "--lookup",
        "engine",
    ];
    let o = BIN.run(&args);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let rep = ibl_testkit::read_json(&out.join("report.json"));
    let c = &rep["cases"][0];
    assert!(c["pixels"].as_u64().unwrap() > 40, "{c}");
    assert_eq!(c["scores"].as_array().unwrap().len(), 2 * 3);
    // Per-pixel views are in the report (perspective: they differ).
    let meta = ibl_testkit::read_json(&out.join("case000_sky/case.json"));
    let px = meta["pixels"].as_array().unwrap();
    assert_ne!(px[0]["v"], px[px.len() - 1]["v"]);
}

#[test]
fn renders_ashikhmin_shirley_lobes_through_the_thesis_route() {
    let dir = tempfile::tempdir().unwrap();
    let env = dir.path().join("sky.exr");
    write_env(&env);
    let out = dir.path().join("as");
    let args = [
        env.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--no-pixels",
        "--sphere-size",
        "12",
        "--roughness",
        "0.5",
        "--eta",
        "0",
        "--views",
        "0",
        "--elevations",
        "0",
        "--truth-samples",
        "512",
        "--as-lobes",
        "100x10",
        "--methods",
        "iso,as-thesis-16,as-weighted-16",
    ];
    let o = BIN.run(&args);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let rep = ibl_testkit::read_json(&out.join("report.json"));
    let cases = rep["cases"].as_array().unwrap();
    assert_eq!(cases.len(), 2);
    let as_case = &cases[1];
    assert!(
        as_case["material"]["AshikhminShirley"].is_object(),
        "{as_case}"
    );
    let names: Vec<&str> = as_case["scores"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| s["method"].as_str().unwrap())
        .collect();
    assert_eq!(
        names,
        [
            "as-thesis-16",
            "as-weighted-16",
            "as-thesis-16",
            "as-weighted-16"
        ]
    );
    // Only AS methods: the GGX lobes have nothing to score and get no case (nor truth).
    let only_as: Vec<&str> = args
        .iter()
        .map(|a| {
            if *a == "iso,as-thesis-16,as-weighted-16" {
                "as-grid-16"
            } else {
                a
            }
        })
        .collect();
    let o = BIN.run(&only_as);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let rep = ibl_testkit::read_json(&out.join("report.json"));
    let cases = rep["cases"].as_array().unwrap();
    assert_eq!(cases.len(), 1, "{rep}");
    assert_eq!(cases[0]["scores"][0]["method"], "as-grid-16");
    let r = BIN.run(&[
        env.to_str().unwrap(),
        "--as-lobes",
        "100",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_one_line_error(&r, 2, "--as-lobes");
}

#[test]
fn reports_are_identical_for_any_thread_count() {
    let dir = tempfile::tempdir().unwrap();
    let env = dir.path().join("sky.exr");
    write_env(&env);
    let mut texts = Vec::new();
    for t in ["1", "2"] {
        let out = dir.path().join(format!("r{t}"));
        let mut args = vec![
            env.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--threads",
            t,
            "--no-pixels",
            "--lookup",
            "engine",
        ];
        args.extend(SMALL);
        let o = BIN.run(&args);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        texts.push(std::fs::read_to_string(out.join("report.json")).unwrap());
    }
    assert_eq!(texts[0], texts[1]);
}

#[test]
fn bad_inputs_fail_cleanly() {
    let dir = tempfile::tempdir().unwrap();
    let env = dir.path().join("sky.exr");
    write_env(&env);
    let garbage = dir.path().join("garbage.exr");
    std::fs::write(&garbage, b"not an exr at all").unwrap();
    let out = dir.path().join("never");
    let (e, o) = (env.to_str().unwrap(), out.to_str().unwrap());
    let missing = dir.path().join("none.exr");
    let cases: Vec<(Vec<&str>, i32, &str)> = vec![
        (vec![missing.to_str().unwrap(), "--out", o], 4, "none.exr"),
        (
            vec![garbage.to_str().unwrap(), "--out", o],
            2,
            "garbage.exr",
        ),
        (vec![e, "--eta", "1", "--out", o], 2, "--eta"),
        (vec![e, "--roughness", "0", "--out", o], 2, "--roughness"),
        (vec![e, "--methods", "major-0", "--out", o], 2, "--methods"),
        (vec![e, "--methods", "magic", "--out", o], 2, "magic"),
        (vec![e, "--tangent", "spiral:x", "--out", o], 2, "--tangent"),
        (vec![e, "--elevations", "90", "--out", o], 2, "--elevations"),
        (vec![e, "--target", "three", "--out", o], 2, "three"),
        (
            vec![e, e, "--prefiltered", e, "--out", o],
            2,
            "single environment",
        ),
        (
            vec![e, "--truth-samples", "8", "--out", o],
            2,
            "--truth-samples",
        ),
    ];
    for (args, code, needle) in cases {
        let r = BIN.run(&args);
        eprintln!("{args:?} → {:?}", r.status.code());
        assert_one_line_error(&r, code, needle);
        assert!(!out.exists());
    }
}

#[test]
fn emits_the_shipped_shader_in_three_languages() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("shaders");
    BIN.run_ok(&["--emit-shader", out.to_str().unwrap()]);
    for (lang, ext) in ibl_aniso::ship::Lang::ALL {
        let text = std::fs::read_to_string(out.join(format!("aniso_fis.{ext}"))).unwrap();
        assert_eq!(text, ibl_aniso::ship::emit(lang), "{ext}");
        assert!(text.contains(&format!(
            "ANISO_FIS_TAPS{} = {}u;",
            if ext == "wgsl" { ": u32" } else { "" },
            ibl_aniso::ship::SHIPPED.taps
        )));
        let text = std::fs::read_to_string(out.join(format!("aniso_as.{ext}"))).unwrap();
        assert_eq!(text, ibl_aniso::ship_as::emit(lang), "{ext}");
    }
    // A file in the way of the folder, and a mix with inputs: one-line errors, nothing written.
    let file = dir.path().join("file");
    std::fs::write(&file, "x").unwrap();
    let r = BIN.run(&["--emit-shader", file.join("sub").to_str().unwrap()]);
    assert_one_line_error(&r, 2, "a file in the way");
    let sky = dir.path().join("sky.exr");
    write_env(&sky);
    let other = dir.path().join("other");
    let r = BIN.run(&[
        sky.to_str().unwrap(),
        "--emit-shader",
        other.to_str().unwrap(),
    ]);
    assert_eq!(r.status.code(), Some(2));
    assert!(!other.exists());
}

/// A tool binary built beside `aniso-eval` (`make test` builds every binary first).
fn tool(name: &str) -> std::path::PathBuf {
    let p = Path::new(env!("CARGO_BIN_EXE_aniso-eval"))
        .parent()
        .unwrap()
        .join(name);
    assert!(
        p.is_file(),
        "{} is not built: cargo build --release --workspace --bins (make test does)",
        p.display()
    );
    p
}

/// The per-pixel frames (t, n) of the first case of a report folder.
fn frames(out: &Path) -> Vec<(Vec<f64>, Vec<f64>)> {
    let meta = ibl_testkit::read_json(&out.join("case000_sky/case.json"));
    meta["pixels"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| {
            let v = |k: &str| -> Vec<f64> {
                p["frame"][k]
                    .as_array()
                    .unwrap()
                    .iter()
                    .map(|x| x.as_f64().unwrap())
                    .collect()
            };
            (v("t"), v("n"))
        })
        .collect()
}

#[test]
fn reads_quat_map_normals_and_tpr_map_tangents_from_the_real_bakes() {
    let dir = tempfile::tempdir().unwrap();
    let env = dir.path().join("sky.exr");
    write_env(&env);
    // A flat normal map through the real quat-map: every texel the identity quaternion.
    let flat = dir.path().join("flat.png");
    let mut img = Image::new(8, 4, 3);
    for t in img.data.chunks_mut(3) {
        t.copy_from_slice(&[0.5, 0.5, 1.0]);
    }
    write_image(&flat, &img, &WriteOptions::default()).unwrap();
    let quat = dir.path().join("flat_q.png");
    let o = std::process::Command::new(tool("quat-map"))
        .args([
            flat.to_str().unwrap(),
            "-o",
            quat.to_str().unwrap(),
            "--bits",
            "16",
        ])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    // A tpr-map of constant:30 from the real tpr-map.
    let tpr = dir.path().join("c30.exr");
    let o = std::process::Command::new(tool("tpr-map"))
        .args([
            "-o",
            tpr.to_str().unwrap(),
            "--size",
            "32x16",
            "--preset",
            "constant:30",
        ])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    // A real normal map (fixture) through quat-map: frames must move, and stay orthonormal.
    let bumpy = dir.path().join("bumpy_q.png");
    let o = std::process::Command::new(tool("quat-map"))
        .arg(ibl_testkit::fixture("normals/0008_128.png"))
        .args(["-o", bumpy.to_str().unwrap(), "--bits", "16"])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let run = |name: &str, extra: &[&str]| -> std::path::PathBuf {
        let out = dir.path().join(name);
        let mut args = vec![
            env.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--sphere-size",
            "12",
            "--roughness",
            "0.5",
            "--eta",
            "0.6",
            "--views",
            "30",
            "--elevations",
            "20",
            "--truth-samples",
            "256",
            "--methods",
            "iso,fisb-16",
            "--lookup",
            "engine",
        ];
        args.extend(extra);
        let o = BIN.run(&args);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        out
    };
    let plain = frames(&run("plain", &["--tangent", "constant:30"]));
    let with_maps = frames(&run(
        "maps",
        &[
            "--tpr-map",
            tpr.to_str().unwrap(),
            "--quat-map",
            quat.to_str().unwrap(),
        ],
    ));
    assert_eq!(plain.len(), with_maps.len());
    assert!(plain.len() > 50);
    let dist = |a: &[f64], b: &[f64]| {
        a.iter()
            .zip(b)
            .map(|(x, y)| (x - y).powi(2))
            .sum::<f64>()
            .sqrt()
    };
    for (a, b) in plain.iter().zip(&with_maps) {
        // 16-bit quantisation of the identity and of (cos 30°, sin 30°): well under 1e-3.
        assert!(
            dist(&a.0, &b.0) < 1e-3 && dist(&a.1, &b.1) < 1e-4,
            "{a:?} {b:?}"
        );
    }
    let bumped = frames(&run("bumpy", &["--quat-map", bumpy.to_str().unwrap()]));
    let base = frames(&run("base", &[]));
    let moved = base
        .iter()
        .zip(&bumped)
        .filter(|(a, b)| dist(&a.1, &b.1) > 1e-3)
        .count();
    assert!(moved > bumped.len() / 2, "{moved} of {}", bumped.len());
    for (t, n) in &bumped {
        let dot: f64 = t.iter().zip(n).map(|(x, y)| x * y).sum();
        let (lt, ln) = (dist(t, &[0.0; 3]), dist(n, &[0.0; 3]));
        assert!(dot.abs() < 1e-5 && (lt - 1.0).abs() < 1e-5 && (ln - 1.0).abs() < 1e-5);
    }
    // Malformed maps: one-line errors naming the flag and the file, nothing written.
    let never = dir.path().join("never");
    let garbage = dir.path().join("garbage.png");
    std::fs::write(&garbage, b"not a png").unwrap();
    let zero = dir.path().join("zero.exr");
    write_image(
        &zero,
        &Image::from_data(1, 1, 3, vec![0.5, 0.5, 0.5]).unwrap(),
        &WriteOptions::default(),
    )
    .unwrap();
    let grey = dir.path().join("grey.exr");
    write_image(
        &grey,
        &Image::from_data(1, 1, 1, vec![0.5]).unwrap(),
        &WriteOptions::default(),
    )
    .unwrap();
    let e = env.to_str().unwrap();
    let o = never.to_str().unwrap();
    for (flag, file, code, needle) in [
        ("--quat-map", &garbage, 3, "garbage.png"),
        ("--quat-map", &zero, 2, "not a quaternion"),
        ("--tpr-map", &grey, 2, "channel"),
        (
            "--tpr-map",
            &dir.path().join("missing.exr"),
            4,
            "missing.exr",
        ),
    ] {
        let r = BIN.run(&[e, "--out", o, flag, file.to_str().unwrap()]);
        let line = assert_one_line_error(&r, code, needle);
        assert!(
            line.contains(file.file_name().unwrap().to_str().unwrap()),
            "{line}"
        );
        assert!(!never.exists());
    }
}

#[test]
fn tpr_map_roughness_channels_give_each_pixel_its_lobe() {
    let dir = tempfile::tempdir().unwrap();
    let env = dir.path().join("sky.exr");
    write_env(&env);
    // The real tpr-map, constant:30 with roughness 0.5 along t and 0.25 along b: α_t = 0.25,
    // α_b = 0.0625, i.e. r = √0.15625, η = 0.6; once as perceptual r, once as α.
    let bake = |name: &str, extra: &[&str]| -> std::path::PathBuf {
        let p = dir.path().join(name);
        let mut args = vec![
            "-o",
            p.to_str().unwrap(),
            "--size",
            "32x16",
            "--preset",
            "constant:30",
            "--roughness",
            "0.5,0.25",
        ];
        args.extend(extra);
        let o = std::process::Command::new(tool("tpr-map"))
            .args(&args)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        p
    };
    let tpr_r = bake("r.exr", &[]);
    let tpr_a = bake("a.exr", &["--store-alpha"]);
    let r = (0.15625f32).sqrt().to_string();
    let run = |name: &str, extra: &[&str]| -> serde_json::Value {
        let out = dir.path().join(name);
        let mut args = vec![
            env.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--sphere-size",
            "12",
            "--views",
            "30",
            "--elevations",
            "20",
            "--truth-samples",
            "512",
            "--methods",
            "iso,bent-lg18,fisb-16",
            "--lookup",
            "engine",
        ];
        args.extend(extra);
        let o = BIN.run(&args);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let meta = ibl_testkit::read_json(&out.join("case000_sky/case.json"));
        let mut rep = ibl_testkit::read_json(&out.join("report.json"));
        rep["pixels"] = meta["pixels"].clone();
        rep
    };
    let global = run(
        "global",
        &[
            "--tangent",
            "constant:30",
            "--roughness",
            &r,
            "--eta",
            "0.6",
        ],
    );
    let from_r = run(
        "from_r",
        &[
            "--tpr-map",
            tpr_r.to_str().unwrap(),
            "--tpr-roughness",
            "r",
            "--roughness",
            "0.9",
            "--eta",
            "0,0.3",
        ],
    );
    let from_a = run(
        "from_a",
        &[
            "--tpr-map",
            tpr_a.to_str().unwrap(),
            "--tpr-roughness",
            "alpha",
        ],
    );
    let g = &global["cases"][0];
    for rep in [&from_r, &from_a] {
        // One case (the file's lobe replaces the --roughness × --eta grid), at the map's lobe.
        let cases = rep["cases"].as_array().unwrap();
        assert_eq!(cases.len(), 1);
        let c = &cases[0];
        for k in ["r", "eta"] {
            let (a, b) = (c[k].as_f64().unwrap(), g[k].as_f64().unwrap());
            assert!((a - b).abs() < 1e-5, "{k}: {a} vs {b}");
        }
        let m = &rep["pixels"][0]["material"]["Ggx"];
        assert!((m["alpha_t"].as_f64().unwrap() - 0.25).abs() < 1e-4, "{m}");
        assert!(
            (m["alpha_b"].as_f64().unwrap() - 0.0625).abs() < 1e-4,
            "{m}"
        );
        // Every method and the truth as with the global material, up to the f32 rounding of
        // α = r²(1 ± η) against the file's r² (and the 16-bit channels of tpr-map).
        let (gs, cs) = (
            g["scores"].as_array().unwrap(),
            c["scores"].as_array().unwrap(),
        );
        assert_eq!(gs.len(), cs.len());
        for (a, b) in gs.iter().zip(cs) {
            assert_eq!((&a["method"], &a["f0"]), (&b["method"], &b["f0"]));
            let (x, y) = (a["mse"].as_f64().unwrap(), b["mse"].as_f64().unwrap());
            assert!((x - y).abs() <= 1e-3 * x.max(1e-12), "{a} vs {b}");
        }
        let (x, y) = (
            g["truth_error_share"][0].as_f64().unwrap(),
            c["truth_error_share"][0].as_f64().unwrap(),
        );
        assert!((x - y).abs() <= 1e-3 * x, "{x} vs {y}");
    }
    // A map whose roughness varies: the pixels carry different lobes.
    let split = dir.path().join("split.exr");
    let mut img = Image::new(32, 16, 4);
    for j in 0..16 {
        for i in 0..32 {
            let rough = if i < 16 { 0.3 } else { 0.8 };
            img.texel_mut(i, j)
                .copy_from_slice(&[1.0, 0.5, rough, rough]);
        }
    }
    write_image(&split, &img, &WriteOptions::default()).unwrap();
    let rep = run(
        "split",
        &["--tpr-map", split.to_str().unwrap(), "--tpr-roughness", "r"],
    );
    let alphas: Vec<f64> = rep["pixels"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| p["material"]["Ggx"]["alpha_t"].as_f64().unwrap())
        .collect();
    assert!(alphas.iter().any(|a| (a - 0.09).abs() < 1e-4), "{alphas:?}");
    assert!(alphas.iter().any(|a| (a - 0.64).abs() < 1e-4), "{alphas:?}");
    // Malformed: one-line errors naming the problem (and the file), nothing written.
    let never = dir.path().join("never");
    let rgb = dir.path().join("rgb.exr");
    write_image(
        &rgb,
        &Image::from_data(1, 1, 3, vec![1.0, 0.5, 0.5]).unwrap(),
        &WriteOptions::default(),
    )
    .unwrap();
    let over = dir.path().join("over.exr");
    write_image(
        &over,
        &Image::from_data(1, 1, 4, vec![1.0, 0.5, 1.5, 0.5]).unwrap(),
        &WriteOptions::default(),
    )
    .unwrap();
    let e = env.to_str().unwrap();
    let o = never.to_str().unwrap();
    for (args, needle) in [
        (vec![e, "--out", o, "--tpr-roughness", "r"], "--tpr-map"),
        (
            vec![
                e,
                "--out",
                o,
                "--tpr-map",
                rgb.to_str().unwrap(),
                "--tpr-roughness",
                "r",
            ],
            "rgb.exr",
        ),
        (
            vec![
                e,
                "--out",
                o,
                "--tpr-map",
                over.to_str().unwrap(),
                "--tpr-roughness",
                "alpha",
            ],
            "over.exr",
        ),
    ] {
        let r = BIN.run(&args);
        let line = assert_one_line_error(&r, 2, needle);
        assert!(
            line.contains("roughness") || line.contains("--tpr-map"),
            "{line}"
        );
        assert!(!never.exists());
    }
}
