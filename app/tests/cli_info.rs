//! `isoscope info` end to end. The truth is the in-memory volume (from `data-samples` or built
//! here): dims, type, spacing and origin from its grid, the value range and histogram by brute
//! force over its voxels. Files are written with `formats::nrrd::write_nrrd` or by hand (raw).

mod common;
use common::isoscope;

use std::path::Path;

use data_samples::Generator;
use formats::nrrd::{NrrdEncoding, write_nrrd};
use glam::{DAffine3, DMat3, DVec3};
use serde_json::Value;
use volume_core::{AxisCoords, Grid, RectilinearVolume, VoxelType};

fn info_json(path: &Path, extra: &[&str]) -> Value {
    let mut args = vec!["info", path.to_str().unwrap(), "--json"];
    args.extend_from_slice(extra);
    let out = isoscope(&args);
    assert!(
        out.status.success(),
        "info {} failed: {}",
        path.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).expect("info --json prints JSON")
}

/// Equal up to float *parsing*: serde_json (without `float_roundtrip`) may read a printed
/// shortest-round-trip number back one ulp off; the printed text itself is exact.
fn assert_close(got: &[f64], want: &[f64], what: &str) {
    assert_eq!(got.len(), want.len(), "{what}: {got:?} vs {want:?}");
    for (g, w) in got.iter().zip(want) {
        let tol = 4.0 * f64::EPSILON * g.abs().max(w.abs());
        assert!((g - w).abs() <= tol, "{what}: {got:?} vs {want:?}");
    }
}

fn f64s(v: &Value) -> Vec<f64> {
    v.as_array()
        .unwrap_or_else(|| panic!("not an array: {v}"))
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect()
}

/// All voxels as f64, x fastest.
fn voxels(v: &RectilinearVolume) -> Vec<f64> {
    let [nx, ny, nz] = v.dims();
    let mut out = Vec::with_capacity(nx * ny * nz);
    for k in 0..nz {
        for j in 0..ny {
            for i in 0..nx {
                out.push(v.value_f64(i, j, k));
            }
        }
    }
    out
}

/// Brute-force range of the finite values.
fn finite_range(values: &[f64]) -> Option<[f64; 2]> {
    let finite: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
    if finite.is_empty() {
        return None;
    }
    Some([
        finite.iter().copied().fold(f64::INFINITY, f64::min),
        finite.iter().copied().fold(f64::NEG_INFINITY, f64::max),
    ])
}

/// Brute-force 64-bin histogram, last bin closed.
fn histogram(values: &[f64], lo: f64, hi: f64) -> Vec<u64> {
    let mut c = vec![0u64; 64];
    for &x in values.iter().filter(|x| x.is_finite()) {
        let b = if hi > lo {
            (((x - lo) / (hi - lo)) * 64.0).floor() as usize
        } else {
            0
        };
        c[b.min(63)] += 1;
    }
    c
}

/// Checks the report of `path` against the in-memory `volume` (single volume).
fn check_report(j: &Value, volume: &RectilinearVolume) {
    let dims = volume.dims();
    assert_eq!(j["dims"], serde_json::json!(dims), "dims");
    assert_eq!(
        j["voxel_type"],
        volume.data.voxel_type().name(),
        "voxel_type"
    );
    let spacing = volume.grid.uniform_spacing().unwrap();
    assert_close(&f64s(&j["spacing"]), &spacing, "spacing");
    assert!(j["coordinates"].is_null());
    assert_close(
        &f64s(&j["origin"]),
        &volume.grid.origin().to_array(),
        "origin",
    );
    let values = voxels(volume);
    let range = finite_range(&values);
    if let Some([lo, hi]) = range {
        assert_close(&f64s(&j["value_range"]), &[lo, hi], "value_range");
        assert_eq!(f64s(&j["histogram"]["counts"]).len(), 64);
        let counts: Vec<u64> = j["histogram"]["counts"]
            .as_array()
            .unwrap()
            .iter()
            .map(|c| c.as_u64().unwrap())
            .collect();
        assert_eq!(counts, histogram(&values, lo, hi), "histogram");
    } else {
        assert!(j["value_range"].is_null());
        assert!(j["histogram"].is_null());
    }
    let nan = values.iter().filter(|x| x.is_nan()).count() as u64;
    let inf = values.iter().filter(|x| x.is_infinite()).count() as u64;
    assert_eq!(j["nan_count"], nan);
    assert_eq!(j["inf_count"], inf);
    assert_eq!(j["time_steps"], 1);
    assert_eq!(j["voxel_count"], (dims[0] * dims[1] * dims[2]) as u64);
}

