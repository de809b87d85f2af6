//! From NRRD axes to a volume grid (and a time axis).
//!
//! - `dimension: 3`: the three axes are x, y, z.
//! - `dimension: 4`: one axis is not spatial. It is the axis whose `space directions` entry is
//!   `none`; else the axis of kind `time`, else the one of a non-domain kind (`scalar`, `list`
//!   ...); else axis 0 if its size is 1, else axis 3. A non-spatial axis 0 must have size 1
//!   (it is dropped: scalar data written with a leading component axis); a non-spatial axis 3
//!   is time (one volume per sample).
//! - Geometry: with `space directions`, spacing is each direction's length; if the directions
//!   are axis-aligned and positive the grid is uniform with origin = `space origin`, otherwise
//!   the grid (origin 0) carries `world_from_grid` = (unit directions as columns, `space
//!   origin`). Without them, `spacings` (default 1) and `axis mins` (default 0) give a uniform
//!   grid. When only `axis mins`/`axis maxs` are given, the spacing follows the centering as in
//!   Teem's `nrrdAxisInfoPos` (cell: (max−min)/n, sample i at min + (i+½)·spacing; node:
//!   (max−min)/(n−1)); unknown centering is cell, Teem's `nrrdDefaultCenter`. With `spacings`
//!   and `axis mins` (what Isoscope writes, with `centers: node`), sample 0 is at the min
//!   (plus half a spacing for explicit `cell` centering).

use std::path::Path;

use glam::{DAffine3, DVec3};
use volume_core::{AxisCoords, Grid, WorldFrame};

use super::header::{Center, NrrdHeader};
use crate::error::FormatError;

/// How a NRRD's axes map to one volume or a series of volumes.
#[derive(Debug, Clone)]
pub struct VolumeLayout {
    /// Geometry of one volume (one time step).
    pub grid: Grid,
    /// Number of time steps (1 for a plain volume).
    pub steps: usize,
    /// `(time of step 0, time per step)` when the time axis records them.
    pub time: Option<(f64, f64)>,
}

const DOMAIN_KINDS: &[&str] = &["domain", "space", "time", "???", "none"];

impl NrrdHeader {
    /// Maps the header's axes to a grid and a step count (see the module docs).
    pub fn volume_layout(&self, path: &Path) -> Result<VolumeLayout, FormatError> {
        let unsupported = |field: &str, reason: String| FormatError::Unsupported {
            path: path.to_path_buf(),
            field: field.to_string(),
            reason,
        };
        let (spatial, extra): ([usize; 3], Option<usize>) = match self.dimension {
            3 => ([0, 1, 2], None),
            4 => {
                let n = self.non_spatial_axis(path)?;
                let spatial: Vec<usize> = (0..4).filter(|&a| a != n).collect();
                ([spatial[0], spatial[1], spatial[2]], Some(n))
            }
            d => {
                return Err(unsupported(
                    "dimension",
                    format!("{d}-dimensional data; volumes need dimension 3 (or 4 with time)"),
                ));
            }
        };
        let mut steps = 1;
        if let Some(n) = extra {
            match n {
                0 if self.sizes[0] == 1 => {}
                0 => {
                    return Err(unsupported(
                        "sizes",
                        format!(
                            "axis 0 holds {} components per voxel{}; only scalar volumes are supported",
                            self.sizes[0],
                            self.kinds
                                .as_ref()
                                .map(|k| format!(" (kind {})", k[0]))
                                .unwrap_or_default()
                        ),
                    ));
                }
                3 => steps = self.sizes[3],
                _ => {
                    return Err(unsupported(
                        "sizes",
                        format!(
                            "the non-spatial axis is axis {n}; only axis 0 (size 1) or axis 3 (time) can be"
                        ),
                    ));
                }
            }
        }
        let dims = spatial.map(|a| self.sizes[a]);
        let grid = if let Some(dirs) = &self.space_directions {
            self.oriented_grid(path, dirs, spatial, dims)?
        } else {
            self.axis_grid(path, spatial, dims)?
        };
        let time = extra.filter(|&n| n == 3).and_then(|n| {
            let step = self
                .spacings
                .as_ref()
                .map(|s| s[n])
                .filter(|s| s.is_finite())?;
            let t0 = self
                .axis_mins
                .as_ref()
                .map(|m| m[n])
                .filter(|m| m.is_finite())
                .unwrap_or(0.0);
            Some((t0, step))
        });
        Ok(VolumeLayout { grid, steps, time })
    }

