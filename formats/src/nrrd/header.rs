//! The NRRD header parser (format definition: teem.sourceforge.net/nrrd/format.html, the
//! NRRD0001–NRRD0005 magics as Teem reads and writes them).
//!
//! [`parse_header`] turns the header text into a [`NrrdHeader`], checking every field on its
//! own and against the others (counts per axis, `spacings` vs `space directions`, `byte skip
//! -1` only with raw data, `endian` required for multi-byte binary data ...). It never reads
//! data and never allocates in proportion to a number found in the header, so it is the fuzz
//! target (`formats/fuzz`).

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use volume_core::VoxelType;

use crate::error::FormatError;
use crate::raw::Endian;

/// Longest header accepted (comments, key/values and `LIST` file names included).
pub const MAX_HEADER_BYTES: usize = 16 << 20;

/// Most data files a detached header may name (a printf pattern could name billions).
pub const MAX_DATA_FILES: u64 = 1 << 20;

/// Largest `dimension` accepted (Teem's `NRRD_DIM_MAX`).
pub const MAX_DIMENSION: usize = 16;

/// How the data bytes are encoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Encoding {
    Raw,
    Ascii,
    Hex,
    Gzip,
    Bzip2,
}

impl Encoding {
    pub const fn name(self) -> &'static str {
        match self {
            Encoding::Raw => "raw",
            Encoding::Ascii => "ascii",
            Encoding::Hex => "hex",
            Encoding::Gzip => "gzip",
            Encoding::Bzip2 => "bzip2",
        }
    }

    /// Whether the byte order of multi-byte values is exposed (and `endian` required).
    pub const fn exposes_endian(self) -> bool {
        !matches!(self, Encoding::Ascii)
    }
}

/// Where the data is.
#[derive(Debug, Clone, PartialEq)]
pub enum DataFiles {
    /// Right after the header, in the same file.
    Attached,
    /// `data file: NAME` — one file with all the data.
    Single(String),
    /// `data file: LIST [subdim]` — the header's remaining lines name the files.
    List { files: Vec<String>, subdim: usize },
    /// `data file: FORMAT MIN MAX STEP [subdim]` — printf-style numbered files.
    Pattern {
        format: String,
        min: i64,
        max: i64,
        step: i64,
        subdim: usize,
    },
}

/// Sample centering of an axis.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Center {
    Cell,
    Node,
    Unknown,
}

/// A parsed and checked NRRD header.
#[derive(Debug, Clone, PartialEq)]
pub struct NrrdHeader {
    /// The `X` of `NRRD000X`.
    pub version: u8,
    pub dimension: usize,
    pub voxel_type: VoxelType,
    /// Samples per axis, fastest first.
    pub sizes: Vec<usize>,
    pub encoding: Encoding,
    /// `None` when not given (allowed for 1-byte types and ascii).
    pub endian: Option<Endian>,
    pub line_skip: u64,
    /// `-1`: the data is the last bytes of the file (raw encoding only).
    pub byte_skip: i64,
    pub data_files: DataFiles,
    /// Space name, if `space` was given (lower case, e.g. `left-posterior-superior`).
    pub space: Option<String>,
    /// From `space` or `space dimension`.
    pub space_dimension: Option<usize>,
    /// Per axis: a direction vector, or `None` for `none` (non-spatial axis).
    pub space_directions: Option<Vec<Option<Vec<f64>>>>,
    pub space_origin: Option<Vec<f64>>,
    pub spacings: Option<Vec<f64>>,
    pub thicknesses: Option<Vec<f64>>,
    pub axis_mins: Option<Vec<f64>>,
    pub axis_maxs: Option<Vec<f64>>,
    pub centers: Option<Vec<Center>>,
    /// Lower-case kind names (`domain`, `space`, `time`, `scalar`, `3-vector`, `???` ...).
    pub kinds: Option<Vec<String>>,
    pub labels: Option<Vec<String>>,
    pub units: Option<Vec<String>>,
    pub content: Option<String>,
    /// `key:=value` pairs in order.
    pub key_values: Vec<(String, String)>,
    /// Bytes of the header including the blank line that ends it (where attached data starts).
    pub header_len: usize,
    /// Header line of each field that was given (1-based), for error messages.
    pub field_lines: HashMap<&'static str, usize>,
}

impl NrrdHeader {
    /// The line a field was given on (0 if absent).
    pub fn line_of(&self, field: &str) -> usize {
        self.field_lines.get(field).copied().unwrap_or(0)
    }

    /// Number of values in the whole array (overflow-checked).
    pub fn element_count(&self) -> Option<u64> {
        self.sizes
            .iter()
            .try_fold(1u64, |acc, &s| acc.checked_mul(s as u64))
    }
}

const FIELDS: &[&str] = &[
    "dimension",
    "type",
    "block size",
    "encoding",
    "endian",
    "content",
    "min",
    "max",
    "old min",
    "old max",
    "data file",
    "line skip",
    "byte skip",
    "number",
    "sample units",
    "space",
    "space dimension",
    "space units",
    "space origin",
    "space directions",
    "measurement frame",
    "sizes",
    "spacings",
    "thicknesses",
    "axis mins",
    "axis maxs",
    "centers",
    "labels",
    "units",
    "kinds",
];

fn canonical_field(name: &str) -> Option<&'static str> {
    let alias = match name {
        "blocksize" => "block size",
        "oldmin" => "old min",
        "oldmax" => "old max",
        "datafile" => "data file",
        "lineskip" => "line skip",
        "byteskip" => "byte skip",
        "sampleunits" => "sample units",
        "axismins" => "axis mins",
        "axismaxs" => "axis maxs",
        "centerings" => "centers",
        other => other,
    };
    FIELDS.iter().copied().find(|f| *f == alias)
}

