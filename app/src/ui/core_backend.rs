//! [`CoreBackend`]: the viewer's link to the real library — `formats::open` for files,
//! `data_samples` for the embedded sample, `AnyGridScene` (the implicit min/max kd-tree,
//! thesis seed 004 ch. 7) and `volume_core::render::render`, the same render call the CLI
//! makes.

use std::path::Path;
use std::sync::atomic::AtomicBool;
use std::sync::{Arc, RwLock};

use glam::Vec3;
use volume_core::grid_scene::AnyGridScene;
use volume_core::intersect::Intersector;
use volume_core::render::{
    Camera, ClipRegion, Keep, Light, LightKind, Projection, RenderSettings, Surface, render,
};
use volume_core::{RectilinearVolume, VoxelType};

use super::backend::{Backend, DataKind, PreparedScene, RenderRequest, RenderedImage};
use super::camera::{bounding_radius, clip_box_world};
use super::jobs::JobControl;
use super::state::{IntersectorChoice, KeepSide, RawLayoutState};

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
    }
}

/// A kd-tree scene; the intersector is switched in place (no rebuild) when a request asks
/// for another one.
struct GridPrepared {
    scene: RwLock<AnyGridScene>,
}

impl PreparedScene for GridPrepared {
    fn render(
        &self,
        request: &RenderRequest,
        cancel: &AtomicBool,
    ) -> Result<Option<RenderedImage>, String> {
        let wanted = intersector(request.options.intersector);
        let current = self
            .scene
            .read()
            .map_err(|_| "the scene lock is poisoned".to_string())?
            .intersector();
        if current != wanted {
            self.scene
                .write()
                .map_err(|_| "the scene lock is poisoned".to_string())?
                .set_intersector(wanted);
        }
        let camera = camera(request);
        camera.validate().map_err(|e| e.to_string())?;
        let settings = settings(request);
        settings.validate().map_err(|e| e.to_string())?;
        let scene = self
            .scene
            .read()
            .map_err(|_| "the scene lock is poisoned".to_string())?;
        Ok(
            render(&*scene, &camera, &settings, cancel).map(|f| RenderedImage {
                width: f.width,
                height: f.height,
                rgba8: f.rgba8,
                elapsed: f.elapsed,
                rays: f.rays.primary,
            }),
        )
    }
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

impl Backend for CoreBackend {
    fn open(
        &self,
        path: &Path,
        raw: Option<&RawLayoutState>,
        _control: &JobControl,
    ) -> Result<DataKind, String> {
        let options = formats::OpenOptions {
            raw: raw.map(raw_layout).transpose()?,
        };
        // FormatError names the file and the field or offset.
        match formats::open(path, &options).map_err(|e| e.to_string())? {
            formats::Dataset::Volume(v) => Ok(DataKind::Volume(Arc::new(v))),
            formats::Dataset::Series(s) => Ok(DataKind::Series(Arc::new(s))),
        }
    }

    fn default_dataset(&self, control: &JobControl) -> Result<(String, DataKind), String> {
        let n = DEFAULT_SAMPLE_SIZE;
        let done = std::sync::atomic::AtomicUsize::new(0);
        let on_slice = || {
            let k = done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
            control.set_progress(k as f32 / n as f32);
        };
        let v =
            data_samples::marschner_lobb::generate_with_progress([n; 3], VoxelType::F32, &on_slice)
                .map_err(|e| format!("generating the default sample: {e}"))?;
        Ok((
            format!("Marschner–Lobb {n}³ (embedded sample)"),
            DataKind::Volume(Arc::new(v)),
        ))
    }

    fn prepare(
        &self,
        volume: &RectilinearVolume,
        choice: IntersectorChoice,
        _control: &JobControl,
    ) -> Result<Arc<dyn PreparedScene>, String> {
        Ok(Arc::new(GridPrepared {
            scene: RwLock::new(AnyGridScene::new(volume, intersector(choice))),
        }))
    }
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
        RenderRequest {
            width: w,
            height: h,
            scale: 1,
            camera: CameraPose::from_state(&state.camera, &data.bounds),
            bounds: data.bounds,
            surfaces: state.surfaces.clone(),
            clip_boxes: state.clip_boxes.clone(),
            clip_planes: state.clip_planes.clone(),
            options: state.render,
            step: 0,
        }
    }

    fn sample() -> LoadedData {
        let (name, kind) = CoreBackend.default_dataset(&JobControl::default()).unwrap();
        LoadedData::new(name, None, kind).unwrap()
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
        let DataKind::Volume(v) = &data.kind else {
            panic!("a volume")
        };
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
            data.histogram.counts.iter().sum::<u64>(),
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
        assert!(s.validate().is_ok());
    }

    /// An isosurface of the real sample, rendered through the viewer's path, covers the
    /// centre pixel; an isovalue outside the data range shows only background.
    #[test]
    fn the_real_renderer_draws_the_sample() {
        let data = sample();
        let DataKind::Volume(v) = &data.kind else {
            panic!("a volume")
        };
        let scene = CoreBackend
            .prepare(v, IntersectorChoice::Exact, &JobControl::default())
            .unwrap();
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
