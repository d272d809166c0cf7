//! The executor: a dependency-ordered scheduler running up to N stages at once, each through
//! its bake's library function in-process, with outputs committed atomically.
//!
//! A stage's files are encoded in memory by the bake, written to `OUTPUT/.bake/tmp/`, and only
//! then committed: a journal naming the renames is written, the files are renamed into place,
//! the manifest records the stage, the journal is removed. So a failed stage leaves nothing, an
//! interrupted run (Ctrl-C, SIGTERM: the handler waits for a commit in flight, removes the
//! staging folder and exits) leaves only complete outputs, and a killed run (SIGKILL) leaves at
//! worst a journal that the next run rolls forward. A stage that fails stops the stages that
//! read it; independent stages go on.

use crate::cache::{self, CacheDir, KeyParts, Manifest, OutputRecord, StageRecord};
use crate::error::{Error, Result};
use crate::graph::Graph;
use crate::kinds::{BakeError, Baked};
use crate::paths;
use crate::plan::{Decision, Plan};
use ibl_core::progress::Progress;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::sync::{mpsc, Mutex, RwLock};
use std::time::Instant;

/// Shared by every thread writing under the output folder (staging files, committing,
/// saving the manifest); the interrupt handler takes it exclusively, so it waits for writes in
/// flight and no new one starts between its clean-up and the exit.
static GATE: RwLock<()> = RwLock::new(());
/// Serialises commits (journal, renames, manifest) between workers.
static COMMIT: Mutex<()> = Mutex::new(());

/// Permission to write under the output folder (see [`GATE`]).
fn gate() -> std::sync::RwLockReadGuard<'static, ()> {
    GATE.read().unwrap_or_else(|e| e.into_inner())
}

/// Permission to commit: the gate, then the commit lock.
pub(crate) fn commit_lock() -> (
    std::sync::RwLockReadGuard<'static, ()>,
    std::sync::MutexGuard<'static, ()>,
) {
    let g = gate();
    (g, COMMIT.lock().unwrap_or_else(|e| e.into_inner()))
}
/// What the interrupt handler removes: the staging folder and lock file of the live session.
static CLEANUP: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());
/// Test hook: each stage sleeps this long after baking, before committing (to kill a run mid-stage).
const DELAY_ENV: &str = "IBL_BAKE_TEST_DELAY_MS";

/// How a stage ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Status {
    Ran,
    Restored,
    UpToDate,
    Skipped,
    Failed,
    /// Not run because a stage it reads failed.
    Blocked,
}

impl Status {
    pub fn word(&self) -> &'static str {
        match self {
            Status::Ran => "ran",
            Status::Restored => "restored",
            Status::UpToDate => "up to date",
            Status::Skipped => "skipped",
            Status::Failed => "FAILED",
            Status::Blocked => "blocked",
        }
    }
}

/// The result of one stage.
#[derive(Clone, Debug, Serialize)]
pub struct StageResult {
    pub id: String,
    pub kind: String,
    pub status: Status,
    /// Why it ran or was skipped; the error for a failed stage.
    pub reason: String,
    pub seconds: f64,
    pub outputs: Vec<PathBuf>,
    pub warnings: Vec<String>,
}

/// The results of a run, in stage order.
#[derive(Clone, Debug, Serialize)]
pub struct RunReport {
    pub pipeline: PathBuf,
    pub output: PathBuf,
    pub stages: Vec<StageResult>,
    pub seconds: f64,
}

impl RunReport {
    pub fn failed(&self) -> bool {
        self.stages
            .iter()
            .any(|s| matches!(s.status, Status::Failed | Status::Blocked))
    }
    pub fn count(&self, status: Status) -> usize {
        self.stages.iter().filter(|s| s.status == status).count()
    }
}

