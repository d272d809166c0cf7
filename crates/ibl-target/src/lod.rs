//! Level ↔ roughness mappings of the engines' runtime lookups: the lod each engine's shader
//! asks of a prefiltered chain for a perceptual roughness r, and its inverse, the roughness a
//! bake must store at each level so that the lookup lands on it.

/// How an engine turns perceptual roughness r (α = r²) into a mip level of the specular chain.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
#[serde(rename_all = "kebab-case", tag = "kind")]
pub enum LodMapping {
    /// lod = r·(N−1), N the chain's level count.
    /// glTF-Sample-Viewer: KhronosGroup/glTF-Sample-Viewer `source/Renderer/shaders/ibl.glsl`
    /// (`getIBLRadianceGGX`: `perceptualRoughness * float(u_MipCount)` with u_MipCount the last
    /// level index); Bevy: bevyengine/bevy
    /// `crates/bevy_pbr/src/light_probe/environment_map.wesl` (`radiance_level =
    /// perceptual_roughness * f32(textureNumLevels(..) - 1u)`).
    Linear,
    /// lod = (N−1)·r(2−r): google/filament `shaders/src/surface_light_indirect.fs`
    /// (`perceptualRoughnessToLod`, `iblRoughnessOneLevel * r * (2.0 - r)`) with
    /// iblRoughnessOneLevel = levels − 1 (google/filament
    /// `filament/src/ds/ColorPassDescriptorSet.cpp`, `prepareAmbientLight`). cmgen bakes the
    /// inverse, r = 1 − √(1 − l/(N−1)) (`lodToPerceptualRoughness`, a = 2, b = −1).
    Filament,
    /// mip = r(1.7 − 0.7r)·UNITY_SPECCUBE_LOD_STEPS, the steps being 6 whatever the chain holds:
    /// Unity-Technologies/Graphics
    /// `Packages/com.unity.render-pipelines.core/ShaderLibrary/ImageBasedLighting.hlsl`
    /// (`PerceptualRoughnessToMipmapLevel`).
    Unity,
    /// lod = log2(size·α)·scale (+ offset 0), α = r²: BabylonJS/Babylon.js
    /// `packages/dev/core/src/Shaders/ShadersInclude/pbrBlockReflection.fx`
    /// (`getLodFromAlphaG`, then `reflectionLOD * vReflectionMicrosurfaceInfos.y + .z`, the
    /// texture's lodGenerationScale and offset); its own prefilter stores α = 2^(l/scale)/size
    /// at level l (`packages/dev/core/src/Materials/Textures/Filtering/hdrFiltering.ts`,
    /// scale 0.8, offset 0, level 0 the mirror).
    Babylon {
        /// Babylon's `lodGenerationScale` (0.8 by default).
        scale: f32,
    },
    /// three.js filters the environment itself at load time (PMREMGenerator): no baked
    /// chain is read, so no level ↔ roughness mapping applies to what we ship.
    Pmrem,
    /// Our own lookup (`--target custom`, docs/CUSTOM_LOOKUP.md): lod = s·log2(1 + α/α₀),
    /// α = r², s = (N−1)/log2(1 + 1/α₀) so that r = 1 lands on the last level. Levels are
    /// geometric in α above α₀ (the lobe's width, hence the texels it needs, goes as α, and the
    /// level sizes halve) and linear in α below it, down to the mirror at lod 0. The shader
    /// reads levels ⌊lod⌋ and ⌊lod⌋ + 1 with two bilinear taps and corrects their linear blend
    /// by the chain's alpha channel (the kernel at the interval's midpoint:
    /// `ibl_prefilter::custom`); see [`custom_lod`].
    Custom {
        /// α₀, the knee between the linear and the geometric spacing.
        alpha0: f32,
    },
}

/// The custom lookup's lod exactly as its emitted shaders compute it (one f32 expression,
/// the constants precomputed): clamp(scale·log2(1 + r·r·inv_alpha0), 0, max_lod).
pub fn custom_lod(r: f32, scale: f32, inv_alpha0: f32, max_lod: f32) -> f32 {
    let r = r.clamp(0.0, 1.0);
    (scale * (1.0 + r * r * inv_alpha0).log2()).clamp(0.0, max_lod)
}

/// The custom lookup's scale s = (N−1)/log2(1 + 1/α₀) for a chain of `levels` levels.
pub fn custom_scale(alpha0: f32, levels: usize) -> f32 {
    let last = levels.saturating_sub(1) as f32;
    last / (1.0 + 1.0 / alpha0).log2()
}

