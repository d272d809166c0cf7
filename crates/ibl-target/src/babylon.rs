//! Babylon.js `.env` files (BabylonJS/Babylon.js
//! `packages/dev/core/src/Misc/environmentTextureTools.ts`): 8 magic bytes, a NUL-terminated
//! JSON manifest (version 2: width, imageType, the irradiance polynomial, the specular mip
//! table and lodGenerationScale), then one RGBD PNG per level and face (level-major, faces
//! +X −X +Y −Y +Z −Z), a full chain down to 1×1.

use crate::lod::BABYLON_LOD_SCALE;
use crate::sh::prescaled_polynomial;
use crate::Orientation;
use ibl_core::cube::{solid_angle_table, texel_direction, CubeMips, Cubemap, Face};
use ibl_core::io::{self, WriteOptions};
use ibl_core::sh::{cosine_lobe_zonal, eval_basis3};
use ibl_core::{Error, Image, Result, Rgb};
use std::path::Path;

/// `MagicBytes` of environmentTextureTools.ts.
pub const MAGIC: [u8; 8] = [0x86, 0x16, 0x87, 0x96, 0xf6, 0xd6, 0x96, 0x36];

/// RGBD as Babylon's `toRGBD` encodes it (`Shaders/ShadersInclude/helperFunctions.fx`):
/// D = saturate(floor(max(255/max(rgb), 1))/255), rgb·D gamma-encoded with exponent 1/2.2,
/// alpha D. Decoded by `fromRGBD`: toLinearSpace(rgb)/a.
pub(crate) fn rgbd(c: Rgb) -> [f32; 4] {
    let m = c[0].max(c[1]).max(c[2]).max(1e-6);
    let d = ((255.0 / m).max(1.0).floor() / 255.0).clamp(0.0, 1.0);
    let g = |v: f32| (v.max(0.0) * d).powf(1.0 / 2.2).clamp(0.0, 1.0);
    [g(c[0]), g(c[1]), g(c[2]), d]
}

#[cfg(test)]
/// Babylon's `fromRGBD` of 8-bit samples.
pub(crate) fn from_rgbd(p: [u8; 4]) -> Rgb {
    let a = p[3] as f32 / 255.0;
    let l = |v: u8| (v as f32 / 255.0).powf(2.2) / a.max(1e-6);
    [l(p[0]), l(p[1]), l(p[2])]
}

/// Our 3-band irradiance coefficients (E/π, our basis and frame) of a cube: the radiance
/// projection Σ L·Y·Ω over its texels times Â_l/π (Ramamoorthi & Hanrahan 2001, eq. 7).
pub fn irradiance_sh(cube: &Cubemap) -> Vec<[f32; 3]> {
    let n = cube.size;
    let sa = solid_angle_table(n);
    let mut acc = [[0.0f64; 3]; 9];
    for face in Face::ALL {
        for j in 0..n {
            for i in 0..n {
                let y = eval_basis3(texel_direction(face, i, j, n).normalize());
                let c = cube.texel(face, i, j);
                let w = sa[j * n + i] as f64;
                for k in 0..9 {
                    for ch in 0..3 {
                        acc[k][ch] += c[ch] as f64 * y[k] as f64 * w;
                    }
                }
            }
        }
    }
    (0..9)
        .map(|k| {
            let l = if k == 0 {
                0
            } else if k < 4 {
                1
            } else {
                2
            };
            let f = cosine_lobe_zonal(l) / std::f64::consts::PI;
            acc[k].map(|v| (v * f) as f32)
        })
        .collect()
}

/// The manifest's `irradiance`: Babylon's SphericalPolynomial (x, y, z, xx, yy, zz, yz, zx, xy)
/// of E/π in the file's frame (`SphericalPolynomial.updateFromHarmonics` folds Â_l/π in, so
/// the polynomial is what the shader's `computeEnvironmentIrradiance` evaluates); the
/// constant term is spread over xx + yy + zz (= 1 on the sphere).
pub fn polynomial(irradiance: &[[f32; 3]], o: Orientation) -> serde_json::Value {
    let p = prescaled_polynomial(irradiance, o);
    let v = |f: &dyn Fn(usize) -> f64| serde_json::json!([f(0), f(1), f(2)]);
    serde_json::json!({
        "x": v(&|c| p[3][c]),
        "y": v(&|c| p[1][c]),
        "z": v(&|c| p[2][c]),
        "xx": v(&|c| p[0][c] - p[6][c] + p[8][c]),
        "yy": v(&|c| p[0][c] - p[6][c] - p[8][c]),
        "zz": v(&|c| p[0][c] + 2.0 * p[6][c]),
        "yz": v(&|c| p[5][c]),
        "zx": v(&|c| p[7][c]),
        "xy": v(&|c| p[4][c]),
    })
}

