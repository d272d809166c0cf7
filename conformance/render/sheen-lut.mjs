//! Writes the placeholder sheen albedo LUT the glTF Sample Renderer's loadEnvironment asks for
//! (its app ships assets/images/lut_sheen_E.png; the npm package does not): 32×32 black, read
//! only by KHR_materials_sheen materials, which the sphere-rows scene has none of.
//! usage: node sheen-lut.mjs OUT.png
import { writePng } from "./lib.mjs";

writePng(process.argv[2], 32, 32, new Float32Array(32 * 32 * 3));
