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

/// A Radiance file's scan lines as rows of RGB f32, one at a time from a buffered reader
/// (neither the file's bytes nor its image held): the rows of a streamed resample.
pub(crate) struct HdrRows {
    path: std::path::PathBuf,
    reader: std::io::BufReader<std::fs::File>,
    width: usize,
    height: usize,
    next: usize,
    line: Vec<[u8; 4]>,
}

impl HdrRows {
    /// Opens `path` (`file_len` bytes, the first `header` of them the header and resolution
    /// line, see [`header_len`]) with the checks of [`decode_file`] (a readable header, a
    /// size [`Image::check_size`] takes, enough bytes for every scan line) done first.
    pub fn open(path: &Path, header: usize, file_len: u64) -> Result<Self> {
        use std::io::{Seek, SeekFrom};
        let open = || std::fs::File::open(path).map_err(|e| Error::io(path, e));
        let bad = |e: image::ImageError| {
            Error::invalid(path, format!("not a readable Radiance HDR file: {e}"))
        };
        // The header parsed by the decoder [`decode_file`] uses (the same sizes, the same
        // refusals), then the scan lines read here from the byte after the resolution line.
        let meta = image::codecs::hdr::HdrDecoder::new(std::io::BufReader::new(open()?))
            .map_err(bad)?
            .metadata();
        Image::check_size(path, meta.width as u64, meta.height as u64)?;
        let (w, h) = (meta.width as usize, meta.height as usize);
        let data = file_len.saturating_sub(header as u64);
        if data < 4 * h as u64 {
            return Err(Error::invalid(
                path,
                format!(
                    "truncated Radiance HDR: {data} bytes of pixel data cannot hold the {h} scan lines of its {w}x{h} header"
                ),
            ));
        }
        let mut file = open()?;
        file.seek(SeekFrom::Start(header as u64))
            .map_err(|e| Error::io(path, e))?;
        Ok(HdrRows {
            path: path.to_path_buf(),
            reader: std::io::BufReader::with_capacity(1 << 20, file),
            width: w,
            height: h,
            next: 0,
            line: vec![[0; 4]; w],
        })
    }
}

impl crate::io::rows::RowSource for HdrRows {
    fn path(&self) -> &Path {
        &self.path
    }
    fn width(&self) -> usize {
        self.width
    }
    fn height(&self) -> usize {
        self.height
    }
    fn channels(&self) -> usize {
        3
    }
    fn read_rows(&mut self, count: usize, out: &mut Vec<f32>) -> Result<()> {
        for _ in 0..count {
            let j = self.next;
            read_scanline(&mut self.reader, &mut self.line).map_err(|e| {
                Error::invalid(
                    &self.path,
                    format!(
                        "not a readable Radiance HDR file: scan line {j} of {}: {e}",
                        self.height
                    ),
                )
            })?;
            out.extend(self.line.iter().flat_map(|&p| rgbe_to_f32(p)));
            self.next += 1;
        }
        Ok(())
    }
}

/// RGBE → linear RGB exactly as the `image` crate's decoder (0.25,
/// src/codecs/hdr/decoder.rs, `Rgbe8Pixel::to_hdr`) converts it, so a streamed read gives the
/// bits of a whole decode: 2^(e−136) built from its bits (a subnormal for e = 1, 0 for e = 0).
#[inline]
fn rgbe_to_f32(p: [u8; 4]) -> [f32; 3] {
    let e = p[3];
    let exp = f32::from_bits(if e > 1 {
        ((e - 1) as u32) << 23
    } else {
        (e as u32) << 22
    }) * 0.00390625;
    [exp * p[0] as f32, exp * p[1] as f32, exp * p[2] as f32]
}

