//! Single-ray and large-packet traversal of the implicit BVH (thesis 004 §8.4.2, §8.2.3).
//!
//! ## Packets
//! A packet is any slice of up to [`MAX_PACKET`] rays (the renderer passes 16×16 tiles in
//! Morton order). Rays need not be coherent: every culling step is conservative, so the
//! result equals single-ray traversal for any rays. Per node, in this order:
//! 1. **Implicit culling**: skip the node if its isorange holds no active isovalue. Below a
//!    node that passed the geometric tests, chains of nodes with a single active child are
//!    descended *without* geometric tests; only at bifurcation nodes (both children active)
//!    are the children tested (Fig. 8.2). A live child's first far loads (a leaf's tet
//!    rows, an inner node's right child) are prefetched as soon as it is found live.
//! 2. **Speculative first-active descent**: test only the first active ray; if it hits the
//!    box, descend with the whole packet from that ray on.
//! 3. **Interval-arithmetic frustum test** (Reshetov et al. 2005, seed 000 §3.3): bounds of
//!    the packet's origins and reciprocal directions (per axis where all rays agree in sign)
//!    give a conservative entry/exit interval for the whole packet; if it is empty, no ray
//!    can hit the node.
//! 4. **First-active tracking**: otherwise test the following rays one by one until one hits;
//!    rays before it are known to miss the node and are skipped in the subtree.
//! 5. **Leaves**: per tet, an isorange test per isovalue; the isopolygon is extracted on the
//!    fly (§8.2.4), culled against the packet frustum by its bounds (§8.2.3), then tested
//!    against rays `first..`. A thread keeps the polygons and bounds of the leaves it
//!    visited (`leaf_cache`), which later packets of a tile, its shadow packets and the
//!    next frames at the same isovalues read instead of extracting them again.
//!
//! Refinement: the packet is also split into sub-frusta of 16 consecutive rays (4×4 blocks
//! of a Morton-ordered tile), held in SoA form so that one call tests a box against all 16
//! at once (8 per `f32x8`). The first-active search (4) and the isopolygon culling (5)
//! visit only the sub-frusta that may meet the box or polygon, so a node or polygon much
//! smaller than the packet costs a few block tests instead of a scan over 256 rays.
//! Front-to-back, a sub-frustum's range end is lowered to its rays' nearest hit after each
//! leaf with hits (and the packet's with it): once a region of the packet has found the
//! surface, nodes behind it are culled by one frustum test instead of per-ray tests.
//!
//! Parallel packets (every ray with one direction `d`: shadow rays towards a directional
//! light, an orthographic view) bound each sub-frustum across `d` instead: the extents of its
//! origins along two axes across `d`, and its range along `d` (`o·d + t·|d|²` over its
//! origins and `[t0, t1]`). A box passes when its projection onto each of the three axes
//! meets the sub-frustum's. Shadow rays start on the surface, so a sub-frustum's origins
//! spread over a tilted patch; the box of those origins swept along `d` (what the frustum
//! test bounds) is wider across `d` than the origins themselves.
//!
//! The rays are held as 8-wide SoA blocks (`tet/simd.rs`): the first-active search tests
//! 8 rays per step and each isopolygon is tested against 8 rays at once, with results
//! bit-identical to the scalar tests. A block's watertight ray space (dominant axis, shear:
//! three divisions) is set up at its first isopolygon test, so blocks that never reach one
//! skip it. A packet whose root isorange holds no isovalue returns before any per-ray
//! setup; one whose frustum misses the root box right after the block and sub-frustum setup.
//!
//! Transparent surfaces: the large packets can also keep each ray's nearest hits up to its
//! first hit on an opaque surface (`RayLayers`, thesis 004 §8.6), its range end lowered to
//! that hit, so one traversal finds all the layers that a new packet per layer would.
//!
//! Shadow rays: the large packets can also close each ray's range at the first hit found,
//! not the nearest (`Occluded`, an any-hit query), so a sub-frustum whose rays are all
//! closed culls every node after, and the walk ends once every range is closed.
//!
//! Packets of at most 4 rays run the *standard* packet traversal instead (every ray tested
//! at every node with the scalar slab test, descend if any hits; one extraction per tet for
//! the packet): the 2×2 baseline of Table 8.4.
//!
//! ## Statistics
//! `box_test` counts individual ray–box tests (an interval frustum test counts as one, the
//! all-sub-frusta test as the number of sub-frusta it tests, an 8-wide block test as the
//! number of rays it tests),
//! `intersection` ray–isopolygon tests, `extraction` isopolygon extractions, `node` and
//! `leaf` visits.

use std::cell::RefCell;

use glam::{BVec3A, Vec3, Vec3A, Vec4};
use wide::f32x8;

use super::bvh::{BvhNode, MAX_DEPTH, TetBvh};
use super::leaf_cache::{LeafCache, LeafPoly};
use super::mt::{self, IsoPoly, RaySpace};
use super::simd::{LANES, RayBlock, poly8, slab8};
use crate::math::{Ray, float::gamma_f32, prefetch};
use crate::render::{Hit, MAX_PEELED, Peel, PeeledHits, Stats};

/// Largest packet traced at once (16×16).
pub const MAX_PACKET: usize = 256;
/// Rays per sub-frustum (a 4×4 block of a Morton-ordered tile).
const GROUP: usize = 16;
const MAX_GROUPS: usize = MAX_PACKET / GROUP;
const MAX_BLOCKS: usize = MAX_PACKET / LANES;

/// A hit before shading: ray parameter, isovalue index and tet (leaf order).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RawHit {
    pub t: f32,
    pub surface: u32,
    pub tet: u32,
}

/// Where the large-packet traversal puts the hits it finds within a ray's range: the
/// ray's nearest hit ([`Nearest`]) or its layers ([`RayLayers`]).
pub(crate) trait LaneHits {
    /// Takes ray `r`'s hit (with its faceted normal on demand): the ray's new range end when
    /// the hit lowers it (hits past it cannot matter), else `None`.
    fn take(&mut self, r: usize, hit: RawHit, normal: impl FnOnce() -> Vec3) -> Option<f32>;
}

/// Each ray's nearest hit, and with `N` its faceted normal.
struct Nearest<'a, const N: bool> {
    out: &'a mut [Option<RawHit>],
    normals: &'a mut [Vec3],
}

impl<const N: bool> LaneHits for Nearest<'_, N> {
    #[inline(always)]
    fn take(&mut self, r: usize, hit: RawHit, normal: impl FnOnce() -> Vec3) -> Option<f32> {
        if !self.out[r].is_none_or(|h| hit.t < h.t) {
            return None;
        }
        self.out[r] = Some(hit);
        if N {
            self.normals[r] = normal();
        }
        Some(hit.t)
    }
}

/// The range end of a ray that [`Occluded`] has closed: below every `t`, and finite, so
/// that the frustum tests' rounding margins stay finite and cull past it.
const CLOSED: f32 = -f32::MAX;

/// Whether each ray has any hit: a ray's range closes at the first hit found, not the
/// nearest (an any-hit query, as shadow rays need), so the rest of the walk skips it and a
/// sub-frustum whose rays are all closed culls every node after.
struct Occluded<'a> {
    out: &'a mut [bool],
}

impl LaneHits for Occluded<'_> {
    #[inline(always)]
    fn take(&mut self, r: usize, _hit: RawHit, _normal: impl FnOnce() -> Vec3) -> Option<f32> {
        self.out[r] = true;
        Some(CLOSED)
    }
}

/// Room per ray in [`RayLayers`]: the most layers a call returns, and as many again for the
/// same crossing found in two tets (a ray through a shared edge).
const LAYER_SLOTS: usize = 2 * MAX_PEELED;

/// Each ray's nearest hits, front to back, up to its first hit on an opaque surface
/// ([`Peel`]), for transparent surfaces in one traversal: the layers that new rays from
/// past each layer ([`Peel::next_t`]) would find, since a tet hit's `t` does not depend on
/// where the ray starts ([`RayLayers::peeled`]). A ray's range end drops to its opaque hit,
/// or to its last kept hit once [`LAYER_SLOTS`] are full. With `faceted`, each kept hit's
/// faceted normal is kept too (no second extraction).
pub(crate) struct RayLayers {
    peel: Peel,
    faceted: bool,
    n: [u8; MAX_PACKET],
    hits: Box<[[RawHit; LAYER_SLOTS]]>,
    normals: Box<[[Vec3; LAYER_SLOTS]]>,
    /// Each ray's range end: its `t_max`, then lowered.
    end: [f32; MAX_PACKET],
    t_max: [f32; MAX_PACKET],
}

