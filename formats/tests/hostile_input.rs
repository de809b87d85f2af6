//! Hostile input: special files, reference cycles, lying compressed headers, negative counts,
//! coordinates that overflow single precision and errors that must name the file. Each test
//! here failed (panic, abort, hang or a nameless error) before the reader was fixed.
//!
//! Tests that could hang run the reader in a thread with a deadline, so a regression fails
//! instead of blocking the suite.

use std::fmt::Write as _;
use std::io::Write;
use std::path::Path;
use std::sync::mpsc;
use std::time::Duration;

use formats::mesh::{self, MeshError, gmsh, tetgen, vtu};
use formats::{FormatError, OpenOptions};

/// Runs `f` in a thread; panics if it does not finish within `secs` (a hang).
fn within<T: Send + 'static>(secs: u64, what: &str, f: impl FnOnce() -> T + Send + 'static) -> T {
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        let _ = tx.send(f());
    });
    rx.recv_timeout(Duration::from_secs(secs))
        .unwrap_or_else(|_| panic!("{what}: no answer within {secs} s (hangs)"))
}

fn mkfifo(path: &Path) {
    let ok = std::process::Command::new("mkfifo")
        .arg(path)
        .status()
        .expect("mkfifo runs")
        .success();
    assert!(ok, "mkfifo {}", path.display());
}

fn nrrd_bytes(dims: [usize; 3], extra: &str) -> Vec<u8> {
    let n = dims.iter().product::<usize>();
    let mut h = format!(
        "NRRD0004\ntype: uint8\ndimension: 3\nsizes: {} {} {}\nencoding: raw\n",
        dims[0], dims[1], dims[2]
    );
    if !extra.is_empty() {
        h.push_str(extra);
        h.push('\n');
    }
    h.push('\n');
    let mut b = h.into_bytes();
    b.extend((0..n).map(|i| i as u8));
    b
}

fn open(path: &Path) -> Result<formats::Dataset, FormatError> {
    formats::open(path, &OpenOptions::default())
}

const TET_VTU: &str = r#"<?xml version="1.0"?>
<VTKFile type="UnstructuredGrid" version="1.0" byte_order="LittleEndian">
<UnstructuredGrid><Piece NumberOfPoints="4" NumberOfCells="1">
<Points><DataArray type="Float32" NumberOfComponents="3" format="ascii">0 0 0 1 0 0 0 1 0 0 0 1</DataArray></Points>
<Cells><DataArray type="Int32" Name="connectivity" format="ascii">0 1 2 3</DataArray>
<DataArray type="Int32" Name="offsets" format="ascii">4</DataArray>
<DataArray type="UInt8" Name="types" format="ascii">10</DataArray></Cells>
</Piece></UnstructuredGrid></VTKFile>
"#;

fn pvd(files: &[&str]) -> String {
    let mut sets = String::new();
    for (i, f) in files.iter().enumerate() {
        let _ = writeln!(sets, "<DataSet timestep=\"{i}\" part=\"0\" file=\"{f}\"/>");
    }
    format!(
        "<?xml version=\"1.0\"?>\n<VTKFile type=\"Collection\" version=\"0.1\">\n<Collection>\n{sets}</Collection>\n</VTKFile>\n"
    )
}

fn assert_special(e: &str, name: &str, kind: &str) {
    assert!(
        e.contains(name) && e.contains(kind) && e.contains("not a regular file"),
        "expected `{name}` and `{kind}` in: {e}"
    );
}

// --- Regular files only ----------------------------------------------------------------

#[test]
fn fifo_named_like_a_volume_is_refused_not_waited_on() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("x.nrrd");
    mkfifo(&p);
    let e = within(10, "open FIFO x.nrrd", move || open(&p).map(|_| ()));
    assert_special(&e.unwrap_err().to_string(), "x.nrrd", "FIFO");
}

#[test]
fn fifo_as_detached_data_file_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let h = dir.path().join("a.nhdr");
    std::fs::write(
        &h,
        "NRRD0004\ntype: uint8\ndimension: 3\nsizes: 2 2 2\nencoding: raw\ndata file: d.raw\n",
    )
    .unwrap();
    mkfifo(&dir.path().join("d.raw"));
    let e = within(10, "open a.nhdr with a FIFO data file", move || {
        open(&h).map(|_| ())
    });
    assert_special(&e.unwrap_err().to_string(), "d.raw", "FIFO");
    // Gzip data is streamed rather than mapped: the same check applies.
    let h = dir.path().join("b.nhdr");
    std::fs::write(
        &h,
        "NRRD0004\ntype: uint8\ndimension: 3\nsizes: 2 2 2\nencoding: gzip\ndata file: d.raw\n",
    )
    .unwrap();
    let e = within(10, "open b.nhdr (gzip) with a FIFO data file", move || {
        open(&h).map(|_| ())
    });
    assert_special(&e.unwrap_err().to_string(), "d.raw", "FIFO");
}

