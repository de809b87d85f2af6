//! Distance-like fields with analytic isosurfaces: a sphere, a torus and nested offset spheres.
//!
//! All three live on `[−1, 1]³` (node-centred samples `x_i = −1 + 2i/(N−1)`, like
//! Marschner–Lobb) and store a value in *world units*, so an isovalue is a length:
//!
//! - **sphere**: `f(p) = |p − c|` with `c = `[`SPHERE_CENTRE`] (deliberately off the grid's
//!   symmetry axes). The level set `f = r` is exactly the sphere of radius `r`.
//! - **torus**: `f(p) = √((√(dx² + dy²) − R)² + dz²)`, `d = p − c`, the distance to the core
//!   circle of radius `R = `[`TORUS_MAJOR_RADIUS`] in the plane `z = c.z`. The level set `f = r`
//!   (`r < R`) is the torus with tube radius `r`.
//! - **nested spheres**: `f(p) = s` where `p` lies on the sphere with centre `a + s·d` and
//!   radius `s·R` ([`NestedSpheres`]). Every level set is a sphere; with `|d| < R` they are
//!   strictly nested but not concentric, so several isovalues give several offset shells.
//!
//! The *samples* are exact; the trilinear interpolant between them is not. For the sphere the
//! interpolation error is bounded by [`Sphere::trilinear_error_bound`] (the bound intersection
//! tests should use as their tolerance).
//!
//! Voxel types: `f32`/`f64` store the value; integer types map the natural range
//! ([`SPHERE_RANGE`], [`TORUS_RANGE`], [`NESTED_RANGE`]) linearly onto `[0, T::MAX]`
//! (see [`crate::ValueMap`]; the distance `0.5` in a `u8` sphere is `round(0.5 · 255/2)`).

use glam::DVec3;
use volume_core::{RectilinearVolume, VoxelType};

use crate::GenerateError;
use crate::sampling::{ValueMap, sample_field, unit_cube_grid};

/// Centre of the `sphere` generator's field.
pub const SPHERE_CENTRE: DVec3 = DVec3::new(0.1, -0.05, 0.03);
/// A radius that fits the domain well.
pub const SPHERE_SUGGESTED_RADIUS: f64 = 0.6;
/// Natural range used for integer voxel types (the farthest corner is at 1.83).
pub const SPHERE_RANGE: (f64, f64) = (0.0, 2.0);

/// Centre of the torus (its core circle lies in the plane `z = TORUS_CENTRE.z`).
pub const TORUS_CENTRE: DVec3 = DVec3::new(0.0, 0.05, -0.02);
/// Radius `R` of the torus core circle.
pub const TORUS_MAJOR_RADIUS: f64 = 0.55;
/// A tube radius that fits the domain well.
pub const TORUS_SUGGESTED_MINOR_RADIUS: f64 = 0.25;
/// Natural range used for integer voxel types (the farthest corner is at about 1.3).
pub const TORUS_RANGE: (f64, f64) = (0.0, 2.0);

/// Natural range of the nested-spheres level used for integer types (corners reach ~2.45).
pub const NESTED_RANGE: (f64, f64) = (0.0, 2.5);

/// A sphere: analytic truth for ray–isosurface tests.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sphere {
    pub centre: DVec3,
    pub radius: f64,
}

impl Sphere {
    /// The isosurface `value = radius` of the `sphere` generator.
    pub fn of_sphere_field(radius: f64) -> Sphere {
        Sphere {
            centre: SPHERE_CENTRE,
            radius,
        }
    }

    /// Distance from the centre (the `sphere` field itself, for this sphere's centre).
    pub fn centre_distance(&self, p: DVec3) -> f64 {
        (p - self.centre).length()
    }

    /// Signed distance to the surface (negative inside).
    pub fn signed_distance(&self, p: DVec3) -> f64 {
        self.centre_distance(p) - self.radius
    }

