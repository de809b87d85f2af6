//! `isoscope.open()` and the data classes.
//!
//! Every data object holds one [`AnyScene`] (the loaded data and its acceleration
//! structure) behind a lock, shared with the `Scene`s made from it: a file is opened by
//! [`open_scene_with`] exactly as `isoscope render` opens it, an array by
//! [`GridData::from_volume`] or [`TetData::from_loaded`]. The Python class says what was
//! loaded: [`Volume`] (one rectilinear volume), [`Series`] (volumes or meshes over time),
//! [`Mesh`] (one tetrahedral mesh), [`OocVolume`] (an out-of-core `.isot` file); all derive
//! from [`Data`].

use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::sync::{Arc, RwLock, RwLockReadGuard, RwLockWriteGuard};

use anyhow::Context as _;
use isoscope::cli::open_args::{self, MeshArgs, OocArgs, OpenArgs};
use isoscope::scene::{AnyScene, GridData, OpenControl, SceneOptions, TetData, open_scene_with};
use numpy::{PyArrayMethods, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use volume_core::intersect::Intersector;
use volume_core::tet::{PointField, TetMesh};

use crate::IntoPyResult as _;
use crate::numpy_source::{Geometry, volume_from_array};
use crate::run::interruptible;

/// Where the data came from (what `info()` describes).
pub enum Source {
    /// A file opened with these flags (`info()` runs `isoscope info` on it).
    File(OpenArgs),
    /// A numpy volume; `in_place` when the voxels are the array's own memory.
    Array { in_place: bool },
    /// Numpy mesh arrays (copied into the BVH's layout).
    MeshArrays,
}

/// One loaded data set, shared by its Python object and the scenes made from it.
pub struct Loaded {
    /// The file, or a name such as `<numpy array>` (in messages and `info()["file"]`).
    pub path: PathBuf,
    pub source: Source,
    /// The normals the data was opened with (its kind's default or `open(normals=...)`):
    /// what a `Scene` made without `normals` draws.
    pub opened_normals: Option<volume_core::render::Normals>,
    scene: RwLock<AnyScene>,
}

impl Loaded {
    fn new(path: PathBuf, source: Source, scene: AnyScene) -> Arc<Self> {
        Arc::new(Self {
            path,
            source,
            opened_normals: scene.data().view_options().normals,
            scene: RwLock::new(scene),
        })
    }

    // A panic while holding the lock leaves a scene that is still whole (every update is a
    // refit or rebuild that replaces it at once), so a poisoned lock is used as is.
    pub fn read(&self) -> RwLockReadGuard<'_, AnyScene> {
        self.scene
            .read()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    pub fn write(&self) -> RwLockWriteGuard<'_, AnyScene> {
        self.scene
            .write()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    /// The `info --json` object of this data, as JSON text.
    fn info_json(&self) -> anyhow::Result<String> {
        let report = match &self.source {
            Source::File(open) => {
                serde_json::to_string(&isoscope::cli::info::gather_any(&self.path, open)?)?
            }
            Source::Array { .. } => {
                let scene = self.read();
                let AnyScene::Grid(g) = &*scene else {
                    anyhow::bail!("internal: an array volume is a grid");
                };
                let dataset = formats::Dataset::Volume(g.volume().clone());
                serde_json::to_string(&isoscope::cli::info::volume_report(&self.path, &dataset)?)?
            }
            Source::MeshArrays => {
                let scene = self.read();
                let AnyScene::Tet(t) = &*scene else {
                    anyhow::bail!("internal: mesh arrays are a tet mesh");
                };
                serde_json::to_string(&isoscope::cli::info::mesh_report(
                    &self.path,
                    t.loaded(),
                    None,
                )?)?
            }
        };
        Ok(report)
    }
}

/// Base class of the data objects: what every kind answers.
#[pyclass(subclass, frozen, module = "isoscope")]
pub struct Data {
    pub loaded: Arc<Loaded>,
}

#[pymethods]
impl Data {
    /// The `isoscope info --json` object as a dict (same fields and values as the CLI).
    fn info(&self, py: Python<'_>) -> PyResult<Py<PyAny>> {
        let loaded = Arc::clone(&self.loaded);
        let text =
            interruptible(py, &AtomicBool::new(false), move || loaded.info_json())?.py_err()?;
        Ok(py.import("json")?.call_method1("loads", (text,))?.unbind())
    }

    /// The file, or `<numpy array>` / `<numpy mesh>`.
    #[getter]
    fn path(&self) -> String {
        self.loaded.path.display().to_string()
    }

    /// `"grid"`, `"tet"` or `"isot"`.
    #[getter]
    fn kind(&self) -> &'static str {
        self.loaded.read().kind().name()
    }

    /// Smallest and largest finite value of the current step, or `None`.
    #[getter]
    fn value_range(&self) -> Option<(f64, f64)> {
        self.loaded.read().value_range()
    }

    /// World-space bounds `((x0, y0, z0), (x1, y1, z1))`.
    #[getter]
    fn bounds(&self) -> ([f32; 3], [f32; 3]) {
        let b = self.loaded.read().world_bounds();
        (b.min.to_array(), b.max.to_array())
    }

    /// Time steps (1 for a single data set).
    #[getter]
    fn step_count(&self) -> usize {
        self.loaded.read().step_count()
    }

    /// One line such as `grid 64x64x64 i16`.
    fn describe(&self) -> String {
        self.loaded.read().describe()
    }

    fn __repr__(&self) -> String {
        format!("<isoscope {}: {}>", self.path(), self.describe())
    }
}

