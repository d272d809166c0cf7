//! Anisotropy direction fields for TPR maps (Marcolongo 2020 §3.5): presets in closed form, angle
//! and direction maps (Cocco et al. 2024 Fig. 22: a value in [0, 1] is an angle in [0, π)), and
//! resampling of such line fields.
//!
//! A field returns the rotated tangent t = (x, y) in tangent-space components, unnormalised
//! (the caller normalises and replaces zero-length or non-finite directions by +x).
//!
//! Which presets depend on the tangent-space y convention: `constant` and `wave` are defined
//! in tangent space (as the thesis's `x = cos πv, y = sin πv`) and ignore it; `radial`,
//! `spiral` and `linear` are defined by where things are on the image, in image space with
//! +y up the image, and are converted with y ↦ −y for DirectX-style (`y_down`) tangent spaces.
//! Image-space positions are measured in units of the larger image side, so circles stay
//! circles on non-square maps.

use std::f64::consts::PI;
use std::fmt;
use std::str::FromStr;

/// A direction-field preset, written `NAME[:ARGS]`.
#[derive(Clone, Debug, PartialEq)]
pub enum Preset {
    /// `constant:DEG`: the tangent turned by DEG about n (from +t towards +b).
    Constant {
        /// Angle in degrees.
        deg: f64,
    },
    /// `linear:DEG`: straight strokes at DEG counter-clockwise from the image's +x, as seen on
    /// the image (the same field as `constant:DEG` for +y-up tangent spaces).
    Linear {
        /// Angle in degrees from the image's +x.
        deg: f64,
    },
    /// `radial[:CX,CY]`: concentric circles about (CX, CY) in texture coordinates (v down the
    /// image, default the centre), tangent along the circle, counter-clockwise — a CD, a pan
    /// bottom.
    Radial {
        /// Centre u in texture coordinates.
        cx: f64,
        /// Centre v in texture coordinates (v down the image).
        cy: f64,
    },
    /// `spiral[:CX,CY,TURNS]`: the Archimedean spiral r = φ/(4π·TURNS) about (CX, CY): TURNS
    /// grooves between the centre and a distance of half the larger side; TURNS = 0 gives
    /// straight rays, negative TURNS winds the other way. Default 0.5,0.5,8.
    Spiral {
        /// Centre u in texture coordinates.
        cx: f64,
        /// Centre v in texture coordinates (v down the image).
        cy: f64,
        /// Grooves between the centre and half the larger side.
        turns: f64,
    },
    /// `wave`: the thesis's example, x = cos πv, y = sin πv.
    Wave,
}

impl Preset {
    /// Unnormalised tangent at texture coordinates (u, v); `scale` = (W, H) / max(W, H).
    pub fn field(&self, u: f64, v: f64, scale: [f64; 2], y_down: bool) -> [f64; 2] {
        let to_tangent = |d: [f64; 2]| if y_down { [d[0], -d[1]] } else { d };
        match *self {
            Preset::Constant { deg } => {
                let (s, c) = deg.to_radians().sin_cos();
                [c, s]
            }
            Preset::Wave => [(PI * v).cos(), (PI * v).sin()],
            Preset::Linear { deg } => {
                let (s, c) = deg.to_radians().sin_cos();
                to_tangent([c, s])
            }
            Preset::Radial { cx, cy } => {
                let p = image_offset(u, v, cx, cy, scale);
                to_tangent([-p[1], p[0]])
            }
            Preset::Spiral { cx, cy, turns } => {
                let p = image_offset(u, v, cx, cy, scale);
                let r = p[0].hypot(p[1]);
                if r == 0.0 {
                    return [0.0, 0.0];
                }
                // d(r e_r(φ))/dφ · turns with r = φ/(4π·turns): e_r/(4π) + turns·r·e_φ.
                let k = 1.0 / (4.0 * PI * r);
                to_tangent([k * p[0] - turns * p[1], k * p[1] + turns * p[0]])
            }
        }
    }
}

/// Position relative to (cx, cy) in image space: +x right, +y up, in units of the larger side.
#[inline]
pub(crate) fn image_offset(u: f64, v: f64, cx: f64, cy: f64, scale: [f64; 2]) -> [f64; 2] {
    [(u - cx) * scale[0], -(v - cy) * scale[1]]
}

/// (W, H) / max(W, H).
pub(crate) fn aspect_scale(width: usize, height: usize) -> [f64; 2] {
    let m = width.max(height) as f64;
    [width as f64 / m, height as f64 / m]
}

