//! BRDF major-axis sampling of Cocco, Zanni & Chermain 2024 ("Cocco et al. 2024", §5 and
//! Appendices A–D), written from the paper's text, in the lobe's local frame (Ū = t, V̄ = b,
//! n = +z) with the view o (towards the eye).
//!
//! Readings and errata (also in docs/ANISOTROPY.md):
//! - σ = α/√2 per axis (§4.1) is a Beckmann slope deviation; GGX slopes have infinite variance,
//!   so k = 1 holds k²/(2+k²) = 1/3 of the GGX slope mass (not a "confidence region" in the
//!   usual sense).
//! - App. D's ζ can leave [0, 1] (Δ' above the clamped major length at grazing views); the
//!   paper does not say what then: we clamp it to [0, 1].
//! - App. B divides by p1 = o_z(1 − z⊤²), 0 for an isotropic lobe seen head-on (all extrema
//!   equidistant): then nothing is clamped (τ0 = 0, τ1 = 1).

use glam::Vec3;

/// Meta-parameters: taps N, β (eq. 10) and the ellipse scale k (eq. 6).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct Params {
    /// Taps N.
    pub taps: usize,
    /// β of eq. 10 (2.3 in the paper).
    pub beta: f32,
    /// k of eq. 6 (1 in the paper).
    pub k: f32,
    /// Not in the paper: the width term of eq. 10 is Δ'/(2k·c). c = 1 is the paper; c = √2
    /// undoes H1 (an isotropic lobe seen head-on is then read at its own α, not α√2). Fitted
    /// on training environments by the bench (`bench/aniso.md`), never on the scored ones.
    pub c: f32,
}

impl Default for Params {
    fn default() -> Self {
        Params {
            taps: 16,
            beta: 2.3,
            k: 1.0,
            c: 1.0,
        }
    }
}

/// App. A: the ellipse parameters (t0, t1) of the closest (argmax of d) and farthest
/// (argmin of d) extrema, each mod π, for radii (r_x, r_y) and the view's tangential
/// components (o_x, o_y) in the ellipse frame.
pub fn extrema(rx: f32, ry: f32, ox: f32, oy: f32) -> (f32, f32) {
    let (rx, ry, ox, oy) = (rx as f64, ry as f64, ox as f64, oy as f64);
    let (rx2, ry2) = (rx * rx, ry * ry);
    let phi0 = 2.0 * ox * oy * rx * ry;
    let phi1 = ox * ox * (rx2 * ry2 + ry2) - oy * oy * (rx2 * ry2 + rx2) + rx2 - ry2;
    let phi2 = -phi0 * (ry2 + 1.0);
    let phi3 = phi0 * phi2 * (rx2 + 1.0);
    let root = (phi1 * phi1 - phi3).max(0.0).sqrt();
    let half_pi = std::f64::consts::FRAC_PI_2;
    if phi2 != 0.0 {
        (
            ((phi1 + root) / phi2).atan() as f32,
            ((phi1 - root) / phi2).atan() as f32,
        )
    } else {
        let t0 = if phi1 >= 0.0 { half_pi } else { 0.0 };
        (t0 as f32, (t0 + half_pi) as f32)
    }
}

/// The microfacet normal of ellipse parameter t (§5.1: ω = (−x̌, −y̌, 1)/‖·‖ of the slope
/// (r_x cos t, r_y sin t)).
#[inline]
pub fn normal_at(rx: f32, ry: f32, t: f32) -> Vec3 {
    let (s, c) = t.sin_cos();
    Vec3::new(-rx * c, -ry * s, 1.0).normalize()
}

/// Mirror of o about m: 2(m·o)m − o.
#[inline]
pub fn refl(o: Vec3, m: Vec3) -> Vec3 {
    2.0 * m.dot(o) * m - o
}

/// Normalised linear interpolation.
#[inline]
pub fn nlerp(a: Vec3, b: Vec3, t: f32) -> Vec3 {
    let w = a * (1.0 - t) + b * t;
    let l = w.length();
    if l > 0.0 {
        w / l
    } else {
        a
    }
}

