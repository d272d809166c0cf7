//! The `tpr-map` bake (Marcolongo 2020 §3.5): an RGBA map whose RG hold the rotated tangent
//! (x, y)·0.5 + 0.5 in tangent space and whose BA hold the two directional roughnesses,
//! from a preset, an angle/direction map or expressions in u, v.
//!
//! Deviation from the thesis, by docs/CONVENTIONS.md: B and A store perceptual roughness r along t
//! and b (α = r²) unless `--store-alpha` asks for the thesis's α. The default roughness is
//! the thesis's α_x = 0.1, α_y = 1.0 as perceptual values (0.31623, 1).

use crate::direction::{aspect_scale, resample_line_field, tangent_from_angle_value, taps, Preset};
use crate::expr::{self, Program, Scratch};
pub use crate::map::LoadedMap;
use crate::Result;
use ibl_core::image::check_texels;
use ibl_core::io;
use ibl_core::progress::Progress;
use ibl_core::{Error, Image};
use serde::Serialize;
use std::fmt;
use std::path::{Path, PathBuf};
use std::str::FromStr;

/// Largest side accepted.
pub(crate) const MAX_SIDE: usize = 16384;

/// Output size `W` or `WxH`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Size {
    /// Columns.
    pub width: usize,
    /// Rows.
    pub height: usize,
}

impl FromStr for Size {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        let parse = |t: &str| {
            t.trim()
                .parse::<usize>()
                .map_err(|_| format!("size '{s}': '{}' is not a whole number", t.trim()))
        };
        let (w, h) = match s.split_once(['x', 'X', '×']) {
            Some((w, h)) => (parse(w)?, parse(h)?),
            None => {
                let n = parse(s)?;
                (n, n)
            }
        };
        if w == 0 || h == 0 || w > MAX_SIDE || h > MAX_SIDE {
            return Err(format!(
                "size {w}x{h} is out of range 1..={MAX_SIDE} per side"
            ));
        }
        Ok(Size {
            width: w,
            height: h,
        })
    }
}

impl fmt::Display for Size {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}x{}", self.width, self.height)
    }
}

#[derive(serde::Deserialize)]
#[serde(untagged)]
enum SizeRepr {
    One(usize),
    Two(usize, usize),
    Text(String),
}

impl Serialize for Size {
    fn serialize<S: serde::Serializer>(&self, s: S) -> std::result::Result<S::Ok, S::Error> {
        s.serialize_str(&self.to_string())
    }
}

impl<'de> serde::Deserialize<'de> for Size {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        let text = match SizeRepr::deserialize(d)? {
            SizeRepr::One(n) => n.to_string(),
            SizeRepr::Two(w, h) => format!("{w}x{h}"),
            SizeRepr::Text(t) => t,
        };
        text.parse().map_err(serde::de::Error::custom)
    }
}

/// Two roughnesses `RX,RY` (or one for both).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Roughness(pub [f64; 2]);

impl FromStr for Roughness {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        let v: Vec<f64> = s
            .split(',')
            .map(|t| {
                t.trim()
                    .parse::<f64>()
                    .map_err(|_| format!("roughness '{s}': '{}' is not a number", t.trim()))
            })
            .collect::<std::result::Result<_, _>>()?;
        let pair = match v.as_slice() {
            [r] => [*r, *r],
            [x, y] => [*x, *y],
            _ => {
                return Err(format!(
                    "roughness '{s}': give RX,RY (or one value for both)"
                ))
            }
        };
        if pair.iter().any(|r| !(0.0..=1.0).contains(r)) {
            return Err(format!(
                "roughness '{s}' is out of range [0, 1] (perceptual roughness; α = r²)"
            ));
        }
        Ok(Roughness(pair))
    }
}

impl fmt::Display for Roughness {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{},{}", self.0[0], self.0[1])
    }
}

#[derive(serde::Deserialize)]
#[serde(untagged)]
enum RoughnessRepr {
    One(f64),
    Two(f64, f64),
    Text(String),
}

impl Serialize for Roughness {
    fn serialize<S: serde::Serializer>(&self, s: S) -> std::result::Result<S::Ok, S::Error> {
        s.serialize_str(&self.to_string())
    }
}

impl<'de> serde::Deserialize<'de> for Roughness {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        let text = match RoughnessRepr::deserialize(d)? {
            RoughnessRepr::One(r) => r.to_string(),
            RoughnessRepr::Two(x, y) => format!("{x},{y}"),
            RoughnessRepr::Text(t) => t,
        };
        text.parse().map_err(serde::de::Error::custom)
    }
}

/// The thesis's α_x = 0.1, α_y = 1.0 (§3.5) as perceptual roughness.
pub(crate) const DEFAULT_ROUGHNESS: [f64; 2] = [0.316_227_766_016_837_94, 1.0];

