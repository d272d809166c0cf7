//! BC6H unsigned-float blocks: encoded by the ISPC texture compressor (the `intel_tex_2`
//! crate: Intel's BC6H encoder, the one most engine pipelines use, with prebuilt kernels, so
//! no ISPC toolchain is needed), decoded by `bcdec_rs` (a port of bcdec). An image whose sides
//! are not multiples of 4, down to 1×1, is padded to whole blocks by repeating its last row and
//! column, as the block format requires (the padding texels are never sampled).
//!
//! Images of at most [`SEARCH_MAX`]² texels (a chain's small levels: four blocks a face or
//! fewer) are encoded by [`encode_searched`] whatever the quality asked: the ISPC kernel's
//! exhaustive profile (every mode, all 32 partitions of the two-region modes, endpoints refined
//! [`SEARCH_REFINE`] times) and then, block by block, a search for the block whose decoded
//! texels minimise the error the sidecar reports ([`super::texture::ERROR_METRIC`]) rather than
//! the kernel's own squared half-float error: targets moved against the decoded error
//! (error feedback) and re-encoded, each candidate decoded and scored, the best kept. The
//! candidates include the plain exhaustive encoding, so the result is never worse than it.

// Index loops over texels, channels and modes read closer to the block format's tables.
#![allow(clippy::needless_range_loop)]

use super::format::Bc6hQuality;
use crate::image::Image;

/// Encodes an RGB float image as BC6H_UF16 blocks, rows of blocks top first. Values are
/// clamped to [0, 65504] (the half-float range BC6H_UF16 stores).
pub fn encode(img: &Image, quality: Bc6hQuality) -> Vec<u8> {
    if img.width <= SEARCH_MAX && img.height <= SEARCH_MAX {
        return encode_searched(img);
    }
    let settings = match quality {
        Bc6hQuality::Fast => intel_tex_2::bc6h::fast_settings(),
        Bc6hQuality::Basic => intel_tex_2::bc6h::basic_settings(),
        Bc6hQuality::Slow => intel_tex_2::bc6h::slow_settings(),
    };
    encode_with(img, &settings)
}

/// Largest side of an image encoded by [`encode_searched`] (two blocks a side).
pub const SEARCH_MAX: usize = 8;

/// What the sidecar says of a level encoded by [`encode_searched`].
pub const SEARCH_NAME: &str = "exhaustive: every mode and all 32 partitions (ISPC kernel, endpoints refined 8 times, 24 error-feedback rounds), every one-region mode re-searched in the sidecar metric; the best block by that metric, decoded by bcdec";

/// Endpoint refinement passes of the exhaustive profile (the kernel's slowest profile does 2).
pub const SEARCH_REFINE: u32 = 8;

/// Error-feedback rounds of [`encode_searched`].
const FEEDBACK_ROUNDS: usize = 24;

/// The ISPC kernel at its exhaustive setting: every mode (`slow_mode`), every one of the 32
/// two-region partitions evaluated fully (`fast_skip_threshold` 32), endpoints refined
/// [`SEARCH_REFINE`] times.
fn exhaustive_settings() -> intel_tex_2::bc6h::EncodeSettings {
    intel_tex_2::bc6h::EncodeSettings {
        slow_mode: true,
        fast_mode: false,
        fast_skip_threshold: 32,
        refine_iterations_1p: SEARCH_REFINE,
        refine_iterations_2p: SEARCH_REFINE,
    }
}

