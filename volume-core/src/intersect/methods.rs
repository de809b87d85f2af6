//! The five cell intersectors and the cubic they share.
//!
//! Along the ray segment `[t_near, t_far]` inside a cell, reparameterised to `s ∈ [0, 1]`,
//! the trilinear interpolant minus the isovalue is the cubic
//! `f(s) = a·s³ + b·s² + c·s + d` (thesis seed 004 §6.5.2, §7.2.2). Its coefficients are
//! built in cell-local coordinates by collapsing the cell one axis at a time
//! (z: 4 linear functions, y: 2 quadratics, x: 1 cubic), each step a lerp between two
//! corners, which keeps every intermediate within the corner range.

use wide::f32x8;

use crate::voxel::{Voxel, VoxelType};

use super::{CellIntersector, CellSegment, RootsX8, SegmentsX8};

/// Corner differences `v − iso` as `f32`, scaled by an exact power of two (or `1/max` when
/// the range leaves `f32`) so that the largest lies in a safe range: values near `f32::MAX`
/// (1e30…3e38) and denormals both become ordinary numbers. Scaling does not move roots.
/// Returns the differences and their largest magnitude (0: the cell equals the isovalue).
#[inline(always)]
pub(crate) fn corner_diffs<T: Voxel>(corners: &[T; 8], iso: f32) -> ([f32; 8], f32) {
    const LO: f32 = 1.0 / (1u64 << 40) as f32;
    const HI: f32 = (1u64 << 40) as f32;
    let wide = matches!(T::TYPE, VoxelType::F64 | VoxelType::I32 | VoxelType::U32);
    if !wide {
        let g = corners.map(|v| v.to_f32() - iso);
        let m = g.iter().fold(0.0f32, |m, x| m.max(x.abs()));
        if m == 0.0 || (LO..=HI).contains(&m) {
            return (g, m);
        }
    }
    // Rare path: 32-bit integers and f64 (which f32 cannot hold exactly) and extreme ranges.
    let iso = f64::from(iso);
    let g = corners.map(|v| v.to_f64() - iso);
    let m = g.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    if m == 0.0 {
        return ([0.0; 8], 0.0);
    }
    let scale = if m >= f64::from(LO) && m <= f64::from(HI) {
        1.0
    } else {
        1.0 / m
    };
    let g = g.map(|x| (x * scale) as f32);
    let m = g.iter().fold(0.0f32, |m, x| m.max(x.abs()));
    (g, m)
}

/// Cubic coefficients `[a, b, c, d]` of `Σ g_i w_i(p0 + s·dp)` (corner index `x + 2y + 4z`).
#[inline(always)]
pub(crate) fn cubic_f32(g: &[f32; 8], p0: [f32; 3], dp: [f32; 3]) -> [f32; 4] {
    // z: four linear functions al + be·s.
    let mut al = [0.0f32; 4];
    let mut be = [0.0f32; 4];
    for xy in 0..4 {
        let (g0, g1) = (g[xy], g[xy + 4]);
        let dz = g1 - g0;
        al[xy] = g0 + dz * p0[2];
        be[xy] = dz * dp[2];
    }
    // y: two quadratics q0 + q1·s + q2·s².
    let mut q = [[0.0f32; 3]; 2];
    for x in 0..2 {
        let (a0, b0, a1, b1) = (al[x], be[x], al[x + 2], be[x + 2]);
        let (da, db) = (a1 - a0, b1 - b0);
        q[x] = [a0 + da * p0[1], b0 + db * p0[1] + da * dp[1], db * dp[1]];
    }
    // x: one cubic.
    let [h0, h1] = q;
    let dh = [h1[0] - h0[0], h1[1] - h0[1], h1[2] - h0[2]];
    [
        dh[2] * dp[0],
        h0[2] + dh[2] * p0[0] + dh[1] * dp[0],
        h0[1] + dh[1] * p0[0] + dh[0] * dp[0],
        h0[0] + dh[0] * p0[0],
    ]
}

/// `f64` twin of [`cubic_f32`].
#[inline]
pub(crate) fn cubic_f64(g: &[f64; 8], p0: [f64; 3], dp: [f64; 3]) -> [f64; 4] {
    cubic_of(g, p0, dp)
}

/// [`cubic_f32`]'s operations, in the same order, for any float type: [`cubic_f64`] and
/// its lanes ([`super::slow_x8`]), bit-identical per lane.
#[inline(always)]
pub(crate) fn cubic_of<F>(g: &[F; 8], p0: [F; 3], dp: [F; 3]) -> [F; 4]
where
    F: Copy + std::ops::Add<Output = F> + std::ops::Sub<Output = F> + std::ops::Mul<Output = F>,
{
    let mut al = [g[0]; 4];
    let mut be = [g[0]; 4];
    for xy in 0..4 {
        let (g0, g1) = (g[xy], g[xy + 4]);
        let dz = g1 - g0;
        al[xy] = g0 + dz * p0[2];
        be[xy] = dz * dp[2];
    }
    let mut q = [[g[0]; 3]; 2];
    for x in 0..2 {
        let (a0, b0, a1, b1) = (al[x], be[x], al[x + 2], be[x + 2]);
        let (da, db) = (a1 - a0, b1 - b0);
        q[x] = [a0 + da * p0[1], b0 + db * p0[1] + da * dp[1], db * dp[1]];
    }
    let [h0, h1] = q;
    let dh = [h1[0] - h0[0], h1[1] - h0[1], h1[2] - h0[2]];
    [
        dh[2] * dp[0],
        h0[2] + dh[2] * p0[0] + dh[1] * dp[0],
        h0[1] + dh[1] * p0[0] + dh[0] * dp[0],
        h0[0] + dh[0] * p0[0],
    ]
}

#[inline(always)]
fn eval(k: &[f32; 4], s: f32) -> f32 {
    ((k[0] * s + k[1]) * s + k[2]) * s + k[3]
}

#[inline(always)]
fn eval64(k: &[f64; 4], s: f64) -> f64 {
    eval_of(k, s)
}

/// Horner's rule for the cubic `k` at `s`, for any float type ([`eval64`] and its lanes).
#[inline(always)]
pub(super) fn eval_of<F>(k: &[F; 4], s: F) -> F
where
    F: Copy + std::ops::Add<Output = F> + std::ops::Mul<Output = F>,
{
    ((k[0] * s + k[1]) * s + k[2]) * s + k[3]
}

