//! Converts an OpenEXR panorama to Radiance .hdr (RGBE, new-style run-length scanlines made of
//! literal runs) for the engines whose own route takes only .hdr (Babylon's HDRCubeTexture, the
//! glTF Sample Renderer's loadEnvironment). Decoded by three's EXRLoader (mrdoob/three.js
//! `examples/jsm/loaders/EXRLoader.js`, rows bottom row first), written top row first.
//! usage: node exr2hdr.mjs IN.exr OUT.hdr
import fs from "node:fs";
import { EXRLoader } from "three/addons/loaders/EXRLoader.js";
import { FloatType } from "three";

const [input, out] = process.argv.slice(2);
const loader = new EXRLoader();
loader.setDataType(FloatType);
const buf = fs.readFileSync(input);
const { width: w, height: h, data } = loader.parse(buf.buffer.slice(buf.byteOffset, buf.byteOffset + buf.byteLength));
const c = data.length / (w * h);
const parts = [Buffer.from(`#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y ${h} +X ${w}\n`, "ascii")];
const rgbe = (r, g, b) => {
  const m = Math.max(r, g, b);
  if (!(m > 1e-32)) return [0, 0, 0, 0];
  const e = Math.ceil(Math.log2(m) + 1e-9);
  let s = Math.pow(2, -e) * 256;
  if (m * s >= 256) s /= 2;
  const ex = Math.round(Math.log2(256 / s));
  return [Math.floor(r * s), Math.floor(g * s), Math.floor(b * s), ex + 128];
};
for (let y = 0; y < h; y++) {
  const row = h - 1 - y; // EXRLoader rows are bottom first
  const px = [];
  for (let x = 0; x < w; x++) {
    const i = (row * w + x) * c;
    px.push(rgbe(Math.max(data[i], 0), Math.max(data[i + 1], 0), Math.max(data[i + 2], 0)));
  }
  const line = [2, 2, (w >> 8) & 0xff, w & 0xff];
  for (let ch = 0; ch < 4; ch++) {
    for (let x = 0; x < w; x += 128) {
      const n = Math.min(128, w - x);
      line.push(n);
      for (let k = 0; k < n; k++) line.push(px[x + k][ch]);
    }
  }
  parts.push(Buffer.from(line));
}
fs.writeFileSync(out, Buffer.concat(parts));
