//! The committed samples in `data-samples/samples/` must still be what the generators produce
//! (regenerated in memory and compared voxel by voxel, geometry exactly). If a generator changes
//! on purpose, rerun `data-samples/samples/make.sh` and update the README there.

use std::path::{Path, PathBuf};

use data_samples::Generator;
use data_samples::blobs::Blobs;
use formats::{Dataset, OpenOptions};
use volume_core::{RectilinearVolume, VoxelType};

fn samples_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("samples")
}

/// Same geometry exactly; voxels equal, except that float samples may differ in the last bits
/// (the platform's `sin`/`exp` are not correctly rounded) and integer samples by one step where
/// such a difference flips a rounding; at most one voxel in a thousand may differ at all.
fn assert_matches(file: &str, got: &RectilinearVolume, want: &RectilinearVolume) {
    assert_eq!(got.dims(), want.dims(), "{file}: dims");
    assert_eq!(
        got.data.voxel_type(),
        want.data.voxel_type(),
        "{file}: type"
    );
    assert_eq!(
        got.grid.uniform_spacing(),
        want.grid.uniform_spacing(),
        "{file}: spacing"
    );
    assert_eq!(got.grid.origin(), want.grid.origin(), "{file}: origin");
    assert_eq!(got.grid.world_from_grid(), None, "{file}: orientation");
    let float = want.data.voxel_type().is_float();
    let [nx, ny, nz] = want.dims();
    let mut differing = 0usize;
    for k in 0..nz {
        for j in 0..ny {
            for i in 0..nx {
                let (g, w) = (got.value_f64(i, j, k), want.value_f64(i, j, k));
                if g == w {
                    continue;
                }
                differing += 1;
                let tol = if float {
                    1e-6 * w.abs().max(1e-30)
                } else {
                    1.0
                };
                assert!(
                    (g - w).abs() <= tol,
                    "{file}: voxel {i},{j},{k}: {g} vs {w}"
                );
            }
        }
    }
    assert!(
        differing * 1000 <= nx * ny * nz,
        "{file}: {differing} voxels differ"
    );
}

fn open_volume(file: &str) -> RectilinearVolume {
    let path = samples_dir().join(file);
    match formats::open(&path, &OpenOptions::default()) {
        Ok(Dataset::Volume(v)) => v,
        Ok(Dataset::Series(_)) => panic!("{file}: expected one volume"),
        Err(e) => panic!("{file}: {e} (regenerate with data-samples/samples/make.sh)"),
    }
}

#[test]
fn committed_volumes_equal_the_generators() {
    // (file, generator, dims, type) — keep in sync with make.sh and README.md.
    let cases = [
        (
            "ml41_u8.nrrd",
            Generator::MarschnerLobb,
            [41, 41, 41],
            VoxelType::U8,
        ),
        (
            "sphere32_f32.nrrd",
            Generator::Sphere,
            [32, 32, 32],
            VoxelType::F32,
        ),
        (
            "torus32_u8.nrrd",
            Generator::Torus,
            [32, 32, 32],
            VoxelType::U8,
        ),
        (
            "nested32_u16.nrrd",
            Generator::NestedSpheres,
            [32, 32, 32],
            VoxelType::U16,
        ),
        (
            "phantom64_i16.nrrd",
            Generator::Phantom,
            [64, 64, 28],
            VoxelType::I16,
        ),
    ];
    for (file, g, dims, t) in cases {
        let got = open_volume(file);
        let want = g.generate(dims, t).unwrap();
        assert_matches(file, &got, &want);
    }
}

#[test]
fn committed_blobs_series_equals_the_generator() {
    let pattern = samples_dir().join("blobs24_%03d.nrrd");
    let Dataset::Series(ts) = formats::open(&pattern, &OpenOptions::default()).unwrap() else {
        panic!("blobs24: expected a series");
    };
    assert_eq!(ts.step_count(), 5);
    let blobs = Blobs::new([24; 3], VoxelType::F32, 5).unwrap();
    for s in 0..5 {
        let want = blobs.step(s, &|| {}).unwrap();
        assert_matches(&format!("blobs24 step {s}"), &ts.step(s).unwrap(), &want);
    }
}

#[test]
fn committed_samples_stay_small() {
    let total: u64 = std::fs::read_dir(samples_dir())
        .unwrap()
        .map(|e| e.unwrap().metadata().unwrap().len())
        .sum();
    assert!(
        total < 3 << 20,
        "samples total {total} bytes; keep them to a few MB"
    );
}
