//! [`TetScene`]: a tetrahedral mesh, one of its point fields and the implicit BVH, behind the
//! renderer's [`IsoScene`] contract (thesis 004 ch. 8).
//!
//! - Hits report `t`, the isovalue index and a unit normal: by default the *faceted* normal
//!   of the isopolygon (the data "as computed", §8.6); with [`Normals::Smooth`] the
//!   normal interpolated by the per-tet matrix `M = N·V⁻¹` (§8.3), where `N` holds the
//!   vertex gradients (volume-weighted averages of the incident tets' gradients) and `V`
//!   the homogeneous vertex positions, so `M·(p, 1)` is the barycentric blend of the vertex
//!   gradients at `p`. Normals point towards increasing value.
//! - Time steps: [`TetScene::refit_scalars`] (values only: only the isoranges are refit)
//!   and [`TetScene::refit_positions`] (§8.5.2, parallel refit); a per-step BVH is just one
//!   `TetScene` per step (§8.5.1).
//! - Layout: tets in BVH leaf order and points renumbered by their first use there, so a
//!   leaf's vertex gathers share cache lines; everything that takes or gives points (time
//!   steps, [`TetScene::points`], colouring fields) keeps the input order.
//! - [`TetScene::brute_force_first_hit`] is the `f64` twin: every tet's isopolygon against
//!   the ray, no acceleration structure.
//!
//! Degenerate input never panics: tets with repeated points or zero volume give empty or
//! zero-area isopolygons, which the watertight test skips; inverted (negative-volume) tets
//! work like any other; a NaN value at any vertex makes the tet void (no surface there).

use glam::{DMat3, DMat4, DVec3, DVec4, Vec3, Vec4};
use rayon::prelude::*;

use super::bvh::{BvhInfo, BvhOptions, TetBvh};
use super::mesh::{TetError, TetMesh};
use super::mt;
use super::traverse::{MAX_PACKET, RawHit, RayLayers, TetView};
use crate::math::{Aabb, Ray, prefetch};
use crate::render::{Hit, HitField, IsoScene, Normals, Peel, PeeledHits, Stats};

/// A tetrahedral mesh ready for isosurface ray tracing (module docs).
#[derive(Debug, Clone)]
pub struct TetScene {
    /// Point position in `xyz`, the selected field's value in `w`, numbered in order of first
    /// use by the leaf-ordered tets (so a leaf's vertices share cache lines).
    pub(crate) verts: Vec<Vec4>,
    /// Tets in leaf order, indexing `verts`.
    pub(crate) tets: Vec<[u32; 4]>,
    /// `order[leaf_position] = index in the input tet list`.
    order: Vec<u32>,
    /// `point_order[vertex] = index in the input point list`.
    point_order: Vec<u32>,
    pub(crate) bvh: TetBvh,
    normals: Normals,
    /// Rows of `M` per tet (leaf order), only for smooth normals.
    normal_rows: Vec<[Vec4; 3]>,
    packet: usize,
    bounds: Aabb,
    /// Changes whenever the points, values or tets do (a new number from [`next_generation`]),
    /// so the traversal's leaf cache never serves polygons of an earlier state.
    generation: u64,
}

/// A number no scene state had before (process-wide).
fn next_generation() -> u64 {
    static NEXT: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(1);
    NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed)
}

fn check_points(points: &[[f32; 3]]) -> Result<(), TetError> {
    if points.len() > u32::MAX as usize {
        return Err(TetError::TooManyPoints {
            points: points.len(),
        });
    }
    match points.iter().position(|p| !p.iter().all(|c| c.is_finite())) {
        Some(point) => Err(TetError::NonFinitePoint {
            point,
            coords: points[point],
        }),
        None => Ok(()),
    }
}

impl TetScene {
    /// Builds the scene for the point field `field` of `mesh`.
    pub fn new(mesh: &TetMesh, field: &str, options: BvhOptions) -> Result<Self, TetError> {
        let values = &mesh.require_field(field)?.values;
        Self::from_parts(&mesh.points, mesh.tets.clone(), values, options)
    }

    /// Builds the scene from raw parts (validated like [`TetMesh::new`]; at least one tet).
    pub fn from_parts(
        points: &[[f32; 3]],
        tets: Vec<[u32; 4]>,
        values: &[f32],
        options: BvhOptions,
    ) -> Result<Self, TetError> {
        check_points(points)?;
        if values.len() != points.len() {
            return Err(TetError::StepLength {
                what: "scalar values",
                expected: points.len(),
                actual: values.len(),
            });
        }
        if tets.is_empty() {
            return Err(TetError::Empty);
        }
        let n = points.len();
        if let Some((cell, t)) = tets
            .iter()
            .enumerate()
            .find(|(_, t)| t.iter().any(|&i| i as usize >= n))
        {
            let index = t.iter().copied().find(|&i| i as usize >= n).unwrap_or(0);
            return Err(TetError::IndexOutOfRange {
                cell,
                index: u64::from(index),
                points: n,
            });
        }
        let verts: Vec<Vec4> = points
            .par_iter()
            .zip(values)
            .map(|(p, &v)| Vec4::new(p[0], p[1], p[2], v))
            .collect();
        let mut tets = tets;
        let (bvh, order) = TetBvh::build(&verts, &mut tets, options);
        let mut scene = Self {
            point_order: (0..verts.len() as u32).collect(),
            verts,
            tets,
            order,
            bvh,
            normals: Normals::Faceted,
            normal_rows: Vec::new(),
            packet: MAX_PACKET,
            bounds: Aabb::EMPTY,
            generation: next_generation(),
        };
        scene.renumber_points();
        scene.update_bounds();
        Ok(scene)
    }

