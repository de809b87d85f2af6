//! From a traversal's cell hit to a world-space [`Hit`]: [`first_hit_with`], the one
//! first-hit loop of the kd-tree scene ([`super::GridScene`]), its DDA twin
//! ([`super::DdaScene`]) and the out-of-core scene ([`crate::ooc::OocScene`]);
//! [`first_hits_packet_with`], the one packet loop of the kd-tree and out-of-core scenes; and
//! [`make_hit`], the hit with its shading normal ([`super::normals`]), which a packet's hits in
//! one voxel block get together (`make_hits_in_block`: smooth normals 8 at a time).

use glam::Vec3;

use super::normals::{faceted_normal_at, normal_at, normals_x8};
use crate::intersect::{CellHit, CellIntersector, LocalRay, TraversalFrame};
use crate::kdtree::packet::LaneNext;
use crate::kdtree::{PACKET_WIDTH, packet_compatible};
use crate::math::Ray;
use crate::render::{Hit, MAX_PEELED, Normals, Peel, Stats};
use crate::voxel::Voxel;

/// The voxel block a cell hit lies in (the grid's, or an out-of-core treelet's), which its
/// normal is computed from.
#[derive(Debug, Clone, Copy)]
pub struct CellBlock<'a, T: Voxel> {
    pub frame: &'a TraversalFrame,
    pub voxels: &'a [T],
    pub dims: [usize; 3],
}

impl<T: Voxel> CellBlock<'_, T> {
    /// Whether `other` is this very block (the same frame and voxels, not equal copies).
    #[inline]
    pub(crate) fn same_as(&self, other: &Self) -> bool {
        std::ptr::eq(self.frame, other.frame) && std::ptr::eq(self.voxels, other.voxels)
    }
}

/// A structure that finds the first cell hit of a ray in traversal units.
pub trait CellTrace<T: Voxel> {
    /// The active isovalues as the traversal reads them
    /// ([`crate::render::IsoScene::prepare`]).
    type Isovalues;

    /// The frame world rays are mapped into.
    fn frame(&self) -> &TraversalFrame;

    /// The shading normal hits of these isovalues need, if any
    /// ([`crate::intersect::IsoSet::normals`]).
    fn normals(isos: &Self::Isovalues) -> Option<Normals>;

