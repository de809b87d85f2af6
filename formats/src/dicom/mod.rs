//! # DICOM series
//!
//! Opens CT, MR, PET and other DICOM image series as volumes in the patient's LPS frame.
//!
//! ## Inputs ([`open`], [`list`])
//! - a folder: every file below it (recursively; symbolic links to folders are not followed);
//! - a `DICOMDIR`: the files its directory records reference (relative to its folder);
//! - one file: its whole series, from the files in the same folder;
//! - a list of files ([`open_files`]; `formats::open` passes the files of a glob such as
//!   `scan/*.dcm`).
//!
//! Files without the DICOM Part 10 header (`DICM` at byte 128), and DICOM files that are not
//! grayscale images (structured reports, RT plans and structure sets, presentation states,
//! color images, the DICOMDIR itself), are skipped with a note ([`SkippedFile`]). A DICOM
//! file that is broken (truncated, lengths beyond the file, bad attributes) is an error
//! naming it, never silently left out of a series.
//!
//! ## Series
//! Images are grouped by SeriesInstanceUID and split where sizes, orientation or pixel
//! spacing change ([`SeriesSummary::part`]). With several series in the input, one is picked
//! by number or UID (`OpenOptions::dicom_series`, the CLI's `--series N|UID`); without a
//! pick, several series are an error that says so. Slices are ordered by position along the
//! slice normal, spacing comes from the positions (uneven spacing: explicit coordinates;
//! gantry tilt: a sheared `world_from_grid`), missing slices are refused, duplicate positions
//! are an error unless TemporalPositionIdentifier makes them phases of a time series (see
//! [`series`](self) for every rule). RescaleSlope/Intercept becomes the volume's
//! [`volume_core::ValueMap`]; slices with different rescales are converted to `f32`.
//!
//! ## Files
//! - `scan`: the element walk that checks every length before dicom-rs parses anything.
//! - `file`: preamble, meta group, transfer syntax, attributes (dicom-rs), pixel data location.
//! - `attributes`: per-frame position, orientation, spacing, rescale; enhanced multi-frame
//!   functional groups; RT Dose grid offsets.
//! - `pixels`: native, RLE, deflated, JPEG (`jpeg-decoder`) and JPEG 2000 (`hayro-jpeg2000`)
//!   frames, BitsStored masking and sign extension.
//! - `series`: grouping, ordering, geometry, missing and duplicate slices, loading.
//!
//! Transfer syntaxes: implicit and explicit VR little endian, explicit VR big endian, deflated
//! explicit VR little endian, RLE lossless, JPEG baseline (process 1), extended (process 2,
//! 8-bit), lossless (processes 14 and 14 SV1), JPEG 2000 (lossless and lossy), encapsulated
//! uncompressed, deflated image frames. Others (JPEG-LS, 12-bit JPEG extended, HTJ2K, JPEG XL,
//! video) are listed, and opening them is an error naming the syntax (UID and name) and file.

mod attributes;
mod file;
mod pixels;
mod scan;
mod series;

use std::path::{Path, PathBuf};

use rayon::prelude::*;

use crate::Dataset;
use crate::error::FormatError;
use attributes::Content;
use series::Group;

/// Deepest folder level searched below an input folder.
const MAX_FOLDER_DEPTH: usize = 32;

/// One series (or series part) found in the input.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct SeriesSummary {
    /// 1-based position in the listing: what `--series N` takes.
    pub index: usize,
    /// SeriesInstanceUID (0020,000E).
    pub uid: String,
    /// When the UID's images differ in size, orientation or pixel spacing, each kind is a
    /// part (1-based); `None` for an unsplit series.
    pub part: Option<usize>,
    /// SeriesDescription (0008,103E).
    pub description: String,
    /// Modality (0008,0060): CT, MR, PT, ...
    pub modality: String,
    /// SeriesNumber (0020,0011).
    pub number: Option<i64>,
    /// Columns, rows and slice positions.
    pub dims: [usize; 3],
    /// Time steps (phases); 1 for a plain volume.
    pub phases: usize,
    /// Files holding its images.
    pub files: usize,
    /// Transfer syntax of its first file, `UID (name)`.
    pub transfer_syntax: String,
    /// Voxel type of the opened volume (`f32` when slices have different rescales).
    pub voxel_type: String,
    /// Why it cannot be opened (missing slices, undecodable syntax ...), if so.
    pub problem: Option<String>,
}