/// Teem's type names (all aliases), 64-bit integers and `block` reported as unsupported.
fn parse_type(s: &str) -> Result<VoxelType, Option<&'static str>> {
    Ok(match s {
        "signed char" | "int8" | "int8_t" => VoxelType::I8,
        "uchar" | "unsigned char" | "uint8" | "uint8_t" => VoxelType::U8,
        "short" | "short int" | "signed short" | "signed short int" | "int16" | "int16_t" => {
            VoxelType::I16
        }
        "ushort" | "unsigned short" | "unsigned short int" | "uint16" | "uint16_t" => {
            VoxelType::U16
        }
        "int" | "signed int" | "int32" | "int32_t" => VoxelType::I32,
        "uint" | "unsigned int" | "uint32" | "uint32_t" => VoxelType::U32,
        "float" => VoxelType::F32,
        "double" => VoxelType::F64,
        "longlong"
        | "long long"
        | "long long int"
        | "signed long long"
        | "signed long long int"
        | "int64"
        | "int64_t"
        | "ulonglong"
        | "unsigned long long"
        | "unsigned long long int"
        | "uint64"
        | "uint64_t" => {
            return Err(Some(
                "64-bit integer voxels are not supported (convert to double or int32)",
            ));
        }
        "block" => return Err(Some("`block` voxels (opaque records) are not supported")),
        _ => return Err(None),
    })
}

fn parse_encoding(s: &str) -> Option<Encoding> {
    Some(match s {
        "raw" => Encoding::Raw,
        "txt" | "text" | "ascii" => Encoding::Ascii,
        "hex" => Encoding::Hex,
        "gz" | "gzip" => Encoding::Gzip,
        "bz2" | "bzip2" => Encoding::Bzip2,
        _ => return None,
    })
}

/// Space names and their dimension (NRRD format §4).
fn parse_space(s: &str) -> Option<(&'static str, usize)> {
    Some(match s {
        "right-anterior-superior" | "ras" => ("right-anterior-superior", 3),
        "left-anterior-superior" | "las" => ("left-anterior-superior", 3),
        "left-posterior-superior" | "lps" => ("left-posterior-superior", 3),
        "right-anterior-superior-time" | "rast" => ("right-anterior-superior-time", 4),
        "left-anterior-superior-time" | "last" => ("left-anterior-superior-time", 4),
        "left-posterior-superior-time" | "lpst" => ("left-posterior-superior-time", 4),
        "scanner-xyz" => ("scanner-xyz", 3),
        "scanner-xyz-time" => ("scanner-xyz-time", 4),
        "3d-right-handed" => ("3d-right-handed", 3),
        "3d-left-handed" => ("3d-left-handed", 3),
        "3d-right-handed-time" => ("3d-right-handed-time", 4),
        "3d-left-handed-time" => ("3d-left-handed-time", 4),
        _ => return None,
    })
}

/// Kind names and the axis size they imply: `None` for an unknown kind, `Some(None)` for a
/// kind of any size.
#[allow(clippy::option_option)]
fn kind_size(kind: &str) -> Option<Option<usize>> {
    Some(match kind {
        "domain" | "space" | "time" | "list" | "point" | "vector" | "covariant-vector"
        | "normal" | "???" | "none" => None,
        "stub" | "scalar" => Some(1),
        "complex" | "2-vector" => Some(2),
        "3-color"
        | "rgb-color"
        | "hsv-color"
        | "xyz-color"
        | "3-vector"
        | "3-gradient"
        | "3-normal"
        | "2d-symmetric-matrix" => Some(3),
        "4-color"
        | "rgba-color"
        | "4-vector"
        | "quaternion"
        | "2d-masked-symmetric-matrix"
        | "2d-matrix" => Some(4),
        "2d-masked-matrix" => Some(5),
        "3d-symmetric-matrix" => Some(6),
        "3d-masked-symmetric-matrix" => Some(7),
        "3d-matrix" => Some(9),
        "3d-masked-matrix" => Some(10),
        _ => return None,
    })
}

struct Ctx<'a> {
    path: &'a Path,
}

impl Ctx<'_> {
    fn bad(&self, line: usize, field: &str, reason: impl Into<String>) -> FormatError {
        FormatError::BadValue {
            path: self.path.to_path_buf(),
            line,
            field: field.to_string(),
            reason: reason.into(),
        }
    }

    fn unsupported(&self, field: &str, reason: impl Into<String>) -> FormatError {
        FormatError::Unsupported {
            path: self.path.to_path_buf(),
            field: field.to_string(),
            reason: reason.into(),
        }
    }

    fn contradiction(&self, field: &str, other: &str, reason: impl Into<String>) -> FormatError {
        FormatError::Contradiction {
            path: self.path.to_path_buf(),
            field: field.to_string(),
            other: other.to_string(),
            reason: reason.into(),
        }
    }

    fn missing(&self, field: &'static str, reason: impl Into<String>) -> FormatError {
        FormatError::MissingField {
            path: self.path.to_path_buf(),
            field,
            reason: reason.into(),
        }
    }
}

/// Parses a NRRD header from the start of `bytes` (which may continue with attached data).
/// Errors name the placeholder file `<header>`; readers use [`parse_header_at`].
pub fn parse_header(bytes: &[u8]) -> Result<NrrdHeader, FormatError> {
    parse_header_at(Path::new("<header>"), bytes)
}

