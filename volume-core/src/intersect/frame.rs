//! The traversal frame: where rays meet the cells of a rectilinear grid.
//!
//! World rays are mapped once per ray into *traversal units* (`grid_from_world`, then the
//! grid origin is subtracted in `f64`, then the per-axis scale): for a uniform axis the
//! traversal coordinate of sample `i` is exactly `i`, so traversal runs in cell units however
//! far the volume sits from the origin (origin 1e6) and however tiny or huge the spacing is.
//! Explicit (rectilinear) axes are scaled by their mean spacing, so their samples sit close
//! to `i` as well. The mapping is affine, so the ray parameter `t` is preserved: a hit at `t`
//! in traversal space is the hit at `t` along the world ray (the direction is not
//! renormalised). The per-axis sample tables [`TraversalFrame::pos`] are the kd-tree's split
//! positions (thesis seed 004 §7.3.1); a spacing edit rebuilds only them (§7.6).

use glam::{DAffine3, DMat3, DVec3, Mat3, Vec3};

use crate::math::{Aabb, Ray};
use crate::volume::{AxisCoords, Grid};

/// A ray in traversal units.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LocalRay {
    pub origin: Vec3,
    pub dir: Vec3,
    /// `1 / dir` (`±inf` for zero components; traversal tests `dir == 0` explicitly).
    pub inv_dir: Vec3,
}

impl LocalRay {
    pub fn new(origin: Vec3, dir: Vec3) -> Self {
        Self {
            origin,
            dir,
            inv_dir: dir.recip(),
        }
    }
}

/// Grid geometry in traversal units plus the transforms in and out of world space.
#[derive(Debug, Clone)]
pub struct TraversalFrame {
    grid_from_world: Option<DAffine3>,
    world_from_grid: Option<DAffine3>,
    origin_grid: DVec3,
    units_per_grid: DVec3,
    /// Sample positions per axis in traversal units (`pos[a][0] == 0`); written only with
    /// what derives from them ([`TraversalFrame::set_positions`]).
    pos: [Box<[f32]>; 3],
    cells: [usize; 3],
    /// Maps a gradient in traversal units to a world-space gradient
    /// (`M⁻ᵀ · diag(units_per_grid)`, with `M` the linear part of `world_from_grid`).
    world_gradient_from_local: DMat3,
    /// The same in `f32`, for the shading normals of the common case
    /// ([`TraversalFrame::world_normal_f32`]).
    world_gradient_from_local_f32: Mat3,
    world_bounds: Aabb,
    /// The far corner of the volume in traversal units (`pos[a][cells[a]]`; zero when empty).
    upper: Vec3,
    /// Per axis, the width of every two-cell span, `pos[a][k + 2] − pos[a][k]` (as `f32`
    /// computes it), when it is one value along the whole axis (2 on a uniform axis, `2^(l+1)`
    /// in a level-`l` treelet of one); `None` otherwise. Kept with `pos` by
    /// [`TraversalFrame::set_positions`].
    central_width: [Option<f32>; 3],
}

impl TraversalFrame {
    pub fn new(grid: &Grid) -> Self {
        let dims = grid.dims();
        let cells = grid.cell_dims();
        let origin_grid = grid.origin();
        let mut units = [1.0f64; 3];
        let pos: [Box<[f32]>; 3] = std::array::from_fn(|a| match grid.axis(a) {
            AxisCoords::Uniform { spacing, .. } => {
                units[a] = 1.0 / spacing;
                (0..dims[a]).map(|i| i as f32).collect()
            }
            AxisCoords::Explicit(c) => {
                let span = c[c.len() - 1] - c[0];
                if cells[a] > 0 && span > 0.0 {
                    units[a] = cells[a] as f64 / span;
                }
                c.iter().map(|x| ((x - c[0]) * units[a]) as f32).collect()
            }
        });
        let units_per_grid = DVec3::from(units);
        let m = grid
            .world_from_grid()
            .map_or(DMat3::IDENTITY, |w| w.matrix3);
        let world_gradient_from_local =
            m.inverse().transpose() * DMat3::from_diagonal(units_per_grid);
        let (lo, hi) = grid.grid_bounds();
        let world_bounds = match grid.world_from_grid() {
            None => Aabb::new(lo.as_vec3(), hi.as_vec3()),
            Some(w) => {
                let mut b = Aabb::EMPTY;
                for c in 0..8 {
                    let p = DVec3::new(
                        if c & 1 == 0 { lo.x } else { hi.x },
                        if c & 2 == 0 { lo.y } else { hi.y },
                        if c & 4 == 0 { lo.z } else { hi.z },
                    );
                    b = b.grow(w.transform_point3(p).as_vec3());
                }
                b
            }
        };
        let upper = if cells.contains(&0) {
            Vec3::ZERO
        } else {
            Vec3::from([0, 1, 2].map(|a| pos[a][cells[a]]))
        };
        let widths = pos.each_ref().map(|p| central_width(p));
        Self {
            grid_from_world: grid.world_from_grid().map(|w| w.inverse()),
            world_from_grid: grid.world_from_grid(),
            origin_grid,
            units_per_grid,
            pos,
            cells,
            world_gradient_from_local,
            world_gradient_from_local_f32: world_gradient_from_local.as_mat3(),
            world_bounds,
            upper,
            central_width: widths,
        }
    }

