//! From image files to series, and from a series to a volume (or a time series).
//!
//! - Grouping: by SeriesInstanceUID, then split where the pixel format (Rows, Columns, bits),
//!   the orientation or the pixel spacing changes: each part is one [`Group`].
//! - Order: slices are sorted by ImagePositionPatient projected on the slice normal (row ×
//!   column direction of ImageOrientationPatient), never by file name or InstanceNumber.
//! - Geometry ([`plan`]): the slice axis is the normal, or, when the positions drift sideways
//!   (gantry tilt), the line through the first and last position (an oblique, sheared
//!   `world_from_grid`). Positions off that line are an error. The slice coordinates come from
//!   the positions, never from SliceThickness: uniform when every position is within 2 % of a
//!   spacing of a uniform grid, explicit ([`AxisCoords::Explicit`]) otherwise.
//! - Missing slices: a gap above 1.5× the median spacing is refused, naming the positions and
//!   files on both sides (the volume would otherwise stretch silently across it).
//! - Duplicates: slices at the same position are an error naming both files, unless
//!   TemporalPositionIdentifier (or, in enhanced files, TemporalPositionIndex) tells phases
//!   apart and every position repeats once per phase: then each phase is a time step.
//! - World frame: LPS, `world_from_grid` columns = row direction, column direction, slice axis
//!   (grid axes: i along a row with the column spacing PixelSpacing[1], j down a column with the
//!   row spacing PixelSpacing[0], k across slices); an axial series with +x, +y, +z directions
//!   needs no transform (origin in the axes, as NRRD does).
//! - Values: stored type (u8/i8/u16/i16/u32/i32/f32/f64) with one RescaleSlope/Intercept as a
//!   [`ValueMap`]; slices of different rescales are converted to `f32` physical values.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use glam::{DAffine3, DMat3, DVec3};
use rayon::prelude::*;
use volume_core::series::{StepLoader, TimeSeries};
use volume_core::{
    AxisCoords, Grid, RectilinearVolume, ValueMap, Voxel, VoxelData, VoxelType, WorldFrame,
};

use super::attributes::{Content, FrameInfo, ImageInfo, content};
use super::pixels::{self, PixelFormat};
use crate::FirstStep;
use crate::error::FormatError;

/// One frame of one file.
#[derive(Debug, Clone)]
pub(crate) struct Slice {
    /// Index into the file list.
    pub file: usize,
    pub frame: usize,
    pub info: FrameInfo,
}

/// A series part: images of one SeriesInstanceUID with one pixel format, orientation and
/// pixel spacing.
#[derive(Debug, Clone)]
pub(crate) struct Group {
    pub uid: String,
    /// 1-based part number when the UID was split, else `None`.
    pub part: Option<usize>,
    pub description: String,
    pub number: Option<i64>,
    pub modality: String,
    pub format: PixelFormat,
    pub syntax: String,
    pub decodable: bool,
    pub slices: Vec<Slice>,
    /// Indices into the file list, in first-seen order, without repeats.
    pub files: Vec<usize>,
}

fn close(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol
}

fn same_orientation(a: Option<[DVec3; 2]>, b: Option<[DVec3; 2]>) -> bool {
    match (a, b) {
        (None, None) => true,
        (Some(a), Some(b)) => a[0].abs_diff_eq(b[0], 1e-4) && a[1].abs_diff_eq(b[1], 1e-4),
        _ => false,
    }
}

fn same_spacing(a: Option<[f64; 2]>, b: Option<[f64; 2]>) -> bool {
    match (a, b) {
        (None, None) => true,
        (Some(a), Some(b)) => close(a[0], b[0], 1e-4 * a[0]) && close(a[1], b[1], 1e-4 * a[1]),
        _ => false,
    }
}

