//! Out-of-core `.isot` files through the `isoscope` binary: `preprocess`, then `render` at the
//! finest level equals the in-core render of the same volume pixel for pixel; `info` and
//! `bench --json` report levels, time to first image and resident memory; truncated and
//! corrupted files are errors, never pictures. A scaled NIfTI keeps its value map in the
//! `.isot`: isovalues and ranges stay physical.

mod common;
use common::{fails, isoscope, ok};

use std::path::{Path, PathBuf};

use volume_core::ooc::TreeletStorage as _;

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// A 41³ f32 sphere distance field and its `.isot` (treelet height 3: several levels).
fn volume_and_isot(dir: &Path) -> (PathBuf, PathBuf) {
    let vol = dir.join("sphere.nrrd");
    ok(&["generate", "sphere", "--size", "41", "-o", s(&vol)]);
    let isot = dir.join("sphere.isot");
    ok(&[
        "preprocess",
        s(&vol),
        "-o",
        s(&isot),
        "--treelet-height",
        "3",
    ]);
    (vol, isot)
}

fn render(file: &Path, out: &Path, extra: &[&str]) -> String {
    let mut args = vec![
        "render",
        s(file),
        "--iso",
        "0.6",
        "--iso",
        "0.3:#4080ff:0.5",
        "--orbit",
        "35,25",
        "--size",
        "64x48",
        "-o",
        s(out),
    ];
    args.extend_from_slice(extra);
    let o = isoscope(&args);
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert!(o.status.success(), "{args:?}: {err}");
    err
}

/// Renders each of `files` (in core, then out of core) with `args` at `size` into `dir` and
/// asserts the same depth maps, bit for bit, with at least `min_hits` hits.
fn assert_same_depths(dir: &Path, files: [&Path; 2], args: &[&str], size: &str, min_hits: usize) {
    let mut depths = Vec::new();
    for f in files {
        let npy = dir.join(format!("{}.npy", f.file_name().unwrap().to_string_lossy()));
        let png = npy.with_extension("png");
        let mut all = vec![
            "render",
            s(f),
            "--size",
            size,
            "-o",
            s(&png),
            "--depth-out",
            s(&npy),
        ];
        all.extend_from_slice(args);
        ok(&all);
        let read = isoscope::cli::npy::read_f32_2d(std::fs::File::open(&npy).unwrap());
        depths.push(read.unwrap().1);
    }
    let hits = depths[0].iter().filter(|d| d.is_finite()).count();
    assert!(hits >= min_hits, "{hits}");
    for (k, (x, y)) in depths[0].iter().zip(&depths[1]).enumerate() {
        assert!(
            x.to_bits() == y.to_bits(),
            "pixel {k}: in-core {x}, out-of-core {y}"
        );
    }
}

#[test]
fn finest_level_render_equals_the_in_core_render() {
    let dir = tempfile::tempdir().unwrap();
    let (vol, isot) = volume_and_isot(dir.path());
    let levels = formats::treelet::IsotFile::open(&isot)
        .unwrap()
        .meta()
        .layout
        .level_count();
    assert!(levels >= 2, "{levels}");
    let a_png = dir.path().join("incore.png");
    let b_png = dir.path().join("ooc.png");
    let a_npy = dir.path().join("incore.npy");
    let b_npy = dir.path().join("ooc.npy");
    render(&vol, &a_png, &["--depth-out", s(&a_npy)]);
    let log = render(&isot, &b_png, &["--depth-out", s(&b_npy)]);
    let finest = levels - 1;
    assert!(
        log.contains(&format!("level {finest} of 0..{finest} (finest)")),
        "{log}"
    );
    let read = |p: &Path| isoscope::cli::npy::read_f32_2d(std::fs::File::open(p).unwrap()).unwrap();
    let (shape_a, depth_a) = read(&a_npy);
    let (shape_b, depth_b) = read(&b_npy);
    assert_eq!(shape_a, shape_b);
    let hits = depth_a.iter().filter(|d| d.is_finite()).count();
    assert!(hits > 100, "{hits}");
    for (k, (a, b)) in depth_a.iter().zip(&depth_b).enumerate() {
        assert!(
            a.to_bits() == b.to_bits(),
            "pixel {k}: in-core {a}, out-of-core {b}"
        );
    }
    let a = image::open(&a_png).unwrap().to_rgba8();
    let b = image::open(&b_png).unwrap().to_rgba8();
    assert_eq!(
        a.as_raw(),
        b.as_raw(),
        "same shading, transparency included"
    );

    // Faceted normals reach the out-of-core frame as the in-core one: the same picture,
    // other than the smooth one.
    let (fa_png, fb_png) = (dir.path().join("fa.png"), dir.path().join("fb.png"));
    render(&vol, &fa_png, &["--normals", "faceted"]);
    render(&isot, &fb_png, &["--normals", "faceted"]);
    let fa = image::open(&fa_png).unwrap().to_rgba8();
    let fb = image::open(&fb_png).unwrap().to_rgba8();
    assert_eq!(fa.as_raw(), fb.as_raw(), "faceted: the same shading");
    assert_ne!(fa.as_raw(), a.as_raw(), "faceted normals shade otherwise");
}

