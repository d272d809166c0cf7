//! KTX2 (Khronos KTX 2.0) framing of a [`Payload`]: cubes or 2D images, all levels, any
//! [`PixelFormat`], optionally zstd-supercompressed (scheme 2), with the data format descriptor
//! libktx derives from the vkFormat (KhronosGroup/KTX-Software `lib/dfdutils/createdfd.c`,
//! `vk2dfd.inl`), so that `ktx validate` finds the two consistent.

use super::format::{Bc6hQuality, PixelFormat};
use super::texture::{self, Payload};
use super::FloatDepth;
use crate::cube::CubeMips;
use crate::error::{Error, Result};
use std::path::Path;

pub(crate) const IDENTIFIER: [u8; 12] = [
    0xAB, 0x4B, 0x54, 0x58, 0x20, 0x32, 0x30, 0xBB, 0x0D, 0x0A, 0x1A, 0x0A,
];
const VK_FORMAT_R32G32B32_SFLOAT: u32 = 106;
const HEADER_LEN: usize = 80;
const SCHEME_NONE: u32 = 0;
const SCHEME_ZSTD: u32 = 2;
/// A zstd stream inflates at most about 32768:1 (a 3-byte RLE block header and one byte give
/// a 128 KiB block); a level claiming more cannot be valid and is refused before inflating.
const ZSTD_MAX_RATIO: u64 = 32_768;

/// Channel-type qualifiers of a DFD sample (KDF 1.3 §5.6.4).
const QUAL_EXPONENT: u8 = 0x20;
const QUAL_SIGNED: u8 = 0x40;
const QUAL_FLOAT: u8 = 0x80;
const F32_ONE: u32 = 0x3F80_0000;
const F32_MINUS_ONE: u32 = 0xBF80_0000;

/// One sample of a basic descriptor block: (bit offset, bit length, channel id | qualifiers,
/// lower, upper).
type Sample = (u16, u8, u8, u32, u32);

/// The basic data format descriptor of `format` (KDF 1.3 §5), byte for byte what libktx's
/// `vk2dfd` makes: colour model RGBSDA (BC6H for BC6H), BT.709 primaries, linear transfer.
fn dfd(format: PixelFormat) -> Vec<u8> {
    let (model, block_dim, bytes_plane0, samples): (u8, [u8; 4], u8, Vec<Sample>) = match format {
        PixelFormat::Rgba32f | PixelFormat::Rgba16f => {
            let bits = if format == PixelFormat::Rgba32f {
                32u16
            } else {
                16
            };
            let q = QUAL_FLOAT | QUAL_SIGNED;
            let s = [0u8, 1, 2, 15]
                .iter()
                .enumerate()
                .map(|(k, &ch)| {
                    (
                        k as u16 * bits,
                        (bits - 1) as u8,
                        ch | q,
                        F32_MINUS_ONE,
                        F32_ONE,
                    )
                })
                .collect();
            (1, [0; 4], (bits / 2) as u8, s)
        }
        PixelFormat::B10g11r11 => (
            1,
            [0; 4],
            4,
            vec![
                (0, 10, QUAL_FLOAT, 0, F32_ONE),
                (11, 10, 1 | QUAL_FLOAT, 0, F32_ONE),
                (22, 9, 2 | QUAL_FLOAT, 0, F32_ONE),
            ],
        ),
        // createDFDPackedShifted's E5B9G9R9 special case: a mantissa and an exponent sample
        // per channel, mantissa upper 8448, exponent bounds 15 (bias) and 31.
        PixelFormat::Rgb9e5 => (
            1,
            [0; 4],
            4,
            (0u8..3)
                .flat_map(|c| {
                    [
                        (9 * c as u16, 8, c, 0, 8448),
                        (27, 4, c | QUAL_EXPONENT, 15, 31),
                    ]
                })
                .collect(),
        ),
        PixelFormat::Bc6h => (
            133,
            [3, 3, 0, 0],
            16,
            vec![(0, 127, QUAL_FLOAT, 0, F32_ONE)],
        ),
    };
    let block_size = 24 + 16 * samples.len() as u32;
    let mut d = Vec::new();
    d.extend((4 + block_size).to_le_bytes()); // dfdTotalSize
    d.extend(0u32.to_le_bytes()); // vendorId 0 (Khronos), descriptorType 0 (basic)
    d.extend((2u32 | (block_size << 16)).to_le_bytes()); // versionNumber 2, descriptorBlockSize
    d.extend([model, 1, 1, 0]); // colorModel, primaries BT.709, transfer linear, flags
    d.extend(block_dim); // texelBlockDimension0..3 (minus one)
    d.extend([bytes_plane0, 0, 0, 0, 0, 0, 0, 0]); // bytesPlane0..7
    for (offset, len, channel, lower, upper) in samples {
        d.extend(offset.to_le_bytes());
        d.push(len);
        d.push(channel);
        d.extend([0u8; 4]); // samplePosition
        d.extend(lower.to_le_bytes());
        d.extend(upper.to_le_bytes());
    }
    d
}

