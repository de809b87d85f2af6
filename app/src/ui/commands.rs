//! User intents: panels, keys, the menu and finished file dialogs push a [`Command`]; the
//! viewer applies the queue at the start of the next frame (`ViewerApp::apply_commands`),
//! before anything is drawn, so a frame always draws one consistent state.
//!
//! Edits without side effects (a slider's isovalue, a checkbox) change the
//! [`ViewerState`] directly instead; the next render request follows from it.

use std::path::PathBuf;
use std::sync::Arc;
use std::time::Instant;

use super::app::ViewerApp;
use super::backend::LoadedData;
use super::file_browser::{BrowsePurpose, FileBrowser};
use super::files::{
    FileGroup, absolute_path, group_files, guess_raw_layout, is_session_file, needs_raw_dialog,
};
use super::jobs::Job;
use super::panels;
use super::runtime::{RawDialog, SeriesDialog};
use super::state::{CameraState, RawLayoutState, ViewerState};

/// Actions with side effects, applied by the viewer at the start of a frame.
#[derive(Debug, Clone, PartialEq)]
pub enum Command {
    OpenFiles(Vec<PathBuf>),
    /// Opens a raw file with an explicit layout (from the raw dialog); `files` replace the
    /// session's list when the open succeeds (`None`: keep it).
    OpenRaw {
        path: PathBuf,
        layout: RawLayoutState,
        files: Option<Vec<PathBuf>>,
    },
    OpenDefault,
    /// Opens series `series` (a number or SeriesInstanceUID; `None`: the only one) of a DICOM
    /// input; `files` replace the session's list when the open succeeds.
    OpenSeries {
        path: PathBuf,
        series: Option<String>,
        files: Option<Vec<PathBuf>>,
    },
    /// Shows the series picker for a DICOM input of several series.
    PickSeries {
        path: PathBuf,
        series: Vec<super::backend::SeriesSummary>,
        files: Option<Vec<PathBuf>>,
    },
    /// Shows file `index` of `state.files`.
    ShowFile(usize),
    /// Tet meshes: draws another point array (a value refit, no rebuild).
    SetField(String),
    /// The file browser for a volume on the shown grid to colour surface `usize` by.
    PickColorVolume(usize),
    /// Opens `path` as a volume on the shown grid and colours surface `surface` by it.
    AddColorVolume {
        surface: usize,
        path: PathBuf,
    },
    /// The file browser for data files.
    PickFiles,
    /// The file browser for a folder (a DICOM series folder).
    PickFolder,
    AddSurface,
    RemoveSurface(usize),
    AddClipBox,
    RemoveClipBox(usize),
    AddClipPlane,
    RemoveClipPlane(usize),
    ResetView,
    /// TIFF stacks: opens the shown file again with this spacing (x, y, z) for the axes the
    /// file does not record.
    SetTiffSpacing([f64; 3]),
    /// Looks at the data from one side (anatomical when the world frame is known).
    ViewFrom(super::orientation::ViewSide),
    AddBookmark,
    SetStep(usize),
    SaveSession(PathBuf),
    LoadSession(PathBuf),
    PickSaveSession,
    PickLoadSession,
    /// Renders at `width × height` and saves a PNG; an existing file is replaced only when
    /// `replace` (the window's "Replace an existing file" box), with `supersample ×
    /// supersample` samples per pixel.
    Screenshot {
        path: PathBuf,
        width: u32,
        height: u32,
        replace: bool,
        supersample: u32,
    },
    /// Opens the file browser to choose where File → Export isosurface… writes.
    PickExportMesh,
    /// Writes the visible surfaces (current clips and time step) as a mesh file, replacing
    /// an existing one (the browser said so).
    ExportMesh(PathBuf),
    CancelJobs,
    /// Records a movie (File → Movie…).
    Movie(Box<super::movie::MovieSettings>),
    /// Restores a session held in memory (the last session, reopened).
    RestoreSession(Box<ViewerState>),
    /// Undoes the last surface, clip or camera edit ([`super::history`]).
    Undo,
    Redo,
}

impl ViewerApp {
    /// The default view framing the data shown (or the unit view without data) in the
    /// viewport ([`super::camera::framed_view`]).
    pub(super) fn framed_view(&self) -> CameraState {
        match &self.rt.data {
            Some(d) => super::camera::framed_view(&d.bounds, self.rt.viewport_px),
            None => CameraState::default(),
        }
    }

