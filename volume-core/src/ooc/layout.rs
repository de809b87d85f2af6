//! Tree and treelet geometry with 64-bit addresses (thesis seed 004 §7.3, §7.8.1).
//!
//! The tree levels are those of the in-core slim kd-tree ([`crate::kdtree`]): each axis is
//! virtually padded to a power of two, every level halves the node extent along its longest
//! axis ([`split_axis`]), and only real nodes (`ceil(cells / extent)` per axis) exist. Level
//! `depth` holds the cells. A layout made for a grid ([`TreeletLayout::for_grid`]) weighs the
//! extents by the cells' world widths, as the in-core tree does, so on anisotropic voxels
//! both trees split alike; a file records the axes it was cut with
//! ([`TreeletLayout::split_axes`], [`TreeletLayout::with_axes`]). [`TreeletLayout::new`]
//! halves in cells (x before y before z on ties): the rule of files that record no axes.
//! Tests check this geometry against [`crate::kdtree::KdTree`].
//!
//! *Treelet level* `L` owns the node levels `first..end` (`end − first` = the treelet
//! height, except the top-most level, which may be shorter, §7.8.1). Its treelets are the
//! subtrees rooted at the nodes of level `first`, numbered in raster order (x fastest) of
//! their root, so a treelet's address is plain arithmetic. The *cells* of treelet level `L`
//! are the nodes of level `end`: the LOD volume of level `L` has one cell per such node
//! (`lod_factor` = their extent in finest cells), so LOD sample `v` sits at finest sample
//! `min(v · factor, cells)` and the last treelet level carries the original voxels.
//!
//! All counts and addresses are `u64`: a 2048×2048×1100 volume has more than 2³² voxels.

use super::OocError;
use crate::intersect::TraversalFrame;
use crate::kdtree::split_axis;
use crate::volume::Grid;

/// One level of the implicit kd-tree.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LevelShape {
    /// Split axis (unused at the cell level).
    pub axis: usize,
    /// Cells per node side, virtual padding included (a power of two).
    pub extent: [u64; 3],
    /// Real nodes per axis.
    pub count: [u64; 3],
}

/// One level of treelets (and the LOD level it carries).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TreeletLevel {
    /// First tree level inside the treelets (their roots).
    pub first: usize,
    /// One past the last tree level inside; the nodes of level `end` are this level's cells.
    pub end: usize,
    /// Treelets per axis (= nodes of tree level `first`).
    pub roots: [u64; 3],
    /// LOD cells per treelet side (virtual padding included).
    pub root_cells: [u64; 3],
    /// Finest cells per LOD cell side.
    pub lod_factor: [u64; 3],
    /// LOD cells per axis.
    pub lod_cells: [u64; 3],
    /// LOD samples per axis (`lod_cells + 1`).
    pub lod_dims: [u64; 3],
}

impl TreeletLevel {
    /// Node levels per treelet.
    pub fn height(&self) -> usize {
        self.end - self.first
    }

    /// Node slots per treelet (`2^height − 1`, heap order, virtual nodes included).
    pub fn node_slots(&self) -> usize {
        (1usize << self.height()) - 1
    }

    pub fn treelet_count(&self) -> u64 {
        self.roots[0] * self.roots[1] * self.roots[2]
    }

    /// Largest voxel block (LOD cells of one treelet plus the one-voxel border).
    pub fn max_block_dims(&self) -> [u64; 3] {
        [0, 1, 2].map(|a| (self.root_cells[a] + 3).min(self.lod_dims[a]))
    }
}

/// The tree geometry of a volume and its cut into treelet levels.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TreeletLayout {
    dims: [u64; 3],
    cells: [u64; 3],
    treelet_height: u32,
    shapes: Vec<LevelShape>,
    levels: Vec<TreeletLevel>,
}

/// Raster (x fastest) linear index of `p` in a `dims` box, in 64 bits.
#[inline(always)]
pub fn linear_index(dims: [u64; 3], p: [u64; 3]) -> u64 {
    p[0] + dims[0] * (p[1] + dims[1] * p[2])
}

/// The tree levels of the slim kd-tree over `cells` `cell_mm` wide ([`crate::kdtree`]'s
/// rule: [`split_axis`]).
pub fn tree_levels(cells: [u64; 3], cell_mm: [f64; 3]) -> Vec<LevelShape> {
    // Widths that are not positive numbers count as 1, as `cell_width_world` gives them.
    let cell_mm = cell_mm.map(|w| if w.is_finite() && w > 0.0 { w } else { 1.0 });
    // Extents are at most 2^32 (checked by the layout).
    levels_by(cells, |extent, _| {
        Some(split_axis(extent.map(|e| e as usize), cell_mm))
    })
    .expect("split_axis picks an axis longer than one cell")
}

