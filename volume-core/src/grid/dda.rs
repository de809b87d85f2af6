//! The brute-force twin of the kd-tree: a 3D-DDA cell walk (Amanatides & Woo 1987) over
//! the same cells, with the same cell test ([`crate::intersect::intersect_cell`]) and
//! intersector. It visits every cell the ray crosses, without culling: the test oracle for
//! [`crate::kdtree`] and the performance baseline of `isoscope bench`.
//!
//! A ray lying exactly in a cell-face plane (zero direction component, origin on a sample
//! coordinate) walks the cells on both sides, as the kd-tree visits both children (seed 000
//! §5). The walk stops once the next cell starts beyond the nearest hit so far, so the
//! result does not depend on the visiting order of cells that share a boundary point.

use super::hit::{CellBlock, CellTrace, first_hit_with};
use crate::intersect::{
    CellHit, CellIntersector, Intersector, IsoSet, LocalRay, TraversalFrame, intersect_cell,
};
use crate::math::{Aabb, Ray};
use crate::render::{Hit, IsoScene, Normals, Stats};
use crate::volume::ValueMap;
use crate::voxel::Voxel;

/// A borrowed view of a grid scene walked cell by cell (see [`super::GridScene::dda`]).
#[derive(Clone, Copy)]
pub struct DdaScene<'a, T: Voxel> {
    frame: &'a TraversalFrame,
    voxels: &'a [T],
    dims: [usize; 3],
    intersector: Intersector,
    /// Physical isovalues to stored ones (the kd-tree scene's map).
    value_map: ValueMap,
}

impl<'a, T: Voxel> DdaScene<'a, T> {
    pub fn new(
        frame: &'a TraversalFrame,
        voxels: &'a [T],
        dims: [usize; 3],
        intersector: Intersector,
    ) -> Self {
        assert_eq!(voxels.len(), dims.iter().product::<usize>(), "voxel count");
        Self {
            frame,
            voxels,
            dims,
            intersector,
            value_map: ValueMap::IDENTITY,
        }
    }

    /// Isovalues are physical values mapped by `value_map` ([`IsoSet::mapped`]).
    pub fn with_value_map(mut self, value_map: ValueMap) -> Self {
        self.value_map = value_map;
        self
    }

    /// First hit in traversal terms with a static intersector.
    pub fn cell_hit_with<C: CellIntersector, S: Stats>(
        &self,
        ray: &LocalRay,
        t_min: f32,
        t_max: f32,
        isos: &IsoSet<T>,
        intersector: C,
        stats: &mut S,
    ) -> Option<CellHit> {
        if isos.is_empty() || ray.dir == glam::Vec3::ZERO {
            return None;
        }
        let (t0, t1) = self.frame.clip(ray, t_min, t_max)?;
        let cells = self.frame.cells();
        // Axes the ray does not move along: one cell, or two if it lies in a face plane.
        let mut cand = [[0usize; 2]; 3];
        let mut ncand = [1usize; 3];
        for a in 0..3 {
            if ray.dir[a] == 0.0 {
                let x = ray.origin[a];
                let m = self.frame.locate(a, x);
                cand[a][0] = m;
                if x == self.frame.pos()[a][m] && m > 0 {
                    cand[a][1] = m - 1;
                    ncand[a] = 2;
                } else if x == self.frame.pos()[a][m + 1] && m + 1 < cells[a] {
                    cand[a][1] = m + 1;
                    ncand[a] = 2;
                }
            }
        }
        let mut best: Option<CellHit> = None;
        for cz in 0..ncand[2] {
            for cy in 0..ncand[1] {
                for cx in 0..ncand[0] {
                    let fixed = [cand[0][cx], cand[1][cy], cand[2][cz]];
                    if let Some(h) = self.walk(ray, t0, t1, fixed, isos, intersector, stats)
                        && best.is_none_or(|b| h.t < b.t)
                    {
                        best = Some(h);
                    }
                }
            }
        }
        best
    }

