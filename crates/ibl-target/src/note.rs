//! The how-to-load note (`LOAD.txt`) every cube writer leaves beside its outputs: which files
//! this run wrote (and no other), what each one is to the engine, in the engine's own API and
//! units, and the loading code as a snippet.
//!
//! The note is built from what the run actually wrote ([`Outputs`]), never from the target's
//! table alone: a run of `prefilter` names its chain, not the skybox `equirect-to-cube` writes
//! or the SH file `irradiance` writes (issue 22: notes named `env_skybox.ktx`, `sh.txt` and
//! container names under `--layout faces` that the run had not written). A file of another
//! run is referred to by the command that writes it.

use crate::{snippet, Target, TargetSpec};
use std::fmt::Write as _;

/// The tool whose run the note describes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Writer {
    /// `equirect-to-cube`: the environment (skybox) cube.
    Cube,
    /// `prefilter`: the GGX chain (and Babylon's `.env`).
    Prefilter,
    /// `irradiance`: the SH coefficients, the E/π cube, the engine's SH file.
    Irradiance,
}

impl Writer {
    /// The command line that writes this kind of output for `target`.
    fn command(self, target: Target) -> String {
        let tool = match self {
            Writer::Cube => "equirect-to-cube",
            Writer::Prefilter => "prefilter",
            Writer::Irradiance => "irradiance",
        };
        format!("{tool} --target {}", target.name())
    }
}

/// What one run wrote, by role: file names inside the output folder (a cube written as faces
/// is the list of its face files). Every name here is written by the run; the note names no
/// other file.
#[derive(Clone, Debug, Default)]
pub struct Outputs {
    /// The environment cube (`equirect-to-cube`).
    pub cube: Vec<String>,
    /// The specular chain (`prefilter`, unless Babylon's `.env` replaces it).
    pub chain: Vec<String>,
    /// Levels of the chain.
    pub levels: usize,
    /// Babylon's `.env` (`prefilter --target babylon`).
    pub env: Option<String>,
    /// `prefilter.json`.
    pub report: Option<String>,
    /// What `--max-roughness` did to the chain, if it cut it.
    pub max_roughness: Option<String>,
    /// The E/π irradiance cube (`irradiance`).
    pub irradiance: Vec<String>,
    /// Our SH coefficients (`sh.json`).
    pub sh: Option<String>,
    /// The engine's own SH file (`sh.txt`, `LightProbe.json`, `SphericalHarmonicsL2.json`).
    pub engine_sh: Option<String>,
    /// Sidecars recording a lossy encoding's cost (`<name>.encoding.json`).
    pub sidecars: Vec<String>,
    /// The sidecar recording the cube's orientation (DDS, EXR faces in an engine's frame).
    pub orientation: Option<String>,
    /// The custom target's lookup function (`lookup.glsl`, `.hlsl`, `.wgsl`).
    pub lookup: Vec<String>,
}

/// The file names (inside the output folder) of the files a writer encoded.
pub fn names<'a>(files: impl IntoIterator<Item = &'a std::path::Path>) -> Vec<String> {
    files
        .into_iter()
        .filter_map(|p| p.file_name())
        .map(|n| n.to_string_lossy().into_owned())
        .collect()
}

/// A cube's files as a note names them: the container, or the first and last face file and
/// their count.
fn files(list: &[String]) -> String {
    match list {
        [] => String::new(),
        [one] => one.clone(),
        [first, .., last] => format!("{first} … {last} ({} EXR faces)", list.len()),
    }
}

/// The string literal a snippet loads: the file this run wrote, or a placeholder naming the
/// command that writes it.
fn lit(list: &[String], other: &str) -> String {
    match list {
        [one] => one.clone(),
        [] => format!("<{other} output>"),
        _ => format!("<the {} faces above>", list.len()),
    }
}

/// Orientation as a user reads it.
fn orientation_text(spec: &TargetSpec) -> &'static str {
    match spec.target {
        Target::Gltf => "our frame (+Y up; faces +X -X +Y -Y +Z -Z, rows top first), as glTF viewers sample it",
        Target::Bevy => "z negated, as Bevy samples cubes (environment_map.wesl: sample_dir.z = -sample_dir.z), so the environment shows as the source panorama",
        Target::Filament => "turned 90 degrees about +Y, as cmgen orients the same panorama",
        Target::Three => "x mirrored, as three.js samples CubeTextures (flipEnvMap = -1)",
        Target::Babylon => "z negated, for Babylon's default left-handed scene",
        Target::Unity => "z negated, for Unity's left-handed frame",
        Target::Custom => "our frame (+Y up; faces +X -X +Y -Y +Z -Z, rows top first), as the emitted lookup samples it",
    }
}

