//! Which jobs run, and what their results do: the viewer's side of the
//! [`JobTable`](super::job_table::JobTable).
//!
//! Every frame `ViewerApp::poll_jobs` applies finished jobs, and `ViewerApp::schedule`
//! compares what the state asks for with what is shown or running and starts what is
//! missing: a time-step switch (a refit job) when the scene holds another step, then a
//! render of the current request (a running full-resolution render of a stale request is
//! cancelled; a coarse one may finish first), and prefetching of the next steps.

use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Duration, Instant};

use egui::TextureOptions;
use formats::output::Replace;

use super::app::ViewerApp;
use super::backend::{LoadedData, RenderRequest, RenderedImage, StepSwitch, ValueInfo};
use super::frame_upload::color_image;
use super::job_table::{Finished, RenderTicket};
use super::jobs::Job;
use super::panels;
use super::runtime::{PickShown, ShownFrame};
use super::state::{CameraState, RawLayoutState, ViewerState};

/// Progressive level used while the user interacts (one ray per 4×4 pixels).
pub const INTERACTIVE_SCALE: u32 = 4;
/// How long after the last input the view counts as still moving.
const SETTLE: Duration = Duration::from_millis(150);
/// Steps loaded ahead of the current one.
const PREFETCH_AHEAD: usize = 2;
/// Largest render side, in pixels.
pub const MAX_RENDER_SIDE: u32 = 4096;
/// How often the out-of-core loader is polled while it loads.
const LOD_POLL: Duration = Duration::from_millis(40);

impl ViewerApp {
    // ---- results ------------------------------------------------------------------------

    /// Applies every finished job, then polls the out-of-core loader (never blocks).
    pub(super) fn poll_jobs(&mut self, ctx: &egui::Context) {
        while let Some(done) = self.jobs.next_finished() {
            self.finish(ctx, done);
        }
        // A newly published level changes the render request.
        self.rt.lod = self.rt.data.as_ref().and_then(|d| d.scene.lod_status());
        // The data section's summary names the drawn point array, step and levels: read
        // them from the scene, not from when it was opened.
        if let Some(d) = self.rt.data.as_mut()
            && let Some(summary) = d.scene.summary()
        {
            d.summary = summary;
        }
        if self.rt.lod.as_ref().is_some_and(|l| !l.finished) {
            ctx.request_repaint_after(LOD_POLL);
        }
    }

