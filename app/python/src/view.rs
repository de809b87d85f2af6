//! `Scene` (render, batched ray queries, time steps), `Camera` and `Image`.
//!
//! A scene shares its data object's loaded [`AnyScene`] and keeps its own view options
//! (intersector; normals; BVH for meshes): they are applied to the shared scene before
//! each call that traces rays, which costs nothing when they already match (switching the
//! intersector or the normals is free; another BVH builder is a rebuild). Isovalues are per
//! call, as in the viewer: changing them re-renders without rebuilding anything.
//!
//! Rendering goes through [`render_scene_with`], the function `isoscope render` uses
//! (including the wait for an `.isot` file's finest needed level), so the image and depth
//! equal the CLI's for the same file, camera and settings. `Scene.first_hit` traces
//! caller-given rays with the same [`IsoScene`] traversal, batched over the rayon pool, each
//! ray limited to the data bounds as the renderer limits its primary rays.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use glam::Vec3;
use isoscope::cli::render::{
    IsoSpec, default_key_light, parse_clip_box, parse_clip_plane, parse_color, render_scene_with,
    surfaces_for,
};
use isoscope::scene::{AnyScene, ViewOptions};
use numpy::ndarray::{Array1, Array2, Array3};
use numpy::{IntoPyArray as _, PyArray2, PyArrayMethods, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyBytes;
use rayon::prelude::*;
use volume_core::math::Ray;
use volume_core::render::{
    Camera as CoreCamera, ClipRegion, ColorBy, ColorField, Frame, IsoScene, Light, LightKind,
    NoStats, Projection, RayGen, RenderSettings, SceneVisitor,
};
use volume_core::tet::BvhOptions;

use crate::IntoPyResult as _;
use crate::data::{Data, Loaded, parse_intersector, value_error};
use crate::run::interruptible;

/// Rays traced per parallel task in [`Scene::first_hit`] (and between cancel checks).
const RAYS_PER_TASK: usize = 1024;

/// A view of a data object: render options and a thread pool.
#[pyclass(frozen, module = "isoscope")]
pub struct Scene {
    loaded: Arc<Loaded>,
    /// The data object (kept for `Scene.data`).
    data: Py<PyAny>,
    view: ViewOptions,
    /// Meshes: the BVH this scene asks for (`None`: the one built at load).
    bvh: Option<BvhOptions>,
    /// `threads=N`: a pool of its own; `None`: rayon's global pool (all cores).
    pool: Option<rayon::ThreadPool>,
}

impl Scene {
    /// Runs `f` on the shared scene with this scene's view options applied, in this scene's
    /// thread pool, without the GIL and interruptible.
    fn with_scene<T: Send>(
        &self,
        py: Python<'_>,
        cancel: &AtomicBool,
        f: impl FnOnce(&AnyScene) -> T + Send,
    ) -> PyResult<T> {
        let loaded = &self.loaded;
        let (view, bvh, pool) = (self.view, self.bvh, self.pool.as_ref());
        interruptible(py, cancel, move || {
            {
                let needs_view = !loaded.read().data().has_view_options(&view);
                let needs_bvh = bvh.is_some_and(|b| match &*loaded.read() {
                    AnyScene::Tet(t) => t.scene().bvh().options() != b,
                    _ => false,
                });
                if needs_view || needs_bvh {
                    let mut scene = loaded.write();
                    scene.data_mut().set_view_options(&view);
                    if let (Some(b), Some(t)) = (bvh, scene.as_tet_mut())
                        && t.scene().bvh().options() != b
                    {
                        t.rebuild(b);
                    }
                }
            }
            let scene = loaded.read();
            match pool {
                Some(p) => p.install(|| f(&scene)),
                None => f(&scene),
            }
        })
    }
}

/// `(v, color, opacity)`, `(v, color)`, `(v,)` or `v`; color `"#rrggbb"` or `(r, g, b)` in
/// `[0, 1]`.
fn iso_spec(item: &Bound<'_, PyAny>) -> PyResult<IsoSpec> {
    let parts: Vec<Bound<'_, PyAny>> = if let Ok(v) = item.extract::<f64>() {
        vec![v.into_pyobject(item.py())?.into_any()]
    } else {
        item.extract().map_err(|_| {
            value_error(
                "isovalues: each entry is a value or a tuple (value, color, opacity)".into(),
            )
        })?
    };
    if parts.is_empty() || parts.len() > 3 {
        return Err(value_error(format!(
            "isovalues: expected (value, color, opacity), got {} items",
            parts.len()
        )));
    }
    let value: f32 = parts[0]
        .extract()
        .map_err(|_| value_error("isovalues: the value must be a number".into()))?;
    if !value.is_finite() {
        return Err(value_error(format!("isovalues: {value} is not finite")));
    }
    let color = match parts.get(1) {
        None => None,
        Some(c) if c.is_none() => None,
        Some(c) => Some(color(c, "isovalues")?),
    };
    let opacity = match parts.get(2) {
        None => 1.0,
        Some(o) => {
            let o: f32 = o
                .extract()
                .map_err(|_| value_error("isovalues: opacity must be a number".into()))?;
            if !(0.0..=1.0).contains(&o) {
                return Err(value_error(format!(
                    "isovalues: opacity {o} is not in [0, 1]"
                )));
            }
            o
        }
    };
    Ok(IsoSpec {
        value,
        color,
        opacity,
    })
}

