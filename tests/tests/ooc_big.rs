//! Out-of-core treelets on a volume with more than 2³² voxels (thesis seed 004
//! §7.7–7.9).
//!
//! The input is `data_samples::sparse_blobs`: 2048×2048×1100 `u8` (4 613 734 400 voxels,
//! 4.6 GB, a sparse file of three analytic cone blobs, one of them straddling linear index
//! 2³²). The test preprocesses it with `isoscope preprocess` (the CLI's `run`), opens the
//! `.isot`, lets the loader reach the finest level for isovalue 100.5 and checks hits against
//! the analytic spheres: positions, hit/miss, no wrap-around. It prints the measurements
//! recorded in `docs/benchmarks.md` ("Out-of-core treelets").
//!
//! It needs about 20 GB of free disk in `ISOSCOPE_BIG_DIR` (default: the system temp dir)
//! and minutes, so it is ignored, and built only with the package's `big` feature (CI's
//! clippy checks it). Run:
//!
//! ```text
//! ISOSCOPE_BIG_DIR=/path/with/20GB cargo test -p isoscope-e2e --features big --test ooc_big -- --ignored --nocapture
//! ```
//!
//! Set `ISOSCOPE_BIG_KEEP=1` to keep the input and the `.isot` afterwards (they are deleted
//! otherwise). The 64-bit address arithmetic itself is tested in CI by
//! `volume_core::ooc::layout` (`addresses_above_four_billion_voxels_do_not_wrap`) and
//! `formats::treelet` (`slot_offsets_above_four_gib_do_not_wrap`).

use std::path::PathBuf;
use std::sync::atomic::AtomicBool;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use data_samples::sparse_blobs::{BIG_DIMS, Blob, big_test_blobs, write_sparse_nrrd};
use volume_core::intersect::Intersector;
use volume_core::math::Ray;
use volume_core::ooc::{LoadProgress, OocOptions};
use volume_core::render::{
    Camera, Hit, IsoScene, NoStats, RenderSettings, Surface, render as render_frame,
};
use volume_core::render::{Normals, SceneVisitor};

const ISO: f32 = 100.5;

/// Nearest analytic hit of `ray` with the blobs' isosurfaces (spheres), as `(t, blob)`.
fn analytic_hit(blobs: &[Blob], o: [f64; 3], d: [f64; 3]) -> Option<(f64, usize)> {
    let mut best: Option<(f64, usize)> = None;
    for (i, b) in blobs.iter().enumerate() {
        let r = b.iso_radius(f64::from(ISO));
        let oc = [0, 1, 2].map(|a| o[a] - b.center[a]);
        let bb = (0..3).map(|a| oc[a] * d[a]).sum::<f64>();
        let c = (0..3).map(|a| oc[a] * oc[a]).sum::<f64>() - r * r;
        let disc = bb * bb - c;
        if disc < 0.0 {
            continue;
        }
        let t = -bb - disc.sqrt();
        if t > 0.0 && best.is_none_or(|(bt, _)| t < bt) {
            best = Some((t, i));
        }
    }
    best
}

/// Distance of the ray's closest approach to a blob's iso-sphere silhouette (to skip rays
/// that graze a surface, where voxel rounding may flip hit and miss).
fn silhouette_margin(blobs: &[Blob], o: [f64; 3], d: [f64; 3]) -> f64 {
    blobs
        .iter()
        .map(|b| {
            let oc = [0, 1, 2].map(|a| b.center[a] - o[a]);
            let along = (0..3).map(|a| oc[a] * d[a]).sum::<f64>();
            let perp2 = (0..3).map(|a| oc[a] * oc[a]).sum::<f64>() - along * along;
            (perp2.max(0.0).sqrt() - b.iso_radius(f64::from(ISO))).abs()
        })
        .fold(f64::INFINITY, f64::min)
}

/// How far the point at `t` along the ray lies from `blob`'s analytic iso-sphere (samples).
/// The voxels are the cone field rounded to `u8`: ±0.5 in value is ±0.375 samples radially
/// for the largest blob (gradient `PEAK / radius`), plus the trilinear interpolation error.
fn radial_error(blob: &Blob, o: [f64; 3], d: [f64; 3], t: f64) -> f64 {
    let dist = (0..3)
        .map(|a| (o[a] + d[a] * t - blob.center[a]).powi(2))
        .sum::<f64>()
        .sqrt();
    (dist - blob.iso_radius(f64::from(ISO))).abs()
}

struct Trace(Vec<Ray>);

impl SceneVisitor for Trace {
    type Output = Vec<Option<Hit>>;
    fn visit<S: IsoScene>(self, scene: &S) -> Self::Output {
        self.0
            .iter()
            .map(|r| scene.first_hit(r, 0.0, f32::INFINITY, &[ISO], &mut NoStats))
            .collect()
    }
}

/// One shaded frame from the levels loaded now: (seconds, depth per pixel).
struct Frame(Camera, u32);