/// Reads one scan line of `line.len()` pixels: the run-length encoding of Radiance's
/// `freadcolrs` (a line starting 2, 2, hi, lo with hi < 128: four component runs), otherwise
/// flat pixels with the old (1, 1, 1, n) repeat markers, as the `image` crate reads them.
fn read_scanline<R: std::io::Read>(
    r: &mut R,
    line: &mut [[u8; 4]],
) -> std::result::Result<(), String> {
    let width = line.len();
    let io = |e: std::io::Error| {
        if e.kind() == std::io::ErrorKind::UnexpectedEof {
            "the file ends inside it (truncated)".to_string()
        } else {
            e.to_string()
        }
    };
    let mut first = [0u8; 4];
    r.read_exact(&mut first).map_err(io)?;
    if first[0] == 2 && first[1] == 2 && first[2] < 128 {
        let mut buf = [0u8; 128];
        for c in 0..4 {
            let mut pos = 0;
            while pos < width {
                let mut b = [0u8; 1];
                r.read_exact(&mut b).map_err(io)?;
                let (run, count) = if b[0] > 128 {
                    (true, (b[0] - 128) as usize)
                } else {
                    (false, b[0] as usize)
                };
                if pos + count > width {
                    return Err(format!(
                        "a run of {count} at pixel {pos} overruns the {width}-pixel line"
                    ));
                }
                if count == 0 {
                    // The image crate reads a zero count as a no-op run; so do we (a line
                    // of them ends at the file's end, as a truncation).
                    continue;
                }
                if run {
                    r.read_exact(&mut b).map_err(io)?;
                    line[pos..pos + count].iter_mut().for_each(|p| p[c] = b[0]);
                } else {
                    r.read_exact(&mut buf[..count]).map_err(io)?;
                    for (p, &v) in line[pos..pos + count].iter_mut().zip(&buf[..count]) {
                        p[c] = v;
                    }
                }
                pos += count;
            }
        }
        return Ok(());
    }
    if first[..3] == [1, 1, 1] {
        return Err("a repeat marker as the line's first pixel".into());
    }
    line[0] = first;
    let (mut x, mut mult, mut prev) = (1usize, 1usize, first);
    while x < width {
        let mut p = [0u8; 4];
        r.read_exact(&mut p).map_err(io)?;
        if p[..3] == [1, 1, 1] {
            let n = (p[3] as usize).saturating_mul(mult);
            mult = mult.saturating_mul(256);
            if n > width - x {
                return Err(format!(
                    "a repeat of {n} at pixel {x} overruns the {width}-pixel line"
                ));
            }
            line[x..x + n].iter_mut().for_each(|q| *q = prev);
            x += n;
        } else {
            mult = 1;
            prev = p;
            line[x] = p;
            x += 1;
        }
    }
    Ok(())
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::rows::RowSource;

    /// The rows [`HdrRows`] reads from `bytes` written to a file, and the whole decode's.
    fn both(bytes: &[u8]) -> (Result<Vec<f32>>, Result<Image>) {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("t.hdr");
        std::fs::write(&p, bytes).unwrap();
        let header = header_len(bytes).unwrap();
        let rows = HdrRows::open(&p, header, bytes.len() as u64).and_then(|mut r| {
            let mut out = Vec::new();
            let h = r.height();
            r.read_rows(h, &mut out).map(|_| out)
        });
        (rows, decode(&p, bytes))
    }

    #[test]
    fn rows_are_the_bits_of_the_image_crates_decode() {
        let (w, h) = (300usize, 5usize);
        let mut bytes =
            format!("#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y {h} +X {w}\n").into_bytes();
        let mut x = 0x2545_f491u32;
        let mut rnd = || {
            x ^= x << 13;
            x ^= x >> 17;
            x ^= x << 5;
            x
        };
        // Flat lines with old-style repeat markers (single and consecutive, which multiply
        // by 256), exponents 0, 1 (a subnormal scale) and 255 among them.
        for j in 0..h - 1 {
            let (mut x_at, mut marker) = (0, false);
            while x_at < w {
                let r = rnd();
                marker = !marker && x_at > 0 && r % 7 == 0 && x_at + 3 <= w;
                if marker {
                    bytes.extend([1, 1, 1, 3]);
                    x_at += 3;
                } else {
                    let e = [0u8, 1, 255, 128, 140][(r as usize / 7) % 5];
                    let c = [(r >> 8) as u8 | 4, (r >> 16) as u8, (r >> 24) as u8];
                    bytes.extend([c[0], c[1], c[2], e]);
                    x_at += 1;
                }
            }
            assert_eq!(x_at, w, "row {j}");
        }
        // Two markers in a row: 43 + 1·256 repeats of the first pixel.
        bytes.extend([9, 8, 7, 130, 1, 1, 1, 43, 1, 1, 1, 1]);
        let (rows, whole) = both(&bytes);
        let (rows, whole) = (rows.unwrap(), whole.unwrap());
        assert_eq!(rows.len(), whole.data.len());
        assert!(rows
            .iter()
            .zip(&whole.data)
            .all(|(a, b)| a.to_bits() == b.to_bits()));
        // Run-length lines as the crate's own encoder writes them.
        let img = Image::from_data(
            w,
            h,
            3,
            (0..w * h * 3)
                .map(|k| ((k * 31) % 97) as f32 * 0.01 + (k / 900) as f32)
                .collect(),
        )
        .unwrap();
        let enc = encode(Path::new("x.hdr"), &img).unwrap();
        let (rows, whole) = both(&enc);
        let (rows, whole) = (rows.unwrap(), whole.unwrap());
        assert!(rows
            .iter()
            .zip(&whole.data)
            .all(|(a, b)| a.to_bits() == b.to_bits()));
        // Cut anywhere in the pixel data: both refuse.
        let header = header_len(&enc).unwrap();
        for cut in [header + 4 * h, header + 100, enc.len() - 1] {
            let (rows, whole) = both(&enc[..cut]);
            assert!(rows.is_err() && whole.is_err(), "cut at {cut}");
            let e = rows.unwrap_err().to_string();
            assert!(e.contains("t.hdr: ") && e.contains("scan line"), "{e}");
        }
    }
}
