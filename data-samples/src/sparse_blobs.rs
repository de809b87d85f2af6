//! A big, mostly empty `u8` volume written as a *sparse file*, for the out-of-core test of
//! volumes with more than 2³² voxels (thesis seed 004 §7.7–7.9 uses a 2048²×1920
//! data set).
//!
//! A few analytic blobs (cones in the distance: `PEAK · (1 − d / radius)`, zero outside)
//! are the only non-zero voxels. The raw file is created at full length with `set_len`
//! (a hole, no disk blocks) and only the rows crossing a blob's bounding box are written,
//! so a 2048×2048×1100 volume (4.6 GB) costs a few tens of MB of disk and seconds to make.
//! A detached NRRD header (`NAME.nhdr`, `data file: NAME.raw`) makes it readable by
//! `formats::open` and `isoscope`.
//!
//! The isosurface `value = c` of a blob is the sphere of radius `radius · (1 − c / PEAK)`
//! around its centre ([`Blob::iso_radius`]): the test truth. Voxels are rounded to integers,
//! which moves that sphere by at most `radius / (2 · PEAK)` samples.

use std::fs::File;
use std::io::{self, Seek as _, SeekFrom, Write as _};
use std::path::{Path, PathBuf};

/// The value at a blob's centre.
pub const PEAK: f64 = 200.0;

/// One cone-shaped blob, in sample (index) coordinates.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Blob {
    pub center: [f64; 3],
    pub radius: f64,
}

impl Blob {
    /// The field of this blob at sample `p` (not rounded).
    pub fn value(&self, p: [f64; 3]) -> f64 {
        let d = (0..3)
            .map(|a| (p[a] - self.center[a]).powi(2))
            .sum::<f64>()
            .sqrt();
        (PEAK * (1.0 - d / self.radius)).max(0.0)
    }

    /// Radius of the isosurface `value = iso` (`0 < iso < PEAK`).
    pub fn iso_radius(&self, iso: f64) -> f64 {
        self.radius * (1.0 - iso / PEAK)
    }

    /// Inclusive sample bounds of the non-zero voxels, clamped to `dims`.
    fn bounds(&self, dims: [u64; 3]) -> ([u64; 3], [u64; 3]) {
        let lo = [0, 1, 2].map(|a| (self.center[a] - self.radius).floor().max(0.0) as u64);
        let hi = [0, 1, 2]
            .map(|a| ((self.center[a] + self.radius).ceil().max(0.0) as u64).min(dims[a] - 1));
        (lo, hi)
    }
}

/// The blobs of the 2048×2048×1100 test: one near the origin, one in the middle, and one
/// near the far corner whose voxels straddle linear index 2³² (z = 1024 at 2048² samples
/// per plane), so 32-bit index arithmetic would put it in the wrong place.
pub fn big_test_blobs() -> Vec<Blob> {
    vec![
        Blob {
            center: [150.0, 200.0, 120.0],
            radius: 100.0,
        },
        Blob {
            center: [1024.0, 900.0, 550.0],
            radius: 150.0,
        },
        Blob {
            center: [1900.0, 1850.0, 1030.0],
            radius: 60.0,
        },
    ]
}

/// Dims of the out-of-core test volume: 4 613 734 400 voxels (more than 2³²).
pub const BIG_DIMS: [u64; 3] = [2048, 2048, 1100];

/// The rounded `u8` voxel at sample `p` (the maximum over blobs).
pub fn voxel(blobs: &[Blob], p: [u64; 3]) -> u8 {
    let q = p.map(|x| x as f64);
    let v = blobs.iter().map(|b| b.value(q)).fold(0.0, f64::max);
    v.round().clamp(0.0, 255.0) as u8
}

