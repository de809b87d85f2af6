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
//! - [`series`]: time series from numbered files (`vol_%03d.nrrd`, `vol_*.nrrd`), loaded
//!   lazily through [`volume_core::series::StepLoader`] (4D NRRD: [`nrrd::NrrdSteps`]).
//! - [`treelet`]: the `.isot` out-of-core treelet file (4 KiB pages, CRC32 per page) and
//!   [`treelet::open_isot`] (see `docs/treelet-format.md`).
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
//!
//! ## NIfTI
//! NIfTI-1 (`.nii`, `.nii.gz`) is not read yet: the `nifti` crate (0.18) was evaluated (see
//! `formats/README.md`); `open` reports NIfTI files as an unknown format with that note.

pub mod dicom;
pub mod error;
pub mod input;
pub mod mesh;
pub mod nrrd;
pub mod output;
pub mod raw;
pub mod series;
pub mod treelet;

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
    /// DICOM: the series to open when the input holds several: its number in
    /// [`dicom::list`] (`"2"`) or its SeriesInstanceUID (the CLI's `--series`).
    pub dicom_series: Option<String>,
}

/// Opens any supported rectilinear file by extension and content: `.nrrd`, `.nhdr`, raw files
/// with `options.raw` or a `NAME.json` sidecar, numbered series (`vol_%03d.nrrd`, or a
/// glob such as `vol_*.nrrd`, when no file of that literal name exists), and DICOM (a folder,
/// a `DICOMDIR`, a file and its series, or a glob of DICOM files: [`dicom`]).
pub fn open(path: &Path, options: &OpenOptions) -> Result<Dataset, FormatError> {
    let pick = options.dicom_series.as_deref();
    if path.is_dir() {
        return dicom::open(path, pick);
    }
    if !path.exists() && series::is_pattern(path) {
        let files = series::expand_pattern(path)?;
        if dicom::is_dicom_input(&files[0]) {
            return dicom::open_files(&files, path, pick);
        }
        return series::open_file_series(path, options).map(Dataset::Series);
    }
    open_file(path, options)
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
        return nrrd::read_nrrd(path);
    }
    if let Some(layout) = &options.raw {
        return raw::read_raw(path, layout).map(Dataset::Volume);
    }
    if dicom::is_dicom_input(path) {
        return dicom::open(path, options.dicom_series.as_deref());
    }
    if name.ends_with(".nii") || name.ends_with(".nii.gz") {
        return Err(FormatError::UnknownFormat {
            path: path.to_path_buf(),
            reason: "NIfTI is not supported yet (see formats/README.md); convert to NRRD, e.g. \
                     with 3D Slicer or `c3d in.nii -o out.nrrd`"
                .into(),
        });
    }
    if let Some(side) = raw::sidecar_path(path)
        && !name.ends_with(".json")
    {
        let layout = raw::RawLayout::from_sidecar(&side)?;
        return raw::read_raw(path, &layout).map(Dataset::Volume);
    }
    // Sniff: a NRRD under another name.
    let mut magic = [0u8; 4];
    let file = input::open_regular(path).map_err(|e| FormatError::io(path, e))?;
    let n = std::io::Read::read(&mut &file, &mut magic).map_err(|e| FormatError::io(path, e))?;
    if n == 4 && &magic == b"NRRD" {
        return nrrd::read_nrrd(path);
    }
    Err(FormatError::UnknownFormat {
        path: path.to_path_buf(),
        reason: "unknown file type: expected .nrrd/.nhdr, or a raw file with --dims/--type/\
                 --endian/--spacing or a NAME.json sidecar"
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