/// A file of the input that is not part of any series, and why.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct SkippedFile {
    pub path: PathBuf,
    pub reason: String,
}

/// The series in an input ([`list`]).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct DicomListing {
    pub series: Vec<SeriesSummary>,
    pub skipped: Vec<SkippedFile>,
    /// The [`SeriesSummary::index`] that [`open`] opens without a pick: the only series, or a
    /// one-file input's own; `None` when a pick is needed.
    pub default_series: Option<usize>,
}

/// The read input: files, their series, the skipped files, and the file named (one-file
/// input).
struct Collection {
    root: PathBuf,
    files: Vec<PathBuf>,
    groups: Vec<Group>,
    skipped: Vec<SkippedFile>,
    focus: Option<usize>,
}

/// True if `path` is read as DICOM by `formats::open`: a folder, a `DICOMDIR`, a `.dcm` /
/// `.dicom` file, or a file with `DICM` at byte 128.
pub fn is_dicom_input(path: &Path) -> bool {
    if path.is_dir() {
        return true;
    }
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default();
    name == "dicomdir"
        || Path::new(&name)
            .extension()
            .is_some_and(|e| e == "dcm" || e == "dicom")
        || (path.is_file() && file::sniff(path))
}

/// Lists the series in `path` (a folder, a DICOMDIR or one file; see the module docs).
pub fn list(path: &Path) -> Result<DicomListing, FormatError> {
    Ok(listing(&collect(path)?))
}

/// Lists the series in `files` (`label` names the list in errors).
pub fn list_files(files: &[PathBuf], label: &Path) -> Result<DicomListing, FormatError> {
    Ok(listing(&collect_files(files.to_vec(), label, None)?))
}

/// [`list`] for any input `formats::open` reads as DICOM (a folder, a DICOMDIR, a DICOM file,
/// or a glob of DICOM files); `None` for other inputs.
pub fn list_input(path: &Path) -> Option<Result<DicomListing, FormatError>> {
    if !path.exists() && crate::series::is_pattern(path) {
        let files = crate::series::expand_pattern(path).ok()?;
        return is_dicom_input(&files[0]).then(|| list_files(&files, path));
    }
    is_dicom_input(path).then(|| list(path))
}

/// Opens the series picked by `pick` (`N` from [`list`], or a SeriesInstanceUID) in `path`,
/// or its only series. One file opens its own series unless `pick` says otherwise.
pub fn open(path: &Path, pick: Option<&str>) -> Result<Dataset, FormatError> {
    open_collection(collect(path)?, pick)
}

/// [`open`] on a list of files.
pub fn open_files(
    files: &[PathBuf],
    label: &Path,
    pick: Option<&str>,
) -> Result<Dataset, FormatError> {
    open_collection(collect_files(files.to_vec(), label, None)?, pick)
}

fn open_collection(c: Collection, pick: Option<&str>) -> Result<Dataset, FormatError> {
    let g = select(&c, pick)?;
    let group = &c.groups[g];
    let plan = series::plan(group, &c.files, &c.root)?;
    series::load(plan, c.files, &c.root)
}

