//! The contract between acceleration structures and the renderer.
//!
//! One renderer, several acceleration structures: the implicit min/max kd-tree over a
//! rectilinear grid (thesis ch. 7) and the implicit min/max BVH over tetrahedra (ch. 8) both
//! implement [`IsoScene`]. The renderer is generic over the scene, so the traversal loop is
//! monomorphized: no dynamic dispatch per node or per ray.
//!
//! Statistics are gathered through a [`Stats`] type parameter. [`NoStats`] compiles every
//! counter away, so statistics cost nothing when they are off.

use glam::Vec3;

use crate::math::{Aabb, Ray};

/// Shading normals of hits. Both are gradients of the data's interpolant; they differ in
/// where the gradient is taken.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Normals {
    /// The gradient of the hit cell's own interpolant: the exact normal of the surface drawn,
    /// which turns at cell faces. A tet's isopolygon plane (the data as computed, thesis
    /// seed 004 §8.6; meshes' default); a grid cell's trilinear surface.
    Faceted,
    /// Gradients at the vertices, interpolated to the hit: continuous across cells. Tets:
    /// `M = N·V⁻¹` (§8.3); grids: central differences at the cell's corners, blended
    /// trilinearly (§6.4; grids' default).
    Smooth,
}

impl Normals {
    /// The name the command line and the Python package take (`faceted`, `smooth`).
    pub fn name(self) -> &'static str {
        match self {
            Self::Faceted => "faceted",
            Self::Smooth => "smooth",
        }
    }
}

/// The first intersection of a ray with one of the active isosurfaces.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Hit {
    /// Ray parameter of the hit (world units along a unit-length world direction).
    pub t: f32,
    /// Index into the isovalue list of the surface that was hit.
    pub surface: u32,
    /// World-space unit normal (orientation unspecified; shading is two-sided).
    pub normal: Vec3,
    /// The primitive holding the hit in the scene's own numbering, for colouring by another
    /// field ([`HitField`]): a tet mesh's tet in BVH leaf order; 0 for scenes that locate
    /// hits by position (grids).
    pub cell: u32,
}

/// A field the renderer samples at shaded hits to colour a surface (one call per shaded
/// hit, none during traversal).
pub trait HitField: Sync {
    /// The field's value at the world position `p` of a hit in primitive `cell`
    /// ([`Hit::cell`]); NaN where the field has none (the surface's flat colour is drawn).
    fn value_at(&self, p: Vec3, cell: u32) -> f32;
}

/// Counters in the spirit of thesis Tables 7.1 and 8.4.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct TraversalCounts {
    pub rays: u64,
    pub nodes_visited: u64,
    pub leaves_visited: u64,
    pub box_tests: u64,
    pub intersection_tests: u64,
    pub polygon_extractions: u64,
}

impl TraversalCounts {
    pub fn add(&mut self, o: &TraversalCounts) {
        self.rays += o.rays;
        self.nodes_visited += o.nodes_visited;
        self.leaves_visited += o.leaves_visited;
        self.box_tests += o.box_tests;
        self.intersection_tests += o.intersection_tests;
        self.polygon_extractions += o.polygon_extractions;
    }
}

/// A sink for traversal statistics; [`NoStats`] makes every call a no-op.
pub trait Stats: Default + Send {
    const ENABLED: bool;
    fn ray(&mut self) {}
    fn node(&mut self) {}
    fn leaf(&mut self) {}
    fn box_test(&mut self, _n: u64) {}
    fn intersection(&mut self) {}
    fn extraction(&mut self) {}
    fn counts(&self) -> TraversalCounts {
        TraversalCounts::default()
    }
    fn merge(&mut self, _o: &Self) {}
}

/// Statistics off: zero cost.
#[derive(Debug, Clone, Copy, Default)]
pub struct NoStats;

impl Stats for NoStats {
    const ENABLED: bool = false;
}

/// Statistics on: plain counters.
#[derive(Debug, Clone, Copy, Default)]
pub struct CountStats(pub TraversalCounts);

impl Stats for CountStats {
    const ENABLED: bool = true;
    #[inline]
    fn ray(&mut self) {
        self.0.rays += 1;
    }
    #[inline]
    fn node(&mut self) {
        self.0.nodes_visited += 1;
    }
    #[inline]
    fn leaf(&mut self) {
        self.0.leaves_visited += 1;
    }
    #[inline]
    fn box_test(&mut self, n: u64) {
        self.0.box_tests += n;
    }
    #[inline]
    fn intersection(&mut self) {
        self.0.intersection_tests += 1;
    }
    #[inline]
    fn extraction(&mut self) {
        self.0.polygon_extractions += 1;
    }
    fn counts(&self) -> TraversalCounts {
        self.0
    }
    fn merge(&mut self, o: &Self) {
        self.0.add(&o.0);
    }
}