#[test]
fn a_scaled_volume_keeps_its_value_map_out_of_core() {
    // int16 written by nibabel with scl_slope 2, scl_inter −1024 (formats/tests/data/nifti).
    let dir = tempfile::tempdir().unwrap();
    let nii =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../formats/tests/data/nifti/scaled_i16.nii");
    let isot = dir.path().join("scaled.isot");
    ok(&[
        "preprocess",
        s(&nii),
        "-o",
        s(&isot),
        "--treelet-height",
        "2",
    ]);
    let json = |f: &Path| -> serde_json::Value {
        serde_json::from_str(&ok(&["info", s(f), "--json"])).unwrap()
    };
    let (a, b) = (json(&nii), json(&isot));
    assert_eq!(b["value_map"], a["value_map"]);
    assert_eq!(b["value_map"]["slope"], 2.0);
    assert_eq!(b["value_range"], a["value_range"]);
    assert_eq!(b["world_frame"], "RAS");
    assert_eq!(b["voxel_type"], "i16");
    let text = ok(&["info", s(&isot)]);
    assert!(text.contains("physical = 2 · stored + -1024"), "{text}");
    // Physical isovalues render the same surfaces as the in-core file, bit for bit.
    let args = [
        "--iso",
        "500",
        "--iso",
        "1200:#4080ff:0.5",
        "--orbit",
        "35,25",
    ];
    assert_same_depths(dir.path(), [&nii, &isot], &args, "48x40", 100);
}

#[test]
fn info_and_bench_report_levels_and_memory() {
    let dir = tempfile::tempdir().unwrap();
    let (_, isot) = volume_and_isot(dir.path());
    let v: serde_json::Value = serde_json::from_str(&ok(&["info", s(&isot), "--json"])).unwrap();
    assert_eq!(v["kind"], "isot");
    assert_eq!(v["dims"], serde_json::json!([41, 41, 41]));
    assert_eq!(v["voxel_type"], "f32");
    assert_eq!(v["treelet_height"], 3);
    let levels = v["levels"].as_u64().unwrap();
    assert!(levels >= 2);
    assert_eq!(
        v["file_bytes"].as_u64().unwrap(),
        std::fs::metadata(&isot).unwrap().len()
    );
    let [lo, hi] = [0, 1].map(|i| v["value_range"][i].as_f64().unwrap());
    assert!((0.0..0.1).contains(&lo) && hi > 1.6, "{lo} {hi}");

    let json = ok(&[
        "bench",
        s(&isot),
        "--iso",
        "0.6",
        "--size",
        "48x48",
        "--frames",
        "2",
        "--json",
    ]);
    let b: serde_json::Value = serde_json::from_str(json.trim()).unwrap();
    assert_eq!(b["kind"], "isot");
    assert_eq!(b["dims"], serde_json::json!([41, 41, 41]));
    let o = &b["ooc"];
    assert_eq!(o["level_count"].as_u64().unwrap(), levels);
    assert_eq!(o["loaded_levels"].as_u64().unwrap(), levels);
    assert!(o["first_image_seconds"].as_f64().unwrap() >= o["open_seconds"].as_f64().unwrap());
    assert!(o["finest_level_seconds"].as_f64().unwrap() > 0.0);
    assert!(o["resident_bytes"].as_u64().unwrap() > 0);
    let per_level = o["levels"].as_array().unwrap();
    let last = per_level.last().unwrap();
    assert_eq!(last["level"].as_u64().unwrap(), levels - 1);
    // Coarser levels hold fewer resident bytes than the finest.
    for l in &per_level[..per_level.len() - 1] {
        assert!(l["level"].as_u64().unwrap() < levels - 1);
        assert!(l["resident_bytes"].as_u64().unwrap() < last["resident_bytes"].as_u64().unwrap());
    }
    assert!(b["rays_per_second"].as_f64().unwrap() > 0.0);
    assert_eq!(b["rays_per_second"], b["configs"][0]["rays_per_second"]);
}

