//! What every table shares: coordinates at texel centres, the parallel row map (deterministic
//! for any thread count: each texel is one sequential sum), and encoding by output extension
//! (`.exr` float, `.png` 8/16-bit, `.json`/`.ron` float dump).

use crate::error::{Error, Result};
use ibl_core::io::{self, FloatDepth, WriteOptions};
use ibl_core::progress::Progress;
use ibl_core::{traverse, Image};
use serde::Serialize;
use std::path::{Path, PathBuf};

/// Largest table side accepted by the bakes.
pub const MAX_SIZE: usize = 4096;
/// Largest sample count accepted by the bakes (per texel).
pub const MAX_SAMPLES: u32 = 1 << 24;

/// The coordinate of texel `i` of `n`: (i + 0.5)/n (docs/CONVENTIONS.md, "LUT axes at texel centres").
#[inline]
pub fn texel_centre(i: usize, n: usize) -> f64 {
    (i as f64 + 0.5) / n as f64
}

/// Builds a width × height table with `channels` channels by calling `kernel(row, out)` for
/// each row in parallel over [`ibl_core::traverse`]; `out` is that row's interleaved data.
pub(crate) fn map_rows<K>(
    width: usize,
    height: usize,
    channels: usize,
    progress: &dyn Progress,
    kernel: K,
) -> Image
where
    K: Fn(usize, &mut [f32]) + Sync,
{
    let mut img = Image::new(width, height, channels);
    traverse::map_image_rows_with(
        &mut img.data,
        width * channels,
        1,
        "rows",
        progress,
        || (),
        |_, j, row| kernel(j, row),
    );
    img
}

/// Output formats, chosen by extension.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Format {
    /// OpenEXR, float or half.
    Exr,
    /// PNG, 8 or 16 bits (values in [0, 1]).
    Png,
    /// A JSON dump of every texel with the table's description.
    Json,
    /// A RON dump of the same.
    Ron,
}

impl Format {
    /// The format of a table output: `.exr`, `.png`, `.json` or `.ron`.
    pub fn of(path: &Path) -> Result<Format> {
        match io::extension(path).as_str() {
            "exr" => Ok(Format::Exr),
            "png" => Ok(Format::Png),
            "json" => Ok(Format::Json),
            "ron" => Ok(Format::Ron),
            _ => Err(unsupported(path, "write .exr, .png, .json or .ron")),
        }
    }

    /// The format of an output that must be an image (`.exr` or `.png`); `what` says why,
    /// e.g. "the half-vector LUT is an image".
    pub(crate) fn image_of(path: &Path, what: &str) -> Result<Format> {
        match Format::of(path) {
            Ok(f @ (Format::Exr | Format::Png)) => Ok(f),
            _ => Err(unsupported(path, &format!("{what}: write .exr or .png"))),
        }
    }
}

/// "'.ext' (hint)", or "no extension (hint)".
fn unsupported(path: &Path, hint: &str) -> Error {
    let ext = io::extension(path);
    let what = if ext.is_empty() {
        format!("no extension ({hint})")
    } else {
        format!("'.{ext}' ({hint})")
    };
    Error::UnsupportedOutput {
        path: path.to_path_buf(),
        what,
    }
}

/// The float dump written for `.json` / `.ron`: self-describing, row 0 first.
#[derive(Serialize)]
pub(crate) struct TableDump<'a> {
    pub table: &'a str,
    pub tool_version: &'a str,
    pub width: usize,
    pub height: usize,
    /// Meaning of each channel, in order.
    pub channels: &'a [&'a str],
    /// What the column coordinate s = (i+0.5)/width stands for.
    pub s: &'a str,
    /// What the row coordinate t = (j+0.5)/height stands for.
    pub t: &'a str,
    pub params: serde_json::Value,
    /// texels[j][i] = the channel values of column i, row j.
    pub texels: Vec<Vec<Vec<f32>>>,
}

/// How a table describes itself in dumps and summaries.
pub struct Describe<'a> {
    /// What the table is, with its reference.
    pub table: &'a str,
    /// Meaning of each channel, in order.
    pub channels: &'a [&'a str],
    /// What the column coordinate s = (i+0.5)/width stands for.
    pub s: &'a str,
    /// What the row coordinate t = (j+0.5)/height stands for.
    pub t: &'a str,
    /// The parameters the table was baked with.
    pub params: serde_json::Value,
}

