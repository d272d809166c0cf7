//! End-to-end tests: the real `bake` binary on temporary copies of pipelines and fixtures.

use ibl_testkit::{copy_tree, stderr, stdout, stdout_json, workspace_root as root};
use serde_json::Value;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::{Duration, Instant};

/// A temporary workspace laid out like the real one (pipelines/, fixtures/, out/).
struct Work {
    dir: tempfile::TempDir,
}

impl Work {
    fn new() -> Self {
        Work {
            dir: tempfile::tempdir().unwrap(),
        }
    }
    fn path(&self, rel: &str) -> PathBuf {
        self.dir.path().join(rel)
    }
    /// Copies a file or folder of the real workspace to the same place here.
    fn copy(&self, rel: &str) {
        copy_tree(&root().join(rel), &self.path(rel));
    }
    fn write(&self, rel: &str, text: &str) {
        let p = self.path(rel);
        std::fs::create_dir_all(p.parent().unwrap()).unwrap();
        std::fs::write(p, text).unwrap();
    }
    fn cmd(&self, args: &[&str]) -> Command {
        let mut c = Command::new(env!("CARGO_BIN_EXE_bake"));
        c.args(args).current_dir(self.dir.path());
        c
    }
    fn bake(&self, args: &[&str]) -> Output {
        self.cmd(args).output().unwrap()
    }
    /// `bake run FILE --json`: stage id → status, asserting success.
    fn run_ok(&self, file: &str, extra: &[&str]) -> BTreeMap<String, String> {
        let mut args = vec!["run", file, "--json"];
        args.extend(extra);
        let out = self.bake(&args);
        assert!(
            out.status.success(),
            "bake run failed: {}\n{}",
            String::from_utf8_lossy(&out.stderr),
            String::from_utf8_lossy(&out.stdout)
        );
        statuses(&out)
    }
}

fn statuses(out: &Output) -> BTreeMap<String, String> {
    let v: Value = stdout_json(out);
    v["stages"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| {
            (
                s["id"].as_str().unwrap().to_string(),
                s["status"].as_str().unwrap().to_string(),
            )
        })
        .collect()
}

/// Every file under `dir` (relative paths), `.bake/` excluded.
fn files_under(dir: &Path) -> Vec<String> {
    ibl_testkit::files_under(dir, &[".bake"])
}

fn ids_with(st: &BTreeMap<String, String>, status: &str) -> Vec<String> {
    st.iter()
        .filter(|(_, s)| *s == status)
        .map(|(id, _)| id.clone())
        .collect()
}

/// A small pipeline of two independent chains, cheap to run.
const CHAINS: &str = r#"Pipeline(
    output: "out",
    inputs: { "a": File("a.exr"), "b": File("b.exr") },
    stages: [
        (id: "a1", kind: "equirect-to-cube", reads: ["a"], params: (size: 16)),
        (id: "a2", kind: "equirect-to-cube", reads: ["a1"], params: (size: 8)),
        (id: "b1", kind: "equirect-to-cube", reads: ["b"], params: (size: 16, layout: ktx2)),
        (id: "b2", kind: "irradiance", reads: ["b1"], params: (size: 4)),
    ],
)"#;

fn chains() -> Work {
    let w = Work::new();
    std::fs::copy(root().join("fixtures/hdri/studio_256.exr"), w.path("a.exr")).unwrap();
    std::fs::copy(root().join("fixtures/hdri/sunset_256.exr"), w.path("b.exr")).unwrap();
    w.write("p.ron", CHAINS);
    w
}

#[test]
fn probe_example_runs_then_a_second_run_does_no_work() {
    let w = Work::new();
    w.copy("pipelines/probe.ron");
    w.copy("fixtures/hdri/city_512.exr");
    let t = Instant::now();
    let st = w.run_ok("pipelines/probe.ron", &[]);
    eprintln!("first run of probe.ron: {:.2} s", t.elapsed().as_secs_f64());
    assert_eq!(
        ids_with(&st, "ran"),
        ["cube", "dfg", "irradiance", "prefiltered", "shexp"]
    );
    for f in [
        "cube/px.exr",
        "cube/nz.exr",
        "prefiltered/m0_px.exr",
        "prefiltered/prefilter.json",
        "irradiance/sh.json",
        "irradiance/py.exr",
        "dfg/dfg.exr",
        "shexp/shexp.json",
    ] {
        assert!(w.path("out/probe").join(f).is_file(), "{f} missing");
    }
    let t = Instant::now();
    let st = w.run_ok("pipelines/probe.ron", &[]);
    eprintln!(
        "second run of probe.ron: {:.3} s",
        t.elapsed().as_secs_f64()
    );
    assert!(st.values().all(|s| s == "up-to-date"), "{st:?}");
    // The human summary says so for every stage too.
    let out = w.bake(&["run", "pipelines/probe.ron"]);
    let text = stdout(&out);
    assert_eq!(
        text.lines()
            .filter(|l| l.contains("  up to date  "))
            .count(),
        5,
        "{text}"
    );
    assert!(text.contains("0 ran, 0 restored, 5 up to date"), "{text}");
    // From another folder, the same pipeline is the same pipeline (paths are relative to it).
    let out = Command::new(env!("CARGO_BIN_EXE_bake"))
        .args(["plan", "probe.ron"])
        .current_dir(w.path("pipelines"))
        .output()
        .unwrap();
    assert_eq!(
        stdout(&out)
            .lines()
            .filter(|l| l.contains("  up-to-date  ") && l.ends_with("up to date"))
            .count(),
        5,
        "the action of an up-to-date stage is 'up-to-date', not 'skip': {}",
        stdout(&out)
    );
}

