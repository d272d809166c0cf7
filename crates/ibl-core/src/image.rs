//! Linear float images (1–4 interleaved channels) and the checks every input goes through.

use crate::error::{Error, Result};
use std::path::Path;

/// Largest image we agree to allocate, in texels (refused before allocating).
pub const MAX_TEXELS: u64 = 1 << 28;

/// A linear float image, row 0 at the top, channels interleaved.
#[derive(Clone, Debug, PartialEq)]
pub struct Image {
    /// Columns.
    pub width: usize,
    /// Rows.
    pub height: usize,
    /// Channels per texel (1 to 4).
    pub channels: usize,
    /// Texels row by row, `channels` values each: `width·height·channels` values.
    pub data: Vec<f32>,
}

impl Image {
    /// A zero-filled image. Panics only on a programming error (channels outside 1..=4).
    pub fn new(width: usize, height: usize, channels: usize) -> Self {
        assert!((1..=4).contains(&channels), "channels must be 1..=4");
        Image {
            width,
            height,
            channels,
            data: vec![0.0; width * height * channels],
        }
    }

    /// Wraps existing data, checking its length.
    pub fn from_data(width: usize, height: usize, channels: usize, data: Vec<f32>) -> Result<Self> {
        if !(1..=4).contains(&channels) || data.len() != width * height * channels {
            return Err(Error::param(format!(
                "image data of {} values does not fit {width}x{height}x{channels}",
                data.len()
            )));
        }
        Ok(Image {
            width,
            height,
            channels,
            data,
        })
    }

    /// Refuses sizes that are empty or would not fit in memory, before anything is allocated.
    pub fn check_size(path: &Path, width: u64, height: u64) -> Result<()> {
        if width == 0 || height == 0 {
            return Err(Error::invalid(
                path,
                format!("zero-size image ({width}x{height})"),
            ));
        }
        if width.saturating_mul(height) > MAX_TEXELS {
            return Err(Error::invalid(
                path,
                format!(
                    "image of {width}x{height} texels is larger than the limit of {MAX_TEXELS}"
                ),
            ));
        }
        Ok(())
    }

    /// The channels of texel (x, y), x the column and y the row from the top.
    #[inline]
    pub fn texel(&self, x: usize, y: usize) -> &[f32] {
        let o = (y * self.width + x) * self.channels;
        &self.data[o..o + self.channels]
    }

    /// The channels of texel (x, y), mutable.
    #[inline]
    pub fn texel_mut(&mut self, x: usize, y: usize) -> &mut [f32] {
        let o = (y * self.width + x) * self.channels;
        &mut self.data[o..o + self.channels]
    }

    /// RGB of a texel: grey for one channel, (r, g, 0) for two, alpha dropped for four.
    #[inline]
    pub fn rgb(&self, x: usize, y: usize) -> [f32; 3] {
        let t = self.texel(x, y);
        match self.channels {
            1 => [t[0], t[0], t[0]],
            2 => [t[0], t[1], 0.0],
            _ => [t[0], t[1], t[2]],
        }
    }

    /// The same pixels with `channels` channels (grey broadcast, missing alpha = 1).
    pub fn to_channels(&self, channels: usize) -> Image {
        if channels == self.channels {
            return self.clone();
        }
        let mut out = Image::new(self.width, self.height, channels);
        for (src, dst) in self
            .data
            .chunks_exact(self.channels)
            .zip(out.data.chunks_exact_mut(channels))
        {
            let rgba = match self.channels {
                1 => [src[0], src[0], src[0], 1.0],
                2 => [src[0], src[1], 0.0, 1.0],
                3 => [src[0], src[1], src[2], 1.0],
                _ => [src[0], src[1], src[2], src[3]],
            };
            if channels == 1 {
                dst[0] = crate::luminance([rgba[0], rgba[1], rgba[2]]);
            } else {
                dst.copy_from_slice(&rgba[..channels]);
            }
        }
        out
    }
}

/// What [`check_texels`] found and did.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct TexelReport {
    /// NaN or infinite values set to 0 (only with `sanitize`).
    pub non_finite_zeroed: usize,
    /// Negative values clamped to 0.
    pub negative_clamped: usize,
    /// The most negative value seen (0 when none).
    pub most_negative: f32,
}

impl TexelReport {
    /// One-line warnings for the user, empty when the input was clean.
    pub fn warnings(&self, path: &Path) -> Vec<String> {
        let mut w = Vec::new();
        if self.negative_clamped > 0 {
            w.push(format!(
                "{}: clamped {} negative texel values to 0 (most negative {})",
                path.display(),
                self.negative_clamped,
                self.most_negative
            ));
        }
        if self.non_finite_zeroed > 0 {
            w.push(format!(
                "{}: set {} NaN/Inf texel values to 0 (--sanitize)",
                path.display(),
                self.non_finite_zeroed
            ));
        }
        w
    }
}

/// The HDR input policy of docs/CONVENTIONS.md: NaN/Inf values are an error unless `sanitize` (then 0);
/// negative values (left by lossy codecs) are clamped to 0 and counted.
pub fn check_texels(image: &mut Image, path: &Path, sanitize: bool) -> Result<TexelReport> {
    let mut report = TexelReport::default();
    let non_finite = image.data.iter().filter(|v| !v.is_finite()).count();
    if non_finite > 0 && !sanitize {
        return Err(Error::NonFinite {
            path: path.to_path_buf(),
            count: non_finite,
        });
    }
    for v in &mut image.data {
        if !v.is_finite() {
            *v = 0.0;
            report.non_finite_zeroed += 1;
        } else if *v < 0.0 {
            report.most_negative = report.most_negative.min(*v);
            report.negative_clamped += 1;
            *v = 0.0;
        }
    }
    Ok(report)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn check_texels_refuses_nan_without_sanitize() {
        let mut img = Image::from_data(2, 1, 1, vec![f32::NAN, 1.0]).unwrap();
        let err = check_texels(&mut img, Path::new("a.exr"), false).unwrap_err();
        assert!(err.to_string().contains("1 NaN/Inf"), "{err}");
    }

    #[test]
    fn check_texels_sanitizes_and_clamps() {
        let mut img = Image::from_data(4, 1, 1, vec![f32::INFINITY, -3.0, -0.5, 2.0]).unwrap();
        let r = check_texels(&mut img, Path::new("a.exr"), true).unwrap();
        assert_eq!(img.data, vec![0.0, 0.0, 0.0, 2.0]);
        assert_eq!(r.non_finite_zeroed, 1);
        assert_eq!(r.negative_clamped, 2);
        assert_eq!(r.most_negative, -3.0);
        assert_eq!(r.warnings(Path::new("a.exr")).len(), 2);
    }

    #[test]
    fn size_limits_refuse_before_allocating() {
        assert!(Image::check_size(Path::new("x"), 0, 10).is_err());
        assert!(Image::check_size(Path::new("x"), 1 << 20, 1 << 20).is_err());
        assert!(Image::check_size(Path::new("x"), 1024, 512).is_ok());
    }
}
