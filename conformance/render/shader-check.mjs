//! Driver of the shader-check page (conformance/render/shader-check.sh): serves the repository
//! on 127.0.0.1 only, opens pages/shader-check.html in headless Chromium (system `chromium`,
//! SwiftShader's WebGL2, as render.mjs does), and writes the page's float outputs as an
//! `ibl-shader-check/1` grid (crates/shader-emulate) for `shader-emulate compare`.
//!
//! usage: node shader-check.mjs KIND GLSL CUBE.ktx2 INPUTS.json OUT.json [generate|box32]
//! (paths inside the repository; the last argument as the page's "mips")
import fs from "node:fs";
import path from "node:path";
import { root, serveAndLaunch } from "./serve.mjs";

const [kind, glsl, cube, inputs, out, mips] = process.argv.slice(2);
if (!out) {
  console.error("usage: node shader-check.mjs KIND GLSL CUBE.ktx2 INPUTS.json OUT.json");
  process.exit(2);
}
const url = (p) => {
  const abs = path.resolve(p);
  if (!abs.startsWith(root + path.sep)) throw new Error(`${p}: outside the served repository ${root}`);
  return "/" + path.relative(root, abs).split(path.sep).map(encodeURIComponent).join("/");
};
const { base, browser, close } = await serveAndLaunch();
let code = 0;
try {
  const t0 = Date.now();
  const page = await browser.newPage();
  const log = [];
  page.on("console", (m) => log.push(`${m.type()}: ${m.text()}`));
  page.on("pageerror", (e) => log.push(`pageerror: ${e.message}`));
  const q = new URLSearchParams({ p: JSON.stringify({ kind, glsl: url(glsl), cube: url(cube), inputs: url(inputs), mips: mips || "generate" }) });
  await page.goto(`${base}/conformance/render/pages/shader-check.html?${q}`);
  await page.waitForFunction(() => window.__result || window.__error, null, { timeout: 300000, polling: 200 });
  const err = await page.evaluate(() => window.__error && String(window.__error));
  if (err) {
    for (const l of log.slice(-15)) console.error(`  ${l}`);
    throw new Error(err);
  }
  const { renderer, ...grid } = await page.evaluate(() => window.__result);
  const tmp = `${out}.partial`;
  fs.writeFileSync(tmp, JSON.stringify(grid));
  fs.renameSync(tmp, out);
  console.log(`shader-check ${kind}: ${grid.count} cases of ${glsl} on ${renderer} in ${((Date.now() - t0) / 1000).toFixed(1)} s`);
} catch (e) {
  console.error(`shader-check ${kind} ${glsl}: ${String(e.message || e).split("\n")[0]}`);
  code = 1;
} finally {
  await close();
}
process.exit(code);
