//! Sampling rectilinear data at hit points, for surfaces coloured by another field
//! ([`crate::render::HitField`]).
//!
//! - [`GridField`] with [`GridQuantity::Value`]: the trilinear interpolant of a volume
//!   (physical values through its [`ValueMap`]), e.g. a second volume on the same grid as the
//!   one drawn ([`VolumeSampler`] owns one with its frame).
//! - [`GridField`] with [`GridQuantity::GradientMagnitude`]: the length of the world-space
//!   gradient, central differences at the samples blended trilinearly — the gradient the
//!   shading normals are made of ([`super::normals::gradient_local_at`], thesis seed 004
//!   §6.4).
//! - [`gradient_magnitude_range`]: the range of that magnitude over the samples (a
//!   colouring's default range), in parallel.
//!
//! A hit position is located from its world coordinates (world → traversal units, then the
//! cell along each axis), so any scene's hits can be coloured; the trilinear interpolant is
//! continuous, so a hit on a cell face reads the same from either side. Voxels stay in their
//! native type; the caller picks the type once ([`crate::dispatch_voxels!`]).

use glam::Vec3;
use rayon::prelude::*;

use crate::intersect::TraversalFrame;
use crate::render::HitField;
use crate::volume::{RectilinearVolume, ValueMap};
use crate::voxel::Voxel;

use super::normals::{gradient_local_at, sample_gradient_local};

/// What a [`GridField`] reads at a position.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum GridQuantity {
    /// The trilinearly interpolated physical value.
    Value,
    /// The length of the physical value's world-space gradient (value per world unit).
    GradientMagnitude,
}

/// Typed voxels on a grid, sampled at world positions (module docs).
#[derive(Debug, Clone, Copy)]
pub struct GridField<'a, T: Voxel> {
    frame: &'a TraversalFrame,
    voxels: &'a [T],
    dims: [usize; 3],
    value_map: ValueMap,
    quantity: GridQuantity,
}

impl<'a, T: Voxel> GridField<'a, T> {
    /// `voxels` laid out on `dims` (x fastest) with the geometry of `frame`; `None` if the
    /// lengths disagree.
    pub fn new(
        frame: &'a TraversalFrame,
        voxels: &'a [T],
        dims: [usize; 3],
        value_map: ValueMap,
        quantity: GridQuantity,
    ) -> Option<Self> {
        let cells = frame.cells();
        let consistent = dims.iter().product::<usize>() == voxels.len()
            && (0..3).all(|a| cells[a] + 1 == dims[a] || (dims[a] == 0 && cells[a] == 0));
        consistent.then_some(Self {
            frame,
            voxels,
            dims,
            value_map,
            quantity,
        })
    }

    /// The cell holding world position `p` (clamped to the grid) and the position in it
    /// (`[0, 1]³`); `None` for a grid without cells.
    fn locate(&self, p: Vec3) -> Option<([usize; 3], Vec3)> {
        if self.frame.is_empty() || !p.is_finite() {
            return None;
        }
        let local = self.frame.local_origin(p);
        let cell = [0, 1, 2].map(|a| self.frame.locate(a, local[a]));
        let (lo, hi) = self.frame.cell_box(cell);
        Some((
            cell,
            ((local - lo) / (hi - lo)).clamp(Vec3::ZERO, Vec3::ONE),
        ))
    }