    /// Replaces the sample positions (a treelet's, from the whole volume's) and what is
    /// derived from them for the shading normals.
    pub(crate) fn set_positions(&mut self, pos: [Box<[f32]>; 3]) {
        self.central_width = pos.each_ref().map(|p| central_width(p));
        self.pos = pos;
    }

    /// Sample positions per axis in traversal units (`pos()[a][0] == 0` for a whole volume).
    #[inline(always)]
    pub fn pos(&self) -> &[Box<[f32]>; 3] {
        &self.pos
    }

    /// The width `pos[a][k + 2] − pos[a][k]` shared by every `k` along axis `a`, if there is
    /// one (a central difference's span: 2 on a uniform axis).
    #[inline]
    pub(crate) fn central_width(&self, a: usize) -> Option<f32> {
        self.central_width[a]
    }

    /// World length of a cell along each grid axis (the mean cell of an explicit axis);
    /// 1 where it is not a positive finite number.
    pub fn cell_width_world(&self) -> [f64; 3] {
        let m = self.world_from_grid.map_or(DMat3::IDENTITY, |w| w.matrix3);
        [0, 1, 2].map(|a| {
            let w = m.col(a).length() / self.units_per_grid[a];
            if w.is_finite() && w > 0.0 { w } else { 1.0 }
        })
    }

    /// Cells per axis (`dims − 1`).
    pub fn cells(&self) -> [usize; 3] {
        self.cells
    }

    /// True when some axis has no cell (a 1-sample axis): such a volume has no surface.
    pub fn is_empty(&self) -> bool {
        self.cells.contains(&0)
    }

    pub fn world_bounds(&self) -> Aabb {
        self.world_bounds
    }

    /// World bounds around the inclusive cell box `[lo, hi]`, one cell wider on every side
    /// (kept inside [`TraversalFrame::world_bounds`]): a ray's clipped interval then starts
    /// and ends at least a cell's width away from every cell of the box, far beyond the
    /// rounding of the world slab test, so the cells' own slab tests decide as with the
    /// whole volume's bounds. The whole grid gives the volume's bounds exactly.
    pub fn world_bounds_of_cells(&self, lo: [usize; 3], hi: [usize; 3]) -> Aabb {
        if self.is_empty() {
            return Aabb::EMPTY;
        }
        let s_lo = [0, 1, 2].map(|a| lo[a].min(self.cells[a]).saturating_sub(1));
        let s_hi = [0, 1, 2].map(|a| (hi[a] + 2).min(self.cells[a]));
        if s_lo == [0; 3] && s_hi == self.cells {
            return self.world_bounds;
        }
        let grid_at = |a: usize, s: usize| {
            self.origin_grid[a] + f64::from(self.pos[a][s]) / self.units_per_grid[a]
        };
        let mut b = Aabb::EMPTY;
        for c in 0..8 {
            let p = DVec3::from(
                [0, 1, 2].map(|a| grid_at(a, if c >> a & 1 == 0 { s_lo[a] } else { s_hi[a] })),
            );
            let w = self.world_from_grid.map_or(p, |m| m.transform_point3(p));
            b = b.grow(w.as_vec3());
        }
        // The `f32` corners (far from the origin, an ulp can exceed a fine cell) and the
        // `f32` sample positions of explicit axes round: a few ulps and a relative hair
        // more, then the volume's own faces wherever the box reaches them.
        b.widened_within(&self.world_bounds)
    }

