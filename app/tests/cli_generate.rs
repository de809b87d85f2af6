//! `isoscope generate` end to end: the binary writes NRRD files whose voxels and geometry equal
//! the in-memory generator output (read back with `formats::open`), series are numbered files
//! that open as a series, and bad arguments give clear errors without writing anything.

mod common;
use common::{fails, ok};

use std::path::Path;

use data_samples::Generator;
use formats::{Dataset, OpenOptions};
use volume_core::{RectilinearVolume, VoxelType};

fn open(path: &Path) -> Dataset {
    formats::open(path, &OpenOptions::default()).unwrap()
}

/// Voxel-for-voxel and geometry equality.
fn assert_same(a: &RectilinearVolume, b: &RectilinearVolume, what: &str) {
    assert_eq!(a.dims(), b.dims(), "{what}: dims");
    assert_eq!(a.data.voxel_type(), b.data.voxel_type(), "{what}: type");
    assert_eq!(
        a.grid.uniform_spacing(),
        b.grid.uniform_spacing(),
        "{what}: spacing"
    );
    assert_eq!(a.grid.origin(), b.grid.origin(), "{what}: origin");
    let [nx, ny, nz] = a.dims();
    for k in 0..nz {
        for j in 0..ny {
            for i in 0..nx {
                let (x, y) = (a.value_f64(i, j, k), b.value_f64(i, j, k));
                assert!(
                    x == y || (x.is_nan() && y.is_nan()),
                    "{what}: voxel {i},{j},{k}: {x} vs {y}"
                );
            }
        }
    }
}

#[test]
fn every_generator_writes_what_it_generates() {
    let dir = tempfile::tempdir().unwrap();
    let cases = [
        (Generator::MarschnerLobb, "9", VoxelType::U8, "raw"),
        (Generator::Sphere, "8x6x5", VoxelType::F32, "gzip"),
        (Generator::Torus, "7", VoxelType::I16, "raw"),
        (Generator::NestedSpheres, "6", VoxelType::F64, "gzip"),
        (Generator::Phantom, "16", VoxelType::I16, "gzip"),
        (Generator::Phantom, "12x10x6", VoxelType::U16, "raw"),
    ];
    for (g, size, t, enc) in cases {
        let file = dir.path().join(format!("{g}_{size}_{t}_{enc}.nrrd"));
        let stdout = ok(&[
            "generate",
            g.name(),
            "--size",
            size,
            "--type",
            t.name(),
            "--encoding",
            enc,
            "-o",
            file.to_str().unwrap(),
        ]);
        assert!(stdout.contains("suggested isovalue"), "{stdout}");
        let dims = if size.contains('x') {
            formats::raw::parse_dims(size).unwrap()
        } else {
            g.dims_for_size(size.parse().unwrap())
        };
        let want = g.generate(dims, t).unwrap();
        let Dataset::Volume(got) = open(&file) else {
            panic!("{g}: expected a single volume");
        };
        assert_same(&want, &got, g.name());
    }
}

#[test]
fn defaults_are_the_documented_ones() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("ml.nrrd");
    ok(&["generate", "marschner-lobb", "-o", file.to_str().unwrap()]);
    let v = open(&file);
    assert_eq!(v.first_volume().dims(), [41, 41, 41]);
    assert_eq!(v.first_volume().data.voxel_type(), VoxelType::F32);
    assert_same(
        &Generator::MarschnerLobb
            .generate([41; 3], VoxelType::F32)
            .unwrap(),
        v.first_volume(),
        "default ML",
    );
}

