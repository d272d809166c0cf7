//! The stage graph: declared and scene-derived stages, their reads resolved to inputs or
//! stages, checked (ids, references, arity, cycles, missing inputs) and put in dependency order,
//! with the set of stages the pipeline needs.

use crate::error::{Diagnostic, Error, Result};
use crate::kinds::{AnyParams, Kind};
use crate::need::Need;
use crate::paths;
use crate::scene;
use crate::schema::{Input, Pipeline};
use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};

/// What a stage reads.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Source {
    /// A declared (or scene) input, by name.
    Input(String),
    /// Another stage, by index into [`Graph::stages`].
    Stage(usize),
}

/// Where a stage comes from.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Origin {
    /// Declared in the pipeline's `stages`.
    Declared,
    /// Derived from the pipeline's `scene`.
    Scene,
}

/// A stage of the graph.
#[derive(Clone)]
pub struct Stage {
    /// Its id (also its output folder's name under the output, by default).
    pub id: String,
    /// Its kind's name, as written.
    pub kind_name: String,
    /// `None` only for stages the scene does not need, of kinds this build lacks.
    pub kind: Option<&'static dyn Kind>,
    /// Its parameters (`None` only where `kind` is).
    pub params: Option<AnyParams>,
    /// (name as written, source) of each read, in order.
    pub reads: Vec<(String, Source)>,
    /// The stage's output folder.
    pub dir: PathBuf,
    /// Declared or derived from the scene.
    pub origin: Origin,
    /// Whether it is baked, and why.
    pub need: Need,
    /// Where it is declared in the pipeline file (for messages).
    pub offset: usize,
}

impl Stage {
    /// Whether it is baked.
    pub fn needed(&self) -> bool {
        matches!(self.need, Need::Needed(_))
    }
    /// Kind and parameters of a stage that can run.
    pub fn runnable(&self) -> Option<(&'static dyn Kind, &AnyParams)> {
        Some((self.kind?, self.params.as_ref()?))
    }
    /// Indices of the stages this one reads.
    pub(crate) fn deps(&self) -> impl Iterator<Item = usize> + '_ {
        self.reads.iter().filter_map(|(_, s)| match s {
            Source::Stage(i) => Some(*i),
            Source::Input(_) => None,
        })
    }
}

/// An input with its files found on disk.
#[derive(Clone, Debug)]
pub struct ResolvedInput {
    /// The input as declared.
    pub input: Input,
    /// The resolved path (or pattern for a glob).
    pub path: PathBuf,
    /// Its files: the file itself, a folder's files recursively (sorted), a glob's matches.
    pub files: Vec<PathBuf>,
    /// What a bake is given for it: the file, the folder, or each match.
    pub args: Vec<PathBuf>,
}

/// A checked pipeline, stages in dependency order.
pub struct Graph {
    /// The parsed pipeline.
    pub pipeline: Pipeline,
    /// Its inputs by name, with their files.
    pub inputs: BTreeMap<String, ResolvedInput>,
    /// Its stages, in dependency order.
    pub stages: Vec<Stage>,
}

impl Graph {
    /// The stage with id `id`.
    pub(crate) fn index(&self, id: &str) -> Option<usize> {
        self.stages.iter().position(|s| s.id == id)
    }

    /// The paths stage `i`'s bake is given, in `reads` order.
    pub fn input_args(&self, i: usize) -> Vec<PathBuf> {
        let mut args = Vec::new();
        for (_, src) in &self.stages[i].reads {
            match src {
                Source::Input(name) => args.extend(self.inputs[name].args.iter().cloned()),
                Source::Stage(j) => {
                    let s = &self.stages[*j];
                    let (kind, params) = s.runnable().expect("a read stage is runnable");
                    args.push(kind.product(params, &s.dir));
                }
            }
        }
        args
    }

