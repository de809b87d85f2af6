//! Tetrahedral BVH measurements (ignored by default; numbers go to docs/benchmarks.md).
//!
//! `cargo test -p volume-core --test tet_perf -- --ignored --nocapture --test-threads 1`
//!
//! Prints: BIH vs SAH build time and frame time (thesis Table 8.1), leaf-size sweep, refit
//! of ~1 M tets, ray–box tests of 16×16 vs 2×2 packets (Table 8.4), and 1024² frame times
//! through the shared renderer. Every timed result is also checked against the single-ray
//! traversal so the numbers are never of wrong pictures.

use std::sync::atomic::AtomicBool;
use std::time::Instant;

use glam::Vec3;
use volume_core::math::Ray;
use volume_core::render::{Camera, CountStats, NoStats, RenderSettings, Surface, render};
use volume_core::tet::{BvhBuilder, BvhOptions, PointField, RawHit, TetMesh, TetScene, split_hex};

/// A wobbly ball field over an `n³`-point jittered grid split into 6 tets per cube.
fn ball_mesh(n: usize) -> TetMesh {
    let id = |i: usize, j: usize, k: usize| (i + n * (j + n * k)) as u32;
    let c = (n - 1) as f32 * 0.5;
    let mut points = Vec::with_capacity(n * n * n);
    let mut values = Vec::with_capacity(n * n * n);
    for k in 0..n {
        for j in 0..n {
            for i in 0..n {
                let h = ((i * 73_856_093) ^ (j * 19_349_663) ^ (k * 83_492_791)) % 1000;
                let jitter = (h as f32 / 1000.0 - 0.5) * 0.3;
                let p = Vec3::new(
                    i as f32 + jitter,
                    j as f32 - jitter,
                    k as f32 + 0.5 * jitter,
                );
                let q = (p - Vec3::splat(c)) / c;
                values.push(q.length() + 0.08 * (5.0 * q.x).sin() * (4.0 * q.y).cos());
                points.push(p.to_array());
            }
        }
    }
    let mut tets = Vec::with_capacity((n - 1).pow(3) * 6);
    for k in 0..n - 1 {
        for j in 0..n - 1 {
            for i in 0..n - 1 {
                tets.extend(split_hex([
                    id(i, j, k),
                    id(i + 1, j, k),
                    id(i + 1, j + 1, k),
                    id(i, j + 1, k),
                    id(i, j, k + 1),
                    id(i + 1, j, k + 1),
                    id(i + 1, j + 1, k + 1),
                    id(i, j + 1, k + 1),
                ]));
            }
        }
    }
    TetMesh::new(points, tets, vec![PointField::new("f", values)]).unwrap()
}

fn best_ms(reps: usize, mut f: impl FnMut()) -> f64 {
    (0..reps)
        .map(|_| {
            let t = Instant::now();
            f();
            t.elapsed().as_secs_f64() * 1e3
        })
        .fold(f64::INFINITY, f64::min)
}

/// 1024² primary rays, 16×16 tiles in Morton order (as the renderer makes them).
fn tile_rays(scene: &TetScene, side: u32) -> Vec<Ray> {
    let cam = Camera::orbit(
        &volume_core::render::IsoScene::world_bounds(scene),
        30.0,
        20.0,
        40.0,
    );
    let mut rays = Vec::with_capacity((side * side) as usize);
    for ty in 0..side / 16 {
        for tx in 0..side / 16 {
            for m in 0..256u32 {
                let (mut x, mut y) = (0u32, 0u32);
                for b in 0..4 {
                    x |= ((m >> (2 * b)) & 1) << b;
                    y |= ((m >> (2 * b + 1)) & 1) << b;
                }
                rays.push(cam.primary_ray(tx * 16 + x, ty * 16 + y, side, side));
            }
        }
    }
    rays
}

fn trace(scene: &TetScene, rays: &[Ray], iso: &[f32]) -> (Vec<Option<RawHit>>, CountStats) {
    let n = rays.len();
    let mut out = vec![None; n];
    let mut stats = CountStats::default();
    scene.first_hit_packet_raw(
        rays,
        &vec![0.0; n],
        &vec![f32::INFINITY; n],
        iso,
        &mut out,
        &mut stats,
    );
    (out, stats)
}

fn frame_ms(scene: &TetScene, iso: f32, side: u32) -> f64 {
    let cam = Camera::orbit(
        &volume_core::render::IsoScene::world_bounds(scene),
        30.0,
        20.0,
        40.0,
    );
    let settings = RenderSettings {
        width: side,
        height: side,
        surfaces: vec![Surface::new(iso, [0.8, 0.7, 0.5])],
        ..RenderSettings::default()
    };
    let go = AtomicBool::new(false);
    render(scene, &cam, &settings, &go).unwrap();
    best_ms(5, || {
        render(scene, &cam, &settings, &go).unwrap();
    })
}

