//! glTF Sample Renderer page (npm `@khronosgroup/gltf-viewer` 1.1.0, KhronosGroup/glTF-Sample-Renderer):
//! the sphere-rows scene (spheres.glb with an orthographic camera) rendered through its public
//! API (GltfView, GltfState, ResourceLoader) from, in one page: route "own", the `.hdr` the
//! viewer filters itself (`ResourceLoader.loadEnvironment`, its documented and only environment
//! entry point); route "ours", the same environment object with our `--target gltf` KTX2 cubes
//! swapped in for its GGX and Lambertian cubes. The viewer's API takes only an .hdr
//! (source/ResourceLoader/resource_loader.js `loadEnvironment` → `loadHDR` →
//! `_loadEnvironmentFromPanorama`, which always runs its own `iblSampler`); its KTX2 environment
//! route is commented out in that function. So ours are loaded by the viewer's own KTX2 decoder
//! (`ResourceLoader.initKtxLib`, its bundled libktx) and put where that commented-out route puts
//! them (environment.diffuseEnvMap / specularEnvMap, mipCount = the chain's level count); the
//! BRDF LUT stays the viewer's own. Both routes share the LUT, the shaders and the camera.
//!
//! Read back: the viewer draws to the default framebuffer with `toneMap` (exposure, then
//! `pow(c, 1/2.2)`, no clamp in the shader: source/Renderer/shaders/tonemapping.glsl, ToneMaps.NONE);
//! the page binds an RGBA32F framebuffer wherever the viewer binds the default one while it
//! draws, and undoes the 2.2 power on read-back (exact up to float rounding).
import { GltfView } from "@khronosgroup/gltf-viewer";
import { params, SCENE, finishAll, run } from "./common.js";

/** The level count of a KTX2 file (header field levelCount at byte 40, KTX 2.0 §3). */
function ktx2Levels(buf) {
  return new DataView(buf).getUint32(40, true);
}