/// Groups the frames of `images` (`(file index, info)`, in file order) into series parts.
pub(crate) fn group(images: &[(usize, &ImageInfo)]) -> Vec<Group> {
    let mut groups: Vec<Group> = Vec::new();
    for &(file, info) in images {
        for (frame, f) in info.frames.iter().enumerate() {
            let found = groups.iter_mut().find(|g| {
                g.uid == info.series_uid
                    && g.format == info.format
                    && g.syntax == info.syntax
                    && same_orientation(g.slices[0].info.orientation, f.orientation)
                    && same_spacing(g.slices[0].info.pixel_spacing, f.pixel_spacing)
            });
            let slice = Slice {
                file,
                frame,
                info: f.clone(),
            };
            match found {
                Some(g) => {
                    if g.files.last() != Some(&file) && !g.files.contains(&file) {
                        g.files.push(file);
                    }
                    g.slices.push(slice);
                }
                None => groups.push(Group {
                    uid: info.series_uid.clone(),
                    part: None,
                    description: info.series_description.clone(),
                    number: info.series_number,
                    modality: info.modality.clone(),
                    format: info.format,
                    syntax: info.syntax.clone(),
                    decodable: info.decodable,
                    slices: vec![slice],
                    files: vec![file],
                }),
            }
        }
    }
    // Number the parts of split UIDs, then order: series number, description, UID, part.
    let uids: Vec<String> = groups.iter().map(|g| g.uid.clone()).collect();
    let mut seen = std::collections::HashMap::<&str, usize>::new();
    for (g, uid) in groups.iter_mut().zip(&uids) {
        if uids.iter().filter(|u| *u == uid).count() > 1 {
            let n = seen.entry(uid.as_str()).or_insert(0);
            *n += 1;
            g.part = Some(*n);
        }
    }
    groups.sort_by(|a, b| {
        a.number
            .unwrap_or(i64::MAX)
            .cmp(&b.number.unwrap_or(i64::MAX))
            .then_with(|| a.description.cmp(&b.description))
            .then_with(|| a.uid.cmp(&b.uid))
            .then_with(|| a.part.cmp(&b.part))
    });
    groups
}

/// How a group becomes volumes: geometry, phases (time steps) of slices in k order, values.
#[derive(Debug, Clone)]
pub(crate) struct Plan {
    pub grid: Grid,
    /// Per phase, the slices in k order.
    pub phases: Vec<Vec<Slice>>,
    pub format: PixelFormat,
    /// The one rescale of every slice, or `None` when they differ (then values are `f32`).
    pub rescale: Option<(f64, f64)>,
}

impl Plan {
    pub(crate) fn voxel_type(&self) -> VoxelType {
        if self.rescale.is_some() {
            self.format.voxel_type()
        } else {
            VoxelType::F32
        }
    }

    pub(crate) fn value_map(&self) -> ValueMap {
        match self.rescale {
            Some((slope, intercept)) => ValueMap::new(slope, intercept).unwrap_or_default(),
            None => ValueMap::IDENTITY,
        }
    }
}

fn fmt_point(p: DVec3) -> String {
    format!("({:.3}, {:.3}, {:.3})", p.x, p.y, p.z)
}

