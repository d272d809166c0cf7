//! Atomic writes: every output goes to a temporary file beside its target, is flushed to
//! disk, then renamed into place, so a failed or interrupted bake leaves the previous file.

use crate::error::{Error, Result};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

static COUNTER: AtomicU64 = AtomicU64::new(0);

/// The temporary path used for `target`: hidden, in the same directory (same file system,
/// so the rename is atomic), unique per process and call.
fn temp_path(target: &Path) -> PathBuf {
    let name = target
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let k = COUNTER.fetch_add(1, Ordering::Relaxed);
    target.with_file_name(format!(".{name}.tmp-{}-{k}", std::process::id()))
}

/// Writes `bytes` to a flushed temporary file beside `path` (creating parent directories) and
/// returns the temporary path; nothing is left behind on error.
fn stage(path: &Path, bytes: &[u8]) -> Result<PathBuf> {
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    }
    let tmp = temp_path(path);
    let result = (|| -> std::io::Result<()> {
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(bytes)?;
        f.sync_data()?;
        Ok(())
    })();
    match result {
        Ok(()) => Ok(tmp),
        Err(e) => {
            let _ = std::fs::remove_file(&tmp);
            Err(Error::io(path, e))
        }
    }
}

/// Renames a staged file into place (removing it if the rename fails).
fn commit(tmp: &Path, path: &Path) -> Result<()> {
    std::fs::rename(tmp, path).map_err(|e| {
        let _ = std::fs::remove_file(tmp);
        Error::io(path, e)
    })
}

/// Writes `bytes` to `path` atomically, creating parent directories.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    let tmp = stage(path, bytes)?;
    commit(&tmp, path)
}

/// Writes several encoded files as one set: every file is first written and flushed to a
/// temporary beside its target, and only when all of them are on disk (and no target is a
/// directory a rename would fail on) are they renamed into place. A full disk, an unwritable
/// folder or a bad target therefore leaves every previous file as it was; only an interruption
/// during the final renames (microseconds) can leave the set mixed.
pub fn write_many_atomic(files: &[(PathBuf, Vec<u8>)]) -> Result<()> {
    let mut staged: Vec<(PathBuf, &Path)> = Vec::with_capacity(files.len());
    let discard = |staged: &[(PathBuf, &Path)]| {
        for (tmp, _) in staged {
            let _ = std::fs::remove_file(tmp);
        }
    };
    for (path, bytes) in files {
        let blocked = std::fs::symlink_metadata(path).is_ok_and(|m| m.is_dir());
        if blocked {
            discard(&staged);
            return Err(Error::io(
                path,
                std::io::Error::new(
                    std::io::ErrorKind::IsADirectory,
                    "a directory is in the way of this output",
                ),
            ));
        }
        match stage(path, bytes) {
            Ok(tmp) => staged.push((tmp, path)),
            Err(e) => {
                discard(&staged);
                return Err(e);
            }
        }
    }
    for (i, (tmp, path)) in staged.iter().enumerate() {
        if let Err(e) = commit(tmp, path) {
            discard(&staged[i + 1..]);
            return Err(e);
        }
    }
    Ok(())
}

/// The name prefix of a write probe: `.ibl-write-probe-<pid>-<n>`.
const PROBE: &str = ".ibl-write-probe-";

/// Removes the write probes in `dir` whose process is gone (a kill between the probe's
/// creation and its removal leaves one). Only where `/proc` says which processes live.
fn remove_dead_probes(dir: &Path) {
    if !Path::new("/proc/self").exists() {
        return;
    }
    let Ok(rd) = std::fs::read_dir(dir) else {
        return;
    };
    for e in rd.flatten() {
        let name = e.file_name();
        let Some(rest) = name.to_str().and_then(|n| n.strip_prefix(PROBE)) else {
            continue;
        };
        let pid = rest.split('-').next().unwrap_or("");
        let dead = !pid.is_empty()
            && pid.bytes().all(|b| b.is_ascii_digit())
            && !Path::new("/proc").join(pid).exists();
        // Only an empty regular file is a probe: nothing of a user's is removed.
        let probe =
            e.file_type().is_ok_and(|t| t.is_file()) && e.metadata().is_ok_and(|m| m.len() == 0);
        if dead && probe {
            let _ = std::fs::remove_file(e.path());
        }
    }
}

/// What `-o` names: a folder the bake writes its files into, or one output file.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum OutputKind {
    /// `-o` is a folder the bake writes several files into.
    Folder,
    /// `-o` is the one output file.
    File,
}

