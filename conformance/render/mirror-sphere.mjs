//! The harness's check of its own orientation check: writes a render with the metallic mirror
//! sphere (x ∈ [−6, −4], pixels 0…127) mirrored left-right about its centre, which is what an
//! engine that mirrors the world in x shows there; render-ref --check-orientation must refuse it.
//! usage: node mirror-sphere.mjs IN.pfm OUT.pfm
import { readPfm, writePfm } from "./lib.mjs";

const [input, out] = process.argv.slice(2);
const im = readPfm(input);
const rgb = Float32Array.from(im.rgb);
for (let y = 0; y < im.h; y++) {
  for (let x = 0; x < 128; x++) {
    for (let c = 0; c < 3; c++) rgb[3 * (y * im.w + x) + c] = im.rgb[3 * (y * im.w + 127 - x) + c];
  }
}
writePfm(out, im.w, im.h, rgb);
