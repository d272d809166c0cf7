//! Anisotropic specular image-based lighting, end to end (issue 23): a ground truth
//! ([`truth`]: Monte Carlo with visible-normal / exact p_h sampling over the native cube, with
//! its standard error, and a texel sum to cross-check it), scenes with per-pixel frames
//! ([`scene`]), materials and their engine parameterisations ([`material`]), the runtime methods
//! that read our baked chain and DFG table as shaders do ([`methods`]: isotropic split-sum,
//! the LG18/HDRP, Filament and KHR bent normals, Cocco et al. 2024's major-axis sampling in
//! [`major_axis`], VNDF filtered importance sampling), the shipped methods and their GLSL/HLSL/WGSL
//! snippets ([`ship`] for anisotropic GGX, [`ship_as`] for Ashikhmin–Shirley) and the evaluator ([`eval`]) behind
//! `aniso-eval`. Conventions: docs/ANISOTROPY.md.

#![warn(missing_docs)]
#![allow(clippy::needless_range_loop)]

pub mod eval;
pub mod major_axis;
pub mod material;
pub mod methods;
pub mod scene;
pub mod ship;
pub mod ship_as;
pub mod truth;

use ibl_core::error::{Classify, ErrorClass};

/// Errors of the anisotropic evaluator.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// Bad input, unsupported input or I/O from the core library.
    #[error(transparent)]
    Core(#[from] ibl_core::Error),
}

impl Classify for Error {
    fn class(&self) -> ErrorClass {
        match self {
            Error::Core(e) => e.class(),
        }
    }
}

/// A result with the anisotropic [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;