#[cfg(unix)]
#[test]
fn pvd_step_linked_to_dev_zero_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    std::os::unix::fs::symlink("/dev/zero", dir.path().join("z.vtu")).unwrap();
    let p = dir.path().join("s.pvd");
    std::fs::write(&p, pvd(&["z.vtu"])).unwrap();
    let q = p.clone();
    let e = within(10, "read s.pvd whose step is /dev/zero", move || {
        mesh::read_mesh(&q).map(|_| ())
    });
    assert_special(&e.unwrap_err().to_string(), "z.vtu", "character device");
    let series = mesh::read_pvd(&p).unwrap();
    let e = within(10, "load step 0 = /dev/zero", move || {
        series.load_step(0).map(|_| ())
    });
    assert_special(&e.unwrap_err().to_string(), "z.vtu", "character device");
}

#[cfg(unix)]
#[test]
fn every_reader_refuses_special_files() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // Mesh main files that are FIFOs, and a TetGen partner that is one.
    for name in ["m.vtk", "m.vtu", "m.msh", "m.pvd"] {
        let p = d.join(name);
        mkfifo(&p);
        let e = within(10, name, move || mesh::read_mesh(&p).map(|_| ()));
        assert_special(&e.unwrap_err().to_string(), name, "FIFO");
    }
    std::fs::write(
        d.join("t.node"),
        "4 3 0 0\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1\n",
    )
    .unwrap();
    mkfifo(&d.join("t.ele"));
    let p = d.join("t.node");
    let e = within(10, "t.node with a FIFO t.ele", move || {
        tetgen::read(&p).map(|_| ())
    });
    assert_special(&e.unwrap_err().to_string(), "t.ele", "FIFO");
    // A raw file whose sidecar is a FIFO, and a raw file that is one (layout given).
    std::fs::write(d.join("r.raw"), [0u8; 8]).unwrap();
    mkfifo(&d.join("r.json"));
    let p = d.join("r.raw");
    let e = within(10, "r.raw with a FIFO sidecar", move || {
        open(&p).map(|_| ())
    });
    assert_special(&e.unwrap_err().to_string(), "r.json", "FIFO");
    mkfifo(&d.join("f.raw"));
    let p = d.join("f.raw");
    let e = within(10, "FIFO raw with a layout", move || {
        let layout = formats::raw::RawLayout {
            dims: [2, 2, 2],
            voxel_type: volume_core::VoxelType::U8,
            endian: formats::raw::Endian::Little,
            header_bytes: 0,
            spacing: [1.0; 3],
            origin: [0.0; 3],
        };
        formats::raw::read_raw(&p, &layout).map(|_| ())
    });
    assert_special(&e.unwrap_err().to_string(), "f.raw", "FIFO");
    // A file of unknown extension (sniffed for the NRRD magic) and a `.isot`.
    for name in ["u.dat", "o.isot"] {
        let p = d.join(name);
        mkfifo(&p);
        let q = p.clone();
        let e = within(10, name, move || {
            if name == "o.isot" {
                formats::treelet::IsotFile::open(&q).map(|_| ())
            } else {
                open(&q).map(|_| ())
            }
        });
        assert_special(&e.unwrap_err().to_string(), name, "FIFO");
        assert!(!formats::treelet::is_isot(&p));
    }
    // A series whose second step is a symbolic link to a FIFO.
    let sd = d.join("series");
    std::fs::create_dir(&sd).unwrap();
    std::fs::write(sd.join("v_0.nrrd"), nrrd_bytes([2, 2, 2], "")).unwrap();
    mkfifo(&d.join("pipe"));
    std::os::unix::fs::symlink(d.join("pipe"), sd.join("v_1.nrrd")).unwrap();
    let pattern = sd.join("v_*.nrrd");
    let e = within(10, "series step linked to a FIFO", move || {
        let ds = open(&pattern).unwrap();
        let formats::Dataset::Series(ts) = ds else {
            panic!("a series")
        };
        ts.step(1).map(|_| ()).map_err(|e| format!("{e}"))
    });
    assert_special(&e.unwrap_err(), "v_1.nrrd", "FIFO");
    // A directory given as a volume.
    let e = open(&d.join("series")).unwrap_err().to_string();
    assert!(e.contains("series"), "{e}");
}

// --- Cycles --------------------------------------------------------------------------

#[test]
fn pvd_that_references_itself_is_an_error_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    let a = dir.path().join("a.pvd");
    std::fs::write(&a, pvd(&["a.pvd"])).unwrap();
    let e = mesh::read_mesh(&a).unwrap_err();
    let s = e.to_string();
    assert!(s.contains("a.pvd") && s.contains("cycle"), "{s}");
}

