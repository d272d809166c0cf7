//! The orientation panorama and its checker. The panorama is an equirect (2:1, our mapping:
//! u = 0.5 + atan2(z, x)/2π, v = acos(y)/π, docs/CONVENTIONS.md) with one saturated patch
//! (30° radius) on each axis, in colours no turn or mirror can confuse, and a white letter
//! "F" beside each patch's centre as the chirality mark (it reads backwards in a mirror and
//! upside down when turned). The checker reads, in a render of the contract scene, which patch
//! the mirror sphere (metallic, r = 0) shows where it reflects ±X, ±Y and +Z, and names the
//! transform that maps the expected world onto what the engine showed.

use crate::scene::{self, Sphere};
use glam::DVec3;
use ibl_core::Image;

/// Angular radius of every patch.
pub const PATCH_RADIUS_DEG: f64 = 30.0;
/// Background radiance (grey).
pub const BACKGROUND: f32 = 0.05;

/// The six patches: axis, name, linear RGB colour.
pub const PATCHES: [([f64; 3], &str, [f32; 3]); 6] = [
    ([1.0, 0.0, 0.0], "+X", [1.0, 0.0, 0.0]),  // red
    ([-1.0, 0.0, 0.0], "-X", [0.0, 1.0, 1.0]), // cyan
    ([0.0, 1.0, 0.0], "+Y", [0.0, 1.0, 0.0]),  // green
    ([0.0, -1.0, 0.0], "-Y", [1.0, 0.0, 1.0]), // magenta
    ([0.0, 0.0, 1.0], "+Z", [0.0, 0.0, 1.0]),  // blue
    ([0.0, 0.0, -1.0], "-Z", [1.0, 1.0, 0.0]), // yellow
];

/// The letter "F", 5 columns × 7 rows, row 0 at the top.
const GLYPH: [&str; 7] = [
    "#####", "#....", "#....", "####.", "#....", "#....", "#....",
];
/// Glyph cell size in the patch's gnomonic (tangent-plane) coordinates.
const CELL: f64 = 0.05;
/// Lower-left corner of the glyph in those coordinates: beside the centre, which stays the
/// patch's colour for the checker.
const GLYPH_ORIGIN: (f64, f64) = (0.1, 0.02);

/// The image-right and image-up tangent directions of a patch as seen from the centre of the
/// world looking out along its axis (right × up = −axis): for the horizon patches they are
/// the panorama's own right and up, so the letters read correctly in the equirect image.
fn frame(axis: DVec3) -> (DVec3, DVec3) {
    if axis.y.abs() > 0.5 {
        // Poles: right = +X, up = ±Z so that right × up = −axis.
        (DVec3::X, DVec3::new(0.0, 0.0, axis.y))
    } else {
        // u grows with atan2(z, x): image-right is d/dφ (cos φ, 0, sin φ) = (−z, 0, x).
        (DVec3::new(-axis.z, 0.0, axis.x), DVec3::Y)
    }
}

/// Radiance of the panorama in direction `d` (unit).
pub fn radiance(d: DVec3) -> [f32; 3] {
    let cos_r = PATCH_RADIUS_DEG.to_radians().cos();
    for (axis, _, colour) in PATCHES {
        let a = DVec3::from(axis);
        let c = d.dot(a);
        if c < cos_r {
            continue;
        }
        let (right, up) = frame(a);
        let (s, t) = (d.dot(right) / c, d.dot(up) / c);
        let col = ((s - GLYPH_ORIGIN.0) / CELL).floor();
        let row_from_bottom = ((t - GLYPH_ORIGIN.1) / CELL).floor();
        if (0.0..5.0).contains(&col) && (0.0..7.0).contains(&row_from_bottom) {
            let row = 6 - row_from_bottom as usize;
            if GLYPH[row].as_bytes()[col as usize] == b'#' {
                return [1.0; 3];
            }
        }
        return colour;
    }
    [BACKGROUND; 3]
}

/// The panorama as a `width` × `width`/2 equirect, each pixel the mean of 2×2 point samples.
pub fn panorama(width: usize) -> Image {
    let (w, h) = (width, (width / 2).max(1));
    let mut img = Image::new(w, h, 3);
    for y in 0..h {
        for x in 0..w {
            let mut acc = [0.0f32; 3];
            for (a, b) in [(0.25, 0.25), (0.75, 0.25), (0.25, 0.75), (0.75, 0.75)] {
                let u = (x as f64 + a) / w as f64;
                let v = (y as f64 + b) / h as f64;
                let phi = (u - 0.5) * std::f64::consts::TAU;
                let theta = v * std::f64::consts::PI;
                let d = DVec3::new(
                    theta.sin() * phi.cos(),
                    theta.cos(),
                    theta.sin() * phi.sin(),
                );
                let c = radiance(d);
                for k in 0..3 {
                    acc[k] += 0.25 * c[k];
                }
            }
            img.texel_mut(x, y).copy_from_slice(&acc);
        }
    }
    img
}