/// How `--angle-map` values are read.
#[derive(
    Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum, serde::Serialize, serde::Deserialize,
)]
#[serde(rename_all = "kebab-case")]
pub enum AngleMapKind {
    /// Grey images (one channel, or R = G = B everywhere) are angles; others (two channels,
    /// grey+alpha, colour) direction maps.
    Auto,
    /// value·π is the angle from +t towards +b (the red channel of a colour image).
    Angle,
    /// (R, G) (grey and alpha for a grey+alpha PNG) hold (x, y)·0.5 + 0.5; a single-channel
    /// image is refused.
    Direction,
}

/// Parameters of the bake: CLI flags and RON keys alike.
#[derive(Clone, Debug, PartialEq, clap::Args, serde::Serialize, serde::Deserialize)]
#[group(id = "tpr_map::Params")]
#[serde(deny_unknown_fields, default)]
pub struct Params {
    /// Output size W or WxH (with --angle-map: defaults to the map's size).
    #[arg(long, value_name = "W[xH]")]
    pub size: Option<Size>,
    /// Direction-field preset, NAME[:ARGS]:
    ///   constant:DEG — the tangent turned by DEG about n (from +t towards +b);
    ///   linear:DEG — straight strokes at DEG counter-clockwise from the image's +x, as seen on
    ///     the image (constant:DEG for +y-up tangent spaces);
    ///   radial[:CX,CY] — concentric circles about (CX, CY) in texture coordinates (v down,
    ///     default 0.5,0.5), counter-clockwise: a CD, a pan bottom;
    ///   spiral[:CX,CY,TURNS] — the Archimedean spiral r = φ/(4π·TURNS) about (CX, CY): TURNS
    ///     grooves from the centre to half the larger side; 0 gives straight rays, negative
    ///     winds the other way (default 0.5,0.5,8);
    ///   wave — Marcolongo 2020's example, x = cos πv, y = sin πv.
    #[arg(long, value_name = "NAME[:ARGS]", conflicts_with_all = ["angle_map", "expr"])]
    pub preset: Option<Preset>,
    /// Direction field from an image: a grey angle map (value·π from +t towards +b, in [0, π))
    /// or a two-channel direction map; resampled as a line field if --size differs.
    #[arg(long, value_name = "IMG", conflicts_with = "expr")]
    pub angle_map: Option<PathBuf>,
    /// How --angle-map is read.
    #[arg(long, value_enum, default_value_t = AngleMapKind::Auto)]
    pub angle_map_kind: AngleMapKind,
    /// Direction field from expressions in u, v (texel centres): "x = ...; y = ...".
    #[arg(long, value_name = "X_AND_Y")]
    pub expr: Option<String>,
    /// Constant perceptual roughness along t and b [default: 0.31623,1 = the thesis's α 0.1, 1].
    #[arg(long, value_name = "RX,RY", conflicts_with_all = ["roughness_expr", "roughness_map"])]
    pub roughness: Option<Roughness>,
    /// Roughness from expressions in u, v and the final direction x, y: "rx = ...; ry = ...".
    #[arg(long, value_name = "RX_AND_RY", conflicts_with = "roughness_map")]
    pub roughness_expr: Option<String>,
    /// Roughness from an image: R → along t, G → along b (a grey image gives both);
    /// bilinearly resampled if its size differs.
    #[arg(long, value_name = "IMG")]
    pub roughness_map: Option<PathBuf>,
    /// Turn every direction by DEG about n (from +t towards +b) after the source.
    #[arg(
        long,
        value_name = "DEG",
        default_value_t = 0.0,
        allow_negative_numbers = true
    )]
    pub rotate: f64,
    /// Store α = r² in B, A (the thesis's convention) instead of perceptual roughness.
    #[arg(long)]
    pub store_alpha: bool,
    /// Tangent-space +y points down the image (DirectX): mirrors the image-space presets
    /// (radial, spiral, linear).
    #[arg(long)]
    pub y_down: bool,
    /// PNG output bit depth: 16 or 8.
    #[arg(long, value_name = "8|16", default_value_t = 16)]
    pub bits: u8,
    /// EXR output: 16-bit half floats instead of 32-bit.
    #[arg(long)]
    pub half: bool,
    /// Set NaN/Inf texels of --angle-map and --roughness-map to 0 instead of refusing them.
    #[arg(long)]
    pub sanitize: bool,
}

impl Default for Params {
    fn default() -> Self {
        ibl_core::params::clap_defaults()
    }
}

