//! The implicit min/max kd-tree over the cells of a rectilinear volume (thesis seed 004
//! §7.1–7.3, §7.6), in the *slim* layout:
//!
//! - **No pointers** (§7.3.1): each axis is virtually padded to a power of two
//!   (§7.3.3), so the tree is balanced and every level splits one dimension: the one along
//!   which the nodes are longest in world space ([`split_axis`]; x before y before z on
//!   ties, so an isotropic grid halves x, y, z in turn). A node is addressed by
//!   `(i, j, k, level)`; its children along the level's axis `a` are `2·idx[a]` and
//!   `2·idx[a] + 1`. Min/max live in one flat array per level holding only the *real*
//!   nodes (`ceil(cells / extent)` per axis); virtual nodes lie beyond the volume bounds,
//!   which every ray is clipped to, and their split positions are `+inf`, so they are never
//!   stored nor visited. Each level's array is row-major with the *parent's* split axis
//!   varying fastest, so two siblings are adjacent: a traversal step reads both children's
//!   ranges from one cache line and culls them before descending or pushing.
//! - **Per-level split tables**: the split of node `idx[a]` at a level is the sample
//!   coordinate of cell boundary `idx[a]·extent + extent/2` (traversal units, see
//!   [`crate::intersect::frame`]). A spacing edit only rebuilds these tables (§7.6).
//! - **Native type**: min/max are stored as `[T; 2]` (u8 data gives a u8 tree).
//! - **No leaves** (§7.3.2): a leaf's range is computed from the cell's 8 corners. Going
//!   further than the thesis, the lowest [`KdTreeConfig::unstored_levels`] inner levels are
//!   not stored either: traversal descends through them without culling (every cell still
//!   gets its exact corner test). Each skipped level halves the memory (thesis: 2× the data
//!   for the full tree; 3 skipped levels: 0.25×); the cost in traversal steps is measured in
//!   docs/benchmarks.md.
//! - **Void**: a cell with a non-finite corner has an empty range; a node of only void
//!   cells has the empty range `[HIGHEST, LOWEST]`, which no isovalue satisfies.
//! - **Build** (§7.1.2) is O(N) and parallel (rayon): the lowest stored level from the
//!   voxels, every level above from its two children. [`KdTree::refit_region`] redoes only
//!   the nodes over an edited voxel box (§7.6).
//!
//! Traversal ([`KdTree::first_hit`]) is single-ray front to back with isovalue culling
//! (§7.2.1), robust for rays lying in a split plane (seed 000 §5, Havran: both children are
//! visited, since the surface on a shared face may belong to either cell), with any number
//! of isovalues in one pass. That child-ordering step is written once (`step.rs`) and shared
//! with the packet traversal and the out-of-core one ([`crate::ooc`]).

pub(crate) mod packet;
pub(crate) mod step;

pub use packet::{PACKET_WIDTH, PacketStack, packet_compatible, with_packet_stack};

use std::time::{Duration, Instant};

use rayon::prelude::*;

use crate::intersect::{
    CellHit, CellIntersector, IsoSet, LocalRay, TraversalFrame, cell_corners, corner_range,
    intersect_cell,
};
use crate::math::{prefetch, union_of_cell_boxes};
use crate::render::Stats;
use crate::voxel::Voxel;
use step::{Step, ray_step, take_step};

/// Build options.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct KdTreeConfig {
    /// Inner levels directly above the leaves whose min/max are not stored (0 = thesis
    /// layout with all inner nodes).
    pub unstored_levels: usize,
}

impl Default for KdTreeConfig {
    fn default() -> Self {
        Self { unstored_levels: 2 }
    }
}

/// The axis a level splits: of those with more than one cell per node, the one along which
/// its nodes are longest in world space (`extent` cells of `cell_mm` each), x before y
/// before z on ties (within a relative 1e-9, so a rotation's rounding of equal spacings
/// keeps the order). On an anisotropic grid (a CT of 0.57 mm pixels and 5 mm slices)
/// index-space halving would keep nodes 8.8× longer along the slices than across them,
/// boxes that rays graze without meeting their surface; near-cubic nodes in world space
/// cull them (docs/benchmarks.md, *Anisotropic voxels*).
pub fn split_axis(extent: [usize; 3], cell_mm: [f64; 3]) -> usize {
    // An axis down to one cell cannot split (the cell level's axis is unused: 0).
    let len = [0, 1, 2].map(|a| {
        if extent[a] > 1 {
            extent[a] as f64 * cell_mm[a]
        } else {
            0.0
        }
    });
    let mut axis = 0;
    for a in 1..3 {
        if len[a] > len[axis] * (1.0 + 1e-9) {
            axis = a;
        }
    }
    axis
}

