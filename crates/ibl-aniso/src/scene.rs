//! Scenes: an orthographic sphere seen from an azimuth and an elevation, with a per-pixel
//! shading frame (t, b, n) whose tangent comes from a `tpr-map` direction preset applied to the
//! sphere's "lathe" tangent (rings about +Y).

use glam::Vec3;
use ibl_material::direction::Preset;
use serde::Serialize;

/// A right-handed shading frame: t the tangent (α_t's axis), b = n × t, n the normal.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Frame {
    /// Tangent.
    pub t: Vec3,
    /// Bitangent n × t.
    pub b: Vec3,
    /// Normal.
    pub n: Vec3,
}

impl Frame {
    /// World → local (t, b, n) components.
    #[inline]
    pub fn to_local(&self, d: Vec3) -> Vec3 {
        Vec3::new(d.dot(self.t), d.dot(self.b), d.dot(self.n))
    }

    /// Local → world.
    #[inline]
    pub fn to_world(&self, l: Vec3) -> Vec3 {
        self.t * l.x + self.b * l.y + self.n * l.z
    }

    /// The frame with t → −t (and so b → −b): every anisotropic lobe is symmetric under it.
    pub fn flipped(&self) -> Frame {
        Frame {
            t: -self.t,
            b: -self.b,
            n: self.n,
        }
    }

    /// The frame turned by 90° about n: (t, b) → (b, −t). With α_t ↔ α_b (η → −η) it
    /// describes the same lobe.
    pub fn turned(&self) -> Frame {
        Frame {
            t: self.b,
            b: -self.t,
            n: self.n,
        }
    }
}

/// Orthographic camera for azimuth φ about +Y (φ = 0 looks from +Z) and elevation θ (degrees):
/// (right, up, towards-camera v).
pub fn camera(azimuth_deg: f32, elevation_deg: f32) -> (Vec3, Vec3, Vec3) {
    let (sp, cp) = azimuth_deg.to_radians().sin_cos();
    let (st, ct) = elevation_deg.clamp(-89.0, 89.0).to_radians().sin_cos();
    let v = Vec3::new(sp * ct, st, cp * ct);
    let right = Vec3::Y.cross(v).normalize();
    let up = v.cross(right);
    (right, up, v)
}

/// Normal of pixel (i, j) of an s×s image of the unit sphere (row 0 at the top), or `None`
/// outside the disc.
pub fn pixel_normal(i: usize, j: usize, s: usize, cam: (Vec3, Vec3, Vec3)) -> Option<Vec3> {
    let x = 2.0 * (i as f32 + 0.5) / s as f32 - 1.0;
    let y = 1.0 - 2.0 * (j as f32 + 0.5) / s as f32;
    let r2 = x * x + y * y;
    if r2 >= 1.0 {
        return None;
    }
    let z = (1.0 - r2).sqrt();
    Some((cam.0 * x + cam.1 * y + cam.2 * z).normalize())
}

/// Pixels within this sine of the poles are masked: the ring tangent Y × n is undefined at
/// the poles (docs/ANISOTROPY.md §6.11).
pub const POLE_MASK: f32 = 0.1;

/// The sphere's frame at normal n: the lathe tangent t₀ = Y × n/|Y × n| (rings about +Y),
/// b₀ = n × t₀, turned in the tangent plane by the preset's direction at the equirect UV of n
/// (u = ½ + atan2(n_x, n_z)/2π, v = acos(n_y)/π), as `tpr-map` turns it. `None` near the poles.
pub fn sphere_frame(n: Vec3, preset: &Preset) -> Option<Frame> {
    let ring = Vec3::Y.cross(n);
    let len = ring.length();
    if len < POLE_MASK {
        return None;
    }
    let t0 = ring / len;
    let b0 = n.cross(t0);
    let u = 0.5 + (n.x as f64).atan2(n.z as f64) / std::f64::consts::TAU;
    let v = (n.y as f64).clamp(-1.0, 1.0).acos() / std::f64::consts::PI;
    let d = preset.field(u, v, [1.0, 1.0], false);
    let t = t0 * d[0] as f32 + b0 * d[1] as f32;
    let t = if t.length_squared() > 1e-12 && t.is_finite() {
        t.normalize()
    } else {
        t0
    };
    Some(Frame {
        t,
        b: n.cross(t),
        n,
    })
}

