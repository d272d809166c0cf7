//! The module graph inside every crate of the workspace is acyclic (issue 24 item 6): a test
//! that parses each crate's sources, builds which module refers to which, and names any cycle.
//!
//! The rule. Each crate root (`src/lib.rs`, `src/main.rs`, `src/bin/*.rs`) is walked through
//! its `mod` declarations (file or inline). Every path a module names that starts with
//! `crate::`, `super::` or `self::` (in a `use` or anywhere in code) is resolved to the deepest
//! module it reaches, giving an edge `from → to`. A parent naming its child (a `mod.rs`
//! re-exporting, a `lib.rs` calling into `io::…`) and a child naming an ancestor's items are
//! the ordinary shape of a Rust crate and are not edges; every other edge is lifted to the
//! children of the two modules' lowest common ancestor, so `io/ktx2.rs → io/container.rs` is
//! the edge `ktx2 → container` among `io`'s children and `io/ktx2.rs → output.rs` is
//! `io → output` among the crate's top-level modules. A cycle among the siblings of any one
//! folder (or of the crate root) fails the test, named module by module. Code under
//! `#[cfg(test)]` is left out: a test module using its neighbours builds no dependency.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use syn::visit::Visit;

/// A module's path from its crate root (`["io", "ktx2"]`; empty for the root).
type ModPath = Vec<String>;

/// Every module of one crate root and the modules each names.
#[derive(Default, Debug)]
struct Crate {
    /// Module → the modules its code names (resolved, deepest known module).
    refs: BTreeMap<ModPath, BTreeSet<ModPath>>,
}

/// Whether an item carries `#[cfg(test)]` (or a `cfg` naming `test` other than `not(test)`).
fn is_test_only(attrs: &[syn::Attribute]) -> bool {
    attrs.iter().any(|a| match &a.meta {
        syn::Meta::List(l) if l.path.is_ident("cfg") => {
            let s = l.tokens.to_string();
            s.contains("test") && !s.contains("not")
        }
        _ => false,
    })
}

/// Collects the raw `crate::`/`super::`/`self::` paths named in one module's own items (not
/// in its child modules, which are walked on their own).
struct Refs<'a> {
    here: &'a ModPath,
    out: Vec<ModPath>,
}

impl Refs<'_> {
    /// Resolves a path's leading `crate`/`super`/`self` segments against the module; `None`
    /// for a path that starts anywhere else (an extern crate, a local name).
    fn resolve(&self, segs: &[String]) -> Option<ModPath> {
        let first = segs.first()?;
        let (mut base, rest) = match first.as_str() {
            "crate" => (Vec::new(), &segs[1..]),
            "self" => (self.here.clone(), &segs[1..]),
            "super" => (self.here.clone(), segs),
            _ => return None,
        };
        let mut rest = rest;
        while rest.first().map(String::as_str) == Some("super") {
            base.pop()?;
            rest = &rest[1..];
        }
        base.extend(rest.iter().cloned());
        Some(base)
    }

    fn push(&mut self, segs: &[String]) {
        if let Some(p) = self.resolve(segs) {
            self.out.push(p);
        }
    }

    /// Flattens a `use` tree into the paths it names.
    fn use_tree(&mut self, prefix: &mut Vec<String>, t: &syn::UseTree) {
        match t {
            syn::UseTree::Path(p) => {
                prefix.push(p.ident.to_string());
                self.use_tree(prefix, &p.tree);
                prefix.pop();
            }
            syn::UseTree::Name(n) => {
                prefix.push(n.ident.to_string());
                self.push(prefix);
                prefix.pop();
            }
            syn::UseTree::Rename(r) => {
                prefix.push(r.ident.to_string());
                self.push(prefix);
                prefix.pop();
            }
            syn::UseTree::Glob(_) => self.push(prefix),
            syn::UseTree::Group(g) => g.items.iter().for_each(|t| self.use_tree(prefix, t)),
        }
    }
}

