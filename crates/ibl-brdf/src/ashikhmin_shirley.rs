//! The Ashikhmin-Shirley anisotropic Phong half-vector distribution (Ashikhmin & Shirley
//! 2000; Marcolongo 2020 §2.4 and §4.3.2): its half-vector pdf p_h, the thesis's sampling of it (and
//! the inverse), the AS specular BRDF, and the same lobe as a [`Microfacet`] distribution.
//!
//! p_h(h) = √((n_u+1)(n_v+1))/(2π) (n·h)^{e(h)}, e(h) = (n_u (t·h)² + n_v (b·h)²)/(1 − (n·h)²),
//! is a normalised density over the solid angle of h: ∫ p_h dω = 1 because
//! ∫₀^{2π} dφ/((n_u+1)cos²φ + (n_v+1)sin²φ) = 2π/√((n_u+1)(n_v+1)).
//! As a microfacet distribution (Atanasov et al. 2022's D with ∫ D(m)(n·m) dm = 1) this is
//! D_AS(m) = p_h(m)/(n·m) — the normalised form pbrt gives, with exponents shifted by one;
//! Kurt et al. 2010 §2 notes the original AS "D" ignored this cosine. AS has no closed-form Smith Λ,
//! so [`AshikhminShirley`]'s Λ is a numerical integral (a few thousand evaluations: fine for
//! validation and tables of Λ, not for inner loops).
//!
//! All arithmetic is f64: exponents reach 10⁶, where (n·h)^e must be taken as
//! exp(e·ln(1−sin²θ)/2) from the tangential components, not from an f32 n·h.

use crate::microfacet::Microfacet;
use crate::quadrature::gauss_legendre;
use glam::{DVec3, Vec3};
use std::f64::consts::{FRAC_PI_2, PI, TAU};

/// Ashikhmin-Shirley shininess exponents n_u (along the tangent t) and n_v (bitangent b).
/// Sampling and p_h accept any exponents ≥ 0; as a microfacet distribution (D = p_h/(n·m),
/// Λ) they must be ≥ 1, as the thesis requires (§4.3.1: n ≈ 1/α²), so that D stays finite
/// at the horizon.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AshikhminShirley {
    /// Phong exponent n_u along the tangent (x).
    pub nu: f64,
    /// Phong exponent n_v along the bitangent (y).
    pub nv: f64,
}

/// A sampled half vector with its density, both in f64: `ratio` = p_h(h)/p_h(n) = (n·h)^e,
/// the value the half-vector LUT stores in alpha.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HalfVectorSample {
    /// The sampled unit half vector h (tangent space, +z the normal).
    pub h: DVec3,
    /// p_h(h), the half-vector density of the sample (per steradian).
    pub pdf: f64,
    /// p_h(h) / p_h(n): the density relative to its peak, what the LUT stores in alpha.
    pub ratio: f64,
}

impl AshikhminShirley {
    /// The lobe with exponents n_u, n_v (finite, ≥ 0; see `ibl_lut::hv::lobe` for the range the bakes accept).
    pub fn new(nu: f64, nv: f64) -> Self {
        AshikhminShirley { nu, nv }
    }

    /// p_h(n) = √((n_u+1)(n_v+1))/(2π), the peak of the half-vector density.
    pub fn pdf_h_at_normal(&self) -> f64 {
        ((self.nu + 1.0) * (self.nv + 1.0)).sqrt() / TAU
    }

    /// e(φ) = n_u cos²φ + n_v sin²φ from the tangential components of h (any scale).
    fn exponent(&self, hx: f64, hy: f64) -> f64 {
        let t2 = hx * hx + hy * hy;
        if t2 > 0.0 {
            (self.nu * hx * hx + self.nv * hy * hy) / t2
        } else {
            0.5 * (self.nu + self.nv)
        }
    }

    /// (n·h)^{e(h)} for a unit h, from its tangential part: exp(e ln(1 − sin²θ)/2).
    pub(crate) fn pdf_ratio(&self, h: DVec3) -> f64 {
        if h.z <= 0.0 {
            return 0.0;
        }
        let s2 = (h.x * h.x + h.y * h.y).min(1.0);
        if s2 >= 1.0 {
            return 0.0;
        }
        (self.exponent(h.x, h.y) * 0.5 * (-s2).ln_1p()).exp()
    }

    /// The half-vector density of Marcolongo 2020 §2.4 (solid angle of h); 0 below the horizon.
    pub fn pdf_h(&self, h: DVec3) -> f64 {
        self.pdf_h_at_normal() * self.pdf_ratio(h)
    }

