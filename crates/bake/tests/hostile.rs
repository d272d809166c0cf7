//! The hostile-input suite of ownership: decoys beside outputs (a user's files named like ours,
//! hand-edited outputs, symlinks leading out of the output folder) for every bake CLI and for
//! `bake run` / `bake clean`, each case asserting the exit code, the one-line message and that
//! every decoy survives byte for byte. The CLIs are the workspace's release binaries beside
//! `bake` (`make test` builds them all).

use ibl_testkit::{assert_one_line_error, fixture, stderr, stdout_json};
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// A tool binary built beside `bake`.
fn tool(name: &str) -> PathBuf {
    let p = Path::new(env!("CARGO_BIN_EXE_bake"))
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

fn run(bin: &Path, args: &[&str], cwd: &Path) -> Output {
    Command::new(bin)
        .args(args)
        .current_dir(cwd)
        .output()
        .unwrap()
}

/// A first run of `bin` with `args` and `--json`, which must succeed.
fn run_json_ok(bin: &Path, name: &str, args: &[String], cwd: &Path) -> Output {
    let mut argv: Vec<&str> = args.iter().map(String::as_str).collect();
    argv.push("--json");
    let o = run(bin, &argv, cwd);
    assert!(o.status.success(), "{name}: {}", stderr(&o));
    o
}

/// Every bake CLI with a small run writing into `OUT` (a folder or, for single-file tools, a
/// file in it); `OUT` is replaced by the output path.
fn clis() -> Vec<(&'static str, Vec<String>)> {
    let h = fixture("hdri/studio_256.hdr").display().to_string();
    let n = fixture("normals/0008_128.png").display().to_string();
    let v = |a: &[&str]| a.iter().map(|s| s.to_string()).collect::<Vec<_>>();
    vec![
        ("equirect-to-cube", v(&[&h, "-o", "OUT", "--size", "8"])),
        (
            "prefilter",
            v(&[&h, "-o", "OUT", "--size", "8", "--levels", "2"]),
        ),
        ("irradiance", v(&[&h, "-o", "OUT", "--size", "8"])),
        (
            "hv-lut",
            v(&[
                "-o",
                "OUT/hv.exr",
                "--nu",
                "10",
                "--nv",
                "10",
                "--size",
                "8",
            ]),
        ),
        (
            "brdf-lut",
            v(&["dfg", "-o", "OUT/dfg.exr", "--size", "8", "--samples", "16"]),
        ),
        (
            "tpr-map",
            v(&["-o", "OUT/tpr.png", "--size", "16x24", "--preset", "wave"]),
        ),
        ("quat-map", v(&[&n, "-o", "OUT/q.png"])),
    ]
}

fn args_for(args: &[String], out: &Path) -> Vec<String> {
    args.iter()
        .map(|a| a.replace("OUT", &out.display().to_string()))
        .collect()
}

/// Every file under `dir` with its bytes (the record and the outputs included).
fn snapshot(dir: &Path) -> Vec<(String, Vec<u8>)> {
    ibl_testkit::files_under(dir, &[])
        .into_iter()
        .map(|rel| {
            let b = std::fs::read(dir.join(&rel)).unwrap();
            (rel, b)
        })
        .collect()
}

#[test]
fn every_cli_refuses_to_replace_a_users_file_and_keeps_its_own_record() {
    let tmp = tempfile::tempdir().unwrap();
    for (name, args) in clis() {
        let bin = tool(name);
        let first = tmp.path().join(format!("{name}-first"));
        let a = args_for(&args, &first);
        let o = run_json_ok(&bin, name, &a, tmp.path());
        let outputs: Vec<PathBuf> = stdout_json(&o)["outputs"]
            .as_array()
            .unwrap()
            .iter()
            .map(|p| PathBuf::from(p.as_str().unwrap()))
            .collect();
        assert!(!outputs.is_empty(), "{name}");
        let record = outputs[0].parent().unwrap().join(".ibl-outputs.json");
        assert!(record.is_file(), "{name}: no record beside its outputs");
        // A second run over its own unchanged outputs is fine.
        let argv: Vec<&str> = a.iter().map(String::as_str).collect();
        assert!(run(&bin, &argv, tmp.path()).status.success(), "{name}");

        // Decoys: the user's own files named like each output, in a fresh folder.
        let out = tmp.path().join(format!("{name}-decoys"));
        let map = |p: &Path| out.join(p.strip_prefix(&first).unwrap());
        for p in &outputs {
            let d = map(p);
            std::fs::create_dir_all(d.parent().unwrap()).unwrap();
            std::fs::write(&d, format!("{name}: the user's own notes\n")).unwrap();
        }
        let before = snapshot(&out);
        let a = args_for(&args, &out);
        let argv: Vec<&str> = a.iter().map(String::as_str).collect();
        let o = run(&bin, &argv, tmp.path());
        let line = assert_one_line_error(&o, 2, "--overwrite");
        assert!(line.starts_with(&format!("{name}: error: ")), "{line}");
        assert!(line.contains("was not written by this tool"), "{line}");
        assert_eq!(snapshot(&out), before, "{name}: a decoy changed");

        // A hand-edited output of its own: refused too, with what changed.
        let edited = &outputs[0];
        let mut bytes = std::fs::read(edited).unwrap();
        bytes.extend_from_slice(b"hand edit");
        std::fs::write(edited, &bytes).unwrap();
        let a = args_for(&args, &first);
        let argv: Vec<&str> = a.iter().map(String::as_str).collect();
        let o = run(&bin, &argv, tmp.path());
        assert_one_line_error(&o, 2, "changed since this tool wrote it");
        assert_eq!(std::fs::read(edited).unwrap(), bytes, "{name}");
        // --overwrite is the user saying so.
        let o = run(&bin, &[&argv[..], &["--overwrite"]].concat(), tmp.path());
        assert!(o.status.success(), "{name}: {}", stderr(&o));
        assert_ne!(std::fs::read(edited).unwrap(), bytes, "{name}");
    }
}

#[cfg(unix)]
#[test]
fn no_cli_writes_through_a_symlink_or_outside_its_output() {
    let tmp = tempfile::tempdir().unwrap();
    let elsewhere = tmp.path().join("elsewhere");
    std::fs::create_dir_all(&elsewhere).unwrap();
    let precious = elsewhere.join("precious.txt");
    std::fs::write(&precious, b"keep me").unwrap();
    for (name, args) in clis() {
        let bin = tool(name);
        // An output file that is a symlink to a file outside: refused, even with --overwrite.
        let first = tmp.path().join(format!("{name}-first-link"));
        let a = args_for(&args, &first);
        let o = run_json_ok(&bin, name, &a, tmp.path());
        let out0 = PathBuf::from(stdout_json(&o)["outputs"][0].as_str().unwrap());
        std::fs::remove_file(&out0).unwrap();
        std::os::unix::fs::symlink(&precious, &out0).unwrap();
        let argv: Vec<&str> = a.iter().map(String::as_str).collect();
        for extra in [&[][..], &["--overwrite"][..]] {
            let o = run(&bin, &[&argv[..], extra].concat(), tmp.path());
            assert_one_line_error(&o, 2, "is a symlink");
        }
        assert_eq!(std::fs::read(&precious).unwrap(), b"keep me", "{name}");
    }
    // A file-name flag leading out of -o, and outputs at the root or a system folder.
    let irr = tool("irradiance");
    let h = fixture("hdri/studio_256.hdr");
    let o = run(
        &irr,
        &[
            h.to_str().unwrap(),
            "-o",
            "irr",
            "--size",
            "8",
            "--sh-file",
            "../x.json",
        ],
        tmp.path(),
    );
    assert_one_line_error(&o, 2, "outside the output folder");
    assert!(!tmp.path().join("x.json").exists());
    for root in ["/", "/etc", "/usr/lib/ibl", "/proc/self"] {
        let o = run(
            &irr,
            &[h.to_str().unwrap(), "-o", root, "--size", "8"],
            tmp.path(),
        );
        assert_one_line_error(&o, 2, "resolves to");
    }
}

#[test]
fn a_stale_layout_cleanup_removes_only_its_own_unchanged_files() {
    let tmp = tempfile::tempdir().unwrap();
    let bin = tool("equirect-to-cube");
    let h = fixture("hdri/studio_256.hdr");
    let out = tmp.path().join("cube");
    let bake = |layout: &str| {
        run(
            &bin,
            &[
                h.to_str().unwrap(),
                "-o",
                out.to_str().unwrap(),
                "--size",
                "8",
                "--layout",
                layout,
            ],
            tmp.path(),
        )
    };
    // The user's files named like other layouts' outputs.
    std::fs::create_dir_all(&out).unwrap();
    for decoy in ["cube.dds", "cube.ktx", "cube.encoding.json"] {
        std::fs::write(out.join(decoy), format!("user's {decoy}")).unwrap();
    }
    assert!(bake("ktx2").status.success());
    // Faces now: our own KTX2 goes (bytes unchanged), the user's files stay with a warning.
    let o = bake("faces");
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(!out.join("cube.ktx2").exists(), "our own stale container");
    for decoy in ["cube.dds", "cube.ktx", "cube.encoding.json"] {
        assert_eq!(
            std::fs::read_to_string(out.join(decoy)).unwrap(),
            format!("user's {decoy}")
        );
        assert!(stderr(&o).contains(&format!("left {}", out.join(decoy).display())));
    }
    // A face edited by hand is not removed when the layout changes back.
    let px = out.join("px.exr");
    let mut b = std::fs::read(&px).unwrap();
    b.extend_from_slice(b"edit");
    std::fs::write(&px, &b).unwrap();
    let o = bake("ktx2");
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(std::fs::read(&px).unwrap(), b);
    assert!(!out.join("nx.exr").exists() || stderr(&o).contains("left"));
}

/// A pipeline writing `cube` (faces) into `scratch` and a `dfg` stage, output `.`: planned
/// from its own folder.
fn pipeline(dir: &Path) -> PathBuf {
    std::fs::copy(fixture("hdri/studio_256.hdr"), dir.join("sky.hdr")).unwrap();
    let p = dir.join("p.ron");
    std::fs::write(
        &p,
        r#"(output: ".", inputs: {"sky": File("sky.hdr")}, stages: [
            (id: "cube", kind: "equirect-to-cube", reads: ["sky"], out: "scratch", params: (size: 8)),
            (id: "dfg", kind: "dfg", params: (size: 8, samples: 16)),
        ])"#,
    )
    .unwrap();
    p
}