#[test]
fn truncated_and_corrupted_files_are_errors() {
    let dir = tempfile::tempdir().unwrap();
    let (_, isot) = volume_and_isot(dir.path());
    let bytes = std::fs::read(&isot).unwrap();
    let out = dir.path().join("o.png");

    let cut = dir.path().join("cut.isot");
    std::fs::write(&cut, &bytes[..bytes.len() - 100]).unwrap();
    let e = fails(&["render", s(&cut), "-o", s(&out)]);
    assert!(e.contains("cut.isot"), "{e}");
    let e = fails(&["info", s(&cut)]);
    assert!(e.contains("cut.isot"), "{e}");

    // A flipped byte in the header.
    let mut head = bytes.clone();
    head[40] ^= 0x10;
    let p = dir.path().join("head.isot");
    std::fs::write(&p, &head).unwrap();
    let e = fails(&["render", s(&p), "-o", s(&out)]);
    assert!(e.contains("head.isot"), "{e}");

    // A flipped byte in every data page below the top level: the file opens (the top
    // treelet is intact) and the loader's checksum error stops the render.
    let f = formats::treelet::IsotFile::open(&isot).unwrap();
    let pages: u64 = f.plans().iter().map(|p| p.page_count).sum();
    let page = formats::treelet::PAGE;
    let data_offset = bytes.len() as u64 - pages * (page + 4);
    let mut bad = bytes.clone();
    for p in &f.plans()[1..] {
        for k in p.first_page..p.first_page + p.page_count {
            bad[(data_offset + k * page + 100) as usize] ^= 0x01;
        }
    }
    drop(f);
    let p = dir.path().join("pages.isot");
    std::fs::write(&p, &bad).unwrap();
    let e = fails(&["render", s(&p), "--iso", "0.6", "-o", s(&out)]);
    assert!(e.contains("pages.isot") && e.contains("checksum"), "{e}");
    assert!(!out.exists());

    // Not an .isot at all.
    let p = dir.path().join("fake.isot");
    std::fs::write(&p, b"hello").unwrap();
    let e = fails(&["render", s(&p), "-o", s(&out)]);
    assert!(e.contains("fake.isot"), "{e}");
}

#[test]
fn an_anisotropic_ct_is_cut_as_the_in_core_tree_is_split() {
    // A real CT crop of 0.57 mm pixels and 5 mm slices (formats/tests/data/ct).
    let dir = tempfile::tempdir().unwrap();
    let ct = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../formats/tests/data/ct/lung1_spine_crop.nrrd");
    let isot = dir.path().join("ct.isot");
    ok(&[
        "preprocess",
        s(&ct),
        "-o",
        s(&isot),
        "--treelet-height",
        "4",
    ]);
    let source = formats::open(&ct, &formats::OpenOptions::default()).unwrap();
    let grid = &source.first_volume().grid;
    let file = formats::treelet::IsotFile::open(&isot).unwrap();
    let layout = &file.meta().layout;
    let world = volume_core::ooc::TreeletLayout::for_grid(grid, 4).unwrap();
    assert_eq!(*layout, world, "the file's tree splits in world space");
    let v: serde_json::Value = serde_json::from_str(&ok(&["info", s(&isot), "--json"])).unwrap();
    assert_eq!(v["format_version"], formats::treelet::VERSION);
    assert_eq!(v["tree_as_in_core"], true);
    // A version-2 file of anisotropic voxels halves in cells, and `info` says so.
    let old =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../formats/tests/data/isot/aniso_v2.isot");
    let v: serde_json::Value = serde_json::from_str(&ok(&["info", s(&old), "--json"])).unwrap();
    assert_eq!(v["format_version"], 2);
    assert_eq!(v["tree_as_in_core"], false);
    assert!(ok(&["info", s(&old)]).contains("halved in cells, not as in core"));
    let index = volume_core::ooc::TreeletLayout::new(layout.dims(), 4).unwrap();
    assert_ne!(layout.split_axes(), index.split_axes());
    // Bone and skin render the in-core depths, bit for bit.
    let args = [
        "--iso",
        "300",
        "--iso",
        "-500:#4080ff:0.5",
        "--orbit",
        "30,45",
    ];
    assert_same_depths(dir.path(), [&ct, &isot], &args, "64x48", 500);
}
