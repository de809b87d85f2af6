//! Packet traversal: 16 coherent rays walk the kd-tree together (thesis seed 004 §7.2.1,
//! after Wald's coherent packets; the thesis used 4). Node min/max are fetched and culled
//! once per packet, and the split distances of all rays are computed lane-wise in one
//! `f32x16` (the `wide` crate: one AVX-512 register when enabled at compile time, AVX or SSE
//! parts otherwise, no `unsafe`); the leaves test the rays in two `f32x8` halves, or in one
//! when a cell's rays, at most 8, fall in both (gathered into one half: one cell test
//! instead of two).
//!
//! A packet descends to one child when every active ray does, else to both; each ray keeps
//! its own `[t_near, t_far]` lane, computed with exactly the single-ray formulas, and leaves
//! run the cell test of all active rays at once (the cell's corners, range and box loaded
//! once per packet; slab, segment, cubic and early out in `f32x8` lanes with the scalar
//! operations, [`crate::intersect::packet`]), so packet results equal single-ray results
//! (tested). Packets need every ray to share the sign of each direction component and have
//! no zero component; [`crate::grid::GridScene`] splits other groups into packets of 8
//! or traces them one by one.
//!
//! A walk whose lane ends at its hit (a first hit, or an opaque surface's behind transparent
//! layers) need not know where in a cell that crossing lies, only that it is there: in a
//! cell whose range holds one active isovalue only, a lane whose crossing the `f32` filter
//! certifies (end values of opposite signs beyond the error bound) is cut at the cell's far
//! end and its root found after the walk, with the other such lanes of that isovalue, 8 at a
//! time by the `f64` slow path (`Deferred`; the same roots, so the same hits as single rays,
//! tested). A lane that goes on past a transparent layer tests its cell again from there,
//! unless the slow path certified that layer the cell's only crossing.

use wide::{f32x8, f32x16};

use super::step::{Step, Visit};
use super::{Entry, INLINE_STACK, KdTree};
use crate::intersect::slow_x8::{SlowJobs, exact_slow_jobs};
use crate::intersect::{
    CellHit, CellIntersector, CellSegment, HitsX8, IsoSet, LocalRay, PreparedCell, RaysX8,
    TraversalFrame, cell_corners, intersect_prepared_cell_x8, root_t,
};
use crate::math::lane_indices;
use crate::render::Stats;
use crate::voxel::Voxel;

/// `f32x8` halves per packet: 2 gives 16-ray packets (4×4 pixels), which halve the scalar
/// per-node work (addresses, min/max loads and culling, branches) per ray.
pub(crate) const HALVES: usize = 2;

/// Rays per packet.
pub const PACKET_WIDTH: usize = 8 * HALVES;

/// Lanes of a packet, one `f32x16` (a single AVX-512 register when the CPU has it, two
/// AVX halves otherwise): the node step's split distances, interval clips and tests are one
/// instruction each instead of one per half.
pub(crate) type Lanes = f32x16;

const _: () = assert!(PACKET_WIDTH == 16, "`Lanes` holds 16 rays");

#[inline(always)]
pub(crate) fn lanes(x: &[f32; PACKET_WIDTH]) -> Lanes {
    f32x16::new(*x)
}

#[inline(always)]
pub(crate) fn splat(x: f32) -> Lanes {
    f32x16::splat(x)
}

/// Whether any lane of the masks `m` is set: one move-mask. The node step decides with
/// this, not with [`mask_bits`]: with two halves, combining their move-masks into one
/// integer lengthened the chain that every branch of a node step waits for.
#[inline(always)]
pub(crate) fn any_lane(m: &Lanes) -> bool {
    m.any()
}

/// Bit `i` set where lane `i` of the masks `m` is set.
#[inline(always)]
pub(crate) fn mask_bits(m: &Lanes) -> u32 {
    m.to_bitmask()
}