    /// Ray parameters `[t_enter, t_exit]` where `origin + t·dir` meets the sphere (`dir` need
    /// not be unit length), or `None` if the line misses it. Roots computed without
    /// cancellation.
    pub fn intersect(&self, origin: DVec3, dir: DVec3) -> Option<[f64; 2]> {
        let oc = origin - self.centre;
        let a = dir.length_squared();
        let half_b = oc.dot(dir);
        let c = oc.length_squared() - self.radius * self.radius;
        // Discriminant via the perpendicular distance: more accurate than b² − ac for far rays.
        let perp = oc - dir * (half_b / a);
        let disc = a * (self.radius * self.radius - perp.length_squared());
        if a == 0.0 || disc < 0.0 {
            return None;
        }
        let q = -(half_b + half_b.signum() * disc.sqrt());
        let (t0, t1) = if q == 0.0 { (0.0, 0.0) } else { (q / a, c / q) };
        Some([t0.min(t1), t0.max(t1)])
    }

    /// Unit outward normal at `p` (on or near the surface).
    pub fn normal(&self, p: DVec3) -> DVec3 {
        (p - self.centre).normalize()
    }

    /// Bound on `|trilinear(p) − |p − c||` for the distance field sampled with `spacing`, at
    /// points within one cell of this sphere's surface. `None` when the sphere is too small
    /// for the bound (a cell near the surface could contain the centre).
    ///
    /// Why: per axis, linear interpolation errs by at most `h²/8 · max|f''|`, the tensor
    /// product adds the three axes' errors, and the distance field's second derivatives are
    /// at most `1/r`. Within one cell diagonal `δ` of the surface, `r ≥ radius − δ`.
    pub fn trilinear_error_bound(&self, spacing: [f64; 3]) -> Option<f64> {
        let h2: f64 = spacing.iter().map(|h| h * h).sum();
        let r_min = self.radius - h2.sqrt();
        (r_min > 0.0).then(|| h2 / (8.0 * r_min))
    }
}

/// Distance from `p` to the torus core circle (centre [`TORUS_CENTRE`], radius
/// [`TORUS_MAJOR_RADIUS`], in a plane of constant z).
pub fn torus_core_distance(p: DVec3) -> f64 {
    let d = p - TORUS_CENTRE;
    (d.x.hypot(d.y) - TORUS_MAJOR_RADIUS).hypot(d.z)
}

/// A one-parameter family of nested, non-concentric spheres: level `s ≥ 0` is the sphere with
/// centre `anchor + s·shift` and radius `s·growth`. Needs `|shift| < growth`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NestedSpheres {
    pub anchor: DVec3,
    pub shift: DVec3,
    pub growth: f64,
}

/// The `nested-spheres` generator's family.
pub const NESTED_SPHERES: NestedSpheres = NestedSpheres {
    anchor: DVec3::new(-0.1, 0.0, 0.0),
    shift: DVec3::new(0.25, 0.1, 0.0),
    growth: 1.0,
};

/// Levels that give three well separated shells inside the domain.
pub const NESTED_SUGGESTED_LEVELS: [f64; 3] = [0.3, 0.55, 0.8];

impl NestedSpheres {
    /// The sphere at level `s`.
    pub fn sphere_at(&self, level: f64) -> Sphere {
        Sphere {
            centre: self.anchor + level * self.shift,
            radius: level * self.growth,
        }
    }

    /// The level `s ≥ 0` of the sphere through `p`: the positive root of
    /// `(R² − |d|²) s² + 2 (q·d) s − |q|² = 0`, `q = p − anchor`, in the cancellation-free
    /// form `s = |q|² / (q·d + √((q·d)² + (R² − |d|²)|q|²))`.
    pub fn level(&self, p: DVec3) -> f64 {
        let q = p - self.anchor;
        let qq = q.length_squared();
        if qq == 0.0 {
            return 0.0;
        }
        let qd = q.dot(self.shift);
        let k = self.growth * self.growth - self.shift.length_squared();
        let root = (qd * qd + k * qq).sqrt();
        if qd >= 0.0 {
            qq / (qd + root)
        } else {
            (root - qd) / k
        }
    }
}

/// Samples the `sphere` field on `dims` over `[−1, 1]³`.
pub fn sphere(
    dims: [usize; 3],
    voxel_type: VoxelType,
    on_slice: &(dyn Fn() + Sync),
) -> Result<RectilinearVolume, GenerateError> {
    let map = ValueMap::range_to_type(SPHERE_RANGE.0, SPHERE_RANGE.1, voxel_type);
    let field = |p: DVec3| (p - SPHERE_CENTRE).length();
    sample_field(unit_cube_grid(dims)?, voxel_type, map, field, on_slice)
}