/// What one probe of the checker saw.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Probe {
    /// The world direction the mirror sphere reflects there ("+X", …).
    pub direction: &'static str,
    /// Pixel (column, row) read (the mean of its 3×3 neighbourhood).
    pub pixel: (usize, usize),
    /// The mean colour.
    pub colour: [f32; 3],
    /// The patch that colour is ("+Z", …), or None (background, mark or unknown).
    pub patch: Option<&'static str>,
}

/// The checker's verdict.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Report {
    /// "correct", or the transform named ("mirrored: x flipped", "turned 90° about +Y",
    /// "upside down (turned 180° about +Z)", …), or "unrecognised: …".
    pub verdict: String,
    /// Whether the render shows the world as our convention maps the panorama.
    pub correct: bool,
    /// M with (what the render shows at world direction d) = M·d, rows; None if unrecognised.
    pub matrix: Option<[[i32; 3]; 3]>,
    /// Every probe.
    pub probes: Vec<Probe>,
}

/// Which patch a colour is: its channels above half its largest one must match a patch's.
fn classify(c: [f32; 3]) -> Option<&'static str> {
    let m = c.iter().cloned().fold(0.0f32, f32::max);
    if m.is_nan() || m <= 0.0 || !m.is_finite() {
        return None;
    }
    let bits = c.map(|v| v > 0.5 * m);
    PATCHES
        .iter()
        .find(|(_, _, col)| col.map(|v| v > 0.5) == bits)
        .map(|p| p.1)
}

fn axis_of(name: &str) -> Option<[i32; 3]> {
    PATCHES
        .iter()
        .find(|p| p.1 == name)
        .map(|p| p.0.map(|v| v as i32))
}

