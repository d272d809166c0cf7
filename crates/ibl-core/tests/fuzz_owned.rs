//! Replays and mutation-fuzzes the `ownership` and `budget` fuzz targets (issue 24): the very
//! entry points cargo-fuzz runs (`fuzz/src/owned.rs`, included by path), with the counting
//! allocator installed, so the `budget` target's memory bound is measured here too. One test
//! runs by default (the allocator's peak is process-wide: no other test may allocate beside
//! it); `mutation_fuzz_long` (ignored) is `scripts/fuzz.sh`'s fallback for these targets.

#[path = "../../../fuzz/src/images.rs"]
#[allow(dead_code)]
mod images;
#[path = "../../../fuzz/src/mutate.rs"]
#[allow(dead_code)]
mod mutate;
#[path = "../../../fuzz/src/owned.rs"]
#[allow(dead_code)]
mod owned;

use ibl_testkit::workspace_root;
use std::path::{Path, PathBuf};

#[global_allocator]
static ALLOC: owned::Counting = owned::Counting;

const TARGETS: [&str; 2] = ["ownership", "budget"];

fn run(name: &str, data: &[u8]) {
    match name {
        "ownership" => owned::ownership(data),
        "budget" => owned::budget(data),
        other => panic!("unknown target {other}"),
    }
}

fn fuzz_dir() -> PathBuf {
    workspace_root().join("fuzz")
}

#[test]
fn ownership_and_budget_seeds_replay_and_mutants_hold() {
    let failures = mutate::replay(&fuzz_dir(), &TARGETS, &run);
    assert!(failures.is_empty(), "panics:\n{}", failures.join("\n"));

    // The allocator is counting: a decode of a seed shows a peak, so the bound is checked.
    owned::Counting::reset();
    let small = std::fs::read(fuzz_dir().join("corpus/hdr/seed-rle-16x8.hdr")).unwrap();
    images::decode_target("hdr", &small).unwrap();
    assert!(owned::Counting::peak().is_some_and(|p| p > 16 * 8 * 3 * 4));

    // The bombs among the seeds (16384² declared in a few hundred bytes) are refused, in one
    // line, naming the file, having allocated a small part of the budget.
    for seed in mutate::files_in(&fuzz_dir().join("corpus/budget")) {
        let name = seed.file_name().unwrap().to_string_lossy().into_owned();
        if !name.contains("bomb") {
            continue;
        }
        let data = std::fs::read(&seed).unwrap();
        let fmt = owned::BUDGET_FORMATS[data[0] as usize % owned::BUDGET_FORMATS.len()];
        let base = owned::Counting::reset();
        let e = images::decode_target(fmt, &data[1..])
            .unwrap_err()
            .to_string();
        let used = owned::Counting::peak().unwrap() - base;
        assert!(e.starts_with("f.") && !e.contains('\n'), "{name}: {e}");
        assert!(
            used < 1 << 20,
            "{name}: {used} bytes allocated to refuse it"
        );
    }

    // A few thousand mutants per target (deterministic).
    let crash_dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("fuzz-owned-crashes");
    let report = mutate::quick_run(&fuzz_dir(), &TARGETS, 0x24_0a11, 3000, &crash_dir, &run);
    owned::ownership_cleanup();
    assert!(
        report.is_empty(),
        "failures (copy the inputs into fuzz/regressions/<target>/):\n{}",
        report.join("\n")
    );
}

/// `scripts/fuzz.sh`'s fallback for these targets: `FUZZ_SECONDS`, `FUZZ_SEED`,
/// `FUZZ_TARGETS` (see `mutate::long_run`).
#[test]
#[ignore]
fn mutation_fuzz_long() {
    let report = mutate::long_run(&fuzz_dir(), &TARGETS, &run);
    owned::ownership_cleanup();
    assert!(report.is_empty(), "panics:\n{}", report.join("\n"));
}
