//! Probing a volume at a world position: which cell holds it, the trilinearly interpolated
//! physical value there and its gradient (the picking of the viewer and `isoscope probe`).
//!
//! The interpolant is the one the isosurface is a level set of (thesis seed 004 §6.1:
//! node-centred samples, trilinear inside each cell), so a probe at a ray's hit returns the
//! isovalue up to the hit's error, and the gradient is that surface's normal direction.
//! Computed in `f64` from the stored voxels through the value map.

use glam::{DAffine3, DVec3};

use super::RectilinearVolume;
use crate::volume::grid::AxisCoords;

/// What a volume holds at one world position.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VolumeProbe {
    /// The position in the grid frame (world = grid frame for axis-aligned data).
    pub grid_position: DVec3,
    /// Continuous voxel index: `i + fx` along each axis, `fx` ∈ [0, 1] the position in the
    /// cell (voxel (i, j, k) is the sample at index (i, j, k)).
    pub index: DVec3,
    /// The voxel nearest to the position.
    pub nearest_voxel: [usize; 3],
    /// Trilinearly interpolated physical value.
    pub value: f64,
    /// Gradient of the interpolant in world units (value per world unit).
    pub gradient_world: DVec3,
}

/// The cell `i` (`0 ..= n − 2`, or 0 on a one-sample axis) holding `x` and the position in
/// it, or `None` if `x` lies outside the samples by more than `slack`.
fn locate(axis: &AxisCoords, n: usize, x: f64, slack: f64) -> Option<(usize, f64)> {
    let (first, last) = (axis.coord(0), axis.coord(n - 1));
    if x.is_nan() || x < first - slack || x > last + slack {
        return None;
    }
    if n == 1 {
        return Some((0, 0.0));
    }
    let i = match axis {
        AxisCoords::Uniform { origin, spacing } => ((x - origin) / spacing).floor() as i64,
        AxisCoords::Explicit(c) => c.partition_point(|&v| v <= x) as i64 - 1,
    }
    .clamp(0, n as i64 - 2) as usize;
    let (x0, x1) = (axis.coord(i), axis.coord(i + 1));
    Some((i, ((x - x0) / (x1 - x0)).clamp(0.0, 1.0)))
}

