//! One stage on its own, for executors other than the in-process one (a Ray cluster): the
//! [`StageEntry`] the plan gives each stage (kind, canonical parameters, key, what it reads and
//! from which files), [`run_entry`] running it on any machine from materialised inputs into a
//! result folder, and [`commit`] putting result folders into the pipeline's output folder and
//! cache through the runner's own staging and commit code (journal, renames, manifest, object
//! store), so that the next `bake run` finds those stages up to date.
//!
//! A result folder holds `stage.json` (a [`StageOutput`]) and `files/`, the stage's files by
//! their path relative to its folder. An input folder holds one folder per read, numbered in
//! `reads` order, each holding that read's files by their `rel` paths.

use crate::cache;
use crate::error::{Error, Result};
use crate::exec::{self, Session, StageResult, Status};
use crate::graph::{Graph, Source};
use crate::kinds::{self, BakeError, Baked};
use crate::plan::{Decision, Plan};
use ibl_core::error::ErrorClass;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::time::Instant;

/// Name of the report in a result folder.
pub(crate) const REPORT: &str = "stage.json";
/// Name of the files' folder in a result folder.
pub(crate) const FILES: &str = "files";

/// Everything needed to run one stage without the pipeline.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StageEntry {
    /// The stage's id.
    pub id: String,
    /// Its kind.
    pub kind: String,
    /// The canonical parameters (every field, keys sorted), as hashed into the key.
    pub params: serde_json::Value,
    /// The key it is planned with (its result is committed only under that key).
    pub key: String,
    /// The build of `bake` that planned it ([`cache::tool`]); only the same build may run it,
    /// or the outputs recorded under the key would be another build's.
    pub tool: String,
    /// The stage's folder relative to the output folder.
    pub dir: String,
    /// What it reads, in order.
    pub reads: Vec<ReadEntry>,
    /// The pipeline's memory budget (`max_memory`), which `bake stage` applies unless its own
    /// `--max-memory` names one: the budget of a run is the same wherever its stages run.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_memory: Option<u64>,
}

/// One source a stage reads, as files to materialise in its numbered input folder.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ReadEntry {
    /// The read's name in the pipeline.
    pub name: String,
    /// For a read of a stage: its id. Its files are that stage's outputs, under `prefix`.
    pub stage: Option<String>,
    /// Where a read stage's outputs go in the input folder (its folder relative to the output).
    pub prefix: String,
    /// The files, relative to the read's input folder, with where they are on the planning
    /// machine (for a stage read: where they are once that stage is built).
    pub files: Vec<ShippedFile>,
    /// What the bake is given, relative to the read's input folder.
    pub args: Vec<String>,
}

/// A file to ship: its place in the input folder and its path where the plan was made.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ShippedFile {
    /// Its path relative to the read's root.
    pub rel: String,
    /// Its absolute path here.
    pub path: PathBuf,
    /// The blake3 hash of its bytes as the plan hashed them (every input file; a read stage's
    /// file when that stage was built when the plan was made). `bake stage` refuses a file
    /// whose bytes differ: a wrong file under `--inputs`, or bytes damaged on the way.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub hash: Option<String>,
}

/// One produced file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct OutputFile {
    /// Relative to the stage's folder.
    pub rel: String,
    /// Its size in bytes.
    pub size: u64,
    /// Its blake3 hash.
    pub hash: String,
}

/// What [`run_entry`] produced: `stage.json` of a result folder.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StageOutput {
    /// The stage's id.
    pub id: String,
    /// The key it ran with.
    pub key: String,
    /// In the order the bake produced them (the order `bake run` records).
    pub outputs: Vec<OutputFile>,
    /// Its bake's warnings.
    pub warnings: Vec<String>,
    /// Wall-clock seconds of the bake.
    pub seconds: f64,
}

