//! [`CoreBackend`]: the viewer's link to the real library. Files open through
//! [`crate::scene::open_scene`] (grids with the implicit min/max kd-tree, thesis seed 004
//! ch. 7; tet meshes with the min/max BVH, ch. 8; `.isot` out-of-core treelets, §7.7–7.8),
//! the embedded sample comes from `data_samples`, and frames from [`AnyScene::render`] — the
//! same open and render calls the CLI makes.
//!
//! Each kind of data answers for itself ([`crate::scene::SceneData`]: step switches,
//! prefetching, value histograms, view options); this file only adds the locking that lets
//! frames render while a job switches a step, and turns a [`RenderRequest`] into the
//! renderer's camera and settings.

use std::path::Path;
use std::sync::atomic::AtomicBool;
use std::sync::{Arc, Mutex, RwLock};

use glam::Vec3;
use volume_core::intersect::Intersector;
use volume_core::render::Normals;
use volume_core::render::{
    Camera, ClipRegion, Keep, Light, LightKind, Projection, RenderSettings, Surface,
};
use volume_core::{RectilinearVolume, VoxelType};

use super::backend::{
    Backend, DataKindLabel, HISTOGRAM_BINS, LoadedData, LodStatus, OpenChoices, PreparedScene,
    RenderRequest, RenderedImage, SeriesSummary, StepSwitch, ValueInfo,
};
use super::camera::{bounding_radius, clip_box_world};
use super::jobs::JobControl;
use super::state::{IntersectorChoice, KeepSide, NormalsChoice, RawLayoutState};
use crate::scene::{
    AnyScene, GridData, OpenControl, SceneOptions, ViewOptions, is_cancelled, open_scene_with,
};

/// Edge length of the embedded default dataset.
pub const DEFAULT_SAMPLE_SIZE: usize = 64;

/// The real library.
#[derive(Debug, Default, Clone, Copy)]
pub struct CoreBackend;

pub fn intersector(choice: IntersectorChoice) -> Intersector {
    match choice {
        IntersectorChoice::Linear => Intersector::Linear,
        IntersectorChoice::Neubauer => Intersector::Neubauer { iterations: 3 },
        IntersectorChoice::Exact => Intersector::Exact,
        IntersectorChoice::Schwarze => Intersector::Schwarze,
        IntersectorChoice::Reference => Intersector::Reference,
    }
}

/// The renderer's camera for a request.
pub fn camera(request: &RenderRequest) -> Camera {
    let c = &request.camera;
    Camera {
        eye: c.eye,
        target: c.target,
        up: c.up,
        vfov_deg: c.vfov_deg,
        projection: if c.orthographic {
            Projection::Orthographic
        } else {
            Projection::Pinhole
        },
        // Default: the pinhole view's height at the target distance, as `CameraPose` projects.
        ortho_height: None,
    }
}

/// The renderer's settings for a request.
pub fn settings(request: &RenderRequest) -> RenderSettings {
    let o = &request.options;
    let surfaces = request
        .surfaces
        .iter()
        .map(|s| Surface {
            isovalue: s.isovalue as f32,
            color: s.color,
            opacity: s.opacity,
            visible: s.visible,
            color_by: s.color_by.clone(),
        })
        .collect();
    let mut clips: Vec<ClipRegion> = request
        .clip_boxes
        .iter()
        .filter(|b| b.enabled)
        .map(|b| {
            let w = clip_box_world(b, &request.bounds);
            ClipRegion::Box {
                min: w.min,
                max: w.max,
                keep: match b.keep {
                    KeepSide::Inside => Keep::Inside,
                    KeepSide::Outside => Keep::Outside,
                },
            }
        })
        .collect();
    let centre = request.bounds.center();
    let radius = bounding_radius(&request.bounds);
    for p in request.clip_planes.iter().filter(|p| p.enabled) {
        // Keep n·x <= n·(centre + offset·radius·n): the side the normal points to goes.
        if let Some(n) = Vec3::from(p.normal).try_normalize() {
            clips.push(ClipRegion::Plane {
                normal: n,
                offset: n.dot(centre) + p.offset * radius,
            });
        }
    }
    // The light direction is given relative to the view, so it turns with the camera.
    let kind = if o.light_azimuth_deg == 0.0 && o.light_elevation_deg == 0.0 {
        LightKind::Headlight
    } else {
        let b = request.camera.basis();
        let (az, el) = (
            o.light_azimuth_deg.to_radians(),
            o.light_elevation_deg.to_radians(),
        );
        let dir = (-b.forward * az.cos() + b.right * az.sin()) * el.cos() + b.up * el.sin();
        LightKind::Directional {
            dir: dir.normalize(),
        }
    };
    RenderSettings {
        width: request.width,
        height: request.height,
        surfaces,
        clips,
        max_layers: o.max_layers.max(1),
        shadows: o.shadows,
        light: Light {
            kind,
            ..Light::default()
        },
        background: o.background,
        collect_stats: false,
        scale: request.scale.max(1),
        packets: true,
        supersample: supersample_for(o.supersample, request.width.max(request.height)),
        region: None,
        depth_only: o.flat,
    }
}

