//! Test harness of Atanasov et al. 2022 §4.3: deterministic quadratures of the normalisation (eq. 3) and
//! the weak white furnace (eq. 2), χ² tests of samplers against their pdfs, and round trips of
//! sample/invert. Used by the unit tests of every distribution (compiled for tests only).
//!
//! Integrals run in projected-normal ("slope") space, m = normalize(p_x, p_y, 1), where
//! dω_m = cos³θ_m dp. The caller gives a 2×2 matrix A (row-major) that maps a round unit lobe
//! t onto the distribution's lobe, p = A t; t is integrated in polar form with ρ = eˣ (x on a
//! composite Gauss–Legendre grid spanning 14 decades, so heavy tails and α = 1e-3 are both
//! resolved) and ψ on the periodic trapezoid rule. The integrand is always the function under
//! test, so a wrong factor in D, Λ or a sampler cannot cancel out.

#![cfg(test)]

use crate::microfacet::Microfacet;
use crate::quadrature::gauss_legendre;
use glam::Vec3;
use ibl_core::sampling::Pcg32;

/// A uniformly random direction on the upper hemisphere, kept off the exact horizon.
pub(crate) fn random_direction(rng: &mut Pcg32) -> Vec3 {
    let z = 0.02 + 0.98 * rng.next_f64();
    let phi = std::f64::consts::TAU * rng.next_f64();
    let s = (1.0 - z * z).sqrt();
    Vec3::new((s * phi.cos()) as f32, (s * phi.sin()) as f32, z as f32)
}

/// A diagonal lobe matrix from per-axis slope scales.
pub fn diag(scale: [f64; 2]) -> [f64; 4] {
    [scale[0], 0.0, 0.0, scale[1]]
}

/// Nodes (x, weight) of the radial grid: ρ = eˣ with x ∈ [−18, 14], 96 panels × 8 points.
fn radial_nodes() -> Vec<(f64, f64)> {
    let (lo, hi, panels) = (-18.0f64, 14.0f64, 96);
    let gl = gauss_legendre(8);
    let w = (hi - lo) / panels as f64;
    let mut out = Vec::with_capacity(panels * 8);
    for p in 0..panels {
        let a = lo + p as f64 * w;
        for &(x, wt) in &gl {
            out.push((a + 0.5 * w * (x + 1.0), 0.5 * w * wt));
        }
    }
    out
}

/// ∫ f(m) dp over the plane of projected normals, with the lobe matrix `a`.
/// `f` receives m and cos θ_m and returns the integrand per unit dp.
fn integrate_plane(a: [f64; 4], n_psi: usize, f: impl Fn(Vec3, f64) -> f64) -> f64 {
    let det = (a[0] * a[3] - a[1] * a[2]).abs();
    let mut total = 0.0;
    for (x, wx) in radial_nodes() {
        let rho = x.exp();
        let mut ring = 0.0;
        for k in 0..n_psi {
            let psi = (k as f64 + 0.5) * std::f64::consts::TAU / n_psi as f64;
            let (s, c) = psi.sin_cos();
            let (tx, ty) = (rho * c, rho * s);
            let (px, py) = (a[0] * tx + a[1] * ty, a[2] * tx + a[3] * ty);
            let len = (px * px + py * py + 1.0).sqrt();
            let m = Vec3::new((px / len) as f32, (py / len) as f32, (1.0 / len) as f32);
            ring += f(m, 1.0 / len);
        }
        // dt = ρ dρ dψ = ρ² dx dψ.
        total += wx * rho * rho * ring * std::f64::consts::TAU / n_psi as f64;
    }
    total * det
}

/// Atanasov et al. 2022 eq. 3: ∫ D(m)(n·m) dm, which must be 1.
pub(crate) fn normalisation_with(d: &dyn Microfacet, a: [f64; 4]) -> f64 {
    integrate_plane(a, 256, |m, c| d.d(m) as f64 * c * c * c * c)
}

pub fn normalisation(d: &dyn Microfacet, scale: [f64; 2]) -> f64 {
    normalisation_with(d, diag(scale))
}

/// Atanasov et al. 2022 eq. 2: (∫ D(m) G1(v,m) max(0, v·m) dm, v·n), which must agree.
/// Λ(v) is evaluated once (G1 = χ⁺/(1+Λ(v)) depends on m only through χ⁺; some Λ are
/// quadratures themselves). No distribution overrides `Microfacet::g1`, so the trait's
/// 1/(1+Λ) is what is integrated here; a type that overrides it must test it on its own.
pub(crate) fn weak_furnace_with(d: &dyn Microfacet, v: Vec3, a: [f64; 4]) -> (f64, f64) {
    let g1v = 1.0 / (1.0 + d.lambda(v) as f64);
    let got = integrate_plane(a, 1024, |m, c| {
        let vm = v.dot(m) as f64;
        if vm <= 0.0 {
            0.0
        } else {
            d.d(m) as f64 * g1v * vm * c * c * c
        }
    });
    (got, v.z as f64)
}

pub(crate) fn weak_furnace(d: &dyn Microfacet, v: Vec3, scale: [f64; 2]) -> (f64, f64) {
    weak_furnace_with(d, v, diag(scale))
}

/// Wilson–Hilferty z-score of a χ² statistic with `dof` degrees of freedom.
fn chi2_z(chi2: f64, dof: f64) -> f64 {
    let k = 2.0 / (9.0 * dof);
    ((chi2 / dof).powf(1.0 / 3.0) - (1.0 - k)) / k.sqrt()
}

