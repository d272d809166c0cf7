//! Finding and reading what a bake wrote: an environment cube, a prefiltered chain (with
//! `prefilter.json`'s roughness per level), an irradiance cube (beside `sh.json`) or a 2D LUT.

use ibl_core::envmap::read_cube_chain;
use ibl_core::io::{self, ColorSpace};
use ibl_core::{CubeMips, Cubemap, Error, Image, Result};
use std::path::{Path, PathBuf};

/// One baked output, read.
#[derive(Clone, Debug)]
pub enum Asset {
    /// A single cube (equirect-to-cube's faces or container).
    Environment {
        /// The file or folder read.
        path: PathBuf,
        /// The cube.
        cube: Cubemap,
    },
    /// A mip chain and the roughness of each level (from `prefilter.json`, when present).
    Prefiltered {
        /// The file or folder read.
        path: PathBuf,
        /// The chain, mirror level first.
        mips: CubeMips,
        /// Perceptual roughness per level, from `prefilter.json`.
        roughness: Option<Vec<f32>>,
    },
    /// The E/π irradiance cube.
    Irradiance {
        /// The file or folder read.
        path: PathBuf,
        /// The E/π cube.
        cube: Cubemap,
    },
    /// A 2D table (the DFG LUT: R = A, G = B), shown as stored.
    Lut {
        /// The file read.
        path: PathBuf,
        /// The table as stored.
        image: Image,
    },
}

impl Asset {
    /// Row order on the sheet: the environment first, then what is baked from it.
    fn rank(&self) -> usize {
        match self {
            Asset::Environment { .. } => 0,
            Asset::Prefiltered { .. } => 1,
            Asset::Irradiance { .. } => 2,
            Asset::Lut { .. } => 3,
        }
    }
}

const FACE_STEMS: [&str; 2] = ["px", "m0_px"];
const CONTAINERS: [&str; 3] = ["ktx2", "ktx", "dds"];
const IMAGES: [&str; 4] = ["exr", "hdr", "png", "jpg"];

fn entries(dir: &Path) -> Result<Vec<PathBuf>> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .map_err(|e| Error::io(dir, e))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            // Hidden entries are a bake's cache (.bake) or temporary files of atomic writes.
            !p.file_name()
                .and_then(|n| n.to_str())
                .is_some_and(|n| n.starts_with('.'))
        })
        .collect();
    v.sort();
    Ok(v)
}

fn stem(p: &Path) -> &str {
    p.file_stem().and_then(|s| s.to_str()).unwrap_or("")
}

/// Reads `prefilter.json`'s `level[].roughness`.
fn level_roughness(json: &Path, levels: usize) -> Result<Vec<f32>> {
    let v: serde_json::Value = io::data::read(json)?;
    let r: Option<Vec<f32>> = v.get("level").and_then(|l| l.as_array()).and_then(|l| {
        l.iter()
            .map(|e| e.get("roughness")?.as_f64().map(|r| r as f32))
            .collect()
    });
    match r {
        Some(r) if r.len() == levels => Ok(r),
        Some(r) => Err(Error::invalid(
            json,
            format!(
                "lists {} levels but the chain beside it has {levels}",
                r.len()
            ),
        )),
        None => Err(Error::invalid(json, "no level[].roughness")),
    }
}

/// Reads a cube chain from a folder of faces or a container and sorts it by what sits
/// beside it: `prefilter.json` (or more than one level) → prefiltered, `sh.json` → irradiance.
fn cube_asset(source: &Path, dir: &Path) -> Result<Asset> {
    let mips = read_cube_chain(source)?;
    let json = dir.join("prefilter.json");
    let path = source.to_path_buf();
    if json.is_file() || mips.levels.len() > 1 {
        let roughness = if json.is_file() {
            Some(level_roughness(&json, mips.levels.len())?)
        } else {
            None
        };
        return Ok(Asset::Prefiltered {
            path,
            mips,
            roughness,
        });
    }
    let cube = mips.levels.into_iter().next().expect("a chain has a level");
    if dir.join("sh.json").is_file() {
        Ok(Asset::Irradiance { path, cube })
    } else {
        Ok(Asset::Environment { path, cube })
    }
}

