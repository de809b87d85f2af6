//! The MetaImage, VTK image data and TIFF readers against files written by SimpleITK, VTK,
//! tifffile and Pillow (`tests/data/{metaimage,vtk_image,tiff}/`, made by
//! `tests/data/make_images.py`), compared with what those libraries report about the same
//! files (`truth.json` in each folder): dims, voxel type, spacing, axis directions, world
//! frame, voxel values, world positions of the corner voxels, time steps. Then bad input:
//! each damaged file fails with its specific error naming the file, never a panic.

use std::path::{Path, PathBuf};

use formats::{Dataset, FormatError, OpenOptions};
use glam::DVec3;
use serde_json::Value;
use volume_core::RectilinearVolume;

fn data(folder: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data")
        .join(folder)
}

fn truth(folder: &str) -> Vec<Value> {
    let text = std::fs::read_to_string(data(folder).join("truth.json")).unwrap();
    serde_json::from_str::<Value>(&text)
        .unwrap()
        .as_array()
        .unwrap()
        .clone()
}

fn f(v: &Value) -> f64 {
    v.as_f64().unwrap_or_else(|| panic!("{v} is not a number"))
}

fn vec3(v: &Value) -> DVec3 {
    DVec3::new(f(&v[0]), f(&v[1]), f(&v[2]))
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-6 * a.abs().max(b.abs()).max(1.0)
}

/// World position of voxel (i, j, k).
fn world(v: &RectilinearVolume, i: usize, j: usize, k: usize) -> DVec3 {
    let p = v.grid.grid_position(i, j, k);
    v.grid
        .world_from_grid()
        .map_or(p, |m| m.transform_point3(p))
}

fn options(t: &Value) -> OpenOptions {
    OpenOptions {
        spacing: t["options_spacing"]
            .as_array()
            .map(|s| [f(&s[0]), f(&s[1]), f(&s[2])]),
        ..OpenOptions::default()
    }
}

/// The checks shared by every format: geometry, type and values of `v` against entry `t`.
fn check_volume(name: &str, v: &RectilinearVolume, t: &Value, samples: &Value, dtype: &Value) {
    let dims: Vec<usize> = t["dims"]
        .as_array()
        .unwrap()
        .iter()
        .map(|d| d.as_u64().unwrap() as usize)
        .collect();
    assert_eq!(v.dims().to_vec(), dims, "{name}: dims");
    assert_eq!(
        v.data.voxel_type().name(),
        dtype.as_str().unwrap(),
        "{name}"
    );
    for s in samples.as_array().unwrap() {
        let (i, j, k) = (
            s[0].as_u64().unwrap() as usize,
            s[1].as_u64().unwrap() as usize,
            s[2].as_u64().unwrap() as usize,
        );
        // serde_json parses decimals to within an ulp; integer voxels compare exactly.
        let (got, want) = (v.value_f64(i, j, k), f(&s[3]));
        assert!(
            got == want
                || (v.data.voxel_type().is_float() && (got - want).abs() <= 1e-12 * want.abs()),
            "{name}: voxel ({i},{j},{k}) is {got}, the library says {want}"
        );
    }
    for c in t["world_corners"].as_array().unwrap() {
        let (i, j, k) = (
            c[0].as_u64().unwrap() as usize,
            c[1].as_u64().unwrap() as usize,
            c[2].as_u64().unwrap() as usize,
        );
        let got = world(v, i, j, k);
        let want = vec3(&c[3]);
        assert!(
            (0..3).all(|a| close(got[a], want[a])),
            "{name}: voxel ({i},{j},{k}) at {got}, the library says {want}"
        );
    }
    if let Some(dirs) = t["axis_directions"].as_array() {
        for (a, d) in dirs.iter().enumerate() {
            let want = vec3(d).normalize();
            let got = v.grid.axis_direction(a);
            assert!(
                (got - want).length() < 1e-9,
                "{name}: axis {a} points to {got}, the library says {want}"
            );
        }
        // Spacing: the length of each axis step in world space.
        let spacing = t["spacing"].as_array().unwrap();
        for a in 0..3 {
            let mut idx = [0usize; 3];
            idx[a] = 1;
            let step = (world(v, idx[0], idx[1], idx[2]) - world(v, 0, 0, 0)).length();
            assert!(close(step, f(&spacing[a])), "{name}: spacing {a} {step}");
        }
    } else if let Some(spacing) = t["spacing"].as_array() {
        let got = v.grid.uniform_spacing().unwrap();
        for a in 0..3 {
            assert!(close(got[a], f(&spacing[a])), "{name}: spacing {got:?}");
        }
    }
    let frame = t["world_frame"].as_str().unwrap();
    assert_eq!(v.grid.world_frame().name(), frame, "{name}: world frame");
}

