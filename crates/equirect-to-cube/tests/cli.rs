//! End-to-end tests of the `equirect-to-cube` binary: orientation, accuracy against an
//! independent area-filtered reference, containers, round trips and bad input.

use glam::Vec3;
use ibl_core::cube::{texel_direction, Face};
use ibl_core::envmap::read_cube_chain;
use ibl_core::equirect::pixel_direction;
use ibl_core::io::{self, ColorSpace, WriteOptions};
use ibl_core::Image;
use ibl_testkit::{files_in, fixture, stderr, Bin};
use std::ffi::OsStr;
use std::path::Path;
use std::process::Output;

const BIN: Bin = Bin::new(env!("CARGO_BIN_EXE_equirect-to-cube"), "equirect-to-cube");

/// Runs `input -o out flags… --quiet`; nothing is asserted.
fn run(input: impl AsRef<OsStr>, out: &Path, flags: &[&str]) -> Output {
    BIN.run_bake(input, out, &[flags, &["--quiet"]].concat())
}

/// Runs `input -o out flags… --quiet` and asserts it succeeded.
fn bake(input: impl AsRef<OsStr>, out: &Path, flags: &[&str]) -> Output {
    BIN.bake(input, out, &[flags, &["--quiet"]].concat())
}

/// An equirect whose texels hold their own direction (offset by 2 to stay positive).
fn direction_equirect(w: usize) -> Image {
    let h = w / 2;
    let mut img = Image::new(w, h, 3);
    for j in 0..h {
        for i in 0..w {
            let d = pixel_direction(i, j, w, h);
            img.texel_mut(i, j)
                .copy_from_slice(&[d.x + 2.0, d.y + 2.0, d.z + 2.0]);
        }
    }
    img
}

#[test]
fn every_face_is_oriented_as_design_md() {
    let dir = tempfile::tempdir().unwrap();
    let src = dir.path().join("dirs.exr");
    io::write_image(&src, &direction_equirect(512), &WriteOptions::default()).unwrap();
    let out = dir.path().join("cube");
    bake(&src, &out, &["--size", "16"]);
    let n = 16;
    let mut worst = 0.0f32;
    for face in Face::ALL {
        let img = io::read_image(
            &out.join(format!("{}.exr", face.name())),
            ColorSpace::Linear,
        )
        .unwrap();
        assert_eq!((img.width, img.height), (n, n));
        for (i, j) in [
            (0, 0),
            (n - 1, 0),
            (0, n - 1),
            (n - 1, n - 1),
            (n / 2, n / 2),
        ] {
            let t = img.rgb(i, j);
            let got = Vec3::new(t[0] - 2.0, t[1] - 2.0, t[2] - 2.0);
            let want = texel_direction(face, i, j, n);
            // The footprint mean of a linear function is close to its centre value.
            worst = worst.max(got.normalize().angle_between(want));
        }
    }
    eprintln!("worst orientation error: {:.3} degrees", worst.to_degrees());
    assert!(worst.to_degrees() < 2.0, "{worst}");
}

#[test]
fn faces_match_independent_area_filtered_reference() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("cube");
    let src_path = fixture("hdri/city_512.exr");
    bake(&src_path, &out, &["--size", "64"]);
    let mut src = io::read_image(&src_path, ColorSpace::Linear).unwrap();
    ibl_core::image::check_texels(&mut src, &src_path, false).unwrap();
    let n = 64;
    let (mut num, mut den) = (0.0f64, 0.0f64);
    for face in Face::ALL {
        let img = io::read_image(
            &out.join(format!("{}.exr", face.name())),
            ColorSpace::Linear,
        )
        .unwrap();
        for j in (0..n).step_by(5) {
            for i in (0..n).step_by(5) {
                let r = ibl_core::equirect::dense_footprint_mean(&src, face, i, j, n, 64);
                let g = img.rgb(i, j);
                for q in 0..3 {
                    num += (g[q] as f64 - r[q]).abs();
                    den += r[q].abs();
                }
            }
        }
    }
    let rel = num / den;
    eprintln!(
        "equirect-to-cube 64² from 512×256 vs 64×64-grid area reference: relative MAE {rel:.5}"
    );
    assert!(rel < 0.01, "{rel}");
}

