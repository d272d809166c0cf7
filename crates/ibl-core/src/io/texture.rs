//! Cube chains as GPU texture payloads: every level's faces encoded in one [`PixelFormat`],
//! with what the encoding cost against the float data. The containers (KTX2, DDS, KTX1) only
//! frame a [`Payload`]; they never see texels.

use super::format::{Bc6hQuality, PixelFormat};
use super::packed;
use crate::cube::{CubeMips, Cubemap};
use crate::error::{Error, Result};
use crate::image::Image;
use rayon::prelude::*;
use std::path::Path;
use std::time::Instant;

/// Encoded images of a texture: a cube (6 faces) or a 2D image (1), every level.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Payload {
    /// How every texel is encoded.
    pub format: PixelFormat,
    /// Width of level 0 (faces are square for cubes).
    pub width: usize,
    /// Height of level 0.
    pub height: usize,
    /// 6 for a cube (faces +X −X +Y −Y +Z −Z), 1 for a 2D image.
    pub faces: usize,
    /// `levels[l][f]`: the bytes of face `f` of level `l`, [`PixelFormat::image_bytes`] long.
    pub levels: Vec<Vec<Vec<u8>>>,
}

impl Payload {
    /// Width and height of level `l` (halved per level, at least 1).
    pub(crate) fn level_dims(&self, l: usize) -> (usize, usize) {
        ((self.width >> l).max(1), (self.height >> l).max(1))
    }

    /// Bytes of one face of level `l`.
    pub(crate) fn face_bytes(&self, l: usize) -> usize {
        let (w, h) = self.level_dims(l);
        self.format.image_bytes(w, h)
    }

    /// Reserves against the run's memory budget what reading `levels` levels of this
    /// payload's shape takes, before any level is copied or inflated: the encoded bytes twice
    /// (inflated or copied, then split into faces) and the RGB f32 texels they decode to.
    pub(crate) fn reserve(
        &self,
        path: &Path,
        container: &str,
        levels: usize,
    ) -> Result<super::budget::Reservation> {
        let (mut encoded, mut texels) = (0u64, 0u64);
        for l in 0..levels {
            let (w, h) = self.level_dims(l);
            encoded = encoded.saturating_add(self.face_bytes(l) as u64 * self.faces as u64);
            texels = texels.saturating_add(w as u64 * h as u64 * self.faces as u64);
        }
        let what = format!(
            "decoding a {}x{} {container} {} of {levels} level(s) in {}",
            self.width,
            self.height,
            if self.faces == 6 { "cube" } else { "image" },
            self.format.name()
        );
        super::budget::reserve(
            path,
            &what,
            encoded
                .saturating_mul(2)
                .saturating_add(texels.saturating_mul(12)),
        )
    }

    /// Checks that the faces hold exactly the bytes their format and size need.
    pub fn check(&self, path: &Path) -> Result<()> {
        for (l, faces) in self.levels.iter().enumerate() {
            let want = self.face_bytes(l);
            if faces.len() != self.faces || faces.iter().any(|f| f.len() != want) {
                return Err(Error::invalid(
                    path,
                    format!(
                        "level {l} does not hold {} images of {want} bytes",
                        self.faces
                    ),
                ));
            }
        }
        Ok(())
    }
}

/// The shape a container header declares, as every container reader checks it before
/// allocating: one 2D image or one cube, no depth or array layers, square cube faces, within
/// the image size limit, and no more levels than halving allows. `what` names the container
/// in messages. Returns (height, levels) with KTX's 0s read as 1.
#[allow(clippy::too_many_arguments)] // one header's fields, named at the call
pub(crate) fn check_shape(
    path: &Path,
    what: &str,
    faces: u32,
    width: u32,
    height: u32,
    depth: u32,
    layers: u32,
    levels: u32,
) -> Result<(u32, u32)> {
    if depth > 1 || layers > 1 || !(faces == 1 || faces == 6) || width == 0 {
        return Err(Error::unsupported(
            path,
            format!("{what} with {faces} faces, {width}x{height}x{depth}, {layers} layers (need a cube or a 2D image)"),
        ));
    }
    let height = height.max(1);
    let bad = |why: String| Error::invalid(path, format!("not a valid {what} file: {why}"));
    if faces == 6 && width != height {
        return Err(bad(format!(
            "cube faces of {width}x{height} are not square"
        )));
    }
    crate::image::Image::check_size(path, width as u64, height as u64 * faces as u64)?;
    let max_levels = 32 - width.max(height).leading_zeros();
    let levels = levels.max(1);
    if levels > max_levels {
        return Err(bad(format!(
            "{levels} levels, but a {width}x{height} image has at most {max_levels}"
        )));
    }
    Ok((height, levels))
}

