//! Test support shared by the workspace's tests: running a tool binary (the usual
//! `input -o out flags…` argv spelt once, here) and checking its one-line errors, file trees
//! (copy, list), JSON output, and the thread-count determinism check the parallel bakes' unit
//! tests make. A dev-dependency only; it depends on no crate of the workspace so that every
//! crate, ibl-core included, can use it without a cycle.

#![warn(missing_docs)]

use std::ffi::{OsStr, OsString};
use std::fmt::Debug;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// The workspace root (where `Cargo.toml`, `fixtures/` and `pipelines/` are).
pub fn workspace_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// A file or folder under the workspace's `fixtures/`, e.g. `fixture("hdri/city_512.exr")`.
pub fn fixture(rel: &str) -> PathBuf {
    workspace_root().join("fixtures").join(rel)
}

/// One of the workspace's tool binaries, as a test crate sees it:
/// `const BIN: Bin = Bin::new(env!("CARGO_BIN_EXE_prefilter"), "prefilter");`
#[derive(Clone, Copy, Debug)]
pub struct Bin {
    /// Path of the executable cargo built for the test (`CARGO_BIN_EXE_<name>`).
    pub path: &'static str,
    /// The tool's name, which starts each of its error lines (`<name>: error: ...`).
    pub name: &'static str,
}

impl Bin {
    /// The binary at `path`, whose messages start with `name`.
    pub const fn new(path: &'static str, name: &'static str) -> Self {
        Bin { path, name }
    }

    /// A command for the binary, to add arguments, a folder or environment to.
    pub fn cmd(&self) -> Command {
        Command::new(self.path)
    }

    /// Runs the binary with `args` and waits for it.
    pub fn run(&self, args: &[&str]) -> Output {
        self.exec(args)
    }

    /// Runs the binary and asserts it succeeded (the failure message shows its stderr).
    pub fn run_ok(&self, args: &[&str]) -> Output {
        self.exec_ok(args)
    }

    /// Runs the binary and asserts it refused: exit `code`, one stderr line starting with
    /// `<name>: error: ` and containing `needle`, no panic. Returns that line.
    pub fn refused(&self, args: &[&str], code: i32, needle: &str) -> String {
        self.exec_refused(args, code, needle)
    }

    /// Runs the usual bake, `input -o out flags…` (see [`bake_args`]), and waits for it;
    /// nothing is asserted. `input` may also be a subcommand (`"dfg"`).
    pub fn run_bake(
        &self,
        input: impl AsRef<OsStr>,
        out: impl AsRef<OsStr>,
        flags: &[&str],
    ) -> Output {
        self.exec(&bake_args(input, out, flags))
    }

    /// Issue 22: bakes `input` for every target × layout (8² faces) and checks that each run
    /// writes a `LOAD.txt` for its target naming only files that run wrote
    /// ([`assert_note_names_only_existing_files`]).
    pub fn assert_every_target_writes_a_true_note(&self, input: &Path) {
        let tmp = tempfile::tempdir().unwrap();
        let layouts: [&[&str]; 5] = [
            &[],
            &["--layout", "faces", "--format", "rgba16f"],
            &["--layout", "ktx2", "--format", "rgba16f"],
            &["--layout", "dds", "--format", "rgba16f"],
            &["--layout", "ktx1", "--format", "rgba16f"],
        ];
        for t in [
            "gltf", "bevy", "filament", "three", "babylon", "unity", "custom",
        ] {
            for (k, layout) in layouts.iter().enumerate() {
                let out = tmp.path().join(format!("{t}-{k}"));
                let mut flags = vec!["--target", t, "--size", "8", "-q"];
                flags.extend_from_slice(layout);
                let o = self.run_bake(input, &out, &flags);
                assert!(
                    o.status.success(),
                    "{t} {layout:?}: {}",
                    String::from_utf8_lossy(&o.stderr)
                );
                let note = assert_note_names_only_existing_files(&out);
                assert!(note.contains(&format!("--target {t}")), "{note}");
            }
        }
    }

    /// [`Bin::run_bake`], asserting it succeeded as [`Bin::run_ok`] does.
    pub fn bake(&self, input: impl AsRef<OsStr>, out: impl AsRef<OsStr>, flags: &[&str]) -> Output {
        self.exec_ok(&bake_args(input, out, flags))
    }