impl SceneVisitor for Frame {
    type Output = (f64, Vec<f32>);
    fn visit<S: IsoScene>(self, scene: &S) -> Self::Output {
        let settings = RenderSettings {
            width: self.1,
            height: self.1 * 3 / 4,
            surfaces: vec![Surface::new(ISO, [0.9, 0.6, 0.3])],
            ..RenderSettings::default()
        };
        let start = Instant::now();
        let f = render_frame(scene, &self.0, &settings, &AtomicBool::new(false)).expect("frame");
        (start.elapsed().as_secs_f64(), f.depth)
    }
}

fn big_dir() -> PathBuf {
    std::env::var_os("ISOSCOPE_BIG_DIR")
        .map_or_else(|| std::env::temp_dir().join("isoscope-big"), PathBuf::from)
}

#[test]
#[ignore = "4.6 GB sparse input, ~20 GB of disk and minutes: run by hand (see the module docs)"]
fn more_than_two_to_the_32_voxels_preprocess_and_render_at_the_right_positions() {
    let dir = big_dir();
    std::fs::create_dir_all(&dir).unwrap();
    let blobs = big_test_blobs();
    let t = Instant::now();
    let header = write_sparse_nrrd(&dir, "big_blobs", BIG_DIMS, &blobs).unwrap();
    println!("sparse input written in {:.1} s", t.elapsed().as_secs_f64());
    let output = dir.join("big_blobs.isot");

    let t = Instant::now();
    isoscope::cli::preprocess::run(&isoscope::cli::preprocess::Args {
        input: header.clone(),
        output: output.clone(),
        treelet_height: 9,
        levels: isoscope::cli::preprocess::Levels::Auto,
        open: isoscope::cli::open_args::OpenArgs::default(),
        // A rerun in the same scratch folder rebuilds the file.
        force: true,
    })
    .unwrap();
    let pre_secs = t.elapsed().as_secs_f64();
    let input_bytes = BIG_DIMS.iter().product::<u64>();
    let out_bytes = std::fs::metadata(&output).unwrap().len();
    println!(
        "preprocess: {:.1} s, {:.1} MB/s input, output {:.2} GB",
        pre_secs,
        input_bytes as f64 / 1e6 / pre_secs,
        out_bytes as f64 / 1e9
    );

    let t = Instant::now();
    let vol = formats::treelet::open_isot(&output, OocOptions::default()).unwrap();
    let open_secs = t.elapsed().as_secs_f64();
    let meta = vol.meta().clone();
    assert_eq!(meta.layout.dims(), BIG_DIMS);
    assert!(meta.layout.voxel_count() > 1 << 32);
    let bounds = vol.visit_scene(Intersector::Exact, Normals::Smooth, BoundsOf);
    let camera = Camera::orbit(&bounds, 35.0, 25.0, 40.0);
    // Time to first image: open + one frame from the top treelet alone.
    let (first_frame, first_depth) =
        vol.visit_scene(Intersector::Exact, Normals::Smooth, Frame(camera, 640));
    let first_hits = first_depth.iter().filter(|d| d.is_finite()).count();
    println!(
        "time to first image: open {open_secs:.3} s + frame {first_frame:.3} s at level 0 \
         ({first_hits} hit pixels)"
    );

    let events = Arc::new(Mutex::new(Vec::<(f64, LoadProgress)>::new()));
    let start = Instant::now();
    {
        let events = events.clone();
        vol.on_level(move |p| {
            events
                .lock()
                .unwrap()
                .push((start.elapsed().as_secs_f64(), *p));
        });
    }
    vol.set_isovalues(&[ISO]);
    assert!(vol.wait_until_finished(Duration::from_mins(30)));
    assert_eq!(vol.error(), None);
    let progress = vol.progress();
    assert!(!progress.budget_limited);
    assert_eq!(progress.loaded_levels, vol.level_count());
    for (secs, p) in events.lock().unwrap().iter() {
        println!(
            "  {secs:8.3} s: level {}/{} published, {} treelets of the level, resident {:.1} MB",
            p.loaded_levels,
            p.level_count,
            p.level_needed,
            p.resident_bytes as f64 / 1e6
        );
    }
    println!(
        "time to finest level: {:.3} s, resident working set {:.1} MB",
        start.elapsed().as_secs_f64(),
        vol.resident_bytes() as f64 / 1e6
    );

    // Frames/s at the finest level (the shaded 640×480 frame of the benchmark rows).
    let mut best = f64::INFINITY;
    let mut depth = Vec::new();
    for _ in 0..3 {
        let (s, d) = vol.visit_scene(Intersector::Exact, Normals::Smooth, Frame(camera, 640));
        best = best.min(s);
        depth = d;
    }
    let hits = depth.iter().filter(|d| d.is_finite()).count();
    println!(
        "finest level: {:.2} frames/s ({hits} hit pixels)",
        1.0 / best
    );
    // Every pixel of that frame against the analytic iso-spheres along the same camera ray
    // (pixels whose ray passes within 1.5 samples of a silhouette are skipped).
    let (width, height) = (640, 480);
    assert_eq!(depth.len(), (width * height) as usize);
    let (mut agree, mut analytic_hits) = (0usize, 0usize);
    for j in 0..height {
        for i in 0..width {
            let ray = camera.primary_ray(i, j, width, height);
            let o = ray.origin.to_array().map(f64::from);
            let d = ray.dir.normalize().to_array().map(f64::from);
            if silhouette_margin(&blobs, o, d) < 1.5 {
                continue;
            }
            let got = depth[(j * width + i) as usize];
            match analytic_hit(&blobs, o, d) {
                None => assert!(
                    !got.is_finite(),
                    "pixel ({i}, {j}): hit at {got}, want a miss"
                ),
                Some((t, bi)) => {
                    analytic_hits += 1;
                    let err = radial_error(&blobs[bi], o, d, f64::from(got));
                    assert!(
                        err < 1.0,
                        "pixel ({i}, {j}): depth {got}, analytic {t} (blob {bi}), {err:.3} \
                         samples off the iso-sphere"
                    );
                }
            }
            agree += 1;
        }
    }
    println!("frame: {agree} pixels agree with the analytic spheres ({analytic_hits} hits)");
    assert!(analytic_hits > 200 && agree > 300_000);

    // Rays along the three axes through each blob centre (both directions, small offsets):
    // the hit point is on the analytic iso-sphere of that blob.
    let mut rays = Vec::new();
    let mut expect = Vec::new();
    for (bi, b) in blobs.iter().enumerate() {
        for axis in 0..3 {
            for sign in [-1.0f64, 1.0] {
                for off in [0.0, 7.3, -11.6] {
                    let mut o = b.center;
                    o[(axis + 1) % 3] += off;
                    o[axis] -= sign * (b.radius + 5.0);
                    let mut d = [0.0; 3];
                    d[axis] = sign;
                    rays.push(Ray::new(
                        glam::Vec3::from_array(o.map(|x| x as f32)),
                        glam::Vec3::from_array(d.map(|x| x as f32)),
                    ));
                    expect.push((bi, o, d));
                }
            }
        }
    }
    // A grid of rays straight down z over the whole volume: hit or miss and depth equal the
    // analytic union (rays grazing a silhouette within 1.5 samples are skipped).
    let n = 96;
    let mut grid_rays = Vec::new();
    for j in 0..n {
        for i in 0..n {
            let o = [
                (f64::from(i) + 0.5) * 2047.0 / f64::from(n),
                (f64::from(j) + 0.5) * 2047.0 / f64::from(n),
                -10.0,
            ];
            grid_rays.push(o);
        }
    }
    let mut all = rays.clone();
    all.extend(
        grid_rays
            .iter()
            .map(|o| Ray::new(glam::Vec3::from_array(o.map(|x| x as f32)), glam::Vec3::Z)),
    );
    let hits = vol.visit_scene(Intersector::Exact, Normals::Smooth, Trace(all));
    for (k, (bi, o, d)) in expect.iter().enumerate() {
        let h = hits[k].unwrap_or_else(|| panic!("ray {k} at blob {bi} missed"));
        let p = [0, 1, 2].map(|a| o[a] + d[a] * f64::from(h.t));
        let b = &blobs[*bi];
        let dist = (0..3)
            .map(|a| (p[a] - b.center[a]).powi(2))
            .sum::<f64>()
            .sqrt();
        let want = b.iso_radius(f64::from(ISO));
        assert!(
            (dist - want).abs() < 1.0,
            "blob {bi} ray {k}: hit at {p:?}, {dist:.3} from the centre, want {want:.3}"
        );
    }
    let (mut checked, mut hit_count) = (0, 0);
    for (k, o) in grid_rays.iter().enumerate() {
        let d = [0.0, 0.0, 1.0];
        if silhouette_margin(&blobs, *o, d) < 1.5 {
            continue;
        }
        checked += 1;
        let got = hits[expect.len() + k];
        match (analytic_hit(&blobs, *o, d), got) {
            (None, None) => {}
            (Some((t, bi)), Some(h)) => {
                hit_count += 1;
                // Radial error: near a silhouette a small radial error is a long one along t.
                let err = radial_error(&blobs[bi], *o, d, f64::from(h.t));
                assert!(
                    err < 1.0,
                    "grid ray at {o:?}: t {} vs analytic {t} (blob {bi}), {err:.3} samples off \
                     the iso-sphere",
                    h.t
                );
            }
            (want, got) => panic!("grid ray at {o:?}: analytic {want:?}, rendered {got:?}"),
        }
    }
    println!("{checked} grid rays checked, {hit_count} hits");
    assert!(hit_count > 50 && checked > 8000);

    drop(vol);
    if std::env::var_os("ISOSCOPE_BIG_KEEP").is_none() {
        let _ = std::fs::remove_file(&output);
        let _ = std::fs::remove_file(dir.join("big_blobs.raw"));
        let _ = std::fs::remove_file(&header);
    }
}

struct BoundsOf;

impl SceneVisitor for BoundsOf {
    type Output = volume_core::math::Aabb;
    fn visit<S: IsoScene>(self, scene: &S) -> Self::Output {
        scene.world_bounds()
    }
}