/// The cubic of a cell segment for one isovalue, or `Err(())` for a cell that equals the
/// isovalue everywhere (the whole segment lies on the surface: the hit is its entry).
#[inline(always)]
fn setup<T: Voxel>(corners: &[T; 8], iso: f32, seg: &CellSegment) -> Result<([f32; 4], f32), ()> {
    let (g, gmax) = corner_diffs(corners, iso);
    if gmax == 0.0 {
        return Err(());
    }
    let (p0, dp) = seg.local_f32();
    Ok((cubic_f32(&g, p0, dp), gmax))
}

/// Regula falsi on `[s0, s1]` with `f(s0) = f0`, `f(s1) = f1` of opposite signs.
#[inline(always)]
fn refine(k: &[f32; 4], mut s0: f32, mut f0: f32, mut s1: f32, mut f1: f32, n: u32) -> f32 {
    for _ in 0..n {
        let s = s0 + (s1 - s0) * (f0 / (f0 - f1));
        let fs = eval(k, s);
        if fs == 0.0 {
            return s;
        }
        if (fs > 0.0) == (f0 > 0.0) {
            s0 = s;
            f0 = fs;
        } else {
            s1 = s;
            f1 = fs;
        }
    }
    let s = s0 + (s1 - s0) * (f0 / (f0 - f1));
    s.clamp(s0.min(s1), s0.max(s1))
}

/// Linear: assumes `f` is linear between entry and exit (thesis §7.2.2). Misses pairs of
/// roots (entering and leaving the surface in one cell) and tangent touches; its hit
/// position errs by the cubic's curvature over the segment (up to a sizeable fraction of a
/// cell on curved surfaces).
#[derive(Debug, Clone, Copy, Default)]
pub struct Linear;

impl CellIntersector for Linear {
    #[inline]
    fn first_root<T: Voxel>(&self, corners: &[T; 8], iso: f32, seg: &CellSegment) -> Option<f64> {
        let Ok((k, _)) = setup(corners, iso, seg) else {
            return Some(0.0);
        };
        let f0 = k[3];
        let f1 = k[0] + k[1] + k[2] + k[3];
        if f0 == 0.0 {
            return Some(0.0);
        }
        if f1 == 0.0 || (f0 > 0.0) != (f1 > 0.0) {
            return Some(f64::from((f0 / (f0 - f1)).clamp(0.0, 1.0)));
        }
        None
    }
}

/// Neubauer et al.: the linear test followed by `iterations` regula-falsi steps on the cubic
/// (thesis §7.2.2; we evaluate the cubic instead of re-interpolating, which is the same
/// function). Misses exactly what [`Linear`] misses; each step shrinks the position error.
#[derive(Debug, Clone, Copy)]
pub struct Neubauer {
    pub iterations: u32,
}

impl CellIntersector for Neubauer {
    #[inline]
    fn first_root<T: Voxel>(&self, corners: &[T; 8], iso: f32, seg: &CellSegment) -> Option<f64> {
        let Ok((k, _)) = setup(corners, iso, seg) else {
            return Some(0.0);
        };
        let f0 = k[3];
        let f1 = k[0] + k[1] + k[2] + k[3];
        if f0 == 0.0 {
            return Some(0.0);
        }
        if f1 == 0.0 {
            return Some(1.0);
        }
        if (f0 > 0.0) != (f1 > 0.0) {
            return Some(f64::from(refine(&k, 0.0, f0, 1.0, f1, self.iterations)));
        }
        None
    }
}

/// The exact iterative method of Listing 7.1 (thesis seed 004 §7.2.2), made exact on every
/// ray by a certified fast path and an exact slow path:
///
/// 1. **Fast path, `f32`** (most cells): the segment's cubic in `f32` and its Bernstein
///    coefficients, whose convex hull contains the cubic on `[0, 1]`. When every coefficient
///    lies farther from 0 than a rigorous bound on the error of this `f32` computation
///    against the `f64` truth (`ExactMargin`: corner differences, segment ends, cubic
///    coefficients, evaluation), the segment provably holds no crossing and no touch: `None`.
/// 2. **Slow path, `f64`** (the rest: cells the ray crosses or passes within the bound): the
///    segment's ends from the exact slab ([`CellSegment::local_f64`]), the cubic in `f64`,
///    and Listing 7.1's monotone pieces between the derivative's roots, decided exactly as
///    [`Reference`] decides them (`first_root_f64`: the same extrema, sign tests and touch
///    tolerance), so the first crossing is found on every ray the reference finds it on and
///    never on another; safeguarded Newton steps then refine it in `f64`
///    (`refine_newton_f64`; the listing's plain regula falsi stagnates on convex pieces).
///
/// Before, the whole method ran in `f32` with a touching band of `64·ε·max|g|`: at 1024²
/// a few rays in a million passed within that band of the surface without touching it
/// (a false hit, seen as a far hit when the next surface lay behind), and the `f32` segment
/// ends (rounded `t`, ~6e-5 cells for a ray from 700 cells away) could move a crossing near
/// a face out of both cells (docs/accuracy.md).
#[derive(Debug, Clone, Copy, Default)]
pub struct Exact;

/// Refinement steps of the slow path at most (it stops earlier, once the bracket is below a
/// quarter of the hit's `f32` resolution in `t`, or `f` vanishes).
pub const EXACT_ITERATIONS: u32 = 24;

