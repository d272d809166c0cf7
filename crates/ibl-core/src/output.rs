//! How a cube or chain is written: container, pixel format, supercompression and BC6H effort,
//! the flags every cube-writing bake shares (one struct, flattened into each bake's `Params`,
//! so `--format bc6h` on the command line is `format: bc6h` in a pipeline), the check of their
//! combination before any work, and the encoding itself. A new container is one module under
//! `io/` implementing [`io::container::Codec`], registered by its [`Layout`] variant
//! (`io::layout`) and its arm in [`Layout::codec`] (`io::container`).

use crate::cube::{CubeMips, Face};
use crate::error::{Error, Result};
use crate::image::Image;
use crate::io::format::{Bc6hQuality, PixelFormat};
use crate::io::texture::{self, LevelEncoding};
use crate::io::{self, FloatDepth, WriteOptions};
use std::path::{Path, PathBuf};

/// Output container for cubemaps (defined in `io::layout`, below the container modules that
/// implement it; its methods are in `io::container`, which registers each codec).
pub use crate::io::layout::Layout;

/// The output flags of every bake that writes a cube or a chain, as [`cube_output_params!`]
/// adds them to its `Params`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct CubeOutput {
    /// `--layout`: the container, `None` for the target's.
    pub layout: Option<Layout>,
    /// `--format`: the pixel format, `None` for the target's.
    pub format: Option<PixelFormat>,
    /// `--half`: the same as `--format rgba16f`.
    pub half: bool,
    /// `--zstd`: KTX2 supercompression level (1–22).
    pub zstd: Option<i32>,
    /// `--bc6h-quality`: the BC6H encoder's effort.
    pub bc6h_quality: Option<Bc6hQuality>,
}

