//! `isoscope accuracy [-o docs/accuracy.md] [--images docs/images/accuracy] [--json FILE]
//! [--size WxH] [--frames N] [--threads T] [--volume FILE:V[,V...]]... [--quick]`
//!
//! Writes the speed/accuracy report of the five cell intersectors (thesis seed 004 §7.2.2)
//! as Markdown, with difference images and a JSON twin:
//! - on Marschner–Lobb 128³ and 256³ (`f32` and `u8`), the CT-like phantom (smooth, and with
//!   table, blur and noise) and any `--volume` files (real data): Mrays/s of full frames
//!   (kd-tree packets, shading included; [`super::bench::time_config`]) and, over every
//!   pixel's primary ray (1024² by default), mean/max |Δt| against the `f64` reference in cell units,
//!   % missed and % false hits ([`volume_core::intersect::accuracy::score`]); one PNG heat map
//!   of |Δt| per pixel and intersector, with missed, false and wrong-surface pixels marked;
//! - on the extreme suite ([`volume_core::intersect::accuracy::extreme_suite`]): totals per
//!   intersector and missed/false/max |Δt| per case.
//!
//! `--quick` uses small volumes and images (for tests); the committed docs/accuracy.md is
//! the full run. The Markdown names the command that produced it.

use std::fmt::Write as _;
use std::path::{Component, Path, PathBuf};
use std::sync::atomic::AtomicBool;

use anyhow::{Context as _, bail};
use data_samples::Generator;
use data_samples::phantom::PhantomOptions;
use formats::output::Replace;
use serde::Serialize;
use volume_core::grid::AnyGridScene;
use volume_core::intersect::Intersector;
use volume_core::intersect::accuracy::{self, AccuracyReport, RayOutcome, Traced};
use volume_core::render::{Camera, IsoScene, RenderSettings, Surface};

use volume_core::{RectilinearVolume, VoxelType};

use super::bench;
use super::render::{PALETTE, parse_size, render_grid, save_png};
use crate::progress::Progress;

/// Arguments of `isoscope accuracy`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Markdown report to write.
    #[arg(
        short,
        long,
        value_name = "FILE.md",
        default_value = "docs/accuracy.md"
    )]
    pub output: PathBuf,
    /// Directory for the difference images (created if missing; linked relative to the
    /// report).
    #[arg(long, value_name = "DIR", default_value = "docs/images/accuracy")]
    pub images: PathBuf,
    /// JSON twin of the report. Default: accuracy.json in the images directory.
    #[arg(long, value_name = "FILE.json")]
    pub json: Option<PathBuf>,
    /// Replace existing report and image files (a rerun that updates the docs).
    #[arg(long)]
    pub force: bool,
    /// Image size of the datasets' camera (every pixel is scored). Default 1024x1024 (48x48
    /// with --quick).
    #[arg(long, value_name = "WxH", value_parser = parse_size)]
    pub size: Option<[u32; 2]>,
    /// Also score a volume file (real data: an MRI, a CT), at these isovalues (physical
    /// units): `FILE:V[,V...]`. Repeatable.
    #[arg(long = "volume", value_name = "FILE:V[,V...]", value_parser = parse_volume_spec)]
    pub volumes: Vec<VolumeSpec>,
    /// Timed frames per intersector (after one warm-up); the median is reported.
    /// Default 3 (1 with --quick).
    #[arg(long, value_name = "N")]
    pub frames: Option<usize>,
    /// Worker threads for the timed frames (a local rayon pool). Default: all cores.
    #[arg(long, value_name = "T")]
    pub threads: Option<usize>,
    /// Small volumes and images (seconds, for tests); the extreme suite stays complete.
    #[arg(long)]
    pub quick: bool,
}

/// One row: one intersector on one dataset or on the suite.
#[derive(Debug, Clone, Serialize)]
pub struct Row {
    pub intersector: String,
    /// Datasets: primary rays/s of full frames (kd-tree packets, all threads), millions.
    /// Suite: rays/s of the single-threaded, one-ray-at-a-time traversal, millions.
    pub mrays_per_second: f64,
    pub rays: u64,
    pub reference_hits: u64,
    /// Hits of this intersector.
    pub hits: u64,
    pub missed: u64,
    pub false_hits: u64,
    pub wrong_surface: u64,
    /// Both hit, more than half a cell apart (a different crossing).
    pub far_hits: u64,
    /// % of reference hits.
    pub missed_percent: f64,
    /// % of rays.
    pub false_percent: f64,
    /// Over rays both hit, cell units.
    pub mean_abs_dt_cells: f64,
    pub max_abs_dt_cells: f64,
    /// Difference image, relative to the Markdown file.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub image: Option<String>,
}

impl Row {
    fn new(name: String, mrays_per_second: f64, r: &AccuracyReport) -> Self {
        Self {
            intersector: name,
            mrays_per_second,
            rays: r.rays,
            reference_hits: r.reference_hits,
            hits: r.reference_hits - r.missed + r.false_hits,
            missed: r.missed,
            false_hits: r.false_hits,
            wrong_surface: r.wrong_surface,
            far_hits: r.far_hits,
            missed_percent: r.missed_percent(),
            false_percent: r.false_percent(),
            mean_abs_dt_cells: r.mean_abs_dt_cells,
            max_abs_dt_cells: r.max_abs_dt_cells,
            image: None,
        }
    }
}

