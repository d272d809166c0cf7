//! BC6H unsigned-float blocks: encoded by the ISPC texture compressor (the `intel_tex_2`
//! crate: Intel's BC6H encoder, the one most engine pipelines use, with prebuilt kernels, so
//! no ISPC toolchain is needed), decoded by `bcdec_rs` (a port of bcdec). An image whose sides
//! are not multiples of 4, down to 1×1, is padded to whole blocks by repeating its last row and
//! column, as the block format requires (the padding texels are never sampled).

use super::format::Bc6hQuality;
use crate::image::Image;

/// Encodes an RGB float image as BC6H_UF16 blocks, rows of blocks top first. Values are
/// clamped to [0, 65504] (the half-float range BC6H_UF16 stores).
pub fn encode(img: &Image, quality: Bc6hQuality) -> Vec<u8> {
    let (w, h) = (img.width.div_ceil(4) * 4, img.height.div_ceil(4) * 4);
    let mut rgba = Vec::with_capacity(w * h * 8);
    for y in 0..h {
        for x in 0..w {
            let px = img.texel(x.min(img.width - 1), y.min(img.height - 1));
            for v in [px[0], px[1], px[2], 1.0] {
                rgba.extend(super::f16_saturating(v.max(0.0)).to_le_bytes());
            }
        }
    }
    let surface = intel_tex_2::RgbaSurface {
        data: &rgba,
        width: w as u32,
        height: h as u32,
        stride: (w * 8) as u32,
    };
    let settings = match quality {
        Bc6hQuality::Fast => intel_tex_2::bc6h::fast_settings(),
        Bc6hQuality::Basic => intel_tex_2::bc6h::basic_settings(),
        Bc6hQuality::Slow => intel_tex_2::bc6h::slow_settings(),
    };
    intel_tex_2::bc6h::compress_blocks(&settings, &surface)
}

/// Decodes BC6H_UF16 blocks into `img` (its size says how many blocks `bytes` holds).
pub fn decode(bytes: &[u8], img: &mut Image) {
    let bw = img.width.div_ceil(4);
    let mut block = [0u16; 48];
    for (k, b) in bytes.chunks_exact(16).enumerate() {
        let (bx, by) = (k % bw, k / bw);
        bcdec_rs::bc6h_half(b, &mut block, 12, false);
        for j in 0..4 {
            for i in 0..4 {
                let (x, y) = (4 * bx + i, 4 * by + j);
                if x < img.width && y < img.height {
                    let t = img.texel_mut(x, y);
                    for c in 0..3 {
                        t[c] = half::f16::from_bits(block[12 * j + 3 * i + c]).to_f32();
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::texture::relative_errors;

    fn gradient(w: usize, h: usize) -> Image {
        let mut img = Image::new(w, h, 3);
        for y in 0..h {
            for x in 0..w {
                let t = img.texel_mut(x, y);
                t[0] = 0.1 + x as f32 * 0.37;
                t[1] = 2.0 + (y as f32 * 0.21).sin();
                t[2] = 0.01 * (1 + x * y) as f32;
            }
        }
        img
    }

    #[test]
    fn encodes_whole_blocks_and_decodes_close() {
        for (w, h) in [(16, 16), (1, 1), (2, 2), (6, 10)] {
            let img = gradient(w, h);
            let b = encode(&img, Bc6hQuality::Basic);
            assert_eq!(b.len(), w.div_ceil(4) * h.div_ceil(4) * 16);
            let mut back = Image::new(w, h, 3);
            decode(&b, &mut back);
            let (mean, _) = relative_errors(&[img], &[back]);
            assert!(mean < 0.03, "{w}x{h}: {mean}");
        }
    }

    #[test]
    fn constant_blocks_are_nearly_exact_and_encoding_is_deterministic() {
        let mut img = Image::new(8, 8, 3);
        img.data
            .chunks_exact_mut(3)
            .for_each(|t| t.copy_from_slice(&[1.0, 0.5, 0.25]));
        let a = encode(&img, Bc6hQuality::Fast);
        assert_eq!(a, encode(&img, Bc6hQuality::Fast));
        let mut back = Image::new(8, 8, 3);
        decode(&a, &mut back);
        for t in back.data.chunks_exact(3) {
            assert!(
                (t[0] - 1.0).abs() < 2e-3 && (t[1] - 0.5).abs() < 2e-3,
                "{t:?}"
            );
        }
    }
}
