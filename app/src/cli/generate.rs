//! `isoscope generate NAME [--size N|XxYxZ] [--type T] [--steps S] [--encoding raw|gzip] -o FILE.nrrd`
//! and `isoscope generate tet-ball|tet-shell|tet-torus [--tets N | --size N] [--steps S]
//! -o FILE.vtu|FILE.vtk`
//!
//! Writes one of the `data-samples` generators as NRRD, or one of its tetrahedral meshes
//! ([`data_samples::tets`]: a structured grid of `--size` cells per axis on [−1, 1]³, the
//! cells whose centre is inside the shape split into 6 tets each; `--tets N` picks the size
//! that gives about N tets) as VTK XML `.vtu` (appended raw) or legacy binary `.vtk`, with the
//! point arrays `distance`, `gaussians` and `moving_gaussian`. With `--steps S` a mesh is
//! written as a time series: `FILE_000.vtu` ... (the moving Gaussian at each step, the same
//! points and tets) and a ParaView collection `FILE.pvd` that lists them.
//!
//! The volume generators' output: The time series (`blobs`) is written
//! as numbered files `FILE_000.nrrd`, `FILE_001.nrrd`, ... (or the printf pattern given with
//! `-o`, e.g. `-o blobs_%03d.nrrd`), which `formats::open` (and so `isoscope info`) reads back
//! as a series from the pattern. Existing files are not overwritten without `--force`.

use std::path::{Path, PathBuf};

use anyhow::{Context as _, bail};
use data_samples::Generator;
use data_samples::tets::TetShape;
use formats::nrrd::{NrrdEncoding, write_nrrd};
use formats::output::Replace;
use volume_core::tet::{PointField, TetMesh};
use volume_core::{RectilinearVolume, VoxelType};

use super::open_args::parse_voxel_type;
use crate::progress::Progress;

/// NRRD data encoding on the command line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Encoding {
    /// Uncompressed (fast; can be memory-mapped when read).
    Raw,
    /// gzip-compressed (small).
    Gzip,
}

impl From<Encoding> for NrrdEncoding {
    fn from(e: Encoding) -> Self {
        match e {
            Encoding::Raw => NrrdEncoding::Raw,
            Encoding::Gzip => NrrdEncoding::Gzip,
        }
    }
}

/// What `generate` makes: a volume generator or a tetrahedral mesh.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum GenName {
    Volume(Generator),
    Mesh(TetShape),
}

impl std::fmt::Display for GenName {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            GenName::Volume(g) => write!(f, "{g}"),
            GenName::Mesh(m) => write!(f, "{m}"),
        }
    }
}

/// Arguments of `isoscope generate`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Generator: marschner-lobb, sphere, torus, nested-spheres, phantom, blobs (NRRD
    /// volumes); tet-ball, tet-shell, tet-torus (tetrahedral meshes, .vtu or .vtk).
    #[arg(value_parser = parse_name)]
    pub name: GenName,
    /// Samples per axis: N (N³; the phantom keeps its aspect, N×N×0.43N) or XxYxZ.
    /// Default: marschner-lobb 41, phantom 256x256x110, others 64. Meshes: N grid cells per
    /// axis (default: the size for --tets).
    #[arg(long, value_name = "N|XxYxZ", value_parser = parse_size)]
    pub size: Option<Size>,
    /// Meshes: about this many tetrahedra (default 100000).
    #[arg(long, value_name = "N", conflicts_with = "size")]
    pub tets: Option<usize>,
    /// Voxel type (u8, i8, u16, i16, u32, i32, f32, f64). Default: i16 for the phantom,
    /// f32 otherwise. Integer types store a documented linear map of the field (see
    /// data-samples/README.md).
    #[arg(long = "type", value_name = "TYPE", value_parser = parse_voxel_type)]
    pub voxel_type: Option<VoxelType>,
    /// Number of time steps (blobs: default 20; meshes: a moving-Gaussian series with a .pvd).
    #[arg(long, value_name = "S")]
    pub steps: Option<usize>,
    /// NRRD data encoding.
    #[arg(long, value_enum, default_value = "raw")]
    pub encoding: Encoding,
    /// Output file (.nrrd; meshes .vtu or .vtk). For series: FILE.nrrd writes FILE_000.nrrd,
    /// FILE_001.nrrd, ...; a name with a printf pattern (FILE_%03d.nrrd) is used as given.
    /// Mesh series: FILE.vtu writes FILE_000.vtu, ... and FILE.pvd.
    #[arg(short, long, value_name = "FILE")]
    pub output: PathBuf,
    /// Replace existing output files (never an input file).
    #[arg(long)]
    pub force: bool,
    /// Phantom: white Gaussian noise of this standard deviation, in HU (real CT: 10–30).
    #[arg(long, value_name = "HU")]
    pub noise: Option<f64>,
    /// Phantom: partial-volume blur, a Gaussian of this standard deviation in mm (real CT:
    /// about 0.5–1).
    #[arg(long, value_name = "MM")]
    pub blur: Option<f64>,
    /// Phantom: add a scanner table (couch and foam pad) under the head.
    #[arg(long)]
    pub table: bool,
    /// Phantom: seed of the noise.
    #[arg(long, value_name = "N", default_value_t = 1)]
    pub seed: u64,
}