/// Trees whose min/max take less than this stay in the last-level cache while a frame is
/// traced, and the grandchild prefetch of the descent step ([`KdTree::prefetch_grandchildren`])
/// only costs instructions there: measured on the MNI MRI's 4.3 MB tree, a frame 2 % faster
/// without it; on a 56 MB tree 1 % slower (docs/benchmarks.md). 8 MiB: below the L3 of
/// current desktop and server cores, above their L2.
pub(crate) const PREFETCH_MIN_TREE_BYTES: usize = 8 << 20;

#[derive(Debug, Clone, Copy)]
struct Level {
    /// Split dimension of this level's nodes (unused at the leaf level).
    axis: usize,
    /// Cells per node side, virtual padding included (a power of two).
    extent: [usize; 3],
    /// Real nodes per axis: `ceil(cells / extent)`.
    count: [usize; 3],
    range_offset: usize,
    split_offset: usize,
    /// One-hot `axis` (`[1, 0, 0]` for x).
    unit: [u32; 3],
    /// Real children along `axis` (the next level's count).
    child_count: u32,
    /// Address strides of this level's min/max array (the parent's split axis has stride 1,
    /// so siblings are adjacent).
    stride: [usize; 3],
    /// Axes from fastest to slowest varying address.
    order: [usize; 3],
    /// The next level's `stride` and `range_offset` (read by the descent step).
    child_stride: [usize; 3],
    child_offset: usize,
    /// Address distance between the child pairs of a right and a left node of this level
    /// (siblings: `right = left + parent unit`), for the prefetch.
    grand_delta: usize,
}

/// The implicit min/max kd-tree (see the module docs).
#[derive(Debug, Clone)]
pub struct KdTree<T: Voxel> {
    dims: [usize; 3],
    cells: [usize; 3],
    /// Number of inner levels; leaves (cells) are level `depth`.
    depth: usize,
    /// Levels `0..stored` carry min/max.
    stored: usize,
    /// The descent step prefetches its grandchildren's ranges when `level + 1 <
    /// prefetch_below`: `stored` for trees of at least [`PREFETCH_MIN_TREE_BYTES`], else 0.
    prefetch_below: usize,
    /// `depth + 1` entries (the last describes the leaves).
    levels: Vec<Level>,
    ranges: Vec<[T; 2]>,
    splits: Vec<f32>,
    build_time: Duration,
}

/// One pending far child on a traversal stack; `L` is a ray's `t` (`f32`) or a packet's
/// lanes.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct Entry<L> {
    pub node: [u32; 3],
    pub level: u32,
    pub t_near: L,
    pub t_far: L,
}

/// Stack entries kept inline (trees deeper than this fall back to a heap stack).
pub(crate) const INLINE_STACK: usize = 64;

/// Most nodes [`KdTree::live_cell_box`] scans: the box comes within a node's extent of the
/// live cells (8 cells for a 256³ grid: 32³ nodes) for well under 0.1 ms of work per frame.
pub const LIVE_BOX_NODES: usize = 1 << 15;

/// Most nodes whose boxes the renderer projects to find the pixels that can see a surface
/// ([`crate::render::IsoScene::live_boxes`]): 16³-cell nodes for a 256³ grid, a few
/// thousand boxes a frame.
pub const LIVE_COVER_NODES: usize = 1 << 12;

