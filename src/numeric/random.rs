//! The one pseudo-random generator of the crate: SplitMix64 (Steele, Lea, Flood, "Fast
//! splittable pseudorandom number generators", OOPSLA 2014), seeded explicitly, so the random
//! states of `check`, the accuracy sweep of `lagrange bench` and the tests are the same on
//! every run and every machine.
//!
//! Not here: what the draws are used for (`check::states`, `precision::accuracy`), anything
//! cryptographic.

/// A small deterministic generator with uniform and Gaussian draws.
#[derive(Clone, Debug)]
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Rng {
        Rng(seed)
    }

    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in `[lo, hi)` (53 random bits).
    pub fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        let unit = (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64;
        lo + (hi - lo) * unit
    }

    /// Standard normal (Box–Muller).
    pub fn normal(&mut self) -> f64 {
        let u = 1.0 - self.uniform(0.0, 1.0);
        let v = self.uniform(0.0, 1.0);
        (-2.0 * u.ln()).sqrt() * (2.0 * std::f64::consts::PI * v).cos()
    }

    /// A vector with `dim` components uniform in `[lo, hi)` (trailing components zero).
    pub fn uniform_vector(&mut self, dim: usize, lo: f64, hi: f64) -> [f64; 3] {
        let mut x = [0.0; 3];
        for c in x.iter_mut().take(dim) {
            *c = self.uniform(lo, hi);
        }
        x
    }

    /// A vector with `dim` components `scale`·N(0, 1) (trailing components zero).
    pub fn normal_vector(&mut self, dim: usize, scale: f64) -> [f64; 3] {
        let mut x = [0.0; 3];
        for c in x.iter_mut().take(dim) {
            *c = scale * self.normal();
        }
        x
    }
}
