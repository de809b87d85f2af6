//! The NIfTI / Analyze reader against files written by other programs, with the values
//! nibabel reports for them (`tests/data/nifti/expected.json`, written by `make_nifti.py`
//! from nibabel; provenance in `tests/data/nifti/README.md`): dims, voxel type, byte order
//! and memory mapping, scaling, stored and physical voxels, the world position of the
//! eight corner voxels, time steps, value ranges; plus bad input (each a clear error naming
//! the file and the header field).

use std::path::{Path, PathBuf};

use formats::nifti::{parse_header, read_nifti};
use formats::{Dataset, FormatError, OpenOptions};
use glam::DVec3;
use serde_json::Value;
use volume_core::{RectilinearVolume, ValueMap, VoxelType, WorldFrame};

fn data_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/nifti")
}

fn expected() -> Value {
    let text = std::fs::read_to_string(data_dir().join("expected.json")).unwrap();
    serde_json::from_str(&text).unwrap()
}

fn f(v: &Value) -> f64 {
    v.as_f64().unwrap_or_else(|| panic!("number expected: {v}"))
}

fn voxel_type(numpy: &str) -> VoxelType {
    match numpy {
        "uint8" => VoxelType::U8,
        "int8" => VoxelType::I8,
        "uint16" => VoxelType::U16,
        "int16" => VoxelType::I16,
        "uint32" => VoxelType::U32,
        "int32" => VoxelType::I32,
        "float32" => VoxelType::F32,
        "float64" => VoxelType::F64,
        other => panic!("dtype {other}"),
    }
}

/// Millimetres per unit of nibabel's space unit name (unknown: millimetres).
fn mm_per(unit: &str) -> f64 {
    match unit {
        "meter" => 1000.0,
        "micron" => 1e-3,
        _ => 1.0,
    }
}

fn seconds_per(unit: &str) -> f64 {
    match unit {
        "msec" => 1e-3,
        "usec" => 1e-6,
        _ => 1.0,
    }
}

fn close(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol * (1.0 + b.abs())
}

/// The world position of voxel `(i, j, k)`.
fn world(v: &RectilinearVolume, i: usize, j: usize, k: usize) -> DVec3 {
    let p = v.grid.grid_position(i, j, k);
    v.grid
        .world_from_grid()
        .map_or(p, |m| m.transform_point3(p))
}

fn volumes(d: &Dataset) -> Vec<RectilinearVolume> {
    match d {
        Dataset::Volume(v) => vec![v.clone()],
        Dataset::Series(s) => (0..s.step_count()).map(|t| s.step(t).unwrap()).collect(),
    }
}

