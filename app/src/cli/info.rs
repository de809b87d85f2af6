//! `isoscope info FILE [--json]`: geometry, voxel type, value range, time steps and a histogram
//! for volumes; tets, points, bounds and every point array's value range for tetrahedral
//! meshes; geometry, levels and treelets for `.isot` files.
//!
//! The `--json` output is a stable interface (documented in `docs/cli.md`): [`InfoReport`]
//! (volumes, `"kind": "grid"`), [`MeshInfoReport`] (`"kind": "tet"`) and [`IsotInfoReport`]
//! (`"kind": "isot"`) are serialized as they are, so renaming a field is a breaking change.
//! Value ranges, non-finite counts and the histogram cover every time step of a series (a
//! pass over the steps, with a progress bar when that takes a while).

use std::path::{Path, PathBuf};

use anyhow::{Context as _, bail};
use formats::mesh::MeshSeries;
use serde::Serialize;
use volume_core::series::TimeSeries;
use volume_core::stats::ValueStats;
use volume_core::{AxisCoords, RectilinearVolume, VoxelType};

use super::open_args::OpenArgs;
use crate::progress::Progress;
use crate::scene::{SceneKind, detect_kind};
use crate::values::ValueFormat;

/// Number of histogram bins.
pub const HISTOGRAM_BINS: usize = 64;

/// Arguments of `isoscope info`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Volume file: .nrrd/.nhdr, .nii/.nii.gz, .hdr/.img (NIfTI pair, Analyze), .mha/.mhd,
    /// .vti, a legacy .vtk image, .tif/.tiff (or numbered 2D slices such as 'slice_*.tif'),
    /// DICOM (a folder, a DICOMDIR, a .dcm file and its series: lists the series), a raw file
    /// (with the raw flags or a NAME.json sidecar), a time series pattern such as
    /// vol_%03d.nrrd or 'vol_*.nrrd'; a tetrahedral mesh (.vtk, .vtu, .msh, .node/.ele, .pvd,
    /// or a pattern such as step_%03d.vtu); or an .isot file.
    pub file: PathBuf,
    /// Print machine-readable JSON (a stable interface, see docs/cli.md).
    #[arg(long)]
    pub json: bool,
    #[command(flatten)]
    pub open: OpenArgs,
}

/// Histogram of the finite values over `[lo, hi]` (the value range), equal-width bins, the
/// last bin closed.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct HistogramReport {
    pub lo: f64,
    pub hi: f64,
    pub counts: Vec<u64>,
}

/// What `info` reports for a volume; the `--json` schema.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct InfoReport {
    /// The path as given.
    pub file: String,
    /// `"grid"`.
    pub kind: String,
    /// Samples per axis `[x, y, z]`, x fastest.
    pub dims: [usize; 3],
    /// `"u8"`, `"i8"`, `"u16"`, `"i16"`, `"u32"`, `"i32"`, `"f32"` or `"f64"`.
    pub voxel_type: VoxelType,
    /// Uniform sample spacing per axis (grid frame), or `null` when an axis has explicit
    /// coordinates (then see `coordinates`).
    pub spacing: Option<[f64; 3]>,
    /// Per-axis sample coordinates when any axis is not uniform, else `null`.
    pub coordinates: Option<[Vec<f64>; 3]>,
    /// Grid-frame position of voxel (0, 0, 0).
    pub origin: [f64; 3],
    /// Grid-frame position of the last voxel (`origin + (dims − 1)·spacing` when uniform).
    pub extent_max: [f64; 3],
    /// The grid-to-world affine of oriented data as 3 rows `[m0, m1, m2, t]`, or `null` for the
    /// identity (world = grid frame).
    pub world_from_grid: Option<[[f64; 4]; 3]>,
    /// What the world axes mean: `"RAS"`, `"LPS"` or `"unknown"`.
    pub world_frame: String,
    /// The anatomical direction each grid axis points to, e.g. `["L", "P", "S"]`; `null` when
    /// the world frame is unknown.
    pub axis_labels: Option<[String; 3]>,
    /// Stored → physical values (`physical = slope · stored + intercept`): `null` when the
    /// file stores physical values. Value ranges and the histogram are physical.
    pub value_map: Option<volume_core::ValueMap>,
    /// Smallest and largest finite value over all steps, `null` if no voxel is finite.
    pub value_range: Option<[f64; 2]>,
    pub nan_count: u64,
    /// Count of `+inf` and `−inf` voxels.
    pub inf_count: u64,
    /// Voxels per step.
    pub voxel_count: u64,
    /// 1 for a single volume.
    pub time_steps: usize,
    /// Time of each step (the step index when the file records none).
    pub time_values: Vec<f64>,
    /// `null` when no voxel is finite.
    pub histogram: Option<HistogramReport>,
    /// True when the voxels are viewed in place in a memory-mapped file (no copy).
    pub memory_mapped: bool,
    /// VTK image data: the scalar point arrays `--field` can choose (empty for other files).
    pub arrays: Vec<String>,
    /// VTK image data: the array reported (and drawn by default); `null` for other files.
    pub array: Option<String>,
    /// DICOM inputs: every series in the input (`null` for other files).
    pub dicom_series: Option<Vec<formats::dicom::SeriesSummary>>,
    /// DICOM inputs: the `index` of the series opened (`null` for other files).
    pub dicom_opened: Option<usize>,
    /// DICOM inputs: files that are not part of any series, and why.
    pub dicom_skipped: Option<Vec<formats::dicom::SkippedFile>>,
}

