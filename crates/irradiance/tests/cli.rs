//! End-to-end tests of the `irradiance` binary against independent references: an explicit
//! f64 projection with the docs/CONVENTIONS.md constants, and a brute-force cosine convolution.
// Index loops over coefficients and channels mirror the sums of the reference formulas.
#![allow(clippy::needless_range_loop)]

use glam::Vec3;
use ibl_core::cube::{texel_direction, Face};
use ibl_core::equirect::{pixel_direction, row_solid_angle};
use ibl_core::io::{self, ColorSpace, WriteOptions};
use ibl_core::Image;
use ibl_testkit::{fixture, stderr, Bin};
use std::ffi::OsStr;
use std::path::Path;
use std::process::Output;

const BIN: Bin = Bin::new(env!("CARGO_BIN_EXE_irradiance"), "irradiance");

/// Runs `input -o out flags… --quiet`; nothing is asserted.
fn run(input: impl AsRef<OsStr>, out: &Path, flags: &[&str]) -> Output {
    BIN.run_bake(input, out, &[flags, &["--quiet"]].concat())
}

/// Runs `input -o out flags… --quiet` and asserts it succeeded.
fn bake(input: impl AsRef<OsStr>, out: &Path, flags: &[&str]) -> Output {
    BIN.bake(input, out, &[flags, &["--quiet"]].concat())
}

fn load_clamped(p: &Path) -> Image {
    let mut img = io::read_image(p, ColorSpace::Linear).unwrap();
    ibl_core::image::check_texels(&mut img, p, false).unwrap();
    img
}

/// The 9 basis functions exactly as docs/CONVENTIONS.md prints them, in f64.
fn y9(d: [f64; 3]) -> [f64; 9] {
    let [x, y, z] = d;
    [
        0.282095,
        0.488603 * y,
        0.488603 * z,
        0.488603 * x,
        1.092548 * x * y,
        1.092548 * y * z,
        0.315392 * (3.0 * z * z - 1.0),
        1.092548 * x * z,
        0.546274 * (x * x - y * y),
    ]
}

fn dir64(d: Vec3) -> [f64; 3] {
    let d = [d.x as f64, d.y as f64, d.z as f64];
    let n = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
    d.map(|v| v / n)
}

#[derive(serde::Deserialize)]
struct ShFile {
    bands: usize,
    radiance: Vec<[f64; 3]>,
    irradiance: Vec<[f64; 3]>,
}

#[test]
fn coefficients_match_an_exact_projection_of_the_source_texels() {
    let dir = tempfile::tempdir().unwrap();
    let src = fixture("hdri/city_512.exr");
    bake(&src, dir.path(), &[]);
    let sh: ShFile =
        serde_json::from_slice(&std::fs::read(dir.path().join("sh.json")).unwrap()).unwrap();
    assert_eq!(
        (sh.bands, sh.radiance.len(), sh.irradiance.len()),
        (3, 9, 9)
    );
    let img = load_clamped(&src);
    let mut want = [[0.0f64; 3]; 9];
    for j in 0..img.height {
        let sa = row_solid_angle(j, img.width, img.height);
        for i in 0..img.width {
            let y = y9(dir64(pixel_direction(i, j, img.width, img.height)));
            let c = img.rgb(i, j);
            for k in 0..9 {
                for q in 0..3 {
                    want[k][q] += c[q] as f64 * y[k] * sa;
                }
            }
        }
    }
    let l00 = want[0][1];
    let mut worst = 0.0f64;
    for k in 0..9 {
        for q in 0..3 {
            worst = worst.max((sh.radiance[k][q] - want[k][q]).abs() / l00);
        }
    }
    eprintln!("radiance SH vs independent f64 projection: worst difference {worst:.2e} of L00");
    assert!(worst < 1e-4, "{worst}");
    // E/π coefficients: Â0 = π, Â1 = 2π/3, Â2 = π/4, divided by π.
    let scale = [
        1.0,
        2.0 / 3.0,
        2.0 / 3.0,
        2.0 / 3.0,
        0.25,
        0.25,
        0.25,
        0.25,
        0.25,
    ];
    for k in 0..9 {
        for q in 0..3 {
            assert!((sh.irradiance[k][q] - scale[k] * sh.radiance[k][q]).abs() < 1e-5 * l00);
        }
    }
}

/// Brute-force E/π at direction n over every source pixel, f64.
fn brute_force(img: &Image, n: [f64; 3]) -> [f64; 3] {
    let mut acc = [0.0f64; 3];
    for j in 0..img.height {
        let sa = row_solid_angle(j, img.width, img.height);
        for i in 0..img.width {
            let d = dir64(pixel_direction(i, j, img.width, img.height));
            let c = (d[0] * n[0] + d[1] * n[1] + d[2] * n[2]).max(0.0);
            if c > 0.0 {
                let l = img.rgb(i, j);
                for q in 0..3 {
                    acc[q] += l[q] as f64 * c * sa;
                }
            }
        }
    }
    acc.map(|v| v / std::f64::consts::PI)
}

