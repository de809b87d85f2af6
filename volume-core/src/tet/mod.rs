//! Tetrahedral meshes: isosurfaces of unstructured data by ray tracing (thesis 004 ch. 8).
//!
//! - [`mesh`]: [`TetMesh`] (points, tets, named point fields), validation, and the crack-free
//!   splitting of hexahedra, wedges and pyramids that readers use.

pub mod mesh;

pub use mesh::{
    PointField, TetError, TetMesh, points_from_f64, split_hex, split_pyramid, split_wedge,
};
