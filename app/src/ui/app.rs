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
use super::panels::{self, Prefs, ReopenLast};
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
        let given = !files.is_empty();
        let mut app = Self::with_backend(&cc.egui_ctx, Arc::new(CoreBackend), files);
        app.start_with_prefs(prefs, given);
        app
    }

    /// Takes the preferences saved by an earlier run; without files given, reopens the
    /// last session or offers to ([`ReopenLast`]).
    pub fn start_with_prefs(&mut self, prefs: Prefs, files_given: bool) {
        self.prefs = prefs;
        let Some(last) = self.prefs.last_session.clone() else {
            return;
        };
        if files_given || last.files.is_empty() {
            return;
        }
        match self.prefs.reopen_last {
            ReopenLast::Always => {
                self.commands.retain(|c| *c != Command::OpenDefault);
                self.restore_session(last);
            }
            ReopenLast::Ask => self.rt.reopen_offer = Some(last),
            ReopenLast::Never => {}
        }
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

    /// Keeps the state as the session to reopen next time, when it shows files (the
    /// embedded sample is not worth reopening; an earlier session stays).
    pub fn remember_session(&mut self) {
        if !self.state.files.is_empty() {
            self.prefs.last_session = Some(self.state.clone());
        }
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

    /// Where the image is drawn, in points (tests click into it).
    pub fn viewport_rect(&self) -> egui::Rect {
        self.rt.viewport_rect
    }

    /// The last pick (a click on the image) and what it found.
    pub fn pick(&self) -> Option<&super::runtime::PickShown> {
        self.rt.pick.as_ref()
    }

    /// Whether undo would change the view now.
    pub fn can_undo(&self) -> bool {
        self.rt.history.can_undo(&self.state)
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
            normals: self.state.render.normals,
            field: self.state.field.clone(),
            dicom_series: None,
            spacing: self.state.tiff_spacing,
        }
    }
}

impl ViewerApp {
    /// Ctrl+Z undoes, Ctrl+Shift+Z or Ctrl+Y redoes, unless a text field has the keys
    /// (it has its own undo).
    fn undo_keys(&mut self, ctx: &egui::Context) {
        if ctx.memory(|m| m.focused().is_some()) {
            return;
        }
        let (undo, redo) = ctx.input_mut(|i| {
            use egui::{Key, KeyboardShortcut, Modifiers};
            let redo = i.consume_shortcut(&KeyboardShortcut::new(
                Modifiers::COMMAND | Modifiers::SHIFT,
                Key::Z,
            )) || i.consume_shortcut(&KeyboardShortcut::new(Modifiers::COMMAND, Key::Y));
            let undo = i.consume_shortcut(&KeyboardShortcut::new(Modifiers::COMMAND, Key::Z));
            (undo, redo)
        });
        if redo || undo {
            self.push(if redo { Command::Redo } else { Command::Undo });
            ctx.request_repaint();
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
        self.undo_keys(&ctx);
        if self.rt.history.feed(ctx.input(|i| i.time), &self.state) {
            // Without further input the edit still becomes an undo point.
            let stable = super::history::STABLE_S + 0.05;
            ctx.request_repaint_after(std::time::Duration::from_secs_f32(stable));
        }
    }

    fn save(&mut self, storage: &mut dyn eframe::Storage) {
        self.remember_session();
        eframe::set_value(storage, PREFS_KEY, &self.prefs);
    }
}