/// Babylon's `lodGenerationScale` (hdrFiltering.ts, `_lodGenerationScale = 0.8`).
pub(crate) const BABYLON_LOD_SCALE: f32 = 0.8;
/// α₀ of the `custom` target's lookup: level 1 of the default 6-level chain at r = 0.0998, so
/// that every r ≥ 0.1 is read above the mirror's interval (which is read linearly, in
/// luminance: 2.2% on studio at r = 0.1 with α₀ = 0.01). Chosen on the design fixtures only
/// (city_512, interior_256), by the worst mean error over r ∈ [0.10, 1] in steps of 0.01, 256
/// directions (docs/notes/custom-log.md): α₀ = 0.004: 0.65 / 0.77%, 0.0054: 0.52 / 0.64%,
/// 0.007: 0.46 / 0.64%, 0.01: 0.52 / 0.88%. (The linear-cubic lookup before it chose 0.01 on
/// the 33 roughness values k/32, which skip r ∈ (0.094, 0.125).) Overridden per bake by
/// `prefilter --custom-alpha0`.
pub const CUSTOM_ALPHA0: f32 = 0.0054;
/// UNITY_SPECCUBE_LOD_STEPS (ImageBasedLighting.hlsl: "the last mip index, we generate 7 mips").
pub(crate) const UNITY_LOD_STEPS: f32 = 6.0;