/// What `info` reports for a DICOM input of several series when none is picked
/// (`"kind": "dicom"`): the list to pick from with `--series`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct DicomListReport {
    /// The path as given.
    pub file: String,
    /// `"dicom"`.
    pub kind: String,
    pub dicom_series: Vec<formats::dicom::SeriesSummary>,
    pub dicom_skipped: Vec<formats::dicom::SkippedFile>,
}

/// The source of the steps: one volume or a lazily loaded series.
enum Steps<'a> {
    One(&'a RectilinearVolume),
    Series(&'a TimeSeries),
}

impl Steps<'_> {
    fn count(&self) -> usize {
        match self {
            Steps::One(_) => 1,
            Steps::Series(s) => s.step_count(),
        }
    }

    /// Step `step`; an error names the series (`path`) as well as the step's own file.
    fn get(&self, step: usize, path: &Path) -> anyhow::Result<RectilinearVolume> {
        match self {
            Steps::One(v) => Ok((*v).clone()),
            Steps::Series(s) => s
                .step(step)
                .with_context(|| format!("{}: loading time step {step}", path.display())),
        }
    }
}

fn merge(a: ValueStats, b: ValueStats) -> ValueStats {
    let finite_range = match (a.finite_range, b.finite_range) {
        (Some((a0, a1)), Some((b0, b1))) => Some((a0.min(b0), a1.max(b1))),
        (x, None) | (None, x) => x,
    };
    ValueStats {
        finite_range,
        nan_count: a.nan_count + b.nan_count,
        pos_inf_count: a.pos_inf_count + b.pos_inf_count,
        neg_inf_count: a.neg_inf_count + b.neg_inf_count,
        count: a.count + b.count,
    }
}

/// Opens `path` and gathers the report.
pub fn gather(path: &Path, options: &formats::OpenOptions) -> anyhow::Result<InfoReport> {
    let (arrays, array) = if formats::vtk_image::is_image_file(path) {
        let a = formats::vtk_image::point_arrays(path)?;
        let chosen = options
            .field
            .clone()
            .or_else(|| a.default_name().map(str::to_owned));
        (a.scalar_names(), chosen)
    } else {
        (Vec::new(), None)
    };
    let dataset = {
        let _spinner = Progress::spinner(format!("opening {}", path.display()));
        formats::open(path, options)?
    };
    let mut report = volume_report(path, &dataset)?;
    report.arrays = arrays;
    report.array = array;
    Ok(report)
}

