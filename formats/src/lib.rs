//! # formats
//!
//! Readers and writers that turn files into `volume-core` types. Errors ([`FormatError`]) name
//! the file and the field, line or byte offset, and what is wrong; every reader checks sizes
//! against the file before it allocates (headers lie).
//!
//! - [`raw`]: raw voxels of explicit layout (command-line flags or a `NAME.json` sidecar),
//!   memory-mapped, zero-copy when native-endian and aligned.
//! - [`nrrd`]: NRRD as Teem writes it (NRRD0001–0005, every type alias, raw/gzip/bzip2/ascii/hex,
//!   attached and detached headers, `LIST` and printf data files, skips, orientation) and the
//!   NRRD writer (raw, gzip).
//! - [`metaimage`]: MetaImage `.mha`/`.mhd` (ITK), 3D or 4D, raw (memory-mapped) or zlib,
//!   local, detached, pattern and `LIST` data files, oriented, LPS world.
//! - [`vtk_image`]: VTK image data, XML `.vti` (every encoding VTK writes) and legacy `.vtk`
//!   structured points and rectilinear grids (a `.vtk` is a grid or a mesh by its `DATASET`).
//! - [`tiff`]: TIFF stacks, multi-page or numbered 2D slices, ImageJ spacing and frames.
//! - [`nifti`]: NIfTI-1 and NIfTI-2 (`.nii`, `.nii.gz`, `.hdr`/`.img` pairs, either byte
//!   order, sform/qform geometry, `scl_slope` as a value map, 4D as a time series) and
//!   Analyze 7.5; the NIfTI-1 writer.
//! - [`series`]: time series from numbered files (`vol_%03d.nrrd`, `vol_*.nrrd`), loaded
//!   lazily through [`volume_core::series::StepLoader`] (4D NRRD: [`nrrd::NrrdSteps`]).
//! - [`treelet`]: the `.isot` out-of-core treelet file (4 KiB pages, CRC32 per page) and
//!   [`treelet::open_isot`] (see `docs/treelet-format.md`).
//! - [`trimesh`]: triangle mesh writers (binary PLY with normals and colours, binary STL,
//!   OBJ) for exported isosurfaces.
//! - [`dicom`]: DICOM series (a folder, a `DICOMDIR`, one file's series, a list of files) as
//!   volumes in LPS, through dicom-rs, with `--series` picking one of several.
//! - [`open`]: picks the reader from the name and contents.
//! - [`input`]: every reader opens its files through [`input::open_regular`] (regular files
//!   only: a FIFO, device or directory is refused before it is opened), and records it in
//!   the input log.
//! - [`output`]: every writer writes through [`output::OutputFile`]: never over an input
//!   file, an existing file only when allowed, a temporary file renamed when complete.
//!
//! The NRRD header parser has a `cargo fuzz` target in `formats/fuzz` (see `formats/README.md`);
//! its seed corpus replays in the tests.

pub mod dicom;
pub mod error;
pub mod input;
pub mod mesh;
pub mod metaimage;
pub mod nifti;
pub mod nrrd;
mod oriented;
pub mod output;
pub mod raw;
pub mod series;
#[cfg(test)]
mod test_support;
pub mod tiff;
pub mod treelet;
pub mod trimesh;
pub mod vtk_image;

pub use error::FormatError;

use std::path::Path;

use volume_core::RectilinearVolume;
use volume_core::series::TimeSeries;

/// What a file opened as.
pub enum Dataset {
    Volume(RectilinearVolume),
    Series(TimeSeries),
}

impl std::fmt::Debug for Dataset {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Dataset::Volume(v) => f.debug_tuple("Volume").field(v).finish(),
            Dataset::Series(s) => f
                .debug_struct("Series")
                .field("steps", &s.step_count())
                .field("first", s.first())
                .finish(),
        }
    }
}

impl Dataset {
    /// The volume, or the first step of the series.
    pub fn first_volume(&self) -> &RectilinearVolume {
        match self {
            Dataset::Volume(v) => v,
            Dataset::Series(s) => s.first(),
        }
    }

    /// Number of time steps (1 for a volume).
    pub fn time_steps(&self) -> usize {
        match self {
            Dataset::Volume(_) => 1,
            Dataset::Series(s) => s.step_count(),
        }
    }
}