/// One dataset's table.
#[derive(Debug, Clone, Serialize)]
pub struct DatasetResult {
    pub name: String,
    pub dims: [usize; 3],
    pub voxel_type: String,
    pub isovalues: Vec<f32>,
    pub width: u32,
    pub height: u32,
    /// The exact intersector's shaded frame, relative to the Markdown file.
    pub render_image: String,
    pub rows: Vec<Row>,
}

/// One case of the extreme suite.
#[derive(Debug, Clone, Serialize)]
pub struct SuiteCase {
    pub name: String,
    pub rows: Vec<Row>,
}

/// The `--json` document.
#[derive(Debug, Clone, Serialize)]
pub struct AccuracyDoc {
    pub command: String,
    pub generated_utc: String,
    pub threads: usize,
    pub quick: bool,
    pub datasets: Vec<DatasetResult>,
    /// Per intersector, over every ray of the suite.
    pub suite_totals: Vec<Row>,
    pub suite: Vec<SuiteCase>,
    /// `accuracy::limit_cases`: outside the suite's requirement (see there).
    pub limits: Vec<SuiteCase>,
}

/// `--volume FILE:V[,V...]`: a volume file and its isovalues.
#[derive(Debug, Clone)]
pub struct VolumeSpec {
    pub path: PathBuf,
    pub isovalues: Vec<f32>,
}

fn parse_volume_spec(s: &str) -> Result<VolumeSpec, String> {
    let (path, values) = s
        .rsplit_once(':')
        .ok_or_else(|| format!("{s:?}: expected FILE:V[,V...]"))?;
    let isovalues = values
        .split(',')
        .map(|v| {
            v.trim()
                .parse::<f32>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| format!("{s:?}: {v:?} is not a finite isovalue"))
        })
        .collect::<Result<Vec<_>, _>>()?;
    if path.is_empty() {
        return Err(format!("{s:?}: no file name"));
    }
    Ok(VolumeSpec {
        path: PathBuf::from(path),
        isovalues,
    })
}

/// Where a dataset's volume comes from.
enum Source {
    /// A generator of `data-samples` (the phantom with its realism options).
    Generated {
        generator: Generator,
        dims: [usize; 3],
        voxel_type: VoxelType,
        phantom: PhantomOptions,
    },
    /// A file (`--volume`).
    File(PathBuf),
}

/// A dataset of the report: its volume and isovalues (physical units).
struct DatasetSpec {
    name: String,
    slug: String,
    source: Source,
    isovalues: Vec<f32>,
}

impl DatasetSpec {
    fn load(&self) -> anyhow::Result<RectilinearVolume> {
        match &self.source {
            Source::Generated {
                generator,
                dims,
                voxel_type,
                phantom,
            } => if phantom.is_smooth() {
                generator.generate(*dims, *voxel_type)
            } else {
                data_samples::phantom::generate_with(*dims, *voxel_type, phantom, &|| {})
            }
            .with_context(|| format!("generating {}", self.name)),
            Source::File(path) => Ok(formats::open(path, &formats::OpenOptions::default())?
                .first_volume()
                .clone()),
        }
    }
}

/// A short name for file names: the file stem's letters and digits.
fn slug_of(path: &Path) -> String {
    let stem = path.file_name().map_or_else(String::new, |n| {
        let n = n.to_string_lossy();
        n.split('.').next().unwrap_or_default().to_string()
    });
    let slug: String = stem
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() {
                c.to_ascii_lowercase()
            } else {
                '-'
            }
        })
        .collect();
    if slug.is_empty() {
        "volume".into()
    } else {
        slug
    }
}

fn dataset_specs(quick: bool, volumes: &[VolumeSpec]) -> Vec<DatasetSpec> {
    let ml_sizes: &[usize] = if quick { &[24, 32] } else { &[128, 256] };
    let mut specs = Vec::new();
    for &n in ml_sizes {
        for t in [VoxelType::F32, VoxelType::U8] {
            let g = Generator::MarschnerLobb;
            let iso = g
                .value_map(t)
                .to_stored(data_samples::marschner_lobb::ISOVALUE) as f32;
            specs.push(DatasetSpec {
                name: format!("Marschner–Lobb {n}³ {}", t.name()),
                slug: format!("ml{n}-{}", t.name()),
                source: Source::Generated {
                    generator: g,
                    dims: [n; 3],
                    voxel_type: t,
                    phantom: PhantomOptions::default(),
                },
                isovalues: vec![iso],
            });
        }
    }
    let g = Generator::Phantom;
    let dims = if quick {
        g.dims_for_size(40)
    } else {
        g.default_dims()
    };
    let t = g.default_voxel_type();
    let isovalues: Vec<f32> = g
        .suggested_isovalues()
        .iter()
        .map(|&v| g.value_map(t).to_stored(v) as f32)
        .collect();
    let dims_name = format!("{}×{}×{} {}", dims[0], dims[1], dims[2], t.name());
    specs.push(DatasetSpec {
        name: format!("CT-like phantom {dims_name} (skin and bone)"),
        slug: "phantom".into(),
        source: Source::Generated {
            generator: g,
            dims,
            voxel_type: t,
            phantom: PhantomOptions::default(),
        },
        isovalues: isovalues.clone(),
    });
    // Real CT's roughness: table, partial-volume blur and noise (`generate phantom
    // --noise 20 --blur 0.7 --table`).
    specs.push(DatasetSpec {
        name: format!("CT-like phantom {dims_name} with table, blur 0.7 mm and noise 20 HU"),
        slug: "phantom-noisy".into(),
        source: Source::Generated {
            generator: g,
            dims,
            voxel_type: t,
            phantom: PhantomOptions {
                noise_hu: 20.0,
                blur_mm: 0.7,
                table: true,
                seed: 1,
            },
        },
        isovalues,
    });
    for v in volumes {
        specs.push(DatasetSpec {
            name: v.path.display().to_string(),
            slug: slug_of(&v.path),
            source: Source::File(v.path.clone()),
            isovalues: v.isovalues.clone(),
        });
    }
    specs
}

