//! End-to-end tests of the `prefilter` binary: outputs, report, layouts, options and bad
//! inputs (non-zero exit, one-line error, nothing written).

use ibl_core::image::Image;
use ibl_core::io::{self, ColorSpace, WriteOptions};
use ibl_testkit::{files_in, fixture, stderr, Bin};
use std::ffi::OsStr;
use std::path::Path;
use std::process::Output;

const BIN: Bin = Bin::new(env!("CARGO_BIN_EXE_prefilter"), "prefilter");

fn report(dir: &Path) -> serde_json::Value {
    ibl_testkit::read_json(&dir.join("prefilter.json"))
}

const FACES: [&str; 6] = ["px", "nx", "py", "ny", "pz", "nz"];

#[test]
fn faces_layout_writes_every_level_and_the_report() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("chain");
    let input = fixture("hdri/sunset_256.exr");
    BIN.bake(&input, &out, &["--size", "32", "-q"]);
    // Default levels: down to 4×4 faces → 32, 16, 8, 4.
    for (l, n) in [(0, 32usize), (1, 16), (2, 8), (3, 4)] {
        for f in FACES {
            let img =
                io::read_image(&out.join(format!("m{l}_{f}.exr")), ColorSpace::Linear).unwrap();
            assert_eq!((img.width, img.height), (n, n), "m{l}_{f}");
            assert!(img.data.iter().all(|v| v.is_finite() && *v >= 0.0));
        }
    }
    // The faces, prefilter.json and LOAD.txt.
    assert_eq!(files_in(&out).len(), 4 * 6 + 2, "{:?}", files_in(&out));
    let r = report(&out);
    assert_eq!(r["size"], 32);
    assert_eq!(r["levels"], 4);
    assert_eq!(r["chain_levels"], 4);
    assert_eq!(r["method"], "tree");
    assert_eq!(r["quality"], "default");
    let levels = r["level"].as_array().unwrap();
    // gltf fits its inner levels to the lookup by default and says how far each moved; the
    // mirror and the last level stay exact.
    assert_eq!(r["fit_lookup"], true);
    let moved: Vec<bool> = levels.iter().map(|l| !l["fit"].is_null()).collect();
    assert_eq!(moved, [false, true, true, false]);
    for l in &levels[1..3] {
        let m = l["fit"]["mean_abs_rel_from_exact"].as_f64().unwrap();
        assert!(m > 0.0 && m < 0.5, "{l}");
    }
    let rough: Vec<f64> = levels
        .iter()
        .map(|l| l["roughness"].as_f64().unwrap())
        .collect();
    let want = [0.0, 1.0 / 3.0, 2.0 / 3.0, 1.0];
    assert!(
        rough.iter().zip(want).all(|(a, b)| (a - b).abs() < 1e-6) && rough.len() == 4,
        "{rough:?}"
    );
    assert!(levels[0]["estimated_error"].is_null());
    for l in &levels[1..] {
        let e = l["estimated_error"]["mean_abs_rel"].as_f64().unwrap();
        eprintln!(
            "level {} estimated mean abs relative error {:.4}%",
            l["level"],
            100.0 * e
        );
        assert!(e < 0.01);
    }
}

/// A quick FIS chain of `levels` levels from 16² faces into `out` (for the folder tests).
fn quick_chain(input: &str, out: &Path, levels: &str) -> Output {
    let flags = [
        "--size",
        "16",
        "--levels",
        levels,
        "--method",
        "fis",
        "--samples",
        "16",
    ];
    BIN.bake(fixture(input), out, &flags)
}

#[test]
fn a_shorter_chain_into_the_same_folder_removes_the_old_levels() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("chain");
    quick_chain("hdri/studio_256.exr", &out, "5");
    assert!(out.join("m4_px.exr").exists());
    let o = quick_chain("hdri/sunset_256.exr", &out, "2");
    let err = stderr(&o);
    assert!(err.contains("m2_px.exr"), "{err}");
    let names = files_in(&out);
    assert!(
        names
            .iter()
            .all(|n| !n.starts_with("m2_") && !n.starts_with("m4_")),
        "{names:?}"
    );
    let chain = ibl_core::envmap::read_cube_chain(&out).unwrap();
    assert_eq!(
        chain.levels.iter().map(|c| c.size).collect::<Vec<_>>(),
        vec![16, 8]
    );
}

