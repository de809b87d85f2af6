//! The implicit min/max BVH over tetrahedra with 4D bounds (thesis 004 §8.4.1, §8.5.2).
//!
//! Every node stores the bounds of its subtree in *four* dimensions: `x, y, z` and the
//! scalar value (`lo.w`, `hi.w` are the subtree's min/max value, its *isorange*). One tree
//! serves every isovalue: traversal culls subtrees whose isorange holds none of the active
//! isovalues ("implicit" culling), so the tree is never rebuilt when isovalues change.
//!
//! ## Layout
//! Nodes are 48-byte, 16-byte aligned [`BvhNode`]s in one flat array in depth-first order:
//! the left child of an interior node `i` is `i + 1`, the right child is `link`, and `end`
//! is one past the subtree's last node, so every subtree is a contiguous slice (what the
//! parallel refit uses). Leaves hold `count ≤ leaf_size` tets: the range `link..link+count`
//! of the tet array, which the build reorders into leaf order (no index indirection).
//!
//! ## Builders (§8.4.1, compared in Table 8.1)
//! - [`BvhBuilder::Bih`]: bounding-interval-hierarchy style spatial median
//!   (Wächter & Keller 2006). A node's *candidate box* (initially the centroid bounds) is
//!   halved on its longest axis and the tets are partitioned by centroid; if one side is
//!   empty, the candidate box shrinks to the other half and the split is retried without
//!   making a node. No cost function: fast. Large subtrees are built in parallel (rayon).
//! - [`BvhBuilder::Sah`] (default): binned surface-area heuristic (16 bins per axis on the
//!   centroid bounds), also parallel over subtrees. On generated meshes of like-sized tets
//!   both render alike (as in the thesis); on a TetGen mesh of a real head, whose tets vary
//!   in size, SAH's tree is visited less (0.89× the node visits) and frames take about 0.96×
//!   as long, for about twice the build time (docs/benchmarks.md).
//!
//! Both fall back to a median split by count when no spatial split separates the tets
//! (coincident centroids) and below depth 96, so leaves always hold at most `leaf_size`
//! tets and the depth stays below [`MAX_DEPTH`] (traversal uses fixed-size stacks).
//!
//! ## Refit (§8.5.2)
//! Bounds are computed bottom-up by [`TetBvh::refit`]: subtrees below a cut of about 64
//! nodes are refit in parallel (each a contiguous slice, children after parents, so one
//! reverse sweep suffices), then the few nodes above the cut. When only the scalars change,
//! only the value lanes are updated. The build itself ends with a refit.
//!
//! ## NaN values
//! A tet with a NaN value at any vertex is *void*: its isorange is empty
//! (`lo.w = +inf`, `hi.w = −inf`), so it is never visited for any isovalue. Its geometric
//! bounds still count.

use glam::{Vec3, Vec4};
use rayon::prelude::*;

/// Bound on the tree depth, so traversal stacks can be fixed arrays.
pub const MAX_DEPTH: usize = 128;
/// Most nodes [`TetBvh::live_boxes`] opens (well under 0.1 ms of work per frame).
pub const LIVE_BOX_NODES: usize = 4096;
/// Depth below which spatial splits give way to balanced median splits.
const MEDIAN_DEPTH: u32 = 96;
/// Subtrees with more tets than this are built in parallel.
const PAR_BUILD: usize = 16 * 1024;
const SAH_BINS: usize = 16;

/// Which top-down builder to use.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum BvhBuilder {
    /// BIH-style spatial median (the thesis' choice; builds 2–5× as fast as SAH).
    Bih,
    /// Binned surface-area heuristic (default: fewer nodes visited on irregular meshes).
    #[default]
    Sah,
}

impl std::str::FromStr for BvhBuilder {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s.to_ascii_lowercase().as_str() {
            "bih" => Ok(Self::Bih),
            "sah" => Ok(Self::Sah),
            _ => Err(format!("unknown BVH builder \"{s}\" (expected bih or sah)")),
        }
    }
}

