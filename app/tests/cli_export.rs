//! `isoscope export` end to end: the meshes against VTK's on the same inputs (files written
//! by VTK 9.7.2, `data-samples/vtk_reference/README.md`), exact geometric checks of the
//! written files, the time step and clip flags, and clear errors.

mod common;
use common::{fails, ok};

use std::path::{Path, PathBuf};

use glam::DVec3;

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

fn repo(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..").join(rel)
}

/// A binary little-endian PLY's positions and triangles (float x, y, z first; other vertex
/// properties of type float or uchar skipped; faces as `list uchar int|uint`).
fn read_ply(path: &Path) -> (Vec<DVec3>, Vec<[u32; 3]>) {
    let bytes = std::fs::read(path).unwrap();
    let end = b"end_header\n";
    let body = bytes.windows(end.len()).position(|w| w == end).unwrap() + end.len();
    let header = std::str::from_utf8(&bytes[..body]).unwrap();
    assert!(
        header.contains("format binary_little_endian 1.0"),
        "{header}"
    );
    let (mut nv, mut nf, mut stride, mut in_vertex) = (0, 0, 0, false);
    for line in header.lines() {
        let w: Vec<&str> = line.split_whitespace().collect();
        match w.as_slice() {
            ["element", "vertex", n] => (nv, in_vertex) = (n.parse().unwrap(), true),
            ["element", "face", n] => (nf, in_vertex) = (n.parse().unwrap(), false),
            ["property", "float", _] if in_vertex => stride += 4,
            ["property", "uchar", _] if in_vertex => stride += 1,
            ["property", "list", "uchar", "int" | "uint", _] => {}
            ["property", ..] => panic!("unexpected {line}"),
            _ => {}
        }
    }
    let f = |at: usize| f32::from_le_bytes(bytes[at..at + 4].try_into().unwrap());
    let positions = (0..nv)
        .map(|v| {
            let at = body + v * stride;
            DVec3::new(f(at).into(), f(at + 4).into(), f(at + 8).into())
        })
        .collect();
    let faces_at = body + nv * stride;
    let triangles = (0..nf)
        .map(|t| {
            let at = faces_at + 13 * t;
            assert_eq!(bytes[at], 3);
            std::array::from_fn(|k| {
                u32::from_le_bytes(bytes[at + 1 + 4 * k..at + 5 + 4 * k].try_into().unwrap())
            })
        })
        .collect();
    assert_eq!(bytes.len(), faces_at + 13 * nf);
    (positions, triangles)
}

fn area(p: &[DVec3], t: &[[u32; 3]]) -> f64 {
    t.iter()
        .map(|t| {
            let [a, b, c] = t.map(|v| p[v as usize]);
            0.5 * (b - a).cross(c - a).length()
        })
        .sum()
}

/// `(vertices, triangles, area)` from the line `export` prints.
fn printed(stdout: &str) -> (usize, usize, f64) {
    let w: Vec<&str> = stdout.split_whitespace().collect();
    let num = |i: usize| w[i].trim_end_matches(',');
    assert_eq!(
        (w[1], w[3], w[4]),
        ("vertices,", "triangles,", "area"),
        "{stdout}"
    );
    (
        num(0).parse().unwrap(),
        num(2).parse().unwrap(),
        num(5).parse().unwrap(),
    )
}

fn reference(name: &str) -> serde_json::Value {
    let text =
        std::fs::read_to_string(repo(&format!("data-samples/vtk_reference/{name}"))).unwrap();
    serde_json::from_str(&text).unwrap()
}

/// Every vertex of `theirs` has one of `ours` within `tol` (and the counts agree): the same
/// edge crossings, whatever the triangulation.
fn same_vertices(ours: &[DVec3], theirs: &[DVec3], tol: f64) {
    assert_eq!(ours.len(), theirs.len());
    for p in theirs {
        let d = ours
            .iter()
            .map(|q| q.distance(*p))
            .fold(f64::INFINITY, f64::min);
        assert!(d < tol, "VTK vertex {p} is {d} from every vertex of ours");
    }
}

/// Marching cubes on the committed torus: the vertices are VTK's (one per crossed edge, the
/// same interpolation), and so is the triangle count. The case tables differ (ours is
/// generated from the faces, VTK's is its own), but the torus has no ambiguous face, so the
/// cells' polygons are the same; only the diagonals splitting a polygon into triangles may
/// differ, which changes the area by 4e-5 (bound: 1e-4). On data with ambiguous faces the
/// tables part ways: Marschner–Lobb (`ml41_u8.nrrd` at 128.5) gives VTK's 20960 triangles
/// and 10729 vertices too, but 1 % less area, as VTK joins some ambiguous faces otherwise.
#[test]
fn marching_cubes_matches_vtk_on_the_torus() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("torus.ply");
    let input = repo("data-samples/samples/torus32_u8.nrrd");
    let stdout = ok(&["export", s(&input), "--iso", "32.5", "-o", s(&out)]);
    let r = reference("torus32_u8_iso32.5.json");
    let (vertices, triangles, printed_area) = printed(&stdout);
    let (p, t) = read_ply(&out);
    assert_eq!((vertices, triangles), (p.len(), t.len()));
    assert!((printed_area - area(&p, &t)).abs() < 1e-9 * printed_area);
    assert_eq!(t.len() as u64, r["triangles"].as_u64().unwrap());
    let vtk_area = r["area"].as_f64().unwrap();
    assert!(
        (area(&p, &t) - vtk_area).abs() < 1e-4 * vtk_area,
        "{} vs VTK {vtk_area}",
        area(&p, &t)
    );
    let (vtk_p, _) = read_ply(&repo("data-samples/vtk_reference/torus32_u8_iso32.5.ply"));
    same_vertices(&p, &vtk_p, 1e-6);
}