/// Encodes a small image block by block for the least sidecar error (see the module doc).
/// Deterministic: a fixed sequence of candidates, ties kept by the earlier.
pub fn encode_searched(img: &Image) -> Vec<u8> {
    let settings = exhaustive_settings();
    let mut best = encode_with(img, &settings);
    let eps = metric_eps(img);
    let score = |bytes: &[u8]| block_errors(img, bytes, eps);
    let mut best_err = score(&best);
    // Error feedback: the target moves by what the kept blocks still miss, so the kernel's
    // least-squares fit in half-float space lands nearer the texels in the sidecar's metric.
    let mut target = img.clone();
    for round in 0..FEEDBACK_ROUNDS {
        let mut decoded = Image::new(img.width, img.height, 3);
        decode(&best, &mut decoded);
        // Alternating full and half steps keeps the iteration from oscillating.
        let step = if round % 2 == 0 { 1.0 } else { 0.5 };
        for ((t, o), d) in target
            .data
            .chunks_exact_mut(img.channels)
            .zip(img.data.chunks_exact(img.channels))
            .zip(decoded.data.chunks_exact(3))
        {
            for c in 0..3 {
                t[c] = (t[c] + step * (o[c] - d[c])).max(0.0);
            }
        }
        let cand = encode_with(&target, &settings);
        let cand_err = score(&cand);
        for (k, (e, b)) in cand_err.iter().zip(cand.chunks_exact(16)).enumerate() {
            if *e < best_err[k] {
                best_err[k] = *e;
                best[16 * k..16 * k + 16].copy_from_slice(b);
            }
        }
    }
    // Every one-region mode searched directly in the sidecar's metric; kept where it beats
    // the kernel's block as the independent decoder (`bcdec`) decodes both.
    for k in 0..best_err.len() {
        if let Some((_, block)) = search_one_region(&block_texels(img, k, eps)) {
            let e = block_errors_of(img, k, &block, eps);
            if e < best_err[k] {
                best_err[k] = e;
                best[16 * k..16 * k + 16].copy_from_slice(&block);
            }
        }
    }
    best
}

/// The one-region BC6H_UF16 modes (11–14 of the D3D11 BC6H table: 16 index values, one
/// pair of endpoints): mode bits, endpoint precision, and the bits of the second endpoint
/// (stored raw in mode 11, as a signed delta from the first in 12–14). The block layout is
/// the one `bcdec` reads (`bcdec_rs` `bc6h_half`, the modes `0b00011` … `0b01111`), and the
/// D3D11 functional spec's (Microsoft, "BC6H Format", table of modes 11–14).
const ONE_REGION_MODES: [(u32, u32, u32); 4] = [
    (0b00011, 10, 10),
    (0b00111, 11, 9),
    (0b01011, 12, 8),
    (0b01111, 16, 4),
];

/// The 4-bit index weights of BC6H (D3D11 spec; `bcdec` `a_weight4`), symmetric:
/// `W4[15 - i] = 64 - W4[i]`.
const W4: [i32; 16] = [0, 4, 9, 13, 17, 21, 26, 30, 34, 38, 43, 47, 51, 55, 60, 64];

/// BC6H unsigned unquantization of a `bits`-bit endpoint to 16 bits (D3D11 spec
/// `unquantize`; the same in `bcdec`).
fn unquantize(q: i32, bits: u32) -> i32 {
    if bits >= 15 {
        q
    } else if q == 0 {
        0
    } else if q == (1 << bits) - 1 {
        0xFFFF
    } else {
        ((q << 16) + 0x8000) >> bits
    }
}

/// The decoded value of weight `w` between unquantized endpoints `a` and `b`: the
/// interpolation, the unsigned finish (× 31/64) to half-float bits, as f32.
fn palette_value(a: i32, b: i32, w: i32) -> f32 {
    let v = (a * (64 - w) + b * w + 32) >> 6;
    half::f16::from_bits(((v * 31) >> 6) as u16).to_f32()
}

/// One block's texels (up to 16; padding texels repeat the edge) with their metric weights
/// 1 / max(m, eps) (0 for padding: never sampled, never scored).
struct BlockTexels {
    v: [[f32; 3]; 16],
    weight: [f64; 16],
}

/// A one-region candidate: mode index into [`ONE_REGION_MODES`], endpoints per channel.
#[derive(Clone, Copy)]
struct OneRegion {
    mode: usize,
    e: [[i32; 2]; 3],
}