#[test]
fn ktx2_layout_and_inverse_round_trip() {
    let dir = tempfile::tempdir().unwrap();
    let src = dir.path().join("dirs.exr");
    let img = direction_equirect(128);
    io::write_image(&src, &img, &WriteOptions::default()).unwrap();
    let out = dir.path().join("k");
    bake(&src, &out, &["--layout", "ktx2", "--half"]);
    let mips = read_cube_chain(&out.join("cube.ktx2")).unwrap();
    assert_eq!(
        mips.levels[0].size, 32,
        "default size is the largest power of two not above width/4"
    );
    // Back to equirect through the KTX2 file.
    let eq = dir.path().join("back.exr");
    bake(
        out.join("cube.ktx2"),
        &eq,
        &["--to-equirect", "--size", "64"],
    );
    let back = io::read_image(&eq, ColorSpace::Linear).unwrap();
    assert_eq!((back.width, back.height), (128, 64));
    let mut worst = 0.0f32;
    for j in 4..60 {
        for i in 0..128 {
            let a = back.rgb(i, j);
            let b = img.rgb(i, j);
            worst = worst.max((0..3).map(|q| (a[q] - b[q]).abs()).fold(0.0, f32::max));
        }
    }
    eprintln!(
        "equirect → cube (half) → equirect worst abs error on a unit-direction field: {worst:.4}"
    );
    assert!(worst < 0.05, "{worst}");
}

#[test]
fn horizontal_cross_input_is_read() {
    let dir = tempfile::tempdir().unwrap();
    let n = 8;
    let mut cross = Image::new(4 * n, 3 * n, 3);
    for (face, col, row) in [
        (Face::Px, 2, 1),
        (Face::Nx, 0, 1),
        (Face::Py, 1, 0),
        (Face::Ny, 1, 2),
        (Face::Pz, 1, 1),
        (Face::Nz, 3, 1),
    ] {
        for j in 0..n {
            for i in 0..n {
                let v = face as usize as f32 + 1.0;
                cross
                    .texel_mut(col * n + i, row * n + j)
                    .copy_from_slice(&[v, v, v]);
            }
        }
    }
    let src = dir.path().join("cross.exr");
    io::write_image(&src, &cross, &WriteOptions::default()).unwrap();
    let out = dir.path().join("c");
    bake(&src, &out, &[]);
    for face in Face::ALL {
        let img = io::read_image(
            &out.join(format!("{}.exr", face.name())),
            ColorSpace::Linear,
        )
        .unwrap();
        assert_eq!(img.rgb(3, 3)[0], face as usize as f32 + 1.0, "{face:?}");
    }
}

/// `input -o out` refused: exit `code`, one line containing `expect`, nothing written.
fn assert_fails_cleanly(input: impl AsRef<OsStr>, out: &Path, expect: &str, code: i32) {
    BIN.refused_bake(input, out, &[], code, expect);
    assert!(files_in(out).is_empty(), "nothing written");
}

