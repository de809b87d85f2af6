//! Tetrahedral meshes: isosurfaces of unstructured data by ray tracing (thesis 004 ch. 8).
//!
//! - [`mesh`]: [`TetMesh`] (points, tets, named point fields), validation, and the crack-free
//!   splitting of hexahedra, wedges and pyramids that readers use.
//! - [`mt`]: the 16-case marching-tetrahedra table, isopolygon extraction with bit-identical
//!   shared vertices, and the watertight ray–isopolygon test (§8.2), plus its `f64` twin.
//! - [`bvh`]: the implicit min/max BVH with 4D bounds: BIH-style and binned-SAH builders,
//!   parallel refit, `validate()` (§8.4.1, §8.5.2).
//! - [`traverse`]: single-ray and 16×16 packet traversal with implicit isorange culling,
//!   speculative first-active descent, interval frustum culling and first-active tracking
//!   (§8.4.2), isopolygon frustum culling (§8.2.3).
//! - `leaf_cache`: the per-thread cache of visited leaves' isopolygons that the large
//!   packets read instead of extracting them again, kept across frames at the same
//!   isovalues.
//! - [`scene`]: [`TetScene`], the [`crate::render::IsoScene`] the renderer draws, with
//!   faceted or smooth normals (§8.3), scalar/position refits for time steps (§8.5) and the
//!   brute-force twin; [`TetField`], another point array sampled at hits (colouring).
//! - [`steps`]: [`TetSteps`], time-varying meshes with a per-step BVH or one refit BVH (§8.5).

pub mod bvh;
mod leaf_cache;
pub mod mesh;
pub mod mt;
pub mod probe;
pub mod scene;
mod simd;
pub mod steps;
pub mod traverse;

pub use bvh::{BvhBuilder, BvhInfo, BvhNode, BvhOptions, TetBvh};
pub use mesh::{
    PointField, TetError, TetMesh, lattice_tets, points_from_f64, split_hex, split_pyramid,
    split_wedge,
};
pub use probe::{TetProbe, probe_tets};
pub use scene::{TetField, TetIsovalues, TetScene};
pub use steps::{StepScheme, TetStep, TetSteps};
pub use traverse::{MAX_PACKET, RawHit};
