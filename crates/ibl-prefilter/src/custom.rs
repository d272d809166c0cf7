//! The `custom` target's lookup (`prefilter --target custom`, docs/CUSTOM_LOOKUP.md), defined
//! once: [`CustomLookup`] holds its few constants, computes the lod exactly as the shaders do
//! (`ibl_target::lod::custom_lod`, the same f32 expression), reads a chain on the CPU as a
//! trilinear sampler does, and emits the GLSL / HLSL / WGSL function and the KTX2 key/value
//! data from those same constants.
//!
//! lod = clamp(s·log2(1 + r²/α₀), 0, N − 1), s = (N − 1)/log2(1 + 1/α₀): level l holds
//! α_l = α₀((1 + 1/α₀)^(l/(N−1)) − 1), geometric in α above α₀ (a lobe's width, hence the texels
//! it needs, goes as α while the level sizes halve) and linear in α below it down to the mirror.
//! One trilinear tap: blending levels linearly keeps a sun's power at every roughness (each
//! level keeps it, `crate::fit::Power::Kept`), which blending in log radiance does not: midway
//! between two Gaussian lobes of variance ratio 4 (α ratio 2) the geometric mean holds
//! σ_h²/σ_g² = 1.6/2, 20% less power.

use glam::Vec3;
use ibl_core::bordered::BorderedMips;
use ibl_core::Rgb;
use ibl_target::lod::{custom_lod, custom_scale};
use serde::Serialize;

/// The lookup formula as the sidecar and the KTX2 metadata state it.
pub const FORMULA: &str =
    "lod = clamp(scale * log2(1 + r*r*inv_alpha0), 0, max_lod); one trilinear tap at lod";

/// Names of the emitted shader files, written beside the chain.
pub const SHADER_FILES: [&str; 3] = ["lookup.glsl", "lookup.hlsl", "lookup.wgsl"];

/// The custom lookup's constants for one chain (`prefilter.json` `"custom_lookup"`).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct CustomLookup {
    /// The formula (see [`FORMULA`]).
    pub formula: &'static str,
    /// α₀, the knee between linear and geometric spacing in α.
    pub alpha0: f32,
    /// s = (N − 1)/log2(1 + 1/α₀).
    pub scale: f32,
    /// 1/α₀ as the shader multiplies by it.
    pub inv_alpha0: f32,
    /// N − 1, the last level (the lod is clamped to it).
    pub max_lod: f32,
    /// Levels N of the chain.
    pub levels: usize,
    /// Face size of level 0.
    pub size: usize,
    /// Texture taps per lookup (one trilinear tap).
    pub taps: usize,
}

impl CustomLookup {
    /// The lookup of a chain of `levels` levels of base `size` with knee `alpha0`.
    pub fn new(alpha0: f32, levels: usize, size: usize) -> Self {
        CustomLookup {
            formula: FORMULA,
            alpha0,
            scale: custom_scale(alpha0, levels),
            inv_alpha0: 1.0 / alpha0,
            max_lod: levels.saturating_sub(1) as f32,
            levels,
            size,
            taps: 1,
        }
    }

    /// The lod the shader samples for perceptual roughness `r`.
    pub fn lod(&self, r: f32) -> f32 {
        custom_lod(r, self.scale, self.inv_alpha0, self.max_lod)
    }

    /// The CPU emulation of the shader: one trilinear tap (seamless bilinear within a level,
    /// linear between the two levels around the lod) of `chain` in direction `d`.
    pub fn read(&self, chain: &BorderedMips, d: Vec3, r: f32) -> Rgb {
        chain.sample(d, self.lod(r))
    }

    /// Shortest decimal that parses back to the same f32 (Rust's `{:?}`), always with a point
    /// or an exponent so every shading language reads it as a float.
    fn lit(x: f32) -> String {
        let s = format!("{x:?}");
        if s.contains('.') || s.contains('e') {
            s
        } else {
            format!("{s}.0")
        }
    }

    fn header(&self, comment: &str) -> String {
        format!(
            "{comment} ibl custom lookup (prefilter --target custom; docs/CUSTOM_LOOKUP.md), generated for\n\
             {comment} this chain: {n} levels of {s}x{s}, alpha0 = {a0}.\n\
             {comment} {FORMULA}.\n\
             {comment} The sampler's mipmap filter must be linear (trilinear).\n",
            n = self.levels,
            s = self.size,
            a0 = Self::lit(self.alpha0),
        )
    }

