//! The viewer's background jobs in one table, polled in one place.
//!
//! Each kind of job has one [`Slot`] (at most one job of a kind runs) holding the job and
//! what the viewer needs to know about it while it runs (the step it switches to, the
//! render request, the files an open will show). [`JobTable::next_finished`] is the only
//! place results are taken out: it returns them one at a time, in a fixed order, as a
//! [`Finished`] value the viewer applies. One at a time, because applying a result can end
//! other jobs (new data drops the step switch and the render of the old data), and those
//! must not be applied after it.
//!
//! Dropping a job raises its cancel flag ([`Job`]), so clearing a slot cancels its job.

use std::path::PathBuf;
use std::time::Instant;

use crate::export::ExportSummary;

use super::backend::{LoadedData, RenderRequest, RenderedImage, StepSwitch, ValueInfo};
use super::commands::Command;
use super::jobs::{Job, take_finished};
use super::runtime::PickShown;
use super::state::ViewerState;

/// At most one running job of a kind, with what is known about it while it runs.
pub struct Slot<M, T> {
    job: Option<Job<T>>,
    /// `Some` exactly while `job` is.
    meta: Option<M>,
}

impl<M, T> Default for Slot<M, T> {
    fn default() -> Self {
        Self {
            job: None,
            meta: None,
        }
    }
}

impl<M, T> Slot<M, T> {
    /// Runs `job` in this slot; a job already here is dropped (and so cancelled).
    pub fn start(&mut self, meta: M, job: Job<T>) {
        self.job = Some(job);
        self.meta = Some(meta);
    }

    pub fn is_running(&self) -> bool {
        self.job.is_some()
    }

    pub fn meta(&self) -> Option<&M> {
        self.meta.as_ref()
    }

    pub fn job(&self) -> Option<&Job<T>> {
        self.job.as_ref()
    }

    /// Removes the job (dropping it raises its cancel flag) and returns what it was about.
    pub fn cancel(&mut self) -> Option<M> {
        self.job = None;
        self.meta.take()
    }

    /// The result of a finished job (the slot is then empty); `Err` names a worker that
    /// panicked.
    fn take_finished(&mut self) -> Option<(M, Result<T, String>)> {
        let result = take_finished(&mut self.job)?;
        Some((self.meta.take()?, result))
    }
}

/// A render job's place in the sequence of frames.
#[derive(Debug, Clone)]
pub struct RenderTicket {
    /// Increases with every render started: an older result never replaces a newer frame.
    pub generation: u64,
    /// The data epoch the render belongs to (see `Runtime::epoch`).
    pub epoch: u64,
    pub request: RenderRequest,
}

/// A step switch: the refit, then the new step's value range and histogram.
pub type StepResult = Result<(StepSwitch, Option<ValueInfo>), String>;

/// Every background job the viewer runs.
#[derive(Default)]
pub struct JobTable {
    /// Opening data and building its scene; the meta is the file list the session shows
    /// when the open succeeds (`None`: keep the session's list).
    pub load: Slot<Option<Vec<PathBuf>>, Result<LoadedData, String>>,
    /// Switching the scene to a time step (a refit holding the scene's write lock).
    pub step: Slot<usize, StepResult>,
    /// Loading a step's data ahead of time.
    pub prefetch: Slot<usize, Result<(), String>>,
    /// A mesh's point-array switch (a value refit holding the scene's write lock).
    pub field: Slot<String, Result<ValueInfo, String>>,
    /// Opening a volume to colour a surface by (the meta is the surface's index): the name
    /// to colour by and the colour fields now available.
    pub color_volume: Slot<usize, Result<(String, Vec<String>), String>>,
    pub render: Slot<RenderTicket, Result<Option<RenderedImage>, String>>,
    /// A question asked off the UI thread (listing a DICOM input's series), answering with
    /// the command to run.
    pub dialog: Slot<(), Option<Command>>,
    /// Rendering and writing a PNG.
    pub screenshot: Slot<(), Result<PathBuf, String>>,
    /// Extracting the visible surfaces and writing them as a mesh file.
    pub export: Slot<(), Result<(PathBuf, ExportSummary), String>>,
    pub save_session: Slot<(), Result<PathBuf, String>>,
    pub load_session: Slot<(), Result<ViewerState, String>>,
    /// Rendering and writing a movie's frames; the meta is true when it plays the time
    /// steps (the scene's step is then the movie's).
    pub movie: Slot<bool, Result<String, String>>,
    /// Probing what a clicked pixel shows.
    pub pick: Slot<(), Result<PickShown, String>>,
}

