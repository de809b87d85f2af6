//! Rectilinear volumes: geometry ([`Grid`]) plus typed voxels ([`VoxelData`]).
//!
//! Convention (thesis, seed 004 §6.1): voxel (i, j, k) is a *sample* (node-centred) at grid
//! position `(x_i, y_j, z_k)`; with uniform spacing `x_i = origin_x + i·spacing_x`, so the
//! volume's bounds are `[origin, origin + (dims − 1)·spacing]` and it has `dims − 1` cells per
//! axis. Voxels are stored x fastest, then y, then z: index `i + nx·(j + ny·k)`.
//!
//! Oriented data (NRRD `space directions`) keeps the grid axis-aligned in its own *grid frame*
//! and carries an optional `world_from_grid` affine (rotation/shear and translation).

mod buffer;
mod grid;

pub use buffer::{ByteSource, VoxelBuffer, VoxelData};
pub use grid::{AxisCoords, Grid, MAX_WORLD_COORD, coordinate_overflow};

use crate::error::VolumeError;
use crate::stats::ValueStats;

/// A rectilinear volume: its geometry and its voxels in their native type.
#[derive(Clone)]
pub struct RectilinearVolume {
    pub grid: Grid,
    pub data: VoxelData,
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
        Ok(Self { grid, data })
    }

    pub fn dims(&self) -> [usize; 3] {
        self.grid.dims()
    }

    /// Value range (NaN ignored, infinities counted separately), computed in parallel.
    pub fn value_stats(&self) -> ValueStats {
        crate::dispatch_voxels!(&self.data, buf => ValueStats::compute(buf.as_slice()))
    }

    /// The voxel at `(i, j, k)` as `f64`.
    ///
    /// # Panics
    /// If the index is outside the grid.
    pub fn value_f64(&self, i: usize, j: usize, k: usize) -> f64 {
        let idx = self.grid.linear_index(i, j, k);
        crate::dispatch_voxels!(&self.data, buf => crate::Voxel::to_f64(buf.as_slice()[idx]))
    }
}

impl std::fmt::Debug for RectilinearVolume {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RectilinearVolume")
            .field("grid", &self.grid)
            .field("voxel_type", &self.data.voxel_type())
            .finish_non_exhaustive()
    }
}
