//! Each engine's own split-sum BRDF terms, as its shader computes them for image-based
//! lighting, for the scene's white materials (base colour 1; metallic F0 = 1, dielectric
//! F0 = 0.04 and diffuse albedo 1; F90 = 1). A pixel is
//!
//!   colour = w_r · Lexact(R, r) + w_e · E(n)/π
//!
//! with the weights ([`Weights`]) of [`weights`]. The DFG pair (A, B) (specular = F0·A + B,
//! docs/CONVENTIONS.md) comes from the engine's own table or fit: engines that sample a DFG
//! table get the table's defining integral computed exactly ([`ExactDfg`]: GGX with
//! height-correlated Smith, the integral each of those tables tabulates; what their 8/16-bit
//! texels and bilinear reads add is theirs to measure), engines with an analytic fit get the
//! fit. Each form cites the engine source it follows (repository and path).
//!
//! What is deliberately *not* modelled (see the report of the engines harness): three.js adds
//! a screen-space `geometryRoughness` (normal derivatives) to the roughness, and Filament
//! (non-mobile builds) bends R toward n (`getSpecularDominantDirection`); both move what the
//! engine reads away from R at the sphere's roughness, which the contract fixes.

use ibl_lut::reference::DfgReference;

/// Whose BRDF terms a render uses.
#[derive(
    Clone,
    Copy,
    Debug,
    PartialEq,
    Eq,
    Hash,
    Default,
    clap::ValueEnum,
    serde::Serialize,
    serde::Deserialize,
)]
#[serde(rename_all = "kebab-case")]
pub enum Engine {
    /// glTF Sample Renderer (KhronosGroup/glTF-Sample-Renderer).
    #[default]
    Gltf,
    /// three.js r187 (MeshStandardMaterial / MeshPhysicalMaterial).
    Three,
    /// Babylon.js 9 (PBRMaterial, metallic workflow).
    Babylon,
    /// Filament (lit material).
    Filament,
    /// Bevy (StandardMaterial with an EnvironmentMapLight).
    Bevy,
    /// Unity URP (Lit).
    Unity,
    /// Our own DFG (ibl-lut), no modifier: specular F0·A + B, diffuse E/π × albedo.
    Exact,
}

impl Engine {
    /// Every engine.
    pub const ALL: [Engine; 7] = [
        Engine::Gltf,
        Engine::Three,
        Engine::Babylon,
        Engine::Filament,
        Engine::Bevy,
        Engine::Unity,
        Engine::Exact,
    ];

    /// The `--engine` value.
    pub fn name(self) -> &'static str {
        match self {
            Engine::Gltf => "gltf",
            Engine::Three => "three",
            Engine::Babylon => "babylon",
            Engine::Filament => "filament",
            Engine::Bevy => "bevy",
            Engine::Unity => "unity",
            Engine::Exact => "exact",
        }
    }

    /// The shader source whose form [`weights`] follows.
    pub fn source(self) -> &'static str {
        match self {
            Engine::Gltf => "KhronosGroup/glTF-Sample-Renderer source/Renderer/shaders/ibl.glsl (getIBLGGXFresnel) and pbr.frag (mix of f_diffuse and the specular by the IBL Fresnel)",
            Engine::Three => "mrdoob/three.js src/renderers/shaders/ShaderChunk/lights_physical_pars_fragment.glsl.js (computeMultiscattering, RE_IndirectSpecular_Physical, dfgLUT) and lights_physical_fragment.glsl.js (roughness >= 0.0525)",
            Engine::Babylon => "BabylonJS/Babylon.js packages/dev/core/src/Shaders/ShadersInclude/pbrBRDFFunctions.fx (getReflectanceFromBRDFLookup, BRDF_V_HEIGHT_CORRELATED; getEnergyConservationFactor) and pbrBlockFinalLitComponents.fx (non-legacy energy conservation)",
            Engine::Filament => "google/filament shaders/src/surface_light_indirect.fs (light_indirect.fs in older trees: specularDFG = mix(dfg.xxx, dfg.yyy, f0) with multiple-scattering compensation, Fr *= energyCompensation, Fd = diffuseColor * irradiance * (1 - E)) and surface_shading_lit.fs (getEnergyCompensationPixelParams: energyCompensation = 1 + f0 (1/dfg.y - 1)); perceptual roughness >= MIN_PERCEPTUAL_ROUGHNESS 0.045",
            Engine::Bevy => "bevyengine/bevy crates/bevy_pbr/src/environment_map/environment_map.wgsl (light_probe/environment_map.wesl in newer trees: FssEss = kS Ess, multiple scattering, Edss) and crates/bevy_pbr/src/render/pbr_lighting.wgsl (F_AB), perceptual roughness >= 0.089",
            Engine::Unity => "Unity-Technologies/Graphics Packages/com.unity.render-pipelines.universal/ShaderLibrary/BRDF.hlsl (EnvironmentBRDF, EnvironmentBRDFSpecular) and GlobalIllumination.hlsl (fresnelTerm = (1 - n.v)^4)",
            Engine::Exact => "ibl-lut DFG (GGX, height-correlated Smith), no modifier",
        }
    }
}

