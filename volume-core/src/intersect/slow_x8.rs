//! The exact intersector's `f64` slow path for several lanes of a packet at once.
//!
//! A packet's rays that meet the surface in one cell all leave the certified `f32` filter of
//! [`super::methods::Exact`] together and each runs the `f64` slow path: the exact segment
//! ([`super::CellSegment::local_f64`]), its cubic, and safeguarded Newton steps to a quarter of an
//! `f32` ulp of the hit's `t`. One lane at a time that path is a chain of dependent divisions
//! and branches (about a sixth of an MRI frame's time); here the lanes run it side by side in
//! `f64x8`, each lane executing exactly the scalar operations in the same order (a branch of
//! the scalar code becomes a select, a loop's exit a lane mask), so every root is
//! bit-identical to [`super::methods::exact_slow`]'s (tested below and by the packet ==
//! single-ray tests).
//!
//! Even a lone lane takes this path: without the scalar code's branches it ran faster
//! (docs/benchmarks.md). Lanes whose cubic is not certified monotone on the segment (extrema
//! to isolate first, [`super::methods::first_root_f64`]) take the scalar path: about one call
//! in twenty on the MNI frame, and their branches differ by lane.
//!
//! The lanes need not share a cell ([`exact_slow_jobs`]): a packet leaves the roots of the
//! certain crossings that end its lanes for after its walk and refines them 8 at a time,
//! whatever cells they lie in ([`crate::kdtree`]'s `Deferred`), instead of the two or three
//! lanes that meet the surface in one cell. Both entry points fill the same lanes
//! (`LaneCells`) and run the same steps.

use wide::{f32x8, f64x8};

use super::methods::{EXACT_ITERATIONS, corner_diffs_f64, cubic_of, eval_of, exact_slow};
use super::{CellSegment, RootsX8, SegmentsX8};
use crate::math::lane_indices;
use crate::voxel::Voxel;

#[inline(always)]
fn wide64(x: f32x8) -> f64x8 {
    f64x8::new(x.to_array().map(f64::from))
}

#[inline(always)]
fn bits(m: f64x8) -> u32 {
    m.to_bitmask()
}

/// [`exact_slow`] for the lanes in `lanes`: each lane's root (its `s` and mask bit) exactly
/// as the scalar path finds it.
pub(crate) fn exact_slow_x8<T: Voxel>(
    corners: &[T; 8],
    iso: f32,
    seg: &SegmentsX8<'_>,
    lanes: u32,
) -> RootsX8 {
    let Some(g) = corner_diffs_f64(corners, iso) else {
        // The cell equals the isovalue: every segment starts on the surface.
        return RootsX8 {
            s: [0.0; 8],
            mask: lanes,
            sole: 0,
        };
    };
    let rays = seg.rays;
    let cells = LaneCells {
        origin: rays.origin,
        dir: rays.dir,
        inv_dir: rays.inv_dir,
        dir_pos: rays.dir_pos,
        lo: [0, 1, 2].map(|a| f32x8::splat(seg.lo[a])),
        hi: [0, 1, 2].map(|a| f32x8::splat(seg.hi[a])),
        t_near: seg.t_near,
        t_far: seg.t_far,
        g: g.map(f64x8::splat),
        flat: 0,
    };
    slow_lanes(&cells, lanes, |i| exact_slow(corners, iso, &seg.lane(i)))
}

/// Up to 8 lanes of work for [`exact_slow_jobs`], one isovalue for all: lane `i` is a ray's
/// segment through its own cell, with that cell's corners, as [`exact_slow`] takes them.
/// Stored as lanes (filled one lane at a time, read 8 at a time).
#[derive(Debug, Clone, Copy)]
pub(crate) struct SlowJobs<T> {
    n: usize,
    iso: f32,
    corners: [[T; 8]; 8],
    /// Per axis `origin`, `dir`, `inv_dir`, `lo`, `hi` (rows `0..15`), then `t_near`, `t_far`.
    v: [[f32; 8]; 17],
}

impl<T: Voxel> SlowJobs<T> {
    pub(crate) fn new(iso: f32) -> Self {
        Self {
            n: 0,
            iso,
            corners: [[T::default(); 8]; 8],
            v: [[0.0; 8]; 17],
        }
    }

    pub(crate) fn len(&self) -> usize {
        self.n
    }