/// `path` relative to `root` as a plain relative path with `/` separators.
fn rel_text(path: &Path, root: &Path) -> Option<String> {
    let rel = crate::paths::absolute(path);
    let rel = rel.strip_prefix(crate::paths::absolute(root)).ok()?;
    let parts: Vec<String> = rel
        .components()
        .map(|c| c.as_os_str().to_string_lossy().into_owned())
        .collect();
    let text = parts.join("/");
    cache::is_inside_rel(&text).then_some(text)
}

/// The deepest folder holding every path of `paths`.
fn common_folder(paths: &[PathBuf]) -> PathBuf {
    let mut c = paths
        .first()
        .and_then(|p| p.parent())
        .map(Path::to_path_buf)
        .unwrap_or_default();
    while !paths.iter().all(|p| p.starts_with(&c)) && c.pop() {}
    c
}

/// The entries of the stages of `plan` that have a key (every needed stage), in stage order.
pub fn entries(graph: &Graph, plan: &Plan) -> Result<Vec<Option<StageEntry>>> {
    let output = &graph.pipeline.output;
    let rel_dir = |dir: &Path| {
        rel_text(dir, output).ok_or_else(|| {
            Error::Core(ibl_core::Error::invalid(
                dir,
                "a stage folder outside the output folder",
            ))
        })
    };
    let mut out = Vec::with_capacity(graph.stages.len());
    for (s, p) in graph.stages.iter().zip(&plan.stages) {
        let (Some(key), Some((_, params))) = (&p.key, s.runnable()) else {
            out.push(None);
            continue;
        };
        let mut reads = Vec::new();
        for (name, src) in &s.reads {
            reads.push(match src {
                Source::Input(n) => input_read(name, &graph.inputs[n], &plan.manifest)?,
                Source::Stage(j) => {
                    let up = &graph.stages[*j];
                    let (uk, up_params) = up.runnable().expect("a read stage is runnable");
                    let prefix = rel_dir(&up.dir)?;
                    let product = uk.product(up_params, &up.dir);
                    // Hashes of the read stage's files when it is built and will not change.
                    let built = if plan.stages[*j].decision == Decision::UpToDate {
                        plan.manifest.stages.get(&up.id)
                    } else {
                        None
                    };
                    let files = uk
                        .outputs(up_params, &graph.input_args(*j), &up.dir)
                        .map_err(|e| Error::Core(ibl_core::Error::invalid(&up.dir, e.message)))?
                        .into_iter()
                        .filter_map(|f| {
                            let hash = built.and_then(|r| {
                                let rel = rel_text(&f, &up.dir)?;
                                let o = r.outputs.iter().find(|o| o.rel == rel)?;
                                Some(o.stamp.hash.clone())
                            });
                            rel_text(&f, output).map(|rel| ShippedFile {
                                rel,
                                path: crate::paths::absolute(&f),
                                hash,
                            })
                        })
                        .collect();
                    ReadEntry {
                        name: name.clone(),
                        stage: Some(up.id.clone()),
                        prefix,
                        files,
                        args: vec![rel_dir(&product)?],
                    }
                }
            });
        }
        out.push(Some(StageEntry {
            id: s.id.clone(),
            kind: s.kind_name.clone(),
            params: params.canonical(),
            key: key.clone(),
            tool: cache::tool(),
            dir: rel_dir(&s.dir)?,
            reads,
            max_memory: graph.pipeline.max_memory,
        }));
    }
    Ok(out)
}