#[test]
fn every_fixture_reads_as_nibabel_reports_it() {
    let exp = expected();
    let files = exp["files"].as_array().unwrap();
    assert!(files.len() >= 14, "{} files", files.len());
    for e in files {
        let name = e["file"].as_str().unwrap();
        let path = data_dir().join(name);
        let d = formats::open(&path, &OpenOptions::default())
            .unwrap_or_else(|err| panic!("{name}: {err}"));
        let shape: Vec<usize> = e["shape"]
            .as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_u64().unwrap() as usize)
            .collect();
        let steps = shape.get(3).copied().unwrap_or(1);
        assert_eq!(d.time_steps(), steps, "{name}");
        let vols = volumes(&d);
        let v = &vols[0];
        assert_eq!(v.dims(), [shape[0], shape[1], shape[2]], "{name}");
        assert_eq!(
            v.data.voxel_type(),
            voxel_type(e["dtype"].as_str().unwrap()),
            "{name}"
        );
        // Uncompressed native-endian data is viewed in the memory map, never copied.
        let native = e["byteorder"] == "little" || v.data.voxel_type().size_bytes() == 1;
        let gz = Path::new(name).extension().is_some_and(|x| x == "gz");
        assert_eq!(v.data.is_shared(), native && !gz, "{name}: memory mapped");
        // Scaling.
        let want = ValueMap::new(f(&e["scl_slope"]), f(&e["scl_inter"])).unwrap();
        assert_eq!(v.value_map, want, "{name}");
        // Voxels, stored and physical.
        for p in e["voxels"].as_array().unwrap() {
            let idx: Vec<usize> = p["index"]
                .as_array()
                .unwrap()
                .iter()
                .map(|x| x.as_u64().unwrap() as usize)
                .collect();
            let t = idx.get(3).copied().unwrap_or(0);
            let vol = &vols[t];
            // serde_json parses floats to within an ulp (no `float_roundtrip`).
            let stored = vol.value_f64(idx[0], idx[1], idx[2]);
            assert!(
                close(stored, f(&p["stored"]), 1e-14),
                "{name} {idx:?}: {stored} vs {}",
                p["stored"]
            );
            let phys = vol.physical_f64(idx[0], idx[1], idx[2]);
            assert!(
                close(phys, f(&p["value"]), 1e-6),
                "{name} {idx:?}: {phys} vs {}",
                p["value"]
            );
        }
        // Geometry: the eight corners in RAS millimetres.
        assert_eq!(v.grid.world_frame(), WorldFrame::Ras, "{name}");
        let mm = mm_per(e["space_unit"].as_str().unwrap());
        for c in e["corners"].as_array().unwrap() {
            let ijk: Vec<usize> = c["index"]
                .as_array()
                .unwrap()
                .iter()
                .map(|x| x.as_u64().unwrap() as usize)
                .collect();
            let got = world(v, ijk[0], ijk[1], ijk[2]);
            let w: Vec<f64> = c["world"].as_array().unwrap().iter().map(f).collect();
            let want = DVec3::new(w[0], w[1], w[2]) * mm;
            assert!(
                (got - want).length() <= 1e-4 * (1.0 + want.length()),
                "{name} corner {ijk:?}: {got} vs {want}"
            );
        }
        // Value range over every step, physical.
        let (lo, hi) = vols
            .iter()
            .map(|v| v.value_stats().finite_range.unwrap())
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), (c, d)| {
                (a.min(c), b.max(d))
            });
        assert!(
            close(lo, f(&e["min"]), 1e-6) && close(hi, f(&e["max"]), 1e-6),
            "{name}: range {lo}..{hi} vs {}..{}",
            e["min"],
            e["max"]
        );
        // Step times.
        if let Dataset::Series(s) = &d {
            let dt = f(&e["pixdim4"]) * seconds_per(e["time_unit"].as_str().unwrap());
            let t0 = f(&e["toffset"]) * seconds_per(e["time_unit"].as_str().unwrap());
            assert!(close(s.time_value(0), t0, 1e-9), "{name}");
            assert!(close(s.time_value(1) - s.time_value(0), dt, 1e-9), "{name}");
        }
    }
}

#[test]
fn header_only_files_give_nibabels_affine_and_a_missing_image_error() {
    let exp = expected();
    for e in exp["headers"].as_array().unwrap() {
        let name = e["file"].as_str().unwrap();
        let path = data_dir().join(name);
        let bytes = std::fs::read(&path).unwrap();
        let h = parse_header(&path, &bytes).unwrap();
        assert!(!h.single_file, "{name}");
        let l = h.layout(&path).unwrap();
        let shape: Vec<usize> = e["shape"]
            .as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_u64().unwrap() as usize)
            .collect();
        assert_eq!(l.grid.dims(), [shape[0], shape[1], shape[2]], "{name}");
        assert_eq!(l.voxel_type, voxel_type(e["dtype"].as_str().unwrap()));
        let slope = e["scl_slope"].as_f64().unwrap_or(1.0);
        let inter = e["scl_inter"].as_f64().unwrap_or(0.0);
        assert_eq!(l.value_map, ValueMap::new(slope, inter).unwrap(), "{name}");
        let a: Vec<Vec<f64>> = e["affine"]
            .as_array()
            .unwrap()
            .iter()
            .map(|r| r.as_array().unwrap().iter().map(f).collect())
            .collect();
        for ijk in [
            [0, 0, 0],
            [shape[0] - 1, 3, 5],
            [2, shape[1] - 1, shape[2] - 1],
        ] {
            let p = l.grid.grid_position(ijk[0], ijk[1], ijk[2]);
            let got = l
                .grid
                .world_from_grid()
                .map_or(p, |m| m.transform_point3(p));
            let want = DVec3::from_array(std::array::from_fn(|r| {
                a[r][3] + (0..3).map(|c| a[r][c] * ijk[c] as f64).sum::<f64>()
            }));
            assert!(
                (got - want).length() < 1e-9,
                "{name} {ijk:?}: {got} vs {want}"
            );
        }
        // The pair's image is not committed: opening names the missing file.
        let err = read_nifti(&path).unwrap_err();
        assert!(
            matches!(&err, FormatError::Io { path: p, .. } if p.extension().is_some_and(|x| x == "img")),
            "{name}: {err}"
        );
    }
}

