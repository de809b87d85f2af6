//! Sampling a scalar field onto a grid, in parallel, in any voxel type.
//!
//! Every generator is a function of the world position `p` (node-centred samples, see
//! `volume_core::volume`), evaluated in `f64` and then stored through a [`ValueMap`]: float
//! types keep the field's natural value, integer types get a documented linear map (rounded
//! and saturated by [`Voxel::from_f64`]). Slices along z are filled in parallel with rayon.

use glam::DVec3;
use rayon::prelude::*;
use volume_core::{Grid, RectilinearVolume, Voxel, VoxelData, VoxelType};

use crate::GenerateError;

/// The linear map from a field's natural value to the stored voxel value:
/// `stored = natural · scale + offset` (then rounded and saturated to the voxel type).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ValueMap {
    pub scale: f64,
    pub offset: f64,
}

impl ValueMap {
    /// Stores natural values unchanged (float types).
    pub const IDENTITY: ValueMap = ValueMap {
        scale: 1.0,
        offset: 0.0,
    };

    /// The map used by the analytic generators: float types store the natural value; integer
    /// types map the natural range `[lo, hi]` linearly onto `[0, T::MAX]` of the type.
    pub fn range_to_type(lo: f64, hi: f64, voxel_type: VoxelType) -> ValueMap {
        if voxel_type.is_float() {
            return ValueMap::IDENTITY;
        }
        let scale = type_max(voxel_type) / (hi - lo);
        ValueMap {
            scale,
            offset: -lo * scale,
        }
    }

    /// Natural value → stored value (before rounding).
    #[inline]
    pub fn to_stored(&self, natural: f64) -> f64 {
        natural * self.scale + self.offset
    }

    /// Stored value → natural value, e.g. to turn a stored isovalue back into world units.
    #[inline]
    pub fn to_natural(&self, stored: f64) -> f64 {
        (stored - self.offset) / self.scale
    }
}

/// The largest value of an integer voxel type, as `f64`.
pub(crate) fn type_max(voxel_type: VoxelType) -> f64 {
    match voxel_type {
        VoxelType::U8 => f64::from(u8::MAX),
        VoxelType::I8 => f64::from(i8::MAX),
        VoxelType::U16 => f64::from(u16::MAX),
        VoxelType::I16 => f64::from(i16::MAX),
        VoxelType::U32 => f64::from(u32::MAX),
        VoxelType::I32 => f64::from(i32::MAX),
        VoxelType::F32 => f64::from(f32::MAX),
        VoxelType::F64 => f64::MAX,
    }
}

/// Checks that every axis has at least two samples (a spacing needs two).
pub(crate) fn check_dims(dims: [usize; 3]) -> Result<(), GenerateError> {
    if dims.iter().any(|&n| n < 2) {
        return Err(GenerateError::DimsTooSmall { dims });
    }
    let count = dims[0]
        .checked_mul(dims[1])
        .and_then(|n| n.checked_mul(dims[2]));
    if count.is_none() {
        return Err(GenerateError::Volume(
            volume_core::VolumeError::DimsOverflow { dims },
        ));
    }
    Ok(())
}

/// The grid of the analytic fields: `[-1, 1]` on every axis, `x_i = −1 + i·2/(N−1)`.
pub fn unit_cube_grid(dims: [usize; 3]) -> Result<Grid, GenerateError> {
    check_dims(dims)?;
    let spacing = dims.map(|n| 2.0 / (n - 1) as f64);
    Ok(Grid::uniform(dims, [-1.0; 3], spacing)?)
}

/// Samples `field` (natural values at grid-frame positions) on `grid`, storing through `map`.
/// `on_slice` is called once per finished z-slice (for progress bars).
pub fn sample_field<F>(
    grid: Grid,
    voxel_type: VoxelType,
    map: ValueMap,
    field: F,
    on_slice: &(dyn Fn() + Sync),
) -> Result<RectilinearVolume, GenerateError>
where
    F: Fn(DVec3) -> f64 + Sync,
{
    let positions = grid.clone();
    sample_indexed(
        grid,
        voxel_type,
        map,
        move |[i, j, k]| field(positions.grid_position(i, j, k)),
        on_slice,
    )
}