/// A rectilinear volume.
#[pyclass(extends = Data, frozen, module = "isoscope")]
pub struct Volume {
    /// The numpy array whose memory the voxels are (zero-copy), if any.
    array: Option<Py<PyAny>>,
}

fn f64x3(v: Option<Vec<f64>>, default: f64, what: &str) -> PyResult<[f64; 3]> {
    match v {
        None => Ok([default; 3]),
        Some(v) => <[f64; 3]>::try_from(v.as_slice()).map_err(|_| {
            pyo3::exceptions::PyValueError::new_err(format!(
                "{what}: expected 3 numbers (x, y, z), got {}",
                v.len()
            ))
        }),
    }
}

/// A 3×4 or 4×4 affine from nested sequences or an array.
fn affine(m: &Bound<'_, PyAny>) -> PyResult<[[f64; 4]; 3]> {
    let rows: Vec<Vec<f64>> = m.extract().map_err(|_| {
        pyo3::exceptions::PyValueError::new_err(
            "world_from_grid: expected a 3x4 or 4x4 matrix of numbers",
        )
    })?;
    let ok = (rows.len() == 3 || rows.len() == 4) && rows.iter().all(|r| r.len() == 4);
    if !ok {
        return Err(pyo3::exceptions::PyValueError::new_err(
            "world_from_grid: expected a 3x4 or 4x4 matrix (rows [m0, m1, m2, t])",
        ));
    }
    if rows.len() == 4 && rows[3] != [0.0, 0.0, 0.0, 1.0] {
        return Err(pyo3::exceptions::PyValueError::new_err(
            "world_from_grid: the last row of a 4x4 affine must be [0, 0, 0, 1]",
        ));
    }
    Ok([0, 1, 2].map(|r| [rows[r][0], rows[r][1], rows[r][2], rows[r][3]]))
}