impl<T: Voxel> KdTree<T> {
    /// Builds the tree over `voxels` (x fastest, `dims` samples) with split positions from
    /// `frame`.
    pub fn build(
        voxels: &[T],
        dims: [usize; 3],
        frame: &TraversalFrame,
        config: KdTreeConfig,
    ) -> Self {
        let start = Instant::now();
        assert_eq!(voxels.len(), dims[0] * dims[1] * dims[2], "voxel count");
        let cells = dims.map(|d| d.saturating_sub(1));
        // Node coordinates are u32 per axis (linear addresses are 64-bit).
        assert!(
            dims.iter().all(|&d| u32::try_from(d).is_ok()),
            "more than 2^32 samples along one axis"
        );
        let mut levels = Vec::new();
        let cell_mm = frame.cell_width_world();
        if !cells.contains(&0) {
            let mut extent = cells.map(usize::next_power_of_two);
            let (mut range_offset, mut split_offset) = (0, 0);
            loop {
                let count = [0, 1, 2].map(|a| cells[a].div_ceil(extent[a]));
                let axis = split_axis(extent, cell_mm);
                // The axis the parent split varies fastest (x at the root).
                let fast = levels.last().map_or(0, |p: &Level| p.axis);
                let mut order = [fast, 0, 0];
                let mut n = 1;
                for b in 0..3 {
                    if b != fast {
                        order[n] = b;
                        n += 1;
                    }
                }
                let mut stride = [0; 3];
                stride[order[0]] = 1;
                stride[order[1]] = count[order[0]];
                stride[order[2]] = count[order[0]] * count[order[1]];
                levels.push(Level {
                    axis,
                    extent,
                    count,
                    range_offset,
                    split_offset,
                    unit: [0, 1, 2].map(|b| u32::from(b == axis)),
                    child_count: 0,
                    stride,
                    order,
                    child_stride: [0; 3],
                    child_offset: 0,
                    grand_delta: 0,
                });
                if extent == [1, 1, 1] {
                    break;
                }
                range_offset += count[0] * count[1] * count[2];
                split_offset += count[axis];
                extent[axis] /= 2;
            }
        }
        for l in 1..levels.len() {
            let a = levels[l - 1].axis;
            levels[l - 1].child_count = levels[l].count[a] as u32;
            levels[l - 1].child_stride = levels[l].stride;
            levels[l - 1].child_offset = levels[l].range_offset;
        }
        for l in 1..levels.len() {
            // (left + u_parent) << u = (left << u) + (u_parent << u), and addresses are linear.
            let a = levels[l - 1].axis;
            levels[l].grand_delta = levels[l].child_stride[a] << levels[l].unit[a];
        }
        let depth = levels.len().saturating_sub(1);
        let stored = depth.saturating_sub(config.unstored_levels);
        let n_ranges = levels.get(stored).map_or(0, |l| l.range_offset);
        let tree_bytes = n_ranges * size_of::<[T; 2]>();
        let mut tree = Self {
            dims,
            cells,
            depth,
            stored,
            prefetch_below: if tree_bytes >= PREFETCH_MIN_TREE_BYTES {
                stored
            } else {
                0
            },
            levels,
            ranges: vec![[T::HIGHEST, T::LOWEST]; n_ranges],
            splits: Vec::new(),
            build_time: Duration::ZERO,
        };
        tree.set_coordinates(frame);
        if stored > 0 {
            let all = [[0, 0, 0], tree.levels[stored - 1].count.map(|c| c - 1)];
            tree.refit_nodes(voxels, all);
        }
        tree.build_time = start.elapsed();
        tree
    }

    /// Recomputes the split tables from new sample coordinates (same dims; thesis §7.6).
    pub fn set_coordinates(&mut self, frame: &TraversalFrame) {
        assert_eq!(frame.cells(), self.cells, "coordinates for other dims");
        self.splits.clear();
        for l in 0..self.depth {
            let lv = self.levels[l];
            let a = lv.axis;
            debug_assert_eq!(lv.split_offset, self.splits.len());
            for i in 0..lv.count[a] {
                let m = i * lv.extent[a] + lv.extent[a] / 2;
                self.splits.push(if m < self.cells[a] {
                    frame.pos()[a][m]
                } else {
                    f32::INFINITY
                });
            }
        }
    }

    /// Refits min/max after the voxels in the inclusive box `[lo, hi]` changed (thesis §7.6):
    /// only nodes over the affected cells are recomputed.
    pub fn refit_region(&mut self, voxels: &[T], lo: [usize; 3], hi: [usize; 3]) {
        assert_eq!(
            voxels.len(),
            self.dims.iter().product::<usize>(),
            "voxel count"
        );
        if self.stored == 0 {
            return;
        }
        let bottom = self.levels[self.stored - 1];
        let mut box_lo = [0; 3];
        let mut box_hi = [0; 3];
        for a in 0..3 {
            // Cells touching the voxels lo..=hi are lo−1 ..= hi.
            let c_lo = lo[a].saturating_sub(1);
            let c_hi = hi[a].min(self.cells[a] - 1);
            if c_lo > c_hi {
                return;
            }
            box_lo[a] = c_lo / bottom.extent[a];
            box_hi[a] = c_hi / bottom.extent[a];
        }
        self.refit_nodes(voxels, [box_lo, box_hi]);
    }