impl RayLayers {
    pub(crate) fn new(peel: &Peel, faceted: bool) -> Self {
        const NONE: RawHit = RawHit {
            t: f32::INFINITY,
            surface: 0,
            tet: 0,
        };
        Self {
            peel: *peel,
            faceted,
            n: [0; MAX_PACKET],
            hits: vec![[NONE; LAYER_SLOTS]; MAX_PACKET].into_boxed_slice(),
            normals: vec![[Vec3::Z; LAYER_SLOTS]; MAX_PACKET].into_boxed_slice(),
            end: [0.0; MAX_PACKET],
            t_max: [0.0; MAX_PACKET],
        }
    }

    fn reset(&mut self, t_max: &[f32]) {
        let len = t_max.len();
        self.n[..len].fill(0);
        self.end[..len].copy_from_slice(t_max);
        self.t_max[..len].copy_from_slice(t_max);
    }

    /// Ray `r`'s kept hits, front to back.
    pub(crate) fn of(&self, r: usize) -> &[RawHit] {
        &self.hits[r][..usize::from(self.n[r])]
    }

    /// Ray `r`'s layers, front to back: the nearest hit, then each next one at or past
    /// [`Peel::next_t`] of the last, until an opaque one or [`Peel`]'s cap; `more` when
    /// the ray may hit more past the last (the caller asks again from there), as
    /// first-hit searches from each layer on would give. `hit` makes each layer's [`Hit`]
    /// from the raw hit and its kept faceted normal (unspecified without `faceted`).
    pub(crate) fn peeled(&self, r: usize, mut hit: impl FnMut(&RawHit, Vec3) -> Hit) -> PeeledHits {
        let mut out = PeeledHits::NONE;
        let mut last: Option<f32> = None;
        for (h, &normal) in self.of(r).iter().zip(&self.normals[r]) {
            if last.is_some_and(|t| h.t < self.peel.next_t(t)) {
                continue;
            }
            out.push(hit(h, normal));
            last = Some(h.t);
            if self.peel.ends_ray(h.surface) {
                return out;
            }
            if out.n as usize == self.peel.cap() {
                out.more = true;
                return out;
            }
        }
        // Past a lowered range end, hits were not kept.
        out.more = out.n > 0 && self.end[r] < self.t_max[r];
        out
    }
}

impl LaneHits for RayLayers {
    #[inline]
    fn take(&mut self, r: usize, hit: RawHit, normal: impl FnOnce() -> Vec3) -> Option<f32> {
        let (list, n) = (&mut self.hits[r], usize::from(self.n[r]));
        // After hits at the same `t` (the first found stays first, as for a nearest hit).
        let mut i = n;
        while i > 0 && list[i - 1].t > hit.t {
            i -= 1;
        }
        if i == LAYER_SLOTS {
            return None;
        }
        let kept = (n + 1).min(LAYER_SLOTS);
        list.copy_within(i..kept - 1, i + 1);
        list[i] = hit;
        if self.faceted {
            let normals = &mut self.normals[r];
            normals.copy_within(i..kept - 1, i + 1);
            normals[i] = normal();
        }
        let mut end = self.end[r];
        let kept = if self.peel.ends_ray(hit.surface) {
            end = end.min(hit.t);
            i + 1
        } else {
            kept
        };
        self.n[r] = kept as u8;
        if kept == LAYER_SLOTS {
            end = end.min(list[LAYER_SLOTS - 1].t);
        }
        (end < self.end[r]).then(|| {
            self.end[r] = end;
            end
        })
    }
}

#[inline]
fn iso_active(lo: f32, hi: f32, iso: &[f32]) -> bool {
    iso.iter().any(|&c| lo <= c && c <= hi)
}

/// Conservative slab test of `[t0, t1]` against the node's spatial box (as [`crate::math::Aabb`]).
#[inline]
pub(crate) fn slab(n: &BvhNode, ray: &Ray, t0: f32, t1: f32) -> bool {
    let a = (n.lo.truncate() - ray.origin) * ray.inv_dir;
    let b = (n.hi.truncate() - ray.origin) * ray.inv_dir;
    let near = a.min(b);
    let far = a.max(b) * (1.0 + 2.0 * gamma_f32(3));
    near.max_element().max(t0) <= far.min_element().min(t1)
}

/// Interval bounds of a packet for the conservative frustum test, in SIMD lanes (`Vec3A`)
/// as [`Frustum::misses`] reads them.
#[derive(Clone, Copy)]
struct Frustum {
    omin: Vec3A,
    omax: Vec3A,
    imin: Vec3A,
    imax: Vec3A,
    /// The axes tested: finite reciprocals of one sign.
    axis: BVec3A,
    t0: f32,
    t1: f32,
}

/// The axes whose reciprocal directions have both signs: their reciprocal interval would
/// span infinity, so a frustum leaves them untested.
#[inline]
fn mixed_signs(imin: Vec3A, imax: Vec3A) -> BVec3A {
    imin.cmplt(Vec3A::ZERO) & imax.cmpgt(Vec3A::ZERO)
}

impl Frustum {
    const NONE: Frustum = Frustum {
        omin: Vec3A::ZERO,
        omax: Vec3A::ZERO,
        imin: Vec3A::ZERO,
        imax: Vec3A::ZERO,
        axis: BVec3A::FALSE,
        t0: f32::NEG_INFINITY,
        t1: f32::INFINITY,
    };

    #[cfg(test)]
    fn new(rays: &[Ray], t_min: &[f32], t_max: &[f32]) -> Self {
        let mut f = Frustum {
            omin: Vec3A::INFINITY,
            omax: Vec3A::NEG_INFINITY,
            imin: Vec3A::INFINITY,
            imax: Vec3A::NEG_INFINITY,
            axis: BVec3A::TRUE,
            t0: f32::INFINITY,
            t1: f32::NEG_INFINITY,
        };
        let mut axis = [true; 3];
        for (i, r) in rays.iter().enumerate() {
            f.omin = f.omin.min(r.origin.into());
            f.omax = f.omax.max(r.origin.into());
            f.imin = f.imin.min(r.inv_dir.into());
            f.imax = f.imax.max(r.inv_dir.into());
            f.t0 = f.t0.min(t_min[i]);
            f.t1 = f.t1.max(t_max[i]);
            if !r.origin.is_finite() {
                axis = [false; 3];
            }
            for (a, used) in axis.iter_mut().enumerate() {
                if !r.inv_dir[a].is_finite() || r.dir[a] == 0.0 {
                    *used = false;
                }
            }
        }
        f.axis = BVec3A::from(axis) & !mixed_signs(f.imin, f.imax);
        // NaN ranges: never cull.
        if f.t0.is_nan() || f.t1.is_nan() {
            f.t0 = f32::NEG_INFINITY;
            f.t1 = f32::INFINITY;
        }
        f
    }

    /// The frustum of the rays of `blocks` (padding lanes repeat lane 0; `t1` holds their
    /// `t_max`, `-inf` in padding lanes), computed 8 lanes at a time. Same result as
    /// [`Frustum::new`] on the rays.
    fn from_blocks(blocks: &[RayBlock], t1: &[f32x8]) -> Self {
        let b0 = &blocks[0];
        // Rows: origin xyz, reciprocal xyz, range end, unused.
        let mut lo = [
            b0.o[0], b0.o[1], b0.o[2], b0.inv[0], b0.inv[1], b0.inv[2], b0.t0, b0.t0,
        ];
        let mut hi = [
            b0.o[0], b0.o[1], b0.o[2], b0.inv[0], b0.inv[1], b0.inv[2], t1[0], t1[0],
        ];
        let mut bad_o = 0u32;
        let mut bad_i = [0u32; 3];
        for (b, t) in blocks.iter().zip(t1) {
            for a in 0..3 {
                lo[a] = lo[a].min(b.o[a]);
                hi[a] = hi[a].max(b.o[a]);
                lo[3 + a] = lo[3 + a].min(b.inv[a]);
                hi[3 + a] = hi[3 + a].max(b.inv[a]);
                bad_o |= !b.o[a].is_finite().to_bitmask() & 0xff;
                bad_i[a] |= !b.inv[a].is_finite().to_bitmask() & 0xff;
            }
            lo[6] = lo[6].min(b.t0);
            hi[6] = hi[6].max(*t);
        }
        // Horizontal min/max of all rows at once: transpose, then reduce the 8 columns.
        // `f32x8::min`/`max` skip NaN lanes, as `f32::min`/`max` do.
        let lo = f32x8::transpose(lo)
            .into_iter()
            .fold(f32x8::INFINITY, f32x8::min)
            .to_array();
        let hi = f32x8::transpose(hi)
            .into_iter()
            .fold(f32x8::NEG_INFINITY, f32x8::max)
            .to_array();
        let mut f = Frustum {
            omin: Vec3A::new(lo[0], lo[1], lo[2]),
            omax: Vec3A::new(hi[0], hi[1], hi[2]),
            imin: Vec3A::new(lo[3], lo[4], lo[5]),
            imax: Vec3A::new(hi[3], hi[4], hi[5]),
            axis: BVec3A::FALSE,
            t0: lo[6],
            t1: hi[6],
        };
        // Zero direction components have infinite reciprocals.
        f.axis = BVec3A::from(std::array::from_fn::<bool, 3, _>(|a| {
            bad_o == 0 && bad_i[a] == 0
        })) & !mixed_signs(f.imin, f.imax);
        if f.t0.is_nan() || f.t1.is_nan() {
            f.t0 = f32::NEG_INFINITY;
            f.t1 = f32::INFINITY;
        }
        f
    }

