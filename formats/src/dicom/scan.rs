//! The element walk that runs before dicom-rs sees a byte: every length checked.
//!
//! DICOM headers lie like any other: an element may claim 4 GB in a 1 kB file, and dicom-rs
//! reserves (and zero-fills) a value's claimed length before it reads it. So the data set is
//! first walked here, element by element and into every sequence and item, with the same
//! rules dicom-rs's parser follows (PS3.5 §7.1: which explicit VRs have 16-bit lengths, an
//! unknown VR read as UN, implicit VR from the standard dictionary, an undefined length
//! opening a sequence, encapsulated pixel data as items), and each defined length is checked
//! against the bytes its container still holds. Only a walk that fits is handed to dicom-rs,
//! so no value it reads can be longer than the file.
//!
//! The walk stops at the top-level pixel data element ((7FE0,0010), or float/double float
//! pixel data): its position is where the attributes end (dicom-rs parses only the bytes
//! before it), and its value is described here — native bytes, or the basic offset table and
//! fragments of encapsulated data — for [`super::pixels`] to decode without another parse.
//!
//! Nesting is limited to [`MAX_DEPTH`] levels, so a file of nested empty sequences cannot
//! exhaust the stack (of this walk or of dicom-rs's recursive object builder).

use std::ops::Range;

use dicom_core::dictionary::{DataDictionary, DataDictionaryEntry};
use dicom_core::{Tag, VR};
use dicom_dictionary_std::StandardDataDictionary;

/// Deepest sequence nesting accepted (real files nest a handful of levels).
pub(crate) const MAX_DEPTH: usize = 32;

/// How a data set is encoded (PS3.5 §7.1 and §7.3).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Encoding {
    pub explicit_vr: bool,
    pub big_endian: bool,
}

impl Encoding {
    pub(crate) const EXPLICIT_LE: Encoding = Encoding {
        explicit_vr: true,
        big_endian: false,
    };
}

/// The top-level pixel data element.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct PixelElement {
    /// (7FE0,0010) Pixel Data, (7FE0,0008) Float Pixel Data or (7FE0,0009) Double Float.
    pub tag: Tag,
    /// Byte offset of the element's header in the walked bytes.
    pub header_start: usize,
    pub value: PixelValue,
}

/// Where the pixel values are, as byte ranges of the walked bytes.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) enum PixelValue {
    /// Native (uncompressed) values of defined length.
    Native(Range<usize>),
    /// Encapsulated: the basic offset table (may be empty) and the fragments, in order.
    Encapsulated {
        offset_table: Vec<u32>,
        fragments: Vec<Range<usize>>,
    },
}

/// What the walk found.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct Walked {
    /// End of the attributes: the start of the pixel data element, or of the data.
    pub attributes_end: usize,
    pub pixel: Option<PixelElement>,
}

/// A structural problem at byte `offset` of the walked bytes.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct ScanError {
    pub offset: usize,
    pub reason: String,
}

type Result<T> = std::result::Result<T, ScanError>;

const ITEM: Tag = Tag(0xFFFE, 0xE000);
const ITEM_END: Tag = Tag(0xFFFE, 0xE00D);
const SEQUENCE_END: Tag = Tag(0xFFFE, 0xE0DD);
const PIXEL_DATA: Tag = Tag(0x7FE0, 0x0010);
const FLOAT_PIXEL_DATA: Tag = Tag(0x7FE0, 0x0008);
const DOUBLE_PIXEL_DATA: Tag = Tag(0x7FE0, 0x0009);
const UNDEFINED: u32 = u32::MAX;

/// Explicit VRs with a 16-bit length (PS3.5 Table 7.1-2); dicom-rs reads every other
/// (including unknown) VR with the reserved field and a 32-bit length.
const SHORT_LENGTH_VRS: [&[u8; 2]; 21] = [
    b"AE", b"AS", b"AT", b"CS", b"DA", b"DS", b"DT", b"FL", b"FD", b"IS", b"LO", b"LT", b"PN",
    b"SH", b"SL", b"SS", b"ST", b"TM", b"UI", b"UL", b"US",
];

