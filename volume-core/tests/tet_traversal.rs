//! Tetrahedral isosurfaces: every traversal variant (single ray, 2×2 and 16×16 packets, the
//! `IsoScene` entry points) against the `f64` brute force, watertightness at shared
//! isosurface edges and vertices, refit == rebuild, BIH == SAH, degenerate input.

use glam::Vec3;
use proptest::prelude::*;
use volume_core::math::Ray;
use volume_core::math::rng::Rng;
use volume_core::render::{CountStats, IsoScene, NoStats, Normals, Peel, PeeledHits};
use volume_core::tet::{
    BvhBuilder, BvhOptions, PointField, RawHit, TetMesh, TetScene, lattice_tets,
};

/// An `n³`-point grid over `[0, n−1]³`, jittered by `jitter`, split into 6 tets per cube;
/// `field(p)` gives the point values.
fn grid_mesh(
    n: usize,
    jitter: f32,
    rng: &mut Rng,
    field: impl Fn(Vec3, &mut Rng) -> f32,
) -> TetMesh {
    let id = |i: usize, j: usize, k: usize| (i + n * (j + n * k)) as u32;
    let mut points = Vec::new();
    let mut values = Vec::new();
    for k in 0..n {
        for j in 0..n {
            for i in 0..n {
                let p = Vec3::new(i as f32, j as f32, k as f32)
                    + Vec3::new(
                        rng.range_f32(-jitter, jitter),
                        rng.range_f32(-jitter, jitter),
                        rng.range_f32(-jitter, jitter),
                    );
                values.push(field(p, rng));
                points.push(p.to_array());
            }
        }
    }
    let tets = lattice_tets(n, id);
    TetMesh::new(points, tets, vec![PointField::new("f", values)]).unwrap()
}

fn random_rays(rng: &mut Rng, count: usize, extent: f32, coherent: bool) -> Vec<Ray> {
    let c = Vec3::splat(extent * 0.5);
    let eye = c + Vec3::new(
        rng.range_f32(-1.0, 1.0),
        rng.range_f32(-1.0, 1.0),
        rng.range_f32(-1.0, 1.0),
    )
    .normalize()
        * extent
        * 1.6;
    (0..count)
        .map(|_| {
            let o = if coherent {
                eye
            } else {
                Vec3::new(
                    rng.range_f32(-0.5, 1.5),
                    rng.range_f32(-0.5, 1.5),
                    rng.range_f32(-0.5, 1.5),
                ) * extent
            };
            let target = Vec3::new(rng.unit_f32(), rng.unit_f32(), rng.unit_f32()) * extent;
            Ray::new(o, (target - o).normalize())
        })
        .collect()
}

/// Checks an accelerated result against the `f64` brute force, allowing only disagreements
/// that a relative `1e-4` change of the polygons explains (rounding at silhouettes).
fn agrees(
    scene: &TetScene,
    ray: &Ray,
    t_min: f32,
    t_max: f32,
    iso: &[f32],
    got: Option<f32>,
) -> Result<(), String> {
    let exact = scene
        .brute_force_first_hit(ray, t_min, t_max, iso)
        .map(|h| h.0);
    let tol = |t: f64| 1e-4 * t.abs().max(1.0);
    match (got, exact) {
        (None, None) => return Ok(()),
        (Some(a), Some(b)) if (f64::from(a) - b).abs() <= tol(b) => return Ok(()),
        _ => {}
    }
    let grown = scene
        .brute_force_first_hit_slack(ray, t_min, t_max, iso, 1e-4)
        .map(|h| h.0);
    let shrunk = scene
        .brute_force_first_hit_slack(ray, t_min, t_max, iso, -1e-4)
        .map(|h| h.0);
    let ok = match got {
        None => shrunk.is_none(),
        Some(a) => {
            let a = f64::from(a);
            grown.is_some_and(|g| a >= g - tol(g)) && shrunk.is_none_or(|s| a <= s + tol(s))
        }
    };
    if ok {
        Ok(())
    } else {
        Err(format!(
            "ray {ray:?} [{t_min}, {t_max}] iso {iso:?}: got {got:?}, f64 {exact:?} (grown {grown:?}, shrunk {shrunk:?})"
        ))
    }
}

/// Hits of two traversals agree: same miss/hit and `t` within a few ulps. (They share the
/// intersector, but where a ray crosses a shared edge two polygons report `t`s an ulp
/// apart, and which one a traversal meets first depends on its order.)
fn same_t(a: Option<f32>, b: Option<f32>) -> bool {
    match (a, b) {
        (None, None) => true,
        (Some(a), Some(b)) => (a - b).abs() <= 1e-5 * a.abs().max(1.0),
        _ => false,
    }
}

