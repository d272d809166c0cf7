// three.js reads our LightProbe: `irradiance --target three` writes LightProbe.json (the form
// LightProbe.toJSON writes); three's own ObjectLoader parses it and three's own
// SphericalHarmonics3.getIrradianceAt must reproduce our irradiance cube (E/π, stored x-mirrored
// as three samples CubeTextures) at every texel.
// Usage: node three_probe.mjs DIR (DIR holds LightProbe.json and irradiance.ktx2).
import * as THREE from 'three';
import { readFileSync } from 'node:fs';
import { join } from 'node:path';
import { readCubeRgba32f, texelDirection, texelOf } from './ktx2.mjs';

const dir = process.argv[2];
const json = JSON.parse(readFileSync(join(dir, 'LightProbe.json'), 'utf8'));
const probe = new THREE.ObjectLoader().parse(json);
if (!probe.isLightProbe) throw new Error('ObjectLoader did not make a LightProbe');
const cube = readCubeRgba32f(join(dir, 'irradiance.ktx2'));
const n = cube.n;
let worst = 0;
let count = 0;
const target = new THREE.Vector3();
for (let f = 0; f < 6; f++) {
  for (let j = 0; j < n; j++) {
    for (let i = 0; i < n; i++) {
      // World direction w; three reads a CubeTexture at (flipEnvMap·x, y, z), flipEnvMap = −1.
      const w = texelDirection(f, i, j, n);
      const [ff, ii, jj] = texelOf([-w[0], w[1], w[2]], n);
      const k = (jj * n + ii) * 4;
      const e = probe.sh.getIrradianceAt(new THREE.Vector3(w[0], w[1], w[2]), target).multiplyScalar(probe.intensity / Math.PI);
      const ours = cube.faces[ff].subarray(k, k + 3);
      [e.x, e.y, e.z].forEach((v, c) => {
        const rel = Math.abs(v - ours[c]) / Math.max(Math.abs(ours[c]), 1e-6);
        worst = Math.max(worst, rel);
      });
      count++;
    }
  }
}
console.log(`three ${THREE.REVISION}: ObjectLoader → LightProbe, getIrradianceAt/π vs our irradiance cube at ${count} texels: worst relative difference ${worst.toExponential(2)}`);
if (!(worst < 1e-4)) {
  console.error('three.js LightProbe does not reproduce our irradiance');
  process.exit(1);
}