#[test]
fn exact_cube_matches_brute_force_and_sh_cube_matches_its_coefficients() {
    let dir = tempfile::tempdir().unwrap();
    let src = fixture("hdri/sunset_256.exr");
    let exact_dir = dir.path().join("exact");
    let sh_dir = dir.path().join("sh");
    for (out, extra) in [(&exact_dir, &["--exact"][..]), (&sh_dir, &["--from-sh"])] {
        bake(&src, out, &[&["--size", "8"], extra].concat());
    }
    let img = load_clamped(&src);
    let sh: ShFile =
        serde_json::from_slice(&std::fs::read(sh_dir.join("sh.json")).unwrap()).unwrap();
    let (mut num, mut den, mut sh_worst) = (0.0f64, 0.0f64, 0.0f64);
    for face in Face::ALL {
        let exact = io::read_image(
            &exact_dir.join(format!("{}.exr", face.name())),
            ColorSpace::Linear,
        )
        .unwrap();
        let from_sh = io::read_image(
            &sh_dir.join(format!("{}.exr", face.name())),
            ColorSpace::Linear,
        )
        .unwrap();
        for (i, j) in [(0, 0), (7, 0), (3, 4), (0, 7), (7, 7)] {
            let n = dir64(texel_direction(face, i, j, 8));
            let want = brute_force(&img, n);
            let got = exact.rgb(i, j);
            for q in 0..3 {
                num += (got[q] as f64 - want[q]).abs();
                den += want[q];
            }
            let y = y9(n);
            let eval: f64 = (0..9)
                .map(|k| sh.irradiance[k][1] * y[k])
                .sum::<f64>()
                .max(0.0);
            sh_worst =
                sh_worst.max((from_sh.rgb(i, j)[1] as f64 - eval).abs() / sh.irradiance[0][1]);
        }
    }
    eprintln!("--exact irradiance vs brute force: relative MAE {:.2e}; SH cube vs its coefficients: worst {sh_worst:.1e} of c00", num / den);
    assert!(num / den < 0.005);
    assert!(sh_worst < 1e-5);
}

#[test]
fn ron_output_more_bands_and_window() {
    let dir = tempfile::tempdir().unwrap();
    let input = fixture("hdri/studio_256.hdr");
    let coeffs = ["--bands", "5", "--sh-file", "coeffs.ron", "--size", "4"];
    bake(
        &input,
        dir.path(),
        &[&coeffs[..], &["--window", "--layout", "ktx2"]].concat(),
    );
    let text = std::fs::read_to_string(dir.path().join("coeffs.ron")).unwrap();
    assert!(text.contains("bands: 5"), "{text}");
    assert!(dir.path().join("irradiance.ktx2").exists());
    // The window scales band l of the irradiance by sinc(πl/5) (Lanczos σ factor), computed
    // here by hand: windowed / plain = σ_l for every coefficient, and the radiance coefficients
    // are untouched.
    let plain_dir = dir.path().join("plain");
    bake(&input, &plain_dir, &coeffs);
    #[derive(serde::Deserialize)]
    struct Sh {
        radiance: Vec<(f64, f64, f64)>,
        irradiance: Vec<(f64, f64, f64)>,
    }
    let read = |p: std::path::PathBuf| -> Sh {
        ron::from_str(&std::fs::read_to_string(p).unwrap()).unwrap()
    };
    let windowed = read(dir.path().join("coeffs.ron"));
    let plain = read(plain_dir.join("coeffs.ron"));
    assert_eq!(windowed.irradiance.len(), 25);
    assert_eq!(windowed.radiance, plain.radiance);
    let mut worst = 0.0f64;
    for (i, (w, p)) in windowed
        .irradiance
        .iter()
        .zip(&plain.irradiance)
        .enumerate()
    {
        let l = (i as f64).sqrt().floor();
        let x = std::f64::consts::PI * l / 5.0;
        let sigma = if l == 0.0 { 1.0 } else { x.sin() / x };
        for (a, b) in [(w.0, p.0), (w.1, p.1), (w.2, p.2)] {
            worst = worst.max((a - sigma * b).abs() / b.abs().max(1e-3));
        }
    }
    eprintln!("--window vs sinc(πl/5) × unwindowed: worst relative difference {worst:.1e}");
    assert!(worst < 1e-5, "{worst}");
}