/// A finished job's result, for the viewer to apply. The outer `Result` of `result` is
/// `Err` when the worker panicked.
pub enum Finished {
    Loaded {
        files: Option<Vec<PathBuf>>,
        result: Result<Result<LoadedData, String>, String>,
    },
    FieldSwitched {
        name: String,
        result: Result<Result<ValueInfo, String>, String>,
    },
    ColorVolumeAdded {
        surface: usize,
        result: Result<Result<(String, Vec<String>), String>, String>,
    },
    StepSwitched {
        step: usize,
        result: Result<StepResult, String>,
    },
    Prefetched {
        step: usize,
        ok: bool,
    },
    Rendered {
        ticket: RenderTicket,
        result: Result<Result<Option<RenderedImage>, String>, String>,
    },
    /// A question answered (`None`: nothing to do).
    Picked(Option<Command>),
    ScreenshotSaved(Result<PathBuf, String>),
    Exported(Result<(PathBuf, ExportSummary), String>),
    SessionSaved(Result<PathBuf, String>),
    SessionLoaded(Result<ViewerState, String>),
    Probed(Result<PickShown, String>),
    MovieDone(Result<String, String>),
}

impl JobTable {
    /// The next finished job, if any (module docs: call until `None`, applying each).
    pub fn next_finished(&mut self) -> Option<Finished> {
        if let Some((files, result)) = self.load.take_finished() {
            return Some(Finished::Loaded { files, result });
        }
        if let Some((name, result)) = self.field.take_finished() {
            return Some(Finished::FieldSwitched { name, result });
        }
        if let Some((step, result)) = self.step.take_finished() {
            return Some(Finished::StepSwitched { step, result });
        }
        if let Some((surface, result)) = self.color_volume.take_finished() {
            return Some(Finished::ColorVolumeAdded { surface, result });
        }
        if let Some((step, result)) = self.prefetch.take_finished() {
            let ok = matches!(result, Ok(Ok(())));
            return Some(Finished::Prefetched { step, ok });
        }
        if let Some((ticket, result)) = self.render.take_finished() {
            return Some(Finished::Rendered { ticket, result });
        }
        if let Some(((), result)) = self.dialog.take_finished() {
            return Some(Finished::Picked(result.ok().flatten()));
        }
        if let Some(((), result)) = self.screenshot.take_finished() {
            return Some(Finished::ScreenshotSaved(result.and_then(|r| r)));
        }
        if let Some(((), result)) = self.export.take_finished() {
            return Some(Finished::Exported(result.and_then(|r| r)));
        }
        if let Some(((), result)) = self.save_session.take_finished() {
            return Some(Finished::SessionSaved(result.and_then(|r| r)));
        }
        if let Some(((), result)) = self.load_session.take_finished() {
            return Some(Finished::SessionLoaded(result.and_then(|r| r)));
        }
        if let Some((_, result)) = self.movie.take_finished() {
            return Some(Finished::MovieDone(result.and_then(|r| r)));
        }
        if let Some(((), result)) = self.pick.take_finished() {
            return Some(Finished::Probed(result.and_then(|r| r)));
        }
        None
    }

    /// True while a job runs that the user waits for (prefetching and dialogs excepted).
    pub fn is_busy(&self) -> bool {
        self.load.is_running()
            || self.step.is_running()
            || self.field.is_running()
            || self.color_volume.is_running()
            || self.render.is_running()
            || self.screenshot.is_running()
            || self.movie.is_running()
            || self.export.is_running()
            || self.save_session.is_running()
            || self.load_session.is_running()
    }

    /// True while a job runs that the Cancel button stops.
    pub fn is_cancellable(&self) -> bool {
        self.load.is_running()
            || self.prefetch.is_running()
            || self.screenshot.is_running()
            || self.movie.is_running()
            || self.export.is_running()
    }

    /// The status bar's rows: label, progress in [0, 1] and start of every job shown there.
    pub fn progress_rows(&self) -> Vec<(&str, f32, Instant)> {
        fn row<M, T>(slot: &Slot<M, T>) -> Option<(&str, f32, Instant)> {
            slot.job()
                .map(|j| (j.label.as_str(), j.progress(), j.started))
        }
        [
            row(&self.load),
            row(&self.step),
            row(&self.prefetch),
            row(&self.field),
            row(&self.color_volume),
            row(&self.screenshot),
            row(&self.movie),
            row(&self.export),
            row(&self.save_session),
            row(&self.load_session),
        ]
        .into_iter()
        .flatten()
        .collect()
    }
}