/// Opens every entry and checks it (series: the first and last step).
fn check_folder(folder: &str) -> usize {
    let mut checked = 0;
    for t in truth(folder) {
        let name = t["open"].as_str().unwrap();
        let path = data(folder).join(name);
        let dataset = formats::open(&path, &options(&t)).unwrap_or_else(|e| panic!("{e}"));
        let steps = t["steps"].as_u64().unwrap() as usize;
        assert_eq!(dataset.time_steps(), steps, "{name}");
        check_volume(name, dataset.first_volume(), &t, &t["samples"], &t["dtype"]);
        if let Dataset::Series(s) = &dataset {
            let last = s.step(steps - 1).unwrap();
            check_volume(name, &last, &t, &t["last_step_samples"], &t["dtype"]);
            if let Some(dt) = t["time_spacing"].as_f64().or(t["time_interval"].as_f64()) {
                let t0 = t["time_origin"].as_f64().unwrap_or(0.0);
                assert!(close(s.time_value(steps - 1), t0 + dt * (steps - 1) as f64));
            }
        }
        checked += 1;
    }
    checked
}

#[test]
fn metaimage_files_written_by_simpleitk_read_as_simpleitk_reads_them() {
    assert!(check_folder("metaimage") >= 10);
    // Uncompressed detached u8 data is viewed in the memory map, not copied.
    let d = formats::open(
        &data("metaimage").join("sagittal_u8.mhd"),
        &OpenOptions::default(),
    )
    .unwrap();
    assert!(d.first_volume().data.is_shared());
    let d = formats::open(
        &data("metaimage").join("float_zlib.mha"),
        &OpenOptions::default(),
    )
    .unwrap();
    assert!(!d.first_volume().data.is_shared());
}

#[test]
fn vtk_image_files_written_by_vtk_read_as_vtk_reads_them() {
    let mut checked = 0;
    for t in truth("vtk_image") {
        let name = t["open"].as_str().unwrap();
        let path = data("vtk_image").join(name);
        let active = t["active"].as_str().unwrap();
        // No choice: the active scalars.
        let v = formats::open(&path, &OpenOptions::default()).unwrap_or_else(|e| panic!("{e}"));
        let a = &t["arrays"][active];
        check_volume(name, v.first_volume(), &t, &a["samples"], &a["dtype"]);
        if let Some(coords) = t["coordinates"].as_array() {
            for (axis, c) in coords.iter().enumerate() {
                let c = c.as_array().unwrap();
                let g = v.first_volume().grid.axis(axis);
                for (i, x) in c.iter().enumerate() {
                    assert!(close(g.coord(i), f(x)), "{name}: axis {axis} coord {i}");
                }
            }
        }
        // Each array by name; several components are refused by name.
        let arrays = formats::vtk_image::point_arrays(&path).unwrap();
        for (array, info) in t["arrays"].as_object().unwrap() {
            let o = OpenOptions {
                field: Some(array.clone()),
                ..OpenOptions::default()
            };
            if info["components"].as_u64() == Some(1) {
                let v = formats::open(&path, &o).unwrap_or_else(|e| panic!("{e}"));
                check_volume(name, v.first_volume(), &t, &info["samples"], &info["dtype"]);
                assert!(arrays.scalar_names().contains(array));
            } else {
                let e = formats::open(&path, &o).unwrap_err();
                assert!(
                    matches!(&e, FormatError::Array { name: n, reason, .. } if n == array && reason.contains("components")),
                    "{e}"
                );
            }
        }
        assert_eq!(arrays.default_name(), Some(active), "{name}");
        let e = formats::open(
            &path,
            &OpenOptions {
                field: Some("nope".into()),
                ..OpenOptions::default()
            },
        )
        .unwrap_err();
        assert!(
            matches!(&e, FormatError::Array { reason, .. } if reason.contains(&format!("\"{active}\""))),
            "{e}"
        );
        checked += 1;
    }
    assert!(checked >= 13, "{checked}");
}