#[test]
fn a_changed_input_or_parameter_reruns_exactly_what_is_downstream() {
    let w = chains();
    let st = w.run_ok("p.ron", &[]);
    assert_eq!(ids_with(&st, "ran"), ["a1", "a2", "b1", "b2"]);
    // New bytes for input b.
    std::fs::copy(
        root().join("fixtures/hdri/interior_256.exr"),
        w.path("b.exr"),
    )
    .unwrap();
    let plan = stdout(&w.bake(&["plan", "p.ron"]));
    assert!(
        plan.lines()
            .any(|l| l.starts_with("b1 ") && l.contains("run") && l.contains("input 'b' changed")),
        "{plan}"
    );
    assert!(
        plan.lines()
            .any(|l| l.starts_with("b2 ") && l.contains("upstream 'b1' changed")),
        "{plan}"
    );
    let st = w.run_ok("p.ron", &[]);
    assert_eq!(ids_with(&st, "ran"), ["b1", "b2"]);
    assert_eq!(ids_with(&st, "up-to-date"), ["a1", "a2"]);
    // One parameter of a2.
    let text = CHAINS.replace("params: (size: 8)", "params: (size: 4)");
    w.write("p.ron", &text);
    let plan = stdout(&w.bake(&["plan", "p.ron"]));
    assert!(plan.contains("parameters changed: size 8 -> 4"), "{plan}");
    let st = w.run_ok("p.ron", &[]);
    assert_eq!(ids_with(&st, "ran"), ["a2"]);
    // Back to the old value: the cache still has those outputs.
    w.write("p.ron", CHAINS);
    let st = w.run_ok("p.ron", &[]);
    assert_eq!(ids_with(&st, "restored"), ["a2"]);
    assert_eq!(ids_with(&st, "ran"), Vec::<String>::new());
}

#[test]
fn outputs_deleted_are_rebuilt_and_edited_ones_with_overwrite() {
    let w = chains();
    w.run_ok("p.ron", &[]);
    let px = std::fs::read(w.path("out/a1/px.exr")).unwrap();
    let sh = std::fs::read(w.path("out/b2/sh.json")).unwrap();
    std::fs::remove_file(w.path("out/a1/px.exr")).unwrap();
    std::fs::remove_dir_all(w.path("out/b2")).unwrap();
    std::fs::write(w.path("out/a2/nx.exr"), b"edited by hand").unwrap();
    let plan = stdout(&w.bake(&["plan", "p.ron"]));
    assert!(plan.contains("outputs missing: px.exr"), "{plan}");
    assert!(plan.contains("outputs modified: nx.exr"), "{plan}");
    // The hand edit is not bake's to replace: refused before any stage runs, edit kept.
    let refused = w.bake(&["run", "p.ron"]);
    let line = ibl_testkit::assert_one_line_error(&refused, 2, "a2/nx.exr");
    assert!(line.contains("--overwrite"), "{line}");
    assert_eq!(
        std::fs::read(w.path("out/a2/nx.exr")).unwrap(),
        b"edited by hand"
    );
    assert!(!w.path("out/a1/px.exr").exists(), "nothing ran");
    let st = w.run_ok("p.ron", &["--overwrite"]);
    assert_eq!(ids_with(&st, "up-to-date"), ["b1"]);
    assert_eq!(std::fs::read(w.path("out/a1/px.exr")).unwrap(), px);
    assert_eq!(std::fs::read(w.path("out/b2/sh.json")).unwrap(), sh);
    assert_ne!(
        std::fs::read(w.path("out/a2/nx.exr")).unwrap(),
        b"edited by hand"
    );
    // With the cache gone too, they are baked again.
    std::fs::remove_dir_all(w.path("out/.bake/objects")).unwrap();
    std::fs::remove_file(w.path("out/a1/px.exr")).unwrap();
    let st = w.run_ok("p.ron", &[]);
    assert_eq!(ids_with(&st, "ran"), ["a1"]);
    assert_eq!(std::fs::read(w.path("out/a1/px.exr")).unwrap(), px);
}

#[test]
fn the_scene_decides_what_is_baked_and_plan_says_why() {
    let w = Work::new();
    w.copy("pipelines/anisotropic-scene.ron");
    w.copy("pipelines/materials");
    w.copy("fixtures/hdri/interior_256.exr");
    w.copy("fixtures/hdri/sunset_256.exr");
    let out = w.bake(&["plan", "pipelines/anisotropic-scene.ron"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let plan = stdout(&out);
    eprintln!("{plan}");
    let line = |id: &str| {
        plan.lines()
            .find(|l| l.starts_with(&format!("{id} ")))
            .unwrap_or_else(|| panic!("no line for {id}:\n{plan}"))
            .to_string()
    };
    let runs = |id: &str| line(id).contains(" run ");
    for id in [
        "lobby/cube",
        "lobby/irradiance",
        "lobby/prefilter",
        "sky/cube",
        "sky/irradiance",
        "sky/shexp",
        "dfg",
        "fresnel-tail",
    ] {
        assert!(runs(id), "{}", line(id));
    }
    assert!(line("lobby/prefilter").contains("split-sum up to roughness 0.5"));
    assert!(
        line("sky/prefilter").contains("skip")
            && line("sky/prefilter")
                .contains("not needed by the scene: probe 'sky' is served by SH-exp")
    );
    assert!(line("lobby/shexp")
        .contains("not needed by the scene: probe 'lobby' is served by split-sum"));
    // One hv-lut and one size/bias table per distinct (n_u, n_v).
    let hv: Vec<&str> = plan.lines().filter(|l| l.starts_with("hv-lut/")).collect();
    assert_eq!(hv.len(), 2, "{hv:?}");
    assert!(
        runs("hv-lut/100x10")
            && runs("hv-lut/1000x20")
            && runs("as-size-bias/100x10")
            && runs("as-size-bias/1000x20")
    );
    assert!(line("hv-lut/100x10").contains("'brushed-steel', 'satin'"));
    // Quaternion maps only for anisotropic bump-mapped materials.
    assert!(runs("brushed-steel/quat-map") && runs("frying-pan/quat-map"));
    assert!(line("painted-metal/quat-map")
        .contains("not needed by the scene: material 'painted-metal' is isotropic GGX"));
    assert!(line("satin/quat-map")
        .contains("not needed by the scene: material 'satin' is not bump-mapped"));
    assert!(line("satin/tpr-map").contains("has no TPR map") && runs("frying-pan/tpr-map"));

    // And the run bakes exactly that.
    let t = Instant::now();
    let st = w.run_ok("pipelines/anisotropic-scene.ron", &[]);
    eprintln!("scene run: {:.2} s", t.elapsed().as_secs_f64());
    assert_eq!(
        ids_with(&st, "skipped"),
        [
            "lobby/shexp",
            "painted-metal/quat-map",
            "painted-metal/tpr-map",
            "satin/quat-map",
            "satin/tpr-map",
            "sky/prefilter"
        ]
    );
    let out = w.path("out/anisotropic-scene");
    assert!(!out.join("sky/prefilter").exists());
    // 32² chain down to 4×4, levels at r = 0, 1/3, 2/3, 1: max roughness 0.5 keeps the
    // level count the engine's lod = r(N-1) needs, the two levels past it exact and marked.
    let chain: Vec<String> = files_under(&out.join("lobby/prefilter"))
        .into_iter()
        .filter(|f| f.ends_with("_px.exr"))
        .collect();
    assert_eq!(chain, ["m0_px.exr", "m1_px.exr", "m2_px.exr", "m3_px.exr"]);
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("lobby/prefilter/prefilter.json")).unwrap())
            .unwrap();
    let beyond: Vec<bool> = report["level"]
        .as_array()
        .unwrap()
        .iter()
        .map(|l| l["beyond_max_roughness"].as_bool().unwrap_or(false))
        .collect();
    assert_eq!(beyond, [false, false, true, true], "{report}");
    assert!(out.join("brushed-steel/quat-map/quaternion.png").is_file());
    assert!(
        out.join("hv-lut/1000x20/hv.exr").is_file() && out.join("hv-lut/1000x20/hv.json").is_file()
    );
    let st = w.run_ok("pipelines/anisotropic-scene.ron", &[]);
    assert_eq!(ids_with(&st, "ran"), Vec::<String>::new());
}

