//! Triangle mesh writers: binary little-endian PLY (optional vertex normals, vertex colours),
//! binary STL and OBJ text, chosen by the file's extension ([`TriMeshFormat::for_path`]).
//!
//! Everything goes through [`crate::output`] (never over an input, an existing file only when
//! allowed, atomic). Positions are `f32` world coordinates; triangles keep the mesh's winding
//! ([`volume_core::extract`]: right-hand normal towards decreasing value), and the STL facet
//! normal is that unit normal.

use std::fmt::Write as _;
use std::io::Write;
use std::path::Path;

use volume_core::extract::TriMesh;

use crate::FormatError;
use crate::output::{Replace, check_output, write_output_with};

/// The mesh file types written.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TriMeshFormat {
    /// Binary little-endian PLY.
    Ply,
    /// Binary STL.
    Stl,
    /// Wavefront OBJ (text).
    Obj,
}

impl TriMeshFormat {
    /// The format `path`'s extension names (case-insensitive); any other is an error naming
    /// the path.
    pub fn for_path(path: &Path) -> Result<Self, FormatError> {
        let ext = path
            .extension()
            .map(|e| e.to_string_lossy().to_ascii_lowercase());
        match ext.as_deref() {
            Some("ply") => Ok(Self::Ply),
            Some("stl") => Ok(Self::Stl),
            Some("obj") => Ok(Self::Obj),
            _ => Err(FormatError::UnknownFormat {
                path: path.to_path_buf(),
                reason: "triangle meshes are written as PLY (.ply), STL (.stl) or OBJ (.obj); \
                         name the output with one of these extensions"
                    .into(),
            }),
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            Self::Ply => "PLY",
            Self::Stl => "STL",
            Self::Obj => "OBJ",
        }
    }
}

/// What to write besides positions and triangles.
#[derive(Debug, Clone, Copy, Default)]
pub struct TriMeshOptions<'a> {
    /// Vertex normals (PLY `nx ny nz`, OBJ `vn`): [`TriMesh::vertex_normals`].
    pub normals: bool,
    /// Linear RGB in `[0, 1]` per surface index (PLY vertex colours, sRGB-encoded bytes);
    /// empty: no colours. Must cover every surface index of the mesh.
    pub surface_colors: &'a [[f32; 3]],
}

/// Writes `mesh` to `path` in the format its extension names; returns that format.
pub fn write_trimesh(
    path: &Path,
    mesh: &TriMesh,
    options: &TriMeshOptions<'_>,
    replace: Replace,
) -> Result<TriMeshFormat, FormatError> {
    // An input or an existing file is the first thing to say, as for every output.
    check_output(path, replace)?;
    let format = TriMeshFormat::for_path(path)?;
    let io = |e: std::io::Error| FormatError::io(path, e);
    if !options.surface_colors.is_empty()
        && let Some(s) = mesh
            .surfaces
            .iter()
            .find(|&&s| s as usize >= options.surface_colors.len())
    {
        return Err(FormatError::BadOutput {
            path: path.to_path_buf(),
            reason: format!(
                "surface {s} has no colour ({} given)",
                options.surface_colors.len()
            ),
        });
    }
    let normals = options.normals.then(|| mesh.vertex_normals());
    write_output_with(path, replace, |w| match format {
        TriMeshFormat::Ply => {
            write_ply(w, mesh, normals.as_deref(), options.surface_colors).map_err(io)
        }
        TriMeshFormat::Stl => write_stl(w, mesh, path),
        TriMeshFormat::Obj => write_obj(w, mesh, normals.as_deref()).map_err(io),
    })?;
    Ok(format)
}

/// A linear `[0, 1]` channel as an sRGB byte (what viewers expect of PLY colours).
fn srgb_byte(linear: f32) -> u8 {
    let c = linear.clamp(0.0, 1.0);
    let s = if c <= 0.003_130_8 {
        12.92 * c
    } else {
        1.055 * c.powf(1.0 / 2.4) - 0.055
    };
    (s * 255.0).round() as u8
}

