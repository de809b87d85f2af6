//! VTK XML image data, `.vti` (VTK file formats document, "XML File Formats", ImageData).
//!
//! One `<Piece>` whose `Extent` is the `WholeExtent` (what `vtkXMLImageDataWriter` writes;
//! a piece of a larger extent is refused, as its data would not fill the grid). Point
//! arrays are decoded by the shared XML machinery; see the parent module for the array
//! choice and the geometry.

use std::path::Path;

use volume_core::RectilinearVolume;

use super::{
    PointArrays, checked_dims, from_mesh_error, image_grid, voxel_type, voxels_from_binary,
    voxels_from_f64,
};
use crate::error::FormatError;
use crate::mesh::MeshError;
use crate::mesh::vtk_xml::{
    ArraySpec, Document, Element, Format, Section, line_of, parse_document,
};

fn document<'a>(path: &'a Path, data: &'a [u8]) -> Result<Document<'a>, FormatError> {
    parse_document(path, data, |ty| {
        if ty == "ImageData" {
            Ok(())
        } else {
            Err(MeshError::Unsupported {
                path: path.to_path_buf(),
                what: format!(
                    "VTKFile type {ty:?} in a .vti file (ImageData is read as a volume; \
                     UnstructuredGrid from .vtu as a tet mesh)"
                ),
            })
        }
    })
    .map_err(from_mesh_error)
}

fn point_arrays_of(doc: &Document<'_>) -> PointArrays {
    let arrays = doc
        .arrays
        .iter()
        .filter(|a| a.section == Section::PointData)
        .map(|a| (a.name.clone(), a.components))
        .collect();
    let active = doc
        .elements_named(b"PointData")
        .next()
        .and_then(|e| e.get(b"Scalars"))
        .map(str::to_owned);
    PointArrays { arrays, active }
}

/// The point arrays of `.vti` bytes.
pub fn point_arrays(path: &Path, data: &[u8]) -> Result<PointArrays, FormatError> {
    Ok(point_arrays_of(&document(path, data)?))
}

/// `count` numbers of the attribute `key` of `e`, or `default` when it is absent.
fn numbers<const N: usize>(
    path: &Path,
    data: &[u8],
    e: &Element,
    key: &str,
    default: Option<[f64; N]>,
) -> Result<[f64; N], FormatError> {
    let bad = |reason: String| FormatError::BadValue {
        path: path.to_path_buf(),
        line: line_of(data, e.pos),
        field: key.into(),
        reason,
    };
    let Some(text) = e.get(key.as_bytes()) else {
        return default.ok_or_else(|| bad(format!("<{}> has no {key}", name(e))));
    };
    let values: Vec<f64> = text
        .split_ascii_whitespace()
        .map(|w| {
            w.parse::<f64>()
                .map_err(|_| bad(format!("{w:?} is not a number")))
        })
        .collect::<Result<_, _>>()?;
    <[f64; N]>::try_from(values.as_slice())
        .map_err(|_| bad(format!("{} numbers, expected {N}", values.len())))
}

fn name(e: &Element) -> String {
    String::from_utf8_lossy(&e.name).into_owned()
}

/// An extent `x0 x1 y0 y1 z0 z1` of integers with `x0 <= x1` etc.
fn extent(path: &Path, data: &[u8], e: &Element, key: &str) -> Result<[i64; 6], FormatError> {
    let v = numbers::<6>(path, data, e, key, None)?;
    let bad = |reason: String| FormatError::BadValue {
        path: path.to_path_buf(),
        line: line_of(data, e.pos),
        field: key.into(),
        reason,
    };
    let mut out = [0i64; 6];
    for (o, x) in out.iter_mut().zip(v) {
        if x.fract() != 0.0 || x.abs() > 1e15 {
            return Err(bad(format!("{x} is not an index")));
        }
        *o = x as i64;
    }
    for a in 0..3 {
        if out[2 * a + 1] < out[2 * a] {
            return Err(bad(format!(
                "axis {a}: end {} before start {}",
                out[2 * a + 1],
                out[2 * a]
            )));
        }
    }
    Ok(out)
}

/// Parses `.vti` bytes (`path` only names the file in errors) and reads the point array
/// `field`, or the default one.
pub fn parse(
    path: &Path,
    data: &[u8],
    field: Option<&str>,
) -> Result<RectilinearVolume, FormatError> {
    let doc = document(path, data)?;
    let image =
        doc.elements_named(b"ImageData")
            .next()
            .ok_or_else(|| FormatError::MissingField {
                path: path.to_path_buf(),
                field: "ImageData",
                reason: "no <ImageData> element".into(),
            })?;
    let whole = extent(path, data, image, "WholeExtent")?;
    let origin = numbers::<3>(path, data, image, "Origin", Some([0.0; 3]))?;
    let spacing = numbers::<3>(path, data, image, "Spacing", Some([1.0; 3]))?;
    let direction = match image.get(b"Direction") {
        Some(_) => Some(numbers::<9>(path, data, image, "Direction", None)?),
        None => None,
    };
    let mut pieces = doc.elements_named(b"Piece");
    let piece = pieces.next().ok_or_else(|| FormatError::MissingField {
        path: path.to_path_buf(),
        field: "Piece",
        reason: "no <Piece> element".into(),
    })?;
    if let Some(second) = pieces.next() {
        return Err(FormatError::Unsupported {
            path: path.to_path_buf(),
            field: "Piece".into(),
            reason: format!(
                "a second <Piece> at line {}: only files of one piece are read",
                line_of(data, second.pos)
            ),
        });
    }
    let piece_extent = extent(path, data, piece, "Extent")?;
    if piece_extent != whole {
        return Err(FormatError::Contradiction {
            path: path.to_path_buf(),
            field: "Extent".into(),
            other: "WholeExtent".into(),
            reason: format!(
                "the piece covers {piece_extent:?} of {whole:?}: only a piece of the whole \
                 extent is read"
            ),
        });
    }
    let dims = [0, 1, 2].map(|a| (whole[2 * a + 1] - whole[2 * a] + 1) as usize);
    let count = checked_dims(path, dims, ("WholeExtent", line_of(data, image.pos)))?;
    let grid = image_grid(
        path,
        dims,
        [whole[0], whole[2], whole[4]],
        origin,
        spacing,
        // `Direction` is written row by row; column `a` is grid axis `a`.
        direction.map(|d| [0, 1, 2].map(|a| [d[a], d[3 + a], d[6 + a]])),
        ("Spacing", line_of(data, image.pos)),
    )?;
    let arrays = point_arrays_of(&doc);
    let index = arrays.choose(path, field)?;
    let spec: &ArraySpec<'_> = doc
        .arrays
        .iter()
        .filter(|a| a.section == Section::PointData)
        .nth(index)
        .expect("chosen among the point arrays");
    let ctx = &doc.ctx;
    let ty = ctx.scalar(spec).map_err(from_mesh_error)?;
    let vt = voxel_type(path, &spec.name, ty, &spec.type_name)?;
    let voxels = if spec.format == Format::Ascii {
        let values = ctx
            .ascii(spec, count, |t| t.parse::<f64>().ok())
            .map_err(from_mesh_error)?;
        voxels_from_f64(path, &spec.name, &values, vt)?
    } else {
        let bytes = ctx.bytes(spec, count, ty).map_err(from_mesh_error)?;
        voxels_from_binary(bytes, vt, ctx.big_endian)
    };
    RectilinearVolume::new(grid, voxels).map_err(|e| FormatError::geometry(path, e))
}
