//! The built-in mutation fuzzer over every target, the pipeline loader included (the image
//! readers are also fuzzed this way by `cargo test -p ibl-core`; the pipeline loader lives in a
//! crate ibl-core cannot depend on). `scripts/fuzz.sh` runs `mutation_fuzz_long` when
//! cargo-fuzz cannot build; `cargo test --manifest-path fuzz/Cargo.toml` runs the rest.

use ibl_fuzz::mutate::{self, files_in, fuzz, panics, save_crashes, seeds};
use ibl_fuzz::{run_target, TARGETS};
use std::path::{Path, PathBuf};
use std::time::Duration;

fn fuzz_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).to_path_buf()
}

#[test]
fn regressions_and_seeds_do_not_panic() {
    let mut failures = Vec::new();
    for t in TARGETS {
        let files: Vec<PathBuf> = ["regressions", "corpus"]
            .iter()
            .flat_map(|d| files_in(&fuzz_dir().join(d).join(t)))
            .collect();
        eprintln!("{t}: replaying {} files", files.len());
        for p in files {
            let data = std::fs::read(&p).unwrap();
            if let Some(msg) = panics(&|d| run_target(t, d), &data) {
                failures.push(format!("{}: {msg}", p.display()));
            }
        }
    }
    assert!(failures.is_empty(), "panics:\n{}", failures.join("\n"));
}

#[test]
fn mutation_fuzz_quick() {
    let mut report = Vec::new();
    for t in TARGETS {
        let corpus = seeds(&fuzz_dir(), t);
        let r = fuzz(
            t,
            &corpus,
            0x1b1_f022,
            2000,
            Duration::from_secs(10),
            &|d| run_target(t, d),
        );
        eprintln!(
            "{t}: {} mutated inputs in {:.2} s, {} panics",
            r.runs,
            r.elapsed.as_secs_f64(),
            r.crashes.len()
        );
        let dir = Path::new(env!("CARGO_TARGET_TMPDIR"))
            .join("fuzz-crashes")
            .join(t);
        report.extend(save_crashes(&dir, &r.crashes));
    }
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
