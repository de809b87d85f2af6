//! # MetaImage: `.mha` (header and data in one file) and `.mhd` (detached data)
//!
//! The format of ITK's MetaIO library (seed: MetaIO documentation, "MetaImage"): text lines
//! `Key = Value`, the last of which is `ElementDataFile`; binary voxels follow it (`LOCAL`)
//! or are in other files.
//!
//! - Read: `ObjectType = Image`, `NDims` 3 or 4 (4: a time series, one volume per sample of
//!   the last axis), `DimSize`, `ElementType` `MET_UCHAR`, `MET_CHAR`, `MET_USHORT`,
//!   `MET_SHORT`, `MET_UINT`, `MET_INT`, `MET_ULONG`, `MET_LONG` (4 bytes in MetaIO's type
//!   table), `MET_FLOAT`, `MET_DOUBLE` (64-bit integers, arrays and strings are refused by
//!   name), `ElementSpacing` (else `ElementSize`, else 1), `Offset` = `Position` = `Origin`,
//!   `TransformMatrix` = `Rotation` = `Orientation` (the direction of grid axis `k` is the
//!   k-th group of `NDims` numbers), `ElementByteOrderMSB` = `BinaryDataByteOrderMSB`,
//!   `HeaderSize` (bytes before the data in each data file, counted from the file's start as
//!   MetaIO seeks; `-1`: the data ends the file), `CompressedData` (zlib, or gzip) with the
//!   optional `CompressedDataSize`, `ElementDataFile` = `LOCAL`, a file name, a printf
//!   pattern with optional `min max step` (one file per slice of the last axis), or `LIST
//!   [dims]` followed by one file name per line. `ElementNumberOfChannels` must be 1.
//!   Other keys (comments, `CenterOfRotation`, `ElementMin`, user keys) are ignored, as
//!   MetaIO does.
//! - Data is read by the NRRD data plan ([`crate::nrrd`]): uncompressed data in one file
//!   (`LOCAL` or detached) is memory-mapped and viewed in place when native-endian and
//!   aligned, as [`crate::raw`] does; a 4D file's steps load lazily (views into the one map).
//! - World frame: MetaImage is ITK's, whose world is LPS. `AnatomicalOrientation` names
//!   where each grid axis comes *from* in ITK's convention (identity direction: `RAI`); when
//!   it agrees with the direction matrix the frame is LPS. Some writers spell the letters the
//!   axes point *to* (`LPS` for the identity): also LPS. Letters that match the direction
//!   only in a RAS world (`LPI` from, `RAS` to, for the identity) make the frame RAS; any
//!   other value makes it unknown rather than guessed.
//!
//! Errors name the file, the key and its line. Sizes are checked against the files before
//! anything is allocated: raw data must fill its file exactly; compressed data may not claim
//! more than zlib can inflate its bytes to.

use std::io::Read as _;
use std::path::{Path, PathBuf};

use glam::DVec3;

use volume_core::{VoxelType, WorldFrame};

use crate::Dataset;
use crate::error::FormatError;
use crate::nrrd::{DataPlan, Encoding, PlanParts, VolumeLayout};
use crate::oriented::{checked_dims, image_grid};
use crate::raw::Endian;

/// The most header bytes read (a `LIST` of many slice files included).
pub const MAX_HEADER_BYTES: usize = 4 << 20;

/// The most data files a pattern or `LIST` may name.
pub const MAX_DATA_FILES: usize = 1 << 20;

/// Where the voxels are.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum DataFile {
    /// After the header, in the same file.
    Local,
    /// One file (relative to the header's folder unless absolute).
    File(String),
    /// A printf pattern: file `i` is `format(min + i·step)`, one per slice of the last axis.
    Pattern { format: String, min: i64, step: i64 },
    /// The files listed after the `ElementDataFile` line, each holding `file_dims` axes.
    List {
        file_dims: usize,
        files: Vec<String>,
    },
}

/// A parsed MetaImage header.
#[derive(Debug, Clone, PartialEq)]
pub struct MetaHeader {
    /// 3 or 4.
    pub ndims: usize,
    pub dim_size: Vec<usize>,
    pub element_type: VoxelType,
    pub spacing: Vec<f64>,
    pub offset: Vec<f64>,
    /// `ndims²` numbers, grid axis by grid axis.
    pub transform: Option<Vec<f64>>,
    pub big_endian: bool,
    /// Bytes before the data in each data file; `-1`: the data ends the file.
    pub header_size: i64,
    pub compressed: bool,
    pub compressed_size: Option<u64>,
    pub data_file: DataFile,
    pub anatomical_orientation: Option<String>,
    /// Bytes of the header (through the `ElementDataFile` line and a `LIST`'s names).
    pub header_len: usize,
    /// Line number of each key read (for errors).
    pub lines: Vec<(String, usize)>,
}

