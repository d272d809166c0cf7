//! Linearly transformed microsurfaces (Atanasov et al. 2022 §4): for any base distribution and an
//! invertible tangential transform M (eq. 9), the distribution D_M (eq. 22), the masking
//! G1_M (eq. 12), and sampling through (M⁻¹)ᵀ (eq. 26, and eq. 28 for visible normals).

use crate::microfacet::Microfacet;
use glam::{DVec3, Vec3};

/// The tangential transform of Atanasov et al. 2022 eq. 9, M = [[a, c, 0], [b, d, 0], [0, 0, 1]].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TangentTransform {
    /// Row 0, column 0 of M.
    pub a: f64,
    /// Row 1, column 0 of M.
    pub b: f64,
    /// Row 0, column 1 of M.
    pub c: f64,
    /// Row 1, column 1 of M.
    pub d: f64,
}

impl TangentTransform {
    /// M = [[a, c, 0], [b, d, 0], [0, 0, 1]] (Atanasov et al. 2022 eq. 9).
    pub fn new(a: f64, b: f64, c: f64, d: f64) -> Self {
        TangentTransform { a, b, c, d }
    }

    /// det M = ad − bc; the transform must have det M ≠ 0.
    pub fn det(&self) -> f64 {
        self.a * self.d - self.b * self.c
    }

    /// Mᵀ m = (a m_x + b m_y, c m_x + d m_y, m_z) (Atanasov et al. 2022, after eq. 13).
    pub(crate) fn transpose_mul(&self, m: DVec3) -> DVec3 {
        DVec3::new(
            self.a * m.x + self.b * m.y,
            self.c * m.x + self.d * m.y,
            m.z,
        )
    }

    /// M⁻¹ v.
    pub(crate) fn inverse_mul(&self, v: DVec3) -> DVec3 {
        let k = 1.0 / self.det();
        DVec3::new(
            k * (self.d * v.x - self.c * v.y),
            k * (-self.b * v.x + self.a * v.y),
            v.z,
        )
    }

    /// (M⁻¹)ᵀ u, the transform of normals (Atanasov et al. 2022 eq. 10).
    pub(crate) fn inverse_transpose_mul(&self, u: DVec3) -> DVec3 {
        let k = 1.0 / self.det();
        DVec3::new(
            k * (self.d * u.x - self.b * u.y),
            k * (-self.c * u.x + self.a * u.y),
            u.z,
        )
    }
}

/// The base microsurface transformed by M (Atanasov et al. 2022's "LTMD").
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Transformed<D> {
    /// The microsurface before the transform.
    pub base: D,
    /// The tangential transform M applied to its microfacet normals.
    pub m: TangentTransform,
}

impl<D: Microfacet> Transformed<D> {
    /// The microsurface `base` transformed by `m`.
    pub fn new(base: D, m: TangentTransform) -> Self {
        Transformed { base, m }
    }
}

impl<D: Microfacet> Microfacet for Transformed<D> {
    /// Eq. 22: D_M(m) = |det M| / ‖Mᵀm‖⁴ · D(Mᵀm / ‖Mᵀm‖).
    fn d(&self, m: Vec3) -> f32 {
        if m.z <= 0.0 {
            return 0.0;
        }
        let m = m.as_dvec3();
        let u = self.m.transpose_mul(m);
        let len2 = u.length_squared() / m.length_squared();
        let u = u.normalize();
        (self.m.det().abs() / (len2 * len2) * self.base.d(u.as_vec3()) as f64) as f32
    }

    /// Eq. 12: G1_M(v, m) = G1(M⁻¹v/‖M⁻¹v‖, Mᵀm/‖Mᵀm‖); Λ depends on v alone, and the sign of
    /// v·m is preserved ((M⁻¹v)·(Mᵀm) = v·m), so Λ_M(v) = Λ(M⁻¹v/‖M⁻¹v‖).
    fn lambda(&self, v: Vec3) -> f32 {
        if v.z <= 0.0 {
            return f32::INFINITY;
        }
        self.base
            .lambda(self.m.inverse_mul(v.as_dvec3()).normalize().as_vec3())
    }

    /// Eqs. 25–26: u' ~ D(u)(n·u), m' = (M⁻¹)ᵀu' / ‖(M⁻¹)ᵀu'‖ ~ D_M(m)(n·m).
    fn sample_d(&self, u1: f32, u2: f32) -> Vec3 {
        let u = self.base.sample_d(u1, u2).as_dvec3();
        self.m.inverse_transpose_mul(u).normalize().as_vec3()
    }

    fn invert_d(&self, m: Vec3) -> (f32, f32) {
        self.base
            .invert_d(self.m.transpose_mul(m.as_dvec3()).normalize().as_vec3())
    }

