//! KTX 1.1 framing of a [`Payload`] (Khronos "KTX File Format Specification" 1.1), as
//! Filament's cmgen writes and its `KtxBundle` reads: OpenGL format codes, key/value
//! metadata (cmgen's `sh`), and per level an `imageSize` followed by the faces, each padded to
//! 4 bytes. For a non-array cube `imageSize` is the size of one face (spec §2.16).

use super::format::PixelFormat;
use super::texture::{self, Payload};
use crate::error::{Error, Result};
use std::path::Path;

pub(crate) const IDENTIFIER: [u8; 12] = [
    0xAB, 0x4B, 0x54, 0x58, 0x20, 0x31, 0x31, 0xBB, 0x0D, 0x0A, 0x1A, 0x0A,
];
const ENDIAN: u32 = 0x0403_0201;
const HEADER_LEN: usize = 64;

/// Frames a payload as little-endian KTX 1.1 with `metadata` key/value pairs (after
/// `KTXwriter`).
pub fn encode(p: &Payload, metadata: &[(String, Vec<u8>)]) -> Vec<u8> {
    let c = p.format.codes();
    let gl_type = header_gl_type(p.format);
    let mut kv = vec![super::ktx2::writer_entry()];
    kv.extend(metadata.iter().cloned());
    let mut kvd = Vec::new();
    for (k, v) in &kv {
        kvd.extend(((k.len() + 1 + v.len()) as u32).to_le_bytes());
        kvd.extend(k.as_bytes());
        kvd.push(0);
        kvd.extend(v);
        kvd.resize(kvd.len().div_ceil(4) * 4, 0);
    }
    let mut out = Vec::new();
    out.extend(IDENTIFIER);
    for v in [
        ENDIAN,
        gl_type,
        c.gl_type_size,
        c.gl_format,
        c.gl_internal_format,
        c.gl_base_internal_format,
        p.width as u32,
        p.height as u32,
        0,
        0,
        p.faces as u32,
        p.levels.len() as u32,
        kvd.len() as u32,
    ] {
        out.extend(v.to_le_bytes());
    }
    out.extend(&kvd);
    for level in &p.levels {
        let image_size = if p.faces == 6 {
            level[0].len()
        } else {
            level.iter().map(Vec::len).sum()
        };
        out.extend((image_size as u32).to_le_bytes());
        for face in level {
            out.extend(face);
            out.resize(out.len().div_ceil(4) * 4, 0); // cubePadding
        }
        out.resize(out.len().div_ceil(4) * 4, 0); // mipPadding
    }
    out
}

/// The `glType` the header carries. The spec's type for R11F_G11F_B10F data is
/// UNSIGNED_INT_10F_11F_11F_REV (0x8C3B), but Filament's KTX1 reader, the one engine that
/// reads these files, maps only UNSIGNED_BYTE, UNSIGNED_SHORT, HALF_FLOAT, FLOAT and
/// R11F_G11F_B10F (0x8C3A) to a pixel type (google/filament
/// `libs/ktxreader/src/Ktx1Reader.cpp`, `toPixelDataType`), and aborts on any other
/// ("internal format=29 and {format=4, type=15} is not supported", `filament/src/Texture.cpp`).
/// cmgen writes 0x8C3A (`tools/cmgen/src/cmgen.cpp` via `libs/image/src/KtxBundle.cpp`), and
/// libktx, which reads the format from glInternalFormat, accepts both, so we write what
/// Filament reads. Our reader keys on glInternalFormat and reads either value.
fn header_gl_type(f: PixelFormat) -> u32 {
    match f {
        PixelFormat::B10g11r11 => f.codes().gl_internal_format,
        _ => f.codes().gl_type,
    }
}