#[test]
fn tiff_files_written_by_tifffile_and_pillow_read_as_they_read_them() {
    assert!(check_folder("tiff") >= 12);
}

#[test]
fn a_vtk_file_is_an_image_or_a_mesh_by_its_dataset_line() {
    let image = data("vtk_image").join("points_v51_binary.vtk");
    let mesh = data("mesh").join("mixed_v51_binary.vtk");
    assert!(!formats::mesh::is_mesh_path(&image));
    assert!(formats::mesh::is_mesh_path(&mesh));
    assert!(formats::mesh::is_mesh_path(Path::new("missing.vtk")));
    assert!(!formats::mesh::is_mesh_path(
        &data("vtk_image").join("rectilinear_*.vtk")
    ));
    let e = formats::open(&mesh, &OpenOptions::default()).unwrap_err();
    assert!(
        matches!(&e, FormatError::UnknownFormat { reason, .. } if reason.contains("UNSTRUCTURED_GRID")),
        "{e}"
    );
    let e = formats::mesh::read_mesh(&image).unwrap_err();
    assert!(e.to_string().contains("STRUCTURED_POINTS"), "{e}");
}

#[test]
fn options_a_format_cannot_use_are_refused() {
    let o = OpenOptions {
        field: Some("temperature".into()),
        ..OpenOptions::default()
    };
    let e = formats::open(&data("metaimage").join("float_zlib.mha"), &o).unwrap_err();
    assert!(
        matches!(&e, FormatError::Unsupported { field, .. } if field == "--field"),
        "{e}"
    );
    let o = OpenOptions {
        spacing: Some([1.0, 2.0, 3.0]),
        ..OpenOptions::default()
    };
    let e = formats::open(&data("vtk_image").join("ascii.vti"), &o).unwrap_err();
    assert!(
        matches!(&e, FormatError::Unsupported { field, .. } if field == "--spacing"),
        "{e}"
    );
}

// ------------------------------------------------------------------ bad input

/// A scratch copy of `src` files, changed by `edit`, opened with `formats::open`.
fn open_edited(
    folder: &str,
    files: &[&str],
    open: &str,
    edit: impl FnOnce(&Path),
) -> (tempfile::TempDir, FormatError) {
    let dir = tempfile::tempdir().unwrap();
    for f in files {
        let to = dir.path().join(f);
        std::fs::create_dir_all(to.parent().unwrap()).unwrap();
        std::fs::copy(data(folder).join(f), to).unwrap();
    }
    edit(dir.path());
    let e = formats::open(&dir.path().join(open), &OpenOptions::default()).unwrap_err();
    assert!(
        e.to_string().contains(dir.path().to_str().unwrap()),
        "the error names no file of the case: {e}"
    );
    (dir, e)
}

fn replace_in(path: &Path, from: &str, to: &str) {
    let bytes = std::fs::read(path).unwrap();
    let text = String::from_utf8_lossy(&bytes);
    let at = text
        .find(from)
        .unwrap_or_else(|| panic!("{from} in {}", path.display()));
    let mut out = bytes[..at].to_vec();
    out.extend_from_slice(to.as_bytes());
    out.extend_from_slice(&bytes[at + from.len()..]);
    std::fs::write(path, out).unwrap();
}

/// Replaces the line that starts with `key`.
fn replace_line(path: &Path, key: &str, line: &str) {
    let text = std::fs::read(path).unwrap();
    let at = text
        .windows(key.len() + 1)
        .position(|w| w[0] == b'\n' && &w[1..] == key.as_bytes())
        .unwrap_or_else(|| panic!("{key} in {}", path.display()))
        + 1;
    let end = at + text[at..].iter().position(|&b| b == b'\n').unwrap();
    let mut out = text[..at].to_vec();
    out.extend_from_slice(line.as_bytes());
    out.extend_from_slice(&text[end..]);
    std::fs::write(path, out).unwrap();
}

fn truncate(path: &Path, keep: u64) {
    let f = std::fs::OpenOptions::new().write(true).open(path).unwrap();
    f.set_len(keep).unwrap();
}