/// The error bound of [`Exact`]'s `f32` fast path for one cell and one isovalue, in the
/// units of the (scaled) corner differences `g` of [`corner_diffs`].
///
/// Against the `f64` cubic on the exact segment (what [`Reference`] and the slow path see):
/// - corner differences `v − iso` rounded to `f32`: `ε·Σ|g|`;
/// - the cubic's coefficients from the `f32` segment by three nested lerps: under
///   `24·ε·Σ|g|` for segment coordinates within `[−δ, 1 + δ]`, `δ ≪ 1`;
/// - the `f32` segment ends: with `u = ε/2`, each coordinate of an end is off by at most
///   `u·(2|o − lo| + 5|d|·|t|)/w + 2u` (the `f32` slab `t` errs by `3u·|t|`, moving the
///   point along the ray; `o − lo`, `d·t`, their sum and the scaling round once each), so by
///   `e = 3ε·(|o − lo| + |d|·|t|)/w + ε` per axis; a point between the ends is off by at
///   most the larger end error, and the trilinear interpolant is `(1 + δ)²·Σ|g|`-Lipschitz
///   per axis there, so the values differ by at most `1.1·Σ|g|·Σ_axes e`;
/// - Bernstein coefficients and Horner evaluation of the `f32` cubic: `16·ε·Σ|k|` (see
///   [`bernstein_clear`]).
///
/// [`ExactMargin::with_segment`] adds the segment term for one ray.
#[derive(Debug, Clone, Copy)]
pub(crate) struct ExactMargin {
    /// `Σ|g|` of the cell's corner differences.
    gsum: f32,
}

impl ExactMargin {
    #[inline(always)]
    pub(crate) fn new(g: &[f32; 8]) -> Self {
        Self {
            gsum: g.iter().map(|x| x.abs()).sum(),
        }
    }

    /// The margin for one segment whose points err by at most `seg_err` cell units summed
    /// over the axes, before the evaluation term of [`bernstein_clear`].
    #[inline(always)]
    pub(crate) fn with_segment(self, seg_err: f32) -> f32 {
        self.gsum * (32.0 * f32::EPSILON + 1.1 * seg_err)
    }
}

/// `Σ_axes 3ε·(|o − lo| + |d|·max(|t_near|, |t_far|))/w + ε`: the bound on the error of a
/// point of [`CellSegment::local_f32`]'s segment, summed over the axes (see [`ExactMargin`]).
#[inline(always)]
fn segment_error(seg: &CellSegment) -> f32 {
    let t = seg.t_near.abs().max(seg.t_far.abs());
    let inv_w = (seg.hi - seg.lo).recip();
    let mut e = 0.0f32;
    for a in 0..3 {
        e += ((seg.origin[a] - seg.lo[a]).abs() + seg.dir[a].abs() * t) * inv_w[a];
    }
    3.0 * f32::EPSILON * e + 3.0 * f32::EPSILON
}

impl CellIntersector for Exact {
    #[inline]
    fn first_root<T: Voxel>(&self, corners: &[T; 8], iso: f32, seg: &CellSegment) -> Option<f64> {
        let (g, gmax) = corner_diffs(corners, iso);
        if gmax == 0.0 {
            // The cell equals the isovalue: the whole segment lies on the surface.
            return Some(0.0);
        }
        let (p0, dp) = seg.local_f32();
        let k = cubic_f32(&g, p0, dp);
        let margin = ExactMargin::new(&g).with_segment(segment_error(seg));
        if bernstein_clear(&k, margin) {
            return None;
        }
        exact_slow(corners, iso, seg)
    }

    /// The corner differences once per cell, the segments' cubics and the certified early
    /// out 8 lanes at a time (the scalar operations lane-wise); only lanes that are not
    /// clear run the `f64` slow path, side by side (`intersect/slow_x8.rs`, bit-identical to
    /// the function the scalar method calls).
    #[inline(always)]
    fn first_roots_x8<T: Voxel>(
        &self,
        corners: &[T; 8],
        iso: f32,
        seg: &SegmentsX8<'_>,
        mask: u32,
    ) -> RootsX8 {
        self.first_roots_x8_deferring(corners, iso, seg, mask, 0).0
    }

    /// As [`Exact::first_roots_x8`]; a lane of `may_defer` that the `f32` fast path cannot
    /// clear is deferred when its segment's end values are certified of opposite signs (the
    /// same error bound as the clearing): the `f64` cubic changes sign on the exact segment,
    /// so the slow path finds a root there.
    #[inline(always)]
    fn first_roots_x8_deferring<T: Voxel>(
        &self,
        corners: &[T; 8],
        iso: f32,
        seg: &SegmentsX8<'_>,
        mask: u32,
        may_defer: u32,
    ) -> (RootsX8, u32) {
        let mut r = RootsX8::default();
        let (g, gmax) = corner_diffs(corners, iso);
        if gmax == 0.0 {
            r.mask = mask;
            return (r, 0);
        }
        let (p0, dp) = seg.local_f32();
        let k = cubic_x8(&g, p0, dp);
        let margin = ExactMargin::new(&g);
        let seg_err = segment_error_x8(seg);
        let margin = f32x8::splat(margin.gsum)
            * (f32x8::splat(32.0 * f32::EPSILON) + f32x8::splat(1.1) * seg_err);
        let slow = mask & !bernstein_clear_x8(&k, margin);
        if slow == 0 {
            return (r, 0);
        }
        let deferred = slow & may_defer & bernstein_crossing_x8(&k, margin);
        let now = slow & !deferred;
        if now != 0 {
            r = super::slow_x8::exact_slow_x8(corners, iso, seg, now);
        }
        (r, deferred)
    }
}

/// [`segment_error`] lane-wise (same operations).
#[inline(always)]
fn segment_error_x8(seg: &SegmentsX8<'_>) -> f32x8 {
    let r = seg.rays;
    let t = seg.t_near.abs().max(seg.t_far.abs());
    let inv_w = (seg.hi - seg.lo).recip();
    let mut e = f32x8::ZERO;
    for a in 0..3 {
        let rel = (r.origin[a] - f32x8::splat(seg.lo[a])).abs();
        e += (rel + r.dir[a].abs() * t) * f32x8::splat(inv_w[a]);
    }
    f32x8::splat(3.0 * f32::EPSILON) * e + f32x8::splat(3.0 * f32::EPSILON)
}

/// The `f64` slow path of [`Exact`]: [`first_root_f64`] on the exact segment, refined by
/// Newton steps ([`refine_newton_f64`]) until the bracket is a quarter of an `f32` ulp of
/// the hit's `t` (what the hit can hold); the root as a position on the `f32` segment.
#[inline(never)]
pub(super) fn exact_slow<T: Voxel>(corners: &[T; 8], iso: f32, seg: &CellSegment) -> Option<f64> {
    let Ok(c) = CubicF64::new(corners, iso, seg) else {
        return Some(0.0);
    };
    let span = c.t1 - c.t0;
    let s_tol = if span > 0.0 {
        (0.25 * f64::from(f32::EPSILON) * c.t0.abs().max(c.t1.abs()) / span).max(f64::EPSILON)
    } else {
        1.0
    };
    let s = first_root_f64(&c.k, c.tol, |k, s0, f0, s1| {
        refine_newton_f64(k, s0, f0, s1, s_tol)
    })?;
    Some(c.s_on_f32_segment(seg, s))
}