/// Parses a KTX 1.1 file (either endianness) into its payload and key/value metadata.
pub fn decode(path: &Path, b: &[u8]) -> Result<(Payload, super::layout::Metadata)> {
    let bad = |why: String| Error::invalid(path, format!("not a valid KTX file: {why}"));
    if b.len() < HEADER_LEN || b[..12] != IDENTIFIER {
        return Err(bad("bad identifier or truncated header".into()));
    }
    let swap = match super::ktx2::u32_at(b, 12) {
        Some(ENDIAN) => false,
        Some(0x0102_0304) => true,
        _ => return Err(bad("bad endianness field".into())),
    };
    let rd = move |d: &[u8], o: usize| {
        super::ktx2::u32_at(d, o).map(|v| if swap { v.swap_bytes() } else { v })
    };
    let h = |k: usize| rd(b, 12 + 4 * k).expect("header is 64 bytes");
    let (internal, width, height, depth, array, faces, levels, kvd_len) =
        (h(4), h(6), h(7), h(8), h(9), h(10), h(11), h(12) as usize);
    let format = PixelFormat::from_gl_internal(internal).ok_or_else(|| {
        Error::unsupported(
            path,
            format!("KTX glInternalFormat 0x{internal:04X} (read: RGBA32F, RGBA16F, RGB9_E5, R11F_G11F_B10F, BPTC unsigned float)"),
        )
    })?;
    let (height, levels) =
        texture::check_shape(path, "KTX", faces, width, height, depth, array, levels)?;
    let kvd = b
        .get(HEADER_LEN..HEADER_LEN.saturating_add(kvd_len))
        .ok_or_else(|| bad("key/value data runs past the end".into()))?;
    let kv = super::ktx2::parse_kvd(path, kvd, rd)?;
    let mut p = Payload {
        format,
        width: width as usize,
        height: height as usize,
        faces: faces as usize,
        levels: Vec::with_capacity(levels as usize),
    };
    let _budget = p.reserve(path, "KTX", levels as usize)?;
    let mut o = HEADER_LEN + kvd_len;
    for l in 0..levels as usize {
        let n = p.face_bytes(l);
        let image_size = rd(b, o).ok_or_else(|| bad(format!("level {l}: truncated")))? as usize;
        let want = if faces == 6 { n } else { n * faces as usize };
        if image_size != want {
            return Err(bad(format!(
                "level {l}: imageSize {image_size}, expected {want}"
            )));
        }
        o += 4;
        let mut level = Vec::with_capacity(faces as usize);
        for f in 0..faces {
            let data = b
                .get(o..o + n)
                .ok_or_else(|| bad(format!("level {l} face {f} lies past the end of the file")))?;
            level.push(if swap {
                swap_elements(data, format.codes().gl_type_size)
            } else {
                data.to_vec()
            });
            o = (o + n).div_ceil(4) * 4;
        }
        p.levels.push(level);
    }
    Ok((p, kv))
}

/// Big-endian files store each element of `size` bytes swapped (compressed data never is).
fn swap_elements(d: &[u8], size: u32) -> Vec<u8> {
    let mut out = d.to_vec();
    if size > 1 {
        out.chunks_exact_mut(size as usize)
            .for_each(|c| c.reverse());
    }
    out
}

/// KTX 1.1 as a [`super::layout::Codec`].
pub struct Ktx1;

