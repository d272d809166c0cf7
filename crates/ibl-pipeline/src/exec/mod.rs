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
use crate::cache::{OutputRecord, StageRecord};
use crate::error::Result;
use crate::graph::{Graph, Stage};
use crate::kinds::{BakeError, Baked};
use crate::plan::{Decision, Plan, PlannedStage};
use commit::{manifest_guard, Staged};
use ibl_core::progress::Progress;
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::sync::{mpsc, Mutex};
use std::time::Instant;

/// How a stage ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Status {
    /// The bake ran and its outputs were committed.
    Ran,
    /// Its outputs came back from the cache, without baking.
    Restored,
    /// Built with this key, outputs in place: nothing to do.
    UpToDate,
    /// Not needed.
    Skipped,
    /// The stage failed (its reason says why); nothing of it was written.
    Failed,
    /// Not run because a stage it reads failed.
    Blocked,
}

impl Status {
    /// The status in words, as the terminal shows it.
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
    /// The stage's id.
    pub id: String,
    /// Its kind.
    pub kind: String,
    /// How it ended.
    pub status: Status,
    /// Why it ran or was skipped; the error for a failed stage.
    pub reason: String,
    /// Wall-clock seconds it took.
    pub seconds: f64,
    /// The files it wrote (or that were in place).
    pub outputs: Vec<PathBuf>,
    /// Its bake's warnings, worded for pipelines.
    pub warnings: Vec<String>,
    /// For a stage baked item by item: what happened to each item.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub items: Vec<ItemResult>,
}

impl StageResult {
    /// The result of stage `s` with no outputs, warnings or time (yet).
    pub fn new(s: &Stage, status: Status, reason: impl Into<String>) -> StageResult {
        StageResult {
            id: s.id.clone(),
            kind: s.kind_name.clone(),
            status,
            reason: reason.into(),
            seconds: 0.0,
            outputs: vec![],
            warnings: vec![],
            items: vec![],
        }
    }
}

/// What happened to one item of a stage baked item by item.
#[derive(Clone, Debug, Serialize)]
pub struct ItemResult {
    /// The item's name (its outputs, relative to the stage's folder).
    pub name: String,
    /// Ran, restored or up to date.
    pub status: Status,
    /// Why.
    pub reason: String,
}

/// The results of a run, in stage order.
#[derive(Clone, Debug, Serialize)]
pub struct RunReport {
    /// The pipeline file.
    pub pipeline: PathBuf,
    /// Its output folder.
    pub output: PathBuf,
    /// Every stage's result, in stage order.
    pub stages: Vec<StageResult>,
    /// Wall-clock seconds of the whole run.
    pub seconds: f64,
}

impl RunReport {
    /// Whether a stage failed or was blocked.
    pub fn failed(&self) -> bool {
        self.stages
            .iter()
            .any(|s| matches!(s.status, Status::Failed | Status::Blocked))
    }
    /// How many stages ended with `status`.
    pub fn count(&self, status: Status) -> usize {
        self.stages.iter().filter(|s| s.status == status).count()
    }
}

/// Receives the executor's events (the binary shows them on a terminal).
pub trait Observer: Sync {
    /// A stage starts (its bake, or its restore from the cache).
    fn started(&self, _id: &str, _decision: &Decision) {}
    /// A progress sink for a running stage's bake.
    fn progress(&self, _id: &str) -> Box<dyn Progress + '_> {
        Box::new(ibl_core::progress::NoProgress)
    }
    /// A stage ended (in any way, including skipped and blocked).
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
            outputs,
            ..StageResult::new(s, status, p.decision.reason())
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
                        run_stage(session, graph, i, plan_stage, manifest, obs)
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
                        let r =
                            StageResult::new(s, Status::Blocked, format!("not run: '{id}' failed"));
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
    StageResult::new(s, Status::Failed, format!("the runner panicked: {msg}"))
}

