//! The render scene "sphere-rows v1" (the contract the engine harness and this renderer share):
//! a 768×256 orthographic view of two rows of six spheres, metallic on top, dielectric below,
//! perceptual roughness 0, 0.2 … 1 from left to right.

use glam::DVec3;

/// Image width in pixels.
pub const WIDTH: usize = 768;
/// Image height in pixels.
pub const HEIGHT: usize = 256;
/// Pixels per world unit (the view window is x ∈ [−6, 6], y ∈ [−2, 2]).
pub const PIXELS_PER_UNIT: f64 = 64.0;
/// Sphere radius in world units.
pub const RADIUS: f64 = 0.9;
/// Pixels whose centre is within this many pixels of a sphere's rim are left out of every
/// comparison (the contract's mask).
pub const RIM_MARGIN_PIXELS: f64 = 2.0;
/// Spheres per row.
pub const COLUMNS: usize = 6;
/// Spheres in the scene (two rows).
pub const SPHERES: usize = 2 * COLUMNS;
/// F0 of the dielectric row (glTF's default dielectric: IOR 1.5).
pub const DIELECTRIC_F0: f64 = 0.04;

/// One sphere of the scene.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct Sphere {
    /// Index 0..12: the top (metallic) row 0..6 left to right, then the bottom row.
    pub index: usize,
    /// Column 0..6 (roughness i/5).
    pub column: usize,
    /// Centre x in world units.
    pub cx: f64,
    /// Centre y in world units (+1 top row, −1 bottom row).
    pub cy: f64,
    /// Perceptual roughness r = column/5 (GGX α = r²).
    pub roughness: f64,
    /// Metallic (1, F0 = baseColor = 1) or dielectric (0, F0 = 0.04, diffuse albedo 1).
    pub metallic: bool,
}

impl Sphere {
    /// Sphere `index` (0..12) of the contract.
    pub fn new(index: usize) -> Sphere {
        let column = index % COLUMNS;
        let metallic = index < COLUMNS;
        Sphere {
            index,
            column,
            cx: -5.0 + 2.0 * column as f64,
            cy: if metallic { 1.0 } else { -1.0 },
            roughness: column as f64 / 5.0,
            metallic,
        }
    }

    /// All twelve spheres.
    pub fn all() -> [Sphere; SPHERES] {
        std::array::from_fn(Sphere::new)
    }

    /// F0 of the sphere's material (white base colour).
    pub fn f0(&self) -> f64 {
        if self.metallic {
            1.0
        } else {
            DIELECTRIC_F0
        }
    }

    /// A short label: "metal r=0.4", "dielectric r=1.0".
    pub fn label(&self) -> String {
        format!(
            "{} r={:.1}",
            if self.metallic { "metal" } else { "dielectric" },
            self.roughness
        )
    }

    /// Pixel column and row of the sphere's centre (as a real number: the centre falls between
    /// pixel centres).
    pub fn centre_pixel(&self) -> (f64, f64) {
        (
            (self.cx + 6.0) * PIXELS_PER_UNIT - 0.5,
            (2.0 - self.cy) * PIXELS_PER_UNIT - 0.5,
        )
    }
}

/// World (x, y) of pixel (px, py)'s centre: x = −6 + (px + 0.5)/64, y = 2 − (py + 0.5)/64.
pub fn pixel_centre(px: usize, py: usize) -> (f64, f64) {
    (
        -6.0 + (px as f64 + 0.5) / PIXELS_PER_UNIT,
        2.0 - (py as f64 + 0.5) / PIXELS_PER_UNIT,
    )
}

/// The view vector (towards the eye) of every pixel.
pub const VIEW: DVec3 = DVec3::new(0.0, 0.0, 1.0);

/// What a pixel sees of a sphere.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    /// The sphere.
    pub sphere: Sphere,
    /// Unit normal n = (x − cx, y − cy, √(0.81 − (x−cx)² − (y−cy)²)) / 0.9.
    pub normal: DVec3,
    /// n·v (= n.z).
    pub n_dot_v: f64,
    /// Mirror direction R = reflect(−v, n) = 2(n·v)n − v.
    pub reflected: DVec3,
    /// Whether the pixel is in the comparison mask (centre at most 0.9 − 2/64 from the
    /// sphere's centre).
    pub masked: bool,
}

/// The sphere a world point (x, y) lies on, if any (the spheres are disjoint: 0.2 units apart).
pub fn hit_at(x: f64, y: f64) -> Option<Hit> {
    let column = ((x + 6.0) / 2.0).floor();
    if !(0.0..COLUMNS as f64).contains(&column) {
        return None;
    }
    let row = if y >= 0.0 { 0 } else { 1 };
    let sphere = Sphere::new(row * COLUMNS + column as usize);
    let (dx, dy) = (x - sphere.cx, y - sphere.cy);
    let d2 = dx * dx + dy * dy;
    if d2 > RADIUS * RADIUS {
        return None;
    }
    let normal = DVec3::new(dx, dy, (RADIUS * RADIUS - d2).max(0.0).sqrt()) / RADIUS;
    let n_dot_v = normal.dot(VIEW);
    let reflected = 2.0 * n_dot_v * normal - VIEW;
    let inner = RADIUS - RIM_MARGIN_PIXELS / PIXELS_PER_UNIT;
    Some(Hit {
        sphere,
        normal,
        n_dot_v,
        reflected,
        masked: d2 <= inner * inner,
    })
}

/// What pixel (px, py) sees, if a sphere.
pub fn hit(px: usize, py: usize) -> Option<Hit> {
    let (x, y) = pixel_centre(px, py);
    hit_at(x, y)
}

