//! Legacy VTK `.vtk` files, DATASET UNSTRUCTURED_GRID (VTK file formats document, "Simple
//! Legacy Formats").
//!
//! Read: versions 2.0–4.2 (`CELLS n size` with a point count before each cell) and 5.1
//! (`CELLS nOffsets nConnectivity` followed by `OFFSETS type` and `CONNECTIVITY type` arrays,
//! usually `vtktypeint64`); ASCII and BINARY (big-endian, data right after the keyword line).
//! POINT_DATA `SCALARS` (with or without a component count; `LOOKUP_TABLE` optional),
//! `FIELD` arrays, `GLOBAL_IDS`/`PEDIGREE_IDS` become point arrays; `VECTORS`, `NORMALS`,
//! `TENSORS`, `TEXTURE_COORDINATES` are read as multi-component arrays (listed, not fields);
//! `COLOR_SCALARS`, lookup tables, CELL_DATA, dataset-level FIELD data and METADATA blocks
//! are parsed and dropped. Names are `%20`-decoded.
//!
//! Write: [`write_vtk_legacy`], version 4.2 (readable by every VTK since 2.0 and by
//! ParaView), `float` points, tetra cells, each field as `SCALARS name float 1`.

use std::fmt::Write as _;
use std::io::Write;
use std::path::Path;

use volume_core::tet::TetMesh;

use super::text::{Cursor, Scalar};
use super::{CellKind, LoadedMesh, MeshError, RawArray, RawMesh, read_file};

/// Reads a legacy `.vtk` mesh.
pub fn read(path: &Path) -> Result<LoadedMesh, MeshError> {
    read_raw(path)?.into_tet_mesh(path)
}

/// Parses a legacy `.vtk` file without splitting cells.
pub fn read_raw(path: &Path) -> Result<RawMesh, MeshError> {
    let data = read_file(path)?;
    parse(path, &data)
}

/// Parses legacy VTK bytes (`path` only names the source in errors).
pub fn parse(path: &Path, data: &[u8]) -> Result<RawMesh, MeshError> {
    let mut p = Parser::new(path, data);
    p.preamble()?;
    p.parse()
}

/// The tokenizer of legacy VTK files, shared with the structured-points and rectilinear-grid
/// image reader (`crate::vtk_image`).
pub(crate) struct Parser<'a> {
    pub c: Cursor<'a>,
    pub binary: bool,
    pub version: (u32, u32),
}

/// A keyword line split into tokens, with where it started.
pub(crate) struct Line<'a> {
    pub start: usize,
    pub words: Vec<&'a str>,
}

/// Array values as read: the big-endian bytes of a binary file (converted by the caller to
/// the type it keeps), or the numbers of an ASCII file.
pub(crate) enum Values<'a> {
    Binary(&'a [u8]),
    Ascii(Vec<f64>),
}

impl Values<'_> {
    pub fn into_f64(self, ty: Scalar) -> Vec<f64> {
        match self {
            Values::Binary(bytes) => ty.decode_f64(bytes, true),
            Values::Ascii(v) => v,
        }
    }
}

/// A POINT_DATA (or FIELD) array with its declared type.
pub(crate) struct LegacyArray<'a> {
    pub name: String,
    /// The keyword that declared it (`SCALARS`, `FIELD`, `VECTORS`, ...).
    pub keyword: &'static str,
    pub components: usize,
    pub ty: Scalar,
    pub values: Values<'a>,
}

impl LegacyArray<'_> {
    fn into_raw(self) -> RawArray {
        RawArray {
            name: self.name,
            components: self.components,
            values: self.values.into_f64(self.ty),
        }
    }
}

pub(crate) fn decode_name(s: &str) -> String {
    // Legacy names encode spaces and other special bytes as %XX.
    let b = s.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        if b[i] == b'%'
            && let Some(hex) = b.get(i + 1..i + 3)
            && let Ok(v) = u8::from_str_radix(std::str::from_utf8(hex).unwrap_or("zz"), 16)
        {
            out.push(v);
            i += 3;
            continue;
        }
        out.push(b[i]);
        i += 1;
    }
    String::from_utf8_lossy(&out).into_owned()
}