/// Which children of a node the packet enters, for the `active` rays (lane masks) with
/// split distances `ts` over `[tn, tf]`: the near child alone when every active ray's
/// split lies beyond its interval, the far child alone when before it, else both (module
/// docs). One decision for the in-core and the out-of-core packet traversals.
#[inline(always)]
pub(crate) fn packet_visit(active: &Lanes, ts: &Lanes, tn: &Lanes, tf: &Lanes) -> Visit<Lanes> {
    // "Every active ray is beyond" is "no active ray is not beyond" (`!` keeps NaN lanes
    // on the not-beyond side, as the bit test did).
    if !any_lane(&(*active & !ts.simd_gt(*tf))) {
        return Visit::Near;
    }
    if !any_lane(&(*active & !ts.simd_lt(*tn))) {
        return Visit::Far;
    }
    Visit::Both {
        near_t_far: tf.min(*ts),
        far_t_near: tn.max(*ts),
    }
}

type PacketEntry = Entry<Lanes>;

/// The packet traversal stack, reusable across packets (zeroing 64 entries, 10 KB, per packet
/// would cost more than a short traversal). [`with_packet_stack`] lends each thread one.
#[derive(Clone)]
pub struct PacketStack {
    entries: [PacketEntry; INLINE_STACK],
    /// The walk's rays as lanes, written in place per packet.
    rays: PacketRays,
    /// The walk's deferred lanes (only their mask is reset per packet, not the slots).
    deferred: Deferred,
}

impl Default for PacketStack {
    fn default() -> Self {
        Self {
            entries: [PacketEntry::default(); INLINE_STACK],
            rays: PacketRays::EMPTY,
            deferred: Deferred::default(),
        }
    }
}

thread_local! {
    static PACKET_STACK: std::cell::RefCell<PacketStack> =
        std::cell::RefCell::new(PacketStack::default());
}

/// Runs `f` with this thread's packet stack (made once per thread, not per call).
pub fn with_packet_stack<R>(f: impl FnOnce(&mut PacketStack) -> R) -> R {
    PACKET_STACK.with_borrow_mut(f)
}

/// True if the rays can travel as one packet: same direction signs, no zero component.
pub fn packet_compatible(rays: &[LocalRay]) -> bool {
    let Some(first) = rays.first() else {
        return false;
    };
    let pos = first.dir.cmpgt(glam::Vec3::ZERO);
    rays.iter()
        .all(|r| r.dir.cmpne(glam::Vec3::ZERO).all() && r.dir.cmpgt(glam::Vec3::ZERO) == pos)
}

/// A packet's rays as lanes (structure of arrays), with padding lanes (origin 0, direction
/// 1, empty interval: `t_near = +inf > t_far = -inf`), as the in-core and the out-of-core
/// ([`crate::ooc`]) packet traversals read them.
#[derive(Clone)]
pub(crate) struct PacketRays {
    pub org: [Lanes; 3],
    pub inv: [Lanes; 3],
    /// Direction signs, shared by the packet ([`packet_compatible`]).
    pub dir_pos: [bool; 3],
    /// The halves for the leaves (SIMD cell tests, [`crate::intersect::packet`]).
    pub leaf: [RaysX8; HALVES],
    /// Lanes of both halves gathered into one for a cell test ([`gather_halves`]).
    pub gathered: RaysX8,
    pub t_near: Lanes,
    pub t_far: Lanes,
}

impl PacketRays {
    /// Zero lanes, to be overwritten by [`PacketRays::set`].
    pub(crate) const EMPTY: Self = Self {
        org: [f32x16::ZERO; 3],
        inv: [f32x16::ZERO; 3],
        dir_pos: [false; 3],
        leaf: [RaysX8::EMPTY; HALVES],
        gathered: RaysX8::EMPTY,
        t_near: f32x16::ZERO,
        t_far: f32x16::ZERO,
    };

