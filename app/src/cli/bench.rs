//! `isoscope bench FILE [--iso V]... [--camera cam.json | --orbit AZ,EL] [--size WxH]
//! [--frames N] [--threads T] [--intersector NAME] [--intersectors all|LIST] [--skip-dda]
//! [--json]`
//!
//! Measures, in one run on the same volume, camera and isovalues:
//! - the kd-tree build time and its memory overhead (tree bytes / voxel bytes);
//! - median ms/frame and primary rays/s of three configurations — kd-tree with packets (the
//!   default, what `render` and the viewer use), kd-tree one ray at a time, and the
//!   brute-force 3D-DDA twin (the baseline) — plus nodes, leaves and intersections per ray
//!   from one extra frame with statistics on (statistics are off while timing);
//! - with `--intersectors`, a speed/accuracy table per intersector: Mrays/s of full frames,
//!   and mean/max |Δt| against the f64 reference in cell units, % missed and % false hits on
//!   the camera's primary rays (`volume_core::intersect::accuracy::compare`).
//!
//! A frame includes shading (headlight Blinn–Phong) and the image assembly, so rays/s is the
//! throughput a user sees. `--json` prints one [`BenchReport`] (a stable interface, see
//! docs/cli.md); its `rays_per_second` is the median primary-ray throughput of the default
//! configuration.

use std::path::PathBuf;
use std::sync::atomic::AtomicBool;
use std::time::Instant;

use anyhow::{Context as _, bail};
use serde::Serialize;
use volume_core::grid_scene::AnyGridScene;
use volume_core::intersect::{Intersector, accuracy};
use volume_core::math::Ray;
use volume_core::render::{Camera, IsoScene, RayGen, RenderSettings, Surface};

use super::open_args::OpenArgs;
use super::render::{
    IsoSpec, ViewArgs, load_volume, parse_intersector, parse_iso, parse_size, render_grid,
    surfaces_from,
};
use crate::progress::Progress;

/// Arguments of `isoscope bench`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Volume file (as for `isoscope render`).
    pub file: PathBuf,
    /// Isovalue(s), as for `render` (colour and opacity accepted). Default: the middle of the
    /// value range.
    #[arg(long = "iso", value_name = "V[:#RRGGBB[:OPACITY]]", value_parser = parse_iso, allow_hyphen_values = true)]
    pub iso: Vec<IsoSpec>,
    #[command(flatten)]
    pub view: ViewArgs,
    /// Image size in pixels.
    #[arg(long, value_name = "WxH", value_parser = parse_size, default_value = "1024x1024")]
    pub size: [u32; 2],
    /// Timed frames per configuration (after one warm-up frame); the median is reported.
    #[arg(long, value_name = "N", default_value_t = 5)]
    pub frames: usize,
    /// Worker threads (a local rayon pool). Default: all cores.
    #[arg(long, value_name = "T")]
    pub threads: Option<usize>,
    /// Intersector of the kd-tree and DDA configurations.
    #[arg(long, value_name = "NAME", default_value = "exact", value_parser = parse_intersector)]
    pub intersector: Intersector,
    /// Also print the speed/accuracy table for these intersectors: `all` or a comma list
    /// (linear,neubauer,exact,schwarze,reference).
    #[arg(long, value_name = "all|LIST", value_parser = parse_intersector_list)]
    pub intersectors: Option<IntersectorList>,
    /// Most primary rays scored per intersector in the accuracy table (a regular subset of
    /// the pixels when the image has more).
    #[arg(long, value_name = "N", default_value_t = 262_144)]
    pub accuracy_rays: usize,
    /// Skip the (slow) DDA baseline.
    #[arg(long)]
    pub skip_dda: bool,
    /// Time step of a series (default 0).
    #[arg(long, value_name = "N")]
    pub step: Option<usize>,
    /// Print one JSON object (a stable interface, see docs/cli.md) instead of tables.
    #[arg(long)]
    pub json: bool,
    #[command(flatten)]
    pub open: OpenArgs,
}

/// Timings of one configuration.
#[derive(Debug, Clone, Serialize)]
pub struct ConfigReport {
    /// `kdtree-packet`, `kdtree-single` or `dda`.
    pub name: String,
    pub median_ms: f64,
    /// Every timed frame, ms.
    pub frame_ms: Vec<f64>,
    /// Primary rays (pixels) per second at the median frame time.
    pub rays_per_second: f64,
    /// Per traced ray (including transparency segments), from one frame with statistics on.
    pub nodes_per_ray: f64,
    pub leaves_per_ray: f64,
    pub intersections_per_ray: f64,
    /// DDA median time / this median time (`null` without the DDA run).
    pub speedup_vs_dda: Option<f64>,
}

