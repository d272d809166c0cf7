//! Anisotropic materials and the parameterisations engines use for them (docs/ANISOTROPY.md).
//!
//! The project's anisotropic GGX is written (r, η) as Kulla & Conty 2017, Filament and Cocco
//! et al. 2024 §4.1: α = r², α_t = α(1+η) along the tangent t, α_b = α(1−η) along b = n × t.
//! KHR_materials_anisotropy writes (r_k, s): α_b = r_k², α_t = mix(α_b, 1, s²)
//! (KhronosGroup/glTF `extensions/2.0/Khronos/KHR_materials_anisotropy/README.md`).

use serde::Serialize;

/// A specular lobe in the local frame (t, b, n).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub enum Material {
    /// Anisotropic GGX with α_t along the tangent and α_b along the bitangent (the GGX α,
    /// never the perceptual roughness).
    Ggx {
        /// α along t.
        alpha_t: f32,
        /// α along b.
        alpha_b: f32,
    },
    /// Ashikhmin–Shirley with exponents n_u along t and n_v along b (Marcolongo 2020 §2.4).
    AshikhminShirley {
        /// Exponent along t.
        nu: f64,
        /// Exponent along b.
        nv: f64,
    },
    /// Kurt et al. 2010's normalised anisotropic Beckmann (`ibl_brdf::Beckmann`).
    Beckmann {
        /// α along t.
        alpha_t: f32,
        /// α along b.
        alpha_b: f32,
    },
    /// GTR_γ of roughness α_b stretched along t by α_t/α_b: Atanasov et al. 2022's transformed
    /// microsurface (`ibl_brdf::Transformed<Gtr>`, M = diag(α_t/α_b, 1)). γ = 2 is GGX.
    TransformedGtr {
        /// α along t.
        alpha_t: f32,
        /// α along b (the base GTR's α).
        alpha_b: f32,
        /// Tail exponent γ.
        gamma: f32,
    },
}

impl Material {
    /// Anisotropic GGX from perceptual roughness r and the Kulla–Conty anisotropy η ∈ (−1, 1):
    /// α_t = r²(1+η), α_b = r²(1−η) (Cocco et al. 2024 §4.1; google/filament
    /// `shaders/src/shading_model_standard.fs`, `at = roughness*(1+anisotropy)`). Each α is
    /// floored at [`MIN_ALPHA`] (η → ±1 would make a mirror axis).
    pub fn ggx_kc(r: f32, eta: f32) -> Material {
        let (at, ab) = kulla_conty(r, eta);
        Material::Ggx {
            alpha_t: at.max(MIN_ALPHA),
            alpha_b: ab.max(MIN_ALPHA),
        }
    }

    /// The (α_t, α_b) of a GGX lobe, `None` for Ashikhmin–Shirley.
    pub fn ggx_alphas(&self) -> Option<(f32, f32)> {
        match *self {
            Material::Ggx { alpha_t, alpha_b } => Some((alpha_t, alpha_b)),
            _ => None,
        }
    }
}

/// Smallest α a lobe axis gets (a 1e-3 α is ≈ 0.06°, far below any cube's texel).
pub const MIN_ALPHA: f32 = 1e-3;

/// Kulla–Conty / Filament / Cocco et al.: (α_t, α_b) = r²(1 ± η).
pub fn kulla_conty(r: f32, eta: f32) -> (f32, f32) {
    let a = r * r;
    (a * (1.0 + eta), a * (1.0 - eta))
}

/// Inverse of [`kulla_conty`]: r = √((α_t+α_b)/2), η = (α_t−α_b)/(α_t+α_b).
pub fn kulla_conty_inverse(alpha_t: f32, alpha_b: f32) -> (f32, f32) {
    let s = alpha_t + alpha_b;
    if s <= 0.0 {
        return (0.0, 0.0);
    }
    ((0.5 * s).sqrt(), (alpha_t - alpha_b) / s)
}

/// KHR_materials_anisotropy: (r_k, s) → (α_t, α_b) = (mix(r_k², 1, s²), r_k²).
pub fn khr(r_k: f32, strength: f32) -> (f32, f32) {
    let a = r_k * r_k;
    (a + (1.0 - a) * strength * strength, a)
}

/// Inverse of [`khr`] for α_t ≥ α_b: r_k = √α_b, s = √((α_t−α_b)/(1−α_b)). KHR cannot
/// hold α_t > 1 (s would exceed 1): s is clamped to 1, so such lobes come back narrower.
/// For α_t < α_b the caller swaps the axes (KHR turns the direction by 90° instead).
pub fn khr_inverse(alpha_t: f32, alpha_b: f32) -> (f32, f32) {
    let rk = alpha_b.max(0.0).sqrt();
    let den = (1.0 - alpha_b).max(1e-12);
    let s = ((alpha_t - alpha_b).max(0.0) / den).sqrt().min(1.0);
    (rk, s)
}

/// The isotropic perceptual roughness an engine reads for an anisotropic lobe: √((α_t+α_b)/2)
/// (Cocco et al. 2024's h1, equal to r under Kulla–Conty).
pub fn iso_roughness(alpha_t: f32, alpha_b: f32) -> f32 {
    (0.5 * (alpha_t + alpha_b)).max(0.0).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn conversions_round_trip() {
        for r in [0.05f32, 0.2, 0.5, 0.7, 1.0] {
            for eta in [-0.95f32, -0.5, 0.0, 0.3, 0.8, 0.95] {
                let (at, ab) = kulla_conty(r, eta);
                let (r2, e2) = kulla_conty_inverse(at, ab);
                assert!(
                    (r2 - r).abs() < 1e-6 && (e2 - eta).abs() < 1e-5,
                    "{r} {eta}"
                );
                // KHR holds the lobe when α_t ≤ 1 (with the axes ordered).
                let (hi, lo) = if at >= ab { (at, ab) } else { (ab, at) };
                let (rk, s) = khr_inverse(hi, lo);
                let (at2, ab2) = khr(rk, s);
                if hi <= 1.0 {
                    assert!(
                        (at2 - hi).abs() < 1e-5 && (ab2 - lo).abs() < 1e-6,
                        "{r} {eta}"
                    );
                } else {
                    assert!(at2 <= 1.0 + 1e-6 && (ab2 - lo).abs() < 1e-6);
                }
            }
        }
        assert_eq!(iso_roughness(0.25, 0.25), 0.5);
    }
}
