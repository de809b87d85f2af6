//! # isoscope (app library)
//!
//! The testable part of the `isoscope` binary.
//!
//! - [`cli`]: the subcommands (`info`, `generate`, `render`, `bench`, ...), each a module with
//!   clap `Args` and a `run` function, so tests call them without spawning a process.
//! - [`progress`]: indicatif bars that show only for long jobs on a terminal.
//! - [`scene`]: [`scene::open_scene`] opens grids, tet meshes and `.isot` files as one
//!   [`scene::AnyScene`] that the CLI and the viewer render through the same call.
//! - [`ui`]: viewer state, background jobs, panels and the backend link.
//! - [`viewer`]: the eframe app (`isoscope` with no subcommand).

pub mod cli;
pub mod progress;
pub mod scene;
pub mod ui;
pub mod viewer;