/// The tree levels over `cells` split along `axes` in turn (a file's), or `None` unless they
/// halve the padded extents down to one cell, each along an axis longer than one cell.
pub fn tree_levels_from_axes(cells: [u64; 3], axes: &[u8]) -> Option<Vec<LevelShape>> {
    let shapes = levels_by(cells, |_, level| axes.get(level).map(|&a| usize::from(a)))?;
    (shapes.len() == axes.len() + 1).then_some(shapes)
}

/// The levels with the split axis of each chosen by `pick(extent, level)`: `None` when it
/// picks none, or an axis that is not longer than one cell.
fn levels_by(
    cells: [u64; 3],
    mut pick: impl FnMut([u64; 3], usize) -> Option<usize>,
) -> Option<Vec<LevelShape>> {
    let mut out = Vec::new();
    let mut extent = cells.map(u64::next_power_of_two);
    loop {
        let count = [0, 1, 2].map(|a| cells[a].div_ceil(extent[a]));
        if extent == [1, 1, 1] {
            // The cell level: its axis is unused.
            out.push(LevelShape {
                axis: 0,
                extent,
                count,
            });
            return Some(out);
        }
        let axis = pick(extent, out.len()).filter(|&a| a < 3 && extent[a] > 1)?;
        out.push(LevelShape {
            axis,
            extent,
            count,
        });
        extent[axis] /= 2;
    }
}

impl TreeletLayout {
    /// The layout of a `dims` sample volume cut into treelets of `treelet_height` node
    /// levels (the thesis found 9 best, §7.9.1), its tree halving in cells: the rule of
    /// files that record no split axes, and of grids whose cells are cubes.
    pub fn new(dims: [u64; 3], treelet_height: u32) -> Result<Self, OocError> {
        Self::with_shapes(dims, treelet_height, |cells| {
            Some(tree_levels(cells, [1.0; 3]))
        })
    }

    /// The layout of `grid` with its tree split as the in-core tree splits it: along the
    /// nodes' longest axis in world space ([`split_axis`] with the cells' world widths).
    pub fn for_grid(grid: &Grid, treelet_height: u32) -> Result<Self, OocError> {
        let cell_mm = TraversalFrame::new(grid).cell_width_world();
        let dims = grid.dims().map(|d| d as u64);
        Self::with_shapes(dims, treelet_height, |cells| {
            Some(tree_levels(cells, cell_mm))
        })
    }

    /// The layout whose tree levels split along `axes` in turn (as a file records them,
    /// [`TreeletLayout::split_axes`]); an error unless they halve every axis down to one
    /// cell.
    pub fn with_axes(dims: [u64; 3], treelet_height: u32, axes: &[u8]) -> Result<Self, OocError> {
        Self::with_shapes(dims, treelet_height, |cells| {
            tree_levels_from_axes(cells, axes)
        })
    }

    /// The checks of the constructors, then the cut of `shapes(cells)` into treelet levels.
    fn with_shapes(
        dims: [u64; 3],
        treelet_height: u32,
        shapes: impl FnOnce([u64; 3]) -> Option<Vec<LevelShape>>,
    ) -> Result<Self, OocError> {
        if !(1..=24).contains(&treelet_height) {
            return Err(OocError::BadHeight(treelet_height));
        }
        let bad = |reason: &str| OocError::BadDims {
            dims,
            reason: reason.into(),
        };
        if dims.iter().any(|&d| d < 2) {
            return Err(bad("every axis needs at least 2 samples (one cell)"));
        }
        if dims.iter().any(|&d| d > u64::from(u32::MAX)) {
            return Err(bad("more than 2^32 samples along one axis"));
        }
        dims.iter()
            .try_fold(1u64, |acc, &d| acc.checked_mul(d))
            .filter(|&n| n <= u64::MAX / 16)
            .ok_or_else(|| bad("voxel count overflows 64-bit addresses"))?;
        let cells = dims.map(|d| d - 1);
        let shapes = shapes(cells)
            .ok_or_else(|| bad("the split axes do not halve every axis down to one cell"))?;
        let depth = shapes.len() - 1;
        let h = treelet_height as usize;
        let n = depth.div_ceil(h).max(1);
        let levels = (0..n)
            .map(|l| {
                let end = depth - (n - 1 - l) * h;
                let first = if l == 0 { 0 } else { end - h };
                let top = shapes[first];
                let bottom = shapes[end];
                TreeletLevel {
                    first,
                    end,
                    roots: top.count,
                    root_cells: [0, 1, 2].map(|a| top.extent[a] / bottom.extent[a]),
                    lod_factor: bottom.extent,
                    lod_cells: bottom.count,
                    lod_dims: bottom.count.map(|c| c + 1),
                }
            })
            .collect();
        Ok(Self {
            dims,
            cells,
            treelet_height,
            shapes,
            levels,
        })
    }

