//! # TIFF stacks: multi-page TIFF files and numbered 2D TIFF slices
//!
//! Read with the `tiff` crate (pure Rust; LZW and deflate codecs, uncompressed and PackBits
//! built in). Greyscale pages only (one sample per pixel, `BlackIsZero`): 8, 16 and 32-bit
//! unsigned and signed integers, 16, 32 and 64-bit floats (half floats are widened to
//! `f32`); RGB, palette, multi-sample, `WhiteIsZero` and 64-bit integer pages are refused
//! with the page named.
//!
//! - A multi-page file: its pages are the z slices of one volume ([`read_tiff`]); every page
//!   must have the first page's size and sample type (else an error naming the page).
//! - Numbered 2D files (`slice_%03d.tif`, `slice_*.tif`: one page each) are the z slices of
//!   ONE volume ([`read_slices`]); numbered multi-page files are a time series of volumes.
//!   [`crate::open`] decides by the page count of the first file ([`is_single_page`]).
//! - ImageJ files (`ImageDescription` starting `ImageJ=`): `slices=`, `frames=` (more than one
//!   frame: a time series, `finterval=` between frames) and `channels=` (more than one is
//!   refused), `spacing=` (z) and `unit=`; x and y spacing are `1 / XResolution` and `1 /
//!   YResolution` (pixels per unit). Spacing stays in the file's unit (`unit=`, e.g. micron).
//! - An axis whose spacing the file does not record takes it from
//!   [`crate::OpenOptions::spacing`] (the CLI's `--spacing`), else 1. Resolution tags of
//!   files without ImageJ metadata are ignored: most writers put 72 dpi there, which says
//!   nothing about the sample spacing. TIFF has no patient frame: the world frame is unknown
//!   and the origin is 0.
//!
//! Headers lie: before a page is decoded, its size is checked against the bytes of its
//! strips or tiles (uncompressed: they must hold the page; compressed: they may not claim
//! more than the codec can expand them to), and the decoder's buffers are capped by the
//! file size; pages are appended as they decode, so memory follows the data actually read.

use std::io::{BufReader, Read, Seek};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use tiff::decoder::ifd::Value;
use tiff::decoder::{Decoder, DecodingResult, Limits};
use tiff::tags::{CompressionMethod, PhotometricInterpretation, Tag};
use tiff::{ColorType, TiffError};
use volume_core::series::{StepLoader, TimeSeries};
use volume_core::{Grid, RectilinearVolume, VoxelData, VoxelType};

use crate::error::FormatError;
use crate::{Dataset, OpenOptions};

/// What the ImageJ `ImageDescription` says (only the keys read here).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ImageJ {
    pub images: Option<usize>,
    pub channels: Option<usize>,
    pub slices: Option<usize>,
    pub frames: Option<usize>,
    /// z spacing.
    pub spacing: Option<f64>,
    pub unit: Option<String>,
    /// Time between frames.
    pub finterval: Option<f64>,
}

/// Parses an ImageJ `ImageDescription` (`None` if it is not one).
pub fn parse_imagej(description: &str) -> Option<ImageJ> {
    if !description.starts_with("ImageJ=") {
        return None;
    }
    let mut m = ImageJ::default();
    for line in description.lines() {
        let Some((k, v)) = line.split_once('=') else {
            continue;
        };
        let (k, v) = (k.trim(), v.trim());
        let count = || v.parse::<usize>().ok();
        let number = || v.parse::<f64>().ok().filter(|x| x.is_finite() && *x > 0.0);
        match k {
            "images" => m.images = count(),
            "channels" => m.channels = count(),
            "slices" => m.slices = count(),
            "frames" => m.frames = count(),
            "spacing" => m.spacing = number(),
            "finterval" => m.finterval = number(),
            "unit" => m.unit = Some(unescape_unit(v)),
            _ => {}
        }
    }
    Some(m)
}

/// ImageJ writes `µ` as `\u00B5` in the unit.
fn unescape_unit(v: &str) -> String {
    v.replace("\\u00B5", "\u{b5}")
}

