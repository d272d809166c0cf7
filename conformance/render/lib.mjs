//! Shared helpers of the render harness: PFM read/write (rows bottom first, as the PFM
//! specification and GL readPixels store them), a small PNG writer for people, and the
//! sphere-rows v1 scene mask (scene-contract: 768×256, spheres r = 0.9 at x = −5…5, y = ±1).
import fs from "node:fs";
import zlib from "node:zlib";

export const W = 768, H = 256;
export const COLS = [-5, -3, -1, 1, 3, 5];
export const ROUGH = [0, 0.2, 0.4, 0.6, 0.8, 1.0];

/** Writes RGB floats (rows bottom first) as a little-endian PFM. */
export function writePfm(path, w, h, rgb) {
  const head = Buffer.from(`PF\n${w} ${h}\n-1.0\n`, "ascii");
  const body = Buffer.from(new Float32Array(rgb).buffer);
  fs.writeFileSync(path, Buffer.concat([head, body]));
}

/** Reads a PFM ("PF", 3 channels) into {w, h, rgb} with rows bottom first. */
export function readPfm(path) {
  const b = fs.readFileSync(path);
  let o = 0;
  const token = () => {
    while (/\s/.test(String.fromCharCode(b[o]))) o++;
    const s = o;
    while (!/\s/.test(String.fromCharCode(b[o]))) o++;
    return b.toString("ascii", s, o);
  };
  const magic = token();
  if (magic !== "PF") throw new Error(`${path}: not a 3-channel PFM (magic ${magic})`);
  const w = +token(), h = +token(), scale = +token();
  o++;
  const n = w * h * 3;
  if (!(w > 0 && h > 0) || b.length - o < n * 4) throw new Error(`${path}: truncated PFM`);
  const rgb = new Float32Array(n);
  for (let i = 0; i < n; i++) rgb[i] = scale < 0 ? b.readFloatLE(o + 4 * i) : b.readFloatBE(o + 4 * i);
  return { w, h, rgb };
}

/** Linear RGB (rows bottom first) to an 8-bit sRGB PNG (exposure `ev`, clamped), for people. */
export function writePng(path, w, h, rgb, ev = 0) {
  const k = Math.pow(2, ev);
  const enc = (v) => {
    v = Math.max(0, Math.min(1, v * k));
    v = v <= 0.0031308 ? 12.92 * v : 1.055 * Math.pow(v, 1 / 2.4) - 0.055;
    return Math.round(v * 255);
  };
  const raw = Buffer.alloc((w * 3 + 1) * h);
  for (let y = 0; y < h; y++) {
    const src = (h - 1 - y) * w * 3; // PNG rows top first
    raw[y * (w * 3 + 1)] = 0;
    for (let x = 0; x < w * 3; x++) raw[y * (w * 3 + 1) + 1 + x] = enc(rgb[src + x]);
  }
  const crcTable = new Int32Array(256).map((_, n) => {
    let c = n;
    for (let k2 = 0; k2 < 8; k2++) c = c & 1 ? 0xedb88320 ^ (c >>> 1) : c >>> 1;
    return c;
  });
  const crc = (buf) => {
    let c = -1;
    for (const x of buf) c = crcTable[(c ^ x) & 0xff] ^ (c >>> 8);
    return (c ^ -1) >>> 0;
  };
  const chunk = (type, data) => {
    const len = Buffer.alloc(4);
    len.writeUInt32BE(data.length);
    const td = Buffer.concat([Buffer.from(type, "ascii"), data]);
    const c = Buffer.alloc(4);
    c.writeUInt32BE(crc(td));
    return Buffer.concat([len, td, c]);
  };
  const ihdr = Buffer.alloc(13);
  ihdr.writeUInt32BE(w, 0);
  ihdr.writeUInt32BE(h, 4);
  ihdr.set([8, 2, 0, 0, 0], 8);
  fs.writeFileSync(path, Buffer.concat([
    Buffer.from([0x89, 0x50, 0x4e, 0x47, 0x0d, 0x0a, 0x1a, 0x0a]),
    chunk("IHDR", ihdr), chunk("IDAT", zlib.deflateSync(raw)), chunk("IEND", Buffer.alloc(0)),
  ]));
}

/** Sphere index (0..11: top row 0..5, bottom row 6..11) of the pixel whose centre is at least
 *  2 pixels inside a sphere's rim, else −1. `row` counts from the top (row 0 = top). */
export function sphereAt(px, row) {
  const x = -6 + (px + 0.5) / 64, y = 2 - (row + 0.5) / 64;
  const r = 0.9 - 2 / 64;
  for (let i = 0; i < 6; i++) {
    for (const [k, cy] of [[0, 1], [1, -1]]) {
      const dx = x - COLS[i], dy = y - cy;
      if (dx * dx + dy * dy <= r * r) return k * 6 + i;
    }
  }
  return -1;
}
