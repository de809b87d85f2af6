//! Building the treelet hierarchy (thesis seed 004 §7.8.1, Fig. 7.7).
//!
//! 1. The finite value range of the volume fixes the [`Quantizer`].
//! 2. The LOD pyramid: repeated 2× decimation after a separable binomial `[1 2 1]/4` filter
//!    per halved axis (a discrete 3D Gaussian, clamped at the borders; void (NaN) taps are
//!    left out and the weights renormalised). Each halving maps LOD sample `d` to the
//!    previous level's sample `min(2d, n − 1)`, so LOD samples sit on finest samples
//!    ([`TreeletLayout::lod_sample`]). An axis stops halving once it reaches the level's
//!    factor (the kd-tree's node extents may differ per axis).
//! 3. The merged min/max tree, bottom-up over treelet levels: a node of treelet level `L`
//!    gets the union of the ranges of the LOD-`L'` cells below it for every `L' ≥ L` (the
//!    levels whose rendering traverses it), which is the thesis' "union over levels" without
//!    the levels that never pass through the node. The bottom of a treelet joins its own
//!    LOD cells with the roots of the finer treelets below, so one level's worth of root
//!    ranges is all that is kept between levels.
//!
//! Memory is bounded independently of the input size: the finest data is read in place
//! (a memory map pages it in and out) in two sequential passes. Pass 1 walks the input
//! z-plane by z-plane, computing the value range and streaming the planes through a
//! cascade of decimation stages (`HalveStage`: three planes each), so only the coarse LOD
//! levels themselves are kept (about `input / 2^height`, 1/512 at the default height 9).
//! Pass 2 encodes the finest treelets in index order, which is z-slab order, in parallel
//! batches handed to the sink in order (a batch is written while the next is encoded), then
//! the coarse levels from memory. `progress` counts input voxels read over both passes
//! (`2 × voxels` in all).
//!
//! Cost per input voxel (target: ≥ 100 MB/s on 2 cores, docs/benchmarks.md): integer volumes halve
//! separably in exact arithmetic (`halve_plane_exact`); a treelet's ranges come from
//! separable cell ranges reduced bottom-up over its heap, and node codes of ≤ 16-bit types
//! from a table (`NodeCodes`). Each fast path has a brute-force twin in the tests and
//! gives the same bytes.

use std::time::{Duration, Instant};

use rayon::prelude::*;

use super::OocError;
use super::layout::{TreeletLayout, linear_index};
use super::quantize::Quantizer;
#[cfg(test)]
use super::treelet::TreeletRecord;
use super::treelet::{OocMeta, TreeletSink, put_header, start_voxels, voxels_to_le};
use crate::intersect::{cell_corners, corner_range};
use crate::stats::ValueStats;
use crate::volume::Grid;
use crate::voxel::Voxel;

/// Treelets encoded per parallel batch.
const BATCH: u64 = 2048;

/// A treelet's root range and its record bytes.
type Encoded<T> = ([T; 2], Vec<u8>);

/// What a build produced.
#[derive(Debug, Clone)]
pub struct BuildReport {
    pub meta: OocMeta,
    pub treelets: u64,
    /// Encoded treelet bytes (before any page padding).
    pub bytes: u64,
    pub build_time: Duration,
}

/// Builds the treelets of `voxels` (x fastest, on `grid`) with treelets of
/// `treelet_height` node levels and hands them to `sink`. `progress(done, total)` is called
/// after each input plane (pass 1) and each batch (pass 2) with input voxels read so far
/// over both passes (`total = 2 × voxels`).
pub fn build_treelets<T: Voxel, S: TreeletSink + Send + ?Sized>(
    grid: &Grid,
    voxels: &[T],
    layout: TreeletLayout,
    sink: &mut S,
    progress: &mut dyn FnMut(u64, u64),
) -> Result<BuildReport, OocError> {
    let start = Instant::now();
    let dims = grid.dims().map(|d| d as u64);
    if layout.dims() != dims {
        return Err(OocError::BadDims {
            dims,
            reason: format!("layout was made for dims {:?}", layout.dims()),
        });
    }
    if voxels.len() as u64 != layout.voxel_count() {
        return Err(OocError::LengthMismatch {
            dims,
            expected: layout.voxel_count(),
            actual: voxels.len() as u64,
        });
    }
    // Pass 1, one z-plane of the input at a time: the finite value range (for the
    // quantizer) and the coarse LOD levels through the streamed decimation cascade.
    let plane_len = (dims[0] * dims[1]) as usize;
    let fine_total = layout.voxel_count();
    let work_total = 2 * fine_total;
    let mut pyramid = Pyramid::<T>::new(&layout);
    let mut range: Option<(f64, f64)> = None;
    for (z, plane) in voxels.chunks_exact(plane_len).enumerate() {
        let r = ValueStats::compute(plane).finite_range;
        range = match (range, r) {
            (Some(a), Some(b)) => Some((a.0.min(b.0), a.1.max(b.1))),
            (x, None) | (None, x) => x,
        };
        pyramid.feed(z as u64, plane);
        progress((z as u64 + 1) * plane_len as u64, work_total);
    }
    let mut lods = pyramid.finish();
    let (lo, hi) = range.unwrap_or((0.0, 0.0));
    let quantizer = Quantizer::for_type(T::TYPE, lo, hi);
    let meta = OocMeta {
        grid: grid.clone(),
        voxel_type: T::TYPE,
        layout,
        quantizer,
        value_map: crate::volume::ValueMap::IDENTITY,
    };
    sink.begin(&meta)?;
    let layout = &meta.layout;
    let n = layout.level_count();
    let total = layout.treelet_count();

    let mut bytes = 0u64;
    let codes = NodeCodes::new::<T>(&meta.quantizer);
    let mut child_roots: Option<Vec<[T; 2]>> = None;
    for l in (0..n).rev() {
        let lv = *layout.level(l);
        let lod: &[T] = if l == n - 1 { voxels } else { &lods[l] };
        let encoder = TreeletEncoder::new(&meta, l, lod, child_roots.as_deref(), &codes);
        let count = lv.treelet_count();
        let mut roots = Vec::with_capacity(count as usize);
        let mut first = 0u64;
        // The previous batch, handed to the sink while the next one is encoded (the sink
        // copies, checksums and writes pages: serial work that would idle the other cores).
        let mut pending: Option<(u64, Vec<Encoded<T>>)> = None;
        while first < count || pending.is_some() {
            let last = (first + BATCH).min(count);
            let (next, written) = rayon::join(
                || {
                    (first < count).then(|| {
                        (first..last)
                            .into_par_iter()
                            .map_init(Scratch::new, |s, index| encoder.encode(index, s))
                            .collect::<Vec<_>>()
                    })
                },
                || -> Result<Option<u64>, OocError> {
                    let Some((at, batch)) = pending.take() else {
                        return Ok(None);
                    };
                    let done = at + batch.len() as u64;
                    for (i, (root_range, rec)) in batch.into_iter().enumerate() {
                        sink.put(l, at + i as u64, &rec)?;
                        bytes += rec.len() as u64;
                        roots.push(root_range);
                    }
                    Ok(Some(done))
                },
            );
            // Pass 2 reads the finest level once more; coarse levels are tiny.
            if let Some(done) = written?
                && l == n - 1
            {
                progress(fine_total + fine_total * done / count, work_total);
            }
            pending = next.map(|b| (first, b));
            first = last;
        }
        drop(encoder);
        child_roots = Some(roots);
        if l + 1 < n {
            lods[l] = Vec::new();
        }
    }
    progress(work_total, work_total);
    Ok(BuildReport {
        meta: meta.clone(),
        treelets: total,
        bytes,
        build_time: start.elapsed(),
    })
}