/// Receives the executor's events (the binary shows them on a terminal).
pub trait Observer: Sync {
    fn started(&self, _id: &str, _decision: &Decision) {}
    /// A progress sink for a running stage's bake.
    fn progress(&self, _id: &str) -> Box<dyn Progress + '_> {
        Box::new(ibl_core::progress::NoProgress)
    }
    fn finished(&self, _result: &StageResult) {}
}

/// Reports nothing.
pub struct Quiet;
impl Observer for Quiet {}

/// A commit in flight, written before the renames so that a killed run can be rolled forward.
#[derive(Serialize, Deserialize)]
struct Journal {
    id: String,
    record: StageRecord,
    renames: Vec<(PathBuf, PathBuf)>,
}

/// Exclusive use of an output folder: the lock, recovery of killed runs, the staging folder.
pub struct Session {
    pub cache: CacheDir,
    tmp: PathBuf,
}

impl Session {
    /// Locks `graph`'s output folder, rolls forward commits a killed run left, clears stale
    /// staging files, and arranges for Ctrl-C / SIGTERM to leave no partial outputs.
    pub fn open(graph: &Graph) -> Result<Session> {
        Session::open_output(&graph.pipeline.output)
    }

    /// [`Session::open`] for an output folder.
    pub fn open_output(output: &Path) -> Result<Session> {
        // Before anything is baked: an `output:` that is a file, lies under a file or cannot
        // be written is said now, with what to do, not as "File exists" after the work.
        ibl_core::io::check_output(output, ibl_core::io::OutputKind::Folder)?;
        let cache = CacheDir::new(output);
        std::fs::create_dir_all(&cache.root).map_err(|e| Error::io(&cache.root, e))?;
        take_lock(&cache.lock_path())?;
        let tmp_root = cache.tmp();
        let tmp = tmp_root.join(std::process::id().to_string());
        *CLEANUP.lock().unwrap() = vec![tmp.clone(), cache.lock_path()];
        install_interrupt_handler();
        let session = Session { cache, tmp };
        // Journals name staged files of the killed run: roll them forward before clearing.
        session.recover()?;
        let _ = std::fs::remove_dir_all(&tmp_root);
        Ok(session)
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
            apply_record(&mut manifest, &self.cache.output, &j.id, j.record);
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
        let _guard = commit_lock();
        let _ = std::fs::remove_dir_all(&self.tmp);
        let _ = std::fs::remove_dir(self.cache.tmp());
        let _ = std::fs::remove_dir(self.cache.journal());
        release_lock(&self.cache.lock_path());
        CLEANUP.lock().unwrap().clear();
    }
}

/// Lock files this process holds, with the open handle that holds the OS lock on each.
static HELD: Mutex<Vec<(PathBuf, std::fs::File)>> = Mutex::new(Vec::new());

/// Takes the lock at `path`: an exclusive OS file lock (flock / LockFileEx) on the file, held
/// for the session; the file also records our pid for the message others get.
///
/// Why an OS lock and not a pid file: the kernel releases it when the process dies, however it
/// dies, so there is no stale lock to take over and no race between two runs taking over the
/// same stale lock (with pid files, both could delete it and both proceed). Unlinking on exit
/// is safe because a taker that opened the old file checks, once locked, that the path still
/// names the file it locked, and starts again if not.
fn take_lock(path: &Path) -> Result<()> {
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
        HELD.lock().unwrap().push((path.to_path_buf(), f));
        return Ok(());
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

/// Releases the lock at `path`: unlinks the file while still holding it, then closes it.
fn release_lock(path: &Path) {
    let mut held = HELD.lock().unwrap();
    if let Some(k) = held.iter().position(|(p, _)| p == path) {
        let _ = std::fs::remove_file(path);
        held.remove(k);
    }
}

fn install_interrupt_handler() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        let _ = ctrlc::set_handler(|| {
            // Wait for writes in flight, keep new ones from starting, leave only complete outputs.
            let _gate = GATE.write();
            for p in CLEANUP.lock().map(|v| v.clone()).unwrap_or_default() {
                let _ = if p.is_dir() {
                    std::fs::remove_dir_all(&p)
                } else {
                    std::fs::remove_file(&p)
                };
                // The staging folder's parent (`.bake/tmp`) goes too when nothing else is in it.
                if let Some(parent) = p
                    .parent()
                    .filter(|d| d.file_name().is_some_and(|n| n == "tmp"))
                {
                    let _ = std::fs::remove_dir(parent);
                }
            }
            eprintln!(
                "bake: interrupted; completed stages are kept, the next run resumes from them"
            );
            std::process::exit(130);
        });
    });
}

