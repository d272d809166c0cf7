//! The RON schema of a pipeline and its parsing, with every problem located at its line and
//! column and reported all at once where the syntax allows.
//!
//! ```ron
//! Pipeline(
//!     output: "../out/probe",                 // relative paths: to this file's folder
//!     inputs: { "sky": File("../fixtures/hdri/studio_256.exr") },   // File, Folder, Glob
//!     stages: [
//!         (id: "cube", kind: "equirect-to-cube", reads: ["sky"], params: (size: 64)),
//!     ],
//!     outputs: ["cube"],                      // optional: what the pipeline is for
//!     max_memory: "2G",                       // optional: the memory budget (`--max-memory` wins)
//!     scene: (probes: [...], materials: [...], params: {"prefilter": (...)}),   // optional
//! )
//! ```
//!
//! Parsing goes in two passes so that one bad stage does not hide the others: the file is read
//! with each stage (and the scene) kept as raw RON text borrowed from the file, then each stage is
//! parsed on its own and its `params` with the `Params` type of its kind. Positions inside a
//! stage are mapped back to the file through the borrowed text's offset.

use crate::error::{offset_of, Diagnostic, Error, Result};
use crate::kinds::{self, ron_options, AnyParams, Kind};
use crate::paths;
use ron::value::RawValue;
use serde::Deserialize;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// A source the pipeline reads from disk.
#[derive(Clone, Debug, PartialEq, Eq, Deserialize, serde::Serialize)]
pub enum Input {
    /// One file.
    File(String),
    /// A folder, read whole (its files, recursively, make its content).
    Folder(String),
    /// The files matching a glob pattern (`*`, `?`, `**`, `[...]`), sorted by path.
    Glob(String),
}

impl Input {
    /// The path or pattern as written.
    pub(crate) fn pattern(&self) -> &str {
        match self {
            Input::File(s) | Input::Folder(s) | Input::Glob(s) => s,
        }
    }
}

/// How the glossy part of a probe reaches the surfaces that use it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, Deserialize, serde::Serialize)]
pub enum Serving {
    /// Prefiltered GGX chain × DFG table.
    #[default]
    SplitSum,
    /// Spherical-harmonic exponential fit × Fresnel-tail table (no prefiltered chain).
    ShExp,
}

/// A light probe of the scene.
#[derive(Clone, Debug, PartialEq, Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields, rename = "Probe")]
pub struct Probe {
    /// The probe's name (its stages are `<id>/...`).
    pub id: String,
    /// Environment file or folder (or the name of a declared input).
    pub env: String,
    /// The largest perceptual roughness of the surfaces this probe lights.
    #[serde(default = "one")]
    pub max_roughness: f32,
    #[serde(default)]
    /// How its glossy part is served (split-sum or SH-exp).
    pub served_by: Serving,
}

fn one() -> f32 {
    1.0
}

/// The reflectance model of a material.
#[derive(Clone, Copy, Debug, PartialEq, Deserialize, serde::Serialize)]
pub enum Model {
    /// Isotropic GGX.
    Ggx,
    /// Anisotropic Ashikhmin-Shirley with exponents (n_u, n_v). Derives the lobe's `hv-lut`
    /// table (and its size/bias table, the thesis's route): what the shipped
    /// `aniso_as.{glsl,hlsl,wgsl}` snippet (`aniso-eval --emit-shader`) reads with the probe's
    /// cube.
    AshikhminShirley {
        /// Exponent along the tangent.
        n_u: f64,
        /// Exponent along the bitangent.
        n_v: f64,
    },
    /// Anisotropic GGX as (perceptual roughness r, anisotropy η) in the Kulla–Conty /
    /// Filament convention: α_t = r²(1+η), α_b = r²(1−η) (docs/ANISOTROPY.md). Rendered by
    /// the shipped `aniso-eval --emit-shader` snippet, which reads the probe's cube and its
    /// box mips only (no prefiltered chain, no DFG table).
    AnisotropicGgx {
        /// Perceptual roughness in [0, 1] (α = r²).
        roughness: f64,
        /// Anisotropy in (−1, 1): > 0 stretches the lobe along the tangent.
        eta: f64,
    },
}