#[test]
fn bad_inputs_fail_with_one_line_and_write_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    // Truncated EXR.
    let good = std::fs::read(fixture("hdri/studio_256.exr")).unwrap();
    let trunc = dir.path().join("trunc.exr");
    std::fs::write(&trunc, &good[..good.len() / 2]).unwrap();
    assert_fails_cleanly(&trunc, &out, "trunc.exr", 2);
    // Empty file, text file, missing file.
    let empty = dir.path().join("empty.exr");
    std::fs::write(&empty, b"").unwrap();
    assert_fails_cleanly(&empty, &out, "empty file", 2);
    let text = dir.path().join("notes.txt");
    std::fs::write(&text, b"not an image at all").unwrap();
    assert_fails_cleanly(&text, &out, "notes.txt", 3);
    assert_fails_cleanly("/nonexistent/env.exr", &out, "no such file", 4);
    // NaN texels: refused with a count, accepted with --sanitize.
    let mut img = Image::new(16, 8, 3);
    img.data[5] = f32::NAN;
    img.data[7] = f32::INFINITY;
    let nan = dir.path().join("nan.exr");
    io::write_image(&nan, &img, &WriteOptions::default()).unwrap();
    assert_fails_cleanly(&nan, &out, "2 NaN/Inf", 2);
    let ok = BIN.bake(&nan, &out, &["--sanitize"]);
    assert!(stderr(&ok).contains("set 2 NaN/Inf"), "{}", stderr(&ok));
    std::fs::remove_dir_all(&out).unwrap();
    // Unsupported layout, bad size.
    let odd = dir.path().join("odd.exr");
    io::write_image(&odd, &Image::new(10, 3, 3), &WriteOptions::default()).unwrap();
    assert_fails_cleanly(&odd, &out, "layout", 3);
    BIN.refused_bake(&nan, &out, &["--size", "0"], 2, "--size 0");
    assert!(files_in(&out).is_empty(), "nothing written");
}

#[test]
fn unwritable_output_fails_and_keeps_previous_files() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let bake = |input: &str| run(fixture(input), &out, &["--size", "8"]);
    // A first bake, then a folder where the last face (nz.exr) should go: the second bake of a
    // different environment must fail and leave every face of the first one as it was.
    let o = bake("hdri/studio_256.exr");
    assert!(o.status.success(), "{}", stderr(&o));
    let faces = ["px", "nx", "py", "ny", "pz", "nz"];
    let first: Vec<Vec<u8>> = faces
        .iter()
        .map(|f| std::fs::read(out.join(format!("{f}.exr"))).unwrap())
        .collect();
    std::fs::remove_file(out.join("nz.exr")).unwrap();
    std::fs::create_dir(out.join("nz.exr")).unwrap();
    let o = bake("hdri/sunset_256.exr");
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert_eq!(stderr(&o).trim().lines().count(), 1, "{}", stderr(&o));
    for (f, before) in faces[..5].iter().zip(&first) {
        assert_eq!(
            &std::fs::read(out.join(format!("{f}.exr"))).unwrap(),
            before,
            "{f}"
        );
    }
    let leftovers: Vec<_> = std::fs::read_dir(&out)
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().contains(".tmp-"))
        .collect();
    assert!(leftovers.is_empty());
}

#[test]
fn rotate_applies_to_the_equirect_output_too() {
    // docs/CONVENTIONS.md: --rotate turns the environment before any bake, --to-equirect included. A
    // 90° turn about +Y moves the equirect content by a quarter of its width.
    let dir = tempfile::tempdir().unwrap();
    let src = dir.path().join("src.exr");
    io::write_image(&src, &direction_equirect(64), &WriteOptions::default()).unwrap();
    let out_of = |rotate: &str| {
        let p = dir.path().join(format!("eq{rotate}.exr"));
        bake(
            &src,
            &p,
            &["--to-equirect", "--size", "16", "--rotate", rotate],
        );
        io::read_image(&p, ColorSpace::Linear).unwrap()
    };
    let (a, b) = (out_of("0"), out_of("90"));
    assert_eq!((a.width, a.height), (32, 16));
    let differs = a
        .data
        .iter()
        .zip(&b.data)
        .any(|(x, y)| (x - y).abs() > 1e-3);
    assert!(differs, "--rotate 90 left the equirect output unchanged");
    // The turned image is the unturned one shifted by a quarter turn in longitude (either
    // direction, per docs/CONVENTIONS.md's sign), up to resampling.
    let shifted = |k: isize| -> f32 {
        let mut worst = 0.0f32;
        for y in 4..12 {
            for x in 0..32isize {
                let xs = (x + k).rem_euclid(32) as usize;
                for c in 0..3 {
                    let d = a.data[(y * 32 + xs) * 3 + c] - b.data[(y * 32 + x as usize) * 3 + c];
                    worst = worst.max(d.abs());
                }
            }
        }
        worst
    };
    let best = shifted(8).min(shifted(-8));
    eprintln!("--rotate 90 vs a quarter-width shift: worst difference {best:.3}");
    assert!(best < 0.1, "{best}");
}