/// Build parameters.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BvhOptions {
    pub builder: BvhBuilder,
    /// Maximum tets per leaf (clamped to `1..=255`; the thesis uses 12). 32 since the
    /// leaf cache keeps a view's isopolygons across frames: a leaf's tets that straddle no
    /// isovalue then cost nothing after the first visit, so larger leaves save node
    /// visits (docs/benchmarks.md: the TetGen head's frame 0.93× that of 12, frames that
    /// change the isovalue 0.95×, 48 and 64 within 2 % of 32).
    pub leaf_size: usize,
}

impl Default for BvhOptions {
    fn default() -> Self {
        Self {
            builder: BvhBuilder::default(),
            leaf_size: 32,
        }
    }
}

/// One node: 4D bounds plus links (48 bytes, 16-byte aligned).
#[repr(C, align(16))]
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BvhNode {
    /// `(x_min, y_min, z_min, value_min)`.
    pub lo: Vec4,
    /// `(x_max, y_max, z_max, value_max)`.
    pub hi: Vec4,
    /// Interior: index of the right child (the left is `self + 1`). Leaf: first tet.
    pub link: u32,
    /// Leaf: number of tets (≥ 1). Interior: 0.
    pub count: u32,
    /// Interior: split axis (0, 1, 2), for front-to-back child order.
    pub axis: u32,
    /// One past the last node of this subtree.
    pub end: u32,
}

impl BvhNode {
    const EMPTY: BvhNode = BvhNode {
        lo: Vec4::splat(f32::INFINITY),
        hi: Vec4::splat(f32::NEG_INFINITY),
        link: 0,
        count: 0,
        axis: 0,
        end: 0,
    };

    #[inline]
    pub fn is_leaf(&self) -> bool {
        self.count > 0
    }
}

/// 4D bounds of one tet; NaN values make the value range empty (module docs).
#[inline]
pub fn tet_bounds(verts: &[Vec4], t: &[u32; 4]) -> (Vec4, Vec4) {
    let a = verts[t[0] as usize];
    let b = verts[t[1] as usize];
    let c = verts[t[2] as usize];
    let d = verts[t[3] as usize];
    let mut lo = a.min(b).min(c.min(d));
    let mut hi = a.max(b).max(c.max(d));
    if a.w.is_nan() || b.w.is_nan() || c.w.is_nan() || d.w.is_nan() {
        lo.w = f32::INFINITY;
        hi.w = f32::NEG_INFINITY;
    }
    (lo, hi)
}

/// Summary numbers for reports and benchmarks.
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Serialize)]
pub struct BvhInfo {
    pub nodes: usize,
    pub leaves: usize,
    pub max_depth: usize,
    pub mean_leaf_tets: f64,
    pub bytes: usize,
}

/// The implicit min/max BVH (module docs).
#[derive(Debug, Clone)]
pub struct TetBvh {
    pub(crate) nodes: Vec<BvhNode>,
    /// Node ranges `[start, end)` of the subtrees refit in parallel (sorted).
    cuts: Vec<[u32; 2]>,
    /// Interior nodes above the cut, in depth-first order.
    top: Vec<u32>,
    options: BvhOptions,
}

struct Builder<'a> {
    cent: &'a [Vec3],
    blo: &'a [Vec3],
    bhi: &'a [Vec3],
    leaf: usize,
    sah: bool,
}

type Split = (usize, u32, [Vec3; 2], [Vec3; 2]);

fn centroid_bounds(cent: &[Vec3], idx: &[u32]) -> [Vec3; 2] {
    idx.iter()
        .fold([Vec3::INFINITY, Vec3::NEG_INFINITY], |[lo, hi], &i| {
            let c = cent[i as usize];
            [lo.min(c), hi.max(c)]
        })
}

fn partition(idx: &mut [u32], pred: impl Fn(u32) -> bool) -> usize {
    let mut k = 0;
    for j in 0..idx.len() {
        if pred(idx[j]) {
            idx.swap(k, j);
            k += 1;
        }
    }
    k
}