#[test]
fn info_json_matches_every_generator_in_memory() {
    let dir = tempfile::tempdir().unwrap();
    let cases = [
        (
            Generator::MarschnerLobb,
            [41, 41, 41],
            VoxelType::U8,
            NrrdEncoding::Raw,
        ),
        (
            Generator::Sphere,
            [32, 30, 28],
            VoxelType::F32,
            NrrdEncoding::Gzip,
        ),
        (
            Generator::Torus,
            [20, 20, 20],
            VoxelType::F64,
            NrrdEncoding::Raw,
        ),
        (
            Generator::NestedSpheres,
            [17, 17, 17],
            VoxelType::U16,
            NrrdEncoding::Gzip,
        ),
        (
            Generator::Phantom,
            [64, 64, 28],
            VoxelType::I16,
            NrrdEncoding::Gzip,
        ),
        (
            Generator::Phantom,
            [32, 32, 14],
            VoxelType::I32,
            NrrdEncoding::Raw,
        ),
    ];
    for (g, dims, t, enc) in cases {
        let v = g.generate(dims, t).unwrap();
        let path = dir.path().join(format!("{g}_{t}.nrrd"));
        write_nrrd(&path, &v, enc, formats::output::Replace::Refuse).unwrap();
        let j = info_json(&path, &[]);
        check_report(&j, &v);
        assert_eq!(j["file"], path.to_str().unwrap());
        assert!(j["world_from_grid"].is_null());
    }
}