#[test]
#[ignore = "measurement; run with --ignored --nocapture"]
fn tet_bvh_measurements() {
    let iso = [0.7f32];
    let mesh = ball_mesh(38);
    println!(
        "mesh: {} tets, {} points, {} threads",
        mesh.num_tets(),
        mesh.num_points(),
        rayon::current_num_threads()
    );

    // Table 8.1: BIH vs SAH build and frame time.
    for builder in [BvhBuilder::Bih, BvhBuilder::Sah] {
        let opts = BvhOptions {
            builder,
            leaf_size: 12,
        };
        let ms = best_ms(3, || {
            TetScene::new(&mesh, "f", opts).unwrap();
        });
        let scene = TetScene::new(&mesh, "f", opts).unwrap();
        scene.validate().unwrap();
        let info = scene.bvh_info();
        let fm = frame_ms(&scene, iso[0], 1024);
        println!(
            "build {builder:?}: {ms:.1} ms; {} nodes, depth {}, {:.1} tets/leaf; 1024² frame {fm:.1} ms ({:.1} fps)",
            info.nodes,
            info.max_depth,
            info.mean_leaf_tets,
            1e3 / fm
        );
    }

    // Leaf-size sweep (BIH), 1024² frame through the renderer.
    for leaf_size in [4, 8, 12, 16, 24] {
        let scene = TetScene::new(
            &mesh,
            "f",
            BvhOptions {
                builder: BvhBuilder::Bih,
                leaf_size,
            },
        )
        .unwrap();
        println!(
            "leaf {leaf_size:2}: 1024² frame {:.1} ms",
            frame_ms(&scene, iso[0], 1024)
        );
    }

    // Table 8.4: 16×16 vs 2×2 packets on 1024² primary rays (same hits).
    let mut scene = TetScene::new(&mesh, "f", BvhOptions::default()).unwrap();
    let rays = tile_rays(&scene, 1024);
    let mut rows = Vec::new();
    for packet in [4, 256] {
        scene.set_packet_size(packet);
        let t = Instant::now();
        let (out, st) = trace(&scene, &rays, &iso);
        let ms = t.elapsed().as_secs_f64() * 1e3;
        let c = st.0;
        let per = |x: u64| x as f64 / c.rays as f64;
        println!(
            "packet {packet:3}: box tests {:.2}/ray, ray-poly tests {:.2}/ray, extractions {:.3}/ray, nodes {:.3}/ray; single thread {ms:.0} ms",
            per(c.box_tests),
            per(c.intersection_tests),
            per(c.polygon_extractions),
            per(c.nodes_visited)
        );
        rows.push((out, c));
    }
    let single: Vec<Option<f32>> = rays
        .iter()
        .map(|r| {
            scene
                .first_hit_raw(r, 0.0, f32::INFINITY, &iso, &mut NoStats)
                .map(|h| h.t)
        })
        .collect();
    for (out, _) in &rows {
        let bad = out
            .iter()
            .zip(&single)
            .filter(|(a, b)| match (a.map(|h| h.t), **b) {
                (None, None) => false,
                (Some(x), Some(y)) => (x - y).abs() > 1e-4 * x.abs().max(1.0),
                _ => true,
            })
            .count();
        assert_eq!(bad, 0);
    }
    println!(
        "ratio 2x2/16x16: box tests {:.1}x, ray-poly tests {:.2}x, extractions {:.1}x",
        rows[0].1.box_tests as f64 / rows[1].1.box_tests as f64,
        rows[0].1.intersection_tests as f64 / rows[1].1.intersection_tests as f64,
        rows[0].1.polygon_extractions as f64 / rows[1].1.polygon_extractions as f64
    );

    // Refit of ~1 M tets.
    let big = ball_mesh(56);
    let mut scene = TetScene::new(&big, "f", BvhOptions::default()).unwrap();
    let build = best_ms(2, || {
        TetScene::new(&big, "f", BvhOptions::default()).unwrap();
    });
    let values: Vec<f32> = big.fields[0].values.iter().map(|v| v * 1.1).collect();
    let moved: Vec<[f32; 3]> = big
        .points
        .iter()
        .map(|p| [p[0] * 1.01, p[1], p[2] + 0.01 * p[0]])
        .collect();
    let scalars = best_ms(5, || scene.refit_scalars(&values).unwrap());
    let positions = best_ms(5, || scene.refit_positions(&moved).unwrap());
    scene.validate().unwrap();
    println!(
        "{} tets: BIH build {build:.0} ms, refit scalars {scalars:.1} ms, refit positions {positions:.1} ms",
        big.num_tets()
    );
}