    /// The world ray in traversal units (f64 transform, then f32).
    #[inline]
    pub fn to_local(&self, ray: &Ray) -> LocalRay {
        LocalRay::new(self.local_origin(ray.origin), self.local_dir(ray.dir))
    }

    /// The origin part of [`TraversalFrame::to_local`] (a point, independent of the
    /// direction: rays from one eye share it).
    #[inline]
    pub fn local_origin(&self, origin: Vec3) -> Vec3 {
        let mut o = origin.as_dvec3();
        if let Some(inv) = self.grid_from_world {
            o = inv.transform_point3(o);
        }
        ((o - self.origin_grid) * self.units_per_grid).as_vec3()
    }

    /// The direction part of [`TraversalFrame::to_local`].
    #[inline]
    pub fn local_dir(&self, dir: Vec3) -> Vec3 {
        let mut d = dir.as_dvec3();
        if let Some(inv) = self.grid_from_world {
            d = inv.transform_vector3(d);
        }
        let mut d = (d * self.units_per_grid).as_vec3();
        // Components negligible against the largest become exactly 0, so every nonzero
        // component has a finite reciprocal (traversal treats 0 as "in the plane").
        let tiny = d.abs().max_element() * 1e-20;
        for a in 0..3 {
            if d[a].abs() <= tiny {
                d[a] = 0.0;
            }
        }
        d
    }