fn color(c: &Bound<'_, PyAny>, what: &str) -> PyResult<[f32; 3]> {
    if let Ok(s) = c.extract::<String>() {
        return parse_color(&s).map_err(|e| value_error(format!("{what}: {e}")));
    }
    let rgb: [f32; 3] = c.extract().map_err(|_| {
        value_error(format!(
            "{what}: a colour is \"#rrggbb\" or (r, g, b) in [0, 1]"
        ))
    })?;
    if rgb.iter().any(|x| !(0.0..=1.0).contains(x)) {
        return Err(value_error(format!(
            "{what}: colour {rgb:?} has a channel outside [0, 1]"
        )));
    }
    Ok(rgb)
}

/// A clip region given as the CLI's text or as a sequence of numbers (and `"inside"`/
/// `"outside"` for boxes), parsed by the CLI's parser.
fn clip(
    item: &Bound<'_, PyAny>,
    parse: fn(&str) -> Result<ClipRegion, String>,
    what: &str,
) -> PyResult<ClipRegion> {
    let text = if let Ok(s) = item.extract::<String>() {
        s
    } else {
        let parts: Vec<Bound<'_, PyAny>> = item
            .extract()
            .map_err(|_| value_error(format!("{what}: expected a sequence or a string")))?;
        let mut numbers = Vec::new();
        let mut keep = None;
        for p in &parts {
            if let Ok(x) = p.extract::<f64>() {
                numbers.push(x.to_string());
            } else if let Ok(k) = p.extract::<String>() {
                keep = Some(k);
            } else {
                return Err(value_error(format!("{what}: {p} is not a number")));
            }
        }
        let mut t = numbers.join(",");
        if let Some(k) = keep {
            t.push(':');
            t.push_str(&k);
        }
        t
    };
    parse(&text).map_err(|e| value_error(format!("{what}: {e}")))
}

impl Scene {
    /// The colouring `render`'s `color_by`, `colormap`, `color_range` and `scalar_bar` give;
    /// a volume's other volume (a path) is opened and checked against its grid first.
    fn coloring(
        &self,
        py: Python<'_>,
        color_by: Option<&str>,
        colormap: Option<&str>,
        color_range: Option<(f32, f32)>,
        scalar_bar: bool,
    ) -> PyResult<Option<ColorBy>> {
        let Some(spec) = color_by else {
            if colormap.is_some() || color_range.is_some() {
                return Err(value_error(
                    "colormap and color_range apply with color_by".into(),
                ));
            }
            return Ok(None);
        };
        let colormap = colormap
            .map(|c| isoscope::cli::render::parse_colormap(c).map_err(value_error))
            .transpose()?
            .unwrap_or_default();
        let field = isoscope::cli::render::color_field(spec, &self.loaded.read());
        if let ColorField::Field(name) = &field {
            let missing = matches!(
                &*self.loaded.read(),
                AnyScene::Grid(g) if g.color_volume(name).is_none()
            );
            if missing {
                let loaded = &self.loaded;
                let path = std::path::PathBuf::from(name);
                interruptible(py, &AtomicBool::new(false), move || {
                    match &mut *loaded.write() {
                        AnyScene::Grid(g) => g.add_color_volume(&path).map(|_| ()),
                        _ => Ok(()),
                    }
                })?
                .py_err()?;
            }
        }
        Ok(Some(ColorBy {
            field,
            colormap,
            range: color_range.map(|(lo, hi)| [lo, hi]),
            scalar_bar,
        }))
    }
}