/// What pixel (px, py) of the scene drawn `scale` times smaller (768/scale × 256/scale, for
/// previews) sees; scale 1 is [`hit`].
pub fn hit_scaled(px: usize, py: usize, scale: usize) -> Option<Hit> {
    let k = scale.max(1) as f64 / PIXELS_PER_UNIT;
    hit_at(-6.0 + (px as f64 + 0.5) * k, 2.0 - (py as f64 + 0.5) * k)
}

/// Where on the image a mirror sphere reflects direction `d` (unit): the world point whose
/// reflection vector is `d` on sphere `sphere` (the normal is the half vector of v and d), or
/// None when no visible normal does (d = −v exactly, behind the sphere).
pub fn point_reflecting(sphere: &Sphere, d: DVec3) -> Option<(f64, f64)> {
    let h = d + VIEW;
    if h.length_squared() < 1e-12 {
        return None;
    }
    let n = h.normalize();
    Some((sphere.cx + RADIUS * n.x, sphere.cy + RADIUS * n.y))
}

/// Pixel (column, row) as real numbers of world point (x, y) (inverse of [`pixel_centre`]).
pub fn world_to_pixel(x: f64, y: f64) -> (f64, f64) {
    (
        (x + 6.0) * PIXELS_PER_UNIT - 0.5,
        (2.0 - y) * PIXELS_PER_UNIT - 0.5,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pixel_centres_follow_the_contract() {
        assert_eq!(pixel_centre(0, 0), (-6.0 + 0.5 / 64.0, 2.0 - 0.5 / 64.0));
        assert_eq!(
            pixel_centre(767, 255),
            (6.0 - 0.5 / 64.0, -2.0 + 0.5 / 64.0)
        );
        let (px, py) = world_to_pixel(pixel_centre(300, 77).0, pixel_centre(300, 77).1);
        assert!((px - 300.0).abs() < 1e-9 && (py - 77.0).abs() < 1e-9);
    }

    #[test]
    fn spheres_follow_the_contract() {
        let s = Sphere::all();
        assert_eq!(
            (s[0].cx, s[0].cy, s[0].roughness, s[0].metallic),
            (-5.0, 1.0, 0.0, true)
        );
        assert_eq!(
            (s[11].cx, s[11].cy, s[11].roughness, s[11].metallic),
            (5.0, -1.0, 1.0, false)
        );
        assert!((s[7].roughness - 0.2).abs() < 1e-12 && s[7].f0() == DIELECTRIC_F0);
        // The centre of sphere 0 is world (−5, 1): between pixels 63/64 and 63/64.
        assert_eq!(s[0].centre_pixel(), (63.5, 63.5));
    }

    /// A pixel's normal and reflection against the contract's formulas, written out by hand.
    #[test]
    fn a_pixel_normal_and_reflection_match_the_contract() {
        // Pixel (80, 50): x = −6 + 80.5/64, y = 2 − 50.5/64, on sphere 0 (cx −5, cy 1).
        let h = hit(80, 50).expect("on sphere 0");
        assert_eq!(h.sphere.index, 0);
        let (x, y) = (-6.0 + 80.5 / 64.0, 2.0 - 50.5 / 64.0);
        let (dx, dy) = (x + 5.0, y - 1.0);
        let n = DVec3::new(dx, dy, (0.81 - dx * dx - dy * dy).sqrt()) / 0.9;
        assert!((h.normal - n).length() < 1e-12);
        assert!((h.normal.length() - 1.0).abs() < 1e-12);
        let r = 2.0 * n.z * n - DVec3::Z;
        assert!((h.reflected - r).length() < 1e-12);
        // Mirror law: R and v make equal angles with n, in the plane of n and v.
        assert!((h.reflected.dot(n) - n.z).abs() < 1e-12);
        assert!(h.reflected.cross(DVec3::Z).dot(n).abs() < 1e-12);
        assert!(h.masked);
        // Off every sphere: the gap between columns and the image corner.
        assert!(hit(128, 64).is_none() && hit(0, 0).is_none());
        // The rim: inside the sphere but outside the mask.
        let (cx, cy): (f64, f64) = (63.5 + 57.2, 63.5);
        let h = hit(cx.round() as usize, cy.round() as usize).unwrap();
        assert!(!h.masked);
    }

    #[test]
    fn the_mirror_law_inverts() {
        let s = Sphere::new(0);
        for d in [
            DVec3::X,
            DVec3::Y,
            -DVec3::X,
            -DVec3::Y,
            DVec3::Z,
            DVec3::new(0.3, -0.5, 0.2).normalize(),
        ] {
            let (x, y) = point_reflecting(&s, d).unwrap();
            let h = hit_at(
                x * (1.0 - 1e-12) + s.cx * 1e-12,
                y * (1.0 - 1e-12) + s.cy * 1e-12,
            )
            .unwrap();
            assert!(
                (h.reflected - d).length() < 1e-5,
                "{d:?} -> {:?}",
                h.reflected
            );
        }
        assert!(point_reflecting(&s, -DVec3::Z).is_none());
    }

    #[test]
    fn every_sphere_has_its_pixels() {
        let mut count = [0usize; SPHERES];
        for py in 0..HEIGHT {
            for px in 0..WIDTH {
                if let Some(h) = hit(px, py) {
                    count[h.sphere.index] += 1;
                }
            }
        }
        // π·57.6² ≈ 10423 pixels a sphere, all alike by symmetry.
        assert!(
            count.iter().all(|&c| (10_300..10_550).contains(&c)),
            "{count:?}"
        );
        assert!(count.iter().all(|&c| c == count[0]));
    }
}