#[test]
fn bake_run_and_clean_never_touch_what_is_not_theirs() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let p = pipeline(d);
    let bake = tool("bake");
    // A user's file where a stage writes: refused before any stage runs, named.
    std::fs::create_dir_all(d.join("scratch")).unwrap();
    std::fs::write(d.join("scratch/px.exr"), b"user's px").unwrap();
    let o = run(&bake, &["run", "p.ron", "-q"], d);
    let line = assert_one_line_error(&o, 2, "scratch/px.exr");
    assert!(
        line.contains("--overwrite") && line.contains("stage 'cube'"),
        "{line}"
    );
    assert_eq!(
        std::fs::read(d.join("scratch/px.exr")).unwrap(),
        b"user's px"
    );
    assert!(!d.join("dfg").exists(), "nothing ran");
    std::fs::remove_file(d.join("scratch/px.exr")).unwrap();
    // `.` means the pipeline's folder from anywhere: run from another folder.
    let o = run(&bake, &["run", p.to_str().unwrap(), "-q"], Path::new("/"));
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(d.join("scratch/px.exr").is_file() && d.join("dfg/dfg.exr").is_file());
    // A hand-edited output: `run` refuses to replace it, `clean` keeps it and says so.
    let nx = d.join("scratch/nx.exr");
    let mut edited = std::fs::read(&nx).unwrap();
    edited.extend_from_slice(b"hand edit");
    std::fs::write(&nx, &edited).unwrap();
    let o = run(&bake, &["run", "p.ron", "-q"], d);
    assert_one_line_error(&o, 2, "scratch/nx.exr");
    assert_eq!(std::fs::read(&nx).unwrap(), edited);
    // Bit rot that keeps size and modification time: `bake verify` hashes and finds it.
    let o = run(&bake, &["verify", "p.ron", "--json"], d);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    let v = stdout_json(&o);
    assert_eq!(v["damaged"].as_array().unwrap().len(), 1, "{v}");
    let py = d.join("dfg/dfg.exr");
    let f = std::fs::File::options().write(true).open(&py).unwrap();
    let mtime = f.metadata().unwrap().modified().unwrap();
    let mut b = std::fs::read(&py).unwrap();
    let k = b.len() - 1;
    b[k] ^= 0x40;
    std::fs::write(&py, &b).unwrap();
    f.set_modified(mtime).unwrap();
    drop(f);
    let o = run(&bake, &["verify", "p.ron", "--json"], d);
    let v = stdout_json(&o);
    let damaged: Vec<&str> = v["damaged"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x["path"].as_str().unwrap())
        .collect();
    assert_eq!(damaged.len(), 2, "{v}");
    assert!(damaged.iter().any(|p| p.ends_with("dfg.exr")), "{v}");
    // A decoy beside the outputs and a user's file in the output folder.
    std::fs::write(d.join("scratch/notes.txt"), b"notes").unwrap();
    let o = run(&bake, &["clean", "p.ron"], d);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("kept") && stderr(&o).contains("nx.exr"),
        "{}",
        stderr(&o)
    );
    assert_eq!(std::fs::read(&nx).unwrap(), edited);
    assert_eq!(
        std::fs::read(d.join("scratch/notes.txt")).unwrap(),
        b"notes"
    );
    assert!(!d.join("scratch/px.exr").exists());
    // The rotted dfg.exr is not ours any more either (clean hashes): kept and reported.
    assert_eq!(std::fs::read(&py).unwrap(), b);
    assert!(d.join("p.ron").is_file() && d.join("sky.hdr").is_file());
}

