//! # Sort-first distributed rendering over MPI
//!
//! `mpirun -n N isoscope render|bench|movie … --mpi`, or `mpirun -n N isoscope --mpi FILE`
//! for the viewer. As in the thesis' cluster runs (seed 004 §7.5.1), every rank opens the
//! same input itself from shared storage (an `.isot` is paged by each rank with its own
//! budget, so a rank holds only the treelets its tiles see), and the image is divided:
//!
//! - [`schedule`]: the image is cut into 64×64-sample chunks; rank 0 hands them out in
//!   shrinking batches, each rank starting from the chunks it had last frame;
//! - [`wire`]: the frame's job (camera, settings, step, field, intersector) and the
//!   chunks' RGBA and depth, encoded bit-exact;
//! - [`link`]: point-to-point messages, MPI (`mpi_link`, cargo feature `mpi`) or threads
//!   ([`link::LocalLink`], for tests);
//! - [`cluster`]: rank 0 — sends the job, answers requests, renders its own chunks between
//!   polls, pastes the others' in, and fails the frame naming a rank that stays silent;
//! - [`worker`]: the other ranks — open, then render batches until told to quit;
//! - [`launch`]: `--mpi` — which rank does what, and ending the job.
//!
//! Rank 0 installs its [`Cluster`] here ([`install`]); from then on
//! [`crate::scene::AnyScene::render`] sends the frames of that input to the job
//! ([`render_if_served`]), so `render`, `movie`, `bench` and the viewer need no code of
//! their own to be distributed. The picture equals a single process's bit for bit: the
//! renderer's tiles are independent and every rank traces the same rays.
//!
//! Failures: a rank that cannot open the input ends the job with its error on rank 0;
//! a rank that stops answering during a frame fails it after `--mpi-timeout`. The CLI then
//! ends every rank (MPI_Abort); the viewer says so and renders locally from then on.

pub mod cluster;
pub mod launch;
pub mod link;
#[cfg(feature = "mpi")]
pub mod mpi_link;
pub mod schedule;
pub mod wire;
pub mod worker;

use std::sync::Mutex;
use std::sync::atomic::AtomicBool;

use volume_core::render::{Camera, Frame, RenderSettings};

pub use cluster::{Cluster, FrameReport, RankReport};

use crate::scene::AnyScene;

/// Rank 0's job, when this process is one; `fallback`: on failure render locally (the
/// viewer) rather than fail the frame (the CLI).
static CLUSTER: Mutex<Option<(Cluster, bool)>> = Mutex::new(None);

/// What [`status`] reports, kept apart from [`CLUSTER`] (which a frame holds while it renders)
/// so that the viewer's status bar never waits for a frame.
static STATUS: Mutex<Option<JobStatus>> = Mutex::new(None);

fn set_status(status: Option<JobStatus>) {
    *STATUS
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner) = status;
}

/// Makes `cluster` render the frames of its input from now on.
pub fn install(cluster: Cluster, fallback: bool) {
    set_status(Some(JobStatus {
        ranks: cluster.size(),
        failure: cluster.failure().map(str::to_string),
    }));
    *CLUSTER
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner) = Some((cluster, fallback));
}

/// Removes the installed cluster (to shut it down).
pub fn uninstall() -> Option<Cluster> {
    set_status(None);
    CLUSTER
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
        .take()
        .map(|(c, _)| c)
}

/// Runs `f` on the installed cluster.
pub fn with_cluster<R>(f: impl FnOnce(&mut Cluster) -> R) -> Option<R> {
    CLUSTER
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
        .as_mut()
        .map(|(c, _)| f(c))
}

/// What the status bar shows: ranks, and why the job stopped if it did.
#[derive(Debug, Clone, PartialEq)]
pub struct JobStatus {
    pub ranks: usize,
    pub failure: Option<String>,
}

/// Never waits for a frame in progress.
pub fn status() -> Option<JobStatus> {
    STATUS
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
        .clone()
}

/// The frame of `scene` rendered by the job, if a job serves `scene`'s input: `Some(None)`
/// when it was cancelled or (CLI) failed — the failure is kept in the cluster. `None`:
/// render locally (no job, another input, or the viewer's job failed).
pub fn render_if_served(
    scene: &AnyScene,
    camera: &Camera,
    settings: &RenderSettings,
    cancel: &AtomicBool,
) -> Option<Option<Frame>> {
    let mut guard = CLUSTER
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    let (cluster, fallback) = guard.as_mut()?;
    if !cluster.serves(scene.path()) {
        return None;
    }
    let result = cluster.render(scene, camera, settings, cancel);
    if result.is_err() {
        set_status(Some(JobStatus {
            ranks: cluster.size(),
            failure: cluster.failure().map(str::to_string),
        }));
    }
    match result {
        Ok(frame) => Some(frame),
        Err(e) if *fallback => {
            eprintln!(
                "warning: MPI job: {}; rendering locally from now on",
                crate::cli::error_text(&e)
            );
            None
        }
        Err(_) => Some(None),
    }
}

#[cfg(test)]
mod tests;
