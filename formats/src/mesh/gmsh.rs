//! Gmsh `.msh` files, versions 2.2 and 4.1, ASCII and binary (Gmsh reference manual,
//! "MSH file format").
//!
//! Read: `$MeshFormat`, `$Nodes`, `$Elements`, `$NodeData` (one field per view: the first
//! string tag is the name; one component becomes a field, several a listed array; nodes
//! without a value get NaN; a name seen again, e.g. a later time step, is listed as skipped).
//! `$Entities` is parsed in binary files (to skip it safely) and every other section
//! (`$PhysicalNames`, `$InterpolationScheme`, `$ElementData`, ...) is skipped to its `$End`.
//! Binary files are in the writer's byte order, detected from the `1` after the format line.
//! Node tags may be sparse; element node tags are mapped to point indices (an unknown tag is
//! an error naming the element). Element types: 4 tetra, 5 hexahedron, 6 prism (wedge),
//! 7 pyramid (first order, same vertex order as VTK); all others are skipped and counted.

use std::collections::HashMap;
use std::path::Path;

use super::text::Cursor;
use super::{CellKind, LoadedMesh, MeshError, RawArray, RawMesh, read_file};

/// Reads a `.msh` mesh.
pub fn read(path: &Path) -> Result<LoadedMesh, MeshError> {
    read_raw(path)?.into_tet_mesh(path)
}

/// Parses a `.msh` file without splitting cells.
pub fn read_raw(path: &Path) -> Result<RawMesh, MeshError> {
    let data = read_file(path)?;
    parse(path, &data)
}

/// Number of nodes of a Gmsh element type (for binary files and validation).
fn nodes_of(ty: i64) -> Option<usize> {
    Some(match ty {
        15 => 1,
        1 => 2,
        2 | 8 => 3,
        3 | 4 | 26 => 4,
        7 | 27 => 5,
        6 | 9 | 28 => 6,
        5 | 16 => 8,
        10 | 20 => 9,
        11 | 21 => 10,
        22 => 12,
        19 => 13,
        14 => 14,
        18 | 23 | 24 => 15,
        13 | 17 | 29 => 20,
        25 => 21,
        12 => 27,
        30 => 35,
        31 => 56,
        92 => 64,
        93 => 125,
        _ => return None,
    })
}

/// Gmsh element type to cell kind (skipped kinds carry the matching VTK code).
fn kind_of(ty: i64) -> CellKind {
    match ty {
        4 => CellKind::Tetra,
        5 => CellKind::Hexahedron,
        6 => CellKind::Wedge,
        7 => CellKind::Pyramid,
        15 => CellKind::Other(1),
        1 => CellKind::Other(3),
        2 => CellKind::Other(5),
        3 => CellKind::Other(9),
        11 => CellKind::Other(24),
        17 => CellKind::Other(25),
        12 => CellKind::Other(29),
        t => CellKind::Other(1000 + t.clamp(0, 10_000) as u32),
    }
}

struct Parser<'a> {
    c: Cursor<'a>,
    binary: bool,
    big_endian: bool,
    size_t: usize,
    v4: bool,
    /// Node tags in file order (index = point index).
    tags: Vec<u64>,
    tag_index: TagIndex,
}

enum TagIndex {
    Dense(Vec<u32>),
    Sparse(HashMap<u64, u32>),
}

impl TagIndex {
    fn build(tags: &[u64]) -> Self {
        let max = tags.iter().copied().max().unwrap_or(0);
        if max <= (tags.len() as u64).saturating_mul(4) + 1024 {
            let mut v = vec![u32::MAX; max as usize + 1];
            for (i, &t) in tags.iter().enumerate() {
                v[t as usize] = i as u32;
            }
            TagIndex::Dense(v)
        } else {
            TagIndex::Sparse(
                tags.iter()
                    .enumerate()
                    .map(|(i, &t)| (t, i as u32))
                    .collect(),
            )
        }
    }

    fn get(&self, tag: u64) -> Option<u32> {
        match self {
            TagIndex::Dense(v) => v.get(tag as usize).copied().filter(|&i| i != u32::MAX),
            TagIndex::Sparse(m) => m.get(&tag).copied(),
        }
    }
}