#[cfg(unix)]
#[test]
fn bake_run_and_clean_do_not_follow_a_symlink_out_of_the_output() {
    let tmp = tempfile::tempdir().unwrap();
    let (work, elsewhere) = (tmp.path().join("work"), tmp.path().join("elsewhere"));
    std::fs::create_dir_all(&work).unwrap();
    std::fs::create_dir_all(&elsewhere).unwrap();
    pipeline(&work);
    let bake = tool("bake");
    std::fs::write(elsewhere.join("dfg.exr"), b"precious").unwrap();
    std::os::unix::fs::symlink(&elsewhere, work.join("dfg")).unwrap();
    for extra in [&[][..], &["--overwrite"][..]] {
        let o = run(&bake, &[&["run", "p.ron", "-q"][..], extra].concat(), &work);
        assert_one_line_error(&o, 2, "symlink");
    }
    assert_eq!(
        std::fs::read(elsewhere.join("dfg.exr")).unwrap(),
        b"precious"
    );
    // Built without the link, then the link put back: clean leaves the outside file alone.
    std::fs::remove_file(work.join("dfg")).unwrap();
    assert!(run(&bake, &["run", "p.ron", "-q"], &work).status.success());
    std::fs::remove_dir_all(work.join("dfg")).unwrap();
    std::os::unix::fs::symlink(&elsewhere, work.join("dfg")).unwrap();
    let o = run(&bake, &["clean", "p.ron"], &work);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(
        std::fs::read(elsewhere.join("dfg.exr")).unwrap(),
        b"precious"
    );
    // An output at the filesystem root or a system folder is refused before anything.
    for (out, why) in [("/", "a filesystem root"), ("/etc", "a system folder")] {
        let text = std::fs::read_to_string(work.join("p.ron"))
            .unwrap()
            .replace("output: \".\"", &format!("output: \"{out}\""));
        std::fs::write(work.join("q.ron"), text).unwrap();
        let o = run(&bake, &["run", "q.ron", "-q"], &work);
        assert_one_line_error(&o, 2, why);
    }
}

