//! # volume-core
//!
//! The format-free, GUI-free heart of Isoscope: volumes, their acceleration structures, and
//! the one renderer that draws them. A tour, from the data up:
//!
//! - [`voxel`]: the native voxel types (`u8` stays `u8`), the [`Voxel`] trait that generic
//!   code (value ranges, kd-tree min/max, interpolation) is written against, and the one
//!   list of the eight types every per-type enum and match is generated from
//!   ([`for_each_voxel_type!`], [`voxel_enum!`], [`match_voxel!`]).
//! - [`volume`]: rectilinear grids — dimensions, per-axis coordinates, the optional
//!   `world_from_grid` affine of oriented data, and voxel storage that is either owned or
//!   borrowed from a shared byte source (a memory map made by `formats`), so opening a huge
//!   file costs no copy.
//! - [`series`]: time series whose steps load lazily through a [`series::StepLoader`].
//! - [`stats`]: value range (NaN ignored) and histograms, computed in parallel.
//! - [`error`]: [`VolumeError`], inconsistent parts of a volume.
//! - [`math`]: bounds, rays, intervals and floating-point error bounds.
//! - [`intersect`]: the ray–isosurface test inside one trilinear cell (five intersectors,
//!   thesis seed 004 §7.2.2), traversal units ([`intersect::TraversalFrame`]), and the
//!   accuracy harness against the `f64` reference.
//! - [`kdtree`]: the implicit min/max kd-tree over a grid's cells (§7.1–7.3, §7.6): build,
//!   refit, single-ray and SIMD packet traversal sharing one robust child-ordering step.
//! - [`grid`]: rectilinear grids as scenes: [`grid::GridScene`] (kd-tree + intersector),
//!   [`grid::AnyGridScene`] for any voxel type, the brute-force DDA twin, and the shading
//!   normals (§6.4).
//! - [`ooc`]: out-of-core treelets (§7.7–7.8): layout, quantized merged min/max tree
//!   and LOD build, loader thread, and the out-of-core scene.
//! - [`tet`]: tetrahedral meshes (ch. 8): marching-tetrahedra isopolygons, the implicit
//!   min/max BVH, large-packet traversal, time steps.
//! - [`extract`]: isosurfaces as triangle meshes for export (marching cubes on grids,
//!   marching tetrahedra on meshes, clipped exactly); rendering never uses them.
//! - [`render`]: the [`render::IsoScene`] contract every scene above implements, and the
//!   renderer on it (camera, clip regions, transparency, shadows, progressive frames).
//!
//! Layering inside the crate: `voxel`, `math` → `volume`, `stats`, `series` → `intersect` →
//! `kdtree` → `grid` → `ooc` (only the accuracy harness, `intersect::accuracy`, reaches up to
//! trace whole grid scenes); `tet` stands beside `grid`; `extract` reads volumes, tet scenes
//! and the clip regions of `render`'s settings, and nothing depends on it; the scenes
//! implement `render`'s contract, and `render` knows none of them.
//!
//! Dependency rule: nothing here knows about files, GUIs, command lines or `anyhow`
//! (see `docs/architecture.md`).

pub mod error;
pub mod extract;
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
pub use volume::{
    AxisCoords, Grid, RectilinearVolume, ValueMap, VoxelBuffer, VoxelData, WorldFrame,
};
pub use voxel::{Voxel, VoxelType};
