//! Renders jobs with the engines' own web builds in headless Chromium (system `chromium`,
//! driven by playwright-core), from pages served on 127.0.0.1 only, and writes each job's
//! linear float read-back as PFM (+ PNG for people).
//!
//! usage: node render.mjs JOBS.json   — JOBS: [{ "page": "three", "params": {...}, "out": "dir/stem" }]
//! (or "outs": [stems] for a page that renders several routes and hands back one image each)
//! Paths in params are URLs relative to the served root (the repository).
import http from "node:http";
import fs from "node:fs";
import path from "node:path";
import { chromium } from "playwright-core";
import { writePfm, writePng } from "./lib.mjs";

const root = path.resolve(path.dirname(new URL(import.meta.url).pathname), "../..");
const jobsFile = process.argv[2];
if (!jobsFile) {
  console.error("usage: node render.mjs JOBS.json");
  process.exit(2);
}
const jobs = JSON.parse(fs.readFileSync(jobsFile, "utf8"));
const types = { ".html": "text/html", ".js": "text/javascript", ".mjs": "text/javascript", ".wasm": "application/wasm", ".json": "application/json", ".png": "image/png" };

const server = http.createServer((req, res) => {
  const u = new URL(req.url, "http://127.0.0.1");
  const p = path.resolve(root, "." + decodeURIComponent(u.pathname));
  if (!p.startsWith(root + path.sep) || !fs.existsSync(p) || !fs.statSync(p).isFile()) {
    res.writeHead(404);
    res.end();
    return;
  }
  res.writeHead(200, { "content-type": types[path.extname(p)] || "application/octet-stream" });
  fs.createReadStream(p).pipe(res);
});
await new Promise((ok) => server.listen(0, "127.0.0.1", ok));
const base = `http://127.0.0.1:${server.address().port}`;

const browser = await chromium.launch({
  executablePath: process.env.CHROMIUM || "/usr/bin/chromium",
  args: ["--no-sandbox", "--use-angle=swiftshader", "--enable-unsafe-swiftshader", "--disable-background-networking",
    "--disable-component-update", "--disable-sync", "--no-first-run", "--disable-quic"],
});
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
  await browser.close();
  server.close();
}
process.exit(failed ? 1 : 0);
