//! DDS framing of a [`Payload`] (Microsoft "Programming Guide for DDS"): the DX10 extended
//! header with a DXGI format, a cube as six faces (+X −X +Y −Y +Z −Z) each followed by its
//! mips, as Direct3D, Unity and Unreal load it. The reader also takes the legacy FourCC float
//! formats (D3DFMT_A16B16G16R16F = 113, D3DFMT_A32B32G32R32F = 116) older tools write.

use super::format::PixelFormat;
use super::texture::{self, Payload};
use crate::error::{Error, Result};
use std::path::Path;

const MAGIC: &[u8; 4] = b"DDS ";
const HEADER_LEN: usize = 4 + 124;
const DX10_LEN: usize = 20;
// DDS_HEADER dwFlags.
const DDSD_CAPS: u32 = 0x1;
const DDSD_HEIGHT: u32 = 0x2;
const DDSD_WIDTH: u32 = 0x4;
const DDSD_PITCH: u32 = 0x8;
const DDSD_PIXELFORMAT: u32 = 0x1000;
const DDSD_MIPMAPCOUNT: u32 = 0x2_0000;
const DDSD_LINEARSIZE: u32 = 0x8_0000;
// DDS_PIXELFORMAT dwFlags.
const DDPF_FOURCC: u32 = 0x4;
// dwCaps, dwCaps2.
const DDSCAPS_COMPLEX: u32 = 0x8;
const DDSCAPS_TEXTURE: u32 = 0x1000;
const DDSCAPS_MIPMAP: u32 = 0x40_0000;
const DDSCAPS2_CUBEMAP: u32 = 0x200;
const DDSCAPS2_CUBEMAP_ALLFACES: u32 = 0xFC00;
// DDS_HEADER_DXT10.
const D3D10_RESOURCE_DIMENSION_TEXTURE2D: u32 = 3;
const DDS_RESOURCE_MISC_TEXTURECUBE: u32 = 0x4;
const D3DFMT_A16B16G16R16F: u32 = 113;
const D3DFMT_A32B32G32R32F: u32 = 116;

/// Frames a payload as DDS with a DX10 header.
pub fn encode(p: &Payload) -> Vec<u8> {
    let levels = p.levels.len() as u32;
    let cube = p.faces == 6;
    let block = p.format.block_dim() > 1;
    let mut flags = DDSD_CAPS | DDSD_HEIGHT | DDSD_WIDTH | DDSD_PIXELFORMAT | DDSD_MIPMAPCOUNT;
    let pitch_or_size = if block {
        flags |= DDSD_LINEARSIZE;
        p.face_bytes(0)
    } else {
        flags |= DDSD_PITCH;
        p.width * p.format.block_bytes()
    };
    let mut caps = DDSCAPS_TEXTURE;
    if levels > 1 {
        caps |= DDSCAPS_COMPLEX | DDSCAPS_MIPMAP;
    }
    let mut caps2 = 0;
    if cube {
        caps |= DDSCAPS_COMPLEX;
        caps2 = DDSCAPS2_CUBEMAP | DDSCAPS2_CUBEMAP_ALLFACES;
    }
    let mut out = Vec::new();
    out.extend(MAGIC);
    let mut header = vec![
        124,
        flags,
        p.height as u32,
        p.width as u32,
        pitch_or_size as u32,
        0,
        levels,
    ];
    header.extend([0u32; 11]); // dwReserved1
    header.extend([32, DDPF_FOURCC, u32::from_le_bytes(*b"DX10"), 0, 0, 0, 0, 0]);
    header.extend([caps, caps2, 0, 0, 0]);
    for v in header {
        out.extend(v.to_le_bytes());
    }
    let misc = if cube {
        DDS_RESOURCE_MISC_TEXTURECUBE
    } else {
        0
    };
    for v in [
        p.format.codes().dxgi,
        D3D10_RESOURCE_DIMENSION_TEXTURE2D,
        misc,
        1,
        0,
    ] {
        out.extend(v.to_le_bytes());
    }
    for f in 0..p.faces {
        for level in &p.levels {
            out.extend(&level[f]);
        }
    }
    out
}

