// The build fingerprint of `build.rs`, in a file of its own so the crate's tests check it too
// (included with `include!` there, so it cannot open with an inner `//!` doc comment).

use std::collections::BTreeMap;
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
    let mut named = relative_names(workspace, files);
    named.sort();
    Ok((hash_files(&named, |_, b| b)?, watch))
}

/// The hash of `named` (relative path, file), in the given order, each as its path, its length
/// and its bytes after `filter(relative path, bytes)`.
fn hash_files(
    named: &[(String, PathBuf)],
    filter: impl Fn(&str, Vec<u8>) -> Vec<u8>,
) -> std::io::Result<String> {
    let mut h = Fnv::new();
    for (rel, path) in named {
        let bytes = filter(rel, std::fs::read(path)?);
        h.update(rel.as_bytes());
        h.update(&[0]);
        h.update(&(bytes.len() as u64).to_le_bytes());
        h.update(&bytes);
    }
    Ok(format!("{:016x}", h.0))
}

/// A workspace crate: its folder and the workspace crates among its `[dependencies]`.
struct Member {
    dir: PathBuf,
    deps: Vec<String>,
}

/// The workspace's crates by package name, read from `crates/*/Cargo.toml`: the `name` of
/// `[package]` and the keys of every `[dependencies]` / `[build-dependencies]` /
/// `[target.*.dependencies]` table (never `[dev-dependencies]`: tests do not bake).
fn members(workspace: &Path) -> std::io::Result<BTreeMap<String, Member>> {
    let mut found: Vec<(String, PathBuf, Vec<String>)> = Vec::new();
    for e in std::fs::read_dir(workspace.join("crates"))?.flatten() {
        let dir = e.path();
        let Ok(toml) = std::fs::read_to_string(dir.join("Cargo.toml")) else {
            continue;
        };
        let (mut name, mut deps, mut section) = (None, Vec::new(), String::new());
        for line in toml.lines().map(str::trim) {
            if line.starts_with('[') {
                section = line.trim_matches(|c| c == '[' || c == ']').to_string();
                continue;
            }
            let Some((key, value)) = line.split_once('=') else {
                continue;
            };
            let key = key.trim();
            if section == "package" && key == "name" {
                name = Some(value.trim().trim_matches('"').to_string());
            } else if section.ends_with("dependencies") && !section.ends_with("dev-dependencies") {
                let dep = key
                    .split('.')
                    .next()
                    .unwrap_or(key)
                    .trim()
                    .trim_matches('"');
                deps.push(dep.to_string());
            }
        }
        if let Some(name) = name {
            found.push((name, dir, deps));
        }
    }
    let names: Vec<String> = found.iter().map(|f| f.0.clone()).collect();
    Ok(found
        .into_iter()
        .map(|(name, dir, deps)| {
            let deps = deps.into_iter().filter(|d| names.contains(d)).collect();
            (name, Member { dir, deps })
        })
        .collect())
}

/// `text` without its `#[cfg(test)]` items (test modules, test-only helpers and imports), so
/// editing a test leaves a bake's fingerprint alone. Relies on rustfmt's layout (enforced by
/// `cargo fmt --check`): an item whose first line ends with `;` or `}` is that line; any other ends at
/// the line that is its closing `}` (or `};`) at the attribute's indentation. A
/// `#[cfg(test)] mod x;` file stays hashed (it then only costs a re-bake).
fn strip_test_items(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    let mut lines = text.lines();
    while let Some(line) = lines.next() {
        if line.trim() != "#[cfg(test)]" {
            out.push_str(line);
            out.push('\n');
            continue;
        }
        let indent = &line[..line.len() - line.trim_start().len()];
        let (close, close_semi) = (format!("{indent}}}"), format!("{indent}}};"));
        let mut head = true;
        for item in lines.by_ref() {
            let body = item.trim_end();
            if head {
                let t = body.trim_start();
                if t.starts_with("#[") || t.starts_with("//") || t.is_empty() {
                    continue;
                }
                head = false;
                if t.ends_with(';') || t.ends_with('}') {
                    break;
                }
            } else if body == close || body == close_semi {
                break;
            }
        }
    }
    out
}

/// The fingerprint of the code a bake in `library` runs: that crate and its transitive
/// workspace dependencies (from the Cargo.toml files), each crate's `Cargo.toml` and
/// `src/**/*.rs` without `#[cfg(test)]` items, plus the workspace's `Cargo.toml` and
/// `Cargo.lock`. Tests, benches, examples and crates the library does not depend on (the
/// plotting crate, the binaries) play no part. `None` when `library` is not a workspace crate.
pub fn library_fingerprint(workspace: &Path, library: &str) -> std::io::Result<Option<String>> {
    let members = members(workspace)?;
    if !members.contains_key(library) {
        return Ok(None);
    }
    let mut closure = vec![library.to_string()];
    let mut i = 0;
    while i < closure.len() {
        for d in &members[&closure[i]].deps {
            if !closure.contains(d) {
                closure.push(d.clone());
            }
        }
        i += 1;
    }
    let mut files = Vec::new();
    for name in &closure {
        let dir = &members[name].dir;
        files.push(dir.join("Cargo.toml"));
        rust_files(&dir.join("src"), &mut files);
    }
    for f in ["Cargo.toml", "Cargo.lock"] {
        let p = workspace.join(f);
        if p.is_file() {
            files.push(p);
        }
    }
    let mut named = relative_names(workspace, files);
    named.sort();
    let fp = hash_files(&named, |rel, bytes| {
        if rel.ends_with(".rs") {
            strip_test_items(&String::from_utf8_lossy(&bytes)).into_bytes()
        } else {
            bytes
        }
    })?;
    Ok(Some(fp))
}

/// Every workspace crate's [`library_fingerprint`], by package name.
pub fn library_fingerprints(workspace: &Path) -> std::io::Result<Vec<(String, String)>> {
    let mut out = Vec::new();
    for name in members(workspace)?.into_keys() {
        if let Some(fp) = library_fingerprint(workspace, &name)? {
            out.push((name, fp));
        }
    }
    Ok(out)
}

/// Each file with its path relative to `workspace` (`/` separators).
fn relative_names(workspace: &Path, files: Vec<PathBuf>) -> Vec<(String, PathBuf)> {
    files
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
        .collect()
}