impl<'ast> Visit<'ast> for Refs<'_> {
    fn visit_item_mod(&mut self, _: &'ast syn::ItemMod) {
        // Child modules are walked as their own nodes.
    }
    fn visit_item(&mut self, i: &'ast syn::Item) {
        let attrs: &[syn::Attribute] = match i {
            syn::Item::Fn(x) => &x.attrs,
            syn::Item::Impl(x) => &x.attrs,
            syn::Item::Use(x) => &x.attrs,
            syn::Item::Struct(x) => &x.attrs,
            syn::Item::Enum(x) => &x.attrs,
            syn::Item::Const(x) => &x.attrs,
            syn::Item::Static(x) => &x.attrs,
            syn::Item::Trait(x) => &x.attrs,
            syn::Item::Type(x) => &x.attrs,
            syn::Item::Macro(x) => &x.attrs,
            _ => &[],
        };
        if !is_test_only(attrs) {
            syn::visit::visit_item(self, i);
        }
    }
    fn visit_item_use(&mut self, u: &'ast syn::ItemUse) {
        self.use_tree(&mut Vec::new(), &u.tree);
    }
    fn visit_path(&mut self, p: &'ast syn::Path) {
        let segs: Vec<String> = p.segments.iter().map(|s| s.ident.to_string()).collect();
        self.push(&segs);
        syn::visit::visit_path(self, p);
    }
}

/// Walks one module (its items in `items`, its file in `file`), recording its raw references
/// in `raw` and recursing into its children.
fn walk(
    file: &Path,
    is_mod_rs: bool,
    here: ModPath,
    items: &[syn::Item],
    raw: &mut BTreeMap<ModPath, Vec<ModPath>>,
) -> Result<(), String> {
    let mut r = Refs {
        here: &here,
        out: Vec::new(),
    };
    for i in items {
        r.visit_item(i);
    }
    raw.insert(here.clone(), r.out);
    // The folder a file module's children live in: `a/` for `a.rs`, `a/` for `a/mod.rs`.
    let dir = if is_mod_rs {
        file.parent().unwrap().to_path_buf()
    } else {
        file.with_extension("")
    };
    for i in items {
        let syn::Item::Mod(m) = i else { continue };
        if is_test_only(&m.attrs) {
            continue;
        }
        let mut child = here.clone();
        child.push(m.ident.to_string());
        match &m.content {
            Some((_, inner)) => {
                // An inline module's own children would sit in `dir/name/`.
                walk(
                    &dir.join(format!("{}.rs", m.ident)),
                    false,
                    child,
                    inner,
                    raw,
                )?;
            }
            None => {
                let a = dir.join(format!("{}.rs", m.ident));
                let b = dir.join(m.ident.to_string()).join("mod.rs");
                let (path, is_mod) = if a.exists() { (a, false) } else { (b, true) };
                let f = parse_file(&path)?;
                walk(&path, is_mod, child, &f.items, raw)?;
            }
        }
    }
    Ok(())
}

fn parse_file(path: &Path) -> Result<syn::File, String> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
    syn::parse_file(&text).map_err(|e| format!("{}: {e}", path.display()))
}

/// Builds the module graph of the crate rooted at `root` (`src/lib.rs`, `src/main.rs`).
fn crate_graph(root: &Path) -> Result<Crate, String> {
    let f = parse_file(root)?;
    let mut raw = BTreeMap::new();
    // A crate root's children live beside it, like a `mod.rs`'s.
    walk(root, true, Vec::new(), &f.items, &mut raw)?;
    Ok(resolve(raw))
}

/// Resolves raw referenced paths to the deepest known module each reaches.
fn resolve(raw: BTreeMap<ModPath, Vec<ModPath>>) -> Crate {
    let known: BTreeSet<ModPath> = raw.keys().cloned().collect();
    let mut c = Crate::default();
    for (from, paths) in raw {
        let set = c.refs.entry(from).or_default();
        for p in paths {
            let deepest = (0..=p.len())
                .rev()
                .map(|n| p[..n].to_vec())
                .find(|q| known.contains(q))
                .unwrap_or_default();
            set.insert(deepest);
        }
    }
    c
}