/// The note for one run: a header, the files, what each one is, the snippet.
pub fn load_note(target: Target, writer: Writer, out: &Outputs) -> String {
    let spec = target.spec();
    let mut s = String::new();
    let _ = writeln!(
        s,
        "{} — written by `{}` (this run wrote only the files named below).",
        spec.engine,
        writer.command(target)
    );
    let _ = writeln!(s);
    let _ = writeln!(s, "Files:");
    let mut line = |what: &str, name: String| {
        if !name.is_empty() {
            let _ = writeln!(s, "  {name}: {what}");
        }
    };
    line("the environment cube", files(&out.cube));
    line(
        &format!(
            "the GGX chain, {} levels, level l at the roughness the engine's lookup ({}) reads there",
            out.levels,
            spec.lod.name()
        ),
        files(&out.chain),
    );
    line(
        "the lookup function that reads the chain (GLSL, HLSL, WGSL)",
        files(&out.lookup),
    );
    if let Some(e) = &out.env {
        line(
            "Babylon's .env: the GGX chain (RGBD PNG levels) and the irradiance harmonics in its JSON manifest",
            e.clone(),
        );
    }
    if let Some(r) = &out.report {
        line(
            "what the bake did: per level roughness, error against the exact kernel, and the error the engine's lookup sees (`runtime`)",
            r.clone(),
        );
    }
    line(
        "the irradiance cube (E/pi: the radiance a white Lambertian surface reflects)",
        files(&out.irradiance),
    );
    if let Some(f) = &out.sh {
        line(
            "SH coefficients of the radiance and of E/pi (our basis and frame, docs/CONVENTIONS.md)",
            f.clone(),
        );
    }
    if let Some(f) = &out.engine_sh {
        line(&engine_sh_text(target), f.clone());
    }
    for f in &out.sidecars {
        line("what the lossy pixel format cost per level", f.clone());
    }
    if let Some(f) = &out.orientation {
        line(
            "the cube's orientation, which our tools read back (a KTX file keeps it in its ibl.orientation key instead)",
            f.clone(),
        );
    }
    let _ = writeln!(s);
    let _ = writeln!(s, "Orientation: {}.", orientation_text(&spec));
    if let Some(m) = &out.max_roughness {
        let _ = writeln!(
            s,
            "Max roughness: {m}. Materials rougher than the cut read those exact, unfitted levels."
        );
    }
    let _ = writeln!(s, "Units: {}", units_text(target));
    let _ = writeln!(s);
    let _ = writeln!(s, "Load it:");
    let _ = writeln!(s, "{}", usage(target, writer, out).trim_end());
    let _ = writeln!(s);
    let _ = writeln!(s, "Snippet:");
    let _ = writeln!(s, "{}", engine_snippet(target, writer, out).trim_end());
    s
}

/// What the engine's own SH file holds.
fn engine_sh_text(target: Target) -> String {
    match target {
        Target::Filament => "the 9 pre-scaled irradiance coefficients as cmgen --sh-shader writes them (IndirectLight::Builder().irradiance(3, sh))".into(),
        Target::Three => "a three.js LightProbe (radiance SH in three's basis), as LightProbe.toJSON writes it: new THREE.ObjectLoader().parse(json)".into(),
        Target::Unity => "Unity's SphericalHarmonicsL2 sh[rgb, i] (pre-multiplied, left-handed) and the packed unity_SHAr..unity_SHC".into(),
        _ => "the engine's SH form".into(),
    }
}