    /// All stages that read stage `i`, directly or not.
    pub(crate) fn dependants(&self, i: usize) -> Vec<usize> {
        let mut out = vec![false; self.stages.len()];
        let mut stack = vec![i];
        while let Some(k) = stack.pop() {
            for (j, s) in self.stages.iter().enumerate() {
                if !out[j] && s.deps().any(|d| d == k) {
                    out[j] = true;
                    stack.push(j);
                }
            }
        }
        (0..out.len()).filter(|&j| out[j]).collect()
    }
}

/// Checks a stage id: non-empty segments of `[A-Za-z0-9_.-]` separated by `/`, none `.`/`..`.
/// The longest stage id, in bytes (a file name holds 255; the slug of an id names a file).
const MAX_ID: usize = 128;

fn check_id(id: &str) -> std::result::Result<(), String> {
    if id.is_empty() {
        return Err("a stage id cannot be empty".into());
    }
    // An id names a folder, a journal and table columns: a few path segments, not a file.
    if id.len() > MAX_ID {
        let head: String = id.chars().take(24).collect();
        return Err(format!(
            "stage id '{head}…' is {} bytes long, more than {MAX_ID}",
            id.len()
        ));
    }
    for seg in id.split('/') {
        if seg.is_empty() || seg == "." || seg == ".." || seg.starts_with(".bake") {
            return Err(format!(
                "stage id '{id}' has an empty, '.', '..' or '.bake' segment"
            ));
        }
        if let Some(c) = seg
            .chars()
            .find(|c| !(c.is_ascii_alphanumeric() || "_.-".contains(*c)))
        {
            return Err(format!("stage id '{id}' has the character '{c}' (use letters, digits, '_', '.', '-' and '/')"));
        }
    }
    Ok(())
}

/// The inputs a pipeline declares and its scene adds: name → (input, offset in the file).
type InputDecls = BTreeMap<String, (Input, usize)>;

/// Builds and checks the graph of a parsed pipeline. Every problem found is reported at once.
pub fn build(pipeline: Pipeline) -> Result<Graph> {
    let p = &pipeline;
    let mut diags: Vec<Diagnostic> = Vec::new();
    let (mut stages, raw_reads, input_decls) = collect_stages(p, &mut diags);
    let by_id = check_ids(p, &stages, &input_decls, &mut diags);
    check_stage_folders(p, &stages, &mut diags);
    let unresolved = resolve_reads(p, &mut stages, &raw_reads, &input_decls, &by_id, &mut diags);
    let order = dependency_order(p, &stages, &mut diags)?;
    mark_needed(p, &mut stages, &order, &by_id, &mut diags);
    check_needed_params(p, &stages, &mut diags);
    let inputs = resolve_inputs(p, &stages, &input_decls, &mut diags);
    check_arity(p, &stages, &unresolved, &inputs, &mut diags);
    if !diags.is_empty() {
        return Err(Error::Invalid(diags));
    }
    let stages = in_order(stages, &order);
    Ok(Graph {
        pipeline,
        inputs,
        stages,
    })
}

/// Every stage, declared then derived from the scene, with the names each reads (resolved
/// later), and every input, declared and scene-added.
fn collect_stages(
    p: &Pipeline,
    diags: &mut Vec<Diagnostic>,
) -> (Vec<Stage>, Vec<Vec<String>>, InputDecls) {
    let mut stages: Vec<Stage> = Vec::new();
    let mut raw_reads: Vec<Vec<String>> = Vec::new();
    for d in &p.stages {
        let dir = paths::normalize(&p.output.join(d.out.as_deref().unwrap_or(&d.id)));
        stages.push(Stage {
            id: d.id.clone(),
            kind_name: d.kind.name().to_string(),
            kind: Some(d.kind),
            params: Some(d.params.clone()),
            reads: vec![],
            dir,
            origin: Origin::Declared,
            need: Need::Needed("declared".into()),
            offset: d.offset,
        });
        raw_reads.push(d.reads.clone());
    }
    let mut input_decls: InputDecls = p.inputs.clone();
    let Some(scene) = &p.scene else {
        return (stages, raw_reads, input_decls);
    };
    let (derived, scene_inputs) = scene::derive(p, scene, diags);
    for (name, input, at) in scene_inputs {
        if input_decls.contains_key(&name) {
            diags.push(p.diag(
                at,
                format!("scene input '{name}' clashes with a declared input of the same name"),
            ));
        }
        input_decls.insert(name, (input, at));
    }
    for d in derived {
        let kind = crate::kinds::find(d.kind);
        if kind.is_none() && d.need.is_needed() {
            diags.push(p.diag(d.offset, format!("the scene needs stage '{}' of kind '{}', which this build of bake does not have", d.id, d.kind)));
        }
        stages.push(Stage {
            dir: paths::normalize(&p.output.join(&d.id)),
            id: d.id,
            kind_name: d.kind.to_string(),
            kind,
            params: d.params,
            reads: vec![],
            origin: Origin::Scene,
            need: d.need,
            offset: d.offset,
        });
        raw_reads.push(d.reads);
    }
    (stages, raw_reads, input_decls)
}

