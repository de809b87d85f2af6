//! Value statistics: range (NaN ignored), non-finite counts and histograms, in parallel.

use rayon::prelude::*;

use crate::volume::ValueMap;
use crate::voxel::Voxel;

/// Summary of a volume's values.
///
/// `min`/`max` cover the finite values only; NaN voxels are void and infinities are counted
/// separately, so one `inf` voxel does not make the range useless. `None` when no voxel is
/// finite.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct ValueStats {
    pub finite_range: Option<(f64, f64)>,
    pub nan_count: u64,
    pub pos_inf_count: u64,
    pub neg_inf_count: u64,
    pub count: u64,
}

const CHUNK: usize = 1 << 16;

impl ValueStats {
    fn empty() -> Self {
        Self {
            finite_range: None,
            nan_count: 0,
            pos_inf_count: 0,
            neg_inf_count: 0,
            count: 0,
        }
    }

    fn merge(a: Self, b: Self) -> Self {
        let finite_range = match (a.finite_range, b.finite_range) {
            (Some((a0, a1)), Some((b0, b1))) => Some((a0.min(b0), a1.max(b1))),
            (x, None) | (None, x) => x,
        };
        Self {
            finite_range,
            nan_count: a.nan_count + b.nan_count,
            pos_inf_count: a.pos_inf_count + b.pos_inf_count,
            neg_inf_count: a.neg_inf_count + b.neg_inf_count,
            count: a.count + b.count,
        }
    }

    fn of_chunk<T: Voxel>(chunk: &[T]) -> Self {
        let mut s = Self::empty();
        s.count = chunk.len() as u64;
        if !T::TYPE.is_float() {
            // Integer chunks: native compares, no classification needed.
            let mut lo = T::HIGHEST;
            let mut hi = T::LOWEST;
            for &v in chunk {
                if v < lo {
                    lo = v;
                }
                if v > hi {
                    hi = v;
                }
            }
            if !chunk.is_empty() {
                s.finite_range = Some((lo.to_f64(), hi.to_f64()));
            }
            return s;
        }
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for &v in chunk {
            let x = v.to_f64();
            if x.is_nan() {
                s.nan_count += 1;
            } else if x == f64::INFINITY {
                s.pos_inf_count += 1;
            } else if x == f64::NEG_INFINITY {
                s.neg_inf_count += 1;
            } else {
                lo = lo.min(x);
                hi = hi.max(x);
            }
        }
        if lo <= hi {
            s.finite_range = Some((lo, hi));
        }
        s
    }

    /// Scans `voxels` in parallel chunks.
    pub fn compute<T: Voxel>(voxels: &[T]) -> Self {
        voxels
            .par_chunks(CHUNK)
            .map(Self::of_chunk)
            .reduce(Self::empty, Self::merge)
    }
}

/// A histogram of finite values over `[lo, hi]` in `bins` equal bins (the last bin is closed).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Histogram {
    pub lo: f64,
    pub hi: f64,
    pub counts: Vec<u64>,
}

impl Histogram {
    /// Counts finite voxels in parallel; values outside `[lo, hi]` are ignored.
    pub fn compute<T: Voxel>(voxels: &[T], lo: f64, hi: f64, bins: usize) -> Self {
        Self::compute_mapped(voxels, ValueMap::IDENTITY, lo, hi, bins)
    }

    /// [`Self::compute`] over the physical values `map.to_physical(v)` of stored voxels.
    pub fn compute_mapped<T: Voxel>(
        voxels: &[T],
        map: ValueMap,
        lo: f64,
        hi: f64,
        bins: usize,
    ) -> Self {
        let bins = bins.max(1);
        let counts = match T::TYPE.size_bytes() {
            1 => by_stored_value::<T, u8>(voxels, map, lo, hi, bins),
            // Every 2-byte voxel type is an integer (u16, i16).
            2 => by_stored_value::<T, u16>(voxels, map, lo, hi, bins),
            _ => None,
        }
        .unwrap_or_else(|| {
            voxels
                .par_chunks(CHUNK)
                .map(|chunk| {
                    let mut c = vec![0u64; bins];
                    for &v in chunk {
                        if let Some(b) = bin_of(map.to_physical(v.to_f64()), lo, hi, bins) {
                            c[b] += 1;
                        }
                    }
                    c
                })
                .reduce(|| vec![0u64; bins], add_counts)
        });
        Self { lo, hi, counts }
    }
}

/// The bin of physical value `x` among `bins` equal bins over `[lo, hi]` (`hi` in the last);
/// `None` outside or not finite.
#[inline(always)]
fn bin_of(x: f64, lo: f64, hi: f64, bins: usize) -> Option<usize> {
    if !x.is_finite() || x < lo || x > hi {
        return None;
    }
    let width = hi - lo;
    let b = if width > 0.0 {
        ((x - lo) / width * bins as f64) as usize
    } else {
        0
    };
    Some(b.min(bins - 1))
}

// `reduce` hands both vectors over by value.
#[allow(clippy::needless_pass_by_value)]
fn add_counts(mut a: Vec<u64>, b: Vec<u64>) -> Vec<u64> {
    a.iter_mut().zip(&b).for_each(|(x, y)| *x += y);
    a
}