/// Pages decoded so far, in their sample type.
enum Pages {
    U8(Vec<u8>),
    I8(Vec<i8>),
    U16(Vec<u16>),
    I16(Vec<i16>),
    U32(Vec<u32>),
    I32(Vec<i32>),
    F32(Vec<f32>),
    F64(Vec<f64>),
}

impl Pages {
    fn voxel_type(&self) -> VoxelType {
        match self {
            Pages::U8(_) => VoxelType::U8,
            Pages::I8(_) => VoxelType::I8,
            Pages::U16(_) => VoxelType::U16,
            Pages::I16(_) => VoxelType::I16,
            Pages::U32(_) => VoxelType::U32,
            Pages::I32(_) => VoxelType::I32,
            Pages::F32(_) => VoxelType::F32,
            Pages::F64(_) => VoxelType::F64,
        }
    }

    fn len(&self) -> usize {
        match self {
            Pages::U8(v) => v.len(),
            Pages::I8(v) => v.len(),
            Pages::U16(v) => v.len(),
            Pages::I16(v) => v.len(),
            Pages::U32(v) => v.len(),
            Pages::I32(v) => v.len(),
            Pages::F32(v) => v.len(),
            Pages::F64(v) => v.len(),
        }
    }

    /// One decoded page as the start of a stack; `Err` names an unsupported sample type.
    fn from_page(page: DecodingResult) -> Result<Self, String> {
        Ok(match page {
            DecodingResult::U8(v) => Pages::U8(v),
            DecodingResult::I8(v) => Pages::I8(v),
            DecodingResult::U16(v) => Pages::U16(v),
            DecodingResult::I16(v) => Pages::I16(v),
            DecodingResult::U32(v) => Pages::U32(v),
            DecodingResult::I32(v) => Pages::I32(v),
            DecodingResult::F16(v) => Pages::F32(v.iter().map(|h| h.to_f32()).collect()),
            DecodingResult::F32(v) => Pages::F32(v),
            DecodingResult::F64(v) => Pages::F64(v),
            DecodingResult::U64(_) | DecodingResult::I64(_) => {
                return Err(
                    "64-bit integer samples are not supported (8 to 32-bit integers \
                            and floats are)"
                        .into(),
                );
            }
        })
    }

    /// Appends a page of the same sample type; `Err` names both types.
    fn push(&mut self, page: DecodingResult) -> Result<(), String> {
        let page = Pages::from_page(page)?;
        let (have, got) = (self.voxel_type(), page.voxel_type());
        match (self, page) {
            (Pages::U8(a), Pages::U8(b)) => a.extend(b),
            (Pages::I8(a), Pages::I8(b)) => a.extend(b),
            (Pages::U16(a), Pages::U16(b)) => a.extend(b),
            (Pages::I16(a), Pages::I16(b)) => a.extend(b),
            (Pages::U32(a), Pages::U32(b)) => a.extend(b),
            (Pages::I32(a), Pages::I32(b)) => a.extend(b),
            (Pages::F32(a), Pages::F32(b)) => a.extend(b),
            (Pages::F64(a), Pages::F64(b)) => a.extend(b),
            _ => {
                return Err(format!(
                    "samples of type {got}, but the first page's are {have}"
                ));
            }
        }
        Ok(())
    }

    /// Voxels `[start, start + count)`.
    fn range(&self, start: usize, count: usize) -> VoxelData {
        let r = start..start + count;
        match self {
            Pages::U8(v) => v[r].to_vec().into(),
            Pages::I8(v) => v[r].to_vec().into(),
            Pages::U16(v) => v[r].to_vec().into(),
            Pages::I16(v) => v[r].to_vec().into(),
            Pages::U32(v) => v[r].to_vec().into(),
            Pages::I32(v) => v[r].to_vec().into(),
            Pages::F32(v) => v[r].to_vec().into(),
            Pages::F64(v) => v[r].to_vec().into(),
        }
    }

