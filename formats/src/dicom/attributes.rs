//! The attributes that place, size and scale the frames of a DICOM image.
//!
//! A single-frame image has one [`FrameInfo`] from its top-level ImagePositionPatient,
//! ImageOrientationPatient, PixelSpacing and RescaleSlope/RescaleIntercept. An enhanced
//! multi-frame image (CT, MR, PET ...) takes each frame's from its Per-frame Functional Groups
//! (PlanePositionSequence, PlaneOrientationSequence, PixelMeasuresSequence,
//! PixelValueTransformationSequence, FrameContentSequence), falling back to the Shared
//! Functional Groups and then to the top level (PS3.3 C.7.6.16). A multi-frame image without
//! per-frame positions (RT Dose, NM) places frame k at ImagePositionPatient + offset_k · normal,
//! the offsets from GridFrameOffsetVector (3004,000C) or k · SpacingBetweenSlices.

use dicom_core::dictionary::{DataDictionary, DataDictionaryEntry};
use dicom_core::{Tag, VR};
use dicom_dictionary_std::StandardDataDictionary;
use dicom_dictionary_std::tags;
use dicom_object::InMemDicomObject;
use glam::DVec3;

use super::file::{DicomFile, PixelCodec};
use super::pixels::PixelFormat;
use super::scan::PixelValue;
use crate::error::FormatError;

/// Where one frame lies and how its values scale.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct FrameInfo {
    /// ImagePositionPatient: the centre of the first transmitted pixel (LPS, mm).
    pub position: Option<DVec3>,
    /// ImageOrientationPatient: the row direction (+column index) and the column direction
    /// (+row index), unit vectors.
    pub orientation: Option<[DVec3; 2]>,
    /// PixelSpacing: `[row spacing, column spacing]` = `[Δ between rows (along the column
    /// direction), Δ between columns (along the row direction)]`, mm.
    pub pixel_spacing: Option<[f64; 2]>,
    /// `(RescaleSlope, RescaleIntercept)`, `(1, 0)` when absent.
    pub rescale: (f64, f64),
    /// TemporalPositionIdentifier (0020,0100) or, in functional groups, TemporalPositionIndex.
    pub temporal: Option<i64>,
}

/// What a DICOM file holds, for grouping into series.
#[derive(Debug, Clone)]
pub(crate) enum Content {
    /// An image usable as volume slices.
    Image(Box<ImageInfo>),
    /// Not a grayscale image (no pixel data, color, 1-bit ...): why, for the skip note.
    Skip(String),
}

/// The attributes of an image file.
#[derive(Debug, Clone)]
pub(crate) struct ImageInfo {
    pub series_uid: String,
    pub series_description: String,
    pub series_number: Option<i64>,
    pub modality: String,
    pub format: PixelFormat,
    pub frames: Vec<FrameInfo>,
    /// The transfer syntax, `"UID (name)"`, and whether Isoscope decodes it.
    pub syntax: String,
    pub decodable: bool,
}

/// `"ImagePositionPatient (0020,0032)"`.
pub(crate) fn attribute_name(tag: Tag) -> String {
    let name = StandardDataDictionary
        .by_tag(tag)
        .map_or("attribute", |e| e.alias());
    format!("{name} ({:04X},{:04X})", tag.0, tag.1)
}

struct Reader<'a> {
    file: &'a DicomFile,
}

