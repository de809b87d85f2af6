//! VTK XML unstructured grids, `.vtu` (VTK file formats document, "XML File Formats").
//!
//! Read: `DataArray` formats `ascii`, `binary` (inline base64) and `appended` (raw bytes or
//! base64 after the `_` of `<AppendedData>`), without compression or with
//! `vtkZLibDataCompressor` blocks; `header_type` UInt32 or UInt64; either byte order.
//! Binary blocks are `[header][data]`: uncompressed `header = nbytes`; compressed
//! `header = [nblocks, block_size, last_block_size, compressed_size * nblocks]`. VTK encodes
//! a compressed header and its data as separately padded base64 runs, so base64 text is
//! decoded in runs split at padding (which also reads one continuous run).
//!
//! The XML part is parsed with `quick-xml` only up to `<AppendedData>` (raw appended bytes are
//! not XML). One `Piece` is read; polyhedron face streams and CellData are ignored.
//!
//! Write: [`write_vtu`], appended raw little-endian, UInt64 headers, no compression (VTK's and
//! ParaView's default layout).

use std::io::{Read, Write};
use std::path::Path;

use base64::Engine;
use quick_xml::events::Event;
use volume_core::tet::TetMesh;

use super::text::Scalar;
use super::{CellKind, LoadedMesh, MeshError, RawArray, RawMesh, read_file};

/// Reads a `.vtu` mesh.
pub fn read(path: &Path) -> Result<LoadedMesh, MeshError> {
    read_raw(path)?.into_tet_mesh(path)
}

/// Parses a `.vtu` file without splitting cells.
pub fn read_raw(path: &Path) -> Result<RawMesh, MeshError> {
    let data = read_file(path)?;
    parse(path, &data)
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Section {
    Points,
    Cells,
    PointData,
    Other,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Format {
    Ascii,
    Binary,
    Appended,
}

struct ArraySpec<'a> {
    section: Section,
    name: String,
    ty: Option<Scalar>,
    type_name: String,
    components: usize,
    format: Format,
    offset: Option<usize>,
    /// Direct text content (ascii or base64), possibly several runs.
    text: Vec<&'a [u8]>,
    /// Byte offset of the `<DataArray` tag (for errors).
    pos: usize,
}

struct Ctx<'a> {
    path: &'a Path,
    data: &'a [u8],
    big_endian: bool,
    header64: bool,
    zlib: bool,
    /// Start of the appended data (after `_`) and whether it is base64.
    appended: Option<(usize, bool)>,
    /// Sorted offsets of all appended arrays (an encoded array ends at the next one).
    appended_offsets: Vec<usize>,
}

fn line_of(data: &[u8], pos: usize) -> usize {
    super::text::newlines(&data[..pos.min(data.len())]) + 1
}

fn attr_str(value: &[u8]) -> String {
    String::from_utf8_lossy(value).into_owned()
}