/// Plans the volume(s) of `group` (see the module docs); `files` names the files and `root`
/// the input in series-level errors.
pub(crate) fn plan(group: &Group, files: &[PathBuf], root: &Path) -> Result<Plan, FormatError> {
    let err = |reason: String| FormatError::DicomSeries {
        path: root.to_path_buf(),
        reason,
    };
    let name = |s: &Slice| {
        let p = files[s.file].display().to_string();
        if s.frame > 0 || group.slices.iter().filter(|o| o.file == s.file).count() > 1 {
            format!("{p} frame {}", s.frame + 1)
        } else {
            p
        }
    };
    let format = group.format;
    let first = &group.slices[0];
    // Rescale: one for all, or f32.
    let rescale = group
        .slices
        .iter()
        .all(|s| s.info.rescale == first.info.rescale)
        .then_some(first.info.rescale);
    if let Some((slope, intercept)) = rescale
        && let Err(e) = ValueMap::new(slope, intercept)
    {
        return Err(FormatError::DicomAttribute {
            path: files[first.file].clone(),
            attribute: "RescaleSlope (0028,1053)".into(),
            reason: e.to_string(),
        });
    }
    let spacing = first.info.pixel_spacing;
    let (dx, dy) = spacing.map_or((1.0, 1.0), |s| (s[1], s[0]));
    let dims2 = [format.cols, format.rows];
    // A single 2D image.
    if group.slices.len() == 1 {
        let (axes, m) = match (first.info.position, first.info.orientation) {
            (Some(p), Some([r, c])) => oriented(
                p,
                r,
                c,
                r.cross(c),
                dx,
                dy,
                AxisCoords::Uniform {
                    origin: 0.0,
                    spacing: 1.0,
                },
            ),
            _ => (
                [
                    AxisCoords::Uniform {
                        origin: 0.0,
                        spacing: dx,
                    },
                    AxisCoords::Uniform {
                        origin: 0.0,
                        spacing: dy,
                    },
                    AxisCoords::Uniform {
                        origin: 0.0,
                        spacing: 1.0,
                    },
                ],
                None,
            ),
        };
        let grid = Grid::new([dims2[0], dims2[1], 1], axes, m)
            .map_err(|e| FormatError::geometry(&files[first.file], e))?
            .with_world_frame(WorldFrame::Lps);
        return Ok(Plan {
            grid,
            phases: vec![group.slices.clone()],
            format,
            rescale,
        });
    }
    if let Some(s) = group
        .slices
        .iter()
        .find(|s| s.info.position.is_none() || s.info.orientation.is_none())
    {
        return Err(err(format!(
            "{} slices, but {} has no ImagePositionPatient/ImageOrientationPatient (or a \
             multi-frame object no per-frame positions): the slices cannot be placed (Isoscope \
             never orders slices by file name or InstanceNumber)",
            group.slices.len(),
            name(s)
        )));
    }
    let Some([ps_row, ps_col]) = spacing else {
        return Err(FormatError::DicomAttribute {
            path: files[first.file].clone(),
            attribute: "PixelSpacing (0028,0030)".into(),
            reason: "missing: the in-plane spacing of the series is unknown".into(),
        });
    };
    let [row, col] = first.info.orientation.unwrap_or([DVec3::X, DVec3::Y]);
    let normal = row.cross(col).normalize();
    let pos = |s: &Slice| s.info.position.unwrap_or(DVec3::ZERO);
    let mut sorted: Vec<Slice> = group.slices.clone();
    sorted.sort_by(|a, b| {
        pos(a)
            .dot(normal)
            .total_cmp(&pos(b).dot(normal))
            .then(a.info.temporal.cmp(&b.info.temporal))
    });
    // Positions that coincide (closer than a thousandth of a pixel) are one slice position.
    let same_at = 1e-3 * ps_row.min(ps_col);
    let mut clusters: Vec<Vec<Slice>> = Vec::new();
    for s in sorted {
        match clusters.last_mut() {
            Some(c) if pos(&c[0]).distance(pos(&s)) <= same_at => c.push(s),
            Some(c) if (pos(&c[0]).dot(normal) - pos(&s).dot(normal)).abs() <= same_at => {
                return Err(err(format!(
                    "{} at {} and {} at {} lie in the same plane at different places: not one \
                     stack of slices",
                    name(&c[0]),
                    fmt_point(pos(&c[0])),
                    name(&s),
                    fmt_point(pos(&s))
                )));
            }
            _ => clusters.push(vec![s]),
        }
    }
    let phases = phases(&clusters, &name, &err, &pos)?;
    let slices = &phases[0];
    let positions: Vec<DVec3> = slices.iter().map(pos).collect();
    let p0 = positions[0];
    // The slice axis: the normal, or the line of the positions (gantry tilt).
    let last = *positions.last().unwrap_or(&p0);
    let drift = (last - p0) - (last - p0).dot(normal) * normal;
    let tolerance = 0.05 * ps_row.min(ps_col);
    let axis = if drift.length() <= tolerance {
        normal
    } else {
        (last - p0).normalize()
    };
    if axis.dot(normal) < 0.2 {
        return Err(err(format!(
            "the slice positions run along {axis:.3}, nearly in the image plane (normal \
             {normal:.3}): not a stack of slices"
        )));
    }
    for (s, p) in slices.iter().zip(&positions) {
        let off = (*p - p0) - (*p - p0).dot(axis) * axis;
        if off.length() > tolerance.max(1e-3 * (last - p0).length()) {
            return Err(err(format!(
                "{} at {} lies {:.3} mm off the line of the other slice positions (from {} to \
                 {}): not a regular stack",
                name(s),
                fmt_point(*p),
                off.length(),
                fmt_point(p0),
                fmt_point(last)
            )));
        }
    }
    let t: Vec<f64> = positions.iter().map(|p| (*p - p0).dot(axis)).collect();
    let n = t.len();
    let mut steps: Vec<f64> = t.windows(2).map(|w| w[1] - w[0]).collect();
    steps.sort_by(f64::total_cmp);
    let median = steps[(steps.len() - 1) / 2];
    let gaps: Vec<usize> = (0..n - 1)
        .filter(|&k| t[k + 1] - t[k] > 1.5 * median)
        .collect();
    if !gaps.is_empty() {
        let list: Vec<String> = gaps
            .iter()
            .take(5)
            .map(|&k| {
                let gap = t[k + 1] - t[k];
                format!(
                    "{:.3} mm between {} ({}) and {} ({}), about {} slice(s) missing",
                    gap,
                    fmt_point(positions[k]),
                    name(&slices[k]),
                    fmt_point(positions[k + 1]),
                    name(&slices[k + 1]),
                    ((gap / median).round() as i64 - 1).max(1)
                )
            })
            .collect();
        return Err(err(format!(
            "missing slices: the median slice spacing is {median:.3} mm, but there {} {} gap{} \
             above 1.5× it: {}{}; Isoscope refuses series with missing slices (open a complete \
             series, or pass the slices of one side as a list of files)",
            if gaps.len() == 1 { "is" } else { "are" },
            gaps.len(),
            if gaps.len() == 1 { "" } else { "s" },
            list.join("; "),
            if gaps.len() > 5 { "; ..." } else { "" }
        )));
    }
    let uniform_step = t[n - 1] / (n - 1) as f64;
    let uniform = t
        .iter()
        .enumerate()
        .all(|(k, &tk)| (tk - k as f64 * uniform_step).abs() <= 0.02 * uniform_step);
    let k_axis = if uniform {
        AxisCoords::Uniform {
            origin: 0.0,
            spacing: uniform_step,
        }
    } else {
        AxisCoords::Explicit(t.clone().into())
    };
    let (axes, m) = oriented(p0, row, col, axis, ps_col, ps_row, k_axis);
    let grid = Grid::new([format.cols, format.rows, n], axes, m)
        .map_err(|e| FormatError::geometry(&files[slices[0].file], e))?
        .with_world_frame(WorldFrame::Lps);
    Ok(Plan {
        grid,
        phases,
        format,
        rescale,
    })
}

