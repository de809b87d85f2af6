//! Cross-check with Teem, the reference NRRD implementation: volumes are wrapped by
//! `unu make` and re-encoded by `unu save` in every encoding unu writes (raw, gzip, bzip2,
//! ascii, hex), both byte orders, attached and detached, with spacings, with space directions
//! (axis-aligned and oblique) and origin, with printf-pattern and LIST data files and as 4D
//! time series; Isoscope must read exactly the voxels and geometry.
//!
//! Needs Teem's `unu` (Debian package `teem-apps`, binary `teem-unu`; `unu` elsewhere). When it
//! is missing the tests fail if `CI` is set (CI must not skip them silently) and print a skip
//! notice otherwise.

use std::path::{Path, PathBuf};
use std::process::Command;

use formats::{Dataset, OpenOptions};
use volume_core::{RectilinearVolume, VoxelType};

fn find_unu() -> Option<PathBuf> {
    let path = std::env::var_os("PATH")?;
    for name in ["teem-unu", "unu"] {
        for dir in std::env::split_paths(&path) {
            let p = dir.join(name);
            if p.is_file() {
                return Some(p);
            }
        }
    }
    None
}

fn require_unu() -> Option<PathBuf> {
    if let Some(p) = find_unu() {
        return Some(p);
    }
    assert!(
        std::env::var_os("CI").is_none(),
        "Teem's unu is not installed (apt-get install teem-apps: binary teem-unu); CI must run the Teem cross-check"
    );
    eprintln!("SKIP nrrd_teem: Teem's unu not found (apt-get install teem-apps)");
    None
}