/// Defines a bake's `Params` struct with the output flags every cube writer shares appended
/// (`--layout`, `--format`, `--half`, `--zstd`, `--bc6h-quality`; the same RON keys), and
/// `Params::cube_output()`. A macro rather than a flattened struct because RON's struct
/// syntax `(size: 16, layout: ktx2)` cannot feed serde's `flatten` (it asks for a map), and the
/// keys must stay flat: a flag and a key are one thing.
#[macro_export]
macro_rules! cube_output_params {
    ($(#[$m:meta])* $v:vis struct $name:ident { $($body:tt)* }) => {
        $(#[$m])*
        $v struct $name {
            $($body)*
            /// Output container: EXR faces, or one KTX2, DDS or KTX1 file with every face and
            /// level [default: faces, or the target's].
            #[arg(long, value_enum)]
            pub layout: Option<$crate::output::Layout>,
            /// Pixel format: rgba32f, rgba16f (EXR faces take these two), or for containers
            /// rgb9e5, b10g11r11 (4 bytes a texel) and bc6h (1 byte a texel) [default: rgba32f,
            /// or the target's].
            #[arg(long, value_enum)]
            pub format: Option<$crate::io::format::PixelFormat>,
            /// Same as --format rgba16f.
            #[arg(long)]
            pub half: bool,
            /// zstd-supercompress every level of a KTX2 output at this level (1–22; 19 is a
            /// common shipping choice).
            #[arg(long, value_name = "LEVEL")]
            pub zstd: Option<i32>,
            /// BC6H encoder effort, the ISPC texture compressor's profiles [default: basic].
            #[arg(long, value_enum)]
            pub bc6h_quality: Option<$crate::io::format::Bc6hQuality>,
        }

        impl $name {
            /// The output flags of these parameters.
            pub fn cube_output(&self) -> $crate::output::CubeOutput {
                $crate::output::CubeOutput {
                    layout: self.layout,
                    format: self.format,
                    half: self.half,
                    zstd: self.zstd,
                    bc6h_quality: self.bc6h_quality,
                }
            }
        }
    };
}

/// A checked, complete output encoding.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub struct Encoding {
    /// Face files or one container file.
    pub layout: Layout,
    /// Pixel format of every level.
    pub format: PixelFormat,
    /// KTX2 zstd supercompression level, if any.
    pub zstd: Option<i32>,
    /// BC6H encoder effort (read only for `PixelFormat::Bc6h`).
    pub bc6h_quality: Bc6hQuality,
}

impl Default for Encoding {
    fn default() -> Self {
        Encoding {
            layout: Layout::Faces,
            format: PixelFormat::Rgba32f,
            zstd: None,
            bc6h_quality: Bc6hQuality::Basic,
        }
    }
}

/// What combinations are valid, for error messages.
pub const VALID_COMBINATIONS: &str = "valid: --layout faces with --format rgba32f|rgba16f; --layout ktx2|dds|ktx1 with --format rgba32f|rgba16f|rgb9e5|b10g11r11|bc6h; --zstd 1..22 with --layout ktx2 only; --bc6h-quality with --format bc6h only";

impl CubeOutput {
    /// The encoding these flags ask for, over `defaults` (a target's, or [`Encoding::default`]
    /// when none), refused up front if the combination makes no sense.
    pub fn resolve(&self, defaults: Encoding) -> Result<Encoding> {
        let refuse = |what: String| Err(Error::param(format!("{what} ({VALID_COMBINATIONS})")));
        let layout = self.layout.unwrap_or(defaults.layout);
        let faces_ok = |f: PixelFormat| matches!(f, PixelFormat::Rgba32f | PixelFormat::Rgba16f);
        let format = match (self.format, self.half) {
            (Some(f), true) if f != PixelFormat::Rgba16f => {
                return refuse(format!(
                    "--half means --format rgba16f, but --format {} was given",
                    f.name()
                ))
            }
            (_, true) => PixelFormat::Rgba16f,
            (Some(f), false) => f,
            // A target's packed format cannot go into EXR faces the user asked for: float.
            (None, false) if layout == Layout::Faces && !faces_ok(defaults.format) => {
                PixelFormat::Rgba32f
            }
            (None, false) => defaults.format,
        };
        // An explicit layout drops a default zstd that only a KTX2 could take.
        let zstd = match (self.zstd, self.layout) {
            (Some(z), _) => Some(z),
            (None, Some(l)) if l != Layout::Ktx2 => None,
            (None, _) => defaults.zstd,
        };
        let enc = Encoding {
            layout,
            format,
            zstd,
            bc6h_quality: self.bc6h_quality.unwrap_or(defaults.bc6h_quality),
        };
        if layout == Layout::Faces && !faces_ok(format) {
            return refuse(format!(
                "--format {} cannot be written as EXR faces: choose --layout ktx2, dds or ktx1",
                format.name()
            ));
        }
        if let Some(z) = zstd {
            if layout != Layout::Ktx2 {
                return refuse(format!("--zstd needs --layout ktx2, not {}", layout.name()));
            }
            if !(1..=22).contains(&z) {
                return refuse(format!("--zstd {z} is out of range 1..=22"));
            }
        }
        if self.bc6h_quality.is_some() && format != PixelFormat::Bc6h {
            return refuse(format!(
                "--bc6h-quality applies to --format bc6h, not {}",
                format.name()
            ));
        }
        Ok(enc)
    }
}

/// A level whose encoding costs more than this mean relative error is reported: BC6H on
/// faces of 4×4 and less, where one block spans the face and its 16 steps cost ~4%.
const BC6H_WARN: f64 = 0.03;

/// A cube or chain encoded for its folder, nothing written yet.
pub struct EncodedCube {
    /// `(path, bytes)` pairs for [`io::write_many_atomic`].
    pub files: Vec<(PathBuf, Vec<u8>)>,
    /// What encoding each level cost against the float data.
    pub levels: Vec<LevelEncoding>,
    /// Clamped values and the like, one line each.
    pub warnings: Vec<String>,
}

/// Encodes a cube for `dir`: faces are `px.exr`… (one level; a cube with mips is named as a
/// chain), a container `dir/<name>.<ext>`. `metadata` goes into KTX1/KTX2 key/value data.
/// A prefiltered chain uses [`encode_chain`], whose faces carry the level whatever the count.
pub fn encode_cube(
    dir: &Path,
    mips: &CubeMips,
    enc: &Encoding,
    name: &str,
    metadata: &[(String, Vec<u8>)],
) -> Result<EncodedCube> {
    encode_with(
        dir,
        mips,
        None,
        None,
        enc,
        name,
        metadata,
        mips.levels.len() > 1,
    )
}

/// Encodes a mip chain for `dir`: faces are `m{l}_px.exr`… for every level, a one-level chain
/// too (`m0_px.exr`: a reader tells a chain from a cube by the name, not by counting), a
/// container `dir/<name>.<ext>`. `metadata` goes into KTX1/KTX2 key/value data.
pub fn encode_chain(
    dir: &Path,
    mips: &CubeMips,
    enc: &Encoding,
    name: &str,
    metadata: &[(String, Vec<u8>)],
) -> Result<EncodedCube> {
    encode_with(dir, mips, None, None, enc, name, metadata, true)
}

/// [`encode_chain`] with a fourth channel: `alpha`'s channel 0 becomes each texel's A
/// ([`texture::set_alpha`]). Only a container (KTX2, KTX1, DDS) in `rgba16f` or `rgba32f`
/// holds it; faces (EXR) or other formats are refused rather than written without it.
pub fn encode_chain_with_alpha(
    dir: &Path,
    mips: &CubeMips,
    alpha: &CubeMips,
    enc: &Encoding,
    name: &str,
    metadata: &[(String, Vec<u8>)],
) -> Result<EncodedCube> {
    encode_with(dir, mips, None, Some(alpha), enc, name, metadata, true)
}

/// A chain's texels encoded once, in memory, before its files are made: what
/// [`texture::encode_chain`] returns for the chain as it will be written (same format and BC6H
/// effort). A bake that reads its own encoded chain back (the runtime report looks up what the
/// engine will sample) hands it to [`encode_chain_from`] rather than encoding twice: BC6H's
/// encode is most of a BC6H bake's extra time.
pub type PreEncoded = (texture::Payload, Vec<LevelEncoding>);

/// [`encode_chain`] (or, with `alpha`, [`encode_chain_with_alpha`]), from the texels `pre`
/// already holds when it is given (encoded from `mips` as the file holds them, in `enc`'s
/// format): a container is made from those bytes, reading only `mips`' shape (so a caller may
/// pass the chain in another frame), and only face images read `mips`' texels.
pub fn encode_chain_from(
    dir: &Path,
    mips: &CubeMips,
    pre: Option<PreEncoded>,
    alpha: Option<&CubeMips>,
    enc: &Encoding,
    name: &str,
    metadata: &[(String, Vec<u8>)],
) -> Result<EncodedCube> {
    encode_with(dir, mips, pre, alpha, enc, name, metadata, true)
}

#[allow(clippy::too_many_arguments)]
fn encode_with(
    dir: &Path,
    mips: &CubeMips,
    pre: Option<PreEncoded>,
    alpha: Option<&CubeMips>,
    enc: &Encoding,
    name: &str,
    metadata: &[(String, Vec<u8>)],
    chain: bool,
) -> Result<EncodedCube> {
    let (mut payload, levels) = match pre {
        Some((payload, levels)) => {
            // Bytes of another chain or format would be written under this one's name.
            assert!(
                payload.format == enc.format
                    && payload.levels.len() == mips.levels.len()
                    && mips.levels.first().map(|c| c.size) == Some(payload.width),
                "pre-encoded chain does not match the chain written"
            );
            (payload, levels)
        }
        None => texture::encode_chain(mips, enc.format, enc.bc6h_quality),
    };
    let files = match (enc.layout.codec(), enc.layout.container_path(dir, name)) {
        (Some(codec), Some(path)) => {
            if let Some(a) = alpha {
                texture::set_alpha(&path, &mut payload, a)?;
            }
            vec![(path, codec.encode(&payload, enc.zstd, metadata)?)]
        }
        _ if alpha.is_some() => return Err(Error::unsupported(
            dir,
            "face images cannot hold the chain's alpha channel: use a container (--layout ktx2)",
        )),
        _ => encode_faces(dir, mips, enc.format, chain)?,
    };
    let clamped: usize = levels.iter().map(|l| l.clamped).sum();
    let mut warnings = Vec::new();
    for l in levels.iter().filter(|l| l.mean_rel > BC6H_WARN) {
        warnings.push(format!(
            "level {} ({}²): {} mean relative error {:.1}% (its 4×4 blocks are coarse on so small a face; rgb9e5 or rgba16f keep it under 0.2%)",
            l.level,
            l.size,
            enc.format.name(),
            100.0 * l.mean_rel,
        ));
    }
    if clamped > 0 {
        warnings.push(format!(
            "{clamped} channel values outside [0, {}] (the largest {} holds) were clamped: use --format rgba32f to keep them",
            enc.format.max_value(),
            enc.format.name()
        ));
    }
    Ok(EncodedCube {
        files,
        levels,
        warnings,
    })
}

fn face_name(level: usize, chain: bool, face: Face) -> String {
    if chain {
        format!("m{level}_{}.exr", face.name())
    } else {
        format!("{}.exr", face.name())
    }
}

fn encode_faces(
    dir: &Path,
    mips: &CubeMips,
    format: PixelFormat,
    chain: bool,
) -> Result<Vec<(PathBuf, Vec<u8>)>> {
    use rayon::prelude::*;
    let opts = WriteOptions {
        float: if format == PixelFormat::Rgba16f {
            FloatDepth::F16
        } else {
            FloatDepth::F32
        },
        ..Default::default()
    };
    let jobs: Vec<(PathBuf, &Image)> = mips
        .levels
        .iter()
        .enumerate()
        .flat_map(|(l, cube)| {
            Face::ALL
                .iter()
                .map(move |f| (dir.join(face_name(l, chain, *f)), &cube.faces[*f as usize]))
        })
        .collect();
    jobs.into_par_iter()
        .map(|(p, img)| io::encode_image(&p, img, &opts).map(|b| (p, b)))
        .collect()
}

/// Paths [`encode_cube`] writes for a cube of `levels` levels (for planning and cleaning).
pub fn cube_output_paths(dir: &Path, levels: usize, layout: Layout, name: &str) -> Vec<PathBuf> {
    output_paths(dir, levels, layout, name, levels > 1)
}

/// Paths [`encode_chain`] writes for a chain of `levels` levels (for planning and cleaning).
pub fn chain_output_paths(dir: &Path, levels: usize, layout: Layout, name: &str) -> Vec<PathBuf> {
    output_paths(dir, levels, layout, name, true)
}

fn output_paths(
    dir: &Path,
    levels: usize,
    layout: Layout,
    name: &str,
    chain: bool,
) -> Vec<PathBuf> {
    match layout.container_path(dir, name) {
        Some(p) => vec![p],
        None => (0..levels)
            .flat_map(|l| {
                Face::ALL
                    .iter()
                    .map(move |f| dir.join(face_name(l, chain, *f)))
            })
            .collect(),
    }
}

/// Files in `dir` that an earlier run of the same bake left and this one, writing `written`,
/// does not replace: the other containers named `<name>`, and complete sets of six face files
/// of another layout or of levels beyond the new chain. A bake removes them after a successful
/// write, so a folder holds exactly one result (a reader would otherwise mix two).
pub fn stale_cube_files(dir: &Path, name: &str, written: &[PathBuf]) -> Vec<PathBuf> {
    // An orientation sidecar is stale too (a reader would turn the new cube by it), but only
    // one our tools wrote: it must parse as one.
    let ours =
        |p: &PathBuf| std::fs::read(p).is_ok_and(|b| crate::orientation::from_sidecar(&b).is_ok());
    let mut out: Vec<PathBuf> = Layout::all()
        .iter()
        .filter_map(|l| l.container_path(dir, name))
        .chain([dir.join(format!("{name}.encoding.json"))])
        .filter(|p| p.is_file())
        .chain(
            [
                dir.join(format!("{name}.orientation.json")),
                dir.join(crate::orientation::FACES_SIDECAR),
            ]
            .into_iter()
            .filter(|p| p.is_file() && ours(p)),
        )
        .collect();
    let six = |stem: &dyn Fn(Face) -> String| -> Vec<PathBuf> {
        let found: Vec<PathBuf> = Face::ALL
            .iter()
            .filter_map(|f| crate::envmap::find_with_stem(dir, &stem(*f)))
            .collect();
        if found.len() == 6 {
            found
        } else {
            Vec::new()
        }
    };
    out.extend(six(&|f| f.name().to_string()));
    for l in 0.. {
        let set = six(&|f| format!("m{l}_{}", f.name()));
        if set.is_empty() {
            break;
        }
        out.extend(set);
    }
    out.retain(|p| !written.contains(p));
    out
}

/// The `encoding` block a sidecar records.
pub fn encoding_report(enc: &Encoding, levels: &[LevelEncoding]) -> serde_json::Value {
    serde_json::json!({
        "layout": enc.layout.name(),
        "format": enc.format.name(),
        "zstd": enc.zstd,
        "bc6h_quality": (enc.format == PixelFormat::Bc6h).then_some(enc.bc6h_quality),
        "metric": texture::ERROR_METRIC,
        "levels": levels,
    })
}

/// Where a bake without a report of its own records a lossy encoding's cost:
/// `dir/<name>.encoding.json` (none for lossless rgba32f).
pub fn encoding_sidecar_path(dir: &Path, name: &str, enc: &Encoding) -> Option<PathBuf> {
    (!enc.format.is_lossless()).then(|| dir.join(format!("{name}.encoding.json")))
}

/// The sidecar of [`encoding_sidecar_path`], encoded, if the encoding is lossy.
pub fn encoding_sidecar(
    dir: &Path,
    name: &str,
    enc: &Encoding,
    levels: &[LevelEncoding],
) -> Result<Option<(PathBuf, Vec<u8>)>> {
    encoding_sidecar_path(dir, name, enc)
        .map(|p| {
            let bytes = io::data::encode(&p, &encoding_report(enc, levels))?;
            Ok((p, bytes))
        })
        .transpose()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn combinations_are_checked_up_front() {
        let ok = |o: CubeOutput| o.resolve(Encoding::default());
        assert_eq!(ok(CubeOutput::default()).unwrap(), Encoding::default());
        let half = ok(CubeOutput {
            half: true,
            ..Default::default()
        })
        .unwrap();
        assert_eq!(half.format, PixelFormat::Rgba16f);
        for (o, needle) in [
            (
                CubeOutput {
                    format: Some(PixelFormat::Bc6h),
                    ..Default::default()
                },
                "cannot be written as EXR faces",
            ),
            (
                CubeOutput {
                    layout: Some(Layout::Dds),
                    zstd: Some(3),
                    ..Default::default()
                },
                "--zstd needs --layout ktx2",
            ),
            (
                CubeOutput {
                    layout: Some(Layout::Ktx2),
                    zstd: Some(40),
                    ..Default::default()
                },
                "out of range",
            ),
            (
                CubeOutput {
                    half: true,
                    format: Some(PixelFormat::Rgb9e5),
                    ..Default::default()
                },
                "--half means",
            ),
            (
                CubeOutput {
                    layout: Some(Layout::Ktx2),
                    bc6h_quality: Some(Bc6hQuality::Slow),
                    ..Default::default()
                },
                "--bc6h-quality",
            ),
        ] {
            let e = ok(o).unwrap_err().to_string();
            assert!(e.contains(needle) && e.contains("valid:"), "{e}");
        }
        // A target's default: KTX2 + RGB9E5 + zstd; an explicit DDS layout drops the zstd.
        let target = Encoding {
            layout: Layout::Ktx2,
            format: PixelFormat::Rgb9e5,
            zstd: Some(19),
            ..Default::default()
        };
        let dds = CubeOutput {
            layout: Some(Layout::Dds),
            ..Default::default()
        }
        .resolve(target)
        .unwrap();
        assert_eq!(
            (dds.layout, dds.format, dds.zstd),
            (Layout::Dds, PixelFormat::Rgb9e5, None)
        );
    }

    #[test]
    fn stale_files_are_other_layouts_and_longer_chains() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        for f in ["prefilter.ktx2", "prefilter.dds", "other.ktx2", "notes.txt"] {
            std::fs::write(d.join(f), b"x").unwrap();
        }
        for l in 0..3 {
            for f in Face::ALL {
                std::fs::write(d.join(format!("m{l}_{}.exr", f.name())), b"x").unwrap();
            }
        }
        // A 2-level chain written as faces: the containers and level 2 are stale.
        let written = cube_output_paths(d, 2, Layout::Faces, "prefilter");
        let mut stale: Vec<String> = stale_cube_files(d, "prefilter", &written)
            .iter()
            .map(|p| p.file_name().unwrap().to_string_lossy().into_owned())
            .collect();
        stale.sort();
        let mut want: Vec<String> = Face::ALL
            .iter()
            .map(|f| format!("m2_{}.exr", f.name()))
            .collect();
        want.extend(["prefilter.dds".into(), "prefilter.ktx2".into()]);
        want.sort();
        assert_eq!(stale, want);
        // Written as KTX2: every face file and the DDS are stale, never other.ktx2 or notes.
        let written = cube_output_paths(d, 2, Layout::Ktx2, "prefilter");
        let stale = stale_cube_files(d, "prefilter", &written);
        assert_eq!(stale.len(), 18 + 1);
        assert!(!stale
            .iter()
            .any(|p| p.ends_with("other.ktx2") || p.ends_with("notes.txt")));
    }

    #[test]
    fn a_chain_names_its_level_whatever_the_count() {
        use crate::cube::Cubemap;
        let one = CubeMips {
            levels: vec![Cubemap::new(2)],
        };
        let names = |files: &[(PathBuf, Vec<u8>)]| -> Vec<String> {
            files
                .iter()
                .map(|f| f.0.file_name().unwrap().to_string_lossy().into_owned())
                .collect()
        };
        let d = Path::new("out");
        let enc = Encoding::default();
        let chain = encode_chain(d, &one, &enc, "prefilter", &[]).unwrap();
        assert_eq!(names(&chain.files)[0], "m0_px.exr");
        assert!(names(&chain.files).iter().all(|n| n.starts_with("m0_")));
        let paths: Vec<PathBuf> = chain.files.iter().map(|f| f.0.clone()).collect();
        assert_eq!(paths, chain_output_paths(d, 1, Layout::Faces, "prefilter"));
        // A cube stays a cube: px.exr…
        let cube = encode_cube(d, &one, &enc, "cube", &[]).unwrap();
        assert_eq!(names(&cube.files)[0], "px.exr");
        assert_eq!(
            cube.files.iter().map(|f| f.0.clone()).collect::<Vec<_>>(),
            cube_output_paths(d, 1, Layout::Faces, "cube")
        );
        // …and the one-level chain reads back as a chain of one level.
        let dir = tempfile::tempdir().unwrap();
        let chain = encode_chain(dir.path(), &one, &enc, "prefilter", &[]).unwrap();
        io::write_many_atomic(&chain.files).unwrap();
        let back = crate::envmap::read_cube_chain(dir.path()).unwrap();
        assert_eq!(back, one);
    }
}
