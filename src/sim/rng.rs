//! The seeded generator of simulations and tests: xoshiro256++
//! (`rand_xoshiro`) for uniform numbers, `rand_distr`'s standard normal for
//! Gaussian ones. Same seed, same sequence, on every platform.

use rand_distr::{Distribution, StandardNormal, StandardUniform};
use rand_xoshiro::Xoshiro256PlusPlus;
use rand_xoshiro::rand_core::{Rng as _, SeedableRng};

/// Seeded generator (xoshiro256++). Not for cryptography.
#[derive(Debug, Clone)]
pub struct Rng {
    bits: Xoshiro256PlusPlus,
}

impl Rng {
    /// A generator for `seed`; every seed (including 0) is valid, and
    /// nearby seeds give unrelated streams (SplitMix64 seeding).
    pub fn new(seed: u64) -> Self {
        Rng {
            bits: Xoshiro256PlusPlus::seed_from_u64(seed),
        }
    }

    /// Next 64 uniformly distributed bits.
    pub fn next_u64(&mut self) -> u64 {
        self.bits.next_u64()
    }

    /// Uniform in [0, 1), 53 bits of precision.
    pub fn uniform(&mut self) -> f64 {
        StandardUniform.sample(&mut self.bits)
    }

    /// Uniform in [lo, hi).
    pub fn uniform_range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.uniform()
    }

    /// Standard normal deviate (mean 0, standard deviation 1).
    pub fn gaussian(&mut self) -> f64 {
        StandardNormal.sample(&mut self.bits)
    }

    /// Normal deviate with standard deviation `sigma`.
    pub fn normal(&mut self, sigma: f64) -> f64 {
        sigma * self.gaussian()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn same_seed_same_stream_and_seeds_differ() {
        let mut a = Rng::new(7);
        let mut b = Rng::new(7);
        let mut c = Rng::new(8);
        let sa: Vec<u64> = (0..5).map(|_| a.next_u64()).collect();
        let sb: Vec<u64> = (0..5).map(|_| b.next_u64()).collect();
        let sc: Vec<u64> = (0..5).map(|_| c.next_u64()).collect();
        assert_eq!(sa, sb);
        assert_ne!(sa, sc);
        assert_ne!(Rng::new(0).next_u64(), 0);
    }

    #[test]
    fn moments_are_right() {
        let mut r = Rng::new(42);
        let n = 200_000;
        let u: Vec<f64> = (0..n).map(|_| r.uniform()).collect();
        assert!(u.iter().all(|&x| (0.0..1.0).contains(&x)));
        let mean_u = u.iter().sum::<f64>() / n as f64;
        assert!((mean_u - 0.5).abs() < 0.005, "{mean_u}");
        let g: Vec<f64> = (0..n).map(|_| r.gaussian()).collect();
        let mean = g.iter().sum::<f64>() / n as f64;
        let var = g.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n as f64;
        assert!(mean.abs() < 0.01, "{mean}");
        assert!((var - 1.0).abs() < 0.02, "{var}");
        // About 4.55 % of a normal sample lies beyond 2σ.
        let tail = g.iter().filter(|x| x.abs() > 2.0).count() as f64 / n as f64;
        assert!((tail - 0.0455).abs() < 0.003, "{tail}");
    }
}
