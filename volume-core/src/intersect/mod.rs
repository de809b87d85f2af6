//! Ray–isosurface intersection inside trilinear cells (thesis seed 004 §6.1.1, §6.5.2,
//! §7.2.2), shared by the kd-tree ([`crate::kdtree`]) and its brute-force twin
//! ([`crate::grid::dda`]).
//!
//! - [`frame`]: world rays into traversal (cell) units; cell boxes; world normals.
//! - [`methods`]: the cubic along a cell segment and the five intersectors.
//! - `slow_x8`: the exact intersector's `f64` slow path for several lanes of a packet.
//! - [`accuracy`]: the extreme suite and the harness that scores an intersector against
//!   the `f64` reference (missed hits, false hits, |Δt| in cell units).
//!
//! The intersector is chosen at run time with [`Intersector`] (parsed from
//! "linear", "neubauer", "exact", "schwarze", "reference") and turned into a type once per
//! frame: the traversal is generic over [`CellIntersector`], so no cell pays for dispatch.
//!
//! Error behaviour (details on each type in [`methods`]):
//! - [`methods::Linear`]: one linear interpolation between entry and exit; misses cells
//!   the ray enters and leaves again, misses tangent touches; position error grows with
//!   surface curvature.
//! - [`methods::Neubauer`]: linear + N regula-falsi steps; same misses, smaller error.
//! - [`methods::Exact`] (Listing 7.1, the default): extrema split the segment into monotone
//!   pieces, so no root is missed; f32 regula falsi gives the position.
//! - [`methods::Schwarze`]: analytic Cardano in f32; exact in exact arithmetic but loses
//!   digits for nearly quadratic segments and clustered roots.
//! - [`methods::Reference`]: f64 root isolation to full double precision (the truth).
//!
//! Cell policy shared by all: a cell with a non-finite corner (NaN = void, or ±inf, whose
//! trilinear interpolant is infinite or NaN almost everywhere in the cell) contains no
//! surface; a cell equal to the isovalue everywhere is hit at its entry; a corner equal to
//! the isovalue is a candidate (ranges are closed).

pub mod accuracy;
pub mod frame;
pub mod methods;
pub mod packet;
pub(crate) mod slow_x8;

use std::str::FromStr;

use glam::Vec3;

use crate::render::Normals;
use crate::volume::ValueMap;
use crate::voxel::{Voxel, VoxelType};

pub use frame::{LocalRay, TraversalFrame};
pub(crate) use packet::root_t;
pub use packet::{HitsX8, RaysX8, RootsX8, SegmentsX8, intersect_prepared_cell_x8};

/// The run-time choice of cell intersector.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Intersector {
    Linear,
    Neubauer {
        iterations: u32,
    },
    /// Listing 7.1 (the default).
    #[default]
    Exact,
    Schwarze,
    /// The f64 reference (slow; the accuracy truth).
    Reference,
}

impl Intersector {
    pub const ALL: [Intersector; 5] = [
        Intersector::Linear,
        Intersector::Neubauer { iterations: 3 },
        Intersector::Exact,
        Intersector::Schwarze,
        Intersector::Reference,
    ];

    pub const fn name(self) -> &'static str {
        match self {
            Intersector::Linear => "linear",
            Intersector::Neubauer { .. } => "neubauer",
            Intersector::Exact => "exact",
            Intersector::Schwarze => "schwarze",
            Intersector::Reference => "reference",
        }
    }
}

impl std::fmt::Display for Intersector {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Intersector::Neubauer { iterations } if *iterations != 3 => {
                write!(f, "neubauer:{iterations}")
            }
            _ => f.write_str(self.name()),
        }
    }
}

/// An unknown intersector name.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unknown intersector {0:?} (expected linear, neubauer[:N], exact, schwarze or reference)")]
pub struct ParseIntersectorError(pub String);

impl FromStr for Intersector {
    type Err = ParseIntersectorError;

