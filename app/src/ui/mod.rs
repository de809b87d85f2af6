//! The viewer's library part, testable without a window.
//!
//! - [`state`]: the persisted session state (files, camera, isosurfaces, clips, render
//!   options, time) with JSON save/restore; no caches.
//! - [`jobs`]: background jobs on std threads with progress and cancel, polled each frame.
//! - [`backend`]: the link to the library (open files, build scenes, render) behind a trait,
//!   so tests can drive the real UI with a recording double.
//! - [`core_backend`]: the real backend (`crate::scene::open_scene`, data-samples, the
//!   renderer), with refits for time steps and the out-of-core level status.
//! - [`files`]: several files opened together become a time series when they are numbered.
//! - [`camera`]: orbit camera → world pose, and projection of world points into the image.
//! - [`panels`]: the side-panel sections as `*_ui(ui, &mut state, ...)` functions and the
//!   [`panels::Command`]s they queue.
//!
//! The eframe app that ties them together is [`crate::viewer::ViewerApp`].

pub mod backend;
pub mod camera;
pub mod core_backend;
pub mod files;
pub mod jobs;
pub mod panels;
pub mod state;