/// Most hits one call of [`IsoScene::peeled_hits_packet_prepared`] returns per ray.
pub const MAX_PEELED: usize = 4;

/// How a ray goes on past transparent hits ("transparent depth peeling", thesis seed 004
/// §8.6): the next layer is the first hit from [`Peel::next_t`] of the last one on, and a
/// hit on an opaque surface ends the ray.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Peel {
    /// Bit `s` set: a hit on isovalue `s` ends the ray. Isovalues from 64 on never do here
    /// (the caller drops layers past where its compositing ends the ray).
    pub opaque: u64,
    /// Hits per ray and call, 1 to [`MAX_PEELED`].
    pub max_hits: u32,
    /// Absolute part of the distance past a hit where the next is sought (a part relative
    /// to `t` is added, [`Peel::next_t`]).
    pub eps: f32,
}

impl Peel {
    /// Where the search for the next layer starts after a hit at `t`: far enough past it
    /// that the same crossing, found again with `f32` rounding, is not taken twice.
    #[inline]
    pub fn next_t(&self, t: f32) -> f32 {
        t + self.eps + t.abs() * 1e-6
    }

    /// Whether a hit on isovalue `surface` ends the ray.
    #[inline]
    pub fn ends_ray(&self, surface: u32) -> bool {
        surface < 64 && self.opaque >> surface & 1 == 1
    }

    pub(crate) fn cap(&self) -> usize {
        (self.max_hits as usize).clamp(1, MAX_PEELED)
    }
}

/// A ray's hits from one call of [`IsoScene::peeled_hits_packet_prepared`], front to back.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PeeledHits {
    /// How many of `hits` are set.
    pub n: u32,
    pub hits: [Hit; MAX_PEELED],
    /// The ray may hit more past the last hit (the caller asks again from its
    /// [`Peel::next_t`]); false when the last hit ends the ray or nothing is left in the
    /// interval.
    pub more: bool,
}

impl PeeledHits {
    pub const NONE: Self = Self {
        n: 0,
        hits: [Hit {
            t: f32::INFINITY,
            surface: 0,
            normal: Vec3::Z,
            cell: 0,
        }; MAX_PEELED],
        more: false,
    };

    /// The hits that are set.
    pub fn hits(&self) -> &[Hit] {
        &self.hits[..self.n as usize]
    }

    /// Sets these to a first-hit search's result: `hit` alone, with more to come past it
    /// unless it ends the ray.
    #[inline]
    pub fn set_first(&mut self, hit: Option<Hit>, peel: &Peel) {
        self.n = u32::from(hit.is_some());
        self.more = false;
        if let Some(h) = hit {
            self.hits[0] = h;
            self.more = !peel.ends_ray(h.surface);
        }
    }

    /// Appends `hit` (the caller keeps them in order and within [`MAX_PEELED`]).
    #[inline]
    pub fn push(&mut self, hit: Hit) {
        self.hits[self.n as usize] = hit;
        self.n += 1;
    }
}

/// Something the renderer can shoot rays at: the isosurfaces of a volume.
///
/// All rays and bounds are in world space. The active isovalues (any number) are prepared
/// once per frame or render call ([`IsoScene::prepare`]: converted to the voxel type,
/// quantized, ...; as Open VKL's hit-iterator context) and handed to every ray of it; the
/// first hit of any of them along `[t_min, t_max]` wins. Implementations must be
/// conservative: a hit the f64 reference finds inside `[t_min, t_max]` is not lost to
/// rounding.
///
/// [`IsoScene::first_hit`], [`IsoScene::occluded`] and [`IsoScene::first_hit_packet`] take
/// the plain isovalue list and prepare it for that one call (tests, single rays).
pub trait IsoScene: Sync {
    /// The active isovalues in the form this scene's traversal reads them.
    type Isovalues: Sync;

    /// Prepares the list of active isovalues for traversal.
    fn prepare(&self, isovalues: &[f32]) -> Self::Isovalues;

    /// Prepares the isovalues for a frame that reads only where rays hit (distance and
    /// surface, [`crate::render::RenderSettings::depth_only`]): the scene may skip the
    /// shading normal, and the hits' normals are then any unit vector. Defaults to
    /// [`IsoScene::prepare`]; grids skip the central-difference gradient.
    fn prepare_distances(&self, isovalues: &[f32]) -> Self::Isovalues {
        self.prepare(isovalues)
    }