/// The supersampling factor `wanted` within what the renderer takes for an image whose
/// larger side is `side` pixels (at least 1).
pub fn supersample_for(wanted: u32, side: u32) -> u32 {
    let fits = volume_core::render::MAX_IMAGE_SIDE / side.max(1);
    wanted
        .min(volume_core::render::supersample::MAX_SUPERSAMPLE)
        .min(fits)
        .max(1)
}

/// An opened scene of any kind behind a lock: renders take the read lock, step switches
/// and intersector or normal changes the write lock (from jobs, never the UI thread).
pub struct CorePrepared {
    scene: RwLock<AnyScene>,
    /// Last out-of-core status, returned while the scene is locked for writing.
    lod: Mutex<Option<LodStatus>>,
    /// Last summary line, returned while the scene is locked for writing.
    summary: Mutex<Option<String>>,
}

#[allow(clippy::needless_pass_by_value)]
fn poisoned<T>(_: T) -> String {
    "the scene lock is poisoned (a render thread panicked)".to_string()
}

/// The options a request asks the built scene to hold.
fn view_options(request: &RenderRequest) -> ViewOptions {
    ViewOptions {
        intersector: intersector(request.options.intersector),
        normals: request.options.normals.map(normals),
    }
}

pub fn normals(choice: NormalsChoice) -> Normals {
    match choice {
        NormalsChoice::Faceted => Normals::Faceted,
        NormalsChoice::Smooth => Normals::Smooth,
    }
}

impl CorePrepared {
    pub fn new(scene: AnyScene) -> Self {
        Self {
            scene: RwLock::new(scene),
            lod: Mutex::new(None),
            summary: Mutex::new(None),
        }
    }

    /// Switches the intersector and the normals in place when the request asks for others.
    fn apply_options(&self, request: &RenderRequest) -> Result<(), String> {
        let want = view_options(request);
        if !self
            .scene
            .read()
            .map_err(poisoned)?
            .data()
            .has_view_options(&want)
        {
            self.scene
                .write()
                .map_err(poisoned)?
                .data_mut()
                .set_view_options(&want);
        }
        Ok(())
    }
}

impl PreparedScene for CorePrepared {
    fn render(
        &self,
        request: &RenderRequest,
        cancel: &AtomicBool,
    ) -> Result<Option<RenderedImage>, String> {
        self.apply_options(request)?;
        let camera = camera(request);
        camera.validate().map_err(|e| e.to_string())?;
        let settings = settings(request);
        settings.validate().map_err(|e| e.to_string())?;
        let scene = self.scene.read().map_err(poisoned)?;
        scene
            .check_colorings(&settings)
            .map_err(|e| crate::cli::error_text(&e))?;
        let scalar_bars = scene.scalar_bars(&settings);
        Ok(scene
            .render_with_level(&camera, &settings, cancel)
            .map(|(f, lod_level)| RenderedImage {
                width: f.width,
                height: f.height,
                rgba8: f.rgba8,
                depth: f.depth,
                elapsed: f.elapsed,
                rays: f.rays.primary,
                lod_level,
                scalar_bars,
            }))
    }