impl MetaHeader {
    /// The line of `key` (0 if absent).
    pub fn line_of(&self, key: &str) -> usize {
        self.lines
            .iter()
            .find(|(k, _)| k.eq_ignore_ascii_case(key))
            .map_or(0, |(_, l)| *l)
    }

    fn bad(&self, path: &Path, key: &str, reason: String) -> FormatError {
        FormatError::BadValue {
            path: path.to_path_buf(),
            line: self.line_of(key),
            field: key.into(),
            reason,
        }
    }

    /// Voxels in all files.
    pub fn element_count(&self) -> Option<u64> {
        self.dim_size
            .iter()
            .try_fold(1u64, |acc, &d| acc.checked_mul(d as u64))
    }
}

fn element_type(name: &str) -> Result<VoxelType, String> {
    Ok(match name {
        "MET_UCHAR" => VoxelType::U8,
        "MET_CHAR" => VoxelType::I8,
        "MET_USHORT" => VoxelType::U16,
        "MET_SHORT" => VoxelType::I16,
        // MetaIO's value type sizes: MET_LONG and MET_ULONG are 4 bytes.
        "MET_UINT" | "MET_ULONG" => VoxelType::U32,
        "MET_INT" | "MET_LONG" => VoxelType::I32,
        "MET_FLOAT" => VoxelType::F32,
        "MET_DOUBLE" => VoxelType::F64,
        "MET_LONG_LONG" | "MET_ULONG_LONG" => {
            return Err(format!(
                "{name}: 64-bit integer voxels are not supported (8 to 32-bit integers, \
                 MET_FLOAT and MET_DOUBLE are)"
            ));
        }
        other => {
            return Err(format!(
                "{other:?} is not a scalar voxel type read here (MET_UCHAR, MET_CHAR, \
                 MET_USHORT, MET_SHORT, MET_UINT, MET_INT, MET_ULONG, MET_LONG, MET_FLOAT, \
                 MET_DOUBLE)"
            ));
        }
    })
}

/// Canonical key names (synonyms folded), compared case-insensitively.
fn canonical(key: &str) -> String {
    match key.to_ascii_lowercase().as_str() {
        "position" | "origin" | "offset" => "Offset".into(),
        "rotation" | "orientation" | "transformmatrix" => "TransformMatrix".into(),
        "elementbyteordermsb" | "binarydatabyteordermsb" => "ElementByteOrderMSB".into(),
        _ => key.to_owned(),
    }
}

