//! The `equirect-to-cube` bake: an environment (equirect, cross, strip, faces or KTX2) to an
//! area-filtered cubemap of any face size, and the inverse to an equirect for previews.

use ibl_core::envmap::{self, Environment, Layout, LoadedEnvironment};
use ibl_core::equirect::{self, Filter};
use ibl_core::io::{self, FloatDepth, WriteOptions};
use ibl_core::progress::Progress;
use ibl_core::{CubeMips, Error, Result};
use std::path::{Path, PathBuf};

/// Parameters of the bake: CLI flags and RON keys alike.
#[derive(Clone, Debug, PartialEq, clap::Args, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Params {
    /// Face size in texels (default: the largest power of two not above width/4).
    #[arg(long, value_name = "N")]
    pub size: Option<usize>,
    /// Turn the environment about +Y by this many degrees first.
    #[arg(
        long,
        value_name = "DEG",
        default_value_t = 0.0,
        allow_negative_numbers = true
    )]
    pub rotate: f32,
    /// Output container: one EXR per face or one KTX2 file.
    #[arg(long, value_enum, default_value_t = Layout::Faces)]
    pub layout: Layout,
    /// Write 16-bit half floats instead of 32-bit.
    #[arg(long)]
    pub half: bool,
    /// Resampling filter: exact footprint mean (area) or one bilinear tap.
    #[arg(long, value_enum, default_value_t = Filter::Area)]
    pub filter: Filter,
    /// Write an equirect image instead (W×H = 4n×2n of the input cube's face size, or --size×2 by --size).
    #[arg(long)]
    pub to_equirect: bool,
    /// Set NaN/Inf input texels to 0 instead of refusing the input.
    #[arg(long)]
    pub sanitize: bool,
}

impl Default for Params {
    fn default() -> Self {
        ibl_core::params::clap_defaults()
    }
}

/// Largest face accepted: 6·n² texels must fit the image limit (`ibl_core::image::MAX_TEXELS`,
/// 2^28) so that a KTX2 cube of that size can be read back (⌊√(2^28/6)⌋ = 6688).
pub const MAX_FACE_SIZE: usize = 6688;

impl Params {
    pub fn validate(&self) -> Result<()> {
        if let Some(n) = self.size {
            if n == 0 || n > MAX_FACE_SIZE {
                return Err(Error::param(format!(
                    "--size {n} is out of range 1..={MAX_FACE_SIZE} (six faces of n² texels \
                     must stay within the 2^28-texel image limit, so that the cube can be read \
                     back, e.g. from a KTX2 file)"
                )));
            }
        }
        ibl_core::params::check_rotate(self.rotate)?;
        Ok(())
    }
}

/// What the bake produced, before anything is written.
pub struct Baked {
    /// Encoded files, ready for [`io::write_many_atomic`].
    pub files: Vec<(PathBuf, Vec<u8>)>,
    pub face_size: usize,
    /// What the user should know (a face size above the source's resolution).
    pub warnings: Vec<String>,
}

/// The face size that holds the source's detail: a face spans a quarter of an equirect's
/// width (90°); a cube's own faces. Not rounded to a power of two, unlike
/// [`Environment::natural_face_size`].
fn source_face_texels(env: &Environment) -> f64 {
    match env {
        Environment::Equirect(img) => img.width as f64 / 4.0,
        Environment::Cube(c) => c.size as f64,
    }
}

/// A warning when face size `n` upsamples the source: the bake then costs n² per face and adds
/// no detail (`prefilter` warns the same way).
pub fn upsampling_warning(input: &LoadedEnvironment, n: usize) -> Option<String> {
    let have = source_face_texels(&input.env);
    (n as f64 > have * 1.001).then(|| {
        let what = match &input.env {
            Environment::Equirect(img) => format!("a {}×{} equirect", img.width, img.height),
            Environment::Cube(c) => format!("a cube of {0}×{0} faces", c.size),
        };
        format!(
            "{}: face size {n} upsamples {what} (about {:.0} texels per face) {:.1}×: no detail \
             is added; omit --size for the source's own size",
            input.path.display(),
            have,
            n as f64 / have
        )
    })
}

/// Resamples a loaded environment to a cube (or an equirect with `to_equirect`) and encodes
/// the outputs for `out_dir` (or the output file for equirect).
pub fn run(
    params: &Params,
    input: &LoadedEnvironment,
    out: &Path,
    progress: &dyn Progress,
) -> Result<Baked> {
    params.validate()?;
    let depth = FloatDepth::from_half(params.half);
    if params.to_equirect {
        // --rotate turns the environment before any bake (docs/CONVENTIONS.md), this one included.
        let base = match &input.env {
            Environment::Cube(c) if params.rotate == 0.0 => c.clone(),
            _ => input.env.to_cube(
                input.env.natural_face_size(),
                Filter::Area,
                params.rotate,
                progress,
            ),
        };
        let w = params.size.map(|s| 2 * s).unwrap_or(4 * base.size);
        let img = equirect::cube_to_equirect(&base, w, w / 2, params.filter);
        let path = if io::extension(out).is_empty() {
            out.join("equirect.exr")
        } else {
            out.to_path_buf()
        };
        let bytes = io::encode_image(
            &path,
            &img,
            &WriteOptions {
                float: depth,
                png_tonemap: true,
                ..Default::default()
            },
        )?;
        return Ok(Baked {
            files: vec![(path, bytes)],
            face_size: base.size,
            warnings: Vec::new(),
        });
    }
    let n = params.size.unwrap_or_else(|| input.env.natural_face_size());
    let cube = input.env.to_cube(n, params.filter, params.rotate, progress);
    let files = envmap::encode_cube_outputs(
        out,
        &CubeMips { levels: vec![cube] },
        params.layout,
        depth,
        "cube",
    )?;
    Ok(Baked {
        files,
        face_size: n,
        warnings: upsampling_warning(input, n).into_iter().collect(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_largest_face_fits_the_image_limit_and_one_more_does_not() {
        let texels = |n: usize| 6 * (n as u64) * (n as u64);
        assert!(texels(MAX_FACE_SIZE) <= ibl_core::image::MAX_TEXELS);
        assert!(texels(MAX_FACE_SIZE + 1) > ibl_core::image::MAX_TEXELS);
    }

    #[test]
    fn defaults_agree_between_clap_serde_and_default() {
        let from_ron: Params = ron_from_str("()");
        assert_eq!(from_ron, Params::default());
        assert_eq!(Params::default().size, None);
        assert_eq!(Params::default().layout, Layout::Faces);
    }

    fn ron_from_str(s: &str) -> Params {
        ron::from_str(s).unwrap()
    }

    #[test]
    fn unknown_keys_are_refused() {
        assert!(ron::from_str::<Params>("(sise: 4)").is_err());
    }

    #[test]
    fn out_of_range_size_is_refused() {
        let p = Params {
            size: Some(0),
            ..Default::default()
        };
        assert!(p.validate().is_err());
    }
}
