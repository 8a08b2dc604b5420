//! The emulator's seeded generator for fault injection: xoshiro256++
//! (`rand_xoshiro`), seeded through SplitMix64, so every emulator run with
//! the same seed injects the same faults on every platform.

use rand_xoshiro::Xoshiro256PlusPlus;
use rand_xoshiro::rand_core::{Rng as _, SeedableRng};

/// Deterministic pseudo-random generator for faults (not cryptographic).
#[derive(Debug, Clone)]
pub struct FaultRng {
    bits: Xoshiro256PlusPlus,
}

impl FaultRng {
    /// A generator for `seed`; every seed (0 too) gives its own stream.
    pub fn new(seed: u64) -> Self {
        Self {
            bits: Xoshiro256PlusPlus::seed_from_u64(seed),
        }
    }

    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.bits.next_u64()
    }

    /// A random byte.
    pub fn next_u8(&mut self) -> u8 {
        (self.next_u64() >> 56) as u8
    }

    /// A uniform number in `[0, 1)`.
    pub fn next_f64(&mut self) -> f64 {
        // 53 random mantissa bits.
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }

    /// True with probability `p` (clamped to `[0, 1]`).
    pub fn chance(&mut self, p: f64) -> bool {
        p > 0.0 && self.next_f64() < p
    }

    /// A uniform integer in `[0, n)`; 0 when `n` is 0. (The modulo's bias
    /// is below 2⁻⁴⁰ for the small `n` faults draw.)
    pub fn below(&mut self, n: u64) -> u64 {
        if n == 0 { 0 } else { self.next_u64() % n }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn same_seed_same_sequence_and_seeds_differ() {
        let mut a = FaultRng::new(42);
        let mut b = FaultRng::new(42);
        let mut c = FaultRng::new(43);
        let sa: Vec<u64> = (0..100).map(|_| a.next_u64()).collect();
        let sb: Vec<u64> = (0..100).map(|_| b.next_u64()).collect();
        let sc: Vec<u64> = (0..100).map(|_| c.next_u64()).collect();
        assert_eq!(sa, sb);
        assert_ne!(sa, sc);
    }

    #[test]
    fn zero_seed_does_not_stick_at_zero() {
        let mut g = FaultRng::new(0);
        assert_ne!(g.next_u64(), 0);
        assert_ne!(g.next_u64(), g.next_u64());
    }

    #[test]
    fn chance_respects_extremes_and_rate() {
        let mut g = FaultRng::new(7);
        assert!(!(0..1000).any(|_| g.chance(0.0)));
        assert!((0..1000).all(|_| g.chance(1.0)));
        let hits = (0..10_000).filter(|_| g.chance(0.25)).count();
        assert!((2_000..3_000).contains(&hits), "hits {hits}");
    }

    #[test]
    fn next_f64_is_in_unit_interval() {
        let mut g = FaultRng::new(3);
        for _ in 0..1000 {
            let x = g.next_f64();
            assert!((0.0..1.0).contains(&x));
        }
    }
}
