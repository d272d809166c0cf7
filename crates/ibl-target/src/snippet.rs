//! Per-engine loading snippets for the web engines (placeholder until the `engines` branch
//! lands its version of this file, which the headless-render harness runs).

use crate::Target;

/// The code that loads a target's files in its engine.
// TODO(engines): replaced by the `engines` branch's snippet.rs (the harness pages' own code).
pub fn load_snippet(target: Target) -> String {
    format!(
        "(the {} loading snippet is added with the headless-render harness)",
        target.name()
    )
}
