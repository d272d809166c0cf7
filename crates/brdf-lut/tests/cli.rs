//! End-to-end tests of the `brdf-lut` binary: every table and output format, determinism
//! across thread counts, and one-line errors with no output for bad parameters.

use ibl_core::io::{read_image, ColorSpace};
use ibl_core::progress::NoProgress;
use ibl_lut::{as_size_bias, dfg, fresnel_tail};
use ibl_testkit::Bin;
use std::path::Path;

const BIN: Bin = Bin::new(env!("CARGO_BIN_EXE_brdf-lut"), "brdf-lut");

/// Reads the R and G channels of an EXR (the core reader keeps a lone R of an RG file).
fn read_exr_channels(path: &Path) -> (usize, usize, Vec<Vec<f32>>) {
    use exr::prelude::*;
    let img = read_all_flat_layers_from_file(path).expect("readable EXR");
    let layer = &img.layer_data[0];
    let (w, h) = (layer.size.0, layer.size.1);
    let mut chans: Vec<(String, Vec<f32>)> = layer
        .channel_data
        .list
        .iter()
        .map(|c| (c.name.to_string(), c.sample_data.values_as_f32().collect()))
        .collect();
    chans.sort_by(|a, b| a.0.cmp(&b.0));
    (w, h, chans.into_iter().map(|c| c.1).collect())
}

#[test]
fn dfg_exr_is_the_library_table_and_deterministic() {
    let dir = tempfile::tempdir().unwrap();
    let a = dir.path().join("a.exr");
    let b = dir.path().join("b.exr");
    for (out, threads) in [(&a, "1"), (&b, "2")] {
        let flags = [
            "--size",
            "16",
            "--samples",
            "256",
            "--threads",
            threads,
            "-q",
        ];
        BIN.bake("dfg", out, &flags);
    }
    assert_eq!(
        std::fs::read(&a).unwrap(),
        std::fs::read(&b).unwrap(),
        "thread count changed the bytes"
    );
    let (w, h, ch) = read_exr_channels(&a);
    assert_eq!((w, h, ch.len()), (16, 16, 2));
    let lib = dfg::dfg_table(16, 256, false, &NoProgress);
    // Channels sorted by name: G, R.
    let (g, r) = (&ch[0], &ch[1]);
    assert_eq!(r.len(), w * h);
    for (k, l) in lib.data.chunks(2).enumerate() {
        assert_eq!((r[k], g[k]), (l[0], l[1]), "(A, B) at {k}");
    }
    // Row 0 is the smallest roughness: at n·v ≈ 1 a near-mirror reflects everything (A ≈ 1).
    assert!(lib.texel(15, 0)[0] > 0.85);
}

#[test]
fn dfg_multiscatter_png_json_and_ron() {
    let dir = tempfile::tempdir().unwrap();
    let p = |n: &str| dir.path().join(n);
    let dfg = |name: &str, size: &str, extra: &[&str]| {
        let flags = ["--size", size, "--samples", "64", "-q"];
        BIN.bake("dfg", p(name), &[&flags[..], extra].concat());
    };
    dfg("m.exr", "8", &["--multiscatter"]);
    let m = read_image(&p("m.exr"), ColorSpace::Linear).unwrap();
    assert_eq!(m.channels, 3);
    for t in m.data.chunks(3) {
        assert_eq!(t[2], t[0] + t[1]);
    }
    dfg("d.png", "8", &[]);
    let png = read_image(&p("d.png"), ColorSpace::Linear).unwrap();
    assert_eq!((png.width, png.channels), (8, 3));
    let lib = dfg::dfg_table(8, 64, false, &NoProgress);
    for (t, l) in png.data.chunks(3).zip(lib.data.chunks(2)) {
        assert!(
            (t[0] - l[0]).abs() <= 0.5 / 65535.0 + 1e-7
                && (t[1] - l[1]).abs() <= 0.5 / 65535.0 + 1e-7
                && t[2] == 0.0
        );
    }
    dfg("d.json", "4", &[]);
    let j: serde_json::Value =
        serde_json::from_slice(&std::fs::read(p("d.json")).unwrap()).unwrap();
    assert_eq!(j["width"], 4);
    let lib = dfg::dfg_table(4, 64, false, &NoProgress);
    assert_eq!(
        j["texels"][2][1][0].as_f64().unwrap() as f32,
        lib.texel(1, 2)[0]
    );
    assert_eq!(j["params"]["samples"], 64);
    dfg("d.ron", "4", &[]);
    let ron_text = std::fs::read_to_string(p("d.ron")).unwrap();
    assert!(
        ron_text.contains("texels") && ron_text.contains("width: 4"),
        "{ron_text}"
    );
}