    /// Adds a lane (at most 8).
    #[inline(always)]
    pub(crate) fn push(&mut self, corners: [T; 8], seg: &CellSegment) {
        let i = self.n;
        self.corners[i] = corners;
        for a in 0..3 {
            self.v[a][i] = seg.origin[a];
            self.v[3 + a][i] = seg.dir[a];
            self.v[6 + a][i] = seg.inv_dir[a];
            self.v[9 + a][i] = seg.lo[a];
            self.v[12 + a][i] = seg.hi[a];
        }
        self.v[15][i] = seg.t_near;
        self.v[16][i] = seg.t_far;
        self.n += 1;
    }

    /// Lane `i` as the scalar path's segment.
    fn segment(&self, i: usize) -> CellSegment {
        let v3 =
            |row: usize| glam::Vec3::new(self.v[row][i], self.v[row + 1][i], self.v[row + 2][i]);
        CellSegment {
            origin: v3(0),
            dir: v3(3),
            inv_dir: v3(6),
            lo: v3(9),
            hi: v3(12),
            t_near: self.v[15][i],
            t_far: self.v[16][i],
        }
    }
}

/// [`exact_slow`] for the lanes of `jobs` side by side, each in its own cell (their rays
/// share direction signs, as a packet's do): bit-identical to the scalar path per lane. A
/// packet's hits are gathered from the cells they lie in and refined together, instead of
/// one cell's few lanes at a time.
pub(crate) fn exact_slow_jobs<T: Voxel>(jobs: &SlowJobs<T>) -> RootsX8 {
    debug_assert!(jobs.n > 0 && jobs.n <= 8);
    let n = jobs.n.min(8);
    let lanes = (1u32 << n) - 1;
    // Lanes past `n` hold zeros: whatever they compute is masked out.
    let v = &jobs.v;
    let mut g = [[0.0f64; 8]; 8];
    let mut flat = 0u32;
    for (i, corners) in jobs.corners.iter().enumerate().take(n) {
        match corner_diffs_f64(corners, jobs.iso) {
            Some(d) => {
                for (gc, dc) in g.iter_mut().zip(d) {
                    gc[i] = dc;
                }
            }
            None => flat |= 1 << i,
        }
    }
    let axes = |first: usize| [0, 1, 2].map(|a| f32x8::new(v[first + a]));
    let cells = LaneCells {
        origin: axes(0),
        dir: axes(3),
        inv_dir: axes(6),
        dir_pos: [0, 1, 2].map(|a| v[3 + a][0] > 0.0),
        lo: axes(9),
        hi: axes(12),
        t_near: f32x8::new(v[15]),
        t_far: f32x8::new(v[16]),
        g: g.map(f64x8::new),
        flat,
    };
    slow_lanes(&cells, lanes, |i| {
        exact_slow(&jobs.corners[i], jobs.iso, &jobs.segment(i))
    })
}

/// Segments through cells, one lane each (a packet's segments through one cell, or jobs
/// gathered from several): what the slow path reads of them.
struct LaneCells {
    origin: [f32x8; 3],
    dir: [f32x8; 3],
    inv_dir: [f32x8; 3],
    dir_pos: [bool; 3],
    lo: [f32x8; 3],
    hi: [f32x8; 3],
    t_near: f32x8,
    t_far: f32x8,
    /// Each lane's cell corner differences ([`corner_diffs_f64`]), unless its bit is in `flat`.
    g: [f64x8; 8],
    /// Lanes whose cell equals the isovalue: the segment starts on the surface.
    flat: u32,
}