/// `target` relative to directory `base` (both made absolute first), with `/` separators.
fn relative_path(base: &Path, target: &Path) -> anyhow::Result<String> {
    let abs = |p: &Path| -> anyhow::Result<PathBuf> {
        let p = if p.is_absolute() {
            p.to_path_buf()
        } else {
            std::env::current_dir()?.join(p)
        };
        // Resolve `.` and `..` lexically (the files need not exist yet).
        let mut out = PathBuf::new();
        for c in p.components() {
            match c {
                Component::ParentDir => {
                    out.pop();
                }
                Component::CurDir => {}
                c => out.push(c),
            }
        }
        Ok(out)
    };
    let (base, target) = (abs(base)?, abs(target)?);
    let b: Vec<_> = base.components().collect();
    let t: Vec<_> = target.components().collect();
    let common = b.iter().zip(&t).take_while(|(x, y)| x == y).count();
    let mut parts: Vec<String> = vec!["..".to_string(); b.len() - common];
    parts.extend(
        t[common..]
            .iter()
            .map(|c| c.as_os_str().to_string_lossy().into_owned()),
    );
    Ok(parts.join("/"))
}

/// Colour of `|Δt|` on a log scale: 1e-7 cell (or less) → black … 1 cell (or more) →
/// yellow, through purple, red and orange (an inferno-like ramp).
pub fn heat_color(abs_dt_cells: f64) -> [u8; 3] {
    const STOPS: [[f64; 3]; 5] = [
        [0.0, 0.0, 4.0],
        [87.0, 16.0, 110.0],
        [188.0, 55.0, 84.0],
        [249.0, 142.0, 9.0],
        [255.0, 230.0, 40.0],
    ];
    let x = if abs_dt_cells > 0.0 {
        ((abs_dt_cells.log10() + 7.0) / 7.0).clamp(0.0, 1.0)
    } else {
        0.0
    };
    let f = x * (STOPS.len() - 1) as f64;
    let i = (f.floor() as usize).min(STOPS.len() - 2);
    let w = f - i as f64;
    [0, 1, 2].map(|c| (STOPS[i][c] + w * (STOPS[i + 1][c] - STOPS[i][c])).round() as u8)
}

/// Pixels where neither hits.
pub const NO_HIT: [u8; 3] = [225, 225, 225];
/// Reference hits, the method does not.
pub const MISSED: [u8; 3] = [0, 210, 0];
/// The method hits, the reference does not.
pub const FALSE_HIT: [u8; 3] = [0, 150, 255];
/// Both hit, different surfaces.
pub const WRONG_SURFACE: [u8; 3] = [255, 0, 255];

/// Most pixels per side of the PNGs (every ray is still scored): a larger frame is shown
/// reduced by square blocks, so 1024² reports keep `docs/images` small.
pub const MAX_IMAGE_SIDE: u32 = 256;

/// The side of the blocks that bring a `size` frame within [`MAX_IMAGE_SIDE`].
pub fn image_block(size: [u32; 2]) -> u32 {
    size[0].max(size[1]).div_ceil(MAX_IMAGE_SIDE).max(1)
}

/// How bad an outcome is, for [`worst_per_block`]: errors above the worst |Δt|, above no hit.
fn severity(o: &RayOutcome) -> (u8, f64) {
    match *o {
        RayOutcome::NoHit => (0, 0.0),
        RayOutcome::Both {
            abs_dt_cells,
            same_surface: true,
        } => (1, abs_dt_cells),
        RayOutcome::Both { .. } => (2, 0.0),
        RayOutcome::Missed => (3, 0.0),
        RayOutcome::False => (4, 0.0),
    }
}

/// The outcomes of a `width × height` frame reduced by `block × block` squares, each to its
/// worst outcome (so one missed ray still shows), with the reduced width and height.
pub fn worst_per_block(
    outcomes: &[RayOutcome],
    width: u32,
    height: u32,
    block: u32,
) -> (Vec<RayOutcome>, u32, u32) {
    let block = block.max(1);
    let (w, h) = (width.div_ceil(block), height.div_ceil(block));
    let mut out = vec![RayOutcome::NoHit; w as usize * h as usize];
    for (n, o) in outcomes.iter().enumerate() {
        let (x, y) = ((n % width as usize) as u32, (n / width as usize) as u32);
        if y >= height {
            break;
        }
        let cell = &mut out[(y / block * w + x / block) as usize];
        if severity(o).partial_cmp(&severity(cell)) == Some(std::cmp::Ordering::Greater) {
            *cell = *o;
        }
    }
    (out, w, h)
}

