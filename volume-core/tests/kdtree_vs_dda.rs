//! The implicit kd-tree against its brute-force twins: the 3D-DDA cell walk (same hits),
//! a naive recursive pointer tree (same node ranges), a full rebuild (refit), and an
//! analytic sphere (hit positions).

use glam::Vec3;
use proptest::prelude::*;
use volume_core::grid::GridScene;
use volume_core::intersect::{Intersector, IsoSet, corner_range, methods::Exact};
use volume_core::kdtree::{KdTree, KdTreeConfig};
use volume_core::math::Ray;
use volume_core::math::rng::Rng;
use volume_core::render::{CountStats, IsoScene, MAX_PEELED, NoStats, Peel, PeeledHits, Stats};
use volume_core::{AxisCoords, Grid, Voxel, VoxelBuffer};

fn grid_for(dims: [usize; 3], rng: &mut Rng, explicit: bool) -> Grid {
    if explicit {
        let axes = [0, 1, 2].map(|a| {
            let mut x = 0.0f64;
            let c: Vec<f64> = (0..dims[a])
                .map(|_| {
                    x += 0.5 + f64::from(rng.unit_f32());
                    x
                })
                .collect();
            AxisCoords::Explicit(c.into())
        });
        Grid::new(dims, axes, None).unwrap()
    } else {
        Grid::uniform(
            dims,
            [-3.0, 1.5, 100.0],
            [1.0, 0.75 + f64::from(rng.unit_f32()), 1.25],
        )
        .unwrap()
    }
}

fn random_ray(rng: &mut Rng, lo: Vec3, hi: Vec3) -> Ray {
    let c = (lo + hi) * 0.5;
    let ext = (hi - lo).max(Vec3::splat(1.0));
    let origin = c + Vec3::new(
        rng.range_f32(-1.2, 1.2),
        rng.range_f32(-1.2, 1.2),
        rng.range_f32(-1.2, 1.2),
    ) * ext;
    let target = c + Vec3::new(
        rng.range_f32(-0.6, 0.6),
        rng.range_f32(-0.6, 0.6),
        rng.range_f32(-0.6, 0.6),
    ) * ext;
    let mut dir = (target - origin).normalize_or(Vec3::X);
    // Some axis-parallel and in-plane rays.
    match rng.below(8) {
        0 => dir = Vec3::new(dir.x.signum(), 0.0, 0.0),
        1 => dir = Vec3::new(0.0, dir.y, dir.z).normalize_or(Vec3::Y),
        _ => {}
    }
    Ray::new(origin, dir)
}

/// Compares kd-tree and DDA on `rays` random rays per tree layout; returns the hit count.
fn compare_scene<T: Voxel>(
    grid: &Grid,
    voxels: Vec<T>,
    isos: &[f32],
    rng: &mut Rng,
    rays: usize,
) -> usize {
    let mut hits = 0;
    let buf = VoxelBuffer::from_vec(voxels);
    for unstored in [0, 2, 3] {
        let scene = GridScene::new(
            grid,
            buf.clone(),
            Intersector::Exact,
            KdTreeConfig {
                unstored_levels: unstored,
            },
        )
        .unwrap();
        let b = scene.world_bounds();
        let live = scene.live_bounds(&scene.prepare(isos));
        let frame = scene.frame();
        let isoset = IsoSet::<T>::new(isos);
        for _ in 0..rays {
            let ray = random_ray(rng, b.min, b.max);
            let local = frame.to_local(&ray);
            let kd = scene.cell_hit_with(&local, 0.0, f32::INFINITY, &isoset, Exact, &mut NoStats);
            let dda =
                scene
                    .dda()
                    .cell_hit_with(&local, 0.0, f32::INFINITY, &isoset, Exact, &mut NoStats);
            match (kd, dda) {
                (None, None) => {}
                (Some(a), Some(d)) => {
                    hits += 1;
                    let tol = 1e-5 * (1.0 + a.t.abs());
                    assert!(
                        (a.t - d.t).abs() <= tol,
                        "t differs: kd {a:?} dda {d:?} ray {ray:?} dims {:?}",
                        grid.dims()
                    );
                    assert_eq!(a.surface, d.surface, "surface: kd {a:?} dda {d:?}");
                    if a.t != d.t || a.cell != d.cell {
                        // Only a hit on a shared cell boundary may name another cell.
                        let diff = (0..3).map(|i| a.cell[i].abs_diff(d.cell[i])).max();
                        assert!(diff <= Some(1), "cells {a:?} vs {d:?}");
                    }
                }
                (a, d) => panic!(
                    "kd {a:?} vs dda {d:?} for ray {ray:?}, dims {:?}, isos {isos:?}, unstored {unstored}",
                    grid.dims()
                ),
            }
            // Through the public IsoScene interface too (world t and a finite unit normal).
            let hit = scene.first_hit(&ray, 0.0, f32::INFINITY, isos, &mut NoStats);
            assert_eq!(hit.map(|h| h.t), kd.map(|h| h.t));
            if let Some(h) = hit {
                assert!(h.normal.is_finite() && (h.normal.length() - 1.0).abs() < 1e-4);
            }
            // Cut to the live bounds as the renderer cuts its rays (it cut them to the data's
            // box before): the same hit.
            let cut = |bounds: &volume_core::math::Aabb| {
                bounds
                    .intersect(&ray, 0.0, f32::INFINITY)
                    .and_then(|(lo, hi)| scene.first_hit(&ray, lo, hi, isos, &mut NoStats))
            };
            assert_eq!(
                cut(&live).map(|h| (h.t, h.surface)),
                cut(&b).map(|h| (h.t, h.surface)),
                "live bounds {live:?} of {b:?} changed the hit of {ray:?}"
            );
        }
    }
    hits
}