#[inline(always)]
fn union<T: Voxel>(a: [T; 2], b: [T; 2]) -> [T; 2] {
    [
        if b[0] < a[0] { b[0] } else { a[0] },
        if b[1] > a[1] { b[1] } else { a[1] },
    ]
}

/// Corner ranges of the `n` cells from cell `lo` of `lod` (x fastest), separably: pairs
/// along x, then y, then z (3 × ~n³ comparisons instead of 8 corner loads and 14
/// comparisons per cell). Integer voxels only: a float NaN corner empties a cell's range
/// ([`corner_range`]), which pairwise min/max does not reproduce. `x_pairs` and `y_pairs`
/// are scratch; the ranges replace the contents of `out`.
fn cell_ranges_into<T: Voxel>(
    lod: &[T],
    lod_dims: [usize; 3],
    lo: [usize; 3],
    n: [usize; 3],
    x_pairs: &mut Vec<[T; 2]>,
    y_pairs: &mut Vec<[T; 2]>,
    out: &mut Vec<[T; 2]>,
) {
    let [nx, ny, nz] = n;
    let a = x_pairs;
    a.clear();
    for z in 0..=nz {
        for y in 0..=ny {
            let at = lo[0] + lod_dims[0] * (lo[1] + y + lod_dims[1] * (lo[2] + z));
            let row = &lod[at..=at + nx];
            a.extend(row.windows(2).map(|w| {
                if w[1] < w[0] {
                    [w[1], w[0]]
                } else {
                    [w[0], w[1]]
                }
            }));
        }
    }
    let b = y_pairs;
    b.clear();
    for z in 0..=nz {
        for y in 0..ny {
            let r0 = &a[nx * (y + (ny + 1) * z)..][..nx];
            let r1 = &a[nx * (y + 1 + (ny + 1) * z)..][..nx];
            b.extend(r0.iter().zip(r1).map(|(&p, &q)| union(p, q)));
        }
    }
    out.clear();
    for z in 0..nz {
        let p0 = &b[nx * ny * z..][..nx * ny];
        let p1 = &b[nx * ny * (z + 1)..][..nx * ny];
        out.extend(p0.iter().zip(p1).map(|(&p, &q)| union(p, q)));
    }
}

/// [`cell_ranges_into`] with fresh buffers (tests).
#[cfg(test)]
fn cell_ranges<T: Voxel>(
    lod: &[T],
    lod_dims: [usize; 3],
    lo: [usize; 3],
    n: [usize; 3],
) -> Vec<[T; 2]> {
    let mut out = Vec::new();
    cell_ranges_into(
        lod,
        lod_dims,
        lo,
        n,
        &mut Vec::new(),
        &mut Vec::new(),
        &mut out,
    );
    out
}

/// Node codes through a table for voxel types of at most 16 bits: `encode(m, M)` is
/// `[floor-code(m), ceil-code(M)]` for a non-empty range, so one table lookup per bound
/// replaces two f64 divisions, `floor`/`ceil` and clamps per node (thesis §7.8.1
/// conservative quantization, unchanged). Wider types use [`Quantizer::encode`].
enum NodeCodes {
    /// Indexed by the voxel's bit pattern (see [`table_index`]).
    Table {
        lo: Vec<u8>,
        hi: Vec<u8>,
    },
    Direct,
}

/// The table index of an at most 16-bit voxel: its bit pattern as an unsigned number.
#[inline(always)]
fn table_index<T: Voxel>(v: T) -> usize {
    let b = bytemuck::bytes_of(&v);
    if size_of::<T>() == 1 {
        usize::from(b[0])
    } else {
        usize::from(u16::from_ne_bytes([b[0], b[1]]))
    }
}

impl NodeCodes {
    fn new<T: Voxel>(q: &Quantizer) -> Self {
        if T::TYPE.is_float() || size_of::<T>() > 2 || q.bits > 8 {
            return Self::Direct;
        }
        let (lo, hi) = (0..1usize << (8 * size_of::<T>()))
            .map(|bits| {
                let bytes = if size_of::<T>() == 1 {
                    [bits as u8, 0]
                } else {
                    (bits as u16).to_ne_bytes()
                };
                let v: T = bytemuck::pod_read_unaligned(&bytes[..size_of::<T>()]);
                debug_assert_eq!(table_index(v), bits);
                let c = q.encode(v.to_f64(), v.to_f64());
                (c[0] as u8, c[1] as u8)
            })
            .unzip();
        Self::Table { lo, hi }
    }

    /// Appends the packed codes of `ranges` (heap order), as [`Quantizer::put`] lays them out.
    fn put_all<T: Voxel>(&self, q: &Quantizer, ranges: &[[T; 2]], out: &mut Vec<u8>) {
        match self {
            Self::Table { lo, hi } => {
                let empty = [q.max_code() as u8, 0];
                if q.bits == 4 {
                    out.extend(ranges.iter().map(|r| {
                        let c = if r[0] <= r[1] {
                            [lo[table_index(r[0])], hi[table_index(r[1])]]
                        } else {
                            empty
                        };
                        c[0] | (c[1] << 4)
                    }));
                } else {
                    for r in ranges {
                        let c = if r[0] <= r[1] {
                            [lo[table_index(r[0])], hi[table_index(r[1])]]
                        } else {
                            empty
                        };
                        out.extend_from_slice(&c);
                    }
                }
            }
            Self::Direct => {
                let at = out.len();
                out.resize(at + ranges.len() * q.node_bytes(), 0);
                for (h, r) in ranges.iter().enumerate() {
                    q.put(&mut out[at..], h, q.encode(r[0].to_f64(), r[1].to_f64()));
                }
            }
        }
    }
}

