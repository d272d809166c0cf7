//! The Generalized Trowbridge-Reitz distribution GTR_γ (Burley 2012; Atanasov et al. 2022 Appendix A,
//! eqs. 32–33) with Dimov's Smith masking for the integer tails γ ∈ {0,1,2,3,4} (eqs. 34–39)
//! and a natural cubic spline in γ between them (as Appendix A recommends), and sampling of
//! D(m)(n·m) by inverting its CDF in cos²θ.
//!
//! Every expression is rearranged so that the removable singularities of the printed forms
//! (γ = 1 in eq. 32, α = 1 in eqs. 32, 33 and 36) evaluate to their limits: with L = ln α²
//! and q(x) = (eˣ − 1)/x, the normalisation of eq. 32 is q(L) / (π q((1−γ)L)).

use crate::microfacet::{azimuth_fraction, Microfacet};
use glam::Vec3;
use std::f64::consts::PI;

/// GTR with roughness α ∈ (0, 1] and tail γ ≥ 0 (γ = 2 is GGX, γ = 1 Berry, γ = 0 uniform).
/// Λ is exact for integer γ ≤ 4 and spline-interpolated in between; γ > 4 uses the γ = 4
/// masking.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Gtr {
    /// Roughness α of the GTR distribution (Burley 2012).
    pub alpha: f32,
    /// Tail exponent γ: γ = 2 is GGX, γ = 1 Berry; larger γ gives shorter tails.
    pub gamma: f32,
}

/// (eˣ − 1)/x, 1 at x = 0.
fn q(x: f64) -> f64 {
    if x == 0.0 {
        1.0
    } else {
        x.exp_m1() / x
    }
}

/// ln q(x) without overflow: for x > 0, x + ln(1 − e⁻ˣ) − ln x (q itself overflows past
/// x ≈ 710, which (1−γ) ln α² reaches for large tails, e.g. γ = 100 at α = 0.01 gives 912).
fn ln_q(x: f64) -> f64 {
    if x > 0.0 {
        x + (-(-x).exp()).ln_1p() - x.ln()
    } else {
        q(x).ln()
    }
}

impl Gtr {
    /// The distribution with roughness α and tail exponent γ.
    pub fn new(alpha: f32, gamma: f32) -> Self {
        Gtr { alpha, gamma }
    }

    fn ln_a2(&self) -> f64 {
        2.0 * (self.alpha as f64).ln()
    }

    /// The normalisation constant of eq. 32, c = (γ−1)(α²−1) / (π(1 − (α²)^{1−γ})), and its
    /// limits at γ = 1 (eq. 33) and α = 1 (1/π): c = q(L) / (π q((1−γ)L)).
    pub fn normalisation(&self) -> f64 {
        let l = self.ln_a2();
        q(l) / (PI * q((1.0 - self.gamma as f64) * l))
    }

    /// Dimov's average visibility S_γ(μ), μ = |cot θ_v| (Atanasov et al. 2022 eqs. 35–39) for
    /// γ ∈ {0,…,4}, G1 = χ⁺ S_γ (eq. 34).
    pub(crate) fn s_integer(gamma: u32, mu: f64, alpha: f64) -> f64 {
        if mu.is_infinite() {
            return 1.0;
        }
        if mu <= 0.0 {
            return 0.0;
        }
        let a2 = alpha * alpha;
        match gamma {
            0 => 2.0 / (1.0 + (1.0 / (mu * mu) + 1.0).sqrt()),
            1 => {
                let l = 2.0 * alpha.ln();
                if l == 0.0 {
                    return Self::s_integer(0, mu, 1.0);
                }
                let a1 = (mu * mu + a2).sqrt();
                let b1 = (mu * mu + 1.0).sqrt();
                // A1 − B1 and log(α²(μ+B1)/(μ+A1)) without cancellation.
                let a_minus_b = l.exp_m1() / (a1 + b1);
                let log_term = l + ((b1 - a1) / (mu + a1)).ln_1p();
                mu * l / (a_minus_b + mu * log_term)
            }
            2 => 2.0 / (1.0 + (a2 / (mu * mu) + 1.0).sqrt()),
            3 => {
                let a3 = (mu * mu + a2).sqrt();
                let b3 = a2 + 1.0;
                4.0 * b3 * mu * a3 / (a2 * (3.0 * a2 + 1.0) + 2.0 * mu * b3 * (mu + a3))
            }
            _ => {
                let a4c = 8.0 * a2 * a2 + 8.0 * a2 + 8.0;
                let b4 = (mu * mu + a2).sqrt();
                let b43 = b4 * b4 * b4;
                2.0 * a4c * mu * b43
                    / (a4c * mu * (b43 + mu * mu * mu)
                        + 3.0
                            * a2
                            * (a2 * (5.0 * a2 * a2 + 2.0 * a2 + 1.0)
                                + 4.0 * mu * mu * (2.0 * a2 * a2 + a2 + 1.0)))
            }
        }
    }

