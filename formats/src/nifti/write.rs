//! The NIfTI-1 writer: one `.nii` file (header, 4-byte extension flag, data at byte 352),
//! gzip-compressed as a whole when the name ends in `.nii.gz`; native byte order.
//!
//! - Geometry: the sform (`sform_code` 1, scanner-based) is the grid's voxel-to-world affine
//!   (`world_from_grid` · spacing, origin), converted to RAS+ (LPS worlds negate x and y).
//!   When the axis directions are orthonormal the same affine is also written as the qform
//!   (`qform_code` 1: quaternion, `qfac` = −1 for a left-handed voxel frame, `pixdim`); a
//!   sheared affine has only the sform. A grid without a patient frame is written as if its
//!   world were RAS (NIfTI has no "unknown" frame with coordinates), so the coordinates
//!   survive. Explicit per-sample coordinates cannot be written.
//! - Values: voxels in their stored type; a volume's value map becomes
//!   `scl_slope`/`scl_inter` (as 32-bit floats), the identity slope 1, intercept 0.
//! - A series is written as one 4D file (`dim[4]` steps, `pixdim[4]` the mean step time,
//!   `toffset` the first); its steps must share the grid and value map of step 0.
//! - Dims are 16-bit in NIfTI-1: sizes above 32767 are refused.
//!
//! The file is written through [`crate::output::OutputFile`] (never over an input; a
//! temporary file renamed when complete).

use std::io::Write;
use std::path::Path;

use glam::{DMat3, DVec3};
use volume_core::series::TimeSeries;
use volume_core::{RectilinearVolume, WorldFrame};

use super::header::datatype_of;
use crate::error::FormatError;
use crate::output::Replace;

/// Bytes before the data: the header and the extension flag (no extensions).
const VOX_OFFSET: usize = 352;

fn bad_output(path: &Path, reason: String) -> FormatError {
    FormatError::BadOutput {
        path: path.to_path_buf(),
        reason,
    }
}

/// True for `.nii.gz` (gzip), false for `.nii`; another name is an error.
#[allow(clippy::case_sensitive_file_extension_comparisons)] // lower-cased first
fn gzip_from_name(path: &Path) -> Result<bool, FormatError> {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default();
    if name.ends_with(".nii.gz") {
        Ok(true)
    } else if name.ends_with(".nii") {
        Ok(false)
    } else {
        Err(bad_output(
            path,
            "a NIfTI output is named .nii or .nii.gz".into(),
        ))
    }
}

/// The voxel-to-RAS affine of `volume`'s grid: the axis directions (one voxel step each)
/// and the world position of voxel (0, 0, 0).
fn ras_affine(path: &Path, volume: &RectilinearVolume) -> Result<(DMat3, DVec3), FormatError> {
    let grid = &volume.grid;
    let Some(spacing) = grid.uniform_spacing() else {
        let axis = grid
            .axes()
            .iter()
            .position(|a| !a.is_uniform())
            .unwrap_or(0);
        return Err(FormatError::Unsupported {
            path: path.to_path_buf(),
            field: format!("pixdim[{}]", axis + 1),
            reason: format!(
                "axis {axis} has explicit coordinates; NIfTI can only store uniform spacing"
            ),
        });
    };
    let m = grid.world_from_grid().unwrap_or_default();
    let linear = m.matrix3 * DMat3::from_diagonal(DVec3::from(spacing));
    let origin = m.transform_point3(grid.origin());
    Ok(match grid.world_frame() {
        WorldFrame::Lps => {
            let flip = DMat3::from_diagonal(DVec3::new(-1.0, -1.0, 1.0));
            (flip * linear, flip * origin)
        }
        WorldFrame::Ras | WorldFrame::Unknown => (linear, origin),
    })
}