#[test]
fn damaged_fixture_negatives_are_clamped_with_a_warning() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let o = BIN.bake(
        fixture("hdri-damaged/esplanade.exr"),
        &out,
        &["--size", "16"],
    );
    let err = stderr(&o);
    assert!(
        err.contains("negative texel values") && err.contains("most negative -3"),
        "{err}"
    );
    for face in Face::ALL {
        let img = io::read_image(
            &out.join(format!("{}.exr", face.name())),
            ColorSpace::Linear,
        )
        .unwrap();
        assert!(img.data.iter().all(|v| v.is_finite() && *v >= 0.0));
    }
}

#[test]
fn every_fixture_is_byte_identical_with_one_and_two_threads() {
    let dir = tempfile::tempdir().unwrap();
    for name in [
        "city_512.exr",
        "studio_256.exr",
        "sunset_256.exr",
        "interior_256.exr",
        "studio_256.hdr",
    ] {
        let src = fixture(&format!("hdri/{name}"));
        let mut outs = Vec::new();
        for threads in ["1", "2"] {
            let out = dir.path().join(format!("{name}-{threads}"));
            let flags = ["--size", "24", "--rotate", "12.5", "--threads", threads];
            bake(&src, &out, &flags);
            outs.push(
                Face::ALL.map(|f| std::fs::read(out.join(format!("{}.exr", f.name()))).unwrap()),
            );
        }
        assert!(outs[0] == outs[1], "{name}");
    }
}

/// `--target bevy` writes the cube as Bevy samples it (z negated: its +Z face is our −Z face
/// mirrored left to right), `--target three` x-mirrored (its +X face our −X face mirrored).
#[test]
fn targets_turn_the_cube_as_the_engine_samples_it() {
    let tmp = tempfile::tempdir().unwrap();
    let input = fixture("hdri/sunset_256.exr");
    let bake = |t: &str| {
        let out = tmp.path().join(t);
        let flags = ["--size", "16", "--target", t, "--layout", "faces"];
        bake(&input, &out, &flags);
        out
    };
    let read = |d: &Path, f: &str| {
        io::read_image(&d.join(format!("{f}.exr")), ColorSpace::Linear).unwrap()
    };
    let (ours, bevy, three) = (bake("gltf"), bake("bevy"), bake("three"));
    for (dir, file_face, our_face) in [
        (&bevy, "pz", "nz"),
        (&bevy, "nz", "pz"),
        (&three, "px", "nx"),
        (&three, "nx", "px"),
    ] {
        let (a, b) = (read(dir, file_face), read(&ours, our_face));
        for j in 0..16 {
            for i in 0..16 {
                assert_eq!(a.rgb(i, j), b.rgb(15 - i, j), "{file_face} ({i}, {j})");
            }
        }
    }
    // +Y keeps its face but is flipped top to bottom: its rows run along z.
    let (a, b) = (read(&bevy, "py"), read(&ours, "py"));
    for j in 0..16 {
        for i in 0..16 {
            assert_eq!(a.rgb(i, j), b.rgb(i, 15 - j));
        }
    }
}

#[test]
fn truncated_jpeg_environments_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let mut rgb = image::RgbImage::new(128, 64);
    for (i, p) in rgb.pixels_mut().enumerate() {
        p.0 = [(i % 256) as u8, (i * 7 % 256) as u8, 128];
    }
    let mut bytes = Vec::new();
    image::codecs::jpeg::JpegEncoder::new_with_quality(&mut bytes, 95)
        .encode_image(&rgb)
        .unwrap();
    let out = dir.path().join("cube");
    for cut in [bytes.len() / 4, bytes.len() / 2, bytes.len() - 1] {
        let t = dir.path().join("env.jpg");
        std::fs::write(&t, &bytes[..cut]).unwrap();
        let o = run(&t, &out, &[]);
        let e = stderr(&o);
        assert_eq!(o.status.code(), Some(2), "cut {cut}: {e}");
        assert!(
            e.contains("env.jpg: truncated JPEG") && e.lines().count() == 1,
            "{e}"
        );
        assert!(!out.exists());
    }
}