impl Reader<'_> {
    fn bad(&self, tag: Tag, reason: impl Into<String>) -> FormatError {
        FormatError::DicomAttribute {
            path: self.file.path.clone(),
            attribute: attribute_name(tag),
            reason: reason.into(),
        }
    }

    fn string(obj: &InMemDicomObject, tag: Tag) -> Option<String> {
        let v = obj.get(tag)?.value().to_str().ok()?;
        let s = v.trim_matches(|c: char| c == '\0' || c.is_whitespace());
        (!s.is_empty()).then(|| s.to_string())
    }

    /// The text of a value stored as UN (some writers lose the VR of DS/IS attributes).
    fn un_text(obj: &InMemDicomObject, tag: Tag) -> Option<String> {
        let e = obj.get(tag)?;
        (e.vr() == VR::UN).then(|| {
            let bytes = e.value().to_bytes().unwrap_or_default();
            String::from_utf8_lossy(&bytes).into_owned()
        })
    }

    /// A multi-valued decimal attribute with exactly `n` finite values (an empty value is
    /// absent).
    fn floats(
        &self,
        obj: &InMemDicomObject,
        tag: Tag,
        n: usize,
    ) -> Result<Option<Vec<f64>>, FormatError> {
        let Some(e) = obj.get(tag) else {
            return Ok(None);
        };
        let v: Vec<f64> = if let Some(text) = Self::un_text(obj, tag) {
            let text = text.trim_matches(|c: char| c == '\0' || c.is_whitespace());
            if text.is_empty() {
                return Ok(None);
            }
            text.split('\\')
                .map(|p| {
                    p.trim_matches(|c: char| c == '\0' || c.is_whitespace())
                        .parse::<f64>()
                })
                .collect::<Result<_, _>>()
                .map_err(|err| {
                    self.bad(
                        tag,
                        format!("`{text}` (stored as UN) is not numbers: {err}"),
                    )
                })?
        } else {
            if e.value().multiplicity() == 0
                || e.value()
                    .to_str()
                    .is_ok_and(|s| s.trim_matches(['\0', ' ']).is_empty())
            {
                return Ok(None);
            }
            e.value()
                .to_multi_float64()
                .map_err(|err| self.bad(tag, format!("not numbers: {err}")))?
        };
        if v.len() != n {
            return Err(self.bad(tag, format!("expected {n} numbers, found {}", v.len())));
        }
        if let Some(x) = v.iter().find(|x| !x.is_finite()) {
            return Err(self.bad(tag, format!("value {x} is not finite")));
        }
        Ok(Some(v))
    }

    fn float(&self, obj: &InMemDicomObject, tag: Tag) -> Result<Option<f64>, FormatError> {
        Ok(self.floats(obj, tag, 1)?.map(|v| v[0]))
    }

    fn int(&self, obj: &InMemDicomObject, tag: Tag) -> Result<Option<i64>, FormatError> {
        let Some(e) = obj.get(tag) else {
            return Ok(None);
        };
        if e.vr() == VR::UN {
            // Binary US/UL/SS/SL (little endian) or IS text, by the dictionary's VR.
            let bytes = e.value().to_bytes().unwrap_or_default();
            let vr = StandardDataDictionary.by_tag(tag).map(|d| d.vr().relaxed());
            let le = |n: usize| {
                bytes
                    .get(..n)
                    .map(|b| b.iter().rev().fold(0u64, |a, &x| (a << 8) | u64::from(x)))
            };
            let v = match vr {
                Some(VR::US) => le(2).map(|v| v as i64),
                Some(VR::SS) => le(2).map(|v| i64::from(v as u16 as i16)),
                Some(VR::UL) => le(4).map(|v| v as i64),
                Some(VR::SL) => le(4).map(|v| i64::from(v as u32 as i32)),
                _ => String::from_utf8_lossy(&bytes)
                    .trim_matches(|c: char| c == '\0' || c.is_whitespace())
                    .parse()
                    .ok(),
            };
            return v
                .map(Some)
                .ok_or_else(|| self.bad(tag, "stored as UN and not readable as an integer"));
        }
        if e.value().multiplicity() == 0 {
            return Ok(None);
        }
        e.value()
            .to_int::<i64>()
            .map(Some)
            .map_err(|err| self.bad(tag, format!("not an integer: {err}")))
    }

    fn required_u16(&self, obj: &InMemDicomObject, tag: Tag) -> Result<u16, FormatError> {
        let v = self
            .int(obj, tag)?
            .ok_or_else(|| self.bad(tag, "missing"))?;
        u16::try_from(v).map_err(|_| self.bad(tag, format!("{v} is out of range")))
    }

    /// The first item of sequence `tag` in `obj`.
    fn item(obj: &InMemDicomObject, tag: Tag) -> Option<&InMemDicomObject> {
        obj.get(tag)?.value().items()?.first()
    }

    fn position(&self, obj: &InMemDicomObject) -> Result<Option<DVec3>, FormatError> {
        Ok(self
            .floats(obj, tags::IMAGE_POSITION_PATIENT, 3)?
            .map(|v| DVec3::new(v[0], v[1], v[2])))
    }

    fn orientation(&self, obj: &InMemDicomObject) -> Result<Option<[DVec3; 2]>, FormatError> {
        let tag = tags::IMAGE_ORIENTATION_PATIENT;
        let Some(v) = self.floats(obj, tag, 6)? else {
            return Ok(None);
        };
        let row = DVec3::new(v[0], v[1], v[2]);
        let col = DVec3::new(v[3], v[4], v[5]);
        // Writers round the cosines to a few digits: accept 1 % off unit length and
        // perpendicularity, then normalize.
        let (lr, lc) = (row.length(), col.length());
        if (lr - 1.0).abs() > 0.01 || (lc - 1.0).abs() > 0.01 {
            return Err(self.bad(
                tag,
                format!("direction cosines {row} and {col} are not unit vectors"),
            ));
        }
        let (row, col) = (row / lr, col / lc);
        if row.dot(col).abs() > 0.01 {
            return Err(self.bad(
                tag,
                format!("the row direction {row} and column direction {col} are not perpendicular"),
            ));
        }
        Ok(Some([row, col]))
    }

    fn spacing(&self, obj: &InMemDicomObject) -> Result<Option<[f64; 2]>, FormatError> {
        let tag = tags::PIXEL_SPACING;
        let Some(v) = self.floats(obj, tag, 2)? else {
            return Ok(None);
        };
        if !(v[0] > 0.0 && v[1] > 0.0) {
            return Err(self.bad(
                tag,
                format!("spacings {} and {} must be positive", v[0], v[1]),
            ));
        }
        Ok(Some([v[0], v[1]]))
    }

    /// `(slope, intercept)` in `obj` if it has either.
    fn rescale(&self, obj: &InMemDicomObject) -> Result<Option<(f64, f64)>, FormatError> {
        let slope = self.float(obj, tags::RESCALE_SLOPE)?;
        let intercept = self.float(obj, tags::RESCALE_INTERCEPT)?;
        if slope == Some(0.0) {
            return Err(self.bad(
                tags::RESCALE_SLOPE,
                "a slope of 0 maps every value to the intercept",
            ));
        }
        Ok((slope.is_some() || intercept.is_some())
            .then(|| (slope.unwrap_or(1.0), intercept.unwrap_or(0.0))))
    }

    /// The first of `groups` (per-frame item, shared item, top level) where `get` finds a
    /// value inside sequence `seq` (the top level is read directly).
    fn grouped<T>(
        groups: &[Option<&InMemDicomObject>],
        top: &InMemDicomObject,
        seq: Tag,
        get: impl Fn(&InMemDicomObject) -> Result<Option<T>, FormatError>,
    ) -> Result<Option<T>, FormatError> {
        for g in groups.iter().flatten() {
            if let Some(item) = Self::item(g, seq)
                && let Some(v) = get(item)?
            {
                return Ok(Some(v));
            }
        }
        get(top)
    }
}