/// Ids are valid, unique and distinct from input names; returns id → index.
fn check_ids(
    p: &Pipeline,
    stages: &[Stage],
    input_decls: &InputDecls,
    diags: &mut Vec<Diagnostic>,
) -> HashMap<String, usize> {
    let mut by_id: HashMap<String, usize> = HashMap::new();
    for (i, s) in stages.iter().enumerate() {
        if let Err(e) = check_id(&s.id) {
            diags.push(p.diag(s.offset, e));
        }
        if let Some(&j) = by_id.get(s.id.as_str()) {
            let what = if stages[j].origin == Origin::Scene || s.origin == Origin::Scene {
                " (the scene derives a stage of that id)"
            } else {
                ""
            };
            diags.push(p.diag(s.offset, format!("duplicate stage id '{}'{what}", s.id)));
        } else {
            by_id.insert(s.id.clone(), i);
        }
        if input_decls.contains_key(&s.id) {
            diags.push(p.diag(
                s.offset,
                format!("'{}' is both an input and a stage id", s.id),
            ));
        }
    }
    by_id
}

/// Each stage writes to its own folder inside the output, out of `.bake/`.
fn check_stage_folders(p: &Pipeline, stages: &[Stage], diags: &mut Vec<Diagnostic>) {
    let output = paths::normalize(&p.output);
    for s in stages {
        if !paths::is_within(&s.dir, &output)
            || paths::absolute(&s.dir) == paths::absolute(&output)
            || paths::is_within(&s.dir, &output.join(".bake"))
        {
            diags.push(p.diag(
                s.offset,
                format!(
                    "stage '{}' would write to {}, which is not a folder inside the output {}",
                    s.id,
                    s.dir.display(),
                    output.display()
                ),
            ));
        }
    }
    let mut dirs: HashMap<&Path, &str> = HashMap::new();
    for s in stages {
        if let Some(other) = dirs.insert(&s.dir, &s.id).filter(|other| *other != s.id) {
            diags.push(p.diag(
                s.offset,
                format!(
                    "stages '{other}' and '{}' write to the same folder {}",
                    s.id,
                    s.dir.display()
                ),
            ));
        }
    }
}

/// Resolves each stage's reads to inputs or stages; returns which stages had a read that
/// names neither (their arity is not checked).
fn resolve_reads(
    p: &Pipeline,
    stages: &mut [Stage],
    raw_reads: &[Vec<String>],
    input_decls: &InputDecls,
    by_id: &HashMap<String, usize>,
    diags: &mut Vec<Diagnostic>,
) -> Vec<bool> {
    let mut unresolved = vec![false; stages.len()];
    for (i, (s, reads)) in stages.iter_mut().zip(raw_reads).enumerate() {
        for r in reads {
            if input_decls.contains_key(r) {
                s.reads.push((r.clone(), Source::Input(r.clone())));
            } else if let Some(&j) = by_id.get(r.as_str()) {
                s.reads.push((r.clone(), Source::Stage(j)));
            } else {
                let at = p.src[s.offset.min(p.src.len())..]
                    .find(&format!("\"{r}\""))
                    .map(|o| s.offset + o)
                    .unwrap_or(s.offset);
                let mut known: Vec<&str> = input_decls.keys().map(|k| k.as_str()).collect();
                let mut ids: Vec<&str> = by_id.keys().map(|s| s.as_str()).collect();
                ids.sort();
                known.extend(ids);
                diags.push(p.diag(
                    at,
                    format!(
                        "stage '{}' reads '{r}', which is neither an input nor a stage (known: {})",
                        s.id,
                        known.join(", ")
                    ),
                ));
                unresolved[i] = true;
            }
        }
    }
    unresolved
}

