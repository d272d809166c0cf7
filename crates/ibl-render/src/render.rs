//! The reference render of the contract scene: every pixel on a sphere is
//! w_r·Lexact(R, r) + w_e·E(n)/π (the engine's own weights, [`crate::brdf`]); the background
//! is 0.

use crate::brdf::{dfg_roughness, weights, Engine, ExactDfg};
use crate::lighting::Lighting;
use crate::scene::{self, Sphere, HEIGHT, SPHERES, WIDTH};
use ibl_core::progress::Progress;
use ibl_core::Image;
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
    use rayon::prelude::*;
    // The engine's DFG, once per column (its table's roughness is the column's, clamped as the
    // engine clamps it).
    let tables: Vec<ExactDfg> = (0..scene::COLUMNS)
        .into_par_iter()
        .map(|c| ExactDfg::new(dfg_roughness(engine, Sphere::new(c).roughness)))
        .collect();
    progress.start("render", HEIGHT as u64);
    let rows: Vec<Vec<f32>> = (0..HEIGHT)
        .into_par_iter()
        .map_init(TreeBuffers::default, |buf, py| {
            let mut row = vec![0.0f32; WIDTH * 3];
            for px in 0..WIDTH {
                let Some(h) = scene::hit(px, py) else {
                    continue;
                };
                if !spheres[h.sphere.index] {
                    continue;
                }
                let s = h.sphere;
                let w = weights(
                    engine,
                    h.n_dot_v,
                    s.roughness,
                    s.metallic,
                    &tables[s.column],
                );
                let spec = lighting.specular(h.reflected, s.roughness, buf);
                let irr = if w.irradiance != 0.0 {
                    lighting.irradiance(h.normal)
                } else {
                    [0.0; 3]
                };
                for k in 0..3 {
                    row[px * 3 + k] =
                        (w.radiance * spec[k] as f64 + w.irradiance * irr[k] as f64) as f32;
                }
            }
            progress.inc(1);
            row
        })
        .collect();
    progress.finish();
    Image::from_data(WIDTH, HEIGHT, 3, rows.concat()).expect("768×256×3 floats")
}

/// Every sphere.
pub const ALL_SPHERES: [bool; SPHERES] = [true; SPHERES];