/// Options for files that do not describe themselves (raw) and for inputs that hold several
/// datasets (DICOM folders) — mirrors the CLI flags.
#[derive(Default, Clone, Debug)]
pub struct OpenOptions {
    pub raw: Option<raw::RawLayout>,
    /// Sample spacing for axes a file does not record (TIFF stacks; `--spacing` without the
    /// other raw flags). Refused for files that record their spacing.
    pub spacing: Option<[f64; 3]>,
    /// The point array to read from files with several (VTK image data; `--field`); `None`:
    /// the active scalars, else the first. Refused for files without named arrays.
    pub field: Option<String>,
    /// DICOM: the series to open when the input holds several: its number in
    /// [`dicom::list`] (`"2"`) or its SeriesInstanceUID (the CLI's `--series`). Refused for
    /// other files.
    pub dicom_series: Option<String>,
}

/// Opens any supported rectilinear file by extension and content: `.nrrd`, `.nhdr`, NIfTI
/// (`.nii`, `.nii.gz`, `.hdr`/`.img`), `.mha`, `.mhd`, `.vti`, legacy `.vtk` images,
/// `.tif`/`.tiff`, raw files with `options.raw` or a `NAME.json` sidecar, numbered series
/// (`vol_%03d.nrrd`, or a glob such as `vol_*.nrrd`, when no file of that literal name
/// exists), and DICOM (a folder, a `DICOMDIR`, a file and its series, or a glob of DICOM
/// files: [`dicom`]). Numbered single-page TIFF files are the slices of one volume, not a
/// series.
pub fn open(path: &Path, options: &OpenOptions) -> Result<Dataset, FormatError> {
    let pick = options.dicom_series.as_deref();
    if path.is_dir() {
        refuse_unused(path, &dicom_options(options), false)?;
        return dicom::open(path, pick);
    }
    if !path.exists() && series::is_pattern(path) {
        let files = series::expand_pattern(path)?;
        if dicom::is_dicom_input(&files[0]) {
            refuse_unused(&files[0], &dicom_options(options), false)?;
            return dicom::open_files(&files, path, pick);
        }
        if tiff::is_slice_stack(&files)? {
            refuse_unused(&files[0], &spacing_used(options), false)?;
            for f in &files {
                input::note_input(f);
            }
            return tiff::read_slices(&files, options).map(Dataset::Volume);
        }
        return series::open_file_series(path, options).map(Dataset::Series);
    }
    open_file(path, options)
}

/// `options` less the spacing, which TIFF stacks and raw files use.
fn spacing_used(options: &OpenOptions) -> OpenOptions {
    OpenOptions {
        spacing: None,
        ..options.clone()
    }
}

/// `options` less the series choice, which DICOM inputs use.
fn dicom_options(options: &OpenOptions) -> OpenOptions {
    OpenOptions {
        dicom_series: None,
        ..options.clone()
    }
}

/// Refuses the options a self-describing format has no use for (a flag that would otherwise
/// be ignored silently).
fn refuse_unused(path: &Path, options: &OpenOptions, field: bool) -> Result<(), FormatError> {
    if options.raw.is_some() {
        return Err(FormatError::Unsupported {
            path: path.to_path_buf(),
            field: "--dims/--type".into(),
            reason: "the file records its own layout (the raw-layout flags --dims, --type, \
                     --endian, --header-bytes and --origin describe headerless raw files)"
                .into(),
        });
    }
    if let Some(series) = &options.dicom_series {
        return Err(FormatError::Unsupported {
            path: path.to_path_buf(),
            field: "--series".into(),
            reason: format!(
                "\"{series}\": only DICOM inputs (a folder, a DICOMDIR, .dcm files) hold \
                 several series to pick from"
            ),
        });
    }
    if !field && let Some(f) = &options.field {
        return Err(FormatError::Unsupported {
            path: path.to_path_buf(),
            field: "--field".into(),
            reason: format!(
                "\"{f}\": only files with named point arrays (VTK image data .vti/.vtk, \
                 meshes) have arrays to choose from"
            ),
        });
    }
    if options.spacing.is_some() {
        return Err(FormatError::Unsupported {
            path: path.to_path_buf(),
            field: "--spacing".into(),
            reason: "the file records its own spacing (--spacing applies to raw files and \
                     to TIFF stacks)"
                .into(),
        });
    }
    Ok(())
}