fn encode_name(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for ch in s.chars() {
        if ch.is_ascii_graphic() && ch != '%' {
            out.push(ch);
        } else {
            for b in ch.to_string().bytes() {
                let _ = write!(out, "%{b:02X}");
            }
        }
    }
    if out.is_empty() {
        "field".to_owned()
    } else {
        out
    }
}

impl<'a> Parser<'a> {
    pub fn new(path: &'a Path, data: &'a [u8]) -> Self {
        Self {
            c: Cursor::new(path, data),
            binary: false,
            version: (4, 2),
        }
    }

    /// The three lines before the first keyword: version, title, ASCII or BINARY.
    pub fn preamble(&mut self) -> Result<(), MeshError> {
        let first = self.c.line().unwrap_or_default();
        let first = String::from_utf8_lossy(first);
        let Some(ver) = first.trim().strip_prefix("# vtk DataFile Version") else {
            return Err(self.c.err_at(0, format!(
                "not a legacy VTK file: first line must be \"# vtk DataFile Version x.y\", found {:?}",
                first.chars().take(60).collect::<String>()
            )));
        };
        let ver = ver.trim();
        let (maj, min) = ver.split_once('.').unwrap_or((ver, "0"));
        self.version = match (maj.parse(), min.parse()) {
            (Ok(a), Ok(b)) => (a, b),
            _ => return Err(self.c.err_at(0, format!("bad version {ver:?}"))),
        };
        if self.version.0 > 5 || (self.version.0 == 5 && self.version.1 > 1) {
            return Err(MeshError::Unsupported {
                path: self.c.path.to_path_buf(),
                what: format!("legacy VTK version {ver} (2.0 to 5.1 are read)"),
            });
        }
        self.c.line(); // title, free text
        let enc = self.c.line().unwrap_or_default();
        match String::from_utf8_lossy(enc)
            .trim()
            .to_ascii_uppercase()
            .as_str()
        {
            "ASCII" => self.binary = false,
            "BINARY" => self.binary = true,
            other => {
                return Err(self.c.err(format!(
                    "line 3 must be ASCII or BINARY, found {:?}",
                    other.chars().take(40).collect::<String>()
                )));
            }
        }
        Ok(())
    }

