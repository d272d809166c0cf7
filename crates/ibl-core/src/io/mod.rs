//! File I/O: image readers and writers chosen by extension, KTX2 cubemaps, JSON/RON data,
//! and the atomic write every output goes through.

pub mod atomic;
mod bc6h;
mod bc6h_search;
pub mod budget;
pub mod container;
pub mod data;
pub mod dds;
mod exr_io;
pub mod format;
mod jpeg_scan;
pub mod ktx1;
pub mod ktx2;
pub mod layout;
mod ldr;
pub mod packed;
mod rgbe;
pub mod rows;
pub mod texture;

pub use atomic::{check_output, write_atomic, write_many_atomic, OutputKind};

use crate::error::{Error, Result};
use crate::image::Image;
use std::path::Path;

/// How 8/16-bit images are decoded: colour textures are sRGB-encoded, data maps (normals,
/// angle maps) are stored linearly.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ColorSpace {
    /// sRGB transfer function (colour images).
    Srgb,
    /// Stored as is (data: normals, angles, tables).
    Linear,
}

/// Sample type of a float output.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum FloatDepth {
    /// 32-bit floats.
    #[default]
    F32,
    /// Half floats, saturating at ±65504 (see [`f16_saturating`]).
    F16,
}

/// f32 → half that saturates at ±65504, the largest finite half, instead of rounding to ±Inf:
/// a sun of 10⁵ in a `--half` output stays finite (as GPU RGBA16F render targets clamp), so the
/// file is still readable by every tool here, which refuse Inf. Energy above 65504 is lost:
/// use float32 outputs for such environments.
#[inline]
pub(crate) fn f16_saturating(v: f32) -> half::f16 {
    half::f16::from_f32(v.clamp(-65504.0, 65504.0))
}

/// `v` as an RGBA16F texel stores it: rounded to the nearest half, saturating at ±65504
/// ([`f16_saturating`]). What a bake must emulate when it reads back what it will write.
#[inline]
pub fn f16_round(v: f32) -> f32 {
    f16_saturating(v).to_f32()
}

/// Encoding choices for [`encode_image`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct WriteOptions {
    /// EXR sample type (KTX2 too).
    pub float: FloatDepth,
    /// PNG bit depth: 8 or 16.
    pub png_bits: u8,
    /// PNG holds HDR data: tone-map (Reinhard) and sRGB-encode it for preview.
    pub png_tonemap: bool,
    /// PNG holds colour (sRGB-encode) rather than data (store linearly).
    pub png_srgb: bool,
}

impl Default for WriteOptions {
    fn default() -> Self {
        WriteOptions {
            float: FloatDepth::F32,
            png_bits: 16,
            png_tonemap: false,
            png_srgb: false,
        }
    }
}

/// Lower-case extension of a path, or "".
pub fn extension(path: &Path) -> String {
    path.extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase()
}

/// Reads `.exr`, `.hdr`, `.png`, `.jpg`/`.jpeg` into a linear float image.
/// Checks sizes before allocating; never panics on malformed bytes.
pub fn read_image(path: &Path, color: ColorSpace) -> Result<Image> {
    let bytes = budget::read_file(path)?;
    decode_image(path, &bytes, color)
}

/// Decodes image bytes; the format is the one the bytes' signature (magic number) names,
/// the extension only when the signature is unknown; `path` names the file in errors.
pub fn decode_image(path: &Path, bytes: &[u8], color: ColorSpace) -> Result<Image> {
    if bytes.is_empty() {
        return Err(Error::invalid(path, "empty file"));
    }
    let ext = extension(path);
    let by_magic = image_signature(bytes).unwrap_or("");
    // The content decides, whatever the name says: EXR data named `.png` reads as it does
    // named `.txt`. The extension only names a format whose signature is unknown.
    let kind = match (by_magic, ext.as_str()) {
        ("", "exr" | "hdr" | "png" | "jpg" | "jpeg" | "pic") => ext.as_str(),
        (magic, _) => magic,
    };
    match kind {
        "exr" => guard(path, "EXR", || exr_io::decode(path, bytes)),
        "hdr" | "pic" => guard(path, "Radiance HDR", || rgbe::decode(path, bytes)),
        "png" | "jpg" | "jpeg" => guard(path, "PNG or JPEG", || ldr::decode(path, bytes, color)),
        _ => Err(Error::unsupported(
            path,
            "not an EXR, HDR, PNG or JPEG image",
        )),
    }
}