#[pymethods]
impl Scene {
    /// A scene of `data` (a `Volume`, `Mesh`, `OocVolume` or `Series`). `intersector`:
    /// exact, linear, neubauer[:N], schwarze, reference; `normals` (faceted|smooth; default:
    /// smooth for volumes, faceted for meshes); meshes: `bvh` (bih|sah), `leaf_size`. `threads`: rayon threads (default: all).
    #[new]
    #[pyo3(signature = (data, intersector=None, bvh=None, leaf_size=None, normals=None, threads=None))]
    fn new(
        data: &Bound<'_, Data>,
        intersector: Option<&str>,
        bvh: Option<&str>,
        leaf_size: Option<usize>,
        normals: Option<&str>,
        threads: Option<usize>,
    ) -> PyResult<Self> {
        let loaded = Arc::clone(&data.get().loaded);
        let is_tet = loaded.read().as_tet().is_some();
        if is_tet && let Some(name) = intersector {
            return Err(value_error(format!(
                "intersector=\"{name}\" chooses the cell intersector of volumes and .isot \
                 files; {} is a tetrahedral mesh, whose isosurface is the marching-tetrahedra \
                 isopolygons of each tet",
                loaded.path.display()
            )));
        }
        if !is_tet && (bvh.is_some() || leaf_size.is_some()) {
            return Err(value_error(format!(
                "bvh and leaf_size apply to tetrahedral meshes; {} is a {} data set",
                loaded.path.display(),
                loaded.read().kind()
            )));
        }
        let current = (
            loaded.opened_normals,
            loaded.read().as_tet().map(|t| t.scene().bvh().options()),
        );
        let normals = match normals {
            Some(n) => Some(isoscope::cli::open_args::parse_normals(n).map_err(value_error)?),
            None => current.0,
        };
        let bvh = if bvh.is_some() || leaf_size.is_some() {
            let args = isoscope::cli::open_args::MeshArgs {
                bvh: bvh
                    .map(|b| isoscope::cli::open_args::parse_bvh(b).map_err(value_error))
                    .transpose()?,
                leaf_size,
                packet: None,
                normals: None,
            };
            Some(args.bvh_options().py_err()?)
        } else {
            current.1
        };
        let pool = match threads {
            None => None,
            Some(0) => return Err(value_error("threads must be at least 1".into())),
            Some(n) => Some(
                rayon::ThreadPoolBuilder::new()
                    .num_threads(n)
                    .build()
                    .map_err(|e| value_error(format!("threads={n}: {e}")))?,
            ),
        };
        Ok(Self {
            loaded,
            data: data.clone().into_any().unbind(),
            view: ViewOptions {
                intersector: intersector
                    .map(parse_intersector)
                    .transpose()?
                    .unwrap_or_default(),
                normals,
            },
            bvh,
            pool,
        })
    }

    /// The data object this scene draws.
    #[getter]
    fn data(&self, py: Python<'_>) -> Py<PyAny> {
        self.data.clone_ref(py)
    }

    /// World-space bounds `((x0, y0, z0), (x1, y1, z1))`.
    #[getter]
    fn bounds(&self) -> ([f32; 3], [f32; 3]) {
        let b = self.loaded.read().world_bounds();
        (b.min.to_array(), b.max.to_array())
    }

    /// The time step shown; setting it loads that step and refits the structure (as the
    /// viewer's time slider does).
    #[getter]
    fn get_step(&self) -> usize {
        self.loaded.read().step()
    }

