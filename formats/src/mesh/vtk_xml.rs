//! VTK XML files: the document walk and the `DataArray` decoding shared by the `.vtu` mesh
//! reader ([`super::vtu`]) and the `.vti` image reader ([`crate::vtk_image`]) (VTK file
//! formats document, "XML File Formats").
//!
//! - [`parse_document`] walks the XML once and keeps every element's attributes
//!   ([`Element`]) and every `DataArray` ([`ArraySpec`], with the section it sits in and its
//!   inline text), without decoding any data yet. The `<VTKFile>` attributes set the
//!   decoding context ([`Ctx`]): byte order, `header_type` UInt32 or UInt64, compressor.
//! - [`Ctx::floats`], [`Ctx::ints`] and [`Ctx::bytes`] decode one array of an expected length:
//!   formats `ascii`, `binary` (inline base64) and `appended` (raw bytes or base64 after the
//!   `_` of `<AppendedData>`), without compression or with `vtkZLibDataCompressor` or
//!   `vtkLZ4DataCompressor` blocks.
//!
//! Binary blocks are `[header][data]`: uncompressed `header = nbytes`; compressed
//! `header = [nblocks, block_size, last_block_size, compressed_size * nblocks]`. VTK encodes
//! a compressed header and its data as separately padded base64 runs, so base64 text is
//! decoded in runs split at padding (which also reads one continuous run).
//!
//! The XML part is parsed with `quick-xml` only up to `<AppendedData>` (raw appended bytes are
//! not XML). Headers lie: an array's declared byte count is compared with the bytes present
//! before anything is copied, and a compressed block that claims more than its compressed
//! bytes can inflate to is refused before it is decoded.

use std::io::Read;
use std::path::Path;

use base64::Engine;
use quick_xml::events::Event;

use super::MeshError;
use super::text::Scalar;

/// The element a `DataArray` sits in.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Section {
    Points,
    Cells,
    PointData,
    CellData,
    Other,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Format {
    Ascii,
    Binary,
    Appended,
}

/// The compressor of the `<VTKFile>`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Compressor {
    None,
    Zlib,
    Lz4,
}

/// A `DataArray` as declared (its data is decoded on demand by [`Ctx`]).
pub(crate) struct ArraySpec<'a> {
    pub section: Section,
    pub name: String,
    pub ty: Option<Scalar>,
    pub type_name: String,
    pub components: usize,
    pub format: Format,
    pub offset: Option<usize>,
    /// Direct text content (ascii or base64), possibly several runs.
    pub text: Vec<&'a [u8]>,
    /// Byte offset of the `<DataArray` tag (for errors).
    pub pos: usize,
}

/// Any other element: its local name, attributes and where its tag starts.
pub(crate) struct Element {
    pub name: Vec<u8>,
    pub attrs: Vec<(Vec<u8>, String)>,
    pub pos: usize,
}

impl Element {
    pub fn get(&self, key: &[u8]) -> Option<&str> {
        self.attrs
            .iter()
            .find(|(k, _)| k == key)
            .map(|(_, v)| v.as_str())
    }
}

/// How to decode the arrays of one file.
pub(crate) struct Ctx<'a> {
    pub path: &'a Path,
    pub data: &'a [u8],
    pub big_endian: bool,
    pub header64: bool,
    pub compressor: Compressor,
    /// Start of the appended data (after `_`) and whether it is base64.
    appended: Option<(usize, bool)>,
    /// Sorted offsets of all appended arrays (an encoded array ends at the next one).
    appended_offsets: Vec<usize>,
}

/// A walked VTK XML file.
pub(crate) struct Document<'a> {
    pub ctx: Ctx<'a>,
    /// Every element outside `DataArray`s (`VTKFile` included), in file order.
    pub elements: Vec<Element>,
    pub arrays: Vec<ArraySpec<'a>>,
}

impl Document<'_> {
    /// The elements named `name`.
    pub fn elements_named<'s>(&'s self, name: &'s [u8]) -> impl Iterator<Item = &'s Element> {
        self.elements.iter().filter(move |e| e.name == name)
    }
}