    fn finish(&mut self, ctx: &egui::Context, done: Finished) {
        match done {
            Finished::Loaded { files, result } => match result.and_then(|r| r) {
                Ok(data) => {
                    self.rt.raw_retry = None;
                    if let Some(files) = files {
                        self.state.files = files;
                    }
                    self.install_data(data);
                }
                Err(e) => {
                    // A raw layout that did not fit: the dialog comes back with the layout
                    // entered and the reason, to correct it.
                    if let Some(mut dialog) = self.rt.raw_retry.take() {
                        dialog.error = Some(e.clone());
                        self.rt.raw_dialog = Some(dialog);
                    }
                    self.notify(e, true);
                }
            },
            Finished::ColorVolumeAdded { surface, result } => match result.and_then(|r| r) {
                Ok((name, fields)) => {
                    if let Some(d) = self.rt.data.as_mut() {
                        d.color_fields = fields;
                    }
                    if let Some(s) = self.state.surfaces.get_mut(surface) {
                        let field = volume_core::render::ColorField::Field(name);
                        match &mut s.color_by {
                            Some(c) => {
                                c.field = field;
                                c.range = None;
                            }
                            None => s.color_by = Some(volume_core::render::ColorBy::new(field)),
                        }
                    }
                    self.load_missing_color_volumes();
                }
                Err(e) => self.notify(format!("colour by another volume: {e}"), true),
            },
            Finished::FieldSwitched { name, result } => match result.and_then(|r| r) {
                Ok(info) => self.field_switched(name, info),
                Err(e) => {
                    let name = self.rt.data_name();
                    self.notify(format!("{name}: {e}"), true);
                }
            },
            Finished::StepSwitched { step, result } => match result.and_then(|r| r) {
                Ok((switch, info)) => {
                    self.rt.scene_step = step;
                    if let (Some(info), Some(d)) = (info, self.rt.data.as_mut()) {
                        d.set_values(info);
                    }
                    match switch {
                        StepSwitch::Refit => self.stats.steps_refit += 1,
                        StepSwitch::Rebuilt => self.stats.steps_rebuilt += 1,
                        StepSwitch::Unchanged => {}
                    }
                }
                Err(e) => {
                    // Stay on the step the scene holds; stop playback so it does not retry.
                    let name = self.rt.data_name();
                    self.notify(format!("{name}: time step {step}: {e}"), true);
                    self.state.time.step = self.rt.scene_step;
                    self.state.time.playing = false;
                }
            },
            Finished::Prefetched { step, ok } => {
                // A failed prefetch is reported when the step is shown; mark it done so
                // playback does not wait for it.
                self.rt.prefetched.push(step);
                if ok {
                    self.stats.steps_prefetched += 1;
                }
            }
            Finished::Rendered { ticket, result } => {
                if let Ok(image) = result {
                    self.finish_render(ctx, ticket, image);
                } else {
                    self.stats.renders_discarded += 1;
                    self.notify("rendering failed (the render thread panicked)", true);
                }
            }
            Finished::Picked(command) => self.commands.extend(command),
            Finished::ScreenshotSaved(result) => match result {
                Ok(p) => self.notify(format!("screenshot saved to {}", p.display()), false),
                Err(e) => self.notify(format!("screenshot: {e}"), true),
            },
            Finished::Exported(result) => match result {
                Ok((p, summary)) => {
                    self.notify(
                        format!("isosurface exported to {}: {summary}", p.display()),
                        false,
                    );
                }
                Err(e) => self.notify(format!("export: {e}"), true),
            },
            Finished::SessionSaved(result) => match result {
                Ok(p) => self.notify(format!("session saved to {}", p.display()), false),
                Err(e) => self.notify(e, true),
            },
            Finished::SessionLoaded(result) => match result {
                Ok(session) => self.restore_session(session),
                Err(e) => self.notify(e, true),
            },
            Finished::MovieDone(result) => match result {
                Ok(text) => self.notify(text, false),
                Err(e) => self.notify(format!("movie: {e}"), true),
            },
            Finished::Probed(result) => match result {
                Ok(pick) => self.rt.pick = Some(pick),
                Err(e) => self.notify(format!("pick: {e}"), true),
            },
        }
    }