/// Reads a render of the contract scene lit by [`panorama`] and names what the engine did to
/// the world (row 0 of `render` at the top).
pub fn check(render: &Image) -> Result<Report, String> {
    if (render.width, render.height) != (scene::WIDTH, scene::HEIGHT) || render.channels < 3 {
        return Err(format!(
            "the render is {}×{}, the scene is {}×{}",
            render.width,
            render.height,
            scene::WIDTH,
            scene::HEIGHT
        ));
    }
    let mirror = Sphere::new(0);
    let dirs: [(&'static str, DVec3); 5] = [
        ("+X", DVec3::X),
        ("-X", -DVec3::X),
        ("+Y", DVec3::Y),
        ("-Y", -DVec3::Y),
        ("+Z", DVec3::Z),
    ];
    let mut probes = Vec::new();
    for (name, d) in dirs {
        let (x, y) = scene::point_reflecting(&mirror, d).expect("visible directions");
        let (px, py) = scene::world_to_pixel(x, y);
        let (px, py) = (px.round() as usize, py.round() as usize);
        let mut acc = [0.0f32; 3];
        for dy in -1i64..=1 {
            for dx in -1i64..=1 {
                let c = render.rgb((px as i64 + dx) as usize, (py as i64 + dy) as usize);
                for k in 0..3 {
                    acc[k] += c[k] / 9.0;
                }
            }
        }
        probes.push(Probe {
            direction: name,
            pixel: (px, py),
            colour: acc,
            patch: classify(acc),
        });
    }
    let seen = |k: usize| probes[k].patch.and_then(axis_of);
    let cols = [seen(0), seen(2), seen(4)];
    let negs = [seen(1), seen(3)];
    let unrecognised = |why: String| Report {
        verdict: format!("unrecognised: {why}"),
        correct: false,
        matrix: None,
        probes: probes.clone(),
    };
    let (Some(mx), Some(my), Some(mz)) = (cols[0], cols[1], cols[2]) else {
        let missing: Vec<&str> = probes
            .iter()
            .filter(|p| p.patch.is_none())
            .map(|p| p.direction)
            .collect();
        return Ok(unrecognised(format!(
            "no patch colour where the mirror reflects {}",
            missing.join(", ")
        )));
    };
    if negs[0] != Some(mx.map(|v| -v)) || negs[1] != Some(my.map(|v| -v)) {
        return Ok(unrecognised(
            "−X/−Y do not show the patches opposite +X/+Y (not a turn or a mirror of the world)"
                .into(),
        ));
    }
    // M's columns are the images of +X, +Y, +Z.
    let m: [[i32; 3]; 3] = std::array::from_fn(|r| [mx[r], my[r], mz[r]]);
    let det = m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
        - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
        + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
    if det.abs() != 1 {
        return Ok(unrecognised(
            "the three axes seen are not independent".into(),
        ));
    }
    let verdict = name_transform(&m, det);
    Ok(Report {
        correct: verdict == "correct",
        verdict,
        matrix: Some(m),
        probes,
    })
}

fn axis_name(v: [i32; 3]) -> String {
    let mut s = String::new();
    for (k, c) in ["X", "Y", "Z"].iter().enumerate() {
        match v[k] {
            1 => s.push_str(&format!("+{c}")),
            -1 => s.push_str(&format!("-{c}")),
            _ => {}
        }
    }
    s
}

/// Names a signed permutation matrix (columns: images of +X, +Y, +Z).
fn name_transform(m: &[[i32; 3]; 3], det: i32) -> String {
    let id = [[1, 0, 0], [0, 1, 0], [0, 0, 1]];
    if *m == id {
        return "correct".into();
    }
    let upside = m[1][1] == -1;
    let suffix = if upside { " (upside down)" } else { "" };
    if det == 1 {
        let tr = m[0][0] + m[1][1] + m[2][2];
        let angle = (((tr - 1) as f64) / 2.0)
            .clamp(-1.0, 1.0)
            .acos()
            .to_degrees()
            .round();
        let axis = if tr == -1 {
            // 180°: the axis is a non-zero column of M + I.
            let col = (0..3)
                .map(|c| [m[0][c] + id[0][c], m[1][c] + id[1][c], m[2][c] + id[2][c]])
                .find(|v| v.iter().any(|&x| x != 0))
                .unwrap_or([0, 1, 0]);
            col.map(|v| v.signum())
        } else {
            [m[2][1] - m[1][2], m[0][2] - m[2][0], m[1][0] - m[0][1]].map(|v| v.signum())
        };
        format!("turned {angle}° about {}{suffix}", axis_name(axis))
    } else {
        let flips: Vec<usize> = (0..3).filter(|&k| m[k][k] == -1).collect();
        let diagonal = (0..3).all(|r| (0..3).all(|c| r == c || m[r][c] == 0));
        if diagonal && flips.len() == 1 {
            let axis = ["x (left-right mirror)", "y", "z (front-back mirror)"][flips[0]];
            format!("mirrored: {axis} flipped{suffix}")
        } else {
            format!(
                "mirrored and turned: +X shows {}, +Y shows {}, +Z shows {}{suffix}",
                axis_name([m[0][0], m[1][0], m[2][0]]),
                axis_name([m[0][1], m[1][1], m[2][1]]),
                axis_name([m[0][2], m[1][2], m[2][2]])
            )
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn patches_sit_on_their_axes_in_our_equirect_mapping() {
        let img = panorama(512);
        assert_eq!((img.width, img.height), (512, 256));
        // +X is at u = 0.5 on the equator, +Z at u = 0.75, −Z at u = 0.25, +Y at the top row.
        let at = |u: f64, v: f64| img.rgb((u * 512.0) as usize, (v * 256.0) as usize);
        assert_eq!(classify(at(0.5, 0.5)), Some("+X"));
        assert_eq!(classify(at(0.75, 0.5)), Some("+Z"));
        assert_eq!(classify(at(0.25, 0.5)), Some("-Z"));
        assert_eq!(classify(at(0.001, 0.5)), Some("-X"));
        assert_eq!(classify(at(0.3, 0.001)), Some("+Y"));
        assert_eq!(classify(at(0.3, 0.999)), Some("-Y"));
        assert_eq!(at(0.375, 0.5), [BACKGROUND; 3]);
    }

    #[test]
    fn the_mark_is_chiral() {
        // The glyph differs from its mirror image and from its 180° turn.
        let mirrored: Vec<String> = GLYPH.iter().map(|r| r.chars().rev().collect()).collect();
        let turned: Vec<String> = GLYPH
            .iter()
            .rev()
            .map(|r| r.chars().rev().collect())
            .collect();
        assert!(GLYPH.iter().zip(&mirrored).any(|(a, b)| *a != b));
        assert!(GLYPH.iter().zip(&turned).any(|(a, b)| *a != b));
        // And it is drawn: some white pixels in the +X patch, right of its centre.
        let img = panorama(1024);
        let white = (180..256).any(|y| (512..600).any(|x| img.rgb(x, y) == [1.0; 3]));
        assert!(white);
    }

    #[test]
    fn transforms_are_named() {
        let t = |m: [[i32; 3]; 3]| {
            let det = m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
                - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
                + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
            name_transform(&m, det)
        };
        assert_eq!(t([[1, 0, 0], [0, 1, 0], [0, 0, 1]]), "correct");
        assert_eq!(
            t([[-1, 0, 0], [0, 1, 0], [0, 0, 1]]),
            "mirrored: x (left-right mirror) flipped"
        );
        assert_eq!(
            t([[1, 0, 0], [0, -1, 0], [0, 0, 1]]),
            "mirrored: y flipped (upside down)"
        );
        // +X → −Z, +Z → +X: a turn about +Y by 90°.
        assert_eq!(t([[0, 0, 1], [0, 1, 0], [-1, 0, 0]]), "turned 90° about +Y");
        assert_eq!(
            t([[-1, 0, 0], [0, -1, 0], [0, 0, 1]]),
            "turned 180° about +Z (upside down)"
        );
    }
}