    /// "linear", "neubauer" (3 iterations) or "neubauer:N", "exact", "schwarze", "reference".
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let lower = s.trim().to_ascii_lowercase();
        match lower.as_str() {
            "linear" => Ok(Intersector::Linear),
            "neubauer" => Ok(Intersector::Neubauer { iterations: 3 }),
            "exact" => Ok(Intersector::Exact),
            "schwarze" => Ok(Intersector::Schwarze),
            "reference" => Ok(Intersector::Reference),
            other => other
                .strip_prefix("neubauer:")
                .and_then(|n| n.parse::<u32>().ok())
                .filter(|n| *n <= 64)
                .map(|iterations| Intersector::Neubauer { iterations })
                .ok_or_else(|| ParseIntersectorError(s.to_string())),
        }
    }
}

/// Runs `$body` with `$c` bound to the [`CellIntersector`] value for an [`Intersector`]:
/// one `match`, then monomorphized code.
#[macro_export]
macro_rules! dispatch_intersector {
    ($which:expr, $c:ident => $body:expr) => {
        match $which {
            $crate::intersect::Intersector::Linear => {
                let $c = $crate::intersect::methods::Linear;
                $body
            }
            $crate::intersect::Intersector::Neubauer { iterations } => {
                let $c = $crate::intersect::methods::Neubauer { iterations };
                $body
            }
            $crate::intersect::Intersector::Exact => {
                let $c = $crate::intersect::methods::Exact;
                $body
            }
            $crate::intersect::Intersector::Schwarze => {
                let $c = $crate::intersect::methods::Schwarze;
                $body
            }
            $crate::intersect::Intersector::Reference => {
                let $c = $crate::intersect::methods::Reference;
                $body
            }
        }
    };
}

/// A ray segment inside one cell, in traversal units.
#[derive(Debug, Clone, Copy)]
pub struct CellSegment {
    pub origin: Vec3,
    pub dir: Vec3,
    /// The ray's `1 / dir` (to recognise the faces the slab test entered and left by).
    pub inv_dir: Vec3,
    /// Cell bounds.
    pub lo: Vec3,
    pub hi: Vec3,
    pub t_near: f32,
    pub t_far: f32,
}

impl CellSegment {
    /// `ray`'s segment `[t_near, t_far]` through the cell `[lo, hi]`.
    #[inline(always)]
    pub fn of(ray: &LocalRay, lo: Vec3, hi: Vec3, t_near: f32, t_far: f32) -> Self {
        Self {
            origin: ray.origin,
            dir: ray.dir,
            inv_dir: ray.inv_dir,
            lo,
            hi,
            t_near,
            t_far,
        }
    }

    /// Cell-local entry point and displacement over the segment (`s ∈ [0, 1]`).
    ///
    /// Entry and exit points are each formed as `((origin − lo) + dir·t) / width`, and the
    /// coordinate across the face the slab test entered (left) by is set to exactly 0 or 1.
    /// Two cells that share a face thus see bit-identical in-face coordinates at the shared
    /// point, so the surface's sign there agrees up to the cubic's own rounding: a crossing
    /// right at a face is found in one of the two cells. (With the entry point alone plus
    /// `dir·Δt`, the f32 cancellation in `(origin − lo) + dir·t`, about `ε·|origin − lo|`
    /// cells, differed between the two cells: a ray from 700 cells away could lose a
    /// crossing within ~1e-4 cells of a face; see docs/accuracy.md, "far hits".)
    #[inline(always)]
    pub fn local_f32(&self) -> ([f32; 3], [f32; 3]) {
        let inv_w = (self.hi - self.lo).recip();
        let rel = self.origin - self.lo;
        let mut p0 = ((rel + self.dir * self.t_near) * inv_w).to_array();
        let mut p1 = ((rel + self.dir * self.t_far) * inv_w).to_array();
        for a in 0..3 {
            let d = self.dir[a];
            if d == 0.0 {
                continue;
            }
            // The slab test's plane distances, from the same operands (frame::slab).
            let inv = self.inv_dir[a];
            let t_lo = (self.lo[a] - self.origin[a]) * inv;
            let t_hi = (self.hi[a] - self.origin[a]) * inv;
            let (t_in, t_out, face_in, face_out) = if d > 0.0 {
                (t_lo, t_hi, 0.0, 1.0)
            } else {
                (t_hi, t_lo, 1.0, 0.0)
            };
            if t_in == self.t_near {
                p0[a] = face_in;
            }
            if t_out == self.t_far {
                p1[a] = face_out;
            }
        }
        let dp = [0, 1, 2].map(|a| p1[a] - p0[a]);
        (p0, dp)
    }

