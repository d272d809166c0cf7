//! The split-sum DFG table (docs/CONVENTIONS.md layout: s = n·v, t = roughness at texel centres,
//! specular = F0·A + B) and the SH-exp Fresnel-tail factor derived from it (Silvennoinen et al. 2025 eq. 15).
//!
//! The table itself comes from `ibl-lut` ([`Dfg::standard`]: `ibl_lut::dfg::dfg_table`, whose
//! B channel is also the R channel of its `fresnel-tail` table, and whose B/(A+B) is that
//! table's G channel). [`dfg_integrals`] / [`Dfg::build`] are an independent VNDF estimator
//! kept as the cross-check of the shared table (see tests).

use crate::microfacet::{g1, g2, reflect, sample_vndf, schlick_tail};
use glam::Vec3;
use ibl_core::sampling::hammersley;

/// (A, B) of the split-sum: A + B = ∫ f_DV (n·l) dl, B = ∫ f_DV (1 − v·h)⁵ (n·l) dl, for a
/// view at cos θ = `n_dot_v` and GGX α = `alpha`, by `samples` VNDF samples (weight G2/G1(v)).
pub fn dfg_integrals(n_dot_v: f32, alpha: f32, samples: u32) -> (f64, f64) {
    let nv = n_dot_v.clamp(1e-4, 1.0);
    let v = Vec3::new((1.0 - nv * nv).sqrt(), 0.0, nv);
    let g1v = g1(nv, alpha);
    let (mut a, mut b) = (0.0f64, 0.0f64);
    for i in 0..samples {
        let (u1, u2) = hammersley(i, samples);
        let h = sample_vndf(v, u1, u2, alpha);
        let l = reflect(v, h);
        if l.z <= 0.0 {
            continue;
        }
        let w = (g2(nv, l.z, alpha) / g1v) as f64;
        let t = schlick_tail(v.dot(h)) as f64;
        a += w * (1.0 - t);
        b += w * t;
    }
    (a / samples as f64, b / samples as f64)
}

/// How the SH-exp path turns E0 into the Fresnel tail E1.
#[derive(
    Clone,
    Copy,
    Debug,
    PartialEq,
    Eq,
    Default,
    serde::Serialize,
    serde::Deserialize,
    clap::ValueEnum,
)]
#[serde(rename_all = "kebab-case")]
pub enum FresnelTail {
    /// Silvennoinen et al. 2025 eq. 15 as printed: E1 ≈ E0 · ∫ f_DV (1−v·h)⁵ (n·l) = E0 · B.
    Printed,
    /// Exact for a constant environment: E1 ≈ E0 · B / (A + B).
    #[default]
    Ratio,
}

/// A tabulated DFG: `data[(j * width + i)] = (A, B)` at n·v = (i+0.5)/width, r = (j+0.5)/height.
#[derive(Clone, Debug)]
pub struct Dfg {
    pub width: usize,
    pub height: usize,
    pub data: Vec<[f32; 2]>,
}

impl Dfg {
    /// Builds a table (parallel over rows).
    pub fn build(width: usize, height: usize, samples: u32) -> Self {
        use rayon::prelude::*;
        let data = (0..width * height)
            .into_par_iter()
            .map(|k| {
                let (i, j) = (k % width, k / width);
                let nv = (i as f32 + 0.5) / width as f32;
                let r = (j as f32 + 0.5) / height as f32;
                let (a, b) = dfg_integrals(nv, r * r, samples);
                [a as f32, b as f32]
            })
            .collect();
        Dfg {
            width,
            height,
            data,
        }
    }

