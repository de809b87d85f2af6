//! Mesh readers against files written by VTK 9.7, Gmsh 4.8 and TetGen 1.5 (see
//! `tests/data/mesh/README.md`). The truth is the generation script's analytic mesh, rebuilt
//! here: points, cells (split with `volume_core::tet`'s splits), fields
//! `temperature = x + 2y + 3z`, `pressure = x*y - z`, `id = point index`.

use std::path::{Path, PathBuf};

use formats::mesh::{self, LoadedMesh, MeshFormat};
use volume_core::tet::{split_hex, split_pyramid, split_wedge};

fn data(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/mesh")
        .join(name)
}

/// `mixed_points()` of make_meshes.py.
fn mixed_points() -> Vec<[f64; 3]> {
    let mut p = Vec::new();
    for k in 0..2 {
        for j in 0..3 {
            for i in 0..3 {
                p.push([0.5 * f64::from(i), 0.25 * f64::from(j), f64::from(k)]);
            }
        }
    }
    p.extend([
        [0.25, 0.125, 1.5],
        [0.5, 0.0, 1.5],
        [1.0, 0.0, 1.5],
        [1.0, 0.25, 1.5],
        [0.1, 0.4, 1.6],
    ]);
    p
}

fn g(i: u32, j: u32, k: u32) -> u32 {
    i + 3 * j + 9 * k
}

/// The expected tets: `mixed_cells()` of make_meshes.py, split.
fn expected_tets() -> Vec<[u32; 4]> {
    let mut t = Vec::new();
    for j in 0..2 {
        for i in 0..2 {
            t.extend(split_hex([
                g(i, j, 0),
                g(i + 1, j, 0),
                g(i + 1, j + 1, 0),
                g(i, j + 1, 0),
                g(i, j, 1),
                g(i + 1, j, 1),
                g(i + 1, j + 1, 1),
                g(i, j + 1, 1),
            ]));
        }
    }
    t.extend(split_pyramid([
        g(0, 0, 1),
        g(1, 0, 1),
        g(1, 1, 1),
        g(0, 1, 1),
        18,
    ]));
    t.extend(split_wedge([
        g(1, 0, 1),
        g(2, 0, 1),
        g(2, 1, 1),
        19,
        20,
        21,
    ]));
    t.push([g(0, 1, 1), g(1, 1, 1), g(0, 2, 1), 22]);
    t
}

fn signed_volume(p: &[[f32; 3]], t: [u32; 4]) -> f64 {
    let q = |i: usize| p[t[i] as usize].map(f64::from);
    let (a, b, c, d) = (q(0), q(1), q(2), q(3));
    let u = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
    let v = [c[0] - a[0], c[1] - a[1], c[2] - a[2]];
    let w = [d[0] - a[0], d[1] - a[1], d[2] - a[2]];
    (u[0] * (v[1] * w[2] - v[2] * w[1]) - u[1] * (v[0] * w[2] - v[2] * w[0])
        + u[2] * (v[0] * w[1] - v[1] * w[0]))
        / 6.0
}

/// Checks a reading of the mixed mesh against the truth; `with_id`: the file has the int
/// `id` array (VTK files); `velocity`: the 3-component array is present (listed, skipped).
fn check_mixed(m: &LoadedMesh, with_id: bool, velocity: bool, sorted_ok: bool) {
    let truth = mixed_points();
    assert_eq!(m.mesh.points.len(), truth.len());
    for (a, b) in m.mesh.points.iter().zip(&truth) {
        for c in 0..3 {
            assert_eq!(a[c], b[c] as f32, "point {a:?} vs {b:?}");
        }
    }
    // Gmsh groups elements by entity and type: compare as sorted lists there.
    let mut got = m.mesh.tets.clone();
    let mut want = expected_tets();
    if !sorted_ok {
        assert_eq!(got, want);
    }
    got.sort_unstable();
    want.sort_unstable();
    assert_eq!(got, want);
    assert_eq!(m.source_cells, 10);
    // One triangle, one vertex, one line skipped.
    assert_eq!(m.skipped.total(), 3, "{:?}", m.skipped);
    assert_eq!(
        (m.skipped.count(5), m.skipped.count(1), m.skipped.count(3)),
        (1, 1, 1)
    );
    assert!(m.skipped_warning().unwrap().contains("triangle"));
    // Volumes: the split cells fill exactly the cells (no gaps, no overlaps):
    // 4 hexes of 0.125, pyramid 0.125 * 0.5 / 3, wedge 0.0625 * 0.5, tet 0.0625 * 0.6 / 3.
    let vol: f64 = m
        .mesh
        .tets
        .iter()
        .map(|&t| signed_volume(&m.mesh.points, t).abs())
        .sum();
    let want = 0.5 + 0.125 * 0.5 / 3.0 + 0.0625 * 0.5 + 0.0625 * 0.6 / 3.0;
    assert!((vol - want).abs() < 1e-6, "{vol} vs {want}");
    let t = m.mesh.require_field("temperature").unwrap();
    let p = m.mesh.require_field("pressure").unwrap();
    for (i, q) in truth.iter().enumerate() {
        let tt = q[0] + 2.0 * q[1] + 3.0 * q[2];
        let pp = q[0] * q[1] - q[2];
        assert!(
            (f64::from(t.values[i]) - tt).abs() < 1e-5,
            "temperature[{i}] {} vs {tt}",
            t.values[i]
        );
        assert!(
            (f64::from(p.values[i]) - pp).abs() < 1e-5,
            "pressure[{i}] {} vs {pp}",
            p.values[i]
        );
    }
    if with_id {
        let id = m.mesh.require_field("id").unwrap();
        assert!(id.values.iter().enumerate().all(|(i, &v)| v == i as f32));
    }
    let mut names = m.array_names();
    names.sort_unstable();
    let want: &[&str] = if with_id {
        &["id", "pressure", "temperature"]
    } else {
        &["pressure", "temperature"]
    };
    assert_eq!(names, want);
    if velocity {
        assert_eq!(
            m.skipped_arrays,
            vec![("velocity".to_owned(), "3 components".to_owned())]
        );
    }
    assert!(m.mesh.require_field("nope").is_err());
}