impl Params {
    /// Checks the parameters (one direction source, ranges) before any input is read.
    pub fn validate(&self) -> ibl_core::Result<()> {
        let sources = self.preset.is_some() as u8
            + self.angle_map.is_some() as u8
            + self.expr.is_some() as u8;
        if sources != 1 {
            return Err(Error::param(
                "give exactly one direction source: --preset, --angle-map or --expr",
            ));
        }
        if self.angle_map.is_none() && self.size.is_none() {
            return Err(Error::param(
                "--size W[xH] is needed with --preset and --expr",
            ));
        }
        let roughness = self.roughness.is_some() as u8
            + self.roughness_expr.is_some() as u8
            + self.roughness_map.is_some() as u8;
        if roughness > 1 {
            return Err(Error::param(
                "give at most one of --roughness, --roughness-expr, --roughness-map",
            ));
        }
        if self.bits != 8 && self.bits != 16 {
            return Err(Error::param(format!("--bits {} (use 8 or 16)", self.bits)));
        }
        if !self.rotate.is_finite() {
            return Err(Error::param("--rotate must be a finite number of degrees"));
        }
        if let Some(Preset::Spiral { turns, .. }) = self.preset {
            if turns.abs() > 1e6 {
                return Err(Error::param(
                    "spiral TURNS above 1e6 would alias at any texture size",
                ));
            }
        }
        Ok(())
    }

    /// [`Params::validate`] plus the checks on the output path (extension, bits, half).
    pub fn validate_output(&self, out: &Path) -> ibl_core::Result<()> {
        self.validate()?;
        crate::output::validate(out, self.bits, self.half, "TPR maps")
    }

    /// Compiles the expressions (errors carry the flag and the column).
    pub fn compile(&self) -> Result<(Option<Program>, Option<Program>)> {
        let dir =
            match &self.expr {
                Some(src) => Some(expr::compile(src, &["u", "v"], &["x", "y"]).map_err(
                    |source| crate::Error::Expr {
                        flag: "--expr",
                        source,
                    },
                )?),
                None => None,
            };
        let rough = match &self.roughness_expr {
            Some(src) => Some(
                expr::compile(src, &["u", "v", "x", "y"], &["rx", "ry"]).map_err(|source| {
                    crate::Error::Expr {
                        flag: "--roughness-expr",
                        source,
                    }
                })?,
            ),
            None => None,
        };
        Ok((dir, rough))
    }
}

/// Images the bake reads, loaded by the caller (or by [`load_inputs`]).
#[derive(Clone, Debug, Default)]
pub struct Inputs {
    /// The angle map given with `--angle-map`, if any.
    pub angle_map: Option<LoadedMap>,
    /// The roughness map given with `--roughness-map`, if any.
    pub roughness_map: Option<LoadedMap>,
    /// What loading them met (negative values clamped, NaN/Inf set to 0 with `--sanitize`),
    /// one line each; the bake's [`TprStats::warnings`] repeats them.
    pub warnings: Vec<String>,
}

/// Reads a map and applies the input policy of docs/CONVENTIONS.md: NaN/Inf texels are an error
/// unless `sanitize` (then 0), negative values are clamped to 0 (both reported).
fn load_map(
    path: &Path,
    sanitize: bool,
    warnings: &mut Vec<String>,
) -> ibl_core::Result<LoadedMap> {
    let mut map = crate::map::load(path)?;
    let report = check_texels(&mut map.image, path, sanitize)?;
    warnings.extend(map.read_as.clone());
    warnings.extend(report.warnings(path));
    Ok(map)
}

/// Reads the images named by the parameters.
pub fn load_inputs(params: &Params) -> ibl_core::Result<Inputs> {
    let mut warnings = Vec::new();
    let mut load = |p: &Option<PathBuf>| {
        p.as_deref()
            .map(|p| load_map(p, params.sanitize, &mut warnings))
            .transpose()
    };
    let angle_map = load(&params.angle_map)?;
    let roughness_map = load(&params.roughness_map)?;
    Ok(Inputs {
        angle_map,
        roughness_map,
        warnings,
    })
}

/// What the bake met.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct TprStats {
    /// Output columns.
    pub width: usize,
    /// Output rows.
    pub height: usize,
    /// Where the directions came from (preset, expression or angle map).
    pub source: String,
    /// Zero-length directions replaced by +x (the centre of a radial field, ...).
    pub zero_length: u64,
    /// NaN/∞ directions (expression domain errors) replaced by +x.
    pub non_finite: u64,
    /// Roughness values outside [0, 1] clamped.
    pub roughness_clamped: u64,
    /// The angle map was resampled to the output size.
    pub resampled: bool,
    /// What loading the input maps met ([`Inputs::warnings`]; shown by [`Self::warnings`],
    /// so not repeated in the JSON stats).
    #[serde(skip)]
    pub input_warnings: Vec<String>,
}

