//! # Loaded scenes: one type for every kind of data the renderer draws
//!
//! [`open_scene`] opens any supported path and returns an [`AnyScene`]; the CLI (`render`,
//! `bench`) and the viewer use it the same way, so there is one place that decides how a
//! file becomes something to ray trace, and one render call for every kind:
//!
//! | kind | files | acceleration structure |
//! |---|---|---|
//! | [`AnyScene::Grid`] | NRRD/NHDR, NIfTI (`.nii`, `.nii.gz`, `.hdr`/`.img`, 4D), Analyze 7.5, MetaImage `.mha`/`.mhd`, VTK image data (`.vti`, legacy `.vtk` structured points and rectilinear grids), TIFF stacks (multi-page, or numbered 2D slices `slice_*.tif`), DICOM (a folder, a `DICOMDIR`, a `.dcm` and its series), raw (+ layout or `NAME.json` sidecar), series patterns (`vol_%03d.nrrd`, `vol_*.nrrd`), 4D NRRD and MetaImage — via `formats::open` | implicit min/max kd-tree ([`AnyGridScene`], thesis 004 ch. 7) |
//! | [`AnyScene::Tet`] | `.vtk` (unstructured grids: a `.vtk` is a mesh or a grid by its `DATASET` line), `.vtu`, `.msh`, `.node`/`.ele`, a `.pvd` collection or a mesh pattern (`step_%03d.vtu`, `step_*.vtu`) — via `formats::mesh` | implicit min/max BVH with 4D bounds ([`TetScene`], ch. 8) |
//! | [`AnyScene::Ooc`] | `.isot` treelet files (`isoscope preprocess`) — via `formats::treelet::open_isot` | treelets + loader thread ([`AnyOocVolume`], §7.7–7.8) |
//!
//! ## Use
//! ```no_run
//! # use std::sync::atomic::AtomicBool;
//! # use isoscope::scene::{open_scene, SceneOptions};
//! # use volume_core::render::{Camera, RenderSettings, Surface};
//! # fn main() -> anyhow::Result<()> {
//! let scene = open_scene("ball.vtu".as_ref(), &SceneOptions::default())?;
//! let iso = scene.default_isovalue().unwrap_or(0.0);
//! let camera = Camera::orbit(&scene.world_bounds(), 30.0, 20.0, 40.0);
//! let settings = RenderSettings {
//!     surfaces: vec![Surface::new(iso, [0.9, 0.8, 0.6])],
//!     ..RenderSettings::default()
//! };
//! let frame = scene.render(&camera, &settings, &AtomicBool::new(false));
//! # Ok(()) }
//! ```
//!
//! - Rendering: [`AnyScene::render`] calls [`volume_core::render::render_colored_into`]
//!   once (surfaces coloured by another field resolved by [`crate::coloring`]), on the
//!   typed scene ([`AnyScene::visit`] hands it to any [`SceneVisitor`], fully monomorphized:
//!   no dynamic dispatch per ray). Shading, transparency, clipping and shadows are the
//!   renderer's, shared by all kinds.
//! - Out-of-core: `render` first tells the loader the frame's active isovalues
//!   ([`OocData::set_isovalues`]; the same quantized bucket is a no-op), then renders with the
//!   levels loaded so far — it never waits. Poll [`OocData::status`] for a progress
//!   indicator, or [`OocData::wait_until_finished`] (not from a render thread) to wait for the
//!   finest level the isovalues need. [`OocData::render_with_level`] also reports the level
//!   the frame reached.
//! - Each kind answers for itself: [`GridData`], [`TetData`] and [`OocData`] implement
//!   [`SceneData`] (steps, prefetching, value range and histogram, view options, summary),
//!   reached through [`AnyScene::data`]; callers never match on the kind. A mesh keeps its
//!   prefetched steps in its own step cache, a grid series in the series' cache.
//! - Time steps: [`AnyScene::step_count`], [`AnyScene::set_step`]: grids refit the kd-tree
//!   (thesis §7.6), meshes refit the BVH (§8.5.2: value ranges only when only scalars change,
//!   full 4D refit when points move).
//! - Meshes: the drawn point array is [`SceneOptions::field`] (default: the first one) and
//!   can be switched with [`TetData::set_field`] (a value refit, no rebuild). VTK image data
//!   with several point arrays likewise (`formats::OpenOptions::field`; default: the active
//!   scalars): [`SceneData::set_field`] re-reads the file with the other array and refits
//!   the kd-tree when dims and voxel type stay. Normals ([`Normals`]: grids and `.isot`
//!   smooth by default, meshes faceted) and the mesh packet size ([`SceneOptions::packet_rays`],
//!   default 256 = 16×16; the renderer orders a tile's rays along a Morton curve, so 4 rays are
//!   a 2×2 block and 256 a 16×16 block) are per-scene settings.
//!
//! Nothing here prints or depends on clap: errors are `anyhow` with the file named.

use std::collections::VecDeque;
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::sync::{Arc, Mutex, OnceLock};
use std::time::{Duration, Instant};

use anyhow::{Context as _, bail};
use formats::mesh::{LoadedMesh, MeshSeries, StepData};
use volume_core::grid::AnyGridScene;
use volume_core::grid::VolumeSampler;
use volume_core::intersect::Intersector;
use volume_core::math::Aabb;
use volume_core::ooc::{AnyOocVolume, OocOptions};
use volume_core::render::Normals;
use volume_core::render::SceneVisitor;
use volume_core::render::{
    Camera, Frame, IsoScene, RenderSettings, Surface, SurfaceColoring, render_colored_into,
};
use volume_core::series::TimeSeries;
use volume_core::stats::Histogram;
use volume_core::tet::{BvhOptions, MAX_PACKET, PointField, TetScene};
use volume_core::{RectilinearVolume, VoxelType};

/// The three kinds of scene.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SceneKind {
    /// A rectilinear volume (or a series of them) with the kd-tree.
    Grid,
    /// A tetrahedral mesh (or a series) with the BVH.
    Tet,
    /// An out-of-core `.isot` treelet file.
    Ooc,
}

impl SceneKind {
    /// `"grid"`, `"tet"` or `"isot"` (the `kind` field of `info --json` and `bench --json`).
    pub const fn name(self) -> &'static str {
        match self {
            SceneKind::Grid => "grid",
            SceneKind::Tet => "tet",
            SceneKind::Ooc => "isot",
        }
    }
}

impl std::fmt::Display for SceneKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// What [`open_scene`] will open `path` as: a folder, a `DICOMDIR` or a `.dcm` file is a grid
/// (a DICOM series); meshes by extension (`.vtk`, `.vtu`, `.msh`, `.node`, `.ele`, `.pvd`,
/// also in patterns; a `.vtk` whose `DATASET` is an image is a grid), `.isot` by extension or
/// magic, else a grid (NRRD, NIfTI, Analyze, MetaImage, VTK image data, TIFF, raw, volume
/// series).
pub fn detect_kind(path: &Path) -> SceneKind {
    let ext = path
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase());
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().to_ascii_lowercase());
    if path.is_dir()
        || name.as_deref() == Some("dicomdir")
        || matches!(ext.as_deref(), Some("dcm" | "dicom"))
    {
        SceneKind::Grid
    } else if formats::mesh::is_mesh_path(path) {
        SceneKind::Tet
    } else if ext.as_deref() == Some("isot") || (path.is_file() && formats::treelet::is_isot(path))
    {
        SceneKind::Ooc
    } else {
        SceneKind::Grid
    }
}

/// How to open a file (everything but the path).
#[derive(Debug, Clone)]
pub struct SceneOptions {
    /// Raw-file layout, TIFF spacing, VTK image array (grids only; see `formats::open`).
    pub open: formats::OpenOptions,
    /// Time step to show first (grids and meshes; `0` for single files).
    pub step: usize,
    /// Mesh point array to draw (`None`: the first one).
    pub field: Option<String>,
    /// Cell intersector (grids and `.isot`).
    pub intersector: Intersector,
    /// BVH builder and leaf size (meshes).
    pub bvh: BvhOptions,
    /// Shading normals (`None`: the kind's default, smooth for grids and `.isot`, faceted
    /// for meshes).
    pub normals: Option<Normals>,
    /// Rays per packet of the mesh traversal, `1..=256` (256 = 16×16, 4 = 2×2).
    pub packet_rays: usize,
    /// Out-of-core loader options (memory budget).
    pub ooc: OocOptions,
}

impl Default for SceneOptions {
    fn default() -> Self {
        Self {
            open: formats::OpenOptions::default(),
            step: 0,
            field: None,
            intersector: Intersector::Exact,
            bvh: BvhOptions::default(),
            normals: None,
            packet_rays: MAX_PACKET,
            ooc: OocOptions::default(),
        }
    }
}