impl Args {
    /// The phantom's options from `--noise`, `--blur`, `--table` and `--seed`.
    fn phantom_options(&self) -> anyhow::Result<data_samples::phantom::PhantomOptions> {
        let check = |flag: &str, v: Option<f64>| -> anyhow::Result<f64> {
            match v {
                Some(x) if !(x.is_finite() && x >= 0.0) => {
                    bail!("{flag} {x}: must be a finite number ≥ 0")
                }
                Some(x) => Ok(x),
                None => Ok(0.0),
            }
        };
        Ok(data_samples::phantom::PhantomOptions {
            noise_hu: check("--noise", self.noise)?,
            blur_mm: check("--blur", self.blur)?,
            table: self.table,
            seed: self.seed,
        })
    }
}

/// `--size`: one size for all axes (generator-specific aspect) or explicit dims.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Size {
    Cube(usize),
    Dims([usize; 3]),
}

fn parse_name(s: &str) -> Result<GenName, String> {
    if let Some(g) = Generator::from_name(s) {
        return Ok(GenName::Volume(g));
    }
    if let Some(m) = TetShape::from_name(s) {
        return Ok(GenName::Mesh(m));
    }
    let names: Vec<&str> = Generator::ALL
        .iter()
        .map(|g| g.name())
        .chain(TetShape::ALL.iter().map(|m| m.name()))
        .collect();
    Err(format!(
        "unknown generator `{s}`: expected one of {}",
        names.join(", ")
    ))
}

fn parse_size(s: &str) -> Result<Size, String> {
    let check = |n: usize| {
        if n < 2 {
            Err(format!("size `{s}`: every axis needs at least 2 samples"))
        } else {
            Ok(n)
        }
    };
    if s.contains(['x', 'X', ',']) {
        let dims = formats::raw::parse_dims(s)?;
        for n in dims {
            check(n)?;
        }
        Ok(Size::Dims(dims))
    } else {
        let n = s
            .trim()
            .parse::<usize>()
            .map_err(|_| format!("size `{s}`: expected a number N or dims XxYxZ"))?;
        Ok(Size::Cube(check(n)?))
    }
}

/// What a run of `generate` wrote.
#[derive(Debug, Clone, PartialEq)]
pub struct Generated {
    pub files: Vec<PathBuf>,
    /// The path to open the result with (the pattern for a series).
    pub open_path: PathBuf,
    pub dims: [usize; 3],
    pub voxel_type: VoxelType,
}

