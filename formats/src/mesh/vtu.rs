//! VTK XML unstructured grids, `.vtu` (VTK file formats document, "XML File Formats").
//!
//! The document walk and the `DataArray` decoding (ascii, inline base64, appended raw or
//! base64, zlib and LZ4 blocks, UInt32/UInt64 headers, either byte order) are
//! `mesh::vtk_xml`'s, shared with the `.vti` image reader. Here: one `Piece`, its
//! `Points`, `Cells` (`connectivity`, `offsets`, `types`) and `PointData` arrays;
//! polyhedron face streams and CellData are ignored.
//!
//! Write: [`write_vtu`], appended raw little-endian, UInt64 headers, no compression (VTK's and
//! ParaView's default layout).

use std::io::Write;
use std::path::Path;

use volume_core::tet::TetMesh;

use super::vtk_xml::{ArraySpec, Compressor, Section, parse_document};
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

/// Parses `.vtu` bytes (`path` only names the source in errors).
pub fn parse(path: &Path, data: &[u8]) -> Result<RawMesh, MeshError> {
    let doc = parse_document(path, data, |ty| {
        if ty == "UnstructuredGrid" {
            Ok(())
        } else {
            Err(MeshError::Unsupported {
                path: path.to_path_buf(),
                what: format!("VTKFile type {ty:?} (only UnstructuredGrid is a tet mesh)"),
            })
        }
    })?;
    let ctx = &doc.ctx;
    let perr = |pos: usize, reason: String| ctx.perr(pos, reason);
    let mut pieces = doc.elements_named(b"Piece");
    let Some(piece) = pieces.next() else {
        return Err(perr(0, "no <Piece> element".into()));
    };
    if pieces.next().is_some() {
        return Err(MeshError::Unsupported {
            path: path.to_path_buf(),
            what: "more than one Piece".to_owned(),
        });
    }
    let count = |k: &[u8], what: &str| -> Result<usize, MeshError> {
        let v = piece
            .get(k)
            .ok_or_else(|| perr(piece.pos, format!("Piece without {what}")))?;
        v.trim()
            .parse()
            .map_err(|_| perr(piece.pos, format!("{what}: cannot parse {v:?}")))
    };
    let n_points = count(b"NumberOfPoints", "NumberOfPoints")?;
    let n_cells = count(b"NumberOfCells", "NumberOfCells")?;
    let arrays = &doc.arrays;

    // Headers lie: bound counts by what a file of this size can describe, unless compressed.
    if ctx.compressor == Compressor::None && (n_points as u64).saturating_mul(3) > data.len() as u64
    {
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