    /// Up to [`PACKET_WIDTH`] compatible rays with clipped intervals `[t0[i], t1[i]]`,
    /// written in place: a `PacketRays` made and returned by value (1.2 KB) was assembled
    /// aside and copied in by six `memcpy` calls per packet (2 % of a frame's samples).
    #[inline(always)]
    pub(crate) fn set(&mut self, rays: &[LocalRay], t0: &[f32], t1: &[f32]) {
        let n = rays.len().min(PACKET_WIDTH);
        // Filled by plain loops (no closure call per lane); padding lanes keep an empty
        // interval.
        let mut soa = [[0.0f32; PACKET_WIDTH]; 11];
        for lane_values in &mut soa[3..9] {
            *lane_values = [1.0; PACKET_WIDTH];
        }
        soa[9] = [f32::INFINITY; PACKET_WIDTH];
        soa[10] = [f32::NEG_INFINITY; PACKET_WIDTH];
        for (i, r) in rays[..n].iter().enumerate() {
            for a in 0..3 {
                soa[a][i] = r.origin[a];
                soa[3 + a][i] = r.inv_dir[a];
                soa[6 + a][i] = r.dir[a];
            }
            soa[9][i] = t0[i];
            soa[10][i] = t1[i];
        }
        let dir_pos = [0, 1, 2].map(|a| rays[0].dir[a] > 0.0);
        self.dir_pos = dir_pos;
        for a in 0..3 {
            self.org[a] = lanes(&soa[a]);
            self.inv[a] = lanes(&soa[3 + a]);
        }
        self.t_near = lanes(&soa[9]);
        self.t_far = lanes(&soa[10]);
        let eight = |x: &[f32; PACKET_WIDTH], h: usize| {
            f32x8::new(x[8 * h..8 * h + 8].try_into().expect("8 lanes"))
        };
        for (h, leaf) in self.leaf.iter_mut().enumerate() {
            for a in 0..3 {
                leaf.origin[a] = eight(&soa[a], h);
                leaf.inv_dir[a] = eight(&soa[3 + a], h);
                leaf.dir[a] = eight(&soa[6 + a], h);
            }
            leaf.dir_pos = dir_pos;
            leaf.t_lo = eight(&soa[9], h);
            leaf.t_hi = eight(&soa[10], h);
        }
    }
}

/// What a packet traversal does with a lane after a cell hit ([`packet_leaf`]'s `on_hit`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum LaneNext {
    /// The lane needs no hit beyond `t`: the traversal cuts it there (a first-hit search
    /// passes the hit's own distance).
    Stop(f32),
    /// The lane goes on past the hit (a transparent layer, [`crate::render::Peel`]): its
    /// cell tests start from `t` from now on, this cell's again first.
    GoOnFrom(f32),
}

/// The one-ray twin of a lane going on past its hits: `first_hit(t)` is the ray's first
/// hit from `t` to `t_to`, handed to `on_hit` until that stops the ray or none is left.
#[inline]
pub(crate) fn ray_go_on(
    t_from: f32,
    t_to: f32,
    mut first_hit: impl FnMut(f32) -> Option<CellHit>,
    mut on_hit: impl FnMut(CellHit) -> LaneNext,
) {
    let mut t = t_from;
    while t <= t_to {
        let Some(hit) = first_hit(t) else {
            return;
        };
        match on_hit(hit) {
            LaneNext::Stop(_) => return,
            LaneNext::GoOnFrom(next) => t = next,
        }
    }
}

/// Half `h`'s lanes in their own slots.
const fn half_lanes(h: usize) -> [u8; 8] {
    let mut lane = [0u8; 8];
    let mut i = 0;
    while i < 8 {
        lane[i] = (8 * h + i) as u8;
        i += 1;
    }
    lane
}

/// Lanes of both halves gathered into [`PacketRays::gathered`] ([`gather_halves`]).
struct Gathered {
    /// The packet lane in each slot.
    lane: [u8; 8],
    /// The slots that hold active lanes.
    slots: u32,
    /// The slots whose lane may be deferred (bit `k` of `undeferred` for lane `k`).
    may_defer: u32,
}

/// Gathers the `active` lanes of both halves (at most 8 of them) into `p.gathered`: half
/// 0's stay in their slots, half 1's move into its free ones, lowest first. At the bottom of
/// the tree a live cell's few lanes often fall in both halves; one cell test of the
/// gathered lanes then replaces two (on the real chest CT at bone 300, a third of the cell
/// tests).
#[inline(always)]
fn gather_halves(p: &mut PacketRays, active: u32, undeferred: u32) -> Gathered {
    let PacketRays { leaf, gathered, .. } = p;
    // Field by field: the compiler copies each with vector moves, the whole struct (360
    // bytes) with a `memcpy` call.
    let (base, moved) = (&leaf[0], &leaf[1]);
    gathered.origin = base.origin;
    gathered.dir = base.dir;
    gathered.inv_dir = base.inv_dir;
    gathered.dir_pos = base.dir_pos;
    gathered.t_lo = base.t_lo;
    gathered.t_hi = base.t_hi;
    let mut g = Gathered {
        lane: half_lanes(0),
        slots: active & 0xff,
        may_defer: undeferred & 0xff,
    };
    let mut free = !active & 0xff;
    for j in lane_indices((active >> 8) & 0xff) {
        let i = free.trailing_zeros() as usize;
        free &= free - 1;
        g.lane[i] = (8 + j) as u8;
        g.slots |= 1 << i;
        g.may_defer = g.may_defer & !(1 << i) | (undeferred >> (8 + j) & 1) << i;
        for a in 0..3 {
            gathered.origin[a].as_mut_array()[i] = moved.origin[a].as_array()[j];
            gathered.dir[a].as_mut_array()[i] = moved.dir[a].as_array()[j];
            gathered.inv_dir[a].as_mut_array()[i] = moved.inv_dir[a].as_array()[j];
        }
        gathered.t_lo.as_mut_array()[i] = moved.t_lo.as_array()[j];
        gathered.t_hi.as_mut_array()[i] = moved.t_hi.as_array()[j];
    }
    g
}

