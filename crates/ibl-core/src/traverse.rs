//! The one texel traversal: parallel maps over cube faces and rows with per-thread state,
//! and ordered reductions whose result does not depend on the thread count.
//!
//! Kernels passed in here never see threads: they compute one texel (or one row) from its
//! coordinates. Work is split by rows, rows are reported to the progress sink.

use crate::cube::{Cubemap, Face};
use crate::progress::Progress;
use crate::Rgb;
use rayon::prelude::*;

/// Builds an n×n cubemap by evaluating `kernel(face, i, j)` for every texel in parallel.
pub fn map_cube_texels<K>(n: usize, progress: &dyn Progress, kernel: K) -> Cubemap
where
    K: Fn(Face, usize, usize) -> Rgb + Sync,
{
    map_cube_texels_with(n, progress, || (), |_, f, i, j| kernel(f, i, j))
}

/// As [`map_cube_texels`], with per-thread scratch state made by `init` (reused across rows).
pub fn map_cube_texels_with<S, I, K>(
    n: usize,
    progress: &dyn Progress,
    init: I,
    kernel: K,
) -> Cubemap
where
    I: Fn() -> S + Sync,
    K: Fn(&mut S, Face, usize, usize) -> Rgb + Sync,
{
    let mut cube = Cubemap::new(n);
    progress.start("texels", (6 * n * n) as u64);
    // Flatten (face, row) so both cores stay busy on small faces.
    let mut rows: Vec<(Face, usize, &mut [f32])> = Vec::with_capacity(6 * n);
    for (fi, face) in cube.faces.iter_mut().enumerate() {
        for (j, row) in face.data.chunks_mut(n * 3).enumerate() {
            rows.push((Face::from_index(fi), j, row));
        }
    }
    rows.into_par_iter()
        .for_each_init(&init, |state, (face, j, row)| {
            for i in 0..n {
                let c = kernel(state, face, i, j);
                row[i * 3..i * 3 + 3].copy_from_slice(&c);
            }
            progress.inc(n as u64);
        });
    progress.finish();
    cube
}

/// Evaluates `row_fn(r)` for rows 0..rows in parallel and folds the results **in row order**
/// with `combine`, so the sum is bit-identical for any thread count.
pub fn ordered_row_reduce<T, F, C>(rows: usize, row_fn: F, init: T, combine: C) -> T
where
    T: Send,
    F: Fn(usize) -> T + Sync,
    C: Fn(T, T) -> T,
{
    let partials: Vec<T> = (0..rows).into_par_iter().map(&row_fn).collect();
    partials.into_iter().fold(init, combine)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::progress::NoProgress;

    #[test]
    fn map_visits_each_texel_once_in_place() {
        let n = 5;
        let cube = map_cube_texels(n, &NoProgress, |f, i, j| {
            [f as usize as f32, i as f32, j as f32]
        });
        for f in Face::ALL {
            for j in 0..n {
                for i in 0..n {
                    assert_eq!(cube.texel(f, i, j), [f as usize as f32, i as f32, j as f32]);
                }
            }
        }
    }

    #[test]
    fn ordered_reduce_is_thread_count_independent() {
        let f = |r: usize| (r as f64 * 0.1).sin() * 1e-3 + 1e7;
        let one = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap();
        let two = rayon::ThreadPoolBuilder::new()
            .num_threads(2)
            .build()
            .unwrap();
        let a = one.install(|| ordered_row_reduce(1000, f, 0.0, |a, b| a + b));
        let b = two.install(|| ordered_row_reduce(1000, f, 0.0, |a, b| a + b));
        assert_eq!(a.to_bits(), b.to_bits());
    }
}
