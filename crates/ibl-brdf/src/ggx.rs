//! GGX / Trowbridge-Reitz (Walter et al. 2007), isotropic and anisotropic: D, Smith Λ, G1,
//! height-correlated G2 and the visibility V = G2/(4 n·v n·l), sampling of D(h)(n·h) and of
//! visible normals (Heitz 2018). Tangent space has the normal on +z. `alpha` is the GGX
//! α = roughness²; it must be > 0 (α = 0 is a delta, callers clamp it).
//!
//! The isotropic free functions take cosines (the forms the LUT and prefilter loops want);
//! [`Ggx`] is the anisotropic (α_x, α_y) distribution behind the [`Microfacet`] trait.

use crate::microfacet::{azimuth_fraction, Microfacet};
use glam::Vec3;
use std::f32::consts::PI;

/// D_GGX(h) = α² / (π ((n·h)²(α²−1)+1)²) (Walter et al. 2007, eq. 33).
///
/// The denominator is evaluated as (1 − (n·h)²) + α²(n·h)², which is the same number but keeps
/// α² when it is below the f32 spacing of 1 (α < 2.4e-4), where the printed form returns ∞.
#[inline]
pub fn d_ggx(n_dot_h: f32, alpha: f32) -> f32 {
    let a2 = alpha * alpha;
    let c2 = n_dot_h * n_dot_h;
    let t = (1.0 - c2) + a2 * c2;
    a2 / (PI * t * t)
}

/// Samples h ∝ D(h)(n·h) from (u1, u2) ∈ [0,1]²: cos²θ = (1−u1)/(1+(α²−1)u1), φ = 2π u2
/// (Walter et al. 2007, eqs. 35–36).
#[inline]
pub fn sample_ggx_d(u1: f32, u2: f32, alpha: f32) -> Vec3 {
    let a2 = alpha as f64 * alpha as f64;
    let u1 = (u1 as f64).clamp(0.0, 1.0);
    // cos²θ and sin²θ over the common denominator (1−u1) + α²u1, each without cancellation.
    let den = (1.0 - u1) + a2 * u1;
    let (cos2, sin2) = if den > 0.0 {
        ((1.0 - u1) / den, a2 * u1 / den)
    } else {
        (1.0, 0.0)
    };
    let phi = std::f64::consts::TAU * u2 as f64;
    let (s, c) = phi.sin_cos();
    let sin_t = sin2.sqrt();
    Vec3::new((sin_t * c) as f32, (sin_t * s) as f32, cos2.sqrt() as f32)
}

#[cfg(test)]
/// Density of [`sample_ggx_d`] with respect to solid angle of h: D(h)(n·h).
#[inline]
pub(crate) fn pdf_ggx_d(n_dot_h: f32, alpha: f32) -> f32 {
    d_ggx(n_dot_h, alpha) * n_dot_h
}

#[cfg(test)]
/// Inverse of [`sample_ggx_d`]: the (u1, u2) that produce h (h.z > 0).
#[inline]
pub(crate) fn invert_ggx_d(h: Vec3, alpha: f32) -> (f32, f32) {
    let a2 = alpha as f64 * alpha as f64;
    let s2 = h.x as f64 * h.x as f64 + h.y as f64 * h.y as f64;
    let c2 = h.z as f64 * h.z as f64;
    // From cos²θ = (1−u1)/((1−u1)+α²u1): u1 = sin²θ / (sin²θ + α² cos²θ).
    let den = s2 + a2 * c2;
    let u1 = if den > 0.0 { s2 / den } else { 0.0 };
    let u2 = azimuth_fraction(h.y as f64, h.x as f64);
    (u1.clamp(0.0, 1.0) as f32, u2 as f32)
}