/// The quaternion `(b, c, d)` (with `a ≥ 0`) of a proper rotation.
fn quaternion(r: DMat3) -> [f64; 3] {
    let e = |i: usize, j: usize| r.col(j)[i];
    let trace = e(0, 0) + e(1, 1) + e(2, 2);
    let (a, b, c, d);
    if trace > 0.0 {
        a = 0.5 * (1.0 + trace).sqrt();
        b = (e(2, 1) - e(1, 2)) / (4.0 * a);
        c = (e(0, 2) - e(2, 0)) / (4.0 * a);
        d = (e(1, 0) - e(0, 1)) / (4.0 * a);
    } else if e(0, 0) >= e(1, 1) && e(0, 0) >= e(2, 2) {
        b = 0.5 * (1.0 + e(0, 0) - e(1, 1) - e(2, 2)).sqrt();
        a = (e(2, 1) - e(1, 2)) / (4.0 * b);
        c = (e(0, 1) + e(1, 0)) / (4.0 * b);
        d = (e(0, 2) + e(2, 0)) / (4.0 * b);
    } else if e(1, 1) >= e(2, 2) {
        c = 0.5 * (1.0 + e(1, 1) - e(0, 0) - e(2, 2)).sqrt();
        a = (e(0, 2) - e(2, 0)) / (4.0 * c);
        b = (e(0, 1) + e(1, 0)) / (4.0 * c);
        d = (e(1, 2) + e(2, 1)) / (4.0 * c);
    } else {
        d = 0.5 * (1.0 + e(2, 2) - e(0, 0) - e(1, 1)).sqrt();
        a = (e(1, 0) - e(0, 1)) / (4.0 * d);
        b = (e(0, 2) + e(2, 0)) / (4.0 * d);
        c = (e(1, 2) + e(2, 1)) / (4.0 * d);
    }
    if a < 0.0 { [-b, -c, -d] } else { [b, c, d] }
}

/// The qform of `linear` (one voxel step per column): `(quaternion, qfac)`, or `None` when
/// the directions are not orthonormal (a sheared affine has no qform).
fn qform(linear: DMat3, spacing: [f64; 3]) -> Option<([f64; 3], f64)> {
    let mut u = DMat3::from_cols(
        linear.x_axis / spacing[0],
        linear.y_axis / spacing[1],
        linear.z_axis / spacing[2],
    );
    let gram = u.transpose() * u;
    let off = (gram - DMat3::IDENTITY).to_cols_array();
    if off.iter().any(|x| x.abs() > 1e-6) {
        return None;
    }
    let qfac = if u.determinant() < 0.0 {
        u.z_axis = -u.z_axis;
        -1.0
    } else {
        1.0
    };
    Some((quaternion(u), qfac))
}

/// The 352 bytes before the data of `steps` volumes shaped like `volume`.
fn header_bytes(
    path: &Path,
    volume: &RectilinearVolume,
    steps: usize,
    time: Option<(f64, f64)>,
) -> Result<Vec<u8>, FormatError> {
    let dims = volume.grid.dims();
    let mut dim = [1i16; 8];
    dim[0] = if steps > 1 { 4 } else { 3 };
    for (i, &n) in dims.iter().chain([&steps]).enumerate() {
        dim[i + 1] = i16::try_from(n).map_err(|_| FormatError::Unsupported {
            path: path.to_path_buf(),
            field: format!("dim[{}]", i + 1),
            reason: format!("size {n}: NIfTI-1 sizes are at most 32767"),
        })?;
    }
    let (linear, origin) = ras_affine(path, volume)?;
    let spacing = volume
        .grid
        .uniform_spacing()
        .expect("checked by ras_affine");
    let q = qform(linear, spacing);
    let t = volume.data.voxel_type();
    let map = volume.value_map;

    let mut h = vec![0u8; VOX_OFFSET];
    let mut put = |at: usize, bytes: &[u8]| h[at..at + bytes.len()].copy_from_slice(bytes);
    put(0, &348i32.to_ne_bytes());
    for (i, d) in dim.iter().enumerate() {
        put(40 + 2 * i, &d.to_ne_bytes());
    }
    put(70, &datatype_of(t).to_ne_bytes());
    put(72, &((t.size_bytes() * 8) as i16).to_ne_bytes());
    let mut pixdim = [0f32; 8];
    pixdim[0] = q.map_or(1.0, |(_, qfac)| qfac as f32);
    for a in 0..3 {
        pixdim[a + 1] = spacing[a] as f32;
    }
    if let Some((_, dt)) = time {
        pixdim[4] = dt as f32;
    }
    for (i, p) in pixdim.iter().enumerate() {
        put(76 + 4 * i, &p.to_ne_bytes());
    }
    put(108, &(VOX_OFFSET as f32).to_ne_bytes());
    put(112, &(map.slope as f32).to_ne_bytes());
    put(116, &(map.intercept as f32).to_ne_bytes());
    // Space in millimetres; time in seconds for a series.
    put(123, &[if steps > 1 { 2 | 8 } else { 2 }]);
    if let Some((t0, _)) = time {
        put(136, &(t0 as f32).to_ne_bytes());
    }
    put(148, b"isoscope");
    put(252, &i16::from(q.is_some()).to_ne_bytes());
    put(254, &1i16.to_ne_bytes());
    if let Some((bcd, _)) = q {
        for (i, v) in bcd.iter().enumerate() {
            put(256 + 4 * i, &(*v as f32).to_ne_bytes());
        }
        for (i, v) in origin.to_array().iter().enumerate() {
            put(268 + 4 * i, &(*v as f32).to_ne_bytes());
        }
    }
    for r in 0..3 {
        let row = [
            linear.x_axis[r],
            linear.y_axis[r],
            linear.z_axis[r],
            origin[r],
        ];
        for (c, v) in row.iter().enumerate() {
            put(280 + 16 * r + 4 * c, &(*v as f32).to_ne_bytes());
        }
    }
    put(344, b"n+1\0");
    Ok(h)
}