    pub(super) fn apply_commands(&mut self) {
        for cmd in std::mem::take(&mut self.commands) {
            self.apply(cmd);
        }
    }

    fn apply(&mut self, cmd: Command) {
        match cmd {
            Command::OpenDefault => self.start_load(None, None, Some(Vec::new())),
            Command::SetField(name) => self.start_field_switch(name),
            Command::OpenFiles(files) => {
                // Absolute from here on: the session's file list and the recent files must
                // name the same files from any working directory.
                let files: Vec<PathBuf> = files.iter().map(|f| absolute_path(f)).collect();
                self.open_files(&files);
            }
            Command::OpenRaw {
                path,
                layout,
                files,
            } => {
                self.state.raw_layout = Some(layout.clone());
                self.start_load(Some(path.clone()), Some(layout.clone()), files.clone());
                // After start_load (which forgets any earlier retry).
                self.rt.raw_retry = Some(RawDialog {
                    path,
                    layout,
                    files,
                    note: "as entered".to_string(),
                    error: None,
                });
            }
            Command::ShowFile(i) => {
                if let Some(p) = self.state.files.get(i).cloned() {
                    self.rt.active_file = i;
                    self.open_path(p, None);
                }
            }
            Command::OpenSeries {
                path,
                series,
                files,
            } => self.start_load_series(Some(path), None, series, files),
            Command::PickSeries {
                path,
                series,
                files,
            } => {
                self.rt.series_dialog = Some(SeriesDialog {
                    path,
                    series,
                    files,
                });
            }
            Command::PickFiles => self.open_browser(BrowsePurpose::OpenData),
            Command::PickFolder => self.open_browser(BrowsePurpose::OpenFolder),
            Command::PickColorVolume(i) => self.open_browser(BrowsePurpose::ColorVolume(i)),
            Command::AddColorVolume { surface, path } => {
                self.start_color_volume(surface, absolute_path(&path));
            }
            Command::AddSurface => {
                if let Some(d) = &self.rt.data {
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
            Command::ResetView => self.state.camera = self.framed_view(),
            Command::SetTiffSpacing(spacing) => {
                if let Some(path) = self.rt.data.as_ref().and_then(|d| d.path.clone()) {
                    self.state.tiff_spacing = Some(spacing);
                    self.open_path(path, None);
                }
            }
            Command::ViewFrom(side) => {
                let frame = self
                    .rt
                    .data
                    .as_ref()
                    .map_or(volume_core::WorldFrame::Unknown, |d| d.world_frame);
                self.state.camera.view_from(side, frame);
            }
            Command::AddBookmark => self.state.bookmarks.push(self.state.camera),
            Command::SetStep(s) => {
                let count = self.rt.data.as_ref().map_or(1, LoadedData::step_count);
                self.state.time.step = s.min(count.saturating_sub(1));
                self.rt.last_step_advance = Instant::now();
            }
            Command::SaveSession(p) => self.start_session_save(p),
            Command::LoadSession(p) => self.start_session_load(p),
            Command::PickSaveSession => self.open_browser(BrowsePurpose::SaveSession),
            Command::PickLoadSession => self.open_browser(BrowsePurpose::OpenSession),
            Command::Screenshot {
                path,
                width,
                height,
                replace,
                supersample,
            } => self.start_screenshot(path, [width, height], replace, supersample),
            Command::PickExportMesh => self.open_browser(BrowsePurpose::ExportMesh),
            Command::ExportMesh(path) => self.start_export(path),
            Command::CancelJobs => {
                // Dropping a job raises its cancel flag (the open stops at its next
                // checkpoint); the data on screen stays. A running step or field switch is
                // left to finish (a refit is short and holds the scene's lock).
                if self.jobs.load.is_running() {
                    let label = self.jobs.load.job().map(|j| j.label.clone());
                    self.jobs.load.cancel();
                    self.notify(format!("cancelled: {}", label.unwrap_or_default()), false);
                }
                self.jobs.prefetch.cancel();
                self.jobs.render.cancel();
                self.rt.pending_render = None;
                self.jobs.screenshot.cancel();
                self.jobs.movie.cancel();
                self.jobs.export.cancel();
                self.state.time.playing = false;
            }
            Command::Movie(settings) => self.start_movie(*settings),
            Command::RestoreSession(session) => {
                self.rt.reopen_offer = None;
                self.restore_session(*session);
            }
            Command::Undo => {
                if !self.rt.history.undo(&mut self.state) {
                    self.notify("nothing to undo", false);
                }
            }
            Command::Redo => {
                if !self.rt.history.redo(&mut self.state) {
                    self.notify("nothing to redo", false);
                }
            }
            Command::RemoveSurface(_) | Command::RemoveClipBox(_) | Command::RemoveClipPlane(_) => {
            }
        }
    }

    /// Opens the in-app file browser, in the shown file's folder (else the working
    /// directory).
    fn open_browser(&mut self, purpose: BrowsePurpose) {
        let folder = self
            .rt
            .data
            .as_ref()
            .and_then(|d| d.path.as_ref())
            .and_then(|p| p.parent())
            .map(std::path::Path::to_path_buf);
        self.rt.file_browser = Some(FileBrowser::new(purpose, folder));
    }

    /// Runs `ask` (a dialog, or a listing that decides what to show next) on its own
    /// thread; its answer is queued as a command.
    fn start_asking(
        &mut self,
        label: &str,
        ask: impl FnOnce() -> Option<Command> + Send + 'static,
    ) {
        let job = Job::spawn(label.to_string(), self.repaint_fn(), |_| ask());
        self.jobs.dialog.start((), job);
    }

    /// A restored session replaces the state and opens its first file (or the sample).
    pub(super) fn restore_session(&mut self, session: ViewerState) {
        let files = session.files.clone();
        let raw = session.raw_layout.clone();
        self.state = session;
        self.rt.active_file = 0;
        match files.first() {
            Some(first) if self.backend.may_hold_several_series(first) => {
                self.open_path(first.clone(), None);
            }
            first => self.start_load(first.cloned(), raw, None),
        }
    }

    /// Several files of one kind and shape open as a time series (see [`group_files`]).
    fn open_files(&mut self, files: &[PathBuf]) {
        // Another file: its own spacing (a session restores its saved one after this).
        self.state.tiff_spacing = None;
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
                self.rt.active_file = 0;
                self.open_path(p.clone(), Some(vec![p]));
            }
            FileGroup::Series { pattern, steps } => {
                // Numbered 2D TIFF files are the slices of one volume (formats::open).
                let slices = formats::series::expand_pattern(&pattern)
                    .is_ok_and(|f| formats::tiff::is_slice_stack(&f).unwrap_or(false));
                self.notify(
                    format!(
                        "opening {steps} files as {} ({})",
                        if slices {
                            "the slices of one volume"
                        } else {
                            "a time series"
                        },
                        pattern.display()
                    ),
                    false,
                );
                self.rt.active_file = 0;
                self.open_path(pattern.clone(), Some(vec![pattern]));
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
                self.rt.active_file = 0;
                self.open_path(first, Some(files));
            }
        }
    }

    /// Raw files without a JSON sidecar get the layout dialog first (which opens them with
    /// [`Command::OpenRaw`]); a DICOM input of several series gets the series picker (a job
    /// lists them first, then [`Command::PickSeries`] or [`Command::OpenSeries`]); `files`
    /// replace the session's list when the open succeeds.
    fn open_path(&mut self, path: PathBuf, files: Option<Vec<PathBuf>>) {
        if self.backend.may_hold_several_series(&path) {
            let backend = Arc::clone(&self.backend);
            let label = format!("listing the series of {}", path.display());
            self.start_asking(&label, move || {
                Some(match backend.series_to_pick(&path) {
                    Ok(Some(series)) => Command::PickSeries {
                        path,
                        series,
                        files,
                    },
                    // One series, or a listing error: the open reports what is wrong.
                    Ok(None) | Err(_) => Command::OpenSeries {
                        path,
                        series: None,
                        files,
                    },
                })
            });
        } else if needs_raw_dialog(&path) {
            let (layout, note) = guess_raw_layout(&path);
            self.rt.raw_dialog = Some(RawDialog {
                path,
                layout,
                files,
                note,
                error: None,
            });
        } else {
            self.start_load(Some(path), None, files);
        }
    }
}