/// A read of an input: a file and a folder keep their own name, glob matches their paths
/// below the folder they share, so the bake sees the names it would see in place.
fn input_read(
    name: &str,
    r: &crate::graph::ResolvedInput,
    manifest: &crate::cache::Manifest,
) -> Result<ReadEntry> {
    let root = match r.input {
        crate::schema::Input::File(_) | crate::schema::Input::Folder(_) => {
            let path = crate::paths::absolute(&r.path);
            path.parent().map(Path::to_path_buf).unwrap_or(path)
        }
        crate::schema::Input::Glob(_) => common_folder(
            &r.files
                .iter()
                .map(|f| crate::paths::absolute(f))
                .collect::<Vec<_>>(),
        ),
    };
    let rel = |p: &Path| {
        rel_text(p, &root).ok_or_else(|| {
            Error::Core(ibl_core::Error::invalid(
                p,
                format!(
                    "input '{name}' cannot be shipped (not below {})",
                    root.display()
                ),
            ))
        })
    };
    Ok(ReadEntry {
        name: name.to_string(),
        stage: None,
        prefix: String::new(),
        files: r
            .files
            .iter()
            .map(|f| {
                let path = crate::paths::absolute(f);
                // The plan hashed every input it reads (its stamps are in the manifest).
                let hash = manifest
                    .files
                    .get(path.to_string_lossy().as_ref())
                    .map(|st| st.hash.clone());
                Ok(ShippedFile {
                    rel: rel(f)?,
                    path,
                    hash,
                })
            })
            .collect::<Result<_>>()?,
        args: r.args.iter().map(|a| rel(a)).collect::<Result<_>>()?,
    })
}

fn invalid(message: String) -> BakeError {
    BakeError {
        message,
        class: ErrorClass::InvalidInput,
    }
}

/// The parameters of `entry`, rebuilt from their canonical form and checked to give it back.
fn entry_params(
    kind: &'static dyn kinds::Kind,
    entry: &StageEntry,
) -> std::result::Result<kinds::AnyParams, BakeError> {
    let serde_json::Value::Object(fields) = &entry.params else {
        return Err(invalid("the entry's params are not an object".into()));
    };
    let mut p = kind.default_params();
    for (k, v) in fields {
        p = kind.with(&p, k, v.clone()).map_err(invalid)?;
    }
    if p.canonical() != entry.params {
        return Err(invalid(format!(
            "the entry's params do not read back the same ({} instead of {})",
            p.canonical(),
            entry.params
        )));
    }
    Ok(p)
}

/// Runs the stage of `entry` from the inputs materialised under `inputs` and writes a result
/// folder `out` (its `files/` and `stage.json`, both atomically, the report last).
pub fn run_entry(
    entry: &StageEntry,
    inputs: &Path,
    out: &Path,
) -> std::result::Result<StageOutput, BakeError> {
    let t0 = Instant::now();
    if entry.tool != cache::tool() {
        return Err(BakeError {
            message: format!(
                "this bake is build {}, the plan was made by build {}: run the same build everywhere",
                cache::tool(),
                entry.tool
            ),
            class: ErrorClass::Unsupported,
        });
    }
    let kind = kinds::find(&entry.kind).ok_or_else(|| BakeError {
        message: format!(
            "unknown kind '{}' (this build has: {})",
            entry.kind,
            kinds::names().join(", ")
        ),
        class: ErrorClass::Unsupported,
    })?;
    let params = entry_params(kind, entry)?;
    kind.validate(&params)?;
    verify_inputs(entry, inputs)?;
    let mut args = Vec::new();
    for (k, r) in entry.reads.iter().enumerate() {
        for a in &r.args {
            if !cache::is_inside_rel(a) {
                return Err(invalid(format!(
                    "read '{}': argument '{a}' is not a plain relative path",
                    r.name
                )));
            }
            args.push(inputs.join(k.to_string()).join(a));
        }
    }
    let dir = out.join(FILES);
    let baked = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        kind.run(&params, &args, &dir, &ibl_core::progress::NoProgress)
    }))
    .map_err(|panic| BakeError {
        message: format!("the bake panicked: {}", exec::panic_message(&*panic)),
        class: ErrorClass::InvalidInput,
    })??;
    let Baked { files, warnings } = baked;
    let mut outputs = Vec::with_capacity(files.len());
    for (path, bytes) in &files {
        let rel = rel_text(path, &dir).ok_or_else(|| {
            invalid(format!(
                "the bake wrote {} outside its folder {}",
                path.display(),
                dir.display()
            ))
        })?;
        outputs.push(OutputFile {
            rel,
            size: bytes.len() as u64,
            hash: cache::hash_bytes(bytes),
        });
    }
    ibl_core::io::write_many_atomic(&files)?;
    let report = StageOutput {
        id: entry.id.clone(),
        key: entry.key.clone(),
        outputs,
        warnings,
        seconds: t0.elapsed().as_secs_f64(),
    };
    ibl_core::io::write_atomic(
        &out.join(REPORT),
        &serde_json::to_vec_pretty(&report).expect("report serialises"),
    )?;
    Ok(report)
}

