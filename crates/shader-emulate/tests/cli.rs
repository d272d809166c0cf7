//! End-to-end tests of the `shader-emulate` binary: inputs → emulate → compare on small cubes
//! written here, the gate's exit codes, and one-line refusals of bad files.

use ibl_core::io::{write_image, WriteOptions};
use ibl_core::{Cubemap, Face, Image};
use ibl_testkit::{assert_one_line_error, stdout, Bin};
use shader_emulate::Grid;
use std::path::Path;

const BIN: Bin = Bin::new(env!("CARGO_BIN_EXE_shader-emulate"), "shader-emulate");

/// Writes `cube`'s faces as `{prefix}{face}.exr` into `dir`.
fn write_faces(dir: &Path, prefix: &str, cube: &Cubemap) {
    std::fs::create_dir_all(dir).unwrap();
    for f in Face::ALL {
        let n = cube.size;
        let mut img = Image::new(n, n, 3);
        for j in 0..n {
            for i in 0..n {
                img.texel_mut(i, j).copy_from_slice(&cube.texel(f, i, j));
            }
        }
        let p = dir.join(format!("{prefix}{}.exr", f.name()));
        write_image(&p, &img, &WriteOptions::default()).unwrap();
    }
}

fn sky(n: usize) -> Cubemap {
    Cubemap::from_fn(n, |d| {
        [0.2 + d.y.max(0.0), 0.3 + 0.5 * d.x.abs(), 0.1 + d.z * d.z]
    })
}

/// A custom chain as `prefilter --target custom` writes it: `dir/prefilter.ktx2`, RGBA16F,
/// with `alpha`'s channel 0 in the alpha channel. Returns its path.
fn write_custom_chain(
    dir: &Path,
    mips: &ibl_core::CubeMips,
    alpha: &ibl_core::CubeMips,
) -> std::path::PathBuf {
    std::fs::create_dir_all(dir).unwrap();
    let enc = ibl_core::output::Encoding {
        layout: ibl_core::output::Layout::Ktx2,
        format: ibl_core::io::format::PixelFormat::Rgba16f,
        ..Default::default()
    };
    let e = ibl_core::output::encode_chain_with_alpha(dir, mips, alpha, &enc, "prefilter", &[])
        .unwrap();
    for (p, b) in &e.files {
        std::fs::write(p, b).unwrap();
    }
    dir.join("prefilter.ktx2")
}

/// A small correction (signed, smooth) for a chain of `mips`' shape.
fn some_alpha(mips: &ibl_core::CubeMips) -> ibl_core::CubeMips {
    ibl_core::CubeMips {
        levels: mips
            .levels
            .iter()
            .map(|c| {
                Cubemap::from_fn(c.size, |d| {
                    let v = 0.05 * d.normalize().x;
                    [v, v, v]
                })
            })
            .collect(),
    }
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

#[test]
fn inputs_emulate_compare_and_the_gate() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // Aniso: a single cube (px.exr …), box-mipped by the tool.
    write_faces(&d.join("env"), "", &sky(8));
    let (inp, cpu) = (d.join("in.json"), d.join("cpu.json"));
    // The isotropic split sum's chain (isoSpecular input) and its sidecar.
    let mips = ibl_core::CubeMips::build(sky(8), 2);
    let chain = write_custom_chain(&d.join("chain"), &mips, &some_alpha(&mips));
    let lk = ibl_prefilter::custom::CustomLookup::new(0.01, mips.levels.len(), 8);
    let sidecar = d.join("prefilter.json");
    std::fs::write(
        &sidecar,
        serde_json::json!({ "custom_lookup": lk }).to_string(),
    )
    .unwrap();
    let out = BIN.run(&["inputs", "aniso", "--normals", "2", "-o", s(&inp)]);
    assert_one_line_error(&out, 2, "--iso-chain");
    BIN.run_ok(&[
        "inputs",
        "aniso",
        "--normals",
        "2",
        "--iso-chain",
        s(&chain),
        "--iso-sidecar",
        s(&sidecar),
        "-o",
        s(&inp),
    ]);
    BIN.run_ok(&[
        "emulate",
        s(&inp),
        "--chain",
        s(&d.join("env")),
        "-o",
        s(&cpu),
    ]);
    let g = Grid::read(&cpu).unwrap();
    assert_eq!(g.count, 2 * 3 * 7 * 5);
    assert!(g.data.iter().all(|v| v.is_finite()));
    let ok = BIN.run_ok(&[
        "compare",
        s(&cpu),
        s(&cpu),
        "--max-mean",
        "0",
        "--max-p99",
        "0",
    ]);
    assert!(stdout(&ok).contains(": ok"), "{}", stdout(&ok));
    // A wrong output fails the gate with exit 1 (not 2: the files are fine).
    // (A case whose reads touch no cube-corner texel: alpha 1.)
    let k = (0..g.count).find(|&i| g.case(i)[3] == 1.0).unwrap();
    let mut bad = g.clone();
    bad.data[4 * k] *= 1.5;
    let badp = d.join("bad.json");
    bad.write(&badp).unwrap();
    let out = BIN.run(&[
        "compare",
        s(&cpu),
        s(&badp),
        "--max-mean",
        "1e-6",
        "--max-p99",
        "1e-6",
    ]);
    assert_eq!(out.status.code(), Some(1), "{}", stdout(&out));
    assert!(stdout(&out).contains("FAIL"));
    // η = 0 returns isoSpecular: one ulp off in one such case fails the gate, whatever the
    // mean/p99 gates say.
    assert!(stdout(&ok).contains("bit-identical"), "{}", stdout(&ok));
    let k = (0..g.count).find(|&i| g.case(i)[3] == 2.0).unwrap();
    let mut bad = g.clone();
    bad.data[4 * k] = f32::from_bits(bad.data[4 * k].to_bits() + 1);
    bad.write(&badp).unwrap();
    let out = BIN.run(&[
        "compare",
        s(&cpu),
        s(&badp),
        "--max-mean",
        "1",
        "--max-p99",
        "1",
    ]);
    assert_eq!(out.status.code(), Some(1), "{}", stdout(&out));
    assert!(stdout(&out).contains("pass-through") && stdout(&out).contains("FAIL"));
}