/// The stages in dependency order; a cycle is reported with its path and ends the checks.
fn dependency_order(
    p: &Pipeline,
    stages: &[Stage],
    diags: &mut Vec<Diagnostic>,
) -> Result<Vec<usize>> {
    topo_order(stages).map_err(|cycle| {
        let names: Vec<&str> = cycle.iter().map(|&i| stages[i].id.as_str()).collect();
        diags.push(p.diag(
            stages[cycle[0]].offset,
            format!("cycle: {} -> {}", names.join(" -> "), names[0]),
        ));
        Error::Invalid(std::mem::take(diags))
    })
}

/// The pipeline's targets: its `outputs`, or every stage needed of itself.
fn targets(
    p: &Pipeline,
    stages: &[Stage],
    by_id: &HashMap<String, usize>,
    diags: &mut Vec<Diagnostic>,
) -> Vec<usize> {
    let Some(ts) = &p.targets else {
        return (0..stages.len()).filter(|&i| stages[i].needed()).collect();
    };
    ts.iter()
        .filter_map(|(t, at)| match by_id.get(t.as_str()) {
            Some(&i) => Some(i),
            None => {
                let ids: Vec<&str> = stages.iter().map(|s| s.id.as_str()).collect();
                diags.push(p.diag(
                    *at,
                    format!("output '{t}' is not a stage (stages: {})", ids.join(", ")),
                ));
                None
            }
        })
        .collect()
}

/// What is needed: the closure of the targets over reads. A target is needed for its own
/// reason; a stage a needed stage reads is needed by it.
fn mark_needed(
    p: &Pipeline,
    stages: &mut [Stage],
    order: &[usize],
    by_id: &HashMap<String, usize>,
    diags: &mut Vec<Diagnostic>,
) {
    let mut is_target = vec![false; stages.len()];
    for t in targets(p, stages, by_id, diags) {
        is_target[t] = true;
    }
    let mut read_by: Vec<Option<usize>> = vec![None; stages.len()];
    for &i in order.iter().rev() {
        if is_target[i] || read_by[i].is_some() {
            for d in stages[i].deps().collect::<Vec<_>>() {
                read_by[d].get_or_insert(i);
            }
        }
    }
    let explicit_targets = p.targets.is_some();
    let ids: Vec<String> = stages.iter().map(|s| s.id.clone()).collect();
    for (i, s) in stages.iter_mut().enumerate() {
        s.need = match (&s.need, is_target[i], read_by[i]) {
            (Need::Needed(_), true, _) if explicit_targets && s.origin == Origin::Declared => {
                Need::Needed("an output of the pipeline".into())
            }
            (Need::Needed(why), true, _) => Need::Needed(why.clone()),
            (Need::NotNeeded(_), true, _) => Need::Needed("an output of the pipeline".into()),
            (Need::Needed(why), false, Some(_)) if s.origin == Origin::Scene => {
                Need::Needed(why.clone())
            }
            (_, _, Some(by)) => Need::Needed(format!("read by '{}'", ids[by])),
            (Need::NotNeeded(why), _, None) => Need::NotNeeded(why.clone()),
            (Need::Needed(_), _, None) => {
                Need::NotNeeded("not needed by the pipeline's outputs".into())
            }
        };
    }
}