/// What one folder holds directly (not its subfolders).
fn folder_assets(dir: &Path) -> Result<Vec<Asset>> {
    let files = entries(dir)?;
    let ext = |p: &Path| io::extension(p);
    if files
        .iter()
        .any(|p| FACE_STEMS.contains(&stem(p)) && IMAGES.contains(&ext(p).as_str()))
    {
        return Ok(vec![cube_asset(dir, dir)?]);
    }
    let mut out = Vec::new();
    for p in files.iter().filter(|p| p.is_file()) {
        if CONTAINERS.contains(&ext(p).as_str()) {
            out.push(cube_asset(p, dir)?);
        } else if IMAGES.contains(&ext(p).as_str()) {
            // Tables are square; anything else (a contact sheet written here) is not an asset.
            let image = io::read_image(p, ColorSpace::Linear)?;
            if image.width == image.height {
                out.push(Asset::Lut {
                    path: p.clone(),
                    image,
                });
            }
        }
    }
    Ok(out)
}

/// Everything to show for one command-line input: a container or image file, a bake's
/// output folder, or a pipeline's output root (each subfolder read in turn; subfolders
/// holding no image, such as shexp/, are skipped). Rows come sorted environment first.
pub fn discover(input: &Path) -> Result<Vec<Asset>> {
    let meta = std::fs::metadata(input).map_err(|e| Error::io(input, e))?;
    let mut assets = if meta.is_file() {
        let dir = input.parent().unwrap_or(Path::new("."));
        if CONTAINERS.contains(&io::extension(input).as_str()) {
            vec![cube_asset(input, dir)?]
        } else {
            let image = io::read_image(input, ColorSpace::Linear)?;
            if image.width == image.height {
                vec![Asset::Lut {
                    path: input.to_path_buf(),
                    image,
                }]
            } else {
                vec![cube_asset(input, dir)?]
            }
        }
    } else {
        // A folder with subfolders is a pipeline's output root: its loose files (a sheet
        // written there) are not read.
        let subs: Vec<PathBuf> = entries(input)?.into_iter().filter(|p| p.is_dir()).collect();
        if subs.is_empty() {
            folder_assets(input)?
        } else {
            let mut all = Vec::new();
            for sub in &subs {
                all.extend(folder_assets(sub)?);
            }
            all
        }
    };
    if assets.is_empty() {
        return Err(Error::invalid(
            input,
            "holds no cube, prefiltered chain, irradiance cube or LUT (expected faces px… or m0_px…, a .ktx2/.ktx/.dds, or an image)",
        ));
    }
    assets.sort_by_key(Asset::rank);
    Ok(assets)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn roughness_count_must_match_the_chain() {
        let dir = tempfile::tempdir().unwrap();
        let json = dir.path().join("prefilter.json");
        std::fs::write(&json, r#"{"level":[{"roughness":0.0},{"roughness":0.5}]}"#).unwrap();
        assert_eq!(level_roughness(&json, 2).unwrap(), vec![0.0, 0.5]);
        let e = level_roughness(&json, 3).unwrap_err().to_string();
        assert!(
            e.contains("2 levels") && e.contains("prefilter.json"),
            "{e}"
        );
        std::fs::write(&json, r#"{"level":[{"size":4}]}"#).unwrap();
        assert!(level_roughness(&json, 1).is_err());
        std::fs::write(&json, "{garbled").unwrap();
        assert!(level_roughness(&json, 1).is_err());
    }

    #[test]
    fn an_empty_or_missing_folder_is_an_error() {
        let dir = tempfile::tempdir().unwrap();
        assert!(discover(dir.path()).is_err());
        assert!(discover(&dir.path().join("missing")).is_err());
    }
}