    fn pick(
        &self,
        request: &RenderRequest,
        size: [u32; 2],
        pixel: [u32; 2],
        t: f32,
    ) -> Result<Option<crate::scene::Pick>, String> {
        let scene = self.scene.read().map_err(poisoned)?;
        scene
            .pick(
                &camera(request),
                &settings(request).surfaces,
                size,
                pixel,
                t,
            )
            .map_err(|e| crate::cli::error_text(&e))
    }

    fn add_color_volume(
        &self,
        path: &Path,
        _control: &JobControl,
    ) -> Result<(String, Vec<String>), String> {
        let not_a_grid = || {
            format!(
                "{}: only volumes can be coloured by another volume (colour a mesh by one of \
                 its point arrays)",
                path.display()
            )
        };
        if !matches!(&*self.scene.read().map_err(poisoned)?, AnyScene::Grid(_)) {
            return Err(not_a_grid());
        }
        // Read without the lock (frames keep rendering), then add under the write lock.
        let (name, volume) =
            crate::scene::read_color_volume(path).map_err(|e| crate::cli::error_text(&e))?;
        let mut s = self.scene.write().map_err(poisoned)?;
        let AnyScene::Grid(g) = &mut *s else {
            return Err(not_a_grid());
        };
        g.set_color_volume(&name, volume)
            .map_err(|e| crate::cli::error_text(&e))?;
        Ok((name, s.color_field_names()))
    }

    fn set_step(&self, step: usize, _control: &JobControl) -> Result<StepSwitch, String> {
        {
            // Read the step's data under the read lock (frames may still finish), then
            // refit under the write lock.
            let s = self.scene.read().map_err(poisoned)?;
            if s.step() == step {
                return Ok(StepSwitch::Unchanged);
            }
            s.data()
                .prefetch(step)
                .map_err(|e| crate::cli::error_text(&e))?;
        }
        let mut s = self.scene.write().map_err(poisoned)?;
        s.set_step(step).map_err(|e| crate::cli::error_text(&e))
    }

    fn prefetch(&self, step: usize, _control: &JobControl) -> Result<(), String> {
        let s = self.scene.read().map_err(poisoned)?;
        s.data()
            .prefetch(step)
            .map_err(|e| crate::cli::error_text(&e))
    }

    fn set_field(&self, name: &str, _control: &JobControl) -> Result<ValueInfo, String> {
        let mut s = self.scene.write().map_err(poisoned)?;
        s.data_mut()
            .set_field(name)
            .map_err(|e| crate::cli::error_text(&e))?;
        drop(s);
        self.value_info()
            .ok_or_else(|| format!("point array \"{name}\" has no finite values"))
    }

    fn export(
        &self,
        request: &RenderRequest,
        path: &Path,
        control: &JobControl,
    ) -> Result<crate::export::ExportSummary, String> {
        let settings = settings(request);
        let scene = self.scene.read().map_err(poisoned)?;
        if scene.step() != request.step {
            return Err(format!(
                "the scene holds time step {}, not {}",
                scene.step(),
                request.step
            ));
        }
        crate::export::export_mesh(
            &scene,
            &settings.surfaces,
            &settings.clips,
            path,
            true,
            formats::output::Replace::Allow,
            control.cancel_flag(),
            &|f| control.set_progress(f),
        )
        .map_err(|e| crate::cli::error_text(&e))
    }

    fn value_info(&self) -> Option<ValueInfo> {
        self.scene.read().ok()?.data().value_info(HISTOGRAM_BINS)
    }

    fn summary(&self) -> Option<String> {
        let mut cached = self.summary.lock().ok()?;
        // Never wait for a writer: keep the last line while the scene is locked.
        if let Ok(s) = self.scene.try_read() {
            *cached = Some(s.describe());
        }
        cached.clone()
    }