/// Streams the header and `steps` volumes (from `step`) into `path`.
fn write_file(
    path: &Path,
    header: &[u8],
    steps: usize,
    replace: Replace,
    step: &mut dyn FnMut(usize) -> Result<RectilinearVolume, FormatError>,
) -> Result<(), FormatError> {
    let gzip = gzip_from_name(path)?;
    let io = |e: std::io::Error| FormatError::io(path, e);
    crate::output::write_output_with(path, replace, |w| {
        let mut body = |out: &mut dyn Write| -> Result<(), FormatError> {
            out.write_all(header).map_err(io)?;
            for s in 0..steps {
                let v = step(s)?;
                let bytes: &[u8] =
                    volume_core::dispatch_voxels!(&v.data, b => bytemuck::cast_slice(b.as_slice()));
                out.write_all(bytes).map_err(io)?;
            }
            Ok(())
        };
        if gzip {
            let mut gz = flate2::write::GzEncoder::new(w, flate2::Compression::new(6));
            body(&mut gz)?;
            // `finish` reports the trailer's write error, which a drop would lose.
            gz.finish().map_err(io)?;
            Ok(())
        } else {
            body(w)
        }
    })
}

/// Writes `volume` to `path` (`.nii` or `.nii.gz`) as NIfTI-1, through
/// [`crate::output::OutputFile`] (never over an input; an existing file only with
/// [`Replace::Allow`]).
pub fn write_nifti(
    path: &Path,
    volume: &RectilinearVolume,
    replace: Replace,
) -> Result<(), FormatError> {
    gzip_from_name(path)?;
    let header = header_bytes(path, volume, 1, None)?;
    write_file(path, &header, 1, replace, &mut |_| Ok(volume.clone()))
}