impl OneRegion {
    /// Whether the second endpoints fit the mode's delta bits (mode 11 stores them raw).
    fn valid(&self) -> bool {
        let (_, p, d) = ONE_REGION_MODES[self.mode];
        self.e.iter().all(|&[a, b]| {
            let top = (1 << p) - 1;
            (0..=top).contains(&a)
                && (0..=top).contains(&b)
                && (p == d || (-(1 << (d - 1))..(1 << (d - 1))).contains(&(b - a)))
        })
    }

    /// The 16 decoded colours of the block's palette.
    fn palette(&self) -> [[f32; 3]; 16] {
        let p = ONE_REGION_MODES[self.mode].1;
        let mut pal = [[0.0; 3]; 16];
        for c in 0..3 {
            let (a, b) = (unquantize(self.e[c][0], p), unquantize(self.e[c][1], p));
            for (i, w) in W4.iter().enumerate() {
                pal[i][c] = palette_value(a, b, *w);
            }
        }
        pal
    }

    /// The least weighted error over the texels and each texel's best index.
    fn fit(&self, t: &BlockTexels) -> (f64, [u8; 16]) {
        let pal = self.palette();
        let mut idx = [0u8; 16];
        let mut total = 0.0;
        for k in 0..16 {
            let (mut best, mut bi) = (f64::INFINITY, 0);
            for (i, q) in pal.iter().enumerate() {
                let e: f64 = (0..3).map(|c| (q[c] - t.v[k][c]).abs() as f64).sum();
                if e < best {
                    (best, bi) = (e, i);
                }
            }
            idx[k] = bi as u8;
            total += best * t.weight[k];
        }
        (total, idx)
    }

    /// Packs the block (the anchor texel's index must have its top bit clear: the endpoints
    /// are swapped and the indices mirrored when not, which decodes the same colours).
    fn pack(mut self, mut idx: [u8; 16]) -> Option<[u8; 16]> {
        if idx[0] >= 8 {
            for e in &mut self.e {
                e.swap(0, 1);
            }
            idx.iter_mut().for_each(|i| *i = 15 - *i);
        }
        if !self.valid() {
            return None;
        }
        let (m, p, d) = ONE_REGION_MODES[self.mode];
        let mut bits = 0u128;
        let mut at = 0;
        let mut put = |v: u32, n: u32| {
            bits |= ((v & ((1u64 << n) - 1) as u32) as u128) << at;
            at += n;
        };
        put(m, 5);
        for c in 0..3 {
            put(self.e[c][0] as u32, 10);
        }
        for c in 0..3 {
            let [a, b] = self.e[c];
            // Mode 11 stores the second endpoint itself, the others its difference.
            let x = if p == d { b } else { b - a };
            put(x as u32 & ((1 << d) - 1), d);
            // The first endpoint's bits above 10, highest first (mode 12 has one).
            for bit in (10..p).rev() {
                put((a as u32 >> bit) & 1, 1);
            }
        }
        put(idx[0] as u32, 3);
        for &i in &idx[1..] {
            put(i as u32, 4);
        }
        debug_assert_eq!(at, 128);
        Some(bits.to_le_bytes())
    }
}

/// The quantized endpoint nearest a 16-bit unquantized target at `p` bits.
fn quantize(unq: f64, p: u32) -> i32 {
    let top = (1i32 << p) - 1;
    ((unq * (1u64 << p) as f64 / 65536.0 - 0.5).round() as i32).clamp(0, top)
}