    #[setter]
    fn set_step(&self, py: Python<'_>, step: usize) -> PyResult<()> {
        let loaded = &self.loaded;
        interruptible(py, &AtomicBool::new(false), move || {
            loaded.write().set_step(step)
        })?
        .py_err()
        .map(|_| ())
    }

    /// Re-reads the voxels of a volume made from a numpy array after the array was written
    /// to (value range and kd-tree refit; no copy). Returns `"refit"`; other data has nothing
    /// to re-read and returns `"unchanged"`.
    fn refresh(&self, py: Python<'_>) -> PyResult<&'static str> {
        let loaded = &self.loaded;
        interruptible(py, &AtomicBool::new(false), move || {
            match &mut *loaded.write() {
                AnyScene::Grid(g) => match g.refresh() {
                    isoscope::scene::StepSwitch::Refit => "refit",
                    isoscope::scene::StepSwitch::Rebuilt => "rebuilt",
                    isoscope::scene::StepSwitch::Unchanged => "unchanged",
                },
                _ => "unchanged",
            }
        })
    }

    /// Renders the isosurfaces; see the stub for the arguments. `camera` or `orbit=(az, el)`
    /// (default `(30, 20)`, framing the data as the CLI's `--orbit`).
    #[pyo3(signature = (isovalues=None, *, camera=None, orbit=None, vfov=40.0, size=(800, 600), shadows=false, light_dir=None, clip_boxes=None, clip_planes=None, layers=4, background=None, supersample=1, level_timeout=120.0, color_by=None, colormap=None, color_range=None, scalar_bar=true, depth_only=false))]
    fn render(
        &self,
        py: Python<'_>,
        isovalues: Option<Vec<Bound<'_, PyAny>>>,
        camera: Option<PyRef<'_, Camera>>,
        orbit: Option<(f32, f32)>,
        vfov: f32,
        size: (u32, u32),
        shadows: bool,
        light_dir: Option<[f32; 3]>,
        clip_boxes: Option<Vec<Bound<'_, PyAny>>>,
        clip_planes: Option<Vec<Bound<'_, PyAny>>>,
        layers: u32,
        background: Option<Bound<'_, PyAny>>,
        supersample: u32,
        level_timeout: f64,
        color_by: Option<String>,
        colormap: Option<String>,
        color_range: Option<(f32, f32)>,
        scalar_bar: bool,
        depth_only: bool,
    ) -> PyResult<Image> {
        if depth_only && (shadows || color_by.is_some()) {
            return Err(value_error(
                "depth_only draws flat colours: no shadows or color_by with it".into(),
            ));
        }
        let specs = isovalues
            .unwrap_or_default()
            .iter()
            .map(iso_spec)
            .collect::<PyResult<Vec<_>>>()?;
        let mut surfaces = surfaces_for(&specs, &self.loaded.read()).py_err()?;
        let coloring = self.coloring(
            py,
            color_by.as_deref(),
            colormap.as_deref(),
            color_range,
            scalar_bar,
        )?;
        if let Some(c) = coloring {
            isoscope::coloring::color_all(&mut surfaces, &c);
        }
        let camera = match (camera, orbit) {
            (Some(_), Some(_)) => {
                return Err(value_error("give camera or orbit, not both".into()));
            }
            (Some(c), None) => c.inner,
            // The CLI's orbit: the same framing of the bounds for this image size.
            (None, orbit) => isoscope::cli::render::ViewArgs {
                camera: None,
                orbit: orbit.map(|(a, e)| [a, e]),
                vfov,
            }
            .camera(&self.loaded.read().world_bounds(), [size.0, size.1])
            .py_err()?,
        };
        camera.validate().py_err()?;
        if layers == 0 {
            return Err(value_error("layers must be at least 1".into()));
        }
        let mut clips = Vec::new();
        for c in clip_boxes.unwrap_or_default() {
            clips.push(clip(&c, parse_clip_box, "clip_boxes")?);
        }
        for c in clip_planes.unwrap_or_default() {
            clips.push(clip(&c, parse_clip_plane, "clip_planes")?);
        }
        let mut light = Light::default();
        if let Some(d) = light_dir {
            light.kind = LightKind::Directional {
                dir: Vec3::from_array(d),
            };
        } else if shadows {
            light.kind = LightKind::Directional {
                dir: default_key_light(&camera),
            };
        }
        let defaults = RenderSettings::default();
        let settings = RenderSettings {
            width: size.0,
            height: size.1,
            surfaces,
            clips,
            max_layers: layers,
            shadows,
            light,
            background: match &background {
                Some(b) => color(b, "background")?,
                None => defaults.background,
            },
            supersample,
            depth_only,
            ..defaults
        };
        settings.validate().py_err()?;
        self.loaded.read().check_colorings(&settings).py_err()?;
        if !(level_timeout.is_finite() && level_timeout >= 0.0) {
            return Err(value_error(format!(
                "level_timeout {level_timeout} must be a number of seconds >= 0"
            )));
        }
        let timeout = Duration::from_secs_f64(level_timeout.min(1e9));
        let cancel = AtomicBool::new(false);
        let mut frame = self
            .with_scene(py, &cancel, |scene| {
                render_scene_with(scene, &camera, &settings, timeout, &cancel)
            })?
            .py_err()?
            .frame;
        let bars = self.loaded.read().scalar_bars(&settings);
        isoscope::scalar_bar::composite(&mut frame.rgba8, frame.width, frame.height, &bars);
        Ok(Image { frame })
    }

    /// Writes the isosurfaces at the current time step, clipped, as a triangle mesh (PLY,
    /// STL or OBJ by `path`'s extension), as `isoscope export` does; returns the counts and
    /// area as a dict.
    #[pyo3(signature = (path, isovalues=None, *, clip_boxes=None, clip_planes=None, normals=false, force=false))]
    fn export<'py>(
        &self,
        py: Python<'py>,
        path: std::path::PathBuf,
        isovalues: Option<Vec<Bound<'_, PyAny>>>,
        clip_boxes: Option<Vec<Bound<'_, PyAny>>>,
        clip_planes: Option<Vec<Bound<'_, PyAny>>>,
        normals: bool,
        force: bool,
    ) -> PyResult<Bound<'py, pyo3::types::PyDict>> {
        let specs = isovalues
            .unwrap_or_default()
            .iter()
            .map(iso_spec)
            .collect::<PyResult<Vec<_>>>()?;
        let surfaces = surfaces_for(&specs, &self.loaded.read()).py_err()?;
        let mut clips = Vec::new();
        for c in clip_boxes.unwrap_or_default() {
            clips.push(clip(&c, parse_clip_box, "clip_boxes")?);
        }
        for c in clip_planes.unwrap_or_default() {
            clips.push(clip(&c, parse_clip_plane, "clip_planes")?);
        }
        let cancel = AtomicBool::new(false);
        let summary = self
            .with_scene(py, &cancel, |scene| {
                isoscope::export::export_mesh(
                    scene,
                    &surfaces,
                    &clips,
                    &path,
                    normals,
                    formats::output::Replace::from_force(force),
                    &cancel,
                    &|_| {},
                )
            })?
            .py_err()?;
        let out = pyo3::types::PyDict::new(py);
        out.set_item("format", summary.format.name().to_ascii_lowercase())?;
        out.set_item("vertices", summary.vertices)?;
        out.set_item("triangles", summary.triangles)?;
        out.set_item("area", summary.area)?;
        Ok(out)
    }

    /// First hits of N rays (`origins`, `directions`: N×3, world units; directions need not
    /// be unit length) with the surfaces `isovalues`. Returns `(t, normal, surface)`: `t`
    /// (N, float32) is the distance along the normalized direction, `inf` on a miss;
    /// `normal` (N×3, float32) a unit world normal (NaN on a miss); `surface` (N, int32) the
    /// index into `isovalues` of the surface hit, `-1` on a miss. Rays are limited to
    /// `[t_min, t_max]` and to the data bounds, as the renderer limits its rays.
    #[pyo3(signature = (origins, directions, isovalues, *, t_min=0.0, t_max=f32::INFINITY))]
    fn first_hit<'py>(
        &self,
        py: Python<'py>,
        origins: &Bound<'py, PyAny>,
        directions: &Bound<'py, PyAny>,
        isovalues: Vec<f32>,
        t_min: f32,
        t_max: f32,
    ) -> PyResult<(Py<PyAny>, Py<PyAny>, Py<PyAny>)> {
        let origins = rays_array(py, origins, "origins")?;
        let directions = rays_array(py, directions, "directions")?;
        let n = origins.shape()[0];
        if directions.shape()[0] != n {
            return Err(value_error(format!(
                "first_hit: {n} origins but {} directions",
                directions.shape()[0]
            )));
        }
        if let Some(v) = isovalues.iter().find(|v| !v.is_finite()) {
            return Err(value_error(format!(
                "first_hit: isovalue {v} is not finite"
            )));
        }
        if t_min.is_nan() || t_max.is_nan() || t_min > t_max {
            return Err(value_error(format!(
                "first_hit: t_min {t_min} and t_max {t_max} are not a range"
            )));
        }
        let o = origins.readonly();
        let d = directions.readonly();
        let (o, d) = (o.as_slice()?, d.as_slice()?);
        let mut t = vec![f32::INFINITY; n];
        let mut normal = vec![f32::NAN; 3 * n];
        let mut surface = vec![-1i32; n];
        let cancel = AtomicBool::new(false);
        {
            let query = FirstHits {
                origins: o,
                directions: d,
                isovalues: &isovalues,
                range: (t_min, t_max),
                cancel: &cancel,
                t: &mut t,
                normal: &mut normal,
                surface: &mut surface,
            };
            self.with_scene(py, &cancel, |scene| {
                if let AnyScene::Ooc(o) = scene {
                    o.set_isovalues(&isovalues);
                }
                scene.visit(query);
            })?;
        }
        Ok((
            Array1::from_vec(t).into_pyarray(py).into_any().unbind(),
            Array2::from_shape_vec((n, 3), normal)
                .map_err(|e| value_error(e.to_string()))?
                .into_pyarray(py)
                .into_any()
                .unbind(),
            Array1::from_vec(surface)
                .into_pyarray(py)
                .into_any()
                .unbind(),
        ))
    }

    fn __repr__(&self) -> String {
        format!(
            "<isoscope.Scene of {}: {}>",
            self.loaded.path.display(),
            self.loaded.read().describe()
        )
    }
}