/// What multiplies each lighting term of a pixel.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Weights {
    /// Weight of the prefiltered radiance Lexact(R, r).
    pub radiance: f64,
    /// Weight of the irradiance E(n)/π.
    pub irradiance: f64,
}

/// The exact split-sum DFG (A, B) at one roughness over n·v ∈ [0, 1]: the Gauss–Legendre
/// reference of `ibl_lut::reference` (independent of the table bake's estimator) on a fine
/// grid, read linearly (its error is below 1e-5 on the masked pixels, n·v ≥ 0.26; see the
/// tests).
#[derive(Clone, Debug)]
pub struct ExactDfg {
    roughness: f64,
    table: Vec<[f64; 2]>,
}

/// n·v samples of [`ExactDfg`].
const DFG_SAMPLES: usize = 256;
/// Quadrature nodes per axis of [`ExactDfg`] (128 × 128).
const DFG_NODES: usize = 128;

impl ExactDfg {
    /// The table at perceptual roughness `roughness` (α = r²; r = 0 is the mirror's closed
    /// form A = 1 − (1 − n·v)⁵, B = (1 − n·v)⁵: D a delta at h = n, G = 1).
    pub fn new(roughness: f64) -> ExactDfg {
        let table = if roughness <= 0.0 {
            Vec::new()
        } else {
            let q = DfgReference::new(DFG_NODES);
            let alpha = roughness * roughness;
            (0..DFG_SAMPLES)
                .map(|k| q.dfg(Self::grid(k), alpha))
                .collect()
        };
        ExactDfg { roughness, table }
    }

    /// n·v of sample k: (k + 0.5)/N, never 0 (where the integrals' 1/(n·v) is singular).
    fn grid(k: usize) -> f64 {
        (k as f64 + 0.5) / DFG_SAMPLES as f64
    }

    /// Perceptual roughness of the table.
    pub fn roughness(&self) -> f64 {
        self.roughness
    }

    /// (A, B) at view cosine `n_dot_v`.
    pub fn ab(&self, n_dot_v: f64) -> [f64; 2] {
        let nv = n_dot_v.clamp(0.0, 1.0);
        if self.table.is_empty() {
            let f = (1.0 - nv).powi(5);
            return [1.0 - f, f];
        }
        let x = (nv * DFG_SAMPLES as f64 - 0.5).clamp(0.0, (DFG_SAMPLES - 1) as f64);
        let i = (x.floor() as usize).min(DFG_SAMPLES - 2);
        let t = x - i as f64;
        let (a, b) = (self.table[i], self.table[i + 1]);
        [a[0] + (b[0] - a[0]) * t, a[1] + (b[1] - a[1]) * t]
    }
}

/// Karis's analytic fit of the DFG pair ("Physically Based Shading on Mobile", 2014), as Bevy
/// writes it (bevyengine/bevy crates/bevy_pbr/src/render/pbr_lighting.wgsl `F_AB`; three.js's
/// older `DFGApprox` is the same polynomial): c0 = (−1, −0.0275, −0.572, 0.022),
/// c1 = (1, 0.0425, 1.04, −0.04), r4 = r·c0 + c1,
/// a004 = min(r4.x², 2^(−9.28 n·v))·r4.x + r4.y, (A, B) = (−1.04, 1.04)·a004 + r4.zw.
pub fn karis_ab(perceptual_roughness: f64, n_dot_v: f64) -> [f64; 2] {
    let c0 = [-1.0, -0.0275, -0.572, 0.022];
    let c1 = [1.0, 0.0425, 1.04, -0.04];
    let r: [f64; 4] = std::array::from_fn(|k| perceptual_roughness * c0[k] + c1[k]);
    let a004 = (r[0] * r[0]).min((-9.28 * n_dot_v).exp2()) * r[0] + r[1];
    [-1.04 * a004 + r[2], 1.04 * a004 + r[3]]
}