/// Parses header bytes (`path` names the file in errors). `bytes` may go on past the header
/// (the data of a `.mha`); [`MetaHeader::header_len`] says where the header ends.
pub fn parse_header(path: &Path, bytes: &[u8]) -> Result<MetaHeader, FormatError> {
    let mut fields: Vec<(String, String, usize)> = Vec::new();
    let mut pos = 0usize;
    let mut line_no = 0usize;
    let mut data_file: Option<(String, usize)> = None;
    let bad_line = |line: usize, reason: String| FormatError::BadLine {
        path: path.to_path_buf(),
        line,
        reason,
    };
    // Lines up to and including `ElementDataFile`.
    while pos < bytes.len() {
        line_no += 1;
        let end = bytes[pos..]
            .iter()
            .position(|&b| b == b'\n')
            .map_or(bytes.len(), |i| pos + i);
        let raw = &bytes[pos..end];
        pos = (end + 1).min(bytes.len());
        if raw.len() > 64 * 1024 {
            return Err(bad_line(line_no, "line longer than 64 KiB".into()));
        }
        let text = std::str::from_utf8(raw)
            .map_err(|_| bad_line(line_no, "not UTF-8 text".into()))?
            .trim();
        if text.is_empty() {
            continue;
        }
        let Some((key, value)) = text.split_once('=') else {
            return Err(bad_line(
                line_no,
                format!(
                    "expected `Key = Value`, found {:?}",
                    text.chars().take(60).collect::<String>()
                ),
            ));
        };
        let key = key.trim();
        let value = value.trim();
        if key.is_empty() || key.contains(char::is_whitespace) {
            return Err(bad_line(line_no, format!("bad key {key:?}")));
        }
        let key = canonical(key);
        if fields.iter().any(|(k, _, _)| k.eq_ignore_ascii_case(&key)) {
            return Err(FormatError::DuplicateField {
                path: path.to_path_buf(),
                line: line_no,
                field: key,
            });
        }
        if key.eq_ignore_ascii_case("ElementDataFile") {
            data_file = Some((value.to_owned(), line_no));
            fields.push(("ElementDataFile".into(), value.to_owned(), line_no));
            break;
        }
        fields.push((key, value.to_owned(), line_no));
    }
    let get = |k: &str| {
        fields
            .iter()
            .find(|(key, _, _)| key.eq_ignore_ascii_case(k))
            .map(|(_, v, l)| (v.as_str(), *l))
    };
    let lines: Vec<(String, usize)> = fields.iter().map(|(k, _, l)| (k.clone(), *l)).collect();
    let missing = |field: &'static str, reason: &str| FormatError::MissingField {
        path: path.to_path_buf(),
        field,
        reason: reason.into(),
    };
    let bad = |key: &str, line: usize, reason: String| FormatError::BadValue {
        path: path.to_path_buf(),
        line,
        field: key.into(),
        reason,
    };
    if fields.is_empty() {
        return Err(missing("NDims", "the file has no `Key = Value` lines"));
    }
    let Some((data_file_value, data_line)) = data_file else {
        return Err(missing(
            "ElementDataFile",
            "the header must end with it (is this a MetaImage file?)",
        ));
    };
    if let Some((v, line)) = get("ObjectType")
        && !v.eq_ignore_ascii_case("Image")
    {
        return Err(FormatError::Unsupported {
            path: path.to_path_buf(),
            field: "ObjectType".into(),
            reason: format!("{v:?} at line {line}: only Image objects are volumes"),
        });
    }
    let (nd, nd_line) = get("NDims").ok_or_else(|| missing("NDims", ""))?;
    let ndims: usize = nd
        .parse()
        .map_err(|_| bad("NDims", nd_line, format!("{nd:?} is not a number")))?;
    if !(3..=4).contains(&ndims) {
        return Err(FormatError::Unsupported {
            path: path.to_path_buf(),
            field: "NDims".into(),
            reason: format!(
                "{ndims} dimensions at line {nd_line}: volumes have 3 (4 with time steps)"
            ),
        });
    }
    let numbers = |key: &str, count: usize| -> Result<Option<Vec<f64>>, FormatError> {
        let Some((v, line)) = get(key) else {
            return Ok(None);
        };
        let values: Vec<f64> = v
            .split_ascii_whitespace()
            .map(|w| {
                w.parse::<f64>()
                    .map_err(|_| bad(key, line, format!("{w:?} is not a number")))
            })
            .collect::<Result<_, _>>()?;
        if values.len() != count {
            return Err(bad(
                key,
                line,
                format!(
                    "{} numbers, expected {count} (NDims = {ndims})",
                    values.len()
                ),
            ));
        }
        if let Some(x) = values.iter().find(|x| !x.is_finite()) {
            return Err(bad(key, line, format!("{x} is not finite")));
        }
        Ok(Some(values))
    };
    let (ds, ds_line) = get("DimSize").ok_or_else(|| missing("DimSize", ""))?;
    let dim_size: Vec<usize> = ds
        .split_ascii_whitespace()
        .map(|w| {
            w.parse::<usize>()
                .ok()
                .filter(|&n| n >= 1)
                .ok_or_else(|| bad("DimSize", ds_line, format!("{w:?} is not a size >= 1")))
        })
        .collect::<Result<_, _>>()?;
    if dim_size.len() != ndims {
        return Err(bad(
            "DimSize",
            ds_line,
            format!("{} sizes, expected {ndims} (NDims)", dim_size.len()),
        ));
    }
    let (et, et_line) = get("ElementType").ok_or_else(|| missing("ElementType", ""))?;
    let element_type = element_type(et).map_err(|reason| FormatError::Unsupported {
        path: path.to_path_buf(),
        field: "ElementType".into(),
        reason: format!("line {et_line}: {reason}"),
    })?;
    if let Some((c, line)) = get("ElementNumberOfChannels")
        && c != "1"
    {
        return Err(FormatError::Unsupported {
            path: path.to_path_buf(),
            field: "ElementNumberOfChannels".into(),
            reason: format!("{c} at line {line}: only scalar images (1 channel) are volumes"),
        });
    }
    let flag = |key: &str| -> Result<Option<bool>, FormatError> {
        match get(key) {
            None => Ok(None),
            Some((v, line)) => match v.to_ascii_lowercase().as_str() {
                "true" | "1" => Ok(Some(true)),
                "false" | "0" => Ok(Some(false)),
                _ => Err(bad(key, line, format!("{v:?} is not True or False"))),
            },
        }
    };
    if flag("BinaryData")? == Some(false) {
        return Err(FormatError::Unsupported {
            path: path.to_path_buf(),
            field: "BinaryData".into(),
            reason: "ASCII voxels (BinaryData = False) are not read".into(),
        });
    }
    let spacing = match numbers("ElementSpacing", ndims)? {
        Some(s) => s,
        None => numbers("ElementSize", ndims)?.unwrap_or_else(|| vec![1.0; ndims]),
    };
    let offset = numbers("Offset", ndims)?.unwrap_or_else(|| vec![0.0; ndims]);
    let transform = numbers("TransformMatrix", ndims * ndims)?;
    let big_endian = flag("ElementByteOrderMSB")?.unwrap_or(false);
    let compressed = flag("CompressedData")?.unwrap_or(false);
    let header_size = match get("HeaderSize") {
        None => 0,
        Some((v, line)) => v
            .parse::<i64>()
            .ok()
            .filter(|&h| h >= -1)
            .ok_or_else(|| bad("HeaderSize", line, format!("{v:?} is not a size or -1")))?,
    };
    let compressed_size = match get("CompressedDataSize") {
        None => None,
        Some((v, line)) => Some(
            v.parse::<u64>()
                .map_err(|_| bad("CompressedDataSize", line, format!("{v:?} is not a size")))?,
        )
        .filter(|&n| n > 0),
    };
    let mut header_len = pos;
    let data_file = if data_file_value.eq_ignore_ascii_case("LOCAL") {
        DataFile::Local
    } else if is_list(&data_file_value) {
        // `is_list` checked that the first 4 bytes are ASCII.
        let dims_word = data_file_value.get(4..).unwrap_or("").trim();
        let file_dims = if dims_word.is_empty() {
            ndims - 1
        } else {
            let digits = dims_word.trim_end_matches(['D', 'd']);
            match digits.parse::<usize>() {
                Ok(d) if (1..=ndims).contains(&d) => d,
                // MetaIO falls back to NDims − 1 for 0 or too many.
                Ok(_) => ndims - 1,
                Err(_) => {
                    return Err(bad(
                        "ElementDataFile",
                        data_line,
                        format!("LIST {dims_word:?}: expected a dimension such as 2D"),
                    ));
                }
            }
        };
        let count = dim_size[file_dims..]
            .iter()
            .try_fold(1usize, |acc, &d| acc.checked_mul(d))
            .filter(|&n| n <= MAX_DATA_FILES)
            .ok_or_else(|| {
                bad(
                    "ElementDataFile",
                    data_line,
                    format!("LIST: more than {MAX_DATA_FILES} data files"),
                )
            })?;
        // A name takes at least two bytes (a character and a newline).
        let mut files = Vec::with_capacity(count.min(bytes.len().saturating_sub(pos) / 2));
        while files.len() < count && pos < bytes.len() {
            let end = bytes[pos..]
                .iter()
                .position(|&b| b == b'\n')
                .map_or(bytes.len(), |i| pos + i);
            let name = std::str::from_utf8(&bytes[pos..end])
                .map_err(|_| bad_line(line_no + files.len() + 1, "not UTF-8 text".into()))?
                .trim();
            pos = (end + 1).min(bytes.len());
            if !name.is_empty() {
                files.push(name.to_owned());
            }
        }
        if files.len() < count {
            return Err(bad(
                "ElementDataFile",
                data_line,
                format!(
                    "LIST names {} files, {count} needed for DimSize {dim_size:?} with \
                     {file_dims}-dimensional files",
                    files.len()
                ),
            ));
        }
        header_len = pos;
        DataFile::List { file_dims, files }
    } else if data_file_value.contains('%') {
        let words: Vec<&str> = data_file_value.split_ascii_whitespace().collect();
        if dim_size[ndims - 1] > MAX_DATA_FILES {
            return Err(bad(
                "ElementDataFile",
                data_line,
                format!(
                    "a pattern of {} files (one per slice of the last axis): more than {MAX_DATA_FILES}",
                    dim_size[ndims - 1]
                ),
            ));
        }
        let last = dim_size[ndims - 1] as i64;
        let num = |i: usize| -> Result<Option<i64>, FormatError> {
            words
                .get(i)
                .map(|w| {
                    w.parse::<i64>().map_err(|_| {
                        bad(
                            "ElementDataFile",
                            data_line,
                            format!("pattern: {w:?} is not an integer"),
                        )
                    })
                })
                .transpose()
        };
        let min = num(1)?.unwrap_or(1);
        let step = match (num(2)?, num(3)?) {
            (_, Some(step)) => step,
            // MetaIO: with only `min max`, the step is (max − min) / slices.
            (Some(max), None) => ((max - min) / last).max(1),
            (None, None) => 1,
        };
        crate::nrrd::header::check_printf(words[0])
            .map_err(|r| bad("ElementDataFile", data_line, format!("pattern: {r}")))?;
        if words.len() > 4 || step == 0 {
            return Err(bad(
                "ElementDataFile",
                data_line,
                format!("pattern {data_file_value:?}: expected `name%d [min [max [step]]]`"),
            ));
        }
        DataFile::Pattern {
            format: words[0].to_owned(),
            min,
            step,
        }
    } else {
        DataFile::File(data_file_value.clone())
    };
    Ok(MetaHeader {
        ndims,
        dim_size,
        element_type,
        spacing,
        offset,
        transform,
        big_endian,
        header_size,
        compressed,
        compressed_size,
        data_file,
        anatomical_orientation: get("AnatomicalOrientation").map(|(v, _)| v.to_owned()),
        header_len,
        lines,
    })
}