    /// The frustum of the union of the groups' rays.
    fn union(groups: &[Frustum]) -> Self {
        let mut f = groups[0];
        for g in &groups[1..] {
            f.omin = f.omin.min(g.omin);
            f.omax = f.omax.max(g.omax);
            f.imin = f.imin.min(g.imin);
            f.imax = f.imax.max(g.imax);
            f.t0 = f.t0.min(g.t0);
            f.t1 = f.t1.max(g.t1);
            f.axis = f.axis & g.axis & !mixed_signs(f.imin, f.imax);
        }
        f
    }

    /// True when no ray of the packet can meet the box `[lo, hi]` within its range: the
    /// three axes of [`Frustum::misses_by_axis`] side by side in SIMD lanes, the same
    /// products, minima and maxima per axis (no NaN arises on an axis that is tested: its
    /// reciprocals are finite and of one sign), so the same answer (tested).
    #[inline]
    fn misses(&self, lo: Vec3A, hi: Vec3A) -> bool {
        let (i0, i1) = (self.imin, self.imax);
        let (omin, omax) = (self.omin, self.omax);
        let pos = i0.cmpgt(Vec3A::ZERO);
        let near = Vec3A::select(pos, lo, hi);
        let far = Vec3A::select(pos, hi, lo);
        let (x0, x1) = (near - omax, near - omin);
        let tn = (x0 * i0).min(x0 * i1).min(x1 * i0).min(x1 * i1);
        let (y0, y1) = (far - omax, far - omin);
        let tf = (y0 * i0).max(y0 * i1).max(y1 * i0).max(y1 * i1);
        let tn = Vec3A::select(self.axis, tn, Vec3A::NEG_INFINITY);
        let tf = Vec3A::select(self.axis, tf, Vec3A::INFINITY);
        let enter = self.t0.max(tn.max_element());
        let exit = self.t1.min(tf.min_element());
        // Margin for rounding (the products above are rounded like the per-ray slab test).
        enter - exit > 1e-5 * enter.abs().max(exit.abs()) + 1e-30
    }

    /// [`Frustum::misses`] one axis at a time (its twin in the tests).
    #[cfg(test)]
    fn misses_by_axis(&self, lo: Vec3A, hi: Vec3A) -> bool {
        let mut enter = self.t0;
        let mut exit = self.t1;
        for a in 0..3 {
            if !self.axis.test(a) {
                continue;
            }
            let (near, far) = if self.imin[a] > 0.0 {
                (lo[a], hi[a])
            } else {
                (hi[a], lo[a])
            };
            let (i0, i1) = (self.imin[a], self.imax[a]);
            let (x0, x1) = (near - self.omax[a], near - self.omin[a]);
            let tn = (x0 * i0).min(x0 * i1).min(x1 * i0).min(x1 * i1);
            let (y0, y1) = (far - self.omax[a], far - self.omin[a]);
            let tf = (y0 * i0).max(y0 * i1).max(y1 * i0).max(y1 * i1);
            enter = enter.max(tn);
            exit = exit.min(tf);
        }
        // Margin for rounding (the products above are rounded like the per-ray slab test).
        enter - exit > 1e-5 * enter.abs().max(exit.abs()) + 1e-30
    }
}

/// The sub-frusta of a packet in SoA form, 8 groups per `f32x8`: [`GroupSet::hits`] tests a
/// box against all 16 at once with the operations of [`Frustum::misses`] per lane.
#[derive(Clone, Copy)]
struct GroupSet {
    /// Per half (groups 0–7, 8–15): origin min/max, reciprocal min/max per axis.
    omin: [[f32x8; 3]; 2],
    omax: [[f32x8; 3]; 2],
    imin: [[f32x8; 3]; 2],
    imax: [[f32x8; 3]; 2],
    /// All-ones lanes where the axis is used (as `Frustum::axis`).
    axis: [[f32x8; 3]; 2],
    t0: [f32x8; 2],
    t1: [f32x8; 2],
    /// Per half: all its groups' origin bounds are single points (`omin == omax`).
    common_origin: [bool; 2],
    /// Bit `g` set for the groups in use.
    valid: u32,
}

/// The sub-frusta of a parallel packet (module docs) across and along its direction `d`:
/// axis 0 and 1 are unit vectors across `d`, axis 2 is `d` itself. The traversal is
/// instantiated for parallel packets and for the others ([`TetView::trace_large`]), so a
/// perspective packet never asks which kind it is.
#[derive(Clone, Copy)]
struct Parallel {
    axes: [Vec3A; 3],
    abs_axes: [Vec3A; 3],
    /// `|d|²`.
    dd: f32,
    /// Per half and axis: each group's least and greatest origin coordinate.
    lo: [[f32x8; 3]; 2],
    hi: [[f32x8; 3]; 2],
    /// Rounding margin (world units): far above the error of the projections.
    margin: f32,
}

/// The direction every ray of `rays` has, when it is finite and can be normalised and every
/// origin is finite (a perspective packet stops at its second ray).
fn common_direction(rays: &[Ray]) -> Option<Vec3> {
    let d = rays.first()?.dir;
    let same = rays.iter().all(|r| r.dir == d && r.origin.is_finite());
    (same && d.is_finite() && d.try_normalize().is_some()).then_some(d)
}

impl Parallel {
    /// Zeros (unused by packets that are not parallel).
    const NONE: Parallel = Parallel {
        axes: [Vec3A::ZERO; 3],
        abs_axes: [Vec3A::ZERO; 3],
        dd: 0.0,
        lo: [[f32x8::ZERO; 3]; 2],
        hi: [[f32x8::ZERO; 3]; 2],
        margin: 0.0,
    };

    /// The tests across `d`, the direction every ray of a packet has ([`common_direction`]):
    /// each group's origin extents from `blocks` (the packet's `len` rays, padding lanes
    /// repeating lane 0), and a margin for coordinates up to `scale` in magnitude (the
    /// scene's and the origins').
    fn from_blocks(blocks: &[RayBlock], len: usize, d: Vec3, scale: f32) -> Self {
        let (u, w) = d.normalize().any_orthonormal_pair();
        let axes = [u, w, d].map(Vec3A::from);
        // Unused groups: an empty extent.
        let mut lo = [[f32::INFINITY; MAX_GROUPS]; 3];
        let mut hi = [[f32::NEG_INFINITY; MAX_GROUPS]; 3];
        // A group's blocks side by side, then across the lanes.
        for (g, group) in blocks[..len.div_ceil(LANES)]
            .chunks(GROUP / LANES)
            .enumerate()
        {
            for a in 0..3 {
                let x = axes[a];
                let (mut l, mut h) = (f32x8::INFINITY, f32x8::NEG_INFINITY);
                for blk in group {
                    let p = (blk.o[0] * f32x8::splat(x.x) + blk.o[1] * f32x8::splat(x.y))
                        + blk.o[2] * f32x8::splat(x.z);
                    (l, h) = (l.min(p), h.max(p));
                }
                lo[a][g] = l.to_array().into_iter().fold(f32::INFINITY, f32::min);
                hi[a][g] = h.to_array().into_iter().fold(f32::NEG_INFINITY, f32::max);
            }
        }
        let half = |row: &[f32; MAX_GROUPS], h: usize| {
            f32x8::new(std::array::from_fn(|l| row[h * LANES + l]))
        };
        let magnitude = scale * (2.0 + d.abs().element_sum()) + d.length_squared();
        Parallel {
            axes,
            abs_axes: axes.map(Vec3A::abs),
            dd: d.length_squared(),
            lo: [0, 1].map(|h| [0, 1, 2].map(|a| half(&lo[a], h))),
            hi: [0, 1].map(|h| [0, 1, 2].map(|a| half(&hi[a], h))),
            margin: 1e-4 * magnitude + 1e-30,
        }
    }

    /// The box `[lo, hi]` projected onto each axis: its least and greatest coordinate there
    /// (centre and half-extent, so the projection's own rounding is below the margin).
    #[inline(always)]
    fn project(&self, lo: Vec3A, hi: Vec3A) -> [[f32x8; 2]; 3] {
        let c = (lo + hi) * 0.5;
        let e = (hi - lo) * 0.5;
        [0, 1, 2].map(|a| {
            let (pc, r) = (c.dot(self.axes[a]), e.dot(self.abs_axes[a]));
            [f32x8::splat(pc - r), f32x8::splat(pc + r)]
        })
    }
}

