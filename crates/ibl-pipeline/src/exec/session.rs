//! A session: exclusive use of an output folder for one run. It holds the folder's lock, rolls
//! forward the commits a killed run left (their journals), owns the staging folder, and on
//! Ctrl-C / SIGTERM waits for the commit in flight, removes its staging folder and lock, and
//! exits: an interrupted run leaves only complete outputs.

use crate::cache::{CacheDir, StageRecord};
use crate::error::{Error, Result};
use crate::paths;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Condvar, Mutex, MutexGuard, RwLock, RwLockReadGuard};

/// A commit in flight, written before the renames so that a killed run can be rolled forward.
#[derive(Serialize, Deserialize)]
pub(crate) struct Journal {
    /// The stage committed.
    pub id: String,
    /// Its record, entered in the manifest once the renames are done.
    pub record: StageRecord,
    /// (staged file, its place in the stage folder).
    pub renames: Vec<(PathBuf, PathBuf)>,
}

/// What a session shares with its interrupt watcher.
struct Shared {
    /// Taken (shared) by every thread writing under the output folder (staging files,
    /// committing, saving the manifest); the watcher takes it exclusively on an interrupt, so
    /// it waits for writes in flight and no new one starts between its clean-up and the exit.
    gate: RwLock<()>,
    /// Serialises commits (journal, renames, manifest) between workers.
    commit: Mutex<()>,
    /// What an interrupt removes: the staging folder and the lock file.
    cleanup: [PathBuf; 2],
    /// Set (under the signal's lock, so the watcher cannot miss it) when the session ends.
    closed: AtomicBool,
}

/// Exclusive use of an output folder: the lock, recovery of killed runs, the staging folder.
pub struct Session {
    /// The output folder's `.bake/` paths.
    pub cache: CacheDir,
    tmp: PathBuf,
    lock: Option<std::fs::File>,
    shared: Arc<Shared>,
    watcher: Option<std::thread::JoinHandle<()>>,
}

impl Session {
    /// Locks `graph`'s output folder, rolls forward commits a killed run left, clears stale
    /// staging files, and arranges for Ctrl-C / SIGTERM to leave no partial outputs.
    pub fn open(graph: &crate::graph::Graph) -> Result<Session> {
        Session::open_output(&graph.pipeline.output)
    }

    /// [`Session::open`] for an output folder.
    pub fn open_output(output: &Path) -> Result<Session> {
        // Before anything is baked: an `output:` that is a file, lies under a file or cannot
        // be written is said now, with what to do, not as "File exists" after the work.
        crate::owned::check_output_folder(output)?;
        ibl_core::io::check_output(output, ibl_core::io::OutputKind::Folder)?;
        let cache = CacheDir::new(output);
        std::fs::create_dir_all(&cache.root).map_err(|e| Error::io(&cache.root, e))?;
        let lock = take_lock(&cache.lock_path())?;
        let tmp_root = cache.tmp();
        let tmp = tmp_root.join(std::process::id().to_string());
        let shared = Arc::new(Shared {
            gate: RwLock::new(()),
            commit: Mutex::new(()),
            cleanup: [tmp.clone(), cache.lock_path()],
            closed: AtomicBool::new(false),
        });
        let watcher = watch_interrupts(shared.clone());
        let session = Session {
            cache,
            tmp,
            lock: Some(lock),
            shared,
            watcher: Some(watcher),
        };
        // Journals name staged files of the killed run: roll them forward before clearing.
        session.recover()?;
        let _ = std::fs::remove_dir_all(&tmp_root);
        Ok(session)
    }