    /// [`TraversalFrame::to_local`] and [`TraversalFrame::clip`] for up to `N` rays at once:
    /// `local[i]` and, where the ray meets the bounds within `[t_min[i], t_max[i]]`, that
    /// range in `t0[i]`, `t1[i]` (else `+inf`, `-inf`). The directions' `f64` transform,
    /// reciprocals and slab test run lane-wise over plain arrays (the compiler vectorises
    /// them), with the scalar paths' operations in their order, so every value is
    /// bit-identical to the per-ray calls (tested). Rays from one eye share the origin's
    /// transform. Returns the lanes whose direction has no zero component and the lanes with
    /// each axis' direction positive (bit `i` = ray `i`), which decide
    /// [`crate::kdtree::packet_compatible`].
    #[inline]
    #[allow(clippy::too_many_arguments)]
    pub fn to_local_clipped<const N: usize>(
        &self,
        rays: &[Ray],
        t_min: &[f32],
        t_max: &[f32],
        local: &mut [LocalRay; N],
        t0: &mut [f32; N],
        t1: &mut [f32; N],
    ) -> (u32, [u32; 3]) {
        const { assert!(N <= 32, "lane masks are u32") };
        let n = rays.len().min(N);
        let mut org = [[0.0f32; N]; 3];
        let mut last_origin: Option<([u32; 3], Vec3)> = None;
        // Directions as lanes: `d[axis][ray]`; padding lanes stay 0 and are not returned.
        let mut d = [[0.0f64; N]; 3];
        let (mut lo, mut hi) = ([0.0f32; N], [0.0f32; N]);
        for (i, ray) in rays[..n].iter().enumerate() {
            let bits = ray.origin.to_array().map(f32::to_bits);
            let o = match last_origin {
                Some((b, o)) if b == bits => o,
                _ => {
                    let o = self.local_origin(ray.origin);
                    last_origin = Some((bits, o));
                    o
                }
            };
            for a in 0..3 {
                org[a][i] = o[a];
                d[a][i] = f64::from(ray.dir[a]);
            }
            lo[i] = t_min[i];
            hi[i] = t_max[i];
        }
        if let Some(inv) = self.grid_from_world {
            // glam's `transform_vector3`: x_axis·x + y_axis·y + z_axis·z, left to right.
            let m = inv.matrix3;
            let [x, y, z] = d;
            for (a, da) in d.iter_mut().enumerate() {
                for i in 0..N {
                    da[i] = m.x_axis[a] * x[i] + m.y_axis[a] * y[i] + m.z_axis[a] * z[i];
                }
            }
        }
        let mut dir = [[0.0f32; N]; 3];
        for a in 0..3 {
            let u = self.units_per_grid[a];
            for i in 0..N {
                dir[a][i] = (d[a][i] * u) as f32;
            }
        }
        // `local_dir`'s flush of negligible components (glam's `max_element`: `a > b ? a : b`).
        let gt_max = |a: f32, b: f32| if a > b { a } else { b };
        let mut tiny = [0.0f32; N];
        for i in 0..N {
            let m = gt_max(gt_max(dir[0][i].abs(), dir[1][i].abs()), dir[2][i].abs());
            tiny[i] = m * 1e-20;
        }
        let mut inv = [[0.0f32; N]; 3];
        let mut nonzero = u32::MAX;
        let mut positive = [0u32; 3];
        // Bit `i`: ray `i` parallel to a slab it starts outside of.
        let mut dead = 0u32;
        let empty = self.is_empty();
        for a in 0..3 {
            let upper = self.upper[a];
            for i in 0..N {
                let v = if dir[a][i].abs() <= tiny[i] {
                    0.0
                } else {
                    dir[a][i]
                };
                dir[a][i] = v;
                inv[a][i] = 1.0 / v;
                // `slab` against `[0, upper]`, one axis.
                let o = org[a][i];
                let ta = (0.0 - o) * inv[a][i];
                let tb = (upper - o) * inv[a][i];
                let (near, far) = if v > 0.0 { (ta, tb) } else { (tb, ta) };
                // Selects, not a branch, so that the loop stays in vector lanes; a zero
                // component (rare) is judged by its origin in the scan below.
                let parallel = v == 0.0;
                lo[i] = if parallel { lo[i] } else { lo[i].max(near) };
                hi[i] = if parallel { hi[i] } else { hi[i].min(far) };
            }
            for (i, &v) in dir[a][..n].iter().enumerate() {
                if v == 0.0 {
                    nonzero &= !(1 << i);
                    let o = org[a][i];
                    if !(o >= 0.0 && o <= upper) {
                        dead |= 1 << i;
                    }
                }
                if v > 0.0 {
                    positive[a] |= 1 << i;
                }
            }
        }
        for i in 0..n {
            local[i] = LocalRay {
                origin: Vec3::new(org[0][i], org[1][i], org[2][i]),
                dir: Vec3::new(dir[0][i], dir[1][i], dir[2][i]),
                inv_dir: Vec3::new(inv[0][i], inv[1][i], inv[2][i]),
            };
            let meets = !empty && dead >> i & 1 == 0 && lo[i] <= hi[i];
            (t0[i], t1[i]) = if meets {
                (lo[i], hi[i])
            } else {
                (f32::INFINITY, f32::NEG_INFINITY)
            };
        }
        let lanes = if n >= 32 { u32::MAX } else { (1u32 << n) - 1 };
        (nonzero & lanes, positive)
    }

    /// The ray's overlap with the volume bounds, clipped to `[t_min, t_max]`.
    #[inline]
    pub fn clip(&self, ray: &LocalRay, t_min: f32, t_max: f32) -> Option<(f32, f32)> {
        if self.is_empty() {
            return None;
        }
        slab(ray, Vec3::ZERO, self.upper, t_min, t_max)
    }

    /// Lower and upper corner of cell `c` in traversal units.
    #[inline(always)]
    pub fn cell_box(&self, c: [usize; 3]) -> (Vec3, Vec3) {
        (
            Vec3::new(self.pos[0][c[0]], self.pos[1][c[1]], self.pos[2][c[2]]),
            Vec3::new(
                self.pos[0][c[0] + 1],
                self.pos[1][c[1] + 1],
                self.pos[2][c[2] + 1],
            ),
        )
    }

    /// A gradient in traversal units as a world-space gradient (value per world unit).
    pub fn world_gradient(&self, grad_local: DVec3) -> DVec3 {
        self.world_gradient_from_local * grad_local
    }

    /// World-space unit normal from a gradient in traversal units, or `None` if it is zero
    /// or not finite.
    pub fn world_normal(&self, grad_local: DVec3) -> Option<Vec3> {
        let g = self.world_gradient_from_local * grad_local;
        let n = g.normalize_or_zero();
        (n != DVec3::ZERO && n.is_finite()).then(|| n.as_vec3())
    }

