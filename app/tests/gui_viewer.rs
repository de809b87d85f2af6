//! Drives the real viewer (`ViewerApp`, all panels and jobs) headless with egui_kittest.
//!
//! The data is real (the embedded Marschner–Lobb sample from `CoreBackend`, and a small
//! in-memory time series); scenes come from a recording backend that logs every prepare and
//! render request and paints each frame in the color of the first visible surface, so the
//! tests can check what reached the renderer and what arrived on screen.

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Condvar, Mutex};
use std::time::{Duration, Instant};

use egui::accesskit::Role;
use egui_kittest::Harness;
use egui_kittest::kittest::Queryable as _;
use isoscope::ui::backend::{
    Backend, CoreBackend, DataKind, PreparedScene, RenderRequest, RenderedImage,
};
use isoscope::ui::jobs::JobControl;
use isoscope::ui::panels::Command;
use isoscope::ui::state::{IntersectorChoice, KeepSide, RawLayoutState, ViewerState};
use isoscope::viewer::ViewerApp;
use volume_core::series::{StepLoader, TimeSeries};
use volume_core::{Grid, RectilinearVolume};

#[derive(Default)]
struct Log {
    /// Voxel (0,0,0) of every volume a scene was built for, with the intersector.
    prepares: Vec<(f64, IntersectorChoice)>,
    requests: Vec<RenderRequest>,
}

/// Blocks scene builds while closed (to check that the UI keeps running).
#[derive(Default)]
struct Gate {
    closed: Mutex<bool>,
    cv: Condvar,
}

impl Gate {
    fn set_closed(&self, closed: bool) {
        *self.closed.lock().unwrap() = closed;
        self.cv.notify_all();
    }
    fn wait_open(&self) {
        let mut closed = self.closed.lock().unwrap();
        while *closed {
            closed = self.cv.wait(closed).unwrap();
        }
    }
}

#[derive(Default)]
struct Recorder {
    log: Mutex<Log>,
    gate: Gate,
}

struct RecordingScene {
    recorder: Arc<Recorder>,
}

impl PreparedScene for RecordingScene {
    fn render(
        &self,
        request: &RenderRequest,
        cancel: &AtomicBool,
    ) -> Result<Option<RenderedImage>, String> {
        self.recorder
            .log
            .lock()
            .unwrap()
            .requests
            .push(request.clone());
        if cancel.load(Ordering::Relaxed) {
            return Ok(None);
        }
        let w = (request.width / request.scale).max(1);
        let h = (request.height / request.scale).max(1);
        let c = request
            .surfaces
            .iter()
            .find(|s| s.visible)
            .map_or(request.options.background, |s| s.color);
        let px = [
            (c[0] * 255.0) as u8,
            (c[1] * 255.0) as u8,
            (c[2] * 255.0) as u8,
            255,
        ];
        Ok(Some(RenderedImage {
            width: w,
            height: h,
            rgba8: px.repeat((w * h) as usize),
            elapsed: Duration::from_millis(1),
            rays: u64::from(w * h),
        }))
    }
}

/// Four steps; voxel values of step s are `s + x index`.
struct Steps;

impl StepLoader for Steps {
    fn step_count(&self) -> usize {
        4
    }
    fn load_step(&self, step: usize) -> Result<RectilinearVolume, String> {
        let dims = [6, 5, 4];
        let grid = Grid::uniform(dims, [0.0; 3], [1.0, 1.0, 2.0]).map_err(|e| e.to_string())?;
        let voxels: Vec<f32> = (0..120).map(|i| (step + i % 6) as f32).collect();
        RectilinearVolume::new(grid, voxels.into()).map_err(|e| e.to_string())
    }
    fn time_value(&self, step: usize) -> Option<f64> {
        Some(0.5 * step as f64)
    }
    fn describe(&self) -> String {
        "test steps".into()
    }
}

struct TestBackend {
    recorder: Arc<Recorder>,
}

