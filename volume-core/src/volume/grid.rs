//! Grid geometry: dimensions, per-axis sample coordinates and orientation.

use std::sync::Arc;

use glam::{DAffine3, DVec3};

use super::world_frame::WorldFrame;
use crate::error::VolumeError;

/// Sample coordinates along one axis, in the grid frame (world units, e.g. millimetres).
#[derive(Debug, Clone, PartialEq)]
pub enum AxisCoords {
    /// `x_i = origin + i·spacing`, `spacing > 0`.
    Uniform { origin: f64, spacing: f64 },
    /// Explicit, strictly increasing coordinates, one per sample.
    Explicit(Arc<[f64]>),
}

impl AxisCoords {
    /// Coordinate of sample `i` (no bounds check for uniform axes).
    #[inline]
    pub fn coord(&self, i: usize) -> f64 {
        match self {
            AxisCoords::Uniform { origin, spacing } => origin + i as f64 * spacing,
            AxisCoords::Explicit(c) => c[i],
        }
    }

    pub fn is_uniform(&self) -> bool {
        matches!(self, AxisCoords::Uniform { .. })
    }
}

/// Largest magnitude a sample's world coordinate may have. The renderer works in `f32` and
/// squares lengths (bounding-sphere radius, eye distance, `|d|²` in the ray setup); `f32`
/// squares overflow above ~1.8e19, so coordinates are kept below 1e15, which leaves room for
/// the camera's distance factor and sums of squares. Beyond it a volume would open and then
/// fail later as a non-finite camera.
pub const MAX_WORLD_COORD: f64 = 1e15;

/// The first sample coordinate of a grid beyond ±[`MAX_WORLD_COORD`]: `(grid axis, value)`.
/// Checks each axis's first and last sample in the grid frame, then the world positions of
/// the eight corners (reported on the grid axis with the largest extent). Inputs are finite
/// (checked by [`Grid::new`] first).
pub fn coordinate_overflow(
    dims: [usize; 3],
    axes: &[AxisCoords; 3],
    world_from_grid: Option<DAffine3>,
) -> Option<(usize, f64)> {
    let range = |a: usize| match &axes[a] {
        AxisCoords::Uniform { origin, spacing } => {
            (*origin, origin + dims[a].saturating_sub(1) as f64 * spacing)
        }
        // Strictly increasing (checked by `Grid::new`): the ends are the extremes.
        AxisCoords::Explicit(c) => (
            c.first().copied().unwrap_or(0.0),
            c.last().copied().unwrap_or(0.0),
        ),
    };
    let ranges = [range(0), range(1), range(2)];
    for (a, &(lo, hi)) in ranges.iter().enumerate() {
        for x in [lo, hi] {
            if x.abs() > MAX_WORLD_COORD || x.is_nan() {
                return Some((a, x));
            }
        }
    }
    let m = world_from_grid?;
    let widest = (0..3)
        .max_by(|&a, &b| {
            let w = |a: usize| (ranges[a].1 - ranges[a].0).abs();
            w(a).total_cmp(&w(b))
        })
        .unwrap_or(0);
    for corner in 0..8 {
        let pick = |a: usize| {
            if (corner >> a) & 1 == 0 {
                ranges[a].0
            } else {
                ranges[a].1
            }
        };
        let p = m.transform_point3(DVec3::new(pick(0), pick(1), pick(2)));
        if let Some(&x) = p
            .to_array()
            .iter()
            .find(|x| x.abs() > MAX_WORLD_COORD || x.is_nan())
        {
            return Some((widest, x));
        }
    }
    None
}

/// The geometry of a rectilinear volume.
#[derive(Debug, Clone, PartialEq)]
pub struct Grid {
    dims: [usize; 3],
    axes: [AxisCoords; 3],
    /// Maps grid-frame positions to world positions; `None` is the identity.
    world_from_grid: Option<DAffine3>,
    /// What the world axes mean anatomically (RAS, LPS or unknown).
    world_frame: WorldFrame,
}