/// What encoding one level cost, against the float texels it came from.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct LevelEncoding {
    /// Mip level (0 the largest).
    pub level: usize,
    /// Face size of that level in texels.
    pub size: usize,
    /// Mean over texels and channels of |decoded − float| / max(m, ε), m the texel's
    /// largest float channel and ε = 10⁻³ × the level's mean m (see [`relative_errors`]).
    pub mean_rel: f64,
    /// The largest such error.
    pub max_rel: f64,
    /// How the BC6H blocks were searched when not by the `--bc6h-quality` profile: levels of
    /// at most 8² texels a face are searched exhaustively (see `io::bc6h::encode_searched`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub bc6h_search: Option<&'static str>,
    /// Channel values outside [0, the format's largest value], clamped when encoded.
    pub clamped: usize,
    /// Bytes of the level (all faces), before supercompression.
    pub bytes: usize,
    /// Wall-clock seconds the level took to encode (not part of any file: outputs are
    /// identical from run to run).
    #[serde(skip)]
    pub seconds: f64,
}

/// How [`relative_errors`] measures: written beside the numbers in sidecars.
pub const ERROR_METRIC: &str = "mean and max over texels and channels of |decoded - float| / max(m, eps), m = the texel's largest float channel, eps = 1e-3 x the level's mean m";

/// Encodes every level of a chain, faces in parallel, and measures each level's error by
/// decoding what was written.
pub fn encode_chain(
    mips: &CubeMips,
    format: PixelFormat,
    quality: Bc6hQuality,
) -> (Payload, Vec<LevelEncoding>) {
    let jobs: Vec<(usize, usize)> = (0..mips.levels.len())
        .flat_map(|l| (0..6).map(move |f| (l, f)))
        .collect();
    // Ordered collect: the bytes do not depend on which thread encoded which face.
    let encoded: Vec<(Vec<u8>, usize, f64)> = jobs
        .par_iter()
        .map(|&(l, f)| {
            let t = Instant::now();
            let face = &mips.levels[l].faces[f];
            let (bytes, clamped) = encode_image(face, format, quality);
            (bytes, clamped, t.elapsed().as_secs_f64())
        })
        .collect();
    let mut levels = Vec::with_capacity(mips.levels.len());
    let mut report = Vec::with_capacity(mips.levels.len());
    // The faces' bytes are moved into the payload, not copied (a copy of the whole chain on
    // one thread was most of this function's serial time).
    let mut encoded = encoded.into_iter();
    for (l, cube) in mips.levels.iter().enumerate() {
        let faces: Vec<(Vec<u8>, usize, f64)> = encoded.by_ref().take(6).collect();
        let decoded: Vec<Image> = if format.is_lossless() {
            Vec::new()
        } else {
            faces
                .par_iter()
                .map(|(b, _, _)| decode_image(b, format, cube.size, cube.size))
                .collect()
        };
        let (mean_rel, max_rel) = if format.is_lossless() {
            (0.0, 0.0)
        } else {
            relative_errors(&cube.faces, &decoded)
        };
        report.push(LevelEncoding {
            level: l,
            size: cube.size,
            mean_rel,
            max_rel,
            bc6h_search: (format == PixelFormat::Bc6h && cube.size <= super::bc6h::SEARCH_MAX)
                .then_some(super::bc6h::SEARCH_NAME),
            clamped: faces.iter().map(|f| f.1).sum(),
            bytes: faces.iter().map(|f| f.0.len()).sum(),
            seconds: faces.iter().map(|f| f.2).sum(),
        });
        levels.push(faces.into_iter().map(|f| f.0).collect());
    }
    let size = mips.levels.first().map_or(0, |c| c.size);
    (
        Payload {
            format,
            width: size,
            height: size,
            faces: 6,
            levels,
        },
        report,
    )
}

