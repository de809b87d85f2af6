//! The Isoscope viewer: an [`eframe::App`] around the persisted [`ViewerState`], background
//! jobs and the side panels.
//!
//! Frame loop (`ViewerApp::ui`):
//! 1. poll finished jobs (load + build, step switch, prefetch, render, dialogs, screenshot)
//!    and the out-of-core loader's progress;
//! 2. apply queued [`Command`]s;
//! 3. draw the menu, side panel, time bar, status bar and viewport (panels edit the state and
//!    queue commands);
//! 4. derive the render request from the state; if it differs from what is shown or running,
//!    start a render job (cancelling a running full-resolution one); switch the time step
//!    (a refit job), prefetch the next steps, advance playback.
//!
//! The UI thread never waits: loading, building, refitting and rendering all run in
//! [`Job`]s, and the out-of-core status is read without blocking. Render results carry a
//! generation number; results older than the frame on screen, or from data that has since
//! been replaced, are discarded.

use std::collections::VecDeque;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Duration, Instant};

use egui::{Color32, Pos2, Rect, Sense, Stroke, TextureHandle, TextureOptions, Vec2};

use crate::ui::backend::{
    Backend, CoreBackend, LoadedData, LodStatus, OpenChoices, RenderRequest, RenderedImage,
    StepSwitch, ValueInfo,
};
use crate::ui::camera::{CameraPose, box_edges, clip_box_world};
use crate::ui::files::{FileGroup, group_files};
use crate::ui::jobs::{Job, JobPoll, take_finished};
use crate::ui::panels::{self, Command, Prefs};
use crate::ui::state::{CameraState, RawLayoutState, ViewerState};

/// Progressive level used while the user interacts (one ray per 4×4 pixels).
pub const INTERACTIVE_SCALE: u32 = 4;
/// How long after the last input the view counts as still moving.
const SETTLE: Duration = Duration::from_millis(150);
/// Steps loaded ahead of the current one.
const PREFETCH_AHEAD: usize = 2;
/// Largest render side, in pixels.
const MAX_RENDER_SIDE: u32 = 4096;
/// How often the out-of-core loader is polled while it loads.
const LOD_POLL: Duration = Duration::from_millis(40);

const PREFS_KEY: &str = "isoscope.prefs";

/// A step switch: the refit, then the new step's value range and histogram.
type StepJob = Job<Result<(StepSwitch, Option<ValueInfo>), String>>;

struct RenderJob {
    generation: u64,
    epoch: u64,
    request: RenderRequest,
    job: Job<Result<Option<RenderedImage>, String>>,
}

/// The frame on screen.
pub struct ShownFrame {
    pub generation: u64,
    pub request: RenderRequest,
    pub texture: TextureHandle,
    pub elapsed: Duration,
    pub rays: u64,
    pub size: [u32; 2],
    /// Out-of-core: the finest level the frame reached.
    pub lod_level: Option<usize>,
}

/// A message for the user (errors from bad files, saved screenshots).
#[derive(Debug, Clone)]
pub struct Notification {
    pub text: String,
    pub is_error: bool,
    pub created: Instant,
}

/// Counters that tests (and the status bar) read.
#[derive(Debug, Clone, Default)]
pub struct ViewerStats {
    pub renders_started: u64,
    pub renders_shown: u64,
    pub renders_discarded: u64,
    /// Acceleration structures built from scratch (one per opened dataset).
    pub scenes_built: u64,
    pub datasets_loaded: u64,
    /// Time-step switches done by refitting, and by rebuilding.
    pub steps_refit: u64,
    pub steps_rebuilt: u64,
    /// Steps loaded ahead of time.
    pub steps_prefetched: u64,
}

/// The raw-file dialog while it is open.
struct RawDialog {
    path: PathBuf,
    layout: RawLayoutState,
}

pub struct ViewerApp {
    /// Persisted session state (files, camera, surfaces, clips, options, time).
    pub state: ViewerState,
    pub prefs: Prefs,
    backend: Arc<dyn Backend>,
    repaint: Arc<dyn Fn() + Send + Sync>,
    commands: Vec<Command>,

    // Caches: rebuilt from the state and the files, never saved.
    data: Option<LoadedData>,
    /// Bumped whenever `data` is replaced; jobs and frames of older epochs are stale.
    epoch: u64,
    active_file: usize,
    load_job: Option<Job<Result<LoadedData, String>>>,
    /// The time step the scene holds (a step switch is a refit job).
    scene_step: usize,
    step_job: Option<(usize, StepJob)>,
    prefetch_job: Option<(usize, Job<Result<(), String>>)>,
    /// Steps of this epoch whose data is loaded ahead.
    prefetched: Vec<usize>,
    /// A point-array switch of a mesh (a value refit holding the scene's write lock).
    field_job: Option<(String, Job<Result<ValueInfo, String>>)>,
    /// The files the running load will show; they replace `state.files` only when it
    /// succeeds, so a cancelled or failed open leaves the session as it was.
    loading_files: Option<Vec<PathBuf>>,
    lod: Option<LodStatus>,
    render_job: Option<RenderJob>,
    pending_render: Option<RenderRequest>,
    generation: u64,
    shown: Option<ShownFrame>,
    shown_times: VecDeque<Instant>,
    dialog_job: Option<Job<Option<Command>>>,
    screenshot_job: Option<Job<Result<PathBuf, String>>>,
    raw_dialog: Option<RawDialog>,
    screenshot_window: bool,
    notifications: Vec<Notification>,
    last_interaction: Option<Instant>,
    last_step_advance: Instant,
    viewport_px: [u32; 2],
    pub stats: ViewerStats,
}

impl ViewerApp {
    /// The app with the real library backend, as `isoscope [FILE...]` starts it.
    pub fn new(cc: &eframe::CreationContext<'_>, files: Vec<PathBuf>) -> Self {
        let prefs = cc
            .storage
            .and_then(|s| eframe::get_value::<Prefs>(s, PREFS_KEY))
            .unwrap_or_default();
        let mut app = Self::with_backend(&cc.egui_ctx, Arc::new(CoreBackend), files);
        app.prefs = prefs;
        app
    }

