//! Radiance RGBE (`.hdr`) reading, run-length encoded or flat, and writing.

use crate::error::{Error, Result};
use crate::image::Image;
use std::io::Cursor;
use std::path::Path;

pub fn decode(path: &Path, bytes: &[u8]) -> Result<Image> {
    decode_from(path, Cursor::new(bytes), data_len(bytes))
}

/// Decodes the file at `path` (`file_len` bytes, the first `header` of them the header and
/// resolution line, see [`header_len`]) from a buffered reader, scan line by scan line into
/// the image, without holding the file's bytes: at 8k that is the file's 134 MB less at the
/// peak.
pub fn decode_file(path: &Path, header: usize, file_len: u64) -> Result<Image> {
    let file = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
    let reader = std::io::BufReader::with_capacity(1 << 20, file);
    decode_from(path, reader, file_len.saturating_sub(header as u64))
}

/// The decoder over `reader`, whose pixel data (after the header) is `data` bytes long.
fn decode_from<R: std::io::BufRead>(path: &Path, reader: R, data: u64) -> Result<Image> {
    let bad = |e: image::ImageError| {
        Error::invalid(path, format!("not a readable Radiance HDR file: {e}"))
    };
    let decoder = image::codecs::hdr::HdrDecoder::new(reader).map_err(bad)?;
    let meta = decoder.metadata();
    Image::check_size(path, meta.width as u64, meta.height as u64)?;
    let (w, h) = (meta.width as usize, meta.height as usize);
    // Every scan line takes at least 4 bytes (one flat or run-length pixel, or the 4-byte
    // header of a run-length line): a header declaring more lines than the data can hold
    // is refused before the decoder allocates the whole image.
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

/// Length of the header and its resolution line (the header ends with an empty line, the
/// resolution line follows), if `bytes` holds them.
pub fn header_len(bytes: &[u8]) -> Option<usize> {
    let blank = bytes.windows(2).position(|w| w == b"\n\n")?;
    let rest = &bytes[blank + 2..];
    let eol = rest.iter().position(|&c| c == b'\n')?;
    Some(blank + 2 + eol + 1)
}

/// Bytes after the header and its resolution line (0 when there is no complete header).
fn data_len(bytes: &[u8]) -> u64 {
    header_len(bytes).map_or(0, |n| (bytes.len() - n) as u64)
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
