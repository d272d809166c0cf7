//! The Fresnel-free GGX BRDF f_DV = D·V of Silvennoinen et al. 2025 eq. 8 (eq. 3: V = G2/(4 n·v n·l) with
//! Smith's height-correlated G2), and visible-normal sampling of it.
//!
//! D, Smith Λ / G1 / G2, V, VNDF sampling and the reflected-direction density are the shared
//! `ibl_brdf::ggx` functions, re-exported with the mirror reflection and Schlick's tail; the
//! tests check the shared functions against the properties this crate relies on.
//! Tangent space has the normal on +z; `alpha` is the GGX α = roughness².

pub use ibl_brdf::ggx::{
    d_ggx, f_dv, g1, g2, lambda, pdf_vndf, pdf_vndf_reflected, sample_vndf, v_smith,
};

/// Mirror reflection 2(v·m)m − v and Schlick's tail weight (1 − v·h)⁵ (Silvennoinen et al. 2025 eq. 4), shared.
pub use ibl_brdf::fresnel::schlick_weight as schlick_tail;
pub use ibl_brdf::reflect;

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;
    use ibl_core::sampling::{hammersley, Pcg32};
    use std::f32::consts::PI;

    fn dir(theta: f32, phi: f32) -> Vec3 {
        Vec3::new(
            theta.sin() * phi.cos(),
            theta.sin() * phi.sin(),
            theta.cos(),
        )
    }

    /// Riemann sum over the hemisphere in (cos θ, φ): equal-area cells.
    fn hemisphere_integral(f: impl Fn(Vec3) -> f64, k: usize) -> f64 {
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
            let nd = hemisphere_integral(|h| (d_ggx(h.z, alpha) * h.z) as f64, 600);
            assert!((nd - 1.0).abs() < 2e-3, "∫D(n·h) = {nd} at α={alpha}");
            for theta in [0.0f32, 0.7, 1.45] {
                let v = dir(theta, 0.3);
                let dv = hemisphere_integral(|h| pdf_vndf(v, h, alpha) as f64, 600);
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
        // 8×8 histogram in (u1, u2) space via... use the density directly: bin h over (cos θ, φ)
        // cells and compare counts with the integrated pdf.
        let alpha = 0.4;
        let v = dir(1.0, 0.5);
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
                dir(std::f32::consts::FRAC_PI_2 - 1e-4, 0.0),
                dir(1.2, 2.0),
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
            let v = dir(theta, 0.0);
            let n = 200_000;
            let mut s = 0.0f64;
            for _ in 0..n {
                let h = sample_vndf(v, rng.next_f32(), rng.next_f32(), alpha);
                let l = reflect(v, h);
                if l.z > 0.0 {
                    s += (g2(v.z, l.z, alpha) / g1(v.z, alpha)) as f64;
                }
            }
            let mc = s / n as f64;
            let quad = hemisphere_integral(|l| (f_dv(v, l, alpha) * l.z) as f64, 800);
            eprintln!("α={alpha} θ={theta}: MC {mc:.5} quadrature {quad:.5}");
            assert!((mc - quad).abs() < 4e-3, "{mc} vs {quad}");
        }
    }
}