/// All traversal variants on the same rays: each equals the brute force, and all agree
/// with each other ([`same_t`]).
fn check_all(
    scene: &mut TetScene,
    rays: &[Ray],
    t_min: &[f32],
    t_max: &[f32],
    iso: &[f32],
) -> Result<(), String> {
    let single: Vec<Option<RawHit>> = rays
        .iter()
        .zip(t_min.iter().zip(t_max))
        .map(|(r, (&a, &b))| scene.first_hit_raw(r, a, b, iso, &mut NoStats))
        .collect();
    for (i, r) in rays.iter().enumerate() {
        agrees(scene, r, t_min[i], t_max[i], iso, single[i].map(|h| h.t))?;
    }
    for packet in [4, 256, 7, 64] {
        scene.set_packet_size(packet);
        let mut out = vec![None; rays.len()];
        scene.first_hit_packet_raw(rays, t_min, t_max, iso, &mut out, &mut NoStats);
        for i in 0..rays.len() {
            if !same_t(out[i].map(|h| h.t), single[i].map(|h| h.t)) {
                return Err(format!(
                    "packet {packet}, ray {i}: {:?} vs single {:?}",
                    out[i], single[i]
                ));
            }
        }
    }
    // The renderer's entry points (with shading normals) agree too.
    scene.set_packet_size(256);
    let mut hits = vec![None; rays.len()];
    scene.first_hit_packet(rays, t_min, t_max, iso, &mut hits, &mut NoStats);
    for i in 0..rays.len() {
        let one = scene.first_hit(&rays[i], t_min[i], t_max[i], iso, &mut NoStats);
        if !same_t(one.map(|h| h.t), hits[i].map(|h| h.t))
            || !same_t(one.map(|h| h.t), single[i].map(|h| h.t))
        {
            return Err(format!("IsoScene ray {i}: {one:?} vs packet {:?}", hits[i]));
        }
        if let Some(h) = one
            && (h.normal.length() - 1.0).abs() > 1e-4
        {
            return Err(format!("normal {:?} not unit", h.normal));
        }
        // Where both found the same tet (a ray through a shared edge may take either), the
        // packet's normal (faceted from the traversal, smooth after the rows' prefetch) is
        // the single ray's, bit for bit.
        if let (Some(a), Some(b)) = (one, hits[i])
            && a.cell == b.cell
            && a.normal.to_array().map(f32::to_bits) != b.normal.to_array().map(f32::to_bits)
        {
            return Err(format!(
                "ray {i}: packet normal {:?} vs single {:?}",
                b.normal, a.normal
            ));
        }
        if scene.occluded(&rays[i], t_min[i], t_max[i], iso, &mut NoStats) != one.is_some() {
            return Err(format!("occluded disagrees with first_hit for ray {i}"));
        }
    }
    Ok(())
}

fn noisy_field(p: Vec3, rng: &mut Rng) -> f32 {
    (p - Vec3::splat(2.0)).length() + rng.range_f32(-0.4, 0.4)
}

fn run_case(
    seed: u64,
    n: usize,
    coherent: bool,
    builder: BvhBuilder,
    leaf_size: usize,
) -> Result<(), String> {
    let mut rng = Rng::new(seed);
    let mesh = grid_mesh(n, 0.3, &mut rng, noisy_field);
    let mut scene = TetScene::new(&mesh, "f", BvhOptions { builder, leaf_size }).unwrap();
    scene.validate()?;
    let (lo, hi) = scene.value_range().unwrap();
    let count = 1 + rng.below(3) as usize;
    let iso: Vec<f32> = (0..count).map(|_| rng.range_f32(lo, hi)).collect();
    let rays = random_rays(&mut rng, 300, (n - 1) as f32, coherent);
    let t_min: Vec<f32> = rays
        .iter()
        .map(|_| {
            if rng.unit_f32() < 0.3 {
                rng.range_f32(0.0, 3.0)
            } else {
                0.0
            }
        })
        .collect();
    let t_max: Vec<f32> = rays
        .iter()
        .map(|_| {
            if rng.unit_f32() < 0.3 {
                rng.range_f32(3.0, 8.0)
            } else {
                f32::INFINITY
            }
        })
        .collect();
    check_all(&mut scene, &rays, &t_min, &t_max, &iso)
}

#[test]
fn seeded_random_meshes_match_brute_force() {
    for seed in 0..12 {
        for builder in [BvhBuilder::Bih, BvhBuilder::Sah] {
            run_case(seed, 6, seed % 2 == 0, builder, 12).unwrap();
        }
    }
}

/// A jittered `n³`-point mesh of [`noisy_field`] (`n` = 6) from `seed`: `n`, its scene, its
/// value range and the generator after it.
fn noisy_scene(seed: u64) -> (usize, TetScene, (f32, f32), Rng) {
    let mut rng = Rng::new(seed);
    let n = 6;
    let mesh = grid_mesh(n, 0.3, &mut rng, noisy_field);
    let scene = TetScene::new(&mesh, "f", BvhOptions::default()).unwrap();
    let range = scene.value_range().unwrap();
    (n, scene, range, rng)
}

/// Packets of parallel rays from surface points (shadow rays towards a directional light:
/// origins spread over the surface, one direction) find the hits of single rays and of the
/// brute force, rays that start on the surface itself included.
#[test]
fn parallel_shadow_packets_match_single_rays() {
    for seed in 0..8u64 {
        let (n, mut scene, (lo, hi), mut rng) = noisy_scene(100 + seed);
        let iso = [rng.range_f32(lo, hi), rng.range_f32(lo, hi)];
        let eyes: Vec<Ray> = (0..6)
            .flat_map(|_| random_rays(&mut rng, 1000, (n - 1) as f32, true))
            .collect();
        let light = Vec3::new(
            rng.range_f32(-1.0, 1.0),
            rng.range_f32(-1.0, 1.0),
            rng.range_f32(-1.0, 1.0),
        )
        .normalize();
        let eps = 1e-4 * (n - 1) as f32;
        let mut rays = Vec::new();
        for r in &eyes {
            if rays.len() == 600 {
                break;
            }
            if let Some(h) = scene.first_hit(r, 0.0, f32::INFINITY, &iso, &mut NoStats) {
                let p = r.origin + r.dir * h.t;
                let side = if h.normal.dot(r.dir) > 0.0 { -1.0 } else { 1.0 };
                // Some rays start just off the surface, some on it.
                let off = if rays.len() % 3 == 0 { 0.0 } else { eps };
                rays.push(Ray::new(p + h.normal * side * off, light));
            }
        }
        assert!(rays.len() > 300, "{} shadow rays", rays.len());
        let t_min = vec![eps; rays.len()];
        let t_max: Vec<f32> = (0..rays.len())
            .map(|i| if i % 4 == 0 { 2.0 } else { f32::INFINITY })
            .collect();
        check_all(&mut scene, &rays, &t_min, &t_max, &iso).unwrap();
    }
}

