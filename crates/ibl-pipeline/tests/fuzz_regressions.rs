//! Replays the pipeline fuzz target's seeds and kept crashes (fuzz/corpus/pipeline,
//! fuzz/regressions/pipeline) through the same entry point the fuzzer ran, so a fixed crash
//! stays fixed under `cargo test --workspace`.

#[path = "../../../fuzz/src/pipeline.rs"]
mod entry;

use std::path::Path;

#[test]
fn pipeline_seeds_and_regressions_do_not_panic() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fuzz");
    let mut replayed = 0;
    for dir in ["corpus/pipeline", "regressions/pipeline"] {
        let Ok(entries) = std::fs::read_dir(root.join(dir)) else {
            continue;
        };
        let mut files: Vec<_> = entries
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.is_file())
            .collect();
        files.sort();
        for f in files {
            let data = std::fs::read(&f).unwrap();
            let result = std::panic::catch_unwind(|| entry::pipeline(&data));
            assert!(result.is_ok(), "{} panics the pipeline loader", f.display());
            replayed += 1;
        }
    }
    assert!(
        replayed > 0,
        "the seed corpus fuzz/corpus/pipeline is missing"
    );
}
