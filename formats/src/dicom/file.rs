//! One DICOM Part 10 file: preamble, file meta group, transfer syntax, attributes, and where
//! its pixel data lies.
//!
//! The bytes are read whole through [`crate::input`], walked by [`super::scan`] (every
//! length checked against the file), and only the attributes before the pixel data are
//! parsed by dicom-rs ([`InMemDicomObject`]). A deflated data set (Deflated Explicit VR Little
//! Endian) is inflated here first, at most [`MAX_INFLATED_BYTES`].

use std::io::Read as _;
use std::path::{Path, PathBuf};

use dicom_object::InMemDicomObject;
use dicom_transfer_syntax_registry::{TransferSyntaxIndex, TransferSyntaxRegistry};

use super::scan::{self, Encoding, PixelElement};
use crate::error::FormatError;

/// Largest inflated data set of a deflated file (DICOM elements are limited to 4 GiB, and a
/// deflated image of this size does not occur; a deflate bomb stops here).
pub(crate) const MAX_INFLATED_BYTES: u64 = 1 << 30;

/// How the pixel data of a transfer syntax is encoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum PixelCodec {
    /// Native values in the data set's byte order.
    Native { big_endian: bool },
    /// Encapsulated Uncompressed Explicit VR Little Endian: one native frame per fragment.
    EncapsulatedNative,
    /// Deflated Image Frame Compression: each frame raw-deflated.
    DeflatedFrames,
    /// RLE Lossless (PS3.5 Annex G).
    Rle,
    /// JPEG baseline, extended (8-bit) and lossless: jpeg-decoder.
    Jpeg,
    /// JPEG 2000 (lossless and lossy): hayro-jpeg2000.
    Jpeg2000,
    /// A syntax whose pixel data Isoscope cannot decode (JPEG-LS, HTJ2K, JPEG XL, video...).
    Unsupported,
}

/// The transfer syntax of a file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct Syntax {
    pub uid: String,
    /// Its name in the standard registry ("unknown transfer syntax" otherwise).
    pub name: String,
    pub codec: PixelCodec,
    encoding: Encoding,
    deflated: bool,
}

impl Syntax {
    pub(crate) fn from_uid(uid: &str) -> Self {
        let name = TransferSyntaxRegistry.get(uid).map_or_else(
            || "unknown transfer syntax".to_string(),
            |ts| ts.name().to_string(),
        );
        let native_le = PixelCodec::Native { big_endian: false };
        let (codec, encoding, deflated) = match uid {
            "1.2.840.10008.1.2" => (
                native_le,
                Encoding {
                    explicit_vr: false,
                    big_endian: false,
                },
                false,
            ),
            "1.2.840.10008.1.2.1" => (native_le, Encoding::EXPLICIT_LE, false),
            "1.2.840.10008.1.2.2" => (
                PixelCodec::Native { big_endian: true },
                Encoding {
                    explicit_vr: true,
                    big_endian: true,
                },
                false,
            ),
            "1.2.840.10008.1.2.1.99" => (native_le, Encoding::EXPLICIT_LE, true),
            "1.2.840.10008.1.2.1.98" => {
                (PixelCodec::EncapsulatedNative, Encoding::EXPLICIT_LE, false)
            }
            "1.2.840.10008.1.2.8.1" => (PixelCodec::DeflatedFrames, Encoding::EXPLICIT_LE, false),
            "1.2.840.10008.1.2.5" => (PixelCodec::Rle, Encoding::EXPLICIT_LE, false),
            "1.2.840.10008.1.2.4.50"
            | "1.2.840.10008.1.2.4.51"
            | "1.2.840.10008.1.2.4.57"
            | "1.2.840.10008.1.2.4.70" => (PixelCodec::Jpeg, Encoding::EXPLICIT_LE, false),
            "1.2.840.10008.1.2.4.90" | "1.2.840.10008.1.2.4.91" => {
                (PixelCodec::Jpeg2000, Encoding::EXPLICIT_LE, false)
            }
            // Every encapsulated syntax encodes its data set as explicit VR little endian
            // (PS3.5 §10), so the attributes of an undecodable file can still be listed.
            _ => (PixelCodec::Unsupported, Encoding::EXPLICIT_LE, false),
        };
        Self {
            uid: uid.to_string(),
            name,
            codec,
            encoding,
            deflated,
        }
    }