    /// The quantity at world position `p` (positions outside the grid read its nearest
    /// cell's interpolant at the clamped position); NaN where it is undefined (a void
    /// corner, a grid without cells).
    pub fn value_at_world(&self, p: Vec3) -> f64 {
        let Some((cell, uvw)) = self.locate(p) else {
            return f64::NAN;
        };
        match self.quantity {
            GridQuantity::Value => {
                let d = self.dims;
                let corner = |c: usize| {
                    let i = cell[0] + (c & 1);
                    let j = cell[1] + ((c >> 1) & 1);
                    let k = cell[2] + ((c >> 2) & 1);
                    self.voxels[i + d[0] * (j + d[1] * k)].to_f64()
                };
                let u = uvw.as_dvec3();
                let lerp = |a: f64, b: f64, t: f64| a + (b - a) * t;
                let x00 = lerp(corner(0), corner(1), u.x);
                let x10 = lerp(corner(2), corner(3), u.x);
                let x01 = lerp(corner(4), corner(5), u.x);
                let x11 = lerp(corner(6), corner(7), u.x);
                let stored = lerp(lerp(x00, x10, u.y), lerp(x01, x11, u.y), u.z);
                self.value_map.to_physical(stored)
            }
            GridQuantity::GradientMagnitude => {
                let g = gradient_local_at(self.frame, self.voxels, self.dims, cell, uvw);
                self.frame.world_gradient(g).length() * self.value_map.slope.abs()
            }
        }
    }
}

impl<T: Voxel> HitField for GridField<'_, T> {
    #[inline]
    fn value_at(&self, p: Vec3, _cell: u32) -> f32 {
        self.value_at_world(p) as f32
    }
}

/// Smallest and largest gradient magnitude (physical value per world unit) over the samples
/// of `voxels` on `frame`'s grid, NaN ignored; `None` if there is none (or no cell).
pub fn gradient_magnitude_range<T: Voxel>(
    frame: &TraversalFrame,
    voxels: &[T],
    dims: [usize; 3],
    value_map: ValueMap,
) -> Option<(f64, f64)> {
    if frame.is_empty() || dims.iter().product::<usize>() != voxels.len() {
        return None;
    }
    let slope = value_map.slope.abs();
    (0..dims[2])
        .into_par_iter()
        .map(|k| {
            let mut range: Option<(f64, f64)> = None;
            for j in 0..dims[1] {
                for i in 0..dims[0] {
                    let (_, g) = sample_gradient_local(frame, voxels, dims, [i, j, k]);
                    let m = frame.world_gradient(g).length() * slope;
                    if m.is_finite() {
                        range = Some(range.map_or((m, m), |(lo, hi)| (lo.min(m), hi.max(m))));
                    }
                }
            }
            range
        })
        .reduce(
            || None,
            |a, b| match (a, b) {
                (Some(a), Some(b)) => Some((a.0.min(b.0), a.1.max(b.1))),
                (a, None) => a,
                (None, b) => b,
            },
        )
}

/// A volume to colour surfaces by, with the traversal frame of its grid: sampled
/// trilinearly ([`GridQuantity::Value`]) at the hits of a scene on the same grid.
#[derive(Debug, Clone)]
pub struct VolumeSampler {
    volume: RectilinearVolume,
    frame: TraversalFrame,
}

impl VolumeSampler {
    pub fn new(volume: RectilinearVolume) -> Self {
        let frame = TraversalFrame::new(&volume.grid);
        Self { volume, frame }
    }

    pub fn volume(&self) -> &RectilinearVolume {
        &self.volume
    }

