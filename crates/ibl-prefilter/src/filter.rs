//! The filtered-importance-sampling kernel of one level: for each output texel, the level's
//! sample table turned into its tangent frame and read trilinearly from the source pyramid.

use crate::samples::{tangent_frame, SampleTable};
use glam::Vec3;
use ibl_core::bordered::BorderedMips;
use ibl_core::cube::{texel_direction, Cubemap};
use ibl_core::progress::Progress;
use ibl_core::traverse::map_cube_texels_with;
use ibl_core::Rgb;

/// Filtered value in direction `n` (unit): Σ_k w_k · L_{lod_k}(T_n l_k), with T_n the tangent
/// frame of n. Sums in f64 so a constant environment comes back to the last bit that f32
/// output can hold.
#[inline]
pub(crate) fn filter_direction(pyr: &BorderedMips, table: &SampleTable, n: Vec3) -> Rgb {
    let (t, b) = tangent_frame(n);
    let mut acc = [0.0f64; 3];
    for k in 0..table.dirs.len() {
        let s = table.dirs[k];
        let d = t * s.x + b * s.y + n * s.z;
        let c = pyr.trilinear(d, table.mips[k] as usize, table.fracs[k]);
        let w = table.weights[k] as f64;
        acc[0] += w * c[0] as f64;
        acc[1] += w * c[1] as f64;
        acc[2] += w * c[2] as f64;
    }
    [acc[0] as f32, acc[1] as f32, acc[2] as f32]
}

/// One level of the chain: an n×n cube, every texel filtered with `table`.
pub(crate) fn filter_level(
    pyr: &BorderedMips,
    table: &SampleTable,
    n: usize,
    progress: &dyn Progress,
) -> Cubemap {
    map_cube_texels_with(
        n,
        progress,
        || (),
        |_, face, i, j| filter_direction(pyr, table, texel_direction(face, i, j, n)),
    )
}
