//! Stacks PFM renders (same size) top to bottom into one PNG for people.
//! usage: node sheet.mjs [--half] OUT.png A.pfm B.pfm ...   (--half: 2×2 box-averaged, smaller)
import { readPfm, writePng } from "./lib.mjs";

const args = process.argv.slice(2);
const half = args[0] === "--half";
const [out, ...inputs] = half ? args.slice(1) : args;
if (!out || !inputs.length) {
  console.error("usage: node sheet.mjs OUT.png A.pfm [B.pfm ...]");
  process.exit(2);
}
const imgs = inputs.map(readPfm);
const { w, h } = imgs[0];
for (const [i, im] of imgs.entries()) {
  if (im.w !== w || im.h !== h) throw new Error(`${inputs[i]}: ${im.w}x${im.h}, expected ${w}x${h}`);
}
// PFM rows are bottom first: the last input's rows come first.
const rgb = new Float32Array(w * h * 3 * imgs.length);
imgs.slice().reverse().forEach((im, k) => rgb.set(im.rgb, k * w * h * 3));
if (!half) writePng(out, w, h * imgs.length, rgb);
else {
  const W2 = w >> 1, H2 = (h * imgs.length) >> 1, o = new Float32Array(W2 * H2 * 3);
  for (let y = 0; y < H2; y++) for (let x = 0; x < W2; x++) for (let c = 0; c < 3; c++) {
    let s = 0;
    for (const [dx, dy] of [[0, 0], [1, 0], [0, 1], [1, 1]]) s += rgb[((2 * y + dy) * w + 2 * x + dx) * 3 + c];
    o[(y * W2 + x) * 3 + c] = s / 4;
  }
  writePng(out, W2, H2, o);
}