fn dims_strategy() -> impl Strategy<Value = [usize; 3]> {
    let d = prop_oneof![
        1usize..=9,
        Just(2usize),
        Just(15),
        Just(17),
        Just(16),
        Just(33)
    ];
    [d.clone(), d.clone(), d]
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, ..ProptestConfig::default() })]

    #[test]
    fn kd_tree_equals_dda_walk_u8(dims in dims_strategy(), seed in any::<u64>(), explicit in any::<bool>(), niso in 1usize..4) {
        let mut rng = Rng::new(seed);
        let grid = grid_for(dims, &mut rng, explicit);
        let n = dims.iter().product::<usize>();
        // Smooth-ish field plus noise so that surfaces are sparse.
        let voxels: Vec<u8> = (0..n).map(|i| {
            let x = (i % dims[0]) as f32;
            let y = ((i / dims[0]) % dims[1]) as f32;
            let z = (i / (dims[0] * dims[1])) as f32;
            let v = 128.0 + 60.0 * (0.7 * x).sin() * (0.5 * y + 0.3 * z).cos() + rng.range_f32(-20.0, 20.0);
            v.clamp(0.0, 255.0) as u8
        }).collect();
        let isos: Vec<f32> = (0..niso).map(|i| if i == 0 { 128.0 } else { rng.range_f32(60.0, 200.0).round() + 0.5 * (i % 2) as f32 }).collect();
        let _hits = compare_scene(&grid, voxels, &isos, &mut rng, 60);
    }

    #[test]
    fn kd_tree_equals_dda_walk_f32_with_void(dims in dims_strategy(), seed in any::<u64>(), explicit in any::<bool>()) {
        let mut rng = Rng::new(seed);
        let grid = grid_for(dims, &mut rng, explicit);
        let n = dims.iter().product::<usize>();
        let voxels: Vec<f32> = (0..n).map(|_| {
            match rng.below(40) {
                0 => f32::NAN,
                1 => f32::INFINITY,
                _ => rng.range_f32(-1.0, 1.0),
            }
        }).collect();
        let isos = [rng.range_f32(-0.5, 0.5), 0.9];
        let _hits = compare_scene(&grid, voxels, &isos, &mut rng, 60);
    }
}

#[test]
fn dda_comparisons_see_many_hits() {
    // Run one fixed comparison and check that a good share of rays hit, so the property
    // tests above compare hits and not only misses.
    let mut rng = Rng::new(5);
    let dims = [17, 9, 12];
    let grid = grid_for(dims, &mut rng, false);
    let n = dims.iter().product::<usize>();
    let voxels: Vec<f32> = (0..n).map(|_| rng.range_f32(-1.0, 1.0)).collect();
    let hits = compare_scene(&grid, voxels, &[0.0, 0.5], &mut rng, 200);
    assert!(hits > 300, "{hits} of 600");
}