impl LodMapping {
    /// Short name written into `prefilter.json`.
    pub fn name(self) -> &'static str {
        match self {
            LodMapping::Linear => "lod = r(N-1)",
            LodMapping::Filament => "lod = (N-1) r(2-r)",
            LodMapping::Unity => "lod = 6 r(1.7-0.7r)",
            LodMapping::Babylon { .. } => "lod = 0.8 log2(size r^2)",
            LodMapping::Pmrem => "pmrem (filtered by the engine)",
            LodMapping::Custom { .. } => "lod = s log2(1 + r^2/a0), 2 taps + midpoint",
        }
    }

    /// Whether the engine reads a baked chain at all.
    pub fn reads_chain(self) -> bool {
        !matches!(self, LodMapping::Pmrem)
    }

    /// The lod the engine samples for roughness `r` on a chain of `levels` levels whose base
    /// face is `size` texels, before the sampler clamps it to [0, levels − 1].
    pub(crate) fn raw_lod(self, r: f32, levels: usize, size: usize) -> f32 {
        let r = r.clamp(0.0, 1.0);
        let last = levels.saturating_sub(1) as f32;
        match self {
            LodMapping::Linear | LodMapping::Pmrem => r * last,
            LodMapping::Filament => last * r * (2.0 - r),
            LodMapping::Unity => r * (1.7 - 0.7 * r) * UNITY_LOD_STEPS,
            LodMapping::Babylon { scale } => {
                let a = (r * r).max(1e-12);
                (size as f32 * a).log2() * scale
            }
            LodMapping::Custom { alpha0 } => {
                custom_lod(r, custom_scale(alpha0, levels), 1.0 / alpha0, f32::INFINITY)
            }
        }
    }

    /// The lod clamped to the chain, as a sampler does.
    pub fn lod(self, r: f32, levels: usize, size: usize) -> f32 {
        self.raw_lod(r, levels, size)
            .clamp(0.0, levels.saturating_sub(1) as f32)
    }

    /// Roughness a bake stores at level `l`: the r whose lookup lands exactly on l (level 0 the
    /// mirror; levels the lookup never reaches get r = 1).
    pub fn level_roughness(self, l: usize, levels: usize, size: usize) -> f32 {
        if l == 0 || levels <= 1 {
            return 0.0;
        }
        let last = (levels - 1) as f32;
        let t = l as f32;
        let r = match self {
            LodMapping::Linear | LodMapping::Pmrem => t / last,
            // (N−1)·r(2−r) = l  ⇔  r = 1 − √(1 − l/(N−1)).
            LodMapping::Filament => 1.0 - (1.0 - (t / last).min(1.0)).sqrt(),
            // 6·(1.7r − 0.7r²) = l  ⇔  4.2r² − 10.2r + l = 0, the root in [0, 1].
            LodMapping::Unity => {
                let s = UNITY_LOD_STEPS;
                let (a, b) = (0.7 * s, 1.7 * s);
                let disc = (b * b - 4.0 * a * t).max(0.0);
                (b - disc.sqrt()) / (2.0 * a)
            }
            // log2(size·α)·scale = l  ⇔  α = 2^(l/scale)/size.
            LodMapping::Babylon { scale } => ((t / scale).exp2() / size as f32).sqrt(),
            // s·log2(1 + α/α₀) = l  ⇔  α = α₀·((1 + 1/α₀)^(l/(N−1)) − 1), in f64 so the
            // last level is r = 1 to the last bit.
            LodMapping::Custom { alpha0 } => {
                let a0 = alpha0 as f64;
                let a = a0 * ((1.0 + 1.0 / a0).powf(t as f64 / last as f64) - 1.0);
                a.sqrt() as f32
            }
        };
        r.clamp(0.0, 1.0)
    }

    /// Roughness of every level of a chain (the runtime bench's floor table reads it).
    pub fn level_roughnesses(self, levels: usize, size: usize) -> Vec<f32> {
        (0..levels)
            .map(|l| self.level_roughness(l, levels, size))
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const ALL: [LodMapping; 6] = [
        LodMapping::Custom { alpha0: 0.01 },
        LodMapping::Custom { alpha0: 0.2 },
        LodMapping::Linear,
        LodMapping::Filament,
        LodMapping::Unity,
        LodMapping::Babylon {
            scale: BABYLON_LOD_SCALE,
        },
    ];

    #[test]
    fn level_roughness_is_where_the_lookup_lands() {
        // Round trip: the engine's lod of the roughness baked at level l is l, for every
        // level the lookup reaches.
        for m in ALL {
            for (levels, size) in [(5, 256), (7, 128), (9, 256), (6, 64)] {
                for l in 1..levels {
                    let r = m.level_roughness(l, levels, size);
                    let raw = m.raw_lod(r, levels, size);
                    if r < 1.0 {
                        assert!(
                            (raw - l as f32).abs() < 1e-4,
                            "{m:?} N {levels} l {l}: r {r} lod {raw}"
                        );
                    } else {
                        assert!(raw <= l as f32 + 1e-4, "{m:?} level {l} beyond the lookup");
                    }
                }
                // Monotone in l.
                let rs = m.level_roughnesses(levels, size);
                assert!(rs.windows(2).all(|w| w[1] >= w[0]), "{m:?} {rs:?}");
                assert_eq!(rs[0], 0.0);
            }
        }
    }

    #[test]
    fn published_values() {
        // cmgen's 5-level chain (lodToPerceptualRoughness at lod = l/4).
        let f: Vec<f32> = LodMapping::Filament.level_roughnesses(5, 256);
        let expect = [0.0, 1.0 - 0.75f32.sqrt(), 1.0 - 0.5f32.sqrt(), 0.5, 1.0];
        for (a, b) in f.iter().zip(expect) {
            assert!((a - b).abs() < 1e-6, "{f:?}");
        }
        // Unity: r = 1 lands on mip 6, r = 0.5 on 6·0.5·1.35 = 4.05.
        assert!((LodMapping::Unity.raw_lod(1.0, 7, 128) - 6.0).abs() < 1e-6);
        assert!((LodMapping::Unity.raw_lod(0.5, 7, 128) - 4.05).abs() < 1e-5);
        assert!((LodMapping::Unity.level_roughness(6, 7, 128) - 1.0).abs() < 1e-5);
        // Babylon: α at level l is 2^(l/0.8)/size (hdrFiltering.ts); r = 1 on a 256² base
        // reads lod 0.8·8 = 6.4.
        let b = LodMapping::Babylon {
            scale: BABYLON_LOD_SCALE,
        };
        assert!((b.raw_lod(1.0, 9, 256) - 6.4).abs() < 1e-5);
        let r3 = b.level_roughness(3, 9, 256);
        assert!((r3 * r3 - 2f32.powf(3.0 / 0.8) / 256.0).abs() < 1e-6);
        // Linear: glTF / Bevy.
        assert_eq!(LodMapping::Linear.level_roughness(2, 5, 256), 0.5);
        assert_eq!(LodMapping::Linear.lod(0.3, 5, 256), 1.2);
        // Clamping to the chain.
        assert_eq!(LodMapping::Unity.lod(1.0, 5, 128), 4.0);
        assert_eq!(b.lod(0.01, 9, 256), 0.0);
    }
}
