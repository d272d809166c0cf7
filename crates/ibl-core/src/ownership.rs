//! Never touch what is not ours: where outputs may go (no filesystem root, no system folder, no
//! symlink out of the output folder, every file-name flag inside `-o`), and the record a tool
//! keeps beside its outputs (`.ibl-outputs.json`: each file it wrote and the blake3 hash of
//! the bytes it wrote), so that it replaces or removes only files it wrote whose bytes are
//! unchanged since, and refuses up front, naming the file, when anything else is in the way.

use crate::error::{Error, Result};
use std::collections::BTreeMap;
use std::path::{Component, Path, PathBuf};

/// The record's file name, in the folder the outputs are written into.
pub const RECORD: &str = ".ibl-outputs.json";

/// The flag that lets a tool replace files it did not write (or that changed since).
pub const OVERWRITE_FLAG: &str = "--overwrite";

/// The blake3 hash of `bytes`, in hex (the runner's manifest uses the same).
pub fn hash_bytes(bytes: &[u8]) -> String {
    blake3::hash(bytes).to_hex().to_string()
}

/// The blake3 hash of a file's bytes, streamed (no allocation of the file's size).
pub fn hash_file(path: &Path) -> std::io::Result<String> {
    let mut h = blake3::Hasher::new();
    h.update_reader(std::fs::File::open(path)?)?;
    Ok(h.finalize().to_hex().to_string())
}

/// Removes `.` and resolves `..` lexically (`pipelines/../out` → `out`); a `..` above the root
/// stays at the root, a leading `..` of a relative path is kept. The runner's paths use it too.
pub fn normalize(p: &Path) -> PathBuf {
    let mut out: Vec<Component> = Vec::new();
    for c in p.components() {
        match c {
            Component::CurDir => {}
            Component::ParentDir => match out.last() {
                Some(Component::Normal(_)) => {
                    out.pop();
                }
                Some(Component::RootDir) | Some(Component::Prefix(_)) => {}
                _ => out.push(c),
            },
            c => out.push(c),
        }
    }
    if out.is_empty() {
        return PathBuf::from(".");
    }
    out.iter().collect()
}

/// `p` as the file system will see it: absolute, its longest existing prefix with every
/// symlink resolved (`canonicalize`), the rest appended. `.` and `..` therefore mean the same
/// from any working folder, and a symlinked folder is seen where it points.
pub fn resolve(p: &Path) -> PathBuf {
    let abs = normalize(&std::path::absolute(p).unwrap_or_else(|_| p.to_path_buf()));
    let mut existing = abs.as_path();
    let mut rest: Vec<&std::ffi::OsStr> = Vec::new();
    loop {
        if let Ok(c) = std::fs::canonicalize(existing) {
            let mut out = c;
            for r in rest.iter().rev() {
                out.push(r);
            }
            return out;
        }
        match (existing.parent(), existing.file_name()) {
            (Some(parent), Some(name)) => {
                rest.push(name);
                existing = parent;
            }
            _ => return abs,
        }
    }
}

/// `p` as the operating system walks it when the file is opened: like [`resolve`], except that
/// a `..` is taken *after* the symlinks before it (`out/link/..` is the parent of where `link`
/// points, not `out`), which is what `open(2)` does with a path that is not normalized.
fn resolve_walked(p: &Path) -> PathBuf {
    // `Path::parent` of a bare file name is the empty path, which is the working folder
    // (`std::path::absolute` refuses the empty path).
    let p = if p.as_os_str().is_empty() {
        Path::new(".")
    } else {
        p
    };
    let abs = std::path::absolute(p).unwrap_or_else(|_| p.to_path_buf());
    let comps: Vec<Component> = abs.components().collect();
    for n in (1..=comps.len()).rev() {
        let prefix: PathBuf = comps[..n].iter().collect();
        if let Ok(mut out) = std::fs::canonicalize(&prefix) {
            // The rest does not exist yet: its folders will be created as real folders.
            out.extend(&comps[n..]);
            return normalize(&out);
        }
    }
    normalize(&abs)
}

