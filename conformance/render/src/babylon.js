//! Babylon.js 9 page (@babylonjs/core): the sphere-rows scene in Babylon's default left-handed
//! scene (the contract's world (x, y, z) is Babylon's (x, y, −z): camera at z = −10 looking
//! at +z), PBRMaterial spheres, lit by (route "hdr") Babylon's own HDRCubeTexture of the
//! panorama, (route "ownenv") the .env Babylon's own writer makes of it
//! (EnvironmentTextureTools.CreateEnvTextureAsync), or (route "ours") our `--target babylon`
//! environment.env loaded by the LOAD.txt snippet. Read back as floats from a float RTT.
import {
  Engine, Scene, Color4, Vector3, FreeCamera, Camera, MeshBuilder, PBRMaterial, Color3,
  HDRCubeTexture, CubeTexture, RenderTargetTexture, Constants, EnvironmentTextureTools,
} from "@babylonjs/core";
import { params, SCENE, loadSnippet, finish, run, b64 } from "./common.js";

/** Resolves when `tex` (a texture loading asynchronously) is ready. */
async function waitReady(tex) {
  for (let k = 0; k < 1200 && !tex.isReady(); k++) await new Promise((ok) => setTimeout(ok, 100));
  if (!tex.isReady()) throw new Error("environment texture never became ready");
}

run(async () => {
  const canvas = document.createElement("canvas");
  canvas.width = SCENE.width;
  canvas.height = SCENE.height;
  document.body.appendChild(canvas);
  const engine = new Engine(canvas, false, { preserveDrawingBuffer: true, antialias: false });
  const scene = new Scene(engine);
  scene.clearColor = new Color4(0, 0, 0, 0);
  // Linear output: image processing "applied by a post-process" that is never attached, so the
  // PBR shader writes linear radiance (pbr.fragment.fx: IMAGEPROCESSINGPOSTPROCESS clamps to
  // [0, 30] and skips applyImageProcessing's gamma encoding and saturate).
  scene.imageProcessingConfiguration.isEnabled = true;
  scene.imageProcessingConfiguration.applyByPostProcess = true;
  scene.imageProcessingConfiguration.toneMappingEnabled = false;
  scene.imageProcessingConfiguration.exposure = 1;
  // rightHanded: Babylon's right-handed mode, the contract's frame as is (camera at +z);
  // otherwise Babylon's default left-handed scene with the contract's z negated.
  scene.useRightHandedSystem = !!params.rightHanded;
  // Babylon's PBR takes the view vector from the eye position even for an orthographic camera
  // (normalize(vEyePosition - vPositionW)), so the eye is put 1e4 away: the contract's
  // v = (0, 0, 1) to within 0.03° at the outer spheres.
  const D = 1e4;
  const camera = new FreeCamera("cam", new Vector3(0, 0, params.rightHanded ? D : -D), scene);
  camera.setTarget(new Vector3(0, 0, 0));
  camera.mode = Camera.ORTHOGRAPHIC_CAMERA;
  Object.assign(camera, { orthoLeft: -6, orthoRight: 6, orthoTop: 2, orthoBottom: -2, minZ: D - 10, maxZ: D + 10 });
  const meshes = [];
  for (const row of SCENE.rows) {
    SCENE.cols.forEach((cx, i) => {
      const s = MeshBuilder.CreateSphere(`s${meshes.length}`, { diameter: 2 * SCENE.radius, segments: 96 }, scene);
      s.position = new Vector3(cx, row.y, 0);
      const m = new PBRMaterial(`m${meshes.length}`, scene);
      m.albedoColor = new Color3(1, 1, 1);
      m.metallic = row.metallic;
      m.roughness = SCENE.roughness[i];
      s.material = m;
      meshes.push(s);
    });
  }
  if (params.route === "hdr" || params.route === "ownenv") {
    // Babylon's documented route for an .hdr panorama: HDRCubeTexture, prefiltered on load.
    const hdr = new HDRCubeTexture(params.hdr, scene, params.size || 256, false, true, false, true);
    await new Promise((ok, err) => { hdr.onLoadObservable.addOnce(ok); setTimeout(() => err(new Error("HDRCubeTexture timed out")), 110000); });
    await new Promise((ok) => scene.executeWhenReady(ok));
    if (params.route === "hdr") scene.environmentTexture = hdr;
    else {
      const buf = await EnvironmentTextureTools.CreateEnvTextureAsync(hdr, { imageType: "image/png" });
      window.__extra = { ext: "env", b64: b64(new Uint8Array(buf)) };
      const url = URL.createObjectURL(new Blob([buf]));
      scene.environmentTexture = CubeTexture.CreateFromPrefilteredData(url, scene, ".env");
    }
  } else {
    const snippet = await loadSnippet(params.note, ["CubeTexture"], ["loadEnvironment"]);
    const { loadEnvironment } = snippet(CubeTexture);
    loadEnvironment(scene, params.env);
  }
  // The page's world turn (the same for every route): rotationY of the environment, degrees.
  scene.environmentTexture.rotationY = ((params.rotationY || 0) * Math.PI) / 180;
  await waitReady(scene.environmentTexture);
  const rtt = new RenderTargetTexture("rt", { width: SCENE.width, height: SCENE.height }, scene, false, true, Constants.TEXTURETYPE_FLOAT);
  rtt.renderList = meshes;
  rtt.activeCamera = camera;
  rtt.clearColor = new Color4(0, 0, 0, 0);
  scene.customRenderTargets.push(rtt);
  await new Promise((ok) => scene.executeWhenReady(ok));
  for (let f = 0; f < 3; f++) {
    scene.render();
    await new Promise((ok) => requestAnimationFrame(ok));
  }
  const px = await rtt.readPixels();
  finish(SCENE.width, SCENE.height, new Float32Array(px.buffer, px.byteOffset, px.length));
});