    /// The app with any backend (tests use a recording double).
    pub fn with_backend(
        ctx: &egui::Context,
        backend: Arc<dyn Backend>,
        files: Vec<PathBuf>,
    ) -> Self {
        let ctx = ctx.clone();
        let mut app = Self {
            state: ViewerState::default(),
            prefs: Prefs::default(),
            backend,
            repaint: Arc::new(move || ctx.request_repaint()),
            commands: Vec::new(),
            data: None,
            epoch: 0,
            active_file: 0,
            load_job: None,
            scene_step: 0,
            step_job: None,
            prefetch_job: None,
            prefetched: Vec::new(),
            field_job: None,
            loading_files: None,
            lod: None,
            render_job: None,
            pending_render: None,
            generation: 0,
            shown: None,
            shown_times: VecDeque::new(),
            dialog_job: None,
            screenshot_job: None,
            raw_dialog: None,
            screenshot_window: false,
            notifications: Vec::new(),
            last_interaction: None,
            last_step_advance: Instant::now(),
            viewport_px: [0, 0],
            stats: ViewerStats::default(),
        };
        if files.is_empty() {
            app.push(Command::OpenDefault);
        } else {
            app.push(Command::OpenFiles(files));
        }
        app
    }

    /// Queues a command for the start of the next frame.
    pub fn push(&mut self, command: Command) {
        self.commands.push(command);
    }

    pub fn data(&self) -> Option<&LoadedData> {
        self.data.as_ref()
    }

    pub fn shown_frame(&self) -> Option<&ShownFrame> {
        self.shown.as_ref()
    }

    pub fn notifications(&self) -> &[Notification] {
        &self.notifications
    }

    /// Out-of-core loading progress of the shown data (polled every frame).
    pub fn lod_status(&self) -> Option<&LodStatus> {
        self.lod.as_ref()
    }

    /// The time step the scene holds (it lags `state.time.step` while a refit runs).
    pub fn scene_step(&self) -> usize {
        self.scene_step
    }

    /// Steps whose data has been loaded ahead of time.
    pub fn prefetched_steps(&self) -> &[usize] {
        &self.prefetched
    }

    /// True while any background job runs (prefetching excepted).
    pub fn is_busy(&self) -> bool {
        self.load_job.is_some()
            || self.step_job.is_some()
            || self.field_job.is_some()
            || self.render_job.is_some()
            || self.screenshot_job.is_some()
    }

    fn notify(&mut self, text: impl Into<String>, is_error: bool) {
        let text = text.into();
        if is_error {
            eprintln!("isoscope: {text}");
        }
        self.notifications.push(Notification {
            text,
            is_error,
            created: Instant::now(),
        });
    }