#[test]
fn custom_emulation_checks_its_sidecar() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let mips = ibl_core::CubeMips::build(sky(8), 2);
    let chain = write_custom_chain(&d.join("chain"), &mips, &some_alpha(&mips));
    let lk = ibl_prefilter::custom::CustomLookup::new(0.01, mips.levels.len(), 8);
    let sidecar = d.join("prefilter.json");
    std::fs::write(
        &sidecar,
        serde_json::json!({ "custom_lookup": lk }).to_string(),
    )
    .unwrap();
    let (inp, cpu) = (d.join("in.json"), d.join("cpu.json"));
    BIN.run_ok(&[
        "inputs",
        "custom",
        "--dirs",
        "8",
        "--roughness",
        "3",
        "-o",
        s(&inp),
    ]);
    let args = |side: &Path| {
        vec![
            "emulate".to_string(),
            s(&inp).into(),
            "--chain".into(),
            s(&chain).into(),
            "--sidecar".into(),
            s(side).into(),
            "-o".into(),
            s(&cpu).into(),
        ]
    };
    let run = |side: &Path| {
        let a = args(side);
        BIN.run(&a.iter().map(String::as_str).collect::<Vec<_>>())
    };
    assert!(run(&sidecar).status.success());
    assert_eq!(Grid::read(&cpu).unwrap().count, (8 + 26) * 3);
    // A sidecar whose constants are not this chain's lookup is refused before any output.
    let mut wrong = lk.clone();
    wrong.scale *= 1.01;
    let bad = d.join("wrong.json");
    std::fs::write(
        &bad,
        serde_json::json!({ "custom_lookup": wrong }).to_string(),
    )
    .unwrap();
    std::fs::remove_file(&cpu).unwrap();
    assert_one_line_error(&run(&bad), 2, "wrong.json");
    assert!(!cpu.exists());
    // The power factors are the chain's: a sidecar without them, or with one pair too few, is
    // refused too (the read would silently lose them).
    for (name, power) in [
        ("nopower.json", serde_json::Value::Null),
        ("shortpower.json", serde_json::json!([[0.0, 0.0]])),
        (
            "nanpower.json",
            serde_json::json!([[0.0, 0.0], ["NaN", 0.0]]),
        ),
    ] {
        let mut v = serde_json::json!({ "custom_lookup": lk });
        v["custom_lookup"]["power"] = power;
        let bad = d.join(name);
        std::fs::write(&bad, v.to_string()).unwrap();
        assert_one_line_error(&run(&bad), 2, "power");
        assert!(!cpu.exists(), "{name}");
    }
    // A chain without an alpha channel (face images) cannot hold the correction: refused.
    let faces = d.join("faces");
    for (l, c) in mips.levels.iter().enumerate() {
        write_faces(&faces, &format!("m{l}_"), c);
    }
    let mut a = args(&sidecar);
    a[3] = s(&faces).into();
    let out = BIN.run(&a.iter().map(String::as_str).collect::<Vec<_>>());
    assert_one_line_error(&out, 2, "alpha");
    // No sidecar, a malformed input grid: one line naming the file, exit 2.
    let out = BIN.run(&["emulate", s(&inp), "--chain", s(&chain), "-o", s(&cpu)]);
    assert_one_line_error(&out, 2, "--sidecar");
    std::fs::write(&inp, "{\"format\":\"ibl-shader-check/1\"").unwrap();
    assert_one_line_error(&run(&sidecar), 2, "in.json");
}