impl GroupSet {
    const NONE: GroupSet = GroupSet {
        omin: [[f32x8::ZERO; 3]; 2],
        omax: [[f32x8::ZERO; 3]; 2],
        imin: [[f32x8::ZERO; 3]; 2],
        imax: [[f32x8::ZERO; 3]; 2],
        axis: [[f32x8::ZERO; 3]; 2],
        t0: [f32x8::ZERO; 2],
        t1: [f32x8::ZERO; 2],
        common_origin: [false; 2],
        valid: 0,
    };

    fn new(groups: &[Frustum]) -> Self {
        debug_assert!(groups.len() <= MAX_GROUPS);
        // Rows: omin xyz, omax xyz, imin xyz, imax xyz, axis xyz, t0, t1.
        let mut r = [[0f32; MAX_GROUPS]; 17];
        // Unused groups: an empty range (their bits are also cleared by `valid`).
        r[15] = [f32::INFINITY; MAX_GROUPS];
        r[16] = [f32::NEG_INFINITY; MAX_GROUPS];
        for (g, f) in groups.iter().enumerate() {
            for a in 0..3 {
                r[a][g] = f.omin[a];
                r[3 + a][g] = f.omax[a];
                r[6 + a][g] = f.imin[a];
                r[9 + a][g] = f.imax[a];
                r[12 + a][g] = f32::from_bits(if f.axis.test(a) { u32::MAX } else { 0 });
            }
            r[15][g] = f.t0;
            r[16][g] = f.t1;
        }
        let half = |row: &[f32; MAX_GROUPS], h: usize| {
            f32x8::new(std::array::from_fn(|l| row[h * LANES + l]))
        };
        let xyz = |k: usize| [0, 1].map(|h| [0, 1, 2].map(|a| half(&r[k + a], h)));
        // Unused groups hold 0 for both bounds: equal.
        let common_origin = [0, 1].map(|h| {
            (0..3).all(|a| {
                (h * LANES..(h + 1) * LANES).all(|g| r[a][g].to_bits() == r[3 + a][g].to_bits())
            })
        });
        GroupSet {
            common_origin,
            omin: xyz(0),
            omax: xyz(3),
            imin: xyz(6),
            imax: xyz(9),
            axis: xyz(12),
            t0: [0, 1].map(|h| half(&r[15], h)),
            t1: [0, 1].map(|h| half(&r[16], h)),
            valid: (1u32 << groups.len()) - 1,
        }
    }

    /// Bit `g` set for the groups in `want` that may meet the box `[lo, hi]` (`!misses`,
    /// conservative). Halves (groups 0–7, 8–15) without a wanted group are skipped.
    /// With `PAR` the packet is parallel and its groups are tested across its direction
    /// (`par`, [`GroupSet::half_misses_parallel`]); otherwise `par` is not read.
    #[inline(always)]
    fn hits<const PAR: bool>(&self, par: &Parallel, lo: Vec3A, hi: Vec3A, want: u32) -> u32 {
        let want = want & self.valid;
        // A parallel packet's box projections, once for both halves.
        let proj = if PAR {
            par.project(lo, hi)
        } else {
            [[f32x8::ZERO; 2]; 3]
        };
        let mut m = 0;
        for h in 0..2 {
            // The 8 group bits of this half.
            if (want >> (h * LANES)) as u8 == 0 {
                continue;
            }
            let miss = if PAR {
                self.half_misses_parallel(par, h, &proj)
            } else if self.common_origin[h] {
                self.half_misses::<true>(h, lo, hi)
            } else {
                self.half_misses::<false>(h, lo, hi)
            };
            m |= (!miss & 0xff) << (h * LANES);
        }
        m & want
    }

    /// `Frustum::misses` for the 8 groups of half `h`, as a lane mask. With `COMMON` (every
    /// group's origin bounds are one point, as for pinhole rays) `near - omax` and
    /// `near - omin` are equal, so two of the four products per bound are dropped: the
    /// minimum and maximum are the same values and the test the same.
    #[inline]
    fn half_misses<const COMMON: bool>(&self, h: usize, lo: Vec3A, hi: Vec3A) -> u32 {
        let zero = f32x8::ZERO;
        let mut enter = self.t0[h];
        let mut exit = self.t1[h];
        for a in 0..3 {
            let (i0, i1) = (self.imin[h][a], self.imax[h][a]);
            let (l, u) = (f32x8::splat(lo[a]), f32x8::splat(hi[a]));
            let pos = i0.simd_gt(zero);
            let near = pos.select(l, u);
            let far = pos.select(u, l);
            let (tn, tf) = if COMMON {
                let x = near - self.omax[h][a];
                let y = far - self.omax[h][a];
                ((x * i0).min(x * i1), (y * i0).max(y * i1))
            } else {
                let (x0, x1) = (near - self.omax[h][a], near - self.omin[h][a]);
                let (y0, y1) = (far - self.omax[h][a], far - self.omin[h][a]);
                (
                    (x0 * i0).min(x0 * i1).min(x1 * i0).min(x1 * i1),
                    (y0 * i0).max(y0 * i1).max(y1 * i0).max(y1 * i1),
                )
            };
            let used = self.axis[h][a];
            enter = enter.max(used.select(tn, f32x8::NEG_INFINITY));
            exit = exit.min(used.select(tf, f32x8::INFINITY));
        }
        let margin = f32x8::splat(1e-5) * enter.abs().max(exit.abs()) + f32x8::splat(1e-30);
        (enter - exit).simd_gt(margin).to_bitmask()
    }

    /// The groups of half `h` that the box `[lo, hi]` misses, as a lane mask, for a parallel
    /// packet: a ray `o + t·d` of a group that meets the box at `t ∈ [t0, t1]` meets it at a
    /// point whose coordinate across `d` is its origin's (`d·u` vanishes up to rounding) and
    /// whose coordinate along `d` is `o·d + t·|d|²`; the box's projection onto each axis must
    /// meet the group's, up to the margin. `proj` holds the box's projections onto the three
    /// axes ([`Parallel::project`]), made once for both halves.
    #[inline]
    fn half_misses_parallel(&self, p: &Parallel, h: usize, proj: &[[f32x8; 2]; 3]) -> u32 {
        let m = f32x8::splat(p.margin);
        let dd = f32x8::splat(p.dd);
        let mut meets = 0xffu32;
        for (a, &[box_lo, box_hi]) in proj.iter().enumerate() {
            let (g_lo, g_hi) = if a == 2 {
                (p.lo[h][2] + self.t0[h] * dd, p.hi[h][2] + self.t1[h] * dd)
            } else {
                (p.lo[h][a], p.hi[h][a])
            };
            meets &= (box_hi.simd_ge(g_lo - m) & box_lo.simd_le(g_hi + m)).to_bitmask();
        }
        !meets & 0xff
    }

    /// Lowers group `g`'s range end to `t1` (after hits shortened its rays).
    #[inline]
    fn set_t1(&mut self, g: usize, t1: f32) {
        self.t1[g / LANES].as_mut_array()[g % LANES] = t1;
    }
}

/// What the traversal reads of a [`super::TetScene`]: the vertices (position and value),
/// the tets in leaf order and the BVH over them.
#[derive(Clone, Copy)]
pub(crate) struct TetView<'a> {
    pub verts: &'a [Vec4],
    pub tets: &'a [[u32; 4]],
    pub bvh: &'a TetBvh,
    /// The scene state's number ([`super::TetScene`]), the leaf cache's key.
    pub generation: u64,
}