/// Splits `bytes` into lines up to the first empty line (the end of the header). Returns the
/// lines (without `\n`/`\r\n`) and the header length including the blank line.
fn header_lines<'a>(path: &Path, bytes: &'a [u8]) -> Result<(Vec<&'a [u8]>, usize), FormatError> {
    let mut lines = Vec::new();
    let mut pos = 0;
    while pos < bytes.len() {
        let end = bytes[pos..]
            .iter()
            .position(|&b| b == b'\n')
            .map_or(bytes.len(), |i| pos + i);
        let mut line = &bytes[pos..end];
        if let [rest @ .., b'\r'] = line {
            line = rest;
        }
        pos = (end + 1).min(bytes.len());
        if line.is_empty() {
            return Ok((lines, pos));
        }
        if pos > MAX_HEADER_BYTES {
            return Err(FormatError::BadLine {
                path: path.to_path_buf(),
                line: lines.len() + 1,
                reason: format!("header longer than {MAX_HEADER_BYTES} bytes"),
            });
        }
        lines.push(line);
    }
    Ok((lines, bytes.len()))
}

/// [`parse_header`] for the file at `path` (named in errors).
pub fn parse_header_at(path: &Path, bytes: &[u8]) -> Result<NrrdHeader, FormatError> {
    let cx = Ctx { path };
    let (lines, header_len) = header_lines(path, bytes)?;
    let Some(magic) = lines.first() else {
        return Err(FormatError::BadMagic {
            path: path.to_path_buf(),
            found: String::new(),
        });
    };
    let [b'N', b'R', b'R', b'D', b'0', b'0', b'0', v @ b'1'..=b'5'] = magic else {
        let shown: String = String::from_utf8_lossy(&magic[..magic.len().min(16)]).into();
        return Err(FormatError::BadMagic {
            path: path.to_path_buf(),
            found: shown,
        });
    };
    let version = v - b'0';

    // Pass 1: split lines into fields and key/values; detect unknown and repeated fields.
    let mut fields: HashMap<&'static str, (usize, String)> = HashMap::new();
    let mut key_values = Vec::new();
    let mut list_files: Option<Vec<String>> = None;
    for (idx, raw_line) in lines.iter().enumerate().skip(1) {
        let line_no = idx + 1;
        let line = std::str::from_utf8(raw_line).map_err(|e| FormatError::BadLine {
            path: path.to_path_buf(),
            line: line_no,
            reason: format!("not valid UTF-8 text at column {}", e.valid_up_to() + 1),
        })?;
        if let Some(files) = list_files.as_mut() {
            // After `data file: LIST`, every line is a file name (comments still allowed).
            if !line.starts_with('#') {
                files.push(line.trim().to_string());
            }
            continue;
        }
        if line.starts_with('#') {
            continue;
        }
        let kv = line.find(":=");
        let colon = line.find(':');
        if let Some(k) = kv
            && colon == Some(k)
        {
            key_values.push((unescape(&line[..k]), unescape(&line[k + 2..])));
            continue;
        }
        let Some(c) = colon else {
            return Err(FormatError::BadLine {
                path: path.to_path_buf(),
                line: line_no,
                reason: format!("expected `<field>: <value>` or `<key>:=<value>`, found {line:?}"),
            });
        };
        let name = line[..c].trim().to_ascii_lowercase();
        let value = line[c + 1..].trim().to_string();
        let Some(field) = canonical_field(&name) else {
            return Err(FormatError::UnknownField {
                path: path.to_path_buf(),
                line: line_no,
                field: line[..c].to_string(),
            });
        };
        if fields.contains_key(field) {
            return Err(FormatError::DuplicateField {
                path: path.to_path_buf(),
                line: line_no,
                field: field.to_string(),
            });
        }
        if field == "data file" && value.split_whitespace().next() == Some("LIST") {
            list_files = Some(Vec::new());
        }
        fields.insert(field, (line_no, value));
    }
    let field_lines: HashMap<&'static str, usize> =
        fields.iter().map(|(k, (l, _))| (*k, *l)).collect();
    let get = |f: &str| fields.get(f).map(|(l, v)| (*l, v.as_str()));

    // Pass 2: interpret, required fields first.
    let (line, v) = get("dimension").ok_or_else(|| cx.missing("dimension", ""))?;
    let dimension: usize = v.parse().map_err(|_| {
        cx.bad(
            line,
            "dimension",
            format!("`{v}` is not a positive integer"),
        )
    })?;
    if dimension == 0 || dimension > MAX_DIMENSION {
        return Err(cx.bad(
            line,
            "dimension",
            format!("{dimension} is outside 1..={MAX_DIMENSION}"),
        ));
    }

    let (line, v) = get("type").ok_or_else(|| cx.missing("type", ""))?;
    let voxel_type = parse_type(&v.to_ascii_lowercase()).map_err(|why| match why {
        Some(reason) => cx.unsupported("type", format!("`{v}`: {reason}")),
        None => cx.bad(line, "type", format!("unknown type `{v}`")),
    })?;

    let (line, v) = get("sizes").ok_or_else(|| cx.missing("sizes", ""))?;
    let sizes = per_axis(&cx, line, "sizes", v, dimension, |t| {
        t.parse::<usize>()
            .ok()
            .filter(|&s| s >= 1)
            .ok_or_else(|| format!("`{t}` is not a size (an integer >= 1)"))
    })?;
    let count = sizes
        .iter()
        .try_fold(1u64, |acc, &s| acc.checked_mul(s as u64))
        .and_then(|n| n.checked_mul(voxel_type.size_bytes() as u64))
        .filter(|&n| usize::try_from(n).is_ok());
    if count.is_none() {
        return Err(cx.bad(
            line,
            "sizes",
            format!("{sizes:?} × {} bytes overflows", voxel_type.size_bytes()),
        ));
    }

    let (line, v) = get("encoding").ok_or_else(|| cx.missing("encoding", ""))?;
    let encoding = parse_encoding(&v.to_ascii_lowercase()).ok_or_else(|| {
        if v.eq_ignore_ascii_case("zrl") {
            cx.unsupported(
                "encoding",
                "zero run-length (`zrl`) encoding is not supported",
            )
        } else {
            cx.bad(line, "encoding", format!("unknown encoding `{v}`"))
        }
    })?;

    let endian = match get("endian") {
        Some((line, v)) => Some(match v.to_ascii_lowercase().as_str() {
            "little" => Endian::Little,
            "big" => Endian::Big,
            _ => return Err(cx.bad(line, "endian", format!("`{v}` is not `little` or `big`"))),
        }),
        None => None,
    };
    if endian.is_none() && voxel_type.size_bytes() > 1 && encoding.exposes_endian() {
        return Err(cx.missing(
            "endian",
            format!(
                "needed for {} data in {} encoding",
                voxel_type,
                encoding.name()
            ),
        ));
    }

    let line_skip = match get("line skip") {
        Some((line, v)) => v
            .parse::<u64>()
            .map_err(|_| cx.bad(line, "line skip", format!("`{v}` is not an integer >= 0")))?,
        None => 0,
    };
    let byte_skip = match get("byte skip") {
        Some((line, v)) => {
            let b = v.parse::<i64>().ok().filter(|&b| b >= -1).ok_or_else(|| {
                cx.bad(line, "byte skip", format!("`{v}` is not an integer >= -1"))
            })?;
            if b == -1 && encoding != Encoding::Raw {
                return Err(cx.contradiction(
                    "byte skip",
                    "encoding",
                    format!(
                        "byte skip -1 (data at the end of the file) needs raw encoding, not {}",
                        encoding.name()
                    ),
                ));
            }
            b
        }
        None => 0,
    };

    let data_files = match get("data file") {
        None => DataFiles::Attached,
        Some((line, v)) => parse_data_file(&cx, line, v, dimension, &sizes, list_files)?,
    };

    // Space and orientation.
    let mut space = None;
    let mut space_dimension = None;
    if let Some((line, v)) = get("space") {
        let (name, dim) = parse_space(&v.to_ascii_lowercase())
            .ok_or_else(|| cx.bad(line, "space", format!("unknown space `{v}`")))?;
        space = Some(name.to_string());
        space_dimension = Some(dim);
    }
    if let Some((line, v)) = get("space dimension") {
        if space.is_some() {
            return Err(cx.contradiction(
                "space dimension",
                "space",
                "give either `space` or `space dimension`, not both",
            ));
        }
        let d = v
            .parse::<usize>()
            .ok()
            .filter(|d| (1..=MAX_DIMENSION).contains(d))
            .ok_or_else(|| cx.bad(line, "space dimension", format!("`{v}` is not in 1..=16")))?;
        space_dimension = Some(d);
    }
    let need_space = |field: &'static str| {
        cx.missing(
            "space",
            format!("`{field}` needs `space` or `space dimension`"),
        )
    };
    let space_directions = match get("space directions") {
        None => None,
        Some((line, v)) => {
            let sd = space_dimension.ok_or_else(|| need_space("space directions"))?;
            let items = vector_tokens(v).map_err(|r| cx.bad(line, "space directions", r))?;
            if items.len() != dimension {
                return Err(cx.bad(
                    line,
                    "space directions",
                    format!("{} entries for dimension {dimension}", items.len()),
                ));
            }
            let mut dirs = Vec::with_capacity(dimension);
            for item in items {
                if item.eq_ignore_ascii_case("none") {
                    dirs.push(None);
                } else {
                    let vec =
                        parse_vector(item, sd).map_err(|r| cx.bad(line, "space directions", r))?;
                    if vec.iter().any(|c| !c.is_finite()) {
                        return Err(cx.bad(
                            line,
                            "space directions",
                            format!("{item}: components must be finite"),
                        ));
                    }
                    dirs.push(Some(vec));
                }
            }
            Some(dirs)
        }
    };
    let space_origin = match get("space origin") {
        None => None,
        Some((line, v)) => {
            let sd = space_dimension.ok_or_else(|| need_space("space origin"))?;
            let o = parse_vector(v.trim(), sd).map_err(|r| cx.bad(line, "space origin", r))?;
            if o.iter().any(|c| !c.is_finite()) {
                return Err(cx.bad(line, "space origin", "components must be finite"));
            }
            Some(o)
        }
    };
    if let Some((line, v)) = get("space units") {
        let sd = space_dimension.ok_or_else(|| need_space("space units"))?;
        let u = quoted_list(v).map_err(|r| cx.bad(line, "space units", r))?;
        if u.len() != sd {
            return Err(cx.bad(
                line,
                "space units",
                format!("{} units for space dimension {sd}", u.len()),
            ));
        }
    }
    if let Some((line, v)) = get("measurement frame") {
        let sd = space_dimension.ok_or_else(|| need_space("measurement frame"))?;
        let items = vector_tokens(v).map_err(|r| cx.bad(line, "measurement frame", r))?;
        if items.len() != sd {
            return Err(cx.bad(
                line,
                "measurement frame",
                format!("{} vectors for space dimension {sd}", items.len()),
            ));
        }
        for item in items {
            parse_vector(item, sd).map_err(|r| cx.bad(line, "measurement frame", r))?;
        }
    }

    // Per-axis fields.
    let float_axis = |field: &'static str| -> Result<Option<Vec<f64>>, FormatError> {
        match get(field) {
            None => Ok(None),
            Some((line, v)) => per_axis(&cx, line, field, v, dimension, parse_f64).map(Some),
        }
    };
    let spacings = float_axis("spacings")?;
    let thicknesses = float_axis("thicknesses")?;
    let axis_mins = float_axis("axis mins")?;
    let axis_maxs = float_axis("axis maxs")?;
    if let Some(s) = &spacings
        && let Some(i) = s.iter().position(|x| *x == 0.0 || x.is_infinite())
    {
        return Err(cx.bad(
            field_lines["spacings"],
            "spacings",
            format!(
                "axis {i}: spacing {} must be non-zero and finite (or nan)",
                s[i]
            ),
        ));
    }
    // Teem (`_nrrdFieldCheck_axis_min`/`_max`): an axis min or max may be nan (unknown) but
    // not infinite; geometry would otherwise drop an infinite one silently as unknown.
    for (field, vals) in [("axis mins", &axis_mins), ("axis maxs", &axis_maxs)] {
        if let Some(v) = vals
            && let Some(i) = v.iter().position(|x| x.is_infinite())
        {
            return Err(cx.bad(
                field_lines[field],
                field,
                format!("axis {i}: {} must be finite (or nan)", v[i]),
            ));
        }
    }
    // Teem: an axis with a space direction gets its spacing and min/max from the space
    // directions and origin; per-axis values on such an axis contradict them.
    if let Some(dirs) = &space_directions {
        for (field, vals) in [
            ("spacings", &spacings),
            ("axis mins", &axis_mins),
            ("axis maxs", &axis_maxs),
        ] {
            if let Some(vals) = vals
                && let Some(i) = (0..dimension).find(|&i| dirs[i].is_some() && !vals[i].is_nan())
            {
                return Err(cx.contradiction(
                    field,
                    "space directions",
                    format!(
                        "axis {i} has a space direction, so its {field} must be nan (got {})",
                        vals[i]
                    ),
                ));
            }
        }
    } else if space_dimension.is_some()
        && let Some(s) = &spacings
        && s.iter().any(|x| !x.is_nan())
    {
        return Err(cx.contradiction(
            "spacings",
            "space",
            "with a space set, spatial axes are given by `space directions`, not `spacings`",
        ));
    }
    if let (Some(mins), Some(maxs)) = (&axis_mins, &axis_maxs)
        && let Some(i) = (0..dimension).find(|&i| mins[i] > maxs[i])
    {
        return Err(cx.contradiction(
            "axis mins",
            "axis maxs",
            format!("axis {i}: min {} > max {}", mins[i], maxs[i]),
        ));
    }
    let centers = match get("centers") {
        None => None,
        Some((line, v)) => Some(per_axis(&cx, line, "centers", v, dimension, |t| {
            match t.to_ascii_lowercase().as_str() {
                "cell" => Ok(Center::Cell),
                "node" => Ok(Center::Node),
                "???" | "none" => Ok(Center::Unknown),
                _ => Err(format!("unknown centering `{t}`")),
            }
        })?),
    };
    let kinds = match get("kinds") {
        None => None,
        Some((line, v)) => {
            let kinds = per_axis(&cx, line, "kinds", v, dimension, |t| {
                let k = t.to_ascii_lowercase();
                kind_size(&k)
                    .map(|_| k)
                    .ok_or_else(|| format!("unknown kind `{t}`"))
            })?;
            for (i, k) in kinds.iter().enumerate() {
                if let Some(Some(n)) = kind_size(k)
                    && sizes[i] != n
                {
                    return Err(cx.contradiction(
                        "kinds",
                        "sizes",
                        format!("axis {i} of kind {k} must have size {n}, not {}", sizes[i]),
                    ));
                }
            }
            Some(kinds)
        }
    };
    let labels = quoted_axis(&cx, get("labels"), "labels", dimension)?;
    let units = quoted_axis(&cx, get("units"), "units", dimension)?;
    for field in ["min", "max", "old min", "old max"] {
        if let Some((line, v)) = get(field) {
            parse_f64(v).map_err(|r| cx.bad(line, field, r))?;
        }
    }
    if let Some((line, v)) = get("sample units") {
        quoted_or_plain(v).map_err(|r| cx.bad(line, "sample units", r))?;
    }
    if let Some((line, v)) = get("block size") {
        v.parse::<usize>()
            .map_err(|_| cx.bad(line, "block size", format!("`{v}` is not an integer")))?;
    }
    let content = get("content").map(|(_, v)| v.to_string());

    Ok(NrrdHeader {
        version,
        dimension,
        voxel_type,
        sizes,
        encoding,
        endian,
        line_skip,
        byte_skip,
        data_files,
        space,
        space_dimension,
        space_directions,
        space_origin,
        spacings,
        thicknesses,
        axis_mins,
        axis_maxs,
        centers,
        kinds,
        labels,
        units,
        content,
        key_values,
        header_len,
        field_lines,
    })
}

