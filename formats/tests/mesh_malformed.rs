//! Malformed mesh files: each case must fail with its specific error (variant and a
//! distinctive part of the message), never panic, never allocate what the header claims.

use std::path::Path;

use formats::mesh::{self, LoadedMesh, MeshError, gmsh, tetgen, vtk_legacy, vtu};
use volume_core::math::rng::Rng;

#[derive(Clone, Copy)]
enum Kind {
    Vtk,
    Vtu,
    Msh,
    /// `.node` text, then `\0`, then `.ele` text.
    TetGen,
}

fn read(kind: Kind, bytes: &[u8]) -> Result<LoadedMesh, MeshError> {
    let raw = match kind {
        Kind::Vtk => vtk_legacy::parse(Path::new("bad.vtk"), bytes)?,
        Kind::Vtu => vtu::parse(Path::new("bad.vtu"), bytes)?,
        Kind::Msh => gmsh::parse(Path::new("bad.msh"), bytes)?,
        Kind::TetGen => {
            let split = bytes.iter().position(|&b| b == 0).unwrap();
            tetgen::parse(
                Path::new("bad.node"),
                &bytes[..split],
                Path::new("bad.ele"),
                &bytes[split + 1..],
            )?
        }
    };
    raw.into_tet_mesh(Path::new("bad.mesh"))
}

const VTK_HEAD: &str = "# vtk DataFile Version 4.2\nt\nASCII\nDATASET UNSTRUCTURED_GRID\n";
const PTS4: &str = "POINTS 4 float\n0 0 0 1 0 0 0 1 0 0 0 1\n";

fn vtk(body: &str) -> Vec<u8> {
    format!("{VTK_HEAD}{body}").into_bytes()
}

fn vtu_doc(attrs: &str, piece: &str, body: &str) -> Vec<u8> {
    format!(
        "<?xml version=\"1.0\"?>\n<VTKFile type=\"UnstructuredGrid\" version=\"1.0\" byte_order=\"LittleEndian\"{attrs}>\n<UnstructuredGrid>\n<Piece {piece}>\n{body}\n</Piece>\n</UnstructuredGrid>\n</VTKFile>\n"
    )
    .into_bytes()
}

const VTU_POINTS: &str = "<Points><DataArray type=\"Float32\" NumberOfComponents=\"3\" format=\"ascii\">0 0 0 1 0 0 0 1 0 0 0 1</DataArray></Points>";

fn vtu_cells(conn: &str) -> String {
    format!(
        "{VTU_POINTS}<Cells><DataArray type=\"Int32\" Name=\"connectivity\" format=\"ascii\">{conn}</DataArray><DataArray type=\"Int32\" Name=\"offsets\" format=\"ascii\">4</DataArray><DataArray type=\"UInt8\" Name=\"types\" format=\"ascii\">10</DataArray></Cells>"
    )
}

const MSH_HEAD: &str = "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n";
const MSH_NODES: &str = "$Nodes\n4\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1\n$EndNodes\n";

fn parse_at(line: usize, needle: &'static str) -> impl Fn(&MeshError) -> bool {
    move |e| matches!(e, MeshError::Parse { line: l, reason, .. } if *l == line && reason.contains(needle))
}