/// The engine's units for the files' values.
fn units_text(target: Target) -> &'static str {
    match target {
        // bevyengine/bevy `crates/bevy_pbr/src/light_probe/environment_map.rs`
        // (EnvironmentMapLight::intensity: "after applying this multiplier, the resulting
        // values should be in units of cd/m^2"); its examples use 900.0
        // (`examples/3d/pbr.rs`), 250.0 (`examples/3d/load_gltf.rs`), 2000.0 elsewhere, under
        // Bevy's default camera exposure.
        Target::Bevy => "the files hold the panorama's own values; EnvironmentMapLight.intensity scales them to cd/m^2. For a display-referred panorama (sky values near 1) use hundreds to thousands, as Bevy's examples do (900.0 in examples/3d/pbr.rs, 250.0 in examples/3d/load_gltf.rs) under Bevy's default exposure; intensity 1.0 shows it nearly black. A panorama calibrated in cd/m^2 takes 1.0.",
        // google/filament `filament/include/filament/IndirectLight.h` (intensity: "default is
        // 30000", in lux for the environment's unit value) and `Skybox.h`.
        Target::Filament => "the files hold the panorama's own values; IndirectLight::Builder().intensity(lux) scales them (Filament's default 30000, matched with a camera exposure as in Filament's samples); give the Skybox the same intensity.",
        Target::Three => "the panorama's own values; scene.environmentIntensity / material.envMapIntensity and LightProbe.intensity scale them (three's default 1).",
        Target::Babylon => "the panorama's own values; scene.environmentIntensity scales them (Babylon's default 1).",
        Target::Unity => "the panorama's own values; the reflection probe's / RenderSettings.reflectionIntensity and ambientIntensity scale them (Unity's default 1).",
        Target::Gltf => "the panorama's own values (linear RGB); the viewer's environment intensity / exposure scales them.",
        Target::Custom => "the panorama's own values (linear RGB); your renderer's exposure scales them.",
    }
}

/// What each written file is to the engine, in its API.
fn usage(target: Target, writer: Writer, out: &Outputs) -> String {
    let chain = files(&out.chain);
    let cube = files(&out.cube);
    let irr = files(&out.irradiance);
    match (target, writer) {
        (Target::Gltf, Writer::Prefilter) => format!("{chain} is the viewer's GGX cube: textureLod(u_GGXEnvSampler, R, roughness * float(mipCount - 1)) (KhronosGroup/glTF-Sample-Viewer source/Renderer/shaders/ibl.glsl); load a KTX2 with libktx as the viewer's ResourceLoader does."),
        (Target::Gltf, Writer::Irradiance) => format!("{irr} is the viewer's Lambertian cube (E/pi; multiplied by the diffuse colour)."),
        (Target::Gltf, Writer::Cube) => format!("{cube} is the environment (background) cube; the viewer's GGX and Lambertian cubes come from `prefilter` and `irradiance`."),
        (Target::Bevy, Writer::Prefilter) => format!("{chain} is EnvironmentMapLight.specular_map (Bevy reads lod = roughness * (mipCount - 1)); enable Bevy's `ktx2` and `zstd_rust` features."),
        (Target::Bevy, Writer::Irradiance) => format!("{irr} is EnvironmentMapLight.diffuse_map; enable Bevy's `ktx2` and `zstd_rust` features."),
        (Target::Bevy, Writer::Cube) => format!("{cube} is the Skybox image (bevy::core_pipeline::Skybox); enable Bevy's `ktx2` and `zstd_rust` features."),
        (Target::Filament, Writer::Prefilter) => format!("{chain} is the IndirectLight reflections cube (ktxreader::Ktx1Reader::createTexture); its `sh` metadata holds the 9 pre-scaled irradiance coefficients (Ktx1Bundle::getSphericalHarmonics). Level l is at cmgen's roughness 1 - sqrt(1 - l/(N-1)), which Filament's lod = (N-1) r(2-r) lands on."),
        (Target::Filament, Writer::Irradiance) => format!("{} holds the IndirectLight irradiance: IndirectLight::Builder().irradiance(3, sh).", out.engine_sh.clone().unwrap_or_default()),
        (Target::Filament, Writer::Cube) => format!("{cube} is the Skybox (Skybox::Builder().environment(texture))."),
        (Target::Three, Writer::Cube) => format!("{cube} are the CubeTexture's faces in three's order px nx py ny pz nz; let PMREMGenerator.fromCubemap filter it (three does not read a prefiltered chain) and use the result as scene.environment."),
        (Target::Three, Writer::Irradiance) => format!("{} is the diffuse LightProbe: scene.add(new THREE.ObjectLoader().parse(json)).", out.engine_sh.clone().unwrap_or_default()),
        (Target::Three, Writer::Prefilter) => "three.js filters the environment itself (PMREMGenerator).".into(),
        (Target::Babylon, Writer::Prefilter) => format!("{} is the scene's environment: scene.environmentTexture = BABYLON.CubeTexture.CreateFromPrefilteredData(url, scene) (a left-handed scene, Babylon's default). Level l holds alpha = 2^(l/0.8)/size, what Babylon's lod = 0.8 log2(size alpha) reads.", out.env.clone().unwrap_or_default()),
        (Target::Babylon, Writer::Irradiance) => format!("{irr}: the E/pi cube for reference; Babylon takes its irradiance from the .env `prefilter --target babylon` writes."),
        (Target::Babylon, Writer::Cube) => format!("{cube}: the environment cube as Babylon's left-handed scene samples it; Babylon's lighting comes from the .env `prefilter --target babylon` writes."),
        (Target::Unity, Writer::Prefilter) => format!("{chain}: import as a Cubemap (Texture Shape: Cube, keep its mips, no 'Convolution' re-filtering) and assign it as a custom reflection probe / RenderSettings.customReflectionTexture; mip m holds the roughness Unity's mip = 6 r(1.7 - 0.7 r) lands on."),
        (Target::Unity, Writer::Irradiance) => format!("{} is the ambient probe (RenderSettings.ambientProbe, SphericalHarmonicsL2).", out.engine_sh.clone().unwrap_or_default()),
        (Target::Custom, Writer::Prefilter) => format!("{chain} is read by the function in {} written beside it: lod = clamp(s log2(1 + r^2/a0), 0, N-1), then two textureLod taps at levels l = min(floor(lod), N-2) and l+1, blended and corrected by their alpha channel (upload the RGBA16F texels as stored: the alpha holds the kernel at the intervals' midpoints; a linear filter, seamless cube; the chain ends at 8x8, so in GL ES / WebGL2 set GL_TEXTURE_MAX_LEVEL to N-1 or the texture is incomplete); s, a0 and N are also in the bake's report (custom_lookup) and the KTX2 key/value data (ibl.lookup.*); the project's docs folder has the definition (CUSTOM_LOOKUP).", files(&out.lookup)),
        (Target::Custom, Writer::Irradiance) => format!("{irr} is the Lambertian cube (E/pi), sampled by the normal and multiplied by the diffuse colour."),
        (Target::Custom, Writer::Cube) => format!("{cube} is the environment (background) cube."),
        (Target::Unity, Writer::Cube) => format!("{cube}: import as a Cubemap for a skybox (Skybox/Cubemap shader)."),
    }
}

