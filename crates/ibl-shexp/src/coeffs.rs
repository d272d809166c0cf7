//! The fitted SH-exponential probe (what `shexp-fit` writes) and its reconstruction,
//! paper 002 eq. 11: E0(v, n, α) ≈ exp(⟨vMF(1/α) ⊙ Y(r), p⟩ + ⟨vMF(1/α) ⊙ Y(h_r), q⟩).

use crate::basis::{band_of, coeffs_of_order, reflection_pair, vmf_band};
use crate::dfg::FresnelTail;
use crate::Error;
use glam::Vec3;
use ibl_core::{sh, Rgb};
use std::path::Path;

/// Coefficients of one probe and how they were fitted.
///
/// `p` holds (p_order+1)² RGB coefficients in DESIGN.md SH order from index 0 (evaluated at
/// the reflection r); `q` holds (q_order+1)² − 1 from index 1 (its DC dropped, evaluated at
/// h_r = normalize(n + r)). Band l of both is damped by exp(−l(l+1)·α/2), α the GGX α = r².
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Coeffs {
    pub p_order: usize,
    pub q_order: usize,
    /// GGX α values the rows were fitted at.
    pub alphas: Vec<f32>,
    pub p: Vec<[f32; 3]>,
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
    /// What exp(P·Q) reconstructs: E0 itself (paper 002, the default) or E0 / (A+B).
    #[serde(default)]
    pub target: Target,
    /// What the solve minimised.
    #[serde(default)]
    pub objective: Objective,
    /// Human-readable reminder of the conventions.
    #[serde(default)]
    pub convention: String,
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
    /// E0(v, n, α) itself (paper 002 eqs. 11, 13).
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
    /// Squared log-space error, paper 002 eq. 13 (one linear least-squares solve).
    #[default]
    Log,
    /// From the eq. 13 solution, Gauss–Newton on the linear error relative per α group plus λ ×
    /// the log-space error ([`crate::refine`]): the linear MSE the paper's log fit is a proxy of.
    Relative,
}

/// Highest SH order (l_max) of P or Q.
pub const MAX_ORDER: usize = 8;

/// The convention string written into every probe.
pub const CONVENTION: &str = "E0(v,n,alpha) = exp(sum_i vmf(l_i,alpha) Y_i(r) p_i + sum_{i>=1} vmf(l_i,alpha) Y_i(h_r) q_{i-1}); \
r = 2(n.v)n - v, h_r = normalize(n + r), Y = DESIGN.md real orthonormal SH (i = l(l+1)+m, no Condon-Shortley phase), \
vmf(l,alpha) = exp(-l(l+1)*alpha/2), alpha = GGX alpha = roughness^2";

impl Coeffs {
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
        Ok(())
    }

    /// Paper 002 eq. 11: the reconstructed base reflectance at normal `n`, view `v` (unit,
    /// pointing away from the surface) and GGX α.
    pub fn e0(&self, n: Vec3, v: Vec3, alpha: f32) -> Rgb {
        let (r, hr) = reflection_pair(n, v);
        let mut y = [0.0f32; coeffs_of_order(MAX_ORDER)];
        let mut s = [0.0f32; 3];
        sh::eval_basis(r, self.p_order + 1, &mut y);
        for (i, c) in self.p.iter().enumerate() {
            let w = vmf_band(band_of(i), alpha) * y[i];
            for k in 0..3 {
                s[k] += w * c[k];
            }
        }
        sh::eval_basis(hr, self.q_order + 1, &mut y);
        for (j, c) in self.q.iter().enumerate() {
            let w = vmf_band(band_of(j + 1), alpha) * y[j + 1];
            for k in 0..3 {
                s[k] += w * c[k];
            }
        }
        s.map(f32::exp)
    }

    /// Bytes of the probe as 32-bit floats (the paper's storage measure).
    pub fn bytes(&self) -> usize {
        (self.p.len() + self.q.len()) * 3 * 4
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dc_only_probe_reconstructs_a_constant() {
        let mut c = Coeffs {
            p_order: 1,
            q_order: 1,
            alphas: vec![0.5],
            p: vec![[0.0; 3]; 4],
            q: vec![[0.0; 3]; 3],
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
        };
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
}