/// The slow path of the lanes in `lanes` side by side; `scalar(i)` is [`exact_slow`] for
/// lane `i`, run for the lanes whose branches differ (see the module docs).
#[inline(always)]
fn slow_lanes(c: &LaneCells, lanes: u32, scalar: impl Fn(usize) -> Option<f64>) -> RootsX8 {
    let flat = lanes & c.flat;
    let lanes = lanes & !flat;
    // CellSegment::local_f64, lane-wise. A packet has no zero direction component
    // (`crate::kdtree::packet_compatible`); lanes that do take the scalar path.
    let mut scalar_lanes = 0u32;
    let (mut in32, mut out32) = (f32x8::splat(f32::NEG_INFINITY), f32x8::splat(f32::INFINITY));
    let (mut in64, mut out64) = (f64x8::splat(f64::NEG_INFINITY), f64x8::splat(f64::INFINITY));
    let mut o64 = [f64x8::ZERO; 3];
    let mut d64 = [f64x8::ZERO; 3];
    let (mut lo64, mut w64) = ([f64x8::ZERO; 3], [f64x8::ONE; 3]);
    let mut unit = true;
    for a in 0..3 {
        scalar_lanes |= c.dir[a].simd_eq(f32x8::ZERO).to_bitmask();
        let ta = (c.lo[a] - c.origin[a]) * c.inv_dir[a];
        let tb = (c.hi[a] - c.origin[a]) * c.inv_dir[a];
        let (o, d) = (wide64(c.origin[a]), wide64(c.dir[a]));
        let (lo, hi) = (wide64(c.lo[a]), wide64(c.hi[a]));
        let ua = (lo - o) / d;
        let ub = (hi - o) / d;
        let (n, f, n64, f64_) = if c.dir_pos[a] {
            (ta, tb, ua, ub)
        } else {
            (tb, ta, ub, ua)
        };
        in32 = in32.max(n);
        out32 = out32.min(f);
        in64 = in64.max(n64);
        out64 = out64.min(f64_);
        o64[a] = o;
        d64[a] = d;
        lo64[a] = lo;
        w64[a] = hi - lo;
        unit &= w64[a].simd_eq(f64x8::ONE).to_bitmask() & lanes == lanes;
    }
    let (tn, tf) = (wide64(c.t_near), wide64(c.t_far));
    // (Equal in f64 exactly when equal in f32: the widening is exact.)
    let t0 = tn.simd_eq(wide64(in32)).select(in64, tn);
    let t1 = tf.simd_eq(wide64(out32)).select(out64, tf);
    let t1 = t1.max(t0);
    let mut p0 = [f64x8::ZERO; 3];
    let mut dp = [f64x8::ZERO; 3];
    for a in 0..3 {
        p0[a] = (o64[a] - lo64[a]) + d64[a] * t0;
        dp[a] = d64[a] * (t1 - t0);
        // Unit-wide cells (a uniform axis' in traversal units): `x / 1` is `x`, so the
        // divisions (6 of the about 19 of a call) are left out when every asked lane's is.
        if !unit {
            p0[a] /= w64[a];
            dp[a] /= w64[a];
        }
    }
    let k = cubic_of(&c.g, p0, dp);

    // exact_slow's tolerance on s.
    let span = t1 - t0;
    let s_tol = (f64x8::splat(0.25 * f64::from(f32::EPSILON)) * t0.abs().max(t1.abs()) / span)
        .max(f64x8::splat(f64::EPSILON));
    let s_tol = span.simd_gt(f64x8::ZERO).select(s_tol, f64x8::ONE);

    // first_root_f64 on the lanes whose cubic is certified monotone (monotone_on_unit).
    let f0 = k[3];
    let (b0, b1, b2) = (
        k[2],
        k[2] + k[1],
        f64x8::splat(3.0) * k[0] + f64x8::splat(2.0) * k[1] + k[2],
    );
    let slack = f64x8::splat(16.0 * f64::EPSILON) * (k[0].abs() + k[1].abs() + k[2].abs());
    let neg_slack = -slack;
    let monotone = (b0.simd_gt(slack) & b1.simd_gt(slack) & b2.simd_gt(slack))
        | (b0.simd_lt(neg_slack) & b1.simd_lt(neg_slack) & b2.simd_lt(neg_slack));
    let (zero, one) = (f64x8::ZERO, f64x8::ONE);
    let start_zero = f0.simd_eq(zero);
    let at_start = lanes & !scalar_lanes & bits(start_zero);
    let vector = lanes & !scalar_lanes & !at_start & bits(monotone);
    scalar_lanes |= lanes & !at_start & !vector;
    let f1 = eval_of(&k, one);
    let end_zero = f1.simd_eq(zero);
    let at_end = vector & bits(end_zero);
    let crossing = vector & !at_end & bits(f1.simd_gt(zero) ^ f0.simd_gt(zero));
    let mut s = zero;
    if crossing != 0 {
        s = refine_newton_x8(&k, f0, f1, s_tol, mask_of(crossing));
    }
    let s = start_zero.select(zero, end_zero.select(one, s));
    // CubicF64::s_on_f32_segment: the root as a position on the f32 segment.
    let t = t0 + s * (t1 - t0);
    let mut r = RootsX8 {
        s: tf.simd_gt(tn).select((t - tn) / (tf - tn), zero).to_array(),
        mask: at_start | at_end | crossing,
        // A strictly monotone cubic crosses zero once at most on the segment.
        sole: (at_start | at_end | crossing) & bits(monotone),
    };
    for i in lane_indices(scalar_lanes & lanes) {
        if let Some(s) = scalar(i) {
            r.s[i] = s;
            r.mask |= 1 << i;
        }
    }
    // Cells equal to the isovalue: every segment starts on the surface.
    for i in lane_indices(flat) {
        r.s[i] = 0.0;
    }
    r.mask |= flat;
    r
}

