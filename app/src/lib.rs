//! # isoscope (app library)
//!
//! The testable part of the `isoscope` binary.
//!
//! - [`cli`]: the subcommands (`info`, `generate`, `render`, `bench`, ...), each a module with
//!   clap `Args` and a `run` function, so tests call them without spawning a process.
//! - [`coloring`]: surfaces coloured by another field (a mesh array, a grid's gradient
//!   magnitude or a second volume on its grid) resolved against a scene, and
//!   [`scalar_bar`], the bar composited into image outputs.
//! - [`distributed`]: sort-first rendering over MPI (`--mpi`; the MPI link needs cargo
//!   feature `mpi`): rank 0 hands out chunks of each frame and assembles the picture.
//! - [`export`]: the visible isosurfaces as a PLY, STL or OBJ triangle mesh (CLI, viewer and
//!   Python share it).
//! - [`output`]: PNG, `.npy`, report and session outputs through `formats::output` (never
//!   over an input; atomic; `--force` to replace).
//! - [`progress`]: indicatif bars that show only for long jobs on a terminal.
//! - [`scene`]: [`scene::open_scene`] opens grids, tet meshes and `.isot` files as one
//!   [`scene::AnyScene`] that the CLI and the viewer render through the same call.
//! - [`values`]: data values printed the way their type reads (integers as integers, `f32`
//!   as the shortest decimal that reads back).
//! - `ui` (cargo feature `viewer`, on by default): the viewer (`isoscope` with no
//!   subcommand): `ui::app::ViewerApp`, its state, background jobs, commands, panels and the
//!   backend link. Without the feature the crate is the CLI and scene library alone, with no
//!   GUI dependencies (the Python package, `app/python`, builds it so).

pub mod cli;
pub mod coloring;
pub mod distributed;
pub mod export;
pub mod output;
pub mod progress;
pub mod scalar_bar;
pub mod scene;
#[cfg(feature = "viewer")]
pub mod ui;
pub mod values;