/// Needed stages have a kind in this build and valid parameters. Parameters are checked once
/// it is known what is needed: the scene's parameters of a stage the scene does not need are
/// not checked unless the outputs or a stage need it. (Declared stages were checked as they
/// were parsed; checking them again is harmless.)
fn check_needed_params(p: &Pipeline, stages: &[Stage], diags: &mut Vec<Diagnostic>) {
    for s in stages.iter().filter(|s| s.needed()) {
        if s.kind.is_none() {
            diags.push(p.diag(
                s.offset,
                format!(
                    "stage '{}' needs kind '{}', which this build of bake does not have",
                    s.id, s.kind_name
                ),
            ));
        }
        let Some((kind, params)) = s.runnable() else {
            continue;
        };
        if let Err(e) = kind.validate(params) {
            let msg = match s.origin {
                Origin::Scene => format!(
                    "scene: parameters of '{}' (stage '{}'): {}",
                    s.kind_name, s.id, e.message
                ),
                Origin::Declared => {
                    format!("stage '{}' ({}): {}", s.id, s.kind_name, e.message)
                }
            };
            diags.push(p.diag(s.offset, msg));
        }
    }
}

/// Finds every input's files on disk; an input a needed stage reads must exist.
fn resolve_inputs(
    p: &Pipeline,
    stages: &[Stage],
    input_decls: &InputDecls,
    diags: &mut Vec<Diagnostic>,
) -> BTreeMap<String, ResolvedInput> {
    let used: std::collections::BTreeSet<&str> = stages
        .iter()
        .filter(|s| s.needed())
        .flat_map(|s| {
            s.reads.iter().filter_map(|(_, src)| match src {
                Source::Input(n) => Some(n.as_str()),
                Source::Stage(_) => None,
            })
        })
        .collect();
    let mut inputs = BTreeMap::new();
    for (name, (input, at)) in input_decls {
        let resolved = match resolve_input(p, input) {
            Ok(r) => r,
            Err(why) if used.contains(name.as_str()) => {
                diags.push(p.diag(*at, format!("input '{name}': {why}")));
                continue;
            }
            Err(_) => ResolvedInput {
                input: input.clone(),
                path: p.resolve(input.pattern()),
                files: vec![],
                args: vec![],
            },
        };
        inputs.insert(name.clone(), resolved);
    }
    inputs
}

/// Every needed stage whose reads all resolved reads as many sources as its kind takes.
fn check_arity(
    p: &Pipeline,
    stages: &[Stage],
    unresolved: &[bool],
    inputs: &BTreeMap<String, ResolvedInput>,
    diags: &mut Vec<Diagnostic>,
) {
    for (s, _) in stages
        .iter()
        .zip(unresolved)
        .filter(|(s, unresolved)| s.needed() && !**unresolved)
    {
        let Some(kind) = s.kind else { continue };
        let n: usize = s
            .reads
            .iter()
            .map(|(_, src)| match src {
                Source::Input(name) => inputs.get(name).map(|r| r.args.len()).unwrap_or(1),
                Source::Stage(_) => 1,
            })
            .sum();
        let a = kind.reads();
        if n < a.min || n > a.max {
            diags.push(p.diag(
                s.offset,
                format!(
                    "stage '{}' ({}) {}, but its reads give {n}",
                    s.id,
                    kind.name(),
                    a.describe()
                ),
            ));
        }
    }
}

/// `stages` reordered as `order` says, their reads remapped to the new indices.
fn in_order(stages: Vec<Stage>, order: &[usize]) -> Vec<Stage> {
    let mut new_index = vec![0; stages.len()];
    for (new, &old) in order.iter().enumerate() {
        new_index[old] = new;
    }
    let mut ordered: Vec<Option<Stage>> = stages.into_iter().map(Some).collect();
    let mut stages: Vec<Stage> = order
        .iter()
        .map(|&old| ordered[old].take().expect("each once"))
        .collect();
    for s in &mut stages {
        for (_, src) in &mut s.reads {
            if let Source::Stage(j) = src {
                *j = new_index[*j];
            }
        }
    }
    stages
}