    /// The `f64` segment inside the cell from the same `f32` ray and cell bounds:
    /// `(p0, dp, t0, t1)`, cell-local entry point and displacement over `[t0, t1]`.
    ///
    /// Each end that the `f32` slab test took from a cell face is recomputed exactly (in
    /// `f64`, from the same face); an end that came from the caller's interval is kept. The
    /// `f32` ends are rounded to a few ulps of `t` (about 6e-5 cells for a ray from 700 cells
    /// away), so the point `origin + dir·t_near` can lie outside the cell; evaluating the
    /// cell's trilinear interpolant there extrapolates it, which can invent a crossing that
    /// the continuous field does not have (a false hit of the reference that showed up as a
    /// "far hit" of the exact method at 1024², docs/accuracy.md). The exact ends make
    /// consecutive cells tile the ray in `f64` too.
    pub fn local_f64(&self) -> ([f64; 3], [f64; 3], f64, f64) {
        let (o, d, lo, hi) = (
            self.origin.as_dvec3(),
            self.dir.as_dvec3(),
            self.lo.as_dvec3(),
            self.hi.as_dvec3(),
        );
        // The f32 slab's own face distances (frame::slab), to tell which ends were faces.
        let (mut in32, mut out32) = (f32::NEG_INFINITY, f32::INFINITY);
        let (mut in64, mut out64) = (f64::NEG_INFINITY, f64::INFINITY);
        for a in 0..3 {
            if self.dir[a] == 0.0 {
                continue;
            }
            let inv = self.inv_dir[a];
            let (ta, tb) = (
                (self.lo[a] - self.origin[a]) * inv,
                (self.hi[a] - self.origin[a]) * inv,
            );
            let (ua, ub) = ((lo[a] - o[a]) / d[a], (hi[a] - o[a]) / d[a]);
            let ((n, f), (n64, f64_)) = if d[a] > 0.0 {
                ((ta, tb), (ua, ub))
            } else {
                ((tb, ta), (ub, ua))
            };
            in32 = in32.max(n);
            out32 = out32.min(f);
            in64 = in64.max(n64);
            out64 = out64.min(f64_);
        }
        let t0 = if self.t_near == in32 {
            in64
        } else {
            f64::from(self.t_near)
        };
        let t1 = if self.t_far == out32 {
            out64
        } else {
            f64::from(self.t_far)
        };
        let t1 = t1.max(t0);
        let w = hi - lo;
        let (mut p0, mut dp) = ((o - lo) + d * t0, d * (t1 - t0));
        // A uniform axis' cells are one unit wide: `x / 1` is `x`, without the division.
        for a in 0..3 {
            if w[a] != 1.0 {
                p0[a] /= w[a];
                dp[a] /= w[a];
            }
        }
        (p0.to_array(), dp.to_array(), t0, t1)
    }

    /// The position on the `f32` segment `[t_near, t_far]` of ray parameter `t` (for roots
    /// found on [`CellSegment::local_f64`]'s segment); 0 for a degenerate segment.
    pub fn s_of_t(&self, t: f64) -> f64 {
        let (tn, tf) = (f64::from(self.t_near), f64::from(self.t_far));
        if tf > tn { (t - tn) / (tf - tn) } else { 0.0 }
    }

    /// The ray parameter of segment position `s`.
    #[inline(always)]
    pub fn t_at(&self, s: f64) -> f32 {
        let (tn, tf) = (f64::from(self.t_near), f64::from(self.t_far));
        (tn + s * (tf - tn)) as f32
    }
}