/// Safeguarded Newton on the bracket `[s0, s1]` (`s0 < s1`, `f(s0) = f0` and `f(s1)` of
/// opposite signs), in `f64`, until the bracket is narrower than `s_tol`.
///
/// The first point is the bracket's secant; every evaluated point replaces the bracket end
/// of its sign, and the next point is Newton's step from it, or the bracket's midpoint when
/// that step leaves the bracket or fails to halve the step before last (the bisection
/// guard of Numerical Recipes' `rtsafe`). A Newton step shorter than half the tolerance is
/// stretched to half of it: once Newton has converged, the next point lands across the
/// root and closes the bracket. The result is the secant of the final bracket, so it stays
/// within the certified bracket whatever the steps did. On the MNI frame a hit takes 3.2
/// evaluations of the cubic where regula falsi with the Illinois modification took 6.7.
fn refine_newton_f64(k: &[f64; 4], s0: f64, f0: f64, s1: f64, s_tol: f64) -> f64 {
    debug_assert!(s0 <= s1);
    let lo_pos = f0 > 0.0;
    let (mut lo, mut f_lo, mut hi, mut f_hi) = (s0, f0, s1, eval64(k, s1));
    let d = [3.0 * k[0], 2.0 * k[1], k[2]];
    let half_tol = 0.5 * s_tol;
    let mut s = lo + (hi - lo) * (f_lo / (f_lo - f_hi));
    let (mut step_old, mut step_older) = (hi - lo, hi - lo);
    for _ in 0..EXACT_ITERATIONS {
        if hi - lo <= s_tol {
            break;
        }
        if !(s > lo && s < hi) {
            s = 0.5 * (lo + hi);
        }
        let fs = eval64(k, s);
        if fs == 0.0 {
            return s;
        }
        if (fs > 0.0) == lo_pos {
            (lo, f_lo) = (s, fs);
        } else {
            (hi, f_hi) = (s, fs);
        }
        let mut step = -fs / ((d[0] * s + d[1]) * s + d[2]);
        if step.is_nan() || step.abs() > 0.5 * step_older {
            // Too slow (or no finite step): bisect.
            step = 0.5 * (lo + hi) - s;
        } else if step.abs() < half_tol {
            step = half_tol.copysign(step);
        }
        (step_older, step_old) = (step_old, step.abs());
        s += step;
    }
    let s = lo + (hi - lo) * (f_lo / (f_lo - f_hi));
    s.clamp(lo, hi)
}

/// True when the Bernstein coefficients of `k` all exceed `margin + 16ε·Σ|k|` (or all lie
/// below its negative): then the cubic stays farther than `margin` from 0 on `[0, 1]`
/// whatever the rounding of these coefficients and of any Horner evaluation.
///
/// On `[0, 1]` the cubic lies in the convex hull of its Bernstein coefficients
/// `d, d + c/3, d + 2c/3 + b/3, a + b + c + d`. With `S = |a| + |b| + |c| + |d|`, forming
/// them in `f32` errs by at most about `3ε·S` and a Horner evaluation at any `s ∈ [0, 1]`
/// by about `6ε·S`; `16ε·S` covers both.
#[inline(always)]
fn bernstein_clear(k: &[f32; 4], margin: f32) -> bool {
    let [a, b, c, d] = *k;
    let b1 = d + c * (1.0 / 3.0);
    let b2 = d + c * (2.0 / 3.0) + b * (1.0 / 3.0);
    let b3 = a + b + c + d;
    let margin = margin + 16.0 * f32::EPSILON * (a.abs() + b.abs() + c.abs() + d.abs());
    let lo = d.min(b1).min(b2.min(b3));
    let hi = d.max(b1).max(b2.max(b3));
    lo > margin || hi < -margin
}

/// [`cubic_f32`] lane-wise (the same operations in the same order, so each lane is
/// bit-identical to the scalar cubic).
#[inline(always)]
pub(crate) fn cubic_x8(g: &[f32; 8], p0: [f32x8; 3], dp: [f32x8; 3]) -> [f32x8; 4] {
    let mut al = [f32x8::ZERO; 4];
    let mut be = [f32x8::ZERO; 4];
    for xy in 0..4 {
        let (g0, g1) = (g[xy], g[xy + 4]);
        let dz = f32x8::splat(g1 - g0);
        al[xy] = f32x8::splat(g0) + dz * p0[2];
        be[xy] = dz * dp[2];
    }
    let mut q = [[f32x8::ZERO; 3]; 2];
    for x in 0..2 {
        let (a0, b0, a1, b1) = (al[x], be[x], al[x + 2], be[x + 2]);
        let (da, db) = (a1 - a0, b1 - b0);
        q[x] = [a0 + da * p0[1], b0 + db * p0[1] + da * dp[1], db * dp[1]];
    }
    let [h0, h1] = q;
    let dh = [h1[0] - h0[0], h1[1] - h0[1], h1[2] - h0[2]];
    [
        dh[2] * dp[0],
        h0[2] + dh[2] * p0[0] + dh[1] * dp[0],
        h0[1] + dh[1] * p0[0] + dh[0] * dp[0],
        h0[0] + dh[0] * p0[0],
    ]
}

/// [`bernstein_clear`] lane-wise with a margin per lane: bit `i` set when lane `i` is
/// clear (same operations; `wide`'s `min`/`max` ignore a NaN operand like `f32::min`/`max`).
#[inline(always)]
fn bernstein_clear_x8(k: &[f32x8; 4], margin: f32x8) -> u32 {
    let [a, b, c, d] = *k;
    let b1 = d + c * f32x8::splat(1.0 / 3.0);
    let b2 = d + c * f32x8::splat(2.0 / 3.0) + b * f32x8::splat(1.0 / 3.0);
    let b3 = a + b + c + d;
    let margin =
        margin + f32x8::splat(16.0 * f32::EPSILON) * (a.abs() + b.abs() + c.abs() + d.abs());
    let lo = d.min(b1).min(b2.min(b3));
    let hi = d.max(b1).max(b2.max(b3));
    (lo.simd_gt(margin) | hi.simd_lt(-margin)).to_bitmask()
}