#[pymethods]
impl Volume {
    /// A volume viewing `array` (3D, indexed `[z, y, x]`) in place; see the module docs.
    #[new]
    #[pyo3(signature = (array, spacing=None, origin=None, world_from_grid=None, intersector="exact"))]
    fn new(
        py: Python<'_>,
        array: &Bound<'_, PyAny>,
        spacing: Option<Vec<f64>>,
        origin: Option<Vec<f64>>,
        world_from_grid: Option<&Bound<'_, PyAny>>,
        intersector: &str,
    ) -> PyResult<PyClassInitializer<Self>> {
        let geometry = Geometry {
            spacing: f64x3(spacing, 1.0, "spacing")?,
            origin: f64x3(origin, 0.0, "origin")?,
            world_from_grid: world_from_grid.map(affine).transpose()?,
        };
        let intersector = parse_intersector(intersector)?;
        let (volume, in_place) = volume_from_array(array, &geometry).py_err()?;
        let path = PathBuf::from("<numpy array>");
        let scene = {
            let path = path.clone();
            interruptible(py, &AtomicBool::new(false), move || {
                AnyScene::Grid(GridData::from_volume(&path, volume, intersector))
            })?
        };
        let loaded = Loaded::new(path, Source::Array { in_place }, scene);
        Ok(
            PyClassInitializer::from(Data { loaded }).add_subclass(Volume {
                array: Some(array.clone().unbind()),
            }),
        )
    }

    /// The numpy array given to `Volume(...)` (`None` for a file).
    #[getter]
    fn array(&self, py: Python<'_>) -> Option<Py<PyAny>> {
        self.array.as_ref().map(|a| a.clone_ref(py))
    }

    /// True when the voxels are the given array's own memory (no copy was made).
    #[getter]
    fn zero_copy(self_: PyRef<'_, Self>) -> bool {
        matches!(
            self_.as_super().loaded.source,
            Source::Array { in_place: true }
        )
    }

    /// Samples per grid axis `(nx, ny, nz)` in memory order (x fastest).
    #[getter]
    fn dims(self_: PyRef<'_, Self>) -> (usize, usize, usize) {
        let [x, y, z] = self_.as_super().loaded.read().data().dims();
        (x, y, z)
    }

    /// Address of the first voxel the renderer reads (to check zero-copy against
    /// `array.ctypes.data`).
    #[getter]
    fn data_address(self_: PyRef<'_, Self>) -> PyResult<usize> {
        let scene = self_.as_super().loaded.read();
        let AnyScene::Grid(g) = &*scene else {
            return Err(pyo3::exceptions::PyValueError::new_err("not a grid"));
        };
        Ok(volume_core::dispatch_voxels!(&g.volume().data, b => b.as_slice().as_ptr() as usize))
    }
}

/// A tetrahedral mesh.
#[pyclass(extends = Data, frozen, module = "isoscope")]
pub struct Mesh {}