/// Reads the header bytes of `path`: through the `ElementDataFile` line (and a `LIST`'s
/// names), at most [`MAX_HEADER_BYTES`].
pub fn read_header_bytes(path: &Path) -> Result<Vec<u8>, FormatError> {
    let mut file = crate::input::open_regular(path).map_err(|e| FormatError::io(path, e))?;
    let mut buf = Vec::new();
    let mut chunk = vec![0u8; 1 << 16];
    loop {
        let n = file
            .read(&mut chunk)
            .map_err(|e| FormatError::io(path, e))?;
        if n == 0 {
            return Ok(buf);
        }
        buf.extend_from_slice(&chunk[..n]);
        if buf.len() >= MAX_HEADER_BYTES {
            return Ok(buf);
        }
        // Done once the ElementDataFile line is complete, unless it starts a LIST (then the
        // parser needs the names that follow: read on, up to the limit).
        if let Some(at) = find_key_line(&buf, b"ElementDataFile")
            && let Some(nl) = buf[at..].iter().position(|&b| b == b'\n')
        {
            let line = String::from_utf8_lossy(&buf[at..at + nl]);
            let value = line.split_once('=').map_or("", |(_, v)| v.trim());
            if !is_list(value) {
                return Ok(buf);
            }
        }
    }
}

