//! End to end: `contact-sheet` on a small bake output tree written with ibl_core's writers
//! (faces, a KTX2 chain with its prefilter.json, an irradiance folder, a DFG table), and on
//! missing or garbled inputs.

use ibl_core::io::{self, ColorSpace, FloatDepth, WriteOptions};
use ibl_core::{CubeMips, Cubemap, Image};
use ibl_testkit::Bin;
use std::path::Path;

const BIN: Bin = Bin::new(env!("CARGO_BIN_EXE_contact-sheet"), "contact-sheet");

fn write_faces(dir: &Path, prefix: &str, cube: &Cubemap) {
    for (k, face) in cube.faces.iter().enumerate() {
        let name = format!("{prefix}{}.exr", ibl_core::Face::from_index(k).name());
        io::write_image(&dir.join(name), face, &WriteOptions::default()).unwrap();
    }
}

/// out/{cube, prefiltered, irradiance, dfg, shexp}: red environment, green 3-level chain (as
/// KTX2), blue irradiance, a yellow 16² table, and a folder with no image.
fn tree(root: &Path) {
    for d in ["cube", "prefiltered", "irradiance", "dfg", "shexp"] {
        std::fs::create_dir_all(root.join(d)).unwrap();
    }
    write_faces(
        &root.join("cube"),
        "",
        &Cubemap::constant(8, [1.0, 0.0, 0.0]),
    );
    let mips = CubeMips {
        levels: [8, 4, 2]
            .map(|n| Cubemap::constant(n, [0.0, 1.0, 0.0]))
            .to_vec(),
    };
    std::fs::write(
        root.join("prefiltered/prefiltered.ktx2"),
        io::ktx2::encode_cube(&mips, FloatDepth::F32),
    )
    .unwrap();
    std::fs::write(
        root.join("prefiltered/prefilter.json"),
        r#"{"level":[{"roughness":0.0},{"roughness":0.5},{"roughness":1.0}]}"#,
    )
    .unwrap();
    write_faces(
        &root.join("irradiance"),
        "",
        &Cubemap::constant(4, [0.0, 0.0, 1.0]),
    );
    std::fs::write(root.join("irradiance/sh.json"), "{}").unwrap();
    let lut = Image::from_data(16, 16, 2, [0.9, 0.9].repeat(256)).unwrap();
    io::write_image(&root.join("dfg/dfg.exr"), &lut, &WriteOptions::default()).unwrap();
    std::fs::write(root.join("shexp/shexp.json"), "{}").unwrap();
}

/// The sphere rows: a probe whose chain and irradiance hold exactly what the reference
/// computes (a constant environment: every level and E/π equal it) reads back with no error;
/// a chain at half the radiance shows as a 50% error on the metal spheres.
#[test]
fn sphere_rows_compare_the_bake_as_gltf_reads_it_with_the_reference() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path().join("out");
    for d in ["cube", "prefiltered", "irradiance"] {
        std::fs::create_dir_all(root.join(d)).unwrap();
    }
    let white = [0.7f32, 0.7, 0.7];
    write_faces(&root.join("cube"), "", &Cubemap::constant(8, white));
    write_faces(&root.join("irradiance"), "", &Cubemap::constant(4, white));
    std::fs::write(root.join("irradiance/sh.json"), "{}").unwrap();
    let chain = |c: [f32; 3]| {
        for (l, n) in [8usize, 4, 2].iter().enumerate() {
            write_faces(
                &root.join("prefiltered"),
                &format!("m{l}_"),
                &Cubemap::constant(*n, c),
            );
        }
    };
    chain(white);
    let sheet = root.join("sheet.png");
    let out = BIN.bake(&root, &sheet, &["--height", "48", "--json"]);
    let j: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let rows = j["details"]["rows"].as_array().unwrap();
    assert!(
        rows.last().unwrap()["title"]
            .as_str()
            .unwrap()
            .starts_with("spheres"),
        "{rows:?}"
    );
    let s = &j["details"]["spheres"];
    for g in ["metal_mirror", "metal_rough", "dielectric_rough"] {
        assert!(s[g].as_f64().unwrap() < 1e-4, "{g}: {s}");
    }
    chain([0.35, 0.35, 0.35]);
    let out = BIN.bake(&root, &sheet, &["--height", "48", "--json"]);
    let j: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let e = j["details"]["spheres"]["metal_rough"].as_f64().unwrap();
    assert!((e - 0.5).abs() < 1e-3, "{e}");
}