/// [`super::methods::refine_newton_f64`] on the bracket `[0, 1]` (`f(0) = f0`,
/// `f(1) = f1` of opposite signs) for the lanes of the mask `lanes`, each lane the scalar
/// steps; other lanes return garbage.
#[inline(always)]
fn refine_newton_x8(k: &[f64x8; 4], f0: f64x8, f1: f64x8, s_tol: f64x8, lanes: f64x8) -> f64x8 {
    let zero = f64x8::ZERO;
    let half = f64x8::splat(0.5);
    let lo_pos = f0.simd_gt(zero);
    let (mut lo, mut f_lo, mut hi, mut f_hi) = (zero, f0, f64x8::ONE, f1);
    let d = [f64x8::splat(3.0) * k[0], f64x8::splat(2.0) * k[1], k[2]];
    let half_tol = half * s_tol;
    let mut s = lo + (hi - lo) * (f_lo / (f_lo - f_hi));
    let (mut step_old, mut step_older) = (hi - lo, hi - lo);
    // Lanes still stepping; lanes that evaluated an exact zero, and where.
    let mut live = lanes;
    let (mut exact, mut s_exact) = (zero, zero);
    for _ in 0..EXACT_ITERATIONS {
        live &= !(hi - lo).simd_le(s_tol);
        if live.to_bitmask() == 0 {
            break;
        }
        let inside = s.simd_gt(lo) & s.simd_lt(hi);
        s = inside.select(s, half * (lo + hi));
        let fs = eval_of(k, s);
        let z = live & fs.simd_eq(zero);
        exact |= z;
        s_exact = z.select(s, s_exact);
        live &= !z;
        // The evaluated point replaces the bracket end of its sign.
        let set_lo = live & !(fs.simd_gt(zero) ^ lo_pos);
        let set_hi = live & !set_lo;
        lo = set_lo.select(s, lo);
        f_lo = set_lo.select(fs, f_lo);
        hi = set_hi.select(s, hi);
        f_hi = set_hi.select(fs, f_hi);
        let step = -fs / ((d[0] * s + d[1]) * s + d[2]);
        let bisect = step.is_nan() | step.abs().simd_gt(half * step_older);
        let short = step.abs().simd_lt(half_tol);
        // half_tol.copysign(step) (half_tol is not negative).
        let stretched = half_tol | (step & f64x8::splat(-0.0));
        let step = bisect.select(half * (lo + hi) - s, short.select(stretched, step));
        (step_older, step_old) = (step_old, step.abs());
        s += step;
    }
    let s_end = lo + (hi - lo) * (f_lo / (f_lo - f_hi));
    // f64::clamp(lo, hi), NaN staying NaN.
    let s_end = s_end
        .simd_lt(lo)
        .select(lo, s_end.simd_gt(hi).select(hi, s_end));
    exact.select(s_exact, s_end)
}

/// The lane mask (all bits set in lane `i` when bit `i` is) of a bit mask.
#[inline(always)]
fn mask_of(bits: u32) -> f64x8 {
    f64x8::new(std::array::from_fn(|i| {
        if bits & (1 << i) != 0 {
            f64::from_bits(u64::MAX)
        } else {
            0.0
        }
    }))
}

#[cfg(test)]
mod tests {
    use glam::Vec3;

    use super::*;
    use crate::intersect::frame::slab;
    use crate::intersect::{LocalRay, RaysX8};
    use crate::math::rng::Rng;

