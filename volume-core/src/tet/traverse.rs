//! Single-ray and large-packet traversal of the implicit BVH (thesis 004 §8.4.2, §8.2.3).
//!
//! ## Packets
//! A packet is any slice of up to [`MAX_PACKET`] rays (the renderer passes 16×16 tiles in
//! Morton order). Rays need not be coherent: every culling step is conservative, so the
//! result equals single-ray traversal for any rays. Per node, in this order:
//! 1. **Implicit culling**: skip the node if its isorange holds no active isovalue. Below a
//!    node that passed the geometric tests, chains of nodes with a single active child are
//!    descended *without* geometric tests; only at bifurcation nodes (both children active)
//!    are the children tested (Fig. 8.2).
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
//!    against rays `first..`.
//!
//! Refinement: the packet is also split into sub-frusta of 16 consecutive rays (4×4 blocks
//! of a Morton-ordered tile). The first-active search (4) and the isopolygon culling (5)
//! skip whole sub-frusta that miss, so a node or polygon much smaller than the packet costs
//! a few group tests instead of a scan over 256 rays.
//!
//! Packets of at most 4 rays run the *standard* SIMD-style packet traversal instead (every
//! ray tested at every node, descend if any hits): the 2×2 baseline of Table 8.4.
//!
//! ## Statistics
//! `box_test` counts individual ray–box tests (an interval frustum test counts as one),
//! `intersection` ray–isopolygon tests, `extraction` isopolygon extractions, `node` and
//! `leaf` visits.

use glam::Vec3;

use super::bvh::{BvhNode, MAX_DEPTH};
use super::mt::{self, RaySpace};
use super::scene::TetScene;
use crate::math::{Ray, float::gamma_f32};
use crate::render::Stats;

/// Largest packet traced at once (16×16).
pub const MAX_PACKET: usize = 256;
/// Rays per sub-frustum (a 4×4 block of a Morton-ordered tile).
const GROUP: usize = 16;
const MAX_GROUPS: usize = MAX_PACKET / GROUP;

/// A hit before shading: ray parameter, isovalue index and tet (leaf order).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RawHit {
    pub t: f32,
    pub surface: u32,
    pub tet: u32,
}

#[inline]
fn iso_active(lo: f32, hi: f32, iso: &[f32]) -> bool {
    iso.iter().any(|&c| lo <= c && c <= hi)
}

/// Conservative slab test of `[t0, t1]` against the node's spatial box (as [`crate::math::Aabb`]).
#[inline]
fn slab(n: &BvhNode, ray: &Ray, t0: f32, t1: f32) -> bool {
    let a = (n.lo.truncate() - ray.origin) * ray.inv_dir;
    let b = (n.hi.truncate() - ray.origin) * ray.inv_dir;
    let near = a.min(b);
    let far = a.max(b) * (1.0 + 2.0 * gamma_f32(3));
    near.max_element().max(t0) <= far.min_element().min(t1)
}

/// Interval bounds of a packet for the conservative frustum test.
#[derive(Clone, Copy)]
struct Frustum {
    omin: Vec3,
    omax: Vec3,
    imin: Vec3,
    imax: Vec3,
    axis: [bool; 3],
    t0: f32,
    t1: f32,
}

impl Frustum {
    const NONE: Frustum = Frustum {
        omin: Vec3::ZERO,
        omax: Vec3::ZERO,
        imin: Vec3::ZERO,
        imax: Vec3::ZERO,
        axis: [false; 3],
        t0: f32::NEG_INFINITY,
        t1: f32::INFINITY,
    };

