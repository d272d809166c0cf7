//! The reflection / half-reflection parameterisation (Silvennoinen et al. 2025 eq. 10), the vMF-damped SH
//! features of eq. 11/14, and the deterministic direction sets the fit samples.

use glam::Vec3;
use ibl_core::sh;

/// Coefficients of an SH expansion of order `order` (bands l = 0 … order): (order+1)².
#[inline]
pub const fn coeffs_of_order(order: usize) -> usize {
    (order + 1) * (order + 1)
}

/// Unknowns per channel: all (p+1)² of P and the (q+1)² − 1 of Q without its DC term
/// (Silvennoinen et al. 2025, end of §4.1: the DC would appear twice).
#[inline]
pub const fn num_unknowns(p_order: usize, q_order: usize) -> usize {
    coeffs_of_order(p_order) + coeffs_of_order(q_order) - 1
}

/// Silvennoinen et al. 2025 eq. 12 with κ = 1/α: vMF_l = exp(−l(l+1)·α/2).
///
/// α is the GGX α = roughness² (the reading that reproduces the paper's behaviour; with
/// κ = 1/roughness the damping is far too strong at low roughness).
#[inline]
pub(crate) fn vmf_band(l: usize, alpha: f32) -> f32 {
    (-((l * (l + 1)) as f32) * alpha * 0.5).exp()
}

/// Linear ("hat") interpolation weights of the α knots of the piecewise-linear extension
/// (`coeffs::AlphaKnots`, not in Silvennoinen et al. 2025): coefficients(α) = w₀·c[s] + w₁·c[s+1] with the
/// segment s whose knots bracket α, α clamped to the knot range. Returns ((s, w₀), (s+1, w₁));
/// one knot gives ((0, 1), (0, 0)). `knots` must be non-empty and strictly increasing.
pub(crate) fn knot_weights(knots: &[f32], alpha: f32) -> ((usize, f32), (usize, f32)) {
    let k = knots.len();
    if k < 2 {
        return ((0, 1.0), (0, 0.0));
    }
    let a = alpha.clamp(knots[0], knots[k - 1]);
    let s = (0..k - 2).find(|&s| a <= knots[s + 1]).unwrap_or(k - 2);
    let t = ((a - knots[s]) / (knots[s + 1] - knots[s])).clamp(0.0, 1.0);
    ((s, 1.0 - t), (s + 1, t))
}

/// Band l of SH index i = l(l+1)+m.
#[inline]
pub(crate) fn band_of(i: usize) -> usize {
    (i as f64).sqrt() as usize
}

/// The reflection r of `v` about `n` and the half-reflection vector h_r = normalize(n + r)
/// (Silvennoinen et al. 2025 eq. 10). For r = −n (only when v = −n) h_r falls back to n.
#[inline]
pub(crate) fn reflection_pair(n: Vec3, v: Vec3) -> (Vec3, Vec3) {
    let r = (2.0 * n.dot(v) * n - v).normalize_or(n);
    let hr = (n + r).normalize_or(n);
    (r, hr)
}

/// SH basis values at the two parameterisation directions, before the α-dependent damping:
/// Y(r) for P (bands 0..=p_order) and Y(h_r) for Q (bands 0..=q_order; index 0 is unused).
#[derive(Clone, Debug)]
pub struct Features {
    /// Y_lm(r), (p_order+1)² values in SH order.
    pub y_r: Vec<f32>,
    /// Y_lm(h_r), (q_order+1)² values (index 0 unused).
    pub y_hr: Vec<f32>,
}

impl Features {
    /// Zeroed features for the given orders.
    pub fn new(p_order: usize, q_order: usize) -> Self {
        Features {
            y_r: vec![0.0; coeffs_of_order(p_order)],
            y_hr: vec![0.0; coeffs_of_order(q_order)],
        }
    }

    /// Evaluates Y(r) and Y(h_r) for normal `n` and view `v` (both unit, world space).
    pub fn eval(&mut self, n: Vec3, v: Vec3) {
        let (r, hr) = reflection_pair(n, v);
        sh::eval_basis(r, band_of(self.y_r.len() - 1) + 1, &mut self.y_r);
        sh::eval_basis(hr, band_of(self.y_hr.len() - 1) + 1, &mut self.y_hr);
    }

    /// One row of eq. 14: [vMF ⊙ Y(r), vMF ⊙ Y(h_r) without DC], written into `row`.
    pub fn row(&self, vmf: &[f32], row: &mut [f64]) {
        let np = self.y_r.len();
        for (i, y) in self.y_r.iter().enumerate() {
            row[i] = (vmf[band_of(i)] * y) as f64;
        }
        for (i, y) in self.y_hr.iter().enumerate().skip(1) {
            row[np + i - 1] = (vmf[band_of(i)] * y) as f64;
        }
    }
}

