//! The built-in mutation fuzzer over every target, the pipeline loader included (the image
//! readers are also fuzzed this way by `cargo test -p ibl-core`; the pipeline loader lives in a
//! crate ibl-core cannot depend on). `scripts/fuzz.sh` runs `mutation_fuzz_long` when
//! cargo-fuzz cannot build; `cargo test --manifest-path fuzz/Cargo.toml` runs the rest.

use ibl_fuzz::mutate;
use ibl_fuzz::{run_target, TARGETS};
use std::path::{Path, PathBuf};

fn fuzz_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).to_path_buf()
}

#[test]
fn regressions_and_seeds_do_not_panic() {
    let failures = mutate::replay(&fuzz_dir(), &TARGETS, &run_target);
    assert!(failures.is_empty(), "panics:\n{}", failures.join("\n"));
}

/// A different seed from ibl-core's quick run (which covers the image readers with
/// 0x1b1_f022), so the two suites explore different inputs; this one also builds with
/// overflow checks in release.
#[test]
fn mutation_fuzz_quick() {
    let crash_dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("fuzz-crashes");
    let report = mutate::quick_run(
        &fuzz_dir(),
        &TARGETS,
        0x2c2_0133,
        2000,
        &crash_dir,
        &run_target,
    );
    assert!(report.is_empty(), "panics:\n{}", report.join("\n"));
}

/// `FUZZ_SECONDS` per target, `FUZZ_SEED`, `FUZZ_TARGETS`: see `mutate::long_run`. Crash
/// inputs go into `fuzz/regressions/<target>/`.
#[test]
#[ignore]
fn mutation_fuzz_long() {
    let report = mutate::long_run(&fuzz_dir(), &TARGETS, &run_target);
    assert!(report.is_empty(), "panics:\n{}", report.join("\n"));
}