    /// S_γ(μ) for any γ ∈ [0, 4]: the integer formulas, or the natural cubic spline through
    /// S_0 … S_4 at this μ (Atanasov et al. 2022 Appendix A, after eq. 39).
    pub fn s(&self, mu: f64) -> f64 {
        let g = (self.gamma as f64).clamp(0.0, 4.0);
        let alpha = self.alpha as f64;
        if g.fract() == 0.0 {
            return Self::s_integer(g as u32, mu, alpha);
        }
        let y: [f64; 5] = std::array::from_fn(|i| Self::s_integer(i as u32, mu, alpha));
        // Second derivatives M1..M3 (M0 = M4 = 0) of the natural spline on unit knots:
        // M_{i−1} + 4 M_i + M_{i+1} = 6 (y_{i+1} − 2 y_i + y_{i−1}).
        let r: [f64; 3] = std::array::from_fn(|k| 6.0 * (y[k + 2] - 2.0 * y[k + 1] + y[k]));
        // Thomas algorithm for the symmetric tridiagonal (1, 4, 1) system.
        let c1 = 1.0 / 4.0;
        let d1 = r[0] / 4.0;
        let den2 = 4.0 - c1;
        let c2 = 1.0 / den2;
        let d2 = (r[1] - d1) / den2;
        let den3 = 4.0 - c2;
        let m3 = (r[2] - d2) / den3;
        let m2 = d2 - c2 * m3;
        let m1 = d1 - c1 * m2;
        let m = [0.0, m1, m2, m3, 0.0];
        let i = (g.floor() as usize).min(3);
        let t = g - i as f64;
        let u = 1.0 - t;
        // The spline may overshoot where S_γ saturates (small α): keep G1 a fraction.
        (u * y[i] + t * y[i + 1] + ((u * u * u - u) * m[i] + (t * t * t - t) * m[i + 1]) / 6.0)
            .clamp(0.0, 1.0)
    }
}

impl Microfacet for Gtr {
    /// Atanasov et al. 2022 eq. 32: D = c / (1 + (α²−1) cos²θ)^γ, the base written sin²θ + α² cos²θ.
    /// Evaluated as exp(ln c − γ ln base), since for large γ c underflows while base^−γ
    /// overflows (γ = 100, α = 0.01: c ≈ e⁻⁹⁰⁸, base^−γ up to e⁹²¹).
    fn d(&self, m: Vec3) -> f32 {
        if m.z <= 0.0 {
            return 0.0;
        }
        let a2 = self.alpha as f64 * self.alpha as f64;
        let c2 = m.z as f64 * m.z as f64;
        let s2 = m.x as f64 * m.x as f64 + m.y as f64 * m.y as f64;
        let base = s2 + a2 * c2;
        let l = self.ln_a2();
        let ln_c = ln_q(l) - PI.ln() - ln_q((1.0 - self.gamma as f64) * l);
        (ln_c - self.gamma as f64 * base.ln()).exp() as f32
    }

    /// Λ = 1/S_γ(μ) − 1 with μ = cot θ_v (eq. 34).
    fn lambda(&self, v: Vec3) -> f32 {
        if v.z <= 0.0 {
            return f32::INFINITY;
        }
        let st = ((v.x as f64).powi(2) + (v.y as f64).powi(2)).sqrt();
        let mu = if st > 0.0 {
            v.z as f64 / st
        } else {
            f64::INFINITY
        };
        let s = self.s(mu);
        if s <= 0.0 {
            f32::INFINITY
        } else {
            (1.0 / s - 1.0).max(0.0) as f32
        }
    }

