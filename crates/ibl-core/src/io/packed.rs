//! The packed HDR texel formats engines ship: shared-exponent RGB9E5 and the unsigned small
//! floats of B10G11R11, encoded as their specifications round them and decoded exactly.

/// Largest RGB9E5 value: (2⁹ − 1)/2⁹ · 2^(31 − 15) = 65408 (EXT_texture_shared_exponent,
/// "sharedexp_max").
pub(crate) const RGB9E5_MAX: f32 = 65408.0;
/// Largest 11-bit unsigned float (5-bit exponent, 6-bit mantissa): (2 − 2⁻⁶)·2¹⁵ = 65024.
pub(crate) const UF11_MAX: f32 = 65024.0;
/// Largest 10-bit unsigned float (5-bit exponent, 5-bit mantissa): (2 − 2⁻⁵)·2¹⁵ = 64512.
pub(crate) const UF10_MAX: f32 = 64512.0;

const E5_BIAS: i32 = 15;
const E5_MANTISSA: i32 = 9;

/// Encodes linear RGB as E5B9G9R9_UFLOAT_PACK32 (R in bits 0–8, G 9–17, B 18–26, exponent
/// 27–31), following the encoding of the EXT_texture_shared_exponent specification (§
/// "Encoding"): channels clamped to [0, sharedexp_max] (NaN to 0), the shared exponent from the
/// largest channel, raised by one when its mantissa would round up to 2⁹, and every mantissa
/// rounded to nearest. The decoded value is then within half a mantissa step, 2⁻¹⁰ of the
/// largest channel's power of two, of each clamped channel.
pub(crate) fn rgb9e5_encode(rgb: [f32; 3]) -> u32 {
    let c = rgb.map(|v| if v > 0.0 { v.min(RGB9E5_MAX) } else { 0.0 });
    let max_c = c[0].max(c[1]).max(c[2]);
    // floor(log2(max_c)) exactly, from the float's exponent (max_c = 0 takes the minimum).
    let floor_log2 = if max_c > 0.0 {
        floor_log2(max_c)
    } else {
        i32::MIN / 2
    };
    let exp_p = floor_log2.max(-E5_BIAS - 1) + 1 + E5_BIAS;
    let scale = |e: i32| exp2i(e - E5_BIAS - E5_MANTISSA);
    let max_s = (max_c as f64 / scale(exp_p) + 0.5).floor();
    let exp = if max_s >= (1 << E5_MANTISSA) as f64 {
        exp_p + 1
    } else {
        exp_p
    };
    let s = scale(exp);
    let m = c.map(|v| ((v as f64 / s + 0.5).floor() as u32).min(511));
    m[0] | (m[1] << 9) | (m[2] << 18) | ((exp as u32) << 27)
}

/// Decodes E5B9G9R9_UFLOAT_PACK32: channel = mantissa · 2^(exponent − 15 − 9).
pub(crate) fn rgb9e5_decode(v: u32) -> [f32; 3] {
    let e = (v >> 27) as i32;
    let s = exp2i(e - E5_BIAS - E5_MANTISSA);
    [v & 511, (v >> 9) & 511, (v >> 18) & 511].map(|m| (m as f64 * s) as f32)
}

/// Encodes a linear value as an unsigned float with a 5-bit exponent (bias 15) and `m`
/// mantissa bits (11-bit: m = 6, 10-bit: m = 5), rounding to nearest even as the Vulkan and
/// OpenGL specifications require of conversions to these formats ("round to nearest" in
/// Vulkan §"Floating-Point Computation"); negatives and NaN become 0, values above the largest
/// finite value saturate to it (never Inf).
pub(crate) fn uf_encode(v: f32, m: u32) -> u32 {
    let max_bits = (30 << m) | ((1 << m) - 1);
    // Negatives and NaN (for which every comparison is false) encode as 0.
    if v.is_nan() || v <= 0.0 {
        return 0;
    }
    // The value in units of the format's smallest step for its binade: exact in f64.
    let e = floor_log2(v).max(1 - E5_BIAS); // denormals share the exponent of the first binade
    let step = exp2i(e - m as i32);
    let q = (v as f64 / step).round_ties_even() as u64;
    // q = 2^m·(1.f) for normals (or < 2^m for denormals); rounding up to 2^(m+1) carries into
    // the exponent, which the packed (exponent << m | mantissa) arithmetic does by itself.
    let biased = if floor_log2(v) < 1 - E5_BIAS {
        0
    } else {
        e + E5_BIAS
    } as u64;
    let bits = if biased == 0 {
        q
    } else {
        ((biased - 1) << m) + q
    };
    (bits as u32).min(max_bits)
}

