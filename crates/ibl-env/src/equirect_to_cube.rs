//! The `equirect-to-cube` bake: an environment (equirect, cross, strip, faces or KTX2) to an
//! area-filtered cubemap of any face size, and the inverse to an equirect for previews.

#[cfg(test)]
use ibl_core::envmap::Layout;
use ibl_core::envmap::{Environment, LoadedEnvironment, Opened};
use ibl_core::equirect::{self, Filter};
use ibl_core::io::format::PixelFormat;
use ibl_core::io::texture::LevelEncoding;
use ibl_core::io::{self, FloatDepth, WriteOptions};
use ibl_core::output::{self, Encoding};
use ibl_core::progress::Progress;
use ibl_core::{CubeMips, Error, Result};
use std::path::{Path, PathBuf};

ibl_core::cube_output_params! {
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
    /// Resampling filter: adaptive (the footprint mean where shrinking, the bilinear reading
    /// where enlarging, blended between), area (the exact footprint mean of the source read
    /// as piecewise constant) or one bilinear tap.
    #[arg(long, value_enum, default_value_t = Filter::Area)]
    pub filter: Filter,
    /// Write an equirect image instead (W×H = 4n×2n of the input cube's face size, or --size×2 by --size).
    #[arg(long)]
    pub to_equirect: bool,
    /// Set NaN/Inf input texels to 0 instead of refusing the input.
    #[arg(long)]
    pub sanitize: bool,
    /// Negative input texels: clamp them to 0 (saying how much power that adds), keep them
    /// (resampling is linear; rgba32f and EXR outputs keep them, packed formats clamp with a
    /// warning) or refuse the input.
    #[arg(long, value_enum, default_value_t = ibl_core::envmap::Negative::Clamp)]
    pub negative: ibl_core::envmap::Negative,
    /// Engine the cube is made for: its orientation (an exact face permutation with flips).
    #[arg(long, value_enum, default_value_t = ibl_target::Target::Gltf)]
    pub target: ibl_target::Target,
}
}

impl Default for Params {
    fn default() -> Self {
        ibl_core::params::clap_defaults()
    }
}

/// Largest face accepted: 6·n² texels must fit the image limit (`ibl_core::image::MAX_TEXELS`,
/// 2^28) so that a KTX2 cube of that size can be read back (⌊√(2^28/6)⌋ = 6688).
pub(crate) const MAX_FACE_SIZE: usize = 6688;

impl Params {
    /// How the input environment is read (`--sanitize`, `--negative`).
    pub fn env_policy(&self) -> ibl_core::envmap::EnvPolicy {
        ibl_core::envmap::EnvPolicy {
            sanitize: self.sanitize,
            negative: self.negative,
        }
    }

    /// Checks the parameters before any input is read (face size within 1..=MAX_FACE_SIZE, ...).
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
        self.encoding()?;
        Ok(())
    }

    /// The output encoding asked for, checked: the flags over the target's container and
    /// format.
    pub fn encoding(&self) -> Result<Encoding> {
        self.cube_output()
            .resolve(self.target.encoding())
            .and_then(|e| self.target.check_encoding(e))
    }

    /// Name (stem) of the cube's container: `cube`, or the target's file name.
    pub fn cube_name(&self) -> &'static str {
        self.target.spec().files.cube
    }
}

