//! The fitted SH-exponential probe (what `shexp-fit` writes) and its reconstruction,
//! Silvennoinen et al. 2025 eq. 11: E0(v, n, α) ≈ exp(⟨vMF(1/α) ⊙ Y(r), p⟩ + ⟨vMF(1/α) ⊙ Y(h_r), q⟩).

use crate::basis::{band_of, coeffs_of_order, knot_weights, reflection_pair, vmf_band};
use crate::dfg::FresnelTail;
use crate::Error;
use glam::Vec3;
use ibl_core::{sh, Rgb};
use std::path::Path;

/// Coefficients of one probe and how they were fitted.
///
/// `p` holds (p_order+1)² RGB coefficients in docs/CONVENTIONS.md SH order from index 0 (evaluated at
/// the reflection r); `q` holds (q_order+1)² − 1 from index 1 (its DC dropped, evaluated at
/// h_r = normalize(n + r)). Band l of both is damped by exp(−l(l+1)·α/2), α the GGX α = r².
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Coeffs {
    /// Highest SH band of P.
    pub p_order: usize,
    /// Highest SH band of Q.
    pub q_order: usize,
    /// GGX α values the rows were fitted at.
    pub alphas: Vec<f32>,
    /// Coefficients of P, RGB.
    pub p: Vec<[f32; 3]>,
    /// Coefficients of Q, RGB (index 0, the DC, unused).
    pub q: Vec<[f32; 3]>,
    /// Log-space RMS residual of the fit over all rows and channels.
    pub residual: f64,
    /// The same per channel.
    #[serde(default)]
    pub residual_rgb: [f64; 3],
    /// 2-norm condition number of the column-equilibrated design matrix.
    #[serde(default)]
    pub condition_number: f64,
    /// Rows of the least-squares system (normals × views × α).
    #[serde(default)]
    pub rows: usize,
    /// E0 samples per row (0 for exact summation).
    #[serde(default)]
    pub samples: usize,
    /// Radiance floor applied to E0 before the log (per channel).
    #[serde(default)]
    pub floor: [f32; 3],
    /// How E1 is derived from E0 by consumers of this probe (eq. 15 printed or B/(A+B)).
    #[serde(default)]
    pub fresnel: FresnelTail,
    /// What exp(P·Q) reconstructs: E0 itself (Silvennoinen et al. 2025, the default) or E0 / (A+B).
    #[serde(default)]
    pub target: Target,
    /// What the solve minimised.
    #[serde(default)]
    pub objective: Objective,
    /// Human-readable reminder of the conventions.
    #[serde(default)]
    pub convention: String,
    /// Optional extension beyond eq. 11 (`--alpha-knots`): coefficient sets at GGX α knots,
    /// interpolated linearly in α. When present, [`Coeffs::e0`] reconstructs from them; `p`
    /// and `q` stay the eq. 11 fit of the same rows, so an eq. 11 reader still reads the file.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub alpha_knots: Option<AlphaKnots>,
}

/// Coefficients that vary with roughness (not in Silvennoinen et al. 2025): at GGX α the probe uses
/// p(α) = w₀·p[s] + w₁·p[s+1] (likewise q), the hat weights of [`crate::basis::knot_weights`],
/// in eq. 11 unchanged. Why: eq. 11 ties every α to one coefficient set through the vMF damping
/// alone, so its DC (undamped) cannot follow the directional albedo's fall with α, and the
/// damping law fixes how each band fades; letting the coefficients move linearly between two
/// or three knots lifts the §5.1 win rate from 60% to 80%+ (bench/shexp.md) at 2–3× the
/// memory, with the same single eq. 11 evaluation per pixel after a lerp of the coefficients.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AlphaKnots {
    /// Knot positions in GGX α, strictly increasing.
    pub alphas: Vec<f32>,
    /// Per knot: p as in [`Coeffs::p`].
    pub p: Vec<Vec<[f32; 3]>>,
    /// Per knot: q as in [`Coeffs::q`].
    pub q: Vec<Vec<[f32; 3]>>,
    /// Log-space RMS residual of the knot fit over all rows and channels.
    #[serde(default)]
    pub residual: f64,
}

