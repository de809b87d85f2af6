//! Reading NRRD data: raw (memory-mapped), gzip, bzip2, ascii and hex, attached or in one or
//! more data files, with `line skip` and `byte skip`. MetaImage data (raw, zlib, `HeaderSize`,
//! one or more data files) is read by the same plan, built from parts ([`PlanParts`]).
//!
//! The decoded data is the concatenation of the data files' contents; [`DataPlan::load`]
//! reads any byte range of it (a whole volume, or one time step). Raw data in one file is
//! viewed in place in a memory map; everything else is decoded into owned memory that grows
//! only as data actually arrives, so a header that lies about the sizes cannot make us
//! allocate more than the stream holds (plus one byte to detect surplus data).

use std::io::{BufRead, BufReader, Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};
use std::sync::{Arc, OnceLock};

use memmap2::Mmap;
use volume_core::{VoxelData, VoxelType};

use super::header::{DataFiles, Encoding, NrrdHeader, data_file_paths};
use crate::error::FormatError;
use crate::raw::{Endian, map_file, voxels_from_map, voxels_from_vec};

/// Where the decoded bytes of a NRRD live and how to decode them.
pub(crate) struct DataPlan {
    files: Vec<PathBuf>,
    /// Where the data section starts in each file before skips (the header length if attached).
    base_offset: u64,
    per_file_bytes: u64,
    encoding: Encoding,
    endian: Endian,
    voxel_type: VoxelType,
    line_skip: u64,
    byte_skip: i64,
    /// `Gzip` data may also be a zlib stream (MetaImage's `CompressedData`).
    zlib: bool,
    /// Compressed data: at most this many bytes of each file are the stream.
    compressed_bytes: Option<u64>,
    /// Raw encoding: each file's map and the offset of its data, made on first use.
    maps: Vec<OnceLock<(Arc<Mmap>, u64)>>,
    /// Bytes after the data are ignored (NIfTI) rather than refused (NRRD); a compressed
    /// stream is still read to its end when its last bytes load (its checksum).
    trailing_ok: bool,
}

/// The parts of a [`DataPlan`] for a header format other than NRRD.
pub(crate) struct PlanParts {
    pub files: Vec<PathBuf>,
    /// Where the data section starts in each file (before `byte_skip`).
    pub base_offset: u64,
    /// Decoded bytes in all files together.
    pub total_bytes: u64,
    /// `Raw` or `Gzip` (with `zlib`: gzip or zlib, told by the stream's first bytes).
    pub encoding: Encoding,
    pub zlib: bool,
    pub endian: Endian,
    pub voxel_type: VoxelType,
    /// Bytes after `base_offset` (raw: `-1` = the data ends the file).
    pub byte_skip: i64,
    pub compressed_bytes: Option<u64>,
}

impl DataPlan {
    pub(crate) fn new(header: &NrrdHeader, header_path: &Path) -> Self {
        let files = data_file_paths(header, header_path);
        let total = header.element_count().unwrap_or(0) * header.voxel_type.size_bytes() as u64;
        let base_offset = if header.data_files == DataFiles::Attached {
            header.header_len as u64
        } else {
            0
        };
        let mut plan = Self::from_parts(PlanParts {
            files,
            base_offset,
            total_bytes: total,
            encoding: header.encoding,
            zlib: false,
            endian: header.endian.unwrap_or(Endian::native()),
            voxel_type: header.voxel_type,
            byte_skip: header.byte_skip,
            compressed_bytes: None,
        });
        plan.line_skip = header.line_skip;
        plan
    }

    pub(crate) fn from_parts(parts: PlanParts) -> Self {
        // Data files are mapped or read on first use; no output may replace them meanwhile.
        for f in &parts.files {
            crate::input::note_input(f);
        }
        let per_file_bytes = parts.total_bytes / parts.files.len().max(1) as u64;
        let maps = parts.files.iter().map(|_| OnceLock::new()).collect();
        Self {
            files: parts.files,
            base_offset: parts.base_offset,
            per_file_bytes,
            encoding: parts.encoding,
            endian: parts.endian,
            voxel_type: parts.voxel_type,
            line_skip: 0,
            byte_skip: parts.byte_skip,
            zlib: parts.zlib,
            compressed_bytes: parts.compressed_bytes,
            maps,
            trailing_ok: false,
        }
    }