/// Decodes an unsigned float with a 5-bit exponent and `m` mantissa bits.
pub(crate) fn uf_decode(bits: u32, m: u32) -> f32 {
    let e = (bits >> m) as i32;
    let f = (bits & ((1 << m) - 1)) as f64;
    let v = if e == 0 {
        f * exp2i(1 - E5_BIAS - m as i32)
    } else {
        (1.0 + f / (1u64 << m) as f64) * exp2i(e - E5_BIAS)
    };
    v as f32
}

/// Encodes linear RGB as B10G11R11_UFLOAT_PACK32 (R 11 bits at 0, G 11 bits at 11, B 10 bits
/// at 22), as Vulkan's, Direct3D's R11G11B10_FLOAT and OpenGL's R11F_G11F_B10F share it.
pub(crate) fn b10g11r11_encode(rgb: [f32; 3]) -> u32 {
    uf_encode(rgb[0], 6) | (uf_encode(rgb[1], 6) << 11) | (uf_encode(rgb[2], 5) << 22)
}

/// Decodes B10G11R11_UFLOAT_PACK32.
pub(crate) fn b10g11r11_decode(v: u32) -> [f32; 3] {
    [
        uf_decode(v & 0x7ff, 6),
        uf_decode((v >> 11) & 0x7ff, 6),
        uf_decode(v >> 22, 5),
    ]
}

/// ⌊log₂ v⌋ of a positive finite f32, exactly (subnormals included).
fn floor_log2(v: f32) -> i32 {
    let bits = v.to_bits();
    let e = ((bits >> 23) & 0xff) as i32;
    if e == 0 {
        // Subnormal: 2^-149 · mantissa.
        let m = bits & 0x7f_ffff;
        -149 + (31 - m.leading_zeros() as i32)
    } else {
        e - 127
    }
}