/// Runs (or restores) one stage and commits its outputs.
fn run_stage(
    session: &Session,
    graph: &Graph,
    i: usize,
    planned: &PlannedStage,
    manifest: &Mutex<Manifest>,
    obs: &dyn Observer,
) -> StageResult {
    let s = &graph.stages[i];
    let t0 = Instant::now();
    obs.started(&s.id, &planned.decision);
    let staging = session.staging_dir(i, &s.id);
    let mut result = StageResult::new(s, Status::Ran, planned.decision.reason());

    let outcome = if planned.items.is_empty() {
        stage_whole(session, graph, i, planned, &staging, obs, &mut result)
            .map(|staged| (staged, vec![]))
    } else {
        let record = manifest_guard(manifest).stages.get(&s.id).cloned();
        stage_items(
            session,
            graph,
            i,
            planned,
            record,
            &staging,
            obs,
            &mut result,
        )
    };
    let (staged, kept) = match outcome {
        Ok(staged) => staged,
        Err(message) => {
            let _ = std::fs::remove_dir_all(&staging);
            result.status = Status::Failed;
            result.reason = message;
            result.seconds = t0.elapsed().as_secs_f64();
            return result;
        }
    };
    let seconds = t0.elapsed().as_secs_f64();
    match commit::commit(session, graph, i, planned, staged, kept, seconds, manifest) {
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

/// Stages the outputs of a stage baked as one piece: restored from the cache, or baked.
fn stage_whole(
    session: &Session,
    graph: &Graph,
    i: usize,
    planned: &PlannedStage,
    staging: &Path,
    obs: &dyn Observer,
    result: &mut StageResult,
) -> std::result::Result<Vec<Staged>, String> {
    let s = &graph.stages[i];
    if let Decision::Restore(_) = planned.decision {
        let key = planned.key.as_deref().expect("work has a key");
        if let Some(staged) = commit::stage_cached(session, key, staging)? {
            result.status = Status::Restored;
            return Ok(staged);
        }
        result.reason = format!("{} (cache damaged: baking)", result.reason);
    }
    let baked = bake(graph, i, &graph.input_args(i), &s.dir, obs)?;
    result.warnings = baked.warnings;
    let _g = session.gate();
    commit::stage_files(staging, &s.dir, baked.files)
}

/// Stages the outputs of a stage baked item by item: items up to date are kept where they
/// are (returned as records), the others restored from the cache or baked, each into its own
/// staging folder.
#[allow(clippy::too_many_arguments)]
pub(crate) fn stage_items(
    session: &Session,
    graph: &Graph,
    i: usize,
    planned: &PlannedStage,
    record: Option<StageRecord>,
    staging: &Path,
    obs: &dyn Observer,
    result: &mut StageResult,
) -> std::result::Result<(Vec<Staged>, Vec<OutputRecord>), String> {
    let s = &graph.stages[i];
    let (mut staged, mut kept) = (vec![], vec![]);
    let (mut ran, mut restored) = (false, false);
    for (n, it) in planned.items.iter().enumerate() {
        let item_staging = staging.join(format!("item-{n}"));
        let mut reason = it.decision.reason().to_string();
        if it.decision == Decision::UpToDate {
            let outputs = record.as_ref().map(|r| r.outputs.as_slice()).unwrap_or(&[]);
            kept.extend(
                outputs
                    .iter()
                    .filter(|o| it.outputs.contains(&o.rel))
                    .cloned(),
            );
            result.items.push(ItemResult {
                name: it.name.clone(),
                status: Status::UpToDate,
                reason,
            });
            continue;
        }
        if let Decision::Restore(_) = it.decision {
            if let Some(files) = commit::stage_cached(session, &it.key, &item_staging)? {
                staged.extend(files);
                restored = true;
                result.items.push(ItemResult {
                    name: it.name.clone(),
                    status: Status::Restored,
                    reason,
                });
                continue;
            }
            reason = format!("{reason} (cache damaged: baking)");
        }
        let baked = bake(graph, i, &it.item.inputs, &it.item.dir, obs)
            .map_err(|e| format!("{}: {e}", it.name))?;
        result.warnings.extend(baked.warnings);
        let _g = session.gate();
        staged.extend(commit::stage_files(&item_staging, &s.dir, baked.files)?);
        ran = true;
        result.items.push(ItemResult {
            name: it.name.clone(),
            status: Status::Ran,
            reason,
        });
    }
    if restored && !ran {
        result.status = Status::Restored;
    }
    Ok((staged, kept))
}

/// Runs stage `i`'s bake on `inputs` into `dir`; a panic in the bake is its failure.
fn bake(
    graph: &Graph,
    i: usize,
    inputs: &[PathBuf],
    dir: &Path,
    obs: &dyn Observer,
) -> std::result::Result<Baked, String> {
    let s = &graph.stages[i];
    let (kind, params) = s.runnable().expect("work is runnable");
    let progress = obs.progress(&s.id);
    let baked = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        kind.run(params, inputs, dir, progress.as_ref())
    }));
    match baked {
        Ok(Ok(b)) => Ok(b),
        Ok(Err(BakeError { message, .. })) => Err(message),
        Err(panic) => Err(format!("the bake panicked: {}", panic_message(&*panic))),
    }
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