/// vMF damping factors of bands 0..=max_order for one α.
pub fn vmf_factors(max_order: usize, alpha: f32) -> Vec<f32> {
    (0..=max_order).map(|l| vmf_band(l, alpha)).collect()
}

/// The golden ratio conjugate, for Fibonacci lattices.
const GOLDEN: f64 = 0.618_033_988_749_894_8;

/// The i-th of `n` spherical Fibonacci points: uniform over the sphere (equal-area bands in z,
/// golden-angle turns in φ). Deterministic.
pub fn fibonacci_sphere(i: usize, n: usize) -> Vec3 {
    let z = 1.0 - (2.0 * i as f64 + 1.0) / n as f64;
    let phi = 2.0 * std::f64::consts::PI * ((i as f64 * GOLDEN).fract());
    let s = (1.0 - z * z).max(0.0).sqrt();
    Vec3::new((s * phi.cos()) as f32, (s * phi.sin()) as f32, z as f32)
}

/// The k-th of `n` Fibonacci points on the upper hemisphere (tangent space, +z up): uniform in
/// solid angle (uniform in cos θ), never exactly at the horizon.
pub fn fibonacci_hemisphere(k: usize, n: usize) -> Vec3 {
    let z = 1.0 - (k as f64 + 0.5) / n as f64;
    let phi = 2.0 * std::f64::consts::PI * ((k as f64 * GOLDEN).fract());
    let s = (1.0 - z * z).max(0.0).sqrt();
    Vec3::new((s * phi.cos()) as f32, (s * phi.sin()) as f32, z as f32)
}

/// An orthonormal tangent frame (t, b) for unit `n` (Duff et al. 2017, branchless), turned by
/// `turn` (in turns, [0, 1)) about n, so successive normals see the view set at different azimuths.
pub fn tangent_frame(n: Vec3, turn: f32) -> (Vec3, Vec3) {
    let sign = 1.0f32.copysign(n.z);
    let a = -1.0 / (sign + n.z);
    let b = n.x * n.y * a;
    let t0 = Vec3::new(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x);
    let b0 = Vec3::new(b, sign + n.y * n.y * a, -n.y);
    let (s, c) = (2.0 * std::f32::consts::PI * turn).sin_cos();
    (c * t0 + s * b0, -s * t0 + c * b0)
}

