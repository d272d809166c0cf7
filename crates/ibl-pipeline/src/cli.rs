//! The `bake` command line: plans, runs and cleans RON bake pipelines, runs one stage for
//! another executor and commits its result (`bake plan|run|clean|stage|commit|kinds`). The
//! binary's `main` calls [`main`]; everything it does is here, over this crate's library.

use crate::exec::{self, Observer, RunReport, StageResult, Status};
use crate::graph::{Graph, Source};
use crate::need::Need;
use crate::plan::{Decision, Plan};
use crate::{kinds, ninja, paths, remote, Error};
use clap::{Parser, Subcommand, ValueEnum};
use ibl_core::error::{Classify, ErrorClass};
use ibl_core::progress::Progress;
use indicatif::{MultiProgress, ProgressBar, ProgressStyle};
use std::io::IsTerminal;
use std::path::{Path, PathBuf};

/// Runs declarative RON bake pipelines: only what changed, only what the scene needs, in
/// parallel, through the same library functions as the bakes' CLIs.
///
/// Relative paths in a pipeline are relative to the pipeline file's folder.
#[derive(Parser)]
#[command(name = "bake", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
    /// Memory the stages' inputs may take once decoded (512M, 8G, ...): a file whose header
    /// declares more is refused before it is decoded [default: min(4 GiB, half the machine's
    /// memory), or $IBL_MAX_MEMORY].
    #[arg(long, global = true, value_name = "SIZE", value_parser = ibl_core::io::budget::parse_size)]
    max_memory: Option<u64>,
}

#[derive(Subcommand)]
enum Cmd {
    /// Print the stage graph and, for every stage, whether it runs and why.
    Plan {
        /// The pipeline (.ron).
        file: PathBuf,
        /// Plan as if every needed stage had to run.
        #[arg(long)]
        force: bool,
        /// Print the plan as JSON on stdout.
        #[arg(long)]
        json: bool,
        /// Write the graph in another form instead: a ninja file whose edges are the bakes'
        /// CLIs, or a Graphviz dot graph.
        #[arg(long, value_enum)]
        emit: Option<Emit>,
        /// Where to write the emitted file (default: build.ninja / stdout for dot).
        #[arg(short, long)]
        output: Option<PathBuf>,
        /// Folder of the bake binaries the ninja edges call (default: this binary's folder).
        #[arg(long)]
        bin_dir: Option<PathBuf>,
    },
    /// Run the pipeline: independent stages in parallel, unchanged ones skipped.
    Run {
        /// The pipeline (.ron).
        file: PathBuf,
        /// Stages run at once, at least 1 (default: the number of cores).
        #[arg(short, long, value_name = "N",
              value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(1..))]
        jobs: Option<usize>,
        /// Re-run every needed stage even if up to date.
        #[arg(long)]
        force: bool,
        /// Replace files in the stages' folders that bake did not write, or that changed
        /// since it wrote them (otherwise refused before any stage runs).
        #[arg(long)]
        overwrite: bool,
        /// Print the summary as JSON on stdout.
        #[arg(long)]
        json: bool,
        /// No progress and no per-stage lines on stderr.
        #[arg(short, long)]
        quiet: bool,
    },
    /// Remove what the pipeline produced and its cache.
    Clean {
        /// The pipeline (.ron).
        file: PathBuf,
        /// Print what was removed as JSON on stdout.
        #[arg(long)]
        json: bool,
    },
    /// Run one stage on its own, from its plan entry (`bake plan --json`, `stages[].entry`) and
    /// its inputs materialised under a folder: what any executor (a Ray task) runs.
    Stage {
        /// The stage's entry (JSON).
        #[arg(long)]
        entry: PathBuf,
        /// Its inputs: one folder per read, numbered in `reads` order, holding that read's
        /// files at their `rel` paths.
        #[arg(long)]
        inputs: PathBuf,
        /// The result folder to write: `files/` (the stage's outputs) and `stage.json`.
        #[arg(long)]
        out: PathBuf,
        /// Print the stage's report (stage.json) on stdout.
        #[arg(long)]
        json: bool,
    },
    /// Commit stages run elsewhere (result folders of `bake stage`) into the pipeline's output
    /// folder and cache exactly as `bake run` does, and restore stages from the cache.
    Commit {
        file: PathBuf,
        /// Result folders written by `bake stage`.
        results: Vec<PathBuf>,
        /// Stages the plan restores from the cache (repeatable).
        #[arg(long, value_name = "STAGE")]
        restore: Vec<String>,
        #[arg(long)]
        json: bool,
    },
    /// Hash every output the manifest records again (size and time are not trusted) and list
    /// those whose bytes changed or that are gone; exit 1 if any.
    Verify {
        /// The pipeline (.ron).
        file: PathBuf,
        /// Print the findings as JSON on stdout.
        #[arg(long)]
        json: bool,
    },
    /// List the stage kinds this build knows, with their parameters and defaults.
    Kinds {
        /// Print the kinds and their parameters as JSON on stdout.
        #[arg(long)]
        json: bool,
    },
}

