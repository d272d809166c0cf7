//! Independent references for the tables: deterministic product Gauss–Legendre quadratures
//! over the half vector, 2^20 nodes by default (1024 × 1024). They share nothing with the
//! bakes' estimators (no Hammersley points, no CDF inversion, no closed-form visibility):
//! the integrands are built from the distributions' D and Smith Λ (`ibl_brdf::Ggx`) or the
//! AS half-vector pdf p_h, which the furnace and normalisation tests of `ibl-brdf` validate.
//!
//! The DFG rule integrates each azimuth ring only over its valid arc (n·l > 0), so it has no
//! kink inside; the AS integrand keeps kinks (n·l = 0 and n·l = n·v), so that rule converges
//! as O(N⁻²). The tests measure both rules against themselves at half the nodes.

use glam::DVec3;
use ibl_brdf::quadrature::gauss_legendre;
use ibl_brdf::{AshikhminShirley, Ggx, Microfacet};
use std::f64::consts::{FRAC_PI_2, PI, TAU};

/// Gauss–Legendre nodes mapped to [a, b] as (x, w·(b−a)/2).
fn mapped(n: usize, a: f64, b: f64) -> Vec<(f64, f64)> {
    let h = 0.5 * (b - a);
    gauss_legendre(n)
        .into_iter()
        .map(|(x, w)| (a + h * (x + 1.0), w * h))
        .collect()
}

/// A quadrature rule for the split-sum integrals of isotropic GGX with height-correlated
/// Smith masking.
pub struct DfgReference {
    beta: Vec<(f64, f64)>,
    phi: Vec<(f64, f64)>,
}

impl DfgReference {
    /// `n` × `n` nodes (n = 1024 is the 2^20-node reference): n/2 on each of two β panels,
    /// n in φ.
    pub fn new(n: usize) -> Self {
        DfgReference {
            beta: mapped((n / 2).max(1), 0.0, 1.0),
            phi: mapped(n, 0.0, 1.0),
        }
    }

    /// (A, B) = ∫ f_DV(v,l) (1−χ, χ) (n·l) dl with χ = (1 − v·h)⁵, at view cosine `n_dot_v`
    /// and GGX `alpha`.
    ///
    /// Half vectors are parametrised by the α-scaled slope angle β (tan θ_h = α tan β) and
    /// φ ∈ [0, π] (v lies in the xz plane, so the integrand is even in φ):
    /// h = (α sin β cos φ, α sin β sin φ, cos β)/N, N = √(cos²β + α² sin²β),
    /// dω_h = α² sin β / N³ dβ dφ, and f_DV (n·l) dl = D G2 (v·h)/(n·v) dω_h
    /// (the half-vector Jacobian dl = 4 (v·h) dω_h).
    pub fn dfg(&self, n_dot_v: f64, alpha: f64) -> [f64; 2] {
        let v = DVec3::new((1.0 - n_dot_v * n_dot_v).max(0.0).sqrt(), 0.0, n_dot_v);
        let ggx = Ggx::isotropic(alpha as f32);
        let lambda_v = ggx.lambda(v.as_vec3()) as f64;
        // The valid arc of a ring is full for θ_h < π/4 − θ_v/2 and empty beyond π/4 + θ_v/2
        // (solving n·l = 0 at φ = π and φ = 0); panels end there, so no rule crosses a kink.
        let theta_v = n_dot_v.clamp(-1.0, 1.0).acos();
        let beta_of = |theta_h: f64| (theta_h.tan() / alpha).atan();
        let b1 = beta_of(std::f64::consts::FRAC_PI_4 - 0.5 * theta_v);
        let b2 = beta_of(std::f64::consts::FRAC_PI_4 + 0.5 * theta_v);
        let panels = [(0.0, b1), (b1, b2)];
        let nodes = panels.iter().flat_map(|&(lo, hi)| {
            self.beta
                .iter()
                .map(move |&(x, w)| (lo + (hi - lo) * x, w * (hi - lo)))
        });
        let (mut a, mut b) = (0.0, 0.0);
        for (beta, wb) in nodes {
            let (sb, cb) = beta.sin_cos();
            let n = (cb * cb + alpha * alpha * sb * sb).sqrt();
            let (sin_h, cos_h) = (alpha * sb / n, cb / n);
            let jac = alpha * alpha * sb / (n * n * n);
            // n·l = 2(v·h)cos θ_h − n·v > 0 ⇔ v_x sin θ_h cos φ > n·v (1/(2 cos θ_h) − cos θ_h):
            // integrate φ over [0, φ_max] only, so the rule never straddles the n·l = 0 kink
            // (v·h > 0 follows from n·l > 0).
            let rhs = n_dot_v * (0.5 / cos_h - cos_h);
            let k = v.x * sin_h;
            let phi_max = if k > 1e-300 {
                let c = rhs / k;
                if c >= 1.0 {
                    continue;
                }
                c.max(-1.0).acos()
            } else if rhs < 0.0 {
                PI
            } else {
                continue;
            };
            let (mut ra, mut rb) = (0.0, 0.0);
            for &(x, wp) in &self.phi {
                let phi = x * phi_max;
                let (sp, cp) = phi.sin_cos();
                let h = DVec3::new(sin_h * cp, sin_h * sp, cos_h);
                let vh = v.dot(h);
                let l = 2.0 * vh * h - v;
                if vh <= 0.0 || l.z <= 0.0 {
                    continue;
                }
                let d = ggx.d(h.as_vec3()) as f64;
                let lambda_l = ggx.lambda(l.as_vec3()) as f64;
                let g2 = 1.0 / (1.0 + lambda_v + lambda_l);
                let f = d * g2 * vh / n_dot_v * jac;
                let chi = (1.0 - vh).powi(5);
                ra += wp * f * (1.0 - chi);
                rb += wp * f * chi;
            }
            a += wb * ra * phi_max;
            b += wb * rb * phi_max;
        }
        [2.0 * a, 2.0 * b]
    }
}