/// (name, parser, bytes, expected error).
type Case = (&'static str, Kind, Vec<u8>, Box<dyn Fn(&MeshError) -> bool>);

#[test]
fn malformed_files_give_specific_errors() {
    // A one-tet inline vtu of the given binary payload for "connectivity" (4 Int32s, header UInt32).
    let conn_b64 = |payload: &str| {
        vtu_doc(
            "",
            "NumberOfPoints=\"4\" NumberOfCells=\"1\"",
            &format!(
                "{VTU_POINTS}<Cells><DataArray type=\"Int32\" Name=\"connectivity\" format=\"binary\">{payload}</DataArray><DataArray type=\"Int32\" Name=\"offsets\" format=\"ascii\">4</DataArray><DataArray type=\"UInt8\" Name=\"types\" format=\"ascii\">10</DataArray></Cells>"
            ),
        )
    };
    let cases: Vec<Case> = vec![
        ("vtk: not a vtk file", Kind::Vtk, b"hello\n".to_vec(), Box::new(parse_at(1, "not a legacy VTK file"))),
        ("vtk: version 6", Kind::Vtk, b"# vtk DataFile Version 6.0\nt\nASCII\n".to_vec(),
            Box::new(|e| matches!(e, MeshError::Unsupported { what, .. } if what.contains("version 6.0")))),
        ("vtk: neither ASCII nor BINARY", Kind::Vtk, b"# vtk DataFile Version 4.2\nt\nTEXT\n".to_vec(),
            Box::new(|e| matches!(e, MeshError::Parse { reason, .. } if reason.contains("ASCII or BINARY")))),
        ("vtk: structured points", Kind::Vtk, b"# vtk DataFile Version 4.2\nt\nASCII\nDATASET STRUCTURED_POINTS\n".to_vec(),
            Box::new(|e| matches!(e, MeshError::Unsupported { what, .. } if what.contains("STRUCTURED_POINTS")))),
        ("vtk: point count lies", Kind::Vtk, vtk("POINTS 1000000000 float\n0 0 0\n"),
            Box::new(|e| matches!(e, MeshError::TooShort { what, .. } if what.contains("POINTS")))),
        ("vtk: non-number coordinate", Kind::Vtk, vtk("POINTS 2 float\n0 0 0\n1 abc 0\n"),
            Box::new(parse_at(7, "value #4 \"abc\" is not a number"))),
        ("vtk: out-of-range index", Kind::Vtk, vtk(&format!("{PTS4}CELLS 2 10\n4 0 1 2 3\n4 0 1 2 9\nCELL_TYPES 2\n10\n10\n")),
            Box::new(|e| matches!(e, MeshError::BadCell { cell: 1, reason, .. } if reason.contains("point index 9 is out of range")))),
        ("vtk: negative index", Kind::Vtk, vtk(&format!("{PTS4}CELLS 1 5\n4 0 -1 2 3\nCELL_TYPES 1\n10\n")),
            Box::new(|e| matches!(e, MeshError::BadCell { cell: 0, reason, .. } if reason.contains("negative point index -1")))),
        ("vtk: CELL_TYPES count differs", Kind::Vtk, vtk(&format!("{PTS4}CELLS 1 5\n4 0 1 2 3\nCELL_TYPES 2\n10\n10\n")),
            Box::new(|e| matches!(e, MeshError::Parse { reason, .. } if reason.contains("CELL_TYPES lists 2 cells but CELLS has 1")))),
        ("vtk: CELLS without CELL_TYPES", Kind::Vtk, vtk(&format!("{PTS4}CELLS 1 5\n4 0 1 2 3\n")),
            Box::new(|e| matches!(e, MeshError::Parse { reason, .. } if reason.contains("CELLS without CELL_TYPES")))),
        ("vtk: hexahedron with 7 points", Kind::Vtk, vtk(&format!("{PTS4}CELLS 1 8\n7 0 1 2 3 0 1 2\nCELL_TYPES 1\n12\n")),
            Box::new(|e| matches!(e, MeshError::BadCell { cell: 0, reason, .. } if reason.contains("needs 8 points, has 7")))),
        ("vtk: cell runs past CELLS list", Kind::Vtk, vtk(&format!("{PTS4}CELLS 1 5\n9 0 1 2 3\nCELL_TYPES 1\n10\n")),
            Box::new(|e| matches!(e, MeshError::BadCell { cell: 0, reason, .. } if reason.contains("runs past")))),
        ("vtk 5.1: decreasing offsets", Kind::Vtk,
            format!("# vtk DataFile Version 5.1\nt\nASCII\nDATASET UNSTRUCTURED_GRID\n{PTS4}CELLS 3 4\nOFFSETS vtktypeint64\n0 4 2\nCONNECTIVITY vtktypeint64\n0 1 2 3\nCELL_TYPES 2\n10\n10\n").into_bytes(),
            Box::new(|e| matches!(e, MeshError::BadCell { cell: 1, reason, .. } if reason.contains("decreasing")))),
        ("vtk 5.1: last offset differs", Kind::Vtk,
            format!("# vtk DataFile Version 5.1\nt\nASCII\nDATASET UNSTRUCTURED_GRID\n{PTS4}CELLS 2 5\nOFFSETS vtktypeint64\n0 4\nCONNECTIVITY vtktypeint64\n0 1 2 3 3\nCELL_TYPES 1\n10\n").into_bytes(),
            Box::new(|e| matches!(e, MeshError::Parse { reason, .. } if reason.contains("last offset 4 differs")))),
        ("vtk: POINT_DATA count differs", Kind::Vtk, vtk(&format!("{PTS4}CELLS 1 5\n4 0 1 2 3\nCELL_TYPES 1\n10\nPOINT_DATA 3\n")),
            Box::new(|e| matches!(e, MeshError::Parse { reason, .. } if reason.contains("POINT_DATA 3 but the file has 4 points")))),
        ("vtk: binary points truncated", Kind::Vtk,
            [b"# vtk DataFile Version 4.2\nt\nBINARY\nDATASET UNSTRUCTURED_GRID\nPOINTS 4 float\n".as_slice(), &[0u8; 20]].concat(),
            Box::new(|e| matches!(e, MeshError::TooShort { needed: 48, available: 20, .. }))),
        ("vtk: FIELD array of wrong length", Kind::Vtk,
            vtk(&format!("{PTS4}CELLS 1 5\n4 0 1 2 3\nCELL_TYPES 1\n10\nPOINT_DATA 4\nFIELD f 1\nheat 1 3 float\n1 2 3\n")),
            Box::new(|e| matches!(e, MeshError::BadArray { name, reason, .. } if name == "heat" && reason.contains("3 tuples")))),
        ("vtk: unknown keyword", Kind::Vtk, vtk(&format!("{PTS4}SPLINES 3\n")), Box::new(parse_at(7, "unknown keyword \"SPLINES\""))),
        ("vtk: unknown data type", Kind::Vtk, vtk("POINTS 1 quaternion\n0 0 0\n"),
            Box::new(|e| matches!(e, MeshError::Parse { reason, .. } if reason.contains("unknown data type \"quaternion\"")))),
        ("vtk: only triangles", Kind::Vtk, vtk(&format!("{PTS4}CELLS 1 4\n3 0 1 2\nCELL_TYPES 1\n5\n")),
            Box::new(|e| matches!(e, MeshError::Mesh { source: volume_core::tet::TetError::Empty, .. }))),
        ("vtu: mismatched XML tags", Kind::Vtu, b"<VTKFile type=\"UnstructuredGrid\"><UnstructuredGrid></Piece></VTKFile>".to_vec(),
            Box::new(|e| matches!(e, MeshError::Parse { reason, .. } if reason.contains("XML error")))),
        ("vtu: PolyData", Kind::Vtu, b"<VTKFile type=\"PolyData\"></VTKFile>".to_vec(),
            Box::new(|e| matches!(e, MeshError::Unsupported { what, .. } if what.contains("PolyData")))),
        ("vtu: LZMA compressor", Kind::Vtu, vtu_doc(" compressor=\"vtkLZMADataCompressor\"", "NumberOfPoints=\"4\" NumberOfCells=\"1\"", &vtu_cells("0 1 2 3")),
            Box::new(|e| matches!(e, MeshError::Unsupported { what, .. } if what.contains("vtkLZMADataCompressor")))),
        ("vtu: out-of-range connectivity", Kind::Vtu, vtu_doc("", "NumberOfPoints=\"4\" NumberOfCells=\"1\"", &vtu_cells("0 1 2 4")),
            Box::new(|e| matches!(e, MeshError::BadCell { cell: 0, reason, .. } if reason.contains("point index 4 is out of range")))),
        ("vtu: too few ascii values", Kind::Vtu, vtu_doc("", "NumberOfPoints=\"4\" NumberOfCells=\"1\"", &vtu_cells("0 1 2")),
            Box::new(|e| matches!(e, MeshError::BadArray { name, reason, .. } if name == "connectivity" && reason.contains("3 values, expected 4")))),
        ("vtu: NumberOfPoints lies", Kind::Vtu, vtu_doc("", "NumberOfPoints=\"99999999999\" NumberOfCells=\"1\"", &vtu_cells("0 1 2 3")),
            Box::new(|e| matches!(e, MeshError::TooShort { what, .. } if what.contains("NumberOfPoints")))),
        ("vtu: invalid base64", Kind::Vtu, conn_b64("EAAAAA!!!AAAA"),
            Box::new(|e| matches!(e, MeshError::BadArray { name, reason, .. } if name == "connectivity" && reason.contains("base64")))),
        // Header says 12 bytes, 4 Int32 need 16: base64 of [12u32, 0, 1, 2].
        ("vtu: binary header size wrong", Kind::Vtu, conn_b64("DAAAAAAAAAABAAAAAgAAAA=="),
            Box::new(|e| matches!(e, MeshError::BadArray { reason, .. } if reason.contains("header says 12 bytes, expected 16")))),
        ("vtu: appended offset past the end", Kind::Vtu,
            b"<VTKFile type=\"UnstructuredGrid\" header_type=\"UInt32\"><UnstructuredGrid><Piece NumberOfPoints=\"1\" NumberOfCells=\"0\"><Points><DataArray type=\"Float32\" NumberOfComponents=\"3\" format=\"appended\" offset=\"5000\"/></Points></Piece></UnstructuredGrid><AppendedData encoding=\"raw\">_\x0c\x00\x00\x00</AppendedData></VTKFile>".to_vec(),
            Box::new(|e| matches!(e, MeshError::BadArray { reason, .. } if reason.contains("offset 5000 is past the end")))),
        ("vtu: corrupt zlib block", Kind::Vtu,
            [b"<VTKFile type=\"UnstructuredGrid\" header_type=\"UInt32\" compressor=\"vtkZLibDataCompressor\"><UnstructuredGrid><Piece NumberOfPoints=\"1\" NumberOfCells=\"0\"><Points><DataArray type=\"Float32\" NumberOfComponents=\"3\" format=\"appended\" offset=\"0\"/></Points></Piece></UnstructuredGrid><AppendedData encoding=\"raw\">_".as_slice(),
             &[1, 0, 0, 0, 12, 0, 0, 0, 0, 0, 0, 0, 6, 0, 0, 0], b"garbag", b"</AppendedData></VTKFile>"].concat(),
            Box::new(|e| matches!(e, MeshError::BadArray { reason, .. } if reason.contains("zlib block 0")))),
        ("msh: version 3", Kind::Msh, b"$MeshFormat\n3.0 0 8\n$EndMeshFormat\n".to_vec(),
            Box::new(|e| matches!(e, MeshError::Unsupported { what, .. } if what.contains("MSH version 3.0")))),
        ("msh: undefined node tag", Kind::Msh, format!("{MSH_HEAD}{MSH_NODES}$Elements\n2\n1 4 2 0 1 1 2 3 4\n2 4 2 0 1 1 2 3 7\n$EndElements\n").into_bytes(),
            Box::new(|e| matches!(e, MeshError::BadCell { cell: 1, reason, .. } if reason.contains("node tag 7 is not defined")))),
        ("msh: node count lies", Kind::Msh, format!("{MSH_HEAD}$Nodes\n100000000\n1 0 0 0\n$EndNodes\n").into_bytes(),
            Box::new(|e| matches!(e, MeshError::TooShort { what, .. } if what.contains("number of nodes")))),
        ("msh: missing $EndNodes", Kind::Msh, format!("{MSH_HEAD}$Nodes\n1\n1 0 0 0\n$Elements\n").into_bytes(),
            Box::new(parse_at(7, "expected $EndNodes"))),
        ("msh: bad endianness marker", Kind::Msh, b"$MeshFormat\n2.2 1 8\n\x07\x00\x00\x00\n$EndMeshFormat\n".to_vec(),
            Box::new(|e| matches!(e, MeshError::Parse { reason, .. } if reason.contains("endianness marker")))),
        ("msh: tet with 3 nodes", Kind::Msh, format!("{MSH_HEAD}{MSH_NODES}$Elements\n1\n1 4 2 0 1 1 2 3\n$EndElements\n").into_bytes(),
            Box::new(|e| matches!(e, MeshError::BadCell { cell: 0, reason, .. } if reason.contains("element type 4 has 4 nodes, found 3")))),
        ("tetgen: index out of range", Kind::TetGen, b"4 3 0 0\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1\n\x001 4 0\n1 1 2 3 5\n".to_vec(),
            Box::new(|e| matches!(e, MeshError::BadCell { path, cell: 0, reason } if path.ends_with("bad.ele") && reason.contains("node index 5 is out of range")))),
        ("tetgen: non-consecutive points", Kind::TetGen, b"2 3 0 0\n1 0 0 0\n3 1 0 0\n\x000 4 0\n".to_vec(),
            Box::new(parse_at(3, "point index 3, expected 2"))),
        ("tetgen: 2D node file", Kind::TetGen, b"2 2 0 0\n1 0 0\n2 1 0\n\x000 4 0\n".to_vec(),
            Box::new(|e| matches!(e, MeshError::Parse { reason, .. } if reason.contains("only 3D")))),
        ("tetgen: tet count lies", Kind::TetGen, b"4 3 0 0\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1\n\x00100000 4 0\n1 1 2 3 4\n".to_vec(),
            Box::new(|e| matches!(e, MeshError::TooShort { what, .. } if what.contains("number of tetrahedra")))),
    ];
    assert!(cases.len() >= 20);
    for (name, kind, bytes, check) in &cases {
        let r = std::panic::catch_unwind(|| read(*kind, bytes));
        let Ok(r) = r else { panic!("{name}: panicked") };
        match r {
            Ok(_) => panic!("{name}: read without error"),
            Err(e) => {
                assert!(check(&e), "{name}: unexpected error: {e:?}");
                // Every message names the file.
                assert!(e.to_string().contains("bad."), "{name}: {e}");
            }
        }
    }
}

#[test]
fn pvd_errors() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("s.pvd");
    std::fs::write(&p, "<VTKFile type=\"Collection\"><Collection>\n<DataSet timestep=\"0\"/>\n</Collection></VTKFile>").unwrap();
    let e = mesh::read_pvd(&p).unwrap_err();
    assert!(
        matches!(&e, MeshError::Parse { line: 2, reason, .. } if reason.contains("without a file")),
        "{e}"
    );
    std::fs::write(&p, "<VTKFile type=\"Collection\"><Collection><DataSet timestep=\"0\" file=\"missing.vtu\"/></Collection></VTKFile>").unwrap();
    let s = mesh::read_pvd(&p).unwrap();
    let e = s.load_step(0).unwrap_err();
    assert!(
        matches!(&e, MeshError::Io { path, .. } if path.ends_with("missing.vtu")),
        "{e}"
    );
    std::fs::write(&p, "<VTKFile type=\"UnstructuredGrid\"></VTKFile>").unwrap();
    assert!(matches!(
        mesh::read_pvd(&p).unwrap_err(),
        MeshError::Parse { .. }
    ));
}

/// Truncating or flipping bytes of every committed test file never panics.
#[test]
fn truncated_and_corrupted_files_never_panic() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/mesh");
    for entry in std::fs::read_dir(&dir).unwrap() {
        let path = entry.unwrap().path();
        let kind = match path.extension().and_then(|e| e.to_str()) {
            Some("vtk") => Kind::Vtk,
            Some("vtu") => Kind::Vtu,
            Some("msh") => Kind::Msh,
            _ => continue,
        };
        let bytes = std::fs::read(&path).unwrap();
        let mut rng = Rng::new(0x9e37_79b9_7f4a_7c15);
        for step in 0..200 {
            let mut b = bytes.clone();
            if step % 2 == 0 {
                b.truncate(rng.index(bytes.len()));
            } else {
                let i = rng.index(b.len());
                b[i] = rng.next_u32() as u8;
            }
            let r = std::panic::catch_unwind(|| read(kind, &b));
            assert!(r.is_ok(), "{}: step {step} panicked", path.display());
        }
    }
}