/// An N×3 float32 C-contiguous array (a copy only if needed).
fn rays_array<'py>(
    py: Python<'py>,
    a: &Bound<'py, PyAny>,
    what: &str,
) -> PyResult<Bound<'py, PyArray2<f32>>> {
    let arr = py
        .import("numpy")?
        .call_method1("ascontiguousarray", (a, "float32"))
        .map_err(|e| value_error(format!("first_hit: {what} is not numeric: {e}")))?;
    let arr = arr
        .cast_into::<PyArray2<f32>>()
        .map_err(|_| value_error(format!("first_hit: {what} must be an N×3 array")))?;
    if arr.shape()[1] != 3 {
        return Err(value_error(format!(
            "first_hit: {what} must be N×3, got shape {:?}",
            arr.shape()
        )));
    }
    Ok(arr)
}

/// Batched first hits on the typed scene (monomorphized, as the renderer is).
struct FirstHits<'a> {
    origins: &'a [f32],
    directions: &'a [f32],
    isovalues: &'a [f32],
    range: (f32, f32),
    cancel: &'a AtomicBool,
    t: &'a mut [f32],
    normal: &'a mut [f32],
    surface: &'a mut [i32],
}

impl SceneVisitor for FirstHits<'_> {
    type Output = ();
    fn visit<S: IsoScene>(self, scene: &S) {
        let isos = scene.prepare(self.isovalues);
        let bounds = scene.world_bounds();
        let (t_min, t_max) = self.range;
        self.t
            .par_chunks_mut(RAYS_PER_TASK)
            .zip(self.normal.par_chunks_mut(3 * RAYS_PER_TASK))
            .zip(self.surface.par_chunks_mut(RAYS_PER_TASK))
            .enumerate()
            .for_each(|(chunk, ((t, normal), surface))| {
                if self.cancel.load(Ordering::Relaxed) {
                    return;
                }
                let first = chunk * RAYS_PER_TASK;
                for k in 0..t.len() {
                    let i = first + k;
                    let o = Vec3::from_slice(&self.origins[3 * i..3 * i + 3]);
                    let d = Vec3::from_slice(&self.directions[3 * i..3 * i + 3]);
                    let Some(d) = d.try_normalize() else { continue };
                    if !o.is_finite() {
                        continue;
                    }
                    let ray = Ray::new(o, d);
                    let Some((lo, hi)) = bounds.intersect(&ray, t_min, t_max) else {
                        continue;
                    };
                    if let Some(hit) = scene.first_hit_prepared(&ray, lo, hi, &isos, &mut NoStats) {
                        t[k] = hit.t;
                        normal[3 * k..3 * k + 3].copy_from_slice(&hit.normal.to_array());
                        surface[k] = hit.surface as i32;
                    }
                }
            });
    }
}

