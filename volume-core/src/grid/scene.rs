//! [`IsoScene`] for rectilinear volumes: the implicit min/max kd-tree
//! ([`crate::kdtree`]) plus the chosen cell intersector ([`crate::intersect`]).
//!
//! [`GridScene<T>`] is the typed scene (voxels in their native type `T`); [`AnyGridScene`]
//! holds one for whatever type a volume has and implements [`IsoScene`] itself (one
//! well-predicted `match` per ray), or hands the typed scene to a [`SceneVisitor`] so a
//! renderer runs fully monomorphized code ([`AnyGridScene::visit`]).
//! [`GridScene::dda`] gives the brute-force twin over the same cells ([`super::dda`]).
//!
//! Rays are mapped into traversal units once per ray ([`TraversalFrame::to_local`]);
//! `world_from_grid` is honoured, and `t` is preserved (the direction is not renormalised),
//! so `Hit::t` is in the caller's ray units. Normals: [`super::normals`].

use std::time::Duration;

use glam::Vec3;

use super::dda::DdaScene;
use super::hit::{
    CellBlock, CellTrace, LaneLayers, LocalPacket, first_hit_with, first_hits_packet_with,
    make_hits_in_block,
};
use super::sample::{GridField, GridQuantity, gradient_magnitude_range};
use crate::error::VolumeError;
use crate::intersect::{CellHit, CellIntersector, Intersector, IsoSet, LocalRay, TraversalFrame};
use crate::kdtree::packet::{WalkFor, ray_go_on};
use crate::kdtree::{KdTree, KdTreeConfig, LIVE_COVER_NODES, PACKET_WIDTH, with_packet_stack};
use crate::math::{Aabb, Ray};
use crate::render::{
    Hit, HitField, IsoScene, MAX_PEELED, Normals, Peel, PeeledHits, SceneVisitor, Stats,
};
use crate::volume::{Grid, RectilinearVolume, ValueMap, VoxelBuffer, VoxelData};
use crate::voxel::Voxel;

/// A rectilinear volume of voxel type `T`, ready for ray casting.
#[derive(Clone)]
pub struct GridScene<T: Voxel> {
    voxels: VoxelBuffer<T>,
    dims: [usize; 3],
    frame: TraversalFrame,
    tree: KdTree<T>,
    intersector: Intersector,
    /// Shading normals of hits (smooth unless set).
    normals: Normals,
    /// Isovalues are physical; the voxels stored (a volume's [`ValueMap`]).
    value_map: ValueMap,
}

impl<T: Voxel> std::fmt::Debug for GridScene<T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("GridScene")
            .field("voxel_type", &T::TYPE)
            .field("dims", &self.dims)
            .field("intersector", &self.intersector)
            .finish_non_exhaustive()
    }
}

impl<T: Voxel> GridScene<T> {
    /// Builds the kd-tree over `voxels` laid out on `grid`.
    pub fn new(
        grid: &Grid,
        voxels: VoxelBuffer<T>,
        intersector: Intersector,
        config: KdTreeConfig,
    ) -> Result<Self, VolumeError> {
        if voxels.len() != grid.voxel_count() {
            return Err(VolumeError::LengthMismatch {
                dims: grid.dims(),
                expected: grid.voxel_count(),
                actual: voxels.len(),
            });
        }
        let frame = TraversalFrame::new(grid);
        let tree = KdTree::build(voxels.as_slice(), grid.dims(), &frame, config);
        Ok(Self {
            voxels,
            dims: grid.dims(),
            frame,
            tree,
            intersector,
            normals: Normals::Smooth,
            value_map: ValueMap::IDENTITY,
        })
    }

    /// Isovalues given to this scene are physical values, mapped to stored ones by
    /// `value_map` once per frame ([`IsoScene::prepare`]).
    pub fn set_value_map(&mut self, value_map: ValueMap) {
        self.value_map = value_map;
    }

    pub fn value_map(&self) -> ValueMap {
        self.value_map
    }

    pub fn intersector(&self) -> Intersector {
        self.intersector
    }

    pub fn set_intersector(&mut self, intersector: Intersector) {
        self.intersector = intersector;
    }

    pub fn normals(&self) -> Normals {
        self.normals
    }

    /// Changing the normals costs nothing: frames prepare them ([`IsoScene::prepare`]).
    pub fn set_normals(&mut self, normals: Normals) {
        self.normals = normals;
    }