    /// The data of one file that is not a NRRD (NIfTI): `total_bytes` at byte `offset` of
    /// the file (raw, memory-mapped) or of its decompressed stream (gzip); bytes after the
    /// data are ignored.
    pub(crate) fn single_file(
        path: &Path,
        encoding: Encoding,
        offset: u64,
        total_bytes: u64,
        endian: Endian,
        voxel_type: VoxelType,
    ) -> Self {
        let (base_offset, byte_skip) = match encoding {
            // The skip of a compressed stream counts decompressed bytes (as NRRD's byte skip).
            Encoding::Raw => (offset, 0),
            _ => (0, i64::try_from(offset).unwrap_or(i64::MAX)),
        };
        let mut plan = Self::from_parts(PlanParts {
            files: vec![path.to_path_buf()],
            base_offset,
            total_bytes,
            encoding,
            zlib: false,
            endian,
            voxel_type,
            byte_skip,
            compressed_bytes: None,
        });
        plan.trailing_ok = true;
        plan
    }

    pub(crate) fn file_count(&self) -> usize {
        self.files.len()
    }

    /// Loads decoded bytes `[start, start + len)` as voxels (`len` a multiple of the voxel
    /// size). A raw range inside one file is viewed in place in its memory map.
    pub(crate) fn load(&self, start: u64, len: u64) -> Result<VoxelData, FormatError> {
        let size = self.voxel_type.size_bytes() as u64;
        let count = (len / size) as usize;
        let per = self.per_file_bytes.max(1);
        let first = (start / per) as usize;
        let last = ((start + len).saturating_sub(1) / per) as usize;
        if self.encoding == Encoding::Raw && first == last {
            let (map, data_start) = self.raw_map(first)?;
            return voxels_from_map(
                &self.files[first],
                map,
                data_start + start % per,
                count,
                self.voxel_type,
                self.endian,
            );
        }
        let mut out = Vec::new();
        for f in first..=last {
            let file_start = f as u64 * per;
            let a = start.max(file_start) - file_start;
            let b = (start + len).min(file_start + per) - file_start;
            if self.encoding == Encoding::Raw {
                let (map, data_start) = self.raw_map(f)?;
                let s = (data_start + a) as usize;
                out.extend_from_slice(&map[s..s + (b - a) as usize]);
            } else {
                self.decode_range(f, a, b, &mut out)?;
            }
        }
        let endian = if self.encoding == Encoding::Ascii {
            Endian::native()
        } else {
            self.endian
        };
        Ok(voxels_from_vec(out, self.voxel_type, endian))
    }

    /// Maps raw data file `f` and finds its data, checking the file size first.
    fn raw_map(&self, f: usize) -> Result<&(Arc<Mmap>, u64), FormatError> {
        if let Some(m) = self.maps[f].get() {
            return Ok(m);
        }
        let path = &self.files[f];
        let file = crate::input::open_regular(path).map_err(|e| FormatError::io(path, e))?;
        let file_len = file.metadata().map_err(|e| FormatError::io(path, e))?.len();
        let need = self.per_file_bytes;
        let data_start = if self.byte_skip == -1 {
            match file_len.checked_sub(need) {
                Some(s) if s >= self.base_offset => s,
                _ => {
                    return Err(FormatError::TooShort {
                        path: path.clone(),
                        offset: self.base_offset,
                        needed: need,
                        available: file_len,
                    });
                }
            }
        } else {
            let mut reader = BufReader::new(&file);
            let after_lines = self.skip_lines(path, &mut reader, file_len)?;
            after_lines.saturating_add(self.byte_skip as u64)
        };
        let end = data_start.saturating_add(need);
        if end > file_len {
            return Err(FormatError::TooShort {
                path: path.clone(),
                offset: data_start,
                needed: need,
                available: file_len,
            });
        }
        if end < file_len && !self.trailing_ok {
            return Err(FormatError::TooLong {
                path: path.clone(),
                offset: end,
                expected: need,
            });
        }
        let map = map_file(path, &file)?;
        Ok(self.maps[f].get_or_init(|| (map, data_start)))
    }

