//! Counter-based random numbers for dataset expansion.
//!
//! A sample must be a pure function of `(dataset seed, sample index)` on every machine, in every
//! process, whatever order the coordinator hands samples out in. So there is no generator state
//! carried between samples: each decision of each sample opens its own short stream keyed by
//! `(seed, index, stream)` and draws from it. Giving every decision its own stream also means a
//! decision added later cannot shift the numbers that existing decisions see, so old datasets
//! keep expanding to the same samples.
//!
//! Only integer arithmetic and IEEE-754 basic operations (`+ - * /`, which Rust never contracts
//! into FMAs) are used, so the results are bit-identical across platforms. No transcendental
//! functions (their libm implementations differ) and no hash-map iteration order.

/// The increment of SplitMix64 (2^64 / golden ratio, odd).
const GOLDEN_GAMMA: u64 = 0x9E37_79B9_7F4A_7C15;

/// The SplitMix64 finaliser (Stafford's "Mix13" variant): a bijection on `u64` with full
/// avalanche, so nearby keys (index 17 vs 18) give unrelated outputs.
#[must_use]
pub const fn mix64(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// Hashes a string under a seed (FNV-1a over the UTF-8 bytes, then [`mix64`]).
///
/// Used to order identities for the held-out split independently of catalog order; FNV-1a is
/// specified byte by byte, unlike `std`'s `DefaultHasher`, whose algorithm may change between
/// Rust releases.
#[must_use]
pub fn hash_str(seed: u64, text: &str) -> u64 {
    const FNV_OFFSET: u64 = 0xCBF2_9CE4_8422_2325;
    const FNV_PRIME: u64 = 0x0000_0100_0000_01B3;
    let mut h = FNV_OFFSET ^ mix64(seed);
    for byte in text.bytes() {
        h ^= u64::from(byte);
        h = h.wrapping_mul(FNV_PRIME);
    }
    mix64(h)
}

/// One independent decision stream of one sample.
///
/// The key is folded through [`mix64`] at every step so that `(seed, index, stream)` triples that
/// differ in one bit still start from unrelated states.
#[derive(Debug, Clone)]
pub struct SampleRng {
    state: u64,
}

impl SampleRng {
    /// Opens the stream `stream` of sample `index` of the dataset seeded with `seed`.
    #[must_use]
    pub fn new(seed: u64, index: u64, stream: u64) -> Self {
        let k = mix64(seed.wrapping_add(GOLDEN_GAMMA));
        let k = mix64(k ^ index.wrapping_mul(GOLDEN_GAMMA));
        let k = mix64(k ^ stream.wrapping_add(1).wrapping_mul(0xD1B5_4A32_D192_ED03));
        Self { state: k }
    }

    /// The next 64 uniformly distributed bits (a SplitMix64 step).
    pub fn next_u64(&mut self) -> u64 {
        self.state = self.state.wrapping_add(GOLDEN_GAMMA);
        mix64(self.state)
    }

    /// Uniform in `[0, 1)`: the top 53 bits scaled by 2^-53, which is exact in `f64`.
    pub fn next_f64(&mut self) -> f64 {
        const SCALE: f64 = 1.0 / (1u64 << 53) as f64;
        (self.next_u64() >> 11) as f64 * SCALE
    }

    /// Uniform in `[lo, hi]` (`hi` itself is reached only when `lo == hi`).
    pub fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.next_f64()
    }

    /// `true` with probability `p`; `p = 0` is never true and `p = 1` always is, because
    /// [`Self::next_f64`] is strictly below 1.
    pub fn bernoulli(&mut self, p: f64) -> bool {
        self.next_f64() < p
    }

    /// Uniform integer in `[0, n)`, exactly unbiased (Lemire's multiply-shift with rejection).
    /// Returns 0 for `n == 0` so callers with an empty choice fail at their own check instead.
    pub fn below(&mut self, n: u64) -> u64 {
        if n == 0 {
            return 0;
        }
        // Values of the low word below `threshold` would make some outcomes one count more
        // likely than others; redraw them (probability < n / 2^64).
        let threshold = n.wrapping_neg() % n;
        loop {
            let m = u128::from(self.next_u64()) * u128::from(n);
            if (m as u64) >= threshold {
                return (m >> 64) as u64;
            }
        }
    }

    /// An approximately standard normal deviate truncated to ±`limit` (at most 6): the
    /// Irwin–Hall sum of twelve uniforms minus 6 (mean 0, variance 1). Sums and products only,
    /// so the value is the same on every machine, unlike a Box–Muller through the platform's
    /// `ln` and `cos`.
    pub fn normal(&mut self, limit: f64) -> f64 {
        let mut s = -6.0;
        for _ in 0..12 {
            s += self.next_f64();
        }
        s.clamp(-limit, limit)
    }

    /// Uniform index into a slice of length `len`.
    pub fn pick(&mut self, len: usize) -> usize {
        // usize -> u64 is lossless on every supported target, and the result is < len.
        self.below(len as u64) as usize
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn known_answers_pin_the_algorithm() {
        // SplitMix64 seeded with 0 is a published sequence; its first output is this value.
        let mut state = 0u64;
        state = state.wrapping_add(GOLDEN_GAMMA);
        assert_eq!(mix64(state), 0xE220_A839_7B1D_CDAF);
    }

    #[test]
    fn streams_and_indices_are_independent() {
        let a = SampleRng::new(7, 17, 0).next_u64();
        let b = SampleRng::new(7, 18, 0).next_u64();
        let c = SampleRng::new(7, 17, 1).next_u64();
        let d = SampleRng::new(8, 17, 0).next_u64();
        assert!(a != b && a != c && a != d && b != c);
        assert_eq!(a, SampleRng::new(7, 17, 0).next_u64());
    }

    #[test]
    fn below_is_in_range_and_covers_it() {
        let mut rng = SampleRng::new(1, 2, 3);
        let mut seen = [0u32; 7];
        for _ in 0..7000 {
            let k = rng.below(7);
            assert!(k < 7);
            seen[k as usize] += 1;
        }
        assert!(seen.iter().all(|&c| (850..1150).contains(&c)), "{seen:?}");
    }

    #[test]
    fn f64_is_in_unit_interval() {
        let mut rng = SampleRng::new(0, 0, 0);
        for _ in 0..10_000 {
            let u = rng.next_f64();
            assert!((0.0..1.0).contains(&u));
        }
    }
}
