//! Benchmark of the runner on the example pipelines: a cold run with 1 and 2 stage workers,
//! the no-op run that follows (what the cache costs), and the run after one input changed.
//! There is no error to trade here (the bakes are the bakes' own benchmarks' business): the
//! table is time and work (stages baked) only.
//!
//! `cargo run --release -p ibl-pipeline --example bench-ibl-pipeline -- [--quick]` prints a markdown table
//! and writes it to `bench/bake.md` under the workspace root.

use ibl_pipeline::exec::{self, Quiet, Status};
use ibl_testkit::{copy_tree, workspace_root as root};
use std::path::Path;
use std::time::Instant;

/// Runs `file` once; (seconds, stages baked).
fn run(file: &Path, jobs: usize) -> (f64, usize) {
    let t = Instant::now();
    let graph = ibl_pipeline::load(file).unwrap();
    let session = exec::Session::open(&graph).unwrap();
    let plan = ibl_pipeline::plan::plan(&graph, false).unwrap();
    let report = exec::run(&session, &graph, plan, jobs, &Quiet).unwrap();
    assert!(!report.failed(), "{file:?} failed");
    (t.elapsed().as_secs_f64(), report.count(Status::Ran))
}

fn clean(file: &Path) {
    let graph = ibl_pipeline::load(file).unwrap();
    exec::clean(exec::Session::open(&graph).unwrap(), &graph).unwrap();
}

fn best(n: usize, mut f: impl FnMut() -> (f64, usize)) -> (f64, usize) {
    (0..n)
        .map(|_| f())
        .fold((f64::INFINITY, 0), |a, b| if b.0 < a.0 { b } else { a })
}

fn main() {
    let quick = std::env::args().any(|a| a == "--quick");
    let reps = if quick { 1 } else { 3 };
    let work = tempfile::tempdir().unwrap();
    for rel in ["pipelines", "fixtures/hdri"] {
        copy_tree(&root().join(rel), &work.path().join(rel));
    }
    // (pipeline, an input file to change, what to change it to)
    let cases = [
        (
            "probe.ron",
            "fixtures/hdri/city_512.exr",
            "fixtures/hdri/studio_256.exr",
        ),
        (
            "materials.ron",
            "pipelines/materials/frying-pan/normal.png",
            "pipelines/materials/painted-metal/normal.png",
        ),
        (
            "anisotropic-scene.ron",
            "fixtures/hdri/sunset_256.exr",
            "fixtures/hdri/studio_256.exr",
        ),
    ];
    let mut table = String::from(
        "| pipeline | stages baked | cold, 1 worker (s) | cold, 2 workers (s) | no-op run (s) | one input changed (s) | stages re-baked |\n|---|---|---|---|---|---|---|\n",
    );
    for (name, input, other) in cases {
        let file = work.path().join("pipelines").join(name);
        let cold1 = best(reps, || {
            clean(&file);
            run(&file, 1)
        });
        let cold2 = best(reps, || {
            clean(&file);
            run(&file, 2)
        });
        let noop = best(reps.max(3), || run(&file, 2));
        assert_eq!(noop.1, 0, "{name}: a no-op run baked something");
        let original = std::fs::read(work.path().join(input)).unwrap();
        std::fs::copy(work.path().join(other), work.path().join(input)).unwrap();
        let changed = run(&file, 2);
        std::fs::write(work.path().join(input), original).unwrap();
        table.push_str(&format!(
            "| {name} | {} | {:.3} | {:.3} | {:.4} | {:.3} | {} |\n",
            cold1.1, cold1.0, cold2.0, noop.0, changed.0, changed.1
        ));
        eprintln!("{name}: done");
    }
    let text = format!(
        "# bake: the runner on the example pipelines\n\n{} build, 2 cores, best of {reps} (no-op: best of {}). \
         Cold runs start from `bake clean`; \"one input changed\" replaces one input file and re-runs \
         (stages downstream of it re-bake, the rest are up to date or restored from the cache).\n\n{table}",
        if cfg!(debug_assertions) { "debug" } else { "release" },
        reps.max(3)
    );
    println!("{text}");
    let out = root().join("bench");
    std::fs::create_dir_all(&out).unwrap();
    std::fs::write(out.join("bake.md"), text).unwrap();
}