#[test]
fn one_sample_thick_volumes_have_no_surface_and_do_not_panic() {
    for dims in [[1, 5, 5], [5, 1, 5], [1, 1, 1], [7, 7, 1]] {
        let grid = Grid::uniform(dims, [0.0; 3], [1.0; 3]).unwrap();
        let n = dims.iter().product();
        let scene = GridScene::new(
            &grid,
            VoxelBuffer::from_vec((0..n).map(|i| i as f32).collect::<Vec<_>>()),
            Intersector::Exact,
            KdTreeConfig::default(),
        )
        .unwrap();
        let ray = Ray::new(Vec3::new(-5.0, 0.5, 0.5), Vec3::X);
        assert_eq!(
            scene.first_hit(&ray, 0.0, f32::INFINITY, &[1.0], &mut NoStats),
            None
        );
        assert!(scene.memory_bytes() < 1024);
    }
}

/// Node ranges of a naive recursive pointer tree, keyed by (level, node index).
#[derive(Debug)]
struct PtrNode {
    range: Option<(f32, f32)>,
    children: Vec<PtrNode>,
}

/// The pointer tree over the cells from `lo` (`ext` cells per side), splitting `axes[level]`
/// at each level.
fn build_ptr(
    vox: &[f32],
    dims: [usize; 3],
    lo: [usize; 3],
    ext: [usize; 3],
    axes: &[usize],
    level: usize,
) -> PtrNode {
    let cells = dims.map(|d| d - 1);
    let hi = [0, 1, 2].map(|a| (lo[a] + ext[a]).min(cells[a]));
    if ext == [1, 1, 1] {
        let c = volume_core::intersect::cell_corners(vox, dims, lo);
        return PtrNode {
            range: corner_range(&c),
            children: vec![],
        };
    }
    let axis = axes[level];
    let mut half = ext;
    half[axis] /= 2;
    let mut children = vec![];
    for side in 0..2 {
        let mut clo = lo;
        clo[axis] += side * half[axis];
        if clo[axis] < cells[axis] {
            children.push(build_ptr(vox, dims, clo, half, axes, level + 1));
        }
    }
    let _ = hi;
    let range = children
        .iter()
        .filter_map(|c| c.range)
        .reduce(|a, b| (a.0.min(b.0), a.1.max(b.1)));
    PtrNode { range, children }
}

fn check_ptr(
    tree: &KdTree<f32>,
    n: &PtrNode,
    level: usize,
    idx: [usize; 3],
    axis_of: &dyn Fn(usize) -> usize,
) {
    if let Some(r) = tree.node_range(level, idx) {
        let expect = n.range.unwrap_or((f32::MAX, f32::MIN));
        assert_eq!(r, expect, "level {level} node {idx:?}");
    }
    if n.children.is_empty() {
        return;
    }
    let a = axis_of(level);
    for (side, c) in n.children.iter().enumerate() {
        let mut ci = idx;
        ci[a] = 2 * idx[a] + side;
        check_ptr(tree, c, level + 1, ci, axis_of);
    }
}

#[test]
fn slim_layout_equals_naive_pointer_tree() {
    let mut rng = Rng::new(7);
    // Unit cells, then cells 6× longer along z than along x (a CT's slices): each level
    // splits the axis along which its nodes are longest in world space.
    let cases = [[2, 2, 2], [3, 5, 2], [9, 4, 6], [17, 3, 10], [6, 6, 6]]
        .map(|d| (d, [1.0; 3]))
        .into_iter()
        .chain([[33, 20, 6], [9, 17, 4], [5, 5, 9]].map(|d| (d, [0.5, 0.6, 3.0])));
    for (dims, spacing) in cases {
        let n: usize = dims.iter().product();
        let vox: Vec<f32> = (0..n)
            .map(|_| {
                if rng.below(13) == 0 {
                    f32::NAN
                } else {
                    rng.range_f32(-5.0, 5.0)
                }
            })
            .collect();
        let grid = Grid::uniform(dims, [0.0; 3], spacing).unwrap();
        let frame = volume_core::intersect::TraversalFrame::new(&grid);
        let tree = KdTree::build(&vox, dims, &frame, KdTreeConfig { unstored_levels: 0 });
        let cells = dims.map(|d| d - 1);
        let pad = cells.map(usize::next_power_of_two);
        // Axis per level: replay the halving of the longest world extent (first on ties)
        // among the axes with more than one cell.
        let mut axes = vec![];
        let mut e = pad;
        while e != [1, 1, 1] {
            let len = |b: usize| e[b] as f64 * spacing[b];
            let a = (0..3)
                .filter(|&b| e[b] > 1)
                .fold(None, |best: Option<usize>, b| match best {
                    Some(x) if len(x) >= len(b) => Some(x),
                    _ => Some(b),
                })
                .unwrap();
            axes.push(a);
            e[a] /= 2;
        }
        assert_eq!(axes.len(), tree.depth());
        let root = build_ptr(&vox, dims, [0; 3], pad, &axes, 0);
        check_ptr(&tree, &root, 0, [0; 3], &|l| axes[l]);
    }
}

