//! The NRRD writer: NRRD0004, native byte order, raw or gzip.
//!
//! Oriented volumes (with `world_from_grid`) are written with `space dimension: 3`, `space
//! directions` and `space origin`; others with `spacings`, `axis mins` and `centers: node`
//! (so the minimum is the first sample, see [`super::geometry`]). Grids with explicit
//! coordinates cannot be written (NRRD has no per-sample coordinates) and are rejected.
//! The file is written to a temporary name in the same directory and renamed, so a failed
//! write never leaves a half-written file under the final name.

use std::fmt::Write as _;
use std::io::Write;
use std::path::Path;

use glam::DVec3;
use volume_core::{AxisCoords, RectilinearVolume, VoxelType, WorldFrame};

use crate::error::FormatError;
use crate::output::Replace;
use crate::raw::Endian;

/// Data encoding of a written NRRD.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum NrrdEncoding {
    #[default]
    Raw,
    Gzip,
}

fn teem_type(t: VoxelType) -> &'static str {
    match t {
        VoxelType::U8 => "uint8",
        VoxelType::I8 => "int8",
        VoxelType::U16 => "uint16",
        VoxelType::I16 => "int16",
        VoxelType::U32 => "uint32",
        VoxelType::I32 => "int32",
        VoxelType::F32 => "float",
        VoxelType::F64 => "double",
    }
}

fn vec3(v: DVec3) -> String {
    format!("({},{},{})", v.x, v.y, v.z)
}

/// The header text for `volume` (ends with the blank line).
pub(crate) fn header_text(
    path: &Path,
    volume: &RectilinearVolume,
    encoding: NrrdEncoding,
) -> Result<String, FormatError> {
    header_with_data_file(path, volume, encoding, None)
}

/// The header text; with `data_file`, a detached header naming it (ends with a newline).
fn header_with_data_file(
    path: &Path,
    volume: &RectilinearVolume,
    encoding: NrrdEncoding,
    data_file: Option<&str>,
) -> Result<String, FormatError> {
    let grid = &volume.grid;
    if !volume.value_map.is_identity() {
        // NRRD has no linear rescale field: writing the stored values alone would change
        // what they mean.
        return Err(FormatError::Unsupported {
            path: path.to_path_buf(),
            field: "type".into(),
            reason: format!(
                "the volume's values are rescaled (slope {}, intercept {}); NRRD stores no \
                 rescale: convert the values first",
                volume.value_map.slope, volume.value_map.intercept
            ),
        });
    }
    let Some(spacing) = grid.uniform_spacing() else {
        let axis = grid
            .axes()
            .iter()
            .position(|a| !a.is_uniform())
            .unwrap_or(0);
        return Err(FormatError::Unsupported {
            path: path.to_path_buf(),
            field: "spacings".into(),
            reason: format!(
                "axis {axis} has explicit coordinates; NRRD can only store uniform spacing"
            ),
        });
    };
    let dims = grid.dims();
    let t = volume.data.voxel_type();
    let mut h = String::from("NRRD0004\n");
    h.push_str("# Complete NRRD file format specification at:\n");
    h.push_str("# http://teem.sourceforge.net/nrrd/format.html\n");
    let _ = writeln!(h, "type: {}", teem_type(t));
    h.push_str("dimension: 3\n");
    let _ = writeln!(h, "sizes: {} {} {}", dims[0], dims[1], dims[2]);
    let frame = grid.world_frame();
    // A known patient frame is written as `space`, which needs `space directions`.
    let oriented = grid
        .world_from_grid()
        .or_else(|| frame.is_known().then_some(glam::DAffine3::IDENTITY));
    if let Some(m) = oriented {
        let origin = m.transform_point3(grid.origin());
        match frame {
            WorldFrame::Ras => h.push_str("space: right-anterior-superior\n"),
            WorldFrame::Lps => h.push_str("space: left-posterior-superior\n"),
            WorldFrame::Unknown => h.push_str("space dimension: 3\n"),
        }
        let dirs: Vec<String> = (0..3)
            .map(|a| vec3(m.matrix3.col(a) * spacing[a]))
            .collect();
        let _ = writeln!(h, "space directions: {}", dirs.join(" "));
        let _ = writeln!(h, "space origin: {}", vec3(origin));
    } else {
        let origin = grid.axes().clone().map(|a| match a {
            AxisCoords::Uniform { origin, .. } => origin,
            AxisCoords::Explicit(c) => c[0],
        });
        let _ = writeln!(h, "spacings: {} {} {}", spacing[0], spacing[1], spacing[2]);
        let _ = writeln!(h, "axis mins: {} {} {}", origin[0], origin[1], origin[2]);
    }
    h.push_str("centers: node node node\n");
    h.push_str("kinds: domain domain domain\n");
    if t.size_bytes() > 1 {
        let _ = writeln!(h, "endian: {}", Endian::native().name());
    }
    let _ = writeln!(
        h,
        "encoding: {}",
        match encoding {
            NrrdEncoding::Raw => "raw",
            NrrdEncoding::Gzip => "gzip",
        }
    );
    if let Some(name) = data_file {
        let _ = writeln!(h, "data file: {name}");
        return Ok(h);
    }
    // Pad with a comment so the data starts 8-byte aligned: readers can then view it in place
    // in a memory map (zero copy) for every voxel type.
    let mut pad = (8 - (h.len() + 1) % 8) % 8;
    if pad == 1 {
        pad = 9;
    }
    if pad > 0 {
        h.extend(std::iter::repeat_n('#', pad - 1));
        h.push('\n');
    }
    h.push('\n');
    debug_assert_eq!(h.len() % 8, 0);
    Ok(h)
}