/// The lanes whose cubic's end values (`s = 0` and `s = 1`) lie farther from 0 than
/// [`bernstein_clear_x8`]'s bound, on opposite sides: the `f64` cubic on the exact segment
/// changes sign, so it has a root there.
#[inline(always)]
fn bernstein_crossing_x8(k: &[f32x8; 4], margin: f32x8) -> u32 {
    let [a, b, c, d] = *k;
    let end = a + b + c + d;
    let margin =
        margin + f32x8::splat(16.0 * f32::EPSILON) * (a.abs() + b.abs() + c.abs() + d.abs());
    let neg = -margin;
    ((d.simd_gt(margin) & end.simd_lt(neg)) | (d.simd_lt(neg) & end.simd_gt(margin))).to_bitmask()
}

/// Schwarze's analytic cubic solver (Graphics Gems I; Cardano with the trigonometric form
/// for three real roots) in `f32`, the smallest root in `[0, 1]` (thesis §7.2.2). Finds all
/// roots in exact arithmetic, but in `f32` the normalisation by `a` and the
/// `acos`/`cbrt` steps lose digits when `a` is small (nearly quadratic segments) or roots
/// cluster, so hits can be missed or misplaced on short or nearly linear segments.
#[derive(Debug, Clone, Copy, Default)]
pub struct Schwarze;

impl CellIntersector for Schwarze {
    #[inline]
    fn first_root<T: Voxel>(&self, corners: &[T; 8], iso: f32, seg: &CellSegment) -> Option<f64> {
        let Ok((k, _)) = setup(corners, iso, seg) else {
            return Some(0.0);
        };
        let mut roots = [f32::NAN; 3];
        solve_cubic_schwarze(k, &mut roots);
        roots
            .into_iter()
            .filter(|r| (0.0..=1.0).contains(r))
            .min_by(f32::total_cmp)
            .map(f64::from)
    }
}

fn solve_quadratic(a: f32, b: f32, c: f32, out: &mut [f32; 3]) {
    if a == 0.0 {
        if b != 0.0 {
            out[0] = -c / b;
        }
        return;
    }
    let p = b / (2.0 * a);
    let q = c / a;
    let disc = p * p - q;
    if disc == 0.0 {
        out[0] = -p;
    } else if disc > 0.0 {
        let r = disc.sqrt();
        out[0] = r - p;
        out[1] = -r - p;
    }
}

fn solve_cubic_schwarze(k: [f32; 4], out: &mut [f32; 3]) {
    let scale = k[1].abs().max(k[2].abs()).max(k[3].abs());
    if k[0].abs() <= 1e-6 * scale {
        solve_quadratic(k[1], k[2], k[3], out);
        return;
    }
    // Normal form x³ + A x² + B x + C.
    let a = k[1] / k[0];
    let b = k[2] / k[0];
    let c = k[3] / k[0];
    // Substitute x = y − A/3 to eliminate the quadratic term: y³ + 3p y + 2q = 0.
    let sq_a = a * a;
    let p = (1.0 / 3.0) * (-(1.0 / 3.0) * sq_a + b);
    let q = 0.5 * ((2.0 / 27.0) * a * sq_a - (1.0 / 3.0) * a * b + c);
    let cb_p = p * p * p;
    let disc = q * q + cb_p;
    let sub = (1.0 / 3.0) * a;
    if disc.abs() <= 1e-7 * (q * q).max(cb_p.abs()) {
        if q == 0.0 {
            out[0] = -sub;
        } else {
            let u = (-q).cbrt();
            out[0] = 2.0 * u - sub;
            out[1] = -u - sub;
        }
    } else if disc < 0.0 {
        let phi = (1.0 / 3.0) * (-q / (-cb_p).sqrt()).clamp(-1.0, 1.0).acos();
        let t = 2.0 * (-p).sqrt();
        out[0] = t * phi.cos() - sub;
        out[1] = -t * (phi + std::f32::consts::FRAC_PI_3).cos() - sub;
        out[2] = -t * (phi - std::f32::consts::FRAC_PI_3).cos() - sub;
    } else {
        let sqrt_d = disc.sqrt();
        let u = (sqrt_d - q).cbrt();
        let v = -(sqrt_d + q).cbrt();
        out[0] = u + v - sub;
    }
}

/// The `f64` reference: isolates every root of the cubic on `[0, 1]` and returns the first,
/// to full double precision (`first_root_f64`, then bisection until the bracket's ends are
/// adjacent doubles). Corner differences `v − iso` are formed in `f64` from the native voxels
/// (exact for every integer type and for `f32`), and the segment in cell-local coordinates
/// is the part of the same `f32` ray inside the same cell bounds the other methods see,
/// with its ends computed in `f64` ([`CellSegment::local_f64`]).
#[derive(Debug, Clone, Copy, Default)]
pub struct Reference;

impl CellIntersector for Reference {
    fn first_root<T: Voxel>(&self, corners: &[T; 8], iso: f32, seg: &CellSegment) -> Option<f64> {
        let Ok(c) = CubicF64::new(corners, iso, seg) else {
            return Some(0.0);
        };
        let s = first_root_f64(&c.k, c.tol, bisect)?;
        Some(c.s_on_f32_segment(seg, s))
    }
}

/// Corner differences `v − iso` in `f64` (exact for every voxel type), divided by their
/// largest magnitude when that leaves `1e-200..=1e200`; `None` for a cell equal to the
/// isovalue everywhere.
#[inline(always)]
pub(super) fn corner_diffs_f64<T: Voxel>(corners: &[T; 8], iso: f32) -> Option<[f64; 8]> {
    let iso = f64::from(iso);
    let g = corners.map(|v| v.to_f64() - iso);
    let gmax = g.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    if gmax == 0.0 {
        return None;
    }
    Some(if (1e-200..=1e200).contains(&gmax) {
        g
    } else {
        g.map(|x| x / gmax)
    })
}

/// A cell segment's cubic in `f64` on the exact segment, with the touch tolerance of
/// [`first_root_f64`] (shared by [`Reference`] and [`Exact`]'s slow path).
struct CubicF64 {
    k: [f64; 4],
    tol: f64,
    /// The exact segment's ends (ray parameters).
    t0: f64,
    t1: f64,
}