    /// Seeks `reader` to the data section and skips `line skip` lines; returns the offset.
    fn skip_lines<R: BufRead + Seek>(
        &self,
        path: &Path,
        reader: &mut R,
        file_len: u64,
    ) -> Result<u64, FormatError> {
        if self.base_offset > file_len {
            return Err(FormatError::TooShort {
                path: path.to_path_buf(),
                offset: self.base_offset,
                needed: self.per_file_bytes,
                available: file_len,
            });
        }
        reader
            .seek(SeekFrom::Start(self.base_offset))
            .map_err(|e| FormatError::io(path, e))?;
        let mut pos = self.base_offset;
        let mut sink = Vec::new();
        for n in 0..self.line_skip {
            sink.clear();
            // Bounded: one line at a time, at most 64 KiB kept (longer lines are still
            // skipped, in pieces).
            let read =
                read_line_bounded(reader, &mut sink).map_err(|e| FormatError::io(path, e))?;
            if read == 0 {
                return Err(FormatError::BadValue {
                    path: path.to_path_buf(),
                    line: 0,
                    field: "line skip".into(),
                    reason: format!(
                        "the data file has only {n} lines after byte offset {}, {} to skip",
                        self.base_offset, self.line_skip
                    ),
                });
            }
            pos += read;
        }
        Ok(pos)
    }

    /// Decodes bytes `[a, b)` of data file `f` (compressed or text) onto `out`.
    fn decode_range(&self, f: usize, a: u64, b: u64, out: &mut Vec<u8>) -> Result<(), FormatError> {
        let path = &self.files[f];
        let file = crate::input::open_regular(path).map_err(|e| FormatError::io(path, e))?;
        let file_len = file.metadata().map_err(|e| FormatError::io(path, e))?.len();
        let mut reader = BufReader::with_capacity(1 << 16, file);
        let data_start = self.skip_lines(path, &mut reader, file_len)?;
        let whole_tail = b == self.per_file_bytes;
        let skip = self.byte_skip.max(0) as u64;
        match self.encoding {
            Encoding::Gzip | Encoding::Bzip2 => {
                let mut name = self.encoding.name();
                let mut reader: Box<dyn BufRead> = match self.compressed_bytes {
                    Some(n) => Box::new(reader.take(n)),
                    None => Box::new(reader),
                };
                let is_gzip = reader
                    .fill_buf()
                    .map_err(|e| FormatError::io(path, e))?
                    .starts_with(&[0x1f, 0x8b]);
                let mut dec: Box<dyn Read> = if self.zlib && !is_gzip {
                    name = "zlib";
                    Box::new(flate2::bufread::ZlibDecoder::new(reader))
                } else if self.encoding == Encoding::Gzip {
                    Box::new(flate2::bufread::MultiGzDecoder::new(reader))
                } else {
                    Box::new(bzip2::bufread::MultiBzDecoder::new(reader))
                };
                // Teem applies the byte skip to the decompressed data.
                // `byte skip` is the header's word (up to i64::MAX): saturate, never wrap.
                read_exact_capped(path, name, &mut dec, skip.saturating_add(a), None)?;
                read_exact_capped(path, name, &mut dec, b - a, Some(out))
                    .map_err(|e| shift_offset(e, skip.saturating_add(a)))?;
                if whole_tail && self.trailing_ok {
                    // Bytes after the data are allowed, but the stream must still be whole:
                    // reading it to its end checks the gzip CRC (discarding, nothing kept).
                    std::io::copy(&mut dec, &mut std::io::sink()).map_err(|e| {
                        FormatError::Decode {
                            path: path.clone(),
                            encoding: name,
                            offset: skip.saturating_add(b),
                            reason: e.to_string(),
                        }
                    })?;
                } else if whole_tail {
                    let mut one = [0u8; 1];
                    match dec.read(&mut one) {
                        Ok(0) => {}
                        Ok(_) => {
                            return Err(FormatError::TooLong {
                                path: path.clone(),
                                offset: skip.saturating_add(b),
                                expected: self.per_file_bytes,
                            });
                        }
                        Err(e) => {
                            return Err(FormatError::Decode {
                                path: path.clone(),
                                encoding: name,
                                offset: skip.saturating_add(b),
                                reason: e.to_string(),
                            });
                        }
                    }
                }
                Ok(())
            }
            Encoding::Ascii | Encoding::Hex => {
                let name = self.encoding.name();
                let skipped = std::io::copy(&mut (&mut reader).take(skip), &mut std::io::sink())
                    .map_err(|e| FormatError::io(path, e))?;
                if skipped < skip {
                    return Err(FormatError::TooShort {
                        path: path.clone(),
                        offset: data_start,
                        needed: skip,
                        available: file_len,
                    });
                }
                let mut text = TextReader {
                    reader,
                    path,
                    encoding: name,
                    offset: data_start + skip,
                    index: 0,
                };
                if self.encoding == Encoding::Ascii {
                    text.ascii(self.voxel_type, a, b, whole_tail, out)
                } else {
                    text.hex(a, b, whole_tail, out)
                }
            }
            Encoding::Raw => unreachable!("raw data is memory-mapped"),
        }
    }
}