/// Writes `volume` to `path` as an attached NRRD, through [`crate::output::OutputFile`]
/// (never over an input; an existing file only with [`Replace::Allow`]).
pub fn write_nrrd(
    path: &Path,
    volume: &RectilinearVolume,
    encoding: NrrdEncoding,
    replace: Replace,
) -> Result<(), FormatError> {
    let header = header_text(path, volume, encoding)?;
    crate::output::write_output_with(path, replace, |w| {
        w.write_all(header.as_bytes())
            .map_err(|e| FormatError::io(path, e))?;
        write_data(path, w, volume, encoding)
    })
}

/// Writes the voxels of `volume` (native order, `encoding`) to `w`.
fn write_data(
    path: &Path,
    w: &mut dyn Write,
    volume: &RectilinearVolume,
    encoding: NrrdEncoding,
) -> Result<(), FormatError> {
    let io = |e: std::io::Error| FormatError::io(path, e);
    let bytes: &[u8] =
        volume_core::dispatch_voxels!(&volume.data, b => bytemuck::cast_slice(b.as_slice()));
    match encoding {
        NrrdEncoding::Raw => w.write_all(bytes).map_err(io),
        NrrdEncoding::Gzip => {
            let mut gz = flate2::write::GzEncoder::new(w, flate2::Compression::new(6));
            gz.write_all(bytes).map_err(io)?;
            gz.finish().map_err(io)?;
            Ok(())
        }
    }
}