#[test]
fn pvd_cycle_through_two_collections_names_both() {
    let dir = tempfile::tempdir().unwrap();
    let (a, b) = (dir.path().join("a.pvd"), dir.path().join("b.pvd"));
    std::fs::write(&a, pvd(&["b.pvd"])).unwrap();
    std::fs::write(&b, pvd(&["a.pvd"])).unwrap();
    for e in [
        mesh::read_mesh(&a).unwrap_err(),
        mesh::read_pvd(&a).unwrap().load_step(0).unwrap_err(),
    ] {
        let s = e.to_string();
        assert!(
            s.contains("a.pvd") && s.contains("b.pvd") && s.contains("cycle"),
            "{s}"
        );
    }
    // A collection of a collection without a cycle still reads.
    std::fs::write(dir.path().join("t.vtu"), TET_VTU).unwrap();
    std::fs::write(&b, pvd(&["t.vtu"])).unwrap();
    assert_eq!(mesh::read_mesh(&a).unwrap().mesh.tets.len(), 1);
}

// --- Allocation from header claims -----------------------------------------------------

fn b64(bytes: &[u8]) -> String {
    use base64::Engine;
    base64::engine::general_purpose::STANDARD.encode(bytes)
}

fn zlib(bytes: &[u8]) -> Vec<u8> {
    let mut e = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::default());
    e.write_all(bytes).unwrap();
    e.finish().unwrap()
}

/// A zlib `.vtu` with NumberOfPoints `n` whose Points block header claims `claimed` bytes in
/// one block and holds the zlib stream of `actual` (UInt64 headers).
fn zlib_vtu(n: u64, claimed: u64, actual: &[u8]) -> Vec<u8> {
    let z = zlib(actual);
    let head: Vec<u8> = [1u64, claimed, claimed, z.len() as u64]
        .iter()
        .flat_map(|w| w.to_le_bytes())
        .collect();
    format!(
        r#"<?xml version="1.0"?>
<VTKFile type="UnstructuredGrid" version="1.0" byte_order="LittleEndian" header_type="UInt64" compressor="vtkZLibDataCompressor">
<UnstructuredGrid><Piece NumberOfPoints="{n}" NumberOfCells="0">
<Points><DataArray type="Float32" NumberOfComponents="3" format="binary">{}{}</DataArray></Points>
</Piece></UnstructuredGrid></VTKFile>
"#,
        b64(&head),
        b64(&z)
    )
    .into_bytes()
}

#[test]
fn zlib_vtu_claiming_1e11_points_is_an_error_not_an_abort() {
    let claimed = 100_000_000_000u64 * 12;
    let doc = zlib_vtu(100_000_000_000, claimed, &[0u8; 1000]);
    let e = vtu::parse(Path::new("huge.vtu"), &doc).unwrap_err();
    let s = e.to_string();
    assert!(
        matches!(e, MeshError::BadArray { .. }) && s.contains("huge.vtu"),
        "{s}"
    );
}

#[test]
fn zlib_bomb_stops_at_the_declared_size() {
    // 4 points (48 bytes) declared; the stream inflates to 64 MiB of zeros.
    let doc = zlib_vtu(4, 48, &vec![0u8; 64 << 20]);
    let e = vtu::parse(Path::new("bomb.vtu"), &doc).unwrap_err();
    assert!(
        e.to_string().contains("inflates to 49 bytes, expected 48"),
        "{e}"
    );
}

#[test]
fn zlib_vtu_with_overflowing_point_count_is_an_error() {
    let doc = zlib_vtu(u64::MAX / 2, 48, &[0u8; 48]);
    let e = vtu::parse(Path::new("ovf.vtu"), &doc).unwrap_err();
    assert!(e.to_string().contains("ovf.vtu"), "{e}");
}

#[test]
fn zlib_vtu_with_block_count_near_u64_max_is_an_error() {
    // Found by the `vtu` fuzz target: `3 + nblocks` (the compression header's length in
    // words) overflowed before it was compared with the block.
    let mut doc = zlib_vtu(1, 12, &[0u8; 12]);
    let head: Vec<u8> = [1u64, 12, 12]
        .iter()
        .flat_map(|w| w.to_le_bytes())
        .collect();
    let huge: Vec<u8> = [u64::MAX, 12, 12]
        .iter()
        .flat_map(|w| w.to_le_bytes())
        .collect();
    let text = String::from_utf8(doc).unwrap();
    let (old, new) = (b64(&head), b64(&huge));
    assert!(text.contains(&old));
    doc = text.replacen(&old, &new, 1).into_bytes();
    let e = vtu::parse(Path::new("blocks.vtu"), &doc).unwrap_err();
    let s = e.to_string();
    assert!(s.contains("blocks.vtu") && s.contains("blocks"), "{s}");
}