/// Marching tetrahedra on the committed tet mesh: isopolygons of a linear field in a tet are
/// planar, so the triangles cover the same surface as VTK's whatever the quad diagonal: same
/// counts, the same vertices, and the area to rounding.
#[test]
fn marching_tetrahedra_match_vtk_on_the_ball() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("ball.ply");
    let input = repo("data-samples/vtk_reference/ball_tets.vtu");
    ok(&["export", s(&input), "--iso", "0.62", "-o", s(&out)]);
    let r = reference("ball_tets_iso0.62.json");
    let (p, t) = read_ply(&out);
    assert_eq!(t.len() as u64, r["triangles"].as_u64().unwrap());
    assert_eq!(p.len() as u64, r["vertices"].as_u64().unwrap());
    let vtk_area = r["area"].as_f64().unwrap();
    assert!((area(&p, &t) - vtk_area).abs() < 1e-5 * vtk_area);
    let (vtk_p, _) = read_ply(&repo("data-samples/vtk_reference/ball_tets_iso0.62.ply"));
    same_vertices(&p, &vtk_p, 1e-6);
}

/// STL and OBJ hold the same triangles as the PLY; clip flags cut them; the time step flag
/// exports that step (the same mesh as the step's own file).
#[test]
fn formats_clips_and_steps_agree() {
    let dir = tempfile::tempdir().unwrap();
    let input = repo("data-samples/samples/sphere32_f32.nrrd");
    let ply = dir.path().join("s.ply");
    let stl = dir.path().join("s.stl");
    let obj = dir.path().join("s.obj");
    let mut counts = Vec::new();
    for out in [&ply, &stl, &obj] {
        counts.push(printed(&ok(&[
            "export",
            s(&input),
            "--iso",
            "0.6",
            "-o",
            s(out),
            "--normals",
        ])));
    }
    assert!(counts.windows(2).all(|w| w[0] == w[1]), "{counts:?}");
    let (p, t) = read_ply(&ply);
    let stl_bytes = std::fs::read(&stl).unwrap();
    assert_eq!(
        u32::from_le_bytes(stl_bytes[80..84].try_into().unwrap()) as usize,
        t.len()
    );
    let obj_faces = std::fs::read_to_string(&obj)
        .unwrap()
        .lines()
        .filter(|l| l.starts_with("f "))
        .count();
    assert_eq!(obj_faces, t.len());
    // The sphere of radius 0.6 around (0.1, -0.05, 0.03): on the surface, area near 4πr².
    let c = DVec3::new(0.1, -0.05, 0.03);
    for q in &p {
        assert!((q.distance(c) - 0.6).abs() < 0.01);
    }
    let exact = 4.0 * std::f64::consts::PI * 0.36;
    assert!((area(&p, &t) - exact).abs() < 0.01 * exact);

    // Keep x <= 0.1 (through the centre): half the area, nothing beyond the plane.
    let half = dir.path().join("half.ply");
    ok(&[
        "export",
        s(&input),
        "--iso",
        "0.6",
        "--clip-plane",
        "1,0,0,0.1",
        "-o",
        s(&half),
    ]);
    let (hp, ht) = read_ply(&half);
    assert!(hp.iter().all(|q| q.x <= 0.1 + 1e-6));
    assert!((area(&hp, &ht) / area(&p, &t) - 0.5).abs() < 0.01);

    let pattern = repo("data-samples/samples/blobs24_%03d.nrrd");
    let step = dir.path().join("step.ply");
    let direct = dir.path().join("direct.ply");
    let a = printed(&ok(&[
        "export",
        s(&pattern),
        "--step",
        "2",
        "--iso",
        "0.5",
        "-o",
        s(&step),
    ]));
    let b = printed(&ok(&[
        "export",
        s(&repo("data-samples/samples/blobs24_002.nrrd")),
        "--iso",
        "0.5",
        "-o",
        s(&direct),
    ]));
    assert_eq!(a, b);
    assert_eq!(
        std::fs::read(&step).unwrap(),
        std::fs::read(&direct).unwrap()
    );
}

#[test]
fn bad_outputs_and_inputs_are_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    let input = repo("data-samples/samples/torus32_u8.nrrd");
    let e = fails(&[
        "export",
        s(&input),
        "--iso",
        "32",
        "-o",
        s(&dir.path().join("t.vrml")),
    ]);
    assert!(e.contains("t.vrml") && e.contains(".ply"), "{e}");
    let out = dir.path().join("t.stl");
    std::fs::write(&out, b"keep").unwrap();
    let e = fails(&["export", s(&input), "--iso", "32", "-o", s(&out)]);
    assert!(e.contains("already exists"), "{e}");
    assert_eq!(std::fs::read(&out).unwrap(), b"keep");
    ok(&["export", s(&input), "--iso", "32", "-o", s(&out), "--force"]);
    assert!(std::fs::read(&out).unwrap().len() > 84);
    // The input itself is never an output.
    let copy = dir.path().join("torus.nrrd");
    std::fs::copy(&input, &copy).unwrap();
    let alias = dir.path().join("alias.stl");
    std::os::unix::fs::symlink(&copy, &alias).unwrap();
    let e = fails(&[
        "export",
        s(&copy),
        "--iso",
        "32",
        "-o",
        s(&alias),
        "--force",
    ]);
    assert!(e.contains("is the input file"), "{e}");
    let e = fails(&[
        "export",
        s(&dir.path().join("big.isot")),
        "--iso",
        "1",
        "-o",
        s(&out),
    ]);
    assert!(e.contains("out-of-core"), "{e}");
}