/// Axes and `world_from_grid` for a grid at `p0` with unit directions `r` (i), `c` (j) and
/// `s` (k), in-plane spacings `dx`, `dy`, and slice coordinates `k_axis` from 0. A grid along
/// +x, +y, +z keeps no transform (its origin goes into the axes).
fn oriented(
    p0: DVec3,
    r: DVec3,
    c: DVec3,
    s: DVec3,
    dx: f64,
    dy: f64,
    k_axis: AxisCoords,
) -> ([AxisCoords; 3], Option<DAffine3>) {
    let aligned = r == DVec3::X && c == DVec3::Y && s == DVec3::Z;
    if aligned {
        let k_axis = match k_axis {
            AxisCoords::Uniform { origin, spacing } => AxisCoords::Uniform {
                origin: origin + p0.z,
                spacing,
            },
            AxisCoords::Explicit(t) => AxisCoords::Explicit(t.iter().map(|x| x + p0.z).collect()),
        };
        return (
            [
                AxisCoords::Uniform {
                    origin: p0.x,
                    spacing: dx,
                },
                AxisCoords::Uniform {
                    origin: p0.y,
                    spacing: dy,
                },
                k_axis,
            ],
            None,
        );
    }
    (
        [
            AxisCoords::Uniform {
                origin: 0.0,
                spacing: dx,
            },
            AxisCoords::Uniform {
                origin: 0.0,
                spacing: dy,
            },
            k_axis,
        ],
        Some(DAffine3::from_mat3_translation(
            DMat3::from_cols(r, c, s),
            p0,
        )),
    )
}