#[pymethods]
impl Mesh {
    /// A mesh from `points` (N×3), `tets` (M×4 point indices) and per-point scalar `fields`
    /// (name → N values); `field` is the one drawn (default: the first).
    #[new]
    #[pyo3(signature = (points, tets, fields, field=None, bvh="sah", leaf_size=None, normals="faceted"))]
    fn new<'py>(
        py: Python<'py>,
        points: &Bound<'py, PyAny>,
        tets: &Bound<'py, PyAny>,
        fields: &Bound<'py, PyDict>,
        field: Option<String>,
        bvh: &str,
        leaf_size: Option<usize>,
        normals: &str,
    ) -> PyResult<PyClassInitializer<Self>> {
        let np = py.import("numpy")?;
        let as_array = |obj: &Bound<'py, PyAny>, dtype: &str, what: &str| {
            np.call_method1("ascontiguousarray", (obj, dtype))
                .map_err(|e| {
                    pyo3::exceptions::PyValueError::new_err(format!(
                        "Mesh: {what} is not numeric: {e}"
                    ))
                })
        };
        let pts = as_array(points, "float32", "points")?;
        let pts = pts.cast::<numpy::PyArray2<f32>>().map_err(|_| {
            pyo3::exceptions::PyValueError::new_err("Mesh: points must be an N×3 array")
        })?;
        if pts.shape()[1] != 3 {
            return Err(pyo3::exceptions::PyValueError::new_err(format!(
                "Mesh: points must be N×3, got shape {:?}",
                pts.shape()
            )));
        }
        let tets_i64 = as_array(tets, "int64", "tets")?;
        let tets_i64 = tets_i64.cast::<numpy::PyArray2<i64>>().map_err(|_| {
            pyo3::exceptions::PyValueError::new_err("Mesh: tets must be an M×4 array")
        })?;
        if tets_i64.shape()[1] != 4 {
            return Err(pyo3::exceptions::PyValueError::new_err(format!(
                "Mesh: tets must be M×4, got shape {:?}",
                tets_i64.shape()
            )));
        }
        let points_vec: Vec<[f32; 3]> = pts
            .readonly()
            .as_slice()?
            .chunks_exact(3)
            .map(|c| [c[0], c[1], c[2]])
            .collect();
        let mut tets_vec = Vec::with_capacity(tets_i64.shape()[0]);
        for (i, c) in tets_i64.readonly().as_slice()?.chunks_exact(4).enumerate() {
            let mut t = [0u32; 4];
            for (k, &v) in c.iter().enumerate() {
                t[k] = u32::try_from(v).map_err(|_| {
                    pyo3::exceptions::PyValueError::new_err(format!(
                        "Mesh: tet {i} has point index {v}, not in 0..{}",
                        points_vec.len()
                    ))
                })?;
            }
            tets_vec.push(t);
        }
        let mut point_fields = Vec::new();
        for (name, values) in fields.iter() {
            let name: String = name.extract().map_err(|_| {
                pyo3::exceptions::PyValueError::new_err("Mesh: field names must be strings")
            })?;
            let v = as_array(&values, "float32", &format!("field \"{name}\""))?;
            let v = v
                .call_method0("ravel")?
                .cast_into::<numpy::PyArray1<f32>>()
                .map_err(|_| {
                    pyo3::exceptions::PyValueError::new_err(format!(
                        "Mesh: field \"{name}\" must be a 1D array"
                    ))
                })?;
            point_fields.push(PointField::new(name, v.readonly().as_slice()?.to_vec()));
        }
        let mesh = TetMesh::new(points_vec, tets_vec, point_fields)
            .context("Mesh")
            .py_err()?;
        let mesh_args = MeshArgs {
            bvh: Some(open_args::parse_bvh(bvh).map_err(value_error)?),
            leaf_size,
            packet: None,
            normals: Some(open_args::parse_normals(normals).map_err(value_error)?),
        };
        let options = SceneOptions {
            field,
            bvh: mesh_args.bvh_options().py_err()?,
            normals: mesh_args.normals,
            ..SceneOptions::default()
        };
        let path = PathBuf::from("<numpy mesh>");
        let loaded_mesh = formats::mesh::LoadedMesh {
            source_cells: mesh.tets.len(),
            mesh,
            skipped: formats::mesh::Skipped::default(),
            skipped_arrays: Vec::new(),
        };
        let scene = {
            let path = path.clone();
            interruptible(py, &AtomicBool::new(false), move || {
                TetData::from_loaded(&path, loaded_mesh, &options).map(AnyScene::Tet)
            })?
            .py_err()?
        };
        let loaded = Loaded::new(path, Source::MeshArrays, scene);
        Ok(PyClassInitializer::from(Data { loaded }).add_subclass(Mesh {}))
    }

    /// The drawn point array.
    #[getter]
    fn field(self_: PyRef<'_, Self>) -> Option<String> {
        self_
            .as_super()
            .loaded
            .read()
            .data()
            .field()
            .map(str::to_owned)
    }

    /// Names of the point arrays.
    #[getter]
    fn fields(self_: PyRef<'_, Self>) -> Vec<String> {
        let scene = self_.as_super().loaded.read();
        scene
            .data()
            .field_names()
            .into_iter()
            .map(str::to_owned)
            .collect()
    }
}

