//! Tests of the whole reference: the furnace, Lexact and E/π against the brute-force sum,
//! symmetry, thread-count independence, and the orientation checker on turned panoramas.

use crate::brdf::{Engine, ExactDfg};
use crate::lighting::{self, BruteForce, Lighting};
use crate::orientation;
use crate::render::{render, ALL_SPHERES};
use crate::scene::{self, Sphere, HEIGHT, SPHERES, WIDTH};
use glam::DVec3;
use ibl_core::envmap::Environment;
use ibl_core::progress::NoProgress;
use ibl_core::Image;
use ibl_prefilter::tree::TreeBuffers;

/// A sky with a sun, a gradient and a dark floor, as an equirect of `w`×`w/2`.
fn sky(w: usize) -> Image {
    let h = w / 2;
    let mut img = Image::new(w, h, 3);
    let sun = DVec3::new(0.4, 0.7, 0.59).normalize();
    for y in 0..h {
        for x in 0..w {
            let d = ibl_core::equirect::pixel_direction(x, y, w, h)
                .as_dvec3()
                .normalize();
            let s = (d.dot(sun) - 0.97).max(0.0) * 300.0;
            let base = 0.2 + 0.8 * d.y.max(0.0) + 0.1 * (3.0 * d.x).sin().abs();
            img.texel_mut(x, y).copy_from_slice(&[
                (base + s) as f32,
                (0.9 * base + s) as f32,
                (0.7 * base + 0.5 * s) as f32,
            ]);
        }
    }
    img
}

/// The furnace: in a constant environment L every pixel is L·(w_r + w_e). With our own DFG
/// (`exact`) a metallic sphere renders L·(A + B) at its pixel's n·v, the mirror L exactly, a
/// dielectric L·(0.04A + B + 1).
#[test]
fn furnace_renders_the_dfg_exactly() {
    let l = [0.5f32, 2.0, 7.0];
    let lighting = lighting::constant(l);
    let img = render(&lighting, Engine::Exact, &ALL_SPHERES, &NoProgress);
    let tables: Vec<ExactDfg> = (0..6).map(|c| ExactDfg::new(c as f64 / 5.0)).collect();
    let mut worst = 0.0f64;
    for py in 0..HEIGHT {
        for px in 0..WIDTH {
            let got = img.rgb(px, py);
            let Some(h) = scene::hit(px, py) else {
                assert_eq!(got, [0.0; 3], "background at {px},{py}");
                continue;
            };
            let [a, b] = tables[h.sphere.column].ab(h.n_dot_v);
            let want = if h.sphere.metallic {
                a + b
            } else {
                0.04 * a + b + 1.0
            };
            if h.sphere.metallic && h.sphere.roughness == 0.0 {
                // The mirror: A + B = 1 exactly, so the pixel is L.
                for k in 0..3 {
                    assert!((got[k] - l[k]).abs() <= 1e-6 * l[k], "{got:?}");
                }
            }
            for k in 0..3 {
                worst =
                    worst.max(((got[k] as f64 - l[k] as f64 * want) / (l[k] as f64 * want)).abs());
            }
        }
    }
    eprintln!("furnace: worst relative deviation from L·(F0·A + B [+1]) {worst:.2e}");
    assert!(worst < 1e-5, "{worst}");
}

/// The furnace of the engines with multiple-scattering compensation: a white metal in a
/// constant environment renders L (the energy the compensation restores), to f32 rounding.
#[test]
fn furnace_of_compensated_engines_is_white() {
    let lighting = lighting::constant([1.0, 1.0, 1.0]);
    let only_metal: [bool; SPHERES] = std::array::from_fn(|i| i == 1 || i == 5);
    for e in [
        Engine::Three,
        Engine::Babylon,
        Engine::Filament,
        Engine::Bevy,
        Engine::Gltf,
    ] {
        let img = render(&lighting, e, &only_metal, &NoProgress);
        for py in (0..128).step_by(3) {
            for px in (0..WIDTH).step_by(3) {
                if scene::hit(px, py).is_some_and(|h| only_metal[h.sphere.index]) {
                    let v = img.rgb(px, py)[1];
                    assert!((v - 1.0).abs() < 1e-5, "{e:?} at {px},{py}: {v}");
                }
            }
        }
    }
}

/// Lexact against the brute-force sum over every texel of the *source equirect* (the kernel
/// written again in f64, no resampling, no tree), and E/π likewise (the α = 1 kernel is the
/// cosine), at directions between texels.
#[test]
fn lexact_and_irradiance_match_the_brute_force_over_the_source() {
    let env = Environment::Equirect(sky(256));
    let lighting = Lighting::new(&env, &NoProgress);
    let brute = BruteForce::new(&env);
    let dirs = [
        DVec3::new(0.3, 0.8, 0.52),
        DVec3::new(-0.7, 0.1, 0.7),
        DVec3::new(0.05, -0.9, 0.4),
        DVec3::new(0.6, 0.3, -0.74),
        DVec3::new(0.41, 0.68, 0.61), // near the sun
    ];
    let mut buf = TreeBuffers::default();
    let lum = |c: [f64; 3]| 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2];
    for r in [0.2f64, 0.5, 1.0] {
        let mut worst = 0.0f64;
        for d in dirs {
            let d = d.normalize();
            let got = lum(lighting.specular(d, r, &mut buf).map(|v| v as f64));
            let want = lum(brute.radiance(d, r));
            worst = worst.max((got - want).abs() / want);
        }
        eprintln!("Lexact r {r}: worst relative error against the brute force {worst:.2e}");
        assert!(worst < 5e-3, "r {r}: {worst}");
    }
    let mut worst = 0.0f64;
    for d in dirs {
        let d = d.normalize();
        let got = lum(lighting.irradiance(d).map(|v| v as f64));
        let want = lum(brute.radiance(d, 1.0));
        worst = worst.max((got - want).abs() / want);
    }
    eprintln!("E/π: worst relative error against the brute force {worst:.2e}");
    assert!(worst < 5e-3, "{worst}");
    // The estimate the binary reports agrees: small on every sphere.
    let est = lighting.estimate(&brute, 6);
    assert_eq!(est.len(), SPHERES);
    assert!(
        est.iter()
            .all(|e| e.specular_mean_rel < 5e-3 && e.probes > 0),
        "{est:?}"
    );
}

