//! `isoscope bench FILE [--iso V]... [--camera cam.json | --orbit AZ,EL] [--size WxH]
//! [--frames N] [--threads T] [--intersector NAME] [--intersectors all|LIST] [--skip-dda]
//! [--iso-sweep N] [--json]`, plus the mesh flags (`--field`, `--bvh`, `--leaf-size`,
//! `--packet`, `--normals`, `--compare-bvh`) and the `.isot` flags (`--level-timeout`,
//! `--budget-mb`).
//!
//! Measures, in one run on the same data, camera and isovalues:
//! - volumes: the kd-tree build time and its memory overhead (tree bytes / voxel bytes);
//!   median ms/frame and primary rays/s of three configurations — kd-tree with packets (the
//!   default, what `render` and the viewer use), kd-tree one ray at a time, and the
//!   brute-force 3D-DDA twin (the baseline) — plus nodes, leaves and intersections per ray
//!   from one extra frame with statistics on (statistics are off while timing); with
//!   `--intersectors`, a speed/accuracy table per intersector: Mrays/s of full frames, and
//!   mean/max |Δt| against the f64 reference in cell units, % missed and % false hits on the
//!   camera's primary rays (`volume_core::intersect::accuracy::compare`);
//! - tetrahedral meshes: BVH build time and bytes; ms/frame, frames/s and rays/s with 16×16
//!   packets (or `--packet`; the default configuration), 2×2 packets and single rays, and per
//!   frame the ray–box tests, isopolygon tests and extractions (thesis Table 8.4), with the
//!   2×2 / 16×16 ratio of ray–box tests; `--compare-bvh` also builds and times the other
//!   builder (BIH vs SAH, Table 8.1);
//! - `.isot` files: open time, time to first image (open + one frame from what is loaded),
//!   time to the finest level the isovalues need, resident memory, and ms/frame at each level
//!   (each coarser level is reached again by reopening with the memory budget that stops
//!   there);
//! - `--iso-sweep N` (volumes and meshes): N frames that each change the isovalue, against the
//!   steady frames of the same run: a new isovalue costs one frame, not a rebuild.
//!
//! A frame includes shading (headlight Blinn–Phong) and the image assembly, so rays/s is the
//! throughput a user sees. `--json` prints one [`BenchReport`] (a stable interface, see
//! docs/cli.md); its `rays_per_second` is the median primary-ray throughput of the default
//! configuration for every kind (kd-tree packets; BVH packets of `--packet`; `.isot` at the
//! finest level loaded).

use std::path::PathBuf;
use std::sync::atomic::AtomicBool;
use std::sync::{Arc, Mutex};
use std::time::Instant;

use anyhow::{Context as _, bail};
use serde::Serialize;
use volume_core::grid::AnyGridScene;
use volume_core::intersect::{Intersector, accuracy};
use volume_core::math::Ray;
use volume_core::ooc::OocOptions;
use volume_core::render::{Camera, Frame, RayGen, RenderSettings, Surface};
use volume_core::tet::{BvhBuilder, BvhOptions};

use super::open_args::{MeshArgs, OocArgs, OpenArgs};
use super::render::{
    IsoSpec, ViewArgs, open_with_flags, packet_side, parse_intersector, parse_iso, parse_size,
    render_grid_into, surfaces_for,
};
use crate::progress::Progress;
use crate::scene::{AnyScene, OocData, SceneKind, SceneOptions, open_scene};

/// Arguments of `isoscope bench`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Volume, tetrahedral mesh or .isot file (as for `isoscope render`).
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
    /// Intersector of the kd-tree and DDA configurations (volumes and .isot files).
    #[arg(long, value_name = "NAME", value_parser = parse_intersector)]
    pub intersector: Option<Intersector>,
    /// Also print the speed/accuracy table for these intersectors: `all` or a comma list
    /// (linear,neubauer,exact,schwarze,reference). Volumes only.
    #[arg(long, value_name = "all|LIST", value_parser = parse_intersector_list)]
    pub intersectors: Option<IntersectorList>,
    /// Most primary rays scored per intersector in the accuracy table (a regular subset of
    /// the pixels when the image has more).
    #[arg(long, value_name = "N", default_value_t = 262_144)]
    pub accuracy_rays: usize,
    /// Skip the (slow) DDA baseline (volumes).
    #[arg(long)]
    pub skip_dda: bool,
    /// Skip the baselines: the one-ray-at-a-time kd-tree configuration (volumes), the 2×2
    /// packets and single rays (meshes). Times only the packets the renderer uses (e.g. for
    /// profiles and peer comparisons).
    #[arg(long)]
    pub skip_single: bool,
    /// Cast shadow rays towards a key light (above, left and behind the camera, as `render
    /// --shadows`): the cost of shadows against the same bench without this flag.
    #[arg(long)]
    pub shadows: bool,
    /// Time the distance query only: each pixel's first hit and its depth, no shading
    /// normal, lighting or transparency (`render --depth-only`), the query the Embree peer
    /// times (`../shared/peers`).
    #[arg(long, conflicts_with = "shadows")]
    pub depth_only: bool,
    /// Also render N frames that each change the isovalue (over the middle half of the value
    /// range) and compare them with the steady frames (volumes and meshes).
    #[arg(long, value_name = "N")]
    pub iso_sweep: Option<usize>,
    /// Meshes: also build the other BVH builder (BIH vs SAH) and time its default
    /// configuration.
    #[arg(long)]
    pub compare_bvh: bool,
    /// Time step of a series (default 0).
    #[arg(long, value_name = "N")]
    pub step: Option<usize>,
    /// Print one JSON object (a stable interface, see docs/cli.md) instead of tables.
    #[arg(long)]
    pub json: bool,
    #[command(flatten)]
    pub open: OpenArgs,
    #[command(flatten)]
    pub mesh: MeshArgs,
    #[command(flatten)]
    pub ooc: OocArgs,
}

