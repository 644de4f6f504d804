//! SplitMix64 (Steele, Lea, Flood 2014): the one seeded generator of the product: pixel sampling, RANSAC, fault
//! schedules. Tiny, fast (a few ns per draw), identical on every platform, so every result that depends on it is
//! reproducible from its seed. Good for sampling and schedules, not for statistics that need a long period.

/// A SplitMix64 state; the seed is the initial state.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SplitMix64(pub u64);

impl SplitMix64 {
    /// A generator seeded with `seed`.
    pub const fn new(seed: u64) -> Self {
        SplitMix64(seed)
    }

    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in [0, 1).
    pub fn unit(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Uniform in [0, 1), single precision.
    pub fn unit_f32(&mut self) -> f32 {
        (self.next_u64() >> 40) as f32 / (1u32 << 24) as f32
    }

    /// True with probability `p`.
    pub fn chance(&mut self, p: f64) -> bool {
        p > 0.0 && self.unit() < p
    }

    /// Uniform in `0..n` (multiply-shift on the high 32 bits; `n` below 2^32).
    pub fn below(&mut self, n: usize) -> usize {
        ((self.next_u64() >> 32) as usize * n) >> 32
    }

    /// A non-zero byte.
    pub fn nonzero_byte(&mut self) -> u8 {
        (self.below(255) + 1) as u8
    }

    /// A uniform integer in `[lo, hi]`.
    pub fn range_i32(&mut self, lo: i32, hi: i32) -> i32 {
        lo + self.below((hi - lo + 1) as usize) as i32
    }
}

/// Decorrelates `(seed, index)` into an independent stream seed (the SplitMix64 finaliser): one generator per
/// image, tree or leaf, whatever the thread that draws from it.
pub fn mix_seed(seed: u64, index: u64) -> u64 {
    SplitMix64::new(seed ^ index.wrapping_mul(0xD1B5_4A32_D192_ED03)).next_u64()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reference_values_and_ranges() {
        // SplitMix64 from seed 0: the published first output.
        assert_eq!(SplitMix64::new(0).next_u64(), 0xE220_A839_7B1D_CDAF);
        let mut r = SplitMix64::new(7);
        for _ in 0..1000 {
            assert!(r.below(10) < 10);
            let u = r.unit_f32();
            assert!((0.0..1.0).contains(&u));
            assert_ne!(r.nonzero_byte(), 0);
        }
        assert!(!r.chance(0.0));
        for _ in 0..1000 {
            assert!((-50..=50).contains(&r.range_i32(-50, 50)));
        }
        assert_ne!(mix_seed(1, 0), mix_seed(1, 1));
    }
}
