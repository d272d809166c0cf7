//! Cubes as horizontal crosses (docs/CONVENTIONS.md faces and orientation: nx pz px nz across the middle,
//! py above pz, ny below, each face as stored), and resampling to a common height.

use ibl_core::{Cubemap, Face, Image};

/// (face, column, row) of each face in a 4×3 horizontal cross: the layout
/// `ibl_core::envmap::classify_layout` reads, so a cross written here reads back as the cube.
pub(crate) const HCROSS: [(Face, usize, usize); 6] = [
    (Face::Px, 2, 1),
    (Face::Nx, 0, 1),
    (Face::Py, 1, 0),
    (Face::Ny, 1, 2),
    (Face::Pz, 1, 1),
    (Face::Nz, 3, 1),
];

/// The cube as a 4n×3n RGBA horizontal cross; the six empty cells have alpha 0.
pub(crate) fn horizontal_cross(cube: &Cubemap) -> Image {
    let n = cube.size;
    let mut img = Image::new(4 * n, 3 * n, 4);
    for (face, col, row) in HCROSS {
        for j in 0..n {
            for i in 0..n {
                let t = img.texel_mut(col * n + i, row * n + j);
                t[..3].copy_from_slice(&cube.texel(face, i, j));
                t[3] = 1.0;
            }
        }
    }
    img
}

/// Resamples `img` to `height` rows, keeping its aspect ratio: the box mean of each output
/// pixel's footprint when shrinking, the nearest texel when enlarging (small mip levels keep
/// their texels visible as blocks).
pub(crate) fn fit_height(img: &Image, height: usize) -> Image {
    let width = ((img.width * height) as f64 / img.height as f64)
        .round()
        .max(1.0) as usize;
    let ch = img.channels;
    let mut out = Image::new(width, height, ch);
    // Source span [a, b) of output index k along an axis of `src` texels mapped onto `dst`.
    let span = |k: usize, src: usize, dst: usize| {
        let a = k * src / dst;
        let b = ((k + 1) * src).div_ceil(dst).max(a + 1).min(src);
        (a, b)
    };
    for y in 0..height {
        let (y0, y1) = span(y, img.height, height);
        for x in 0..width {
            let (x0, x1) = span(x, img.width, width);
            let mut acc = [0.0f32; 4];
            for sy in y0..y1 {
                for sx in x0..x1 {
                    for (a, v) in acc.iter_mut().zip(img.texel(sx, sy)) {
                        *a += v;
                    }
                }
            }
            let count = ((y1 - y0) * (x1 - x0)) as f32;
            for (o, a) in out.texel_mut(x, y).iter_mut().zip(acc) {
                *o = a / count;
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use ibl_core::envmap::{classify_layout, Environment};

    /// Face k holds the constant (k + 1, 10(k + 1), 100(k + 1)).
    fn labelled_cube(n: usize) -> Cubemap {
        let mut c = Cubemap::new(n);
        for (k, face) in c.faces.iter_mut().enumerate() {
            let v = (k + 1) as f32;
            for t in face.data.chunks_exact_mut(3) {
                t.copy_from_slice(&[v, 10.0 * v, 100.0 * v]);
            }
        }
        c
    }

    #[test]
    fn each_face_lands_in_its_cell_of_the_cross() {
        let n = 4;
        let img = horizontal_cross(&labelled_cube(n));
        assert_eq!((img.width, img.height, img.channels), (16, 12, 4));
        // docs/CONVENTIONS.md's cross, written out cell by cell (row, column) → face index + 1 (0: empty).
        let expected = [[0, 3, 0, 0], [2, 5, 1, 6], [0, 4, 0, 0]];
        for (row, cells) in expected.iter().enumerate() {
            for (col, &k) in cells.iter().enumerate() {
                for j in 0..n {
                    for i in 0..n {
                        let t = img.texel(col * n + i, row * n + j);
                        let v = k as f32;
                        let want = if k == 0 {
                            [0.0; 4]
                        } else {
                            [v, 10.0 * v, 100.0 * v, 1.0]
                        };
                        assert_eq!(t, want, "cell ({row}, {col}) texel ({i}, {j})");
                    }
                }
            }
        }
    }

    #[test]
    fn the_cross_reads_back_as_the_cube_and_is_continuous_at_seams() {
        // The library's own cross reader (ibl_core::envmap) recovers every face, orientation
        // included: faces hold their direction, so a flipped or turned face would differ.
        let n = 8;
        let cube = Cubemap::from_fn(n, |d| [d.x, d.y, d.z]);
        let cross = horizontal_cross(&cube).to_channels(3);
        match classify_layout(std::path::Path::new("cross.exr"), cross.clone()).unwrap() {
            Environment::Cube(c) => assert_eq!(c, cube),
            Environment::Equirect(_) => panic!("read as an equirect"),
        }
        // Along every seam inside the cross, neighbours are one texel apart on the sphere.
        let dir = |x: usize, y: usize| {
            let t = cross.rgb(x, y);
            unit(t)
        };
        let near = |a: [f32; 3], b: [f32; 3]| {
            let dot: f32 = a.iter().zip(b).map(|(p, q)| p * q).sum();
            dot > (3.0 / n as f32).cos()
        };
        for j in 0..n {
            // nx|pz|px|nz in the middle row.
            for c in 1..4 {
                assert!(near(dir(c * n - 1, n + j), dir(c * n, n + j)));
            }
        }
        for i in 0..n {
            assert!(near(dir(n + i, n - 1), dir(n + i, n)), "py above pz");
            assert!(
                near(dir(n + i, 2 * n - 1), dir(n + i, 2 * n)),
                "ny below pz"
            );
        }
    }

    fn unit(v: [f32; 3]) -> [f32; 3] {
        let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        v.map(|c| c / l)
    }

    #[test]
    fn fit_height_averages_when_shrinking_and_repeats_when_enlarging() {
        let img =
            Image::from_data(4, 2, 1, vec![0.0, 2.0, 4.0, 6.0, 8.0, 10.0, 12.0, 14.0]).unwrap();
        let small = fit_height(&img, 1);
        assert_eq!((small.width, small.height), (2, 1));
        assert_eq!(small.data, vec![5.0, 9.0]);
        let big = fit_height(&img, 4);
        assert_eq!((big.width, big.height), (8, 4));
        assert_eq!(big.texel(0, 0)[0], 0.0);
        assert_eq!(big.texel(1, 1)[0], 0.0);
        assert_eq!(big.texel(7, 3)[0], 14.0);
        assert_eq!(big.texel(2, 2)[0], 10.0);
        // The mean is kept when shrinking by an integer factor.
        let mean = |i: &Image| i.data.iter().sum::<f32>() / i.data.len() as f32;
        assert_eq!(mean(&small), mean(&img));
    }
}