fn shift_offset(e: FormatError, by: u64) -> FormatError {
    match e {
        FormatError::Decode {
            path,
            encoding,
            offset,
            reason,
        } => FormatError::Decode {
            path,
            encoding,
            offset: offset.saturating_sub(by),
            reason,
        },
        other => other,
    }
}

/// Reads one line (through `\n`) keeping at most 64 KiB of it; returns the bytes consumed.
fn read_line_bounded<R: BufRead>(reader: &mut R, keep: &mut Vec<u8>) -> std::io::Result<u64> {
    let mut total = 0u64;
    loop {
        let buf = reader.fill_buf()?;
        if buf.is_empty() {
            return Ok(total);
        }
        let (n, done) = match buf.iter().position(|&c| c == b'\n') {
            Some(i) => (i + 1, true),
            None => (buf.len(), false),
        };
        if keep.len() < 1 << 16 {
            keep.extend_from_slice(&buf[..n.min((1 << 16) - keep.len())]);
        }
        reader.consume(n);
        total += n as u64;
        if done {
            return Ok(total);
        }
    }
}

/// Reads exactly `n` decoded bytes (onto `out`, or discarding them), growing `out` only as
/// data arrives. A short stream is a truncated one.
fn read_exact_capped(
    path: &Path,
    encoding: &'static str,
    dec: &mut dyn Read,
    n: u64,
    out: Option<&mut Vec<u8>>,
) -> Result<(), FormatError> {
    let got = match out {
        Some(out) => {
            let before = out.len();
            let r = dec.take(n).read_to_end(out);
            let got = (out.len() - before) as u64;
            r.map_err(|e| FormatError::Decode {
                path: path.to_path_buf(),
                encoding,
                offset: got,
                reason: e.to_string(),
            })?;
            got
        }
        None => std::io::copy(&mut dec.take(n), &mut std::io::sink()).map_err(|e| {
            FormatError::Decode {
                path: path.to_path_buf(),
                encoding,
                offset: 0,
                reason: e.to_string(),
            }
        })?,
    };
    if got < n {
        return Err(FormatError::Decode {
            path: path.to_path_buf(),
            encoding,
            offset: got,
            reason: format!("stream ends after {got} of {n} bytes (truncated)"),
        });
    }
    Ok(())
}

/// Streaming parser of ascii values and hex bytes.
struct TextReader<'a, R> {
    reader: R,
    path: &'a Path,
    encoding: &'static str,
    /// Byte offset in the file (for messages).
    offset: u64,
    /// Index of the next value.
    index: u64,
}