    /// World-space bounds of the data.
    fn world_bounds(&self) -> Aabb;

    /// World-space bounds outside which no hit of the prepared isovalues lies (empty when
    /// there is none); the renderer clips its rays to them, so rays passing beside the
    /// surfaces are never traced. Defaults to [`IsoScene::world_bounds`]; scenes whose
    /// acceleration structure knows where the isovalues can be tighten them.
    fn live_bounds(&self, isos: &Self::Isovalues) -> Aabb {
        let _ = isos;
        self.world_bounds()
    }

    /// World boxes outside all of which no hit of the prepared isovalues lies, pushed onto
    /// `out`: the renderer projects them and makes no ray for a pixel that sees none of them
    /// (`render::coverage`). Defaults to [`IsoScene::live_bounds`] alone; scenes that know
    /// where the isovalues can be give several smaller boxes.
    fn live_boxes(&self, isos: &Self::Isovalues, out: &mut Vec<Aabb>) {
        out.push(self.live_bounds(isos));
    }

    /// First hit along the ray in `[t_min, t_max]`.
    fn first_hit_prepared<S: Stats>(
        &self,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
        isos: &Self::Isovalues,
        stats: &mut S,
    ) -> Option<Hit>;

    /// Any hit in `[t_min, t_max]` (shadow rays). Defaults to `first_hit_prepared`.
    fn occluded_prepared<S: Stats>(
        &self,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
        isos: &Self::Isovalues,
        stats: &mut S,
    ) -> bool {
        self.first_hit_prepared(ray, t_min, t_max, isos, stats)
            .is_some()
    }

    /// First hits for a coherent packet of rays sharing `[t_min[i], t_max[i]]`, written to
    /// every `out[i]` (`None` for a miss: the renderer does not clear `out` first).
    ///
    /// Structures with packet traversal (SIMD kd-tree packets, 16×16 BVH frusta) override
    /// this; the default traces the rays one by one.
    fn first_hit_packet_prepared<S: Stats>(
        &self,
        rays: &[Ray],
        t_min: &[f32],
        t_max: &[f32],
        isos: &Self::Isovalues,
        out: &mut [Option<Hit>],
        stats: &mut S,
    ) {
        for (i, ray) in rays.iter().enumerate() {
            out[i] = self.first_hit_prepared(ray, t_min[i], t_max[i], isos, stats);
        }
    }

    /// Whether each ray has a hit in `[t_min[i], t_max[i]]` (shadow rays), written to
    /// `out[i]`: where is not asked, so no root need be refined and no normal made.
    ///
    /// The default takes [`IsoScene::first_hit_packet_prepared`]'s hits; the kd-tree
    /// packets override it.
    fn occluded_packet_prepared<S: Stats>(
        &self,
        rays: &[Ray],
        t_min: &[f32],
        t_max: &[f32],
        isos: &Self::Isovalues,
        out: &mut [bool],
        stats: &mut S,
    ) {
        first_hits_in_chunks(self, rays, t_min, t_max, isos, stats, |i, h| {
            out[i] = h.is_some();
        });
    }

    /// For each ray, its layers as the renderer peels them: the first hit in
    /// `[t_min[i], t_max[i]]`, then the first from [`Peel::next_t`] of the previous one on,
    /// until a hit ends the ray ([`Peel::ends_ray`]), `peel.max_hits` are found or none is
    /// left; written to every `out[i]`.
    ///
    /// The default returns each ray's first hit only ([`IsoScene::first_hit_packet_prepared`],
    /// [`PeeledHits::more`] set after a transparent one), so the caller shoots again from
    /// past it. Scenes whose traversal can go on past a hit override this: the kd-tree
    /// packets carry their rays on through the cells that follow, instead of new rays
    /// descending from the root.
    fn peeled_hits_packet_prepared<S: Stats>(
        &self,
        rays: &[Ray],
        t_min: &[f32],
        t_max: &[f32],
        isos: &Self::Isovalues,
        peel: &Peel,
        out: &mut [PeeledHits],
        stats: &mut S,
    ) {
        first_hits_in_chunks(self, rays, t_min, t_max, isos, stats, |i, h| {
            out[i].set_first(h, peel);
        });
    }

    /// [`IsoScene::first_hit_prepared`] of `isovalues` prepared for this ray only.
    fn first_hit<S: Stats>(
        &self,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
        isovalues: &[f32],
        stats: &mut S,
    ) -> Option<Hit> {
        self.first_hit_prepared(ray, t_min, t_max, &self.prepare(isovalues), stats)
    }