    /// Recomputes the lowest stored level over the node box `b` (inclusive), then every
    /// level above.
    fn refit_nodes(&mut self, voxels: &[T], b: [[usize; 3]; 2]) {
        let sb = self.stored - 1;
        let lv = self.levels[sb];
        let (dims, cells) = (self.dims, self.cells);
        let (start, end) = (
            lv.range_offset,
            lv.range_offset + lv.count.iter().product::<usize>(),
        );
        let level = &mut self.ranges[start..end];
        let [lo, hi] = b;
        // One row (along the level's fastest axis) per task.
        let [f, m, s] = lv.order;
        level
            .par_chunks_mut(lv.count[f])
            .enumerate()
            .for_each(|(row, out)| {
                let mut n = [0; 3];
                n[m] = row % lv.count[m];
                n[s] = row / lv.count[m];
                if n[m] < lo[m] || n[m] > hi[m] || n[s] < lo[s] || n[s] > hi[s] {
                    return;
                }
                for (i, o) in out.iter_mut().enumerate().take(hi[f] + 1).skip(lo[f]) {
                    n[f] = i;
                    *o = node_range_from_cells(voxels, dims, cells, lv.extent, n);
                }
            });
        let (mut lo, mut hi) = (lo, hi);
        for l in (0..sb).rev() {
            let parent = self.levels[l];
            let child = self.levels[l + 1];
            let a = parent.axis;
            lo[a] /= 2;
            hi[a] /= 2;
            let (head, tail) = self.ranges.split_at_mut(child.range_offset);
            let parents = &mut head[parent.range_offset..];
            let children = &tail[..child.count.iter().product::<usize>()];
            let [f, m, s] = parent.order;
            parents
                .par_chunks_mut(parent.count[f])
                .enumerate()
                .for_each(|(row, out)| {
                    let mut n = [0; 3];
                    n[m] = row % parent.count[m];
                    n[s] = row / parent.count[m];
                    if n[m] < lo[m] || n[m] > hi[m] || n[s] < lo[s] || n[s] > hi[s] {
                        return;
                    }
                    for (i, o) in out.iter_mut().enumerate().take(hi[f] + 1).skip(lo[f]) {
                        n[f] = i;
                        let mut c = n;
                        c[a] *= 2;
                        let mut r = children[child_addr(&child, c)];
                        c[a] += 1;
                        if c[a] < child.count[a] {
                            r = union(r, children[child_addr(&child, c)]);
                        }
                        *o = r;
                    }
                });
        }
    }

    /// Bytes of tree storage (min/max arrays, split tables, level descriptors).
    pub fn memory_bytes(&self) -> usize {
        self.ranges.len() * size_of::<[T; 2]>()
            + self.splits.len() * size_of::<f32>()
            + self.levels.len() * size_of::<Level>()
            + size_of::<Self>()
    }

    /// Tree bytes per voxel byte.
    pub fn memory_ratio(&self) -> f64 {
        let data = (self.dims.iter().product::<usize>() * size_of::<T>()).max(1);
        self.memory_bytes() as f64 / data as f64
    }

    pub fn build_time(&self) -> Duration {
        self.build_time
    }

    /// Inner levels (the leaves are cells at this level).
    pub fn depth(&self) -> usize {
        self.depth
    }

    /// Levels that store min/max.
    pub fn stored_levels(&self) -> usize {
        self.stored
    }

    /// The split axis of inner `level` (tests compare it with the treelet layout's).
    #[cfg(test)]
    pub(crate) fn level_axis(&self, level: usize) -> usize {
        self.levels[level].axis
    }

    /// Min/max of node `(i, j, k)` at a stored `level`, or `None` for an unstored level or
    /// a node that does not exist (virtual or out of range).
    pub fn node_range(&self, level: usize, node: [usize; 3]) -> Option<(T, T)> {
        let exists = level < self.stored && (0..3).all(|a| node[a] < self.levels[level].count[a]);
        exists.then(|| {
            let r = self.ranges
                [self.levels[level].range_offset + child_addr(&self.levels[level], node)];
            (r[0], r[1])
        })
    }