/// The per-normal azimuth turn used with [`tangent_frame`]: a second golden-ratio sequence.
#[inline]
pub(crate) fn normal_turn(i: usize) -> f32 {
    ((i as f64 * 0.754_877_666_246_692_8).fract()) as f32
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn vmf_matches_eq_12_with_kappa_one_over_alpha() {
        for alpha in [0.2f32, 0.5, 1.0] {
            let kappa = 1.0 / alpha;
            for l in 0..7 {
                let want = (-((l * (l + 1)) as f32) / (2.0 * kappa)).exp();
                assert!((vmf_band(l, alpha) - want).abs() < 1e-7);
            }
        }
        assert_eq!(vmf_band(0, 1.0), 1.0);
    }

    #[test]
    fn knot_weights_interpolate_and_clamp() {
        let knots = [0.2f32, 0.5, 1.0];
        // Exact at the knots, a partition of unity in between, clamped outside.
        assert_eq!(knot_weights(&knots, 0.2), ((0, 1.0), (1, 0.0)));
        assert_eq!(knot_weights(&knots, 0.5).1, (1, 1.0));
        assert_eq!(knot_weights(&knots, 1.0), ((1, 0.0), (2, 1.0)));
        assert_eq!(knot_weights(&knots, 0.05), ((0, 1.0), (1, 0.0)));
        assert_eq!(knot_weights(&knots, 3.0), ((1, 0.0), (2, 1.0)));
        let ((s, w0), (s1, w1)) = knot_weights(&knots, 0.75);
        assert_eq!((s, s1), (1, 2));
        assert!((w0 - 0.5).abs() < 1e-6 && (w1 - 0.5).abs() < 1e-6);
        // Linear in α: interpolating the knot positions themselves returns α.
        for i in 0..=100 {
            let a = 0.2 + 0.8 * i as f32 / 100.0;
            let ((s, w0), (s1, w1)) = knot_weights(&knots, a);
            assert!((w0 * knots[s] + w1 * knots[s1] - a).abs() < 1e-6, "{a}");
            assert!((w0 + w1 - 1.0).abs() < 1e-6);
        }
        assert_eq!(knot_weights(&[0.4], 0.9), ((0, 1.0), (0, 0.0)));
    }

    #[test]
    fn unknown_counts_match_the_paper() {
        assert_eq!(num_unknowns(4, 2), 33);
        assert_eq!(coeffs_of_order(4), 25);
        for i in 0..49 {
            let l = band_of(i);
            assert!(l * l <= i && i < (l + 1) * (l + 1));
        }
    }

    #[test]
    fn reflection_pair_geometry() {
        let n = Vec3::new(0.3, 0.5, 0.8).normalize();
        let v = Vec3::new(-0.2, 0.1, 0.97).normalize();
        let (r, hr) = reflection_pair(n, v);
        assert!((r.dot(n) - v.dot(n)).abs() < 1e-6);
        assert!((r.length() - 1.0).abs() < 1e-6);
        // h_r bisects n and r.
        assert!((hr.dot(n) - hr.dot(r)).abs() < 1e-6);
        // n = v gives r = h_r = n.
        let (r, hr) = reflection_pair(n, n);
        assert!((r - n).length() < 1e-6 && (hr - n).length() < 1e-6);
        let (r, hr) = reflection_pair(n, -n);
        assert!(r.is_finite() && hr.is_finite());
    }

    #[test]
    fn fibonacci_sets_are_uniform() {
        // Mean of z and of z² over uniform sphere: 0 and 1/3; hemisphere: 1/2 and 1/3.
        let n = 4096;
        let (mut z1, mut z2) = (0.0f64, 0.0f64);
        let (mut h1, mut h2) = (0.0f64, 0.0f64);
        for i in 0..n {
            let d = fibonacci_sphere(i, n);
            assert!((d.length() - 1.0).abs() < 1e-5);
            z1 += d.z as f64;
            z2 += (d.x * d.x) as f64;
            let h = fibonacci_hemisphere(i, n);
            assert!(h.z > 0.0);
            h1 += h.z as f64;
            h2 += (h.y * h.y) as f64;
        }
        let n = n as f64;
        eprintln!(
            "sphere <z>={:.2e} <x²>={:.5}; hemisphere <z>={:.5} <y²>={:.5}",
            z1 / n,
            z2 / n,
            h1 / n,
            h2 / n
        );
        assert!((z1 / n).abs() < 1e-6 && (z2 / n - 1.0 / 3.0).abs() < 1e-3);
        assert!((h1 / n - 0.5).abs() < 1e-4 && (h2 / n - 1.0 / 3.0).abs() < 1e-3);
    }

    #[test]
    fn tangent_frames_are_orthonormal() {
        for i in 0..500 {
            let n = fibonacci_sphere(i, 500);
            let (t, b) = tangent_frame(n, normal_turn(i));
            assert!(t.dot(n).abs() < 1e-5 && b.dot(n).abs() < 1e-5 && t.dot(b).abs() < 1e-5);
            assert!((t.cross(b) - n).length() < 1e-4, "right-handed");
        }
        let (t, b) = tangent_frame(-Vec3::Z, 0.0);
        assert!(t.is_finite() && b.is_finite());
    }

    #[test]
    fn rows_use_the_orthonormal_basis_with_damping() {
        // The row's P block must equal vMF ⊙ Y(r) with Y orthonormal: integrate Y_i Y_j over
        // the sphere through `Features` and compare with δ_ij.
        let (p, q) = (4, 2);
        let mut f = Features::new(p, q);
        let k = num_unknowns(p, q);
        let nb = coeffs_of_order(p);
        let m = 20_000;
        let mut gram = vec![0.0f64; nb * nb];
        let vmf = vec![1.0f32; p + 1];
        let mut row = vec![0.0f64; k];
        for i in 0..m {
            let n = fibonacci_sphere(i, m);
            // v = n makes r = h_r = n.
            f.eval(n, n);
            f.row(&vmf, &mut row);
            for a in 0..nb {
                for b in 0..nb {
                    gram[a * nb + b] += row[a] * row[b] * 4.0 * std::f64::consts::PI / m as f64;
                }
            }
            // Q block holds Y_1.. of h_r = n.
            for j in 1..coeffs_of_order(q) {
                assert!((row[nb + j - 1] - row[j]).abs() < 1e-6);
            }
        }
        let mut worst = 0.0f64;
        for a in 0..nb {
            for b in 0..nb {
                let want = if a == b { 1.0 } else { 0.0 };
                worst = worst.max((gram[a * nb + b] - want).abs());
            }
        }
        eprintln!("max |Gram − I| over Fibonacci quadrature: {worst:.2e}");
        assert!(worst < 2e-3);
        // Damping multiplies band l by vMF_l.
        let vmf = vmf_factors(p, 0.5);
        f.eval(Vec3::new(0.2, 0.3, 0.9).normalize(), Vec3::Z);
        f.row(&vmf, &mut row);
        for i in 0..nb {
            assert!((row[i] - (f.y_r[i] * vmf[band_of(i)]) as f64).abs() < 1e-9);
        }
    }
}