pub(crate) fn line_of(data: &[u8], pos: usize) -> usize {
    super::text::newlines(&data[..pos.min(data.len())]) + 1
}

fn attr_str(value: &[u8]) -> String {
    String::from_utf8_lossy(value).into_owned()
}

/// A parse error at byte `pos` of `data`.
pub(crate) fn parse_error(path: &Path, data: &[u8], pos: usize, reason: String) -> MeshError {
    MeshError::Parse {
        path: path.to_path_buf(),
        line: line_of(data, pos),
        offset: pos as u64,
        reason,
    }
}

/// Walks a VTK XML file (`path` only names it in errors). `check_type` is called with the
/// `<VTKFile type="...">` as soon as it is read, so a file of another kind is refused by
/// its type before anything else.
pub(crate) fn parse_document<'a>(
    path: &'a Path,
    data: &'a [u8],
    check_type: impl Fn(&str) -> Result<(), MeshError>,
) -> Result<Document<'a>, MeshError> {
    let perr = |pos: usize, reason: String| parse_error(path, data, pos, reason);
    // Split off the appended data: it may be raw bytes, which are not XML.
    let mut xml_end = data.len();
    let mut appended = None;
    if let Some(tag) = find(data, b"<AppendedData", 0) {
        xml_end = tag;
        let close = find(data, b">", tag)
            .ok_or_else(|| perr(tag, "unterminated <AppendedData> tag".into()))?;
        let head = &data[tag..close];
        let base64 = if find(head, b"encoding=\"raw\"", 0).is_some()
            || find(head, b"encoding='raw'", 0).is_some()
        {
            false
        } else if find(head, b"base64", 0).is_some() {
            true
        } else {
            return Err(perr(
                tag,
                "<AppendedData> without encoding=\"raw\" or \"base64\"".into(),
            ));
        };
        let underscore = find(data, b"_", close)
            .ok_or_else(|| perr(close, "appended data does not start with `_`".into()))?;
        if !data[close + 1..underscore]
            .iter()
            .all(u8::is_ascii_whitespace)
        {
            return Err(perr(close, "appended data does not start with `_`".into()));
        }
        appended = Some((underscore + 1, base64));
    }
    let xml = &data[..xml_end];
    let mut reader = quick_xml::Reader::from_reader(xml);
    reader.config_mut().check_end_names = true;
    let mut ctx = Ctx {
        path,
        data,
        big_endian: false,
        header64: false,
        compressor: Compressor::None,
        appended,
        appended_offsets: Vec::new(),
    };
    let mut section = Section::Other;
    let mut saw_vtkfile = false;
    let mut elements = Vec::new();
    let mut arrays: Vec<ArraySpec<'_>> = Vec::new();
    // Depth inside the current DataArray (text is taken only at depth 1).
    let mut in_array = 0usize;
    loop {
        let pos = reader.buffer_position() as usize;
        let ev = match reader.read_event() {
            Ok(ev) => ev,
            Err(e) => {
                let at = reader.error_position() as usize;
                return Err(perr(at, format!("XML error: {e}")));
            }
        };
        match ev {
            Event::Eof => break,
            Event::Start(ref e) | Event::Empty(ref e) => {
                let empty = matches!(ev, Event::Empty(_));
                let name = e.local_name();
                let name = name.as_ref();
                if in_array > 0 {
                    if !empty {
                        in_array += 1;
                    }
                    continue;
                }
                let mut attrs = Vec::new();
                for a in e.attributes() {
                    let a = a.map_err(|err| perr(pos, format!("bad attribute: {err}")))?;
                    let value = match a.normalized_value(quick_xml::XmlVersion::Implicit1_0) {
                        Ok(v) => v.into_owned(),
                        Err(_) => attr_str(&a.value),
                    };
                    attrs.push((a.key.as_ref().to_vec(), value));
                }
                let element = Element {
                    name: name.to_vec(),
                    attrs,
                    pos,
                };
                let get = |k: &[u8]| element.get(k).map(str::to_owned);
                match name {
                    b"VTKFile" => {
                        let ty = get(b"type").unwrap_or_default();
                        check_type(&ty)?;
                        saw_vtkfile = true;
                        match get(b"byte_order").as_deref() {
                            None | Some("LittleEndian") => ctx.big_endian = false,
                            Some("BigEndian") => ctx.big_endian = true,
                            Some(o) => return Err(perr(pos, format!("unknown byte_order {o:?}"))),
                        }
                        match get(b"header_type").as_deref() {
                            None | Some("UInt32") => ctx.header64 = false,
                            Some("UInt64") => ctx.header64 = true,
                            Some(o) => return Err(perr(pos, format!("unknown header_type {o:?}"))),
                        }
                        ctx.compressor = match get(b"compressor").as_deref() {
                            None | Some("") => Compressor::None,
                            Some("vtkZLibDataCompressor") => Compressor::Zlib,
                            Some("vtkLZ4DataCompressor") => Compressor::Lz4,
                            Some(o) => {
                                return Err(MeshError::Unsupported {
                                    path: path.to_path_buf(),
                                    what: format!(
                                        "compressor {o} (vtkZLibDataCompressor and \
                                         vtkLZ4DataCompressor are read)"
                                    ),
                                });
                            }
                        };
                    }
                    b"Points" if !empty => section = Section::Points,
                    b"Cells" if !empty => section = Section::Cells,
                    b"PointData" if !empty => section = Section::PointData,
                    b"CellData" if !empty => section = Section::CellData,
                    b"FieldData" | b"Coordinates" if !empty => section = Section::Other,
                    b"DataArray" => {
                        let type_name = get(b"type").unwrap_or_default();
                        let format = match get(b"format").as_deref() {
                            Some("ascii") => Format::Ascii,
                            Some("binary") => Format::Binary,
                            Some("appended") => Format::Appended,
                            f => {
                                return Err(perr(
                                    pos,
                                    format!(
                                        "DataArray format {f:?} is not ascii, binary or appended"
                                    ),
                                ));
                            }
                        };
                        let components = match get(b"NumberOfComponents") {
                            None => 1,
                            Some(c) => c
                                .trim()
                                .parse::<usize>()
                                .ok()
                                .filter(|c| (1..=64).contains(c))
                                .ok_or_else(|| {
                                    perr(pos, format!("NumberOfComponents {c:?} is not 1..64"))
                                })?,
                        };
                        let offset =
                            match get(b"offset") {
                                None => None,
                                Some(o) => Some(o.trim().parse::<usize>().map_err(|_| {
                                    perr(pos, format!("offset {o:?} is not a number"))
                                })?),
                            };
                        if format == Format::Appended {
                            let o = offset.ok_or_else(|| {
                                perr(pos, "appended DataArray without offset".into())
                            })?;
                            ctx.appended_offsets.push(o);
                        }
                        arrays.push(ArraySpec {
                            section,
                            name: get(b"Name").unwrap_or_default(),
                            ty: Scalar::from_xml(&type_name),
                            type_name,
                            components,
                            format,
                            offset,
                            text: Vec::new(),
                            pos,
                        });
                        if !empty {
                            in_array = 1;
                        }
                        continue;
                    }
                    _ => {}
                }
                elements.push(element);
            }
            Event::End(ref e) => {
                if in_array > 0 {
                    in_array -= 1;
                    continue;
                }
                match e.local_name().as_ref() {
                    b"Points" | b"Cells" | b"PointData" | b"CellData" | b"FieldData"
                    | b"Coordinates" => {
                        section = Section::Other;
                    }
                    _ => {}
                }
            }
            Event::Text(t) if in_array == 1 => {
                if let Some(a) = arrays.last_mut() {
                    let bytes: &[u8] = match t.into_inner() {
                        std::borrow::Cow::Borrowed(b) => b,
                        std::borrow::Cow::Owned(_) => &[],
                    };
                    a.text.push(bytes);
                }
            }
            Event::CData(t) if in_array == 1 => {
                if let Some(a) = arrays.last_mut()
                    && let std::borrow::Cow::Borrowed(b) = t.into_inner()
                {
                    a.text.push(b);
                }
            }
            _ => {}
        }
    }
    if !saw_vtkfile {
        return Err(perr(0, "no <VTKFile> element".into()));
    }
    ctx.appended_offsets.sort_unstable();
    ctx.appended_offsets.dedup();
    Ok(Document {
        ctx,
        elements,
        arrays,
    })
}