/// The file names of a series written to `output`: `(pattern, files)`.
pub fn series_paths(output: &Path, steps: usize) -> anyhow::Result<(PathBuf, Vec<PathBuf>)> {
    let name = output
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .context("the output path has no file name")?;
    let parent = output.parent().unwrap_or(Path::new(""));
    let (prefix, width, suffix) = if let Some(start) = name.find('%') {
        // A printf pattern: %d or %0Nd.
        let rest = &name[start + 1..];
        let digits = rest
            .find('d')
            .filter(|&e| rest[..e].chars().all(|c| c.is_ascii_digit()));
        let Some(end) = digits else {
            bail!("output pattern `{name}`: only %d or %0Nd (e.g. %03d) is supported");
        };
        let width = rest[..end]
            .trim_start_matches('0')
            .parse::<usize>()
            .unwrap_or(0);
        (
            name[..start].to_string(),
            width,
            rest[end + 1..].to_string(),
        )
    } else {
        let stem = name.strip_suffix(".nrrd").unwrap_or(&name);
        (format!("{stem}_"), 3, ".nrrd".to_string())
    };
    if suffix.contains('%') {
        bail!("output pattern `{name}`: only one % conversion is allowed");
    }
    let conversion = if width == 0 {
        "%d".to_string()
    } else {
        format!("%0{width}d")
    };
    let pattern = parent.join(format!("{prefix}{conversion}{suffix}"));
    let files = (0..steps)
        .map(|s| parent.join(format!("{prefix}{s:0width$}{suffix}")))
        .collect();
    Ok((pattern, files))
}

fn check_output_name(path: &Path) -> anyhow::Result<()> {
    let ok = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("nrrd"));
    if !ok {
        bail!(
            "output `{}` must end in .nrrd (the generators write NRRD files)",
            path.display()
        );
    }
    Ok(())
}

/// What a run of `generate` wrote for a mesh.
#[derive(Debug, Clone, PartialEq)]
pub struct GeneratedMesh {
    pub files: Vec<PathBuf>,
    /// The path to open the result with (the `.pvd` for a series).
    pub open_path: PathBuf,
    /// Grid cells per axis.
    pub cells: usize,
    pub tets: usize,
    pub points: usize,
}

/// Default target tet count of the mesh generators.
pub const DEFAULT_TETS: usize = 100_000;

/// Generates and writes a tetrahedral mesh (or a series of them).
pub fn generate_mesh(args: &Args, shape: TetShape) -> anyhow::Result<GeneratedMesh> {
    if args.voxel_type.is_some() {
        bail!("--type applies to volumes; {shape} writes f32 point arrays");
    }
    if args.encoding != Encoding::Raw {
        bail!("--encoding applies to NRRD volumes; meshes are written as VTK files");
    }
    let cells = match (args.size, args.tets) {
        (Some(Size::Cube(n)), _) => n,
        (Some(Size::Dims(_)), _) => {
            bail!("--size for a mesh is one number: grid cells per axis (e.g. --size 40)")
        }
        (None, Some(0)) => bail!("--tets must be at least 1"),
        (None, t) => data_samples::tets::cells_for_tets(shape, t.unwrap_or(DEFAULT_TETS)),
    };
    if cells > 1000 {
        bail!("{cells} cells per axis is too large a mesh (at most 1000, about 3e9 tets)");
    }
    let ext = args
        .output
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase());
    let legacy = match ext.as_deref() {
        Some("vtu") => false,
        Some("vtk") => true,
        _ => bail!(
            "output `{}` must end in .vtu or .vtk (meshes are written as VTK files)",
            args.output.display()
        ),
    };
    let steps = match args.steps {
        Some(0) => bail!("--steps must be at least 1"),
        s => s,
    };
    let (open_path, files) = match steps {
        None => (args.output.clone(), vec![args.output.clone()]),
        Some(n) => {
            let stem = args
                .output
                .file_stem()
                .map(|s| s.to_string_lossy().into_owned())
                .context("the output path has no file name")?;
            let dir = args.output.parent().unwrap_or(Path::new(""));
            let ext = ext.as_deref().unwrap_or("vtu");
            let files: Vec<PathBuf> = (0..n)
                .map(|k| dir.join(format!("{stem}_{k:03}.{ext}")))
                .collect();
            (dir.join(format!("{stem}.pvd")), files)
        }
    };
    let mut all = files.clone();
    if steps.is_some() {
        all.push(open_path.clone());
    }
    let replace = Replace::from_force(args.force);
    for f in &all {
        formats::output::check_output(f, replace)?;
    }
    if let Some(dir) = args.output.parent().filter(|d| !d.as_os_str().is_empty())
        && !dir.is_dir()
    {
        bail!("output directory {} does not exist", dir.display());
    }
    let mesh = {
        let _spinner = Progress::spinner(format!("generating {shape} ({cells} cells per axis)"));
        data_samples::tets::tet_mesh(shape, cells)
            .with_context(|| format!("generating {shape} with {cells} cells per axis"))?
    };
    let write = |path: &Path, m: &TetMesh| -> anyhow::Result<()> {
        if legacy {
            formats::mesh::write_vtk_legacy(
                path,
                m,
                formats::mesh::LegacyEncoding::Binary,
                replace,
            )?;
        } else {
            formats::mesh::write_vtu(path, m, replace)?;
        }
        Ok(())
    };
    match steps {
        None => write(&files[0], &mesh)?,
        Some(n) => {
            let values = data_samples::tets::moving_gaussian_steps(&mesh, n);
            let progress = Progress::bar(n as u64, format!("writing {shape} steps"));
            let mut step_mesh = mesh.clone();
            for (file, v) in files.iter().zip(values) {
                if let Some(f) = step_mesh
                    .fields
                    .iter_mut()
                    .find(|f| f.name == "moving_gaussian")
                {
                    *f = PointField::new("moving_gaussian", v);
                }
                write(file, &step_mesh)?;
                progress.inc(1);
            }
            progress.finish();
            write_pvd(&open_path, &files, replace)?;
        }
    }
    Ok(GeneratedMesh {
        files,
        open_path,
        cells,
        tets: mesh.num_tets(),
        points: mesh.num_points(),
    })
}

