//! # VTK image data: `.vti` and legacy `.vtk` structured points and rectilinear grids
//!
//! - [`vti`]: VTK XML `ImageData` (`WholeExtent`, `Origin`, `Spacing`, VTK 9's `Direction`,
//!   `PointData` arrays in every encoding VTK writes: ascii, inline base64, appended raw or
//!   base64; no compression, zlib or LZ4; UInt32 or UInt64 block headers; either byte order).
//!   The XML walk and the array decoding are the `.vtu` reader's (`mesh::vtk_xml`).
//! - [`legacy`]: legacy `.vtk` `DATASET STRUCTURED_POINTS` (`DIMENSIONS`, `ORIGIN`,
//!   `SPACING`) and `DATASET RECTILINEAR_GRID` (`X/Y/Z_COORDINATES`, explicit axes), ASCII or
//!   big-endian BINARY, through the legacy mesh reader's tokenizer (`mesh::vtk_legacy`).
//!
//! A `.vtk` file is an image or a mesh by its `DATASET` line, not its name:
//! [`legacy_dataset`] reads the header, and [`crate::mesh::is_mesh_path`] uses it so that
//! an unstructured grid opens as a tet mesh and structured points as a grid.
//!
//! ## Which array
//! An image may carry several point arrays. The one read is the one asked for
//! ([`crate::OpenOptions::field`], the CLI's `--field`), else the active scalars (`<PointData
//! Scalars="...">`; in a legacy file the first `SCALARS`), else the first one-component
//! array. Arrays of several components (vectors) are not scalar fields; 64-bit integer
//! arrays have no voxel type here (as in NRRD): both are refused by name. [`point_arrays`]
//! lists a file's arrays (for `info` and the viewer's array menu).
//!
//! ## Geometry
//! Voxel `(i, j, k)` of an extent starting at `(x0, y0, z0)` lies at `Origin + Direction ·
//! ((x0 + i)·sx, (y0 + j)·sy, (z0 + k)·sz)`; `Direction` is written row by row. A negative
//! spacing flips its direction column. VTK has no patient frame: the world frame is unknown.
//! Cell data is not read (a grid's values are its samples).

pub mod legacy;
pub mod vti;

pub(crate) use crate::oriented::{checked_dims, image_grid};

use std::io::Read as _;
use std::path::Path;

use volume_core::{RectilinearVolume, VoxelData, VoxelType};

use crate::error::FormatError;
use crate::mesh::MeshError;
use crate::mesh::text::Scalar;
use crate::raw::Endian;

/// The point arrays of an image file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PointArrays {
    /// `(name, components)` in file order.
    pub arrays: Vec<(String, usize)>,
    /// The active scalars, if the file names them.
    pub active: Option<String>,
}

impl PointArrays {
    /// Names of the arrays that can be drawn (one component), in file order.
    pub fn scalar_names(&self) -> Vec<String> {
        self.arrays
            .iter()
            .filter(|(_, c)| *c == 1)
            .map(|(n, _)| n.clone())
            .collect()
    }

    /// The array read when none is asked for: the active scalars if they have one
    /// component, else the first one-component array.
    pub fn default_name(&self) -> Option<&str> {
        self.active
            .as_deref()
            .filter(|a| self.arrays.iter().any(|(n, c)| n == a && *c == 1))
            .or_else(|| {
                self.arrays
                    .iter()
                    .find(|(_, c)| *c == 1)
                    .map(|(n, _)| n.as_str())
            })
    }

