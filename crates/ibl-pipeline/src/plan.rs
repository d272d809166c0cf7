//! Planning: for every stage, its cache key and whether it runs, is restored from the cache,
//! is up to date, or is skipped, with the reason in words.

use crate::cache::{input_digest, CacheDir, Hasher, KeyParts, Manifest, StageRecord};
use crate::error::{Diagnostic, Error, Result};
use crate::graph::{Graph, Source};
use crate::kinds::canonical_text;
use crate::need::Need;
use std::collections::BTreeMap;
use std::path::Path;

/// What happens to a stage.
#[derive(Clone, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(tag = "action", content = "reason", rename_all = "kebab-case")]
pub enum Decision {
    /// The bake runs (why: never built, parameters changed, 'sky' changed, outputs missing...).
    Run(String),
    /// The outputs of this exact key are in the cache: they are put back without baking.
    Restore(String),
    /// Built with this key and its outputs are in place.
    UpToDate,
    /// Not needed (by the scene or by the pipeline's outputs).
    Skip(String),
}

impl Decision {
    /// The action in one word, as `plan --json` writes it.
    pub fn word(&self) -> &'static str {
        match self {
            Decision::Run(_) => "run",
            Decision::Restore(_) => "restore",
            Decision::UpToDate => "up-to-date",
            Decision::Skip(_) => "skip",
        }
    }
    pub fn reason(&self) -> &str {
        match self {
            Decision::Run(r) | Decision::Restore(r) | Decision::Skip(r) => r,
            Decision::UpToDate => "up to date",
        }
    }
    /// Work the executor must do.
    pub fn is_work(&self) -> bool {
        matches!(self, Decision::Run(_) | Decision::Restore(_))
    }
}

/// One stage's plan.
#[derive(Clone, Debug)]
pub struct PlannedStage {
    pub key: Option<String>,
    pub parts: Option<KeyParts>,
    pub decision: Decision,
}

/// The plan of a whole pipeline.
pub struct Plan {
    pub stages: Vec<PlannedStage>,
    /// The manifest as loaded, with the input hash stamps refreshed.
    pub manifest: Manifest,
    /// Stages the manifest has that the pipeline no longer declares.
    pub orphans: Vec<String>,
    pub cache: CacheDir,
}

/// How an output recorded in the manifest compares with the disk.
#[derive(Debug, PartialEq, Eq)]
pub enum OutputState {
    Ok,
    Missing,
    Modified,
}

/// Checks a record's outputs in `dir`: size and mtime first, the hash only when they moved.
pub fn check_outputs(rec: &StageRecord, dir: &Path) -> Vec<(String, OutputState)> {
    rec.outputs
        .iter()
        .map(|o| {
            let path = dir.join(&o.rel);
            let state = match std::fs::metadata(&path) {
                Err(_) => OutputState::Missing,
                Ok(md)
                    if md.len() == o.stamp.size
                        && crate::cache::mtime_ns(&md) == o.stamp.mtime_ns =>
                {
                    OutputState::Ok
                }
                Ok(md) if md.len() != o.stamp.size => OutputState::Modified,
                Ok(_) => match crate::cache::hash_file(&path) {
                    Ok((h, _)) if h == o.stamp.hash => OutputState::Ok,
                    _ => OutputState::Modified,
                },
            };
            (o.rel.clone(), state)
        })
        .collect()
}

fn list(names: &[&String]) -> String {
    const MAX: usize = 3;
    let mut s = names
        .iter()
        .take(MAX)
        .map(|n| n.as_str())
        .collect::<Vec<_>>()
        .join(", ");
    if names.len() > MAX {
        s.push_str(&format!(" and {} more", names.len() - MAX));
    }
    s
}