#[test]
fn blobs_series_is_numbered_files_that_open_as_a_series() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("b.nrrd");
    let stdout = ok(&[
        "generate",
        "blobs",
        "--size",
        "10",
        "--steps",
        "4",
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(stdout.contains("b_%03d.nrrd"), "{stdout}");
    for s in 0..4 {
        assert!(dir.path().join(format!("b_{s:03}.nrrd")).is_file());
    }
    assert!(!dir.path().join("b_004.nrrd").exists());
    assert!(!out.exists());
    let Dataset::Series(ts) = open(&dir.path().join("b_%03d.nrrd")) else {
        panic!("expected a series");
    };
    assert_eq!(ts.step_count(), 4);
    let blobs = data_samples::blobs::Blobs::new([10; 3], VoxelType::F32, 4).unwrap();
    for s in 0..4 {
        let want = blobs.step(s, &|| {}).unwrap();
        assert_same(&want, &ts.step(s).unwrap(), &format!("step {s}"));
    }
    // An explicit pattern is used as given.
    let pat = dir.path().join("c%02d.nrrd");
    ok(&[
        "generate",
        "blobs",
        "--size",
        "4",
        "--steps",
        "2",
        "-o",
        pat.to_str().unwrap(),
    ]);
    assert!(dir.path().join("c01.nrrd").is_file());
}

#[test]
fn a_leftover_step_that_would_join_the_series_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("b.nrrd");
    let o = out.to_str().unwrap();
    ok(&["generate", "blobs", "--size", "4", "--steps", "3", "-o", o]);
    let e = fails(&[
        "generate", "blobs", "--size", "4", "--steps", "2", "--force", "-o", o,
    ]);
    assert!(e.contains("b_002.nrrd") && e.contains("step 2"), "{e}");
}

#[test]
fn bad_arguments_are_clear_errors_and_write_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("x.nrrd");
    let o = out.to_str().unwrap();
    let e = fails(&["generate", "spheres", "-o", o]);
    assert!(
        e.contains("unknown generator `spheres`") && e.contains("nested-spheres"),
        "{e}"
    );
    let e = fails(&["generate", "sphere", "--size", "0", "-o", o]);
    assert!(e.contains("at least 2 samples"), "{e}");
    let e = fails(&["generate", "sphere", "--size", "8x1x8", "-o", o]);
    assert!(e.contains("at least 2 samples"), "{e}");
    let e = fails(&["generate", "sphere", "--size", "huge", "-o", o]);
    assert!(e.contains("expected a number"), "{e}");
    let e = fails(&["generate", "sphere", "--type", "float", "-o", o]);
    assert!(e.contains("unknown voxel type `float`"), "{e}");
    let e = fails(&["generate", "sphere", "--steps", "3", "-o", o]);
    assert!(e.contains("--steps only applies"), "{e}");
    let e = fails(&["generate", "blobs", "--steps", "0", "-o", o]);
    assert!(e.contains("--steps must be at least 1"), "{e}");
    let e = fails(&[
        "generate",
        "sphere",
        "-o",
        dir.path().join("x.raw").to_str().unwrap(),
    ]);
    assert!(e.contains("must end in .nrrd"), "{e}");
    let e = fails(&[
        "generate",
        "sphere",
        "-o",
        dir.path().join("no/x.nrrd").to_str().unwrap(),
    ]);
    assert!(e.contains("does not exist"), "{e}");
    let e = fails(&["generate", "sphere", "--encoding", "bzip2", "-o", o]);
    assert!(e.contains("bzip2"), "{e}");
    assert!(
        std::fs::read_dir(dir.path()).unwrap().next().is_none(),
        "nothing written"
    );
}

#[test]
fn existing_files_are_kept_unless_forced() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("s.nrrd");
    std::fs::write(&out, b"precious").unwrap();
    let o = out.to_str().unwrap();
    let e = fails(&["generate", "sphere", "--size", "4", "-o", o]);
    assert!(e.contains("--force"), "{e}");
    assert_eq!(std::fs::read(&out).unwrap(), b"precious");
    ok(&["generate", "sphere", "--size", "4", "--force", "-o", o]);
    assert_eq!(open(&out).first_volume().dims(), [4, 4, 4]);
}