    /// The unstructured grid after the preamble.
    fn parse(&mut self) -> Result<RawMesh, MeshError> {
        let mut mesh = RawMesh::new();
        let mut have_dataset = false;
        let mut have_points = false;
        let mut have_cells = false;
        let mut cell_types: Option<Vec<i64>> = None;
        while let Some(line) = self.keyword_line()? {
            let kw = line.words[0].to_ascii_uppercase();
            match kw.as_str() {
                "DATASET" => {
                    let kind = line.words.get(1).copied().unwrap_or("");
                    if !kind.eq_ignore_ascii_case("UNSTRUCTURED_GRID") {
                        return Err(MeshError::Unsupported {
                            path: self.c.path.to_path_buf(),
                            what: format!("DATASET {kind} (only UNSTRUCTURED_GRID is a tet mesh)"),
                        });
                    }
                    have_dataset = true;
                }
                "FIELD" => {
                    // Dataset-level field data: parsed and dropped.
                    self.field(&line, None)?;
                }
                "POINTS" => {
                    self.need_dataset(have_dataset, &line)?;
                    let n = self.count_word(&line, 1, "POINTS count", 3)?;
                    let ty = self.scalar_word(&line, 2)?;
                    let v = self.values(n * 3, ty, "POINTS")?;
                    mesh.points = v.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
                    have_points = true;
                }
                "CELLS" => {
                    self.need_dataset(have_dataset, &line)?;
                    if self.version.0 >= 5 {
                        self.cells_v5(&line, &mut mesh)?;
                    } else {
                        self.cells_v4(&line, &mut mesh)?;
                    }
                    have_cells = true;
                }
                "CELL_TYPES" => {
                    let n = self.count_word(&line, 1, "CELL_TYPES count", 1)?;
                    cell_types = Some(self.ints(n, Scalar::I32, "CELL_TYPES")?);
                }
                "POINT_DATA" => {
                    let n = self.count_word(&line, 1, "POINT_DATA count", 0)?;
                    if have_points && n != mesh.points.len() {
                        return Err(self.c.err_at(
                            line.start,
                            format!(
                                "POINT_DATA {n} but the file has {} points",
                                mesh.points.len()
                            ),
                        ));
                    }
                    let mut arrays = Vec::new();
                    self.attributes(n, Some(&mut arrays))?;
                    mesh.arrays
                        .extend(arrays.into_iter().map(LegacyArray::into_raw));
                }
                "CELL_DATA" => {
                    let n = self.count_word(&line, 1, "CELL_DATA count", 0)?;
                    self.attributes(n, None)?;
                }
                "METADATA" => self.metadata(),
                _ => {
                    return Err(self
                        .c
                        .err_at(line.start, format!("unknown keyword {:?}", line.words[0])));
                }
            }
        }
        if !have_dataset {
            return Err(self.c.err("no DATASET line"));
        }
        if !have_points {
            return Err(self.c.err("no POINTS section"));
        }
        let n_cells = mesh.offsets.len() - 1;
        match cell_types {
            None if have_cells && n_cells > 0 => {
                return Err(self.c.err("CELLS without CELL_TYPES"));
            }
            None => {}
            Some(types) => {
                if types.len() != n_cells {
                    return Err(self.c.err(format!(
                        "CELL_TYPES lists {} cells but CELLS has {n_cells}",
                        types.len()
                    )));
                }
                mesh.kinds = Vec::with_capacity(types.len());
                for (cell, &t) in types.iter().enumerate() {
                    let Ok(code) = u32::try_from(t) else {
                        return Err(MeshError::BadCell {
                            path: self.c.path.to_path_buf(),
                            cell,
                            reason: format!("negative cell type {t}"),
                        });
                    };
                    mesh.kinds.push(CellKind::from_vtk(code));
                }
            }
        }
        Ok(mesh)
    }

    fn need_dataset(&self, have: bool, line: &Line<'_>) -> Result<(), MeshError> {
        if have {
            Ok(())
        } else {
            Err(self
                .c
                .err_at(line.start, format!("{} before DATASET", line.words[0])))
        }
    }

