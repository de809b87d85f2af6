//! A time-varying series: four Gaussian blobs that move and merge.
//!
//! `f(p, t) = Σ_k exp(−|p − c_k(t)|² / (2σ²))` on `[−1, 1]³` (node-centred like
//! Marschner–Lobb), `σ = `[`SIGMA`], with `t = step/(steps − 1) ∈ [0, 1]`. Each centre moves
//! from its start to its end along an eased path `c_k(t) = s_k + (e_k − s_k)·(3t² − 2t³)`.
//! Blobs 0 and 1 end at the same point, as do blobs 2 and 3, and the two merged pairs end
//! close enough that the isosurface `f = 0.5` ([`ISOVALUE`]) goes from four separate
//! components at `t = 0` to a single one at `t = 1` (checked in the tests).
//!
//! The default is 20 steps ([`DEFAULT_STEPS`]). The series can be materialised step by step
//! ([`Blobs::step`]) or opened lazily as a `volume_core::series::TimeSeries` through
//! [`Blobs`]'s [`StepLoader`] implementation.
//!
//! Voxel types: floats store `f`; integer types map `[0, 2.5]` onto `[0, T::MAX]` (values never
//! exceed 2.5: two coincident blobs give 2, the others add less than 0.1).

use std::sync::Arc;

use glam::DVec3;
use volume_core::series::{StepLoader, TimeSeries};
use volume_core::{RectilinearVolume, VoxelType};

use crate::GenerateError;
use crate::sampling::{ValueMap, check_dims, sample_field, unit_cube_grid};

/// Number of steps of the `blobs` generator by default.
pub const DEFAULT_STEPS: usize = 20;
/// Width of every blob.
pub const SIGMA: f64 = 0.16;
/// The isovalue the series is designed for.
pub const ISOVALUE: f64 = 0.5;
/// Natural range used for integer voxel types.
pub const RANGE: (f64, f64) = (0.0, 2.5);

/// Start and end positions of the four blobs.
pub const PATHS: [(DVec3, DVec3); 4] = [
    (DVec3::new(-0.6, -0.5, -0.3), DVec3::new(-0.25, 0.0, 0.0)),
    (DVec3::new(-0.5, 0.6, 0.3), DVec3::new(-0.25, 0.0, 0.0)),
    (DVec3::new(0.6, 0.5, -0.2), DVec3::new(0.25, 0.0, 0.0)),
    (DVec3::new(0.55, -0.55, 0.35), DVec3::new(0.25, 0.0, 0.0)),
];

/// Normalised time of `step` in a series of `steps` (0 for a single step).
pub fn time_of_step(step: usize, steps: usize) -> f64 {
    if steps <= 1 {
        0.0
    } else {
        step as f64 / (steps - 1) as f64
    }
}

/// Centre of blob `k` at normalised time `t`.
pub fn centre(k: usize, t: f64) -> DVec3 {
    let (start, end) = PATHS[k];
    let ease = t * t * (3.0 - 2.0 * t);
    start + (end - start) * ease
}

/// The field at position `p` and normalised time `t`.
pub fn field(p: DVec3, t: f64) -> f64 {
    (0..PATHS.len())
        .map(|k| (-(p - centre(k, t)).length_squared() / (2.0 * SIGMA * SIGMA)).exp())
        .sum()
}

/// How `f` is stored in `voxel_type` (see the module docs).
pub fn value_map(voxel_type: VoxelType) -> ValueMap {
    ValueMap::range_to_type(RANGE.0, RANGE.1, voxel_type)
}

/// The blobs series at a given size, type and step count. Also a lazy [`StepLoader`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Blobs {
    dims: [usize; 3],
    voxel_type: VoxelType,
    steps: usize,
}

impl Blobs {
    /// Checks the size (every axis ≥ 2) and step count (≥ 1).
    pub fn new(
        dims: [usize; 3],
        voxel_type: VoxelType,
        steps: usize,
    ) -> Result<Self, GenerateError> {
        check_dims(dims)?;
        if steps == 0 {
            return Err(GenerateError::NoSteps);
        }
        Ok(Self {
            dims,
            voxel_type,
            steps,
        })
    }

    pub fn dims(&self) -> [usize; 3] {
        self.dims
    }

    pub fn voxel_type(&self) -> VoxelType {
        self.voxel_type
    }

    pub fn steps(&self) -> usize {
        self.steps
    }

    /// Samples step `step` (< `steps`), calling `on_slice` after each z-slice.
    pub fn step(
        &self,
        step: usize,
        on_slice: &(dyn Fn() + Sync),
    ) -> Result<RectilinearVolume, GenerateError> {
        if step >= self.steps {
            return Err(GenerateError::StepOutOfRange {
                step,
                steps: self.steps,
            });
        }
        let t = time_of_step(step, self.steps);
        sample_field(
            unit_cube_grid(self.dims)?,
            self.voxel_type,
            value_map(self.voxel_type),
            |p| field(p, t),
            on_slice,
        )
    }

    /// Opens the series lazily: steps are generated when first asked for.
    pub fn into_time_series(self) -> Result<TimeSeries, GenerateError> {
        Ok(TimeSeries::open(Arc::new(self))?)
    }
}