impl TetView<'_> {
    /// Faceted shading normal of a raw hit: its tet's isopolygon extracted again.
    pub(crate) fn faceted_normal(&self, h: &RawHit, iso: &[f32]) -> Vec3 {
        let ids = &self.tets[h.tet as usize];
        let v = ids.map(|i| self.verts[i as usize]);
        let c = iso[h.surface as usize];
        mt::extract(&v, ids, c).map_or(Vec3::Z, |p| p.oriented_normal(&v, c))
    }

    /// Calls `f(tet, surface, vertices, polygon, stats)` for every non-empty isopolygon of
    /// the leaf's tets: per tet an isorange test per isovalue, then the on-the-fly extraction
    /// (§8.2.4); NaN-valued tets are void. The one leaf prologue of all traversals.
    #[inline]
    fn leaf_polys<S: Stats>(
        &self,
        n: &BvhNode,
        iso: &[f32],
        stats: &mut S,
        mut f: impl FnMut(u32, u32, &[Vec4; 4], &IsoPoly, &mut S),
    ) {
        for ti in n.link..n.link + n.count {
            let ids = &self.tets[ti as usize];
            let v = ids.map(|i| self.verts[i as usize]);
            if v.iter().any(|p| p.w.is_nan()) {
                continue;
            }
            for (s, &c) in iso.iter().enumerate() {
                // Cases 0 and 15 (no corner above `c`, or all) have no polygon: the
                // isorange test without the tet's minimum and maximum.
                let case = mt::case_index(&v, c);
                if case == 0 || case == 15 {
                    continue;
                }
                stats.extraction();
                if let Some(poly) = mt::extract_case(&v, ids, c, case) {
                    f(ti, s as u32, &v, &poly, stats);
                }
            }
        }
    }

    /// Tests the isopolygons of leaf tets against one ray, updating `best`.
    #[inline]
    fn leaf_single<S: Stats>(
        &self,
        n: &BvhNode,
        rs: &RaySpace,
        t_min: f32,
        best: &mut f32,
        hit: &mut Option<RawHit>,
        iso: &[f32],
        stats: &mut S,
    ) {
        self.leaf_polys(n, iso, stats, |ti, s, _, poly, stats| {
            stats.intersection();
            if let Some(t) = mt::intersect(rs, poly)
                && t >= t_min
                && t <= *best
                && hit.is_none_or(|h| t < h.t)
            {
                *best = t;
                *hit = Some(RawHit {
                    t,
                    surface: s,
                    tet: ti,
                });
            }
        });
    }

    /// Front-to-back single-ray traversal. With `ANY`, returns at the first hit found.
    pub(crate) fn trace_single<S: Stats, const ANY: bool>(
        &self,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
        iso: &[f32],
        stats: &mut S,
    ) -> Option<RawHit> {
        stats.ray();
        let rs = RaySpace::new(ray.origin, ray.dir);
        if !rs.valid || iso.is_empty() || self.tets.is_empty() {
            return None;
        }
        let nodes = &self.bvh.nodes;
        let mut best = t_max;
        let mut hit = None;
        let mut stack = [0u32; MAX_DEPTH + 1];
        let mut sp = 0;
        let mut node = 0u32;
        loop {
            let n = &nodes[node as usize];
            stats.node();
            if iso_active(n.lo.w, n.hi.w, iso) && {
                stats.box_test(1);
                slab(n, ray, t_min, best)
            } {
                if n.is_leaf() {
                    stats.leaf();
                    self.leaf_single(n, &rs, t_min, &mut best, &mut hit, iso, stats);
                    if ANY && hit.is_some() {
                        return hit;
                    }
                } else {
                    let (near, far) = if ray.dir[n.axis as usize] >= 0.0 {
                        (node + 1, n.link)
                    } else {
                        (n.link, node + 1)
                    };
                    stack[sp] = far;
                    sp += 1;
                    node = near;
                    continue;
                }
            }
            if sp == 0 {
                return hit;
            }
            sp -= 1;
            node = stack[sp];
        }
    }

    /// Packet traversal (module docs) of at most [`MAX_PACKET`] rays; `out[i]` gets ray `i`'s
    /// first hit.
    pub(crate) fn trace_packet<S: Stats>(
        &self,
        rays: &[Ray],
        t_min: &[f32],
        t_max: &[f32],
        iso: &[f32],
        out: &mut [Option<RawHit>],
        stats: &mut S,
    ) {
        self.trace_packet_impl::<S, false>(rays, t_min, t_max, iso, out, &mut [], stats);
    }

    /// [`TetView::trace_packet`] that also writes the faceted shading normal of each ray's
    /// hit into `normals[i]` (entries of rays without a hit are unspecified). The large
    /// packets take it from the polygon when the hit is recorded, instead of extracting the
    /// polygon again afterwards; the result is the same ([`IsoPoly::oriented_normal`]).
    pub(crate) fn trace_packet_faceted<S: Stats>(
        &self,
        rays: &[Ray],
        t_min: &[f32],
        t_max: &[f32],
        iso: &[f32],
        out: &mut [Option<RawHit>],
        normals: &mut [Vec3],
        stats: &mut S,
    ) {
        assert!(normals.len() >= rays.len());
        self.trace_packet_impl::<S, true>(rays, t_min, t_max, iso, out, normals, stats);
    }

    #[allow(clippy::too_many_arguments)]
    #[inline]
    fn trace_packet_impl<S: Stats, const N: bool>(
        &self,
        rays: &[Ray],
        t_min: &[f32],
        t_max: &[f32],
        iso: &[f32],
        out: &mut [Option<RawHit>],
        normals: &mut [Vec3],
        stats: &mut S,
    ) {
        if !self.packet_start(rays, t_min, t_max, iso, out, None, stats) {
            return;
        }
        let len = rays.len();
        if len <= 4 {
            self.trace_standard(rays, t_min, t_max, iso, out, stats);
            if N {
                for (h, nrm) in out[..len].iter().zip(normals.iter_mut()) {
                    if let Some(h) = h {
                        *nrm = self.faceted_normal(h, iso);
                    }
                }
            }
        } else {
            let mut nearest = Nearest::<N> { out, normals };
            self.trace_large_scratch(rays, t_min, t_max, iso, &mut nearest, stats);
        }
    }

    /// Packet traversal of at most [`MAX_PACKET`] rays that only asks whether each ray hits
    /// anything in its range (`out[i]`): large packets stop each ray at the first hit found
    /// ([`Occluded`]); packets of at most 4 rays take the 2×2 baseline's first hits.
    pub(crate) fn trace_packet_occluded<S: Stats>(
        &self,
        rays: &[Ray],
        t_min: &[f32],
        t_max: &[f32],
        iso: &[f32],
        out: &mut [bool],
        stats: &mut S,
    ) {
        if !self.packet_start(rays, t_min, t_max, iso, out, false, stats) {
            return;
        }
        let len = rays.len();
        if len <= 4 {
            let mut first = [None; 4];
            self.trace_standard(rays, t_min, t_max, iso, &mut first[..len], stats);
            for (o, h) in out.iter_mut().zip(&first[..len]) {
                *o = h.is_some();
            }
        } else {
            self.trace_large_scratch(rays, t_min, t_max, iso, &mut Occluded { out }, stats);
        }
    }

    /// The large-packet traversal of more than 4 rays (at most [`MAX_PACKET`]) that collects
    /// each ray's hits in `layers` (its nearest ones, up to the first opaque one, for
    /// transparent surfaces: [`RayLayers`]) instead of its nearest hit only.
    pub(crate) fn trace_packet_layers<S: Stats>(
        &self,
        rays: &[Ray],
        t_min: &[f32],
        t_max: &[f32],
        iso: &[f32],
        layers: &mut RayLayers,
        stats: &mut S,
    ) {
        let len = rays.len();
        assert!(
            (5..=MAX_PACKET).contains(&len) && t_min.len() >= len && t_max.len() >= len,
            "a large packet"
        );
        layers.reset(&t_max[..len]);
        if self.packet_may_hit(len, iso, stats) {
            self.trace_large_scratch(rays, t_min, t_max, iso, layers, stats);
        }
    }

    /// A first-hit or occlusion packet's prologue: checks its slices, sets its `out` entries
    /// to `none` and culls it at the root ([`TetView::packet_may_hit`]); false when that
    /// is all.
    #[allow(clippy::too_many_arguments)]
    #[inline]
    fn packet_start<S: Stats, T: Copy>(
        &self,
        rays: &[Ray],
        t_min: &[f32],
        t_max: &[f32],
        iso: &[f32],
        out: &mut [T],
        none: T,
        stats: &mut S,
    ) -> bool {
        let len = rays.len();
        assert!(len <= MAX_PACKET && t_min.len() >= len && t_max.len() >= len && out.len() >= len);
        out[..len].fill(none);
        self.packet_may_hit(len, iso, stats)
    }

    /// Counts a packet's `len` rays and culls it at the root first: a packet that cannot
    /// see any isovalue costs nothing more.
    #[inline]
    fn packet_may_hit<S: Stats>(&self, len: usize, iso: &[f32], stats: &mut S) -> bool {
        if S::ENABLED {
            for _ in 0..len {
                stats.ray();
            }
        }
        let root = self.bvh.root();
        len > 0 && !self.tets.is_empty() && iso_active(root.lo.w, root.hi.w, iso)
    }

    /// [`TetView::trace_large`] with this thread's scratch buffers.
    fn trace_large_scratch<S: Stats, H: LaneHits>(
        &self,
        rays: &[Ray],
        t_min: &[f32],
        t_max: &[f32],
        iso: &[f32],
        hits: &mut H,
        stats: &mut S,
    ) {
        PACKET_SCRATCH.with(|cell| {
            let mut guard = cell.try_borrow_mut();
            let mut fresh = None;
            let sc: &mut PacketScratch = match &mut guard {
                Ok(sc) => sc,
                // Re-entered from the same thread (not done by the renderer): fresh buffers.
                Err(_) => fresh.insert(PacketScratch::new()),
            };
            // One walk for parallel packets, one for the others (the choice made once here).
            if common_direction(rays).is_some() {
                self.trace_large::<S, H, true>(rays, t_min, t_max, iso, hits, stats, sc);
            } else {
                self.trace_large::<S, H, false>(rays, t_min, t_max, iso, hits, stats, sc);
            }
        });
    }

    /// The 2×2 baseline of Table 8.4 (standard packet traversal): every ray is tested at
    /// every node with the scalar slab test, the packet descends if any ray hits.
    fn trace_standard<S: Stats>(
        &self,
        rays: &[Ray],
        t_min: &[f32],
        t_max: &[f32],
        iso: &[f32],
        out: &mut [Option<RawHit>],
        stats: &mut S,
    ) {
        let len = rays.len();
        let mut rs = [RaySpace::INVALID; 4];
        let mut best = [0f32; 4];
        for i in 0..len {
            rs[i] = RaySpace::new(rays[i].origin, rays[i].dir);
            best[i] = t_max[i];
        }
        let nodes = &self.bvh.nodes;
        let mut stack = [(0u32, 0u16); MAX_DEPTH + 1];
        let mut sp = 0;
        let (mut node, mut first) = (0u32, 0usize);
        'outer: loop {
            'visit: {
                let n = &nodes[node as usize];
                stats.node();
                if !iso_active(n.lo.w, n.hi.w, iso) {
                    break 'visit;
                }
                stats.box_test((len - first) as u64);
                match (first..len).find(|&i| slab(n, &rays[i], t_min[i], best[i])) {
                    Some(i) => first = i,
                    None => break 'visit,
                }
                if n.is_leaf() {
                    stats.leaf();
                    self.leaf_standard(n, &rs[..len], t_min, &mut best, first, out, iso, stats);
                    break 'visit;
                }
                let (near, far) = if rays[first].dir[n.axis as usize] >= 0.0 {
                    (node + 1, n.link)
                } else {
                    (n.link, node + 1)
                };
                stack[sp] = (far, first as u16);
                sp += 1;
                node = near;
                continue 'outer;
            }
            if sp == 0 {
                return;
            }
            sp -= 1;
            (node, first) = (stack[sp].0, stack[sp].1 as usize);
        }
    }

    /// Leaf of the 2×2 baseline: one extraction per tet and isovalue for the packet, then
    /// every ray from `first` on.
    #[allow(clippy::too_many_arguments)]
    fn leaf_standard<S: Stats>(
        &self,
        n: &BvhNode,
        rs: &[RaySpace],
        t_min: &[f32],
        best: &mut [f32; 4],
        first: usize,
        out: &mut [Option<RawHit>],
        iso: &[f32],
        stats: &mut S,
    ) {
        self.leaf_polys(n, iso, stats, |ti, s, _, poly, stats| {
            for i in first..rs.len() {
                stats.intersection();
                if let Some(t) = mt::intersect(&rs[i], poly)
                    && t >= t_min[i]
                    && t <= best[i]
                    && out[i].is_none_or(|h| t < h.t)
                {
                    best[i] = t;
                    out[i] = Some(RawHit {
                        t,
                        surface: s,
                        tet: ti,
                    });
                }
            }
        });
    }

    /// The large-packet traversal (module docs) on 8-ray SIMD blocks; every hit within a
    /// ray's range goes to `hits`, which may lower the range's end. With `PAR` every ray
    /// has the first ray's direction ([`common_direction`]) and the sub-frusta are tested
    /// across it ([`Parallel`]).
    #[allow(clippy::too_many_arguments)]
    fn trace_large<S: Stats, H: LaneHits, const PAR: bool>(
        &self,
        rays: &[Ray],
        t_min: &[f32],
        t_max: &[f32],
        iso: &[f32],
        hits: &mut H,
        stats: &mut S,
        sc: &mut PacketScratch,
    ) {
        let len = rays.len();
        let nb = len.div_ceil(LANES);
        let ng = len.div_ceil(GROUP);
        let PacketScratch {
            blocks,
            best,
            groups,
            gs,
            par,
            leaves,
        } = sc;
        let blocks = &mut blocks[..nb];
        let best = &mut best[..nb];
        for (b, (blk, bt)) in blocks.iter_mut().zip(best.iter_mut()).enumerate() {
            let (s, e) = (b * LANES, ((b + 1) * LANES).min(len));
            // The ray space waits for the block's first polygon test (`spaced`).
            *blk = RayBlock::base(&rays[s..e], &t_min[s..e]);
            *bt = f32x8::new(std::array::from_fn(|l| {
                if s + l < e {
                    t_max[s + l]
                } else {
                    f32::NEG_INFINITY
                }
            }));
        }
        let mut spaced = 0u32;
        for (g, fr) in groups[..ng].iter_mut().enumerate() {
            let (s, e) = (g * GROUP / LANES, ((g + 1) * GROUP / LANES).min(nb));
            *fr = Frustum::from_blocks(&blocks[s..e], &best[s..e]);
        }
        let mut fr = Frustum::union(&groups[..ng]);
        let root = self.bvh.root();
        if fr.misses(Vec3A::from_vec4(root.lo), Vec3A::from_vec4(root.hi)) {
            return;
        }
        let gs: &mut GroupSet = gs;
        *gs = GroupSet::new(&groups[..ng]);
        if PAR {
            let scale = Vec3A::from_vec4(root.lo)
                .abs()
                .max(Vec3A::from_vec4(root.hi).abs())
                .max(fr.omin.abs())
                .max(fr.omax.abs())
                .max_element();
            **par = Parallel::from_blocks(blocks, len, rays[0].dir, scale);
        }
        let par: &Parallel = par;
        leaves.begin(
            self.generation,
            self.bvh.nodes.len(),
            iso,
            rayon::current_num_threads(),
        );
        let nodes = &self.bvh.nodes;
        let mut stack = [(0u32, 0u16); MAX_DEPTH + 1];
        let mut sp = 0;
        let (mut node, mut first) = (0u32, 0usize);
        let mut needs_test = true;
        'outer: loop {
            'visit: {
                let n = &nodes[node as usize];
                stats.node();
                if needs_test || n.is_leaf() {
                    if !iso_active(n.lo.w, n.hi.w, iso) {
                        break 'visit;
                    }
                    // Speculative first-active descent: one ray.
                    stats.box_test(1);
                    let bf = best[first / LANES].as_array()[first % LANES];
                    if !slab(n, &rays[first], t_min[first], bf) {
                        // Interval frustum test of the whole packet.
                        stats.box_test(1);
                        let (lo, hi) = (Vec3A::from_vec4(n.lo), Vec3A::from_vec4(n.hi));
                        if fr.misses(lo, hi) {
                            break 'visit;
                        }
                        // First-active tracking: the sub-frusta that may meet the box (all
                        // at once), then their rays 8 at a time.
                        let from = first + 1;
                        let after = !0u32 << (from / GROUP).min(31);
                        let mut gm = gs.valid & after;
                        if ng > 1 && gm != 0 {
                            stats.box_test(u64::from(gm.count_ones()));
                            gm = gs.hits::<PAR>(par, lo, hi, gm);
                        }
                        let mut found = None;
                        'search: while gm != 0 {
                            let g = gm.trailing_zeros() as usize;
                            gm &= gm - 1;
                            let mut i = (g * GROUP).max(from);
                            let end = ((g + 1) * GROUP).min(len);
                            while i < end {
                                let b = i / LANES;
                                let e = ((b + 1) * LANES).min(len);
                                stats.box_test((e - i) as u64);
                                let m = slab8(n, &blocks[b], best[b]) & (!0u32 << (i % LANES));
                                if m != 0 {
                                    found = Some(b * LANES + m.trailing_zeros() as usize);
                                    break 'search;
                                }
                                i = e;
                            }
                        }
                        match found {
                            Some(i) => first = i,
                            None => break 'visit,
                        }
                    }
                }
                if n.is_leaf() {
                    stats.leaf();
                    let hit_groups = self.leaf_large::<S, H, PAR>(
                        n,
                        node,
                        leaves,
                        rays,
                        t_min,
                        blocks,
                        &mut spaced,
                        best,
                        first,
                        &fr,
                        gs,
                        par,
                        hits,
                        iso,
                        stats,
                    );
                    if hit_groups != 0 {
                        tighten(gs, &mut fr, best, hit_groups);
                        if fr.t1 <= CLOSED {
                            // Every ray's range is closed ([`Occluded`]).
                            return;
                        }
                    }
                    break 'visit;
                }
                // Implicit descent: geometric tests only at bifurcation nodes.
                let (l, r) = (node + 1, n.link);
                let la = self.live_child(&nodes[l as usize], iso);
                let ra = self.live_child(&nodes[r as usize], iso);
                match (la, ra) {
                    (false, false) => break 'visit,
                    (true, false) | (false, true) => {
                        node = if la { l } else { r };
                        needs_test = false;
                    }
                    (true, true) => {
                        let (near, far) = if rays[first].dir[n.axis as usize] >= 0.0 {
                            (l, r)
                        } else {
                            (r, l)
                        };
                        stack[sp] = (far, first as u16);
                        sp += 1;
                        node = near;
                        needs_test = true;
                    }
                }
                continue 'outer;
            }
            if sp == 0 {
                return;
            }
            sp -= 1;
            (node, first) = (stack[sp].0, stack[sp].1 as usize);
            needs_test = true;
        }
    }

    /// Whether the child `c` holds an isovalue (implicit culling); if so, prefetches what its
    /// visit loads first and far from it: a leaf's tet rows, an inner node's right child (the
    /// left one follows it). Those loads were the hottest stalls of the walk in `perf`;
    /// issued a step ahead, they overlap the box tests in between.
    #[inline(always)]
    fn live_child(&self, c: &BvhNode, iso: &[f32]) -> bool {
        if !iso_active(c.lo.w, c.hi.w, iso) {
            return false;
        }
        if c.is_leaf() {
            // 16 bytes a tet: four tets a cache line.
            let (s, e) = (c.link as usize, (c.link + c.count) as usize);
            for ti in (s..e).step_by(4) {
                prefetch(self.tets.as_ptr().wrapping_add(ti));
            }
            prefetch(self.tets.as_ptr().wrapping_add(e - 1));
        } else {
            prefetch(self.bvh.nodes.as_ptr().wrapping_add(c.link as usize));
        }
        true
    }

    /// Leaf of the large-packet traversal: the leaf's isopolygons (from this thread's leaf
    /// cache, or extracted on the fly into it), each culled against the packet frustum and
    /// then against all sub-frusta at once (§8.2.3), then tested against the active rays 8
    /// at a time.
    /// Returns the groups (bit `g`) where some ray's range end was lowered (`hits`).
    #[allow(clippy::too_many_arguments)]
    #[inline]
    fn leaf_large<S: Stats, H: LaneHits, const PAR: bool>(
        &self,
        n: &BvhNode,
        node: u32,
        leaves: &mut LeafCache,
        rays: &[Ray],
        t_min: &[f32],
        blocks: &mut [RayBlock],
        spaced: &mut u32,
        best: &mut [f32x8],
        first: usize,
        fr: &Frustum,
        gs: &GroupSet,
        par: &Parallel,
        hits: &mut H,
        iso: &[f32],
        stats: &mut S,
    ) -> u32 {
        let len = rays.len();
        let mut hit_groups = 0u32;
        let from_group = gs.valid & (!0u32 << (first / GROUP));
        let mut test = |lp: &LeafPoly, stats: &mut S| {
            let (plo, phi) = (lp.lo, lp.hi);
            if fr.misses(plo, phi) {
                return;
            }
            let mut gm = from_group;
            if from_group & !1 != 0 {
                gm = gs.hits::<PAR>(par, plo, phi, gm);
            }
            let (poly, s, ti) = (&lp.poly, lp.surface, lp.tet);
            let hit = |t: f32| RawHit {
                t,
                surface: s,
                tet: ti,
            };
            // The faceted normal, computed only for hits the sink keeps.
            let normal = || {
                let v = self.tets[ti as usize].map(|i| self.verts[i as usize]);
                poly.oriented_normal(&v, iso[s as usize])
            };
            while gm != 0 {
                let g = gm.trailing_zeros() as usize;
                gm &= gm - 1;
                let mut i = (g * GROUP).max(first);
                let end = ((g + 1) * GROUP).min(len);
                while i < end {
                    let b = i / LANES;
                    let e = ((b + 1) * LANES).min(len);
                    if S::ENABLED {
                        for _ in i..e {
                            stats.intersection();
                        }
                    }
                    if *spaced >> b & 1 == 0 {
                        // First polygon test of this block: its ray space, once per packet.
                        blocks[b].prepare_space(&rays[b * LANES..e]);
                        *spaced |= 1 << b;
                    }
                    let blk = &blocks[b];
                    if blk.uniform {
                        let (t, m) = poly8(blk, poly, best[b]);
                        let mut m = m & (!0u32 << (i % LANES));
                        if m != 0 {
                            let t = t.to_array();
                            let bb = best[b].as_mut_array();
                            while m != 0 {
                                let l = m.trailing_zeros() as usize;
                                m &= m - 1;
                                let r = b * LANES + l;
                                if let Some(end) = hits.take(r, hit(t[l]), normal) {
                                    bb[l] = end;
                                    hit_groups |= 1 << g;
                                }
                            }
                        }
                    } else {
                        // Mixed ray-space axes or invalid rays: the scalar test per ray.
                        let bb = best[b].as_mut_array();
                        for r in i..e {
                            let rs = RaySpace::new(rays[r].origin, rays[r].dir);
                            let l = r % LANES;
                            if let Some(t) = mt::intersect(&rs, poly)
                                && t >= t_min[r]
                                && t <= bb[l]
                                && let Some(end) = hits.take(r, hit(t), normal)
                            {
                                bb[l] = end;
                                hit_groups |= 1 << g;
                            }
                        }
                    }
                    i = e;
                }
            }
        };
        // The leaf's polygons from the cache, or extracted into it (too many to cache:
        // extracted into the cache's buffer for them). One loop tests them, so the test
        // above is inlined into it (with a second call site it was a call per polygon).
        let max_len = n.count as usize * iso.len();
        let polys = leaves.leaf(node, max_len, |out| {
            let mut k = 0;
            self.leaf_polys(n, iso, stats, |ti, s, _, poly, _| {
                out[k] = LeafPoly::new(ti, s, *poly);
                k += 1;
            });
            k
        });
        for lp in polys {
            test(lp, stats);
        }
        hit_groups
    }
}