/// Issue 22: for every target × layout, the note (LOAD.txt) is written (gltf too) and names
/// only files this run wrote.
#[test]
fn every_target_and_layout_writes_a_note_naming_only_its_own_files() {
    BIN.assert_every_target_writes_a_true_note(&fixture("hdri/sunset_256.exr"));
}

/// Filament's KTX1 reader has no pixel type for packed RGB9E5 (google/filament
/// `libs/ktxreader/src/Ktx1Reader.cpp`, `toPixelDataType`): its skybox is refused in that
/// format before any work; without the target the same KTX1 is written.
#[test]
fn target_filament_refuses_an_rgb9e5_skybox() {
    let tmp = tempfile::tempdir().unwrap();
    let input = fixture("hdri/sunset_256.exr");
    let out = tmp.path().join("sky");
    let flags = ["--target", "filament", "--format", "rgb9e5", "--size", "8"];
    let line = BIN.refused_bake(&input, &out, &flags, 2, "Ktx1Reader.cpp");
    assert!(line.contains("b10g11r11"), "{line}");
    assert!(!out.exists());
    let plain = tmp.path().join("plain");
    bake(
        &input,
        &plain,
        &["--layout", "ktx1", "--format", "rgb9e5", "--size", "8"],
    );
    assert_eq!(
        files_in(&plain)
            .iter()
            .filter(|f| f.ends_with(".ktx"))
            .count(),
        1
    );
}

#[test]
fn a_large_hdr_streamed_gives_the_cube_of_the_same_texels_read_whole() {
    // A 2048×1024 Radiance file is resampled as its scan lines arrive, the same texels in an
    // EXR as its blocks arrive (two readers; each against the whole read in ibl-core's
    // tests): the faces must be the same bytes. Cut short mid-stream, it fails in one line
    // naming the file and writes nothing.
    let dir = tempfile::tempdir().unwrap();
    let mut img = direction_equirect(2048);
    for (k, v) in img.data.iter_mut().enumerate() {
        *v *= 1.0 + (k % 37) as f32 * 0.1 + if k % 4099 == 0 { 900.0 } else { 0.0 };
    }
    let hdr = dir.path().join("env.hdr");
    io::write_image(&hdr, &img, &WriteOptions::default()).unwrap();
    let same = io::read_image(&hdr, ColorSpace::Linear).unwrap();
    let exr = dir.path().join("env.exr");
    io::write_image(&exr, &same, &WriteOptions::default()).unwrap();
    for flags in [&["--size", "128"][..], &["--size", "77", "--rotate", "33"]] {
        let (a, b) = (dir.path().join("a"), dir.path().join("b"));
        bake(&hdr, &a, flags);
        bake(&exr, &b, flags);
        let faces: Vec<String> = files_in(&a)
            .into_iter()
            .filter(|f| f.ends_with(".exr"))
            .collect();
        assert_eq!(faces.len(), 6, "{faces:?}");
        for f in &faces {
            let (x, y) = (
                std::fs::read(a.join(f)).unwrap(),
                std::fs::read(b.join(f)).unwrap(),
            );
            assert!(x == y, "{f} {flags:?}");
        }
        std::fs::remove_dir_all(&a).unwrap();
        std::fs::remove_dir_all(&b).unwrap();
    }
    let bytes = std::fs::read(&hdr).unwrap();
    let cut = dir.path().join("cut.hdr");
    std::fs::write(&cut, &bytes[..bytes.len() * 3 / 4]).unwrap();
    let out = dir.path().join("out");
    assert_fails_cleanly(&cut, &out, "cut.hdr", 2);
    let e = stderr(&run(&cut, &out, &["--size", "64"]));
    assert!(
        e.contains("scan line") && e.trim().lines().count() == 1,
        "{e}"
    );
}