    fn into_voxels(self) -> VoxelData {
        match self {
            Pages::U8(v) => v.into(),
            Pages::I8(v) => v.into(),
            Pages::U16(v) => v.into(),
            Pages::I16(v) => v.into(),
            Pages::U32(v) => v.into(),
            Pages::I32(v) => v.into(),
            Pages::F32(v) => v.into(),
            Pages::F64(v) => v.into(),
        }
    }
}

/// A `tiff` error on page `page` of `path`.
fn page_error(path: &Path, page: usize, e: &TiffError) -> FormatError {
    match e {
        TiffError::IoError(io) if io.kind() == std::io::ErrorKind::UnexpectedEof => {
            FormatError::Page {
                path: path.to_path_buf(),
                page,
                reason: format!("the file ends inside the page's data or directory ({io})"),
            }
        }
        other => FormatError::Page {
            path: path.to_path_buf(),
            page,
            reason: other.to_string(),
        },
    }
}

/// The pages of one TIFF file.
struct Reader<'a> {
    path: &'a Path,
    file_len: u64,
}

/// The most bytes `compressed` bytes can decode to with `method` (`None`: no bound known,
/// the method is refused).
fn max_decoded(method: CompressionMethod, compressed: u64) -> Option<u64> {
    let slack = 4096;
    Some(
        match method {
            CompressionMethod::None => compressed,
            // A 12-bit LZW code (at least 9 bits in the stream) emits at most 4096 bytes.
            CompressionMethod::LZW => compressed.saturating_mul(4096 * 8 / 9),
            // Deflate: at most 1032 bytes per compressed byte.
            CompressionMethod::Deflate | CompressionMethod::OldDeflate => {
                compressed.saturating_mul(1032)
            }
            // PackBits: a 2-byte run expands to at most 128 bytes.
            CompressionMethod::PackBits => compressed.saturating_mul(64),
            _ => return None,
        }
        .saturating_add(slack),
    )
}