impl CubicF64 {
    /// `Err` for a cell equal to the isovalue everywhere (the hit is the segment's entry).
    #[inline(always)]
    fn new<T: Voxel>(corners: &[T; 8], iso: f32, seg: &CellSegment) -> Result<Self, ()> {
        let g = corner_diffs_f64(corners, iso).ok_or(())?;
        let (p0, dp, t0, t1) = seg.local_f64();
        let k = cubic_f64(&g, p0, dp);
        // Bound on Σ|terms| of f over the segment: each weight's magnitude is at most
        // max(|x|, |1 − x|) at the segment ends, per axis.
        let mut wmax = 1.0f64;
        for a in 0..3 {
            let (x0, x1) = (p0[a], p0[a] + dp[a]);
            wmax *= x0.abs().max(x1.abs()) + (1.0 - x0).abs().max((1.0 - x1).abs());
        }
        let gsum: f64 = g.iter().map(|x| x.abs()).sum();
        Ok(Self {
            k,
            tol: 64.0 * f64::EPSILON * gsum * wmax,
            t0,
            t1,
        })
    }

    /// A root `s` of this cubic as a position on the `f32` segment `[t_near, t_far]` that
    /// [`CellSegment::t_at`] turns into the ray parameter.
    #[inline(always)]
    fn s_on_f32_segment(&self, seg: &CellSegment, s: f64) -> f64 {
        seg.s_of_t(self.t0 + s * (self.t1 - self.t0))
    }
}

/// The first root of the cubic `k` on `[0, 1]`, decided in `f64`: the derivative's roots
/// (refined by Newton steps) split the segment into monotone pieces; the first piece whose
/// ends differ in sign holds the first crossing, which `refine(k, s0, f(s0), s1)` locates;
/// an extremum with `|f| ≤ tol` (a rigorous rounding bound) is a touching double or triple
/// root and counts as a hit. A cubic certified monotone on `[0, 1]` (`monotone_on_unit`) is
/// one piece: no extrema to find.
pub(crate) fn first_root_f64(
    k: &[f64; 4],
    tol: f64,
    refine: impl Fn(&[f64; 4], f64, f64, f64) -> f64,
) -> Option<f64> {
    let f0 = k[3];
    if f0 == 0.0 {
        return Some(0.0);
    }
    if !monotone_on_unit(k) {
        return first_root_by_pieces(k, tol, refine);
    }
    // No extremum in [0, 1]: one piece, no touch to test; what the pieces below do then.
    let f1 = eval64(k, 1.0);
    if f1 == 0.0 {
        return Some(1.0);
    }
    ((f1 > 0.0) != (f0 > 0.0)).then(|| refine(k, 0.0, f0, 1.0))
}

/// True when the cubic `k` is strictly monotone on `[0, 1]`: the Bernstein coefficients of
/// its derivative `3a·s² + 2b·s + c` there (`c`, `c + b`, `3a + 2b + c`), whose convex hull
/// holds `f'` on `[0, 1]`, share a sign by more than their rounding (a few ulps of
/// `|a| + |b| + |c|`). Most cells a ray crosses are: they then skip the extrema's square
/// root and Newton steps.
#[inline(always)]
fn monotone_on_unit(k: &[f64; 4]) -> bool {
    let (b0, b1, b2) = (k[2], k[2] + k[1], 3.0 * k[0] + 2.0 * k[1] + k[2]);
    let slack = 16.0 * f64::EPSILON * (k[0].abs() + k[1].abs() + k[2].abs());
    (b0 > slack && b1 > slack && b2 > slack) || (b0 < -slack && b1 < -slack && b2 < -slack)
}

/// [`first_root_f64`] for any cubic (`k[3] != 0`): the monotone pieces between the
/// derivative's roots, in order.
fn first_root_by_pieces(
    k: &[f64; 4],
    tol: f64,
    refine: impl Fn(&[f64; 4], f64, f64, f64) -> f64,
) -> Option<f64> {
    let f0 = k[3];
    let mut ext = [0.0f64; 2];
    let mut n = 0;
    let (qa, qb, qc) = (3.0 * k[0], 2.0 * k[1], k[2]);
    let mut cand = [f64::NAN; 2];
    if qa == 0.0 {
        if qb != 0.0 {
            cand[0] = -qc / qb;
        }
    } else {
        let disc = qb * qb - 4.0 * qa * qc;
        // A slightly negative discriminant from rounding is a (near) double extremum.
        let disc = if disc < 0.0 && disc > -1e-12 * (qb * qb).max((4.0 * qa * qc).abs()) {
            0.0
        } else {
            disc
        };
        if disc >= 0.0 {
            let r = disc.sqrt();
            let q = -0.5 * (qb + r.copysign(qb));
            if q == 0.0 {
                cand[0] = 0.0;
            } else {
                cand = [q / qa, qc / q];
            }
        }
    }
    for mut e in cand {
        if !e.is_finite() {
            continue;
        }
        // Newton on f' polishes the extremum (f'' = 6a·s + 2b).
        for _ in 0..2 {
            let d1 = (qa * e + qb) * e + qc;
            let d2 = 2.0 * qa * e + qb;
            if d2 != 0.0 {
                let next = e - d1 / d2;
                if next.is_finite() {
                    e = next;
                }
            }
        }
        if e > 0.0 && e < 1.0 && !ext[..n].contains(&e) {
            ext[n] = e;
            n += 1;
        }
    }
    if n == 2 && ext[0] > ext[1] {
        ext.swap(0, 1);
    }
    let (mut s_prev, mut f_prev) = (0.0f64, f0);
    let ends = ext[..n].iter().map(|&e| (e, true));
    for (s, is_extremum) in ends.chain(std::iter::once((1.0, false))) {
        let fs = eval64(k, s);
        if fs == 0.0 {
            // A touching root at an extremum, or a root exactly at an end: a sign change
            // strictly inside the piece comes first only if f_prev and fs differ, which a
            // zero cannot.
            return Some(s);
        }
        if (fs > 0.0) != (f_prev > 0.0) {
            return Some(refine(k, s_prev, f_prev, s));
        }
        if is_extremum && fs.abs() <= tol {
            return Some(s);
        }
        s_prev = s;
        f_prev = fs;
    }
    None
}