/// Searches every one-region mode for the block: endpoints started at each channel's extremes
/// and refined by coordinate descent (steps from an eighth of the range down to 1, each of the
/// six endpoints moved while the error falls), indices chosen per texel exactly. Returns the
/// best packed block and its error.
fn search_one_region(t: &BlockTexels) -> Option<(f64, [u8; 16])> {
    let mut best: Option<(f64, [u8; 16])> = None;
    // Each channel's extremes, in the 16-bit space endpoints unquantize to (half bits × 64/31).
    let unq = |v: f32| half::f16::from_f32(v.max(0.0)).to_bits() as f64 * 64.0 / 31.0;
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [0.0f64; 3];
    for k in (0..16).filter(|&k| t.weight[k] > 0.0) {
        for c in 0..3 {
            lo[c] = lo[c].min(unq(t.v[k][c]));
            hi[c] = hi[c].max(unq(t.v[k][c]));
        }
    }
    for mode in 0..ONE_REGION_MODES.len() {
        let p = ONE_REGION_MODES[mode].1;
        let mut cand = OneRegion {
            mode,
            e: std::array::from_fn(|c| [quantize(lo[c], p), quantize(hi[c], p)]),
        };
        if !cand.valid() {
            // A delta mode whose range is too wide: pull the second endpoint in.
            let d = ONE_REGION_MODES[mode].2;
            for e in &mut cand.e {
                e[1] = e[1].min(e[0] + (1 << (d - 1)) - 1);
            }
        }
        let mut err = cand.fit(t).0;
        let span = cand
            .e
            .iter()
            .map(|e| (e[1] - e[0]).abs())
            .max()
            .unwrap_or(0);
        let mut step = (span / 8).max(1);
        loop {
            let mut improved = false;
            for c in 0..3 {
                for end in 0..2 {
                    for dir in [-1, 1] {
                        loop {
                            let mut next = cand;
                            next.e[c][end] += dir * step;
                            if !next.valid() {
                                break;
                            }
                            let e = next.fit(t).0;
                            if e < err {
                                (cand, err, improved) = (next, e, true);
                            } else {
                                break;
                            }
                        }
                    }
                }
            }
            if !improved {
                if step == 1 {
                    break;
                }
                step = (step / 2).max(1);
            }
        }
        let (e, idx) = cand.fit(t);
        if let Some(block) = cand.pack(idx) {
            if best.as_ref().is_none_or(|b| e < b.0) {
                best = Some((e, block));
            }
        }
    }
    best
}

/// The texels of block `k` of `img` and their metric weights.
fn block_texels(img: &Image, k: usize, eps: f64) -> BlockTexels {
    let bw = img.width.div_ceil(4);
    let (bx, by) = (k % bw, k / bw);
    let mut t = BlockTexels {
        v: [[0.0; 3]; 16],
        weight: [0.0; 16],
    };
    for j in 0..4 {
        for i in 0..4 {
            let (x, y) = (4 * bx + i, 4 * by + j);
            let px = img.texel(x.min(img.width - 1), y.min(img.height - 1));
            let v = [px[0].max(0.0), px[1].max(0.0), px[2].max(0.0)];
            t.v[4 * j + i] = v;
            if x < img.width && y < img.height {
                t.weight[4 * j + i] = 1.0 / (v[0].max(v[1]).max(v[2]) as f64).max(eps);
            }
        }
    }
    t
}

/// The sidecar metric's floor for `img`: 1e-3 × its mean largest channel.
fn metric_eps(img: &Image) -> f64 {
    let m: f64 = img
        .data
        .chunks_exact(img.channels)
        .map(|p| p[0].max(p[1]).max(p[2]).max(0.0) as f64)
        .sum();
    (1e-3 * m / (img.width * img.height).max(1) as f64).max(f64::MIN_POSITIVE)
}

/// Each block's summed error in the sidecar metric (|decoded − float| / max(m, eps) over its
/// texels and channels), the blocks decoded from `bytes`.
fn block_errors(img: &Image, bytes: &[u8], eps: f64) -> Vec<f64> {
    bytes
        .chunks_exact(16)
        .enumerate()
        .map(|(k, b)| block_errors_of(img, k, b, eps))
        .collect()
}

/// Block `k`'s error in the sidecar metric, `b` its 16 bytes decoded by `bcdec`.
fn block_errors_of(img: &Image, k: usize, b: &[u8], eps: f64) -> f64 {
    let bw = img.width.div_ceil(4);
    let mut block = [0u16; 48];
    {
        {
            let (bx, by) = (k % bw, k / bw);
            bcdec_rs::bc6h_half(b, &mut block, 12, false);
            let mut sum = 0.0;
            for j in 0..4 {
                for i in 0..4 {
                    let (x, y) = (4 * bx + i, 4 * by + j);
                    if x < img.width && y < img.height {
                        let t = img.texel(x, y);
                        let d = (t[0].max(t[1]).max(t[2]).max(0.0) as f64).max(eps);
                        for c in 0..3 {
                            let v = half::f16::from_bits(block[12 * j + 3 * i + c]).to_f32();
                            sum += (v as f64 - t[c] as f64).abs() / d;
                        }
                    }
                }
            }
            sum
        }
    }
}