    /// The index of the array to read: `wanted` if given, else [`Self::default_name`].
    /// Errors name the array and list what the file has.
    pub(crate) fn choose(&self, path: &Path, wanted: Option<&str>) -> Result<usize, FormatError> {
        let listing = || {
            if self.arrays.is_empty() {
                "the file has no point arrays".to_owned()
            } else {
                let all: Vec<String> = self
                    .arrays
                    .iter()
                    .map(|(n, c)| {
                        if *c == 1 {
                            format!("\"{n}\"")
                        } else {
                            format!("\"{n}\" ({c} components)")
                        }
                    })
                    .collect();
                format!("the file has {}", all.join(", "))
            }
        };
        let name = match wanted {
            Some(w) => w,
            None => self.default_name().ok_or_else(|| FormatError::Array {
                path: path.to_path_buf(),
                name: String::new(),
                reason: format!(
                    "no scalar (one-component) point array to draw an isosurface of; {}",
                    listing()
                ),
            })?,
        };
        let index = self
            .arrays
            .iter()
            .position(|(n, _)| n == name)
            .ok_or_else(|| FormatError::Array {
                path: path.to_path_buf(),
                name: name.to_owned(),
                reason: format!("no point array of this name; {}", listing()),
            })?;
        let components = self.arrays[index].1;
        if components != 1 {
            return Err(FormatError::Array {
                path: path.to_path_buf(),
                name: name.to_owned(),
                reason: format!(
                    "{components} components per point: only scalar (one-component) arrays \
                     can be drawn"
                ),
            });
        }
        Ok(index)
    }
}

/// The `DATASET` of a legacy `.vtk` file (upper case, e.g. `STRUCTURED_POINTS`), read from
/// its first 4 KiB; `None` if the file cannot be read or has no such line there.
pub fn legacy_dataset(path: &Path) -> Option<String> {
    let file = crate::input::open_regular(path).ok()?;
    let mut head = Vec::new();
    file.take(4096).read_to_end(&mut head).ok()?;
    if !head.starts_with(b"# vtk DataFile") {
        return None;
    }
    // The DATASET line follows the version, title and ASCII/BINARY lines (comments and
    // blank lines are not allowed in between, but tolerate them).
    head.split(|&b| b == b'\n').skip(3).find_map(|line| {
        let text = std::str::from_utf8(line).ok()?;
        let mut words = text.split_ascii_whitespace();
        match words.next() {
            Some(w) if w.eq_ignore_ascii_case("DATASET") => {
                Some(words.next().unwrap_or("").to_ascii_uppercase())
            }
            _ => None,
        }
    })
}

/// The image datasets of legacy `.vtk` files.
pub const LEGACY_IMAGE_DATASETS: [&str; 2] = ["STRUCTURED_POINTS", "RECTILINEAR_GRID"];

/// True if `path` is a legacy `.vtk` whose `DATASET` is an image (structured points or a
/// rectilinear grid).
pub fn is_legacy_image(path: &Path) -> bool {
    legacy_dataset(path).is_some_and(|d| LEGACY_IMAGE_DATASETS.contains(&d.as_str()))
}

/// True for the files this module reads: `.vti`, or a `.vtk` whose `DATASET` is an image.
// `name` is lower-cased first.
#[allow(clippy::case_sensitive_file_extension_comparisons)]
pub fn is_image_file(path: &Path) -> bool {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default();
    name.ends_with(".vti") || (name.ends_with(".vtk") && is_legacy_image(path))
}

/// Reads a `.vti` or legacy image `.vtk` file (by name), the array `field` or the default
/// one (module docs).
// `name` is lower-cased first.
#[allow(clippy::case_sensitive_file_extension_comparisons)]
pub fn read(path: &Path, field: Option<&str>) -> Result<RectilinearVolume, FormatError> {
    let data = crate::input::read_regular(path).map_err(|e| FormatError::io(path, e))?;
    let name = path.to_string_lossy().to_ascii_lowercase();
    if name.ends_with(".vti") {
        vti::parse(path, &data, field)
    } else {
        legacy::parse(path, &data, field)
    }
}

/// The point arrays of a `.vti` or legacy image `.vtk` file (no voxels are decoded).
// `name` is lower-cased first.
#[allow(clippy::case_sensitive_file_extension_comparisons)]
pub fn point_arrays(path: &Path) -> Result<PointArrays, FormatError> {
    let data = crate::input::read_regular(path).map_err(|e| FormatError::io(path, e))?;
    let name = path.to_string_lossy().to_ascii_lowercase();
    if name.ends_with(".vti") {
        vti::point_arrays(path, &data)
    } else {
        legacy::point_arrays(path, &data)
    }
}

