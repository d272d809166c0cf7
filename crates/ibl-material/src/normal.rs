//! Reading normal maps and decoding their texels into unit tangent-space normals
//! (Marcolongo 2020 §3.3: a vector (x, y, z) is stored as (x, y, z)·0.5 + 0.5).

use crate::quaternion::Vec3;
use ibl_core::traverse::ordered_row_reduce;
use ibl_core::{Error, Image};

pub use crate::map::load;

/// A normal map as read from disk ([`load`]): the material bakes' one map type.
pub type NormalImage = crate::map::LoadedMap;

/// How texels become normals.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Decoding {
    /// Green points down the image (DirectX convention): negate y.
    pub y_down: bool,
    /// Only x and y are stored (BC5-style): z = sqrt(max(0, 1 − x² − y²)).
    pub two_channel: bool,
    /// Texels hold the vector itself, not v·0.5 + 0.5 (some float maps).
    pub signed: bool,
    /// Decoded vectors shorter than this carry no direction (degenerate texels).
    pub min_length: f64,
}

/// One decoded texel.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Texel {
    /// A unit normal, with the length the stored vector had before normalisation and
    /// whether a two-channel texel lay outside the unit disk (x² + y² > 1, z set to 0).
    Unit {
        /// The unit normal (tangent space).
        n: Vec3,
        /// Length of the stored vector before normalisation.
        len: f64,
        /// A two-channel texel with x² + y² > 1 (z set to 0).
        outside_disk: bool,
    },
    /// Shorter than `min_length` (e.g. mid-grey padding): no direction.
    Degenerate {
        /// Length of the stored vector.
        len: f64,
    },
    /// NaN or infinite components.
    NonFinite,
}

/// A [`Decoding`] bound to an image's channel layout.
#[derive(Clone, Copy, Debug)]
pub struct Decoder {
    /// How stored values become a normal.
    pub decoding: Decoding,
    /// Channels holding x and y (and z unless two-channel).
    x: usize,
    y: usize,
    z: usize,
}

impl Decoder {
    /// Checks that the image has the channels the decoding needs.
    pub fn new(decoding: Decoding, img: &NormalImage) -> ibl_core::Result<Decoder> {
        let path = &img.path;
        match (img.image.channels, decoding.two_channel, img.grey_alpha) {
            (1, true, _) => Err(Error::unsupported(
                path,
                "a single channel: --two-channel needs x and y (R and G, or grey and alpha)",
            )),
            (1, false, _) => Err(Error::unsupported(
                path,
                "a normal map needs RGB channels (or two with --two-channel); this one has a single channel",
            )),
            (2, false, _) => Err(Error::unsupported(
                path,
                "two channels: use --two-channel (x from R, y from G, z reconstructed)",
            )),
            (_, false, true) => Err(Error::unsupported(
                path,
                "grey+alpha PNG: a two-channel normal map? use --two-channel (x from grey, y from alpha)",
            )),
            (_, true, true) => Ok(Decoder { decoding, x: 0, y: 3, z: 2 }),
            _ => Ok(Decoder { decoding, x: 0, y: 1, z: 2 }),
        }
    }

    /// Decodes one texel (its channels as stored) to a unit normal.
    #[inline]
    pub fn decode(&self, texel: &[f32]) -> Texel {
        match self.decode_raw(texel) {
            RawTexel::Vector {
                v,
                len,
                outside_disk,
            } => {
                let inv = 1.0 / len;
                Texel::Unit {
                    n: [v[0] * inv, v[1] * inv, v[2] * inv],
                    len,
                    outside_disk,
                }
            }
            RawTexel::Degenerate { len } => Texel::Degenerate { len },
            RawTexel::NonFinite => Texel::NonFinite,
        }
    }

