//! What the protocol's integration tests share.

/// Small deterministic generator (xorshift64*), so the seeded sweeps need no extra dependency.
pub struct Rng(pub u64);

// Each test crate that includes this module uses only some of the draws.
#[allow(dead_code)]
impl Rng {
    /// The next 64 random bits.
    pub fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }
    /// A value in 0..n.
    pub fn below(&mut self, n: u64) -> u64 {
        self.next() % n
    }
    /// A value in [0, 1) with 53 random bits.
    pub fn unit(&mut self) -> f64 {
        (self.next() >> 11) as f64 / (1u64 << 53) as f64
    }
    /// A random byte.
    pub fn byte(&mut self) -> u8 {
        self.next() as u8
    }
}
