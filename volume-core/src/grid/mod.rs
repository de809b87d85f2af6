//! Rectilinear grids as ray-traceable isosurface scenes (thesis seed 004 ch. 6–7), the
//! counterpart of [`crate::tet`] for tetrahedral meshes.
//!
//! - [`scene`]: [`GridScene<T>`] (voxels of native type `T`, the implicit min/max
//!   [`crate::kdtree`], a cell intersector) and [`AnyGridScene`], one of those for whatever
//!   voxel type a volume has; a time step refits or rebuilds it ([`StepSwitch`]).
//! - [`dda`]: [`DdaScene`], the brute-force 3D-DDA walk over the same cells: the test oracle
//!   of the kd-tree and the baseline of `isoscope bench`.
//! - [`normals`]: shading normals from central differences (§6.4) and [`make_hit`], which
//!   turns a cell hit into a world-space [`crate::render::Hit`]; shared by both scenes above
//!   and the out-of-core scene ([`crate::ooc`]).
//!
//! Dependencies run one way: `scene` → `dda` → `normals`.

pub mod dda;
pub mod normals;
pub mod scene;

pub use dda::DdaScene;
pub use normals::{make_hit, normal_at};
pub use scene::{AnyGridScene, GridScene, StepSwitch};