    /// The inclusive cell box `[lo, hi]` around every cell that can hold a crossing of one of
    /// `isos`: the union of the live nodes of one stored level, the deepest with at most
    /// [`LIVE_BOX_NODES`] nodes (the whole grid when no level is stored). `None` when no
    /// cell can hold one. Rays clipped to this box lose no hit: every cell outside lies in
    /// a node whose range holds no isovalue, and a cell's trilinear values stay within its
    /// corners' range. Tight bounds are what a BVH over the extracted triangles gets for
    /// free; here they spare the rays that pass beside the surface a walk through the
    /// culled nodes around it.
    pub fn live_cell_box(&self, isos: &IsoSet<T>) -> Option<[[usize; 3]; 2]> {
        union_of_cell_boxes(|f| self.live_cell_boxes(isos, LIVE_BOX_NODES, f))
    }

    /// Calls `f` with the inclusive cell box `[lo, hi]` of every live node (its range holds
    /// one of `isos`) of the deepest stored level with at most `max_nodes` nodes (the
    /// whole grid, once, when no level is stored); every cell that can hold a crossing lies
    /// in one of these boxes ([`KdTree::live_cell_box`]).
    pub fn live_cell_boxes(
        &self,
        isos: &IsoSet<T>,
        max_nodes: usize,
        mut f: impl FnMut([[usize; 3]; 2]),
    ) {
        if self.levels.is_empty() || isos.is_empty() {
            return;
        }
        if self.stored == 0 {
            f([[0; 3], self.cells.map(|c| c - 1)]);
            return;
        }
        let l = (0..self.stored)
            .rev()
            .find(|&l| self.levels[l].count.iter().product::<usize>() <= max_nodes)
            .unwrap_or(0);
        let lv = &self.levels[l];
        let len = lv.count.iter().product::<usize>();
        let level = &self.ranges[lv.range_offset..lv.range_offset + len];
        let e = lv.extent;
        // Rows run along the fastest axis `f` (see `refit_nodes`).
        let [fa, m, sa] = lv.order;
        for (row, nodes) in level.chunks_exact(lv.count[fa]).enumerate() {
            let mut n = [0; 3];
            n[m] = row % lv.count[m];
            n[sa] = row / lv.count[m];
            for (i, r) in nodes.iter().enumerate() {
                if isos.any_in(r[0], r[1]) {
                    n[fa] = i;
                    f([
                        [0, 1, 2].map(|a| n[a] * e[a]),
                        [0, 1, 2].map(|a| ((n[a] + 1) * e[a]).min(self.cells[a]) - 1),
                    ]);
                }
            }
        }
    }

    /// First hit of `ray` (traversal units) within `[t0, t1]`, already clipped to the
    /// volume bounds (see [`TraversalFrame::clip`]).
    #[inline]
    pub fn first_hit<C: CellIntersector, S: Stats>(
        &self,
        frame: &TraversalFrame,
        voxels: &[T],
        ray: &LocalRay,
        t0: f32,
        t1: f32,
        isos: &IsoSet<T>,
        intersector: C,
        stats: &mut S,
    ) -> Option<CellHit> {
        if self.levels.is_empty() || isos.is_empty() {
            return None;
        }
        if self.depth < INLINE_STACK {
            let mut stack = [Entry::default(); INLINE_STACK];
            self.traverse(
                frame,
                voxels,
                ray,
                t0,
                t1,
                isos,
                intersector,
                stats,
                &mut stack,
            )
        } else {
            let mut stack = vec![Entry::default(); self.depth + 1];
            self.traverse(
                frame,
                voxels,
                ray,
                t0,
                t1,
                isos,
                intersector,
                stats,
                &mut stack,
            )
        }
    }