/// The report of a dataset already open (a file, or a volume made in memory); `path` names
/// it in the report and in errors. `arrays` and `array` are left empty.
pub fn volume_report(path: &Path, dataset: &formats::Dataset) -> anyhow::Result<InfoReport> {
    let (first, steps) = match dataset {
        formats::Dataset::Volume(v) => (v, Steps::One(v)),
        formats::Dataset::Series(s) => (s.first(), Steps::Series(s)),
    };
    let grid = &first.grid;
    let n = steps.count();

    // Pass 1: value range and non-finite counts.
    let mut stats: Option<ValueStats> = None;
    {
        let progress = Progress::bar(n as u64, "value range");
        for s in 0..n {
            let v = if s == 0 {
                first.clone()
            } else {
                steps.get(s, path)?
            };
            let st = v.value_stats();
            stats = Some(stats.map_or(st, |acc| merge(acc, st)));
            progress.inc(1);
        }
    }
    let stats = stats.context("no time steps")?;

    // Pass 2: histogram over the finite range.
    let histogram = match stats.finite_range {
        None => None,
        Some((lo, hi)) => {
            let progress = Progress::bar(n as u64, "histogram");
            let mut counts = vec![0u64; HISTOGRAM_BINS];
            for s in 0..n {
                let v = if s == 0 {
                    first.clone()
                } else {
                    steps.get(s, path)?
                };
                let h = v.histogram(lo, hi, HISTOGRAM_BINS);
                counts.iter_mut().zip(&h.counts).for_each(|(c, x)| *c += x);
                progress.inc(1);
            }
            Some(HistogramReport { lo, hi, counts })
        }
    };

    let coordinates = if grid.uniform_spacing().is_some() {
        None
    } else {
        Some([0, 1, 2].map(|a| {
            let axis: &AxisCoords = grid.axis(a);
            (0..grid.dims()[a]).map(|i| axis.coord(i)).collect()
        }))
    };
    let (lo, hi) = grid.grid_bounds();
    let world_from_grid = grid.world_from_grid().map(|m| {
        [0, 1, 2].map(|r| {
            [
                m.matrix3.col(0)[r],
                m.matrix3.col(1)[r],
                m.matrix3.col(2)[r],
                m.translation[r],
            ]
        })
    });
    let time_values = (0..n)
        .map(|s| match &steps {
            Steps::One(_) => 0.0,
            Steps::Series(ts) => ts.time_value(s),
        })
        .collect();
    Ok(InfoReport {
        file: path.display().to_string(),
        kind: SceneKind::Grid.name().to_string(),
        dims: grid.dims(),
        voxel_type: first.data.voxel_type(),
        spacing: grid.uniform_spacing(),
        coordinates,
        origin: lo.to_array(),
        extent_max: hi.to_array(),
        world_from_grid,
        world_frame: grid.world_frame().name().to_string(),
        axis_labels: grid.axis_letters().map(|l| l.map(String::from)),
        value_map: (!first.value_map.is_identity()).then_some(first.value_map),
        value_range: stats.finite_range.map(|(a, b)| [a, b]),
        nan_count: stats.nan_count,
        inf_count: stats.pos_inf_count + stats.neg_inf_count,
        voxel_count: grid.voxel_count() as u64,
        time_steps: n,
        time_values,
        histogram,
        memory_mapped: first.data.is_shared(),
        arrays: Vec::new(),
        array: None,
        dicom_series: None,
        dicom_opened: None,
        dicom_skipped: None,
    })
}

/// The text list of DICOM series (and skipped files).
pub fn render_dicom_text(
    series: &[formats::dicom::SeriesSummary],
    skipped: &[formats::dicom::SkippedFile],
    opened: Option<usize>,
) -> String {
    use std::fmt::Write as _;
    let mut out = String::new();
    let _ = writeln!(out, "DICOM series: {}", series.len());
    for s in series {
        let mark = if Some(s.index) == opened { "*" } else { " " };
        let _ = writeln!(
            out,
            "{mark}{:>3}  {:<3} {:>4} x {:>4} x {:>4}{}  {:>3} file{}  {:<4} {}{}{}",
            s.index,
            s.modality,
            s.dims[0],
            s.dims[1],
            s.dims[2],
            if s.phases > 1 {
                format!(" x {} phases", s.phases)
            } else {
                String::new()
            },
            s.files,
            if s.files == 1 { " " } else { "s" },
            s.voxel_type,
            if s.description.is_empty() {
                "(no description)"
            } else {
                &s.description
            },
            s.number.map(|n| format!("  #{n}")).unwrap_or_default(),
            s.part.map(|p| format!("  (part {p})")).unwrap_or_default(),
        );
        let _ = writeln!(out, "       uid {}  {}", s.uid, s.transfer_syntax);
        if let Some(p) = &s.problem {
            let _ = writeln!(out, "       cannot open: {p}");
        }
    }
    if !skipped.is_empty() {
        let _ = writeln!(out, "skipped files: {}", skipped.len());
        for f in skipped.iter().take(20) {
            let _ = writeln!(out, "  {}: {}", f.path.display(), f.reason);
        }
        if skipped.len() > 20 {
            let _ = writeln!(out, "  ... and {} more", skipped.len() - 20);
        }
    }
    out
}

fn fmt3(v: [f64; 3]) -> String {
    format!("{}, {}, {}", v[0], v[1], v[2])
}

/// Mesh points are `f32`: printed as they read.
fn fmt3_f32(v: [f64; 3]) -> String {
    let f = ValueFormat::F32;
    format!("{}, {}, {}", f.value(v[0]), f.value(v[1]), f.value(v[2]))
}

fn human_bytes(bytes: u64) -> String {
    const UNITS: [&str; 5] = ["B", "KiB", "MiB", "GiB", "TiB"];
    let mut x = bytes as f64;
    let mut u = 0;
    while x >= 1024.0 && u + 1 < UNITS.len() {
        x /= 1024.0;
        u += 1;
    }
    if u == 0 {
        format!("{bytes} B")
    } else {
        format!("{x:.1} {}", UNITS[u])
    }
}