/// What the data holds at one world position ([`AnyScene::probe`]): picking and
/// `isoscope probe`.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Probe {
    /// The position probed, world units.
    pub world: [f64; 3],
    /// The interpolated value (trilinear in a voxel cell, linear in a tet), physical units.
    pub value: f64,
    /// The interpolant's gradient, value per world unit.
    pub gradient_world: [f64; 3],
    /// The unit normal of the level set through the position (the gradient's direction),
    /// `null` where the gradient is zero.
    pub normal: Option<[f64; 3]>,
    pub location: ProbeLocation,
}

/// Where a probed position lies in the data.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
#[serde(tag = "kind", rename_all = "lowercase")]
pub enum ProbeLocation {
    /// A volume: the continuous voxel index (`i + fraction` per axis) and the nearest voxel.
    Voxel {
        index: [f64; 3],
        nearest_voxel: [usize; 3],
    },
    /// A mesh: the tet holding the position and its barycentric coordinates.
    Tet { tet: usize, barycentric: [f64; 4] },
}

/// What one pixel of a rendered frame shows ([`AnyScene::pick`]): the viewer's picking and
/// `render --pick`.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Pick {
    /// The pixel, in the frame's own size (row 0 at the top).
    pub pixel: [u32; 2],
    /// The hit's ray parameter: world units along the unit primary ray.
    pub t: f32,
    /// The hit, world units.
    pub world: [f64; 3],
    /// The visible surface whose isovalue is nearest the value there (the one hit), as an
    /// index into the surfaces rendered.
    pub surface: Option<usize>,
    /// The data at the hit; `None` when the hit lies outside the data.
    pub probe: Option<Probe>,
}

/// A loaded scene of any kind (module docs).
#[derive(Debug)]
#[allow(clippy::large_enum_variant)] // one per open file; boxing would only add a pointer hop
pub enum AnyScene {
    Grid(GridData),
    Tet(TetData),
    Ooc(OocData),
}

/// Opens `path` as whatever it is ([`detect_kind`]) and builds its acceleration structure.
/// `.isot` files start their loader thread with the top treelet only.
pub fn open_scene(path: &Path, options: &SceneOptions) -> anyhow::Result<AnyScene> {
    open_scene_with(path, options, &OpenControl::NONE)
}

/// [`open_scene`] with progress and a cooperative cancel (the viewer's load job). The flag is
/// checked between the phases — read, value statistics, structure build — so a cancel takes
/// effect when the running phase ends; the error is then [`Cancelled`].
pub fn open_scene_with(
    path: &Path,
    options: &SceneOptions,
    control: &OpenControl<'_>,
) -> anyhow::Result<AnyScene> {
    control.checkpoint(0.0)?;
    let scene = match detect_kind(path) {
        SceneKind::Grid => GridData::open(path, options, control).map(AnyScene::Grid),
        SceneKind::Tet => TetData::open(path, options, control).map(AnyScene::Tet),
        SceneKind::Ooc => OocData::open(path, options).map(AnyScene::Ooc),
    }?;
    control.checkpoint(1.0)?;
    Ok(scene)
}

/// An open stopped by [`OpenControl::cancel`]: not a failure, nothing to report.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Cancelled;

impl std::fmt::Display for Cancelled {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("cancelled")
    }
}

impl std::error::Error for Cancelled {}

/// Progress (fraction of the phases done) and cancel for [`open_scene_with`].
#[derive(Clone, Copy)]
pub struct OpenControl<'a> {
    pub cancel: &'a AtomicBool,
    pub progress: &'a (dyn Fn(f32) + Sync),
}

static NEVER_CANCELLED: AtomicBool = AtomicBool::new(false);

impl OpenControl<'_> {
    /// No progress, never cancelled.
    pub const NONE: OpenControl<'static> = OpenControl {
        cancel: &NEVER_CANCELLED,
        progress: &|_| {},
    };

    /// Reports `fraction` and returns [`Cancelled`] if the flag is raised.
    pub fn checkpoint(&self, fraction: f32) -> anyhow::Result<()> {
        if self.cancel.load(std::sync::atomic::Ordering::Relaxed) {
            return Err(Cancelled.into());
        }
        (self.progress)(fraction);
        Ok(())
    }
}

/// True when `error` is an open stopped by its cancel flag.
pub fn is_cancelled(error: &anyhow::Error) -> bool {
    error.downcast_ref::<Cancelled>().is_some()
}

/// Renders a typed scene with [`volume_core::render::render_colored_into`] (the one
/// shading path).
#[derive(Clone, Copy)]
pub struct RenderVisitor<'a> {
    pub camera: &'a Camera,
    pub settings: &'a RenderSettings,
    /// Per surface, its resolved colouring (empty: flat colours;
    /// [`AnyScene::render`] resolves them from the settings).
    pub colorings: &'a [Option<SurfaceColoring<'a>>],
    pub cancel: &'a AtomicBool,
}

impl SceneVisitor for RenderVisitor<'_> {
    type Output = Option<Frame>;
    fn visit<S: IsoScene>(self, scene: &S) -> Option<Frame> {
        let mut frame = Frame::default();
        RenderIntoVisitor {
            camera: self.camera,
            settings: self.settings,
            colorings: self.colorings,
            cancel: self.cancel,
            frame: &mut frame,
        }
        .visit(scene)
        .then_some(frame)
    }
}

/// [`RenderVisitor`] into a caller's frame, reusing its buffers.
pub struct RenderIntoVisitor<'a> {
    pub camera: &'a Camera,
    pub settings: &'a RenderSettings,
    pub colorings: &'a [Option<SurfaceColoring<'a>>],
    pub cancel: &'a AtomicBool,
    pub frame: &'a mut Frame,
}

impl SceneVisitor for RenderIntoVisitor<'_> {
    type Output = bool;
    fn visit<S: IsoScene>(self, scene: &S) -> bool {
        render_colored_into(
            scene,
            self.camera,
            self.settings,
            self.colorings,
            self.cancel,
            self.frame,
        )
    }
}

struct BoundsVisitor;

impl SceneVisitor for BoundsVisitor {
    type Output = Aabb;
    fn visit<S: IsoScene>(self, scene: &S) -> Aabb {
        scene.world_bounds()
    }
}

/// How a time step was switched.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StepSwitch {
    /// The acceleration structure was refit in place (thesis §7.6 for grids, §8.5.2 for meshes).
    Refit,
    /// The step had another shape: the structure was rebuilt.
    Rebuilt,
    /// The scene already held that step.
    Unchanged,
}

/// What the isovalue sliders range over: the drawn values' range and histogram.
#[derive(Debug, Clone, PartialEq)]
pub struct ValueInfo {
    pub value_range: (f64, f64),
    pub histogram: Option<Histogram>,
    /// What the histogram counts (shown under it), e.g. "262144 voxels".
    pub histogram_note: String,
}

/// The render options a built scene holds and can switch in place.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ViewOptions {
    /// Cell intersector (grids and `.isot`).
    pub intersector: Intersector,
    /// Shading normals (`None`: keep the scene's).
    pub normals: Option<Normals>,
}

/// What every kind of data answers for itself. [`AnyScene`] forwards to it, so no caller
/// matches on kinds; only the typed render ([`AnyScene::visit`]) stays a `match`.
pub trait SceneData {
    fn path(&self) -> &Path;
    /// Time steps (1 for single files and `.isot`).
    fn step_count(&self) -> usize;
    /// The time step shown.
    fn step(&self) -> usize;
    /// The time of `step` as the file records it (the step index otherwise).
    fn time_value(&self, step: usize) -> f64;
    /// Smallest and largest finite value of what is drawn now; `None` if nothing is finite.
    fn value_range(&self) -> Option<(f64, f64)>;
    /// The value range and a `bins`-bin histogram of what is drawn now (scans every value,
    /// or reads the file: call from a worker); `None` without finite values.
    fn value_info(&self, bins: usize) -> Option<ValueInfo>;
    /// Grid dims in voxels (`[0; 3]` for meshes).
    fn dims(&self) -> [usize; 3];
    /// The anatomical frame of world coordinates (RAS, LPS), for orientation labels and view
    /// presets; unknown for meshes and files that do not say.
    fn world_frame(&self) -> volume_core::WorldFrame {
        volume_core::WorldFrame::Unknown
    }
    /// Loads `step`'s data ahead of time (shared access, so frames keep rendering), so that
    /// a later [`Self::set_step`] only refits.
    fn prefetch(&self, step: usize) -> anyhow::Result<()>;
    /// Makes `step` current: a refit where the structure allows.
    fn set_step(&mut self, step: usize) -> anyhow::Result<StepSwitch>;
    /// True when the scene already renders with `options`.
    fn has_view_options(&self, options: &ViewOptions) -> bool;
    fn set_view_options(&mut self, options: &ViewOptions);
    /// The options it renders with (the one a kind does not use at its default).
    fn view_options(&self) -> ViewOptions;
    /// Time to build the acceleration structure (the `.isot` open time for out-of-core).
    fn build_time(&self) -> Duration;
    /// Bytes of the acceleration structure (kd-tree, BVH nodes) or of the resident treelets.
    fn structure_bytes(&self) -> u64;
    /// One line for status bars and logs.
    fn describe(&self) -> String;
    /// Meshes: the point arrays that can be drawn (none for other kinds).
    fn field_names(&self) -> Vec<&str> {
        Vec::new()
    }
    /// Meshes: the drawn point array.
    fn field(&self) -> Option<&str> {
        None
    }
    /// Meshes: draws another point array (a value refit, no rebuild).
    fn set_field(&mut self, name: &str) -> anyhow::Result<()> {
        bail!("point array \"{name}\": only tet meshes have point arrays")
    }
    /// Out-of-core loader progress; `None` for in-core data.
    fn loader_status(&self) -> Option<OocStatus> {
        None
    }
}