/// A material of the scene.
#[derive(Clone, Debug)]
pub struct Material {
    /// The material's name (its stages are `<id>/...`).
    pub id: String,
    /// The material's folder (the thesis layout: `normal.*` inside), or a declared input's name.
    pub folder: String,
    /// Its BRDF model.
    pub model: Model,
    /// Whether it has a normal map (anisotropic ones then need a quaternion map).
    pub bump_mapped: bool,
    /// Whether it uses a TPR map.
    pub tpr_map: bool,
    /// The material's own `tpr-map` parameters (its preset): the keys it gives (`tpr_keys`)
    /// override the scene's `tpr-map` parameters one by one, the others are the scene's.
    pub tpr_params: Option<AnyParams>,
    /// The keys `tpr_params` gives, in the order written.
    pub tpr_keys: Vec<String>,
    /// Where it is declared in the file.
    pub offset: usize,
}

/// What the scene needs: the runner derives its stages from it.
#[derive(Clone, Debug)]
pub struct Scene {
    /// The probes, with where each is declared.
    pub probes: Vec<(Probe, usize)>,
    /// The materials.
    pub materials: Vec<Material>,
    /// Parameters of the derived stages, per kind (over that kind's defaults).
    pub params: BTreeMap<String, AnyParams>,
    /// Where the scene is declared.
    pub offset: usize,
}

/// A stage as declared.
#[derive(Clone)]
pub struct StageDecl {
    /// Its id.
    pub id: String,
    /// Its kind.
    pub kind: &'static dyn Kind,
    /// Its parameters, parsed by its kind.
    pub params: AnyParams,
    /// Names of inputs or ids of stages, in the order the bake takes them.
    pub reads: Vec<String>,
    /// Output folder under the pipeline's output, when not the id.
    pub out: Option<String>,
    /// Byte offset of the stage in the pipeline file (for later diagnostics).
    pub offset: usize,
}

impl std::fmt::Debug for StageDecl {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("StageDecl")
            .field("id", &self.id)
            .field("kind", &self.kind.name())
            .field("reads", &self.reads)
            .finish()
    }
}

/// A parsed pipeline (not yet checked as a graph).
#[derive(Clone, Debug)]
pub struct Pipeline {
    /// The file as given on the command line.
    pub file: PathBuf,
    /// Its text (diagnostics quote it).
    pub src: String,
    /// The folder relative paths are resolved against: the pipeline file's own.
    pub base: PathBuf,
    /// Where outputs go (the cache lives in `output/.bake/`).
    pub output: PathBuf,
    /// Declared inputs: name -> (input, where declared).
    pub inputs: BTreeMap<String, (Input, usize)>,
    /// Declared stages.
    pub stages: Vec<StageDecl>,
    /// The `outputs` list, if any, with where each is named.
    pub targets: Option<Vec<(String, usize)>>,
    /// The scene, if any.
    pub scene: Option<Scene>,
    /// `max_memory: "2G"`: the memory budget of a run (as `--max-memory`, which wins over it),
    /// in bytes.
    pub max_memory: Option<u64>,
}

impl Pipeline {
    /// A path of the pipeline resolved against its folder.
    pub fn resolve(&self, p: &str) -> PathBuf {
        paths::normalize(&self.base.join(p))
    }
    /// A diagnostic at byte `offset` of the file.
    pub(crate) fn diag(&self, offset: usize, msg: impl Into<String>) -> Diagnostic {
        Diagnostic::at(&self.file, &self.src, offset, msg)
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields, rename = "Pipeline")]
struct RawPipeline<'a> {
    #[serde(default)]
    output: Option<String>,
    #[serde(default)]
    inputs: BTreeMap<String, Input>,
    #[serde(default, borrow)]
    stages: Vec<&'a RawValue>,
    #[serde(default)]
    outputs: Option<Vec<String>>,
    #[serde(default, borrow)]
    scene: Option<&'a RawValue>,
    #[serde(default)]
    max_memory: Option<Size>,
}

