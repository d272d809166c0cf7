//! The one folder walker of the workspace (`quat-map --batch`, `bake`'s Folder inputs and
//! material stages) and its one symlink policy: symbolic links to folders are followed like
//! folders, links to files like files, dangling links are skipped, hidden entries (".name")
//! are left out, and a link that leads back into a folder being walked is refused as a loop.

use std::io;
use std::path::{Path, PathBuf};

/// One folder's entries, each list sorted by path.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Listing {
    /// Subfolders (symlinks to folders followed).
    pub dirs: Vec<PathBuf>,
    /// Regular files (symlinks to files followed).
    pub files: Vec<PathBuf>,
}

/// The entries of `dir` (not recursive), links resolved as the policy says.
pub fn list(dir: &Path) -> io::Result<Listing> {
    let mut l = Listing::default();
    for e in std::fs::read_dir(dir)? {
        let e = e?;
        if e.file_name().to_string_lossy().starts_with('.') {
            continue;
        }
        let path = e.path();
        let ft = e.file_type()?;
        let (is_dir, is_file) = if ft.is_symlink() {
            match std::fs::metadata(&path) {
                Ok(m) => (m.is_dir(), m.is_file()),
                Err(_) => (false, false), // dangling
            }
        } else {
            (ft.is_dir(), ft.is_file())
        };
        if is_dir {
            l.dirs.push(path);
        } else if is_file {
            l.files.push(path);
        }
    }
    l.dirs.sort();
    l.files.sort();
    Ok(l)
}

/// Visits `root` and every folder under it, parents before children, in path order.
/// `visit` gets each folder with its listing, or with the error that kept it from being listed
/// (the walk goes on with the others). Fails if `root` cannot be listed or a symbolic link
/// loops back into a folder on the way down.
pub fn folders(root: &Path, visit: &mut dyn FnMut(&Path, io::Result<&Listing>)) -> io::Result<()> {
    let listing = list(root)?;
    let mut ancestors = vec![std::fs::canonicalize(root)?];
    walk_in(root, listing, &mut ancestors, visit)
}

fn walk_in(
    dir: &Path,
    listing: Listing,
    ancestors: &mut Vec<PathBuf>,
    visit: &mut dyn FnMut(&Path, io::Result<&Listing>),
) -> io::Result<()> {
    visit(dir, Ok(&listing));
    for sub in &listing.dirs {
        let real = match std::fs::canonicalize(sub) {
            Ok(r) => r,
            Err(e) => {
                visit(sub, Err(e));
                continue;
            }
        };
        if let Some(a) = ancestors.iter().find(|a| **a == real) {
            return Err(io::Error::other(format!(
                "{}: a symbolic link loop (it leads back to {})",
                sub.display(),
                a.display()
            )));
        }
        match list(sub) {
            Ok(l) => {
                ancestors.push(real);
                walk_in(sub, l, ancestors, visit)?;
                ancestors.pop();
            }
            Err(e) => visit(sub, Err(e)),
        }
    }
    Ok(())
}

/// Every file under `root`, sorted; any folder that cannot be listed is an error.
pub fn files(root: &Path) -> io::Result<Vec<PathBuf>> {
    let mut out = Vec::new();
    let mut first_error = None;
    folders(root, &mut |dir, l| match l {
        Ok(l) => out.extend(l.files.iter().cloned()),
        Err(e) => {
            first_error
                .get_or_insert_with(|| io::Error::new(e.kind(), format!("{}: {e}", dir.display())));
        }
    })?;
    if let Some(e) = first_error {
        return Err(e);
    }
    out.sort();
    Ok(out)
}

#[cfg(all(test, unix))]
mod tests {
    use super::*;
    use std::os::unix::fs::symlink;

    #[test]
    fn symlinked_folders_are_followed_and_loops_refused() {
        let t = tempfile::tempdir().unwrap();
        let root = t.path().join("root");
        let elsewhere = t.path().join("elsewhere");
        std::fs::create_dir_all(root.join("a")).unwrap();
        std::fs::create_dir_all(&elsewhere).unwrap();
        std::fs::write(root.join("a/normal.png"), "x").unwrap();
        std::fs::write(elsewhere.join("normal.png"), "y").unwrap();
        std::fs::write(root.join(".hidden"), "h").unwrap();
        symlink(&elsewhere, root.join("b")).unwrap();
        symlink(root.join("a/normal.png"), root.join("link.png")).unwrap();
        symlink(t.path().join("missing"), root.join("dangling.png")).unwrap();
        let found = files(&root).unwrap();
        let rel: Vec<_> = found
            .iter()
            .map(|f| f.strip_prefix(&root).unwrap())
            .collect();
        assert_eq!(
            rel,
            [
                Path::new("a/normal.png"),
                Path::new("b/normal.png"),
                Path::new("link.png")
            ]
        );
        // A link back to an ancestor is a loop: refused, not walked forever.
        symlink(&root, root.join("a/up")).unwrap();
        let e = files(&root).unwrap_err().to_string();
        assert!(e.contains("symbolic link loop"), "{e}");
        // The same folder reached twice without a loop is fine (a sibling link).
        std::fs::remove_file(root.join("a/up")).unwrap();
        symlink(root.join("a"), root.join("c")).unwrap();
        assert_eq!(files(&root).unwrap().len(), 4);
    }
}
