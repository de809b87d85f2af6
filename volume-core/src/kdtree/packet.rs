//! Packet traversal: 8 coherent rays walk the kd-tree together (thesis seed 004 §7.2.1,
//! after Wald's coherent packets). Node min/max are fetched and culled once per packet, and
//! the split distances of all rays are computed in one `f32x8` (the `wide` crate: AVX when
//! enabled at compile time, SSE pairs otherwise, no `unsafe`).
//!
//! A packet descends to one child when every active ray does, else to both; each ray keeps
//! its own `[t_near, t_far]` lane, computed with exactly the single-ray formulas, and leaves
//! run the same scalar cell test per active ray (the cell's corners, range and box loaded
//! once per packet), so packet results equal single-ray results (tested). Packets need every ray to share the sign of each direction component and have
//! no zero component; [`crate::grid_scene::GridScene`] traces other groups one by one.

use wide::f32x8;

use super::{INLINE_STACK, KdTree, addr};
use crate::intersect::{
    CellHit, CellIntersector, IsoSet, LocalRay, PreparedCell, TraversalFrame,
    intersect_prepared_cell,
};
use crate::render::Stats;
use crate::voxel::Voxel;

/// Rays per packet.
pub const PACKET_WIDTH: usize = 8;

#[derive(Clone, Copy)]
struct PacketEntry {
    node: [u32; 3],
    level: u32,
    t_near: f32x8,
    t_far: f32x8,
}

impl Default for PacketEntry {
    fn default() -> Self {
        Self {
            node: [0; 3],
            level: 0,
            t_near: f32x8::splat(0.0),
            t_far: f32x8::splat(0.0),
        }
    }
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
        let n = rays.len().min(PACKET_WIDTH);
        for o in &mut out[..n] {
            *o = None;
        }
        if self.levels.is_empty() || isos.is_empty() || n == 0 {
            return;
        }
        debug_assert!(packet_compatible(&rays[..n]));
        let lanes = |f: &dyn Fn(usize) -> f32, pad: f32| {
            f32x8::new(std::array::from_fn(|i| if i < n { f(i) } else { pad }))
        };
        let org = [0, 1, 2].map(|a| lanes(&|i| rays[i].origin[a], 0.0));
        let inv = [0, 1, 2].map(|a| lanes(&|i| rays[i].inv_dir[a], 1.0));
        let dir_pos = [0, 1, 2].map(|a| rays[0].dir[a] > 0.0);
        // Padding lanes are empty: t_near = +inf > t_far = −inf.
        let mut tn = lanes(&|i| t0[i], f32::INFINITY);
        let mut tf = lanes(&|i| t1[i], f32::NEG_INFINITY);
        let mut best = [f32::INFINITY; PACKET_WIDTH];
        let mut best_v = f32x8::splat(f32::INFINITY);
        let mut stack = [PacketEntry::default(); INLINE_STACK];
        if self.depth >= INLINE_STACK {
            // Absurdly deep trees (> 2^64 cells): trace one by one.
            for i in 0..n {
                out[i] = self.first_hit(
                    frame,
                    voxels,
                    &rays[i],
                    t0[i],
                    t1[i],
                    isos,
                    intersector,
                    stats,
                );
            }
            return;
        }
        let mut sp = 0usize;
        let mut node = [0u32; 3];
        let mut level = 0usize;
        // Children are culled before they are entered or pushed; only the root here.
        if self.stored > 0 && !isos.any_in(self.ranges[0][0], self.ranges[0][1]) {
            return;
        }
        'outer: loop {
            loop {
                let active = tn.simd_le(tf).to_bitmask();
                if active == 0 {
                    break;
                }
                if level == self.depth {
                    let cell = node.map(|x| x as usize);
                    for _ in 0..active.count_ones() {
                        stats.leaf();
                    }
                    let Some(pc) = PreparedCell::load(frame, voxels, self.dims, cell, isos) else {
                        break;
                    };
                    let mut bits = active;
                    while bits != 0 {
                        let i = bits.trailing_zeros() as usize;
                        bits &= bits - 1;
                        if let Some(h) = intersect_prepared_cell(
                            &pc,
                            &rays[i],
                            t0[i],
                            t1[i],
                            isos,
                            intersector,
                            stats,
                        ) && h.t < best[i]
                        {
                            best[i] = h.t;
                            out[i] = Some(h);
                        }
                    }
                    best_v = f32x8::new(best);
                    break;
                }
                let lv = &self.levels[level];
                stats.node();
                let a = lv.axis;
                let u = lv.unit;
                let na = node[0] * u[0] + node[1] * u[1] + node[2] * u[2];
                let split = self.splits[lv.split_offset + na as usize];
                let left = [node[0] << u[0], node[1] << u[1], node[2] << u[2]];
                let right = [left[0] + u[0], left[1] + u[1], left[2] + u[2]];
                let right_real = 2 * na + 1 < lv.child_count;
                level += 1;
                self.prefetch_grandchildren(level, left, right);
                let (left_live, right_live) = if level < self.stored {
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
                let ts = (f32x8::splat(split) - org[a]) * inv[a];
                let (near, far, near_real, far_real) = if dir_pos[a] {
                    (left, right, left_live, right_live)
                } else {
                    (right, left, right_live, left_live)
                };
                let beyond = ts.simd_gt(tf).to_bitmask();
                let before = ts.simd_lt(tn).to_bitmask();
                if beyond & active == active {
                    if !near_real {
                        break;
                    }
                    node = near;
                } else if before & active == active {
                    if !far_real {
                        break;
                    }
                    node = far;
                } else {
                    if far_real {
                        stack[sp] = PacketEntry {
                            node: far,
                            level: level as u32,
                            t_near: tn.max(ts),
                            t_far: tf,
                        };
                        sp += 1;
                    }
                    if !near_real {
                        break;
                    }
                    node = near;
                    tf = tf.min(ts);
                }
            }
            loop {
                if sp == 0 {
                    break 'outer;
                }
                sp -= 1;
                let e = stack[sp];
                let e_tf = e.t_far.min(best_v);
                if e.t_near.simd_le(e_tf).to_bitmask() != 0 {
                    node = e.node;
                    level = e.level as usize;
                    tn = e.t_near;
                    tf = e_tf;
                    continue 'outer;
                }
            }
        }
    }
}