/// What the bake produced, before anything is written.
pub struct Baked {
    /// Encoded files, ready for [`io::write_many_atomic`].
    pub files: Vec<(PathBuf, Vec<u8>)>,
    /// Face size of the cube written (the `--size` given or derived from the source width).
    pub face_size: usize,
    /// What the output encoding cost (one entry for the cube; none for --to-equirect).
    pub encoding: Vec<LevelEncoding>,
    /// What the user should know: a face size above the source's resolution, values the
    /// output format clamped.
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
pub(crate) fn upsampling_warning(input: &LoadedEnvironment, n: usize) -> Option<String> {
    let what = match &input.env {
        Environment::Equirect(img) => format!("a {}×{} equirect", img.width, img.height),
        Environment::Cube(c) => format!("a cube of {0}×{0} faces", c.size),
    };
    upsampling(&input.path, source_face_texels(&input.env), &what, n)
}

/// [`upsampling_warning`] for a source of `have` texels per face described as `what`.
fn upsampling(path: &Path, have: f64, what: &str, n: usize) -> Option<String> {
    (n as f64 > have * 1.001).then(|| {
        format!(
            "{}: face size {n} upsamples {what} (about {:.0} texels per face) {:.1}×: no detail \
             is added; omit --size for the source's own size",
            path.display(),
            have,
            n as f64 / have
        )
    })
}

/// Paths [`run`] writes for `params` into `out` (for planning, cleaning and stale files).
pub fn output_paths(params: &Params, out: &Path) -> Result<Vec<PathBuf>> {
    let enc = params.encoding()?;
    let mut p = output::cube_output_paths(out, 1, enc.layout, params.cube_name());
    p.extend(output::encoding_sidecar_path(out, params.cube_name(), &enc));
    if !params.to_equirect {
        p.extend(params.target.spec().orientation.sidecar_path(
            out,
            enc.layout,
            params.cube_name(),
        ));
        p.push(out.join(ibl_target::NOTE_NAME));
    }
    Ok(p)
}

/// Resamples an environment to a cube (or an equirect with `to_equirect`) and encodes the
/// outputs for `out_dir` (or the output file for equirect). A streamed equirect
/// ([`ibl_core::envmap::open_environment_with`]) is resampled as its rows arrive (the same
/// texels; its input warnings lead the bake's); for `to_equirect` it is read whole.
pub fn run(
    params: &Params,
    input: impl Into<Opened>,
    out: &Path,
    progress: &dyn Progress,
) -> Result<Baked> {
    params.validate()?;
    let enc = params.encoding()?;
    let input = match input.into() {
        Opened::Streamed(s) if !params.to_equirect => {
            let n = params.size.unwrap_or_else(|| s.natural_face_size());
            let path = s.path().to_path_buf();
            let what = format!("a {}×{} equirect", s.width(), s.height());
            let have = s.width() as f64 / 4.0;
            let streamed = s.to_cube(n, params.filter, params.rotate, progress)?;
            let mut warnings = streamed.warnings(&path);
            warnings.extend(upsampling(&path, have, &what, n));
            return encode_cube(params, enc, out, streamed.cube, n, warnings);
        }
        Opened::Streamed(s) => s.load()?,
        Opened::Loaded(l) => l,
    };
    let input = &input;
    let depth = if enc.format == PixelFormat::Rgba16f {
        FloatDepth::F16
    } else {
        FloatDepth::F32
    };
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
            encoding: Vec::new(),
            warnings: Vec::new(),
        });
    }
    let n = params.size.unwrap_or_else(|| input.env.natural_face_size());
    let cube = input.env.to_cube(n, params.filter, params.rotate, progress);
    let warnings = upsampling_warning(input, n).into_iter().collect();
    encode_cube(params, enc, out, cube, n, warnings)
}