#[derive(Clone, Copy, ValueEnum)]
enum Emit {
    Ninja,
    Dot,
}

fn exit_code(class: ErrorClass) -> i32 {
    match class {
        ErrorClass::InvalidInput => 2,
        ErrorClass::Unsupported => 3,
        ErrorClass::Io => 4,
    }
}

/// The whole `bake` binary: parses the command line, runs the subcommand, prints its report
/// or its one-line error, and exits with its code.
pub fn main() -> ! {
    let cli = ibl_cli::parse::<Cli>("bake");
    if let Some(m) = cli.max_memory {
        ibl_core::io::budget::set_max_memory(m);
    }
    let json = matches!(
        cli.cmd,
        Cmd::Plan { json: true, .. }
            | Cmd::Run { json: true, .. }
            | Cmd::Clean { json: true, .. }
            | Cmd::Verify { json: true, .. }
            | Cmd::Kinds { json: true }
    );
    let code = match run(cli) {
        Ok(code) => code,
        Err(e) => {
            eprintln!("bake: error: {e}");
            let code = exit_code(e.class());
            if json {
                ibl_cli::print_stdout(&ibl_cli::json_error("bake", &e.to_string(), code, &[]));
            }
            code
        }
    };
    std::process::exit(code)
}

fn run(cli: Cli) -> Result<i32, Error> {
    // The pipeline's `max_memory` applies where the command line names no budget.
    let file_budget = |graph: &Graph| {
        if let (None, Some(m)) = (cli.max_memory, graph.pipeline.max_memory) {
            ibl_core::io::budget::set_max_memory(m);
        }
    };
    match cli.cmd {
        Cmd::Kinds { json } => {
            print_kinds(json);
            Ok(0)
        }
        Cmd::Plan {
            file,
            force,
            json,
            emit,
            output,
            bin_dir,
        } => {
            let graph = crate::load(&file)?;
            match emit {
                Some(Emit::Ninja) => {
                    let out = output.unwrap_or_else(|| PathBuf::from("build.ninja"));
                    let bin_dir = bin_dir
                        .or_else(|| {
                            std::env::current_exe()
                                .ok()
                                .and_then(|p| p.parent().map(Path::to_path_buf))
                        })
                        .unwrap_or_else(|| PathBuf::from("."));
                    let text = ninja::emit(&graph, &out, &paths::absolute(&bin_dir))?;
                    ibl_core::io::write_atomic(&out, text.as_bytes())?;
                    eprintln!(
                        "bake: wrote {} ({} edges); run it with `ninja -C {}`",
                        out.display(),
                        text.matches("\nbuild ").count(),
                        out.parent()
                            .filter(|p| !p.as_os_str().is_empty())
                            .unwrap_or(Path::new("."))
                            .display()
                    );
                    Ok(0)
                }
                Some(Emit::Dot) => {
                    let text = dot(&graph);
                    match output {
                        Some(out) => ibl_core::io::write_atomic(&out, text.as_bytes())?,
                        None => print!("{text}"),
                    }
                    Ok(0)
                }
                None => {
                    let plan = crate::plan::plan(&graph, force)?;
                    if json {
                        let entries = remote::entries(&graph, &plan)?;
                        println!(
                            "{}",
                            serde_json::to_string_pretty(&plan_json(&graph, &plan, &entries))
                                .expect("plan serialises")
                        );
                    } else {
                        print_plan(&graph, &plan);
                    }
                    Ok(0)
                }
            }
        }
        Cmd::Run {
            file,
            jobs,
            force,
            overwrite,
            json,
            quiet,
        } => {
            let graph = crate::load(&file)?;
            file_budget(&graph);
            let session = exec::Session::open(&graph)?;
            let plan = crate::plan::plan(&graph, force)?;
            // Before any stage runs: nothing of the user's is in the way.
            crate::owned::check_writes(&graph, &plan, overwrite)?;
            let jobs = jobs.unwrap_or_else(|| {
                std::thread::available_parallelism()
                    .map(|n| n.get())
                    .unwrap_or(1)
            });
            let show = !quiet && !json;
            let work = plan.stages.iter().filter(|p| p.decision.is_work()).count();
            let term = Term::new(show && std::io::stderr().is_terminal(), show, work);
            let report = exec::run(&session, &graph, plan, jobs, &term)?;
            drop(session);
            term.clear();
            if json {
                println!(
                    "{}",
                    serde_json::to_string_pretty(&report).expect("report serialises")
                );
            } else {
                print_report(&report);
            }
            Ok(if report.failed() { 1 } else { 0 })
        }
        Cmd::Stage {
            entry,
            inputs,
            out,
            json,
        } => {
            let text = std::fs::read(&entry).map_err(|e| Error::io(&entry, e))?;
            let e: remote::StageEntry = serde_json::from_slice(&text).map_err(|e| {
                Error::Core(ibl_core::Error::invalid(
                    &entry,
                    format!("not a stage entry: {e}"),
                ))
            })?;
            if let (None, Some(m)) = (cli.max_memory, e.max_memory) {
                ibl_core::io::budget::set_max_memory(m);
            }
            match remote::run_entry(&e, &inputs, &out) {
                Ok(report) => {
                    if json {
                        println!(
                            "{}",
                            serde_json::to_string_pretty(&report).expect("report serialises")
                        );
                    }
                    for w in &report.warnings {
                        eprintln!("bake: warning: {}: {w}", e.id);
                    }
                    Ok(0)
                }
                Err(err) => {
                    eprintln!("bake: error: stage '{}': {}", e.id, err.message);
                    Ok(exit_code(err.class))
                }
            }
        }
        Cmd::Commit {
            file,
            results,
            restore,
            json,
        } => {
            let graph = crate::load(&file)?;
            let done = remote::commit(&graph, &results, &restore)?;
            if json {
                println!(
                    "{}",
                    serde_json::to_string_pretty(&done).expect("results serialise")
                );
            }
            let mut failed = false;
            for r in &done {
                if r.status == Status::Failed {
                    failed = true;
                    eprintln!("bake: error: stage '{}': {}", r.id, r.reason);
                }
            }
            Ok(if failed { 1 } else { 0 })
        }
        Cmd::Verify { file, json } => {
            let pipeline = crate::schema::load(&file)?;
            let (checked, damaged) = crate::owned::verify(&pipeline.output)?;
            if json {
                println!(
                    "{}",
                    serde_json::to_string_pretty(
                        &serde_json::json!({"checked": checked, "damaged": damaged})
                    )
                    .expect("findings serialise")
                );
            } else {
                for d in &damaged {
                    println!("{} {} (stage '{}')", d.state, d.path.display(), d.stage);
                }
                println!(
                    "bake: {checked} output(s) hashed, {} not as recorded{}",
                    damaged.len(),
                    if damaged.is_empty() {
                        ""
                    } else {
                        ": re-bake them with `bake run --force --overwrite`"
                    }
                );
            }
            Ok(if damaged.is_empty() { 0 } else { 1 })
        }
        Cmd::Clean { file, json } => {
            // Cleaning needs the output folder and its manifest, not the inputs: the graph
            // (which checks them) only adds the files a ninja run would have written.
            let pipeline = crate::schema::load(&file)?;
            let output = pipeline.output.clone();
            let graph = crate::graph::build(pipeline).ok();
            let session = exec::Session::open_output(&output)?;
            let report = exec::clean_output(session, graph.as_ref())?;
            if json {
                println!(
                    "{}",
                    serde_json::to_string_pretty(&report).expect("report serialises")
                );
            } else {
                println!(
                    "bake: removed {} file(s){} under {}",
                    report.removed.len(),
                    if report.cache.is_some() {
                        " and the cache"
                    } else {
                        ""
                    },
                    output.display()
                );
                for k in &report.kept {
                    eprintln!(
                        "bake: kept {}: not written by bake, or changed since (remove it yourself)",
                        k.display()
                    );
                }
            }
            Ok(0)
        }
    }
}