impl Backend for TestBackend {
    fn open(
        &self,
        path: &std::path::Path,
        _raw: Option<&RawLayoutState>,
        _control: &JobControl,
    ) -> Result<DataKind, String> {
        if path.ends_with("series.test") {
            let s = TimeSeries::open(Arc::new(Steps)).map_err(|e| e.to_string())?;
            Ok(DataKind::Series(Arc::new(s)))
        } else {
            Err(format!("{}: no such test file", path.display()))
        }
    }

    fn default_dataset(&self, control: &JobControl) -> Result<(String, DataKind), String> {
        CoreBackend.default_dataset(control)
    }

    fn prepare(
        &self,
        volume: &RectilinearVolume,
        intersector: IntersectorChoice,
        _control: &JobControl,
    ) -> Result<Arc<dyn PreparedScene>, String> {
        self.recorder.gate.wait_open();
        self.recorder
            .log
            .lock()
            .unwrap()
            .prepares
            .push((volume.value_f64(0, 0, 0), intersector));
        Ok(Arc::new(RecordingScene {
            recorder: Arc::clone(&self.recorder),
        }))
    }
}

fn harness(files: Vec<PathBuf>) -> (Harness<'static, ViewerApp>, Arc<Recorder>) {
    let recorder = Arc::new(Recorder::default());
    let backend = Arc::new(TestBackend {
        recorder: Arc::clone(&recorder),
    });
    let h = Harness::builder()
        .with_size(egui::vec2(1200.0, 900.0))
        .build_eframe(move |cc| ViewerApp::with_backend(&cc.egui_ctx, backend, files));
    (h, recorder)
}

/// Steps the app (which repaints continuously while rendering) until `done` holds.
fn step_until(h: &mut Harness<'_, ViewerApp>, what: &str, done: impl Fn(&ViewerApp) -> bool) {
    let start = Instant::now();
    while !done(h.state()) {
        assert!(
            start.elapsed() < Duration::from_secs(30),
            "timed out waiting for {what}: {:?}, busy {}, notes {:?}",
            h.state().stats,
            h.state().is_busy(),
            h.state()
                .notifications()
                .iter()
                .map(|n| n.text.clone())
                .collect::<Vec<_>>()
        );

        h.step();
        std::thread::sleep(Duration::from_millis(5));
    }
}

/// Waits until a full-resolution frame of the current state is on screen.
fn settle(h: &mut Harness<'_, ViewerApp>) {
    // Interaction keeps the view coarse for a moment; let that pass.
    std::thread::sleep(Duration::from_millis(200));
    step_until(h, "a full-resolution frame of the current state", |app| {
        app.shown_frame().is_some_and(|f| {
            f.request.scale == 1 && Some(&f.request) == app.desired_request(1).as_ref()
        })
    });
}

#[test]
fn opens_the_default_sample_and_shows_a_frame() {
    let (mut h, rec) = harness(vec![]);
    step_until(&mut h, "the default sample", |a| a.data().is_some());
    settle(&mut h);
    let app = h.state();
    let data = app.data().unwrap();
    assert_eq!(data.dims, [64, 64, 64]);
    assert_eq!(app.state.surfaces.len(), 1, "a first surface is added");
    let mid = 0.5 * (data.value_range.0 + data.value_range.1);
    assert!((app.state.surfaces[0].isovalue - mid).abs() < 1e-12);
    let frame = app.shown_frame().unwrap();
    assert!(frame.size[0] > 100 && frame.size[1] > 100);
    let log = rec.log.lock().unwrap();
    assert_eq!(log.prepares.len(), 1, "the scene is built once");
    assert_eq!(log.requests.last(), Some(&frame.request));
}

