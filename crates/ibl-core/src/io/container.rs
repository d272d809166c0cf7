//! Single-file texture containers: the [`Codec`] each one's module implements (its extension,
//! its magic bytes, how a whole chain is framed and read back), which one a file is (by its
//! magic bytes, whatever its name), and reading any of them into a [`Payload`] with its
//! key/value metadata.
//!
//! A new container is one module under `io/` implementing [`Codec`], registered by a
//! `Layout` variant (`io::layout`) and its arm in `Layout::codec` (here): the flag value, the RON
//! key, file names, stale-file removal, sniffing and reading follow.

use super::texture::Payload;
use crate::error::Result;
use std::path::{Path, PathBuf};

/// A single-file GPU texture container: the layouts that are one file (`Layout::Faces` is not).
pub use super::layout::Layout as Container;
use super::layout::Layout;
pub use super::layout::{Codec, Metadata};

impl Container {
    /// Every layout, in declaration order (clap's list of `--layout` values).
    pub fn all() -> &'static [Layout] {
        <Layout as clap::ValueEnum>::value_variants()
    }

    /// The codec of a single-file container, `None` for face files: the one place a container
    /// is registered.
    pub fn codec(self) -> Option<&'static dyn Codec> {
        match self {
            Layout::Faces => None,
            Layout::Ktx2 => Some(&super::ktx2::Ktx2),
            Layout::Dds => Some(&super::dds::Dds),
            Layout::Ktx1 => Some(&super::ktx1::Ktx1),
        }
    }

    /// File extension of a single-file container, `None` for face files.
    pub fn extension(self) -> Option<&'static str> {
        self.codec().map(|c| c.extension())
    }

    /// `dir/<name>.<ext>` for a single-file container, `None` for face files.
    pub fn container_path(self, dir: &Path, name: &str) -> Option<PathBuf> {
        self.extension().map(|e| dir.join(format!("{name}.{e}")))
    }

    /// The name flags and RON keys use.
    pub fn name(self) -> &'static str {
        self.codec().map_or("faces", |c| c.name())
    }

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
