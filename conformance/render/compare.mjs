//! Compares engine renders of the sphere-rows v1 scene with a reference render (PFM) over the
//! contract's mask (pixel centres at least 2 px inside a sphere's rim): per group — metallic
//! mirror (r = 0), metallic rough (r ≥ 0.2), dielectric mirror, dielectric rough — the mean
//! relative luminance error |a − ref| / max(ref, eps) and its 95th percentile.
//!
//! usage: node compare.mjs REF.pfm A.pfm [--label NAME] [--max GROUP=MEAN ...]
//!          [--max-p95 GROUP=P95 ...] [--json OUT] [--patches MIN]
//!   GROUP: met-mirror | met-rough | diel-mirror | diel-rough | all. Exits 1 when a group's mean
//!   is above its --max or its 95th percentile above its --max-p95 (or, with --patches, when fewer than MIN of the metallic mirror sphere's
//!   coloured pixels carry the reference's hue: the orientation panorama's ±X ±Y ±Z patches
//!   seen where the reference sees them), 2 on bad input.
import fs from "node:fs";
import { readPfm, sphereAt, W, H } from "./lib.mjs";

const GROUPS = ["met-mirror", "met-rough", "diel-mirror", "diel-rough"];

/** Relative errors per group of `a` against `ref` (both {w, h, rgb}, rows bottom first). */
export function groupErrors(ref, a) {
  const lum = (im, i) => 0.2126 * im.rgb[3 * i] + 0.7152 * im.rgb[3 * i + 1] + 0.0722 * im.rgb[3 * i + 2];
  const errs = Object.fromEntries([...GROUPS, "all"].map((g) => [g, []]));
  const perSphere = Array.from({ length: 12 }, () => []);
  for (let row = 0; row < H; row++) {
    for (let px = 0; px < W; px++) {
      const s = sphereAt(px, row);
      if (s < 0) continue;
      const i = (H - 1 - row) * W + px; // PFM rows bottom first
      const r = lum(ref, i), v = lum(a, i);
      const e = Number.isFinite(v) ? Math.abs(v - r) / Math.max(r, 1e-4) : Infinity;
      const g = `${s < 6 ? "met" : "diel"}-${s % 6 === 0 ? "mirror" : "rough"}`;
      errs[g].push(e);
      errs.all.push(e);
      perSphere[s].push(e);
    }
  }
  const stat = (v) => {
    const s = Float64Array.from(v).sort();
    const mean = s.reduce((x, y) => x + y, 0) / Math.max(s.length, 1);
    return { mean, p95: s[Math.min(s.length - 1, Math.floor(0.95 * s.length))], n: s.length };
  };
  return {
    groups: Object.fromEntries(Object.entries(errs).map(([g, v]) => [g, stat(v)])),
    spheres: perSphere.map(stat),
  };
}

/** Hue sector (0..5, 60° each) of a saturated colour, −1 for greys and darks. */
function hue(r, g, b) {
  const mx = Math.max(r, g, b), mn = Math.min(r, g, b);
  if (!(mx > 1e-4) || (mx - mn) / mx < 0.35) return -1;
  let h = mx === r ? ((g - b) / (mx - mn)) % 6 : mx === g ? (b - r) / (mx - mn) + 2 : (r - g) / (mx - mn) + 4;
  if (h < 0) h += 6;
  return Math.floor(h + 0.5) % 6;
}

/** Fraction of the metallic mirror sphere's saturated reference pixels whose hue sector `a`
 *  shows too: a flipped, turned or upside-down world moves the patches and fails it. */
export function patchAgreement(ref, a) {
  let n = 0, same = 0;
  for (let row = 0; row < H; row++) {
    for (let px = 0; px < W; px++) {
      if (sphereAt(px, row) !== 0) continue;
      const i = 3 * ((H - 1 - row) * W + px);
      const hr = hue(ref.rgb[i], ref.rgb[i + 1], ref.rgb[i + 2]);
      if (hr < 0) continue;
      n++;
      if (hue(a.rgb[i], a.rgb[i + 1], a.rgb[i + 2]) === hr) same++;
    }
  }
  return n ? same / n : NaN;
}

function main(argv) {
  const pos = [], max = {}, maxP95 = {};
  let label = null, json = null, patches = null;
  for (let k = 0; k < argv.length; k++) {
    if (argv[k] === "--label") label = argv[++k];
    else if (argv[k] === "--json") json = argv[++k];
    else if (argv[k] === "--patches") patches = +argv[++k];
    else if (argv[k] === "--max" || argv[k] === "--max-p95") {
      const flag = argv[k], [g, v] = argv[++k].split("=");
      if (![...GROUPS, "all"].includes(g) || !(+v >= 0)) throw new Error(`${flag} ${argv[k]}: GROUP=VALUE with GROUP one of ${GROUPS.join(", ")}, all`);
      (flag === "--max" ? max : maxP95)[g] = +v;
    } else pos.push(argv[k]);
  }
  if (pos.length !== 2) throw new Error("usage: node compare.mjs REF.pfm A.pfm [--label NAME] [--max GROUP=MEAN ...] [--json OUT]");
  const [refPath, aPath] = pos;
  const ref = readPfm(refPath), a = readPfm(aPath);
  for (const [p, im] of [[refPath, ref], [aPath, a]]) {
    if (im.w !== W || im.h !== H) throw new Error(`${p}: ${im.w}x${im.h}, the scene contract says ${W}x${H}`);
  }
  const r = groupErrors(ref, a);
  const pct = (x) => (100 * x).toFixed(2).padStart(7) + "%";
  const cells = GROUPS.map((g) => `${g} ${pct(r.groups[g].mean)} p95 ${pct(r.groups[g].p95)}`);
  console.log(`${(label || aPath).padEnd(28)} ${cells.join("  ")}`);
  if (json) fs.writeFileSync(json, JSON.stringify({ label, ref: refPath, image: aPath, max, maxP95, ...r }, null, 1));
  const over = Object.entries(max).filter(([g, m]) => !(r.groups[g].mean <= m));
  for (const [g, m] of over) console.error(`${label || aPath}: ${g} mean error ${pct(r.groups[g].mean)} is above ${pct(m)} (vs ${refPath})`);
  const overP95 = Object.entries(maxP95).filter(([g, m]) => !(r.groups[g].p95 <= m));
  for (const [g, m] of overP95) console.error(`${label || aPath}: ${g} p95 error ${pct(r.groups[g].p95)} is above ${pct(m)} (vs ${refPath})`);
  let bad = over.length > 0 || overP95.length > 0;
  if (patches !== null) {
    const f = patchAgreement(ref, a);
    console.log(`${(label || aPath).padEnd(28)} orientation patches: ${pct(f)} of the mirror sphere's coloured pixels agree`);
    if (!(f >= patches)) {
      console.error(`${label || aPath}: orientation patches agree on ${pct(f)}, below ${pct(patches)} (vs ${refPath})`);
      bad = true;
    }
  }
  return bad ? 1 : 0;
}

if (import.meta.url === `file://${process.argv[1]}`) {
  try {
    process.exit(main(process.argv.slice(2)));
  } catch (e) {
    console.error(`compare: ${e.message}`);
    process.exit(2);
  }
}
