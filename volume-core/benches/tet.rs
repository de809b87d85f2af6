//! Tetrahedral-mesh benchmarks (thesis seed 004 §8.7): BIH vs SAH build (Table 8.1),
//! refit of ~1 M tets (§8.5.2), 16×16 vs 2×2 packets (Table 8.4) and 1024² frames through
//! the shared renderer (one isosurface, diffuse shading).
//!
//! `cargo bench -p volume-core --bench tet` (criterion). A summary with the rows for
//! docs/benchmarks.md is printed first; `TET_BENCH_SUMMARY=0` skips it (for profiling with
//! `-- --profile-time 10 frame`). Every timed frame is also checked against single-ray
//! traversal, so the numbers are never of wrong pictures.
//!
//! Meshes (made here: data-samples depends on volume-core, not the other way round):
//! - `cube`: a jittered 38³-point grid split into 6 tets per cell (303,918 tets), field a
//!   wobbly distance from the centre, isovalue 0.7 (a bumpy closed surface);
//! - `ball`: the `isoscope generate tet-ball` construction (cells of a 74³ grid on `[−1, 1]³`
//!   whose centre is inside the radius-0.9 ball, 6 tets each, about 1 M tets at n = 76),
//!   field "gaussians" (sum of three Gaussians, as data-samples), isovalue 0.5.

use std::hint::black_box;
use std::sync::atomic::AtomicBool;
use std::time::Instant;

use criterion::{Criterion, criterion_group, criterion_main};
use glam::Vec3;
use volume_core::math::Ray;
use volume_core::render::{
    Camera, CountStats, IsoScene, Light, NoStats, RenderSettings, Surface, render, render_into,
};
use volume_core::tet::{
    BvhBuilder, BvhOptions, PointField, RawHit, TetMesh, TetScene, lattice_tets, split_hex,
};

/// A wobbly ball field over an `n³`-point jittered grid split into 6 tets per cube.
fn cube_mesh(n: usize) -> TetMesh {
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
    let tets = lattice_tets(n, id);
    TetMesh::new(points, tets, vec![PointField::new("f", values)]).unwrap()
}

