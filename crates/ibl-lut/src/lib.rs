//! Lookup-table bakes, one module per table, each with its `Params` (CLI flags = RON keys)
//! and a pure `run` that returns encoded files:
//!
//! - [`dfg`]: the split-sum DFG table (GGX, height-correlated Smith; optional E_ss channel);
//! - [`fresnel_tail`]: the Fresnel-tail integral of Silvennoinen et al. 2025 eq. 15;
//! - [`as_size_bias`]: the Ashikhmin-Shirley size/bias table of Marcolongo 2020 §4.3.3;
//! - [`hv`]: the Ashikhmin-Shirley half-vector LUT of Marcolongo 2020 §4.3.2.
//!
//! [`reference`] holds the independent quadratures the tests and the benchmark compare with.

#![warn(missing_docs)]

pub mod as_size_bias;
mod bake_def;
pub mod dfg;
pub mod error;
pub mod fresnel_tail;
pub mod hv;
pub mod reference;
pub mod table;

pub use bake_def::{AsSizeBias, Dfg, FresnelTail, HvLut, AS_SIZE_BIAS, DFG, FRESNEL_TAIL, HV_LUT};
pub use error::{Error, Result};
pub use table::Baked;
