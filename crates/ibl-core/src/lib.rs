//! Core of the baking toolchain: the conventions of docs/CONVENTIONS.md implemented once.
//!
//! Images and cubemaps ([`image`], [`cube`]), the equirect mapping ([`equirect`]),
//! texel solid angles, low-discrepancy sequences ([`sampling`]), the real SH basis ([`sh`]),
//! the parallel texel traversal every bake shares ([`traverse`]) and file I/O with atomic
//! writes ([`io`]).

#![warn(missing_docs)]

pub mod approx;
pub mod area;
pub mod bordered;
pub mod cube;
pub mod envmap;
pub mod equirect;
pub mod error;
pub mod image;
pub mod io;
pub mod linalg;
pub mod orientation;
pub mod output;
pub mod ownership;
pub mod params;
pub mod progress;
pub mod sampling;
pub mod sh;
pub mod stream;
pub mod traverse;
pub mod walk;

pub use cube::{CubeMips, Cubemap, Face};
pub use error::{Error, Result};
pub use image::Image;

/// Version string baked into cache keys and file metadata.
pub const TOOL_VERSION: &str = env!("CARGO_PKG_VERSION");

/// Linear RGB radiance triple used by every environment bake.
pub type Rgb = [f32; 3];

/// Rec. 709 luminance of a linear RGB triple.
#[inline]
pub fn luminance(c: Rgb) -> f32 {
    0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2]
}
