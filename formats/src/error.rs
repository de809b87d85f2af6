//! Errors of the readers and writers.
//!
//! Every variant names the file; header problems also name the field (and the header line),
//! data problems the byte offset. Tests match on the variant and its `field`, so the variants
//! are part of the interface: add new ones rather than overloading an existing one.

use std::path::{Path, PathBuf};

use thiserror::Error;

/// Why a file could not be read or written.
#[derive(Debug, Error)]
pub enum FormatError {
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// An output that is one of the files an input reads (the same device and inode, or the
    /// same path after resolution).
    #[error("{}: is the input file {}; refusing to write over it (choose another output)", path.display(), input.display())]
    OutputIsInput { path: PathBuf, input: PathBuf },
    /// An output that exists, without permission to replace it.
    #[error("{}: already exists; pass --force to replace it", path.display())]
    OutputExists { path: PathBuf },
    /// An output path that cannot be a new regular file (a device, a directory, no name).
    #[error("{}: {reason}", path.display())]
    BadOutput { path: PathBuf, reason: String },
    /// The file does not start with a known magic (e.g. `NRRD0001`..`NRRD0005`).
    #[error("{}: not a NRRD file or unsupported version: magic {found:?}", path.display())]
    BadMagic { path: PathBuf, found: String },
    /// The header is not well formed text (no `: ` in a field line, invalid UTF-8, too long).
    #[error("{}: line {line}: {reason}", path.display())]
    BadLine {
        path: PathBuf,
        line: usize,
        reason: String,
    },
    #[error("{}: line {line}: unknown field `{field}`", path.display())]
    UnknownField {
        path: PathBuf,
        line: usize,
        field: String,
    },
    #[error("{}: line {line}: field `{field}` given twice", path.display())]
    DuplicateField {
        path: PathBuf,
        line: usize,
        field: String,
    },
    #[error("{}: required field `{field}` is missing{}", path.display(), if reason.is_empty() { String::new() } else { format!(" ({reason})") })]
    MissingField {
        path: PathBuf,
        field: &'static str,
        reason: String,
    },
    /// A field's value could not be parsed or is out of range.
    #[error("{}: line {line}: field `{field}`: {reason}", path.display())]
    BadValue {
        path: PathBuf,
        line: usize,
        field: String,
        reason: String,
    },
    /// Two fields that cannot both hold (e.g. `spacings` together with `space directions`).
    #[error("{}: field `{field}` contradicts `{other}`: {reason}", path.display())]
    Contradiction {
        path: PathBuf,
        field: String,
        other: String,
        reason: String,
    },
    /// Valid in the format, but not something Isoscope can represent (64-bit ints, vectors).
    #[error("{}: field `{field}`: unsupported: {reason}", path.display())]
    Unsupported {
        path: PathBuf,
        field: String,
        reason: String,
    },
    /// The file is shorter than the header says (checked before anything is allocated).
    #[error("{}: file has {available} bytes but the data needs {needed} bytes from byte offset {offset}", path.display())]
    TooShort {
        path: PathBuf,
        offset: u64,
        needed: u64,
        available: u64,
    },
    /// The data holds more bytes than the header says (raw files of explicit layout, encoded
    /// streams that decode to more than expected, ascii files with extra values).
    #[error("{}: data is longer than expected: {expected} bytes expected, more found at byte offset {offset}", path.display())]
    TooLong {
        path: PathBuf,
        offset: u64,
        expected: u64,
    },
    /// A compressed stream ended early or is corrupt; `offset` is the decoded byte count
    /// reached.
    #[error("{}: {encoding} data corrupt or truncated after {offset} decoded bytes: {reason}", path.display())]
    Decode {
        path: PathBuf,
        encoding: &'static str,
        offset: u64,
        reason: String,
    },
    /// An ascii/hex value that does not parse or does not fit the voxel type.
    #[error("{}: {encoding} data: value #{index} (byte offset {offset}) {reason}", path.display())]
    BadText {
        path: PathBuf,
        encoding: &'static str,
        index: u64,
        offset: u64,
        reason: String,
    },
    /// The parts read are inconsistent as a volume (bad spacing, singular orientation).
    #[error("{}: invalid geometry: {source}", path.display())]
    Geometry {
        path: PathBuf,
        #[source]
        source: volume_core::VolumeError,
    },
    /// A raw file's JSON sidecar is malformed.
    #[error("{}: sidecar: {reason}", path.display())]
    Sidecar { path: PathBuf, reason: String },
    /// A time series pattern or glob that matches nothing or is malformed.
    #[error("{}: series: {reason}", path.display())]
    Series { path: PathBuf, reason: String },
    /// The file's kind could not be determined, or it is not something `open` reads.
    #[error("{}: {reason}", path.display())]
    UnknownFormat { path: PathBuf, reason: String },
    /// A page (image) of a multi-page file (TIFF) that cannot be read or does not fit the
    /// others (size, sample type); pages count from 0.
    #[error("{}: page {page}: {reason}", path.display())]
    Page {
        path: PathBuf,
        page: usize,
        reason: String,
    },
    /// A named data array (VTK image data) that is missing, not a scalar, or does not decode.
    #[error("{}: array \"{name}\": {reason}", path.display())]
    Array {
        path: PathBuf,
        name: String,
        reason: String,
    },
    /// A field of a binary header (NIfTI `dim[3]`, `vox_offset`, ...) that is out of range or
    /// inconsistent with the file.
    #[error("{}: header field `{field}`: {reason}", path.display())]
    BadField {
        path: PathBuf,
        field: String,
        reason: String,
    },
    /// A DICOM file whose structure is broken (a length beyond the file, a bad sequence) or
    /// that cannot be a volume slice (a color image, 1-bit pixels).
    #[error("{}: DICOM: {reason}", path.display())]
    DicomFile { path: PathBuf, reason: String },
    /// A DICOM attribute that is missing or wrong; `attribute` is its keyword and tag, e.g.
    /// `ImagePositionPatient (0020,0032)`.
    #[error("{}: DICOM {attribute}: {reason}", path.display())]
    DicomAttribute {
        path: PathBuf,
        attribute: String,
        reason: String,
    },
    /// A DICOM series that cannot be one volume (duplicate positions, missing slices, mixed
    /// sizes) or a series choice that does not match; `path` is the file, folder or DICOMDIR.
    #[error("{}: {reason}", path.display())]
    DicomSeries { path: PathBuf, reason: String },
}

