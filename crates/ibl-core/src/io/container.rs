//! Single-file texture containers: the [`Codec`] each one's module implements (its extension,
//! its magic bytes, how a whole chain is framed and read back), which one a file is (by its
//! magic bytes, whatever its name), and reading any of them into a [`Payload`] with its
//! key/value metadata.
//!
//! A new container is one module under `io/` implementing [`Codec`], registered by a
//! `Layout` variant and its arm in `Layout::codec` (`crate::output`): the flag value, the RON
//! key, file names, stale-file removal, sniffing and reading follow.

use super::ktx2::Metadata;
use super::texture::Payload;
use crate::error::Result;
use std::path::Path;

/// A single-file GPU texture container: the layouts that are one file (`Layout::Faces` is not).
pub use crate::output::Layout as Container;

/// What a single-file container is: implemented once, in the container's module.
pub trait Codec: Sync {
    /// The name flags and RON keys use (`--layout ktx1`).
    fn name(&self) -> &'static str;
    /// The file extension, without the dot (`ktx2`).
    fn extension(&self) -> &'static str;
    /// The bytes every file of this container starts with.
    fn magic(&self) -> &'static [u8];
    /// Frames a chain with its key/value `metadata` (where the container has any) and, where
    /// the container supercompresses, `zstd` (validated against the layout beforehand).
    fn encode(
        &self,
        p: &Payload,
        zstd: Option<i32>,
        metadata: &[(String, Vec<u8>)],
    ) -> Result<Vec<u8>>;
    /// Parses a file into its payload and key/value metadata.
    fn decode(&self, path: &Path, bytes: &[u8]) -> Result<(Payload, Metadata)>;
}

impl Container {
    /// The container `bytes` start like, if any.
    pub(crate) fn sniff(bytes: &[u8]) -> Option<Container> {
        Self::containers()
            .find(|(_, c)| bytes.starts_with(c.magic()))
            .map(|(l, _)| l)
    }

    /// Whether a file name's extension names a container (`.ktx2`, `.ktx`, `.dds`).
    pub(crate) fn from_extension(path: &Path) -> Option<Container> {
        let ext = super::extension(path);
        Self::containers()
            .find(|(_, c)| c.extension() == ext)
            .map(|(l, _)| l)
    }

    /// Every single-file layout with its codec.
    fn containers() -> impl Iterator<Item = (Container, &'static dyn Codec)> {
        Self::all().iter().filter_map(|&l| Some((l, l.codec()?)))
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
    let codec = container.codec().expect("a sniffed container has a codec");
    let (payload, metadata) = codec.decode(path, bytes)?;
    payload.check(path)?;
    Ok(Some(Texture {
        container,
        payload,
        metadata,
    }))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cube::{CubeMips, Cubemap};
    use crate::io::format::{Bc6hQuality, PixelFormat};

    #[test]
    fn every_registered_container_is_named_sniffed_and_read_back() {
        let cube = Cubemap::from_fn(4, |d| [d.x.abs(), d.y.abs(), d.z.abs()]);
        let (payload, _) = crate::io::texture::encode_chain(
            &CubeMips { levels: vec![cube] },
            PixelFormat::Rgba16f,
            Bc6hQuality::default(),
        );
        let mut extensions = Vec::new();
        for &layout in Container::all() {
            // The name the flag, the RON key and `name()` use is one.
            let flag = clap::ValueEnum::to_possible_value(&layout).unwrap();
            assert_eq!(flag.get_name(), layout.name());
            assert_eq!(serde_json::to_value(layout).unwrap(), layout.name());
            let Some(codec) = layout.codec() else {
                continue;
            };
            extensions.push(codec.extension());
            let path = Path::new("x").with_extension(codec.extension());
            assert_eq!(Container::from_extension(&path), Some(layout));
            let bytes = codec.encode(&payload, None, &[]).unwrap();
            assert_eq!(Container::sniff(&bytes), Some(layout), "{}", layout.name());
            let back = read(&path, &bytes).unwrap().unwrap();
            assert_eq!(back.container, layout);
            assert_eq!(back.payload.levels, payload.levels, "{}", layout.name());
        }
        assert_eq!(extensions, ["ktx2", "dds", "ktx"]);
    }
}