/// The planner's item-by-item decisions across real runs: here, not in `plan.rs`, so that the
/// planner never imports the executor (the executor reads plans; plans know nothing of it).
#[cfg(all(test, feature = "material"))]
mod planned_items {
    use crate::exec::{self, Quiet, Session};
    use crate::graph::Graph;
    use crate::plan::{plan, Decision};
    use std::path::Path;

    /// A folder of two material folders read by a quat-map stage, planned and run once.
    fn baked(dir: &Path, bits: u32) -> Graph {
        let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../pipelines/materials");
        for m in ["frying-pan", "painted-metal"] {
            std::fs::create_dir_all(dir.join("mats").join(m)).unwrap();
            std::fs::copy(
                root.join(m).join("normal.png"),
                dir.join("mats").join(m).join("normal.png"),
            )
            .unwrap();
        }
        let file = dir.join("p.ron");
        let src = format!(
            r#"(output: "out", inputs: {{"mats": Folder("mats")}}, stages: [
                (id: "q", kind: "quat-map", reads: ["mats"], params: (bits: {bits})),
            ])"#
        );
        std::fs::write(&file, src).unwrap();
        crate::load(&file).unwrap()
    }

    fn run(graph: &Graph) {
        let session = Session::open(graph).unwrap();
        let report = exec::run(&session, graph, plan(graph, false).unwrap(), 1, &Quiet).unwrap();
        assert!(!report.failed(), "{:?}", report.stages);
    }

    fn items(graph: &Graph) -> Vec<(String, Decision)> {
        let p = plan(graph, false).unwrap();
        p.stages[0]
            .items
            .iter()
            .map(|it| (it.name.clone(), it.decision.clone()))
            .collect()
    }

    #[test]
    fn items_are_planned_from_their_own_files_and_the_stages_parameters() {
        let dir = tempfile::tempdir().unwrap();
        let graph = baked(dir.path(), 8);
        let first = items(&graph);
        assert_eq!(first.len(), 2);
        assert!(first
            .iter()
            .all(|(_, d)| *d == Decision::Run("never built".into())));
        run(&graph);
        // Built: the stage is up to date, no item is planned.
        assert_eq!(
            plan(&graph, false).unwrap().stages[0].decision,
            Decision::UpToDate
        );
        assert!(items(&graph).is_empty());
        // One output deleted by hand: that item alone comes back from the object store.
        std::fs::remove_file(dir.path().join("out/q/painted-metal/quaternion.png")).unwrap();
        let now = items(&graph);
        assert_eq!(now[0].1, Decision::UpToDate, "{now:?}");
        assert!(matches!(&now[1].1, Decision::Restore(w) if w.contains("outputs missing")));
        run(&graph);
        // Another parameter changes every item's key, and says which.
        let graph = baked(dir.path(), 16);
        let now = items(&graph);
        assert!(
            now.iter().all(
                |(_, d)| matches!(d, Decision::Run(w) if w.contains("parameters changed: bits 8 -> 16"))
            ),
            "{now:?}"
        );
    }
}
