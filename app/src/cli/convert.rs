//! `isoscope convert IN -o OUT.nrrd|OUT.nhdr|OUT.nii|OUT.nii.gz [--step N] [--encoding raw|gzip]
//! [--force]`: writes any volume `formats::open` reads (NRRD, NIfTI, Analyze, raw with its
//! flags or sidecar, a series pattern) with its geometry and world frame.
//!
//! - A time series is written whole as a 4D NIfTI, or one step with `--step N` (NRRD holds
//!   one volume: a series to NRRD needs `--step`).
//! - NIfTI output keeps the stored voxels and writes the value map as `scl_slope`/`scl_inter`.
//!   NRRD has no rescale field (`write_nrrd` refuses a scaled volume), so a scaled volume is
//!   written to NRRD as its physical values, in the narrowest voxel type that holds every one
//!   of them exactly ([`physical_volume`]: e.g. `i16` Hounsfield units for slope 1,
//!   intercept −1024), else `f32`; stderr says which.
//! - The input is opened first, so no output can replace a file it reads; outputs are written
//!   through `formats::output` (temporary file, rename; existing files only with `--force`).

use std::path::{Path, PathBuf};

use anyhow::{Context as _, bail};
use formats::Dataset;
use formats::nrrd::{NrrdEncoding, write_nrrd, write_nrrd_detached};
use formats::output::Replace;
use volume_core::{RectilinearVolume, Voxel, VoxelData, VoxelType};

use super::generate::Encoding;
use super::open_args::OpenArgs;
use crate::scene::{SceneKind, detect_kind};

/// Arguments of `isoscope convert`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Input volume: .nrrd/.nhdr, .nii/.nii.gz, .hdr/.img (NIfTI pair or Analyze 7.5), a raw
    /// file (with the raw flags or a NAME.json sidecar), or a series pattern such as
    /// vol_%03d.nrrd.
    pub input: PathBuf,
    /// Output: .nrrd (attached), .nhdr (detached, data in NAME.raw or NAME.raw.gz), .nii or
    /// .nii.gz (NIfTI-1).
    #[arg(short, long, value_name = "OUT")]
    pub output: PathBuf,
    /// Time series: write only this step (0-based). Without it a series is written whole as
    /// a 4D NIfTI.
    #[arg(long, value_name = "N")]
    pub step: Option<usize>,
    /// NRRD data encoding (default raw). NIfTI compression follows the name (.nii.gz).
    #[arg(long, value_enum)]
    pub encoding: Option<Encoding>,
    /// Replace existing output files (never an input file).
    #[arg(long)]
    pub force: bool,
    #[command(flatten)]
    pub open: OpenArgs,
}

/// What `-o` names.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Output {
    Nrrd,
    Nhdr,
    Nifti,
}

impl Output {
    // Lower-cased first.
    #[allow(clippy::case_sensitive_file_extension_comparisons)]
    fn of(path: &Path) -> anyhow::Result<Self> {
        let name = path
            .file_name()
            .map(|n| n.to_string_lossy().to_ascii_lowercase())
            .unwrap_or_default();
        Ok(if name.ends_with(".nrrd") {
            Output::Nrrd
        } else if name.ends_with(".nhdr") {
            Output::Nhdr
        } else if name.ends_with(".nii") || name.ends_with(".nii.gz") {
            Output::Nifti
        } else {
            bail!(
                "{}: the output must be named .nrrd, .nhdr, .nii or .nii.gz",
                path.display()
            )
        })
    }
}

/// How [`physical_volume`] stored the values.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PhysicalType {
    pub voxel_type: VoxelType,
    /// False when some value had to be rounded (non-integers that `f32` does not hold).
    pub exact: bool,
}

/// The physical values of `v` as `T` (rounded and saturated by [`Voxel::from_f64`]).
fn physical_as<T: Voxel>(v: &RectilinearVolume) -> VoxelData
where
    VoxelData: From<Vec<T>>,
{
    let map = v.value_map;
    let out: Vec<T> = volume_core::dispatch_voxels!(&v.data, buf => buf
        .as_slice()
        .iter()
        .map(|&x| T::from_f64(map.to_physical(x.to_f64())))
        .collect());
    out.into()
}