    /// Renumbers the points in order of first use by the tets (leaf order; unused points
    /// last, in their order): the traversal's vertex gathers of one leaf, and of the leaves
    /// after it, then fall on few cache lines instead of all over the point array. Keeps
    /// `point_order` and the BVH (whose bounds do not depend on numbering) in step.
    fn renumber_points(&mut self) {
        const UNSEEN: u32 = u32::MAX;
        let mut new_of_old = vec![UNSEEN; self.verts.len()];
        let mut next = 0u32;
        for t in &mut self.tets {
            for i in t.iter_mut() {
                let n = &mut new_of_old[*i as usize];
                if *n == UNSEEN {
                    *n = next;
                    next += 1;
                }
                *i = *n;
            }
        }
        for n in new_of_old.iter_mut().filter(|n| **n == UNSEEN) {
            *n = next;
            next += 1;
        }
        let mut verts = vec![Vec4::ZERO; self.verts.len()];
        let mut point_order = vec![0u32; self.verts.len()];
        for (old, &new) in new_of_old.iter().enumerate() {
            verts[new as usize] = self.verts[old];
            point_order[new as usize] = self.point_order[old];
        }
        self.verts = verts;
        self.point_order = point_order;
        self.generation = next_generation();
    }

    fn update_bounds(&mut self) {
        let r = self.bvh.root();
        self.bounds = Aabb::new(r.lo.truncate(), r.hi.truncate());
    }

    /// Rebuilds the BVH from scratch (e.g. after large deformations), keeping the data.
    pub fn rebuild(&mut self, options: BvhOptions) {
        let mut tets = std::mem::take(&mut self.tets);
        let (bvh, order) = TetBvh::build(&self.verts, &mut tets, options);
        self.order = order.iter().map(|&i| self.order[i as usize]).collect();
        self.tets = tets;
        self.bvh = bvh;
        self.renumber_points();
        self.update_bounds();
        self.update_normals();
    }

    /// A new time step's scalars (same points): only the isoranges are refit (§8.5.2).
    pub fn refit_scalars(&mut self, values: &[f32]) -> Result<(), TetError> {
        if values.len() != self.verts.len() {
            return Err(TetError::StepLength {
                what: "scalar values",
                expected: self.verts.len(),
                actual: values.len(),
            });
        }
        self.verts
            .par_iter_mut()
            .zip(&self.point_order)
            .for_each(|(p, &i)| p.w = values[i as usize]);
        self.bvh.refit(&self.verts, &self.tets, true);
        self.generation = next_generation();
        self.update_normals();
        Ok(())
    }

    /// A new time step's point positions (same topology): full 4D refit (§8.5.2).
    pub fn refit_positions(&mut self, points: &[[f32; 3]]) -> Result<(), TetError> {
        if points.len() != self.verts.len() {
            return Err(TetError::StepLength {
                what: "point positions",
                expected: self.verts.len(),
                actual: points.len(),
            });
        }
        check_points(points)?;
        self.verts
            .par_iter_mut()
            .zip(&self.point_order)
            .for_each(|(p, &i)| {
                let q = points[i as usize];
                *p = Vec4::new(q[0], q[1], q[2], p.w);
            });
        self.bvh.refit(&self.verts, &self.tets, false);
        self.generation = next_generation();
        self.update_bounds();
        self.update_normals();
        Ok(())
    }

    pub fn set_normals(&mut self, normals: Normals) {
        self.normals = normals;
        self.update_normals();
    }

    pub fn normals(&self) -> Normals {
        self.normals
    }

    /// Rays traced together by `first_hit_packet` (clamped to `1..=256`; default 256 = 16×16).
    pub fn set_packet_size(&mut self, rays: usize) {
        self.packet = rays.clamp(1, MAX_PACKET);
    }

    pub fn packet_size(&self) -> usize {
        self.packet
    }

    pub fn num_tets(&self) -> usize {
        self.tets.len()
    }

    pub fn num_points(&self) -> usize {
        self.verts.len()
    }

    /// `(min, max)` of the non-NaN values used by any tet, or `None` if all are void.
    pub fn value_range(&self) -> Option<(f32, f32)> {
        let r = self.bvh.root();
        (r.lo.w <= r.hi.w).then_some((r.lo.w, r.hi.w))
    }

    pub fn bvh(&self) -> &TetBvh {
        &self.bvh
    }

    pub fn bvh_info(&self) -> BvhInfo {
        self.bvh.info()
    }

    /// The input index of the tet at leaf position `tet` (as in [`RawHit::tet`]).
    pub fn input_tet(&self, tet: u32) -> u32 {
        self.order[tet as usize]
    }