fn parse_data_file(
    cx: &Ctx<'_>,
    line: usize,
    v: &str,
    dimension: usize,
    sizes: &[usize],
    list_files: Option<Vec<String>>,
) -> Result<DataFiles, FormatError> {
    let tokens: Vec<&str> = v.split_whitespace().collect();
    let parse_subdim = |t: Option<&&str>| -> Result<usize, FormatError> {
        match t {
            None => Ok(dimension.saturating_sub(1).max(1)),
            Some(t) => t
                .parse::<usize>()
                .ok()
                .filter(|d| (1..=dimension).contains(d))
                .ok_or_else(|| {
                    cx.bad(
                        line,
                        "data file",
                        format!("subdim `{t}` is not in 1..={dimension}"),
                    )
                }),
        }
    };
    // Files needed: the product of the sizes of the axes above `subdim`.
    let files_needed = |subdim: usize| -> u64 {
        sizes[subdim..]
            .iter()
            .fold(1u64, |a, &s| a.saturating_mul(s as u64))
    };
    if tokens.first() == Some(&"LIST") {
        if tokens.len() > 2 {
            return Err(cx.bad(line, "data file", "expected `LIST [<subdim>]`"));
        }
        let subdim = parse_subdim(tokens.get(1))?;
        let files = list_files.unwrap_or_default();
        if files.len() as u64 != files_needed(subdim) {
            return Err(cx.bad(
                line,
                "data file",
                format!(
                    "LIST names {} files but sizes {sizes:?} with subdim {subdim} need {}",
                    files.len(),
                    files_needed(subdim)
                ),
            ));
        }
        if let Some(i) = files.iter().position(String::is_empty) {
            return Err(cx.bad(line, "data file", format!("LIST entry {i} is empty")));
        }
        return Ok(DataFiles::List { files, subdim });
    }
    if tokens.len() >= 4 && tokens[0].contains('%') {
        if tokens.len() > 5 {
            return Err(cx.bad(
                line,
                "data file",
                "expected `<format> <min> <max> <step> [<subdim>]`",
            ));
        }
        let format = tokens[0].to_string();
        check_printf(&format).map_err(|r| cx.bad(line, "data file", r))?;
        let int = |t: &str, what: &str| {
            t.parse::<i64>()
                .map_err(|_| cx.bad(line, "data file", format!("{what} `{t}` is not an integer")))
        };
        let (min, max, step) = (
            int(tokens[1], "min")?,
            int(tokens[2], "max")?,
            int(tokens[3], "step")?,
        );
        if step == 0 || (i128::from(max) - i128::from(min)).signum() * i128::from(step.signum()) < 0
        {
            return Err(cx.bad(
                line,
                "data file",
                format!("step {step} does not lead from {min} to {max}"),
            ));
        }
        let subdim = parse_subdim(tokens.get(4))?;
        let count = (i128::from(max) - i128::from(min)) / i128::from(step) + 1;
        if count > i128::from(MAX_DATA_FILES) {
            return Err(cx.bad(
                line,
                "data file",
                format!("pattern names {count} files; at most {MAX_DATA_FILES} are supported"),
            ));
        }
        let count = count as u64;
        if count != files_needed(subdim) {
            return Err(cx.bad(
                line,
                "data file",
                format!(
                    "pattern gives {count} files but sizes {sizes:?} with subdim {subdim} need {}",
                    files_needed(subdim)
                ),
            ));
        }
        return Ok(DataFiles::Pattern {
            format,
            min,
            max,
            step,
            subdim,
        });
    }
    if v.is_empty() {
        return Err(cx.bad(line, "data file", "no file name"));
    }
    Ok(DataFiles::Single(v.to_string()))
}