/// Records `record` for stage `id`: keeps the previous key in its history (for the object
/// store) and removes the previous outputs that the new ones do not replace.
fn apply_record(m: &mut Manifest, output: &Path, id: &str, mut record: StageRecord) {
    // Only the outputs of a sound record are removed: they lie in the output folder.
    if let Some(old) = m.stages.remove(id).filter(StageRecord::is_sound) {
        let new_files: std::collections::HashSet<PathBuf> = record
            .outputs
            .iter()
            .map(|o| output.join(&record.dir).join(&o.rel))
            .collect();
        for o in &old.outputs {
            let p = output.join(&old.dir).join(&o.rel);
            if !new_files.contains(&p) {
                let _ = std::fs::remove_file(&p);
                remove_empty_parents(&p, output);
            }
        }
        let mut history = vec![];
        if old.key != record.key {
            history.push(old.key);
        }
        history.extend(old.history.into_iter().filter(|k| *k != record.key));
        history.truncate(cache::KEEP_KEYS - 1);
        record.history = history;
    }
    m.stages.insert(id.to_string(), record);
}

/// Removes the empty folders from `file`'s folder up to (not including) `stop`.
pub fn remove_empty_parents(file: &Path, stop: &Path) {
    let mut d = file.parent();
    while let Some(dir) = d {
        if !paths::is_within(dir, stop)
            || paths::normalize(dir) == paths::normalize(stop)
            || std::fs::remove_dir(dir).is_err()
        {
            break;
        }
        d = dir.parent();
    }
}

/// What a worker sends back.
struct Done {
    index: usize,
    result: StageResult,
}