#[test]
fn bad_metaimage_files_are_clear_errors() {
    let mi = |files: &[&str], open: &str, edit: &dyn Fn(&Path)| {
        open_edited("metaimage", files, open, |d| edit(d)).1
    };
    // DimSize larger than the data: the raw file is too short.
    let e = mi(&["oblique_i16.mha"], "oblique_i16.mha", &|d| {
        replace_in(
            &d.join("oblique_i16.mha"),
            "DimSize = 10 8 6",
            "DimSize = 10 8 9",
        );
    });
    assert!(matches!(e, FormatError::TooShort { .. }), "{e}");
    // Truncated detached data.
    let e = mi(
        &["sagittal_u8.mhd", "sagittal_u8.raw"],
        "sagittal_u8.mhd",
        &|d| truncate(&d.join("sagittal_u8.raw"), 100),
    );
    assert!(
        matches!(e, FormatError::TooShort { available: 100, .. }),
        "{e}"
    );
    // Compressed stream cut short, and garbage instead of zlib.
    let e = mi(
        &["flipped_u16.mhd", "flipped_u16.zraw"],
        "flipped_u16.mhd",
        &|d| {
            let p = d.join("flipped_u16.zraw");
            let len = std::fs::metadata(&p).unwrap().len();
            truncate(&p, len / 2);
        },
    );
    assert!(
        matches!(e, FormatError::TooShort { .. } | FormatError::Decode { .. }),
        "{e}"
    );
    let e = mi(
        &["flipped_u16.mhd", "flipped_u16.zraw"],
        "flipped_u16.mhd",
        &|d| {
            let p = d.join("flipped_u16.zraw");
            let mut b = std::fs::read(&p).unwrap();
            for x in b.iter_mut().skip(2).take(40) {
                *x ^= 0x5a;
            }
            std::fs::write(&p, b).unwrap();
        },
    );
    assert!(
        matches!(
            e,
            FormatError::Decode {
                encoding: "zlib",
                ..
            }
        ),
        "{e}"
    );
    // A compressed size larger than the file.
    let e = mi(&["float_zlib.mha"], "float_zlib.mha", &|d| {
        replace_in(
            &d.join("float_zlib.mha"),
            "CompressedDataSize = ",
            "CompressedDataSize = 9",
        );
    });
    assert!(matches!(e, FormatError::TooShort { .. }), "{e}");
    // DimSize claiming more than zlib can inflate the bytes to.
    let e = mi(&["float_zlib.mha"], "float_zlib.mha", &|d| {
        replace_in(
            &d.join("float_zlib.mha"),
            "DimSize = 10 8 6",
            "DimSize = 10000 8000 6",
        );
    });
    assert!(
        matches!(&e, FormatError::BadValue { field, .. } if field == "DimSize"),
        "{e}"
    );
    // Unsupported and malformed keys name the key and the line.
    let e = mi(&["oblique_i16.mha"], "oblique_i16.mha", &|d| {
        replace_in(&d.join("oblique_i16.mha"), "MET_SHORT", "MET_LONG_LONG");
    });
    assert!(
        matches!(&e, FormatError::Unsupported { field, .. } if field == "ElementType"),
        "{e}"
    );
    let e = mi(&["oblique_i16.mha"], "oblique_i16.mha", &|d| {
        replace_in(&d.join("oblique_i16.mha"), "NDims = 3", "NDims = 2");
    });
    assert!(
        matches!(&e, FormatError::Unsupported { field, .. } if field == "NDims"),
        "{e}"
    );
    let e = mi(&["oblique_i16.mha"], "oblique_i16.mha", &|d| {
        replace_line(
            &d.join("oblique_i16.mha"),
            "ElementSpacing",
            "ElementSpacing = 0.8 x 1.5",
        );
    });
    assert!(
        matches!(&e, FormatError::BadValue { field, line, .. } if field == "ElementSpacing" && *line > 1),
        "{e}"
    );
    let e = mi(&["oblique_i16.mha"], "oblique_i16.mha", &|d| {
        replace_line(
            &d.join("oblique_i16.mha"),
            "ElementSpacing",
            "ElementSpacing = 0 1.1 1.5",
        );
    });
    assert!(
        matches!(&e, FormatError::BadValue { field, .. } if field == "ElementSpacing"),
        "{e}"
    );
    // A missing slice file of a pattern: the last is looked at first (before the list of
    // all is made), then each in order.
    let e = mi(
        &["pattern_u8.mhd", "slices/pat_001.raw", "slices/pat_003.raw"],
        "pattern_u8.mhd",
        &|_| {},
    );
    assert!(
        matches!(&e, FormatError::Io { path, .. } if path.ends_with("pat_011.raw")),
        "{e}"
    );
    let e = mi(
        &[
            "pattern_u8.mhd",
            "slices/pat_001.raw",
            "slices/pat_003.raw",
            "slices/pat_011.raw",
        ],
        "pattern_u8.mhd",
        &|_| {},
    );
    assert!(
        matches!(&e, FormatError::Io { path, .. } if path.ends_with("pat_005.raw")),
        "{e}"
    );
    // A LIST with too few names.
    let e = mi(&["list_u8.mhd"], "list_u8.mhd", &|d| {
        replace_in(&d.join("list_u8.mhd"), "slices/list_5.raw\n", "");
    });
    assert!(
        matches!(&e, FormatError::BadValue { field, .. } if field == "ElementDataFile"),
        "{e}"
    );
    // HeaderSize pointing into the header of a LOCAL file.
    let e = mi(&["oblique_i16.mha"], "oblique_i16.mha", &|d| {
        replace_in(
            &d.join("oblique_i16.mha"),
            "ObjectType = Image\n",
            "ObjectType = Image\nHeaderSize = 4\n",
        );
    });
    assert!(
        matches!(&e, FormatError::BadValue { field, .. } if field == "HeaderSize"),
        "{e}"
    );
}