    #[inline(always)]
    fn traverse<C: CellIntersector, S: Stats>(
        &self,
        frame: &TraversalFrame,
        voxels: &[T],
        ray: &LocalRay,
        t0: f32,
        t1: f32,
        isos: &IsoSet<T>,
        intersector: C,
        stats: &mut S,
        stack: &mut [Entry<f32>],
    ) -> Option<CellHit> {
        let mut sp = 0usize;
        let mut best: Option<CellHit> = None;
        let mut node = [0u32; 3];
        let mut level = 0usize;
        let (mut ta, mut tb) = (t0, t1);
        // Ranges are tested one level ahead (a child before it is entered or pushed), so
        // only the root is tested here.
        if self.stored > 0 && !isos.any_in(self.ranges[0][0], self.ranges[0][1]) {
            return None;
        }
        'outer: loop {
            loop {
                if level == self.depth {
                    let cell = node.map(|x| x as usize);
                    if let Some(h) = intersect_cell(
                        frame,
                        voxels,
                        self.dims,
                        ray,
                        cell,
                        t0,
                        t1,
                        isos,
                        intersector,
                        stats,
                    ) && best.is_none_or(|b| h.t < b.t)
                    {
                        best = Some(h);
                    }
                    break;
                }
                stats.node();
                let ch = self.children(level, node, isos);
                level += 1;
                let a = ch.axis;
                let step = ray_step(ray.origin[a], ray.dir[a], ray.inv_dir[a], ch.split, ta, tb);
                match ch.descend(step, level, &mut tb, stack, &mut sp) {
                    Some(next) => node = next,
                    None => break,
                }
            }
            // Pop the next entry that can still hold a nearer hit. Entries pushed for a
            // split-plane ray share their parent's interval, so the stack is not strictly
            // ordered: skip rather than stop.
            loop {
                if sp == 0 {
                    break 'outer;
                }
                sp -= 1;
                let e = stack[sp];
                let limit = best.map_or(f32::INFINITY, |b| b.t);
                if e.t_near <= limit {
                    node = e.node;
                    level = e.level as usize;
                    ta = e.t_near;
                    tb = e.t_far.min(limit);
                    continue 'outer;
                }
            }
        }
        best
    }
}

/// The children of a node, as a traversal step reads them ([`KdTree::children`]).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Children {
    pub axis: usize,
    /// Split position (traversal units).
    pub split: f32,
    pub left: [u32; 3],
    pub right: [u32; 3],
    /// A child is live if it is real and (on a stored level) its range holds an isovalue.
    pub left_live: bool,
    pub right_live: bool,
}

impl Children {
    /// Applies `step` ([`take_step`]) for the in-core traversals: a live far child entered
    /// later is pushed onto `stack` (at `*sp`, for `level`), and the child to descend into is
    /// returned (`None`: pop).
    #[inline(always)]
    pub(crate) fn descend<L: Copy>(
        &self,
        step: Step<L>,
        level: usize,
        t_far: &mut L,
        stack: &mut [Entry<L>],
        sp: &mut usize,
    ) -> Option<[u32; 3]> {
        let (next, push) = take_step(
            step,
            self.left,
            self.right,
            self.left_live,
            self.right_live,
            t_far,
        );
        if let Some((far, t_near, t_far)) = push {
            stack[*sp] = Entry {
                node: far,
                level: level as u32,
                t_near,
                t_far,
            };
            *sp += 1;
        }
        next
    }
}

impl<T: Voxel> KdTree<T> {
    /// The children of `node` at inner `level`: split, addresses and liveness (siblings are
    /// adjacent in the level array, so both ranges come from one cache line); also starts
    /// loading the grandchildren.
    #[inline(always)]
    pub(crate) fn children(&self, level: usize, node: [u32; 3], isos: &IsoSet<T>) -> Children {
        let lv = &self.levels[level];
        // One-hot axis arithmetic keeps the node in registers (indexing a `[u32; 3]`
        // by `a` and reading it back whole stalls store forwarding).
        let u = lv.unit;
        let na = node[0] * u[0] + node[1] * u[1] + node[2] * u[2];
        let split = self.splits[lv.split_offset + na as usize];
        let left = [node[0] << u[0], node[1] << u[1], node[2] << u[2]];
        let right = [left[0] + u[0], left[1] + u[1], left[2] + u[2]];
        let right_real = 2 * na + 1 < lv.child_count;
        self.prefetch_grandchildren(level + 1, left);
        let (left_live, right_live) = if level + 1 < self.stored {
            let i = lv.child_offset + addr(lv.child_stride, left);
            let l = self.ranges[i];
            let live_l = isos.any_in(l[0], l[1]);
            let live_r = right_real && {
                let r = self.ranges[i + 1];
                isos.any_in(r[0], r[1])
            };
            (live_l, live_r)
        } else {
            (true, right_real)
        };
        Children {
            axis: lv.axis,
            split,
            left,
            right,
            left_live,
            right_live,
        }
    }

