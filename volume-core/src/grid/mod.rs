//! Rectilinear grids as ray-traceable isosurface scenes (thesis seed 004 ch. 6–7), the
//! counterpart of [`crate::tet`] for tetrahedral meshes.
//!
//! - [`scene`]: [`GridScene<T>`] (voxels of native type `T`, the implicit min/max
//!   [`crate::kdtree`], a cell intersector) and [`AnyGridScene`], one of those for whatever
//!   voxel type a volume has; a time step refits or rebuilds it ([`StepSwitch`]).
//! - [`dda`]: [`DdaScene`], the brute-force 3D-DDA walk over the same cells: the test oracle
//!   of the kd-tree and the baseline of `isoscope bench`.
//! - [`hit`]: the first-hit loop shared by both scenes above and the out-of-core scene
//!   ([`crate::ooc`]): world ray to traversal units, a [`CellTrace`]'s cell hit, and
//!   [`make_hit`], the world-space [`crate::render::Hit`] with its normal.
//! - [`normals`]: shading normals from central differences (§6.4).
//! - [`sample`]: values and gradient magnitudes at hit positions, for surfaces coloured by
//!   another field.
//!
//! Dependencies run one way: `scene` → `dda` → `hit` → `normals`; `sample` → `normals`.

pub mod dda;
pub mod hit;
pub mod normals;
pub mod sample;
pub mod scene;

pub use dda::DdaScene;
pub use hit::{CellBlock, CellTrace, make_hit};
pub use normals::{LaneNormals, normal_at, normals_x8};
pub use sample::{GridField, GridQuantity, VolumeSampler, gradient_magnitude_range};
pub use scene::{AnyGridScene, GridScene, StepSwitch};