impl super::layout::Codec for Ktx1 {
    fn name(&self) -> &'static str {
        "ktx1"
    }
    fn extension(&self) -> &'static str {
        "ktx"
    }
    fn magic(&self) -> &'static [u8] {
        &IDENTIFIER
    }
    fn encode(
        &self,
        p: &Payload,
        _zstd: Option<i32>,
        metadata: &[(String, Vec<u8>)],
    ) -> Result<Vec<u8>> {
        Ok(encode(p, metadata))
    }
    fn decode(&self, path: &Path, bytes: &[u8]) -> Result<(Payload, super::layout::Metadata)> {
        decode(path, bytes)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::format::Bc6hQuality;
    use crate::io::texture::encode_chain;
    use crate::{CubeMips, Cubemap};

    fn payload(format: PixelFormat, size: usize) -> Payload {
        let base = Cubemap::from_fn(size, |d| [d.x.abs() + 0.1, d.y.abs(), 2.0 * d.z.abs()]);
        encode_chain(&CubeMips::build(base, 1), format, Bc6hQuality::Fast).0
    }

    #[test]
    fn round_trips_every_format_with_metadata() {
        for f in PixelFormat::ALL {
            let p = payload(f, 8);
            let sh = ("sh".to_string(), b"0.1 0.2 0.3\n".to_vec());
            let (back, kv) =
                decode(Path::new("c.ktx"), &encode(&p, std::slice::from_ref(&sh))).unwrap();
            assert_eq!(back, p);
            assert!(kv.contains(&sh));
        }
    }

    #[test]
    fn image_size_is_one_face_for_cubes() {
        let p = payload(PixelFormat::B10g11r11, 4);
        let b = encode(&p, &[]);
        let kvd_len = u32::from_le_bytes(b[60..64].try_into().unwrap()) as usize;
        let first = u32::from_le_bytes(b[64 + kvd_len..68 + kvd_len].try_into().unwrap());
        assert_eq!(first as usize, 4 * 4 * 4);
        assert_eq!(
            b.len(),
            64 + kvd_len + (4 + 6 * 64) + (4 + 6 * 16) + (4 + 6 * 4)
        );
    }

    #[test]
    fn b10g11r11_header_carries_the_gl_type_filament_reads() {
        let b = encode(&payload(PixelFormat::B10g11r11, 2), &[]);
        let word = |k: usize| u32::from_le_bytes(b[12 + 4 * k..16 + 4 * k].try_into().unwrap());
        // glType, glTypeSize, glFormat, glInternalFormat, glBaseInternalFormat as cmgen
        // writes them (Filament's Ktx1Reader.cpp maps glType 0x8C3A, not 0x8C3B).
        assert_eq!(
            (word(1), word(2), word(3), word(4), word(5)),
            (0x8C3A, 4, 0x1907, 0x8C3A, 0x1907)
        );
        // The spec's glType (0x8C3B, what we wrote before) still reads.
        let mut spec = b.clone();
        spec[16..20].copy_from_slice(&0x8C3Bu32.to_le_bytes());
        assert_eq!(
            decode(Path::new("c.ktx"), &spec).unwrap().0,
            decode(Path::new("c.ktx"), &b).unwrap().0
        );
    }

    #[test]
    fn big_endian_files_are_read() {
        let p = payload(PixelFormat::Rgba16f, 2);
        let le = encode(&p, &[]);
        // Swap every header word and every 2-byte element, as a big-endian writer would.
        let mut be = le[..12].to_vec();
        for w in le[12..64].chunks_exact(4) {
            be.extend(w.iter().rev());
        }
        let kvd_len = u32::from_le_bytes(le[60..64].try_into().unwrap()) as usize;
        for w in le[64..64 + kvd_len].chunks_exact(4).take(1) {
            be.extend(w.iter().rev());
        }
        be.extend(&le[68..64 + kvd_len]);
        let mut o = 64 + kvd_len;
        for l in 0..p.levels.len() {
            be.extend(le[o..o + 4].iter().rev());
            o += 4;
            let n = p.face_bytes(l) * 6;
            for e in le[o..o + n].chunks_exact(2) {
                be.extend(e.iter().rev());
            }
            o += n;
        }
        let (back, _) = decode(Path::new("be.ktx"), &be).unwrap();
        assert_eq!(back, p);
    }

    #[test]
    fn truncated_and_garbled_files_are_errors() {
        let b = encode(&payload(PixelFormat::Bc6h, 8), &[]);
        for cut in [0, 12, 63, 70, b.len() - 3] {
            assert!(decode(Path::new("c.ktx"), &b[..cut]).is_err(), "cut {cut}");
        }
        let mut bad = b.clone();
        bad[60..64].copy_from_slice(&u32::MAX.to_le_bytes()); // kvd length past the end
        assert!(decode(Path::new("c.ktx"), &bad).is_err());
        let mut bad = b;
        bad[28..32].copy_from_slice(&0x1234u32.to_le_bytes()); // unknown internal format
        assert!(matches!(
            decode(Path::new("c.ktx"), &bad),
            Err(Error::Unsupported { .. })
        ));
    }
}