/// Packets of parallel rays from a plane outside the mesh (an orthographic view: origins in
/// a row-major grid, one direction) find the hits of single rays and of the brute force,
/// with ranges closed early too.
#[test]
fn orthographic_packets_match_single_rays() {
    for seed in 0..6u64 {
        let (n, mut scene, (lo, hi), mut rng) = noisy_scene(200 + seed);
        // A noisy sphere about (2, 2, 2) (`noisy_field`), the grid of rays aimed at it.
        let iso = [lo + (hi - lo) * rng.range_f32(0.2, 0.5)];
        let extent = (n - 1) as f32;
        let c = Vec3::splat(2.0);
        let dir = Vec3::new(
            rng.range_f32(-1.0, 1.0),
            rng.range_f32(-1.0, 1.0),
            rng.range_f32(-1.0, 1.0),
        )
        .normalize()
            * rng.range_f32(0.5, 2.0);
        let (u, v) = dir.normalize().any_orthonormal_pair();
        let side = 24;
        let rays: Vec<Ray> = (0..side * side)
            .map(|i| {
                let (x, y) = ((i % side) as f32, (i / side) as f32);
                let across = (x / (side - 1) as f32 - 0.5) * 1.2 * extent;
                let up = (y / (side - 1) as f32 - 0.5) * 1.2 * extent;
                let o = c - dir.normalize() * (2.0 * extent) + u * across + v * up;
                Ray::new(o, dir)
            })
            .collect();
        let t_min = vec![0.0; rays.len()];
        let t_max: Vec<f32> = (0..rays.len())
            .map(|i| {
                if i % 5 == 0 {
                    2.5 * extent
                } else {
                    f32::INFINITY
                }
            })
            .collect();
        let hits = rays
            .iter()
            .filter(|r| {
                scene
                    .first_hit_raw(r, 0.0, f32::INFINITY, &iso, &mut NoStats)
                    .is_some()
            })
            .count();
        assert!(hits > 50, "{hits} hits");
        check_all(&mut scene, &rays, &t_min, &t_max, &iso).unwrap();
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]
    #[test]
    fn proptest_traversals_match_brute_force(seed in any::<u64>(), n in 3usize..7, coherent in any::<bool>(), sah in any::<bool>(), leaf in prop_oneof![Just(1usize), Just(4), Just(12), Just(40)]) {
        let builder = if sah { BvhBuilder::Sah } else { BvhBuilder::Bih };
        prop_assert_eq!(run_case(seed, n, coherent, builder, leaf), Ok(()));
    }
}

/// A linear field on an unjittered grid: the isosurface is exactly the plane
/// `x + 2y + 4z = c`, and with `c` at odd multiples of 0.5 every isopolygon vertex is an
/// exactly representable edge midpoint. Rays aimed exactly at isopolygon vertices and along
/// shared isopolygon edges (axis-parallel and diagonal) must all hit, at the analytic `t`.
#[test]
fn rays_through_shared_isosurface_edges_and_vertices_never_miss() {
    let n = 6;
    let mut rng = Rng::new(7);
    let mesh = grid_mesh(n, 0.0, &mut rng, |p, _| p.x + 2.0 * p.y + 4.0 * p.z);
    let mut scene = TetScene::new(&mesh, "f", BvhOptions::default()).unwrap();
    let c = 10.5f32;
    let normal = Vec3::new(1.0, 2.0, 4.0);
    // Isopolygon vertices and edge midpoints, from the tets' own extraction.
    let mut targets: Vec<Vec3> = Vec::new();
    for t in &mesh.tets {
        let v = t.map(|i| {
            let p = Vec3::from(mesh.points[i as usize]);
            p.extend(mesh.fields[0].values[i as usize])
        });
        if let Some(poly) = volume_core::tet::mt::extract(&v, t, c) {
            let k = poly.count as usize;
            for e in 0..k {
                targets.push(poly.v[e]);
                targets.push((poly.v[e] + poly.v[(e + 1) % k]) * 0.5);
            }
        }
    }
    // Only targets strictly inside the mesh: isopolygon edges on the mesh boundary are not
    // shared, and a ray grazing the surface's outer rim may round either way.
    let inner = |p: &Vec3| {
        p.cmpgt(Vec3::splat(0.01)).all() && p.cmplt(Vec3::splat((n - 1) as f32 - 0.01)).all()
    };
    targets.retain(inner);
    assert!(targets.len() > 500);
    let dirs = [
        Vec3::Z,
        -Vec3::Z,
        Vec3::X,
        Vec3::Y,
        Vec3::new(1.0, 1.0, 1.0),
        Vec3::new(-1.0, 0.5, 2.0),
        Vec3::new(0.3, -0.7, -0.1),
    ];
    let mut rays = Vec::new();
    for &p in &targets {
        for d in dirs {
            // Origin backed off along the direction; t = 8 lands on the target in exact
            // arithmetic (the rounding of the origin is what makes this hard).
            rays.push(Ray::new(p - d * 8.0, d));
        }
    }
    let t_min = vec![0.0; rays.len()];
    let t_max = vec![f32::INFINITY; rays.len()];
    let iso = [c];
    let mut missed = 0;
    for r in &rays {
        // Analytic: plane n·x = c.
        let t_exact = (c - normal.dot(r.origin)) / normal.dot(r.dir);
        match scene.first_hit_raw(r, 0.0, f32::INFINITY, &iso, &mut NoStats) {
            Some(h) => assert!(
                (h.t - t_exact).abs() < 1e-4 * t_exact.abs().max(1.0),
                "{r:?}: {} vs {t_exact}",
                h.t
            ),
            None => missed += 1,
        }
    }
    assert_eq!(
        missed,
        0,
        "{missed} of {} rays through shared edges/vertices missed",
        rays.len()
    );
    check_all(
        &mut scene,
        &rays[..2000],
        &t_min[..2000],
        &t_max[..2000],
        &iso,
    )
    .unwrap();
}