/// Per-worker buffers of [`TreeletEncoder::encode`] (no allocation per treelet but the
/// record itself).
struct Scratch<T> {
    x_pairs: Vec<[T; 2]>,
    y_pairs: Vec<[T; 2]>,
    cells: Vec<[T; 2]>,
    /// The treelet's heap with its bottom (cell) level: `2^(height + 1) − 1` ranges.
    heap: Vec<[T; 2]>,
}

impl<T> Scratch<T> {
    fn new() -> Self {
        Self {
            x_pairs: Vec::new(),
            y_pairs: Vec::new(),
            cells: Vec::new(),
            heap: Vec::new(),
        }
    }
}

/// Encodes the treelets of one level. A treelet's merged ranges are its bottom nodes (its
/// LOD cells, joined with the roots of the finer treelets below) reduced bottom-up over the
/// heap (`h ← 2h + 1 ∪ 2h + 2`): no recursion, and the cell of each bottom node is a
/// precomputed offset. Virtual nodes (beyond the volume's cells) start empty and stay empty,
/// which is what the per-node recursion (`encode_treelet_reference` in the tests) stores.
struct TreeletEncoder<'a, T: Voxel> {
    meta: &'a OocMeta,
    l: usize,
    lod: &'a [T],
    lod_dims: [usize; 3],
    child_roots: Option<&'a [[T; 2]]>,
    /// Cell offset from the treelet's first cell of each bottom node, heap order.
    leaf_offsets: Vec<[usize; 3]>,
    /// The same offsets as indices into the cell ranges of a treelet that the border does
    /// not clip (the common case: a plain gather).
    leaf_full_index: Vec<u32>,
    codes: &'a NodeCodes,
}

impl<'a, T: Voxel> TreeletEncoder<'a, T> {
    fn new(
        meta: &'a OocMeta,
        l: usize,
        lod: &'a [T],
        child_roots: Option<&'a [[T; 2]]>,
        codes: &'a NodeCodes,
    ) -> Self {
        let layout = &meta.layout;
        let lv = layout.level(l);
        // Children of heap slot `h` are `2h + 1, 2h + 2`: expanding a level's nodes in
        // order (left, right) lists the next level in heap order.
        let mut leaf_offsets = vec![[0usize; 3]];
        for level in lv.first..lv.end {
            let a = layout.shape(level).axis;
            leaf_offsets = leaf_offsets
                .iter()
                .flat_map(|&n| {
                    let mut left = n;
                    left[a] *= 2;
                    let mut right = left;
                    right[a] += 1;
                    [left, right]
                })
                .collect();
        }
        let n = lv.root_cells.map(|c| c as usize);
        let leaf_full_index = leaf_offsets
            .iter()
            .map(|o| (o[0] + n[0] * (o[1] + n[1] * o[2])) as u32)
            .collect();
        Self {
            meta,
            l,
            lod,
            lod_dims: lv.lod_dims.map(|d| d as usize),
            child_roots,
            leaf_offsets,
            leaf_full_index,
            codes,
        }
    }

    /// Treelet `index`: its root range and its encoding (the bytes of
    /// [`super::TreeletRecord::encode`]).
    fn encode(&self, index: u64, s: &mut Scratch<T>) -> ([T; 2], Vec<u8>) {
        let meta = self.meta;
        let layout = &meta.layout;
        let lv = layout.level(self.l);
        let root = layout.root_of(self.l, index);
        let cell_lo = [0, 1, 2].map(|a| root[a] * lv.root_cells[a]);
        let cell_n = [0, 1, 2]
            .map(|a| ((cell_lo[a] + lv.root_cells[a]).min(lv.lod_cells[a]) - cell_lo[a]) as usize);
        let lo = cell_lo.map(|c| c as usize);
        let float = T::TYPE.is_float();
        if !float {
            cell_ranges_into(
                self.lod,
                self.lod_dims,
                lo,
                cell_n,
                &mut s.x_pairs,
                &mut s.y_pairs,
                &mut s.cells,
            );
        }
        let slots = lv.node_slots();
        s.heap.clear();
        s.heap.resize(slots, [T::HIGHEST, T::LOWEST]);
        let full = (0..3).all(|a| cell_n[a] as u64 == lv.root_cells[a]);
        if full && !float && self.child_roots.is_none() {
            let cells = &s.cells;
            s.heap
                .extend(self.leaf_full_index.iter().map(|&i| cells[i as usize]));
        } else {
            self.bottom_nodes(lo, cell_n, s);
        }
        for h in (0..slots).rev() {
            s.heap[h] = union(s.heap[2 * h + 1], s.heap[2 * h + 2]);
        }
        let root_range = s.heap[0];
        let (origin, bdims) = layout.voxel_block(self.l, root);
        let record_bytes = meta.record_bytes(self.l, bdims[0] * bdims[1] * bdims[2]) as usize;
        let mut out = Vec::with_capacity(record_bytes);
        put_header(&mut out, self.l, lv.height(), index, origin, bdims);
        self.codes
            .put_all(&meta.quantizer, &s.heap[..slots], &mut out);
        let at = start_voxels(&mut out);
        let row_len = bdims[0] as usize;
        for k in 0..bdims[2] {
            for j in 0..bdims[1] {
                let row =
                    linear_index(lv.lod_dims, [origin[0], origin[1] + j, origin[2] + k]) as usize;
                out.extend_from_slice(bytemuck::cast_slice::<T, u8>(&self.lod[row..row + row_len]));
            }
        }
        voxels_to_le::<T>(&mut out[at..]);
        debug_assert_eq!(out.len(), record_bytes);
        (root_range, out)
    }

    /// Appends the bottom nodes of a treelet clipped by the border (virtual nodes stay
    /// empty), of a float one (per-cell corner ranges: a void corner empties its cell), or
    /// of one above finer treelets (joined with their roots).
    fn bottom_nodes(&self, lo: [usize; 3], cell_n: [usize; 3], s: &mut Scratch<T>) {
        let lv = self.meta.layout.level(self.l);
        let float = T::TYPE.is_float();
        let empty = [T::HIGHEST, T::LOWEST];
        for off in &self.leaf_offsets {
            if (0..3).any(|a| off[a] >= cell_n[a]) {
                s.heap.push(empty);
                continue;
            }
            let cell = [0, 1, 2].map(|a| lo[a] + off[a]);
            let mut r = if float {
                corner_range(&cell_corners(self.lod, self.lod_dims, cell))
                    .map_or(empty, |(a, b)| [a, b])
            } else {
                s.cells[off[0] + cell_n[0] * (off[1] + cell_n[1] * off[2])]
            };
            if let Some(c) = self.child_roots {
                r = union(
                    r,
                    c[linear_index(lv.lod_cells, cell.map(|x| x as u64)) as usize],
                );
            }
            s.heap.push(r);
        }
    }
}

