// Babylon.js reads our .env: `prefilter --target babylon` writes environment.env; Babylon's own
// GetEnvInfo parses the magic and manifest, CreateRadianceImageDataArrayBufferViews slices the
// RGBD PNG of every face and level, UploadEnvSpherical builds its SphericalPolynomial, and the
// irradiance is evaluated as Babylon's PBR shader does (packages/dev/core/src/Shaders/
// ShadersInclude/harmonicsFunctions.fx, SPHERICAL_HARMONICS: the polynomial's
// `preScaledHarmonics`, i.e. SphericalHarmonics.FromPolynomial then preScaleForRendering);
// it must reproduce our irradiance cube (E/π) in the file's frame. (This check used to evaluate
// the polynomial itself, a model of Babylon that its shader does not follow: it passed files
// that Babylon rendered with band 1 ×1.5 and band 2 ×4.)
// Usage: node babylon_env.mjs ENV_FILE IRRADIANCE_KTX2
import { readFileSync } from 'node:fs';
import { GetEnvInfo, CreateRadianceImageDataArrayBufferViews, UploadEnvSpherical } from '@babylonjs/core/Misc/environmentTextureTools.pure.js';
import { SphericalPolynomial } from '@babylonjs/core/Maths/sphericalPolynomial.pure.js';
import { readCubeRgba32f, texelDirection } from './ktx2.mjs';

const [envPath, irrPath] = process.argv.slice(2);
const data = new Uint8Array(readFileSync(envPath));
const info = GetEnvInfo(data);
if (!info) throw new Error(`${envPath}: Babylon's GetEnvInfo refused it`);
const fail = (m) => {
  console.error(m);
  process.exit(1);
};
if (info.version !== 2 || info.specular.lodGenerationScale !== 0.8) fail(`manifest: ${JSON.stringify({ v: info.version, s: info.specular.lodGenerationScale })}`);
const views = CreateRadianceImageDataArrayBufferViews(data, info);
const levels = Math.log2(info.width) + 1;
if (views.length !== levels) fail(`levels ${views.length}, want ${levels}`);
views.forEach((faces, l) =>
  faces.forEach((v, f) => {
    const png = [0x89, 0x50, 0x4e, 0x47];
    if (!png.every((b, k) => v[k] === b)) fail(`level ${l} face ${f}: not a PNG`);
    const dv = new DataView(v.buffer, v.byteOffset, v.byteLength);
    const w = dv.getUint32(16), h = dv.getUint32(20), type = v[25];
    if (w !== info.width >> l || h !== w || type !== 6) fail(`level ${l} face ${f}: ${w}×${h} colour type ${type}`);
  }),
);
const tex = {};
UploadEnvSpherical(tex, info);
// A fresh polynomial so that preScaledHarmonics derives the harmonics from the file's numbers.
const sh = SphericalPolynomial.FromArray(['x', 'y', 'z', 'xx', 'yy', 'zz', 'yz', 'zx', 'xy'].map((k) => tex._sphericalPolynomial[k].asArray())).preScaledHarmonics;
const cube = readCubeRgba32f(irrPath);
const n = cube.n;
let worst = 0;
for (let f = 0; f < 6; f++) {
  for (let j = 0; j < n; j++) {
    for (let i = 0; i < n; i++) {
      // The file's direction t is Babylon's world direction; the cube holds E/π there.
      const [x, y, z] = texelDirection(f, i, j, n);
      const e = ['x', 'y', 'z'].map(
        (c) =>
          sh.l00[c] + sh.l1_1[c] * y + sh.l10[c] * z + sh.l11[c] * x + sh.l2_2[c] * y * x + sh.l2_1[c] * y * z +
          sh.l20[c] * (3 * z * z - 1) + sh.l21[c] * z * x + sh.l22[c] * (x * x - y * y),
      );
      const k = (j * n + i) * 4;
      e.forEach((v, c) => {
        worst = Math.max(worst, Math.abs(v - cube.faces[f][k + c]) / Math.max(cube.faces[f][k + c], 1e-6));
      });
    }
  }
}
console.log(`babylon: GetEnvInfo v${info.version} ${info.width}² × ${levels} levels of RGBD PNG; its shader's harmonics vs our irradiance cube at ${6 * n * n} texels: worst relative difference ${worst.toExponential(2)}`);
// The .env's polynomial is projected from the chain's mirror level, the cube from the input:
// two discretisations of one environment.
if (!(worst < 1e-2)) fail('Babylon SphericalPolynomial does not reproduce our irradiance');