/// Checks that a printf format has exactly one integer conversion (`%d`, `%03d`, `%i`, `%u`).
pub(crate) fn check_printf(format: &str) -> Result<(), String> {
    let mut conversions = 0;
    let mut chars = format.chars().peekable();
    while let Some(c) = chars.next() {
        if c != '%' {
            continue;
        }
        if chars.peek() == Some(&'%') {
            chars.next();
            continue;
        }
        while chars
            .peek()
            .is_some_and(|c| c.is_ascii_digit() || *c == '-' || *c == '+')
        {
            chars.next();
        }
        match chars.next() {
            Some('d' | 'i' | 'u') => conversions += 1,
            other => {
                return Err(format!(
                    "format `{format}`: unsupported conversion `%{}`",
                    other.map(String::from).unwrap_or_default()
                ));
            }
        }
    }
    if conversions == 1 {
        Ok(())
    } else {
        Err(format!(
            "format `{format}` must have exactly one integer conversion like %03d"
        ))
    }
}

/// Formats `n` with a printf format that has exactly one integer conversion (`%d`, `%03d`,
/// `%i`, `%u`), as the header parser checks for data file patterns.
pub fn format_printf(format: &str, n: i64) -> String {
    let mut out = String::new();
    let mut chars = format.chars().peekable();
    while let Some(c) = chars.next() {
        if c != '%' {
            out.push(c);
            continue;
        }
        if chars.peek() == Some(&'%') {
            chars.next();
            out.push('%');
            continue;
        }
        let mut spec = String::new();
        while let Some(&d) = chars.peek() {
            if d.is_ascii_digit() || d == '-' || d == '+' {
                spec.push(d);
                chars.next();
            } else {
                break;
            }
        }
        chars.next(); // the conversion letter
        let left = spec.contains('-');
        let plus = spec.contains('+');
        let digits: String = spec.chars().filter(char::is_ascii_digit).collect();
        let zero = digits.starts_with('0') && !left;
        let width: usize = digits.parse().unwrap_or(0).min(64);
        let sign = if n < 0 {
            "-"
        } else if plus {
            "+"
        } else {
            ""
        };
        let body = n.unsigned_abs().to_string();
        let len = sign.len() + body.len();
        let pad = width.saturating_sub(len);
        if zero {
            out.push_str(sign);
            out.extend(std::iter::repeat_n('0', pad));
            out.push_str(&body);
        } else if left {
            out.push_str(sign);
            out.push_str(&body);
            out.extend(std::iter::repeat_n(' ', pad));
        } else {
            out.extend(std::iter::repeat_n(' ', pad));
            out.push_str(sign);
            out.push_str(&body);
        }
    }
    out
}