/// Checks the inputs materialised under `inputs` against `entry` before anything is baked:
/// each read's folder holds exactly the files the entry lists (regular files, no symlink, no
/// other file a folder read would pick up), and every file whose hash the plan recorded holds
/// those bytes; an input file must have one.
fn verify_inputs(entry: &StageEntry, inputs: &Path) -> std::result::Result<(), BakeError> {
    for (k, r) in entry.reads.iter().enumerate() {
        let root = inputs.join(k.to_string());
        let mut listed = std::collections::BTreeSet::new();
        for f in &r.files {
            if !cache::is_inside_rel(&f.rel) {
                return Err(invalid(format!(
                    "read '{}': file '{}' is not a plain relative path",
                    r.name, f.rel
                )));
            }
            let p = root.join(&f.rel);
            match std::fs::symlink_metadata(&p) {
                Ok(m) if m.is_file() => {}
                Ok(_) => {
                    return Err(invalid(format!(
                        "read '{}': {} is not a regular file (a symlink or a folder)",
                        r.name,
                        p.display()
                    )))
                }
                Err(e) => return Err(invalid(format!("read '{}': {}: {e}", r.name, p.display()))),
            }
            let want = match (&f.hash, &r.stage) {
                (Some(h), _) => h,
                (None, None) => {
                    return Err(invalid(format!(
                        "read '{}': the entry records no hash for input file '{}' (plan it with \
                         this build of bake)",
                        r.name, f.rel
                    )))
                }
                (None, Some(_)) => {
                    listed.insert(p);
                    continue;
                }
            };
            let got = ibl_core::ownership::hash_file(&p)
                .map_err(|e| invalid(format!("read '{}': {}: {e}", r.name, p.display())))?;
            if &got != want {
                return Err(invalid(format!(
                    "read '{}': {} is not the file the plan recorded (blake3 {}…, planned {}…): \
                     a wrong file under --inputs, or damaged on the way",
                    r.name,
                    p.display(),
                    &got[..12],
                    &want[..want.len().min(12)]
                )));
            }
            listed.insert(p);
        }
        // Nothing else: a folder read would bake an extra file too. (A read stage's folder is
        // what its task returned, checked by hash where the plan knew it.)
        if r.stage.is_some() {
            continue;
        }
        let mut stack = vec![root.clone()];
        while let Some(d) = stack.pop() {
            let Ok(rd) = std::fs::read_dir(&d) else {
                continue;
            };
            for e in rd.flatten() {
                let p = e.path();
                let t = e
                    .file_type()
                    .map_err(|err| invalid(format!("{}: {err}", p.display())))?;
                if t.is_dir() {
                    stack.push(p);
                } else if !listed.contains(&p) {
                    return Err(invalid(format!(
                        "read '{}': {} is not one of the files the plan lists for it",
                        r.name,
                        p.display()
                    )));
                }
            }
        }
    }
    Ok(())
}

/// A result folder's files: path relative to the stage's folder, bytes.
type ResultFiles = Vec<(String, Vec<u8>)>;

