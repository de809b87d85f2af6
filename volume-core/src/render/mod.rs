//! Rendering: the [`scene::IsoScene`] contract that acceleration structures implement, and
//! the renderer built on it.

pub mod scene;

pub use scene::{CountStats, Hit, IsoScene, NoStats, Stats, TraversalCounts};