#[test]
fn metaimage_header_parser_names_key_and_line() {
    let p = Path::new("h.mhd");
    let e = formats::metaimage::parse_header(p, b"NDims = 3\nDimSize 4 4 4\n").unwrap_err();
    assert!(matches!(e, FormatError::BadLine { line: 2, .. }), "{e}");
    let e = formats::metaimage::parse_header(p, b"NDims = 3\nNDims = 3\n").unwrap_err();
    assert!(
        matches!(&e, FormatError::DuplicateField { line: 2, field, .. } if field == "NDims"),
        "{e}"
    );
    let e = formats::metaimage::parse_header(p, b"NDims = 3\nDimSize = 4 4 4\n").unwrap_err();
    assert!(
        matches!(
            e,
            FormatError::MissingField {
                field: "ElementDataFile",
                ..
            }
        ),
        "{e}"
    );
    let h = formats::metaimage::parse_header(
        p,
        b"NDims = 3\nDimSize = 4 4 4\nPosition = 1 2 3\nOrientation = 0 1 0 1 0 0 0 0 1\nElementType = MET_UCHAR\nElementDataFile = d%02d.raw 0\n",
    )
    .unwrap();
    assert_eq!(h.offset, vec![1.0, 2.0, 3.0]);
    assert_eq!(
        h.transform.as_deref(),
        Some(&[0.0, 1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0][..])
    );
    assert!(matches!(
        &h.data_file,
        formats::metaimage::DataFile::Pattern {
            min: 0,
            step: 1,
            ..
        }
    ));
    let files = formats::metaimage::data_file_paths(&h, Path::new("/x/h.mhd"));
    assert_eq!(files[3], Path::new("/x/d03.raw"));
}

#[test]
fn metaimage_data_file_names_of_any_text_are_not_sliced_mid_character() {
    // "LIST" is checked on the first four bytes: a name whose 4th byte is inside a
    // multi-byte character must not panic.
    let h = formats::metaimage::parse_header(
        Path::new("h.mhd"),
        "NDims = 3\nDimSize = 1 1 1\nElementType = MET_UCHAR\nElementDataFile = ab\u{e9}c.raw\n"
            .as_bytes(),
    )
    .unwrap();
    assert_eq!(
        h.data_file,
        formats::metaimage::DataFile::File("ab\u{e9}c.raw".into())
    );
    // A pattern of 10^12 slice files is refused before a name is made.
    let e = formats::metaimage::parse_header(
        Path::new("h.mhd"),
        b"NDims = 3\nDimSize = 1 1 1000000000000\nElementType = MET_UCHAR\nElementDataFile = s%d.raw\n",
    )
    .unwrap_err();
    assert!(
        matches!(&e, FormatError::BadValue { field, .. } if field == "ElementDataFile"),
        "{e}"
    );
}