/// The physical values of `volume` (its value map applied) as a volume with the identity
/// map, in the narrowest type that holds every value exactly: the smallest of `u8`, `i8`,
/// `u16`, `i16`, `u32`, `i32` whose range covers them when all are integers; `f64` for
/// integers beyond 32 bits; otherwise `f32` (exact when `f32` holds every value, else
/// rounded). NaN stays NaN (`f32`).
pub fn physical_volume(volume: &RectilinearVolume) -> (RectilinearVolume, PhysicalType) {
    let map = volume.value_map;
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    let (mut integers, mut f32_exact) = (true, true);
    volume_core::dispatch_voxels!(&volume.data, buf => {
        for &x in buf.as_slice() {
            let p = map.to_physical(x.to_f64());
            if p.is_finite() && p.fract() == 0.0 {
                lo = lo.min(p);
                hi = hi.max(p);
            } else {
                integers = false;
            }
            if !p.is_nan() && f64::from(p as f32) != p {
                f32_exact = false;
            }
        }
    });
    let fits = |t: VoxelType| {
        let (min, max) = match t {
            VoxelType::U8 => (0.0, f64::from(u8::MAX)),
            VoxelType::I8 => (f64::from(i8::MIN), f64::from(i8::MAX)),
            VoxelType::U16 => (0.0, f64::from(u16::MAX)),
            VoxelType::I16 => (f64::from(i16::MIN), f64::from(i16::MAX)),
            VoxelType::U32 => (0.0, f64::from(u32::MAX)),
            VoxelType::I32 => (f64::from(i32::MIN), f64::from(i32::MAX)),
            VoxelType::F32 | VoxelType::F64 => return true,
        };
        lo >= min && hi <= max
    };
    let (voxel_type, exact) = if integers {
        let t = [
            VoxelType::U8,
            VoxelType::I8,
            VoxelType::U16,
            VoxelType::I16,
            VoxelType::U32,
            VoxelType::I32,
        ]
        .into_iter()
        .find(|&t| fits(t))
        .unwrap_or(VoxelType::F64);
        (t, true)
    } else {
        (VoxelType::F32, f32_exact)
    };
    let data = volume_core::match_voxel_type!(voxel_type, T => physical_as::<T>(volume));
    let out = RectilinearVolume::new(volume.grid.clone(), data).expect("same voxel count");
    (out, PhysicalType { voxel_type, exact })
}

