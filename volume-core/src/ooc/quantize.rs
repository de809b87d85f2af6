//! Conservative quantization of node min/max to half the voxel bits (thesis seed 004
//! §7.8.1: "the min/max values are quantized to half of the original bit resolution").
//!
//! A value `v` maps to the code axis `x(v) = (v − lo) · Q / (hi − lo)` with `Q = 2^bits − 1`
//! and `[lo, hi]` the finite value range of the whole volume. A range `[m, M]` is stored as
//! `[floor(x(m) − ε), ceil(x(M) + ε)]` (clamped to `0..=Q`), `ε` absorbing the f64 rounding
//! of `x`. An isovalue `c` is turned once into integer bounds `a = floor(x(c) + ε)`,
//! `b = ceil(x(c) − ε)`, and a node is visited iff `q_min ≤ a && q_max ≥ b`. If `c ∈ [m, M]`
//! then `x(m) ≤ x(c) ≤ x(M)` up to rounding, so the node is visited: quantization may add
//! traversal work (the thesis measured 5–10 %), never lose a hit. An empty range (only void
//! cells) is stored as `[Q, 0]`, which no isovalue passes.

use crate::voxel::VoxelType;

/// The code bounds an isovalue is compared against (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CodeQuery {
    pub a: u32,
    pub b: u32,
}

impl CodeQuery {
    /// True if a node with codes `[q_min, q_max]` may contain the isovalue.
    #[inline(always)]
    pub fn passes(self, q_min: u32, q_max: u32) -> bool {
        q_min <= self.a && q_max >= self.b
    }
}

/// Maps value ranges to `bits`-bit codes over `[lo, hi]`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Quantizer {
    /// Bits per code: half the voxel bits (4 for 8-bit voxels, 32 for f64).
    pub bits: u32,
    pub lo: f64,
    pub hi: f64,
}

impl Quantizer {
    /// Half the bits of `voxel_type` over the finite value range `[lo, hi]`.
    pub fn for_type(voxel_type: VoxelType, lo: f64, hi: f64) -> Self {
        let (lo, hi) = if lo.is_finite() && hi.is_finite() && lo <= hi {
            (lo, hi)
        } else {
            (0.0, 0.0)
        };
        Self {
            bits: voxel_type.size_bytes() as u32 * 4,
            lo,
            hi,
        }
    }

    /// The largest code `Q`.
    pub fn max_code(&self) -> u32 {
        ((1u64 << self.bits) - 1) as u32
    }

    /// Bytes per node in the encoded form (two codes).
    pub fn node_bytes(&self) -> usize {
        (self.bits as usize * 2).div_ceil(8)
    }

    fn scale(&self) -> f64 {
        if self.hi > self.lo {
            f64::from(self.max_code()) / (self.hi - self.lo)
        } else {
            0.0
        }
    }

    fn eps(&self) -> f64 {
        // f64 rounding of x(v) is below 1e-15·Q; a much larger margin costs nothing.
        1e-9 * f64::from(self.max_code()).max(1.0)
    }

    fn x(&self, v: f64) -> f64 {
        (v - self.lo) * self.scale()
    }

    fn clamp_code(&self, x: f64) -> u32 {
        x.clamp(0.0, f64::from(self.max_code())) as u32
    }

    /// Codes `[q_min, q_max]` of the true range `[min, max]`; `[Q, 0]` for an empty range
    /// (`min > max` or non-finite bounds).
    pub fn encode(&self, min: f64, max: f64) -> [u32; 2] {
        if !(min <= max && min.is_finite() && max.is_finite()) {
            return [self.max_code(), 0];
        }
        let e = self.eps();
        [
            self.clamp_code((self.x(min) - e).floor()),
            self.clamp_code((self.x(max) + e).ceil()),
        ]
    }

    /// The value range codes `q` stand for, rounded outwards (it contains the range that was
    /// encoded). `None` for the empty range.
    pub fn decode(&self, q: [u32; 2]) -> Option<(f64, f64)> {
        if q[0] > q[1] {
            return None;
        }
        if self.scale() == 0.0 {
            return Some((self.lo, self.hi));
        }
        let step = (self.hi - self.lo) / f64::from(self.max_code());
        let lo = self.lo + f64::from(q[0]) * step;
        let hi = self.lo + f64::from(q[1]) * step;
        // Outward by a few ulps of the larger magnitude plus the ε margin of `encode`.
        let slack = self.eps() * step + 4.0 * f64::EPSILON * lo.abs().max(hi.abs());
        Some((lo - slack, hi + slack))
    }

    /// The code bounds of isovalue `iso`, or `None` when no voxel range can contain it (NaN,
    /// or outside `[lo, hi]`).
    pub fn query(&self, iso: f32) -> Option<CodeQuery> {
        let c = f64::from(iso);
        if !(c >= self.lo && c <= self.hi) {
            return None;
        }
        let x = self.x(c);
        let e = self.eps();
        Some(CodeQuery {
            a: self.clamp_code((x + e).floor()),
            b: self.clamp_code((x - e).ceil()),
        })
    }

    /// Writes codes `q` of node `slot` into `out` (the packed node array of a treelet).
    pub fn put(&self, out: &mut [u8], slot: usize, q: [u32; 2]) {
        match self.bits {
            4 => out[slot] = (q[0] as u8) | ((q[1] as u8) << 4),
            8 => out[2 * slot..2 * slot + 2].copy_from_slice(&[q[0] as u8, q[1] as u8]),
            16 => {
                out[4 * slot..4 * slot + 2].copy_from_slice(&(q[0] as u16).to_le_bytes());
                out[4 * slot + 2..4 * slot + 4].copy_from_slice(&(q[1] as u16).to_le_bytes());
            }
            _ => {
                out[8 * slot..8 * slot + 4].copy_from_slice(&q[0].to_le_bytes());
                out[8 * slot + 4..8 * slot + 8].copy_from_slice(&q[1].to_le_bytes());
            }
        }
    }

