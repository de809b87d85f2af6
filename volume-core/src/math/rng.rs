//! The one deterministic random generator of the workspace, for tests, benchmarks and the
//! generated accuracy cases.
//!
//! A 64-bit linear congruential generator with Knuth's MMIX constants (the state update of
//! PCG): tiny, seedable, and identical on every machine, so a failing random case replays
//! from its seed. It is not a cryptographic or a high-quality statistical generator: every
//! output is taken from the *high* bits of the state (the low bits of an LCG have short
//! periods), which is plenty for picking rays, jitter and corrupted bytes.
//!
//! The floating-point outputs reproduce the sequences the accuracy suite
//! (`intersect::accuracy`) was generated with, so its report stays the same.

use glam::Vec3;

const MULTIPLIER: u64 = 6_364_136_223_846_793_005;
const INCREMENT: u64 = 1_442_695_040_888_963_407;

/// The largest `f32` below 1 (the upper clamp of [`Rng::unit_f32`]).
const ONE_BELOW_F32: f32 = 1.0 - f32::EPSILON * 0.5;

/// Seeded deterministic generator; see the module docs.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Rng {
    state: u64,
}

impl Rng {
    /// A generator whose first step starts from `seed` (any value, 0 included).
    pub const fn new(seed: u64) -> Self {
        Self { state: seed }
    }

    /// Advances the state and returns it (callers take high bits only).
    #[inline]
    fn step(&mut self) -> u64 {
        self.state = self.state.wrapping_mul(MULTIPLIER).wrapping_add(INCREMENT);
        self.state
    }

    /// 32 uniformly random bits (the high half of the state).
    #[inline]
    pub fn next_u32(&mut self) -> u32 {
        (self.step() >> 32) as u32
    }

    /// A uniform integer in `[0, n)` (multiply-shift, bias below `n / 2³²`); 0 for `n == 0`.
    #[inline]
    pub fn below(&mut self, n: u32) -> u32 {
        ((u64::from(self.next_u32()) * u64::from(n)) >> 32) as u32
    }

    /// `true` with probability `p`.
    #[inline]
    pub fn chance(&mut self, p: f32) -> bool {
        self.unit_f32() < p
    }

    /// Uniform in `[0, 1)` with 53 random bits.
    #[inline]
    pub fn unit_f64(&mut self) -> f64 {
        (self.step() >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Uniform in `[0, 1)`: [`unit_f64`](Self::unit_f64) rounded to `f32` (kept below 1).
    #[inline]
    pub fn unit_f32(&mut self) -> f32 {
        (self.unit_f64() as f32).min(ONE_BELOW_F32)
    }

    /// Uniform in `[lo, hi)` (up to the rounding of `lo + (hi − lo)·u`).
    #[inline]
    pub fn range_f32(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * self.unit_f32()
    }

    /// A point with each coordinate uniform in `[lo, hi)`, drawn x, y, z in order.
    #[inline]
    pub fn vec3(&mut self, lo: f32, hi: f32) -> Vec3 {
        let x = self.range_f32(lo, hi);
        let y = self.range_f32(lo, hi);
        let z = self.range_f32(lo, hi);
        Vec3::new(x, y, z)
    }

    /// A uniform index in `[0, n)` from one [`unit_f32`](Self::unit_f32) draw; 0 for `n == 0`.
    #[inline]
    pub fn index(&mut self, n: usize) -> usize {
        ((self.unit_f32() * n as f32) as usize).min(n.saturating_sub(1))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn same_seed_same_sequence_and_outputs_in_range() {
        let (mut a, mut b) = (Rng::new(42), Rng::new(42));
        let mut counts = [0u32; 8];
        for _ in 0..80_000 {
            assert_eq!(a.next_u32(), b.next_u32());
            let u = a.unit_f32();
            assert!((0.0..1.0).contains(&u), "{u}");
            let x = a.range_f32(-2.0, 3.0);
            assert!((-2.0..=3.0).contains(&x), "{x}");
            assert!(a.index(5) < 5 && a.below(7) < 7);
            counts[a.below(8) as usize] += 1;
            b.unit_f32();
            b.range_f32(-2.0, 3.0);
            b.index(5);
            b.below(7);
            b.below(8);
        }
        // Roughly uniform: each of 8 buckets within 10 % of 10,000.
        assert!(
            counts.iter().all(|&c| c.abs_diff(10_000) < 1_000),
            "{counts:?}"
        );
        assert_ne!(Rng::new(1).next_u32(), Rng::new(2).next_u32());
    }

    #[test]
    fn unit_f64_is_the_lcg_high_bits() {
        // The accuracy suite's cases were generated from exactly this sequence.
        let mut r = Rng::new(0x1505_c0de);
        let s = 0x1505_c0deu64
            .wrapping_mul(MULTIPLIER)
            .wrapping_add(INCREMENT);
        assert_eq!(r.unit_f64(), (s >> 11) as f64 / (1u64 << 53) as f64);
    }
}