    /// φ_red(t) = arctan(√((n_u+1)/(n_v+1)) tan(πt/2)) (Marcolongo 2020 §4.3.2), as an atan2 so that
    /// t = 1 gives π/2 instead of tan(π/2).
    fn phi_reduced(&self, t: f64) -> f64 {
        let (s, c) = (FRAC_PI_2 * t.clamp(0.0, 1.0)).sin_cos();
        ((self.nu + 1.0).sqrt() * s)
            .atan2((self.nv + 1.0).sqrt() * c.max(0.0))
            .min(FRAC_PI_2)
    }

    /// Marcolongo 2020 §4.3.2: φ(ξ1) by quadrant from φ_red, cos θ = (1−ξ2)^{1/(e(φ)+1)}.
    /// ξ1 = 1 gives φ = 2π ≡ 0, ξ2 = 1 the horizon, ξ2 = 0 the normal; never NaN or ∞ for
    /// exponents up to 10⁶ and beyond.
    pub fn sample(&self, xi1: f64, xi2: f64) -> HalfVectorSample {
        let xi1 = xi1.clamp(0.0, 1.0);
        let xi2 = xi2.clamp(0.0, 1.0);
        let phi = if xi1 < 0.25 {
            self.phi_reduced(4.0 * xi1)
        } else if xi1 < 0.5 {
            PI - self.phi_reduced(2.0 - 4.0 * xi1)
        } else if xi1 < 0.75 {
            PI + self.phi_reduced(4.0 * xi1 - 2.0)
        } else {
            TAU - self.phi_reduced(4.0 - 4.0 * xi1)
        };
        let (sp, cp) = phi.sin_cos();
        let e = self.nu * cp * cp + self.nv * sp * sp;
        // ln cos θ = ln(1−ξ2)/(e+1); sin²θ = −expm1(2 ln cos θ) keeps the tiny angles of
        // large exponents that 1 − cos²θ would round to 0.
        let ln_1m = (-xi2).ln_1p(); // −∞ at ξ2 = 1
        let ln_cos = ln_1m / (e + 1.0);
        let cos_t = ln_cos.exp();
        let sin_t = (-(2.0 * ln_cos).exp_m1()).clamp(0.0, 1.0).sqrt();
        let h = DVec3::new(sin_t * cp, sin_t * sp, cos_t);
        // (n·h)^e = (1−ξ2)^{e/(e+1)}.
        let ratio = if ln_1m == f64::NEG_INFINITY {
            0.0
        } else {
            (ln_1m * e / (e + 1.0)).exp()
        };
        HalfVectorSample {
            h,
            pdf: self.pdf_h_at_normal() * ratio,
            ratio,
        }
    }

    /// Inverse of [`AshikhminShirley::sample`]: (ξ1, ξ2) of a unit h with h.z > 0.
    pub(crate) fn invert(&self, h: DVec3) -> (f64, f64) {
        let mut phi = h.y.atan2(h.x);
        if phi < 0.0 {
            phi += TAU;
        }
        // Inverse of φ_red in the first quadrant: t = (2/π) atan(√((n_v+1)/(n_u+1)) tan φ').
        let reduce = |p: f64| {
            let (s, c) = p.sin_cos();
            ((self.nv + 1.0).sqrt() * s).atan2((self.nu + 1.0).sqrt() * c) / FRAC_PI_2
        };
        let xi1 = if phi < FRAC_PI_2 {
            reduce(phi) / 4.0
        } else if phi < PI {
            (2.0 - reduce(PI - phi)) / 4.0
        } else if phi < 1.5 * PI {
            (reduce(phi - PI) + 2.0) / 4.0
        } else {
            (4.0 - reduce(TAU - phi)) / 4.0
        };
        let e = self.exponent(h.x, h.y);
        let s2 = (h.x * h.x + h.y * h.y).min(1.0);
        // 1 − ξ2 = cos^{e+1}θ.
        let xi2 = -((e + 1.0) * 0.5 * (-s2).ln_1p()).exp_m1();
        (xi1.clamp(0.0, 1.0), xi2.clamp(0.0, 1.0))
    }

    /// The AS specular BRDF with Schlick Fresnel (Marcolongo 2020 §2.4):
    /// f_s = p_h(h) F(v·h) / (4 (v·h) max(n·v, n·l)); 0 below either horizon.
    pub fn brdf(&self, v: DVec3, l: DVec3, f0: f64) -> f64 {
        if v.z <= 0.0 || l.z <= 0.0 {
            return 0.0;
        }
        let h = (v + l).normalize();
        let vh = v.dot(h);
        if vh <= 0.0 {
            return 0.0;
        }
        let chi = (1.0 - vh).clamp(0.0, 1.0).powi(5);
        self.pdf_h(h) * (f0 + (1.0 - f0) * chi) / (4.0 * vh * v.z.max(l.z))
    }