fn listing(c: &Collection) -> DicomListing {
    let series = c
        .groups
        .iter()
        .enumerate()
        .map(|(i, g)| {
            let planned = series::plan(g, &c.files, &c.root);
            let (dims, phases, voxel_type, mut problem) = match &planned {
                Ok(p) => (
                    p.grid.dims(),
                    p.phases.len(),
                    p.voxel_type().name().to_string(),
                    None,
                ),
                Err(e) => (
                    [g.format.cols, g.format.rows, g.slices.len()],
                    1,
                    g.format.voxel_type().name().to_string(),
                    Some(match e {
                        FormatError::DicomSeries { reason, .. } => reason.clone(),
                        other => other.to_string(),
                    }),
                ),
            };
            if !g.decodable && problem.is_none() {
                problem = Some(format!("transfer syntax {} cannot be decoded", g.syntax));
            }
            SeriesSummary {
                index: i + 1,
                uid: g.uid.clone(),
                part: g.part,
                description: g.description.clone(),
                modality: g.modality.clone(),
                number: g.number,
                dims,
                phases,
                files: g.files.len(),
                transfer_syntax: g.syntax.clone(),
                voxel_type,
                problem,
            }
        })
        .collect();
    DicomListing {
        series,
        skipped: c.skipped.clone(),
        default_series: select(c, None).ok().map(|g| g + 1),
    }
}

/// The group `pick` names, or the only (or named file's) group.
fn select(c: &Collection, pick: Option<&str>) -> Result<usize, FormatError> {
    let err = |reason: String| FormatError::DicomSeries {
        path: c.root.clone(),
        reason,
    };
    let root = c.root.display();
    let n = c.groups.len();
    let none_found = || {
        let why = if c.skipped.is_empty() {
            String::new()
        } else {
            let first: Vec<String> = c
                .skipped
                .iter()
                .take(3)
                .map(|s| format!("{}: {}", s.path.display(), s.reason))
                .collect();
            format!(
                " ({} file{} skipped: {}{})",
                c.skipped.len(),
                if c.skipped.len() == 1 { "" } else { "s" },
                first.join("; "),
                if c.skipped.len() > 3 { "; ..." } else { "" }
            )
        };
        err(format!("no DICOM image series found{why}"))
    };
    match pick.map(str::trim) {
        Some(p) if !p.is_empty() && p.bytes().all(|b| b.is_ascii_digit()) => {
            let i: usize = p.parse().unwrap_or(0);
            if n == 0 {
                return Err(none_found());
            }
            if i == 0 || i > n {
                return Err(err(format!(
                    "--series {i}: there {} {n} series in {root} (1 to {n}); `isoscope info {root}` lists them",
                    if n == 1 { "is" } else { "are" }
                )));
            }
            Ok(i - 1)
        }
        Some(uid) => {
            let found: Vec<usize> = (0..n).filter(|&g| c.groups[g].uid == uid).collect();
            match found.as_slice() {
                [one] => Ok(*one),
                [] => Err(err(format!(
                    "--series {uid}: no series with this SeriesInstanceUID in {root}; `isoscope info {root}` lists them"
                ))),
                many => Err(err(format!(
                    "--series {uid}: this series is split into {} parts (their sizes, \
                     orientations or pixel spacings differ): pass --series N with N one of {}",
                    many.len(),
                    many.iter()
                        .map(|g| (g + 1).to_string())
                        .collect::<Vec<_>>()
                        .join(", ")
                ))),
            }
        }
        None => {
            if let Some(f) = c.focus
                && let Some(g) = c.groups.iter().position(|g| g.files.contains(&f))
            {
                return Ok(g);
            }
            match n {
                0 => Err(none_found()),
                1 => Ok(0),
                _ => Err(err(format!(
                    "{n} series in {root}: pass --series N; `isoscope info {root}` lists them"
                ))),
            }
        }
    }
}