/// The per-node recursion the encoder replaced, with the per-cell corner path: the tests'
/// brute-force twin of [`TreeletEncoder::encode`].
#[cfg(test)]
fn encode_treelet_reference<T: Voxel>(
    meta: &OocMeta,
    l: usize,
    index: u64,
    lod: &[T],
    child_roots: Option<&[[T; 2]]>,
) -> ([T; 2], Vec<u8>) {
    struct RangeCtx<'a, T: Voxel> {
        layout: &'a TreeletLayout,
        end: usize,
        lod: &'a [T],
        lod_dims: [usize; 3],
        lod_cells: [u64; 3],
        child_roots: Option<&'a [[T; 2]]>,
    }
    impl<T: Voxel> RangeCtx<'_, T> {
        fn subtree(&self, level: usize, node: [u64; 3], h: usize, out: &mut [[T; 2]]) -> [T; 2] {
            if level == self.end {
                let cell = node.map(|x| x as usize);
                let mut r = corner_range(&cell_corners(self.lod, self.lod_dims, cell))
                    .map_or([T::HIGHEST, T::LOWEST], |(a, b)| [a, b]);
                if let Some(c) = self.child_roots {
                    r = union(r, c[linear_index(self.lod_cells, node) as usize]);
                }
                return r;
            }
            let a = self.layout.shape(level).axis;
            let child_count = self.layout.shape(level + 1).count[a];
            let mut left = node;
            left[a] *= 2;
            let mut r = self.subtree(level + 1, left, 2 * h + 1, out);
            let mut right = left;
            right[a] += 1;
            if right[a] < child_count {
                r = union(r, self.subtree(level + 1, right, 2 * h + 2, out));
            }
            out[h] = r;
            r
        }
    }
    let layout = &meta.layout;
    let lv = *layout.level(l);
    let root = layout.root_of(l, index);
    let mut ranges = vec![[T::HIGHEST, T::LOWEST]; lv.node_slots()];
    let ctx = RangeCtx {
        layout,
        end: lv.end,
        lod,
        lod_dims: lv.lod_dims.map(|d| d as usize),
        lod_cells: lv.lod_cells,
        child_roots,
    };
    let root_range = ctx.subtree(lv.first, root, 0, &mut ranges);
    let q = &meta.quantizer;
    let mut nodes = vec![0u8; lv.node_slots() * q.node_bytes()].into_boxed_slice();
    for (h, r) in ranges.iter().enumerate() {
        q.put(&mut nodes, h, q.encode(r[0].to_f64(), r[1].to_f64()));
    }
    let (origin, bdims) = layout.voxel_block(l, root);
    let mut voxels = Vec::with_capacity((bdims[0] * bdims[1] * bdims[2]) as usize);
    for k in 0..bdims[2] {
        for j in 0..bdims[1] {
            let row = linear_index(lv.lod_dims, [origin[0], origin[1] + j, origin[2] + k]) as usize;
            voxels.extend_from_slice(&lod[row..row + bdims[0] as usize]);
        }
    }
    let rec = TreeletRecord {
        level: l,
        index,
        height: lv.height(),
        voxel_origin: origin,
        voxel_dims: bdims.map(|d| d as usize),
        nodes,
        voxels,
    };
    (root_range, rec.encode())
}

/// The coarse LOD levels built in one streamed pass: a cascade of `HalveStage`s fed the
/// input's z-planes; a level's planes are kept when its stage emits them. Memory: three
/// planes per stage plus the coarse levels themselves (level `L` has `1 / 2^(height ·
/// (levels − 1 − L))` of the input's cells, so about `input / 2^height` in all).
struct Pyramid<T: Voxel> {
    stages: Vec<HalveStage<T>>,
    /// `(stage, level)`: the output of `stage` is LOD level `level`.
    keep: Vec<(usize, usize)>,
    levels: Vec<Vec<T>>,
}

impl<T: Voxel> Pyramid<T> {
    fn new(layout: &TreeletLayout) -> Self {
        let n = layout.level_count();
        let mut stages = Vec::new();
        let mut keep = Vec::new();
        let mut levels = vec![Vec::new(); n - 1];
        let mut dims = layout.dims();
        let mut factor = [1u64; 3];
        for l in (0..n - 1).rev() {
            let target = layout.level(l).lod_factor;
            while factor != target {
                let halve = [0, 1, 2].map(|a| factor[a] < target[a]);
                let stage = HalveStage::new(dims, halve);
                dims = stage.ddims;
                stages.push(stage);
                for a in 0..3 {
                    if halve[a] {
                        factor[a] *= 2;
                    }
                }
            }
            debug_assert_eq!(dims, layout.level(l).lod_dims);
            keep.push((stages.len() - 1, l));
            levels[l] = Vec::with_capacity((dims[0] * dims[1] * dims[2]) as usize);
        }
        Self {
            stages,
            keep,
            levels,
        }
    }

    /// Feeds finest plane `z` (in order).
    fn feed(&mut self, z: u64, plane: &[T]) {
        if self.stages.is_empty() {
            return;
        }
        let mut input = vec![(z, plane.to_vec())];
        for s in 0..self.stages.len() {
            let mut out = Vec::new();
            for (z, p) in input.drain(..) {
                self.stages[s].push(z, p, &mut out);
            }
            let first = self.stages[s].next_out - out.len() as u64;
            for &(_, l) in self.keep.iter().filter(|(ks, _)| *ks == s) {
                for p in &out {
                    self.levels[l].extend_from_slice(p);
                }
            }
            input = out
                .into_iter()
                .enumerate()
                .map(|(i, p)| (first + i as u64, p))
                .collect();
            if input.is_empty() {
                return;
            }
        }
    }

    /// The coarse LOD levels (index = treelet level; the finest is not here).
    fn finish(self) -> Vec<Vec<T>> {
        debug_assert!(self.stages.iter().all(|s| s.next_out == s.ddims[2]));
        self.levels
    }
}