fn reads_text(graph: &Graph, i: usize) -> String {
    let s = &graph.stages[i];
    if s.reads.is_empty() {
        return "-".into();
    }
    s.reads
        .iter()
        .map(|(n, _)| n.as_str())
        .collect::<Vec<_>>()
        .join(", ")
}

/// Prints rows as aligned columns (the last one unpadded).
fn table(rows: &[Vec<String>]) {
    let cols = rows.iter().map(|r| r.len()).max().unwrap_or(0);
    let widths: Vec<usize> = (0..cols)
        .map(|c| {
            rows.iter()
                .filter_map(|r| r.get(c))
                .map(|s| s.chars().count())
                .max()
                .unwrap_or(0)
        })
        .collect();
    for r in rows {
        let mut line = String::new();
        for (c, cell) in r.iter().enumerate() {
            if c + 1 == r.len() {
                line.push_str(cell);
            } else {
                line.push_str(&format!("{cell:<w$}  ", w = widths[c]));
            }
        }
        println!("{}", line.trim_end());
    }
}

fn print_plan(graph: &Graph, plan: &Plan) {
    let count = |f: fn(&Decision) -> bool| plan.stages.iter().filter(|p| f(&p.decision)).count();
    println!(
        "pipeline {} -> {}",
        graph.pipeline.file.display(),
        graph.pipeline.output.display()
    );
    println!(
        "{} stages: {} to run, {} to restore from the cache, {} up to date, {} not needed\n",
        graph.stages.len(),
        count(|d| matches!(d, Decision::Run(_))),
        count(|d| matches!(d, Decision::Restore(_))),
        count(|d| matches!(d, Decision::UpToDate)),
        count(|d| matches!(d, Decision::Skip(_))),
    );
    let mut rows = vec![vec![
        "STAGE".into(),
        "KIND".into(),
        "READS".into(),
        "ACTION".into(),
        "WHY".into(),
    ]];
    for (i, (s, p)) in graph.stages.iter().zip(&plan.stages).enumerate() {
        let mut why = p.decision.reason().to_string();
        if let (Need::Needed(need), true) = (
            &s.need,
            p.decision.is_work() || p.decision == Decision::UpToDate,
        ) {
            if need != "declared" {
                why.push_str(&format!(" [{need}]"));
            }
        }
        rows.push(vec![
            s.id.clone(),
            s.kind_name.clone(),
            reads_text(graph, i),
            p.decision.word().into(),
            why,
        ]);
    }
    table(&rows);
    print_items(graph, plan);
    if !plan.orphans.is_empty() {
        println!(
            "\nno longer in the pipeline (outputs kept until `bake clean`): {}",
            plan.orphans.join(", ")
        );
    }
}