impl Grid {
    /// A uniform grid: `origin + index · spacing` per axis.
    pub fn uniform(
        dims: [usize; 3],
        origin: [f64; 3],
        spacing: [f64; 3],
    ) -> Result<Self, VolumeError> {
        let axes = [0, 1, 2].map(|a| AxisCoords::Uniform {
            origin: origin[a],
            spacing: spacing[a],
        });
        Self::new(dims, axes, None)
    }

    /// A grid from explicit parts, validated: no zero or overflowing dims, positive finite
    /// spacing, explicit coordinates strictly increasing with one entry per sample, an
    /// invertible finite `world_from_grid`, and every sample within ±[`MAX_WORLD_COORD`].
    pub fn new(
        dims: [usize; 3],
        axes: [AxisCoords; 3],
        world_from_grid: Option<DAffine3>,
    ) -> Result<Self, VolumeError> {
        if dims.contains(&0) {
            return Err(VolumeError::EmptyDims { dims });
        }
        checked_count(dims).ok_or(VolumeError::DimsOverflow { dims })?;
        for (axis, coords) in axes.iter().enumerate() {
            match coords {
                AxisCoords::Uniform { origin, spacing } => {
                    if !origin.is_finite() {
                        return Err(VolumeError::BadAxis {
                            axis,
                            reason: format!("origin {origin} is not finite"),
                        });
                    }
                    if !(spacing.is_finite() && *spacing > 0.0) {
                        return Err(VolumeError::BadAxis {
                            axis,
                            reason: format!("spacing {spacing} must be finite and positive"),
                        });
                    }
                }
                AxisCoords::Explicit(c) => {
                    if c.len() != dims[axis] {
                        return Err(VolumeError::BadAxis {
                            axis,
                            reason: format!("{} coordinates for {} samples", c.len(), dims[axis]),
                        });
                    }
                    if let Some(i) = c.iter().position(|x| !x.is_finite()) {
                        return Err(VolumeError::BadAxis {
                            axis,
                            reason: format!("coordinate {i} is not finite"),
                        });
                    }
                    if let Some(i) = c.windows(2).position(|w| w[1] <= w[0]) {
                        return Err(VolumeError::BadAxis {
                            axis,
                            reason: format!(
                                "coordinates are not strictly increasing at index {}",
                                i + 1
                            ),
                        });
                    }
                }
            }
        }
        if let Some(m) = world_from_grid {
            let det = m.matrix3.determinant();
            if !(det.is_finite() && det != 0.0 && m.translation.is_finite()) {
                return Err(VolumeError::SingularTransform);
            }
        }
        if let Some((axis, x)) = coordinate_overflow(dims, &axes, world_from_grid) {
            return Err(VolumeError::BadAxis {
                axis,
                reason: format!(
                    "a sample lies at coordinate {x:e}, beyond the ±{MAX_WORLD_COORD:e} that \
                     single-precision rendering supports"
                ),
            });
        }
        Ok(Self {
            dims,
            axes,
            world_from_grid,
            world_frame: WorldFrame::Unknown,
        })
    }

    /// The same grid with its world axes given an anatomical meaning.
    pub fn with_world_frame(mut self, frame: WorldFrame) -> Self {
        self.world_frame = frame;
        self
    }

    pub fn world_frame(&self) -> WorldFrame {
        self.world_frame
    }

    /// The world direction (unit length) of grid axis `a`: the column of `world_from_grid`'s
    /// linear part, or the world axis itself.
    pub fn axis_direction(&self, a: usize) -> DVec3 {
        if let Some(m) = self.world_from_grid {
            m.matrix3.col(a).normalize_or_zero()
        } else {
            let mut d = DVec3::ZERO;
            d[a] = 1.0;
            d
        }
    }

    /// The anatomical letter each grid axis points to (`+i → L`, …), or `None` when the
    /// world frame is unknown.
    pub fn axis_letters(&self) -> Option<[char; 3]> {
        let f = self.world_frame;
        Some([
            f.direction_letter(self.axis_direction(0))?,
            f.direction_letter(self.axis_direction(1))?,
            f.direction_letter(self.axis_direction(2))?,
        ])
    }