fn numbers(name: &str, args: &str, want: &[usize]) -> Result<Vec<f64>, String> {
    let v: Vec<f64> = if args.trim().is_empty() {
        Vec::new()
    } else {
        args.split(',')
            .map(|a| {
                a.trim()
                    .parse::<f64>()
                    .map_err(|_| format!("preset {name}: '{}' is not a number", a.trim()))
            })
            .collect::<Result<_, _>>()?
    };
    if !want.contains(&v.len()) {
        return Err(format!(
            "preset {name} takes {} number(s), got {}",
            want.iter()
                .map(|n| n.to_string())
                .collect::<Vec<_>>()
                .join(" or "),
            v.len()
        ));
    }
    if let Some(bad) = v.iter().find(|x| !x.is_finite()) {
        return Err(format!("preset {name}: {bad} is not finite"));
    }
    Ok(v)
}

impl FromStr for Preset {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        let (name, args) = s.split_once(':').unwrap_or((s, ""));
        let name = name.trim().to_ascii_lowercase();
        Ok(match name.as_str() {
            "constant" => Preset::Constant { deg: numbers(&name, args, &[1])?[0] },
            "linear" => Preset::Linear { deg: numbers(&name, args, &[1])?[0] },
            "radial" => match numbers(&name, args, &[0, 2])?.as_slice() {
                [cx, cy] => Preset::Radial { cx: *cx, cy: *cy },
                _ => Preset::Radial { cx: 0.5, cy: 0.5 },
            },
            "spiral" => match numbers(&name, args, &[0, 3])?.as_slice() {
                [cx, cy, turns] => Preset::Spiral { cx: *cx, cy: *cy, turns: *turns },
                _ => Preset::Spiral { cx: 0.5, cy: 0.5, turns: 8.0 },
            },
            "wave" => {
                numbers(&name, args, &[0])?;
                Preset::Wave
            }
            _ => {
                return Err(format!(
                    "unknown preset '{name}' (constant:DEG, linear:DEG, radial[:CX,CY], spiral[:CX,CY,TURNS], wave)"
                ))
            }
        })
    }
}

impl fmt::Display for Preset {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Preset::Constant { deg } => write!(f, "constant:{deg}"),
            Preset::Linear { deg } => write!(f, "linear:{deg}"),
            Preset::Radial { cx, cy } => write!(f, "radial:{cx},{cy}"),
            Preset::Spiral { cx, cy, turns } => write!(f, "spiral:{cx},{cy},{turns}"),
            Preset::Wave => write!(f, "wave"),
        }
    }
}

impl serde::Serialize for Preset {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(&self.to_string())
    }
}

impl<'de> serde::Deserialize<'de> for Preset {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let s = String::deserialize(d)?;
        s.parse().map_err(serde::de::Error::custom)
    }
}

/// Angle in [0, π) stored as a value in [0, 1] (Cocco et al. 2024 Fig. 22) → unit tangent.
#[inline]
pub(crate) fn tangent_from_angle_value(value: f64) -> [f64; 2] {
    let (s, c) = (value * PI).sin_cos();
    [c, s]
}

/// Resamples a line field (unit or zero tangents, W×H) to another size by bilinear
/// interpolation at texel centres of the doubled-angle vectors (x² − y², 2xy): t and −t are
/// the same anisotropy axis, so averaging them must not cancel. Zero input texels carry no
/// weight; an output with no consistent direction comes out as (0, 0).
pub(crate) fn resample_line_field(
    src: &[[f64; 2]],
    sw: usize,
    sh: usize,
    dw: usize,
    dh: usize,
) -> Vec<[f64; 2]> {
    let doubled: Vec<[f64; 2]> = src
        .iter()
        .map(|&[x, y]| [x * x - y * y, 2.0 * x * y])
        .collect();
    let mut out = Vec::with_capacity(dw * dh);
    for j in 0..dh {
        let (y0, y1, fy) = taps((j as f64 + 0.5) / dh as f64, sh);
        for i in 0..dw {
            let (x0, x1, fx) = taps((i as f64 + 0.5) / dw as f64, sw);
            let mut acc = [0.0f64; 2];
            for (yy, wy) in [(y0, 1.0 - fy), (y1, fy)] {
                for (xx, wx) in [(x0, 1.0 - fx), (x1, fx)] {
                    let d = doubled[yy * sw + xx];
                    acc[0] += wx * wy * d[0];
                    acc[1] += wx * wy * d[1];
                }
            }
            let len = acc[0].hypot(acc[1]);
            out.push(if len > 1e-9 {
                let half = 0.5 * acc[1].atan2(acc[0]);
                [half.cos(), half.sin()]
            } else {
                [0.0, 0.0]
            });
        }
    }
    out
}