    fn lod_status(&self) -> Option<LodStatus> {
        let mut cached = self.lod.lock().ok()?;
        // Never wait for a writer: keep the last status while the scene is locked.
        if let Ok(s) = self.scene.try_read() {
            *cached = s.data().loader_status();
        }
        cached.clone()
    }
}

/// What the panels show about a freshly opened scene (scans the values for the histogram;
/// call from a job).
pub fn loaded_data(
    name: String,
    path: Option<std::path::PathBuf>,
    scene: AnyScene,
) -> Result<LoadedData, String> {
    let data = scene.data();
    let info = data
        .value_info(HISTOGRAM_BINS)
        .ok_or_else(|| format!("{name}: no finite data values"))?;
    let times = (0..data.step_count()).map(|s| data.time_value(s)).collect();
    Ok(LoadedData {
        name,
        path,
        kind: DataKindLabel::from(scene.kind()),
        summary: data.describe(),
        dims: data.dims(),
        bounds: scene.world_bounds(),
        world_frame: data.world_frame(),
        value_range: info.value_range,
        value_format: scene.value_format(),
        histogram: info.histogram,
        histogram_note: info.histogram_note,
        fields: data.field_names().into_iter().map(str::to_owned).collect(),
        field: data.field().map(str::to_owned),
        color_fields: scene.color_field_names(),
        gradient_coloring: scene.can_color_by_gradient(),
        times,
        scene: Arc::new(CorePrepared::new(scene)),
    })
}

fn raw_layout(state: &RawLayoutState) -> Result<formats::raw::RawLayout, String> {
    let voxel_type = VoxelType::from_name(&state.voxel_type)
        .ok_or_else(|| format!("unknown voxel type {:?}", state.voxel_type))?;
    Ok(formats::raw::RawLayout {
        dims: state.dims,
        voxel_type,
        endian: if state.little_endian {
            formats::raw::Endian::Little
        } else {
            formats::raw::Endian::Big
        },
        header_bytes: state.header_bytes,
        spacing: state.spacing,
        origin: [0.0; 3],
    })
}

fn scene_options(
    path: &Path,
    raw: Option<&RawLayoutState>,
    choices: &OpenChoices,
) -> Result<SceneOptions, String> {
    Ok(SceneOptions {
        open: formats::OpenOptions {
            raw: raw.map(raw_layout).transpose()?,
            dicom_series: choices.dicom_series.clone(),
            // Other formats record their spacing and refuse one.
            spacing: choices
                .spacing
                .filter(|_| formats::tiff::is_tiff_path(path)),
            ..formats::OpenOptions::default()
        },
        intersector: intersector(choices.intersector),
        normals: choices.normals.map(normals),
        ..SceneOptions::default()
    })
}

impl Backend for CoreBackend {
    fn open(
        &self,
        path: &Path,
        raw: Option<&RawLayoutState>,
        choices: OpenChoices,
        control: &JobControl,
    ) -> Result<LoadedData, String> {
        let options = scene_options(path, raw, &choices)?;
        // Reading and building take 90% of the bar, the histogram scan the rest.
        let progress = |f: f32| control.set_progress(0.9 * f);
        let open_control = OpenControl {
            cancel: control.cancel_flag(),
            progress: &progress,
        };
        // The error chain names the file and the field or offset.
        let mut scene = open_scene_with(path, &options, &open_control).map_err(|e| {
            if is_cancelled(&e) {
                format!("{}: opening cancelled", path.display())
            } else {
                crate::cli::error_text(&e)
            }
        })?;
        // A restored session's point array, if this mesh has it.
        if let Some(want) = &choices.field
            && scene.data().field().is_some_and(|f| f != want)
            && scene.data().field_names().contains(&want.as_str())
        {
            scene
                .data_mut()
                .set_field(want)
                .map_err(|e| crate::cli::error_text(&e))?;
        }
        open_control
            .checkpoint(1.0)
            .map_err(|_| format!("{}: opening cancelled", path.display()))?;
        let name = path.file_name().map_or_else(
            || path.display().to_string(),
            |n| n.to_string_lossy().into_owned(),
        );
        loaded_data(name, Some(path.to_path_buf()), scene)
    }