    /// [`Bin::run_bake`], asserting it refused as [`Bin::refused`] does; returns the line.
    pub fn refused_bake(
        &self,
        input: impl AsRef<OsStr>,
        out: impl AsRef<OsStr>,
        flags: &[&str],
        code: i32,
        needle: &str,
    ) -> String {
        self.exec_refused(&bake_args(input, out, flags), code, needle)
    }

    /// Runs a tool that reads no input (a table or map generator) as `-o out flags…` (see
    /// [`generate_args`]) and waits for it; nothing is asserted.
    pub fn run_generate(&self, out: impl AsRef<OsStr>, flags: &[&str]) -> Output {
        self.exec(&generate_args(out, flags))
    }

    /// [`Bin::run_generate`], asserting it succeeded as [`Bin::run_ok`] does.
    pub fn generate(&self, out: impl AsRef<OsStr>, flags: &[&str]) -> Output {
        self.exec_ok(&generate_args(out, flags))
    }

    /// [`Bin::run_generate`], asserting it refused as [`Bin::refused`] does; returns the line.
    pub fn refused_generate(
        &self,
        out: impl AsRef<OsStr>,
        flags: &[&str],
        code: i32,
        needle: &str,
    ) -> String {
        self.exec_refused(&generate_args(out, flags), code, needle)
    }

    fn exec<S: AsRef<OsStr>>(&self, args: &[S]) -> Output {
        self.cmd()
            .args(args)
            .output()
            .unwrap_or_else(|e| panic!("{} does not start: {e}", self.path))
    }

    fn exec_ok<S: AsRef<OsStr> + Debug>(&self, args: &[S]) -> Output {
        let out = self.exec(args);
        assert!(
            out.status.success(),
            "{} {args:?} failed ({:?}): {}",
            self.name,
            out.status.code(),
            stderr(&out)
        );
        out
    }

    fn exec_refused<S: AsRef<OsStr> + Debug>(&self, args: &[S], code: i32, needle: &str) -> String {
        let out = self.exec(args);
        let line = assert_one_line_error(&out, code, needle);
        let prefix = format!("{}: error: ", self.name);
        assert!(line.starts_with(&prefix), "{args:?}: {line}");
        eprintln!("{args:?} -> {line}");
        line
    }
}

/// The argv the workspace's tools share, `input -o out flags…`: one leading positional (an
/// input file or folder, or a subcommand), the output, then the flags as given. Paths pass
/// through as `OsStr`, so a call site needs no `.to_str().unwrap()`.
pub fn bake_args(
    input: impl AsRef<OsStr>,
    out: impl AsRef<OsStr>,
    flags: &[&str],
) -> Vec<OsString> {
    let mut argv = vec![input.as_ref().to_owned()];
    argv.extend(generate_args(out, flags));
    argv
}

/// The argv of a tool that reads no input, `-o out flags…`.
pub fn generate_args(out: impl AsRef<OsStr>, flags: &[&str]) -> Vec<OsString> {
    let mut argv = vec![OsString::from("-o"), out.as_ref().to_owned()];
    argv.extend(flags.iter().map(OsString::from));
    argv
}

/// The process's stderr, lossily decoded.
pub fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// The process's stdout, lossily decoded.
pub fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// Asserts the process failed with exit `code` and exactly one stderr line containing
/// `needle` (and no panic); returns the line.
pub fn assert_one_line_error(out: &Output, code: i32, needle: &str) -> String {
    let err = stderr(out);
    assert_eq!(out.status.code(), Some(code), "{err}");
    assert_eq!(err.trim().lines().count(), 1, "not one line: {err}");
    assert!(err.contains(needle), "{needle:?} not in: {err}");
    assert!(!err.contains("panicked"), "{err}");
    err.trim().to_string()
}

/// Parses the process's stdout as JSON (the `--json` outputs).
pub fn stdout_json(o: &Output) -> serde_json::Value {
    serde_json::from_slice(&o.stdout)
        .unwrap_or_else(|e| panic!("stdout is not JSON ({e}): {}", stdout(o)))
}