    /// Inverts the CDF of D(m)(n·m) in x = cos²θ: with s = 1 + (α²−1)x and k = 1−γ,
    /// u1 = (s^k − α^{2k}) / (1 − α^{2k}) (u1 = 0 at the normal), so
    /// ln s = ln(1 + (1−u1)(α^{2k} − 1)) / k (→ (1−u1) ln α² at k = 0); φ = 2π u2.
    /// When kL = k ln α² > 0 (γ > 1 with α < 1) α^{2k} = e^{kL} overflows for large γ, so
    /// there ln s = (kL + ln(1 + u1 (e^{−kL} − 1))) / k, the same number divided through by
    /// e^{kL}; ln s is kept in [min(L, 0), max(L, 0)] (s between α² and 1).
    fn sample_d(&self, u1: f32, u2: f32) -> Vec3 {
        let u = (u1 as f64).clamp(0.0, 1.0);
        let l = self.ln_a2();
        let k = 1.0 - self.gamma as f64;
        let (cos2, sin2) = if l == 0.0 {
            (1.0 - u, u)
        } else {
            let kl = k * l;
            let ln_s = if k == 0.0 {
                (1.0 - u) * l
            } else if kl > 0.0 {
                (kl + (u * (-kl).exp_m1()).ln_1p()) / k
            } else {
                ((1.0 - u) * kl.exp_m1()).ln_1p() / k
            };
            let ln_s = ln_s.clamp(l.min(0.0), l.max(0.0));
            // cos²θ = (1−s)/(1−α²), sin²θ = (s−α²)/(1−α²), each from expm1 without cancellation.
            let den = l.exp_m1();
            (ln_s.exp_m1() / den, l.exp() * (ln_s - l).exp_m1() / (-den))
        };
        let (cos2, sin2) = (cos2.clamp(0.0, 1.0), sin2.clamp(0.0, 1.0));
        let phi = std::f64::consts::TAU * u2 as f64;
        let (s, c) = phi.sin_cos();
        let st = sin2.sqrt();
        Vec3::new((st * c) as f32, (st * s) as f32, cos2.sqrt() as f32)
    }

