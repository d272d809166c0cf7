//! Writes the sphere-rows v1 scene (scene-contract) as a binary glTF: one UV sphere mesh of
//! radius 0.9 (smooth normals) referenced by 12 nodes, each with its own metallic-roughness
//! material (baseColor 1, metallic 1 top row / 0 bottom row, roughness i/5). For engines whose
//! web build loads geometry only through glTF (Filament's npm build ships no material
//! compiler: gltfio's ubershaders are its materials; the glTF Sample Renderer).
//! With --camera D, also the contract's camera as a glTF orthographic camera (camera 0) at
//! (0, 0, D) looking down −z (xmag 6, ymag 2), for viewers that draw through a glTF camera (the
//! Sample Renderer): D large, because its shader takes V = normalize(camera − position) even
//! for an orthographic camera, and the contract's V is (0, 0, 1).
//! usage: node spheres-glb.mjs [--camera D] OUT.glb
import fs from "node:fs";
import { COLS, ROUGH } from "./lib.mjs";

const args = process.argv.slice(2);
const camD = args[0] === "--camera" ? +args[1] : null;
const out = camD === null ? args[0] : args[2];
const R = 0.9, SEG = 160, RINGS = 80;
const pos = [], nrm = [], idx = [];
for (let j = 0; j <= RINGS; j++) {
  const th = (Math.PI * j) / RINGS;
  for (let i = 0; i <= SEG; i++) {
    const ph = (2 * Math.PI * i) / SEG;
    const n = [Math.sin(th) * Math.cos(ph), Math.cos(th), -Math.sin(th) * Math.sin(ph)];
    nrm.push(...n);
    pos.push(...n.map((v) => v * R));
  }
}
for (let j = 0; j < RINGS; j++) {
  for (let i = 0; i < SEG; i++) {
    const a = j * (SEG + 1) + i, b = a + SEG + 1;
    idx.push(a, b, a + 1, a + 1, b, b + 1); // counter-clockwise seen from outside
  }
}
const P = new Float32Array(pos), N = new Float32Array(nrm), I = new Uint32Array(idx);
const bin = Buffer.concat([Buffer.from(P.buffer), Buffer.from(N.buffer), Buffer.from(I.buffer)]);
const nodes = [], meshes = [], materials = [];
[1, -1].forEach((cy, row) => {
  COLS.forEach((cx, i) => {
    const k = materials.length;
    materials.push({ name: `m${k}`, pbrMetallicRoughness: { baseColorFactor: [1, 1, 1, 1], metallicFactor: row === 0 ? 1 : 0, roughnessFactor: ROUGH[i] } });
    meshes.push({ primitives: [{ attributes: { POSITION: 0, NORMAL: 1 }, indices: 2, material: k }] });
    nodes.push({ name: `sphere${k}`, mesh: k, translation: [cx, cy, 0] });
  });
});
const gltf = {
  asset: { version: "2.0", generator: "ibl-bake conformance/render spheres-glb.mjs" },
  scene: 0,
  scenes: [{ nodes: nodes.map((_, k) => k) }],
  nodes, meshes, materials,
  buffers: [{ byteLength: bin.length }],
  bufferViews: [
    { buffer: 0, byteOffset: 0, byteLength: P.byteLength, target: 34962 },
    { buffer: 0, byteOffset: P.byteLength, byteLength: N.byteLength, target: 34962 },
    { buffer: 0, byteOffset: P.byteLength + N.byteLength, byteLength: I.byteLength, target: 34963 },
  ],
  accessors: [
    { bufferView: 0, componentType: 5126, count: P.length / 3, type: "VEC3", min: [-R, -R, -R], max: [R, R, R] },
    { bufferView: 1, componentType: 5126, count: N.length / 3, type: "VEC3" },
    { bufferView: 2, componentType: 5125, count: I.length, type: "SCALAR" },
  ],
};
if (camD !== null) {
  gltf.cameras = [{ type: "orthographic", orthographic: { xmag: 6, ymag: 2, znear: camD - 10, zfar: camD + 10 } }];
  gltf.nodes.push({ name: "camera", camera: 0, translation: [0, 0, camD] });
  gltf.scenes[0].nodes.push(gltf.nodes.length - 1);
}
let json = Buffer.from(JSON.stringify(gltf));
json = Buffer.concat([json, Buffer.alloc((4 - (json.length % 4)) % 4, 0x20)]);
const head = Buffer.alloc(12), jh = Buffer.alloc(8), bh = Buffer.alloc(8);
head.write("glTF", 0, "ascii");
head.writeUInt32LE(2, 4);
head.writeUInt32LE(12 + 8 + json.length + 8 + bin.length, 8);
jh.writeUInt32LE(json.length, 0);
jh.write("JSON", 4, "ascii");
bh.writeUInt32LE(bin.length, 0);
bh.write("BIN\0", 4, "ascii");
fs.writeFileSync(out, Buffer.concat([head, jh, json, bh, bin]));
