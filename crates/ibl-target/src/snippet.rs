//! The loading code of each web engine's `LOAD.txt`: a fenced JS snippet that the render
//! harness (conformance/render) extracts from the note a run wrote and executes, so the note
//! cannot drift from what renders right.

use crate::Target;

/// three.js r187 (`equirect-to-cube --target three`, `irradiance --target three`).
///
/// mrdoob/three.js `examples/jsm/loaders/EXRLoader.js` returns a DataTexture whose rows are
/// bottom row first (it is made for 2D textures with flipY = false); a cube face is uploaded
/// top row first (`src/renderers/webgl/WebGLTextures.js`, `uploadCubeTexture`), so each face is
/// flipped before the CubeTexture is built. `src/extras/PMREMGenerator.js` `fromCubemap`
/// filters it; `src/loaders/ObjectLoader.js` reads LightProbe.json.
const THREE: &str = r#"import * as THREE from "three";
import { EXRLoader } from "three/addons/loaders/EXRLoader.js";

// The environment for scene.environment: our six EXR faces (stored x-mirrored, as three
// samples cube maps) as a CubeTexture, filtered by three's PMREMGenerator.
export async function loadEnvironment(renderer, dir) {
  const loader = new EXRLoader();
  const faces = await Promise.all(
    ["px", "nx", "py", "ny", "pz", "nz"].map((f) => loader.loadAsync(`${dir}/${f}.exr`)),
  );
  for (const face of faces) {
    // EXRLoader returns rows bottom row first; a cube face wants its top row first.
    const { width: w, height: h, data } = face.image;
    const row = (data.length / h) | 0;
    const flipped = new data.constructor(data.length);
    for (let y = 0; y < h; y++) flipped.set(data.subarray((h - 1 - y) * row, (h - y) * row), y * row);
    face.image.data = flipped;
  }
  const cube = new THREE.CubeTexture(faces);
  cube.type = faces[0].type;
  cube.format = faces[0].format;
  cube.colorSpace = THREE.LinearSRGBColorSpace;
  cube.minFilter = THREE.LinearFilter;
  cube.generateMipmaps = false;
  cube.needsUpdate = true;
  const pmrem = new THREE.PMREMGenerator(renderer);
  return pmrem.fromCubemap(cube).texture;
}

// The diffuse probe: LightProbe.json (three's toJSON form) as a LightProbe to scene.add().
// Use it instead of scene.environment's diffuse, not on top of it.
export async function loadLightProbe(url) {
  const json = await (await fetch(url)).json();
  return new THREE.ObjectLoader().parse(json);
}
"#;

/// Filament 1.53 (npm `filament`, `prefilter --target filament`).
///
/// google/filament `web/filament-js/utilities.js` (`_createIblFromKtx1`): createIblFromKtx1
/// builds the IndirectLight from the reflections alone and only parses the `sh` metadata into
/// `ibl.shfloats`, so without a second build the diffuse term is missing; the irradiance is
/// passed with `irradianceSh(3, …)` (`filament/include/filament/IndirectLight.h`). Its
/// intensity defaults to 30000 (a sunny sky in lux, to go with the default camera exposure):
/// with `camera.setExposureDirect(1)` an intensity of 1 renders the file's radiance as stored.
const FILAMENT: &str = r#"// Filament.init([...urls, "env_ibl.ktx"], onReady) fetches the file first.
export function loadIndirectLight(Filament, engine, url) {
  // createIblFromKtx1 reads the chain; Filament 1.53 keeps the file's `sh` metadata (the 9
  // irradiance coefficients) in .shfloats only, so build the light again with them.
  const fromKtx = engine.createIblFromKtx1(url);
  return Filament.IndirectLight.Builder()
    .reflections(fromKtx.getReflectionsTexture())
    .irradianceSh(3, fromKtx.shfloats)
    .intensity(1.0) // radiance as stored; scale to your camera's exposure
    .build(engine);
}
"#;

/// Babylon.js 9 (`@babylonjs/core`, `prefilter --target babylon`): BabylonJS/Babylon.js
/// `packages/dev/core/src/Materials/Textures/cubeTexture.ts` (`CreateFromPrefilteredData`
/// reads a `.env` through `Misc/environmentTextureTools.ts`), in Babylon's default
/// left-handed scene, the frame the file is written in.
const BABYLON: &str = r#"import { CubeTexture } from "@babylonjs/core";

// In Babylon's default (left-handed) scene; the .env carries the chain and the irradiance.
export function loadEnvironment(scene, url) {
  return (scene.environmentTexture = CubeTexture.CreateFromPrefilteredData(url, scene));
}
"#;

/// The JS snippet of `target`'s note, if the engine is a web engine the harness renders.
pub fn load_snippet(target: Target) -> Option<&'static str> {
    match target {
        Target::Three => Some(THREE),
        Target::Filament => Some(FILAMENT),
        Target::Babylon => Some(BABYLON),
        _ => None,
    }
}

/// `target`'s snippet fenced as the note carries it (empty when it has none).
pub fn fenced(target: Target) -> String {
    load_snippet(target)
        .map(|s| format!("\n```js\n{s}```\n"))
        .unwrap_or_default()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn snippets_are_fenced_once_and_export_their_loaders() {
        for t in crate::ALL_TARGETS {
            let f = fenced(t);
            if let Some(s) = load_snippet(t) {
                assert!(!s.contains("```"), "{t:?}");
                assert_eq!(f.matches("```").count(), 2);
                assert!(s.contains("export "), "{t:?}");
            } else {
                assert!(f.is_empty());
            }
        }
    }
}