/// Kahn's algorithm, ties broken by declaration order; on a cycle, the stages of one cycle.
fn topo_order(stages: &[Stage]) -> std::result::Result<Vec<usize>, Vec<usize>> {
    let n = stages.len();
    let mut indeg = vec![0usize; n];
    let mut users: Vec<Vec<usize>> = vec![vec![]; n];
    for (i, s) in stages.iter().enumerate() {
        for d in s.deps() {
            indeg[i] += 1;
            users[d].push(i);
        }
    }
    let mut ready: std::collections::BTreeSet<usize> = (0..n).filter(|&i| indeg[i] == 0).collect();
    let mut order = Vec::with_capacity(n);
    while let Some(i) = ready.pop_first() {
        order.push(i);
        for &u in &users[i] {
            indeg[u] -= 1;
            if indeg[u] == 0 {
                ready.insert(u);
            }
        }
    }
    if order.len() == n {
        return Ok(order);
    }
    // Walk backwards along reads from a stage left over: every left-over stage reads another
    // left-over stage, so the walk must revisit one; the loop from there is a cycle.
    let left: Vec<bool> = (0..n).map(|i| indeg[i] > 0).collect();
    let mut path = vec![(0..n).find(|&i| left[i]).expect("a left-over stage")];
    loop {
        let cur = *path.last().unwrap();
        let next = stages[cur]
            .deps()
            .find(|&d| left[d])
            .expect("left-over stages read left-over stages");
        if let Some(pos) = path.iter().position(|&x| x == next) {
            // path goes cur -> next along "reads"; print the cycle in data-flow order.
            let mut cycle: Vec<usize> = path[pos..].to_vec();
            cycle.reverse();
            // Start at the stage declared first, so the message does not depend on the walk.
            let first = (0..cycle.len())
                .min_by_key(|&k| cycle[k])
                .expect("a cycle has a stage");
            cycle.rotate_left(first);
            return Err(cycle);
        }
        path.push(next);
    }
}

/// Finds an input's files on disk.
fn resolve_input(p: &Pipeline, input: &Input) -> std::result::Result<ResolvedInput, String> {
    let path = p.resolve(input.pattern());
    let (files, args) = match input {
        Input::File(_) => {
            if !path.is_file() {
                return Err(if path.exists() {
                    format!("{} is not a file", path.display())
                } else {
                    format!("{} does not exist", path.display())
                });
            }
            (vec![path.clone()], vec![path.clone()])
        }
        Input::Folder(_) => {
            if !path.is_dir() {
                return Err(if path.exists() {
                    format!("{} is not a folder", path.display())
                } else {
                    format!("folder {} does not exist", path.display())
                });
            }
            // The pipeline's own outputs are not part of an input folder that holds them.
            let files: Vec<PathBuf> = walk(&path)
                .map_err(|e| format!("{}: {e}", path.display()))?
                .into_iter()
                .filter(|f| !paths::is_within(f, &p.output))
                .collect();
            (files, vec![path.clone()])
        }
        Input::Glob(_) => {
            let pat = path.to_string_lossy().into_owned();
            let files: Vec<PathBuf> = glob::glob(&pat)
                .map_err(|e| format!("bad glob '{pat}': {e}"))?
                .filter_map(|r| r.ok())
                .filter(|f| f.is_file())
                .collect();
            if files.is_empty() {
                return Err(format!("glob '{}' matches no files", pat));
            }
            (files.clone(), files)
        }
    };
    Ok(ResolvedInput {
        input: input.clone(),
        path,
        files,
        args,
    })
}

