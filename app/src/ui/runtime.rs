//! What the viewer shows and holds now, beside the persisted [`ViewerState`]: the loaded
//! data, the frame on screen, notifications, counters. Rebuilt from the state and the
//! files, never saved.

use std::collections::VecDeque;
use std::path::PathBuf;
use std::time::{Duration, Instant};

use egui::TextureHandle;

use super::backend::{LoadedData, LodStatus, RenderRequest};
use super::state::{RawLayoutState, ViewerState};

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
    /// The scalar bars of the frame's coloured surfaces (drawn over it).
    pub scalar_bars: Vec<crate::coloring::ScalarBar>,
    /// The frame's depth (ray parameter per pixel, infinite where nothing was hit), which
    /// picking reads; empty when the backend keeps none.
    pub depth: Vec<f32>,
}

/// The last pick (a click on the image): what the pick section shows and the viewport
/// marks.
#[derive(Debug, Clone, PartialEq)]
pub struct PickShown {
    /// What the pixel shows, in the CLI's words (`render --pick`).
    pub text: String,
    /// The hit (`None`: no surface there).
    pub pick: Option<crate::scene::Pick>,
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
pub struct RawDialog {
    pub path: PathBuf,
    pub layout: RawLayoutState,
    /// What the session's file list becomes when the open succeeds.
    pub files: Option<Vec<PathBuf>>,
    /// Where the starting layout came from (the sidecar, or a guess from the file size).
    pub note: String,
    /// Why the last open with this dialog's layout failed (the dialog comes back with it).
    pub error: Option<String>,
}

/// The DICOM series picker while it is open: a folder (or DICOMDIR, or file) of several
/// series.
pub struct SeriesDialog {
    pub path: PathBuf,
    pub series: Vec<super::backend::SeriesSummary>,
    /// What the session's file list becomes when the open succeeds.
    pub files: Option<Vec<PathBuf>>,
}

/// The viewer's non-persisted state (module docs).
pub struct Runtime {
    pub data: Option<LoadedData>,
    /// Bumped whenever `data` is replaced; jobs and frames of older epochs are stale.
    pub epoch: u64,
    /// The file of `state.files` shown.
    pub active_file: usize,
    /// The time step the scene holds (a step switch is a refit job).
    pub scene_step: usize,
    /// Steps of this epoch whose data is loaded ahead.
    pub prefetched: Vec<usize>,
    pub lod: Option<LodStatus>,
    /// TIFF stacks: the spacing being edited in the Data section, and the file it is for.
    pub spacing_edit: Option<(PathBuf, [f64; 3])>,
    /// The newest request, to start when the running (coarse) render finishes.
    pub pending_render: Option<RenderRequest>,
    /// Generation of the last render started.
    pub generation: u64,
    pub shown: Option<ShownFrame>,
    /// When recent frames arrived (the status bar's frames/s).
    pub shown_times: VecDeque<Instant>,
    pub raw_dialog: Option<RawDialog>,
    /// The raw dialog whose layout is being opened: shown again, with the error, if the
    /// open fails.
    pub raw_retry: Option<RawDialog>,
    /// The in-app file browser (File → Open…, sessions) while it is open.
    pub file_browser: Option<super::file_browser::FileBrowser>,
    pub series_dialog: Option<SeriesDialog>,
    pub screenshot_window: bool,
    pub movie_window: bool,
    pub notifications: Vec<Notification>,
    pub last_interaction: Option<Instant>,
    /// How long the last full-resolution frame took to render: playback draws full frames
    /// when this fits in a step's time at the playback rate, previews otherwise.
    pub last_full_frame: Option<Duration>,
    pub last_step_advance: Instant,
    /// The viewport's size in pixels (the full-resolution render size).
    pub viewport_px: [u32; 2],
    /// Where the viewport is drawn, in points.
    pub viewport_rect: egui::Rect,
    /// The last pick's answer.
    pub pick: Option<PickShown>,
    /// Undo/redo of the shown data's surface, clip and camera edits.
    pub history: super::history::History,
    /// The last session, offered in a window at start ([`super::panels::ReopenLast::Ask`]).
    pub reopen_offer: Option<ViewerState>,
}

impl Default for Runtime {
    fn default() -> Self {
        Self {
            data: None,
            epoch: 0,
            active_file: 0,
            scene_step: 0,
            prefetched: Vec::new(),
            lod: None,
            spacing_edit: None,
            pending_render: None,
            generation: 0,
            shown: None,
            shown_times: VecDeque::new(),
            raw_dialog: None,
            raw_retry: None,
            file_browser: None,
            series_dialog: None,
            screenshot_window: false,
            movie_window: false,
            notifications: Vec::new(),
            last_interaction: None,
            last_full_frame: None,
            last_step_advance: Instant::now(),
            viewport_px: [0, 0],
            viewport_rect: egui::Rect::NOTHING,
            pick: None,
            history: super::history::History::default(),
            reopen_offer: None,
        }
    }
}

/// Longest notification shown, in characters. Errors quote file contents (a section name, a
/// file name from a header); a multi-megabyte line laid out every frame stalled the viewer
/// and took gigabytes. The full text still goes to stderr.
pub const MAX_NOTIFICATION_CHARS: usize = 400;

/// `text` cut to [`MAX_NOTIFICATION_CHARS`] characters, marked with an ellipsis when cut.
pub fn shorten_notification(text: &str) -> String {
    match text.char_indices().nth(MAX_NOTIFICATION_CHARS) {
        None => text.to_owned(),
        Some((at, _)) => format!("{}… ({} more bytes)", &text[..at], text.len() - at),
    }
}

impl Runtime {
    pub fn notify(&mut self, text: impl Into<String>, is_error: bool) {
        let text = text.into();
        if is_error {
            eprintln!("isoscope: {text}");
        }
        self.notifications.push(Notification {
            text: shorten_notification(&text),
            is_error,
            created: Instant::now(),
        });
    }

    /// The shown data's name (empty before any data).
    pub fn data_name(&self) -> String {
        self.data
            .as_ref()
            .map_or_else(String::new, |d| d.name.clone())
    }

    /// The request `state` asks for (`None` before data and a viewport exist).
    pub fn desired_request(&self, state: &ViewerState, scale: u32) -> Option<RenderRequest> {
        let data = self.data.as_ref()?;
        let [w, h] = self.viewport_px;
        if w == 0 || h == 0 {
            return None;
        }
        let lod_levels = self.lod.as_ref().map_or(0, |l| l.loaded_levels);
        Some(RenderRequest::from_state(
            state,
            data,
            [w, h],
            scale,
            lod_levels,
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn long_notifications_are_cut_at_a_character_boundary() {
        let short = "v.nrrd: bad";
        assert_eq!(shorten_notification(short), short);
        let long = format!("m.msh: ${}", "é".repeat(1 << 20));
        let cut = shorten_notification(&long);
        assert_eq!(
            cut.chars().filter(|&c| c == 'é').count(),
            MAX_NOTIFICATION_CHARS - 8
        );
        assert!(
            cut.starts_with("m.msh: $") && cut.ends_with("more bytes)"),
            "{cut}"
        );
        assert!(cut.len() < 2 * MAX_NOTIFICATION_CHARS + 40);
    }
}
