//! The DICOM reader against files written by other programs and what those programs report.
//!
//! `tests/data/dicom/` holds real files from pydicom's test data (CT, MR in five transfer
//! syntaxes, deflate, JPEG 2000, RT Dose, a DICOMDIR set written by DCMTK) and series written
//! by `make_dicom.py` with pydicom, SimpleITK/GDCM (JPEG lossless, JPEG 2000) and Pillow (JPEG
//! baseline). `truth.json` is what pydicom + numpy (or GDCM) report: dims, stored values,
//! rescale, and the LPS position of the corner voxels computed from each slice's own
//! ImagePositionPatient / ImageOrientationPatient / PixelSpacing; or the error expected.

use std::path::{Path, PathBuf};

use formats::{Dataset, FormatError, OpenOptions};
use glam::DVec3;
use serde_json::Value;
use volume_core::{AxisCoords, RectilinearVolume, WorldFrame};

fn data_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/dicom")
}

fn truth() -> serde_json::Map<String, Value> {
    let text = std::fs::read_to_string(data_dir().join("truth.json")).unwrap();
    let v: Value = serde_json::from_str(&text).unwrap();
    v["cases"].as_object().unwrap().clone()
}

fn open_case(case: &Value) -> Result<Dataset, FormatError> {
    let options = OpenOptions {
        dicom_series: case["pick"].as_str().map(String::from),
        ..OpenOptions::default()
    };
    formats::open(&data_dir().join(case["path"].as_str().unwrap()), &options)
}

fn f64s(v: &Value) -> Vec<f64> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect()
}