/// An out-of-core `.isot` volume (treelets paged in by a loader thread).
#[pyclass(extends = Data, frozen, module = "isoscope")]
pub struct OocVolume {}

/// A time series of volumes or meshes; `Scene.step` switches steps by refitting.
#[pyclass(extends = Data, frozen, module = "isoscope")]
pub struct Series {}

#[pymethods]
impl Series {
    /// The time of each step as the files record it (else the step index).
    #[getter]
    fn time_values(self_: PyRef<'_, Self>) -> Vec<f64> {
        let scene = self_.as_super().loaded.read();
        (0..scene.step_count())
            .map(|s| scene.time_value(s))
            .collect()
    }
}

pub fn value_error(message: String) -> PyErr {
    pyo3::exceptions::PyValueError::new_err(message)
}

pub fn parse_intersector(name: &str) -> PyResult<Intersector> {
    isoscope::cli::render::parse_intersector(name).map_err(value_error)
}

/// A raw-layout value given as a string (`"256x256x108"`) or a sequence.
fn text_or_numbers(v: &Bound<'_, PyAny>, sep: &str) -> PyResult<String> {
    if let Ok(s) = v.extract::<String>() {
        return Ok(s);
    }
    let numbers: Vec<f64> = v.extract().map_err(|_| {
        pyo3::exceptions::PyValueError::new_err("expected a string or a sequence of numbers")
    })?;
    Ok(numbers
        .iter()
        .map(f64::to_string)
        .collect::<Vec<_>>()
        .join(sep))
}

/// Opens any file `isoscope info`/`render` open, with the same options and errors.
///
/// Raw layout keywords mirror the CLI flags: `dims`, `voxel_type`, `endian`, `spacing`,
/// `header_bytes`, `origin`; also `series` (DICOM), `field`, `step`, `intersector`,
/// `normals` (faceted|smooth, any data), `bvh`, `leaf_size` (meshes) and `budget_mb`
/// (`.isot`).
#[pyfunction]
#[pyo3(signature = (path, *, dims=None, voxel_type=None, endian=None, spacing=None, header_bytes=None, origin=None, series=None, field=None, step=None, intersector=None, bvh=None, leaf_size=None, normals=None, budget_mb=None))]
pub fn open(
    py: Python<'_>,
    path: PathBuf,
    dims: Option<&Bound<'_, PyAny>>,
    voxel_type: Option<&str>,
    endian: Option<&str>,
    spacing: Option<&Bound<'_, PyAny>>,
    header_bytes: Option<u64>,
    origin: Option<&Bound<'_, PyAny>>,
    series: Option<&Bound<'_, PyAny>>,
    field: Option<String>,
    step: Option<usize>,
    intersector: Option<&str>,
    bvh: Option<&str>,
    leaf_size: Option<usize>,
    normals: Option<&str>,
    budget_mb: Option<u64>,
) -> PyResult<Py<PyAny>> {
    let open = OpenArgs {
        series: series.map(|s| s.str().map(|s| s.to_string())).transpose()?,
        dims: dims
            .map(|d| {
                formats::raw::parse_dims(&text_or_numbers(d, "x")?)
                    .map_err(|e| value_error(format!("dims: {e}")))
            })
            .transpose()?,
        voxel_type: voxel_type
            .map(|t| {
                open_args::parse_voxel_type(t).map_err(|e| value_error(format!("voxel_type: {e}")))
            })
            .transpose()?,
        endian: endian
            .map(|e| open_args::parse_endian(e).map_err(|e| value_error(format!("endian: {e}"))))
            .transpose()?,
        spacing: spacing
            .map(|s| {
                formats::raw::parse_spacing(&text_or_numbers(s, ",")?)
                    .map_err(|e| value_error(format!("spacing: {e}")))
            })
            .transpose()?,
        header_bytes,
        origin: origin
            .map(|o| {
                open_args::parse_point(&text_or_numbers(o, ",")?)
                    .map_err(|e| value_error(format!("origin: {e}")))
            })
            .transpose()?,
        field,
    };
    let mesh = MeshArgs {
        bvh: bvh
            .map(|b| open_args::parse_bvh(b).map_err(value_error))
            .transpose()?,
        leaf_size,
        packet: None,
        normals: normals
            .map(|n| open_args::parse_normals(n).map_err(value_error))
            .transpose()?,
    };
    let ooc = OocArgs {
        level_timeout: None,
        budget_mb,
    };
    // Volumes and .isot files only: a mesh refuses a cell intersector, as the CLI does.
    let intersector = intersector.map(parse_intersector).transpose()?;
    let options =
        open_args::scene_options(&path, &open, &mesh, &ooc, step, intersector).py_err()?;
    let cancel = AtomicBool::new(false);
    let scene = {
        let (path, cancel) = (path.clone(), &cancel);
        interruptible(py, cancel, move || {
            let control = OpenControl {
                cancel,
                progress: &|_| {},
            };
            open_scene_with(&path, &options, &control)
        })?
        .py_err()?
    };
    wrap_scene(py, &path, Source::File(open), scene)
}

