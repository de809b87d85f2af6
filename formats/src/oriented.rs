//! Grids of images described by an origin, a spacing per axis and the world direction of
//! each grid axis (VTK image data, MetaImage). Voxels are samples (seed 004 §6.1): voxel
//! `(i, j, k)` lies at `origin + Σ_a direction_a · index_a · spacing_a`. An axis-aligned
//! image is a uniform grid; any other direction becomes the grid's `world_from_grid`
//! (columns: the axis directions as given, translation: the origin), so the grid frame keeps
//! the spacing. A negative spacing (VTK allows it) runs its axis backwards: the same points,
//! with the direction flipped and the spacing positive.

use std::path::Path;

use glam::{DAffine3, DMat3, DVec3};
use volume_core::{AxisCoords, Grid};

use crate::error::FormatError;

/// The grid of an image: `dims` samples from index `first` along each axis, sample `(i, j,
/// k)` at `origin + Σ_a axis_dirs[a] · (first[a] + index_a) · spacing[a]` (`axis_dirs`: the
/// world direction of each grid axis; `None` for the world axes). `field` names where the
/// spacing came from, and `line` its line, for errors.
pub(crate) fn image_grid(
    path: &Path,
    dims: [usize; 3],
    first: [i64; 3],
    origin: [f64; 3],
    spacing: [f64; 3],
    axis_dirs: Option<[[f64; 3]; 3]>,
    (field, line): (&str, usize),
) -> Result<Grid, FormatError> {
    let mut cols = match axis_dirs {
        Some(d) => d.map(DVec3::from_array),
        None => [DVec3::X, DVec3::Y, DVec3::Z],
    };
    let mut step = spacing;
    for a in 0..3 {
        if !(spacing[a].is_finite() && spacing[a] != 0.0) {
            return Err(FormatError::BadValue {
                path: path.to_path_buf(),
                line,
                field: field.into(),
                reason: format!(
                    "axis {a}: spacing {} must be finite and not zero",
                    spacing[a]
                ),
            });
        }
        if spacing[a] < 0.0 {
            // A negative spacing runs the axis backwards: the same points with the
            // direction column flipped.
            step[a] = -spacing[a];
            cols[a] = -cols[a];
        }
    }
    let identity = cols == [DVec3::X, DVec3::Y, DVec3::Z];
    let axes = |shift: [f64; 3]| {
        [0, 1, 2].map(|a| AxisCoords::Uniform {
            origin: shift[a] + first[a] as f64 * step[a],
            spacing: step[a],
        })
    };
    let (axes, world_from_grid) = if identity {
        (axes(origin), None)
    } else {
        let m = DAffine3::from_mat3_translation(
            DMat3::from_cols(cols[0], cols[1], cols[2]),
            DVec3::from_array(origin),
        );
        (axes([0.0; 3]), Some(m))
    };
    Grid::new(dims, axes, world_from_grid).map_err(|e| FormatError::geometry(path, e))
}

/// `a × b × c` for sample counts, or an error naming `field`.
pub(crate) fn checked_dims(
    path: &Path,
    dims: [usize; 3],
    (field, line): (&str, usize),
) -> Result<usize, FormatError> {
    let bad = |reason: String| FormatError::BadValue {
        path: path.to_path_buf(),
        line,
        field: field.into(),
        reason,
    };
    if dims.contains(&0) {
        return Err(bad(format!(
            "{dims:?}: every axis needs at least one sample"
        )));
    }
    dims[0]
        .checked_mul(dims[1])
        .and_then(|n| n.checked_mul(dims[2]))
        .ok_or_else(|| bad(format!("{dims:?} samples overflow")))
}
