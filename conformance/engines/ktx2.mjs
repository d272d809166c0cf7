// Reads the first level of an uncompressed RGBA32F KTX2 cube (what `irradiance --layout ktx2`
// writes) into six faces of Float32Array RGBA texels: only what these checks need.
import { readFileSync } from 'node:fs';

export function readCubeRgba32f(path) {
  const b = readFileSync(path);
  const v = new DataView(b.buffer, b.byteOffset, b.byteLength);
  const vkFormat = v.getUint32(12, true);
  const n = v.getUint32(20, true);
  const faces = v.getUint32(36, true);
  if (vkFormat !== 109 || faces !== 6) throw new Error(`${path}: not an RGBA32F cube (vkFormat ${vkFormat}, faces ${faces})`);
  const offset = Number(v.getBigUint64(80, true));
  const face = n * n * 4;
  const all = new Float32Array(b.buffer.slice(b.byteOffset + offset, b.byteOffset + offset + 6 * face * 4));
  return { n, faces: [0, 1, 2, 3, 4, 5].map((f) => all.subarray(f * face, (f + 1) * face)) };
}

// Direction of texel (i, j) of face f of an n-texel face (docs/CONVENTIONS.md table, faces px nx py ny pz nz).
export function texelDirection(f, i, j, n) {
  const sc = (2 * (i + 0.5)) / n - 1;
  const tc = (2 * (j + 0.5)) / n - 1;
  const d = [
    [1, -tc, -sc],
    [-1, -tc, sc],
    [sc, 1, tc],
    [sc, -1, -tc],
    [sc, -tc, 1],
    [-sc, -tc, -1],
  ][f];
  const l = Math.hypot(d[0], d[1], d[2]);
  return [d[0] / l, d[1] / l, d[2] / l];
}

// Face and texel of a direction (the inverse on the major axis), nearest texel.
export function texelOf(d, n) {
  const [x, y, z] = d;
  const [ax, ay, az] = [Math.abs(x), Math.abs(y), Math.abs(z)];
  let f, sc, tc;
  if (ax >= ay && ax >= az) {
    [f, sc, tc] = x > 0 ? [0, -z / ax, -y / ax] : [1, z / ax, -y / ax];
  } else if (ay >= az) {
    [f, sc, tc] = y > 0 ? [2, x / ay, z / ay] : [3, x / ay, -z / ay];
  } else {
    [f, sc, tc] = z > 0 ? [4, x / az, -y / az] : [5, -x / az, -y / az];
  }
  const clamp = (k) => Math.min(n - 1, Math.max(0, k));
  return [f, clamp(Math.floor(((sc + 1) / 2) * n)), clamp(Math.floor(((tc + 1) / 2) * n))];
}