/// 2^e as f64 (exact for the exponents used here).
fn exp2i(e: i32) -> f64 {
    (e as f64).exp2()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A slow, independent RGB9E5 encoder written from the specification's formulas with
    /// f64 log2 and powers, for comparison.
    fn rgb9e5_reference(rgb: [f32; 3]) -> [f64; 3] {
        let c = rgb.map(|v| (v as f64).clamp(0.0, RGB9E5_MAX as f64));
        let max_c = c[0].max(c[1]).max(c[2]);
        let exp_p = (max_c.log2().floor() as i32).max(-16) + 1 + 15;
        let max_s = (max_c / 2f64.powi(exp_p - 24) + 0.5).floor();
        let exp = if max_s == 512.0 { exp_p + 1 } else { exp_p };
        c.map(|v| (v / 2f64.powi(exp - 24) + 0.5).floor() * 2f64.powi(exp - 24))
    }

    fn lcg(seed: &mut u64) -> f32 {
        *seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((*seed >> 40) as f32) / (1u64 << 24) as f32
    }

    #[test]
    fn rgb9e5_matches_the_specification_and_its_error_bound() {
        let mut seed = 7u64;
        for k in 0..200_000 {
            // Values over 40 binades, with channels far apart and near powers of two.
            let e = (k % 40) - 24;
            let rgb =
                [0, 1, 2].map(|_| lcg(&mut seed) * 2f32.powi(e - (lcg(&mut seed) * 12.0) as i32));
            let d = rgb9e5_decode(rgb9e5_encode(rgb));
            let r = rgb9e5_reference(rgb);
            let max_c = rgb[0].max(rgb[1]).max(rgb[2]);
            for c in 0..3 {
                assert_eq!(d[c] as f64, r[c], "{rgb:?}");
                // Within 2^-8 of the texel's largest channel, or half the smallest step
                // (2^-25) where the shared exponent bottoms out.
                let bound = (max_c * 2f32.powi(-8)).max(2f32.powi(-25));
                assert!((d[c] - rgb[c]).abs() <= bound, "{rgb:?} → {d:?}");
            }
        }
    }

    #[test]
    fn rgb9e5_edges() {
        assert_eq!(rgb9e5_decode(rgb9e5_encode([0.0; 3])), [0.0; 3]);
        assert_eq!(
            rgb9e5_decode(rgb9e5_encode([1e9, -1.0, f32::NAN])),
            [RGB9E5_MAX, 0.0, 0.0]
        );
        assert_eq!(
            rgb9e5_decode(rgb9e5_encode([1.0, 0.5, 0.25])),
            [1.0, 0.5, 0.25]
        );
        // 511.5/512·2^k rounds up to the next exponent (the max_s = 2^9 case).
        let v = 511.75 / 512.0;
        assert_eq!(rgb9e5_decode(rgb9e5_encode([v, 0.0, 0.0]))[0], 1.0);
        // Smallest non-zero: 2^-24.
        assert_eq!(rgb9e5_decode(1)[0], 2f32.powi(-24));
    }

    #[test]
    fn small_floats_round_to_nearest_even_and_round_trip_exactly() {
        for m in [5u32, 6] {
            let max = if m == 6 { UF11_MAX } else { UF10_MAX };
            // Every representable value decodes and re-encodes to itself.
            for bits in 0..(31u32 << m) {
                let v = uf_decode(bits, m);
                assert_eq!(uf_encode(v, m), bits, "m={m} bits={bits} v={v}");
            }
            assert_eq!(uf_decode((30 << m) | ((1 << m) - 1), m), max);
            // Midpoints go to the even neighbour; just above goes up.
            for bits in (0..(30u32 << m)).step_by(37) {
                let (a, b) = (uf_decode(bits, m) as f64, uf_decode(bits + 1, m) as f64);
                let mid = ((a + b) / 2.0) as f32;
                let want = if bits % 2 == 0 { bits } else { bits + 1 };
                assert_eq!(uf_encode(mid, m), want, "m={m} bits={bits}");
                let above = f32::from_bits(mid.to_bits() + 1);
                assert_eq!(uf_encode(above, m), bits + 1);
            }
            assert_eq!(uf_encode(1e9, m), (30 << m) | ((1 << m) - 1));
            assert_eq!(uf_encode(-3.0, m), 0);
            assert_eq!(uf_encode(f32::NAN, m), 0);
            assert_eq!(uf_encode(f32::INFINITY, m), (30 << m) | ((1 << m) - 1));
        }
    }

    #[test]
    fn b10g11r11_packs_as_vulkan_lays_it_out() {
        let v = b10g11r11_encode([1.0, 2.0, 0.5]);
        // 1.0 = exponent 15, mantissa 0 → 15 << 6; 2.0 → 16 << 6; 0.5 (10-bit) → 14 << 5.
        assert_eq!(v & 0x7ff, 15 << 6);
        assert_eq!((v >> 11) & 0x7ff, 16 << 6);
        assert_eq!(v >> 22, 14 << 5);
        assert_eq!(b10g11r11_decode(v), [1.0, 2.0, 0.5]);
        let mut seed = 3u64;
        for _ in 0..100_000 {
            let rgb =
                [0, 1, 2].map(|_| lcg(&mut seed) * 2f32.powi((lcg(&mut seed) * 30.0) as i32 - 14));
            let d = b10g11r11_decode(b10g11r11_encode(rgb));
            for c in 0..3 {
                // Half a step of a 6-bit (5-bit for blue) mantissa, relative; for denormals half
                // the smallest step, 2^-(15+m).
                let (rel, abs) = if c == 2 { (-6, -20) } else { (-7, -21) };
                let bound = (rgb[c] * 2f32.powi(rel)).max(2f32.powi(abs));
                assert!((d[c] - rgb[c]).abs() <= bound, "{rgb:?} {d:?}");
            }
        }
    }
}
