//! Tetrahedral (unstructured) mesh readers and writers (thesis seed 004 ch. 8).
//!
//! Tour:
//! - [`read_mesh`] opens a mesh by extension and returns a [`LoadedMesh`]: a
//!   [`volume_core::tet::TetMesh`] (points, tets, named point scalars) plus what was skipped.
//! - Readers, each parsing into the format-neutral [`RawMesh`] first:
//!   [`vtk_legacy`] (`.vtk` UNSTRUCTURED_GRID 4.x and 5.1, ASCII and big-endian binary),
//!   [`vtu`] (VTK XML: ascii, inline base64 with or without zlib or LZ4, appended raw or
//!   base64, UInt32/UInt64 headers; the XML walk and array decoding are shared with the `.vti`
//!   image reader), [`gmsh`] (`.msh` 2.2 and 4.1, ASCII and binary, `$NodeData` as
//!   fields), [`tetgen`] (`.node` + `.ele`, node attributes as fields).
//! - [`RawMesh::into_tet_mesh`] validates every cell's connectivity (an out-of-range index is
//!   an error naming the cell), splits hexahedra, wedges and pyramids with the crack-free
//!   splits of [`volume_core::tet`], and counts skipped cells (vertices, lines, triangles,
//!   quads, polyhedra, higher-order cells) in [`Skipped`].
//! - [`pvd`]: time series, from a ParaView `.pvd` collection or numbered files, loaded
//!   lazily, with a shared-topology check per step.
//! - Writers: [`write_vtu`] (appended raw, VTK's default layout) and [`write_vtk_legacy`]
//!   (4.2, ASCII or binary) so generated meshes can be saved.
//!
//! Point arrays with one component become fields (converted to `f32`); arrays with several
//! components (vectors, tensors) are listed in [`LoadedMesh::skipped_arrays`], not fields.
//!
//! ## Why not the `vtkio` crate
//! Evaluated on the files in `formats/tests/data/mesh/` (written by VTK 9.7 itself):
//! `vtkio` 0.6.3 fails on legacy 5.1 (`Parse(Alt)`), on every zlib-compressed inline `.vtu`
//! (base64 of separately padded header and data) and on appended raw zlib data; 0.7.0-rc2 (a
//! pre-release) reads those but rejects appended raw data (`unknown variant raw`), which is
//! what VTK and ParaView write by default. It reads neither Gmsh nor TetGen files. The readers
//! here are small, bounded (every count is checked against the bytes left before anything is
//! allocated) and tested against VTK's, Gmsh's and TetGen's own output.
//!
//! ## Bad input
//! Headers lie: every count is checked against the remaining file size before a buffer is
//! allocated; every error names the file and the line, byte offset or cell index. No input
//! panics (see `formats/tests/mesh_malformed.rs` and the `mesh_vtk` fuzz target).

pub mod gmsh;
pub mod pvd;
pub mod tetgen;
pub(crate) mod text;
pub mod vtk_legacy;
pub(crate) mod vtk_xml;
pub mod vtu;

use std::path::{Path, PathBuf};

use thiserror::Error;
use volume_core::tet::{PointField, TetError, TetMesh, split_hex, split_pyramid, split_wedge};

pub use pvd::{MeshSeries, MeshStep, StepData, parse_pvd, read_pvd};
pub use vtk_legacy::{LegacyEncoding, write_vtk_legacy};
pub use vtu::write_vtu;