/// An element header.
struct Header {
    tag: Tag,
    /// `UNDEFINED` for an undefined length.
    len: u32,
    /// Header size in bytes (8 or 12).
    size: usize,
    /// Whether a defined-length value is a sequence of items.
    sequence: bool,
    /// The size of one value of a binary VR (2 for US, 4 for UL, 8 for FD, ...), 1 for the
    /// others: dicom-rs reads `len / unit` values and counts `len` bytes, so a length that is
    /// not a multiple leaves the stream behind its count and the next header is read from
    /// inside this value (any length at all, reserved before it is read).
    unit: u32,
}

/// Size of one value of a VR read as numbers (PS3.5 Table 6.2-1), 1 for the others.
fn vr_unit(vr: [u8; 2]) -> u32 {
    match &vr {
        b"US" | b"SS" | b"OW" => 2,
        b"UL" | b"SL" | b"FL" | b"OF" | b"OL" | b"AT" => 4,
        b"FD" | b"OD" | b"SV" | b"UV" | b"OV" => 8,
        _ => 1,
    }
}

struct Walker<'a> {
    bytes: &'a [u8],
    enc: Encoding,
}

/// Walks the data set in `bytes` (everything after the file meta group).
pub(crate) fn walk_dataset(bytes: &[u8], enc: Encoding) -> Result<Walked> {
    let w = Walker { bytes, enc };
    let mut pixel = None;
    let end = w.walk_items(0, Region::TopLevel, 0, &mut pixel)?;
    Ok(Walked {
        attributes_end: pixel
            .as_ref()
            .map_or(end, |p: &PixelElement| p.header_start),
        pixel,
    })
}

/// The elements of the file meta group: `(tag, value range)`.
pub(crate) type MetaElements = Vec<(Tag, Range<usize>)>;

/// Walks the file meta group (explicit VR little endian, group 0002) starting at `bytes[0]`;
/// returns the end of the group and its elements.
pub(crate) fn walk_meta(bytes: &[u8]) -> Result<(usize, MetaElements)> {
    let w = Walker {
        bytes,
        enc: Encoding::EXPLICIT_LE,
    };
    let mut p = 0;
    let mut elements = Vec::new();
    while p + 4 <= bytes.len() && w.u16(p) == 0x0002 {
        let h = w.header(p, 0)?;
        if h.len == UNDEFINED {
            return Err(err(p, "a file meta element has an undefined length"));
        }
        let start = p + h.size;
        let end = w.fits(p, start, h.len, bytes.len(), h.tag)?;
        elements.push((h.tag, start..end));
        p = end;
    }
    Ok((p, elements))
}

fn err(offset: usize, reason: impl Into<String>) -> ScanError {
    ScanError {
        offset,
        reason: reason.into(),
    }
}

/// What holds a run of elements.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Region {
    /// The data set itself: ends with the bytes.
    TopLevel,
    /// An item of defined length: ends at this offset.
    Defined(usize),
    /// An item of undefined length: ends with an item delimiter.
    Undefined,
}

