//! Babylon.js `.env` files (BabylonJS/Babylon.js
//! `packages/dev/core/src/Misc/environmentTextureTools.ts`): 8 magic bytes, a NUL-terminated
//! JSON manifest (version 2: width, imageType, the irradiance polynomial, the specular mip
//! table and lodGenerationScale), then one RGBD PNG per level and face (level-major, faces
//! +X −X +Y −Y +Z −Z), a full chain down to 1×1.
//!
//! Three things Babylon expects that its loader does not check, each found by rendering our file
//! and Babylon's own `.env` of the same panorama through Babylon itself (conformance/render):
//! faces stored bottom row first ([`encode_env`]), the world turned as Babylon's own panorama
//! route turns it ([`ORIENTATION`]), and the irradiance polynomial in the form Babylon's
//! `SphericalPolynomial.updateFromHarmonics` makes, which its shader turns back into harmonics
//! ([`polynomial`]).

use crate::lod::BABYLON_LOD_SCALE;
use crate::sh::prescaled_polynomial;
use crate::Orientation;
use ibl_core::cube::{solid_angle_table, texel_direction, CubeMips, Cubemap, Face};
use ibl_core::io::{self, WriteOptions};
use ibl_core::sh::{cosine_lobe_zonal, eval_basis3};
use ibl_core::{Error, Image, Result, Rgb};
use std::path::Path;

/// The frame of a Babylon `.env`: the file's direction t holds our direction (t.z, t.y, t.x).
/// Babylon's own route from a panorama (`HDRCubeTexture` →
/// `Misc/HighDynamicRange/panoramaToCubemap.ts` → `EnvironmentTextureTools.CreateEnvTextureAsync`)
/// and ours from the same panorama, compared face by face (conformance/render/envfaces.mjs):
/// Babylon's +X face is our −Z face after z is negated for the left-handed scene, i.e. the
/// left-handed flip plus a 90° turn about +Y. A z flip alone (what we wrote before) showed the
/// world turned 90° against Babylon's own bake; a Babylon user swapping Babylon's `.env` for
/// ours now sees the same world.
pub const ORIENTATION: Orientation = Orientation {
    ours_from_file: [[0, 0, 1], [0, 1, 0], [1, 0, 0]],
};

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

/// Babylon's factors from the plain E/π polynomial to the one its files hold, per band: 1, 2/3,
/// 1/4. BabylonJS/Babylon.js `packages/dev/core/src/Maths/sphericalPolynomial.ts`:
/// `CubeMapToSphericalPolynomialTools` projects radiance S_lm, `convertIncidentRadianceToIrradiance`
/// multiplies by Â_l (π, 2π/3, π/4) and `convertIrradianceToLambertianRadiance` by 1/π; then
/// `updateFromHarmonics` multiplies again by the constants 1.02333 = (2π/3)·√(3/4π) and
/// 0.858086 = (π/4)·√(15/4π) (and 0.886277 ≈ π·√(1/4π) for band 0) before its final 1/π: Â_l/π is
/// applied twice to bands 1 and 2. The shader never evaluates that polynomial: the material
/// (`PBRBaseMaterial`, `SPHERICAL_HARMONICS`) takes `preScaledHarmonics`, i.e.
/// `SphericalHarmonics.FromPolynomial` (the exact inverse, constants 0.977204 = 1/1.02333,
/// 1.16538 = 1/0.858086) times the basis constants (`preScaleForRendering`), evaluated by
/// `Shaders/ShadersInclude/harmonicsFunctions.fx` `computeEnvironmentIrradiance` — which is
/// E/π again only if the polynomial carried the extra Â_l/π. A plain E/π polynomial rendered
/// band 1 ×1.5 and band 2 ×4 (black bands and 20–39% dark diffuse in Babylon).
/// Erratum (Babylon): 0.886277 should be π·√(1/4π) = 0.886227 (5.6e-5 relative, cancelled by
/// FromPolynomial's 0.376127 = 1/(3·0.886277)).
const BAND_FACTOR: [f64; 3] = [1.0, 2.0 / 3.0, 0.25];