/// Why a mesh file could not be read or written.
#[derive(Debug, Error)]
pub enum MeshError {
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// Malformed text or structure at a place in the file.
    #[error("{}: line {line} (byte {offset}): {reason}", path.display())]
    Parse {
        path: PathBuf,
        line: usize,
        offset: u64,
        reason: String,
    },
    /// A header promises more data than the file holds (checked before allocating).
    #[error("{}: {what} needs {needed} bytes from byte {offset}, but only {available} are left", path.display())]
    TooShort {
        path: PathBuf,
        what: String,
        offset: u64,
        needed: u64,
        available: u64,
    },
    /// A cell with an out-of-range point index or the wrong number of points.
    #[error("{}: cell {cell}: {reason}", path.display())]
    BadCell {
        path: PathBuf,
        cell: usize,
        reason: String,
    },
    /// A point array whose length does not match the point count, or that does not decode.
    #[error("{}: array \"{name}\": {reason}", path.display())]
    BadArray {
        path: PathBuf,
        name: String,
        reason: String,
    },
    /// Valid in the format but not read here (other dataset types, LZMA compression, ...).
    #[error("{}: unsupported: {what}", path.display())]
    Unsupported { path: PathBuf, what: String },
    /// The parsed mesh is inconsistent (e.g. non-finite coordinates, no tetrahedra).
    #[error("{}: {source}", path.display())]
    Mesh {
        path: PathBuf,
        #[source]
        source: TetError,
    },
    /// A time series step whose topology differs from the first step's.
    #[error("{}: step {step}: {reason}", path.display())]
    Topology {
        path: PathBuf,
        step: usize,
        reason: String,
    },
    /// The extension is not a mesh format read here.
    #[error("{}: {reason}", path.display())]
    UnknownFormat { path: PathBuf, reason: String },
    /// `.pvd` collections that lead back to one already being read (`chain` is the path of
    /// references, ending at the repeated file), or nest deeper than [`MAX_PVD_DEPTH`].
    #[error("{}: {reason}: {}", path.display(), show_chain(chain))]
    Cycle {
        path: PathBuf,
        chain: Vec<PathBuf>,
        reason: String,
    },
    /// A mesh output that could not be created or completed ([`crate::output`]).
    #[error(transparent)]
    Output(#[from] crate::FormatError),
}

fn show_chain(chain: &[PathBuf]) -> String {
    chain
        .iter()
        .map(|p| p.display().to_string())
        .collect::<Vec<_>>()
        .join(" -> ")
}

/// How deep `.pvd` collections may refer to collections (each level is one stack frame of the
/// reader; real files have at most one level).
pub const MAX_PVD_DEPTH: usize = 16;

impl MeshError {
    /// The file the error is about.
    pub fn path(&self) -> &Path {
        match self {
            MeshError::Io { path, .. }
            | MeshError::Parse { path, .. }
            | MeshError::TooShort { path, .. }
            | MeshError::BadCell { path, .. }
            | MeshError::BadArray { path, .. }
            | MeshError::Unsupported { path, .. }
            | MeshError::Mesh { path, .. }
            | MeshError::Topology { path, .. }
            | MeshError::UnknownFormat { path, .. }
            | MeshError::Cycle { path, .. } => path,
            MeshError::Output(e) => e.path(),
        }
    }

    pub(crate) fn io(path: &Path, source: std::io::Error) -> Self {
        MeshError::Io {
            path: path.to_path_buf(),
            source,
        }
    }
}

/// Cell kinds, numbered as VTK's cell types (the readers of other formats map to these).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum CellKind {
    Tetra,
    Hexahedron,
    /// VTK_VOXEL: a hexahedron in pixel (lexicographic) vertex order.
    Voxel,
    Wedge,
    Pyramid,
    /// Anything else (vertex, line, triangle, quad, polyhedron, higher order), with its
    /// VTK type code (or the Gmsh element type + 1000 for Gmsh-only types).
    Other(u32),
}

impl CellKind {
    /// From a VTK cell type code.
    pub fn from_vtk(code: u32) -> Self {
        match code {
            10 => CellKind::Tetra,
            11 => CellKind::Voxel,
            12 => CellKind::Hexahedron,
            13 => CellKind::Wedge,
            14 => CellKind::Pyramid,
            c => CellKind::Other(c),
        }
    }

    /// The VTK type code.
    pub fn vtk_code(self) -> u32 {
        match self {
            CellKind::Tetra => 10,
            CellKind::Voxel => 11,
            CellKind::Hexahedron => 12,
            CellKind::Wedge => 13,
            CellKind::Pyramid => 14,
            CellKind::Other(c) => c,
        }
    }

    /// Points a volume cell of this kind must have (`None` for skipped kinds).
    fn volume_points(self) -> Option<usize> {
        match self {
            CellKind::Tetra => Some(4),
            CellKind::Hexahedron | CellKind::Voxel => Some(8),
            CellKind::Wedge => Some(6),
            CellKind::Pyramid => Some(5),
            CellKind::Other(_) => None,
        }
    }
}

/// A point array as read: `components` values per point, row-major.
#[derive(Debug, Clone, PartialEq)]
pub struct RawArray {
    pub name: String,
    pub components: usize,
    pub values: Vec<f64>,
}

/// The format-neutral result of a parser, before validation and splitting.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RawMesh {
    pub points: Vec<[f64; 3]>,
    /// One kind per cell.
    pub kinds: Vec<CellKind>,
    /// Cell `i` uses `connectivity[offsets[i]..offsets[i + 1]]`; `offsets.len() == kinds.len() + 1`.
    pub offsets: Vec<usize>,
    /// Zero-based point indices (as read, before the range check).
    pub connectivity: Vec<u64>,
    pub arrays: Vec<RawArray>,
}