/// After hits in `hit_groups`: lowers those sub-frusta's range ends to their rays' nearest
/// hits so far (front-to-back, nothing farther can matter), and the packet's with them.
/// Groups with a NaN range end keep theirs (`Frustum::from_blocks` made it infinite).
fn tighten(gs: &mut GroupSet, fr: &mut Frustum, best: &[f32x8], hit_groups: u32) {
    let per = GROUP / LANES;
    let mut m = hit_groups;
    while m != 0 {
        let g = m.trailing_zeros() as usize;
        m &= m - 1;
        let blocks = &best[g * per..((g + 1) * per).min(best.len())];
        if blocks.iter().any(|b| b.is_nan().to_bitmask() != 0) {
            continue;
        }
        let t1 = blocks
            .iter()
            .fold(f32x8::NEG_INFINITY, |a, &b| a.max(b))
            .to_array()
            .into_iter()
            .fold(f32::NEG_INFINITY, f32::max);
        gs.set_t1(g, t1);
    }
    fr.t1 = gs.t1[0]
        .max(gs.t1[1])
        .to_array()
        .into_iter()
        .fold(f32::NEG_INFINITY, f32::max);
}

/// Per-thread buffers of the large-packet traversal (no allocation or large clearing per
/// packet: only the blocks in use are written).
pub(crate) struct PacketScratch {
    blocks: Box<[RayBlock; MAX_BLOCKS]>,
    best: Box<[f32x8; MAX_BLOCKS]>,
    groups: Box<[Frustum; MAX_GROUPS]>,
    gs: Box<GroupSet>,
    par: Box<Parallel>,
    leaves: LeafCache,
}

