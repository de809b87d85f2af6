//! Volumes that view a numpy array's memory in place (zero-copy).
//!
//! `volume_core` stores voxels either owned or as a view into a shared
//! `ByteSource` (there: a memory map). [`NumpyBytes`] is
//! one more such source: the array's data pointer and length, kept valid by a reference to
//! the array itself. The kd-tree and the renderer then read the array's own memory through
//! the same typed slice as a mapped file, so there is no per-voxel dispatch and no copy; the
//! voxel type stays the array's (`uint8` stays `u8`).
//!
//! Axis convention: a 3D array is indexed `array[z, y, x]` (x is the last axis), whatever
//! its memory order. A C-contiguous array has x fastest in memory, which is the voxel order
//! of the library, so its grid is `dims = [nx, ny, nz]` directly. An F-contiguous array has
//! z fastest: it is viewed in place too, with its grid axes in memory order (grid axis 0 =
//! array axis 0 = z) and a `world_from_grid` that swaps the grid's first and last axes, so the
//! world-space volume is the same as for the C-ordered copy. Other layouts (strided views,
//! non-native byte order) are copied once into a C-contiguous array of the same dtype.
//!
//! The caller must not resize the array, and should not write to it while a render runs (it
//! would see a mix of old and new values); after writing, `Scene.refresh()` refits the
//! kd-tree to the new values.

use std::sync::Arc;

use anyhow::{Context as _, bail};
use glam::{DAffine3, DMat3, DVec3};
use numpy::{PyArrayDescrMethods, PyUntypedArray, PyUntypedArrayMethods};
use pyo3::prelude::*;
use volume_core::volume::ByteSource;
use volume_core::{AxisCoords, Grid, RectilinearVolume, VoxelData, VoxelType};

/// The bytes of a numpy array, kept alive by a reference to the array.
pub struct NumpyBytes {
    /// The array (or the C-contiguous copy made of it); never read from Rust.
    _owner: Py<PyAny>,
    data: *const u8,
    len: usize,
}

// SAFETY: the pointer is only read (through `as_ref`), and the memory it points to belongs
// to `_owner`, which lives as long as this value; numpy memory is plain bytes that any
// thread may read. Concurrent writes from Python are the caller's contract (module docs).
unsafe impl Send for NumpyBytes {}
// SAFETY: as for `Send`: shared references only ever read the bytes.
unsafe impl Sync for NumpyBytes {}

impl AsRef<[u8]> for NumpyBytes {
    fn as_ref(&self) -> &[u8] {
        if self.len == 0 {
            return &[];
        }
        // SAFETY: `data` is the start of the array's `len` bytes (a contiguous array, checked
        // in `volume_from_array`), which stay allocated while `_owner` holds the array.
        unsafe { std::slice::from_raw_parts(self.data, self.len) }
    }
}

/// The voxel type of a numpy dtype in native byte order, if the library has it.
fn voxel_type_of(kind: u8, size: usize) -> Option<VoxelType> {
    Some(match (kind, size) {
        (b'u', 1) => VoxelType::U8,
        (b'i', 1) => VoxelType::I8,
        (b'u', 2) => VoxelType::U16,
        (b'i', 2) => VoxelType::I16,
        (b'u', 4) => VoxelType::U32,
        (b'i', 4) => VoxelType::I32,
        (b'f', 4) => VoxelType::F32,
        (b'f', 8) => VoxelType::F64,
        _ => return None,
    })
}

/// Geometry given from Python, in the array's logical axis order `x, y, z`.
pub struct Geometry {
    pub spacing: [f64; 3],
    pub origin: [f64; 3],
    /// 3×4 (or the top of a 4×4) grid → world affine, rows `[m0, m1, m2, t]`.
    pub world_from_grid: Option<[[f64; 4]; 3]>,
}