/// Encodes a table for `path`: EXR float (or half), PNG of `png_bits` bits (two-channel
/// tables get a zero blue channel, since a two-channel PNG is grey + alpha), or the dump.
pub fn encode(
    path: &Path,
    img: &Image,
    desc: &Describe,
    png_bits: u8,
    half: bool,
) -> Result<Vec<u8>> {
    match Format::of(path)? {
        Format::Exr => {
            let opts = WriteOptions {
                float: if half {
                    FloatDepth::F16
                } else {
                    FloatDepth::F32
                },
                ..Default::default()
            };
            Ok(io::encode_image(path, img, &opts)?)
        }
        Format::Png => {
            let img3 = if img.channels == 2 {
                img.to_channels(3)
            } else {
                img.clone()
            };
            let opts = WriteOptions {
                png_bits,
                png_tonemap: false,
                png_srgb: false,
                ..Default::default()
            };
            Ok(io::encode_image(path, &img3, &opts)?)
        }
        Format::Json | Format::Ron => {
            let texels = (0..img.height)
                .map(|j| (0..img.width).map(|i| img.texel(i, j).to_vec()).collect())
                .collect();
            let dump = TableDump {
                table: desc.table,
                tool_version: ibl_core::TOOL_VERSION,
                width: img.width,
                height: img.height,
                channels: desc.channels,
                s: desc.s,
                t: desc.t,
                params: desc.params.clone(),
                texels,
            };
            Ok(io::data::encode(path, &dump)?)
        }
    }
}

/// What a bake produced, before anything is written.
pub struct Baked {
    /// Encoded files, ready for [`ibl_core::io::write_many_atomic`].
    pub files: Vec<(PathBuf, Vec<u8>)>,
    /// The table itself (float).
    pub image: Image,
    /// Bake-specific details for the summary.
    pub details: serde_json::Value,
}

/// Checks a table side against 1..=MAX_SIZE.
pub fn check_size(name: &str, n: usize) -> Result<()> {
    if n == 0 || n > MAX_SIZE {
        return Err(Error::param(format!(
            "--{name} {n} is out of range 1..={MAX_SIZE}"
        )));
    }
    Ok(())
}

/// Checks a sample count against 1..=MAX_SAMPLES.
pub(crate) fn check_samples(n: u32) -> Result<()> {
    if n == 0 || n > MAX_SAMPLES {
        return Err(Error::param(format!(
            "--samples {n} is out of range 1..={MAX_SAMPLES}"
        )));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use ibl_core::progress::NoProgress;

    #[test]
    fn rows_are_filled_in_place_and_thread_count_does_not_matter() {
        let k = |j: usize, row: &mut [f32]| {
            for (i, t) in row.chunks_mut(2).enumerate() {
                t[0] = texel_centre(i, 7) as f32;
                t[1] = (texel_centre(j, 5) as f32).sin() * 1e-3 + 1.0;
            }
        };
        let a =
            ibl_testkit::thread_count_independent(&[1, 2, 3], || map_rows(7, 5, 2, &NoProgress, k));
        assert_eq!(a.texel(3, 0)[0], 0.5);
        assert_eq!(a.texel(0, 2)[1], (0.5f32).sin() * 1e-3 + 1.0);
    }

    #[test]
    fn formats_by_extension() {
        assert_eq!(Format::of(Path::new("a.EXR")).unwrap(), Format::Exr);
        assert_eq!(Format::of(Path::new("a.ron")).unwrap(), Format::Ron);
        let msg = |r: Result<Format>| r.unwrap_err().to_string();
        assert_eq!(
            msg(Format::of(Path::new("a.txt"))),
            "a.txt: unsupported output: '.txt' (write .exr, .png, .json or .ron)"
        );
        assert_eq!(
            msg(Format::of(Path::new("a"))),
            "a: unsupported output: no extension (write .exr, .png, .json or .ron)"
        );
        assert_eq!(
            Format::image_of(Path::new("a.PNG"), "x").unwrap(),
            Format::Png
        );
        assert_eq!(
            msg(Format::image_of(Path::new("a.json"), "the LUT is an image")),
            "a.json: unsupported output: '.json' (the LUT is an image: write .exr or .png)"
        );
        assert_eq!(
            msg(Format::image_of(Path::new("a"), "the LUT is an image")),
            "a: unsupported output: no extension (the LUT is an image: write .exr or .png)"
        );
    }
}