/// One 2× decimation step along the axes in `halve` (see the module docs), on a whole
/// volume; the build streams the same arithmetic plane by plane (`HalveStage`). The
/// tests' independent pyramid.
#[cfg(test)]
pub(crate) fn halve_lod<T: Voxel>(
    src: &[T],
    sdims: [u64; 3],
    halve: [bool; 3],
) -> (Vec<T>, [u64; 3]) {
    let mut stage = HalveStage::new(sdims, halve);
    let plane = (sdims[0] * sdims[1]) as usize;
    let ddims = stage.ddims;
    let mut out = Vec::with_capacity((ddims[0] * ddims[1] * ddims[2]) as usize);
    let mut planes = Vec::new();
    for (z, p) in src.chunks_exact(plane).enumerate() {
        stage.push(z as u64, p.to_vec(), &mut planes);
        for o in planes.drain(..) {
            out.extend_from_slice(&o);
        }
    }
    (out, ddims)
}

/// One 2× decimation step fed z-planes in order: it keeps at most three input planes and
/// emits each output plane as soon as its last tap has arrived, so a pyramid of stages
/// builds the coarse LOD levels in one pass over the input with bounded memory.
#[derive(Debug)]
pub(crate) struct HalveStage<T: Voxel> {
    sdims: [u64; 3],
    ddims: [u64; 3],
    halve: [bool; 3],
    /// Received planes still needed, z ascending.
    ring: std::collections::VecDeque<(u64, Vec<T>)>,
    received: u64,
    next_out: u64,
}

impl<T: Voxel> HalveStage<T> {
    pub(crate) fn new(sdims: [u64; 3], halve: [bool; 3]) -> Self {
        let ddims = [0, 1, 2].map(|a| {
            if halve[a] {
                (sdims[a] - 1).div_ceil(2) + 1
            } else {
                sdims[a]
            }
        });
        Self {
            sdims,
            ddims,
            halve,
            ring: std::collections::VecDeque::with_capacity(4),
            received: 0,
            next_out: 0,
        }
    }

    /// Input plane of output plane `k` (the filter centre).
    fn center(&self, k: u64) -> u64 {
        if self.halve[2] {
            (2 * k).min(self.sdims[2] - 1)
        } else {
            k
        }
    }

    /// Input planes `[below, centre, above]` (clamped) that output plane `k` reads.
    fn taps(&self, k: u64) -> [u64; 3] {
        let c = self.center(k);
        if self.halve[2] {
            [c.saturating_sub(1), c, (c + 1).min(self.sdims[2] - 1)]
        } else {
            [c; 3]
        }
    }

    /// Adds input plane `z` (the next in order) and appends the output planes it completes.
    pub(crate) fn push(&mut self, z: u64, plane: Vec<T>, out: &mut Vec<Vec<T>>) {
        debug_assert_eq!(z, self.received, "planes arrive in order");
        debug_assert_eq!(plane.len() as u64, self.sdims[0] * self.sdims[1]);
        self.ring.push_back((z, plane));
        self.received = z + 1;
        while self.next_out < self.ddims[2] && self.taps(self.next_out)[2] < self.received {
            let zs = self.taps(self.next_out);
            let find = |z: u64| {
                self.ring
                    .iter()
                    .find(|(rz, _)| *rz == z)
                    .map(|(_, p)| p.as_slice())
                    .expect("tap plane kept in the ring")
            };
            let planes = [find(zs[0]), find(zs[1]), find(zs[2])];
            let mut o = vec![T::default(); (self.ddims[0] * self.ddims[1]) as usize];
            halve_plane(planes, self.sdims, self.ddims, self.halve, &mut o);
            out.push(o);
            self.next_out += 1;
            let keep_from = if self.next_out < self.ddims[2] {
                self.taps(self.next_out)[0]
            } else {
                u64::MAX
            };
            while self.ring.front().is_some_and(|(rz, _)| *rz < keep_from) {
                self.ring.pop_front();
            }
        }
    }
}

/// One output plane of a decimation step from its (clamped) input planes `[z − 1, z, z + 1]`
/// (only the middle one is read when z is not halved). Integer voxels take the separable
/// exact path (`halve_plane_exact`), floats the per-tap path with void taps left out.
fn halve_plane<T: Voxel>(
    planes: [&[T]; 3],
    sdims: [u64; 3],
    ddims: [u64; 3],
    halve: [bool; 3],
    out: &mut [T],
) {
    if T::TYPE.is_float() {
        halve_plane_taps(planes, sdims, ddims, halve, out);
    } else if size_of::<T>() <= 2 {
        halve_plane_exact::<T, f32>(planes, sdims, ddims, halve, out);
    } else {
        halve_plane_exact::<T, f64>(planes, sdims, ddims, halve, out);
    }
}

/// Accumulator of `halve_plane_exact`.
trait ExactSum:
    Copy + Send + Sync + std::ops::Add<Output = Self> + std::ops::Mul<Output = Self>
{
    const ZERO: Self;
    fn of<T: Voxel>(v: T) -> Self;
    fn weight(w: u8) -> Self;
    fn exact(self) -> f64;
}

impl ExactSum for f32 {
    const ZERO: Self = 0.0;
    #[inline(always)]
    fn of<T: Voxel>(v: T) -> Self {
        v.to_f32()
    }
    #[inline(always)]
    fn weight(w: u8) -> Self {
        f32::from(w)
    }
    #[inline(always)]
    fn exact(self) -> f64 {
        f64::from(self)
    }
}

impl ExactSum for f64 {
    const ZERO: Self = 0.0;
    #[inline(always)]
    fn of<T: Voxel>(v: T) -> Self {
        v.to_f64()
    }
    #[inline(always)]
    fn weight(w: u8) -> Self {
        f64::from(w)
    }
    #[inline(always)]
    fn exact(self) -> f64 {
        self
    }
}