#[test]
fn sweeping_an_isovalue_rerenders_without_rebuilding() {
    let (mut h, rec) = harness(vec![]);
    step_until(&mut h, "the default sample", |a| a.data().is_some());
    settle(&mut h);

    h.get_by_label("Add isosurface").click();
    h.run_steps(2);
    assert_eq!(h.state().state.surfaces.len(), 2);

    let (lo, hi) = h.state().data().unwrap().value_range;
    for frac in [0.2, 0.3, 0.4] {
        let target = lo + frac * (hi - lo);
        h.get_by_role_and_label(Role::Slider, "Isovalue 2")
            .set_value_accesskit(target);
        h.run_steps(2);
        let iso = h.state().state.surfaces[1].isovalue;
        assert!((iso - target).abs() < 1e-9 * (hi - lo), "{iso} vs {target}");
        settle(&mut h);
        let shown = h.state().shown_frame().unwrap();
        assert_eq!(
            shown.request.surfaces[1].isovalue, iso,
            "a frame with the new isovalue arrived"
        );
    }
    let log = rec.log.lock().unwrap();
    assert_eq!(
        log.prepares.len(),
        1,
        "isovalue changes never rebuild the scene"
    );
    let isovalues: Vec<f64> = log
        .requests
        .iter()
        .filter_map(|r| r.surfaces.get(1).map(|s| s.isovalue))
        .collect();
    assert!(isovalues.len() >= 3, "{isovalues:?}");
}

#[test]
fn a_clip_box_reaches_the_renderer_and_toggles() {
    let (mut h, rec) = harness(vec![]);
    step_until(&mut h, "the default sample", |a| a.data().is_some());
    settle(&mut h);
    h.get_by_label("Add clip box").click();
    h.run_steps(2);
    settle(&mut h);
    let shown = h.state().shown_frame().unwrap().request.clone();
    assert_eq!(shown.clip_boxes.len(), 1);
    assert!(shown.clip_boxes[0].enabled);

    h.get_by_label("Clip box 1").click();
    h.run_steps(2);
    assert!(!h.state().state.clip_boxes[0].enabled);
    settle(&mut h);
    assert!(!h.state().shown_frame().unwrap().request.clip_boxes[0].enabled);

    h.get_by_label("Keep outside").click();
    h.run_steps(2);
    assert_eq!(h.state().state.clip_boxes[0].keep, KeepSide::Outside);
    h.get_by_role_and_label(Role::Slider, "Box 1 x max")
        .set_value_accesskit(0.75);
    h.run_steps(2);
    assert!((h.state().state.clip_boxes[0].max[0] - 0.75).abs() < 1e-6);
    settle(&mut h);
    // The frame on screen was rendered with the new box; a coarse render of an older state
    // may finish (and be logged) after it, so look for the request rather than the last one.
    let shown = h.state().shown_frame().unwrap().request.clone();
    assert!((shown.clip_boxes[0].max[0] - 0.75).abs() < 1e-6);
    assert_eq!(shown.clip_boxes[0].keep, KeepSide::Outside);
    let log = rec.log.lock().unwrap();
    assert!(
        log.requests.iter().any(|r| r == &shown),
        "the renderer received the shown request"
    );
}

#[test]
fn stepping_the_time_slider_builds_and_shows_that_step() {
    let (mut h, rec) = harness(vec![PathBuf::from("/virtual/series.test")]);
    step_until(&mut h, "the series", |a| a.data().is_some());
    settle(&mut h);
    assert_eq!(h.state().data().unwrap().step_count(), 4);

    h.get_by_role_and_label(Role::Slider, "Time step")
        .set_value_accesskit(2.0);
    h.run_steps(2);
    assert_eq!(h.state().state.time.step, 2);
    settle(&mut h);
    assert_eq!(h.state().shown_frame().unwrap().request.step, 2);
    // Step s has value s at voxel (0,0,0): the scene for step 2 was built from step 2's data.
    assert!(
        rec.log
            .lock()
            .unwrap()
            .prepares
            .iter()
            .any(|&(v, _)| v == 2.0)
    );

    h.get_by_label("Next").click();
    h.run_steps(2);
    assert_eq!(h.state().state.time.step, 3);
    settle(&mut h);
    assert_eq!(h.state().shown_frame().unwrap().request.step, 3);
}