/// Every stored (or, for `f32` conversions, physical) value, x fastest.
fn values(v: &RectilinearVolume) -> Vec<f64> {
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

fn world(v: &RectilinearVolume, i: usize, j: usize, k: usize) -> DVec3 {
    let p = v.grid.grid_position(i, j, k);
    v.grid
        .world_from_grid()
        .map_or(p, |m| m.transform_point3(p))
}

/// Checks a volume against a truth entry: dims, type, rescale, values, corner positions.
fn check_volume(name: &str, case: &Value, v: &RectilinearVolume, expected_values: &[f64]) {
    let dims: Vec<usize> = f64s(&case["dims"]).iter().map(|&d| d as usize).collect();
    assert_eq!(v.dims().to_vec(), dims, "{name}: dims");
    if let Some(t) = case["dtype"].as_str() {
        assert_eq!(v.data.voxel_type().name(), t, "{name}: voxel type");
    }
    assert_eq!(v.grid.world_frame(), WorldFrame::Lps, "{name}: world frame");
    if let Some(slope) = case["slope"].as_f64() {
        assert_eq!(v.value_map.slope, slope, "{name}: slope");
        assert_eq!(
            v.value_map.intercept,
            case["intercept"].as_f64().unwrap(),
            "{name}: intercept"
        );
    }
    let tolerance = case["tolerance"].as_f64().unwrap_or(0.0);
    let got = values(v);
    if case.get("voxel_stride").is_some() {
        let stride = case["voxel_stride"].as_u64().unwrap() as usize;
        let sampled = f64s(&case["voxels_sampled"]);
        let ours: Vec<f64> = got.iter().copied().step_by(stride).collect();
        assert_eq!(ours.len(), sampled.len(), "{name}: sampled count");
        let worst = ours
            .iter()
            .zip(&sampled)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        assert!(
            worst <= tolerance,
            "{name}: sampled values differ by {worst}"
        );
        let min = got.iter().copied().fold(f64::INFINITY, f64::min);
        let max = got.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        if tolerance == 0.0 {
            assert_eq!(
                got.iter().sum::<f64>(),
                case["sum"].as_f64().unwrap(),
                "{name}"
            );
            assert_eq!(
                (min, max),
                (case["min"].as_f64().unwrap(), case["max"].as_f64().unwrap())
            );
        }
    } else {
        assert_eq!(got.len(), expected_values.len(), "{name}: voxel count");
        let worst = got
            .iter()
            .zip(expected_values)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        assert!(
            worst
                <= tolerance.max(1e-4 * expected_values.iter().fold(0.0f64, |m, x| m.max(x.abs()))),
            "{name}: values differ by up to {worst}"
        );
    }
    for c in case["corners"].as_array().unwrap() {
        let ijk: Vec<usize> = f64s(&c["ijk"]).iter().map(|&x| x as usize).collect();
        let lps = f64s(&c["lps"]);
        let p = world(v, ijk[0], ijk[1], ijk[2]);
        let d = p.distance(DVec3::new(lps[0], lps[1], lps[2]));
        assert!(
            d < 2e-3,
            "{name}: voxel {ijk:?} at {p}, pydicom+numpy say {lps:?} ({d} mm off)"
        );
    }
    if let Some(uniform) = case["uniform"].as_bool() {
        assert_eq!(
            v.grid.axis(2).is_uniform(),
            uniform,
            "{name}: slice axis kind"
        );
    }
}

#[test]
fn volumes_match_what_pydicom_reports() {
    let mut checked = 0;
    for (name, case) in truth() {
        if case.get("error").is_some() || case.get("phases").is_some() {
            continue;
        }
        let d = open_case(&case).unwrap_or_else(|e| panic!("{name}: {e}"));
        let Dataset::Volume(v) = d else {
            panic!("{name}: a volume expected")
        };
        check_volume(
            &name,
            &case,
            &v,
            &f64s(&case["voxels"].clone().take_or_empty()),
        );
        checked += 1;
    }
    assert!(checked >= 20, "{checked} volumes checked");
}

trait TakeOrEmpty {
    fn take_or_empty(self) -> Value;
}

impl TakeOrEmpty for Value {
    fn take_or_empty(self) -> Value {
        if self.is_array() {
            self
        } else {
            Value::Array(Vec::new())
        }
    }
}

#[test]
fn errors_name_the_problem_and_the_file() {
    let mut checked = 0;
    for (name, case) in truth() {
        let Some(expected) = case["error"].as_str() else {
            continue;
        };
        let result = std::panic::catch_unwind(|| open_case(&case));
        let Ok(result) = result else {
            panic!("{name}: panicked")
        };
        let e = result
            .err()
            .unwrap_or_else(|| panic!("{name}: opened, expected an error"));
        let text = e.to_string();
        assert!(
            text.contains(expected),
            "{name}: `{text}` lacks `{expected}`"
        );
        for also in case["error_also"].as_array().into_iter().flatten() {
            let also = also.as_str().unwrap();
            assert!(text.contains(also), "{name}: `{text}` lacks `{also}`");
        }
        checked += 1;
    }
    assert!(checked >= 12, "{checked} errors checked");
}

#[test]
fn pixel_spacing_is_row_spacing_then_column_spacing() {
    // oblique: PixelSpacing [0.7, 0.4] = [Δ between rows, Δ between columns], 12 columns.
    let case = &truth()["oblique"];
    let Dataset::Volume(v) = open_case(case).unwrap() else {
        panic!()
    };
    assert_eq!(v.dims()[0], 12);
    let spacing = |a: usize| match v.grid.axis(a) {
        AxisCoords::Uniform { spacing, .. } => *spacing,
        AxisCoords::Explicit(_) => panic!("uniform"),
    };
    assert!(
        (spacing(0) - 0.4).abs() < 1e-9,
        "i (along a row) is the column spacing"
    );
    assert!(
        (spacing(1) - 0.7).abs() < 1e-9,
        "j (down a column) is the row spacing"
    );
    assert!(
        (spacing(2) - 1.5).abs() < 1e-6,
        "slice spacing from the positions, not 99"
    );
    // Physical values through the rescale (slope 2, intercept -100).
    let stored = v.value_f64(3, 4, 2);
    assert_eq!(v.physical_f64(3, 4, 2), 2.0 * stored - 100.0);
}

#[test]
fn one_file_opens_its_series_and_a_glob_is_a_list_of_files() {
    let dir = data_dir().join("synthetic/oblique");
    let one = std::fs::read_dir(&dir)
        .unwrap()
        .next()
        .unwrap()
        .unwrap()
        .path();
    let d = formats::open(&one, &OpenOptions::default()).unwrap();
    assert_eq!(d.first_volume().dims(), [12, 10, 6]);
    let d = formats::open(
        &data_dir().join("synthetic/uneven/s*.dcm"),
        &OpenOptions::default(),
    )
    .unwrap();
    assert_eq!(d.first_volume().dims(), [8, 7, 5]);
}

#[test]
fn several_series_are_listed_and_picked() {
    let case = &truth()["two_series"];
    let listing = formats::dicom::list(&data_dir().join("synthetic/two_series")).unwrap();
    let expected = case["series"].as_array().unwrap();
    assert_eq!(listing.series.len(), expected.len());
    for (s, e) in listing.series.iter().zip(expected) {
        assert_eq!(s.uid, e["uid"].as_str().unwrap());
        assert_eq!(s.modality, e["modality"].as_str().unwrap());
        assert_eq!(s.description, e["description"].as_str().unwrap());
        assert_eq!(s.number, e["number"].as_i64());
        let dims: Vec<usize> = f64s(&e["dims"]).iter().map(|&x| x as usize).collect();
        assert_eq!(s.dims.to_vec(), dims);
        assert_eq!(s.files as u64, e["files"].as_u64().unwrap());
        assert!(s.problem.is_none(), "{:?}", s.problem);
        assert!(s.transfer_syntax.starts_with("1.2.840.10008.1.2.1 "));
    }
    for name in case["skipped"].as_array().unwrap() {
        let name = name.as_str().unwrap();
        assert!(
            listing
                .skipped
                .iter()
                .any(|s| s.path.file_name().unwrap() == name),
            "{name} not noted as skipped: {:?}",
            listing.skipped
        );
    }
    let sr = listing
        .skipped
        .iter()
        .find(|s| s.path.ends_with("report.dcm"))
        .unwrap();
    assert!(sr.reason.contains("Basic Text SR"), "{}", sr.reason);
    // Without a pick: the error says how to pick.
    let e = formats::open(
        &data_dir().join("synthetic/two_series"),
        &OpenOptions::default(),
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("2 series in") && e.contains("--series N") && e.contains("isoscope info"),
        "{e}"
    );
    for bad in ["0", "3", "1.2.3"] {
        let o = OpenOptions {
            dicom_series: Some(bad.into()),
            ..OpenOptions::default()
        };
        let e = formats::open(&data_dir().join("synthetic/two_series"), &o).unwrap_err();
        assert!(e.to_string().contains(&format!("--series {bad}")), "{e}");
    }
}

#[test]
fn a_split_series_lists_its_parts() {
    let listing = formats::dicom::list(&data_dir().join("synthetic/split")).unwrap();
    assert_eq!(listing.series.len(), 2);
    assert_eq!(listing.series[0].uid, listing.series[1].uid);
    let mut parts: Vec<_> = listing.series.iter().map(|s| (s.part, s.dims)).collect();
    parts.sort();
    assert_eq!(parts, vec![(Some(1), [4, 4, 2]), (Some(2), [4, 5, 1])]);
    let o = OpenOptions {
        dicom_series: Some("2".into()),
        ..OpenOptions::default()
    };
    let d = formats::open(&data_dir().join("synthetic/split"), &o).unwrap();
    assert!(d.first_volume().dims()[2] >= 1);
}

#[test]
fn repeated_positions_with_temporal_positions_are_phases() {
    let case = &truth()["phases"];
    let Dataset::Series(ts) = open_case(case).unwrap() else {
        panic!("a time series expected")
    };
    assert_eq!(ts.step_count(), 2);
    for (step, expected) in case["phase_voxels"].as_array().unwrap().iter().enumerate() {
        let v = ts.step(step).unwrap();
        assert_eq!(v.dims(), [4, 4, 3]);
        assert_eq!(values(&v), f64s(expected), "phase {step}");
        assert_eq!(ts.time_value(step), (step + 1) as f64);
    }
}

#[test]
fn dicomdir_records_are_followed() {
    let cases = truth();
    for name in [
        "real/DICOMDIR",
        "real/DICOMDIR-bigEnd",
        "real/DICOMDIR-implicit",
    ] {
        let case = &cases[name];
        let listing = formats::dicom::list(&data_dir().join(case["path"].as_str().unwrap()))
            .unwrap_or_else(|e| panic!("{name}: {e}"));
        let mut uids: Vec<String> = listing.series.iter().map(|s| s.uid.clone()).collect();
        uids.sort();
        uids.dedup();
        let expected: Vec<String> = case["series_uids"]
            .as_array()
            .unwrap()
            .iter()
            .map(|u| u.as_str().unwrap().to_string())
            .collect();
        assert_eq!(uids, expected, "{name}: series");
        let files: usize = listing.series.iter().map(|s| s.files).sum();
        assert_eq!(
            (files + listing.skipped.len()) as u64,
            case["referenced_files"].as_u64().unwrap(),
            "{name}: referenced files"
        );
    }
}

#[test]
fn every_fixture_opens_or_fails_without_panicking() {
    fn walk(dir: &Path, out: &mut Vec<PathBuf>) {
        for e in std::fs::read_dir(dir).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                out.push(p.clone());
                walk(&p, out);
            } else if p
                .extension()
                .is_none_or(|x| x != "py" && x != "json" && x != "md")
            {
                out.push(p);
            }
        }
    }
    let mut all = Vec::new();
    walk(&data_dir(), &mut all);
    assert!(all.len() > 60);
    for p in all {
        let r = std::panic::catch_unwind(|| {
            let _ = formats::dicom::list(&p);
            let _ = formats::open(&p, &OpenOptions::default());
        });
        assert!(r.is_ok(), "{} panicked", p.display());
    }
}

