//! The commit: a stage's files, encoded in memory by its bake (or linked from the object
//! store), are written to the session's staging folder, then moved into place under a journal
//! (written before the renames, so a killed run is rolled forward), entered in the manifest and
//! kept in the object store. Outputs that already hold the new bytes are left untouched. Also
//! the reverse: `clean` removes what was committed.

use super::session::{Journal, Session};
use crate::cache::{self, ItemRecord, Manifest, OutputRecord, StageRecord};
use crate::error::{Error, Result};
use crate::graph::Graph;
use crate::paths;
use crate::plan::PlannedStage;
use serde::Serialize;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Mutex;

/// The manifest, even if a thread panicked while holding it (it is only ever replaced whole
/// record by record).
pub(crate) fn manifest_guard(m: &Mutex<Manifest>) -> std::sync::MutexGuard<'_, Manifest> {
    m.lock().unwrap_or_else(|e| e.into_inner())
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
    let _g = session.gate();
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

/// Renames staged files into place and records the stage as `planned` (its key, and its
/// items' keys), under the commit lock and a journal. `kept` are outputs of items that were up
/// to date: they stay as they are.
#[allow(clippy::too_many_arguments)]
pub(crate) fn commit(
    session: &Session,
    graph: &Graph,
    i: usize,
    planned: &PlannedStage,
    staged: Vec<Staged>,
    kept: Vec<OutputRecord>,
    seconds: f64,
    manifest: &Mutex<Manifest>,
) -> Result<Vec<PathBuf>> {
    let s = &graph.stages[i];
    let output = &graph.pipeline.output;
    let key = planned.key.clone().expect("work has a key");
    let parts = planned.parts.clone().expect("work has key parts");
    let mut staged = keep_unchanged(&s.dir, staged);
    staged.extend(kept.into_iter().map(|o| (None, o.rel, o.stamp)));
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
        items: BTreeMap::new(),
    };
    let record = StageRecord {
        items: item_records(planned, &record.outputs),
        ..record
    };
    let renames: Vec<(PathBuf, PathBuf)> = staged
        .iter()
        .filter_map(|(p, rel, _)| p.as_ref().map(|p| (p.clone(), s.dir.join(rel))))
        .collect();
    let _g = session.commit_lock();
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
    for item in record.items.values() {
        let files: Vec<OutputRecord> = record
            .outputs
            .iter()
            .filter(|o| item.outputs.contains(&o.rel))
            .cloned()
            .collect();
        let _ = session.cache.put(&item.key, &s.dir, &files);
    }
    {
        let mut m = manifest_guard(manifest);
        m.apply(output, &s.id, record);
        session.cache.save_manifest(&m)?;
    }
    let _ = std::fs::remove_file(&journal_path);
    Ok(staged.iter().map(|(_, rel, _)| s.dir.join(rel)).collect())
}

/// The records of the items of `planned` whose outputs are all among `outputs`.
fn item_records(planned: &PlannedStage, outputs: &[OutputRecord]) -> BTreeMap<String, ItemRecord> {
    planned
        .items
        .iter()
        .filter(|it| {
            it.outputs
                .iter()
                .all(|o| outputs.iter().any(|r| r.rel == *o))
        })
        .map(|it| {
            let record = ItemRecord {
                key: it.key.clone(),
                inputs: it.inputs.clone(),
                outputs: it.outputs.clone(),
                history: vec![],
            };
            (it.name.clone(), record)
        })
        .collect()
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

/// What `clean` removed, and what it left because it is not the runner's to remove.
#[derive(Clone, Debug, Default, Serialize)]
pub struct CleanReport {
    /// Output files removed.
    pub removed: Vec<PathBuf>,
    /// Files named like outputs that were left in place: changed since they were written,
    /// not written by bake, or reached through a symlink out of the output folder.
    pub kept: Vec<PathBuf>,
    /// The cache folder, if there was one (removed whole).
    pub cache: Option<PathBuf>,
}

/// Removes every output the pipeline recorded or would write, and its cache folder.
pub fn clean(session: Session, graph: &Graph) -> Result<CleanReport> {
    clean_output(session, Some(graph))
}

/// Removes every output the manifest of the session's output folder records whose bytes are
/// the ones recorded, and the cache folder; with the pipeline's graph, also what a ninja run
/// of it wrote (files the bakes' CLIs recorded in `.ibl-outputs.json`, bytes unchanged). Any
/// other file is left and reported in [`CleanReport::kept`]. Only the output folder is
/// needed: a pipeline whose inputs are gone can still be cleaned.
pub fn clean_output(session: Session, graph: Option<&Graph>) -> Result<CleanReport> {
    let output = session.cache.output.clone();
    let manifest = session.cache.load_manifest()?;
    // (file, whether it is ours to remove)
    let mut files: Vec<(PathBuf, bool)> = manifest
        .stages
        .values()
        .flat_map(|r| {
            r.outputs
                .iter()
                .map(|o| {
                    let p = paths::normalize(&output.join(&r.dir).join(&o.rel));
                    let ours = crate::owned::matches_stamp(&p, &o.stamp, true);
                    (p, ours)
                })
                .collect::<Vec<_>>()
        })
        .collect();
    // Also what a ninja run of the same pipeline wrote (same files, not in the manifest).
    if let Some(graph) = graph {
        for (i, s) in graph.stages.iter().enumerate() {
            if let (true, Some((kind, params))) = (s.needed(), s.runnable()) {
                if let Ok(outs) = kind.outputs(params, &graph.input_args(i), &s.dir) {
                    for f in outs.iter().map(|f| paths::normalize(f)) {
                        let folder = f.parent().unwrap_or(&s.dir).to_path_buf();
                        let ours = ibl_core::ownership::Record::load(&folder).owns(&folder, &f);
                        files.push((f, ours));
                    }
                }
            }
        }
    }
    // A file both recorded and planned is ours if either record says so.
    files.sort();
    let mut merged: Vec<(PathBuf, bool)> = Vec::with_capacity(files.len());
    for (f, ours) in files {
        match merged.last_mut() {
            Some((last, o)) if *last == f => *o |= ours,
            _ => merged.push((f, ours)),
        }
    }
    let mut report = CleanReport::default();
    let mut records: BTreeMap<PathBuf, ibl_core::ownership::Record> = BTreeMap::new();
    for (f, ours) in merged {
        if std::fs::symlink_metadata(&f).is_err() {
            continue;
        }
        let inside =
            paths::is_within(&f, &output) && ibl_core::ownership::check_inside(&f, &output).is_ok();
        if !(ours && inside) {
            report.kept.push(f);
            continue;
        }
        if std::fs::remove_file(&f).is_ok() {
            let folder = f.parent().unwrap_or(&output).to_path_buf();
            records
                .entry(folder.clone())
                .or_insert_with(|| ibl_core::ownership::Record::load(&folder))
                .remove(&folder, &f);
            report.removed.push(f);
        }
    }
    // The CLIs' records: rewritten without the files removed, removed when empty.
    for (folder, record) in records {
        let path = folder.join(ibl_core::ownership::RECORD);
        if !std::fs::symlink_metadata(&path).is_ok_and(|m| m.is_file()) {
            continue;
        }
        if record.files.is_empty() {
            let _ = std::fs::remove_file(&path);
        } else {
            let _ = record.save(&folder);
        }
    }
    for f in &report.removed {
        paths::remove_empty_parents(f, &output);
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