/// A size as `--max-memory` takes it: `"512M"`, `"8G"`, or a number of bytes.
#[derive(Deserialize)]
#[serde(untagged)]
enum Size {
    Bytes(u64),
    Text(String),
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields, rename = "Stage")]
struct RawStage<'a> {
    id: String,
    kind: String,
    #[serde(default)]
    reads: Vec<String>,
    #[serde(default, borrow)]
    params: Option<&'a RawValue>,
    #[serde(default)]
    out: Option<String>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields, rename = "Scene")]
struct RawScene<'a> {
    #[serde(default, borrow)]
    probes: Vec<&'a RawValue>,
    #[serde(default, borrow)]
    materials: Vec<&'a RawValue>,
    #[serde(default, borrow)]
    params: BTreeMap<String, &'a RawValue>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields, rename = "Material")]
struct RawMaterial<'a> {
    id: String,
    folder: String,
    model: Model,
    #[serde(default)]
    bump_mapped: bool,
    #[serde(default)]
    tpr_map: bool,
    #[serde(default, borrow)]
    tpr_params: Option<&'a RawValue>,
}

/// The keys of a RON struct `(key: value, ...)`, in the order written (values not parsed).
struct Keys(Vec<String>);

impl<'de> Deserialize<'de> for Keys {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        struct V;
        impl<'de> serde::de::Visitor<'de> for V {
            type Value = Keys;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("parameters `(key: value, ...)`")
            }
            fn visit_map<A: serde::de::MapAccess<'de>>(
                self,
                mut m: A,
            ) -> std::result::Result<Keys, A::Error> {
                let mut keys = Vec::new();
                while let Some(k) = m.next_key::<String>()? {
                    m.next_value::<serde::de::IgnoredAny>()?;
                    keys.push(k);
                }
                Ok(Keys(keys))
            }
        }
        d.deserialize_struct("Params", &[], V)
    }
}

/// Byte offset of `part` (a slice of `src`) in `src`.
fn offset_in(src: &str, part: &str) -> usize {
    let (s, p) = (src.as_ptr() as usize, part.as_ptr() as usize);
    debug_assert!(
        p >= s && p + part.len() <= s + src.len(),
        "raw value not borrowed from the source"
    );
    p.saturating_sub(s).min(src.len())
}

/// A ron error inside `part` (a slice of `src`) as a diagnostic located in `src`.
fn ron_diag(
    file: &Path,
    src: &str,
    part: &str,
    e: &ron::error::SpannedError,
    context: &str,
) -> Diagnostic {
    let base = offset_in(src, part);
    let inner = offset_of(part, e.span.start.line, e.span.start.col);
    let msg = if context.is_empty() {
        e.code.to_string()
    } else {
        format!("{context}: {}", e.code)
    };
    Diagnostic::at(file, src, base + inner, msg)
}

/// The byte offset of the opening quote of each string's first occurrence in `src` (the raw
/// text between the quotes, escapes as written: names are plain).
fn first_quoted(src: &str) -> std::collections::HashMap<&str, usize> {
    let mut map = std::collections::HashMap::new();
    let b = src.as_bytes();
    let mut i = 0;
    while i < b.len() {
        if b[i] != b'"' {
            i += 1;
            continue;
        }
        let start = i;
        i += 1;
        while i < b.len() && b[i] != b'"' {
            i += if b[i] == b'\\' { 2 } else { 1 };
        }
        let end = i.min(b.len());
        // Quotes are ASCII, so both ends are character boundaries.
        map.entry(&src[start + 1..end]).or_insert(start);
        i += 1;
    }
    map
}

/// Offset of the first occurrence of `needle` in `part`, else of `part` itself.
fn find_in(src: &str, part: &str, needle: &str) -> usize {
    offset_in(src, part) + part.find(needle).unwrap_or(0)
}