/// The items of stages baked item by item that have work: which run or are restored, and why.
fn print_items(graph: &Graph, plan: &Plan) {
    for (s, p) in graph.stages.iter().zip(&plan.stages) {
        if p.items.is_empty() {
            continue;
        }
        println!("\n{} item by item:", s.id);
        let mut rows = vec![vec!["  ITEM".into(), "ACTION".into(), "WHY".into()]];
        for it in p.items.iter().filter(|it| it.decision.is_work()) {
            rows.push(vec![
                format!("  {}", it.name),
                it.decision.word().into(),
                it.decision.reason().into(),
            ]);
        }
        table(&rows);
        let idle = p.items.iter().filter(|it| !it.decision.is_work()).count();
        if idle > 0 {
            println!("  and {idle} up to date");
        }
    }
}

fn plan_json(
    graph: &Graph,
    plan: &Plan,
    entries: &[Option<remote::StageEntry>],
) -> serde_json::Value {
    let stages: Vec<serde_json::Value> = graph
        .stages
        .iter()
        .zip(&plan.stages)
        .enumerate()
        .map(|(i, (s, p))| {
            let outputs = s.runnable().filter(|_| s.needed()).and_then(|(k, params)| k.outputs(params, &graph.input_args(i), &s.dir).ok()).unwrap_or_default();
            serde_json::json!({
                "id": s.id,
                "kind": s.kind_name,
                "reads": s.reads.iter().map(|(n, src)| serde_json::json!({"name": n, "type": if matches!(src, Source::Stage(_)) {"stage"} else {"input"}})).collect::<Vec<_>>(),
                "dir": s.dir,
                "origin": format!("{:?}", s.origin).to_lowercase(),
                "needed": s.needed(),
                "need": match &s.need { Need::Needed(w) | Need::NotNeeded(w) => w.clone() },
                "action": p.decision.word(),
                "reason": p.decision.reason(),
                "key": p.key,
                "params": s.params.as_ref().map(|p| p.canonical()),
                "outputs": outputs,
                "items": p.items.iter().map(|it| serde_json::json!({"name": it.name, "action": it.decision.word(), "reason": it.decision.reason(), "key": it.key})).collect::<Vec<_>>(),
                "entry": entries[i],
            })
        })
        .collect();
    serde_json::json!({ "pipeline": graph.pipeline.file, "output": graph.pipeline.output, "stages": stages, "orphans": plan.orphans })
}

