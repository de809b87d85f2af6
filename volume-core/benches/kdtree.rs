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
//!
//! `KDBENCH=trace` times the kd-tree's own work without the renderer, on the CT-like
//! volume at 1024² (orbit 30°/20°, the renderer's camera): the frame's primary rays are
//! generated once, in 16×16 tiles in Morton order and clipped to the bounds (the rays and
//! packets of 8 the renderer casts), then each mode is timed over rayon per tile:
//! `scene packet` (`GridScene::first_hit_packet`: per-packet setup, traversal,
//! intersection, normals), `scene single` (`first_hit`), `tree packet` (only
//! `KdTree::first_hit_packet` on precomputed traversal-unit rays), `normals` (only
//! `normal_at` at the frame's hits) and the DDA. `KDBENCH_FRAMES` sets the median count,
//! `KDBENCH_SIZE` the image side (default 1024), `KDBENCH_MODES` a comma list of the modes
//! to time (`scene-packet,scene-single,tree-packet,normals,dda`, default all): with a small
//! frame, one mode and `RAYON_NUM_THREADS=1` the run suits `valgrind --tool=callgrind`
//! (instruction counts do not depend on the machine's load).

use std::hint::black_box;
use std::time::Instant;

use criterion::{Criterion, criterion_group, criterion_main};
use glam::Vec3;
use rayon::prelude::*;
use volume_core::grid::{GridScene, normal_at};
use volume_core::intersect::methods::Exact;
use volume_core::intersect::{CellHit, Intersector, IsoSet, LocalRay};
use volume_core::kdtree::{KdTreeConfig, PACKET_WIDTH, PacketStack, packet_compatible};
use volume_core::math::Ray;
use volume_core::render::{
    Camera, CountStats, IsoScene, NoStats, RayGen, RenderSettings, Stats, Surface, TILE, render,
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

/// The renderer's primary rays for one frame: per 16×16 tile in Morton order, clipped to
/// the bounds (rays that miss the bounds are dropped, as the renderer does).
struct TileRays {
    rays: Vec<Ray>,
    t0: Vec<f32>,
    t1: Vec<f32>,
}

fn frame_tiles<S: IsoScene>(scene: &S, camera: &Camera, size: u32) -> Vec<TileRays> {
    let raygen = RayGen::new(camera, size, size);
    let bounds = scene.world_bounds();
    let morton: Vec<[u32; 2]> = (0..TILE * TILE)
        .map(|m| {
            let (mut x, mut y) = (0, 0);
            for b in 0..8 {
                x |= ((m >> (2 * b)) & 1) << b;
                y |= ((m >> (2 * b + 1)) & 1) << b;
            }
            [x, y]
        })
        .filter(|p| p[0] < TILE && p[1] < TILE)
        .collect();
    let tiles = size.div_ceil(TILE);
    (0..tiles * tiles)
        .map(|t| {
            let (tx, ty) = (t % tiles, t / tiles);
            let mut tr = TileRays {
                rays: vec![],
                t0: vec![],
                t1: vec![],
            };
            for &[dx, dy] in &morton {
                let (x, y) = (tx * TILE + dx, ty * TILE + dy);
                if x >= size || y >= size {
                    continue;
                }
                let ray = raygen.ray_at(x as f32 + 0.5, y as f32 + 0.5);
                if let Some((a, b)) = bounds.intersect(&ray, 0.0, f32::INFINITY) {
                    tr.rays.push(ray);
                    tr.t0.push(a);
                    tr.t1.push(b);
                }
            }
            tr
        })
        .collect()
}

/// CPU seconds used by this process so far (user + system, all threads; Linux
/// `/proc/self/stat`, 10 ms ticks), or NaN elsewhere. On a shared machine CPU time is far
/// steadier than wall time: waiting for a core is not counted.
fn process_cpu_seconds() -> f64 {
    let Ok(stat) = std::fs::read_to_string("/proc/self/stat") else {
        return f64::NAN;
    };
    // Fields after the parenthesised command name; utime and stime are fields 14 and 15.
    let rest = stat.rsplit_once(')').map_or("", |(_, r)| r);
    let f: Vec<f64> = rest
        .split_whitespace()
        .skip(11)
        .take(2)
        .filter_map(|x| x.parse().ok())
        .collect();
    if f.len() == 2 {
        (f[0] + f[1]) / 100.0
    } else {
        f64::NAN
    }
}

/// (median wall seconds, mean CPU seconds) per call of `f` over `n` calls.
fn wall_and_cpu(mut f: impl FnMut(), n: usize) -> (f64, f64) {
    let c0 = process_cpu_seconds();
    let wall = median_seconds(&mut f, n);
    (wall, (process_cpu_seconds() - c0) / n as f64)
}

/// Times the kd-tree's own work per frame (see the module docs).
fn trace_summary() {
    let frames: usize = std::env::var("KDBENCH_FRAMES")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(5);
    // KDBENCH_UNSTORED overrides the default unstored levels (layout experiments).
    let unstored = std::env::var("KDBENCH_UNSTORED")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(KdTreeConfig::default().unstored_levels);
    // KDBENCH_RAW=FILE:XxYxZ:ISO traces a raw little-endian i16 volume (spacing 1) at
    // isovalue ISO instead of the CT-like one (real data, e.g. an MRI written as i16).
    let raw = std::env::var("KDBENCH_RAW").ok().map(|spec| {
        let parts: Vec<&str> = spec.split(':').collect();
        assert_eq!(parts.len(), 3, "KDBENCH_RAW=FILE:XxYxZ:ISO");
        let dims: Vec<usize> = parts[1].split('x').map(|x| x.parse().unwrap()).collect();
        let dims = [dims[0], dims[1], dims[2]];
        let bytes = std::fs::read(parts[0]).expect("KDBENCH_RAW file");
        assert_eq!(bytes.len(), 2 * dims.iter().product::<usize>(), "file size");
        let voxels: Vec<i16> = bytes
            .chunks_exact(2)
            .map(|b| i16::from_le_bytes([b[0], b[1]]))
            .collect();
        (dims, voxels, parts[2].parse::<f32>().unwrap())
    });
    let (dims, voxels, iso, spacing) = match raw {
        Some((dims, v, iso)) => (dims, v, iso, [1.0; 3]),
        None => (
            [256, 256, 110],
            ct_like([256, 256, 110]),
            300.0,
            [0.9, 0.9, 1.5],
        ),
    };
    let grid = Grid::uniform(dims, [0.0; 3], spacing).unwrap();
    let ct = GridScene::new(
        &grid,
        VoxelBuffer::from_vec(voxels),
        Intersector::Exact,
        KdTreeConfig {
            unstored_levels: unstored,
        },
    )
    .unwrap();
    let size: u32 = std::env::var("KDBENCH_SIZE")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(1024);
    let modes = std::env::var("KDBENCH_MODES")
        .unwrap_or_else(|_| "scene-packet,scene-single,tree-packet,normals,dda".into());
    let on = |m: &str| modes.split(',').any(|x| x.trim() == m);
    let cam = Camera::orbit(&ct.world_bounds(), 30.0, 20.0, 40.0);
    let tiles = frame_tiles(&ct, &cam, size);
    let isos = [iso];
    let iso_set = IsoSet::<i16>::new(&isos);
    let pixels = f64::from(size) * f64::from(size);
    let n_rays: usize = tiles.iter().map(|t| t.rays.len()).sum();

    let scene_packet = || -> usize {
        tiles
            .par_iter()
            .map(|t| {
                let mut out = vec![None; t.rays.len()];
                ct.first_hit_packet(&t.rays, &t.t0, &t.t1, &isos, &mut out, &mut NoStats);
                out.iter().filter(|h| h.is_some()).count()
            })
            .sum()
    };
    let scene_single = || -> usize {
        tiles
            .par_iter()
            .map(|t| {
                (0..t.rays.len())
                    .filter(|&i| {
                        ct.first_hit(&t.rays[i], t.t0[i], t.t1[i], &isos, &mut NoStats)
                            .is_some()
                    })
                    .count()
            })
            .sum()
    };
    // Traversal-unit rays and clipped intervals, precomputed per packet.
    let local: Vec<Vec<(LocalRay, f32, f32)>> = tiles
        .iter()
        .map(|t| {
            (0..t.rays.len())
                .map(|i| {
                    let l = ct.frame().to_local(&t.rays[i]);
                    let (a, b) = ct
                        .frame()
                        .clip(&l, t.t0[i], t.t1[i])
                        .unwrap_or((f32::INFINITY, f32::NEG_INFINITY));
                    (l, a, b)
                })
                .collect()
        })
        .collect();
    let tree_packet = |collect: bool| -> (usize, Vec<(CellHit, Vec3)>) {
        tiles
            .par_iter()
            .zip(&local)
            .map(|(_, l)| {
                let mut hits = 0;
                let mut found = vec![];
                let mut stack = PacketStack::default();
                for chunk in l.chunks(PACKET_WIDTH) {
                    let rays: [LocalRay; PACKET_WIDTH] =
                        std::array::from_fn(|i| chunk.get(i).map_or(chunk[0].0, |c| c.0));
                    let n = chunk.len();
                    let t0: [f32; PACKET_WIDTH] =
                        std::array::from_fn(|i| chunk.get(i).map_or(0.0, |c| c.1));
                    let t1: [f32; PACKET_WIDTH] =
                        std::array::from_fn(|i| chunk.get(i).map_or(0.0, |c| c.2));
                    let mut out = [None; PACKET_WIDTH];
                    if packet_compatible(&rays[..n]) {
                        ct.tree().first_hit_packet_in(
                            &mut stack,
                            ct.frame(),
                            ct.voxels(),
                            &rays[..n],
                            &t0[..n],
                            &t1[..n],
                            &iso_set,
                            Exact,
                            &mut NoStats,
                            &mut out[..n],
                        );
                    } else {
                        for i in 0..n {
                            if t0[i] <= t1[i] {
                                out[i] = ct.tree().first_hit(
                                    ct.frame(),
                                    ct.voxels(),
                                    &rays[i],
                                    t0[i],
                                    t1[i],
                                    &iso_set,
                                    Exact,
                                    &mut NoStats,
                                );
                            }
                        }
                    }
                    for (i, h) in out[..n].iter().enumerate() {
                        if let Some(h) = h {
                            hits += 1;
                            if collect {
                                let (lo, hi) = ct.frame().cell_box(h.cell);
                                let p = rays[i].origin + rays[i].dir * h.t;
                                let uvw = ((p - lo) / (hi - lo)).clamp(Vec3::ZERO, Vec3::ONE);
                                found.push((*h, uvw));
                            }
                        }
                    }
                }
                (hits, found)
            })
            .reduce(
                || (0, vec![]),
                |mut a, b| {
                    a.0 += b.0;
                    a.1.extend(b.1);
                    a
                },
            )
    };
    let cell_hits = if on("normals") {
        tree_packet(true).1
    } else {
        vec![]
    };
    let normals = || -> usize {
        cell_hits
            .par_chunks(256)
            .map(|c| {
                c.iter()
                    .filter(|(h, uvw)| {
                        normal_at(ct.frame(), ct.voxels(), ct.dims(), h.cell, *uvw).is_some()
                    })
                    .count()
            })
            .sum()
    };
    let dda = ct.dda();
    let dda_frame = || -> usize {
        tiles
            .par_iter()
            .map(|t| {
                (0..t.rays.len())
                    .filter(|&i| {
                        dda.first_hit(&t.rays[i], t.t0[i], t.t1[i], &isos, &mut NoStats)
                            .is_some()
                    })
                    .count()
            })
            .sum()
    };
    // Hits are checked between the selected modes (the packet frame is the reference).
    let hits = scene_packet();
    if on("scene-single") {
        assert_eq!(hits, scene_single(), "packet and single hits differ");
    }
    if on("tree-packet") {
        assert_eq!(hits, tree_packet(false).0, "tree-only hits differ");
    }
    println!(
        "CT-like i16 256×256×110 @{size}², iso 300, unstored levels {unstored}: {n_rays} rays in the bounds, {hits} hits, {frames} frames (median)"
    );
    println!(
        "| mode | wall ms/frame (median) | CPU ms/frame (mean) | Mrays/s (per pixel, wall) | vs DDA (CPU) |"
    );
    let (dd_wall, dd) = if on("dda") {
        wall_and_cpu(
            || {
                black_box(dda_frame());
            },
            1,
        )
    } else {
        (f64::NAN, f64::NAN)
    };
    let row = |name: &str, (wall, cpu): (f64, f64)| {
        println!(
            "| {name} | {:.1} | {:.1} | {:.2} | {:.1}× |",
            wall * 1e3,
            cpu * 1e3,
            pixels / wall / 1e6,
            dd / cpu
        );
    };
    let timed = |f: &dyn Fn()| wall_and_cpu(f, frames);
    if on("scene-packet") {
        row(
            "scene packet (setup + traversal + normals)",
            timed(&|| {
                black_box(scene_packet());
            }),
        );
    }
    if on("scene-single") {
        row(
            "scene single",
            timed(&|| {
                black_box(scene_single());
            }),
        );
    }
    if on("tree-packet") {
        row(
            "tree packet (traversal + intersection)",
            timed(&|| {
                black_box(tree_packet(false));
            }),
        );
    }
    if on("normals") {
        row(
            "normals at the hits",
            timed(&|| {
                black_box(normals());
            }),
        );
    }
    if on("dda") {
        row("DDA single", (dd_wall, dd));
    }
}

fn bench(c: &mut Criterion) {
    if std::env::var("KDBENCH").as_deref() == Ok("render") {
        render_summary();
        std::process::exit(0);
    }
    if std::env::var("KDBENCH").as_deref() == Ok("trace") {
        trace_summary();
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
