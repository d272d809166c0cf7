//! Spherical-harmonic-exponential glossy reflections (Silvennoinen, Sloan, Iwanicki,
//! Nowrouzezahrai 2025, "Silvennoinen et al. 2025"): the log-space least-squares fit of the base reflectance
//! E0 (§4.1, eqs. 9–14), its reconstruction (eq. 11), the Fresnel tail (eq. 15), an exact
//! ground truth, the split-sum baseline and the §5.1 evaluator, and GLSL/HLSL emission.
//!
//! Errata and readings of Silvennoinen et al. 2025 (also in the report):
//! - α everywhere is the GGX α = roughness² ("linear roughness"), κ = 1/α in eq. 12.
//! - Eq. 15 as printed, E1 ≈ E0 · ∫ f_DV (1−v·h)⁵ (n·l), is not exact even for a constant
//!   environment: there E1 = E0 · B/(A+B) (B/(A+B) of the DFG table). Both are implemented
//!   ([`dfg::FresnelTail`]); on the fixtures B/(A+B) has the lower MSE in 84 of 96 dielectric
//!   cases, so it is the default. Even with an exact E0, the constant-environment assumption of
//!   eq. 15 alone loses to split-sum in 19 of 96 dielectric cases (bench/shexp.md).
//! - Eq. 11 cannot represent a view- or roughness-dependent albedo: the DC term is not damped
//!   (vMF_0 = 1), and for a constant environment E0 = L·(A+B)(n·v, α) depends on n·v = r·n only
//!   through the coupling of r and h_r, which a sum P(r) + Q(h_r) cannot hold (log RMS residual
//!   ≈ 0.33 on a constant environment, see `fit` tests). Dividing the DFG albedo out of the
//!   target ([`coeffs::Target::E0OverAlbedo`], not in the paper) removes that error.
//! - Eq. 13's log-space error is a weak proxy of the linear MSE §5.1 measures: it weighs a dark
//!   row's relative error like a sunlit one's. The default solve refines the eq. 13 solution on
//!   the relative linear error ([`refine`], `objective = relative`), keeping eq. 11's form.
//! - §5.1's "lower MSE in 95% of 192 cases" does not hold against this workspace's split-sum
//!   (ibl-prefilter chain × ibl-lut DFG) on the fixtures: 54% with the paper's log fit, 60% with
//!   the default refinement, 70% with E0/(A+B) as the target; nor against a paper-like chain
//!   (1024 samples, mips ≥ 32², the same score). SH-exp loses mostly at α ≤ 0.36, where order-4
//!   SH cannot hold the lobe-scale detail (per-α oracle fits reach 73%, 79% at P order 8), and
//!   for the dielectric, where eq. 15 alone (exact E0) loses 19 of 96 cases.

#![warn(missing_docs)]

mod bake_def;
pub mod basis;
pub mod coeffs;
pub mod dfg;
pub mod estimate;
pub mod eval;
pub mod fit;
pub mod refine;
pub mod shader;
pub mod solve;
pub mod splitsum;
pub mod truth;

pub use bake_def::{ShexpFit, SHEXP_FIT};
pub use coeffs::Coeffs;

use ibl_core::error::{Classify, ErrorClass};

/// Errors of the SH-exp fit and evaluator.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// Bad input, unsupported input or I/O from the core library.
    #[error(transparent)]
    Core(#[from] ibl_core::Error),
    /// The least-squares system has too few rows or is numerically rank deficient.
    #[error("least-squares system of {rows} rows and {unknowns} unknowns is rank deficient (condition number above 1e12): use more --normals, --views or --alphas, or lower --p-order/--q-order")]
    RankDeficient {
        /// Rows of the system.
        rows: usize,
        /// Unknowns of the system.
        unknowns: usize,
    },
}

impl Classify for Error {
    fn class(&self) -> ErrorClass {
        match self {
            Error::Core(e) => e.class(),
            Error::RankDeficient { .. } => ErrorClass::InvalidInput,
        }
    }
}

/// A result with the SH-exp [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;