fn half_area(lo: Vec3, hi: Vec3) -> f32 {
    let e = (hi - lo).max(Vec3::ZERO);
    e.x * e.y + e.y * e.z + e.z * e.x
}

impl Builder<'_> {
    fn median(&self, idx: &mut [u32]) -> Split {
        let cb = centroid_bounds(self.cent, idx);
        let axis = (cb[1] - cb[0]).max_position();
        let k = idx.len() / 2;
        let cent = self.cent;
        idx.select_nth_unstable_by(k, |&a, &b| {
            cent[a as usize][axis].total_cmp(&cent[b as usize][axis])
        });
        let l = centroid_bounds(cent, &idx[..k]);
        let r = centroid_bounds(cent, &idx[k..]);
        (k, axis as u32, l, r)
    }

    fn bih(&self, idx: &mut [u32], cbox: [Vec3; 2]) -> Option<Split> {
        let mut cb = cbox;
        for _ in 0..64 {
            let ext = cb[1] - cb[0];
            let axis = ext.max_position();
            if ext[axis].is_nan() || ext[axis] <= 0.0 {
                return None;
            }
            let mid = 0.5 * (cb[0][axis] + cb[1][axis]);
            if mid <= cb[0][axis] || mid >= cb[1][axis] {
                return None;
            }
            let cent = self.cent;
            let k = partition(idx, |i| cent[i as usize][axis] < mid);
            if k == 0 {
                cb[0][axis] = mid;
            } else if k == idx.len() {
                cb[1][axis] = mid;
            } else {
                let mut l = cb;
                l[1][axis] = mid;
                let mut r = cb;
                r[0][axis] = mid;
                return Some((k, axis as u32, l, r));
            }
        }
        None
    }

    #[allow(clippy::needless_range_loop)] // `axis` indexes vectors of several types
    fn sah(&self, idx: &mut [u32]) -> Option<Split> {
        let cb = centroid_bounds(self.cent, idx);
        let mut best: Option<(f32, usize, usize)> = None;
        for axis in 0..3 {
            let (lo, ext) = (cb[0][axis], cb[1][axis] - cb[0][axis]);
            if ext.is_nan() || ext <= 0.0 {
                continue;
            }
            let scale = SAH_BINS as f32 / ext;
            let bin_of =
                |i: u32| (((self.cent[i as usize][axis] - lo) * scale) as usize).min(SAH_BINS - 1);
            let mut cnt = [0usize; SAH_BINS];
            let mut blo = [Vec3::INFINITY; SAH_BINS];
            let mut bhi = [Vec3::NEG_INFINITY; SAH_BINS];
            for &i in idx.iter() {
                let b = bin_of(i);
                cnt[b] += 1;
                blo[b] = blo[b].min(self.blo[i as usize]);
                bhi[b] = bhi[b].max(self.bhi[i as usize]);
            }
            // Right-to-left sweep of areas, then the left-to-right cost evaluation.
            let mut right_area = [0f32; SAH_BINS];
            let (mut rl, mut rh, mut rn) = (Vec3::INFINITY, Vec3::NEG_INFINITY, 0usize);
            let mut right_cnt = [0usize; SAH_BINS];
            for b in (1..SAH_BINS).rev() {
                rl = rl.min(blo[b]);
                rh = rh.max(bhi[b]);
                rn += cnt[b];
                right_area[b] = half_area(rl, rh);
                right_cnt[b] = rn;
            }
            let (mut ll, mut lh, mut ln) = (Vec3::INFINITY, Vec3::NEG_INFINITY, 0usize);
            for b in 0..SAH_BINS - 1 {
                ll = ll.min(blo[b]);
                lh = lh.max(bhi[b]);
                ln += cnt[b];
                if ln == 0 || right_cnt[b + 1] == 0 {
                    continue;
                }
                let cost =
                    half_area(ll, lh) * ln as f32 + right_area[b + 1] * right_cnt[b + 1] as f32;
                if best.is_none_or(|(c, _, _)| cost < c) {
                    best = Some((cost, axis, b));
                }
            }
        }
        let (_, axis, b) = best?;
        let (lo, ext) = (cb[0][axis], cb[1][axis] - cb[0][axis]);
        let scale = SAH_BINS as f32 / ext;
        let cent = self.cent;
        let k = partition(idx, |i| {
            (((cent[i as usize][axis] - lo) * scale) as usize).min(SAH_BINS - 1) <= b
        });
        if k == 0 || k == idx.len() {
            return None;
        }
        Some((k, axis as u32, cb, cb))
    }

    fn split(&self, idx: &mut [u32], cbox: [Vec3; 2], depth: u32) -> Split {
        let spatial = if depth >= MEDIAN_DEPTH {
            None
        } else if self.sah {
            self.sah(idx)
        } else {
            self.bih(idx, cbox)
        };
        spatial.unwrap_or_else(|| self.median(idx))
    }

    /// Builds the subtree over `idx` (tets `first..first+len` after reordering) into `out`,
    /// node indices relative to `base` (the index `out[0]` will have in the final array).
    fn build_seq(
        &self,
        idx: &mut [u32],
        first: u32,
        cbox: [Vec3; 2],
        depth: u32,
        out: &mut Vec<BvhNode>,
        base: u32,
    ) {
        let me = out.len();
        if idx.len() <= self.leaf {
            out.push(BvhNode {
                link: first,
                count: idx.len() as u32,
                end: base + me as u32 + 1,
                ..BvhNode::EMPTY
            });
            return;
        }
        out.push(BvhNode::EMPTY);
        let (k, axis, l, r) = self.split(idx, cbox, depth);
        let (li, ri) = idx.split_at_mut(k);
        self.build_seq(li, first, l, depth + 1, out, base);
        let right = base + out.len() as u32;
        self.build_seq(ri, first + k as u32, r, depth + 1, out, base);
        out[me] = BvhNode {
            link: right,
            count: 0,
            axis,
            end: base + out.len() as u32,
            ..BvhNode::EMPTY
        };
    }

    /// Parallel top levels: returns the subtree with indices relative to its root.
    fn build_par(&self, idx: &mut [u32], first: u32, cbox: [Vec3; 2], depth: u32) -> Vec<BvhNode> {
        if idx.len() <= PAR_BUILD {
            let mut out = Vec::with_capacity(2 * idx.len() / self.leaf.max(1) + 1);
            self.build_seq(idx, first, cbox, depth, &mut out, 0);
            return out;
        }
        let (k, axis, l, r) = self.split(idx, cbox, depth);
        let (li, ri) = idx.split_at_mut(k);
        let (left, right) = rayon::join(
            || self.build_par(li, first, l, depth + 1),
            || self.build_par(ri, first + k as u32, r, depth + 1),
        );
        let total = 1 + left.len() + right.len();
        let mut out = Vec::with_capacity(total);
        out.push(BvhNode {
            link: 1 + left.len() as u32,
            count: 0,
            axis,
            end: total as u32,
            ..BvhNode::EMPTY
        });
        let right_shift = out[0].link;
        for (sub, shift) in [(left, 1u32), (right, right_shift)] {
            for mut n in sub {
                if !n.is_leaf() {
                    n.link += shift;
                }
                n.end += shift;
                out.push(n);
            }
        }
        out
    }
}