    fn new(rays: &[Ray], t_min: &[f32], t_max: &[f32]) -> Self {
        let mut f = Frustum {
            omin: Vec3::INFINITY,
            omax: Vec3::NEG_INFINITY,
            imin: Vec3::INFINITY,
            imax: Vec3::NEG_INFINITY,
            axis: [true; 3],
            t0: f32::INFINITY,
            t1: f32::NEG_INFINITY,
        };
        for (i, r) in rays.iter().enumerate() {
            f.omin = f.omin.min(r.origin);
            f.omax = f.omax.max(r.origin);
            f.imin = f.imin.min(r.inv_dir);
            f.imax = f.imax.max(r.inv_dir);
            f.t0 = f.t0.min(t_min[i]);
            f.t1 = f.t1.max(t_max[i]);
            if !r.origin.is_finite() {
                f.axis = [false; 3];
            }
            for a in 0..3 {
                if !r.inv_dir[a].is_finite() || r.dir[a] == 0.0 {
                    f.axis[a] = false;
                }
            }
        }
        for a in 0..3 {
            // Mixed signs: the reciprocal interval would span infinity.
            if f.axis[a] && f.imin[a] < 0.0 && f.imax[a] > 0.0 {
                f.axis[a] = false;
            }
        }
        // NaN ranges: never cull.
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
            for a in 0..3 {
                f.axis[a] &= g.axis[a] && !(f.imin[a] < 0.0 && f.imax[a] > 0.0);
            }
        }
        f
    }

    /// True when no ray of the packet can meet the box `[lo, hi]` within its range.
    #[inline]
    fn misses(&self, lo: Vec3, hi: Vec3) -> bool {
        let mut enter = self.t0;
        let mut exit = self.t1;
        for a in 0..3 {
            if !self.axis[a] {
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

impl TetScene {
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
        for ti in n.link..n.link + n.count {
            let ids = &self.tets[ti as usize];
            let v = ids.map(|i| self.verts[i as usize]);
            let lo = v[0].w.min(v[1].w).min(v[2].w.min(v[3].w));
            let hi = v[0].w.max(v[1].w).max(v[2].w.max(v[3].w));
            if v.iter().any(|p| p.w.is_nan()) {
                continue;
            }
            for (s, &c) in iso.iter().enumerate() {
                if !(lo <= c && c <= hi) {
                    continue;
                }
                stats.extraction();
                let Some(poly) = mt::extract(&v, ids, c) else {
                    continue;
                };
                stats.intersection();
                if let Some(t) = mt::intersect(rs, &poly)
                    && t >= t_min
                    && t <= *best
                    && hit.is_none_or(|h| t < h.t)
                {
                    *best = t;
                    *hit = Some(RawHit {
                        t,
                        surface: s as u32,
                        tet: ti,
                    });
                }
            }
        }
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
        let len = rays.len();
        assert!(len <= MAX_PACKET && t_min.len() >= len && t_max.len() >= len && out.len() >= len);
        out[..len].fill(None);
        if len == 0 || iso.is_empty() || self.tets.is_empty() {
            return;
        }
        let mut rs = [RaySpace::INVALID; MAX_PACKET];
        let mut best = [0f32; MAX_PACKET];
        for i in 0..len {
            stats.ray();
            rs[i] = RaySpace::new(rays[i].origin, rays[i].dir);
            best[i] = t_max[i];
        }
        // Sub-frusta of 16 consecutive rays: the first-active search and the isopolygon
        // culling skip whole groups that miss (a refinement of steps 3–5). The packet
        // frustum is their union.
        let mut groups = [Frustum::NONE; MAX_GROUPS];
        for (g, start) in (0..len).step_by(GROUP).enumerate() {
            let end = (start + GROUP).min(len);
            groups[g] = Frustum::new(&rays[start..end], &t_min[start..end], &t_max[start..end]);
        }
        let fr = Frustum::union(&groups[..len.div_ceil(GROUP)]);
        let groups = &groups[..len.div_ceil(GROUP)];
        let standard = len <= 4;
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
                    if standard {
                        // 2×2 baseline: every ray against every node.
                        stats.box_test((len - first) as u64);
                        let hits = (first..len).filter(|&i| slab(n, &rays[i], t_min[i], best[i]));
                        match hits.min() {
                            Some(i) => first = i,
                            None => break 'visit,
                        }
                    } else {
                        stats.box_test(1);
                        if !slab(n, &rays[first], t_min[first], best[first]) {
                            stats.box_test(1);
                            if fr.misses(n.lo.truncate(), n.hi.truncate()) {
                                break 'visit;
                            }
                            let mut found = None;
                            let mut i = first + 1;
                            'search: while i < len {
                                let g = i / GROUP;
                                let g_end = ((g + 1) * GROUP).min(len);
                                if len > GROUP {
                                    stats.box_test(1);
                                    if groups[g].misses(n.lo.truncate(), n.hi.truncate()) {
                                        i = g_end;
                                        continue;
                                    }
                                }
                                while i < g_end {
                                    stats.box_test(1);
                                    if slab(n, &rays[i], t_min[i], best[i]) {
                                        found = Some(i);
                                        break 'search;
                                    }
                                    i += 1;
                                }
                            }
                            match found {
                                Some(i) => first = i,
                                None => break 'visit,
                            }
                        }
                    }
                }
                if n.is_leaf() {
                    stats.leaf();
                    self.leaf_packet(
                        n,
                        &rs[..len],
                        &t_min[..len],
                        &mut best[..len],
                        first,
                        &fr,
                        groups,
                        out,
                        iso,
                        stats,
                    );
                    break 'visit;
                }
                // Implicit descent: geometric tests only at bifurcation nodes.
                let (l, r) = (node + 1, n.link);
                let la = {
                    let c = &nodes[l as usize];
                    iso_active(c.lo.w, c.hi.w, iso)
                };
                let ra = {
                    let c = &nodes[r as usize];
                    iso_active(c.lo.w, c.hi.w, iso)
                };
                match (la, ra) {
                    (false, false) => break 'visit,
                    (true, false) | (false, true) => {
                        node = if la { l } else { r };
                        needs_test = standard;
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

    #[inline]
    fn leaf_packet<S: Stats>(
        &self,
        n: &BvhNode,
        rs: &[RaySpace],
        t_min: &[f32],
        best: &mut [f32],
        first: usize,
        fr: &Frustum,
        groups: &[Frustum],
        out: &mut [Option<RawHit>],
        iso: &[f32],
        stats: &mut S,
    ) {
        for ti in n.link..n.link + n.count {
            let ids = &self.tets[ti as usize];
            let v = ids.map(|i| self.verts[i as usize]);
            if v.iter().any(|p| p.w.is_nan()) {
                continue;
            }
            let lo = v[0].w.min(v[1].w).min(v[2].w.min(v[3].w));
            let hi = v[0].w.max(v[1].w).max(v[2].w.max(v[3].w));
            for (s, &c) in iso.iter().enumerate() {
                if !(lo <= c && c <= hi) {
                    continue;
                }
                stats.extraction();
                let Some(poly) = mt::extract(&v, ids, c) else {
                    continue;
                };
                let (plo, phi) = poly.bounds();
                if rs.len() > 4 && fr.misses(plo, phi) {
                    continue;
                }
                let mut i = first;
                while i < rs.len() {
                    let g = i / GROUP;
                    let g_end = ((g + 1) * GROUP).min(rs.len());
                    if rs.len() > GROUP && groups[g].misses(plo, phi) {
                        i = g_end;
                        continue;
                    }
                    for i in i..g_end {
                        stats.intersection();
                        if let Some(t) = mt::intersect(&rs[i], &poly)
                            && t >= t_min[i]
                            && t <= best[i]
                            && out[i].is_none_or(|h| t < h.t)
                        {
                            best[i] = t;
                            out[i] = Some(RawHit {
                                t,
                                surface: s as u32,
                                tet: ti,
                            });
                        }
                    }
                    i = g_end;
                }
            }
        }
    }
}