/// Rays aimed exactly at the `f32` midpoints of isopolygon edges shared by two polygons of a
/// closed curved surface (a sphere through a jittered mesh): none may slip through the
/// crack. Rays for which the two polygons fold onto the same side of the edge in projection
/// (a silhouette, where rounding may legitimately go either way) are excluded.
#[test]
fn rays_through_curved_surface_edges_never_miss() {
    use std::collections::HashMap;
    let mut rng = Rng::new(99);
    let centre = Vec3::splat(3.0);
    let mesh = grid_mesh(7, 0.25, &mut rng, |p, _| (p - centre).length());
    let mut scene = TetScene::new(&mesh, "f", BvhOptions::default()).unwrap();
    let c = 2.1f32;
    let key = |p: Vec3| p.to_array().map(f32::to_bits);
    let mut edges: HashMap<[[u32; 3]; 2], Vec<Vec3>> = HashMap::new();
    for t in &mesh.tets {
        let v = t
            .map(|i| Vec3::from(mesh.points[i as usize]).extend(mesh.fields[0].values[i as usize]));
        if let Some(poly) = volume_core::tet::mt::extract(&v, t, c) {
            let k = poly.count as usize;
            let centroid = poly.v[..k].iter().copied().sum::<Vec3>() / k as f32;
            for e in 0..k {
                let (a, b) = (poly.v[e], poly.v[(e + 1) % k]);
                let mut ends = [key(a), key(b)];
                ends.sort_unstable();
                edges.entry(ends).or_default().push(centroid);
            }
        }
    }
    let mut rays = Vec::new();
    for (ends, cents) in &edges {
        assert_eq!(
            cents.len(),
            2,
            "every edge of a closed surface is shared by two polygons"
        );
        let [a, b] = ends.map(|k| Vec3::from_array(k.map(f32::from_bits)));
        let target = (a + b) * 0.5;
        let o = Vec3::new(rng.range_f32(-3.0, 9.0), rng.range_f32(-3.0, 9.0), -4.0);
        let d = (target - o).normalize();
        // Sides of the two polygons across the edge, seen along the ray.
        let side = |p: Vec3| {
            (b - a)
                .as_dvec3()
                .cross((p - a).as_dvec3())
                .dot(d.as_dvec3())
        };
        let (s0, s1) = (side(cents[0]), side(cents[1]));
        if s0 * s1 < 0.0 && s0.abs().min(s1.abs()) > 1e-3 {
            rays.push(Ray::new(o, d));
        }
    }
    assert!(rays.len() > 300, "{}", rays.len());
    let iso = [c];
    let mut hits = 0;
    for r in &rays {
        let got = scene.first_hit_raw(r, 0.0, f32::INFINITY, &iso, &mut NoStats);
        hits += usize::from(got.is_some());
        agrees(&scene, r, 0.0, f32::INFINITY, &iso, got.map(|h| h.t)).unwrap();
    }
    assert_eq!(hits, rays.len());
    let t_min = vec![0.0; rays.len()];
    let t_max = vec![f32::INFINITY; rays.len()];
    check_all(&mut scene, &rays, &t_min, &t_max, &iso).unwrap();
}

#[test]
fn refit_equals_rebuild_for_scalars_and_positions() {
    let mut rng = Rng::new(3);
    let mesh = grid_mesh(7, 0.3, &mut rng, noisy_field);
    let mut scene = TetScene::new(&mesh, "f", BvhOptions::default()).unwrap();
    let rays = random_rays(&mut rng, 400, 6.0, true);
    let t_min = vec![0.0; rays.len()];
    let t_max = vec![f32::INFINITY; rays.len()];
    let iso = [2.2f32, 3.1];
    for step in 0..3 {
        // New scalars: a moving blob.
        let centre = Vec3::new(2.0 + step as f32, 3.0, 3.0);
        let values: Vec<f32> = mesh
            .points
            .iter()
            .map(|p| (Vec3::from(*p) - centre).length() + rng.range_f32(-0.2, 0.2))
            .collect();
        // Packets traced before and after the refit, with the same isovalues on this thread:
        // the leaf cache must not serve the old state's polygons.
        check_all(&mut scene, &rays[..100], &t_min[..100], &t_max[..100], &iso).unwrap();
        scene.refit_scalars(&values).unwrap();
        scene.validate().unwrap();
        check_all(&mut scene, &rays[..100], &t_min[..100], &t_max[..100], &iso).unwrap();
        let fresh_mesh = TetMesh::new(
            mesh.points.clone(),
            mesh.tets.clone(),
            vec![PointField::new("f", values.clone())],
        )
        .unwrap();
        let fresh = TetScene::new(&fresh_mesh, "f", BvhOptions::default()).unwrap();
        // New positions: a shear.
        let points: Vec<[f32; 3]> = mesh
            .points
            .iter()
            .map(|p| {
                [
                    p[0] + 0.1 * step as f32 * p[2],
                    p[1],
                    p[2] * (1.0 + 0.05 * step as f32),
                ]
            })
            .collect();
        let mut moved = scene.clone();
        check_all(&mut moved, &rays[..100], &t_min[..100], &t_max[..100], &iso).unwrap();
        moved.refit_positions(&points).unwrap();
        moved.validate().unwrap();
        let moved_mesh = TetMesh::new(
            points,
            mesh.tets.clone(),
            vec![PointField::new("f", values)],
        )
        .unwrap();
        let moved_fresh = TetScene::new(
            &moved_mesh,
            "f",
            BvhOptions {
                builder: BvhBuilder::Sah,
                leaf_size: 5,
            },
        )
        .unwrap();
        for (i, r) in rays.iter().enumerate() {
            let a = scene
                .first_hit_raw(r, t_min[i], t_max[i], &iso, &mut NoStats)
                .map(|h| h.t);
            let b = fresh
                .first_hit_raw(r, t_min[i], t_max[i], &iso, &mut NoStats)
                .map(|h| h.t);
            assert!(
                same_t(a, b),
                "scalar refit vs rebuild, step {step}, ray {i}: {a:?} {b:?}"
            );
            let a = moved
                .first_hit_raw(r, t_min[i], t_max[i], &iso, &mut NoStats)
                .map(|h| h.t);
            let b = moved_fresh
                .first_hit_raw(r, t_min[i], t_max[i], &iso, &mut NoStats)
                .map(|h| h.t);
            assert!(
                same_t(a, b),
                "position refit vs rebuild, step {step}, ray {i}: {a:?} {b:?}"
            );
        }
        check_all(&mut moved, &rays[..100], &t_min[..100], &t_max[..100], &iso).unwrap();
    }
    // Wrong lengths are errors, not panics.
    assert!(scene.refit_scalars(&[1.0]).is_err());
    assert!(scene.refit_positions(&[[0.0; 3]]).is_err());
    let mut bad = mesh.points.clone();
    bad[3][0] = f32::NAN;
    assert!(scene.refit_positions(&bad).is_err());
}

