//! Beckmann, isotropic and the anisotropic normalised model of Kurt, Szirmay-Kalos and
//! Křivánek (Kurt et al. 2010, eqs. 4–7, sampling eqs. 16–18, 20), with its Smith Λ (Walter et al.
//! 2007 eq. 27 with the projected roughness of Heitz 2014 eq. 80) and visible-normal
//! sampling (Heitz & d'Eon 2014, the slope-space inversion).
//!
//! Kurt's m_x, m_y are the α_x, α_y here.
//!
//! Erratum (Kurt et al. 2010 eq. 17): φ_h = arctan((m_y/m_x) tan(2πξ₂)) returns only (−π/2, π/2), so
//! taken literally it samples half of the azimuths twice; φ_h must lie in the quadrant of
//! 2πξ₂, i.e. φ_h = atan2(m_y sin 2πξ₂, m_x cos 2πξ₂), which is what Ward's sampling (and
//! Walter's notes the paper cites) intends. With that fix the density is exactly eq. 20's
//! D(h) cos θ_h. (Eq. 21's weight also carries a stray (ω_i·n)^{1−α}: the ratio of eq. 10 ×
//! (ω_i·n) to eq. 20 is k_s F / (cos θ_h (ω_o·n)^α); we do not use eq. 21.)

use crate::microfacet::{azimuth_fraction, Microfacet};
use crate::special::erfc;
use glam::Vec3;
use std::f64::consts::PI;

/// Anisotropic Beckmann with roughness α_x (tangent) and α_y (bitangent).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Beckmann {
    /// Roughness α_x along the tangent.
    pub alpha_x: f32,
    /// Roughness α_y along the bitangent.
    pub alpha_y: f32,
}

impl Beckmann {
    /// The distribution with roughness α_x (tangent) and α_y (bitangent).
    pub fn new(alpha_x: f32, alpha_y: f32) -> Self {
        Beckmann { alpha_x, alpha_y }
    }
    /// The isotropic distribution, α_x = α_y = α.
    pub fn isotropic(alpha: f32) -> Self {
        Beckmann {
            alpha_x: alpha,
            alpha_y: alpha,
        }
    }
}

/// Smith Λ of the Beckmann profile as a function of a = 1/(α_v tan θ_v) (Walter et al. 2007
/// eq. 27 in Λ form): (erf(a) − 1)/2 + exp(−a²)/(2a√π).
pub(crate) fn lambda_beckmann(a: f64) -> f64 {
    if a <= 0.0 {
        return f64::INFINITY;
    }
    if a > 6.0 {
        // Below 1e-17: both terms cancel to rounding.
        return 0.0;
    }
    ((-a * a).exp() / (a * PI.sqrt()) - erfc(a)) * 0.5
}

impl Microfacet for Beckmann {
    /// Kurt et al. 2010 eqs. 4–5: D(h) = exp(−tan²θ (cos²φ/m_x² + sin²φ/m_y²)) / (π m_x m_y cos⁴θ),
    /// written with the components of h: exp(−(h_x²/m_x² + h_y²/m_y²)/h_z²).
    fn d(&self, m: Vec3) -> f32 {
        if m.z <= 0.0 {
            return 0.0;
        }
        let (ax, ay) = (self.alpha_x as f64, self.alpha_y as f64);
        let (x, y, z) = (m.x as f64 / ax, m.y as f64 / ay, m.z as f64);
        let z2 = z * z;
        let q = (-(x * x + y * y) / z2).exp();
        (q / (PI * ax * ay * z2 * z2)) as f32
    }

    fn lambda(&self, v: Vec3) -> f32 {
        if v.z <= 0.0 {
            return f32::INFINITY;
        }
        let (ax, ay) = (self.alpha_x as f64, self.alpha_y as f64);
        let (x, y, z) = (v.x as f64, v.y as f64, v.z as f64);
        let t = (ax * ax * x * x + ay * ay * y * y).sqrt();
        if t <= 0.0 {
            return 0.0;
        }
        lambda_beckmann(z / t) as f32
    }

    /// Kurt et al. 2010 eqs. 16–18 (with the quadrant fix of eq. 17): tan²θ (cos²φ/m_x² + sin²φ/m_y²)
    /// = −ln u1, φ = atan2(m_y sin 2πu2, m_x cos 2πu2). Written as the unnormalised normal
    /// (m_x √(−ln u1) cos 2πu2, m_y √(−ln u1) sin 2πu2, 1); u1 = 0 gives the horizon.
    fn sample_d(&self, u1: f32, u2: f32) -> Vec3 {
        let u1 = (u1 as f64).clamp(0.0, 1.0);
        let r2 = -u1.ln(); // ∞ at u1 = 0
        let psi = std::f64::consts::TAU * u2 as f64;
        let (s, c) = psi.sin_cos();
        let (ax, ay) = (self.alpha_x as f64, self.alpha_y as f64);
        let m = if r2.is_finite() {
            let r = r2.max(0.0).sqrt();
            [ax * r * c, ay * r * s, 1.0]
        } else {
            [ax * c, ay * s, 0.0]
        };
        let l = (m[0] * m[0] + m[1] * m[1] + m[2] * m[2]).sqrt();
        Vec3::new((m[0] / l) as f32, (m[1] / l) as f32, (m[2] / l) as f32)
    }

