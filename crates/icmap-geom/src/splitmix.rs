//! SplitMix64, the tiny deterministic generator of the unit tests, the benches and the examples
//! (no extra dependency). One copy: the unit tests use it as `crate::splitmix`, the benches and
//! examples include this file by path. Not part of the library.

// Each user takes the methods it needs.
#![allow(dead_code)]

/// SplitMix64: a 64-bit state advanced by a constant, each output a mix of the state.
pub struct Rng(pub u64);

impl Rng {
    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in [0, 1) (53 random bits).
    pub fn next(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Uniform in [lo, hi).
    pub fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.next()
    }

    /// Normal with mean 0 and deviation `sigma` (Box-Muller).
    pub fn normal(&mut self, sigma: f64) -> f64 {
        let u = self.next().max(1e-300);
        sigma * (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * self.next()).cos()
    }
}