/// The data-samples tet ball (`n` cells per axis): field "f" is "gaussians", and
/// "distance" from the centre (iso 0.85: a sphere covering ~40 % of the pixels).
fn ball_mesh(n: usize) -> TetMesh {
    const GAUSSIANS: [([f64; 3], f64, f64); 3] = [
        ([0.4, 0.1, 0.0], 1.0, 0.25),
        ([-0.3, 0.35, 0.2], 0.8, 0.2),
        ([0.0, -0.45, -0.3], 0.6, 0.3),
    ];
    const CORNERS: [[usize; 3]; 8] = [
        [0, 0, 0],
        [1, 0, 0],
        [1, 1, 0],
        [0, 1, 0],
        [0, 0, 1],
        [1, 0, 1],
        [1, 1, 1],
        [0, 1, 1],
    ];
    let centre = [0.013, -0.021, 0.008];
    let coord = |i: usize| -1.0 + 2.0 * i as f64 / n as f64;
    let np = n + 1;
    let gid = |i: usize, j: usize, k: usize| i + np * (j + np * k);
    let mut kept = Vec::new();
    for k in 0..n {
        for j in 0..n {
            for i in 0..n {
                let c = [i, j, k].map(|a| coord(a) + 1.0 / n as f64);
                let d2: f64 = (0..3).map(|a| (c[a] - centre[a]).powi(2)).sum();
                if d2.sqrt() <= 0.9 {
                    kept.push([i, j, k]);
                }
            }
        }
    }
    let mut remap = vec![u32::MAX; np * np * np];
    for &[i, j, k] in &kept {
        for [di, dj, dk] in CORNERS {
            remap[gid(i + di, j + dj, k + dk)] = 0;
        }
    }
    let (mut points, mut values, mut dist) = (Vec::new(), Vec::new(), Vec::new());
    let mut next = 0u32;
    for (g, slot) in remap.iter_mut().enumerate() {
        if *slot == 0 {
            *slot = next;
            next += 1;
            let p = [g % np, (g / np) % np, g / (np * np)].map(coord);
            let v: f64 = GAUSSIANS
                .iter()
                .map(|&(c, a, s)| {
                    let r2: f64 = (0..3).map(|x| (p[x] - c[x]).powi(2)).sum();
                    a * (-r2 / (2.0 * s * s)).exp()
                })
                .sum();
            points.push(p.map(|x| x as f32));
            values.push(v as f32);
            let d2: f64 = (0..3).map(|a| (p[a] - centre[a]).powi(2)).sum();
            dist.push(d2.sqrt() as f32);
        }
    }
    let mut tets = Vec::with_capacity(kept.len() * 6);
    for &[i, j, k] in &kept {
        tets.extend(split_hex(
            CORNERS.map(|[di, dj, dk]| remap[gid(i + di, j + dj, k + dk)]),
        ));
    }
    TetMesh::new(
        points,
        tets,
        vec![
            PointField::new("f", values),
            PointField::new("distance", dist),
        ],
    )
    .unwrap()
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

fn camera(scene: &TetScene) -> Camera {
    Camera::orbit(&scene.world_bounds(), 30.0, 20.0, 40.0)
}

fn settings(iso: f32, side: u32, packets: bool, stats: bool) -> RenderSettings {
    RenderSettings {
        width: side,
        height: side,
        surfaces: vec![Surface::new(iso, [0.8, 0.7, 0.5])],
        // Diffuse shading (no highlight), headlight, no shadows: the target setup of docs/benchmarks.md.
        light: Light {
            specular: 0.0,
            ..Light::default()
        },
        packets,
        collect_stats: stats,
        ..RenderSettings::default()
    }
}

/// 1024² primary rays, 16×16 tiles in Morton order (as the renderer makes them).
fn tile_rays(scene: &TetScene, side: u32) -> Vec<Ray> {
    let cam = camera(scene);
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

/// Renders once with statistics and checks depth against single-ray traversal.
fn checked_frame(scene: &TetScene, iso: f32, side: u32) -> volume_core::render::Frame {
    let go = AtomicBool::new(false);
    let cam = camera(scene);
    let f = render(scene, &cam, &settings(iso, side, true, true), &go).unwrap();
    let single = render(scene, &cam, &settings(iso, side, false, false), &go).unwrap();
    let bad = f
        .depth
        .iter()
        .zip(&single.depth)
        .filter(|(a, b)| !(a == b || (*a - *b).abs() <= 1e-4 * a.abs().max(1.0)))
        .count();
    assert_eq!(bad, 0, "packet frame differs from single rays");
    f
}

fn frame_ms(scene: &TetScene, iso: f32, side: u32, reps: usize) -> f64 {
    let go = AtomicBool::new(false);
    let cam = camera(scene);
    let s = settings(iso, side, true, false);
    render(scene, &cam, &s, &go).unwrap();
    best_ms(reps, || {
        black_box(render(scene, &cam, &s, &go).unwrap());
    })
}

/// Process CPU time (user + system, all threads) in ms, from `/proc/self/stat` (10 ms ticks):
/// on a shared machine it is steadier than wall time. `NaN` where unavailable.
fn cpu_ms() -> f64 {
    std::fs::read_to_string("/proc/self/stat")
        .ok()
        .and_then(|s| {
            let rest = &s[s.rfind(')')? + 2..];
            let f: Vec<&str> = rest.split(' ').collect();
            let ticks = f.get(11)?.parse::<f64>().ok()? + f.get(12)?.parse::<f64>().ok()?;
            Some(ticks * 10.0)
        })
        .unwrap_or(f64::NAN)
}

/// CPU ms per call of `f`, over enough calls for at least ~1 s of CPU time.
fn cpu_ms_per(mut f: impl FnMut()) -> f64 {
    let (c0, mut n) = (cpu_ms(), 0);
    let t = Instant::now();
    while n < 3 || (cpu_ms() - c0 < 1000.0 && t.elapsed().as_secs() < 20) {
        f();
        n += 1;
    }
    (cpu_ms() - c0) / f64::from(n)
}

/// Renderer-like packets: per 16×16 tile, only the rays that meet the scene bounds, with
/// `[t_min, t_max]` cut to them (the renderer passes no others). Returns the rays, ranges
/// and the packet start offsets.
fn bounded_packets(scene: &TetScene, side: u32) -> (Vec<Ray>, Vec<f32>, Vec<f32>, Vec<usize>) {
    let b = scene.world_bounds();
    let (mut rays, mut t0, mut t1, mut starts) = (Vec::new(), Vec::new(), Vec::new(), vec![]);
    for tile in tile_rays(scene, side).chunks(256) {
        starts.push(rays.len());
        for r in tile {
            if let Some((a, c)) = b.intersect(r, 0.0, f32::INFINITY) {
                rays.push(*r);
                t0.push(a);
                t1.push(c);
            }
        }
    }
    starts.push(rays.len());
    (rays, t0, t1, starts)
}

/// Traces renderer-like packets ([`bounded_packets`]) one by one; `normals` through the
/// `IsoScene` entry point (with the shading normal), else raw hits.
fn trace_packets(
    scene: &TetScene,
    p: &(Vec<Ray>, Vec<f32>, Vec<f32>, Vec<usize>),
    iso: f32,
    normals: bool,
) -> usize {
    let (rays, t0, t1, starts) = p;
    let mut raw = [None; 256];
    let mut hits = [None; 256];
    let mut n_hit = 0;
    for w in starts.windows(2) {
        let (s, e) = (w[0], w[1]);
        if s == e {
            continue;
        }
        let n = e - s;
        if normals {
            scene.first_hit_packet(
                &rays[s..e],
                &t0[s..e],
                &t1[s..e],
                &[iso],
                &mut hits[..n],
                &mut NoStats,
            );
            n_hit += hits[..n].iter().filter(|h| h.is_some()).count();
        } else {
            scene.first_hit_packet_raw(
                &rays[s..e],
                &t0[s..e],
                &t1[s..e],
                &[iso],
                &mut raw[..n],
                &mut NoStats,
            );
            n_hit += raw[..n].iter().filter(|h| h.is_some()).count();
        }
    }
    n_hit
}

/// Where a frame's time goes (`TET_BENCH_ONLY=probe`); `TET_BENCH_ONLY=loop-empty`,
/// `loop-frame`, `loop-trace` (cube), `loop-frame-ball`, `loop-frame-sphere` (distance 0.85),
/// `loop-trace-ball` run one part for
/// ~10 s (for `perf record`; `TET_BENCH_SIDE` sets the frame side, default 1024, and
/// `TET_BENCH_LOOPS` a fixed number of loops instead, e.g. 256 and 2 for callgrind).
fn probe(mode: &str) {
    let cube = cube_mesh(38);
    let scene = TetScene::new(&cube, "f", BvhOptions::default()).unwrap();
    let go = AtomicBool::new(false);
    let until = Instant::now() + std::time::Duration::from_secs(10);
    let side: u32 = std::env::var("TET_BENCH_SIDE")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(1024);
    // A fixed number of loops instead of ~10 s (instruction counts under callgrind).
    let loops: Option<usize> = std::env::var("TET_BENCH_LOOPS")
        .ok()
        .and_then(|s| s.parse().ok());
    let mut done = 0;
    let mut more = move || {
        done += 1;
        loops.map_or(Instant::now() < until, |n| done < n)
    };
    match mode {
        "loop-empty" | "loop-frame" | "loop-frame-ball" | "loop-frame-sphere" => {
            let ball;
            let (scene, iso) = match mode {
                "loop-empty" => (&scene, 100.0),
                "loop-frame" => (&scene, 0.7),
                "loop-frame-ball" => {
                    ball = TetScene::new(&ball_mesh(46), "f", BvhOptions::default()).unwrap();
                    (&ball, 0.5)
                }
                _ => {
                    let field = "distance";
                    ball = TetScene::new(&ball_mesh(46), field, BvhOptions::default()).unwrap();
                    (&ball, 0.85)
                }
            };
            let cam = camera(scene);
            let s = settings(iso, side, true, false);
            let mut frame = volume_core::render::Frame::default();
            loop {
                assert!(render_into(scene, &cam, &s, &go, &mut frame));
                black_box(&frame);
                if !more() {
                    break;
                }
            }
            return;
        }
        "loop-trace" | "loop-trace-ball" => {
            let (scene, iso) = if mode == "loop-trace" {
                (scene, 0.7)
            } else {
                let ball = ball_mesh(46);
                (
                    TetScene::new(&ball, "f", BvhOptions::default()).unwrap(),
                    0.5,
                )
            };
            let p = bounded_packets(&scene, side);
            loop {
                black_box(trace_packets(&scene, &p, iso, false));
                if !more() {
                    break;
                }
            }
            return;
        }
        _ => {}
    }
    let ball_mesh = ball_mesh(46);
    let ball = TetScene::new(&ball_mesh, "f", BvhOptions::default()).unwrap();
    let sphere = TetScene::new(&ball_mesh, "distance", BvhOptions::default()).unwrap();
    // Whole frames as `isoscope bench` (`render`: a new frame each time) and as an
    // interactive caller that keeps its frame (`render_into`); all rayon threads.
    let mut frame = volume_core::render::Frame::default();
    for (name, scene, what, iso) in [
        ("cube", &scene, "no surface (renderer only)", 100.0f32),
        ("cube", &scene, "isovalue 0.7", 0.7),
        ("ball", &ball, "isovalue 0.5", 0.5),
        ("ball", &sphere, "distance 0.85", 0.85),
    ] {
        let cam = camera(scene);
        let s = settings(iso, 1024, true, false);
        let wall = best_ms(10, || {
            black_box(render(scene, &cam, &s, &go).unwrap());
        });
        let cpu = cpu_ms_per(|| {
            black_box(render(scene, &cam, &s, &go).unwrap());
        });
        let cpu_into = cpu_ms_per(|| {
            assert!(render_into(scene, &cam, &s, &go, &mut frame));
        });
        let wall_into = best_ms(10, || {
            assert!(render_into(scene, &cam, &s, &go, &mut frame));
        });
        println!(
            "{name} frame, {what}, {} threads: render wall {wall:.1} ms, cpu {cpu:.1} ms/frame; \
             render_into wall {wall_into:.1} ms, cpu {cpu_into:.1} ms/frame",
            rayon::current_num_threads()
        );
    }
    for (name, scene, iso) in [
        ("cube", &scene, 0.7f32),
        ("ball", &ball, 0.5),
        ("ball distance", &sphere, 0.85),
    ] {
        let p = bounded_packets(scene, 1024);
        let hits = trace_packets(scene, &p, iso, false);
        let cpu = cpu_ms_per(|| {
            black_box(trace_packets(scene, &p, iso, false));
        });
        println!(
            "{name}: trace only, 1 thread, {} rays in bounds, {hits} hits: cpu {cpu:.1} ms/frame",
            p.0.len()
        );
        let cpu = cpu_ms_per(|| {
            black_box(trace_packets(scene, &p, iso, true));
        });
        println!("{name}: first_hit_packet incl. normals, 1 thread: cpu {cpu:.1} ms/frame");
    }
}

fn summary() {
    let side = 1024;
    println!("threads: {}", rayon::current_num_threads());
    for (name, mesh, iso) in [
        ("cube", cube_mesh(38), 0.7f32),
        ("ball", ball_mesh(46), 0.5f32),
    ] {
        println!(
            "\n## {name}: {} tets, {} points, isovalue {iso}",
            mesh.num_tets(),
            mesh.num_points()
        );
        // Table 8.1: BIH vs SAH.
        println!("| builder | build ms | nodes | depth | tets/leaf | 1024² ms | fps | hit px |");
        println!("|---|---|---|---|---|---|---|---|");
        for builder in [BvhBuilder::Bih, BvhBuilder::Sah] {
            let opts = BvhOptions {
                builder,
                leaf_size: 12,
            };
            let build = best_ms(5, || {
                black_box(TetScene::new(&mesh, "f", opts).unwrap());
            });
            let scene = TetScene::new(&mesh, "f", opts).unwrap();
            scene.validate().unwrap();
            let f = checked_frame(&scene, iso, side);
            let hit = f.depth.iter().filter(|d| d.is_finite()).count();
            let ms = frame_ms(&scene, iso, side, 7);
            let info = scene.bvh_info();
            println!(
                "| {builder:?} | {build:.1} | {} | {} | {:.1} | {ms:.1} | {:.1} | {hit} |",
                info.nodes,
                info.max_depth,
                info.mean_leaf_tets,
                1e3 / ms
            );
        }
        // Leaf-size sweep (BIH).
        println!("| leaf size | 1024² ms |");
        println!("|---|---|");
        for leaf_size in [2, 4, 8, 12, 16, 24] {
            let scene = TetScene::new(
                &mesh,
                "f",
                BvhOptions {
                    builder: BvhBuilder::Bih,
                    leaf_size,
                },
            )
            .unwrap();
            println!("| {leaf_size} | {:.1} |", frame_ms(&scene, iso, side, 5));
        }
        // Table 8.4: 16×16 vs 2×2 on the same rays (per primary ray; one thread).
        let mut scene = TetScene::new(&mesh, "f", BvhOptions::default()).unwrap();
        let rays = tile_rays(&scene, side);
        let single: Vec<Option<f32>> = rays
            .iter()
            .map(|r| {
                scene
                    .first_hit_raw(r, 0.0, f32::INFINITY, &[iso], &mut NoStats)
                    .map(|h| h.t)
            })
            .collect();
        println!(
            "| packet | box tests/ray | ray–poly tests/ray | extractions/ray | nodes/ray | 1 thread ms |"
        );
        println!("|---|---|---|---|---|---|");
        let mut rows = Vec::new();
        for packet in [4, 256] {
            scene.set_packet_size(packet);
            let (out, st) = trace(&scene, &rays, &[iso]);
            let ms = best_ms(3, || {
                black_box(trace(&scene, &rays, &[iso]));
            });
            let bad = out
                .iter()
                .zip(&single)
                .filter(|(a, b)| match (a.map(|h| h.t), **b) {
                    (None, None) => false,
                    (Some(x), Some(y)) => (x - y).abs() > 1e-4 * x.abs().max(1.0),
                    _ => true,
                })
                .count();
            assert_eq!(bad, 0, "packet {packet} differs from single rays");
            let c = st.0;
            let per = |x: u64| x as f64 / c.rays as f64;
            println!(
                "| {} | {:.3} | {:.3} | {:.4} | {:.3} | {ms:.0} |",
                if packet == 4 { "2×2" } else { "16×16" },
                per(c.box_tests),
                per(c.intersection_tests),
                per(c.polygon_extractions),
                per(c.nodes_visited)
            );
            rows.push((c, ms));
        }
        let (a, b) = (rows[0].0, rows[1].0);
        let r = |x: u64, y: u64| x as f64 / y.max(1) as f64;
        println!(
            "| ratio 2×2/16×16 | {:.1}× | {:.2}× | {:.1}× | {:.1}× | {:.2}× |",
            r(a.box_tests, b.box_tests),
            r(a.intersection_tests, b.intersection_tests),
            r(a.polygon_extractions, b.polygon_extractions),
            r(a.nodes_visited, b.nodes_visited),
            rows[0].1 / rows[1].1
        );
    }

    // Refit of ~1 M tets.
    let big = ball_mesh(76);
    // The BIH rebuild: the cheapest full build, against which the refit is compared.
    let bih = BvhOptions {
        builder: BvhBuilder::Bih,
        ..BvhOptions::default()
    };
    let build = best_ms(3, || {
        black_box(TetScene::new(&big, "f", bih).unwrap());
    });
    let mut scene = TetScene::new(&big, "f", BvhOptions::default()).unwrap();
    let values: Vec<f32> = big.fields[0].values.iter().map(|v| v * 1.1).collect();
    let moved: Vec<[f32; 3]> = big
        .points
        .iter()
        .map(|p| [p[0] * 1.01, p[1], p[2] + 0.01 * p[0]])
        .collect();
    let scalars = best_ms(7, || scene.refit_scalars(&values).unwrap());
    let positions = best_ms(7, || scene.refit_positions(&moved).unwrap());
    scene.validate().unwrap();
    println!(
        "\n| {} tets | BIH build {build:.0} ms | refit scalars {scalars:.1} ms | refit positions {positions:.1} ms | rebuild/refit {:.0}× |",
        big.num_tets(),
        build / positions
    );
}

fn bench(c: &mut Criterion) {
    if let Ok(mode) = std::env::var("TET_BENCH_ONLY") {
        probe(&mode);
        return;
    }
    if std::env::var("TET_BENCH_SUMMARY").as_deref() != Ok("0") {
        summary();
    }
    let mesh = cube_mesh(38);
    let iso = 0.7;
    let mut g = c.benchmark_group("tet_cube_304k");
    g.sample_size(10);
    for builder in [BvhBuilder::Bih, BvhBuilder::Sah] {
        let opts = BvhOptions {
            builder,
            leaf_size: 12,
        };
        g.bench_function(format!("build_{builder:?}"), |bn| {
            bn.iter(|| TetScene::new(&mesh, "f", opts).unwrap());
        });
    }
    let mut scene = TetScene::new(&mesh, "f", BvhOptions::default()).unwrap();
    let cam = camera(&scene);
    let go = AtomicBool::new(false);
    for (name, packet) in [("frame_1024_16x16", 256), ("frame_1024_2x2", 4)] {
        scene.set_packet_size(packet);
        let s = settings(iso, 1024, true, false);
        g.bench_function(name, |bn| {
            bn.iter(|| render(&scene, &cam, &s, &go).unwrap());
        });
    }
    g.finish();

    let big = ball_mesh(76);
    let mut scene = TetScene::new(&big, "f", BvhOptions::default()).unwrap();
    let moved: Vec<[f32; 3]> = big
        .points
        .iter()
        .map(|p| [p[0] * 1.01, p[1], p[2] + 0.01 * p[0]])
        .collect();
    let mut g = c.benchmark_group(format!("tet_ball_{}k", big.num_tets() / 1000));
    g.sample_size(10);
    g.bench_function("refit_positions", |bn| {
        bn.iter(|| scene.refit_positions(&moved).unwrap());
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