/// A quadrature rule for the Ashikhmin-Shirley size/bias integrals of Marcolongo 2020 §4.3.3.
pub struct AsReference {
    beta: Vec<(f64, f64)>,
    phi: Vec<(f64, f64)>,
}

impl AsReference {
    /// `n` × `n` nodes.
    pub fn new(n: usize) -> Self {
        AsReference {
            beta: mapped(n, 0.0, FRAC_PI_2),
            phi: mapped(n, 0.0, TAU),
        }
    }

    /// (size, bias) = ∫ p_l(l) (1−χ, χ) (n·l)/max(n·v, n·l) dl for the unit view `v`
    /// (tangent space), integrated over half vectors: p_l dl = p_h dω_h. The half vectors
    /// follow the AS lobe: h = normalize(σ_u tan β cos φ, σ_v tan β sin φ, 1) with
    /// σ = 1/√(n+1), so dω_h = cos³θ_h σ_u σ_v tan β sec²β dβ dφ.
    pub fn size_bias(&self, a: &AshikhminShirley, v: DVec3) -> [f64; 2] {
        let (su, sv) = (1.0 / (a.nu + 1.0).sqrt(), 1.0 / (a.nv + 1.0).sqrt());
        let (mut s, mut b) = (0.0, 0.0);
        for &(beta, wb) in &self.beta {
            let (sbeta, cbeta) = beta.sin_cos();
            let t = sbeta / cbeta;
            let (mut rs, mut rb) = (0.0, 0.0);
            for &(phi, wp) in &self.phi {
                let (sp, cp) = phi.sin_cos();
                // Unit h from (p, 1)·cos β-scaled components, finite at β → π/2.
                let q = DVec3::new(su * sbeta * cp, sv * sbeta * sp, cbeta);
                let len = q.length();
                let h = q / len;
                let vh = v.dot(h);
                if vh <= 0.0 {
                    continue;
                }
                let l = 2.0 * vh * h - v;
                if l.z <= 0.0 {
                    continue;
                }
                let cos_h = h.z;
                let jac = cos_h * cos_h * cos_h * su * sv * t / (cbeta * cbeta);
                let f = a.pdf_h(h) * jac * l.z / v.z.max(l.z);
                let chi = (1.0 - vh).powi(5);
                rs += wp * f * (1.0 - chi);
                rb += wp * f * chi;
            }
            s += wb * rs;
            b += wb * rb;
        }
        [s, b]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dfg_reference_converges_and_has_the_known_limits() {
        let fine = DfgReference::new(512);
        let coarse = DfgReference::new(256);
        let mut worst = 0.0f64;
        for &(nv, alpha) in &[
            (0.05, 0.01),
            (0.5, 0.25),
            (0.9, 0.8),
            (0.2, 1.0),
            (1.0, 0.5),
            (0.004, 1e-4),
        ] {
            let a = fine.dfg(nv, alpha);
            let b = coarse.dfg(nv, alpha);
            worst = worst.max((a[0] - b[0]).abs()).max((a[1] - b[1]).abs());
        }
        eprintln!("DFG reference 512² vs 256²: worst difference {worst:.2e}");
        assert!(worst < 1e-6);
        // Near-mirror: A + B → G2-weighted mirror; at normal incidence A = 1 − B, B = 0.
        let [a, b] = fine.dfg(1.0, 1e-4);
        assert!((a - 1.0).abs() < 1e-4 && b < 1e-6, "{a} {b}");
        // Mirror at n·v: B = (1 − n·v)⁵ (v·h = n·v), A + B = G2 ≈ 1.
        let nv = 0.3f64;
        let [a, b] = fine.dfg(nv, 1e-4);
        assert!(
            (b - (1.0 - nv).powi(5)).abs() < 1e-4 && (a + b - 1.0).abs() < 1e-4,
            "{a} {b}"
        );
    }

    #[test]
    fn as_reference_converges_and_conserves_at_most_unit_energy() {
        let fine = AsReference::new(512);
        let coarse = AsReference::new(256);
        let mut worst = 0.0f64;
        for (nu, nv) in [(100.0, 10.0), (20000.0, 70.0), (1.0, 1.0)] {
            let a = AshikhminShirley::new(nu, nv);
            for v in [
                DVec3::new(0.6, 0.3, 0.742),
                DVec3::new(0.1, 0.99, 0.1),
                DVec3::new(0.0, 0.0, 1.0),
            ] {
                let v = v.normalize();
                let x = fine.size_bias(&a, v);
                let y = coarse.size_bias(&a, v);
                assert!(x[0] + x[1] <= 1.0 + 1e-9);
                worst = worst.max((x[0] - y[0]).abs()).max((x[1] - y[1]).abs());
            }
        }
        eprintln!("AS reference 512² vs 256²: worst difference {worst:.2e}");
        assert!(worst < 1e-4);
        // Normal incidence, a sharp lobe: nearly all energy returns with F(1) weighting.
        let a = AshikhminShirley::new(1e5, 1e5);
        let [s, b] = fine.size_bias(&a, DVec3::Z);
        assert!((s - 1.0).abs() < 1e-3 && b < 1e-6, "{s} {b}");
    }
}
