//! The CPU reference render of the scene "sphere-rows v1" (two rows of six spheres, metallic
//! and dielectric, roughness 0 … 1, orthographic, 768×256; [`scene`]): each pixel the split
//! sum an engine computes, w_r·Lexact(R, r) + w_e·E(n)/π, but with Lexact the exact
//! GGX-prefiltered radiance of the *source* at the pixel's reflection direction and the
//! sphere's continuous roughness, and E the exact irradiance ([`lighting`]); the weights are
//! the engine's own DFG term and diffuse modifiers, cited per engine ([`brdf`]).
//!
//! The difference between an engine's render and this one is what the bake (and the engine's
//! lookup of it) costs in that engine ([`compare`]). [`orientation`] holds the panorama with
//! coloured axis patches and the checker that names a flip or a turn; [`pfm`] the
//! interchange format.

#![warn(missing_docs)]

pub mod brdf;
pub mod compare;
pub mod lighting;
pub mod orientation;
pub mod pfm;
pub mod render;
pub mod scene;

pub use brdf::Engine;
pub use lighting::Lighting;
pub use render::{render, render_engines, render_lit, ChainLookup, Lit, ALL_SPHERES};

#[cfg(test)]
mod tests;