/// Bisection to adjacent doubles on a sign change.
fn bisect(k: &[f64; 4], mut lo: f64, f_lo: f64, mut hi: f64) -> f64 {
    let lo_pos = f_lo > 0.0;
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if mid <= lo || mid >= hi {
            break;
        }
        let fm = eval64(k, mid);
        if fm == 0.0 {
            return mid;
        }
        if (fm > 0.0) == lo_pos {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    /// f(s) evaluated straight from the trilinear definition.
    fn trilinear(g: &[f64; 8], p: [f64; 3]) -> f64 {
        let mut f = 0.0;
        for (c, gc) in g.iter().enumerate() {
            let w = |a: usize, bit: usize| if c >> bit & 1 == 1 { p[a] } else { 1.0 - p[a] };
            f += gc * w(0, 0) * w(1, 1) * w(2, 2);
        }
        f
    }

    #[test]
    fn cubic_matches_trilinear_interpolation() {
        let g = [0.3, -1.2, 2.0, 0.7, -0.4, 1.1, -2.5, 0.9];
        let p0 = [0.1, 0.8, 0.3];
        let dp = [0.7, -0.5, 0.6];
        let k = cubic_f64(&g, p0, dp);
        let kf = cubic_f32(
            &g.map(|x| x as f32),
            p0.map(|x| x as f32),
            dp.map(|x| x as f32),
        );
        for i in 0..=10 {
            let s = f64::from(i) / 10.0;
            let p = [0, 1, 2].map(|a| p0[a] + s * dp[a]);
            let truth = trilinear(&g, p);
            assert!((eval64(&k, s) - truth).abs() < 1e-12);
            assert!((f64::from(eval(&kf, s as f32)) - truth).abs() < 1e-5);
        }
    }

    #[test]
    fn reference_finds_simple_double_and_triple_roots() {
        // (s − 0.25)(s − 0.5)(s − 0.75) = s³ − 1.5 s² + 0.6875 s − 0.09375
        let k = [1.0, -1.5, 0.6875, -0.09375];
        assert!((first_root_f64(&k, 1e-15, bisect).unwrap() - 0.25).abs() < 1e-15);
        // Touching double root at 0.5: (s − 0.5)² = s² − s + 0.25.
        let k = [0.0, 1.0, -1.0, 0.25];
        assert_eq!(first_root_f64(&k, 1e-15, bisect), Some(0.5));
        // Just missing the tangent.
        let k = [0.0, 1.0, -1.0, 0.25 + 1e-9];
        assert_eq!(first_root_f64(&k, 1e-15, bisect), None);
        // Triple root at 0.5: (s − 0.5)³.
        let k = [1.0, -1.5, 0.75, -0.125];
        assert!((first_root_f64(&k, 1e-15, bisect).unwrap() - 0.5).abs() < 1e-5);
        // Root at the exit end.
        let k = [0.0, 0.0, 1.0, -1.0];
        assert_eq!(first_root_f64(&k, 1e-15, bisect), Some(1.0));
    }

    #[test]
    fn monotone_cubics_take_the_one_piece_the_general_path_takes() {
        // Random cubics with roots inside and outside [0, 1]: where the derivative test
        // certifies monotonicity, the short path gives exactly what splitting at the
        // derivative's roots gives (no extremum lies inside [0, 1] then).
        let mut rng = crate::math::rng::Rng::new(17);
        let (mut monotone, mut hits, mut general) = (0, 0, 0);
        for _ in 0..20_000 {
            let r = [0, 1, 2].map(|_| f64::from(rng.range_f32(-1.0, 2.0)));
            let scale = f64::from(rng.range_f32(-3.0, 3.0));
            // scale·(s − r0)(s − r1)(s − r2), or a quadratic or a line.
            let k = match rng.below(3) {
                0 => [
                    scale,
                    -scale * (r[0] + r[1] + r[2]),
                    scale * (r[0] * r[1] + r[1] * r[2] + r[0] * r[2]),
                    -scale * r[0] * r[1] * r[2],
                ],
                1 => [0.0, scale, -scale * (r[0] + r[1]), scale * r[0] * r[1]],
                _ => [0.0, 0.0, scale, -scale * r[0]],
            };
            if k[3] == 0.0 {
                continue;
            }
            let want = first_root_by_pieces(&k, 1e-15, bisect);
            if monotone_on_unit(&k) {
                monotone += 1;
                hits += usize::from(want.is_some());
                assert_eq!(
                    first_root_f64(&k, 1e-15, bisect).map(f64::to_bits),
                    want.map(f64::to_bits),
                    "{k:?}"
                );
                // Monotone: at most one sign change, so no root inside before the found one.
                if let Some(s) = want {
                    assert!((eval64(&k, s * 0.5) > 0.0) == (k[3] > 0.0) || s == 0.0);
                }
            } else {
                general += 1;
            }
        }
        assert!(
            monotone > 5000 && hits > 1000 && general > 2000,
            "{monotone} {hits} {general}"
        );
    }

    #[test]
    fn newton_refinement_lands_within_the_tolerance_of_the_bisected_root() {
        // Random cubics' first crossings, refined to tolerances from 1e-2 to 1e-12: the
        // result lies within `s_tol` of bisection to adjacent doubles on the same piece.
        let mut rng = crate::math::rng::Rng::new(23);
        let mut checked = 0;
        for _ in 0..20_000 {
            let r = [0, 1, 2].map(|_| f64::from(rng.range_f32(-0.5, 1.5)));
            let scale = f64::from(rng.range_f32(-3.0, 3.0));
            let k = [
                scale,
                -scale * (r[0] + r[1] + r[2]),
                scale * (r[0] * r[1] + r[1] * r[2] + r[0] * r[2]),
                -scale * r[0] * r[1] * r[2],
            ];
            if k[3] == 0.0 {
                continue;
            }
            let s_tol = 10f64.powi(-2 - rng.below(11) as i32);
            let tol = 1e-15;
            let truth = first_root_f64(&k, tol, bisect);
            let got = first_root_f64(&k, tol, |k, s0, f0, s1| {
                refine_newton_f64(k, s0, f0, s1, s_tol)
            });
            let (Some(truth), Some(got)) = (truth, got) else {
                assert_eq!(truth.is_some(), got.is_some(), "{k:?}");
                continue;
            };
            assert!(
                (got - truth).abs() <= s_tol,
                "{k:?} {s_tol}: {got} vs {truth}"
            );
            checked += 1;
        }
        assert!(checked > 5000, "{checked}");
        // A triple root (Newton converges only linearly there; the bisection guard holds).
        let k = [1.0, -1.5, 0.75, -0.125];
        let s = refine_newton_f64(&k, 0.0, k[3], 1.0, 1e-6);
        assert!((s - 0.5).abs() <= 1e-6, "{s}");
        // A flat start: the derivative vanishes at the bracket's left end.
        let k = [1.0, 0.0, 0.0, -0.001];
        let s = refine_newton_f64(&k, 0.0, k[3], 1.0, 1e-9);
        assert!((s - 0.1).abs() <= 1e-9, "{s}");
    }

    #[test]
    fn schwarze_solves_three_real_roots() {
        let mut r = [f32::NAN; 3];
        solve_cubic_schwarze([1.0, -1.5, 0.6875, -0.09375], &mut r);
        let mut r: Vec<f32> = r.into_iter().filter(|x| !x.is_nan()).collect();
        r.sort_by(f32::total_cmp);
        assert_eq!(r.len(), 3);
        for (x, t) in r.iter().zip([0.25, 0.5, 0.75]) {
            assert!((x - t).abs() < 1e-5, "{r:?}");
        }
    }

    /// A random segment of a ray from `dist` cells away through cell `lo..lo + 1`, as the
    /// traversal forms it (`f32` slab), or `None` if the ray misses the cell.
    fn random_segment(rnd: &mut impl FnMut() -> f32, lo: Vec3, dist: f32) -> Option<CellSegment> {
        use crate::intersect::{LocalRay, frame::slab};
        let target = lo + Vec3::new(rnd(), rnd(), rnd());
        let dir =
            Vec3::new(rnd() - 0.5, rnd() - 0.5, rnd() - 0.5).normalize() * (1.0 + 100.0 * rnd());
        let origin = target - dir.normalize() * dist;
        let ray = LocalRay::new(origin, dir);
        let hi = lo + Vec3::ONE;
        let (t_near, t_far) = slab(&ray, lo, hi, 0.0, f32::INFINITY)?;
        Some(CellSegment {
            origin,
            dir,
            inv_dir: ray.inv_dir,
            lo,
            hi,
            t_near,
            t_far,
        })
    }

    #[test]
    fn exact_decides_every_segment_as_the_reference_does() {
        // Random cells (a third of them barely straddling the isovalue, so that near-tangent
        // and near-face crossings are common) and rays from near and far (up to 2000 cells,
        // where f32 segment ends err by ~1e-4 cells): the certified early out may only skip
        // segments the f64 slow path misses, the slow path must decide every segment as the
        // reference does, and the early out must still fire on most segments.
        let mut rng = crate::math::rng::Rng::new(0x9e37_79b9_7f4a_7c15);
        let mut rnd = || rng.unit_f32();
        let (mut skipped, mut total, mut hits) = (0, 0, 0);
        for case in 0..200_000 {
            let mut corners: [f32; 8] = std::array::from_fn(|_| 2.0 * rnd() - 1.0);
            if case % 3 == 0 {
                let m = corners.iter().fold(f32::INFINITY, |m, v| m.min(*v));
                corners = corners.map(|v| v - m - 1e-4 * rnd());
            }
            let lo = Vec3::new(
                (rnd() * 500.0).floor(),
                (rnd() * 500.0).floor(),
                (rnd() * 200.0).floor(),
            );
            let dist = [3.0, 50.0, 700.0, 2000.0][case % 4];
            let Some(seg) = random_segment(&mut rnd, lo, dist) else {
                continue;
            };
            total += 1;
            let fast = Exact.first_root(&corners, 0.0, &seg);
            let slow = exact_slow(&corners, 0.0, &seg);
            let truth = Reference.first_root(&corners, 0.0, &seg);
            let cleared = {
                let (g, _) = corner_diffs(&corners, 0.0);
                let (p0, dp) = seg.local_f32();
                let k = cubic_f32(&g, p0, dp);
                bernstein_clear(&k, ExactMargin::new(&g).with_segment(segment_error(&seg)))
            };
            if cleared {
                skipped += 1;
                assert_eq!(
                    slow, None,
                    "case {case}: early out skipped a hit: {corners:?} {seg:?}"
                );
            }
            assert_eq!(fast, slow, "case {case}");
            assert_eq!(
                fast.is_some(),
                truth.is_some(),
                "case {case}: {corners:?} {seg:?}"
            );
            if let (Some(f), Some(t)) = (fast, truth) {
                hits += 1;
                let (tn, tf) = (f64::from(seg.t_near), f64::from(seg.t_far));
                // Within the f32 resolution of the hit's t (what a hit holds).
                let cells = (f - t).abs() * (tf - tn) * f64::from(seg.dir.length());
                let ulp_cells = f64::from(f32::EPSILON * seg.t_far.abs() * seg.dir.length());
                assert!(
                    cells <= ulp_cells + 1e-9,
                    "case {case}: {f} vs {t} ({cells} cells)"
                );
            }
        }
        assert!(hits > 10_000, "{hits} hits of {total}");
        // Most segments without a crossing are cleared by the f32 early out.
        assert!(
            skipped * 10 > (total - hits) * 7,
            "early out fired on {skipped} of {} segments without a hit",
            total - hits
        );
    }

    #[test]
    fn corner_diffs_rescale_extreme_ranges() {
        let big = [3e38f32, -3e38, 1e30, 0.0, 0.0, 0.0, 0.0, 0.0];
        let (g, m) = corner_diffs(&big, 0.0);
        assert!(g.iter().all(|x| x.is_finite()) && m <= 1.0 + 1e-6 && m > 0.5);
        let tiny = [1e-40f32, -2e-40, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];
        let (g, m) = corner_diffs(&tiny, 0.0);
        assert!(m > 0.5 && g[1] < 0.0 && g[0] > 0.0);
        let (_, m) = corner_diffs(&[7u8; 8], 7.0);
        assert_eq!(m, 0.0);
    }
}