    /// The volume's values as a [`HitField`] (one voxel-type dispatch per call, none per
    /// hit).
    pub fn field(&self) -> Box<dyn HitField + '_> {
        let (frame, dims, map) = (&self.frame, self.volume.dims(), self.volume.value_map);
        crate::dispatch_voxels!(&self.volume.data, b => {
            let field = GridField::new(frame, b.as_slice(), dims, map, GridQuantity::Value)
                .expect("a volume's voxel count matches its grid");
            Box::new(field) as Box<dyn HitField + '_>
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::volume::{AxisCoords, Grid};
    use glam::{DAffine3, DVec3};
    use std::sync::Arc;

    /// `f = 3x − 2y + 0.5z + 7` at the samples of `grid`, as `T`.
    fn linear<T: Voxel>(grid: &Grid, scale: f64) -> Vec<T> {
        let d = grid.dims();
        let mut v = Vec::new();
        for k in 0..d[2] {
            for j in 0..d[1] {
                for i in 0..d[0] {
                    let p = grid.grid_position(i, j, k);
                    v.push(T::from_f64(
                        scale * (3.0 * p.x - 2.0 * p.y + 0.5 * p.z + 7.0),
                    ));
                }
            }
        }
        v
    }

    #[test]
    fn the_gradient_magnitude_of_a_linear_field_is_its_constant_slope() {
        let slope = (9.0f64 + 4.0 + 0.25).sqrt();
        let uniform = Grid::uniform([6, 5, 4], [-1.0, 2.0, 0.5], [0.5, 1.0, 2.0]).unwrap();
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
        // Rotated: world = R · grid, so the world gradient is R · (3, −2, 0.5), same length.
        let rotated = Grid::new(
            [5, 5, 5],
            uniform.axes().clone(),
            Some(DAffine3::from_rotation_z(0.7) * DAffine3::from_translation(DVec3::X)),
        )
        .unwrap();
        for grid in [uniform, explicit, rotated] {
            let frame = TraversalFrame::new(&grid);
            let voxels: Vec<f32> = linear(&grid, 1.0);
            let field = GridField::new(
                &frame,
                &voxels,
                grid.dims(),
                ValueMap::IDENTITY,
                GridQuantity::GradientMagnitude,
            )
            .unwrap();
            let (lo, hi) = grid.grid_bounds();
            for t in [0.0, 0.21, 0.5, 0.93, 1.0] {
                let g = lo + (hi - lo) * DVec3::new(t, 1.0 - t, 0.3 + 0.5 * t);
                let w = grid.world_from_grid().map_or(g, |m| m.transform_point3(g));
                let m = field.value_at(w.as_vec3(), 0);
                assert!((f64::from(m) - slope).abs() < 1e-4, "{g}: {m}");
            }
            let (a, b) =
                gradient_magnitude_range(&frame, &voxels, grid.dims(), ValueMap::IDENTITY).unwrap();
            assert!(
                (a - slope).abs() < 1e-4 && (b - slope).abs() < 1e-4,
                "{a} {b}"
            );
        }
    }

    /// A sphere (|p| = 0.6 on a sampled distance field) coloured by a second volume on the
    /// same grid, g = x: under pure ambient light each hit pixel is the colormap of the
    /// analytic x of its hit point (trilinear interpolation reproduces x exactly).
    #[test]
    fn a_sphere_coloured_by_a_volume_of_x_shows_the_colormap_of_x_at_each_hit() {
        use crate::grid::AnyGridScene;
        use crate::intersect::Intersector;
        use crate::render::{
            Camera, Colormap, Frame, Light, Projection, RayGen, RenderSettings, Surface,
            SurfaceColoring, render_colored_into,
        };
        use std::sync::atomic::AtomicBool;

        let n = 33;
        let grid = Grid::uniform([n; 3], [-1.0; 3], [2.0 / (n - 1) as f64; 3]).unwrap();
        let (mut dist, mut xs) = (Vec::new(), Vec::new());
        for k in 0..n {
            for j in 0..n {
                for i in 0..n {
                    let p = grid.grid_position(i, j, k);
                    dist.push(p.length() as f32);
                    xs.push(p.x as f32);
                }
            }
        }
        let scene = AnyGridScene::new(
            &RectilinearVolume::new(grid.clone(), dist.into()).unwrap(),
            Intersector::Exact,
        );
        let sampler = VolumeSampler::new(RectilinearVolume::new(grid, xs.into()).unwrap());
        let field = sampler.field();
        let settings = RenderSettings {
            width: 48,
            height: 40,
            surfaces: vec![Surface::new(0.6, [1.0, 1.0, 1.0])],
            light: Light {
                ambient: 1.0,
                diffuse: 0.0,
                specular: 0.0,
                ..Light::default()
            },
            ..RenderSettings::default()
        };
        let cam = Camera {
            eye: Vec3::new(0.5, 0.3, 3.0),
            target: Vec3::ZERO,
            up: Vec3::Y,
            vfov_deg: 35.0,
            projection: Projection::Pinhole,
            ortho_height: None,
        };
        let range = [-0.6, 0.6];
        let colorings = [Some(SurfaceColoring {
            field: &*field,
            colormap: Colormap::Viridis,
            range,
        })];
        let mut frame = Frame::default();
        assert!(render_colored_into(
            &scene,
            &cam,
            &settings,
            &colorings,
            &AtomicBool::new(false),
            &mut frame
        ));
        let raygen = RayGen::new(&cam, 48, 40);
        let mut compared = 0;
        for j in 0..40u32 {
            for i in 0..48u32 {
                let p = (j * 48 + i) as usize;
                let t = frame.depth[p];
                if !t.is_finite() {
                    continue;
                }
                let ray = raygen.ray_at(i as f32 + 0.5, j as f32 + 0.5);
                let hit = ray.origin.as_dvec3() + ray.dir.as_dvec3() * f64::from(t);
                let want = Colormap::Viridis.map(hit.x as f32, range);
                for c in 0..3 {
                    let want = (want[c] * 255.0 + 0.5) as i32;
                    let got = i32::from(frame.rgba8[4 * p + c]);
                    assert!((got - want).abs() <= 1, "pixel {i},{j}: {got} vs {want}");
                }
                compared += 1;
            }
        }
        assert!(compared > 300, "{compared}");
    }

    #[test]
    fn values_are_trilinear_and_physical_in_native_types() {
        // Stored i16 = round(10 f), physical = stored / 10: a linear field read back exactly
        // at the samples and up to the rounding in between.
        let grid = Grid::uniform([5, 4, 3], [0.0, 0.0, 0.0], [1.0, 1.0, 1.0]).unwrap();
        let voxels: Vec<i16> = linear(&grid, 10.0);
        let volume = RectilinearVolume::new(grid.clone(), voxels.into())
            .unwrap()
            .with_value_map(ValueMap::new(0.1, 0.0).unwrap());
        let sampler = VolumeSampler::new(volume);
        let field = sampler.field();
        let f = |p: DVec3| 3.0 * p.x - 2.0 * p.y + 0.5 * p.z + 7.0;
        for p in [
            DVec3::new(1.0, 2.0, 1.0),
            DVec3::new(0.25, 1.5, 0.75),
            DVec3::new(3.9, 0.1, 2.0),
        ] {
            let v = field.value_at(p.as_vec3(), 0);
            assert!((f64::from(v) - f(p)).abs() < 0.06, "{p}: {v}");
        }
        // The gradient magnitude is physical too: slope × stored gradient.
        let frame = TraversalFrame::new(&grid);
        let stored: Vec<i16> = linear(&grid, 10.0);
        let g = GridField::new(
            &frame,
            &stored,
            grid.dims(),
            ValueMap::new(0.1, 0.0).unwrap(),
            GridQuantity::GradientMagnitude,
        )
        .unwrap();
        let m = g.value_at(Vec3::new(2.0, 1.5, 1.0), 0);
        assert!((f64::from(m) - (13.25f64).sqrt()).abs() < 0.05, "{m}");
        // A void corner: no value (the flat colour is drawn there).
        let mut with_nan: Vec<f32> = linear(&grid, 1.0);
        with_nan[0] = f32::NAN;
        let v = GridField::new(
            &frame,
            &with_nan,
            grid.dims(),
            ValueMap::IDENTITY,
            GridQuantity::Value,
        )
        .unwrap();
        assert!(v.value_at(Vec3::new(0.5, 0.5, 0.5), 0).is_nan());
        assert!(
            GridField::new(
                &frame,
                &with_nan[1..],
                grid.dims(),
                ValueMap::IDENTITY,
                GridQuantity::Value
            )
            .is_none()
        );
    }
}
