//! Environment bakes that resample or project an environment: `equirect-to-cube` and
//! `irradiance`. Each module holds its `Params` and a pure `run`.

#![warn(missing_docs)]

mod bake_def;
pub mod equirect_to_cube;
pub mod irradiance;

pub use bake_def::{EquirectToCube, Irradiance, EQUIRECT_TO_CUBE, IRRADIANCE};