impl StepLoader for Blobs {
    fn step_count(&self) -> usize {
        self.steps
    }

    fn load_step(&self, step: usize) -> Result<RectilinearVolume, String> {
        self.step(step, &|| {}).map_err(|e| e.to_string())
    }

    fn time_value(&self, step: usize) -> Option<f64> {
        Some(time_of_step(step, self.steps))
    }

    fn describe(&self) -> String {
        format!(
            "blobs generator: {} steps of {}x{}x{} {}",
            self.steps, self.dims[0], self.dims[1], self.dims[2], self.voxel_type
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Number of 6-connected components of `{v > iso}` (brute-force flood fill).
    fn components(v: &RectilinearVolume, iso: f64) -> usize {
        let [nx, ny, nz] = v.dims();
        let mut seen = vec![false; nx * ny * nz];
        let mut count = 0;
        for start in 0..seen.len() {
            let (i, j, k) = (start % nx, (start / nx) % ny, start / (nx * ny));
            if seen[start] || v.value_f64(i, j, k) <= iso {
                continue;
            }
            count += 1;
            let mut stack = vec![start];
            seen[start] = true;
            while let Some(idx) = stack.pop() {
                let (i, j, k) = (idx % nx, (idx / nx) % ny, idx / (nx * ny));
                let mut visit = |i: usize, j: usize, k: usize| {
                    let n = i + nx * (j + ny * k);
                    if !seen[n] && v.value_f64(i, j, k) > iso {
                        seen[n] = true;
                        stack.push(n);
                    }
                };
                if i > 0 {
                    visit(i - 1, j, k);
                }
                if i + 1 < nx {
                    visit(i + 1, j, k);
                }
                if j > 0 {
                    visit(i, j - 1, k);
                }
                if j + 1 < ny {
                    visit(i, j + 1, k);
                }
                if k > 0 {
                    visit(i, j, k - 1);
                }
                if k + 1 < nz {
                    visit(i, j, k + 1);
                }
            }
        }
        count
    }

    #[test]
    fn blobs_start_apart_and_end_merged() {
        let b = Blobs::new([33, 33, 33], VoxelType::F32, DEFAULT_STEPS).unwrap();
        let first = b.step(0, &|| {}).unwrap();
        let last = b.step(DEFAULT_STEPS - 1, &|| {}).unwrap();
        assert_eq!(components(&first, ISOVALUE), 4);
        assert_eq!(components(&last, ISOVALUE), 1);
        assert!(matches!(
            b.step(DEFAULT_STEPS, &|| {}),
            Err(GenerateError::StepOutOfRange { .. })
        ));
    }

    #[test]
    fn centres_move_along_their_paths() {
        assert_eq!(centre(0, 0.0), PATHS[0].0);
        assert_eq!(centre(0, 1.0), PATHS[0].1);
        assert_eq!(centre(1, 1.0), centre(0, 1.0));
        // The sampled maximum follows the centre: at t = 0 the voxel nearest blob 2's start
        // is a local maximum of the field.
        let b = Blobs::new([41, 41, 41], VoxelType::F64, 5).unwrap();
        let v = b.step(0, &|| {}).unwrap();
        let idx = |x: f64| ((x + 1.0) / 0.05).round() as usize;
        let s = PATHS[2].0;
        let (i, j, k) = (idx(s.x), idx(s.y), idx(s.z));
        let c = v.value_f64(i, j, k);
        for (di, dj, dk) in [(1, 0, 0), (0, 1, 0), (0, 0, 1)] {
            assert!(c > v.value_f64(i + di, j + dj, k + dk));
            assert!(c > v.value_f64(i - di, j - dj, k - dk));
        }
        // Step 2 of 5 is t = 1/2: the voxel value there matches the field at that time.
        let mid = b.step(2, &|| {}).unwrap();
        let p = mid.grid.grid_position(13, 20, 27);
        assert!((mid.value_f64(13, 20, 27) - field(p, 0.5)).abs() < 1e-15);
        assert_ne!(mid.value_f64(i, j, k), c);
    }

    #[test]
    fn lazy_series_has_the_steps_and_times() {
        let ts = Blobs::new([8, 8, 8], VoxelType::U8, 20)
            .unwrap()
            .into_time_series()
            .unwrap();
        assert_eq!(ts.step_count(), 20);
        assert_eq!(ts.time_value(19), 1.0);
        assert_eq!(ts.step(19).unwrap().dims(), [8, 8, 8]);
        assert!(Blobs::new([8, 8, 8], VoxelType::U8, 0).is_err());
    }

    #[test]
    fn values_stay_inside_the_quantization_range() {
        let b = Blobs::new([25, 25, 25], VoxelType::F64, 20).unwrap();
        for s in 0..20 {
            let (lo, hi) = b
                .step(s, &|| {})
                .unwrap()
                .value_stats()
                .finite_range
                .unwrap();
            assert!(lo >= RANGE.0 && hi < RANGE.1, "step {s}: {lo} {hi}");
        }
    }
}