    /// The scene draws point array `name` now: the sliders take its range and histogram,
    /// and every isovalue keeps its relative position in the range.
    fn field_switched(&mut self, name: String, info: ValueInfo) {
        let Some(d) = self.rt.data.as_mut() else {
            return;
        };
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

    /// New data replaces the old: the jobs of the old data end, its frames become stale.
    fn install_data(&mut self, data: LoadedData) {
        self.rt.epoch += 1;
        self.jobs.step.cancel();
        self.jobs.field.cancel();
        self.jobs.prefetch.cancel();
        self.rt.prefetched.clear();
        self.jobs.render.cancel();
        self.rt.pending_render = None;
        // Undo history and the last pick belong to the old data.
        self.rt.history.clear();
        self.rt.pick = None;
        if let Some(p) = &data.path {
            self.prefs.remember(p);
        }
        // Scenes open at step 0; a restored session's step is then a refit away.
        self.rt.scene_step = 0;
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
        self.rt.lod = data.scene.lod_status();
        // An untouched default view (not a session's, not the user's) frames the new data.
        let untouched = self.state.camera == CameraState::default();
        self.jobs.color_volume.cancel();
        self.rt.data = Some(data);
        if untouched {
            self.state.camera = self.framed_view();
        }
        self.load_missing_color_volumes();
        self.stats.datasets_loaded += 1;
        self.stats.scenes_built += 1;
    }

    fn finish_render(
        &mut self,
        ctx: &egui::Context,
        ticket: RenderTicket,
        image: Result<Option<RenderedImage>, String>,
    ) {
        let newest_shown = self.rt.shown.as_ref().map_or(0, |s| s.generation);
        match image {
            Err(e) => {
                self.stats.renders_discarded += 1;
                self.notify(format!("rendering: {e}"), true);
            }
            Ok(Some(img)) if ticket.epoch == self.rt.epoch && ticket.generation > newest_shown => {
                let (width, height, bytes) = (img.width, img.height, img.rgba8.len());
                let size = [width as usize, height as usize];
                if ticket.request.scale == 1 {
                    self.rt.last_full_frame = Some(img.elapsed);
                }
                if let Some(color) = color_image(size, img.rgba8) {
                    let texture = match self.rt.shown.take() {
                        Some(mut s) => {
                            s.texture.set(color, TextureOptions::LINEAR);
                            s.texture
                        }
                        None => ctx.load_texture("isoscope-view", color, TextureOptions::LINEAR),
                    };
                    self.rt.shown = Some(ShownFrame {
                        generation: ticket.generation,
                        request: ticket.request,
                        texture,
                        elapsed: img.elapsed,
                        rays: img.rays,
                        size: [width, height],
                        lod_level: img.lod_level,
                        depth: img.depth,
                        scalar_bars: img.scalar_bars,
                    });
                    self.rt.shown_times.push_back(Instant::now());

                    self.stats.renders_shown += 1;
                } else {
                    self.stats.renders_discarded += 1;
                    self.notify(
                        format!("renderer returned a {width}×{height} image with {bytes} bytes"),
                        true,
                    );
                }
            }
            _ => self.stats.renders_discarded += 1,
        }
        if let Some(next) = self.rt.pending_render.take() {
            self.start_render(next);
        }
    }

    // ---- starting jobs ------------------------------------------------------------------

    /// Opens `path` (the embedded sample for `None`); on success `files` replace the
    /// session's list, so a cancelled or failed open leaves the session as it was.
    pub(super) fn start_load(
        &mut self,
        path: Option<PathBuf>,
        raw: Option<RawLayoutState>,
        files: Option<Vec<PathBuf>>,
    ) {
        self.start_load_series(path, raw, None, files);
    }

    /// [`Self::start_load`] of DICOM series `series` (a number or SeriesInstanceUID) of `path`.
    pub(super) fn start_load_series(
        &mut self,
        path: Option<PathBuf>,
        raw: Option<RawLayoutState>,
        series: Option<String>,
        files: Option<Vec<PathBuf>>,
    ) {
        let backend = Arc::clone(&self.backend);
        let label = path.as_ref().map_or_else(
            || "generating the default sample".to_string(),
            |p| format!("loading {}", p.display()),
        );
        // Another open replaces a raw open whose dialog would come back on failure.
        self.rt.raw_retry = None;
        let mut choices = self.open_choices();
        choices.dicom_series = series;
        let job = Job::spawn(label, self.repaint_fn(), move |control| match path {
            Some(p) => backend.open(&p, raw.as_ref(), choices, control),
            None => backend.default_dataset(choices, control),
        });
        self.jobs.load.start(files, job);
    }

    /// Writes the session (a snapshot of the state, written by a job; the save dialog asked
    /// before replacing a file).
    pub(super) fn start_session_save(&mut self, path: PathBuf) {
        let state = self.state.clone();
        let job = Job::spawn("saving the session", self.repaint_fn(), move |_| {
            state.save(&path).map(|()| path.clone())
        });
        self.jobs.save_session.start((), job);
    }

    /// Reads and parses a session in a job; it replaces the state when it arrives.
    pub(super) fn start_session_load(&mut self, path: PathBuf) {
        let job = Job::spawn("reading the session", self.repaint_fn(), move |_| {
            ViewerState::load(&path)
        });
        self.jobs.load_session.start((), job);
    }

    /// True when the scene holds the step the state asks for.
    pub(super) fn scene_ready(&self) -> bool {
        self.rt.data.is_some()
            && !self.jobs.step.is_running()
            && !self.jobs.field.is_running()
            && !self.movie_plays_steps()
            && self.rt.scene_step == self.state.time.step
    }

    fn start_render(&mut self, request: RenderRequest) {
        if !self.scene_ready() || request.step != self.rt.scene_step {
            return;
        }
        let Some(scene) = self.rt.data.as_ref().map(|d| Arc::clone(&d.scene)) else {
            return;
        };
        self.rt.generation += 1;
        let req = request.clone();
        let job = Job::spawn("rendering", self.repaint_fn(), move |control| {
            scene.render(&req, control.cancel_flag())
        });
        let ticket = RenderTicket {
            generation: self.rt.generation,
            epoch: self.rt.epoch,
            request,
        };
        self.jobs.render.start(ticket, job);
        self.stats.renders_started += 1;
    }

    /// A step or field switch takes the scene's write lock: stop the running frame first.
    fn stop_render_for_refit(&mut self) {
        if self.jobs.render.cancel().is_some() {
            self.stats.renders_discarded += 1;
        }
        self.rt.pending_render = None;
    }

    /// Opens `path` as a volume on the shown grid in a job, then colours surface `surface`
    /// by it.
    pub(super) fn start_color_volume(&mut self, surface: usize, path: PathBuf) {
        let Some(d) = &self.rt.data else { return };
        if self.jobs.color_volume.is_running() {
            self.notify(
                "colour by another volume: one is already being opened",
                true,
            );
            return;
        }
        let scene = Arc::clone(&d.scene);
        self.stop_render_for_refit();
        let job = Job::spawn(
            format!("opening {} to colour by", path.display()),
            self.repaint_fn(),
            move |control| scene.add_color_volume(&path, control),
        );
        self.jobs.color_volume.start(surface, job);
    }

    /// Grids: opens (one at a time) the volumes a restored session colours surfaces by that
    /// the scene does not hold yet.
    pub(super) fn load_missing_color_volumes(&mut self) {
        let Some(d) = &self.rt.data else { return };
        if !d.gradient_coloring || self.jobs.color_volume.is_running() {
            return;
        }
        let missing = self.state.surfaces.iter().enumerate().find_map(|(i, s)| {
            match s.color_by.as_ref().map(|c| &c.field) {
                Some(volume_core::render::ColorField::Field(name))
                    if !d.color_fields.contains(name) =>
                {
                    Some((i, PathBuf::from(name)))
                }
                _ => None,
            }
        });
        if let Some((i, path)) = missing {
            self.start_color_volume(i, path);
        }
    }

    /// Draws another point array of a mesh (a value refit in a job; renders wait for it).
    pub(super) fn start_field_switch(&mut self, name: String) {
        let Some(d) = &self.rt.data else { return };
        if d.field.as_deref() == Some(name.as_str()) || self.jobs.field.is_running() {
            return;
        }
        if !d.fields.contains(&name) {
            let text = format!("{}: no point array \"{name}\"", d.name);
            self.notify(text, true);
            return;
        }
        let scene = Arc::clone(&d.scene);
        self.stop_render_for_refit();
        let n = name.clone();
        let job = Job::spawn(
            format!("switching to point array {name}"),
            self.repaint_fn(),
            move |control| scene.set_field(&n, control),
        );
        self.jobs.field.start(name, job);
    }

    pub(super) fn start_screenshot(
        &mut self,
        path: PathBuf,
        [width, height]: [u32; 2],
        replace: bool,
        supersample: u32,
    ) {
        let Some(mut req) = self.desired_request(1) else {
            self.notify("screenshot: nothing to render yet", true);
            return;
        };
        if !self.scene_ready() {
            self.notify("screenshot: the scene is still being prepared", true);
            return;
        }
        let Some(scene) = self.rt.data.as_ref().map(|d| Arc::clone(&d.scene)) else {
            return;
        };
        req.width = width.clamp(1, MAX_RENDER_SIDE * 4);
        req.height = height.clamp(1, MAX_RENDER_SIDE * 4);
        req.options.supersample = supersample;
        let job = Job::spawn("screenshot", self.repaint_fn(), move |control| {
            let img = scene
                .render(&req, control.cancel_flag())?
                .ok_or_else(|| "cancelled".to_string())?;
            if img.rgba8.len() != img.width as usize * img.height as usize * 4 {
                return Err("the renderer returned a wrong-sized image".to_string());
            }
            let mut img = img;
            crate::scalar_bar::composite(&mut img.rgba8, img.width, img.height, &img.scalar_bars);
            crate::output::save_rgba_image(
                &path,
                &img.rgba8,
                img.width,
                img.height,
                Replace::from_force(replace),
            )
            .map_err(|e| crate::cli::error_text(&e))?;
            Ok(path)
        });
        self.jobs.screenshot.start((), job);
    }

    /// Probes what the frame on screen shows at `at` (fractions of its width and height
    /// from the top left): the hit, the surface and the data there, in a job. A pick
    /// still running is replaced.
    pub(super) fn start_pick(&mut self, at: [f32; 2]) {
        let (Some(shown), Some(data)) = (&self.rt.shown, &self.rt.data) else {
            return;
        };
        let [w, h] = shown.size;
        if shown.depth.len() != w as usize * h as usize || w == 0 || h == 0 {
            return;
        }
        let pixel = [
            ((at[0] * w as f32) as u32).min(w - 1),
            ((at[1] * h as f32) as u32).min(h - 1),
        ];
        let t = shown.depth[(pixel[1] * w + pixel[0]) as usize];
        let request = shown.request.clone();
        let scene = Arc::clone(&data.scene);
        let job = Job::spawn("pick", self.repaint_fn(), move |_| {
            let pick = scene.pick(&request, [w, h], pixel, t)?;
            let surfaces = super::core_backend::settings(&request).surfaces;
            Ok(PickShown {
                text: format!(
                    "pixel {},{} of {w}x{h}: {}",
                    pixel[0],
                    pixel[1],
                    crate::cli::probe::pick_text(pick.as_ref(), &surfaces)
                ),
                pick,
            })
        });
        self.jobs.pick.start((), job);
    }

    /// Writes the visible surfaces with the current clips and time step as a mesh file
    /// (PLY, STL or OBJ by `path`'s extension) in a job with progress and cancel.
    pub(super) fn start_export(&mut self, path: PathBuf) {
        let Some(req) = self.desired_request(1) else {
            self.notify("export: nothing to export yet", true);
            return;
        };
        if !self.scene_ready() {
            self.notify("export: the scene is still being prepared", true);
            return;
        }
        let Some(scene) = self.rt.data.as_ref().map(|d| Arc::clone(&d.scene)) else {
            return;
        };
        let job = Job::spawn(
            "exporting the isosurface",
            self.repaint_fn(),
            move |control| {
                let summary = scene.export(&req, &path, control)?;
                Ok((path, summary))
            },
        );
        self.jobs.export.start((), job);
    }

    // ---- what the state asks for --------------------------------------------------------

    /// True while the view moves (a drag, or input within [`SETTLE`]).
    fn is_interacting(&self, ctx: &egui::Context) -> bool {
        ctx.dragged_id().is_some()
            || self
                .rt
                .last_interaction
                .is_some_and(|t| t.elapsed() < SETTLE)
    }

    /// Playback draws previews only when full frames cannot keep up: when the last
    /// full-resolution frame took longer than a step lasts at the playback rate (or none
    /// has been measured yet).
    fn playback_needs_previews(&self) -> bool {
        let t = &self.state.time;
        t.playing
            && self
                .rt
                .last_full_frame
                .is_none_or(|took| took > playback_period(t.fps))
    }

    /// Starts the step switch, render and prefetch the state asks for (module docs).
    pub(super) fn schedule(&mut self, ctx: &egui::Context) {
        self.schedule_step();
        let interacting = self.is_interacting(ctx);
        let previews = interacting || self.playback_needs_previews();
        if interacting {
            // A frame once the view settles, which starts the full-resolution refinement.
            // Asked for before anything below returns early: after keyboard input (arrows,
            // R, +/-) no pointer event follows to wake the viewer, and a coarse frame that
            // is already on screen would otherwise stay there.
            ctx.request_repaint_after(SETTLE);
        }
        let scale = if previews { INTERACTIVE_SCALE } else { 1 };
        let Some(wanted) = self.desired_request(scale) else {
            return;
        };
        if !self.scene_ready() {
            return;
        }
        let same_as = |r: &RenderRequest| *r == wanted;
        let running = self.jobs.render.meta();
        if self.rt.shown.as_ref().is_some_and(|s| same_as(&s.request))
            && running.is_none_or(|t| same_as(&t.request))
        {
            return;
        }
        if running.is_some_and(|t| same_as(&t.request)) {
            self.rt.pending_render = None;
            return;
        }
        // Out-of-core: a frame of a coarser level is still worth showing; let it finish.
        let only_lod_differs = |r: &RenderRequest| {
            RenderRequest {
                lod_levels: wanted.lod_levels,
                ..r.clone()
            } == wanted
        };
        let epoch = self.rt.epoch;
        match running {
            None => self.start_render(wanted),
            Some(t) if t.epoch == epoch && only_lod_differs(&t.request) => {
                self.rt.pending_render = Some(wanted);
            }
            Some(t) if t.request.scale == 1 || t.epoch != epoch => {
                // A full-resolution frame would arrive stale: cancel it and start over.
                self.jobs.render.cancel();
                self.stats.renders_discarded += 1;
                self.start_render(wanted);
            }
            // A coarse frame is cheap: let it finish (the user sees progress), then render
            // the newest request.
            Some(_) => self.rt.pending_render = Some(wanted),
        }
    }

    /// Switches the scene to the wanted step (a refit job) and prefetches the next ones.
    fn schedule_step(&mut self) {
        if self.movie_plays_steps() {
            return;
        }
        let Some(data) = &self.rt.data else { return };
        let scene = Arc::clone(&data.scene);
        let count = data.step_count();
        let wanted = self.state.time.step;
        if wanted != self.rt.scene_step
            && !self.jobs.step.is_running()
            && !self.jobs.field.is_running()
        {
            self.stop_render_for_refit();
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
            self.jobs.step.start(wanted, job);
            return;
        }
        if count <= 1 || self.jobs.step.is_running() || self.jobs.prefetch.is_running() {
            return;
        }
        let mut t = self.state.time;
        for _ in 0..PREFETCH_AHEAD {
            let Some(next) = t.next_step(count) else {
                return;
            };
            t.step = next;
            if next != self.rt.scene_step && !self.rt.prefetched.contains(&next) {
                let scene = Arc::clone(&scene);
                let job = Job::spawn(
                    format!("prefetching step {next}"),
                    self.repaint_fn(),
                    move |control| scene.prefetch(next, control),
                );
                self.jobs.prefetch.start(next, job);
                return;
            }
        }
    }

    /// Playback: the next step once the current one is on screen and the next is loaded.
    pub(super) fn advance_playback(&mut self, ctx: &egui::Context) {
        let Some(data) = &self.rt.data else { return };
        let count = data.step_count();
        let t = self.state.time;
        if !t.playing || count <= 1 {
            return;
        }
        let period = playback_period(t.fps);
        let since = self.rt.last_step_advance.elapsed();
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
            .rt
            .shown
            .as_ref()
            .is_some_and(|s| s.request.step == t.step);
        if shown_current && self.rt.prefetched.contains(&next) && !self.jobs.step.is_running() {
            self.state.time.step = next;
            self.rt.last_step_advance = Instant::now();
        }
        ctx.request_repaint_after(period);
    }
}

/// How long one step lasts when playing at `fps` steps per second.
fn playback_period(fps: f32) -> Duration {
    Duration::from_secs_f32(1.0 / fps.clamp(0.1, 120.0))
}