#[test]
fn a_chain_with_a_foreign_level_is_refused_by_the_reader() {
    // Files copied in by hand (not through the writer): a level that does not halve.
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("chain");
    quick_chain("hdri/studio_256.exr", &out, "3");
    for f in FACES {
        std::fs::copy(
            out.join(format!("m1_{f}.exr")),
            out.join(format!("m2_{f}.exr")),
        )
        .unwrap();
    }
    let e = ibl_core::envmap::read_cube_chain(&out)
        .unwrap_err()
        .to_string();
    assert!(e.contains("level 2 is 8²"), "{e}");
    // A single cube beside a chain is ambiguous.
    std::fs::copy(out.join("m0_px.exr"), out.join("px.exr")).unwrap();
    let e = ibl_core::envmap::read_cube_chain(&out)
        .unwrap_err()
        .to_string();
    assert!(e.contains("both a single cube"), "{e}");
}

#[test]
fn ktx2_layout_reads_back_equal_to_the_faces() {
    let tmp = tempfile::tempdir().unwrap();
    let (a, b) = (tmp.path().join("faces"), tmp.path().join("ktx"));
    let input = fixture("hdri/studio_256.exr");
    for (dir, extra) in [(&a, vec![]), (&b, vec!["--layout", "ktx2"])] {
        quick_sized(&input, dir, "16", "4", &extra);
    }
    assert_eq!(
        files_in(&b),
        vec![
            "LOAD.txt".to_string(),
            "prefilter.json".to_string(),
            "prefilter.ktx2".to_string()
        ]
    );
    let ktx = ibl_core::envmap::read_cube_chain(&b.join("prefilter.ktx2")).unwrap();
    let faces = ibl_core::envmap::read_cube_chain(&a).unwrap();
    assert_eq!(
        ktx.levels.iter().map(|c| c.size).collect::<Vec<_>>(),
        vec![16, 8, 4, 2]
    );
    assert_eq!(ktx, faces);
}

#[test]
fn max_roughness_keeps_the_level_count_the_lookup_needs_and_says_so() {
    // Issue 22: the engine's lod = r·(mipCount − 1) needs the full chain's level count, so
    // the levels past the cut are still written (the exact kernel, unfitted).
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("o");
    let flags = ["--size", "32", "--levels", "5", "--max-roughness", "0.6"];
    let o = BIN.bake(fixture("hdri/interior_256.exr"), &out, &flags);
    let err = stderr(&o);
    assert!(err.contains("--max-roughness"), "{err}");
    // r = 0, 0.25, 0.5 fitted; 0.75 and 1 kept exact.
    assert!(out.join("m4_px.exr").exists() && !out.join("m5_px.exr").exists());
    let r = report(&out);
    assert_eq!(r["levels"], 5);
    assert_eq!(r["chain_levels"], 5);
    assert_eq!(r["level"][2]["roughness"].as_f64().unwrap(), 0.5);
    assert!(r["level"][2].get("beyond_max_roughness").is_none());
    assert_eq!(r["level"][3]["beyond_max_roughness"], true);
    assert!(r["level"][3]["fit"].is_null());
    let note = r["note"].as_str().unwrap();
    assert!(
        note.contains("levels 0..=2") && note.contains("full chain"),
        "{note}"
    );
}

#[test]
fn half_json_reference_and_folder_input() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("h");
    let flags = ["--size", "8", "--levels", "3", "--half", "--json"];
    let o = BIN.bake(fixture("hdri/city_512.exr"), &out, &flags);
    let summary: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(summary["tool"], "prefilter");
    assert_eq!(summary["outputs"].as_array().unwrap().len(), 3 * 6 + 2);
    // The written chain is a face folder: it is a valid input (its level 0 is read).
    let again = tmp.path().join("again");
    let flags = ["--size", "8", "--levels", "2", "--reference", "-q"];
    BIN.bake(&out, &again, &flags);
    let r = report(&again);
    assert_eq!(r["method"], "reference");
    // The brute-force reference is the exact kernel at every level: never fitted.
    assert_eq!(r["fit_lookup"], false);
    assert_eq!(r["source_size"], 8);
}

