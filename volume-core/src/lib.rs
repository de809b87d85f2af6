//! # volume-core
//!
//! The format-free, GUI-free heart of Isoscope.
//!
//! - [`voxel`]: the native voxel types (`u8` stays `u8`) and the [`Voxel`] trait that generic
//!   code (value ranges, kd-tree min/max, interpolation) is written against.
//! - [`volume`]: rectilinear grids — dimensions, per-axis coordinates, the optional
//!   `world_from_grid` affine of oriented data, and voxel storage that is either owned or
//!   borrowed from a shared byte source (a memory map made by `formats`), so opening a huge
//!   file costs no copy.
//! - [`series`]: time series whose steps load lazily through a [`series::StepLoader`].
//! - [`stats`]: value range (NaN ignored) and histograms, computed in parallel.
//! - [`math`]: bounds, rays, intervals and floating-point error bounds.
//! - [`ooc`]: out-of-core treelets (thesis §7.7–7.8): layout, quantized merged min/max tree
//!   and LOD build, loader thread, and the out-of-core `IsoScene`.
//!
//! Dependency rule: nothing here knows about files, GUIs, command lines or `anyhow`
//! (see `docs/architecture.md`).

pub mod error;
pub mod grid;
pub mod intersect;
pub mod kdtree;
pub mod math;
pub mod ooc;
pub mod render;
pub mod series;
pub mod stats;
pub mod tet;
pub mod volume;
pub mod voxel;

pub use error::VolumeError;
pub use volume::{AxisCoords, Grid, RectilinearVolume, VoxelBuffer, VoxelData};
pub use voxel::{Voxel, VoxelType};