/// True for an `ElementDataFile` value `LIST [dims]`.
fn is_list(value: &str) -> bool {
    value
        .get(..4)
        .is_some_and(|p| p.eq_ignore_ascii_case("LIST"))
}

/// The start of a line beginning with `key` (case-insensitive).
fn find_key_line(buf: &[u8], key: &[u8]) -> Option<usize> {
    let mut start = 0;
    while start < buf.len() {
        let line = &buf[start..];
        let trimmed = line
            .iter()
            .position(|b| !b.is_ascii_whitespace() || *b == b'\n')
            .unwrap_or(0);
        let l = &line[trimmed..];
        if l.len() >= key.len() && l[..key.len()].eq_ignore_ascii_case(key) {
            return Some(start);
        }
        match line.iter().position(|&b| b == b'\n') {
            Some(i) => start += i + 1,
            None => return None,
        }
    }
    None
}

/// Reads and parses the header of the MetaImage at `path`.
pub fn read_header(path: &Path) -> Result<MetaHeader, FormatError> {
    parse_header(path, &read_header_bytes(path)?)
}

/// How many data files a header names: one per slice for a pattern, one per name for a
/// `LIST`, else one.
pub fn data_file_count(header: &MetaHeader) -> usize {
    match &header.data_file {
        DataFile::Local | DataFile::File(_) => 1,
        DataFile::Pattern { .. } => header.dim_size[header.ndims - 1],
        DataFile::List { files, .. } => files.len(),
    }
}