#[test]
fn same_input_gives_identical_bytes_for_any_thread_count() {
    let tmp = tempfile::tempdir().unwrap();
    let input = fixture("hdri/sunset_256.exr");
    let mut outputs = Vec::new();
    for threads in ["1", "2"] {
        let out = tmp.path().join(threads);
        let flags = ["--size", "16", "--levels", "3", "--threads", threads, "-q"];
        BIN.bake(&input, &out, &flags);
        outputs.push(
            files_in(&out)
                .iter()
                .map(|f| std::fs::read(out.join(f)).unwrap())
                .collect::<Vec<_>>(),
        );
    }
    assert!(outputs[0] == outputs[1]);
}

/// A bad run of `input -o out flags…`: non-zero exit with `code`, one line on stderr naming
/// the problem, nothing written. Returns the line.
fn assert_fails_cleanly(
    input: impl AsRef<OsStr>,
    out: &Path,
    flags: &[&str],
    code: i32,
    needle: &str,
) -> String {
    let line = BIN.refused_bake(input, out, flags, code, needle);
    assert!(files_in(out).is_empty(), "wrote {:?}", files_in(out));
    line
}

#[test]
fn bad_inputs_fail_with_one_line_and_write_nothing() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("out");
    // Truncated EXR.
    let bytes = std::fs::read(fixture("hdri/sunset_256.exr")).unwrap();
    let truncated = tmp.path().join("truncated.exr");
    std::fs::write(&truncated, &bytes[..bytes.len() / 2]).unwrap();
    assert_fails_cleanly(&truncated, &out, &["--size", "8"], 2, "truncated.exr");
    // NaN texels without --sanitize (and with it, the bake runs).
    let mut img = Image::new(16, 8, 3);
    img.data
        .iter_mut()
        .enumerate()
        .for_each(|(k, v)| *v = (k % 7) as f32 * 0.1);
    img.data[40] = f32::NAN;
    let nan = tmp.path().join("nan.exr");
    io::write_image(&nan, &img, &WriteOptions::default()).unwrap();
    assert_fails_cleanly(&nan, &out, &["--size", "4"], 2, "NaN");
    let ok = tmp.path().join("sanitized");
    BIN.bake(&nan, &ok, &["--size", "4", "--sanitize", "-q"]);
    // Missing file.
    let missing = tmp.path().join("missing.exr");
    assert_fails_cleanly(&missing, &out, &[], 4, "missing.exr");
    // Parameters out of range.
    let i = fixture("hdri/sunset_256.exr");
    assert_fails_cleanly(&i, &out, &["--size", "0"], 2, "--size");
    let levels = ["--size", "16", "--levels", "9"];
    assert_fails_cleanly(&i, &out, &levels, 2, "--levels");
    let rough = ["--max-roughness", "2"];
    assert_fails_cleanly(&i, &out, &rough, 2, "--max-roughness");
    assert_fails_cleanly(&i, &out, &["--samples", "64"], 2, "--samples");
}

#[test]
fn a_bake_over_the_memory_budget_is_refused_before_it_starts() {
    // sunset_256 (256×128) → 512² faces: a 512² source cube and its tree, about 0.4 GB by
    // the estimate, refused under 64 MiB with exit 3 and nothing written; the same bake at
    // 32² fits and runs.
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("out");
    let i = fixture("hdri/sunset_256.exr");
    let line = assert_fails_cleanly(
        &i,
        &out,
        &["--size", "512", "--max-memory", "64M"],
        3,
        "sunset_256.exr",
    );
    assert!(
        line.contains("512² faces") && line.contains("needs") && line.contains("--max-memory"),
        "{line}"
    );
    let want = ibl_prefilter::bake::working_set_bytes(512, 512);
    assert!(want > 64 << 20, "{want}");
    BIN.bake(&i, &out, &["--size", "32", "--max-memory", "64M", "-q"]);
}