impl RawMesh {
    /// An empty mesh with `offsets == [0]`.
    pub fn new() -> Self {
        Self {
            offsets: vec![0],
            ..Self::default()
        }
    }

    /// Appends a cell.
    pub fn push_cell(&mut self, kind: CellKind, points: &[u64]) {
        self.kinds.push(kind);
        self.connectivity.extend_from_slice(points);
        self.offsets.push(self.connectivity.len());
    }

    pub fn num_cells(&self) -> usize {
        self.kinds.len()
    }

    /// The point indices of cell `i`.
    pub fn cell(&self, i: usize) -> &[u64] {
        &self.connectivity[self.offsets[i]..self.offsets[i + 1]]
    }

    /// Validates and converts to a [`TetMesh`]: checks each cell's point count and indices
    /// (errors name the cell), splits hexahedra/voxels/wedges/pyramids crack-free, skips and
    /// counts other cells, turns one-component arrays into `f32` fields.
    pub fn into_tet_mesh(self, path: &Path) -> Result<LoadedMesh, MeshError> {
        let n_points = self.points.len();
        if n_points > u32::MAX as usize {
            return Err(MeshError::Unsupported {
                path: path.to_path_buf(),
                what: format!("{n_points} points (at most {} supported)", u32::MAX),
            });
        }
        if self.offsets.len() != self.kinds.len() + 1 {
            return Err(MeshError::Parse {
                path: path.to_path_buf(),
                line: 0,
                offset: 0,
                reason: format!(
                    "{} cell offsets for {} cells",
                    self.offsets.len().saturating_sub(1),
                    self.kinds.len()
                ),
            });
        }
        let mut tets: Vec<[u32; 4]> = Vec::with_capacity(self.kinds.len());
        let mut skipped = Skipped::default();
        for (cell, &kind) in self.kinds.iter().enumerate() {
            let (lo, hi) = (self.offsets[cell], self.offsets[cell + 1]);
            if lo > hi || hi > self.connectivity.len() {
                return Err(MeshError::BadCell {
                    path: path.to_path_buf(),
                    cell,
                    reason: format!(
                        "offsets {lo}..{hi} outside the connectivity (length {})",
                        self.connectivity.len()
                    ),
                });
            }
            let ids = &self.connectivity[lo..hi];
            let Some(need) = kind.volume_points() else {
                skipped.add(kind);
                continue;
            };
            if ids.len() != need {
                return Err(MeshError::BadCell {
                    path: path.to_path_buf(),
                    cell,
                    reason: format!(
                        "{kind:?} (type {}) needs {need} points, has {}",
                        kind.vtk_code(),
                        ids.len()
                    ),
                });
            }
            let mut v = [0u32; 8];
            for (slot, &id) in v.iter_mut().zip(ids) {
                if id >= n_points as u64 {
                    return Err(MeshError::BadCell {
                        path: path.to_path_buf(),
                        cell,
                        reason: format!(
                            "point index {id} is out of range (the mesh has {n_points} points)"
                        ),
                    });
                }
                *slot = id as u32;
            }
            match kind {
                CellKind::Tetra => tets.push([v[0], v[1], v[2], v[3]]),
                CellKind::Hexahedron => tets.extend(split_hex(v)),
                // Voxel order is lexicographic: swap to the hexahedron's cyclic quads.
                CellKind::Voxel => {
                    tets.extend(split_hex([v[0], v[1], v[3], v[2], v[4], v[5], v[7], v[6]]));
                }
                CellKind::Wedge => tets.extend(split_wedge([v[0], v[1], v[2], v[3], v[4], v[5]])),
                CellKind::Pyramid => tets.extend(split_pyramid([v[0], v[1], v[2], v[3], v[4]])),
                CellKind::Other(_) => unreachable!("skipped above"),
            }
        }
        let mut fields = Vec::new();
        let mut skipped_arrays = Vec::new();
        for a in self.arrays {
            if a.components != 1 {
                skipped_arrays.push((a.name, format!("{} components", a.components)));
                continue;
            }
            if a.values.len() != n_points {
                return Err(MeshError::BadArray {
                    path: path.to_path_buf(),
                    name: a.name,
                    reason: format!("{} values for {n_points} points", a.values.len()),
                });
            }
            if fields.iter().any(|f: &PointField| f.name == a.name) {
                skipped_arrays.push((a.name, "name occurs twice (first kept)".to_owned()));
                continue;
            }
            let values = a.values.iter().map(|&x| x as f32).collect();
            fields.push(PointField::new(a.name, values));
        }
        if tets.is_empty() {
            return Err(MeshError::Mesh {
                path: path.to_path_buf(),
                source: TetError::Empty,
            });
        }
        // Finite but huge coordinates would open and then fail as a non-finite camera (the
        // renderer squares lengths in f32): refuse them here, naming the point.
        let limit = volume_core::volume::MAX_WORLD_COORD;
        if let Some((i, p)) = self
            .points
            .iter()
            .enumerate()
            .find(|(_, p)| p.iter().any(|c| c.is_finite() && c.abs() > limit))
        {
            return Err(MeshError::BadArray {
                path: path.to_path_buf(),
                name: "points".to_owned(),
                reason: format!(
                    "point {i} at {p:?} lies beyond the ±{limit:e} that single-precision \
                     rendering supports"
                ),
            });
        }
        let points = volume_core::tet::points_from_f64(&self.points);
        let mesh = TetMesh::new(points, tets, fields).map_err(|source| MeshError::Mesh {
            path: path.to_path_buf(),
            source,
        })?;
        Ok(LoadedMesh {
            mesh,
            source_cells: self.kinds.len(),
            skipped,
            skipped_arrays,
        })
    }
}

