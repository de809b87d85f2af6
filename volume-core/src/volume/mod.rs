//! Rectilinear volumes: geometry ([`Grid`]) plus typed voxels ([`VoxelData`]).
//!
//! Convention (thesis, seed 004 §6.1): voxel (i, j, k) is a *sample* (node-centred) at grid
//! position `(x_i, y_j, z_k)`; with uniform spacing `x_i = origin_x + i·spacing_x`, so the
//! volume's bounds are `[origin, origin + (dims − 1)·spacing]` and it has `dims − 1` cells per
//! axis. Voxels are stored x fastest, then y, then z: index `i + nx·(j + ny·k)`.
//!
//! Oriented data (NRRD `space directions`) keeps the grid axis-aligned in its own *grid frame*
//! and carries an optional `world_from_grid` affine (rotation/shear and translation), and the
//! anatomical meaning of its world axes ([`WorldFrame`]).
//!
//! Voxels keep the type the file stores; a [`ValueMap`] (NIfTI `scl_slope`, DICOM
//! RescaleSlope) turns stored values into physical ones, so isovalues, value ranges and
//! histograms are physical while memory stays native.

mod buffer;
mod grid;
mod probe;
mod value_map;
mod world_frame;

pub use buffer::{ByteSource, VoxelBuffer, VoxelData};
pub use grid::{AxisCoords, Grid, MAX_WORLD_COORD, coordinate_overflow};
pub use probe::VolumeProbe;
pub use value_map::{BadValueMap, ValueMap};
pub use world_frame::WorldFrame;

use crate::error::VolumeError;
use crate::stats::{Histogram, ValueStats};

/// A rectilinear volume: its geometry, its voxels in their native type, and the map from
/// stored to physical values.
#[derive(Clone)]
pub struct RectilinearVolume {
    pub grid: Grid,
    pub data: VoxelData,
    /// Stored → physical values (the identity for most files).
    pub value_map: ValueMap,
}

impl RectilinearVolume {
    /// Pairs a grid with voxel data, checking that the voxel count matches.
    pub fn new(grid: Grid, data: VoxelData) -> Result<Self, VolumeError> {
        let expected = grid.voxel_count();
        let actual = data.len();
        if expected != actual {
            return Err(VolumeError::LengthMismatch {
                dims: grid.dims(),
                expected,
                actual,
            });
        }
        Ok(Self {
            grid,
            data,
            value_map: ValueMap::IDENTITY,
        })
    }

    /// The same volume with stored values mapped to physical ones by `value_map`.
    pub fn with_value_map(mut self, value_map: ValueMap) -> Self {
        self.value_map = value_map;
        self
    }

    pub fn dims(&self) -> [usize; 3] {
        self.grid.dims()
    }

    /// Value range in physical units (NaN ignored, infinities counted separately),
    /// computed in parallel over the stored values.
    pub fn value_stats(&self) -> ValueStats {
        let mut s = crate::dispatch_voxels!(&self.data, buf => ValueStats::compute(buf.as_slice()));
        s.finite_range = s.finite_range.map(|r| self.value_map.range_to_physical(r));
        if self.value_map.reverses() {
            std::mem::swap(&mut s.pos_inf_count, &mut s.neg_inf_count);
        }
        s
    }

    /// A `bins`-bin histogram of the physical values in `[lo, hi]`.
    pub fn histogram(&self, lo: f64, hi: f64, bins: usize) -> Histogram {
        let map = self.value_map;
        crate::dispatch_voxels!(&self.data, buf => Histogram::compute_mapped(buf.as_slice(), map, lo, hi, bins))
    }

    /// The stored voxel at `(i, j, k)` as `f64`.
    ///
    /// # Panics
    /// If the index is outside the grid.
    pub fn value_f64(&self, i: usize, j: usize, k: usize) -> f64 {
        let idx = self.grid.linear_index(i, j, k);
        crate::dispatch_voxels!(&self.data, buf => crate::Voxel::to_f64(buf.as_slice()[idx]))
    }

    /// The physical value at `(i, j, k)`.
    pub fn physical_f64(&self, i: usize, j: usize, k: usize) -> f64 {
        self.value_map.to_physical(self.value_f64(i, j, k))
    }
}

impl std::fmt::Debug for RectilinearVolume {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RectilinearVolume")
            .field("grid", &self.grid)
            .field("voxel_type", &self.data.voxel_type())
            .field("value_map", &self.value_map)
            .finish_non_exhaustive()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn value_map_gives_physical_ranges_histograms_and_values() {
        let g = Grid::uniform([4, 1, 1], [0.0; 3], [1.0; 3]).unwrap();
        let stored: Vec<i16> = vec![0, 10, 10, 30];
        let v = RectilinearVolume::new(g, stored.into())
            .unwrap()
            .with_value_map(ValueMap::new(-2.0, 100.0).unwrap());
        // Physical values 100, 80, 80, 40.
        assert_eq!(v.value_stats().finite_range, Some((40.0, 100.0)));
        assert_eq!(v.physical_f64(3, 0, 0), 40.0);
        assert_eq!(v.value_f64(3, 0, 0), 30.0);
        let h = v.histogram(40.0, 100.0, 3);
        // Bins [40, 60), [60, 80), [80, 100]: 40 | none | 80, 80, 100.
        assert_eq!((h.lo, h.hi), (40.0, 100.0));
        assert_eq!(h.counts, vec![1, 0, 3]);
    }
}
