//! Planning: for every stage, its cache key and whether it runs, is restored from the cache,
//! is up to date, or is skipped, with the reason in words.

use crate::cache::{input_digest, item_key, CacheDir, Hasher, KeyParts, Manifest, StageRecord};
use crate::error::{Diagnostic, Error, Result};
use crate::graph::Stage;
use crate::graph::{Graph, Source};
use crate::kinds::{canonical_text, Item};
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
    /// Why, in words.
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
    /// Its cache key (`None` for a stage that is skipped).
    pub key: Option<String>,
    /// What the key is made of.
    pub parts: Option<KeyParts>,
    /// What happens to it.
    pub decision: Decision,
    /// For a stage baked item by item that has work: each item's plan (empty otherwise).
    pub items: Vec<PlannedItem>,
}

/// One item's plan, in a stage baked item by item (see [`Item`]).
#[derive(Clone, Debug)]
pub struct PlannedItem {
    /// Its name: its outputs, relative to the stage's folder.
    pub name: String,
    /// What its bake reads and where it writes.
    pub item: Item,
    /// Its cache key ([`item_key`]).
    pub key: String,
    /// The digest of the files it reads.
    pub inputs: String,
    /// Its outputs, relative to the stage's folder.
    pub outputs: Vec<String>,
    /// What happens to it.
    pub decision: Decision,
}

/// The plan of a whole pipeline.
pub struct Plan {
    /// Every stage's plan, in stage order.
    pub stages: Vec<PlannedStage>,
    /// The manifest as loaded, with the input hash stamps refreshed.
    pub manifest: Manifest,
    /// Stages the manifest has that the pipeline no longer declares.
    pub orphans: Vec<String>,
    /// The output folder's cache.
    pub cache: CacheDir,
}

/// How an output recorded in the manifest compares with the disk.
#[derive(Debug, PartialEq, Eq)]
pub(crate) enum OutputState {
    /// In place, as recorded.
    Ok,
    /// Gone.
    Missing,
    /// Changed since it was written.
    Modified,
}