#[test]
fn generate_then_info_round_trip_through_the_cli() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("phantom.nrrd");
    let out = isoscope(&[
        "generate",
        "phantom",
        "--size",
        "48",
        "--encoding",
        "gzip",
        "-o",
        path.to_str().unwrap(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let j = info_json(&path, &[]);
    let truth = Generator::Phantom
        .generate(Generator::Phantom.dims_for_size(48), VoxelType::I16)
        .unwrap();
    check_report(&j, &truth);
    // The phantom's documented geometry and values.
    assert_eq!(j["dims"], serde_json::json!([48, 48, 21]));
    let s = data_samples::phantom::spacing_for([48, 48, 21]);
    assert_close(&f64s(&j["spacing"]), &s, "phantom spacing");
    assert!(s[2] > s[0], "anisotropic");
    assert_eq!(j["value_range"][0], -1000.0);
    assert!(j["value_range"][1].as_f64().unwrap() > 1000.0);
}

#[test]
fn non_finite_values_are_counted_and_excluded_from_the_range() {
    let dir = tempfile::tempdir().unwrap();
    let g = Grid::uniform([4, 3, 2], [1.0, -2.0, 0.5], [0.5, 0.25, 2.0]).unwrap();
    let mut vals: Vec<f32> = (0..24).map(|i| i as f32 * 0.5 - 3.0).collect();
    vals[0] = f32::NAN;
    vals[5] = f32::INFINITY;
    vals[23] = f32::NEG_INFINITY;
    vals[7] = f32::NAN;
    let v = RectilinearVolume::new(g.clone(), vals.into()).unwrap();
    let path = dir.path().join("nan.nrrd");
    write_nrrd(
        &path,
        &v,
        NrrdEncoding::Raw,
        formats::output::Replace::Refuse,
    )
    .unwrap();
    let j = info_json(&path, &[]);
    check_report(&j, &v);
    assert_eq!(j["nan_count"], 2);
    assert_eq!(j["inf_count"], 2);
    assert_eq!(f64s(&j["value_range"]), vec![-2.5, 8.0]);

    let all_nan = RectilinearVolume::new(g, vec![f64::NAN; 24].into()).unwrap();
    let path = dir.path().join("void.nrrd");
    write_nrrd(
        &path,
        &all_nan,
        NrrdEncoding::Gzip,
        formats::output::Replace::Refuse,
    )
    .unwrap();
    let j = info_json(&path, &[]);
    check_report(&j, &all_nan);
    assert_eq!(j["nan_count"], 24);
    let text = String::from_utf8(isoscope(&["info", path.to_str().unwrap()]).stdout).unwrap();
    assert!(text.contains("no finite voxel"), "{text}");
}

#[test]
fn oriented_volumes_report_world_from_grid() {
    let dir = tempfile::tempdir().unwrap();
    let rot = DMat3::from_axis_angle(DVec3::new(1.0, 2.0, 3.0).normalize(), 0.7);
    let m = DAffine3::from_mat3_translation(rot, DVec3::new(10.0, -4.0, 2.5));
    let u = |o: f64, s: f64| AxisCoords::Uniform {
        origin: o,
        spacing: s,
    };
    let grid = Grid::new(
        [5, 4, 3],
        [u(0.5, 1.5), u(-1.0, 0.75), u(2.0, 2.0)],
        Some(m),
    )
    .unwrap();
    let v = RectilinearVolume::new(grid, (0..60u16).collect::<Vec<_>>().into()).unwrap();
    let path = dir.path().join("oriented.nrrd");
    write_nrrd(
        &path,
        &v,
        NrrdEncoding::Raw,
        formats::output::Replace::Refuse,
    )
    .unwrap();
    let j = info_json(&path, &[]);
    let rows = j["world_from_grid"]
        .as_array()
        .expect("world_from_grid is set");
    assert_eq!(rows.len(), 3);
    let r: Vec<Vec<f64>> = rows.iter().map(f64s).collect();
    let spacing = f64s(&j["spacing"]);
    let origin = f64s(&j["origin"]);
    // Every corner lands at the same world position as in memory.
    for (i, jj, k) in [(0, 0, 0), (4, 0, 0), (0, 3, 0), (0, 0, 2), (4, 3, 2)] {
        let g = [
            origin[0] + i as f64 * spacing[0],
            origin[1] + jj as f64 * spacing[1],
            origin[2] + k as f64 * spacing[2],
        ];
        let world: Vec<f64> = (0..3)
            .map(|a| r[a][0] * g[0] + r[a][1] * g[1] + r[a][2] * g[2] + r[a][3])
            .collect();
        let want = m.transform_point3(v.grid.grid_position(i, jj, k));
        for a in 0..3 {
            assert!(
                (world[a] - want[a]).abs() < 1e-9,
                "corner {i},{jj},{k}: {world:?} vs {want}"
            );
        }
    }
    assert_eq!(f64s(&j["value_range"]), vec![0.0, 59.0]);
    let text = String::from_utf8(isoscope(&["info", path.to_str().unwrap()]).stdout).unwrap();
    assert!(text.contains("world_from_grid"), "{text}");
}

#[test]
fn raw_flags_open_a_headerless_file() {
    let dir = tempfile::tempdir().unwrap();
    let truth = Generator::Phantom
        .generate([20, 18, 9], VoxelType::I16)
        .unwrap();
    let volume_core::VoxelData::I16(buf) = &truth.data else {
        unreachable!()
    };
    // Big-endian with a 16-byte header to skip.
    let mut bytes = vec![0xAAu8; 16];
    for v in buf.as_slice() {
        bytes.extend_from_slice(&v.to_be_bytes());
    }
    let path = dir.path().join("head.raw");
    std::fs::write(&path, &bytes).unwrap();
    let s = truth.grid.uniform_spacing().unwrap();
    let o = truth.grid.origin();
    let spacing = format!("{},{},{}", s[0], s[1], s[2]);
    let origin = format!("{},{},{}", o.x, o.y, o.z);
    let flags = [
        "--dims",
        "20x18x9",
        "--type",
        "i16",
        "--endian",
        "big",
        "--header-bytes",
        "16",
        "--spacing",
        &spacing,
        "--origin",
        &origin,
    ];
    let j = info_json(&path, &flags);
    check_report(&j, &truth);

    // Missing byte order for a 2-byte type, wrong size, incomplete flags: clear errors.
    let p = path.to_str().unwrap();
    let out = isoscope(&["info", p, "--dims", "20x18x9", "--type", "i16"]);
    let e = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && e.contains("--endian"), "{e}");
    let out = isoscope(&[
        "info", p, "--dims", "20x18x10", "--type", "i16", "--endian", "big",
    ]);
    let e = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && e.contains("head.raw"), "{e}");
    let out = isoscope(&["info", p, "--spacing", "1,1,1"]);
    let e = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && e.contains("--dims"), "{e}");
    let out = isoscope(&["info", p, "--dims", "20x18", "--type", "i16"]);
    let e = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && e.contains("256x256x108"), "{e}");
}

