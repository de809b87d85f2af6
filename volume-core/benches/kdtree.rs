//! Kd-tree benchmarks: build time, memory overhead and primary-ray throughput of the
//! kd-tree (single rays and packets) against the brute-force DDA, on a synthetic CT-like
//! i16 volume (256×256×110) and Marschner–Lobb fields.
//!
//! `cargo bench -p volume-core --bench kdtree` (criterion); a summary with rays/s and
//! memory ratios is printed first (rows for docs/benchmarks.md).
//!
//! `KDBENCH=render cargo bench -p volume-core --bench kdtree` instead times whole frames of
//! the renderer (what `isoscope bench` measures: packets, single rays and the DDA in the
//! same run, Blinn–Phong shading included) on the CT-like volume at 1024² and on
//! Marschner–Lobb 64³…512³ at 512² (`KDBENCH_ML=64,512` picks the sizes), then exits.

use std::hint::black_box;
use std::time::Instant;

use criterion::{Criterion, criterion_group, criterion_main};
use glam::Vec3;
use rayon::prelude::*;
use volume_core::grid_scene::GridScene;
use volume_core::intersect::Intersector;
use volume_core::kdtree::KdTreeConfig;
use volume_core::math::Ray;
use volume_core::render::{
    Camera, CountStats, IsoScene, NoStats, RenderSettings, Stats, Surface, render,
};
use volume_core::{Grid, Voxel, VoxelBuffer};

/// A CT-like head: air, soft tissue with texture, a bone shell, and inner structures.
fn ct_like(dims: [usize; 3]) -> Vec<i16> {
    let c = dims.map(|d| d as f32 * 0.5);
    let mut v = vec![0i16; dims.iter().product()];
    v.par_chunks_mut(dims[0] * dims[1])
        .enumerate()
        .for_each(|(k, slice)| {
            for j in 0..dims[1] {
                for i in 0..dims[0] {
                    let p = Vec3::new(
                        (i as f32 - c[0]) / (0.45 * dims[0] as f32),
                        (j as f32 - c[1]) / (0.40 * dims[1] as f32),
                        (k as f32 - c[2]) / (0.48 * dims[2] as f32),
                    );
                    let r = p.length();
                    let tex = 30.0 * (0.31 * i as f32).sin() * (0.23 * j as f32).cos()
                        + 20.0 * (0.17 * k as f32 + 0.05 * i as f32).sin();
                    let val = if r > 1.0 {
                        -1000.0 + tex
                    } else if r > 0.9 {
                        1100.0 + 3.0 * tex
                    } else {
                        let blob = (6.0 * p.x).sin() * (5.0 * p.y).cos() * (4.0 * p.z).sin();
                        40.0 + tex + if blob > 0.6 { 700.0 } else { 0.0 }
                    };
                    slice[i + dims[0] * j] = val as i16;
                }
            }
        });
    v
}

/// Marschner–Lobb (1994) test signal on `[-1, 1]³`, alpha 0.25, f_M 6.
fn marschner_lobb(n: usize) -> Vec<f32> {
    let mut v = vec![0f32; n * n * n];
    v.par_chunks_mut(n * n).enumerate().for_each(|(k, s)| {
        for j in 0..n {
            for i in 0..n {
                let x = 2.0 * i as f32 / (n - 1) as f32 - 1.0;
                let y = 2.0 * j as f32 / (n - 1) as f32 - 1.0;
                let z = 2.0 * k as f32 / (n - 1) as f32 - 1.0;
                let r = (x * x + y * y).sqrt();
                let rho =
                    (2.0 * std::f32::consts::PI * 6.0 * (std::f32::consts::PI * r / 2.0).cos())
                        .cos();
                s[i + n * j] = (1.0 - (std::f32::consts::PI * z / 2.0).sin() + 0.25 * (1.0 + rho))
                    / (2.0 * 1.25);
            }
        }
    });
    v
}

/// Pinhole rays at `size²` looking at the box centre from `dir_from_center`.
fn camera_rays(lo: Vec3, hi: Vec3, size: usize, dir_from_center: Vec3) -> Vec<Ray> {
    let c = (lo + hi) * 0.5;
    let radius = (hi - lo).length() * 0.5;
    let eye = c + dir_from_center.normalize() * radius * 2.6;
    let fwd = (c - eye).normalize();
    let right = fwd.cross(Vec3::Z).normalize();
    let up = right.cross(fwd);
    let tan = (20f32).to_radians().tan();
    let mut rays = Vec::with_capacity(size * size);
    for j in 0..size {
        for i in 0..size {
            let u = (2.0 * (i as f32 + 0.5) / size as f32 - 1.0) * tan;
            let v = (1.0 - 2.0 * (j as f32 + 0.5) / size as f32) * tan;
            rays.push(Ray::new(eye, (fwd + right * u + up * v).normalize()));
        }
    }
    rays
}