/// A pinhole or orthographic camera (world units), as the CLI's camera JSON.
#[pyclass(frozen, module = "isoscope")]
#[derive(Clone)]
pub struct Camera {
    inner: CoreCamera,
}

#[pymethods]
impl Camera {
    #[new]
    #[pyo3(signature = (eye, target, up=(0.0, 0.0, 1.0), vfov_deg=40.0, projection="pinhole", ortho_height=None))]
    fn new(
        eye: [f32; 3],
        target: [f32; 3],
        up: (f32, f32, f32),
        vfov_deg: f32,
        projection: &str,
        ortho_height: Option<f32>,
    ) -> PyResult<Self> {
        let projection = match projection {
            "pinhole" => Projection::Pinhole,
            "orthographic" => Projection::Orthographic,
            other => {
                return Err(value_error(format!(
                    "projection \"{other}\": expected \"pinhole\" or \"orthographic\""
                )));
            }
        };
        let inner = CoreCamera {
            eye: Vec3::from_array(eye),
            target: Vec3::from_array(target),
            up: Vec3::new(up.0, up.1, up.2),
            vfov_deg,
            projection,
            ortho_height,
        };
        inner.validate().py_err()?;
        Ok(Self { inner })
    }

    /// The orbit camera the CLI's `--orbit AZ,EL --size WxH` frames `scene` with.
    #[staticmethod]
    #[pyo3(signature = (scene, azimuth_deg=30.0, elevation_deg=20.0, vfov_deg=40.0, size=(800, 600)))]
    fn orbit(
        scene: &Scene,
        azimuth_deg: f32,
        elevation_deg: f32,
        vfov_deg: f32,
        size: (u32, u32),
    ) -> PyResult<Self> {
        let inner = isoscope::cli::render::ViewArgs {
            camera: None,
            orbit: Some([azimuth_deg, elevation_deg]),
            vfov: vfov_deg,
        }
        .camera(&scene.loaded.read().world_bounds(), [size.0, size.1])
        .py_err()?;
        Ok(Self { inner })
    }

