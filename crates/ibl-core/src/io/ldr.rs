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
pub(crate) fn srgb_to_linear(c: f32) -> f32 {
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

/// Linear → sRGB-encoded value.
#[inline]
pub(crate) fn linear_to_srgb(c: f32) -> f32 {
    if c <= 0.0031308 {
        c * 12.92
    } else {
        1.055 * c.powf(1.0 / 2.4) - 0.055
    }
}

/// Walks a PNG's chunks: refuses a palette (PLTE chunk) that is not whole RGB triples, as
/// `png` 0.18.1 panics on one (image-rs/image-png#694; found by fuzzing,
/// `fuzz/regressions/png/`; `io::guard` would catch the panic, but not before its message
/// reached stderr), and a file that ends before its IEND chunk: the decoder returns the image
/// once the pixel data is complete, so a file cut after its last IDAT would pass as whole.
///
/// It also refuses, before anything is inflated, image data too short for the header's size:
/// deflate inflates at most 1032:1 (a 258-byte match per 2 bits, RFC 1951 §3.2.5; zlib's
/// `deflateBound` documents the same limit), so IDAT chunks holding fewer than 1/1032 of the
/// filtered rows the IHDR declares are a bomb or a truncated file. Returns the IHDR's width,
/// height and bytes per texel as decoded (palette expanded to RGB(A), at least 1 byte a
/// sample) for the memory budget.
fn check_png_structure(path: &Path, bytes: &[u8]) -> Result<Option<(u64, u64, u64)>> {
    if !bytes.starts_with(b"\x89PNG\r\n\x1a\n") {
        return Ok(None);
    }
    let mut at = 8usize;
    let mut ihdr: Option<(u64, u64, u64, u64)> = None; // width, height, bits a pixel, decoded bytes
    let mut idat = 0u64;
    while let Some(head) = bytes.get(at..at.saturating_add(8)) {
        let len = u32::from_be_bytes([head[0], head[1], head[2], head[3]]) as usize;
        if &head[4..8] == b"PLTE" && !len.is_multiple_of(3) {
            return Err(Error::invalid(
                path,
                format!("PNG palette of {len} bytes is not whole RGB entries"),
            ));
        }
        if &head[4..8] == b"IHDR" {
            if let Some(d) = bytes.get(at + 8..at + 8 + 13) {
                let be = |o: usize| u32::from_be_bytes([d[o], d[o + 1], d[o + 2], d[o + 3]]) as u64;
                let (depth, colour) = (d[8] as u64, d[9]);
                let samples = match colour {
                    0 => 1,
                    2 => 3,
                    3 => 1,
                    4 => 2,
                    _ => 4,
                };
                // Decoded: palette to RGBA8, everything else at max(depth, 8) bits.
                let decoded = if colour == 3 {
                    4
                } else {
                    samples * depth.max(8) / 8
                };
                ihdr = Some((be(0), be(4), samples * depth, decoded));
            }
        }
        if &head[4..8] == b"IDAT" {
            idat += len as u64;
        }
        let end = at.saturating_add(12).saturating_add(len);
        if end > bytes.len() {
            break;
        }
        if &head[4..8] == b"IEND" {
            let Some((w, h, bits, decoded)) = ihdr else {
                return Err(Error::invalid(path, "PNG without an IHDR chunk"));
            };
            let rows = h.saturating_mul(1 + w.saturating_mul(bits).div_ceil(8));
            if idat.saturating_mul(1032).saturating_add(1032) < rows {
                return Err(Error::invalid(
                    path,
                    format!(
                        "truncated PNG: {idat} bytes of image data cannot inflate to the {rows} bytes of a {w}x{h} image"
                    ),
                ));
            }
            return Ok(Some((w, h, decoded)));
        }
        at = end;
    }
    Err(Error::invalid(
        path,
        "truncated PNG: the file ends before its IEND chunk (an incomplete download or copy?)",
    ))
}

/// Finds where a JPEG's segments end, walking markers from SOI through every scan to EOI:
/// `None` when the data stops first. Entropy-coded data cannot contain a marker (0xFF is
/// stuffed as FF 00), so the walk needs no decoding; an EXIF thumbnail's own EOI lies inside
/// its APP1 segment and is skipped with it.
fn jpeg_end(bytes: &[u8]) -> Option<usize> {
    let mut at = 2usize; // after SOI
    loop {
        // Markers may be preceded by fill bytes 0xFF.
        while *bytes.get(at)? == 0xFF && *bytes.get(at + 1)? == 0xFF {
            at += 1;
        }
        if *bytes.get(at)? != 0xFF {
            return None;
        }
        let m = *bytes.get(at + 1)?;
        match m {
            0xD9 => return Some(at + 2),
            0x01 | 0xD0..=0xD7 => at += 2,
            _ => {
                let len = u16::from_be_bytes([*bytes.get(at + 2)?, *bytes.get(at + 3)?]) as usize;
                at = at + 2 + len;
                if m == 0xDA {
                    // Entropy-coded data up to the next marker that is not a stuffed 0xFF or
                    // a restart marker.
                    loop {
                        if *bytes.get(at)? == 0xFF {
                            let n = *bytes.get(at + 1)?;
                            if n != 0x00 && !(0xD0..=0xD7).contains(&n) {
                                break;
                            }
                            at += 2;
                        } else {
                            at += 1;
                        }
                    }
                }
            }
        }
    }
}

/// Decodes a JPEG in zune-jpeg's strict mode: the `image` crate runs it leniently, which
/// fills what a truncated or corrupt file lacks with grey and returns success. Returns
/// 8-bit grey or RGB samples and the channel count.
fn decode_jpeg(path: &Path, bytes: &[u8]) -> Result<(usize, usize, usize, Vec<u8>)> {
    use zune_core::colorspace::ColorSpace as Zcs;
    if jpeg_end(bytes).is_none() {
        return Err(Error::invalid(
            path,
            "truncated JPEG: the data ends before the end-of-image marker (an incomplete \
             download or copy?)",
        ));
    }
    let bad = |e: zune_jpeg::errors::DecodeErrors| {
        // zune-jpeg's I/O errors span two lines (found by the `budget` fuzz target): one here.
        let e = format!("{e:?}");
        let e = e.split_whitespace().collect::<Vec<_>>().join(" ");
        Error::invalid(path, format!("not a readable JPEG image: {e}"))
    };
    let options = zune_core::options::DecoderOptions::default()
        .set_strict_mode(true)
        .set_max_width(usize::MAX)
        .set_max_height(usize::MAX);
    let mut d = zune_jpeg::JpegDecoder::new_with_options(
        zune_core::bytestream::ZCursor::new(bytes),
        options,
    );
    d.decode_headers().map_err(bad)?;
    let (w, h) = d
        .dimensions()
        .ok_or_else(|| Error::invalid(path, "JPEG without dimensions"))?;
    Image::check_size(path, w as u64, h as u64)?;
    let grey = matches!(d.input_colorspace(), Some(Zcs::Luma | Zcs::LumaA));
    let (out, channels) = if grey { (Zcs::Luma, 1) } else { (Zcs::RGB, 3) };
    super::jpeg_scan::check(path, bytes)?;
    // The decoder's component planes and output (a few bytes a sample) and our f32 image.
    let _budget = super::budget::reserve(
        path,
        &format!("decoding a {w}x{h} JPEG image"),
        (w as u64 * h as u64 * channels as u64).saturating_mul(4 + 4),
    )?;
    d.set_options(options.jpeg_set_out_colorspace(out));
    let data = d.decode().map_err(bad)?;
    if data.len() != w * h * channels {
        return Err(Error::invalid(path, "JPEG decoded to the wrong size"));
    }
    Ok((w, h, channels, data))
}

pub fn decode(path: &Path, bytes: &[u8], color: ColorSpace) -> Result<Image> {
    if bytes.starts_with(&[0xFF, 0xD8]) {
        let (w, h, channels, data) = decode_jpeg(path, bytes)?;
        let data = data.into_iter().map(|v| v as f32 / 255.0).collect();
        return finish(Image::from_data(w, h, channels, data)?, color);
    }
    let png = check_png_structure(path, bytes)?;
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
    // The decoder's buffer, its 16-bit copy (up to 4 channels) and our f32 image.
    let decoded = png.map_or(8, |(_, _, d)| d);
    let _budget = super::budget::reserve(
        path,
        &format!("decoding a {w}x{h} image"),
        (w as u64 * h as u64).saturating_mul(decoded + 8 + 16),
    )?;
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
    finish(
        Image::from_data(w as usize, h as usize, channels, data)?,
        color,
    )
}

/// Decodes sRGB-encoded colour channels to linear (alpha stays as stored).
fn finish(mut img: Image, color: ColorSpace) -> Result<Image> {
    let channels = img.channels;
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

pub(crate) fn encode_png(path: &Path, img: &Image, opts: &WriteOptions) -> Result<Vec<u8>> {
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