/// Decodes a cube payload into float levels.
pub fn decode_cube(path: &Path, p: &Payload) -> Result<CubeMips> {
    p.check(path)?;
    if p.faces != 6 || p.width != p.height {
        return Err(Error::invalid(path, "not a cube map (need 6 square faces)"));
    }
    let levels = p
        .levels
        .par_iter()
        .enumerate()
        .map(|(l, faces)| {
            let (n, _) = p.level_dims(l);
            let imgs: Vec<Image> = faces
                .iter()
                .map(|b| decode_image(b, p.format, n, n))
                .collect();
            Cubemap::from_faces(imgs.try_into().expect("six faces"))
        })
        .collect::<Result<Vec<_>>>()?;
    Ok(CubeMips { levels })
}

/// Writes a fourth channel into an encoded RGBA chain: `alpha`'s channel 0 (a chain of the
/// payload's shape) becomes each texel's A, in the payload's precision (f16 rounds to
/// nearest, saturating; f32 as it is). The custom lookup stores its mid-interval correction
/// there (`ibl_prefilter::custom`). Only `rgba16f` and `rgba32f` have an A channel to write:
/// any other format, or a chain of another shape, is refused.
pub fn set_alpha(path: &Path, p: &mut Payload, alpha: &CubeMips) -> Result<()> {
    let bytes_per = match p.format {
        PixelFormat::Rgba16f => 8,
        PixelFormat::Rgba32f => 16,
        f => {
            return Err(Error::unsupported(
                path,
                format!(
                "{} has no alpha channel to hold the lookup's correction: use rgba16f or rgba32f",
                f.name()
            ),
            ))
        }
    };
    if alpha.levels.len() != p.levels.len() || p.faces != 6 {
        return Err(Error::invalid(
            path,
            "the alpha chain's shape is not the chain's",
        ));
    }
    let sizes: Vec<usize> = (0..p.levels.len()).map(|l| p.level_dims(l).0).collect();
    for ((faces, n), cube) in p.levels.iter_mut().zip(sizes).zip(&alpha.levels) {
        if cube.size != n {
            return Err(Error::invalid(
                path,
                "the alpha chain's shape is not the chain's",
            ));
        }
        for (bytes, img) in faces.iter_mut().zip(&cube.faces) {
            for (px, t) in bytes
                .chunks_exact_mut(bytes_per)
                .zip(img.data.chunks_exact(img.channels))
            {
                let a = t[0];
                if bytes_per == 8 {
                    px[6..8].copy_from_slice(&super::f16_saturating(a).to_le_bytes());
                } else {
                    px[12..16].copy_from_slice(&a.to_le_bytes());
                }
            }
        }
    }
    Ok(())
}

/// The A channel of an RGBA cube chain (`rgba16f`, `rgba32f`) as a chain whose three channels
/// each hold it; `None` for formats without one.
pub fn decode_alpha(path: &Path, p: &Payload) -> Result<Option<CubeMips>> {
    p.check(path)?;
    let (bytes_per, off) = match p.format {
        PixelFormat::Rgba16f => (8, 6),
        PixelFormat::Rgba32f => (16, 12),
        _ => return Ok(None),
    };
    if p.faces != 6 || p.width != p.height {
        return Err(Error::invalid(path, "not a cube map (need 6 square faces)"));
    }
    let mut levels = Vec::with_capacity(p.levels.len());
    for (l, faces) in p.levels.iter().enumerate() {
        let (n, _) = p.level_dims(l);
        let imgs: Vec<Image> = faces
            .iter()
            .map(|b| {
                let mut img = Image::new(n, n, 3);
                for (t, px) in img.data.chunks_exact_mut(3).zip(b.chunks_exact(bytes_per)) {
                    let a = if bytes_per == 8 {
                        half::f16::from_le_bytes([px[off], px[off + 1]]).to_f32()
                    } else {
                        f32::from_le_bytes(px[off..off + 4].try_into().unwrap())
                    };
                    t.fill(a);
                }
                img
            })
            .collect();
        levels.push(Cubemap::from_faces(imgs.try_into().expect("six faces"))?);
    }
    Ok(Some(CubeMips { levels }))
}