/// The manifest's `irradiance`: Babylon's SphericalPolynomial (x, y, z, xx, yy, zz, yz, zx, xy)
/// of E/π in the file's frame, scaled per band by [`BAND_FACTOR`] as Babylon's own files hold it
/// (the shader turns it back into E/π); the constant term is spread over xx + yy + zz (= 1 on
/// the sphere).
pub fn polynomial(irradiance: &[[f32; 3]], o: Orientation) -> serde_json::Value {
    let mut p = prescaled_polynomial(irradiance, o);
    for (i, c) in p.iter_mut().enumerate() {
        let band = match i {
            0 => 0,
            1..=3 => 1,
            _ => 2,
        };
        c.iter_mut().for_each(|v| *v *= BAND_FACTOR[band]);
    }
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
            // Bottom row first: Babylon's writer PNG-encodes `readPixels` of each face (GL rows,
            // t = 1 first) and its loader uploads the PNG as is (`_UploadLevelsAsync`,
            // invertY false on the float path) — environmentTextureTools.ts.
            let n = level.size;
            let data = (0..n)
                .rev()
                .flat_map(|j| f.data[j * n * 3..(j + 1) * n * 3].chunks_exact(3))
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

    /// Babylon's shader on a manifest polynomial, transcribed from BabylonJS/Babylon.js
    /// `Maths/sphericalPolynomial.ts` (`SphericalHarmonics.FromPolynomial`,
    /// `preScaleForRendering`) and `Shaders/ShadersInclude/harmonicsFunctions.fx`
    /// (`computeEnvironmentIrradiance`, SPHERICAL_HARMONICS): an independent model of what
    /// Babylon renders, with Babylon's own rounded constants.
    fn babylon_shader(j: &serde_json::Value, t: glam::Vec3, c: usize) -> f64 {
        use std::f64::consts::PI;
        let g = |k: &str| j[k][c].as_f64().unwrap();
        let (xx, yy, zz) = (g("xx"), g("yy"), g("zz"));
        let l00 = PI * (0.376127 * xx + 0.376127 * yy + 0.376126 * zz);
        let l1_1 = -PI * 0.977204 * g("y");
        let l10 = PI * 0.977204 * g("z");
        let l11 = -PI * 0.977204 * g("x");
        let l2_2 = PI * 1.16538 * g("xy");
        let l2_1 = -PI * 1.16538 * g("yz");
        let l20 = PI * (1.34567 * zz - 0.672834 * xx - 0.672834 * yy);
        let l21 = -PI * 1.16538 * g("zx");
        let l22 = PI * (1.16538 * xx - 1.16538 * yy);
        let k = |a: f64| a.sqrt();
        let (c0, c1, c2, c20, c22) = (
            k(1.0 / (4.0 * PI)),
            k(3.0 / (4.0 * PI)),
            k(15.0 / (4.0 * PI)),
            k(5.0 / (16.0 * PI)),
            k(15.0 / (16.0 * PI)),
        );
        let (x, y, z) = (t.x as f64, t.y as f64, t.z as f64);
        c0 * l00 - c1 * l1_1 * y + c1 * l10 * z - c1 * l11 * x + c2 * l2_2 * y * x
            - c2 * l2_1 * y * z
            + c20 * l20 * (3.0 * z * z - 1.0)
            - c2 * l21 * z * x
            + c22 * l22 * (x * x - y * y)
    }

    #[test]
    fn babylons_shader_renders_our_irradiance_from_the_manifest() {
        let irr: Vec<[f32; 3]> = (0..9)
            .map(|i| [0.5 - 0.04 * i as f32, 0.1 * (i as f32 - 4.0), 0.3])
            .collect();
        let o = ORIENTATION;
        let j = polynomial(&irr, o);
        for t in [
            glam::Vec3::new(0.3, 0.8, -0.52),
            glam::Vec3::new(-0.6, -0.2, 0.77),
            glam::Vec3::new(0.0, -1.0, 0.0),
        ] {
            let t = t.normalize();
            let ours = eval_rgb(&irr, o.ours_from_file(t));
            for c in 0..3 {
                let e = babylon_shader(&j, t, c);
                // Babylon's 6-digit constants: about 1e-5 relative.
                assert!(
                    (e - ours[c] as f64).abs() < 1e-4 * (1.0 + ours[c].abs() as f64),
                    "{t:?} {c}: babylon {e} ours {}",
                    ours[c]
                );
            }
        }
    }

    #[test]
    fn faces_are_stored_bottom_row_first() {
        // Level 0 of a 2×2 cube whose top row is bright: the first PNG row is the dim one.
        let mut base = Cubemap::constant(2, [1.0, 1.0, 1.0]);
        for f in base.faces.iter_mut() {
            f.data[..6].copy_from_slice(&[4.0; 6]);
        }
        let chain = CubeMips::build(base, 1);
        let b = encode_env(Path::new("e.env"), &chain, &[[0.0; 3]; 9], ORIENTATION).unwrap();
        let end = b[8..].iter().position(|&c| c == 0).unwrap() + 8;
        let m: serde_json::Value = serde_json::from_slice(&b[8..end]).unwrap();
        let len = m["specular"]["mipmaps"][0]["length"].as_u64().unwrap() as usize;
        let img = ibl_core::io::decode_image(
            Path::new("f.png"),
            &b[end + 1..end + 1 + len],
            ibl_core::io::ColorSpace::Linear,
        )
        .unwrap();
        let px = |row: usize| {
            from_rgbd(std::array::from_fn(|k| {
                (img.data[row * 2 * 4 + k] * 255.0).round() as u8
            }))
        };
        assert!(
            (px(0)[0] - 1.0).abs() < 0.02 && (px(1)[0] - 4.0).abs() < 0.08,
            "{:?} {:?}",
            px(0),
            px(1)
        );
    }

    #[test]
    fn env_layout_and_refusals() {
        let chain = CubeMips::build(Cubemap::constant(4, [2.0, 1.0, 0.5]), 1);
        let irr = irradiance_sh(&chain.levels[0]);
        // A constant environment: E/π = the constant (only the DC coefficient).
        assert!((eval_rgb(&irr, glam::Vec3::Y)[0] - 2.0).abs() < 1e-4);
        let b = encode_env(Path::new("e.env"), &chain, &irr, ORIENTATION).unwrap();
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
        assert!(encode_env(Path::new("e.env"), &short, &irr, ORIENTATION).is_err());
    }
}
