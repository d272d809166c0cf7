//! HDR → display: exposure from the environment's log-average luminance, the ACES filmic
//! curve and the sRGB transfer function.

use ibl_core::cube::texel_solid_angle;
use ibl_core::{luminance, Cubemap};

/// Mid-grey the log-average luminance is mapped to (Reinhard et al. 2002, "Photographic Tone
/// Reproduction for Digital Images", eq. 2, key a = 0.18).
pub(crate) const KEY: f32 = 0.18;

/// Luminance below which texels count as this floor in the log-average (the δ of Reinhard et
/// al. 2002 eq. 1: keeps black texels from sending the mean to 0).
const LOG_FLOOR: f64 = 1e-4;

/// Solid-angle-weighted log-average luminance of a cube (Reinhard et al. 2002 eq. 1 over the
/// sphere). The geometric mean, not the arithmetic one: a sun of a few texels would otherwise
/// set the exposure and leave the rest of the sky black.
pub(crate) fn log_average_luminance(cube: &Cubemap) -> f32 {
    let n = cube.size;
    let (mut sum, mut weight) = (0.0f64, 0.0f64);
    for face in &cube.faces {
        for j in 0..n {
            for i in 0..n {
                let w = texel_solid_angle(i, j, n);
                let l = luminance(face.rgb(i, j)).max(0.0) as f64;
                sum += w * (l + LOG_FLOOR).ln();
                weight += w;
            }
        }
    }
    ((sum / weight).exp() - LOG_FLOOR).max(LOG_FLOOR) as f32
}

/// The linear scale that maps an environment of log-average luminance `mean` to [`KEY`],
/// times 2^`ev`.
pub fn exposure_scale(mean: f32, ev: f32) -> f32 {
    KEY / mean.max(LOG_FLOOR as f32) * ev.exp2()
}

/// Narkowicz's fit of the ACES filmic curve (K. Narkowicz 2015, "ACES Filmic Tone Mapping
/// Curve"): x(2.51x + 0.03) / (x(2.43x + 0.59) + 0.14), clamped to [0, 1]; 0 → 0, increasing.
pub(crate) fn aces(x: f32) -> f32 {
    let x = x.max(0.0);
    (x * (2.51 * x + 0.03) / (x * (2.43 * x + 0.59) + 0.14)).clamp(0.0, 1.0)
}

/// The sRGB encoding (IEC 61966-2-1) of a linear value in [0, 1].
pub(crate) fn srgb_encode(c: f32) -> f32 {
    let c = c.clamp(0.0, 1.0);
    if c <= 0.003_130_8 {
        12.92 * c
    } else {
        1.055 * c.powf(1.0 / 2.4) - 0.055
    }
}

/// Linear HDR radiance → display value in [0, 1]: exposure, ACES per channel, sRGB.
pub fn display(rgb: [f32; 3], scale: f32) -> [f32; 3] {
    rgb.map(|c| srgb_encode(aces(c * scale)))
}

/// Log-average luminance of the non-black pixels of a flat image (a render on a black
/// background: the background must not set the exposure).
pub fn image_log_average(img: &ibl_core::Image) -> f32 {
    let (mut sum, mut n) = (0.0f64, 0usize);
    for y in 0..img.height {
        for x in 0..img.width {
            let l = luminance(img.rgb(x, y));
            if l > 0.0 && l.is_finite() {
                sum += (l as f64 + LOG_FLOOR).ln();
                n += 1;
            }
        }
    }
    if n == 0 {
        return LOG_FLOOR as f32;
    }
    ((sum / n as f64).exp() - LOG_FLOOR).max(LOG_FLOOR) as f32
}

/// A linear HDR image as display values (exposure `scale`, ACES, sRGB), RGB, for an 8-bit PNG.
pub fn display_image(img: &ibl_core::Image, scale: f32) -> ibl_core::Image {
    let mut out = ibl_core::Image::new(img.width, img.height, 3);
    for y in 0..img.height {
        for x in 0..img.width {
            out.texel_mut(x, y)
                .copy_from_slice(&display(img.rgb(x, y), scale));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tone_curve_maps_zero_to_zero_and_is_monotonic() {
        assert_eq!(aces(0.0), 0.0);
        assert_eq!(display([0.0; 3], 3.0), [0.0; 3]);
        assert_eq!(aces(-1.0), 0.0);
        let mut prev = 0.0;
        for k in 1..=20_000 {
            let x = k as f32 * 1e-3; // up to 20× mid-grey exposure
            let y = srgb_encode(aces(x));
            assert!(y >= prev, "not monotonic at {x}: {y} < {prev}");
            prev = y;
        }
        assert!(prev > 0.99 && prev <= 1.0);
        // Mid-grey 0.18 → 0.0867 / 0.3249 ≈ 0.2669 by hand; large x saturates at 1.
        assert!((aces(0.18) - 0.2669).abs() < 1e-3);
    }

    #[test]
    fn srgb_matches_the_standard_at_known_points() {
        assert_eq!(srgb_encode(0.0), 0.0);
        assert!((srgb_encode(1.0) - 1.0).abs() < 1e-6);
        // 0.5 linear is 0.7354 in sRGB; 0.002 is on the linear segment.
        assert!((srgb_encode(0.5) - 0.735_357).abs() < 1e-5);
        assert!((srgb_encode(0.002) - 0.025_84).abs() < 1e-6);
    }

    #[test]
    fn exposure_maps_a_uniform_environment_to_the_key() {
        for l in [0.01f32, 1.0, 250.0] {
            let cube = Cubemap::constant(8, [l, l, l]);
            let mean = log_average_luminance(&cube);
            assert!((mean - l).abs() <= 1e-4 * l.max(1.0), "{mean} vs {l}");
            assert!((exposure_scale(mean, 0.0) * l - KEY).abs() < 1e-4);
            assert!((exposure_scale(mean, 1.0) * l - 2.0 * KEY).abs() < 2e-4);
        }
        // A sun of one texel barely moves the geometric mean (it would triple the arithmetic one).
        let mut cube = Cubemap::constant(8, [1.0; 3]);
        cube.faces[0].texel_mut(3, 3).copy_from_slice(&[1000.0; 3]);
        assert!(log_average_luminance(&cube) < 1.05);
    }
}