/// Reads a result folder's report and files, checking every file's size and hash.
fn read_result(dir: &Path) -> std::result::Result<(StageOutput, ResultFiles), String> {
    let report_path = dir.join(REPORT);
    let bytes =
        std::fs::read(&report_path).map_err(|e| format!("{}: {e}", report_path.display()))?;
    let report: StageOutput = serde_json::from_slice(&bytes)
        .map_err(|e| format!("{}: not a stage report: {e}", report_path.display()))?;
    let mut files = Vec::with_capacity(report.outputs.len());
    for o in &report.outputs {
        if !cache::is_inside_rel(&o.rel) {
            return Err(format!(
                "{}: output '{}' is not a plain relative path",
                report_path.display(),
                o.rel
            ));
        }
        let p = dir.join(FILES).join(&o.rel);
        // Read no further than a regular file of the size reported: a symlink could lead
        // anywhere, a larger file is not what the stage wrote.
        match std::fs::symlink_metadata(&p) {
            Ok(m) if m.is_file() && m.len() == o.size => {}
            Ok(m) if m.is_file() => {
                return Err(format!(
                    "{}: {} bytes, the stage reported {} (damaged in transfer?)",
                    p.display(),
                    m.len(),
                    o.size
                ))
            }
            Ok(_) => return Err(format!("{}: not a regular file", p.display())),
            Err(e) => return Err(format!("{}: {e}", p.display())),
        }
        let b = std::fs::read(&p).map_err(|e| format!("{}: {e}", p.display()))?;
        if b.len() as u64 != o.size || cache::hash_bytes(&b) != o.hash {
            return Err(format!(
                "{}: its bytes are not those the stage reported (damaged in transfer?)",
                p.display()
            ));
        }
        files.push((o.rel.clone(), b));
    }
    Ok((report, files))
}

/// Files staged for a commit, and outputs kept where they are.
type StagedAndKept = (Vec<exec::commit::Staged>, Vec<crate::cache::OutputRecord>);

