//! Pins the bytes every bake writes: each example pipeline and `golden/fixtures.ron` (every
//! fixture, engine target, container and pixel format) is run by the real `bake`, and every
//! output file's BLAKE3 hash is compared with the manifest committed under `tests/golden/`.
//!
//! Why: refactors (one `Bake` definition per bake, the runner's module split) must leave every
//! output byte-identical, and a change of behaviour must be deliberate. When a change is meant to
//! alter outputs, regenerate the manifests with `GOLDEN_UPDATE=1 cargo test --release -p bake
//! --test golden` and say why in the commit: the manifest's diff shows exactly which files moved.
//! The CLIs are held to the same bytes by e2e's ninja test, which runs them and compares.

use ibl_testkit::{copy_tree, workspace_root as root};
use std::collections::BTreeMap;
use std::path::Path;
use std::process::Command;

/// Relative path → BLAKE3 hex of every file under `dir`, the runner's own `.bake/` excluded.
fn hashes(dir: &Path, rel: &Path, out: &mut BTreeMap<String, String>) {
    let mut entries: Vec<_> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap())
        .collect();
    entries.sort_by_key(|e| e.file_name());
    for e in entries {
        let name = e.file_name();
        if name == ".bake" {
            continue;
        }
        let (path, rel) = (e.path(), rel.join(&name));
        if path.is_dir() {
            hashes(&path, &rel, out);
        } else {
            let bytes = std::fs::read(&path).unwrap();
            let rel = rel.to_string_lossy().replace('\\', "/");
            out.insert(rel, blake3::hash(&bytes).to_hex().to_string());
        }
    }
}

fn manifest_text(h: &BTreeMap<String, String>) -> String {
    h.iter().map(|(p, x)| format!("{x}  {p}\n")).collect()
}

fn parse_manifest(text: &str) -> BTreeMap<String, String> {
    text.lines()
        .filter_map(|l| l.split_once("  "))
        .map(|(x, p)| (p.to_string(), x.to_string()))
        .collect()
}

/// Every file whose hash differs between the manifest (`want`) and a run (`got`), one line each.
fn differences(want: &BTreeMap<String, String>, got: &BTreeMap<String, String>) -> Vec<String> {
    let mut problems = Vec::new();
    for (path, hash) in want {
        match got.get(path) {
            None => problems.push(format!("{path}: no longer written")),
            Some(h) if h != hash => problems.push(format!("{path}: bytes changed")),
            Some(_) => {}
        }
    }
    for path in got.keys().filter(|p| !want.contains_key(*p)) {
        problems.push(format!("{path}: newly written"));
    }
    problems
}

/// Runs `pipelines/<name>.ron` in a copy of the workspace and checks (or, with
/// `GOLDEN_UPDATE=1`, rewrites) `tests/golden/<name>.b3`.
fn check(name: &str, output: &str) {
    let work = tempfile::tempdir().unwrap();
    copy_tree(&root().join("pipelines"), &work.path().join("pipelines"));
    copy_tree(&root().join("fixtures"), &work.path().join("fixtures"));
    copy_tree(
        &Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/golden/fixtures.ron"),
        &work.path().join("pipelines/golden-fixtures.ron"),
    );
    let out = Command::new(env!("CARGO_BIN_EXE_bake"))
        .args(["run", &format!("pipelines/{name}.ron"), "--quiet"])
        .current_dir(work.path())
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "bake run pipelines/{name}.ron failed:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let mut got = BTreeMap::new();
    hashes(&work.path().join(output), Path::new(""), &mut got);
    assert!(!got.is_empty(), "{name} wrote nothing");

    let manifest = Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("tests/golden/{name}.b3"));
    if std::env::var_os("GOLDEN_UPDATE").is_some() {
        std::fs::write(&manifest, manifest_text(&got)).unwrap();
        return;
    }
    let want = parse_manifest(&std::fs::read_to_string(&manifest).unwrap_or_else(|e| {
        panic!(
            "{}: {e}; create it with GOLDEN_UPDATE=1 cargo test --release -p bake --test golden",
            manifest.display()
        )
    }));
    let problems = differences(&want, &got);
    assert!(
        problems.is_empty(),
        "{name}: {} of {} outputs differ from tests/golden/{name}.b3 (if meant, regenerate with \
         GOLDEN_UPDATE=1 and say why in the commit):\n{}",
        problems.len(),
        want.len(),
        problems.join("\n")
    );
}

#[test]
fn probe_pipeline_bytes_are_pinned() {
    check("probe", "out/probe");
}

#[test]
fn materials_pipeline_bytes_are_pinned() {
    check("materials", "out/materials");
}

#[test]
fn anisotropic_scene_bytes_are_pinned() {
    check("anisotropic-scene", "out/anisotropic-scene");
}

#[test]
fn every_fixture_target_and_format_bytes_are_pinned() {
    check("golden-fixtures", "out/golden-fixtures");
}

#[test]
fn a_manifest_round_trips_and_a_changed_missing_or_new_file_is_caught() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::create_dir_all(dir.path().join("a")).unwrap();
    std::fs::write(dir.path().join("a/b.exr"), b"x").unwrap();
    std::fs::write(dir.path().join("c.json"), b"y").unwrap();
    std::fs::create_dir_all(dir.path().join(".bake")).unwrap();
    std::fs::write(dir.path().join(".bake/lock"), b"").unwrap();
    let mut want = BTreeMap::new();
    hashes(dir.path(), Path::new(""), &mut want);
    assert_eq!(
        want.keys().collect::<Vec<_>>(),
        ["a/b.exr", "c.json"],
        "the runner's .bake/ is not an output"
    );
    assert_eq!(parse_manifest(&manifest_text(&want)), want);
    assert!(differences(&want, &want).is_empty());

    // One byte more in one file, one file gone, one file new: each named.
    std::fs::write(dir.path().join("a/b.exr"), b"x\0").unwrap();
    std::fs::remove_file(dir.path().join("c.json")).unwrap();
    std::fs::write(dir.path().join("d.ktx2"), b"z").unwrap();
    let mut got = BTreeMap::new();
    hashes(dir.path(), Path::new(""), &mut got);
    assert_eq!(
        differences(&want, &got),
        [
            "a/b.exr: bytes changed",
            "c.json: no longer written",
            "d.ktx2: newly written"
        ]
    );
}