impl<R: BufRead> TextReader<'_, R> {
    fn err(&self, reason: impl Into<String>) -> FormatError {
        FormatError::BadText {
            path: self.path.to_path_buf(),
            encoding: self.encoding,
            index: self.index,
            offset: self.offset,
            reason: reason.into(),
        }
    }

    /// The next token (separated by whitespace or commas) into `tok`; false at the end.
    fn token(&mut self, tok: &mut Vec<u8>) -> Result<bool, FormatError> {
        tok.clear();
        loop {
            let buf = self
                .reader
                .fill_buf()
                .map_err(|e| FormatError::io(self.path, e))?;
            if buf.is_empty() {
                return Ok(!tok.is_empty());
            }
            let mut used = 0;
            let mut done = false;
            for &c in buf {
                if c.is_ascii_whitespace() || c == b',' {
                    if !tok.is_empty() {
                        done = true;
                        break;
                    }
                    used += 1;
                } else {
                    tok.push(c);
                    used += 1;
                    if tok.len() > 128 {
                        return Err(self.err("is longer than 128 characters"));
                    }
                }
            }
            self.reader.consume(used);
            if tok.is_empty() {
                self.offset += used as u64;
            }
            if done {
                return Ok(true);
            }
        }
    }

    fn ascii(
        &mut self,
        voxel_type: VoxelType,
        a: u64,
        b: u64,
        whole_tail: bool,
        out: &mut Vec<u8>,
    ) -> Result<(), FormatError> {
        let size = voxel_type.size_bytes() as u64;
        let (first, end) = (a / size, b / size);
        let mut tok = Vec::new();
        while self.index < end {
            if !self.token(&mut tok)? {
                return Err(self.err(format!(
                    "missing: the data ends after {} of {} values (truncated)",
                    self.index, end
                )));
            }
            if self.index >= first {
                let text = std::str::from_utf8(&tok).map_err(|_| self.err("is not text"))?;
                push_value(voxel_type, text, out).map_err(|r| self.err(format!("`{text}` {r}")))?;
            }
            self.offset += tok.len() as u64;
            self.index += 1;
        }
        if whole_tail && self.token(&mut tok)? {
            return Err(FormatError::TooLong {
                path: self.path.to_path_buf(),
                offset: self.offset,
                expected: end,
            });
        }
        Ok(())
    }

    fn hex(
        &mut self,
        a: u64,
        b: u64,
        whole_tail: bool,
        out: &mut Vec<u8>,
    ) -> Result<(), FormatError> {
        let mut pending: Option<u8> = None;
        while self.index < b {
            let mut byte = [0u8; 1];
            let n = self
                .reader
                .read(&mut byte)
                .map_err(|e| FormatError::io(self.path, e))?;
            if n == 0 {
                return Err(self.err(format!(
                    "missing: the data ends after {} of {b} bytes (truncated)",
                    self.index
                )));
            }
            self.offset += 1;
            let c = byte[0];
            if c.is_ascii_whitespace() {
                continue;
            }
            let v = (c as char)
                .to_digit(16)
                .ok_or_else(|| self.err(format!("`{}` is not a hex digit", c as char)))?
                as u8;
            match pending.take() {
                None => pending = Some(v),
                Some(hi) => {
                    if self.index >= a {
                        out.push(hi << 4 | v);
                    }
                    self.index += 1;
                }
            }
        }
        if whole_tail {
            let mut rest = Vec::new();
            if self.token(&mut rest)? {
                return Err(FormatError::TooLong {
                    path: self.path.to_path_buf(),
                    offset: self.offset,
                    expected: b,
                });
            }
        }
        Ok(())
    }
}

/// Parses one ascii value and appends it in native byte order.
fn push_value(voxel_type: VoxelType, text: &str, out: &mut Vec<u8>) -> Result<(), String> {
    fn int<T: TryFrom<i64> + bytemuck::Pod>(text: &str, out: &mut Vec<u8>) -> Result<(), String> {
        let v: i64 = text.parse().map_err(|_| "is not an integer".to_string())?;
        let t = T::try_from(v).map_err(|_| "is out of range for the voxel type".to_string())?;
        out.extend_from_slice(bytemuck::bytes_of(&t));
        Ok(())
    }
    match voxel_type {
        VoxelType::U8 => int::<u8>(text, out),
        VoxelType::I8 => int::<i8>(text, out),
        VoxelType::U16 => int::<u16>(text, out),
        VoxelType::I16 => int::<i16>(text, out),
        VoxelType::U32 => int::<u32>(text, out),
        VoxelType::I32 => int::<i32>(text, out),
        VoxelType::F32 => {
            let v: f32 = text.parse().map_err(|_| "is not a number".to_string())?;
            out.extend_from_slice(&v.to_ne_bytes());
            Ok(())
        }
        VoxelType::F64 => {
            let v: f64 = text.parse().map_err(|_| "is not a number".to_string())?;
            out.extend_from_slice(&v.to_ne_bytes());
            Ok(())
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ascii_values_parse_with_range_checks() {
        let mut out = Vec::new();
        push_value(VoxelType::I16, "-300", &mut out).unwrap();
        assert_eq!(out, (-300i16).to_ne_bytes());
        assert!(
            push_value(VoxelType::U8, "256", &mut out)
                .unwrap_err()
                .contains("range")
        );
        assert!(push_value(VoxelType::U8, "1.5", &mut out).is_err());
        out.clear();
        push_value(VoxelType::F32, "nan", &mut out).unwrap();
        assert!(f32::from_ne_bytes(out[..4].try_into().unwrap()).is_nan());
    }

    #[test]
    fn bounded_line_reader_consumes_whole_long_lines() {
        let text = format!("{}\nnext", "x".repeat(200_000));
        let mut r = std::io::Cursor::new(text.as_bytes());
        let mut keep = Vec::new();
        assert_eq!(read_line_bounded(&mut r, &mut keep).unwrap(), 200_001);
        assert_eq!(keep.len(), 1 << 16);
        let mut rest = String::new();
        r.read_to_string(&mut rest).unwrap();
        assert_eq!(rest, "next");
    }
}