/// Parses a DDS file (cube or 2D, DX10 or legacy float FourCC) into its payload.
pub fn decode(path: &Path, b: &[u8]) -> Result<Payload> {
    let bad = |why: String| Error::invalid(path, format!("not a valid DDS file: {why}"));
    if b.len() < HEADER_LEN || &b[..4] != MAGIC {
        return Err(bad("bad magic or truncated header".into()));
    }
    let h = |k: usize| super::ktx2::u32_at(b, 4 + 4 * k).expect("header is 128 bytes");
    if h(0) != 124 || h(18) != 32 {
        return Err(bad(format!(
            "header sizes {} and {} (need 124 and 32)",
            h(0),
            h(18)
        )));
    }
    let (flags, height, width, mips) = (h(1), h(2), h(3), h(6));
    let (pf_flags, four_cc) = (h(19), h(20));
    let (caps2, depth) = (h(27), h(5));
    let levels = if flags & DDSD_MIPMAPCOUNT != 0 {
        mips.max(1)
    } else {
        1
    };
    let mut data_off = HEADER_LEN;
    let (format, cube) = if pf_flags & DDPF_FOURCC != 0 && four_cc == u32::from_le_bytes(*b"DX10") {
        let d = |k: usize| {
            super::ktx2::u32_at(b, HEADER_LEN + 4 * k)
                .ok_or_else(|| bad("truncated DX10 header".into()))
        };
        let (dxgi, dim, misc, array) = (d(0)?, d(1)?, d(2)?, d(3)?);
        data_off += DX10_LEN;
        if dim != D3D10_RESOURCE_DIMENSION_TEXTURE2D || array > 1 {
            return Err(Error::unsupported(
                path,
                format!("DDS resource dimension {dim} with {array} array elements (need one 2D texture or cube)"),
            ));
        }
        let format = PixelFormat::from_dxgi(dxgi).ok_or_else(|| {
            Error::unsupported(
                path,
                format!("DDS DXGI format {dxgi} (read: 2 RGBA32F, 10 RGBA16F, 67 R9G9B9E5, 26 R11G11B10F, 95 BC6H_UF16)"),
            )
        })?;
        (format, misc & DDS_RESOURCE_MISC_TEXTURECUBE != 0)
    } else if pf_flags & DDPF_FOURCC != 0 && four_cc == D3DFMT_A16B16G16R16F {
        (PixelFormat::Rgba16f, caps2 & DDSCAPS2_CUBEMAP != 0)
    } else if pf_flags & DDPF_FOURCC != 0 && four_cc == D3DFMT_A32B32G32R32F {
        (PixelFormat::Rgba32f, caps2 & DDSCAPS2_CUBEMAP != 0)
    } else {
        return Err(Error::unsupported(
            path,
            "DDS pixel format (read: DX10 headers, and FourCC 113/116 half and float RGBA)",
        ));
    };
    if cube
        && caps2 & DDSCAPS2_CUBEMAP != 0
        && caps2 & DDSCAPS2_CUBEMAP_ALLFACES != DDSCAPS2_CUBEMAP_ALLFACES
    {
        return Err(Error::unsupported(
            path,
            "DDS cube map without all six faces",
        ));
    }
    let (height, levels) = texture::check_shape(
        path,
        "DDS",
        if cube { 6 } else { 1 },
        width,
        height,
        depth,
        1,
        levels,
    )?;
    let faces: usize = if cube { 6 } else { 1 };
    let mut p = Payload {
        format,
        width: width as usize,
        height: height as usize,
        faces,
        levels: vec![Vec::with_capacity(faces); levels as usize],
    };
    let total: usize = (0..levels as usize).map(|l| p.face_bytes(l)).sum::<usize>() * faces;
    if b.len() < data_off + total {
        return Err(bad(format!(
            "{} bytes of texel data, the header needs {total}",
            b.len() - data_off
        )));
    }
    let _budget = p.reserve(path, "DDS", levels as usize)?;
    let mut o = data_off;
    for _ in 0..faces {
        for l in 0..levels as usize {
            let n = p.face_bytes(l);
            p.levels[l].push(b[o..o + n].to_vec());
            o += n;
        }
    }
    Ok(p)
}

