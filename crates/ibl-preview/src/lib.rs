//! Previews of what the bakes write: cubes laid out as horizontal crosses, HDR tone-mapped to
//! 8-bit sRGB, labels in a tiny embedded bitmap font, and the labelled contact sheet that
//! `make demo` writes.

#![warn(missing_docs)]

pub mod assets;
pub mod cross;
pub mod font;
pub mod sheet;
pub mod tonemap;
