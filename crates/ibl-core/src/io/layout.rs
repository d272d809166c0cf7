//! The container types every container module shares: the [`Layout`] flag, the [`Codec`]
//! trait each single-file container implements and its key/value [`Metadata`]. Kept below
//! `container` (which registers each codec in `Layout::codec`) and the codec modules (`ktx2`,
//! `dds`, `ktx1`), so neither needs the other: the module graph stays acyclic.

use super::texture::Payload;
use crate::error::Result;
use std::path::Path;

/// Key/value metadata of KTX1 and KTX2 files: (key, value bytes) pairs.
pub type Metadata = Vec<(String, Vec<u8>)>;

/// Output container for cubemaps.
#[derive(
    Clone,
    Copy,
    Debug,
    PartialEq,
    Eq,
    Default,
    serde::Serialize,
    serde::Deserialize,
    clap::ValueEnum,
)]
#[serde(rename_all = "kebab-case")]
pub enum Layout {
    /// One EXR per face (`px.exr` … or `m{l}_px.exr` … for chains).
    #[default]
    Faces,
    /// One KTX2 file with all faces and levels.
    Ktx2,
    /// One DDS file (DX10 header, cubemap flags) with all faces and levels.
    Dds,
    /// One KTX 1.1 file with all faces and levels (what Filament's cmgen writes).
    Ktx1,
}

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