fn dot(graph: &Graph) -> String {
    let mut s = String::from(
        "digraph bake {\n  rankdir=LR;\n  node [shape=box, fontname=\"monospace\"];\n",
    );
    for name in graph.inputs.keys() {
        s.push_str(&format!(
            "  \"input:{name}\" [label=\"{name}\", shape=note];\n"
        ));
    }
    for (i, st) in graph.stages.iter().enumerate() {
        let style = if st.needed() {
            ""
        } else {
            ", style=dashed, color=gray"
        };
        s.push_str(&format!(
            "  \"{}\" [label=\"{}\\n({})\"{style}];\n",
            st.id, st.id, st.kind_name
        ));
        for (n, src) in &graph.stages[i].reads {
            let from = match src {
                Source::Input(_) => format!("input:{n}"),
                Source::Stage(_) => n.clone(),
            };
            s.push_str(&format!("  \"{from}\" -> \"{}\";\n", st.id));
        }
    }
    s.push_str("}\n");
    s
}

fn print_report(r: &RunReport) {
    let mut rows = vec![vec![
        "STAGE".into(),
        "KIND".into(),
        "STATUS".into(),
        "TIME".into(),
        "OUTPUTS".into(),
    ]];
    for s in &r.stages {
        let time = if matches!(s.status, Status::Ran | Status::Restored | Status::Failed) {
            format!("{:.2} s", s.seconds)
        } else {
            "-".into()
        };
        let outputs = match s.status {
            Status::Ran | Status::Restored | Status::UpToDate => outputs_text(&s.outputs),
            _ => s.reason.clone(),
        };
        rows.push(vec![
            s.id.clone(),
            s.kind.clone(),
            s.status.word().into(),
            time,
            outputs,
        ]);
    }
    table(&rows);
    println!(
        "\n{} ran, {} restored, {} up to date, {} skipped, {} failed, {} blocked in {:.2} s",
        r.count(Status::Ran),
        r.count(Status::Restored),
        r.count(Status::UpToDate),
        r.count(Status::Skipped),
        r.count(Status::Failed),
        r.count(Status::Blocked),
        r.seconds
    );
    for s in r.stages.iter().filter(|s| s.status == Status::Failed) {
        eprintln!("bake: error: stage '{}': {}", s.id, s.reason);
    }
}

/// "6 files in out/probe/cube" or the single file.
fn outputs_text(outputs: &[PathBuf]) -> String {
    match outputs {
        [] => "-".into(),
        [one] => one.display().to_string(),
        many => {
            let first = many[0].parent().unwrap_or(Path::new("."));
            if many.iter().all(|p| p.parent() == Some(first)) {
                format!("{} files in {}", many.len(), first.display())
            } else {
                format!("{} files under {}", many.len(), common_dir(many).display())
            }
        }
    }
}

fn common_dir(ps: &[PathBuf]) -> PathBuf {
    let mut c = ps[0].parent().unwrap_or(Path::new(".")).to_path_buf();
    while !ps.iter().all(|p| p.starts_with(&c)) {
        if !c.pop() {
            break;
        }
    }
    c
}

/// Progress bars per running stage on a terminal; one line per finished stage otherwise.
struct Term {
    multi: Option<MultiProgress>,
    /// Stages done out of the stages with work, above the per-stage bars.
    overall: Option<ProgressBar>,
    lines: bool,
}