    fn repaint_fn(&self) -> impl Fn() + Send + 'static {
        let r = Arc::clone(&self.repaint);
        move || r()
    }

    fn open_choices(&self) -> OpenChoices {
        OpenChoices {
            intersector: self.state.render.intersector,
            smooth_normals: self.state.render.smooth_normals,
            field: self.state.field.clone(),
        }
    }

    /// Progress of the running open (0..1), if any.
    pub fn load_progress(&self) -> Option<f32> {
        self.load_job.as_ref().map(Job::progress)
    }

    // ---- jobs -------------------------------------------------------------------------

    fn start_load(&mut self, path: Option<PathBuf>, raw: Option<RawLayoutState>) {
        let backend = Arc::clone(&self.backend);
        let label = path.as_ref().map_or_else(
            || "generating the default sample".to_string(),
            |p| format!("loading {}", p.display()),
        );
        let choices = self.open_choices();
        self.load_job = Some(Job::spawn(
            label,
            self.repaint_fn(),
            move |control| match path {
                Some(p) => backend.open(&p, raw.as_ref(), choices, control),
                None => backend.default_dataset(choices, control),
            },
        ));
    }

    fn poll_jobs(&mut self, ctx: &egui::Context) {
        if let Some(result) = take_finished(&mut self.load_job) {
            let files = self.loading_files.take();
            match result.and_then(|r| r) {
                Ok(data) => {
                    if let Some(files) = files {
                        self.state.files = files;
                    }
                    self.install_data(data);
                }
                Err(e) => self.notify(e, true),
            }
        }
        if let Some((name, _)) = &self.field_job {
            let name = name.clone();
            let mut slot = self.field_job.take().map(|(_, j)| j);
            match take_finished(&mut slot) {
                None => self.field_job = slot.map(|j| (name, j)),
                Some(Ok(Ok(info))) => self.field_switched(name, info),
                Some(Ok(Err(e)) | Err(e)) => {
                    self.notify(format!("{}: {e}", self.data_name()), true);
                }
            }
        }
        if let Some((step, _)) = &self.step_job {
            let step = *step;
            let mut slot = self.step_job.take().map(|(_, j)| j);
            match take_finished(&mut slot) {
                None => self.step_job = slot.map(|j| (step, j)),
                Some(Ok(Ok((switch, info)))) => {
                    self.scene_step = step;
                    if let (Some(info), Some(d)) = (info, self.data.as_mut()) {
                        d.set_values(info);
                    }
                    match switch {
                        StepSwitch::Refit => self.stats.steps_refit += 1,
                        StepSwitch::Rebuilt => self.stats.steps_rebuilt += 1,
                        StepSwitch::Unchanged => {}
                    }
                }
                Some(Ok(Err(e)) | Err(e)) => {
                    // Stay on the step the scene holds; stop playback so it does not retry.
                    self.notify(format!("{}: time step {step}: {e}", self.data_name()), true);
                    self.state.time.step = self.scene_step;
                    self.state.time.playing = false;
                }
            }
        }
        if let Some((step, _)) = &self.prefetch_job {
            let step = *step;
            let mut slot = self.prefetch_job.take().map(|(_, j)| j);
            match take_finished(&mut slot) {
                None => self.prefetch_job = slot.map(|j| (step, j)),
                Some(Ok(Ok(()))) => {
                    self.prefetched.push(step);
                    self.stats.steps_prefetched += 1;
                }
                // A failed prefetch is reported when the step is shown; mark it done so
                // playback does not wait for it.
                Some(_) => self.prefetched.push(step),
            }
        }
        if let Some(rj) = &self.render_job {
            match rj.job.poll() {
                JobPoll::Pending => {}
                JobPoll::Done(image) => {
                    let rj = self.render_job.take().expect("checked above");
                    self.finish_render(ctx, rj, image);
                }
                JobPoll::Failed => {
                    self.render_job = None;
                    self.stats.renders_discarded += 1;
                    self.notify("rendering failed (the render thread panicked)", true);
                }
            }
        }
        if let Some(Ok(Some(cmd))) = take_finished(&mut self.dialog_job) {
            self.commands.push(cmd);
        }
        if let Some(result) = take_finished(&mut self.screenshot_job) {
            match result.and_then(|r| r) {
                Ok(p) => self.notify(format!("screenshot saved to {}", p.display()), false),
                Err(e) => self.notify(format!("screenshot: {e}"), true),
            }
        }
        // Out-of-core: poll the loader (never blocks); a new level changes the request.
        self.lod = self.data.as_ref().and_then(|d| d.scene.lod_status());
        if self.lod.as_ref().is_some_and(|l| !l.finished) {
            ctx.request_repaint_after(LOD_POLL);
        }
    }

    fn data_name(&self) -> String {
        self.data
            .as_ref()
            .map_or_else(String::new, |d| d.name.clone())
    }

    /// The scene draws point array `name` now: the sliders take its range and histogram,
    /// and every isovalue keeps its relative position in the range.
    fn field_switched(&mut self, name: String, info: ValueInfo) {
        let Some(d) = self.data.as_mut() else { return };
        let (lo0, hi0) = d.value_range;
        let (lo, hi) = info.value_range;
        for s in &mut self.state.surfaces {
            let frac = if hi0 > lo0 {
                ((s.isovalue - lo0) / (hi0 - lo0)).clamp(0.0, 1.0)
            } else {
                0.5
            };
            s.isovalue = lo + frac * (hi - lo);
        }
        d.set_values(info);
        d.field = Some(name.clone());
        self.state.field = Some(name);
    }

    fn install_data(&mut self, data: LoadedData) {
        self.epoch += 1;
        self.step_job = None;
        self.field_job = None;
        self.prefetch_job = None;
        self.prefetched.clear();
        if let Some(rj) = self.render_job.take() {
            rj.job.cancel();
        }
        self.pending_render = None;
        if let Some(p) = &data.path {
            self.prefs.remember(p);
        }
        // Scenes open at step 0; a restored session's step is then a refit away.
        self.scene_step = 0;
        self.state.time.step = self
            .state
            .time
            .step
            .min(data.step_count().saturating_sub(1));
        let (lo, hi) = data.value_range;
        // Keep restored isovalues (sessions) if they fit the data; otherwise start fresh.
        self.state
            .surfaces
            .retain(|s| s.isovalue >= lo && s.isovalue <= hi);
        if self.state.surfaces.is_empty() {
            self.state
                .surfaces
                .push(panels::new_surface(&self.state, &data));
        }
        self.state.field.clone_from(&data.field);
        self.lod = data.scene.lod_status();
        self.data = Some(data);
        self.stats.datasets_loaded += 1;
        self.stats.scenes_built += 1;
    }

    fn finish_render(
        &mut self,
        ctx: &egui::Context,
        rj: RenderJob,
        image: Result<Option<RenderedImage>, String>,
    ) {
        let newest_shown = self.shown.as_ref().map_or(0, |s| s.generation);
        match image {
            Err(e) => {
                self.stats.renders_discarded += 1;
                self.notify(format!("rendering: {e}"), true);
            }
            Ok(Some(img)) if rj.epoch == self.epoch && rj.generation > newest_shown => {
                let size = [img.width as usize, img.height as usize];
                if img.rgba8.len() == size[0] * size[1] * 4 && size[0] > 0 && size[1] > 0 {
                    let color = egui::ColorImage::from_rgba_unmultiplied(size, &img.rgba8);
                    let texture = match self.shown.take() {
                        Some(mut s) => {
                            s.texture.set(color, TextureOptions::LINEAR);
                            s.texture
                        }
                        None => ctx.load_texture("isoscope-view", color, TextureOptions::LINEAR),
                    };
                    self.shown = Some(ShownFrame {
                        generation: rj.generation,
                        request: rj.request,
                        texture,
                        elapsed: img.elapsed,
                        rays: img.rays,
                        size: [img.width, img.height],
                        lod_level: img.lod_level,
                    });
                    self.shown_times.push_back(Instant::now());
                    self.stats.renders_shown += 1;
                } else {
                    self.stats.renders_discarded += 1;
                    self.notify(
                        format!(
                            "renderer returned a {}×{} image with {} bytes",
                            img.width,
                            img.height,
                            img.rgba8.len()
                        ),
                        true,
                    );
                }
            }
            _ => self.stats.renders_discarded += 1,
        }
        if let Some(next) = self.pending_render.take() {
            self.start_render(next);
        }
    }

    /// True when the scene holds the step the state asks for.
    fn scene_ready(&self) -> bool {
        self.data.is_some()
            && self.step_job.is_none()
            && self.field_job.is_none()
            && self.scene_step == self.state.time.step
    }

    fn start_render(&mut self, request: RenderRequest) {
        if !self.scene_ready() || request.step != self.scene_step {
            return;
        }
        let Some(scene) = self.data.as_ref().map(|d| Arc::clone(&d.scene)) else {
            return;
        };
        self.generation += 1;
        let req = request.clone();
        let job = Job::spawn("rendering", self.repaint_fn(), move |control| {
            scene.render(&req, control.cancel_flag())
        });
        self.render_job = Some(RenderJob {
            generation: self.generation,
            epoch: self.epoch,
            request,
            job,
        });
        self.stats.renders_started += 1;
    }

    /// The request the current state asks for (`None` before data and a viewport exist).
    pub fn desired_request(&self, scale: u32) -> Option<RenderRequest> {
        let data = self.data.as_ref()?;
        let [w, h] = self.viewport_px;
        if w == 0 || h == 0 {
            return None;
        }
        Some(RenderRequest {
            width: w,
            height: h,
            scale,
            camera: CameraPose::from_state(&self.state.camera, &data.bounds),
            bounds: data.bounds,
            surfaces: self.state.surfaces.clone(),
            clip_boxes: self.state.clip_boxes.clone(),
            clip_planes: self.state.clip_planes.clone(),
            options: self.state.render,
            step: self.state.time.step,
            field: data.field.clone(),
            lod_levels: self.lod.as_ref().map_or(0, |l| l.loaded_levels),
        })
    }

    fn is_interacting(&self, ctx: &egui::Context) -> bool {
        ctx.dragged_id().is_some()
            || self.state.time.playing
            || self.last_interaction.is_some_and(|t| t.elapsed() < SETTLE)
    }

    fn schedule(&mut self, ctx: &egui::Context) {
        self.schedule_step();
        // Render.
        let interacting = self.is_interacting(ctx);
        let scale = if interacting { INTERACTIVE_SCALE } else { 1 };
        let Some(wanted) = self.desired_request(scale) else {
            return;
        };
        if !self.scene_ready() {
            return;
        }
        let same_as = |r: &RenderRequest| *r == wanted;
        if self.shown.as_ref().is_some_and(|s| same_as(&s.request))
            && self.render_job.as_ref().is_none_or(|r| same_as(&r.request))
        {
            return;
        }
        if self
            .render_job
            .as_ref()
            .is_some_and(|r| same_as(&r.request))
        {
            self.pending_render = None;
            return;
        }
        // Out-of-core: a frame of a coarser level is still worth showing; let it finish.
        let only_lod_differs = |r: &RenderRequest| {
            RenderRequest {
                lod_levels: wanted.lod_levels,
                ..r.clone()
            } == wanted
        };
        match &self.render_job {
            None => self.start_render(wanted),
            Some(r) if r.epoch == self.epoch && only_lod_differs(&r.request) => {
                self.pending_render = Some(wanted);
            }
            Some(r) if r.request.scale == 1 || r.epoch != self.epoch => {
                // A full-resolution frame would arrive stale: cancel it and start over.
                r.job.cancel();
                self.render_job = None;
                self.stats.renders_discarded += 1;
                self.start_render(wanted);
            }
            // A coarse frame is cheap: let it finish (the user sees progress), then render
            // the newest request.
            Some(_) => self.pending_render = Some(wanted),
        }
        if interacting {
            ctx.request_repaint_after(SETTLE);
        }
    }

    /// Switches the scene to the wanted step (a refit job) and prefetches the next ones.
    fn schedule_step(&mut self) {
        let Some(data) = &self.data else { return };
        let scene = Arc::clone(&data.scene);
        let count = data.step_count();
        let wanted = self.state.time.step;
        if wanted != self.scene_step && self.step_job.is_none() && self.field_job.is_none() {
            // The refit takes the scene's write lock: stop the running frame first.
            if let Some(r) = self.render_job.take() {
                r.job.cancel();
                self.stats.renders_discarded += 1;
            }
            self.pending_render = None;
            let job = Job::spawn(
                format!("switching to step {wanted}"),
                self.repaint_fn(),
                move |control| {
                    let switch = scene.set_step(wanted, control)?;
                    // The new step's range and histogram (unchanged: nothing to scan).
                    let info = match switch {
                        StepSwitch::Unchanged => None,
                        _ => scene.value_info(),
                    };
                    Ok((switch, info))
                },
            );
            self.step_job = Some((wanted, job));
            return;
        }
        if count <= 1 || self.step_job.is_some() || self.prefetch_job.is_some() {
            return;
        }
        let mut t = self.state.time;
        for _ in 0..PREFETCH_AHEAD {
            let Some(next) = t.next_step(count) else {
                return;
            };
            t.step = next;
            if next != self.scene_step && !self.prefetched.contains(&next) {
                let scene = Arc::clone(&scene);
                let job = Job::spawn(
                    format!("prefetching step {next}"),
                    self.repaint_fn(),
                    move |control| scene.prefetch(next, control),
                );
                self.prefetch_job = Some((next, job));
                return;
            }
        }
    }

    fn advance_playback(&mut self, ctx: &egui::Context) {
        let Some(data) = &self.data else { return };
        let count = data.step_count();
        let t = self.state.time;
        if !t.playing || count <= 1 {
            return;
        }
        let period = Duration::from_secs_f32(1.0 / t.fps.clamp(0.1, 120.0));
        let since = self.last_step_advance.elapsed();
        if since < period {
            ctx.request_repaint_after(period.saturating_sub(since));
            return;
        }
        let Some(next) = t.next_step(count) else {
            self.state.time.playing = false;
            return;
        };
        // Advance once the current step is on screen and the next one is loaded (no
        // stutter through steps still being read).
        let shown_current = self
            .shown
            .as_ref()
            .is_some_and(|s| s.request.step == t.step);
        if shown_current && self.prefetched.contains(&next) && self.step_job.is_none() {
            self.state.time.step = next;
            self.last_step_advance = Instant::now();
        }
        ctx.request_repaint_after(period);
    }

    // ---- commands ---------------------------------------------------------------------

    fn apply_commands(&mut self) {
        for cmd in std::mem::take(&mut self.commands) {
            self.apply(cmd);
        }
    }

    fn apply(&mut self, cmd: Command) {
        match cmd {
            Command::OpenDefault => {
                self.loading_files = Some(Vec::new());
                self.start_load(None, None);
            }
            Command::SetField(name) => self.start_field_switch(name),
            Command::OpenFiles(files) => self.open_files(&files),
            Command::OpenRaw(path, layout) => {
                self.state.raw_layout = Some(layout.clone());
                if !self.state.files.contains(&path) {
                    self.loading_files = Some(vec![path.clone()]);
                }
                self.start_load(Some(path), Some(layout));
            }
            Command::ShowFile(i) => {
                if let Some(p) = self.state.files.get(i).cloned() {
                    self.active_file = i;
                    self.open_path(p);
                }
            }
            Command::PickFiles => {
                self.dialog_job = Some(Job::spawn("file dialog", self.repaint_fn(), |_| {
                    rfd::FileDialog::new()
                        .set_title("Open volume data")
                        .pick_files()
                        .map(Command::OpenFiles)
                }));
            }
            Command::AddSurface => {
                if let Some(d) = &self.data {
                    let s = panels::new_surface(&self.state, d);
                    self.state.surfaces.push(s);
                }
            }
            Command::RemoveSurface(i) if i < self.state.surfaces.len() => {
                self.state.surfaces.remove(i);
            }
            Command::AddClipBox => self.state.clip_boxes.push(panels::new_clip_box()),
            Command::RemoveClipBox(i) if i < self.state.clip_boxes.len() => {
                self.state.clip_boxes.remove(i);
            }
            Command::AddClipPlane => self.state.clip_planes.push(panels::new_clip_plane()),
            Command::RemoveClipPlane(i) if i < self.state.clip_planes.len() => {
                self.state.clip_planes.remove(i);
            }
            Command::ResetView => self.state.camera = CameraState::default(),
            Command::AddBookmark => self.state.bookmarks.push(self.state.camera),
            Command::SetStep(s) => {
                let count = self.data.as_ref().map_or(1, LoadedData::step_count);
                self.state.time.step = s.min(count.saturating_sub(1));
                self.last_step_advance = Instant::now();
            }
            Command::SaveSession(p) => match self.state.save(&p) {
                Ok(()) => self.notify(format!("session saved to {}", p.display()), false),
                Err(e) => self.notify(e, true),
            },
            Command::LoadSession(p) => match ViewerState::load(&p) {
                Ok(s) => {
                    let files = s.files.clone();
                    let raw = s.raw_layout.clone();
                    self.state = s;
                    self.active_file = 0;
                    match (files.first(), raw) {
                        (None, _) => self.start_load(None, None),
                        (Some(f), Some(layout)) => self.start_load(Some(f.clone()), Some(layout)),
                        (Some(f), None) => self.start_load(Some(f.clone()), None),
                    }
                }
                Err(e) => self.notify(e, true),
            },
            Command::PickSaveSession => {
                self.dialog_job = Some(Job::spawn("file dialog", self.repaint_fn(), |_| {
                    rfd::FileDialog::new()
                        .add_filter("Isoscope session", &["json"])
                        .set_file_name("session.json")
                        .save_file()
                        .map(Command::SaveSession)
                }));
            }
            Command::PickLoadSession => {
                self.dialog_job = Some(Job::spawn("file dialog", self.repaint_fn(), |_| {
                    rfd::FileDialog::new()
                        .add_filter("Isoscope session", &["json"])
                        .pick_file()
                        .map(Command::LoadSession)
                }));
            }
            Command::Screenshot {
                path,
                width,
                height,
            } => self.start_screenshot(path, width, height),
            Command::CancelJobs => {
                // Dropping a job raises its cancel flag (the open stops at its next
                // checkpoint); the data on screen stays. A running step or field switch is
                // left to finish (a refit is short and holds the scene's lock).
                if let Some(j) = self.load_job.take() {
                    self.notify(format!("cancelled: {}", j.label), false);
                }
                self.loading_files = None;
                self.prefetch_job = None;
                if let Some(r) = self.render_job.take() {
                    r.job.cancel();
                }
                self.pending_render = None;
                self.screenshot_job = None;
                self.state.time.playing = false;
            }
            Command::RemoveSurface(_) | Command::RemoveClipBox(_) | Command::RemoveClipPlane(_) => {
            }
        }
    }

    /// Several files of one kind and shape open as a time series (see [`group_files`]).
    fn open_files(&mut self, files: &[PathBuf]) {
        // A session file (from the command line, drag and drop or the file dialog) restores
        // the session instead.
        if let [one] = files
            && is_session_file(one)
        {
            self.apply(Command::LoadSession(one.clone()));
            return;
        }
        match group_files(files) {
            FileGroup::Single(p) => {
                self.loading_files = Some(vec![p.clone()]);
                self.active_file = 0;
                self.open_path(p);
            }
            FileGroup::Series { pattern, steps } => {
                self.notify(
                    format!(
                        "opening {steps} files as a time series ({})",
                        pattern.display()
                    ),
                    false,
                );
                self.loading_files = Some(vec![pattern.clone()]);
                self.active_file = 0;
                self.open_path(pattern);
            }
            FileGroup::List { files, reason } => {
                let Some(first) = files.first().cloned() else {
                    return;
                };
                if files.len() > 1 {
                    self.notify(
                        format!("{} files, shown one at a time: {reason}", files.len()),
                        false,
                    );
                }
                self.loading_files = Some(files);
                self.active_file = 0;
                self.open_path(first);
            }
        }
    }

    /// Raw files without a JSON sidecar get the layout dialog first.
    fn open_path(&mut self, path: PathBuf) {
        if needs_raw_dialog(&path) {
            let layout = self.state.raw_layout.clone().unwrap_or_default();
            self.raw_dialog = Some(RawDialog { path, layout });
        } else {
            self.start_load(Some(path), None);
        }
    }

    /// Draws another point array of a mesh (a value refit in a job; renders wait for it).
    fn start_field_switch(&mut self, name: String) {
        let Some(d) = &self.data else { return };
        if d.field.as_deref() == Some(name.as_str()) || self.field_job.is_some() {
            return;
        }
        if !d.fields.contains(&name) {
            self.notify(format!("{}: no point array \"{name}\"", d.name), true);
            return;
        }
        let scene = Arc::clone(&d.scene);
        // The refit takes the scene's write lock: stop the running frame first.
        if let Some(r) = self.render_job.take() {
            r.job.cancel();
            self.stats.renders_discarded += 1;
        }
        self.pending_render = None;
        let n = name.clone();
        let job = Job::spawn(
            format!("switching to point array {name}"),
            self.repaint_fn(),
            move |control| scene.set_field(&n, control),
        );
        self.field_job = Some((name, job));
    }

    fn start_screenshot(&mut self, path: PathBuf, width: u32, height: u32) {
        let Some(mut req) = self.desired_request(1) else {
            self.notify("screenshot: nothing to render yet", true);
            return;
        };
        if !self.scene_ready() {
            self.notify("screenshot: the scene is still being prepared", true);
            return;
        }
        let Some(scene) = self.data.as_ref().map(|d| Arc::clone(&d.scene)) else {
            return;
        };
        req.width = width.clamp(1, MAX_RENDER_SIDE * 4);
        req.height = height.clamp(1, MAX_RENDER_SIDE * 4);
        self.screenshot_job = Some(Job::spawn(
            "screenshot",
            self.repaint_fn(),
            move |control| {
                let img = scene
                    .render(&req, control.cancel_flag())?
                    .ok_or_else(|| "cancelled".to_string())?;
                let buf = image::RgbaImage::from_raw(img.width, img.height, img.rgba8)
                    .ok_or_else(|| "the renderer returned a wrong-sized image".to_string())?;
                buf.save(&path)
                    .map_err(|e| format!("{}: {e}", path.display()))?;
                Ok(path)
            },
        ));
    }

    // ---- UI ---------------------------------------------------------------------------

    fn menu_ui(&mut self, ui: &mut egui::Ui) {
        egui::MenuBar::new().ui(ui, |ui| {
            ui.menu_button("File", |ui| {
                if ui.button("Open…").clicked() {
                    self.commands.push(Command::PickFiles);
                }
                if ui.button("Open default sample").clicked() {
                    self.commands.push(Command::OpenDefault);
                }
                ui.menu_button("Open recent", |ui| {
                    if self.prefs.recent_files.is_empty() {
                        ui.label("no recent files");
                    }
                    for p in self.prefs.recent_files.clone() {
                        if ui.button(p.display().to_string()).clicked() {
                            self.commands.push(Command::OpenFiles(vec![p]));
                        }
                    }
                });
                ui.separator();
                if ui.button("Save session…").clicked() {
                    self.commands.push(Command::PickSaveSession);
                }
                if ui.button("Open session…").clicked() {
                    self.commands.push(Command::PickLoadSession);
                }
                ui.separator();
                if ui.button("Screenshot…").clicked() {
                    self.screenshot_window = true;
                }
            });
            ui.menu_button("View", |ui| {
                if ui.button("Reset view").clicked() {
                    self.commands.push(Command::ResetView);
                }
            });
        });
    }

    fn side_ui(&mut self, ui: &mut egui::Ui) {
        egui::ScrollArea::vertical().show(ui, |ui| {
            egui::CollapsingHeader::new("Data")
                .default_open(true)
                .show(ui, |ui| {
                    panels::data_ui(
                        ui,
                        &self.state,
                        self.data.as_ref(),
                        self.active_file,
                        &mut self.commands,
                    );
                });
            egui::CollapsingHeader::new("Isosurfaces")
                .default_open(true)
                .show(ui, |ui| {
                    panels::isosurface_ui(
                        ui,
                        &mut self.state,
                        self.data.as_ref(),
                        &mut self.prefs.log_histogram,
                        &mut self.commands,
                    );
                });
            egui::CollapsingHeader::new("Clipping")
                .default_open(true)
                .show(ui, |ui| {
                    panels::clip_ui(ui, &mut self.state, &mut self.commands);
                });
            egui::CollapsingHeader::new("Rendering")
                .default_open(true)
                .show(ui, |ui| {
                    panels::render_options_ui(
                        ui,
                        &mut self.state,
                        self.data.as_ref().map(|d| d.kind),
                    );
                });
            egui::CollapsingHeader::new("Camera")
                .default_open(false)
                .show(ui, |ui| {
                    panels::camera_ui(ui, &mut self.state, &mut self.commands);
                });
        });
    }

    fn status_ui(&mut self, ui: &mut egui::Ui) {
        ui.horizontal(|ui| {
            let now = Instant::now();
            while self
                .shown_times
                .front()
                .is_some_and(|t| now.duration_since(*t) > Duration::from_secs(1))
            {
                self.shown_times.pop_front();
            }
            ui.label(format!("{} frames/s", self.shown_times.len()));
            if let Some(s) = &self.shown {
                let secs = s.elapsed.as_secs_f64();
                let rays_per_s = if secs > 0.0 {
                    s.rays as f64 / secs
                } else {
                    0.0
                };
                ui.label(format!("{:.2} Mrays/s", rays_per_s / 1e6));
                let res = if s.request.scale > 1 {
                    format!(
                        "{}×{} (1/{} while moving)",
                        s.size[0], s.size[1], s.request.scale
                    )
                } else {
                    format!("{}×{}", s.size[0], s.size[1])
                };
                ui.label(res);
                ui.label(format!("{:.1} ms", secs * 1e3));
            }
            ui.separator();
            let mut cancel = false;
            let job_row = |ui: &mut egui::Ui, label: &str, progress: f32, started: Instant| {
                ui.add(
                    egui::ProgressBar::new(progress)
                        .desired_width(220.0)
                        .text(format!(
                            "{label} {:.0}% {:.1}s",
                            progress * 100.0,
                            started.elapsed().as_secs_f32()
                        )),
                );
            };
            if let Some(j) = &self.load_job {
                job_row(ui, &j.label, j.progress(), j.started);
            }
            if let Some((_, j)) = &self.step_job {
                job_row(ui, &j.label, j.progress(), j.started);
            }
            if let Some((_, j)) = &self.prefetch_job {
                job_row(ui, &j.label, j.progress(), j.started);
            }
            if let Some((_, j)) = &self.field_job {
                job_row(ui, &j.label, j.progress(), j.started);
            }
            if let Some(j) = &self.screenshot_job {
                job_row(ui, &j.label, j.progress(), j.started);
            }
            if self.load_job.is_some()
                || self.prefetch_job.is_some()
                || self.screenshot_job.is_some()
            {
                cancel = ui.button("Cancel").clicked();
                ui.ctx().request_repaint_after(Duration::from_millis(100));
            }
            if let Some(l) = &self.lod {
                ui.separator();
                lod_ui(ui, l, self.shown.as_ref().and_then(|s| s.lod_level));
            }
            if cancel {
                self.commands.push(Command::CancelJobs);
            }
        });
    }

    fn viewport_ui(&mut self, ui: &mut egui::Ui) {
        let rect = ui.available_rect_before_wrap();
        let response = ui.allocate_rect(rect, Sense::click_and_drag());
        let ppp = ui.ctx().pixels_per_point();
        self.viewport_px = [
            ((rect.width() * ppp).round() as u32).min(MAX_RENDER_SIDE),
            ((rect.height() * ppp).round() as u32).min(MAX_RENDER_SIDE),
        ];
        let painter = ui.painter_at(rect);
        let bg = self
            .state
            .render
            .background
            .map(|c| (c.clamp(0.0, 1.0) * 255.0) as u8);
        painter.rect_filled(rect, 0.0, Color32::from_rgb(bg[0], bg[1], bg[2]));
        if let Some(s) = &self.shown {
            painter.image(
                s.texture.id(),
                rect,
                Rect::from_min_max(Pos2::ZERO, Pos2::new(1.0, 1.0)),
                Color32::WHITE,
            );
        } else {
            let text = if self.is_busy() {
                "working…"
            } else {
                "no image"
            };
            painter.text(
                rect.center(),
                egui::Align2::CENTER_CENTER,
                text,
                egui::FontId::proportional(18.0),
                Color32::GRAY,
            );
        }
        self.handle_view_input(ui, &response, rect);
        self.draw_clip_outlines(&painter, rect);
    }

    fn handle_view_input(&mut self, ui: &egui::Ui, response: &egui::Response, rect: Rect) {
        let mut moved = false;
        let (shift, scroll) = ui.input(|i| (i.modifiers.shift, i.smooth_scroll_delta.y));
        let pan_drag = response.dragged_by(egui::PointerButton::Secondary)
            || response.dragged_by(egui::PointerButton::Middle)
            || (shift && response.dragged_by(egui::PointerButton::Primary));
        let d = response.drag_delta();
        let px_to_radii = 2.0 * self.state.camera.zoom / rect.height().max(1.0);
        if pan_drag && d != Vec2::ZERO {
            self.state
                .camera
                .pan_by(-d.x * px_to_radii, d.y * px_to_radii);
            moved = true;
        } else if response.dragged_by(egui::PointerButton::Primary) && d != Vec2::ZERO {
            self.state.camera.orbit(-d.x * 0.4, d.y * 0.4);
            moved = true;
        }
        if response.hovered() && scroll != 0.0 {
            self.state.camera.zoom_by((-scroll * 0.002).exp());
            moved = true;
        }
        let typing = ui.ctx().memory(|m| m.focused().is_some());
        if response.hovered() && !typing {
            ui.input(|i| {
                use egui::Key;
                let c = &mut self.state.camera;
                let step = if i.modifiers.shift { 1.0 } else { 5.0 };
                let mut any = true;
                if i.key_down(Key::ArrowLeft) {
                    c.orbit(-step, 0.0);
                } else if i.key_down(Key::ArrowRight) {
                    c.orbit(step, 0.0);
                } else if i.key_down(Key::ArrowUp) {
                    c.orbit(0.0, step);
                } else if i.key_down(Key::ArrowDown) {
                    c.orbit(0.0, -step);
                } else if i.key_down(Key::Plus) || i.key_down(Key::Equals) {
                    c.zoom_by(0.97);
                } else if i.key_down(Key::Minus) {
                    c.zoom_by(1.03);
                } else if i.key_pressed(Key::R) {
                    *c = CameraState::default();
                } else {
                    any = false;
                }
                moved |= any;
            });
        }
        if moved {
            self.last_interaction = Some(Instant::now());
        }
    }

    fn draw_clip_outlines(&self, painter: &egui::Painter, rect: Rect) {
        let Some(data) = &self.data else { return };
        let pose = CameraPose::from_state(&self.state.camera, &data.bounds);
        for b in self.state.clip_boxes.iter().filter(|b| b.enabled) {
            let world = clip_box_world(b, &data.bounds);
            for (p, q) in box_edges(&world) {
                if let Some((a, c)) = pose.project_segment(p, q, rect.width(), rect.height()) {
                    painter.line_segment(
                        [rect.min + Vec2::from(a), rect.min + Vec2::from(c)],
                        Stroke::new(1.5, Color32::from_rgb(255, 200, 40)),
                    );
                }
            }
        }
    }

    fn windows_ui(&mut self, ctx: &egui::Context) {
        if let Some(dialog) = &mut self.raw_dialog {
            let mut open = true;
            let mut confirmed = false;
            egui::Window::new("Raw file layout")
                .open(&mut open)
                .collapsible(false)
                .show(ctx, |ui| {
                    ui.label(dialog.path.display().to_string());
                    confirmed = panels::raw_layout_ui(ui, &mut dialog.layout);
                });
            if confirmed {
                let d = self.raw_dialog.take().expect("dialog is open");
                self.commands.push(Command::OpenRaw(d.path, d.layout));
            } else if !open {
                self.raw_dialog = None;
            }
        }
        if self.screenshot_window {
            let mut open = true;
            let mut take = false;
            egui::Window::new("Screenshot")
                .open(&mut open)
                .collapsible(false)
                .show(ctx, |ui| {
                    let [w, h] = &mut self.prefs.screenshot_size;
                    ui.horizontal(|ui| {
                        let l = ui.label("Width");
                        ui.add(egui::DragValue::new(w).range(16..=16384))
                            .labelled_by(l.id);
                        let l = ui.label("Height");
                        ui.add(egui::DragValue::new(h).range(16..=16384))
                            .labelled_by(l.id);
                    });
                    let mut path = self.prefs.screenshot_path.display().to_string();
                    ui.horizontal(|ui| {
                        let l = ui.label("PNG file");
                        if ui
                            .text_edit_singleline(&mut path)
                            .labelled_by(l.id)
                            .changed()
                        {
                            self.prefs.screenshot_path = PathBuf::from(&path);
                        }
                    });
                    take = ui.button("Save PNG").clicked();
                });
            if take {
                let [width, height] = self.prefs.screenshot_size;
                self.commands.push(Command::Screenshot {
                    path: self.prefs.screenshot_path.clone(),
                    width,
                    height,
                });
                open = false;
            }
            self.screenshot_window = open;
        }
        // Notifications, newest at the bottom; errors stay until dismissed.
        self.notifications
            .retain(|n| n.is_error || n.created.elapsed() < Duration::from_secs(6));
        if !self.notifications.is_empty() {
            let mut dismiss = None;
            egui::Area::new(egui::Id::unique("isoscope-notifications"))
                .anchor(egui::Align2::RIGHT_TOP, Vec2::new(-12.0, 40.0))
                .show(ctx, |ui| {
                    for (i, n) in self.notifications.iter().enumerate() {
                        egui::Frame::popup(ui.style()).show(ui, |ui| {
                            ui.set_max_width(380.0);
                            let color = if n.is_error {
                                Color32::from_rgb(255, 120, 100)
                            } else {
                                ui.visuals().text_color()
                            };
                            ui.colored_label(color, &n.text);
                            if ui.small_button("Dismiss").clicked() {
                                dismiss = Some(i);
                            }
                        });
                    }
                });
            if let Some(i) = dismiss {
                self.notifications.remove(i);
            }
            ctx.request_repaint_after(Duration::from_secs(1));
        }
    }

    fn handle_dropped_files(&mut self, ctx: &egui::Context) {
        let dropped: Vec<PathBuf> = ctx.input(|i| {
            i.raw
                .dropped_files
                .iter()
                .map(|f| f.path().to_path_buf())
                .filter(|p| !p.as_os_str().is_empty())
                .collect()
        });
        if !dropped.is_empty() {
            self.commands.push(Command::OpenFiles(dropped));
        }
    }
}