/// Plans `graph` against what its output folder holds. `force` runs every needed stage.
pub fn plan(graph: &Graph, force: bool) -> Result<Plan> {
    let cache = CacheDir::new(&graph.pipeline.output);
    let mut manifest = cache.load_manifest()?;
    let mut hasher = Hasher::new(&manifest.files);
    let mut diags = Vec::new();

    // Digests of the inputs needed stages read (hashing only what changed since last time).
    let mut digests: BTreeMap<&str, String> = BTreeMap::new();
    for s in graph.stages.iter().filter(|s| s.needed()) {
        for (_, src) in &s.reads {
            let Source::Input(name) = src else { continue };
            if digests.contains_key(name.as_str()) {
                continue;
            }
            let r = &graph.inputs[name];
            let kind = match r.input {
                crate::schema::Input::File(_) => "file",
                crate::schema::Input::Folder(_) => "folder",
                crate::schema::Input::Glob(_) => "glob",
            };
            let mut hashed = Vec::new();
            for f in &r.files {
                match hasher.stamp(f) {
                    Ok(st) => hashed.push((f.clone(), st.hash)),
                    Err(e) => diags.push(Diagnostic::global(
                        &graph.pipeline.file,
                        format!("input '{name}': {}: {e}", f.display()),
                    )),
                }
            }
            let base = if kind == "glob" {
                graph.pipeline.base.clone()
            } else {
                r.path.clone()
            };
            digests.insert(name, input_digest(kind, &base, &hashed));
        }
    }
    if !diags.is_empty() {
        return Err(Error::Invalid(diags));
    }
    let fresh = std::mem::take(&mut hasher.fresh);
    drop(hasher);
    // Keep stamps of the inputs this pipeline reads now only (the cache stays bounded).
    manifest.files = fresh;

    let mut stages: Vec<PlannedStage> = Vec::with_capacity(graph.stages.len());
    for s in &graph.stages {
        match &s.need {
            Need::Needed(_) => {}
            Need::NotNeeded(why) => {
                stages.push(PlannedStage {
                    key: None,
                    parts: None,
                    decision: Decision::Skip(why.clone()),
                });
                continue;
            }
        }
        let (kind, params) = s
            .runnable()
            .expect("needed stages are runnable (checked by the graph)");
        let reads = s
            .reads
            .iter()
            .map(|(name, src)| {
                // Names say what a source is, for "input 'sky' changed" (keys ignore them).
                match src {
                    Source::Input(n) => (format!("input '{name}'"), digests[n.as_str()].clone()),
                    Source::Stage(j) => (
                        format!("upstream '{name}'"),
                        stages[*j]
                            .key
                            .clone()
                            .expect("a needed stage reads needed stages"),
                    ),
                }
            })
            .collect();
        let parts = KeyParts {
            tool: crate::cache::tool_for(kind.library()),
            kind: kind.name().to_string(),
            params: canonical_text(params),
            reads,
        };
        let key = parts.key();
        let rel_dir = s
            .dir
            .strip_prefix(&graph.pipeline.output)
            .unwrap_or(&s.dir)
            .to_string_lossy()
            .into_owned();
        let cached = || cache.entry(&key).is_some();
        let decision = match manifest.stages.get(&s.id) {
            _ if force => Decision::Run("forced".into()),
            Some(rec) if rec.key == key => {
                if rec.dir != rel_dir {
                    if cached() {
                        Decision::Restore("output folder moved".into())
                    } else {
                        Decision::Run("output folder moved".into())
                    }
                } else {
                    let states = check_outputs(rec, &s.dir);
                    let missing: Vec<&String> = states
                        .iter()
                        .filter(|(_, st)| *st == OutputState::Missing)
                        .map(|(n, _)| n)
                        .collect();
                    let modified: Vec<&String> = states
                        .iter()
                        .filter(|(_, st)| *st == OutputState::Modified)
                        .map(|(n, _)| n)
                        .collect();
                    if missing.is_empty() && modified.is_empty() {
                        Decision::UpToDate
                    } else {
                        let mut why = Vec::new();
                        if !missing.is_empty() {
                            why.push(format!("outputs missing: {}", list(&missing)));
                        }
                        if !modified.is_empty() {
                            why.push(format!("outputs modified: {}", list(&modified)));
                        }
                        let why = why.join("; ");
                        if cached() {
                            Decision::Restore(why)
                        } else {
                            Decision::Run(why)
                        }
                    }
                }
            }
            Some(rec) => {
                let why = rec.parts.diff(&parts);
                if cached() {
                    Decision::Restore(format!("{why} (built before with these inputs)"))
                } else {
                    Decision::Run(why)
                }
            }
            None if cached() => Decision::Restore("built before with these inputs".into()),
            None => Decision::Run("never built".into()),
        };
        stages.push(PlannedStage {
            key: Some(key),
            parts: Some(parts),
            decision,
        });
    }
    let orphans = manifest
        .stages
        .keys()
        .filter(|id| graph.index(id).is_none())
        .cloned()
        .collect();
    Ok(Plan {
        stages,
        manifest,
        orphans,
        cache,
    })
}
