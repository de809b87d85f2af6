//! The viewer's link to the library: opening data (which builds its scene), switching time
//! steps and rendering.
//!
//! The viewer talks to a [`Backend`] so that the same UI code drives the real library
//! ([`CoreBackend`]: `crate::scene::open_scene` and `AnyScene::render`, exactly the path the
//! CLI takes) and, in tests, a recording double. A scene is built once per dataset;
//! everything that changes per frame (camera, isovalues, colors, clips, light, intersector,
//! tet normals) travels in a [`RenderRequest`], so sweeping an isovalue never rebuilds, and a
//! new time step is a refit ([`PreparedScene::set_step`]), not a rebuild.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::AtomicBool;
use std::time::Duration;

use volume_core::WorldFrame;
use volume_core::math::Aabb;
use volume_core::stats::Histogram;

use crate::scene::SceneKind;
pub use crate::scene::{StepSwitch, ValueInfo};

use super::camera::CameraPose;
use super::jobs::JobControl;
use super::state::{
    ClipBoxState, ClipPlaneState, IntersectorChoice, NormalsChoice, RawLayoutState, RenderOptions,
    SurfaceState, ViewerState,
};

/// Everything a frame depends on besides the scene.
#[derive(Debug, Clone, PartialEq)]
pub struct RenderRequest {
    /// Image size in pixels at full resolution.
    pub width: u32,
    pub height: u32,
    /// Progressive level: 1 renders every pixel, 4 one ray per 4×4 block (while interacting).
    pub scale: u32,
    pub camera: CameraPose,
    pub bounds: Aabb,
    /// All surfaces (invisible ones included; the backend skips them).
    pub surfaces: Vec<SurfaceState>,
    pub clip_boxes: Vec<ClipBoxState>,
    pub clip_planes: Vec<ClipPlaneState>,
    pub options: RenderOptions,
    /// Time step the scene holds.
    pub step: usize,
    /// Tet meshes: the point array the scene draws (`None` for other kinds).
    pub field: Option<String>,
    /// Out-of-core levels loaded when the request was made (0 for in-core data): a newly
    /// published level changes the request, so the view re-renders as the data refines.
    pub lod_levels: usize,
}

impl RenderRequest {
    /// What `state` asks of `data` at `width`×`height` pixels and progressive `scale`, with
    /// `lod_levels` out-of-core levels loaded.
    pub fn from_state(
        state: &ViewerState,
        data: &LoadedData,
        [width, height]: [u32; 2],
        scale: u32,
        lod_levels: usize,
    ) -> Self {
        Self {
            width,
            height,
            scale,
            camera: CameraPose::from_state(&state.camera, &data.bounds),
            bounds: data.bounds,
            surfaces: state.surfaces.clone(),
            clip_boxes: state.clip_boxes.clone(),
            clip_planes: state.clip_planes.clone(),
            options: state.render,
            step: state.time.step,
            field: data.field.clone(),
            lod_levels,
        }
    }
}

/// A finished frame.
#[derive(Debug, Clone)]
pub struct RenderedImage {
    pub width: u32,
    pub height: u32,
    /// Row 0 at the top, 4 bytes per pixel, not premultiplied.
    pub rgba8: Vec<u8>,
    /// The first hit's ray parameter per pixel (row 0 at the top), infinite where no
    /// surface was hit: what picking reads. Empty when the backend keeps no depth.
    pub depth: Vec<f32>,
    pub elapsed: Duration,
    /// Primary rays traced.
    pub rays: u64,
    /// Out-of-core: the finest level (0 = coarsest) this frame reached.
    pub lod_level: Option<usize>,
    /// The scalar bars of the frame's coloured surfaces (the viewer's overlay; composited
    /// into screenshots).
    pub scalar_bars: Vec<crate::coloring::ScalarBar>,
}

/// Out-of-core loading progress (a level/progress indicator), as the scene reports it.
pub type LodStatus = crate::scene::OocStatus;