/// Resolves the data file names of a detached header relative to the header's directory.
pub fn data_file_paths(header: &NrrdHeader, header_path: &Path) -> Vec<PathBuf> {
    let resolve = |name: &str| crate::input::beside(header_path, name);
    match &header.data_files {
        DataFiles::Attached => vec![header_path.to_path_buf()],
        DataFiles::Single(name) => vec![resolve(name)],
        DataFiles::List { files, .. } => files.iter().map(|f| resolve(f)).collect(),
        DataFiles::Pattern {
            format,
            min,
            max,
            step,
            ..
        } => {
            let mut out = Vec::new();
            let mut n = *min;
            while (*step > 0 && n <= *max) || (*step < 0 && n >= *max) {
                out.push(resolve(&format_printf(format, n)));
                match n.checked_add(*step) {
                    Some(next) => n = next,
                    None => break,
                }
            }
            out
        }
    }
}

fn per_axis<T>(
    cx: &Ctx<'_>,
    line: usize,
    field: &str,
    v: &str,
    dimension: usize,
    parse: impl Fn(&str) -> Result<T, String>,
) -> Result<Vec<T>, FormatError> {
    let tokens: Vec<&str> = v.split_whitespace().collect();
    if tokens.len() != dimension {
        return Err(cx.bad(
            line,
            field,
            format!("{} values for dimension {dimension}", tokens.len()),
        ));
    }
    tokens
        .iter()
        .enumerate()
        .map(|(i, t)| parse(t).map_err(|r| cx.bad(line, field, format!("axis {i}: {r}"))))
        .collect()
}