/// Histogram of 8- and 16-bit integer voxels: each voxel is counted under its stored bits
/// `R` (one increment), then each of the at most 65536 stored values is binned with
/// [`bin_of`] — the same counts as binning every voxel, without a conversion and division
/// per voxel (a 512×512×300 CT: 0.4 s less for `info` and the viewer's first histogram).
/// `None` when `T` and `R` differ in size.
fn by_stored_value<T: Voxel, R: bytemuck::Pod + Sync + Into<usize> + TryFrom<usize>>(
    voxels: &[T],
    map: ValueMap,
    lo: f64,
    hi: f64,
    bins: usize,
) -> Option<Vec<u64>> {
    let raw: &[R] = bytemuck::try_cast_slice(voxels).ok()?;
    let values = 1usize << (8 * size_of::<R>());
    let per_value = raw
        .par_chunks(CHUNK)
        .fold(
            || vec![0u64; values],
            |mut c, chunk| {
                for &r in chunk {
                    c[r.into()] += 1;
                }
                c
            },
        )
        .reduce(|| vec![0u64; values], add_counts);
    let mut counts = vec![0u64; bins];
    for (bits, &n) in per_value.iter().enumerate() {
        if n == 0 {
            continue;
        }
        // The voxel whose stored bits are `bits` (R and T have the same size).
        let v: T = bytemuck::try_cast(R::try_from(bits).ok()?).ok()?;
        if let Some(b) = bin_of(map.to_physical(v.to_f64()), lo, hi, bins) {
            counts[b] += n;
        }
    }
    Some(counts)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn range_ignores_nan_and_counts_infinities() {
        let mut v = vec![1.0f32; 200_000];
        v[7] = f32::NAN;
        v[100_001] = -3.0;
        v[150_000] = f32::INFINITY;
        v[3] = 9.5;
        let s = ValueStats::compute(&v);
        assert_eq!(s.finite_range, Some((-3.0, 9.5)));
        assert_eq!(
            (s.nan_count, s.pos_inf_count, s.neg_inf_count, s.count),
            (1, 1, 0, 200_000)
        );
        let all_nan = ValueStats::compute(&[f64::NAN, f64::NAN]);
        assert_eq!(all_nan.finite_range, None);
    }

    #[test]
    fn integer_range_matches_brute_force() {
        let v: Vec<i16> = (0..300_000i64)
            .map(|i| ((i * 7919) % 6007) as i16 - 3000)
            .collect();
        let s = ValueStats::compute(&v);
        let lo = *v.iter().min().unwrap() as f64;
        let hi = *v.iter().max().unwrap() as f64;
        assert_eq!(s.finite_range, Some((lo, hi)));
    }

    #[test]
    fn histogram_counts_every_finite_value_once() {
        let v: Vec<u8> = (0..=255).collect();
        let h = Histogram::compute(&v, 0.0, 255.0, 64);
        assert_eq!(h.counts.iter().sum::<u64>(), 256);
        assert_eq!(h.counts[0], 4);
        assert_eq!(h.counts[63], 4);
        let c = Histogram::compute(&[2.0f32, 2.0, f32::NAN], 2.0, 2.0, 8);
        assert_eq!(c.counts[0], 2);
    }

    /// The per-voxel binning, written out: the twin of the per-stored-value path.
    fn brute_force<T: Voxel>(v: &[T], map: ValueMap, lo: f64, hi: f64, bins: usize) -> Vec<u64> {
        let mut c = vec![0u64; bins];
        for &x in v {
            let p = map.to_physical(x.to_f64());
            if p.is_finite() && p >= lo && p <= hi {
                let b = ((p - lo) / (hi - lo) * bins as f64) as usize;
                c[b.min(bins - 1)] += 1;
            }
        }
        c
    }

    #[test]
    fn small_integer_histograms_equal_binning_every_voxel() {
        // Pseudo-random stored values over the whole type, a reversing map, a range that
        // cuts off both ends, more voxels than one chunk.
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            state
        };
        let i16s: Vec<i16> = (0..200_000).map(|_| next() as i16).collect();
        let u16s: Vec<u16> = (0..200_000).map(|_| next() as u16).collect();
        let i8s: Vec<i8> = (0..70_000).map(|_| next() as i8).collect();
        let u8s: Vec<u8> = (0..70_000).map(|_| next() as u8).collect();
        for map in [ValueMap::IDENTITY, ValueMap::new(-0.5, 1024.0).unwrap()] {
            for (lo, hi, bins) in [
                (-40_000.0, 40_000.0, 64),
                (-1000.0, 3000.0, 128),
                (7.0, 7.0, 3),
            ] {
                assert_eq!(
                    Histogram::compute_mapped(&i16s, map, lo, hi, bins).counts,
                    brute_force(&i16s, map, lo, hi, bins),
                    "i16 {map:?} {lo} {hi}"
                );
                assert_eq!(
                    Histogram::compute_mapped(&u16s, map, lo, hi, bins).counts,
                    brute_force(&u16s, map, lo, hi, bins)
                );
                assert_eq!(
                    Histogram::compute_mapped(&i8s, map, lo, hi, bins).counts,
                    brute_force(&i8s, map, lo, hi, bins)
                );
                assert_eq!(
                    Histogram::compute_mapped(&u8s, map, lo, hi, bins).counts,
                    brute_force(&u8s, map, lo, hi, bins)
                );
            }
        }
    }
}
