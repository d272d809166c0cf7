//! Exports `IBL_BUILD_FINGERPRINT`: a hash of the workspace's crate sources, part of every cache
//! key (see `cache::tool`).
//!
//! The package version alone does not change when a commit changes how a bake computes its
//! results, so without this a cache built by older code would be reused after pulling such a
//! commit. The fingerprint covers every `crates/*/src/**/*.rs` and `crates/*/Cargo.toml` (the
//! bakes and everything they depend on in the workspace), plus the workspace's `Cargo.toml` and
//! `Cargo.lock` (dependency versions). It is deterministic: files are hashed in sorted order of
//! their path relative to the workspace, by path and content only (never mtimes or absolute
//! paths), so the same sources give the same fingerprint in any checkout, and a change to any
//! of them gives a new one (cached results are then rebuilt once).
//!
//! Stage keys use a narrower fingerprint per library crate (`library_fingerprints.rs` in
//! `OUT_DIR`): only that crate and its workspace dependencies, without test code, so editing a
//! test, the plotting crate or another bake's library re-bakes nothing it does not run.

#[path = "build/fingerprint.rs"]
mod fingerprint;

use std::path::PathBuf;

fn main() {
    let manifest_dir =
        PathBuf::from(std::env::var_os("CARGO_MANIFEST_DIR").expect("cargo sets it"));
    let workspace = manifest_dir.join("../..");
    let (fp, watch) = fingerprint::fingerprint(&workspace)
        .unwrap_or_else(|e| panic!("fingerprinting the workspace sources: {e}"));
    for p in watch {
        println!("cargo:rerun-if-changed={}", p.display());
    }
    // A crate added later is picked up when a Cargo.toml naming it changes.
    println!("cargo:rerun-if-changed=build.rs");
    println!("cargo:rerun-if-changed=build/fingerprint.rs");
    println!("cargo:rustc-env=IBL_BUILD_FINGERPRINT={fp}");
    // Per library crate, the fingerprint of the code its bakes run (`cache::tool_for`).
    let libraries = fingerprint::library_fingerprints(&workspace)
        .unwrap_or_else(|e| panic!("fingerprinting the workspace crates: {e}"));
    let table: String = libraries
        .iter()
        .map(|(name, fp)| format!("    ({name:?}, {fp:?}),\n"))
        .collect();
    let out = PathBuf::from(std::env::var_os("OUT_DIR").expect("cargo sets it"));
    std::fs::write(
        out.join("library_fingerprints.rs"),
        format!("&[\n{table}]\n"),
    )
    .unwrap_or_else(|e| panic!("writing the library fingerprints: {e}"));
}