/// Reads and parses a pipeline file.
pub fn load(file: &Path) -> Result<Pipeline> {
    let bytes = std::fs::read(file).map_err(|e| Error::io(file, e))?;
    // An image or any other binary file handed to `bake run` is a usage mistake (exit 2),
    // not a file-system error: say what the file is not.
    let src = String::from_utf8(bytes).map_err(|_| {
        Error::invalid(Diagnostic::global(
            file,
            "not a RON pipeline (the file is binary, not text; `bake run` takes a .ron \
             pipeline such as pipelines/probe.ron)",
        ))
    })?;
    // A UTF-8 byte-order mark (some Windows editors write one) is not part of the text.
    let src = match src.strip_prefix('\u{feff}') {
        Some(rest) => rest.to_string(),
        None => src,
    };
    parse(file, src)
}

/// Parses a pipeline's text; `file` names it in diagnostics and sets the base folder.
pub fn parse(file: &Path, src: String) -> Result<Pipeline> {
    let mut diags = Vec::new();
    let base = file
        .parent()
        .map(|p| {
            if p.as_os_str().is_empty() {
                Path::new(".")
            } else {
                p
            }
        })
        .unwrap_or(Path::new("."))
        .to_path_buf();
    let raw: RawPipeline = match ron_options().from_str(&src) {
        Ok(r) => r,
        Err(e) => return Err(Error::invalid(ron_diag(file, &src, &src, &e, ""))),
    };
    let output = raw.output.clone().unwrap_or_else(|| "out".to_string());
    // Where each string first appears, found in one pass: searching the text once per input
    // made planning quadratic in the number of inputs (40k inputs: 15 s).
    let quoted = first_quoted(&src);
    let mut inputs = BTreeMap::new();
    for (name, input) in &raw.inputs {
        let at = quoted.get(name.as_str()).copied().unwrap_or(0);
        if let Input::Glob(pat) = input {
            if let Err(e) = glob::Pattern::new(pat) {
                diags.push(Diagnostic::at(
                    file,
                    &src,
                    at,
                    format!("input '{name}': bad glob pattern '{pat}': {e}"),
                ));
            }
        }
        inputs.insert(name.clone(), (input.clone(), at));
    }

    let mut stages = Vec::new();
    for raw_stage in &raw.stages {
        let text = raw_stage.get_ron();
        let offset = offset_in(&src, text);
        let st: RawStage = match ron_options().from_str(text) {
            Ok(s) => s,
            Err(e) => {
                diags.push(ron_diag(file, &src, text, &e, "stage"));
                continue;
            }
        };
        let Some(kind) = kinds::find(&st.kind) else {
            let at = find_in(&src, text, &format!("\"{}\"", st.kind));
            diags.push(Diagnostic::at(
                file,
                &src,
                at,
                format!(
                    "stage '{}': unknown kind '{}' (valid kinds: {})",
                    st.id,
                    st.kind,
                    kinds::names().join(", ")
                ),
            ));
            continue;
        };
        let params = match st.params {
            None => kind.default_params(),
            Some(p) => match kind.parse(p.get_ron()) {
                Ok(p) => p,
                Err(e) => {
                    diags.push(ron_diag(
                        file,
                        &src,
                        p.get_ron(),
                        &e,
                        &format!("stage '{}' ({}) params", st.id, kind.name()),
                    ));
                    continue;
                }
            },
        };
        if let Err(e) = kind.validate(&params) {
            let at = st
                .params
                .map(|p| offset_in(&src, p.get_ron()))
                .unwrap_or(offset);
            diags.push(Diagnostic::at(
                file,
                &src,
                at,
                format!("stage '{}' ({}): {}", st.id, kind.name(), e.message),
            ));
            continue;
        }
        stages.push(StageDecl {
            id: st.id,
            kind,
            params,
            reads: st.reads,
            out: st.out,
            offset,
        });
    }

    let targets = raw.outputs.map(|outs| {
        outs.into_iter()
            .map(|o| (quoted.get(o.as_str()).copied().unwrap_or(0), o))
            .map(|(at, o)| (o, at))
            .collect()
    });
    let scene = raw
        .scene
        .and_then(|s| parse_scene(file, &src, s, &mut diags));
    let max_memory = match raw.max_memory {
        None => None,
        Some(Size::Bytes(b)) if b > 0 => Some(b),
        Some(size) => {
            let text = match size {
                Size::Bytes(b) => b.to_string(),
                Size::Text(t) => t,
            };
            match ibl_core::io::budget::parse_size(&text) {
                Ok(b) => Some(b),
                Err(e) => {
                    let at = quoted.get(text.as_str()).copied();
                    let at = at.or_else(|| src.find("max_memory")).unwrap_or(0);
                    diags.push(Diagnostic::at(file, &src, at, format!("max_memory: {e}")));
                    None
                }
            }
        }
    };
    if !diags.is_empty() {
        return Err(Error::Invalid(diags));
    }
    let output = paths::normalize(&base.join(output));
    Ok(Pipeline {
        file: file.to_path_buf(),
        src: src.clone(),
        base,
        output,
        inputs,
        stages,
        targets,
        scene,
        max_memory,
    })
}

