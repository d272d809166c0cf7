//! A labelled side-by-side picture of renders (PFM, same size) for people: a grid with one
//! column per engine and one row per route, each cell a render box-averaged `--scale` times
//! smaller under a caption drawn into the PNG with the 5×7 bitmap font of ibl-preview
//! (crates/ibl-preview/src/font.rs, read from that file: one font in the repository).
//!
//! usage: node sheet.mjs OUT.png [--scale K] [--title TEXT] --cols A,B,... --row NAME=CELL,CELL,...
//!   CELL: PATH.pfm, PATH.pfm|CAPTION (caption under the column's name), or -|TEXT for an empty
//!   cell saying TEXT. Every --row has one cell per column. One exposure for every cell: the
//!   first render's log-average luminance over its lit pixels mapped to 0.18 (or --ev EV).
import fs from "node:fs";
import path from "node:path";
import { readPfm, writePng } from "./lib.mjs";

const root = path.resolve(path.dirname(new URL(import.meta.url).pathname), "../..");

/** The glyph table of crates/ibl-preview/src/font.rs: char → 7 rows (bit 4 = leftmost column). */
function loadFont() {
  const src = fs.readFileSync(path.join(root, "crates/ibl-preview/src/font.rs"), "utf8");
  const font = new Map();
  for (const m of src.matchAll(/\('(.)', \[((?:0x[0-9A-Fa-f]{2},? ?){7})\]\)/gu)) {
    font.set(m[1], m[2].split(",").map((s) => parseInt(s, 16)));
  }
  if (!font.has("?") || font.size < 40) throw new Error("crates/ibl-preview/src/font.rs: glyph table not found");
  return font;
}

const GW = 5, GH = 7, ADV = 6, LINE = 10;

/** Draws `text` (upper-cased) into `img` ({w, h, rgb}, rows top first) at (x, y), colour c. */
function drawText(font, img, x, y, text, c = [1, 1, 1]) {
  for (const ch of text.toUpperCase()) {
    const g = font.get(ch) || font.get("?");
    for (let r = 0; r < GH; r++) for (let k = 0; k < GW; k++) {
      if (!(g[r] & (0x10 >> k))) continue;
      const px = x + k, py = y + r;
      if (px < 0 || py < 0 || px >= img.w || py >= img.h) continue;
      img.rgb.set(c, 3 * (py * img.w + px));
    }
    x += ADV;
  }
}

function main(argv) {
  let out = null, scale = 2, title = "", cols = null, ev = null;
  const rows = [];
  for (let k = 0; k < argv.length; k++) {
    const a = argv[k];
    if (a === "--scale") scale = +argv[++k];
    else if (a === "--title") title = argv[++k];
    else if (a === "--ev") ev = +argv[++k];
    else if (a === "--cols") cols = argv[++k].split(",");
    else if (a === "--row") {
      const v = argv[++k], eq = v.indexOf("=");
      rows.push({ name: v.slice(0, eq), cells: v.slice(eq + 1).split(",") });
    } else if (!out) out = a;
    else throw new Error(`unexpected argument ${a}`);
  }
  if (!out || !cols || !rows.length || !(scale >= 1 && Number.isInteger(scale))) {
    throw new Error("usage: node sheet.mjs OUT.png [--scale K] [--title TEXT] --cols A,B --row NAME=CELL,CELL ...");
  }
  for (const r of rows) if (r.cells.length !== cols.length) throw new Error(`row ${r.name}: ${r.cells.length} cells for ${cols.length} columns`);
  const font = loadFont();
  const imgs = rows.map((r) => r.cells.map((c) => {
    const [p, caption = ""] = c.split("|");
    if (p !== "-" && !fs.existsSync(p)) return { im: null, caption: "not rendered", path: p };
    return { im: p === "-" ? null : readPfm(p), caption, path: p };
  }));
  const first = imgs.flat().find((c) => c.im);
  if (!first) throw new Error("no render given");
  const { w, h } = first.im;
  for (const c of imgs.flat()) if (c.im && (c.im.w !== w || c.im.h !== h)) throw new Error(`${c.path}: ${c.im.w}x${c.im.h}, expected ${w}x${h}`);
  let gain = Math.pow(2, ev ?? 0);
  if (ev === null) {
    let n = 0, acc = 0;
    for (let i = 0; i < w * h; i++) {
      const l = 0.2126 * first.im.rgb[3 * i] + 0.7152 * first.im.rgb[3 * i + 1] + 0.0722 * first.im.rgb[3 * i + 2];
      if (l > 0 && Number.isFinite(l)) { acc += Math.log(l); n++; }
    }
    if (n) gain = 0.18 / Math.exp(acc / n);
  }
  const cw = Math.floor(w / scale), ch = Math.floor(h / scale), gap = 4;
  const head = title ? LINE + 4 : 0, cap = 2 * LINE + 2;
  const W = cols.length * (cw + gap) - gap, H = head + rows.length * (cap + ch + gap) - gap;
  const sheet = { w: W, h: H, rgb: new Float32Array(W * H * 3) }; // rows top first
  if (title) drawText(font, sheet, 2, 2, title, [1, 1, 0.6]);
  rows.forEach((r, ri) => {
    const y0 = head + ri * (cap + ch + gap);
    imgs[ri].forEach((c, ci) => {
      const x0 = ci * (cw + gap);
      drawText(font, sheet, x0 + 2, y0 + 1, `${cols[ci]} · ${r.name}`, [1, 1, 1]);
      if (c.caption) drawText(font, sheet, x0 + 2, y0 + 1 + LINE, c.caption, [0.7, 0.85, 1]);
      if (!c.im) return;
      for (let y = 0; y < ch; y++) for (let x = 0; x < cw; x++) for (let k = 0; k < 3; k++) {
        let s = 0;
        for (let dy = 0; dy < scale; dy++) for (let dx = 0; dx < scale; dx++) {
          const row = h - 1 - (y * scale + dy); // PFM rows bottom first
          s += c.im.rgb[3 * (row * w + x * scale + dx) + k];
        }
        const v = (gain * s) / (scale * scale);
        sheet.rgb[3 * ((y0 + cap + y) * W + x0 + x) + k] = Number.isFinite(v) ? v : 0;
      }
    });
  });
  // writePng takes rows bottom first.
  const flipped = new Float32Array(sheet.rgb.length);
  for (let y = 0; y < H; y++) flipped.set(sheet.rgb.subarray(y * W * 3, (y + 1) * W * 3), (H - 1 - y) * W * 3);
  writePng(out, W, H, flipped);
}

try {
  main(process.argv.slice(2));
} catch (e) {
  console.error(`sheet: ${e.message}`);
  process.exit(2);
}
