//! The one texel traversal: parallel maps over cube faces and image rows with per-thread
//! state, and ordered reductions whose result does not depend on the thread count.
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

/// Builds `count` n×n cubemaps tile by tile, for kernels that share work across a tile (one
/// hierarchical cut for its texels, several roughness values per cut): `kernel(state, face,
/// i0, j0, w, h, out)` fills `out` (`count` × h × w texels, output-major then row-major) for the
/// w×h tile whose first texel is (i0, j0). Tiles are t×t (clipped at the face edge); one
/// parallel job per row of tiles, so a tile's work is done once whatever the thread count, and
/// every texel is a function of its tile alone (the same bits for any thread count).
pub fn map_cube_tiles_with<S, I, K>(
    n: usize,
    t: usize,
    count: usize,
    progress: &dyn Progress,
    init: I,
    kernel: K,
) -> Vec<Cubemap>
where
    I: Fn() -> S + Sync,
    K: Fn(&mut S, Face, usize, usize, usize, usize, &mut [Rgb]) + Sync,
{
    let t = t.clamp(1, n.max(1));
    let tiles = n.div_ceil(t);
    progress.start("texels", (count * 6 * n * n) as u64);
    let jobs: Vec<(Face, usize)> = Face::ALL
        .iter()
        .flat_map(|&f| (0..tiles).map(move |ty| (f, ty)))
        .collect();
    // Each job returns its rows of every output: count × h × n texels.
    let rows: Vec<Vec<Rgb>> = jobs
        .par_iter()
        .map_init(
            || (init(), Vec::new()),
            |(state, buf), &(face, ty)| {
                let (j0, h) = (ty * t, t.min(n - ty * t));
                let mut rows = vec![[0.0f32; 3]; count * h * n];
                for tx in 0..tiles {
                    let (i0, w) = (tx * t, t.min(n - tx * t));
                    buf.clear();
                    buf.resize(count * w * h, [0.0f32; 3]);
                    kernel(state, face, i0, j0, w, h, buf);
                    for c in 0..count {
                        for jj in 0..h {
                            let src = &buf[(c * h + jj) * w..(c * h + jj + 1) * w];
                            let at = (c * h + jj) * n + i0;
                            rows[at..at + w].copy_from_slice(src);
                        }
                    }
                    progress.inc((count * w * h) as u64);
                }
                rows
            },
        )
        .collect();
    let mut cubes: Vec<Cubemap> = (0..count).map(|_| Cubemap::new(n)).collect();
    for (&(face, ty), rows) in jobs.iter().zip(&rows) {
        let (j0, h) = (ty * t, t.min(n - ty * t));
        for (c, cube) in cubes.iter_mut().enumerate() {
            let data = &mut cube.faces[face as usize].data;
            for jj in 0..h {
                let src = &rows[(c * h + jj) * n..(c * h + jj + 1) * n];
                let dst = &mut data[(j0 + jj) * n * 3..(j0 + jj + 1) * n * 3];
                for (d, s) in dst.chunks_exact_mut(3).zip(src) {
                    d.copy_from_slice(s);
                }
            }
        }
    }
    progress.finish();
    cubes
}

/// Fills an image's rows in parallel: `data` is split into rows of `row_len` floats and
/// `kernel(state, j, row)` writes row j and returns what it measured there. The results come
/// back **in row order** (fold them for a thread-count-independent total). `init` makes
/// per-thread scratch state; `label` and `texels_per_row` drive the progress sink.
pub fn map_image_rows_with<S, T, I, K>(
    data: &mut [f32],
    row_len: usize,
    texels_per_row: usize,
    label: &str,
    progress: &dyn Progress,
    init: I,
    kernel: K,
) -> Vec<T>
where
    T: Send,
    I: Fn() -> S + Sync,
    K: Fn(&mut S, usize, &mut [f32]) -> T + Sync,
{
    let rows = data.len() / row_len.max(1);
    progress.start(label, (rows * texels_per_row) as u64);
    let out = data
        .par_chunks_mut(row_len.max(1))
        .enumerate()
        .map_init(&init, |state, (j, row)| {
            let t = kernel(state, j, row);
            progress.inc(texels_per_row as u64);
            t
        })
        .collect();
    progress.finish();
    out
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
    fn tiles_cover_every_texel_once_with_partial_tiles_at_the_edges() {
        // 7×7 faces in 3×3 tiles (the last row and column of tiles partial), two outputs.
        let cubes = map_cube_tiles_with(
            7,
            3,
            2,
            &NoProgress,
            || 0usize,
            |calls, face, i0, j0, w, h, out| {
                *calls += 1;
                assert!(w <= 3 && h <= 3 && i0 + w <= 7 && j0 + h <= 7);
                for c in 0..2 {
                    for jj in 0..h {
                        for ii in 0..w {
                            let v =
                                (c * 1000 + face as usize * 100 + (j0 + jj) * 10 + i0 + ii) as f32;
                            out[(c * h + jj) * w + ii] = [v, -v, 1.0];
                        }
                    }
                }
            },
        );
        assert_eq!(cubes.len(), 2);
        for (c, cube) in cubes.iter().enumerate() {
            for face in Face::ALL {
                for j in 0..7 {
                    for i in 0..7 {
                        let v = (c * 1000 + face as usize * 100 + j * 10 + i) as f32;
                        assert_eq!(cube.texel(face, i, j), [v, -v, 1.0]);
                    }
                }
            }
        }
    }

    #[test]
    fn image_rows_are_filled_and_reported_in_order() {
        let (w, h, ch) = (7, 33, 2);
        let mut data = vec![0.0f32; w * h * ch];
        let sums = map_image_rows_with(
            &mut data,
            w * ch,
            w,
            "rows",
            &NoProgress,
            || 0usize,
            |calls, j, row| {
                *calls += 1;
                for (i, px) in row.chunks_exact_mut(ch).enumerate() {
                    px.copy_from_slice(&[j as f32, i as f32]);
                }
                j
            },
        );
        assert_eq!(sums, (0..h).collect::<Vec<_>>());
        for j in 0..h {
            for i in 0..w {
                assert_eq!(&data[(j * w + i) * ch..][..ch], &[j as f32, i as f32]);
            }
        }
    }

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
        ibl_testkit::thread_count_independent(&[1, 2, 3], || {
            ordered_row_reduce(1000, f, 0.0, |a, b| a + b)
        });
    }
}