#[test]
fn bake_takes_the_memory_budget_of_every_tool() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    pipeline(d);
    let bake = tool("bake");
    // studio_256.hdr decodes to 256×128 RGB f32 (384 KiB): a 64 KiB budget refuses it before
    // decoding, naming the budget; the default budget bakes it.
    let o = run(&bake, &["run", "p.ron", "-q", "--max-memory", "64K"], d);
    assert!(!o.status.success());
    let err = stderr(&o);
    assert!(
        err.contains("budget") && err.contains("--max-memory"),
        "{err}"
    );
    assert!(
        !d.join("scratch/px.exr").exists(),
        "nothing of the cube written"
    );
    let o = run(&bake, &["run", "p.ron", "-q", "--max-memory", "1G"], d);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(d.join("scratch/px.exr").is_file());
    let o = run(&bake, &["run", "p.ron", "--max-memory", "lots"], d);
    assert_one_line_error(&o, 2, "not a size");
}

#[test]
fn a_pipelines_max_memory_is_its_budget_and_the_flag_wins() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    pipeline(d);
    std::fs::write(d.join("notes.txt"), b"mine").unwrap();
    let with = |budget: &str| {
        std::fs::read_to_string(d.join("p.ron")).unwrap().replacen(
            "(output: \".\",",
            &format!("(output: \".\", max_memory: {budget},"),
            1,
        )
    };
    std::fs::write(d.join("m.ron"), with("\"64K\"")).unwrap();
    let bake = tool("bake");
    // The file's 64 KiB budget refuses the 384 KiB sky before decoding it, naming the budget.
    let o = run(&bake, &["run", "m.ron", "-q"], d);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    let err = stderr(&o);
    let lines: Vec<&str> = err.lines().filter(|l| l.contains("error")).collect();
    assert_eq!(lines.len(), 1, "one error line: {err}");
    assert!(
        lines[0].contains("stage 'cube'")
            && lines[0].contains("over the memory budget of 65 kB")
            && lines[0].contains("sky.hdr"),
        "{err}"
    );
    assert!(!d.join("scratch/px.exr").exists(), "nothing of the cube");
    // The command line's budget wins over the file's.
    let o = run(&bake, &["run", "m.ron", "-q", "--max-memory", "1G"], d);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(d.join("scratch/px.exr").is_file());
    // A number of bytes is a size too; nonsense is refused at its place in the file.
    std::fs::write(d.join("n.ron"), with("65536")).unwrap();
    let o = run(&bake, &["run", "n.ron", "-q", "--force"], d);
    assert!(
        stderr(&o).contains("over the memory budget of 65 kB"),
        "{}",
        stderr(&o)
    );
    std::fs::write(d.join("bad.ron"), with("\"lots\"")).unwrap();
    let o = run(&bake, &["plan", "bad.ron"], d);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    let err = stderr(&o);
    assert!(
        err.lines().next().unwrap().contains("bad.ron:1:")
            && err.contains("max_memory: 'lots' is not a size"),
        "{err}"
    );
    assert_eq!(std::fs::read(d.join("notes.txt")).unwrap(), b"mine");
}