/// Runs the work of `plan` with up to `jobs` stages at once.
pub fn run(
    session: &Session,
    graph: &Graph,
    plan: Plan,
    jobs: usize,
    obs: &dyn Observer,
) -> Result<RunReport> {
    let start = Instant::now();
    let jobs = jobs.max(1);
    let n = graph.stages.len();
    let delay_ms: u64 = std::env::var(DELAY_ENV)
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(0);
    let manifest = Mutex::new(plan.manifest);
    // Save the refreshed input stamps now, so even an interrupted run keeps them.
    {
        let _g = commit_lock();
        session.cache.save_manifest(&lock(&manifest))?;
    }

    let mut results: Vec<Option<StageResult>> = vec![None; n];
    let mut pending: Vec<bool> = plan.stages.iter().map(|p| p.decision.is_work()).collect();
    for (i, (s, p)) in graph.stages.iter().zip(&plan.stages).enumerate() {
        if p.decision.is_work() {
            continue;
        }
        let (status, outputs) = match &p.decision {
            Decision::UpToDate => {
                let rec = lock(&manifest).stages.get(&s.id).cloned();
                (
                    Status::UpToDate,
                    rec.map(|r| r.outputs.iter().map(|o| s.dir.join(&o.rel)).collect())
                        .unwrap_or_default(),
                )
            }
            _ => (Status::Skipped, vec![]),
        };
        let r = StageResult {
            id: s.id.clone(),
            kind: s.kind_name.clone(),
            status,
            reason: p.decision.reason().to_string(),
            seconds: 0.0,
            outputs,
            warnings: vec![],
        };
        obs.finished(&r);
        results[i] = Some(r);
    }

    let (tx, rx) = mpsc::channel::<Done>();
    std::thread::scope(|scope| {
        let mut running = 0usize;
        loop {
            // Start every stage whose reads are done, lowest index first, up to `jobs`.
            while running < jobs {
                let ready = (0..n).find(|&i| {
                    pending[i]
                        && graph.stages[i].deps().all(|d| {
                            results[d].as_ref().is_some_and(|r| {
                                matches!(
                                    r.status,
                                    Status::Ran | Status::Restored | Status::UpToDate
                                )
                            })
                        })
                });
                let Some(i) = ready else { break };
                pending[i] = false;
                running += 1;
                let tx = tx.clone();
                let (manifest, plan_stage) = (&manifest, &plan.stages[i]);
                scope.spawn(move || {
                    // Whatever happens in the stage, the loop below hears of it (it waits for
                    // one report per stage started, and holds a sender itself).
                    let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                        run_stage(session, graph, i, plan_stage, manifest, delay_ms, obs)
                    }))
                    .unwrap_or_else(|panic| panicked(session, graph, i, panic_message(&*panic)));
                    let _ = tx.send(Done { index: i, result });
                });
            }
            if running == 0 {
                break;
            }
            let done = rx.recv().expect("a worker reports");
            running -= 1;
            let failed = done.result.status == Status::Failed;
            obs.finished(&done.result);
            let id = done.result.id.clone();
            results[done.index] = Some(done.result);
            if failed {
                for j in graph.dependants(done.index) {
                    if pending[j] {
                        pending[j] = false;
                        let s = &graph.stages[j];
                        let r = StageResult {
                            id: s.id.clone(),
                            kind: s.kind_name.clone(),
                            status: Status::Blocked,
                            reason: format!("not run: '{id}' failed"),
                            seconds: 0.0,
                            outputs: vec![],
                            warnings: vec![],
                        };
                        obs.finished(&r);
                        results[j] = Some(r);
                    }
                }
            }
        }
    });

    {
        let _g = commit_lock();
        let m = lock(&manifest);
        session.cache.save_manifest(&m)?;
        let _ = session.cache.collect_garbage(&m);
    }
    Ok(RunReport {
        pipeline: graph.pipeline.file.clone(),
        output: graph.pipeline.output.clone(),
        stages: results
            .into_iter()
            .map(|r| r.expect("every stage has a result"))
            .collect(),
        seconds: start.elapsed().as_secs_f64(),
    })
}

/// The manifest, even if a thread panicked while holding it (it is only ever replaced whole
/// record by record).
pub(crate) fn lock(m: &Mutex<Manifest>) -> std::sync::MutexGuard<'_, Manifest> {
    m.lock().unwrap_or_else(|e| e.into_inner())
}

/// The text of a panic's payload.
pub(crate) fn panic_message(panic: &(dyn std::any::Any + Send)) -> String {
    panic
        .downcast_ref::<String>()
        .cloned()
        .or_else(|| panic.downcast_ref::<&str>().map(|s| s.to_string()))
        .unwrap_or_default()
}

/// The result of stage `i` whose run panicked outside the bake: failed, its staging removed.
fn panicked(session: &Session, graph: &Graph, i: usize, msg: String) -> StageResult {
    let s = &graph.stages[i];
    let _ = std::fs::remove_dir_all(staging_dir(session, i, &s.id));
    StageResult {
        id: s.id.clone(),
        kind: s.kind_name.clone(),
        status: Status::Failed,
        reason: format!("the runner panicked: {msg}"),
        seconds: 0.0,
        outputs: vec![],
        warnings: vec![],
    }
}

/// The staging folder of stage `i`.
pub(crate) fn staging_dir(session: &Session, i: usize, id: &str) -> PathBuf {
    session.tmp.join(format!("{i}-{}", paths::slug(id)))
}

