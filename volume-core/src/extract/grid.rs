//! Marching cubes over a rectilinear volume, with shared vertices.
//!
//! Cells are visited layer by layer (z), row by row. The vertex on a crossed grid edge is made
//! the first time a cell needs it and its index kept in edge tables: x and y edges of the
//! layer's lower and upper sample planes and the layer's z edges, `nx·ny` entries each, so a
//! neighbouring cell reuses it (the upper plane's tables become the next layer's lower ones).
//! The vertex is the linear interpolation of the physical values (after the volume's
//! [`crate::ValueMap`]) along the edge, placed on the axis's own coordinates (uniform or
//! explicit, so non-uniform spacing is exact) and mapped by `world_from_grid`.

use glam::DVec3;

use super::builder::MeshBuilder;
use super::cases::{CASES, edge_corners};
use super::clip::prepare;
use super::{Control, ExtractError, TriMesh, check_isovalues};
use crate::render::ClipRegion;
use crate::volume::{Grid, ValueMap};
use crate::{RectilinearVolume, Voxel};

/// "No vertex yet" in the edge tables.
const NONE: u32 = u32::MAX;

/// The isosurfaces of `volume` at `isovalues` (physical values), clipped by `clips`, as one
/// mesh in world coordinates (see the [module docs](super)).
pub fn grid_isosurfaces(
    volume: &RectilinearVolume,
    isovalues: &[f32],
    clips: &[ClipRegion],
    control: &Control<'_>,
) -> Result<TriMesh, ExtractError> {
    check_isovalues(isovalues)?;
    let regions = prepare(clips)?;
    let mut builder = MeshBuilder::new(&regions);
    let n = isovalues.len().max(1) as f32;
    for (s, &iso) in isovalues.iter().enumerate() {
        builder.surface = s as u32;
        let progress = |f: f32| (control.progress)((s as f32 + f) / n);
        let control = Control {
            cancel: control.cancel,
            progress: &progress,
        };
        crate::dispatch_voxels!(&volume.data, buf => march(
            buf.as_slice(),
            &volume.grid,
            volume.value_map,
            f64::from(iso),
            &mut builder,
            &control,
        ))?;
    }
    control.checkpoint(1.0)?;
    Ok(builder.finish())
}

/// The edge tables of one layer of cells (module docs).
struct EdgeTables {
    /// x and y edges of the lower (`[0]`) and upper (`[1]`) sample plane.
    x: [Vec<u32>; 2],
    y: [Vec<u32>; 2],
    z: Vec<u32>,
}

fn march<T: Voxel>(
    voxels: &[T],
    grid: &Grid,
    value_map: ValueMap,
    iso: f64,
    builder: &mut MeshBuilder<'_>,
    control: &Control<'_>,
) -> Result<(), ExtractError> {
    let [nx, ny, nz] = grid.dims();
    if nx < 2 || ny < 2 || nz < 2 {
        return control.checkpoint(1.0);
    }
    let coords: [Vec<f64>; 3] =
        std::array::from_fn(|a| (0..grid.dims()[a]).map(|i| grid.axis(a).coord(i)).collect());
    let world = grid.world_from_grid();
    let plane = nx * ny;
    let fresh = || vec![NONE; plane];
    let mut tables = EdgeTables {
        x: [fresh(), fresh()],
        y: [fresh(), fresh()],
        z: fresh(),
    };
    // Voxel offset of each cell corner.
    let offset: [usize; 8] =
        std::array::from_fn(|c| (c & 1) + nx * (c >> 1 & 1) + plane * (c >> 2 & 1));
    for k in 0..nz - 1 {
        control.checkpoint(k as f32 / (nz - 1) as f32)?;
        if k > 0 {
            tables.x.swap(0, 1);
            tables.y.swap(0, 1);
            tables.x[1].fill(NONE);
            tables.y[1].fill(NONE);
            tables.z.fill(NONE);
        }
        for j in 0..ny - 1 {
            for i in 0..nx - 1 {
                let base = i + nx * (j + ny * k);
                let mut value = [0.0f64; 8];
                let mut void = false;
                let mut mask = 0usize;
                for c in 0..8 {
                    let v = voxels[base + offset[c]];
                    void |= v.is_void();
                    value[c] = value_map.to_physical(v.to_f64());
                    mask |= usize::from(value[c] > iso) << c;
                }
                if void || mask == 0 || mask == 255 {
                    continue;
                }
                let case = &CASES[mask];
                let mut ids = [NONE; 12];
                for tri in &case.triangles[..usize::from(case.count)] {
                    let mut t = [0u32; 3];
                    for (slot, &e) in t.iter_mut().zip(tri) {
                        let e = usize::from(e);
                        if ids[e] == NONE {
                            ids[e] = edge_vertex(
                                e,
                                [i, j, k],
                                &value,
                                iso,
                                &coords,
                                world,
                                &mut tables,
                                builder,
                            )?;
                        }
                        *slot = ids[e];
                    }
                    builder.triangle(t)?;
                }
            }
        }
    }
    Ok(())
}

