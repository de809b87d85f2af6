//! Tree and treelet geometry with 64-bit addresses (thesis seed 004 §7.3, §7.8.1).
//!
//! The tree levels are those of the in-core slim kd-tree ([`crate::kdtree`]) with unit cell
//! widths: each axis is virtually padded to a power of two, every level halves the node
//! extent along its largest axis *in cells* (x before y before z on ties), and only real
//! nodes (`ceil(cells / extent)` per axis) exist. Level `depth` holds the cells. The in-core
//! tree weighs the extents by the cells' world widths; a treelet file's layout depends on
//! its dims alone, so the two trees differ on anisotropic grids (the hits do not). A test
//! checks this geometry against [`crate::kdtree::KdTree`] on a unit grid.
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
use crate::kdtree::split_axis;

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

/// The tree levels of the slim kd-tree over `cells` ([`crate::kdtree`]'s rule with unit cell
/// widths).
pub fn tree_levels(cells: [u64; 3]) -> Vec<LevelShape> {
    let mut out = Vec::new();
    let mut extent = cells.map(u64::next_power_of_two);
    loop {
        let count = [0, 1, 2].map(|a| cells[a].div_ceil(extent[a]));
        // Index-space halving (unit cell widths): a treelet file's layout is a function of
        // its dims alone. Extents are at most 2^32 (checked by the layout).
        let axis = split_axis(extent.map(|e| e as usize), [1.0; 3]);
        out.push(LevelShape {
            axis,
            extent,
            count,
        });
        if extent == [1, 1, 1] {
            return out;
        }
        extent[axis] /= 2;
    }
}

impl TreeletLayout {
    /// The layout of a `dims` sample volume cut into treelets of `treelet_height` node
    /// levels (the thesis found 9 best, §7.9.1).
    pub fn new(dims: [u64; 3], treelet_height: u32) -> Result<Self, OocError> {
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
        let shapes = tree_levels(cells);
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

    /// The layout with `levels` treelet levels (the height is chosen to fit).
    pub fn with_levels(dims: [u64; 3], levels: usize) -> Result<Self, OocError> {
        let cells = dims.map(|d| d.saturating_sub(1).max(1));
        let depth = tree_levels(cells).len() - 1;
        let h = depth.div_ceil(levels.max(1)).clamp(1, 24);
        Self::new(dims, h as u32)
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
        for dims in [[2, 2, 2], [5, 3, 9], [17, 2, 33], [40, 41, 7], [2, 100, 2]] {
            let n: usize = dims.iter().product();
            let voxels: Vec<u8> = (0..n).map(|i| (i * 37 % 251) as u8).collect();
            let grid = Grid::uniform(dims, [0.0; 3], [1.0; 3]).unwrap();
            let frame = TraversalFrame::new(&grid);
            let config = KdTreeConfig { unstored_levels: 0 };
            let tree = KdTree::build(&voxels, dims, &frame, config);
            let cells = dims.map(|d| d as u64 - 1);
            let shapes = tree_levels(cells);
            assert_eq!(shapes.len() - 1, tree.depth(), "{dims:?}");
            for (l, s) in shapes.iter().enumerate().take(tree.depth()) {
                let c = s.count.map(|x| x as usize);
                assert!(tree.node_range(l, c.map(|x| x - 1)).is_some());
                for a in 0..3 {
                    let mut past = c.map(|x| x - 1);
                    past[a] += 1;
                    assert!(tree.node_range(l, past).is_none(), "{dims:?} level {l}");
                }
            }
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
            TreeletLayout::with_levels([257; 3], 4)
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
