//! Legacy VTK images (VTK file formats document, "Simple Legacy Formats", Dataset Format):
//! `DATASET STRUCTURED_POINTS` (`DIMENSIONS`, `ORIGIN`, `SPACING` or the older
//! `ASPECT_RATIO`) and `DATASET RECTILINEAR_GRID` (`DIMENSIONS`, `X_COORDINATES`,
//! `Y_COORDINATES`, `Z_COORDINATES`: explicit axes), versions 2.0 to 5.1, ASCII or BINARY
//! (big-endian). `POINT_DATA` arrays (`SCALARS` with or without `LOOKUP_TABLE`, `FIELD`
//! arrays; vectors and the like are listed but not scalar) are read with the legacy mesh
//! reader's tokenizer; `CELL_DATA` is parsed and dropped.

use std::path::Path;
use std::sync::Arc;

use volume_core::{AxisCoords, Grid, RectilinearVolume};

use super::{
    PointArrays, checked_dims, from_mesh_error, image_grid, voxel_type, voxels_from_binary,
    voxels_from_f64,
};
use crate::error::FormatError;
use crate::mesh::MeshError;
use crate::mesh::vtk_legacy::{LegacyArray, Line, Parser, Values};

/// What the keywords of an image file said.
struct Parsed<'a> {
    dataset: String,
    dims: Option<([usize; 3], usize)>,
    origin: [f64; 3],
    spacing: ([f64; 3], usize),
    coords: [Option<Vec<f64>>; 3],
    arrays: Vec<LegacyArray<'a>>,
}

fn walk<'a>(path: &'a Path, data: &'a [u8]) -> Result<Parsed<'a>, MeshError> {
    let mut p = Parser::new(path, data);
    p.preamble()?;
    let mut out = Parsed {
        dataset: String::new(),
        dims: None,
        origin: [0.0; 3],
        spacing: ([1.0; 3], 0),
        coords: [None, None, None],
        arrays: Vec::new(),
    };
    let three = |p: &Parser<'_>, line: &Line<'_>| -> Result<[f64; 3], MeshError> {
        let mut v = [0.0; 3];
        for (i, x) in v.iter_mut().enumerate() {
            let w = p.word(line, i + 1, "three numbers")?;
            *x = w.parse().map_err(|_| {
                p.c.err_at(
                    line.start,
                    format!("{}: {w:?} is not a number", line.words[0]),
                )
            })?;
        }
        Ok(v)
    };
    while let Some(line) = p.keyword_line()? {
        let kw = line.words[0].to_ascii_uppercase();
        if kw != "DATASET" && out.dataset.is_empty() && kw != "FIELD" && kw != "METADATA" {
            return Err(p
                .c
                .err_at(line.start, format!("{} before DATASET", line.words[0])));
        }
        match kw.as_str() {
            "DATASET" => {
                let kind = p.word(&line, 1, "dataset type")?.to_ascii_uppercase();
                if !super::LEGACY_IMAGE_DATASETS.contains(&kind.as_str()) {
                    return Err(MeshError::Unsupported {
                        path: path.to_path_buf(),
                        what: format!(
                            "DATASET {kind} (STRUCTURED_POINTS and RECTILINEAR_GRID are read as \
                             volumes, UNSTRUCTURED_GRID as a tet mesh)"
                        ),
                    });
                }
                out.dataset = kind;
            }
            "DIMENSIONS" => {
                // One grid per file: the point data is checked against the DIMENSIONS before
                // it, which a later one would contradict.
                if let Some((_, first)) = out.dims {
                    return Err(p.c.err_at(
                        line.start,
                        format!(
                            "a second DIMENSIONS line (the first is on line {})",
                            crate::mesh::text::newlines(&data[..first.min(data.len())]) + 1
                        ),
                    ));
                }
                let mut d = [0usize; 3];
                for (i, x) in d.iter_mut().enumerate() {
                    *x = p.count_word(&line, i + 1, "DIMENSIONS", 0)?;
                }
                out.dims = Some((d, line.start));
            }
            "ORIGIN" => out.origin = three(&p, &line)?,
            "SPACING" | "ASPECT_RATIO" => out.spacing = (three(&p, &line)?, line.start),
            "X_COORDINATES" | "Y_COORDINATES" | "Z_COORDINATES" => {
                let axis = usize::from(kw.as_bytes()[0] - b'X');
                let n = p.count_word(&line, 1, &kw, 1)?;
                let ty = p.scalar_word(&line, 2)?;
                out.coords[axis] = Some(p.values(n, ty, &kw)?);
            }
            "POINT_DATA" => {
                let n = p.count_word(&line, 1, "POINT_DATA count", 0)?;
                let Some((dims, _)) = out.dims else {
                    return Err(p.c.err_at(line.start, "POINT_DATA before DIMENSIONS"));
                };
                let points = dims
                    .iter()
                    .try_fold(1usize, |acc, &d| acc.checked_mul(d))
                    .unwrap_or(usize::MAX);
                if n != points {
                    return Err(p.c.err_at(
                        line.start,
                        format!("POINT_DATA {n} but DIMENSIONS {dims:?} make {points} points"),
                    ));
                }
                p.attributes(n, Some(&mut out.arrays))?;
            }
            "CELL_DATA" => {
                let n = p.count_word(&line, 1, "CELL_DATA count", 0)?;
                p.attributes(n, None)?;
            }
            "FIELD" => p.field(&line, None)?,
            "METADATA" => p.metadata(),
            _ => {
                return Err(p
                    .c
                    .err_at(line.start, format!("unknown keyword {:?}", line.words[0])));
            }
        }
    }
    if out.dataset.is_empty() {
        return Err(p.c.err("no DATASET line"));
    }
    Ok(out)
}