    /// `"1.2.840.10008.1.2.4.80 (JPEG-LS Lossless Image Compression)"`.
    pub(crate) fn describe(&self) -> String {
        format!("{} ({})", self.uid, self.name)
    }
}

/// A read DICOM file.
pub(crate) struct DicomFile {
    pub path: PathBuf,
    pub syntax: Syntax,
    /// (0002,0002) Media Storage SOP Class UID (or (0008,0016) when the meta group lacks it).
    pub sop_class_uid: String,
    /// The attributes before the pixel data.
    pub attributes: InMemDicomObject,
    /// The top-level pixel data element, as ranges of [`DicomFile::data`].
    pub pixel: Option<PixelElement>,
    /// The data set bytes (inflated for a deflated file); empty unless pixels were asked for.
    pub data: Vec<u8>,
}

/// SOP class of a DICOMDIR (Media Storage Directory Storage).
pub(crate) const DICOMDIR_SOP_CLASS: &str = "1.2.840.10008.1.3.10";

/// What [`read`] reads.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Want {
    /// The attributes (and where the pixel data lies).
    Attributes,
    /// The attributes, but not those of a DICOMDIR (a folder scan skips it unread, so a
    /// damaged DICOMDIR beside good images does not stop the scan).
    ImageAttributes,
    /// The attributes and the data set bytes, to decode the pixels.
    Pixels,
}

/// True if `bytes` start like a DICOM Part 10 file (`DICM` at byte 128, or at 0 without the
/// preamble).
pub(crate) fn has_magic(bytes: &[u8]) -> bool {
    (bytes.len() >= 132 && &bytes[128..132] == b"DICM") || bytes.starts_with(b"DICM")
}

/// True if the regular file at `path` starts like a DICOM Part 10 file. Unreadable files and
/// non-regular files are not (the caller reports them when it opens them).
pub(crate) fn sniff(path: &Path) -> bool {
    let Ok(file) = crate::input::open_regular(path) else {
        return false;
    };
    let mut head = Vec::with_capacity(132);
    if file.take(132).read_to_end(&mut head).is_err() {
        return false;
    }
    has_magic(&head)
}

/// The whole error chain of a dicom-rs error, for messages.
pub(crate) fn error_chain(e: &dyn std::error::Error) -> String {
    let mut s = e.to_string();
    let mut source = e.source();
    while let Some(inner) = source {
        let text = inner.to_string();
        if !s.contains(&text) {
            s.push_str(": ");
            s.push_str(&text);
        }
        source = inner.source();
    }
    s
}

fn meta_string(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes)
        .trim_matches(|c: char| c == '\0' || c.is_whitespace())
        .to_string()
}

/// Reads `path` (see [`Want`]).
pub(crate) fn read(path: &Path, want: Want) -> Result<DicomFile, FormatError> {
    let bytes = crate::input::read_regular(path).map_err(|e| FormatError::io(path, e))?;
    parse(path, bytes, want)
}