/// [`halve_plane_taps`] for integer voxels, separably: each output row sums its (up to 9)
/// weighted input rows once into a full-width row, then filters that along x. Same result
/// bit for bit: integer weights `[1 2 1]` per halved axis and one division by `4^halved`
/// at the end are exact in `A` (f32 for ≤ 16-bit voxels: |sum| ≤ 64 · 2¹⁶ < 2²⁴; f64 for
/// 32-bit: < 2³⁹ < 2⁵³), as is the per-tap f64 sum (dyadic weights, and the weights sum to
/// exactly 1), so both round the same exact value.
fn halve_plane_exact<T: Voxel, A: ExactSum>(
    planes: [&[T]; 3],
    sdims: [u64; 3],
    ddims: [u64; 3],
    halve: [bool; 3],
    out: &mut [T],
) {
    let sd = sdims.map(|d| d as usize);
    let dd = ddims.map(|d| d as usize);
    let sx = sd[0];
    let plane_len = sd[0] * sd[1];
    let planes = planes.map(|p| &p[..plane_len]);
    let halved = halve.iter().filter(|&&h| h).count() as i32;
    let scale = 0.25f64.powi(halved);
    let z_taps: &[(usize, u8)] = if halve[2] {
        &[(0, 1), (1, 2), (2, 1)]
    } else {
        &[(1, 1)]
    };
    out.par_chunks_mut(dd[0]).enumerate().for_each_init(
        || vec![A::ZERO; sx],
        |acc, (j, row)| {
            let mut y_taps = [(0usize, 0u8); 3];
            let y_taps: &[(usize, u8)] = if halve[1] {
                let cy = (2 * j).min(sd[1] - 1);
                y_taps = [
                    (cy.saturating_sub(1), 1),
                    (cy, 2),
                    ((cy + 1).min(sd[1] - 1), 1),
                ];
                &y_taps
            } else {
                y_taps[0] = (j, 1);
                &y_taps[..1]
            };
            acc.fill(A::ZERO);
            for &(zp, wz) in z_taps {
                for &(y, wy) in y_taps {
                    let w = A::weight(wz * wy);
                    let src = &planes[zp][sx * y..][..sx];
                    for (a, &v) in acc.iter_mut().zip(src) {
                        *a = *a + w * A::of(v);
                    }
                }
            }
            if halve[0] {
                let two = A::weight(2);
                for (i, dst) in row.iter_mut().enumerate() {
                    let cx = (2 * i).min(sx - 1);
                    let s = acc[cx.saturating_sub(1)] + two * acc[cx] + acc[(cx + 1).min(sx - 1)];
                    *dst = T::from_f64(s.exact() * scale);
                }
            } else {
                for (dst, &s) in row.iter_mut().zip(acc.iter()) {
                    *dst = T::from_f64(s.exact() * scale);
                }
            }
        },
    );
}