    /// Random packets through one cell: every lane's root from the lanes side by side equals
    /// the scalar slow path's, bit for bit (or both find none).
    fn lanes_equal_scalar<T: Voxel>(
        rng: &mut Rng,
        corner: impl Fn(&mut Rng) -> T,
        iso: f32,
        seen: &mut [usize; 4],
    ) {
        // Half the cells a uniform axis' (integer corners, unit width: the branch without
        // divisions by the width), half of random size.
        let (lo, hi) = if rng.below(2) == 0 {
            let lo = rng.vec3(-40.0, 40.0).floor();
            (lo, lo + Vec3::ONE)
        } else {
            let lo = rng.vec3(-40.0, 40.0);
            (lo, lo + rng.vec3(0.3, 2.0))
        };
        let corners: [T; 8] = std::array::from_fn(|_| corner(rng));
        let sign = [0, 1, 2].map(|_| if rng.below(2) == 0 { 1.0f32 } else { -1.0 });
        let far = rng.range_f32(1.0, 300.0);
        let eye = (lo + hi) * 0.5 - Vec3::from(sign) * far;
        let rays: [LocalRay; 8] = std::array::from_fn(|_| {
            let target = lo + (hi - lo) * rng.vec3(0.0, 1.0);
            let d = (target - eye).abs().max(Vec3::splat(1e-4)) * Vec3::from(sign);
            LocalRay::new(eye, d * rng.range_f32(0.2, 5.0))
        });
        let packet = RaysX8::from_rays(&rays, f32x8::ZERO, f32x8::splat(f32::INFINITY));
        // Ends from the slab test (faces, the usual case) or cut inside the cell (a ray
        // that starts or stops there: peeled, shadow and clipped rays).
        let ends: [(f32, f32); 8] = std::array::from_fn(|i| {
            let (n, f) = slab(&rays[i], lo, hi, 0.0, f32::INFINITY).unwrap_or((1.0, 1.0));
            let cut = |t: f32| n + (f - n) * t;
            match rng.below(4) {
                0 => (cut(rng.unit_f32()), f),
                1 => (n, cut(rng.unit_f32())),
                _ => (n, f),
            }
        });
        let seg = SegmentsX8 {
            rays: &packet,
            lo,
            hi,
            t_near: f32x8::new(ends.map(|e| e.0)),
            t_far: f32x8::new(ends.map(|e| e.1)),
        };
        let lanes_on = rng.next_u32() & 0xff | 3;
        let got = exact_slow_x8(&corners, iso, &seg, lanes_on);
        assert_eq!(got.mask & !lanes_on, 0, "roots only on the lanes asked for");
        for i in lane_indices(lanes_on) {
            let want = exact_slow(&corners, iso, &seg.lane(i));
            let got_i = (got.mask & (1 << i) != 0).then(|| got.s[i]);
            assert_eq!(
                got_i.map(f64::to_bits),
                want.map(f64::to_bits),
                "lane {i}: {got_i:?} vs {want:?}, corners {corners:?}, iso {iso}, segment {:?}",
                seg.lane(i)
            );
            seen[usize::from(want.is_some())] += 1;
            seen[2] += usize::from(want.is_some_and(|s| s > 0.0 && s < 1.0));
        }
        assert_eq!(got.sole & !got.mask, 0, "only lanes with a root are sole");
        for i in lane_indices(got.sole) {
            seen[3] += usize::from(sole_root_is_the_only_crossing(
                &corners,
                iso,
                &seg.lane(i),
                got.s[i],
            ));
        }
    }

    /// Past a lane's sole root, the trilinear interpolant (in `f64`, from its definition)
    /// keeps the sign it has at the segment's end: a search from there finds no crossing.
    /// Returns whether any point past the root was checked.
    fn sole_root_is_the_only_crossing<T: Voxel>(
        corners: &[T; 8],
        iso: f32,
        lane: &CellSegment,
        s: f64,
    ) -> bool {
        let g = corners.map(|v| v.to_f64() - f64::from(iso));
        let scale: f64 = g.iter().map(|x| x.abs()).sum();
        let (o, d) = (lane.origin.as_dvec3(), lane.dir.as_dvec3());
        let (lo, w) = (lane.lo.as_dvec3(), (lane.hi - lane.lo).as_dvec3());
        let f = |t: f64| {
            let p = ((o + d * t - lo) / w).to_array();
            let mut f = 0.0;
            for (c, gc) in g.iter().enumerate() {
                let wt = |a: usize| if c >> a & 1 == 1 { p[a] } else { 1.0 - p[a] };
                f += gc * wt(0) * wt(1) * wt(2);
            }
            f
        };
        let (tn, tf) = (f64::from(lane.t_near), f64::from(lane.t_far));
        let root = tn + s * (tf - tn);
        // Past the root by more than its rounding (a quarter `f32` ulp of `t`), as a
        // peeled ray's next search starts (`Peel::next_t`).
        let from = root + 1e-5 * (1.0 + root.abs()) + 1e-3 * (tf - tn);
        let end = f(tf);
        if from >= tf || end.abs() <= 1e-9 * scale {
            return false;
        }
        for j in 0..=64 {
            let t = from + (tf - from) * f64::from(j) / 64.0;
            let v = f(t);
            assert!(
                v * end.signum() > -1e-9 * scale,
                "a crossing past the sole root {root} at t = {t} (f = {v}, end {end}): \
                 corners {corners:?}, iso {iso}, {lane:?}"
            );
        }
        true
    }