/// The loading code: the web engines' snippets from [`snippet::load_snippet`] (what the
/// headless-render harness runs), Bevy's and Unity's written here against this run's files.
fn engine_snippet(target: Target, writer: Writer, out: &Outputs) -> String {
    match target {
        Target::Bevy => bevy_snippet(writer, out),
        Target::Unity => unity_snippet(writer, out),
        // The web engines' snippets load what the harness reads from each run: three's the
        // cube faces and LightProbe.json (irradiance's note), Filament's and Babylon's the chain
        // (prefilter's note); a note never names a file its run did not write.
        // and only when that run wrote the container the snippet names.
        Target::Three
            if writer == Writer::Irradiance
                && out.engine_sh.as_deref() == Some("LightProbe.json") =>
        {
            snippet::fenced(target)
        }
        Target::Filament
            if writer == Writer::Prefilter && out.chain.iter().any(|f| f == "env_ibl.ktx") =>
        {
            snippet::fenced(target)
        }
        Target::Babylon if writer == Writer::Prefilter && out.env.is_some() => {
            snippet::fenced(target)
        }
        _ => String::new(),
    }
}

/// Bevy (0.14+): `EnvironmentMapLight` and `Skybox` components on the camera, as Bevy's
/// examples insert them (bevyengine/bevy `examples/3d/pbr.rs`, `examples/3d/skybox.rs`).
/// Bevy's KTX2 zstd feature is `zstd_rust` (or `zstd_c`): bevy 0.19.1's and 0.20.1's
/// Cargo.toml have no `zstd` feature, so `features = ["ktx2", "zstd"]` does not resolve. The
/// global ambient light is added on top of the environment map whatever the map holds
/// (`crates/bevy_pbr/src/render/pbr_functions.wgsl`, `ambient::ambient_light`; the resource is
/// `GlobalAmbientLight` in `crates/bevy_light/src/ambient_light.rs`, brightness 80 by default).
fn bevy_snippet(writer: Writer, out: &Outputs) -> String {
    let spec = lit(&out.chain, &Writer::Prefilter.command(Target::Bevy));
    let diff = lit(&out.irradiance, &Writer::Irradiance.command(Target::Bevy));
    let sky = lit(&out.cube, &Writer::Cube.command(Target::Bevy));
    let env = format!(
        "    EnvironmentMapLight {{\n        diffuse_map: asset_server.load(\"{diff}\"),\n        specular_map: asset_server.load(\"{spec}\"),\n        intensity: 900.0, // cd/m^2 per unit of the files (see Units)\n        ..default()\n    }},\n"
    );
    let skybox = format!(
        "    Skybox {{\n        image: asset_server.load(\"{sky}\"),\n        brightness: 900.0,\n        ..default()\n    }},\n"
    );
    let body = match writer {
        Writer::Cube => skybox,
        _ => env,
    };
    format!("// Cargo.toml: bevy = {{ features = [\"ktx2\", \"zstd_rust\"] }}\n// Bevy also adds its GlobalAmbientLight (80 cd/m^2 by default) on top of the map:\n// app.insert_resource(GlobalAmbientLight {{ brightness: 0.0, ..default() }}) shows the map alone.\ncommands.spawn((\n    Camera3d::default(),\n{body}));")
}