/// Timings of one configuration.
#[derive(Debug, Clone, Serialize)]
pub struct ConfigReport {
    /// Volumes: `kdtree-packet`, `kdtree-single`, `dda`. Meshes: `bvh-packet-16x16` (or the
    /// `--packet` side), `bvh-packet-2x2`, `bvh-single`. `.isot`: `isot-level-L`.
    pub name: String,
    pub median_ms: f64,
    /// Every timed frame, ms.
    pub frame_ms: Vec<f64>,
    /// `1000 / median_ms`.
    pub frames_per_second: f64,
    /// Primary rays (pixels) per second at the median frame time.
    pub rays_per_second: f64,
    /// Per traced ray (including transparency segments), from one frame with statistics on.
    pub nodes_per_ray: f64,
    pub leaves_per_ray: f64,
    pub intersections_per_ray: f64,
    /// Meshes: ray–box tests in the statistics frame (a packet test counts its active rays).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub box_tests_per_frame: Option<u64>,
    /// Meshes: ray–isopolygon tests in the statistics frame.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub isopolygon_tests_per_frame: Option<u64>,
    /// Meshes: isopolygon extractions (marching tetrahedra) in the statistics frame.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub extractions_per_frame: Option<u64>,
    /// Shadow rays traced in the statistics frame (0 without `--shadows`).
    pub shadow_rays_per_frame: u64,
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

/// Mesh-only results (`kind == "tet"`).
#[derive(Debug, Clone, Serialize)]
pub struct MeshReport {
    /// Tetrahedra after splitting other cells, and points.
    pub tets: usize,
    pub points: usize,
    /// The drawn point array.
    pub field: String,
    /// `bih` or `sah`.
    pub builder: String,
    pub leaf_size: usize,
    pub bvh_nodes: usize,
    pub bvh_leaves: usize,
    pub bvh_max_depth: usize,
    pub mean_leaf_tets: f64,
    /// Rays per packet side of the default configuration (16 = 16×16).
    pub packet_side: usize,
    /// Ray–box tests per frame with 2×2 packets / with the default packets.
    pub box_test_ratio_2x2: Option<f64>,
    /// With `--compare-bvh`: the other builder.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub other_builder: Option<BuilderReport>,
}

/// The other BVH builder of `--compare-bvh`.
#[derive(Debug, Clone, Serialize)]
pub struct BuilderReport {
    pub builder: String,
    pub build_seconds: f64,
    pub bvh_nodes: usize,
    pub bvh_bytes: usize,
    /// Its default configuration (same packets).
    pub config: ConfigReport,
}

/// `.isot` results (`kind == "isot"`).
#[derive(Debug, Clone, Serialize)]
pub struct OocReport {
    pub level_count: usize,
    /// Bytes of the `.isot` file.
    pub file_bytes: u64,
    /// Opening the file and loading the top treelet.
    pub open_seconds: f64,
    /// Open + the first frame (drawn from whatever is loaded then).
    pub first_image_seconds: f64,
    pub first_image_level: usize,
    /// From the first frame's isovalue request until the loader finished (`null` if
    /// `--level-timeout` passed first). Includes the first frame's rendering.
    pub finest_level_seconds: Option<f64>,
    /// Levels loaded when timing (== `level_count` unless a budget or timeout stopped it).
    pub loaded_levels: usize,
    pub budget_limited: bool,
    /// Resident treelet bytes at the finest level loaded.
    pub resident_bytes: u64,
    /// Frames at each level, coarsest first.
    pub levels: Vec<LevelReport>,
}

/// Frames rendered at one LOD level of an `.isot` file.
#[derive(Debug, Clone, Serialize)]
pub struct LevelReport {
    pub level: usize,
    pub resident_bytes: u64,
    pub median_ms: f64,
    pub frames_per_second: f64,
    pub rays_per_second: f64,
}

/// `--iso-sweep` results.
#[derive(Debug, Clone, Serialize)]
pub struct IsoSweepReport {
    /// The isovalue of each sweep frame.
    pub isovalues: Vec<f32>,
    /// Time of each sweep frame, ms.
    pub frame_ms: Vec<f64>,
    /// Median of the steady frames (fixed isovalue) of the default configuration, same run.
    pub steady_median_ms: f64,
    /// Median and largest sweep frame / steady median.
    pub median_ratio: f64,
    pub max_ratio: f64,
    /// The acceleration structure's build time, ms (what a rebuild per isovalue would add).
    pub build_ms: f64,
}

/// The `--json` output.
#[derive(Debug, Clone, Serialize)]
pub struct BenchReport {
    pub file: String,
    /// `grid`, `tet` or `isot`.
    pub kind: String,
    /// Volumes and `.isot`: samples per axis.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub dims: Option<[usize; 3]>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub voxel_type: Option<String>,
    pub isovalues: Vec<f32>,
    pub width: u32,
    pub height: u32,
    pub frames: usize,
    pub threads: usize,
    /// Cell intersector (volumes, `.isot`); `isopolygon` for meshes.
    pub intersector: String,
    /// `--depth-only`: the frames found first hits and depths, unshaded.
    pub depth_only: bool,
    /// Shading normals of the frames: `faceted` or `smooth` (`--normals`; unused with
    /// `--depth-only`).
    pub normals: String,
    /// Build time of the acceleration structure, s (kd-tree, BVH; `.isot`: open time).
    pub build_seconds: f64,
    /// Acceleration structure bytes (kd-tree, BVH nodes; `.isot`: resident treelets).
    pub tree_bytes: u64,
    /// Data bytes (voxels; mesh points, values and tets).
    pub data_bytes: u64,
    /// `tree_bytes / data_bytes`.
    pub memory_overhead: f64,
    /// Median primary rays/s of the default configuration (`configs[0]`).
    pub rays_per_second: f64,
    pub configs: Vec<ConfigReport>,
    /// Present with `--intersectors`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub intersectors: Option<Vec<IntersectorReport>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mesh: Option<MeshReport>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ooc: Option<OocReport>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub iso_sweep: Option<IsoSweepReport>,
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

/// Times `frames` frames of `draw` (after a warm-up) and one statistics frame, all drawn
/// into one reused [`Frame`], as the viewer redraws (a fresh frame per call would also time
/// the kernel zeroing 8 MB of new pages at 1024², which an interactive redraw never pays).
fn time_frames(
    name: &str,
    settings: &RenderSettings,
    frames: usize,
    draw: &dyn Fn(&RenderSettings, &mut Frame) -> bool,
) -> anyhow::Result<ConfigReport> {
    let progress = Progress::bar(frames as u64 + 2, format!("bench {name}"));
    let mut frame = Frame::default();
    anyhow::ensure!(draw(settings, &mut frame), "cancelled");
    let primary_rays = frame.rays.primary;
    progress.inc(1);
    let mut frame_ms = Vec::with_capacity(frames);
    for _ in 0..frames {
        anyhow::ensure!(draw(settings, &mut frame), "cancelled");
        frame_ms.push(frame.elapsed.as_secs_f64() * 1e3);
        progress.inc(1);
    }
    let stats_settings = RenderSettings {
        collect_stats: true,
        ..settings.clone()
    };
    anyhow::ensure!(draw(&stats_settings, &mut frame), "cancelled");
    let s = &frame;
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
        frames_per_second: 1e3 / median_ms.max(1e-9),
        rays_per_second: primary_rays as f64 / (median_ms / 1e3).max(1e-12),
        nodes_per_ray: c.nodes_visited as f64 / rays,
        leaves_per_ray: c.leaves_visited as f64 / rays,
        intersections_per_ray: c.intersection_tests as f64 / rays,
        box_tests_per_frame: Some(c.box_tests),
        isopolygon_tests_per_frame: Some(c.intersection_tests),
        extractions_per_frame: Some(c.polygon_extractions),
        shadow_rays_per_frame: s.rays.shadow,
        speedup_vs_dda: None,
    })
}