/// The files of a resampled cube of n² faces for `out`, `warnings` first among the bake's.
fn encode_cube(
    params: &Params,
    enc: Encoding,
    out: &Path,
    cube: ibl_core::cube::Cubemap,
    n: usize,
    warnings: Vec<String>,
) -> Result<Baked> {
    let orientation = params.target.spec().orientation;
    let cube = orientation.apply(&cube);
    let name = params.cube_name();
    let metadata = orientation.metadata(params.target.name());
    let encoded =
        output::encode_cube(out, &CubeMips { levels: vec![cube] }, &enc, name, &metadata)?;
    let mut files = encoded.files;
    let sidecar = output::encoding_sidecar(out, name, &enc, &encoded.levels)?;
    let mut outputs = ibl_target::note::Outputs {
        cube: ibl_target::note::names(files.iter().map(|f| f.0.as_path())),
        levels: 1,
        sidecars: ibl_target::note::names(sidecar.iter().map(|f| f.0.as_path())),
        ..Default::default()
    };
    files.extend(sidecar);
    if let Some(side) = orientation.sidecar(out, enc.layout, name, params.target.name()) {
        outputs.orientation = ibl_target::note::names([side.0.as_path()]).pop();
        files.push(side);
    }
    // The how-to-load note, naming only what this run wrote (every target, gltf too).
    let note = ibl_target::note::load_note(params.target, ibl_target::note::Writer::Cube, &outputs);
    files.push((out.join(ibl_target::NOTE_NAME), note.into_bytes()));
    Ok(Baked {
        files,
        face_size: n,
        encoding: encoded.levels,
        warnings: warnings.into_iter().chain(encoded.warnings).collect(),
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
        assert_eq!(Params::default().layout, None);
        assert_eq!(Params::default().encoding().unwrap().layout, Layout::Faces);
        let p: Params =
            ron_from_str("(layout: Some(ktx2), format: Some(bc6h), bc6h_quality: Some(slow))");
        assert_eq!(p.encoding().unwrap().format, PixelFormat::Bc6h);
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

    /// Issue 22: a cube written in any target's orientation, in any container, reads back
    /// (load_environment undoing what its KTX key or sidecar records) as our cube: the same
    /// SH as the cube written in our frame (Bevy's had L10's sign flipped, Filament's L10 and
    /// L11 swapped).
    #[test]
    fn every_targets_orientation_reads_back_as_ours() {
        use crate::irradiance::project;
        use ibl_core::envmap::load_environment;
        use ibl_core::progress::NoProgress;
        use ibl_target::Target;
        let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/hdri/sunset_256.exr");
        let input = load_environment(&src, false).unwrap();
        let tmp = tempfile::tempdir().unwrap();
        let bake = |target: Target, layout: Layout, dir: &str| {
            let params = Params {
                size: Some(16),
                target,
                layout: Some(layout),
                format: Some(PixelFormat::Rgba32f),
                ..Default::default()
            };
            let out = tmp.path().join(dir);
            let baked = run(&params, input.clone(), &out, &NoProgress).unwrap();
            io::write_many_atomic(&baked.files).unwrap();
            let path = match layout.container_path(&out, params.cube_name()) {
                Some(p) => p,
                None => out,
            };
            let back = load_environment(&path, false).unwrap();
            (project(&back.env, 3, 0.0), back.read_as)
        };
        let (ours, _) = bake(Target::Gltf, Layout::Faces, "ours");
        for target in [
            Target::Gltf,
            Target::Bevy,
            Target::Filament,
            Target::Three,
            Target::Babylon,
            Target::Unity,
        ] {
            for layout in [Layout::Faces, Layout::Ktx2, Layout::Ktx1, Layout::Dds] {
                let (sh, notes) = bake(target, layout, &format!("{target:?}-{layout:?}"));
                for (i, (a, b)) in sh.iter().zip(&ours).enumerate() {
                    for c in 0..3 {
                        assert!(
                            (a[c] - b[c]).abs() <= 1e-5 * b[0].abs().max(1e-6),
                            "{target:?} {layout:?} coefficient {i}: {a:?} vs ours {b:?}"
                        );
                    }
                }
                // Our own files carry their orientation: no "unknown orientation" warning.
                assert!(
                    notes.iter().all(|n| !n.contains("no ibl.orientation")),
                    "{target:?} {layout:?}: {notes:?}"
                );
            }
        }
        // A foreign container (no key, no sidecar) is read as ours, with a warning.
        let foreign = tmp
            .path()
            .join("Bevy-Dds/skybox_rgb9e5_zstd.orientation.json");
        std::fs::remove_file(&foreign).unwrap();
        let back =
            load_environment(&tmp.path().join("Bevy-Dds/skybox_rgb9e5_zstd.dds"), false).unwrap();
        assert!(
            back.read_as
                .iter()
                .any(|n| n.contains("no ibl.orientation")),
            "{:?}",
            back.read_as
        );
    }
}