    /// The first cell hit in `[t_min, t_max]` and the block holding its cell.
    fn cell_hit<C: CellIntersector, S: Stats>(
        &self,
        ray: &LocalRay,
        t_min: f32,
        t_max: f32,
        isos: &Self::Isovalues,
        intersector: C,
        stats: &mut S,
    ) -> Option<(CellHit, CellBlock<'_, T>)>;

    /// First cell hits of up to [`PACKET_WIDTH`] [`packet_compatible`] rays over their
    /// clipped intervals `[t0[i], t1[i]]` (empty when `t0[i] > t1[i]`), equal to
    /// [`CellTrace::cell_hit`] ray by ray. The default traces them one by one.
    #[allow(clippy::too_many_arguments)]
    fn cell_hits_packet<'s, C: CellIntersector, S: Stats>(
        &'s self,
        rays: &[LocalRay],
        t0: &[f32],
        t1: &[f32],
        isos: &Self::Isovalues,
        intersector: C,
        stats: &mut S,
        out: &mut [Option<(CellHit, CellBlock<'s, T>)>],
    ) {
        for (i, ray) in rays.iter().enumerate() {
            out[i] = if t0[i] <= t1[i] {
                self.cell_hit(ray, t0[i], t1[i], isos, intersector, stats)
            } else {
                None
            };
        }
    }
}

/// [`crate::render::IsoScene::first_hit_prepared`] of `scene` with a static intersector `C`
/// (no per-ray dispatch): the ray in traversal units, the cell hit, its normal.
#[inline]
pub fn first_hit_with<T: Voxel, G: CellTrace<T>, C: CellIntersector, S: Stats>(
    scene: &G,
    ray: &Ray,
    t_min: f32,
    t_max: f32,
    isos: &G::Isovalues,
    intersector: C,
    stats: &mut S,
) -> Option<Hit> {
    stats.ray();
    let local = scene.frame().to_local(ray);
    let (h, block) = scene.cell_hit(&local, t_min, t_max, isos, intersector, stats)?;
    Some(make_hit(
        block.frame,
        block.voxels,
        block.dims,
        &local,
        ray,
        h,
        G::normals(isos),
    ))
}

/// Up to [`PACKET_WIDTH`] world rays in traversal units, clipped to the traversal box.
pub(crate) struct LocalPacket {
    pub n: usize,
    pub local: [LocalRay; PACKET_WIDTH],
    pub t0: [f32; PACKET_WIDTH],
    pub t1: [f32; PACKET_WIDTH],
    /// The rays share direction signs and have no zero component: one packet.
    pub one_packet: bool,
}

impl LocalPacket {
    #[inline(always)]
    pub(crate) fn new(frame: &TraversalFrame, rays: &[Ray], t_min: &[f32], t_max: &[f32]) -> Self {
        let n = rays.len().min(PACKET_WIDTH);
        let mut local = [LocalRay::new(Vec3::ZERO, Vec3::ZERO); PACKET_WIDTH];
        let mut t0 = [f32::INFINITY; PACKET_WIDTH];
        let mut t1 = [f32::NEG_INFINITY; PACKET_WIDTH];
        let (nonzero, positive) =
            frame.to_local_clipped(rays, t_min, t_max, &mut local, &mut t0, &mut t1);
        let lanes = (1u32 << n) - 1;
        // `packet_compatible` from the lane masks: no zero component, one sign per axis.
        let one_packet =
            n > 0 && nonzero == lanes && positive.iter().all(|&p| p == 0 || p == lanes);
        Self {
            n,
            local,
            t0,
            t1,
            one_packet,
        }
    }

    /// Hands the rays, in order, to `packet(state, from, to)` where they travel as one packet
    /// (all of them, or a group of 8 sharing direction signs) and to `alone(state, i)` one
    /// by one otherwise (rays on both sides of an axis-parallel direction).
    #[inline(always)]
    pub(crate) fn for_each_group<X>(
        &self,
        state: &mut X,
        mut packet: impl FnMut(&mut X, usize, usize),
        mut alone: impl FnMut(&mut X, usize),
    ) {
        if self.one_packet {
            packet(state, 0, self.n);
            return;
        }
        for from in (0..self.n).step_by(8) {
            let to = (from + 8).min(self.n);
            if packet_compatible(&self.local[from..to]) {
                packet(state, from, to);
            } else {
                for i in from..to {
                    alone(state, i);
                }
            }
        }
    }
}

/// [`crate::render::IsoScene::first_hit_packet_prepared`] of `scene` for up to
/// [`PACKET_WIDTH`] rays with a static intersector: the rays in traversal units and clipped,
/// then one packet ([`CellTrace::cell_hits_packet`]) when their directions allow it, else
/// groups of 8 as packets or one by one; same hits as [`first_hit_with`] either way.
#[allow(clippy::too_many_arguments)]
#[inline]
pub fn first_hits_packet_with<T: Voxel, G: CellTrace<T>, C: CellIntersector, S: Stats>(
    scene: &G,
    rays: &[Ray],
    t_min: &[f32],
    t_max: &[f32],
    isos: &G::Isovalues,
    intersector: C,
    out: &mut [Option<Hit>],
    stats: &mut S,
) {
    let lp = LocalPacket::new(scene.frame(), rays, t_min, t_max);
    let (n, local, t0, t1) = (lp.n, &lp.local, &lp.t0, &lp.t1);
    for _ in 0..n {
        stats.ray();
    }
    let mut cell_hits = [None; PACKET_WIDTH];
    lp.for_each_group(
        &mut (&mut cell_hits, stats),
        |(cell_hits, stats), from, to| {
            scene.cell_hits_packet(
                &local[from..to],
                &t0[from..to],
                &t1[from..to],
                isos,
                intersector,
                *stats,
                &mut cell_hits[from..to],
            );
        },
        |(cell_hits, stats), i| {
            if t0[i] <= t1[i] {
                // Clipping again inside `cell_hit` changes nothing (a slab test of the same
                // box).
                cell_hits[i] = scene.cell_hit(&local[i], t0[i], t1[i], isos, intersector, *stats);
            }
        },
    );
    // Runs of hit lanes in one block (the whole packet in core) get their hits together.
    let normals = G::normals(isos);
    let mut lanes = [0usize; PACKET_WIDTH];
    let mut hits = [CellHit::NONE; PACKET_WIDTH];
    let mut i = 0;
    while i < n {
        let Some((_, block)) = cell_hits[i] else {
            out[i] = None;
            i += 1;
            continue;
        };
        let mut m = 0;
        while i < n {
            match cell_hits[i] {
                None => out[i] = None,
                Some((h, b)) if b.same_as(&block) => {
                    (lanes[m], hits[m]) = (i, h);
                    m += 1;
                }
                Some(_) => break,
            }
            i += 1;
        }
        make_hits_in_block(
            &block,
            local,
            rays,
            &lanes[..m],
            &hits[..m],
            normals,
            |j, hit| {
                out[lanes[j]] = Some(hit);
            },
        );
    }
}

/// The layers each lane of a packet collects as it goes on past transparent hits
/// ([`crate::render::IsoScene::peeled_hits_packet_prepared`]), in order of distance.
pub(crate) struct LaneLayers {
    peel: Peel,
    cap: usize,
    n: [usize; PACKET_WIDTH],
    hits: [[CellHit; MAX_PEELED]; PACKET_WIDTH],
}

impl LaneLayers {
    pub(crate) fn new(peel: &Peel) -> Self {
        Self {
            peel: *peel,
            cap: peel.cap(),
            n: [0; PACKET_WIDTH],
            hits: [[CellHit::NONE; MAX_PEELED]; PACKET_WIDTH],
        }
    }

    /// Takes lane `k`'s hit: the lane stops at its last layer when that ends the ray or
    /// the layers are full, else goes on from [`Peel::next_t`] of it. Hits come in order of
    /// distance, but for a ray through a cell edge that two visited cells share: sorted in.
    #[inline]
    pub(crate) fn add(&mut self, k: usize, hit: CellHit) -> LaneNext {
        let (list, n) = (&mut self.hits[k], &mut self.n[k]);
        let mut i = *n;
        while i > 0 && list[i - 1].t > hit.t {
            i -= 1;
        }
        if i < self.cap {
            let end = (*n + 1).min(self.cap);
            list.copy_within(i..end - 1, i + 1);
            list[i] = hit;
            *n = if self.peel.ends_ray(hit.surface) {
                i + 1
            } else {
                end
            };
        }
        let last = list[*n - 1];
        if *n == self.cap || self.peel.ends_ray(last.surface) {
            LaneNext::Stop(last.t)
        } else {
            LaneNext::GoOnFrom(self.peel.next_t(last.t))
        }
    }

    pub(crate) fn of(&self, k: usize) -> &[CellHit] {
        &self.hits[k][..self.n[k]]
    }

    /// Whether lane `k` may hit more past its last layer: the layers are full and the
    /// last one does not end the ray.
    pub(crate) fn more(&self, k: usize) -> bool {
        let n = self.n[k];
        n == self.cap && !self.peel.ends_ray(self.hits[k][n - 1].surface)
    }
}

/// Turns a cell hit into a [`Hit`] with a world-space normal of kind `normal`
/// ([`super::normals`]), else the ray's reverse (a frame of hit distances only; the
/// smooth gradient is about a tenth of a shaded frame, `docs/benchmarks.md`).
pub fn make_hit<T: Voxel>(
    frame: &TraversalFrame,
    voxels: &[T],
    dims: [usize; 3],
    local: &LocalRay,
    world: &Ray,
    h: CellHit,
    normal: Option<Normals>,
) -> Hit {
    let normal = normal.and_then(|kind| {
        let uvw = hit_uvw(frame, local, &h);
        match kind {
            Normals::Smooth => normal_at(frame, voxels, dims, h.cell, uvw),
            Normals::Faceted => faceted_normal_at(frame, voxels, dims, h.cell, uvw),
        }
    });
    hit_facing(h, normal, world)
}

/// Where hit `h` lies in its cell, in `[0, 1]³` (what the normals read).
#[inline(always)]
fn hit_uvw(frame: &TraversalFrame, local: &LocalRay, h: &CellHit) -> Vec3 {
    let (lo, hi) = frame.cell_box(h.cell);
    let p = local.origin + local.dir * h.t;
    ((p - lo) / (hi - lo)).clamp(Vec3::ZERO, Vec3::ONE)
}

/// The [`Hit`] of `h` with `normal`, else the ray's reverse.
#[inline]
fn hit_facing(h: CellHit, normal: Option<Vec3>, world: &Ray) -> Hit {
    Hit {
        t: h.t,
        surface: h.surface,
        normal: normal.unwrap_or_else(|| (-world.dir).normalize_or(Vec3::Z)),
        cell: 0,
    }
}

/// [`make_hit`] of the cell hits `hits[j]` of the rays `lanes[j]`, all in `block`, handed to
/// `put(j, hit)`: smooth normals 8 at a time side by side ([`normals_x8`], the same normals
/// bit for bit), other kinds one by one.
pub(crate) fn make_hits_in_block<T: Voxel>(
    block: &CellBlock<'_, T>,
    local: &[LocalRay],
    rays: &[Ray],
    lanes: &[usize],
    hits: &[CellHit],
    normal: Option<Normals>,
    mut put: impl FnMut(usize, Hit),
) {
    if normal != Some(Normals::Smooth) {
        for (j, (&i, &h)) in lanes.iter().zip(hits).enumerate() {
            let (f, v, d) = (block.frame, block.voxels, block.dims);
            put(j, make_hit(f, v, d, &local[i], &rays[i], h, normal));
        }
        return;
    }
    for (c, (lanes, hits)) in lanes.chunks(8).zip(hits.chunks(8)).enumerate() {
        let m = lanes.len();
        let mut cells = [[0usize; 3]; 8];
        let mut uvw = [Vec3::ZERO; 8];
        for (j, (&i, h)) in lanes.iter().zip(hits).enumerate() {
            cells[j] = h.cell;
            uvw[j] = hit_uvw(block.frame, &local[i], h);
        }
        let normals = normals_x8(
            block.frame,
            block.voxels,
            block.dims,
            &cells[..m],
            &uvw[..m],
        );
        for (j, (&i, &h)) in lanes.iter().zip(hits).enumerate() {
            put(c * 8 + j, hit_facing(h, normals.get(j), &rays[i]));
        }
    }
}