impl Reader<'_> {
    fn err(&self, page: usize, reason: String) -> FormatError {
        FormatError::Page {
            path: self.path.to_path_buf(),
            page,
            reason,
        }
    }

    fn decoder<R: Read + Seek>(&self, reader: R) -> Result<Decoder<R>, FormatError> {
        let decoder = Decoder::new(reader).map_err(|e| match e {
            TiffError::FormatError(f) => FormatError::UnknownFormat {
                path: self.path.to_path_buf(),
                reason: format!("not a readable TIFF file: {f}"),
            },
            other => page_error(self.path, 0, &other),
        })?;
        // A compressed chunk is read whole before it is decoded: never more than the file;
        // a page never more than the file's bytes can decode to (each page is checked more
        // closely before it is decoded).
        let mut limits = Limits::default();
        limits.intermediate_buffer_size = usize::try_from(self.file_len)
            .unwrap_or(usize::MAX)
            .clamp(1 << 16, limits.intermediate_buffer_size);
        limits.decoding_buffer_size =
            usize::try_from(max_decoded(CompressionMethod::Deflate, self.file_len).unwrap_or(0))
                .unwrap_or(usize::MAX);
        Ok(decoder.with_limits(limits))
    }

    /// Checks the current page (greyscale, size, bytes present) and decodes it.
    fn page<R: Read + Seek>(
        &self,
        d: &mut Decoder<R>,
        page: usize,
        size: Option<(u32, u32)>,
    ) -> Result<(DecodingResult, (u32, u32)), FormatError> {
        let e = |err: TiffError| page_error(self.path, page, &err);
        let (w, h) = d.dimensions().map_err(e)?;
        if let Some(first) = size
            && first != (w, h)
        {
            return Err(self.err(
                page,
                format!(
                    "{w} x {h} pixels, but the first page is {} x {}: every page of a stack \
                     must have the same size",
                    first.0, first.1
                ),
            ));
        }
        let photometric = d
            .find_tag_unsigned::<u16>(Tag::PhotometricInterpretation)
            .map_err(e)?;
        if photometric == Some(PhotometricInterpretation::WhiteIsZero.to_u16()) {
            return Err(self.err(
                page,
                "WhiteIsZero greyscale (inverted values) is not read; only BlackIsZero".into(),
            ));
        }
        let bits = match d.colortype().map_err(e)? {
            ColorType::Gray(bits) => bits,
            other => {
                return Err(self.err(
                    page,
                    format!(
                        "colour type {other:?}: only greyscale pages (one sample per pixel) \
                         are volumes"
                    ),
                ));
            }
        };
        if !matches!(bits, 8 | 16 | 32 | 64) {
            return Err(self.err(
                page,
                format!("{bits}-bit samples: only 8, 16, 32 and 64-bit samples are read"),
            ));
        }
        let page_bytes = u64::from(w)
            .saturating_mul(u64::from(h))
            .saturating_mul(u64::from(bits / 8));
        let method = d
            .find_tag_unsigned::<u16>(Tag::Compression)
            .map_err(e)?
            .map_or(
                CompressionMethod::None,
                CompressionMethod::from_u16_exhaustive,
            );
        let counts = match d
            .find_tag_unsigned_vec::<u64>(Tag::StripByteCounts)
            .map_err(e)?
        {
            Some(c) => c,
            None => d
                .find_tag_unsigned_vec::<u64>(Tag::TileByteCounts)
                .map_err(e)?
                .unwrap_or_default(),
        };
        let stored = counts.iter().fold(0u64, |a, &c| a.saturating_add(c));
        if stored > self.file_len {
            return Err(self.err(
                page,
                format!(
                    "its strips or tiles claim {stored} bytes, but the file has {} bytes",
                    self.file_len
                ),
            ));
        }
        let Some(most) = max_decoded(method, stored) else {
            return Err(self.err(
                page,
                format!("compression {method:?} is not read (none, LZW, deflate and PackBits are)"),
            ));
        };
        if page_bytes > most {
            return Err(self.err(
                page,
                format!(
                    "{w} x {h} pixels of {bits} bits need {page_bytes} bytes, but its {} \
                     strips or tiles ({stored} bytes, {method:?}) can hold at most {most}",
                    counts.len()
                ),
            ));
        }
        let image = d.read_image().map_err(e)?;
        Ok((image, (w, h)))
    }

    /// Decodes the pages of the open file, at most `max_pages`, appending to `pages`.
    fn all_pages<R: Read + Seek>(
        &self,
        mut d: Decoder<R>,
        pages: &mut Option<Pages>,
        size: &mut Option<(u32, u32)>,
        first_page: usize,
        max_pages: usize,
    ) -> Result<usize, FormatError> {
        let mut n = 0;
        loop {
            let index = first_page + n;
            let (image, wh) = self.page(&mut d, index, *size)?;
            match pages {
                None => {
                    *pages = Some(Pages::from_page(image).map_err(|r| self.err(index, r))?);
                }
                Some(p) => p.push(image).map_err(|r| self.err(index, r))?,
            }
            *size = Some(wh);
            n += 1;
            if n == max_pages || !d.more_images() {
                return Ok(n);
            }
            d.next_image()
                .map_err(|err| page_error(self.path, index + 1, &err))?;
        }
    }
}

/// The spacing recorded by an ImageJ file's first page: x, y from the resolution tags, z
/// from `spacing=`.
fn recorded_spacing<R: Read + Seek>(
    d: &mut Decoder<R>,
    imagej: Option<&ImageJ>,
) -> [Option<f64>; 3] {
    let Some(ij) = imagej else {
        return [None; 3];
    };
    let per_unit = |d: &mut Decoder<R>, tag: Tag| -> Option<f64> {
        let v = match d.find_tag(tag).ok()?? {
            Value::Rational(n, den) => f64::from(n) / f64::from(den),
            Value::Float(x) => f64::from(x),
            Value::Double(x) => x,
            _ => return None,
        };
        (v.is_finite() && v > 0.0).then(|| 1.0 / v)
    };
    [
        per_unit(d, Tag::XResolution),
        per_unit(d, Tag::YResolution),
        ij.spacing,
    ]
}