#[test]
fn refit_after_edits_equals_rebuild() {
    let mut rng = Rng::new(11);
    let dims = [19, 12, 9];
    let grid = Grid::uniform(dims, [0.0; 3], [1.0; 3]).unwrap();
    let n: usize = dims.iter().product();
    let vox: Vec<i16> = (0..n).map(|_| (rng.below(1000)) as i16).collect();
    let mut scene = GridScene::new(
        &grid,
        VoxelBuffer::from_vec(vox),
        Intersector::Exact,
        KdTreeConfig { unstored_levels: 1 },
    )
    .unwrap();
    for _ in 0..20 {
        let lo = [0, 1, 2].map(|a| rng.index(dims[a]));
        let hi = [0, 1, 2].map(|a| (lo[a] + rng.below(4) as usize).min(dims[a] - 1));
        let val = (rng.below(3000)) as i16 - 1000;
        scene.edit_voxels(lo, hi, |v| {
            for k in lo[2]..=hi[2] {
                for j in lo[1]..=hi[1] {
                    for i in lo[0]..=hi[0] {
                        v[i + dims[0] * (j + dims[1] * k)] = val;
                    }
                }
            }
        });
        let rebuilt = KdTree::build(
            scene.voxels(),
            dims,
            scene.frame(),
            KdTreeConfig { unstored_levels: 1 },
        );
        let tree = scene.tree();
        for level in 0..tree.stored_levels() {
            // Walk all node indices that exist at this level.
            for k in 0..dims[2] {
                for j in 0..dims[1] {
                    for i in 0..dims[0] {
                        let idx = [i, j, k];
                        assert_eq!(
                            tree.node_range(level, idx),
                            rebuilt.node_range(level, idx),
                            "level {level} node {idx:?}"
                        );
                    }
                }
            }
        }
    }
    // Spacing change: only split tables; hits equal a fresh build on the new grid.
    let grid2 = Grid::uniform(dims, [5.0, 0.0, -2.0], [0.5, 2.0, 1.5]).unwrap();
    scene.set_grid(&grid2).unwrap();
    let fresh = GridScene::new(
        &grid2,
        VoxelBuffer::from_vec(scene.voxels().to_vec()),
        Intersector::Exact,
        KdTreeConfig { unstored_levels: 1 },
    )
    .unwrap();
    let b = fresh.world_bounds();
    let mut hits = 0;
    for _ in 0..300 {
        let ray = random_ray(&mut rng, b.min, b.max);
        let x = scene.first_hit(&ray, 0.0, f32::INFINITY, &[400.5], &mut NoStats);
        let y = fresh.first_hit(&ray, 0.0, f32::INFINITY, &[400.5], &mut NoStats);
        assert_eq!(x, y);
        hits += usize::from(x.is_some());
    }
    assert!(hits > 30, "too few hits to be meaningful: {hits}");
}

