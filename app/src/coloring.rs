//! # Surfaces coloured by another field
//!
//! A [`Surface`]'s [`ColorBy`] names the field (the renderer only describes it); here it
//! is resolved against an [`AnyScene`] into what the renderer samples at each shaded hit
//! ([`volume_core::render::SurfaceColoring`]) and what a scalar bar shows ([`ScalarBar`]):
//!
//! | scene | [`ColorField::Field`]`(name)` | [`ColorField::Gradient`] |
//! |---|---|---|
//! | tet mesh | the point array `name` at the current step, linear in the hit tet | refused (meshes colour by arrays) |
//! | grid | the volume added as `name` ([`GridData::add_color_volume`]: same dims and geometry), trilinear | the drawn field's gradient magnitude (central differences, trilinear) |
//! | `.isot` | refused | refused |
//!
//! The range is the colouring's own or, by default, the field's finite data range (for
//! the gradient, computed once per step over every voxel). Errors name the scene and list
//! what it can be coloured by.
//!
//! [`GridData::add_color_volume`]: crate::scene::GridData::add_color_volume

use anyhow::{Context as _, bail};
use volume_core::Grid;
use volume_core::render::{
    ColorBy, ColorField, Colormap, HitField, RenderSettings, Surface, SurfaceColoring,
};

use crate::scene::AnyScene;

/// What a scalar bar shows: a colouring's field, colormap and range.
#[derive(Debug, Clone, PartialEq)]
pub struct ScalarBar {
    /// The field's name ([`ColorField::label`]; a volume's file name).
    pub label: String,
    pub colormap: Colormap,
    /// `[min, max]` of the colormap's ends.
    pub range: [f32; 2],
}

/// A surface's colouring resolved against a scene for one frame.
pub struct Resolved<'a> {
    pub field: Box<dyn HitField + 'a>,
    pub colormap: Colormap,
    pub range: [f32; 2],
}