/// Files under `dir`, recursively, sorted, skipping hidden entries: the workspace's one
/// walker and symlink policy (`ibl_core::walk`), shared with `quat-map --batch`.
pub(crate) fn walk(dir: &Path) -> std::io::Result<Vec<PathBuf>> {
    ibl_core::walk::files(dir)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::schema;

    fn graph(src: &str) -> Result<Graph> {
        build(schema::parse(Path::new("p.ron"), src.to_string())?)
    }

    fn diags(src: &str) -> Vec<Diagnostic> {
        match graph(src) {
            Err(Error::Invalid(d)) => d,
            Err(e) => panic!("{e}"),
            Ok(_) => panic!("accepted"),
        }
    }

    const E2C: &str = "kind: \"equirect-to-cube\"";

    #[test]
    fn cycles_are_printed_in_data_flow_order() {
        let src = format!("(stages: [(id: \"a\", {E2C}, reads: [\"c\"]), (id: \"b\", {E2C}, reads: [\"a\"]), (id: \"c\", {E2C}, reads: [\"b\"]), (id: \"d\", {E2C}, reads: [\"a\"])])");
        let d = diags(&src);
        eprintln!("{}", d[0]);
        assert_eq!(d.len(), 1);
        assert_eq!(d[0].message, "cycle: a -> b -> c -> a");
        let d = diags(&format!("(stages: [(id: \"s\", {E2C}, reads: [\"s\"])])"));
        assert_eq!(d[0].message, "cycle: s -> s");
    }

    #[test]
    fn unknown_reads_duplicates_and_missing_inputs_are_all_reported() {
        let src = format!(
            "(inputs: {{\"sky\": File(\"no/such.exr\"), \"unused\": File(\"nope.exr\")}}, stages: [(id: \"a\", {E2C}, reads: [\"sky\"]), (id: \"a\", {E2C}, reads: [\"ghost\"]), (id: \"b\", {E2C})])"
        );
        let d = diags(&src);
        for x in &d {
            eprintln!("{x}");
        }
        let all = d
            .iter()
            .map(|x| x.message.clone())
            .collect::<Vec<_>>()
            .join("\n");
        assert!(all.contains("duplicate stage id 'a'"), "{all}");
        assert!(
            all.contains("reads 'ghost', which is neither an input nor a stage"),
            "{all}"
        );
        assert!(
            all.contains("input 'sky': no/such.exr does not exist"),
            "{all}"
        );
        assert!(
            !all.contains("input 'unused'"),
            "unused inputs are not required: {all}"
        );
        assert!(
            all.contains("stage 'b' (equirect-to-cube) reads exactly 1"),
            "{all}"
        );
    }

    #[test]
    fn order_is_topological_and_outputs_select_what_is_needed() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("sky.exr"), b"x").unwrap();
        let src = format!(
            "(inputs: {{\"sky\": File(\"sky.exr\")}}, stages: [(id: \"late\", {E2C}, reads: [\"mid\"]), (id: \"mid\", {E2C}, reads: [\"first\"]), (id: \"first\", {E2C}, reads: [\"sky\"]), (id: \"other\", {E2C}, reads: [\"sky\"])], outputs: [\"mid\"])"
        );
        let g = build(schema::parse(&dir.path().join("p.ron"), src).unwrap()).unwrap();
        let ids: Vec<_> = g.stages.iter().map(|s| s.id.as_str()).collect();
        assert_eq!(ids, ["first", "mid", "late", "other"]);
        let need: Vec<_> = g.stages.iter().map(|s| s.need.clone()).collect();
        assert_eq!(need[0], Need::Needed("read by 'mid'".into()));
        assert_eq!(need[1], Need::Needed("an output of the pipeline".into()));
        assert_eq!(
            need[2],
            Need::NotNeeded("not needed by the pipeline's outputs".into())
        );
        assert_eq!(g.stages[1].reads[0].1, Source::Stage(0));
        assert_eq!(
            g.input_args(1),
            vec![paths::normalize(&dir.path().join("out/first"))]
        );
        assert_eq!(g.dependants(0), vec![1, 2]);
    }

    #[test]
    fn folder_and_glob_inputs_list_their_files() {
        let dir = tempfile::tempdir().unwrap();
        for f in [
            "m/a/normal.png",
            "m/b/normal.png",
            "m/.hidden",
            "h/x.exr",
            "h/y.exr",
            "h/z.txt",
        ] {
            let p = dir.path().join(f);
            std::fs::create_dir_all(p.parent().unwrap()).unwrap();
            std::fs::write(p, f).unwrap();
        }
        let src = format!("(inputs: {{\"m\": Folder(\"m\"), \"h\": Glob(\"h/*.exr\")}}, stages: [(id: \"c\", {E2C}, reads: [\"m\"])])");
        let g = build(schema::parse(&dir.path().join("p.ron"), src).unwrap()).unwrap();
        assert_eq!(g.inputs["m"].files.len(), 2);
        assert_eq!(g.inputs["m"].args, vec![dir.path().join("m")]);
        assert_eq!(g.inputs["h"].args.len(), 2);
        let src = format!(
            "(inputs: {{\"h\": Glob(\"h/*.exr\")}}, stages: [(id: \"c\", {E2C}, reads: [\"h\"])])"
        );
        let d = match build(schema::parse(&dir.path().join("p.ron"), src).unwrap()) {
            Err(Error::Invalid(d)) => d,
            _ => panic!(),
        };
        assert!(d[0].message.contains("its reads give 2"), "{}", d[0]);
    }

    #[test]
    fn stage_folders_stay_inside_the_output_and_apart() {
        for (out, want) in [
            ("../elsewhere", "not a folder inside the output"),
            (".", "not a folder inside the output"),
            ("b", "write to the same folder"),
            (".bake/objects", "not a folder inside the output"),
        ] {
            let src = format!("(stages: [(id: \"a\", {E2C}, out: \"{out}\"), (id: \"b\", {E2C})])");
            let d = diags(&src);
            assert!(d.iter().any(|d| d.message.contains(want)), "{out}: {d:?}");
        }
    }

    #[test]
    fn ids_are_checked() {
        for bad in ["", "a//b", "../x", "a b", ".bake"] {
            assert!(check_id(bad).is_err(), "{bad}");
        }
        // 65,536 characters once panicked in the table's column width: now refused, briefly.
        let long = "a".repeat(65_536);
        let e = check_id(&long).unwrap_err();
        assert!(e.contains("65536 bytes long") && e.len() < 120, "{e}");
        assert!(check_id(&"a".repeat(MAX_ID)).is_ok());
        for good in ["cube", "lobby/cube", "hv-lut/100x10", "a.b_c"] {
            assert!(check_id(good).is_ok(), "{good}");
        }
    }

    #[test]
    #[cfg(all(feature = "material", feature = "lut"))]
    fn scene_parameters_are_checked_only_where_used() {
        let check = |src: &str| match build(
            schema::parse(Path::new("s.ron"), src.into()).unwrap_or_else(|e| panic!("{e}")),
        ) {
            Ok(_) => vec![],
            Err(Error::Invalid(d)) => d,
            Err(e) => panic!("{e}"),
        };
        // 12-bit TPR maps are invalid, but no material uses a TPR map.
        let d = check(
            r#"(scene: (materials: [(id: "a", folder: "f", model: Ggx)], params: {"tpr-map": (size: 8, bits: 12)}))"#,
        );
        assert!(d.is_empty(), "{d:?}");
        let d = check(
            r#"(scene: (materials: [(id: "a", folder: "f", model: Ggx, tpr_map: true)], params: {"tpr-map": (size: 8, bits: 12)}))"#,
        );
        assert_eq!(d.len(), 1, "{d:?}");
        assert!(
            d[0].message.contains("tpr-map") && d[0].message.contains("bits"),
            "{}",
            d[0]
        );
        // A stage the scene does not need, needed by the outputs: checked too.
        let d =
            check(r#"(outputs: ["as-size-bias"], scene: (params: {"as-size-bias": (nu: -5)}))"#);
        assert_eq!(d.len(), 1, "{d:?}");
        assert!(
            d[0].message.contains("as-size-bias") && d[0].message.contains("nu"),
            "{}",
            d[0]
        );
    }
}