/// The ImageJ metadata of the current page, if any.
fn imagej_of<R: Read + Seek>(d: &mut Decoder<R>) -> Option<ImageJ> {
    let desc = d.get_tag_ascii_string(Tag::ImageDescription).ok()?;
    parse_imagej(&desc)
}

fn open_file(path: &Path) -> Result<(BufReader<std::fs::File>, u64), FormatError> {
    let file = crate::input::open_regular(path).map_err(|e| FormatError::io(path, e))?;
    let len = file.metadata().map_err(|e| FormatError::io(path, e))?.len();
    Ok((BufReader::with_capacity(1 << 16, file), len))
}

/// True if the TIFF at `path` has exactly one page (a 2D image).
pub fn is_single_page(path: &Path) -> Result<bool, FormatError> {
    let (reader, file_len) = open_file(path)?;
    let r = Reader { path, file_len };
    let d = r.decoder(reader)?;
    Ok(!d.more_images())
}

/// Reads a TIFF file: its pages are the z slices of a volume; an ImageJ file with several
/// frames is a time series.
pub fn read_tiff(path: &Path, options: &OpenOptions) -> Result<Dataset, FormatError> {
    let (reader, file_len) = open_file(path)?;
    read_tiff_from(path, reader, file_len, options)
}

/// [`read_tiff`] on the file's bytes in memory (`path` only names it in errors): for fuzzing.
pub fn parse_tiff(
    path: &Path,
    bytes: &[u8],
    options: &OpenOptions,
) -> Result<Dataset, FormatError> {
    read_tiff_from(
        path,
        std::io::Cursor::new(bytes),
        bytes.len() as u64,
        options,
    )
}

fn read_tiff_from<R: Read + Seek>(
    path: &Path,
    reader: R,
    file_len: u64,
    options: &OpenOptions,
) -> Result<Dataset, FormatError> {
    let r = Reader { path, file_len };
    let mut d = r.decoder(reader)?;
    let imagej = imagej_of(&mut d);
    let recorded = recorded_spacing(&mut d, imagej.as_ref());
    if let Some(c) = imagej.as_ref().and_then(|m| m.channels)
        && c > 1
    {
        return Err(FormatError::Unsupported {
            path: path.to_path_buf(),
            field: "ImageDescription".into(),
            reason: format!("ImageJ channels={c}: only one channel can be a volume"),
        });
    }
    let mut pages = None;
    let mut size = None;
    let n = r.all_pages(d, &mut pages, &mut size, 0, usize::MAX)?;
    let pages = pages.expect("at least one page");
    let (w, h) = size.expect("at least one page");
    let frames = imagej.as_ref().and_then(|m| m.frames).unwrap_or(1).max(1);
    if let Some(images) = imagej.as_ref().and_then(|m| m.images)
        && images != n
    {
        return Err(FormatError::BadValue {
            path: path.to_path_buf(),
            line: 0,
            field: "ImageDescription images".into(),
            reason: format!(
                "ImageJ says {images} images but the file has {n} pages (ImageJ files of one \
                 page with the rest of the stack after it are not read)"
            ),
        });
    }
    if n % frames != 0 {
        return Err(FormatError::BadValue {
            path: path.to_path_buf(),
            line: 0,
            field: "ImageDescription frames".into(),
            reason: format!("{frames} frames do not divide the {n} pages"),
        });
    }
    let depth = n / frames;
    let spacing = axis_spacing(recorded, options);
    let grid = Grid::uniform([w as usize, h as usize, depth], [0.0; 3], spacing)
        .map_err(|e| FormatError::geometry(path, e))?;
    if frames == 1 {
        let v = RectilinearVolume::new(grid, pages.into_voxels())
            .map_err(|e| FormatError::geometry(path, e))?;
        return Ok(Dataset::Volume(v));
    }
    let per = grid.voxel_count();
    let steps = (0..frames)
        .map(|f| RectilinearVolume::new(grid.clone(), pages.range(f * per, per)))
        .collect::<Result<Vec<_>, _>>()
        .map_err(|e| FormatError::geometry(path, e))?;
    let loader = FrameSteps {
        path: path.to_path_buf(),
        steps,
        interval: imagej.and_then(|m| m.finterval),
    };
    let series = TimeSeries::open(Arc::new(loader)).map_err(|e| FormatError::Series {
        path: path.to_path_buf(),
        reason: e.to_string(),
    })?;
    Ok(Dataset::Series(series))
}