#[test]
fn materials_example_converts_every_material_folder() {
    let w = Work::new();
    w.copy("pipelines/materials.ron");
    w.copy("pipelines/materials");
    let st = w.run_ok("pipelines/materials.ron", &[]);
    assert_eq!(ids_with(&st, "ran").len(), 3, "{st:?}");
    let files = files_under(&w.path("out/materials"));
    assert_eq!(
        files,
        [
            "brushed-steel-tpr/tpr.png",
            "frying-pan-tpr/tpr.png",
            "quaternions/brushed-steel/quaternion.png",
            "quaternions/frying-pan/quaternion.png",
            "quaternions/painted-metal/quaternion.png"
        ]
    );
    // A new material folder: only the quaternion stage runs again.
    copy_tree(
        &w.path("pipelines/materials/frying-pan"),
        &w.path("pipelines/materials/wok"),
    );
    let st = w.run_ok("pipelines/materials.ron", &[]);
    assert_eq!(ids_with(&st, "ran"), ["quaternions"]);
    assert!(w
        .path("out/materials/quaternions/wok/quaternion.png")
        .is_file());
}

#[test]
fn renaming_an_input_that_names_outputs_reruns_the_stage() {
    let w = Work::new();
    w.copy("pipelines/materials/frying-pan/normal.png");
    w.copy("pipelines/materials/brushed-steel/normal.png");
    std::fs::rename(
        w.path("pipelines/materials/brushed-steel/normal.png"),
        w.path("pipelines/materials/brushed-steel/silk.png"),
    )
    .unwrap();
    let pipeline = |name: &str| {
        format!(
            r#"(output: "out", inputs: {{"a": File("pipelines/materials/frying-pan/normal.png"), "b": File("pipelines/materials/brushed-steel/{name}.png")}}, stages: [(id: "q", kind: "quat-map", reads: ["a", "b"])])"#
        )
    };
    w.write("p.ron", &pipeline("silk"));
    assert_eq!(ids_with(&w.run_ok("p.ron", &[]), "ran"), ["q"]);
    assert_eq!(
        files_under(&w.path("out")),
        ["q/normal/quaternion.png", "q/silk/quaternion.png"]
    );
    // Renamed: quat-map writes a folder named after it, so the stage runs again.
    std::fs::rename(
        w.path("pipelines/materials/brushed-steel/silk.png"),
        w.path("pipelines/materials/brushed-steel/velvet.png"),
    )
    .unwrap();
    w.write("p.ron", &pipeline("velvet"));
    assert_eq!(ids_with(&w.run_ok("p.ron", &[]), "ran"), ["q"]);
    assert_eq!(
        files_under(&w.path("out")),
        ["q/normal/quaternion.png", "q/velvet/quaternion.png"]
    );
    // The same bytes under the same name in another folder: nothing to do.
    let moved = w.path("moved/velvet.png");
    std::fs::create_dir_all(moved.parent().unwrap()).unwrap();
    std::fs::rename(
        w.path("pipelines/materials/brushed-steel/velvet.png"),
        &moved,
    )
    .unwrap();
    w.write(
        "p.ron",
        &pipeline("velvet").replace(
            "pipelines/materials/brushed-steel/velvet.png",
            "moved/velvet.png",
        ),
    );
    assert_eq!(ids_with(&w.run_ok("p.ron", &[]), "up-to-date"), ["q"]);
}

#[test]
fn a_malformed_pipeline_is_reported_with_line_and_column() {
    let w = chains();
    w.write("bad.ron", "Pipeline(\n    output: \"out\",\n    stages: [(id: \"a\" kind: \"equirect-to-cube\")],\n)\n");
    let out = w.bake(&["run", "bad.ron"]);
    assert_eq!(out.status.code(), Some(2));
    let err = stderr(&out);
    eprintln!("{err}");
    assert!(err.starts_with("bake: error: bad.ron:3:"), "{err}");
    assert!(
        err.contains("(id: \"a\" kind: \"equirect-to-cube\")") && err.contains('^'),
        "the offending text is shown: {err}"
    );
    assert!(!w.path("out").exists(), "nothing ran");
    // Unknown kinds and parameters, all at once, each with the valid names.
    w.write("bad.ron", "(\n  inputs: {\"a\": File(\"a.exr\")},\n  stages: [\n    (id: \"x\", kind: \"equirect2cube\", reads: [\"a\"]),\n    (id: \"y\", kind: \"equirect-to-cube\", reads: [\"a\"], params: (sise: 8)),\n  ],\n)\n");
    let err = stderr(&w.bake(&["plan", "bad.ron"]));
    eprintln!("{err}");
    assert!(err.contains("bad.ron:4:21: stage 'x': unknown kind 'equirect2cube' (valid kinds: equirect-to-cube, irradiance"), "{err}");
    assert!(
        err.contains("bad.ron:5:64:") && err.contains("`sise`") && err.contains("`size`"),
        "{err}"
    );
    assert!(err.contains("2 problems found; nothing was run"), "{err}");
}