#[test]
fn metaimage_pattern_of_100000_slice_files_is_read_without_a_scan_per_file() {
    // Every data file is noted in the input log before any is read; each note scanned the
    // whole log, so 10^5 names took minutes (10^4: 10 s, found by the fuzzer) and the 2^20
    // the header may name, hours. Only the last file exists (so that the list is made): the
    // first is named, in a second.
    let dir = tempfile::tempdir().unwrap();
    let header = dir.path().join("p.mhd");
    std::fs::write(
        &header,
        "NDims = 3\nDimSize = 1 1 100000\nElementType = MET_UCHAR\nElementDataFile = s%06d.raw 1 100000 1\n",
    )
    .unwrap();
    std::fs::write(dir.path().join("s100000.raw"), [7u8]).unwrap();
    let (send, receive) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let _ = send.send(formats::metaimage::read_metaimage(&header).map(|_| ()));
    });
    let e = receive
        .recv_timeout(std::time::Duration::from_mins(1))
        .expect("read_metaimage still running after 60 s")
        .unwrap_err();
    assert!(
        matches!(&e, FormatError::Io { path, .. } if path.ends_with("s000001.raw")),
        "{e}"
    );
}

#[test]
fn metaimage_pattern_whose_last_file_is_missing_is_refused_before_listing_its_files() {
    // Found by the fuzzer: 91 bytes naming 882,185 slice files made a list of their names
    // (and input-log entries, and one lazy map each) past 512 MB before any file was looked
    // at. The last file is checked first.
    let dir = tempfile::tempdir().unwrap();
    let header = dir.path().join("h.mhd");
    std::fs::write(
        &header,
        "NDims = 3\nDimSize =223 7  882185\nElementType= MET_UCHAR\nElementDataFile = s000%0730334409d3\n",
    )
    .unwrap();
    std::fs::write(dir.path().join(format!("s000{:064}3", 1)), [0u8; 1561]).unwrap();
    let e = formats::metaimage::read_metaimage(&header).unwrap_err();
    let last = format!("s000{:064}3", 882_185);
    assert!(
        matches!(&e, FormatError::Io { path, .. } if path.ends_with(&last)),
        "{e}"
    );
}

#[test]
fn metaimage_world_frame_follows_anatomical_orientation() {
    use formats::metaimage::{parse_header, world_frame};
    use volume_core::WorldFrame;
    let frame = |code: &str| {
        let text = format!(
            "NDims = 3\nDimSize = 2 2 2\nAnatomicalOrientation = {code}\nElementType = MET_UCHAR\nElementDataFile = LOCAL\n"
        );
        let h = parse_header(Path::new("a.mha"), text.as_bytes()).unwrap();
        world_frame(&h, [DVec3::X, DVec3::Y, DVec3::Z])
    };
    // ITK writes the "from" letters of an LPS world: RAI for the identity.
    assert_eq!(frame("RAI"), WorldFrame::Lps);
    assert_eq!(frame("LPS"), WorldFrame::Lps);
    assert_eq!(frame("LPI"), WorldFrame::Ras);
    assert_eq!(frame("RAS"), WorldFrame::Ras);
    assert_eq!(frame("???"), WorldFrame::Lps);
    assert_eq!(frame("PRI"), WorldFrame::Unknown);
}