impl Term {
    fn new(bars: bool, lines: bool, work: usize) -> Self {
        let multi = bars.then(MultiProgress::new);
        let overall = multi.as_ref().filter(|_| work > 0).map(|m| {
            let b = m.add(ProgressBar::new(work as u64));
            b.set_style(
                ProgressStyle::with_template("{msg:<36} {pos}/{len} stages, {elapsed}")
                    .expect("static template"),
            );
            b.set_message("bake");
            b
        });
        Term {
            multi,
            overall,
            lines,
        }
    }
    fn clear(&self) {
        if let Some(b) = &self.overall {
            b.finish_and_clear();
        }
        if let Some(m) = &self.multi {
            let _ = m.clear();
        }
    }
    fn line(&self, s: String) {
        match &self.multi {
            Some(m) => {
                let _ = m.println(s);
            }
            None => eprintln!("{s}"),
        }
    }
}

impl Observer for Term {
    fn started(&self, id: &str, decision: &Decision) {
        if self.lines && self.multi.is_none() {
            eprintln!(
                "bake: {} {id} ({})",
                if matches!(decision, Decision::Restore(_)) {
                    "restoring"
                } else {
                    "running"
                },
                decision.reason()
            );
        }
    }
    fn progress(&self, id: &str) -> Box<dyn Progress + '_> {
        match &self.multi {
            Some(m) => {
                let bar = m.add(ProgressBar::new(0));
                bar.set_style(
                    ProgressStyle::with_template("{msg:<36} [{bar:30}] {percent:>3}% {eta}")
                        .expect("static template")
                        .progress_chars("=> "),
                );
                bar.set_message(id.to_string());
                Box::new(Bar {
                    bar,
                    id: id.to_string(),
                })
            }
            None => Box::new(ibl_core::progress::NoProgress),
        }
    }
    fn finished(&self, r: &StageResult) {
        let work = matches!(
            r.status,
            Status::Ran | Status::Restored | Status::Failed | Status::Blocked
        );
        if let (Some(b), true) = (&self.overall, work) {
            b.inc(1);
        }
        if self.lines && work {
            let detail = if r.status == Status::Failed || r.status == Status::Blocked {
                r.reason.clone()
            } else if !r.items.is_empty() {
                let baked = r.items.iter().filter(|i| i.status == Status::Ran).count();
                format!(
                    "{baked} of {} items baked, {:.2} s",
                    r.items.len(),
                    r.seconds
                )
            } else {
                format!("{:.2} s", r.seconds)
            };
            self.line(format!("bake: {:<10} {} ({detail})", r.status.word(), r.id));
            for w in &r.warnings {
                self.line(format!("bake: warning: {}: {w}", r.id));
            }
        }
    }
}

struct Bar {
    bar: ProgressBar,
    id: String,
}

impl Progress for Bar {
    fn start(&self, label: &str, total: u64) {
        self.bar.reset();
        self.bar.set_length(total);
        self.bar.set_message(format!("{}: {label}", self.id));
    }
    fn inc(&self, n: u64) {
        self.bar.inc(n);
    }
}

impl Drop for Bar {
    fn drop(&mut self) {
        self.bar.finish_and_clear();
    }
}

fn print_kinds(json: bool) {
    let all = kinds::all();
    if json {
        let v: Vec<serde_json::Value> = all
            .iter()
            .map(|k| serde_json::json!({"kind": k.name(), "command": k.command(), "reads": k.reads().describe(), "summary": k.summary(), "defaults": k.default_params().canonical()}))
            .collect();
        println!(
            "{}",
            serde_json::to_string_pretty(&v).expect("kinds serialise")
        );
        return;
    }
    for k in all {
        println!(
            "{:<18} {} ({}; CLI: {})",
            k.name(),
            k.summary(),
            k.reads().describe(),
            k.command().join(" ")
        );
        if let serde_json::Value::Object(m) = k.default_params().canonical() {
            let ps: Vec<String> = k
                .param_names()
                .iter()
                .map(|n| {
                    format!(
                        "{n}: {}",
                        m.get(n)
                            .map(|v| if v.is_null() {
                                "none".to_string()
                            } else {
                                v.to_string()
                            })
                            .unwrap_or_default()
                    )
                })
                .collect();
            println!("{:<18} params: ({})", "", ps.join(", "));
        }
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn help_has_no_rustdoc_links_or_file_citations() {
        let problems = ibl_cli::help_problems(<super::Cli as clap::CommandFactory>::command());
        assert!(problems.is_empty(), "{problems:#?}");
    }
}