/// [`sample_field`] for a field given per sample index `[i, j, k]` (e.g. values computed
/// beforehand and post-processed).
pub fn sample_indexed<F>(
    grid: Grid,
    voxel_type: VoxelType,
    map: ValueMap,
    field: F,
    on_slice: &(dyn Fn() + Sync),
) -> Result<RectilinearVolume, GenerateError>
where
    F: Fn([usize; 3]) -> f64 + Sync,
{
    let dims = grid.dims();
    let data: VoxelData = match voxel_type {
        VoxelType::U8 => fill::<u8, _>(dims, map, &field, on_slice)?.into(),
        VoxelType::I8 => fill::<i8, _>(dims, map, &field, on_slice)?.into(),
        VoxelType::U16 => fill::<u16, _>(dims, map, &field, on_slice)?.into(),
        VoxelType::I16 => fill::<i16, _>(dims, map, &field, on_slice)?.into(),
        VoxelType::U32 => fill::<u32, _>(dims, map, &field, on_slice)?.into(),
        VoxelType::I32 => fill::<i32, _>(dims, map, &field, on_slice)?.into(),
        VoxelType::F32 => fill::<f32, _>(dims, map, &field, on_slice)?.into(),
        VoxelType::F64 => fill::<f64, _>(dims, map, &field, on_slice)?.into(),
    };
    Ok(RectilinearVolume::new(grid, data)?)
}

fn fill<T: Voxel, F>(
    dims: [usize; 3],
    map: ValueMap,
    field: &F,
    on_slice: &(dyn Fn() + Sync),
) -> Result<Vec<T>, GenerateError>
where
    F: Fn([usize; 3]) -> f64 + Sync,
{
    let count = dims.iter().product::<usize>();
    let bytes = count.saturating_mul(size_of::<T>());
    let mut voxels: Vec<T> = Vec::new();
    // A clear error instead of an abort when the requested size does not fit in memory.
    voxels
        .try_reserve_exact(count)
        .map_err(|_| GenerateError::OutOfMemory { bytes })?;
    voxels.resize(count, T::default());
    let [nx, ny, _] = dims;
    voxels
        .par_chunks_mut(nx * ny)
        .enumerate()
        .for_each(|(k, slice)| {
            for j in 0..ny {
                for i in 0..nx {
                    slice[i + nx * j] = T::from_f64(map.to_stored(field([i, j, k])));
                }
            }
            on_slice();
        });
    Ok(voxels)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unit_cube_grid_spans_minus_one_to_one() {
        let g = unit_cube_grid([5, 3, 2]).unwrap();
        let (lo, hi) = g.grid_bounds();
        assert_eq!(lo, DVec3::splat(-1.0));
        assert_eq!(hi, DVec3::splat(1.0));
        assert_eq!(g.uniform_spacing(), Some([0.5, 1.0, 2.0]));
        assert!(matches!(
            unit_cube_grid([5, 1, 2]),
            Err(GenerateError::DimsTooSmall { .. })
        ));
    }

    #[test]
    fn range_map_sends_the_natural_range_to_zero_and_type_max() {
        let m = ValueMap::range_to_type(-2.0, 6.0, VoxelType::U8);
        assert_eq!(m.to_stored(-2.0), 0.0);
        assert_eq!(m.to_stored(6.0), 255.0);
        assert!((m.to_natural(m.to_stored(1.25)) - 1.25).abs() < 1e-12);
        assert_eq!(
            ValueMap::range_to_type(-2.0, 6.0, VoxelType::F32),
            ValueMap::IDENTITY
        );
        let m = ValueMap::range_to_type(0.0, 1.0, VoxelType::I16);
        assert_eq!(m.to_stored(1.0), 32767.0);
    }

    #[test]
    fn sampling_stores_each_voxel_at_its_grid_position() {
        let g = Grid::uniform([3, 4, 5], [1.0, 2.0, 3.0], [0.5, 1.0, 2.0]).unwrap();
        let v = sample_field(
            g,
            VoxelType::F64,
            ValueMap::IDENTITY,
            |p| p.x + 10.0 * p.y + 100.0 * p.z,
            &|| {},
        )
        .unwrap();
        for (i, j, k) in [(0, 0, 0), (2, 3, 4), (1, 2, 3)] {
            let (x, y, z) = (1.0 + 0.5 * i as f64, 2.0 + j as f64, 3.0 + 2.0 * k as f64);
            assert_eq!(v.value_f64(i, j, k), x + 10.0 * y + 100.0 * z);
        }
    }
}
