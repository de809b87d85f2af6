//! A byte cursor shared by the text-and-binary mesh parsers (legacy VTK, Gmsh, TetGen), and
//! the scalar types of VTK arrays with their binary decoding.
//!
//! Every read is bounded: counts are checked against the bytes left before allocating, and
//! every error carries the byte offset (the line number is computed only when erring).

use std::path::Path;

use super::MeshError;

/// Number of `\n` bytes (for line numbers in errors; only computed when erring).
#[allow(clippy::naive_bytecount)]
pub(crate) fn newlines(data: &[u8]) -> usize {
    data.iter().filter(|&&b| b == b'\n').count()
}

pub(crate) struct Cursor<'a> {
    pub path: &'a Path,
    pub data: &'a [u8],
    pub pos: usize,
}

impl<'a> Cursor<'a> {
    pub fn new(path: &'a Path, data: &'a [u8]) -> Self {
        Self { path, data, pos: 0 }
    }

    /// 1-based line number of a byte offset.
    pub fn line_of(&self, pos: usize) -> usize {
        let end = pos.min(self.data.len());
        newlines(&self.data[..end]) + 1
    }

    pub fn err_at(&self, pos: usize, reason: impl Into<String>) -> MeshError {
        MeshError::Parse {
            path: self.path.to_path_buf(),
            line: self.line_of(pos),
            offset: pos as u64,
            reason: reason.into(),
        }
    }

    pub fn err(&self, reason: impl Into<String>) -> MeshError {
        self.err_at(self.pos, reason)
    }

    pub fn remaining(&self) -> usize {
        self.data.len().saturating_sub(self.pos)
    }

    pub fn skip_ws(&mut self) {
        while self.pos < self.data.len() && self.data[self.pos].is_ascii_whitespace() {
            self.pos += 1;
        }
    }

    /// Skips whitespace and `#` comments up to the end of their line.
    pub fn skip_ws_comments(&mut self) {
        loop {
            self.skip_ws();
            if self.pos < self.data.len() && self.data[self.pos] == b'#' {
                while self.pos < self.data.len() && self.data[self.pos] != b'\n' {
                    self.pos += 1;
                }
            } else {
                return;
            }
        }
    }

    /// The next whitespace-separated token, or `None` at the end.
    pub fn token(&mut self) -> Option<&'a [u8]> {
        self.skip_ws();
        let start = self.pos;
        while self.pos < self.data.len() && !self.data[self.pos].is_ascii_whitespace() {
            self.pos += 1;
        }
        (self.pos > start).then(|| &self.data[start..self.pos])
    }

    /// The next token as text; `what` names the expected item in the error.
    pub fn expect_token(&mut self, what: &str) -> Result<&'a str, MeshError> {
        let start = self.pos;
        let t = self.token().ok_or_else(|| {
            self.err_at(start, format!("unexpected end of file, expected {what}"))
        })?;
        std::str::from_utf8(t)
            .map_err(|_| self.err_at(self.pos - t.len(), format!("{what}: not text")))
    }

    /// The next token parsed as `T`.
    pub fn parse<T: std::str::FromStr>(&mut self, what: &str) -> Result<T, MeshError> {
        let t = self.expect_token(what)?;
        t.parse()
            .map_err(|_| self.err_at(self.pos - t.len(), format!("{what}: cannot parse {t:?}")))
    }

    /// A non-negative count, checked so that `count * min_bytes_each` fits in what is left
    /// of the file (headers lie; this bounds every allocation by the file size).
    pub fn count(&mut self, what: &str, min_bytes_each: u64) -> Result<usize, MeshError> {
        let start = self.pos;
        let n: i64 = self.parse(what)?;
        if n < 0 {
            return Err(self.err_at(start, format!("{what}: negative count {n}")));
        }
        self.check_fits(n as u64, min_bytes_each, what)?;
        Ok(n as usize)
    }

    /// Errors with [`MeshError::TooShort`] when `count * each` bytes are not left.
    pub fn check_fits(&self, count: u64, each: u64, what: &str) -> Result<(), MeshError> {
        let needed = count.saturating_mul(each);
        if needed > self.remaining() as u64 {
            return Err(MeshError::TooShort {
                path: self.path.to_path_buf(),
                what: format!("{what} ({count})"),
                offset: self.pos as u64,
                needed,
                available: self.remaining() as u64,
            });
        }
        Ok(())
    }

    /// The rest of the current line (without `\r\n`), moving past the newline.
    pub fn line(&mut self) -> Option<&'a [u8]> {
        if self.pos >= self.data.len() {
            return None;
        }
        let start = self.pos;
        while self.pos < self.data.len() && self.data[self.pos] != b'\n' {
            self.pos += 1;
        }
        let mut end = self.pos;
        if self.pos < self.data.len() {
            self.pos += 1;
        }
        if end > start && self.data[end - 1] == b'\r' {
            end -= 1;
        }
        Some(&self.data[start..end])
    }

    /// Moves past the end of the current line (before binary data that follows a keyword).
    pub fn skip_to_next_line(&mut self) {
        while self.pos < self.data.len() && self.data[self.pos] != b'\n' {
            self.pos += 1;
        }
        if self.pos < self.data.len() {
            self.pos += 1;
        }
    }

    /// The next `n` bytes (binary data), or [`MeshError::TooShort`].
    pub fn take(&mut self, n: usize, what: &str) -> Result<&'a [u8], MeshError> {
        self.check_fits(n as u64, 1, what)?;
        let s = &self.data[self.pos..self.pos + n];
        self.pos += n;
        Ok(s)
    }

    /// Position of the next occurrence of `needle` at or after the cursor.
    pub fn find(&self, needle: &[u8]) -> Option<usize> {
        if needle.is_empty() || self.pos >= self.data.len() {
            return None;
        }
        self.data[self.pos..]
            .windows(needle.len())
            .position(|w| w == needle)
            .map(|i| self.pos + i)
    }
}

