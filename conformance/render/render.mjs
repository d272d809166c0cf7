//! Renders jobs with the engines' own web builds in headless Chromium (system `chromium`,
//! driven by playwright-core), from pages served on 127.0.0.1 only, and writes each job's
//! linear float read-back as PFM (+ PNG for people).
//!
//! usage: node render.mjs JOBS.json   — JOBS: [{ "page": "three", "params": {...}, "out": "dir/stem" }]
//! (or "outs": [stems] for a page that renders several routes and hands back one image each)
//! Paths in params are URLs relative to the served root (the repository).
import fs from "node:fs";
import path from "node:path";
import { root, serveAndLaunch } from "./serve.mjs";
import { writePfm, writePng } from "./lib.mjs";

const jobsFile = process.argv[2];
if (!jobsFile) {
  console.error("usage: node render.mjs JOBS.json");
  process.exit(2);
}
const jobs = JSON.parse(fs.readFileSync(jobsFile, "utf8"));
const { base, browser, close } = await serveAndLaunch();
let failed = 0;
try {
  for (const job of jobs) {
    const t0 = Date.now();
    const page = await browser.newPage();
    const log = [];
    page.on("console", (m) => log.push(`${m.type()}: ${m.text()}`));
    page.on("pageerror", (e) => log.push(`pageerror: ${e.message}`));
    const q = new URLSearchParams({ p: JSON.stringify(job.params) });
    try {
      await page.goto(`${base}/conformance/render/pages/${job.page}.html?${q}`);
      await page.waitForFunction(() => window.__result || window.__results || window.__error, null, { timeout: (job.timeout || 120) * 1000, polling: 200 });
      const err = await page.evaluate(() => window.__error && String(window.__error));
      if (err) throw new Error(err);
      const results = await page.evaluate(() => window.__results || [window.__result]);
      const outs = job.outs || [job.out];
      if (results.length !== outs.length) throw new Error(`the page handed back ${results.length} images for ${outs.length} outputs`);
      for (const [k, { w, h, b64 }] of results.entries()) {
        const f = new Float32Array(Buffer.from(b64, "base64").buffer.slice(0));
        const rgb = new Float32Array(w * h * 3);
        for (let i = 0; i < w * h; i++) for (let c = 0; c < 3; c++) rgb[3 * i + c] = f[4 * i + c];
        fs.mkdirSync(path.dirname(outs[k]), { recursive: true });
        writePfm(`${outs[k]}.pfm`, w, h, rgb);
        writePng(`${outs[k]}.png`, w, h, rgb);
      }
      // A file the page made with the engine's own tools (Babylon's .env writer), kept beside.
      const extra = await page.evaluate(() => window.__extra || null);
      if (extra) fs.writeFileSync(`${outs[0]}.${extra.ext}`, Buffer.from(extra.b64, "base64"));
      for (const l of log.filter((x) => x.startsWith("log:"))) console.log(`  ${l}`);
      console.log(`rendered ${outs.map((o) => `${o}.pfm`).join(", ")} (${job.page}, ${((Date.now() - t0) / 1000).toFixed(1)} s)`);
    } catch (e) {
      failed++;
      console.error(`render ${job.page} ${JSON.stringify(job.params)}: ${e.message.split("\n")[0]}`);
      for (const l of log.slice(-15)) console.error(`  ${l}`);
    }
    await page.close();
  }
} finally {
  await close();
}
process.exit(failed ? 1 : 0);