/// Key/value metadata of KTX1 and KTX2 files (defined in `io::layout`; named here too, where
/// it was first).
pub use super::layout::Metadata;

/// Key/value data: entries sorted by key (as the KTX2 spec requires), each padded to 4 bytes.
fn kvd(entries: &[(String, Vec<u8>)]) -> Vec<u8> {
    let mut sorted: Vec<&(String, Vec<u8>)> = entries.iter().collect();
    sorted.sort_by(|a, b| a.0.as_bytes().cmp(b.0.as_bytes()));
    let mut d = Vec::new();
    for (k, v) in sorted {
        let len = k.len() + 1 + v.len();
        d.extend((len as u32).to_le_bytes());
        d.extend(k.as_bytes());
        d.push(0);
        d.extend(v);
        d.resize(d.len().div_ceil(4) * 4, 0);
    }
    d
}

/// The `KTXwriter` entry every writer here puts in its files.
pub(crate) fn writer_entry() -> (String, Vec<u8>) {
    (
        "KTXwriter".into(),
        format!("ibl-bake {}\0", crate::TOOL_VERSION).into_bytes(),
    )
}

/// Frames a payload as KTX2; `zstd` is the supercompression level (1..=22), if any.
/// `metadata` entries are written besides `KTXwriter`.
pub fn encode(p: &Payload, zstd: Option<i32>, metadata: &[(String, Vec<u8>)]) -> Result<Vec<u8>> {
    let codes = p.format.codes();
    let levels = p.levels.len();
    let dfd = dfd(p.format);
    let mut kv = vec![writer_entry()];
    kv.extend(metadata.iter().cloned());
    let kvd = kvd(&kv);
    let index_len = 24 * levels;
    let dfd_off = HEADER_LEN + index_len;
    let kvd_off = dfd_off + dfd.len();
    let mut data_start = kvd_off + kvd.len();
    // Level alignment: lcm(texel block size, 4) uncompressed, none when supercompressed.
    let align = if zstd.is_some() {
        1
    } else {
        let b = p.format.block_bytes();
        b * 4 / gcd(b, 4)
    };
    let raw: Vec<Vec<u8>> = p.levels.iter().map(|faces| faces.concat()).collect();
    let stored: Vec<Vec<u8>> = match zstd {
        None => raw.clone(),
        Some(level) => {
            use rayon::prelude::*;
            raw.par_iter()
                .map(|b| {
                    deflate(b, level)
                        .map_err(|e| Error::param(format!("zstd compression failed: {e}")))
                })
                .collect::<Result<_>>()?
        }
    };
    // Level data is stored smallest level first.
    let mut offsets = vec![0usize; levels];
    for l in (0..levels).rev() {
        data_start = data_start.div_ceil(align) * align;
        offsets[l] = data_start;
        data_start += stored[l].len();
    }
    let mut out = Vec::with_capacity(data_start);
    out.extend(IDENTIFIER);
    let (layers, faces) = (0u32, p.faces as u32);
    let scheme = if zstd.is_some() {
        SCHEME_ZSTD
    } else {
        SCHEME_NONE
    };
    for v in [
        codes.vk,
        codes.ktx2_type_size,
        p.width as u32,
        p.height as u32,
        0,
        layers,
        faces,
        levels as u32,
        scheme,
    ] {
        out.extend(v.to_le_bytes());
    }
    for v in [dfd_off, dfd.len(), kvd_off, kvd.len()] {
        out.extend((v as u32).to_le_bytes());
    }
    out.extend(0u64.to_le_bytes()); // sgdByteOffset
    out.extend(0u64.to_le_bytes()); // sgdByteLength
    for l in 0..levels {
        out.extend((offsets[l] as u64).to_le_bytes());
        out.extend((stored[l].len() as u64).to_le_bytes());
        out.extend((raw[l].len() as u64).to_le_bytes());
    }
    out.extend(&dfd);
    out.extend(&kvd);
    for l in (0..levels).rev() {
        out.resize(offsets[l], 0);
        out.extend(&stored[l]);
    }
    Ok(out)
}