    /// Checks the BVH invariants against the current data.
    pub fn validate(&self) -> Result<(), String> {
        self.bvh.validate(&self.verts, &self.tets)?;
        if self.order.len() != self.tets.len() || self.point_order.len() != self.verts.len() {
            return Err(format!(
                "{} tets and {} points, but orders of {} and {}",
                self.tets.len(),
                self.verts.len(),
                self.order.len(),
                self.point_order.len()
            ));
        }
        if let Some(o) = not_a_permutation(&self.order) {
            return Err(format!(
                "input tet {o} is not in the leaf order exactly once"
            ));
        }
        if let Some(o) = not_a_permutation(&self.point_order) {
            return Err(format!("input point {o} is not numbered exactly once"));
        }
        Ok(())
    }

    fn update_normals(&mut self) {
        if self.normals == Normals::Faceted {
            self.normal_rows = Vec::new();
            return;
        }
        // Vertex gradients: volume-weighted mean of the incident tets' gradients.
        let grads: Vec<(DVec3, f64)> = self
            .tets
            .par_iter()
            .map(|t| tet_gradient(&self.verts, t))
            .collect();
        let mut acc = vec![DVec3::ZERO; self.verts.len()];
        for (t, (g, w)) in self.tets.iter().zip(&grads) {
            for &i in t {
                acc[i as usize] += *g * *w;
            }
        }
        let vgrad: Vec<DVec3> = acc.into_iter().map(DVec3::normalize_or_zero).collect();
        self.normal_rows = self
            .tets
            .par_iter()
            .map(|t| {
                let p = t.map(|i| self.verts[i as usize]);
                let v = DMat4::from_cols(
                    p[0].as_dvec4().truncate().extend(1.0),
                    p[1].as_dvec4().truncate().extend(1.0),
                    p[2].as_dvec4().truncate().extend(1.0),
                    p[3].as_dvec4().truncate().extend(1.0),
                );
                let det = v.determinant();
                if det.abs() <= 1e-300 || !det.is_finite() {
                    return [Vec4::ZERO; 3];
                }
                let nm = DMat4::from_cols(
                    vgrad[t[0] as usize].extend(0.0),
                    vgrad[t[1] as usize].extend(0.0),
                    vgrad[t[2] as usize].extend(0.0),
                    vgrad[t[3] as usize].extend(0.0),
                );
                let m = nm * v.inverse();
                [m.row(0), m.row(1), m.row(2)].map(|r: DVec4| r.as_vec4())
            })
            .collect();
    }

    /// The traversal's view of this scene ([`super::traverse`]).
    pub(crate) fn view(&self) -> TetView<'_> {
        TetView {
            verts: &self.verts,
            tets: &self.tets,
            bvh: &self.bvh,
            generation: self.generation,
        }
    }

    /// Shading normal of a raw hit (module docs); the isopolygon is extracted again only
    /// for a faceted normal, or where the smooth one is degenerate.
    fn hit_normal(&self, ray: &Ray, h: &RawHit, iso: &[f32]) -> Vec3 {
        if self.normals == Normals::Smooth
            && let Some(rows) = self.normal_rows.get(h.tet as usize)
        {
            let p = ray.at(h.t).extend(1.0);
            let n = Vec3::new(rows[0].dot(p), rows[1].dot(p), rows[2].dot(p)).normalize_or_zero();
            if n != Vec3::ZERO && n.is_finite() {
                return n;
            }
        }
        self.view().faceted_normal(h, iso)
    }

    /// Starts loading the smooth-normal rows of a packet's hits, so that their cache misses
    /// (48 bytes a tet, in tet order: a hit's row is rarely cached) overlap instead of
    /// coming one per hit.
    fn prefetch_normal_rows<'a>(&self, hits: impl Iterator<Item = &'a RawHit>) {
        if self.normals != Normals::Smooth {
            return;
        }
        for h in hits {
            if let Some(rows) = self.normal_rows.get(h.tet as usize) {
                let first = std::ptr::from_ref(rows).cast::<u8>();
                prefetch(first);
                prefetch(first.wrapping_add(size_of::<[Vec4; 3]>() - 1));
            }
        }
    }

    fn to_hit(&self, ray: &Ray, h: &RawHit, isos: &TetIsovalues) -> Hit {
        Hit {
            t: h.t,
            surface: h.surface,
            normal: if isos.normals {
                self.hit_normal(ray, h, &isos.values)
            } else {
                (-ray.dir).normalize_or(Vec3::Z)
            },
            cell: h.tet,
        }
    }

    /// First hit without shading data (tests, statistics).
    pub fn first_hit_raw<S: Stats>(
        &self,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
        iso: &[f32],
        stats: &mut S,
    ) -> Option<RawHit> {
        self.view()
            .trace_single::<S, false>(ray, t_min, t_max, iso, stats)
    }

    /// Packet first hits without shading data, in packets of [`TetScene::packet_size`].
    pub fn first_hit_packet_raw<S: Stats>(
        &self,
        rays: &[Ray],
        t_min: &[f32],
        t_max: &[f32],
        iso: &[f32],
        out: &mut [Option<RawHit>],
        stats: &mut S,
    ) {
        let p = self.packet;
        for start in (0..rays.len()).step_by(p) {
            let end = (start + p).min(rays.len());
            if p == 1 {
                out[start] = self.view().trace_single::<S, false>(
                    &rays[start],
                    t_min[start],
                    t_max[start],
                    iso,
                    stats,
                );
            } else {
                self.view().trace_packet(
                    &rays[start..end],
                    &t_min[start..end],
                    &t_max[start..end],
                    iso,
                    &mut out[start..end],
                    stats,
                );
            }
        }
    }

    /// The `f64` brute-force twin: nearest `(t, isovalue index)` over every tet.
    pub fn brute_force_first_hit(
        &self,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
        iso: &[f32],
    ) -> Option<(f64, u32)> {
        self.brute_force_first_hit_slack(ray, t_min, t_max, iso, 0.0)
    }

    /// [`Self::brute_force_first_hit`] with polygons grown (`slack > 0`) or shrunk (`< 0`)
    /// by a barycentric margin: tests use it to tell rounding from real disagreements.
    pub fn brute_force_first_hit_slack(
        &self,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
        iso: &[f32],
        slack: f64,
    ) -> Option<(f64, u32)> {
        let (o, d) = (ray.origin.as_dvec3(), ray.dir.as_dvec3());
        let (t0, t1) = (f64::from(t_min), f64::from(t_max));
        let mut best: Option<(f64, u32)> = None;
        for t in &self.tets {
            let p = t.map(|i| self.verts[i as usize].truncate().as_dvec3());
            let val = t.map(|i| f64::from(self.verts[i as usize].w));
            for (s, &c) in iso.iter().enumerate() {
                let Some((poly, count)) = mt::extract_f64(&p, &val, f64::from(c)) else {
                    continue;
                };
                if let Some(th) = mt::intersect_f64(o, d, &poly, count, slack)
                    && th >= t0
                    && th <= t1
                    && best.is_none_or(|(b, _)| th < b)
                {
                    best = Some((th, s as u32));
                }
            }
        }
        best
    }

    /// Input data of the scene: point positions, in input order.
    pub fn points(&self) -> Vec<[f32; 3]> {
        let mut out = vec![[0.0; 3]; self.verts.len()];
        for (v, &i) in self.verts.iter().zip(&self.point_order) {
            out[i as usize] = v.truncate().to_array();
        }
        out
    }
}

