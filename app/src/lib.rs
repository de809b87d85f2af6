//! # isoscope (app library)
//!
//! The testable part of the `isoscope` binary.
//!
//! - [`cli`]: the subcommands (`info`, `generate`, `render`, `bench`, ...), each a module with
//!   clap `Args` and a `run` function, so tests call them without spawning a process.
//! - [`progress`]: indicatif bars that show only for long jobs on a terminal.
//! - [`ui`]: viewer state, background jobs, panels and the backend link.
//! - [`viewer`]: the eframe app (`isoscope` with no subcommand).

pub mod cli;
pub mod progress;
pub mod ui;
pub mod viewer;