#[test]
fn bih_and_sah_and_leaf_sizes_give_identical_hits() {
    let mut rng = Rng::new(11);
    let mesh = grid_mesh(8, 0.3, &mut rng, noisy_field);
    let rays = random_rays(&mut rng, 500, 7.0, false);
    let iso = [2.5f32];
    let reference = TetScene::new(&mesh, "f", BvhOptions::default()).unwrap();
    let want: Vec<Option<f32>> = rays
        .iter()
        .map(|r| {
            reference
                .first_hit_raw(r, 0.0, f32::INFINITY, &iso, &mut NoStats)
                .map(|h| h.t)
        })
        .collect();
    for builder in [BvhBuilder::Bih, BvhBuilder::Sah] {
        // 100: leaves with more polygons than the packets' leaf cache keeps.
        for leaf_size in [1, 2, 8, 12, 16, 64, 100] {
            let mut s = TetScene::new(&mesh, "f", BvhOptions { builder, leaf_size }).unwrap();
            s.validate().unwrap();
            assert!(
                s.bvh()
                    .nodes()
                    .iter()
                    .all(|n| n.count as usize <= leaf_size)
            );
            if leaf_size == 100 {
                assert!(s.bvh().nodes().iter().any(|n| n.count > 64), "{builder:?}");
            }
            let mut out = vec![None; rays.len()];
            s.set_packet_size(256);
            s.first_hit_packet_raw(
                &rays,
                &vec![0.0; rays.len()],
                &vec![f32::INFINITY; rays.len()],
                &iso,
                &mut out,
                &mut NoStats,
            );
            let got: Vec<Option<f32>> = out.iter().map(|h| h.map(|h| h.t)).collect();
            for (i, (g, w)) in got.iter().zip(&want).enumerate() {
                assert!(
                    same_t(*g, *w),
                    "{builder:?} leaf {leaf_size} ray {i}: {g:?} vs {w:?}"
                );
            }
        }
    }
}