/// Splits position clusters into phases: one slice per cluster (a plain volume), or, when
/// every position repeats once per temporal position, one volume per temporal position.
fn phases(
    clusters: &[Vec<Slice>],
    name: &dyn Fn(&Slice) -> String,
    err: &dyn Fn(String) -> FormatError,
    pos: &dyn Fn(&Slice) -> DVec3,
) -> Result<Vec<Vec<Slice>>, FormatError> {
    if clusters.iter().all(|c| c.len() == 1) {
        return Ok(vec![clusters.iter().map(|c| c[0].clone()).collect()]);
    }
    let duplicate = || {
        let c = clusters
            .iter()
            .find(|c| c.len() > 1)
            .unwrap_or(&clusters[0]);
        let (a, b) = (&c[0], &c[c.len().min(2) - 1]);
        err(format!(
            "duplicate slices: {} and {} are both at {}{}",
            name(a),
            name(b),
            fmt_point(pos(a)),
            if a.info.temporal.is_some() && a.info.temporal == b.info.temporal {
                format!(
                    " with the same temporal position {}",
                    a.info.temporal.unwrap_or(0)
                )
            } else if a.info.temporal.is_none() || b.info.temporal.is_none() {
                " (a multi-phase series needs TemporalPositionIdentifier to tell its phases apart)"
                    .to_string()
            } else {
                String::new()
            }
        ))
    };
    let count = clusters[0].len();
    let mut ids: Vec<i64> = Vec::with_capacity(count);
    for s in &clusters[0] {
        match s.info.temporal {
            Some(t) if !ids.contains(&t) => ids.push(t),
            _ => return Err(duplicate()),
        }
    }
    ids.sort_unstable();
    let mut out = vec![Vec::with_capacity(clusters.len()); count];
    for c in clusters {
        let mut here: Vec<i64> = c.iter().filter_map(|s| s.info.temporal).collect();
        here.sort_unstable();
        if c.len() != count || here != ids {
            return Err(duplicate());
        }
        for s in c {
            let phase = ids
                .iter()
                .position(|&t| Some(t) == s.info.temporal)
                .unwrap_or(0);
            out[phase].push(s.clone());
        }
    }
    Ok(out)
}

/// Loads phase `phase` of `plan` from `files`.
pub(crate) fn load_phase(
    plan: &Plan,
    phase: usize,
    files: &[PathBuf],
) -> Result<RectilinearVolume, FormatError> {
    let slices = &plan.phases[phase];
    let data: VoxelData = volume_core::match_voxel_type!(plan.voxel_type(), V => {
        assemble::<V>(plan, slices, files)?.into()
    });
    let volume = RectilinearVolume::new(plan.grid.clone(), data)
        .map_err(|e| FormatError::geometry(&files[slices[0].file], e))?;
    Ok(volume.with_value_map(plan.value_map()))
}

/// Where a frame goes: `(frame, rescale, destination)`.
type Target<'a, T> = (usize, (f64, f64), &'a mut [T]);