    pub fn dims(&self) -> [usize; 3] {
        self.dims
    }

    pub fn axes(&self) -> &[AxisCoords; 3] {
        &self.axes
    }

    pub fn axis(&self, a: usize) -> &AxisCoords {
        &self.axes[a]
    }

    pub fn world_from_grid(&self) -> Option<DAffine3> {
        self.world_from_grid
    }

    /// Total number of voxels (checked against overflow at construction).
    pub fn voxel_count(&self) -> usize {
        self.dims[0] * self.dims[1] * self.dims[2]
    }

    /// Number of cells per axis (`dims − 1`, at least 0).
    pub fn cell_dims(&self) -> [usize; 3] {
        self.dims.map(|d| d.saturating_sub(1))
    }

    /// Linear index of voxel `(i, j, k)`, x fastest. 64-bit arithmetic: no wrap above 2^32.
    #[inline]
    pub fn linear_index(&self, i: usize, j: usize, k: usize) -> usize {
        i + self.dims[0] * (j + self.dims[1] * k)
    }

    /// Uniform spacing per axis, or `None` if any axis has explicit coordinates.
    pub fn uniform_spacing(&self) -> Option<[f64; 3]> {
        let mut s = [0.0; 3];
        for (a, c) in self.axes.iter().enumerate() {
            match c {
                AxisCoords::Uniform { spacing, .. } => s[a] = *spacing,
                AxisCoords::Explicit(_) => return None,
            }
        }
        Some(s)
    }

    /// Grid-frame position of sample `(i, j, k)`.
    pub fn grid_position(&self, i: usize, j: usize, k: usize) -> DVec3 {
        DVec3::new(
            self.axes[0].coord(i),
            self.axes[1].coord(j),
            self.axes[2].coord(k),
        )
    }

    /// Grid-frame bounds `[first sample, last sample]` per axis.
    pub fn grid_bounds(&self) -> (DVec3, DVec3) {
        let lo = self.grid_position(0, 0, 0);
        let hi = self.grid_position(self.dims[0] - 1, self.dims[1] - 1, self.dims[2] - 1);
        (lo, hi)
    }

    /// Grid-frame origin (position of voxel 0).
    pub fn origin(&self) -> DVec3 {
        self.grid_position(0, 0, 0)
    }

    /// Replaces the per-axis coordinates (same dims), e.g. a spacing edit (thesis §7.6: only
    /// the kd-tree's split tables depend on these).
    pub fn with_axes(&self, axes: [AxisCoords; 3]) -> Result<Self, VolumeError> {
        Ok(Self::new(self.dims, axes, self.world_from_grid)?.with_world_frame(self.world_frame))
    }
}