fn find(hay: &[u8], needle: &[u8], from: usize) -> Option<usize> {
    if from >= hay.len() {
        return None;
    }
    hay[from..]
        .windows(needle.len())
        .position(|w| w == needle)
        .map(|i| i + from)
}

/// Decodes base64 text that may be several separately padded runs, ignoring whitespace.
fn decode_base64_runs(text: &[u8]) -> Result<Vec<u8>, String> {
    let clean: Vec<u8> = text
        .iter()
        .copied()
        .filter(|b| !b.is_ascii_whitespace())
        .collect();
    let mut out = Vec::with_capacity(clean.len() / 4 * 3);
    let mut start = 0;
    let eng = base64::engine::general_purpose::STANDARD;
    let mut i = 0;
    while i < clean.len() {
        let end = (i + 4).min(clean.len());
        let group = &clean[i..end];
        i = end;
        if group.contains(&b'=') || i == clean.len() {
            eng.decode_vec(&clean[start..i], &mut out)
                .map_err(|e| format!("base64 at character {start}: {e}"))?;
            start = i;
        }
    }
    Ok(out)
}

impl Ctx<'_> {
    /// A [`MeshError::Parse`] at byte `pos`.
    pub fn perr(&self, pos: usize, reason: String) -> MeshError {
        parse_error(self.path, self.data, pos, reason)
    }

    pub fn bad(&self, a: &ArraySpec<'_>, reason: String) -> MeshError {
        MeshError::BadArray {
            path: self.path.to_path_buf(),
            name: if a.name.is_empty() {
                format!("(unnamed, line {})", line_of(self.data, a.pos))
            } else {
                a.name.clone()
            },
            reason,
        }
    }

    pub fn scalar(&self, a: &ArraySpec<'_>) -> Result<Scalar, MeshError> {
        a.ty.ok_or_else(|| MeshError::Unsupported {
            path: self.path.to_path_buf(),
            what: format!("DataArray {:?} of type {:?}", a.name, a.type_name),
        })
    }

    /// `count` values of `a` as `f64`.
    pub fn floats(&self, a: &ArraySpec<'_>, count: usize) -> Result<Vec<f64>, MeshError> {
        let ty = self.scalar(a)?;
        if a.format == Format::Ascii {
            return self.ascii(a, count, |t| t.parse::<f64>().ok());
        }
        let bytes = self.bytes(a, count, ty)?;
        Ok(ty.decode_f64(&bytes, self.big_endian))
    }

    /// `count` values of the integer array `a`.
    pub fn ints(&self, a: &ArraySpec<'_>, count: usize) -> Result<Vec<i64>, MeshError> {
        let ty = self.scalar(a)?;
        if ty.is_float() {
            return Err(self.bad(
                a,
                format!("type {} where integers are expected", a.type_name),
            ));
        }
        if a.format == Format::Ascii {
            return self.ascii(a, count, |t| t.parse::<i64>().ok());
        }
        let bytes = self.bytes(a, count, ty)?;
        Ok(ty.decode_i64(&bytes, self.big_endian))
    }

    /// Exactly `count` whitespace-separated values of an ascii array.
    pub fn ascii<T>(
        &self,
        a: &ArraySpec<'_>,
        count: usize,
        parse: impl Fn(&str) -> Option<T>,
    ) -> Result<Vec<T>, MeshError> {
        let total: usize = a.text.iter().map(|t| t.len()).sum();
        if count > total {
            return Err(self.bad(
                a,
                format!("{count} values expected but the text has only {total} bytes"),
            ));
        }
        let mut out = Vec::with_capacity(count);
        for run in &a.text {
            for tok in run.split(u8::is_ascii_whitespace).filter(|t| !t.is_empty()) {
                let s = std::str::from_utf8(tok).unwrap_or("");
                let v = parse(s).ok_or_else(|| {
                    self.bad(a, format!("value #{} {s:?} does not parse", out.len()))
                })?;
                if out.len() == count {
                    return Err(self.bad(a, format!("more than the {count} expected values")));
                }
                out.push(v);
            }
        }
        if out.len() != count {
            return Err(self.bad(a, format!("{} values, expected {count}", out.len())));
        }
        Ok(out)
    }

    fn header_word(&self, b: &[u8]) -> u64 {
        let mut w = [0u8; 8];
        let n = b.len();
        w[..n].copy_from_slice(b);
        if self.big_endian {
            w[..n].reverse();
        }
        u64::from_le_bytes(w)
    }

    /// The decoded bytes of a binary or appended array, exactly `count` values of `ty`, in
    /// the file's byte order.
    pub fn bytes(&self, a: &ArraySpec<'_>, count: usize, ty: Scalar) -> Result<Vec<u8>, MeshError> {
        let expected = (count as u64)
            .checked_mul(ty.size() as u64)
            .filter(|&n| usize::try_from(n).is_ok())
            .ok_or_else(|| {
                self.bad(
                    a,
                    format!("{count} values of {} overflow a byte count", ty.xml_name()),
                )
            })?;
        let decoded;
        let block: &[u8] = match a.format {
            Format::Binary => {
                let text: Vec<u8> = a.text.concat();
                decoded = decode_base64_runs(&text).map_err(|e| self.bad(a, e))?;
                &decoded
            }
            Format::Appended => {
                let (base, b64) = self.appended.ok_or_else(|| {
                    self.bad(a, "format=\"appended\" but no <AppendedData>".into())
                })?;
                let off = a.offset.unwrap_or(0);
                let start = base
                    .checked_add(off)
                    .filter(|&s| s <= self.data.len())
                    .ok_or_else(|| {
                        self.bad(
                            a,
                            format!("appended offset {off} is past the end of the file"),
                        )
                    })?;
                if b64 {
                    let next = self
                        .appended_offsets
                        .iter()
                        .find(|&&o| o > off)
                        .map(|&o| base.saturating_add(o));
                    let mut end = next.unwrap_or(self.data.len()).min(self.data.len());
                    if next.is_none() {
                        end = start
                            + self.data[start..]
                                .iter()
                                .position(|&c| {
                                    !(c.is_ascii_alphanumeric()
                                        || c == b'+'
                                        || c == b'/'
                                        || c == b'=')
                                })
                                .unwrap_or(self.data.len() - start);
                    }
                    decoded = decode_base64_runs(&self.data[start..end.max(start)])
                        .map_err(|e| self.bad(a, e))?;
                    &decoded
                } else {
                    &self.data[start..]
                }
            }
            Format::Ascii => {
                return Err(self.bad(a, "ascii data where binary was expected".into()));
            }
        };
        let hs = if self.header64 { 8 } else { 4 };
        let short = |what: &str, needed: u64| {
            self.bad(
                a,
                format!(
                    "{what}: needs {needed} bytes, only {} available",
                    block.len()
                ),
            )
        };
        if block.len() < hs {
            return Err(short("block header", hs as u64));
        }
        if self.compressor == Compressor::None {
            let nbytes = self.header_word(&block[..hs]);
            if nbytes != expected {
                return Err(self.bad(
                    a,
                    format!(
                        "header says {nbytes} bytes, expected {expected} ({count} values of {})",
                        ty.xml_name()
                    ),
                ));
            }
            if ((block.len() - hs) as u64) < expected {
                return Err(short("data", expected.saturating_add(hs as u64)));
            }
            return Ok(block[hs..hs + expected as usize].to_vec());
        }
        if block.len() < 3 * hs {
            return Err(short("compression header", 3 * hs as u64));
        }
        let nblocks = self.header_word(&block[..hs]);
        let block_size = self.header_word(&block[hs..2 * hs]);
        let last_size = self.header_word(&block[2 * hs..3 * hs]);
        let head_len = nblocks.saturating_add(3).saturating_mul(hs as u64);
        if head_len > block.len() as u64 {
            return Err(short(
                &format!("compression header of {nblocks} blocks"),
                head_len,
            ));
        }
        let total = if nblocks == 0 {
            0
        } else if last_size == 0 {
            nblocks.saturating_mul(block_size)
        } else {
            (nblocks - 1)
                .saturating_mul(block_size)
                .saturating_add(last_size)
        };
        if total != expected || (nblocks > 1 && last_size > block_size) {
            return Err(self.bad(a, format!("compressed blocks hold {total} bytes, expected {expected} ({count} values of {})", ty.xml_name())));
        }
        let (codec, verb, max_ratio) = match self.compressor {
            Compressor::Lz4 => ("lz4", "decodes", max_lz4_inflated as fn(u64) -> u64),
            _ => ("zlib", "inflates", max_inflated as fn(u64) -> u64),
        };
        // The header's sizes are claims: nothing is reserved from them. zlib output grows
        // only as bytes arrive, each block capped at its declared size (+1 to detect
        // surplus); an LZ4 block is allocated at its declared size only after that size was
        // checked against what its compressed bytes can decode to.
        let mut out = Vec::new();
        let mut pos = head_len as usize;
        for b in 0..nblocks as usize {
            let csize = self.header_word(&block[(3 + b) * hs..(4 + b) * hs]);
            let end = (pos as u64).saturating_add(csize);
            if end > block.len() as u64 {
                return Err(short(&format!("compressed block {b}"), end));
            }
            let want = if b + 1 == nblocks as usize && last_size != 0 {
                last_size
            } else {
                block_size
            };
            if want > max_ratio(csize) {
                return Err(self.bad(
                    a,
                    format!(
                        "{codec} block {b} claims {want} bytes from {csize} compressed bytes, more than {codec} can {} to ({})",
                        verb.trim_end_matches('s'),
                        max_ratio(csize)
                    ),
                ));
            }
            let input = &block[pos..end as usize];
            let before = out.len();
            if self.compressor == Compressor::Lz4 {
                out.resize(before + want as usize, 0);
                let n = lz4_flex::block::decompress_into(input, &mut out[before..])
                    .map_err(|e| self.bad(a, format!("lz4 block {b}: {e}")))?;
                out.truncate(before + n);
            } else {
                let mut dec = flate2::read::ZlibDecoder::new(input).take(want + 1);
                dec.read_to_end(&mut out)
                    .map_err(|e| self.bad(a, format!("zlib block {b}: {e}")))?;
            }
            if (out.len() - before) as u64 != want {
                return Err(self.bad(
                    a,
                    format!(
                        "{codec} block {b} {verb} to {} bytes, expected {want}",
                        out.len() - before
                    ),
                ));
            }
            pos = end as usize;
        }
        Ok(out)
    }
}

/// The most bytes `compressed` bytes of a zlib stream can inflate to: deflate's best ratio is
/// 1032:1 (a 258-byte match per 2 bits), plus slack for the stream header and a final
/// partial block.
fn max_inflated(compressed: u64) -> u64 {
    compressed.saturating_mul(1032).saturating_add(1024)
}

/// The most bytes `compressed` bytes of an LZ4 block can decode to: each further byte of a
/// match length adds at most 255 bytes of output (LZ4 block format), plus slack for the
/// last sequence.
fn max_lz4_inflated(compressed: u64) -> u64 {
    compressed.saturating_mul(255).saturating_add(1024)
}