    /// Starts loading the child pairs of `left` and `right` (nodes at `level`), which the
    /// step after next reads, while this step's pair is still on its way: on the deep
    /// stored levels these pairs miss the cache (the hottest load of the traversal before).
    /// Only addresses are computed (no data dependency), so the loads overlap. Trees smaller
    /// than [`PREFETCH_MIN_TREE_BYTES`] skip it.
    #[inline(always)]
    pub(crate) fn prefetch_grandchildren(&self, level: usize, left: [u32; 3]) {
        if level + 1 < self.prefetch_below {
            let lv = &self.levels[level];
            let u = lv.unit;
            let base = self.ranges.as_ptr().wrapping_add(lv.child_offset);
            let l = [left[0] << u[0], left[1] << u[1], left[2] << u[2]];
            let at_left = base.wrapping_add(addr(lv.child_stride, l));
            prefetch(at_left);
            prefetch(at_left.wrapping_add(lv.grand_delta));
        }
    }
}

#[inline(always)]
fn child_addr(l: &Level, c: [usize; 3]) -> usize {
    addr(l.stride, [c[0] as u32, c[1] as u32, c[2] as u32])
}

/// Address of node `n` in a level array with strides `s`.
#[inline(always)]
fn addr(s: [usize; 3], n: [u32; 3]) -> usize {
    n[0] as usize * s[0] + n[1] as usize * s[1] + n[2] as usize * s[2]
}

#[inline(always)]
fn union<T: Voxel>(a: [T; 2], b: [T; 2]) -> [T; 2] {
    [
        if b[0] < a[0] { b[0] } else { a[0] },
        if b[1] > a[1] { b[1] } else { a[1] },
    ]
}

/// Min/max over the real, non-void cells of node `n` with the given extent.
fn node_range_from_cells<T: Voxel>(
    voxels: &[T],
    dims: [usize; 3],
    cells: [usize; 3],
    extent: [usize; 3],
    n: [usize; 3],
) -> [T; 2] {
    let lo = [0, 1, 2].map(|a| n[a] * extent[a]);
    let hi = [0, 1, 2].map(|a| ((n[a] + 1) * extent[a]).min(cells[a]));
    let mut r = [T::HIGHEST, T::LOWEST];
    if T::TYPE.is_float() {
        // Void (non-finite) corners exclude their cells.
        for k in lo[2]..hi[2] {
            for j in lo[1]..hi[1] {
                for i in lo[0]..hi[0] {
                    if let Some((mn, mx)) = corner_range(&cell_corners(voxels, dims, [i, j, k])) {
                        r = union(r, [mn, mx]);
                    }
                }
            }
        }
    } else {
        // No void integers: the range of the cells is the range of their corner voxels.
        let nx = dims[0];
        let nxy = dims[0] * dims[1];
        for k in lo[2]..=hi[2] {
            for j in lo[1]..=hi[1] {
                let row = &voxels[nx * j + nxy * k + lo[0]..=nx * j + nxy * k + hi[0]];
                for &v in row {
                    if v < r[0] {
                        r[0] = v;
                    }
                    if v > r[1] {
                        r[1] = v;
                    }
                }
            }
        }
    }
    r
}

#[cfg(test)]
mod tests {
    use glam::Vec3;

    use super::*;
    use crate::intersect::methods::Exact;
    use crate::math::Ray;
    use crate::math::rng::Rng;
    use crate::render::NoStats;
    use crate::volume::Grid;