/// One output plane, tap by tap in f64 (the general path: void taps are left out and the
/// weights renormalised).
fn halve_plane_taps<T: Voxel>(
    planes: [&[T]; 3],
    sdims: [u64; 3],
    ddims: [u64; 3],
    halve: [bool; 3],
    out: &mut [T],
) {
    let sd = sdims.map(|d| d as usize);
    let dd = ddims.map(|d| d as usize);
    // Taps per axis: (offset, weight); z taps index `planes`.
    let taps = |a: usize| -> &'static [(isize, f64)] {
        if halve[a] {
            &[(-1, 0.25), (0, 0.5), (1, 0.25)]
        } else {
            &[(0, 1.0)]
        }
    };
    let (tx, ty, tz) = (taps(0), taps(1), taps(2));
    let center = |a: usize, d: usize| if halve[a] { (2 * d).min(sd[a] - 1) } else { d };
    let clampi =
        |a: usize, c: usize, o: isize| (c as isize + o).clamp(0, sd[a] as isize - 1) as usize;
    out.par_chunks_mut(dd[0]).enumerate().for_each(|(j, row)| {
        let cy = center(1, j);
        for (i, dst) in row.iter_mut().enumerate() {
            let cx = center(0, i);
            let (mut sum, mut wsum) = (0.0f64, 0.0f64);
            for &(oz, wz) in tz {
                let src = planes[(oz + 1) as usize];
                for &(oy, wy) in ty {
                    let y = clampi(1, cy, oy);
                    for &(ox, wx) in tx {
                        let x = clampi(0, cx, ox);
                        let v = src[x + sd[0] * y].to_f64();
                        if v.is_finite() {
                            let w = wx * wy * wz;
                            sum += w * v;
                            wsum += w;
                        }
                    }
                }
            }
            *dst = if wsum > 0.0 {
                T::from_f64(sum / wsum)
            } else {
                T::from_f64(f64::NAN)
            };
        }
    });
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ooc::treelet::{MemoryStorage, TreeletStorage};

    fn field(dims: [usize; 3], seed: u64) -> Vec<f32> {
        let mut v = Vec::with_capacity(dims.iter().product());
        let mut rng = crate::math::rng::Rng::new(seed);
        for k in 0..dims[2] {
            for j in 0..dims[1] {
                for i in 0..dims[0] {
                    let noise = rng.unit_f32();
                    v.push((i as f32 * 0.3).sin() * 10.0 + j as f32 * 0.5 - k as f32 + noise);
                }
            }
        }
        v
    }

    #[test]
    fn halving_keeps_linear_fields_and_sample_positions() {
        let dims = [9u64, 6, 5];
        let f = |i: f64, j: f64, k: f64| 2.0 * i - 3.0 * j + 0.5 * k + 1.0;
        let mut src = Vec::new();
        for k in 0..5 {
            for j in 0..6 {
                for i in 0..9 {
                    src.push(f(f64::from(i), f64::from(j), f64::from(k)) as f32);
                }
            }
        }
        let (out, d) = halve_lod(&src, dims, [true, true, false]);
        assert_eq!(d, [5, 4, 5]);
        // Interior samples (taps not clamped): the binomial filter reproduces linear
        // functions, at finest sample (2i, 2j, k).
        for k in 0..5usize {
            for j in 1..3usize {
                for i in 1..4usize {
                    let got = f64::from(out[i + 5 * (j + 4 * k)]);
                    let want = f((2 * i) as f64, (2 * j) as f64, k as f64);
                    assert!((got - want).abs() < 1e-4, "{i} {j} {k}: {got} {want}");
                }
            }
        }
        // Void taps are left out, an all-void neighbourhood stays void.
        let mut holes = vec![1.0f32; 27];
        holes[13] = f32::NAN;
        let (o, _) = halve_lod(&holes, [3, 3, 3], [true; 3]);
        assert!(o.iter().all(|&x| x == 1.0));
        let (o, _) = halve_lod(&[f32::NAN; 8], [2, 2, 2], [true; 3]);
        assert!(o.iter().all(|x| x.is_nan()));
    }

    /// Every stored node code equals the encoding of the brute-force union over the LOD
    /// levels rendered through the node (independent truth: geometric containment).
    #[test]
    fn merged_ranges_equal_brute_force_union_over_levels() {
        for (dims, h) in [([13usize, 9, 7], 3u32), ([20, 5, 11], 4), ([6, 6, 6], 2)] {
            let voxels = field(dims, 7);
            let grid = Grid::uniform(dims, [0.0; 3], [1.0; 3]).unwrap();
            let layout = TreeletLayout::new(dims.map(|d| d as u64), h).unwrap();
            let mut store = MemoryStorage::new();
            let report =
                build_treelets(&grid, &voxels, layout.clone(), &mut store, &mut |_, _| {}).unwrap();
            let meta = store.meta().clone();
            assert_eq!(report.treelets, layout.treelet_count());
            let n = layout.level_count();
            assert!(n >= 2, "{dims:?}");
            // LOD volumes by repeated halving, independent of the build's schedule: halve
            // axis by axis.
            let mut lods: Vec<(Vec<f32>, [u64; 3])> = Vec::new();
            for l in 0..n {
                let target = layout.level(l).lod_factor;
                let mut cur = (voxels.clone(), dims.map(|d| d as u64));
                let mut fac = [1u64; 3];
                while fac != target {
                    let halve = [0, 1, 2].map(|a| fac[a] < target[a]);
                    cur = halve_lod(&cur.0, cur.1, halve);
                    for a in 0..3 {
                        if halve[a] {
                            fac[a] *= 2;
                        }
                    }
                }
                assert_eq!(cur.1, layout.level(l).lod_dims);
                lods.push(cur);
            }
            let q = meta.quantizer;
            for l in 0..n {
                let lv = *layout.level(l);
                for index in 0..lv.treelet_count() {
                    let rec = TreeletRecord::<f32>::decode(
                        &meta,
                        l,
                        index,
                        &store.fetch(l, index).unwrap(),
                    )
                    .unwrap();
                    let root = layout.root_of(l, index);
                    // Walk the heap: (tree level, node, slot).
                    let mut todo = vec![(lv.first, root, 0usize)];
                    while let Some((level, node, h)) = todo.pop() {
                        if level == lv.end {
                            continue;
                        }
                        let ext = layout.shape(level).extent;
                        let (mut mn, mut mx) = (f32::INFINITY, f32::NEG_INFINITY);
                        for (lp, (lod, ld)) in lods.iter().enumerate().skip(l) {
                            let e = layout.level(lp).lod_factor;
                            let lc = layout.level(lp).lod_cells;
                            for k in 0..lc[2] {
                                for j in 0..lc[1] {
                                    for i in 0..lc[0] {
                                        let c = [i, j, k];
                                        if (0..3).all(|a| c[a] * e[a] / ext[a] == node[a]) {
                                            let ld = ld.map(|x| x as usize);
                                            let cs = cell_corners(lod, ld, c.map(|x| x as usize));
                                            let (a, b) = corner_range(&cs).unwrap();
                                            mn = mn.min(a);
                                            mx = mx.max(b);
                                        }
                                    }
                                }
                            }
                        }
                        let want = q.encode(f64::from(mn), f64::from(mx));
                        assert_eq!(q.get(&rec.nodes, h), want, "{dims:?} l{l} {node:?}@{level}");
                        let a = layout.shape(level).axis;
                        let cc = layout.shape(level + 1).count[a];
                        let mut left = node;
                        left[a] *= 2;
                        todo.push((level + 1, left, 2 * h + 1));
                        let mut right = left;
                        right[a] += 1;
                        if right[a] < cc {
                            todo.push((level + 1, right, 2 * h + 2));
                        } else if level + 1 < lv.end {
                            // Virtual node: empty range.
                            let e = q.get(&rec.nodes, 2 * h + 2);
                            assert!(e[0] > e[1]);
                        }
                    }
                    // Voxel block = LOD samples.
                    let (o, d) = layout.voxel_block(l, root);
                    let (lod, ld) = &lods[l];
                    for k in 0..d[2] {
                        for j in 0..d[1] {
                            for i in 0..d[0] {
                                let g = linear_index(*ld, [o[0] + i, o[1] + j, o[2] + k]);
                                let b = linear_index(d, [i, j, k]);
                                // Halving all axes at once or axis by axis rounds the
                                // f32 intermediates differently.
                                let (x, y) = (rec.voxels[b as usize], lod[g as usize]);
                                assert!((x - y).abs() <= 1e-5 * y.abs().max(1.0), "{x} {y}");
                            }
                        }
                    }
                }
            }
        }
    }

    /// The build's encoder (separable cell ranges for integers, bottom-up heap, table
    /// codes for ≤ 16-bit types) equals the per-node recursion over per-cell corner ranges
    /// with `Quantizer::encode` (its brute-force twin) record for record, merged coarse
    /// levels, clipped border treelets and void (NaN) cells included.
    #[test]
    fn encoder_equals_the_recursive_corner_path_record_for_record() {
        fn check<T: Voxel>(voxels: &[T], dims: [usize; 3], h: u32) {
            let grid = Grid::uniform(dims, [0.0; 3], [1.0; 3]).unwrap();
            let layout = TreeletLayout::new(dims.map(|d| d as u64), h).unwrap();
            let mut store = MemoryStorage::new();
            build_treelets(&grid, voxels, layout.clone(), &mut store, &mut |_, _| {}).unwrap();
            let meta = store.meta().clone();
            let mut pyramid = Pyramid::<T>::new(&layout);
            for (z, p) in voxels.chunks_exact(dims[0] * dims[1]).enumerate() {
                pyramid.feed(z as u64, p);
            }
            let lods = pyramid.finish();
            let n = layout.level_count();
            assert!(n >= 2);
            let codes = NodeCodes::new::<T>(&meta.quantizer);
            assert_eq!(
                matches!(codes, NodeCodes::Table { .. }),
                !T::TYPE.is_float() && size_of::<T>() <= 2
            );
            let mut scratch = Scratch::new();
            let mut child: Option<Vec<[T; 2]>> = None;
            for l in (0..n).rev() {
                let lod: &[T] = if l == n - 1 { voxels } else { &lods[l] };
                let encoder = TreeletEncoder::new(&meta, l, lod, child.as_deref(), &codes);
                let mut roots = Vec::new();
                for i in 0..layout.level(l).treelet_count() {
                    let (r, want) = encode_treelet_reference(&meta, l, i, lod, child.as_deref());
                    let (r2, got) = encoder.encode(i, &mut scratch);
                    assert_eq!(r, r2, "{:?} level {l} treelet {i}", T::TYPE);
                    assert_eq!(want, got, "{:?} level {l} treelet {i}", T::TYPE);
                    assert_eq!(store.fetch(l, i).unwrap(), got);
                    roots.push(r);
                }
                drop(encoder);
                child = Some(roots);
            }
        }
        for (dims, h) in [([13usize, 9, 7], 3u32), ([20, 5, 11], 4), ([17, 17, 9], 2)] {
            let f = field(dims, 11);
            let u8s: Vec<u8> = f
                .iter()
                .map(|v| (v * 4.0 + 100.0).clamp(0.0, 255.0) as u8)
                .collect();
            let i8s: Vec<i8> = u8s.iter().map(|&v| v.wrapping_sub(128) as i8).collect();
            let i16s: Vec<i16> = f.iter().map(|v| (v * 300.0) as i16).collect();
            let u16s: Vec<u16> = f.iter().map(|v| (v * 900.0 + 30000.0) as u16).collect();
            let i32s: Vec<i32> = f.iter().map(|v| (v * 1e7) as i32).collect();
            // Void cells: a NaN empties its eight cells and is left out of the LOD filter.
            let mut f32s = f.clone();
            for i in (0..f32s.len()).step_by(37) {
                f32s[i] = f32::NAN;
            }
            check(&u8s, dims, h);
            check(&i8s, dims, h);
            check(&i16s, dims, h);
            check(&u16s, dims, h);
            check(&i32s, dims, h);
            check(&f32s, dims, h);
        }
        // Directly against corner_range on a block away from the origin.
        let dims = [9usize, 8, 7];
        let v: Vec<u16> = field(dims, 3)
            .iter()
            .map(|x| (x * 50.0 + 3000.0) as u16)
            .collect();
        let (lo, n) = ([2usize, 1, 3], [5usize, 6, 3]);
        let c = cell_ranges(&v, dims, lo, n);
        for k in 0..n[2] {
            for j in 0..n[1] {
                for i in 0..n[0] {
                    let cs = cell_corners(&v, dims, [lo[0] + i, lo[1] + j, lo[2] + k]);
                    let (a, b) = corner_range(&cs).unwrap();
                    assert_eq!(c[i + n[0] * (j + n[1] * k)], [a, b]);
                }
            }
        }
    }

    /// The code tables equal `Quantizer::encode` for every value and for the empty range,
    /// on value ranges that do and do not span the type.
    #[test]
    fn code_tables_equal_the_quantizer() {
        fn check<T: Voxel>(lo: f64, hi: f64, values: &(impl Iterator<Item = T> + Clone)) {
            let q = Quantizer::for_type(T::TYPE, lo, hi);
            let codes = NodeCodes::new::<T>(&q);
            assert!(matches!(codes, NodeCodes::Table { .. }));
            for a in values.clone().step_by(7) {
                for b in values.clone().step_by(5) {
                    let mut got = Vec::new();
                    codes.put_all(&q, &[[a, b]], &mut got);
                    let mut want = vec![0u8; q.node_bytes()];
                    q.put(&mut want, 0, q.encode(a.to_f64(), b.to_f64()));
                    assert_eq!(got, want, "{:?} [{a:?}, {b:?}] over [{lo}, {hi}]", T::TYPE);
                }
            }
        }
        check(0.0, 255.0, &(0..=255u8));
        check(3.0, 200.0, &(0..=255u8));
        check(-100.0, 27.0, &(-128..=127i8));
        check(-3000.0, 17000.0, &(-32768..=32767i16).step_by(131));
        check(100.0, 60000.0, &(0..=65535u16).step_by(111));
        check(5.0, 5.0, &(0..=255u8));
    }

    /// The separable exact halving of integer voxels equals the per-tap f64 path bit for
    /// bit, for every combination of halved axes, odd and even sizes, and the extremes of
    /// each type (rounding of exact halves included).
    #[test]
    fn exact_halving_equals_the_tap_path_for_integer_voxels() {
        fn check<T: Voxel>(values: &[T]) {
            for sdims in [[7u64, 6, 3], [8, 9, 3], [2, 2, 3], [5, 3, 3]] {
                let plane_len = (sdims[0] * sdims[1]) as usize;
                let vol: Vec<T> = (0..3 * plane_len)
                    .map(|i| values[(i * 7 + i / 3) % values.len()])
                    .collect();
                let p: Vec<&[T]> = vol.chunks_exact(plane_len).collect();
                for bits in 0..8u32 {
                    let halve = [0, 1, 2].map(|a| (bits >> a) & 1 == 1);
                    let ddims = HalveStage::<T>::new(sdims, halve).ddims;
                    let planes = if halve[2] {
                        [p[0], p[1], p[2]]
                    } else {
                        [p[1]; 3]
                    };
                    let n = (ddims[0] * ddims[1]) as usize;
                    let (mut want, mut got) = (vec![T::default(); n], vec![T::default(); n]);
                    halve_plane_taps(planes, sdims, ddims, halve, &mut want);
                    halve_plane(planes, sdims, ddims, halve, &mut got);
                    assert_eq!(want, got, "{:?} {sdims:?} {halve:?}", T::TYPE);
                }
            }
        }
        check(&[0u8, 255, 1, 254, 128, 3, 77]);
        check(&[i8::MIN, i8::MAX, -1, 0, 1, 5, -77]);
        check(&[0u16, u16::MAX, 1, 32768, 999, 65534]);
        check(&[i16::MIN, i16::MAX, -1, 0, 1, -3001, 12345]);
        check(&[0u32, u32::MAX, 1, 1 << 31, 123_456_789, u32::MAX - 1]);
        check(&[i32::MIN, i32::MAX, -1, 0, 1, -123_456_789, 987_654_321]);
    }

    #[test]
    fn records_reject_damage_and_misplacement() {
        let dims = [9usize, 9, 9];
        let voxels: Vec<u8> = (0..729).map(|i| (i % 200) as u8).collect();
        let grid = Grid::uniform(dims, [0.0; 3], [1.0; 3]).unwrap();
        let layout = TreeletLayout::new([9; 3], 3).unwrap();
        let mut store = MemoryStorage::new();
        build_treelets(&grid, &voxels, layout, &mut store, &mut |_, _| {}).unwrap();
        let meta = store.meta().clone();
        let good = store.fetch(1, 0).unwrap();
        assert!(TreeletRecord::<u8>::decode(&meta, 1, 0, &good).is_ok());
        assert!(TreeletRecord::<u16>::decode(&meta, 1, 0, &good).is_err());
        assert!(TreeletRecord::<u8>::decode(&meta, 1, 1, &good).is_err());
        assert!(TreeletRecord::<u8>::decode(&meta, 1, 0, &good[..good.len() - 1]).is_err());
        let mut bad = good.clone();
        bad[20] ^= 0x40; // voxel origin
        let e = TreeletRecord::<u8>::decode(&meta, 1, 0, &bad).unwrap_err();
        assert!(e.to_string().contains("voxel block"), "{e}");
        let err = build_treelets(
            &grid,
            &voxels[1..],
            TreeletLayout::new([9; 3], 3).unwrap(),
            &mut store,
            &mut |_, _| {},
        );
        assert!(matches!(err, Err(OocError::LengthMismatch { .. })));
    }
}