#[test]
fn scene_parameters_of_a_stage_only_the_outputs_need_are_checked_before_any_work() {
    let w = chains();
    // No anisotropic material: the scene does not need 'as-size-bias', but the outputs do, and
    // a declared stage reads it. Its scene parameters are invalid (n_u must be positive).
    w.write(
        "p.ron",
        r#"(output: "out", stages: [
            (id: "cube", kind: "equirect-to-cube", reads: ["as-size-bias"], params: (size: 8)),
        ], outputs: ["as-size-bias", "p/cube", "cube"],
        scene: (probes: [(id: "p", env: "a.exr")], params: {"as-size-bias": (nu: -5)}))"#,
    );
    for args in [
        &["run", "p.ron"][..],
        &["plan", "p.ron", "--json"],
        &["plan", "p.ron", "--emit", "ninja", "-o", "build.ninja"],
    ] {
        let out = w.bake(args);
        let err = stderr(&out);
        eprintln!("{args:?}: {err}");
        assert_eq!(out.status.code(), Some(2), "{args:?}: {err}");
        assert_eq!(err.matches("bake: error:").count(), 1, "{args:?}: {err}");
        assert!(
            err.contains("as-size-bias") && err.contains("nu") && !err.contains("panicked"),
            "{args:?}: {err}"
        );
        assert!(
            !err.contains("problems found"),
            "one problem, reported once: {err}"
        );
        assert!(!w.path("out").exists(), "{args:?}: nothing was baked");
        assert!(!w.path("build.ninja").exists(), "{args:?}");
    }
}

#[test]
fn a_cycle_is_printed() {
    let w = chains();
    w.write("cycle.ron", r#"(stages: [(id: "x", kind: "equirect-to-cube", reads: ["z"]), (id: "y", kind: "equirect-to-cube", reads: ["x"]), (id: "z", kind: "equirect-to-cube", reads: ["y"])])"#);
    let out = w.bake(&["run", "cycle.ron"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(
        stderr(&out).contains("cycle: x -> y -> z -> x"),
        "{}",
        stderr(&out)
    );
}

#[test]
fn missing_inputs_and_references_are_all_reported_before_any_work() {
    let w = chains();
    w.write(
        "p.ron",
        r#"(output: "out", inputs: {"a": File("a.exr"), "gone": File("gone.exr"), "lost": Folder("lost")}, stages: [
            (id: "ok", kind: "equirect-to-cube", reads: ["a"], params: (size: 8)),
            (id: "x", kind: "equirect-to-cube", reads: ["gone"]),
            (id: "y", kind: "quat-map", reads: ["lost"]),
            (id: "z", kind: "irradiance", reads: ["nobody"]),
        ])"#,
    );
    let out = w.bake(&["run", "p.ron"]);
    assert_eq!(out.status.code(), Some(2));
    let err = stderr(&out);
    eprintln!("{err}");
    assert!(
        err.contains("input 'gone': gone.exr does not exist"),
        "{err}"
    );
    assert!(
        err.contains("input 'lost': folder lost does not exist"),
        "{err}"
    );
    assert!(
        err.contains("stage 'z' reads 'nobody', which is neither an input nor a stage"),
        "{err}"
    );
    assert!(!w.path("out").exists(), "no stage ran, not even 'ok'");
}

#[test]
fn a_failing_stage_blocks_its_dependants_and_lets_the_others_finish() {
    let w = chains();
    // b.exr truncated: exists (so the plan accepts it) but cannot be decoded.
    let bytes = std::fs::read(w.path("b.exr")).unwrap();
    std::fs::write(w.path("b.exr"), &bytes[..bytes.len() / 3]).unwrap();
    let out = w.bake(&["run", "p.ron", "--json", "--jobs", "2"]);
    assert_eq!(out.status.code(), Some(1));
    let st = statuses(&out);
    assert_eq!(st["b1"], "failed");
    assert_eq!(st["b2"], "blocked");
    assert_eq!((st["a1"].as_str(), st["a2"].as_str()), ("ran", "ran"));
    assert!(
        !w.path("out/b1").exists() && !w.path("out/b2").exists(),
        "no partial output"
    );
    assert!(!w.path("out/.bake/tmp").exists());
    let v: Value = serde_json::from_slice(&out.stdout).unwrap();
    let reason = v["stages"]
        .as_array()
        .unwrap()
        .iter()
        .find(|s| s["id"] == "b1")
        .unwrap()["reason"]
        .as_str()
        .unwrap()
        .to_string();
    assert!(
        reason.contains("b.exr"),
        "the bake's error names the file: {reason}"
    );
    // The human form says which stage failed and why, on stderr.
    let out = w.bake(&["run", "p.ron"]);
    assert_eq!(out.status.code(), Some(1));
    assert!(
        stderr(&out).contains("bake: error: stage 'b1':"),
        "{}",
        stderr(&out)
    );
    // Repaired, only the b chain runs.
    std::fs::write(w.path("b.exr"), &bytes).unwrap();
    let st = w.run_ok("p.ron", &[]);
    assert_eq!(ids_with(&st, "ran"), ["b1", "b2"]);
}

/// Three stages, the middle one slow by its real work (a brute-force prefiltered chain of
/// 128² faces from a 64² cube: seconds of CPU), so a run can be interrupted while it bakes.
/// No test hook in the shipped binary slows it down.
fn slow_chain() -> Work {
    let w = Work::new();
    std::fs::copy(root().join("fixtures/hdri/studio_256.exr"), w.path("a.exr")).unwrap();
    w.write(
        "slow.ron",
        r#"(output: "out", inputs: {"a": File("a.exr")}, stages: [
            (id: "s1", kind: "equirect-to-cube", reads: ["a"], params: (size: 64)),
            (id: "s2", kind: "prefilter", reads: ["s1"], params: (size: 128, reference: true)),
            (id: "s3", kind: "equirect-to-cube", reads: ["s1"], params: (size: 4)),
        ])"#,
    );
    w
}