#[test]
fn degenerate_tets_and_nan_values_do_not_panic() {
    // Points: a unit tet plus coplanar and duplicate points.
    let points = vec![
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [0.0, 0.0, 1.0],
        [1.0, 1.0, 0.0], // coplanar with 0, 1, 2
        [2.0, 0.0, 0.0],
        [2.0, 1.0, 1.0],
    ];
    let values = vec![0.0, 1.0, 1.0, 1.0, 2.0, f32::NAN, 3.0];
    let tets = vec![
        [0, 1, 2, 3], // fine
        [0, 2, 1, 3], // inverted
        [0, 1, 2, 4], // zero volume
        [0, 0, 1, 3], // duplicate vertex
        [1, 5, 6, 3], // NaN value: void
        [3, 3, 3, 3], // collapsed to a point
    ];
    let mesh = TetMesh::new(points, tets, vec![PointField::new("f", values)]).unwrap();
    for builder in [BvhBuilder::Bih, BvhBuilder::Sah] {
        let mut scene = TetScene::new(
            &mesh,
            "f",
            BvhOptions {
                builder,
                leaf_size: 2,
            },
        )
        .unwrap();
        scene.validate().unwrap();
        scene.set_normals(Normals::Smooth);
        let mut rng = Rng::new(5);
        let mut rays = random_rays(&mut rng, 200, 2.0, false);
        rays.push(Ray::new(Vec3::new(0.2, 0.2, -1.0), Vec3::ZERO));
        rays.push(Ray::new(Vec3::NAN, Vec3::Z));
        rays.push(Ray::new(
            Vec3::new(0.1, 0.1, -1.0),
            Vec3::new(0.0, 0.0, f32::INFINITY),
        ));
        let n = rays.len();
        let mut t_min = vec![0.0; n];
        t_min[3] = f32::NAN;
        let mut t_max = vec![f32::INFINITY; n];
        t_max[4] = -1.0;
        for iso in [vec![0.5f32], vec![0.0, 1.0, 2.5, f32::NAN], vec![]] {
            check_all(&mut scene, &rays, &t_min, &t_max, &iso).unwrap();
        }
        // The NaN tet is void: a ray through its interior only, at a value inside its
        // other vertices' range, finds nothing there.
        let r = Ray::new(Vec3::new(1.8, 0.5, -1.0), Vec3::Z);
        assert!(
            scene
                .first_hit_raw(&r, 0.0, f32::INFINITY, &[2.0], &mut NoStats)
                .is_none()
        );
        // A good tet is still hit through the inverted copy and degenerate neighbours.
        let r = Ray::new(Vec3::new(0.2, 0.2, -1.0), Vec3::Z);
        let h = scene
            .first_hit(&r, 0.0, f32::INFINITY, &[0.5], &mut NoStats)
            .unwrap();
        assert!((h.t - 1.1).abs() < 1e-5, "{h:?}");
    }
    // All values NaN: no range, no hits.
    let mesh = TetMesh::new(
        vec![[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        vec![[0, 1, 2, 3]],
        vec![PointField::new("f", vec![f32::NAN; 4])],
    )
    .unwrap();
    let scene = TetScene::new(&mesh, "f", BvhOptions::default()).unwrap();
    assert_eq!(scene.value_range(), None);
    // Bad construction input: errors.
    assert!(TetScene::new(&mesh, "g", BvhOptions::default()).is_err());
    assert!(TetScene::from_parts(&[[0.0; 3]], vec![], &[0.0], BvhOptions::default()).is_err());
    assert!(
        TetScene::from_parts(
            &[[0.0; 3]],
            vec![[0, 0, 0, 1]],
            &[0.0],
            BvhOptions::default()
        )
        .is_err()
    );
}

#[test]
fn smooth_normals_follow_the_gradient() {
    let mut rng = Rng::new(1);
    // Linear field: smooth and faceted normals are both the constant gradient direction.
    let mesh = grid_mesh(5, 0.2, &mut rng, |p, _| p.x + 2.0 * p.y + 4.0 * p.z);
    let mut scene = TetScene::new(&mesh, "f", BvhOptions::default()).unwrap();
    let g = Vec3::new(1.0, 2.0, 4.0).normalize();
    let rays = random_rays(&mut rng, 200, 4.0, true);
    for normals in [Normals::Faceted, Normals::Smooth] {
        scene.set_normals(normals);
        let mut n_hits = 0;
        for r in &rays {
            if let Some(h) = scene.first_hit(r, 0.0, f32::INFINITY, &[12.0], &mut NoStats) {
                n_hits += 1;
                assert!(h.normal.dot(g) > 0.999, "{normals:?}: {:?}", h.normal);
            }
        }
        assert!(n_hits > 50);
    }
    // Distance field: smooth normals are close to the radial direction, closer than faceted.
    let centre = Vec3::splat(4.0);
    let mesh = grid_mesh(9, 0.0, &mut rng, |p, _| (p - centre).length());
    let mut scene = TetScene::new(&mesh, "f", BvhOptions::default()).unwrap();
    let rays = random_rays(&mut rng, 300, 8.0, true);
    let mut err = [0f32; 2];
    for (k, normals) in [Normals::Faceted, Normals::Smooth].into_iter().enumerate() {
        scene.set_normals(normals);
        for r in &rays {
            if let Some(h) = scene.first_hit(r, 0.0, f32::INFINITY, &[3.0], &mut NoStats) {
                let radial = (r.at(h.t) - centre).normalize();
                assert!(h.normal.dot(radial) > 0.95, "{normals:?}");
                err[k] += 1.0 - h.normal.dot(radial);
            }
        }
    }
    assert!(err[1] < err[0], "smooth {} vs faceted {}", err[1], err[0]);
}

#[test]
fn packets_of_16x16_need_far_fewer_box_tests_than_2x2() {
    let mut rng = Rng::new(21);
    let mesh = grid_mesh(16, 0.3, &mut rng, |p, r| {
        (p - Vec3::splat(7.5)).length() + r.range_f32(-0.3, 0.3)
    });
    let mut scene = TetScene::new(&mesh, "f", BvhOptions::default()).unwrap();
    // A 64×64 pinhole image in Morton order per 16×16 tile.
    let eye = Vec3::new(7.5, 7.5, -20.0);
    let mut rays = Vec::new();
    for ty in 0..4 {
        for tx in 0..4 {
            for m in 0..256u32 {
                let (mut x, mut y) = (0u32, 0u32);
                for b in 0..4 {
                    x |= ((m >> (2 * b)) & 1) << b;
                    y |= ((m >> (2 * b + 1)) & 1) << b;
                }
                let px = ((tx * 16 + x) as f32 / 64.0 - 0.5) * 0.6;
                let py = ((ty * 16 + y) as f32 / 64.0 - 0.5) * 0.6;
                rays.push(Ray::new(eye, Vec3::new(px, py, 1.0).normalize()));
            }
        }
    }
    let n = rays.len();
    let (t_min, t_max) = (vec![0.0; n], vec![f32::INFINITY; n]);
    let iso = [5.0f32];
    let mut counts = Vec::new();
    let mut results = Vec::new();
    for packet in [4, 256] {
        scene.set_packet_size(packet);
        let mut stats = CountStats::default();
        let mut out = vec![None; n];
        scene.first_hit_packet_raw(&rays, &t_min, &t_max, &iso, &mut out, &mut stats);
        counts.push(stats.0);
        results.push(out.iter().map(|h| h.map(|h| h.t)).collect::<Vec<_>>());
    }
    for (a, b) in results[0].iter().zip(&results[1]) {
        assert!(same_t(*a, *b));
    }
    assert!(results[0].iter().filter(|h| h.is_some()).count() > n / 5);
    let ratio = counts[0].box_tests as f64 / counts[1].box_tests as f64;
    eprintln!(
        "2x2 {:?}\n16x16 {:?}\nbox-test ratio {ratio:.1}",
        counts[0], counts[1]
    );
    assert!(ratio > 5.0, "ratio {ratio}");
    assert!(counts[1].polygon_extractions < counts[0].polygon_extractions);
}

#[test]
fn time_steps_per_step_bvh_equals_refit() {
    use volume_core::tet::{StepScheme, TetStep, TetSteps};
    let mut rng = Rng::new(17);
    let mesh = grid_mesh(6, 0.3, &mut rng, noisy_field);
    // 4 steps: scalars move; steps 1 and 3 also move the points; step 2 is back at the reference.
    let steps: Vec<TetStep> = (0..4)
        .map(|k| {
            let centre = Vec3::new(1.5 + 0.5 * k as f32, 2.5, 2.5);
            let values = mesh
                .points
                .iter()
                .map(|p| (Vec3::from(*p) - centre).length())
                .collect();
            let positions = (k % 2 == 1).then(|| {
                mesh.points
                    .iter()
                    .map(|p| [p[0] + 0.2 * (p[1] * 0.7).sin(), p[1], p[2] * 1.05])
                    .collect()
            });
            TetStep { positions, values }
        })
        .collect();
    let opts = BvhOptions::default();
    let mut per = TetSteps::new(
        &mesh.points,
        &mesh.tets,
        steps.clone(),
        StepScheme::PerStepBvh,
        opts,
    )
    .unwrap();
    let mut refit = TetSteps::new(
        &mesh.points,
        &mesh.tets,
        steps.clone(),
        StepScheme::Refit,
        opts,
    )
    .unwrap();
    let rays = random_rays(&mut rng, 200, 5.0, true);
    let iso = [1.7f32];
    for step in [1, 2, 3, 0, 3, 1, 2] {
        per.set_step(step).unwrap();
        refit.set_step(step).unwrap();
        refit.scene().validate().unwrap();
        assert_eq!(per.current_step(), step);
        for r in &rays {
            let a = per
                .scene()
                .first_hit_raw(r, 0.0, f32::INFINITY, &iso, &mut NoStats)
                .map(|h| h.t);
            let b = refit
                .scene()
                .first_hit_raw(r, 0.0, f32::INFINITY, &iso, &mut NoStats)
                .map(|h| h.t);
            assert!(same_t(a, b), "step {step}: {a:?} vs {b:?}");
            agrees(refit.scene(), r, 0.0, f32::INFINITY, &iso, b).unwrap();
        }
    }
    assert!(refit.set_step(4).is_err());
    let mut bad = steps;
    bad[2].values.pop();
    assert!(TetSteps::new(&mesh.points, &mesh.tets, bad, StepScheme::Refit, opts).is_err());
}

/// The shared renderer draws a `TetScene`: its depth buffer equals the `f64` brute force on
/// the same primary rays, with packets and without, faceted and smooth.
/// Every pixel's depth in `frame` against the brute-force first hit of its primary ray;
/// returns the pixels that hit.
fn depth_agrees_with_brute_force(
    scene: &TetScene,
    cam: &volume_core::render::Camera,
    frame: &volume_core::render::Frame,
    isos: &[f32],
) -> usize {
    let (w, h) = (frame.width, frame.height);
    let mut hits = 0;
    for j in 0..h {
        for i in 0..w {
            let ray = cam.primary_ray(i, j, w, h);
            let depth = frame.depth[(j * w + i) as usize];
            let got = depth.is_finite().then_some(depth);
            hits += usize::from(got.is_some());
            agrees(scene, &ray, 0.0, f32::INFINITY, isos, got).unwrap();
        }
    }
    hits
}

#[test]
fn renderer_depth_matches_brute_force() {
    use std::sync::atomic::AtomicBool;
    use volume_core::render::{Camera, RenderSettings, Surface, render};
    let mut rng = Rng::new(23);
    let mesh = grid_mesh(8, 0.3, &mut rng, noisy_field);
    let mut scene = TetScene::new(&mesh, "f", BvhOptions::default()).unwrap();
    let cam = Camera::orbit(&scene.world_bounds(), 35.0, 25.0, 40.0);
    let (w, h) = (48u32, 40u32);
    let iso = [2.6f32, 4.0];
    let go = AtomicBool::new(false);
    for (packets, normals) in [(true, Normals::Faceted), (false, Normals::Smooth)] {
        scene.set_normals(normals);
        let settings = RenderSettings {
            width: w,
            height: h,
            surfaces: iso
                .iter()
                .map(|&c| Surface::new(c, [0.8, 0.7, 0.6]))
                .collect(),
            packets,
            ..RenderSettings::default()
        };
        let frame = render(&scene, &cam, &settings, &go).unwrap();
        let hits = depth_agrees_with_brute_force(&scene, &cam, &frame, &iso);
        assert!(hits > (w * h / 10) as usize, "{hits}");
    }
}

/// Frames cut to the BVH's live bounds equal frames over the whole mesh bit for bit (a
/// transparent surface over an opaque one, shadows, both normal modes), agree with brute
/// force, and trace fewer rays: the field is a blob in one corner of the mesh.
#[test]
fn live_bounds_leave_frames_unchanged_and_trace_fewer_rays() {
    use std::sync::atomic::AtomicBool;
    use volume_core::render::{
        Camera, Light, LightKind, RenderSettings, Surface, WholeBounds, render,
    };
    let mut rng = Rng::new(29);
    let corner = Vec3::new(2.0, 2.5, 2.0);
    let mesh = grid_mesh(12, 0.25, &mut rng, |p, rng| {
        (p - corner).length() + rng.range_f32(-0.05, 0.05)
    });
    let mut scene = TetScene::new(&mesh, "f", BvhOptions::default()).unwrap();
    let b = scene.world_bounds();
    let live = scene.live_bounds(&scene.prepare(&[1.5, 2.2]));
    assert!(
        (0..3).all(|a| live.extent()[a] < 0.6 * b.extent()[a]),
        "live {live:?} of {b:?}"
    );
    assert!(scene.live_bounds(&scene.prepare(&[1e6])).is_empty());
    let cam = Camera::orbit(&b, 35.0, 25.0, 40.0);
    let (w, h) = (64u32, 48u32);
    let mut skin = Surface::new(2.2, [0.9, 0.5, 0.4]);
    skin.opacity = 0.4;
    let go = AtomicBool::new(false);
    for normals in [Normals::Faceted, Normals::Smooth] {
        scene.set_normals(normals);
        let settings = RenderSettings {
            width: w,
            height: h,
            surfaces: vec![skin.clone(), Surface::new(1.5, [0.8, 0.8, 0.7])],
            shadows: true,
            light: Light {
                kind: LightKind::Directional {
                    dir: Vec3::new(0.4, -0.5, 0.8),
                },
                ..Light::default()
            },
            collect_stats: true,
            ..RenderSettings::default()
        };
        let cut = render(&scene, &cam, &settings, &go).unwrap();
        let whole = render(&WholeBounds(&scene), &cam, &settings, &go).unwrap();
        assert_eq!(cut.rgba8, whole.rgba8);
        let bits = |d: &[f32]| d.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&cut.depth), bits(&whole.depth));
        assert!(cut.counts.rays < whole.counts.rays);
        // Depth only: the shaded frame's depth map (its first hit through the transparent
        // skin is the skin).
        let flat = RenderSettings {
            depth_only: true,
            ..settings.clone()
        };
        let flat = render(&scene, &cam, &flat, &go).unwrap();
        assert_eq!(bits(&flat.depth), bits(&cut.depth));
        assert_eq!(flat.rays.shadow, 0);
        let hits = depth_agrees_with_brute_force(&scene, &cam, &cut, &[2.2, 1.5]);
        assert!(hits > 20, "{hits} hits");
    }
    // Rays are made only for samples inside the projections of the live frontier's boxes
    // (`IsoScene::live_boxes`): fewer than the samples whose ray meets the live box around
    // a ball in the middle of the mesh, and the same frame as over the whole mesh.
    let centre = Vec3::splat(1.5);
    let ball = grid_mesh(12, 0.25, &mut rng, |p, _| (p - centre).length());
    // BIH with 12-tet leaves: on this small lattice the SAH tree's frontier boxes, and
    // those of larger leaves, happen to cover the whole live box's projection, so only
    // these show the cut (the frames match for all).
    let bih = BvhOptions {
        builder: BvhBuilder::Bih,
        leaf_size: 12,
    };
    let scene = TetScene::new(&ball, "f", bih).unwrap();
    let settings = RenderSettings {
        width: 4 * w,
        height: 4 * h,
        surfaces: vec![Surface::new(0.9, [0.8, 0.8, 0.7])],
        collect_stats: true,
        ..RenderSettings::default()
    };
    let f = render(&scene, &cam, &settings, &go).unwrap();
    assert_eq!(
        f.rgba8,
        render(&WholeBounds(&scene), &cam, &settings, &go)
            .unwrap()
            .rgba8
    );
    let live = scene.live_bounds(&scene.prepare(&[0.9]));
    let raygen = volume_core::render::RayGen::new(&cam, 4 * w, 4 * h);
    let meet = (0..4 * h)
        .flat_map(|y| (0..4 * w).map(move |x| (x, y)))
        .filter(|&(x, y)| {
            let ray = raygen.ray_at(x as f32 + 0.5, y as f32 + 0.5);
            live.intersect(&ray, 0.0, f32::INFINITY).is_some()
        })
        .count() as u64;
    assert!(
        f.counts.rays < meet,
        "{} rays traced, {meet} meet the live box",
        f.counts.rays
    );
}