/// A ParaView collection listing `files` (relative to the `.pvd`'s folder), time = index.
fn write_pvd(path: &Path, files: &[PathBuf], replace: Replace) -> anyhow::Result<()> {
    use std::fmt::Write as _;
    let mut xml = String::from(
        "<?xml version=\"1.0\"?>\n<VTKFile type=\"Collection\" version=\"0.1\">\n  <Collection>\n",
    );
    for (k, f) in files.iter().enumerate() {
        let name = f
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        let name = name
            .replace('&', "&amp;")
            .replace('"', "&quot;")
            .replace('<', "&lt;");
        let _ = writeln!(
            xml,
            "    <DataSet timestep=\"{k}\" part=\"0\" file=\"{name}\"/>"
        );
    }
    xml.push_str("  </Collection>\n</VTKFile>\n");
    crate::output::save_text(path, &xml, replace)
}

/// Generates and writes a volume; returns what was written.
pub fn generate(args: &Args) -> anyhow::Result<Generated> {
    let g = match args.name {
        GenName::Volume(g) => g,
        GenName::Mesh(m) => bail!("{m} is a mesh: use generate_mesh"),
    };
    if args.tets.is_some() {
        bail!("--tets applies to the mesh generators (tet-ball, tet-shell, tet-torus)");
    }
    let phantom = args.phantom_options()?;
    if g != Generator::Phantom && !phantom.is_smooth() {
        bail!("--noise, --blur and --table apply to the phantom, not {g}");
    }
    let dims = match args.size {
        None => g.default_dims(),
        Some(Size::Cube(n)) => g.dims_for_size(n),
        Some(Size::Dims(d)) => d,
    };
    let voxel_type = args.voxel_type.unwrap_or(g.default_voxel_type());
    let steps = match (args.steps, g.is_series()) {
        (None, _) => g.default_steps(),
        (Some(0), true) => bail!("--steps must be at least 1"),
        (Some(s), true) => s,
        (Some(_), false) => bail!("--steps only applies to time series (blobs), not {g}"),
    };
    let (open_path, files) = if g.is_series() {
        series_paths(&args.output, steps)?
    } else {
        (args.output.clone(), vec![args.output.clone()])
    };
    for f in &files {
        check_output_name(f)?;
    }
    let replace = Replace::from_force(args.force);
    for f in &files {
        formats::output::check_output(f, replace)?;
    }
    if g.is_series() {
        // A leftover step after the last one would silently join the series when read back.
        let (_, more) = series_paths(&args.output, steps + 1)?;
        if let Some(extra) = more.last().filter(|f| f.exists()) {
            bail!(
                "{} exists and would be read as step {steps} of the new series; remove it or choose another output name",
                extra.display()
            );
        }
    }
    if let Some(dir) = args.output.parent().filter(|d| !d.as_os_str().is_empty())
        && !dir.is_dir()
    {
        bail!("output directory {} does not exist", dir.display());
    }

    let progress = Progress::bar((dims[2] * steps) as u64, format!("generating {g}"));
    for (step, file) in files.iter().enumerate() {
        let volume: RectilinearVolume = if phantom.is_smooth() {
            g.generate_step(dims, voxel_type, step, steps, &progress.ticker())
        } else {
            data_samples::phantom::generate_with(dims, voxel_type, &phantom, &progress.ticker())
        }
        .with_context(|| {
            format!(
                "generating {g} {}x{}x{} {voxel_type}",
                dims[0], dims[1], dims[2]
            )
        })?;
        progress.set_message(format!("writing {}", file.display()));
        write_nrrd(file, &volume, args.encoding.into(), replace)?;
        progress.set_message(format!("generating {g}"));
    }
    progress.finish();
    Ok(Generated {
        files,
        open_path,
        dims,
        voxel_type,
    })
}