pub fn run(args: &Args) -> anyhow::Result<()> {
    let replace = Replace::from_force(args.force);
    let output = Output::of(&args.output)?;
    if output == Output::Nifti && args.encoding.is_some() {
        bail!("--encoding applies to NRRD output; NIfTI is compressed when named .nii.gz");
    }
    match detect_kind(&args.input) {
        SceneKind::Grid => {}
        SceneKind::Tet => bail!(
            "{}: convert writes volumes; this is a tetrahedral mesh",
            args.input.display()
        ),
        SceneKind::Ooc => bail!(
            "{}: convert writes volumes; this is an out-of-core .isot file",
            args.input.display()
        ),
    }
    let options = args.open.open_options()?;
    let dataset = formats::open(&args.input, &options)
        .with_context(|| format!("opening {}", args.input.display()))?;
    // After the open, which recorded every file the input reads.
    formats::output::check_output(&args.output, replace)?;
    let encoding = match args.encoding.unwrap_or(Encoding::Raw) {
        Encoding::Raw => NrrdEncoding::Raw,
        Encoding::Gzip => NrrdEncoding::Gzip,
    };
    let volume = match (&dataset, args.step) {
        (Dataset::Series(s), None) => {
            if output != Output::Nifti {
                bail!(
                    "{} has {} time steps and NRRD holds one volume: pick one with --step N, or \
                     write all of them to a .nii/.nii.gz",
                    args.input.display(),
                    s.step_count()
                );
            }
            formats::nifti::write_nifti_series(&args.output, s, replace)?;
            let v = s.first();
            println!(
                "{}: NIfTI-1, {} x {} x {} {} x {} time steps",
                args.output.display(),
                v.dims()[0],
                v.dims()[1],
                v.dims()[2],
                v.data.voxel_type(),
                s.step_count()
            );
            return Ok(());
        }
        (Dataset::Series(s), Some(n)) => s
            .step(n)
            .with_context(|| format!("{}: time step {n}", args.input.display()))?,
        (Dataset::Volume(v), Some(n)) if n > 0 => bail!(
            "--step {n}: {} is a single volume (step 0 only)",
            args.input.display()
        ),
        (Dataset::Volume(v), _) => v.clone(),
    };
    let written = match output {
        Output::Nifti => {
            formats::nifti::write_nifti(&args.output, &volume, replace)?;
            volume
        }
        Output::Nrrd | Output::Nhdr => {
            let volume = if volume.value_map.is_identity() {
                volume
            } else {
                let map = volume.value_map;
                let (physical, t) = physical_volume(&volume);
                eprintln!(
                    "note: {} stores {} values with slope {} and intercept {}; NRRD has no \
                     rescale, so the physical values are written as {}{}",
                    args.input.display(),
                    volume.data.voxel_type(),
                    map.slope,
                    map.intercept,
                    t.voxel_type,
                    if t.exact {
                        " (exact)"
                    } else {
                        " (rounded: not every value is a float32)"
                    }
                );
                physical
            };
            if output == Output::Nrrd {
                write_nrrd(&args.output, &volume, encoding, replace)?;
            } else {
                write_nrrd_detached(&args.output, &volume, encoding, replace)?;
            }
            volume
        }
    };
    let d = written.dims();
    println!(
        "{}: {}, {} x {} x {} {}",
        args.output.display(),
        if output == Output::Nifti {
            "NIfTI-1"
        } else {
            "NRRD"
        },
        d[0],
        d[1],
        d[2],
        written.data.voxel_type()
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use volume_core::{Grid, ValueMap};

    fn scaled<T: Voxel>(stored: Vec<T>, slope: f64, intercept: f64) -> RectilinearVolume
    where
        VoxelData: From<Vec<T>>,
    {
        let g = Grid::uniform([stored.len(), 1, 1], [0.0; 3], [1.0; 3]).unwrap();
        RectilinearVolume::new(g, stored.into())
            .unwrap()
            .with_value_map(ValueMap::new(slope, intercept).unwrap())
    }

    /// Every physical value of `v` equals the converted voxel (brute force).
    fn check_exact(v: &RectilinearVolume, p: &RectilinearVolume) {
        assert!(p.value_map.is_identity());
        for i in 0..v.dims()[0] {
            let want = v.physical_f64(i, 0, 0);
            let got = p.value_f64(i, 0, 0);
            assert!(
                want == got || (want.is_nan() && got.is_nan()),
                "{i}: {want} vs {got}"
            );
        }
    }

    #[test]
    fn physical_values_go_to_the_narrowest_exact_type() {
        // CT: stored 0..4095, slope 1, intercept −1024 → −1024..3071 in i16.
        let ct = scaled((0u16..4096).collect(), 1.0, -1024.0);
        let (p, t) = physical_volume(&ct);
        assert_eq!(
            t,
            PhysicalType {
                voxel_type: VoxelType::I16,
                exact: true
            }
        );
        check_exact(&ct, &p);
        // Slope 2, intercept 10 over u8 0..100 → 10..210: u8.
        let v = scaled((0u8..=100).collect(), 2.0, 10.0);
        let (p, t) = physical_volume(&v);
        assert_eq!(t.voxel_type, VoxelType::U8);
        check_exact(&v, &p);
        // Negative slope: −5..0 fits i8.
        let v = scaled(vec![0i16, 1, 5], -1.0, 0.0);
        assert_eq!(physical_volume(&v).1.voxel_type, VoxelType::I8);
        // Beyond u16 and negative: i32; beyond 32 bits: f64.
        let v = scaled(vec![0u16, 65535], 2.0, -1.0);
        assert_eq!(physical_volume(&v).1.voxel_type, VoxelType::I32);
        let v = scaled(vec![0u32, 4_000_000_000], 2.0, 0.0);
        let (p, t) = physical_volume(&v);
        assert_eq!(
            t,
            PhysicalType {
                voxel_type: VoxelType::F64,
                exact: true
            }
        );
        check_exact(&v, &p);
        // Halves are f32-exact; 0.1 steps are not.
        let v = scaled(vec![0i16, 1, 3], 0.5, 0.0);
        let (p, t) = physical_volume(&v);
        assert_eq!(
            t,
            PhysicalType {
                voxel_type: VoxelType::F32,
                exact: true
            }
        );
        check_exact(&v, &p);
        let v = scaled(vec![0i16, 1, 3], 0.1, 0.0);
        assert_eq!(
            physical_volume(&v).1,
            PhysicalType {
                voxel_type: VoxelType::F32,
                exact: false
            }
        );
        // NaN stays NaN.
        let v = scaled(vec![1.0f32, f32::NAN], 2.0, 0.0);
        let (p, t) = physical_volume(&v);
        assert_eq!(t.voxel_type, VoxelType::F32);
        check_exact(&v, &p);
    }

    #[test]
    fn output_names_pick_the_format() {
        assert_eq!(Output::of(Path::new("a.NRRD")).unwrap(), Output::Nrrd);
        assert_eq!(Output::of(Path::new("a.nhdr")).unwrap(), Output::Nhdr);
        assert_eq!(Output::of(Path::new("a.nii.gz")).unwrap(), Output::Nifti);
        let e = Output::of(Path::new("a.png")).unwrap_err().to_string();
        assert!(e.contains(".nii.gz"), "{e}");
    }
}