/// Sibling-level edges under one parent: child → (child it names → the first pair of
/// modules, `from` and `to`, that made the edge, to say where a cycle comes from).
type Edges = BTreeMap<String, BTreeMap<String, (ModPath, ModPath)>>;

/// The sibling-level edges of every parent, per the rule above.
fn sibling_edges(c: &Crate) -> BTreeMap<ModPath, Edges> {
    let mut out: BTreeMap<ModPath, Edges> = BTreeMap::new();
    for (from, tos) in &c.refs {
        for to in tos {
            let common = from.iter().zip(to).take_while(|(a, b)| a == b).count();
            // One is an ancestor of the other (or the same module): no edge.
            if common == from.len() || common == to.len() {
                continue;
            }
            out.entry(from[..common].to_vec())
                .or_default()
                .entry(from[common].clone())
                .or_default()
                .entry(to[common].clone())
                .or_insert_with(|| (from.clone(), to.clone()));
        }
    }
    out
}

/// Every cycle among one folder's siblings, each as its modules in order (first repeated
/// last), found by a depth-first search (one cycle per strongly connected tangle is enough to
/// name it).
fn cycles(edges: &Edges) -> Vec<Vec<String>> {
    #[derive(Clone, Copy, PartialEq)]
    enum Mark {
        New,
        Open,
        Done,
    }
    fn dfs(
        n: &str,
        edges: &Edges,
        mark: &mut BTreeMap<String, Mark>,
        stack: &mut Vec<String>,
        found: &mut Vec<Vec<String>>,
    ) {
        mark.insert(n.to_string(), Mark::Open);
        stack.push(n.to_string());
        for m in edges.get(n).into_iter().flat_map(|e| e.keys()) {
            match mark.get(m).copied().unwrap_or(Mark::New) {
                Mark::New => dfs(m, edges, mark, stack, found),
                Mark::Open => {
                    let at = stack.iter().position(|s| s == m).unwrap();
                    let mut cyc = stack[at..].to_vec();
                    cyc.push(m.clone());
                    found.push(cyc);
                }
                Mark::Done => {}
            }
        }
        stack.pop();
        mark.insert(n.to_string(), Mark::Done);
    }
    let mut mark = BTreeMap::new();
    let mut found = Vec::new();
    for n in edges.keys() {
        if mark.get(n).copied().unwrap_or(Mark::New) == Mark::New {
            dfs(n, edges, &mut mark, &mut Vec::new(), &mut found);
        }
    }
    found
}

/// Every sibling-level cycle of a crate, each named `crate/folder: a → b → a`.
fn crate_cycles(name: &str, c: &Crate) -> Vec<String> {
    let mut out = Vec::new();
    for (parent, edges) in sibling_edges(c) {
        let at = if parent.is_empty() {
            name.to_string()
        } else {
            format!("{name}::{}", parent.join("::"))
        };
        for cyc in cycles(&edges) {
            let why: Vec<String> = cyc
                .windows(2)
                .map(|w| {
                    let (f, t) = &edges[&w[0]][&w[1]];
                    format!("{} names {}", f.join("::"), t.join("::"))
                })
                .collect();
            out.push(format!("{at}: {} ({})", cyc.join(" → "), why.join("; ")));
        }
    }
    out
}

/// The crate roots of the workspace: each crate's `src/lib.rs`, `src/main.rs`, `src/bin/*.rs`.
fn workspace_roots() -> Vec<(String, PathBuf)> {
    let crates = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let mut out = Vec::new();
    let mut dirs: Vec<_> = std::fs::read_dir(&crates)
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    dirs.sort();
    for d in dirs {
        let name = d.file_name().unwrap().to_string_lossy().to_string();
        for r in ["src/lib.rs", "src/main.rs"] {
            let p = d.join(r);
            if p.exists() {
                out.push((format!("{name} ({r})"), p));
            }
        }
        if let Ok(bins) = std::fs::read_dir(d.join("src/bin")) {
            let mut bins: Vec<_> = bins.map(|e| e.unwrap().path()).collect();
            bins.sort();
            for b in bins
                .into_iter()
                .filter(|b| b.extension() == Some("rs".as_ref()))
            {
                out.push((format!("{name} ({})", b.display()), b));
            }
        }
    }
    out
}

