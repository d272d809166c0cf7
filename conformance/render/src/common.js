//! Page-side helpers shared by the engine pages: parameters, the LOAD.txt snippet, the result
//! hand-back (linear RGBA floats, rows bottom first as readPixels returns them).

/** The job's parameters (JSON in ?p=). */
export const params = JSON.parse(new URLSearchParams(location.search).get("p") || "{}");

/** The sphere-rows v1 scene (scene-contract): columns, roughness, rows. */
export const SCENE = {
  width: 768, height: 256,
  cols: [-5, -3, -1, 1, 3, 5],
  roughness: [0, 0.2, 0.4, 0.6, 0.8, 1.0],
  rows: [{ y: 1, metallic: 1 }, { y: -1, metallic: 0 }],
  radius: 0.9,
};

/** The fenced ```js block of the LOAD.txt a run wrote, with its import lines and `export`
 *  keywords removed (the page imports the same modules and hands them in by name), turned into
 *  a function of `names` returning the snippet's functions `exports`. So the page runs exactly
 *  the code the note shows a user. */
export async function loadSnippet(noteUrl, names, exports) {
  const r = await fetch(noteUrl);
  if (!r.ok) throw new Error(`${noteUrl}: ${r.status}`);
  const text = await r.text();
  const m = text.match(/```js\n([\s\S]*?)```/);
  if (!m) throw new Error(`${noteUrl}: no \`\`\`js snippet in the note`);
  const code = m[1]
    .split("\n")
    .filter((l) => !/^\s*import\s/.test(l))
    .map((l) => l.replace(/^export\s+/, ""))
    .join("\n");
  // eslint-disable-next-line no-new-func
  const f = new Function(...names, `${code}\nreturn { ${exports.join(", ")} };`);
  return (...values) => f(...values);
}

/** Base64 of bytes. */
export function b64(bytes) {
  let s = "";
  for (let i = 0; i < bytes.length; i += 0x8000) s += String.fromCharCode.apply(null, bytes.subarray(i, i + 0x8000));
  return btoa(s);
}

/** Hands the RGBA float read-back (rows bottom first) to the driver. */
export function finish(w, h, rgba) {
  window.__result = { w, h, b64: b64(new Uint8Array(rgba.buffer, rgba.byteOffset, rgba.byteLength)) };
}

/** Hands several read-backs of one page (one per route, in the job's `outs` order). */
export function finishAll(w, h, list) {
  window.__results = list.map((rgba) => ({ w, h, b64: b64(new Uint8Array(rgba.buffer, rgba.byteOffset, rgba.byteLength)) }));
}

/** Runs `main`, reporting any failure to the driver. */
export function run(main) {
  main().catch((e) => {
    console.error(e && e.stack ? e.stack : String(e));
    window.__error = `${e && e.message ? e.message : e}`;
  });
}