fn write_ply(
    w: &mut impl Write,
    mesh: &TriMesh,
    normals: Option<&[[f32; 3]]>,
    colors: &[[f32; 3]],
) -> std::io::Result<()> {
    let index = if i32::try_from(mesh.positions.len()).is_ok() {
        "int"
    } else {
        "uint"
    };
    let mut header = format!(
        "ply\nformat binary_little_endian 1.0\ncomment isosurface written by Isoscope\n\
         element vertex {}\nproperty float x\nproperty float y\nproperty float z\n",
        mesh.positions.len()
    );
    if normals.is_some() {
        header.push_str("property float nx\nproperty float ny\nproperty float nz\n");
    }
    if !colors.is_empty() {
        header.push_str("property uchar red\nproperty uchar green\nproperty uchar blue\n");
    }
    let _ = write!(
        header,
        "element face {}\nproperty list uchar {index} vertex_indices\nend_header\n",
        mesh.triangles.len()
    );
    w.write_all(header.as_bytes())?;
    let rgb: Vec<[u8; 3]> = colors.iter().map(|c| c.map(srgb_byte)).collect();
    for (v, p) in mesh.positions.iter().enumerate() {
        for x in p {
            w.write_all(&x.to_le_bytes())?;
        }
        if let Some(n) = normals {
            for x in n[v] {
                w.write_all(&x.to_le_bytes())?;
            }
        }
        if !rgb.is_empty() {
            w.write_all(&rgb[mesh.surfaces[v] as usize])?;
        }
    }
    for t in &mesh.triangles {
        w.write_all(&[3])?;
        for i in t {
            w.write_all(&i.to_le_bytes())?;
        }
    }
    Ok(())
}

fn write_stl(w: &mut impl Write, mesh: &TriMesh, path: &Path) -> Result<(), FormatError> {
    let io = |e: std::io::Error| FormatError::io(path, e);
    let count = u32::try_from(mesh.triangles.len()).map_err(|_| FormatError::BadOutput {
        path: path.to_path_buf(),
        reason: format!(
            "{} triangles exceed the {} a binary STL file counts",
            mesh.triangles.len(),
            u32::MAX
        ),
    })?;
    let mut header = [b' '; 80];
    let text = b"binary STL isosurface written by Isoscope";
    header[..text.len()].copy_from_slice(text);
    w.write_all(&header).map_err(io)?;
    w.write_all(&count.to_le_bytes()).map_err(io)?;
    let mut record = [0u8; 50];
    for (t, tri) in mesh.triangles.iter().enumerate() {
        let n = mesh
            .triangle_normal(t)
            .normalize_or_zero()
            .as_vec3()
            .to_array();
        let floats = n
            .iter()
            .chain(tri.iter().flat_map(|&v| &mesh.positions[v as usize]));
        for (k, x) in floats.enumerate() {
            record[4 * k..4 * k + 4].copy_from_slice(&x.to_le_bytes());
        }
        // Bytes 48..50: the attribute byte count, 0.
        w.write_all(&record).map_err(io)?;
    }
    Ok(())
}