/// d(t) = ω̌_t · ω̌_g of §5.3 (the alignment the extrema maximise and minimise).
pub fn alignment(rx: f32, ry: f32, o: Vec3, t: f32) -> f32 {
    refl(o, normal_at(rx, ry, t)).dot(refl(o, Vec3::Z))
}

/// The taps of eq. 9 (reflected directions, local frame) and the perceptual roughness
/// α_lin = √r_s the chain is read at (§5.7), for a lobe of slope deviations (σ_U, σ_V) along
/// (t, b) = (Ū, V̄) and a local view o with o_z > 0.
pub fn taps(o: Vec3, sigma_u: f32, sigma_v: f32, p: &Params) -> (Vec<Vec3>, f32) {
    let n = p.taps.max(1);
    let (rx, ry) = (p.k * sigma_u, p.k * sigma_v);
    let (t0, t1) = extrema(rx, ry, o.x, o.y);
    let pi = std::f32::consts::PI;
    // Farthest extrema ⊤0, ⊤1 (App. A) in normal space.
    let top0 = normal_at(rx, ry, t1);
    let top1 = normal_at(rx, ry, t1 + pi);
    // App. B: the range of τ whose reflection stays above the horizon.
    let p0 = top1.x * o.x + top1.y * o.y;
    let p1 = o.z * (1.0 - top1.z * top1.z);
    let (tau0, tau1) = if p1 > 1e-12 {
        let root = (p0 * p0 + o.z * p1).max(0.0).sqrt();
        (
            0.5 + top1.z * (p0 - root) / (2.0 * p1),
            0.5 + top1.z * (p0 + root) / (2.0 * p1),
        )
    } else {
        (0.0, 1.0)
    };
    let (tc0, tc1) = (tau0.clamp(0.0, 1.0), tau1.clamp(0.0, 1.0));
    let topc0 = nlerp(top0, top1, tc0);
    let topc1 = nlerp(top0, top1, tc1);
    // App. C: the closest extrema moved along the ellipse by the clamping.
    let delta = if tc0 > 0.0 {
        tc0 * (t0 - t1)
    } else {
        (tc1 - 1.0) * (t0 - t1)
    };
    let bot0 = normal_at(rx, ry, t0 + delta);
    let bot1 = normal_at(rx, ry, t0 - delta + pi);
    let width = (refl(o, bot0) - refl(o, bot1)).length();
    let major = (refl(o, topc0) - refl(o, topc1)).length();
    // App. D.
    let zeta = if major > 0.0 {
        ((major - width) / major).clamp(0.0, 1.0)
    } else {
        0.0
    };
    let centre = nlerp(topc0, topc1, 0.5);
    let end0 = nlerp(centre, topc0, zeta);
    let end1 = nlerp(centre, topc1, zeta);
    let dirs = (0..n)
        .map(|j| {
            let s = if n == 1 {
                0.5
            } else {
                j as f32 / (n - 1) as f32
            };
            refl(o, nlerp(end0, end1, s))
        })
        .collect();
    // Eq. 10 and §5.7.
    let rs = (width / (2.0 * p.k * p.c)).max(p.beta * major / (2.0 * n as f32));
    (dirs, rs.max(0.0).sqrt().min(1.0))
}

#[cfg(test)]
mod tests {
    use super::*;
    use ibl_core::sampling::Pcg32;