fn parse_scene(
    file: &Path,
    src: &str,
    raw: &RawValue,
    diags: &mut Vec<Diagnostic>,
) -> Option<Scene> {
    let text = raw.get_ron();
    let rs: RawScene = match ron_options().from_str(text) {
        Ok(s) => s,
        Err(e) => {
            diags.push(ron_diag(file, src, text, &e, "scene"));
            return None;
        }
    };
    let mut scene = Scene {
        probes: Vec::new(),
        materials: Vec::new(),
        params: BTreeMap::new(),
        offset: offset_in(src, text),
    };
    for (kind_name, p) in &rs.params {
        let at = find_in(src, text, &format!("\"{kind_name}\""));
        let Some(kind) = kinds::find(kind_name) else {
            diags.push(Diagnostic::at(
                file,
                src,
                at,
                format!(
                    "scene params: unknown kind '{kind_name}' (valid kinds: {})",
                    kinds::names().join(", ")
                ),
            ));
            continue;
        };
        // Validated once the scene's values (max roughness, exponents) are in: see `scene`.
        match kind.parse(p.get_ron()) {
            Ok(params) => {
                scene.params.insert(kind_name.clone(), params);
            }
            Err(e) => diags.push(ron_diag(
                file,
                src,
                p.get_ron(),
                &e,
                &format!("scene params for '{kind_name}'"),
            )),
        }
    }
    for p in &rs.probes {
        match ron_options().from_str::<Probe>(p.get_ron()) {
            Ok(probe) => {
                let at = offset_in(src, p.get_ron());
                if !(0.0..=1.0).contains(&probe.max_roughness) {
                    diags.push(Diagnostic::at(
                        file,
                        src,
                        at,
                        format!(
                            "probe '{}': max_roughness {} is outside [0, 1]",
                            probe.id, probe.max_roughness
                        ),
                    ));
                }
                scene.probes.push((probe, at));
            }
            Err(e) => diags.push(ron_diag(file, src, p.get_ron(), &e, "probe")),
        }
    }
    for m in &rs.materials {
        let rm: RawMaterial = match ron_options().from_str(m.get_ron()) {
            Ok(rm) => rm,
            Err(e) => {
                diags.push(ron_diag(file, src, m.get_ron(), &e, "material"));
                continue;
            }
        };
        let at = offset_in(src, m.get_ron());
        if let Model::AshikhminShirley { n_u, n_v } = rm.model {
            if !(n_u.is_finite() && n_v.is_finite() && n_u > 0.0 && n_v > 0.0) {
                diags.push(Diagnostic::at(
                    file,
                    src,
                    at,
                    format!(
                        "material '{}': n_u and n_v must be positive, got ({n_u}, {n_v})",
                        rm.id
                    ),
                ));
            }
        }
        if let Model::AnisotropicGgx { roughness, eta } = rm.model {
            if !((0.0..=1.0).contains(&roughness) && eta > -1.0 && eta < 1.0) {
                diags.push(Diagnostic::at(
                    file,
                    src,
                    at,
                    format!(
                        "material '{}': AnisotropicGgx needs roughness in [0, 1] and eta in (-1, 1), got ({roughness}, {eta})",
                        rm.id
                    ),
                ));
            }
        }
        let tpr_keys = rm
            .tpr_params
            .and_then(|raw| ron_options().from_str::<Keys>(raw.get_ron()).ok())
            .map(|k| k.0)
            .unwrap_or_default();
        let tpr_params = match rm.tpr_params {
            None => None,
            Some(raw) => {
                match kinds::find("tpr-map") {
                    None => {
                        diags.push(Diagnostic::at(file, src, offset_in(src, raw.get_ron()), format!("material '{}': tpr_params given but this build has no 'tpr-map' kind", rm.id)));
                        None
                    }
                    Some(k) => match k.parse(raw.get_ron()) {
                        Ok(p) => Some(p),
                        Err(e) => {
                            diags.push(ron_diag(
                                file,
                                src,
                                raw.get_ron(),
                                &e,
                                &format!("material '{}' tpr_params", rm.id),
                            ));
                            None
                        }
                    },
                }
            }
        };
        scene.materials.push(Material {
            id: rm.id,
            folder: rm.folder,
            model: rm.model,
            bump_mapped: rm.bump_mapped,
            tpr_map: rm.tpr_map,
            tpr_params,
            tpr_keys,
            offset: at,
        });
    }
    Some(scene)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse_str(s: &str) -> Result<Pipeline> {
        parse(Path::new("dir/p.ron"), s.to_string())
    }

    fn diags(s: &str) -> Vec<Diagnostic> {
        match parse_str(s) {
            Err(Error::Invalid(d)) => d,
            Err(e) => panic!("unexpected error {e}"),
            Ok(_) => panic!("parsed"),
        }
    }

    #[test]
    fn a_small_pipeline_parses_with_defaults_and_relative_paths() {
        let p = parse_str(
            r#"Pipeline(
                output: "../out/x",
                inputs: { "sky": File("sky.exr"), "all": Glob("hdr/*.exr") },
                stages: [ (id: "cube", kind: "equirect-to-cube", reads: ["sky"], params: (size: 8)) ],
            )"#,
        )
        .unwrap();
        assert_eq!(p.output, PathBuf::from("out/x"));
        assert_eq!(p.resolve("sky.exr"), PathBuf::from("dir/sky.exr"));
        assert_eq!(p.stages.len(), 1);
        assert_eq!(p.stages[0].kind.name(), "equirect-to-cube");
        assert!(kinds::canonical_text(&p.stages[0].params).contains("\"size\":8"));
        assert!(p.targets.is_none() && p.scene.is_none());
    }

    #[test]
    fn a_byte_order_mark_is_not_text() {
        let dir = tempfile::tempdir().unwrap();
        let f = dir.path().join("p.ron");
        std::fs::write(&f, "\u{feff}(stages: [])").unwrap();
        load(&f).unwrap();
        // Only at the start: elsewhere it is a character RON refuses.
        std::fs::write(&f, "(stages: \u{feff}[])").unwrap();
        assert!(load(&f).is_err());
    }

    #[test]
    fn syntax_error_has_line_column_and_the_offending_line() {
        let d = diags("Pipeline(\n  stages: [\n    (id: \"a\" kind: \"x\"),\n  ],\n)");
        assert_eq!(d.len(), 1);
        assert_eq!(d[0].line, Some(3), "{}", d[0]);
        assert!(
            d[0].snippet.as_ref().unwrap().contains("(id: \"a\" kind"),
            "{}",
            d[0]
        );
        eprintln!("{}", d[0]);
    }

    #[test]
    fn all_stage_problems_are_reported_at_once_with_positions() {
        let src = "Pipeline(\n  stages: [\n    (id: \"a\", kind: \"equirect-to-cub\"),\n    (id: \"b\", kind: \"equirect-to-cube\", params: (size: 8,\n       sise: 3)),\n    (id: \"c\", kind: \"equirect-to-cube\", colour: 1),\n  ],\n)";
        let d = diags(src);
        for x in &d {
            eprintln!("{x}");
        }
        assert_eq!(d.len(), 3);
        assert!(
            d[0].message.contains("unknown kind 'equirect-to-cub'")
                && d[0].message.contains("valid kinds: equirect-to-cube")
        );
        assert_eq!((d[0].line, d[0].col), (Some(3), Some(21)));
        assert!(
            d[1].message.contains("sise") && d[1].message.contains("size"),
            "lists the valid names: {}",
            d[1].message
        );
        assert_eq!((d[1].line, d[1].col), (Some(5), Some(8)));
        assert!(d[2].message.contains("colour"));
        assert_eq!(d[2].line, Some(6));
    }

    #[test]
    fn bad_parameter_values_are_refused_by_the_bakes_validation() {
        let d = diags("(stages: [(id: \"a\", kind: \"equirect-to-cube\", params: (size: 0))])");
        assert!(d[0].message.contains("out of range"), "{}", d[0]);
    }

    #[test]
    fn a_binary_file_is_not_a_pipeline_and_an_invalid_input() {
        let dir = tempfile::tempdir().unwrap();
        let f = dir.path().join("forest.exr");
        std::fs::write(&f, [0x76, 0x2f, 0x31, 0x01, 0xff, 0xfe, 0x00]).unwrap();
        let e = load(&f).unwrap_err();
        assert!(e.to_string().contains("not a RON pipeline"), "{e}");
        assert_eq!(
            ibl_core::error::Classify::class(&e),
            ibl_core::error::ErrorClass::InvalidInput
        );
    }

    #[test]
    fn unknown_top_level_key_is_refused() {
        let d = diags("Pipeline(stagse: [])");
        assert!(
            d[0].message.contains("stagse") && d[0].message.contains("stages"),
            "{}",
            d[0]
        );
        assert_eq!(d[0].col, Some(10));
    }

    #[test]
    fn scene_parses_and_checks_its_values() {
        let p = parse_str(
            r#"(scene: (
                probes: [(id: "lobby", env: "a.exr", max_roughness: 0.5), (id: "sky", env: "b.exr", served_by: ShExp)],
                materials: [(id: "brushed", folder: "m/b", model: AshikhminShirley(n_u: 100, n_v: 10), bump_mapped: true)],
                params: { "equirect-to-cube": (size: 16) },
            ))"#,
        )
        .unwrap();
        let s = p.scene.unwrap();
        assert_eq!(s.probes[0].0.served_by, Serving::SplitSum);
        assert_eq!(s.probes[1].0.max_roughness, 1.0);
        assert_eq!(
            s.materials[0].model,
            Model::AshikhminShirley {
                n_u: 100.0,
                n_v: 10.0
            }
        );
        let d = diags(
            r#"(scene: (probes: [(id: "p", env: "a", max_roughness: 1.5)], materials: [(id: "m", folder: "f", model: Ggx, shiny: true)], params: {"nope": ()}))"#,
        );
        assert_eq!(d.len(), 3, "{d:?}");
    }

    #[test]
    fn anisotropic_ggx_parses_and_checks_its_range() {
        let p = parse_str(
            r#"(scene: (probes: [(id: "p", env: "a")], materials: [(id: "m", folder: "f", model: AnisotropicGgx(roughness: 0.5, eta: -0.9))]))"#,
        )
        .unwrap();
        assert_eq!(
            p.scene.unwrap().materials[0].model,
            Model::AnisotropicGgx {
                roughness: 0.5,
                eta: -0.9
            }
        );
        for (r, eta) in [(1.5, 0.0), (0.5, 1.0), (0.5, -1.2), (-0.1, 0.0)] {
            let d = diags(&format!(
                r#"(scene: (probes: [(id: "p", env: "a")], materials: [(id: "m", folder: "f", model: AnisotropicGgx(roughness: {r:?}, eta: {eta:?}))]))"#
            ));
            assert!(
                d.len() == 1
                    && d[0]
                        .to_string()
                        .contains("AnisotropicGgx needs roughness in [0, 1]"),
                "{d:?}"
            );
        }
    }
}