    pub fn tree(&self) -> &KdTree<T> {
        &self.tree
    }

    pub fn frame(&self) -> &TraversalFrame {
        &self.frame
    }

    pub fn voxels(&self) -> &[T] {
        self.voxels.as_slice()
    }

    pub fn dims(&self) -> [usize; 3] {
        self.dims
    }

    /// Replaces all voxels (a new time step with the same dims): refit, not rebuild.
    pub fn replace_voxels(&mut self, voxels: VoxelBuffer<T>) -> Result<(), VolumeError> {
        let expected = self.dims.iter().product();
        if voxels.len() != expected {
            return Err(VolumeError::LengthMismatch {
                dims: self.dims,
                expected,
                actual: voxels.len(),
            });
        }
        self.voxels = voxels;
        let hi = self.dims.map(|d| d - 1);
        self.tree.refit_region(self.voxels.as_slice(), [0; 3], hi);
        Ok(())
    }

    /// Edits the voxels in place, then refits the nodes over the inclusive voxel box
    /// `[lo, hi]`, which must cover every voxel `edit` changes (thesis §7.6).
    pub fn edit_voxels(&mut self, lo: [usize; 3], hi: [usize; 3], edit: impl FnOnce(&mut [T])) {
        edit(self.voxels.make_mut());
        let hi = [0, 1, 2].map(|a| hi[a].min(self.dims[a] - 1));
        self.tree.refit_region(self.voxels.as_slice(), lo, hi);
    }

    /// New sample coordinates or orientation with the same dims: only the split tables
    /// change (thesis §7.6).
    pub fn set_grid(&mut self, grid: &Grid) -> Result<(), VolumeError> {
        if grid.dims() != self.dims {
            return Err(VolumeError::LengthMismatch {
                dims: grid.dims(),
                expected: grid.voxel_count(),
                actual: self.voxels.len(),
            });
        }
        self.frame = TraversalFrame::new(grid);
        self.tree.set_coordinates(&self.frame);
        Ok(())
    }

    /// Tree bytes (see [`KdTree::memory_bytes`]).
    pub fn memory_bytes(&self) -> usize {
        self.tree.memory_bytes()
    }

    /// Tree bytes per voxel byte.
    pub fn memory_ratio(&self) -> f64 {
        self.tree.memory_ratio()
    }

    pub fn build_time(&self) -> Duration {
        self.tree.build_time()
    }

    /// The brute-force 3D-DDA twin over the same cells and intersector.
    pub fn dda(&self) -> DdaScene<'_, T> {
        DdaScene::new(
            &self.frame,
            self.voxels.as_slice(),
            self.dims,
            self.intersector,
        )
        .with_value_map(self.value_map)
    }

    /// The kd-tree hit in traversal terms, with a static intersector.
    #[inline]
    pub fn cell_hit_with<C: CellIntersector, S: Stats>(
        &self,
        ray: &LocalRay,
        t_min: f32,
        t_max: f32,
        isos: &IsoSet<T>,
        intersector: C,
        stats: &mut S,
    ) -> Option<CellHit> {
        if ray.dir == Vec3::ZERO {
            return None;
        }
        let (t0, t1) = self.frame.clip(ray, t_min, t_max)?;
        self.tree.first_hit(
            &self.frame,
            self.voxels.as_slice(),
            ray,
            t0,
            t1,
            isos,
            intersector,
            stats,
        )
    }

    /// The gradient magnitude of this scene's field at hit positions (colouring).
    pub fn gradient_field(&self) -> GridField<'_, T> {
        GridField::new(
            &self.frame,
            self.voxels.as_slice(),
            self.dims,
            self.value_map,
            GridQuantity::GradientMagnitude,
        )
        .expect("the scene's voxels match its grid")
    }

    /// The grid as the block every hit lies in.
    fn block(&self) -> CellBlock<'_, T> {
        CellBlock {
            frame: &self.frame,
            voxels: self.voxels.as_slice(),
            dims: self.dims,
        }
    }
}

impl<T: Voxel> CellTrace<T> for GridScene<T> {
    type Isovalues = IsoSet<T>;

    fn frame(&self) -> &TraversalFrame {
        &self.frame
    }

    fn normals(isos: &Self::Isovalues) -> Option<Normals> {
        isos.normals()
    }