    fn non_spatial_axis(&self, path: &Path) -> Result<usize, FormatError> {
        if let Some(dirs) = &self.space_directions {
            let none: Vec<usize> = (0..4).filter(|&a| dirs[a].is_none()).collect();
            if none.len() != 1 {
                return Err(FormatError::BadValue {
                    path: path.to_path_buf(),
                    line: self.line_of("space directions"),
                    field: "space directions".into(),
                    reason: format!(
                        "a 4-dimensional volume needs exactly one `none` axis, found {}",
                        none.len()
                    ),
                });
            }
            return Ok(none[0]);
        }
        if let Some(kinds) = &self.kinds {
            if let Some(a) = kinds.iter().position(|k| k == "time") {
                return Ok(a);
            }
            if let Some(a) = kinds
                .iter()
                .position(|k| !DOMAIN_KINDS.contains(&k.as_str()))
            {
                return Ok(a);
            }
        }
        Ok(if self.sizes[0] == 1 { 0 } else { 3 })
    }

    fn oriented_grid(
        &self,
        path: &Path,
        dirs: &[Option<Vec<f64>>],
        spatial: [usize; 3],
        dims: [usize; 3],
    ) -> Result<Grid, FormatError> {
        let bad = |reason: String| FormatError::BadValue {
            path: path.to_path_buf(),
            line: self.line_of("space directions"),
            field: "space directions".into(),
            reason,
        };
        let sd = self.space_dimension.unwrap_or(0);
        if sd != 3 {
            return Err(FormatError::Unsupported {
                path: path.to_path_buf(),
                field: if self.space.is_some() {
                    "space"
                } else {
                    "space dimension"
                }
                .into(),
                reason: format!("space dimension {sd}; only 3-dimensional spaces are supported"),
            });
        }
        let mut directions = [DVec3::ZERO; 3];
        for (i, &a) in spatial.iter().enumerate() {
            let d = dirs[a]
                .as_ref()
                .ok_or_else(|| bad(format!("spatial axis {a} has direction `none`")))?;
            directions[i] = DVec3::new(d[0], d[1], d[2]);
        }
        let origin = self
            .space_origin
            .as_ref()
            .map_or(DVec3::ZERO, |o| DVec3::new(o[0], o[1], o[2]));
        let geometry = |e| FormatError::geometry(path, e);
        let (axes, world_from_grid) = crate::oriented::axes_from_directions(directions, origin)
            .map_err(|i| {
                bad(format!(
                    "axis {}: direction {} has no length",
                    spatial[i], directions[i]
                ))
            })?;
        let origin_too_far = origin.abs().max_element() > volume_core::volume::MAX_WORLD_COORD;
        let field = if origin_too_far {
            "space origin"
        } else {
            "space directions"
        };
        self.check_coordinates(path, field, spatial, dims, &axes, world_from_grid)?;
        let frame = match self.space.as_deref() {
            Some("right-anterior-superior") => WorldFrame::Ras,
            Some("left-posterior-superior") => WorldFrame::Lps,
            // LAS, scanner and plain 3D spaces name no frame Isoscope labels.
            _ => WorldFrame::Unknown,
        };
        Ok(Grid::new(dims, axes, world_from_grid)
            .map_err(geometry)?
            .with_world_frame(frame))
    }

    /// Refuses coordinates that single-precision rendering cannot handle, naming the header
    /// field that put them there (rather than failing later as a non-finite camera).
    fn check_coordinates(
        &self,
        path: &Path,
        field: &str,
        spatial: [usize; 3],
        dims: [usize; 3],
        axes: &[AxisCoords; 3],
        world_from_grid: Option<DAffine3>,
    ) -> Result<(), FormatError> {
        use volume_core::volume::{MAX_WORLD_COORD, coordinate_overflow};
        // Non-finite parts are reported by `Grid::new` with its own reason.
        let finite = axes.iter().all(|a| match a {
            AxisCoords::Uniform { origin, spacing } => origin.is_finite() && spacing.is_finite(),
            AxisCoords::Explicit(c) => c.iter().all(|x| x.is_finite()),
        });
        if !finite {
            return Ok(());
        }
        match coordinate_overflow(dims, axes, world_from_grid) {
            None => Ok(()),
            Some((i, x)) => Err(FormatError::BadValue {
                path: path.to_path_buf(),
                line: self.line_of(field),
                field: field.to_string(),
                reason: format!(
                    "axis {}: with {} samples a coordinate reaches {x:e}, beyond the \
                     ±{MAX_WORLD_COORD:e} that single-precision rendering supports",
                    spatial[i], dims[i]
                ),
            }),
        }
    }