    fn invert_d(&self, m: Vec3) -> (f32, f32) {
        let sx = m.x as f64 / (self.alpha_x as f64 * m.z as f64);
        let sy = m.y as f64 / (self.alpha_y as f64 * m.z as f64);
        let u1 = (-(sx * sx + sy * sy)).exp();
        let u2 = azimuth_fraction(
            m.y as f64 / self.alpha_y as f64,
            m.x as f64 / self.alpha_x as f64,
        );
        (u1.clamp(0.0, 1.0) as f32, u2 as f32)
    }

    /// Heitz & d'Eon 2014 ("Importance Sampling Microfacet-Based BSDFs using the Distribution
    /// of Visible Normals", Appendix B): stretch v to α = 1, sample the visible slope
    /// distribution of the standard Beckmann P22 (x̃ by inverting its conditional CDF with
    /// Newton–bisection, ỹ Gaussian), rotate by φ_v and unstretch.
    fn sample_visible(&self, v: Vec3, u1: f32, u2: f32) -> Option<Vec3> {
        let (ax, ay) = (self.alpha_x as f64, self.alpha_y as f64);
        let w = [ax * v.x as f64, ay * v.y as f64, v.z as f64];
        let len = (w[0] * w[0] + w[1] * w[1] + w[2] * w[2]).sqrt();
        let w = [w[0] / len, w[1] / len, w[2] / len];
        let sin_t = (w[0] * w[0] + w[1] * w[1]).sqrt();
        let (cos_phi, sin_phi) = if sin_t > 0.0 {
            (w[0] / sin_t, w[1] / sin_t)
        } else {
            (1.0, 0.0)
        };
        let (sx, sy) = beckmann_visible_slopes(w[2], sin_t, u1 as f64, u2 as f64);
        // Rotate by φ_v, unstretch, and turn slopes into a normal (−x̃, −ỹ, 1).
        let tx = cos_phi * sx - sin_phi * sy;
        let ty = sin_phi * sx + cos_phi * sy;
        let m = [-tx * ax, -ty * ay, 1.0];
        let l = (m[0] * m[0] + m[1] * m[1] + 1.0).sqrt();
        Some(Vec3::new(
            (m[0] / l) as f32,
            (m[1] / l) as f32,
            (1.0 / l) as f32,
        ))
    }
}

/// Visible slopes of the standard (α = 1) Beckmann surface seen from polar angle θ
/// (cos θ, sin θ given), Heitz & d'Eon 2014 Appendix B: x̃ from the conditional CDF
/// C(x̃) = (erfc-based) with a bracketed Newton iteration, ỹ = erf⁻¹(2u2 − 1).
fn beckmann_visible_slopes(cos_t: f64, sin_t: f64, u1: f64, u2: f64) -> (f64, f64) {
    let u1 = u1.clamp(1e-12, 1.0 - 1e-12);
    let u2 = u2.clamp(1e-12, 1.0 - 1e-12);
    let sqrt_pi_inv = 1.0 / PI.sqrt();
    // Normal incidence: the visible slopes are the slopes (2D Gaussian, variance 1/2).
    if sin_t < 1e-6 {
        let r = (-u1.ln()).sqrt();
        let phi = std::f64::consts::TAU * u2;
        return (r * phi.cos(), r * phi.sin());
    }
    let cot = cos_t / sin_t;
    // The visible x̃ density ∝ max(0, cot θ − x̃) e^{−x̃²} (a facet (−x̃, −ỹ, 1) seen from
    // (sin θ, 0, cos θ) projects ∝ cot θ − x̃); its CDF, divided by √π, is
    // F(x) = [cot θ (1 + erf x)/2 + e^{−x²}/(2√π)] / norm with norm = F's numerator at cot θ.
    let norm = 0.5 * cot * (2.0 - erfc(cot)) + 0.5 * sqrt_pi_inv * (-cot * cot).exp();
    let cdf = |x: f64| (0.5 * cot * (2.0 - erfc(x)) + 0.5 * sqrt_pi_inv * (-x * x).exp()) / norm;
    let pdf = |x: f64| (cot - x).max(0.0) * (-x * x).exp() * sqrt_pi_inv / norm;
    // Bracket [lo, cot]: cdf(cot) = 1, cdf(−∞) = 0.
    let (mut lo, mut hi) = (-8.0f64, cot);
    let mut x = 0.5 * (lo + hi);
    for _ in 0..100 {
        let f = cdf(x) - u1;
        if f > 0.0 {
            hi = x;
        } else {
            lo = x;
        }
        let p = pdf(x);
        let mut nx = if p > 0.0 { x - f / p } else { 0.5 * (lo + hi) };
        if !(nx > lo && nx < hi) {
            nx = 0.5 * (lo + hi);
        }
        if (nx - x).abs() < 1e-12 * (1.0 + x.abs()) {
            x = nx;
            break;
        }
        x = nx;
    }
    // ỹ: Gaussian slope with variance 1/2, i.e. erf⁻¹(2u2−1).
    let y = inverse_erf(2.0 * u2 - 1.0);
    (x, y)
}