/// A cell intersector (one of [`methods`]): the first root `s ∈ [0, 1]` of
/// `f(s) = trilinear(corners)(segment(s)) − iso`.
pub trait CellIntersector: Copy + Send + Sync + 'static {
    fn first_root<T: Voxel>(&self, corners: &[T; 8], iso: f32, seg: &CellSegment) -> Option<f64>;

    /// [`CellIntersector::first_root`] for the lanes in `mask` of a packet's segments through
    /// one cell (packet leaves), bit-identical per lane. The default runs it lane by lane.
    #[inline(always)]
    fn first_roots_x8<T: Voxel>(
        &self,
        corners: &[T; 8],
        iso: f32,
        seg: &SegmentsX8<'_>,
        mask: u32,
    ) -> RootsX8 {
        packet::first_roots_by_lane(self, corners, iso, seg, mask)
    }

    /// [`CellIntersector::first_roots_x8`], except that lanes in `may_defer` whose segment
    /// certainly crosses the surface may be left out of the roots and returned in the second
    /// mask: their root is then found later, together with other cells' lanes (the slow
    /// path's jobs; a first-hit packet needs only to know that its lane ends in this cell).
    /// The default defers nothing.
    #[inline(always)]
    fn first_roots_x8_deferring<T: Voxel>(
        &self,
        corners: &[T; 8],
        iso: f32,
        seg: &SegmentsX8<'_>,
        mask: u32,
        may_defer: u32,
    ) -> (RootsX8, u32) {
        let _ = may_defer;
        (self.first_roots_x8(corners, iso, seg, mask), 0)
    }
}

/// The most isovalues one traversal handles without allocating (more are still correct, the
/// set then lives on the heap).
pub const INLINE_ISOVALUES: usize = 16;

/// Active isovalues converted into the voxel type's comparable range, once per frame
/// ([`crate::render::IsoScene::prepare`]).
///
/// Iso `c` lies in a node range `[min, max]` iff `min <= lo && max >= hi`, with
/// `lo = floor(c)`, `hi = ceil(c)` for integer types (exact: integer ranges contain the
/// real `c` iff they contain both) and `lo = hi = c` for floats. Isovalues outside the
/// type's range or NaN can never be hit and are dropped.
///
/// The set also says which shading normal hits need (smooth unless
/// [`IsoSet::with_normals`] says otherwise), or none ([`IsoSet::without_normals`]): a frame
/// that reads only hit distances skips it.
#[derive(Debug, Clone)]
pub struct IsoSet<T: Voxel> {
    len: usize,
    normals: Option<Normals>,
    lo: [T; INLINE_ISOVALUES],
    hi: [T; INLINE_ISOVALUES],
    value: [f32; INLINE_ISOVALUES],
    surface: [u32; INLINE_ISOVALUES],
    spill: Vec<(T, T, f32, u32)>,
}

impl<T: Voxel> IsoSet<T> {
    pub fn new(isovalues: &[f32]) -> Self {
        Self::mapped(isovalues, ValueMap::IDENTITY)
    }

    /// The set of physical `isovalues` over voxels whose stored values `map` turns into
    /// physical ones: each isovalue is mapped to stored units here, once per frame.
    pub fn mapped(isovalues: &[f32], map: ValueMap) -> Self {
        let mut s = Self {
            len: 0,
            normals: Some(Normals::Smooth),
            lo: [T::default(); INLINE_ISOVALUES],
            hi: [T::default(); INLINE_ISOVALUES],
            value: [0.0; INLINE_ISOVALUES],
            surface: [0; INLINE_ISOVALUES],
            spill: Vec::new(),
        };
        for (i, &c) in isovalues.iter().enumerate() {
            let c = map.iso_to_stored(c);
            let Some((lo, hi)) = native_bounds::<T>(c) else {
                continue;
            };
            if s.len < INLINE_ISOVALUES {
                s.lo[s.len] = lo;
                s.hi[s.len] = hi;
                s.value[s.len] = c;
                s.surface[s.len] = i as u32;
                s.len += 1;
            } else {
                s.spill.push((lo, hi, c, i as u32));
            }
        }
        s
    }

    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// The isovalue and surface of a set of exactly one.
    #[inline]
    pub fn single(&self) -> Option<(f32, u32)> {
        (self.len == 1 && self.spill.is_empty()).then(|| (self.value[0], self.surface[0]))
    }