/// The difference image: |Δt| heat map; missed, false and wrong-surface pixels drawn as
/// 3×3 marks on top so that single pixels stay visible.
pub fn difference_image(outcomes: &[RayOutcome], width: u32, height: u32) -> image::RgbImage {
    let mut img = image::RgbImage::new(width, height);
    let mut marks = Vec::new();
    for (n, o) in outcomes.iter().enumerate() {
        let (x, y) = ((n % width as usize) as u32, (n / width as usize) as u32);
        if y >= height {
            break;
        }
        let c = match *o {
            RayOutcome::NoHit => NO_HIT,
            RayOutcome::Both {
                abs_dt_cells,
                same_surface,
            } => {
                if !same_surface {
                    marks.push((x, y, WRONG_SURFACE));
                }
                heat_color(abs_dt_cells)
            }
            RayOutcome::Missed => {
                marks.push((x, y, MISSED));
                MISSED
            }
            RayOutcome::False => {
                marks.push((x, y, FALSE_HIT));
                FALSE_HIT
            }
        };
        img.put_pixel(x, y, image::Rgb(c));
    }
    for (x, y, c) in marks {
        for yy in y.saturating_sub(1)..=(y + 1).min(height - 1) {
            for xx in x.saturating_sub(1)..=(x + 1).min(width - 1) {
                img.put_pixel(xx, yy, image::Rgb(c));
            }
        }
    }
    img
}

/// The colour bar of [`heat_color`]: 1e-7 … 1 cell, a tick at every decade.
pub fn legend_image() -> image::RgbImage {
    let (w, h) = (281u32, 16u32);
    image::RgbImage::from_fn(w, h, |x, y| {
        let decade = x as f64 / f64::from(w - 1) * 7.0;
        if y >= h - 4 && (decade - decade.round()).abs() < 0.5 / 40.0 {
            return image::Rgb([255, 255, 255]);
        }
        image::Rgb(heat_color(10f64.powf(decade - 7.0)))
    })
}

fn save_rgb(img: &image::RgbImage, path: &Path, replace: Replace) -> anyhow::Result<()> {
    let bytes = crate::output::png_bytes(
        img.as_raw(),
        img.width(),
        img.height(),
        image::ExtendedColorType::Rgb8,
    )?;
    formats::output::write_output(path, &bytes, replace)?;
    Ok(())
}

/// Every file `accuracy` writes, to check them all before the long measurement.
fn output_paths(args: &Args) -> Vec<PathBuf> {
    let mut paths = vec![
        args.output.clone(),
        json_path(args),
        args.images.join("legend.png"),
    ];
    for spec in dataset_specs(args.quick, &args.volumes) {
        paths.push(args.images.join(format!("{}-render.png", spec.slug)));
        for method in Intersector::ALL {
            if method != Intersector::Reference {
                paths.push(args.images.join(format!("{}-{method}.png", spec.slug)));
            }
        }
    }
    paths
}

fn json_path(args: &Args) -> PathBuf {
    args.json
        .clone()
        .unwrap_or_else(|| args.images.join("accuracy.json"))
}

/// Measures one dataset: frames per intersector, per-pixel scores, images.
fn measure_dataset(
    spec: &DatasetSpec,
    size: [u32; 2],
    frames: usize,
    images: &Path,
    md_dir: &Path,
    replace: Replace,
) -> anyhow::Result<DatasetResult> {
    let volume: RectilinearVolume = {
        let _s = Progress::spinner(format!("loading {}", spec.name));
        spec.load()?
    };
    let mut scene = {
        let _s = Progress::spinner("building the kd-tree");
        AnyGridScene::new(&volume, Intersector::Exact)
    };
    let camera = Camera::orbit(&scene.world_bounds(), 30.0, 20.0, 40.0);
    let settings = RenderSettings {
        width: size[0],
        height: size[1],
        surfaces: spec
            .isovalues
            .iter()
            .enumerate()
            .map(|(i, &v)| Surface::new(v, PALETTE[i % PALETTE.len()]))
            .collect(),
        ..RenderSettings::default()
    };
    settings.validate()?;

    let go = AtomicBool::new(false);
    let block = image_block(size);
    let picture = RenderSettings {
        width: size[0].div_ceil(block),
        height: size[1].div_ceil(block),
        ..settings.clone()
    };
    let frame = render_grid(&scene, false, &camera, &picture, &go).context("cancelled")?;
    let render_path = images.join(format!("{}-render.png", spec.slug));
    save_png(&frame, &render_path, replace)?;

    let pixels = size[0] as usize * size[1] as usize;
    let rays = bench::accuracy_rays(&camera, size[0], size[1], pixels);
    let truth: Traced = {
        let _s = Progress::spinner(format!("{}: f64 reference", spec.name));
        accuracy::trace_rays(&scene, &rays, &spec.isovalues, Intersector::Reference)
    };
    let mut rows = Vec::new();
    for method in Intersector::ALL {
        scene.set_intersector(method);
        let timing = bench::time_config(
            &format!("{} {method}", spec.slug),
            &scene,
            false,
            &camera,
            &settings,
            frames,
        )?;
        let got = if method == Intersector::Reference {
            truth.clone()
        } else {
            let _s = Progress::spinner(format!("{}: {method}", spec.name));
            accuracy::trace_rays(&scene, &rays, &spec.isovalues, method)
        };
        let (report, outcomes) = accuracy::score(&got, &truth);
        let mut row = Row::new(method.to_string(), timing.rays_per_second / 1e6, &report);
        if method != Intersector::Reference {
            let path = images.join(format!("{}-{method}.png", spec.slug));
            let (worst, w, h) = worst_per_block(&outcomes, size[0], size[1], block);
            save_rgb(&difference_image(&worst, w, h), &path, replace)?;
            row.image = Some(relative_path(md_dir, &path)?);
        }
        rows.push(row);
    }
    Ok(DatasetResult {
        name: spec.name.clone(),
        dims: volume.dims(),
        voxel_type: volume.data.voxel_type().name().to_string(),
        isovalues: spec.isovalues.clone(),
        width: size[0],
        height: size[1],
        render_image: relative_path(md_dir, &render_path)?,
        rows,
    })
}

