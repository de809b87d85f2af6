//! Exporting the visible isosurfaces of a scene as a triangle mesh file (PLY, STL, OBJ): the
//! one path the CLI (`isoscope export`), the viewer (File → Export isosurface…) and Python
//! (`Scene.export`) share.
//!
//! Grids (the current step's volume) go through marching cubes and meshes (the current
//! step's positions and drawn array) through marching tetrahedra
//! ([`volume_core::extract`]); the clip regions cut the triangles exactly. Out-of-core
//! `.isot` files hold no full-resolution volume in memory and are refused.

use std::path::Path;
use std::sync::atomic::AtomicBool;

use anyhow::{Context as _, bail};
use formats::output::Replace;
use formats::trimesh::{TriMeshFormat, TriMeshOptions, write_trimesh};
use volume_core::extract::{Control, ExtractError, TriMesh, grid_isosurfaces, tet_isosurfaces};
use volume_core::render::{ClipRegion, Surface};

use crate::scene::{AnyScene, Cancelled};

/// What an export wrote.
#[derive(Debug, Clone, PartialEq)]
pub struct ExportSummary {
    pub format: TriMeshFormat,
    pub vertices: usize,
    pub triangles: usize,
    /// Total triangle area, world units squared.
    pub area: f64,
}

impl std::fmt::Display for ExportSummary {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} vertices, {} triangles, area {}",
            self.vertices,
            self.triangles,
            crate::values::ValueFormat::F64.value(self.area)
        )
    }
}

/// The triangles of the active `surfaces` of `scene` (in their order; see
/// [`Surface::is_active`]) clipped by `clips`. `progress` gets the fraction done; a raised
/// `cancel` stops the work with a [`Cancelled`] error.
pub fn extract_mesh(
    scene: &AnyScene,
    surfaces: &[Surface],
    clips: &[ClipRegion],
    cancel: &AtomicBool,
    progress: &(dyn Fn(f32) + Sync),
) -> anyhow::Result<TriMesh> {
    let isovalues: Vec<f32> = active(surfaces).map(|s| s.isovalue).collect();
    let control = Control { cancel, progress };
    let result = match scene {
        AnyScene::Grid(g) => grid_isosurfaces(g.volume(), &isovalues, clips, &control),
        AnyScene::Tet(t) => tet_isosurfaces(t.scene(), &isovalues, clips, &control),
        AnyScene::Ooc(_) => bail!(
            "{}: an out-of-core .isot file cannot be exported (it holds no full-resolution \
             volume in memory); export the volume it was made from",
            scene.path().display()
        ),
    };
    match result {
        Ok(mesh) => Ok(mesh),
        Err(ExtractError::Cancelled) => Err(Cancelled.into()),
        Err(e) => {
            Err(e).with_context(|| format!("{}: extracting the isosurface", scene.path().display()))
        }
    }
}

fn active(surfaces: &[Surface]) -> impl Iterator<Item = &Surface> {
    surfaces.iter().filter(|s| s.is_active())
}

/// Extracts ([`extract_mesh`]) and writes the mesh to `path` (format by extension; PLY
/// vertex colours are the surfaces' colours; `normals` adds vertex normals to PLY and OBJ).
pub fn export_mesh(
    scene: &AnyScene,
    surfaces: &[Surface],
    clips: &[ClipRegion],
    path: &Path,
    normals: bool,
    replace: Replace,
    cancel: &AtomicBool,
    progress: &(dyn Fn(f32) + Sync),
) -> anyhow::Result<ExportSummary> {
    // A bad output is said before the work: an input, an existing file, an unknown type.
    formats::output::check_output(path, replace)?;
    TriMeshFormat::for_path(path)?;
    if active(surfaces).next().is_none() {
        bail!("no visible isosurface to export");
    }
    let mesh = extract_mesh(scene, surfaces, clips, cancel, progress)?;
    let colors: Vec<[f32; 3]> = active(surfaces).map(|s| s.color).collect();
    let options = TriMeshOptions {
        normals,
        surface_colors: &colors,
    };
    let format = write_trimesh(path, &mesh, &options, replace)?;
    Ok(ExportSummary {
        format,
        vertices: mesh.positions.len(),
        triangles: mesh.triangles.len(),
        area: mesh.area(),
    })
}