/// The human-readable form of the report.
pub fn render_text(r: &InfoReport) -> String {
    use std::fmt::Write as _;
    let mut out = String::new();
    let bytes = r.voxel_count * r.voxel_type.size_bytes() as u64;
    let _ = writeln!(out, "file:         {}", r.file);
    let _ = writeln!(
        out,
        "dims:         {} x {} x {}  ({} voxels, {} per step)",
        r.dims[0],
        r.dims[1],
        r.dims[2],
        r.voxel_count,
        human_bytes(bytes)
    );
    let _ = writeln!(
        out,
        "voxel type:   {}{}",
        r.voxel_type,
        if r.memory_mapped {
            "  (memory-mapped, not copied)"
        } else {
            ""
        }
    );
    match (&r.spacing, &r.coordinates) {
        (Some(s), _) => {
            let _ = writeln!(out, "spacing:      {}", fmt3(*s));
        }
        (None, Some(c)) => {
            for (a, name) in ["x", "y", "z"].iter().enumerate() {
                let axis = &c[a];
                let _ = writeln!(
                    out,
                    "coordinates {name}: {} samples, {} .. {} (explicit)",
                    axis.len(),
                    axis.first().copied().unwrap_or(f64::NAN),
                    axis.last().copied().unwrap_or(f64::NAN)
                );
            }
        }
        (None, None) => {}
    }
    let _ = writeln!(out, "origin:       {}", fmt3(r.origin));
    let _ = writeln!(
        out,
        "extent:       {} .. {}",
        fmt3(r.origin),
        fmt3(r.extent_max)
    );
    match &r.world_from_grid {
        None => {
            let _ = writeln!(out, "orientation:  axis-aligned (world = grid frame)");
        }
        Some(m) => {
            let _ = writeln!(out, "orientation:  world_from_grid =");
            for row in m {
                let _ = writeln!(
                    out,
                    "              [{:>10.6} {:>10.6} {:>10.6} | {:>12.6}]",
                    row[0], row[1], row[2], row[3]
                );
            }
        }
    }
    match &r.axis_labels {
        Some([i, j, k]) => {
            let _ = writeln!(
                out,
                "world frame:  {}  (+i → {i}, +j → {j}, +k → {k})",
                r.world_frame
            );
        }
        None => {
            let _ = writeln!(out, "world frame:  {}", r.world_frame);
        }
    }
    if let Some(a) = &r.array {
        let _ = writeln!(
            out,
            "array:        {a}  (of {}; choose with --field)",
            r.arrays.join(", ")
        );
    }
    if let Some(m) = &r.value_map {
        let _ = writeln!(
            out,
            "values:       physical = {} · stored + {}  (voxels kept as {})",
            m.slope, m.intercept, r.voxel_type
        );
    }
    let values = ValueFormat::of(r.voxel_type, r.value_map.as_ref());
    match r.value_range {
        Some([lo, hi]) => {
            let _ = writeln!(
                out,
                "value range:  {} .. {}  (finite values)",
                values.value(lo),
                values.value(hi)
            );
        }
        None => {
            let _ = writeln!(out, "value range:  none (no finite voxel)");
        }
    }
    if r.voxel_type.is_float() {
        let _ = writeln!(
            out,
            "non-finite:   {} NaN (void), {} infinite",
            r.nan_count, r.inf_count
        );
    }
    if r.time_steps == 1 {
        let _ = writeln!(out, "time steps:   1");
    } else {
        let first = r.time_values.first().copied().unwrap_or(0.0);
        let last = r.time_values.last().copied().unwrap_or(0.0);
        let _ = writeln!(
            out,
            "time steps:   {} (t = {first} .. {last})",
            r.time_steps
        );
    }
    if let Some(h) = &r.histogram {
        let bins = h.counts.len();
        let width = (h.hi - h.lo) / bins as f64;
        let max = h.counts.iter().copied().max().unwrap_or(0);
        let scale = if max > 0 { (max as f64).ln_1p() } else { 1.0 };
        let _ = writeln!(
            out,
            "histogram:    {bins} bins over the value range (bar length ~ log(1 + count))"
        );
        for (b, &c) in h.counts.iter().enumerate() {
            let lo = values.edge(h.lo + b as f64 * width, width);
            let bar = ((c as f64).ln_1p() / scale * 40.0).round() as usize;
            let _ = writeln!(out, "  {lo:>12} | {:<40} {c}", "#".repeat(bar));
        }
    }
    out
}

/// One point array of a mesh.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ArrayReport {
    pub name: String,
    /// Smallest and largest non-NaN value over all steps, `null` if there is none.
    pub value_range: Option<[f64; 2]>,
    /// NaN values (void data) over all steps.
    pub nan_count: u64,
}