/// The leaf step of a packet traversal, written once for the in-core and out-of-core trees:
/// tests cell `cell` of the block (`frame`, `voxels`, `dims`) against the `active` rays (bit
/// `k` = ray `k`) in `f32x8` lanes, each over its clipped interval as the single-ray
/// traversal does (lanes equal the scalar test bit for bit, [`crate::intersect::packet`]);
/// calls `on_hit(k, hit)` for a hit nearer than `best[k]` and returns the updated `best` as
/// lanes. A lane that goes on past its hit ([`LaneNext::GoOnFrom`]) has its interval start
/// moved there and the cell tested again for it, so its next hit is the one a new ray from
/// that distance would find; not when the hit was certified the cell's only crossing on the
/// lane's segment ([`HitsX8::sole`]), where that test would find none. `defer` takes the
/// lanes whose certain crossing ends them ([`Deferred`]). Even one active ray of a half
/// takes the lanes: measured against a scalar test for halves of one or two rays, the lanes
/// were no slower (docs/benchmarks.md). Lanes of both halves, at most 8, are tested as one
/// half ([`gather_halves`]).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub(crate) fn packet_leaf<T: Voxel, C: CellIntersector, S: Stats>(
    frame: &TraversalFrame,
    voxels: &[T],
    dims: [usize; 3],
    cell: [usize; 3],
    p: &mut PacketRays,
    active: u32,
    isos: &IsoSet<T>,
    intersector: C,
    stats: &mut S,
    best: &mut [f32; PACKET_WIDTH],
    mut defer: Option<&mut Deferred>,
    mut on_hit: impl FnMut(usize, CellHit) -> LaneNext,
) -> Lanes {
    for _ in 0..active.count_ones() {
        stats.leaf();
    }
    let Some(pc) = PreparedCell::load(frame, voxels, dims, cell, isos) else {
        return lanes(best);
    };
    // A lane is deferred once at most (its cut then ends the walk for it).
    let (undeferred, defers) = defer.as_ref().map_or((0, 0), |d| (!d.lanes, d.surfaces));
    if active & 0xff != 0 && active >> 8 != 0 && active.count_ones() <= 8 {
        let g = gather_halves(p, active, undeferred);
        let PacketRays { leaf, gathered, .. } = p;
        test_lanes(
            &pc,
            gathered,
            g.lane,
            g.slots,
            (g.may_defer, defers),
            Some(leaf),
            isos,
            intersector,
            stats,
            best,
            defer.as_deref_mut(),
            &mut on_hit,
        );
    } else {
        for h in 0..HALVES {
            let test = (active >> (8 * h)) & 0xff;
            if test != 0 {
                test_lanes(
                    &pc,
                    &mut p.leaf[h],
                    half_lanes(h),
                    test,
                    ((undeferred >> (8 * h)) & 0xff, defers),
                    None,
                    isos,
                    intersector,
                    stats,
                    best,
                    defer.as_deref_mut(),
                    &mut on_hit,
                );
            }
        }
    }
    lanes(best)
}

