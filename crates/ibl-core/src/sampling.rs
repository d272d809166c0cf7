//! Deterministic sample sequences: Hammersley points and a small seeded PCG generator.

/// Van der Corput radical inverse in base 2 of `i`, in [0, 1).
#[inline]
pub(crate) fn radical_inverse_base2(i: u32) -> f32 {
    (i.reverse_bits() >> 8) as f32 * (1.0 / 16777216.0)
}

/// The i-th of n Hammersley points: (i/n, radical_inverse(i)), both in [0, 1).
#[inline]
pub fn hammersley(i: u32, n: u32) -> (f32, f32) {
    (i as f32 / n as f32, radical_inverse_base2(i))
}

/// PCG32 (O'Neill 2014, XSH-RR): a seeded generator for tests and Monte-Carlo references.
#[derive(Clone, Debug)]
pub struct Pcg32 {
    state: u64,
    inc: u64,
}

impl Pcg32 {
    /// The generator of O'Neill 2014 seeded with `seed` on sequence `stream` (each stream an independent sequence).
    pub fn new(seed: u64, stream: u64) -> Self {
        let mut rng = Pcg32 {
            state: 0,
            inc: (stream << 1) | 1,
        };
        rng.next_u32();
        rng.state = rng.state.wrapping_add(seed);
        rng.next_u32();
        rng
    }

    /// The next uniformly distributed 32-bit value (PCG-XSH-RR output function).
    pub fn next_u32(&mut self) -> u32 {
        let old = self.state;
        self.state = old.wrapping_mul(6364136223846793005).wrapping_add(self.inc);
        let xorshifted = (((old >> 18) ^ old) >> 27) as u32;
        let rot = (old >> 59) as u32;
        xorshifted.rotate_right(rot)
    }

    /// Uniform in [0, 1).
    pub fn next_f32(&mut self) -> f32 {
        (self.next_u32() >> 8) as f32 * (1.0 / 16777216.0)
    }

    /// Uniform in [0, 1) with 53 bits.
    pub fn next_f64(&mut self) -> f64 {
        let hi = (self.next_u32() as u64) << 21;
        let lo = (self.next_u32() >> 11) as u64;
        (hi | lo) as f64 * (1.0 / 9007199254740992.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn radical_inverse_known_values() {
        assert_eq!(radical_inverse_base2(0), 0.0);
        assert_eq!(radical_inverse_base2(1), 0.5);
        assert_eq!(radical_inverse_base2(2), 0.25);
        assert_eq!(radical_inverse_base2(3), 0.75);
        assert!(radical_inverse_base2(u32::MAX) < 1.0);
    }

    #[test]
    fn hammersley_is_stratified() {
        // Every dyadic box of area 1/n holds exactly one point (a (0,m,2)-net).
        let n = 64u32;
        let mut seen = vec![false; n as usize];
        for i in 0..n {
            let (a, b) = hammersley(i, n);
            let cell = ((a * 8.0) as usize) * 8 + (b * 8.0) as usize;
            assert!(!seen[cell]);
            seen[cell] = true;
        }
    }

    #[test]
    fn pcg_mean_is_half() {
        let mut r = Pcg32::new(42, 7);
        let m: f64 = (0..100_000).map(|_| r.next_f64()).sum::<f64>() / 100_000.0;
        assert!((m - 0.5).abs() < 0.005);
    }
}
