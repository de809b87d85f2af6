//! The shared renderer's own cost per frame: everything `render::render`
//! does besides traversal — ray generation, bounds and clip intervals, per-ray bookkeeping,
//! shading, compositing and writing the frame.
//!
//! `cargo bench -p volume-core --bench render` (criterion). A summary with the rows for
//! docs/benchmarks.md ("Shared renderer overhead") is printed first; `RENDER_BENCH_SUMMARY=0`
//! skips it, `RENDER_BENCH_ONLY=loop-culled` renders the culled frame for ~10 s (for
//! `perf record`).
//!
//! Scenes, 1024² pixels, pinhole camera framing a cube that fills most of the image:
//! - `culled`: every packet is culled at the root (what a kd-tree or BVH does when the
//!   isovalue is outside the data range): `first_hit_packet` returns at once, so the frame
//!   costs the renderer alone;
//! - `sphere`: `render::analytic::SphereScene` with a sphere covering ~10 % of the image,
//!   headlight Blinn–Phong: adds shading and compositing of ~0.1 M hits (plus the analytic
//!   scene's f64 ray–sphere tests).
//!
//! CPU ms come from `/proc/self/stat` (all threads, 10 ms ticks, over >= 1 s of frames); on a
//! shared machine they are steadier than wall time, which is the median of 15 frames.

use std::hint::black_box;
use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};

use criterion::{Criterion, criterion_group, criterion_main};
use glam::Vec3;
use volume_core::math::{Aabb, Ray};
use volume_core::render::analytic::SphereScene;
use volume_core::render::{Camera, Frame, Hit, IsoScene, RenderSettings, Stats, Surface};

/// A scene whose acceleration structure culls every ray at the root.
struct Culled(Aabb);

impl IsoScene for Culled {
    type Isovalues = ();

    fn prepare(&self, _: &[f32]) {}

    fn world_bounds(&self) -> Aabb {
        self.0
    }

    fn first_hit_prepared<S: Stats>(
        &self,
        _: &Ray,
        _: f32,
        _: f32,
        (): &(),
        _: &mut S,
    ) -> Option<Hit> {
        None
    }

    fn first_hit_packet_prepared<S: Stats>(
        &self,
        rays: &[Ray],
        _: &[f32],
        _: &[f32],
        (): &(),
        out: &mut [Option<Hit>],
        _: &mut S,
    ) {
        // Every ray misses (the trait writes every `out[i]`); keep one read of the rays so
        // that nothing is optimized away.
        out.fill(None);
        black_box((rays.len(), out.len()));
    }
}

fn cube() -> Aabb {
    Aabb::new(Vec3::splat(-1.0), Vec3::splat(1.0))
}

fn camera() -> Camera {
    Camera::orbit(&cube(), 30.0, 20.0, 40.0)
}

fn settings(side: u32, iso: f32) -> RenderSettings {
    RenderSettings {
        width: side,
        height: side,
        surfaces: vec![Surface::new(iso, [0.8, 0.7, 0.5])],
        ..RenderSettings::default()
    }
}

/// One frame into a reused buffer (the path the viewer and `isoscope bench` can take).
fn frame<S: IsoScene>(scene: &S, settings: &RenderSettings, out: &mut Frame) {
    let go = AtomicBool::new(false);
    assert!(volume_core::render::render_into(
        scene,
        &camera(),
        settings,
        &go,
        out
    ));
    black_box(&out.rgba8);
}

/// Process CPU time (user + system, all threads) in ms, from `/proc/self/stat` (10 ms ticks).
/// `NaN` where unavailable.
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

/// (CPU ms per call over >= 1 s of CPU, median wall ms of 15 calls).
fn measure(mut f: impl FnMut()) -> (f64, f64) {
    for _ in 0..3 {
        f();
    }
    let mut walls: Vec<f64> = (0..15)
        .map(|_| {
            let t = Instant::now();
            f();
            t.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    walls.sort_by(f64::total_cmp);
    let (c0, mut n) = (cpu_ms(), 0u32);
    let t = Instant::now();
    while n < 3 || (cpu_ms() - c0 < 1000.0 && t.elapsed() < Duration::from_secs(20)) {
        f();
        n += 1;
    }
    ((cpu_ms() - c0) / f64::from(n), walls[walls.len() / 2])
}

fn sphere_scene() -> SphereScene {
    SphereScene::distance_field(Vec3::ZERO, cube())
}

fn summary() {
    let side = 1024;
    let culled = Culled(cube());
    let sphere = sphere_scene();
    println!("| frame 1024² | threads | CPU ms/frame | wall ms/frame |");
    println!("|---|---|---|---|");
    for threads in [2, 1] {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            let mut out = volume_core::render::render(
                &culled,
                &camera(),
                &settings(8, 0.5),
                &AtomicBool::new(false),
            )
            .unwrap();
            let s = settings(side, 0.5);
            let (cpu, wall) = measure(|| frame(&culled, &s, &mut out));
            println!("| culled at the root | {threads} | {cpu:.1} | {wall:.1} |");
            // Isovalue outside the field's range [0, sqrt(3)]: the analytic scene skips it.
            let s = settings(side, -5.0);
            let (cpu, wall) = measure(|| frame(&sphere, &s, &mut out));
            println!("| sphere scene, iso outside the range | {threads} | {cpu:.1} | {wall:.1} |");
            let s = settings(side, 0.7);
            let (cpu, wall) = measure(|| frame(&sphere, &s, &mut out));
            let hits = out.depth.iter().filter(|d| d.is_finite()).count();
            println!(
                "| sphere scene, iso 0.7 ({hits} hit px) | {threads} | {cpu:.1} | {wall:.1} |"
            );
        });
    }
}

fn bench(c: &mut Criterion) {
    if let Ok(mode) = std::env::var("RENDER_BENCH_ONLY") {
        if mode == "loop-culled" {
            let culled = Culled(cube());
            let s = settings(1024, 0.5);
            let mut out = volume_core::render::render(
                &culled,
                &camera(),
                &settings(8, 0.5),
                &AtomicBool::new(false),
            )
            .unwrap();
            let until = Instant::now() + Duration::from_secs(10);
            while Instant::now() < until {
                frame(&culled, &s, &mut out);
            }
        }
        return;
    }
    if std::env::var("RENDER_BENCH_SUMMARY").as_deref() != Ok("0") {
        summary();
    }
    let culled = Culled(cube());
    let sphere = sphere_scene();
    let mut g = c.benchmark_group("render_1024");
    g.sample_size(10);
    let mut out = volume_core::render::render(
        &culled,
        &camera(),
        &settings(8, 0.5),
        &AtomicBool::new(false),
    )
    .unwrap();
    let s = settings(1024, 0.5);
    g.bench_function("culled", |b| b.iter(|| frame(&culled, &s, &mut out)));
    let s = settings(1024, 0.7);
    g.bench_function("sphere", |b| b.iter(|| frame(&sphere, &s, &mut out)));
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
