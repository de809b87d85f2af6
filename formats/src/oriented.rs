//! Grid axes from a file's per-axis world directions, shared by the readers so that every
//! format orients a grid the same way (NRRD `space directions`, a NIfTI sform/qform, VTK
//! image data and MetaImage origin/spacing/direction). Voxels are samples (seed 004 §6.1).
//!
//! Each direction is one grid step along that axis in world units: its length is the
//! spacing, its unit vector the axis direction. When every direction points along its own
//! world axis in the positive sense the grid is uniform with its origin (no transform);
//! otherwise the grid keeps origin 0 in its own frame and carries `world_from_grid` = (unit
//! directions as columns, the origin), as `volume_core::volume` describes for oriented data.
//! A negative spacing (VTK allows it) runs its axis backwards: the same points, with the
//! direction flipped and the spacing positive.

use std::path::Path;

use glam::{DAffine3, DMat3, DVec3};
use volume_core::{AxisCoords, Grid};

use crate::error::FormatError;

/// The grid axes and optional `world_from_grid` of axis directions `directions` (one grid
/// step each, world units) and the world position `origin` of voxel (0, 0, 0).
///
/// # Errors
/// The index of the first direction that has no length (zero or not finite).
pub(crate) fn axes_from_directions(
    directions: [DVec3; 3],
    origin: DVec3,
) -> Result<([AxisCoords; 3], Option<DAffine3>), usize> {
    let mut cols = [DVec3::ZERO; 3];
    let mut spacing = [0.0; 3];
    for (i, d) in directions.iter().enumerate() {
        let len = d.length();
        if !(len.is_finite() && len > 0.0) {
            return Err(i);
        }
        cols[i] = *d / len;
        spacing[i] = len;
    }
    let axis_aligned = (0..3).all(|i| {
        (0..3).all(|c| {
            if c == i {
                cols[i][c] > 0.0
            } else {
                cols[i][c] == 0.0
            }
        })
    });
    if axis_aligned {
        let axes = [0, 1, 2].map(|i| AxisCoords::Uniform {
            origin: origin[i],
            spacing: spacing[i],
        });
        return Ok((axes, None));
    }
    let axes = spacing.map(|s| AxisCoords::Uniform {
        origin: 0.0,
        spacing: s,
    });
    let m = DAffine3::from_mat3_translation(DMat3::from_cols(cols[0], cols[1], cols[2]), origin);
    Ok((axes, Some(m)))
}

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
    let unit = match axis_dirs {
        Some(d) => d.map(DVec3::from_array),
        None => [DVec3::X, DVec3::Y, DVec3::Z],
    };
    for (a, s) in spacing.iter().enumerate() {
        if !(s.is_finite() && *s != 0.0) {
            return Err(FormatError::BadValue {
                path: path.to_path_buf(),
                line,
                field: field.into(),
                reason: format!("axis {a}: spacing {s} must be finite and not zero"),
            });
        }
    }
    let directions = [0, 1, 2].map(|a| unit[a] * spacing[a]);
    // Sample 0 of the file is index `first`: move the origin there.
    let origin = (0..3).fold(DVec3::from_array(origin), |o, a| {
        o + directions[a] * first[a] as f64
    });
    let (axes, world_from_grid) =
        axes_from_directions(directions, origin).map_err(|a| FormatError::BadValue {
            path: path.to_path_buf(),
            line,
            field: field.into(),
            reason: format!("axis {a}: direction {:?} has no length", unit[a].to_array()),
        })?;
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn aligned_directions_are_uniform_and_others_carry_a_transform() {
        let (axes, m) = axes_from_directions(
            [DVec3::X * 0.5, DVec3::Y * 2.0, DVec3::Z * 3.0],
            DVec3::new(1.0, 2.0, 3.0),
        )
        .unwrap();
        assert!(m.is_none());
        assert_eq!(
            axes[1],
            AxisCoords::Uniform {
                origin: 2.0,
                spacing: 2.0
            }
        );
        // A flipped axis is not "aligned and positive": it needs the transform.
        let (axes, m) = axes_from_directions(
            [DVec3::X * -2.0, DVec3::Y, DVec3::Z],
            DVec3::new(5.0, 0.0, 0.0),
        )
        .unwrap();
        let m = m.unwrap();
        assert_eq!(
            axes[0],
            AxisCoords::Uniform {
                origin: 0.0,
                spacing: 2.0
            }
        );
        // Voxel 1 along x: one step of (−2, 0, 0) from the origin.
        assert_eq!(
            m.transform_point3(DVec3::new(axes[0].coord(1), 0.0, 0.0)),
            DVec3::new(3.0, 0.0, 0.0)
        );
        assert_eq!(
            axes_from_directions([DVec3::X, DVec3::ZERO, DVec3::Z], DVec3::ZERO),
            Err(1)
        );
        assert_eq!(
            axes_from_directions([DVec3::X, DVec3::Y, DVec3::Z * f64::NAN], DVec3::ZERO),
            Err(2)
        );
    }
}