/// zstd-compresses one level with the frame's content checksum (RFC 8878 §3.1.1.1.1:
/// Content_Checksum_Flag, an XXH64 of the content's low 32 bits after the last block), so
/// that bit rot in a stored file is found when it is read, not baked into a result.
fn deflate(raw: &[u8], level: i32) -> std::io::Result<Vec<u8>> {
    let mut c = zstd::bulk::Compressor::new(level)?;
    c.set_parameter(zstd::stream::raw::CParameter::ChecksumFlag(true))?;
    c.compress(raw)
}

/// Inflates one zstd level into exactly `size` bytes (allocated fallibly), verifying the
/// frame's content checksum where it has one (files of other writers may not: libktx writes
/// none).
fn inflate(path: &Path, data: &[u8], size: usize) -> std::result::Result<Vec<u8>, String> {
    let mut out: Vec<u8> = Vec::new();
    out.try_reserve_exact(size)
        .map_err(|_| super::budget::out_of_memory(path, size as u64).to_string())?;
    let mut d = zstd::bulk::Decompressor::new().map_err(|e| format!("zstd: {e}"))?;
    let n = d.decompress_to_buffer(data, &mut out).map_err(|e| {
        let e = e.to_string();
        if e.to_ascii_lowercase().contains("checksum") {
            "zstd content checksum mismatch: the level's bytes are damaged".to_string()
        } else {
            format!("zstd stream: {e}")
        }
    })?;
    out.truncate(n);
    Ok(out)
}

fn gcd(a: usize, b: usize) -> usize {
    if b == 0 {
        a
    } else {
        gcd(b, a % b)
    }
}

pub(crate) fn u32_at(b: &[u8], o: usize) -> Option<u32> {
    b.get(o..o + 4)
        .map(|s| u32::from_le_bytes(s.try_into().expect("4 bytes")))
}
fn u64_at(b: &[u8], o: usize) -> Option<u64> {
    b.get(o..o + 8)
        .map(|s| u64::from_le_bytes(s.try_into().expect("8 bytes")))
}

/// Parses key/value data into (key, value) pairs; malformed data is an error.
pub(crate) fn parse_kvd(
    path: &Path,
    d: &[u8],
    read_u32: impl Fn(&[u8], usize) -> Option<u32>,
) -> Result<Metadata> {
    let bad = || Error::invalid(path, "malformed key/value data");
    let mut out = Vec::new();
    let mut o = 0usize;
    while o < d.len() {
        let len = read_u32(d, o).ok_or_else(bad)? as usize;
        let entry = d
            .get(o + 4..(o + 4).checked_add(len).ok_or_else(bad)?)
            .ok_or_else(bad)?;
        let nul = entry.iter().position(|&c| c == 0).ok_or_else(bad)?;
        let key = String::from_utf8_lossy(&entry[..nul]).into_owned();
        out.push((key, entry[nul + 1..].to_vec()));
        o += 4 + len.div_ceil(4) * 4;
    }
    Ok(out)
}

