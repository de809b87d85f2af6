//! NIfTI-1, NIfTI-2 and Analyze 7.5: the reader and the NIfTI-1 writer.
//!
//! - [`header`]: the binary headers ([`parse_header`]) and what they say
//!   ([`NiftiHeader::layout`]: grid, voxel type, value map, time steps, data offset).
//! - [`read_nifti`]: a `.nii`, `.nii.gz`, or a `.hdr`/`.img` pair (either part may be
//!   gzipped: `.hdr.gz`, `.img.gz`; opening the `.img` finds its `.hdr`). Uncompressed data
//!   is memory-mapped after the file length is checked against `vox_offset` and the sizes
//!   (zero-copy when native-endian and aligned, through `nrrd::DataPlan`, the one
//!   data path of every reader of raw or gzip data at an offset); gzip data is decompressed
//!   into memory that grows only as the stream delivers bytes, never beyond what the header
//!   asks for. Bytes after the data are ignored, as nibabel and niftilib do.
//! - A file with `dim[4] > 1` opens as a time series whose steps load lazily
//!   ([`NiftiSteps`]; uncompressed: each step a view into the one map).
//! - [`write_nifti`], [`write_nifti_series`]: NIfTI-1 `.nii` / `.nii.gz` (see [`write`]).

pub mod header;
mod write;

use std::io::Read;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use volume_core::series::{StepLoader, TimeSeries};
use volume_core::{RectilinearVolume, VoxelData};

pub use header::{
    GeometrySource, NIFTI1_HEADER_BYTES, NIFTI2_HEADER_BYTES, NiftiHeader, NiftiLayout,
    NiftiVersion, datatype_name, parse_header,
};
pub use write::{write_nifti, write_nifti_series};

use crate::error::FormatError;
use crate::nrrd::{DataPlan, Encoding};
use crate::{Dataset, FirstStep};

/// True for the names [`read_nifti`] opens: `.nii`, `.nii.gz`, `.hdr`, `.hdr.gz`, and
/// `.img`/`.img.gz` when a `.hdr` (or `.hdr.gz`) of the same name exists.
#[allow(clippy::case_sensitive_file_extension_comparisons)] // lower-cased first
pub fn is_nifti_path(path: &Path) -> bool {
    let name = lower_name(path);
    [".nii", ".nii.gz", ".hdr", ".hdr.gz"]
        .iter()
        .any(|e| name.ends_with(e))
        || (is_img(&name) && header_of_img(path).is_some())
}

