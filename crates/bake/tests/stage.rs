//! End-to-end tests of the single-stage entry points other executors use: `bake stage` runs a
//! plan entry from materialised inputs into a result folder, `bake commit` commits result
//! folders. Checked against `bake run` itself: same bytes, and a pipeline built stage by stage
//! is up to date for `bake run`.

use ibl_testkit::{copy_tree, stderr, stdout, stdout_json, workspace_root as root};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn bake(dir: &Path, args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_bake"))
        .args(args)
        .current_dir(dir)
        .output()
        .unwrap()
}

fn ok(o: Output) -> Output {
    assert!(o.status.success(), "{}\n{}", stderr(&o), stdout(&o));
    o
}

/// Every file under `dir` but the cache, with its bytes.
fn tree(dir: &Path) -> Vec<(String, Vec<u8>)> {
    ibl_testkit::files_under(dir, &[".bake"])
        .into_iter()
        .map(|rel| {
            let bytes = std::fs::read(dir.join(&rel)).unwrap();
            (rel, bytes)
        })
        .collect()
}

/// A workspace copy holding the probe pipeline writing into `out/<name>`.
fn workspace(dir: &Path, name: &str) -> PathBuf {
    copy_tree(&root().join("fixtures/hdri"), &dir.join("fixtures/hdri"));
    let text = std::fs::read_to_string(root().join("pipelines/probe.ron"))
        .unwrap()
        .replace("../out/probe", &format!("../out/{name}"));
    let p = dir.join(format!("pipelines/{name}.ron"));
    std::fs::create_dir_all(p.parent().unwrap()).unwrap();
    std::fs::write(&p, text).unwrap();
    p
}

fn plan(dir: &Path, pipeline: &Path) -> Vec<Value> {
    let o = ok(bake(dir, &["plan", pipeline.to_str().unwrap(), "--json"]));
    let v: Value = stdout_json(&o);
    v["stages"].as_array().unwrap().clone()
}

/// Materialises an entry's reads under `inputs` from where the plan says the files are, as
/// an executor ships them.
fn materialise(entry: &Value, inputs: &Path) {
    for (k, read) in entry["reads"].as_array().unwrap().iter().enumerate() {
        for f in read["files"].as_array().unwrap() {
            let to = inputs.join(k.to_string()).join(f["rel"].as_str().unwrap());
            std::fs::create_dir_all(to.parent().unwrap()).unwrap();
            std::fs::copy(f["path"].as_str().unwrap(), &to).unwrap();
        }
    }
}

/// Runs `bake stage` for `entry` in a scratch folder away from the pipeline; the result folder.
fn run_stage(scratch: &Path, entry: &Value) -> PathBuf {
    let id = entry["id"].as_str().unwrap().replace('/', "_");
    let (inputs, out) = (
        scratch.join(format!("in-{id}")),
        scratch.join(format!("res-{id}")),
    );
    materialise(entry, &inputs);
    let e = scratch.join(format!("{id}.json"));
    std::fs::write(&e, serde_json::to_vec(entry).unwrap()).unwrap();
    let o = ok(bake(
        scratch,
        &[
            "stage",
            "--entry",
            e.to_str().unwrap(),
            "--inputs",
            inputs.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--json",
        ],
    ));
    let report: Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(report["id"], entry["id"]);
    assert_eq!(report["key"], entry["key"]);
    out
}

