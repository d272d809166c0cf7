//! Radiance RGBE (`.hdr`) reading, run-length encoded or flat, and writing.

use crate::error::{Error, Result};
use crate::image::Image;
use std::io::Cursor;
use std::path::Path;

pub fn decode(path: &Path, bytes: &[u8]) -> Result<Image> {
    let bad = |e: image::ImageError| {
        Error::invalid(path, format!("not a readable Radiance HDR file: {e}"))
    };
    let decoder = image::codecs::hdr::HdrDecoder::new(Cursor::new(bytes)).map_err(bad)?;
    let meta = decoder.metadata();
    Image::check_size(path, meta.width as u64, meta.height as u64)?;
    let (w, h) = (meta.width as usize, meta.height as usize);
    // Every scan line takes at least 4 bytes (one flat or run-length pixel, or the 4-byte
    // header of a run-length line): a header declaring more lines than the data can hold
    // is refused before the decoder allocates the whole image.
    let data = data_len(bytes);
    if data < 4 * h as u64 {
        return Err(Error::invalid(
            path,
            format!(
                "truncated Radiance HDR: {data} bytes of pixel data cannot hold the {h} scan lines of its {w}x{h} header"
            ),
        ));
    }
    // The decoder's RGB f32 buffer (which becomes the image without a copy).
    let _budget = super::budget::reserve(
        path,
        &format!("decoding a {w}x{h} Radiance HDR image"),
        (w as u64 * h as u64).saturating_mul(12),
    )?;
    let dynimg = image::DynamicImage::from_decoder(decoder).map_err(bad)?;
    let rgb = dynimg.into_rgb32f();
    Image::from_data(w, h, 3, rgb.into_raw())
}

/// Bytes after the header and its resolution line (the header ends with an empty line, the
/// resolution line follows).
fn data_len(bytes: &[u8]) -> u64 {
    let Some(blank) = bytes.windows(2).position(|w| w == b"\n\n") else {
        return 0;
    };
    let rest = &bytes[blank + 2..];
    rest.iter()
        .position(|&c| c == b'\n')
        .map_or(0, |eol| (rest.len() - eol - 1) as u64)
}

pub fn encode(path: &Path, img: &Image) -> Result<Vec<u8>> {
    let rgb = img.to_channels(3);
    let pixels: Vec<image::Rgb<f32>> = rgb
        .data
        .chunks_exact(3)
        .map(|c| image::Rgb([c[0].max(0.0), c[1].max(0.0), c[2].max(0.0)]))
        .collect();
    let mut out = Vec::new();
    image::codecs::hdr::HdrEncoder::new(&mut out)
        .encode(&pixels, img.width, img.height)
        .map_err(|e| Error::invalid(path, format!("HDR encoding failed: {e}")))?;
    Ok(out)
}
