//! Packet leaves: the rays of a kd-tree packet (thesis seed 004 §7.2.1) tested against one
//! cell together, 8 lanes at a time (`wide::f32x8`, no `unsafe`).
//!
//! Every lane runs exactly the floating-point operations of the scalar path
//! ([`super::frame::slab`], [`super::CellSegment::local_f32`], the intersector), in the same
//! order and with the same NaN-ignoring `min`/`max`, so results are bit-identical to
//! [`super::intersect_prepared_cell`] per ray (tested below and by the packet == single-ray
//! proptests). Packets share each direction component's sign and have no zero component
//! ([`crate::kdtree::packet_compatible`]), so the slab's near/far choice is one branch per
//! axis for all lanes.

use glam::Vec3;
use wide::f32x8;

use super::{CellIntersector, CellSegment, IsoSet, LocalRay, PreparedCell};
use crate::render::Stats;
use crate::voxel::Voxel;

/// Lanes per packet.
pub const LANES: usize = 8;

/// The rays of a packet in traversal units, one lane per ray.
#[derive(Debug, Clone, Copy)]
pub struct RaysX8 {
    pub origin: [f32x8; 3],
    pub dir: [f32x8; 3],
    pub inv_dir: [f32x8; 3],
    /// `dir[a] > 0` for every lane (packets share direction signs).
    pub dir_pos: [bool; 3],
    /// Each ray's interval clipped to the volume (`t_lo`, `t_hi` of [`super::intersect_cell`]).
    pub t_lo: f32x8,
    pub t_hi: f32x8,
}

impl RaysX8 {
    /// Zero lanes, to be overwritten.
    pub(crate) const EMPTY: Self = Self {
        origin: [f32x8::ZERO; 3],
        dir: [f32x8::ZERO; 3],
        inv_dir: [f32x8::ZERO; 3],
        dir_pos: [false; 3],
        t_lo: f32x8::ZERO,
        t_hi: f32x8::ZERO,
    };
}

#[cfg(test)]
impl RaysX8 {
    /// Eight rays as lanes (tests), with direction signs from the first ray (the rays must
    /// share them, as a packet's do) and the intervals `t_lo..t_hi`.
    pub(crate) fn from_rays(rays: &[LocalRay; LANES], t_lo: f32x8, t_hi: f32x8) -> Self {
        let lanes = |f: &dyn Fn(&LocalRay) -> Vec3| -> [f32x8; 3] {
            [0, 1, 2].map(|a| f32x8::new(std::array::from_fn(|i| f(&rays[i])[a])))
        };
        Self {
            origin: lanes(&|r| r.origin),
            dir: lanes(&|r| r.dir),
            inv_dir: lanes(&|r| r.inv_dir),
            dir_pos: [0, 1, 2].map(|a| rays[0].dir[a] > 0.0),
            t_lo,
            t_hi,
        }
    }
}

/// The segments of a packet's rays inside one cell (`t_near`, `t_far` per lane).
#[derive(Debug, Clone, Copy)]
pub struct SegmentsX8<'a> {
    pub rays: &'a RaysX8,
    pub lo: Vec3,
    pub hi: Vec3,
    pub t_near: f32x8,
    pub t_far: f32x8,
}

impl RaysX8 {
    /// Lane `i` as the scalar [`LocalRay`] (its stored reciprocals, not recomputed).
    #[inline(always)]
    pub fn lane(&self, i: usize) -> LocalRay {
        let v =
            |x: &[f32x8; 3]| Vec3::new(x[0].as_array()[i], x[1].as_array()[i], x[2].as_array()[i]);
        LocalRay {
            origin: v(&self.origin),
            dir: v(&self.dir),
            inv_dir: v(&self.inv_dir),
        }
    }
}

