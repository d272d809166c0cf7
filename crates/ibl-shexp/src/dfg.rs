//! The split-sum DFG table (docs/CONVENTIONS.md layout: s = n·v, t = roughness at texel centres,
//! specular = F0·A + B) and the SH-exp Fresnel-tail factor derived from it (Silvennoinen et al. 2025 eq. 15).
//!
//! The table itself comes from `ibl-lut` ([`Dfg::standard`]: `ibl_lut::dfg::dfg_table`, whose
//! B channel is also the R channel of its `fresnel-tail` table, and whose B/(A+B) is that
//! table's G channel); the tests check it against `ibl_lut::reference::DfgReference`, the
//! Gauss–Legendre quadrature that shares nothing with the bake's estimator.

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
    /// Columns (n·v axis).
    pub width: usize,
    /// Rows (roughness axis).
    pub height: usize,
    /// (A, B) per texel, row by row.
    pub data: Vec<[f32; 2]>,
}

impl Dfg {
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

    /// A small table baked by `ibl-lut` (size², `samples` per texel) for tests that need a
    /// cheap one.
    #[cfg(test)]
    pub(crate) fn baked(size: usize, samples: u32) -> Self {
        Dfg::from_image(&ibl_lut::dfg::dfg_table(
            size,
            samples,
            false,
            &ibl_core::progress::NoProgress,
        ))
    }

    /// A table from an image in the docs/CONVENTIONS.md layout (R = A, G = B).
    pub(crate) fn from_image(img: &ibl_core::Image) -> Self {
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
    use ibl_lut::reference::DfgReference;

    #[test]
    fn shared_table_agrees_with_the_quadrature_reference() {
        // The table as this crate loads it (R = A, G = B) against the independent product
        // Gauss–Legendre rule at the same texel centres.
        let shared = Dfg::standard();
        let reference = DfgReference::new(256);
        let mut worst = [0.0f64; 2];
        for (i, j) in [
            (0usize, 0usize),
            (3, 64),
            (64, 64),
            (127, 10),
            (10, 127),
            (127, 127),
            (0, 127),
        ] {
            let nv = (i as f64 + 0.5) / shared.width as f64;
            let r = (j as f64 + 0.5) / shared.height as f64;
            let [a, b] = reference.dfg(nv, r * r);
            let s = shared.data[j * shared.width + i];
            worst[0] = worst[0].max((s[0] as f64 - a).abs());
            worst[1] = worst[1].max((s[1] as f64 - b).abs());
        }
        eprintln!(
            "ibl-lut DFG vs Gauss–Legendre reference: max |ΔA| {:.2e}, max |ΔB| {:.2e}",
            worst[0], worst[1]
        );
        assert!(worst[0] < 5e-3 && worst[1] < 5e-3, "{worst:?}");
    }

    #[test]
    fn lookup_hits_texel_centres_and_factor_limits() {
        let dfg = Dfg::baked(8, 512);
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