/// Reads what `file` holds (see the module docs).
pub(crate) fn content(file: &DicomFile) -> Result<Content, FormatError> {
    let r = Reader { file };
    let a = &file.attributes;
    let Some(pixel) = &file.pixel else {
        if file.sop_class_uid == super::file::DICOMDIR_SOP_CLASS {
            return Ok(Content::Skip(
                "a DICOMDIR (open it to read the files it lists)".into(),
            ));
        }
        let class = sop_class_name(&file.sop_class_uid);
        return Ok(Content::Skip(format!("no pixel data ({class})")));
    };
    let samples = r.int(a, tags::SAMPLES_PER_PIXEL)?.unwrap_or(1);
    let photometric =
        Reader::string(a, tags::PHOTOMETRIC_INTERPRETATION).unwrap_or_else(|| "MONOCHROME2".into());
    if samples != 1 {
        return Ok(Content::Skip(format!(
            "a color image (SamplesPerPixel {samples}, {photometric}); volumes are grayscale"
        )));
    }
    if photometric.starts_with("PALETTE") {
        return Ok(Content::Skip(
            "a PALETTE COLOR image (its values index a color table); volumes are grayscale".into(),
        ));
    }
    let float = pixel.tag != tags::PIXEL_DATA;
    let rows = r.required_u16(a, tags::ROWS)?;
    let cols = r.required_u16(a, tags::COLUMNS)?;
    if rows == 0 || cols == 0 {
        return Err(r.bad(
            tags::ROWS,
            format!("an image of {cols}×{rows} pixels (Columns×Rows)"),
        ));
    }
    let bits_allocated = if float {
        if pixel.tag == tags::DOUBLE_FLOAT_PIXEL_DATA {
            64
        } else {
            32
        }
    } else {
        r.required_u16(a, tags::BITS_ALLOCATED)?
    };
    if !float && !matches!(bits_allocated, 8 | 16 | 32) {
        return Ok(Content::Skip(format!(
            "{bits_allocated}-bit pixels (BitsAllocated); volumes need 8, 16 or 32"
        )));
    }
    let bits_stored = if float {
        bits_allocated
    } else {
        r.int(a, tags::BITS_STORED)?
            .map_or(Ok(bits_allocated), |v| {
                u16::try_from(v)
                    .map_err(|_| r.bad(tags::BITS_STORED, format!("{v} is out of range")))
            })?
    };
    if bits_stored == 0 || bits_stored > bits_allocated {
        return Err(r.bad(
            tags::BITS_STORED,
            format!("{bits_stored} bits stored in {bits_allocated} allocated"),
        ));
    }
    let high_bit = if float {
        bits_allocated - 1
    } else {
        r.int(a, tags::HIGH_BIT)?
            .unwrap_or(i64::from(bits_stored) - 1)
            .clamp(0, 64) as u16
    };
    if high_bit + 1 < bits_stored || high_bit >= bits_allocated {
        return Err(r.bad(
            tags::HIGH_BIT,
            format!("high bit {high_bit} with {bits_stored} bits stored in {bits_allocated}"),
        ));
    }
    let signed = !float && r.int(a, tags::PIXEL_REPRESENTATION)?.unwrap_or(0) == 1;
    let format = PixelFormat {
        rows: usize::from(rows),
        cols: usize::from(cols),
        bits_allocated,
        bits_stored,
        high_bit,
        signed,
        float,
    };
    let frame_count = match r.int(a, tags::NUMBER_OF_FRAMES)? {
        None => 1,
        Some(n) if n >= 1 && n <= i64::from(u32::MAX) => n as usize,
        Some(n) => return Err(r.bad(tags::NUMBER_OF_FRAMES, format!("{n} frames"))),
    };
    // Sizes against the data before anything is allocated.
    match &pixel.value {
        PixelValue::Native(range) => {
            let needed = (frame_count as u64).saturating_mul(format.frame_bytes() as u64);
            let have = (range.end - range.start) as u64;
            if have < needed && matches!(file.syntax.codec, PixelCodec::Native { .. }) {
                return Err(FormatError::TooShort {
                    path: file.path.clone(),
                    offset: range.start as u64,
                    needed,
                    available: have,
                });
            }
        }
        PixelValue::Encapsulated { fragments, .. } => {
            if fragments.is_empty() {
                return Err(FormatError::DicomFile {
                    path: file.path.clone(),
                    reason: "encapsulated pixel data without fragments".into(),
                });
            }
            if frame_count > fragments.len() {
                return Err(FormatError::DicomFile {
                    path: file.path.clone(),
                    reason: format!(
                        "{frame_count} frames (NumberOfFrames) in {} pixel data fragments",
                        fragments.len()
                    ),
                });
            }
            // No codec expands its bytes beyond its ratio: a larger image means a lying header
            // (checked per frame again when decoding).
            let encoded: u64 = fragments.iter().map(|f| (f.end - f.start) as u64).sum();
            let ratio = super::pixels::max_ratio(file.syntax.codec) as u64;
            let decoded = (frame_count as u64).saturating_mul(format.frame_bytes() as u64);
            if file.syntax.codec != PixelCodec::Unsupported
                && decoded
                    > encoded
                        .saturating_mul(ratio)
                        .saturating_add((frame_count as u64).saturating_mul(64 << 10))
            {
                return Err(FormatError::DicomFile {
                    path: file.path.clone(),
                    reason: format!(
                        "{frame_count} frame(s) of {}×{} samples of {} bits ({decoded} bytes) \
                         cannot come from {encoded} encoded bytes in {}",
                        format.cols,
                        format.rows,
                        format.bits_allocated,
                        file.syntax.describe()
                    ),
                });
            }
        }
    }
    let frames = frames(&r, frame_count)?;
    Ok(Content::Image(Box::new(ImageInfo {
        series_uid: Reader::string(a, tags::SERIES_INSTANCE_UID).unwrap_or_default(),
        series_description: Reader::string(a, tags::SERIES_DESCRIPTION).unwrap_or_default(),
        series_number: r.int(a, tags::SERIES_NUMBER).ok().flatten(),
        modality: Reader::string(a, tags::MODALITY).unwrap_or_default(),
        format,
        frames,
        syntax: file.syntax.describe(),
        decodable: file.syntax.codec != PixelCodec::Unsupported,
    })))
}