/// Counts of cells that are not volumes and were left out, by VTK type code.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Skipped {
    /// `(vtk type code, count)`, in order of first occurrence.
    pub by_type: Vec<(u32, usize)>,
}

impl Skipped {
    fn add(&mut self, kind: CellKind) {
        let code = kind.vtk_code();
        if let Some(e) = self.by_type.iter_mut().find(|e| e.0 == code) {
            e.1 += 1;
        } else {
            self.by_type.push((code, 1));
        }
    }

    /// Total number of skipped cells.
    pub fn total(&self) -> usize {
        self.by_type.iter().map(|e| e.1).sum()
    }

    /// Count of skipped cells of one VTK type code.
    pub fn count(&self, vtk_code: u32) -> usize {
        self.by_type
            .iter()
            .find(|e| e.0 == vtk_code)
            .map_or(0, |e| e.1)
    }
}

/// A mesh read from a file, with what was left out of it.
#[derive(Debug, Clone, PartialEq)]
pub struct LoadedMesh {
    pub mesh: TetMesh,
    /// Cells in the file (before splitting and skipping).
    pub source_cells: usize,
    /// Non-volume cells that were skipped (a warning for the user).
    pub skipped: Skipped,
    /// Point arrays that are not scalar fields: `(name, why)`.
    pub skipped_arrays: Vec<(String, String)>,
}

impl LoadedMesh {
    /// Names of the scalar point fields, in file order (`isoscope info` lists these).
    pub fn array_names(&self) -> Vec<&str> {
        self.mesh.field_names()
    }

    /// One-line warning about skipped cells, if any (e.g. `skipped 3 cells: 1 of type 5, ...`).
    pub fn skipped_warning(&self) -> Option<String> {
        if self.skipped.total() == 0 {
            return None;
        }
        let parts: Vec<String> = self
            .skipped
            .by_type
            .iter()
            .map(|(code, n)| format!("{n} of VTK type {code} ({})", vtk_type_name(*code)))
            .collect();
        Some(format!(
            "skipped {} non-volume cells: {}",
            self.skipped.total(),
            parts.join(", ")
        ))
    }
}

/// Human name of a VTK cell type code (for warnings).
pub fn vtk_type_name(code: u32) -> &'static str {
    match code {
        1 => "vertex",
        2 => "poly-vertex",
        3 => "line",
        4 => "poly-line",
        5 => "triangle",
        6 => "triangle strip",
        7 => "polygon",
        8 => "pixel",
        9 => "quad",
        10 => "tetra",
        11 => "voxel",
        12 => "hexahedron",
        13 => "wedge",
        14 => "pyramid",
        21..=34 => "quadratic cell",
        42 => "polyhedron",
        68..=83 => "higher-order cell",
        _ => "other",
    }
}

/// The mesh formats read here.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MeshFormat {
    VtkLegacy,
    Vtu,
    Gmsh,
    TetGen,
    Pvd,
}