pub fn run(args: &Args) -> anyhow::Result<()> {
    let g = match args.name {
        GenName::Volume(g) => g,
        GenName::Mesh(shape) => {
            let out = generate_mesh(args, shape)?;
            if out.files.len() == 1 {
                println!("wrote {}", out.open_path.display());
            } else {
                println!(
                    "wrote {} steps: {} .. {} and the collection {}",
                    out.files.len(),
                    out.files[0].display(),
                    out.files[out.files.len() - 1].display(),
                    out.open_path.display()
                );
            }
            println!(
                "{shape}: {} tets, {} points ({} grid cells per axis); point arrays distance, gaussians, moving_gaussian; suggested: --field distance --iso 0.5",
                out.tets, out.points, out.cells
            );
            return Ok(());
        }
    };
    let out = generate(args)?;
    let map = g.value_map(out.voxel_type);
    let isos: Vec<String> = g
        .suggested_isovalues()
        .iter()
        .map(|&v| {
            let stored = map.to_stored(v);
            if out.voxel_type.is_float() {
                format!("{v}")
            } else {
                format!("{} (field value {v})", stored.round())
            }
        })
        .collect();
    if out.files.len() == 1 {
        println!("wrote {}", out.open_path.display());
    } else {
        println!(
            "wrote {} steps: {} .. {}",
            out.files.len(),
            out.files[0].display(),
            out.files[out.files.len() - 1].display()
        );
        println!(
            "open the series with: isoscope info '{}'",
            out.open_path.display()
        );
    }
    println!(
        "{g}: {}x{}x{} {}; suggested isovalue(s): {}",
        out.dims[0],
        out.dims[1],
        out.dims[2],
        out.voxel_type,
        isos.join(", ")
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_parse_and_reject_degenerate_values() {
        assert_eq!(parse_size("41"), Ok(Size::Cube(41)));
        assert_eq!(parse_size("64x64x28"), Ok(Size::Dims([64, 64, 28])));
        assert!(parse_size("0").unwrap_err().contains("at least 2"));
        assert!(parse_size("1").is_err());
        assert!(parse_size("4x1x4").is_err());
        assert!(parse_size("big").unwrap_err().contains("expected a number"));
    }

    #[test]
    fn generator_names_parse_and_errors_list_them() {
        assert_eq!(
            parse_name("phantom"),
            Ok(GenName::Volume(Generator::Phantom))
        );
        let e = parse_name("spheres").unwrap_err();
        assert!(
            e.contains("nested-spheres") && e.contains("marschner-lobb") && e.contains("tet-ball"),
            "{e}"
        );
        assert_eq!(parse_name("tet-torus"), Ok(GenName::Mesh(TetShape::Torus)));
    }

    #[test]
    fn series_paths_number_the_steps() {
        let (p, f) = series_paths(Path::new("out/blobs.nrrd"), 3).unwrap();
        assert_eq!(p, Path::new("out/blobs_%03d.nrrd"));
        assert_eq!(f[2], Path::new("out/blobs_002.nrrd"));
        let (p, f) = series_paths(Path::new("t%d.nrrd"), 11).unwrap();
        assert_eq!(p, Path::new("t%d.nrrd"));
        assert_eq!(f[10], Path::new("t10.nrrd"));
        let (_, f) = series_paths(Path::new("s_%04d.nrrd"), 2).unwrap();
        assert_eq!(f[1], Path::new("s_0001.nrrd"));
        assert!(series_paths(Path::new("s_%s.nrrd"), 2).is_err());
    }
}