/// ", step 3 of 8" for series, nothing for single data sets.
fn step_suffix(data: &dyn SceneData) -> String {
    let steps = data.step_count();
    if steps > 1 {
        format!(", step {} of {steps}", data.step())
    } else {
        String::new()
    }
}

impl AnyScene {
    pub fn kind(&self) -> SceneKind {
        match self {
            AnyScene::Grid(_) => SceneKind::Grid,
            AnyScene::Tet(_) => SceneKind::Tet,
            AnyScene::Ooc(_) => SceneKind::Ooc,
        }
    }

    /// The kind's own answers ([`SceneData`]).
    pub fn data(&self) -> &dyn SceneData {
        match self {
            AnyScene::Grid(g) => g,
            AnyScene::Tet(t) => t,
            AnyScene::Ooc(o) => o,
        }
    }

    pub fn data_mut(&mut self) -> &mut dyn SceneData {
        match self {
            AnyScene::Grid(g) => g,
            AnyScene::Tet(t) => t,
            AnyScene::Ooc(o) => o,
        }
    }

    pub fn path(&self) -> &Path {
        self.data().path()
    }

    pub fn as_grid(&self) -> Option<&GridData> {
        match self {
            AnyScene::Grid(g) => Some(g),
            _ => None,
        }
    }

    pub fn as_tet(&self) -> Option<&TetData> {
        match self {
            AnyScene::Tet(t) => Some(t),
            _ => None,
        }
    }

    pub fn as_tet_mut(&mut self) -> Option<&mut TetData> {
        match self {
            AnyScene::Tet(t) => Some(t),
            _ => None,
        }
    }

    pub fn as_ooc(&self) -> Option<&OocData> {
        match self {
            AnyScene::Ooc(o) => Some(o),
            _ => None,
        }
    }

    /// Hands the typed scene (kd-tree, BVH, or this frame's out-of-core snapshot) to
    /// `visitor`: the generic code runs monomorphized for the concrete scene type.
    pub fn visit<V: SceneVisitor>(&self, visitor: V) -> V::Output {
        match self {
            AnyScene::Grid(g) => g.scene.visit(visitor),
            AnyScene::Tet(t) => visitor.visit(&t.scene),
            AnyScene::Ooc(o) => o.volume.visit_scene(o.intersector, o.normals, visitor),
        }
    }

    /// Renders one frame (`None` if `cancel` was set). Out-of-core scenes first request the
    /// treelets of the active isovalues, then draw what is loaded (module docs). Surfaces
    /// with a [`volume_core::render::ColorBy`] are coloured by their field; one that does
    /// not resolve (check with [`AnyScene::check_colorings`] first) keeps its flat colour.
    ///
    /// In an MPI job ([`crate::distributed`]), rank 0's frames of the input every rank opened
    /// are rendered across the ranks; the picture is the same.
    pub fn render(
        &self,
        camera: &Camera,
        settings: &RenderSettings,
        cancel: &AtomicBool,
    ) -> Option<Frame> {
        if let Some(frame) = crate::distributed::render_if_served(self, camera, settings, cancel) {
            return frame;
        }
        let mut frame = Frame::default();
        self.render_local_into(camera, settings, cancel, &mut frame)
            .then_some(frame)
    }

    /// Renders in this process into `frame`, reusing its buffers (`false` if `cancel` was
    /// set). With [`RenderSettings::region`] only that part of `frame` is written, which is
    /// how an MPI rank renders its chunks.
    pub fn render_local_into(
        &self,
        camera: &Camera,
        settings: &RenderSettings,
        cancel: &AtomicBool,
        frame: &mut Frame,
    ) -> bool {
        if let AnyScene::Ooc(o) = self {
            o.set_isovalues(&settings.active_isovalues().0);
        }
        let resolved = self.resolve_colorings(settings);
        let colorings = crate::coloring::as_colorings(&resolved);
        self.visit(RenderIntoVisitor {
            camera,
            settings,
            colorings: &colorings,
            cancel,
            frame,
        })
    }

    /// [`Self::render`], with the finest out-of-core level the frame reached (`None` for
    /// in-core data).
    pub fn render_with_level(
        &self,
        camera: &Camera,
        settings: &RenderSettings,
        cancel: &AtomicBool,
    ) -> Option<(Frame, Option<usize>)> {
        match self {
            AnyScene::Ooc(o) => {
                if let Some(frame) =
                    crate::distributed::render_if_served(self, camera, settings, cancel)
                {
                    // Every rank drew from at least rank 0's levels, which the frame reports.
                    let level = o.volume.current_level(o.intersector);
                    return frame.map(|f| (f, Some(level)));
                }
                o.render_with_level(camera, settings, cancel)
                    .map(|(f, level)| (f, Some(level)))
            }
            s => s.render(camera, settings, cancel).map(|f| (f, None)),
        }
    }

    /// World-space bounds of the data.
    pub fn world_bounds(&self) -> Aabb {
        self.visit(BoundsVisitor)
    }

    /// Smallest and largest finite value of the current step (grids, `.isot`) or of the drawn
    /// array at the current step (meshes); `None` if nothing is finite.
    pub fn value_range(&self) -> Option<(f64, f64)> {
        self.data().value_range()
    }

    /// What the data holds at `world` (the current step and array): the interpolated value,
    /// its gradient and where it lies (voxel index or tet); `None` outside the data. `.isot`
    /// files are not probed (their finest voxels may not be resident): an error says so.
    pub fn probe(&self, world: glam::DVec3) -> anyhow::Result<Option<Probe>> {
        let (value, gradient, location) = match self {
            AnyScene::Grid(g) => {
                let Some(p) = g.volume().probe_world(world) else {
                    return Ok(None);
                };
                let location = ProbeLocation::Voxel {
                    index: p.index.to_array(),
                    nearest_voxel: p.nearest_voxel,
                };
                (p.value, p.gradient_world, location)
            }
            AnyScene::Tet(t) => {
                let Some(values) = t.field_values() else {
                    bail!("{}: no point array to probe", t.path.display());
                };
                let points = t.scene().points();
                let tets = &t.loaded().mesh.tets;
                let Some(p) = volume_core::tet::probe_tets(&points, tets, values, world) else {
                    return Ok(None);
                };
                let location = ProbeLocation::Tet {
                    tet: p.tet,
                    barycentric: p.barycentric,
                };
                (p.value, p.gradient_world, location)
            }
            AnyScene::Ooc(o) => bail!(
                "{}: probing an .isot file is not supported (its finest voxels may not be in \
                 memory): probe the volume it was made from",
                o.path.display()
            ),
        };
        Ok(Some(Probe {
            world: world.to_array(),
            value,
            gradient_world: gradient.to_array(),
            normal: gradient.try_normalize().map(|n| n.to_array()),
            location,
        }))
    }

    /// What pixel `pixel` of a frame of `size` pixels seen by `camera` shows, given the
    /// frame's depth `t` there (infinite: no hit, `None`): the hit's world position, the data
    /// there ([`Self::probe`]) and which of `surfaces` it lies on.
    pub fn pick(
        &self,
        camera: &Camera,
        surfaces: &[Surface],
        size: [u32; 2],
        pixel: [u32; 2],
        t: f32,
    ) -> anyhow::Result<Option<Pick>> {
        if !t.is_finite() {
            return Ok(None);
        }
        let ray = camera.primary_ray(pixel[0], pixel[1], size[0], size[1]);
        let to_f64 = |v: glam::Vec3| glam::DVec3::from(v.to_array().map(f64::from));
        let world = to_f64(ray.origin) + to_f64(ray.dir) * f64::from(t);
        let probe = self.probe(world)?;
        let surface = probe.and_then(|p| {
            surfaces
                .iter()
                .enumerate()
                .filter(|(_, s)| s.is_active())
                .min_by(|(_, a), (_, b)| {
                    let d = |s: &Surface| (f64::from(s.isovalue) - p.value).abs();
                    d(a).total_cmp(&d(b))
                })
                .map(|(i, _)| i)
        });
        Ok(Some(Pick {
            pixel,
            t,
            world: world.to_array(),
            surface,
            probe,
        }))
    }