#[test]
fn sphere_distance_field_hits_within_bound() {
    // f = |p − c| sampled at spacing h on an anisotropic grid far from the origin; the
    // trilinear interpolant of a distance field differs from it by at most
    // Σ h_a²/8 · max|∂²f/∂x_a²| ≤ Σ h_a² / (8 r_min), r_min the smallest radius in the cell.
    let dims = [48, 40, 44];
    let spacing = [0.5f64, 0.6, 0.55];
    let origin = [1e6, -2e5, 3e5];
    let grid = Grid::uniform(dims, origin, spacing).unwrap();
    let c = [0, 1, 2].map(|a| origin[a] + spacing[a] * (dims[a] - 1) as f64 * 0.5);
    let r = 8.0f64;
    let mut vox = Vec::with_capacity(dims.iter().product());
    for k in 0..dims[2] {
        for j in 0..dims[1] {
            for i in 0..dims[0] {
                let p = [i, j, k];
                let d2: f64 = (0..3)
                    .map(|a| (origin[a] + spacing[a] * p[a] as f64 - c[a]).powi(2))
                    .sum();
                vox.push(d2.sqrt() as f32);
            }
        }
    }
    let scene = GridScene::new(
        &grid,
        VoxelBuffer::from_vec(vox),
        Intersector::Exact,
        KdTreeConfig::default(),
    )
    .unwrap();
    let bound = spacing.iter().map(|h| h * h).sum::<f64>() / (8.0 * (r - 1.0));
    let live = scene.live_bounds(&scene.prepare(&[r as f32]));
    let whole = scene.world_bounds();
    assert!(
        (0..3).all(|a| live.extent()[a] < 0.9 * whole.extent()[a]),
        "a sphere of radius 8 in a box of 24: live {live:?} of {whole:?}"
    );
    let mut rng = Rng::new(3);
    let cv = glam::DVec3::from(c);
    let mut stats = CountStats::default();
    for _ in 0..500 {
        // Rays from 20 units away aimed near the centre; the camera sits at 1e6 too.
        let dir = glam::DVec3::new(
            f64::from(rng.range_f32(-1.0, 1.0)),
            f64::from(rng.range_f32(-1.0, 1.0)),
            f64::from(rng.range_f32(-1.0, 1.0)),
        )
        .normalize();
        let eye = cv - dir * 20.0;
        let aim = cv
            + glam::DVec3::new(
                f64::from(rng.range_f32(-3.0, 3.0)),
                f64::from(rng.range_f32(-3.0, 3.0)),
                f64::from(rng.range_f32(-3.0, 3.0)),
            );
        let d = (aim - eye).normalize();
        // Keep the ray in f64 relative to the eye: f32 world coordinates near 1e6 have
        // 0.06 ulps, which is the caller's precision, not the tracer's.
        let ray = Ray::new(eye.as_vec3(), d.as_vec3());
        let eye32 = ray.origin.as_dvec3();
        let hit = scene
            .first_hit(&ray, 0.0, f32::INFINITY, &[r as f32], &mut stats)
            .expect("ray aimed inside the sphere hits it");
        // Far from the origin the live bounds' `f32` corners round by 0.06: still the hit.
        let (lo, hi) = live
            .intersect(&ray, 0.0, f32::INFINITY)
            .expect("a ray that hits meets the live bounds");
        let cut = scene.first_hit(&ray, lo, hi, &[r as f32], &mut NoStats);
        assert_eq!(cut, Some(hit));
        let p = eye32 + ray.dir.as_dvec3() * f64::from(hit.t);
        let err = ((p - cv).length() - r).abs();
        // ulp(1e6) in f32 for the ray origin and 1e-5 relative in t.
        let ray_precision = 0.07 + 1e-5 * f64::from(hit.t);
        assert!(err <= bound + ray_precision, "error {err} > bound {bound}");
        let n = hit.normal.as_dvec3();
        let radial = (p - cv).normalize();
        assert!(n.dot(radial) > 0.98, "normal {n:?} vs radial {radial:?}");
    }
    let counts = stats.counts();
    assert_eq!(counts.rays, 500);
    assert!(counts.leaves_visited > 0 && counts.nodes_visited > 0);
}

/// The layers a packet collects as it goes on past transparent hits
/// ([`IsoScene::peeled_hits_packet_prepared`]) against new single rays shot from past each
/// one, as the renderer used to: the same hits, bit for bit, and the same `more`. Returns
/// the layers seen beyond the first.
fn peeled_equal_reshot<T: Voxel>(
    scene: &GridScene<T>,
    rays: &[Ray],
    t0: &[f32],
    t1: &[f32],
    isos: &[f32],
    rng: &mut Rng,
) -> usize {
    let peel = Peel {
        opaque: u64::from(rng.below(1 << isos.len())),
        max_hits: 1 + rng.below(MAX_PEELED as u32),
        eps: [1e-4, 0.05][rng.below(2) as usize],
    };
    let mut out = vec![PeeledHits::NONE; rays.len()];
    let prepared = scene.prepare(isos);
    scene.peeled_hits_packet_prepared(rays, t0, t1, &prepared, &peel, &mut out, &mut NoStats);
    let mut deeper = 0;
    for (i, ray) in rays.iter().enumerate() {
        let mut want = PeeledHits::NONE;
        let mut t = t0[i];
        while let Some(h) = scene.first_hit(ray, t, t1[i], isos, &mut NoStats) {
            want.push(h);
            if peel.ends_ray(h.surface) || want.n == peel.max_hits {
                want.more = !peel.ends_ray(h.surface);
                break;
            }
            t = peel.next_t(h.t);
        }
        assert_eq!(out[i], want, "ray {i} of {}: {ray:?}, {peel:?}", rays.len());
        deeper += (want.n as usize).saturating_sub(1);
    }
    deeper
}