/// What `info` reports for a tetrahedral mesh (`"kind": "tet"`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MeshInfoReport {
    /// The path as given.
    pub file: String,
    /// `"tet"`.
    pub kind: String,
    /// Tetrahedra after splitting hexahedra, wedges and pyramids.
    pub tets: usize,
    pub points: usize,
    /// Cells in the file before splitting and skipping.
    pub source_cells: usize,
    /// Non-volume cells that were skipped (vertices, lines, triangles, ...).
    pub skipped_cells: usize,
    /// Names of the scalar point arrays, in file order (`--field` takes one of them).
    pub arrays: Vec<String>,
    /// Each array's value range.
    pub array_ranges: Vec<ArrayReport>,
    /// Point arrays that are not scalar fields (vectors, tensors): `"name: why"`.
    pub skipped_arrays: Vec<String>,
    /// Bounds of the points of the first step: `[[x0, y0, z0], [x1, y1, z1]]`.
    pub bounds: [[f64; 3]; 2],
    /// 1 for a single mesh.
    pub time_steps: usize,
    /// Time of each step (from the .pvd; the step index otherwise).
    pub time_values: Vec<f64>,
}

/// What `info` reports for an `.isot` out-of-core file (`"kind": "isot"`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct IsotInfoReport {
    pub file: String,
    /// `"isot"`.
    pub kind: String,
    pub dims: [u64; 3],
    pub voxel_type: VoxelType,
    /// Uniform sample spacing, `null` for explicit coordinates.
    pub spacing: Option<[f64; 3]>,
    /// Grid-frame positions of the first and last voxel.
    pub origin: [f64; 3],
    pub extent_max: [f64; 3],
    /// The finite value range recorded in the file (the min/max quantizer's range), physical
    /// (through `value_map`).
    pub value_range: Option<[f64; 2]>,
    /// Stored → physical values (`physical = slope · stored + intercept`), `null` when the
    /// treelets store physical values (and for version-1 files).
    pub value_map: Option<volume_core::ValueMap>,
    /// What the world axes mean: `"RAS"`, `"LPS"` or `"unknown"` (version-1 files).
    pub world_frame: String,
    pub voxel_count: u64,
    /// Treelet levels (LOD levels; the last is the full resolution).
    pub levels: usize,
    pub treelet_height: u32,
    pub treelets: u64,
    /// Bits per quantized min/max code.
    pub quantizer_bits: u32,
    /// The file's format version.
    pub format_version: u32,
    /// Whether the file's tree splits its nodes as the in-core tree of its grid does (along
    /// their longest world axis); files before version 3 halve them in cells, which differs
    /// on anisotropic voxels.
    pub tree_as_in_core: bool,
    pub file_bytes: u64,
}

/// Any of the reports (serialized without a wrapper: see each `kind`).
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(untagged)]
#[allow(clippy::large_enum_variant)] // one value per run
pub enum AnyInfo {
    Grid(InfoReport),
    Tet(MeshInfoReport),
    Isot(IsotInfoReport),
    /// A DICOM input of several series, none picked.
    Dicom(DicomListReport),
}

/// Reads `path` as a mesh (a single file, a `.pvd` or a pattern) and gathers the report.
pub fn gather_mesh(path: &Path) -> anyhow::Result<MeshInfoReport> {
    let is_pvd = formats::mesh::MeshFormat::from_path(path) == Some(formats::mesh::MeshFormat::Pvd);
    let series = if is_pvd {
        Some(formats::mesh::read_pvd(path)?)
    } else if !path.exists() && formats::series::is_pattern(path) {
        Some(MeshSeries::from_files(formats::series::expand_pattern(
            path,
        )?))
    } else {
        None
    };
    let first = {
        let _spinner = Progress::spinner(format!("reading {}", path.display()));
        match &series {
            Some(s) => s.load_step(0)?,
            None => formats::mesh::read_mesh(path)?,
        }
    };
    mesh_report(path, &first, series.as_ref())
}