    /// Smith Λ(v) of D_AS by quadrature (Heitz 2014 eq. 17 in its projected-area form):
    /// Λ(v) = (1/v_z) ∫_{m_z>0, v·m<0} D(m) |v·m| dm. The back-facing region is
    /// {tan θ_m cos(φ_m−φ_v) < −cot θ_v}; per azimuth the θ integral is mapped by
    /// cos θ = cos θ₀ s^{1/e} onto the measure cos^{e−1}θ sin θ dθ (resolving the boundary
    /// layer of large exponents) and the azimuth follows the AS azimuthal warp (resolving
    /// strong anisotropy). 4 × 48 azimuths × 24 polar nodes.
    pub(crate) fn lambda_numeric(&self, v: DVec3) -> f64 {
        if v.z <= 0.0 {
            return f64::INFINITY;
        }
        let st = (v.x * v.x + v.y * v.y).sqrt();
        if st <= 0.0 {
            return 0.0;
        }
        let (cpv, spv) = (v.x / st, v.y / st);
        let mu = v.z / st;
        let c = self.pdf_h_at_normal();
        let k = ((self.nu + 1.0) / (self.nv + 1.0)).sqrt();
        let gl_psi = gauss_legendre(48);
        let gl_s = gauss_legendre(24);
        let mut total = 0.0;
        for quadrant in 0..4 {
            for &(xa, wa) in &gl_psi {
                let t = 0.5 * (xa + 1.0);
                let (s, co) = (FRAC_PI_2 * t).sin_cos();
                let pr = self.phi_reduced(t);
                // dφ/dt of φ_red: (π/2) k / (cos² + k² sin²).
                let jac = FRAC_PI_2 * k / (co * co + k * k * s * s);
                let psi = match quadrant {
                    0 => pr,
                    1 => PI - pr,
                    2 => PI + pr,
                    _ => TAU - pr,
                };
                let (sp, cp) = psi.sin_cos();
                let cos_d = cp * cpv + sp * spv; // cos(ψ − φ_v)
                if cos_d >= 0.0 {
                    continue;
                }
                let e = self.nu * cp * cp + self.nv * sp * sp;
                // θ₀ = atan(μ / |cos Δ|).
                let tan0 = mu / -cos_d;
                let cos0 = 1.0 / (1.0 + tan0 * tan0).sqrt();
                // ∫_{θ₀}^{π/2} g cos^{e−1}θ sinθ dθ = (cos^e θ₀ / e) ∫₀¹ g(θ(s)) ds.
                let ln_cos0 = cos0.ln();
                let outer = (e * ln_cos0).exp() / e;
                if outer == 0.0 {
                    continue;
                }
                let mut inner = 0.0;
                for &(xs, ws) in &gl_s {
                    let sv = 0.5 * (xs + 1.0);
                    let cos_t = (ln_cos0 + sv.ln() / e).exp();
                    let sin_t = (1.0 - cos_t * cos_t).max(0.0).sqrt();
                    // g = |v·m| / v_z = tan θ_v sinθ |cosΔ| − cosθ = (sinθ |cosΔ| − μ cosθ)/μ.
                    let g = (sin_t * -cos_d - mu * cos_t) / mu;
                    inner += 0.5 * ws * g.max(0.0);
                }
                total += 0.5 * wa * jac * outer * inner;
            }
        }
        c * total
    }
}

impl Microfacet for AshikhminShirley {
    /// D_AS(m) = p_h(m)/(n·m).
    fn d(&self, m: Vec3) -> f32 {
        if m.z <= 0.0 {
            return 0.0;
        }
        let m = m.as_dvec3();
        // (n·m)^{e−1}: the ratio over n·m, as exp((e−1) ln cos θ). ln cos θ comes from the
        // tangential part near the normal (½ ln(1 − sin²θ) keeps tiny angles), and from
        // m.z/|m| towards the horizon, where 1 − sin²θ rounds to 0 and e = 1 would give
        // 0·(−∞) = NaN instead of (n·m)⁰ = 1.
        let len2 = m.length_squared();
        let s2 = (m.x * m.x + m.y * m.y) / len2;
        let ln_cos = if s2 > 0.5 {
            (m.z / len2.sqrt()).ln()
        } else {
            0.5 * (-s2).ln_1p()
        };
        let e = self.exponent(m.x, m.y);
        (self.pdf_h_at_normal() * ((e - 1.0) * ln_cos).exp()) as f32
    }