/// The out-of-core indicator: levels loaded and drawn, loading progress, resident memory.
fn lod_ui(ui: &mut egui::Ui, l: &LodStatus, drawn_level: Option<usize>) {
    let count = l.level_count.max(1);
    let state = if let Some(e) = &l.error {
        format!("stopped: {e}")
    } else if l.finished && l.budget_limited {
        "memory budget reached".to_string()
    } else if l.finished {
        "loaded".to_string()
    } else {
        "loading…".to_string()
    };
    ui.add(
        egui::ProgressBar::new(l.loaded_levels as f32 / count as f32)
            .desired_width(100.0)
            .text(format!("LOD {}/{count}", l.loaded_levels)),
    );
    let drawn = drawn_level.map_or_else(String::new, |d| format!(", drawn at {}", d + 1));
    ui.label(format!(
        "LOD level {}/{count}{drawn} · {state} · {:.1} MiB resident",
        l.loaded_levels,
        l.resident_bytes as f64 / f64::from(1u32 << 20)
    ));
}

/// A `.json` file holding a viewer session (a `version` and at least one of the session's
/// sections), not a raw file's layout sidecar.
pub fn is_session_file(path: &Path) -> bool {
    let is_json = path
        .extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("json"));
    if !is_json {
        return false;
    }
    let Ok(text) = std::fs::read_to_string(path) else {
        return false;
    };
    serde_json::from_str::<serde_json::Value>(&text).is_ok_and(|v| {
        v.get("version").is_some()
            && ["files", "surfaces", "camera"]
                .iter()
                .any(|k| v.get(k).is_some())
    })
}