/// Writes `volume` as a detached NRRD: the header at `path` (`NAME.nhdr`) and the data in
/// `NAME.raw` (raw) or `NAME.raw.gz` (gzip) beside it, named by its `data file:` field.
/// Both outputs are checked first (never over an input; existing files only with
/// [`Replace::Allow`]); the data is written before the header, so a header never names data
/// that is not complete.
pub fn write_nrrd_detached(
    path: &Path,
    volume: &RectilinearVolume,
    encoding: NrrdEncoding,
    replace: Replace,
) -> Result<(), FormatError> {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let stem = match name.rfind('.') {
        Some(i) if i > 0 => &name[..i],
        _ => &name[..],
    };
    let data_name = format!(
        "{stem}.raw{}",
        if encoding == NrrdEncoding::Gzip {
            ".gz"
        } else {
            ""
        }
    );
    if data_name.chars().any(char::is_whitespace) {
        return Err(FormatError::BadOutput {
            path: path.to_path_buf(),
            reason: "a detached NRRD's data file name may not contain spaces".into(),
        });
    }
    let data_path = path.with_file_name(&data_name);
    let header = header_with_data_file(path, volume, encoding, Some(&data_name))?;
    crate::output::check_output(&data_path, replace)?;
    crate::output::check_output(path, replace)?;
    crate::output::check_distinct(&[path, &data_path])?;
    crate::output::write_output_with(&data_path, replace, |w| {
        write_data(&data_path, w, volume, encoding)
    })?;
    crate::output::write_output(path, header.as_bytes(), replace)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::nrrd::read_nrrd;
    use glam::{DAffine3, DMat3};
    use volume_core::Grid;

    use crate::test_support::{sample_volume as sample, volume_of};

    fn read_volume(p: &Path) -> RectilinearVolume {
        volume_of(read_nrrd(p))
    }

    #[test]
    fn round_trips_uniform_volumes_in_both_encodings() {
        let dir = tempfile::tempdir().unwrap();
        let v = sample(Grid::uniform([5, 4, 3], [-1.5, 0.25, 7.0], [0.3, 0.7, 1.1]).unwrap());
        for (enc, name) in [
            (NrrdEncoding::Raw, "a.nrrd"),
            (NrrdEncoding::Gzip, "b.nrrd"),
        ] {
            let p = dir.path().join(name);
            write_nrrd(&p, &v, enc, Replace::Refuse).unwrap();
            let r = read_volume(&p);
            assert_eq!(r.grid, v.grid);
            assert_eq!(r.data.is_shared(), enc == NrrdEncoding::Raw);
            for k in 0..3 {
                for j in 0..4 {
                    for i in 0..5 {
                        assert_eq!(r.value_f64(i, j, k), v.value_f64(i, j, k));
                    }
                }
            }
        }
        // No temporary files left behind.
        let names: Vec<_> = std::fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(names.len(), 2, "{names:?}");
    }

    #[test]
    fn round_trips_oriented_volumes_through_space_directions() {
        let dir = tempfile::tempdir().unwrap();
        let rot = DMat3::from_rotation_z(0.3) * DMat3::from_rotation_x(-0.2);
        let wfg = DAffine3::from_mat3_translation(rot, DVec3::new(10.0, -5.0, 2.5));
        let axes = [0.5, 1.0, 2.0].map(|s| AxisCoords::Uniform {
            origin: 0.0,
            spacing: s,
        });
        let v = sample(Grid::new([3, 3, 2], axes, Some(wfg)).unwrap());
        let p = dir.path().join("o.nrrd");
        write_nrrd(&p, &v, NrrdEncoding::Raw, Replace::Refuse).unwrap();
        let r = read_volume(&p);
        let m = r.grid.world_from_grid().expect("oriented");
        for (i, j, k) in [(0, 0, 0), (2, 1, 1), (1, 2, 0)] {
            let want = wfg.transform_point3(v.grid.grid_position(i, j, k));
            let got = m.transform_point3(r.grid.grid_position(i, j, k));
            assert!((want - got).length() < 1e-12, "{want} vs {got}");
        }
    }

    #[test]
    fn round_trips_the_world_frame() {
        let dir = tempfile::tempdir().unwrap();
        for frame in [WorldFrame::Ras, WorldFrame::Lps, WorldFrame::Unknown] {
            let g = Grid::uniform([3, 3, 2], [1.0, -2.0, 3.0], [0.5, 1.0, 2.0]).unwrap();
            let v = sample(g.with_world_frame(frame));
            let p = dir.path().join(format!("{frame}.nrrd"));
            write_nrrd(&p, &v, NrrdEncoding::Raw, Replace::Refuse).unwrap();
            let r = read_volume(&p);
            assert_eq!(r.grid, v.grid, "{frame}");
        }
        let v = sample(Grid::uniform([3, 3, 2], [0.0; 3], [1.0; 3]).unwrap())
            .with_value_map(volume_core::ValueMap::new(2.0, 1.0).unwrap());
        let p = dir.path().join("scaled.nrrd");
        let e = write_nrrd(&p, &v, NrrdEncoding::Raw, Replace::Refuse).unwrap_err();
        assert!(e.to_string().contains("rescale"), "{e}");
        assert!(!p.exists());
    }

    #[test]
    fn detached_headers_name_their_data_file() {
        let dir = tempfile::tempdir().unwrap();
        let v = sample(
            Grid::uniform([4, 3, 2], [1.0, -2.0, 0.5], [0.5, 1.0, 2.0])
                .unwrap()
                .with_world_frame(WorldFrame::Lps),
        );
        for (enc, data) in [
            (NrrdEncoding::Raw, "d.raw"),
            (NrrdEncoding::Gzip, "g.raw.gz"),
        ] {
            let p = dir
                .path()
                .join(data.replace(".raw", ".nhdr").replace(".gz", ""));
            write_nrrd_detached(&p, &v, enc, Replace::Refuse).unwrap();
            let text = std::fs::read_to_string(&p).unwrap();
            assert!(text.contains(&format!("data file: {data}")), "{text}");
            assert!(dir.path().join(data).is_file());
            // Both outputs exist now: refused without --force.
            let e = write_nrrd_detached(&p, &v, enc, Replace::Refuse).unwrap_err();
            assert!(matches!(e, FormatError::OutputExists { .. }), "{e}");
            let r = read_volume(&p);
            assert_eq!(r.grid, v.grid);
            assert_eq!(r.data.is_shared(), enc == NrrdEncoding::Raw);
            assert_eq!(r.value_f64(3, 2, 1), v.value_f64(3, 2, 1));
            // Once read, the data file is an input: never an output, even with --force.
            let e = write_nrrd_detached(&p, &v, enc, Replace::Allow).unwrap_err();
            assert!(matches!(e, FormatError::OutputIsInput { .. }), "{e}");
        }
    }

    #[test]
    fn rejects_explicit_coordinates() {
        let dir = tempfile::tempdir().unwrap();
        let u = AxisCoords::Uniform {
            origin: 0.0,
            spacing: 1.0,
        };
        let e = AxisCoords::Explicit(vec![0.0, 1.0, 3.0].into());
        let v = sample(Grid::new([2, 3, 2], [u.clone(), e, u], None).unwrap());
        let p = dir.path().join("x.nrrd");
        let err = write_nrrd(&p, &v, NrrdEncoding::Raw, Replace::Refuse).unwrap_err();
        assert!(
            matches!(&err, FormatError::Unsupported { field, reason, .. } if field == "spacings" && reason.contains("axis 1")),
            "{err}"
        );
        assert!(!p.exists());
    }
}