    #[inline]
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
        Some((h, self.block()))
    }

    #[inline]
    fn cell_hits_packet<'s, C: CellIntersector, S: Stats>(
        &'s self,
        rays: &[LocalRay],
        t0: &[f32],
        t1: &[f32],
        isos: &IsoSet<T>,
        intersector: C,
        stats: &mut S,
        out: &mut [Option<(CellHit, CellBlock<'s, T>)>],
    ) {
        let mut hits = [None; PACKET_WIDTH];
        let n = rays.len().min(PACKET_WIDTH);
        with_packet_stack(|stack| {
            self.tree.first_hit_packet_in(
                stack,
                &self.frame,
                self.voxels.as_slice(),
                rays,
                t0,
                t1,
                isos,
                intersector,
                stats,
                &mut hits[..n],
            );
        });
        let block = self.block();
        for (o, h) in out.iter_mut().zip(&hits[..n]) {
            *o = h.map(|h| (h, block));
        }
    }
}

impl<T: Voxel> IsoScene for GridScene<T> {
    type Isovalues = IsoSet<T>;

    fn prepare(&self, isovalues: &[f32]) -> IsoSet<T> {
        IsoSet::mapped(isovalues, self.value_map).with_normals(self.normals)
    }

    fn prepare_distances(&self, isovalues: &[f32]) -> IsoSet<T> {
        self.prepare(isovalues).without_normals()
    }

    fn world_bounds(&self) -> Aabb {
        self.frame.world_bounds()
    }

    /// The world box of [`KdTree::live_cell_box`], a cell wider on every side
    /// ([`TraversalFrame::world_bounds_of_cells`]).
    fn live_bounds(&self, isos: &IsoSet<T>) -> Aabb {
        match self.tree.live_cell_box(isos) {
            Some([lo, hi]) => self.frame.world_bounds_of_cells(lo, hi),
            None => Aabb::EMPTY,
        }
    }

    /// The world boxes of the live nodes of [`KdTree::live_cell_boxes`] at
    /// [`LIVE_COVER_NODES`], each a cell wider on every side.
    fn live_boxes(&self, isos: &IsoSet<T>, out: &mut Vec<Aabb>) {
        self.tree
            .live_cell_boxes(isos, LIVE_COVER_NODES, |[lo, hi]| {
                out.push(self.frame.world_bounds_of_cells(lo, hi));
            });
    }

    #[inline]
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

    fn first_hit_packet_prepared<S: Stats>(
        &self,
        rays: &[Ray],
        t_min: &[f32],
        t_max: &[f32],
        isos: &IsoSet<T>,
        out: &mut [Option<Hit>],
        stats: &mut S,
    ) {
        crate::dispatch_intersector!(self.intersector, c => {
            for (start, chunk) in rays.chunks(PACKET_WIDTH).enumerate() {
                let base = start * PACKET_WIDTH;
                first_hits_packet_with(self, chunk, &t_min[base..], &t_max[base..], isos, c, &mut out[base..], stats);
            }
        });
    }

    /// Shadow rays in packets that end each lane at its first hit found and refine no
    /// certain crossing ([`KdTree::any_hit_packet_in`]); no hit point or normal is made.
    fn occluded_packet_prepared<S: Stats>(
        &self,
        rays: &[Ray],
        t_min: &[f32],
        t_max: &[f32],
        isos: &IsoSet<T>,
        out: &mut [bool],
        stats: &mut S,
    ) {
        crate::dispatch_intersector!(self.intersector, c => {
            for (start, chunk) in rays.chunks(PACKET_WIDTH).enumerate() {
                let base = start * PACKET_WIDTH;
                self.occluded_packet(chunk, &t_min[base..], &t_max[base..], isos, c, &mut out[base..], stats);
            }
        });
    }

    /// The packets go on past transparent hits: a lane that hits a transparent layer has
    /// its cell tested again from [`Peel::next_t`] and walks on with its packet through the
    /// cells that follow ([`KdTree`]'s packet walk), instead of a new ray descending from
    /// the root. The layers are the ones new rays would find (tested).
    fn peeled_hits_packet_prepared<S: Stats>(
        &self,
        rays: &[Ray],
        t_min: &[f32],
        t_max: &[f32],
        isos: &IsoSet<T>,
        peel: &Peel,
        out: &mut [PeeledHits],
        stats: &mut S,
    ) {
        crate::dispatch_intersector!(self.intersector, c => {
            for (start, chunk) in rays.chunks(PACKET_WIDTH).enumerate() {
                let base = start * PACKET_WIDTH;
                self.peeled_packet(chunk, &t_min[base..], &t_max[base..], isos, c, peel, &mut out[base..], stats);
            }
        });
    }
}