impl TetBvh {
    /// Builds the tree over `tets` (reordered in place into leaf order) and returns it with
    /// the permutation: `order[new_position] = old_position`.
    ///
    /// `verts` holds each point's position in `xyz` and its value in `w`.
    pub fn build(
        verts: &[Vec4],
        tets: &mut Vec<[u32; 4]>,
        options: BvhOptions,
    ) -> (Self, Vec<u32>) {
        let options = BvhOptions {
            leaf_size: options.leaf_size.clamp(1, 255),
            ..options
        };
        let n = tets.len();
        let (blo, bhi): (Vec<Vec3>, Vec<Vec3>) = tets
            .par_iter()
            .map(|t| {
                let (lo, hi) = tet_bounds(verts, t);
                (lo.truncate(), hi.truncate())
            })
            .unzip();
        let cent: Vec<Vec3> = blo
            .par_iter()
            .zip(&bhi)
            .map(|(a, b)| (*a + *b) * 0.5)
            .collect();
        let mut idx: Vec<u32> = (0..n as u32).collect();
        let builder = Builder {
            cent: &cent,
            blo: &blo,
            bhi: &bhi,
            leaf: options.leaf_size,
            sah: options.builder == BvhBuilder::Sah,
        };
        let nodes = if n == 0 {
            vec![BvhNode {
                link: 0,
                count: 0,
                end: 1,
                ..BvhNode::EMPTY
            }]
        } else {
            let cb = centroid_bounds(&cent, &idx);
            builder.build_par(&mut idx, 0, cb, 0)
        };
        let reordered: Vec<[u32; 4]> = idx.par_iter().map(|&i| tets[i as usize]).collect();
        *tets = reordered;
        let mut bvh = Self {
            nodes,
            cuts: Vec::new(),
            top: Vec::new(),
            options,
        };
        bvh.make_cuts();
        bvh.refit(verts, tets, false);
        (bvh, idx)
    }