impl Walker<'_> {
    fn u16(&self, p: usize) -> u16 {
        let b = [self.bytes[p], self.bytes[p + 1]];
        if self.enc.big_endian {
            u16::from_be_bytes(b)
        } else {
            u16::from_le_bytes(b)
        }
    }

    fn u32(&self, p: usize) -> u32 {
        let b = [
            self.bytes[p],
            self.bytes[p + 1],
            self.bytes[p + 2],
            self.bytes[p + 3],
        ];
        if self.enc.big_endian {
            u32::from_be_bytes(b)
        } else {
            u32::from_le_bytes(b)
        }
    }

    /// Reads the header at `p` (the caller checked that 4 bytes are there).
    fn header(&self, p: usize, limit: usize) -> Result<Header> {
        let limit = if limit == 0 { self.bytes.len() } else { limit };
        if p + 8 > limit {
            return Err(err(p, "the file ends inside an element header"));
        }
        let tag = Tag(self.u16(p), self.u16(p + 2));
        if tag.0 == 0xFFFE {
            return Ok(Header {
                tag,
                len: self.u32(p + 4),
                size: 8,
                sequence: false,
                unit: 1,
            });
        }
        if !self.enc.explicit_vr {
            // dicom-rs takes an implicit VR from the standard dictionary (UN if unknown).
            let vr = StandardDataDictionary.by_tag(tag).map(|e| e.vr().relaxed());
            let unit = vr.map_or(1, |vr| vr_unit(vr.to_bytes()));
            return Ok(Header {
                tag,
                len: self.u32(p + 4),
                size: 8,
                sequence: vr == Some(VR::SQ),
                unit,
            });
        }
        let vr = [self.bytes[p + 4], self.bytes[p + 5]];
        if SHORT_LENGTH_VRS.iter().any(|v| **v == vr) {
            return Ok(Header {
                tag,
                len: u32::from(self.u16(p + 6)),
                size: 8,
                sequence: false,
                unit: vr_unit(vr),
            });
        }
        if p + 12 > limit {
            return Err(err(p, "the file ends inside an element header"));
        }
        Ok(Header {
            tag,
            len: self.u32(p + 8),
            size: 12,
            sequence: &vr == b"SQ",
            unit: vr_unit(vr),
        })
    }

    /// The end of a value of `len` bytes at `start` if it fits before `limit`.
    fn fits(&self, header: usize, start: usize, len: u32, limit: usize, tag: Tag) -> Result<usize> {
        let end = start.saturating_add(len as usize);
        if end > limit {
            return Err(err(
                header,
                format!(
                    "element ({:04X},{:04X}) claims {len} bytes but only {} remain{}",
                    tag.0,
                    tag.1,
                    limit.saturating_sub(start),
                    if limit < self.bytes.len() {
                        " in its item"
                    } else {
                        " in the file"
                    }
                ),
            ));
        }
        Ok(end)
    }

    /// Walks elements from `p` to the end of `region`; returns the offset after it.
    fn walk_items(
        &self,
        mut p: usize,
        region: Region,
        depth: usize,
        pixel: &mut Option<PixelElement>,
    ) -> Result<usize> {
        let limit = match region {
            Region::Defined(end) => end,
            _ => self.bytes.len(),
        };
        loop {
            if p >= limit {
                if region == Region::Undefined {
                    return Err(err(p, "the file ends inside an item (no item delimiter)"));
                }
                return Ok(p);
            }
            // dicom-rs ends a data set quietly when the file ends inside a tag.
            if region == Region::TopLevel && p + 4 > limit {
                return Ok(limit);
            }
            let h = self.header(p, limit)?;
            if h.tag == ITEM_END {
                match region {
                    Region::Undefined => return Ok(p + 8),
                    // dicom-rs skips a stray delimiter outside a sequence.
                    Region::TopLevel => {
                        p += 8;
                        continue;
                    }
                    Region::Defined(_) => return Ok(limit),
                }
            }
            if h.tag.0 == 0xFFFE {
                return Err(err(
                    p,
                    format!(
                        "unexpected item tag ({:04X},{:04X}) among the elements",
                        h.tag.0, h.tag.1
                    ),
                ));
            }
            let start = p + h.size;
            let is_pixel = matches!(h.tag, PIXEL_DATA | FLOAT_PIXEL_DATA | DOUBLE_PIXEL_DATA);
            if h.len == UNDEFINED {
                if depth >= MAX_DEPTH {
                    return Err(err(
                        p,
                        format!("sequences nested deeper than {MAX_DEPTH} levels"),
                    ));
                }
                if h.tag == PIXEL_DATA {
                    let (offset_table, fragments, end) = self.walk_fragments(start, limit)?;
                    if region == Region::TopLevel {
                        *pixel = Some(PixelElement {
                            tag: h.tag,
                            header_start: p,
                            value: PixelValue::Encapsulated {
                                offset_table,
                                fragments,
                            },
                        });
                        return Ok(end);
                    }
                    p = end;
                } else {
                    p = self.walk_sequence(start, None, depth + 1)?;
                }
                continue;
            }
            let end = self.fits(p, start, h.len, limit, h.tag)?;
            if is_pixel && region == Region::TopLevel {
                *pixel = Some(PixelElement {
                    tag: h.tag,
                    header_start: p,
                    value: PixelValue::Native(start..end),
                });
                return Ok(end);
            }
            if h.len % h.unit != 0 {
                return Err(err(
                    p,
                    format!(
                        "element ({:04X},{:04X}) has {} bytes, not a multiple of {} (the size of \
                         each value of its VR)",
                        h.tag.0, h.tag.1, h.len, h.unit
                    ),
                ));
            }
            if h.sequence {
                if depth >= MAX_DEPTH {
                    return Err(err(
                        p,
                        format!("sequences nested deeper than {MAX_DEPTH} levels"),
                    ));
                }
                self.walk_sequence(start, Some(end), depth + 1)?;
            }
            p = end;
        }
    }

    /// Walks the items of a sequence starting at `p`, of defined extent (`end`) or closed by a
    /// sequence delimiter.
    fn walk_sequence(&self, mut p: usize, end: Option<usize>, depth: usize) -> Result<usize> {
        let limit = end.unwrap_or(self.bytes.len());
        let mut none = None;
        loop {
            if p >= limit {
                return match end {
                    Some(_) => Ok(p),
                    None => Err(err(
                        p,
                        "the file ends inside a sequence (no sequence delimiter)",
                    )),
                };
            }
            let h = self.header(p, limit)?;
            match h.tag {
                SEQUENCE_END => {
                    return Ok(if end.is_some() { limit } else { p + 8 });
                }
                ITEM if h.len == UNDEFINED => {
                    p = self.walk_items(p + 8, Region::Undefined, depth, &mut none)?;
                }
                ITEM => {
                    let item_end = self.fits(p, p + 8, h.len, limit, h.tag)?;
                    self.walk_items(p + 8, Region::Defined(item_end), depth, &mut none)?;
                    p = item_end;
                }
                t => {
                    return Err(err(
                        p,
                        format!(
                            "expected an item in a sequence, found ({:04X},{:04X})",
                            t.0, t.1
                        ),
                    ));
                }
            }
        }
    }

    /// Walks encapsulated pixel data items from `p`: the basic offset table, the fragments
    /// and the sequence delimiter.
    fn walk_fragments(
        &self,
        mut p: usize,
        limit: usize,
    ) -> Result<(Vec<u32>, Vec<Range<usize>>, usize)> {
        let mut offset_table = None;
        let mut fragments = Vec::new();
        loop {
            if p >= limit {
                return Err(err(
                    p,
                    "the file ends inside the encapsulated pixel data (no sequence delimiter)",
                ));
            }
            let h = self.header(p, limit)?;
            match h.tag {
                SEQUENCE_END => break,
                ITEM if h.len != UNDEFINED => {
                    let end = self.fits(p, p + 8, h.len, limit, h.tag)?;
                    if offset_table.is_none() {
                        if h.len % 4 != 0 {
                            return Err(err(
                                p,
                                format!(
                                    "the basic offset table has {} bytes, not a multiple of 4",
                                    h.len
                                ),
                            ));
                        }
                        // Offsets are always little endian (encapsulation is little endian).
                        let table = self.bytes[p + 8..end]
                            .chunks_exact(4)
                            .map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]]))
                            .collect();
                        offset_table = Some(table);
                    } else {
                        fragments.push(p + 8..end);
                    }
                    p = end;
                }
                t => {
                    return Err(err(
                        p,
                        format!(
                            "encapsulated pixel data: expected a fragment item, found ({:04X},{:04X}){}",
                            t.0,
                            t.1,
                            if h.len == UNDEFINED {
                                " of undefined length"
                            } else {
                                ""
                            }
                        ),
                    ));
                }
            }
        }
        Ok((offset_table.unwrap_or_default(), fragments, p + 8))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Explicit VR little endian element bytes.
    fn el(g: u16, e: u16, vr: [u8; 2], value: &[u8]) -> Vec<u8> {
        let mut b = Vec::new();
        b.extend(g.to_le_bytes());
        b.extend(e.to_le_bytes());
        b.extend(vr);
        if SHORT_LENGTH_VRS.contains(&&vr) {
            b.extend((value.len() as u16).to_le_bytes());
        } else {
            b.extend([0, 0]);
            b.extend((value.len() as u32).to_le_bytes());
        }
        b.extend(value);
        b
    }

    fn item(tag_e: u16, len: u32) -> Vec<u8> {
        let mut b = Vec::new();
        b.extend(0xFFFEu16.to_le_bytes());
        b.extend(tag_e.to_le_bytes());
        b.extend(len.to_le_bytes());
        b
    }

    #[test]
    fn native_and_encapsulated_pixel_data_are_located() {
        let mut b = el(0x0028, 0x0010, *b"US", &2u16.to_le_bytes());
        let pd_at = b.len();
        b.extend(el(0x7FE0, 0x0010, *b"OW", &[1, 0, 2, 0, 3, 0, 4, 0]));
        let w = walk_dataset(&b, Encoding::EXPLICIT_LE).unwrap();
        assert_eq!(w.attributes_end, pd_at);
        let pixel = w.pixel.unwrap();
        assert_eq!(pixel.value, PixelValue::Native(pd_at + 12..pd_at + 20));

        let mut e = el(0x0028, 0x0010, *b"US", &2u16.to_le_bytes());
        let pd_at = e.len();
        e.extend(0x7FE0u16.to_le_bytes());
        e.extend(0x0010u16.to_le_bytes());
        e.extend(b"OB\0\0");
        e.extend(u32::MAX.to_le_bytes());
        e.extend(item(0xE000, 4));
        e.extend(0u32.to_le_bytes());
        let f0 = e.len() + 8;
        e.extend(item(0xE000, 6));
        e.extend([9; 6]);
        let f1 = e.len() + 8;
        e.extend(item(0xE000, 2));
        e.extend([7; 2]);
        e.extend(item(0xE0DD, 0));
        let w = walk_dataset(&e, Encoding::EXPLICIT_LE).unwrap();
        assert_eq!(w.attributes_end, pd_at);
        assert_eq!(
            w.pixel.unwrap().value,
            PixelValue::Encapsulated {
                offset_table: vec![0],
                fragments: vec![f0..f0 + 6, f1..f1 + 2],
            }
        );
    }

    #[test]
    fn binary_values_of_a_length_not_a_multiple_of_their_size_are_refused() {
        // dicom-rs reads 6 of the 26 bytes of this UL as values and the next header from the
        // last 2 (found by the fuzzer: a 6 kB file then claimed a 400 MB value).
        let mut b = el(0x0008, 0x0016, *b"UL", &[b'1'; 26]);
        b.extend(el(0x0010, 0x0010, *b"PN", b"AB"));
        let e = walk_dataset(&b, Encoding::EXPLICIT_LE).unwrap_err();
        assert_eq!(e.offset, 0);
        assert!(
            e.reason
                .contains("(0008,0016) has 26 bytes, not a multiple of 4"),
            "{e:?}"
        );
        // Implicit VR: the dictionary's (Rows is US).
        let mut i = Vec::new();
        i.extend(0x0028u16.to_le_bytes());
        i.extend(0x0010u16.to_le_bytes());
        i.extend(3u32.to_le_bytes());
        i.extend([0; 3]);
        let implicit = Encoding {
            explicit_vr: false,
            big_endian: false,
        };
        let e = walk_dataset(&i, implicit).unwrap_err();
        assert!(e.reason.contains("not a multiple of 2"), "{e:?}");
        // Multiples, and strings of any length, pass.
        let mut ok = el(0x0008, 0x0016, *b"UL", &[0; 8]);
        ok.extend(el(0x0010, 0x0010, *b"PN", b"ABC"));
        ok.extend(el(0x0018, 0x0050, *b"FD", &[0; 16]));
        assert!(walk_dataset(&ok, Encoding::EXPLICIT_LE).is_ok());
    }

    #[test]
    fn lengths_beyond_the_file_or_item_are_refused() {
        // A 4 GB claim in a small file.
        let mut b = el(0x0010, 0x0010, *b"PN", b"AB");
        let at = b.len();
        b.extend(0x0011u16.to_le_bytes());
        b.extend(0x1010u16.to_le_bytes());
        b.extend(b"OB\0\0");
        b.extend(0xFFFF_FFF0u32.to_le_bytes());
        b.extend([0; 16]);
        let e = walk_dataset(&b, Encoding::EXPLICIT_LE).unwrap_err();
        assert_eq!(e.offset, at);
        assert!(
            e.reason.contains("(0011,1010) claims 4294967280 bytes"),
            "{e:?}"
        );
        // A defined-length item whose element is longer than the item.
        let inner = el(0x0008, 0x0100, *b"SH", b"ABCD");
        let mut seq_value = item(0xE000, 6); // item claims 6 bytes, the element needs 12
        seq_value.extend(&inner);
        let mut s = el(0x0008, 0x1140, *b"SQ", &seq_value);
        s.extend(el(0x0010, 0x0010, *b"PN", b"AB"));
        let e = walk_dataset(&s, Encoding::EXPLICIT_LE).unwrap_err();
        assert!(
            e.reason.contains("in its item") || e.reason.contains("header"),
            "{e:?}"
        );
        // Truncated pixel data.
        let mut t = el(0x7FE0, 0x0010, *b"OW", &[0; 8]);
        t.truncate(t.len() - 2);
        let e = walk_dataset(&t, Encoding::EXPLICIT_LE).unwrap_err();
        assert!(
            e.reason.contains("claims 8 bytes but only 6 remain"),
            "{e:?}"
        );
    }

    #[test]
    fn deep_nesting_is_refused_and_implicit_sequences_are_walked() {
        // 40 nested undefined-length sequences.
        let mut b = Vec::new();
        for _ in 0..40 {
            b.extend(0x0008u16.to_le_bytes());
            b.extend(0x1140u16.to_le_bytes());
            b.extend(b"SQ\0\0");
            b.extend(u32::MAX.to_le_bytes());
            b.extend(item(0xE000, u32::MAX));
        }
        let e = walk_dataset(&b, Encoding::EXPLICIT_LE).unwrap_err();
        assert!(e.reason.contains("nested deeper"), "{e:?}");
        // Implicit VR: (0008,1140) is SQ in the dictionary, so its items are walked and a
        // lying length inside is found.
        let mut inner = Vec::new();
        inner.extend(0x0008u16.to_le_bytes());
        inner.extend(0x1150u16.to_le_bytes());
        inner.extend(1000u32.to_le_bytes());
        inner.extend(b"1.2");
        let mut seq = item(0xE000, inner.len() as u32);
        seq.extend(&inner);
        let mut i = Vec::new();
        i.extend(0x0008u16.to_le_bytes());
        i.extend(0x1140u16.to_le_bytes());
        i.extend((seq.len() as u32).to_le_bytes());
        i.extend(&seq);
        let implicit = Encoding {
            explicit_vr: false,
            big_endian: false,
        };
        let e = walk_dataset(&i, implicit).unwrap_err();
        assert!(e.reason.contains("(0008,1150) claims 1000"), "{e:?}");
    }

    #[test]
    fn meta_group_ends_at_the_first_other_group() {
        let mut b = el(0x0002, 0x0010, *b"UI", b"1.2.840.10008.1.2\0");
        let meta_end = b.len();
        b.extend(el(0x0008, 0x0060, *b"CS", b"CT"));
        let (end, els) = walk_meta(&b).unwrap();
        assert_eq!(end, meta_end);
        assert_eq!(els.len(), 1);
        assert_eq!(&b[els[0].1.clone()], b"1.2.840.10008.1.2\0");
    }
}