/// Parses a KTX2 file into its payload and key/value metadata. Every length and offset is
/// checked against the file and the image size before anything is allocated; zstd levels are
/// inflated into exactly the size the header justifies.
pub fn decode(path: &Path, b: &[u8]) -> Result<(Payload, Metadata)> {
    let bad = |why: String| Error::invalid(path, format!("not a valid KTX2 file: {why}"));
    if b.len() < HEADER_LEN || b[..12] != IDENTIFIER {
        return Err(bad("bad identifier or truncated header".into()));
    }
    let h = |k: usize| u32_at(b, 12 + 4 * k).expect("header is 80 bytes");
    let (vk, width, height, depth, layers, faces, levels, scheme) =
        (h(0), h(2), h(3), h(4), h(5), h(6), h(7), h(8));
    if scheme != SCHEME_NONE && scheme != SCHEME_ZSTD {
        let name = match scheme {
            1 => "BasisLZ",
            3 => "zlib",
            _ => "an unknown scheme",
        };
        return Err(Error::unsupported(
            path,
            format!("KTX2 supercompressed with {name} (scheme {scheme}; zstd and none are read)"),
        ));
    }
    let (height, levels) =
        texture::check_shape(path, "KTX2", faces, width, height, depth, layers, levels)?;
    let (format, rgb32) = match (PixelFormat::from_vk(vk), vk) {
        (Some(f), _) => (f, false),
        (None, VK_FORMAT_R32G32B32_SFLOAT) => (PixelFormat::Rgba32f, true),
        (None, f) => {
            return Err(Error::unsupported(
                path,
                format!("KTX2 vkFormat {f} (read: RGBA32F, RGBA16F, RGB32F, E5B9G9R9, B10G11R11, BC6H_UFLOAT)"),
            ))
        }
    };
    let index_end = HEADER_LEN + 24 * levels as usize;
    if b.len() < index_end {
        return Err(bad("truncated level index".into()));
    }
    let mut payload = Payload {
        format,
        width: width as usize,
        height: height as usize,
        faces: faces as usize,
        levels: Vec::with_capacity(levels as usize),
    };
    let _budget = payload.reserve(path, "KTX2", levels as usize)?;
    for l in 0..levels as usize {
        let o = HEADER_LEN + 24 * l;
        let (off, len, raw_len) = (
            u64_at(b, o).expect("index checked"),
            u64_at(b, o + 8).expect("index checked"),
            u64_at(b, o + 16).expect("index checked"),
        );
        let (w, hh) = payload.level_dims(l);
        let face = if rgb32 {
            w * hh * 12
        } else {
            format.image_bytes(w, hh)
        };
        let expect = (face * faces as usize) as u64;
        let data = off
            .checked_add(len)
            .and_then(|end| b.get(off as usize..end as usize))
            .ok_or_else(|| bad(format!("level {l} lies outside the file")))?;
        let level: Vec<u8> = if scheme == SCHEME_ZSTD {
            if raw_len != expect {
                return Err(bad(format!(
                    "level {l} inflates to {raw_len} bytes, expected {expect}"
                )));
            }
            if expect > len.saturating_mul(ZSTD_MAX_RATIO) + 131_072 {
                return Err(bad(format!(
                    "level {l}: {len} zstd bytes cannot inflate to {expect}"
                )));
            }
            let out =
                inflate(path, data, expect as usize).map_err(|e| bad(format!("level {l}: {e}")))?;
            if out.len() as u64 != expect {
                return Err(bad(format!(
                    "level {l} inflates to {} bytes, expected {expect}",
                    out.len()
                )));
            }
            out
        } else {
            if len != expect {
                return Err(bad(format!(
                    "level {l} holds {len} bytes, expected {expect}"
                )));
            }
            if raw_len != expect && raw_len != 0 {
                return Err(bad(format!(
                    "level {l}: uncompressedByteLength says {raw_len} bytes, but the level \
                     holds {expect}"
                )));
            }
            data.to_vec()
        };
        let faces_bytes: Vec<Vec<u8>> = level
            .chunks_exact(face)
            .map(|f| if rgb32 { rgb_to_rgba32(f) } else { f.to_vec() })
            .collect();
        payload.levels.push(faces_bytes);
    }
    let dfd_kv = |k: usize| u32_at(b, 48 + 4 * k).expect("header");
    let (kvd_off, kvd_len) = (dfd_kv(2) as usize, dfd_kv(3) as usize);
    let kvd = b
        .get(kvd_off..kvd_off.saturating_add(kvd_len))
        .ok_or_else(|| bad("key/value data lies outside the file".into()))?;
    let kv = parse_kvd(path, kvd, u32_at)?;
    Ok((payload, kv))
}

