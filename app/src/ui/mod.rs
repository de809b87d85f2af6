//! The viewer (`isoscope` with no subcommand), split the way rerun splits its app: state,
//! a job table polled in one place, commands applied at the start of a frame, and drawing.
//!
//! - [`app`]: the [`eframe::App`] ([`app::ViewerApp`]) and its frame loop; start here.
//! - State: [`state`] is what a session file holds (files, camera, isosurfaces, clips,
//!   render options, time) with JSON save/restore; [`runtime`] is what the viewer shows
//!   now (loaded data, the frame on screen, notifications), never saved.
//! - Jobs: [`jobs`] runs one computation on a std thread with progress and cancel;
//!   [`job_table`] holds every running job and hands finished ones back, in order;
//!   [`scheduler`] decides which jobs the state asks for and applies their results.
//! - Commands: [`commands`] holds the user intents queued by panels, keys and dialogs;
//!   [`history`] is the undo/redo of surface, clip and camera edits.
//! - Drawing: [`panels`] (side-panel sections), [`bars`] (menu and status bar),
//!   [`viewport`] (the image, mouse and keys), [`windows`] (dialogs, notifications),
//!   [`movie`] (File → Movie…: orbit or time-series frames and MP4, in a job),
//!   [`file_browser`] (the in-app Open/Save browser: no desktop portal needed).
//! - The library link: [`backend`] (open files, build scenes, render, behind a trait so
//!   tests drive the real UI with a recording double) and [`core_backend`] (the real one).
//! - Helpers: [`files`] (numbered files become a time series; session and raw probes),
//!   [`camera`] (orbit camera → world pose, projection of world points into the image),
//!   [`orientation`] (anatomical view presets and the orientation marker),
//!   [`frame_upload`] (the rendered frame into a texture without a per-pixel pass).

pub mod app;
pub mod backend;
pub mod bars;
pub mod camera;
pub mod commands;
pub mod core_backend;
pub mod file_browser;
pub mod files;
pub mod frame_upload;
pub mod history;
pub mod job_table;
pub mod jobs;
pub mod movie;
pub mod orientation;
pub mod panels;
pub mod runtime;
pub mod scheduler;
pub mod state;
pub mod viewport;
pub mod windows;