/// Unity (C#): the chain and cube are imported as Cubemap assets; the SH file is read into a
/// `SphericalHarmonicsL2` (UnityEngine.Rendering) and set as the ambient probe.
fn unity_snippet(writer: Writer, out: &Outputs) -> String {
    match writer {
        Writer::Irradiance => {
            let f = out.engine_sh.clone().unwrap_or_default();
            format!(
                "// C#: {f} -> RenderSettings.ambientProbe\n[System.Serializable] class ShFile {{ public float[][] SphericalHarmonicsL2; }}\nvar j = Newtonsoft.Json.JsonConvert.DeserializeObject<ShFile>(File.ReadAllText(path));\nvar sh = new UnityEngine.Rendering.SphericalHarmonicsL2();\nfor (int c = 0; c < 3; c++) for (int i = 0; i < 9; i++) sh[c, i] = j.SphericalHarmonicsL2[c][i];\nRenderSettings.ambientMode = UnityEngine.Rendering.AmbientMode.Custom;\nRenderSettings.ambientProbe = sh;"
            )
        }
        Writer::Prefilter => {
            let f = lit(&out.chain, &Writer::Prefilter.command(Target::Unity));
            format!(
                "// C#: {f} imported as a Cubemap asset (mips kept)\nRenderSettings.defaultReflectionMode = UnityEngine.Rendering.DefaultReflectionMode.Custom;\nRenderSettings.customReflectionTexture = cubemap; // or probe.customBakedTexture = cubemap"
            )
        }
        Writer::Cube => {
            let f = lit(&out.cube, &Writer::Cube.command(Target::Unity));
            format!(
                "// C#: {f} imported as a Cubemap asset\nvar sky = new Material(Shader.Find(\"Skybox/Cubemap\"));\nsky.SetTexture(\"_Tex\", cubemap);\nRenderSettings.skybox = sky;"
            )
        }
    }
}

/// File names a note mentions: words ending in an extension our tools write (the test of
/// every target × layout × writer checks each exists in the output folder).
pub fn mentioned_files(note: &str) -> Vec<String> {
    const EXT: [&str; 11] = [
        ".ktx2", ".ktx", ".dds", ".exr", ".hdr", ".png", ".json", ".ron", ".txt", ".env", ".pfm",
    ];
    let mut out = Vec::new();
    for word in note.split(|c: char| !(c.is_ascii_alphanumeric() || "._-".contains(c))) {
        let w = word.trim_matches('.');
        let lower = w.to_ascii_lowercase();
        if EXT
            .iter()
            .any(|e| lower.ends_with(e) && lower.len() > e.len())
        {
            out.push(w.to_string());
        }
    }
    out.sort();
    out.dedup();
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ALL_TARGETS;

    #[test]
    fn mentions_are_found_and_notes_name_only_the_outputs_given() {
        assert_eq!(
            mentioned_files("load a.ktx2, then m0_px.exr … m6_nz.exr. See `sh.txt`."),
            ["a.ktx2", "m0_px.exr", "m6_nz.exr", "sh.txt"]
        );
        for t in ALL_TARGETS {
            for w in [Writer::Cube, Writer::Prefilter, Writer::Irradiance] {
                let out = Outputs {
                    cube: vec!["c.ktx2".into()],
                    levels: 1,
                    ..Default::default()
                };
                let note = load_note(t, w, &out);
                for f in mentioned_files(&note) {
                    assert_eq!(f, "c.ktx2", "{t:?} {w:?}: {note}");
                }
            }
        }
    }
}