/// The width and height an image file's header declares, read without decoding anything (so
/// a caller can refuse a shape it cannot use before the decode allocates); `None` when the
/// format is not one [`decode_image`] reads or the header is unreadable (the decode then
/// reports why).
pub fn declared_size(bytes: &[u8]) -> Option<(u64, u64)> {
    match image_signature(bytes)? {
        "exr" => {
            let meta =
                exr::meta::MetaData::read_from_buffered(std::io::Cursor::new(bytes), false).ok()?;
            let s = meta.headers.first()?.layer_size;
            Some((s.0 as u64, s.1 as u64))
        }
        "hdr" => {
            let d = image::codecs::hdr::HdrDecoder::new(std::io::Cursor::new(bytes)).ok()?;
            let m = d.metadata();
            Some((m.width as u64, m.height as u64))
        }
        "png" => {
            let be = |o: usize| -> Option<u64> {
                Some(u32::from_be_bytes(bytes.get(o..o + 4)?.try_into().ok()?) as u64)
            };
            (bytes.get(12..16)? == b"IHDR").then_some(())?;
            Some((be(16)?, be(20)?))
        }
        _ => {
            // JPEG: the first SOFn segment (T.81 B.2.2: P, Y, X).
            let mut at = 2usize;
            loop {
                while bytes.get(at) == Some(&0xFF) && bytes.get(at + 1) == Some(&0xFF) {
                    at += 1;
                }
                let (0xFF, m) = (*bytes.get(at)?, *bytes.get(at + 1)?) else {
                    return None;
                };
                let len = u16::from_be_bytes([*bytes.get(at + 2)?, *bytes.get(at + 3)?]) as usize;
                if matches!(m, 0xC0..=0xCF) && !matches!(m, 0xC4 | 0xC8 | 0xCC) {
                    let h = u16::from_be_bytes([*bytes.get(at + 5)?, *bytes.get(at + 6)?]);
                    let w = u16::from_be_bytes([*bytes.get(at + 7)?, *bytes.get(at + 8)?]);
                    return Some((w as u64, h as u64));
                }
                if m == 0xDA || m == 0xD9 {
                    return None;
                }
                at += 2 + len;
            }
        }
    }
}

/// The image format `bytes` start like ("exr", "hdr", "png" or "jpg"), if any.
fn image_signature(bytes: &[u8]) -> Option<&'static str> {
    if bytes.starts_with(&[0x76, 0x2f, 0x31, 0x01]) {
        Some("exr")
    } else if bytes.starts_with(b"#?") {
        Some("hdr")
    } else if bytes.starts_with(&[0x89, b'P', b'N', b'G']) {
        Some("png")
    } else if bytes.starts_with(&[0xff, 0xd8]) {
        Some("jpg")
    } else {
        None
    }
}

/// Decodes the image file at `path` (`file_len` bytes, whose first bytes are `head`) from a
/// stream, without holding its bytes, when its format allows (Radiance HDR, header in
/// `head`); `None` for the others (read them whole and [`decode_image`]).
pub(crate) fn decode_file_streamed(
    path: &Path,
    head: &[u8],
    file_len: u64,
) -> Option<Result<Image>> {
    if image_signature(head) != Some("hdr") {
        return None;
    }
    let header = rgbe::header_len(head)?;
    Some(guard(path, "Radiance HDR", || {
        rgbe::decode_file(path, header, file_len)
    }))
}

/// The rows of the image file at `path` (`file_len` bytes, whose first bytes are `head`) as a
/// stream, when its format allows a row-by-row read (Radiance HDR; OpenEXR scan lines whose
/// blocks follow one another in increasing line order); `None` for the others. The header's
/// checks are done here, before any row is read.
pub(crate) fn open_rows_streamed(
    path: &Path,
    head: &[u8],
    file_len: u64,
) -> Option<Result<Box<dyn rows::RowSource>>> {
    if image_signature(head) == Some("exr") {
        let rows = guard(path, "OpenEXR", || exr_io::ExrRows::open(path, file_len));
        return match rows {
            Ok(Some(r)) => Some(Ok(Box::new(r))),
            Ok(None) => None,
            Err(e) => Some(Err(e)),
        };
    }
    if image_signature(head) != Some("hdr") {
        return None;
    }
    let header = rgbe::header_len(head)?;
    Some(guard(path, "Radiance HDR", || {
        rgbe::HdrRows::open(path, header, file_len).map(|r| Box::new(r) as Box<dyn rows::RowSource>)
    }))
}

