//! Writes a synthetic orientation panorama (EXR, 256×128, our mapping u = 0.5 + atan2(z, x)/2π,
//! v = acos(y)/π): grey, with a saturated disc (0.5 rad) on each axis — +X red, −X cyan, +Y green,
//! −Y magenta, +Z blue, −Z yellow — and an orange chirality mark at (0.7, 0.7, 0.14), so a flip,
//! a 90° turn or an upside-down face moves a colour. Stands in until the reference branch's
//! generator is merged (then pass its file as ORIENT_ENV). Encoded by three's EXRExporter.
//! usage: node orientation-exr.mjs OUT.exr
import fs from "node:fs";
import { DataTexture, FloatType, RGBAFormat } from "three";
import { EXRExporter } from "three/addons/exporters/EXRExporter.js";

const w = 256, h = 128, data = new Float32Array(w * h * 4);
const patches = [
  [[1, 0, 0], [1, 0.05, 0.05]], [[-1, 0, 0], [0.05, 1, 1]], [[0, 1, 0], [0.05, 1, 0.05]],
  [[0, -1, 0], [1, 0.05, 1]], [[0, 0, 1], [0.05, 0.05, 1]], [[0, 0, -1], [1, 1, 0.05]],
  [[0.7, 0.7, 0.14], [1, 0.5, 0.05]],
];
for (let y = 0; y < h; y++) {
  for (let x = 0; x < w; x++) {
    const ph = ((x + 0.5) / w - 0.5) * 2 * Math.PI, th = ((y + 0.5) / h) * Math.PI;
    const d = [Math.sin(th) * Math.cos(ph), Math.cos(th), Math.sin(th) * Math.sin(ph)];
    let c = [0.2, 0.2, 0.2];
    for (const [p, col] of patches) {
      if ((d[0] * p[0] + d[1] * p[1] + d[2] * p[2]) / Math.hypot(...p) > Math.cos(0.5)) c = col;
    }
    data.set([...c, 1], ((h - 1 - y) * w + x) * 4); // DataTexture rows bottom first
  }
}
const out = await new EXRExporter().parse(new DataTexture(data, w, h, RGBAFormat, FloatType), { type: FloatType });
fs.writeFileSync(process.argv[2], Buffer.from(out));