    /// Chooses the parallel refit cut: subtrees at depth 6 (or leaves above it).
    fn make_cuts(&mut self) {
        self.cuts.clear();
        self.top.clear();
        if self.nodes.len() < 4096 {
            self.cuts.push([0, self.nodes.len() as u32]);
            return;
        }
        let mut stack = vec![(0u32, 0u32)];
        while let Some((i, depth)) = stack.pop() {
            let n = self.nodes[i as usize];
            if n.is_leaf() || depth == 6 {
                self.cuts.push([i, n.end]);
            } else {
                self.top.push(i);
                stack.push((n.link, depth + 1));
                stack.push((i + 1, depth + 1));
            }
        }
        self.cuts.sort_unstable();
        self.top.sort_unstable();
    }

    pub fn nodes(&self) -> &[BvhNode] {
        &self.nodes
    }

    pub fn options(&self) -> BvhOptions {
        self.options
    }

    /// Root bounds (4D).
    pub fn root(&self) -> &BvhNode {
        &self.nodes[0]
    }

    /// The spatial box `(lo, hi)` of the nodes whose isorange holds one of `isovalues`, or
    /// `None` when none does: the union of [`TetBvh::live_boxes`].
    pub fn live_bounds(&self, isovalues: &[f32]) -> Option<(Vec3, Vec3)> {
        let (mut lo, mut hi) = (Vec3::INFINITY, Vec3::NEG_INFINITY);
        self.live_boxes(isovalues, |l, h| {
            lo = lo.min(l);
            hi = hi.max(h);
        });
        (lo.cmple(hi).all()).then_some((lo, hi))
    }

    /// Calls `f` with the spatial box `(lo, hi)` of each node of a frontier of the nodes
    /// whose isorange holds one of `isovalues`: live subtrees are opened until
    /// [`LIVE_BOX_NODES`] nodes have been looked at, the rest are taken whole. Every tet
    /// that can hold a crossing lies inside one of the boxes (a tet's values stay within
    /// its vertices' range, which its leaf's isorange holds).
    pub fn live_boxes(&self, isovalues: &[f32], mut f: impl FnMut(Vec3, Vec3)) {
        let live = |n: &BvhNode| isovalues.iter().any(|&c| n.lo.w <= c && c <= n.hi.w);
        // Breadth first, so the frontier's boxes are of like size (depth first left the
        // big siblings of one deep branch whole).
        let mut queue = std::collections::VecDeque::with_capacity(LIVE_BOX_NODES);
        if self.nodes.first().is_some_and(live) {
            queue.push_back(0u32);
        }
        let mut looked = 0usize;
        while let Some(i) = queue.pop_front() {
            let n = &self.nodes[i as usize];
            looked += 1;
            if n.is_leaf() || looked + queue.len() >= LIVE_BOX_NODES {
                f(n.lo.truncate(), n.hi.truncate());
                continue;
            }
            for c in [i + 1, n.link] {
                if live(&self.nodes[c as usize]) {
                    queue.push_back(c);
                }
            }
        }
    }