    /// Reads a camera JSON file (the CLI's `--camera`).
    #[staticmethod]
    fn load(path: std::path::PathBuf) -> PyResult<Self> {
        Ok(Self {
            inner: isoscope::cli::render::load_camera(&path).py_err()?,
        })
    }

    /// The camera as the CLI's camera JSON.
    fn to_json(&self) -> PyResult<String> {
        serde_json::to_string_pretty(&self.inner).py_err()
    }

    #[getter]
    fn eye(&self) -> [f32; 3] {
        self.inner.eye.to_array()
    }

    #[getter]
    fn target(&self) -> [f32; 3] {
        self.inner.target.to_array()
    }

    #[getter]
    fn up(&self) -> [f32; 3] {
        self.inner.up.to_array()
    }

    #[getter]
    fn vfov_deg(&self) -> f32 {
        self.inner.vfov_deg
    }

    /// The primary rays of a `width`×`height` image through pixel centres, row 0 at the top:
    /// `(origins, directions)`, each (H·W)×3 float32, directions unit length — the rays the
    /// renderer traces for each pixel.
    fn rays(&self, py: Python<'_>, width: u32, height: u32) -> PyResult<(Py<PyAny>, Py<PyAny>)> {
        if width == 0 || height == 0 {
            return Err(value_error(
                "rays: width and height must be at least 1".into(),
            ));
        }
        let ray_gen = RayGen::new(&self.inner, width, height);
        let n = (width * height) as usize;
        let mut o = Vec::with_capacity(3 * n);
        let mut d = Vec::with_capacity(3 * n);
        for j in 0..height {
            for i in 0..width {
                let r = ray_gen.ray_at(i as f32 + 0.5, j as f32 + 0.5);
                o.extend_from_slice(&r.origin.to_array());
                d.extend_from_slice(&r.dir.to_array());
            }
        }
        let shape = (n, 3);
        Ok((
            Array2::from_shape_vec(shape, o)
                .map_err(|e| value_error(e.to_string()))?
                .into_pyarray(py)
                .into_any()
                .unbind(),
            Array2::from_shape_vec(shape, d)
                .map_err(|e| value_error(e.to_string()))?
                .into_pyarray(py)
                .into_any()
                .unbind(),
        ))
    }