/// A copy of a fixture in a scratch folder (so damaged variants can be written beside it).
fn scratch_copy(dir: &Path, name: &str) -> (PathBuf, Vec<u8>) {
    let bytes = std::fs::read(data_dir().join(name)).unwrap();
    let p = dir.join(name);
    std::fs::write(&p, &bytes).unwrap();
    (p, bytes)
}

fn expect_field(path: &Path, field: &str) -> FormatError {
    let e = formats::open(path, &OpenOptions::default()).unwrap_err();
    let text = e.to_string();
    assert!(
        text.contains(&path.file_name().unwrap().to_string_lossy().into_owned()),
        "{text}"
    );
    assert_eq!(e.field(), Some(field), "{text}");
    e
}

#[test]
fn damaged_files_are_clear_errors_naming_file_and_field() {
    let dir = tempfile::tempdir().unwrap();
    let (p, bytes) = scratch_copy(dir.path(), "u16.nii");
    // Truncated header.
    std::fs::write(&p, &bytes[..200]).unwrap();
    let e = expect_field(&p, "sizeof_hdr");
    assert!(e.to_string().contains("truncated"), "{e}");
    // sizeof_hdr neither 348 nor 540.
    let mut x = bytes.clone();
    x[0..4].copy_from_slice(&347i32.to_le_bytes());
    std::fs::write(&p, &x).unwrap();
    expect_field(&p, "sizeof_hdr");
    // vox_offset beyond the file.
    let mut x = bytes.clone();
    x[108..112].copy_from_slice(&1e6f32.to_le_bytes());
    std::fs::write(&p, &x).unwrap();
    let e = expect_field(&p, "vox_offset");
    assert!(e.to_string().contains("beyond"), "{e}");
    // Data cut short.
    std::fs::write(&p, &bytes[..bytes.len() - 10]).unwrap();
    let e = expect_field(&p, "dim");
    assert!(e.to_string().contains("truncated"), "{e}");
    // Dims whose product overflows (7 dims of 32767).
    let mut x = bytes.clone();
    for i in 0..8 {
        let d: i16 = if i == 0 { 7 } else { 32767 };
        x[40 + 2 * i..42 + 2 * i].copy_from_slice(&d.to_le_bytes());
    }
    std::fs::write(&p, &x).unwrap();
    // dim[5..7] > 1 is refused first; with them at 1 the 4D product still overflows.
    expect_field(&p, "dim[5]");
    for i in 5..8 {
        x[40 + 2 * i..42 + 2 * i].copy_from_slice(&1i16.to_le_bytes());
    }
    x[40..42].copy_from_slice(&4i16.to_le_bytes());
    std::fs::write(&p, &x).unwrap();
    let e = expect_field(&p, "dim");
    assert!(e.to_string().contains("truncated"), "{e}");
    // NIfTI-2 (big-endian) sizes whose product overflows 64 bits.
    let (p2, bytes2) = scratch_copy(dir.path(), "nifti2_be_4d.nii");
    let mut x = bytes2.clone();
    for i in 1..4 {
        x[16 + 8 * i..24 + 8 * i].copy_from_slice(&(1i64 << 30).to_be_bytes());
    }
    std::fs::write(&p2, &x).unwrap();
    let e = expect_field(&p2, "dim");
    assert!(e.to_string().contains("overflow"), "{e}");
    // A negative size.
    let mut x = bytes2;
    x[40..48].copy_from_slice(&(-3i64).to_be_bytes());
    std::fs::write(&p2, &x).unwrap();
    expect_field(&p2, "dim[3]");
    // Unsupported datatypes, named by code and name.
    for (code, name) in [
        (1024i16, "INT64"),
        (32, "COMPLEX64"),
        (128, "RGB24"),
        (7, "not a NIfTI"),
    ] {
        let mut x = bytes.clone();
        x[70..72].copy_from_slice(&code.to_le_bytes());
        std::fs::write(&p, &x).unwrap();
        let e = expect_field(&p, "datatype");
        assert!(
            matches!(&e, FormatError::Unsupported { reason, .. } if reason.contains(name) && reason.contains(&code.to_string())),
            "{e}"
        );
    }
    // gzip shorter than the header says: the stream ends inside the data.
    let (gz, gz_bytes) = scratch_copy(dir.path(), "f64.nii.gz");
    let mut raw = Vec::new();
    std::io::Read::read_to_end(&mut flate2::read::GzDecoder::new(&gz_bytes[..]), &mut raw).unwrap();
    let mut enc = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
    std::io::Write::write_all(&mut enc, &raw[..raw.len() / 2]).unwrap();
    std::fs::write(&gz, enc.finish().unwrap()).unwrap();
    let e = formats::open(&gz, &OpenOptions::default()).unwrap_err();
    assert!(
        matches!(&e, FormatError::Decode { reason, .. } if reason.contains("truncated") && reason.contains("vox_offset")),
        "{e}"
    );
    assert!(e.to_string().contains("f64.nii.gz"), "{e}");
    // A damaged checksum: the data decodes, but the stream is not what was written.
    let mut x = gz_bytes.clone();
    let n = x.len();
    x[n - 6] ^= 0x5a;
    std::fs::write(&gz, &x).unwrap();
    let e = formats::open(&gz, &OpenOptions::default()).unwrap_err();
    assert!(matches!(&e, FormatError::Decode { .. }), "{e}");
    // A gzip stream cut inside the header, and one that is not gzip at all.
    std::fs::write(&gz, &gz_bytes[..20]).unwrap();
    let e = formats::open(&gz, &OpenOptions::default()).unwrap_err();
    assert!(e.to_string().contains("f64.nii.gz"), "{e}");
    std::fs::write(&gz, &raw).unwrap();
    let e = formats::open(&gz, &OpenOptions::default()).unwrap_err();
    assert!(e.to_string().contains("f64.nii.gz"), "{e}");
}