/// The per-frame geometry (see the module docs).
fn frames(r: &Reader<'_>, count: usize) -> Result<Vec<FrameInfo>, FormatError> {
    let a = &r.file.attributes;
    let shared = Reader::item(a, tags::SHARED_FUNCTIONAL_GROUPS_SEQUENCE);
    let per_frame = a
        .get(tags::PER_FRAME_FUNCTIONAL_GROUPS_SEQUENCE)
        .and_then(|e| e.value().items());
    if let Some(items) = per_frame
        && items.len() != count
    {
        return Err(r.bad(
            tags::PER_FRAME_FUNCTIONAL_GROUPS_SEQUENCE,
            format!("{} items for {count} frames (NumberOfFrames)", items.len()),
        ));
    }
    let top_rescale = match r.rescale(a)? {
        Some(m) => Some(m),
        // RT Dose: dose = stored · DoseGridScaling.
        None => r
            .float(a, tags::DOSE_GRID_SCALING)?
            .filter(|s| *s != 0.0)
            .map(|s| (s, 0.0)),
    };
    let top_temporal = r.int(a, tags::TEMPORAL_POSITION_IDENTIFIER)?;
    // Frames without their own positions: offsets along the normal.
    let offsets: Option<Vec<f64>> = if count > 1 && per_frame.is_none() {
        if let Some(v) = r.floats(a, tags::GRID_FRAME_OFFSET_VECTOR, count)? {
            Some(v.iter().map(|g| g - v[0]).collect())
        } else {
            r.float(a, tags::SPACING_BETWEEN_SLICES)?
                .filter(|s| *s > 0.0)
                .map(|s| (0..count).map(|k| k as f64 * s).collect())
        }
    } else {
        None
    };
    let mut out = Vec::with_capacity(count);
    for k in 0..count {
        let own = per_frame.map(|items| &items[k]);
        let groups = [own, shared];
        let mut position =
            Reader::grouped(&groups, a, tags::PLANE_POSITION_SEQUENCE, |o| r.position(o))?;
        let orientation = Reader::grouped(&groups, a, tags::PLANE_ORIENTATION_SEQUENCE, |o| {
            r.orientation(o)
        })?;
        let pixel_spacing =
            Reader::grouped(&groups, a, tags::PIXEL_MEASURES_SEQUENCE, |o| r.spacing(o))?;
        let rescale = match Reader::grouped(
            &[own, shared],
            a,
            tags::PIXEL_VALUE_TRANSFORMATION_SEQUENCE,
            |o| r.rescale(o),
        )? {
            Some(m) => m,
            None => top_rescale.unwrap_or((1.0, 0.0)),
        };
        let temporal = match own.and_then(|o| Reader::item(o, tags::FRAME_CONTENT_SEQUENCE)) {
            Some(content) => r
                .int(content, tags::TEMPORAL_POSITION_INDEX)?
                .or(top_temporal),
            None => top_temporal,
        };
        if let (Some(offsets), Some(p), Some([row, col])) = (&offsets, position, orientation) {
            position = Some(p + offsets[k] * row.cross(col));
        } else if count > 1 && per_frame.is_none() {
            // Several frames at one position cannot be placed.
            position = None;
        }
        out.push(FrameInfo {
            position,
            orientation,
            pixel_spacing,
            rescale,
            temporal,
        });
    }
    Ok(out)
}

/// The name of a SOP class UID, or the UID.
pub(crate) fn sop_class_name(uid: &str) -> String {
    use dicom_core::dictionary::{UidDictionary, UidDictionaryEntry};
    if uid.is_empty() {
        return "no SOP class".into();
    }
    dicom_dictionary_std::sop_class::StandardSopClassDictionary
        .by_uid(uid)
        .map_or_else(|| uid.to_string(), |e| e.name().to_string())
}