#[test]
fn vtk_legacy_42_and_51_ascii_and_binary() {
    for name in [
        "mixed_v42_ascii.vtk",
        "mixed_v42_binary.vtk",
        "mixed_v51_ascii.vtk",
        "mixed_v51_binary.vtk",
    ] {
        let m = mesh::read_mesh(&data(name)).unwrap_or_else(|e| panic!("{name}: {e}"));
        check_mixed(&m, true, true, false);
    }
}

#[test]
fn vtu_every_encoding() {
    for name in [
        "mixed_ascii.vtu",
        "mixed_base64.vtu",
        "mixed_base64_zlib.vtu",
        "mixed_base64_zlib_u64.vtu",
        "mixed_appended_raw.vtu",
        "mixed_appended_raw_zlib_u64.vtu",
        "mixed_appended_base64.vtu",
        "mixed_appended_base64_zlib.vtu",
    ] {
        let m = mesh::read_mesh(&data(name)).unwrap_or_else(|e| panic!("{name}: {e}"));
        check_mixed(&m, true, true, false);
    }
}

#[test]
fn gmsh_22_and_41_ascii_and_binary() {
    for name in [
        "mixed_msh22_ascii.msh",
        "mixed_msh22_binary.msh",
        "mixed_msh41_ascii.msh",
        "mixed_msh41_binary.msh",
    ] {
        let m = mesh::read_mesh(&data(name)).unwrap_or_else(|e| panic!("{name}: {e}"));
        check_mixed(&m, false, false, true);
    }
}

/// Gmsh's own unit-box tet mesh (with $Entities, boundary triangles, lines, points): the
/// four encodings agree and the tets fill the unit cube.
#[test]
fn gmsh_box_volume_is_one() {
    let first = mesh::read_mesh(&data("box_msh22_ascii.msh")).unwrap();
    assert!(first.mesh.tets.len() > 20);
    let vol: f64 = first
        .mesh
        .tets
        .iter()
        .map(|&t| signed_volume(&first.mesh.points, t).abs())
        .sum();
    assert!((vol - 1.0).abs() < 1e-5, "{vol}");
    assert!(
        first.skipped.count(5) > 0,
        "boundary triangles are skipped: {:?}",
        first.skipped
    );
    for name in [
        "box_msh22_binary.msh",
        "box_msh41_ascii.msh",
        "box_msh41_binary.msh",
    ] {
        let m = mesh::read_mesh(&data(name)).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(m.mesh.points, first.mesh.points, "{name}");
        assert_eq!(m.mesh.tets, first.mesh.tets, "{name}");
    }
}

/// TetGen's mesh of the unit cube (`tetgen -pqa0.05 box.poly`): volume 1, corner attributes
/// `x + 2y + 3z` as given in the .poly, 0 at Steiner points; 0- and 1-based numbering agree.
#[test]
fn tetgen_box() {
    for name in ["tetgen_box.1.node", "tetgen_box.1.ele", "tetgen_box0.1.ele"] {
        let m = mesh::read_mesh(&data(name)).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!((m.mesh.points.len(), m.mesh.tets.len()), (50, 68), "{name}");
        let vol: f64 = m
            .mesh
            .tets
            .iter()
            .map(|&t| signed_volume(&m.mesh.points, t).abs())
            .sum();
        assert!((vol - 1.0).abs() < 1e-6, "{name}: {vol}");
        let a = m.mesh.require_field("attribute_0").unwrap();
        for (p, &v) in m.mesh.points.iter().zip(&a.values) {
            let corner = p.iter().all(|&c| c == 0.0 || c == 1.0);
            let want = if corner {
                p[0] + 2.0 * p[1] + 3.0 * p[2]
            } else {
                0.0
            };
            assert_eq!(v, want, "{name}: point {p:?}");
        }
    }
    let a = mesh::read_mesh(&data("tetgen_box.1.node")).unwrap();
    let b = mesh::read_mesh(&data("tetgen_box0.1.node")).unwrap();
    assert_eq!(a.mesh, b.mesh);
}