/// Runs (or restores) one stage and commits its outputs.
fn run_stage(
    session: &Session,
    graph: &Graph,
    i: usize,
    planned: &crate::plan::PlannedStage,
    manifest: &Mutex<Manifest>,
    delay_ms: u64,
    obs: &dyn Observer,
) -> StageResult {
    let s = &graph.stages[i];
    let t0 = Instant::now();
    obs.started(&s.id, &planned.decision);
    let key = planned.key.clone().expect("work has a key");
    let parts = planned.parts.clone().expect("work has key parts");
    let staging = staging_dir(session, i, &s.id);
    let mut result = StageResult {
        id: s.id.clone(),
        kind: s.kind_name.clone(),
        status: Status::Ran,
        reason: planned.decision.reason().to_string(),
        seconds: 0.0,
        outputs: vec![],
        warnings: vec![],
    };

    let outcome: std::result::Result<Vec<Staged>, String> = (|| {
        if let Decision::Restore(_) = planned.decision {
            if let Some(staged) = stage_cached(session, &key, &staging)? {
                result.status = Status::Restored;
                return Ok(staged);
            }
            result.reason = format!("{} (cache damaged: baking)", result.reason);
        }
        let (kind, params) = s.runnable().expect("work is runnable");
        let inputs = graph.input_args(i);
        let progress = obs.progress(&s.id);
        let baked = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            kind.run(params, &inputs, &s.dir, progress.as_ref())
        }));
        drop(progress);
        let Baked { files, warnings } = match baked {
            Ok(Ok(b)) => b,
            Ok(Err(BakeError { message, .. })) => return Err(message),
            Err(panic) => {
                return Err(format!("the bake panicked: {}", panic_message(&*panic)));
            }
        };
        result.warnings = warnings;
        let _g = gate();
        stage_files(&staging, &s.dir, files)
    })();

    let staged = match outcome {
        Ok(staged) => staged,
        Err(message) => {
            let _ = std::fs::remove_dir_all(&staging);
            result.status = Status::Failed;
            result.reason = message;
            result.seconds = t0.elapsed().as_secs_f64();
            return result;
        }
    };
    if delay_ms > 0 {
        std::thread::sleep(std::time::Duration::from_millis(delay_ms));
    }
    let seconds = t0.elapsed().as_secs_f64();
    match commit(session, graph, i, key, parts, staged, seconds, manifest) {
        Ok(outputs) => result.outputs = outputs,
        Err(e) => {
            result.status = Status::Failed;
            result.reason = e.to_string();
        }
    }
    let _ = std::fs::remove_dir_all(&staging);
    result.seconds = t0.elapsed().as_secs_f64();
    result
}

/// A staged file: its path in the staging folder, its path relative to the stage's folder,
/// its stamp.
pub(crate) type Staged = (PathBuf, String, cache::FileStamp);

/// Links the cache's outputs of `key` into `staging`; `None` when the cache has no sound entry
/// for it (the stage must be baked).
pub(crate) fn stage_cached(
    session: &Session,
    key: &str,
    staging: &Path,
) -> std::result::Result<Option<Vec<Staged>>, String> {
    let Some(entry) = session.cache.entry(key) else {
        return Ok(None);
    };
    let _g = gate();
    let Some(staged) = session
        .cache
        .stage_entry(&entry, staging)
        .map_err(|e| e.to_string())?
    else {
        return Ok(None);
    };
    staged
        .into_iter()
        .zip(entry.files)
        .map(|((path, rel), f)| {
            let md = std::fs::metadata(&path).map_err(|e| format!("{}: {e}", path.display()))?;
            Ok((
                path,
                rel,
                cache::FileStamp {
                    mtime_ns: cache::mtime_ns(&md),
                    ..f.stamp
                },
            ))
        })
        .collect::<std::result::Result<Vec<_>, String>>()
        .map(Some)
}