impl SegmentsX8<'_> {
    /// Lane `i` as the scalar [`CellSegment`].
    #[inline(always)]
    pub fn lane(&self, i: usize) -> CellSegment {
        let (t_near, t_far) = (self.t_near.as_array()[i], self.t_far.as_array()[i]);
        CellSegment::of(&self.rays.lane(i), self.lo, self.hi, t_near, t_far)
    }

    /// [`CellSegment::local_f32`] for every lane: cell-local entry points and displacements.
    #[inline(always)]
    pub fn local_f32(&self) -> ([f32x8; 3], [f32x8; 3]) {
        let r = self.rays;
        let inv_w = (self.hi - self.lo).recip();
        let mut p0 = [f32x8::ZERO; 3];
        let mut dp = [f32x8::ZERO; 3];
        for a in 0..3 {
            let lo = f32x8::splat(self.lo[a]);
            let hi = f32x8::splat(self.hi[a]);
            let w = f32x8::splat(inv_w[a]);
            let rel = r.origin[a] - lo;
            let q0 = (rel + r.dir[a] * self.t_near) * w;
            let q1 = (rel + r.dir[a] * self.t_far) * w;
            let t_lo = (lo - r.origin[a]) * r.inv_dir[a];
            let t_hi = (hi - r.origin[a]) * r.inv_dir[a];
            let (t_in, t_out, face_in, face_out) = if r.dir_pos[a] {
                (t_lo, t_hi, 0.0, 1.0)
            } else {
                (t_hi, t_lo, 1.0, 0.0)
            };
            let q0 = t_in.simd_eq(self.t_near).select(f32x8::splat(face_in), q0);
            let q1 = t_out.simd_eq(self.t_far).select(f32x8::splat(face_out), q1);
            p0[a] = q0;
            dp[a] = q1 - q0;
        }
        (p0, dp)
    }
}

/// First roots `s ∈ [0, 1]` for the lanes in a bit mask (bit `i` = lane `i`).
#[derive(Debug, Clone, Copy, Default)]
pub struct RootsX8 {
    pub s: [f64; LANES],
    pub mask: u32,
    /// Lanes of `mask` whose root is certified the only one on their segment (the exact
    /// intersector's cubic is monotone there): a search past it finds nothing more.
    pub sole: u32,
}

/// Each lane's nearest hit in one cell: ray parameter and surface for the lanes in `mask`.
#[derive(Debug, Clone, Copy)]
pub struct HitsX8 {
    pub t: [f32; LANES],
    pub surface: [u32; LANES],
    pub mask: u32,
    /// Lanes of `mask` whose hit is the only crossing of any active isovalue on their
    /// segment through the cell ([`RootsX8::sole`]): going on past it, they need not test
    /// the cell again.
    pub sole: u32,
    /// Lanes whose hit in this cell is certain but left for later (see `may_defer`), the
    /// cell's isovalue and surface, and their segments through the cell (set only when some
    /// lane is deferred).
    pub deferred: u32,
    pub deferred_iso: (f32, u32),
    pub t_near: [f32; LANES],
    pub t_far: [f32; LANES],
}