/// Encodes `chain` (already in the file's orientation, a full chain of a power-of-two base
/// down to 1×1) and the irradiance (our coefficients, turned by `o` into the file's frame) as
/// a `.env`. `path` names the file in errors.
pub fn encode_env(
    path: &Path,
    chain: &CubeMips,
    irradiance: &[[f32; 3]],
    o: Orientation,
) -> Result<Vec<u8>> {
    let width = chain.levels[0].size;
    let count = width.trailing_zeros() as usize + 1;
    if !width.is_power_of_two() || chain.levels.len() != count {
        return Err(Error::param(format!(
            "a Babylon .env needs a power-of-two base and its full chain down to 1×1 ({} levels for {width}², got {} levels)",
            count,
            chain.levels.len()
        )));
    }
    let png_opts = WriteOptions {
        png_bits: 8,
        ..Default::default()
    };
    let png_path = path.with_extension("png");
    let mut blobs = Vec::new();
    for (l, level) in chain.levels.iter().enumerate() {
        if level.size != width >> l {
            return Err(Error::param(format!(
                "level {l} is {}², a Babylon .env needs {}²",
                level.size,
                width >> l
            )));
        }
        for f in &level.faces {
            let data = f
                .data
                .chunks_exact(3)
                .flat_map(|c| rgbd([c[0], c[1], c[2]]))
                .collect();
            let img = Image::from_data(level.size, level.size, 4, data)?;
            blobs.push(io::encode_image(&png_path, &img, &png_opts)?);
        }
    }
    let mut position = 0usize;
    let mipmaps: Vec<serde_json::Value> = blobs
        .iter()
        .map(|b| {
            let m = serde_json::json!({ "length": b.len(), "position": position });
            position += b.len();
            m
        })
        .collect();
    let manifest = serde_json::json!({
        "version": 2,
        "width": width,
        "imageType": "image/png",
        "irradiance": polynomial(irradiance, o),
        // The f32 scale written as the decimal Babylon uses (0.8, not 0.800000011920929).
        "specular": {
            "mipmaps": mipmaps,
            "lodGenerationScale": (BABYLON_LOD_SCALE as f64 * 1e6).round() / 1e6,
        },
    });
    let mut out = MAGIC.to_vec();
    out.extend_from_slice(manifest.to_string().as_bytes());
    out.push(0);
    for b in blobs {
        out.extend_from_slice(&b);
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use ibl_core::sh::eval_rgb;

    #[test]
    fn rgbd_round_trips_within_8_bit_steps() {
        for c in [
            [0.01f32, 0.02, 0.005],
            [1.0, 0.5, 0.25],
            [40.0, 3.0, 0.1],
            [200.0, 250.0, 255.0],
        ] {
            let e = rgbd(c);
            let q = e.map(|v| (v * 255.0).round() as u8);
            let back = from_rgbd(q);
            let m = c[0].max(c[1]).max(c[2]);
            for k in 0..3 {
                // 8-bit gamma steps: about 1% of the largest channel.
                assert!(
                    (back[k] - c[k]).abs() <= 0.012 * m + 1e-4,
                    "{c:?} → {back:?}"
                );
            }
        }
    }

    #[test]
    fn polynomial_evaluates_to_our_irradiance_in_the_file_frame() {
        let irr: Vec<[f32; 3]> = (0..9)
            .map(|i| [0.5 - 0.04 * i as f32, 0.1 * (i as f32 - 4.0), 0.3])
            .collect();
        let o = Orientation::FLIP_Z;
        let j = polynomial(&irr, o);
        let g = |k: &str, c: usize| j[k][c].as_f64().unwrap();
        for t in [
            glam::Vec3::new(0.3, 0.8, -0.52),
            glam::Vec3::new(-0.6, -0.2, 0.77),
        ] {
            let t = t.normalize();
            let (x, y, z) = (t.x as f64, t.y as f64, t.z as f64);
            let ours = eval_rgb(&irr, o.ours_from_file(t));
            for c in 0..3 {
                let e = g("x", c) * x
                    + g("y", c) * y
                    + g("z", c) * z
                    + g("xx", c) * x * x
                    + g("yy", c) * y * y
                    + g("zz", c) * z * z
                    + g("yz", c) * y * z
                    + g("zx", c) * z * x
                    + g("xy", c) * x * y;
                assert!((e - ours[c] as f64).abs() < 1e-5);
            }
        }
    }

    #[test]
    fn env_layout_and_refusals() {
        let chain = CubeMips::build(Cubemap::constant(4, [2.0, 1.0, 0.5]), 1);
        let irr = irradiance_sh(&chain.levels[0]);
        // A constant environment: E/π = the constant (only the DC coefficient).
        assert!((eval_rgb(&irr, glam::Vec3::Y)[0] - 2.0).abs() < 1e-4);
        let b = encode_env(Path::new("e.env"), &chain, &irr, Orientation::FLIP_Z).unwrap();
        assert_eq!(&b[..8], &MAGIC);
        let end = b[8..].iter().position(|&c| c == 0).unwrap() + 8;
        let m: serde_json::Value = serde_json::from_slice(&b[8..end]).unwrap();
        assert_eq!(m["width"], 4);
        let mips = m["specular"]["mipmaps"].as_array().unwrap();
        assert_eq!(mips.len(), 6 * 3);
        let last = &mips[17];
        assert_eq!(
            end + 1
                + (last["position"].as_u64().unwrap() + last["length"].as_u64().unwrap()) as usize,
            b.len()
        );
        assert_eq!(&b[end + 1..end + 5], b"\x89PNG");
        let short = CubeMips {
            levels: chain.levels[..2].to_vec(),
        };
        assert!(encode_env(Path::new("e.env"), &short, &irr, Orientation::FLIP_Z).is_err());
    }
}