    /// [`IsoScene::occluded_prepared`] of `isovalues` prepared for this ray only.
    fn occluded<S: Stats>(
        &self,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
        isovalues: &[f32],
        stats: &mut S,
    ) -> bool {
        self.occluded_prepared(ray, t_min, t_max, &self.prepare(isovalues), stats)
    }

    /// [`IsoScene::first_hit_packet_prepared`] of `isovalues` prepared for these rays only.
    fn first_hit_packet<S: Stats>(
        &self,
        rays: &[Ray],
        t_min: &[f32],
        t_max: &[f32],
        isovalues: &[f32],
        out: &mut [Option<Hit>],
        stats: &mut S,
    ) {
        let isos = self.prepare(isovalues);
        self.first_hit_packet_prepared(rays, t_min, t_max, &isos, out, stats);
    }
}

/// `scene`'s first hits of `rays` ([`IsoScene::first_hit_packet_prepared`]), handed to
/// `each(i, hit)`, in chunks of as many rays as a renderer tile has, so structures with
/// large packets (16×16 BVH frusta) keep them.
fn first_hits_in_chunks<Sc: IsoScene + ?Sized, S: Stats>(
    scene: &Sc,
    rays: &[Ray],
    t_min: &[f32],
    t_max: &[f32],
    isos: &Sc::Isovalues,
    stats: &mut S,
    mut each: impl FnMut(usize, Option<Hit>),
) {
    const CHUNK: usize = 256;
    let mut hits = [None; CHUNK];
    for (c, chunk) in rays.chunks(CHUNK).enumerate() {
        let base = c * CHUNK;
        let m = chunk.len();
        scene.first_hit_packet_prepared(
            chunk,
            &t_min[base..base + m],
            &t_max[base..base + m],
            isos,
            &mut hits[..m],
            stats,
        );
        for (j, &h) in hits[..m].iter().enumerate() {
            each(base + j, h);
        }
    }
}

/// A scene with its live bounds widened to the data's bounds ([`IsoScene::live_bounds`] left
/// at its default), everything else delegated: the twin that tests compare frames cut to
/// the live bounds against.
pub struct WholeBounds<'a, S>(pub &'a S);

impl<S: IsoScene> IsoScene for WholeBounds<'_, S> {
    type Isovalues = S::Isovalues;

    fn prepare(&self, isovalues: &[f32]) -> S::Isovalues {
        self.0.prepare(isovalues)
    }

    fn prepare_distances(&self, isovalues: &[f32]) -> S::Isovalues {
        self.0.prepare_distances(isovalues)
    }

    fn world_bounds(&self) -> Aabb {
        self.0.world_bounds()
    }

    fn first_hit_prepared<St: Stats>(
        &self,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
        isos: &S::Isovalues,
        stats: &mut St,
    ) -> Option<Hit> {
        self.0.first_hit_prepared(ray, t_min, t_max, isos, stats)
    }

    fn occluded_prepared<St: Stats>(
        &self,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
        isos: &S::Isovalues,
        stats: &mut St,
    ) -> bool {
        self.0.occluded_prepared(ray, t_min, t_max, isos, stats)
    }

    fn first_hit_packet_prepared<St: Stats>(
        &self,
        rays: &[Ray],
        t_min: &[f32],
        t_max: &[f32],
        isos: &S::Isovalues,
        out: &mut [Option<Hit>],
        stats: &mut St,
    ) {
        self.0
            .first_hit_packet_prepared(rays, t_min, t_max, isos, out, stats);
    }

    fn occluded_packet_prepared<St: Stats>(
        &self,
        rays: &[Ray],
        t_min: &[f32],
        t_max: &[f32],
        isos: &S::Isovalues,
        out: &mut [bool],
        stats: &mut St,
    ) {
        self.0
            .occluded_packet_prepared(rays, t_min, t_max, isos, out, stats);
    }

    fn peeled_hits_packet_prepared<St: Stats>(
        &self,
        rays: &[Ray],
        t_min: &[f32],
        t_max: &[f32],
        isos: &S::Isovalues,
        peel: &Peel,
        out: &mut [PeeledHits],
        stats: &mut St,
    ) {
        self.0
            .peeled_hits_packet_prepared(rays, t_min, t_max, isos, peel, out, stats);
    }
}

/// Receives a concretely typed scene from a holder of one of several types
/// ([`crate::grid::AnyGridScene::visit`], [`crate::ooc::AnyOocVolume::visit_scene`]), so
/// the code it runs is monomorphized for that scene.
pub trait SceneVisitor {
    type Output;
    fn visit<S: IsoScene>(self, scene: &S) -> Self::Output;
}