/// A dataset with its built scene: renders any request, switches steps.
pub trait PreparedScene: Send + Sync {
    /// Renders; `Ok(None)` when `cancel` was raised, `Err` for a request the renderer refuses.
    fn render(
        &self,
        request: &RenderRequest,
        cancel: &AtomicBool,
    ) -> Result<Option<RenderedImage>, String>;

    /// Makes `step` current (a refit where the structure allows). Call from a job.
    fn set_step(&self, step: usize, control: &JobControl) -> Result<StepSwitch, String>;

    /// Loads `step`'s data ahead of time so that a later [`Self::set_step`] only refits.
    /// Call from a job.
    fn prefetch(&self, step: usize, control: &JobControl) -> Result<(), String>;

    /// Tet meshes: draws point array `name` (a value refit, no rebuild) and returns the new
    /// value range and histogram. Call from a job.
    fn set_field(&self, name: &str, _control: &JobControl) -> Result<ValueInfo, String> {
        Err(format!(
            "point array \"{name}\": this data has no point arrays to choose from"
        ))
    }

    /// The value range and histogram of what the scene draws now (after a step or field
    /// switch); `None` when they do not change (the default). Call from a job: it may scan
    /// every value.
    fn value_info(&self) -> Option<ValueInfo> {
        None
    }

    /// The summary line of what the scene holds now (kind and size, the drawn point array,
    /// the step, out-of-core levels and memory); `None` when it never changes (the
    /// default). Never blocks.
    fn summary(&self) -> Option<String> {
        None
    }

    /// Out-of-core loading progress; `None` for in-core data. Never blocks.
    fn lod_status(&self) -> Option<LodStatus> {
        None
    }

    /// What pixel `pixel` of a frame of `size` pixels rendered for `request` shows, given
    /// its depth `t` ([`crate::scene::AnyScene::pick`]). Call from a job: probing a mesh
    /// visits every tet.
    fn pick(
        &self,
        _request: &RenderRequest,
        _size: [u32; 2],
        _pixel: [u32; 2],
        _t: f32,
    ) -> Result<Option<crate::scene::Pick>, String> {
        Err("this data cannot be probed".to_string())
    }

    /// Writes the request's visible surfaces, clipped, as a triangle mesh file at `path`
    /// (replacing an existing one; [`crate::export`]). Call from a job: progress and cancel
    /// go through `control`.
    fn export(
        &self,
        _request: &RenderRequest,
        path: &Path,
        _control: &JobControl,
    ) -> Result<crate::export::ExportSummary, String> {
        Err(format!(
            "{}: this data cannot be exported as a mesh",
            path.display()
        ))
    }

    /// Grids: opens `path` as a volume on the same grid to colour surfaces by and returns
    /// the name to colour by and the updated list of named colour fields. Call from a job.
    fn add_color_volume(
        &self,
        path: &Path,
        _control: &JobControl,
    ) -> Result<(String, Vec<String>), String> {
        Err(format!(
            "{}: only volumes can be coloured by another volume",
            path.display()
        ))
    }
}

/// What kind of data is shown.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DataKindLabel {
    Grid,
    Tet,
    OutOfCore,
}

impl From<SceneKind> for DataKindLabel {
    fn from(kind: SceneKind) -> Self {
        match kind {
            SceneKind::Grid => Self::Grid,
            SceneKind::Tet => Self::Tet,
            SceneKind::Ooc => Self::OutOfCore,
        }
    }
}

/// Number of histogram bins under the isovalue sliders.
pub const HISTOGRAM_BINS: usize = 128;