    /// How the values drawn read ([`crate::values::ValueFormat`]): the voxel type through
    /// its value map; mesh arrays are `f32`.
    pub fn value_format(&self) -> crate::values::ValueFormat {
        use crate::values::ValueFormat;
        match self {
            AnyScene::Grid(g) => {
                let v = g.volume();
                ValueFormat::of(v.data.voxel_type(), Some(&v.value_map))
            }
            AnyScene::Tet(_) => ValueFormat::F32,
            AnyScene::Ooc(o) => {
                let meta = o.volume().meta();
                ValueFormat::of(meta.voxel_type, Some(&meta.value_map))
            }
        }
    }

    /// The middle of [`Self::value_range`]: the isovalue shown when none is given.
    pub fn default_isovalue(&self) -> Option<f32> {
        self.value_range().map(|(lo, hi)| (0.5 * (lo + hi)) as f32)
    }

    /// Time steps (1 for single files and `.isot`).
    pub fn step_count(&self) -> usize {
        self.data().step_count()
    }

    pub fn step(&self) -> usize {
        self.data().step()
    }

    /// The time of `step` as the file records it (the step index otherwise).
    pub fn time_value(&self, step: usize) -> f64 {
        self.data().time_value(step)
    }

    /// Switches to another time step: a refit, not a rebuild, where the shape allows.
    pub fn set_step(&mut self, step: usize) -> anyhow::Result<StepSwitch> {
        self.data_mut().set_step(step)
    }

    /// Time to build the acceleration structure (the `.isot` open time for out-of-core).
    pub fn build_time(&self) -> Duration {
        self.data().build_time()
    }

    /// Bytes of the acceleration structure (kd-tree, BVH nodes) or of the resident treelets.
    pub fn structure_bytes(&self) -> u64 {
        self.data().structure_bytes()
    }

    /// One line for status bars and logs, e.g. `tet mesh: 12000 tets, 2400 points, field
    /// "distance"`.
    pub fn describe(&self) -> String {
        self.data().describe()
    }
}

fn check_step(step: usize, count: usize, path: &Path) -> anyhow::Result<()> {
    if step >= count {
        if count == 1 {
            bail!(
                "time step {step}: {} is a single data set, not a time series",
                path.display()
            );
        }
        bail!(
            "time step {step}: {} has {count} time steps (0..{})",
            path.display(),
            count - 1
        );
    }
    Ok(())
}

// ---------------------------------------------------------------------------------------
// Grids

/// A rectilinear volume (one step of a series) and its kd-tree.
pub struct GridData {
    path: PathBuf,
    /// The current step's volume (voxels shared with the scene, not copied).
    volume: RectilinearVolume,
    series: Option<TimeSeries>,
    step: usize,
    scene: AnyGridScene,
    value_range: Option<(f64, f64)>,
    /// How the file was opened (to re-read it with another array).
    open: formats::OpenOptions,
    /// VTK image data: the scalar point arrays and the one drawn.
    arrays: Vec<String>,
    field: Option<String>,
    /// Volumes on the same grid that surfaces can be coloured by, by name.
    color_volumes: Vec<ColorVolume>,
    /// The gradient magnitude's range over the current step (computed on first use).
    gradient_range: OnceLock<Option<(f64, f64)>>,
}

/// A volume to colour a grid's surfaces by ([`GridData::add_color_volume`]).
#[derive(Debug)]
pub struct ColorVolume {
    /// The name it was added under (the path as given).
    pub name: String,
    pub sampler: VolumeSampler,
    /// Its finite physical value range.
    pub value_range: Option<(f64, f64)>,
}

impl std::fmt::Debug for GridData {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("GridData")
            .field("path", &self.path)
            .field("step", &self.step)
            .field(
                "steps",
                &self.series.as_ref().map_or(1, TimeSeries::step_count),
            )
            .field("scene", &self.scene)
            .finish_non_exhaustive()
    }
}

impl GridData {
    fn open(
        path: &Path,
        options: &SceneOptions,
        control: &OpenControl<'_>,
    ) -> anyhow::Result<Self> {
        let (arrays, field) = image_arrays(path, &options.open)?;
        let (volume, series) = match formats::open(path, &options.open)? {
            formats::Dataset::Volume(v) => {
                check_step(options.step, 1, path)?;
                (v, None)
            }
            formats::Dataset::Series(s) => {
                check_step(options.step, s.step_count(), path)?;
                let v = s.step(options.step).with_context(|| {
                    format!("loading time step {} of {}", options.step, path.display())
                })?;
                (v, Some(s))
            }
        };
        control.checkpoint(0.5)?;
        let value_range = volume.value_stats().finite_range;
        control.checkpoint(0.6)?;
        let mut scene = AnyGridScene::new(&volume, options.intersector);
        if let Some(normals) = options.normals {
            scene.set_normals(normals);
        }
        Ok(Self {
            path: path.to_path_buf(),
            volume,
            series,
            step: options.step,
            scene,
            value_range,
            open: options.open.clone(),
            arrays,
            field,
            color_volumes: Vec::new(),
            gradient_range: OnceLock::new(),
        })
    }

    /// Wraps an already loaded volume (e.g. a generated sample) as a grid scene.
    pub fn from_volume(path: &Path, volume: RectilinearVolume, intersector: Intersector) -> Self {
        let scene = AnyGridScene::new(&volume, intersector);
        let value_range = volume.value_stats().finite_range;
        Self {
            path: path.to_path_buf(),
            volume,
            series: None,
            step: 0,
            scene,
            value_range,
            open: formats::OpenOptions::default(),
            arrays: Vec::new(),
            field: None,
            color_volumes: Vec::new(),
            gradient_range: OnceLock::new(),
        }
    }

    pub fn volume(&self) -> &RectilinearVolume {
        &self.volume
    }

    pub fn scene(&self) -> &AnyGridScene {
        &self.scene
    }

    pub fn series(&self) -> Option<&TimeSeries> {
        self.series.as_ref()
    }

    /// Re-reads the voxels in place after their memory changed (a volume viewing memory it
    /// does not own, such as a numpy array): value range and a kd-tree refit, no rebuild.
    pub fn refresh(&mut self) -> StepSwitch {
        let switch = update_grid_scene(&mut self.scene, &self.volume);
        self.value_range = self.volume.value_stats().finite_range;
        self.gradient_range = OnceLock::new();
        switch
    }

    /// The range of the drawn field's gradient magnitude (computed once per step, scanning
    /// every voxel).
    pub fn gradient_range(&self) -> Option<(f64, f64)> {
        *self
            .gradient_range
            .get_or_init(|| self.scene.gradient_magnitude_range())
    }

    /// The volumes added to colour surfaces by.
    pub fn color_volumes(&self) -> &[ColorVolume] {
        &self.color_volumes
    }

    /// The colour volume added as `name`.
    pub fn color_volume(&self, name: &str) -> Option<&ColorVolume> {
        self.color_volumes.iter().find(|v| v.name == name)
    }

    /// Opens `path` as a volume to colour surfaces by, refusing one whose dims or geometry
    /// differ from this volume's; returns the name to colour by (the path as given). Adding
    /// a name again reloads it.
    pub fn add_color_volume(&mut self, path: &Path) -> anyhow::Result<String> {
        let (name, volume) = read_color_volume(path)?;
        self.set_color_volume(&name, volume)?;
        Ok(name)
    }

    /// Adds `volume` (already in memory) as the colour volume `name`; see
    /// [`Self::add_color_volume`].
    pub fn set_color_volume(
        &mut self,
        name: &str,
        volume: RectilinearVolume,
    ) -> anyhow::Result<()> {
        crate::coloring::check_same_grid(&self.volume.grid, &volume.grid).with_context(|| {
            format!(
                "{name} cannot colour {}: it must have the same dims and geometry",
                self.path.display()
            )
        })?;
        let value_range = volume.value_stats().finite_range;
        let entry = ColorVolume {
            name: name.to_owned(),
            sampler: VolumeSampler::new(volume),
            value_range,
        };
        match self.color_volumes.iter_mut().find(|v| v.name == name) {
            Some(v) => *v = entry,
            None => self.color_volumes.push(entry),
        }
        Ok(())
    }

    /// Loads `step` through the series (which caches it) after checking its range.
    fn load_step(&self, step: usize) -> anyhow::Result<Option<RectilinearVolume>> {
        let Some(series) = &self.series else {
            check_step(step, 1, &self.path)?;
            return Ok(None);
        };
        check_step(step, series.step_count(), &self.path)?;
        let v = series
            .step(step)
            .with_context(|| format!("loading time step {step} of {}", self.path.display()))?;
        Ok(Some(v))
    }
}

/// Reads `path` as one volume to colour surfaces by ([`GridData::set_color_volume`] checks
/// its grid): the name to colour by (the path as given) and the volume.
pub fn read_color_volume(path: &Path) -> anyhow::Result<(String, RectilinearVolume)> {
    let name = path.display().to_string();
    match formats::open(path, &formats::OpenOptions::default())? {
        formats::Dataset::Volume(v) => Ok((name, v)),
        formats::Dataset::Series(_) => {
            bail!("{name}: a time series cannot colour a surface: give one volume on the same grid")
        }
    }
}

