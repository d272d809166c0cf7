//! Filament 1.53 page (npm `filament`, its wasm build): the sphere-rows scene (spheres from a
//! glTF through gltfio, Filament's own ubershader materials) lit by our `--target filament`
//! env_ibl.ktx loaded by the LOAD.txt snippet, or (`route: "own"`) by cmgen's KTX; read back as floats from an RGBA32F render target.
import { params, SCENE, loadSnippet, finish, run } from "./common.js";

/* global Filament */
run(async () => {
  const canvas = document.createElement("canvas");
  canvas.width = SCENE.width;
  canvas.height = SCENE.height;
  // Filament's Engine.create takes this same WebGL2 context (getContext returns it again); we
  // note which texture its render target allocates so that we can read it back as floats.
  const gl = canvas.getContext("webgl2", { antialias: false, depth: true, alpha: false });
  gl.getExtension("EXT_color_buffer_float");
  let bound = null, target = null;
  const bind = gl.bindTexture.bind(gl), storage = gl.texStorage2D.bind(gl);
  gl.bindTexture = (t, tex) => { if (t === gl.TEXTURE_2D) bound = tex; bind(t, tex); };
  gl.texStorage2D = (t, levels, fmt, w, h) => {
    if (t === gl.TEXTURE_2D && fmt === gl.RGBA32F && w === SCENE.width && h === SCENE.height) target = bound;
    storage(t, levels, fmt, w, h);
  };
  await new Promise((ok) => Filament.init([params.glb, params.ktx], ok));
  const engine = Filament.Engine.create(canvas);
  const scene = engine.createScene();
  const swapChain = engine.createSwapChain();
  const renderer = engine.createRenderer();
  const camera = engine.createCamera(Filament.EntityManager.get().create());
  const view = engine.createView();
  view.setCamera(camera);
  view.setScene(scene);
  view.setViewport([0, 0, SCENE.width, SCENE.height]);
  // Linear output: no post-processing (no tone mapping, dithering, AA), exposure 1.
  view.setPostProcessingEnabled(false);
  camera.setProjection(Filament.Camera$Projection.ORTHO, -6, 6, -2, 2, 0.1, 100);
  camera.lookAt([0, 0, 10], [0, 0, 0], [0, 1, 0]);
  camera.setExposureDirect(1.0);
  renderer.setClearOptions({ clearColor: [0, 0, 0, 0], clear: true });
  const color = Filament.Texture.Builder().width(SCENE.width).height(SCENE.height).levels(1)
    .usage(1 | 16).format(Filament.Texture$InternalFormat.RGBA32F).sampler(Filament.Texture$Sampler.SAMPLER_2D).build(engine);
  const depth = Filament.Texture.Builder().width(SCENE.width).height(SCENE.height).levels(1)
    .usage(2).format(Filament.Texture$InternalFormat.DEPTH32F).sampler(Filament.Texture$Sampler.SAMPLER_2D).build(engine);
  view.setRenderTarget(Filament.RenderTarget.Builder()
    .texture(Filament.RenderTarget$AttachmentPoint.COLOR, color)
    .texture(Filament.RenderTarget$AttachmentPoint.DEPTH, depth).build(engine));

  const loader = engine.createAssetLoader();
  const asset = loader.createAsset(Filament.assets[params.glb]);
  await new Promise((ok) => asset.loadResources(ok, null, null, null));
  scene.addEntities(asset.getRenderableEntities());

  let ibl;
  if (params.route === "own") {
    // Filament's own route: cmgen's deployment KTX through Filament's loader, as its samples
    // load one. 1.53 keeps the file's `sh` metadata in .shfloats only (Ktx1Bundle), so the
    // light is built again with them, as any page must.
    const fromKtx = engine.createIblFromKtx1(params.ktx);
    ibl = Filament.IndirectLight.Builder()
      .reflections(fromKtx.getReflectionsTexture())
      .irradianceSh(3, fromKtx.shfloats)
      .intensity(1.0)
      .build(engine);
  } else {
    const snippet = await loadSnippet(params.note, [], ["loadIndirectLight"]);
    const { loadIndirectLight } = snippet();
    ibl = loadIndirectLight(Filament, engine, params.ktx);
  }
  // The file is oriented as cmgen orients the panorama; `rotation` (row-major 3×3, optional)
  // turns the page's world to the contract's.
  if (params.rotation) ibl.setRotation(params.rotation);
  scene.setIndirectLight(ibl);

  for (let f = 0; f < 3; f++) {
    renderer.render(swapChain, view);
    await new Promise((ok) => requestAnimationFrame(ok));
  }
  if (!target) throw new Error("Filament's RGBA32F render target was not seen");
  const fbo = gl.createFramebuffer();
  gl.bindFramebuffer(gl.FRAMEBUFFER, fbo);
  gl.framebufferTexture2D(gl.FRAMEBUFFER, gl.COLOR_ATTACHMENT0, gl.TEXTURE_2D, target, 0);
  const out = new Float32Array(SCENE.width * SCENE.height * 4);
  gl.readPixels(0, 0, SCENE.width, SCENE.height, gl.RGBA, gl.FLOAT, out);
  finish(SCENE.width, SCENE.height, out);
});