/// The cell test of [`packet_leaf`] for the lanes `test` of one half `rays`, whose slot `i`
/// is packet lane `lane[i]`; `(may_defer, defers)` as for [`intersect_prepared_cell_x8`]. A
/// lane that goes on past its hit has its interval start moved in `rays` and, when `rays` is
/// a gathered copy, in its own half of `halves` too.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn test_lanes<T: Voxel, C: CellIntersector, S: Stats>(
    pc: &PreparedCell<T>,
    rays: &mut RaysX8,
    lane: [u8; 8],
    mut test: u32,
    (may_defer, defers): (u32, u64),
    mut halves: Option<&mut [RaysX8; HALVES]>,
    isos: &IsoSet<T>,
    intersector: C,
    stats: &mut S,
    best: &mut [f32; PACKET_WIDTH],
    mut defer: Option<&mut Deferred>,
    on_hit: &mut impl FnMut(usize, CellHit) -> LaneNext,
) {
    while test != 0 {
        let hits =
            intersect_prepared_cell_x8(pc, rays, test, may_defer, defers, isos, intersector, stats);
        if hits.deferred != 0
            && let Some(d) = defer.as_deref_mut()
        {
            d.record(lane, pc.cell, &hits, best);
        }
        let mut again = 0u32;
        let mut b = hits.mask;
        while b != 0 {
            let i = b.trailing_zeros() as usize;
            b &= b - 1;
            let k = usize::from(lane[i]);
            if hits.t[i] < best[k] {
                let hit = CellHit {
                    t: hits.t[i],
                    surface: hits.surface[i],
                    cell: pc.cell,
                };
                match on_hit(k, hit) {
                    LaneNext::Stop(t) => best[k] = t,
                    LaneNext::GoOnFrom(t) => {
                        let mut t_lo = rays.t_lo.to_array();
                        t_lo[i] = t;
                        rays.t_lo = f32x8::new(t_lo);
                        if let Some(halves) = halves.as_deref_mut() {
                            let own = &mut halves[k / 8];
                            let mut t_lo = own.t_lo.to_array();
                            t_lo[k % 8] = t;
                            own.t_lo = f32x8::new(t_lo);
                        }
                        // The cell's only crossing on the lane's segment: a test past it
                        // would find nothing.
                        again |= !hits.sole & (1 << i);
                    }
                }
            }
        }
        test = again;
    }
}

/// What a packet walk's hits are for ([`KdTree::walk_packet_in`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum WalkFor {
    /// Where each lane hits.
    Hits,
    /// Whether each lane hits (shadow rays): certain crossings are not refined.
    AnyHit,
}

/// The lanes of a packet whose last hit's cell is known (the `f32` fast path certified a
/// crossing there of the cell's only isovalue, of a surface that ends the lane,
/// [`crate::intersect::CellIntersector::first_roots_x8_deferring`]) but whose root the walk
/// left for later: the slow path then runs on 8 of them at a time, whatever their cells,
/// instead of on the few lanes of one cell each time.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct Deferred {
    /// Bit `s`: hits on surface `s` end their lane, so they may be deferred (this walk's).
    pub surfaces: u64,
    /// Bit `k`: lane `k` is deferred.
    pub lanes: u32,
    /// The lane's isovalue and surface.
    pub iso: [(f32, u32); PACKET_WIDTH],
    pub cell: [[usize; 3]; PACKET_WIDTH],
    /// The lane's segment through the cell.
    pub segment: [(f32, f32); PACKET_WIDTH],
    /// The lane's cut when it was deferred: its hit counts if nearer.
    pub cut: [f32; PACKET_WIDTH],
}

impl Deferred {
    /// Records the deferred lanes of a cell test in `cell` (slot `i` is packet lane
    /// `lane[i]`), and cuts them at their segment's end. Out of line: the walk's loop stays as
    /// small as it was.
    #[inline(never)]
    fn record(
        &mut self,
        lane: [u8; 8],
        cell: [usize; 3],
        hits: &HitsX8,
        best: &mut [f32; PACKET_WIDTH],
    ) {
        for i in lane_indices(hits.deferred) {
            let k = usize::from(lane[i]);
            self.lanes |= 1 << k;
            self.iso[k] = hits.deferred_iso;
            self.cell[k] = cell;
            self.segment[k] = (hits.t_near[i], hits.t_far[i]);
            self.cut[k] = best[k];
            // The hit lies in `[t_near, t_far]`; a hit at `t_far` or beyond, in a later
            // cell, could not be nearer (a hit must be nearer than the cut).
            best[k] = best[k].min(hits.t_far[i].next_down());
        }
    }