/// One row of the speed/accuracy table.
#[derive(Debug, Clone, Serialize)]
pub struct IntersectorReport {
    /// `linear`, `neubauer`, `exact`, `schwarze`, `reference` (`neubauer:N` if N ≠ 3).
    pub name: String,
    /// Primary rays per second of full frames (kd-tree, packets), millions.
    pub mrays_per_second: f64,
    pub median_ms: f64,
    /// Rays scored for accuracy.
    pub rays: u64,
    pub reference_hits: u64,
    /// Over rays both hit: mean and max |t − t_ref| in cell units.
    pub mean_abs_dt_cells: f64,
    pub max_abs_dt_cells: f64,
    /// Reference hits the intersector misses, % of reference hits.
    pub missed_percent: f64,
    /// Hits the reference does not have, % of rays.
    pub false_hits_percent: f64,
    /// Rays where both hit different surfaces.
    pub wrong_surface: u64,
}

/// The `--json` output.
#[derive(Debug, Clone, Serialize)]
pub struct BenchReport {
    pub file: String,
    pub dims: [usize; 3],
    pub voxel_type: String,
    pub isovalues: Vec<f32>,
    pub width: u32,
    pub height: u32,
    pub frames: usize,
    pub threads: usize,
    pub intersector: String,
    /// kd-tree build time (s).
    pub build_seconds: f64,
    pub tree_bytes: u64,
    pub data_bytes: u64,
    /// `tree_bytes / data_bytes`.
    pub memory_overhead: f64,
    /// Median primary rays/s of the default configuration (kd-tree, packets).
    pub rays_per_second: f64,
    pub configs: Vec<ConfigReport>,
    /// Present with `--intersectors`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub intersectors: Option<Vec<IntersectorReport>>,
}

/// The intersectors of `--intersectors` (a newtype so that clap takes it as one value).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct IntersectorList(pub Vec<Intersector>);

/// `all` or a comma-separated list of intersector names.
pub fn parse_intersector_list(s: &str) -> Result<IntersectorList, String> {
    if s.trim().eq_ignore_ascii_case("all") {
        return Ok(IntersectorList(Intersector::ALL.to_vec()));
    }
    s.split(',')
        .map(parse_intersector)
        .collect::<Result<_, _>>()
        .map(IntersectorList)
}

fn median(v: &[f64]) -> f64 {
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    let n = s.len();
    if n == 0 {
        0.0
    } else if n % 2 == 1 {
        s[n / 2]
    } else {
        0.5 * (s[n / 2 - 1] + s[n / 2])
    }
}

/// Times `frames` frames (after a warm-up) and one statistics frame of one configuration
/// (also used by `isoscope accuracy`).
pub fn time_config(
    name: &str,
    scene: &AnyGridScene,
    dda: bool,
    camera: &Camera,
    settings: &RenderSettings,
    frames: usize,
) -> anyhow::Result<ConfigReport> {
    let go = AtomicBool::new(false);
    let progress = Progress::bar(frames as u64 + 2, format!("bench {name}"));
    let warm = render_grid(scene, dda, camera, settings, &go).context("cancelled")?;
    progress.inc(1);
    let mut frame_ms = Vec::with_capacity(frames);
    for _ in 0..frames {
        let f = render_grid(scene, dda, camera, settings, &go).context("cancelled")?;
        frame_ms.push(f.elapsed.as_secs_f64() * 1e3);
        progress.inc(1);
    }
    let stats_settings = RenderSettings {
        collect_stats: true,
        ..settings.clone()
    };
    let s = render_grid(scene, dda, camera, &stats_settings, &go).context("cancelled")?;
    progress.inc(1);
    let c = s.counts;
    let rays = if c.rays > 0 {
        c.rays as f64
    } else {
        (s.rays.primary + s.rays.transparency).max(1) as f64
    };
    let median_ms = median(&frame_ms);
    Ok(ConfigReport {
        name: name.to_string(),
        median_ms,
        frame_ms,
        rays_per_second: warm.rays.primary as f64 / (median_ms / 1e3).max(1e-12),
        nodes_per_ray: c.nodes_visited as f64 / rays,
        leaves_per_ray: c.leaves_visited as f64 / rays,
        intersections_per_ray: c.intersection_tests as f64 / rays,
        speedup_vs_dda: None,
    })
}

