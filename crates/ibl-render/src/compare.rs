//! The contract's comparison of a render with the reference: per sphere, over the masked
//! pixels (centre at most 0.9 − 2/64 from the sphere's centre), the mean and the 95th
//! percentile of |render − reference| / max(reference, ε) of luminance; grouped as mirror
//! (r = 0) and rough (r ≥ 0.2) spheres, metallic and dielectric rows apart.

use crate::scene::{self, Sphere, HEIGHT, SPHERES, WIDTH};
use ibl_core::{luminance, Image};

/// The error of one sphere.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct SphereError {
    /// Sphere index 0..12.
    pub sphere: usize,
    /// Its label ("metal r=0.4").
    pub label: String,
    /// Masked pixels compared.
    pub pixels: usize,
    /// Mean relative error of luminance.
    pub mean_rel: f64,
    /// 95th percentile of the same.
    pub p95_rel: f64,
}

/// The errors of a render, per sphere and per group.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Comparison {
    /// Per sphere, in index order.
    pub spheres: Vec<SphereError>,
    /// Mean of the per-sphere means of the metallic mirror (r = 0).
    pub metal_mirror: f64,
    /// Mean of the per-sphere means of the metallic rough spheres (r ≥ 0.2).
    pub metal_rough: f64,
    /// Mean of the per-sphere means of the dielectric mirror.
    pub dielectric_mirror: f64,
    /// Mean of the per-sphere means of the dielectric rough spheres.
    pub dielectric_rough: f64,
}

/// ε of the relative error, relative to the mean luminance of the reference over the mask
/// (a black reference pixel would otherwise dominate the mean).
pub const EPSILON_OF_MEAN: f64 = 1e-3;

/// Compares `render` with `reference` (both 768×256, row 0 at the top).
pub fn compare(render: &Image, reference: &Image) -> Result<Comparison, String> {
    compare_scaled(render, reference, 1)
}

/// [`compare`] for the scene drawn `scale` times smaller (previews).
pub fn compare_scaled(
    render: &Image,
    reference: &Image,
    scale: usize,
) -> Result<Comparison, String> {
    let scale = scale.max(1);
    let (w, h) = (WIDTH / scale, HEIGHT / scale);
    for (name, img) in [("render", render), ("reference", reference)] {
        if (img.width, img.height) != (w, h) || img.channels < 3 {
            return Err(format!(
                "the {name} is {}×{}×{}, the scene is {w}×{h} RGB",
                img.width, img.height, img.channels
            ));
        }
    }
    let mut per: Vec<Vec<(f64, f64)>> = vec![Vec::new(); SPHERES];
    for py in 0..h {
        for px in 0..w {
            if let Some(h) = scene::hit_scaled(px, py, scale).filter(|h| h.masked) {
                let a = luminance(render.rgb(px, py)) as f64;
                let b = luminance(reference.rgb(px, py)) as f64;
                per[h.sphere.index].push((a, b));
            }
        }
    }
    let spheres: Vec<SphereError> = per
        .iter()
        .enumerate()
        .map(|(i, pairs)| {
            let mean_ref = pairs.iter().map(|p| p.1).sum::<f64>() / pairs.len().max(1) as f64;
            let eps = (EPSILON_OF_MEAN * mean_ref).max(1e-30);
            let mut e: Vec<f64> = pairs
                .iter()
                .map(|&(a, b)| {
                    let r = (a - b).abs() / b.max(eps);
                    if r.is_finite() {
                        r
                    } else {
                        f64::INFINITY
                    }
                })
                .collect();
            e.sort_by(|a, b| a.total_cmp(b));
            let mean = e.iter().sum::<f64>() / e.len().max(1) as f64;
            let p95 = e
                .get(((e.len() as f64 * 0.95).ceil() as usize).saturating_sub(1))
                .copied()
                .unwrap_or(0.0);
            SphereError {
                sphere: i,
                label: Sphere::new(i).label(),
                pixels: e.len(),
                mean_rel: mean,
                p95_rel: p95,
            }
        })
        .collect();
    let group = |metallic: bool, mirror: bool| {
        let v: Vec<f64> = spheres
            .iter()
            .filter(|s| {
                let sp = Sphere::new(s.sphere);
                sp.metallic == metallic && (sp.roughness == 0.0) == mirror
            })
            .map(|s| s.mean_rel)
            .collect();
        v.iter().sum::<f64>() / v.len().max(1) as f64
    };
    Ok(Comparison {
        metal_mirror: group(true, true),
        metal_rough: group(true, false),
        dielectric_mirror: group(false, true),
        dielectric_rough: group(false, false),
        spheres,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_uniform_scale_is_its_relative_error_everywhere() {
        let mut a = Image::new(WIDTH, HEIGHT, 3);
        for py in 0..HEIGHT {
            for px in 0..WIDTH {
                a.texel_mut(px, py)
                    .copy_from_slice(&[1.0 + px as f32 * 0.01, 0.5, 0.25]);
            }
        }
        let mut b = a.clone();
        b.data.iter_mut().for_each(|v| *v *= 1.1);
        let c = compare(&b, &a).unwrap();
        for s in &c.spheres {
            assert!(
                (s.mean_rel - 0.1).abs() < 1e-5 && (s.p95_rel - 0.1).abs() < 1e-5,
                "{s:?}"
            );
            assert!(s.pixels > 9000);
        }
        assert!((c.metal_rough - 0.1).abs() < 1e-5);
        assert_eq!(compare(&a, &a).unwrap().metal_mirror, 0.0);
        assert!(compare(&Image::new(10, 10, 3), &a).is_err());
    }
}