fn parse_f64(t: &str) -> Result<f64, String> {
    let t = t.trim();
    if t.eq_ignore_ascii_case("nan") {
        return Ok(f64::NAN);
    }
    t.parse::<f64>()
        .map_err(|_| format!("`{t}` is not a number"))
}

/// Splits `(1,0,0) none (0,1,0)` into its items (vectors may contain spaces inside parens).
fn vector_tokens(v: &str) -> Result<Vec<&str>, String> {
    let mut items = Vec::new();
    let mut rest = v.trim_start();
    while !rest.is_empty() {
        if rest.starts_with('(') {
            let end = rest
                .find(')')
                .ok_or_else(|| format!("unclosed `(` in `{v}`"))?;
            items.push(&rest[..=end]);
            rest = rest[end + 1..].trim_start();
        } else {
            let end = rest.find(char::is_whitespace).unwrap_or(rest.len());
            let tok = &rest[..end];
            if !tok.eq_ignore_ascii_case("none") {
                return Err(format!("expected `(x,y,z)` or `none`, found `{tok}`"));
            }
            items.push(tok);
            rest = rest[end..].trim_start();
        }
    }
    Ok(items)
}

/// Parses `(x,y,z)` with exactly `n` components.
fn parse_vector(item: &str, n: usize) -> Result<Vec<f64>, String> {
    let inner = item
        .strip_prefix('(')
        .and_then(|s| s.strip_suffix(')'))
        .ok_or_else(|| format!("`{item}` is not a `(x,y,z)` vector"))?;
    let comps: Vec<f64> = inner
        .split(',')
        .map(parse_f64)
        .collect::<Result<_, _>>()
        .map_err(|r| format!("{item}: {r}"))?;
    if comps.len() != n {
        return Err(format!(
            "{item}: {} components for space dimension {n}",
            comps.len()
        ));
    }
    Ok(comps)
}

fn quoted_axis(
    cx: &Ctx<'_>,
    entry: Option<(usize, &str)>,
    field: &str,
    dimension: usize,
) -> Result<Option<Vec<String>>, FormatError> {
    let Some((line, v)) = entry else {
        return Ok(None);
    };
    let items = quoted_list(v).map_err(|r| cx.bad(line, field, r))?;
    if items.len() != dimension {
        return Err(cx.bad(
            line,
            field,
            format!("{} strings for dimension {dimension}", items.len()),
        ));
    }
    Ok(Some(items))
}

/// Parses `"a" "b c" "d\"e"`.
fn quoted_list(v: &str) -> Result<Vec<String>, String> {
    let mut out = Vec::new();
    let mut chars = v.chars().peekable();
    loop {
        while chars.peek().is_some_and(|c| c.is_whitespace()) {
            chars.next();
        }
        match chars.next() {
            None => return Ok(out),
            Some('"') => {}
            Some(c) => return Err(format!("expected `\"`, found `{c}`")),
        }
        let mut s = String::new();
        loop {
            match chars.next() {
                None => return Err("unterminated quoted string".into()),
                Some('"') => break,
                Some('\\') => match chars.next() {
                    Some(c) => s.push(c),
                    None => return Err("unterminated quoted string".into()),
                },
                Some(c) => s.push(c),
            }
        }
        out.push(s);
    }
}

fn quoted_or_plain(v: &str) -> Result<String, String> {
    if v.starts_with('"') {
        let mut l = quoted_list(v)?;
        if l.len() != 1 {
            return Err("expected one quoted string".into());
        }
        Ok(l.remove(0))
    } else {
        Ok(v.to_string())
    }
}