fn lower_name(path: &Path) -> String {
    path.file_name()
        .map(|n| n.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default()
}

#[allow(clippy::case_sensitive_file_extension_comparisons)] // lower-cased first
fn is_img(lower: &str) -> bool {
    lower.ends_with(".img") || lower.ends_with(".img.gz")
}

/// `path` with its `.nii`/`.hdr`/`.img` extension (and a `.gz` after it) replaced by `ext`,
/// keeping the case of the rest of the name.
fn with_ext(path: &Path, ext: &str) -> PathBuf {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let lower = name.to_ascii_lowercase();
    let stem_len = [".nii.gz", ".hdr.gz", ".img.gz", ".nii", ".hdr", ".img"]
        .iter()
        .find(|e| lower.ends_with(*e))
        .map_or(name.len(), |e| name.len() - e.len());
    path.with_file_name(format!("{}{ext}", &name[..stem_len]))
}

/// The `.hdr` (or `.hdr.gz`) beside an `.img`/`.img.gz`, if one exists.
fn header_of_img(img: &Path) -> Option<PathBuf> {
    [".hdr", ".hdr.gz", ".HDR"]
        .iter()
        .map(|e| with_ext(img, e))
        .find(|p| p.exists())
}

/// The `.img` (or `.img.gz`) beside a `.hdr`: the first that exists, else the plain name
/// (whose opening then reports it missing).
fn image_of_hdr(hdr: &Path) -> PathBuf {
    let candidates = [".img", ".img.gz", ".IMG"].map(|e| with_ext(hdr, e));
    candidates
        .iter()
        .find(|p| p.exists())
        .cloned()
        .unwrap_or_else(|| candidates[0].clone())
}

#[allow(clippy::case_sensitive_file_extension_comparisons)] // lower-cased first
fn is_gz(path: &Path) -> bool {
    lower_name(path).ends_with(".gz")
}

/// The first `n` bytes of `path` (fewer if it is shorter), decompressed if it is gzipped.
fn read_prefix(path: &Path, n: u64) -> Result<Vec<u8>, FormatError> {
    let file = crate::input::open_regular(path).map_err(|e| FormatError::io(path, e))?;
    let mut out = Vec::new();
    if is_gz(path) {
        flate2::read::MultiGzDecoder::new(std::io::BufReader::new(file))
            .take(n)
            .read_to_end(&mut out)
            .map_err(|e| FormatError::Decode {
                path: path.to_path_buf(),
                encoding: "gzip",
                offset: out.len() as u64,
                reason: e.to_string(),
            })?;
    } else {
        file.take(n)
            .read_to_end(&mut out)
            .map_err(|e| FormatError::io(path, e))?;
    }
    Ok(out)
}

/// Reads the header of the NIfTI or Analyze file at `path` (for a `.img`, its `.hdr`).
/// Returns the header's path too.
pub fn read_header(path: &Path) -> Result<(PathBuf, NiftiHeader), FormatError> {
    let header_path = if is_img(&lower_name(path)) {
        header_of_img(path).ok_or_else(|| FormatError::UnknownFormat {
            path: path.to_path_buf(),
            reason: format!(
                "an Analyze/NIfTI image file needs its header {} beside it",
                with_ext(path, ".hdr").display()
            ),
        })?
    } else {
        path.to_path_buf()
    };
    let bytes = read_prefix(&header_path, NIFTI2_HEADER_BYTES as u64)?;
    let header = parse_header(&header_path, &bytes)?;
    Ok((header_path, header))
}

/// Where the voxels of a parsed header are.
struct DataSource {
    path: PathBuf,
    encoding: Encoding,
}

fn data_source(header_path: &Path, header: &NiftiHeader) -> DataSource {
    let path = if header.single_file {
        header_path.to_path_buf()
    } else {
        image_of_hdr(header_path)
    };
    let encoding = if is_gz(&path) {
        Encoding::Gzip
    } else {
        Encoding::Raw
    };
    DataSource { path, encoding }
}

/// Checks that the data the header describes is there, before anything is mapped or
/// allocated: the file length for uncompressed data; for gzip, that the stream reaches
/// `vox_offset` (streamed, nothing kept). Errors name `vox_offset` or `dim`.
fn check_data_extent(
    header_path: &Path,
    source: &DataSource,
    layout: &NiftiLayout,
) -> Result<(), FormatError> {
    let path = &source.path;
    if path.symlink_metadata().is_err() {
        return Err(FormatError::Io {
            path: path.clone(),
            source: std::io::Error::new(
                std::io::ErrorKind::NotFound,
                format!(
                    "the image file of {} does not exist (also looked for .img.gz)",
                    header_path.display()
                ),
            ),
        });
    }
    let total = layout.step_bytes * layout.steps as u64; // checked by `layout`
    let offset = layout.data_offset;
    let beyond = |available: u64, what: &str| FormatError::BadField {
        path: header_path.to_path_buf(),
        field: "vox_offset".into(),
        reason: format!(
            "{offset} lies beyond the end of {} ({available} {what})",
            path.display()
        ),
    };
    if source.encoding == Encoding::Raw {
        let file = crate::input::open_regular(path).map_err(|e| FormatError::io(path, e))?;
        let len = file.metadata().map_err(|e| FormatError::io(path, e))?.len();
        if offset > len {
            return Err(beyond(len, "bytes"));
        }
        if len - offset < total {
            return Err(FormatError::BadField {
                path: header_path.to_path_buf(),
                field: "dim".into(),
                reason: format!(
                    "{:?} of {} bytes per voxel need {total} bytes from vox_offset {offset}, but \
                     {} has only {} bytes there (truncated, or the header lies)",
                    layout.grid.dims(),
                    layout.voxel_type.size_bytes(),
                    path.display(),
                    len - offset
                ),
            });
        }
        return Ok(());
    }
    let file = crate::input::open_regular(path).map_err(|e| FormatError::io(path, e))?;
    let mut dec = flate2::read::MultiGzDecoder::new(std::io::BufReader::new(file)).take(offset);
    let skipped =
        std::io::copy(&mut dec, &mut std::io::sink()).map_err(|e| FormatError::Decode {
            path: path.clone(),
            encoding: "gzip",
            offset: 0,
            reason: e.to_string(),
        })?;
    if skipped < offset {
        return Err(beyond(skipped, "decompressed bytes"));
    }
    Ok(())
}

/// A truncated or corrupt gzip stream: the message also says what the header asked for.
fn explain_decode(e: FormatError, layout: &NiftiLayout) -> FormatError {
    match e {
        FormatError::Decode {
            path,
            encoding,
            offset,
            reason,
        } => FormatError::Decode {
            path,
            encoding,
            offset,
            reason: format!(
                "{reason} (dim {:?} × {} time steps of {} bytes per voxel from vox_offset {})",
                layout.grid.dims(),
                layout.steps,
                layout.voxel_type.size_bytes(),
                layout.data_offset
            ),
        },
        other => other,
    }
}

/// Reads a NIfTI-1, NIfTI-2 or Analyze 7.5 file (see the module docs): a volume, or a
/// lazily loaded time series when `dim[4] > 1`.
pub fn read_nifti(path: &Path) -> Result<Dataset, FormatError> {
    let (header_path, header) = read_header(path)?;
    let layout = header.layout(&header_path)?;
    let source = data_source(&header_path, &header);
    check_data_extent(&header_path, &source, &layout)?;
    let plan = Arc::new(DataPlan::single_file(
        &source.path,
        source.encoding,
        layout.data_offset,
        layout.step_bytes * layout.steps as u64,
        header.endian,
        layout.voxel_type,
    ));
    if layout.steps == 1 {
        return load_step(&source.path, &plan, &layout, 0).map(Dataset::Volume);
    }
    let steps = NiftiSteps::new(&header_path, &source.path, plan, layout)?;
    let series = TimeSeries::open(Arc::new(steps)).map_err(|e| FormatError::Series {
        path: path.to_path_buf(),
        reason: e.to_string(),
    })?;
    Ok(Dataset::Series(series))
}

fn load_step(
    data_path: &Path,
    plan: &DataPlan,
    layout: &NiftiLayout,
    step: usize,
) -> Result<RectilinearVolume, FormatError> {
    let data: VoxelData = plan
        .load(step as u64 * layout.step_bytes, layout.step_bytes)
        .map_err(|e| explain_decode(e, layout))?;
    Ok(RectilinearVolume::new(layout.grid.clone(), data)
        .map_err(|e| FormatError::geometry(data_path, e))?
        .with_value_map(layout.value_map))
}

/// The volumes along `dim[4]` of a NIfTI file, loaded on demand (step 0 when opened, so its
/// errors are reported typed).
pub struct NiftiSteps {
    header_path: PathBuf,
    data_path: PathBuf,
    plan: Arc<DataPlan>,
    layout: NiftiLayout,
    first: FirstStep,
}

impl NiftiSteps {
    fn new(
        header_path: &Path,
        data_path: &Path,
        plan: Arc<DataPlan>,
        layout: NiftiLayout,
    ) -> Result<Self, FormatError> {
        let first = load_step(data_path, &plan, &layout, 0)?;
        Ok(Self {
            header_path: header_path.to_path_buf(),
            data_path: data_path.to_path_buf(),
            plan,
            layout,
            first: FirstStep::new(first),
        })
    }

    /// What the header said.
    pub fn layout(&self) -> &NiftiLayout {
        &self.layout
    }
}

impl StepLoader for NiftiSteps {
    fn step_count(&self) -> usize {
        self.layout.steps
    }

    fn load_step(&self, step: usize) -> Result<RectilinearVolume, String> {
        if step == 0
            && let Some(v) = self.first.take()
        {
            return Ok(v);
        }
        load_step(&self.data_path, &self.plan, &self.layout, step).map_err(|e| e.to_string())
    }

    fn time_value(&self, step: usize) -> Option<f64> {
        self.layout.time.map(|(t0, dt)| t0 + step as f64 * dt)
    }

    fn describe(&self) -> String {
        format!(
            "{} time steps (dim[4]) of NIfTI {}",
            self.layout.steps,
            self.header_path.display()
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_pair_headers_and_images() {
        assert_eq!(
            with_ext(Path::new("d/A.Nii.Gz"), ".nii"),
            Path::new("d/A.nii")
        );
        assert_eq!(with_ext(Path::new("b.img.gz"), ".hdr"), Path::new("b.hdr"));
        assert_eq!(with_ext(Path::new("b.x"), ".hdr"), Path::new("b.x.hdr"));
        let dir = tempfile::tempdir().unwrap();
        let img = dir.path().join("v.img");
        std::fs::write(&img, [0u8; 8]).unwrap();
        assert!(
            !is_nifti_path(&img),
            "an .img without a header is not NIfTI"
        );
        std::fs::write(dir.path().join("v.hdr"), [0u8; 8]).unwrap();
        assert!(is_nifti_path(&img));
        assert_eq!(image_of_hdr(&dir.path().join("v.hdr")), img);
        assert!(is_nifti_path(Path::new("x.NII")));
        assert!(!is_nifti_path(Path::new("x.nrrd")));
    }
}
