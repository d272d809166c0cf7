//! The executor's scheduler: which stage runs when (a stage starts once every stage it reads
//! is done, lowest index first, up to N at once), each through its bake's library function
//! in-process, results reported in stage order. A stage that fails stops the stages that read
//! it; independent stages go on. The output folder is held by a [`Session`] (lock, journal,
//! interrupts); a stage's files reach their place through the [`commit`].
//!
//! So a failed stage leaves nothing, an interrupted run (Ctrl-C, SIGTERM) leaves only complete
//! outputs, and a killed run (SIGKILL) leaves at worst a journal that the next run rolls
//! forward.

pub mod commit;
pub mod session;

pub use commit::{clean, clean_output, CleanReport};
pub use session::Session;

use crate::cache::Manifest;
use crate::error::Result;
use crate::graph::Graph;
use crate::kinds::{BakeError, Baked};
use crate::plan::{Decision, Plan};
use commit::{manifest_guard, Staged};
use ibl_core::progress::Progress;
use serde::Serialize;
use std::path::PathBuf;
use std::sync::{mpsc, Mutex};
use std::time::Instant;

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
        let _g = session.commit_lock();
        session.cache.save_manifest(&manifest_guard(&manifest))?;
    }

    let mut results: Vec<Option<StageResult>> = vec![None; n];
    let mut pending: Vec<bool> = plan.stages.iter().map(|p| p.decision.is_work()).collect();
    for (i, (s, p)) in graph.stages.iter().zip(&plan.stages).enumerate() {
        if p.decision.is_work() {
            continue;
        }
        let (status, outputs) = match &p.decision {
            Decision::UpToDate => {
                let rec = manifest_guard(&manifest).stages.get(&s.id).cloned();
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
        let _g = session.commit_lock();
        let m = manifest_guard(&manifest);
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
    let _ = std::fs::remove_dir_all(session.staging_dir(i, &s.id));
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
    let staging = session.staging_dir(i, &s.id);
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
            if let Some(staged) = commit::stage_cached(session, &key, &staging)? {
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
        let _g = session.gate();
        commit::stage_files(&staging, &s.dir, files)
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
    match commit::commit(session, graph, i, key, parts, staged, seconds, manifest) {
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

#[cfg(test)]
mod tests {
    use super::*;

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
}
