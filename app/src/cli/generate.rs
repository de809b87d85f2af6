//! `isoscope generate NAME [--size N|XxYxZ] [--type T] [--steps S] [--encoding raw|gzip] -o FILE.nrrd`
//!
//! Writes one of the `data-samples` generators as NRRD. The time series (`blobs`) is written
//! as numbered files `FILE_000.nrrd`, `FILE_001.nrrd`, ... (or the printf pattern given with
//! `-o`, e.g. `-o blobs_%03d.nrrd`), which `formats::open` (and so `isoscope info`) reads back
//! as a series from the pattern. Existing files are not overwritten without `--force`.

use std::path::{Path, PathBuf};

use anyhow::{Context as _, bail};
use data_samples::Generator;
use formats::nrrd::{NrrdEncoding, write_nrrd};
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

/// Arguments of `isoscope generate`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Generator: marschner-lobb, sphere, torus, nested-spheres, phantom, blobs.
    #[arg(value_parser = parse_generator)]
    pub name: Generator,
    /// Samples per axis: N (N³; the phantom keeps its aspect, N×N×0.43N) or XxYxZ.
    /// Default: marschner-lobb 41, phantom 256x256x110, others 64.
    #[arg(long, value_name = "N|XxYxZ", value_parser = parse_size)]
    pub size: Option<Size>,
    /// Voxel type (u8, i8, u16, i16, u32, i32, f32, f64). Default: i16 for the phantom,
    /// f32 otherwise. Integer types store a documented linear map of the field (see
    /// data-samples/README.md).
    #[arg(long = "type", value_name = "TYPE", value_parser = parse_voxel_type)]
    pub voxel_type: Option<VoxelType>,
    /// Number of time steps (blobs only; default 20).
    #[arg(long, value_name = "S")]
    pub steps: Option<usize>,
    /// NRRD data encoding.
    #[arg(long, value_enum, default_value = "raw")]
    pub encoding: Encoding,
    /// Output file (.nrrd). For series: FILE.nrrd writes FILE_000.nrrd, FILE_001.nrrd, ...;
    /// a name with a printf pattern (FILE_%03d.nrrd) is used as given.
    #[arg(short, long, value_name = "FILE.nrrd")]
    pub output: PathBuf,
    /// Overwrite existing output files.
    #[arg(long)]
    pub force: bool,
}

/// `--size`: one size for all axes (generator-specific aspect) or explicit dims.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Size {
    Cube(usize),
    Dims([usize; 3]),
}

fn parse_generator(s: &str) -> Result<Generator, String> {
    Generator::from_name(s).ok_or_else(|| {
        let names: Vec<&str> = Generator::ALL.iter().map(|g| g.name()).collect();
        format!(
            "unknown generator `{s}`: expected one of {}",
            names.join(", ")
        )
    })
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

/// Generates and writes; returns what was written.
pub fn generate(args: &Args) -> anyhow::Result<Generated> {
    let g = args.name;
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
    if !args.force
        && let Some(existing) = files.iter().find(|f| f.exists())
    {
        bail!(
            "{} exists; pass --force to overwrite it",
            existing.display()
        );
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
        let volume: RectilinearVolume = g
            .generate_step(dims, voxel_type, step, steps, &progress.ticker())
            .with_context(|| {
                format!(
                    "generating {g} {}x{}x{} {voxel_type}",
                    dims[0], dims[1], dims[2]
                )
            })?;
        progress.set_message(format!("writing {}", file.display()));
        write_nrrd(file, &volume, args.encoding.into())?;
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
    let out = generate(args)?;
    let g = args.name;
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
        assert_eq!(parse_generator("phantom"), Ok(Generator::Phantom));
        let e = parse_generator("spheres").unwrap_err();
        assert!(
            e.contains("nested-spheres") && e.contains("marschner-lobb"),
            "{e}"
        );
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