/// The reader's errors as [`FormatError`]s (the shared VTK tokenizer and XML decoding speak
/// [`MeshError`]).
pub(crate) fn from_mesh_error(e: MeshError) -> FormatError {
    match e {
        MeshError::Io { path, source } => FormatError::Io { path, source },
        MeshError::Parse {
            path,
            line,
            offset,
            reason,
        } => FormatError::BadLine {
            path,
            line,
            reason: format!("(byte {offset}) {reason}"),
        },
        MeshError::TooShort {
            path,
            what,
            offset,
            needed,
            available,
        } => FormatError::BadValue {
            path,
            line: 0,
            field: what,
            reason: format!(
                "needs {needed} bytes from byte {offset}, but only {available} are left"
            ),
        },
        MeshError::BadArray { path, name, reason } => FormatError::Array { path, name, reason },
        MeshError::Unsupported { path, what } => FormatError::Unsupported {
            path,
            field: "DATASET".into(),
            reason: what,
        },
        MeshError::Output(e) => e,
        other => FormatError::UnknownFormat {
            path: other.path().to_path_buf(),
            reason: other.to_string(),
        },
    }
}

/// The voxel type of a VTK scalar type; 64-bit integers have none.
pub(crate) fn voxel_type(
    path: &Path,
    name: &str,
    ty: Scalar,
    type_name: &str,
) -> Result<VoxelType, FormatError> {
    Ok(match ty {
        Scalar::I8 => VoxelType::I8,
        Scalar::U8 => VoxelType::U8,
        Scalar::I16 => VoxelType::I16,
        Scalar::U16 => VoxelType::U16,
        Scalar::I32 => VoxelType::I32,
        Scalar::U32 => VoxelType::U32,
        Scalar::F32 => VoxelType::F32,
        Scalar::F64 => VoxelType::F64,
        Scalar::I64 | Scalar::U64 => {
            return Err(FormatError::Array {
                path: path.to_path_buf(),
                name: name.to_owned(),
                reason: format!(
                    "type {type_name}: 64-bit integer voxels are not supported (8 to 32-bit \
                     integers, float and double are)"
                ),
            });
        }
    })
}

/// Voxels from numbers read as text, each checked to be a value of `ty`.
pub(crate) fn voxels_from_f64(
    path: &Path,
    name: &str,
    values: &[f64],
    ty: VoxelType,
) -> Result<VoxelData, FormatError> {
    fn conv<T: volume_core::Voxel>(
        values: &[f64],
        exact: impl Fn(f64) -> bool,
    ) -> Result<Vec<T>, usize> {
        values
            .iter()
            .enumerate()
            .map(|(i, &v)| if exact(v) { Ok(T::from_f64(v)) } else { Err(i) })
            .collect()
    }
    let int = |lo: f64, hi: f64| move |v: f64| v.fract() == 0.0 && (lo..=hi).contains(&v);
    let any = |_: f64| true;
    let r = match ty {
        VoxelType::U8 => conv::<u8>(values, int(0.0, 255.0)).map(VoxelData::from),
        VoxelType::I8 => conv::<i8>(values, int(-128.0, 127.0)).map(VoxelData::from),
        VoxelType::U16 => conv::<u16>(values, int(0.0, 65535.0)).map(VoxelData::from),
        VoxelType::I16 => conv::<i16>(values, int(-32768.0, 32767.0)).map(VoxelData::from),
        VoxelType::U32 => conv::<u32>(values, int(0.0, 4_294_967_295.0)).map(VoxelData::from),
        VoxelType::I32 => {
            conv::<i32>(values, int(-2_147_483_648.0, 2_147_483_647.0)).map(VoxelData::from)
        }
        VoxelType::F32 => Ok(VoxelData::from(
            values.iter().map(|&v| v as f32).collect::<Vec<f32>>(),
        )),
        VoxelType::F64 => conv::<f64>(values, any).map(VoxelData::from),
    };
    r.map_err(|i| FormatError::Array {
        path: path.to_path_buf(),
        name: name.to_owned(),
        reason: format!("value #{i} ({}) is not a {ty} value", values[i]),
    })
}

/// Voxels from binary bytes of `ty` in the given byte order.
pub(crate) fn voxels_from_binary(bytes: Vec<u8>, ty: VoxelType, big_endian: bool) -> VoxelData {
    let endian = if big_endian {
        Endian::Big
    } else {
        Endian::Little
    };
    crate::raw::voxels_from_vec(bytes, ty, endian)
}
