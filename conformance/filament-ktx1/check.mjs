//! Filament's own KTX1 reader (npm `filament` 1.53, its wasm build, in headless Chromium with
//! SwiftShader WebGL2) loads each file given; exits 1 when a file marked `ok` does not load or
//! one marked `abort` does (the second kind documents a refusal of ours: when Filament starts
//! taking the file, the refusal can go).
//!
//! usage: node check.mjs ok:FILE ... abort:FILE ...   (paths relative to the repository root)
import { serveAndLaunch } from "../render/serve.mjs";

const { base, browser, close } = await serveAndLaunch();
let passed = 0, failed = 0;
try {
  for (const arg of process.argv.slice(2)) {
    const [want, file] = [arg.slice(0, arg.indexOf(":")), arg.slice(arg.indexOf(":") + 1)];
    const page = await browser.newPage();
    const log = [];
    page.on("console", (m) => log.push(m.text()));
    const url = `${base}/conformance/filament-ktx1/page.html?f=${encodeURIComponent("/" + file)}`;
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
  await close();
}
console.log(`${passed} passed, ${failed} failed`);
process.exit(failed ? 1 : 0);