/// Packets (8 coherent rays from one eye, as a camera makes them) give exactly the
/// single-ray hits, including groups the packet code must split (mixed direction signs).
/// The packets' peeled layers are checked too ([`peeled_equal_reshot`]). Returns the first
/// hits and the deeper layers seen.
fn packets_equal_single<T: Voxel>(
    grid: &Grid,
    voxels: &[T],
    isos: &[f32],
    rng: &mut Rng,
) -> (usize, usize) {
    let (mut hits, mut layers) = (0, 0);
    for unstored in [0, 2] {
        let scene = GridScene::new(
            grid,
            VoxelBuffer::from_vec(voxels.to_vec()),
            Intersector::Exact,
            KdTreeConfig {
                unstored_levels: unstored,
            },
        )
        .unwrap();
        let b = scene.world_bounds();
        for _ in 0..40 {
            let c = (b.min + b.max) * 0.5;
            let ext = (b.max - b.min).max(Vec3::ONE);
            let eye = c + Vec3::new(
                rng.range_f32(-1.5, 1.5),
                rng.range_f32(-1.5, 1.5),
                rng.range_f32(-1.5, 1.5),
            ) * ext;
            let aim = c + Vec3::new(
                rng.range_f32(-0.5, 0.5),
                rng.range_f32(-0.5, 0.5),
                rng.range_f32(-0.5, 0.5),
            ) * ext;
            let spread = rng.range_f32(0.001, 0.3);
            let n = 1 + rng.below(16) as usize;
            let rays: Vec<Ray> = (0..n)
                .map(|_| {
                    let jitter = Vec3::new(
                        rng.range_f32(-1.0, 1.0),
                        rng.range_f32(-1.0, 1.0),
                        rng.range_f32(-1.0, 1.0),
                    ) * spread;
                    Ray::new(eye, ((aim - eye).normalize() + jitter).normalize())
                })
                .collect();
            let t0: Vec<f32> = (0..n).map(|i| if i % 5 == 4 { 2.0 } else { 0.0 }).collect();
            let t1: Vec<f32> = (0..n)
                .map(|i| if i % 7 == 6 { 10.0 } else { f32::INFINITY })
                .collect();
            let mut out = vec![None; n];
            scene.first_hit_packet(&rays, &t0, &t1, isos, &mut out, &mut NoStats);
            // Shadow-ray packets: a hit exactly where the first-hit packets find one.
            let mut occluded = vec![false; n];
            let prepared = scene.prepare(isos);
            scene.occluded_packet_prepared(&rays, &t0, &t1, &prepared, &mut occluded, &mut NoStats);
            for i in 0..n {
                let single = scene.first_hit(&rays[i], t0[i], t1[i], isos, &mut NoStats);
                assert_eq!(out[i], single, "ray {i} of {n}: {:?}", rays[i]);
                assert_eq!(
                    occluded[i],
                    single.is_some(),
                    "occluded, ray {i} of {n}: {:?}",
                    rays[i]
                );
                hits += usize::from(single.is_some());
            }
            layers += peeled_equal_reshot(&scene, &rays, &t0, &t1, isos, rng);
        }
    }
    (hits, layers)
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 32, ..ProptestConfig::default() })]

    #[test]
    fn packet_traversal_equals_single_rays(dims in dims_strategy(), seed in any::<u64>(), explicit in any::<bool>()) {
        let mut rng = Rng::new(seed);
        let grid = grid_for(dims, &mut rng, explicit);
        let n = dims.iter().product::<usize>();
        let voxels: Vec<f32> = (0..n).map(|_| if rng.below(50) == 0 { f32::NAN } else { rng.range_f32(-1.0, 1.0) }).collect();
        let _hits = packets_equal_single(&grid, &voxels, &[0.2, -0.5], &mut rng);
        // One isovalue: a packet's certain crossings are refined after its walk, together.
        let _hits = packets_equal_single(&grid, &voxels, &[0.2], &mut rng);
    }
}