#[test]
fn no_crate_has_a_cycle_among_sibling_modules() {
    let roots = workspace_roots();
    assert!(roots.len() > 20, "found only {} crate roots", roots.len());
    let mut all = Vec::new();
    for (name, root) in roots {
        let c = crate_graph(&root).unwrap_or_else(|e| panic!("{e}"));
        all.extend(crate_cycles(&name, &c));
    }
    assert!(
        all.is_empty(),
        "circular imports between modules:\n{}",
        all.join("\n")
    );
}

/// Builds a crate from `(file, text)` pairs in a temporary folder and returns its cycles.
fn synthetic(files: &[(&str, &str)]) -> Vec<String> {
    let dir = tempfile::tempdir().unwrap();
    for (f, text) in files {
        let p = dir.path().join(f);
        std::fs::create_dir_all(p.parent().unwrap()).unwrap();
        std::fs::write(p, text).unwrap();
    }
    let c = crate_graph(&dir.path().join("lib.rs")).unwrap();
    crate_cycles("t", &c)
}

#[test]
fn a_cycle_between_siblings_in_a_folder_is_named() {
    let found = synthetic(&[
        ("lib.rs", "pub mod io;"),
        (
            "io/mod.rs",
            "pub mod container; pub mod ktx2; pub use ktx2::Ktx2;",
        ),
        (
            "io/container.rs",
            "use super::ktx2::Metadata; pub trait Codec {}",
        ),
        (
            "io/ktx2.rs",
            "pub type Metadata = (); pub struct Ktx2; impl super::container::Codec for Ktx2 {}",
        ),
    ]);
    assert_eq!(
        found,
        ["t::io: container → ktx2 → container \
          (io::container names io::ktx2; io::ktx2 names io::container)"]
    );
}

#[test]
fn a_three_module_cycle_at_the_top_through_code_paths_is_named() {
    let found = synthetic(&[
        ("lib.rs", "mod a; mod b; mod c;"),
        ("a.rs", "fn f() { crate::b::g() }"),
        ("b/mod.rs", "mod inner; pub fn g() {}"),
        ("b/inner.rs", "fn h() -> crate::c::T { todo!() }"),
        ("c.rs", "pub struct T; use crate::a as _;"),
    ]);
    assert_eq!(
        found,
        ["t: a → b → c → a (a names b; b::inner names c; c names a)"]
    );
}

#[test]
fn parents_children_tests_and_one_way_edges_are_not_cycles() {
    let found = synthetic(&[
        (
            "lib.rs",
            "pub mod io; pub use io::Thing; fn f() { io::g() }",
        ),
        (
            "io/mod.rs",
            "mod a; mod b; pub use a::Thing; pub fn g() {} fn helper() {}",
        ),
        // A child using its parent's items and its sibling one way.
        (
            "io/a.rs",
            "use super::helper; use super::b::B; pub struct Thing;",
        ),
        // A test module naming back its sibling builds nothing.
        (
            "io/b.rs",
            "pub struct B; #[cfg(test)] mod tests { use super::super::a::Thing; }",
        ),
    ]);
    assert!(found.is_empty(), "{found:?}");
    // The same back edge outside a test module is a cycle.
    let found = synthetic(&[
        ("lib.rs", "pub mod io;"),
        ("io/mod.rs", "mod a; mod b;"),
        ("io/a.rs", "use super::b::B; pub struct Thing;"),
        (
            "io/b.rs",
            "pub struct B; mod inner { use super::super::a::Thing; }",
        ),
    ]);
    assert_eq!(
        found,
        ["t::io: a → b → a (io::a names io::b; io::b::inner names io::a)"]
    );
}