#[test]
fn bad_vti_files_are_clear_errors() {
    let vti = |file: &str, edit: &dyn Fn(&Path)| {
        open_edited("vtk_image", &[file], file, |d| edit(&d.join(file))).1
    };
    // An extent larger than the data.
    let e = vti("binary.vti", &|p| {
        let t = std::fs::read_to_string(p).unwrap();
        assert_eq!(t.matches("\"2 11 -1 6 0 5\"").count(), 2);
        std::fs::write(p, t.replace("\"2 11 -1 6 0 5\"", "\"2 11 -1 6 0 7\"")).unwrap();
    });
    assert!(matches!(e, FormatError::Array { .. }), "{e}");
    // The piece covers less than the whole extent.
    let e = vti("ascii.vti", &|p| {
        replace_in(p, "<Piece Extent=\"2 11", "<Piece Extent=\"3 11");
    });
    assert!(
        matches!(&e, FormatError::Contradiction { field, .. } if field == "Extent"),
        "{e}"
    );
    // Truncated appended data (inside the first array, the active one).
    let e = vti("appended_raw.vti", &|p| {
        let t = std::fs::read(p).unwrap();
        let at = t.windows(13).position(|w| w == b"<AppendedData").unwrap();
        truncate(p, at as u64 + 1000);
    });
    assert!(
        matches!(e, FormatError::Array { .. } | FormatError::BadLine { .. }),
        "{e}"
    );
    // A corrupt zlib block, and an LZ4 block claiming more than it can hold.
    let e = vti("binary_zlib.vti", &|p| {
        let t = std::fs::read_to_string(p).unwrap();
        let at = t.find("Name=\"temperature\"").unwrap();
        let start = at + t[at..].find('>').unwrap() + 1;
        let mut b = t.into_bytes();
        // Base64 characters deep in the drawn array's data (after the header run).
        for x in &mut b[start + 80..start + 120] {
            if x.is_ascii_alphabetic() {
                *x = if *x == b'A' { b'B' } else { b'A' };
            }
        }
        std::fs::write(p, b).unwrap();
    });
    assert!(matches!(e, FormatError::Array { .. }), "{e}");
    let e = vti("appended_lz4.vti", &|p| {
        replace_in(
            p,
            "WholeExtent=\"2 11 -1 6 0 5\"",
            "WholeExtent=\"2 11 -1 6 0 500\"",
        );
        replace_in(
            p,
            "Piece Extent=\"2 11 -1 6 0 5\"",
            "Piece Extent=\"2 11 -1 6 0 500\"",
        );
    });
    assert!(matches!(e, FormatError::Array { .. }), "{e}");
    // Zero spacing, and a file of another type.
    let e = vti("ascii.vti", &|p| {
        replace_in(p, "Spacing=\"0.6", "Spacing=\"0");
    });
    assert!(
        matches!(&e, FormatError::BadValue { field, .. } if field == "Spacing"),
        "{e}"
    );
    let e = vti("ascii.vti", &|p| {
        replace_in(p, "type=\"ImageData\"", "type=\"PolyData\"");
    });
    assert!(matches!(e, FormatError::Unsupported { .. }), "{e}");
}

#[test]
fn bad_legacy_vtk_images_are_clear_errors() {
    let vtk = |file: &str, edit: &dyn Fn(&Path)| {
        open_edited("vtk_image", &[file], file, |d| edit(&d.join(file))).1
    };
    let e = vtk("points_v51_binary.vtk", &|p| {
        replace_in(p, "DIMENSIONS 10 8 6", "DIMENSIONS 10 8 7");
    });
    assert!(
        matches!(&e, FormatError::BadLine { reason, .. } if reason.contains("POINT_DATA 480")),
        "{e}"
    );
    let e = vtk("points_v51_binary.vtk", &|p| {
        let len = std::fs::metadata(p).unwrap().len();
        truncate(p, len - 2000);
    });
    assert!(matches!(e, FormatError::BadValue { .. }), "{e}");
    let e = vtk("rectilinear_ascii.vtk", &|p| {
        replace_in(
            p,
            "Z_COORDINATES 6 double\n0 0.5",
            "Z_COORDINATES 6 double\n0 0",
        );
    });
    assert!(matches!(e, FormatError::Geometry { .. }), "{e}");
    let e = vtk("rectilinear_ascii.vtk", &|p| {
        replace_in(p, "X_COORDINATES 10", "X_COORDINATES 9");
    });
    assert!(
        matches!(
            e,
            FormatError::BadLine { .. } | FormatError::Contradiction { .. }
        ),
        "{e}"
    );
    // A second DIMENSIONS after the data (found by the fuzzer): the data was checked against
    // the first, so the grid no longer matched it (a failed assertion).
    let e = vtk("points_v42_binary.vtk", &|p| {
        let mut bytes = std::fs::read(p).unwrap();
        bytes.extend_from_slice(b"\nDIMENSIONS 9 8 6\n");
        std::fs::write(p, bytes).unwrap();
    });
    assert!(
        matches!(&e, FormatError::BadLine { reason, .. } if reason.contains("DIMENSIONS")),
        "{e}"
    );
    let e = vtk("points_v51_ascii.vtk", &|p| {
        replace_in(p, "SCALARS density short", "SCALARS density vtktypeint64");
    });
    assert!(
        matches!(&e, FormatError::Array { reason, .. } if reason.contains("64-bit")),
        "{e}"
    );
}