    fn lambda(&self, v: Vec3) -> f32 {
        self.lambda_numeric(v.as_dvec3().normalize()) as f32
    }

    fn sample_d(&self, u1: f32, u2: f32) -> Vec3 {
        self.sample(u1 as f64, u2 as f64).h.as_vec3()
    }

    fn invert_d(&self, m: Vec3) -> (f32, f32) {
        let (a, b) = self.invert(m.as_dvec3().normalize());
        (a as f32, b as f32)
    }

    fn pdf_d(&self, m: Vec3) -> f32 {
        if m.z <= 0.0 {
            0.0
        } else {
            self.pdf_h(m.as_dvec3().normalize()) as f32
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gtr::Gtr;
    use crate::validation::*;
    use ibl_core::sampling::Pcg32;

    fn scale(a: &AshikhminShirley) -> [f64; 2] {
        [1.0 / (a.nu + 1.0).sqrt(), 1.0 / (a.nv + 1.0).sqrt()]
    }

    #[test]
    fn half_vector_pdf_integrates_to_one_and_furnace_holds() {
        let mut rng = Pcg32::new(41, 5);
        for (nu, nv) in [
            (1.0, 1.0),
            (10.0, 1000.0),
            (20000.0, 70.0),
            (1e6, 1e6),
            (1e6, 1.0),
            (3.0, 50.0),
        ] {
            let a = AshikhminShirley::new(nu, nv);
            let norm = normalisation(&a, scale(&a));
            eprintln!("AS ({nu}, {nv}): ∫ p_h dω = {norm:.6}");
            assert!((norm - 1.0).abs() < 1e-3);
            for _ in 0..2 {
                let v = random_direction(&mut rng);
                let (got, want) = weak_furnace(&a, v, scale(&a));
                eprintln!(
                    "  v.z {:.3}: furnace {got:.6} vs {want:.6} (Λ {:.3e})",
                    v.z,
                    a.lambda(v)
                );
                assert!((got - want).abs() < 1e-3);
            }
        }
    }

    #[test]
    fn numerical_lambda_matches_closed_forms() {
        // n_u = n_v = 1 makes D_AS = 1/π, the uniform distribution = GTR γ = 0 (eq. 35).
        let a = AshikhminShirley::new(1.0, 1.0);
        let g = Gtr::new(0.5, 0.0);
        let mut worst = 0.0f64;
        for k in 1..40 {
            let z = k as f64 / 40.0;
            let v = DVec3::new((1.0 - z * z).sqrt(), 0.0, z);
            let want = g.lambda(v.as_vec3()) as f64;
            worst = worst.max((a.lambda_numeric(v) - want).abs() / (1.0 + want));
        }
        eprintln!("AS(1,1) numerical Λ vs closed-form uniform Λ: worst {worst:.2e}");
        assert!(worst < 1e-5);
    }

    #[test]
    fn sampling_matches_pdf_and_inverts() {
        for (nu, nv) in [(10.0, 100.0), (20000.0, 70.0), (1.0, 1.0), (1e6, 3.0)] {
            let a = AshikhminShirley::new(nu, nv);
            eprintln!("AS ({nu}, {nv}):");
            chi2_test(|u1, u2| a.sample_d(u1, u2), |m| a.pdf_d(m), scale(&a), 12);
            let mut rng = Pcg32::new(5, 5);
            let mut worst = 0.0f64;
            for _ in 0..20_000 {
                let (x1, x2) = (rng.next_f64(), 0.999 * rng.next_f64());
                let s = a.sample(x1, x2);
                let (y1, y2) = a.invert(s.h);
                let d1 = (x1 - y1).abs();
                worst = worst.max(d1.min(1.0 - d1)).max((x2 - y2).abs());
                assert!(
                    (s.pdf - a.pdf_h(s.h)).abs() <= 1e-6 * s.pdf.max(1.0),
                    "{} {}",
                    s.pdf,
                    a.pdf_h(s.h)
                );
            }
            eprintln!("  sample/invert round trip: worst {worst:.2e}");
            assert!(worst < 1e-9);
        }
    }

    #[test]
    fn extreme_exponents_and_end_points_are_finite() {
        let xs = [0.0, 1e-12, 0.25, 0.5, 0.75, 1.0 - 1e-12, 1.0];
        for nu in [0.0, 1.0, 70.0, 20000.0, 1e6] {
            for nv in [0.0, 1.0, 1e6] {
                let a = AshikhminShirley::new(nu, nv);
                for &x1 in &xs {
                    for &x2 in &xs {
                        let s = a.sample(x1, x2);
                        assert!(
                            s.h.is_finite() && s.pdf.is_finite() && s.ratio.is_finite(),
                            "{nu} {nv} {x1} {x2} {s:?}"
                        );
                        assert!((s.h.length() - 1.0).abs() < 1e-12 && s.h.z >= 0.0);
                        assert!((0.0..=1.0).contains(&s.ratio));
                        let (y1, y2) = a.invert(s.h);
                        assert!(y1.is_finite() && y2.is_finite());
                        let m = s.h.as_vec3();
                        assert!(a.pdf_d(m).is_finite());
                        if nu >= 1.0 && nv >= 1.0 {
                            assert!(a.d(m).is_finite());
                        }
                    }
                }
                // ξ2 = 0 is the normal with ratio 1, ξ2 = 1 the horizon with ratio 0.
                assert_eq!(a.sample(0.3, 0.0).ratio, 1.0);
                assert_eq!(a.sample(0.3, 1.0).ratio, 0.0);
                if nu >= 1.0 && nv >= 1.0 {
                    assert!(a.lambda_numeric(DVec3::new(0.6, 0.0, 0.8)).is_finite());
                }
            }
        }
    }

    #[test]
    fn d_is_finite_at_the_horizon_with_unit_exponents() {
        // With an exponent of 1 along m's azimuth, D_AS = p_h(n) (n·m)^{e−1} = p_h(n) for
        // every m above the horizon, however close to it; elsewhere (n·m)^{e−1} with
        // n·m = m.z/|m| (computed here in f64 from the same f32 components).
        let cases = [
            ((1.0, 1.0), Vec3::new(1.0, 0.0, 1e-30)),
            ((1.0, 1.0), Vec3::new(0.6, 0.8, 1e-30)),
            ((1.0, 100.0), Vec3::new(1.0, 0.0, 1e-30)),
            ((1.0, 1.0), Vec3::new(1.0, 0.0, 1e-3)),
            ((3.0, 2.0), Vec3::new(1.0, 0.0, 1e-3)),
            ((3.0, 2.0), Vec3::new(0.0, 1.0, 0.2)),
            ((3.0, 2.0), Vec3::new(0.1, 0.0, 1.0)),
        ];
        let mut worst = 0.0f64;
        for ((nu, nv), m) in cases {
            let a = AshikhminShirley::new(nu, nv);
            let got = a.d(m) as f64;
            let md = m.as_dvec3();
            let cos = md.z / md.length();
            let e = if md.x == 0.0 && md.y == 0.0 {
                0.5 * (nu + nv)
            } else {
                (nu * md.x * md.x + nv * md.y * md.y) / (md.x * md.x + md.y * md.y)
            };
            let want = a.pdf_h_at_normal() * cos.powf(e - 1.0);
            assert!(got.is_finite(), "AS({nu},{nv}).d({m}) = {got}");
            let rel = (got - want).abs() / want;
            worst = worst.max(rel);
            // d() returns f32: a correct result is within its rounding, 2⁻²⁴ ≈ 6e-8 (measured
            // worst 4e-8); 1e-6 leaves room for the f64 libm calls and still rejects NaN or a
            // wrong power of n·m.
            assert!(
                rel < 1e-6,
                "AS({nu},{nv}).d({m}) = {got}, closed form {want}"
            );
        }
        eprintln!("AS D near the horizon vs (n·m)^(e−1) closed form: worst relative {worst:.2e}");
        let d11 = AshikhminShirley::new(1.0, 1.0).d(Vec3::new(1.0, 0.0, 1e-30));
        assert_eq!(d11, (1.0 / PI) as f32, "AS(1,1) is the uniform 1/π");
    }

    #[test]
    fn brdf_is_reciprocal_and_matches_its_definition() {
        let a = AshikhminShirley::new(100.0, 10.0);
        let v = DVec3::new(0.3, 0.2, 0.9).normalize();
        let l = DVec3::new(-0.1, 0.4, 0.8).normalize();
        let f = a.brdf(v, l, 0.04);
        assert!((f - a.brdf(l, v, 0.04)).abs() < 1e-12 * f.max(1.0));
        let h = (v + l).normalize();
        let want = a.pdf_h(h) * crate::fresnel::fresnel_schlick(0.04, v.dot(h) as f32) as f64
            / (4.0 * v.dot(h) * v.z.max(l.z));
        assert!((f - want).abs() < 1e-6 * want);
    }
}