// --- Signs and ranges of counts ----------------------------------------------------------

#[test]
fn gmsh22_negative_tag_count_is_an_error() {
    let msh = "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n4\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1\n$EndNodes\n$Elements\n1\n1 4 -5 1 2 3 4\n$EndElements\n";
    let e = gmsh::parse(Path::new("neg.msh"), msh.as_bytes()).unwrap_err();
    assert!(
        matches!(&e, MeshError::BadCell { cell: 0, reason, .. } if reason.contains("-5")),
        "{e}"
    );
    // A huge tag count is an error too, not an overflow.
    let msh = msh.replace("1 4 -5", &format!("1 4 {}", i64::MAX));
    assert!(gmsh::parse(Path::new("big.msh"), msh.as_bytes()).is_err());
}

#[test]
fn tetgen_extreme_node_index_is_an_error() {
    let node = b"4 3 0 0\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1\n";
    let ele = format!("1 4 0\n1 1 2 3 {}\n", i64::MIN);
    let e = tetgen::parse(
        Path::new("t.node"),
        node,
        Path::new("t.ele"),
        ele.as_bytes(),
    )
    .unwrap_err();
    assert!(
        matches!(&e, MeshError::BadCell { cell: 0, .. }) && e.to_string().contains("t.ele"),
        "{e}"
    );
    let ele = b"1 4 7\n1 1 2 3 4\n";
    let e = tetgen::parse(Path::new("t.node"), node, Path::new("t.ele"), ele).unwrap_err();
    assert!(e.to_string().contains("region attribute flag"), "{e}");
}

// --- Errors name the file and the field ------------------------------------------------

#[test]
fn spacing_that_overflows_f32_is_rejected_at_open_naming_file_and_field() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("big.nrrd");
    std::fs::write(&p, nrrd_bytes([256, 2, 2], "spacings: 1e30 1 1")).unwrap();
    let e = open(&p).unwrap_err();
    assert_eq!(e.field(), Some("spacings"), "{e}");
    let s = e.to_string();
    assert!(s.contains("big.nrrd") && s.contains("spacings"), "{s}");
    // Oriented: the directions carry the spacing.
    let p = dir.path().join("dirs.nrrd");
    std::fs::write(
        &p,
        nrrd_bytes(
            [256, 2, 2],
            "space: RAS\nspace directions: (0,1e30,0) (1,0,0) (0,0,1)",
        ),
    )
    .unwrap();
    let e = open(&p).unwrap_err();
    assert_eq!(e.field(), Some("space directions"), "{e}");
    // A raw sidecar.
    let r = dir.path().join("r.raw");
    std::fs::write(&r, [0u8; 8]).unwrap();
    std::fs::write(
        dir.path().join("r.json"),
        r#"{"dims":[2,2,2],"type":"u8","endian":"little","spacing":[1,1,1],"origin":[0,3e20,0]}"#,
    )
    .unwrap();
    let e = open(&r).unwrap_err();
    assert_eq!(e.field(), Some("origin"), "{e}");
    assert!(e.to_string().contains("r.raw"), "{e}");
}

#[test]
fn mesh_coordinates_beyond_f32_rendering_are_rejected_naming_the_point() {
    let vtk = "# vtk DataFile Version 4.2\nt\nASCII\nDATASET UNSTRUCTURED_GRID\nPOINTS 4 double\n0 0 0 1e30 0 0 0 1 0 0 0 1\nCELLS 1 5\n4 0 1 2 3\nCELL_TYPES 1\n10\n";
    let raw = mesh::vtk_legacy::parse(Path::new("far.vtk"), vtk.as_bytes()).unwrap();
    let e = raw.into_tet_mesh(Path::new("far.vtk")).unwrap_err();
    let s = e.to_string();
    assert!(
        s.contains("far.vtk") && s.contains("points") && s.contains("point 1"),
        "{s}"
    );
}

#[test]
fn series_step_of_other_dims_names_the_step_file() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("v_0.nrrd"), nrrd_bytes([2, 2, 2], "")).unwrap();
    std::fs::write(dir.path().join("v_1.nrrd"), nrrd_bytes([3, 2, 2], "")).unwrap();
    let ds = open(&dir.path().join("v_*.nrrd")).unwrap();
    let formats::Dataset::Series(ts) = ds else {
        panic!("a series")
    };
    let e = ts.step(1).unwrap_err().to_string();
    assert!(e.contains("v_1.nrrd") && e.contains("v_0.nrrd"), "{e}");
}
