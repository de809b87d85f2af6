//! The viewer's link to the library: opening data, building scenes and rendering.
//!
//! The viewer talks to a [`Backend`] so that the same UI code drives the real library
//! ([`CoreBackend`]: `formats::open`, the kd-tree scene and `volume_core::render::render`,
//! exactly the API the CLI uses) and, in tests, a recording double. Scenes are built once per
//! volume (and intersector); everything that changes per frame (camera, isovalues, colors,
//! clips, light) travels in a [`RenderRequest`], so sweeping an isovalue never rebuilds.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::AtomicBool;
use std::time::Duration;

use glam::{DVec3, Vec3};
use volume_core::RectilinearVolume;
use volume_core::math::Aabb;
use volume_core::series::TimeSeries;
use volume_core::stats::Histogram;

use super::camera::CameraPose;
use super::jobs::JobControl;
use super::state::{
    ClipBoxState, ClipPlaneState, IntersectorChoice, RawLayoutState, RenderOptions, SurfaceState,
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
    /// Time step the scene belongs to.
    pub step: usize,
}

/// A finished frame.
#[derive(Debug, Clone)]
pub struct RenderedImage {
    pub width: u32,
    pub height: u32,
    /// Row 0 at the top, 4 bytes per pixel, not premultiplied.
    pub rgba8: Vec<u8>,
    pub elapsed: Duration,
    /// Primary rays traced.
    pub rays: u64,
}

/// A scene built for one volume: renders any request for that volume.
pub trait PreparedScene: Send + Sync {
    /// Renders; `Ok(None)` when `cancel` was raised, `Err` for a request the renderer refuses.
    fn render(
        &self,
        request: &RenderRequest,
        cancel: &AtomicBool,
    ) -> Result<Option<RenderedImage>, String>;
}

/// Data as the viewer holds it.
#[derive(Clone)]
pub enum DataKind {
    Volume(Arc<RectilinearVolume>),
    Series(Arc<TimeSeries>),
}

impl DataKind {
    pub fn step_count(&self) -> usize {
        match self {
            DataKind::Volume(_) => 1,
            DataKind::Series(s) => s.step_count(),
        }
    }

    /// The volume shown at `step` (loads it for a series; call from a job).
    pub fn volume_at(&self, step: usize) -> Result<Arc<RectilinearVolume>, String> {
        match self {
            DataKind::Volume(v) => Ok(Arc::clone(v)),
            DataKind::Series(s) => s.step(step).map(Arc::new).map_err(|e| e.to_string()),
        }
    }

    pub fn time_value(&self, step: usize) -> f64 {
        match self {
            DataKind::Volume(_) => 0.0,
            DataKind::Series(s) => s.time_value(step),
        }
    }

    fn first(&self) -> &RectilinearVolume {
        match self {
            DataKind::Volume(v) => v,
            DataKind::Series(s) => s.first(),
        }
    }
}

/// Number of histogram bins under the isovalue sliders.
pub const HISTOGRAM_BINS: usize = 128;

/// A loaded dataset with what the panels show about it.
#[derive(Clone)]
pub struct LoadedData {
    /// File name, or a description of the embedded sample.
    pub name: String,
    pub path: Option<PathBuf>,
    pub kind: DataKind,
    pub dims: [usize; 3],
    pub voxel_type: String,
    pub bounds: Aabb,
    /// Finite value range of the first step.
    pub value_range: (f64, f64),
    pub histogram: Histogram,
}

impl LoadedData {
    /// Computes range, histogram and world bounds (parallel scans; call from a job).
    pub fn new(name: String, path: Option<PathBuf>, kind: DataKind) -> Result<Self, String> {
        let first = kind.first();
        let stats = first.value_stats();
        let (lo, hi) = stats
            .finite_range
            .ok_or_else(|| format!("{name}: no finite voxel values"))?;
        let histogram = volume_core::dispatch_voxels!(&first.data, buf =>
            Histogram::compute(buf.as_slice(), lo, hi, HISTOGRAM_BINS));
        Ok(Self {
            name,
            path,
            dims: first.dims(),
            voxel_type: first.data.voxel_type().to_string(),
            bounds: world_bounds(first),
            value_range: (lo, hi),
            histogram,
            kind,
        })
    }

    pub fn step_count(&self) -> usize {
        self.kind.step_count()
    }
}

/// World-space bounds: the grid box, through the `world_from_grid` affine when present.
pub fn world_bounds(volume: &RectilinearVolume) -> Aabb {
    let (lo, hi) = volume.grid.grid_bounds();
    let affine = volume.grid.world_from_grid();
    let mut b = Aabb::EMPTY;
    for corner in 0..8u32 {
        let p = DVec3::new(
            if corner & 1 == 0 { lo.x } else { hi.x },
            if corner & 2 == 0 { lo.y } else { hi.y },
            if corner & 4 == 0 { lo.z } else { hi.z },
        );
        let w = affine.map_or(p, |a| a.transform_point3(p));
        b = b.grow(Vec3::new(w.x as f32, w.y as f32, w.z as f32));
    }
    b
}

/// Opening data and building scenes; implemented by [`CoreBackend`] and by test doubles.
pub trait Backend: Send + Sync + 'static {
    /// Opens a file (raw files use `raw` when given). The error names the file and the reason.
    fn open(
        &self,
        path: &Path,
        raw: Option<&RawLayoutState>,
        control: &JobControl,
    ) -> Result<DataKind, String>;

    /// The embedded default dataset, generated in memory.
    fn default_dataset(&self, control: &JobControl) -> Result<(String, DataKind), String>;

    /// Builds the acceleration structure for one volume.
    fn prepare(
        &self,
        volume: &RectilinearVolume,
        intersector: IntersectorChoice,
        control: &JobControl,
    ) -> Result<Arc<dyn PreparedScene>, String>;
}

pub use super::core_backend::{CoreBackend, DEFAULT_SAMPLE_SIZE};
