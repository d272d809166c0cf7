//! Reads a Babylon `.env` (BabylonJS/Babylon.js `packages/dev/core/src/Misc/
//! environmentTextureTools.ts`: magic, NUL-terminated JSON manifest, RGBD PNG per level and
//! face) into linear float faces, and finds for each face of file B which face of file A, under
//! which of the 8 square symmetries, it matches: how two writers' orientations relate.
//! usage: node envfaces.mjs A.env B.env
import fs from "node:fs";
import zlib from "node:zlib";

/** Decodes an 8-bit RGBA, non-interlaced PNG into {w, h, px: Uint8Array}. */
export function decodePng(buf) {
  let o = 8, w = 0, h = 0, idat = [];
  while (o < buf.length) {
    const len = buf.readUInt32BE(o), type = buf.toString("ascii", o + 4, o + 8);
    const d = buf.subarray(o + 8, o + 8 + len);
    if (type === "IHDR") {
      w = d.readUInt32BE(0);
      h = d.readUInt32BE(4);
      if (d[8] !== 8 || d[9] !== 6 || d[12] !== 0) throw new Error(`PNG: want 8-bit RGBA non-interlaced, got depth ${d[8]} type ${d[9]}`);
    } else if (type === "IDAT") idat.push(d);
    o += 12 + len;
  }
  const raw = zlib.inflateSync(Buffer.concat(idat)), bpp = 4, stride = w * bpp;
  const px = new Uint8Array(w * h * bpp);
  for (let y = 0; y < h; y++) {
    const f = raw[y * (stride + 1)], src = raw.subarray(y * (stride + 1) + 1, (y + 1) * (stride + 1));
    for (let x = 0; x < stride; x++) {
      const a = x >= bpp ? px[y * stride + x - bpp] : 0, b = y > 0 ? px[(y - 1) * stride + x] : 0;
      const c = x >= bpp && y > 0 ? px[(y - 1) * stride + x - bpp] : 0;
      let v = src[x];
      if (f === 1) v += a;
      else if (f === 2) v += b;
      else if (f === 3) v += (a + b) >> 1;
      else if (f === 4) { const p = a + b - c, pa = Math.abs(p - a), pb = Math.abs(p - b), pc = Math.abs(p - c); v += pa <= pb && pa <= pc ? a : pb <= pc ? b : c; }
      px[y * stride + x] = v & 0xff;
    }
  }
  return { w, h, px };
}

/** The .env's manifest and its level `level` faces as linear RGB floats (rows as stored). */
export function readEnv(path, level = 0) {
  const b = fs.readFileSync(path);
  let end = 8;
  while (b[end] !== 0) end++;
  const info = JSON.parse(b.toString("utf8", 8, end));
  const base = end + 1;
  const faces = [];
  for (let f = 0; f < 6; f++) {
    const m = info.specular.mipmaps[level * 6 + f];
    const { w, h, px } = decodePng(b.subarray(base + m.position, base + m.position + m.length));
    const rgb = new Float32Array(w * h * 3);
    for (let i = 0; i < w * h; i++) {
      const d = px[4 * i + 3] / 255;
      for (let c = 0; c < 3; c++) rgb[3 * i + c] = Math.pow(px[4 * i + c] / 255, 2.2) / Math.max(d, 1e-6);
    }
    faces.push({ w, h, rgb });
  }
  return { info, faces };
}

/** Log luminance of `face` averaged down to n×n. */
function small(face, n) {
  const out = new Float64Array(n * n), k = face.w / n;
  for (let y = 0; y < face.h; y++) for (let x = 0; x < face.w; x++) {
    const i = 3 * (y * face.w + x);
    out[Math.floor(y / k) * n + Math.floor(x / k)] += 0.2126 * face.rgb[i] + 0.7152 * face.rgb[i + 1] + 0.0722 * face.rgb[i + 2];
  }
  return out.map((v) => Math.log(1e-3 + v / (k * k)));
}

const SYM = ["id", "flipX", "flipY", "rot180", "transpose", "rot90cw", "rot90ccw", "antitranspose"];
function sym(a, n, s) {
  const out = new Float64Array(n * n);
  for (let y = 0; y < n; y++) for (let x = 0; x < n; x++) {
    const [sx, sy] = [[x, y], [n - 1 - x, y], [x, n - 1 - y], [n - 1 - x, n - 1 - y], [y, x], [y, n - 1 - x], [n - 1 - y, x], [n - 1 - y, n - 1 - x]][s];
    out[y * n + x] = a[sy * n + sx];
  }
  return out;
}

if (import.meta.url === `file://${process.argv[1]}`) {
  const [pa, pb] = process.argv.slice(2);
  const A = readEnv(pa), B = readEnv(pb), n = 16;
  const names = ["+X", "-X", "+Y", "-Y", "+Z", "-Z"];
  const sa = A.faces.map((f) => small(f, n)), sb = B.faces.map((f) => small(f, n));
  for (let fb = 0; fb < 6; fb++) {
    let best = null;
    for (let fa = 0; fa < 6; fa++) for (let s = 0; s < 8; s++) {
      const t = sym(sa[fa], n, s);
      let e = 0;
      for (let i = 0; i < n * n; i++) e += (t[i] - sb[fb][i]) ** 2;
      if (!best || e < best.e) best = { fa, s, e };
    }
    console.log(`${pb} face ${names[fb]} = ${pa} face ${names[best.fa]} ${SYM[best.s]} (rms log diff ${Math.sqrt(best.e / (n * n)).toFixed(3)})`);
  }
}