/// Writes every step of `series` to `path` as one 4D NIfTI-1 file (see the module docs).
pub fn write_nifti_series(
    path: &Path,
    series: &TimeSeries,
    replace: Replace,
) -> Result<(), FormatError> {
    gzip_from_name(path)?;
    let n = series.step_count();
    let first = series.first();
    let time = (n > 1).then(|| {
        let t0 = series.time_value(0);
        (t0, (series.time_value(n - 1) - t0) / (n - 1) as f64)
    });
    let header = header_bytes(path, first, n, time)?;
    write_file(path, &header, n, replace, &mut |s| {
        let v = series.step(s).map_err(|e| FormatError::Series {
            path: path.to_path_buf(),
            reason: format!("step {s}: {e}"),
        })?;
        if v.grid != first.grid || v.value_map != first.value_map {
            return Err(FormatError::Series {
                path: path.to_path_buf(),
                reason: format!(
                    "step {s} has another geometry or value map than step 0; a 4D NIfTI holds one"
                ),
            });
        }
        Ok(v)
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::nifti::read_nifti;
    use glam::DAffine3;
    use volume_core::{AxisCoords, Grid, ValueMap};

    use crate::test_support::{sample_volume as sample, volume_of};

    fn read_volume(p: &Path) -> RectilinearVolume {
        volume_of(read_nifti(p))
    }

    fn same_voxels(a: &RectilinearVolume, b: &RectilinearVolume) {
        let [nx, ny, nz] = a.dims();
        for k in 0..nz {
            for j in 0..ny {
                for i in 0..nx {
                    assert_eq!(a.value_f64(i, j, k), b.value_f64(i, j, k));
                }
            }
        }
    }

    #[test]
    fn quaternions_round_trip_rotations_of_every_branch() {
        for r in [
            DMat3::IDENTITY,
            DMat3::from_rotation_z(3.0),
            DMat3::from_rotation_x(3.1),
            DMat3::from_rotation_y(-3.0),
            DMat3::from_rotation_z(0.3) * DMat3::from_rotation_x(-2.9),
        ] {
            let q = quaternion(r);
            // Back through the reader's formula (header.rs): a from b, c, d.
            let a = (1.0 - q.iter().map(|x| x * x).sum::<f64>()).max(0.0).sqrt();
            let [b, c, d] = q;
            let back = DMat3::from_quat(glam::DQuat::from_xyzw(b, c, d, a));
            assert!(
                (back - r).to_cols_array().iter().all(|x| x.abs() < 1e-12),
                "{r} vs {back}"
            );
        }
    }

    #[test]
    #[allow(clippy::case_sensitive_file_extension_comparisons)] // names made here
    fn round_trips_uniform_oriented_and_lps_volumes_in_both_compressions() {
        let dir = tempfile::tempdir().unwrap();
        let rot = DMat3::from_rotation_z(0.3) * DMat3::from_rotation_x(-0.2);
        let wfg = DAffine3::from_mat3_translation(rot, DVec3::new(10.0, -5.0, 2.5));
        let axes = [0.5, 1.0, 2.0].map(|s| AxisCoords::Uniform {
            origin: 0.0,
            spacing: s,
        });
        let volumes = [
            sample(Grid::uniform([5, 4, 3], [-1.5, 0.25, 7.0], [0.3, 0.7, 1.1]).unwrap()),
            sample(
                Grid::new([3, 3, 2], axes, Some(wfg))
                    .unwrap()
                    .with_world_frame(WorldFrame::Ras),
            ),
            sample(
                Grid::uniform([3, 2, 2], [1.0, 2.0, 3.0], [1.0; 3])
                    .unwrap()
                    .with_world_frame(WorldFrame::Lps),
            ),
        ];
        for (n, v) in volumes.iter().enumerate() {
            for name in [format!("v{n}.nii"), format!("v{n}.nii.gz")] {
                let p = dir.path().join(&name);
                write_nifti(&p, v, Replace::Refuse).unwrap();
                let r = read_volume(&p);
                assert_eq!(r.data.is_shared(), !name.ends_with(".gz"), "{name}");
                assert_eq!(r.dims(), v.dims());
                assert_eq!(r.grid.world_frame(), WorldFrame::Ras);
                same_voxels(&r, v);
                // The same points in RAS, to f32 precision.
                let ras = |g: &Grid, i, j, k| {
                    let m = g.world_from_grid().unwrap_or_default();
                    let w = m.transform_point3(g.grid_position(i, j, k));
                    g.world_frame()
                        .ras_from_world()
                        .unwrap_or_default()
                        .transform_point3(w)
                };
                for (i, j, k) in [(0, 0, 0), (2, 1, 1), (1, 1, 0)] {
                    let (a, b) = (ras(&v.grid, i, j, k), ras(&r.grid, i, j, k));
                    assert!((a - b).length() < 1e-5, "{name}: {a} vs {b}");
                }
            }
        }
    }

    #[test]
    fn a_scaled_volume_keeps_its_stored_type_and_map() {
        let dir = tempfile::tempdir().unwrap();
        let v = sample(Grid::uniform([3, 3, 2], [0.0; 3], [1.0; 3]).unwrap())
            .with_value_map(ValueMap::new(0.5, -1024.0).unwrap());
        let p = dir.path().join("s.nii");
        write_nifti(&p, &v, Replace::Refuse).unwrap();
        let r = read_volume(&p);
        assert_eq!(r.data.voxel_type(), v.data.voxel_type());
        assert_eq!(r.value_map, v.value_map);
        same_voxels(&r, &v);
        // Refused: another name, explicit coordinates, dims beyond 16 bits; no file left.
        let e = write_nifti(&dir.path().join("s.nrrd"), &v, Replace::Refuse).unwrap_err();
        assert!(matches!(e, FormatError::BadOutput { .. }), "{e}");
        let u = AxisCoords::Uniform {
            origin: 0.0,
            spacing: 1.0,
        };
        let x = AxisCoords::Explicit(vec![0.0, 1.0, 3.0].into());
        let g = Grid::new([2, 3, 2], [u.clone(), x, u], None).unwrap();
        let e = write_nifti(&dir.path().join("x.nii"), &sample(g), Replace::Refuse).unwrap_err();
        assert_eq!(e.field(), Some("pixdim[2]"), "{e}");
        let wide = RectilinearVolume::new(
            Grid::uniform([40000, 1, 1], [0.0; 3], [1.0; 3]).unwrap(),
            vec![0u8; 40000].into(),
        )
        .unwrap();
        let e = write_nifti(&dir.path().join("w.nii"), &wide, Replace::Refuse).unwrap_err();
        assert_eq!(e.field(), Some("dim[1]"), "{e}");
        let names: Vec<_> = std::fs::read_dir(dir.path()).unwrap().collect();
        assert_eq!(names.len(), 1);
    }
}
