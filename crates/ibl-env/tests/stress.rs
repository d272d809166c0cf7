//! Numerical stress suite of the foundation bakes: suns of 1e5 and 1e9 in black skies,
//! all-black and all-constant environments, 1×1 and non-power-of-two sizes, rotation.
//! Asserts finite outputs, furnace (constant stays constant) and energy conservation.

use ibl_core::cube::{solid_angle_table, Face};
use ibl_core::envmap::Environment;
use ibl_core::equirect::{row_solid_angle, Filter};
use ibl_core::progress::NoProgress;
use ibl_core::{Cubemap, Image};
use ibl_env::irradiance;

fn equirect_with_sun(w: usize, value: f32, at: (usize, usize)) -> Image {
    let mut img = Image::new(w, w / 2, 3);
    img.texel_mut(at.0, at.1)
        .copy_from_slice(&[value, value, value]);
    img
}

fn source_energy(img: &Image) -> f64 {
    let mut e = 0.0;
    for j in 0..img.height {
        let sa = row_solid_angle(j, img.width, img.height);
        for i in 0..img.width {
            e += img.rgb(i, j)[0] as f64 * sa;
        }
    }
    e
}

fn cube_energy(c: &Cubemap) -> f64 {
    let sa = solid_angle_table(c.size);
    c.faces
        .iter()
        .flat_map(|f| f.data.chunks_exact(3).zip(&sa))
        .map(|(t, s)| t[0] as f64 * *s as f64)
        .sum()
}

fn all_finite(c: &Cubemap) -> bool {
    c.faces.iter().all(|f| f.data.iter().all(|v| v.is_finite()))
}

#[test]
fn single_texel_suns_keep_their_energy_at_every_size() {
    for value in [1e5f32, 1e9] {
        // Suns at the equator, near a pole, on the u seam, on a face corner direction.
        for at in [(300, 128), (17, 1), (0, 100), (64, 60)] {
            let src = equirect_with_sun(512, value, at);
            let e = source_energy(&src);
            for n in [1usize, 3, 7, 16, 100] {
                let cube =
                    Environment::Equirect(src.clone()).to_cube(n, Filter::Area, 0.0, &NoProgress);
                assert!(all_finite(&cube));
                let rel = cube_energy(&cube) / e - 1.0;
                assert!(
                    rel.abs() < 1e-5,
                    "sun {value} at {at:?}, n={n}: energy off by {rel:e}"
                );
            }
            // The SH projection of a sun is a point evaluation: finite and energy-exact in L00.
            let rad = irradiance::project(&Environment::Equirect(src.clone()), 3, 0.0);
            let l00 = rad[0][0] / 0.282_094_791_773_878_1;
            assert!((l00 / e - 1.0).abs() < 1e-5);
            assert!(rad.iter().flatten().all(|v| v.is_finite()));
        }
    }
}

#[test]
fn black_and_constant_environments() {
    for w in [2usize, 6, 64] {
        let black = Image::new(w, w / 2, 3);
        let cube = Environment::Equirect(black.clone()).to_cube(5, Filter::Area, 33.0, &NoProgress);
        assert!(cube.faces.iter().all(|f| f.data.iter().all(|v| *v == 0.0)));
        let rad = irradiance::project(&Environment::Equirect(black), 4, 0.0);
        assert!(rad.iter().flatten().all(|v| *v == 0.0));

        let mut constant = Image::new(w, w / 2, 3);
        constant.data.iter_mut().for_each(|v| *v = 3.0);
        for n in [1usize, 2, 9] {
            let cube =
                Environment::Equirect(constant.clone()).to_cube(n, Filter::Area, 17.0, &NoProgress);
            let worst = cube
                .faces
                .iter()
                .flat_map(|f| f.data.iter())
                .map(|v| (v - 3.0).abs())
                .fold(0.0f32, f32::max);
            assert!(worst < 1e-5, "w={w} n={n}: {worst}");
            let exact =
                irradiance::convolve_cosine_exact(&Environment::Cube(cube), 2, 0, 0.0, &NoProgress);
            assert!(all_finite(&exact));
            // E/π of a constant radiance L is L: every texel reads 3 (white furnace).
            let worst_e = exact
                .faces
                .iter()
                .flat_map(|f| f.data.iter())
                .map(|v| (v - 3.0).abs())
                .fold(0.0f32, f32::max);
            assert!(worst_e < 1e-5, "w={w} n={n}: E/π off by {worst_e}");
        }
    }
}

#[test]
fn irradiance_of_a_1e9_sun_is_finite_and_nonnegative_after_clamping() {
    let src = equirect_with_sun(256, 1e9, (10, 20));
    let rad = irradiance::project(&Environment::Equirect(src), 3, 0.0);
    let irr = irradiance::irradiance_coefficients(&rad, 3, true);
    let c: Vec<[f32; 3]> = irr.iter().map(|v| v.map(|x| x as f32)).collect();
    let (cube, _) = irradiance::cube_from_sh(&c, 7, &NoProgress);
    assert!(cube
        .faces
        .iter()
        .all(|f| f.data.iter().all(|v| v.is_finite() && *v >= 0.0)));
}

#[test]
fn one_by_one_cube_input_round_trips() {
    let cube = Cubemap::constant(1, [0.5, 1.0, 2.0]);
    let env = Environment::Cube(cube.clone());
    let up = env.to_cube(3, Filter::Area, 0.0, &NoProgress);
    for face in Face::ALL {
        assert_eq!(up.texel(face, 1, 1), [0.5, 1.0, 2.0]);
    }
    let rad = irradiance::project(&env, 2, 0.0);
    assert!((rad[0][2] - 2.0 * (4.0 * std::f64::consts::PI).sqrt()).abs() < 1e-4);
}