/// A ray's layers by definition: its first hit, then the first hit from [`Peel::next_t`] of
/// the last one on, until an opaque one or `cap` (single rays, one traversal per layer).
fn reshot_layers(
    scene: &TetScene,
    ray: &Ray,
    t_min: f32,
    t_max: f32,
    isos: &[f32],
    peel: &Peel,
    cap: usize,
) -> Vec<(u32, u32)> {
    let mut out = Vec::new();
    let mut t = t_min;
    while out.len() < cap {
        let Some(h) = scene.first_hit(ray, t, t_max, isos, &mut NoStats) else {
            break;
        };
        out.push((h.t.to_bits(), h.surface));
        if peel.ends_ray(h.surface) {
            break;
        }
        t = peel.next_t(h.t);
    }
    out
}

#[test]
fn packet_layers_equal_the_first_hits_of_rays_reshot_past_each_layer() {
    let mut rng = Rng::new(17);
    let mesh = grid_mesh(9, 0.3, &mut rng, noisy_field);
    let mut scene = TetScene::new(&mesh, "f", BvhOptions::default()).unwrap();
    // Nested noisy shells: a ray crosses each several times.
    let isos = [1.2f32, 2.0, 2.9];
    let prepared = scene.prepare(&isos);
    let (mut layers_seen, mut truncated, mut with_more) = (0usize, 0usize, 0usize);
    for (packet, opaque, max_hits, normals) in [
        (256, 0b100u64, 4u32, Normals::Faceted),
        (256, 0b000, 4, Normals::Smooth),
        (64, 0b010, 2, Normals::Faceted),
        (7, 0b000, 3, Normals::Smooth),
        (4, 0b100, 4, Normals::Faceted),
    ] {
        scene.set_packet_size(packet);
        scene.set_normals(normals);
        let peel = Peel {
            opaque,
            max_hits,
            eps: 1e-4,
        };
        let cap = max_hits as usize;
        let rays = random_rays(&mut rng, 600, 8.0, true);
        let n = rays.len();
        let t_min: Vec<f32> = (0..n).map(|i| if i % 5 == 0 { 3.0 } else { 0.0 }).collect();
        let t_max = vec![f32::INFINITY; n];
        let mut out = vec![PeeledHits::NONE; n];
        scene.peeled_hits_packet_prepared(
            &rays,
            &t_min,
            &t_max,
            &prepared,
            &peel,
            &mut out,
            &mut NoStats,
        );
        for (i, got) in out.iter().enumerate() {
            let want = reshot_layers(&scene, &rays[i], t_min[i], t_max[i], &isos, &peel, cap);
            let g: Vec<(u32, u32)> = got
                .hits()
                .iter()
                .map(|h| (h.t.to_bits(), h.surface))
                .collect();
            let k = g.len();
            assert!(
                k <= want.len() && g[..] == want[..k],
                "packet {packet}, ray {i}: {g:?} vs {want:?}"
            );
            let ends = want.last().is_some_and(|&(_, s)| peel.ends_ray(s));
            if got.more {
                // Truncated (the caller asks again from past the last layer) or full.
                assert!(k > 0 && !got.hits().last().is_some_and(|h| peel.ends_ray(h.surface)));
                truncated += usize::from(k < cap);
                with_more += 1;
            } else {
                assert_eq!(k, want.len(), "packet {packet}, ray {i}: ended early");
                assert!(
                    k < cap || ends,
                    "packet {packet}, ray {i}: full without more"
                );
            }
            for h in got.hits() {
                assert!(
                    (h.normal.length() - 1.0).abs() < 1e-4,
                    "normal {:?}",
                    h.normal
                );
            }
            layers_seen += k;
        }
    }
    assert!(layers_seen > 1000, "{layers_seen} layers");
    assert!(with_more > 50, "{with_more} rays with more");
    assert!(
        truncated * 10 < with_more,
        "{truncated} truncated of {with_more}"
    );
}