/// Writes a bake's encoded files into `staging` (synced), checking they belong in `dir`.
/// Returns (staged file, path relative to `dir`, stamp).
pub(crate) fn stage_files(
    staging: &Path,
    dir: &Path,
    files: Vec<(PathBuf, Vec<u8>)>,
) -> std::result::Result<Vec<Staged>, String> {
    use std::io::Write;
    std::fs::create_dir_all(staging).map_err(|e| format!("{}: {e}", staging.display()))?;
    let mut out = Vec::with_capacity(files.len());
    for (n, (path, bytes)) in files.into_iter().enumerate() {
        let norm = paths::normalize(&path);
        let rel = norm.strip_prefix(paths::normalize(dir)).map_err(|_| {
            format!(
                "the bake wrote {} outside its folder {}",
                path.display(),
                dir.display()
            )
        })?;
        let staged = staging.join(n.to_string());
        let write = || -> std::io::Result<()> {
            let mut f = std::fs::File::create(&staged)?;
            f.write_all(&bytes)?;
            f.sync_data()
        };
        write().map_err(|e| format!("{}: {e}", staged.display()))?;
        let md = std::fs::metadata(&staged).map_err(|e| format!("{}: {e}", staged.display()))?;
        let stamp = cache::FileStamp {
            size: bytes.len() as u64,
            mtime_ns: cache::mtime_ns(&md),
            hash: cache::hash_bytes(&bytes),
        };
        out.push((staged, rel.to_string_lossy().into_owned(), stamp));
    }
    Ok(out)
}

/// Renames staged files into place and records the stage, under the commit lock and a journal.
#[allow(clippy::too_many_arguments)]
pub(crate) fn commit(
    session: &Session,
    graph: &Graph,
    i: usize,
    key: String,
    parts: KeyParts,
    staged: Vec<Staged>,
    seconds: f64,
    manifest: &Mutex<Manifest>,
) -> Result<Vec<PathBuf>> {
    let s = &graph.stages[i];
    let output = &graph.pipeline.output;
    let staged = keep_unchanged(&s.dir, staged);
    let rel_dir = s
        .dir
        .strip_prefix(output)
        .unwrap_or(&s.dir)
        .to_string_lossy()
        .into_owned();
    let record = StageRecord {
        key: key.clone(),
        parts,
        dir: rel_dir,
        outputs: staged
            .iter()
            .map(|(_, rel, stamp)| OutputRecord {
                rel: rel.clone(),
                stamp: stamp.clone(),
            })
            .collect(),
        seconds,
        history: vec![],
    };
    let renames: Vec<(PathBuf, PathBuf)> = staged
        .iter()
        .filter_map(|(p, rel, _)| p.as_ref().map(|p| (p.clone(), s.dir.join(rel))))
        .collect();
    let _g = commit_lock();
    let journal_path = session
        .cache
        .journal()
        .join(format!("{}.json", paths::slug(&s.id)));
    let journal = Journal {
        id: s.id.clone(),
        record: record.clone(),
        renames: renames.clone(),
    };
    cache::write_atomic(
        &journal_path,
        &serde_json::to_vec(&journal).expect("journal serialises"),
    )?;
    for (staged, target) in &renames {
        if let Some(d) = target.parent() {
            std::fs::create_dir_all(d).map_err(|e| Error::io(d, e))?;
        }
        std::fs::rename(staged, target).map_err(|e| Error::io(target, e))?;
    }
    // The object store is a convenience: failing to link into it must not fail the stage.
    let _ = session.cache.put(&key, &s.dir, &record.outputs);
    {
        let mut m = lock(manifest);
        apply_record(&mut m, output, &s.id, record);
        session.cache.save_manifest(&m)?;
    }
    let _ = std::fs::remove_file(&journal_path);
    Ok(staged.iter().map(|(_, rel, _)| s.dir.join(rel)).collect())
}