/// Per axis: the recorded spacing, else the option's, else 1.
fn axis_spacing(recorded: [Option<f64>; 3], options: &OpenOptions) -> [f64; 3] {
    [0, 1, 2].map(|a| recorded[a].or(options.spacing.map(|s| s[a])).unwrap_or(1.0))
}

/// Reads numbered single-page TIFF files (in order) as the z slices of one volume.
pub fn read_slices(
    files: &[PathBuf],
    options: &OpenOptions,
) -> Result<RectilinearVolume, FormatError> {
    let mut pages = None;
    let mut size = None;
    let mut recorded = [None; 3];
    for (i, path) in files.iter().enumerate() {
        let (reader, file_len) = open_file(path)?;
        let r = Reader { path, file_len };
        let mut d = r.decoder(reader)?;
        if i == 0 {
            let imagej = imagej_of(&mut d);
            recorded = recorded_spacing(&mut d, imagej.as_ref());
        }
        if d.more_images() {
            return Err(FormatError::Page {
                path: path.clone(),
                page: 1,
                reason: format!(
                    "a file of several pages among the 2D slices (the first file, {}, has \
                     one page)",
                    files[0].display()
                ),
            });
        }
        r.all_pages(d, &mut pages, &mut size, 0, 1)
            .map_err(|e| match e {
                // Pages of the other files are named by their file, page 0.
                FormatError::Page { path, page, reason } if i > 0 => FormatError::Page {
                    path,
                    page,
                    reason: format!("{reason} (first file: {})", files[0].display()),
                },
                other => other,
            })?;
    }
    let pages = pages.ok_or_else(|| FormatError::Series {
        path: files.first().cloned().unwrap_or_default(),
        reason: "no files".into(),
    })?;
    let (w, h) = size.expect("one page per file");
    debug_assert_eq!(pages.len(), w as usize * h as usize * files.len());
    let first = &files[0];
    let grid = Grid::uniform(
        [w as usize, h as usize, files.len()],
        [0.0; 3],
        axis_spacing(recorded, options),
    )
    .map_err(|e| FormatError::geometry(first, e))?;
    RectilinearVolume::new(grid, pages.into_voxels()).map_err(|e| FormatError::geometry(first, e))
}

/// The frames of an ImageJ hyperstack, decoded at open.
struct FrameSteps {
    path: PathBuf,
    steps: Vec<RectilinearVolume>,
    interval: Option<f64>,
}

impl StepLoader for FrameSteps {
    fn step_count(&self) -> usize {
        self.steps.len()
    }

    fn load_step(&self, step: usize) -> Result<RectilinearVolume, String> {
        self.steps
            .get(step)
            .cloned()
            .ok_or_else(|| format!("{}: step {step} out of range", self.path.display()))
    }

    fn time_value(&self, step: usize) -> Option<f64> {
        self.interval.map(|dt| step as f64 * dt)
    }

    fn describe(&self) -> String {
        format!(
            "{} frames of ImageJ TIFF {}",
            self.steps.len(),
            self.path.display()
        )
    }
}

/// True if numbered `files` are the 2D slices of one volume: TIFF files whose first has
/// one page ([`read_slices`] reads them); otherwise numbered files are a time series.
/// Reads the first file's header only.
pub fn is_slice_stack(files: &[PathBuf]) -> Result<bool, FormatError> {
    match files.first() {
        Some(first) if is_tiff_path(first) => is_single_page(first),
        _ => Ok(false),
    }
}

/// True for `.tif` and `.tiff` names.
pub fn is_tiff_path(path: &Path) -> bool {
    path.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("tif") || e.eq_ignore_ascii_case("tiff"))
}
