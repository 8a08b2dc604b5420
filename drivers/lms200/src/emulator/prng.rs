//! A tiny seeded pseudo-random generator for fault injection.
//!
//! xorshift64* (Marsaglia's xorshift with a multiplicative output step): not
//! cryptographic, but fast, dependency-free and fully deterministic, so every
//! emulator run with the same seed injects the same faults.

/// Deterministic 64-bit pseudo-random generator (xorshift64*).
#[derive(Debug, Clone)]
pub struct XorShift64 {
    state: u64,
}

impl XorShift64 {
    /// A generator for `seed`; seed 0 (a fixed point of xorshift) is remapped.
    pub fn new(seed: u64) -> Self {
        let state = if seed == 0 {
            0x9E37_79B9_7F4A_7C15
        } else {
            seed
        };
        Self { state }
    }

    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        let mut x = self.state;
        x ^= x >> 12;
        x ^= x << 25;
        x ^= x >> 27;
        self.state = x;
        x.wrapping_mul(0x2545_F491_4F6C_DD1D)
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

    /// A uniform integer in `[0, n)`; 0 when `n` is 0.
    pub fn below(&mut self, n: u64) -> u64 {
        if n == 0 { 0 } else { self.next_u64() % n }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn same_seed_same_sequence() {
        let mut a = XorShift64::new(42);
        let mut b = XorShift64::new(42);
        for _ in 0..100 {
            assert_eq!(a.next_u64(), b.next_u64());
        }
    }

    #[test]
    fn zero_seed_does_not_stick_at_zero() {
        let mut g = XorShift64::new(0);
        assert_ne!(g.next_u64(), 0);
        assert_ne!(g.next_u64(), g.next_u64());
    }

    #[test]
    fn chance_respects_extremes_and_rate() {
        let mut g = XorShift64::new(7);
        assert!(!(0..1000).any(|_| g.chance(0.0)));
        assert!((0..1000).all(|_| g.chance(1.0)));
        let hits = (0..10_000).filter(|_| g.chance(0.25)).count();
        assert!((2_000..3_000).contains(&hits), "hits {hits}");
    }

    #[test]
    fn next_f64_is_in_unit_interval() {
        let mut g = XorShift64::new(3);
        for _ in 0..1000 {
            let x = g.next_f64();
            assert!((0.0..1.0).contains(&x));
        }
    }
}