/// Encodes with explicit kernel settings.
fn encode_with(img: &Image, settings: &intel_tex_2::bc6h::EncodeSettings) -> Vec<u8> {
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
    intel_tex_2::bc6h::compress_blocks(settings, &surface)
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

    /// A small xorshift, so the property test needs no dependency.
    fn rng(seed: &mut u64) -> u64 {
        *seed ^= *seed << 13;
        *seed ^= *seed >> 7;
        *seed ^= *seed << 17;
        *seed
    }

    #[test]
    fn one_region_blocks_decode_in_bcdec_as_the_model_says() {
        // The packing checked bit for bit against the independent decoder: random valid
        // endpoints and indices of every one-region mode, packed, decoded by bcdec, equal to
        // the palette the search scores.
        let mut seed = 0x9e37_79b9_7f4a_7c15u64;
        for mode in 0..ONE_REGION_MODES.len() {
            let (_, p, d) = ONE_REGION_MODES[mode];
            let mut tried = 0;
            while tried < 300 {
                let a: [i32; 3] = std::array::from_fn(|_| (rng(&mut seed) % (1 << p)) as i32);
                let span = 1i64 << (d - 1);
                let e = std::array::from_fn(|c| {
                    let delta = (rng(&mut seed) % (2 * span as u64)) as i64 - span;
                    [a[c], (a[c] as i64 + delta) as i32]
                });
                let cand = OneRegion { mode, e };
                if !cand.valid() {
                    continue;
                }
                let idx: [u8; 16] = std::array::from_fn(|_| (rng(&mut seed) % 16) as u8);
                // Swapping for the anchor can push a delta of −2^(d−1) out of range: None.
                let Some(block) = cand.pack(idx) else {
                    continue;
                };
                tried += 1;
                let mut out = [0u16; 48];
                bcdec_rs::bc6h_half(&block, &mut out, 12, false);
                let pal = cand.palette();
                for k in 0..16 {
                    for c in 0..3 {
                        let got = half::f16::from_bits(out[3 * k + c]).to_f32();
                        assert_eq!(got, pal[idx[k] as usize][c], "mode {mode} texel {k}");
                    }
                }
            }
        }
    }

    #[test]
    fn the_search_is_never_worse_than_the_exhaustive_kernel_and_exact_on_a_constant() {
        let mut seed = 7u64;
        for (w, h) in [(1, 1), (2, 2), (4, 4), (8, 8), (3, 5)] {
            let mut img = Image::new(w, h, 3);
            for v in img.data.iter_mut() {
                // Three decades of dynamic range, as a small level near a sun has.
                *v = 10f32.powf((rng(&mut seed) % 3000) as f32 / 1000.0 - 1.0);
            }
            let eps = metric_eps(&img);
            let plain = block_errors(&img, &encode_with(&img, &exhaustive_settings()), eps);
            let searched = block_errors(&img, &encode_searched(&img), eps);
            for (s, p) in searched.iter().zip(&plain) {
                assert!(s <= p, "{w}x{h}: {s} > {p}");
            }
            assert_eq!(
                encode_searched(&img),
                encode_searched(&img),
                "deterministic"
            );
        }
        // A constant colour is one palette entry away: well under a half-float step.
        let mut img = Image::new(2, 2, 3);
        img.data
            .chunks_exact_mut(3)
            .for_each(|t| t.copy_from_slice(&[3.7, 0.42, 0.05]));
        let mut back = Image::new(2, 2, 3);
        decode(&encode_searched(&img), &mut back);
        let (mean, _) = relative_errors(&[img], &[back]);
        assert!(mean < 1e-3, "{mean}");
    }
}