/// Leaves in place every output whose file already holds the new bytes: a stage that re-runs
/// because one of its inputs changed (one normal map of a material folder) rewrites only the
/// outputs that differ, and the others keep their bytes and modification times. The staged
/// copy of a kept file is dropped (None) and its stamp takes the file's own time.
#[allow(clippy::type_complexity)]
fn keep_unchanged(
    dir: &Path,
    staged: Vec<(PathBuf, String, cache::FileStamp)>,
) -> Vec<(Option<PathBuf>, String, cache::FileStamp)> {
    staged
        .into_iter()
        .map(|(path, rel, stamp)| {
            let target = dir.join(&rel);
            let same = std::fs::metadata(&target)
                .ok()
                .filter(|m| m.is_file() && m.len() == stamp.size)
                .and_then(|m| {
                    let bytes = std::fs::read(&target).ok()?;
                    (cache::hash_bytes(&bytes) == stamp.hash).then_some(m)
                });
            match same {
                Some(m) => {
                    let _ = std::fs::remove_file(&path);
                    let stamp = cache::FileStamp {
                        mtime_ns: cache::mtime_ns(&m),
                        ..stamp
                    };
                    (None, rel, stamp)
                }
                None => (Some(path), rel, stamp),
            }
        })
        .collect()
}

/// What `clean` removed.
#[derive(Clone, Debug, Default, Serialize)]
pub struct CleanReport {
    /// Output files removed.
    pub removed: Vec<PathBuf>,
    /// The cache folder, if there was one (removed whole).
    pub cache: Option<PathBuf>,
}

/// Removes every output the pipeline recorded or would write, and its cache folder.
pub fn clean(session: Session, graph: &Graph) -> Result<CleanReport> {
    clean_output(session, Some(graph))
}