    #[inline]
    fn walk<C: CellIntersector, S: Stats>(
        &self,
        ray: &LocalRay,
        t0: f32,
        t1: f32,
        fixed: [usize; 3],
        isos: &IsoSet<T>,
        intersector: C,
        stats: &mut S,
    ) -> Option<CellHit> {
        let cells = self.frame.cells();
        let pos = &self.frame.pos();
        let tpos = |a: usize, i: usize| (pos[a][i] - ray.origin[a]) * ray.inv_dir[a];
        let mut cell = fixed;
        let mut t_next = [f32::INFINITY; 3];
        let p = ray.origin + ray.dir * t0;
        for a in 0..3 {
            let d = ray.dir[a];
            if d == 0.0 {
                continue;
            }
            let n = cells[a];
            let mut m = self.frame.locate(a, p[a]);
            // Fix rounding of the entry point: the first cell whose span reaches t0.
            if d > 0.0 {
                while m > 0 && tpos(a, m) > t0 {
                    m -= 1;
                }
                while m + 1 < n && tpos(a, m + 1) < t0 {
                    m += 1;
                }
                t_next[a] = tpos(a, m + 1);
            } else {
                while m + 1 < n && tpos(a, m + 1) > t0 {
                    m += 1;
                }
                while m > 0 && tpos(a, m) < t0 {
                    m -= 1;
                }
                t_next[a] = tpos(a, m);
            }
            cell[a] = m;
        }
        let mut best: Option<CellHit> = None;
        loop {
            stats.node();
            if let Some(h) = intersect_cell(
                self.frame,
                self.voxels,
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
            let mut a = 0;
            for b in 1..3 {
                if t_next[b] < t_next[a] {
                    a = b;
                }
            }
            let t_cross = t_next[a];
            if t_cross > t1 || best.is_some_and(|b| t_cross > b.t) || t_cross == f32::INFINITY {
                return best;
            }
            if ray.dir[a] > 0.0 {
                if cell[a] + 1 >= cells[a] {
                    return best;
                }
                cell[a] += 1;
                t_next[a] = tpos(a, cell[a] + 1);
            } else {
                if cell[a] == 0 {
                    return best;
                }
                cell[a] -= 1;
                t_next[a] = tpos(a, cell[a]);
            }
        }
    }
}

impl<T: Voxel> CellTrace<T> for DdaScene<'_, T> {
    type Isovalues = IsoSet<T>;

    fn frame(&self) -> &TraversalFrame {
        self.frame
    }

    fn normals(isos: &Self::Isovalues) -> Option<Normals> {
        isos.normals()
    }

    fn cell_hit<C: CellIntersector, S: Stats>(
        &self,
        ray: &LocalRay,
        t_min: f32,
        t_max: f32,
        isos: &IsoSet<T>,
        intersector: C,
        stats: &mut S,
    ) -> Option<(CellHit, CellBlock<'_, T>)> {
        let h = self.cell_hit_with(ray, t_min, t_max, isos, intersector, stats)?;
        let block = CellBlock {
            frame: self.frame,
            voxels: self.voxels,
            dims: self.dims,
        };
        Some((h, block))
    }
}

impl<T: Voxel> IsoScene for DdaScene<'_, T> {
    type Isovalues = IsoSet<T>;

    fn prepare(&self, isovalues: &[f32]) -> IsoSet<T> {
        IsoSet::mapped(isovalues, self.value_map)
    }

    fn world_bounds(&self) -> Aabb {
        self.frame.world_bounds()
    }

    fn first_hit_prepared<S: Stats>(
        &self,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
        isos: &IsoSet<T>,
        stats: &mut S,
    ) -> Option<Hit> {
        crate::dispatch_intersector!(self.intersector, c => first_hit_with(self, ray, t_min, t_max, isos, c, stats))
    }
}