#[test]
fn bad_tiff_files_are_clear_errors() {
    let tif = |file: &str, edit: &dyn Fn(&Path)| {
        open_edited("tiff", &[file], file, |d| edit(&d.join(file))).1
    };
    // Truncated pages.
    let e = tif("plain_u16.tif", &|p| truncate(p, 600));
    assert!(matches!(e, FormatError::Page { .. }), "{e}");
    let e = tif("deflate_i32.tif", &|p| {
        let len = std::fs::metadata(p).unwrap().len();
        let mut b = std::fs::read(p).unwrap();
        // Garble the compressed strips (tifffile writes the data before the directories).
        for x in &mut b[200..(len as usize / 2)] {
            *x = x.wrapping_mul(31).wrapping_add(7);
        }
        std::fs::write(p, b).unwrap();
    });
    assert!(
        matches!(
            e,
            FormatError::Page { .. } | FormatError::UnknownFormat { .. }
        ),
        "{e}"
    );
    // Not a TIFF at all.
    let e = tif("plain_u16.tif", &|p| {
        std::fs::write(p, b"II*\x00garbage").unwrap();
    });
    assert!(
        matches!(
            e,
            FormatError::UnknownFormat { .. } | FormatError::Page { .. }
        ),
        "{e}"
    );
    // Pages of different sizes: numbered slices where one slice is larger.
    let dir = tempfile::tempdir().unwrap();
    for k in 0..3 {
        std::fs::copy(
            data("tiff").join(format!("slices/slice_{k:03}.tif")),
            dir.path().join(format!("s_{k}.tif")),
        )
        .unwrap();
    }
    std::fs::copy(
        data("tiff").join("imagej_f32.tif"),
        dir.path().join("s_3.tif"),
    )
    .unwrap();
    let e = formats::open(&dir.path().join("s_*.tif"), &OpenOptions::default()).unwrap_err();
    assert!(
        matches!(&e, FormatError::Page { path, .. } if path.ends_with("s_3.tif")),
        "{e}"
    );
}

#[test]
fn a_multi_page_tiff_with_pages_of_different_sizes_names_the_page() {
    // Pages 0 and 1 are 4 x 2, page 2 is 3 x 2 (a minimal baseline TIFF, little-endian).
    let mut b = b"II*\0".to_vec();
    let page = |w: u32, data_at: u32, next: u32| -> Vec<u8> {
        let mut ifd = Vec::new();
        let entries: [(u16, u16, u32); 8] = [
            (256, 4, w),
            (257, 4, 2),
            (258, 3, 8),
            (259, 3, 1),
            (262, 3, 1),
            (273, 4, data_at),
            (278, 4, 2),
            (279, 4, w * 2),
        ];
        ifd.extend((entries.len() as u16).to_le_bytes());
        for (tag, ty, v) in entries {
            ifd.extend(tag.to_le_bytes());
            ifd.extend(ty.to_le_bytes());
            ifd.extend(1u32.to_le_bytes());
            if ty == 3 {
                ifd.extend((v as u16).to_le_bytes());
                ifd.extend([0, 0]);
            } else {
                ifd.extend(v.to_le_bytes());
            }
        }
        ifd.extend(next.to_le_bytes());
        ifd
    };
    let ifd_len = 2 + 8 * 12 + 4;
    let first_ifd = 8u32;
    let data_at = first_ifd + 3 * ifd_len;
    b.extend(first_ifd.to_le_bytes());
    b.extend(page(4, data_at, first_ifd + ifd_len));
    b.extend(page(4, data_at + 8, first_ifd + 2 * ifd_len));
    b.extend(page(3, data_at + 16, 0));
    b.extend((0u8..22).collect::<Vec<_>>());
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("mixed.tif");
    std::fs::write(&p, &b).unwrap();
    let e = formats::open(&p, &OpenOptions::default()).unwrap_err();
    assert!(
        matches!(&e, FormatError::Page { page: 2, reason, .. } if reason.contains("3 x 2")),
        "{e}"
    );
    // The same bytes in memory (the fuzz target's entry) give the same error.
    let e = formats::tiff::parse_tiff(&p, &b, &OpenOptions::default()).unwrap_err();
    assert!(matches!(e, FormatError::Page { page: 2, .. }), "{e}");
}