/// Reads the input at `path` (see the module docs).
fn collect(path: &Path) -> Result<Collection, FormatError> {
    if path.is_dir() {
        let mut files = Vec::new();
        let mut skipped = Vec::new();
        walk_folder(path, 0, &mut files, &mut skipped)?;
        let mut c = collect_files(files, path, None)?;
        skipped.append(&mut c.skipped);
        c.skipped = skipped;
        return Ok(c);
    }
    let named = file::read(path, file::Want::Attributes)?;
    if named.sop_class_uid == file::DICOMDIR_SOP_CLASS {
        let files = dicomdir_files(&named)?;
        return collect_files(files, path, None);
    }
    // One file: the DICOM files of its folder, itself first.
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let mut files = vec![path.to_path_buf()];
    let mut skipped = Vec::new();
    for entry in read_folder(&dir)? {
        if entry.is_file() && !same_file(&entry, path) {
            if file::sniff(&entry) {
                files.push(entry);
            } else {
                skipped.push(SkippedFile {
                    path: entry,
                    reason: "not a DICOM file".into(),
                });
            }
        }
    }
    let mut c = collect_files(files, path, Some(0))?;
    skipped.append(&mut c.skipped);
    c.skipped = skipped;
    Ok(c)
}

fn same_file(a: &Path, b: &Path) -> bool {
    a == b || crate::input::resolved_path(a) == crate::input::resolved_path(b)
}

/// The entries of `dir`, in natural order of their names.
fn read_folder(dir: &Path) -> Result<Vec<PathBuf>, FormatError> {
    let mut out: Vec<PathBuf> = std::fs::read_dir(dir)
        .map_err(|e| FormatError::io(dir, e))?
        .map(|e| e.map(|e| e.path()).map_err(|e| FormatError::io(dir, e)))
        .collect::<Result<_, _>>()?;
    out.sort_by(|a, b| crate::series::natural_cmp(&a.to_string_lossy(), &b.to_string_lossy()));
    Ok(out)
}

/// Files below `dir` that start like DICOM; others are noted as skipped.
fn walk_folder(
    dir: &Path,
    depth: usize,
    files: &mut Vec<PathBuf>,
    skipped: &mut Vec<SkippedFile>,
) -> Result<(), FormatError> {
    for entry in read_folder(dir)? {
        let Ok(meta) = std::fs::symlink_metadata(&entry) else {
            continue;
        };
        if meta.is_dir() {
            if depth + 1 >= MAX_FOLDER_DEPTH {
                skipped.push(SkippedFile {
                    path: entry,
                    reason: format!("a folder deeper than {MAX_FOLDER_DEPTH} levels"),
                });
            } else {
                walk_folder(&entry, depth + 1, files, skipped)?;
            }
        } else if entry.is_file() {
            // Regular files and links to them (a link to a folder is not followed).
            if file::sniff(&entry) {
                files.push(entry);
            } else {
                skipped.push(SkippedFile {
                    path: entry,
                    reason: "not a DICOM file".into(),
                });
            }
        } else if !meta.is_symlink() || !entry.is_dir() {
            skipped.push(SkippedFile {
                path: entry,
                reason: "not a regular file".into(),
            });
        }
    }
    Ok(())
}

/// The files a DICOMDIR's directory records reference (ReferencedFileID, relative to the
/// DICOMDIR's folder), each checked to exist.
fn dicomdir_files(dir_file: &file::DicomFile) -> Result<Vec<PathBuf>, FormatError> {
    use dicom_dictionary_std::tags;
    let path = &dir_file.path;
    let base = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let bad = |reason: String| FormatError::DicomSeries {
        path: path.clone(),
        reason: format!("DICOMDIR: {reason}"),
    };
    let Some(records) = dir_file
        .attributes
        .get(tags::DIRECTORY_RECORD_SEQUENCE)
        .and_then(|e| e.value().items())
    else {
        return Err(bad("no DirectoryRecordSequence (0004,1220)".into()));
    };
    let mut files = Vec::new();
    for (r, record) in records.iter().enumerate() {
        let Some(id) = record.get(tags::REFERENCED_FILE_ID) else {
            continue;
        };
        let parts: Vec<String> = id
            .value()
            .to_multi_str()
            .map_err(|e| bad(format!("record {}: ReferencedFileID: {e}", r + 1)))?
            .iter()
            .map(|s| s.trim_matches(|c: char| c == '\0' || c == ' ').to_string())
            .collect();
        if parts.is_empty()
            || parts
                .iter()
                .any(|p| p.is_empty() || p == "." || p == ".." || p.contains(['/', '\\', ':']))
        {
            return Err(bad(format!(
                "record {}: ReferencedFileID {:?} is not a relative path of plain names",
                r + 1,
                parts.join("\\")
            )));
        }
        let file = resolve(&base, &parts).ok_or_else(|| {
            bad(format!(
                "record {} references {}, which does not exist",
                r + 1,
                base.join(parts.join("/")).display()
            ))
        })?;
        if !files.contains(&file) {
            files.push(file);
        }
    }
    Ok(files)
}