    /// The deferred lanes' hits, handed to `on_hit` as the walk would have: the roots of
    /// [`exact_slow_jobs`] (bit-identical to the cell test's; 8 lanes of one isovalue a
    /// time), each lane's `t` as [`intersect_prepared_cell_x8`] makes it. `retrace(k, t)` is
    /// lane `k`'s first hit from `t` on, traced alone: for a lane whose certified crossing the
    /// slow path did not find (not seen; a rounding case beyond the bound would otherwise drop
    /// the hit).
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn resolve<T: Voxel>(
        &self,
        frame: &TraversalFrame,
        voxels: &[T],
        dims: [usize; 3],
        p: &PacketRays,
        mut retrace: impl FnMut(usize, f32) -> Option<CellHit>,
        mut on_hit: impl FnMut(usize, CellHit) -> LaneNext,
    ) {
        let mut rest = self.lanes;
        while rest != 0 {
            let (iso, surface) = self.iso[rest.trailing_zeros() as usize];
            let mut ks = [0usize; 8];
            let mut jobs = SlowJobs::new(iso);
            for k in lane_indices(rest) {
                if jobs.len() == 8 {
                    break;
                }
                if self.iso[k] != (iso, surface) {
                    continue;
                }
                rest &= !(1 << k);
                ks[jobs.len()] = k;
                let cell = self.cell[k];
                let (lo, hi) = frame.cell_box(cell);
                let (t_near, t_far) = self.segment[k];
                let ray = p.leaf[k / 8].lane(k % 8);
                let seg = CellSegment::of(&ray, lo, hi, t_near, t_far);
                jobs.push(cell_corners(voxels, dims, cell), &seg);
            }
            let n = jobs.len();
            let roots = exact_slow_jobs(&jobs);
            for (j, &k) in ks[..n].iter().enumerate() {
                let (tn, tf) = self.segment[k];
                let hit = if roots.mask >> j & 1 == 1 {
                    Some(CellHit {
                        t: root_t(tn, tf, roots.s[j]),
                        surface,
                        cell: self.cell[k],
                    })
                } else {
                    // The certified crossing: the slow path finds a root.
                    debug_assert!(false, "deferred lane {k} without a root");
                    retrace(k, tf)
                };
                if let Some(hit) = hit.filter(|h| h.t < self.cut[k]) {
                    let _ = on_hit(k, hit);
                }
            }
        }
    }
}

impl<T: Voxel> KdTree<T> {
    /// First hits of up to [`PACKET_WIDTH`] rays with per-ray clipped intervals
    /// `[t0[i], t1[i]]` (empty when `t0 > t1`). The rays must be [`packet_compatible`].
    pub fn first_hit_packet<C: CellIntersector, S: Stats>(
        &self,
        frame: &TraversalFrame,
        voxels: &[T],
        rays: &[LocalRay],
        t0: &[f32],
        t1: &[f32],
        isos: &IsoSet<T>,
        intersector: C,
        stats: &mut S,
        out: &mut [Option<CellHit>],
    ) {
        let mut stack = PacketStack::default();
        self.first_hit_packet_in(
            &mut stack,
            frame,
            voxels,
            rays,
            t0,
            t1,
            isos,
            intersector,
            stats,
            out,
        );
    }

    /// Whether each of up to [`PACKET_WIDTH`] [`packet_compatible`] rays has a hit in
    /// `[t0[i], t1[i]]` (shadow rays), written to `out[i]`: a lane ends at its first hit
    /// found, and a crossing the `f32` filter certifies is a hit without its root refined.
    #[allow(clippy::too_many_arguments)]
    #[inline]
    pub fn any_hit_packet_in<C: CellIntersector, S: Stats>(
        &self,
        stack: &mut PacketStack,
        frame: &TraversalFrame,
        voxels: &[T],
        rays: &[LocalRay],
        t0: &[f32],
        t1: &[f32],
        isos: &IsoSet<T>,
        intersector: C,
        stats: &mut S,
        out: &mut [bool],
    ) {
        let n = rays.len().min(PACKET_WIDTH);
        for o in &mut out[..n] {
            *o = false;
        }
        self.walk_packet_in(
            stack,
            frame,
            voxels,
            rays,
            t0,
            t1,
            isos,
            intersector,
            stats,
            u64::MAX,
            WalkFor::AnyHit,
            |k, _| {
                out[k] = true;
                // Nothing past it is live for the lane.
                LaneNext::Stop(f32::NEG_INFINITY)
            },
        );
    }