/// VTK image data (a file, or the first file of a pattern): its scalar point arrays and the
/// one `open` reads; nothing for other files.
fn image_arrays(
    path: &Path,
    open: &formats::OpenOptions,
) -> anyhow::Result<(Vec<String>, Option<String>)> {
    let file = if !path.exists() && formats::series::is_pattern(path) {
        match formats::series::expand_pattern(path) {
            Ok(files) => files.into_iter().next(),
            // `formats::open` reports the pattern's error.
            Err(_) => None,
        }
    } else {
        Some(path.to_path_buf())
    };
    let Some(file) = file.filter(|f| formats::vtk_image::is_image_file(f)) else {
        return Ok((Vec::new(), None));
    };
    let arrays = formats::vtk_image::point_arrays(&file)?;
    let field = open
        .field
        .clone()
        .or_else(|| arrays.default_name().map(str::to_owned));
    Ok((arrays.scalar_names(), field))
}

/// Puts `volume` into `scene`: a refit when dims and voxel type stay, else a rebuild
/// (`update_volume` decides and says which).
fn update_grid_scene(scene: &mut AnyGridScene, volume: &RectilinearVolume) -> StepSwitch {
    match scene.update_volume(volume) {
        volume_core::grid::StepSwitch::Refit => StepSwitch::Refit,
        volume_core::grid::StepSwitch::Rebuild => StepSwitch::Rebuilt,
    }
}

impl SceneData for GridData {
    fn path(&self) -> &Path {
        &self.path
    }

    fn step_count(&self) -> usize {
        self.series.as_ref().map_or(1, TimeSeries::step_count)
    }

    fn step(&self) -> usize {
        self.step
    }

    fn time_value(&self, step: usize) -> f64 {
        self.series
            .as_ref()
            .map_or(step as f64, |s| s.time_value(step))
    }

    fn value_range(&self) -> Option<(f64, f64)> {
        self.value_range
    }

    fn value_info(&self, bins: usize) -> Option<ValueInfo> {
        let (lo, hi) = self.value_range?;
        let d = self.volume.dims();
        Some(ValueInfo {
            value_range: (lo, hi),
            histogram: Some(self.volume.histogram(lo, hi, bins)),
            histogram_note: format!("all {}×{}×{} voxels of the step shown", d[0], d[1], d[2]),
        })
    }

    fn dims(&self) -> [usize; 3] {
        self.volume.dims()
    }

    fn world_frame(&self) -> volume_core::WorldFrame {
        self.volume.grid.world_frame()
    }

    fn prefetch(&self, step: usize) -> anyhow::Result<()> {
        self.load_step(step).map(|_| ())
    }

    fn set_step(&mut self, step: usize) -> anyhow::Result<StepSwitch> {
        if step == self.step {
            check_step(step, self.step_count(), &self.path)?;
            return Ok(StepSwitch::Unchanged);
        }
        let Some(v) = self.load_step(step)? else {
            return Ok(StepSwitch::Unchanged);
        };
        let switch = update_grid_scene(&mut self.scene, &v);
        self.value_range = v.value_stats().finite_range;
        self.gradient_range = OnceLock::new();
        self.volume = v;
        self.step = step;
        Ok(switch)
    }

    fn has_view_options(&self, options: &ViewOptions) -> bool {
        self.scene.intersector() == options.intersector
            && options.normals.is_none_or(|n| n == self.scene.normals())
    }

    fn set_view_options(&mut self, options: &ViewOptions) {
        self.scene.set_intersector(options.intersector);
        if let Some(normals) = options.normals {
            self.scene.set_normals(normals);
        }
    }

    fn view_options(&self) -> ViewOptions {
        ViewOptions {
            intersector: self.scene.intersector(),
            normals: Some(self.scene.normals()),
        }
    }

    fn build_time(&self) -> Duration {
        self.scene.build_time()
    }

    fn structure_bytes(&self) -> u64 {
        self.scene.memory_bytes() as u64
    }

    fn describe(&self) -> String {
        let d = self.volume.dims();
        format!(
            "grid {}x{}x{} {}{}{}",
            d[0],
            d[1],
            d[2],
            self.volume.data.voxel_type(),
            self.field
                .as_ref()
                .map(|f| format!(", array \"{f}\""))
                .unwrap_or_default(),
            step_suffix(self)
        )
    }

    fn field_names(&self) -> Vec<&str> {
        self.arrays.iter().map(String::as_str).collect()
    }

    fn field(&self) -> Option<&str> {
        self.field.as_deref()
    }

    /// Re-reads the file with the point array `name` (VTK image data) at the current step.
    fn set_field(&mut self, name: &str) -> anyhow::Result<()> {
        if !self.arrays.iter().any(|a| a == name) {
            bail!(
                "{}: no scalar point array \"{name}\"{}",
                self.path.display(),
                if self.arrays.is_empty() {
                    " (only VTK image data and meshes have named arrays)".to_owned()
                } else {
                    format!("; it has {}", self.arrays.join(", "))
                }
            );
        }
        let open = formats::OpenOptions {
            field: Some(name.to_owned()),
            ..self.open.clone()
        };
        let (volume, series) = match formats::open(&self.path, &open)? {
            formats::Dataset::Volume(v) => (v, None),
            formats::Dataset::Series(s) => {
                let v = s.step(self.step).with_context(|| {
                    format!("loading time step {} of {}", self.step, self.path.display())
                })?;
                (v, Some(s))
            }
        };
        update_grid_scene(&mut self.scene, &volume);
        self.value_range = volume.value_stats().finite_range;
        self.gradient_range = OnceLock::new();
        self.volume = volume;
        self.series = series;
        self.open = open;
        self.field = Some(name.to_owned());
        Ok(())
    }
}

// ---------------------------------------------------------------------------------------
// Tetrahedral meshes

/// A tetrahedral mesh (one step of a series), the drawn point array and its BVH.
#[derive(Debug)]
pub struct TetData {
    path: PathBuf,
    /// Step 0 as read (reference topology, all arrays, skipped-cell counts).
    loaded: LoadedMesh,
    series: Option<MeshSeries>,
    step: usize,
    /// The current step's arrays (step 0: `loaded.mesh.fields`).
    step_fields: Vec<PointField>,
    /// The current step moved points away from the reference positions.
    moved: bool,
    field: String,
    scene: TetScene,
    build_time: Duration,
    /// Steps read ahead (prefetched) or recently shown: a step switch then only refits.
    step_cache: Mutex<StepCache>,
}

/// Mesh steps read ahead: `(step, data)`, oldest first.
type StepCache = VecDeque<(usize, Arc<StepData>)>;

/// Mesh steps kept in the step cache (the current one plus those ahead).
const MESH_STEP_CACHE: usize = 4;

impl TetData {
    fn open(
        path: &Path,
        options: &SceneOptions,
        control: &OpenControl<'_>,
    ) -> anyhow::Result<Self> {
        let series =
            if formats::mesh::MeshFormat::from_path(path) == Some(formats::mesh::MeshFormat::Pvd) {
                Some(formats::mesh::read_pvd(path)?)
            } else if !path.exists() && formats::series::is_pattern(path) {
                Some(MeshSeries::from_files(formats::series::expand_pattern(
                    path,
                )?))
            } else {
                None
            };
        let (loaded, count) = match &series {
            Some(s) => {
                if s.is_empty() {
                    bail!("{}: the series has no steps", path.display());
                }
                (s.load_step(0)?, s.len())
            }
            None => (formats::mesh::read_mesh(path)?, 1),
        };
        check_step(options.step, count, path)?;
        control.checkpoint(0.5)?;
        Self::build(path, loaded, series, options, control)
    }

    /// Wraps a mesh already in memory (e.g. arrays from Python) as a mesh scene named `path`
    /// in messages: the same field choice and BVH build as a file.
    pub fn from_loaded(
        path: &Path,
        loaded: LoadedMesh,
        options: &SceneOptions,
    ) -> anyhow::Result<Self> {
        check_step(options.step, 1, path)?;
        Self::build(path, loaded, None, options, &OpenControl::NONE)
    }