fn wait_for_stage_in_manifest(w: &Work, id: &str, child: &mut std::process::Child) {
    let t = Instant::now();
    loop {
        let text = std::fs::read_to_string(w.path("out/.bake/manifest.json")).unwrap_or_default();
        if text.contains(&format!("\"{id}\": {{")) {
            return;
        }
        assert!(child.try_wait().unwrap().is_none(), "bake ended early");
        assert!(
            t.elapsed() < Duration::from_secs(60),
            "stage {id} never completed"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
}

fn no_temporaries(dir: &Path) {
    let all = files_under(dir);
    assert!(
        all.iter().all(|f| !f.contains(".tmp")),
        "temporary files left: {all:?}"
    );
}

#[test]
fn an_interrupted_run_leaves_only_complete_outputs_and_the_next_run_resumes() {
    let w = slow_chain();
    // Ctrl-C (SIGINT) while s2 bakes.
    let mut child = w
        .cmd(&["run", "slow.ron", "--jobs", "1", "--quiet"])
        .spawn()
        .unwrap();
    wait_for_stage_in_manifest(&w, "s1", &mut child);
    // Meanwhile the output folder is taken.
    let busy = w.bake(&["run", "slow.ron"]);
    assert_eq!(busy.status.code(), Some(4), "{}", stderr(&busy));
    assert!(
        stderr(&busy).contains(&format!(
            "another bake (pid {}) is using this output folder",
            child.id()
        )),
        "{}",
        stderr(&busy)
    );
    let kill = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(kill.success());
    let status = child.wait().unwrap();
    assert_eq!(status.code(), Some(130), "{status:?}");
    assert_eq!(
        files_under(&w.path("out")).len(),
        7,
        "only s1's six faces and its LOAD.txt: {:?}",
        files_under(&w.path("out"))
    );
    assert!(!w.path("out/s2").exists());
    assert!(!w.path("out/.bake/tmp").exists() && !w.path("out/.bake/lock").exists());
    no_temporaries(&w.path("out"));
    let st = w.run_ok("slow.ron", &[]);
    assert_eq!(st["s1"], "up-to-date");
    assert_eq!(ids_with(&st, "ran"), ["s2", "s3"]);

    // SIGKILL (no handler can run) in the middle of a forced run: the outputs in place are
    // whole files, and the next run takes over the stale lock and finishes.
    let before: Vec<Vec<u8>> = ["out/s2/m0_px.exr", "out/s3/px.exr"]
        .iter()
        .map(|f| std::fs::read(w.path(f)).unwrap())
        .collect();
    std::fs::remove_dir_all(w.path("out/s3")).unwrap();
    let mut child = w
        .cmd(&["run", "slow.ron", "--jobs", "1", "--quiet", "--force"])
        .spawn()
        .unwrap();
    // s1 takes milliseconds, s2 seconds: the kill lands in s2 (or s1), before s3 commits.
    std::thread::sleep(Duration::from_millis(500));
    child.kill().unwrap();
    child.wait().unwrap();
    assert_eq!(
        std::fs::read(w.path("out/s2/m0_px.exr")).unwrap(),
        before[0]
    );
    no_temporaries(&w.path("out"));
    let st = w.run_ok("slow.ron", &[]);
    assert_eq!(st["s3"], "restored", "{st:?}");
    assert_eq!(std::fs::read(w.path("out/s3/px.exr")).unwrap(), before[1]);
    assert!(!w.path("out/.bake/tmp").exists());
}

#[test]
fn clean_removes_what_the_pipeline_made_and_its_cache() {
    let w = chains();
    w.run_ok("p.ron", &[]);
    std::fs::write(w.path("out/notes.txt"), b"mine").unwrap();
    let out = w.bake(&["clean", "p.ron"]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert_eq!(
        files_under(&w.path("out")),
        ["notes.txt"],
        "only what bake did not make is left"
    );
    assert!(!w.path("out/.bake").exists());
    assert!(
        w.path("a.exr").is_file() && w.path("b.exr").is_file(),
        "inputs untouched"
    );
    let st = w.run_ok("p.ron", &[]);
    assert_eq!(ids_with(&st, "ran").len(), 4);
}

#[test]
fn clean_works_when_an_input_is_gone() {
    let w = chains();
    w.run_ok("p.ron", &[]);
    std::fs::remove_file(w.path("b.exr")).unwrap();
    let out = w.bake(&["clean", "p.ron"]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(!w.path("out").exists(), "{:?}", files_under(&w.path("out")));
}

#[test]
fn plan_lists_reads_and_json_forms_are_machine_readable() {
    let w = chains();
    let out = w.bake(&["plan", "p.ron", "--json"]);
    let v: Value = serde_json::from_slice(&out.stdout).unwrap();
    let stages = v["stages"].as_array().unwrap();
    assert_eq!(stages.len(), 4);
    let b2 = stages.iter().find(|s| s["id"] == "b2").unwrap();
    assert_eq!(b2["reads"][0]["name"], "b1");
    assert_eq!(b2["action"], "run");
    assert_eq!(b2["params"]["size"], 4);
    assert!(b2["outputs"]
        .as_array()
        .unwrap()
        .iter()
        .any(|o| o.as_str().unwrap().ends_with("out/b2/sh.json")));
    let dot = stdout(&w.bake(&["plan", "p.ron", "--emit", "dot"]));
    assert!(dot.contains("\"a1\" -> \"a2\""), "{dot}");
    let kinds = stdout(&w.bake(&["kinds"]));
    assert!(
        kinds.contains("prefilter") && kinds.contains("max_roughness"),
        "{kinds}"
    );
}

/// The packages of the CLIs a ninja file calls, built (or found fresh) next to `bake`.
fn build_clis(packages: &[&str]) -> Result<PathBuf, String> {
    let bin_dir = Path::new(env!("CARGO_BIN_EXE_bake"))
        .parent()
        .unwrap()
        .to_path_buf();
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let mut cmd = Command::new(cargo);
    // The profile `cargo test` itself used, so the libraries it compiled are reused and the
    // binaries it put beside `bake` are the ones rebuilt (if at all).
    let profile = if bin_dir.ends_with("release") {
        "release"
    } else {
        "test"
    };
    cmd.args(["build", "--profile", profile])
        .current_dir(root());
    for p in packages {
        cmd.args(["-p", p]);
    }
    let out = cmd.output().map_err(|e| format!("cannot run cargo: {e}"))?;
    if !out.status.success() {
        return Err(format!("cargo build failed:\n{}", stderr(&out)));
    }
    for p in packages {
        if !bin_dir.join(p).is_file() {
            return Err(format!("{} is not in {}", p, bin_dir.display()));
        }
    }
    Ok(bin_dir)
}

#[test]
fn the_emitted_ninja_file_runs_the_same_bakes_as_run() {
    if Command::new("ninja").arg("--version").output().is_err() {
        // Not a failure (ninja is optional), but said loudly: this test checked nothing.
        eprintln!(
            "\n*** SKIPPED the_emitted_ninja_file_runs_the_same_bakes_as_run: ninja is not \
             installed (apt-get install ninja-build); the ninja file was not run ***\n"
        );
        return;
    }
    let w = Work::new();
    w.copy("pipelines/materials");
    std::fs::copy(root().join("fixtures/hdri/studio_256.exr"), w.path("a.exr")).unwrap();
    // Every kind, small.
    w.write(
        "all.ron",
        r#"(output: "out", inputs: {"a": File("a.exr"), "mats": Folder("pipelines/materials"), "one": File("pipelines/materials/frying-pan/normal.png")}, stages: [
            (id: "cube", kind: "equirect-to-cube", reads: ["a"], params: (size: 16)),
            (id: "chain", kind: "prefilter", reads: ["cube"], params: (size: 16, levels: 3, quality: draft, max_roughness: 0.5)),
            (id: "irr", kind: "irradiance", reads: ["cube"], params: (size: 4, sh_file: "sh.ron")),
            (id: "fit", kind: "shexp-fit", reads: ["cube"], params: (normals: 8, views: 8, samples: 32, size: 8, emit_shader: true)),
            (id: "dfg", kind: "dfg", params: (size: 8, samples: 32)),
            (id: "tail", kind: "fresnel-tail", params: (size: 8, samples: 32)),
            (id: "hv", kind: "hv-lut", params: (nu: 100, nv: 10, size: 8)),
            (id: "sb", kind: "as-size-bias", params: (nu: 100, nv: 10, size: 8, samples: 32)),
            (id: "quats", kind: "quat-map", reads: ["mats"], params: (bits: 8, output_name: "q.png")),
            (id: "quat", kind: "quat-map", reads: ["one"]),
            (id: "tpr", kind: "tpr-map", params: (size: "16x8", preset: "spiral:0.5,0.5,2", roughness: "0.25,0.5")),
        ])"#,
    );
    let graph_kinds = [
        "equirect-to-cube",
        "prefilter",
        "irradiance",
        "shexp-fit",
        "brdf-lut",
        "hv-lut",
        "quat-map",
        "tpr-map",
    ];
    // The CLIs are part of this workspace: failing to build them fails the test.
    let bin_dir = build_clis(&graph_kinds)
        .unwrap_or_else(|e| panic!("the bake CLIs the ninja file calls could not be built: {e}"));
    w.run_ok("all.ron", &[]);
    std::fs::rename(w.path("out"), w.path("out-run")).unwrap();
    let out = w.bake(&[
        "plan",
        "all.ron",
        "--emit",
        "ninja",
        "-o",
        "build/build.ninja",
        "--bin-dir",
        bin_dir.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let ninja_text = std::fs::read_to_string(w.path("build/build.ninja")).unwrap();
    assert!(
        ninja_text
            .contains("$bindir/brdf-lut dfg -o ../out/dfg/dfg.exr --size=8 --samples=32 --quiet"),
        "{ninja_text}"
    );
    let out = Command::new("ninja")
        .args(["-C", "build"])
        .current_dir(w.path(""))
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "ninja failed:\n{}\n{}",
        stdout(&out),
        stderr(&out)
    );
    let ran = files_under(&w.path("out-run"));
    // The CLIs ninja runs also leave their ownership record (`.ibl-outputs.json`) beside their
    // outputs, which `bake run` keeps in its manifest instead.
    let by_ninja: Vec<String> = files_under(&w.path("out"))
        .into_iter()
        .filter(|f| !f.ends_with(ibl_testkit::OWNERSHIP_RECORD))
        .collect();
    assert_eq!(by_ninja, ran, "ninja made the same files");
    assert!(w
        .path("out/dfg")
        .join(ibl_testkit::OWNERSHIP_RECORD)
        .is_file());
    for f in &ran {
        let (a, b) = (
            std::fs::read(w.path("out-run").join(f)).unwrap(),
            std::fs::read(w.path("out").join(f)).unwrap(),
        );
        assert!(a == b, "{f} differs between bake run and ninja");
    }
    eprintln!(
        "ninja and bake run made the same {} files, byte for byte",
        ran.len()
    );
    // ninja sees nothing left to do.
    let out = Command::new("ninja")
        .args(["-C", "build", "-n"])
        .current_dir(w.path(""))
        .output()
        .unwrap();
    assert!(stdout(&out).contains("no work to do"), "{}", stdout(&out));
}

/// Runs `bake ARGS` with its stdout already closed (a `| head -1` whose reader went away).
fn with_closed_stdout(w: &Work, args: &[&str]) -> Output {
    let (reader, writer) = std::io::pipe().unwrap();
    drop(reader);
    w.cmd(args).stdout(writer).output().unwrap()
}

#[test]
fn a_closed_stdout_ends_quietly_instead_of_panicking() {
    let w = Work::new();
    w.copy("pipelines/probe.ron");
    w.copy("fixtures/hdri/city_512.exr");
    for args in [
        &["kinds"][..],
        &["kinds", "--json"],
        &["plan", "pipelines/probe.ron"],
        &["plan", "pipelines/probe.ron", "--json"],
        &["plan", "pipelines/probe.ron", "--emit", "dot"],
    ] {
        let o = with_closed_stdout(&w, args);
        let e = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(0), "{args:?}: {e}");
        assert!(!e.contains("panicked"), "{args:?}: {e}");
    }
}

#[test]
fn not_a_pipeline_zero_jobs_and_json_errors() {
    let w = Work::new();
    w.copy("fixtures/hdri/city_512.exr");
    let o = w.bake(&["run", "fixtures/hdri/city_512.exr"]);
    let e = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{e}");
    assert!(e.contains("not a RON pipeline"), "{e}");
    let o = w.bake(&["run", "fixtures/hdri/city_512.exr", "--json"]);
    let v: Value = serde_json::from_slice(&o.stdout).expect("a JSON error object");
    assert_eq!(v["exit_code"], 2);
    assert!(v["error"].as_str().unwrap().contains("not a RON pipeline"));
    // An output folder that is an existing file: said before any stage runs.
    w.write("notes.txt", "x");
    w.write(
        "f.ron",
        r#"(output: "notes.txt", inputs: {}, stages: [(id: "dfg", kind: "dfg", params: (size: 8, samples: 32))])"#,
    );
    let o = w.bake(&["run", "f.ron"]);
    let e = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{e}");
    assert!(e.contains("is an existing file"), "{e}");
    w.copy("pipelines/probe.ron");
    let o = w.bake(&["run", "pipelines/probe.ron", "--jobs", "0"]);
    let e = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{e}");
    assert!(e.contains("--jobs"), "{e}");
}

fn mtime(p: &Path) -> std::time::SystemTime {
    std::fs::metadata(p).unwrap().modified().unwrap()
}

#[test]
fn a_folder_converts_per_item_and_one_changed_map_rewrites_one_output() {
    let w = Work::new();
    // A flat folder of normal maps, one output per map ({stem}).
    for (i, m) in ["brushed-steel", "frying-pan", "painted-metal"]
        .iter()
        .enumerate()
    {
        std::fs::create_dir_all(w.path("flat")).unwrap();
        std::fs::copy(
            root().join(format!("pipelines/materials/{m}/normal.png")),
            w.path(&format!("flat/m{i}_normal.png")),
        )
        .unwrap();
    }
    w.write(
        "flat.ron",
        r#"(output: "out", inputs: {"maps": Folder("flat")}, stages: [
            (id: "q", kind: "quat-map", reads: ["maps"], params: (bits: 8, input_name: "*_normal.png", output_name: "{stem}_quat.png")),
        ])"#,
    );
    let st = w.run_ok("flat.ron", &[]);
    assert_eq!(st["q"], "ran");
    let outs: Vec<PathBuf> = (0..3)
        .map(|i| w.path(&format!("out/q/m{i}_normal_quat.png")))
        .collect();
    let before: Vec<(Vec<u8>, std::time::SystemTime)> = outs
        .iter()
        .map(|p| (std::fs::read(p).unwrap(), mtime(p)))
        .collect();
    std::thread::sleep(Duration::from_millis(50));
    // Change one map: its own output changes, the two others keep bytes and mtime.
    std::fs::copy(
        root().join("pipelines/materials/frying-pan/normal.png"),
        w.path("flat/m0_normal.png"),
    )
    .unwrap();
    let st = w.run_ok("flat.ron", &[]);
    assert_eq!(st["q"], "ran");
    assert_ne!(std::fs::read(&outs[0]).unwrap(), before[0].0);
    for k in 1..3 {
        assert_eq!(std::fs::read(&outs[k]).unwrap(), before[k].0, "output {k}");
        assert_eq!(mtime(&outs[k]), before[k].1, "output {k} was rewritten");
    }
}