/// A loaded dataset: its scene and what the panels show about it.
#[derive(Clone)]
pub struct LoadedData {
    /// File name, or a description of the embedded sample.
    pub name: String,
    pub path: Option<PathBuf>,
    pub kind: DataKindLabel,
    /// One line: dims and type, tet and point counts, point array, step, levels; refreshed
    /// from [`PreparedScene::summary`] every frame, so it never disagrees with the scene.
    pub summary: String,
    /// Grid dims (`[0; 3]` for meshes).
    pub dims: [usize; 3],
    pub bounds: Aabb,
    /// The anatomical frame of world coordinates (orientation marker, view presets).
    pub world_frame: WorldFrame,
    /// Finite value range of the current step and field (the slider range).
    pub value_range: (f64, f64),
    /// How the values read (integers as integers, `f32` as the shortest decimal).
    pub value_format: crate::values::ValueFormat,
    /// Histogram of the current step and field (`.isot`: of the coarsest level).
    pub histogram: Option<Histogram>,
    /// What the histogram counts, shown under it.
    pub histogram_note: String,
    /// Tet meshes: the point arrays that can be drawn, and the drawn one.
    pub fields: Vec<String>,
    pub field: Option<String>,
    /// The named fields surfaces can be coloured by (a mesh's point arrays, a grid's added
    /// volumes), and whether the gradient magnitude is one (grids).
    pub color_fields: Vec<String>,
    pub gradient_coloring: bool,
    /// Time value of every step (one entry for a single data set).
    pub times: Vec<f64>,
    pub scene: Arc<dyn PreparedScene>,
}

impl LoadedData {
    /// Takes the range and histogram of a new step or field.
    pub fn set_values(&mut self, info: ValueInfo) {
        self.value_range = info.value_range;
        self.histogram = info.histogram;
        self.histogram_note = info.histogram_note;
    }

    pub fn step_count(&self) -> usize {
        self.times.len().max(1)
    }

    pub fn time_value(&self, step: usize) -> f64 {
        self.times.get(step).copied().unwrap_or(step as f64)
    }
}

/// How to build a scene (the render options that are fixed at build time are only initial
/// values: the intersector and the normals are switched in place later).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct OpenChoices {
    pub intersector: IntersectorChoice,
    pub normals: Option<NormalsChoice>,
    /// Tet meshes: the point array to draw if the mesh has it (a restored session's).
    pub field: Option<String>,
    /// DICOM inputs of several series: the one picked (its number or SeriesInstanceUID).
    pub dicom_series: Option<String>,
    /// TIFF stacks: the spacing of axes the file does not record (ignored for other files).
    pub spacing: Option<[f64; 3]>,
}

/// One series of a DICOM input, as the series picker lists it.
pub use formats::dicom::SeriesSummary;

/// Opening data and building scenes; implemented by [`CoreBackend`] and by test doubles.
pub trait Backend: Send + Sync + 'static {
    /// Opens a file or series pattern and builds its scene (raw files use `raw` when given).
    /// The error names the file and the reason.
    fn open(
        &self,
        path: &Path,
        raw: Option<&RawLayoutState>,
        choices: OpenChoices,
        control: &JobControl,
    ) -> Result<LoadedData, String>;

    /// The embedded default dataset, generated in memory.
    fn default_dataset(
        &self,
        choices: OpenChoices,
        control: &JobControl,
    ) -> Result<LoadedData, String>;

    /// True if `path` may hold several datasets to pick from (a DICOM folder, `DICOMDIR` or
    /// file): the viewer then asks [`Self::series_to_pick`] (in a job) before it opens it.
    /// Cheap: it runs on the UI thread and reads no file.
    fn may_hold_several_series(&self, _path: &Path) -> bool {
        false
    }

    /// The series of `path` when the user has to pick one (several, and none implied);
    /// `Ok(None)` when `path` opens without a pick. Call from a job: it reads every file.
    fn series_to_pick(&self, _path: &Path) -> Result<Option<Vec<SeriesSummary>>, String> {
        Ok(None)
    }
}

pub use super::core_backend::{CoreBackend, DEFAULT_SAMPLE_SIZE};