/// A point field of a [`TetScene`]'s mesh sampled at its hits, for colouring a surface by
/// another array: linear inside each tet (thesis seed 004 §8.2), so the value at a hit is
/// the barycentric blend of the hit tet's four corner values ([`Hit::cell`] names the tet).
#[derive(Debug, Clone, Copy)]
pub struct TetField<'a> {
    scene: &'a TetScene,
    values: &'a [f32],
}

impl TetScene {
    /// `values` (one per point, in point order) as a field to colour this scene's hits by.
    pub fn point_field<'a>(&'a self, values: &'a [f32]) -> Result<TetField<'a>, TetError> {
        if values.len() != self.verts.len() {
            return Err(TetError::StepLength {
                what: "colouring values",
                expected: self.verts.len(),
                actual: values.len(),
            });
        }
        Ok(TetField {
            scene: self,
            values,
        })
    }
}

impl HitField for TetField<'_> {
    /// The barycentric interpolant of tet `cell` at `p` (weights clamped to the tet, so a
    /// hit a rounding error outside reads the nearest point of it); NaN for a degenerate tet.
    fn value_at(&self, p: Vec3, cell: u32) -> f32 {
        let Some(ids) = self.scene.tets.get(cell as usize) else {
            return f32::NAN;
        };
        let v = ids.map(|i| self.scene.verts[i as usize].truncate().as_dvec3());
        let m = DMat3::from_cols(v[1] - v[0], v[2] - v[0], v[3] - v[0]);
        if m.determinant() == 0.0 {
            return f32::NAN;
        }
        let l = m.inverse() * (p.as_dvec3() - v[0]);
        let w = [1.0 - l.x - l.y - l.z, l.x, l.y, l.z].map(|w| w.max(0.0));
        let sum: f64 = w.iter().sum();
        if !(sum.is_finite() && sum > 0.0) {
            return f32::NAN;
        }
        let value: f64 = (0..4)
            .map(|c| {
                w[c] * f64::from(self.values[self.scene.point_order[ids[c] as usize] as usize])
            })
            .sum();
        (value / sum) as f32
    }
}

/// The first entry of `order` that is out of range or repeated, if `order` is not a
/// permutation of `0..order.len()`.
fn not_a_permutation(order: &[u32]) -> Option<u32> {
    let mut seen = vec![false; order.len()];
    order.iter().copied().find(|&o| {
        seen.get_mut(o as usize)
            .is_none_or(|s| std::mem::replace(s, true))
    })
}

