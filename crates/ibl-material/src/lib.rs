//! Material maps (Marcolongo 2020, Marcolongo 2020, §3.2–3.5 and §5.2): the quaternion map that
//! carries a normal map's perturbation of the whole tangent frame ([`quat_map`], math in
//! [`quaternion`]), the tangent-plane rotation map of anisotropy directions and directional
//! roughnesses ([`tpr_map`], fields in [`direction`], user formulas in [`expr`]), and batch
//! conversion of material folders ([`batch`]).
//!
//! Conventions shared by every map here: tangent space is (t, b, n) = (+x, +y, +z), a map
//! texel stores a vector v as v·0.5 + 0.5, texture coordinates are texel centres
//! u = (i + 0.5)/W, v = (j + 0.5)/H with row j = 0 stored first.

#![warn(missing_docs)]

mod bake_def;
pub mod batch;
pub mod direction;
pub mod error;
pub mod expr;
pub mod map;
pub mod normal;
pub mod output;
pub mod quat_map;
pub mod quaternion;
pub mod tpr_map;

pub use bake_def::{QuatMap, TprMap, QUAT_MAP, TPR_MAP};
pub use error::{Error, Result};