/// Item name → status (`run --json`) or action (`plan --json`) of the items of stage `id`.
fn items_of(out: &Output, id: &str, field: &str) -> BTreeMap<String, String> {
    let v: Value = serde_json::from_slice(&out.stdout)
        .unwrap_or_else(|e| panic!("{e}: {}", String::from_utf8_lossy(&out.stdout)));
    let stage = v["stages"]
        .as_array()
        .unwrap()
        .iter()
        .find(|s| s["id"] == id)
        .unwrap_or_else(|| panic!("no stage {id}"));
    stage["items"]
        .as_array()
        .map(|items| {
            items
                .iter()
                .map(|i| {
                    let name = i["name"].as_str().unwrap().to_string();
                    (name, i[field].as_str().unwrap().to_string())
                })
                .collect()
        })
        .unwrap_or_default()
}

#[test]
fn a_folder_of_materials_bakes_item_by_item_and_plan_says_which_items_run() {
    let w = Work::new();
    w.copy("pipelines/materials.ron");
    w.copy("pipelines/materials");
    let mats = w.path("pipelines/materials");
    let q = |m: &str| w.path(&format!("out/materials/quaternions/{m}/quaternion.png"));
    let run = |field: &str| -> BTreeMap<String, String> {
        let out = w.bake(&["run", "pipelines/materials.ron", "--json"]);
        assert!(out.status.success(), "{}", stderr(&out));
        items_of(&out, "quaternions", field)
    };
    let plan = || w.bake(&["plan", "pipelines/materials.ron", "--json"]);
    let count = |items: &BTreeMap<String, String>, what: &str| {
        items.values().filter(|s| *s == what).count()
    };
    let first = run("status");
    assert_eq!(count(&first, "ran"), 3, "{first:?}");
    let stamp = |m: &str| (std::fs::read(q(m)).unwrap(), mtime(&q(m)));
    let before: BTreeMap<&str, _> = ["brushed-steel", "frying-pan", "painted-metal"]
        .into_iter()
        .map(|m| (m, stamp(m)))
        .collect();
    std::thread::sleep(Duration::from_millis(50));

    // One normal map changes: the plan names that item, the run bakes it alone.
    std::fs::copy(
        mats.join("frying-pan/normal.png"),
        mats.join("brushed-steel/normal.png"),
    )
    .unwrap();
    let planned = items_of(&plan(), "quaternions", "action");
    assert_eq!(
        planned["brushed-steel/quaternion.png"], "run",
        "{planned:?}"
    );
    assert_eq!(planned["frying-pan/quaternion.png"], "up-to-date");
    assert_eq!(planned["painted-metal/quaternion.png"], "up-to-date");
    let text = stdout(&w.bake(&["plan", "pipelines/materials.ron"]));
    assert!(
        text.contains("1 of 3 items to bake (brushed-steel/quaternion.png)"),
        "{text}"
    );
    assert!(
        text.contains("its input changed") && text.contains("and 2 up to date"),
        "{text}"
    );
    let second = run("status");
    assert_eq!(count(&second, "ran"), 1, "{second:?}");
    assert_eq!(count(&second, "up-to-date"), 2, "{second:?}");
    assert_ne!(stamp("brushed-steel").0, before["brushed-steel"].0);
    assert_eq!(
        std::fs::read(q("brushed-steel")).unwrap(),
        before["frying-pan"].0
    );
    for m in ["frying-pan", "painted-metal"] {
        assert_eq!(stamp(m), before[m], "{m} was rewritten");
    }
    // Nothing changed: nothing runs.
    let out = w.bake(&["run", "pipelines/materials.ron", "--json"]);
    assert_eq!(statuses(&out)["quaternions"], "up-to-date");

    // A new material is baked alone; a removed one's output goes; a reverted one comes back
    // from the cache without baking.
    copy_tree(&mats.join("painted-metal"), &mats.join("wok"));
    std::fs::remove_dir_all(mats.join("painted-metal")).unwrap();
    std::fs::copy(
        root().join("pipelines/materials/brushed-steel/normal.png"),
        mats.join("brushed-steel/normal.png"),
    )
    .unwrap();
    let text = stdout(&w.bake(&["plan", "pipelines/materials.ron"]));
    assert!(
        text.contains("1 removed (painted-metal/quaternion.png)"),
        "{text}"
    );
    let third = run("status");
    assert_eq!(third["wok/quaternion.png"], "ran", "{third:?}");
    assert_eq!(
        third["brushed-steel/quaternion.png"], "restored",
        "{third:?}"
    );
    assert_eq!(
        third["frying-pan/quaternion.png"], "up-to-date",
        "{third:?}"
    );
    assert_eq!(count(&third, "ran"), 1, "{third:?}");
    assert!(!q("painted-metal").exists());
    assert_eq!(std::fs::read(q("wok")).unwrap(), before["painted-metal"].0);
    assert_eq!(stamp("brushed-steel").0, before["brushed-steel"].0);
    assert_eq!(stamp("frying-pan"), before["frying-pan"]);
}