fn suite_cases(results: &[(String, Vec<AccuracyReport>)]) -> Vec<SuiteCase> {
    results
        .iter()
        .map(|(name, reports)| SuiteCase {
            name: name.clone(),
            rows: reports
                .iter()
                .map(|r| Row::new(r.intersector.to_string(), r.mrays_per_second(), r))
                .collect(),
        })
        .collect()
}

/// Runs the extreme suite: per-case rows and totals per intersector.
fn measure_suite() -> (Vec<SuiteCase>, Vec<Row>) {
    let results = {
        let _s = Progress::spinner("extreme suite");
        accuracy::run_extreme_suite(&Intersector::ALL)
    };
    let cases = suite_cases(&results);
    let totals = Intersector::ALL
        .iter()
        .enumerate()
        .map(|(i, &method)| {
            let mut total = AccuracyReport {
                intersector: method,
                rays: 0,
                reference_hits: 0,
                missed: 0,
                false_hits: 0,
                mean_abs_dt_cells: 0.0,
                max_abs_dt_cells: 0.0,
                wrong_surface: 0,
                far_hits: 0,
                seconds: 0.0,
            };
            let mut sum_dt = 0.0;
            let mut both = 0u64;
            for (_, reports) in &results {
                let r = &reports[i];
                total.rays += r.rays;
                total.reference_hits += r.reference_hits;
                total.missed += r.missed;
                total.false_hits += r.false_hits;
                total.wrong_surface += r.wrong_surface;
                total.far_hits += r.far_hits;
                total.seconds += r.seconds;
                total.max_abs_dt_cells = total.max_abs_dt_cells.max(r.max_abs_dt_cells);
                let n = r.reference_hits - r.missed;
                sum_dt += r.mean_abs_dt_cells * n as f64;
                both += n;
            }
            if both > 0 {
                total.mean_abs_dt_cells = sum_dt / both as f64;
            }
            Row::new(method.to_string(), total.mrays_per_second(), &total)
        })
        .collect();
    (cases, totals)
}

/// `YYYY-MM-DD HH:MM` UTC of the system clock.
fn utc_now() -> String {
    let secs = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs());
    let (days, rem) = ((secs / 86_400) as i64, secs % 86_400);
    // Civil date from days since 1970-01-01 (H. Hinnant's algorithm).
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z.rem_euclid(146_097);
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + i64::from(m <= 2);
    format!(
        "{y:04}-{m:02}-{d:02} {:02}:{:02}",
        rem / 3600,
        (rem % 3600) / 60
    )
}

/// Short scientific notation for the tables (`0` stays `0`).
fn sci(x: f64) -> String {
    if x == 0.0 {
        "0".to_string()
    } else {
        format!("{x:.1e}")
    }
}

fn pct(x: f64) -> String {
    if x == 0.0 {
        "0".to_string()
    } else {
        format!("{x:.3}")
    }
}

const METHOD_NOTES: &str = "\
- **linear**: one linear interpolation between the cell entry and exit values. Misses every
  cell the ray enters and leaves on the same side of the isovalue (tangent touches, thin
  features), and its position error grows with the surface's curvature inside the cell.
- **neubauer** (3 iterations): linear plus regula-falsi steps on the same bracket: the same
  misses, a much smaller position error.
- **exact** (Listing 7.1, the default): exact on every ray by construction. A segment is
  dismissed in f32 only when the convex hull of its cubic's Bernstein coefficients stays
  farther from the isovalue than a rigorous bound on the f32 error against the f64 truth
  (corner differences, segment ends, coefficients, evaluation); every other segment is
  decided by the reference's own f64 procedure on the exact segment (the derivative's roots
  split it into monotone pieces; the first piece whose ends differ in sign holds the first
  crossing; a touch counts within the reference's rounding bound), then refined by
  safeguarded f64 Newton steps instead of bisection. So it finds exactly the reference's
  crossings: 0 missed, 0 false and 0 far hits on every dataset, at any resolution; |Δt| is
  the refinement's residue. Earlier versions decided in f32 with a touching band of
  64·ε·max|g|, which at 1024² turned a few near misses per million rays into hits
  (regression tests in `volume_core::intersect::accuracy`).