    /// Permission to write under the output folder (see [`Shared::gate`]).
    pub(crate) fn gate(&self) -> RwLockReadGuard<'_, ()> {
        self.shared.gate.read().unwrap_or_else(|e| e.into_inner())
    }

    /// Permission to commit: the gate, then the commit lock.
    pub(crate) fn commit_lock(&self) -> (RwLockReadGuard<'_, ()>, MutexGuard<'_, ()>) {
        let g = self.gate();
        let c = self.shared.commit.lock().unwrap_or_else(|e| e.into_inner());
        (g, c)
    }

    /// The staging folder of stage `i`.
    pub(crate) fn staging_dir(&self, i: usize, id: &str) -> PathBuf {
        self.tmp.join(format!("{i}-{}", paths::slug(id)))
    }

    /// Rolls forward every journal: finishes its renames and records its stage.
    fn recover(&self) -> Result<()> {
        let Ok(rd) = std::fs::read_dir(self.cache.journal()) else {
            return Ok(());
        };
        let mut manifest = self.cache.load_manifest()?;
        let mut any = false;
        for e in rd.flatten() {
            let path = e.path();
            let Ok(j) = std::fs::read(&path)
                .map_err(|_| ())
                .and_then(|b| serde_json::from_slice::<Journal>(&b).map_err(|_| ()))
            else {
                let _ = std::fs::remove_file(&path);
                continue;
            };
            // A damaged journal (or one naming files outside this output folder's staging
            // and stage folders) is dropped: its stage is rebuilt, nothing else is touched.
            let (output, root) = (&self.cache.output, &self.cache.root);
            let sound = j.record.is_sound()
                && j.renames.iter().all(|(staged, target)| {
                    paths::is_within(staged, &self.cache.tmp())
                        && paths::is_within(target, output)
                        && !paths::is_within(target, root)
                        && ibl_core::ownership::check_inside(target, output).is_ok()
                });
            if !sound {
                let _ = std::fs::remove_file(&path);
                continue;
            }
            for (staged, target) in &j.renames {
                if staged.exists() {
                    if let Some(d) = target.parent() {
                        std::fs::create_dir_all(d).map_err(|e| Error::io(d, e))?;
                    }
                    std::fs::rename(staged, target).map_err(|e| Error::io(target, e))?;
                }
            }
            let dir = self.cache.output.join(&j.record.dir);
            let _ = self.cache.put(&j.record.key, &dir, &j.record.outputs);
            manifest.apply(&self.cache.output, &j.id, j.record);
            any = true;
            let _ = std::fs::remove_file(&path);
        }
        if any {
            self.cache.save_manifest(&manifest)?;
        }
        Ok(())
    }
}

impl Drop for Session {
    fn drop(&mut self) {
        {
            let _st = INTERRUPTS.state.lock().unwrap_or_else(|e| e.into_inner());
            self.shared.closed.store(true, Ordering::SeqCst);
        }
        INTERRUPTS.wake.notify_all();
        if let Some(w) = self.watcher.take() {
            let _ = w.join();
        }
        let lock = self.lock.take();
        let _guard = self.commit_lock();
        let _ = std::fs::remove_dir_all(&self.tmp);
        let _ = std::fs::remove_dir(self.cache.tmp());
        let _ = std::fs::remove_dir(self.cache.journal());
        if let Some(f) = lock {
            release_lock(&self.cache.lock_path(), f);
        }
    }
}

/// Takes the lock at `path`: an exclusive OS file lock (flock / LockFileEx) on the file, held
/// for the session; the file also records our pid for the message others get.
///
/// Why an OS lock and not a pid file: the kernel releases it when the process dies, however it
/// dies, so there is no stale lock to take over and no race between two runs taking over the
/// same stale lock (with pid files, both could delete it and both proceed). Unlinking on exit
/// is safe because a taker that opened the old file checks, once locked, that the path still
/// names the file it locked, and starts again if not.
fn take_lock(path: &Path) -> Result<std::fs::File> {
    use std::fs::TryLockError;
    use std::io::{Read, Seek, Write};
    for _ in 0..8 {
        let mut f = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(false)
            .open(path)
            .map_err(|e| Error::io(path, e))?;
        match f.try_lock() {
            Ok(()) => {}
            Err(TryLockError::WouldBlock) => {
                let mut text = String::new();
                let _ = f.read_to_string(&mut text);
                let who = match text.trim().parse::<u32>() {
                    Ok(pid) => format!("pid {pid}"),
                    Err(_) => "starting".into(),
                };
                return Err(Error::Busy {
                    path: path.to_path_buf(),
                    why: format!("another bake ({who}) is using this output folder"),
                });
            }
            Err(TryLockError::Error(e)) => {
                return Err(Error::io(
                    path,
                    std::io::Error::new(
                        e.kind(),
                        format!("cannot lock (does this file system support locks?): {e}"),
                    ),
                ))
            }
        }
        if !same_file(&f, path) {
            // Unlinked (and maybe re-created) by its last holder after we opened it.
            continue;
        }
        let written = f
            .set_len(0)
            .and_then(|_| f.rewind())
            .and_then(|_| f.write_all(std::process::id().to_string().as_bytes()));
        written.map_err(|e| Error::io(path, e))?;
        return Ok(f);
    }
    Err(Error::Busy {
        path: path.to_path_buf(),
        why: "could not take the lock (it kept being replaced)".into(),
    })
}