/// One shaded pixel of a view.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct Pixel {
    /// Row-major index in the s×s image.
    pub idx: usize,
    /// The shading frame.
    pub frame: Frame,
    /// Unit direction towards the eye.
    pub v: Vec3,
}

/// The shaded pixels of an s×s sphere image under `cam` with tangent field `preset`.
pub fn sphere_pixels(s: usize, cam: (Vec3, Vec3, Vec3), preset: &Preset) -> Vec<Pixel> {
    let mut out = Vec::new();
    for j in 0..s {
        for i in 0..s {
            let Some(n) = pixel_normal(i, j, s, cam) else {
                continue;
            };
            // Grazing rim pixels (n·v < 0.02) are dropped: every method is 0 there.
            if n.dot(cam.2) < 0.02 {
                continue;
            }
            if let Some(frame) = sphere_frame(n, preset) {
                out.push(Pixel {
                    idx: j * s + i,
                    frame,
                    v: cam.2,
                });
            }
        }
    }
    out
}

/// The plate: the unit disc x² + z² ≤ 1 in the plane y = 0 (normal +Y), seen by a pinhole
/// camera at distance 3 from the centre, at azimuth φ about +Y (φ = 0 from +Z) and elevation θ
/// above the plate, with a 50° vertical field of view (Marcolongo 2020's frying pan, Cocco et
/// al. 2024 Fig. 22). UV = ((x+1)/2, (1−z)/2) on the disc; the base tangent is +X, b₀ = n × t₀
/// = −Z, turned by `preset` (a `radial` preset gives the pan's concentric grooves). The view
/// varies per pixel: v = normalize(eye − p).
pub fn plate_pixels(s: usize, azimuth_deg: f32, elevation_deg: f32, preset: &Preset) -> Vec<Pixel> {
    let (sp, cp) = azimuth_deg.to_radians().sin_cos();
    let (st, ct) = elevation_deg.clamp(5.0, 89.0).to_radians().sin_cos();
    let dir = Vec3::new(sp * ct, st, cp * ct);
    let eye = 3.0 * dir;
    let fwd = -dir;
    let right = fwd.cross(Vec3::Y).normalize();
    let up = right.cross(fwd);
    let half = 25f32.to_radians().tan();
    let n = Vec3::Y;
    let t0 = Vec3::X;
    let b0 = n.cross(t0);
    let mut out = Vec::new();
    for j in 0..s {
        for i in 0..s {
            let x = (2.0 * (i as f32 + 0.5) / s as f32 - 1.0) * half;
            let y = (1.0 - 2.0 * (j as f32 + 0.5) / s as f32) * half;
            let ray = (fwd + right * x + up * y).normalize();
            if ray.y >= -1e-6 {
                continue;
            }
            let p = eye + ray * (-eye.y / ray.y);
            if p.x * p.x + p.z * p.z > 1.0 {
                continue;
            }
            let (u, v) = (0.5 * (p.x as f64 + 1.0), 0.5 * (1.0 - p.z as f64));
            let d = preset.field(u, v, [1.0, 1.0], false);
            let t = t0 * d[0] as f32 + b0 * d[1] as f32;
            let t = if t.length_squared() > 1e-12 && t.is_finite() {
                t.normalize()
            } else {
                t0
            };
            out.push(Pixel {
                idx: j * s + i,
                frame: Frame {
                    t,
                    b: n.cross(t),
                    n,
                },
                v: (eye - p).normalize(),
            });
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_are_orthonormal_and_right_handed() {
        let preset: Preset = "spiral".parse().unwrap();
        for (az, el) in [(0.0, 0.0), (90.0, 30.0), (200.0, 60.0)] {
            let px = sphere_pixels(16, camera(az, el), &preset);
            assert!(px.len() > 100, "{}", px.len());
            for p in px {
                let f = p.frame;
                assert!((f.t.length() - 1.0).abs() < 1e-5 && (f.b.length() - 1.0).abs() < 1e-5);
                assert!(f.t.dot(f.n).abs() < 1e-5 && f.t.cross(f.b).dot(f.n) > 0.999);
            }
        }
        let plate = plate_pixels(32, 30.0, 40.0, &"radial".parse().unwrap());
        assert!(plate.len() > 150, "{}", plate.len());
        for p in plate {
            assert!(p.v.dot(p.frame.n) > 0.0 && (p.frame.t.length() - 1.0).abs() < 1e-5);
            assert!(p.frame.t.y.abs() < 1e-6);
        }
    }
}
