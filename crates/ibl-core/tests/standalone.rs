//! The repository stands alone: no file points outside it (the conventions, engine notes and
//! bibliography live in docs/), and papers are cited by author and year, not by file number.

use ibl_testkit::workspace_root as root;
use std::path::{Path, PathBuf};

/// Every file a clone holds, skipping build output and VCS data.
fn files(dir: &Path, out: &mut Vec<PathBuf>) {
    for e in std::fs::read_dir(dir).unwrap().flatten() {
        let p = e.path();
        let name = e.file_name().to_string_lossy().to_string();
        let ft = e.file_type().unwrap();
        if ft.is_dir() {
            if !(name.starts_with('.') || name == "target" || name == "node_modules") {
                files(&p, out);
            }
        } else if ft.is_file() {
            out.push(p);
        }
    }
}

#[test]
fn no_file_references_outside_the_repository_or_cites_by_file_number() {
    let mut all = Vec::new();
    files(&root(), &mut all);
    assert!(all.len() > 100, "walked only {} files", all.len());
    // Built here so that this file does not match itself.
    let outside = concat!("..", "/shared");
    let numbered: Vec<String> = ["paper", "Paper", "thesis", "Thesis"]
        .iter()
        .flat_map(|w| (0..5).map(move |k| format!("{w} 00{k}")))
        .collect();
    let mut found = Vec::new();
    for f in &all {
        let Ok(text) = std::fs::read_to_string(f) else {
            continue; // binary fixtures
        };
        for (n, line) in text.lines().enumerate() {
            if line.contains(outside) || numbered.iter().any(|k| line.contains(k.as_str())) {
                found.push(format!("{}:{}: {}", f.display(), n + 1, line.trim()));
            }
        }
    }
    assert!(
        found.is_empty(),
        "cite docs/ and docs/BIBLIOGRAPHY.md instead:\n{}",
        found.join("\n")
    );
    for doc in ["CONVENTIONS.md", "ENGINES.md", "BIBLIOGRAPHY.md"] {
        assert!(
            root().join("docs").join(doc).is_file(),
            "docs/{doc} is missing"
        );
    }
}
