//! 8/16-bit PNG and JPEG: sRGB or linear decoding, PNG encoding of data maps and of
//! tone-mapped previews of HDR images.

use super::{ColorSpace, WriteOptions};
use crate::error::{Error, Result};
use crate::image::Image;
use rayon::prelude::*;
use std::io::Cursor;
use std::path::Path;

/// sRGB transfer function, encoded value → linear.
#[inline]
pub fn srgb_to_linear(c: f32) -> f32 {
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

/// Linear → sRGB-encoded value.
#[inline]
pub fn linear_to_srgb(c: f32) -> f32 {
    if c <= 0.0031308 {
        c * 12.92
    } else {
        1.055 * c.powf(1.0 / 2.4) - 0.055
    }
}

/// Refuses a PNG palette (PLTE chunk) that is not whole RGB triples: `png` 0.18.1 panics on
/// one (image-rs/image-png#694; found by fuzzing, `fuzz/regressions/png/`). `io::guard` would
/// catch the panic, but not before the panic message reached stderr.
fn check_png_palette(path: &Path, bytes: &[u8]) -> Result<()> {
    if !bytes.starts_with(b"\x89PNG\r\n\x1a\n") {
        return Ok(());
    }
    let mut at = 8usize;
    while let Some(head) = bytes.get(at..at.saturating_add(8)) {
        let len = u32::from_be_bytes([head[0], head[1], head[2], head[3]]) as usize;
        if &head[4..8] == b"PLTE" && !len.is_multiple_of(3) {
            return Err(Error::invalid(
                path,
                format!("PNG palette of {len} bytes is not whole RGB entries"),
            ));
        }
        at = at.saturating_add(12).saturating_add(len);
    }
    Ok(())
}

pub fn decode(path: &Path, bytes: &[u8], color: ColorSpace) -> Result<Image> {
    check_png_palette(path, bytes)?;
    let bad = |e: image::ImageError| Error::invalid(path, format!("not a readable image: {e}"));
    let reader = image::ImageReader::new(Cursor::new(bytes))
        .with_guessed_format()
        .map_err(|e| Error::io(path, e))?;
    // Only PNG and JPEG: the sniffing would also hand EXR or HDR bytes to the `image` crate's
    // decoders, which clamp to [0, 1] here and decode EXR on worker threads (where a panic
    // aborts the process instead of reaching `io::guard`).
    match reader.format() {
        Some(image::ImageFormat::Png | image::ImageFormat::Jpeg) => {}
        other => {
            let what = other.map_or("unknown data".to_string(), |f| format!("{f:?} data"));
            return Err(Error::unsupported(
                path,
                format!("{what}: not a PNG or JPEG image"),
            ));
        }
    }
    let (w, h) = reader.into_dimensions().map_err(bad)?;
    Image::check_size(path, w as u64, h as u64)?;
    let mut reader = image::ImageReader::new(Cursor::new(bytes))
        .with_guessed_format()
        .map_err(|e| Error::io(path, e))?;
    reader.no_limits();
    let dynimg = reader.decode().map_err(bad)?;
    let channels = match dynimg.color().channel_count() {
        1 => 1,
        2 => 4, // grey + alpha: expand to RGBA
        3 => 3,
        _ => 4,
    };
    let data: Vec<f32> = match channels {
        1 => dynimg
            .into_luma16()
            .into_raw()
            .into_iter()
            .map(|v| v as f32 / 65535.0)
            .collect(),
        3 => dynimg
            .into_rgb16()
            .into_raw()
            .into_iter()
            .map(|v| v as f32 / 65535.0)
            .collect(),
        _ => dynimg
            .into_rgba16()
            .into_raw()
            .into_iter()
            .map(|v| v as f32 / 65535.0)
            .collect(),
    };
    let mut img = Image::from_data(w as usize, h as usize, channels, data)?;
    if color == ColorSpace::Srgb {
        for px in img.data.chunks_exact_mut(channels) {
            let colour = if channels == 4 { 3 } else { channels };
            for v in &mut px[..colour] {
                *v = srgb_to_linear(*v);
            }
        }
    }
    Ok(img)
}

/// Reinhard tone map for previews: c / (1 + luminance).
fn tonemap(rgb: [f32; 3]) -> [f32; 3] {
    let l = crate::luminance(rgb).max(0.0);
    rgb.map(|c| (c / (1.0 + l)).clamp(0.0, 1.0))
}

pub fn encode_png(path: &Path, img: &Image, opts: &WriteOptions) -> Result<Vec<u8>> {
    let ch = img.channels;
    // Data maps are quantised as they are; colour goes through tone mapping and/or sRGB.
    let transform = opts.png_tonemap || opts.png_srgb;
    let colour = if ch == 4 || ch == 2 { ch - 1 } else { ch };
    let mut values: Vec<f32>;
    let values: &[f32] = if !transform {
        &img.data
    } else {
        values = img.data.clone();
        values
            .par_chunks_mut(ch * img.width.max(1))
            .for_each(|row| {
                for px in row.chunks_exact_mut(ch) {
                    if opts.png_tonemap && ch >= 3 {
                        let t = tonemap([px[0], px[1], px[2]]);
                        px[..3].copy_from_slice(&t);
                    }
                    for v in &mut px[..colour] {
                        *v = linear_to_srgb(v.clamp(0.0, 1.0));
                    }
                }
            });
        &values
    };
    let (w, h) = (img.width as u32, img.height as u32);
    let color = match (ch, opts.png_bits) {
        (1, 8) => image::ExtendedColorType::L8,
        (2, 8) => image::ExtendedColorType::La8,
        (3, 8) => image::ExtendedColorType::Rgb8,
        (4, 8) => image::ExtendedColorType::Rgba8,
        (1, 16) => image::ExtendedColorType::L16,
        (2, 16) => image::ExtendedColorType::La16,
        (3, 16) => image::ExtendedColorType::Rgb16,
        (4, 16) => image::ExtendedColorType::Rgba16,
        (_, b) => {
            return Err(Error::unsupported(
                path,
                format!("PNG bit depth {b} (use 8 or 16)"),
            ))
        }
    };
    let raw: Vec<u8> = if opts.png_bits == 8 {
        values
            .par_iter()
            .map(|v| (v.clamp(0.0, 1.0) * 255.0).round() as u8)
            .collect()
    } else {
        // PNG stores 16-bit samples big-endian; the encoder takes native-endian bytes.
        let mut raw = vec![0u8; values.len() * 2];
        raw.par_chunks_mut(2)
            .zip(values.par_iter())
            .for_each(|(b, v)| {
                b.copy_from_slice(&((v.clamp(0.0, 1.0) * 65535.0).round() as u16).to_ne_bytes())
            });
        raw
    };
    let mut out = Vec::new();
    use image::ImageEncoder;
    // Fast deflate: maps are re-encoded on every bake, and the default level costs 2-3x the
    // time for files a few percent smaller.
    image::codecs::png::PngEncoder::new_with_quality(
        &mut out,
        image::codecs::png::CompressionType::Fast,
        image::codecs::png::FilterType::Adaptive,
    )
    .write_image(&raw, w, h, color)
    .map_err(|e| Error::invalid(path, format!("PNG encoding failed: {e}")))?;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn srgb_transfer_round_trips() {
        for k in 0..=255 {
            let c = k as f32 / 255.0;
            assert!((linear_to_srgb(srgb_to_linear(c)) - c).abs() < 1e-5);
        }
    }
}