#[test]
fn playback_advances_and_loops() {
    let (mut h, _rec) = harness(vec![PathBuf::from("/virtual/series.test")]);
    step_until(&mut h, "the series", |a| a.data().is_some());
    h.state_mut().state.time.fps = 50.0;
    h.get_by_label("Play").click();
    h.run_steps(1);
    assert!(h.state().state.time.playing);
    let mut seen = [false; 4];
    let start = Instant::now();
    // Looping wraps to 0 after step 3: seeing every step (and 0 again) proves both.
    while !(seen.iter().all(|&s| s) && h.state().state.time.step == 0) {
        assert!(
            start.elapsed() < Duration::from_secs(30),
            "playback stalled: {seen:?}"
        );
        seen[h.state().state.time.step] = true;
        h.step();
        std::thread::sleep(Duration::from_millis(5));
    }
}

#[test]
fn the_ui_keeps_running_while_a_scene_builds() {
    let recorder = Arc::new(Recorder::default());
    recorder.gate.set_closed(true);
    let backend = Arc::new(TestBackend {
        recorder: Arc::clone(&recorder),
    });
    let mut h = Harness::builder()
        .with_size(egui::vec2(1000.0, 700.0))
        .build_eframe(move |cc| ViewerApp::with_backend(&cc.egui_ctx, backend, vec![]));
    step_until(&mut h, "the default sample", |a| a.data().is_some());
    let start = Instant::now();
    for _ in 0..20 {
        h.step();
    }
    // 20 frames while the build is blocked: the UI thread did not wait for it.
    assert!(start.elapsed() < Duration::from_secs(10));
    assert!(h.state().is_busy());
    assert!(h.state().shown_frame().is_none());
    recorder.gate.set_closed(false);
    settle(&mut h);
    assert_eq!(recorder.log.lock().unwrap().prepares.len(), 1);
}

#[test]
fn a_bad_file_gives_a_notification_and_the_app_keeps_running() {
    let (mut h, _rec) = harness(vec![]);
    step_until(&mut h, "the default sample", |a| a.data().is_some());
    settle(&mut h);
    h.state_mut().push(Command::OpenFiles(vec![PathBuf::from(
        "/nowhere/broken.nrrd",
    )]));
    step_until(&mut h, "the error notification", |a| {
        a.notifications().iter().any(|n| n.is_error)
    });
    let n = h
        .state()
        .notifications()
        .iter()
        .find(|n| n.is_error)
        .unwrap();
    assert!(n.text.contains("broken.nrrd"), "{}", n.text);
    // The previous data stays and still renders.
    assert_eq!(h.state().data().unwrap().dims, [64, 64, 64]);
    h.get_by_label("Add isosurface").click();
    h.run_steps(2);
    settle(&mut h);
    assert_eq!(h.state().shown_frame().unwrap().request.surfaces.len(), 2);
}

#[test]
fn a_session_saves_and_restores() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("session.json");
    let (mut h, _rec) = harness(vec![]);
    step_until(&mut h, "the default sample", |a| a.data().is_some());
    h.get_by_label("Add isosurface").click();
    h.get_by_label("Add clip box").click();
    h.run_steps(2);
    h.state_mut().state.camera.orbit(30.0, 10.0);
    h.state_mut().state.render.shadows = true;
    let saved = h.state().state.clone();
    h.state_mut().push(Command::SaveSession(path.clone()));
    h.run_steps(1);
    assert_eq!(ViewerState::load(&path).unwrap(), saved);

    h.state_mut().push(Command::RemoveSurface(1));
    h.state_mut().push(Command::ResetView);
    h.run_steps(1);
    assert_ne!(h.state().state, saved);
    h.state_mut().push(Command::LoadSession(path));
    step_until(&mut h, "the restored session", |a| {
        a.state == saved && !a.is_busy()
    });
    settle(&mut h);
    assert_eq!(
        h.state().shown_frame().unwrap().request.surfaces,
        saved.surfaces
    );
}
