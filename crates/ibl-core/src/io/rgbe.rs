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
    let dynimg = image::DynamicImage::from_decoder(decoder).map_err(bad)?;
    let rgb = dynimg.into_rgb32f();
    Image::from_data(w, h, 3, rgb.into_raw())
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