impl PacketScratch {
    fn new() -> Self {
        Self {
            blocks: Box::new([RayBlock::EMPTY; MAX_BLOCKS]),
            best: Box::new([f32x8::ZERO; MAX_BLOCKS]),
            groups: Box::new([Frustum::NONE; MAX_GROUPS]),
            gs: Box::new(GroupSet::NONE),
            par: Box::new(Parallel::NONE),
            leaves: LeafCache::new(),
        }
    }
}

thread_local! {
    static PACKET_SCRATCH: RefCell<PacketScratch> = RefCell::new(PacketScratch::new());
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The SIMD group frustum equals the per-ray one (zero and mixed-sign directions,
    /// partial blocks, infinite ranges).
    #[test]
    fn frustum_from_blocks_equals_per_ray_frustum() {
        let mut rng = crate::math::rng::Rng::new(3);
        let mut f = move || rng.unit_f32() * 2.0 - 1.0;
        for trial in 0..500 {
            let n = 1 + trial % 16;
            let rays: Vec<Ray> = (0..n)
                .map(|i| {
                    let mut d = Vec3::new(f() + 2.0, f(), 0.5 * f() - 1.0);
                    if trial % 3 == 0 && i == n / 2 {
                        d.y = 0.0;
                    }
                    Ray::new(Vec3::new(f(), f(), 5.0 + f()), d)
                })
                .collect();
            let t0: Vec<f32> = (0..n).map(|_| f()).collect();
            let t1: Vec<f32> = (0..n)
                .map(|i| if i % 4 == 0 { f32::INFINITY } else { 3.0 + f() })
                .collect();
            let blocks: Vec<RayBlock> = (0..n)
                .step_by(LANES)
                .map(|s| {
                    let e = (s + LANES).min(n);
                    RayBlock::new(&rays[s..e], &t0[s..e])
                })
                .collect();
            let best: Vec<f32x8> = (0..n)
                .step_by(LANES)
                .map(|s| {
                    f32x8::new(std::array::from_fn(|l| {
                        if s + l < n {
                            t1[s + l]
                        } else {
                            f32::NEG_INFINITY
                        }
                    }))
                })
                .collect();
            let a = Frustum::new(&rays, &t0, &t1);
            let b = Frustum::from_blocks(&blocks, &best);
            assert_eq!(
                (a.omin, a.omax, a.imin, a.imax, a.axis, a.t0, a.t1),
                (b.omin, b.omax, b.imin, b.imax, b.axis, b.t0, b.t1),
                "trial {trial}"
            );
            if trial % 3 == 0 {
                assert!(!b.axis.test(1));
            }
        }
    }

    /// Parallel packets (one direction, origins scattered over a tilted patch, as shadow
    /// rays' are): a group whose rays meet a box within their ranges is never culled by the
    /// tests across the direction (truth: each ray's slab in `f64`), and the tests cull more
    /// boxes than the frustum test of the same groups.
    #[test]
    fn parallel_groups_keep_every_box_their_rays_meet() {
        let mut rng = crate::math::rng::Rng::new(11);
        let mut f = move || rng.unit_f32() * 2.0 - 1.0;
        let (mut met, mut culled, mut frustum_culled) = (0, 0, 0);
        for trial in 0..200 {
            let len = 1 + (trial * 37) % MAX_PACKET;
            let d = Vec3::new(f(), f(), f() + 1.5) * (0.5 + f().abs());
            let (n, c) = (Vec3::new(f(), f(), 1.0), Vec3::new(f(), f(), f()) * 5.0);
            let (u, w) = n.normalize().any_orthonormal_pair();
            let rays: Vec<Ray> = (0..len)
                .map(|i| {
                    // Origins on a tilted plane, in Morton-like runs of 16 nearby points.
                    let (gx, gy) = ((i / GROUP) % 4, (i / GROUP) / 4);
                    let (x, y) = (
                        gx as f32 + 0.25 * (i % 4) as f32,
                        gy as f32 + 0.25 * ((i / 4) % 4) as f32,
                    );
                    Ray::new(c + u * x + w * y, d)
                })
                .collect();
            let t_min: Vec<f32> = (0..len).map(|_| 0.01 * f().abs()).collect();
            let t_max: Vec<f32> = (0..len)
                .map(|i| {
                    if (trial + i) % 3 == 0 {
                        f32::INFINITY
                    } else {
                        2.0 + 4.0 * f().abs()
                    }
                })
                .collect();
            let groups: Vec<Frustum> = (0..len.div_ceil(GROUP))
                .map(|g| {
                    let (s, e) = (g * GROUP, ((g + 1) * GROUP).min(len));
                    Frustum::new(&rays[s..e], &t_min[s..e], &t_max[s..e])
                })
                .collect();
            assert_eq!(common_direction(&rays), Some(d));
            let blocks: Vec<RayBlock> = (0..len.div_ceil(LANES))
                .map(|b| {
                    let (s, e) = (b * LANES, ((b + 1) * LANES).min(len));
                    RayBlock::base(&rays[s..e], &t_min[s..e])
                })
                .collect();
            let gs = GroupSet::new(&groups);
            let par = Parallel::from_blocks(&blocks, len, d, 20.0);
            for k in 0..40 {
                // Small boxes near the rays' paths (where the two tests differ), and some
                // anywhere.
                let at = if k % 4 == 0 {
                    Vec3A::from(c) + Vec3A::new(f(), f(), f()) * 8.0
                } else {
                    let r = &rays[(k * 7 + trial) % len];
                    Vec3A::from(r.origin + d * (3.0 * f().abs())) + Vec3A::new(f(), f(), f())
                };
                let lo = at;
                let hi = lo + Vec3A::new(f().abs(), f().abs(), f().abs()) * 0.3;
                let m = gs.hits::<true>(&par, lo, hi, u32::MAX);
                let m_plain = gs.hits::<false>(&Parallel::NONE, lo, hi, u32::MAX);
                for g in 0..groups.len() {
                    let (s, e) = (g * GROUP, ((g + 1) * GROUP).min(len));
                    let meets = (s..e).any(|i| {
                        let (o, dir) = (rays[i].origin.as_dvec3(), d.as_dvec3());
                        let (l, h) = (Vec3::from(lo).as_dvec3(), Vec3::from(hi).as_dvec3());
                        let (mut t0, mut t1) = (f64::from(t_min[i]), f64::from(t_max[i]));
                        for a in 0..3 {
                            let (ta, tb) = ((l[a] - o[a]) / dir[a], (h[a] - o[a]) / dir[a]);
                            t0 = t0.max(ta.min(tb));
                            t1 = t1.min(ta.max(tb));
                        }
                        t0 <= t1
                    });
                    let kept = m >> g & 1 == 1;
                    assert!(
                        kept || !meets,
                        "trial {trial} group {g}: a ray meets the box"
                    );
                    met += usize::from(meets);
                    culled += usize::from(!kept);
                    frustum_culled += usize::from(m_plain >> g & 1 == 0);
                }
            }
        }
        assert!(met > 300, "{met} boxes met");
        assert!(
            culled > frustum_culled,
            "culled {culled}, frustum {frustum_culled}"
        );
    }

    /// The all-at-once sub-frustum test equals `Frustum::misses` per group (random boxes,
    /// groups with zero and mixed-sign directions, partial packets).
    #[test]
    fn group_set_hits_equal_per_group_frustum_tests() {
        let mut rng = crate::math::rng::Rng::new(5);
        let mut f = move || rng.unit_f32() * 2.0 - 1.0;
        let (mut hit, mut miss) = (0, 0);
        for trial in 0..300 {
            let ng = 1 + trial % MAX_GROUPS;
            let groups: Vec<Frustum> = (0..ng)
                .map(|g| {
                    let rays: Vec<Ray> = (0..GROUP)
                        .map(|i| {
                            let mut d = Vec3::new(0.3 * f(), 0.3 * f(), -1.0);
                            if (trial + g) % 5 == 0 && i == 3 {
                                d.x = 0.0;
                            }
                            if (trial + g) % 7 == 0 && i == 4 {
                                d.y = -d.y.abs() - 0.1;
                            }
                            // Even trials: one origin for all rays (pinhole packets).
                            let o = if trial % 2 == 0 {
                                Vec3::new(0.05, -0.03, 4.0)
                            } else {
                                Vec3::new(0.2 * f(), 0.2 * f(), 4.0)
                            };
                            Ray::new(o, d)
                        })
                        .collect();
                    let t0 = vec![0.0; GROUP];
                    let t1: Vec<f32> = (0..GROUP).map(|_| 4.0 + 3.0 * f()).collect();
                    Frustum::new(&rays, &t0, &t1)
                })
                .collect();
            let gs = GroupSet::new(&groups);
            assert_eq!(gs.common_origin[0], trial % 2 == 0, "trial {trial}");
            for k in 0..20 {
                let lo = Vec3A::new(3.0 * f(), 3.0 * f(), 4.0 * f());
                let hi = lo + Vec3A::new(0.2 * (f() + 1.0), 0.2 * (f() + 1.0), 0.2 * (f() + 1.0));
                // Every other box asks for a part of the groups only.
                let wanted = if k % 2 == 0 {
                    u32::MAX
                } else {
                    (f().to_bits() >> 7) & 0xffff
                };
                let m = gs.hits::<false>(&Parallel::NONE, lo, hi, wanted);
                for (g, fr) in groups.iter().enumerate() {
                    assert_eq!(fr.misses(lo, hi), fr.misses_by_axis(lo, hi));
                    // An axis left untested (a zero or mixed-sign direction component).
                    let mut open = *fr;
                    open.axis.set(k % 3, false);
                    assert_eq!(open.misses(lo, hi), open.misses_by_axis(lo, hi));
                    let want = !fr.misses(lo, hi) && wanted >> g & 1 == 1;
                    assert_eq!(m >> g & 1 == 1, want, "trial {trial} group {g}");
                    if want {
                        hit += 1;
                    } else {
                        miss += 1;
                    }
                }
                assert_eq!(m >> ng, 0, "unused groups never hit");
            }
        }
        assert!(hit > 500 && miss > 500, "{hit} hits, {miss} misses");
    }
}