run(async () => {
  const canvas = document.createElement("canvas");
  canvas.width = SCENE.width;
  canvas.height = SCENE.height;
  document.body.appendChild(canvas);
  const gl = canvas.getContext("webgl2", { antialias: false, alpha: true, depth: true, preserveDrawingBuffer: true });
  if (!gl.getExtension("EXT_color_buffer_float") || !gl.getExtension("OES_texture_float_linear")) {
    throw new Error("WebGL2 without float render targets or float linear filtering");
  }
  // The float target that stands in for the default framebuffer while the viewer draws.
  const color = gl.createTexture();
  gl.bindTexture(gl.TEXTURE_2D, color);
  gl.texStorage2D(gl.TEXTURE_2D, 1, gl.RGBA32F, SCENE.width, SCENE.height);
  const depth = gl.createRenderbuffer();
  gl.bindRenderbuffer(gl.RENDERBUFFER, depth);
  gl.renderbufferStorage(gl.RENDERBUFFER, gl.DEPTH_COMPONENT24, SCENE.width, SCENE.height);
  const fbo = gl.createFramebuffer();
  gl.bindFramebuffer(gl.FRAMEBUFFER, fbo);
  gl.framebufferTexture2D(gl.FRAMEBUFFER, gl.COLOR_ATTACHMENT0, gl.TEXTURE_2D, color, 0);
  gl.framebufferRenderbuffer(gl.FRAMEBUFFER, gl.DEPTH_ATTACHMENT, gl.RENDERBUFFER, depth);
  if (gl.checkFramebufferStatus(gl.FRAMEBUFFER) !== gl.FRAMEBUFFER_COMPLETE) throw new Error("float framebuffer incomplete");
  gl.bindFramebuffer(gl.FRAMEBUFFER, null);
  let redirect = false;
  const bindFb = gl.bindFramebuffer.bind(gl);
  gl.bindFramebuffer = (t, fb) => bindFb(t, fb === null && redirect ? fbo : fb);

  const view = new GltfView(gl);
  const state = view.createState();
  // The viewer's bundled libktx (libs/libktx.js, a script tag) and mikktspace wasm (libPath).
  const loader = view.createResourceLoader(undefined, undefined, params.libPath);
  state.gltf = await loader.loadGltf(params.glb);
  state.sceneIndex = 0;
  state.cameraIndex = 0; // the glb's orthographic camera (spheres-glb.mjs --camera)
  const rp = state.renderingParameters;
  rp.toneMap = "None (Linear mapping, clamped at 1.0)"; // GltfState.ToneMaps.NONE
  rp.exposure = 1.0;
  rp.usePunctual = false;
  rp.renderEnvironmentMap = false;
  rp.clearColor = [0, 0, 0, 0];
  // environmentRotation: degrees about +Y (the viewer's default is 90, "front face +Z"); the
  // page's value (run.sh: 0, where its own route shows the world as our convention maps the
  // panorama: u_EnvRotation = rotateY(environmentRotation) turns every lookup direction,
  // source/Renderer/environment_renderer.js and renderer.js) applies to both routes alike.
  rp.environmentRotation = params.environmentRotation ?? 90;
  // Its own route: the .hdr filtered by its iblSampler (also makes the BRDF LUT both use).
  // lutFiles: the viewer reads its sheen albedo LUT from its app's assets/ (not in the npm
  // package; a load error there never settles its promise): the page hands it a placeholder,
  // which no material of this scene reads (none has KHR_materials_sheen).
  const t0 = performance.now();
  state.environment = await loader.loadEnvironment(params.hdr, { lut_sheen_E_file: params.sheenLut });
  console.log(`loadEnvironment (the viewer's own filtering): ${((performance.now() - t0) / 1000).toFixed(1)} s`);
  if (!state.environment) throw new Error(`${params.hdr}: the viewer did not load it`);

  const render = () => {
    redirect = true;
    for (let f = 0; f < 2; f++) view.renderFrame(state, SCENE.width, SCENE.height);
    bindFb(gl.FRAMEBUFFER, fbo);
    const out = new Float32Array(SCENE.width * SCENE.height * 4);
    gl.readPixels(0, 0, SCENE.width, SCENE.height, gl.RGBA, gl.FLOAT, out);
    bindFb(gl.FRAMEBUFFER, null);
    redirect = false;
    for (let i = 0; i < out.length; i++) if (i % 4 !== 3) out[i] = Math.pow(Math.max(out[i], 0), 2.2) / rp.exposure;
    return out;
  };
  const results = [];
  for (const route of params.routes || ["own", "ours"]) {
    if (route === "ours") {
      // Our cubes where the viewer keeps its own (environment.textures of the Lambertian and
      // GGX images), sampled as its samplers say (trilinear for the chain).
      const env = state.environment;
      const put = async (url, info, mipmapped) => {
        const r = await fetch(url);
        if (!r.ok) throw new Error(`${url}: ${r.status}`);
        const buf = await r.arrayBuffer();
        const tex = await view.ktxDecoder.loadKtxFromBuffer(new Uint8Array(buf));
        if (!tex) throw new Error(`${url}: the viewer's KTX2 decoder refused it`);
        gl.bindTexture(gl.TEXTURE_CUBE_MAP, tex);
        gl.texParameteri(gl.TEXTURE_CUBE_MAP, gl.TEXTURE_MIN_FILTER, mipmapped ? gl.LINEAR_MIPMAP_LINEAR : gl.LINEAR);
        gl.texParameteri(gl.TEXTURE_CUBE_MAP, gl.TEXTURE_MAG_FILTER, gl.LINEAR);
        for (const w of [gl.TEXTURE_WRAP_S, gl.TEXTURE_WRAP_T]) gl.texParameteri(gl.TEXTURE_CUBE_MAP, w, gl.CLAMP_TO_EDGE);
        const t = env.textures[info.index];
        env.images[t.source].image = tex;
        t.glTexture = tex;
        return ktx2Levels(buf);
      };
      env.mipCount = await put(params.specular, env.specularEnvMap, true);
      await put(params.diffuse, env.diffuseEnvMap, false);
      env.iblIntensityScale = 1.0; // the viewer's own scale compensates its 8-bit input path only
    }
    results.push(render());
  }
  finishAll(SCENE.width, SCENE.height, results);
});