/// Folders no bake writes into, nor anywhere under them.
const SYSTEM_TREES: &[&str] = &[
    "/bin", "/boot", "/dev", "/etc", "/lib", "/lib32", "/lib64", "/libx32", "/proc", "/sbin",
    "/sys", "/usr", "/run",
];
/// Folders no bake writes into directly (their subfolders may be a user's: `/tmp/x`,
/// `/home/me/out`).
const SYSTEM_FOLDERS: &[&str] = &[
    "/",
    "/home",
    "/mnt",
    "/media",
    "/opt",
    "/root",
    "/srv",
    "/tmp",
    "/var",
    "/var/tmp",
    "/var/lib",
    "/var/log",
    "/Users",
    "/System",
    "/Library",
    "/Applications",
];

/// Refuses an output folder at a filesystem root, in or under a system folder, or (for a
/// `folder` of outputs, where a stale-file cleanup or a `clean` would reach the user's files)
/// `/tmp`, `/home`, `/var` and the like themselves or the home folder itself; a single named
/// file (`-o ~/dfg.png`) may go there. `what` names the flag or key (`-o`, `output`).
pub fn check_output_folder(dir: &Path, what: &str, folder: bool) -> Result<()> {
    let r = resolve(dir);
    let home = std::env::var_os("HOME")
        .filter(|h| !h.is_empty())
        .map(|h| resolve(Path::new(&h)));
    let refuse = |why: &str| {
        Err(Error::invalid(
            dir,
            format!(
                "{what} resolves to {}, {why}: outputs go into a folder of their own (e.g. {})",
                r.display(),
                dir.join("ibl-out").display()
            ),
        ))
    };
    if r.parent().is_none() {
        return refuse("a filesystem root");
    }
    if SYSTEM_TREES.iter().any(|s| r.starts_with(s))
        || (folder && SYSTEM_FOLDERS.iter().any(|s| r == Path::new(s)))
    {
        return refuse("a system folder");
    }
    if folder && home.as_deref() == Some(r.as_path()) {
        return refuse("the home folder itself");
    }
    Ok(())
}

/// Checks that `file` lies inside `dir` both as written (`--sh-file ../x.json` does not) and
/// as the file system resolves it (no symlinked folder leads out of `dir`), and that `file`
/// itself is not a symlink or a folder. `what` names the output for the message.
pub fn check_inside(file: &Path, dir: &Path) -> Result<()> {
    let rd = resolve(dir);
    let lexical = normalize(&std::path::absolute(file).unwrap_or_else(|_| file.to_path_buf()));
    let lexical_dir = normalize(&std::path::absolute(dir).unwrap_or_else(|_| dir.to_path_buf()));
    if !lexical.starts_with(&lexical_dir) || lexical == lexical_dir {
        return Err(Error::invalid(
            file,
            format!(
                "is outside the output folder {}: every output and file-name flag stays inside it",
                dir.display()
            ),
        ));
    }
    if file.file_name().is_none() {
        return Err(Error::invalid(
            file,
            "does not end in a file name: an output is a file inside the output folder",
        ));
    }
    // The folder the file goes into, resolved: a symlink on the way must stay inside, both
    // for the path normalized and as the system walks the path as given (`link/../x.json`
    // goes where `link` points, then up).
    let parent_resolved = resolve(lexical.parent().unwrap_or(Path::new("/")));
    let walked = resolve_walked(file.parent().unwrap_or(Path::new("/")));
    let parent_resolved = if parent_resolved.starts_with(&rd) {
        walked
    } else {
        parent_resolved
    };
    if !parent_resolved.starts_with(&rd) {
        return Err(Error::invalid(
            file,
            format!(
                "leads out of the output folder {} through a symlink (to {}): remove the link or \
                 choose another output",
                dir.display(),
                parent_resolved.display()
            ),
        ));
    }
    match std::fs::symlink_metadata(file) {
        Ok(m) if m.file_type().is_symlink() => Err(Error::invalid(
            file,
            "is a symlink: a bake replaces only regular files it wrote (remove the link, or \
             choose another output)",
        )),
        Ok(m) if m.is_dir() => Err(Error::invalid(
            file,
            "is a folder in the way of an output: move it or choose another output",
        )),
        _ => Ok(()),
    }
}

/// What a tool wrote into one folder: file name (relative to the folder) → blake3 of the bytes.
#[derive(Clone, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct Record {
    /// The tools that wrote into this folder (the last one first), for a reader's information.
    #[serde(default)]
    pub tools: Vec<String>,
    /// Each file written: its name relative to the folder and the hash of its bytes.
    #[serde(default)]
    pub files: BTreeMap<String, String>,
}

