//! Holds a compare.mjs result (its --json output) against conformance/bevy-render/gates.txt:
//! for the named fixture, every group's mean and 95th percentile of the relative luminance error
//! must be at or below the gate (compare.mjs's own --max gates only the mean).
//!
//! usage: node gate.mjs GATES.txt FIXTURE RESULT.json
//!   Exits 0 when every gated group passes, 1 when one is above its gate (one line per group),
//!   2 on bad input (no gate for the fixture, a group the result lacks, a malformed line).
import fs from "node:fs";

function main([gatesPath, fixture, resultPath]) {
  if (!resultPath) throw new Error("usage: node gate.mjs GATES.txt FIXTURE RESULT.json");
  const gates = [];
  fs.readFileSync(gatesPath, "utf8").split("\n").forEach((line, k) => {
    const t = line.replace(/#.*/, "").trim();
    if (!t) return;
    const f = t.split(/\s+/);
    if (f.length !== 4 || !(+f[2] >= 0) || !(+f[3] >= 0)) throw new Error(`${gatesPath}:${k + 1}: expected "FIXTURE GROUP MEAN P95", got "${t}"`);
    if (f[0] === fixture) gates.push({ group: f[1], mean: +f[2], p95: +f[3] });
  });
  if (!gates.length) throw new Error(`${gatesPath}: no gate for ${fixture}`);
  const r = JSON.parse(fs.readFileSync(resultPath, "utf8"));
  const pct = (x) => (100 * x).toFixed(2) + "%";
  let bad = false;
  for (const g of gates) {
    const s = r.groups?.[g.group];
    if (!s) throw new Error(`${resultPath}: no group ${g.group}`);
    for (const k of ["mean", "p95"]) {
      // NaN (an empty group or a non-finite pixel) fails too.
      if (!(s[k] <= g[k])) {
        console.error(`bevy-render ${fixture}: ${g.group} ${k} error ${pct(s[k])} is above its gate ${pct(g[k])} (${gatesPath})`);
        bad = true;
      }
    }
  }
  return bad ? 1 : 0;
}

try {
  process.exit(main(process.argv.slice(2)));
} catch (e) {
  console.error(`gate.mjs: ${e.message}`);
  process.exit(2);
}