/// `base/parts...`, matching each name case-insensitively when the exact one is absent
/// (DICOMDIR names are upper case; copies on other file systems may not be).
fn resolve(base: &Path, parts: &[String]) -> Option<PathBuf> {
    let mut at = base.to_path_buf();
    for p in parts {
        let exact = at.join(p);
        at = if exact.exists() {
            exact
        } else {
            std::fs::read_dir(&at)
                .ok()?
                .filter_map(Result::ok)
                .map(|e| e.path())
                .find(|e| {
                    e.file_name()
                        .is_some_and(|n| n.to_string_lossy().eq_ignore_ascii_case(p))
                })?
        };
    }
    at.is_file().then_some(at)
}

/// Reads the attributes of `files` (in parallel) and groups their images. A file that cannot
/// be read is an error, except, for a one-file input (`focus`), another file of its folder
/// that does not contain the named file's SeriesInstanceUID: that one is noted and skipped.
fn collect_files(
    files: Vec<PathBuf>,
    root: &Path,
    focus: Option<usize>,
) -> Result<Collection, FormatError> {
    let results: Vec<Result<Content, FormatError>> = files
        .par_iter()
        .map(|f| {
            let dicom = file::read(f, file::Want::ImageAttributes)?;
            attributes::content(&dicom)
        })
        .collect();
    let focus_uid = focus.and_then(|f| match &results[f] {
        Ok(Content::Image(info)) if !info.series_uid.is_empty() => Some(info.series_uid.clone()),
        _ => None,
    });
    let mut skipped = Vec::new();
    let mut contents = Vec::with_capacity(files.len());
    for (i, r) in results.into_iter().enumerate() {
        match r {
            Ok(c) => contents.push(Some(c)),
            Err(e) => match &focus_uid {
                Some(uid) if Some(i) != focus && !mentions(&files[i], uid) => {
                    skipped.push(SkippedFile {
                        path: files[i].clone(),
                        reason: format!("unreadable, and not of the opened series: {e}"),
                    });
                    contents.push(None);
                }
                _ => return Err(e),
            },
        }
    }
    let mut images = Vec::new();
    for (i, c) in contents.iter().enumerate() {
        match c {
            Some(Content::Image(info)) => images.push((i, info.as_ref())),
            Some(Content::Skip(reason)) => skipped.push(SkippedFile {
                path: files[i].clone(),
                reason: reason.clone(),
            }),
            None => {}
        }
    }
    let groups = series::group(&images);
    if let Some(f) = focus
        && let Some(Content::Skip(reason)) = &contents[f]
    {
        return Err(FormatError::DicomFile {
            path: files[f].clone(),
            reason: format!("not a volume slice: {reason}"),
        });
    }
    Ok(Collection {
        root: root.to_path_buf(),
        files,
        groups,
        skipped,
        focus,
    })
}

/// True if the bytes of `path` contain `uid` (or cannot be read: then assume they might).
fn mentions(path: &Path, uid: &str) -> bool {
    crate::input::read_regular(path).map_or(true, |bytes| {
        bytes.windows(uid.len()).any(|w| w == uid.as_bytes())
    })
}