impl Record {
    /// The record of `dir`; none yet is an empty record. A record that cannot be read or
    /// parsed is empty too: nothing is then known to be ours, so nothing is replaced.
    pub fn load(dir: &Path) -> Record {
        let path = dir.join(RECORD);
        let Ok(m) = std::fs::symlink_metadata(&path) else {
            return Record::default();
        };
        // A record is a few hundred bytes a file; a huge or linked one is not ours.
        if !m.is_file() || m.len() > 64 << 20 {
            return Record::default();
        }
        std::fs::read(&path)
            .ok()
            .and_then(|b| serde_json::from_slice(&b).ok())
            .unwrap_or_default()
    }

    /// The name `file` has in the record of `dir`.
    fn key(dir: &Path, file: &Path) -> Option<String> {
        let (d, f) = (
            normalize(&std::path::absolute(dir).ok()?),
            normalize(&std::path::absolute(file).ok()?),
        );
        Some(f.strip_prefix(&d).ok()?.to_string_lossy().into_owned())
    }

    /// Whether `file` (in `dir`) is ours: recorded, a regular file, and its bytes the ones
    /// recorded.
    pub fn owns(&self, dir: &Path, file: &Path) -> bool {
        let Some(want) = Record::key(dir, file).and_then(|k| self.files.get(&k)) else {
            return false;
        };
        let regular = std::fs::symlink_metadata(file).is_ok_and(|m| m.is_file());
        regular && hash_file(file).is_ok_and(|h| &h == want)
    }

    /// Records `files` (path, bytes written) under `tool`.
    pub fn add(&mut self, dir: &Path, tool: &str, files: &[(PathBuf, Vec<u8>)]) {
        for (p, bytes) in files {
            if let Some(k) = Record::key(dir, p) {
                self.files.insert(k, hash_bytes(bytes));
            }
        }
        self.tools.retain(|t| t != tool);
        self.tools.insert(0, tool.to_string());
    }

    /// Forgets `file`.
    pub fn remove(&mut self, dir: &Path, file: &Path) {
        if let Some(k) = Record::key(dir, file) {
            self.files.remove(&k);
        }
    }

    /// Writes the record into `dir` atomically (replacing only a regular file or nothing).
    pub fn save(&self, dir: &Path) -> Result<()> {
        let path = dir.join(RECORD);
        if std::fs::symlink_metadata(&path).is_ok_and(|m| !m.is_file()) {
            return Err(Error::invalid(
                &path,
                "is not a regular file: the record of what was written cannot go there",
            ));
        }
        let bytes = serde_json::to_vec_pretty(self).expect("record serialises");
        crate::io::write_atomic(&path, &bytes)
    }
}

/// Checks, before any work, that every file of `files` may be written into `dir`: inside it
/// ([`check_inside`]), and either absent or a file the record says this folder's tools wrote,
/// bytes unchanged. Anything else is refused, naming the file and how to proceed, unless
/// `overwrite` (the user said so: [`OVERWRITE_FLAG`]); even then a file outside `dir` or a
/// symlink is refused.
pub fn check_writes(dir: &Path, files: &[PathBuf], overwrite: bool) -> Result<()> {
    let record = Record::load(dir);
    for f in files {
        check_inside(f, dir)?;
        if overwrite || std::fs::symlink_metadata(f).is_err() || record.owns(dir, f) {
            continue;
        }
        let why = if Record::key(dir, f).is_some_and(|k| record.files.contains_key(&k)) {
            "changed since this tool wrote it"
        } else {
            "was not written by this tool"
        };
        return Err(Error::invalid(
            f,
            format!(
                "exists and {why} ({} in its folder has no matching entry): move it away, or \
                 pass {OVERWRITE_FLAG} to replace it",
                RECORD
            ),
        ));
    }
    Ok(())
}