/// Smith Λ for isotropic GGX (Heitz 2014, eq. 72): (−1 + sqrt(1 + α² tan²θ)) / 2, written
/// as a/(2(1+sqrt(1+a))) with a = α² tan²θ so it keeps full precision for small α and is ∞
/// (not NaN) at cos θ = 0.
#[inline]
pub fn lambda(cos_theta: f32, alpha: f32) -> f32 {
    let c2 = cos_theta * cos_theta;
    if c2 <= 0.0 {
        return f32::INFINITY;
    }
    let a = alpha * alpha * (1.0 - c2).max(0.0) / c2;
    a / (2.0 * (1.0 + (1.0 + a).sqrt()))
}

/// Smith masking G1 = 1/(1+Λ) for isotropic GGX (Heitz 2014, eq. 43), in the form
/// 2c / (c + sqrt(c² + α²(1−c²))) which is exact (0) at c = 0.
#[inline]
pub fn g1(cos_theta: f32, alpha: f32) -> f32 {
    let c = cos_theta.max(0.0);
    let c2 = c * c;
    let s = (c2 + alpha * alpha * (1.0 - c2)).sqrt();
    if c + s <= 0.0 {
        return 0.0;
    }
    2.0 * c / (c + s)
}

/// Height-correlated Smith G2 = 1/(1 + Λ(v) + Λ(l)) for isotropic GGX (Heitz 2014, eq. 99),
/// 0 when either direction is at or below the horizon.
#[inline]
pub fn g2(n_dot_v: f32, n_dot_l: f32, alpha: f32) -> f32 {
    if n_dot_v <= 0.0 || n_dot_l <= 0.0 {
        return 0.0;
    }
    4.0 * n_dot_v * n_dot_l * v_smith(n_dot_v, n_dot_l, alpha)
}

/// The visibility V = G2/(4 n·v n·l) of Silvennoinen et al. 2025 eq. 3 for height-correlated GGX:
/// 0.5 / (n·l sqrt(n·v²(1−α²)+α²) + n·v sqrt(n·l²(1−α²)+α²)) (Heitz 2014; Filament),
/// finite at grazing angles and 0 when both cosines are 0.
#[inline]
pub(crate) fn v_smith(n_dot_v: f32, n_dot_l: f32, alpha: f32) -> f32 {
    let a2 = alpha * alpha;
    let gv = n_dot_l * (n_dot_v * n_dot_v * (1.0 - a2) + a2).sqrt();
    let gl = n_dot_v * (n_dot_l * n_dot_l * (1.0 - a2) + a2).sqrt();
    let d = gv + gl;
    if d <= 0.0 {
        0.0
    } else {
        0.5 / d
    }
}

/// The Fresnel-free GGX BRDF f_DV = D(h) V(v, l) (Silvennoinen et al. 2025 eq. 8) in tangent space.
#[inline]
pub fn f_dv(v: Vec3, l: Vec3, alpha: f32) -> f32 {
    if v.z <= 0.0 || l.z <= 0.0 {
        return 0.0;
    }
    let h = (v + l).normalize_or_zero();
    d_ggx(h.z, alpha) * v_smith(v.z, l.z, alpha)
}

/// Samples an isotropic GGX visible normal for view `v` (v.z > 0) from (u1, u2) ∈ [0,1]²
/// (Heitz 2018, listing 1): h ~ G1(v) max(0, v·h) D(h) / (n·v).
#[inline]
pub fn sample_vndf(v: Vec3, u1: f32, u2: f32, alpha: f32) -> Vec3 {
    sample_vndf_aniso(v, u1, u2, alpha, alpha)
}

#[cfg(test)]
/// Density of [`sample_vndf`]: G1(v) max(0, v·h) D(h) / (n·v).
#[inline]
pub(crate) fn pdf_vndf(v: Vec3, h: Vec3, alpha: f32) -> f32 {
    if v.z <= 0.0 || h.z <= 0.0 {
        return 0.0;
    }
    g1(v.z, alpha) * v.dot(h).max(0.0) * d_ggx(h.z, alpha) / v.z
}