    /// On an anisotropic grid (CT-like: 0.57 mm pixels, 5 mm slices) the levels split the
    /// axis along which nodes are longest in world space, so no node is more than twice as
    /// long along one axis as along another that still has cells to split; index-space
    /// halving would keep them 8.8× longer along the slices. Equal spacings keep the
    /// index-space order x, y, z (the tree of an isotropic grid is unchanged).
    #[test]
    fn levels_split_the_longest_world_axis() {
        let dims = [64, 64, 12];
        let voxels = vec![0i16; dims.iter().product()];
        let mm = [0.570_312_5, 0.570_312_5, 5.0];
        let grid = Grid::uniform(dims, [0.0; 3], mm).unwrap();
        let frame = TraversalFrame::new(&grid);
        let tree = KdTree::build(&voxels, dims, &frame, KdTreeConfig::default());
        // Once the volume's own elongation is split away, every level's nodes stay within
        // 2× between the axes that still have cells to split.
        let mut balanced = false;
        for lv in &tree.levels[..tree.depth] {
            let len = [0, 1, 2].map(|a| lv.extent[a] as f64 * mm[a]);
            let open: Vec<usize> = (0..3).filter(|&a| lv.extent[a] > 1).collect();
            assert!(
                open.contains(&lv.axis),
                "{:?} splits axis {}",
                lv.extent,
                lv.axis
            );
            let longest = open.iter().map(|&a| len[a]).fold(0.0, f64::max);
            let shortest = open.iter().map(|&a| len[a]).fold(f64::INFINITY, f64::min);
            assert_eq!(
                len[lv.axis], longest,
                "{:?}: not the longest axis",
                lv.extent
            );
            if balanced {
                assert!(longest <= 2.0 * shortest, "{:?}: {len:?}", lv.extent);
            }
            balanced |= longest <= 2.0 * shortest;
        }
        assert!(balanced);
        // The z axis (16 padded cells of 5 mm) is split before x and y are halved twice.
        let first_z = tree.levels.iter().position(|l| l.axis == 2).unwrap();
        assert!(first_z <= 2, "first z split at level {first_z}");
        // Isotropic spacing: x, y, z in turn, the index-space order.
        let iso = Grid::uniform([9, 9, 9], [0.0; 3], [0.7; 3]).unwrap();
        let t = KdTree::build(
            &[0u8; 729],
            [9, 9, 9],
            &TraversalFrame::new(&iso),
            KdTreeConfig::default(),
        );
        let axes: Vec<usize> = t.levels[..t.depth].iter().map(|l| l.axis).collect();
        assert_eq!(axes, [0, 1, 2, 0, 1, 2, 0, 1, 2]);
    }

    /// The grandchild prefetch reads nothing into the traversal: the same tree with it on
    /// finds the hits it finds with it off (as a tree this small has it).
    #[test]
    fn the_grandchild_prefetch_leaves_hits_unchanged() {
        let mut rng = Rng::new(5);
        let dims = [33, 20, 27];
        let grid = Grid::uniform(dims, [-4.0, 2.0, 0.5], [1.0, 0.8, 1.3]).unwrap();
        let voxels: Vec<f32> = (0..dims.iter().product::<usize>())
            .map(|_| rng.range_f32(-1.0, 1.0))
            .collect();
        let frame = TraversalFrame::new(&grid);
        let off = KdTree::build(&voxels, dims, &frame, KdTreeConfig::default());
        assert_eq!(off.prefetch_below, 0, "a small tree prefetches nothing");
        let mut on = off.clone();
        on.prefetch_below = on.stored;
        assert!(on.stored > 2);
        let isos = IsoSet::new(&[0.3]);
        let (mut hits, mut packets) = (0, 0);
        for _ in 0..100 {
            let eye = Vec3::new(-60.0, -40.0, -50.0)
                + Vec3::new(rng.unit_f32(), rng.unit_f32(), rng.unit_f32()) * 10.0;
            let aim = Vec3::new(12.0, 10.0, 18.0)
                + Vec3::new(rng.unit_f32(), rng.unit_f32(), rng.unit_f32()) * 8.0;
            let rays: Vec<Ray> = (0..16)
                .map(|_| {
                    let jitter = Vec3::new(rng.unit_f32(), rng.unit_f32(), rng.unit_f32());
                    Ray::new(eye, ((aim - eye).normalize() + jitter * 0.05).normalize())
                })
                .collect();
            let (mut local, mut t0, mut t1) =
                ([frame.to_local(&rays[0]); 16], [0.0; 16], [0.0; 16]);
            frame.to_local_clipped(
                &rays,
                &[0.0; 16],
                &[f32::INFINITY; 16],
                &mut local,
                &mut t0,
                &mut t1,
            );
            if !packet_compatible(&local) {
                continue;
            }
            packets += 1;
            let [a, b] = [&off, &on].map(|tree| {
                let mut out = [None; 16];
                tree.first_hit_packet(
                    &frame,
                    &voxels,
                    &local,
                    &t0,
                    &t1,
                    &isos,
                    Exact,
                    &mut NoStats,
                    &mut out,
                );
                out
            });
            assert_eq!(a, b);
            hits += a.iter().flatten().count();
        }
        assert!(packets > 50 && hits > 400, "{packets} packets, {hits} hits");
    }
}
