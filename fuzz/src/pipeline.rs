//! Entry point of the `pipeline` fuzz target: the RON pipeline loader of `ibl-pipeline`
//! (`schema::parse`, the text parser behind `ibl_pipeline::load`, then `graph::build`, the
//! checks that run before any work) on arbitrary text.

use ibl_pipeline::schema::{self, Input, Pipeline};
use std::path::Path;

/// A base folder that does not exist, so relative input paths resolve to nothing quickly.
const FILE: &str = ".ibl-fuzz-no-such-folder/f.ron";

/// True unless the graph builder would walk a real folder or glob outside the missing base
/// folder (`Folder("/")`, `Glob("/**")`, a scene path naming `..`): slow, not wrong, so such
/// pipelines are only parsed. Files are only looked at (`is_file`), whatever their path.
fn cheap_to_build(p: &Pipeline) -> bool {
    let local = |s: &str| !Path::new(s).has_root() && !s.contains("..");
    let not_a_dir = |s: &str| !p.resolve(s).is_dir();
    let inputs = p.inputs.values().all(|(i, _)| match i {
        Input::File(_) => true,
        Input::Folder(s) => not_a_dir(s),
        Input::Glob(s) => local(s),
    });
    let scene = p.scene.as_ref().is_none_or(|s| {
        s.probes.iter().all(|(probe, _)| not_a_dir(&probe.env))
            && s.materials.iter().all(|m| not_a_dir(&m.folder))
    });
    inputs && scene
}

/// `pipeline` target. Like `ibl_pipeline::load`, text that is not UTF-8 never reaches the parser
/// (`read_to_string` refuses it), so it is skipped here.
pub fn pipeline(data: &[u8]) {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    if let Ok(p) = schema::parse(Path::new(FILE), text.to_string()) {
        if cheap_to_build(&p) {
            let _ = ibl_pipeline::graph::build(p);
        }
    }
}
