//! KTX2 cubemaps (Khronos KTX 2.0 spec): all faces and mips, RGBA16F or RGBA32F, faces in
//! KTX2 order (+X −X +Y −Y +Z −Z), rows top first, no supercompression. The reader takes
//! what the writer produces (and any uncompressed RGBA16F/32F or RGB32F cube).

use super::FloatDepth;
use crate::cube::{CubeMips, Cubemap};
use crate::error::{Error, Result};
use crate::image::Image;
use std::path::Path;

const IDENTIFIER: [u8; 12] = [
    0xAB, 0x4B, 0x54, 0x58, 0x20, 0x32, 0x30, 0xBB, 0x0D, 0x0A, 0x1A, 0x0A,
];
const VK_FORMAT_R16G16B16A16_SFLOAT: u32 = 97;
const VK_FORMAT_R32G32B32_SFLOAT: u32 = 106;
const VK_FORMAT_R32G32B32A32_SFLOAT: u32 = 109;
const HEADER_LEN: usize = 80;

/// Basic data format descriptor for an RGBA float format (KDF 1.3 §5: colour model RGBSDA,
/// BT.709 primaries, linear transfer; one 16-byte sample per channel, float and signed,
/// sample bounds −1.0 and 1.0 as float bit patterns).
fn dfd(bytes_per_channel: u32) -> Vec<u8> {
    let samples = 4u32;
    let block_size = 24 + 16 * samples;
    let mut d = Vec::new();
    d.extend((4 + block_size).to_le_bytes()); // dfdTotalSize
    d.extend(0u32.to_le_bytes()); // vendorId 0 (Khronos), descriptorType 0 (basic)
    d.extend((2u32 | (block_size << 16)).to_le_bytes()); // versionNumber 2, descriptorBlockSize
    d.extend([1u8, 1, 1, 0]); // colorModel RGBSDA, primaries BT709, transfer linear, flags
    d.extend([0u8; 4]); // texelBlockDimension 1×1×1×1 (stored minus one)
    d.extend([(bytes_per_channel * 4) as u8, 0, 0, 0, 0, 0, 0, 0]); // bytesPlane0..7
    for (k, channel_id) in [0u8, 1, 2, 15].iter().enumerate() {
        let bit_offset = (k as u32) * bytes_per_channel * 8;
        let bit_length = (bytes_per_channel * 8 - 1) as u8;
        let channel_type = channel_id | 0x80 | 0x40; // float, signed
        d.extend((bit_offset as u16).to_le_bytes());
        d.push(bit_length);
        d.push(channel_type);
        d.extend([0u8; 4]); // samplePosition
        d.extend(0xBF80_0000u32.to_le_bytes()); // sampleLower −1.0
        d.extend(0x3F80_0000u32.to_le_bytes()); // sampleUpper 1.0
    }
    d
}

fn kvd(writer: &str) -> Vec<u8> {
    let mut d = Vec::new();
    let entry = format!("KTXwriter\0{writer}\0");
    d.extend((entry.len() as u32).to_le_bytes());
    d.extend(entry.as_bytes());
    while d.len() % 4 != 0 {
        d.push(0);
    }
    d
}

/// Encodes a cube mip chain (level 0 first) as KTX2.
pub fn encode_cube(mips: &CubeMips, depth: FloatDepth) -> Vec<u8> {
    let (vk_format, bpc) = match depth {
        FloatDepth::F16 => (VK_FORMAT_R16G16B16A16_SFLOAT, 2u32),
        FloatDepth::F32 => (VK_FORMAT_R32G32B32A32_SFLOAT, 4u32),
    };
    let levels = mips.levels.len();
    let base = mips.levels[0].size as u32;
    let dfd = dfd(bpc);
    let kvd = kvd(&format!("ibl-bake {}", crate::TOOL_VERSION));
    let index_len = 24 * levels;
    let dfd_off = HEADER_LEN + index_len;
    let kvd_off = dfd_off + dfd.len();
    let mut data_start = kvd_off + kvd.len();
    let align = (bpc * 4) as usize; // lcm(texel size, 4)
                                    // Level data is stored smallest level first.
    let level_bytes: Vec<Vec<u8>> = mips
        .levels
        .iter()
        .map(|cube| {
            let mut b = Vec::with_capacity(cube.size * cube.size * 6 * align);
            for face in &cube.faces {
                for px in face.data.chunks_exact(3) {
                    for v in [px[0], px[1], px[2], 1.0] {
                        match depth {
                            FloatDepth::F16 => b.extend(super::f16_saturating(v).to_le_bytes()),
                            FloatDepth::F32 => b.extend(v.to_le_bytes()),
                        }
                    }
                }
            }
            b
        })
        .collect();
    let mut offsets = vec![0usize; levels];
    for l in (0..levels).rev() {
        data_start = data_start.div_ceil(align) * align;
        offsets[l] = data_start;
        data_start += level_bytes[l].len();
    }
    let mut out = Vec::with_capacity(data_start);
    out.extend(IDENTIFIER);
    let bpc_type_size = bpc;
    for v in [
        vk_format,
        bpc_type_size,
        base,
        base,
        0,
        0,
        6,
        levels as u32,
        0,
    ] {
        out.extend(v.to_le_bytes());
    }
    for v in [
        dfd_off as u32,
        dfd.len() as u32,
        kvd_off as u32,
        kvd.len() as u32,
    ] {
        out.extend(v.to_le_bytes());
    }
    out.extend(0u64.to_le_bytes());
    out.extend(0u64.to_le_bytes());
    for l in 0..levels {
        let len = level_bytes[l].len() as u64;
        out.extend((offsets[l] as u64).to_le_bytes());
        out.extend(len.to_le_bytes());
        out.extend(len.to_le_bytes());
    }
    out.extend(&dfd);
    out.extend(&kvd);
    for l in (0..levels).rev() {
        out.resize(offsets[l], 0);
        out.extend(&level_bytes[l]);
    }
    out
}