/// Reads and decodes the slices (files in parallel) into one buffer, slice k at `k·rows·cols`.
fn assemble<T: Voxel>(
    plan: &Plan,
    slices: &[Slice],
    files: &[PathBuf],
) -> Result<Vec<T>, FormatError> {
    let per_slice = plan.format.frame_samples();
    let mut buf = vec![T::default(); per_slice * slices.len()];
    // Destination chunks grouped by file: (file, [(frame, rescale, chunk)]).
    let mut by_file: Vec<(usize, Vec<Target<'_, T>>)> = Vec::new();
    let mut index = std::collections::HashMap::new();
    for (s, chunk) in slices.iter().zip(buf.chunks_mut(per_slice)) {
        let i = *index.entry(s.file).or_insert_with(|| {
            by_file.push((s.file, Vec::new()));
            by_file.len() - 1
        });
        by_file[i].1.push((s.frame, s.info.rescale, chunk));
    }
    let convert = plan.rescale.is_none();
    by_file
        .into_par_iter()
        .try_for_each(|(file, mut targets)| {
            let path = &files[file];
            let dicom = super::file::read(path, super::file::Want::Pixels)?;
            // The file may have changed since it was listed: its format must still match.
            let frames = match content(&dicom)? {
                Content::Image(info) if info.format == plan.format => info.frames.len(),
                _ => {
                    return Err(FormatError::DicomFile {
                        path: path.clone(),
                        reason: "changed since the series was listed (its image format differs)"
                            .into(),
                    });
                }
            };
            if let Some((frame, _, _)) = targets.iter().find(|(f, _, _)| *f >= frames) {
                return Err(FormatError::DicomFile {
                    path: path.clone(),
                    reason: format!("frame {} is gone: the file has {frames} frames", frame + 1),
                });
            }
            pixels::for_each_frame(&dicom, &plan.format, frames, |frame, samples| {
                for (_, rescale, dst) in targets.iter_mut().filter(|(f, _, _)| *f == frame) {
                    pixels::store(samples, &plan.format, convert.then_some(*rescale), dst);
                }
                Ok(())
            })
        })?;
    Ok(buf)
}

/// The phases of a multi-phase series, loaded lazily.
pub(crate) struct PhaseSteps {
    plan: Arc<Plan>,
    files: Arc<Vec<PathBuf>>,
    root: PathBuf,
    first: FirstStep,
}

impl StepLoader for PhaseSteps {
    fn step_count(&self) -> usize {
        self.plan.phases.len()
    }

    fn load_step(&self, step: usize) -> Result<RectilinearVolume, String> {
        if step == 0
            && let Some(v) = self.first.take()
        {
            return Ok(v);
        }
        if step >= self.plan.phases.len() {
            return Err(format!("step {step} out of range"));
        }
        load_phase(&self.plan, step, &self.files).map_err(|e| e.to_string())
    }

    fn time_value(&self, step: usize) -> Option<f64> {
        self.plan
            .phases
            .get(step)?
            .first()?
            .info
            .temporal
            .map(|t| t as f64)
    }

    fn describe(&self) -> String {
        format!(
            "DICOM series of {} phases × {} slices ({})",
            self.plan.phases.len(),
            self.plan.phases[0].len(),
            self.root.display()
        )
    }
}

/// Loads the planned series: a volume, or a time series of its phases.
pub(crate) fn load(
    plan: Plan,
    files: Vec<PathBuf>,
    root: &Path,
) -> Result<crate::Dataset, FormatError> {
    for s in plan.phases.iter().flatten() {
        crate::input::note_input(&files[s.file]);
    }
    let first = load_phase(&plan, 0, &files)?;
    if plan.phases.len() == 1 {
        return Ok(crate::Dataset::Volume(first));
    }
    let loader = PhaseSteps {
        plan: Arc::new(plan),
        files: Arc::new(files),
        root: root.to_path_buf(),
        first: FirstStep::new(first),
    };
    let series = TimeSeries::open(Arc::new(loader)).map_err(|e| FormatError::DicomSeries {
        path: root.to_path_buf(),
        reason: e.to_string(),
    })?;
    Ok(crate::Dataset::Series(series))
}