#[test]
fn a_gzip_bomb_is_read_only_as_far_as_the_header_says() {
    // 120 bytes of voxels declared, 64 MiB of zeros in the stream: only what the header
    // asks for is decompressed into memory.
    let dir = tempfile::tempdir().unwrap();
    let bytes = std::fs::read(data_dir().join("pair.hdr")).unwrap();
    let mut h = bytes.clone();
    h.resize(352, 0);
    h[344..348].copy_from_slice(b"n+1\0");
    h[108..112].copy_from_slice(&352f32.to_le_bytes());
    for (i, d) in [3i16, 5, 4, 3, 1, 1, 1, 1].iter().enumerate() {
        h[40 + 2 * i..42 + 2 * i].copy_from_slice(&d.to_le_bytes());
    }
    h[70..72].copy_from_slice(&2i16.to_le_bytes());
    let mut enc = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::best());
    std::io::Write::write_all(&mut enc, &h).unwrap();
    let zeros = vec![0u8; 1 << 20];
    for _ in 0..64 {
        std::io::Write::write_all(&mut enc, &zeros).unwrap();
    }
    let p = dir.path().join("bomb.nii.gz");
    std::fs::write(&p, enc.finish().unwrap()).unwrap();
    let d = formats::open(&p, &OpenOptions::default()).unwrap();
    let v = d.first_volume();
    assert_eq!(v.dims(), [5, 4, 3]);
    assert_eq!(v.data.size_bytes(), 60);
}

#[test]
fn nifti_under_another_name_is_sniffed() {
    let dir = tempfile::tempdir().unwrap();
    let bytes = std::fs::read(data_dir().join("u16.nii")).unwrap();
    let p = dir.path().join("scan.dat");
    std::fs::write(&p, &bytes).unwrap();
    let d = formats::open(&p, &OpenOptions::default()).unwrap();
    assert_eq!(d.first_volume().dims(), [12, 10, 8]);
    assert!(d.first_volume().data.is_shared());
}