    fn __repr__(&self) -> String {
        format!(
            "Camera(eye={:?}, target={:?}, up={:?}, vfov_deg={})",
            self.inner.eye.to_array(),
            self.inner.target.to_array(),
            self.inner.up.to_array(),
            self.inner.vfov_deg
        )
    }
}

/// A rendered frame.
#[pyclass(frozen, module = "isoscope")]
pub struct Image {
    frame: Frame,
}

#[pymethods]
impl Image {
    #[getter]
    fn width(&self) -> u32 {
        self.frame.width
    }

    #[getter]
    fn height(&self) -> u32 {
        self.frame.height
    }

    /// H×W×4 uint8, row 0 at the top (a new array each time).
    #[getter]
    fn rgba(&self, py: Python<'_>) -> PyResult<Py<PyAny>> {
        let (w, h) = (self.frame.width as usize, self.frame.height as usize);
        Ok(Array3::from_shape_vec((h, w, 4), self.frame.rgba8.clone())
            .map_err(|e| value_error(e.to_string()))?
            .into_pyarray(py)
            .into_any()
            .unbind())
    }

    /// H×W float32 first-hit distance along each pixel's unit ray, `inf` where it misses
    /// (the CLI's `--depth-out`).
    #[getter]
    fn depth(&self, py: Python<'_>) -> PyResult<Py<PyAny>> {
        let (w, h) = (self.frame.width as usize, self.frame.height as usize);
        Ok(Array2::from_shape_vec((h, w), self.frame.depth.clone())
            .map_err(|e| value_error(e.to_string()))?
            .into_pyarray(py)
            .into_any()
            .unbind())
    }

    /// Render time in seconds.
    #[getter]
    fn elapsed_s(&self) -> f64 {
        self.frame.elapsed.as_secs_f64()
    }

    /// Writes the image as an RGBA PNG (atomically; an existing file only with `force`).
    #[pyo3(signature = (path, *, force=false))]
    fn save(&self, path: std::path::PathBuf, force: bool) -> PyResult<()> {
        isoscope::cli::render::save_png(
            &self.frame,
            &path,
            formats::output::Replace::from_force(force),
        )
        .py_err()
    }

    /// PNG bytes, so a Jupyter cell shows the image.
    fn _repr_png_<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyBytes>> {
        let png = isoscope::output::png_bytes(
            &self.frame.rgba8,
            self.frame.width,
            self.frame.height,
            image::ExtendedColorType::Rgba8,
        )
        .py_err()?;
        Ok(PyBytes::new(py, &png))
    }

    fn __repr__(&self) -> String {
        format!(
            "<isoscope.Image {}x{}>",
            self.frame.width, self.frame.height
        )
    }
}
