//! The pipeline runner's library: RON pipelines ([`schema`]) become a checked stage graph
//! ([`graph`], with the stages a scene needs derived by `scene` and each stage's [`need`]),
//! planned against a content-addressed cache ([`plan`], `cache`), run in parallel in-process
//! ([`exec`]: its scheduler, [`exec::session`] and [`exec::commit`]), stage by stage by another
//! executor ([`remote`]), or written out as a ninja file ([`ninja`]). Each stage kind is a
//! small adapter over a bake library's `Params` and `run` ([`kinds`]).
//!
//! Relative paths in a pipeline are relative to the pipeline file's folder, so a pipeline
//! means the same from any working folder. Everything the runner keeps lives under the
//! pipeline's output folder, in `.bake/` (see [`cache`]). `pipelines/README.md` at the
//! workspace root describes the schema and the commands.

#![warn(missing_docs)]

pub(crate) mod cache;
pub mod cli;
pub mod error;
pub mod exec;
pub mod graph;
pub mod kinds;
pub mod need;
pub mod ninja;
pub mod owned;
pub mod paths;
pub mod plan;
pub mod remote;
pub(crate) mod scene;
pub mod schema;

pub use error::{Diagnostic, Error, Result};
pub use graph::Graph;

/// Reads, parses and checks a pipeline file: every problem found before any work.
pub fn load(file: &std::path::Path) -> Result<Graph> {
    graph::build(schema::load(file)?)
}