#[test]
fn packet_comparison_sees_hits() {
    let mut rng = Rng::new(21);
    let dims = [20, 17, 9];
    let grid = grid_for(dims, &mut rng, false);
    let voxels: Vec<u8> = (0..dims.iter().product::<usize>())
        .map(|_| (rng.below(256)) as u8)
        .collect();
    let (hits, layers) = packets_equal_single(&grid, &voxels, &[100.5, 200.0], &mut rng);
    // One isovalue (the packets' deferred refinement).
    let (one_hits, _) = packets_equal_single(&grid, &voxels, &[100.5], &mut rng);
    assert!(one_hits > 100, "{one_hits} hits with one isovalue");
    assert!(hits > 200, "{hits}");
    assert!(layers > 200, "{layers}");
}

/// Packets of 16 rays whose halves differ in direction signs (the eye looks across a
/// coordinate plane: the group is split into two packets of 8), and groups of 16 sharing
/// signs (one packet): every ray equals its single-ray hit.
#[test]
fn packet_groups_with_mixed_signs_equal_single_rays() {
    let mut rng = Rng::new(77);
    let dims = [24, 19, 13];
    let grid = grid_for(dims, &mut rng, false);
    let voxels: Vec<f32> = (0..dims.iter().product::<usize>())
        .map(|_| rng.range_f32(-1.0, 1.0))
        .collect();
    let scene = GridScene::new(
        &grid,
        VoxelBuffer::from_vec(voxels),
        Intersector::Exact,
        KdTreeConfig::default(),
    )
    .unwrap();
    let b = scene.world_bounds();
    let c = (b.min + b.max) * 0.5;
    let ext = b.max - b.min;
    let (mut hits, mut total, mut layers) = (0, 0, 0);
    for trial in 0..200 {
        let eye = c + Vec3::new(rng.range_f32(-0.3, 0.3), -1.5, rng.range_f32(-0.3, 0.3)) * ext;
        // Targets left and right of the eye's x (mixed halves) or all on one side.
        let mixed = trial % 2 == 0;
        let rays: Vec<Ray> = (0..16)
            .map(|i| {
                let side = if mixed && i >= 8 { -1.0 } else { 1.0 };
                let target = Vec3::new(
                    eye.x + side * rng.range_f32(0.05, 0.4) * ext.x,
                    c.y + rng.range_f32(-0.3, 0.3) * ext.y,
                    c.z + rng.range_f32(-0.3, 0.3) * ext.z,
                );
                Ray::new(eye, (target - eye).normalize())
            })
            .collect();
        let t0 = vec![0.0; 16];
        let t1 = vec![f32::INFINITY; 16];
        let mut out = vec![None; 16];
        scene.first_hit_packet(&rays, &t0, &t1, &[0.25], &mut out, &mut NoStats);
        for i in 0..16 {
            let single = scene.first_hit(&rays[i], 0.0, f32::INFINITY, &[0.25], &mut NoStats);
            assert_eq!(out[i], single, "trial {trial} ray {i}");
            hits += usize::from(single.is_some());
            total += 1;
        }
        layers += peeled_equal_reshot(&scene, &rays, &t0, &t1, &[0.25, -0.3], &mut rng);
    }
    assert!(hits > total / 2, "{hits} of {total}");
    assert!(layers > total / 2, "{layers} of {total}");
}

/// A blob in one corner of `dims` (distance to a point near the low corner, plus noise),
/// with NaN voids sprinkled in when `T` is a float.
fn corner_blob(dims: [usize; 3], rng: &mut Rng) -> Vec<f32> {
    let c = [0, 1, 2].map(|a| dims[a] as f32 * 0.2);
    let mut vox = Vec::with_capacity(dims.iter().product());
    for k in 0..dims[2] {
        for j in 0..dims[1] {
            for i in 0..dims[0] {
                let p = [i as f32, j as f32, k as f32];
                let d = (0..3).map(|a| (p[a] - c[a]).powi(2)).sum::<f32>().sqrt();
                vox.push(if rng.below(50) == 0 {
                    f32::NAN
                } else {
                    d + rng.range_f32(-0.3, 0.3)
                });
            }
        }
    }
    vox
}