    /// Jobs from 8 different cells side by side: each lane's root equals the scalar slow
    /// path's for its own job, bit for bit (or both find none).
    #[test]
    fn jobs_from_different_cells_equal_the_scalar_slow_path() {
        let mut rng = Rng::new(77);
        let (mut some, mut none) = (0, 0);
        for round in 0..3000 {
            let sign = [0, 1, 2].map(|_| if rng.below(2) == 0 { 1.0f32 } else { -1.0 });
            let n = 1 + rng.below(8) as usize;
            // One isovalue per batch, as a packet's jobs have; shallow cells around 0.3
            // (cubics with extrema near zero: the scalar lanes), now and then a cell equal
            // to the isovalue.
            let iso = if rng.below(3) == 0 { 0.3 } else { 0.0 };
            let jobs: Vec<([f32; 8], CellSegment)> = (0..n)
                .map(|_| {
                    // Unit cells (all lanes: no divisions by widths) or random sizes.
                    let lo = rng.vec3(-40.0, 40.0).floor();
                    let hi = if round % 2 == 0 {
                        lo + Vec3::ONE
                    } else {
                        lo + rng.vec3(0.3, 2.0)
                    };
                    let flat = rng.below(20) == 0;
                    let corners: [f32; 8] = std::array::from_fn(|_| {
                        if flat {
                            iso
                        } else if iso == 0.0 {
                            rng.range_f32(-1.0, 1.0)
                        } else {
                            0.3 + 0.02 * rng.range_f32(-1.0, 1.0)
                        }
                    });
                    let far = rng.range_f32(1.0, 300.0);
                    let eye = (lo + hi) * 0.5 - Vec3::from(sign) * far;
                    let target = lo + (hi - lo) * rng.vec3(0.0, 1.0);
                    let d = (target - eye).abs().max(Vec3::splat(1e-4)) * Vec3::from(sign);
                    let ray = LocalRay::new(eye, d * rng.range_f32(0.2, 5.0));
                    let (t_near, t_far) =
                        slab(&ray, lo, hi, 0.0, f32::INFINITY).unwrap_or((1.0, 1.0));
                    (corners, CellSegment::of(&ray, lo, hi, t_near, t_far))
                })
                .collect();
            let mut batch = SlowJobs::new(iso);
            for (corners, seg) in &jobs {
                batch.push(*corners, seg);
            }
            let got = exact_slow_jobs(&batch);
            assert_eq!(got.mask >> n, 0, "roots only on the jobs' lanes");
            for (i, j) in jobs.iter().enumerate() {
                let want = exact_slow(&j.0, iso, &j.1);
                let got_i = (got.mask >> i & 1 == 1).then(|| got.s[i]);
                assert_eq!(
                    got_i.map(f64::to_bits),
                    want.map(f64::to_bits),
                    "job {i} of {n}: {j:?}"
                );
                if want.is_some() {
                    some += 1;
                } else {
                    none += 1;
                }
            }
        }
        assert!(some > 1000 && none > 1000, "{some} roots, {none} without");
    }

    #[test]
    fn lanes_side_by_side_equal_the_scalar_slow_path() {
        let mut rng = Rng::new(2026);
        let mut seen = [0usize; 4];
        for _ in 0..4000 {
            lanes_equal_scalar(
                &mut rng,
                |r: &mut Rng| r.range_f32(-1.0, 1.0),
                0.0,
                &mut seen,
            );
            // Shallow cells: cubics with extrema near zero (the scalar lanes).
            lanes_equal_scalar(
                &mut rng,
                |r: &mut Rng| 0.3 + 0.02 * r.range_f32(-1.0, 1.0),
                0.3,
                &mut seen,
            );
            // Integer voxels: corners on the isovalue, cells equal to it.
            let spread = rng.below(3);
            lanes_equal_scalar(
                &mut rng,
                |r: &mut Rng| 100 + r.below(2 * spread + 1) as i16 - spread as i16,
                100.0,
                &mut seen,
            );
        }
        let [none, some, inside, sole] = seen;
        assert!(
            none > 5_000 && some > 5_000 && inside > 5_000 && sole > 2_000,
            "{seen:?}"
        );
    }
}
