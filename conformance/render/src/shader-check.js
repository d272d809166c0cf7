//! The shader-check page (conformance/render/shader-check.sh): takes an emitted GLSL file
//! verbatim, wraps it in a WebGL2 fragment shader that calls the emitted function once per
//! case of an input grid (an RGBA32F texture, read with texelFetch), uploads the cube the
//! function reads as a renderer is told to (docs/CUSTOM_LOOKUP.md, the aniso_fis.glsl header),
//! renders into an RGBA32F target and hands the floats back. No engine, no bundler: plain
//! WebGL2, so what runs is the emitted text and the GPU's (here SwiftShader's) sampler.
//!
//! ?p={"kind":"custom"|"aniso"|"as","glsl":URL,"cube":URL (KTX2),"inputs":URL (grid JSON),
//!     "mips":"generate"|"box32" (aniso; box32, for diagnosis: the 2x2 box chain computed here
//!     in float32 and uploaded as RGBA32F, the emulation's pyramid, instead of generateMipmap)}

const ROW = 256; // cases per row, as crates/shader-emulate (ROW)
const params = JSON.parse(new URLSearchParams(location.search).get("p") || "{}");

/** An uncompressed KTX2 cube (RGBA16F or RGBA32F): {size, levels: [[6 faces' typed arrays]]}. */
function parseKtx2Cube(buf, url) {
  const u8 = new Uint8Array(buf);
  const id = [0xab, 0x4b, 0x54, 0x58, 0x20, 0x32, 0x30, 0xbb, 0x0d, 0x0a, 0x1a, 0x0a];
  if (u8.length < 80 || id.some((b, i) => u8[i] !== b)) throw new Error(`${url}: not a KTX2 file`);
  const dv = new DataView(buf);
  const u32 = (o) => dv.getUint32(o, true);
  const u64 = (o) => Number(dv.getBigUint64(o, true));
  const vkFormat = u32(12), width = u32(20), height = u32(24), faces = u32(36);
  const levelCount = Math.max(1, u32(40)), scheme = u32(44);
  // VK_FORMAT_R16G16B16A16_SFLOAT (97) and VK_FORMAT_R32G32B32A32_SFLOAT (109) only.
  const half = vkFormat === 97;
  if (!half && vkFormat !== 109) throw new Error(`${url}: vkFormat ${vkFormat}, this page reads RGBA16F (97) or RGBA32F (109)`);
  if (faces !== 6 || width !== height) throw new Error(`${url}: not a square cube (${faces} faces, ${width}x${height})`);
  if (scheme !== 0) throw new Error(`${url}: supercompressed (scheme ${scheme}); bake without --zstd`);
  const levels = [];
  for (let l = 0; l < levelCount; l++) {
    const off = u64(80 + 24 * l), len = u64(88 + 24 * l);
    const s = Math.max(1, width >> l), n = s * s * 4;
    if (len !== 6 * n * (half ? 2 : 4) || off + len > buf.byteLength) throw new Error(`${url}: level ${l} is ${len} bytes at ${off}, expected 6 faces of ${s}x${s} RGBA`);
    const facesData = [];
    for (let f = 0; f < 6; f++) {
      const o = off + f * n * (half ? 2 : 4);
      facesData.push(half ? new Uint16Array(buf.slice(o, o + 2 * n)) : new Float32Array(buf.slice(o, o + 4 * n)));
    }
    levels.push(facesData);
  }
  return { size: width, half, levels };
}

/** IEEE half to float. */
function halfToFloat(h) {
  const e = (h >> 10) & 31, m = h & 1023;
  const v = e === 0 ? m * 2 ** -24 : e === 31 ? (m ? NaN : Infinity) : (1 + m / 1024) * 2 ** (e - 15);
  return h & 0x8000 ? -v : v;
}

/** Level 0 of the cube and its 2x2 box means down to 1x1, in float32 (ibl_core's
 *  Cubemap::downsample, the emulation's pyramid). */