#[test]
fn bad_parameters_and_inputs_fail_cleanly() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let src = fixture("hdri/studio_256.exr");
    for (args, code, expect) in [
        (vec!["--bands", "0"], 2, "--bands 0"),
        (vec!["--bands", "40"], 2, "--bands 40"),
        (vec!["--sh-file", "sh.txt"], 2, "sh.txt"),
        (vec!["--exact", "--from-sh"], 2, "--exact and --from-sh"),
    ] {
        BIN.refused_bake(&src, &out, &args, code, expect);
        assert!(!out.exists());
    }
    let mut img = Image::new(8, 4, 3);
    img.data[0] = f32::NAN;
    let nan = dir.path().join("nan.exr");
    io::write_image(&nan, &img, &WriteOptions::default()).unwrap();
    let o = BIN.run_bake(&nan, &out, &[]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("1 NaN/Inf"));
    assert!(!out.exists());
}

#[test]
fn outputs_are_byte_identical_for_one_and_two_threads() {
    let dir = tempfile::tempdir().unwrap();
    let src = fixture("hdri/city_512.exr");
    let mut outs = Vec::new();
    for threads in ["1", "2"] {
        let out = dir.path().join(threads);
        for exact in [false, true] {
            let sub = out.join(if exact { "exact" } else { "sh" });
            let flags = ["--size", "8", "--threads", threads];
            let extra: &[&str] = if exact { &["--exact"] } else { &["--from-sh"] };
            bake(&src, &sub, &[&flags[..], extra].concat());
        }
        let mut files: Vec<(String, Vec<u8>)> = Vec::new();
        for sub in ["sh", "exact"] {
            for name in ["sh.json", "px.exr", "nz.exr"] {
                files.push((
                    format!("{sub}/{name}"),
                    std::fs::read(out.join(sub).join(name)).unwrap(),
                ));
            }
        }
        outs.push(files);
    }
    assert!(outs[0] == outs[1]);
}

/// `--target`: the cube turned as the engine samples it and the engine's own SH file, whose
/// values, evaluated the engine's way, reproduce our irradiance (the gltf cube).
/// Every `.exr` face of a `--layout faces` output folder, in Face order.
fn faces(dir: &Path) -> Vec<Vec<f32>> {
    Face::ALL
        .iter()
        .map(|f| load_clamped(&dir.join(format!("{}.exr", f.name()))).data)
        .collect()
}

#[test]
fn cube_reading_targets_get_the_exact_cube_by_default_sh_readers_the_sh_cube() {
    // Issue 22: engines that sample the diffuse cube (gltf, bevy) show every texel of it, and
    // a 3-band SH misses a sun by several percent; SH-reading engines never see the cube.
    let tmp = tempfile::tempdir().unwrap();
    let src = fixture("hdri/city_512.exr");
    let run = |name: &str, flags: &[&str]| {
        let out = tmp.path().join(name);
        let base = ["--size", "8", "--layout", "faces"];
        bake(&src, &out, &[&base[..], flags].concat());
        faces(&out)
    };
    let exact = run("exact", &["--exact"]);
    let sh = run("sh", &["--from-sh"]);
    assert_ne!(exact, sh, "the fixture must tell the two cubes apart");
    assert_eq!(
        run("gltf", &[]),
        exact,
        "gltf's default cube is the exact one"
    );
    // custom stores half floats: compare it with its own --exact.
    assert_eq!(
        run("custom", &["--target", "custom"]),
        run("custom-exact", &["--target", "custom", "--exact"])
    );
    assert_eq!(run("gltf-sh", &["--target", "gltf", "--from-sh"]), sh);
    // An SH reader: its default is the SH cube, --exact still forces the exact one.
    let unity = run("unity", &["--target", "unity"]);
    let unity_exact = run("unity-exact", &["--target", "unity", "--exact"]);
    assert_ne!(unity, unity_exact, "unity's default cube is the SH one");
    assert_eq!(run("unity-sh", &["--target", "unity", "--from-sh"]), unity);
}

