//! Reading the input maps of the material bakes (normal maps, angle/direction maps,
//! roughness maps): one loader and one map type for all of them. Maps are data: decoded
//! linearly, never as sRGB.

use ibl_core::io::{self, ColorSpace};
use ibl_core::{Error, Image};
use std::path::{Path, PathBuf};

/// An input map as read from disk.
#[derive(Clone, Debug)]
pub struct LoadedMap {
    /// The texels as read (linear; 8-bit PNGs scaled to [0, 1]).
    pub image: Image,
    /// The file was a grey+alpha PNG (the reader expands it to (L, L, L, A)): its two
    /// channels are then L and A (BC5-style normal maps, direction maps saved as LA).
    pub grey_alpha: bool,
    /// The file it was read from.
    pub path: PathBuf,
    /// The one-line warning when the file's content and name disagree (EXR data named
    /// `.png`, ...): it was read by its content ([`io::content_mismatch`]).
    pub read_as: Option<String>,
}

/// PNG colour type from the IHDR chunk (0 grey, 2 RGB, 3 palette, 4 grey+alpha, 6 RGBA).
pub(crate) fn png_color_type(bytes: &[u8]) -> Option<u8> {
    (bytes.len() > 25 && bytes.starts_with(&[0x89, b'P', b'N', b'G']) && &bytes[12..16] == b"IHDR")
        .then(|| bytes[25])
}

/// Reads a map (8/16-bit PNG, JPEG, EXR, HDR) linearly. Texel values are left as stored:
/// what NaN/Inf or negative values mean is the bake's business.
pub fn load(path: &Path) -> ibl_core::Result<LoadedMap> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    let image = io::decode_image(path, &bytes, ColorSpace::Linear)?;
    Ok(LoadedMap {
        image,
        grey_alpha: png_color_type(&bytes) == Some(4),
        path: path.to_path_buf(),
        read_as: io::content_mismatch(path, &bytes),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn png_color_type_is_read_from_ihdr() {
        let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/normals/0008_128.png");
        assert_eq!(png_color_type(&std::fs::read(p).unwrap()), Some(2));
        assert_eq!(png_color_type(b"not a png at all, not at all......"), None);
    }

    #[test]
    fn grey_alpha_pngs_are_flagged_and_missing_files_are_io_errors() {
        let dir = tempfile::tempdir().unwrap();
        let la = dir.path().join("la.png");
        io::write_image(
            &la,
            &Image::from_data(1, 1, 2, vec![0.25, 0.75]).unwrap(),
            &Default::default(),
        )
        .unwrap();
        let m = load(&la).unwrap();
        assert!(m.grey_alpha && m.image.channels == 4 && m.path == la);
        let rgb = load(
            &Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/normals/0008_128.png"),
        )
        .unwrap();
        assert!(!rgb.grey_alpha && rgb.image.channels == 3);
        let e = load(&dir.path().join("missing.png")).err().unwrap();
        assert_eq!(e.class(), ibl_core::error::ErrorClass::Io);
    }
}