    /// The same isovalues for hits whose normal nobody reads
    /// ([`crate::render::IsoScene::prepare_distances`]).
    pub fn without_normals(mut self) -> Self {
        self.normals = None;
        self
    }

    /// The same isovalues for hits with `normals` ([`crate::grid::GridScene::set_normals`]).
    pub fn with_normals(mut self, normals: Normals) -> Self {
        self.normals = Some(normals);
        self
    }

    /// The shading normal hits need, if any.
    #[inline]
    pub fn normals(&self) -> Option<Normals> {
        self.normals
    }

    /// True if some isovalue lies in `[min, max]` (an empty range `min > max` never does).
    #[inline(always)]
    pub fn any_in(&self, min: T, max: T) -> bool {
        for i in 0..self.len {
            if min <= self.lo[i] && max >= self.hi[i] {
                return true;
            }
        }
        self.spill
            .iter()
            .any(|&(lo, hi, _, _)| min <= lo && max >= hi)
    }

    /// The isovalue inside `[min, max]` and its surface, when exactly one is.
    #[inline(always)]
    pub fn only_in(&self, min: T, max: T) -> Option<(f32, u32)> {
        let (mut n, mut found) = (0, None);
        self.for_each_in(min, max, |iso, surface| {
            n += 1;
            found = Some((iso, surface));
        });
        found.filter(|_| n == 1)
    }

    /// Calls `f(iso, surface)` for each isovalue inside `[min, max]`.
    #[inline(always)]
    pub fn for_each_in(&self, min: T, max: T, mut f: impl FnMut(f32, u32)) {
        for i in 0..self.len {
            if min <= self.lo[i] && max >= self.hi[i] {
                f(self.value[i], self.surface[i]);
            }
        }
        for &(lo, hi, c, s) in &self.spill {
            if min <= lo && max >= hi {
                f(c, s);
            }
        }
    }
}

/// `(floor(c), ceil(c))` in `T` for integer types, `(c, c)` for floats; `None` when no
/// voxel value range of `T` can contain `c`.
pub fn native_bounds<T: Voxel>(c: f32) -> Option<(T, T)> {
    if c.is_nan() {
        return None;
    }
    let c = f64::from(c);
    if T::TYPE.is_float() {
        if T::TYPE == VoxelType::F32 && !(c >= f64::from(f32::MIN) && c <= f64::from(f32::MAX)) {
            return None;
        }
        return Some((T::from_f64(c), T::from_f64(c)));
    }
    let (lo, hi) = (c.floor(), c.ceil());
    if lo < T::LOWEST.to_f64() || hi > T::HIGHEST.to_f64() {
        return None;
    }
    // Integral values convert exactly (from_f64 rounds, which is the identity here).
    Some((T::from_f64(lo), T::from_f64(hi)))
}

/// The value range of a cell's corners, or `None` for a void cell (a non-finite corner).
#[inline(always)]
pub fn corner_range<T: Voxel>(c: &[T; 8]) -> Option<(T, T)> {
    if T::TYPE.is_float() && c.iter().any(|v| !v.to_f64().is_finite()) {
        return None;
    }
    let mut lo = c[0];
    let mut hi = c[0];
    for &v in &c[1..] {
        if v < lo {
            lo = v;
        }
        if v > hi {
            hi = v;
        }
    }
    Some((lo, hi))
}