    /// Decodes one texel without normalising it (the conversion's fast path: the quaternion
    /// formula takes the length instead).
    #[inline(always)]
    pub(crate) fn decode_raw(&self, texel: &[f32]) -> RawTexel {
        let d = &self.decoding;
        let (scale, offset) = if d.signed { (1.0, 0.0) } else { (2.0, -1.0) };
        let y_sign = if d.y_down { -1.0 } else { 1.0 };
        let x = texel[self.x] as f64 * scale + offset;
        let y = (texel[self.y] as f64 * scale + offset) * y_sign;
        if d.two_channel {
            if !(x.is_finite() && y.is_finite()) {
                return RawTexel::NonFinite;
            }
            let r2 = x * x + y * y;
            let z = (1.0 - r2).max(0.0).sqrt();
            return RawTexel::Vector {
                v: [x, y, z],
                len: (r2 + z * z).sqrt(),
                outside_disk: r2 > 1.0,
            };
        }
        let z = texel[self.z] as f64 * scale + offset;
        if !(x.is_finite() && y.is_finite() && z.is_finite()) {
            return RawTexel::NonFinite;
        }
        let len = (x * x + y * y + z * z).sqrt();
        if len < d.min_length || len == 0.0 {
            return RawTexel::Degenerate { len };
        }
        RawTexel::Vector {
            v: [x, y, z],
            len,
            outside_disk: false,
        }
    }
}

/// A decoded texel before normalisation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum RawTexel {
    /// The decoded vector and its length (≥ `min_length`).
    Vector {
        v: Vec3,
        len: f64,
        outside_disk: bool,
    },
    Degenerate {
        len: f64,
    },
    NonFinite,
}

/// Which y convention makes the map's slopes a gradient field. Normals of a height field h
/// are n ∝ (−∂h/∂x, −∂h/∂y, 1), so the slopes p = −n_x/n_z, q = −n_y/n_z satisfy
/// ∂p/∂y = ∂q/∂x (zero curl). A map read with the wrong green convention has q negated and a
/// large curl; the mean squared curl under both readings tells which one the map was made in.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct ConventionCheck {
    /// Mean squared curl of the slopes as decoded (with the chosen `y_down`).
    pub curl_as_decoded: f64,
    /// The same with green flipped.
    pub curl_flipped: f64,
    /// (flipped − as decoded)/(flipped + as decoded) ∈ [−1, 1]: the correlation of ∂p/∂y with
    /// ∂q/∂x; near +1 the decoded convention is right, near −1 the flipped one.
    pub agreement: f64,
    /// Texel pairs the agreement was measured on.
    pub samples: u64,
}

impl ConventionCheck {
    /// The other convention is more integrable. Real maps (painted, photo-derived, lossy)
    /// are far from exact gradient fields: they reach |agreement| ≈ 0.3–0.8 where an exact
    /// height field gives 1, hence the modest threshold (the warning shows the number).
    pub(crate) fn suggests_flip(&self) -> bool {
        self.samples >= 256 && self.agreement < -0.25
    }
}

