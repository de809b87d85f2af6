//! # isoscope (app library)
//!
//! The testable part of the `isoscope` binary: CLI commands, UI state, panels, background jobs.