/// Density of the reflected direction l = 2(v·h)h − v when h ~ [`sample_vndf`]: the Jacobian
/// 1/(4 v·h) turns D_v into G1(v) D(h) / (4 n·v).
#[inline]
pub fn pdf_vndf_reflected(v: Vec3, h: Vec3, alpha: f32) -> f32 {
    if v.z <= 0.0 || h.z <= 0.0 || v.dot(h) <= 0.0 {
        return 0.0;
    }
    g1(v.z, alpha) * d_ggx(h.z, alpha) / (4.0 * v.z)
}

/// Heitz 2018, "Sampling the GGX Distribution of Visible Normals", listing 1, for (α_x, α_y):
/// stretch v to the α = 1 configuration, sample the projected hemisphere as a disk warped
/// towards the visible half, and unstretch the normal.
pub(crate) fn sample_vndf_aniso(v: Vec3, u1: f32, u2: f32, alpha_x: f32, alpha_y: f32) -> Vec3 {
    let (ax, ay) = (alpha_x as f64, alpha_y as f64);
    let vh = [ax * v.x as f64, ay * v.y as f64, v.z as f64];
    let len = (vh[0] * vh[0] + vh[1] * vh[1] + vh[2] * vh[2]).sqrt();
    let vh = [vh[0] / len, vh[1] / len, vh[2] / len];
    let lensq = vh[0] * vh[0] + vh[1] * vh[1];
    let t1 = if lensq > 0.0 {
        let inv = 1.0 / lensq.sqrt();
        [-vh[1] * inv, vh[0] * inv, 0.0]
    } else {
        [1.0, 0.0, 0.0]
    };
    let t2 = [
        vh[1] * t1[2] - vh[2] * t1[1],
        vh[2] * t1[0] - vh[0] * t1[2],
        vh[0] * t1[1] - vh[1] * t1[0],
    ];
    let r = (u1 as f64).clamp(0.0, 1.0).sqrt();
    let phi = std::f64::consts::TAU * u2 as f64;
    let p1 = r * phi.cos();
    let mut p2 = r * phi.sin();
    let s = 0.5 * (1.0 + vh[2]);
    p2 = (1.0 - s) * (1.0 - p1 * p1).max(0.0).sqrt() + s * p2;
    let pz = (1.0 - p1 * p1 - p2 * p2).max(0.0).sqrt();
    let nh = [
        p1 * t1[0] + p2 * t2[0] + pz * vh[0],
        p1 * t1[1] + p2 * t2[1] + pz * vh[1],
        p1 * t1[2] + p2 * t2[2] + pz * vh[2],
    ];
    let ne = [ax * nh[0], ay * nh[1], nh[2].max(0.0)];
    let l = (ne[0] * ne[0] + ne[1] * ne[1] + ne[2] * ne[2]).sqrt();
    if l > 0.0 {
        Vec3::new((ne[0] / l) as f32, (ne[1] / l) as f32, (ne[2] / l) as f32)
    } else {
        Vec3::Z
    }
}

/// Anisotropic GGX with roughness α_x along the tangent and α_y along the bitangent
/// (Heitz 2014 §5.2; Atanasov et al. 2022 eq. 7 with the GGX profile). `Ggx::isotropic(α)` is the
/// distribution of [`d_ggx`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ggx {
    /// Roughness α_x along the tangent (α = r², r the perceptual roughness).
    pub alpha_x: f32,
    /// Roughness α_y along the bitangent.
    pub alpha_y: f32,
}

impl Ggx {
    /// The distribution with roughness α_x (tangent) and α_y (bitangent).
    pub fn new(alpha_x: f32, alpha_y: f32) -> Self {
        Ggx { alpha_x, alpha_y }
    }
    /// The isotropic distribution, α_x = α_y = α.
    pub fn isotropic(alpha: f32) -> Self {
        Ggx {
            alpha_x: alpha,
            alpha_y: alpha,
        }
    }
}