/// Opens one file (no pattern expansion).
// `name` is lower-cased first, so the extension comparisons are case-insensitive.
#[allow(clippy::case_sensitive_file_extension_comparisons)]
pub fn open_file(path: &Path, options: &OpenOptions) -> Result<Dataset, FormatError> {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default();
    if name.ends_with(".nrrd") || name.ends_with(".nhdr") {
        refuse_unused(path, options, false)?;
        return nrrd::read_nrrd(path);
    }
    if name.ends_with(".mha") || name.ends_with(".mhd") {
        refuse_unused(path, options, false)?;
        return metaimage::read_metaimage(path);
    }
    if name.ends_with(".vti") || name.ends_with(".vtk") {
        refuse_unused(path, options, true)?;
        if name.ends_with(".vtk") && !vtk_image::is_legacy_image(path) {
            // Read the file (a missing or special file is named by its own error).
            input::check_regular(path).map_err(|e| FormatError::io(path, e))?;
            return Err(FormatError::UnknownFormat {
                path: path.to_path_buf(),
                reason: match vtk_image::legacy_dataset(path) {
                    Some(d) => format!(
                        "DATASET {d}: not an image (STRUCTURED_POINTS or RECTILINEAR_GRID); \
                         an UNSTRUCTURED_GRID is a tetrahedral mesh, opened as one by \
                         `isoscope render`, `info` and the viewer"
                    ),
                    None => "not a legacy VTK file with a DATASET line in its first 4 KiB".into(),
                },
            });
        }
        return vtk_image::read(path, options.field.as_deref()).map(Dataset::Volume);
    }
    if tiff::is_tiff_path(path) {
        refuse_unused(path, &spacing_used(options), false)?;
        return tiff::read_tiff(path, options);
    }
    if let Some(layout) = &options.raw {
        let used = OpenOptions {
            raw: None,
            ..spacing_used(options)
        };
        refuse_unused(path, &used, false)?;
        return raw::read_raw(path, layout).map(Dataset::Volume);
    }
    if dicom::is_dicom_input(path) {
        refuse_unused(path, &dicom_options(options), false)?;
        return dicom::open(path, options.dicom_series.as_deref());
    }
    if nifti::is_nifti_path(path) {
        refuse_unused(path, options, false)?;
        return nifti::read_nifti(path);
    }
    if let Some(side) = raw::sidecar_path(path)
        && !name.ends_with(".json")
    {
        let layout = raw::RawLayout::from_sidecar(&side)?;
        // The sidecar gives the spacing: a --spacing would be ignored.
        refuse_unused(path, options, false)?;
        return raw::read_raw(path, &layout).map(Dataset::Volume);
    }
    // Sniff: a NRRD or a single-file NIfTI under another name.
    let file = input::open_regular(path).map_err(|e| FormatError::io(path, e))?;
    let mut magic = Vec::new();
    std::io::Read::read_to_end(
        &mut std::io::Read::take(&file, nifti::NIFTI1_HEADER_BYTES as u64),
        &mut magic,
    )
    .map_err(|e| FormatError::io(path, e))?;
    if magic.starts_with(b"NRRD") {
        refuse_unused(path, options, false)?;
        return nrrd::read_nrrd(path);
    }
    if magic.get(4..8) == Some(b"n+2\0") || magic.get(344..348) == Some(b"n+1\0") {
        refuse_unused(path, options, false)?;
        return nifti::read_nifti(path);
    }
    if [&b"II*\0"[..], b"MM\0*", b"II+\0"]
        .iter()
        .any(|m| magic.starts_with(m))
    {
        refuse_unused(path, &spacing_used(options), false)?;
        return tiff::read_tiff(path, options);
    }
    Err(FormatError::UnknownFormat {
        path: path.to_path_buf(),
        reason: "unknown file type: expected .nrrd/.nhdr, .nii/.nii.gz/.hdr, .mha/.mhd, .vti, a \
                 legacy .vtk image, .tif/.tiff, or a raw file with \
                 --dims/--type/--endian/--spacing or a NAME.json sidecar"
            .into(),
    })
}