#[test]
fn targets_write_the_engines_sh_forms_and_orientation() {
    let tmp = tempfile::tempdir().unwrap();
    let input = fixture("hdri/sunset_256.exr");
    let bake = |t: &str| {
        let out = tmp.path().join(t);
        // Faces here (each target's own container is checked by `make conformance`). The
        // SH cube for every target (gltf's default is exact): the SH forms are checked against it.
        let flags = [
            "--size",
            "8",
            "--target",
            t,
            "--layout",
            "faces",
            "--from-sh",
        ];
        bake(&input, &out, &flags);
        out
    };
    let gltf = bake("gltf");
    let face = |dir: &Path, f: &str| load_clamped(&dir.join(format!("{f}.exr")));
    let ours: Vec<Image> = ["px", "nx", "py", "ny", "pz", "nz"]
        .iter()
        .map(|f| face(&gltf, f))
        .collect();
    let ours_at = |d: Vec3| {
        let (f, sc, tc) = Face::from_direction(d);
        let (i, j) = ibl_core::cube::face_texel_index(sc, tc, 8);
        ours[f as usize].rgb(i, j)
    };
    assert!(
        gltf.join("LOAD.txt").exists(),
        "gltf writes its note too (issue 22)"
    );
    // Filament: sh.txt lines "(r, g, b); // Llm, irradiance, pre-scaled base", evaluated as
    // its shader does, in the file's frame: our direction (z, y, −x) at file direction t.
    let fil = bake("filament");
    let txt = std::fs::read_to_string(fil.join("sh.txt")).unwrap();
    let sh: Vec<[f64; 3]> = txt
        .lines()
        .map(|l| {
            let inside = &l[l.find('(').unwrap() + 1..l.find(')').unwrap()];
            let v: Vec<f64> = inside
                .split(',')
                .map(|s| s.trim().parse().unwrap())
                .collect();
            [v[0], v[1], v[2]]
        })
        .collect();
    assert_eq!(sh.len(), 9);
    let fil_px = face(&fil, "px");
    for j in 0..8 {
        for i in 0..8 {
            let t = texel_direction(Face::Px, i, j, 8).normalize();
            let (x, y, z) = (t.x as f64, t.y as f64, t.z as f64);
            let poly = [
                1.0,
                y,
                z,
                x,
                y * x,
                y * z,
                3.0 * z * z - 1.0,
                z * x,
                x * x - y * y,
            ];
            let want = ours_at(Vec3::new(t.z, t.y, -t.x));
            for c in 0..3 {
                let e: f64 = (0..9).map(|k| sh[k][c] * poly[k]).sum();
                assert!(
                    (e - want[c] as f64).abs() < 1e-4 * want[c].max(1e-3) as f64 + 1e-6,
                    "filament sh at {t:?}: {e} vs {}",
                    want[c]
                );
            }
            // The cube itself: the same permutation, texel for texel.
            assert_eq!(fil_px.rgb(i, j), want);
        }
    }
    assert!(std::fs::read_to_string(fil.join("LOAD.txt"))
        .unwrap()
        .contains("Filament"));
    // Unity: SphericalHarmonicsL2 packed as PackSH and evaluated as SampleSH9, in Unity's
    // left-handed frame (our z negated).
    let uni = bake("unity");
    let j: serde_json::Value =
        serde_json::from_slice(&std::fs::read(uni.join("SphericalHarmonicsL2.json")).unwrap())
            .unwrap();
    let k = |n: &str| -> Vec<f64> {
        j["shader"][n]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect()
    };
    // At texel centres (our z-negated direction is one too), where the cube holds the SH value.
    for (f, i, j) in [
        (Face::Py, 2, 5),
        (Face::Nz, 7, 0),
        (Face::Px, 3, 3),
        (Face::Ny, 1, 6),
    ] {
        let u = texel_direction(f, i, j, 8).normalize();
        let (x, y, z) = (u.x as f64, u.y as f64, u.z as f64);
        let want = ours_at(Vec3::new(u.x, u.y, -u.z));
        for (c, (a, b)) in [
            ("unity_SHAr", "unity_SHBr"),
            ("unity_SHAg", "unity_SHBg"),
            ("unity_SHAb", "unity_SHBb"),
        ]
        .iter()
        .enumerate()
        {
            let (a, b, cc) = (k(a), k(b), k("unity_SHC"));
            let e = a[0] * x
                + a[1] * y
                + a[2] * z
                + a[3]
                + b[0] * x * y
                + b[1] * y * z
                + b[2] * z * z
                + b[3] * z * x
                + cc[c] * (x * x - y * y);
            assert!(
                (e - want[c] as f64).abs() < 1e-4 * want[c] as f64 + 1e-6,
                "unity {u:?} {e} vs {}",
                want[c]
            );
        }
    }
    // three: the LightProbe document holds 27 numbers.
    let three = bake("three");
    let j: serde_json::Value =
        serde_json::from_slice(&std::fs::read(three.join("LightProbe.json")).unwrap()).unwrap();
    assert_eq!(j["object"]["type"], "LightProbe");
    assert_eq!(j["object"]["sh"].as_array().unwrap().len(), 27);
    // Fewer than 3 bands cannot make an engine's 9 coefficients.
    let flags = ["--bands", "2", "--target", "unity"];
    let o = run(&input, &tmp.path().join("x"), &flags);
    assert_eq!(o.status.code(), Some(2));
}

/// Issue 22: for every target × layout, the note (LOAD.txt) is written (gltf too) and names
/// only files this run wrote.
#[test]
fn every_target_and_layout_writes_a_note_naming_only_its_own_files() {
    BIN.assert_every_target_writes_a_true_note(&fixture("hdri/sunset_256.exr"));
}