/// The format an extension names, in the terms of [`image_signature`] and
/// [`container::Container`].
fn format_of_extension(ext: &str) -> Option<&'static str> {
    Some(match ext {
        "exr" => "exr",
        "hdr" | "pic" => "hdr",
        "png" => "png",
        "jpg" | "jpeg" => "jpg",
        "ktx2" => "ktx2",
        "ktx" => "ktx",
        "dds" => "dds",
        _ => return None,
    })
}

/// What a format is called in messages.
fn format_name(kind: &str) -> &'static str {
    match kind {
        "exr" => "OpenEXR",
        "hdr" => "Radiance HDR",
        "png" => "PNG",
        "jpg" => "JPEG",
        "ktx2" => "KTX2",
        "ktx" => "KTX",
        _ => "DDS",
    }
}

/// The one-line warning for a file whose content and name disagree (EXR data named `.png`, a
/// PNG named `.exr`, Radiance HDR named `.txt`, a KTX2 cube named `.exr`): the readers go by
/// the content's signature, and the user learns how the file was read. `None` when the name
/// agrees or the content has no signature we know (the extension decides then).
pub fn content_mismatch(path: &Path, bytes: &[u8]) -> Option<String> {
    let kind = image_signature(bytes).or_else(|| {
        container::Container::sniff(bytes)
            .and_then(|c| c.codec())
            .map(|c| c.extension())
    })?;
    let ext = extension(path);
    if format_of_extension(&ext) == Some(kind) {
        return None;
    }
    let named = if ext.is_empty() {
        "has no extension".to_string()
    } else {
        format!("is named .{ext}")
    };
    let name = format_name(kind);
    Some(format!(
        "{}: holds {name} data but {named}; read as {name} (by its content)",
        path.display()
    ))
}

/// Runs a third-party decoder, turning a panic inside it into an invalid-input error: fuzzing
/// found malformed files that make the decoders we depend on panic (an overflow in the `exr`
/// crate's B44 unpacking, see `fuzz/README.md`), and a bad file must give an error, never a
/// crash. The decoders run on the calling thread for this (a panic in a worker thread of a
/// parallel decoder aborts the process instead of unwinding).
fn guard<T>(path: &Path, what: &str, decode: impl FnOnce() -> Result<T>) -> Result<T> {
    std::panic::catch_unwind(std::panic::AssertUnwindSafe(decode)).unwrap_or_else(|panic| {
        let why = panic
            .downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| panic.downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "unknown cause".into());
        Err(Error::invalid(
            path,
            format!("not a readable {what} file: the decoder failed ({why})"),
        ))
    })
}

/// Encodes an image for `path`'s extension (`.exr`, `.hdr`, `.png`).
pub fn encode_image(path: &Path, img: &Image, opts: &WriteOptions) -> Result<Vec<u8>> {
    match extension(path).as_str() {
        "exr" => exr_io::encode(path, img, opts.float),
        "hdr" => rgbe::encode(path, img),
        "png" => ldr::encode_png(path, img, opts),
        other => Err(Error::unsupported(
            path,
            format!("cannot write '.{other}' images (use .exr, .hdr or .png)"),
        )),
    }
}