/// Writes `NAME.raw` (sparse, x fastest) and `NAME.nhdr` into `dir`; returns the header
/// path. Unit spacing, origin 0: world coordinates are sample indices.
pub fn write_sparse_nrrd(
    dir: &Path,
    name: &str,
    dims: [u64; 3],
    blobs: &[Blob],
) -> io::Result<PathBuf> {
    let raw_name = format!("{name}.raw");
    let raw_path = dir.join(&raw_name);
    let total = dims
        .iter()
        .try_fold(1u64, |a, &d| a.checked_mul(d))
        .ok_or_else(|| io::Error::other("voxel count overflows u64"))?;
    let mut file = File::create(&raw_path)?;
    file.set_len(total)?;
    let mut row = Vec::new();
    for b in blobs {
        let (lo, hi) = b.bounds(dims);
        for z in lo[2]..=hi[2] {
            for y in lo[1]..=hi[1] {
                // Other blobs may overlap this row: take the maximum over all of them.
                row.clear();
                row.extend((lo[0]..=hi[0]).map(|x| voxel(blobs, [x, y, z])));
                if row.iter().all(|&v| v == 0) {
                    continue;
                }
                let at = lo[0] + dims[0] * (y + dims[1] * z);
                file.seek(SeekFrom::Start(at))?;
                file.write_all(&row)?;
            }
        }
    }
    file.sync_all()?;
    let header = dir.join(format!("{name}.nhdr"));
    let mut h = File::create(&header)?;
    write!(
        h,
        "NRRD0004\n# sparse analytic blobs, data-samples::sparse_blobs\ntype: uint8\n\
         dimension: 3\nsizes: {} {} {}\nspacings: 1 1 1\nencoding: raw\n\
         data file: {raw_name}\n",
        dims[0], dims[1], dims[2]
    )?;
    Ok(header)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sparse_file_holds_the_blobs_at_64_bit_offsets() {
        // Small dims, blobs at the far end: the written bytes sit where the index says.
        let dims = [40u64, 30, 20];
        let blobs = [
            Blob {
                center: [30.0, 20.0, 15.0],
                radius: 6.0,
            },
            Blob {
                center: [5.0, 5.0, 3.0],
                radius: 4.0,
            },
        ];
        let dir = tempfile_dir();
        let h = write_sparse_nrrd(&dir, "t", dims, &blobs).unwrap();
        let raw = std::fs::read(dir.join("t.raw")).unwrap();
        assert_eq!(raw.len() as u64, dims.iter().product::<u64>());
        let mut nonzero = 0;
        for z in 0..dims[2] {
            for y in 0..dims[1] {
                for x in 0..dims[0] {
                    let i = (x + dims[0] * (y + dims[1] * z)) as usize;
                    assert_eq!(raw[i], voxel(&blobs, [x, y, z]), "{x} {y} {z}");
                    nonzero += usize::from(raw[i] > 0);
                }
            }
        }
        assert!(nonzero > 500);
        assert_eq!(raw[(30 + 40 * (20 + 30 * 15)) as usize], PEAK as u8);
        let text = std::fs::read_to_string(h).unwrap();
        assert!(text.contains("sizes: 40 30 20") && text.contains("data file: t.raw"));
        std::fs::remove_dir_all(dir).unwrap();
    }

    #[test]
    fn big_blobs_straddle_index_two_to_the_32() {
        let blobs = big_test_blobs();
        let plane = BIG_DIMS[0] * BIG_DIMS[1];
        assert!(BIG_DIMS.iter().product::<u64>() > 1 << 32);
        let far = blobs.last().unwrap();
        let (lo, hi) = far.bounds(BIG_DIMS);
        assert!(lo[2] * plane < 1 << 32 && hi[2] * plane > 1 << 32);
        assert!(hi[2] < BIG_DIMS[2]);
        assert!((far.iso_radius(100.0) - 30.0).abs() < 1e-12);
    }

    fn tempfile_dir() -> PathBuf {
        let d = std::env::temp_dir().join(format!(
            "isoscope-sparse-blobs-{}-{:?}",
            std::process::id(),
            std::thread::current().id()
        ));
        std::fs::create_dir_all(&d).unwrap();
        d
    }
}