    /// Recomputes the bounds bottom-up (parallel subtrees, then the top). With
    /// `values_only`, only the isoranges are updated (scalar-only time steps).
    pub fn refit(&mut self, verts: &[Vec4], tets: &[[u32; 4]], values_only: bool) {
        let mut slices: Vec<(u32, &mut [BvhNode])> = Vec::with_capacity(self.cuts.len());
        let mut rest: &mut [BvhNode] = &mut self.nodes;
        let mut offset = 0u32;
        for &[s, e] in &self.cuts {
            let (_, tail) = std::mem::take(&mut rest).split_at_mut((s - offset) as usize);
            let (mid, tail) = tail.split_at_mut((e - s) as usize);
            slices.push((s, mid));
            rest = tail;
            offset = e;
        }
        slices
            .into_par_iter()
            .for_each(|(base, sl)| refit_range(sl, base, verts, tets, values_only));
        for &i in self.top.iter().rev() {
            let n = self.nodes[i as usize];
            let l = self.nodes[i as usize + 1];
            let r = self.nodes[n.link as usize];
            set_bounds(
                &mut self.nodes[i as usize],
                l.lo.min(r.lo),
                l.hi.max(r.hi),
                values_only,
            );
        }
    }

    /// Summary numbers (node count, leaves, depth, memory).
    pub fn info(&self) -> BvhInfo {
        let mut info = BvhInfo {
            nodes: self.nodes.len(),
            bytes: self.nodes.len() * size_of::<BvhNode>(),
            ..BvhInfo::default()
        };
        let mut tets = 0usize;
        let mut stack = vec![(0u32, 1usize)];
        while let Some((i, d)) = stack.pop() {
            let n = &self.nodes[i as usize];
            info.max_depth = info.max_depth.max(d);
            if n.is_leaf() {
                info.leaves += 1;
                tets += n.count as usize;
            } else if n.end > i + 1 {
                stack.push((i + 1, d + 1));
                stack.push((n.link, d + 1));
            }
        }
        info.mean_leaf_tets = tets as f64 / info.leaves.max(1) as f64;
        info
    }

