//! # isoscope (app library)
//!
//! The testable part of the `isoscope` binary.
//!
//! - [`cli`]: the subcommands (`info`, `generate`, `render`, `bench`, ...), each a module with
//!   clap `Args` and a `run` function, so tests call them without spawning a process.

pub mod cli;