    /// The layout of `grid` ([`TreeletLayout::for_grid`]) with `levels` treelet levels (the
    /// height is chosen to fit).
    pub fn for_grid_with_levels(grid: &Grid, levels: usize) -> Result<Self, OocError> {
        let cells = grid.dims().map(|d| (d as u64).saturating_sub(1).max(1));
        let cell_mm = TraversalFrame::new(grid).cell_width_world();
        let depth = tree_levels(cells, cell_mm).len() - 1;
        let h = depth.div_ceil(levels.max(1)).clamp(1, 24);
        Self::for_grid(grid, h as u32)
    }

    /// The split axis of each inner tree level, root first (what a file records).
    pub fn split_axes(&self) -> Vec<u8> {
        let inner = &self.shapes[..self.shapes.len() - 1];
        inner.iter().map(|s| s.axis as u8).collect()
    }

    pub fn dims(&self) -> [u64; 3] {
        self.dims
    }

    pub fn cells(&self) -> [u64; 3] {
        self.cells
    }

    pub fn treelet_height(&self) -> u32 {
        self.treelet_height
    }

    /// Inner tree levels (level `depth` holds the cells).
    pub fn depth(&self) -> usize {
        self.shapes.len() - 1
    }

    pub fn shape(&self, tree_level: usize) -> &LevelShape {
        &self.shapes[tree_level]
    }

    pub fn shapes(&self) -> &[LevelShape] {
        &self.shapes
    }

    pub fn levels(&self) -> &[TreeletLevel] {
        &self.levels
    }

    pub fn level(&self, l: usize) -> &TreeletLevel {
        &self.levels[l]
    }

    pub fn level_count(&self) -> usize {
        self.levels.len()
    }

    pub fn voxel_count(&self) -> u64 {
        self.dims[0] * self.dims[1] * self.dims[2]
    }

    /// Total treelets over all levels.
    pub fn treelet_count(&self) -> u64 {
        self.levels.iter().map(TreeletLevel::treelet_count).sum()
    }

    /// Root node (at tree level `first`) of treelet `index` of level `l`.
    pub fn root_of(&self, l: usize, index: u64) -> [u64; 3] {
        let r = self.levels[l].roots;
        [index % r[0], (index / r[0]) % r[1], index / (r[0] * r[1])]
    }

    pub fn index_of(&self, l: usize, root: [u64; 3]) -> u64 {
        linear_index(self.levels[l].roots, root)
    }

    /// The LOD sample box `(origin, dims)` stored with treelet `root` of level `l`: its LOD
    /// cells plus a one-voxel border (clamped to the volume) for central differences.
    pub fn voxel_block(&self, l: usize, root: [u64; 3]) -> ([u64; 3], [u64; 3]) {
        let lv = &self.levels[l];
        let mut origin = [0; 3];
        let mut dims = [0; 3];
        for a in 0..3 {
            let c_lo = root[a] * lv.root_cells[a];
            let c_hi = ((root[a] + 1) * lv.root_cells[a]).min(lv.lod_cells[a]);
            let lo = c_lo.saturating_sub(1);
            let hi = (c_hi + 1).min(lv.lod_dims[a] - 1);
            origin[a] = lo;
            dims[a] = hi - lo + 1;
        }
        (origin, dims)
    }

    /// Finest sample index of LOD sample `v` of level `l` along `axis`.
    pub fn lod_sample(&self, l: usize, axis: usize, v: u64) -> u64 {
        (v * self.levels[l].lod_factor[axis]).min(self.cells[axis])
    }