impl Microfacet for Ggx {
    /// D(m) = 1 / (π α_x α_y (m_x²/α_x² + m_y²/α_y² + m_z²)²) (Heitz 2014 eq. 85).
    fn d(&self, m: Vec3) -> f32 {
        if m.z <= 0.0 {
            return 0.0;
        }
        let (ax, ay) = (self.alpha_x as f64, self.alpha_y as f64);
        let (x, y, z) = (m.x as f64 / ax, m.y as f64 / ay, m.z as f64);
        let t = x * x + y * y + z * z;
        (1.0 / (std::f64::consts::PI * ax * ay * t * t)) as f32
    }

    /// Λ(v) = (−1 + sqrt(1 + (α_x² v_x² + α_y² v_y²)/v_z²)) / 2 (Heitz 2014 eqs. 72, 80).
    fn lambda(&self, v: Vec3) -> f32 {
        if v.z <= 0.0 {
            return f32::INFINITY;
        }
        let (ax, ay) = (self.alpha_x as f64, self.alpha_y as f64);
        let (x, y, z) = (v.x as f64, v.y as f64, v.z as f64);
        let a = (ax * ax * x * x + ay * ay * y * y) / (z * z);
        (a / (2.0 * (1.0 + (1.0 + a).sqrt()))) as f32
    }

    /// Slope-space sampling: the α = 1 slope radius tan²θ = u1/(1−u1) at φ = 2π u2, stretched
    /// by (α_x, α_y) (Heitz 2014 §5.3); written as the unnormalised normal
    /// (α_x √u1 cos φ, α_y √u1 sin φ, √(1−u1)), finite at u1 = 1.
    fn sample_d(&self, u1: f32, u2: f32) -> Vec3 {
        let u1 = (u1 as f64).clamp(0.0, 1.0);
        let phi = std::f64::consts::TAU * u2 as f64;
        let (s, c) = phi.sin_cos();
        let r = u1.sqrt();
        let m = [
            self.alpha_x as f64 * r * c,
            self.alpha_y as f64 * r * s,
            (1.0 - u1).sqrt(),
        ];
        let l = (m[0] * m[0] + m[1] * m[1] + m[2] * m[2]).sqrt();
        if l > 0.0 {
            Vec3::new((m[0] / l) as f32, (m[1] / l) as f32, (m[2] / l) as f32)
        } else {
            Vec3::Z
        }
    }

    fn invert_d(&self, m: Vec3) -> (f32, f32) {
        let sx = m.x as f64 / self.alpha_x as f64;
        let sy = m.y as f64 / self.alpha_y as f64;
        let x = sx * sx + sy * sy;
        let z = m.z as f64 * m.z as f64;
        let u1 = if x + z > 0.0 { x / (x + z) } else { 0.0 };
        (u1.clamp(0.0, 1.0) as f32, azimuth_fraction(sy, sx) as f32)
    }