    /// The GLSL function `iblCustomSpecular(samplerCube, vec3 R, float roughness)`.
    pub fn glsl(&self) -> String {
        format!(
            "{h}const float IBL_LOOKUP_SCALE = {s};\n\
             const float IBL_LOOKUP_INV_ALPHA0 = {i};\n\
             const float IBL_LOOKUP_MAX_LOD = {m};\n\n\
             vec3 iblCustomSpecular(samplerCube chain, vec3 R, float roughness) {{\n\
             \x20   float r = clamp(roughness, 0.0, 1.0);\n\
             \x20   float lod = clamp(IBL_LOOKUP_SCALE * log2(1.0 + r * r * IBL_LOOKUP_INV_ALPHA0), 0.0, IBL_LOOKUP_MAX_LOD);\n\
             \x20   return textureLod(chain, R, lod).rgb;\n\
             }}\n",
            h = self.header("//"),
            s = Self::lit(self.scale),
            i = Self::lit(self.inv_alpha0),
            m = Self::lit(self.max_lod),
        )
    }

    /// The HLSL function `iblCustomSpecular(TextureCube, SamplerState, float3 R, float roughness)`.
    pub fn hlsl(&self) -> String {
        format!(
            "{h}static const float IBL_LOOKUP_SCALE = {s};\n\
             static const float IBL_LOOKUP_INV_ALPHA0 = {i};\n\
             static const float IBL_LOOKUP_MAX_LOD = {m};\n\n\
             float3 iblCustomSpecular(TextureCube chain, SamplerState trilinear, float3 R, float roughness) {{\n\
             \x20   float r = clamp(roughness, 0.0, 1.0);\n\
             \x20   float lod = clamp(IBL_LOOKUP_SCALE * log2(1.0 + r * r * IBL_LOOKUP_INV_ALPHA0), 0.0, IBL_LOOKUP_MAX_LOD);\n\
             \x20   return chain.SampleLevel(trilinear, R, lod).rgb;\n\
             }}\n",
            h = self.header("//"),
            s = Self::lit(self.scale),
            i = Self::lit(self.inv_alpha0),
            m = Self::lit(self.max_lod),
        )
    }

    /// The WGSL function `ibl_custom_specular(texture_cube<f32>, sampler, dir, roughness)`.
    pub fn wgsl(&self) -> String {
        format!(
            "{h}const IBL_LOOKUP_SCALE: f32 = {s};\n\
             const IBL_LOOKUP_INV_ALPHA0: f32 = {i};\n\
             const IBL_LOOKUP_MAX_LOD: f32 = {m};\n\n\
             fn ibl_custom_specular(chain: texture_cube<f32>, trilinear: sampler, dir: vec3<f32>, roughness: f32) -> vec3<f32> {{\n\
             \x20   let r = clamp(roughness, 0.0, 1.0);\n\
             \x20   let lod = clamp(IBL_LOOKUP_SCALE * log2(1.0 + r * r * IBL_LOOKUP_INV_ALPHA0), 0.0, IBL_LOOKUP_MAX_LOD);\n\
             \x20   return textureSampleLevel(chain, trilinear, dir, lod).rgb;\n\
             }}\n",
            h = self.header("//"),
            s = Self::lit(self.scale),
            i = Self::lit(self.inv_alpha0),
            m = Self::lit(self.max_lod),
        )
    }