#[test]
fn a_broken_file_beside_one_opened_file_is_skipped_only_if_not_of_its_series() {
    let dir = tempfile::tempdir().unwrap();
    let src = data_dir().join("synthetic/uneven");
    let mut names: Vec<PathBuf> = std::fs::read_dir(&src)
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    names.sort();
    for p in &names {
        std::fs::copy(p, dir.path().join(p.file_name().unwrap())).unwrap();
    }
    // A truncated DICOM file of another series: skipped with a note.
    let other = std::fs::read(data_dir().join("bad/truncated/truncated.dcm")).unwrap();
    std::fs::write(dir.path().join("zz_other.dcm"), &other).unwrap();
    let one = dir.path().join(names[0].file_name().unwrap());
    let d = formats::open(&one, &OpenOptions::default()).unwrap();
    assert_eq!(d.first_volume().dims(), [8, 7, 5]);
    // A truncated slice of the same series: an error naming it.
    let mut own = std::fs::read(&names[1]).unwrap();
    own.truncate(own.len() - 5);
    std::fs::write(dir.path().join("zz_own.dcm"), &own).unwrap();
    let e = formats::open(&one, &OpenOptions::default()).unwrap_err();
    assert!(e.to_string().contains("zz_own.dcm"), "{e}");
    // The folder itself: every DICOM file must read.
    let e = formats::open(dir.path(), &OpenOptions::default()).unwrap_err();
    assert!(e.to_string().contains("zz_o"), "{e}");
}