fn rgb_to_rgba32(f: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(f.len() / 3 * 4);
    for px in f.chunks_exact(12) {
        out.extend(px);
        out.extend(1.0f32.to_le_bytes());
    }
    out
}

/// Encodes a cube chain as an uncompressed float KTX2 (RGBA16F or RGBA32F).
pub fn encode_cube(mips: &CubeMips, depth: FloatDepth) -> Vec<u8> {
    let format = match depth {
        FloatDepth::F16 => PixelFormat::Rgba16f,
        FloatDepth::F32 => PixelFormat::Rgba32f,
    };
    let (payload, _) = texture::encode_chain(mips, format, Bc6hQuality::default());
    encode(&payload, None, &[]).expect("uncompressed KTX2 encoding cannot fail")
}

/// Decodes a KTX2 cube map with all its levels, in any format this reader takes.
pub fn decode_cube(path: &Path, b: &[u8]) -> Result<CubeMips> {
    let (payload, _) = decode(path, b)?;
    texture::decode_cube(path, &payload)
}

/// KTX2 as a [`super::layout::Codec`].
pub struct Ktx2;

impl super::layout::Codec for Ktx2 {
    fn name(&self) -> &'static str {
        "ktx2"
    }
    fn extension(&self) -> &'static str {
        "ktx2"
    }
    fn magic(&self) -> &'static [u8] {
        &IDENTIFIER
    }
    fn encode(
        &self,
        p: &Payload,
        zstd: Option<i32>,
        metadata: &[(String, Vec<u8>)],
    ) -> Result<Vec<u8>> {
        encode(p, zstd, metadata)
    }
    fn decode(&self, path: &Path, bytes: &[u8]) -> Result<(Payload, Metadata)> {
        decode(path, bytes)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cube::Cubemap;

    fn chain() -> CubeMips {
        let mut base = Cubemap::new(8);
        for (f, face) in base.faces.iter_mut().enumerate() {
            for (k, v) in face.data.iter_mut().enumerate() {
                *v = (f * 1000 + k) as f32 * 0.25;
            }
        }
        CubeMips::build(base, 1)
    }

    #[test]
    fn ktx2_float_round_trip_is_exact() {
        let mips = chain();
        let bytes = encode_cube(&mips, FloatDepth::F32);
        let back = decode_cube(Path::new("c.ktx2"), &bytes).unwrap();
        assert_eq!(back, mips);
    }

    #[test]
    fn ktx2_layout_is_aligned_and_smallest_level_first() {
        let mips = chain();
        let b = encode_cube(&mips, FloatDepth::F16);
        let off0 = u64_at(&b, HEADER_LEN).unwrap();
        let off_last = u64_at(&b, HEADER_LEN + 24 * (mips.levels.len() - 1)).unwrap();
        assert!(off_last < off0);
        for l in 0..mips.levels.len() {
            assert_eq!(u64_at(&b, HEADER_LEN + 24 * l).unwrap() % 8, 0);
        }
        assert_eq!(u32_at(&b, 12 + 4 * 6), Some(6));
    }

    #[test]
    fn every_format_with_and_without_zstd_round_trips_its_payload() {
        let mips = chain();
        for format in PixelFormat::ALL {
            let (p, _) = texture::encode_chain(&mips, format, Bc6hQuality::Fast);
            let plain = encode(&p, None, &[]).unwrap();
            let packed = encode(&p, Some(3), &[("sh".into(), b"1 2 3\n".to_vec())]).unwrap();
            let (a, _) = decode(Path::new("a.ktx2"), &plain).unwrap();
            let (z, kv) = decode(Path::new("z.ktx2"), &packed).unwrap();
            assert_eq!(a, p, "{format:?}");
            assert_eq!(z, p, "{format:?}");
            assert!(kv.iter().any(|(k, v)| k == "sh" && v == b"1 2 3\n"));
            assert_eq!(u32_at(&packed, 44), Some(SCHEME_ZSTD));
        }
    }

    #[test]
    fn dfds_are_libktx_s() {
        // Sizes and key fields from KTX-Software's createdfd.c for each format.
        let rgb9e5 = dfd(PixelFormat::Rgb9e5);
        assert_eq!(rgb9e5.len(), 4 + 24 + 6 * 16);
        assert_eq!(u32_at(&rgb9e5, 4 + 24 + 16 + 8), Some(15)); // exponent sampleLower (bias)
        assert_eq!(u32_at(&rgb9e5, 4 + 24 + 12), Some(8448)); // mantissa sampleUpper
        let bc6h = dfd(PixelFormat::Bc6h);
        assert_eq!(bc6h[12], 133);
        assert_eq!(&bc6h[16..20], &[3, 3, 0, 0]);
        assert_eq!(bc6h[20], 16);
        let b10 = dfd(PixelFormat::B10g11r11);
        assert_eq!(b10.len(), 4 + 24 + 3 * 16);
        assert_eq!(b10[4 + 24 + 2 * 16 + 2], 9); // blue: 10 bits
    }

    #[test]
    fn truncated_or_garbled_ktx2_is_an_error() {
        let bytes = encode_cube(&chain(), FloatDepth::F32);
        for cut in [0, 11, 79, 100, bytes.len() - 1] {
            assert!(decode_cube(Path::new("c.ktx2"), &bytes[..cut]).is_err());
        }
        let mut b = bytes.clone();
        b[12 + 4 * 6] = 1;
        assert!(decode_cube(Path::new("c.ktx2"), &b).is_err());
    }

    #[test]
    fn zstd_levels_claiming_huge_sizes_are_refused_without_allocating() {
        let (p, _) = texture::encode_chain(&chain(), PixelFormat::Rgb9e5, Bc6hQuality::Fast);
        let good = encode(&p, Some(1), &[]).unwrap();
        // Level 0's uncompressedByteLength → 2^40: refused (does not match the header's size).
        let mut b = good.clone();
        b[HEADER_LEN + 16..HEADER_LEN + 24].copy_from_slice(&(1u64 << 40).to_le_bytes());
        let e = decode(Path::new("z.ktx2"), &b).unwrap_err().to_string();
        assert!(e.contains("inflates"), "{e}");
        // A huge declared image: refused by the size limit before any level is read.
        let mut b = good.clone();
        b[20..24].copy_from_slice(&60000u32.to_le_bytes());
        b[24..28].copy_from_slice(&60000u32.to_le_bytes());
        assert!(decode(Path::new("z.ktx2"), &b).is_err());
        // Corrupt zstd bytes: an error, not a panic.
        let off = u64_at(&good, HEADER_LEN).unwrap() as usize;
        let mut b = good.clone();
        for k in 0..8 {
            b[off + k] ^= 0x5a;
        }
        assert!(decode(Path::new("z.ktx2"), &b).is_err());
    }
}