impl RectilinearVolume {
    /// The volume at `world`, or `None` outside its samples (a relative tolerance of 10⁻⁹
    /// of the extent keeps points on the boundary, where rays enter).
    pub fn probe_world(&self, world: DVec3) -> Option<VolumeProbe> {
        let grid = &self.grid;
        let grid_from_world = grid.world_from_grid().map(|m| m.inverse());
        let p = grid_from_world.map_or(world, |m| m.transform_point3(world));
        let dims = grid.dims();
        let (lo, hi) = grid.grid_bounds();
        let slack = 1e-9 * (hi - lo).length().max(1e-300);
        let mut cell = [0usize; 3];
        let mut f = [0.0f64; 3];
        for a in 0..3 {
            let (i, t) = locate(grid.axis(a), dims[a], p[a], slack)?;
            cell[a] = i;
            f[a] = t;
        }
        // Corner values; a one-sample axis repeats its sample.
        let corner = |c: usize| {
            let idx = [0, 1, 2].map(|a| (cell[a] + ((c >> a) & 1)).min(dims[a] - 1));
            self.physical_f64(idx[0], idx[1], idx[2])
        };
        let v: [f64; 8] = std::array::from_fn(corner);
        let lerp = |a: f64, b: f64, t: f64| a + (b - a) * t;
        let value = {
            let x00 = lerp(v[0], v[1], f[0]);
            let x10 = lerp(v[2], v[3], f[0]);
            let x01 = lerp(v[4], v[5], f[0]);
            let x11 = lerp(v[6], v[7], f[0]);
            lerp(lerp(x00, x10, f[1]), lerp(x01, x11, f[1]), f[2])
        };
        // d/d(fraction) of the trilinear interpolant along each axis, then per grid unit.
        let weight = |c: usize, a: usize| if (c >> a) & 1 == 1 { f[a] } else { 1.0 - f[a] };
        let mut grad_grid = DVec3::ZERO;
        for a in 0..3 {
            let width = if dims[a] > 1 {
                grid.axis(a).coord(cell[a] + 1) - grid.axis(a).coord(cell[a])
            } else {
                continue;
            };
            let mut d = 0.0;
            for (c, value) in v.iter().enumerate() {
                let sign = if (c >> a) & 1 == 1 { 1.0 } else { -1.0 };
                let others: f64 = (0..3).filter(|&b| b != a).map(|b| weight(c, b)).product();
                d += sign * others * value;
            }
            grad_grid[a] = d / width;
        }
        // A gradient is a covector: world = A^{-T} · grid for world = A · grid + t.
        let gradient_world = grid.world_from_grid().map_or(grad_grid, |m: DAffine3| {
            m.matrix3.inverse().transpose() * grad_grid
        });
        let index = DVec3::new(
            cell[0] as f64 + f[0],
            cell[1] as f64 + f[1],
            cell[2] as f64 + f[2],
        );
        let nearest_voxel =
            [0, 1, 2].map(|a| (index[a].round() as usize).min(dims[a].saturating_sub(1)));
        Some(VolumeProbe {
            grid_position: p,
            index,
            nearest_voxel,
            value,
            gradient_world,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::volume::{Grid, ValueMap};
    use std::sync::Arc;

    /// f(x, y, z) = 3x − 2y + 0.5z + 7 sampled on the grid: trilinear interpolation
    /// reproduces a linear function exactly, and its gradient is (3, −2, 0.5).
    fn linear(grid: Grid) -> RectilinearVolume {
        let d = grid.dims();
        let mut values = Vec::with_capacity(grid.voxel_count());
        for k in 0..d[2] {
            for j in 0..d[1] {
                for i in 0..d[0] {
                    let p = grid.grid_position(i, j, k);
                    values.push((3.0 * p.x - 2.0 * p.y + 0.5 * p.z + 7.0) as f32);
                }
            }
        }
        RectilinearVolume::new(grid, values.into()).unwrap()
    }

    fn f(p: DVec3) -> f64 {
        3.0 * p.x - 2.0 * p.y + 0.5 * p.z + 7.0
    }

    #[test]
    fn a_linear_field_is_probed_exactly_on_uniform_and_explicit_axes() {
        let uniform = Grid::uniform([5, 4, 3], [-1.0, 0.0, 2.0], [0.5, 1.0, 2.0]).unwrap();
        let explicit = Grid::new(
            [4, 3, 3],
            [
                AxisCoords::Explicit(Arc::from(vec![0.0, 0.1, 0.5, 2.0])),
                AxisCoords::Uniform {
                    origin: 0.0,
                    spacing: 1.0,
                },
                AxisCoords::Explicit(Arc::from(vec![-1.0, 0.0, 4.0])),
            ],
            None,
        )
        .unwrap();
        for grid in [uniform, explicit] {
            let v = linear(grid.clone());
            let (lo, hi) = grid.grid_bounds();
            for t in [0.0, 0.13, 0.5, 0.77, 1.0] {
                let p = lo + (hi - lo) * DVec3::new(t, 1.0 - t, 0.5 * t + 0.2);
                let probe = v.probe_world(p).unwrap();
                assert!((probe.value - f(p)).abs() < 1e-5, "{p}: {}", probe.value);
                assert!(
                    (probe.gradient_world - DVec3::new(3.0, -2.0, 0.5)).length() < 1e-5,
                    "{}",
                    probe.gradient_world
                );
                // The continuous index maps back to the position.
                for a in 0..3 {
                    let i = probe.index[a].floor().min(grid.dims()[a] as f64 - 2.0) as usize;
                    let frac = probe.index[a] - i as f64;
                    let x = grid.axis(a).coord(i)
                        + frac * (grid.axis(a).coord(i + 1) - grid.axis(a).coord(i));
                    assert!((x - p[a]).abs() < 1e-9);
                }
            }
            assert!(v.probe_world(hi + DVec3::splat(0.01)).is_none());
        }
    }

    #[test]
    fn oriented_volumes_and_value_maps_are_probed_in_world_and_physical_units() {
        // World = rotation of 90° about z plus a shift: world (x, y) = (−y_g, x_g) + t.
        let m = DAffine3::from_rotation_z(std::f64::consts::FRAC_PI_2)
            * DAffine3::from_translation(DVec3::new(0.0, 0.0, 0.0));
        let m = DAffine3::from_translation(DVec3::new(10.0, 0.0, 0.0)) * m;
        let grid = Grid::new(
            [3, 3, 2],
            [0, 1, 2].map(|_| AxisCoords::Uniform {
                origin: 0.0,
                spacing: 1.0,
            }),
            Some(m),
        )
        .unwrap();
        let v = linear(grid).with_value_map(ValueMap::new(2.0, -1.0).unwrap());
        let g = DVec3::new(1.5, 0.25, 0.75);
        let world = m.transform_point3(g);
        let probe = v.probe_world(world).unwrap();
        assert!((probe.grid_position - g).length() < 1e-12);
        assert!((probe.value - (2.0 * f(g) - 1.0)).abs() < 1e-5);
        // Physical gradient 2·(3, −2, 0.5) in the grid frame, rotated into the world.
        let want = m.matrix3 * DVec3::new(6.0, -4.0, 1.0);
        assert!((probe.gradient_world - want).length() < 1e-5);
        assert_eq!(probe.nearest_voxel, [2, 0, 1]);
    }
}