/// Mean and largest relative error of `decoded` against `float` (see [`ERROR_METRIC`]).
pub fn relative_errors(float: &[Image], decoded: &[Image]) -> (f64, f64) {
    let m = |px: &[f32]| px[0].max(px[1]).max(px[2]).max(0.0) as f64;
    let (mut sum_m, mut n) = (0.0f64, 0usize);
    for img in float {
        for px in img.data.chunks_exact(3) {
            sum_m += m(px);
            n += 1;
        }
    }
    let eps = (1e-3 * sum_m / n.max(1) as f64).max(f64::MIN_POSITIVE);
    let (mut sum, mut max) = (0.0f64, 0.0f64);
    for (a, b) in float.iter().zip(decoded) {
        for (pa, pb) in a.data.chunks_exact(3).zip(b.data.chunks_exact(3)) {
            let d = m(pa).max(eps);
            for c in 0..3 {
                let e = (pb[c] as f64 - pa[c] as f64).abs() / d;
                sum += e;
                max = max.max(e);
            }
        }
    }
    (sum / (3 * n.max(1)) as f64, max)
}

/// Encodes one RGB float image; returns the bytes and how many channel values were clamped.
pub fn encode_image(img: &Image, format: PixelFormat, quality: Bc6hQuality) -> (Vec<u8>, usize) {
    let max = format.max_value();
    // rgba32f stores every value as it is (negatives kept by `--negative keep` included):
    // nothing is clamped, and a warning saying so would send the user to the format in use.
    let clamped = if format == PixelFormat::Rgba32f {
        0
    } else {
        img.data
            .chunks_exact(img.channels)
            .map(|px| {
                px[..3]
                    .iter()
                    .enumerate()
                    .filter(|&(c, &v)| {
                        let top = if format == PixelFormat::B10g11r11 && c == 2 {
                            packed::UF10_MAX
                        } else {
                            max
                        };
                        !(0.0..=top).contains(&v)
                    })
                    .count()
            })
            .sum()
    };
    let mut out = Vec::with_capacity(format.image_bytes(img.width, img.height));
    let texels = img
        .data
        .chunks_exact(img.channels)
        .map(|px| [px[0], px[1], px[2]]);
    match format {
        PixelFormat::Rgba32f => texels.for_each(|t| {
            for v in [t[0], t[1], t[2], 1.0] {
                out.extend(v.to_le_bytes());
            }
        }),
        PixelFormat::Rgba16f => texels.for_each(|t| {
            for v in [t[0], t[1], t[2], 1.0] {
                out.extend(super::f16_saturating(v.max(0.0)).to_le_bytes());
            }
        }),
        PixelFormat::Rgb9e5 => {
            texels.for_each(|t| out.extend(packed::rgb9e5_encode(t).to_le_bytes()))
        }
        PixelFormat::B10g11r11 => {
            texels.for_each(|t| out.extend(packed::b10g11r11_encode(t).to_le_bytes()))
        }
        PixelFormat::Bc6h => out = super::bc6h::encode(img, quality),
    }
    (out, clamped)
}