/// DDS as a [`super::layout::Codec`] (it has no key/value metadata: none is written or read).
pub struct Dds;

impl super::layout::Codec for Dds {
    fn name(&self) -> &'static str {
        "dds"
    }
    fn extension(&self) -> &'static str {
        "dds"
    }
    fn magic(&self) -> &'static [u8] {
        MAGIC
    }
    fn encode(
        &self,
        p: &Payload,
        _zstd: Option<i32>,
        _metadata: &[(String, Vec<u8>)],
    ) -> Result<Vec<u8>> {
        Ok(encode(p))
    }
    fn decode(&self, path: &Path, bytes: &[u8]) -> Result<(Payload, super::layout::Metadata)> {
        Ok((decode(path, bytes)?, Vec::new()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::format::Bc6hQuality;
    use crate::io::texture::encode_chain;
    use crate::{CubeMips, Cubemap};

    fn payload(format: PixelFormat) -> Payload {
        let base = Cubemap::from_fn(8, |d| [d.x.abs() + 0.1, d.y.abs(), 2.0 * d.z.abs()]);
        encode_chain(&CubeMips::build(base, 1), format, Bc6hQuality::Fast).0
    }

    #[test]
    fn round_trips_every_format() {
        for f in PixelFormat::ALL {
            let p = payload(f);
            assert_eq!(decode(Path::new("c.dds"), &encode(&p)).unwrap(), p);
        }
    }

    #[test]
    fn an_independent_reader_parses_our_headers() {
        // ddsfile (used by intel_tex_2's own examples) reads what Direct3D tools write.
        let p = payload(PixelFormat::Bc6h);
        let dds = ddsfile::Dds::read(&mut std::io::Cursor::new(encode(&p))).unwrap();
        assert_eq!(dds.get_dxgi_format(), Some(ddsfile::DxgiFormat::BC6H_UF16));
        assert_eq!(dds.get_num_mipmap_levels(), 4);
        assert_eq!((dds.get_width(), dds.get_height()), (8, 8));
        assert!(dds
            .header10
            .unwrap()
            .misc_flag
            .contains(ddsfile::MiscFlag::TEXTURECUBE));
        assert!(dds.header.caps2.contains(ddsfile::Caps2::CUBEMAP));
        // Six faces of 4 levels of 4x4 blocks: 4 + 1 + 1 + 1 blocks of 16 bytes each.
        assert_eq!(dds.data.len(), 6 * 7 * 16);
    }

    #[test]
    fn truncated_and_garbled_files_are_errors() {
        let b = encode(&payload(PixelFormat::Rgb9e5));
        for cut in [0, 3, 100, HEADER_LEN + 5, b.len() - 1] {
            assert!(decode(Path::new("c.dds"), &b[..cut]).is_err(), "cut {cut}");
        }
        let mut bad = b.clone();
        bad[HEADER_LEN..HEADER_LEN + 4].copy_from_slice(&77u32.to_le_bytes()); // unknown DXGI
        assert!(matches!(
            decode(Path::new("c.dds"), &bad),
            Err(Error::Unsupported { .. })
        ));
        let mut bad = b.clone();
        bad[4 + 4 * 6..4 + 4 * 7].copy_from_slice(&40u32.to_le_bytes()); // 40 mips of 8x8
        assert!(decode(Path::new("c.dds"), &bad).is_err());
        let mut bad = b;
        bad[12..20].copy_from_slice(&[0xff; 8]); // 4G x 4G
        assert!(decode(Path::new("c.dds"), &bad).is_err());
    }
}
