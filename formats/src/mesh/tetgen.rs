//! TetGen `.node` + `.ele` files (TetGen manual, "File formats").
//!
//! `.node`: `<#points> <dimension (3)> <#attributes> <boundary markers (0|1)>`, then one line
//! per point: `<index> <x> <y> <z> [attributes] [marker]`. `.ele`: `<#tets> <nodes per tet
//! (4|10)> <region attribute (0|1)>`, then `<index> <n1> ... <nk> [attribute]`. `#` starts a
//! comment. Numbering starts at the first point's index (0 or 1) and must be consecutive.
//! Node attributes become fields `attribute_0`, `attribute_1`, ...; ten-node tets use their
//! four corner nodes. Either file's path may be given; the other is found beside it.

use std::path::{Path, PathBuf};

use super::text::Cursor;
use super::{CellKind, LoadedMesh, MeshError, RawArray, RawMesh, read_file};

/// Reads a TetGen mesh from `x.node` or `x.ele` (both must exist).
pub fn read(path: &Path) -> Result<LoadedMesh, MeshError> {
    read_raw(path)?.into_tet_mesh(path)
}

/// The `.node` and `.ele` paths for either one.
pub fn pair(path: &Path) -> (PathBuf, PathBuf) {
    (path.with_extension("node"), path.with_extension("ele"))
}

/// Parses a TetGen pair without splitting cells.
pub fn read_raw(path: &Path) -> Result<RawMesh, MeshError> {
    let (node, ele) = pair(path);
    let nd = read_file(&node)?;
    let ed = read_file(&ele)?;
    parse(&node, &nd, &ele, &ed)
}

/// Parses the bytes of a `.node` and an `.ele` file (paths name them in errors).
pub fn parse(
    node_path: &Path,
    node: &[u8],
    ele_path: &Path,
    ele: &[u8],
) -> Result<RawMesh, MeshError> {
    let mut c = Cursor::new(node_path, node);
    let mut mesh = RawMesh::new();
    let next = |c: &mut Cursor<'_>, what: &str| -> Result<f64, MeshError> {
        c.skip_ws_comments();
        c.parse::<f64>(what)
    };
    c.skip_ws_comments();
    let n = c.count("number of points", 8)?;
    let dim = next(&mut c, "dimension")?;
    if dim != 3.0 {
        return Err(c.err(format!("dimension {dim}: only 3D meshes are read")));
    }
    let nattr = next(&mut c, "number of attributes")?;
    let markers = next(&mut c, "boundary marker flag")?;
    if !(0.0..=64.0).contains(&nattr) || nattr.fract() != 0.0 {
        return Err(c.err(format!("attribute count {nattr} is not 0..64")));
    }
    let nattr = nattr as usize;
    let has_marker = markers != 0.0;
    mesh.points = Vec::with_capacity(n);
    let mut attrs = vec![Vec::with_capacity(n); nattr];
    let mut base = 0i64;
    for i in 0..n {
        c.skip_ws_comments();
        let start = c.pos;
        let idx: i64 = c.parse("point index")?;
        if i == 0 {
            if idx != 0 && idx != 1 {
                return Err(c.err_at(start, format!("first point index {idx} must be 0 or 1")));
            }
            base = idx;
        } else if idx != base + i as i64 {
            return Err(c.err_at(
                start,
                format!(
                    "point index {idx}, expected {} (numbering must be consecutive)",
                    base + i as i64
                ),
            ));
        }
        mesh.points
            .push([next(&mut c, "x")?, next(&mut c, "y")?, next(&mut c, "z")?]);
        for a in &mut attrs {
            a.push(next(&mut c, "attribute")?);
        }
        if has_marker {
            next(&mut c, "boundary marker")?;
        }
    }
    mesh.arrays = attrs
        .into_iter()
        .enumerate()
        .map(|(i, values)| RawArray {
            name: format!("attribute_{i}"),
            components: 1,
            values,
        })
        .collect();

    let mut e = Cursor::new(ele_path, ele);
    e.skip_ws_comments();
    let nt = e.count("number of tetrahedra", 10)?;
    e.skip_ws_comments();
    let per: usize = e.parse("nodes per tetrahedron")?;
    if per != 4 && per != 10 {
        return Err(e.err(format!("{per} nodes per tetrahedron (4 or 10 expected)")));
    }
    e.skip_ws_comments();
    let region: usize = e.parse("region attribute flag")?;
    if region > 1 {
        return Err(e.err(format!("region attribute flag {region} is not 0 or 1")));
    }
    mesh.kinds = Vec::with_capacity(nt);
    mesh.connectivity = Vec::with_capacity(nt * 4);
    mesh.offsets = Vec::with_capacity(nt + 1);
    mesh.offsets.push(0);
    for cell in 0..nt {
        e.skip_ws_comments();
        let start = e.pos;
        let idx: i64 = e.parse("tetrahedron index")?;
        if idx != base + cell as i64 {
            return Err(e.err_at(
                start,
                format!("tetrahedron index {idx}, expected {}", base + cell as i64),
            ));
        }
        let mut ids = [0u64; 4];
        #[allow(clippy::needless_range_loop)] // `k` also counts the nodes past the four corners
        for k in 0..per {
            e.skip_ws_comments();
            let at = e.pos;
            let v: i64 = e.parse("node index")?;
            // `base` is 0 or 1; `i64::MIN - 1` must be an error, not an overflow.
            let local = v.checked_sub(base).unwrap_or(-1);
            if local < 0 {
                return Err(MeshError::BadCell {
                    path: ele_path.to_path_buf(),
                    cell,
                    reason: format!(
                        "node index {v} is below the first index {base} (line {})",
                        e.line_of(at)
                    ),
                });
            }
            if let Some(slot) = ids.get_mut(k) {
                *slot = local as u64;
            }
        }
        for _ in 0..region {
            e.skip_ws_comments();
            let _: f64 = e.parse("region attribute")?;
        }
        mesh.push_cell(CellKind::Tetra, &ids);
    }
    // Out-of-range indices are reported by `into_tet_mesh` with the cell number; name the
    // .ele file there too.
    for (cell, w) in mesh.offsets.windows(2).enumerate() {
        if let Some(&bad) = mesh.connectivity[w[0]..w[1]]
            .iter()
            .find(|&&i| i >= n as u64)
        {
            return Err(MeshError::BadCell {
                path: ele_path.to_path_buf(),
                cell,
                reason: format!(
                    "node index {} is out of range ({n} points numbered from {base})",
                    bad as i64 + base
                ),
            });
        }
    }
    Ok(mesh)
}