/// The eight corner voxels of cell `(i, j, k)` (corner index `x + 2y + 4z`).
#[inline(always)]
pub fn cell_corners<T: Voxel>(voxels: &[T], dims: [usize; 3], c: [usize; 3]) -> [T; 8] {
    let nx = dims[0];
    let nxy = dims[0] * dims[1];
    let base = c[0] + nx * c[1] + nxy * c[2];
    [
        voxels[base],
        voxels[base + 1],
        voxels[base + nx],
        voxels[base + nx + 1],
        voxels[base + nxy],
        voxels[base + nxy + 1],
        voxels[base + nxy + nx],
        voxels[base + nxy + nx + 1],
    ]
}

/// A hit inside one cell: ray parameter (traversal units = world `t`), surface index and
/// the cell.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CellHit {
    pub t: f32,
    pub surface: u32,
    pub cell: [usize; 3],
}

impl CellHit {
    /// A placeholder for fixed-size lane arrays (no hit: `t` is infinite).
    pub const NONE: Self = Self {
        t: f32::INFINITY,
        surface: 0,
        cell: [0; 3],
    };
}

/// Intersects the ray with the active isosurfaces inside cell `cell`, within `[t_lo, t_hi]`.
///
/// The segment is the cell's own slab overlap (not the traversal's interval), so every
/// traversal that visits the cell gets bit-identical results. Returns the nearest hit.
#[inline(always)]
pub fn intersect_cell<T: Voxel, C: CellIntersector, S: crate::render::Stats>(
    frame: &TraversalFrame,
    voxels: &[T],
    dims: [usize; 3],
    ray: &LocalRay,
    cell: [usize; 3],
    t_lo: f32,
    t_hi: f32,
    isos: &IsoSet<T>,
    intersector: C,
    stats: &mut S,
) -> Option<CellHit> {
    stats.leaf();
    let corners = cell_corners(voxels, dims, cell);
    let (min, max) = corner_range(&corners)?;
    if !isos.any_in(min, max) {
        return None;
    }
    let (lo, hi) = frame.cell_box(cell);
    intersect_prepared_cell(
        &PreparedCell {
            corners,
            min,
            max,
            lo,
            hi,
            cell,
        },
        ray,
        t_lo,
        t_hi,
        isos,
        intersector,
        stats,
    )
}

/// A cell whose corners, value range and box were loaded once, to be tested against several
/// rays (the rays of a packet that reach the same leaf).
#[derive(Debug, Clone, Copy)]
pub struct PreparedCell<T: Voxel> {
    pub corners: [T; 8],
    pub min: T,
    pub max: T,
    pub lo: Vec3,
    pub hi: Vec3,
    pub cell: [usize; 3],
}

impl<T: Voxel> PreparedCell<T> {
    /// The cell's data, or `None` when no active isovalue can lie in it (void cells
    /// included), i.e. when [`intersect_cell`] returns `None` for every ray.
    #[inline(always)]
    pub fn load(
        frame: &TraversalFrame,
        voxels: &[T],
        dims: [usize; 3],
        cell: [usize; 3],
        isos: &IsoSet<T>,
    ) -> Option<Self> {
        let corners = cell_corners(voxels, dims, cell);
        let (min, max) = corner_range(&corners)?;
        if !isos.any_in(min, max) {
            return None;
        }
        let (lo, hi) = frame.cell_box(cell);
        Some(Self {
            corners,
            min,
            max,
            lo,
            hi,
            cell,
        })
    }
}

