//! Isosurfaces as triangle meshes, for export (3D printing, other tools). Rendering never uses
//! them: it ray traces the exact surfaces directly.
//!
//! - [`cases`]: the marching-cubes case table, generated from the cube's faces.
//! - [`grid`]: [`grid_isosurfaces`], marching cubes over a [`crate::RectilinearVolume`] of
//!   any voxel type, one shared vertex per crossed grid edge, in world coordinates.
//! - [`tets`]: [`tet_isosurfaces`], the marching-tetrahedra isopolygons of a
//!   [`crate::tet::TetScene`] (its current step) triangulated, one shared vertex per crossed
//!   mesh edge.
//! - [`clip`]: the clip regions of the renderer applied exactly: triangles are cut at the
//!   region boundaries (convex polygon clipping; a keep-outside box is six disjoint convex
//!   pieces), and cut points are shared between the triangles that meet there.
//!
//! Both extractors use the renderer's rule for a sample exactly at the isovalue (it counts as
//! below), skip cells with a void (NaN) sample, and wind every triangle so that its
//! right-hand normal `(b − a) × (c − a)` points towards **decreasing** value: out of the
//! region above the isovalue, which is the solid's outside when the data is a density.
//! Several isovalues give one mesh; each vertex records the index of its isovalue.
//!
//! Work is checked for cancellation and reported as progress once per slab (a layer of
//! cells, a block of tets); nothing is allocated per cell.

mod builder;
pub mod cases;
pub mod clip;
pub mod grid;
pub mod tets;

use std::sync::atomic::{AtomicBool, Ordering};

use glam::DVec3;
use thiserror::Error;

pub use grid::grid_isosurfaces;
pub use tets::tet_isosurfaces;

/// An indexed triangle mesh in world coordinates.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct TriMesh {
    pub positions: Vec<[f32; 3]>,
    /// Per vertex: the index of its isovalue in the list extracted.
    pub surfaces: Vec<u32>,
    /// Vertex indices, wound with the normal towards decreasing value (module docs).
    pub triangles: Vec<[u32; 3]>,
}

impl TriMesh {
    fn point(&self, v: u32) -> DVec3 {
        DVec3::from_array(self.positions[v as usize].map(f64::from))
    }

    /// The unnormalized normal `(b − a) × (c − a)` of triangle `t` (twice its area long).
    pub fn triangle_normal(&self, t: usize) -> DVec3 {
        let [a, b, c] = self.triangles[t].map(|v| self.point(v));
        (b - a).cross(c - a)
    }

    /// Total area of the triangles (world units squared), summed in `f64`.
    pub fn area(&self) -> f64 {
        (0..self.triangles.len())
            .map(|t| 0.5 * self.triangle_normal(t).length())
            .sum()
    }

    /// Unit vertex normals: the area-weighted mean of the normals of the triangles around
    /// each vertex (zero for a vertex whose triangles all have zero area).
    pub fn vertex_normals(&self) -> Vec<[f32; 3]> {
        let mut sum = vec![DVec3::ZERO; self.positions.len()];
        for (t, tri) in self.triangles.iter().enumerate() {
            let n = self.triangle_normal(t);
            for &v in tri {
                sum[v as usize] += n;
            }
        }
        sum.iter()
            .map(|n| n.normalize_or_zero().as_vec3().to_array())
            .collect()
    }

    /// The number of undirected edges not shared by exactly two triangles: 0 for a closed
    /// (watertight) surface.
    pub fn open_edges(&self) -> usize {
        let mut edges: Vec<(u32, u32)> = self
            .triangles
            .iter()
            .flat_map(|t| [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])])
            .map(|(a, b)| (a.min(b), a.max(b)))
            .collect();
        edges.sort_unstable();
        let mut open = 0;
        let mut k = 0;
        while k < edges.len() {
            let mut n = 1;
            while k + n < edges.len() && edges[k + n] == edges[k] {
                n += 1;
            }
            if n != 2 {
                open += 1;
            }
            k += n;
        }
        open
    }
}

/// Why an extraction stopped.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum ExtractError {
    #[error("the extraction was cancelled")]
    Cancelled,
    #[error(
        "the surface has more than {} vertices, the most a mesh file indexes",
        u32::MAX
    )]
    TooManyVertices,
    #[error("isovalue {index} ({value}) is not finite")]
    Isovalue { index: usize, value: f32 },
    #[error("clip region {index}: {reason}")]
    Clip { index: usize, reason: String },
}

/// Progress and cancellation of an extraction: `cancel` is checked and `progress` (a
/// fraction in `[0, 1]`) called once per slab.
#[derive(Clone, Copy)]
pub struct Control<'a> {
    pub cancel: &'a AtomicBool,
    pub progress: &'a (dyn Fn(f32) + Sync),
}

impl std::fmt::Debug for Control<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Control")
            .field("cancel", &self.cancel)
            .finish_non_exhaustive()
    }
}

static NEVER_CANCELLED: AtomicBool = AtomicBool::new(false);
static NO_PROGRESS: fn(f32) = |_| {};

impl Control<'static> {
    /// No progress reports, never cancelled.
    pub fn none() -> Self {
        Control {
            cancel: &NEVER_CANCELLED,
            progress: &NO_PROGRESS,
        }
    }
}

impl Control<'_> {
    /// Reports `fraction` done, or `Cancelled`.
    fn checkpoint(&self, fraction: f32) -> Result<(), ExtractError> {
        if self.cancel.load(Ordering::Relaxed) {
            return Err(ExtractError::Cancelled);
        }
        (self.progress)(fraction.clamp(0.0, 1.0));
        Ok(())
    }
}

fn check_isovalues(isovalues: &[f32]) -> Result<(), ExtractError> {
    match isovalues.iter().position(|v| !v.is_finite()) {
        Some(index) => Err(ExtractError::Isovalue {
            index,
            value: isovalues[index],
        }),
        None => Ok(()),
    }
}
