//! The render harness's summary: per engine and fixture, our bake's error against the
//! reference (render-ref) beside the engine's own route's error, the gate each was held to, and
//! the orientation verdicts (render-ref --check-orientation) of every engine's render of the
//! orientation panorama. Writes a markdown table and prints it.
//!
//! usage: node summary.mjs OUT.md DIR FIXTURE... — reads DIR/FIXTURE/{ENGINE}-{ours,own}.vs-ref.json
//!   (compare.mjs --json) and DIR/orientation/{ENGINE}-{ours,own}.orientation.json.
import fs from "node:fs";
import path from "node:path";

const ENGINES = [["three", "three.js r187"], ["filament", "Filament 1.53"], ["babylon", "Babylon.js 9"], ["gltf", "glTF Sample Renderer 1.1"]];
const [out, dir, ...fixtures] = process.argv.slice(2);
const read = (p) => (fs.existsSync(p) ? JSON.parse(fs.readFileSync(p, "utf8")) : null);
const pct = (x) => (x === undefined || x === null ? "—" : (100 * x).toFixed(2));
const cell = (c, g) => (c ? `${pct(c.groups[g].mean)} / ${pct(c.groups[g].p95)}` : "—");
const gate = (c) => {
  if (!c || !c.max || !Object.keys(c.max).length) return "—";
  const g = (k) => (c.max[k] === undefined ? "—" : pct(c.max[k]));
  const q = (k) => (c.maxP95?.[k] === undefined ? "—" : pct(c.maxP95[k]));
  return `${g("met-mirror")} / ${g("met-rough")} / ${g("diel-rough")} (p95 ${q("met-mirror")} / ${q("met-rough")} / ${q("diel-rough")})`;
};
const lines = [
  "| engine | fixture | ours: metal mirror | ours: metal rough | ours: dielectric rough | own route: metal mirror | own route: metal rough | own route: dielectric rough | gate on ours, mean % mirror / rough / diel (p95) |",
  "|---|---|---|---|---|---|---|---|---|",
];
for (const [e, name] of ENGINES) {
  for (const f of fixtures.filter((x) => x !== "orientation")) {
    const ours = read(path.join(dir, f, `${e}-ours.vs-ref.json`)), own = read(path.join(dir, f, `${e}-own.vs-ref.json`));
    lines.push(`| ${name} | ${f} | ${cell(ours, "met-mirror")} | ${cell(ours, "met-rough")} | ${cell(ours, "diel-rough")} | ${cell(own, "met-mirror")} | ${cell(own, "met-rough")} | ${cell(own, "diel-rough")} | ${gate(ours)} |`);
  }
}
lines.push("", "Mean relative luminance error / 95th percentile, %, over the masked spheres, against render-ref's reference with the engine's own BRDF terms (\"—\": no such route).");
if (fixtures.includes("orientation")) {
  lines.push("", "| engine | orientation, ours | orientation, own route |", "|---|---|---|");
  for (const [e, name] of ENGINES) {
    const v = (r) => {
      const j = read(path.join(dir, "orientation", `${e}-${r}.orientation.json`));
      return j ? `${j.verdict}${j.patches !== undefined ? ` (patches ${pct(j.patches)}% agree)` : ""}` : "—";
    };
    lines.push(`| ${name} | ${v("ours")} | ${v("own")} |`);
  }
}
const md = lines.join("\n") + "\n";
fs.writeFileSync(out, md);
process.stdout.write(md);