/// Step 0 of a lazily loaded series: loaded when the series is opened (so a broken first
/// step is reported with its typed [`FormatError`]) and handed out by the first
/// `load_step(0)`, which then needs no second read.
pub(crate) struct FirstStep(std::sync::Mutex<Option<RectilinearVolume>>);

impl FirstStep {
    pub(crate) fn new(volume: RectilinearVolume) -> Self {
        Self(std::sync::Mutex::new(Some(volume)))
    }

    /// The kept step 0, once.
    pub(crate) fn take(&self) -> Option<RectilinearVolume> {
        self.0
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .take()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::nrrd::{NrrdEncoding, write_nrrd};
    use crate::output::Replace;
    use volume_core::Grid;

    #[test]
    fn raw_layout_options_are_refused_by_files_with_a_header() {
        let dir = tempfile::tempdir().unwrap();
        let g = Grid::uniform([2, 2, 2], [0.0; 3], [1.0; 3]).unwrap();
        let v = RectilinearVolume::new(g, (0u8..8).collect::<Vec<_>>().into()).unwrap();
        let p = dir.path().join("a.nrrd");
        write_nrrd(&p, &v, NrrdEncoding::Raw, Replace::Refuse).unwrap();
        let layout = raw::RawLayout {
            dims: [2, 2, 2],
            voxel_type: volume_core::VoxelType::U8,
            endian: raw::Endian::Little,
            header_bytes: 0,
            spacing: [1.0; 3],
            origin: [0.0; 3],
        };
        let options = OpenOptions {
            raw: Some(layout.clone()),
            ..OpenOptions::default()
        };
        let e = open(&p, &options).unwrap_err();
        assert!(
            matches!(&e, FormatError::Unsupported { field, .. } if field == "--dims/--type"),
            "{e}"
        );
        // The same flags read a headerless file.
        let r = dir.path().join("a.raw");
        std::fs::write(&r, (0u8..8).collect::<Vec<_>>()).unwrap();
        let read = open(&r, &options).unwrap();
        assert_eq!(read.first_volume().value_f64(1, 1, 1), 7.0);
    }

    #[test]
    fn open_dispatches_on_name_sidecar_and_content() {
        let dir = tempfile::tempdir().unwrap();
        let g = Grid::uniform([2, 2, 2], [0.0; 3], [1.0; 3]).unwrap();
        let v = RectilinearVolume::new(g, (0u8..8).collect::<Vec<_>>().into()).unwrap();
        let p = dir.path().join("a.nrrd");
        write_nrrd(&p, &v, NrrdEncoding::Raw, Replace::Refuse).unwrap();
        assert_eq!(
            open(&p, &OpenOptions::default())
                .unwrap()
                .first_volume()
                .value_f64(1, 1, 1),
            7.0
        );
        // Same bytes under another name: sniffed.
        let q = dir.path().join("a.dat");
        std::fs::copy(&p, &q).unwrap();
        assert_eq!(open(&q, &OpenOptions::default()).unwrap().time_steps(), 1);
        // Raw with a sidecar.
        let r = dir.path().join("b.raw");
        std::fs::write(&r, (0u8..8).collect::<Vec<_>>()).unwrap();
        let e = open(&r, &OpenOptions::default()).unwrap_err();
        assert!(matches!(e, FormatError::UnknownFormat { .. }), "{e}");
        std::fs::write(
            dir.path().join("b.json"),
            r#"{"dims":[2,2,2],"type":"u8","endian":"little","spacing":[1,1,1]}"#,
        )
        .unwrap();
        let d = open(&r, &OpenOptions::default()).unwrap();
        assert_eq!(d.first_volume().value_f64(0, 1, 1), 6.0);
        assert!(d.first_volume().data.is_shared());
        // Pattern.
        let d = open(&dir.path().join("a*.nrrd"), &OpenOptions::default()).unwrap();
        assert_eq!(d.time_steps(), 1);
        assert!(matches!(d, Dataset::Series(_)));
    }
}