/// Gradient of the linear field over a tet and its |volume| (zero weight when degenerate
/// or void).
fn tet_gradient(verts: &[Vec4], t: &[u32; 4]) -> (DVec3, f64) {
    let v = t.map(|i| verts[i as usize].as_dvec4());
    if v.iter().any(|p| p.w.is_nan()) {
        return (DVec3::ZERO, 0.0);
    }
    let e = [1, 2, 3].map(|k| (v[k] - v[0]).truncate());
    let m = DMat3::from_cols(e[0], e[1], e[2]).transpose();
    let det = m.determinant();
    if det.abs() <= 1e-300 || !det.is_finite() {
        return (DVec3::ZERO, 0.0);
    }
    let dw = DVec3::new(v[1].w - v[0].w, v[2].w - v[0].w, v[3].w - v[0].w);
    (m.inverse() * dw, det.abs() / 6.0)
}

/// A tet scene's prepared isovalues: as given (the BVH tests them per node and tet as they
/// are), and whether hits need the scene's shading normal.
#[derive(Debug, Clone)]
pub struct TetIsovalues {
    pub values: Vec<f32>,
    /// False for depth-only frames and shadow rays ([`IsoScene::prepare_distances`]): hits
    /// get the ray's reverse as their normal, and packets make no polygon normal.
    pub normals: bool,
}

impl IsoScene for TetScene {
    type Isovalues = TetIsovalues;

    fn prepare(&self, isovalues: &[f32]) -> TetIsovalues {
        TetIsovalues {
            values: isovalues.to_vec(),
            normals: true,
        }
    }

    fn prepare_distances(&self, isovalues: &[f32]) -> TetIsovalues {
        TetIsovalues {
            normals: false,
            ..self.prepare(isovalues)
        }
    }

    fn world_bounds(&self) -> Aabb {
        self.bounds
    }

    /// The box of the BVH's live nodes ([`TetBvh::live_bounds`]), a hair wider so that
    /// rounding of the renderer's slab test never cuts a crossing on its faces.
    fn live_bounds(&self, isos: &TetIsovalues) -> Aabb {
        let Some((lo, hi)) = self.bvh.live_bounds(&isos.values) else {
            return Aabb::EMPTY;
        };
        Aabb::new(lo, hi).widened_within(&self.bounds)
    }

    /// The boxes of the BVH's live frontier ([`TetBvh::live_boxes`]), each a hair wider.
    fn live_boxes(&self, isos: &TetIsovalues, out: &mut Vec<Aabb>) {
        self.bvh.live_boxes(&isos.values, |lo, hi| {
            out.push(Aabb::new(lo, hi).widened_within(&self.bounds));
        });
    }

    fn first_hit_prepared<S: Stats>(
        &self,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
        isos: &TetIsovalues,
        stats: &mut S,
    ) -> Option<Hit> {
        self.view()
            .trace_single::<S, false>(ray, t_min, t_max, &isos.values, stats)
            .map(|h| self.to_hit(ray, &h, isos))
    }

    fn occluded_prepared<S: Stats>(
        &self,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
        isos: &TetIsovalues,
        stats: &mut S,
    ) -> bool {
        self.view()
            .trace_single::<S, true>(ray, t_min, t_max, &isos.values, stats)
            .is_some()
    }

    /// Any-hit packets: a ray stops at the first crossing its walk finds, not the nearest
    /// (`TetView::trace_packet_occluded`).
    fn occluded_packet_prepared<S: Stats>(
        &self,
        rays: &[Ray],
        t_min: &[f32],
        t_max: &[f32],
        isos: &TetIsovalues,
        out: &mut [bool],
        stats: &mut S,
    ) {
        let p = self.packet;
        for start in (0..rays.len()).step_by(p) {
            let end = (start + p).min(rays.len());
            if p == 1 {
                out[start] =
                    self.occluded_prepared(&rays[start], t_min[start], t_max[start], isos, stats);
            } else {
                self.view().trace_packet_occluded(
                    &rays[start..end],
                    &t_min[start..end],
                    &t_max[start..end],
                    &isos.values,
                    &mut out[start..end],
                    stats,
                );
            }
        }
    }

    /// Large packets collect every ray's layers in one traversal (`RayLayers`: its
    /// nearest hits up to the first opaque one) instead of a new packet from the root per
    /// layer; packets of at most 4 rays return first hits, as the trait's default does.
    fn peeled_hits_packet_prepared<S: Stats>(
        &self,
        rays: &[Ray],
        t_min: &[f32],
        t_max: &[f32],
        isos: &TetIsovalues,
        peel: &Peel,
        out: &mut [PeeledHits],
        stats: &mut S,
    ) {
        // Faceted normals from the traversal, as for first hits; smooth ones per layer.
        let faceted = isos.normals && self.normals == Normals::Faceted;
        // Made at the first large packet of the call (a tile's rays), not per ray.
        let mut layers: Option<RayLayers> = None;
        let mut first = [None; 4];
        for start in (0..rays.len()).step_by(self.packet) {
            let end = (start + self.packet).min(rays.len());
            let n = end - start;
            let (rays, t_min, t_max) = (&rays[start..end], &t_min[start..end], &t_max[start..end]);
            if n <= 4 {
                self.first_hit_packet_prepared(rays, t_min, t_max, isos, &mut first[..n], stats);
                for (o, &h) in out[start..end].iter_mut().zip(&first[..n]) {
                    o.set_first(h, peel);
                }
                continue;
            }
            let layers = layers.get_or_insert_with(|| RayLayers::new(peel, faceted));
            self.view()
                .trace_packet_layers(rays, t_min, t_max, &isos.values, layers, stats);
            if isos.normals {
                self.prefetch_normal_rows((0..n).flat_map(|k| layers.of(k)));
            }
            for (k, o) in out[start..end].iter_mut().enumerate() {
                *o = layers.peeled(k, |h, normal| {
                    if faceted {
                        Hit {
                            t: h.t,
                            surface: h.surface,
                            normal,
                            cell: h.tet,
                        }
                    } else {
                        self.to_hit(&rays[k], h, isos)
                    }
                });
            }
        }
    }