fn unu(bin: &Path, dir: &Path, args: &[&str]) {
    let out = Command::new(bin)
        .args(args)
        .current_dir(dir)
        .output()
        .expect("run unu");
    assert!(
        out.status.success(),
        "unu {args:?} failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

const DIMS: [usize; 3] = [5, 4, 3];
const N: usize = DIMS[0] * DIMS[1] * DIMS[2];

/// The test value of voxel `i` (exactly representable in type `t`, and short in ascii).
fn sample(t: VoxelType, i: usize) -> f64 {
    let x = ((i * 7919 + 13) % 251) as f64;
    match t {
        VoxelType::U8 => x,
        VoxelType::I8 => x - 125.0,
        VoxelType::U16 => x * 250.0,
        VoxelType::I16 => (x - 125.0) * 250.0,
        VoxelType::U32 => x * 1.0e6,
        VoxelType::I32 => (x - 125.0) * 1.0e6,
        VoxelType::F32 | VoxelType::F64 => (x - 125.0) * 0.25,
    }
}

/// Little-endian bytes of voxels `offset..offset + n`.
fn le_bytes(t: VoxelType, offset: usize, n: usize) -> Vec<u8> {
    (offset..offset + n)
        .flat_map(|i| {
            let v = sample(t, i);
            match t {
                VoxelType::U8 => vec![v as u8],
                VoxelType::I8 => vec![v as i8 as u8],
                VoxelType::U16 => (v as u16).to_le_bytes().to_vec(),
                VoxelType::I16 => (v as i16).to_le_bytes().to_vec(),
                VoxelType::U32 => (v as u32).to_le_bytes().to_vec(),
                VoxelType::I32 => (v as i32).to_le_bytes().to_vec(),
                VoxelType::F32 => (v as f32).to_le_bytes().to_vec(),
                VoxelType::F64 => v.to_le_bytes().to_vec(),
            }
        })
        .collect()
}

fn teem_name(t: VoxelType) -> &'static str {
    match t {
        VoxelType::U8 => "uchar",
        VoxelType::I8 => "signed char",
        VoxelType::U16 => "ushort",
        VoxelType::I16 => "short",
        VoxelType::U32 => "uint",
        VoxelType::I32 => "int",
        VoxelType::F32 => "float",
        VoxelType::F64 => "double",
    }
}

fn open(path: &Path) -> Dataset {
    formats::open(path, &OpenOptions::default())
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

fn volume(path: &Path) -> RectilinearVolume {
    match open(path) {
        Dataset::Volume(v) => v,
        Dataset::Series(_) => panic!("{}: volume expected", path.display()),
    }
}

/// `isoscope info --json` for `path`, as the CLI prints it (the stable interface).
fn info_json(path: &Path) -> serde_json::Value {
    let report = isoscope::cli::info::gather(path, &OpenOptions::default())
        .unwrap_or_else(|e| panic!("info {}: {e:#}", path.display()));
    serde_json::to_value(&report).unwrap()
}

/// Checks `info --json` against the values the test wrote: dims, type and the finite range
/// of `sample(t, offset..offset + N)`, computed here independently of the reader.
fn assert_info(json: &serde_json::Value, t: VoxelType, offset: usize, what: &str) {
    assert_eq!(json["dims"], serde_json::json!(DIMS), "{what}");
    assert_eq!(json["voxel_type"], t.name(), "{what}");
    let values = (offset..offset + N).map(|i| sample(t, i));
    let lo = values.clone().fold(f64::INFINITY, f64::min);
    let hi = values.fold(f64::NEG_INFINITY, f64::max);
    assert_eq!(json["value_range"], serde_json::json!([lo, hi]), "{what}");
    assert_eq!(json["nan_count"], 0, "{what}");
}

fn assert_voxels(v: &RectilinearVolume, t: VoxelType, offset: usize, what: &str) {
    assert_eq!(v.data.voxel_type(), t, "{what}");
    assert_eq!(v.dims(), DIMS, "{what}");
    for k in 0..DIMS[2] {
        for j in 0..DIMS[1] {
            for i in 0..DIMS[0] {
                let idx = i + DIMS[0] * (j + DIMS[1] * k);
                assert_eq!(
                    v.value_f64(i, j, k),
                    sample(t, offset + idx),
                    "{what}: voxel ({i},{j},{k})"
                );
            }
        }
    }
}

#[test]
fn every_type_in_every_unu_encoding_and_byte_order() {
    let Some(bin) = require_unu() else { return };
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let mut checked = 0;
    for t in VoxelType::ALL {
        let tn = t.name();
        std::fs::write(d.join(format!("{tn}.raw")), le_bytes(t, 0, N)).unwrap();
        let base = format!("{tn}.nrrd");
        unu(
            &bin,
            d,
            &[
                "make",
                "-i",
                &format!("{tn}.raw"),
                "-t",
                teem_name(t),
                "-s",
                "5",
                "4",
                "3",
                "-en",
                "little",
                "-sp",
                "0.5",
                "1",
                "2",
                "-o",
                &base,
            ],
        );
        for enc in ["raw", "gzip", "bzip2", "ascii", "hex"] {
            for endian in ["little", "big"] {
                // Ascii stores no byte order; `unu save -e ascii -en big` byte-swaps the values
                // themselves before printing them (a Teem quirk), so only the native order is a
                // meaningful ascii case.
                if enc == "ascii" && endian == "big" {
                    continue;
                }
                for ext in ["nrrd", "nhdr"] {
                    let out = format!("{tn}_{enc}_{endian}.{ext}");
                    unu(
                        &bin,
                        d,
                        &[
                            "save", "-f", "nrrd", "-e", enc, "-en", endian, "-i", &base, "-o", &out,
                        ],
                    );
                    let v = volume(&d.join(&out));
                    assert_voxels(&v, t, 0, &out);
                    let info = info_json(&d.join(&out));
                    assert_info(&info, t, 0, &out);
                    assert_eq!(info["spacing"], serde_json::json!([0.5, 1.0, 2.0]), "{out}");
                    assert_eq!(info["origin"], serde_json::json!([0.0, 0.0, 0.0]), "{out}");
                    assert!(info["world_from_grid"].is_null(), "{out}");
                    assert_eq!(v.grid.uniform_spacing(), Some([0.5, 1.0, 2.0]), "{out}");
                    assert_eq!(v.grid.origin().to_array(), [0.0; 3], "{out}");
                    assert_eq!(v.grid.world_from_grid(), None, "{out}");
                    checked += 1;
                }
            }
        }
    }
    assert_eq!(checked, 8 * (4 * 2 + 1) * 2);
}

/// World position of voxel (i, j, k) for origin (1,2,3) and directions (0,0.5,0) (-1,0,0)
/// (0,0,2): origin + i·d0 + j·d1 + k·d2.
fn world_oblique(i: usize, j: usize, k: usize) -> [f64; 3] {
    let (i, j, k) = (i as f64, j as f64, k as f64);
    [1.0 - j, 2.0 + 0.5 * i, 3.0 + 2.0 * k]
}

fn assert_close(got: [f64; 3], want: [f64; 3], at: (usize, usize, usize)) {
    let err = (0..3).map(|c| (got[c] - want[c]).abs()).fold(0.0, f64::max);
    assert!(
        err < 1e-12,
        "voxel {at:?}: world {got:?}, expected {want:?}"
    );
}

#[test]
fn space_directions_origin_and_detached_data_files() {
    let Some(bin) = require_unu() else { return };
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let t = VoxelType::I16;
    let slice = DIMS[0] * DIMS[1];
    for z in 0..DIMS[2] {
        std::fs::write(
            d.join(format!("s{z:03}.raw")),
            le_bytes(t, z * slice, slice),
        )
        .unwrap();
    }
    std::fs::write(d.join("all.raw"), le_bytes(t, 0, N)).unwrap();
    let dirs_oblique = "(0,0.5,0) (-1,0,0) (0,0,2)";
    let common = [
        "-t", "short", "-s", "5", "4", "3", "-en", "little", "-spc", "RAS", "-orig", "(1,2,3)",
    ];

    // Printf pattern of slice files, oblique directions.
    let mut args = vec!["make", "-h", "-i", "s%03d.raw", "0", "2", "1"];
    args.extend(common);
    args.extend(["-dirs", dirs_oblique, "-o", "pattern.nhdr"]);
    unu(&bin, d, &args);
    let v = volume(&d.join("pattern.nhdr"));
    assert_voxels(&v, t, 0, "pattern.nhdr");
    // `info --json` reports the oblique geometry: world = M · (origin + index · spacing) + t
    // must land every corner voxel where Teem's directions put it.
    let info = info_json(&d.join("pattern.nhdr"));
    assert_info(&info, t, 0, "pattern.nhdr info");
    let rows = &info["world_from_grid"];
    let spacing: Vec<f64> = (0..3)
        .map(|a| info["spacing"][a].as_f64().unwrap())
        .collect();
    let origin: Vec<f64> = (0..3)
        .map(|a| info["origin"][a].as_f64().unwrap())
        .collect();
    for (i, j, k) in [(0, 0, 0), (4, 0, 0), (0, 3, 0), (0, 0, 2), (4, 3, 2)] {
        let g = [
            origin[0] + i as f64 * spacing[0],
            origin[1] + j as f64 * spacing[1],
            origin[2] + k as f64 * spacing[2],
        ];
        let world: [f64; 3] = std::array::from_fn(|r| {
            let row = &rows[r];
            (0..3).map(|c| row[c].as_f64().unwrap() * g[c]).sum::<f64>() + row[3].as_f64().unwrap()
        });
        assert_close(world, world_oblique(i, j, k), (i, j, k));
    }
    let m = v
        .grid
        .world_from_grid()
        .expect("oblique directions give world_from_grid");
    for (i, j, k) in [(0, 0, 0), (4, 3, 2), (1, 2, 1)] {
        let got = m.transform_point3(v.grid.grid_position(i, j, k)).to_array();
        assert_close(got, world_oblique(i, j, k), (i, j, k));
    }

    // LIST of slice files, axis-aligned directions: a uniform grid at the origin.
    let mut args = vec!["make", "-h", "-i", "s000.raw", "s001.raw", "s002.raw"];
    args.extend(common);
    args.extend(["-dirs", "(0.5,0,0) (0,1,0) (0,0,2)", "-o", "list.nhdr"]);
    unu(&bin, d, &args);
    let header = std::fs::read_to_string(d.join("list.nhdr")).unwrap();
    assert!(header.contains("data file: LIST"), "{header}");
    let v = volume(&d.join("list.nhdr"));
    assert_voxels(&v, t, 0, "list.nhdr");
    assert_eq!(v.grid.world_from_grid(), None);
    assert_eq!(v.grid.uniform_spacing(), Some([0.5, 1.0, 2.0]));
    assert_eq!(v.grid.origin().to_array(), [1.0, 2.0, 3.0]);

    // One data file; then re-saved attached in gzip and big-endian by unu.
    let mut args = vec!["make", "-h", "-i", "all.raw"];
    args.extend(common);
    args.extend(["-dirs", dirs_oblique, "-o", "single.nhdr"]);
    unu(&bin, d, &args);
    assert_voxels(&volume(&d.join("single.nhdr")), t, 0, "single.nhdr");
    unu(
        &bin,
        d,
        &[
            "save",
            "-f",
            "nrrd",
            "-e",
            "gzip",
            "-en",
            "big",
            "-i",
            "single.nhdr",
            "-o",
            "oblique.nrrd",
        ],
    );
    let v = volume(&d.join("oblique.nrrd"));
    assert_voxels(&v, t, 0, "oblique.nrrd");
    let m = v.grid.world_from_grid().unwrap();
    let got = m.transform_point3(v.grid.grid_position(4, 3, 2)).to_array();
    assert_close(got, world_oblique(4, 3, 2), (4, 3, 2));

    // Line skip and byte skip given to unu make.
    let mut skipped = b"first line\nsecond\nXYZ".to_vec();
    skipped.extend(le_bytes(t, 0, N));
    std::fs::write(d.join("skip.dat"), skipped).unwrap();
    unu(
        &bin,
        d,
        &[
            "make",
            "-h",
            "-i",
            "skip.dat",
            "-t",
            "short",
            "-s",
            "5",
            "4",
            "3",
            "-en",
            "little",
            "-ls",
            "2",
            "-bs",
            "3",
            "-o",
            "skip.nhdr",
        ],
    );
    assert_voxels(&volume(&d.join("skip.nhdr")), t, 0, "skip.nhdr");
}

#[test]
fn four_d_time_series_and_leading_scalar_axis() {
    let Some(bin) = require_unu() else { return };
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let t = VoxelType::F32;
    let steps = 3;
    std::fs::write(d.join("t.raw"), le_bytes(t, 0, N * steps)).unwrap();
    unu(
        &bin,
        d,
        &[
            "make", "-i", "t.raw", "-t", "float", "-s", "5", "4", "3", "3", "-en", "little", "-k",
            "space", "space", "space", "time", "-sp", "1", "1", "1", "0.5", "-o", "t.nrrd",
        ],
    );
    for (enc, name) in [("raw", "t.nrrd"), ("gzip", "tg.nrrd"), ("bzip2", "tb.nhdr")] {
        if name != "t.nrrd" {
            unu(
                &bin,
                d,
                &["save", "-f", "nrrd", "-e", enc, "-i", "t.nrrd", "-o", name],
            );
        }
        let Dataset::Series(ts) = open(&d.join(name)) else {
            panic!("{name}: series expected")
        };
        assert_eq!(ts.step_count(), steps, "{name}");
        assert_eq!(ts.time_value(2), 1.0, "{name}");
        for s in [2, 0, 1] {
            assert_voxels(&ts.step(s).unwrap(), t, s * N, &format!("{name} step {s}"));
        }
    }
    // One file per step (unu make -fd 3 with a pattern).
    for s in 0..steps {
        std::fs::write(d.join(format!("step{s}.raw")), le_bytes(t, s * N, N)).unwrap();
    }
    unu(
        &bin,
        d,
        &[
            "make",
            "-h",
            "-i",
            "step%d.raw",
            "0",
            "2",
            "1",
            "3",
            "-t",
            "float",
            "-s",
            "5",
            "4",
            "3",
            "3",
            "-en",
            "little",
            "-k",
            "space",
            "space",
            "space",
            "time",
            "-o",
            "steps.nhdr",
        ],
    );
    let Dataset::Series(ts) = open(&d.join("steps.nhdr")) else {
        panic!("steps.nhdr: series expected")
    };
    assert_eq!(ts.step_count(), steps);
    assert_voxels(&ts.step(1).unwrap(), t, N, "steps.nhdr step 1");

    // A leading axis of size 1 (scalar kind) is dropped.
    std::fs::write(d.join("one.raw"), le_bytes(t, 0, N)).unwrap();
    unu(
        &bin,
        d,
        &[
            "make", "-i", "one.raw", "-t", "float", "-s", "1", "5", "4", "3", "-en", "little",
            "-k", "scalar", "space", "space", "space", "-o", "one.nrrd",
        ],
    );
    assert_voxels(&volume(&d.join("one.nrrd")), t, 0, "one.nrrd");
}