    fn axis_grid(
        &self,
        path: &Path,
        spatial: [usize; 3],
        dims: [usize; 3],
    ) -> Result<Grid, FormatError> {
        let get =
            |v: &Option<Vec<f64>>, a: usize| v.as_ref().map(|v| v[a]).filter(|x| x.is_finite());
        let mut origin = [0.0; 3];
        let mut spacing = [1.0; 3];
        for (i, &a) in spatial.iter().enumerate() {
            let n = dims[i] as f64;
            let center = self.centers.as_ref().map_or(Center::Unknown, |c| c[a]);
            let (sp, min, max) = (
                get(&self.spacings, a),
                get(&self.axis_mins, a),
                get(&self.axis_maxs, a),
            );
            if let Some(s) = sp
                && s < 0.0
            {
                return Err(FormatError::Unsupported {
                    path: path.to_path_buf(),
                    field: "spacings".into(),
                    reason: format!(
                        "axis {a}: negative spacing {s} (flipped axes) is not supported; use space directions"
                    ),
                });
            }
            match (sp, min, max) {
                (Some(s), min, max) => {
                    spacing[i] = s;
                    let half = if center == Center::Cell { 0.5 * s } else { 0.0 };
                    origin[i] = min.unwrap_or(0.0) + half;
                    if let (Some(lo), Some(hi)) = (min, max) {
                        let node = if dims[i] > 1 {
                            (hi - lo) / (n - 1.0)
                        } else {
                            s
                        };
                        let cell = (hi - lo) / n;
                        let close = |x: f64| (x - s).abs() <= 1e-6 * s.abs().max(x.abs());
                        let ok = match center {
                            Center::Cell => close(cell),
                            Center::Node => close(node),
                            Center::Unknown => close(cell) || close(node),
                        };
                        if !ok {
                            return Err(FormatError::Contradiction {
                                path: path.to_path_buf(),
                                field: "axis maxs".into(),
                                other: "spacings".into(),
                                reason: format!(
                                    "axis {a}: min {lo}, max {hi} and {} samples do not give spacing {s}",
                                    dims[i]
                                ),
                            });
                        }
                    }
                }
                (None, Some(lo), Some(hi)) if hi > lo => {
                    if center == Center::Node {
                        spacing[i] = if dims[i] > 1 {
                            (hi - lo) / (n - 1.0)
                        } else {
                            1.0
                        };
                        origin[i] = lo;
                    } else {
                        spacing[i] = (hi - lo) / n;
                        origin[i] = lo + 0.5 * spacing[i];
                    }
                }
                (None, min, _) => origin[i] = min.unwrap_or(0.0),
            }
        }
        let axes = [0, 1, 2].map(|i| AxisCoords::Uniform {
            origin: origin[i],
            spacing: spacing[i],
        });
        if let Some((i, _)) = volume_core::volume::coordinate_overflow(dims, &axes, None) {
            // Name the field that set this axis: its min, else its spacing, else its max.
            let a = spatial[i];
            let far = |x: f64| x.abs() > volume_core::volume::MAX_WORLD_COORD;
            let field = if get(&self.axis_mins, a).is_some_and(far) {
                "axis mins"
            } else if get(&self.spacings, a).is_some() {
                "spacings"
            } else {
                "axis maxs"
            };
            self.check_coordinates(path, field, spatial, dims, &axes, None)?;
        }
        Grid::uniform(dims, origin, spacing).map_err(|e| FormatError::geometry(path, e))
    }
}

#[cfg(test)]
mod tests {
    use super::super::header::parse_header;
    use super::*;