/// Reads and parses a JSON file (reports, sidecars).
pub fn read_json(path: &Path) -> serde_json::Value {
    let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    serde_json::from_slice(&bytes).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// Copies a file, or a folder and everything under it, creating `to`'s parents.
pub fn copy_tree(from: &Path, to: &Path) {
    if from.is_dir() {
        for e in std::fs::read_dir(from).unwrap() {
            let e = e.unwrap();
            copy_tree(&e.path(), &to.join(e.file_name()));
        }
    } else {
        std::fs::create_dir_all(to.parent().unwrap()).unwrap();
        std::fs::copy(from, to)
            .unwrap_or_else(|e| panic!("{} -> {}: {e}", from.display(), to.display()));
    }
}

/// Checks the how-to-load note `dir/LOAD.txt` (issue 22): it exists, and every file name it
/// mentions (a word ending in an extension our tools write) is a file in `dir`. Independent of
/// the note's own parser. Returns the note.
pub fn assert_note_names_only_existing_files(dir: &Path) -> String {
    const EXT: [&str; 11] = [
        "ktx2", "ktx", "dds", "exr", "hdr", "png", "json", "ron", "txt", "env", "pfm",
    ];
    let note = std::fs::read_to_string(dir.join("LOAD.txt"))
        .unwrap_or_else(|e| panic!("{}/LOAD.txt: {e}", dir.display()));
    let present = files_in(dir);
    for word in note.split(|c: char| c.is_whitespace() || "\"'`(),;:<>[]{}/=".contains(c)) {
        let w = word.trim_end_matches('.');
        let Some((stem, ext)) = w.rsplit_once('.') else {
            continue;
        };
        if stem.is_empty() || !EXT.contains(&ext.to_ascii_lowercase().as_str()) {
            continue;
        }
        assert!(
            present.iter().any(|f| f == w),
            "{}: the note names {w}, which this run did not write (files: {present:?})\n{note}",
            dir.display()
        );
    }
    note
}

/// The record of what a CLI wrote (`ibl_core::ownership`): [`files_in`] leaves it out, since
/// it is in every output folder; `crates/bake/tests/hostile.rs` checks it.
pub const OWNERSHIP_RECORD: &str = ".ibl-outputs.json";

/// Names of the entries of `dir` but the ownership record, sorted; empty when `dir` does not
/// exist.
pub fn files_in(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .map(|r| {
            r.map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
                .filter(|n| n != OWNERSHIP_RECORD)
                .collect()
        })
        .unwrap_or_default();
    v.sort();
    v
}

/// Every file under `dir` as a path relative to it, sorted; entries whose relative path is in
/// `skip` (e.g. `.bake`) are left out with everything under them.
pub fn files_under(dir: &Path, skip: &[&str]) -> Vec<String> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        let Ok(rd) = std::fs::read_dir(&d) else {
            continue;
        };
        for e in rd.flatten() {
            let p = e.path();
            let rel = p.strip_prefix(dir).unwrap().to_string_lossy().into_owned();
            if skip.contains(&rel.as_str()) {
                continue;
            }
            if p.is_dir() {
                stack.push(p);
            } else {
                out.push(rel);
            }
        }
    }
    out.sort();
    out
}

