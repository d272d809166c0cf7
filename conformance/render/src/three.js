//! three.js r187 page: the sphere-rows scene lit by (route "own") three's own PMREM of the
//! source panorama, (route "ours") our `--target three` cube loaded by the LOAD.txt snippet and
//! filtered by PMREMGenerator, or (route "probe") our LightProbe.json alone (diffuse only).
import * as THREE from "three";
import { EXRLoader } from "three/addons/loaders/EXRLoader.js";
import { params, SCENE, loadSnippet, finish, run } from "./common.js";

run(async () => {
  const canvas = document.createElement("canvas");
  canvas.width = SCENE.width;
  canvas.height = SCENE.height;
  const renderer = new THREE.WebGLRenderer({ canvas, antialias: false });
  renderer.toneMapping = THREE.NoToneMapping;
  renderer.outputColorSpace = THREE.LinearSRGBColorSpace;
  renderer.setClearColor(0x000000, 0);
  const scene = new THREE.Scene();
  // Contract camera: orthographic, at +Z looking at −Z, x ∈ [−6, 6], y ∈ [−2, 2].
  const camera = new THREE.OrthographicCamera(-6, 6, 2, -2, 0.1, 100);
  camera.position.set(0, 0, 10);
  camera.lookAt(0, 0, 0);
  for (const row of SCENE.rows) {
    SCENE.cols.forEach((cx, i) => {
      // diffuseOnly: the dielectric row without its specular lobe (specularIntensity 0 zeroes F0,
      // F90 and the multiscatter term of three's physical shading), to set a diffuse-only
      // render from the environment beside one from the LightProbe.
      const opts = { color: 0xffffff, metalness: row.metallic, roughness: SCENE.roughness[i] };
      const m = params.diffuseOnly && row.metallic === 0
        ? new THREE.MeshPhysicalMaterial({ ...opts, specularIntensity: 0 })
        : new THREE.MeshStandardMaterial(opts);
      const s = new THREE.Mesh(new THREE.SphereGeometry(SCENE.radius, 192, 96), m);
      s.position.set(cx, row.y, 0);
      scene.add(s);
    });
  }
  const pmrem = new THREE.PMREMGenerator(renderer);
  if (params.route === "own") {
    // three's documented route for an equirect: EXRLoader + EquirectangularReflectionMapping,
    // filtered by PMREMGenerator (examples/webgl_loader_texture_exr.html).
    const tex = await new EXRLoader().loadAsync(params.equirect);
    tex.mapping = THREE.EquirectangularReflectionMapping;
    scene.environment = pmrem.fromEquirectangular(tex).texture;
  } else {
    const snippet = await loadSnippet(params.note, ["THREE", "EXRLoader"], ["loadEnvironment", "loadLightProbe"]);
    const { loadEnvironment, loadLightProbe } = snippet(THREE, EXRLoader);
    if (params.route === "ours") scene.environment = await loadEnvironment(renderer, params.dir);
    else scene.add(await loadLightProbe(params.probe));
  }
  const rt = new THREE.WebGLRenderTarget(SCENE.width, SCENE.height, { type: THREE.FloatType });
  renderer.setRenderTarget(rt);
  renderer.render(scene, camera);
  const out = new Float32Array(SCENE.width * SCENE.height * 4);
  renderer.readRenderTargetPixels(rt, 0, 0, SCENE.width, SCENE.height, out);
  finish(SCENE.width, SCENE.height, out);
});