impl FormatError {
    /// The file the error is about.
    pub fn path(&self) -> &Path {
        match self {
            FormatError::Io { path, .. }
            | FormatError::BadMagic { path, .. }
            | FormatError::BadLine { path, .. }
            | FormatError::UnknownField { path, .. }
            | FormatError::DuplicateField { path, .. }
            | FormatError::MissingField { path, .. }
            | FormatError::BadValue { path, .. }
            | FormatError::Contradiction { path, .. }
            | FormatError::Unsupported { path, .. }
            | FormatError::TooShort { path, .. }
            | FormatError::TooLong { path, .. }
            | FormatError::Decode { path, .. }
            | FormatError::BadText { path, .. }
            | FormatError::Geometry { path, .. }
            | FormatError::Sidecar { path, .. }
            | FormatError::Series { path, .. }
            | FormatError::UnknownFormat { path, .. }
            | FormatError::Array { path, .. }
            | FormatError::Page { path, .. }
            | FormatError::DicomFile { path, .. }
            | FormatError::DicomAttribute { path, .. }
            | FormatError::DicomSeries { path, .. }
            | FormatError::OutputIsInput { path, .. }
            | FormatError::OutputExists { path }
            | FormatError::BadOutput { path, .. }
            | FormatError::BadField { path, .. } => path,
        }
    }

    /// The header field the error is about, if any.
    pub fn field(&self) -> Option<&str> {
        match self {
            FormatError::UnknownField { field, .. }
            | FormatError::DuplicateField { field, .. }
            | FormatError::BadValue { field, .. }
            | FormatError::Contradiction { field, .. }
            | FormatError::Unsupported { field, .. }
            | FormatError::BadField { field, .. }
            | FormatError::DicomAttribute {
                attribute: field, ..
            } => Some(field),
            FormatError::MissingField { field, .. } => Some(field),
            _ => None,
        }
    }

    pub fn io(path: &Path, source: std::io::Error) -> Self {
        FormatError::Io {
            path: path.to_path_buf(),
            source,
        }
    }

    pub(crate) fn geometry(path: &Path, source: volume_core::VolumeError) -> Self {
        FormatError::Geometry {
            path: path.to_path_buf(),
            source,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn messages_name_file_and_field() {
        let e = FormatError::BadValue {
            path: "a/b.nrrd".into(),
            line: 4,
            field: "sizes".into(),
            reason: "expected 3 numbers".into(),
        };
        let s = e.to_string();
        assert!(
            s.contains("a/b.nrrd") && s.contains("line 4") && s.contains("sizes"),
            "{s}"
        );
        assert_eq!(e.field(), Some("sizes"));
        assert_eq!(e.path(), Path::new("a/b.nrrd"));
        let m = FormatError::MissingField {
            path: "x.nrrd".into(),
            field: "endian",
            reason: String::new(),
        };
        assert_eq!(m.to_string(), "x.nrrd: required field `endian` is missing");
    }
}