/// A raw file needs its layout from the user unless a `NAME.json` sidecar gives it.
pub fn needs_raw_dialog(path: &Path) -> bool {
    let is_raw = path
        .extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| matches!(e.to_ascii_lowercase().as_str(), "raw" | "bin" | "dat"));
    is_raw && !path.with_extension("json").exists()
}

impl eframe::App for ViewerApp {
    fn ui(&mut self, ui: &mut egui::Ui, _frame: &mut eframe::Frame) {
        let ctx = ui.ctx().clone();
        self.poll_jobs(&ctx);
        self.handle_dropped_files(&ctx);
        self.apply_commands();

        egui::Panel::top("isoscope-menu").show(ui, |ui| self.menu_ui(ui));
        egui::Panel::bottom("isoscope-status").show(ui, |ui| self.status_ui(ui));
        if self.data.as_ref().is_some_and(|d| d.step_count() > 1) {
            egui::Panel::bottom("isoscope-time").show(ui, |ui| {
                panels::time_ui(ui, &mut self.state, self.data.as_ref(), &mut self.commands);
            });
        }
        egui::Panel::left("isoscope-controls")
            .default_size(340.0)
            .size_range(240.0..=560.0)
            .show(ui, |ui| self.side_ui(ui));
        egui::CentralPanel::no_frame().show(ui, |ui| self.viewport_ui(ui));
        self.windows_ui(&ctx);

        self.advance_playback(&ctx);
        self.schedule(&ctx);
    }

    fn save(&mut self, storage: &mut dyn eframe::Storage) {
        eframe::set_value(storage, PREFS_KEY, &self.prefs);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn raw_extensions_need_the_dialog_unless_a_sidecar_exists() {
        let dir = tempfile::tempdir().unwrap();
        let raw = dir.path().join("ct.raw");
        assert!(needs_raw_dialog(&raw));
        std::fs::write(dir.path().join("ct.json"), "{}").unwrap();
        assert!(!needs_raw_dialog(&raw));
        assert!(!needs_raw_dialog(Path::new("a.nrrd")));
        assert!(needs_raw_dialog(Path::new("x/VOL.RAW")));
    }
}