    /// Reads the codes of node `slot` (one well-predicted branch on `bits`).
    #[inline(always)]
    pub fn get(&self, nodes: &[u8], slot: usize) -> [u32; 2] {
        match self.bits {
            4 => {
                let b = nodes[slot];
                [u32::from(b & 15), u32::from(b >> 4)]
            }
            8 => [u32::from(nodes[2 * slot]), u32::from(nodes[2 * slot + 1])],
            16 => {
                let s = &nodes[4 * slot..4 * slot + 4];
                [
                    u32::from(u16::from_le_bytes([s[0], s[1]])),
                    u32::from(u16::from_le_bytes([s[2], s[3]])),
                ]
            }
            _ => {
                let s = &nodes[8 * slot..8 * slot + 8];
                [
                    u32::from_le_bytes([s[0], s[1], s[2], s[3]]),
                    u32::from_le_bytes([s[4], s[5], s[6], s[7]]),
                ]
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    const TYPES: [VoxelType; 8] = [
        VoxelType::U8,
        VoxelType::I8,
        VoxelType::U16,
        VoxelType::I16,
        VoxelType::U32,
        VoxelType::I32,
        VoxelType::F32,
        VoxelType::F64,
    ];

    #[test]
    fn half_the_voxel_bits_and_packing_round_trips() {
        for t in TYPES {
            let q = Quantizer::for_type(t, -10.0, 300.0);
            assert_eq!(q.bits as usize, t.size_bytes() * 4);
            let mut buf = vec![0u8; 3 * q.node_bytes()];
            let codes = [[0, q.max_code()], [q.max_code(), 0], [1, q.max_code() / 2]];
            for (s, c) in codes.iter().enumerate() {
                q.put(&mut buf, s, *c);
            }
            for (s, c) in codes.iter().enumerate() {
                assert_eq!(q.get(&buf, s), *c, "{t:?}");
            }
        }
    }

    #[test]
    fn empty_ranges_and_outside_isovalues_never_pass() {
        let q = Quantizer::for_type(VoxelType::U8, 0.0, 255.0);
        let empty = q.encode(5.0, 4.0);
        assert_eq!(q.decode(empty), None);
        for iso in [0.0f32, 0.5, 100.0, 255.0] {
            let c = q.query(iso).unwrap();
            assert!(!c.passes(empty[0], empty[1]), "{iso}");
        }
        assert_eq!(q.query(-0.5), None);
        assert_eq!(q.query(255.5), None);
        assert_eq!(q.query(f32::NAN), None);
        // A constant volume: the single value passes.
        let k = Quantizer::for_type(VoxelType::F32, 7.0, 7.0);
        let r = k.encode(7.0, 7.0);
        assert!(k.query(7.0).unwrap().passes(r[0], r[1]));
    }

    fn type_and_ranges() -> impl Strategy<Value = (usize, f64, f64, f64, f64, f64)> {
        (
            0usize..8,
            -1e6f64..1e6,
            0.0f64..1e6,
            0.0f64..1.0,
            0.0f64..1.0,
            0.0f64..1.0,
        )
            .prop_map(|(t, lo, width, a, b, s)| {
                let (a, b) = if a <= b { (a, b) } else { (b, a) };
                let m = lo + a * width;
                let big_m = lo + b * width;
                let c = m + s * (big_m - m);
                (t, lo, lo + width, m, big_m, c)
            })
    }

    proptest! {
        /// The quantized range contains the true range, and every isovalue inside the true
        /// range passes the code test (no lost hits).
        #[test]
        fn quantized_range_contains_true_range((t, lo, hi, m, big_m, c) in type_and_ranges()) {
            let t = TYPES[t];
            let q = Quantizer::for_type(t, lo, hi);
            let codes = q.encode(m, big_m);
            let (qlo, qhi) = q.decode(codes).unwrap();
            prop_assert!(qlo <= m && qhi >= big_m, "{qlo} {qhi} vs {m} {big_m}");
            for iso in [m, big_m, c] {
                // An f32 isovalue rounded into [m, M] must pass.
                let iso32 = iso as f32;
                if f64::from(iso32) >= m && f64::from(iso32) <= big_m {
                    let query = q.query(iso32).unwrap();
                    prop_assert!(query.passes(codes[0], codes[1]), "{iso32} in [{m}, {big_m}]");
                }
            }
        }

        /// Integer data: exhaustive-ish check on u8 with random sub-ranges.
        #[test]
        fn u8_ranges_pass_their_integer_and_half_isovalues(a in 0u8..=255, b in 0u8..=255, lo in 0u8..=10, hi in 245u8..=255) {
            let (m, big_m) = (a.min(b).max(lo).min(hi), a.max(b).min(hi).max(lo));
            let q = Quantizer::for_type(VoxelType::U8, f64::from(lo), f64::from(hi));
            let codes = q.encode(f64::from(m), f64::from(big_m));
            let mut iso = f32::from(m);
            while iso <= f32::from(big_m) {
                prop_assert!(q.query(iso).unwrap().passes(codes[0], codes[1]));
                iso += 0.5;
            }
        }
    }
}