#[cfg(unix)]
#[test]
fn symlinked_material_folders_are_followed_and_loops_refused() {
    let w = Work::new();
    w.copy("pipelines/materials/frying-pan");
    std::fs::create_dir_all(w.path("mats")).unwrap();
    std::os::unix::fs::symlink(w.path("pipelines/materials/frying-pan"), w.path("mats/pan"))
        .unwrap();
    w.write(
        "m.ron",
        r#"(output: "out", inputs: {"mats": Folder("mats")}, stages: [
            (id: "q", kind: "quat-map", reads: ["mats"], params: (bits: 8)),
        ])"#,
    );
    let st = w.run_ok("m.ron", &[]);
    assert_eq!(st["q"], "ran");
    assert!(w.path("out/q/pan/quaternion.png").is_file());
    std::os::unix::fs::symlink(w.path("mats"), w.path("mats/pan/loop")).unwrap_or(());
    std::os::unix::fs::symlink(w.path("mats"), w.path("mats/loop")).unwrap();
    let o = w.bake(&["run", "m.ron"]);
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success(), "{e}");
    assert!(e.contains("symbolic link loop"), "{e}");
}

#[test]
fn a_prefilter_warning_shows_once_in_bake_run_and_once_in_the_cli() {
    // Both front-ends come from the one `Bake` definition: the same warnings, each once
    // (pipeline runs used to repeat the chain's warnings and report the report's note as one).
    let w = Work::new();
    std::fs::copy(root().join("fixtures/hdri/studio_256.exr"), w.path("a.exr")).unwrap();
    w.write(
        "up.ron",
        r#"(output: "out", inputs: {"a": File("a.exr")}, stages: [
            (id: "chain", kind: "prefilter", reads: ["a"], params: (size: 128, levels: 2, quality: draft)),
        ])"#,
    );
    let upsampled = "level 0 is upsampled";
    let out = w.bake(&["run", "up.ron"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let run = stderr(&out);
    assert_eq!(run.matches(upsampled).count(), 1, "bake run:\n{run}");
    assert!(run.contains("less than size 128"), "in RON terms:\n{run}");

    let bin_dir = build_clis(&["prefilter"]).unwrap_or_else(|e| panic!("{e}"));
    let out = Command::new(bin_dir.join("prefilter"))
        .args(["a.exr", "-o", "cli", "--size", "128", "--levels", "2"])
        .args(["--quality", "draft"])
        .current_dir(w.path(""))
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", stderr(&out));
    let cli = stderr(&out);
    assert_eq!(cli.matches(upsampled).count(), 1, "prefilter:\n{cli}");
    assert!(
        cli.contains("less than --size 128"),
        "in flag terms:\n{cli}"
    );
}