/// Removes every output the manifest of the session's output folder records, and the cache
/// folder; with the pipeline's graph, also what a ninja run of it would have written. Only the
/// output folder is needed: a pipeline whose inputs are gone can still be cleaned.
pub fn clean_output(session: Session, graph: Option<&Graph>) -> Result<CleanReport> {
    let output = session.cache.output.clone();
    let manifest = session.cache.load_manifest()?;
    let mut files: Vec<PathBuf> = manifest
        .stages
        .values()
        .flat_map(|r| {
            r.outputs
                .iter()
                .map(|o| output.join(&r.dir).join(&o.rel))
                .collect::<Vec<_>>()
        })
        .collect();
    // Also what a ninja run of the same pipeline wrote (same files, not in the manifest).
    if let Some(graph) = graph {
        for (i, s) in graph.stages.iter().enumerate() {
            if let (true, Some((kind, params))) = (s.needed(), s.runnable()) {
                if let Ok(outs) = kind.outputs(params, &graph.input_args(i), &s.dir) {
                    files.extend(outs);
                }
            }
        }
    }
    files.sort();
    files.dedup();
    let mut report = CleanReport::default();
    for f in files {
        if paths::is_within(&f, &output) && std::fs::remove_file(&f).is_ok() {
            remove_empty_parents(&f, &output);
            report.removed.push(f);
        }
    }
    let cache_root = session.cache.root.clone();
    drop(session);
    if cache_root.exists() {
        std::fs::remove_dir_all(&cache_root).map_err(|e| Error::io(&cache_root, e))?;
        report.cache = Some(cache_root);
    }
    let _ = std::fs::remove_dir(&output);
    Ok(report)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn record(dir: &str, files: &[(&str, &[u8])]) -> StageRecord {
        StageRecord {
            key: cache::hash_bytes(dir.as_bytes()),
            parts: KeyParts {
                tool: "t".into(),
                kind: "k".into(),
                params: "{}".into(),
                reads: vec![],
            },
            dir: dir.into(),
            outputs: files
                .iter()
                .map(|(rel, b)| OutputRecord {
                    rel: rel.to_string(),
                    stamp: cache::FileStamp {
                        size: b.len() as u64,
                        mtime_ns: 0,
                        hash: cache::hash_bytes(b),
                    },
                })
                .collect(),
            seconds: 0.0,
            history: vec![],
        }
    }

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
        let rec = record("s", &[("a.exr", b"first"), ("b.exr", b"second")]);
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
        let mut bad = record("s", &[("x.exr", b"x")]);
        bad.outputs[0].rel = "../../victim.exr".into();
        m.stages.insert("s".into(), bad);
        apply_record(&mut m, &out, "s", record("s", &[("y.exr", b"y")]));
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
                record: record("s", &[("a.exr", b"evil")]),
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
    fn a_panic_in_the_runner_fails_the_stage_instead_of_hanging_the_run() {
        let dir = tempfile::tempdir().unwrap();
        let src = r#"(output: "out", stages: [
            (id: "a", kind: "equirect-to-cube", reads: ["b"]),
            (id: "b", kind: "dfg", params: (size: 4, samples: 8)),
        ])"#;
        let file = dir.path().join("p.ron");
        std::fs::write(&file, src).unwrap();
        let graph = crate::load(&file).unwrap();
        let session = Session::open(&graph).unwrap();
        let mut plan = crate::plan::plan(&graph, false).unwrap();
        let b = graph.index("b").unwrap();
        // Work without a key: `run_stage` panics before the bake is called.
        plan.stages[b].key = None;
        // A thread of its own (not scoped): before the fix the run never ended.
        let (tx, rx) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            let report = run(&session, &graph, plan, 2, &Quiet);
            let _ = tx.send((report, graph, session));
        });
        let (report, graph, session) = rx
            .recv_timeout(std::time::Duration::from_secs(60))
            .expect("the run ends");
        let report = report.unwrap();
        let status = |id: &str| report.stages[graph.index(id).unwrap()].status;
        assert_eq!(status("b"), Status::Failed);
        assert!(report.stages[b].reason.contains("the runner panicked"));
        assert_eq!(status("a"), Status::Blocked);
        drop(session);
        assert!(!dir.path().join("out/.bake/tmp").exists());
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
            std::thread::scope(|s| {
                for _ in 0..8 {
                    s.spawn(|| {
                        if take_lock(&lock).is_ok() {
                            won.fetch_add(1, std::sync::atomic::Ordering::SeqCst);
                        }
                    });
                }
            });
            assert_eq!(won.into_inner(), 1, "round {round}");
            release_lock(&lock);
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
                        if take_lock(&lock).is_ok() {
                            let now = inside.fetch_add(1, std::sync::atomic::Ordering::SeqCst) + 1;
                            max.fetch_max(now, std::sync::atomic::Ordering::SeqCst);
                            std::thread::yield_now();
                            inside.fetch_sub(1, std::sync::atomic::Ordering::SeqCst);
                            release_lock(&lock);
                        }
                    }
                });
            }
        });
        assert_eq!(max.into_inner(), 1);
    }

    #[test]
    fn a_new_record_removes_the_outputs_the_old_one_had_and_keeps_history() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path();
        std::fs::create_dir_all(out.join("s")).unwrap();
        for f in ["m0.exr", "m1.exr", "m2.exr"] {
            std::fs::write(out.join("s").join(f), f).unwrap();
        }
        let mut m = Manifest::default();
        apply_record(
            &mut m,
            out,
            "s",
            record(
                "s",
                &[
                    ("m0.exr", b"m0.exr"),
                    ("m1.exr", b"m1.exr"),
                    ("m2.exr", b"m2.exr"),
                ],
            ),
        );
        let mut shorter = record("s", &[("m0.exr", b"m0.exr"), ("m1.exr", b"m1.exr")]);
        shorter.key = "other".into();
        apply_record(&mut m, out, "s", shorter);
        assert!(out.join("s/m1.exr").exists() && !out.join("s/m2.exr").exists());
        assert_eq!(m.stages["s"].history, vec![cache::hash_bytes(b"s")]);
    }
}