    fn invert_d(&self, m: Vec3) -> (f32, f32) {
        let a2 = self.alpha as f64 * self.alpha as f64;
        let c2 = m.z as f64 * m.z as f64;
        let s2 = m.x as f64 * m.x as f64 + m.y as f64 * m.y as f64;
        let l = self.ln_a2();
        let k = 1.0 - self.gamma as f64;
        let u = if l == 0.0 {
            s2 / (s2 + c2)
        } else {
            let ln_s = (s2 + a2 * c2).ln() - (s2 + c2).ln();
            let kl = k * l;
            if k == 0.0 {
                1.0 - ln_s / l
            } else if kl > 0.0 {
                // The form below divided through by e^{kL} (which overflows for large γ).
                (k * (ln_s - l)).exp_m1() / (-kl).exp_m1()
            } else {
                kl.exp() * (k * (ln_s - l)).exp_m1() / -kl.exp_m1()
            }
        };
        (
            u.clamp(0.0, 1.0) as f32,
            azimuth_fraction(m.y as f64, m.x as f64) as f32,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::validation::*;
    use ibl_core::sampling::Pcg32;

    #[test]
    fn limits_of_the_normalisation() {
        // γ = 2 is GGX: c = α²/π.
        let a2 = (0.3f32 as f64).powi(2);
        let g = Gtr::new(0.3, 2.0);
        assert!((g.normalisation() - a2 / PI).abs() < 1e-12);
        // γ = 1 is eq. 33: (α²−1)/(π ln α²).
        let g = Gtr::new(0.3, 1.0);
        assert!((g.normalisation() - (a2 - 1.0) / (PI * a2.ln())).abs() < 1e-12);
        // α = 1 and γ = 0 are uniform.
        assert!((Gtr::new(1.0, 3.3).normalisation() - 1.0 / PI).abs() < 1e-12);
        assert!((Gtr::new(0.2, 0.0).normalisation() - 1.0 / PI).abs() < 1e-12);
        // Continuity across γ = 1.
        let a = Gtr::new(0.4, 1.0 - 1e-7).normalisation();
        let b = Gtr::new(0.4, 1.0 + 1e-7).normalisation();
        assert!((a - b).abs() < 1e-6 * a);
    }

    #[test]
    fn gtr_normalisation_and_weak_furnace_at_integer_tails() {
        let mut rng = Pcg32::new(31, 4);
        let mut worst = 0.0f64;
        for gamma in 0..=4u32 {
            for case in 0..3 {
                let alpha = if case == 0 {
                    0.01
                } else {
                    0.05 + 0.95 * rng.next_f32()
                };
                let g = Gtr::new(alpha, gamma as f32);
                let norm = normalisation(&g, [alpha as f64; 2]);
                assert!((norm - 1.0).abs() < 1e-3, "γ {gamma} α {alpha}: {norm}");
                for _ in 0..2 {
                    let v = random_direction(&mut rng);
                    let (got, want) = weak_furnace(&g, v, [alpha as f64; 2]);
                    eprintln!("GTR γ={gamma} α={alpha:.3}: ∫D(n·m) {norm:.6}; v.z {:.3} furnace {got:.6} vs {want:.6}", v.z);
                    worst = worst.max((got - want).abs());
                    assert!((got - want).abs() < 1e-3, "γ {gamma} α {alpha} v {v}");
                }
            }
        }
        eprintln!("GTR integer tails: worst furnace error {worst:.2e}");
    }

    #[test]
    fn spline_masking_is_close_between_integers() {
        let mut rng = Pcg32::new(32, 4);
        let mut worst = 0.0f64;
        for gamma in [0.5f32, 1.5, 2.5, 3.5] {
            let g = Gtr::new(0.3, gamma);
            let norm = normalisation(&g, [0.3; 2]);
            assert!((norm - 1.0).abs() < 1e-3);
            for _ in 0..2 {
                let v = random_direction(&mut rng);
                let (got, want) = weak_furnace(&g, v, [0.3; 2]);
                worst = worst.max((got - want).abs() / want);
            }
        }
        eprintln!("GTR spline masking (non-integer γ): worst relative furnace error {worst:.2e}");
        assert!(worst < 2e-2);
    }

    #[test]
    fn gtr_sampling_matches_pdf() {
        for (alpha, gamma) in [
            (0.3f32, 1.0f32),
            (0.2, 3.0),
            (0.5, 0.5),
            (0.1, 4.0),
            (1.0, 2.5),
        ] {
            let g = Gtr::new(alpha, gamma);
            eprintln!("GTR α={alpha} γ={gamma}:");
            chi2_test(
                |u1, u2| g.sample_d(u1, u2),
                |m| g.pdf_d(m),
                [alpha as f64; 2],
                9,
            );
            round_trip(&g, 10);
        }
    }

    #[test]
    fn large_tails_sample_finite_unit_normals_with_a_normalised_pdf() {
        // γ = 100, α = 0.01: (1−γ) ln α² = 912, past where e^x overflows (709.8). The lobe is
        // about α/√(γ−1) wide in slope, which is the scale the quadratures use.
        let (alpha, gamma) = (0.01f32, 100.0f32);
        let g = Gtr::new(alpha, gamma);
        let scale = [alpha as f64 / (gamma as f64 - 1.0).sqrt(); 2];
        let mut rng = Pcg32::new(33, 7);
        let ends = [0.0f32, 1e-7, 0.5, 1.0 - 1e-7, 1.0];
        let pairs = ends
            .iter()
            .flat_map(|&a| ends.iter().map(move |&b| (a, b)))
            .chain((0..10_000).map(|_| (rng.next_f32(), rng.next_f32())));
        let mut worst_len = 0.0f32;
        for (u1, u2) in pairs {
            let m = g.sample_d(u1, u2);
            assert!(m.is_finite() && m.z >= 0.0, "{u1} {u2} {m}");
            worst_len = worst_len.max((m.length() - 1.0).abs());
            assert!(g.pdf_d(m).is_finite(), "{u1} {u2} {m}");
        }
        eprintln!("GTR α={alpha} γ={gamma}: worst ||m| − 1| {worst_len:.2e}");
        assert!(worst_len < 1e-6);
        // u1 = 0 is the normal, u1 = 1 the horizon.
        assert_eq!(g.sample_d(0.0, 0.3), Vec3::Z);
        assert!(g.sample_d(1.0, 0.0).z.abs() < 1e-6);
        let norm = normalisation(&g, scale);
        eprintln!("GTR α={alpha} γ={gamma}: ∫D(n·m) = {norm:.6}");
        assert!((norm - 1.0).abs() < 1e-3, "{norm}");
        chi2_test(|u1, u2| g.sample_d(u1, u2), |m| g.pdf_d(m), scale, 11);
        round_trip(&g, 12);
    }

    #[test]
    fn end_points_and_limits_are_finite() {
        for alpha in [1e-4f32, 0.5, 1.0] {
            for gamma in [0.0f32, 1.0, 1.0 + 1e-6, 2.0, 3.7, 4.0] {
                let g = Gtr::new(alpha, gamma);
                for (u1, u2) in [(0.0, 0.0), (1.0, 1.0), (0.5, 0.5)] {
                    let m = g.sample_d(u1, u2);
                    assert!(
                        m.is_finite() && (m.length() - 1.0).abs() < 1e-5,
                        "{alpha} {gamma} {m}"
                    );
                    assert!(g.pdf_d(m).is_finite());
                }
                for mu in [0.0, 1e-8, 1.0, 1e8, f64::INFINITY] {
                    let s = g.s(mu);
                    assert!(
                        s.is_finite() && (0.0..=1.0 + 1e-9).contains(&s),
                        "{alpha} {gamma} {mu} {s}"
                    );
                }
            }
        }
    }
}
