//! Stacks PFM renders (same size) top to bottom into one PNG for people.
//! usage: node sheet.mjs OUT.png A.pfm B.pfm ...
import { readPfm, writePng } from "./lib.mjs";

const [out, ...inputs] = process.argv.slice(2);
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
writePng(out, w, h * imgs.length, rgb);