    #[test]
    fn appendix_a_matches_brute_force_extrema() {
        let mut rng = Pcg32::new(23, 1);
        let (mut worst_max, mut worst_min) = (0.0f64, 0.0f64);
        let steps = 100_000;
        for _ in 0..10_000 {
            let rx = 0.02 + rng.next_f32();
            let ry = 0.02 + rng.next_f32();
            let th = 1.5 * rng.next_f32();
            let ph = std::f32::consts::TAU * rng.next_f32();
            let o = Vec3::new(th.sin() * ph.cos(), th.sin() * ph.sin(), th.cos());
            let (t0, t1) = extrema(rx, ry, o.x, o.y);
            // Brute force over t ∈ [0, π) in f64 (d is π-periodic).
            let d = |t: f64| -> f64 {
                let (s, c) = t.sin_cos();
                let m = glam::DVec3::new(-(rx as f64) * c, -(ry as f64) * s, 1.0).normalize();
                let o = o.as_dvec3();
                let r = 2.0 * m.dot(o) * m - o;
                r.dot(glam::DVec3::new(-o.x, -o.y, o.z))
            };
            let (mut hi, mut lo) = (f64::MIN, f64::MAX);
            // 10⁵ values on the 10⁴ cases would take minutes: sample 10⁵ on every 100th case.
            let n = if worst_max == 0.0 || rng.next_u32().is_multiple_of(100) {
                steps
            } else {
                2000
            };
            for i in 0..n {
                let v = d(std::f64::consts::PI * i as f64 / n as f64);
                hi = hi.max(v);
                lo = lo.min(v);
            }
            // The closed form must reach the brute-force optimum (it may beat the grid).
            worst_max = worst_max.max(hi - d(t0 as f64));
            worst_min = worst_min.max(d(t1 as f64) - lo);
        }
        eprintln!("App. A: worst shortfall argmax {worst_max:.2e}, argmin {worst_min:.2e}");
        assert!(
            worst_max < 1e-6 && worst_min < 1e-6,
            "{worst_max} {worst_min}"
        );
    }

    #[test]
    fn taps_stay_above_the_horizon_and_collapse_when_isotropic_at_normal_incidence() {
        let mut rng = Pcg32::new(5, 2);
        let p = Params::default();
        for _ in 0..2000 {
            let th = 1.55 * rng.next_f32();
            let ph = std::f32::consts::TAU * rng.next_f32();
            let o = Vec3::new(th.sin() * ph.cos(), th.sin() * ph.sin(), th.cos());
            let (su, sv) = (0.7 * rng.next_f32() + 0.001, 0.7 * rng.next_f32() + 0.001);
            let (dirs, r) = taps(o, su, sv, &p);
            assert!(r.is_finite() && (0.0..=1.0).contains(&r));
            for d in dirs {
                assert!(
                    d.z >= -1e-5,
                    "App. B: tap below the horizon {d} (o {o}, σ {su} {sv})"
                );
            }
        }
        // H1: isotropic, head-on: the taps collapse onto the mirror direction.
        for (rough, want) in [(0.1f32, 1.41f32), (0.5, 1.37), (0.9, 1.06)] {
            let alpha = rough * rough;
            let sigma = alpha / 2f32.sqrt();
            let (dirs, r) = taps(Vec3::Z, sigma, sigma, &p);
            let spread = dirs
                .iter()
                .map(|d| (*d - Vec3::Z).length())
                .fold(0.0f32, f32::max);
            assert!(spread < 1e-6, "{spread}");
            // ... and the chain is read at α·√2 at low r (docs/ANISOTROPY.md §1.7, H1: read
            // α / true α = 1.41, 1.37, 1.06 at r = 0.1, 0.5, 0.9).
            let ratio = r * r / alpha;
            assert!((ratio - want).abs() < 0.02, "r {rough}: {ratio}");
        }
    }

    #[test]
    fn symmetric_under_tangent_flip() {
        let p = Params::default();
        let o = Vec3::new(0.3, -0.5, 0.8).normalize();
        let (a, ra) = taps(o, 0.4, 0.05, &p);
        let (b, rb) = taps(Vec3::new(-o.x, -o.y, o.z), 0.4, 0.05, &p);
        assert!((ra - rb).abs() < 1e-5);
        // The same tap set, mirrored (and possibly in reverse order).
        let mut worst = 0.0f32;
        for d in &a {
            let m = Vec3::new(-d.x, -d.y, d.z);
            let best = b.iter().map(|e| (*e - m).length()).fold(f32::MAX, f32::min);
            worst = worst.max(best);
        }
        assert!(worst < 1e-4, "{worst}");
    }
}