/// The rest of [`intersect_cell`] for a loaded cell (bit-identical results; no leaf is
/// counted here).
#[inline(always)]
pub fn intersect_prepared_cell<T: Voxel, C: CellIntersector, S: crate::render::Stats>(
    pc: &PreparedCell<T>,
    ray: &LocalRay,
    t_lo: f32,
    t_hi: f32,
    isos: &IsoSet<T>,
    intersector: C,
    stats: &mut S,
) -> Option<CellHit> {
    let (lo, hi, cell) = (pc.lo, pc.hi, pc.cell);
    let (t_near, t_far) = frame::slab(ray, lo, hi, t_lo, t_hi)?;
    if !(hi.cmpgt(lo).all()) {
        return None; // zero-width cell (explicit coordinates closer than f32 resolution)
    }
    let seg = CellSegment::of(ray, lo, hi, t_near, t_far);
    let mut best: Option<CellHit> = None;
    isos.for_each_in(pc.min, pc.max, |iso, surface| {
        stats.intersection();
        if let Some(s) = intersector.first_root(&pc.corners, iso, &seg) {
            let t = seg.t_at(s).clamp(t_near, t_far);
            if best.is_none_or(|b| t < b.t) {
                best = Some(CellHit { t, surface, cell });
            }
        }
    });
    best
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn intersector_names_round_trip() {
        for i in Intersector::ALL {
            assert_eq!(i.to_string().parse::<Intersector>(), Ok(i));
        }
        assert_eq!(
            "neubauer:5".parse(),
            Ok(Intersector::Neubauer { iterations: 5 })
        );
        assert_eq!("EXACT".parse(), Ok(Intersector::Exact));
        assert!("cubic".parse::<Intersector>().is_err());
        assert_eq!(Intersector::default(), Intersector::Exact);
    }

    #[test]
    fn integer_iso_bounds_are_exact() {
        assert_eq!(native_bounds::<u8>(100.5), Some((100, 101)));
        assert_eq!(native_bounds::<u8>(100.0), Some((100, 100)));
        assert_eq!(native_bounds::<u8>(255.5), None);
        assert_eq!(native_bounds::<u8>(-0.5), None);
        assert_eq!(native_bounds::<i16>(-3.25), Some((-4, -3)));
        assert_eq!(native_bounds::<f32>(f32::NAN), None);
        let s = IsoSet::<u8>::new(&[100.5, 300.0, 7.0]);
        // 100.5 is inside [100, 101] but not [100, 100] or [101, 200].
        assert!(s.any_in(100, 101));
        assert!(!s.any_in(101, 200) || s.any_in(7, 7));
        assert!(!IsoSet::<u8>::new(&[100.5]).any_in(100, 100));
        assert!(!IsoSet::<u8>::new(&[100.5]).any_in(101, 200));
        let mut hits = vec![];
        s.for_each_in(0, 255, |c, i| hits.push((c, i)));
        assert_eq!(hits, vec![(100.5, 0), (7.0, 2)]);
        // An empty range (min > max) never matches.
        assert!(!IsoSet::<f32>::new(&[0.0]).any_in(f32::MAX, f32::MIN));
    }

    #[test]
    fn mapped_isovalues_are_stored_units() {
        // CT: HU = stored − 1024; bone at 500 HU is stored 1524, air at −1000.5 HU between
        // stored 23 and 24.
        let m = ValueMap::new(1.0, -1024.0).unwrap();
        let s = IsoSet::<u16>::mapped(&[500.0, -1000.5], m);
        assert!(s.any_in(1524, 1524) && !s.any_in(1525, 2000));
        assert!(s.any_in(23, 24) && !s.any_in(24, 30));
        let mut v = vec![];
        s.for_each_in(0, 4095, |c, i| v.push((c, i)));
        assert_eq!(v, vec![(1524.0, 0), (23.5, 1)]);
        // A physical isovalue below the stored type's range is dropped.
        assert!(IsoSet::<u16>::mapped(&[-2000.0], m).is_empty());
    }

    #[test]
    fn more_isovalues_than_inline_capacity_still_work() {
        let isos: Vec<f32> = (0..40).map(|i| i as f32).collect();
        let s = IsoSet::<u8>::new(&isos);
        let mut n = 0;
        s.for_each_in(30, 35, |_, _| n += 1);
        assert_eq!(n, 6);
    }

    #[test]
    fn void_and_infinite_cells_have_no_range() {
        let mut c = [1.0f32; 8];
        assert_eq!(corner_range(&c), Some((1.0, 1.0)));
        c[3] = f32::NAN;
        assert_eq!(corner_range(&c), None);
        c[3] = f32::INFINITY;
        assert_eq!(corner_range(&c), None);
    }
}