fn point_arrays_of(parsed: &Parsed<'_>) -> PointArrays {
    PointArrays {
        arrays: parsed
            .arrays
            .iter()
            .map(|a| (a.name.clone(), a.components))
            .collect(),
        // VTK's legacy reader makes the first SCALARS the active scalars.
        active: parsed
            .arrays
            .iter()
            .find(|a| a.keyword == "SCALARS")
            .map(|a| a.name.clone()),
    }
}

/// The point arrays of a legacy image file's bytes.
pub fn point_arrays(path: &Path, data: &[u8]) -> Result<PointArrays, FormatError> {
    Ok(point_arrays_of(&walk(path, data).map_err(from_mesh_error)?))
}

/// Parses legacy `.vtk` image bytes (`path` only names the file in errors) and reads the
/// point array `field`, or the default one.
pub fn parse(
    path: &Path,
    data: &[u8],
    field: Option<&str>,
) -> Result<RectilinearVolume, FormatError> {
    let parsed = walk(path, data).map_err(from_mesh_error)?;
    let line = |pos: usize| crate::mesh::text::newlines(&data[..pos.min(data.len())]) + 1;
    let Some((dims, dims_at)) = parsed.dims else {
        return Err(FormatError::MissingField {
            path: path.to_path_buf(),
            field: "DIMENSIONS",
            reason: format!("DATASET {}", parsed.dataset),
        });
    };
    let count = checked_dims(path, dims, ("DIMENSIONS", line(dims_at)))?;
    let grid = if parsed.dataset == "RECTILINEAR_GRID" {
        rectilinear_grid(path, dims, &parsed.coords)?
    } else {
        image_grid(
            path,
            dims,
            [0; 3],
            parsed.origin,
            parsed.spacing.0,
            None,
            ("SPACING", line(parsed.spacing.1)),
        )?
    };
    let arrays = point_arrays_of(&parsed);
    if parsed.arrays.is_empty() {
        return Err(FormatError::MissingField {
            path: path.to_path_buf(),
            field: "POINT_DATA",
            reason: "no point arrays to draw".into(),
        });
    }
    let index = arrays.choose(path, field)?;
    let array = parsed
        .arrays
        .into_iter()
        .nth(index)
        .expect("chosen among the arrays");
    let vt = voxel_type(path, &array.name, array.ty, array.ty.xml_name())?;
    debug_assert_eq!(array.components, 1);
    let voxels = match array.values {
        Values::Binary(bytes) => {
            debug_assert_eq!(bytes.len(), count * array.ty.size());
            voxels_from_binary(bytes.to_vec(), vt, true)
        }
        Values::Ascii(values) => voxels_from_f64(path, &array.name, &values, vt)?,
    };
    RectilinearVolume::new(grid, voxels).map_err(|e| FormatError::geometry(path, e))
}

fn rectilinear_grid(
    path: &Path,
    dims: [usize; 3],
    coords: &[Option<Vec<f64>>; 3],
) -> Result<Grid, FormatError> {
    const NAMES: [&str; 3] = ["X_COORDINATES", "Y_COORDINATES", "Z_COORDINATES"];
    let mut axes = Vec::with_capacity(3);
    for a in 0..3 {
        let c = coords[a]
            .as_ref()
            .ok_or_else(|| FormatError::MissingField {
                path: path.to_path_buf(),
                field: NAMES[a],
                reason: "DATASET RECTILINEAR_GRID".into(),
            })?;
        if c.len() != dims[a] {
            return Err(FormatError::Contradiction {
                path: path.to_path_buf(),
                field: NAMES[a].into(),
                other: "DIMENSIONS".into(),
                reason: format!("{} coordinates for {} samples", c.len(), dims[a]),
            });
        }
        axes.push(AxisCoords::Explicit(Arc::from(c.as_slice())));
    }
    let axes: [AxisCoords; 3] = axes.try_into().expect("three axes");
    Grid::new(dims, axes, None).map_err(|e| FormatError::geometry(path, e))
}