/// Splits stale candidates into the files that are ours to remove (recorded, bytes unchanged,
/// inside `dir`) and the others, which are left alone and reported.
pub fn split_owned(dir: &Path, candidates: Vec<PathBuf>) -> (Vec<PathBuf>, Vec<PathBuf>) {
    let record = Record::load(dir);
    candidates
        .into_iter()
        .partition(|p| check_inside(p, dir).is_ok() && record.owns(dir, p))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn system_folders_and_roots_are_refused() {
        for bad in [
            "/",
            "/etc",
            "/usr/share/x",
            "/tmp",
            "/var",
            "/proc/self",
            "/tmp/..",
        ] {
            let e = check_output_folder(Path::new(bad), "-o", true).unwrap_err();
            assert!(e.to_string().contains("-o resolves to"), "{bad}: {e}");
        }
        let dir = tempfile::tempdir().unwrap();
        check_output_folder(&dir.path().join("out"), "-o", true).unwrap();
        check_output_folder(Path::new("/tmp"), "-o", false).unwrap();
        assert!(check_output_folder(Path::new("/etc"), "-o", false).is_err());
    }

    #[test]
    fn a_bare_file_names_folder_is_the_working_folder() {
        // `Path::new("n.png").parent()` is the empty path: `-o n.png` writes into the working
        // folder, which must not read as a link leading to "." (quat-map's e2e caught it).
        let cwd = std::fs::canonicalize(std::env::current_dir().unwrap()).unwrap();
        assert_eq!(resolve_walked(Path::new("")), cwd);
        assert_eq!(resolve_walked(Path::new(".")), cwd);
    }

    #[test]
    fn files_stay_inside_and_links_do_not_lead_out() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("out");
        let elsewhere = dir.path().join("elsewhere");
        std::fs::create_dir_all(&out).unwrap();
        std::fs::create_dir_all(&elsewhere).unwrap();
        check_inside(&out.join("a/b.exr"), &out).unwrap();
        let e = check_inside(&out.join("../x.json"), &out).unwrap_err();
        assert!(e.to_string().contains("outside the output folder"), "{e}");
        #[cfg(unix)]
        {
            std::os::unix::fs::symlink(&elsewhere, out.join("dfg")).unwrap();
            let e = check_inside(&out.join("dfg/lut.png"), &out).unwrap_err();
            assert!(e.to_string().contains("through a symlink"), "{e}");
            std::fs::write(elsewhere.join("f"), b"x").unwrap();
            std::os::unix::fs::symlink(elsewhere.join("f"), out.join("px.exr")).unwrap();
            let e = check_inside(&out.join("px.exr"), &out).unwrap_err();
            assert!(e.to_string().contains("is a symlink"), "{e}");
            // `..` after a link is taken where the link points (found while writing the
            // `ownership` fuzz target): `out/deep/../sh.json` is `elsewhere/sh.json` to open(2).
            std::fs::create_dir_all(elsewhere.join("deep")).unwrap();
            std::os::unix::fs::symlink(elsewhere.join("deep"), out.join("deep")).unwrap();
            let e = check_inside(&out.join("deep/../sh.json"), &out).unwrap_err();
            assert!(e.to_string().contains("through a symlink"), "{e}");
            // Without a link on the way, `..` inside the folder is fine.
            std::fs::create_dir_all(out.join("sub")).unwrap();
            check_inside(&out.join("sub/../sh.json"), &out).unwrap();
            check_inside(&out.join("new/../sh.json"), &out).unwrap();
            let e = check_inside(&out.join("sub/x/.."), &out).unwrap_err();
            assert!(e.to_string().contains("file name"), "{e}");
        }
    }

    #[test]
    fn only_recorded_unchanged_files_are_ours() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        let (a, b) = (d.join("a.exr"), d.join("b.exr"));
        std::fs::write(&a, b"mine").unwrap();
        std::fs::write(&b, b"users").unwrap();
        let mut r = Record::default();
        r.add(d, "t", &[(a.clone(), b"mine".to_vec())]);
        r.save(d).unwrap();
        check_writes(d, &[a.clone(), d.join("new.exr")], false).unwrap();
        let e = check_writes(d, std::slice::from_ref(&b), false)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("was not written by this tool") && e.contains("--overwrite"),
            "{e}"
        );
        check_writes(d, std::slice::from_ref(&b), true).unwrap();
        std::fs::write(&a, b"edited").unwrap();
        let e = check_writes(d, std::slice::from_ref(&a), false)
            .unwrap_err()
            .to_string();
        assert!(e.contains("changed since"), "{e}");
        let (ours, not) = split_owned(d, vec![a.clone(), b.clone()]);
        assert!(ours.is_empty() && not.len() == 2);
        std::fs::write(&a, b"mine").unwrap();
        let (ours, not) = split_owned(d, vec![a.clone(), b.clone()]);
        assert_eq!((ours, not), (vec![a], vec![b]));
    }
}