/// Bilinear taps for coordinate t ∈ [0, 1] over n texels (centres at (k + 0.5)/n), clamped.
pub fn taps(t: f64, n: usize) -> (usize, usize, f64) {
    let x = (t * n as f64 - 0.5).clamp(0.0, (n - 1) as f64);
    let x0 = x.floor() as usize;
    let x1 = (x0 + 1).min(n - 1);
    (x0, x1, x - x0 as f64)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn unit(d: [f64; 2]) -> [f64; 2] {
        let l = d[0].hypot(d[1]);
        [d[0] / l, d[1] / l]
    }

    /// Distance between two axes (t ≡ −t): 1 − |cos| of the angle.
    fn axis_err(a: [f64; 2], b: [f64; 2]) -> f64 {
        let (a, b) = (unit(a), unit(b));
        1.0 - (a[0] * b[0] + a[1] * b[1]).abs()
    }

    #[test]
    fn presets_parse_and_print() {
        for s in [
            "constant:30",
            "linear:-45",
            "radial:0.25,0.75",
            "spiral:0.5,0.5,3",
            "wave",
        ] {
            let p: Preset = s.parse().unwrap();
            assert_eq!(p.to_string(), s);
        }
        assert_eq!(
            "radial".parse::<Preset>().unwrap(),
            Preset::Radial { cx: 0.5, cy: 0.5 }
        );
        assert_eq!(
            "Spiral".parse::<Preset>().unwrap(),
            Preset::Spiral {
                cx: 0.5,
                cy: 0.5,
                turns: 8.0
            }
        );
        for bad in [
            "constant",
            "constant:x",
            "radial:1",
            "spiral:1,2",
            "wave:3",
            "swirl",
            "linear:inf",
            "constant:1,2",
        ] {
            let e = bad.parse::<Preset>().unwrap_err();
            eprintln!("{bad:14} → {e}");
        }
    }

    #[test]
    fn constant_linear_and_wave_match_their_closed_forms() {
        let s = [1.0, 1.0];
        for deg in [0.0f64, 30.0, 90.0, 135.0, -60.0] {
            let want = [deg.to_radians().cos(), deg.to_radians().sin()];
            for (u, v) in [(0.1, 0.9), (0.5, 0.5)] {
                for y_down in [false, true] {
                    let c = Preset::Constant { deg }.field(u, v, s, y_down);
                    assert!((c[0] - want[0]).abs() < 1e-15 && (c[1] - want[1]).abs() < 1e-15);
                    let l = Preset::Linear { deg }.field(u, v, s, y_down);
                    let sign = if y_down { -1.0 } else { 1.0 };
                    assert!(
                        (l[0] - want[0]).abs() < 1e-15 && (l[1] - sign * want[1]).abs() < 1e-15
                    );
                }
            }
        }
        for j in 0..16 {
            let v = (j as f64 + 0.5) / 16.0;
            let w = Preset::Wave.field(0.3, v, s, true);
            assert!((w[0] - (PI * v).cos()).abs() < 1e-15 && (w[1] - (PI * v).sin()).abs() < 1e-15);
        }
    }

    #[test]
    fn radial_is_tangent_to_circles_in_pixel_space() {
        // On a 64×32 map, circles about the centre in pixels: walk a circle of radius R pixels
        // (finite differences of its parametrisation) and compare with the field there.
        let (w, h) = (64usize, 32usize);
        let scale = aspect_scale(w, h);
        let (cx, cy) = (0.4, 0.55);
        let mut worst = 0.0f64;
        for y_down in [false, true] {
            for k in 0..360 {
                let phi = (k as f64).to_radians();
                let r_px = 10.0;
                // Circle in pixel coordinates (x right, y up) mapped to (u, v).
                let at = |p: f64| {
                    let (px, py) = (r_px * p.cos(), r_px * p.sin());
                    (cx + px / w as f64, cy - py / h as f64)
                };
                let (u, v) = at(phi);
                let (u1, v1) = at(phi + 1e-6);
                let (u0, v0) = at(phi - 1e-6);
                // Tangent in image space (y up), then in tangent space.
                let mut d = [(u1 - u0) * w as f64, -(v1 - v0) * h as f64];
                if y_down {
                    d[1] = -d[1];
                }
                let f = Preset::Radial { cx, cy }.field(u, v, scale, y_down);
                // Same orientation (counter-clockwise), not only the same axis.
                let (a, b) = (unit(d), unit(f));
                worst = worst.max(1.0 - (a[0] * b[0] + a[1] * b[1]));
            }
        }
        eprintln!("radial vs circle tangents: max 1 − cos = {worst:.2e}");
        assert!(worst < 1e-9);
        assert_eq!(
            Preset::Radial { cx: 0.5, cy: 0.5 }.field(0.5, 0.5, [1.0, 1.0], false),
            [-0.0, 0.0]
        );
    }

    #[test]
    fn spiral_is_tangent_to_the_archimedean_spiral() {
        let (w, h) = (48usize, 48usize);
        let scale = aspect_scale(w, h);
        let (cx, cy) = (0.5, 0.5);
        let mut worst = 0.0f64;
        for turns in [1.0f64, 3.0, 8.0, -2.0] {
            // r(φ) = φ/(4π·turns), in units of the larger side; φ·turns > 0.
            let r = |phi: f64| phi / (4.0 * PI * turns);
            let pos = |phi: f64| {
                let (x, y) = (r(phi) * phi.cos(), r(phi) * phi.sin());
                (cx + x / scale[0], cy - y / scale[1])
            };
            for k in 1..400 {
                let phi = turns.signum() * k as f64 * 0.05;
                let (u, v) = pos(phi);
                let (u1, v1) = pos(phi + 1e-6);
                let (u0, v0) = pos(phi - 1e-6);
                let d = [(u1 - u0) * scale[0], -(v1 - v0) * scale[1]];
                let f = Preset::Spiral { cx, cy, turns }.field(u, v, scale, false);
                worst = worst.max(axis_err(d, f));
            }
        }
        eprintln!("spiral vs finite-difference curve tangents: max 1 − |cos| = {worst:.2e}");
        assert!(worst < 1e-9);
        // Zero turns: rays; very many turns: circles.
        let rays = Preset::Spiral {
            cx: 0.5,
            cy: 0.5,
            turns: 0.0,
        }
        .field(0.8, 0.5, [1.0, 1.0], false);
        assert!(axis_err(rays, [1.0, 0.0]) < 1e-15);
        let circ = Preset::Spiral {
            cx: 0.5,
            cy: 0.5,
            turns: 1e9,
        }
        .field(0.8, 0.5, [1.0, 1.0], false);
        assert!(axis_err(circ, [0.0, 1.0]) < 1e-15);
        assert_eq!(
            Preset::Spiral {
                cx: 0.5,
                cy: 0.5,
                turns: 2.0
            }
            .field(0.5, 0.5, [1.0, 1.0], false),
            [0.0, 0.0]
        );
    }

    #[test]
    fn angle_values_and_line_field_resampling() {
        assert_eq!(tangent_from_angle_value(0.0), [1.0, 0.0]);
        let t = tangent_from_angle_value(0.5);
        assert!(t[0].abs() < 1e-15 && (t[1] - 1.0).abs() < 1e-15);
        // Identity resampling keeps every direction (up to sign).
        let (w, h) = (7, 5);
        let src: Vec<[f64; 2]> = (0..w * h)
            .map(|k| tangent_from_angle_value(k as f64 / 35.0))
            .collect();
        let same = resample_line_field(&src, w, h, w, h);
        for (a, b) in src.iter().zip(&same) {
            assert!(axis_err(*a, *b) < 1e-12);
        }
        // t and −t next to each other average to that axis, not to zero.
        let pair = vec![[1.0, 0.0], [-1.0, 0.0]];
        let up = resample_line_field(&pair, 2, 1, 3, 1);
        for d in &up {
            assert!(axis_err(*d, [1.0, 0.0]) < 1e-12, "{d:?}");
        }
        // Perpendicular axes half-way have no direction: (0, 0), the caller's fallback.
        let cross = vec![[1.0, 0.0], [0.0, 1.0]];
        let mid = resample_line_field(&cross, 2, 1, 1, 1);
        assert_eq!(mid[0], [0.0, 0.0]);
        // Upsampling a constant angle field is exact.
        let c = vec![tangent_from_angle_value(0.3); 4];
        for d in resample_line_field(&c, 2, 2, 5, 3) {
            assert!(axis_err(d, tangent_from_angle_value(0.3)) < 1e-12);
        }
    }
}