/// Checks a record's outputs in `dir`: size and mtime first, the hash only when they moved.
pub(crate) fn check_outputs(rec: &StageRecord, dir: &Path) -> Vec<(String, OutputState)> {
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
    let mut stages: Vec<PlannedStage> = Vec::with_capacity(graph.stages.len());
    for (i, s) in graph.stages.iter().enumerate() {
        match &s.need {
            Need::Needed(_) => {}
            Need::NotNeeded(why) => {
                stages.push(PlannedStage {
                    key: None,
                    parts: None,
                    decision: Decision::Skip(why.clone()),
                    items: vec![],
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
        let rec = manifest.stages.get(&s.id);
        let mut decision = stage_decision(rec, &parts, &key, &rel_dir, s, force, &cache);
        let mut items = vec![];
        if decision.is_work() {
            if let Some(planned) = plan_items(graph, i, &parts, rec, force, &cache, &mut hasher) {
                decision = items_decision(&decision, &planned, rec);
                items = planned;
            }
        }
        stages.push(PlannedStage {
            key: Some(key),
            parts: Some(parts),
            decision,
            items,
        });
    }
    // Keep stamps of the inputs this pipeline reads now only (the cache stays bounded).
    let fresh = std::mem::take(&mut hasher.fresh);
    drop(hasher);
    manifest.files = fresh;
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

/// "outputs missing: a, b; outputs modified: c", or `None` when every output is in place.
fn outputs_problem(states: &[(String, OutputState)]) -> Option<String> {
    let with = |state: OutputState| -> Vec<&String> {
        states
            .iter()
            .filter(|(_, st)| *st == state)
            .map(|(n, _)| n)
            .collect()
    };
    let (missing, modified) = (with(OutputState::Missing), with(OutputState::Modified));
    let mut why = Vec::new();
    if !missing.is_empty() {
        why.push(format!("outputs missing: {}", list(&missing)));
    }
    if !modified.is_empty() {
        why.push(format!("outputs modified: {}", list(&modified)));
    }
    (!why.is_empty()).then(|| why.join("; "))
}

/// Restore when the cache holds the outputs of `key`, else run; for the same reason.
fn restore_or_run(cache: &CacheDir, key: &str, why: String) -> Decision {
    if cache.entry(key).is_some() {
        Decision::Restore(why)
    } else {
        Decision::Run(why)
    }
}

/// What happens to a needed stage, given its record in the manifest.
fn stage_decision(
    rec: Option<&StageRecord>,
    parts: &KeyParts,
    key: &str,
    rel_dir: &str,
    s: &Stage,
    force: bool,
    cache: &CacheDir,
) -> Decision {
    match rec {
        _ if force => Decision::Run("forced".into()),
        Some(rec) if rec.key == key => {
            if rec.dir != rel_dir {
                restore_or_run(cache, key, "output folder moved".into())
            } else {
                match outputs_problem(&check_outputs(rec, &s.dir)) {
                    None => Decision::UpToDate,
                    Some(why) => restore_or_run(cache, key, why),
                }
            }
        }
        Some(rec) => {
            let why = rec.parts.diff(parts);
            if cache.entry(key).is_some() {
                Decision::Restore(format!("{why} (built before with these inputs)"))
            } else {
                Decision::Run(why)
            }
        }
        None => restore_or_run(cache, key, "never built".into()),
    }
    .with_cached_wording()
}

impl Decision {
    /// "built before with these inputs" for a restore of a stage never built here.
    fn with_cached_wording(self) -> Decision {
        match self {
            Decision::Restore(why) if why == "never built" => {
                Decision::Restore("built before with these inputs".into())
            }
            d => d,
        }
    }
}

/// The plans of the items of stage `i`, when its kind bakes item by item; `None` when it
/// bakes its inputs as one piece (or they cannot be split: the bake will say why).
#[allow(clippy::too_many_arguments)]
fn plan_items(
    graph: &Graph,
    i: usize,
    parts: &KeyParts,
    rec: Option<&StageRecord>,
    force: bool,
    cache: &CacheDir,
    hasher: &mut Hasher,
) -> Option<Vec<PlannedItem>> {
    let s = &graph.stages[i];
    let (kind, params) = s.runnable()?;
    let items = kind.items(params, &graph.input_args(i), &s.dir)?.ok()?;
    let mut planned = Vec::with_capacity(items.len());
    for item in items {
        let mut outputs: Vec<String> = kind
            .outputs(params, &item.inputs, &item.dir)
            .ok()?
            .iter()
            .map(|o| Some(o.strip_prefix(&s.dir).ok()?.to_string_lossy().into_owned()))
            .collect::<Option<_>>()?;
        outputs.sort();
        let name = outputs.join(", ");
        let mut hashed = Vec::new();
        for f in &item.inputs {
            hashed.push((f.clone(), hasher.stamp(f).ok()?.hash));
        }
        let inputs = input_digest("file", &item.dir, &hashed);
        let key = item_key(parts, &name, &inputs);
        let decision = item_decision(rec, parts, &name, &key, &inputs, &outputs, s, force, cache);
        planned.push(PlannedItem {
            name,
            item,
            key,
            inputs,
            outputs,
            decision,
        });
    }
    Some(planned)
}

/// What happens to one item, given the stage's record in the manifest.
#[allow(clippy::too_many_arguments)]
fn item_decision(
    rec: Option<&StageRecord>,
    parts: &KeyParts,
    name: &str,
    key: &str,
    inputs: &str,
    outputs: &[String],
    s: &Stage,
    force: bool,
    cache: &CacheDir,
) -> Decision {
    if force {
        return Decision::Run("forced".into());
    }
    let why = match rec.map(|r| (r, r.items.get(name))) {
        Some((rec, Some(item))) if item.key == key => {
            let states: Vec<(String, OutputState)> = outputs
                .iter()
                .map(|o| match rec.outputs.iter().find(|r| r.rel == *o) {
                    Some(r) => {
                        let one = StageRecord {
                            outputs: vec![r.clone()],
                            ..rec.clone()
                        };
                        check_outputs(&one, &s.dir).remove(0)
                    }
                    None => (o.clone(), OutputState::Missing),
                })
                .collect();
            match outputs_problem(&states) {
                None => return Decision::UpToDate,
                Some(why) => why,
            }
        }
        Some((_, Some(item))) if item.inputs != inputs => "its input changed".to_string(),
        // Same files, another key: the stage's tool or parameters changed.
        Some((rec, Some(_))) => rec.parts.diff(parts),
        Some((_, None)) => "new".to_string(),
        None => "never built".to_string(),
    };
    restore_or_run(cache, key, why)
}

/// The decision of a stage baked item by item, from its items': it runs when an item runs,
/// is restored when items are only restored, and otherwise runs only to record the change
/// (items removed, or files no item reads changed). The reason counts the items.
fn items_decision(stage: &Decision, items: &[PlannedItem], rec: Option<&StageRecord>) -> Decision {
    let names = |f: fn(&Decision) -> bool| -> Vec<&String> {
        items
            .iter()
            .filter(|it| f(&it.decision))
            .map(|it| &it.name)
            .collect()
    };
    let run = names(|d| matches!(d, Decision::Run(_)));
    let restore = names(|d| matches!(d, Decision::Restore(_)));
    let current: std::collections::HashSet<&str> =
        items.iter().map(|it| it.name.as_str()).collect();
    let removed: Vec<&String> = rec
        .map(|r| {
            r.items
                .keys()
                .filter(|n| !current.contains(n.as_str()))
                .collect()
        })
        .unwrap_or_default();
    let mut parts = vec![format!("{} of {} items to bake", run.len(), items.len())];
    if !run.is_empty() {
        parts[0].push_str(&format!(" ({})", list(&run)));
    }
    if !restore.is_empty() {
        parts.push(format!("{} to restore ({})", restore.len(), list(&restore)));
    }
    if !removed.is_empty() {
        parts.push(format!("{} removed ({})", removed.len(), list(&removed)));
    }
    let why = format!("{}: {}", stage.reason(), parts.join(", "));
    if run.is_empty() && !restore.is_empty() {
        Decision::Restore(why)
    } else {
        Decision::Run(why)
    }
}
