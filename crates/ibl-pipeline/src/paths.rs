//! Lexical path helpers: normalising `a/../b`, relative paths for ninja files, and the
//! hidden staging names the runner uses.

use std::path::{Path, PathBuf};

/// Removes `.` and resolves `..` lexically (`pipelines/../out` → `out`); keeps leading `..`.
pub(crate) use ibl_core::ownership::normalize;

/// An absolute, normalised form of `p` (relative to the current folder).
pub fn absolute(p: &Path) -> PathBuf {
    normalize(&std::path::absolute(p).unwrap_or_else(|_| p.to_path_buf()))
}

/// `p` relative to folder `base` (both made absolute first): `../x/y` when needed.
pub(crate) fn relative_to(p: &Path, base: &Path) -> PathBuf {
    let (p, base) = (absolute(p), absolute(base));
    let pc: Vec<_> = p.components().collect();
    let bc: Vec<_> = base.components().collect();
    let common = pc.iter().zip(&bc).take_while(|(a, b)| a == b).count();
    if common == 0 {
        return p;
    }
    let mut r = PathBuf::new();
    for _ in common..bc.len() {
        r.push("..");
    }
    for c in &pc[common..] {
        r.push(c);
    }
    if r.as_os_str().is_empty() {
        PathBuf::from(".")
    } else {
        r
    }
}

/// True when `p` is `dir` or inside it (lexically, both made absolute: `a` is inside `.`).
pub(crate) fn is_within(p: &Path, dir: &Path) -> bool {
    absolute(p).starts_with(absolute(dir))
}

/// A file-name-safe form of a stage id (`lobby/cube` → `lobby_cube`).
pub(crate) fn slug(id: &str) -> String {
    id.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' || c == '.' {
                c
            } else {
                '_'
            }
        })
        .collect()
}

/// Removes the empty folders from `file`'s folder up to (not including) `stop`.
pub(crate) fn remove_empty_parents(file: &Path, stop: &Path) {
    let mut d = file.parent();
    while let Some(dir) = d {
        if !is_within(dir, stop)
            || normalize(dir) == normalize(stop)
            || std::fs::remove_dir(dir).is_err()
        {
            break;
        }
        d = dir.parent();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn normalises_lexically() {
        assert_eq!(
            normalize(Path::new("pipelines/../out/x")),
            PathBuf::from("out/x")
        );
        assert_eq!(normalize(Path::new("./a/./b/..")), PathBuf::from("a"));
        assert_eq!(normalize(Path::new("../a")), PathBuf::from("../a"));
        assert_eq!(normalize(Path::new("/../a")), PathBuf::from("/a"));
        assert_eq!(normalize(Path::new("a/..")), PathBuf::from("."));
    }

    #[test]
    fn relative_paths_walk_up_and_down() {
        assert_eq!(
            relative_to(Path::new("/w/out/probe/a.exr"), Path::new("/w/build")),
            PathBuf::from("../out/probe/a.exr")
        );
        assert_eq!(
            relative_to(Path::new("/w/a"), Path::new("/w")),
            PathBuf::from("a")
        );
        assert_eq!(
            relative_to(Path::new("/w"), Path::new("/w")),
            PathBuf::from(".")
        );
        assert!(is_within(Path::new("/w/out/../out/x"), Path::new("/w/out")));
        assert!(!is_within(Path::new("/w/outx"), Path::new("/w/out")));
    }
}