/// Parses `.vtu` bytes (`path` only names the source in errors).
pub fn parse(path: &Path, data: &[u8]) -> Result<RawMesh, MeshError> {
    let perr = |pos: usize, reason: String| MeshError::Parse {
        path: path.to_path_buf(),
        line: line_of(data, pos),
        offset: pos as u64,
        reason,
    };
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
        zlib: false,
        appended,
        appended_offsets: Vec::new(),
    };
    let mut section = Section::Other;
    let mut pieces = 0usize;
    let mut n_points: Option<usize> = None;
    let mut n_cells: Option<usize> = None;
    let mut saw_vtkfile = false;
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
                let get = |k: &[u8]| {
                    attrs
                        .iter()
                        .find(|(key, _)| key == k)
                        .map(|(_, v)| v.clone())
                };
                match name {
                    b"VTKFile" => {
                        saw_vtkfile = true;
                        let ty = get(b"type").unwrap_or_default();
                        if ty != "UnstructuredGrid" {
                            return Err(MeshError::Unsupported {
                                path: path.to_path_buf(),
                                what: format!(
                                    "VTKFile type {ty:?} (only UnstructuredGrid is a tet mesh)"
                                ),
                            });
                        }
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
                        match get(b"compressor").as_deref() {
                            None | Some("") => ctx.zlib = false,
                            Some("vtkZLibDataCompressor") => ctx.zlib = true,
                            Some(o) => {
                                return Err(MeshError::Unsupported {
                                    path: path.to_path_buf(),
                                    what: format!(
                                        "compressor {o} (only vtkZLibDataCompressor is read)"
                                    ),
                                });
                            }
                        }
                    }
                    b"Piece" => {
                        pieces += 1;
                        if pieces > 1 {
                            return Err(MeshError::Unsupported {
                                path: path.to_path_buf(),
                                what: "more than one Piece".to_owned(),
                            });
                        }
                        let count = |k: &[u8], what: &str| -> Result<usize, MeshError> {
                            let v =
                                get(k).ok_or_else(|| perr(pos, format!("Piece without {what}")))?;
                            v.trim()
                                .parse()
                                .map_err(|_| perr(pos, format!("{what}: cannot parse {v:?}")))
                        };
                        n_points = Some(count(b"NumberOfPoints", "NumberOfPoints")?);
                        n_cells = Some(count(b"NumberOfCells", "NumberOfCells")?);
                    }
                    b"Points" if !empty => section = Section::Points,
                    b"Cells" if !empty => section = Section::Cells,
                    b"PointData" if !empty => section = Section::PointData,
                    b"CellData" | b"FieldData" if !empty => section = Section::Other,
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
                    }
                    _ => {}
                }
            }
            Event::End(ref e) => {
                if in_array > 0 {
                    in_array -= 1;
                    continue;
                }
                match e.local_name().as_ref() {
                    b"Points" | b"Cells" | b"PointData" | b"CellData" | b"FieldData" => {
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
    let (Some(n_points), Some(n_cells)) = (n_points, n_cells) else {
        return Err(perr(0, "no <Piece> element".into()));
    };
    ctx.appended_offsets.sort_unstable();
    ctx.appended_offsets.dedup();

    // Headers lie: bound counts by what a file of this size can describe, unless compressed.
    if !ctx.zlib && (n_points as u64).saturating_mul(3) > data.len() as u64 {
        return Err(MeshError::TooShort {
            path: path.to_path_buf(),
            what: format!("NumberOfPoints ({n_points})"),
            offset: 0,
            needed: (n_points as u64).saturating_mul(3),
            available: data.len() as u64,
        });
    }
    let mut mesh = RawMesh::new();
    let pts = arrays
        .iter()
        .find(|a| a.section == Section::Points)
        .ok_or_else(|| perr(0, "no <Points> DataArray".into()))?;
    if pts.components != 3 {
        return Err(perr(
            pts.pos,
            format!("Points have {} components, expected 3", pts.components),
        ));
    }
    let p = ctx.floats(pts, n_points.saturating_mul(3))?;
    mesh.points = p.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();

    let cell_array = |name: &str| -> Result<&ArraySpec<'_>, MeshError> {
        arrays
            .iter()
            .find(|a| a.section == Section::Cells && a.name == name)
            .ok_or_else(|| perr(0, format!("no <Cells> DataArray named {name:?}")))
    };
    if n_cells > 0 {
        let offsets = ctx.ints(cell_array("offsets")?, n_cells)?;
        let types = ctx.ints(cell_array("types")?, n_cells)?;
        let conn_len = *offsets.last().unwrap_or(&0);
        let conn_spec = cell_array("connectivity")?;
        let conn_len = usize::try_from(conn_len)
            .map_err(|_| perr(conn_spec.pos, format!("last offset {conn_len} is negative")))?;
        let conn = ctx.ints(conn_spec, conn_len)?;
        let mut prev = 0i64;
        mesh.offsets = Vec::with_capacity(n_cells + 1);
        mesh.offsets.push(0);
        mesh.kinds = Vec::with_capacity(n_cells);
        for (cell, (&o, &t)) in offsets.iter().zip(&types).enumerate() {
            if o < prev {
                return Err(MeshError::BadCell {
                    path: path.to_path_buf(),
                    cell,
                    reason: format!("offset {o} is smaller than the previous {prev}"),
                });
            }
            prev = o;
            mesh.offsets.push(o as usize);
            let code = u32::try_from(t).map_err(|_| MeshError::BadCell {
                path: path.to_path_buf(),
                cell,
                reason: format!("bad cell type {t}"),
            })?;
            mesh.kinds.push(CellKind::from_vtk(code));
        }
        mesh.connectivity = Vec::with_capacity(conn.len());
        for (cell, w) in mesh.offsets.windows(2).enumerate() {
            for &id in &conn[w[0]..w[1]] {
                let id = u64::try_from(id).map_err(|_| MeshError::BadCell {
                    path: path.to_path_buf(),
                    cell,
                    reason: format!("negative point index {id}"),
                })?;
                mesh.connectivity.push(id);
            }
        }
    }
    for a in arrays.iter().filter(|a| a.section == Section::PointData) {
        if a.ty.is_none() {
            // String and bit arrays are not fields.
            continue;
        }
        let values = ctx.floats(a, n_points.saturating_mul(a.components))?;
        mesh.arrays.push(RawArray {
            name: a.name.clone(),
            components: a.components,
            values,
        });
    }
    Ok(mesh)
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
    fn bad(&self, a: &ArraySpec<'_>, reason: String) -> MeshError {
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

    fn scalar(&self, a: &ArraySpec<'_>) -> Result<Scalar, MeshError> {
        a.ty.ok_or_else(|| MeshError::Unsupported {
            path: self.path.to_path_buf(),
            what: format!("DataArray {:?} of type {:?}", a.name, a.type_name),
        })
    }

    fn floats(&self, a: &ArraySpec<'_>, count: usize) -> Result<Vec<f64>, MeshError> {
        let ty = self.scalar(a)?;
        if a.format == Format::Ascii {
            return self.ascii(a, count, |t| t.parse::<f64>().ok());
        }
        let bytes = self.bytes(a, count, ty)?;
        Ok(ty.decode_f64(&bytes, self.big_endian))
    }

    fn ints(&self, a: &ArraySpec<'_>, count: usize) -> Result<Vec<i64>, MeshError> {
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

    fn ascii<T>(
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

    /// The decoded bytes of a binary or appended array, exactly `count` values of `ty`.
    fn bytes(&self, a: &ArraySpec<'_>, count: usize, ty: Scalar) -> Result<Vec<u8>, MeshError> {
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
            Format::Ascii => unreachable!("ascii handled by the caller"),
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
        if !self.zlib {
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
        // The header's sizes are claims: nothing is reserved from them. `out` grows only as
        // zlib produces bytes, each block capped at its declared size (+1 to detect surplus),
        // and a block claiming more than its compressed bytes can inflate to is refused first.
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
            if want > max_inflated(csize) {
                return Err(self.bad(
                    a,
                    format!(
                        "zlib block {b} claims {want} bytes from {csize} compressed bytes, more than zlib can inflate to ({})",
                        max_inflated(csize)
                    ),
                ));
            }
            let before = out.len();
            let mut dec = flate2::read::ZlibDecoder::new(&block[pos..end as usize]).take(want + 1);
            dec.read_to_end(&mut out)
                .map_err(|e| self.bad(a, format!("zlib block {b}: {e}")))?;
            if (out.len() - before) as u64 != want {
                return Err(self.bad(
                    a,
                    format!(
                        "zlib block {b} inflates to {} bytes, expected {want}",
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

fn xml_escape(s: &str) -> String {
    quick_xml::escape::escape(s).into_owned()
}

/// Writes `mesh` as a `.vtu` (appended raw, little-endian, UInt64 headers, Float32 points and
/// fields, Int64 connectivity/offsets, UInt8 types), through [`crate::output::OutputFile`]
/// (never over an input; an existing file only with [`crate::output::Replace::Allow`]; a failed write leaves
/// no file).
pub fn write_vtu(
    path: &Path,
    mesh: &TetMesh,
    replace: crate::output::Replace,
) -> Result<(), MeshError> {
    crate::output::write_output_with(path, replace, |w| {
        write_vtu_to(w, mesh).map_err(|e| MeshError::io(path, e))
    })
}

fn write_vtu_to(w: &mut impl Write, mesh: &TetMesh) -> std::io::Result<()> {
    let np = mesh.points.len();
    let nc = mesh.tets.len();
    // (xml line, payload size) in appended order.
    let mut offset = 0u64;
    let mut next = |bytes: usize| {
        let o = offset;
        offset += 8 + bytes as u64;
        o
    };
    writeln!(w, "<?xml version=\"1.0\"?>")?;
    writeln!(
        w,
        "<VTKFile type=\"UnstructuredGrid\" version=\"1.0\" byte_order=\"LittleEndian\" header_type=\"UInt64\">"
    )?;
    writeln!(w, "  <UnstructuredGrid>")?;
    writeln!(
        w,
        "    <Piece NumberOfPoints=\"{np}\" NumberOfCells=\"{nc}\">"
    )?;
    if let Some(first) = mesh.fields.first() {
        writeln!(
            w,
            "      <PointData Scalars=\"{}\">",
            xml_escape(&first.name)
        )?;
        for f in &mesh.fields {
            writeln!(
                w,
                "        <DataArray type=\"Float32\" Name=\"{}\" format=\"appended\" offset=\"{}\"/>",
                xml_escape(&f.name),
                next(np * 4)
            )?;
        }
        writeln!(w, "      </PointData>")?;
    }
    writeln!(w, "      <Points>")?;
    writeln!(
        w,
        "        <DataArray type=\"Float32\" NumberOfComponents=\"3\" format=\"appended\" offset=\"{}\"/>",
        next(np * 12)
    )?;
    writeln!(w, "      </Points>")?;
    writeln!(w, "      <Cells>")?;
    writeln!(
        w,
        "        <DataArray type=\"Int64\" Name=\"connectivity\" format=\"appended\" offset=\"{}\"/>",
        next(nc * 32)
    )?;
    writeln!(
        w,
        "        <DataArray type=\"Int64\" Name=\"offsets\" format=\"appended\" offset=\"{}\"/>",
        next(nc * 8)
    )?;
    writeln!(
        w,
        "        <DataArray type=\"UInt8\" Name=\"types\" format=\"appended\" offset=\"{}\"/>",
        next(nc)
    )?;
    writeln!(w, "      </Cells>")?;
    writeln!(w, "    </Piece>")?;
    writeln!(w, "  </UnstructuredGrid>")?;
    writeln!(w, "  <AppendedData encoding=\"raw\">")?;
    w.write_all(b"   _")?;
    for f in &mesh.fields {
        w.write_all(&((np * 4) as u64).to_le_bytes())?;
        for v in &f.values {
            w.write_all(&v.to_le_bytes())?;
        }
    }
    w.write_all(&((np * 12) as u64).to_le_bytes())?;
    for p in &mesh.points {
        for c in p {
            w.write_all(&c.to_le_bytes())?;
        }
    }
    w.write_all(&((nc * 32) as u64).to_le_bytes())?;
    for t in &mesh.tets {
        for &i in t {
            w.write_all(&i64::from(i).to_le_bytes())?;
        }
    }
    w.write_all(&((nc * 8) as u64).to_le_bytes())?;
    for i in 0..nc {
        w.write_all(&(4 * (i as i64 + 1)).to_le_bytes())?;
    }
    w.write_all(&(nc as u64).to_le_bytes())?;
    for _ in 0..nc {
        w.write_all(&[10u8])?;
    }
    writeln!(w)?;
    writeln!(w, "  </AppendedData>")?;
    writeln!(w, "</VTKFile>")?;
    Ok(())
}
