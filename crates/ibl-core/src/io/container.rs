//! Single-file texture containers: which one a file is (by its magic bytes, whatever its
//! name), and reading any of them into a [`Payload`] with its key/value metadata.

use super::texture::Payload;
use crate::error::Result;
use std::path::Path;

/// A single-file GPU texture container.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Container {
    /// KTX 2.0 (Khronos), optionally zstd supercompressed.
    Ktx2,
    /// KTX 1.1 (Khronos).
    Ktx1,
    /// DirectDraw Surface with the DX10 header.
    Dds,
}

impl Container {
    /// The container `bytes` start like, if any.
    pub(crate) fn sniff(bytes: &[u8]) -> Option<Container> {
        if bytes.starts_with(&super::ktx2::IDENTIFIER) {
            Some(Container::Ktx2)
        } else if bytes.starts_with(&super::ktx1::IDENTIFIER) {
            Some(Container::Ktx1)
        } else if bytes.starts_with(b"DDS ") {
            Some(Container::Dds)
        } else {
            None
        }
    }

    /// Whether a file name's extension names a container (`.ktx2`, `.ktx`, `.dds`).
    pub(crate) fn from_extension(path: &Path) -> Option<Container> {
        match super::extension(path).as_str() {
            "ktx2" => Some(Container::Ktx2),
            "ktx" => Some(Container::Ktx1),
            "dds" => Some(Container::Dds),
            _ => None,
        }
    }
}

/// A texture read from a container.
#[derive(Clone, Debug)]
pub struct Texture {
    /// The container the texture was read from.
    pub container: Container,
    /// The encoded levels and their pixel format.
    pub payload: Payload,
    /// Key/value metadata (KTX1 and KTX2; empty for DDS).
    pub metadata: Vec<(String, Vec<u8>)>,
}

/// Parses `bytes` as the container its magic says; `None` if it is none of them.
pub fn read(path: &Path, bytes: &[u8]) -> Result<Option<Texture>> {
    let Some(container) = Container::sniff(bytes) else {
        return Ok(None);
    };
    let (payload, metadata) = match container {
        Container::Ktx2 => super::ktx2::decode(path, bytes)?,
        Container::Ktx1 => super::ktx1::decode(path, bytes)?,
        Container::Dds => (super::dds::decode(path, bytes)?, Vec::new()),
    };
    payload.check(path)?;
    Ok(Some(Texture {
        container,
        payload,
        metadata,
    }))
}