/// Measures [`ConventionCheck`] on a grid of at most ~2^18 squares (the circulation of the
/// slopes around each, rows summed in order, so the result does not depend on the thread
/// count). Texels steeper than ~78° (n_z < 0.2) or without a direction are left out.
pub fn convention_check(decoder: &Decoder, img: &Image) -> ConventionCheck {
    let (w, h) = (img.width, img.height);
    if w < 3 || h < 3 {
        return ConventionCheck::default();
    }
    let stride = (((w * h) as f64 / (1u64 << 18) as f64).sqrt().ceil() as usize).max(1);
    let slope = |i: usize, j: usize| -> Option<[f64; 2]> {
        match decoder.decode_raw(img.texel(i, j)) {
            RawTexel::Vector { v, len, .. } if v[2] >= 0.2 * len => {
                Some([-v[0] / v[2], -v[1] / v[2]])
            }
            _ => None,
        }
    };
    // Squares of 2×2 texels: a little less sensitive to lossy-codec noise than 1×1, the same
    // signs on every real map tried (see bench/material.md).
    let k = 2;
    if w <= k || h <= k {
        return ConventionCheck::default();
    }
    // Circulation of (p, q) around the k×k square with corners at texels (i, j) … (i+k, j+k)
    // (row j + k is down the image): ∮ = (q_x − p_y)·area with y up, both derivatives taken
    // by the same trapezoid stencil at the square's centre.
    // Sampled rows j = r·stride, summed in row order.
    let rows = (h - k).div_ceil(stride);
    let row = |r: usize| {
        let j = r * stride;
        let mut acc = (0.0f64, 0.0f64, 0u64);
        for i in (0..w - k).step_by(stride) {
            let (Some(tl), Some(tr), Some(bl), Some(br)) = (
                slope(i, j),
                slope(i + k, j),
                slope(i, j + k),
                slope(i + k, j + k),
            ) else {
                continue;
            };
            // Bottom edge minus top edge of p (= −∂p/∂y), right minus left edge of q (= ∂q/∂x).
            let dp = 0.5 * ((bl[0] + br[0]) - (tl[0] + tr[0]));
            let dq = 0.5 * ((tr[1] + br[1]) - (tl[1] + bl[1]));
            acc.0 += (dp + dq).powi(2);
            acc.1 += (dp - dq).powi(2);
            acc.2 += 1;
        }
        acc
    };
    let (a, b, n) = ordered_row_reduce(rows, row, (0.0, 0.0, 0), |x, y| {
        (x.0 + y.0, x.1 + y.1, x.2 + y.2)
    });
    let m = (n.max(1)) as f64;
    let agreement = if a + b > 0.0 { (b - a) / (a + b) } else { 0.0 };
    ConventionCheck {
        curl_as_decoded: a / m,
        curl_flipped: b / m,
        agreement,
        samples: n,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn img(channels: usize, grey_alpha: bool) -> NormalImage {
        NormalImage {
            image: Image::new(1, 1, channels),
            grey_alpha,
            path: std::path::PathBuf::from("n.png"),
            read_as: None,
        }
    }

    const D: Decoding = Decoding {
        y_down: false,
        two_channel: false,
        signed: false,
        min_length: 0.01,
    };

    #[test]
    fn decodes_2c_minus_1_and_renormalises() {
        let dec = Decoder::new(D, &img(3, false)).unwrap();
        // 8-bit flat blue (128, 128, 255): not unit before renormalising.
        let t = [128.0 / 255.0, 128.0 / 255.0, 1.0];
        let Texel::Unit { n, len, .. } = dec.decode(&t) else {
            panic!()
        };
        assert!((len - (2.0 * (1.0f64 / 255.0).powi(2) + 1.0).sqrt()).abs() < 1e-6);
        assert!(
            (n[0] - n[1]).abs() < 1e-12
                && n[0] > 0.0
                && (crate::quaternion::length(n) - 1.0).abs() < 1e-15
        );
        // Exactly mid-grey is degenerate, as is 8-bit mid-grey (length √3/255 < 0.01).
        assert!(matches!(
            dec.decode(&[0.5, 0.5, 0.5]),
            Texel::Degenerate { .. }
        ));
        assert!(matches!(
            dec.decode(&[128.0 / 255.0; 3]),
            Texel::Degenerate { .. }
        ));
        assert_eq!(dec.decode(&[f32::NAN, 0.5, 1.0]), Texel::NonFinite);
    }

    #[test]
    fn y_down_flips_green() {
        let up = Decoder::new(D, &img(3, false))
            .unwrap()
            .decode(&[0.5, 1.0, 0.5]);
        let down = Decoder::new(Decoding { y_down: true, ..D }, &img(3, false))
            .unwrap()
            .decode(&[0.5, 1.0, 0.5]);
        let (Texel::Unit { n: a, .. }, Texel::Unit { n: b, .. }) = (up, down) else {
            panic!()
        };
        assert_eq!(a, [0.0, 1.0, 0.0]);
        assert_eq!(b, [0.0, -1.0, 0.0]);
    }

    #[test]
    fn two_channel_reconstructs_z() {
        let d2 = Decoding {
            two_channel: true,
            ..D
        };
        let dec = Decoder::new(d2, &img(3, false)).unwrap();
        // x = 0.6, y = 0: z = 0.8; blue ignored.
        let Texel::Unit {
            n, outside_disk, ..
        } = dec.decode(&[0.8, 0.5, 0.0])
        else {
            panic!()
        };
        assert!(
            (n[0] - 0.6).abs() < 1e-7
                && n[1].abs() < 1e-7
                && (n[2] - 0.8).abs() < 1e-7
                && !outside_disk
        );
        // Outside the disk: z = 0, (x, y) renormalised, flagged.
        let Texel::Unit {
            n, outside_disk, ..
        } = dec.decode(&[1.0, 1.0, 0.0])
        else {
            panic!()
        };
        assert!(outside_disk && n[2] == 0.0 && (n[0] - n[1]).abs() < 1e-15);
        // Grey+alpha PNG: x from grey, y from alpha.
        let la = Decoder::new(d2, &img(4, true)).unwrap();
        let Texel::Unit { n, .. } = la.decode(&[0.5, 0.5, 0.5, 1.0]) else {
            panic!()
        };
        assert!((n[1] - 1.0).abs() < 1e-15);
        assert!(Decoder::new(D, &img(4, true)).is_err());
        assert!(Decoder::new(D, &img(1, false)).is_err());
        assert!(Decoder::new(d2, &img(1, false)).is_err());
        // A two-channel EXR (R, G kept as two channels): refused without --two-channel
        // (it has no z to read), decoded from R, G with it.
        let e = Decoder::new(D, &img(2, false)).err().unwrap().to_string();
        assert!(e.contains("two channels: use --two-channel"), "{e}");
        let rg = Decoder::new(d2, &img(2, false)).unwrap();
        let Texel::Unit { n, .. } = rg.decode(&[0.5, 1.0]) else {
            panic!()
        };
        assert!((n[1] - 1.0).abs() < 1e-15);
    }

    #[test]
    fn signed_maps_are_taken_as_they_are() {
        let dec = Decoder::new(Decoding { signed: true, ..D }, &img(3, false)).unwrap();
        let Texel::Unit { n, len, .. } = dec.decode(&[0.0, -2.0, 0.0]) else {
            panic!()
        };
        assert_eq!((n, len), ([0.0, -1.0, 0.0], 2.0));
    }

    /// A height field's normals, y up (OpenGL), stored as v·0.5 + 0.5.
    fn height_field_map(n: usize, y_down: bool) -> NormalImage {
        let mut img = Image::new(n, n, 3);
        for j in 0..n {
            for i in 0..n {
                let (x, y) = (i as f64 / n as f64, 1.0 - j as f64 / n as f64);
                // h = 0.02 sin(2π·3x) cos(2π·2y) + 0.01 sin(2π(x + 4y)): gradient by hand.
                let tau = std::f64::consts::TAU;
                let hx = 0.02 * tau * 3.0 * (tau * 3.0 * x).cos() * (tau * 2.0 * y).cos()
                    + 0.01 * tau * (tau * (x + 4.0 * y)).cos();
                let hy = -0.02 * tau * 2.0 * (tau * 3.0 * x).sin() * (tau * 2.0 * y).sin()
                    + 0.04 * tau * (tau * (x + 4.0 * y)).cos();
                // Per texel, not per unit length: slopes in texel units scale by 1/n alike.
                let (gx, gy) = (hx, if y_down { -hy } else { hy });
                let l = (gx * gx + gy * gy + 1.0).sqrt();
                let px = img.texel_mut(i, j);
                px.copy_from_slice(&[
                    (-gx / l * 0.5 + 0.5) as f32,
                    (-gy / l * 0.5 + 0.5) as f32,
                    (1.0 / l * 0.5 + 0.5) as f32,
                ]);
            }
        }
        NormalImage {
            image: img,
            grey_alpha: false,
            path: std::path::PathBuf::from("h.png"),
            read_as: None,
        }
    }

    #[test]
    fn convention_check_tells_opengl_from_directx() {
        for (made_y_down, read_y_down) in
            [(false, false), (true, false), (true, true), (false, true)]
        {
            let map = height_field_map(64, made_y_down);
            let dec = Decoder::new(
                Decoding {
                    y_down: read_y_down,
                    ..D
                },
                &map,
            )
            .unwrap();
            let c = convention_check(&dec, &map.image);
            eprintln!("made y_down {made_y_down}, read y_down {read_y_down}: {c:?}");
            assert_eq!(c.suggests_flip(), made_y_down != read_y_down);
        }
    }
}