/// erf⁻¹(y) for y ∈ (−1, 1): Giles' single-precision approximation refined by two Newton
/// steps on erf.
fn inverse_erf(y: f64) -> f64 {
    let w = -((1.0 - y) * (1.0 + y)).ln();
    let mut x = if w < 5.0 {
        let w = w - 2.5;
        let mut p = 2.810_226_36e-08;
        for c in [
            3.432_739_39e-07,
            -3.523_387_7e-06,
            -4.391_506_54e-06,
            0.000_218_580_87,
            -0.001_253_725_03,
            -0.004_177_681_64,
            0.246_640_727,
            1.501_409_41,
        ] {
            p = c + p * w;
        }
        p * y
    } else {
        let w = w.sqrt() - 3.0;
        let mut p = -0.000_200_214_257;
        for c in [
            0.000_100_950_558,
            0.001_349_343_22,
            -0.003_673_428_44,
            0.005_739_507_73,
            -0.007_622_461_3,
            0.009_438_870_47,
            1.001_674_06,
            2.832_976_82,
        ] {
            p = c + p * w;
        }
        p * y
    };
    for _ in 0..2 {
        let e = crate::special::erf(x) - y;
        x -= e / (2.0 / PI.sqrt() * (-x * x).exp());
    }
    x
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::validation::*;
    use ibl_core::sampling::Pcg32;

    #[test]
    fn beckmann_normalisation_and_weak_furnace() {
        let mut rng = Pcg32::new(21, 3);
        for case in 0..6 {
            let (ax, ay) = if case == 0 {
                (1e-3, 2e-3)
            } else {
                (0.02 + 1.2 * rng.next_f32(), 0.02 + 1.2 * rng.next_f32())
            };
            let b = Beckmann::new(ax, ay);
            let scale = [ax as f64, ay as f64];
            let norm = normalisation(&b, scale);
            eprintln!("Beckmann ({ax:.3},{ay:.3}): ∫D(n·m) = {norm:.6}");
            assert!((norm - 1.0).abs() < 1e-3);
            for _ in 0..3 {
                let v = random_direction(&mut rng);
                let (got, want) = weak_furnace(&b, v, scale);
                eprintln!("  v.z {:.3}: furnace {got:.6} vs {want:.6}", v.z);
                assert!((got - want).abs() < 1e-3);
            }
        }
    }

    #[test]
    fn beckmann_sampling_matches_pdf() {
        let b = Beckmann::new(0.2, 0.6);
        chi2_test(|u1, u2| b.sample_d(u1, u2), |m| b.pdf_d(m), [0.2, 0.6], 1);
        round_trip(&b, 2);
        for v in [
            Vec3::new(0.6, 0.3, 0.742).normalize(),
            Vec3::new(0.0, 0.0, 1.0),
            Vec3::new(0.99, 0.0, 0.141).normalize(),
        ] {
            chi2_test(
                |u1, u2| b.sample_visible(v, u1, u2).unwrap(),
                |m| b.pdf_visible(v, m),
                [0.2, 0.6],
                3,
            );
        }
    }

    #[test]
    fn quadrant_fix_of_eq_17_matters() {
        // The literal eq. 17 (arctan, no quadrant) never produces φ in (π/2, 3π/2); with the
        // fix, φ follows the quadrant of 2πu2, so exactly half of a uniform u2 grid samples
        // m.x < 0.
        let b = Beckmann::new(0.3, 0.15);
        let mut left_fixed = 0;
        for k in 0..1000 {
            let u2 = (k as f64 + 0.5) / 1000.0;
            if b.sample_d(0.5, u2 as f32).x < 0.0 {
                left_fixed += 1;
            }
        }
        assert_eq!(left_fixed, 500);
    }

    #[test]
    fn end_points_are_finite() {
        for (ax, ay) in [(1e-4f32, 1e-4f32), (1.0, 0.01), (2.0, 2.0)] {
            let b = Beckmann::new(ax, ay);
            for (u1, u2) in [(0.0, 0.0), (1.0, 1.0), (0.0, 1.0), (1.0, 0.0)] {
                let m = b.sample_d(u1, u2);
                assert!(m.is_finite() && m.z >= 0.0, "{m}");
                let v = Vec3::new(0.8, 0.0, 0.6);
                assert!(b.sample_visible(v, u1, u2).unwrap().is_finite());
                assert!(b.pdf_d(m).is_finite());
            }
            assert!(b.lambda(Vec3::new(1.0, 0.0, 0.0)).is_infinite());
            assert_eq!(b.g1(Vec3::new(1.0, 0.0, 0.0), Vec3::Z), 0.0);
        }
        assert!((inverse_erf(crate::special::erf(0.7)) - 0.7).abs() < 1e-7);
    }
}