/// Primary rays of the camera, every `stride`-th pixel per axis so that at most `max` remain.
pub fn accuracy_rays(camera: &Camera, width: u32, height: u32, max: usize) -> Vec<Ray> {
    let pixels = width as usize * height as usize;
    let stride = ((pixels as f64 / max.max(1) as f64).sqrt().ceil() as u32).max(1);
    let raygen = RayGen::new(camera, width, height);
    let mut rays = Vec::new();
    for j in (0..height).step_by(stride as usize) {
        for i in (0..width).step_by(stride as usize) {
            rays.push(raygen.ray_at(i as f32 + 0.5, j as f32 + 0.5));
        }
    }
    rays
}

/// Runs the benchmark and returns the report (no printing).
pub fn measure(args: &Args) -> anyhow::Result<BenchReport> {
    if args.frames == 0 {
        bail!("--frames must be at least 1");
    }
    let volume = load_volume(&args.file, &args.open, args.step)?;
    let surfaces: Vec<Surface> = surfaces_from(&args.iso, &volume)?;
    let t0 = Instant::now();
    let mut scene = {
        let _spinner = Progress::spinner("building the kd-tree");
        AnyGridScene::new(&volume, args.intersector)
    };
    let build_seconds = {
        let reported = scene.build_time().as_secs_f64();
        if reported > 0.0 {
            reported
        } else {
            t0.elapsed().as_secs_f64()
        }
    };
    let camera = args.view.camera(&scene.world_bounds())?;
    let settings = RenderSettings {
        width: args.size[0],
        height: args.size[1],
        surfaces,
        ..RenderSettings::default()
    };
    settings.validate()?;
    let isovalues = settings.active_isovalues().0;

    let mut configs = vec![
        time_config(
            "kdtree-packet",
            &scene,
            false,
            &camera,
            &settings,
            args.frames,
        )?,
        time_config(
            "kdtree-single",
            &scene,
            false,
            &camera,
            &RenderSettings {
                packets: false,
                ..settings.clone()
            },
            args.frames,
        )?,
    ];
    if !args.skip_dda {
        let dda = time_config(
            "dda",
            &scene,
            true,
            &camera,
            &RenderSettings {
                packets: false,
                ..settings.clone()
            },
            args.frames,
        )?;
        let base = dda.median_ms;
        for c in &mut configs {
            c.speedup_vs_dda = Some(base / c.median_ms.max(1e-12));
        }
        configs.push(ConfigReport {
            speedup_vs_dda: Some(1.0),
            ..dda
        });
    }

    let intersectors = match &args.intersectors {
        None => None,
        Some(IntersectorList(list)) => {
            let rays = accuracy_rays(&camera, args.size[0], args.size[1], args.accuracy_rays);
            let mut rows = Vec::new();
            for &method in list {
                scene.set_intersector(method);
                let timing = time_config(
                    &method.to_string(),
                    &scene,
                    false,
                    &camera,
                    &settings,
                    args.frames,
                )?;
                let acc = {
                    let _spinner = Progress::spinner(format!("accuracy of {method}"));
                    accuracy::compare(&scene, &rays, &isovalues, method)
                };
                rows.push(IntersectorReport {
                    name: method.to_string(),
                    mrays_per_second: timing.rays_per_second / 1e6,
                    median_ms: timing.median_ms,
                    rays: acc.rays,
                    reference_hits: acc.reference_hits,
                    mean_abs_dt_cells: acc.mean_abs_dt_cells,
                    max_abs_dt_cells: acc.max_abs_dt_cells,
                    missed_percent: acc.missed_percent(),
                    false_hits_percent: acc.false_percent(),
                    wrong_surface: acc.wrong_surface,
                });
            }
            scene.set_intersector(args.intersector);
            Some(rows)
        }
    };

    let voxel_type = volume.data.voxel_type();
    let data_bytes = (volume.grid.voxel_count() * voxel_type.size_bytes()) as u64;
    let tree_bytes = scene.memory_bytes() as u64;
    Ok(BenchReport {
        file: args.file.display().to_string(),
        dims: volume.dims(),
        voxel_type: voxel_type.name().to_string(),
        isovalues,
        width: args.size[0],
        height: args.size[1],
        frames: args.frames,
        threads: rayon::current_num_threads(),
        intersector: args.intersector.to_string(),
        build_seconds,
        tree_bytes,
        data_bytes,
        memory_overhead: tree_bytes as f64 / data_bytes.max(1) as f64,
        rays_per_second: configs[0].rays_per_second,
        configs,
        intersectors,
    })
}