    fn layout(fields: &str) -> Result<VolumeLayout, FormatError> {
        let h = parse_header(format!("NRRD0004\ntype: uint8\nencoding: raw\n{fields}").as_bytes())?;
        h.volume_layout(Path::new("t.nrrd"))
    }

    #[test]
    fn axis_aligned_directions_give_a_uniform_grid() {
        let l = layout(
            "dimension: 3\nsizes: 2 3 4\nspace: RAS\nspace directions: (0.5,0,0) (0,2,0) (0,0,3)\nspace origin: (1,2,3)\n",
        )
        .unwrap();
        assert_eq!(l.grid.world_from_grid(), None);
        assert_eq!(l.grid.uniform_spacing(), Some([0.5, 2.0, 3.0]));
        assert_eq!(l.grid.origin(), DVec3::new(1.0, 2.0, 3.0));
        assert_eq!(l.steps, 1);
        assert_eq!(l.grid.world_frame(), WorldFrame::Ras);
        assert_eq!(l.grid.axis_letters(), Some(['R', 'A', 'S']));
    }

    #[test]
    fn oblique_directions_give_world_from_grid() {
        let l = layout(
            "dimension: 3\nsizes: 2 3 4\nspace: LPS\nspace directions: (0,2,0) (-1,0,0) (0,0,3)\nspace origin: (1,2,3)\n",
        )
        .unwrap();
        let m = l.grid.world_from_grid().unwrap();
        assert_eq!(l.grid.world_frame(), WorldFrame::Lps);
        // i runs along +y (posterior), j along −x (right).
        assert_eq!(l.grid.axis_letters(), Some(['P', 'R', 'S']));
        assert_eq!(l.grid.uniform_spacing(), Some([2.0, 1.0, 3.0]));
        assert_eq!(l.grid.origin(), DVec3::ZERO);
        // Voxel (1, 1, 1) in world: origin + 1·d0 + 1·d1 + 1·d2.
        let p = m.transform_point3(l.grid.grid_position(1, 1, 1));
        assert!((p - DVec3::new(1.0 - 1.0, 2.0 + 2.0, 3.0 + 3.0)).length() < 1e-12);
    }

    #[test]
    fn four_d_axes_are_time_or_dropped() {
        let l = layout("dimension: 4\nsizes: 2 3 4 5\nspacings: 1 1 1 0.5\naxis mins: 0 0 0 10\n")
            .unwrap();
        assert_eq!(l.steps, 5);
        assert_eq!(l.time, Some((10.0, 0.5)));
        assert_eq!(l.grid.dims(), [2, 3, 4]);
        let l = layout("dimension: 4\nsizes: 1 3 4 5\nkinds: scalar space space space\n").unwrap();
        assert_eq!((l.steps, l.grid.dims()), (1, [3, 4, 5]));
        let e = layout("dimension: 4\nsizes: 3 3 4 5\nkinds: 3-vector space space space\n")
            .unwrap_err();
        assert!(
            matches!(&e, FormatError::Unsupported { field, .. } if field == "sizes"),
            "{e}"
        );
        let l = layout(
            "dimension: 4\nsizes: 2 2 2 3\nspace: RAS\nspace directions: (1,0,0) (0,1,0) (0,0,1) none\n",
        )
        .unwrap();
        assert_eq!(l.steps, 3);
    }

    #[test]
    fn axis_mins_follow_centering() {
        let l = layout("dimension: 3\nsizes: 4 2 2\nspacings: 2 1 1\naxis mins: 10 0 0\ncenters: node cell ???\n").unwrap();
        assert_eq!(l.grid.origin(), DVec3::new(10.0, 0.5, 0.0));
        let l = layout("dimension: 3\nsizes: 4 2 2\naxis mins: 0 0 0\naxis maxs: 4 1 1\ncenters: cell node ???\n").unwrap();
        assert_eq!(l.grid.uniform_spacing(), Some([1.0, 1.0, 0.5]));
        assert_eq!(l.grid.origin(), DVec3::new(0.5, 0.0, 0.25));
        let e = layout(
            "dimension: 3\nsizes: 4 2 2\nspacings: 2 1 1\naxis mins: 0 0 0\naxis maxs: 3 1 1\n",
        )
        .unwrap_err();
        assert!(
            matches!(&e, FormatError::Contradiction { field, .. } if field == "axis maxs"),
            "{e}"
        );
    }
}
