//! Our containers as read by independent readers: the `ktx2` crate (the KTX2 parser Bevy's
//! loader uses) parses every format with and without zstd, and its levels, inflated by the
//! reference zstd library, equal the uncompressed twin's.

use ibl_core::io::format::{Bc6hQuality, PixelFormat};
use ibl_core::io::{ktx2 as our_ktx2, texture};
use ibl_core::{CubeMips, Cubemap};

fn chain() -> CubeMips {
    let base = Cubemap::from_fn(16, |d| {
        [
            d.x.abs() * 3.0 + 0.05,
            d.y.max(0.0) * 900.0,
            0.2 + d.z * d.z,
        ]
    });
    CubeMips::build(base, 1)
}

fn expected_format(f: PixelFormat) -> ktx2::Format {
    match f {
        PixelFormat::Rgba32f => ktx2::Format::R32G32B32A32_SFLOAT,
        PixelFormat::Rgba16f => ktx2::Format::R16G16B16A16_SFLOAT,
        PixelFormat::Rgb9e5 => ktx2::Format::E5B9G9R9_UFLOAT_PACK32,
        PixelFormat::B10g11r11 => ktx2::Format::B10G11R11_UFLOAT_PACK32,
        PixelFormat::Bc6h => ktx2::Format::BC6H_UFLOAT_BLOCK,
    }
}

#[test]
fn the_ktx2_crate_parses_every_format_and_zstd_levels_inflate_to_the_plain_twin() {
    let mips = chain();
    for format in PixelFormat::ALL {
        let (payload, _) = texture::encode_chain(&mips, format, Bc6hQuality::Fast);
        let plain = our_ktx2::encode(&payload, None, &[]).unwrap();
        let packed = our_ktx2::encode(&payload, Some(19), &[]).unwrap();
        let a = ktx2::Reader::new(&plain[..]).expect("ktx2 crate reads ours");
        let z = ktx2::Reader::new(&packed[..]).expect("ktx2 crate reads our zstd file");
        for (r, scheme) in [
            (&a, None),
            (&z, Some(ktx2::SupercompressionScheme::Zstandard)),
        ] {
            let h = r.header();
            assert_eq!(h.format, Some(expected_format(format)), "{format:?}");
            assert_eq!((h.pixel_width, h.pixel_height, h.face_count), (16, 16, 6));
            assert_eq!(h.level_count as usize, mips.levels.len());
            assert_eq!(h.supercompression_scheme, scheme);
            assert_eq!(r.dfd_blocks().count(), 1);
        }
        for (l, (pl, zl)) in a.levels().zip(z.levels()).enumerate() {
            assert_eq!(pl.data, payload.levels[l].concat().as_slice());
            let inflated = zstd::bulk::decompress(zl.data, pl.data.len()).unwrap();
            assert_eq!(inflated, pl.data, "{format:?} level {l}");
            assert_eq!(zl.uncompressed_byte_length as usize, pl.data.len());
        }
    }
}