/// [`super::intersect_prepared_cell`] for the lanes of `active` (no leaf is counted here).
/// In a cell whose range holds one of the isovalues only, of a surface in the bit set
/// `defers` (surfaces whose hit ends the lane), lanes of `may_defer` that certainly cross
/// the surface may be returned as `deferred` instead of with a hit
/// ([`CellIntersector::first_roots_x8_deferring`]).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub fn intersect_prepared_cell_x8<T: Voxel, C: CellIntersector, S: Stats>(
    pc: &PreparedCell<T>,
    rays: &RaysX8,
    active: u32,
    may_defer: u32,
    defers: u64,
    isos: &IsoSet<T>,
    intersector: C,
    stats: &mut S,
) -> HitsX8 {
    let mut hits = HitsX8 {
        t: [0.0; LANES],
        surface: [0; LANES],
        mask: 0,
        sole: 0,
        deferred: 0,
        deferred_iso: (0.0, 0),
        t_near: [0.0; LANES],
        t_far: [0.0; LANES],
    };
    let (lo, hi) = (pc.lo, pc.hi);
    // frame::slab, lane-wise (no zero direction components in a packet).
    let (mut t0, mut t1) = (rays.t_lo, rays.t_hi);
    for a in 0..3 {
        let ta = (f32x8::splat(lo[a]) - rays.origin[a]) * rays.inv_dir[a];
        let tb = (f32x8::splat(hi[a]) - rays.origin[a]) * rays.inv_dir[a];
        let (n, f) = if rays.dir_pos[a] { (ta, tb) } else { (tb, ta) };
        t0 = t0.max(n);
        t1 = t1.min(f);
    }
    let mask = active & t0.simd_le(t1).to_bitmask();
    if mask == 0 || !(hi.cmpgt(lo).all()) {
        return hits;
    }
    let seg = SegmentsX8 {
        rays,
        lo,
        hi,
        t_near: t0,
        t_far: t1,
    };
    let (tn, tf) = (t0.to_array(), t1.to_array());
    // Deferring needs the cell's only isovalue: with more, a lane's hit is the nearest of
    // theirs.
    // (A set of one: the cell was loaded because its range holds it.)
    let defer_iso = if may_defer & mask != 0 {
        isos.single()
            .or_else(|| isos.only_in(pc.min, pc.max))
            .filter(|&(_, surface)| surface < 64 && defers >> surface & 1 == 1)
    } else {
        None
    };
    let may_defer = if defer_iso.is_some() {
        may_defer & mask
    } else {
        0
    };
    // Lanes with a root of more than one isovalue: not sole, whichever is nearer.
    let mut several = 0u32;
    isos.for_each_in(pc.min, pc.max, |iso, surface| {
        for _ in 0..mask.count_ones() {
            stats.intersection();
        }
        let (roots, deferred) =
            intersector.first_roots_x8_deferring(&pc.corners, iso, &seg, mask, may_defer);
        hits.deferred |= deferred;
        several |= hits.mask & roots.mask;
        let mut bits = roots.mask;
        while bits != 0 {
            let i = bits.trailing_zeros() as usize;
            bits &= bits - 1;
            let t = root_t(tn[i], tf[i], roots.s[i]);
            if hits.mask & (1 << i) == 0 || t < hits.t[i] {
                hits.t[i] = t;
                hits.surface[i] = surface;
                hits.mask |= 1 << i;
                hits.sole = hits.sole & !(1 << i) | roots.sole & (1 << i);
            }
        }
    });
    hits.sole &= !several;
    if hits.deferred != 0
        && let Some(iso) = defer_iso
    {
        (hits.t_near, hits.t_far) = (tn, tf);
        hits.deferred_iso = iso;
    }
    hits
}

/// A lane's hit `t` from its root `s` on its segment `[t_near, t_far]` through a cell:
/// [`CellSegment::t_at`], then the clamp of [`super::intersect_prepared_cell`].
#[inline(always)]
pub(crate) fn root_t(t_near: f32, t_far: f32, s: f64) -> f32 {
    let (n, f) = (f64::from(t_near), f64::from(t_far));
    ((n + s * (f - n)) as f32).clamp(t_near, t_far)
}