    /// Picks the drawn array and builds the BVH of step `options.step` (checked).
    fn build(
        path: &Path,
        loaded: LoadedMesh,
        series: Option<MeshSeries>,
        options: &SceneOptions,
        control: &OpenControl<'_>,
    ) -> anyhow::Result<Self> {
        let mesh = &loaded.mesh;
        let field = if let Some(f) = &options.field {
            f.clone()
        } else if let Some(f) = mesh.fields.first() {
            f.name.clone()
        } else {
            let skipped: Vec<String> = loaded
                .skipped_arrays
                .iter()
                .map(|(n, why)| format!("{n} ({why})"))
                .collect();
            bail!(
                "{}: the mesh has no scalar point array to draw an isosurface of{}",
                path.display(),
                if skipped.is_empty() {
                    String::new()
                } else {
                    format!("; skipped arrays: {}", skipped.join(", "))
                }
            );
        };
        mesh.require_field(&field)
            .with_context(|| format!("{}: --field", path.display()))?;
        let (positions, step_fields) = match (&series, options.step) {
            (Some(s), step) if step > 0 => {
                let data = s.load_step_data(step, mesh)?;
                (data.positions, data.fields)
            }
            _ => (None, mesh.fields.clone()),
        };
        let values = step_field(&step_fields, &field, options.step, path)?;
        let moved = positions.is_some();
        control.checkpoint(0.6)?;
        let points = positions.as_deref().unwrap_or(&mesh.points);
        let t0 = Instant::now();
        let mut scene = TetScene::from_parts(points, mesh.tets.clone(), values, options.bvh)
            .with_context(|| format!("{}: building the BVH", path.display()))?;
        let build_time = t0.elapsed();
        if let Some(normals) = options.normals {
            scene.set_normals(normals);
        }
        scene.set_packet_size(options.packet_rays);
        Ok(Self {
            path: path.to_path_buf(),
            loaded,
            series,
            step: options.step,
            step_fields,
            moved,
            field,
            scene,
            build_time,
            step_cache: Mutex::new(VecDeque::new()),
        })
    }

    pub fn scene(&self) -> &TetScene {
        &self.scene
    }

    /// Step 0 as read: all point arrays, the reference topology, skipped cells.
    pub fn loaded(&self) -> &LoadedMesh {
        &self.loaded
    }

    pub fn series(&self) -> Option<&MeshSeries> {
        self.series.as_ref()
    }

    /// The drawn point array.
    pub fn field(&self) -> &str {
        &self.field
    }

    /// Names of the point arrays that can be drawn.
    pub fn field_names(&self) -> Vec<&str> {
        self.step_fields.iter().map(|f| f.name.as_str()).collect()
    }

    /// BVH build time at open.
    pub fn build_time(&self) -> Duration {
        self.build_time
    }

    /// Range of the drawn array at the current step.
    pub fn value_range(&self) -> Option<(f64, f64)> {
        self.step_fields
            .iter()
            .find(|f| f.name == self.field)
            .and_then(PointField::value_range)
            .map(|(a, b)| (f64::from(a), f64::from(b)))
    }

    /// Draws another point array: only the BVH's value ranges are refit.
    pub fn set_field(&mut self, name: &str) -> anyhow::Result<()> {
        let values = step_field(&self.step_fields, name, self.step, &self.path)?;
        self.scene.refit_scalars(values)?;
        name.clone_into(&mut self.field);
        Ok(())
    }

    pub fn set_normals(&mut self, normals: Normals) {
        self.scene.set_normals(normals);
    }

    /// Rays per traversal packet, `1..=256` (256 = 16×16, 4 = 2×2).
    pub fn set_packet_rays(&mut self, rays: usize) {
        self.scene.set_packet_size(rays);
    }

    /// Rebuilds the BVH with other options (e.g. the SAH builder); returns the build time.
    pub fn rebuild(&mut self, bvh: BvhOptions) -> Duration {
        let t0 = Instant::now();
        self.scene.rebuild(bvh);
        t0.elapsed()
    }

    /// The time step shown.
    pub fn step(&self) -> usize {
        self.step
    }

    /// The drawn array's values at the current step (one per point).
    pub fn field_values(&self) -> Option<&[f32]> {
        self.step_fields
            .iter()
            .find(|f| f.name == self.field)
            .map(|f| f.values.as_slice())
    }

    /// The point array `name` at the current step (any array, not only the drawn one).
    pub fn step_field(&self, name: &str) -> Option<&PointField> {
        self.step_fields.iter().find(|f| f.name == name)
    }

    /// Reads `step`'s arrays and positions (step 0: the arrays as read at open). Touches no
    /// state, so it can run ahead of time (prefetching) while the scene renders.
    pub fn load_step_data(&self, step: usize) -> anyhow::Result<StepData> {
        let count = self.series.as_ref().map_or(1, MeshSeries::len);
        check_step(step, count, &self.path)?;
        match &self.series {
            Some(series) if step > 0 => Ok(series.load_step_data(step, &self.loaded.mesh)?),
            _ => Ok(StepData {
                time: self
                    .series
                    .as_ref()
                    .and_then(|s| s.steps.first())
                    .map_or(0.0, |s| s.time),
                positions: None,
                fields: self.loaded.mesh.fields.clone(),
            }),
        }
    }

    /// Makes `step` current from its already loaded `data` (see [`Self::load_step_data`]):
    /// refits the BVH (values, then positions when they moved) and updates the step, the
    /// drawn array's values and so [`Self::value_range`] and [`Self::field_values`].
    pub fn set_step_from(&mut self, step: usize, data: &StepData) -> anyhow::Result<()> {
        let count = self.series.as_ref().map_or(1, MeshSeries::len);
        check_step(step, count, &self.path)?;
        let values = step_field(&data.fields, &self.field, step, &self.path)?;
        // Values first (cheap refit of the ranges), then positions if they changed.
        self.scene.refit_scalars(values)?;
        match &data.positions {
            Some(p) => {
                self.scene.refit_positions(p)?;
                self.moved = true;
            }
            None if self.moved => {
                self.scene.refit_positions(&self.loaded.mesh.points)?;
                self.moved = false;
            }
            None => {}
        }
        self.step_fields.clone_from(&data.fields);
        self.step = step;
        Ok(())
    }

    /// `step`'s data from the step cache, or read now and kept there (the oldest of
    /// [`MESH_STEP_CACHE`] entries goes).
    fn cached_step_data(&self, step: usize) -> anyhow::Result<Arc<StepData>> {
        let cached = |cache: &StepCache| {
            cache
                .iter()
                .find(|(s, _)| *s == step)
                .map(|(_, d)| Arc::clone(d))
        };
        if let Some(d) = cached(&self.lock_step_cache()) {
            return Ok(d);
        }
        // Read without holding the lock: a prefetch may read another step meanwhile.
        let data = Arc::new(self.load_step_data(step)?);
        let mut cache = self.lock_step_cache();
        cache.retain(|(s, _)| *s != step);
        if cache.len() >= MESH_STEP_CACHE {
            cache.pop_front();
        }
        cache.push_back((step, Arc::clone(&data)));
        Ok(data)
    }

    fn lock_step_cache(&self) -> std::sync::MutexGuard<'_, StepCache> {
        // The cache holds only finished reads: one left by a panicked thread is still valid.
        self.step_cache
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }
}

impl SceneData for TetData {
    fn path(&self) -> &Path {
        &self.path
    }

    fn step_count(&self) -> usize {
        self.series.as_ref().map_or(1, MeshSeries::len)
    }

    fn step(&self) -> usize {
        self.step
    }

    fn time_value(&self, step: usize) -> f64 {
        self.series
            .as_ref()
            .and_then(|s| s.steps.get(step))
            .map_or(step as f64, |s| s.time)
    }

    fn value_range(&self) -> Option<(f64, f64)> {
        TetData::value_range(self)
    }

    fn value_info(&self, bins: usize) -> Option<ValueInfo> {
        let (lo, hi) = TetData::value_range(self)?;
        let values = self.field_values()?;
        Some(ValueInfo {
            value_range: (lo, hi),
            histogram: Some(Histogram::compute(values, lo, hi, bins)),
            histogram_note: format!(
                "the {} point values of \"{}\" at the step shown",
                values.len(),
                self.field
            ),
        })
    }

    fn dims(&self) -> [usize; 3] {
        [0; 3]
    }

    fn prefetch(&self, step: usize) -> anyhow::Result<()> {
        self.cached_step_data(step).map(|_| ())
    }

    fn set_step(&mut self, step: usize) -> anyhow::Result<StepSwitch> {
        if step == self.step {
            check_step(step, SceneData::step_count(self), &self.path)?;
            return Ok(StepSwitch::Unchanged);
        }
        let data = self.cached_step_data(step)?;
        self.set_step_from(step, &data)?;
        Ok(StepSwitch::Refit)
    }

    fn has_view_options(&self, options: &ViewOptions) -> bool {
        options.normals.is_none_or(|n| n == self.scene.normals())
    }

    fn set_view_options(&mut self, options: &ViewOptions) {
        if let Some(normals) = options.normals {
            self.scene.set_normals(normals);
        }
    }

    fn view_options(&self) -> ViewOptions {
        ViewOptions {
            intersector: Intersector::default(),
            normals: Some(self.scene.normals()),
        }
    }

    fn build_time(&self) -> Duration {
        self.build_time
    }

    fn structure_bytes(&self) -> u64 {
        self.scene.bvh_info().bytes as u64
    }