function boxChain(cube) {
  let cur = cube.levels[0].map((d) => (cube.half ? Float32Array.from(d, halfToFloat) : Float32Array.from(d)));
  const out = [cur];
  for (let s = cube.size; s > 1; s >>= 1) {
    const m = s >> 1;
    cur = cur.map((a) => {
      const o = new Float32Array(m * m * 4);
      for (let j = 0; j < m; j++) for (let i = 0; i < m; i++) for (let c = 0; c < 4; c++) {
        const at = (x, y) => a[(y * s + x) * 4 + c];
        o[(j * m + i) * 4 + c] = 0.25 * (at(2 * i, 2 * j) + at(2 * i + 1, 2 * j) + at(2 * i, 2 * j + 1) + at(2 * i + 1, 2 * j + 1));
      }
      return o;
    });
    out.push(cur);
  }
  return out;
}

const CALL = {
  // iblCustomSpecular(samplerCube chain, vec3 R, float roughness) of lookup.glsl.
  custom: { fields: 1, body: `vec4 a = field(0);\n  o = vec4(iblCustomSpecular(u_cube, a.xyz, a.w), 1.0);` },
  // anisoFisSpecular(env, log2TexelSolidAngle, maxLod, n, t, b, v, alphaT, alphaB, f0, rotation,
  // isoSpecular). isoSpecular, the renderer's isotropic split sum (custom chain read at r_iso
  // times F0 A + B), is computed on the CPU (shader-emulate inputs aniso) and fed to both
  // sides, so what is tested is the emitted function itself. The emitted file runs verbatim
  // in GLSL ES 3.00: it carries its own bit reversal (no bitfieldReverse in ES 3.00).
  aniso: {
    fields: 6,
    body: `vec4 n = field(0), t = field(1), b = field(2), v = field(3), rot = field(4), iso = field(5);
  o = vec4(anisoFisSpecular(u_cube, u_log2TexelSolidAngle, u_maxLod, n.xyz, t.xyz, b.xyz, v.xyz, n.w, t.w, vec3(b.w), rot.xy, iso.rgb), 1.0);`,
  },
  // anisoAsSpecular(env, hvLut, pdfHN, gridA, gridB, log2TexelSolidAngle, maxLod, n, t, b, v,
  // f0): the hv-lut table travels in the input grid ("lut") and is uploaded as an RGBA32F 2D
  // texture, bilinear, clamped to the edge, no mips (the snippet's header).
  as: {
    fields: 4,
    prelude: "uniform sampler2D u_lut;",
    body: `vec4 n = field(0), t = field(1), b = field(2), v = field(3);
  o = vec4(anisoAsSpecular(u_cube, u_lut, n.w, int(t.w), int(b.w), u_log2TexelSolidAngle, u_maxLod, n.xyz, t.xyz, b.xyz, v.xyz, vec3(v.w)), 1.0);`,
  },
};

function fragmentSource(kind, emitted) {
  const c = CALL[kind];
  return `#version 300 es
precision highp float;
precision highp int;
precision highp sampler2D;
precision highp samplerCube;
uniform sampler2D u_inputs;
uniform samplerCube u_cube;
uniform float u_log2TexelSolidAngle;
uniform float u_maxLod;
uniform int u_count;
out vec4 o;
${c.prelude || ""}
// ---- emitted file, verbatim ----
${emitted}
// ---- end of emitted file ----
vec4 field(int k) {
  ivec2 p = ivec2(gl_FragCoord.xy);
  return texelFetch(u_inputs, ivec2(p.x, p.y * ${c.fields} + k), 0);
}
void main() {
  ivec2 p = ivec2(gl_FragCoord.xy);
  if (p.y * ${ROW} + p.x >= u_count) { o = vec4(0.0); return; }
  ${c.body}
}
`;
}

function compile(gl, type, src) {
  const s = gl.createShader(type);
  gl.shaderSource(s, src);
  gl.compileShader(s);
  if (!gl.getShaderParameter(s, gl.COMPILE_STATUS)) throw new Error(`shader compile: ${gl.getShaderInfoLog(s)}`);
  return s;
}

async function fetchOk(url, how) {
  const r = await fetch(url);
  if (!r.ok) throw new Error(`${url}: HTTP ${r.status}`);
  return how === "json" ? r.json() : how === "text" ? r.text() : r.arrayBuffer();
}