/// The vertex on edge `e` of cell `cell` (from the tables, or made and recorded there).
fn edge_vertex(
    e: usize,
    cell: [usize; 3],
    value: &[f64; 8],
    iso: f64,
    coords: &[Vec<f64>; 3],
    world: Option<glam::DAffine3>,
    tables: &mut EdgeTables,
    builder: &mut MeshBuilder<'_>,
) -> Result<u32, ExtractError> {
    let [i, j, _] = cell;
    let nx = coords[0].len();
    let (axis, s) = (e / 4, e % 4);
    let (lo_bit, hi_bit) = (s & 1, s >> 1);
    let slot = match axis {
        0 => &mut tables.x[hi_bit][i + nx * (j + lo_bit)],
        1 => &mut tables.y[hi_bit][i + lo_bit + nx * j],
        _ => &mut tables.z[i + lo_bit + nx * (j + hi_bit)],
    };
    if *slot != NONE {
        return Ok(*slot);
    }
    let [a, b] = edge_corners(e);
    let t = (iso - value[a]) / (value[b] - value[a]);
    let corner = |c: usize| -> DVec3 {
        DVec3::new(
            coords[0][i + (c & 1)],
            coords[1][j + (c >> 1 & 1)],
            coords[2][cell[2] + (c >> 2 & 1)],
        )
    };
    let (pa, pb) = (corner(a), corner(b));
    let p = pa + (pb - pa) * t;
    let p = world.map_or(p, |m| m.transform_point3(p));
    let v = builder.vertex(p)?;
    *slot = v;
    Ok(v)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::Keep;
    use crate::volume::AxisCoords;
    use glam::{DAffine3, Vec3};

    const C: DVec3 = DVec3::new(10.3, 9.7, 10.1);
    const R: f64 = 7.0;

    /// The distance from `C` sampled on `grid` (as `T`, scaled by `scale`).
    fn distance_volume<T: Voxel>(grid: Grid, scale: f64) -> RectilinearVolume
    where
        crate::VoxelData: From<crate::VoxelBuffer<T>>,
    {
        let [nx, ny, nz] = grid.dims();
        let mut v = Vec::with_capacity(nx * ny * nz);
        for k in 0..nz {
            for j in 0..ny {
                for i in 0..nx {
                    let p = grid.grid_position(i, j, k);
                    v.push(T::from_f64((p - C).length() * scale));
                }
            }
        }
        RectilinearVolume::new(grid, crate::VoxelBuffer::from_vec(v).into()).unwrap()
    }

    fn sphere(n: usize) -> RectilinearVolume {
        distance_volume::<f32>(Grid::uniform([n; 3], [0.0; 3], [1.0; 3]).unwrap(), 1.0)
    }

    fn extract(v: &RectilinearVolume, iso: &[f32], clips: &[ClipRegion]) -> TriMesh {
        grid_isosurfaces(v, iso, clips, &Control::none()).unwrap()
    }

    #[test]
    fn sphere_is_closed_on_the_surface_and_has_its_area() {
        let mesh = extract(&sphere(21), &[R as f32], &[]);
        assert_eq!(mesh.open_edges(), 0, "watertight");
        // Every vertex on the sphere within linear-interpolation error (edge length 1:
        // at most 1/(8R) of chord sag plus f32 rounding).
        for p in &mesh.positions {
            let r = (DVec3::from_array(p.map(f64::from)) - C).length();
            assert!((r - R).abs() < 1.0 / (8.0 * R) + 1e-5, "r = {r}");
        }
        // Inscribed facets: slightly less than 4πr², within 2 %.
        let exact = 4.0 * std::f64::consts::PI * R * R;
        let area = mesh.area();
        assert!(area < exact && area > 0.98 * exact, "{area} vs {exact}");
        // The distance grows outward, so the normals (down the values) point inwards.
        for t in 0..mesh.triangles.len() {
            let n = mesh.triangle_normal(t);
            let centre = mesh.triangles[t]
                .iter()
                .map(|&v| DVec3::from_array(mesh.positions[v as usize].map(f64::from)))
                .sum::<DVec3>()
                / 3.0;
            assert!(
                n.dot(centre - C) <= 0.0,
                "triangle {t} faces up the gradient"
            );
        }
    }

    fn volume_of(grid: &Grid, f: impl Fn(DVec3) -> f64) -> RectilinearVolume {
        let [nx, ny, nz] = grid.dims();
        let mut v = Vec::new();
        for k in 0..nz {
            for j in 0..ny {
                for i in 0..nx {
                    v.push(f(grid.grid_position(i, j, k)) as f32);
                }
            }
        }
        RectilinearVolume::new(grid.clone(), crate::VoxelBuffer::from_vec(v).into()).unwrap()
    }

    #[test]
    fn linear_fields_give_patches_on_the_plane_facing_down_the_gradient() {
        let mut rng = crate::math::rng::Rng::new(5);
        let grid = Grid::uniform([4; 3], [0.0; 3], [1.0; 3]).unwrap();
        for _ in 0..300 {
            let mut u = || rng.unit_f64() * 2.0 - 1.0;
            let g = DVec3::new(u(), u(), u());
            let c = 1.5 * (g.x + g.y + g.z) + 0.5 * u();
            let mesh = extract(&volume_of(&grid, |p| g.dot(p)), &[c as f32], &[]);
            for p in &mesh.positions {
                let p = DVec3::from_array(p.map(f64::from));
                assert!((g.dot(p) - f64::from(c as f32)).abs() < 1e-5);
            }
            for t in 0..mesh.triangles.len() {
                let n = mesh.triangle_normal(t);
                assert!(
                    n.dot(g) <= 1e-9 * g.length(),
                    "triangle {t} faces up the gradient"
                );
            }
        }
    }

    #[test]
    fn random_fields_meet_every_case_and_give_consistently_wound_surfaces() {
        // A consistently wound surface uses each inner edge once in each direction; with the
        // linear-field test (which fixes the direction), every case is wound correctly.
        let mut rng = crate::math::rng::Rng::new(11);
        let n = 5;
        let grid = Grid::uniform([n; 3], [0.0; 3], [1.0; 3]).unwrap();
        let mut seen = [false; 256];
        for _ in 0..400 {
            let vals: Vec<f32> = (0..n * n * n).map(|_| rng.unit_f32()).collect();
            for k in 0..n - 1 {
                for j in 0..n - 1 {
                    for i in 0..n - 1 {
                        let mask = (0..8).fold(0, |m, c: usize| {
                            let idx =
                                grid.linear_index(i + (c & 1), j + (c >> 1 & 1), k + (c >> 2));
                            m | usize::from(vals[idx] > 0.5) << c
                        });
                        seen[mask] = true;
                    }
                }
            }
            let v = RectilinearVolume::new(grid.clone(), crate::VoxelBuffer::from_vec(vals).into())
                .unwrap();
            let mesh = extract(&v, &[0.5], &[]);
            let mut directed = std::collections::HashMap::new();
            for t in &mesh.triangles {
                for k in 0..3 {
                    *directed.entry((t[k], t[(k + 1) % 3])).or_insert(0) += 1;
                }
            }
            let on_boundary = |v: u32| {
                mesh.positions[v as usize]
                    .iter()
                    .any(|&x| x == 0.0 || x == (n - 1) as f32)
            };
            for (&(a, b), &count) in &directed {
                assert_eq!(
                    count, 1,
                    "edge {a}->{b} used {count} times in one direction"
                );
                let back = directed.get(&(b, a)).copied().unwrap_or(0);
                assert!(
                    back == 1 || (on_boundary(a) && on_boundary(b)),
                    "inner edge {a}->{b} has no opposite"
                );
            }
        }
        assert!(seen.iter().all(|&s| s), "every case met");
    }

    #[test]
    fn every_voxel_type_value_maps_orientation_and_explicit_axes() {
        // u8 distance ×10 with a value map back to distance: the same surface as f32.
        let g = Grid::uniform([21; 3], [0.0; 3], [1.0; 3]).unwrap();
        let reference = extract(&sphere(21), &[R as f32], &[]);
        let mapped =
            distance_volume::<u8>(g.clone(), 10.0).with_value_map(ValueMap::new(0.1, 0.0).unwrap());
        // Stored steps of 0.1 (physical): an isovalue between two steps.
        let m = extract(&mapped, &[7.05], &[]);
        assert_eq!(m.open_edges(), 0);
        let exact = 4.0 * std::f64::consts::PI * 7.05 * 7.05;
        assert!((m.area() - exact).abs() < 0.03 * exact, "{}", m.area());
        // Non-uniform x: vertices stay on the sphere (the axis coordinates are used).
        let xs: Vec<f64> = (0..21)
            .map(|i| f64::from(i) + 0.3 * f64::from(i % 2))
            .collect();
        let u = AxisCoords::Uniform {
            origin: 0.0,
            spacing: 1.0,
        };
        let g2 = Grid::new(
            [21; 3],
            [AxisCoords::Explicit(xs.into()), u.clone(), u],
            None,
        )
        .unwrap();
        let m2 = extract(&distance_volume::<f64>(g2, 1.0), &[R as f32], &[]);
        assert_eq!(m2.open_edges(), 0);
        for p in &m2.positions {
            let r = (DVec3::from_array(p.map(f64::from)) - C).length();
            assert!((r - R).abs() < 0.05, "r = {r}");
        }
        // world_from_grid: positions are mapped (a translation here).
        let shift = DVec3::new(100.0, -50.0, 3.0);
        let g3 = Grid::new(
            [21; 3],
            g.axes().clone(),
            Some(DAffine3::from_translation(shift)),
        )
        .unwrap();
        let m3 = extract(&distance_volume::<f32>(g3, 1.0), &[R as f32], &[]);
        assert_eq!(m3.positions.len(), reference.positions.len());
        for (a, b) in m3.positions.iter().zip(&reference.positions) {
            let d = DVec3::from_array(a.map(f64::from)) - DVec3::from_array(b.map(f64::from));
            assert!((d - shift).length() < 1e-4);
        }
    }

    #[test]
    fn several_isovalues_give_one_mesh_with_surface_indices() {
        let v = sphere(21);
        let one = extract(&v, &[4.0], &[]);
        let two = extract(&v, &[R as f32], &[]);
        let both = extract(&v, &[4.0, R as f32], &[]);
        assert_eq!(
            both.triangles.len(),
            one.triangles.len() + two.triangles.len()
        );
        let first = both.surfaces.iter().filter(|&&s| s == 0).count();
        assert_eq!(first, one.positions.len());
        assert_eq!(both.surfaces.len() - first, two.positions.len());
    }

    #[test]
    fn clipping_cuts_exactly_and_keeps_shared_vertices() {
        let v = sphere(21);
        let whole = extract(&v, &[R as f32], &[]);
        // A plane through the centre keeps half the area; the cut is a closed circle of
        // boundary edges on the plane.
        let half = extract(
            &v,
            &[R as f32],
            &[ClipRegion::Plane {
                normal: Vec3::X,
                offset: C.x as f32,
            }],
        );
        assert!((half.area() / whole.area() - 0.5).abs() < 0.02);
        for p in &half.positions {
            assert!(f64::from(p[0]) <= C.x + 1e-5);
        }
        assert!(half.open_edges() > 0);
        // A keep-inside box and the keep-outside box with the same corners split the area
        // exactly in two (the cut points are shared, the pieces do not overlap).
        let (min, max) = (Vec3::new(5.0, 3.0, 4.0), Vec3::new(12.5, 11.0, 20.0));
        let inside = extract(
            &v,
            &[R as f32],
            &[ClipRegion::Box {
                min,
                max,
                keep: Keep::Inside,
            }],
        );
        let outside = extract(
            &v,
            &[R as f32],
            &[ClipRegion::Box {
                min,
                max,
                keep: Keep::Outside,
            }],
        );
        let sum = inside.area() + outside.area();
        assert!((sum - whole.area()).abs() < 1e-6 * whole.area(), "{sum}");
        for p in &inside.positions {
            let p = Vec3::from_array(*p);
            assert!(p.cmpge(min - 1e-5).all() && p.cmple(max + 1e-5).all());
        }
        for p in &outside.positions {
            let p = Vec3::from_array(*p);
            assert!(
                p.cmple(min + 1e-5).any() || p.cmpge(max - 1e-5).any(),
                "{p}"
            );
        }
        // Inside the keep-outside result, every edge not on the box is shared twice: the
        // cut introduced no cracks.
        let on_box =
            |p: Vec3| (0..3).any(|a| (p[a] - min[a]).abs() < 1e-4 || (p[a] - max[a]).abs() < 1e-4);
        let mut count = std::collections::HashMap::new();
        for t in &outside.triangles {
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                *count.entry((a.min(b), a.max(b))).or_insert(0) += 1;
            }
        }
        for (&(a, b), &n) in &count {
            let (pa, pb) = (
                Vec3::from_array(outside.positions[a as usize]),
                Vec3::from_array(outside.positions[b as usize]),
            );
            if !(on_box(pa) && on_box(pb)) {
                assert_eq!(n, 2, "edge {pa} {pb}");
            }
        }
    }

    #[test]
    fn void_cells_are_skipped_and_cancel_stops() {
        let mut v = sphere(21);
        let whole = extract(&v, &[R as f32], &[]);
        let mut vals: Vec<f32> = crate::dispatch_voxels!(&v.data, b => b.as_slice().iter().map(|x| x.to_f32()).collect());
        let hole = v.grid.linear_index(17, 10, 10);
        vals[hole] = f32::NAN;
        v = RectilinearVolume::new(v.grid.clone(), crate::VoxelBuffer::from_vec(vals).into())
            .unwrap();
        let holed = extract(&v, &[R as f32], &[]);
        assert!(holed.triangles.len() < whole.triangles.len());
        assert!(holed.open_edges() > 0);
        let cancel = std::sync::atomic::AtomicBool::new(true);
        let control = Control {
            cancel: &cancel,
            progress: &|_| {},
        };
        assert_eq!(
            grid_isosurfaces(&v, &[1.0], &[], &control),
            Err(ExtractError::Cancelled)
        );
        assert!(matches!(
            grid_isosurfaces(&v, &[f32::NAN], &[], &Control::none()),
            Err(ExtractError::Isovalue { index: 0, .. })
        ));
    }
}