#[test]
fn sheet_has_every_row_in_order_and_the_lut_as_stored() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path().join("out");
    tree(&root);
    let sheet = root.join("sheet.png");
    let out = BIN.bake(&root, &sheet, &["--height", "48", "--json", "--no-spheres"]);
    let summary: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert!(summary["details"]["spheres"].is_null());
    let img = io::read_image(&sheet, ColorSpace::Linear).unwrap();
    assert_eq!(summary["details"]["width"], img.width);
    assert_eq!(summary["details"]["height"], img.height);
    let rows = summary["details"]["rows"].as_array().unwrap();
    assert_eq!(rows.len(), 4, "{rows:?}");
    assert_eq!(rows[1]["tiles"][2], "level 2, r = 1.00 (2²)");
    // Four rows of 48-pixel tiles; the widest row is the chain's three 64×48 crosses.
    assert!(
        img.height > 4 * 48 && img.width > 3 * 64,
        "{}×{}",
        img.width,
        img.height
    );

    // Each row's tiles: pixels of its colour, at least a whole cross's 6 faces of 16² each,
    // and the rows top to bottom in the order environment, chain, irradiance, table.
    let byte = |v: f32| (v * 255.0).round() as i32;
    let rows_of = |pred: &dyn Fn([i32; 3]) -> bool| {
        let mut ys = Vec::new();
        for y in 0..img.height {
            for x in 0..img.width {
                let t = img.texel(x, y);
                if pred([byte(t[0]), byte(t[1]), byte(t[2])]) {
                    ys.push(y);
                }
            }
        }
        ys
    };
    let dominant = |c: usize| move |p: [i32; 3]| (0..3).all(|k| k == c || p[c] > p[k] + 80);
    let red = rows_of(&dominant(0));
    let green = rows_of(&dominant(1));
    let blue = rows_of(&dominant(2));
    let lut = rows_of(&|p| p == [230, 230, 0]);
    assert!(
        red.len() >= 6 * 16 * 16,
        "environment row: {} px",
        red.len()
    );
    assert!(
        green.len() >= 3 * 6 * 16 * 16,
        "chain row: {} px",
        green.len()
    );
    assert!(
        blue.len() >= 6 * 16 * 16,
        "irradiance row: {} px",
        blue.len()
    );
    // The table is shown as stored, 0.9 → 230, scaled from 16² to 48².
    assert_eq!(lut.len(), 48 * 48);
    let span = |v: &[usize]| (v[0], *v.last().unwrap());
    let (r, g, b, l) = (span(&red), span(&green), span(&blue), span(&lut));
    assert!(
        r.1 < g.0 && g.1 < b.0 && b.1 < l.0,
        "{r:?} {g:?} {b:?} {l:?}"
    );
    assert_eq!((l.1 - l.0 + 1), 48);
}

#[test]
fn missing_garbled_or_mismatched_inputs_fail_in_one_line_and_write_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let sheet = dir.path().join("sheet.png");

    let missing = dir.path().join("nowhere");
    BIN.refused_bake(&missing, &sheet, &[], 4, "nowhere");

    let garbled = dir.path().join("garbled");
    std::fs::create_dir_all(&garbled).unwrap();
    for f in ["px", "nx", "py", "ny", "pz", "nz"] {
        std::fs::write(garbled.join(format!("{f}.exr")), b"not an exr at all").unwrap();
    }
    BIN.refused_bake(&garbled, &sheet, &[], 2, "garbled");

    let empty = dir.path().join("empty");
    std::fs::create_dir_all(&empty).unwrap();
    BIN.refused_bake(&empty, &sheet, &[], 2, "empty");

    // prefilter.json that disagrees with the chain beside it.
    let root = dir.path().join("out");
    tree(&root);
    std::fs::write(
        root.join("prefiltered/prefilter.json"),
        r#"{"level":[{"roughness":0.0}]}"#,
    )
    .unwrap();
    BIN.refused_bake(&root, &sheet, &[], 2, "prefilter.json");

    BIN.refused_bake(&empty, dir.path().join("s.jpg"), &[], 2, ".png");

    assert!(!sheet.exists());
    let left: Vec<_> = std::fs::read_dir(dir.path()).unwrap().collect();
    assert_eq!(left.len(), 3, "only the inputs remain: {left:?}");
}

/// Issue 24: `-o` replaces only a sheet contact-sheet wrote (recorded in `.ibl-outputs.json`
/// beside it, bytes unchanged); a user's file of that name, or a sheet edited since, is refused
/// before any work and survives byte for byte; `--overwrite` replaces it; a second run over
/// its own sheet (as `make demo` does) just works.
#[test]
fn the_sheet_replaces_only_its_own_file() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path().join("out");
    tree(&root);
    let sheet = dir.path().join("sheets/sheet.png");
    std::fs::create_dir_all(sheet.parent().unwrap()).unwrap();
    let flags = ["--height", "16", "--no-spheres", "-q"];
    // A user's file named like the sheet.
    std::fs::write(&sheet, b"my drawing").unwrap();
    let line = BIN.refused_bake(&root, &sheet, &flags, 2, "sheet.png");
    assert!(
        line.contains("was not written by this tool") && line.contains("--overwrite"),
        "{line}"
    );
    assert_eq!(std::fs::read(&sheet).unwrap(), b"my drawing");
    assert!(!sheet.with_file_name(".ibl-outputs.json").exists());
    // --overwrite: the user means it; the sheet is then recorded as ours.
    let mut forced = flags.to_vec();
    forced.push("--overwrite");
    BIN.bake(&root, &sheet, &forced);
    let first = std::fs::read(&sheet).unwrap();
    assert_ne!(first, b"my drawing");
    let record: serde_json::Value =
        serde_json::from_slice(&std::fs::read(sheet.with_file_name(".ibl-outputs.json")).unwrap())
            .unwrap();
    assert_eq!(
        record["files"]["sheet.png"].as_str().unwrap(),
        ibl_core::ownership::hash_bytes(&first)
    );
    // Its own sheet: a second run replaces it without a flag (make demo runs it twice).
    BIN.bake(&root, &sheet, &flags);
    assert_eq!(std::fs::read(&sheet).unwrap(), first);
    // Edited since: refused, the edit kept.
    let mut edited = first.clone();
    edited.extend_from_slice(b"edit");
    std::fs::write(&sheet, &edited).unwrap();
    let line = BIN.refused_bake(&root, &sheet, &flags, 2, "sheet.png");
    assert!(line.contains("changed since"), "{line}");
    assert_eq!(std::fs::read(&sheet).unwrap(), edited);
    // A symlink where the sheet goes is never written through, --overwrite or not.
    let target = dir.path().join("elsewhere.png");
    std::fs::write(&target, b"not yours").unwrap();
    let link = dir.path().join("sheets/link.png");
    std::os::unix::fs::symlink(&target, &link).unwrap();
    BIN.refused_bake(&root, &link, &forced, 2, "symlink");
    assert_eq!(std::fs::read(&target).unwrap(), b"not yours");
}
