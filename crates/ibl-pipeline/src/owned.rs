//! What the runner may touch: only files its manifest records with their bytes unchanged
//! (or that a bake's CLI, run by a ninja file, recorded in its folder's `.ibl-outputs.json`),
//! inside the output folder as the file system resolves it. Checked before any stage runs:
//! `bake run` refuses to replace anything else, naming the file (`--overwrite` when the user
//! means it); the stale-output removal of a re-run and `bake clean` leave anything else in
//! place and say so.

use crate::cache::{Manifest, OutputRecord};
use crate::error::{Error, Result};
use crate::graph::Graph;
use crate::plan::Plan;
use ibl_core::ownership;
use std::path::{Path, PathBuf};

/// Whether a file still holds the bytes its stamp records (in [`crate::cache`], beside the
/// stamp, so the cache needs nothing of this module).
pub(crate) use crate::cache::matches_stamp;

/// Whether `path`, an output of the stage with id `id` in folder `dir`, is the runner's to
/// replace or remove: the manifest records it with these bytes, or a CLI run of the same bake
/// (a ninja edge) recorded it in its folder.
pub(crate) fn is_ours(manifest: &Manifest, id: &str, dir: &Path, path: &Path) -> bool {
    let recorded = manifest.stages.get(id).and_then(|r| {
        let rel = path.strip_prefix(dir).ok()?.to_string_lossy().into_owned();
        r.outputs.iter().find(|o| o.rel == rel).cloned()
    });
    if let Some(OutputRecord { stamp, .. }) = recorded {
        if matches_stamp(path, &stamp, false) {
            return true;
        }
    }
    let folder = path.parent().unwrap_or(dir);
    ownership::Record::load(folder).owns(folder, path)
}

/// The output folder of a pipeline, refused at a filesystem root, a system folder or the home
/// folder itself.
pub fn check_output_folder(output: &Path) -> Result<()> {
    Ok(ownership::check_output_folder(
        output,
        "the pipeline's output",
        true,
    )?)
}

/// Checks, before any stage runs, that every file the work of `plan` writes lies inside the
/// output folder (no symlink leads out) and is absent or the runner's own (see [`is_ours`]);
/// unless `overwrite`, anything else in the way is refused, naming the file.
pub fn check_writes(graph: &Graph, plan: &Plan, overwrite: bool) -> Result<()> {
    let mut theirs: Vec<(PathBuf, String)> = Vec::new();
    for (i, (s, p)) in graph.stages.iter().zip(&plan.stages).enumerate() {
        if !p.decision.is_work() {
            continue;
        }
        let Some((kind, params)) = s.runnable() else {
            continue;
        };
        let mut files: Vec<PathBuf> = kind
            .outputs(params, &graph.input_args(i), &s.dir)
            .unwrap_or_default();
        for it in &p.items {
            files.extend(it.outputs.iter().map(|o| s.dir.join(o)));
        }
        theirs.extend(not_ours(graph, &plan.manifest, i, files, overwrite)?);
    }
    refuse(&theirs)
}

/// The files of `files` (outputs of stage `i`) in the way: present and not the runner's
/// (none when `overwrite`); an error for a file outside the output folder or behind a symlink.
pub(crate) fn not_ours(
    graph: &Graph,
    manifest: &Manifest,
    i: usize,
    mut files: Vec<PathBuf>,
    overwrite: bool,
) -> Result<Vec<(PathBuf, String)>> {
    let s = &graph.stages[i];
    files.sort();
    files.dedup();
    let mut theirs = Vec::new();
    for f in files {
        ownership::check_inside(&f, &graph.pipeline.output)?;
        if overwrite || std::fs::symlink_metadata(&f).is_err() {
            continue;
        }
        if !is_ours(manifest, &s.id, &s.dir, &f) {
            theirs.push((f, s.id.clone()));
        }
    }
    Ok(theirs)
}

/// The error for files in the way (the first named, the others counted), or `Ok`.
pub(crate) fn refuse(theirs: &[(PathBuf, String)]) -> Result<()> {
    let Some((first, id)) = theirs.first() else {
        return Ok(());
    };
    let more = match theirs.len() {
        1 => String::new(),
        n => format!(" (and {} more)", n - 1),
    };
    Err(Error::Core(ibl_core::Error::invalid(
        first,
        format!(
            "stage '{id}' would replace this file{more}, which bake did not write or which \
             changed since: move it away, or pass --overwrite to replace it"
        ),
    )))
}

/// One output `verify` found not as recorded.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Damaged {
    /// The stage that wrote it.
    pub stage: String,
    /// The file.
    pub path: PathBuf,
    /// `missing`, or `modified` (other bytes, whatever its size and time say).
    pub state: &'static str,
}

/// `bake verify`: every output the manifest of `output` records, hashed again (size and mtime
/// are not trusted: bit rot keeps both); the number hashed and the files not as recorded. The
/// cheap size+mtime check of `bake run` does not see bit rot; `verify` does.
pub fn verify(output: &Path) -> Result<(usize, Vec<Damaged>)> {
    let manifest = crate::cache::CacheDir::new(output).load_manifest()?;
    let mut checked = 0;
    let mut damaged = Vec::new();
    for (id, r) in &manifest.stages {
        for o in &r.outputs {
            let path = output.join(&r.dir).join(&o.rel);
            checked += 1;
            let state = if std::fs::symlink_metadata(&path).is_err() {
                "missing"
            } else if matches_stamp(&path, &o.stamp, true) {
                continue;
            } else {
                "modified"
            };
            damaged.push(Damaged {
                stage: id.clone(),
                path,
                state,
            });
        }
    }
    Ok((checked, damaged))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cache::FileStamp;

    #[test]
    fn a_stamp_matches_only_the_same_bytes_in_a_regular_file() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("a.exr");
        std::fs::write(&p, b"bytes").unwrap();
        let md = std::fs::metadata(&p).unwrap();
        let stamp = FileStamp {
            size: 5,
            mtime_ns: crate::cache::mtime_ns(&md),
            hash: crate::cache::hash_bytes(b"bytes"),
        };
        assert!(matches_stamp(&p, &stamp, false));
        assert!(matches_stamp(&p, &stamp, true));
        // Same size, other bytes, the time moved: the hash decides.
        std::fs::write(&p, b"BYTES").unwrap();
        let moved = FileStamp {
            mtime_ns: 1,
            ..stamp.clone()
        };
        assert!(!matches_stamp(&p, &moved, false));
        assert!(!matches_stamp(&p, &stamp, true));
    }
}
