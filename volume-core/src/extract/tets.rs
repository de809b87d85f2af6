//! Marching tetrahedra over a tet scene, triangulated, with shared vertices.
//!
//! Each tet's isopolygon comes from [`crate::tet::mt::CASES`] (a triangle, or a quad split
//! into `(0, 1, 2), (0, 2, 3)`); its vertex on mesh edge `(p, q)` is looked up by the sorted
//! global point pair, so the tets around an edge share it. It is interpolated from the lower
//! point index, as the renderer does (in `f64`, then stored as `f32`). The polygon is wound
//! towards decreasing value: its normal is compared with the direction from a tet vertex above
//! the isovalue to one below, which for a linear field has the sign of the gradient.

use std::collections::HashMap;

use glam::{DVec3, Vec4};

use super::builder::MeshBuilder;
use super::clip::prepare;
use super::{Control, ExtractError, TriMesh, check_isovalues};
use crate::render::ClipRegion;
use crate::tet::TetScene;
use crate::tet::mt::{CASES, case_index};

/// Tets per progress report and cancellation check.
const SLAB: usize = 1 << 14;

/// The isosurfaces of `scene` (its current positions and values) at `isovalues`, clipped by
/// `clips`, as one mesh (see the [module docs](super)).
pub fn tet_isosurfaces(
    scene: &TetScene,
    isovalues: &[f32],
    clips: &[ClipRegion],
    control: &Control<'_>,
) -> Result<TriMesh, ExtractError> {
    check_isovalues(isovalues)?;
    let regions = prepare(clips)?;
    let mut builder = MeshBuilder::new(&regions);
    let verts = &scene.verts;
    let tets = &scene.tets;
    let mut on_edge: HashMap<(u32, u32), u32> = HashMap::new();
    let slabs = tets.len().div_ceil(SLAB).max(1);
    let total = (slabs * isovalues.len()).max(1) as f32;
    for (s, &iso) in isovalues.iter().enumerate() {
        builder.surface = s as u32;
        on_edge.clear();
        for (slab, chunk) in tets.chunks(SLAB).enumerate() {
            control.checkpoint((s * slabs + slab) as f32 / total)?;
            for ids in chunk {
                let v: [Vec4; 4] = ids.map(|i| verts[i as usize]);
                if v.iter().any(|p| p.w.is_nan()) {
                    continue;
                }
                let case = &CASES[case_index(&v, iso)];
                let count = usize::from(case.count);
                if count == 0 {
                    continue;
                }
                let mut poly = [0u32; 4];
                for (slot, &[a, b]) in poly.iter_mut().zip(&case.edges[..count]) {
                    let (a, b) = (usize::from(a), usize::from(b));
                    // From the lower global index (ties: local order).
                    let (p, q) = if (ids[a], a) < (ids[b], b) {
                        (a, b)
                    } else {
                        (b, a)
                    };
                    let key = (ids[p], ids[q]);
                    *slot = if let Some(&id) = on_edge.get(&key) {
                        id
                    } else {
                        let (vp, vq) = (v[p].as_dvec4(), v[q].as_dvec4());
                        let t = (f64::from(iso) - vp.w) / (vq.w - vp.w);
                        let id = builder.vertex(vp.truncate() + (vq - vp).truncate() * t)?;
                        on_edge.insert(key, id);
                        id
                    };
                }
                let poly = &mut poly[..count];
                if points_up(&builder, poly, &v, iso) {
                    poly.reverse();
                }
                for k in 1..count - 1 {
                    builder.triangle([poly[0], poly[k], poly[k + 1]])?;
                }
            }
        }
    }
    control.checkpoint(1.0)?;
    Ok(builder.finish())
}