/// [`read`] on bytes already in memory (`path` names them in errors).
pub(crate) fn parse(path: &Path, bytes: Vec<u8>, want: Want) -> Result<DicomFile, FormatError> {
    let bad = |reason: String| FormatError::DicomFile {
        path: path.to_path_buf(),
        reason,
    };
    let start = if bytes.len() >= 132 && &bytes[128..132] == b"DICM" {
        132
    } else if bytes.starts_with(b"DICM") {
        4
    } else {
        return Err(FormatError::UnknownFormat {
            path: path.to_path_buf(),
            reason: "not a DICOM file: no `DICM` at byte 128 (files without the DICOM Part 10 \
                     header are not read)"
                .into(),
        });
    };
    let (meta_len, meta) = scan::walk_meta(&bytes[start..]).map_err(|e| {
        bad(format!(
            "file meta group, byte {}: {}",
            start + e.offset,
            e.reason
        ))
    })?;
    let meta_value = |e: u16| {
        meta.iter()
            .find(|(t, _)| t.1 == e)
            .map(|(_, r)| meta_string(&bytes[start + r.start..start + r.end]))
    };
    let media_sop_class = meta_value(0x0002);
    let ts_uid = meta_value(0x0010)
        .filter(|s| !s.is_empty())
        .ok_or_else(|| FormatError::DicomAttribute {
            path: path.to_path_buf(),
            attribute: "TransferSyntaxUID (0002,0010)".into(),
            reason: "missing from the file meta group".into(),
        })?;
    let syntax = Syntax::from_uid(&ts_uid);
    if want == Want::ImageAttributes && media_sop_class.as_deref() == Some(DICOMDIR_SOP_CLASS) {
        return Ok(DicomFile {
            path: path.to_path_buf(),
            syntax,
            sop_class_uid: DICOMDIR_SOP_CLASS.into(),
            attributes: InMemDicomObject::new_empty(),
            pixel: None,
            data: Vec::new(),
        });
    }
    let data_start = start + meta_len;
    let mut data = if syntax.deflated {
        let mut out = Vec::new();
        flate2::read::DeflateDecoder::new(&bytes[data_start..])
            .take(MAX_INFLATED_BYTES + 1)
            .read_to_end(&mut out)
            .map_err(|e| FormatError::Decode {
                path: path.to_path_buf(),
                encoding: "deflate",
                offset: out.len() as u64,
                reason: e.to_string(),
            })?;
        if out.len() as u64 > MAX_INFLATED_BYTES {
            return Err(bad(format!(
                "the deflated data set inflates to more than {MAX_INFLATED_BYTES} bytes"
            )));
        }
        out
    } else {
        bytes[data_start..].to_vec()
    };
    drop(bytes);
    // Offsets in messages: of the file, or of the inflated data set.
    let where_ = |offset: usize| {
        if syntax.deflated {
            format!("inflated data set byte {offset}")
        } else {
            format!("byte {}", data_start + offset)
        }
    };
    let walked = scan::walk_dataset(&data, syntax.encoding)
        .map_err(|e| bad(format!("{}: {}", where_(e.offset), e.reason)))?;
    let parse_ts = match syntax.encoding {
        Encoding {
            explicit_vr: false, ..
        } => "1.2.840.10008.1.2",
        Encoding {
            big_endian: true, ..
        } => "1.2.840.10008.1.2.2",
        _ => "1.2.840.10008.1.2.1",
    };
    let ts = TransferSyntaxRegistry.get(parse_ts).ok_or_else(|| {
        bad(format!(
            "transfer syntax {parse_ts} missing from the registry"
        ))
    })?;
    let attributes = InMemDicomObject::read_dataset_with_ts(&data[..walked.attributes_end], ts)
        .map_err(|e| {
            bad(format!(
                "attributes ({} data set): {}",
                syntax.describe(),
                error_chain(&e)
            ))
        })?;
    let sop_class_uid = media_sop_class
        .filter(|s| !s.is_empty())
        .or_else(|| {
            attributes
                .get(dicom_dictionary_std::tags::SOP_CLASS_UID)
                .and_then(|e| e.value().to_str().ok())
                .map(|s| meta_string(s.as_bytes()))
        })
        .unwrap_or_default();
    if want != Want::Pixels {
        data = Vec::new();
    }
    Ok(DicomFile {
        path: path.to_path_buf(),
        syntax,
        sop_class_uid,
        attributes,
        pixel: walked.pixel,
        data,
    })
}