/// Fdez-Agüera 2019's multiple-scattering terms from the single-scattering FssEss, the
/// directional albedo Ess = A + B and F0: Favg = F0 + (1 − F0)/21,
/// FmsEms = (1 − Ess)·FssEss·Favg / (1 − (1 − Ess)·Favg).
fn fms_ems(fss_ess: f64, ess: f64, f0: f64) -> f64 {
    let ems = 1.0 - ess;
    let favg = f0 + (1.0 - f0) / 21.0;
    ems * fss_ess * favg / (1.0 - ems * favg)
}

/// The roughness at which `engine` reads its DFG table for a sphere of perceptual roughness
/// `r`: the engine's own lower clamp (three.js 0.0525, Filament 0.045), else r.
pub fn dfg_roughness(engine: Engine, r: f64) -> f64 {
    match engine {
        Engine::Three => r.max(0.0525),
        Engine::Filament => r.max(0.045),
        _ => r,
    }
}

/// The weights of a pixel with view cosine `n_dot_v` on a sphere of perceptual roughness `r`,
/// metallic or dielectric, in `engine`. `dfg` is the exact table at
/// [`dfg_roughness`]`(engine, r)` (used by the engines whose shaders sample a DFG table).
pub fn weights(engine: Engine, n_dot_v: f64, r: f64, metallic: bool, dfg: &ExactDfg) -> Weights {
    let nv = n_dot_v.clamp(0.0, 1.0);
    let f0 = if metallic {
        1.0
    } else {
        crate::scene::DIELECTRIC_F0
    };
    let albedo = if metallic { 0.0 } else { 1.0 };
    debug_assert!((dfg.roughness() - dfg_roughness(engine, r)).abs() < 1e-12);
    match engine {
        Engine::Exact => {
            let [a, b] = dfg.ab(nv);
            Weights {
                radiance: f0 * a + b,
                irradiance: albedo,
            }
        }
        Engine::Gltf => {
            // getIBLGGXFresnel: roughness-dependent Fresnel k_S = F0 + (max(1 − r, F0) − F0)(1 − n·v)⁵,
            // FssEss = k_S·A + B, plus FmsEms; pbr.frag: metal = F·L, dielectric =
            // mix(f_diffuse, L, F) = (1 − F)·E/π + F·L (diffuse albedo = base colour).
            let [a, b] = dfg.ab(nv);
            let fr = (1.0 - r).max(f0) - f0;
            let ks = f0 + fr * (1.0 - nv).powi(5);
            let fss = ks * a + b;
            let f = fss + fms_ems(fss, a + b, f0);
            if metallic {
                Weights {
                    radiance: f,
                    irradiance: 0.0,
                }
            } else {
                Weights {
                    radiance: f,
                    irradiance: 1.0 - f,
                }
            }
        }
        Engine::Three => {
            // roughness = max(r, 0.0525); dfgLUT read at (roughness, n·v): FssEss = F0·A + F90·B,
            // multiScatter = Fms·Ems (Fdez-Agüera) on the irradiance; diffuse =
            // diffuseContribution·(1 − (single + multi)) on the irradiance.
            let [a, b] = dfg.ab(nv);
            let fss = f0 * a + b;
            let ms = fms_ems(fss, a + b, f0);
            Weights {
                radiance: fss,
                irradiance: ms + albedo * (1.0 - (fss + ms)),
            }
        }
        Engine::Babylon => {
            // The BRDF texture holds (B, A + B) (BRDF_V_HEIGHT_CORRELATED: reflectance =
            // (R90 − R0)·x + R0·y = R0·A + B with R90 = 1); MS_BRDF_ENERGY_CONSERVATION scales it
            // by 1 + R0(1/y − 1); the irradiance is multiplied by 1 − (the dielectric base
            // reflectance × its factor) and by surfaceAlbedo = baseColour·(1 − metallic).
            let [a, b] = dfg.ab(nv);
            let y = a + b;
            let spec = |r0: f64| (r0 * a + b) * (1.0 + r0 * (1.0 / y - 1.0));
            Weights {
                radiance: spec(f0),
                irradiance: albedo * (1.0 - spec(crate::scene::DIELECTRIC_F0)).clamp(0.0, 1.0),
            }
        }
        Engine::Filament => {
            // perceptualRoughness ≥ 0.045; E = mix(dfg.x, dfg.y, f0) = F0·A + B (dfg = (B, A+B)),
            // Fr = E·L·energyCompensation, energyCompensation = 1 + f0(1/dfg.y − 1);
            // Fd = diffuseColor·irradiance·(1 − E).
            let [a, b] = dfg.ab(nv);
            let e = f0 * a + b;
            Weights {
                radiance: e * (1.0 + f0 * (1.0 / (a + b) - 1.0)),
                irradiance: albedo * (1.0 - e),
            }
        }
        Engine::Bevy => {
            // perceptual roughness ≥ 0.089 (α its square); f_ab = F_AB (Karis's fit);
            // Fr = max(1 − α, F0) − F0, kS = F0 + Fr(1 − n·v)⁵, FssEss = kS·Ess·specular_occlusion
            // (specular_occlusion = saturate(F0·16.5·3) = 1 for both materials), Fms·Ems,
            // Edss = 1 − (FssEss + FmsEms); diffuse = (FmsEms + diffuse_color·Edss)·irradiance.
            let pr = r.clamp(0.089, 1.0);
            let alpha = pr * pr;
            let [a, b] = karis_ab(pr, nv);
            let ess = a + b;
            let fr = (1.0 - alpha).max(f0) - f0;
            let ks = f0 + fr * (1.0 - nv).powi(5);
            let occlusion = (f0 * 50.0 * 0.33 * 3.0).clamp(0.0, 1.0);
            let fss = ks * ess * occlusion;
            let ms = fms_ems(fss, ess, f0);
            let edss = 1.0 - (fss + ms);
            Weights {
                radiance: fss,
                irradiance: ms + albedo * edss,
            }
        }
        Engine::Unity => {
            // roughness = max(r², HALF_MIN_SQRT), roughness2 = max(roughness², HALF_MIN);
            // surfaceReduction = 1/(roughness2 + 1); reflectivity = 1 − 0.96(1 − metallic),
            // grazing = saturate(1 − r + reflectivity), specular = lerp(0.04, 1, metallic);
            // w = surfaceReduction·lerp(specular, grazing, (1 − n·v)⁴); diffuse =
            // albedo·0.96(1 − metallic) times the SH irradiance.
            const HALF_MIN_SQRT: f64 = 0.0078125;
            const HALF_MIN: f64 = 6.103_515_625e-5;
            let roughness = (r * r).max(HALF_MIN_SQRT);
            let roughness2 = (roughness * roughness).max(HALF_MIN);
            let metal = if metallic { 1.0 } else { 0.0 };
            let one_minus_reflectivity = 0.96 * (1.0 - metal);
            let reflectivity = 1.0 - one_minus_reflectivity;
            let grazing = (1.0 - r + reflectivity).clamp(0.0, 1.0);
            let specular = 0.04 + (1.0 - 0.04) * metal;
            let fresnel = (1.0 - nv).powi(4);
            Weights {
                radiance: (specular + (grazing - specular) * fresnel) / (roughness2 + 1.0),
                irradiance: one_minus_reflectivity,
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exact_dfg_reads_the_quadrature_between_its_samples() {
        let q = DfgReference::new(256);
        for r in [0.2f64, 0.6, 1.0] {
            let t = ExactDfg::new(r);
            let mut worst = 0.0f64;
            for k in 0..40 {
                let nv = 0.26 + 0.74 * (k as f64 + 0.37) / 40.0;
                let want = q.dfg(nv, r * r);
                let got = t.ab(nv);
                worst = worst
                    .max((got[0] - want[0]).abs())
                    .max((got[1] - want[1]).abs());
            }
            eprintln!("exact DFG r {r}: worst |table − quadrature(256²)| = {worst:.2e}");
            assert!(worst < 2e-5, "r {r}: {worst}");
        }
    }

    #[test]
    fn mirror_dfg_is_schlick_and_the_quadrature_tends_to_it() {
        let t = ExactDfg::new(0.0);
        let q = DfgReference::new(256);
        for nv in [0.3, 0.7, 1.0] {
            let [a, b] = t.ab(nv);
            assert!((a + b - 1.0).abs() < 1e-12);
            assert!((b - (1.0f64 - nv).powi(5)).abs() < 1e-12);
            // α = 0.01 is all but a mirror: within 1e-3.
            let near = q.dfg(nv, 1e-2);
            assert!(
                (near[0] - a).abs() < 2e-3 && (near[1] - b).abs() < 2e-3,
                "{nv}: {near:?} vs {a} {b}"
            );
        }
    }

    #[test]
    fn karis_fit_is_within_its_known_error_of_the_exact_dfg() {
        // The fit was made to UE4's table (separable Schlick-Smith G), not the height-correlated
        // integral: measured up to 17% below it (A + B at r = 0.5, n·v = 0.6: 0.725 against 0.872). A transcription error (a
        // swapped constant) is far larger, and the mirror must come out as Schlick's A + B = 1.
        for nv in [0.3f64, 0.6, 1.0] {
            let [a, b] = karis_ab(0.0, nv);
            assert!((a + b - 1.0).abs() < 0.01, "mirror nv {nv}: {a} + {b}");
        }
        assert!(karis_ab(0.0, 1.0)[1].abs() < 0.01);
        for r in [0.2f64, 0.5, 1.0] {
            let t = ExactDfg::new(r);
            for nv in [0.3f64, 0.6, 0.95] {
                let [a, b] = karis_ab(r, nv);
                let [ea, eb] = t.ab(nv);
                assert!(
                    (a + b - (ea + eb)).abs() < 0.2,
                    "r {r} nv {nv}: {a}+{b} vs {ea}+{eb}"
                );
                assert!((b - eb).abs() < 0.05, "r {r} nv {nv}: B {b} vs {eb}");
            }
        }
    }

    /// The furnace of every engine: a white metallic sphere in a constant environment L
    /// renders L·(w_r + w_e); exact = A + B (< 1 for rough spheres, 1 at r = 0); the engines
    /// with multiple-scattering compensation restore energy to 1 (three, Babylon, Filament,
    /// Bevy, glTF) up to their fits.
    #[test]
    fn metallic_furnace_per_engine() {
        for r in [0.0f64, 0.2, 0.6, 1.0] {
            let t = ExactDfg::new(r);
            for nv in [0.3f64, 0.8] {
                let total = |e: Engine| {
                    let w = weights(e, nv, r, true, &ExactDfg::new(dfg_roughness(e, r)));
                    w.radiance + w.irradiance
                };
                let [a, b] = t.ab(nv);
                assert!((total(Engine::Exact) - (a + b)).abs() < 1e-12);
                assert!((total(Engine::Babylon) - 1.0).abs() < 1e-9, "babylon r {r}");
                assert!(
                    (total(Engine::Filament) - 1.0).abs() < 1e-9,
                    "filament r {r}"
                );
                assert!((total(Engine::Three) - 1.0).abs() < 1e-9, "three r {r}");
                assert!((total(Engine::Bevy) - 1.0).abs() < 1e-9, "bevy r {r}");
                // glTF's F = FssEss + FmsEms with F0 = 1 is Ess/(1 − Ems) = 1 as well.
                assert!((total(Engine::Gltf) - 1.0).abs() < 1e-9, "gltf r {r}");
                // Unity: 1/(α² + 1), no compensation.
                let a2 = (r * r).max(0.0078125).powi(2).max(6.103515625e-5);
                assert!((total(Engine::Unity) - 1.0 / (a2 + 1.0)).abs() < 1e-9);
            }
        }
    }

    #[test]
    fn dielectric_weights_are_in_range() {
        for e in Engine::ALL {
            for r in [0.0f64, 0.4, 1.0] {
                let t = ExactDfg::new(dfg_roughness(e, r));
                for nv in [0.26f64, 0.5, 1.0] {
                    let w = weights(e, nv, r, false, &t);
                    assert!(
                        w.radiance > 0.0 && w.radiance < 1.0,
                        "{e:?} {r} {nv}: {w:?}"
                    );
                    assert!(
                        w.irradiance > 0.0 && w.irradiance <= 1.0,
                        "{e:?} {r} {nv}: {w:?}"
                    );
                    // Energy: a white dielectric in a furnace reflects at most (about) 1 — except
                    // in Unity, whose diffuse (0.96 albedo) ignores the specular it adds, and in
                    // `exact`, which by definition adds the diffuse unmodified.
                    if e != Engine::Unity && e != Engine::Exact {
                        assert!(w.radiance + w.irradiance < 1.06, "{e:?} {r} {nv}: {w:?}");
                    }
                }
            }
        }
    }
}