    /// Eq. 28 and the text after it: w = M⁻¹v/‖M⁻¹v‖, a base visible normal u'_w for w,
    /// m' = (M⁻¹)ᵀu'_w / ‖(M⁻¹)ᵀu'_w‖.
    fn sample_visible(&self, v: Vec3, u1: f32, u2: f32) -> Option<Vec3> {
        let w = self.m.inverse_mul(v.as_dvec3()).normalize().as_vec3();
        let u = self.base.sample_visible(w, u1, u2)?;
        Some(
            self.m
                .inverse_transpose_mul(u.as_dvec3())
                .normalize()
                .as_vec3(),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ashikhmin_shirley::AshikhminShirley;
    use crate::beckmann::Beckmann;
    use crate::ggx::Ggx;
    use crate::gtr::Gtr;
    use crate::validation::*;
    use ibl_core::sampling::Pcg32;

    /// A random invertible M with entries in [−2, 2] and |det M| ≥ 0.25.
    fn random_transform(rng: &mut Pcg32) -> TangentTransform {
        loop {
            let mut e = || 4.0 * rng.next_f64() - 2.0;
            let t = TangentTransform::new(e(), e(), e(), e());
            if t.det().abs() >= 0.25 {
                return t;
            }
        }
    }

    /// The lobe matrix of the transformed distribution: p_m = M₂⁻ᵀ p_u, p_u = diag(σ) t.
    fn lobe(t: &TangentTransform, sigma: [f64; 2]) -> [f64; 4] {
        let k = 1.0 / t.det();
        let inv_t = [k * t.d, -k * t.b, -k * t.c, k * t.a];
        [
            inv_t[0] * sigma[0],
            inv_t[1] * sigma[1],
            inv_t[2] * sigma[0],
            inv_t[3] * sigma[1],
        ]
    }

    fn check<D: Microfacet>(name: &str, base: D, sigma: [f64; 2], rng: &mut Pcg32) {
        let t = random_transform(rng);
        let tr = Transformed::new(base, t);
        let a = lobe(&t, sigma);
        let norm = normalisation_with(&tr, a);
        eprintln!(
            "{name} × M({:.2},{:.2},{:.2},{:.2}): ∫D_M(n·m) = {norm:.6}",
            t.a, t.b, t.c, t.d
        );
        assert!((norm - 1.0).abs() < 1e-3, "{norm}");
        for _ in 0..2 {
            let v = random_direction(rng);
            let (got, want) = weak_furnace_with(&tr, v, a);
            eprintln!("  v.z {:.3}: furnace {got:.6} vs {want:.6}", v.z);
            assert!((got - want).abs() < 1e-3);
        }
    }

    #[test]
    fn transformed_distributions_are_normalised_and_pass_the_furnace() {
        let mut rng = Pcg32::new(51, 6);
        for _ in 0..2 {
            let (ax, ay) = (0.05 + rng.next_f32(), 0.05 + rng.next_f32());
            check("GGX", Ggx::new(ax, ay), [ax as f64, ay as f64], &mut rng);
            let (bx, by) = (0.05 + rng.next_f32(), 0.05 + rng.next_f32());
            check(
                "Beckmann",
                Beckmann::new(bx, by),
                [bx as f64, by as f64],
                &mut rng,
            );
            let (ga, gg) = (0.05 + 0.95 * rng.next_f32(), (rng.next_u32() % 5) as f32);
            check(
                &format!("GTR γ={gg}"),
                Gtr::new(ga, gg),
                [ga as f64; 2],
                &mut rng,
            );
            let (nu, nv) = (1.0 + 500.0 * rng.next_f64(), 1.0 + 50.0 * rng.next_f64());
            let s = [1.0 / (nu + 1.0).sqrt(), 1.0 / (nv + 1.0).sqrt()];
            check(
                &format!("AS({nu:.0},{nv:.0})"),
                AshikhminShirley::new(nu, nv),
                s,
                &mut rng,
            );
        }
    }

    #[test]
    fn diagonal_transform_of_isotropic_ggx_is_anisotropic_ggx() {
        // Atanasov et al. 2022 eq. 29: M = diag(α/α_x, α/α_y) turns GGX(α) into GGX(α_x, α_y).
        let (alpha, ax, ay) = (0.3f32, 0.1f32, 0.6f32);
        let tr = Transformed::new(
            Ggx::isotropic(alpha),
            TangentTransform::new((alpha / ax) as f64, 0.0, 0.0, (alpha / ay) as f64),
        );
        let g = Ggx::new(ax, ay);
        let mut rng = Pcg32::new(1, 1);
        let mut worst = 0.0f32;
        for _ in 0..1000 {
            let m = random_direction(&mut rng);
            worst = worst.max((tr.d(m) - g.d(m)).abs() / g.d(m));
            worst = worst.max((tr.lambda(m) - g.lambda(m)).abs() / (1.0 + g.lambda(m)));
        }
        eprintln!("eq. 29 equivalence: worst relative difference {worst:.2e}");
        assert!(worst < 1e-5);
    }

    #[test]
    fn transformed_sampling_matches_pdf() {
        let mut rng = Pcg32::new(52, 6);
        let t = random_transform(&mut rng);
        let tr = Transformed::new(Ggx::new(0.3, 0.5), t);
        let a = lobe(&t, [0.3, 0.5]);
        chi2_test_with(|u1, u2| tr.sample_d(u1, u2), |m| tr.pdf_d(m), a, 13);
        let v = Vec3::new(0.5, 0.5, 0.707).normalize();
        chi2_test_with(
            |u1, u2| tr.sample_visible(v, u1, u2).unwrap(),
            |m| tr.pdf_visible(v, m),
            a,
            14,
        );
        round_trip(&tr, 15);
        let t = random_transform(&mut rng);
        let tg = Transformed::new(Gtr::new(0.4, 1.0), t);
        chi2_test_with(
            |u1, u2| tg.sample_d(u1, u2),
            |m| tg.pdf_d(m),
            lobe(&t, [0.4, 0.4]),
            16,
        );
        let tb = Transformed::new(Beckmann::new(0.2, 0.3), t);
        chi2_test_with(
            |u1, u2| tb.sample_visible(v, u1, u2).unwrap(),
            |m| tb.pdf_visible(v, m),
            lobe(&t, [0.2, 0.3]),
            17,
        );
    }
}