- **schwarze**: Cardano's formula in f32. Exact in exact arithmetic, but cancellation for
  nearly quadratic segments and clustered roots costs digits: large |Δt| on a few rays, and
  misses where rounding pushes a double root to a complex pair.
- **reference**: f64 root isolation (derivative roots as brackets, bisection to full double
  precision) on the same f32 inputs: the truth every other row is measured against.
";

/// Title, method notes and the suite tables.
fn format_head(s: &mut String, doc: &AccuracyDoc, legend: &str) {
    let _ = writeln!(s, "# Intersector speed and accuracy\n");
    let _ = writeln!(
        s,
        "_Generated by `{}` on {} UTC ({} threads){}. Do not edit by hand: rerun the command \
         (release build: `cargo run --release -p isoscope -- accuracy --force`)._\n",
        doc.command,
        doc.generated_utc,
        doc.threads,
        if doc.quick {
            "; **--quick: small volumes**"
        } else {
            ""
        }
    );
    let _ = writeln!(
        s,
        "The five cell intersectors (thesis seed 004 §7.2.2) against the f64 \
         reference, on the same kd-tree and the same rays. **|Δt|** is the distance between \
         the method's first hit and the reference's along the ray, in **cell units** (one \
         cell edge on a uniform axis), over the rays both hit. **% missed**: reference hits \
         the method does not find, in % of reference hits. **% false**: method hits where \
         the reference has none, in % of rays. **wrong surf.**: both hit, but different \
         isosurfaces first. **far hits**: both hit, more than half a cell apart, i.e. \
         different crossings: the method skipped the reference's first crossing (a missed \
         hit in disguise) or found one before it (a false hit in disguise); they are \
         included in the |Δt| columns.\n"
    );
    let _ = writeln!(
        s,
        "Datasets: every pixel's primary ray of an orbit camera (azimuth 30°, elevation 20°, \
         40° field of view) is scored; **Mrays/s** is the median primary-ray throughput of \
         full frames at that size (kd-tree, 16-ray packets, shading, all threads; \
         `isoscope bench`'s measurement), so it includes the traversal and shading every \
         method shares. Extreme suite: Mrays/s of the single-threaded one-ray-at-a-time \
         traversal over the suite's few thousand rays (noisy; a relative measure only). \
         Images of frames wider than {MAX_IMAGE_SIDE} pixels are reduced by square blocks: \
         a difference image's pixel shows the worst ray of its block (every ray is scored; one \
         missed ray still shows).\n"
    );
    let _ = writeln!(s, "## Error behaviour\n\n{METHOD_NOTES}");
    let _ = writeln!(
        s,
        "Difference images: |Δt| per pixel on a log scale, ![colour bar]({legend}) from \
         1e-7 cell (black) through 1e-3 (red) to ≥ 1 cell (yellow), ticks at every decade; \
         light grey: neither hits; **green** 3×3 marks: missed hits; **blue**: false hits; \
         **magenta**: wrong surface. The reference's own image would be all black and is \
         left out.\n"
    );

    let _ = writeln!(s, "## Extreme suite (all cases)\n");
    let _ = writeln!(
        s,
        "The extreme cases (`volume_core::intersect::accuracy::extreme_suite`, seeded): \
         grazing and axis-parallel rays, rays along cell faces and edges (inside the volume \
         and on its outer faces), tangent (double-root) cells in u8 and f32 with \
         near-tangent rays, triple-root cells, integer data (u8, i16) at integer isovalues \
         with iso-valued constant cells, planes and grid lines, NaN and ±inf voxels, values \
         near the f32 limits, around 1e30 and denormal, a volume at 1e6 from the origin, \
         volumes one sample or one cell thin along each axis, and cameras inside the volume \
         (also on sample positions inside iso-valued cells). Rays through iso-valued samples \
         use small integer directions so that they pass the sample exactly: a ray with a \
         random unit direction passes it ~1e-7 cell away, where a touch of the surface is \
         decided by the rounding of the cell-local entry point (f32 in the fast methods, \
         f64 in the reference), not by the method; while building the suite such rays gave \
         the exact intersector 1 missed and 1 false hit in 200.\n"
    );
    let _ = writeln!(
        s,
        "| intersector | Mrays/s (1 thread) | rays | reference hits | missed | false | % missed | % false | wrong surf. | far hits | mean \\|Δt\\| (cells) | max \\|Δt\\| (cells) |"
    );
    let _ = writeln!(
        s,
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"
    );
    for r in &doc.suite_totals {
        let _ = writeln!(
            s,
            "| {} | {:.2} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} |",
            r.intersector,
            r.mrays_per_second,
            r.rays,
            r.reference_hits,
            r.missed,
            r.false_hits,
            pct(r.missed_percent),
            pct(r.false_percent),
            r.wrong_surface,
            r.far_hits,
            sci(r.mean_abs_dt_cells),
            sci(r.max_abs_dt_cells)
        );
    }
    let _ = writeln!(
        s,
        "\nPer case: `missed / false / far · max |Δt|` (cells) for each intersector.\n"
    );
    case_table(s, &doc.suite);
    let _ = writeln!(s, "## Limits of f32\n");
    let _ = writeln!(
        s,
        "Inputs whose answer is decided below f32 resolution \
         (`volume_core::intersect::accuracy::limit_cases`): rays along the saddle diagonals \
         with the isovalue a small gap below the saddle value (along even diagonals the field \
         stays `gap` above the isovalue: a near miss; along odd diagonals two roots 2·√gap \
         apart), and random unit rays aimed at iso-valued samples (see above). The f32 \
         methods cannot tell these apart; the exact method hands them to its f64 path. Same \
         format as the per-case table.\n"
    );
    case_table(s, &doc.limits);
}