#[test]
fn fresnel_tail_and_as_size_bias() {
    let dir = tempfile::tempdir().unwrap();
    let tail = dir.path().join("tail.exr");
    BIN.bake(
        "fresnel-tail",
        &tail,
        &["--size", "8", "--samples", "128", "-q"],
    );
    let (_, _, ch) = read_exr_channels(&tail);
    let lib = fresnel_tail::tail_table(8, 128, &NoProgress);
    assert_eq!(ch[1][5], lib.data[10]);
    assert_eq!(ch[0][5], lib.data[11]);

    let sb = dir.path().join("sb.exr");
    let lobe = ["--nu", "20000", "--nv", "70"];
    let small = ["--size", "8", "--samples", "256", "-q"];
    BIN.bake("as-size-bias", &sb, &[&lobe[..], &small].concat());
    let (w, _, ch) = read_exr_channels(&sb);
    let a = ibl_brdf_as(20000.0, 70.0);
    let lib =
        as_size_bias::size_bias_table(&as_size_bias::SampleSet::direct(&a, 256), 8, &NoProgress);
    assert_eq!(w, 8);
    for (k, l) in lib.data.chunks(2).enumerate() {
        assert_eq!((ch[1][k], ch[0][k]), (l[0], l[1]));
    }
    // The thesis's names: a folder, brdfIntegration[NU,NV].png with B = 0.
    let thesis = ["--thesis-names", "--size", "8", "--samples", "64"];
    let hv = ["--sampler", "hv-lut", "-q"];
    BIN.bake(
        "as-size-bias",
        dir.path(),
        &[&lobe[..], &thesis, &hv].concat(),
    );
    let png = read_image(
        &dir.path().join("brdfIntegration[20000,70].png"),
        ColorSpace::Linear,
    )
    .unwrap();
    assert_eq!(png.channels, 3);
    assert!(png.data.chunks(3).all(|t| t[2] == 0.0 && t[0] > 0.0));
}

fn ibl_brdf_as(nu: f64, nv: f64) -> ibl_brdf::AshikhminShirley {
    ibl_brdf::AshikhminShirley::new(nu, nv)
}

/// A bad invocation `table -o out flags…`: exit code, exactly one line on stderr, nothing
/// written into `dir` (which holds one file, `file`).
fn refused(table: &str, out: &Path, flags: &[&str], dir: &Path, code: i32) {
    BIN.refused_bake(table, out, flags, code, "");
    let left = ibl_testkit::files_in(dir);
    assert!(left.iter().all(|n| n == "file"), "{flags:?} left {left:?}");
}

#[test]
fn bad_parameters_are_one_line_errors_with_no_output() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("file"), b"x").unwrap();
    let o = &d.join("o.exr");
    let asb = "as-size-bias";
    refused(asb, o, &["--nu", "0", "--nv", "70"], d, 2);
    refused(asb, o, &["--nv", "70"], d, 2);
    refused(asb, o, &["--nu", "1e7", "--nv", "70"], d, 2);
    refused(asb, o, &["--nu", "nan", "--nv", "70"], d, 2);
    refused("dfg", o, &["--size", "0"], d, 2);
    refused("dfg", o, &["--size", "100000"], d, 2);
    refused("dfg", o, &["--samples", "-5"], d, 2);
    refused("dfg", o, &["--samples", "0"], d, 2);
    refused("fresnel-tail", o, &["--samples", "x"], d, 2);
    refused("dfg", &d.join("o.txt"), &[], d, 3);
    refused("dfg", &d.join("file/o.exr"), &["--size", "4"], d, 2);
    for args in [["dfg"], ["nonsense"]] {
        BIN.refused(&args, 2, "");
    }
    assert_eq!(ibl_testkit::files_in(d), ["file"]);
}