/// The renderer's view of resolved colourings (borrowing them).
pub fn as_colorings<'a>(resolved: &'a [Option<Resolved<'a>>]) -> Vec<Option<SurfaceColoring<'a>>> {
    resolved
        .iter()
        .map(|r| {
            r.as_ref().map(|r| SurfaceColoring {
                field: &*r.field,
                colormap: r.colormap,
                range: r.range,
            })
        })
        .collect()
}

/// `Ok` when `b` has `a`'s dims, sample coordinates and orientation (coordinates equal to
/// a relative 1e-6 of the extent).
pub fn check_same_grid(a: &Grid, b: &Grid) -> anyhow::Result<()> {
    let (da, db) = (a.dims(), b.dims());
    if da != db {
        bail!(
            "its dims are {}x{}x{}, not {}x{}x{}",
            db[0],
            db[1],
            db[2],
            da[0],
            da[1],
            da[2]
        );
    }
    let (lo, hi) = a.grid_bounds();
    let tol = 1e-6 * (hi - lo).length().max(1e-300);
    for axis in 0..3 {
        let n = da[axis];
        // Explicit and uniform axes with the same samples are the same geometry.
        let differs = (0..n).find(|&i| (a.axis(axis).coord(i) - b.axis(axis).coord(i)).abs() > tol);
        if let Some(i) = differs {
            bail!(
                "sample {i} along axis {} is at {} instead of {}",
                ["x", "y", "z"][axis],
                b.axis(axis).coord(i),
                a.axis(axis).coord(i)
            );
        }
    }
    match (a.world_from_grid(), b.world_from_grid()) {
        (None, None) => {}
        (Some(x), Some(y))
            if (x.matrix3 - y.matrix3)
                .to_cols_array()
                .iter()
                .all(|d| d.abs() <= 1e-9)
                && (x.translation - y.translation).length() <= tol => {}
        _ => bail!("its orientation (world_from_grid) differs"),
    }
    Ok(())
}

impl AnyScene {
    /// The named fields surfaces of this scene can be coloured by: a mesh's point arrays,
    /// a grid's added colour volumes (grids can also use [`ColorField::Gradient`]).
    pub fn color_field_names(&self) -> Vec<String> {
        match self {
            AnyScene::Tet(t) => t.field_names().into_iter().map(str::to_owned).collect(),
            AnyScene::Grid(g) => g.color_volumes().iter().map(|v| v.name.clone()).collect(),
            AnyScene::Ooc(_) => Vec::new(),
        }
    }

    /// Whether [`ColorField::Gradient`] applies (grids).
    pub fn can_color_by_gradient(&self) -> bool {
        matches!(self, AnyScene::Grid(_))
    }

    /// The field of `color_by` at this scene's hits and the range it spans.
    fn resolve(&self, color_by: &ColorBy) -> anyhow::Result<(Box<dyn HitField + '_>, [f32; 2])> {
        let path = self.path().display();
        let label = color_by.field.label();
        let (field, data_range): (Box<dyn HitField + '_>, Option<(f64, f64)>) =
            match (self, &color_by.field) {
                (AnyScene::Ooc(_), _) => bail!(
                    "{path}: an out-of-core .isot scene cannot colour a surface by another field \
                     (its finest voxels may not be in memory): colour the volume it was made from"
                ),
                (AnyScene::Tet(t), ColorField::Field(name)) => {
                    let Some(f) = t.step_field(name) else {
                        bail!(
                            "{path}: no point array \"{name}\" to colour by (available: {})",
                            t.field_names().join(", ")
                        );
                    };
                    let field = t
                        .scene()
                        .point_field(&f.values)
                        .with_context(|| format!("{path}: point array \"{name}\""))?;
                    let range = f.value_range().map(|(a, b)| (f64::from(a), f64::from(b)));
                    (Box::new(field), range)
                }
                (AnyScene::Tet(t), ColorField::Gradient) => bail!(
                    "{path}: gradient colouring is for volumes; colour a mesh by one of its point \
                     arrays (available: {})",
                    t.field_names().join(", ")
                ),
                (AnyScene::Grid(g), ColorField::Gradient) => {
                    (g.scene().gradient_field(), g.gradient_range())
                }
                (AnyScene::Grid(g), ColorField::Field(name)) => {
                    let Some(v) = g.color_volume(name) else {
                        let loaded: Vec<&str> =
                            g.color_volumes().iter().map(|v| v.name.as_str()).collect();
                        bail!(
                            "{path}: no volume \"{name}\" to colour by: colour a volume by \
                             \"gradient\" or by the path of another volume on the same grid{}",
                            if loaded.is_empty() {
                                String::new()
                            } else {
                                format!(" (loaded: {})", loaded.join(", "))
                            }
                        );
                    };
                    // A series step may have another grid than the one it was added on.
                    check_same_grid(&g.volume().grid, &v.sampler.volume().grid)
                        .with_context(|| format!("{name} no longer matches the grid of {path}"))?;
                    (v.sampler.field(), v.value_range)
                }
            };
        let range = if let Some(r) = color_by.range {
            r
        } else {
            let Some((lo, hi)) = data_range else {
                bail!("{path}: {label} has no finite value to colour by");
            };
            [lo as f32, hi as f32]
        };
        Ok((field, range))
    }

    /// Every visible surface's colouring resolved (`None` for flat surfaces and for those
    /// that do not resolve: [`Self::check_colorings`] says why).
    pub fn resolve_colorings(&self, settings: &RenderSettings) -> Vec<Option<Resolved<'_>>> {
        if settings.surfaces.iter().all(|s| s.color_by.is_none()) {
            return Vec::new();
        }
        settings
            .surfaces
            .iter()
            .map(|s| {
                let c = s.color_by.as_ref().filter(|_| s.is_active())?;
                let (field, range) = self.resolve(c).ok()?;
                Some(Resolved {
                    field,
                    colormap: c.colormap,
                    range,
                })
            })
            .collect()
    }

    /// `Ok` when every surface's colouring resolves against this scene; else the first
    /// error (naming what the scene can be coloured by).
    pub fn check_colorings(&self, settings: &RenderSettings) -> anyhow::Result<()> {
        for (i, s) in settings.surfaces.iter().enumerate() {
            if let Some(c) = &s.color_by {
                self.resolve(c)
                    .with_context(|| format!("surface {i}: colour by {}", c.field.label()))?;
            }
        }
        Ok(())
    }

    /// The scalar bars of the visible coloured surfaces that ask for one, in surface order
    /// (one per distinct field, colormap and range).
    pub fn scalar_bars(&self, settings: &RenderSettings) -> Vec<ScalarBar> {
        let mut bars: Vec<ScalarBar> = Vec::new();
        for s in &settings.surfaces {
            let Some(c) = s
                .color_by
                .as_ref()
                .filter(|c| c.scalar_bar && s.is_active())
            else {
                continue;
            };
            let Ok((_, range)) = self.resolve(c) else {
                continue;
            };
            // A volume is named by its file name, not its whole path.
            let label = match (self, &c.field) {
                (AnyScene::Grid(_), ColorField::Field(name)) => std::path::Path::new(name)
                    .file_name()
                    .map_or_else(|| name.clone(), |n| n.to_string_lossy().into_owned()),
                _ => c.field.label().to_owned(),
            };
            let bar = ScalarBar {
                label,
                colormap: c.colormap,
                range,
            };
            if !bars.contains(&bar) {
                bars.push(bar);
            }
        }
        bars
    }
}

/// Sets every surface's colouring to `color_by` (the CLI's and Python's "all surfaces").
pub fn color_all(surfaces: &mut [Surface], color_by: &ColorBy) {
    for s in surfaces {
        s.color_by = Some(color_by.clone());
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DAffine3;

    #[test]
    fn grids_must_match_in_dims_coordinates_and_orientation() {
        let a = Grid::uniform([4, 3, 2], [0.0; 3], [1.0, 2.0, 3.0]).unwrap();
        assert!(check_same_grid(&a, &a.clone()).is_ok());
        let dims = Grid::uniform([4, 3, 3], [0.0; 3], [1.0, 2.0, 3.0]).unwrap();
        let e = check_same_grid(&a, &dims).unwrap_err().to_string();
        assert!(e.contains("4x3x3") && e.contains("4x3x2"), "{e}");
        let spacing = Grid::uniform([4, 3, 2], [0.0; 3], [1.0, 2.5, 3.0]).unwrap();
        let e = check_same_grid(&a, &spacing).unwrap_err().to_string();
        assert!(e.contains("axis y"), "{e}");
        let turned = Grid::new(
            [4, 3, 2],
            a.axes().clone(),
            Some(DAffine3::from_rotation_z(0.5)),
        )
        .unwrap();
        let e = check_same_grid(&a, &turned).unwrap_err().to_string();
        assert!(e.contains("orientation"), "{e}");
    }
}
