//! GGX prefiltered specular mip chains (the radiance term of the split sum): level l of N holds
//! the environment convolved with K(l) ∝ D_GGX(n·h, α)·max(n·l, 0), h = normalize(n + l),
//! roughness r = l/(N−1), α = r², n = v = r (Karis 2013; Cocco et al. 2024 §3 eqs. 2–3).
//!
//! [`bake`] holds the `Params` and the pure `run`; [`tree`] the default method (the exact
//! kernel summed hierarchically over the source); [`samples`] and [`filter`] the filtered
//! importance sampling of Křivánek & Colbert 2008 / Lagarde & de Rousiers 2014 (per-level
//! sample tables and the per-texel loop, reading the source seamlessly and trilinearly through
//! `ibl_core::bordered`), kept as `--method fis`; [`kernel`] the exact kernel and the brute-force reference;
//! [`runtime`] the error an engine's lookup sees, and [`fit`] the levels fitted to that lookup;
//! [`custom`] our own lookup (`--target custom`) and its emitted shaders.

#![warn(missing_docs)]
// Index loops read closer to the papers' sums than iterator chains in the numeric kernels.
#![allow(clippy::needless_range_loop)]

pub mod bake;
mod bake_def;
pub mod custom;
pub mod error;
pub mod filter;
pub mod fit;
pub mod kernel;
pub mod runtime;
pub mod samples;
pub mod spatial;
pub mod stats;
pub mod tree;

pub use bake::{run, Method, Params, Quality};
pub use bake_def::{Prefilter, PREFILTER};
pub use error::Error;

/// What the unit tests of several modules share.
#[cfg(test)]
pub(crate) mod test_util {
    use ibl_core::CubeMips;

    /// Asserts that two chains have the same levels, faces and texel bits (a zip alone would
    /// pass chains of different lengths).
    pub(crate) fn assert_same_bits(a: &CubeMips, b: &CubeMips) {
        assert_eq!(a.levels.len(), b.levels.len(), "level count");
        for (l, (x, y)) in a.levels.iter().zip(&b.levels).enumerate() {
            for (f, (p, q)) in x.faces.iter().zip(&y.faces).enumerate() {
                assert_eq!(
                    p.data.len(),
                    q.data.len(),
                    "level {l} face {f}: texel count"
                );
                assert!(
                    p.data
                        .iter()
                        .zip(&q.data)
                        .all(|(u, v)| u.to_bits() == v.to_bits()),
                    "level {l} face {f}: texels differ"
                );
            }
        }
    }
}