impl MeshFormat {
    /// By file extension (`.vtk`, `.vtu`, `.msh`, `.node`/`.ele`, `.pvd`), case-insensitive.
    pub fn from_path(path: &Path) -> Option<Self> {
        let ext = path.extension()?.to_str()?.to_ascii_lowercase();
        match ext.as_str() {
            "vtk" => Some(MeshFormat::VtkLegacy),
            "vtu" => Some(MeshFormat::Vtu),
            "msh" => Some(MeshFormat::Gmsh),
            "node" | "ele" => Some(MeshFormat::TetGen),
            "pvd" => Some(MeshFormat::Pvd),
            _ => None,
        }
    }
}

/// Whether `path` is a mesh (for dispatch between volume and mesh readers): a mesh
/// extension, except a legacy `.vtk` whose `DATASET` is an image (structured points or a
/// rectilinear grid: a grid, read by [`crate::vtk_image`]). For a series pattern that names
/// no file, its first match decides.
pub fn is_mesh_path(path: &Path) -> bool {
    match MeshFormat::from_path(path) {
        Some(MeshFormat::VtkLegacy) => {
            let first = if !path.exists() && crate::series::is_pattern(path) {
                crate::series::expand_pattern(path)
                    .ok()
                    .and_then(|f| f.into_iter().next())
            } else {
                Some(path.to_path_buf())
            };
            !first.is_some_and(|f| crate::vtk_image::is_legacy_image(&f))
        }
        Some(_) => true,
        None => false,
    }
}

/// Reads a mesh file of any supported format (by extension). A `.pvd` loads its first step;
/// use [`read_pvd`] for the whole series.
pub fn read_mesh(path: &Path) -> Result<LoadedMesh, MeshError> {
    read_raw(path)?.into_tet_mesh(path)
}

/// Parses a mesh file into the format-neutral [`RawMesh`] (no validation or splitting yet).
pub fn read_raw(path: &Path) -> Result<RawMesh, MeshError> {
    read_raw_within(path, &mut Vec::new())
}

/// The identity of a file for cycle detection: its canonical path (symbolic links and `..`
/// resolved), or the path as given when it cannot be resolved (then opening fails anyway).
fn file_key(path: &Path) -> PathBuf {
    std::fs::canonicalize(path).unwrap_or_else(|_| path.to_path_buf())
}

/// [`read_raw`] inside the `.pvd` collections of `chain` (outermost first, canonical paths):
/// a `.pvd` already in the chain is a cycle, reported with the whole chain instead of
/// recursing until the stack overflows.
pub(crate) fn read_raw_within(path: &Path, chain: &mut Vec<PathBuf>) -> Result<RawMesh, MeshError> {
    match MeshFormat::from_path(path) {
        Some(MeshFormat::VtkLegacy) => vtk_legacy::read_raw(path),
        Some(MeshFormat::Vtu) => vtu::read_raw(path),
        Some(MeshFormat::Gmsh) => gmsh::read_raw(path),
        Some(MeshFormat::TetGen) => tetgen::read_raw(path),
        Some(MeshFormat::Pvd) => {
            let key = file_key(path);
            if chain.contains(&key) || chain.len() >= MAX_PVD_DEPTH {
                let cycle = chain.contains(&key);
                let mut shown = chain.clone();
                shown.push(key);
                return Err(MeshError::Cycle {
                    path: path.to_path_buf(),
                    chain: shown,
                    reason: if cycle {
                        "the .pvd collections refer to each other in a cycle".to_owned()
                    } else {
                        format!(".pvd collections nest deeper than {MAX_PVD_DEPTH} levels")
                    },
                });
            }
            let series = read_pvd(path)?;
            let first = series.steps.first().ok_or_else(|| MeshError::Parse {
                path: path.to_path_buf(),
                line: 1,
                offset: 0,
                reason: "the collection lists no data sets".to_owned(),
            })?;
            chain.push(key);
            let raw = read_raw_within(&first.path, chain);
            chain.pop();
            raw
        }
        None => Err(MeshError::UnknownFormat {
            path: path.to_path_buf(),
            reason: "not a mesh extension (.vtk, .vtu, .msh, .node, .ele, .pvd)".to_owned(),
        }),
    }
}

/// Reads a whole file, as the parsers work on bytes in memory (regular files only: see
/// [`crate::input`]).
pub(crate) fn read_file(path: &Path) -> Result<Vec<u8>, MeshError> {
    crate::input::read_regular(path).map_err(|e| MeshError::io(path, e))
}