fn write_obj(
    w: &mut impl Write,
    mesh: &TriMesh,
    normals: Option<&[[f32; 3]]>,
) -> std::io::Result<()> {
    writeln!(w, "# isosurface written by Isoscope")?;
    writeln!(
        w,
        "# {} vertices, {} triangles",
        mesh.positions.len(),
        mesh.triangles.len()
    )?;
    for p in &mesh.positions {
        writeln!(w, "v {} {} {}", p[0], p[1], p[2])?;
    }
    if let Some(n) = normals {
        for n in n {
            writeln!(w, "vn {} {} {}", n[0], n[1], n[2])?;
        }
    }
    // OBJ indices count from 1.
    for t in &mesh.triangles {
        let [a, b, c] = t.map(|v| u64::from(v) + 1);
        if normals.is_some() {
            writeln!(w, "f {a}//{a} {b}//{b} {c}//{c}")?;
        } else {
            writeln!(w, "f {a} {b} {c}")?;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two triangles of two surfaces (a unit square split on its diagonal).
    fn square() -> TriMesh {
        TriMesh {
            positions: vec![
                [0.0, 0.0, 0.0],
                [1.0, 0.0, 0.0],
                [1.0, 1.0, 0.0],
                [0.0, 1.0, 0.5],
            ],
            surfaces: vec![0, 0, 1, 1],
            triangles: vec![[0, 1, 2], [0, 2, 3]],
        }
    }

    fn f32_at(b: &[u8], at: usize) -> f32 {
        f32::from_le_bytes(b[at..at + 4].try_into().unwrap())
    }

    fn u32_at(b: &[u8], at: usize) -> u32 {
        u32::from_le_bytes(b[at..at + 4].try_into().unwrap())
    }

    #[test]
    fn ply_holds_positions_normals_colours_and_faces() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("m.ply");
        let mesh = square();
        let colors = [[1.0, 0.0, 0.0], [0.0, 0.5, 1.0]];
        let options = TriMeshOptions {
            normals: true,
            surface_colors: &colors,
        };
        assert_eq!(
            write_trimesh(&path, &mesh, &options, Replace::Refuse).unwrap(),
            TriMeshFormat::Ply
        );
        let bytes = std::fs::read(&path).unwrap();
        let end = b"end_header\n";
        let body = bytes.windows(end.len()).position(|w| w == end).unwrap() + end.len();
        let header = std::str::from_utf8(&bytes[..body]).unwrap();
        assert!(header.contains("format binary_little_endian 1.0"));
        assert!(header.contains("element vertex 4") && header.contains("element face 2"));
        assert!(header.contains("property float nz") && header.contains("property uchar red"));
        // Vertex records: 6 floats + 3 bytes.
        let stride = 27;
        let normals = mesh.vertex_normals();
        for v in 0..4 {
            let at = body + v * stride;
            for (a, (&p, &n)) in mesh.positions[v].iter().zip(&normals[v]).enumerate() {
                assert_eq!(f32_at(&bytes, at + 4 * a), p);
                assert_eq!(f32_at(&bytes, at + 12 + 4 * a), n);
            }
            let rgb = &bytes[at + 24..at + 27];
            let want = colors[mesh.surfaces[v] as usize].map(srgb_byte);
            assert_eq!(rgb, want);
        }
        let faces = body + 4 * stride;
        for (t, tri) in mesh.triangles.iter().enumerate() {
            let at = faces + t * 13;
            assert_eq!(bytes[at], 3);
            for (k, &corner) in tri.iter().enumerate() {
                assert_eq!(u32_at(&bytes, at + 1 + 4 * k), corner);
            }
        }
        assert_eq!(bytes.len(), faces + 2 * 13);
        // sRGB bytes of linear 0, 0.5 and 1.
        assert_eq!(
            [srgb_byte(0.0), srgb_byte(0.5), srgb_byte(1.0)],
            [0, 188, 255]
        );
    }

    #[test]
    fn stl_holds_unit_normals_and_corners() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("m.STL");
        let mesh = square();
        write_trimesh(&path, &mesh, &TriMeshOptions::default(), Replace::Refuse).unwrap();
        let bytes = std::fs::read(&path).unwrap();
        assert_eq!(u32_at(&bytes, 80), 2);
        assert_eq!(bytes.len(), 84 + 2 * 50);
        for (t, tri) in mesh.triangles.iter().enumerate() {
            let at = 84 + 50 * t;
            let n = mesh.triangle_normal(t).normalize();
            for a in 0..3 {
                assert!((f64::from(f32_at(&bytes, at + 4 * a)) - n[a]).abs() < 1e-6);
            }
            for (k, &v) in tri.iter().enumerate() {
                for a in 0..3 {
                    assert_eq!(
                        f32_at(&bytes, at + 12 + 12 * k + 4 * a),
                        mesh.positions[v as usize][a]
                    );
                }
            }
        }
    }

    #[test]
    fn obj_round_trips_as_text() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("m.obj");
        let mesh = square();
        write_trimesh(&path, &mesh, &TriMeshOptions::default(), Replace::Refuse).unwrap();
        let text = std::fs::read_to_string(&path).unwrap();
        let verts: Vec<[f32; 3]> = text
            .lines()
            .filter_map(|l| l.strip_prefix("v "))
            .map(|l| {
                let v: Vec<f32> = l.split(' ').map(|x| x.parse().unwrap()).collect();
                [v[0], v[1], v[2]]
            })
            .collect();
        let faces: Vec<[u32; 3]> = text
            .lines()
            .filter_map(|l| l.strip_prefix("f "))
            .map(|l| {
                let f: Vec<u32> = l
                    .split(' ')
                    .map(|x| x.parse::<u32>().unwrap() - 1)
                    .collect();
                [f[0], f[1], f[2]]
            })
            .collect();
        assert_eq!(verts, mesh.positions);
        assert_eq!(faces, mesh.triangles);
    }

    #[test]
    fn bad_outputs_are_refused_with_the_path() {
        let dir = tempfile::tempdir().unwrap();
        let mesh = square();
        let opts = TriMeshOptions::default();
        let bad = dir.path().join("m.xyz");
        let e = write_trimesh(&bad, &mesh, &opts, Replace::Refuse).unwrap_err();
        assert!(
            e.to_string().contains("m.xyz") && e.to_string().contains(".ply"),
            "{e}"
        );
        let existing = dir.path().join("e.stl");
        std::fs::write(&existing, b"keep").unwrap();
        let e = write_trimesh(&existing, &mesh, &opts, Replace::Refuse).unwrap_err();
        assert!(matches!(e, FormatError::OutputExists { .. }), "{e}");
        assert_eq!(std::fs::read(&existing).unwrap(), b"keep");
        write_trimesh(&existing, &mesh, &opts, Replace::Allow).unwrap();
        assert_eq!(std::fs::read(&existing).unwrap().len(), 84 + 100);
        let few = TriMeshOptions {
            normals: false,
            surface_colors: &[[1.0; 3]],
        };
        let e = write_trimesh(&dir.path().join("c.ply"), &mesh, &few, Replace::Refuse).unwrap_err();
        assert!(e.to_string().contains("surface 1 has no colour"), "{e}");
    }
}