/// Encodes and atomically writes an image.
pub fn write_image(path: &Path, img: &Image, opts: &WriteOptions) -> Result<()> {
    let bytes = encode_image(path, img, opts)?;
    write_atomic(path, &bytes)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn test_image(channels: usize) -> Image {
        let mut img = Image::new(13, 7, channels);
        for (k, v) in img.data.iter_mut().enumerate() {
            *v = (k as f32 * 0.37).sin().abs() * 10.0 + 0.001 * k as f32;
        }
        img
    }

    #[test]
    fn exr_float_round_trip_is_exact() {
        let dir = tempfile::tempdir().unwrap();
        for ch in [1, 2, 3, 4] {
            let p = dir.path().join(format!("a{ch}.exr"));
            let img = test_image(ch);
            write_image(&p, &img, &WriteOptions::default()).unwrap();
            let back = read_image(&p, ColorSpace::Linear).unwrap();
            assert_eq!(back, img, "channels {ch}");
        }
    }

    #[test]
    fn half_outputs_saturate_instead_of_writing_inf() {
        assert_eq!(f16_saturating(1e5).to_f32(), 65504.0);
        assert_eq!(f16_saturating(-1e30).to_f32(), -65504.0);
        assert_eq!(f16_saturating(f32::INFINITY).to_f32(), 65504.0);
        assert_eq!(f16_saturating(1.5).to_f32(), 1.5);
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("sun.exr");
        let mut img = test_image(3);
        img.data[0] = 1e5;
        let opts = WriteOptions {
            float: FloatDepth::F16,
            ..Default::default()
        };
        write_image(&p, &img, &opts).unwrap();
        let back = read_image(&p, ColorSpace::Linear).unwrap();
        assert_eq!(back.data[0], 65504.0);
        assert!(back.data.iter().all(|v| v.is_finite()));
        let mut cube = crate::Cubemap::constant(2, [1.0; 3]);
        cube.faces[0].data[0] = 1e5;
        let k = ktx2::encode_cube(&crate::CubeMips { levels: vec![cube] }, FloatDepth::F16);
        let back = ktx2::decode_cube(Path::new("sun.ktx2"), &k).unwrap();
        assert_eq!(back.levels[0].faces[0].data[0], 65504.0);
    }

    #[test]
    fn exr_half_round_trip_is_exact_on_half_values() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("h.exr");
        let mut img = test_image(3);
        img.data
            .iter_mut()
            .for_each(|v| *v = half::f16::from_f32(*v).to_f32());
        write_image(
            &p,
            &img,
            &WriteOptions {
                float: FloatDepth::F16,
                ..Default::default()
            },
        )
        .unwrap();
        assert_eq!(read_image(&p, ColorSpace::Linear).unwrap(), img);
    }

    #[test]
    fn png16_data_round_trip_is_exact_on_16_bit_values() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("d.png");
        let mut img = test_image(4);
        img.data
            .iter_mut()
            .for_each(|v| *v = ((*v / 11.0).clamp(0.0, 1.0) * 65535.0).round() / 65535.0);
        write_image(&p, &img, &WriteOptions::default()).unwrap();
        assert_eq!(read_image(&p, ColorSpace::Linear).unwrap(), img);
    }

    #[test]
    fn hdr_round_trip_within_rgbe_precision() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("e.hdr");
        let img = test_image(3);
        write_image(&p, &img, &WriteOptions::default()).unwrap();
        let back = read_image(&p, ColorSpace::Linear).unwrap();
        // RGBE keeps 8 mantissa bits relative to the largest channel.
        for (a, b) in img.data.chunks(3).zip(back.data.chunks(3)) {
            let m = a.iter().cloned().fold(0.0f32, f32::max);
            for k in 0..3 {
                assert!((a[k] - b[k]).abs() <= m / 128.0, "{a:?} {b:?}");
            }
        }
        // And what RGBE returns survives a second round trip exactly.
        write_image(&p, &back, &WriteOptions::default()).unwrap();
        assert_eq!(read_image(&p, ColorSpace::Linear).unwrap(), back);
    }

    fn find(hay: &[u8], needle: &[u8]) -> usize {
        hay.windows(needle.len())
            .position(|w| w == needle)
            .expect("present")
    }

    #[test]
    fn huge_declared_sizes_are_refused_before_allocating() {
        let dir = tempfile::tempdir().unwrap();
        // EXR: the header's dataWindow box2i (xmin, ymin, xmax, ymax) patched to 200000².
        let p = dir.path().join("big.exr");
        write_image(&p, &test_image(3), &WriteOptions::default()).unwrap();
        let mut b = std::fs::read(&p).unwrap();
        let at = find(&b, b"dataWindow\0box2i\0") + "dataWindow\0box2i\0".len() + 4;
        b[at + 8..at + 12].copy_from_slice(&199_999i32.to_le_bytes());
        b[at + 12..at + 16].copy_from_slice(&199_999i32.to_le_bytes());
        let err = decode_image(&p, &b, ColorSpace::Linear)
            .unwrap_err()
            .to_string();
        assert!(err.contains("larger than the limit"), "{err}");
        // Radiance HDR: a header declaring 100000 × 100000 with no pixel data.
        let hdr = b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 100000 +X 100000\n";
        let err = decode_image(Path::new("big.hdr"), hdr, ColorSpace::Linear)
            .unwrap_err()
            .to_string();
        assert!(err.contains("limit"), "{err}");
    }

    /// One small image in every format the readers take, JPEG in grey and colour, baseline
    /// and progressive-free (the `image` encoder writes baseline).
    fn every_format() -> Vec<(&'static str, Vec<u8>)> {
        let mut img = Image::new(64, 48, 3);
        for (k, v) in img.data.iter_mut().enumerate() {
            *v = ((k * 7919) % 1000) as f32 / 1000.0;
        }
        let p8 = WriteOptions {
            png_bits: 8,
            ..Default::default()
        };
        let enc = |n: &str, o: &WriteOptions| encode_image(Path::new(n), &img, o).unwrap();
        let jpeg = |grey: bool| {
            let mut out = Vec::new();
            let (data, color): (Vec<u8>, _) = if grey {
                let g = img.data.iter().step_by(3).map(|v| (v * 255.0) as u8);
                (g.collect(), image::ExtendedColorType::L8)
            } else {
                let c = img.data.iter().map(|v| (v * 255.0) as u8);
                (c.collect(), image::ExtendedColorType::Rgb8)
            };
            image::codecs::jpeg::JpegEncoder::new_with_quality(&mut out, 90)
                .encode(&data, 64, 48, color)
                .unwrap();
            out
        };
        let half = WriteOptions {
            float: FloatDepth::F16,
            ..Default::default()
        };
        vec![
            ("a.exr", enc("a.exr", &WriteOptions::default())),
            ("h.exr", enc("h.exr", &half)),
            ("a.hdr", enc("a.hdr", &WriteOptions::default())),
            ("a.png", enc("a.png", &p8)),
            ("b.png", enc("b.png", &WriteOptions::default())),
            ("a.jpg", jpeg(false)),
            ("g.jpg", jpeg(true)),
        ]
    }

    #[test]
    fn truncated_files_are_refused_in_every_format() {
        for (name, bytes) in every_format() {
            let path = Path::new(name);
            let whole = decode_image(path, &bytes, ColorSpace::Linear).unwrap();
            assert_eq!((whole.width, whole.height), (64, 48), "{name}");
            let n = bytes.len();
            let mut cuts: Vec<usize> = [0.05, 0.3, 0.5, 0.7, 0.9, 0.99]
                .iter()
                .map(|f| (n as f64 * f) as usize)
                .collect();
            cuts.extend([n - 1, n - 2, n - 3, n - 12]);
            for cut in cuts {
                let err = decode_image(path, &bytes[..cut], ColorSpace::Linear)
                    .map(|_| ())
                    .expect_err(&format!("{name} cut at {cut} of {n} was accepted"));
                assert!(err.to_string().starts_with(name), "{err}");
            }
        }
    }

    #[test]
    fn the_content_decides_the_format_not_the_name() {
        for (name, bytes) in every_format() {
            let whole = decode_image(Path::new(name), &bytes, ColorSpace::Linear).unwrap();
            for other in ["x.png", "x.exr", "x.txt", "x.jpg", "x.hdr", "x"] {
                let back = decode_image(Path::new(other), &bytes, ColorSpace::Linear)
                    .unwrap_or_else(|e| panic!("{name} named {other}: {e}"));
                assert_eq!(back, whole, "{name} named {other}");
            }
        }
    }

    #[test]
    fn jpeg_corrupt_scan_data_is_refused() {
        let (_, bytes) = every_format().remove(5);
        let jpeg = |b: &[u8]| decode_image(Path::new("c.jpg"), b, ColorSpace::Linear);
        // A reserved marker in the middle of the scan, the file still ending in EOI: the
        // lenient decoder skips it and fills the rest.
        let mut b = bytes.clone();
        let at = b.len() / 2;
        b[at] = 0xFF;
        b[at + 1] = 0x05;
        assert!(jpeg(&b).is_err());
        // Trailing bytes after EOI are common (camera padding) and harmless.
        let mut b = bytes.clone();
        b.extend_from_slice(&[0u8; 16]);
        assert!(jpeg(&b).is_ok());
    }

    #[test]
    fn malformed_bytes_are_errors_not_panics() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("t.exr");
        write_image(&p, &test_image(3), &WriteOptions::default()).unwrap();
        let bytes = std::fs::read(&p).unwrap();
        for cut in [0, 4, 20, bytes.len() / 2, bytes.len() - 1] {
            assert!(
                decode_image(&p, &bytes[..cut], ColorSpace::Linear).is_err(),
                "cut {cut}"
            );
        }
        for name in ["x.hdr", "x.png", "x.jpg", "x.exr", "x.bin"] {
            assert!(decode_image(
                Path::new(name),
                b"garbage bytes that are no image",
                ColorSpace::Linear
            )
            .is_err());
        }
    }
}