    fn default_dataset(
        &self,
        choices: OpenChoices,
        control: &JobControl,
    ) -> Result<LoadedData, String> {
        let (name, scene) = default_scene(&choices, control)?;
        loaded_data(name, None, scene)
    }

    fn may_hold_several_series(&self, path: &Path) -> bool {
        let name = path
            .file_name()
            .map(|n| n.to_string_lossy().to_ascii_lowercase())
            .unwrap_or_default();
        path.is_dir()
            || name == "dicomdir"
            || Path::new(&name)
                .extension()
                .is_some_and(|e| e == "dcm" || e == "dicom")
    }

    fn series_to_pick(&self, path: &Path) -> Result<Option<Vec<SeriesSummary>>, String> {
        match formats::dicom::list_input(path) {
            None => Ok(None),
            Some(Err(e)) => Err(e.to_string()),
            Some(Ok(listing)) => Ok(
                (listing.default_series.is_none() && listing.series.len() > 1)
                    .then_some(listing.series),
            ),
        }
    }
}

/// The embedded sample: Marschner–Lobb on the cube [-1, 1]³, `DEFAULT_SAMPLE_SIZE`³ f32.
pub fn default_scene(
    choices: &OpenChoices,
    control: &JobControl,
) -> Result<(String, AnyScene), String> {
    let n = DEFAULT_SAMPLE_SIZE;
    let done = std::sync::atomic::AtomicUsize::new(0);
    let on_slice = || {
        let k = done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
        control.set_progress(k as f32 / n as f32);
    };
    let v: RectilinearVolume =
        data_samples::marschner_lobb::generate_with_progress([n; 3], VoxelType::F32, &on_slice)
            .map_err(|e| format!("generating the default sample: {e}"))?;
    let name = format!("Marschner–Lobb {n}³ (embedded sample)");
    let scene = AnyScene::Grid(GridData::from_volume(
        Path::new(&name),
        v,
        intersector(choices.intersector),
    ));
    Ok((name, scene))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ui::backend::LoadedData;
    use crate::ui::camera::CameraPose;
    use crate::ui::state::{
        ClipBoxState, ClipPlaneState, RenderOptions, SurfaceState, ViewerState,
    };

    fn request(data: &LoadedData, state: &ViewerState, w: u32, h: u32) -> RenderRequest {
        RenderRequest::from_state(state, data, [w, h], 1, 0)
    }

    fn sample() -> LoadedData {
        CoreBackend
            .default_dataset(OpenChoices::default(), &JobControl::default())
            .unwrap()
    }

    /// The Marschner–Lobb formula typed independently of data-samples.
    fn ml(x: f64, y: f64, z: f64) -> f64 {
        use std::f64::consts::PI;
        let r = (x * x + y * y).sqrt();
        let rho = (2.0 * PI * 6.0 * (PI * r / 2.0).cos()).cos();
        ((1.0 - (PI * z / 2.0).sin()) + 0.25 * (1.0 + rho)) / 2.5
    }

    #[test]
    fn default_sample_is_marschner_lobb_on_the_unit_cube() {
        let data = sample();
        assert_eq!(data.dims, [DEFAULT_SAMPLE_SIZE; 3]);
        assert_eq!(data.bounds.min, Vec3::splat(-1.0));
        assert!((data.bounds.max - Vec3::splat(1.0)).abs().max_element() < 1e-6);
        assert!(data.summary.contains("64x64x64 f32"), "{}", data.summary);
        let (_, scene) = default_scene(&OpenChoices::default(), &JobControl::default()).unwrap();
        let v = scene.as_grid().unwrap().volume();
        let h = 2.0 / (DEFAULT_SAMPLE_SIZE - 1) as f64;
        for (i, j, k) in [(0, 0, 0), (10, 20, 30), (63, 31, 5)] {
            let want = ml(
                -1.0 + h * i as f64,
                -1.0 + h * j as f64,
                -1.0 + h * k as f64,
            );
            assert!((v.value_f64(i, j, k) - want).abs() < 1e-6);
        }
        assert_eq!(
            data.histogram.as_ref().unwrap().counts.iter().sum::<u64>(),
            (DEFAULT_SAMPLE_SIZE as u64).pow(3)
        );
    }

    #[test]
    fn settings_carry_surfaces_clips_and_light() {
        let data = sample();
        let mut state = ViewerState::default();
        state.surfaces.push(SurfaceState::new(0.25, 0));
        state.clip_boxes.push(ClipBoxState {
            min: [0.0, 0.0, 0.0],
            max: [0.5, 1.0, 1.0],
            keep: KeepSide::Outside,
            enabled: true,
        });
        state.clip_boxes.push(ClipBoxState {
            enabled: false,
            ..ClipBoxState::default()
        });
        state.clip_planes.push(ClipPlaneState {
            enabled: true,
            normal: [0.0, 0.0, 2.0],
            offset: 0.5,
        });
        state.render = RenderOptions {
            light_elevation_deg: 90.0,
            shadows: true,
            ..RenderOptions::default()
        };
        let s = settings(&request(&data, &state, 64, 48));
        assert_eq!(
            s.surfaces,
            vec![Surface::new(0.25, state.surfaces[0].color)]
        );
        assert_eq!(s.clips.len(), 2, "the disabled box is left out");
        assert_eq!(
            s.clips[0],
            ClipRegion::Box {
                min: Vec3::splat(-1.0),
                max: Vec3::new(0.0, 1.0, 1.0),
                keep: Keep::Outside
            }
        );
        let r = 3f32.sqrt();
        match s.clips[1] {
            ClipRegion::Plane { normal, offset } => {
                assert_eq!(normal, Vec3::Z);
                assert!((offset - 0.5 * r).abs() < 1e-6);
            }
            ClipRegion::Box { .. } => panic!("a plane"),
        }
        // Elevation 90° relative to the view: the light comes from the view's up direction.
        let up = CameraPose::from_state(&state.camera, &data.bounds)
            .basis()
            .up;
        match s.light.kind {
            LightKind::Directional { dir } => assert!((dir - up).length() < 1e-5),
            k => panic!("directional light expected, got {k:?}"),
        }
        assert!(s.shadows);
        assert!(!s.depth_only);
        assert!(s.validate().is_ok());
        state.render.flat = true;
        assert!(settings(&request(&data, &state, 64, 48)).depth_only);
    }

    /// An isosurface of the real sample, rendered through the viewer's path, covers the
    /// centre pixel; an isovalue outside the data range shows only background.
    #[test]
    fn the_real_renderer_draws_the_sample() {
        let data = sample();
        let scene = Arc::clone(&data.scene);
        let mut state = ViewerState::default();
        state.surfaces.push(SurfaceState::new(0.5, 0));
        let cancel = AtomicBool::new(false);
        let img = scene
            .render(&request(&data, &state, 64, 48), &cancel)
            .unwrap()
            .unwrap();
        assert_eq!(
            (img.width, img.height, img.rgba8.len()),
            (64, 48, 64 * 48 * 4)
        );
        let bg = state.render.background.map(|c| (c * 255.0).round() as i32);
        let px = |i: usize, j: usize| {
            let o = 4 * (j * 64 + i);
            [
                img.rgba8[o] as i32,
                img.rgba8[o + 1] as i32,
                img.rgba8[o + 2] as i32,
            ]
        };
        let differs = |p: [i32; 3]| (0..3).any(|c| (p[c] - bg[c]).abs() > 3);
        assert!(
            differs(px(32, 24)),
            "the surface covers the centre: {:?}",
            px(32, 24)
        );
        state.surfaces[0].isovalue = 5.0;
        let empty = scene
            .render(&request(&data, &state, 64, 48), &cancel)
            .unwrap()
            .unwrap();
        assert!(
            empty
                .rgba8
                .chunks(4)
                .all(|p| { !differs([p[0] as i32, p[1] as i32, p[2] as i32]) })
        );
    }
}