    /// The `f32` matrix of [`Self::world_normal_f32`], for code that repeats its arithmetic
    /// in lanes ([`crate::grid::normals_x8`]).
    pub(crate) fn world_gradient_from_local_f32(&self) -> &Mat3 {
        &self.world_gradient_from_local_f32
    }

    /// [`TraversalFrame::world_normal`] of an `f32` gradient, in `f32` (a shading normal
    /// needs no more); the `f64` path only when `f32` overflows, underflows or has a
    /// non-finite matrix (extreme spacings or values).
    #[inline]
    pub fn world_normal_f32(&self, grad_local: Vec3) -> Option<Vec3> {
        let n = (self.world_gradient_from_local_f32 * grad_local).normalize_or_zero();
        if n != Vec3::ZERO && n.is_finite() {
            Some(n)
        } else {
            self.world_normal(grad_local.as_dvec3())
        }
    }

    /// The cell along axis `a` that contains traversal coordinate `x` (clamped to the grid).
    pub fn locate(&self, a: usize, x: f32) -> usize {
        let n = self.cells[a];
        if n == 0 {
            return 0;
        }
        // `pos` is increasing; the last sample with pos <= x starts the cell.
        let p = &self.pos[a];
        let i = p.partition_point(|&s| s <= x);
        i.saturating_sub(1).min(n - 1)
    }
}

/// Slab test of `ray` against `[lo, hi]`, clipped to `[t_min, t_max]`.
///
/// A zero direction component is decided by the origin alone (inside the closed slab: all
/// `t`; outside: none), so a ray lying in a face plane is inside; no `0·inf` NaN arises.
/// Both adjacent cells compute a shared plane's `t` from the same operands, so consecutive
/// cells tile the ray without gaps.
#[inline(always)]
pub fn slab(ray: &LocalRay, lo: Vec3, hi: Vec3, t_min: f32, t_max: f32) -> Option<(f32, f32)> {
    let mut t0 = t_min;
    let mut t1 = t_max;
    for a in 0..3 {
        let d = ray.dir[a];
        let o = ray.origin[a];
        if d == 0.0 {
            if !(o >= lo[a] && o <= hi[a]) {
                return None;
            }
        } else {
            let inv = ray.inv_dir[a];
            let ta = (lo[a] - o) * inv;
            let tb = (hi[a] - o) * inv;
            let (n, f) = if d > 0.0 { (ta, tb) } else { (tb, ta) };
            t0 = t0.max(n);
            t1 = t1.min(f);
        }
    }
    (t0 <= t1).then_some((t0, t1))
}