impl<T: Voxel> GridScene<T> {
    /// [`IsoScene::occluded_packet_prepared`] for up to [`PACKET_WIDTH`] rays with a static
    /// intersector; rays that cannot travel as one packet go as groups of 8 or one by one,
    /// as in [`first_hits_packet_with`].
    #[allow(clippy::too_many_arguments)]
    fn occluded_packet<C: CellIntersector, S: Stats>(
        &self,
        rays: &[Ray],
        t_min: &[f32],
        t_max: &[f32],
        isos: &IsoSet<T>,
        intersector: C,
        out: &mut [bool],
        stats: &mut S,
    ) {
        let lp = LocalPacket::new(&self.frame, rays, t_min, t_max);
        let (n, local, t0, t1) = (lp.n, &lp.local, &lp.t0, &lp.t1);
        for _ in 0..n {
            stats.ray();
        }
        let voxels = self.voxels.as_slice();
        lp.for_each_group(
            &mut (out, stats),
            |(out, stats), from, to| {
                with_packet_stack(|stack| {
                    self.tree.any_hit_packet_in(
                        stack,
                        &self.frame,
                        voxels,
                        &local[from..to],
                        &t0[from..to],
                        &t1[from..to],
                        isos,
                        intersector,
                        *stats,
                        &mut out[from..to],
                    );
                });
            },
            |(out, stats), i| {
                out[i] = t0[i] <= t1[i]
                    && self
                        .cell_hit_with(&local[i], t0[i], t1[i], isos, intersector, *stats)
                        .is_some();
            },
        );
    }

    /// [`IsoScene::peeled_hits_packet_prepared`] for up to [`PACKET_WIDTH`] rays with a
    /// static intersector; rays that cannot travel as one packet go as groups of 8 or one by
    /// one, as in [`first_hits_packet_with`].
    #[allow(clippy::too_many_arguments)]
    fn peeled_packet<C: CellIntersector, S: Stats>(
        &self,
        rays: &[Ray],
        t_min: &[f32],
        t_max: &[f32],
        isos: &IsoSet<T>,
        intersector: C,
        peel: &Peel,
        out: &mut [PeeledHits],
        stats: &mut S,
    ) {
        let lp = LocalPacket::new(&self.frame, rays, t_min, t_max);
        let (n, local, t0, t1) = (lp.n, &lp.local, &lp.t0, &lp.t1);
        for _ in 0..n {
            stats.ray();
        }
        let mut layers = LaneLayers::new(peel);
        let voxels = self.voxels.as_slice();
        lp.for_each_group(
            &mut (&mut layers, stats),
            |(layers, stats), from, to| {
                with_packet_stack(|stack| {
                    self.tree.walk_packet_in(
                        stack,
                        &self.frame,
                        voxels,
                        &local[from..to],
                        &t0[from..to],
                        &t1[from..to],
                        isos,
                        intersector,
                        *stats,
                        // Hits on opaque surfaces end their lane (`LaneLayers::add`).
                        peel.opaque,
                        WalkFor::Hits,
                        |k, hit| layers.add(from + k, hit),
                    );
                });
            },
            // One by one: the ray again from past each transparent layer.
            |(layers, stats), i| {
                ray_go_on(
                    t0[i],
                    t1[i],
                    |t| self.cell_hit_with(&local[i], t, t1[i], isos, intersector, *stats),
                    |h| layers.add(i, h),
                );
            },
        );
        // Every lane's layers, in lane order, get their hits together.
        let mut lanes = [0usize; PACKET_WIDTH * MAX_PEELED];
        let mut hits = [CellHit::NONE; PACKET_WIDTH * MAX_PEELED];
        let mut m = 0;
        for (i, o) in out[..n].iter_mut().enumerate() {
            *o = PeeledHits::NONE;
            o.more = layers.more(i);
            for &h in layers.of(i) {
                (lanes[m], hits[m]) = (i, h);
                m += 1;
            }
        }
        let (lanes, hits) = (&lanes[..m], &hits[..m]);
        make_hits_in_block(
            &self.block(),
            local,
            rays,
            lanes,
            hits,
            isos.normals(),
            |j, hit| {
                out[lanes[j]].push(hit);
            },
        );
    }
}