#[test]
fn each_stage_on_its_own_gives_bake_runs_bytes_and_commits_up_to_date() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let reference = workspace(d, "ref");
    ok(bake(d, &["run", reference.to_str().unwrap(), "--quiet"]));
    let expected = tree(&d.join("out/ref"));
    assert!(expected.len() > 10, "{}", expected.len());

    // Stage by stage, in plan order, each in a scratch folder, committed as it finishes.
    let staged = workspace(d, "staged");
    let scratch = d.join("scratch");
    let stages = plan(d, &staged);
    assert!(stages.iter().all(|s| s["action"] == "run"));
    for s in &stages {
        let result = run_stage(&scratch, &s["entry"]);
        // The stage's own files are those `bake run` wrote for it.
        let dir_rel = s["entry"]["dir"].as_str().unwrap();
        let mine: Vec<(String, Vec<u8>)> = tree(&result.join("files"));
        let theirs: Vec<(String, Vec<u8>)> = expected
            .iter()
            .filter_map(|(rel, b)| {
                Path::new(rel)
                    .strip_prefix(dir_rel)
                    .ok()
                    .map(|r| (r.to_string_lossy().into_owned(), b.clone()))
            })
            .collect();
        assert!(!mine.is_empty());
        assert_eq!(mine, theirs, "stage {}", s["id"]);
        let o = ok(bake(
            d,
            &[
                "commit",
                staged.to_str().unwrap(),
                result.to_str().unwrap(),
                "--json",
            ],
        ));
        let done: Value = serde_json::from_slice(&o.stdout).unwrap();
        assert_eq!(done[0]["status"], "ran", "{done}");
    }
    assert_eq!(tree(&d.join("out/staged")), expected);
    let o = ok(bake(d, &["run", staged.to_str().unwrap(), "--json"]));
    let v: Value = serde_json::from_slice(&o.stdout).unwrap();
    for s in v["stages"].as_array().unwrap() {
        assert_eq!(s["status"], "up-to-date", "{s}");
    }
    assert!(!d.join("out/staged/.bake/tmp").exists());

    // Deleted outputs come back from the cache with `commit --restore`, as `bake run` would.
    std::fs::remove_dir_all(d.join("out/staged/irradiance")).unwrap();
    let p = plan(d, &staged);
    let irr = p.iter().find(|s| s["id"] == "irradiance").unwrap();
    assert_eq!(irr["action"], "restore");
    let o = ok(bake(
        d,
        &[
            "commit",
            staged.to_str().unwrap(),
            "--restore",
            "irradiance",
            "--json",
        ],
    ));
    let done: Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(done[0]["status"], "restored", "{done}");
    assert_eq!(tree(&d.join("out/staged")), expected);
}

#[test]
fn bad_entries_inputs_and_results_fail_with_one_line_and_write_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let pipeline = workspace(d, "p");
    let stages = plan(d, &pipeline);
    let cube = stages.iter().find(|s| s["id"] == "cube").unwrap()["entry"].clone();
    let scratch = d.join("scratch");
    let stage = |entry: &Value, inputs: &Path, out: &Path| {
        let e = scratch.join("e.json");
        std::fs::create_dir_all(&scratch).unwrap();
        std::fs::write(&e, serde_json::to_vec(entry).unwrap()).unwrap();
        bake(
            d,
            &[
                "stage",
                "--entry",
                e.to_str().unwrap(),
                "--inputs",
                inputs.to_str().unwrap(),
                "--out",
                out.to_str().unwrap(),
            ],
        )
    };
    let one_error = |o: &Output, code: i32, needle: &str| {
        let err = String::from_utf8_lossy(&o.stderr).into_owned();
        assert_eq!(o.status.code(), Some(code), "{err}");
        assert_eq!(err.lines().count(), 1, "{err}");
        assert!(
            err.starts_with("bake: error: stage 'cube': ") && err.contains(needle),
            "{err}"
        );
    };

    // A damaged input: the sky cut short.
    let inputs = scratch.join("in");
    materialise(&cube, &inputs);
    let sky = inputs
        .join("0")
        .join(cube["reads"][0]["args"][0].as_str().unwrap());
    let bytes = std::fs::read(&sky).unwrap();
    std::fs::write(&sky, &bytes[..bytes.len() / 3]).unwrap();
    let out = scratch.join("res");
    one_error(&stage(&cube, &inputs, &out), 2, "city_512.exr");
    assert!(!out.exists(), "nothing written");
    std::fs::write(&sky, &bytes).unwrap();

    // A wrong but valid file under the input's name (another HDRI): refused by its hash,
    // before the bake; so is a file the plan does not list, and a symlink.
    std::fs::copy(root().join("fixtures/hdri/studio_256.exr"), &sky).unwrap();
    one_error(
        &stage(&cube, &inputs, &out),
        2,
        "is not the file the plan recorded",
    );
    assert!(!out.exists(), "nothing written");
    std::fs::write(&sky, &bytes).unwrap();
    let extra = inputs.join("0/extra.exr");
    std::fs::write(&extra, b"x").unwrap();
    one_error(
        &stage(&cube, &inputs, &out),
        2,
        "not one of the files the plan lists",
    );
    std::fs::remove_file(&extra).unwrap();
    #[cfg(unix)]
    {
        let moved = scratch.join("sky-elsewhere.exr");
        std::fs::rename(&sky, &moved).unwrap();
        std::os::unix::fs::symlink(&moved, &sky).unwrap();
        one_error(&stage(&cube, &inputs, &out), 2, "not a regular file");
        std::fs::remove_file(&sky).unwrap();
        std::fs::rename(&moved, &sky).unwrap();
    }
    assert!(!out.exists(), "nothing written");

    // Another build's plan, parameters that do not read back, an unknown kind.
    let mut other = cube.clone();
    other["tool"] = "0.0.0+elsewhere".into();
    one_error(&stage(&other, &inputs, &out), 3, "0.0.0+elsewhere");
    let mut bad = cube.clone();
    bad["params"]["size"] = "huge".into();
    one_error(&stage(&bad, &inputs, &out), 2, "size");
    let mut bad = cube.clone();
    bad["kind"] = "teleport".into();
    one_error(&stage(&bad, &inputs, &out), 3, "teleport");
    let mut bad = cube.clone();
    bad["reads"][0]["args"][0] = "../../etc/passwd".into();
    one_error(&stage(&bad, &inputs, &out), 2, "plain relative path");
    assert!(!out.exists(), "nothing written");

    // A result whose bytes changed after the stage reported them is not committed.
    ok(stage(&cube, &inputs, &out));
    let face = out.join("files/px.exr");
    let mut b = std::fs::read(&face).unwrap();
    b[100] ^= 1;
    std::fs::write(&face, b).unwrap();
    let o = bake(
        d,
        &["commit", pipeline.to_str().unwrap(), out.to_str().unwrap()],
    );
    assert_eq!(
        o.status.code(),
        Some(2),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(String::from_utf8_lossy(&o.stderr).contains("px.exr"));
    assert!(!d.join("out/p/cube").exists());

    // A result holding a file the stage does not write (reported consistently in its
    // stage.json) is not committed either.
    let _ = std::fs::remove_dir_all(&out);
    ok(stage(&cube, &inputs, &out));
    let report_path = out.join("stage.json");
    let mut report: Value = serde_json::from_slice(&std::fs::read(&report_path).unwrap()).unwrap();
    std::fs::write(out.join("files/extra.bin"), b"x").unwrap();
    report["outputs"]
        .as_array_mut()
        .unwrap()
        .push(serde_json::json!({
            "rel": "extra.bin", "size": 1, "hash": blake3::hash(b"x").to_hex().to_string()
        }));
    std::fs::write(&report_path, serde_json::to_vec(&report).unwrap()).unwrap();
    let o = bake(
        d,
        &["commit", pipeline.to_str().unwrap(), out.to_str().unwrap()],
    );
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("not those the stage writes"),
        "{}",
        stderr(&o)
    );
    assert!(!d.join("out/p/cube/extra.bin").exists());
}