/// One frame over rayon in tiles of 64 rays; returns hits.
fn frame<S: IsoScene>(scene: &S, rays: &[Ray], isos: &[f32], packets: bool) -> usize {
    rays.par_chunks(64)
        .map(|chunk| {
            if packets {
                let t0 = [0.0f32; 64];
                let t1 = [f32::INFINITY; 64];
                let mut out = [None; 64];
                let n = chunk.len();
                scene.first_hit_packet(
                    chunk,
                    &t0[..n],
                    &t1[..n],
                    isos,
                    &mut out[..n],
                    &mut NoStats,
                );
                out[..n].iter().filter(|h| h.is_some()).count()
            } else {
                chunk
                    .iter()
                    .filter(|r| {
                        scene
                            .first_hit(r, 0.0, f32::INFINITY, isos, &mut NoStats)
                            .is_some()
                    })
                    .count()
            }
        })
        .sum()
}

fn median_seconds(mut f: impl FnMut(), n: usize) -> f64 {
    let mut t: Vec<f64> = (0..n)
        .map(|_| {
            let s = Instant::now();
            f();
            s.elapsed().as_secs_f64()
        })
        .collect();
    t.sort_by(f64::total_cmp);
    t[n / 2]
}

fn scene_of<T: Voxel>(dims: [usize; 3], v: Vec<T>, unstored: usize) -> GridScene<T> {
    let grid = Grid::uniform(dims, [0.0; 3], [1.0; 3]).unwrap();
    GridScene::new(
        &grid,
        VoxelBuffer::from_vec(v),
        Intersector::Exact,
        KdTreeConfig {
            unstored_levels: unstored,
        },
    )
    .unwrap()
}

fn summary() {
    let size = 1024;
    let dims = [256, 256, 110];
    let ct = ct_like(dims);
    println!(
        "| volume | layout | build ms | tree/data | kd Mrays/s | packet Mrays/s | DDA Mrays/s | hits |"
    );
    for unstored in [0, 1, 2, 3] {
        let scene = scene_of(dims, ct.clone(), unstored);
        let b = scene.world_bounds();
        let rays = camera_rays(b.min, b.max, size, Vec3::new(1.0, -0.7, 0.5));
        let isos = [300.0];
        let hits = frame(&scene, &rays, &isos, false);
        let kd = median_seconds(
            || {
                black_box(frame(&scene, &rays, &isos, false));
            },
            5,
        );
        let pk = median_seconds(
            || {
                black_box(frame(&scene, &rays, &isos, true));
            },
            5,
        );
        let dda = if unstored == 2 {
            let d = scene.dda();
            median_seconds(
                || {
                    black_box(frame(&d, &rays, &isos, false));
                },
                1,
            )
        } else {
            f64::NAN
        };
        let mut st = CountStats::default();
        for r in &rays {
            scene.first_hit(r, 0.0, f32::INFINITY, &isos, &mut st);
        }
        let c = st.counts();
        let nr = rays.len() as f64;
        println!(
            "  per ray: nodes {:.1} leaves {:.1} intersections {:.2}",
            c.nodes_visited as f64 / nr,
            c.leaves_visited as f64 / nr,
            c.intersection_tests as f64 / nr
        );
        let mr = |s: f64| rays.len() as f64 / s / 1e6;
        println!(
            "| CT-like i16 256×256×110 @1024² | unstored {unstored} | {:.0} | {:.3} | {:.1} | {:.1} | {:.2} | {hits} |",
            scene.build_time().as_secs_f64() * 1e3,
            scene.memory_ratio(),
            mr(kd),
            mr(pk),
            mr(dda),
        );
    }
    for n in [64, 128, 256] {
        let ml = marschner_lobb(n);
        let scene = scene_of([n; 3], ml.clone(), 2);
        let u8s: Vec<u8> = ml.iter().map(|x| (x * 255.0).round() as u8).collect();
        let scene8 = scene_of([n; 3], u8s, 2);
        let b = scene.world_bounds();
        let rays = camera_rays(b.min, b.max, 512, Vec3::new(0.8, -1.0, 0.6));
        let kd = median_seconds(
            || {
                black_box(frame(&scene, &rays, &[0.5], false));
            },
            5,
        );
        let kd8 = median_seconds(
            || {
                black_box(frame(&scene8, &rays, &[127.5], false));
            },
            5,
        );
        println!(
            "| ML {n}³ f32 / u8 @512² | unstored 2 | {:.0} | {:.3} / {:.3} | {:.1} / {:.1} | | | |",
            scene.build_time().as_secs_f64() * 1e3,
            scene.memory_ratio(),
            scene8.memory_ratio(),
            rays.len() as f64 / kd / 1e6,
            rays.len() as f64 / kd8 / 1e6,
        );
    }
}