/// What the fitted exponential reconstructs.
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
#[serde(rename_all = "snake_case")]
pub enum Target {
    /// E0(v, n, α) itself (Silvennoinen et al. 2025 eqs. 11, 13).
    #[default]
    E0,
    /// E0 / (A+B)(n·v, r): the environment's share of E0 once the directional albedo of the
    /// split-sum DFG table is divided out; consumers multiply by F0·A + B (with `fresnel =
    /// ratio`) instead of E0's Fresnel factor. Not in the paper (ablation).
    E0OverAlbedo,
}

/// What the least-squares solve minimised (recorded in the probe; eq. 11 reads both alike).
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
#[serde(rename_all = "snake_case")]
pub enum Objective {
    /// Squared log-space error, Silvennoinen et al. 2025 eq. 13 (one linear least-squares solve).
    #[default]
    Log,
    /// From the eq. 13 solution, Gauss–Newton on the linear error relative per α group plus λ ×
    /// the log-space error (the refine module): the linear MSE the paper's log fit is a proxy of.
    Relative,
}

/// Highest SH order (l_max) of P or Q.
pub(crate) const MAX_ORDER: usize = 8;

/// The convention string written into every probe.
pub(crate) const CONVENTION: &str = "E0(v,n,alpha) = exp(sum_i vmf(l_i,alpha) Y_i(r) p_i + sum_{i>=1} vmf(l_i,alpha) Y_i(h_r) q_{i-1}); \
r = 2(n.v)n - v, h_r = normalize(n + r), Y = docs/CONVENTIONS.md real orthonormal SH (i = l(l+1)+m, no Condon-Shortley phase), \
vmf(l,alpha) = exp(-l(l+1)*alpha/2), alpha = GGX alpha = roughness^2";

impl Coeffs {
    /// A probe of the given orders with every coefficient 0 (E0 = 1) and empty diagnostics,
    /// to be filled in.
    pub fn zeros(p_order: usize, q_order: usize, alphas: Vec<f32>) -> Coeffs {
        Coeffs {
            p_order,
            q_order,
            alphas,
            p: vec![[0.0; 3]; coeffs_of_order(p_order)],
            q: vec![[0.0; 3]; coeffs_of_order(q_order) - 1],
            residual: 0.0,
            residual_rgb: [0.0; 3],
            condition_number: 1.0,
            rows: 0,
            samples: 0,
            floor: [0.0; 3],
            fresnel: FresnelTail::Ratio,
            target: Target::E0,
            objective: Objective::Log,
            convention: CONVENTION.into(),
            alpha_knots: None,
        }
    }

    /// Checks the shapes (after reading a file).
    pub fn validate(&self, path: &Path) -> Result<(), Error> {
        if self.p_order > MAX_ORDER || self.q_order > MAX_ORDER {
            return Err(Error::Core(ibl_core::Error::invalid(
                path,
                format!("SH orders above {MAX_ORDER} are not supported"),
            )));
        }
        if self.p.len() != coeffs_of_order(self.p_order) {
            return Err(Error::Core(ibl_core::Error::invalid(
                path,
                format!(
                    "p has {} coefficients, p_order {} needs {}",
                    self.p.len(),
                    self.p_order,
                    coeffs_of_order(self.p_order)
                ),
            )));
        }
        if self.q.len() + 1 != coeffs_of_order(self.q_order) {
            return Err(Error::Core(ibl_core::Error::invalid(
                path,
                format!(
                    "q has {} coefficients, q_order {} needs {}",
                    self.q.len(),
                    self.q_order,
                    coeffs_of_order(self.q_order) - 1
                ),
            )));
        }
        if self
            .p
            .iter()
            .chain(&self.q)
            .flatten()
            .any(|v| !v.is_finite())
        {
            return Err(Error::Core(ibl_core::Error::invalid(
                path,
                "non-finite coefficient",
            )));
        }
        if let Some(k) = &self.alpha_knots {
            let bad = |m: String| Err(Error::Core(ibl_core::Error::invalid(path, m)));
            if k.alphas.len() < 2 || k.alphas.len() > MAX_KNOTS {
                return bad(format!(
                    "alpha_knots has {} knots, 2..={MAX_KNOTS} are supported",
                    k.alphas.len()
                ));
            }
            if k.alphas.iter().any(|a| !(*a > 0.0 && *a <= 1.0))
                || k.alphas.windows(2).any(|w| w[1] <= w[0])
            {
                return bad("alpha_knots.alphas must increase strictly within (0, 1]".into());
            }
            if k.p.len() != k.alphas.len() || k.q.len() != k.alphas.len() {
                return bad("alpha_knots needs one p and one q set per knot".into());
            }
            if k.p.iter().any(|p| p.len() != self.p.len())
                || k.q.iter().any(|q| q.len() != self.q.len())
            {
                return bad("alpha_knots sets must have the lengths of p and q".into());
            }
            if k.p
                .iter()
                .chain(&k.q)
                .flatten()
                .flatten()
                .any(|v| !v.is_finite())
            {
                return bad("non-finite coefficient in alpha_knots".into());
            }
        }
        Ok(())
    }