#[test]
fn every_container_and_format_reads_back_within_the_reported_error() {
    let tmp = tempfile::tempdir().unwrap();
    let input = fixture("hdri/interior_256.exr");
    // 64² down to 8×8 (BC6H is bounded there, see below; the default chain goes on to 4×4).
    let float_dir = tmp.path().join("float");
    quick_sized(&input, &float_dir, "64", "4", &["--layout", "ktx2"]);
    let float = ibl_core::envmap::read_cube_chain(&float_dir.join("prefilter.ktx2")).unwrap();
    for (layout, ext, zstd) in [
        ("ktx2", "ktx2", false),
        ("ktx2", "ktx2", true),
        ("dds", "dds", false),
        ("ktx1", "ktx", false),
    ] {
        for format in ["rgba16f", "rgb9e5", "b10g11r11", "bc6h"] {
            let dir = tmp.path().join(format!("{layout}-{zstd}-{format}"));
            let mut args = vec!["--layout", layout, "--format", format];
            if zstd {
                args.extend(["--zstd", "19"]);
            }
            quick_sized(&input, &dir, "64", "4", &args);
            let file = dir.join(format!("prefilter.{ext}"));
            let mut want = vec![
                "LOAD.txt".to_string(),
                "prefilter.json".to_string(),
                format!("prefilter.{ext}"),
            ];
            if ext == "dds" {
                // DDS has no key/value data: the orientation sidecar (issue 22).
                want.push("prefilter.orientation.json".to_string());
            }
            want.sort();
            assert_eq!(files_in(&dir), want);
            let back = ibl_core::envmap::read_cube_chain(&file).unwrap();
            let enc = &report(&dir)["encoding"];
            assert_eq!(enc["format"], format);
            assert_eq!(enc["layout"], layout);
            for (l, (a, b)) in float.levels.iter().zip(&back.levels).enumerate() {
                let (mean, max) = ibl_core::io::texture::relative_errors(&a.faces, &b.faces);
                let reported = &enc["levels"][l];
                assert!(
                    (reported["mean_rel"].as_f64().unwrap() - mean).abs() < 1e-12,
                    "{file:?} {l}"
                );
                assert!((reported["max_rel"].as_f64().unwrap() - max).abs() < 1e-12);
                // BC6H: under 3% down to 8×8 faces; below (the default chain's 4×4), one
                // block spans a quarter face or more and its 16 steps cost a few percent.
                let bound = match format {
                    "rgba16f" => 2f64.powi(-11),
                    "rgb9e5" => 2f64.powi(-9),
                    "b10g11r11" => 2f64.powi(-6),
                    _ if a.size >= 8 => 0.03,
                    _ => 0.06,
                };
                assert!(mean < bound, "{format} level {l}: {mean}");
            }
        }
    }
}

fn quick_container(input: &Path, out: &Path, extra: &[&str]) {
    quick_sized(input, out, "16", "5", extra)
}

fn quick_sized(input: &Path, out: &Path, size: &str, levels: &str, extra: &[&str]) {
    let flags = ["--size", size, "--levels", levels, "-q"];
    BIN.bake(input, out, &[&flags[..], extra].concat());
}

#[test]
fn changing_the_layout_leaves_only_this_run_s_files() {
    let tmp = tempfile::tempdir().unwrap();
    let input = fixture("hdri/sunset_256.exr");
    let out = tmp.path().join("o");
    quick_container(&input, &out, &[]);
    assert_eq!(files_in(&out).len(), 6 * 5 + 2);
    quick_container(&input, &out, &["--layout", "ktx2", "--format", "bc6h"]);
    assert_eq!(
        files_in(&out),
        vec!["LOAD.txt", "prefilter.json", "prefilter.ktx2"]
    );
    quick_container(&input, &out, &["--layout", "dds", "--half"]);
    assert_eq!(
        files_in(&out),
        vec![
            "LOAD.txt",
            "prefilter.dds",
            "prefilter.json",
            "prefilter.orientation.json"
        ]
    );
    quick_container(&input, &out, &[]);
    assert!(!files_in(&out)
        .iter()
        .any(|f| f.ends_with(".dds") || f.ends_with(".orientation.json")));
}

#[test]
fn combinations_that_make_no_sense_are_refused_before_reading_the_input() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("out");
    // The input does not exist: the parameters are refused first (exit 2, not 4).
    let missing = tmp.path().join("missing.exr");
    for (args, needle) in [
        (vec!["--format", "bc6h"], "cannot be written as EXR faces"),
        (
            vec!["--layout", "dds", "--zstd", "3"],
            "--zstd needs --layout ktx2",
        ),
        (vec!["--layout", "ktx2", "--zstd", "99"], "out of range"),
        (
            vec!["--half", "--format", "rgb9e5", "--layout", "ktx2"],
            "--half means",
        ),
        (
            vec!["--layout", "ktx1", "--bc6h-quality", "slow"],
            "--bc6h-quality",
        ),
    ] {
        let e = assert_fails_cleanly(&missing, &out, &args, 2, needle);
        assert!(e.contains("valid:"), "{e}");
    }
}