/// Key/value escapes: `\n` and `\\`.
fn unescape(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    let mut chars = s.chars();
    while let Some(c) = chars.next() {
        if c == '\\' {
            match chars.next() {
                Some('n') => out.push('\n'),
                Some(o) => out.push(o),
                None => out.push('\\'),
            }
        } else {
            out.push(c);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(s: &str) -> Result<NrrdHeader, FormatError> {
        parse_header(s.as_bytes())
    }

    #[test]
    fn parses_a_full_teem_header() {
        let h = parse(
            "NRRD0005\n# Complete NRRD file format specification at:\n\
             type: short\ndimension: 3\nspace: left-posterior-superior\n\
             sizes: 4 5 6\nspace directions: (0.5,0,0) (0,0.5,0) (0,0,1.5)\n\
             kinds: domain domain domain\nendian: little\nencoding: gzip\n\
             space origin: (-10,-20,-30)\nlabels: \"x\" \"y y\" \"z\"\n\
             centers: cell cell cell\nmeasurement frame: (1,0,0) (0,1,0) (0,0,1)\n\
             space units: \"mm\" \"mm\" \"mm\"\nold min: -1\nold max: 1e3\n\
             modality:=CT\nnote:=a:=b\n\nDATA",
        )
        .unwrap();
        assert_eq!(h.version, 5);
        assert_eq!(h.voxel_type, VoxelType::I16);
        assert_eq!(h.sizes, vec![4, 5, 6]);
        assert_eq!(h.encoding, Encoding::Gzip);
        assert_eq!(h.endian, Some(Endian::Little));
        assert_eq!(h.space.as_deref(), Some("left-posterior-superior"));
        assert_eq!(h.space_dimension, Some(3));
        assert_eq!(h.space_origin, Some(vec![-10.0, -20.0, -30.0]));
        assert_eq!(
            h.space_directions.as_ref().unwrap()[2],
            Some(vec![0.0, 0.0, 1.5])
        );
        assert_eq!(h.labels.as_ref().unwrap()[1], "y y");
        assert_eq!(
            h.key_values,
            vec![
                ("modality".into(), "CT".into()),
                ("note".into(), "a:=b".into())
            ]
        );
        assert_eq!(h.data_files, DataFiles::Attached);
        assert_eq!(h.line_of("sizes"), 6);
    }

    #[test]
    fn accepts_every_type_alias() {
        let cases: &[(&str, VoxelType)] = &[
            ("signed char", VoxelType::I8),
            ("int8", VoxelType::I8),
            ("int8_t", VoxelType::I8),
            ("uchar", VoxelType::U8),
            ("unsigned char", VoxelType::U8),
            ("uint8", VoxelType::U8),
            ("uint8_t", VoxelType::U8),
            ("short", VoxelType::I16),
            ("short int", VoxelType::I16),
            ("signed short", VoxelType::I16),
            ("signed short int", VoxelType::I16),
            ("int16", VoxelType::I16),
            ("int16_t", VoxelType::I16),
            ("ushort", VoxelType::U16),
            ("unsigned short", VoxelType::U16),
            ("unsigned short int", VoxelType::U16),
            ("uint16", VoxelType::U16),
            ("uint16_t", VoxelType::U16),
            ("int", VoxelType::I32),
            ("signed int", VoxelType::I32),
            ("int32", VoxelType::I32),
            ("int32_t", VoxelType::I32),
            ("uint", VoxelType::U32),
            ("unsigned int", VoxelType::U32),
            ("uint32", VoxelType::U32),
            ("uint32_t", VoxelType::U32),
            ("float", VoxelType::F32),
            ("double", VoxelType::F64),
        ];
        for (name, t) in cases {
            let h = parse(&format!(
                "NRRD0004\ntype: {name}\ndimension: 3\nsizes: 1 1 1\nencoding: raw\nendian: big\n"
            ))
            .unwrap();
            assert_eq!(h.voxel_type, *t, "{name}");
        }
        for name in ["int64", "unsigned long long", "uint64_t", "block"] {
            let e = parse(&format!(
                "NRRD0004\ntype: {name}\ndimension: 3\nsizes: 1 1 1\nencoding: raw\nendian: big\n"
            ))
            .unwrap_err();
            assert!(
                matches!(&e, FormatError::Unsupported { field, .. } if field == "type"),
                "{e}"
            );
        }
    }

    #[test]
    fn parses_detached_forms() {
        let h = parse(
            "NRRD0004\ntype: uint8\ndimension: 3\nsizes: 2 2 3\nencoding: raw\n\
             data file: slice_%03d.raw 1 5 2 2\n",
        )
        .unwrap();
        let DataFiles::Pattern {
            min,
            max,
            step,
            subdim,
            ..
        } = &h.data_files
        else {
            panic!("pattern expected")
        };
        assert_eq!((*min, *max, *step, *subdim), (1, 5, 2, 2));
        let paths = data_file_paths(&h, Path::new("/d/h.nhdr"));
        assert_eq!(
            paths,
            vec![
                PathBuf::from("/d/slice_001.raw"),
                PathBuf::from("/d/slice_003.raw"),
                PathBuf::from("/d/slice_005.raw")
            ]
        );
        let h = parse(
            "NRRD0004\ntype: uint8\ndimension: 4\nsizes: 2 2 2 2\nencoding: raw\n\
             data file: LIST 3\na.raw\n# comment\nsub/b.raw\n",
        )
        .unwrap();
        assert_eq!(
            h.data_files,
            DataFiles::List {
                files: vec!["a.raw".into(), "sub/b.raw".into()],
                subdim: 3
            }
        );
        let h = parse(
            "NRRD0004\ntype: uint8\ndimension: 3\nsizes: 2 2 2\nencoding: raw\n\
             datafile: my data.raw\n",
        )
        .unwrap();
        assert_eq!(h.data_files, DataFiles::Single("my data.raw".into()));
    }

    #[test]
    fn printf_formatting_matches_c() {
        assert_eq!(format_printf("v_%03d.raw", 7), "v_007.raw");
        assert_eq!(format_printf("v_%d.raw", -7), "v_-7.raw");
        assert_eq!(format_printf("%4d|", 12), "  12|");
        assert_eq!(format_printf("|%-4d|", 12), "|12  |");
        assert_eq!(format_printf("100%%_%02i", 3), "100%_03");
        assert!(check_printf("a%d%d").is_err());
        assert!(check_printf("a%s").is_err());
        assert!(check_printf("plain").is_err());
    }

    #[test]
    fn header_ends_at_first_blank_line_with_crlf() {
        let text = "NRRD0004\r\ntype: uint8\r\ndimension: 3\r\nsizes: 1 1 2\r\nencoding: raw\r\n\r\n\x01\x02";
        let h = parse(text).unwrap();
        assert_eq!(h.header_len, text.len() - 2);
    }
}