fn u32_at(b: &[u8], o: usize) -> Option<u32> {
    b.get(o..o + 4)
        .map(|s| u32::from_le_bytes(s.try_into().unwrap()))
}
fn u64_at(b: &[u8], o: usize) -> Option<u64> {
    b.get(o..o + 8)
        .map(|s| u64::from_le_bytes(s.try_into().unwrap()))
}

/// Decodes an uncompressed float KTX2 cubemap with all its levels.
pub fn decode_cube(path: &Path, b: &[u8]) -> Result<CubeMips> {
    let bad = |why: &str| Error::invalid(path, format!("not a valid KTX2 cubemap: {why}"));
    if b.len() < HEADER_LEN || b[..12] != IDENTIFIER {
        return Err(bad("bad identifier or truncated header"));
    }
    let h = |k: usize| u32_at(b, 12 + 4 * k).unwrap();
    let (vk_format, width, height, depth, layers, faces, levels, scheme) =
        (h(0), h(2), h(3), h(4), h(5), h(6), h(7), h(8));
    if scheme != 0 {
        return Err(Error::unsupported(path, "supercompressed KTX2"));
    }
    if faces != 6 || depth != 0 || layers > 1 || width != height {
        return Err(Error::unsupported(path, format!("KTX2 with {faces} faces, {width}x{height}x{depth}, {layers} layers (need one square cubemap)")));
    }
    let (channels, bpc) = match vk_format {
        VK_FORMAT_R16G16B16A16_SFLOAT => (4usize, 2usize),
        VK_FORMAT_R32G32B32A32_SFLOAT => (4, 4),
        VK_FORMAT_R32G32B32_SFLOAT => (3, 4),
        f => {
            return Err(Error::unsupported(
                path,
                format!("KTX2 vkFormat {f} (need RGBA16F, RGBA32F or RGB32F)"),
            ))
        }
    };
    Image::check_size(path, width as u64, height as u64 * 6)?;
    let levels = levels.max(1) as usize;
    if levels > 32 {
        return Err(bad("more than 32 levels"));
    }
    let mut out = Vec::with_capacity(levels);
    for l in 0..levels {
        let o = HEADER_LEN + 24 * l;
        let (off, len) = (
            u64_at(b, o).ok_or_else(|| bad("truncated level index"))?,
            u64_at(b, o + 8).ok_or_else(|| bad("truncated level index"))?,
        );
        let size = ((width as usize) >> l).max(1);
        let expect = size * size * 6 * channels * bpc;
        if len as usize != expect {
            return Err(bad(&format!(
                "level {l} holds {len} bytes, expected {expect}"
            )));
        }
        let data = b
            .get(off as usize..(off as usize).saturating_add(expect))
            .ok_or_else(|| bad(&format!("level {l} lies past the end of the file")))?;
        let mut cube = Cubemap::new(size);
        for (fi, face) in cube.faces.iter_mut().enumerate() {
            let fb =
                &data[fi * size * size * channels * bpc..(fi + 1) * size * size * channels * bpc];
            for (t, px) in face
                .data
                .chunks_exact_mut(3)
                .zip(fb.chunks_exact(channels * bpc))
            {
                for k in 0..3 {
                    let s = &px[k * bpc..(k + 1) * bpc];
                    t[k] = if bpc == 2 {
                        half::f16::from_le_bytes([s[0], s[1]]).to_f32()
                    } else {
                        f32::from_le_bytes(s.try_into().unwrap())
                    };
                }
            }
        }
        out.push(cube);
    }
    Ok(CubeMips { levels: out })
}

#[cfg(test)]
mod tests {
    use super::*;

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
    fn truncated_or_garbled_ktx2_is_an_error() {
        let bytes = encode_cube(&chain(), FloatDepth::F32);
        for cut in [0, 11, 79, 100, bytes.len() - 1] {
            assert!(decode_cube(Path::new("c.ktx2"), &bytes[..cut]).is_err());
        }
        let mut b = bytes.clone();
        b[12 + 4 * 6] = 1;
        assert!(decode_cube(Path::new("c.ktx2"), &b).is_err());
    }
}
