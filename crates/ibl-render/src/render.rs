//! The reference render of the contract scene: every pixel on a sphere is
//! w_r·Lexact(R, r) + w_e·E(n)/π (the engine's own weights, [`crate::brdf`]); the background
//! is 0.

use crate::brdf::{dfg_roughness, weights, Engine, ExactDfg};
use crate::lighting::Lighting;
use crate::scene::{self, Sphere, HEIGHT, SPHERES, WIDTH};
use glam::DVec3;
use ibl_core::progress::Progress;
use ibl_core::Image;
use ibl_core::Rgb;
use ibl_prefilter::tree::TreeBuffers;

/// Renders the scene lit by `lighting` with `engine`'s BRDF terms: a 768×256 RGB float image,
/// row 0 at the top. `spheres` selects which spheres are drawn (all twelve for the contract;
/// tests draw fewer). Rows in parallel, each pixel on its own: bit-identical for any thread
/// count.
pub fn render(
    lighting: &Lighting,
    engine: Engine,
    spheres: &[bool; SPHERES],
    progress: &dyn Progress,
) -> Image {
    render_lit(lighting, engine, spheres, 1, progress)
}

/// What lights the spheres: the prefiltered radiance and the irradiance E/π at any direction.
pub trait Lit: Sync {
    /// The prefiltered radiance at perceptual roughness `r` in direction `d` (unit).
    fn specular(&self, d: DVec3, r: f64, buffers: &mut TreeBuffers) -> Rgb;
    /// E(n)/π.
    fn irradiance(&self, n: DVec3) -> Rgb;
}

impl Lit for Lighting {
    fn specular(&self, d: DVec3, r: f64, buffers: &mut TreeBuffers) -> Rgb {
        Lighting::specular(self, d, r, buffers)
    }
    fn irradiance(&self, n: DVec3) -> Rgb {
        Lighting::irradiance(self, n)
    }
}

/// The scene lit by `lit`, drawn `scale` times smaller than the contract (768/scale ×
/// 256/scale; 1 is the contract image).
pub fn render_lit(
    lit: &dyn Lit,
    engine: Engine,
    spheres: &[bool; SPHERES],
    scale: usize,
    progress: &dyn Progress,
) -> Image {
    render_engines(lit, &[engine], spheres, scale, progress)
        .pop()
        .expect("one engine, one image")
}

/// One render per engine of `engines`, the lighting evaluated once per pixel for all of them
/// (it is nearly all the cost): what `render-ref --all-engines` writes.
pub fn render_engines(
    lit: &dyn Lit,
    engines: &[Engine],
    spheres: &[bool; SPHERES],
    scale: usize,
    progress: &dyn Progress,
) -> Vec<Image> {
    use rayon::prelude::*;
    let scale = scale.max(1);
    let (width, height) = (WIDTH / scale, HEIGHT / scale);
    // Each engine's DFG, once per column (its table's roughness is the column's, clamped as
    // the engine clamps it).
    let tables: Vec<Vec<ExactDfg>> = engines
        .iter()
        .map(|&e| {
            (0..scene::COLUMNS)
                .into_par_iter()
                .map(|c| ExactDfg::new(dfg_roughness(e, Sphere::new(c).roughness)))
                .collect()
        })
        .collect();
    let n = engines.len();
    progress.start("render", height as u64);
    let rows: Vec<Vec<f32>> = (0..height)
        .into_par_iter()
        .map_init(TreeBuffers::default, |buf, py| {
            // The row of every engine, side by side.
            let mut row = vec![0.0f32; n * width * 3];
            for px in 0..width {
                let Some(h) = scene::hit_scaled(px, py, scale) else {
                    continue;
                };
                if !spheres[h.sphere.index] {
                    continue;
                }
                let s = h.sphere;
                let ws: Vec<_> = engines
                    .iter()
                    .zip(&tables)
                    .map(|(&e, t)| weights(e, h.n_dot_v, s.roughness, s.metallic, &t[s.column]))
                    .collect();
                let spec = lit.specular(h.reflected, s.roughness, buf);
                let irr = if ws.iter().any(|w| w.irradiance != 0.0) {
                    lit.irradiance(h.normal)
                } else {
                    [0.0; 3]
                };
                for (e, w) in ws.iter().enumerate() {
                    for k in 0..3 {
                        row[(e * width + px) * 3 + k] =
                            (w.radiance * spec[k] as f64 + w.irradiance * irr[k] as f64) as f32;
                    }
                }
            }
            progress.inc(1);
            row
        })
        .collect();
    progress.finish();
    (0..n)
        .map(|e| {
            let data: Vec<f32> = rows
                .iter()
                .flat_map(|r| r[e * width * 3..(e + 1) * width * 3].iter().copied())
                .collect();
            Image::from_data(width, height, 3, data).expect("width × height × 3 floats")
        })
        .collect()
}

/// Every sphere.
pub const ALL_SPHERES: [bool; SPHERES] = [true; SPHERES];

/// A baked chain as an engine's shader reads it: its lod for roughness r by the engine's
/// mapping, bilinear within a level and seamless across faces, linear between levels
/// (`ibl_prefilter::runtime::lookup`), and its irradiance cube read bilinearly.
pub struct ChainLookup {
    chain: ibl_core::bordered::BorderedMips,
    mapping: ibl_target::LodMapping,
    irradiance: Option<ibl_core::Cubemap>,
}

impl ChainLookup {
    /// The lookup of `mips` by `mapping` (e.g. `Target::Gltf.spec().lod`), with the E/π cube
    /// `irradiance` (None: the diffuse term reads the chain's last level, as a fallback).
    pub fn new(
        mips: &ibl_core::CubeMips,
        mapping: ibl_target::LodMapping,
        irradiance: Option<ibl_core::Cubemap>,
    ) -> ChainLookup {
        ChainLookup {
            chain: ibl_core::bordered::BorderedMips::new(mips),
            mapping,
            irradiance,
        }
    }
}

impl Lit for ChainLookup {
    fn specular(&self, d: DVec3, r: f64, _buffers: &mut TreeBuffers) -> Rgb {
        ibl_prefilter::runtime::lookup(&self.chain, self.mapping, d.as_vec3(), r as f32)
    }
    fn irradiance(&self, n: DVec3) -> Rgb {
        match &self.irradiance {
            Some(c) => c.sample_bilinear(n.as_vec3()),
            None => ibl_prefilter::runtime::lookup(&self.chain, self.mapping, n.as_vec3(), 1.0),
        }
    }
}