/// A volume viewing `array` (3D, a supported dtype) in place when it is contiguous and in
/// native byte order, else a C-contiguous copy of it. Returns the volume and whether it is a
/// view of `array`'s own memory.
pub fn volume_from_array(
    array: &Bound<'_, PyAny>,
    geometry: &Geometry,
) -> anyhow::Result<(RectilinearVolume, bool)> {
    let py = array.py();
    let arr = array.cast::<PyUntypedArray>().map_err(|_| {
        anyhow::anyhow!(
            "Volume: expected a 3D numpy array, got {}",
            array
                .get_type()
                .name()
                .map_or_else(|_| "an object".into(), |n| n.to_string())
        )
    })?;
    if arr.ndim() != 3 {
        bail!(
            "Volume: expected a 3D array indexed [z, y, x], got shape {:?}",
            arr.shape()
        );
    }
    let dtype = arr.dtype();
    let kind = dtype.kind();
    let size = dtype.itemsize();
    let Some(voxel_type) = voxel_type_of(kind, size) else {
        bail!(
            "Volume: dtype {} is not a voxel type; use uint8, int8, uint16, int16, uint32, \
             int32, float32 or float64",
            dtype.str().map_or_else(|_| "?".into(), |s| s.to_string())
        );
    };
    let native = dtype.is_native_byteorder().unwrap_or(true);
    let in_place = native && (arr.is_c_contiguous() || arr.is_fortran_contiguous());
    let owner: Bound<'_, PyUntypedArray> = if in_place {
        arr.clone()
    } else {
        // One copy, same values, native order, C-contiguous.
        let np = py.import("numpy").context("importing numpy")?;
        let native_dtype = dtype
            .call_method1("newbyteorder", ("=",))
            .context("numpy dtype.newbyteorder")?;
        np.call_method1("ascontiguousarray", (arr, native_dtype))
            .context("numpy.ascontiguousarray")?
            .cast_into::<PyUntypedArray>()
            .map_err(|_| anyhow::anyhow!("numpy.ascontiguousarray did not return an array"))?
    };
    let shape = owner.shape().to_vec();
    // F-order (and not also C-order, as arrays with at most one long axis are): the memory
    // order is the shape order, z fastest.
    let fortran = !owner.is_c_contiguous();
    let len = shape.iter().product::<usize>();
    // SAFETY: `as_array_ptr` is a valid PyArrayObject for as long as `owner` lives (we hold
    // it); reading its `data` field is how numpy exposes the buffer.
    let data = unsafe { (*owner.as_array_ptr()).fields.data }.cast::<u8>();
    let source = NumpyBytes {
        _owner: owner.clone().into_any().unbind(),
        data,
        len: len * size,
    };
    let logical_dims = [shape[2], shape[1], shape[0]];
    let grid = if fortran {
        grid_for(
            [shape[0], shape[1], shape[2]],
            geometry,
            Some(DMat3::from_cols(DVec3::Z, DVec3::Y, DVec3::X)),
        )
    } else {
        grid_for(logical_dims, geometry, None)
    }?;
    let source: Arc<dyn ByteSource> = Arc::new(source);
    let voxels = VoxelData::from_shared(voxel_type, source, 0, len)
        .context("Volume: viewing the array's memory")?;
    let volume = RectilinearVolume::new(grid, voxels).context("Volume")?;
    Ok((volume, in_place))
}

/// The grid of `dims` (memory order) with the logical `geometry`; `permute` maps grid axes
/// to logical axes (the F-order case: grid axis 0 is logical z).
fn grid_for(dims: [usize; 3], geometry: &Geometry, permute: Option<DMat3>) -> anyhow::Result<Grid> {
    let reorder = |v: [f64; 3]| {
        if permute.is_some() {
            [v[2], v[1], v[0]]
        } else {
            v
        }
    };
    let (spacing, origin) = (reorder(geometry.spacing), reorder(geometry.origin));
    let axes = [0, 1, 2].map(|a| AxisCoords::Uniform {
        origin: origin[a],
        spacing: spacing[a],
    });
    let user = geometry.world_from_grid.map(|m| DAffine3 {
        matrix3: DMat3::from_cols(
            DVec3::new(m[0][0], m[1][0], m[2][0]),
            DVec3::new(m[0][1], m[1][1], m[2][1]),
            DVec3::new(m[0][2], m[1][2], m[2][2]),
        ),
        translation: DVec3::new(m[0][3], m[1][3], m[2][3]),
    });
    let world_from_grid = match (user, permute) {
        (None, None) => None,
        (Some(u), None) => Some(u),
        (u, Some(p)) => Some(u.unwrap_or(DAffine3::IDENTITY) * DAffine3::from_mat3(p)),
    };
    Grid::new(dims, axes, world_from_grid).context("Volume: geometry")
}
