// The build fingerprint of `build.rs`, in a file of its own so the crate's tests check it too
// (included with `include!` there, so it cannot open with an inner `//!` doc comment).

use std::path::{Path, PathBuf};

/// FNV-1a, 64 bits: small, dependency-free, and enough to tell builds apart.
struct Fnv(u64);

impl Fnv {
    fn new() -> Self {
        Fnv(0xcbf2_9ce4_8422_2325)
    }
    fn update(&mut self, bytes: &[u8]) {
        for b in bytes {
            self.0 ^= u64::from(*b);
            self.0 = self.0.wrapping_mul(0x0000_0100_0000_01b3);
        }
    }
}

/// The `.rs` files under `dir`, recursively.
fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let Ok(rd) = std::fs::read_dir(dir) else {
        return;
    };
    for e in rd.flatten() {
        let p = e.path();
        if p.is_dir() {
            rust_files(&p, out);
        } else if p.extension().is_some_and(|x| x == "rs") {
            out.push(p);
        }
    }
}

/// The fingerprint of the workspace at `workspace`, and what cargo must watch for it: every
/// `crates/*/Cargo.toml` and `crates/*/src` folder, the workspace's `Cargo.toml` and `Cargo.lock`.
///
/// Files are hashed in the order of their path relative to `workspace` (with `/` separators),
/// each as its relative path, its length and its bytes: mtimes, absolute paths and the order
/// the file system lists folders in play no part.
pub fn fingerprint(workspace: &Path) -> std::io::Result<(String, Vec<PathBuf>)> {
    let crates = workspace.join("crates");
    let mut files: Vec<PathBuf> = Vec::new();
    let mut watch: Vec<PathBuf> = Vec::new();
    let mut crate_dirs: Vec<PathBuf> = std::fs::read_dir(&crates)?
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.is_dir())
        .collect();
    crate_dirs.sort();
    for dir in &crate_dirs {
        let toml = dir.join("Cargo.toml");
        if !toml.is_file() {
            continue;
        }
        watch.push(toml.clone());
        files.push(toml);
        let src = dir.join("src");
        if src.is_dir() {
            // A folder: cargo reruns the build script when anything under it changes.
            watch.push(src.clone());
            rust_files(&src, &mut files);
        }
    }
    for f in ["Cargo.toml", "Cargo.lock"] {
        let p = workspace.join(f);
        if p.is_file() {
            watch.push(p.clone());
            files.push(p);
        }
    }
    let mut named: Vec<(String, PathBuf)> = files
        .into_iter()
        .map(|p| {
            let rel = p
                .strip_prefix(workspace)
                .unwrap_or(&p)
                .components()
                .map(|c| c.as_os_str().to_string_lossy().into_owned())
                .collect::<Vec<_>>()
                .join("/");
            (rel, p)
        })
        .collect();
    named.sort();
    let mut h = Fnv::new();
    for (rel, path) in &named {
        let bytes = std::fs::read(path)?;
        h.update(rel.as_bytes());
        h.update(&[0]);
        h.update(&(bytes.len() as u64).to_le_bytes());
        h.update(&bytes);
    }
    Ok((format!("{:016x}", h.0), watch))
}