/// Brute force over every cell: the live box holds each cell whose corner range holds an
/// isovalue, comes within a node of them, and is `None` when no cell is live.
#[test]
fn live_cell_box_holds_every_live_cell() {
    let mut rng = Rng::new(21);
    for (dims, unstored) in [([64, 40, 33], 2), ([17, 9, 30], 0), ([5, 70, 6], 3)] {
        let vox = corner_blob(dims, &mut rng);
        let grid = Grid::uniform(dims, [0.0; 3], [1.0; 3]).unwrap();
        let frame = volume_core::intersect::TraversalFrame::new(&grid);
        let tree = KdTree::build(
            &vox,
            dims,
            &frame,
            KdTreeConfig {
                unstored_levels: unstored,
            },
        );
        let cells = dims.map(|d| d - 1);
        for isos in [vec![3.0f32], vec![2.5, 6.0], vec![1e6], vec![-1.0, 4.0]] {
            let set = IsoSet::<f32>::new(&isos);
            let (mut lo, mut hi) = ([usize::MAX; 3], [0usize; 3]);
            for k in 0..cells[2] {
                for j in 0..cells[1] {
                    for i in 0..cells[0] {
                        let c = volume_core::intersect::cell_corners(&vox, dims, [i, j, k]);
                        if corner_range(&c).is_some_and(|(a, b)| set.any_in(a, b)) {
                            for (a, x) in [i, j, k].into_iter().enumerate() {
                                lo[a] = lo[a].min(x);
                                hi[a] = hi[a].max(x);
                            }
                        }
                    }
                }
            }
            let live = tree.live_cell_box(&set);
            if lo[0] == usize::MAX {
                assert_eq!(live, None, "no live cell for {isos:?}");
                continue;
            }
            let [b_lo, b_hi] = live.expect("live cells exist");
            for a in 0..3 {
                assert!(
                    b_lo[a] <= lo[a] && hi[a] <= b_hi[a],
                    "{live:?} misses {lo:?}..{hi:?}"
                );
                assert!(b_hi[a] < cells[a], "{live:?} beyond the cells {cells:?}");
                // Nodes of the scanned level span at most 8 cells on grids this small.
                assert!(lo[a] - b_lo[a] < 8 && b_hi[a] - hi[a] < 8, "{live:?} loose");
            }
        }
    }
}

/// Frames cut to the live bounds equal frames over the whole volume bit for bit, with a
/// transparent surface over an opaque one, shadows and a clip box, and trace fewer rays.
#[test]
fn live_bounds_leave_frames_unchanged_and_trace_fewer_rays() {
    use volume_core::render::{
        Camera, ClipRegion, Keep, Light, LightKind, RenderSettings, Surface, WholeBounds, render,
    };
    let mut rng = Rng::new(5);
    let dims = [48, 36, 40];
    let grid = Grid::uniform(dims, [1e3, -20.0, 5.0], [0.8, 1.0, 1.2]).unwrap();
    let vox: Vec<i16> = corner_blob(dims, &mut rng)
        .into_iter()
        .map(|v| {
            if v.is_finite() {
                (v * 10.0) as i16
            } else {
                600
            }
        })
        .collect();
    let scene = GridScene::new(
        &grid,
        VoxelBuffer::from_vec(vox),
        Intersector::Exact,
        KdTreeConfig::default(),
    )
    .unwrap();
    let b = scene.world_bounds();
    let mut transparent = Surface::new(60.0, [0.9, 0.5, 0.4]);
    transparent.opacity = 0.4;
    let mut settings = RenderSettings {
        width: 96,
        height: 72,
        surfaces: vec![transparent, Surface::new(90.0, [0.8, 0.8, 0.7])],
        shadows: true,
        light: Light {
            kind: LightKind::Directional {
                dir: Vec3::new(-0.3, 0.5, 0.8),
            },
            ..Light::default()
        },
        collect_stats: true,
        ..RenderSettings::default()
    };
    let go = std::sync::atomic::AtomicBool::new(false);
    for (az, clip) in [(30.0, false), (200.0, true)] {
        settings.clips = if clip {
            // Cuts the blob through its centre.
            vec![ClipRegion::Box {
                min: b.min,
                max: Vec3::new(b.min.x + 0.2 * b.extent().x, b.max.y, b.max.z),
                keep: Keep::Outside,
            }]
        } else {
            Vec::new()
        };
        let cam = Camera::orbit(&b, az, 25.0, 40.0);
        let cut = render(&scene, &cam, &settings, &go).unwrap();
        let whole = render(&WholeBounds(&scene), &cam, &settings, &go).unwrap();
        assert_eq!(cut.rgba8, whole.rgba8);
        let bits = |d: &[f32]| d.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&cut.depth), bits(&whole.depth));
        assert!(
            cut.depth.iter().any(|d| d.is_finite()),
            "the blob is in view"
        );
        assert!(
            cut.counts.rays < whole.counts.rays,
            "rays traced: {} cut, {} whole",
            cut.counts.rays,
            whole.counts.rays
        );
    }
}