/// Runs `f` in a rayon pool of each of `threads` and asserts every result is bit-identical to
/// the first, which it returns. Results are compared by their `Debug` text: Rust prints a
/// float as the shortest decimal that reads back to the same bits, so equal text means equal
/// bits (−0.0 and 0.0 differ, where `==` would let them pass).
pub fn thread_count_independent<T, F>(threads: &[usize], f: F) -> T
where
    T: Debug + Send,
    F: Fn() -> T + Sync,
{
    assert!(!threads.is_empty(), "no thread count given");
    let mut first: Option<(usize, T, String)> = None;
    for &n in threads {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build()
            .unwrap();
        let r = pool.install(&f);
        let text = format!("{r:?}");
        match &first {
            None => first = Some((n, r, text)),
            Some((n0, _, t0)) => {
                assert!(*t0 == text, "results differ between {n0} and {n} threads");
            }
        }
    }
    first.unwrap().1
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn thread_count_independence_is_bit_exact() {
        // A sum whose order depends on the split would differ; a fixed order does not.
        let xs: Vec<f64> = (0..10_000)
            .map(|i| (i as f64 * 0.37).sin() * 1e-3 + 1e7)
            .collect();
        let s = thread_count_independent(&[1, 2, 3], || xs.iter().sum::<f64>());
        assert_eq!(s, xs.iter().sum::<f64>());
        // −0.0 == 0.0, but not bit for bit: caught.
        let flip = std::sync::atomic::AtomicBool::new(false);
        let r = std::panic::catch_unwind(|| {
            thread_count_independent(&[1, 2], || {
                if flip.fetch_xor(true, std::sync::atomic::Ordering::SeqCst) {
                    -0.0f32
                } else {
                    0.0f32
                }
            })
        });
        assert!(r.is_err());
    }

    #[test]
    fn trees_are_copied_and_listed() {
        let d = tempfile_dir("trees");
        std::fs::create_dir_all(d.join("a/b")).unwrap();
        std::fs::write(d.join("a/b/x.txt"), "x").unwrap();
        std::fs::write(d.join("a/y.txt"), "y").unwrap();
        std::fs::create_dir_all(d.join("a/.bake")).unwrap();
        std::fs::write(d.join("a/.bake/j"), "j").unwrap();
        copy_tree(&d.join("a"), &d.join("c"));
        assert_eq!(files_under(&d.join("c"), &[".bake"]), ["b/x.txt", "y.txt"]);
        assert_eq!(
            files_under(&d.join("c"), &[]),
            [".bake/j", "b/x.txt", "y.txt"]
        );
        assert_eq!(files_in(&d.join("c")), [".bake", "b", "y.txt"]);
        assert!(files_in(&d.join("missing")).is_empty());
        std::fs::remove_dir_all(&d).unwrap();
    }

    /// A fresh folder under the target's temporary directory (no tempfile dependency here).
    /// `tag` keeps the tests, which run in parallel, out of each other's folders.
    fn tempfile_dir(tag: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("ibl-testkit-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    #[test]
    fn one_line_errors_are_checked() {
        let out = Command::new("sh")
            .args(["-c", "echo 'tool: error: x.exr: bad' >&2; exit 2"])
            .output()
            .unwrap();
        assert_eq!(
            assert_one_line_error(&out, 2, "x.exr"),
            "tool: error: x.exr: bad"
        );
        let two = Command::new("sh")
            .args(["-c", "printf 'a\\nb\\n' >&2; exit 2"])
            .output()
            .unwrap();
        assert!(std::panic::catch_unwind(|| assert_one_line_error(&two, 2, "a")).is_err());
    }

    #[test]
    fn bake_argv_is_input_output_then_flags_with_paths_untouched() {
        assert_eq!(
            bake_args("in.exr", Path::new("out dir"), &["--size", "8"]),
            ["in.exr", "-o", "out dir", "--size", "8"]
        );
        assert_eq!(generate_args("t.png", &[]), ["-o", "t.png"]);
        // A path that is not UTF-8 reaches the tool byte for byte.
        #[cfg(unix)]
        {
            use std::os::unix::ffi::OsStrExt;
            let odd = OsStr::from_bytes(b"caf\xe9.exr");
            assert_eq!(bake_args(odd, "o", &[])[0], odd);
        }
    }

    /// The bake calls on a stand-in tool: a shell script (the "input" of `sh script -o …`)
    /// that echoes its arguments, or refuses the way the workspace's tools do.
    #[cfg(unix)]
    #[test]
    fn bake_calls_pass_the_argv_and_check_the_outcome() {
        let d = tempfile_dir("bake");
        let ok = d.join("ok.sh");
        std::fs::write(&ok, "echo \"$*\"").unwrap();
        let no = d.join("no.sh");
        std::fs::write(&no, "echo \"tool: error: $2: bad $3\" >&2; exit 2").unwrap();
        let sh = Bin::new("sh", "tool");
        let out = sh.bake(&ok, d.join("o.exr"), &["--size", "8"]);
        let want = format!("-o {} --size 8\n", d.join("o.exr").display());
        assert_eq!(stdout(&out), want);
        assert_eq!(
            sh.refused_bake(&no, "o.exr", &["--levels"], 2, "o.exr"),
            "tool: error: o.exr: bad --levels"
        );
        assert_eq!(sh.run_bake(&no, "o.exr", &[]).status.code(), Some(2));
        assert!(std::panic::catch_unwind(|| sh.bake(&no, "o.exr", &[])).is_err());
        assert!(std::panic::catch_unwind(|| sh.refused_bake(&ok, "o", &[], 2, "")).is_err());
        std::fs::remove_dir_all(&d).unwrap();
    }
}