/// Decodes one `width`×`height` image of `format` (bytes already checked to be
/// [`PixelFormat::image_bytes`] long) to RGB floats.
pub fn decode_image(bytes: &[u8], format: PixelFormat, width: usize, height: usize) -> Image {
    debug_assert_eq!(bytes.len(), format.image_bytes(width, height));
    let mut img = Image::new(width, height, 3);
    let u32s = || {
        bytes
            .chunks_exact(4)
            .map(|b| u32::from_le_bytes(b.try_into().unwrap()))
    };
    match format {
        PixelFormat::Rgba32f => {
            for (t, b) in img.data.chunks_exact_mut(3).zip(bytes.chunks_exact(16)) {
                for c in 0..3 {
                    t[c] = f32::from_le_bytes(b[4 * c..4 * c + 4].try_into().unwrap());
                }
            }
        }
        PixelFormat::Rgba16f => {
            for (t, b) in img.data.chunks_exact_mut(3).zip(bytes.chunks_exact(8)) {
                for c in 0..3 {
                    t[c] = half::f16::from_le_bytes([b[2 * c], b[2 * c + 1]]).to_f32();
                }
            }
        }
        PixelFormat::Rgb9e5 => {
            for (t, v) in img.data.chunks_exact_mut(3).zip(u32s()) {
                t.copy_from_slice(&packed::rgb9e5_decode(v));
            }
        }
        PixelFormat::B10g11r11 => {
            for (t, v) in img.data.chunks_exact_mut(3).zip(u32s()) {
                t.copy_from_slice(&packed::b10g11r11_decode(v));
            }
        }
        PixelFormat::Bc6h => super::bc6h::decode(bytes, &mut img),
    }
    img
}

#[cfg(test)]
mod tests {
    use super::*;

    fn chain(value: impl Fn(usize, usize, usize) -> f32) -> CubeMips {
        let mut mips = CubeMips::build(Cubemap::constant(8, [0.5, 0.25, 0.125]), 4);
        for (l, c) in mips.levels.iter_mut().enumerate() {
            for (f, face) in c.faces.iter_mut().enumerate() {
                for (p, t) in face.data.chunks_exact_mut(3).enumerate() {
                    t.fill(value(l, f, p));
                }
            }
        }
        mips
    }

    /// The alpha written into an rgba16f / rgba32f payload comes back as written (signed, to the
    /// format's precision), the RGB is untouched, and formats without alpha or a chain of
    /// another shape are refused.
    #[test]
    fn alpha_round_trips_and_is_refused_where_it_cannot_be_held() {
        let path = Path::new("chain.ktx2");
        let rgb = CubeMips::build(Cubemap::constant(8, [0.5, 0.25, 0.125]), 4);
        let alpha = chain(|l, f, p| (l as f32 - 0.5) * 0.1 + f as f32 * 1e-3 - p as f32 * 1e-4);
        for format in [PixelFormat::Rgba16f, PixelFormat::Rgba32f] {
            let (mut payload, _) = encode_chain(&rgb, format, Bc6hQuality::default());
            assert!(decode_alpha(path, &payload).unwrap().is_some());
            set_alpha(path, &mut payload, &alpha).unwrap();
            let back = decode_alpha(path, &payload).unwrap().unwrap();
            let tol = if format == PixelFormat::Rgba16f {
                1e-3
            } else {
                0.0
            };
            for (a, b) in alpha.levels.iter().zip(&back.levels) {
                for (x, y) in a.faces.iter().zip(&b.faces) {
                    for (u, v) in x.data.iter().zip(&y.data) {
                        assert!(
                            (u - v).abs() <= tol * u.abs().max(1e-2),
                            "{format:?}: {u} {v}"
                        );
                    }
                }
            }
            assert!(back.levels[0].faces[0].data[0] < 0.0, "signed");
            let rgb_back = decode_cube(path, &payload).unwrap();
            assert_eq!(
                rgb_back.levels[1].texel(crate::cube::Face::ALL[3], 1, 0),
                [0.5, 0.25, 0.125]
            );
            // A chain of another shape.
            let short = CubeMips {
                levels: alpha.levels[..1].to_vec(),
            };
            let e = set_alpha(path, &mut payload, &short)
                .unwrap_err()
                .to_string();
            assert!(e.contains("chain.ktx2") && e.contains("shape"), "{e}");
        }
        for format in [PixelFormat::Rgb9e5, PixelFormat::Bc6h] {
            let (mut payload, _) = encode_chain(&rgb, format, Bc6hQuality::default());
            assert!(decode_alpha(path, &payload).unwrap().is_none());
            let e = set_alpha(path, &mut payload, &alpha)
                .unwrap_err()
                .to_string();
            assert!(e.contains("no alpha channel") && !e.contains('\n'), "{e}");
        }
    }
}