/// The report of a mesh already read (from a file, or made in memory) with its series, if
/// any; `path` names it in the report and in errors.
pub fn mesh_report(
    path: &Path,
    first: &formats::mesh::LoadedMesh,
    series: Option<&MeshSeries>,
) -> anyhow::Result<MeshInfoReport> {
    let mesh = &first.mesh;
    let steps = series.map_or(1, MeshSeries::len);
    let mut ranges: Vec<ArrayReport> = mesh
        .fields
        .iter()
        .map(|f| ArrayReport {
            name: f.name.clone(),
            value_range: None,
            nan_count: 0,
        })
        .collect();
    let mut add = |fields: &[volume_core::tet::PointField]| {
        for r in &mut ranges {
            let Some(f) = fields.iter().find(|f| f.name == r.name) else {
                continue;
            };
            r.nan_count += f.values.iter().filter(|v| v.is_nan()).count() as u64;
            if let Some((lo, hi)) = f.value_range() {
                let (lo, hi) = (f64::from(lo), f64::from(hi));
                r.value_range = Some(match r.value_range {
                    Some([a, b]) => [a.min(lo), b.max(hi)],
                    None => [lo, hi],
                });
            }
        }
    };
    add(&mesh.fields);
    if let Some(s) = series {
        let progress = Progress::bar(steps as u64, "value ranges");
        progress.inc(1);
        for i in 1..steps {
            let d = s
                .load_step_data(i, mesh)
                .with_context(|| format!("time step {i} of {}", path.display()))?;
            add(&d.fields);
            progress.inc(1);
        }
    }
    let b = mesh.bounds();
    let bounds = if mesh.points.is_empty() {
        [[0.0; 3]; 2]
    } else {
        [b.min.as_dvec3().to_array(), b.max.as_dvec3().to_array()]
    };
    Ok(MeshInfoReport {
        file: path.display().to_string(),
        kind: SceneKind::Tet.name().to_string(),
        tets: mesh.num_tets(),
        points: mesh.num_points(),
        source_cells: first.source_cells,
        skipped_cells: first.skipped.total(),
        arrays: mesh.fields.iter().map(|f| f.name.clone()).collect(),
        array_ranges: ranges,
        skipped_arrays: first
            .skipped_arrays
            .iter()
            .map(|(n, why)| format!("{n}: {why}"))
            .collect(),
        bounds,
        time_steps: steps,
        time_values: match series {
            Some(s) => s.steps.iter().map(|st| st.time).collect(),
            None => vec![0.0],
        },
    })
}

/// Opens `path` as an `.isot` file (header, level table and file length are checked) and
/// gathers the report.
pub fn gather_isot(path: &Path) -> anyhow::Result<IsotInfoReport> {
    use volume_core::ooc::TreeletStorage as _;
    let file = formats::treelet::IsotFile::open(path)?;
    let meta = file.meta();
    let (lo, hi) = meta.grid.grid_bounds();
    let q = &meta.quantizer;
    Ok(IsotInfoReport {
        file: path.display().to_string(),
        kind: SceneKind::Ooc.name().to_string(),
        dims: meta.layout.dims(),
        voxel_type: meta.voxel_type,
        spacing: meta.grid.uniform_spacing(),
        origin: lo.to_array(),
        extent_max: hi.to_array(),
        value_range: (q.lo.is_finite() && q.hi.is_finite() && q.lo <= q.hi).then(|| {
            let (lo, hi) = meta.value_map.range_to_physical((q.lo, q.hi));
            [lo, hi]
        }),
        value_map: (!meta.value_map.is_identity()).then_some(meta.value_map),
        world_frame: meta.grid.world_frame().name().to_string(),
        voxel_count: meta.layout.voxel_count(),
        levels: meta.layout.level_count(),
        treelet_height: meta.layout.treelet_height(),
        treelets: meta.layout.treelet_count(),
        quantizer_bits: q.bits,
        format_version: file.version(),
        tree_as_in_core: volume_core::ooc::TreeletLayout::for_grid(
            &meta.grid,
            meta.layout.treelet_height(),
        )
        .is_ok_and(|in_core| in_core == meta.layout),
        file_bytes: std::fs::metadata(path)
            .with_context(|| format!("cannot read {}", path.display()))?
            .len(),
    })
}

/// The text form of a mesh report.
pub fn render_mesh_text(r: &MeshInfoReport) -> String {
    use std::fmt::Write as _;
    let mut out = String::new();
    let _ = writeln!(out, "file:         {}", r.file);
    let _ = writeln!(out, "kind:         tetrahedral mesh");
    let _ = writeln!(
        out,
        "tets:         {} (from {} cells in the file; hexahedra, wedges and pyramids split)",
        r.tets, r.source_cells
    );
    if r.skipped_cells > 0 {
        let _ = writeln!(out, "skipped:      {} non-volume cells", r.skipped_cells);
    }
    let _ = writeln!(out, "points:       {}", r.points);
    let _ = writeln!(
        out,
        "bounds:       {} .. {}",
        fmt3_f32(r.bounds[0]),
        fmt3_f32(r.bounds[1])
    );
    let _ = writeln!(
        out,
        "arrays:       {} scalar point arrays (draw one with --field NAME)",
        r.arrays.len()
    );
    let width = r.arrays.iter().map(String::len).max().unwrap_or(0);
    for a in &r.array_ranges {
        let range = a.value_range.map_or_else(
            || "no finite value".to_string(),
            |[lo, hi]| {
                let f = ValueFormat::F32;
                format!("{} .. {}", f.value(lo), f.value(hi))
            },
        );
        let nan = if a.nan_count > 0 {
            format!("  ({} NaN)", a.nan_count)
        } else {
            String::new()
        };
        let _ = writeln!(out, "  {:<width$}  {range}{nan}", a.name);
    }
    for s in &r.skipped_arrays {
        let _ = writeln!(out, "  (not a scalar array: {s})");
    }
    if r.time_steps == 1 {
        let _ = writeln!(out, "time steps:   1");
    } else {
        let first = r.time_values.first().copied().unwrap_or(0.0);
        let last = r.time_values.last().copied().unwrap_or(0.0);
        let _ = writeln!(
            out,
            "time steps:   {} (t = {first} .. {last})",
            r.time_steps
        );
    }
    out
}