/// Whether the polygon's normal points towards increasing value (it must be reversed).
fn points_up(builder: &MeshBuilder<'_>, poly: &[u32], v: &[Vec4; 4], iso: f32) -> bool {
    let p = |k: usize| builder.position(poly[k]);
    let n = if poly.len() == 4 {
        (p(2) - p(0)).cross(p(3) - p(1))
    } else {
        (p(1) - p(0)).cross(p(2) - p(0))
    };
    let pick = |above: bool| {
        v.iter()
            .find(|q| (q.w > iso) == above)
            .map_or(DVec3::ZERO, |q| q.truncate().as_dvec3())
    };
    n.dot(pick(true) - pick(false)) > 0.0
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::Keep;
    use crate::tet::{BvhOptions, lattice_tets, mt};
    use glam::Vec3;

    const C: DVec3 = DVec3::new(5.2, 4.9, 5.1);
    const R: f64 = 3.5;

    /// A lattice of `n³` points with the distance from `C` (spacing 1).
    fn sphere_scene(n: usize) -> TetScene {
        let id = |i: usize, j: usize, k: usize| (i + n * (j + n * k)) as u32;
        let mut points = Vec::new();
        let mut values = Vec::new();
        for k in 0..n {
            for j in 0..n {
                for i in 0..n {
                    let p = DVec3::new(i as f64, j as f64, k as f64);
                    points.push(p.as_vec3().to_array());
                    values.push((p - C).length() as f32);
                }
            }
        }
        TetScene::from_parts(&points, lattice_tets(n, id), &values, BvhOptions::default()).unwrap()
    }

    fn pos(m: &TriMesh, v: u32) -> DVec3 {
        DVec3::from_array(m.positions[v as usize].map(f64::from))
    }

    #[test]
    fn sphere_is_closed_oriented_and_matches_the_f64_isopolygons() {
        let scene = sphere_scene(11);
        let mesh = tet_isosurfaces(&scene, &[R as f32], &[], &Control::none()).unwrap();
        assert_eq!(mesh.open_edges(), 0, "watertight");
        for t in 0..mesh.triangles.len() {
            let centre = mesh.triangles[t]
                .iter()
                .map(|&v| pos(&mesh, v))
                .sum::<DVec3>()
                / 3.0;
            assert!(
                mesh.triangle_normal(t).dot(centre - C) <= 0.0,
                "triangle {t}"
            );
        }
        // Brute-force twin: the f64 isopolygon of every tet, its area summed.
        let mut twin = 0.0;
        let mut polygons = 0;
        for ids in &scene.tets {
            let v = ids.map(|i| scene.verts[i as usize]);
            let p = v.map(|q| q.truncate().as_dvec3());
            let val = v.map(|q| f64::from(q.w));
            if let Some((poly, count)) = mt::extract_f64(&p, &val, R) {
                polygons += 1;
                for k in 1..count - 1 {
                    twin += 0.5 * (poly[k] - poly[0]).cross(poly[k + 1] - poly[0]).length();
                }
            }
        }
        assert!(polygons > 0);
        assert!(
            (mesh.area() - twin).abs() < 1e-4 * twin,
            "{} vs {twin}",
            mesh.area()
        );
        let exact = 4.0 * std::f64::consts::PI * R * R;
        assert!((mesh.area() - exact).abs() < 0.05 * exact);
    }

    #[test]
    fn clipping_and_several_isovalues() {
        let scene = sphere_scene(11);
        let none = Control::none();
        let whole = tet_isosurfaces(&scene, &[R as f32], &[], &none).unwrap();
        let (min, max) = (Vec3::new(2.0, 2.5, 0.0), Vec3::new(6.0, 8.0, 6.5));
        let inside = tet_isosurfaces(
            &scene,
            &[R as f32],
            &[ClipRegion::Box {
                min,
                max,
                keep: Keep::Inside,
            }],
            &none,
        )
        .unwrap();
        let outside = tet_isosurfaces(
            &scene,
            &[R as f32],
            &[ClipRegion::Box {
                min,
                max,
                keep: Keep::Outside,
            }],
            &none,
        )
        .unwrap();
        let sum = inside.area() + outside.area();
        assert!((sum - whole.area()).abs() < 1e-6 * whole.area());
        let two = tet_isosurfaces(&scene, &[2.0, R as f32], &[], &none).unwrap();
        let inner = tet_isosurfaces(&scene, &[2.0], &[], &none).unwrap();
        assert_eq!(
            two.triangles.len(),
            whole.triangles.len() + inner.triangles.len()
        );
        assert_eq!(
            two.surfaces.iter().filter(|&&s| s == 1).count(),
            whole.positions.len()
        );
    }
}