    /// What [`Coeffs::e0`] reconstructs, in words (for reports).
    pub fn describe(&self) -> String {
        let per = self.p.len() + self.q.len();
        match &self.alpha_knots {
            None => format!("eq. 11, {per} coefficients per channel"),
            Some(k) => format!(
                "α knots {:?} (beyond eq. 11): {} × {per} coefficients per channel",
                k.alphas,
                k.alphas.len()
            ),
        }
    }

    /// The probe as Silvennoinen et al. 2025 writes it: p and q alone, any `alpha_knots` dropped.
    pub fn eq11(&self) -> Coeffs {
        Coeffs {
            alpha_knots: None,
            ..self.clone()
        }
    }

    /// The coefficients reconstruction uses at GGX α: p, q, or their knot interpolation.
    pub(crate) fn coefficients_at(&self, alpha: f32) -> (Vec<[f32; 3]>, Vec<[f32; 3]>) {
        let Some(k) = &self.alpha_knots else {
            return (self.p.clone(), self.q.clone());
        };
        let ((s0, w0), (s1, w1)) = knot_weights(&k.alphas, alpha);
        let lerp = |a: &[[f32; 3]], b: &[[f32; 3]]| -> Vec<[f32; 3]> {
            a.iter()
                .zip(b)
                .map(|(x, y)| std::array::from_fn(|c| w0 * x[c] + w1 * y[c]))
                .collect()
        };
        (lerp(&k.p[s0], &k.p[s1]), lerp(&k.q[s0], &k.q[s1]))
    }

    /// Silvennoinen et al. 2025 eq. 11: the reconstructed base reflectance at normal `n`, view `v` (unit,
    /// pointing away from the surface) and GGX α.
    pub fn e0(&self, n: Vec3, v: Vec3, alpha: f32) -> Rgb {
        if self.alpha_knots.is_some() {
            let (p, q) = self.coefficients_at(alpha);
            return e0_with(self.p_order, self.q_order, &p, &q, n, v, alpha);
        }
        e0_with(self.p_order, self.q_order, &self.p, &self.q, n, v, alpha)
    }

    /// Bytes of the probe as 32-bit floats (the paper's storage measure), counting what
    /// [`Coeffs::e0`] reads: the knot sets when present.
    pub fn bytes(&self) -> usize {
        let sets = self.alpha_knots.as_ref().map_or(1, |k| k.alphas.len());
        sets * (self.p.len() + self.q.len()) * 3 * 4
    }
}

/// Most α knots a probe may carry.
pub(crate) const MAX_KNOTS: usize = 8;