/// χ² test of a sampler against its pdf (solid-angle density of m) on 20 × 24 bins of the
/// lobe-adapted plane: u = ρ/(1+ρ) of t = A⁻¹p (ρ = |t|), and its azimuth. Expected counts
/// integrate the pdf over each bin (8×8 Gauss–Legendre); bins expecting < 5 are pooled. Fails when the
/// Wilson–Hilferty z-score exceeds 4.5 (p ≈ 3e-6) or a sample leaves the hemisphere.
pub(crate) fn chi2_test_with(
    sample: impl Fn(f32, f32) -> Vec3,
    pdf: impl Fn(Vec3) -> f32,
    a: [f64; 4],
    seed: u64,
) -> f64 {
    const NU: usize = 20;
    const NPSI: usize = 24;
    const N: usize = 200_000;
    let det = a[0] * a[3] - a[1] * a[2];
    let inv = [a[3] / det, -a[1] / det, -a[2] / det, a[0] / det];
    let mut rng = Pcg32::new(seed, 99);
    let mut observed = vec![0.0f64; NU * NPSI];
    let mut outside = 0usize;
    for _ in 0..N {
        let m = sample(rng.next_f32(), rng.next_f32());
        assert!(m.is_finite(), "non-finite sample");
        if m.z <= 0.0 {
            outside += 1;
            continue;
        }
        let (px, py) = (m.x as f64 / m.z as f64, m.y as f64 / m.z as f64);
        let (tx, ty) = (inv[0] * px + inv[1] * py, inv[2] * px + inv[3] * py);
        let r = (tx * tx + ty * ty).sqrt();
        let u = r / (1.0 + r);
        let psi = crate::microfacet::azimuth_fraction(ty, tx);
        let i = ((u * NU as f64) as usize).min(NU - 1);
        let j = ((psi * NPSI as f64) as usize).min(NPSI - 1);
        observed[i * NPSI + j] += 1.0;
    }
    let gl = gauss_legendre(8);
    let mut expected = vec![0.0f64; NU * NPSI];
    for i in 0..NU {
        for j in 0..NPSI {
            let mut p = 0.0;
            for &(xa, wa) in &gl {
                let u = (i as f64 + 0.5 + 0.5 * xa) / NU as f64;
                for &(xb, wb) in &gl {
                    let psi = (j as f64 + 0.5 + 0.5 * xb) / NPSI as f64 * std::f64::consts::TAU;
                    let rho = u / (1.0 - u);
                    let (tx, ty) = (rho * psi.cos(), rho * psi.sin());
                    let (px, py) = (a[0] * tx + a[1] * ty, a[2] * tx + a[3] * ty);
                    let len = (px * px + py * py + 1.0).sqrt();
                    let m = Vec3::new((px / len) as f32, (py / len) as f32, (1.0 / len) as f32);
                    let c = 1.0 / len;
                    // p_t = pdf_ω cos³θ |det A|; dt = ρ dρ dψ = ρ du dψ / (1−u)².
                    let jac = c * c * c * det.abs() * rho / ((1.0 - u) * (1.0 - u));
                    p += wa * wb * 0.25 * pdf(m) as f64 * jac;
                }
            }
            expected[i * NPSI + j] = p / NU as f64 * std::f64::consts::TAU / NPSI as f64 * N as f64;
        }
    }
    let (mut chi2, mut dof) = (0.0, 0usize);
    let (mut pool_o, mut pool_e) = (outside as f64, 0.0);
    for k in 0..NU * NPSI {
        if expected[k] < 5.0 {
            pool_o += observed[k];
            pool_e += expected[k];
        } else {
            chi2 += (observed[k] - expected[k]).powi(2) / expected[k];
            dof += 1;
        }
    }
    if pool_e > 0.0 || pool_o > 0.0 {
        chi2 += (pool_o - pool_e).powi(2) / pool_e.max(1.0);
        dof += 1;
    }
    let total_e: f64 = expected.iter().sum();
    let dof = (dof.max(2) - 1) as f64;
    let z = chi2_z(chi2, dof);
    eprintln!("  χ² = {chi2:.1} on {dof} dof (z = {z:.2}); pdf mass in bins {:.5}; {outside} samples below horizon", total_e / N as f64);
    assert!(outside == 0, "{outside} samples below the horizon");
    assert!(
        z < 4.5,
        "χ² test failed: χ² = {chi2:.1}, dof {dof}, z {z:.2}"
    );
    assert!(
        (total_e / N as f64 - 1.0).abs() < 2e-3,
        "pdf does not integrate to 1 over the bins: {}",
        total_e / N as f64
    );
    z
}

pub(crate) fn chi2_test(
    sample: impl Fn(f32, f32) -> Vec3,
    pdf: impl Fn(Vec3) -> f32,
    scale: [f64; 2],
    seed: u64,
) -> f64 {
    chi2_test_with(sample, pdf, diag(scale), seed)
}

/// invert_d(sample_d(u)) = u away from the singular ends (u1 → 1, where m reaches the
/// horizon and f32 cannot resolve u1).
pub(crate) fn round_trip(d: &dyn Microfacet, seed: u64) {
    let mut rng = Pcg32::new(seed, 5);
    let mut worst = 0.0f32;
    for _ in 0..20_000 {
        let (u1, u2) = (0.999 * rng.next_f32(), rng.next_f32());
        let m = d.sample_d(u1, u2);
        let (a, b) = d.invert_d(m);
        let du2 = (b - u2).abs();
        let du2 = du2.min(1.0 - du2);
        worst = worst
            .max((a - u1).abs())
            .max(if u1 > 1e-6 { du2 } else { 0.0 });
    }
    eprintln!("  sample/invert round trip: worst |Δu| {worst:.2e}");
    assert!(worst < 2e-3, "{worst}");
}
