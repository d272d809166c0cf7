//! The entry points of the image fuzz targets, shared word for word with the regression test
//! `crates/ibl-core/tests/fuzz_regressions.rs` (which includes this file by path), so a crash
//! kept in `fuzz/regressions/<target>/` is replayed through exactly what the fuzzer ran.
//!
//! Each entry decodes arbitrary bytes and must return (Ok or Err) without panicking; on Ok it
//! also checks the decoded value is self-consistent, since a decoder that "succeeds" with a
//! mis-sized buffer would only panic later, in a bake.

use ibl_core::image::Image;
use ibl_core::io::{decode_image, ktx2, ColorSpace};
use std::path::Path;

/// Names of the image targets, as in `fuzz/fuzz_targets/` and `fuzz/corpus/`.
pub const IMAGE_TARGETS: [&str; 4] = ["exr", "hdr", "png", "ktx2"];

fn check_image(img: &Image) {
    assert!(img.width > 0 && img.height > 0, "decoded an empty image");
    assert!((1..=4).contains(&img.channels), "{} channels", img.channels);
    assert_eq!(img.data.len(), img.width * img.height * img.channels);
}

/// `exr` target: OpenEXR through the extension dispatch.
pub fn exr(data: &[u8]) {
    if let Ok(img) = decode_image(Path::new("f.exr"), data, ColorSpace::Linear) {
        check_image(&img);
    }
}

/// `hdr` target: Radiance RGBE.
pub fn hdr(data: &[u8]) {
    if let Ok(img) = decode_image(Path::new("f.hdr"), data, ColorSpace::Linear) {
        check_image(&img);
        assert_eq!(img.channels, 3);
    }
}

/// `png` target: the 8/16-bit reader, as data (linear) and as colour (sRGB). It sniffs the
/// format from the bytes, so JPEG (and whatever else the `image` crate recognises) is reached
/// from here too.
pub fn png(data: &[u8]) {
    for color in [ColorSpace::Linear, ColorSpace::Srgb] {
        if let Ok(img) = decode_image(Path::new("f.png"), data, color) {
            check_image(&img);
            assert!(img
                .data
                .iter()
                .all(|v| v.is_finite() && (0.0..=1.0).contains(v)));
        }
    }
}

/// `ktx2` target: float cubemaps with their mip chain.
pub fn ktx2(data: &[u8]) {
    if let Ok(mips) = ktx2::decode_cube(Path::new("f.ktx2"), data) {
        assert!(!mips.levels.is_empty());
        for (l, cube) in mips.levels.iter().enumerate() {
            assert!(cube.size > 0, "level {l} is empty");
            for face in &cube.faces {
                assert_eq!(face.data.len(), cube.size * cube.size * 3, "level {l}");
            }
        }
    }
}

/// Runs the image target called `name` on `data`.
pub fn run_image_target(name: &str, data: &[u8]) {
    match name {
        "exr" => exr(data),
        "hdr" => hdr(data),
        "png" => png(data),
        "ktx2" => ktx2(data),
        other => panic!("unknown image fuzz target '{other}'"),
    }
}
