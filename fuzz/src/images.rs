//! The entry points of the image fuzz targets, shared word for word with the regression test
//! `crates/ibl-core/tests/fuzz_regressions.rs` (which includes this file by path), so a crash
//! kept in `fuzz/regressions/<target>/` is replayed through exactly what the fuzzer ran.
//!
//! Each entry decodes arbitrary bytes and must return (Ok or Err) without panicking; on Ok it
//! also checks the decoded value is self-consistent, since a decoder that "succeeds" with a
//! mis-sized buffer would only panic later, in a bake.

use ibl_core::image::Image;
use ibl_core::io::{container, decode_image, texture, ColorSpace};
use ibl_core::CubeMips;
use std::path::Path;

/// Names of the image targets, as in `fuzz/fuzz_targets/` and `fuzz/corpus/`. `zstd` is the
/// KTX2 reader again, seeded with zstd-supercompressed files so the fuzzer works on the
/// inflation path.
pub const IMAGE_TARGETS: [&str; 8] = ["exr", "hdr", "png", "jpeg", "ktx2", "zstd", "dds", "ktx1"];

/// The file name a target's inputs are read under (errors must name it).
pub fn target_path(name: &str) -> &'static Path {
    Path::new(match name {
        "exr" => "f.exr",
        "hdr" => "f.hdr",
        "png" => "f.png",
        "jpeg" => "f.jpg",
        "ktx2" | "zstd" => "f.ktx2",
        "dds" => "f.dds",
        "ktx1" => "f.ktx",
        other => panic!("unknown image fuzz target '{other}'"),
    })
}

/// Decodes `data` as target `name` reads it: a container (KTX2, DDS, KTX1) as a cube chain,
/// anything else as an image.
pub fn decode_target(name: &str, data: &[u8]) -> Result<(), ibl_core::Error> {
    let path = target_path(name);
    match name {
        "ktx2" | "zstd" | "dds" | "ktx1" => container_cube(path, data).map(|_| ()),
        _ => decode_image(path, data, ColorSpace::Linear).map(|_| ()),
    }
}

/// A container's texture decoded: a cube chain, or for a 2D texture its level 0 checked.
fn container_cube(path: &Path, data: &[u8]) -> Result<Option<CubeMips>, ibl_core::Error> {
    let Some(tex) = container::read(path, data)? else {
        return Err(ibl_core::Error::invalid(path, "not a container"));
    };
    if tex.payload.faces == 6 {
        return texture::decode_cube(path, &tex.payload).map(Some);
    }
    let p = &tex.payload;
    let img = texture::decode_image(&p.levels[0][0], p.format, p.width, p.height);
    check_image(&img);
    Ok(None)
}

fn check_image(img: &Image) {
    assert!(img.width > 0 && img.height > 0, "decoded an empty image");
    assert!(
        img.width as u64 * img.height as u64 <= ibl_core::image::MAX_TEXELS,
        "decoded past the size limit"
    );
    assert!((1..=4).contains(&img.channels), "{} channels", img.channels);
    assert_eq!(img.data.len(), img.width * img.height * img.channels);
}

/// The size the header declares (what the budget and the shape checks are computed from)
/// is the size decoded: a decoder that returns another size has read past or short of what
/// was checked.
fn check_declared(data: &[u8], img: &Image) {
    if let Some((w, h)) = ibl_core::io::declared_size(data) {
        assert_eq!(
            (w, h),
            (img.width as u64, img.height as u64),
            "the header declares another size than was decoded"
        );
    }
}

/// `exr` target: OpenEXR through the extension dispatch.
pub fn exr(data: &[u8]) {
    if let Ok(img) = decode_image(Path::new("f.exr"), data, ColorSpace::Linear) {
        check_image(&img);
        check_declared(data, &img);
    }
}

/// `jpeg` target: the strict JPEG reader with its scan walk (every block the frame header
/// declares must be in the entropy-coded data), seeded with libjpeg-turbo's files in every
/// mode it reads. A JPEG that decodes is as large as its header says.
pub fn jpeg(data: &[u8]) {
    for color in [ColorSpace::Linear, ColorSpace::Srgb] {
        if let Ok(img) = decode_image(Path::new("f.jpg"), data, color) {
            check_image(&img);
            check_declared(data, &img);
            assert!(matches!(img.channels, 1 | 3), "{} channels", img.channels);
        }
    }
}

/// `hdr` target: Radiance RGBE.
pub fn hdr(data: &[u8]) {
    if let Ok(img) = decode_image(Path::new("f.hdr"), data, ColorSpace::Linear) {
        check_image(&img);
        check_declared(data, &img);
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
            check_declared(data, &img);
            assert!(img
                .data
                .iter()
                .all(|v| v.is_finite() && (0.0..=1.0).contains(v)));
        }
    }
}

/// `ktx2`, `zstd`, `dds` and `ktx1` targets: cube maps with their mip chain, in every pixel
/// format the readers take.
pub fn container(name: &str, data: &[u8]) {
    if let Ok(Some(mips)) = container_cube(target_path(name), data) {
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
        "jpeg" => jpeg(data),
        "ktx2" | "zstd" | "dds" | "ktx1" => container(name, data),
        other => panic!("unknown image fuzz target '{other}'"),
    }
}
