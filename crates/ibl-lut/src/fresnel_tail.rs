//! The Fresnel-tail table of the SH-exponential paper (Silvennoinen et al. 2025 §4.2, eq. 15): over
//! s = n·v (columns) and t = roughness r (rows), at texel centres like the DFG table,
//!   R = T(v, α) = ∫ f_DV(v, l) (1 − v·h)⁵ (n·l) dl     (the integral printed in eq. 15),
//!   G = T / E_dir,   E_dir = ∫ f_DV (n·l) dl              (the same integral per unit albedo).
//!
//! f_DV = D·V is GGX with height-correlated Smith, α = r² (clamped to `dfg::ALPHA_MIN`).
//! T is exactly the B channel of the split-sum table (the two integrands are the same), and it
//! comes from the same estimators (VNDF by default), so `tail_value` equals
//! `dfg::dfg_value(..)[1]` bit for bit.
//!
//! Erratum (Silvennoinen et al. 2025 eq. 15): under its own premise — a constant environment L — eq. 6 gives
//! E0 = L·E_dir and eq. 7 gives E1 = L·T, so E1 = E0 · T / E_dir. The printed
//! E1 ≈ E0 ∫ f_DV (1 − v·h)⁵ (n·l) dl omits the division by E_dir (it reads E0 as if it were L);
//! the G channel is that normalised ratio, for callers who want the self-consistent form.

use crate::dfg::{map_dfg_rows, Estimator};
use crate::error::{Error, Result};
use crate::table::{self, Baked, Describe};
use ibl_core::progress::Progress;
use ibl_core::Image;
use std::path::Path;

/// Parameters of the `fresnel-tail` bake: CLI flags and RON keys alike.
#[derive(Clone, Debug, PartialEq, clap::Args, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Params {
    /// Table side in texels (size × size).
    #[arg(
        long,
        value_name = "N",
        default_value_t = 64,
        allow_negative_numbers = true
    )]
    pub size: usize,
    /// Hammersley samples per texel.
    #[arg(
        long,
        value_name = "N",
        default_value_t = 1024,
        allow_negative_numbers = true
    )]
    pub samples: u32,
    /// Monte-Carlo estimator: visible normals (vndf) or D(h)(n·h) (ndf).
    #[arg(long, value_enum, default_value_t = Estimator::Vndf)]
    pub estimator: Estimator,
    /// Write half floats in EXR outputs.
    #[arg(long)]
    pub half: bool,
}

impl Default for Params {
    fn default() -> Self {
        ibl_core::params::clap_defaults()
    }
}

impl Params {
    /// Checks the parameters (size, samples) before any work.
    pub fn validate(&self) -> Result<()> {
        table::check_size("size", self.size)?;
        table::check_samples(self.samples)
    }
}

#[cfg(test)]
/// T(n·v, r) = ∫ f_DV (1 − v·h)⁵ (n·l) dl (Silvennoinen et al. 2025 eq. 15's integral) with `samples`
/// Hammersley samples; the value the table stores in R at that texel.
pub(crate) fn tail_value(n_dot_v: f32, roughness: f32, samples: u32) -> f32 {
    tail_and_albedo(n_dot_v, roughness, samples)[0]
}

#[cfg(test)]
/// (T, E_dir) at (n·v, r): the tail integral and the directional albedo ∫ f_DV (n·l) dl.
pub(crate) fn tail_and_albedo(n_dot_v: f32, roughness: f32, samples: u32) -> [f32; 2] {
    let [a, b] = crate::dfg::dfg_value(n_dot_v, roughness, samples);
    [b, a + b]
}

/// The whole table with the default (VNDF) estimator: size × size, R = T, G = T / E_dir.
pub fn tail_table(size: usize, samples: u32, progress: &dyn Progress) -> Image {
    tail_table_with(Estimator::Vndf, size, samples, progress)
}

/// [`tail_table`] with a chosen estimator.
pub(crate) fn tail_table_with(
    estimator: Estimator,
    size: usize,
    samples: u32,
    progress: &dyn Progress,
) -> Image {
    map_dfg_rows(estimator, size, samples, 2, progress, |[a, b], t| {
        let e = a + b;
        t[0] = b;
        t[1] = if e > 0.0 { b / e } else { 0.0 };
    })
}

/// How the Fresnel-tail table describes itself in its JSON/RON dump.
pub fn describe(params: &Params) -> Describe<'static> {
    Describe {
        table:
            "Fresnel tail of Silvennoinen et al. 2025 eq. 15 (GGX, height-correlated Smith, alpha = roughness^2)",
        channels: &[
            "T = integral of f_DV (1-v.h)^5 (n.l) dl",
            "T / E_dir (E_dir = integral of f_DV (n.l) dl)",
        ],
        s: "n.v at texel centres (i+0.5)/W",
        t: "perceptual roughness r at texel centres (j+0.5)/H, row 0 first",
        params: serde_json::to_value(params).expect("params serialise"),
    }
}

/// Bakes the table and encodes it for `out` (.exr, .png 16-bit, .json, .ron).
pub fn run(params: &Params, out: &Path, progress: &dyn Progress) -> Result<Baked> {
    params.validate()?;
    table::Format::of(out)?;
    let image = tail_table_with(params.estimator, params.size, params.samples, progress);
    if image.data.iter().any(|v| !v.is_finite()) {
        return Err(Error::param(
            "internal error: non-finite Fresnel-tail texel",
        ));
    }
    let bytes = table::encode(out, &image, &describe(params), 16, params.half)?;
    let details = serde_json::json!({ "table": "fresnel-tail", "size": params.size, "samples": params.samples, "estimator": params.estimator });
    Ok(Baked {
        files: vec![(out.to_path_buf(), bytes)],
        image,
        details,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dfg::{alpha_of, dfg_value};
    use crate::reference::DfgReference;
    use crate::table::texel_centre;
    use ibl_core::progress::NoProgress;

    #[test]
    fn tail_is_the_dfg_bias_and_matches_the_reference() {
        let size = 8;
        let img = tail_table(size, 1024, &NoProgress);
        let reference = DfgReference::new(256);
        let (mut sum, mut worst) = (0.0f64, 0.0f64);
        for j in 0..size {
            for i in 0..size {
                let (nv, r) = (texel_centre(i, size) as f32, texel_centre(j, size) as f32);
                let t = img.texel(i, j);
                assert_eq!(t[0], dfg_value(nv, r, 1024)[1]);
                assert_eq!(t[0], tail_value(nv, r, 1024));
                let [a, b] = reference.dfg(nv as f64, alpha_of(r) as f64);
                let e = (t[0] as f64 - b).abs();
                let e_ratio = (t[1] as f64 - b / (a + b)).abs();
                sum += e;
                worst = worst.max(e).max(e_ratio);
            }
        }
        eprintln!("Fresnel tail 8² × 1024 vs quadrature: mean abs error {:.2e}, max (T and ratio) {worst:.2e}", sum / 64.0);
        assert!(sum / 64.0 < 2e-3 && worst < 1e-2);
    }

    #[test]
    fn edges_are_finite() {
        for &r in &[0.0f32, 1.0] {
            for &nv in &[1e-6f32, 1.0] {
                let [t, e] = tail_and_albedo(nv, r, 64);
                assert!(t.is_finite() && e.is_finite() && t >= 0.0 && t <= e.max(0.0) + 1e-6);
            }
        }
        let img = tail_table(4, 16, &NoProgress);
        assert!(img
            .data
            .iter()
            .all(|v| v.is_finite() && *v >= 0.0 && *v <= 1.0));
    }
}
