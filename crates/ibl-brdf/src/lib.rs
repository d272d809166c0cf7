//! BRDF building blocks: microfacet distributions, Smith masking, Fresnel, and their
//! importance sampling, each as small pure functions named after the papers' notation.
//!
//! - [`ggx`]: GGX isotropic (free functions on cosines: `d_ggx`, `lambda`, `g1`, `g2`,
//!   `v_smith`, sampling triples) and anisotropic ([`ggx::Ggx`]), VNDF (Heitz 2018).
//! - [`beckmann`]: anisotropic normalised Beckmann of Kurt et al. (Kurt et al. 2010), VNDF.
//! - [`gtr`]: Generalized Trowbridge-Reitz with Dimov's Smith G1 (Atanasov et al. 2022 App. A).
//! - [`ashikhmin_shirley`]: the AS half-vector pdf and its sampling (Marcolongo 2020).
//! - [`transformed`]: linearly transformed microsurfaces of any of them (Atanasov et al. 2022 §4).
//! - [`microfacet::Microfacet`]: the trait they share; [`fresnel`]: Schlick.

#![warn(missing_docs)]

pub mod ashikhmin_shirley;
pub mod beckmann;
pub mod fresnel;
pub mod ggx;
pub mod gtr;
pub mod microfacet;
pub mod quadrature;
pub mod special;
pub mod transformed;
mod validation;

pub use ashikhmin_shirley::AshikhminShirley;
pub use beckmann::Beckmann;
pub use ggx::Ggx;
pub use gtr::Gtr;
pub use microfacet::{pdf_reflected, reflect, Microfacet};
pub use transformed::{TangentTransform, Transformed};