/// Parses `.msh` bytes (`path` only names the source in errors).
pub fn parse(path: &Path, data: &[u8]) -> Result<RawMesh, MeshError> {
    let mut p = Parser {
        c: Cursor::new(path, data),
        binary: false,
        big_endian: false,
        size_t: 8,
        v4: false,
        tags: Vec::new(),
        tag_index: TagIndex::Dense(Vec::new()),
    };
    p.parse()
}

impl Parser<'_> {
    fn parse(&mut self) -> Result<RawMesh, MeshError> {
        let mut mesh = RawMesh::new();
        let mut have_format = false;
        let mut have_nodes = false;
        let mut have_elements = false;
        loop {
            self.c.skip_ws();
            let start = self.c.pos;
            let Some(line) = self.c.line() else { break };
            let line = String::from_utf8_lossy(line).trim().to_owned();
            let Some(section) = line.strip_prefix('$') else {
                return Err(self.c.err_at(
                    start,
                    format!(
                        "expected a $Section line, found {:?}",
                        line.chars().take(40).collect::<String>()
                    ),
                ));
            };
            let section = section.to_owned();
            if !have_format && section != "MeshFormat" && section != "Comments" {
                return Err(self
                    .c
                    .err_at(start, format!("${section} before $MeshFormat")));
            }
            match section.as_str() {
                "MeshFormat" => {
                    self.mesh_format()?;
                    have_format = true;
                }
                "Nodes" => {
                    if have_nodes {
                        return Err(self.c.err_at(start, "second $Nodes section"));
                    }
                    mesh.points = if self.v4 {
                        self.nodes4()?
                    } else {
                        self.nodes2()?
                    };
                    self.tag_index = TagIndex::build(&self.tags);
                    have_nodes = true;
                }
                "Elements" => {
                    if !have_nodes {
                        return Err(self.c.err_at(start, "$Elements before $Nodes"));
                    }
                    if self.v4 {
                        self.elements4(&mut mesh)?;
                    } else {
                        self.elements2(&mut mesh)?;
                    }
                    have_elements = true;
                }
                "NodeData" => {
                    if !have_nodes {
                        return Err(self.c.err_at(start, "$NodeData before $Nodes"));
                    }
                    let a = self.node_data()?;
                    mesh.arrays.push(a);
                }
                "Entities" if self.binary && self.v4 => self.entities_binary()?,
                _ => {
                    // Skip to the matching end marker.
                    let end = format!("$End{section}");
                    let at = self
                        .c
                        .find(end.as_bytes())
                        .ok_or_else(|| self.c.err_at(start, format!("${section} without {end}")))?;
                    self.c.pos = at;
                }
            }
            self.c.skip_ws();
            let at = self.c.pos;
            let end = self
                .c
                .line()
                .map(|l| String::from_utf8_lossy(l).trim().to_owned())
                .unwrap_or_default();
            if end != format!("$End{section}") {
                return Err(self.c.err_at(
                    at,
                    format!(
                        "expected $End{section}, found {:?}",
                        end.chars().take(40).collect::<String>()
                    ),
                ));
            }
        }
        if !have_format {
            return Err(self.c.err_at(0, "not a Gmsh file: no $MeshFormat"));
        }
        if !have_nodes || !have_elements {
            return Err(self.c.err(format!(
                "missing ${}",
                if have_nodes { "Elements" } else { "Nodes" }
            )));
        }
        Ok(mesh)
    }

    fn mesh_format(&mut self) -> Result<(), MeshError> {
        let start = self.c.pos;
        let version: String = self.c.parse("format version")?;
        let file_type: u32 = self.c.parse("file type")?;
        let data_size: usize = self.c.parse("data size")?;
        self.v4 = match version.as_str() {
            "2" | "2.0" | "2.1" | "2.2" => false,
            "4.1" => true,
            v => {
                return Err(MeshError::Unsupported {
                    path: self.c.path.to_path_buf(),
                    what: format!("MSH version {v} (2.2 and 4.1 are read)"),
                });
            }
        };
        if data_size != 8 && data_size != 4 {
            return Err(self
                .c
                .err_at(start, format!("data size {data_size} is not 4 or 8")));
        }
        self.size_t = data_size;
        self.binary = match file_type {
            0 => false,
            1 => true,
            t => {
                return Err(self.c.err_at(
                    start,
                    format!("file type {t} is not 0 (ASCII) or 1 (binary)"),
                ));
            }
        };
        if self.binary {
            self.c.skip_to_next_line();
            let b = self.c.take(4, "endianness marker")?;
            self.big_endian = match b {
                [1, 0, 0, 0] => false,
                [0, 0, 0, 1] => true,
                _ => {
                    return Err(self.c.err_at(
                        self.c.pos - 4,
                        format!("endianness marker {b:?} is not the integer 1"),
                    ));
                }
            };
        }
        Ok(())
    }

    fn word(&self, b: &[u8]) -> u64 {
        let mut w = [0u8; 8];
        w[..b.len()].copy_from_slice(b);
        if self.big_endian {
            w[..b.len()].reverse();
        }
        u64::from_le_bytes(w)
    }

    fn bin_i32(&mut self, what: &str) -> Result<i64, MeshError> {
        let b = self.c.take(4, what)?;
        Ok(i64::from(self.word(b) as u32 as i32))
    }

    fn bin_size(&mut self, what: &str) -> Result<u64, MeshError> {
        let n = self.size_t;
        let b = self.c.take(n, what)?;
        Ok(self.word(b))
    }

    fn bin_f64s(&mut self, n: usize, what: &str) -> Result<Vec<f64>, MeshError> {
        let b = self.c.take(n.saturating_mul(8), what)?;
        Ok(b.chunks_exact(8)
            .map(|c| f64::from_bits(self.word(c)))
            .collect())
    }

    /// A count (ASCII token or binary size_t/int) checked against the bytes left.
    fn count(&mut self, what: &str, each: u64, bin_int: bool) -> Result<usize, MeshError> {
        let n = if self.binary {
            if bin_int {
                self.bin_i32(what)?
            } else {
                self.bin_size(what)? as i64
            }
        } else {
            self.c.parse::<i64>(what)?
        };
        if n < 0 {
            return Err(self.c.err(format!("{what}: negative count {n}")));
        }
        self.c.check_fits(n as u64, each, what)?;
        Ok(n as usize)
    }

    /// A count that is text even in binary files (MSH 2.2 headers, `$NodeData` tags).
    fn count_text(&mut self, what: &str, each: u64) -> Result<usize, MeshError> {
        self.c.count(what, each)
    }

    fn f64_ascii(&mut self, what: &str) -> Result<f64, MeshError> {
        self.c.parse(what)
    }

    fn nodes2(&mut self) -> Result<Vec<[f64; 3]>, MeshError> {
        let n = self.count_text("number of nodes", if self.binary { 28 } else { 7 })?;
        if self.binary {
            self.c.skip_to_next_line();
        }
        let mut pts = Vec::with_capacity(n);
        self.tags = Vec::with_capacity(n);
        for _ in 0..n {
            let (tag, p) = if self.binary {
                let t = self.bin_i32("node tag")?;
                let v = self.bin_f64s(3, "node coordinates")?;
                (t, [v[0], v[1], v[2]])
            } else {
                let t: i64 = self.c.parse("node tag")?;
                (
                    t,
                    [
                        self.f64_ascii("x")?,
                        self.f64_ascii("y")?,
                        self.f64_ascii("z")?,
                    ],
                )
            };
            self.push_node(tag, p, &mut pts)?;
        }
        Ok(pts)
    }

    fn push_node(
        &mut self,
        tag: i64,
        p: [f64; 3],
        pts: &mut Vec<[f64; 3]>,
    ) -> Result<(), MeshError> {
        if tag <= 0 {
            return Err(self.c.err(format!("node tag {tag} is not positive")));
        }
        self.tags.push(tag as u64);
        pts.push(p);
        Ok(())
    }

    fn nodes4(&mut self) -> Result<Vec<[f64; 3]>, MeshError> {
        let blocks = self.count("number of node blocks", 1, false)?;
        let n = self.count("number of nodes", if self.binary { 32 } else { 7 }, false)?;
        let _min = self.count("min node tag", 0, false)?;
        let _max = self.count("max node tag", 0, false)?;
        let mut pts = Vec::with_capacity(n);
        self.tags = Vec::with_capacity(n);
        for _ in 0..blocks {
            let dim = self.count("entity dimension", 0, true)?;
            let _tag = self.count("entity tag", 0, true)?;
            let parametric = self.count("parametric flag", 0, true)?;
            let k = self.count("nodes in block", if self.binary { 32 } else { 7 }, false)?;
            if pts.len() + k > n {
                return Err(self.c.err(format!(
                    "node blocks hold more than the {n} nodes announced"
                )));
            }
            let extra = if parametric != 0 { dim.min(3) } else { 0 };
            let first = self.tags.len();
            for _ in 0..k {
                let t = if self.binary {
                    self.bin_size("node tag")? as i64
                } else {
                    self.c.parse("node tag")?
                };
                if t <= 0 {
                    return Err(self.c.err(format!("node tag {t} is not positive")));
                }
                self.tags.push(t as u64);
            }
            for _ in 0..k {
                let v = if self.binary {
                    self.bin_f64s(3 + extra, "node coordinates")?
                } else {
                    let mut v = Vec::with_capacity(3 + extra);
                    for _ in 0..3 + extra {
                        v.push(self.f64_ascii("coordinate")?);
                    }
                    v
                };
                pts.push([v[0], v[1], v[2]]);
            }
            debug_assert_eq!(self.tags.len() - first, k);
        }
        if pts.len() != n {
            return Err(self
                .c
                .err(format!("{} nodes in blocks, {n} announced", pts.len())));
        }
        Ok(pts)
    }

    fn map_nodes(&self, elem: usize, tags: &[i64], out: &mut Vec<u64>) -> Result<(), MeshError> {
        for &t in tags {
            let idx = u64::try_from(t)
                .ok()
                .and_then(|t| self.tag_index.get(t))
                .ok_or_else(|| MeshError::BadCell {
                    path: self.c.path.to_path_buf(),
                    cell: elem,
                    reason: format!("node tag {t} is not defined in $Nodes"),
                })?;
            out.push(u64::from(idx));
        }
        Ok(())
    }

    fn push_element(
        &self,
        mesh: &mut RawMesh,
        elem: usize,
        ty: i64,
        nodes: &[i64],
    ) -> Result<(), MeshError> {
        if let Some(nn) = nodes_of(ty)
            && nn != nodes.len()
        {
            return Err(MeshError::BadCell {
                path: self.c.path.to_path_buf(),
                cell: elem,
                reason: format!("element type {ty} has {nn} nodes, found {}", nodes.len()),
            });
        }
        let kind = kind_of(ty);
        if matches!(kind, CellKind::Other(_)) {
            // Skipped cells keep no connectivity (their tags are not checked either).
            mesh.push_cell(kind, &[]);
            return Ok(());
        }
        let mut ids = Vec::with_capacity(nodes.len());
        self.map_nodes(elem, nodes, &mut ids)?;
        mesh.push_cell(kind, &ids);
        Ok(())
    }

    fn ascii_line_ints(&mut self, what: &str) -> Result<Vec<i64>, MeshError> {
        self.c.skip_ws();
        let start = self.c.pos;
        let line = self
            .c
            .line()
            .ok_or_else(|| self.c.err(format!("unexpected end of file in {what}")))?;
        let text = std::str::from_utf8(line)
            .map_err(|_| self.c.err_at(start, format!("{what}: not text")))?;
        text.split_ascii_whitespace()
            .map(|t| {
                t.parse::<i64>().map_err(|_| {
                    self.c
                        .err_at(start, format!("{what}: {t:?} is not an integer"))
                })
            })
            .collect()
    }

    fn elements2(&mut self, mesh: &mut RawMesh) -> Result<(), MeshError> {
        let n = self.count_text("number of elements", if self.binary { 12 } else { 6 })?;
        mesh.kinds.reserve(n);
        if self.binary {
            self.c.skip_to_next_line();
            let mut done = 0usize;
            while done < n {
                let ty = self.bin_i32("element type")?;
                let k = self.count("elements in block", 4, true)?;
                let ntags = self.count("number of tags", 0, true)?;
                let nn = nodes_of(ty).ok_or_else(|| MeshError::Unsupported {
                    path: self.c.path.to_path_buf(),
                    what: format!("element type {ty} in a binary file (node count unknown)"),
                })?;
                if done + k > n {
                    return Err(self.c.err(format!(
                        "element blocks hold more than the {n} elements announced"
                    )));
                }
                let rec = 1 + ntags + nn;
                self.c
                    .check_fits(k as u64, (rec as u64).saturating_mul(4), "element block")?;
                for _ in 0..k {
                    let mut v = Vec::with_capacity(rec);
                    for _ in 0..rec {
                        v.push(self.bin_i32("element data")?);
                    }
                    self.push_element(mesh, done, ty, &v[1 + ntags..])?;
                    done += 1;
                }
            }
        } else {
            for elem in 0..n {
                let v = self.ascii_line_ints("element")?;
                // `number-of-tags` is read from the file: negative or past the line is an error
                // (not a slice panic, not an overflow).
                let nodes_at = match v.get(2) {
                    Some(&t) => usize::try_from(t)
                        .ok()
                        .and_then(|t| t.checked_add(3))
                        .filter(|&at| at <= v.len())
                        .ok_or_else(|| MeshError::BadCell {
                            path: self.c.path.to_path_buf(),
                            cell: elem,
                            reason: format!(
                                "tag count {t} is negative or exceeds the {} numbers of the element line",
                                v.len()
                            ),
                        })?,
                    None => {
                        return Err(MeshError::BadCell {
                            path: self.c.path.to_path_buf(),
                            cell: elem,
                            reason: format!("element line has {} numbers", v.len()),
                        });
                    }
                };
                self.push_element(mesh, elem, v[1], &v[nodes_at..])?;
            }
        }
        Ok(())
    }

    fn elements4(&mut self, mesh: &mut RawMesh) -> Result<(), MeshError> {
        let blocks = self.count("number of element blocks", 1, false)?;
        let n = self.count(
            "number of elements",
            if self.binary { 16 } else { 4 },
            false,
        )?;
        let _min = self.count("min element tag", 0, false)?;
        let _max = self.count("max element tag", 0, false)?;
        mesh.kinds.reserve(n);
        let mut done = 0usize;
        for _ in 0..blocks {
            let _dim = self.count("entity dimension", 0, true)?;
            let _tag = self.count("entity tag", 0, true)?;
            let ty = if self.binary {
                self.bin_i32("element type")?
            } else {
                self.c.parse("element type")?
            };
            let k = self.count("elements in block", if self.binary { 16 } else { 4 }, false)?;
            if done + k > n {
                return Err(self.c.err(format!(
                    "element blocks hold more than the {n} elements announced"
                )));
            }
            if self.binary {
                let nn = nodes_of(ty).ok_or_else(|| MeshError::Unsupported {
                    path: self.c.path.to_path_buf(),
                    what: format!("element type {ty} in a binary file (node count unknown)"),
                })?;
                self.c.check_fits(
                    k as u64,
                    (1 + nn) as u64 * self.size_t as u64,
                    "element block",
                )?;
                for _ in 0..k {
                    let mut v = Vec::with_capacity(1 + nn);
                    for _ in 0..=nn {
                        v.push(self.bin_size("element data")? as i64);
                    }
                    self.push_element(mesh, done, ty, &v[1..])?;
                    done += 1;
                }
            } else {
                for _ in 0..k {
                    let v = self.ascii_line_ints("element")?;
                    if v.is_empty() {
                        return Err(MeshError::BadCell {
                            path: self.c.path.to_path_buf(),
                            cell: done,
                            reason: "empty element line".into(),
                        });
                    }
                    self.push_element(mesh, done, ty, &v[1..])?;
                    done += 1;
                }
            }
        }
        if done != n {
            return Err(self
                .c
                .err(format!("{done} elements in blocks, {n} announced")));
        }
        Ok(())
    }

    /// Skips a binary 4.1 `$Entities` section by parsing its structure.
    fn entities_binary(&mut self) -> Result<(), MeshError> {
        // The section line was consumed: binary data starts here.
        let counts = [
            self.bin_size("number of points")?,
            self.bin_size("number of curves")?,
            self.bin_size("number of surfaces")?,
            self.bin_size("number of volumes")?,
        ];
        for (dim, &k) in counts.iter().enumerate() {
            self.c.check_fits(k, 4 + 24, "entities")?;
            for _ in 0..k {
                self.c.take(4, "entity tag")?;
                self.c
                    .take(if dim == 0 { 24 } else { 48 }, "entity bounds")?;
                let np = self.bin_size("physical tag count")?;
                self.c.take(
                    np.saturating_mul(4).min(usize::MAX as u64) as usize,
                    "physical tags",
                )?;
                if dim > 0 {
                    let nb = self.bin_size("bounding entity count")?;
                    self.c.take(
                        nb.saturating_mul(4).min(usize::MAX as u64) as usize,
                        "bounding entities",
                    )?;
                }
            }
        }
        Ok(())
    }

    fn quoted_line(&mut self) -> Result<String, MeshError> {
        self.c.skip_ws();
        let line = self
            .c
            .line()
            .ok_or_else(|| self.c.err("unexpected end of file in $NodeData tags"))?;
        let s = String::from_utf8_lossy(line).trim().to_owned();
        Ok(s.trim_matches('"').to_owned())
    }

    fn node_data(&mut self) -> Result<RawArray, MeshError> {
        let ns = self.count_text("number of string tags", 1)?;
        let mut name = String::from("node_data");
        for i in 0..ns {
            let s = self.quoted_line()?;
            if i == 0 {
                name = s;
            }
        }
        let nr = self.count_text("number of real tags", 1)?;
        for _ in 0..nr {
            let _: f64 = self.c.parse("real tag")?;
        }
        let ni = self.count_text("number of integer tags", 1)?;
        let mut ints = Vec::with_capacity(ni);
        for _ in 0..ni {
            ints.push(self.c.parse::<i64>("integer tag")?);
        }
        if ints.len() < 3 {
            return Err(self.c.err(format!(
                "$NodeData \"{name}\": {} integer tags, need 3 (step, components, count)",
                ints.len()
            )));
        }
        let comps = usize::try_from(ints[1])
            .ok()
            .filter(|c| (1..=9).contains(c))
            .ok_or_else(|| {
                self.c.err(format!(
                    "$NodeData \"{name}\": component count {} is not 1..9",
                    ints[1]
                ))
            })?;
        let count = usize::try_from(ints[2]).map_err(|_| {
            self.c
                .err(format!("$NodeData \"{name}\": negative value count"))
        })?;
        let rec = if self.binary {
            4 + 8 * comps
        } else {
            2 * (1 + comps)
        };
        self.c
            .check_fits(count as u64, rec as u64, "$NodeData values")?;
        let np = self.tags.len();
        let mut values = vec![f64::NAN; np * comps];
        if self.binary {
            self.c.skip_to_next_line();
        }
        for _ in 0..count {
            let (tag, v) = if self.binary {
                let t = self.bin_i32("node tag")?;
                (t, self.bin_f64s(comps, "node values")?)
            } else {
                let t: i64 = self.c.parse("node tag")?;
                let mut v = Vec::with_capacity(comps);
                for _ in 0..comps {
                    v.push(self.f64_ascii("node value")?);
                }
                (t, v)
            };
            let idx = u64::try_from(tag)
                .ok()
                .and_then(|t| self.tag_index.get(t))
                .ok_or_else(|| MeshError::BadArray {
                    path: self.c.path.to_path_buf(),
                    name: name.clone(),
                    reason: format!("node tag {tag} is not defined in $Nodes"),
                })? as usize;
            values[idx * comps..(idx + 1) * comps].copy_from_slice(&v);
        }
        Ok(RawArray {
            name,
            components: comps,
            values,
        })
    }
}