    fn first_hit_packet_prepared<S: Stats>(
        &self,
        rays: &[Ray],
        t_min: &[f32],
        t_max: &[f32],
        isos: &TetIsovalues,
        out: &mut [Option<Hit>],
        stats: &mut S,
    ) {
        let isovalues = &isos.values;
        let mut raw = [None; MAX_PACKET];
        let faceted = isos.normals && self.normals == Normals::Faceted;
        if (faceted || !isos.normals) && self.packet > 1 {
            // Faceted normals straight from the traversal (no second extraction per hit),
            // or none at all for distances. Same packets as `first_hit_packet_raw` below.
            let mut normals = [Vec3::ZERO; MAX_PACKET];
            for chunk in (0..rays.len()).step_by(MAX_PACKET) {
                let chunk_end = (chunk + MAX_PACKET).min(rays.len());
                for start in (chunk..chunk_end).step_by(self.packet) {
                    let end = (start + self.packet).min(chunk_end);
                    let n = end - start;
                    let (r, t0, t1) = (&rays[start..end], &t_min[start..end], &t_max[start..end]);
                    if faceted {
                        self.view().trace_packet_faceted(
                            r,
                            t0,
                            t1,
                            isovalues,
                            &mut raw[..n],
                            &mut normals[..n],
                            stats,
                        );
                    } else {
                        self.view()
                            .trace_packet(r, t0, t1, isovalues, &mut raw[..n], stats);
                    }
                    for k in 0..n {
                        out[start + k] = raw[k].map(|h| {
                            if faceted {
                                Hit {
                                    t: h.t,
                                    surface: h.surface,
                                    normal: normals[k],
                                    cell: h.tet,
                                }
                            } else {
                                self.to_hit(&r[k], &h, isos)
                            }
                        });
                    }
                }
            }
            return;
        }
        for start in (0..rays.len()).step_by(MAX_PACKET) {
            let end = (start + MAX_PACKET).min(rays.len());
            let n = end - start;
            self.first_hit_packet_raw(
                &rays[start..end],
                &t_min[start..end],
                &t_max[start..end],
                isovalues,
                &mut raw[..n],
                stats,
            );
            if isos.normals {
                self.prefetch_normal_rows(raw[..n].iter().flatten());
            }
            for k in 0..n {
                out[start + k] = raw[k].map(|h| self.to_hit(&rays[start + k], &h, isos));
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::NoStats;
    use crate::tet::BvhBuilder;
    use crate::tet::{PointField, lattice_tets};

    /// A jittered `n³`-point grid, 6 tets per cell, with a bumpy distance field.
    fn grid_scene(n: usize, seed: u64) -> TetScene {
        let mut rng = crate::math::rng::Rng::new(seed);
        let mut f = move || rng.unit_f32() - 0.5;
        let id = |i: usize, j: usize, k: usize| (i + n * (j + n * k)) as u32;
        let (mut points, mut values) = (Vec::new(), Vec::new());
        for k in 0..n {
            for j in 0..n {
                for i in 0..n {
                    let p = Vec3::new(i as f32 + 0.4 * f(), j as f32 + 0.4 * f(), k as f32);
                    values.push((p - Vec3::splat(n as f32 * 0.5)).length() + 0.3 * f());
                    points.push(p.to_array());
                }
            }
        }
        let tets = lattice_tets(n, id);
        let mesh = TetMesh::new(points, tets, vec![PointField::new("f", values)]).unwrap();
        TetScene::new(&mesh, "f", BvhOptions::default()).unwrap()
    }

    /// Points are renumbered by first use in leaf order (unused ones last), and everything
    /// that takes or gives points in input order still does: `points()`, the tets' corners
    /// (through `input_tet`), and a rebuild.
    #[test]
    fn renumbered_points_keep_the_input_order_outside() {
        let n = 5;
        let mut rng = crate::math::rng::Rng::new(9);
        let id = |i: usize, j: usize, k: usize| (i + n * (j + n * k)) as u32;
        let mut points: Vec<[f32; 3]> = (0..n * n * n)
            .map(|m| [(m % n) as f32, ((m / n) % n) as f32, (m / (n * n)) as f32])
            .collect();
        // Two points no tet uses.
        points.push([0.5, 0.5, 9.0]);
        points.insert(0, [0.5, 9.0, 0.5]);
        let tets: Vec<[u32; 4]> = lattice_tets(n, id)
            .into_iter()
            .map(|t| t.map(|i| i + 1))
            .collect();
        let values: Vec<f32> = (0..points.len()).map(|_| rng.unit_f32()).collect();
        let mut scene =
            TetScene::from_parts(&points, tets.clone(), &values, BvhOptions::default()).unwrap();
        for _ in 0..2 {
            scene.validate().unwrap();
            assert_eq!(scene.points(), points);
            let mut next = 0;
            for (leaf, t) in scene.tets.iter().enumerate() {
                let input = tets[scene.input_tet(leaf as u32) as usize];
                for (&v, &i) in t.iter().zip(&input) {
                    assert_eq!(
                        scene.verts[v as usize].truncate().to_array(),
                        points[i as usize]
                    );
                    assert_eq!(scene.verts[v as usize].w, values[i as usize]);
                    // First use in leaf order takes the next number.
                    assert!(v <= next, "tet {leaf}: vertex {v} before {next}");
                    next = next.max(v + 1);
                }
            }
            assert_eq!(
                next as usize,
                points.len() - 2,
                "the unused points come last"
            );
            scene.rebuild(BvhOptions {
                builder: BvhBuilder::Sah,
                leaf_size: 3,
            });
        }
    }

    /// `first_hit_packet` (faceted normals taken from the traversal's polygons) equals raw
    /// packet hits with the polygon extracted again (`to_hit`), bit for bit, for every packet
    /// size and for several isovalues at once.
    #[test]
    fn packet_normals_equal_reextracted_normals() {
        let n = 9;
        let mut scene = grid_scene(n, 17);
        let c = n as f32 * 0.5;
        let eye = Vec3::new(c + 3.0, c - 2.0, -9.0);
        let rays: Vec<Ray> = (0..600)
            .map(|i| {
                let (x, y) = ((i % 24) as f32, (i / 24) as f32);
                let target = Vec3::new(x * 0.35, y * 0.35, c);
                Ray::new(eye, (target - eye).normalize())
            })
            .collect();
        let t_min = vec![0.0; rays.len()];
        let t_max: Vec<f32> = (0..rays.len())
            .map(|i| if i % 5 == 0 { 12.0 } else { f32::INFINITY })
            .collect();
        let bits = |v: Vec3| v.to_array().map(f32::to_bits);
        let mut hits_seen = 0;
        for iso in [vec![2.5f32], vec![3.0, 1.7]] {
            for packet in [1, 2, 4, 7, 64, 256] {
                scene.set_packet_size(packet);
                let mut raw = vec![None; rays.len()];
                scene.first_hit_packet_raw(&rays, &t_min, &t_max, &iso, &mut raw, &mut NoStats);
                let mut hits = vec![None; rays.len()];
                scene.first_hit_packet(&rays, &t_min, &t_max, &iso, &mut hits, &mut NoStats);
                for (i, (r, h)) in raw.iter().zip(&hits).enumerate() {
                    let want = r.map(|r| scene.to_hit(&rays[i], &r, &scene.prepare(&iso)));
                    assert_eq!(
                        h.map(|h| (h.t.to_bits(), h.surface, bits(h.normal))),
                        want.map(|h| (h.t.to_bits(), h.surface, bits(h.normal))),
                        "iso {iso:?}, packet {packet}, ray {i}"
                    );
                    hits_seen += usize::from(h.is_some());
                }
            }
        }
        assert!(hits_seen > 800, "{hits_seen} hits");
    }

    /// Distances without normals (depth-only frames, and shadow rays, which the renderer
    /// traces with distance isovalues) find the hits that the shaded packets find: the same
    /// `t`, surface and tet for every packet size, faceted and smooth, and a shadow ray is
    /// occluded exactly when it has a first hit.
    #[test]
    fn distance_only_packets_find_the_shaded_packets_hits() {
        let n = 9;
        let mut scene = grid_scene(n, 23);
        let c = n as f32 * 0.5;
        let eye = Vec3::new(c - 2.0, c + 3.0, -9.0);
        let rays: Vec<Ray> = (0..600)
            .map(|i| {
                let (x, y) = ((i % 24) as f32, (i / 24) as f32);
                Ray::new(eye, (Vec3::new(x * 0.35, y * 0.35, c) - eye).normalize())
            })
            .collect();
        let t_min = vec![0.0; rays.len()];
        let t_max: Vec<f32> = (0..rays.len())
            .map(|i| if i % 7 == 0 { 11.0 } else { f32::INFINITY })
            .collect();
        let key = |h: &Option<Hit>| h.map(|h| (h.t.to_bits(), h.surface, h.cell));
        let (mut hits_seen, mut misses_seen) = (0, 0);
        for normals in [Normals::Faceted, Normals::Smooth] {
            scene.set_normals(normals);
            for iso in [vec![2.5f32], vec![3.0, 1.7]] {
                let (shaded, distances) = (scene.prepare(&iso), scene.prepare_distances(&iso));
                for packet in [1, 4, 64, 256] {
                    scene.set_packet_size(packet);
                    let mut want = vec![None; rays.len()];
                    scene.first_hit_packet_prepared(
                        &rays,
                        &t_min,
                        &t_max,
                        &shaded,
                        &mut want,
                        &mut NoStats,
                    );
                    let mut got = vec![None; rays.len()];
                    scene.first_hit_packet_prepared(
                        &rays,
                        &t_min,
                        &t_max,
                        &distances,
                        &mut got,
                        &mut NoStats,
                    );
                    let mut occluded = vec![false; rays.len()];
                    scene.occluded_packet_prepared(
                        &rays,
                        &t_min,
                        &t_max,
                        &distances,
                        &mut occluded,
                        &mut NoStats,
                    );
                    for i in 0..rays.len() {
                        let what = format!("{normals:?}, iso {iso:?}, packet {packet}, ray {i}");
                        assert_eq!(key(&got[i]), key(&want[i]), "{what}");
                        assert_eq!(occluded[i], want[i].is_some(), "{what}");
                        if let Some(h) = got[i] {
                            assert!((h.normal + rays[i].dir).length() < 1e-6, "{what}");
                        }
                        hits_seen += usize::from(want[i].is_some());
                        misses_seen += usize::from(want[i].is_none());
                    }
                }
            }
        }
        assert!(
            hits_seen > 1000 && misses_seen > 200,
            "{hits_seen} hits, {misses_seen} misses"
        );
    }

    /// Shadow-like packets (origins scattered through the mesh, one direction, ranges
    /// that start and end inside it): the any-hit packets are occluded exactly where the
    /// single-ray walk finds a first hit, for every packet size and ray order.
    #[test]
    fn any_hit_packets_agree_with_single_ray_first_hits() {
        let n = 9;
        let mut scene = grid_scene(n, 5);
        let mut rng = crate::math::rng::Rng::new(77);
        let (mut hits_seen, mut misses_seen) = (0, 0);
        for dir in [Vec3::new(0.3, 0.5, 0.81), Vec3::new(-0.7, 0.1, -0.2)] {
            let dir = dir.normalize();
            let rays: Vec<Ray> = (0..700)
                .map(|_| Ray::new(rng.vec3(0.0, (n - 1) as f32), dir))
                .collect();
            let t_min: Vec<f32> = (0..rays.len()).map(|_| rng.range_f32(0.0, 0.5)).collect();
            let t_max: Vec<f32> = t_min
                .iter()
                .map(|&t0| {
                    if rng.chance(0.3) {
                        f32::INFINITY
                    } else {
                        t0 + rng.range_f32(0.0, 4.0)
                    }
                })
                .collect();
            for iso in [vec![2.5f32], vec![3.0, 1.7]] {
                let isos = scene.prepare_distances(&iso);
                let want: Vec<bool> = (0..rays.len())
                    .map(|i| {
                        scene
                            .first_hit_raw(&rays[i], t_min[i], t_max[i], &iso, &mut NoStats)
                            .is_some()
                    })
                    .collect();
                for packet in [1, 4, 16, 64, 256] {
                    scene.set_packet_size(packet);
                    let mut got = vec![false; rays.len()];
                    scene.occluded_packet_prepared(
                        &rays,
                        &t_min,
                        &t_max,
                        &isos,
                        &mut got,
                        &mut NoStats,
                    );
                    for i in 0..rays.len() {
                        assert_eq!(got[i], want[i], "iso {iso:?}, packet {packet}, ray {i}");
                    }
                }
                hits_seen += want.iter().filter(|&&h| h).count();
                misses_seen += want.iter().filter(|&&h| !h).count();
            }
        }
        assert!(
            hits_seen > 500 && misses_seen > 500,
            "{hits_seen} hits, {misses_seen} misses"
        );
    }

    /// Colouring by another array: a linear field `g = 2x − y + 0.5z` sampled at the hits of
    /// the bumpy surface is `g` at the hit point (linear fields are exact in every tet).
    #[test]
    fn a_linear_point_field_is_read_exactly_at_hits() {
        let n = 9;
        let scene = grid_scene(n, 5);
        let g = |p: DVec3| 2.0 * p.x - p.y + 0.5 * p.z;
        let values: Vec<f32> = scene
            .points()
            .iter()
            .map(|q| g(Vec3::from(*q).as_dvec3()) as f32)
            .collect();
        let field = scene.point_field(&values).unwrap();
        assert!(scene.point_field(&values[1..]).is_err());
        let c = n as f32 * 0.5;
        let eye = Vec3::new(c + 1.0, c - 1.5, -9.0);
        let mut seen = 0;
        for i in 0..400 {
            let (x, y) = ((i % 20) as f32, (i / 20) as f32);
            let target = Vec3::new(x * 0.4, y * 0.4, c);
            let ray = Ray::new(eye, (target - eye).normalize());
            let Some(hit) = scene.first_hit(&ray, 0.0, f32::INFINITY, &[2.5], &mut NoStats) else {
                continue;
            };
            let p = ray.at(hit.t);
            let v = field.value_at(p, hit.cell);
            assert!(
                (f64::from(v) - g(p.as_dvec3())).abs() < 1e-4,
                "ray {i}: {v}"
            );
            seen += 1;
        }
        assert!(seen > 100, "{seen} hits");
        assert!(field.value_at(Vec3::ZERO, u32::MAX).is_nan());
    }
}