    /// Finest linear voxel index of LOD sample `p` of level `l` (64-bit).
    pub fn fine_voxel_index(&self, l: usize, p: [u64; 3]) -> u64 {
        linear_index(self.dims, [0, 1, 2].map(|a| self.lod_sample(l, a, p[a])))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::intersect::TraversalFrame;
    use crate::kdtree::{KdTree, KdTreeConfig};
    use crate::volume::Grid;

    #[test]
    fn tree_levels_match_the_in_core_kdtree() {
        // Cubic cells, then anisotropic ones (a CT's 0.57 mm pixels and 5 mm slices, and
        // others) where the world rule and halving in cells differ.
        let cases = [
            ([2, 2, 2], [1.0; 3]),
            ([5, 3, 9], [1.0; 3]),
            ([17, 2, 33], [1.0; 3]),
            ([40, 41, 7], [1.0; 3]),
            ([2, 100, 2], [1.0; 3]),
            ([65, 65, 9], [0.57, 0.57, 5.0]),
            ([40, 41, 7], [0.3, 2.0, 1.0]),
            ([9, 30, 30], [4.0, 1.0, 0.25]),
        ];
        for (dims, spacing) in cases {
            let n: usize = dims.iter().product();
            let voxels: Vec<u8> = (0..n).map(|i| (i * 37 % 251) as u8).collect();
            let grid = Grid::uniform(dims, [0.0; 3], spacing).unwrap();
            let frame = TraversalFrame::new(&grid);
            let config = KdTreeConfig { unstored_levels: 0 };
            let tree = KdTree::build(&voxels, dims, &frame, config);
            let cells = dims.map(|d| d as u64 - 1);
            let layout = TreeletLayout::for_grid(&grid, 3).unwrap();
            let shapes = layout.shapes();
            assert_eq!(shapes, tree_levels(cells, spacing).as_slice());
            assert_eq!(shapes.len() - 1, tree.depth(), "{dims:?}");
            for (l, s) in shapes.iter().enumerate().take(tree.depth()) {
                assert_eq!(s.axis, tree.level_axis(l), "{dims:?} {spacing:?} level {l}");
                let c = s.count.map(|x| x as usize);
                assert!(tree.node_range(l, c.map(|x| x - 1)).is_some());
                for a in 0..3 {
                    let mut past = c.map(|x| x - 1);
                    past[a] += 1;
                    assert!(tree.node_range(l, past).is_none(), "{dims:?} level {l}");
                }
            }
            if spacing == [1.0; 3] {
                assert_eq!(
                    layout,
                    TreeletLayout::new(dims.map(|d| d as u64), 3).unwrap()
                );
            }
        }
    }

    #[test]
    fn recorded_axes_give_the_layout_back_and_bad_ones_are_refused() {
        let grid = Grid::uniform([65, 65, 9], [0.0; 3], [0.57, 0.57, 5.0]).unwrap();
        let world = TreeletLayout::for_grid(&grid, 4).unwrap();
        let axes = world.split_axes();
        assert_eq!(axes.len(), world.depth());
        let dims = [65, 65, 9];
        assert_eq!(TreeletLayout::with_axes(dims, 4, &axes).unwrap(), world);
        // The root splits z in world space: 8 slices of 5 mm (40 mm) against 64 pixels of
        // 0.57 mm (36.5 mm); halving in cells splits x first.
        assert_eq!(axes[0], 2);
        let index = TreeletLayout::new(dims, 4).unwrap();
        assert_eq!(index.split_axes()[0], 0);
        // Another order that halves every axis is a valid layout of its own.
        assert_eq!(
            TreeletLayout::with_axes(dims, 4, &index.split_axes()).unwrap(),
            index
        );
        // Too few, too many, an axis already one cell wide, no such axis.
        let bad = [
            axes[..axes.len() - 1].to_vec(),
            [axes.clone(), vec![0]].concat(),
            vec![2; axes.len()],
            [vec![3], axes[1..].to_vec()].concat(),
        ];
        for b in &bad {
            assert!(TreeletLayout::with_axes(dims, 4, b).is_err(), "{b:?}");
        }
    }

    #[test]
    fn treelet_levels_cover_the_tree_top_level_shortest() {
        let t = TreeletLayout::new([257, 257, 257], 9).unwrap();
        assert_eq!(t.depth(), 24);
        let spans: Vec<_> = t.levels().iter().map(|l| (l.first, l.end)).collect();
        assert_eq!(spans, vec![(0, 6), (6, 15), (15, 24)]);
        let last = t.level(2);
        assert_eq!(last.lod_factor, [1, 1, 1]);
        assert_eq!(last.lod_dims, [257, 257, 257]);
        // Each level's LOD cells are the next level's treelet roots.
        for w in t.levels().windows(2) {
            assert_eq!(w[0].lod_cells, w[1].roots);
        }
        // Root treelet: one, covering the whole volume.
        assert_eq!(t.level(0).treelet_count(), 1);
        // A one-cell volume: one level, one treelet, no nodes.
        let one = TreeletLayout::new([2, 2, 2], 9).unwrap();
        assert_eq!(one.level_count(), 1);
        assert_eq!(one.level(0).node_slots(), 0);
        assert_eq!(one.voxel_block(0, [0, 0, 0]), ([0; 3], [2; 3]));
        assert!(TreeletLayout::new([1, 5, 5], 9).is_err());
        assert!(TreeletLayout::new([5, 5, 5], 0).is_err());
        assert_eq!(
            TreeletLayout::for_grid_with_levels(
                &Grid::uniform([257; 3], [0.0; 3], [1.0; 3]).unwrap(),
                4
            )
            .unwrap()
            .level_count(),
            4
        );
    }

    #[test]
    fn voxel_blocks_tile_the_lod_volume_with_borders() {
        let t = TreeletLayout::new([30, 19, 11], 4).unwrap();
        for l in 0..t.level_count() {
            let lv = *t.level(l);
            let mut covered = vec![0u32; lv.lod_cells.iter().product::<u64>() as usize];
            for i in 0..lv.treelet_count() {
                let root = t.root_of(l, i);
                assert_eq!(t.index_of(l, root), i);
                let (o, d) = t.voxel_block(l, root);
                for a in 0..3 {
                    assert!(o[a] + d[a] <= lv.lod_dims[a]);
                    assert!(d[a] <= lv.max_block_dims()[a]);
                }
                // Cells owned by this treelet are inside the block with a border where the
                // volume continues.
                for k in 0..lv.lod_cells[2] {
                    for j in 0..lv.lod_cells[1] {
                        for i2 in 0..lv.lod_cells[0] {
                            let c = [i2, j, k];
                            if (0..3).all(|a| c[a] / lv.root_cells[a] == root[a]) {
                                covered[linear_index(lv.lod_cells, c) as usize] += 1;
                                for a in 0..3 {
                                    assert!(c[a] >= o[a] && c[a] + 1 < o[a] + d[a]);
                                    assert!(c[a] == 0 || c[a] > o[a]);
                                    assert!(c[a] + 2 >= lv.lod_dims[a] || c[a] + 2 < o[a] + d[a]);
                                }
                            }
                        }
                    }
                }
            }
            assert!(covered.iter().all(|&c| c == 1), "level {l}");
        }
    }

    /// 64-bit address arithmetic on a 2048×2048×1100 volume (more than 2³² voxels), checked
    /// against u128 arithmetic; pure arithmetic, no allocation of the volume.
    #[test]
    fn addresses_above_four_billion_voxels_do_not_wrap() {
        let dims = [2048u64, 2048, 1100];
        let t = TreeletLayout::new(dims, 9).unwrap();
        assert!(t.voxel_count() > 1 << 32);
        assert_eq!(u128::from(t.voxel_count()), 2048u128 * 2048 * 1100);
        let last = t.level_count() - 1;
        let far = [2047u64, 2047, 1099];
        let idx = t.fine_voxel_index(last, far);
        assert_eq!(
            u128::from(idx),
            2047u128 + 2048 * (2047 + 2048 * 1099),
            "last voxel"
        );
        assert!(idx > u64::from(u32::MAX));
        // The last treelet of the finest level owns the last cell.
        let lv = *t.level(last);
        let n = lv.treelet_count();
        let root = t.root_of(last, n - 1);
        let (o, d) = t.voxel_block(last, root);
        for a in 0..3 {
            assert_eq!(o[a] + d[a], dims[a], "axis {a}");
        }
        assert_eq!(
            u128::from(n),
            (0..3)
                .map(|a| u128::from((dims[a] - 1).div_ceil(lv.root_cells[a] * lv.lod_factor[a])))
                .product::<u128>()
        );
        // Coarser levels map back to in-range finest samples.
        for l in 0..t.level_count() {
            let lv = *t.level(l);
            let p = lv.lod_dims.map(|d| d - 1);
            let i = t.fine_voxel_index(l, p);
            assert_eq!(i, t.voxel_count() - 1, "level {l}");
        }
    }
}