/// `x·y·z` without overflow, or `None`.
pub fn checked_count(dims: [usize; 3]) -> Option<usize> {
    dims[0].checked_mul(dims[1])?.checked_mul(dims[2])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn uniform_grid_bounds_follow_node_centred_convention() {
        let g = Grid::uniform([4, 3, 2], [1.0, 2.0, 3.0], [0.5, 1.0, 2.0]).unwrap();
        let (lo, hi) = g.grid_bounds();
        assert_eq!(lo, DVec3::new(1.0, 2.0, 3.0));
        assert_eq!(hi, DVec3::new(1.0 + 3.0 * 0.5, 2.0 + 2.0, 3.0 + 2.0));
        assert_eq!(g.cell_dims(), [3, 2, 1]);
        assert_eq!(g.linear_index(1, 2, 1), 1 + 4 * (2 + 3));
    }

    #[test]
    fn rejects_bad_geometry() {
        assert!(matches!(
            Grid::uniform([0, 1, 1], [0.0; 3], [1.0; 3]),
            Err(VolumeError::EmptyDims { .. })
        ));
        assert!(matches!(
            Grid::uniform([usize::MAX, 2, 2], [0.0; 3], [1.0; 3]),
            Err(VolumeError::DimsOverflow { .. })
        ));
        assert!(matches!(
            Grid::uniform([2, 2, 2], [0.0; 3], [1.0, -1.0, 1.0]),
            Err(VolumeError::BadAxis { axis: 1, .. })
        ));
        let bad = AxisCoords::Explicit(vec![0.0, 2.0, 1.0].into());
        let u = AxisCoords::Uniform {
            origin: 0.0,
            spacing: 1.0,
        };
        assert!(matches!(
            Grid::new([3, 1, 1], [bad, u.clone(), u.clone()], None),
            Err(VolumeError::BadAxis { axis: 0, .. })
        ));
        let singular = DAffine3::from_cols_array(&[
            1.0, 0.0, 0.0, 2.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0,
        ]);
        assert_eq!(
            Grid::new([2, 2, 2], [u.clone(), u.clone(), u], Some(singular)),
            Err(VolumeError::SingularTransform)
        );
    }

    #[test]
    fn rejects_coordinates_beyond_single_precision_rendering() {
        // 255 samples of 1e30: finite in f32, but its squares (camera distance) are not.
        let e = Grid::uniform([256, 2, 2], [0.0; 3], [1e30, 1.0, 1.0]).unwrap_err();
        assert!(
            matches!(&e, VolumeError::BadAxis { axis: 0, reason } if reason.contains("single-precision")),
            "{e}"
        );
        assert!(matches!(
            Grid::uniform([2, 2, 2], [0.0, 0.0, -2e15], [1.0; 3]),
            Err(VolumeError::BadAxis { axis: 2, .. })
        ));
        let u = AxisCoords::Uniform {
            origin: 0.0,
            spacing: 1.0,
        };
        let far = DAffine3::from_translation(DVec3::new(0.0, 5e15, 0.0));
        assert!(matches!(
            Grid::new([2, 3, 2], [u.clone(), u.clone(), u.clone()], Some(far)),
            Err(VolumeError::BadAxis { .. })
        ));
        // Large but representable grids still open.
        assert!(Grid::uniform([256, 2, 2], [-1e14, 0.0, 0.0], [1e11, 1.0, 1.0]).is_ok());
        assert!(Grid::new([2, 2, 2], [u.clone(), u.clone(), u], None).is_ok());
    }

    #[test]
    fn axis_letters_follow_orientation_and_frame() {
        let g = Grid::uniform([2, 2, 2], [0.0; 3], [1.0; 3]).unwrap();
        assert_eq!(g.axis_letters(), None);
        let g = g.with_world_frame(WorldFrame::Lps);
        assert_eq!(g.axis_letters(), Some(['L', 'P', 'S']));
        // A sagittal grid in RAS: i runs posterior-to-anterior, j toward inferior, k left.
        let m = DAffine3::from_cols(
            DVec3::new(0.0, 2.0, 0.0),
            DVec3::new(0.0, 0.0, -1.0),
            DVec3::new(-1.0, 0.0, 0.0),
            DVec3::ZERO,
        );
        let u = AxisCoords::Uniform {
            origin: 0.0,
            spacing: 1.0,
        };
        let s = Grid::new([2, 2, 2], [u.clone(), u.clone(), u], Some(m))
            .unwrap()
            .with_world_frame(WorldFrame::Ras);
        assert_eq!(s.axis_letters(), Some(['A', 'I', 'L']));
        assert_eq!(s.axis_direction(0), DVec3::Y);
        // Edits of the axes keep the frame.
        let e = s.with_axes(s.axes().clone()).unwrap();
        assert_eq!(e.world_frame(), WorldFrame::Ras);
    }

    #[test]
    fn index_arithmetic_does_not_wrap_above_u32() {
        let g = Grid::uniform([2048, 2048, 1100], [0.0; 3], [1.0; 3]).unwrap();
        assert_eq!(g.voxel_count(), 2048usize * 2048 * 1100);
        assert!(g.voxel_count() > u32::MAX as usize);
        assert_eq!(g.linear_index(2047, 2047, 1099), g.voxel_count() - 1);
    }
}
