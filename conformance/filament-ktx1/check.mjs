//! Filament's own KTX1 reader (npm `filament` 1.53, its wasm build, in headless Chromium with
//! SwiftShader WebGL2) loads each file given; exits 1 when a file marked `ok` does not load or
//! one marked `abort` does (the second kind documents a refusal of ours: when Filament starts
//! taking the file, the refusal can go).
//!
//! usage: node check.mjs ok:FILE ... abort:FILE ...   (paths relative to the repository root)
import http from "node:http";
import fs from "node:fs";
import path from "node:path";
import { createRequire } from "node:module";

const root = path.resolve(path.dirname(new URL(import.meta.url).pathname), "../..");
const require = createRequire(path.join(root, "conformance/render/package.json"));
const { chromium } = require("playwright-core");
const types = { ".html": "text/html", ".js": "text/javascript", ".wasm": "application/wasm" };
const server = http.createServer((req, res) => {
  const p = path.resolve(root, "." + decodeURIComponent(new URL(req.url, "http://127.0.0.1").pathname));
  if (!p.startsWith(root + path.sep) || !fs.existsSync(p) || !fs.statSync(p).isFile()) {
    res.writeHead(404);
    return res.end();
  }
  res.writeHead(200, { "content-type": types[path.extname(p)] || "application/octet-stream" });
  fs.createReadStream(p).pipe(res);
});
await new Promise((ok) => server.listen(0, "127.0.0.1", ok));
const browser = await chromium.launch({
  executablePath: process.env.CHROMIUM || "/usr/bin/chromium",
  args: ["--no-sandbox", "--use-angle=swiftshader", "--enable-unsafe-swiftshader", "--disable-background-networking"],
});
let passed = 0, failed = 0;
try {
  for (const arg of process.argv.slice(2)) {
    const [want, file] = [arg.slice(0, arg.indexOf(":")), arg.slice(arg.indexOf(":") + 1)];
    const page = await browser.newPage();
    const log = [];
    page.on("console", (m) => log.push(m.text()));
    const url = `http://127.0.0.1:${server.address().port}/conformance/filament-ktx1/page.html?f=${encodeURIComponent("/" + file)}`;
    await page.goto(url);
    let got;
    try {
      got = await (await page.waitForFunction(() => window.__done, null, { timeout: 60000, polling: 100 })).jsonValue();
    } catch (e) {
      got = `no answer: ${e.message.split("\n")[0]}`;
    }
    const reason = log.join(" ").match(/reason: ([^\n]*)/);
    const ok = want === "ok" ? got === "loaded" : got.startsWith("error");
    ok ? passed++ : failed++;
    console.log(`${ok ? "ok  " : "FAIL"} Filament ${got === "loaded" ? "loads" : "aborts on"} ${file} (expected ${want === "ok" ? "to load" : "an abort"})${reason ? `: ${reason[1]}` : ""}`);
    await page.close();
  }
} finally {
  await browser.close();
  server.close();
}
console.log(`${passed} passed, ${failed} failed`);
process.exit(failed ? 1 : 0);