impl TprStats {
    /// The one-line warnings of the bake (input warnings first).
    pub fn warnings(&self) -> Vec<String> {
        let mut w = self.input_warnings.clone();
        if self.zero_length > 0 {
            w.push(format!(
                "{} texel(s) with a zero-length direction were given +x",
                self.zero_length
            ));
        }
        if self.non_finite > 0 {
            w.push(format!(
                "{} texel(s) with a NaN/infinite direction were given +x",
                self.non_finite
            ));
        }
        if self.roughness_clamped > 0 {
            w.push(format!(
                "{} roughness value(s) outside [0, 1] were clamped",
                self.roughness_clamped
            ));
        }
        w
    }
}

/// The source of directions, resolved for a size.
enum Field<'a> {
    Preset(&'a Preset),
    Expr(&'a Program),
    /// One unnormalised tangent per output texel.
    Texels(Vec<[f64; 2]>),
}

/// Whether `auto` reads a map as angles: one channel, or three or more with R = G = B
/// everywhere (within 2/255: lossy codecs leave a little chroma on grey images saved as
/// colour). Two channels (an RG EXR) and grey+alpha PNGs are direction maps.
fn reads_as_grey(map: &LoadedMap) -> bool {
    let img = &map.image;
    match img.channels {
        1 => true,
        2 => false,
        _ => {
            !map.grey_alpha
                && img.data.chunks_exact(img.channels).all(|t| {
                    (t[0] - t[1]).abs() <= 2.0 / 255.0 && (t[1] - t[2]).abs() <= 2.0 / 255.0
                })
        }
    }
}

/// Directions from an angle or direction map, at the output size.
fn map_directions(
    map: &LoadedMap,
    kind: AngleMapKind,
    w: usize,
    h: usize,
) -> ibl_core::Result<(Vec<[f64; 2]>, bool)> {
    let img = &map.image;
    let as_angle = match kind {
        AngleMapKind::Auto => reads_as_grey(map),
        AngleMapKind::Angle => true,
        AngleMapKind::Direction => false,
    };
    if !as_angle && img.channels < 2 {
        return Err(Error::unsupported(
            &map.path,
            "a single channel cannot be a direction map (x, y need R and G, or grey and alpha): use --angle-map-kind angle",
        ));
    }
    let yi = if map.grey_alpha { 3 } else { 1 };
    let src: Vec<[f64; 2]> = img
        .data
        .chunks_exact(img.channels)
        .map(|t| {
            if as_angle {
                tangent_from_angle_value(t[0] as f64)
            } else {
                [2.0 * t[0] as f64 - 1.0, 2.0 * t[yi] as f64 - 1.0]
            }
        })
        .collect();
    if (img.width, img.height) == (w, h) {
        return Ok((src, false));
    }
    let unit: Vec<[f64; 2]> = src
        .iter()
        .map(|d| {
            let l = d[0].hypot(d[1]);
            if l > 0.0 && l.is_finite() {
                [d[0] / l, d[1] / l]
            } else {
                [0.0, 0.0]
            }
        })
        .collect();
    Ok((
        resample_line_field(&unit, img.width, img.height, w, h),
        true,
    ))
}

/// Bilinear sample of channel `c` at texture coordinates (u, v), texel centres, clamped.
fn sample(img: &Image, c: usize, u: f64, v: f64) -> f64 {
    let (x0, x1, fx) = taps(u, img.width);
    let (y0, y1, fy) = taps(v, img.height);
    let at = |x: usize, y: usize| img.texel(x, y)[c.min(img.channels - 1)] as f64;
    (at(x0, y0) * (1.0 - fx) + at(x1, y0) * fx) * (1.0 - fy)
        + (at(x0, y1) * (1.0 - fx) + at(x1, y1) * fx) * fy
}

/// What the bake produced, before anything is written.
pub struct Baked {
    /// Encoded files, ready for [`io::write_many_atomic`].
    pub files: Vec<(PathBuf, Vec<u8>)>,
    /// What the bake met.
    pub stats: TprStats,
}

/// The map itself: RGBA with RG = unit tangent·0.5 + 0.5 and BA = roughnesses (or α).
pub fn generate(
    params: &Params,
    inputs: &Inputs,
    progress: &dyn Progress,
) -> Result<(Image, TprStats)> {
    params.validate()?;
    let (dir_prog, rough_prog) = params.compile()?;
    let (w, h) = match (params.size, &inputs.angle_map) {
        (Some(s), _) => (s.width, s.height),
        (None, Some(m)) => (m.image.width, m.image.height),
        (None, None) => {
            return Err(Error::param("--size W[xH] is needed with --preset and --expr").into())
        }
    };
    Image::check_size(Path::new("output"), w as u64, h as u64)?;
    let mut stats = TprStats {
        width: w,
        height: h,
        input_warnings: inputs.warnings.clone(),
        ..Default::default()
    };
    let field = match (&params.preset, &dir_prog, &params.angle_map) {
        (Some(p), _, _) => {
            stats.source = format!("preset {p}");
            Field::Preset(p)
        }
        (_, Some(prog), _) => {
            stats.source = format!("expr {:?}", prog.source);
            Field::Expr(prog)
        }
        (_, _, Some(path)) => {
            let map = inputs
                .angle_map
                .as_ref()
                .ok_or_else(|| Error::param(format!("{}: angle map not loaded", path.display())))?;
            let (dirs, resampled) = map_directions(map, params.angle_map_kind, w, h)?;
            stats.source = format!("angle map {}", path.display());
            stats.resampled = resampled;
            Field::Texels(dirs)
        }
        _ => {
            return Err(Error::param(
                "give exactly one direction source: --preset, --angle-map or --expr",
            )
            .into())
        }
    };
    if params.roughness_map.is_some() && inputs.roughness_map.is_none() {
        return Err(Error::param("roughness map not loaded").into());
    }
    let constant = params.roughness.map(|r| r.0).unwrap_or(DEFAULT_ROUGHNESS);
    let scale = aspect_scale(w, h);
    let (rot_s, rot_c) = params.rotate.to_radians().sin_cos();
    let mut out = Image::new(w, h, 4);
    type RowResult = std::result::Result<[u64; 3], (usize, usize)>;
    let rows: Vec<RowResult> = ibl_core::traverse::map_image_rows_with(
        &mut out.data,
        w * 4,
        w,
        "tpr texels",
        progress,
        Scratch::default,
        |scratch, j, row| {
            let v = (j as f64 + 0.5) / h as f64;
            let mut counts = [0u64; 3];
            let mut pair = [0.0f64; 2];
            for (i, px) in row.chunks_exact_mut(4).enumerate() {
                let u = (i as f64 + 0.5) / w as f64;
                let d = match &field {
                    Field::Preset(p) => p.field(u, v, scale, params.y_down),
                    Field::Expr(prog) => {
                        prog.eval(&[u, v], scratch, &mut pair);
                        pair
                    }
                    Field::Texels(t) => t[j * w + i],
                };
                let d = if params.rotate != 0.0 {
                    [rot_c * d[0] - rot_s * d[1], rot_s * d[0] + rot_c * d[1]]
                } else {
                    d
                };
                let len = d[0].hypot(d[1]);
                let t = if !len.is_finite() || d[0].is_nan() || d[1].is_nan() {
                    counts[1] += 1;
                    [1.0, 0.0]
                } else if len == 0.0 {
                    counts[0] += 1;
                    [1.0, 0.0]
                } else {
                    [d[0] / len, d[1] / len]
                };
                let mut r = match (&rough_prog, &inputs.roughness_map) {
                    (Some(prog), _) => {
                        prog.eval(&[u, v, t[0], t[1]], scratch, &mut pair);
                        pair
                    }
                    (None, Some(map)) => [sample(&map.image, 0, u, v), sample(&map.image, 1, u, v)],
                    _ => constant,
                };
                for r in &mut r {
                    if r.is_nan() {
                        return Err((i, j));
                    }
                    if !(0.0..=1.0).contains(r) {
                        counts[2] += 1;
                        *r = r.clamp(0.0, 1.0);
                    }
                    if params.store_alpha {
                        *r *= *r;
                    }
                }
                px.copy_from_slice(&[
                    (t[0] * 0.5 + 0.5) as f32,
                    (t[1] * 0.5 + 0.5) as f32,
                    r[0] as f32,
                    r[1] as f32,
                ]);
            }
            Ok(counts)
        },
    );
    for r in rows {
        match r {
            Ok([z, n, c]) => {
                stats.zero_length += z;
                stats.non_finite += n;
                stats.roughness_clamped += c;
            }
            Err((i, j)) => {
                return Err(Error::param(format!(
                    "--roughness-expr gives NaN at texel ({i}, {j}) (u = {:.4}, v = {:.4})",
                    (i as f64 + 0.5) / w as f64,
                    (j as f64 + 0.5) / h as f64
                ))
                .into())
            }
        }
    }
    Ok((out, stats))
}

/// Generates and encodes the map for `out` (.png or .exr).
pub fn run(params: &Params, inputs: &Inputs, out: &Path, progress: &dyn Progress) -> Result<Baked> {
    params.validate_output(out)?;
    let maps = [&inputs.angle_map, &inputs.roughness_map];
    crate::output::refuse_overwriting_input(
        out,
        maps.into_iter().flatten().map(|m| m.path.as_path()),
    )?;
    let (image, stats) = generate(params, inputs, progress)?;
    let opts = crate::output::write_options(params.bits, params.half);
    let bytes = io::encode_image(out, &image, &opts)?;
    Ok(Baked {
        files: vec![(out.to_path_buf(), bytes)],
        stats,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use ibl_core::progress::NoProgress;
    use std::f64::consts::PI;

    fn params(src: &str) -> Params {
        let mut p = Params {
            size: Some(Size {
                width: 24,
                height: 16,
            }),
            ..Default::default()
        };
        if src.contains('=') {
            p.expr = Some(src.to_string());
        } else {
            p.preset = Some(src.parse().unwrap());
        }
        p
    }

    fn texel(img: &Image, i: usize, j: usize) -> [f64; 4] {
        let t = img.texel(i, j);
        [
            t[0] as f64 * 2.0 - 1.0,
            t[1] as f64 * 2.0 - 1.0,
            t[2] as f64,
            t[3] as f64,
        ]
    }

    #[test]
    fn defaults_agree_between_clap_serde_and_default() {
        // RON as pipelines are read: `size: 64` for an Option, no `Some(...)`.
        let opts = ron::Options::default()
            .with_default_extension(ron::extensions::Extensions::IMPLICIT_SOME);
        let from_ron: Params = opts.from_str("()").unwrap();
        assert_eq!(from_ron, Params::default());
        assert!(opts.from_str::<Params>("(presets: \"wave\")").is_err());
        let p: Params = opts
            .from_str("(size: \"64x32\", preset: \"radial:0.5,0.5\", roughness: (0.2, 0.4))")
            .unwrap();
        assert_eq!(
            p.size,
            Some(Size {
                width: 64,
                height: 32
            })
        );
        assert_eq!(p.roughness, Some(Roughness([0.2, 0.4])));
        let p: Params = opts
            .from_str("(size: 64, expr: \"x=1;y=0\", roughness: \"0.5\")")
            .unwrap();
        assert_eq!(
            (p.size.unwrap().height, p.roughness.unwrap().0),
            (64, [0.5, 0.5])
        );
        assert!(opts.from_str::<Params>("(roughness: (0.2, 1.5))").is_err());
        assert!(opts.from_str::<Params>("(size: \"0x4\")").is_err());
    }

    #[test]
    fn sources_and_sizes_are_validated() {
        assert!(Params::default().validate().is_err());
        assert!(Params {
            preset: Some(Preset::Wave),
            ..Default::default()
        }
        .validate()
        .is_err());
        let both = Params {
            expr: Some("x=1;y=0".into()),
            ..params("wave")
        };
        assert!(both.validate().is_err());
        assert!(params("wave").validate_output(Path::new("t.tga")).is_err());
        assert!("100000".parse::<Size>().is_err() && "12x".parse::<Size>().is_err());
        assert_eq!(
            "12×7".parse::<Size>().unwrap(),
            Size {
                width: 12,
                height: 7
            }
        );
    }

    #[test]
    fn wave_matches_the_thesis_and_the_equal_expression() {
        let (a, _) = generate(&params("wave"), &Inputs::default(), &NoProgress).unwrap();
        let (b, _) = generate(
            &params("x = cos(pi*v); y = sin(pi*v)"),
            &Inputs::default(),
            &NoProgress,
        )
        .unwrap();
        assert_eq!(a, b);
        let mut worst = 0.0f64;
        for j in 0..16 {
            let v = (j as f64 + 0.5) / 16.0;
            for i in 0..24 {
                let t = texel(&a, i, j);
                worst = worst
                    .max((t[0] - (PI * v).cos()).abs())
                    .max((t[1] - (PI * v).sin()).abs());
                assert!((t[2] - DEFAULT_ROUGHNESS[0]).abs() < 1e-7 && t[3] == 1.0);
            }
        }
        eprintln!("wave vs cos πv, sin πv: max {worst:.2e}");
        assert!(worst < 1e-7);
    }

    #[test]
    fn rotate_turns_every_direction() {
        let mut p = params("constant:10");
        p.rotate = 80.0;
        let (img, _) = generate(&p, &Inputs::default(), &NoProgress).unwrap();
        let t = texel(&img, 3, 5);
        assert!(t[0].abs() < 1e-6 && (t[1] - 1.0).abs() < 1e-6, "{t:?}");
    }

    #[test]
    fn radial_centre_falls_back_to_plus_x_and_is_counted() {
        // 5×5: the middle texel centre is exactly (0.5, 0.5).
        let p = Params {
            size: Some(Size {
                width: 5,
                height: 5,
            }),
            preset: Some(Preset::Radial { cx: 0.5, cy: 0.5 }),
            ..Default::default()
        };
        let (img, stats) = generate(&p, &Inputs::default(), &NoProgress).unwrap();
        assert_eq!(stats.zero_length, 1);
        assert_eq!(&texel(&img, 2, 2)[..2], &[1.0, 0.0]);
        // Right of the centre the circle runs up the image: +y (y up).
        let t = texel(&img, 4, 2);
        assert!(t[0].abs() < 1e-7 && (t[1] - 1.0).abs() < 1e-7, "{t:?}");
        let down = Params { y_down: true, ..p };
        let (img, _) = generate(&down, &Inputs::default(), &NoProgress).unwrap();
        assert!((texel(&img, 4, 2)[1] + 1.0).abs() < 1e-7);
    }

    #[test]
    fn expression_domain_errors_fall_back_and_roughness_expressions_work() {
        let mut p = params("x = sqrt(u - 0.5); y = 0");
        p.roughness_expr = Some("rx = u; ry = 2 * v + x * 0".into());
        let (img, stats) = generate(&p, &Inputs::default(), &NoProgress).unwrap();
        // u < 0.5 for 12 of 24 columns: sqrt of a negative number.
        assert_eq!(stats.non_finite, 12 * 16);
        // ry = 2v > 1 for v > 0.5: 8 rows × 24 columns clamped.
        assert_eq!(stats.roughness_clamped, 8 * 24);
        let t = texel(&img, 0, 0);
        assert_eq!(&t[..2], &[1.0, 0.0]);
        assert!((t[2] - 0.5 / 24.0).abs() < 1e-7);
        // store_alpha squares.
        p.store_alpha = true;
        let (img, _) = generate(&p, &Inputs::default(), &NoProgress).unwrap();
        assert!((texel(&img, 0, 0)[2] - (0.5f64 / 24.0).powi(2)).abs() < 1e-8);
        // NaN roughness is an error naming the texel.
        let mut bad = params("wave");
        bad.roughness_expr = Some("rx = sqrt(-u); ry = 0".into());
        let e = generate(&bad, &Inputs::default(), &NoProgress)
            .err()
            .unwrap();
        assert!(e.to_string().contains("NaN at texel (0, 0)"), "{e}");
        // Parse errors carry the flag and the column.
        let e = generate(
            &params("x = cos(pi*v; y = 0"),
            &Inputs::default(),
            &NoProgress,
        )
        .err()
        .unwrap();
        assert_eq!(
            e.to_string(),
            "--expr: column 13: expected ')' to close the '(' at column 8, found ';'"
        );
    }

    fn map(img: Image, grey_alpha: bool) -> LoadedMap {
        LoadedMap {
            image: img,
            grey_alpha,
            path: "m.png".into(),
            read_as: None,
        }
    }

    #[test]
    fn an_angle_map_read_against_its_name_is_one_warning() {
        let d = tempfile::tempdir().unwrap();
        let img = Image::from_data(4, 2, 1, vec![0.25; 8]).unwrap();
        let exr = ibl_core::io::encode_image(
            Path::new("a.exr"),
            &img,
            &ibl_core::io::WriteOptions::default(),
        )
        .unwrap();
        let named_png = d.path().join("angle.png");
        std::fs::write(&named_png, &exr).unwrap();
        let inputs = load_inputs(&Params {
            angle_map: Some(named_png.clone()),
            ..Default::default()
        })
        .unwrap();
        assert_eq!(
            inputs.warnings,
            [format!(
                "{}: holds OpenEXR data but is named .png; read as OpenEXR (by its content)",
                named_png.display()
            )]
        );
        // The texels are the EXR's, not a failed PNG decode.
        assert_eq!(inputs.angle_map.unwrap().image.data[0], 0.25);
        let named_exr = d.path().join("angle.exr");
        std::fs::write(&named_exr, &exr).unwrap();
        let inputs = load_inputs(&Params {
            angle_map: Some(named_exr),
            ..Default::default()
        })
        .unwrap();
        assert!(inputs.warnings.is_empty(), "{:?}", inputs.warnings);
    }

    #[test]
    fn angle_and_direction_maps() {
        // Grey angle map: value·π.
        let mut grey = Image::new(4, 2, 1);
        for (k, v) in grey.data.iter_mut().enumerate() {
            *v = k as f32 / 8.0;
        }
        let p = Params {
            angle_map: Some("a.png".into()),
            ..Default::default()
        };
        let inputs = Inputs {
            angle_map: Some(map(grey.clone(), false)),
            ..Default::default()
        };
        let (img, stats) = generate(&p, &inputs, &NoProgress).unwrap();
        assert_eq!((stats.width, stats.height, stats.resampled), (4, 2, false));
        for k in 0..8 {
            let t = texel(&img, k % 4, k / 4);
            let a = k as f64 / 8.0 * PI;
            assert!((t[0] - a.cos()).abs() < 1e-7 && (t[1] - a.sin()).abs() < 1e-7);
        }
        // The same angles saved as RGB grey are still angles; as a direction map they are not.
        let rgb = grey.to_channels(3);
        let inputs = Inputs {
            angle_map: Some(map(rgb.clone(), false)),
            ..Default::default()
        };
        assert_eq!(generate(&p, &inputs, &NoProgress).unwrap().0, img);
        // Direction map (RG): (0.5, 1) is +y; grey+alpha: x from grey, y from alpha.
        let dir = Image::from_data(1, 1, 3, vec![0.5, 1.0, 0.0]).unwrap();
        let inputs = Inputs {
            angle_map: Some(map(dir, false)),
            ..Default::default()
        };
        let t = texel(&generate(&p, &inputs, &NoProgress).unwrap().0, 0, 0);
        assert!(t[0].abs() < 1e-7 && (t[1] - 1.0).abs() < 1e-7);
        let la = Image::from_data(1, 1, 4, vec![1.0, 1.0, 1.0, 0.5]).unwrap();
        let inputs = Inputs {
            angle_map: Some(map(la, true)),
            ..Default::default()
        };
        let t = texel(&generate(&p, &inputs, &NoProgress).unwrap().0, 0, 0);
        assert!((t[0] - 1.0).abs() < 1e-7 && t[1].abs() < 1e-7);
        // Two channels (an RG EXR) are a direction map, even where R = G.
        let rg = Image::from_data(2, 1, 2, vec![1.0, 1.0, 0.5, 0.0]).unwrap();
        let inputs = Inputs {
            angle_map: Some(map(rg, false)),
            ..Default::default()
        };
        let img2 = generate(&p, &inputs, &NoProgress).unwrap().0;
        let (a, b) = (texel(&img2, 0, 0), texel(&img2, 1, 0));
        let s = std::f64::consts::FRAC_1_SQRT_2;
        assert!((a[0] - s).abs() < 1e-7 && (a[1] - s).abs() < 1e-7, "{a:?}");
        assert!(b[0].abs() < 1e-7 && (b[1] + 1.0).abs() < 1e-7, "{b:?}");
        // One channel read as a direction map: an error, not +x everywhere.
        let inputs = Inputs {
            angle_map: Some(map(grey.clone(), false)),
            ..Default::default()
        };
        let direction = Params {
            angle_map_kind: AngleMapKind::Direction,
            ..p.clone()
        };
        let e = generate(&direction, &inputs, &NoProgress).err().unwrap();
        assert!(e.to_string().contains("single channel"), "{e}");
        assert_eq!(e.class(), ibl_core::error::ErrorClass::Unsupported);
        // Resampled to another size: a constant angle stays that angle.
        let flat = Image::from_data(2, 2, 1, vec![0.25; 4]).unwrap();
        let p2 = Params {
            size: Some(Size {
                width: 5,
                height: 3,
            }),
            ..p
        };
        let inputs = Inputs {
            angle_map: Some(map(flat, false)),
            ..Default::default()
        };
        let (img, stats) = generate(&p2, &inputs, &NoProgress).unwrap();
        assert!(stats.resampled);
        for t in img.data.chunks(4) {
            assert!((t[0] as f64 * 2.0 - 1.0 - (PI / 4.0).cos()).abs() < 1e-6);
        }
    }

    #[test]
    fn roughness_map_channels_and_resampling() {
        let rm = Image::from_data(2, 1, 3, vec![0.2, 0.6, 0.0, 0.4, 0.8, 0.0]).unwrap();
        let mut p = params("constant:0");
        p.size = Some(Size {
            width: 4,
            height: 1,
        });
        p.roughness_map = Some("r.png".into());
        let inputs = Inputs {
            angle_map: None,
            roughness_map: Some(map(rm, false)),
            ..Default::default()
        };
        let (img, _) = generate(&p, &inputs, &NoProgress).unwrap();
        // Output texel centres 1/8, 3/8, 5/8, 7/8 → source x = 0.25·... clamped bilinear.
        let want_r = [0.2, 0.25, 0.35, 0.4];
        for (i, w) in want_r.iter().enumerate() {
            let t = texel(&img, i, 0);
            assert!(
                (t[2] - w).abs() < 1e-6 && (t[3] - (w + 0.4)).abs() < 1e-6,
                "{i}: {t:?}"
            );
        }
    }

    #[test]
    fn outputs_round_trip_through_png16() {
        let p = params("spiral:0.3,0.6,2");
        let baked = run(&p, &Inputs::default(), Path::new("t.png"), &NoProgress).unwrap();
        let back = io::decode_image(
            Path::new("t.png"),
            &baked.files[0].1,
            io::ColorSpace::Linear,
        )
        .unwrap();
        assert_eq!(back.channels, 4);
        let (img, _) = generate(&p, &Inputs::default(), &NoProgress).unwrap();
        let worst = img
            .data
            .iter()
            .zip(&back.data)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0f32, f32::max);
        assert!(worst <= 0.5 / 65535.0 + 1e-7, "{worst}");
    }
}