    /// The table every part of this crate shares: `ibl-lut`'s DFG bake at its defaults
    /// (128², 1024 samples per texel), built once per process, so the fit's E0/(A+B) target and
    /// the evaluator use the same values a renderer loads.
    pub fn standard() -> &'static Dfg {
        static TABLE: std::sync::OnceLock<Dfg> = std::sync::OnceLock::new();
        TABLE.get_or_init(|| {
            let p = ibl_lut::dfg::Params::default();
            Dfg::from_image(&ibl_lut::dfg::dfg_table(
                p.size,
                p.samples,
                false,
                &ibl_core::progress::NoProgress,
            ))
        })
    }

    /// A table from an image in the docs/CONVENTIONS.md layout (R = A, G = B).
    pub fn from_image(img: &ibl_core::Image) -> Self {
        let data = (0..img.width * img.height).map(|k| {
            let t = img.texel(k % img.width, k / img.width);
            [t[0], t.get(1).copied().unwrap_or(0.0)]
        });
        Dfg {
            width: img.width,
            height: img.height,
            data: data.collect(),
        }
    }

    /// Bilinear lookup of (A, B) at (n·v, roughness), clamped to the texel centres.
    pub fn ab(&self, n_dot_v: f32, roughness: f32) -> (f32, f32) {
        let x =
            (n_dot_v.clamp(0.0, 1.0) * self.width as f32 - 0.5).clamp(0.0, (self.width - 1) as f32);
        let y = (roughness.clamp(0.0, 1.0) * self.height as f32 - 0.5)
            .clamp(0.0, (self.height - 1) as f32);
        let (x0, y0) = (x.floor() as usize, y.floor() as usize);
        let (x1, y1) = ((x0 + 1).min(self.width - 1), (y0 + 1).min(self.height - 1));
        let (fx, fy) = (x - x0 as f32, y - y0 as f32);
        let at = |i: usize, j: usize| self.data[j * self.width + i];
        let mut out = [0.0f32; 2];
        for (k, o) in out.iter_mut().enumerate() {
            let top = at(x0, y0)[k] + (at(x1, y0)[k] - at(x0, y0)[k]) * fx;
            let bot = at(x0, y1)[k] + (at(x1, y1)[k] - at(x0, y1)[k]) * fx;
            *o = top + (bot - top) * fy;
        }
        (out[0], out[1])
    }

    /// The factor E/E0 of the SH-exp path for base reflectance `f0`:
    /// E = F0·E0 + (1−F0)·E1 with E1 from `tail` (Silvennoinen et al. 2025 eqs. 5, 15).
    pub fn shexp_fresnel_factor(
        &self,
        n_dot_v: f32,
        roughness: f32,
        f0: f32,
        tail: FresnelTail,
    ) -> f32 {
        let (a, b) = self.ab(n_dot_v, roughness);
        let e1_over_e0 = match tail {
            FresnelTail::Printed => b,
            FresnelTail::Ratio => {
                if a + b > 0.0 {
                    b / (a + b)
                } else {
                    0.0
                }
            }
        };
        f0 + (1.0 - f0) * e1_over_e0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::microfacet::f_dv;

    #[test]
    fn integrals_match_quadrature() {
        for (nv, alpha) in [(0.9f32, 0.25f32), (0.3, 0.6), (0.05, 1.0)] {
            let (a, b) = dfg_integrals(nv, alpha, 1 << 16);
            let v = Vec3::new((1.0 - nv * nv).sqrt(), 0.0, nv);
            let k = 600;
            let (mut s, mut t) = (0.0f64, 0.0f64);
            for i in 0..k {
                let z = (i as f64 + 0.5) / k as f64;
                let st = (1.0 - z * z).sqrt();
                for j in 0..2 * k {
                    let phi = std::f64::consts::PI * (j as f64 + 0.5) / k as f64;
                    let l = Vec3::new((st * phi.cos()) as f32, (st * phi.sin()) as f32, z as f32);
                    let f = (f_dv(v, l, alpha) * l.z) as f64;
                    s += f;
                    t += f * schlick_tail(v.dot((v + l).normalize())) as f64;
                }
            }
            let w = 2.0 * std::f64::consts::PI / (2 * k * k) as f64;
            eprintln!(
                "n·v={nv} α={alpha}: A+B {:.5} vs {:.5}, B {b:.5} vs {:.5}",
                a + b,
                s * w,
                t * w
            );
            assert!((a + b - s * w).abs() < 3e-3);
            assert!((b - t * w).abs() < 2e-3);
        }
    }

    #[test]
    fn shared_table_agrees_with_the_independent_estimator() {
        // ibl-lut's table (GGX-D sampling) against our VNDF estimator at the same texel centres.
        let shared = Dfg::standard();
        let mut worst = [0.0f32; 2];
        for (i, j) in [
            (0usize, 0usize),
            (3, 64),
            (64, 64),
            (127, 10),
            (10, 127),
            (127, 127),
            (0, 127),
        ] {
            let nv = (i as f32 + 0.5) / shared.width as f32;
            let r = (j as f32 + 0.5) / shared.height as f32;
            let (a, b) = dfg_integrals(nv, r * r, 1 << 15);
            let s = shared.data[j * shared.width + i];
            worst[0] = worst[0].max((s[0] - a as f32).abs());
            worst[1] = worst[1].max((s[1] - b as f32).abs());
        }
        eprintln!(
            "ibl-lut DFG vs independent VNDF estimate: max |ΔA| {:.2e}, max |ΔB| {:.2e}",
            worst[0], worst[1]
        );
        assert!(worst[0] < 5e-3 && worst[1] < 5e-3, "{worst:?}");
    }

    #[test]
    fn lookup_hits_texel_centres_and_factor_limits() {
        let dfg = Dfg::build(8, 8, 512);
        let (a, b) = dfg.ab(2.5 / 8.0, 5.5 / 8.0);
        assert_eq!([a, b], dfg.data[5 * 8 + 2]);
        // Chrome: factor 1 whatever the tail; ratio mode gives at most 1.
        assert_eq!(
            dfg.shexp_fresnel_factor(0.5, 0.7, 1.0, FresnelTail::Ratio),
            1.0
        );
        let f = dfg.shexp_fresnel_factor(0.05, 0.7, 0.04, FresnelTail::Ratio);
        assert!(f > 0.04 && f <= 1.0, "{f}");
    }
}
