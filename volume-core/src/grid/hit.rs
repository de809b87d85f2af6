//! From a traversal's cell hit to a world-space [`Hit`]: [`first_hit_with`], the one
//! first-hit loop of the kd-tree scene ([`super::GridScene`]), its DDA twin
//! ([`super::DdaScene`]) and the out-of-core scene ([`crate::ooc::OocScene`]), and
//! [`make_hit`], the hit with its shading normal ([`super::normals`]).

use glam::Vec3;

use super::normals::normal_at;
use crate::intersect::{CellHit, CellIntersector, LocalRay, TraversalFrame};
use crate::math::Ray;
use crate::render::{Hit, Stats};
use crate::voxel::Voxel;

/// The voxel block a cell hit lies in (the grid's, or an out-of-core treelet's), which its
/// normal is computed from.
#[derive(Debug, Clone, Copy)]
pub struct CellBlock<'a, T: Voxel> {
    pub frame: &'a TraversalFrame,
    pub voxels: &'a [T],
    pub dims: [usize; 3],
}

/// A structure that finds the first cell hit of a ray in traversal units.
pub trait CellTrace<T: Voxel> {
    /// The active isovalues as the traversal reads them
    /// ([`crate::render::IsoScene::prepare`]).
    type Isovalues;

    /// The frame world rays are mapped into.
    fn frame(&self) -> &TraversalFrame;

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
    ))
}

/// Turns a cell hit into a [`Hit`] with a world-space normal.
pub fn make_hit<T: Voxel>(
    frame: &TraversalFrame,
    voxels: &[T],
    dims: [usize; 3],
    local: &LocalRay,
    world: &Ray,
    h: CellHit,
) -> Hit {
    let (lo, hi) = frame.cell_box(h.cell);
    let p = local.origin + local.dir * h.t;
    let uvw = ((p - lo) / (hi - lo)).clamp(Vec3::ZERO, Vec3::ONE);
    let normal = normal_at(frame, voxels, dims, h.cell, uvw)
        .unwrap_or_else(|| (-world.dir).normalize_or(Vec3::Z));
    Hit {
        t: h.t,
        surface: h.surface,
        normal,
        cell: 0,
    }
}