/// The pipeline's `max_memory` travels with each plan entry: `bake stage` on another machine
/// runs under the same budget (refusing the 512×256 panorama the equirect stage reads, in one
/// line naming the budget, exit 3), unless its own `--max-memory` names one.
#[test]
fn a_pipelines_budget_travels_with_its_entries() {
    let dir = tempfile::tempdir().unwrap();
    let pipeline = workspace(dir.path(), "budget");
    let text = std::fs::read_to_string(&pipeline).unwrap().replacen(
        "Pipeline(\n",
        "Pipeline(\n    max_memory: \"64K\",\n",
        1,
    );
    std::fs::write(&pipeline, text).unwrap();
    let stages = plan(dir.path(), &pipeline);
    let entry = stages
        .iter()
        .find(|s| s["id"] == "cube")
        .and_then(|s| s.get("entry"))
        .cloned()
        .unwrap_or_else(|| panic!("no entry for 'cube' in {stages:?}"));
    assert_eq!(entry["max_memory"], 65536, "{entry}");

    let scratch = dir.path().join("scratch");
    let (inputs, e) = (scratch.join("in"), scratch.join("cube.json"));
    materialise(&entry, &inputs);
    std::fs::write(&e, serde_json::to_vec(&entry).unwrap()).unwrap();
    let stage = |extra: &[&str], out: &str| {
        let mut args = vec!["stage", "--entry", e.to_str().unwrap()];
        args.extend(["--inputs", inputs.to_str().unwrap()]);
        args.extend(["--out", out]);
        args.extend(extra);
        bake(&scratch, &args)
    };
    let refused = stage(&[], "res-a");
    assert_eq!(refused.status.code(), Some(3), "{}", stderr(&refused));
    let msg = stderr(&refused);
    assert_eq!(msg.trim_end().lines().count(), 1, "{msg}");
    assert!(msg.contains("memory budget"), "{msg}");
    assert!(!scratch.join("res-a").join("stage.json").exists());
    // The flag names the budget: the stage runs.
    ok(stage(&["--max-memory", "2G"], "res-b"));
}