/// The text form of an `.isot` report.
pub fn render_isot_text(r: &IsotInfoReport) -> String {
    use std::fmt::Write as _;
    let mut out = String::new();
    let _ = writeln!(out, "file:         {}", r.file);
    let _ = writeln!(
        out,
        "kind:         out-of-core treelet file (.isot), {}",
        human_bytes(r.file_bytes)
    );
    let _ = writeln!(
        out,
        "dims:         {} x {} x {}  ({} voxels)",
        r.dims[0], r.dims[1], r.dims[2], r.voxel_count
    );
    let _ = writeln!(out, "voxel type:   {}", r.voxel_type);
    if let Some(s) = r.spacing {
        let _ = writeln!(out, "spacing:      {}", fmt3(s));
    }
    let _ = writeln!(
        out,
        "extent:       {} .. {}",
        fmt3(r.origin),
        fmt3(r.extent_max)
    );
    let _ = writeln!(out, "world frame:  {}", r.world_frame);
    if let Some(m) = &r.value_map {
        let _ = writeln!(
            out,
            "values:       physical = {} · stored + {}  (treelets keep {})",
            m.slope, m.intercept, r.voxel_type
        );
    }
    let values = ValueFormat::of(r.voxel_type, r.value_map.as_ref());
    match r.value_range {
        Some([lo, hi]) => {
            let _ = writeln!(
                out,
                "value range:  {} .. {}",
                values.value(lo),
                values.value(hi)
            );
        }
        None => {
            let _ = writeln!(out, "value range:  none (no finite voxel)");
        }
    }
    let _ = writeln!(
        out,
        "treelets:     {} in {} levels, height {}, min/max in {} bits",
        r.treelets, r.levels, r.treelet_height, r.quantizer_bits
    );
    let tree = if r.tree_as_in_core {
        "as in core: each level splits its nodes' longest world axis"
    } else {
        // Files before version 3 halve nodes in cells.
        "halved in cells, not as in core (preprocess the source again: faster on anisotropic \
         voxels)"
    };
    let _ = writeln!(
        out,
        "tree:         {tree} (format version {})",
        r.format_version
    );
    out
}

/// Gathers the report of whatever `path` is.
pub fn gather_any(path: &Path, open: &OpenArgs) -> anyhow::Result<AnyInfo> {
    let kind = detect_kind(path);
    if kind != SceneKind::Grid && open.any() {
        bail!(
            "the raw-file flags (--dims, --type, ...) apply to raw volumes; {} is a {kind} file",
            path.display()
        );
    }
    if kind != SceneKind::Grid && open.field.is_some() {
        bail!(
            "--field chooses the array of VTK image data; info lists every array of a mesh, \
             and {} is a {kind} file",
            path.display()
        );
    }
    Ok(match kind {
        SceneKind::Grid => {
            let options = open.open_options()?;
            let Some(listing) = formats::dicom::list_input(path) else {
                return Ok(AnyInfo::Grid(gather(path, &options)?));
            };
            let listing = listing?;
            let opened = match options.dicom_series.as_deref().map(str::trim) {
                None => listing.default_series,
                Some(pick) => listing
                    .series
                    .iter()
                    .find(|s| s.index.to_string() == pick || s.uid == pick)
                    .map(|s| s.index),
            };
            if options.dicom_series.is_none() && opened.is_none() && listing.series.len() > 1 {
                return Ok(AnyInfo::Dicom(DicomListReport {
                    file: path.display().to_string(),
                    kind: "dicom".into(),
                    dicom_series: listing.series,
                    dicom_skipped: listing.skipped,
                }));
            }
            let mut report = gather(path, &options)?;
            report.dicom_series = Some(listing.series);
            report.dicom_opened = opened;
            report.dicom_skipped = Some(listing.skipped);
            AnyInfo::Grid(report)
        }
        SceneKind::Tet => AnyInfo::Tet(gather_mesh(path)?),
        SceneKind::Ooc => AnyInfo::Isot(gather_isot(path)?),
    })
}