    /// The three shader files ([`SHADER_FILES`]) and their text.
    pub fn shaders(&self) -> [(&'static str, String); 3] {
        [
            (SHADER_FILES[0], self.glsl()),
            (SHADER_FILES[1], self.hlsl()),
            (SHADER_FILES[2], self.wgsl()),
        ]
    }

    /// KTX2 key/value data: the formula and its constants as NUL-terminated UTF-8 strings
    /// (floats in the shortest form that parses back to the same f32), and the roughness of
    /// every level.
    pub fn metadata(&self, level_roughness: &[f32]) -> Vec<(String, Vec<u8>)> {
        let rs: Vec<String> = level_roughness.iter().map(|&r| Self::lit(r)).collect();
        [
            ("ibl.lookup", FORMULA.to_string()),
            ("ibl.lookup.scale", Self::lit(self.scale)),
            ("ibl.lookup.inv_alpha0", Self::lit(self.inv_alpha0)),
            ("ibl.lookup.max_lod", Self::lit(self.max_lod)),
            ("ibl.lookup.alpha0", Self::lit(self.alpha0)),
            ("ibl.level_roughness", rs.join(",")),
        ]
        .into_iter()
        .map(|(k, v)| {
            let mut b = v.into_bytes();
            b.push(0);
            (k.to_string(), b)
        })
        .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ibl_target::LodMapping;

    /// The constants a shader text declares, parsed back (independently of the emitter: the
    /// name, then the first float literal after it on its line).
    fn constants(text: &str) -> [f32; 3] {
        [
            "IBL_LOOKUP_SCALE",
            "IBL_LOOKUP_INV_ALPHA0",
            "IBL_LOOKUP_MAX_LOD",
        ]
        .map(|name| {
            let line = text
                .lines()
                .find(|l| l.contains(&format!("{name}:")) || l.contains(&format!("{name} =")))
                .unwrap_or_else(|| panic!("{name} not declared"));
            let v = line.split('=').nth(1).unwrap().trim().trim_end_matches(';');
            v.parse::<f32>().unwrap()
        })
    }

    /// An independent lod: the formula of docs/CUSTOM_LOOKUP.md from the parsed constants,
    /// in f64.
    fn lod_by_hand(c: [f32; 3], r: f64) -> f64 {
        let r = r.clamp(0.0, 1.0);
        (c[0] as f64 * (1.0 + r * r * c[1] as f64).log2()).clamp(0.0, c[2] as f64)
    }

    #[test]
    fn emitted_shaders_parse_back_to_the_same_constants_and_lod() {
        for (a0, n, size) in [(0.02f32, 6usize, 256usize), (0.003, 7, 256), (0.5, 5, 64)] {
            let lk = CustomLookup::new(a0, n, size);
            let m = LodMapping::Custom { alpha0: a0 };
            for (name, text) in lk.shaders() {
                let c = constants(&text);
                assert_eq!(c, [lk.scale, lk.inv_alpha0, lk.max_lod], "{name}");
                // One tap, and the formula's text is the one documented.
                let taps = [" textureLod(", ".SampleLevel(", " textureSampleLevel("]
                    .iter()
                    .map(|t| text.matches(t).count())
                    .sum::<usize>();
                assert_eq!(taps, 1, "{name}");
                assert!(text.contains("log2(1.0 + r * r * IBL_LOOKUP_INV_ALPHA0)"));
                for k in 0..=64 {
                    let r = k as f32 / 64.0;
                    let by_hand = lod_by_hand(c, r as f64);
                    // The emulation, the engine-mapping view and the hand formula agree.
                    assert!((lk.lod(r) as f64 - by_hand).abs() < 1e-5, "{name} r {r}");
                    assert_eq!(lk.lod(r), m.lod(r, n, size), "r {r}");
                }
            }
            // Level l's roughness is where the lookup lands.
            for l in 0..n {
                let r = m.level_roughness(l, n, size);
                assert!((lk.lod(r) - l as f32).abs() < 2e-4, "a0 {a0} l {l}");
            }
            // The metadata carries the same constants.
            let md = lk.metadata(&m.level_roughnesses(n, size));
            let get = |k: &str| {
                let v = &md.iter().find(|e| e.0 == k).unwrap().1;
                assert_eq!(v.last(), Some(&0));
                String::from_utf8(v[..v.len() - 1].to_vec()).unwrap()
            };
            assert_eq!(get("ibl.lookup.scale").parse::<f32>().unwrap(), lk.scale);
            assert_eq!(
                get("ibl.lookup.inv_alpha0").parse::<f32>().unwrap(),
                lk.inv_alpha0
            );
            assert_eq!(
                get("ibl.lookup.max_lod").parse::<f32>().unwrap(),
                lk.max_lod
            );
            assert_eq!(get("ibl.level_roughness").split(',').count(), n);
        }
    }

    use crate::bake::{bake_chain, Params};
    use crate::kernel::SourceTexels;
    use crate::runtime::{abs_rel_stats, probe_directions, roughness_grid, Reference};
    use ibl_core::cube::{texel_direction, texel_solid_angle, Cubemap, Face};
    use ibl_core::envmap::Environment;
    use ibl_core::progress::NoProgress;
    use ibl_target::Target;

    /// A sky with a small bright patch, a gradient and a dark floor (as runtime's tests).
    fn sky(n: usize) -> Cubemap {
        Cubemap::from_fn(n, |d| {
            let d = d.normalize();
            let sun = (d.dot(Vec3::new(0.4, 0.7, 0.59).normalize()) - 0.97).max(0.0) * 300.0;
            let base = 0.2 + 0.8 * d.y.max(0.0) + 0.1 * (3.0 * d.x).sin().abs();
            [base + sun, base * 0.9 + sun, base * 0.7 + 0.5 * sun]
        })
    }

    fn params(target: Target, size: usize, levels: usize) -> Params {
        Params {
            size,
            levels: Some(levels),
            target,
            ..Default::default()
        }
    }

    /// The emulated shader read of a custom chain against the exact kernel summed by brute
    /// force over every source texel, at the 33 roughness values: bounded, and better than the
    /// linear (gltf) lookup of a chain of the same bytes at every r ≥ 0.1 taken together.
    #[test]
    fn emulation_against_the_brute_force_kernel_at_33_roughness_values() {
        let src = sky(32);
        let env = Environment::Cube(src.clone());
        let texels = SourceTexels::new(&src);
        let brute = Reference::Brute {
            texels: &texels,
            source: &src,
        };
        let rs = roughness_grid(33);
        let dirs = probe_directions(96);
        let worst = |target: Target| {
            let p = params(target, 32, 4);
            let chain = bake_chain(&p, &env, &NoProgress).unwrap();
            let b = BorderedMips::new(&chain.mips);
            let st = abs_rel_stats(&b, p.lookup(), &rs, &dirs, &brute);
            if let Some(lk) = p.custom_lookup() {
                // The emulation is the mapping's read, tap for tap.
                for &r in &rs {
                    let d = dirs[7];
                    assert_eq!(lk.read(&b, d, r), b.sample(d, p.lookup().lod(r, 4, 32)));
                }
            }
            let hi: Vec<f64> = rs
                .iter()
                .zip(&st)
                .filter(|(r, _)| **r >= 0.1)
                .map(|(_, s)| s.mean)
                .collect();
            (hi.iter().cloned().fold(0.0, f64::max), hi)
        };
        let (custom, profile) = worst(Target::Custom);
        let (gltf, _) = worst(Target::Gltf);
        // Measured 2026-11: worst over r ≥ 0.1 on this 32² × 4 chain 1.9% custom, 4.0% gltf.
        assert!(custom < 0.03, "custom worst {custom}: {profile:?}");
        assert!(custom < gltf, "custom {custom} vs gltf {gltf}");
    }

    /// Power of a cube-valued function over the sphere, sampled at the centres of an n×n grid.
    fn power(n: usize, f: impl Fn(Vec3) -> Rgb) -> f64 {
        let mut s = 0.0;
        for face in Face::ALL {
            for j in 0..n {
                for i in 0..n {
                    let v = f(texel_direction(face, i, j, n));
                    s += ibl_core::luminance(v) as f64 * texel_solid_angle(i, j, n);
                }
            }
        }
        s
    }

    /// A one-texel 10⁵ sun over a dim sky keeps its power through the custom lookup at every
    /// roughness, between the levels too (one trilinear tap of levels whose *read* keeps it:
    /// `crate::spatial::keep_read_power`), to the 0.1%: the read's power integrated
    /// through the emulation on a 192² grid a face (an even multiple of every level's size).
    #[test]
    fn sun_power_is_kept_between_levels() {
        let n = 32;
        let mut src = Cubemap::constant(n, [0.05, 0.05, 0.05]);
        let (face, i, j) = (Face::from_index(2), 11, 19);
        let k = 3 * (j * n + i);
        src.faces[face as usize].data[k..k + 3].copy_from_slice(&[1e5, 1e5, 1e5]);
        let mut want = 0.0f64;
        for f in Face::ALL {
            for j in 0..n {
                for i in 0..n {
                    want +=
                        ibl_core::luminance(src.texel(f, i, j)) as f64 * texel_solid_angle(i, j, n);
                }
            }
        }
        let env = Environment::Cube(src.clone());
        let p = params(Target::Custom, 32, 5);
        let chain = bake_chain(&p, &env, &NoProgress).unwrap();
        let b = BorderedMips::new(&chain.mips);
        let lk = p.custom_lookup().unwrap();
        let levels = &chain.report.level_roughness;
        let mut rs: Vec<f32> = vec![0.1, 0.17, 0.29, 0.41, 0.58, 0.77, 0.93];
        assert!(rs
            .iter()
            .all(|r| levels.iter().all(|l| (l - r).abs() > 1e-3)));
        rs.extend(levels);
        for r in rs {
            let got = power(192, |d| lk.read(&b, d, r));
            let e = (got - want).abs() / want;
            eprintln!(
                "r {r} lod {} power {:+.4}%",
                lk.lod(r),
                100.0 * (got - want) / want
            );
            assert!(e < 1e-3, "r {r}: power {got} vs {want} ({:.3}%)", 100.0 * e);
        }
    }

    /// The lookup fit is planned with the chain's own α₀ (--custom-alpha0): every fitted
    /// level's neighbours are the chain's levels and its nodes lie between them. (The first
    /// pass planned it with the default α₀, so a chain baked with another α₀ was fitted to
    /// the kernel at the wrong roughness: worst mean over r ≥ 0.1 on city / interior 5.0 /
    /// 9.1% at α₀ = 0.02, 1.5 / 2.4% once planned with it.)
    #[test]
    fn the_fit_is_planned_with_the_chains_own_alpha0() {
        for a0 in [0.003f32, 0.05] {
            let p = Params {
                custom_alpha0: Some(a0),
                ..params(Target::Custom, 32, 4)
            };
            // Four levels: level 1's coarser neighbour and level 2's both are inner levels,
            // whose roughness depends on α₀ (a three-level chain's are 0 and 1 whatever α₀).
            let chain = bake_chain(&p, &Environment::Cube(sky(32)), &NoProgress).unwrap();
            let rl = &chain.report.level_roughness;
            let mut fitted = 0;
            for (l, lv) in chain.report.level.iter().enumerate() {
                let Some(fit) = &lv.fit else { continue };
                fitted += 1;
                assert_eq!(fit.neighbours[0], rl[l - 1], "a0 {a0} level {l}");
                if let Some(hi) = fit.neighbours.get(1) {
                    assert_eq!(*hi, rl[l + 1], "a0 {a0} level {l}");
                }
                let top = fit.neighbours.last().copied().unwrap();
                assert!(
                    fit.roughness.iter().all(|r| *r > rl[l - 1] && *r <= top)
                        && fit.roughness.iter().any(|r| *r > rl[l]),
                    "a0 {a0} level {l}: nodes {:?} levels {rl:?}",
                    fit.roughness
                );
            }
            assert_eq!(fitted, 2, "a0 {a0}: levels 1 and 2 fitted");
        }
    }

    /// The custom chain and its report are bit-identical whatever the thread count.
    #[test]
    fn bit_identical_for_any_thread_count() {
        let env = Environment::Cube(sky(32));
        let p = params(Target::Custom, 16, 4);
        let run = |threads: usize| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap()
                .install(|| bake_chain(&p, &env, &NoProgress).unwrap())
        };
        let (a, b) = (run(1), run(3));
        crate::test_util::assert_same_bits(&a.mips, &b.mips);
        let ja = serde_json::to_string(&a.report).unwrap();
        let jb = serde_json::to_string(&b.report).unwrap();
        assert_eq!(ja, jb);
        assert!(ja.contains("\"custom_lookup\":{"), "{ja}");
    }

    /// Pipelines and scenes reach the custom target through the same Params (RON keys), and
    /// --custom-alpha0 is checked before any work.
    #[test]
    fn ron_params_select_the_custom_lookup_and_bad_knees_are_refused() {
        let p: Params =
            ron::from_str("(target: custom, custom_alpha0: Some(0.02), size: 64)").unwrap();
        p.validate().unwrap();
        assert_eq!(p.lookup(), LodMapping::Custom { alpha0: 0.02 });
        assert_eq!(p.chain_levels(), 5, "down to 4×4 faces");
        let lk = p.custom_lookup().unwrap();
        assert_eq!((lk.levels, lk.size, lk.alpha0), (5, 64, 0.02));
        let d: Params = ron::from_str("(target: custom)").unwrap();
        assert_eq!(
            d.lookup(),
            LodMapping::Custom {
                alpha0: ibl_target::lod::CUSTOM_ALPHA0
            }
        );
        for bad in [
            "(target: gltf, custom_alpha0: Some(0.02))",
            "(target: custom, custom_alpha0: Some(0.0))",
            "(target: custom, custom_alpha0: Some(NaN))",
            "(target: custom, custom_alpha0: Some(100.0))",
        ] {
            let p: Params = ron::from_str(bad).unwrap();
            let e = p.validate().unwrap_err().to_string();
            assert!(
                e.contains("--custom-alpha0") && !e.contains('\n'),
                "{bad}: {e}"
            );
        }
    }
}