    fn describe(&self) -> String {
        format!(
            "tet mesh: {} tets, {} points, field \"{}\"{}",
            self.scene.num_tets(),
            self.scene.num_points(),
            self.field,
            step_suffix(self)
        )
    }

    fn field_names(&self) -> Vec<&str> {
        TetData::field_names(self)
    }

    fn field(&self) -> Option<&str> {
        Some(&self.field)
    }

    fn set_field(&mut self, name: &str) -> anyhow::Result<()> {
        TetData::set_field(self, name)
    }
}

fn step_field<'a>(
    fields: &'a [PointField],
    name: &str,
    step: usize,
    path: &Path,
) -> anyhow::Result<&'a [f32]> {
    if let Some(f) = fields.iter().find(|f| f.name == name) {
        return Ok(&f.values);
    }
    let names: Vec<&str> = fields.iter().map(|f| f.name.as_str()).collect();
    bail!(
        "{}: time step {step} has no point array \"{name}\" (available: {})",
        path.display(),
        names.join(", ")
    )
}

// ---------------------------------------------------------------------------------------
// Out-of-core

/// Loader progress of an `.isot` scene (for a level/progress indicator).
#[derive(Debug, Clone, PartialEq)]
pub struct OocStatus {
    /// Levels published for the current isovalues (1 = the top treelet only).
    pub loaded_levels: usize,
    pub level_count: usize,
    pub resident_bytes: u64,
    /// The loader is idle for the current isovalues.
    pub finished: bool,
    /// The memory budget stopped loading at a coarser level.
    pub budget_limited: bool,
    /// What stopped the last sweep (a damaged treelet, an I/O error).
    pub error: Option<String>,
}

/// An out-of-core `.isot` volume with its loader thread.
#[derive(Debug)]
pub struct OocData {
    path: PathBuf,
    volume: AnyOocVolume,
    intersector: Intersector,
    normals: Normals,
    open_time: Duration,
}

impl OocData {
    fn open(path: &Path, options: &SceneOptions) -> anyhow::Result<Self> {
        if options.step != 0 {
            check_step(options.step, 1, path)?;
        }
        let t0 = Instant::now();
        let volume = formats::treelet::open_isot(path, options.ooc)?;
        Ok(Self {
            path: path.to_path_buf(),
            volume,
            intersector: options.intersector,
            normals: options.normals.unwrap_or(Normals::Smooth),
            open_time: t0.elapsed(),
        })
    }

    pub fn volume(&self) -> &AnyOocVolume {
        &self.volume
    }

    pub fn intersector(&self) -> Intersector {
        self.intersector
    }

    /// Time to open the file and load the top treelet.
    pub fn open_time(&self) -> Duration {
        self.open_time
    }

    /// The finite value range recorded in the file (the quantizer's range), physical.
    pub fn value_range(&self) -> Option<(f64, f64)> {
        let meta = self.volume.meta();
        let q = &meta.quantizer;
        (q.lo.is_finite() && q.hi.is_finite() && q.lo <= q.hi)
            .then(|| meta.value_map.range_to_physical((q.lo, q.hi)))
    }

    /// Requests the treelets of `isovalues` (same quantized bucket: no reload).
    pub fn set_isovalues(&self, isovalues: &[f32]) {
        self.volume.set_isovalues(isovalues);
    }

    /// Waits until the loader is idle (finest level the isovalues need, the budget, or an
    /// error) or `timeout` passes; returns whether it finished. Not from a render thread.
    pub fn wait_until_finished(&self, timeout: Duration) -> bool {
        self.volume.wait_until_finished(timeout)
    }

    pub fn status(&self) -> OocStatus {
        OocStatus {
            loaded_levels: self.volume.loaded_levels(),
            level_count: self.volume.level_count(),
            resident_bytes: self.volume.resident_bytes(),
            finished: self.volume.is_finished(),
            budget_limited: self.volume.budget_limited(),
            error: self.volume.error().map(|e| e.to_string()),
        }
    }

    /// Renders with the levels loaded now (after requesting the frame's isovalues) and
    /// returns the finest level the frame could reach (0 = coarsest).
    pub fn render_with_level(
        &self,
        camera: &Camera,
        settings: &RenderSettings,
        cancel: &AtomicBool,
    ) -> Option<(Frame, usize)> {
        self.set_isovalues(&settings.active_isovalues().0);
        self.volume
            .render_with_level(self.intersector, self.normals, camera, settings, cancel)
    }
}

impl SceneData for OocData {
    fn path(&self) -> &Path {
        &self.path
    }

    fn step_count(&self) -> usize {
        1
    }

    fn step(&self) -> usize {
        0
    }

    fn time_value(&self, step: usize) -> f64 {
        step as f64
    }

    fn value_range(&self) -> Option<(f64, f64)> {
        OocData::value_range(self)
    }

    /// The histogram of the coarsest level (the top treelet): the finest data is never
    /// resident as a whole, and the coarse level subsamples the full volume (thesis 004
    /// §7.7), so its histogram has the full one's shape. A file that cannot be read again
    /// gives the range without a histogram, and says why.
    fn value_info(&self, bins: usize) -> Option<ValueInfo> {
        let (lo, hi) = OocData::value_range(self)?;
        Some(
            coarsest_level_histogram(&self.path, lo, hi, bins).unwrap_or_else(|e| ValueInfo {
                value_range: (lo, hi),
                histogram: None,
                histogram_note: format!("no histogram: {e}"),
            }),
        )
    }

    fn dims(&self) -> [usize; 3] {
        self.volume
            .meta()
            .layout
            .dims()
            .map(|x| usize::try_from(x).unwrap_or(usize::MAX))
    }

    fn world_frame(&self) -> volume_core::WorldFrame {
        self.volume.meta().grid.world_frame()
    }

    fn prefetch(&self, step: usize) -> anyhow::Result<()> {
        check_step(step, 1, &self.path)
    }

    fn set_step(&mut self, step: usize) -> anyhow::Result<StepSwitch> {
        check_step(step, 1, &self.path)?;
        Ok(StepSwitch::Unchanged)
    }

    fn has_view_options(&self, options: &ViewOptions) -> bool {
        self.intersector == options.intersector && options.normals.is_none_or(|n| n == self.normals)
    }

    fn set_view_options(&mut self, options: &ViewOptions) {
        self.intersector = options.intersector;
        if let Some(normals) = options.normals {
            self.normals = normals;
        }
    }

    fn view_options(&self) -> ViewOptions {
        ViewOptions {
            intersector: self.intersector,
            normals: Some(self.normals),
        }
    }

    fn build_time(&self) -> Duration {
        self.open_time
    }

    fn structure_bytes(&self) -> u64 {
        self.volume.resident_bytes()
    }

    fn describe(&self) -> String {
        let d = self.volume.meta().layout.dims();
        let s = self.status();
        format!(
            "out-of-core {}x{}x{} {}: level {}/{} loaded, {:.1} MiB resident",
            d[0],
            d[1],
            d[2],
            self.volume.meta().voxel_type,
            s.loaded_levels,
            s.level_count,
            s.resident_bytes as f64 / f64::from(1u32 << 20)
        )
    }

    fn loader_status(&self) -> Option<OocStatus> {
        Some(self.status())
    }
}