/// The data file number `i` (`i < data_file_count`) of a header at `path`. A pattern's names
/// are made one at a time: a 100-byte header can name 2^20 files.
pub fn data_file_path(header: &MetaHeader, path: &Path, i: usize) -> PathBuf {
    let resolve = |name: &str| crate::input::beside(path, name);
    match &header.data_file {
        DataFile::Local => path.to_path_buf(),
        DataFile::File(name) => resolve(name),
        DataFile::Pattern { format, min, step } => {
            let n = min.saturating_add((i as i64).saturating_mul(*step));
            resolve(&crate::nrrd::header::format_printf(format, n))
        }
        DataFile::List { files, .. } => resolve(&files[i]),
    }
}

/// The data files of a header at `path`, in order.
pub fn data_file_paths(header: &MetaHeader, path: &Path) -> Vec<PathBuf> {
    (0..data_file_count(header))
        .map(|i| data_file_path(header, path, i))
        .collect()
}

/// The world frame the header's `AnatomicalOrientation` and direction matrix give (module
/// docs).
pub fn world_frame(header: &MetaHeader, axis_dirs: [DVec3; 3]) -> WorldFrame {
    let Some(code) = header.anatomical_orientation.as_deref() else {
        return WorldFrame::Lps;
    };
    let code = code.trim().to_ascii_uppercase();
    let letters: Vec<char> = code.chars().collect();
    if letters.len() < 3 || letters.iter().take(3).all(|&c| c == '?') {
        return WorldFrame::Lps;
    }
    // The letter each grid axis points to (`to`) or comes from (`from`) in `frame`.
    let spelled = |frame: WorldFrame, to: bool| -> Option<Vec<char>> {
        axis_dirs
            .iter()
            .map(|&d| frame.direction_letter(if to { d } else { -d }))
            .collect()
    };
    let is = |frame, to| spelled(frame, to).is_some_and(|s| s[..] == letters[..3]);
    if is(WorldFrame::Lps, false) || is(WorldFrame::Lps, true) {
        WorldFrame::Lps
    } else if is(WorldFrame::Ras, false) || is(WorldFrame::Ras, true) {
        WorldFrame::Ras
    } else {
        WorldFrame::Unknown
    }
}

/// Reads a MetaImage: a volume, or (`NDims = 4`) a lazily loaded time series.
pub fn read_metaimage(path: &Path) -> Result<Dataset, FormatError> {
    let header = read_header(path)?;
    let (plan, layout, step_bytes) = plan(path, &header)?;
    crate::nrrd::planned_dataset(path, plan, layout, step_bytes, "MetaImage")
}