/// Samples the `torus` field on `dims` over `[−1, 1]³`.
pub fn torus(
    dims: [usize; 3],
    voxel_type: VoxelType,
    on_slice: &(dyn Fn() + Sync),
) -> Result<RectilinearVolume, GenerateError> {
    let map = ValueMap::range_to_type(TORUS_RANGE.0, TORUS_RANGE.1, voxel_type);
    sample_field(
        unit_cube_grid(dims)?,
        voxel_type,
        map,
        torus_core_distance,
        on_slice,
    )
}

/// Samples the `nested-spheres` field on `dims` over `[−1, 1]³`.
pub fn nested_spheres(
    dims: [usize; 3],
    voxel_type: VoxelType,
    on_slice: &(dyn Fn() + Sync),
) -> Result<RectilinearVolume, GenerateError> {
    let map = ValueMap::range_to_type(NESTED_RANGE.0, NESTED_RANGE.1, voxel_type);
    let field = |p: DVec3| NESTED_SPHERES.level(p);
    sample_field(unit_cube_grid(dims)?, voxel_type, map, field, on_slice)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn trilinear(v: &RectilinearVolume, p: DVec3) -> f64 {
        let s = v.grid.uniform_spacing().unwrap();
        let o = v.grid.origin();
        let dims = v.dims();
        let mut idx = [0usize; 3];
        let mut frac = [0.0; 3];
        for a in 0..3 {
            let u = (p[a] - o[a]) / s[a];
            let i = (u.floor() as usize).min(dims[a] - 2);
            idx[a] = i;
            frac[a] = u - i as f64;
        }
        let mut sum = 0.0;
        for c in 0..8usize {
            let (di, dj, dk) = (c & 1, (c >> 1) & 1, (c >> 2) & 1);
            let w = [di, dj, dk]
                .iter()
                .zip(frac)
                .map(|(&d, f)| if d == 1 { f } else { 1.0 - f })
                .product::<f64>();
            sum += w * v.value_f64(idx[0] + di, idx[1] + dj, idx[2] + dk);
        }
        sum
    }

    #[test]
    fn sphere_samples_are_exact_distances() {
        let n = 33;
        let v = sphere([n, n, n], VoxelType::F64, &|| {}).unwrap();
        for (i, j, k) in [(0, 0, 0), (16, 16, 16), (32, 5, 17), (9, 31, 2)] {
            let x = |i: usize| -1.0 + 2.0 * i as f64 / 32.0;
            let (dx, dy, dz) = (x(i) - 0.1, x(j) + 0.05, x(k) - 0.03);
            let want = (dx * dx + dy * dy + dz * dz).sqrt();
            assert!((v.value_f64(i, j, k) - want).abs() < 1e-14);
        }
    }

    #[test]
    fn sphere_interpolant_stays_within_the_error_bound_near_the_surface() {
        let n = 24;
        let v = sphere([n, n, n], VoxelType::F64, &|| {}).unwrap();
        let s = Sphere::of_sphere_field(SPHERE_SUGGESTED_RADIUS);
        let bound = s
            .trilinear_error_bound(v.grid.uniform_spacing().unwrap())
            .unwrap();
        // Deterministic spiral of points on the sphere: the interpolant there must be within
        // `bound` of the radius.
        let mut worst = 0.0f64;
        for m in 0..2000 {
            let z = 1.0 - 2.0 * (m as f64 + 0.5) / 2000.0;
            let phi = m as f64 * 2.399_963_229_728_653; // golden angle
            let rxy = (1.0 - z * z).sqrt();
            let p = s.centre + s.radius * DVec3::new(rxy * phi.cos(), rxy * phi.sin(), z);
            worst = worst.max((trilinear(&v, p) - s.radius).abs());
        }
        assert!(worst <= bound, "worst {worst} > bound {bound}");
        // The bound is not vacuous: the interpolant does deviate measurably.
        assert!(worst > bound / 20.0);
    }

    #[test]
    fn sphere_ray_intersection_matches_the_surface() {
        let s = Sphere::of_sphere_field(0.6);
        let o = DVec3::new(-3.0, 0.2, 0.1);
        let d = DVec3::new(1.0, -0.05, 0.02);
        let [t0, t1] = s.intersect(o, d).unwrap();
        assert!(t0 < t1);
        for t in [t0, t1] {
            assert!(s.signed_distance(o + t * d).abs() < 1e-12);
        }
        // Through the centre along x: entry/exit at centre ∓ r.
        let o = DVec3::new(-5.0, s.centre.y, s.centre.z);
        let [t0, t1] = s.intersect(o, DVec3::X).unwrap();
        assert!((t0 - (s.centre.x - 0.6 + 5.0)).abs() < 1e-12);
        assert!((t1 - (s.centre.x + 0.6 + 5.0)).abs() < 1e-12);
        assert!(s.intersect(DVec3::new(0.0, 2.0, 0.0), DVec3::X).is_none());
        assert!(s.intersect(o, DVec3::ZERO).is_none());
    }

    #[test]
    fn torus_samples_are_distances_to_the_core_circle() {
        let n = 21;
        let v = torus([n, n, n], VoxelType::F64, &|| {}).unwrap();
        for (i, j, k) in [(0, 0, 0), (10, 10, 10), (17, 3, 12), (20, 20, 0)] {
            let p = v.grid.grid_position(i, j, k);
            // Brute force: nearest of many points on the core circle.
            let brute = (0..20_000)
                .map(|m| {
                    let a = m as f64 / 20_000.0 * std::f64::consts::TAU;
                    let q = TORUS_CENTRE
                        + DVec3::new(
                            TORUS_MAJOR_RADIUS * a.cos(),
                            TORUS_MAJOR_RADIUS * a.sin(),
                            0.0,
                        );
                    (p - q).length()
                })
                .fold(f64::INFINITY, f64::min);
            assert!((v.value_f64(i, j, k) - brute).abs() < 1e-6, "{i} {j} {k}");
        }
        let (_, hi) = v.value_stats().finite_range.unwrap();
        assert!(hi < TORUS_RANGE.1);
    }

    #[test]
    fn nested_levels_are_spheres_and_nest() {
        let f = NESTED_SPHERES;
        for level in [0.1, 0.3, 0.55, 0.8, 1.7] {
            let s = f.sphere_at(level);
            for m in 0..50 {
                let a = m as f64 * 0.7;
                let b = m as f64 * 0.31 - 1.0;
                let dir = DVec3::new(a.cos() * b.cos(), a.sin() * b.cos(), b.sin());
                let p = s.centre + s.radius * dir;
                assert!(
                    (f.level(p) - level).abs() < 1e-12,
                    "level {level} dir {dir}"
                );
            }
        }
        // Strictly nested: each suggested shell lies inside the next one.
        for w in NESTED_SUGGESTED_LEVELS.windows(2) {
            let (inner, outer) = (f.sphere_at(w[0]), f.sphere_at(w[1]));
            assert!((outer.centre - inner.centre).length() + inner.radius < outer.radius);
        }
        let v = nested_spheres([17, 17, 17], VoxelType::F64, &|| {}).unwrap();
        let (lo, hi) = v.value_stats().finite_range.unwrap();
        assert!(lo >= 0.0 && hi < NESTED_RANGE.1);
    }

    #[test]
    fn integer_sphere_quantizes_distance_over_zero_to_two() {
        let f = sphere([9, 9, 9], VoxelType::F64, &|| {}).unwrap();
        let u = sphere([9, 9, 9], VoxelType::U16, &|| {}).unwrap();
        let m = ValueMap::range_to_type(0.0, 2.0, VoxelType::U16);
        for (i, j, k) in [(0, 0, 0), (4, 4, 4), (8, 1, 3)] {
            assert_eq!(
                u.value_f64(i, j, k),
                (f.value_f64(i, j, k) * 65535.0 / 2.0).round()
            );
            assert!((m.to_natural(u.value_f64(i, j, k)) - f.value_f64(i, j, k)).abs() < 2e-5);
        }
    }
}
