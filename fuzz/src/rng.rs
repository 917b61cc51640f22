//! A small deterministic generator (SplitMix64): every input is a pure function of
//! `(target, seed, index)`, so a finding reproduces with `--seed S --only INDEX`.

/// SplitMix64: fast, good enough for choosing mutations, and stable across platforms and
/// crate versions (unlike `rand`'s generators, whose streams may change between releases).
#[derive(Debug, Clone)]
pub struct Rng(u64);

impl Rng {
    /// A generator from a 64-bit state.
    pub fn new(state: u64) -> Self {
        Rng(state)
    }

    /// The generator of input `index` of `target` in campaign `seed`.
    pub fn for_input(target: &str, seed: u64, index: u64) -> Self {
        // FNV-1a of the target name, mixed with the seed and the index.
        let mut h: u64 = 0xcbf2_9ce4_8422_2325;
        for b in target.bytes() {
            h ^= u64::from(b);
            h = h.wrapping_mul(0x0000_0100_0000_01b3);
        }
        let mut r = Rng(h ^ seed.wrapping_mul(0x9e37_79b9_7f4a_7c15));
        let a = r.next_u64();
        Rng(a ^ index.wrapping_mul(0xd1b5_4a32_d192_ed03))
    }

    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    /// A number in `0..n` (0 when `n` is 0).
    pub fn below(&mut self, n: usize) -> usize {
        if n == 0 {
            0
        } else {
            (self.next_u64() % n as u64) as usize
        }
    }

    /// A number in `lo..=hi`.
    pub fn range(&mut self, lo: usize, hi: usize) -> usize {
        lo + self.below(hi.saturating_sub(lo) + 1)
    }

    /// True with probability `1 / n`.
    pub fn one_in(&mut self, n: usize) -> bool {
        self.below(n) == 0
    }

    /// A uniformly chosen element of a non-empty slice.
    pub fn pick<'a, T>(&mut self, items: &'a [T]) -> &'a T {
        &items[self.below(items.len())]
    }

    /// A size biased towards small values: mostly 1-8, sometimes up to `max`.
    pub fn small_size(&mut self, max: usize) -> usize {
        match self.below(8) {
            0..=4 => self.range(1, 8.min(max.max(1))),
            5 | 6 => self.range(1, 128.min(max.max(1))),
            _ => self.range(1, max.max(1)),
        }
    }

    /// A random byte.
    pub fn byte(&mut self) -> u8 {
        self.next_u64() as u8
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn inputs_are_deterministic_and_distinct() {
        let a = Rng::for_input("session", 1, 7).next_u64();
        let b = Rng::for_input("session", 1, 7).next_u64();
        let c = Rng::for_input("session", 1, 8).next_u64();
        let d = Rng::for_input("urdf", 1, 7).next_u64();
        assert_eq!(a, b);
        assert_ne!(a, c);
        assert_ne!(a, d);
    }
}