#[test]
fn pvd_series_shares_topology_and_moves() {
    let s = mesh::read_pvd(&data("series.pvd")).unwrap();
    assert_eq!(s.len(), 3);
    assert_eq!(
        s.steps.iter().map(|st| st.time).collect::<Vec<_>>(),
        vec![0.0, 0.5, 1.0]
    );
    let first = s.load_step(0).unwrap();
    check_mixed(&first, true, true, false);
    for i in 0..3 {
        let d = s.load_step_data(i, &first.mesh).unwrap();
        assert_eq!(d.time, 0.5 * i as f64);
        let t = d.fields.iter().find(|f| f.name == "temperature").unwrap();
        let truth = mixed_points();
        let pos = d.positions.as_ref().unwrap_or(&first.mesh.points);
        assert_eq!(d.positions.is_some(), i > 0, "step {i} moved iff i > 0");
        for (k, q) in truth.iter().enumerate() {
            let x = q[0] + 0.1 * i as f64;
            assert!((f64::from(pos[k][0]) - x).abs() < 1e-6);
            let tt = x + 2.0 * q[1] + 3.0 * q[2] + i as f64;
            assert!(
                (f64::from(t.values[k]) - tt).abs() < 1e-5,
                "step {i} point {k}"
            );
        }
    }
    // The numbered-file form of the same series.
    let n = mesh::MeshSeries::numbered(&data("series/step_001.vtu")).unwrap();
    assert_eq!(n.len(), 3);
    assert_eq!(n.steps[2].time, 2.0);
    assert_eq!(n.load_step(2).unwrap().mesh, s.load_step(2).unwrap().mesh);
    // A step of another topology is refused, naming the step.
    let other = mesh::read_mesh(&data("tetgen_box.1.node")).unwrap();
    let e = s.load_step_data(1, &other.mesh).unwrap_err();
    assert!(
        matches!(e, mesh::MeshError::Topology { step: 1, .. }),
        "{e}"
    );
}

#[test]
fn format_by_extension() {
    assert_eq!(
        MeshFormat::from_path(Path::new("a/b.VTU")),
        Some(MeshFormat::Vtu)
    );
    assert_eq!(
        MeshFormat::from_path(Path::new("b.ele")),
        Some(MeshFormat::TetGen)
    );
    assert!(!mesh::is_mesh_path(Path::new("b.nrrd")));
    let e = mesh::read_mesh(Path::new("x.nrrd")).unwrap_err();
    assert!(matches!(e, mesh::MeshError::UnknownFormat { .. }));
}

/// Writers: a mesh written as .vtu and as legacy ASCII/binary reads back identically
/// (including awkward field names and non-round values).
#[test]
fn writers_round_trip() {
    use volume_core::tet::{PointField, TetMesh};
    let src = mesh::read_mesh(&data("mixed_v51_binary.vtk")).unwrap().mesh;
    let mut fields = src.fields.clone();
    fields.push(PointField::new(
        "odd name <&> \"x\"",
        (0..src.points.len())
            .map(|i| (i as f32).sin() * 1e-3 + 1.0 / 3.0)
            .collect(),
    ));
    let points: Vec<[f32; 3]> = src
        .points
        .iter()
        .map(|p| [p[0] + 0.1, p[1] / 3.0, -p[2]])
        .collect();
    let m = TetMesh::new(points, src.tets.clone(), fields).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let a = dir.path().join("a.vtu");
    mesh::write_vtu(&a, &m, formats::output::Replace::Refuse).unwrap();
    assert_eq!(mesh::read_mesh(&a).unwrap().mesh, m);
    for (name, enc) in [
        ("b.vtk", mesh::LegacyEncoding::Ascii),
        ("c.vtk", mesh::LegacyEncoding::Binary),
    ] {
        let p = dir.path().join(name);
        mesh::write_vtk_legacy(&p, &m, enc, formats::output::Replace::Refuse).unwrap();
        let back = mesh::read_mesh(&p).unwrap();
        assert_eq!(back.mesh, m, "{name}");
        assert_eq!(back.skipped.total(), 0);
    }
}