    fn sample_visible(&self, v: Vec3, u1: f32, u2: f32) -> Option<Vec3> {
        Some(sample_vndf_aniso(v, u1, u2, self.alpha_x, self.alpha_y))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::validation::*;
    use ibl_core::sampling::{hammersley, Pcg32};

    #[test]
    fn isotropic_free_functions_agree_with_the_struct() {
        let mut rng = Pcg32::new(3, 1);
        // Worst |Δh|, relative ΔD × α² / ε_f32, ΔΛ/(1+Λ), |Δu| of the inverse.
        let mut worst = [0.0f32; 4];
        for _ in 0..2000 {
            let alpha = 0.02 + 0.98 * rng.next_f32();
            let g = Ggx::isotropic(alpha);
            let (u1, u2) = (rng.next_f32(), rng.next_f32());
            let h = sample_ggx_d(u1, u2, alpha);
            let h2 = g.sample_d(u1, u2);
            worst[0] = worst[0].max((h - h2).length());
            let rel = |a: f32, b: f32| (a - b).abs() / b.abs().max(1e-6);
            // d_ggx's base (1 − (n·h)²) + α²(n·h)² ≥ α² carries the f32 rounding of (n·h)²
            // (~ε), so D (∝ base⁻²) differs from the f64 struct by up to ~2ε/α² relative.
            let rel_d = rel(d_ggx(h.z, alpha), g.d(h));
            worst[1] = worst[1].max(rel_d * alpha * alpha / f32::EPSILON);
            let v = random_direction(&mut rng);
            worst[2] = worst[2].max((lambda(v.z, alpha) - g.lambda(v)).abs() / (1.0 + g.lambda(v)));
            let (a, b) = invert_ggx_d(h, alpha);
            worst[3] = worst[3].max((a - u1).abs().max((b - u2).abs().min(1.0 - (b - u2).abs())));
        }
        eprintln!(
            "free functions vs Ggx struct: worst |Δh| {:.2e}, rel ΔD {:.2} ε/α², \
             ΔΛ/(1+Λ) {:.2e}, |Δu| {:.2e}",
            worst[0], worst[1], worst[2], worst[3]
        );
        // Both sides are the same formulas in f32 / f64, so the differences are f32 rounding:
        // measured |Δh| 0, ΔD 2.0 ε/α² (1.8e-4 relative at α = 0.02), ΔΛ 1.4e-7, |Δu| 6e-8.
        assert!(
            worst[0] < 1e-6 && worst[2] < 1e-6 && worst[3] < 1e-6,
            "{worst:?}"
        );
        assert!(worst[1] < 3.0, "D differs by {} ε/α²", worst[1]);
    }

    #[test]
    fn tiny_alpha_and_end_points_are_finite() {
        for alpha in [1e-6f32, 1e-4, 1e-2, 1.0] {
            assert!(
                d_ggx(1.0, alpha).is_finite() && d_ggx(1.0, alpha) > 0.0,
                "{alpha}"
            );
            for (u1, u2) in [(0.0, 0.0), (1.0, 1.0), (0.0, 1.0), (1.0, 0.0), (0.5, 0.25)] {
                let h = sample_ggx_d(u1, u2, alpha);
                assert!(
                    h.is_finite() && (h.length() - 1.0).abs() < 1e-5,
                    "{alpha} {u1} {u2} {h}"
                );
                let g = Ggx::new(alpha, 0.5 * alpha + 1e-3);
                let m = g.sample_d(u1, u2);
                assert!(m.is_finite() && (m.length() - 1.0).abs() < 1e-5);
                let v = Vec3::new(0.6, 0.0, 0.8);
                assert!(g.sample_visible(v, u1, u2).unwrap().is_finite());
            }
            assert!(lambda(0.0, alpha).is_infinite() && g1(0.0, alpha) == 0.0);
            assert!(v_smith(0.0, 0.0, alpha).is_finite());
        }
    }

    #[test]
    fn ggx_normalisation_and_weak_furnace() {
        let mut rng = Pcg32::new(11, 2);
        for case in 0..6 {
            let (ax, ay) = if case == 0 {
                (1e-3, 1e-3)
            } else {
                (0.02 + rng.next_f32(), 0.02 + rng.next_f32())
            };
            let g = Ggx::new(ax, ay);
            let scale = [ax as f64, ay as f64];
            let norm = normalisation(&g, scale);
            eprintln!("GGX ({ax:.3},{ay:.3}): ∫D(n·m) = {norm:.6}");
            assert!((norm - 1.0).abs() < 1e-3, "{norm}");
            for _ in 0..3 {
                let v = random_direction(&mut rng);
                let (got, want) = weak_furnace(&g, v, scale);
                eprintln!(
                    "  v.z {:.3}: ∫D G1 max(v·m,0) = {got:.6} vs v·n {want:.6}",
                    v.z
                );
                assert!((got - want).abs() < 1e-3);
            }
        }
    }

    #[test]
    fn ggx_sampling_matches_pdf() {
        let g = Ggx::new(0.3, 0.7);
        chi2_test(|u1, u2| g.sample_d(u1, u2), |m| g.pdf_d(m), [0.3, 0.7], 5);
        let v = Vec3::new(0.7, -0.3, 0.648).normalize();
        chi2_test(
            |u1, u2| g.sample_visible(v, u1, u2).unwrap(),
            |m| g.pdf_visible(v, m),
            [0.3, 0.7],
            6,
        );
        let iso = 0.15;
        chi2_test(
            |u1, u2| sample_ggx_d(u1, u2, iso),
            |m| pdf_ggx_d(m.z, iso),
            [0.15, 0.15],
            7,
        );
        round_trip(&g, 8);
    }

    // The isotropic free functions as the SH-exp and split-sum code uses them: D and the
    // visible-normal density normalised, G1/G2 from Λ, VNDF samples following their density
    // and the G2/G1 estimator of the directional albedo against quadrature.

    fn polar_dir(theta: f32, phi: f32) -> Vec3 {
        Vec3::new(
            theta.sin() * phi.cos(),
            theta.sin() * phi.sin(),
            theta.cos(),
        )
    }

    /// Riemann sum over the hemisphere in (cos θ, φ): equal-area cells.
    fn hemisphere_riemann(f: impl Fn(Vec3) -> f64, k: usize) -> f64 {
        let mut s = 0.0;
        for a in 0..k {
            let z = (a as f64 + 0.5) / k as f64;
            let st = (1.0 - z * z).sqrt();
            for b in 0..2 * k {
                let phi = std::f64::consts::PI * (b as f64 + 0.5) / k as f64;
                s += f(Vec3::new(
                    (st * phi.cos()) as f32,
                    (st * phi.sin()) as f32,
                    z as f32,
                ));
            }
        }
        s * 2.0 * std::f64::consts::PI / (2 * k * k) as f64
    }

    #[test]
    fn d_is_normalised_and_visible_normals_integrate_to_one() {
        for alpha in [0.2f32, 0.5, 1.0] {
            let nd = hemisphere_riemann(|h| (d_ggx(h.z, alpha) * h.z) as f64, 600);
            assert!((nd - 1.0).abs() < 2e-3, "∫D(n·h) = {nd} at α={alpha}");
            for theta in [0.0f32, 0.7, 1.45] {
                let v = polar_dir(theta, 0.3);
                let dv = hemisphere_riemann(|h| pdf_vndf(v, h, alpha) as f64, 600);
                eprintln!("α={alpha} θv={theta}: ∫D(n·h)={nd:.5} ∫D_v={dv:.5}");
                assert!((dv - 1.0).abs() < 3e-3, "∫D_v = {dv}");
            }
        }
    }

    #[test]
    fn g1_and_g2_match_lambda() {
        for alpha in [0.05f32, 0.3, 1.0] {
            for c in [0.01f32, 0.2, 0.7, 1.0] {
                let want = 1.0 / (1.0 + lambda(c, alpha));
                assert!((g1(c, alpha) - want).abs() < 1e-5, "G1({c},{alpha})");
                for cl in [0.05f32, 0.5, 1.0] {
                    let want = 1.0 / (1.0 + lambda(c, alpha) + lambda(cl, alpha));
                    assert!(
                        (g2(c, cl, alpha) - want).abs() < 1e-5,
                        "G2({c},{cl},{alpha}) {} {want}",
                        g2(c, cl, alpha)
                    );
                }
            }
        }
        assert_eq!(g1(0.0, 0.5), 0.0);
        assert!(v_smith(0.0, 0.5, 0.3).is_finite());
    }

    #[test]
    fn vndf_samples_follow_their_density_chi2() {
        // Bin h over 8×8 (cos θ, φ) cells and compare counts with the integrated pdf.
        let alpha = 0.4;
        let v = polar_dir(1.0, 0.5);
        let (nz, np) = (8usize, 8usize);
        let n = 200_000u32;
        let mut counts = vec![0f64; nz * np];
        for i in 0..n {
            let (u1, u2) = hammersley(i, n);
            let h = sample_vndf(v, u1, u2, alpha);
            let z = ((h.z * nz as f32) as usize).min(nz - 1);
            let mut phi = h.y.atan2(h.x);
            if phi < 0.0 {
                phi += 2.0 * PI;
            }
            let p = ((phi / (2.0 * PI) * np as f32) as usize).min(np - 1);
            counts[z * np + p] += 1.0;
        }
        let mut chi2 = 0.0;
        let k = 60;
        for zc in 0..nz {
            for pc in 0..np {
                // Expected mass of the cell by midpoint quadrature.
                let mut m = 0.0f64;
                for a in 0..k {
                    let z = (zc as f64 + (a as f64 + 0.5) / k as f64) / nz as f64;
                    let st = (1.0 - z * z).sqrt();
                    for b in 0..k {
                        let phi =
                            2.0 * std::f64::consts::PI * (pc as f64 + (b as f64 + 0.5) / k as f64)
                                / np as f64;
                        let h =
                            Vec3::new((st * phi.cos()) as f32, (st * phi.sin()) as f32, z as f32);
                        m += pdf_vndf(v, h, alpha) as f64;
                    }
                }
                let area = 2.0 * std::f64::consts::PI / (nz * np) as f64;
                let e = m / (k * k) as f64 * area * n as f64;
                if e > 5.0 {
                    chi2 += (counts[zc * np + pc] - e).powi(2) / e;
                }
            }
        }
        eprintln!("VNDF χ² over 64 cells = {chi2:.1}");
        assert!(chi2 < 120.0, "χ² = {chi2}");
    }

    #[test]
    fn sampling_is_finite_at_the_edges() {
        for alpha in [1e-4f32, 0.2, 1.0] {
            for v in [
                Vec3::Z,
                polar_dir(std::f32::consts::FRAC_PI_2 - 1e-4, 0.0),
                polar_dir(1.2, 2.0),
            ] {
                for (u1, u2) in [(0.0, 0.0), (0.999_999, 0.999_999), (0.5, 0.0), (0.0, 1.0)] {
                    let h = sample_vndf(v, u1, u2, alpha);
                    assert!(
                        h.is_finite() && (h.length() - 1.0).abs() < 1e-4,
                        "{h} α={alpha} v={v}"
                    );
                    assert!(pdf_vndf_reflected(v, h, alpha).is_finite());
                }
            }
        }
    }

    #[test]
    fn reflected_weight_estimates_the_directional_albedo() {
        // E[G2/G1(v)] under VNDF sampling = ∫ f_DV (n·l) dl: check against brute quadrature.
        let mut rng = Pcg32::new(5, 1);
        for (alpha, theta) in [(0.25f32, 0.3f32), (0.7, 1.2), (1.0, 0.8)] {
            let v = polar_dir(theta, 0.0);
            let n = 200_000;
            let mut s = 0.0f64;
            for _ in 0..n {
                let h = sample_vndf(v, rng.next_f32(), rng.next_f32(), alpha);
                let l = crate::reflect(v, h);
                if l.z > 0.0 {
                    s += (g2(v.z, l.z, alpha) / g1(v.z, alpha)) as f64;
                }
            }
            let mc = s / n as f64;
            let quad = hemisphere_riemann(|l| (f_dv(v, l, alpha) * l.z) as f64, 800);
            eprintln!("α={alpha} θ={theta}: MC {mc:.5} quadrature {quad:.5}");
            assert!((mc - quad).abs() < 4e-3, "{mc} vs {quad}");
        }
    }
}