crate::voxel_enum! {
    /// A [`GridScene`] of whichever voxel type the volume has.
    #[derive(Debug, Clone)]
    pub enum AnyGridScene(GridScene)
}

/// Runs `$body` with `$s` bound to the typed [`GridScene`] inside an [`AnyGridScene`]
/// ([`crate::match_voxel!`] for `AnyGridScene`).
#[macro_export]
macro_rules! dispatch_grid_scene {
    ($scene:expr, $s:ident => $body:expr) => {
        $crate::match_voxel!($crate::grid::AnyGridScene, $scene, $s => $body)
    };
}

/// What [`AnyGridScene::update_volume`] did for a new time step.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StepSwitch {
    /// Same dims and voxel type: the tree was refit in place (thesis §7.6) and the split
    /// tables recomputed.
    Refit,
    /// Other dims or voxel type: the scene was rebuilt.
    Rebuild,
}

impl AnyGridScene {
    /// Builds the scene for `volume` with the default tree layout.
    pub fn new(volume: &RectilinearVolume, intersector: Intersector) -> Self {
        Self::with_config(volume, intersector, KdTreeConfig::default())
    }

    pub fn with_config(
        volume: &RectilinearVolume,
        intersector: Intersector,
        config: KdTreeConfig,
    ) -> Self {
        let g = &volume.grid;
        // Lengths were checked when the volume was made.
        let map = volume.value_map;
        crate::dispatch_voxels!(&volume.data, b => {
            let mut s = GridScene::new(g, b.clone(), intersector, config)
                .expect("volume length checked");
            s.set_value_map(map);
            s.into()
        })
    }

    pub fn intersector(&self) -> Intersector {
        dispatch_grid_scene!(self, s => s.intersector())
    }

    /// Changing the intersector costs nothing (no rebuild).
    pub fn set_intersector(&mut self, intersector: Intersector) {
        dispatch_grid_scene!(self, s => s.set_intersector(intersector));
    }

    pub fn normals(&self) -> Normals {
        dispatch_grid_scene!(self, s => s.normals())
    }

    /// Changing the normals costs nothing (no rebuild).
    pub fn set_normals(&mut self, normals: Normals) {
        dispatch_grid_scene!(self, s => s.set_normals(normals));
    }

    pub fn memory_bytes(&self) -> usize {
        dispatch_grid_scene!(self, s => s.memory_bytes())
    }

    pub fn memory_ratio(&self) -> f64 {
        dispatch_grid_scene!(self, s => s.memory_ratio())
    }

    pub fn build_time(&self) -> Duration {
        dispatch_grid_scene!(self, s => s.build_time())
    }

    pub fn dims(&self) -> [usize; 3] {
        dispatch_grid_scene!(self, s => s.dims())
    }

    /// Switches to another volume (a time step). Same dims and voxel type: the tree is
    /// refit (thesis §7.6) and the split tables are recomputed; otherwise it is rebuilt.
    pub fn update_volume(&mut self, volume: &RectilinearVolume) -> StepSwitch {
        let same_dims = volume.dims() == self.dims();
        // Same dims: the lengths match, so replacing the voxels and the grid cannot fail.
        let refit = same_dims
            && crate::match_voxel!(
                AnyGridScene, &mut *self, s; VoxelData, &volume.data, b => {
                    s.set_value_map(volume.value_map);
                    s.replace_voxels(b.clone()).is_ok() && s.set_grid(&volume.grid).is_ok()
                };
                else false
            );
        if refit {
            StepSwitch::Refit
        } else {
            let normals = self.normals();
            *self = Self::new(volume, self.intersector());
            self.set_normals(normals);
            StepSwitch::Rebuild
        }
    }

    /// The gradient magnitude of the scene's field at hit positions, for colouring
    /// ([`GridScene::gradient_field`]).
    pub fn gradient_field(&self) -> Box<dyn HitField + '_> {
        dispatch_grid_scene!(self, s => Box::new(s.gradient_field()) as Box<dyn HitField + '_>)
    }