/// Whether `path` still names the file `f` has open.
fn same_file(f: &std::fs::File, path: &Path) -> bool {
    let (Ok(a), Ok(b)) = (f.metadata(), std::fs::metadata(path)) else {
        return false;
    };
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        a.dev() == b.dev() && a.ino() == b.ino()
    }
    #[cfg(not(unix))]
    {
        // Windows refuses to delete a file another handle has open without sharing it, so
        // the path cannot have been replaced under us.
        let _ = (a, b);
        true
    }
}

/// Releases the lock at `path` held through `f`: unlinks the file while still holding it,
/// then closes it.
fn release_lock(path: &Path, f: std::fs::File) {
    let _ = std::fs::remove_file(path);
    drop(f);
}

/// The process's interrupt signal, as the sessions' watchers see it: whether Ctrl-C / SIGTERM
/// came, and how many watchers have not yet cleaned up after it. No paths live here: each
/// session's watcher holds its own.
struct Interrupts {
    state: Mutex<Signal>,
    wake: Condvar,
}

struct Signal {
    fired: bool,
    /// Watchers running (each one session's).
    watching: usize,
}

static INTERRUPTS: Interrupts = Interrupts {
    state: Mutex::new(Signal {
        fired: false,
        watching: 0,
    }),
    wake: Condvar::new(),
};

/// Starts the watcher of one session: on an interrupt it waits for the session's writes in
/// flight, removes its staging folder and lock file, and keeps the gate shut until the
/// process exits; it stops when the session closes.
fn watch_interrupts(shared: Arc<Shared>) -> std::thread::JoinHandle<()> {
    install_interrupt_handler();
    let signals = &INTERRUPTS;
    signals
        .state
        .lock()
        .unwrap_or_else(|e| e.into_inner())
        .watching += 1;
    std::thread::spawn(move || {
        let mut st = signals.state.lock().unwrap_or_else(|e| e.into_inner());
        while !st.fired && !shared.closed.load(Ordering::SeqCst) {
            st = signals.wake.wait(st).unwrap_or_else(|e| e.into_inner());
        }
        let fired = st.fired;
        drop(st);
        if fired {
            // Wait for writes in flight; no new one starts before the exit (the gate stays shut).
            let gate = shared.gate.write().unwrap_or_else(|e| e.into_inner());
            remove_staging(&shared.cleanup);
            std::mem::forget(gate);
        }
        let mut st = signals.state.lock().unwrap_or_else(|e| e.into_inner());
        st.watching -= 1;
        signals.wake.notify_all();
    })
}

/// Removes what an interrupted session leaves: its staging folder and its lock file, and
/// `.bake/tmp` when nothing else is in it.
fn remove_staging(paths: &[PathBuf]) {
    for p in paths {
        let _ = if p.is_dir() {
            std::fs::remove_dir_all(p)
        } else {
            std::fs::remove_file(p)
        };
        if let Some(parent) = p
            .parent()
            .filter(|d| d.file_name().is_some_and(|n| n == "tmp"))
        {
            let _ = std::fs::remove_dir(parent);
        }
    }
}

