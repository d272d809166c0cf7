//! The common interface of microfacet distributions: D, Smith Λ, G1, height-correlated G2,
//! and sampling of D(m)(n·m) (and of visible normals where a closed form exists).
//!
//! Tangent space has the macro-normal n on +z. Every distribution is normalised as Atanasov et al. 2022
//! eq. 3 requires, ∫ D(m)(n·m) dm = 1, and its Λ satisfies the weak white furnace (eq. 2),
//! ∫ D(m) G1(v,m) max(0, v·m) dm = v·n; the unit tests of each module check both.

use glam::Vec3;

/// A microfacet normal distribution with its Smith masking function.
pub trait Microfacet {
    /// D(m), the microfacet normal distribution (per unit solid angle and unit macro-area);
    /// 0 for m.z ≤ 0. `m` must be unit length.
    fn d(&self, m: Vec3) -> f32;

    /// Smith Λ(v) for a unit direction with v.z > 0 (∞ at and below the horizon).
    fn lambda(&self, v: Vec3) -> f32;

    /// Samples m with density D(m)(n·m) (solid angle of m) from (u1, u2) ∈ [0,1]².
    /// Finite for every input, the end points 0 and 1 included.
    fn sample_d(&self, u1: f32, u2: f32) -> Vec3;

    /// Inverse of [`Microfacet::sample_d`]: the (u1, u2) ∈ [0,1]² that produce m (m.z > 0).
    fn invert_d(&self, m: Vec3) -> (f32, f32);

    /// Density of [`Microfacet::sample_d`]: D(m)(n·m).
    fn pdf_d(&self, m: Vec3) -> f32 {
        if m.z <= 0.0 {
            0.0
        } else {
            self.d(m) * m.z
        }
    }

    /// Samples a visible normal, m ~ D_v(m) = G1(v,m) max(0, v·m) D(m) / (v·n) (Atanasov et al. 2022
    /// eq. 27), where the distribution has a closed-form sampler; `None` otherwise.
    fn sample_visible(&self, _v: Vec3, _u1: f32, _u2: f32) -> Option<Vec3> {
        None
    }

    /// Density of [`Microfacet::sample_visible`]: D_v(m) of Atanasov et al. 2022 eq. 27.
    fn pdf_visible(&self, v: Vec3, m: Vec3) -> f32 {
        if v.z <= 0.0 || m.z <= 0.0 {
            return 0.0;
        }
        let vm = v.dot(m);
        if vm <= 0.0 {
            return 0.0;
        }
        self.g1(v, m) * vm * self.d(m) / v.z
    }

    /// Smith monodirectional masking G1(v, m) = χ⁺(v·m / v·n) / (1 + Λ(v)) (Heitz 2014 eq. 43).
    fn g1(&self, v: Vec3, m: Vec3) -> f32 {
        if v.z <= 0.0 || v.dot(m) <= 0.0 {
            return 0.0;
        }
        1.0 / (1.0 + self.lambda(v))
    }

    /// Height-correlated Smith masking-shadowing G2(v, l, m) = χ⁺ χ⁺ / (1 + Λ(v) + Λ(l))
    /// (Heitz 2014 eq. 99).
    fn g2(&self, v: Vec3, l: Vec3, m: Vec3) -> f32 {
        if v.z <= 0.0 || l.z <= 0.0 || v.dot(m) <= 0.0 || l.dot(m) <= 0.0 {
            return 0.0;
        }
        1.0 / (1.0 + self.lambda(v) + self.lambda(l))
    }
}

/// Mirror reflection of `v` about the unit normal `m`: 2(v·m)m − v.
#[inline]
pub fn reflect(v: Vec3, m: Vec3) -> Vec3 {
    2.0 * v.dot(m) * m - v
}

/// Density of l = reflect(v, h) from the density of h: p_l = p_h / (4 |v·h|)
/// (the half-vector Jacobian, Walter et al. 2007 eq. 14; Marcolongo 2020 §2.4).
#[inline]
pub fn pdf_reflected(pdf_h: f32, v_dot_h: f32) -> f32 {
    let d = 4.0 * v_dot_h.abs();
    if d <= 0.0 {
        0.0
    } else {
        pdf_h / d
    }
}

/// Azimuth of m in [0, 2π) mapped to [0, 1).
#[inline]
pub(crate) fn azimuth_fraction(y: f64, x: f64) -> f64 {
    let mut u = y.atan2(x) / std::f64::consts::TAU;
    if u < 0.0 {
        u += 1.0;
    }
    if u >= 1.0 {
        u = 0.0;
    }
    u
}