    /// The range of the gradient magnitude over the samples (scans every voxel, in
    /// parallel); `None` without a finite one.
    pub fn gradient_magnitude_range(&self) -> Option<(f64, f64)> {
        dispatch_grid_scene!(self, s => gradient_magnitude_range(
            &s.frame, s.voxels.as_slice(), s.dims, s.value_map
        ))
    }

    /// Hands the typed kd-tree scene to `visitor` (monomorphized traversal).
    pub fn visit<V: SceneVisitor>(&self, visitor: V) -> V::Output {
        dispatch_grid_scene!(self, s => visitor.visit(s))
    }

    /// Hands the typed brute-force DDA twin to `visitor`.
    pub fn visit_dda<V: SceneVisitor>(&self, visitor: V) -> V::Output {
        dispatch_grid_scene!(self, s => visitor.visit(&s.dda()))
    }
}

crate::voxel_enum! {
    /// The active isovalues prepared for an [`AnyGridScene`]: the [`IsoSet`] of its voxel
    /// type.
    #[derive(Debug, Clone)]
    pub enum AnyIsoSet(IsoSet)
}

/// Isovalues handed to a scene other than the one that prepared them.
#[cold]
fn isovalues_of_another_type() -> ! {
    panic!("isovalues prepared by an AnyGridScene of another voxel type")
}

impl IsoScene for AnyGridScene {
    type Isovalues = AnyIsoSet;

    fn prepare(&self, isovalues: &[f32]) -> AnyIsoSet {
        dispatch_grid_scene!(self, s => s.prepare(isovalues).into())
    }

    fn prepare_distances(&self, isovalues: &[f32]) -> AnyIsoSet {
        dispatch_grid_scene!(self, s => s.prepare_distances(isovalues).into())
    }

    fn world_bounds(&self) -> Aabb {
        dispatch_grid_scene!(self, s => s.world_bounds())
    }

    fn live_bounds(&self, isos: &AnyIsoSet) -> Aabb {
        crate::match_voxel!(AnyGridScene, self, s; AnyIsoSet, isos, i => {
            s.live_bounds(i)
        }; else isovalues_of_another_type())
    }

    fn live_boxes(&self, isos: &AnyIsoSet, out: &mut Vec<Aabb>) {
        crate::match_voxel!(AnyGridScene, self, s; AnyIsoSet, isos, i => {
            s.live_boxes(i, out);
        }; else isovalues_of_another_type());
    }

    #[inline]
    fn first_hit_prepared<S: Stats>(
        &self,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
        isos: &AnyIsoSet,
        stats: &mut S,
    ) -> Option<Hit> {
        crate::match_voxel!(AnyGridScene, self, s; AnyIsoSet, isos, i => {
            s.first_hit_prepared(ray, t_min, t_max, i, stats)
        }; else isovalues_of_another_type())
    }

    fn first_hit_packet_prepared<S: Stats>(
        &self,
        rays: &[Ray],
        t_min: &[f32],
        t_max: &[f32],
        isos: &AnyIsoSet,
        out: &mut [Option<Hit>],
        stats: &mut S,
    ) {
        crate::match_voxel!(AnyGridScene, self, s; AnyIsoSet, isos, i => {
            s.first_hit_packet_prepared(rays, t_min, t_max, i, out, stats);
        }; else isovalues_of_another_type());
    }

    fn occluded_packet_prepared<S: Stats>(
        &self,
        rays: &[Ray],
        t_min: &[f32],
        t_max: &[f32],
        isos: &AnyIsoSet,
        out: &mut [bool],
        stats: &mut S,
    ) {
        crate::match_voxel!(AnyGridScene, self, s; AnyIsoSet, isos, i => {
            s.occluded_packet_prepared(rays, t_min, t_max, i, out, stats);
        }; else isovalues_of_another_type());
    }

    fn peeled_hits_packet_prepared<S: Stats>(
        &self,
        rays: &[Ray],
        t_min: &[f32],
        t_max: &[f32],
        isos: &AnyIsoSet,
        peel: &Peel,
        out: &mut [PeeledHits],
        stats: &mut S,
    ) {
        crate::match_voxel!(AnyGridScene, self, s; AnyIsoSet, isos, i => {
            s.peeled_hits_packet_prepared(rays, t_min, t_max, i, peel, out, stats);
        }; else isovalues_of_another_type());
    }
}
