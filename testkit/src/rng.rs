//! A small seeded generator (xorshift64) for deterministic test data: random edits, points,
//! rays and shuffles that every run and every machine draws alike.

/// Marsaglia's xorshift64: each call shifts the state and returns it. The seed must not be
/// zero (zero stays zero).
#[derive(Clone, Debug)]
pub struct XorShift64(pub u64);

impl XorShift64 {
    /// The next state.
    pub fn next_u64(&mut self) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0
    }

    /// Uniform in [0, 1), from the state's top 53 bits.
    pub fn unit_f64(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Uniform in [0, 1), from the state's top 24 bits.
    pub fn unit_f32(&mut self) -> f32 {
        (self.next_u64() >> 40) as f32 / (1u64 << 24) as f32
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_stream_is_xorshift64_and_its_units_lie_in_zero_to_one() {
        let mut rng = XorShift64(1);
        // x ^= x << 13; x ^= x >> 7; x ^= x << 17, from 1.
        assert_eq!(rng.next_u64(), 0x4082_2041);
        let mut rng = XorShift64(0x2545_f491_4f6c_dd1d);
        for _ in 0..10_000 {
            let (a, b) = (rng.unit_f64(), rng.unit_f32());
            assert!(
                (0.0..1.0).contains(&a) && (0.0..1.0).contains(&b),
                "{a} {b}"
            );
        }
    }
}