pub fn run(args: &Args) -> anyhow::Result<()> {
    let report = gather_any(&args.file, &args.open)?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        print!(
            "{}",
            match &report {
                AnyInfo::Grid(r) => {
                    let mut text = render_text(r);
                    if let Some(series) = &r.dicom_series {
                        text.push_str(&render_dicom_text(
                            series,
                            r.dicom_skipped.as_deref().unwrap_or_default(),
                            r.dicom_opened,
                        ));
                    }
                    text
                }
                AnyInfo::Tet(r) => render_mesh_text(r),
                AnyInfo::Isot(r) => render_isot_text(r),
                AnyInfo::Dicom(r) => format!(
                    "file:         {}\n{}pass --series N (or a SeriesInstanceUID) to open one: \
                     isoscope info {} --series 1\n",
                    r.file,
                    render_dicom_text(&r.dicom_series, &r.dicom_skipped, None),
                    r.file
                ),
            }
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn report() -> InfoReport {
        InfoReport {
            file: "x.nrrd".into(),
            kind: "grid".into(),
            dims: [2, 3, 4],
            voxel_type: VoxelType::F32,
            spacing: Some([1.0, 2.0, 3.0]),
            coordinates: None,
            origin: [0.0; 3],
            extent_max: [1.0, 4.0, 9.0],
            world_from_grid: None,
            world_frame: "LPS".into(),
            axis_labels: Some(["L", "P", "S"].map(String::from)),
            value_map: Some(volume_core::ValueMap::new(1.0, -1024.0).unwrap()),
            value_range: Some([0.0, 2.0]),
            nan_count: 1,
            inf_count: 0,
            voxel_count: 24,
            time_steps: 1,
            time_values: vec![0.0],
            histogram: Some(HistogramReport {
                lo: 0.0,
                hi: 2.0,
                counts: vec![20, 0, 3],
            }),
            memory_mapped: false,
            arrays: vec!["temperature".into(), "label".into()],
            array: Some("temperature".into()),
            dicom_series: None,
            dicom_opened: None,
            dicom_skipped: None,
        }
    }

    #[test]
    fn json_uses_the_documented_names_and_shapes() {
        let j = serde_json::to_value(report()).unwrap();
        assert_eq!(j["dims"], serde_json::json!([2, 3, 4]));
        assert_eq!(j["voxel_type"], "f32");
        assert_eq!(j["spacing"], serde_json::json!([1.0, 2.0, 3.0]));
        assert!(j["coordinates"].is_null());
        assert!(j["world_from_grid"].is_null());
        assert_eq!(j["world_frame"], "LPS");
        assert_eq!(j["axis_labels"], serde_json::json!(["L", "P", "S"]));
        assert_eq!(j["arrays"], serde_json::json!(["temperature", "label"]));
        assert_eq!(j["array"], "temperature");
        assert_eq!(
            j["value_map"],
            serde_json::json!({"slope": 1.0, "intercept": -1024.0})
        );
        assert_eq!(j["value_range"], serde_json::json!([0.0, 2.0]));
        assert_eq!(j["histogram"]["counts"], serde_json::json!([20, 0, 3]));
        assert_eq!(j["time_steps"], 1);
        assert_eq!(j["file"], "x.nrrd");
        assert_eq!(j["kind"], "grid");
        let any = serde_json::to_value(AnyInfo::Grid(report())).unwrap();
        assert_eq!(any, j, "no wrapper object around the report");
    }

    #[test]
    fn mesh_reports_count_split_tets_and_every_array() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("ball.vtu");
        let mesh = data_samples::tets::tet_mesh(data_samples::tets::TetShape::Ball, 6).unwrap();
        formats::mesh::write_vtu(&p, &mesh, formats::output::Replace::Refuse).unwrap();
        let r = gather_mesh(&p).unwrap();
        assert_eq!(r.tets, mesh.num_tets());
        assert_eq!(r.points, mesh.num_points());
        assert_eq!(r.arrays, ["distance", "gaussians", "moving_gaussian"]);
        let d = mesh.field("distance").unwrap().value_range().unwrap();
        assert_eq!(
            r.array_ranges[0].value_range,
            Some([f64::from(d.0), f64::from(d.1)])
        );
        let t = render_mesh_text(&r);
        assert!(t.contains("gaussians") && t.contains("tets:"), "{t}");
    }

    #[test]
    fn text_has_one_bar_line_per_bin_and_longest_bar_for_the_largest_bin() {
        let t = render_text(&report());
        let bars: Vec<&str> = t.lines().filter(|l| l.contains(" | ")).collect();
        assert_eq!(bars.len(), 3);
        assert!(bars[0].contains(&"#".repeat(40)));
        assert!(!bars[1].contains('#'));
        assert!(t.contains("1 NaN"));
    }
}