#[test]
fn damaged_containers_are_refused_cleanly() {
    let tmp = tempfile::tempdir().unwrap();
    let good = tmp.path().join("good");
    quick_container(
        &fixture("hdri/sunset_256.exr"),
        &good,
        &["--layout", "ktx2", "--format", "rgb9e5", "--zstd", "5"],
    );
    let bytes = std::fs::read(good.join("prefilter.ktx2")).unwrap();
    let out = tmp.path().join("out");
    for (name, data) in [
        ("cut.ktx2", bytes[..bytes.len() - 7].to_vec()),
        ("header.ktx2", bytes[..60].to_vec()),
        ("named.dds", bytes[..bytes.len() / 2].to_vec()),
    ] {
        let p = tmp.path().join(name);
        std::fs::write(&p, data).unwrap();
        assert_fails_cleanly(&p, &out, &["--size", "8"], 2, name);
    }
}

#[test]
fn target_sets_level_roughness_orientation_and_the_runtime_report() {
    let tmp = tempfile::tempdir().unwrap();
    let input = fixture("hdri/sunset_256.exr");
    let bake = |target: &str| {
        let out = tmp.path().join(target);
        let flags = [
            "--size", "16", "--levels", "5", "--target", target, "--layout", "faces", "-q",
        ];
        BIN.bake(&input, &out, &flags);
        out
    };
    let gltf = bake("gltf");
    let fil = bake("filament");
    let rg = report(&gltf);
    let rf = report(&fil);
    assert_eq!(rg["target"], "gltf");
    assert_eq!(rf["target"], "filament");
    // cmgen's level roughness: 1 − √(1 − l/4).
    for l in 0..5 {
        let want = 1.0 - (1.0 - l as f64 / 4.0).sqrt();
        let got = rf["level_roughness"][l].as_f64().unwrap();
        assert!((got - want).abs() < 1e-6, "level {l}: {got}");
        assert!((rf["level"][l]["roughness"].as_f64().unwrap() - want).abs() < 1e-6);
        assert!((rg["level_roughness"][l].as_f64().unwrap() - l as f64 / 4.0).abs() < 1e-6);
    }
    // The runtime lookup error at 33 roughness values.
    let rt = &rf["runtime"];
    assert_eq!(rt["target"], "filament");
    assert_eq!(rt["roughness"].as_array().unwrap().len(), 33);
    let e: Vec<f64> = rt["mean_abs_rel"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    assert_eq!(e.len(), 33);
    assert!(e.iter().all(|v| v.is_finite() && *v >= 0.0));
    // Orientation: Filament's mirror level is ours turned 90° about +Y, (x, y, z) ↦ (z, y, −x):
    // its +X face holds our −Z face... checked texel by texel through the directions.
    let read = |dir: &Path, f: &str| {
        io::read_image(&dir.join(format!("m0_{f}.exr")), ColorSpace::Linear).unwrap()
    };
    let ours_nz = read(&gltf, "nz");
    let fil_px = read(&fil, "px");
    // File direction on +X: (1, −tc, −sc) ↦ ours (−sc, −tc, −1), which is on −Z at (sc, tc):
    // the same texel (i, j).
    assert_eq!(fil_px.data, ours_nz.data);
}

#[test]
fn target_three_has_no_chain_to_bake() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("t");
    let input = fixture("hdri/sunset_256.exr");
    BIN.refused_bake(input, &out, &["--target", "three"], 2, "PMREMGenerator");
    assert!(!out.exists());
}

