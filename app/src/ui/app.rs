//! The Isoscope viewer: the [`eframe::App`] that ties the pieces of [`crate::ui`] together.
//!
//! [`ViewerApp`] holds four things, each in its own module:
//! - the state: what the user edits ([`ViewerState`], saved in sessions, and [`Prefs`]) and
//!   what the viewer shows now ([`Runtime`]: the loaded data, the frame on screen,
//!   notifications; never saved);
//! - the [`JobTable`]: every background job, polled in one place;
//! - the [`Command`] queue: user intents pushed by panels, keys and finished dialogs;
//! - the drawing code (menu and status bars, side panels, viewport, windows), which reads
//!   the state, edits it directly where that has no side effects, and pushes commands.
//!
//! Frame loop (`eframe::App::ui` below):
//! 1. take in finished jobs ([`JobTable::next_finished`]) and the out-of-core loader's
//!    progress;
//! 2. apply queued commands;
//! 3. draw;
//! 4. derive the render request from the state and start the jobs it needs
//!    ([`crate::ui::scheduler`]): a render (cancelling a stale full-resolution one), a step
//!    switch (a refit), prefetching of the next steps; advance playback.
//!
//! The UI thread never waits and does no file I/O beyond small probes: loading, building,
//! refitting, rendering and session files all run in jobs. Render results carry a
//! generation number; results older than the frame on screen, or from data that has since
//! been replaced, are discarded.

use std::path::PathBuf;
use std::sync::Arc;

use super::backend::{Backend, CoreBackend, LoadedData, LodStatus, OpenChoices, RenderRequest};
use super::commands::Command;
use super::job_table::JobTable;
use super::panels::{self, Prefs};
use super::runtime::{Notification, Runtime, ShownFrame, ViewerStats};
use super::state::ViewerState;

const PREFS_KEY: &str = "isoscope.prefs";

/// The viewer (module docs).
pub struct ViewerApp {
    /// Persisted session state (files, camera, surfaces, clips, options, time).
    pub state: ViewerState,
    pub prefs: Prefs,
    /// Counters that tests and the status bar read.
    pub stats: ViewerStats,
    pub(super) backend: Arc<dyn Backend>,
    repaint: Arc<dyn Fn() + Send + Sync>,
    pub(super) commands: Vec<Command>,
    pub(super) rt: Runtime,
    pub(super) jobs: JobTable,
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
            stats: ViewerStats::default(),
            backend,
            repaint: Arc::new(move || ctx.request_repaint()),
            commands: Vec::new(),
            rt: Runtime::default(),
            jobs: JobTable::default(),
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
        self.rt.data.as_ref()
    }

    /// The viewport's size in pixels (the full-resolution render size).
    pub fn viewport_px(&self) -> [u32; 2] {
        self.rt.viewport_px
    }

    pub fn shown_frame(&self) -> Option<&ShownFrame> {
        self.rt.shown.as_ref()
    }

    pub fn notifications(&self) -> &[Notification] {
        &self.rt.notifications
    }

    /// Out-of-core loading progress of the shown data (polled every frame).
    pub fn lod_status(&self) -> Option<&LodStatus> {
        self.rt.lod.as_ref()
    }

    /// The time step the scene holds (it lags `state.time.step` while a refit runs).
    pub fn scene_step(&self) -> usize {
        self.rt.scene_step
    }

    /// Steps whose data has been loaded ahead of time.
    pub fn prefetched_steps(&self) -> &[usize] {
        &self.rt.prefetched
    }

    /// True while any background job runs (prefetching excepted).
    pub fn is_busy(&self) -> bool {
        self.jobs.is_busy()
    }

    /// Progress of the running open (0..1), if any.
    pub fn load_progress(&self) -> Option<f32> {
        self.jobs.load.job().map(super::jobs::Job::progress)
    }

    /// The request the current state asks for (`None` before data and a viewport exist).
    pub fn desired_request(&self, scale: u32) -> Option<RenderRequest> {
        self.rt.desired_request(&self.state, scale)
    }

    pub(super) fn notify(&mut self, text: impl Into<String>, is_error: bool) {
        self.rt.notify(text, is_error);
    }

    /// Called by a job's thread when its result is ready.
    pub(super) fn repaint_fn(&self) -> impl Fn() + Send + 'static {
        let r = Arc::clone(&self.repaint);
        move || r()
    }

    pub(super) fn open_choices(&self) -> OpenChoices {
        OpenChoices {
            intersector: self.state.render.intersector,
            smooth_normals: self.state.render.smooth_normals,
            field: self.state.field.clone(),
            dicom_series: None,
            spacing: self.state.tiff_spacing,
        }
    }
}

impl eframe::App for ViewerApp {
    fn ui(&mut self, ui: &mut egui::Ui, _frame: &mut eframe::Frame) {
        let ctx = ui.ctx().clone();
        self.poll_jobs(&ctx);
        self.handle_dropped_files(&ctx);
        self.apply_commands();

        egui::Panel::top("isoscope-menu").show(ui, |ui| self.menu_ui(ui));
        egui::Panel::bottom("isoscope-status").show(ui, |ui| self.status_ui(ui));
        if self.rt.data.as_ref().is_some_and(|d| d.step_count() > 1) {
            egui::Panel::bottom("isoscope-time").show(ui, |ui| {
                panels::time_ui(
                    ui,
                    &mut self.state,
                    self.rt.data.as_ref(),
                    &mut self.commands,
                );
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
