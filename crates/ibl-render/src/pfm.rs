//! PFM, the contract's interchange format for float images: "PF" (RGB), width and height,
//! a scale whose sign gives the byte order (−1.0: little endian), then 3 floats a pixel with
//! the rows stored bottom row first (Paul Debevec's PFM specification,
//! https://www.pauldebevec.com/Research/HDR/PFM/). In memory, row 0 is the top, as
//! everywhere in this workspace.

use ibl_core::{Error, Image};
use std::path::Path;

/// Encodes an RGB float image (row 0 at the top) as little-endian PFM bytes.
pub fn encode(img: &Image) -> Vec<u8> {
    let rgb = img.to_channels(3);
    let mut out = format!("PF\n{} {}\n-1.0\n", rgb.width, rgb.height).into_bytes();
    out.reserve(rgb.width * rgb.height * 12);
    for y in (0..rgb.height).rev() {
        for x in 0..rgb.width {
            for v in rgb.texel(x, y) {
                out.extend_from_slice(&v.to_le_bytes());
            }
        }
    }
    out
}

/// Largest PFM side accepted (the size check before any allocation).
const MAX_SIDE: usize = 1 << 15;

/// Decodes PFM bytes ("PF" colour or "Pf" grey, either byte order) into an RGB image with row
/// 0 at the top; `path` names the file in errors.
pub fn decode(path: &Path, bytes: &[u8]) -> Result<Image, Error> {
    let bad = |why: &str| Error::invalid(path, format!("not a valid PFM: {why}"));
    // Header: three whitespace-separated tokens after the magic, one whitespace byte, data.
    let mut pos = 0usize;
    let token = |pos: &mut usize| -> Option<String> {
        while *pos < bytes.len() && bytes[*pos].is_ascii_whitespace() {
            *pos += 1;
        }
        let start = *pos;
        while *pos < bytes.len() && !bytes[*pos].is_ascii_whitespace() && *pos - start < 32 {
            *pos += 1;
        }
        (*pos > start).then(|| String::from_utf8_lossy(&bytes[start..*pos]).into_owned())
    };
    let magic = token(&mut pos).ok_or_else(|| bad("empty file"))?;
    let channels = match magic.as_str() {
        "PF" => 3,
        "Pf" => 1,
        _ => return Err(bad("the header does not start with PF or Pf")),
    };
    let mut num = |what: &str| -> Result<String, Error> {
        token(&mut pos).ok_or_else(|| bad(&format!("the header ends before its {what}")))
    };
    let width: usize = num("width")?
        .parse()
        .map_err(|_| bad("width is not a number"))?;
    let height: usize = num("height")?
        .parse()
        .map_err(|_| bad("height is not a number"))?;
    let scale: f64 = num("scale")?
        .parse()
        .map_err(|_| bad("scale is not a number"))?;
    if width == 0 || height == 0 || width > MAX_SIDE || height > MAX_SIDE {
        return Err(bad(&format!(
            "size {width}×{height} is out of range 1..={MAX_SIDE}"
        )));
    }
    if scale == 0.0 || !scale.is_finite() {
        return Err(bad(
            "scale must be a non-zero number (its sign gives the byte order)",
        ));
    }
    // Exactly one whitespace byte ends the header.
    if pos >= bytes.len() || !bytes[pos].is_ascii_whitespace() {
        return Err(bad("no data after the header"));
    }
    pos += 1;
    let need = width * height * channels * 4;
    let data = &bytes[pos..];
    if data.len() != need {
        return Err(bad(&format!(
            "{}×{} {} needs {need} bytes of data, the file has {}",
            width,
            height,
            if channels == 3 { "RGB" } else { "grey" },
            data.len()
        )));
    }
    let little = scale < 0.0;
    let mut img = Image::new(width, height, 3);
    for (k, chunk) in data.chunks_exact(4).enumerate() {
        let b = [chunk[0], chunk[1], chunk[2], chunk[3]];
        let v = if little {
            f32::from_le_bytes(b)
        } else {
            f32::from_be_bytes(b)
        };
        let (p, c) = (k / channels, k % channels);
        let (x, y_from_bottom) = (p % width, p / width);
        let y = height - 1 - y_from_bottom;
        let t = img.texel_mut(x, y);
        if channels == 1 {
            t.copy_from_slice(&[v, v, v]);
        } else {
            t[c] = v;
        }
    }
    Ok(img)
}

/// Reads a PFM file.
pub fn read(path: &Path) -> Result<Image, Error> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    decode(path, &bytes)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_and_row_order() {
        let mut img = Image::new(3, 2, 3);
        for y in 0..2 {
            for x in 0..3 {
                img.texel_mut(x, y)
                    .copy_from_slice(&[x as f32, y as f32, 0.5]);
            }
        }
        let bytes = encode(&img);
        assert!(bytes.starts_with(b"PF\n3 2\n-1.0\n"));
        // The first stored row is the bottom one (y = 1): its first pixel is (0, 1, 0.5).
        let data = &bytes[b"PF\n3 2\n-1.0\n".len()..];
        assert_eq!(f32::from_le_bytes(data[4..8].try_into().unwrap()), 1.0);
        let back = decode(Path::new("t.pfm"), &bytes).unwrap();
        assert_eq!(back, img);
    }

    #[test]
    fn big_endian_and_grey_are_read() {
        let mut b = b"Pf\n2 1\n1.0\n".to_vec();
        for v in [1.5f32, -2.0] {
            b.extend_from_slice(&v.to_be_bytes());
        }
        let img = decode(Path::new("g.pfm"), &b).unwrap();
        assert_eq!(img.rgb(1, 0), [-2.0, -2.0, -2.0]);
    }

    #[test]
    fn malformed_files_are_refused_with_a_reason() {
        let p = Path::new("bad.pfm");
        for (bytes, needle) in [
            (b"".to_vec(), "empty"),
            (b"P6\n1 1\n255\n".to_vec(), "PF or Pf"),
            (b"PF\n-3 2\n-1.0\n".to_vec(), "width"),
            (b"PF\n99999 2\n-1.0\n".to_vec(), "out of range"),
            (b"PF\n2 2\n0\n".to_vec(), "scale"),
            (b"PF\n2 2\n-1.0\n\0\0\0\0".to_vec(), "needs 48 bytes"),
            (b"PF\n2 2".to_vec(), "ends before"),
        ] {
            let e = decode(p, &bytes).unwrap_err().to_string();
            assert!(
                e.contains(needle) && e.contains("bad.pfm") && !e.contains('\n'),
                "{e}"
            );
        }
    }
}