/// Installs (once per process) the Ctrl-C / SIGTERM handler: it wakes every session's
/// watcher, waits until they have cleaned up, and exits with 130.
fn install_interrupt_handler() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        let _ = ctrlc::set_handler(|| {
            let signals = &INTERRUPTS;
            let mut st = signals.state.lock().unwrap_or_else(|e| e.into_inner());
            st.fired = true;
            signals.wake.notify_all();
            while st.watching > 0 {
                st = signals.wake.wait(st).unwrap_or_else(|e| e.into_inner());
            }
            eprintln!(
                "bake: interrupted; completed stages are kept, the next run resumes from them"
            );
            std::process::exit(130);
        });
    });
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cache::{self, test_record, Manifest};

    #[test]
    fn a_journal_left_by_a_killed_run_is_rolled_forward() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("out");
        let cache = CacheDir::new(&out);
        // A killed run: one file renamed into place, one still staged, the journal written.
        let staged = cache.tmp().join("4242");
        std::fs::create_dir_all(&staged).unwrap();
        std::fs::write(staged.join("1"), b"second").unwrap();
        std::fs::create_dir_all(out.join("s")).unwrap();
        std::fs::write(out.join("s/a.exr"), b"first").unwrap();
        let rec = test_record("s", &[("a.exr", b"first"), ("b.exr", b"second")]);
        let j = Journal {
            id: "s".into(),
            record: rec.clone(),
            renames: vec![
                (staged.join("0"), out.join("s/a.exr")),
                (staged.join("1"), out.join("s/b.exr")),
            ],
        };
        cache::write_atomic(
            &cache.journal().join("s.json"),
            &serde_json::to_vec(&j).unwrap(),
        )
        .unwrap();
        std::fs::write(cache.lock_path(), "4294967295").unwrap();

        let session = Session::open_output(&out).unwrap();
        assert_eq!(std::fs::read(out.join("s/b.exr")).unwrap(), b"second");
        assert!(
            !cache.tmp().join("4242").exists(),
            "stale staging is cleared"
        );
        assert_eq!(std::fs::read_dir(cache.journal()).unwrap().count(), 0);
        let m = cache.load_manifest().unwrap();
        assert_eq!(m.stages["s"].key, rec.key);
        assert!(
            cache.entry(&rec.key).is_some(),
            "the outputs went into the object store"
        );
        // A second session cannot open the folder while this one holds it.
        assert!(matches!(
            Session::open_output(&out),
            Err(Error::Busy { .. })
        ));
        drop(session);
        assert!(!cache.lock_path().exists());
        drop(Session::open_output(&out).unwrap());
    }

    #[test]
    fn damaged_records_and_journals_touch_nothing_outside_the_output() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("out");
        let cache = CacheDir::new(&out);
        let victim = dir.path().join("victim.exr");
        std::fs::write(&victim, b"keep me").unwrap();
        // A record whose output climbs out of the output folder, replaced by a new one.
        let mut m = Manifest::default();
        let mut bad = test_record("s", &[("x.exr", b"x")]);
        bad.outputs[0].rel = "../../victim.exr".into();
        m.stages.insert("s".into(), bad);
        m.apply(&out, "s", test_record("s", &[("y.exr", b"y")]));
        assert!(victim.is_file());
        // A journal renaming a file outside the output folder is not rolled forward.
        let staged = cache.tmp().join("4242");
        std::fs::create_dir_all(&staged).unwrap();
        std::fs::write(staged.join("0"), b"evil").unwrap();
        for (from, to) in [
            (staged.join("0"), victim.clone()),
            (victim.clone(), out.join("s/a.exr")),
            (staged.join("0"), out.join(".bake/manifest.json")),
        ] {
            let j = Journal {
                id: "s".into(),
                record: test_record("s", &[("a.exr", b"evil")]),
                renames: vec![(from, to)],
            };
            cache::write_atomic(
                &cache.journal().join("s.json"),
                &serde_json::to_vec(&j).unwrap(),
            )
            .unwrap();
            drop(Session::open_output(&out).unwrap());
            assert_eq!(std::fs::read(&victim).unwrap(), b"keep me");
            assert!(!out.join("s/a.exr").exists());
            assert!(cache.load_manifest().unwrap().stages.is_empty());
            std::fs::create_dir_all(&staged).unwrap();
            std::fs::write(staged.join("0"), b"evil").unwrap();
        }
    }

    #[test]
    fn a_held_lock_is_busy_and_a_stale_one_is_taken() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("out");
        let cache = CacheDir::new(&out);
        std::fs::create_dir_all(&cache.root).unwrap();
        // A lock file left by a dead run (any content, no OS lock on it) is simply taken.
        for text in ["", "12ab", "4000000"] {
            std::fs::write(cache.lock_path(), text).unwrap();
            let session = Session::open_output(&out).unwrap();
            assert_eq!(
                std::fs::read_to_string(cache.lock_path()).unwrap(),
                std::process::id().to_string()
            );
            drop(session);
            assert!(!cache.lock_path().exists(), "released locks are removed");
        }
        // One held through another handle (as another process would) is busy, names the pid,
        // and is left alone.
        std::fs::write(cache.lock_path(), "4242").unwrap();
        let holder = std::fs::File::open(cache.lock_path()).unwrap();
        holder.lock().unwrap();
        match Session::open_output(&out) {
            Err(Error::Busy { why, .. }) => assert!(why.contains("pid 4242"), "{why}"),
            Err(e) => panic!("{e}"),
            Ok(_) => panic!("took a held lock"),
        }
        assert_eq!(std::fs::read_to_string(cache.lock_path()).unwrap(), "4242");
        drop(holder);
        let session = Session::open_output(&out).unwrap();
        let names: Vec<String> = std::fs::read_dir(&cache.root)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        assert!(
            names.iter().all(|n| !n.contains(".tmp")),
            "no temporary lock left: {names:?}"
        );
        drop(session);
    }

    #[test]
    fn of_threads_racing_for_a_lock_exactly_one_gets_it() {
        // Fresh locks and stale ones (a file a dead run left): one winner either way.
        for round in 0..20 {
            let dir = tempfile::tempdir().unwrap();
            let lock = dir.path().join("lock");
            if round % 2 == 1 {
                std::fs::write(&lock, "4000000").unwrap();
            }
            let won = std::sync::atomic::AtomicUsize::new(0);
            let held = Mutex::new(Vec::new());
            std::thread::scope(|s| {
                for _ in 0..8 {
                    s.spawn(|| {
                        if let Ok(f) = take_lock(&lock) {
                            won.fetch_add(1, std::sync::atomic::Ordering::SeqCst);
                            held.lock().unwrap().push(f);
                        }
                    });
                }
            });
            assert_eq!(won.into_inner(), 1, "round {round}");
            for f in held.into_inner().unwrap() {
                release_lock(&lock, f);
            }
            assert!(!lock.exists());
        }
    }

    #[test]
    fn a_lock_released_while_another_taker_holds_its_old_file_is_retaken_cleanly() {
        // The unlink race: a taker that opened the file before its holder unlinked it must not
        // end up holding a lock on a file no longer at the path while a third party holds the
        // new one. Hammer take/release from threads; at any instant at most one holder.
        let dir = tempfile::tempdir().unwrap();
        let lock = dir.path().join("lock");
        let inside = std::sync::atomic::AtomicUsize::new(0);
        let max = std::sync::atomic::AtomicUsize::new(0);
        std::thread::scope(|s| {
            for _ in 0..4 {
                s.spawn(|| {
                    for _ in 0..200 {
                        if let Ok(f) = take_lock(&lock) {
                            let now = inside.fetch_add(1, std::sync::atomic::Ordering::SeqCst) + 1;
                            max.fetch_max(now, std::sync::atomic::Ordering::SeqCst);
                            std::thread::yield_now();
                            inside.fetch_sub(1, std::sync::atomic::Ordering::SeqCst);
                            release_lock(&lock, f);
                        }
                    }
                });
            }
        });
        assert_eq!(max.into_inner(), 1);
    }
}