/// Median seconds per rendered frame (after one warm-up frame) and the frame's hit count.
fn render_seconds<S: IsoScene>(
    scene: &S,
    camera: &Camera,
    settings: &RenderSettings,
    frames: usize,
) -> f64 {
    let go = std::sync::atomic::AtomicBool::new(false);
    black_box(render(scene, camera, settings, &go));
    median_seconds(
        || {
            black_box(render(scene, camera, settings, &go));
        },
        frames,
    )
}

fn render_settings(size: u32, iso: f32, packets: bool) -> RenderSettings {
    RenderSettings {
        width: size,
        height: size,
        surfaces: vec![Surface::new(iso, [0.9, 0.8, 0.7])],
        packets,
        ..RenderSettings::default()
    }
}

/// Whole-frame throughput of the renderer (see the module docs), one row per scene.
fn render_summary() {
    let frames: usize = std::env::var("KDBENCH_FRAMES")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(5);
    println!(
        "| scene | size | kd packet Mrays/s | kd single Mrays/s | DDA Mrays/s | packet / DDA | single / DDA | tree/data |"
    );
    // KDBENCH_ONLY=packet skips the single-ray and DDA frames (for profiling).
    let only_packet = std::env::var("KDBENCH_ONLY").as_deref() == Ok("packet");
    let row = |name: &str,
               size: u32,
               scene: &dyn Fn(&RenderSettings) -> f64,
               iso: f32,
               dda: &dyn Fn(&RenderSettings) -> f64,
               ratio: f64| {
        let rays = f64::from(size) * f64::from(size);
        let pk = scene(&render_settings(size, iso, true));
        if only_packet {
            println!(
                "| {name} | {size}² | {:.2} | | | | | {ratio:.3} |",
                rays / pk / 1e6
            );
            return pk;
        }
        let sg = scene(&render_settings(size, iso, false));
        let dd = dda(&render_settings(size, iso, false));
        println!(
            "| {name} | {size}² | {:.2} | {:.2} | {:.3} | {:.1}× | {:.1}× | {ratio:.3} |",
            rays / pk / 1e6,
            rays / sg / 1e6,
            rays / dd / 1e6,
            dd / pk,
            dd / sg,
        );
        pk
    };
    let dims = [256, 256, 110];
    let grid = Grid::uniform(dims, [0.0; 3], [0.9, 0.9, 1.5]).unwrap();
    let ct = GridScene::new(
        &grid,
        VoxelBuffer::from_vec(ct_like(dims)),
        Intersector::Exact,
        KdTreeConfig::default(),
    )
    .unwrap();
    let cam = Camera::orbit(&ct.world_bounds(), 30.0, 20.0, 40.0);
    row(
        "CT-like i16 256×256×110",
        1024,
        &|s| render_seconds(&ct, &cam, s, frames),
        300.0,
        &|s| render_seconds(&ct.dda(), &cam, s, 1),
        ct.memory_ratio(),
    );
    let ml_sizes: Vec<usize> = std::env::var("KDBENCH_ML")
        .unwrap_or_else(|_| "64,256".into())
        .split(',')
        .filter_map(|s| s.trim().parse().ok())
        .collect();
    let mut first = None;
    for n in ml_sizes {
        let scene = scene_of(
            [n; 3],
            marschner_lobb(n),
            KdTreeConfig::default().unstored_levels,
        );
        let cam = Camera::orbit(&scene.world_bounds(), 30.0, 20.0, 40.0);
        let pk = row(
            &format!("ML {n}³ f32"),
            512,
            &|s| render_seconds(&scene, &cam, s, frames),
            0.5,
            &|s| render_seconds(&scene.dda(), &cam, s, 1),
            scene.memory_ratio(),
        );
        let base = *first.get_or_insert(pk);
        println!("  ML {n}³ packet frame / first ML frame: {:.2}×", pk / base);
    }
}

fn bench(c: &mut Criterion) {
    if std::env::var("KDBENCH").as_deref() == Ok("render") {
        render_summary();
        std::process::exit(0);
    }
    summary();
    let dims = [256, 256, 110];
    let scene = scene_of(dims, ct_like(dims), KdTreeConfig::default().unstored_levels);
    let b = scene.world_bounds();
    let rays = camera_rays(b.min, b.max, 256, Vec3::new(1.0, -0.7, 0.5));
    let mut g = c.benchmark_group("ct_like_256x256x110_256sq");
    g.sample_size(10);
    g.bench_function("kd_single", |bn| {
        bn.iter(|| frame(&scene, &rays, &[300.0], false));
    });
    g.bench_function("kd_packet", |bn| {
        bn.iter(|| frame(&scene, &rays, &[300.0], true));
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