/// The human-readable tables.
pub fn format_report(r: &BenchReport) -> String {
    use std::fmt::Write as _;
    let mut s = String::new();
    let _ = writeln!(
        s,
        "{}: {}x{}x{} {}, isovalues {:?}, {}x{} pixels, {} threads, intersector {}",
        r.file,
        r.dims[0],
        r.dims[1],
        r.dims[2],
        r.voxel_type,
        r.isovalues,
        r.width,
        r.height,
        r.threads,
        r.intersector
    );
    let _ = writeln!(
        s,
        "kd-tree build {:.1} ms, {} bytes = {:.3}x the {} voxel bytes",
        r.build_seconds * 1e3,
        r.tree_bytes,
        r.memory_overhead,
        r.data_bytes
    );
    let _ = writeln!(
        s,
        "\n{:<14} {:>10} {:>10} {:>11} {:>11} {:>13} {:>9}",
        "config", "ms/frame", "Mrays/s", "nodes/ray", "leaves/ray", "isects/ray", "vs DDA"
    );
    for c in &r.configs {
        let _ = writeln!(
            s,
            "{:<14} {:>10.2} {:>10.2} {:>11.1} {:>11.1} {:>13.2} {:>9}",
            c.name,
            c.median_ms,
            c.rays_per_second / 1e6,
            c.nodes_per_ray,
            c.leaves_per_ray,
            c.intersections_per_ray,
            c.speedup_vs_dda
                .map_or_else(|| "-".to_string(), |x| format!("{x:.1}x"))
        );
    }
    if let Some(rows) = &r.intersectors {
        let _ = writeln!(
            s,
            "\n{:<12} {:>9} {:>15} {:>15} {:>9} {:>9} {:>8}",
            "intersector",
            "Mrays/s",
            "mean |dt| cells",
            "max |dt| cells",
            "% missed",
            "% false",
            "rays"
        );
        for i in rows {
            let _ = writeln!(
                s,
                "{:<12} {:>9.2} {:>15.3e} {:>15.3e} {:>9.4} {:>9.4} {:>8}",
                i.name,
                i.mrays_per_second,
                i.mean_abs_dt_cells,
                i.max_abs_dt_cells,
                i.missed_percent,
                i.false_hits_percent,
                i.rays
            );
        }
    }
    s
}

pub fn run(args: &Args) -> anyhow::Result<()> {
    let report = match args.threads {
        None => measure(args)?,
        Some(0) => bail!("--threads must be at least 1"),
        Some(t) => rayon::ThreadPoolBuilder::new()
            .num_threads(t)
            .build()
            .context("cannot start the thread pool")?
            .install(|| measure(args))?,
    };
    if args.json {
        println!("{}", serde_json::to_string(&report)?);
    } else {
        print!("{}", format_report(&report));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn median_and_lists() {
        assert_eq!(median(&[3.0, 1.0, 2.0]), 2.0);
        assert_eq!(median(&[4.0, 1.0, 2.0, 3.0]), 2.5);
        assert_eq!(parse_intersector_list("all").unwrap().0.len(), 5);
        assert_eq!(
            parse_intersector_list("linear,exact").unwrap().0,
            vec![Intersector::Linear, Intersector::Exact]
        );
        assert!(parse_intersector_list("linear,bogus").is_err());
    }

    #[test]
    fn accuracy_rays_are_capped() {
        let cam = Camera::orbit(
            &volume_core::math::Aabb::new(glam::Vec3::ZERO, glam::Vec3::ONE),
            30.0,
            20.0,
            40.0,
        );
        let rays = accuracy_rays(&cam, 1000, 500, 10_000);
        assert!(rays.len() <= 10_000 && rays.len() > 2_000, "{}", rays.len());
        assert_eq!(accuracy_rays(&cam, 10, 10, 1000).len(), 100);
    }
}