/// The numeric types of VTK arrays (legacy names and XML names map here).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    I64,
    U64,
    F32,
    F64,
}

impl Scalar {
    pub fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::I64 | Scalar::U64 | Scalar::F64 => 8,
        }
    }

    /// Legacy VTK type names (case-insensitive).
    pub fn from_legacy(name: &str) -> Option<Self> {
        Some(match name.to_ascii_lowercase().as_str() {
            "char" => Scalar::I8,
            "unsigned_char" => Scalar::U8,
            "short" => Scalar::I16,
            "unsigned_short" => Scalar::U16,
            "int" => Scalar::I32,
            "unsigned_int" => Scalar::U32,
            // VTK writes `long` as 64-bit on 64-bit systems (vtkLegacyWriter).
            "long" | "vtktypeint64" | "vtkidtype" => Scalar::I64,
            "unsigned_long" | "vtktypeuint64" => Scalar::U64,
            "float" => Scalar::F32,
            "double" => Scalar::F64,
            _ => return None,
        })
    }

    /// VTK XML type names (`Int32`, `Float64`, also the old `Int`/`Float` forms).
    pub fn from_xml(name: &str) -> Option<Self> {
        Some(match name {
            "Int8" | "Char" => Scalar::I8,
            "UInt8" | "UChar" => Scalar::U8,
            "Int16" | "Short" => Scalar::I16,
            "UInt16" | "UShort" => Scalar::U16,
            "Int32" | "Int" => Scalar::I32,
            "UInt32" | "UInt" => Scalar::U32,
            "Int64" | "Long" | "IdType" => Scalar::I64,
            "UInt64" | "ULong" => Scalar::U64,
            "Float32" | "Float" => Scalar::F32,
            "Float64" | "Double" => Scalar::F64,
            _ => return None,
        })
    }

    pub fn xml_name(self) -> &'static str {
        match self {
            Scalar::I8 => "Int8",
            Scalar::U8 => "UInt8",
            Scalar::I16 => "Int16",
            Scalar::U16 => "UInt16",
            Scalar::I32 => "Int32",
            Scalar::U32 => "UInt32",
            Scalar::I64 => "Int64",
            Scalar::U64 => "UInt64",
            Scalar::F32 => "Float32",
            Scalar::F64 => "Float64",
        }
    }

    pub fn is_float(self) -> bool {
        matches!(self, Scalar::F32 | Scalar::F64)
    }

    /// Decodes `bytes` (a whole number of values) to `f64`.
    pub fn decode_f64(self, bytes: &[u8], big_endian: bool) -> Vec<f64> {
        let n = self.size();
        bytes
            .chunks_exact(n)
            .map(|c| {
                let mut b = [0u8; 8];
                b[..n].copy_from_slice(c);
                if big_endian {
                    b[..n].reverse();
                }
                // `b` now holds the value little-endian in its first n bytes.
                match self {
                    Scalar::I8 => f64::from(b[0] as i8),
                    Scalar::U8 => f64::from(b[0]),
                    Scalar::I16 => f64::from(i16::from_le_bytes([b[0], b[1]])),
                    Scalar::U16 => f64::from(u16::from_le_bytes([b[0], b[1]])),
                    Scalar::I32 => f64::from(i32::from_le_bytes([b[0], b[1], b[2], b[3]])),
                    Scalar::U32 => f64::from(u32::from_le_bytes([b[0], b[1], b[2], b[3]])),
                    Scalar::I64 => i64::from_le_bytes(b) as f64,
                    Scalar::U64 => u64::from_le_bytes(b) as f64,
                    Scalar::F32 => f64::from(f32::from_le_bytes([b[0], b[1], b[2], b[3]])),
                    Scalar::F64 => f64::from_le_bytes(b),
                }
            })
            .collect()
    }

    /// Decodes integer `bytes` to `i64` (floats are rejected by the callers first).
    pub fn decode_i64(self, bytes: &[u8], big_endian: bool) -> Vec<i64> {
        let n = self.size();
        bytes
            .chunks_exact(n)
            .map(|c| {
                let mut b = [0u8; 8];
                b[..n].copy_from_slice(c);
                if big_endian {
                    b[..n].reverse();
                }
                match self {
                    Scalar::I8 => i64::from(b[0] as i8),
                    Scalar::U8 => i64::from(b[0]),
                    Scalar::I16 => i64::from(i16::from_le_bytes([b[0], b[1]])),
                    Scalar::U16 => i64::from(u16::from_le_bytes([b[0], b[1]])),
                    Scalar::I32 => i64::from(i32::from_le_bytes([b[0], b[1], b[2], b[3]])),
                    Scalar::U32 => i64::from(u32::from_le_bytes([b[0], b[1], b[2], b[3]])),
                    Scalar::I64 => i64::from_le_bytes(b),
                    // Values above i64::MAX are out of range for any mesh anyway.
                    Scalar::U64 => i64::try_from(u64::from_le_bytes(b)).unwrap_or(i64::MAX),
                    Scalar::F32 => f32::from_le_bytes([b[0], b[1], b[2], b[3]]) as i64,
                    Scalar::F64 => f64::from_le_bytes(b) as i64,
                }
            })
            .collect()
    }
}