/// Silvennoinen et al. 2025 eq. 11 for explicit coefficient sets.
fn e0_with(
    p_order: usize,
    q_order: usize,
    p: &[[f32; 3]],
    q: &[[f32; 3]],
    n: Vec3,
    v: Vec3,
    alpha: f32,
) -> Rgb {
    let (r, hr) = reflection_pair(n, v);
    let mut y = [0.0f32; coeffs_of_order(MAX_ORDER)];
    let mut s = [0.0f32; 3];
    sh::eval_basis(r, p_order + 1, &mut y);
    for (i, c) in p.iter().enumerate() {
        let w = vmf_band(band_of(i), alpha) * y[i];
        for k in 0..3 {
            s[k] += w * c[k];
        }
    }
    sh::eval_basis(hr, q_order + 1, &mut y);
    for (j, c) in q.iter().enumerate() {
        let w = vmf_band(band_of(j + 1), alpha) * y[j + 1];
        for k in 0..3 {
            s[k] += w * c[k];
        }
    }
    s.map(f32::exp)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dc_only_probe_reconstructs_a_constant() {
        let mut c = Coeffs::zeros(1, 1, vec![0.5]);
        // p00 · Y00 = ln 2 → E0 = 2 everywhere, at every α (the DC is not damped).
        c.p[0] = [(2.0f32).ln() / 0.282_094_8; 3];
        for alpha in [0.2, 1.0] {
            let e = c.e0(Vec3::new(0.0, 0.6, 0.8), Vec3::Z, alpha);
            assert!((e[0] - 2.0).abs() < 1e-5, "{e:?}");
        }
        // A band-1 Q term along +z, seen at n = v = +z (h_r = +z): exp(vmf_1 · Y10 · q).
        c.q[1] = [1.0, 0.0, 0.0];
        let e = c.e0(Vec3::Z, Vec3::Z, 0.5);
        let want = 2.0 * (vmf_band(1, 0.5) * 0.488_602_5f32).exp();
        assert!((e[0] - want).abs() < 1e-5 && (e[1] - 2.0).abs() < 1e-5);
        assert!(c.validate(Path::new("x.json")).is_ok());
        c.q.pop();
        assert!(c.validate(Path::new("x.json")).is_err());
    }

    #[test]
    fn alpha_knots_interpolate_validate_and_round_trip() {
        let mut c = Coeffs {
            p: (0..9).map(|i| [0.1 * i as f32, -0.2, 0.05]).collect(),
            q: vec![[0.3, 0.0, -0.1]; 3],
            ..Coeffs::zeros(2, 1, vec![0.2, 1.0])
        };
        let json_eq11 = serde_json::to_string(&c).unwrap();
        assert!(
            !json_eq11.contains("alpha_knots"),
            "eq. 11 files keep their shape"
        );
        let (n, v) = (Vec3::new(0.3, 0.8, 0.52).normalize(), Vec3::Y);
        // Identical sets at every knot: the same as eq. 11 at every α.
        c.alpha_knots = Some(AlphaKnots {
            alphas: vec![0.2, 0.6, 1.0],
            p: vec![c.p.clone(); 3],
            q: vec![c.q.clone(); 3],
            residual: 0.0,
        });
        for alpha in [0.1f32, 0.2, 0.45, 0.6, 0.9, 1.0] {
            let (a, b) = (c.e0(n, v, alpha), c.eq11().e0(n, v, alpha));
            assert!(
                (0..3).all(|k| (a[k] - b[k]).abs() <= 1e-6 * b[k]),
                "{a:?} {b:?}"
            );
        }
        // A DC that moves with α: halfway between knots 0.2 and 0.6 it is the mean of the two.
        let y00 = 0.282_094_8f32;
        let k = c.alpha_knots.as_mut().unwrap();
        k.p[0][0] = [(2.0f32).ln() / y00; 3];
        k.p[1][0] = [(8.0f32).ln() / y00; 3];
        let mut flat = c.clone();
        for set in flat.alpha_knots.as_mut().unwrap().p.iter_mut() {
            set[0] = [0.0; 3];
        }
        let ratio = c.e0(n, v, 0.4)[0] / flat.e0(n, v, 0.4)[0];
        assert!((ratio - 4.0).abs() < 1e-4, "{ratio}");
        assert_eq!(c.bytes(), 3 * c.eq11().bytes());
        assert!(c.validate(Path::new("x.json")).is_ok());
        // Round trip, and files without knots still read.
        let back: Coeffs = serde_json::from_str(&serde_json::to_string(&c).unwrap()).unwrap();
        assert_eq!(back, c);
        let old: Coeffs = serde_json::from_str(&json_eq11).unwrap();
        assert!(old.alpha_knots.is_none());
        // Malformed knots are refused.
        let broken = |f: &dyn Fn(&mut AlphaKnots)| {
            let mut b = c.clone();
            f(b.alpha_knots.as_mut().unwrap());
            b.validate(Path::new("x.json")).is_err()
        };
        assert!(broken(&|k| k.alphas = vec![0.2, 0.2, 1.0]));
        assert!(broken(&|k| k.alphas = vec![0.2, 0.6, 1.5]));
        assert!(broken(&|k| k.alphas = vec![0.2]));
        assert!(broken(&|k| {
            k.p.pop();
        }));
        assert!(broken(&|k| {
            k.q[1].pop();
        }));
        assert!(broken(&|k| k.p[2][3][1] = f32::NAN));
    }
}