/// `.isot`: the value range and a `bins`-bin histogram of the coarsest level's voxels (the
/// top treelet, read again from the file).
fn coarsest_level_histogram(
    path: &Path,
    lo: f64,
    hi: f64,
    bins: usize,
) -> Result<ValueInfo, String> {
    use volume_core::ooc::{TreeletRecord, TreeletStorage as _};
    let file = formats::treelet::IsotFile::open(path).map_err(|e| e.to_string())?;
    let meta = file.meta();
    let bytes = file
        .fetch(0, 0)
        .map_err(|e| format!("{}: {e}", path.display()))?;
    macro_rules! top {
        ($t:ty) => {{
            let r = TreeletRecord::<$t>::decode(meta, 0, 0, &bytes)
                .map_err(|e| format!("{}: {e}", path.display()))?;
            (Histogram::compute(&r.voxels, lo, hi, bins), r.voxel_dims)
        }};
    }
    let (histogram, d) = match meta.voxel_type {
        VoxelType::U8 => top!(u8),
        VoxelType::I8 => top!(i8),
        VoxelType::U16 => top!(u16),
        VoxelType::I16 => top!(i16),
        VoxelType::U32 => top!(u32),
        VoxelType::I32 => top!(i32),
        VoxelType::F32 => top!(f32),
        VoxelType::F64 => top!(f64),
    };
    Ok(ValueInfo {
        value_range: (lo, hi),
        histogram: Some(histogram),
        histogram_note: format!(
            "the {}×{}×{} voxels of the coarsest level (top treelet)",
            d[0], d[1], d[2]
        ),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use volume_core::render::Surface;

    fn write_ball(dir: &Path, n: usize) -> PathBuf {
        let mesh = data_samples::tets::tet_mesh(data_samples::tets::TetShape::Ball, n).unwrap();
        let p = dir.join("ball.vtu");
        formats::mesh::write_vtu(&p, &mesh, formats::output::Replace::Refuse).unwrap();
        p
    }

    #[test]
    fn kinds_are_detected_by_name_and_magic() {
        assert_eq!(detect_kind(Path::new("a.vtu")), SceneKind::Tet);
        assert_eq!(detect_kind(Path::new("s_%03d.vtk")), SceneKind::Tet);
        assert_eq!(detect_kind(Path::new("c.pvd")), SceneKind::Tet);
        assert_eq!(detect_kind(Path::new("v.isot")), SceneKind::Ooc);
        assert_eq!(detect_kind(Path::new("v.nrrd")), SceneKind::Grid);
        for nifti in [
            "t1.nii",
            "bold.nii.gz",
            "a.hdr",
            "a.img",
            "a.img.gz",
            "s_%03d.nii.gz",
        ] {
            assert_eq!(detect_kind(Path::new(nifti)), SceneKind::Grid, "{nifti}");
        }
    }

    fn image_data(name: &str) -> PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../formats/tests/data")
            .join(name)
    }

    #[test]
    fn a_vtk_image_is_a_grid_and_switches_arrays() {
        let vti = image_data("vtk_image/binary_zlib.vti");
        let legacy = image_data("vtk_image/points_v42_binary.vtk");
        assert_eq!(detect_kind(&vti), SceneKind::Grid);
        assert_eq!(detect_kind(&legacy), SceneKind::Grid);
        assert_eq!(
            detect_kind(&image_data("mesh/mixed_v42_binary.vtk")),
            SceneKind::Tet
        );
        let mut scene = open_scene(&vti, &SceneOptions::default()).unwrap();
        let data = scene.data();
        assert_eq!(data.field(), Some("temperature"));
        assert_eq!(data.field_names(), vec!["label", "temperature"]);
        let (_, hi) = scene.value_range().unwrap();
        scene.data_mut().set_field("label").unwrap();
        assert_eq!(scene.data().field(), Some("label"));
        let (_, hi_label) = scene.value_range().unwrap();
        // `label` is the u8 copy of 1.5 × `temperature`.
        assert_eq!(hi_label, (hi * 1.5).floor());
        assert!(
            scene.describe().contains("array \"label\""),
            "{}",
            scene.describe()
        );
        let e = scene.data_mut().set_field("velocity").unwrap_err();
        assert!(e.to_string().contains("temperature"), "{e}");
        // A grid without named arrays has none to switch to.
        let mha = open_scene(
            &image_data("metaimage/float_zlib.mha"),
            &SceneOptions::default(),
        )
        .unwrap();
        assert!(mha.data().field_names().is_empty());
    }

    #[test]
    fn a_mesh_opens_renders_and_switches_fields() {
        let dir = tempfile::tempdir().unwrap();
        let p = write_ball(dir.path(), 8);
        let mut scene = open_scene(&p, &SceneOptions::default()).unwrap();
        assert_eq!(scene.kind(), SceneKind::Tet);
        let t = scene.as_tet().unwrap();
        assert_eq!(t.field(), "distance");
        t.scene().validate().unwrap();
        let (lo, hi) = scene.value_range().unwrap();
        assert!(lo >= 0.0 && hi <= 0.9 * 3f64.sqrt() && hi > lo);
        let camera = Camera::orbit(&scene.world_bounds(), 30.0, 20.0, 40.0);
        let settings = RenderSettings {
            width: 32,
            height: 32,
            surfaces: vec![Surface::new(0.5, [1.0; 3])],
            ..RenderSettings::default()
        };
        let f = scene
            .render(&camera, &settings, &AtomicBool::new(false))
            .unwrap();
        assert!(f.depth.iter().any(|d| d.is_finite()));
        let t = scene.as_tet_mut().unwrap();
        t.set_field("gaussians").unwrap();
        assert!(
            t.set_field("nope")
                .unwrap_err()
                .to_string()
                .contains("distance")
        );
        t.scene().validate().unwrap();
        assert!(scene.set_step(1).is_err());
    }

    /// Two numbered files of a ball whose `distance` array is scaled per step (step 1 also
    /// moves the points): `set_step_from` leaves the step, the drawn values, the value range
    /// and the picture exactly as a fresh open at that step has them.
    #[test]
    fn set_step_from_updates_step_values_and_range() {
        let dir = tempfile::tempdir().unwrap();
        let base = data_samples::tets::tet_mesh(data_samples::tets::TetShape::Ball, 6).unwrap();
        for s in 0..2 {
            let mut mesh = base.clone();
            for f in &mut mesh.fields {
                f.values.iter_mut().for_each(|v| *v *= 1.0 + 2.0 * s as f32);
            }
            if s == 1 {
                mesh.points
                    .iter_mut()
                    .for_each(|p| *p = p.map(|c| c * 1.25));
            }
            formats::mesh::write_vtu(
                &dir.path().join(format!("b_{s:03}.vtu")),
                &mesh,
                formats::output::Replace::Refuse,
            )
            .unwrap();
        }
        let pattern = dir.path().join("b_*.vtu");
        let mut scene = open_scene(&pattern, &SceneOptions::default()).unwrap();
        let t = scene.as_tet_mut().unwrap();
        let (lo0, hi0) = t.value_range().unwrap();
        let data = t.load_step_data(1).unwrap();
        t.set_step_from(1, &data).unwrap();
        assert_eq!(t.step(), 1);
        // Truth computed from the written values, independently of the scene.
        let want: Vec<f32> = base.fields[0].values.iter().map(|v| v * 3.0).collect();
        assert_eq!(t.field_values().unwrap(), want.as_slice());
        let lo = want.iter().copied().fold(f32::INFINITY, f32::min);
        let hi = want.iter().copied().fold(f32::NEG_INFINITY, f32::max);
        assert_eq!(t.value_range(), Some((f64::from(lo), f64::from(hi))));
        assert!(hi0 < f64::from(hi), "the step-1 values are larger");
        t.scene().validate().unwrap();
        assert!(
            t.set_step_from(5, &data).is_err(),
            "out-of-range steps are refused"
        );
        let fresh = open_scene(
            &pattern,
            &SceneOptions {
                step: 1,
                ..SceneOptions::default()
            },
        )
        .unwrap();
        let camera = Camera::orbit(&fresh.world_bounds(), 30.0, 20.0, 40.0);
        let settings = RenderSettings {
            width: 40,
            height: 30,
            surfaces: vec![Surface::new(0.5 * (lo + hi), [1.0; 3])],
            ..RenderSettings::default()
        };
        let never = AtomicBool::new(false);
        let a = scene.render(&camera, &settings, &never).unwrap();
        let b = fresh.render(&camera, &settings, &never).unwrap();
        assert!(a.depth.iter().any(|d| d.is_finite()));
        assert_eq!(a.rgba8, b.rgba8);
        // Back to step 0: the reference positions and values again.
        let t = scene.as_tet_mut().unwrap();
        let d0 = t.load_step_data(0).unwrap();
        t.set_step_from(0, &d0).unwrap();
        assert_eq!(t.value_range(), Some((lo0, hi0)));
    }

    #[test]
    fn a_raised_cancel_flag_stops_an_open() {
        let dir = tempfile::tempdir().unwrap();
        let p = write_ball(dir.path(), 4);
        let cancel = AtomicBool::new(true);
        let control = OpenControl {
            cancel: &cancel,
            progress: &|_| {},
        };
        let e = open_scene_with(&p, &SceneOptions::default(), &control).unwrap_err();
        assert!(is_cancelled(&e), "{e:#}");
        cancel.store(false, std::sync::atomic::Ordering::Relaxed);
        let seen = Mutex::new(Vec::new());
        let record = |f: f32| seen.lock().unwrap().push(f);
        let control = OpenControl {
            cancel: &cancel,
            progress: &record,
        };
        open_scene_with(&p, &SceneOptions::default(), &control).unwrap();
        let seen = seen.into_inner().unwrap();
        assert!(seen.windows(2).all(|w| w[0] <= w[1]), "{seen:?}");
        assert_eq!(seen.last(), Some(&1.0));
    }

    #[test]
    fn missing_fields_and_steps_are_clear_errors() {
        let dir = tempfile::tempdir().unwrap();
        let p = write_ball(dir.path(), 4);
        let e = open_scene(
            &p,
            &SceneOptions {
                field: Some("pressure".into()),
                ..SceneOptions::default()
            },
        )
        .unwrap_err();
        let msg = format!("{e:#}");
        assert!(
            msg.contains("pressure") && msg.contains("distance"),
            "{msg}"
        );
        let e = open_scene(
            &p,
            &SceneOptions {
                step: 2,
                ..SceneOptions::default()
            },
        )
        .unwrap_err();
        assert!(e.to_string().contains("single"), "{e}");
    }
}