/// The Python object for a scene opened from a file.
fn wrap_scene(py: Python<'_>, path: &Path, source: Source, scene: AnyScene) -> PyResult<Py<PyAny>> {
    let series = scene.step_count() > 1;
    let kind = scene.kind();
    let base = Data {
        loaded: Loaded::new(path.to_path_buf(), source, scene),
    };
    let init = PyClassInitializer::from(base);
    Ok(match kind {
        _ if series => Py::new(py, init.add_subclass(Series {}))?.into_any(),
        isoscope::scene::SceneKind::Grid => {
            Py::new(py, init.add_subclass(Volume { array: None }))?.into_any()
        }
        isoscope::scene::SceneKind::Tet => Py::new(py, init.add_subclass(Mesh {}))?.into_any(),
        isoscope::scene::SceneKind::Ooc => Py::new(py, init.add_subclass(OocVolume {}))?.into_any(),
    })
}

/// Writes the out-of-core `.isot` file of a volume (`isoscope preprocess`), calling
/// `progress(done_bytes, total_bytes)` now and then.
#[pyfunction]
#[pyo3(signature = (src, dst, *, progress=None, treelet_height=9, levels=None, force=false))]
pub fn preprocess(
    py: Python<'_>,
    src: PathBuf,
    dst: PathBuf,
    progress: Option<Py<PyAny>>,
    treelet_height: u32,
    levels: Option<usize>,
    force: bool,
) -> PyResult<()> {
    if !(1..=24).contains(&treelet_height) {
        return Err(value_error(format!(
            "treelet_height {treelet_height} must be between 1 and 24"
        )));
    }
    let levels = match levels {
        None => isoscope::cli::preprocess::Levels::Auto,
        Some(n) => isoscope::cli::preprocess::parse_levels(&n.to_string()).map_err(value_error)?,
    };
    let args = isoscope::cli::preprocess::Args {
        input: src,
        output: dst,
        force,
        treelet_height,
        levels,
        open: OpenArgs::default(),
    };
    let mut callback_error: Option<PyErr> = None;
    let mut last = std::time::Instant::now();
    let result = interruptible(py, &AtomicBool::new(false), || {
        isoscope::cli::preprocess::build(&args, &mut |done, total| {
            let Some(cb) = &progress else { return };
            let finished = done >= total;
            if callback_error.is_some() || !(finished || last.elapsed().as_millis() >= 100) {
                return;
            }
            last = std::time::Instant::now();
            Python::attach(|py| {
                if let Err(e) = cb.call1(py, (done, total)) {
                    callback_error = Some(e);
                }
            });
        })
    })?;
    if let Some(e) = callback_error {
        return Err(e);
    }
    result.py_err().map(|_| ())
}