    /// The next non-empty line, split into words (`None` at the end of the file).
    pub fn keyword_line(&mut self) -> Result<Option<Line<'a>>, MeshError> {
        self.c.skip_ws();
        let start = self.c.pos;
        let Some(raw) = self.c.line() else {
            return Ok(None);
        };
        if raw.len() > 4096 {
            return Err(self.c.err_at(start, "keyword line longer than 4096 bytes"));
        }
        let text = std::str::from_utf8(raw)
            .map_err(|_| self.c.err_at(start, "keyword line is not text"))?;
        let words: Vec<&str> = text.split_ascii_whitespace().collect();
        if words.is_empty() {
            return Ok(None);
        }
        Ok(Some(Line { start, words }))
    }

    pub fn word<'l>(&self, line: &Line<'l>, i: usize, what: &str) -> Result<&'l str, MeshError> {
        line.words.get(i).copied().ok_or_else(|| {
            self.c
                .err_at(line.start, format!("{}: missing {what}", line.words[0]))
        })
    }

    /// Word `i` as a count whose data (`each` values) must fit in the rest of the file.
    pub fn count_word(
        &self,
        line: &Line<'_>,
        i: usize,
        what: &str,
        each: u64,
    ) -> Result<usize, MeshError> {
        let w = self.word(line, i, what)?;
        let n: u64 = w.parse().map_err(|_| {
            self.c
                .err_at(line.start, format!("{what}: cannot parse {w:?}"))
        })?;
        // ASCII values take at least one byte each, binary ones at least their size.
        self.c.check_fits(n, each, what)?;
        Ok(n as usize)
    }

    pub fn scalar_word(&self, line: &Line<'_>, i: usize) -> Result<Scalar, MeshError> {
        let w = self.word(line, i, "data type")?;
        Scalar::from_legacy(w).ok_or_else(|| {
            if w.eq_ignore_ascii_case("bit") || w.eq_ignore_ascii_case("string") {
                MeshError::Unsupported {
                    path: self.c.path.to_path_buf(),
                    what: format!("{} data of type {w}", line.words[0]),
                }
            } else {
                self.c.err_at(
                    line.start,
                    format!("{}: unknown data type {w:?}", line.words[0]),
                )
            }
        })
    }

    /// `n` values of type `ty` as f64 (ASCII tokens or big-endian binary).
    pub fn values(&mut self, n: usize, ty: Scalar, what: &str) -> Result<Vec<f64>, MeshError> {
        Ok(self.raw_values(n, ty, what)?.into_f64(ty))
    }

    /// `n` values of type `ty`: binary bytes as they are (big-endian), ASCII tokens parsed.
    pub fn raw_values(
        &mut self,
        n: usize,
        ty: Scalar,
        what: &str,
    ) -> Result<Values<'a>, MeshError> {
        if self.binary {
            let bytes = self.c.take(n.saturating_mul(ty.size()), what)?;
            Ok(Values::Binary(bytes))
        } else {
            self.c.check_fits(n as u64, 1, what)?;
            let mut v = Vec::with_capacity(n);
            for i in 0..n {
                let start = self.c.pos;
                let t = self.c.expect_token(what)?;
                let x: f64 = t.parse().map_err(|_| {
                    self.c
                        .err_at(start, format!("{what}: value #{i} {t:?} is not a number"))
                })?;
                v.push(x);
            }
            Ok(Values::Ascii(v))
        }
    }

    fn ints(&mut self, n: usize, ty: Scalar, what: &str) -> Result<Vec<i64>, MeshError> {
        if ty.is_float() {
            return Err(self
                .c
                .err(format!("{what}: integer type expected, found a float type")));
        }
        if self.binary {
            let bytes = self.c.take(n.saturating_mul(ty.size()), what)?;
            Ok(ty.decode_i64(bytes, true))
        } else {
            self.c.check_fits(n as u64, 1, what)?;
            let mut v = Vec::with_capacity(n);
            for i in 0..n {
                let start = self.c.pos;
                let t = self.c.expect_token(what)?;
                let x: i64 = t.parse().map_err(|_| {
                    self.c
                        .err_at(start, format!("{what}: value #{i} {t:?} is not an integer"))
                })?;
                v.push(x);
            }
            Ok(v)
        }
    }

    fn cells_v4(&mut self, line: &Line<'_>, mesh: &mut RawMesh) -> Result<(), MeshError> {
        let n_cells = self.count_word(line, 1, "CELLS count", 1)?;
        let size = self.count_word(line, 2, "CELLS size", 1)?;
        if n_cells > size {
            return Err(self.c.err_at(
                line.start,
                format!("CELLS {n_cells} {size}: size is smaller than the count"),
            ));
        }
        let list = self.ints(size, Scalar::I32, "CELLS")?;
        let mut offsets = Vec::with_capacity(n_cells + 1);
        let mut conn = Vec::with_capacity(size - n_cells);
        offsets.push(0);
        let mut i = 0usize;
        for cell in 0..n_cells {
            let Some(&k) = list.get(i) else {
                return Err(self.bad_cell(
                    cell,
                    format!("CELLS list ends before cell {cell} (size {size})"),
                ));
            };
            if k < 0 || (k as usize) > list.len() - i - 1 {
                return Err(self.bad_cell(
                    cell,
                    format!("point count {k} runs past the CELLS list (size {size})"),
                ));
            }
            for &id in &list[i + 1..=i + k as usize] {
                conn.push(self.index(cell, id)?);
            }
            i += k as usize + 1;
            offsets.push(conn.len());
        }
        if i != size {
            return Err(self.c.err_at(
                line.start,
                format!("CELLS size {size} but the {n_cells} cells use {i} numbers"),
            ));
        }
        mesh.offsets = offsets;
        mesh.connectivity = conn;
        Ok(())
    }

    fn cells_v5(&mut self, line: &Line<'_>, mesh: &mut RawMesh) -> Result<(), MeshError> {
        let n_off = self.count_word(line, 1, "CELLS offsets count", 1)?;
        let n_conn = self.count_word(line, 2, "CELLS connectivity count", 1)?;
        let l = self.expect_keyword("OFFSETS")?;
        let ty = self.scalar_word(&l, 1)?;
        let offsets = self.ints(n_off, ty, "OFFSETS")?;
        let l = self.expect_keyword("CONNECTIVITY")?;
        let ty = self.scalar_word(&l, 1)?;
        let conn = self.ints(n_conn, ty, "CONNECTIVITY")?;
        if n_off == 0 {
            if n_conn != 0 {
                return Err(self
                    .c
                    .err_at(line.start, "CELLS: no offsets but a non-empty connectivity"));
            }
            mesh.offsets = vec![0];
            mesh.connectivity.clear();
            return Ok(());
        }
        if offsets[0] != 0 {
            return Err(self.bad_cell(0, format!("first offset is {}, must be 0", offsets[0])));
        }
        let mut offs = Vec::with_capacity(n_off);
        for (i, w) in offsets.windows(2).enumerate() {
            if w[1] < w[0] || w[1] as u64 > n_conn as u64 {
                return Err(self.bad_cell(
                    i,
                    format!(
                        "offsets {}..{} are decreasing or past the connectivity (length {n_conn})",
                        w[0], w[1]
                    ),
                ));
            }
        }
        if *offsets.last().unwrap_or(&0) as usize != n_conn {
            return Err(self.c.err_at(
                line.start,
                format!(
                    "last offset {} differs from the connectivity length {n_conn}",
                    offsets.last().unwrap_or(&0)
                ),
            ));
        }
        offs.extend(offsets.iter().map(|&o| o as usize));
        let mut ids = Vec::with_capacity(n_conn);
        for (cell, w) in offs.windows(2).enumerate() {
            for &id in &conn[w[0]..w[1]] {
                ids.push(self.index(cell, id)?);
            }
        }
        mesh.offsets = offs;
        mesh.connectivity = ids;
        Ok(())
    }

    fn index(&self, cell: usize, id: i64) -> Result<u64, MeshError> {
        u64::try_from(id).map_err(|_| self.bad_cell(cell, format!("negative point index {id}")))
    }

    fn bad_cell(&self, cell: usize, reason: String) -> MeshError {
        MeshError::BadCell {
            path: self.c.path.to_path_buf(),
            cell,
            reason,
        }
    }

    fn expect_keyword(&mut self, kw: &str) -> Result<Line<'a>, MeshError> {
        let pos = self.c.pos;
        match self.keyword_line()? {
            Some(l) if l.words[0].eq_ignore_ascii_case(kw) => Ok(l),
            Some(l) => Err(self
                .c
                .err_at(l.start, format!("expected {kw}, found {:?}", l.words[0]))),
            None => Err(self
                .c
                .err_at(pos, format!("unexpected end of file, expected {kw}"))),
        }
    }

    /// Skips a METADATA block (it ends at an empty line).
    pub fn metadata(&mut self) {
        while let Some(l) = self.c.line() {
            if l.iter().all(u8::is_ascii_whitespace) {
                break;
            }
        }
    }

    /// A POINT_DATA or CELL_DATA section of `n` tuples; arrays go to `out` (None: dropped).
    pub fn attributes(
        &mut self,
        n: usize,
        mut out: Option<&mut Vec<LegacyArray<'a>>>,
    ) -> Result<(), MeshError> {
        loop {
            let save = self.c.pos;
            let Some(line) = self.keyword_line()? else {
                return Ok(());
            };
            let kw = line.words[0].to_ascii_uppercase();
            let (keyword, name, comps, ty) = match kw.as_str() {
                "SCALARS" => {
                    let name = decode_name(self.word(&line, 1, "name")?);
                    let ty = self.scalar_word(&line, 2)?;
                    let comps = match line.words.get(3) {
                        Some(w) => w
                            .parse::<usize>()
                            .ok()
                            .filter(|c| (1..=4).contains(c))
                            .ok_or_else(|| {
                                self.c.err_at(
                                    line.start,
                                    format!("SCALARS: component count {w:?} is not 1..4"),
                                )
                            })?,
                        None => 1,
                    };
                    // LOOKUP_TABLE is required by the spec, tolerated when missing.
                    let before = self.c.pos;
                    match self.keyword_line()? {
                        Some(l) if l.words[0].eq_ignore_ascii_case("LOOKUP_TABLE") => {}
                        _ => self.c.pos = before,
                    }
                    ("SCALARS", name, comps, ty)
                }
                "VECTORS" | "NORMALS" => (
                    if kw == "VECTORS" {
                        "VECTORS"
                    } else {
                        "NORMALS"
                    },
                    decode_name(self.word(&line, 1, "name")?),
                    3,
                    self.scalar_word(&line, 2)?,
                ),
                "TENSORS" => (
                    "TENSORS",
                    decode_name(self.word(&line, 1, "name")?),
                    9,
                    self.scalar_word(&line, 2)?,
                ),
                "TENSORS6" => (
                    "TENSORS6",
                    decode_name(self.word(&line, 1, "name")?),
                    6,
                    self.scalar_word(&line, 2)?,
                ),
                "TEXTURE_COORDINATES" => {
                    let dim = self.count_word(&line, 2, "dimension", 0)?;
                    if !(1..=3).contains(&dim) {
                        return Err(self.c.err_at(
                            line.start,
                            format!("TEXTURE_COORDINATES dimension {dim} is not 1..3"),
                        ));
                    }
                    (
                        "TEXTURE_COORDINATES",
                        decode_name(self.word(&line, 1, "name")?),
                        dim,
                        self.scalar_word(&line, 3)?,
                    )
                }
                "GLOBAL_IDS" | "PEDIGREE_IDS" => (
                    if kw == "GLOBAL_IDS" {
                        "GLOBAL_IDS"
                    } else {
                        "PEDIGREE_IDS"
                    },
                    decode_name(self.word(&line, 1, "name")?),
                    1,
                    self.scalar_word(&line, 2)?,
                ),
                "COLOR_SCALARS" => {
                    let k = self.count_word(&line, 2, "COLOR_SCALARS components", 0)?;
                    let total = n.saturating_mul(k);
                    if self.binary {
                        self.c.take(total, "COLOR_SCALARS")?;
                    } else {
                        self.values(total, Scalar::F32, "COLOR_SCALARS")?;
                    }
                    continue;
                }
                "LOOKUP_TABLE" => {
                    let k = self.count_word(&line, 2, "LOOKUP_TABLE size", 4)?;
                    if self.binary {
                        self.c.take(k * 4, "LOOKUP_TABLE")?;
                    } else {
                        self.values(k * 4, Scalar::F32, "LOOKUP_TABLE")?;
                    }
                    continue;
                }
                "FIELD" => {
                    self.field(&line, out.as_deref_mut().map(|o| (o, n)))?;
                    continue;
                }
                "METADATA" => {
                    self.metadata();
                    continue;
                }
                _ => {
                    // Not an attribute: the section ended.
                    self.c.pos = save;
                    return Ok(());
                }
            };
            let values = self.raw_values(n.saturating_mul(comps), ty, &format!("{kw} {name}"))?;
            if let Some(o) = out.as_deref_mut() {
                o.push(LegacyArray {
                    name,
                    keyword,
                    components: comps,
                    ty,
                    values,
                });
            }
        }
    }

    /// A FIELD block; arrays with `n` tuples go to `out` when given.
    pub fn field(
        &mut self,
        line: &Line<'_>,
        mut out: Option<(&mut Vec<LegacyArray<'a>>, usize)>,
    ) -> Result<(), MeshError> {
        let k = self.count_word(line, 2, "FIELD array count", 1)?;
        for _ in 0..k {
            let Some(l) = self.keyword_line()? else {
                return Err(self.c.err("FIELD ends before all its arrays"));
            };
            if l.words[0].eq_ignore_ascii_case("NULL_ARRAY") {
                continue;
            }
            if l.words[0].eq_ignore_ascii_case("METADATA") {
                self.metadata();
                continue;
            }
            let name = decode_name(l.words[0]);
            let comps = self.count_word(&l, 1, "components", 0)?;
            let tuples = self.count_word(&l, 2, "tuples", 0)?;
            let ty = self.scalar_word(&l, 3)?;
            let total = comps.saturating_mul(tuples);
            let values = self.raw_values(total, ty, &format!("FIELD array {name}"))?;
            if let Some((o, n)) = out.as_mut() {
                if tuples != *n {
                    return Err(MeshError::BadArray {
                        path: self.c.path.to_path_buf(),
                        name,
                        reason: format!("{tuples} tuples in POINT_DATA of {n} points"),
                    });
                }
                o.push(LegacyArray {
                    name,
                    keyword: "FIELD",
                    components: comps,
                    ty,
                    values,
                });
            }
            // An optional METADATA block may follow each array.
            let save = self.c.pos;
            match self.keyword_line()? {
                Some(m) if m.words[0].eq_ignore_ascii_case("METADATA") => self.metadata(),
                _ => self.c.pos = save,
            }
        }
        Ok(())
    }
}