/// An environment symmetric under x → −x renders every sphere symmetric about its vertical
/// axis (pixel columns mirror about the centre, which falls between two pixels).
#[test]
fn a_mirror_symmetric_environment_renders_symmetric_spheres() {
    let mut img = sky(128);
    // Symmetrise the sky under x → −x: in our mapping that is u → 0.5 − u (mod 1) … i.e.
    // φ → π − φ; average each pixel with its mirror.
    let w = img.width;
    let src = img.clone();
    for y in 0..img.height {
        for x in 0..w {
            let xm = (w + w / 2 - 1 - x) % w;
            let (a, b) = (src.rgb(x, y), src.rgb(xm, y));
            img.texel_mut(x, y).copy_from_slice(&[
                0.5 * (a[0] + b[0]),
                0.5 * (a[1] + b[1]),
                0.5 * (a[2] + b[2]),
            ]);
        }
    }
    let lighting = Lighting::new(&Environment::Equirect(img), &NoProgress);
    let some: [bool; SPHERES] = std::array::from_fn(|i| [0, 2, 7, 11].contains(&i));
    let out = render(&lighting, Engine::Gltf, &some, &NoProgress);
    let mut worst = 0.0f32;
    for s in Sphere::all().iter().filter(|s| some[s.index]) {
        let (cx, cy) = s.centre_pixel();
        for dy in -50i64..=50 {
            for dx in 0..50i64 {
                let py = (cy + dy as f64).round() as usize;
                let (pl, pr) = (
                    (cx - 0.5 - dx as f64) as usize,
                    (cx + 0.5 + dx as f64) as usize,
                );
                let (a, b) = (out.rgb(pl, py), out.rgb(pr, py));
                for k in 0..3 {
                    worst = worst.max((a[k] - b[k]).abs() / b[k].max(1e-3));
                }
            }
        }
    }
    eprintln!("mirror symmetry: worst relative difference {worst:.2e}");
    assert!(worst < 2e-3, "{worst}");
}

#[test]
fn the_render_is_independent_of_the_thread_count() {
    let lighting = Lighting::with_irradiance_size(&Environment::Equirect(sky(64)), 8, &NoProgress);
    let some: [bool; SPHERES] = std::array::from_fn(|i| i == 2 || i == 9);
    ibl_testkit::thread_count_independent(&[1, 2, 3], || {
        render(&lighting, Engine::Filament, &some, &NoProgress).data
    });
}

/// The checker reads our own render of the panorama as correct, and names what a turned or
/// mirrored panorama does (the transforms an engine's orientation bugs produce).
#[test]
fn the_orientation_checker_names_flips_and_turns() {
    let pano = orientation::panorama(256);
    let (w, h) = (pano.width, pano.height);
    let remap = |f: &dyn Fn(usize, usize) -> (usize, usize)| {
        let mut out = Image::new(w, h, 3);
        for y in 0..h {
            for x in 0..w {
                let (sx, sy) = f(x, y);
                out.texel_mut(x, y).copy_from_slice(&pano.rgb(sx, sy));
            }
        }
        out
    };
    let mirror_only: [bool; SPHERES] = std::array::from_fn(|i| i == 0);
    let verdict = |img: Image| {
        // Only the mirror is drawn: no irradiance is read.
        let lighting = Lighting::with_irradiance_size(&Environment::Equirect(img), 2, &NoProgress);
        let r = render(&lighting, Engine::Exact, &mirror_only, &NoProgress);
        orientation::check(&r).unwrap().verdict
    };
    assert_eq!(verdict(pano.clone()), "correct");
    // The image flipped left-right: u → 1 − u, i.e. φ → −φ: z → −z.
    assert_eq!(
        verdict(remap(&|x, y| (w - 1 - x, y))),
        "mirrored: z (front-back mirror) flipped"
    );
    // Upside down: v → 1 − v: y → −y.
    assert_eq!(
        verdict(remap(&|x, y| (x, h - 1 - y))),
        "mirrored: y flipped (upside down)"
    );
    // Turned by a quarter: the image shifted by w/4 (what shows at φ came from φ − 90°).
    let v = verdict(remap(&|x, y| ((x + w - w / 4) % w, y)));
    assert!(v.starts_with("turned 90° about"), "{v}");
    // A black render is unrecognised, not "correct".
    let black = Image::new(WIDTH, HEIGHT, 3);
    assert!(orientation::check(&black)
        .unwrap()
        .verdict
        .starts_with("unrecognised"));
}

/// All engines at once give exactly what each engine's own render gives.
#[test]
fn render_engines_matches_one_engine_at_a_time() {
    let lighting = Lighting::with_irradiance_size(&Environment::Equirect(sky(64)), 8, &NoProgress);
    let some: [bool; SPHERES] = std::array::from_fn(|i| i == 3 || i == 6 || i == 10);
    let all = crate::render::render_engines(&lighting, &Engine::ALL, &some, 1, &NoProgress);
    for (k, e) in Engine::ALL.iter().enumerate() {
        assert_eq!(all[k], render(&lighting, *e, &some, &NoProgress), "{e:?}");
    }
    // And the engines differ (their BRDF terms are not all the same).
    assert_ne!(all[0], all[6]);
}
