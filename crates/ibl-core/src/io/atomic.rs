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
    // Every target is checked before anything is written.
    for (path, _) in files {
        if std::fs::symlink_metadata(path).is_ok_and(|m| m.is_dir()) {
            return Err(Error::io(
                path,
                std::io::Error::new(
                    std::io::ErrorKind::IsADirectory,
                    "a directory is in the way of this output",
                ),
            ));
        }
    }
    let staged = stage_all(files);
    if staged.iter().any(|r| !matches!(r, Some(Ok(_)))) {
        // Nothing is renamed: every staged temporary goes, and the first failure in the
        // set's order is reported, whichever thread met it.
        let mut first = None;
        for r in staged {
            match r {
                Some(Ok(tmp)) => {
                    let _ = std::fs::remove_file(tmp);
                }
                Some(Err(e)) => {
                    first.get_or_insert(e);
                }
                None => {}
            }
        }
        return Err(first.unwrap_or_else(|| {
            Error::io(
                &files[0].0,
                std::io::Error::other("the set was not written"),
            )
        }));
    }
    let staged: Vec<PathBuf> = staged.into_iter().flatten().flatten().collect();
    for (i, (tmp, (path, _))) in staged.iter().zip(files).enumerate() {
        if let Err(e) = commit(tmp, path) {
            for tmp in &staged[i + 1..] {
                let _ = std::fs::remove_file(tmp);
            }
            return Err(e);
        }
    }
    Ok(())
}

/// Threads that stage a set's files at once: writing and flushing are waits on the disk
/// (`fdatasync` per file), which overlap; the bake's CPU work is done by then.
const STAGE_THREADS: usize = 4;

/// Stages every file of a set ([`stage`]), on up to [`STAGE_THREADS`] threads; each slot is
/// the file's temporary path, its error, or `None` where a failure elsewhere stopped the set
/// before this file was begun.
fn stage_all(files: &[(PathBuf, Vec<u8>)]) -> Vec<Option<Result<PathBuf>>> {
    use std::sync::atomic::{AtomicBool, AtomicUsize};
    use std::sync::Mutex;
    let slots: Vec<Mutex<Option<Result<PathBuf>>>> =
        files.iter().map(|_| Mutex::new(None)).collect();
    let (next, failed) = (AtomicUsize::new(0), AtomicBool::new(false));
    let work = || {
        while !failed.load(Ordering::Relaxed) {
            let i = next.fetch_add(1, Ordering::Relaxed);
            let Some((path, bytes)) = files.get(i) else {
                break;
            };
            let r = stage(path, bytes);
            if r.is_err() {
                failed.store(true, Ordering::Relaxed);
            }
            *slots[i].lock().unwrap_or_else(|p| p.into_inner()) = Some(r);
        }
    };
    std::thread::scope(|s| {
        // Helpers where the system grants them; this thread works too, so a refused spawn
        // only costs the overlap.
        for _ in 1..STAGE_THREADS.min(files.len()) {
            let _ = std::thread::Builder::new().spawn_scoped(s, work);
        }
        work();
    });
    slots
        .into_iter()
        .map(|m| m.into_inner().unwrap_or_else(|p| p.into_inner()))
        .collect()
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
    fn a_set_staged_on_several_threads_lands_whole_or_not_at_all() {
        let dir = tempfile::tempdir().unwrap();
        let set = |tag: &str| -> Vec<(PathBuf, Vec<u8>)> {
            (0..3 * STAGE_THREADS)
                .map(|k| {
                    (
                        dir.path().join(format!("f{k}.bin")),
                        format!("{tag}{k}").into_bytes(),
                    )
                })
                .collect()
        };
        // Every file gets its own bytes, whichever thread staged it.
        write_many_atomic(&set("old")).unwrap();
        for (path, bytes) in set("old") {
            assert_eq!(std::fs::read(&path).unwrap(), bytes);
        }
        // A file in the middle of the set fails at staging (its folder cannot be created):
        // the error names where, nothing is renamed, no temporary is left.
        std::fs::write(dir.path().join("plain"), b"x").unwrap();
        let mut bad = set("new");
        let blocked = dir.path().join("plain/sub/g.bin");
        bad.insert(STAGE_THREADS + 1, (blocked, b"new".to_vec()));
        let err = write_many_atomic(&bad).unwrap_err().to_string();
        assert!(err.contains("plain/sub"), "{err}");
        for (path, bytes) in set("old") {
            assert_eq!(std::fs::read(&path).unwrap(), bytes);
        }
        assert_eq!(
            std::fs::read_dir(dir.path()).unwrap().count(),
            3 * STAGE_THREADS + 1
        );
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