/// The `f32` difference `p[k + 2] − p[k]` when it is the same for every `k` (`None` without
/// any `k`: an axis of fewer than 3 samples has no interior cell to read it).
fn central_width(p: &[f32]) -> Option<f32> {
    let mut spans = p.windows(3).map(|w| (w[2] - w[0]).to_bits());
    let first = spans.next()?;
    spans.all(|w| w == first).then_some(f32::from_bits(first))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_central_width_is_shared_only_when_every_two_cell_span_has_it() {
        assert_eq!(central_width(&[0.0, 1.0, 2.0, 3.0, 4.0]), Some(2.0));
        assert_eq!(central_width(&[10.0, 12.0, 14.0, 16.0]), Some(4.0));
        assert_eq!(central_width(&[0.0, 1.0, 3.0, 4.0, 5.0]), None);
        assert_eq!(central_width(&[0.0, 0.5, 1.0, 1.5]), Some(1.0));
        // Fewer than 3 samples: no span.
        assert_eq!(central_width(&[0.0, 7.0]), None);
        // A uniform axis past 2^24 samples: `i as f32` rounds, the spans differ.
        let big: Vec<f32> = ((1 << 24) - 2..(1 << 24) + 4).map(|i| i as f32).collect();
        assert_eq!(central_width(&big), None);
    }

    #[test]
    fn uniform_far_origin_maps_to_index_units_and_keeps_t() {
        let g = Grid::uniform([5, 4, 3], [1e6, -2e6, 3.0], [0.5, 2.0, 1e-3]).unwrap();
        let f = TraversalFrame::new(&g);
        let ray = Ray::new(Vec3::new(1e6 + 1.0, -2e6 + 4.0, 3.001), Vec3::X);
        let l = f.to_local(&ray);
        assert!((l.origin - Vec3::new(2.0, 2.0, 1.0)).abs().max_element() < 1e-3);
        assert_eq!(l.dir, Vec3::new(2.0, 0.0, 0.0));
        assert_eq!(f.pos[1].as_ref(), &[0.0, 1.0, 2.0, 3.0]);
        // Ray parameter preserved: t = 0.5 world units = one sample along x.
        let (t0, t1) = f.clip(&l, 0.0, f32::INFINITY).unwrap();
        assert_eq!(t0, 0.0);
        assert!((t1 - 1.0).abs() < 1e-6);
        assert_eq!(f.locate(0, 2.5), 2);
        assert_eq!(f.locate(0, 9.0), 3);
        assert_eq!(f.locate(0, -1.0), 0);
    }

    #[test]
    fn world_normal_respects_anisotropic_spacing_and_orientation() {
        // f = x_grid (world units); with spacing 2 along x, one traversal unit is 2 mm, so
        // the local gradient (2, 0, 0) is the world gradient (1, 0, 0).
        let g = Grid::uniform([3, 3, 3], [0.0; 3], [2.0, 1.0, 1.0]).unwrap();
        let f = TraversalFrame::new(&g);
        let n = f.world_normal(DVec3::new(2.0, 0.0, 0.0)).unwrap();
        assert!((n - Vec3::X).length() < 1e-6);
        // Rotated 90° about z: grid x becomes world y.
        let rot = DAffine3::from_rotation_z(std::f64::consts::FRAC_PI_2);
        let g = Grid::new([3, 3, 3], g.axes().clone(), Some(rot)).unwrap();
        let f = TraversalFrame::new(&g);
        let n = f.world_normal(DVec3::new(2.0, 0.0, 0.0)).unwrap();
        assert!((n - Vec3::Y).length() < 1e-6);
        assert!(f.world_normal(DVec3::ZERO).is_none());
    }

    /// The `f32` shading normal agrees with the `f64` one to a few ulps on anisotropic,
    /// rotated frames, and gradients that overflow or underflow `f32` after the transform
    /// still get the `f64` normal.
    #[test]
    fn f32_world_normal_matches_the_f64_one_and_falls_back_at_extremes() {
        let rot = DAffine3::from_rotation_z(0.7) * DAffine3::from_rotation_x(-0.3);
        let axes = Grid::uniform([4, 4, 4], [0.0; 3], [0.3, 2.5, 1.1])
            .unwrap()
            .axes()
            .clone();
        let f = TraversalFrame::new(&Grid::new([4, 4, 4], axes, Some(rot)).unwrap());
        let mut rng = crate::math::rng::Rng::new(7);
        for _ in 0..1000 {
            let g = rng.vec3(-50.0, 50.0);
            let (a, b) = (f.world_normal_f32(g), f.world_normal(g.as_dvec3()));
            assert_eq!(a.is_some(), b.is_some(), "{g}");
            if let (Some(a), Some(b)) = (a, b) {
                assert!((a - b).length() < 1e-6, "{g}: {a} vs {b}");
            }
        }
        for g in [Vec3::new(3e37, -1e38, 2e38), Vec3::new(1e-40, 0.0, -2e-41)] {
            let want = f.world_normal(g.as_dvec3()).unwrap();
            assert_eq!(f.world_normal_f32(g), Some(want), "{g}");
        }
        assert!(f.world_normal_f32(Vec3::ZERO).is_none());
    }

    #[test]
    fn lane_wise_set_up_equals_the_per_ray_mapping_and_clip() {
        use crate::math::rng::Rng;
        let mut rng = Rng::new(5);
        let base = Grid::uniform([9, 7, 5], [1e3, -20.0, 3.0], [0.5, 2.0, 0.7]).unwrap();
        let rot = DAffine3::from_rotation_z(0.3) * DAffine3::from_rotation_x(-1.1);
        let grids = [
            base.clone(),
            Grid::new([9, 7, 5], base.axes().clone(), Some(rot)).unwrap(),
            Grid::uniform([1, 7, 5], [0.0; 3], [1.0; 3]).unwrap(),
        ];
        let mut cases = [0usize; 3];
        for g in &grids {
            let f = TraversalFrame::new(g);
            let b = f.world_bounds();
            for _ in 0..400 {
                let n = 1 + rng.below(16) as usize;
                let eye = b.center()
                    + Vec3::new(
                        rng.range_f32(-9.0, 9.0),
                        rng.range_f32(-9.0, 9.0),
                        rng.range_f32(-9.0, 9.0),
                    );
                let shared = rng.below(2) == 0;
                let rays: Vec<Ray> = (0..n)
                    .map(|_| {
                        let o = if shared {
                            eye
                        } else {
                            eye + Vec3::splat(rng.range_f32(-1.0, 1.0))
                        };
                        let mut d = (b.center() - o)
                            + Vec3::new(
                                rng.range_f32(-4.0, 4.0),
                                rng.range_f32(-4.0, 4.0),
                                rng.range_f32(-4.0, 4.0),
                            );
                        // Zero and negligible components (rays in face planes).
                        match rng.below(6) {
                            0 => d.x = 0.0,
                            1 => d.y = d.z * 1e-22,
                            _ => {}
                        }
                        Ray::new(o, d)
                    })
                    .collect();
                let t_min: Vec<f32> = (0..n).map(|_| rng.range_f32(-1.0, 2.0)).collect();
                let t_max: Vec<f32> = (0..n)
                    .map(|_| {
                        if rng.below(2) == 0 {
                            f32::INFINITY
                        } else {
                            rng.range_f32(0.0, 30.0)
                        }
                    })
                    .collect();
                let mut local = [LocalRay::new(Vec3::ZERO, Vec3::ONE); 16];
                let (mut t0, mut t1) = ([0.0; 16], [0.0; 16]);
                let (nonzero, positive) =
                    f.to_local_clipped(&rays, &t_min, &t_max, &mut local, &mut t0, &mut t1);
                let bits = |v: Vec3| v.to_array().map(f32::to_bits);
                for i in 0..n {
                    let want = f.to_local(&rays[i]);
                    assert_eq!(bits(local[i].origin), bits(want.origin), "origin {i}");
                    assert_eq!(bits(local[i].dir), bits(want.dir), "dir {i}");
                    assert_eq!(bits(local[i].inv_dir), bits(want.inv_dir), "inv {i}");
                    let clip = f.clip(&want, t_min[i], t_max[i]);
                    let got = (t0[i] <= t1[i]).then_some((t0[i], t1[i]));
                    assert_eq!(
                        got.map(|(a, b)| (a.to_bits(), b.to_bits())),
                        clip.map(|(a, b)| (a.to_bits(), b.to_bits())),
                        "clip {i}"
                    );
                    if clip.is_none() {
                        assert_eq!((t0[i], t1[i]), (f32::INFINITY, f32::NEG_INFINITY));
                    }
                    cases[usize::from(clip.is_some())] += 1;
                    cases[2] += usize::from(want.dir.x == 0.0);
                    assert_eq!(nonzero >> i & 1 == 1, want.dir.cmpne(Vec3::ZERO).all());
                    for (a, p) in positive.iter().enumerate() {
                        assert_eq!(p >> i & 1 == 1, want.dir[a] > 0.0);
                    }
                }
                assert_eq!(nonzero >> n, 0);
            }
        }
        // Missed, met, and rays in an x face plane.
        assert!(cases.iter().all(|&c| c > 100), "cases {cases:?}");
    }

    #[test]
    fn slab_handles_rays_in_face_planes() {
        let r = LocalRay::new(Vec3::new(-1.0, 1.0, 0.5), Vec3::X);
        assert_eq!(slab(&r, Vec3::ZERO, Vec3::ONE, 0.0, 10.0), Some((1.0, 2.0)));
        let r = LocalRay::new(Vec3::new(-1.0, 1.5, 0.5), Vec3::X);
        assert_eq!(slab(&r, Vec3::ZERO, Vec3::ONE, 0.0, 10.0), None);
    }
}