/// The geometry, the data plan and the bytes per step of a parsed header.
fn plan(path: &Path, h: &MetaHeader) -> Result<(DataPlan, VolumeLayout, u64), FormatError> {
    let nd = h.ndims;
    let dims = [h.dim_size[0], h.dim_size[1], h.dim_size[2]];
    let voxels = checked_dims(path, dims, ("DimSize", h.line_of("DimSize")))?;
    let steps = if nd == 4 { h.dim_size[3] } else { 1 };
    let size = h.element_type.size_bytes() as u64;
    let step_bytes = (voxels as u64)
        .checked_mul(size)
        .ok_or_else(|| h.bad(path, "DimSize", format!("{:?} voxels overflow", h.dim_size)))?;
    let total = step_bytes
        .checked_mul(steps as u64)
        .filter(|&t| usize::try_from(t).is_ok())
        .ok_or_else(|| h.bad(path, "DimSize", format!("{:?} voxels overflow", h.dim_size)))?;
    // Grid axis k's direction: the k-th group of NDims numbers; the time axis must not mix
    // with space.
    let axis_dirs = match &h.transform {
        None => None,
        Some(m) => {
            let col = |k: usize| [m[k * nd], m[k * nd + 1], m[k * nd + 2]];
            if nd == 4 {
                let mixed =
                    (0..3).any(|k| m[k * nd + 3] != 0.0) || (0..3).any(|c| m[3 * nd + c] != 0.0);
                if mixed {
                    return Err(FormatError::Unsupported {
                        path: path.to_path_buf(),
                        field: "TransformMatrix".into(),
                        reason: "the time axis is mixed with the spatial axes".into(),
                    });
                }
            }
            Some([col(0), col(1), col(2)])
        }
    };
    let grid = image_grid(
        path,
        dims,
        [0; 3],
        [h.offset[0], h.offset[1], h.offset[2]],
        [h.spacing[0], h.spacing[1], h.spacing[2]],
        axis_dirs,
        ("ElementSpacing", h.line_of("ElementSpacing")),
    )?;
    let dirs = [0, 1, 2].map(|a| grid.axis_direction(a));
    let grid = grid.with_world_frame(world_frame(h, dirs));
    let time = (nd == 4).then(|| (h.offset[3], h.spacing[3]));
    let layout = VolumeLayout { grid, steps, time };

    // A pattern names one file per slice: its last file must exist before the list of them
    // all is made (a 100-byte header can name 2^20 files, a few hundred MB of names).
    if let DataFile::Pattern { .. } = &h.data_file {
        let last_file = data_file_path(h, path, data_file_count(h) - 1);
        crate::input::check_regular(&last_file).map_err(|e| FormatError::io(&last_file, e))?;
    }
    let files = data_file_paths(h, path);
    if total % files.len() as u64 != 0 {
        return Err(h.bad(
            path,
            "ElementDataFile",
            format!(
                "{} data files do not divide {total} bytes evenly",
                files.len()
            ),
        ));
    }
    let local = h.data_file == DataFile::Local;
    if h.header_size > 0 && local && (h.header_size as u64) < h.header_len as u64 {
        return Err(h.bad(
            path,
            "HeaderSize",
            format!(
                "{} bytes, but the header itself is {} bytes long",
                h.header_size, h.header_len
            ),
        ));
    }
    let header_end = if local { h.header_len as u64 } else { 0 };
    let parts = if h.compressed {
        if h.header_size == -1 {
            return Err(h.bad(
                path,
                "HeaderSize",
                "-1 (data at the end) with CompressedData: the compressed size is unknown".into(),
            ));
        }
        let start = if h.header_size > 0 {
            h.header_size as u64
        } else {
            header_end
        };
        let compressed_bytes = if files.len() == 1 {
            h.compressed_size
        } else {
            None
        };
        check_compressed(path, h, &files, start, compressed_bytes, total)?;
        PlanParts {
            files,
            base_offset: start,
            total_bytes: total,
            encoding: Encoding::Gzip,
            zlib: true,
            endian: endian(h),
            voxel_type: h.element_type,
            byte_skip: 0,
            compressed_bytes,
        }
    } else {
        let (base_offset, byte_skip) = match h.header_size {
            -1 => (header_end, -1),
            0 => (header_end, 0),
            n => (0, n),
        };
        PlanParts {
            files,
            base_offset,
            total_bytes: total,
            encoding: Encoding::Raw,
            zlib: false,
            endian: endian(h),
            voxel_type: h.element_type,
            byte_skip,
            compressed_bytes: None,
        }
    };
    Ok((DataPlan::from_parts(parts), layout, step_bytes))
}

fn endian(h: &MetaHeader) -> Endian {
    if h.big_endian {
        Endian::Big
    } else {
        Endian::Little
    }
}

/// Compressed data may not claim more than its bytes can inflate to, nor more bytes than
/// its file holds (checked before anything is decoded).
fn check_compressed(
    path: &Path,
    h: &MetaHeader,
    files: &[PathBuf],
    start: u64,
    compressed_bytes: Option<u64>,
    total: u64,
) -> Result<(), FormatError> {
    let mut available = 0u64;
    for f in files {
        let len = std::fs::metadata(f)
            .map_err(|e| FormatError::io(f, e))?
            .len();
        let here = len.saturating_sub(start);
        if let Some(n) = compressed_bytes
            && n > here
        {
            return Err(FormatError::TooShort {
                path: f.clone(),
                offset: start,
                needed: n,
                available: len,
            });
        }
        available = available.saturating_add(compressed_bytes.unwrap_or(here));
    }
    // Deflate's best ratio is 1032:1; slack for the stream headers of every file.
    let most = available
        .saturating_mul(1032)
        .saturating_add(1024 * files.len() as u64);
    if total > most {
        return Err(h.bad(
            path,
            "DimSize",
            format!(
                "{total} bytes of voxels cannot come from {available} compressed bytes \
                 (zlib inflates to at most {most})"
            ),
        ));
    }
    Ok(())
}
