//! The one way the conformance pages are served and the browser started: the repository served
//! read-only on 127.0.0.1 (an ephemeral port, nothing outside the repository, no listing), and
//! the system `chromium` ($CHROMIUM) headless with SwiftShader WebGL2 and no network of its own.
//! Used by render.mjs, shader-check.mjs and ../filament-ktx1/check.mjs.
import http from "node:http";
import fs from "node:fs";
import path from "node:path";
import { createRequire } from "node:module";

/** The repository root (two folders above this file). */
export const root = path.resolve(path.dirname(new URL(import.meta.url).pathname), "../..");

const TYPES = {
  ".html": "text/html",
  ".js": "text/javascript",
  ".mjs": "text/javascript",
  ".wasm": "application/wasm",
  ".json": "application/json",
  ".png": "image/png",
};

/** Serves `root` on 127.0.0.1 and starts the browser: `{ base, browser, close }`. */
export async function serveAndLaunch() {
  const server = http.createServer((req, res) => {
    const u = new URL(req.url, "http://127.0.0.1");
    const p = path.resolve(root, "." + decodeURIComponent(u.pathname));
    if (!p.startsWith(root + path.sep) || !fs.existsSync(p) || !fs.statSync(p).isFile()) {
      res.writeHead(404);
      res.end();
      return;
    }
    res.writeHead(200, { "content-type": TYPES[path.extname(p)] || "application/octet-stream" });
    fs.createReadStream(p).pipe(res);
  });
  await new Promise((ok) => server.listen(0, "127.0.0.1", ok));
  // playwright-core is installed beside this file (conformance/render/node_modules), whoever imports it.
  const { chromium } = createRequire(new URL(import.meta.url))("playwright-core");
  const browser = await chromium.launch({
    executablePath: process.env.CHROMIUM || "/usr/bin/chromium",
    args: ["--no-sandbox", "--use-angle=swiftshader", "--enable-unsafe-swiftshader", "--disable-background-networking",
      "--disable-component-update", "--disable-sync", "--no-first-run", "--disable-quic"],
  });
  return {
    base: `http://127.0.0.1:${server.address().port}`,
    browser,
    close: async () => {
      await browser.close();
      server.close();
    },
  };
}