/// One row per case: `missed / false · max |Δt|` per intersector.
fn case_table(s: &mut String, cases: &[SuiteCase]) {
    let names: Vec<String> = Intersector::ALL.iter().map(ToString::to_string).collect();
    let _ = writeln!(s, "| case | rays | ref. hits | {} |", names.join(" | "));
    let _ = writeln!(s, "|---|---:|---:|{}", "---|".repeat(names.len()));
    for case in cases {
        let first = &case.rows[0];
        let cells: Vec<String> = case
            .rows
            .iter()
            .map(|r| {
                format!(
                    "{} / {} / {} · {}",
                    r.missed,
                    r.false_hits,
                    r.far_hits,
                    sci(r.max_abs_dt_cells)
                )
            })
            .collect();
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} |",
            case.name,
            first.rays,
            first.reference_hits,
            cells.join(" | ")
        );
    }
    let _ = writeln!(s);
}

/// The Markdown report.
pub fn format_markdown(doc: &AccuracyDoc, legend: &str) -> String {
    let mut s = String::new();
    format_head(&mut s, doc, legend);
    for d in &doc.datasets {
        let _ = writeln!(s, "## {}\n", d.name);
        let _ = writeln!(
            s,
            "{}×{}×{} {}, isovalue(s) {:?}, {}×{} rays (every pixel).\n",
            d.dims[0], d.dims[1], d.dims[2], d.voxel_type, d.isovalues, d.width, d.height
        );
        let _ = writeln!(
            s,
            "| intersector | Mrays/s | mean \\|Δt\\| (cells) | max \\|Δt\\| (cells) | % missed | % false | wrong surf. | far hits | difference image |"
        );
        let _ = writeln!(s, "|---|---:|---:|---:|---:|---:|---:|---:|---|");
        for r in &d.rows {
            let image = r.image.as_ref().map_or_else(
                || "(the truth)".to_string(),
                |p| {
                    format!(
                        "[{}]({p})",
                        Path::new(p)
                            .file_name()
                            .map_or_else(String::new, |f| f.to_string_lossy().into_owned())
                    )
                },
            );
            let _ = writeln!(
                s,
                "| {} | {:.2} | {} | {} | {} | {} | {} | {} | {} |",
                r.intersector,
                r.mrays_per_second,
                sci(r.mean_abs_dt_cells),
                sci(r.max_abs_dt_cells),
                pct(r.missed_percent),
                pct(r.false_percent),
                r.wrong_surface,
                r.far_hits,
                image
            );
        }
        let _ = writeln!(s);
        // One row of thumbnails: the shaded frame, then each method's difference image.
        let mut head = vec!["exact (shaded)".to_string()];
        let mut imgs = vec![format!("![{} shaded]({})", d.name, d.render_image)];
        for r in &d.rows {
            if let Some(p) = &r.image {
                head.push(r.intersector.clone());
                imgs.push(format!("![{} {}]({p})", d.name, r.intersector));
            }
        }
        let _ = writeln!(s, "| {} |", head.join(" | "));
        let _ = writeln!(s, "|{}", "---|".repeat(head.len()));
        let _ = writeln!(s, "| {} |\n", imgs.join(" | "));
    }
    s
}

fn measure(args: &Args, command: String) -> anyhow::Result<AccuracyDoc> {
    let size = args
        .size
        .unwrap_or(if args.quick { [48, 48] } else { [1024, 1024] });
    let frames = args.frames.unwrap_or(if args.quick { 1 } else { 3 });
    if frames == 0 {
        bail!("--frames must be at least 1");
    }
    let md_dir = args
        .output
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or_else(|| Path::new("."))
        .to_path_buf();
    std::fs::create_dir_all(&md_dir)
        .with_context(|| format!("cannot create {}", md_dir.display()))?;
    std::fs::create_dir_all(&args.images)
        .with_context(|| format!("cannot create {}", args.images.display()))?;

    let (suite, suite_totals) = measure_suite();
    let limits = suite_cases(&accuracy::run_cases(
        &accuracy::limit_cases(),
        &Intersector::ALL,
    ));
    let mut datasets = Vec::new();
    for spec in dataset_specs(args.quick, &args.volumes) {
        datasets.push(measure_dataset(
            &spec,
            size,
            frames,
            &args.images,
            &md_dir,
            Replace::from_force(args.force),
        )?);
    }
    Ok(AccuracyDoc {
        command,
        generated_utc: utc_now(),
        threads: rayon::current_num_threads(),
        quick: args.quick,
        datasets,
        suite_totals,
        suite,
        limits,
    })
}