    /// [`KdTree::first_hit_packet`] with a caller's stack (reused across packets).
    #[inline]
    pub fn first_hit_packet_in<C: CellIntersector, S: Stats>(
        &self,
        stack: &mut PacketStack,
        frame: &TraversalFrame,
        voxels: &[T],
        rays: &[LocalRay],
        t0: &[f32],
        t1: &[f32],
        isos: &IsoSet<T>,
        intersector: C,
        stats: &mut S,
        out: &mut [Option<CellHit>],
    ) {
        let n = rays.len().min(PACKET_WIDTH);
        for o in &mut out[..n] {
            *o = None;
        }
        self.walk_packet_in(
            stack,
            frame,
            voxels,
            rays,
            t0,
            t1,
            isos,
            intersector,
            stats,
            // Every hit ends its lane.
            u64::MAX,
            WalkFor::Hits,
            |k, hit| {
                out[k] = Some(hit);
                LaneNext::Stop(hit.t)
            },
        );
    }

    /// The packet walk of [`KdTree::first_hit_packet_in`], handing every cell hit nearer than
    /// its lane's cut to `on_hit`, which says whether the lane stops there or goes on past
    /// it ([`packet_leaf`]): a first-hit search, or one that collects a ray's transparent
    /// layers as it goes ([`crate::render::IsoScene::peeled_hits_packet_prepared`]).
    /// `defers`: bit `s` when `on_hit` stops its lane at every hit on surface `s`
    /// ([`LaneNext::Stop`] at the hit), so a lane whose such hit's cell is certain may have
    /// its root found after the walk ([`Deferred`]; in cells holding that isovalue only).
    /// `walk_for`: [`WalkFor::AnyHit`] hands such a lane to `on_hit` at its segment's start
    /// instead, its root not found (whether the ray hits, not where).
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    pub(crate) fn walk_packet_in<C: CellIntersector, S: Stats>(
        &self,
        stack: &mut PacketStack,
        frame: &TraversalFrame,
        voxels: &[T],
        rays: &[LocalRay],
        t0: &[f32],
        t1: &[f32],
        isos: &IsoSet<T>,
        intersector: C,
        stats: &mut S,
        defers: u64,
        walk_for: WalkFor,
        mut on_hit: impl FnMut(usize, CellHit) -> LaneNext,
    ) {
        let PacketStack {
            entries: stack,
            rays: p,
            deferred,
        } = stack;
        let n = rays.len().min(PACKET_WIDTH);
        if self.levels.is_empty() || isos.is_empty() || n == 0 {
            return;
        }
        debug_assert!(packet_compatible(&rays[..n]));
        if self.depth >= INLINE_STACK {
            // Absurdly deep trees (> 2^64 cells): trace one by one.
            for i in 0..n {
                ray_go_on(
                    t0[i],
                    t1[i],
                    |t| self.first_hit(frame, voxels, &rays[i], t, t1[i], isos, intersector, stats),
                    |hit| on_hit(i, hit),
                );
            }
            return;
        }
        // Children are culled before they are entered or pushed; only the root here.
        if self.stored > 0 && !isos.any_in(self.ranges[0][0], self.ranges[0][1]) {
            return;
        }
        p.set(&rays[..n], &t0[..n], &t1[..n]);
        let (mut tn, mut tf) = (p.t_near, p.t_far);
        deferred.lanes = 0;
        deferred.surfaces = defers;
        let mut best = [f32::INFINITY; PACKET_WIDTH];
        let mut best_v = splat(f32::INFINITY);
        let mut sp = 0usize;
        let mut node = [0u32; 3];
        let mut level = 0usize;
        'outer: loop {
            loop {
                let active = tn.simd_le(tf);
                if !any_lane(&active) {
                    break;
                }
                if level == self.depth {
                    let cell = node.map(|x| x as usize);
                    best_v = packet_leaf(
                        frame,
                        voxels,
                        self.dims,
                        cell,
                        p,
                        mask_bits(&active),
                        isos,
                        intersector,
                        stats,
                        &mut best,
                        (defers != 0).then_some(&mut *deferred),
                        &mut on_hit,
                    );
                    break;
                }
                stats.node();
                let ch = self.children(level, node, isos);
                level += 1;
                let a = ch.axis;
                let ts = (f32x16::splat(ch.split) - p.org[a]) * p.inv[a];
                let step = Step {
                    near_is_left: p.dir_pos[a],
                    visit: packet_visit(&active, &ts, &tn, &tf),
                };
                match ch.descend(step, level, &mut tf, stack, &mut sp) {
                    Some(next) => node = next,
                    None => break,
                }
            }
            loop {
                if sp == 0 {
                    break 'outer;
                }
                sp -= 1;
                let e = stack[sp];
                let e_tf = e.t_far.min(best_v);
                if any_lane(&e.t_near.simd_le(e_tf)) {
                    node = e.node;
                    level = e.level as usize;
                    tn = e.t_near;
                    tf = e_tf;
                    continue 'outer;
                }
            }
        }
        if deferred.lanes != 0 && walk_for == WalkFor::AnyHit {
            for k in lane_indices(deferred.lanes) {
                let (t_near, _) = deferred.segment[k];
                let hit = CellHit {
                    t: t_near,
                    surface: deferred.iso[k].1,
                    cell: deferred.cell[k],
                };
                let _ = on_hit(k, hit);
            }
        } else if deferred.lanes != 0 {
            let retrace = |k: usize, t: f32| {
                self.first_hit(frame, voxels, &rays[k], t, t1[k], isos, intersector, stats)
            };
            deferred.resolve(frame, voxels, self.dims, p, retrace, on_hit);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::rng::Rng;
    use glam::Vec3;

    /// Gathered slots hold exactly the active lanes of both halves, each once, with their
    /// rays' values.
    #[test]
    fn gathered_slots_hold_each_active_lane_once() {
        let mut rng = Rng::new(7);
        let mut tried = 0;
        for _ in 0..2000 {
            let rays: Vec<LocalRay> = (0..PACKET_WIDTH)
                .map(|_| {
                    let o = Vec3::new(
                        rng.range_f32(-3.0, 3.0),
                        rng.range_f32(-3.0, 3.0),
                        rng.range_f32(-3.0, 3.0),
                    );
                    let d = Vec3::new(
                        rng.range_f32(0.1, 1.0),
                        -rng.range_f32(0.1, 1.0),
                        rng.range_f32(0.1, 1.0),
                    );
                    LocalRay::new(o, d)
                })
                .collect();
            let t0: Vec<f32> = (0..PACKET_WIDTH).map(|_| rng.range_f32(0.0, 1.0)).collect();
            let t1: Vec<f32> = t0.iter().map(|t| t + rng.range_f32(0.0, 5.0)).collect();
            let mut p = PacketRays::EMPTY;
            p.set(&rays, &t0, &t1);
            let active = rng.next_u32() & 0xffff;
            if active.trailing_zeros() >= 8 || active >> 8 == 0 || active.count_ones() > 8 {
                continue;
            }
            tried += 1;
            let undeferred = rng.next_u32();
            let g = gather_halves(&mut p, active, undeferred);
            let (lane, slots) = (g.lane, g.slots);
            assert_eq!(slots.count_ones(), active.count_ones());
            let mut seen = 0u32;
            for i in lane_indices(slots) {
                let k = usize::from(lane[i]);
                assert!(active >> k & 1 == 1, "slot {i} holds inactive lane {k}");
                assert!(seen >> k & 1 == 0, "lane {k} twice");
                seen |= 1 << k;
                let (got, want) = (p.gathered.lane(i), rays[k]);
                assert_eq!(got.origin, want.origin);
                assert_eq!(got.dir, want.dir);
                assert_eq!(got.inv_dir, want.inv_dir);
                assert_eq!(p.gathered.t_lo.as_array()[i], t0[k]);
                assert_eq!(p.gathered.t_hi.as_array()[i], t1[k]);
                assert_eq!(g.may_defer >> i & 1, undeferred >> k & 1);
            }
            assert_eq!(seen, active);
            assert_eq!(p.gathered.dir_pos, [true, false, true]);
        }
        assert!(tried > 100, "{tried} masks tried");
    }
}