/// Filament's KTX1 reader has no pixel type for packed RGB9E5 (google/filament
/// `libs/ktxreader/src/Ktx1Reader.cpp`, `toPixelDataType`): refused up front, nothing written;
/// the formats it does read (b10g11r11, rgba16f) still bake.
#[test]
fn target_filament_refuses_rgb9e5_in_ktx1() {
    let tmp = tempfile::tempdir().unwrap();
    let input = fixture("hdri/sunset_256.exr");
    let out = tmp.path().join("f");
    let line = BIN.refused_bake(
        &input,
        &out,
        &["--target", "filament", "--format", "rgb9e5", "--size", "16"],
        2,
        "Ktx1Reader.cpp",
    );
    assert!(
        line.contains("rgb9e5") && line.contains("b10g11r11"),
        "{line}"
    );
    assert!(!out.exists());
    for format in ["b10g11r11", "rgba16f"] {
        let ok = tmp.path().join(format);
        BIN.bake(
            &input,
            &ok,
            &[
                "--target", "filament", "--format", format, "--size", "16", "-q",
            ],
        );
        assert!(ok.join("env_ibl.ktx").is_file(), "{format}");
    }
}

#[test]
fn target_babylon_writes_an_env_of_the_full_chain_or_refuses() {
    let tmp = tempfile::tempdir().unwrap();
    let input = fixture("hdri/sunset_256.exr");
    let babylon = |out: &Path, extra: &[&str]| {
        let flags = ["--size", "16", "--target", "babylon", "-q"];
        BIN.run_bake(&input, out, &[&flags[..], extra].concat())
    };
    let out = tmp.path().join("b");
    let o = babylon(&out, &[]);
    assert!(o.status.success(), "{}", stderr(&o));
    let env = std::fs::read(out.join("environment.env")).unwrap();
    assert_eq!(&env[..8], &[0x86, 0x16, 0x87, 0x96, 0xf6, 0xd6, 0x96, 0x36]);
    assert_eq!(report(&out)["levels"], 5);
    // Babylon reads every level: a truncated chain is refused before any work.
    let bad = tmp.path().join("c");
    let o = babylon(&bad, &["--levels", "3"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(!bad.exists());
}

#[test]
fn negative_values_reach_the_range_check_and_outputs_are_checked_first() {
    let dir = tempfile::tempdir().unwrap();
    let input = fixture("hdri/studio_256.exr");
    let out = dir.path().join("o");
    let o = BIN.run_bake(&input, &out, &["--max-roughness", "-0.5"]);
    let e = stderr(&o);
    assert_eq!(o.status.code(), Some(2), "{e}");
    assert!(e.contains("--max-roughness -0.5 is out of range"), "{e}");
    assert!(!e.contains("unexpected argument"), "{e}");
    // An existing file where the output folder should be: said before the bake, with what
    // to do, in one line.
    let notes = dir.path().join("notes.txt");
    std::fs::write(&notes, "x").unwrap();
    let says = "is an existing file (a file in the way): choose another name";
    BIN.refused_bake(&input, &notes, &[], 2, says);
}

/// Issue 22: for every target × layout, the note (LOAD.txt) is written (gltf too) and names
/// only files this run wrote.
#[test]
fn every_target_and_layout_writes_a_note_naming_only_its_own_files() {
    let tmp = tempfile::tempdir().unwrap();
    let input = fixture("hdri/sunset_256.exr");
    for t in ["gltf", "bevy", "filament", "three", "babylon", "unity"] {
        if t == "three" {
            continue;
        }
        let layouts: [&[&str]; 5] = [
            &[],
            &["--layout", "faces", "--format", "rgba16f"],
            &["--layout", "ktx2", "--format", "rgba16f"],
            &["--layout", "dds", "--format", "rgba16f"],
            &["--layout", "ktx1", "--format", "rgba16f"],
        ];
        for (k, layout) in layouts.iter().enumerate() {
            let out = tmp.path().join(format!("{t}-{k}"));
            let mut flags = vec!["--target", t, "--size", "8", "--quality", "draft", "-q"];
            flags.extend_from_slice(layout);
            let o = BIN.run_bake(&input, &out, &flags);
            assert!(o.status.success(), "{t} {layout:?}: {}", stderr(&o));
            let note = ibl_testkit::assert_note_names_only_existing_files(&out);
            assert!(note.contains(&format!("--target {t}")), "{note}");
            if t == "babylon" {
                // Only the .env, its report and the note: no EXR faces beside the .env.
                assert_eq!(
                    files_in(&out),
                    ["LOAD.txt", "environment.env", "prefilter.json"],
                    "{layout:?}"
                );
            }
        }
    }
}