fn without_mesh_counts(mut r: ConfigReport) -> ConfigReport {
    r.box_tests_per_frame = None;
    r.isopolygon_tests_per_frame = None;
    r.extractions_per_frame = None;
    r
}

/// Times `frames` frames (after a warm-up) and one statistics frame of one kd-tree
/// configuration (also used by `isoscope accuracy`).
pub fn time_config(
    name: &str,
    scene: &AnyGridScene,
    dda: bool,
    camera: &Camera,
    settings: &RenderSettings,
    frames: usize,
) -> anyhow::Result<ConfigReport> {
    let go = AtomicBool::new(false);
    time_frames(name, settings, frames, &|s, frame| {
        render_grid_into(scene, dda, camera, s, &go, frame)
    })
    .map(without_mesh_counts)
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

/// What every kind shares: the opened scene, camera and settings.
struct Setup {
    scene: AnyScene,
    camera: Camera,
    settings: RenderSettings,
    isovalues: Vec<f32>,
}

fn setup(args: &Args) -> anyhow::Result<Setup> {
    let scene = open_with_flags(
        &args.file,
        &args.open,
        &args.mesh,
        &args.ooc,
        args.step,
        args.intersector,
    )?;
    let surfaces: Vec<Surface> = surfaces_for(&args.iso, &scene)?;
    let camera = args.view.camera(&scene.world_bounds(), args.size)?;
    let mut settings = RenderSettings {
        width: args.size[0],
        height: args.size[1],
        surfaces,
        depth_only: args.depth_only,
        ..RenderSettings::default()
    };
    if args.shadows {
        settings.shadows = true;
        settings.light.kind = volume_core::render::LightKind::Directional {
            dir: super::render::default_key_light(&camera),
        };
    }
    settings.validate()?;
    let isovalues = settings.active_isovalues().0;
    Ok(Setup {
        scene,
        camera,
        settings,
        isovalues,
    })
}

/// Runs the benchmark and returns the report (no printing).
pub fn measure(args: &Args) -> anyhow::Result<BenchReport> {
    if args.frames == 0 {
        bail!("--frames must be at least 1");
    }
    if args.iso_sweep == Some(0) {
        bail!("--iso-sweep must be at least 1");
    }
    let t0 = Instant::now();
    let s = setup(args)?;
    let kind = s.scene.kind();
    if args.intersectors.is_some() && s.scene.as_grid().is_none() {
        bail!(
            "--intersectors applies to volumes; {} is a {kind} file",
            args.file.display()
        );
    }
    if args.compare_bvh && s.scene.as_tet().is_none() {
        bail!(
            "--compare-bvh applies to tetrahedral meshes; {} is a {kind} file",
            args.file.display()
        );
    }
    if args.iso_sweep.is_some() && s.scene.as_ooc().is_some() {
        bail!(
            "--iso-sweep applies to volumes and meshes: a new isovalue on an .isot file restarts loading, so its frames measure the coarse levels"
        );
    }
    let mut report = match kind {
        SceneKind::Grid => measure_grid(args, &s)?,
        SceneKind::Tet => measure_tet(args, s)?,
        SceneKind::Ooc => measure_ooc(args, &s, t0)?,
    };
    report.rays_per_second = report.configs[0].rays_per_second;
    Ok(report)
}

fn base_report(args: &Args, s: &Setup) -> BenchReport {
    BenchReport {
        file: args.file.display().to_string(),
        kind: s.scene.kind().name().to_string(),
        dims: None,
        voxel_type: None,
        isovalues: s.isovalues.clone(),
        width: args.size[0],
        height: args.size[1],
        frames: args.frames,
        threads: rayon::current_num_threads(),
        intersector: args.intersector.unwrap_or_default().to_string(),
        depth_only: args.depth_only,
        normals: s
            .scene
            .data()
            .view_options()
            .normals
            .map_or("", |n| n.name())
            .to_string(),
        build_seconds: s.scene.build_time().as_secs_f64(),
        tree_bytes: s.scene.structure_bytes(),
        data_bytes: 0,
        memory_overhead: 0.0,
        rays_per_second: 0.0,
        configs: Vec::new(),
        intersectors: None,
        mesh: None,
        ooc: None,
        iso_sweep: None,
    }
}

/// `--iso-sweep`: frames that each change the first surface's isovalue.
fn iso_sweep(
    n: usize,
    s: &Setup,
    steady_median_ms: f64,
    build_seconds: f64,
) -> anyhow::Result<IsoSweepReport> {
    let (lo, hi) = s
        .scene
        .value_range()
        .context("no finite values to sweep the isovalue over")?;
    let go = AtomicBool::new(false);
    let progress = Progress::bar(n as u64, "isovalue sweep");
    let mut settings = s.settings.clone();
    let mut isovalues = Vec::with_capacity(n);
    let mut frame_ms = Vec::with_capacity(n);
    for k in 0..n {
        let f = if n == 1 {
            0.5
        } else {
            k as f64 / (n - 1) as f64
        };
        let iso = (lo + (0.25 + 0.5 * f) * (hi - lo)) as f32;
        settings.surfaces[0].isovalue = iso;
        let frame = s
            .scene
            .render(&s.camera, &settings, &go)
            .context("cancelled")?;
        isovalues.push(iso);
        frame_ms.push(frame.elapsed.as_secs_f64() * 1e3);
        progress.inc(1);
    }
    let base = steady_median_ms.max(1e-9);
    Ok(IsoSweepReport {
        median_ratio: median(&frame_ms) / base,
        max_ratio: frame_ms.iter().copied().fold(0.0, f64::max) / base,
        isovalues,
        frame_ms,
        steady_median_ms,
        build_ms: build_seconds * 1e3,
    })
}

fn measure_grid(args: &Args, s: &Setup) -> anyhow::Result<BenchReport> {
    let grid = s.scene.as_grid().context("not a volume")?;
    let mut report = base_report(args, s);
    let (camera, settings) = (&s.camera, &s.settings);
    let mut configs = vec![time_config(
        "kdtree-packet",
        grid.scene(),
        false,
        camera,
        settings,
        args.frames,
    )?];
    if !args.skip_single {
        configs.push(time_config(
            "kdtree-single",
            grid.scene(),
            false,
            camera,
            &RenderSettings {
                packets: false,
                ..settings.clone()
            },
            args.frames,
        )?);
    }
    if !args.skip_dda {
        let dda = time_config(
            "dda",
            grid.scene(),
            true,
            camera,
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
    if let Some(n) = args.iso_sweep {
        report.iso_sweep = Some(iso_sweep(n, s, configs[0].median_ms, report.build_seconds)?);
    }
    report.intersectors = match &args.intersectors {
        None => None,
        Some(IntersectorList(list)) => {
            let rays = accuracy_rays(camera, args.size[0], args.size[1], args.accuracy_rays);
            let mut scene = grid.scene().clone();
            let mut rows = Vec::new();
            for &method in list {
                scene.set_intersector(method);
                let timing = time_config(
                    &method.to_string(),
                    &scene,
                    false,
                    camera,
                    settings,
                    args.frames,
                )?;
                let acc = {
                    let _spinner = Progress::spinner(format!("accuracy of {method}"));
                    accuracy::compare(&scene, &rays, &s.isovalues, method)
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
            Some(rows)
        }
    };
    let volume = grid.volume();
    let voxel_type = volume.data.voxel_type();
    let data_bytes = (volume.grid.voxel_count() * voxel_type.size_bytes()) as u64;
    report.dims = Some(volume.dims());
    report.voxel_type = Some(voxel_type.name().to_string());
    report.data_bytes = data_bytes;
    report.memory_overhead = report.tree_bytes as f64 / data_bytes.max(1) as f64;
    report.configs = configs;
    Ok(report)
}

fn builder_name(b: BvhBuilder) -> &'static str {
    match b {
        BvhBuilder::Bih => "bih",
        BvhBuilder::Sah => "sah",
    }
}

fn measure_tet(args: &Args, mut s: Setup) -> anyhow::Result<BenchReport> {
    let mut report = base_report(args, &s);
    report.intersector = "isopolygon".into();
    let go = AtomicBool::new(false);
    let camera = s.camera;
    let settings = s.settings.clone();
    let tet = s.scene.as_tet_mut().context("not a mesh")?;
    let default_rays = tet.scene().packet_size();
    let side = packet_side(default_rays);
    let mut configs = Vec::new();
    let timed = |tet: &mut crate::scene::TetData,
                 name: String,
                 rays: usize,
                 packets: bool|
     -> anyhow::Result<ConfigReport> {
        tet.set_packet_rays(rays);
        let st = RenderSettings {
            packets,
            ..settings.clone()
        };
        let scene = tet.scene();
        time_frames(&name, &st, args.frames, &|x, frame| {
            volume_core::render::render_into(scene, &camera, x, &go, frame)
        })
    };
    configs.push(timed(
        tet,
        format!("bvh-packet-{side}x{side}"),
        default_rays,
        true,
    )?);
    if side != 2 && !args.skip_single {
        configs.push(timed(tet, "bvh-packet-2x2".into(), 4, true)?);
    }
    if side != 1 && !args.skip_single {
        configs.push(timed(tet, "bvh-single".into(), 1, false)?);
    }
    let other_builder = if args.compare_bvh {
        let mine = tet.scene().bvh().options();
        let other = BvhOptions {
            builder: match mine.builder {
                BvhBuilder::Bih => BvhBuilder::Sah,
                BvhBuilder::Sah => BvhBuilder::Bih,
            },
            ..mine
        };
        let secs = {
            let _spinner =
                Progress::spinner(format!("building the {} BVH", builder_name(other.builder)));
            tet.rebuild(other).as_secs_f64()
        };
        let info = tet.scene().bvh_info();
        let config = timed(
            tet,
            format!("bvh-{}-packet-{side}x{side}", builder_name(other.builder)),
            default_rays,
            true,
        )?;
        tet.rebuild(mine);
        Some(BuilderReport {
            builder: builder_name(other.builder).into(),
            build_seconds: secs,
            bvh_nodes: info.nodes,
            bvh_bytes: info.bytes,
            config,
        })
    } else {
        None
    };
    tet.set_packet_rays(default_rays);
    let box_of = |name: &str| {
        configs
            .iter()
            .find(|c| c.name == name)
            .and_then(|c| c.box_tests_per_frame)
    };
    let box_test_ratio_2x2 = match (box_of("bvh-packet-2x2"), configs[0].box_tests_per_frame) {
        (Some(a), Some(b)) if b > 0 => Some(a as f64 / b as f64),
        _ => None,
    };
    let ts = tet.scene();
    let info = ts.bvh_info();
    let options = ts.bvh().options();
    let data_bytes = (ts.num_points() * 16 + ts.num_tets() * 16) as u64;
    report.mesh = Some(MeshReport {
        tets: ts.num_tets(),
        points: ts.num_points(),
        field: tet.field().to_string(),
        builder: builder_name(options.builder).into(),
        leaf_size: options.leaf_size,
        bvh_nodes: info.nodes,
        bvh_leaves: info.leaves,
        bvh_max_depth: info.max_depth,
        mean_leaf_tets: info.mean_leaf_tets,
        packet_side: side,
        box_test_ratio_2x2,
        other_builder,
    });
    report.data_bytes = data_bytes;
    report.tree_bytes = info.bytes as u64;
    report.memory_overhead = info.bytes as f64 / data_bytes.max(1) as f64;
    if let Some(n) = args.iso_sweep {
        report.iso_sweep = Some(iso_sweep(
            n,
            &s,
            configs[0].median_ms,
            report.build_seconds,
        )?);
    }
    report.configs = configs;
    Ok(report)
}

/// Renders `frames` timed frames of an `.isot` scene as loaded now; returns the report of
/// the level the frames reached.
fn time_ooc_frames(
    o: &OocData,
    camera: &Camera,
    settings: &RenderSettings,
    frames: usize,
) -> anyhow::Result<(ConfigReport, usize)> {
    let go = AtomicBool::new(false);
    let (_, level) = o
        .render_with_level(camera, settings, &go)
        .context("cancelled")?;
    let r = time_frames(
        &format!("isot-level-{level}"),
        settings,
        frames,
        &|x, frame| {
            o.render_with_level(camera, x, &go)
                .map(|(f, _)| *frame = f)
                .is_some()
        },
    )?;
    Ok((without_mesh_counts(r), level))
}

/// `t0`: before the file was opened (time to first image counts from there).
fn measure_ooc(args: &Args, s: &Setup, t0: Instant) -> anyhow::Result<BenchReport> {
    let timeout = args.ooc.level_timeout()?;
    let mut report = base_report(args, s);
    let (camera, settings) = (&s.camera, &s.settings);
    let file_bytes = std::fs::metadata(&args.file)
        .with_context(|| format!("cannot read {}", args.file.display()))?
        .len();
    let options = super::open_args::scene_options(
        &args.file,
        &args.open,
        &args.mesh,
        &args.ooc,
        args.step,
        args.intersector,
    )?;
    let go = AtomicBool::new(false);
    let o = s.scene.as_ooc().context("not an .isot file")?;
    let open_seconds = o.open_time().as_secs_f64();
    // Before any isovalue only the top treelet is resident: level 0's budget.
    let top = o.status();
    // Every published level is recorded by the loader's notification (a poll missed
    // levels that load between two polls), before the first frame requests the isovalues.
    let levels_seen = record_levels(o);
    let t_request = Instant::now();
    let (_, first_image_level) = o
        .render_with_level(camera, settings, &go)
        .context("cancelled")?;
    let first_image_seconds = t0.elapsed().as_secs_f64();
    let finished = {
        let _spinner = Progress::spinner("loading treelets");
        o.wait_until_finished(timeout)
    };
    let mut level_bytes = levels_seen.lock().expect("level listener").clone();
    if top.loaded_levels == 1
        && let Some(slot) = level_bytes.first_mut()
    {
        *slot = Some(slot.map_or(top.resident_bytes, |b| b.min(top.resident_bytes)));
    }
    let finest_level_seconds = finished.then(|| t_request.elapsed().as_secs_f64());
    let status = o.status();
    if let Some(e) = &status.error {
        bail!("{}: {e}", args.file.display());
    }
    let (finest, finest_level) = time_ooc_frames(o, camera, settings, args.frames)?;
    let mut levels = Vec::new();
    // Coarser levels: reopen with the budget that stops the loader right after level L.
    for (level, &bytes) in level_bytes.iter().enumerate().take(finest_level) {
        let Some(bytes) = bytes else { continue };
        let opts = SceneOptions {
            ooc: OocOptions {
                budget_bytes: bytes,
            },
            ..options.clone()
        };
        let again = open_scene(&args.file, &opts)?;
        let a = again.as_ooc().context("not an .isot file")?;
        a.set_isovalues(&s.isovalues);
        a.wait_until_finished(timeout);
        let (r, reached) = time_ooc_frames(a, camera, settings, args.frames)?;
        if reached == level {
            levels.push(LevelReport {
                level,
                resident_bytes: a.status().resident_bytes,
                median_ms: r.median_ms,
                frames_per_second: r.frames_per_second,
                rays_per_second: r.rays_per_second,
            });
        }
    }
    levels.push(LevelReport {
        level: finest_level,
        resident_bytes: status.resident_bytes,
        median_ms: finest.median_ms,
        frames_per_second: finest.frames_per_second,
        rays_per_second: finest.rays_per_second,
    });
    let meta = o.volume().meta();
    let dims = meta.layout.dims();
    report.dims = Some(dims.map(|d| d as usize));
    report.voxel_type = Some(meta.voxel_type.name().to_string());
    report.build_seconds = open_seconds;
    report.tree_bytes = status.resident_bytes;
    report.data_bytes = meta.layout.voxel_count() * meta.voxel_type.size_bytes() as u64;
    report.memory_overhead = report.tree_bytes as f64 / report.data_bytes.max(1) as f64;
    report.rays_per_second = finest.rays_per_second;
    report.configs = vec![finest];
    report.ooc = Some(OocReport {
        level_count: status.level_count,
        file_bytes,
        open_seconds,
        first_image_seconds,
        first_image_level,
        finest_level_seconds,
        loaded_levels: status.loaded_levels,
        budget_limited: status.budget_limited,
        resident_bytes: status.resident_bytes,
        levels,
    });
    Ok(report)
}

/// Per level, the smallest resident size published with exactly that many levels (the
/// budget that stops loading there), recorded by [`OocData`]'s level notification (one
/// call per published level, however fast it loads).
fn record_levels(o: &OocData) -> Arc<Mutex<Vec<Option<u64>>>> {
    let seen = Arc::new(Mutex::new(vec![None; o.status().level_count]));
    let sink = seen.clone();
    o.volume().on_level(move |p| {
        let mut bytes = sink.lock().expect("level listener");
        if let Some(slot) = p
            .loaded_levels
            .checked_sub(1)
            .and_then(|l| bytes.get_mut(l))
        {
            *slot = Some(slot.map_or(p.resident_bytes, |b: u64| b.min(p.resident_bytes)));
        }
    });
    seen
}

fn config_table(s: &mut String, configs: &[ConfigReport], mesh: bool) {
    use std::fmt::Write as _;
    if mesh {
        let _ = writeln!(
            s,
            "\n{:<22} {:>10} {:>9} {:>10} {:>14} {:>14} {:>12}",
            "config",
            "ms/frame",
            "frames/s",
            "Mrays/s",
            "box tests",
            "isopoly tests",
            "extractions"
        );
        for c in configs {
            let _ = writeln!(
                s,
                "{:<22} {:>10.2} {:>9.1} {:>10.2} {:>14} {:>14} {:>12}",
                c.name,
                c.median_ms,
                c.frames_per_second,
                c.rays_per_second / 1e6,
                c.box_tests_per_frame.unwrap_or(0),
                c.isopolygon_tests_per_frame.unwrap_or(0),
                c.extractions_per_frame.unwrap_or(0)
            );
        }
        return;
    }
    let _ = writeln!(
        s,
        "\n{:<14} {:>10} {:>10} {:>11} {:>11} {:>13} {:>9}",
        "config", "ms/frame", "Mrays/s", "nodes/ray", "leaves/ray", "isects/ray", "vs DDA"
    );
    for c in configs {
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
}

/// The human-readable tables.
pub fn format_report(r: &BenchReport) -> String {
    use std::fmt::Write as _;
    let mut s = String::new();
    let what = match (&r.dims, &r.voxel_type, &r.mesh) {
        (_, _, Some(m)) => format!(
            "tet mesh, {} tets, {} points, field \"{}\"",
            m.tets, m.points, m.field
        ),
        (Some(d), Some(t), _) => format!("{}x{}x{} {t}", d[0], d[1], d[2]),
        _ => r.kind.clone(),
    };
    let _ = writeln!(
        s,
        "{}: {what}, isovalues {:?}, {}x{} pixels, {} threads, intersector {}",
        r.file, r.isovalues, r.width, r.height, r.threads, r.intersector
    );
    if let Some(m) = &r.mesh {
        let _ = writeln!(
            s,
            "BVH ({}, leaves <= {}) built in {:.1} ms: {} nodes, {} leaves, depth {}, {:.1} tets/leaf, {} bytes = {:.3}x the {} data bytes",
            m.builder,
            m.leaf_size,
            r.build_seconds * 1e3,
            m.bvh_nodes,
            m.bvh_leaves,
            m.bvh_max_depth,
            m.mean_leaf_tets,
            r.tree_bytes,
            r.memory_overhead,
            r.data_bytes
        );
        config_table(&mut s, &r.configs, true);
        if let Some(x) = m.box_test_ratio_2x2 {
            let _ = writeln!(
                s,
                "\nray-box tests: 2x2 packets need {x:.1}x those of {0}x{0} packets",
                m.packet_side
            );
        }
        if let Some(o) = &m.other_builder {
            let _ = writeln!(
                s,
                "\nother builder {}: built in {:.1} ms, {} nodes, {} bytes",
                o.builder,
                o.build_seconds * 1e3,
                o.bvh_nodes,
                o.bvh_bytes
            );
            config_table(&mut s, std::slice::from_ref(&o.config), true);
        }
    } else if let Some(o) = &r.ooc {
        let _ = writeln!(
            s,
            "open {:.1} ms; first image after {:.1} ms (level {}); finest level {} of {} levels {}; {} bytes resident of a {} byte file{}",
            o.open_seconds * 1e3,
            o.first_image_seconds * 1e3,
            o.first_image_level,
            o.loaded_levels.saturating_sub(1),
            o.level_count,
            o.finest_level_seconds.map_or_else(
                || "not reached before --level-timeout".to_string(),
                |t| format!("after {:.1} ms", t * 1e3)
            ),
            o.resident_bytes,
            o.file_bytes,
            if o.budget_limited {
                " (memory budget reached)"
            } else {
                ""
            }
        );
        let _ = writeln!(
            s,
            "\n{:>6} {:>14} {:>10} {:>9} {:>10}",
            "level", "resident bytes", "ms/frame", "frames/s", "Mrays/s"
        );
        for l in &o.levels {
            let _ = writeln!(
                s,
                "{:>6} {:>14} {:>10.2} {:>9.1} {:>10.2}",
                l.level,
                l.resident_bytes,
                l.median_ms,
                l.frames_per_second,
                l.rays_per_second / 1e6
            );
        }
    } else {
        let _ = writeln!(
            s,
            "kd-tree build {:.1} ms, {} bytes = {:.3}x the {} voxel bytes",
            r.build_seconds * 1e3,
            r.tree_bytes,
            r.memory_overhead,
            r.data_bytes
        );
        config_table(&mut s, &r.configs, false);
    }
    if let Some(w) = &r.iso_sweep {
        let _ = writeln!(
            s,
            "\nisovalue sweep: {} frames, each with a new isovalue ({} .. {}): median {:.2} ms, max {:.2} ms = {:.2}x / {:.2}x the steady {:.2} ms (a rebuild would add {:.1} ms)",
            w.frame_ms.len(),
            w.isovalues.first().copied().unwrap_or(0.0),
            w.isovalues.last().copied().unwrap_or(0.0),
            median(&w.frame_ms),
            w.frame_ms.iter().copied().fold(0.0, f64::max),
            w.median_ratio,
            w.max_ratio,
            w.steady_median_ms,
            w.build_ms
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

/// `bench --mpi`: frames rendered across the job's ranks, and what each rank did.
#[derive(Debug, Serialize)]
pub struct DistributedReport {
    pub file: String,
    pub ranks: usize,
    pub threads_per_rank: usize,
    pub width: u32,
    pub height: u32,
    pub frames: usize,
    pub median_frame_ms: f64,
    /// Primary rays per second of the whole job (median frame).
    pub rays_per_second: f64,
    /// Per rank, over all timed frames: chunks per frame and rays/s while rendering.
    pub per_rank: Vec<DistributedRank>,
    pub gather_bytes_per_frame: f64,
    pub median_gather_ms: f64,
}

#[derive(Debug, Serialize)]
pub struct DistributedRank {
    pub rank: usize,
    pub chunks_per_frame: f64,
    pub rays_per_second: f64,
}

fn measure_distributed(args: &Args) -> anyhow::Result<DistributedReport> {
    let s = setup(args)?;
    let go = AtomicBool::new(false);
    let failed = || {
        crate::distributed::status()
            .and_then(|j| j.failure)
            .map_or_else(|| anyhow::anyhow!("cancelled"), |f| anyhow::anyhow!(f))
    };
    // The first frame waits for every rank to open the input; not timed.
    s.scene
        .render(&s.camera, &s.settings, &go)
        .ok_or_else(failed)?;
    let frames = args.frames.max(1);
    let mut frame_ms = Vec::with_capacity(frames);
    let mut rays_per_s = Vec::with_capacity(frames);
    let mut gather_ms = Vec::with_capacity(frames);
    let mut gather_bytes = 0u64;
    let mut per_rank: Vec<(usize, u64, f64)> = Vec::new();
    for _ in 0..frames {
        let f = s
            .scene
            .render(&s.camera, &s.settings, &go)
            .ok_or_else(failed)?;
        let r = crate::distributed::with_cluster(|c| c.last_report().cloned())
            .flatten()
            .context("no MPI job serves this file")?;
        let secs = f.elapsed.as_secs_f64();
        frame_ms.push(secs * 1e3);
        rays_per_s.push(f.rays.primary as f64 / secs.max(1e-9));
        gather_ms.push(r.gather_seconds * 1e3);
        gather_bytes += r.gather_bytes;
        per_rank.resize(r.ranks.len(), (0, 0, 0.0));
        for (acc, rank) in per_rank.iter_mut().zip(&r.ranks) {
            acc.0 += rank.chunks;
            acc.1 += rank.primary_rays;
            acc.2 += rank.render_seconds;
        }
    }
    Ok(DistributedReport {
        file: args.file.display().to_string(),
        ranks: per_rank.len(),
        threads_per_rank: rayon::current_num_threads(),
        width: s.settings.width,
        height: s.settings.height,
        frames,
        median_frame_ms: median(&frame_ms),
        rays_per_second: median(&rays_per_s),
        per_rank: per_rank
            .iter()
            .enumerate()
            .map(|(rank, &(chunks, rays, secs))| DistributedRank {
                rank,
                chunks_per_frame: chunks as f64 / frames as f64,
                rays_per_second: rays as f64 / secs.max(1e-9),
            })
            .collect(),
        gather_bytes_per_frame: gather_bytes as f64 / frames as f64,
        median_gather_ms: median(&gather_ms),
    })
}

fn format_distributed(r: &DistributedReport) -> String {
    use std::fmt::Write as _;
    let mut s = String::new();
    let _ = writeln!(
        s,
        "{}: {}x{}, MPI {} ranks x {} threads, {} frames",
        r.file, r.width, r.height, r.ranks, r.threads_per_rank, r.frames
    );
    let _ = writeln!(
        s,
        "frame: median {:.1} ms, {:.2} M primary rays/s",
        r.median_frame_ms,
        r.rays_per_second / 1e6
    );
    for p in &r.per_rank {
        let _ = writeln!(
            s,
            "rank {}: {:.1} chunks/frame, {:.2} M rays/s while rendering",
            p.rank,
            p.chunks_per_frame,
            p.rays_per_second / 1e6
        );
    }
    let _ = writeln!(
        s,
        "gather on rank 0: {:.2} MB/frame, median {:.2} ms/frame",
        r.gather_bytes_per_frame / 1e6,
        r.median_gather_ms
    );
    s
}

/// Runs `measure` on `--threads` threads (the global pool without the flag) and prints its
/// report as JSON or text.
fn report_with<R: Serialize + Send>(
    args: &Args,
    measure: fn(&Args) -> anyhow::Result<R>,
    text: fn(&R) -> String,
) -> anyhow::Result<()> {
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
        print!("{}", text(&report));
    }
    Ok(())
}

pub fn run(args: &Args) -> anyhow::Result<()> {
    if crate::distributed::status().is_some() {
        report_with(args, measure_distributed, format_distributed)
    } else {
        report_with(args, measure, format_report)
    }
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