#[test]
fn series_report_covers_all_steps() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("blobs.nrrd");
    let o = isoscope(&[
        "generate",
        "blobs",
        "--size",
        "12",
        "--steps",
        "5",
        "--type",
        "u8",
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let pattern = dir.path().join("blobs_%03d.nrrd");
    let j = info_json(&pattern, &[]);
    assert_eq!(j["time_steps"], 5);
    assert_eq!(f64s(&j["time_values"]).len(), 5);
    assert_eq!(j["voxel_type"], "u8");
    let blobs = data_samples::blobs::Blobs::new([12; 3], VoxelType::U8, 5).unwrap();
    let all: Vec<f64> = (0..5)
        .flat_map(|s| voxels(&blobs.step(s, &|| {}).unwrap()))
        .collect();
    let [lo, hi] = finite_range(&all).unwrap();
    assert_close(&f64s(&j["value_range"]), &[lo, hi], "series range");
    let counts: Vec<u64> = j["histogram"]["counts"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| c.as_u64().unwrap())
        .collect();
    assert_eq!(counts, histogram(&all, lo, hi));
    let text = String::from_utf8(isoscope(&["info", pattern.to_str().unwrap()]).stdout).unwrap();
    assert!(text.contains("time steps:   5"), "{text}");
}

#[test]
fn text_output_shows_geometry_range_and_a_64_bin_histogram() {
    let dir = tempfile::tempdir().unwrap();
    let v = Generator::MarschnerLobb
        .generate([21; 3], VoxelType::U8)
        .unwrap();
    let path = dir.path().join("ml.nrrd");
    write_nrrd(
        &path,
        &v,
        NrrdEncoding::Raw,
        formats::output::Replace::Refuse,
    )
    .unwrap();
    let out = isoscope(&["info", path.to_str().unwrap()]);
    assert!(out.status.success());
    let text = String::from_utf8(out.stdout).unwrap();
    for needle in [
        "dims:         21 x 21 x 21",
        "voxel type:   u8",
        "spacing:      0.1, 0.1, 0.1",
        "origin:       -1, -1, -1",
        "axis-aligned",
        "time steps:   1",
    ] {
        assert!(text.contains(needle), "missing `{needle}` in\n{text}");
    }
    let [lo, hi] = finite_range(&voxels(&v)).unwrap();
    assert!(
        text.contains(&format!("value range:  {lo} .. {hi}")),
        "{text}"
    );
    assert_eq!(text.lines().filter(|l| l.contains(" | ")).count(), 64);
}

#[test]
fn missing_and_unknown_files_are_errors_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("nope.nrrd");
    let out = isoscope(&["info", missing.to_str().unwrap()]);
    let e = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && e.contains("nope.nrrd"), "{e}");
    let odd = dir.path().join("data.bin");
    std::fs::write(&odd, [1u8, 2, 3]).unwrap();
    let out = isoscope(&["info", odd.to_str().unwrap()]);
    let e = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && e.contains("data.bin"), "{e}");
}

/// DICOM inputs (fixtures of `formats/tests/dicom.rs`, written by pydicom): a folder of two
/// series is listed (text and JSON, exit 0), `--series` opens one for `info` and `render`,
/// without it `render` refuses and says how to pick, and a CT slice reports LPS labels and
/// its Hounsfield rescale.
#[test]
fn dicom_folders_list_their_series_and_series_picks_one() {
    let data = Path::new(env!("CARGO_MANIFEST_DIR")).join("../formats/tests/data/dicom");
    let two = data.join("synthetic/two_series");
    let listed = info_json(&two, &[]);
    assert_eq!(listed["kind"], "dicom");
    let series = listed["dicom_series"].as_array().unwrap();
    assert_eq!(series.len(), 2);
    assert_eq!(series[0]["modality"], "CT");
    assert_eq!(series[1]["modality"], "MR");
    assert_eq!(series[1]["dims"], serde_json::json!([5, 5, 3]));
    assert_eq!(series[1]["index"], 2);
    assert!(
        listed["dicom_skipped"]
            .as_array()
            .unwrap()
            .iter()
            .any(|s| s["path"].as_str().unwrap().ends_with("report.dcm")),
        "{listed}"
    );
    let text = common::ok(&["info", two.to_str().unwrap()]);
    assert!(
        text.contains("DICOM series: 2") && text.contains("MR T1") && text.contains("--series N"),
        "{text}"
    );

    let mr = info_json(&two, &["--series", "2"]);
    assert_eq!(mr["kind"], "grid");
    assert_eq!(mr["dims"], serde_json::json!([5, 5, 3]));
    assert_eq!(mr["world_frame"], "LPS");
    assert_eq!(mr["dicom_opened"], 2);
    assert_eq!(mr["dicom_series"].as_array().unwrap().len(), 2);

    let e = common::fails(&[
        "render",
        two.to_str().unwrap(),
        "-o",
        "/nonexistent-dir/x.png",
    ]);
    assert!(e.contains("2 series in") && e.contains("--series N"), "{e}");
    let e = common::fails(&["info", two.to_str().unwrap(), "--series", "7"]);
    assert!(e.contains("--series 7"), "{e}");

    let ct = info_json(&data.join("real/CT_small/CT_small.dcm"), &[]);
    assert_eq!(ct["dims"], serde_json::json!([128, 128, 1]));
    assert_eq!(ct["axis_labels"], serde_json::json!(["L", "P", "S"]));
    assert_eq!(
        ct["value_map"],
        serde_json::json!({"slope": 1.0, "intercept": -1024.0})
    );
    assert_eq!(ct["dicom_opened"], 1);
}