/// The default [`CellIntersector::first_roots_x8`]: the scalar method per lane.
#[inline(always)]
pub fn first_roots_by_lane<T: Voxel, C: CellIntersector>(
    c: &C,
    corners: &[T; 8],
    iso: f32,
    seg: &SegmentsX8<'_>,
    mask: u32,
) -> RootsX8 {
    let mut r = RootsX8::default();
    let mut bits = mask;
    while bits != 0 {
        let i = bits.trailing_zeros() as usize;
        bits &= bits - 1;
        if let Some(s) = c.first_root(corners, iso, &seg.lane(i)) {
            r.s[i] = s;
            r.mask |= 1 << i;
        }
    }
    r
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::intersect::{Intersector, LocalRay, intersect_prepared_cell};
    use crate::math::rng::Rng;
    use crate::render::CountStats;

    /// Outcome counts of one comparison run (to check that the cases were exercised).
    #[derive(Default)]
    struct Seen {
        lanes: usize,
        hits: usize,
        tests: usize,
    }

    /// One random cell and packet: the lane-wise test equals the scalar test per lane
    /// (bit-identical `t`, same surface, same intersection count).
    fn compare_once<T: Voxel, C: CellIntersector>(
        rng: &mut Rng,
        c: C,
        corner: impl Fn(&mut Rng) -> T,
        isovalues: &[f32],
        seen: &mut Seen,
    ) {
        let lo = Vec3::new(
            rng.range_f32(-5.0, 5.0),
            rng.range_f32(-5.0, 5.0),
            rng.range_f32(-5.0, 5.0),
        );
        let w = Vec3::new(
            rng.range_f32(0.2, 2.0),
            rng.range_f32(0.2, 2.0),
            rng.range_f32(0.2, 2.0),
        );
        let hi = if rng.below(50) == 0 { lo } else { lo + w };
        let corners: [T; 8] = std::array::from_fn(|_| corner(rng));
        let isos = IsoSet::new(isovalues);
        let Some((min, max)) = super::super::corner_range(&corners) else {
            return;
        };
        let pc = PreparedCell {
            corners,
            min,
            max,
            lo,
            hi,
            cell: [1, 2, 3],
        };
        // A pinhole-like packet: one eye (sometimes per-lane origins), directions with one
        // sign per axis and no zero component, aimed near the cell.
        let eye = lo
            + w * Vec3::new(
                rng.range_f32(-3.0, 4.0),
                rng.range_f32(-3.0, 4.0),
                rng.range_f32(-3.0, 4.0),
            );
        let sign = Vec3::new(
            if rng.below(2) == 0 { 1.0 } else { -1.0 },
            if rng.below(2) == 0 { 1.0 } else { -1.0 },
            if rng.below(2) == 0 { 1.0 } else { -1.0 },
        );
        let shared_origin = !rng.below(3) == 0;
        let rays: [LocalRay; LANES] = std::array::from_fn(|_| {
            let o = if shared_origin {
                eye
            } else {
                eye + Vec3::new(
                    rng.range_f32(-0.3, 0.3),
                    rng.range_f32(-0.3, 0.3),
                    rng.range_f32(-0.3, 0.3),
                )
            };
            let target = (lo + hi) * 0.5
                + w * Vec3::new(
                    rng.range_f32(-0.8, 0.8),
                    rng.range_f32(-0.8, 0.8),
                    rng.range_f32(-0.8, 0.8),
                );
            let d = (target - o).abs().max(Vec3::splat(1e-3)) * sign;
            LocalRay::new(o, d * rng.range_f32(0.5, 3.0))
        });
        let t_lo: [f32; LANES] = std::array::from_fn(|_| {
            if rng.below(4) == 0 {
                rng.range_f32(0.0, 2.0)
            } else {
                0.0
            }
        });
        let t_hi: [f32; LANES] = std::array::from_fn(|_| {
            if rng.below(4) == 0 {
                rng.range_f32(0.0, 3.0)
            } else {
                f32::INFINITY
            }
        });
        let active = rng.next_u32() & 0xff | 1;
        let packet = RaysX8::from_rays(&rays, f32x8::new(t_lo), f32x8::new(t_hi));
        let mut st_x8 = CountStats::default();
        let got = intersect_prepared_cell_x8(&pc, &packet, active, 0, 0, &isos, c, &mut st_x8);
        let mut st_1 = CountStats::default();
        for i in 0..LANES {
            let want = if active & (1 << i) != 0 {
                seen.lanes += 1;
                intersect_prepared_cell(&pc, &rays[i], t_lo[i], t_hi[i], &isos, c, &mut st_1)
            } else {
                None
            };
            let got_i = (got.mask & (1 << i) != 0).then(|| (got.t[i].to_bits(), got.surface[i]));
            assert_eq!(
                got_i,
                want.map(|h| (h.t.to_bits(), h.surface)),
                "lane {i}: {:?} in {lo:?}..{hi:?}, corners {corners:?}, t {}..{}",
                rays[i],
                t_lo[i],
                t_hi[i]
            );
            seen.hits += usize::from(want.is_some());
        }
        let (n_x8, n_1) = (
            st_x8.counts().intersection_tests,
            st_1.counts().intersection_tests,
        );
        assert_eq!(n_x8, n_1, "intersection tests counted");
        seen.tests += n_1 as usize;
    }

    #[test]
    fn lanes_equal_scalar_cell_tests_for_every_intersector() {
        for which in Intersector::ALL {
            let mut rng = Rng::new(7 + which.name().len() as u64);
            let mut seen = Seen::default();
            for n in 0..3000 {
                let isos: &[f32] = match n % 3 {
                    0 => &[0.0],
                    1 => &[0.3, -0.2],
                    _ => &[0.1, 0.1, 0.7],
                };
                crate::dispatch_intersector!(which, c => compare_once(
                    &mut rng,
                    c,
                    |r: &mut Rng| r.range_f32(-1.0, 1.0),
                    isos,
                    &mut seen,
                ));
            }
            // Integer voxels at integer isovalues: corners equal to the isovalue, constant
            // cells (the whole segment on the surface).
            for n in 0..2000 {
                let spread = if n % 7 == 0 { 0 } else { 3 };
                crate::dispatch_intersector!(which, c => compare_once(
                    &mut rng,
                    c,
                    |r: &mut Rng| 100 + r.below(2 * spread + 1) as i16 - spread as i16,
                    &[100.0, 101.5],
                    &mut seen,
                ));
            }
            assert!(seen.lanes > 10_000, "{which}: {} lanes", seen.lanes);
            assert!(seen.hits > 500, "{which}: {} hits", seen.hits);
            assert!(
                seen.tests > 2 * seen.hits,
                "{which}: {} tests, {} hits",
                seen.tests,
                seen.hits
            );
        }
    }

    #[test]
    fn lane_segments_equal_scalar_segments() {
        let mut rng = Rng::new(99);
        for _ in 0..2000 {
            let lo = Vec3::new(
                rng.range_f32(-9.0, 9.0),
                rng.range_f32(-9.0, 9.0),
                rng.range_f32(-9.0, 9.0),
            );
            let hi = lo
                + Vec3::new(
                    rng.range_f32(0.1, 3.0),
                    rng.range_f32(0.1, 3.0),
                    rng.range_f32(0.1, 3.0),
                );
            let sign = [0, 1, 2].map(|_| if rng.below(2) == 0 { 1.0 } else { -1.0 });
            let rays: [LocalRay; LANES] = std::array::from_fn(|_| {
                let o = Vec3::new(
                    rng.range_f32(-20.0, 20.0),
                    rng.range_f32(-20.0, 20.0),
                    rng.range_f32(-20.0, 20.0),
                );
                let d = Vec3::from(sign.map(|s| s * rng.range_f32(0.01, 2.0)));
                LocalRay::new(o, d)
            });
            let packet = RaysX8::from_rays(&rays, f32x8::ZERO, f32x8::splat(f32::INFINITY));
            // Segment ends from the slab (so the face snapping is exercised) or arbitrary.
            let ends: [(f32, f32); LANES] = std::array::from_fn(|i| {
                crate::intersect::frame::slab(&rays[i], lo, hi, -50.0, 50.0)
                    .unwrap_or((rng.range_f32(-5.0, 0.0), rng.range_f32(0.0, 5.0)))
            });
            let seg = SegmentsX8 {
                rays: &packet,
                lo,
                hi,
                t_near: f32x8::new(ends.map(|e| e.0)),
                t_far: f32x8::new(ends.map(|e| e.1)),
            };
            let (p0, dp) = seg.local_f32();
            for (i, ray) in rays.iter().enumerate() {
                let s = seg.lane(i);
                assert_eq!(s.origin, ray.origin);
                let (q0, dq) = s.local_f32();
                for a in 0..3 {
                    assert_eq!(
                        p0[a].as_array()[i].to_bits(),
                        q0[a].to_bits(),
                        "p0 lane {i} axis {a}"
                    );
                    assert_eq!(
                        dp[a].as_array()[i].to_bits(),
                        dq[a].to_bits(),
                        "dp lane {i} axis {a}"
                    );
                }
            }
        }
    }
}