async function main() {
  const { kind, glsl, cube, inputs } = params;
  if (!CALL[kind]) throw new Error(`unknown kind ${kind}`);
  const [emitted, grid, ktx] = await Promise.all([fetchOk(glsl, "text"), fetchOk(inputs, "json"), fetchOk(cube, "buf")]);
  const c = CALL[kind];
  if (grid.format !== "ibl-shader-check/1" || grid.kind !== kind || grid.fields !== c.fields || grid.data.length !== grid.count * c.fields * 4) {
    throw new Error(`${inputs}: not a ${kind} input grid of ${c.fields} fields`);
  }
  const cubeData = parseKtx2Cube(ktx, cube);

  const canvas = document.createElement("canvas");
  const gl = canvas.getContext("webgl2", { antialias: false });
  if (!gl) throw new Error("no WebGL2");
  // Float render targets (and RGBA16F color-renderable for generateMipmap).
  if (!gl.getExtension("EXT_color_buffer_float")) throw new Error("no EXT_color_buffer_float");
  if (!cubeData.half && !gl.getExtension("OES_texture_float_linear")) throw new Error("RGBA32F cube but no OES_texture_float_linear");

  // The cube, as the renderer is told to upload it. WebGL2 cube maps are always seamless.
  const tex = gl.createTexture();
  gl.activeTexture(gl.TEXTURE1);
  gl.bindTexture(gl.TEXTURE_CUBE_MAP, tex);
  gl.pixelStorei(gl.UNPACK_ALIGNMENT, 1);
  const [ifmt, type] = cubeData.half ? [gl.RGBA16F, gl.HALF_FLOAT] : [gl.RGBA32F, gl.FLOAT];
  // custom: every level of the chain, the lod clamped to its last level (TEXTURE_MAX_LEVEL,
  // else a chain that stops above 1x1 is incomplete). aniso: level 0 and generateMipmap, the
  // full box chain the snippet's header asks for.
  const box32 = kind !== "custom" && params.mips === "box32";
  const upload = kind === "custom" ? cubeData.levels : box32 ? boxChain(cubeData) : cubeData.levels.slice(0, 1);
  if (box32 && !gl.getExtension("OES_texture_float_linear")) throw new Error("no OES_texture_float_linear");
  upload.forEach((faces, l) => {
    const s = Math.max(1, cubeData.size >> l);
    const [fi, ty] = box32 ? [gl.RGBA32F, gl.FLOAT] : [ifmt, type];
    faces.forEach((data, f) => gl.texImage2D(gl.TEXTURE_CUBE_MAP_POSITIVE_X + f, l, fi, s, s, 0, gl.RGBA, ty, data));
  });
  let maxLod;
  if (box32) {
    maxLod = upload.length - 1;
  } else if (kind === "custom") {
    maxLod = upload.length - 1;
    gl.texParameteri(gl.TEXTURE_CUBE_MAP, gl.TEXTURE_MAX_LEVEL, maxLod);
  } else {
    gl.generateMipmap(gl.TEXTURE_CUBE_MAP);
    maxLod = Math.log2(cubeData.size);
  }
  gl.texParameteri(gl.TEXTURE_CUBE_MAP, gl.TEXTURE_MIN_FILTER, gl.LINEAR_MIPMAP_LINEAR);
  gl.texParameteri(gl.TEXTURE_CUBE_MAP, gl.TEXTURE_MAG_FILTER, gl.LINEAR);
  gl.texParameteri(gl.TEXTURE_CUBE_MAP, gl.TEXTURE_WRAP_S, gl.CLAMP_TO_EDGE);
  gl.texParameteri(gl.TEXTURE_CUBE_MAP, gl.TEXTURE_WRAP_T, gl.CLAMP_TO_EDGE);

  // The inputs: case i's field k at texel (i mod ROW, (i div ROW)·fields + k).
  const rows = Math.ceil(grid.count / ROW);
  const inData = new Float32Array(ROW * rows * c.fields * 4);
  for (let i = 0; i < grid.count; i++) {
    const x = i % ROW, y = Math.floor(i / ROW);
    for (let k = 0; k < c.fields; k++) {
      for (let ch = 0; ch < 4; ch++) inData[(((y * c.fields + k) * ROW) + x) * 4 + ch] = grid.data[(i * c.fields + k) * 4 + ch];
    }
  }
  const inTex = gl.createTexture();
  gl.activeTexture(gl.TEXTURE0);
  gl.bindTexture(gl.TEXTURE_2D, inTex);
  gl.texImage2D(gl.TEXTURE_2D, 0, gl.RGBA32F, ROW, rows * c.fields, 0, gl.RGBA, gl.FLOAT, inData);
  gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MIN_FILTER, gl.NEAREST);
  gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MAG_FILTER, gl.NEAREST);
  if (kind === "as") {
    const lut = grid.lut;
    if (!lut || lut.data.length !== lut.width * lut.height * 4) throw new Error(`${inputs}: as inputs without a width x height RGBA "lut"`);
    if (!gl.getExtension("OES_texture_float_linear")) throw new Error("no OES_texture_float_linear (the hv-lut table is RGBA32F, filtered)");
    const lutTex = gl.createTexture();
    gl.activeTexture(gl.TEXTURE2);
    gl.bindTexture(gl.TEXTURE_2D, lutTex);
    gl.texImage2D(gl.TEXTURE_2D, 0, gl.RGBA32F, lut.width, lut.height, 0, gl.RGBA, gl.FLOAT, Float32Array.from(lut.data));
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MIN_FILTER, gl.LINEAR);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MAG_FILTER, gl.LINEAR);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_WRAP_S, gl.CLAMP_TO_EDGE);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_WRAP_T, gl.CLAMP_TO_EDGE);
    // Unit 2 keeps the table: what follows binds on unit 0, as before.
    gl.activeTexture(gl.TEXTURE0);
  }

  const prog = gl.createProgram();
  gl.attachShader(prog, compile(gl, gl.VERTEX_SHADER, `#version 300 es
void main() { vec2 p = vec2(float((gl_VertexID & 1) << 2) - 1.0, float((gl_VertexID & 2) << 1) - 1.0); gl_Position = vec4(p, 0.0, 1.0); }`));
  gl.attachShader(prog, compile(gl, gl.FRAGMENT_SHADER, fragmentSource(kind, emitted)));
  gl.linkProgram(prog);
  if (!gl.getProgramParameter(prog, gl.LINK_STATUS)) throw new Error(`link: ${gl.getProgramInfoLog(prog)}`);
  gl.useProgram(prog);
  gl.uniform1i(gl.getUniformLocation(prog, "u_inputs"), 0);
  gl.uniform1i(gl.getUniformLocation(prog, "u_cube"), 1);
  if (kind === "as") gl.uniform1i(gl.getUniformLocation(prog, "u_lut"), 2);
  gl.uniform1i(gl.getUniformLocation(prog, "u_count"), grid.count);
  // log2 of the base texel's solid angle, 4 pi / (6 size^2), as the snippet's header defines it.
  gl.uniform1f(gl.getUniformLocation(prog, "u_log2TexelSolidAngle"), Math.log2((4 * Math.PI) / (6 * cubeData.size * cubeData.size)));
  gl.uniform1f(gl.getUniformLocation(prog, "u_maxLod"), maxLod);

  const target = gl.createTexture();
  gl.bindTexture(gl.TEXTURE_2D, target);
  gl.texStorage2D(gl.TEXTURE_2D, 1, gl.RGBA32F, ROW, rows);
  const fb = gl.createFramebuffer();
  gl.bindFramebuffer(gl.FRAMEBUFFER, fb);
  gl.framebufferTexture2D(gl.FRAMEBUFFER, gl.COLOR_ATTACHMENT0, gl.TEXTURE_2D, target, 0);
  if (gl.checkFramebufferStatus(gl.FRAMEBUFFER) !== gl.FRAMEBUFFER_COMPLETE) throw new Error("RGBA32F target incomplete");
  gl.activeTexture(gl.TEXTURE0);
  gl.bindTexture(gl.TEXTURE_2D, inTex);
  gl.viewport(0, 0, ROW, rows);
  gl.drawArrays(gl.TRIANGLES, 0, 3);
  const out = new Float32Array(ROW * rows * 4);
  gl.readPixels(0, 0, ROW, rows, gl.RGBA, gl.FLOAT, out);
  const err = gl.getError();
  if (err !== gl.NO_ERROR) throw new Error(`GL error 0x${err.toString(16)}`);
  window.__result = {
    format: "ibl-shader-check/1", kind, role: "outputs", fields: 1, count: grid.count,
    data: Array.from(out.subarray(0, grid.count * 4)),
    renderer: gl.getParameter(gl.RENDERER),
  };
}

main().catch((e) => {
  console.error(e && e.stack ? e.stack : String(e));
  window.__error = `${e && e.message ? e.message : e}`;
});