/// Checks, before any input is read, that a bake will be able to write where its output goes:
/// a bake of minutes must not end in "File exists" or "Permission denied". Refuses an
/// existing file where a folder is needed (and the reverse), a file in the way of a folder
/// to be created, and a folder that cannot be written; each message says what to do.
pub fn check_output(path: &std::path::Path, kind: OutputKind) -> Result<()> {
    let shown = path.display();
    match (kind, std::fs::metadata(path)) {
        (OutputKind::Folder, Ok(m)) if !m.is_dir() => {
            return Err(Error::invalid(
                path,
                format!(
                    "the output must be a folder, but {shown} is an existing file (a file in the \
                     way): choose another name or remove the file"
                ),
            ))
        }
        (OutputKind::File, Ok(m)) if m.is_dir() => {
            return Err(Error::invalid(
                path,
                format!(
                "the output must be a file, but {shown} is an existing folder: give a file name \
                     such as {}",
                path.join("out.exr").display()
            ),
            ))
        }
        _ => {}
    }
    // The folder the files will be created in: `path` itself or its parent. Its nearest
    // existing ancestor must be a folder (a file in the way cannot become one) and writable.
    let dir = match kind {
        OutputKind::Folder => path.to_path_buf(),
        OutputKind::File => match path.parent() {
            Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
            _ => std::path::PathBuf::from("."),
        },
    };
    let mut existing = dir.as_path();
    while std::fs::symlink_metadata(existing).is_err() {
        match existing.parent() {
            Some(p) if !p.as_os_str().is_empty() => existing = p,
            _ => {
                existing = std::path::Path::new(".");
                break;
            }
        }
    }
    // The same class (exit 2) and words whether `-o file` or `-o file/sub` meets the file.
    if !existing.is_dir() {
        return Err(Error::invalid(
            path,
            format!(
                "the output must be a folder, but {} is an existing file (a file in the way): \
                 choose another name or remove the file",
                existing.display()
            ),
        ));
    }
    // Writability as the writes will see it (permissions, read-only mounts, ACLs): create
    // and remove a probe file.
    // The probe is unique per call; a probe a killed process left (its pid gone) is removed.
    remove_dead_probes(existing);
    let k = COUNTER.fetch_add(1, Ordering::Relaxed);
    let probe = existing.join(format!("{PROBE}{}-{k}", std::process::id()));
    match std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(&probe)
    {
        Ok(_) => {
            let _ = std::fs::remove_file(&probe);
            Ok(())
        }
        Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => Ok(()),
        Err(e) => Err(Error::io(
            path,
            std::io::Error::new(
                e.kind(),
                format!(
                    "cannot write into {} ({e}): choose a writable output",
                    existing.display()
                ),
            ),
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn writes_and_replaces_without_leftovers() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("sub/out.bin");
        write_atomic(&p, b"one").unwrap();
        write_atomic(&p, b"two").unwrap();
        assert_eq!(std::fs::read(&p).unwrap(), b"two");
        let names: Vec<_> = std::fs::read_dir(p.parent().unwrap())
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(names.len(), 1, "{names:?}");
    }

    #[test]
    fn a_set_with_one_blocked_target_changes_none_of_the_previous_files() {
        let dir = tempfile::tempdir().unwrap();
        let names = ["a.bin", "b.bin", "c.bin"];
        let set = |tag: &[u8]| -> Vec<(PathBuf, Vec<u8>)> {
            names
                .iter()
                .map(|n| (dir.path().join(n), tag.to_vec()))
                .collect()
        };
        write_many_atomic(&set(b"old")).unwrap();
        // The last target becomes a directory: the set must fail before any rename.
        std::fs::remove_file(dir.path().join("c.bin")).unwrap();
        std::fs::create_dir(dir.path().join("c.bin")).unwrap();
        assert!(write_many_atomic(&set(b"new")).is_err());
        for n in &names[..2] {
            assert_eq!(std::fs::read(dir.path().join(n)).unwrap(), b"old", "{n}");
        }
        // No temporaries are left: a.bin, b.bin and the directory c.bin.
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 3);
        // A target folder that cannot be created fails at staging, also without renames.
        std::fs::write(dir.path().join("file"), b"x").unwrap();
        let mut bad = set(b"new");
        bad.push((dir.path().join("file/sub/d.bin"), b"new".to_vec()));
        assert!(write_many_atomic(&bad).is_err());
        for n in &names[..2] {
            assert_eq!(std::fs::read(dir.path().join(n)).unwrap(), b"old", "{n}");
        }
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 4);
    }

    #[test]
    fn unwritable_target_is_an_error_and_keeps_nothing() {
        let dir = tempfile::tempdir().unwrap();
        // A directory where the file should go.
        let p = dir.path().join("taken");
        std::fs::create_dir(&p).unwrap();
        assert!(write_atomic(&p, b"x").is_err());
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
    }
}