pub fn run(args: &Args) -> anyhow::Result<()> {
    let outputs = output_paths(args);
    let refs: Vec<&Path> = outputs.iter().map(PathBuf::as_path).collect();
    formats::output::check_distinct(&refs)?;
    for out in &outputs {
        formats::output::check_output(out, Replace::from_force(args.force))?;
    }
    let command = std::iter::once("isoscope".to_string())
        .chain(std::env::args().skip(1))
        .collect::<Vec<_>>()
        .join(" ");
    let doc = match args.threads {
        None => measure(args, command)?,
        Some(0) => bail!("--threads must be at least 1"),
        Some(t) => rayon::ThreadPoolBuilder::new()
            .num_threads(t)
            .build()
            .context("cannot start the thread pool")?
            .install(|| measure(args, command))?,
    };
    let md_dir = args
        .output
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or_else(|| Path::new("."))
        .to_path_buf();
    let replace = Replace::from_force(args.force);
    let legend_path = args.images.join("legend.png");
    save_rgb(&legend_image(), &legend_path, replace)?;
    let legend = relative_path(&md_dir, &legend_path)?;
    let json_path = json_path(args);
    crate::output::save_text(
        &json_path,
        &(serde_json::to_string_pretty(&doc)? + "\n"),
        replace,
    )?;
    crate::output::save_text(&args.output, &format_markdown(&doc, &legend), replace)?;
    eprintln!(
        "wrote {}, {} and the images in {}",
        args.output.display(),
        json_path.display(),
        args.images.display()
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn relative_paths() {
        assert_eq!(
            relative_path(Path::new("/a/docs"), Path::new("/a/docs/images/x.png")).unwrap(),
            "images/x.png"
        );
        assert_eq!(
            relative_path(Path::new("/a/docs"), Path::new("/a/img/./x.png")).unwrap(),
            "../img/x.png"
        );
    }

    #[test]
    fn heat_scale_ends_and_marks() {
        assert_eq!(heat_color(0.0), [0, 0, 4]);
        assert_eq!(heat_color(1e-9), [0, 0, 4]);
        assert_eq!(heat_color(1.0), [255, 230, 40]);
        assert_eq!(heat_color(50.0), [255, 230, 40]);
        // Monotone brightness along the ramp.
        let lum = |c: [u8; 3]| u32::from(c[0]) + u32::from(c[1]) + u32::from(c[2]);
        let mut last = 0;
        for e in -7..=0 {
            let l = lum(heat_color(10f64.powi(e)));
            assert!(l >= last, "{e}");
            last = l;
        }
        let outcomes = [
            RayOutcome::NoHit,
            RayOutcome::Missed,
            RayOutcome::NoHit,
            RayOutcome::Both {
                abs_dt_cells: 1.0,
                same_surface: true,
            },
            RayOutcome::NoHit,
            RayOutcome::NoHit,
            RayOutcome::NoHit,
            RayOutcome::NoHit,
            RayOutcome::NoHit,
            RayOutcome::NoHit,
            RayOutcome::NoHit,
            RayOutcome::NoHit,
            RayOutcome::NoHit,
            RayOutcome::NoHit,
            RayOutcome::NoHit,
            RayOutcome::False,
        ];
        let img = difference_image(&outcomes, 4, 4);
        // The missed mark covers its 3×3 neighbourhood, clipped at the border.
        assert_eq!(img.get_pixel(0, 0).0, MISSED);
        assert_eq!(img.get_pixel(2, 1).0, MISSED);
        assert_eq!(img.get_pixel(3, 0).0, heat_color(1.0));
        assert_eq!(img.get_pixel(3, 3).0, FALSE_HIT);
        assert_eq!(img.get_pixel(0, 3).0, NO_HIT);
    }

    #[test]
    fn blocks_keep_their_worst_ray() {
        assert_eq!(image_block([1024, 1024]), 4);
        assert_eq!(image_block([48, 48]), 1);
        assert_eq!(image_block([257, 10]), 2);
        let both = |dt: f64| RayOutcome::Both {
            abs_dt_cells: dt,
            same_surface: true,
        };
        // 3×2 rays in blocks of 2: [0..2)×[0..2) and the cut block [2..3)×[0..2).
        let outcomes = [
            both(1e-6),
            RayOutcome::Missed,
            both(1e-3),
            RayOutcome::NoHit,
            both(0.5),
            RayOutcome::NoHit,
        ];
        let (worst, w, h) = worst_per_block(&outcomes, 3, 2, 2);
        assert_eq!((w, h), (2, 1));
        assert_eq!(worst, vec![RayOutcome::Missed, both(1e-3)]);
        let (worst, ..) = worst_per_block(&[both(1e-6), both(0.5), RayOutcome::NoHit], 3, 1, 3);
        assert_eq!(worst, vec![both(0.5)]);
    }

    #[test]
    fn civil_date_is_plausible() {
        let d = utc_now();
        assert_eq!(d.len(), 16, "{d}");
        assert!(d.starts_with("20"), "{d}");
    }
}