    /// Checks the invariants: links form a tree in depth-first order, every tet is in
    /// exactly one leaf, leaves hold at most `leaf_size` tets, child bounds lie inside the
    /// parent's (4D), leaf bounds contain their tets' points and (non-NaN) value ranges.
    pub fn validate(&self, verts: &[Vec4], tets: &[[u32; 4]]) -> Result<(), String> {
        let nodes = &self.nodes;
        let len = nodes.len() as u32;
        if nodes.is_empty() {
            return Err("no nodes".into());
        }
        if tets.is_empty() {
            return if nodes.len() == 1 {
                Ok(())
            } else {
                Err("nodes without tets".into())
            };
        }
        let mut seen = vec![false; tets.len()];
        let mut visited = 0usize;
        let mut stack = vec![(0u32, 0usize)];
        while let Some((i, depth)) = stack.pop() {
            visited += 1;
            if depth >= MAX_DEPTH {
                return Err(format!("node {i}: depth {depth} exceeds {MAX_DEPTH}"));
            }
            let n = &nodes[i as usize];
            if n.end <= i || n.end > len {
                return Err(format!("node {i}: bad subtree end {}", n.end));
            }
            if n.is_leaf() {
                if n.end != i + 1 {
                    return Err(format!("leaf {i}: end {} != {}", n.end, i + 1));
                }
                if n.count as usize > self.options.leaf_size {
                    return Err(format!(
                        "leaf {i}: {} tets > leaf size {}",
                        n.count, self.options.leaf_size
                    ));
                }
                let range = n.link as usize..n.link as usize + n.count as usize;
                if range.end > tets.len() {
                    return Err(format!("leaf {i}: tets {range:?} out of range"));
                }
                for t in range {
                    if std::mem::replace(&mut seen[t], true) {
                        return Err(format!("tet {t} is in two leaves"));
                    }
                    let (lo, hi) = tet_bounds(verts, &tets[t]);
                    if !(lo.truncate().cmpge(n.lo.truncate()).all()
                        && hi.truncate().cmple(n.hi.truncate()).all())
                    {
                        return Err(format!("leaf {i}: tet {t} sticks out of the leaf box"));
                    }
                    if lo.w <= hi.w && !(lo.w >= n.lo.w && hi.w <= n.hi.w) {
                        return Err(format!(
                            "leaf {i}: tet {t} value range [{}, {}] not in [{}, {}]",
                            lo.w, hi.w, n.lo.w, n.hi.w
                        ));
                    }
                }
            } else {
                let (l, r) = (i + 1, n.link);
                if r <= l
                    || r >= len
                    || nodes[l as usize].end != r
                    || nodes[r as usize].end != n.end
                    || n.axis > 2
                {
                    return Err(format!(
                        "node {i}: bad links (left {l}, right {r}, end {})",
                        n.end
                    ));
                }
                for c in [l, r] {
                    let cn = &nodes[c as usize];
                    // Empty value ranges (void subtrees) are inside anything.
                    let geo = cn.lo.truncate().cmpge(n.lo.truncate()).all()
                        && cn.hi.truncate().cmple(n.hi.truncate()).all();
                    let val = cn.lo.w > cn.hi.w || (cn.lo.w >= n.lo.w && cn.hi.w <= n.hi.w);
                    if !(geo && val) {
                        return Err(format!("node {c}: bounds not inside parent {i}"));
                    }
                }
                stack.push((l, depth + 1));
                stack.push((r, depth + 1));
            }
        }
        if visited != nodes.len() {
            return Err(format!("{} of {} nodes reachable", visited, nodes.len()));
        }
        if let Some(t) = seen.iter().position(|s| !s) {
            return Err(format!("tet {t} is in no leaf"));
        }
        Ok(())
    }
}

#[inline]
fn set_bounds(n: &mut BvhNode, lo: Vec4, hi: Vec4, values_only: bool) {
    if values_only {
        n.lo.w = lo.w;
        n.hi.w = hi.w;
    } else {
        n.lo = lo;
        n.hi = hi;
    }
}

/// Reverse sweep over one contiguous subtree (`base` is the index of `nodes[0]`).
fn refit_range(
    nodes: &mut [BvhNode],
    base: u32,
    verts: &[Vec4],
    tets: &[[u32; 4]],
    values_only: bool,
) {
    for i in (0..nodes.len()).rev() {
        let n = nodes[i];
        let (lo, hi) = if n.is_leaf() {
            let first = n.link as usize;
            let mut lo = Vec4::INFINITY;
            let mut hi = Vec4::NEG_INFINITY;
            for t in &tets[first..first + n.count as usize] {
                let (a, b) = tet_bounds(verts, t);
                lo = lo.min(a);
                hi = hi.max(b);
            }
            (lo, hi)
        } else if n.end == base + i as u32 + 1 {
            // The single empty root of a mesh without tets.
            (Vec4::INFINITY, Vec4::NEG_INFINITY)
        } else {
            let l = nodes[i + 1];
            let r = nodes[(n.link - base) as usize];
            (l.lo.min(r.lo), l.hi.max(r.hi))
        };
        set_bounds(&mut nodes[i], lo, hi, values_only);
    }
}