/// Commits result folders (stages run elsewhere) and restores stages from the cache, as
/// `bake run` would: each stage is re-planned here and committed only if its key is the one
/// it ran with. Stages are committed one by one, so an interrupt keeps those done.
pub fn commit(graph: &Graph, results: &[PathBuf], restore: &[String]) -> Result<Vec<StageResult>> {
    let session = Session::open(graph)?;
    let plan = crate::plan::plan(graph, false)?;
    let manifest = Mutex::new(plan.manifest);
    {
        let _g = session.commit_lock();
        session
            .cache
            .save_manifest(&exec::commit::manifest_guard(&manifest))?;
    }
    let result_of = |i: usize, status: Status, reason: String| {
        StageResult::new(&graph.stages[i], status, reason)
    };
    let find = |id: &str| {
        graph.index(id).ok_or_else(|| {
            Error::Core(ibl_core::Error::param(format!(
                "'{id}' is not a stage of {}",
                graph.pipeline.file.display()
            )))
        })
    };
    let mut done = Vec::new();
    let commit_one = |i: usize,
                      staged: std::result::Result<StagedAndKept, String>,
                      status: Status,
                      seconds: f64,
                      warnings: Vec<String>| {
        let planned = &plan.stages[i];
        let staging = session.staging_dir(i, &graph.stages[i].id);
        let mut r = result_of(i, status, planned.decision.reason().to_string());
        r.warnings = warnings;
        r.seconds = seconds;
        let committed = staged.and_then(|(staged, kept)| {
            exec::commit::commit(
                &session, graph, i, planned, staged, kept, seconds, &manifest,
            )
            .map_err(|e| e.to_string())
        });
        match committed {
            Ok(outputs) => r.outputs = outputs,
            Err(e) => {
                r.status = Status::Failed;
                r.reason = e;
            }
        }
        let _ = std::fs::remove_dir_all(&staging);
        r
    };
    for id in restore {
        let i = find(id)?;
        let planned = &plan.stages[i];
        match &planned.decision {
            Decision::Restore(_) => {
                let staging = session.staging_dir(i, &graph.stages[i].id);
                let staged = if planned.items.is_empty() {
                    let key = planned.key.as_deref().expect("work has a key");
                    exec::commit::stage_cached(&session, key, &staging).and_then(|s| {
                        s.map(|s| (s, vec![])).ok_or_else(|| {
                            "its outputs are no longer in the cache: run it".to_string()
                        })
                    })
                } else {
                    // Item by item: the items up to date stay, the others come back.
                    let record = exec::commit::manifest_guard(&manifest)
                        .stages
                        .get(&graph.stages[i].id)
                        .cloned();
                    let mut r = result_of(i, Status::Restored, String::new());
                    exec::stage_items(
                        &session,
                        graph,
                        i,
                        planned,
                        record,
                        &staging,
                        &exec::Quiet,
                        &mut r,
                    )
                };
                done.push(commit_one(i, staged, Status::Restored, 0.0, vec![]));
            }
            Decision::UpToDate => done.push(result_of(i, Status::UpToDate, "up to date".into())),
            d => done.push(result_of(
                i,
                Status::Failed,
                format!("cannot be restored: {} ({})", d.word(), d.reason()),
            )),
        }
    }
    for dir in results {
        let (report, files) = match read_result(dir) {
            Ok(r) => r,
            Err(e) => {
                return Err(Error::Core(ibl_core::Error::invalid(dir, e)));
            }
        };
        let i = find(&report.id)?;
        let (s, planned) = (&graph.stages[i], &plan.stages[i]);
        if planned.key.as_deref() != Some(report.key.as_str()) {
            done.push(result_of(
                i,
                Status::Failed,
                "the pipeline or its inputs changed since this stage was planned: run again".into(),
            ));
            continue;
        }
        // The files must be those the stage's entry writes, no more, no fewer.
        if let Some((kind, params)) = s.runnable() {
            if let Ok(expected) = kind.outputs(params, &graph.input_args(i), &s.dir) {
                let mut want: Vec<String> = expected
                    .iter()
                    .filter_map(|f| rel_text(f, &s.dir))
                    .collect();
                let mut got: Vec<String> = files.iter().map(|(r, _)| r.clone()).collect();
                want.sort();
                got.sort();
                if want != got {
                    done.push(result_of(
                        i,
                        Status::Failed,
                        format!(
                            "{}: the result's files ({}) are not those the stage writes ({})",
                            dir.display(),
                            got.join(", "),
                            want.join(", ")
                        ),
                    ));
                    continue;
                }
            }
        }
        if planned.decision == Decision::UpToDate {
            // Committed meanwhile (by another run): the bytes are those of the same key.
            done.push(result_of(i, Status::UpToDate, "up to date".into()));
            continue;
        }
        // Nothing of the user's is replaced (as `bake run` checks before it starts).
        let targets: Vec<PathBuf> = files.iter().map(|(rel, _)| s.dir.join(rel)).collect();
        let in_the_way = crate::owned::not_ours(
            graph,
            &exec::commit::manifest_guard(&manifest),
            i,
            targets,
            false,
        )
        .and_then(|theirs| crate::owned::refuse(&theirs));
        if let Err(e) = in_the_way {
            done.push(result_of(i, Status::Failed, e.to_string()));
            continue;
        }
        let staging = session.staging_dir(i, &s.id);
        let staged = {
            let _g = session.commit_lock();
            exec::commit::stage_files(
                &staging,
                &s.dir,
                files
                    .into_iter()
                    .map(|(rel, b)| (s.dir.join(rel), b))
                    .collect(),
            )
            .map(|staged| (staged, vec![]))
        };
        done.push(commit_one(
            i,
            staged,
            Status::Ran,
            report.seconds,
            report.warnings,
        ));
    }
    {
        let _g = session.commit_lock();
        let m = exec::commit::manifest_guard(&manifest);
        session.cache.save_manifest(&m)?;
        let _ = session.cache.collect_garbage(&m);
    }
    Ok(done)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_kinds_parameters_read_back_from_their_canonical_form() {
        for kind in kinds::all() {
            for p in [kind.default_params(), kind.example_params()] {
                let entry = StageEntry {
                    id: "s".into(),
                    kind: kind.name().into(),
                    params: p.canonical(),
                    key: String::new(),
                    tool: cache::tool(),
                    dir: "s".into(),
                    reads: vec![],
                    max_memory: None,
                };
                let back = entry_params(kind, &entry)
                    .unwrap_or_else(|e| panic!("{}: {}", kind.name(), e.message));
                assert_eq!(
                    kinds::canonical_text(&back),
                    kinds::canonical_text(&p),
                    "{}",
                    kind.name()
                );
            }
        }
    }

    #[test]
    fn relative_paths_stay_inside_and_globs_share_their_folder() {
        let root = Path::new("/a/b");
        assert_eq!(
            rel_text(Path::new("/a/b/c/d.exr"), root).as_deref(),
            Some("c/d.exr")
        );
        assert_eq!(rel_text(Path::new("/a/b/../x.exr"), root), None);
        assert_eq!(rel_text(Path::new("/a/b"), root), None, "not a file below");
        assert_eq!(rel_text(Path::new("/elsewhere/x"), root), None);
        let files = [
            PathBuf::from("/h/x/one.exr"),
            PathBuf::from("/h/x/y/two.exr"),
            PathBuf::from("/h/z/three.exr"),
        ];
        assert_eq!(common_folder(&files), PathBuf::from("/h"));
        assert_eq!(common_folder(&files[..1]), PathBuf::from("/h/x"));
    }

    #[test]
    fn the_plans_entries_ship_inputs_by_name_and_stages_by_folder() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::create_dir_all(dir.path().join("hdri/sub")).unwrap();
        for f in ["hdri/a.exr", "hdri/sub/b.exr"] {
            std::fs::write(dir.path().join(f), f).unwrap();
        }
        let src = r#"(output: "out", inputs: { "sky": File("hdri/a.exr"), "all": Glob("hdri/sub/*.exr"), "dir": Folder("hdri") },
            stages: [
                (id: "cube", kind: "equirect-to-cube", reads: ["sky"], params: (size: 4)),
                (id: "irr", kind: "irradiance", reads: ["cube"]),
                (id: "g", kind: "equirect-to-cube", reads: ["all"]),
                (id: "f", kind: "equirect-to-cube", reads: ["dir"]),
            ])"#;
        let file = dir.path().join("p.ron");
        std::fs::write(&file, src).unwrap();
        let graph = crate::load(&file).unwrap();
        let plan = crate::plan::plan(&graph, false).unwrap();
        let e = entries(&graph, &plan).unwrap();
        let e: Vec<&StageEntry> = e.iter().map(|e| e.as_ref().unwrap()).collect();
        assert_eq!(e[0].reads[0].args, ["a.exr"]);
        assert_eq!(e[0].reads[0].files[0].rel, "a.exr");
        assert_eq!(e[0].key, plan.stages[0].key.clone().unwrap());
        let irr = &e[1].reads[0];
        assert_eq!(irr.stage.as_deref(), Some("cube"));
        assert_eq!(
            (irr.prefix.as_str(), irr.args[0].as_str()),
            ("cube", "cube")
        );
        let files: Vec<&str> = irr.files.iter().map(|f| f.rel.as_str()).collect();
        // The six faces and the stage's how-to-load note (every cube writer writes one).
        assert!(files.contains(&"cube/LOAD.txt"), "{files:?}");
        let faces: Vec<&&str> = files.iter().filter(|f| f.ends_with(".exr")).collect();
        assert_eq!((faces.len(), files.len()), (6, 7), "{files:?}");
        assert!(faces.iter().all(|f| f.starts_with("cube/")));
        assert_eq!(e[2].reads[0].args, ["b.exr"]);
        assert_eq!(e[2].reads[0].files[0].rel, "b.exr");
        assert_eq!(e[3].reads[0].args, ["hdri"]);
        let dir_files: Vec<&str> = e[3].reads[0].files.iter().map(|f| f.rel.as_str()).collect();
        assert_eq!(dir_files, ["hdri/a.exr", "hdri/sub/b.exr"]);
    }
}