/// Encoding of a written legacy file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LegacyEncoding {
    Ascii,
    /// Big-endian binary, as the format prescribes.
    Binary,
}

/// Writes `mesh` as a legacy VTK 4.2 unstructured grid of tetrahedra with all fields as
/// `SCALARS` (float), through [`crate::output::OutputFile`] (never over an input; an existing
/// file only with [`crate::output::Replace::Allow`]; a failed write leaves no file).
pub fn write_vtk_legacy(
    path: &Path,
    mesh: &TetMesh,
    encoding: LegacyEncoding,
    replace: crate::output::Replace,
) -> Result<(), MeshError> {
    crate::output::write_output_with(path, replace, |w| {
        write_legacy_to(w, mesh, encoding).map_err(|e| MeshError::io(path, e))
    })
}

fn write_legacy_to(
    w: &mut impl Write,
    mesh: &TetMesh,
    encoding: LegacyEncoding,
) -> std::io::Result<()> {
    let bin = encoding == LegacyEncoding::Binary;
    writeln!(w, "# vtk DataFile Version 4.2")?;
    writeln!(w, "isoscope tetrahedral mesh")?;
    writeln!(w, "{}", if bin { "BINARY" } else { "ASCII" })?;
    writeln!(w, "DATASET UNSTRUCTURED_GRID")?;
    writeln!(w, "POINTS {} float", mesh.points.len())?;
    if bin {
        for p in &mesh.points {
            for c in p {
                w.write_all(&c.to_be_bytes())?;
            }
        }
        writeln!(w)?;
    } else {
        for p in &mesh.points {
            writeln!(w, "{} {} {}", p[0], p[1], p[2])?;
        }
    }
    let n = mesh.tets.len();
    writeln!(w, "CELLS {n} {}", n * 5)?;
    if bin {
        for t in &mesh.tets {
            w.write_all(&4i32.to_be_bytes())?;
            for &i in t {
                w.write_all(&(i as i32).to_be_bytes())?;
            }
        }
        writeln!(w)?;
    } else {
        for t in &mesh.tets {
            writeln!(w, "4 {} {} {} {}", t[0], t[1], t[2], t[3])?;
        }
    }
    writeln!(w, "CELL_TYPES {n}")?;
    if bin {
        for _ in 0..n {
            w.write_all(&10i32.to_be_bytes())?;
        }
        writeln!(w)?;
    } else {
        for _ in 0..n {
            writeln!(w, "10")?;
        }
    }
    if !mesh.fields.is_empty() {
        writeln!(w, "POINT_DATA {}", mesh.points.len())?;
        for f in &mesh.fields {
            writeln!(w, "SCALARS {} float 1", encode_name(&f.name))?;
            writeln!(w, "LOOKUP_TABLE default")?;
            if bin {
                for v in &f.values {
                    w.write_all(&v.to_be_bytes())?;
                }
                writeln!(w)?;
            } else {
                for v in &f.values {
                    writeln!(w, "{v}")?;
                }
            }
        }
    }
    Ok(())
}
