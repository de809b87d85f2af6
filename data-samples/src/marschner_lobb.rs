//! The Marschner–Lobb test signal.
//!
//! S. R. Marschner and R. J. Lobb, "An evaluation of reconstruction filters for volume
//! rendering", IEEE Visualization 1994. The thesis (seed 004, §7.5: Figure 7.5, Table 7.4 and
//! the scalability study of §7.5.2 / Figure 7.6) renders it from 32³ to 1024³; its many thin
//! rings make it a hard case for reconstruction and a good stress test for the kd-tree.
//!
//! With `f_M = 6` and `α = 0.25`, on `[−1, 1]³`:
//!
//! ```text
//! ρ(x, y, z) = (1 − sin(π z / 2) + α (1 + ρ_r(√(x² + y²)))) / (2 (1 + α))
//! ρ_r(r)     = cos(2π f_M cos(π r / 2))
//! ```
//!
//! `ρ` lies in `[0, 1]`; the classic isovalue is `0.5`. Samples are node-centred at
//! `x_i = −1 + 2i/(N−1)` (spacing `2/(N−1)`, origin `−1`), so `N = 41` gives the original
//! 41³ data set.
//!
//! Voxel types: `f32`/`f64` store `ρ`; integer types store `round(ρ · T::MAX)` (the natural
//! range `[0, 1]` mapped onto `[0, T::MAX]`; `u8`: `0..=255`, `i16`: `0..=32767`).

use std::f64::consts::PI;

use glam::DVec3;
use volume_core::{RectilinearVolume, VoxelType};

use crate::GenerateError;
use crate::sampling::{ValueMap, sample_field, unit_cube_grid};

/// Maximum frequency `f_M` of the radial rings.
pub const F_M: f64 = 6.0;
/// Modulation depth `α` of the rings.
pub const ALPHA: f64 = 0.25;
/// The isovalue used in the literature.
pub const ISOVALUE: f64 = 0.5;
/// Natural value range of `ρ`.
pub const RANGE: (f64, f64) = (0.0, 1.0);

/// The radial ring term `ρ_r(r) = cos(2π f_M cos(π r / 2))`.
pub fn rho_r(r: f64) -> f64 {
    (2.0 * PI * F_M * (PI * r / 2.0).cos()).cos()
}

/// The Marschner–Lobb signal `ρ(x, y, z)` in `[0, 1]`.
pub fn rho(p: DVec3) -> f64 {
    let r = p.x.hypot(p.y);
    (1.0 - (PI * p.z / 2.0).sin() + ALPHA * (1.0 + rho_r(r))) / (2.0 * (1.0 + ALPHA))
}

/// How `ρ` is stored in `voxel_type` (see the module docs).
pub fn value_map(voxel_type: VoxelType) -> ValueMap {
    ValueMap::range_to_type(RANGE.0, RANGE.1, voxel_type)
}

/// Samples the signal on `dims` (each ≥ 2) over `[−1, 1]³`.
pub fn generate(
    dims: [usize; 3],
    voxel_type: VoxelType,
) -> Result<RectilinearVolume, GenerateError> {
    generate_with_progress(dims, voxel_type, &|| {})
}

/// [`generate`], calling `on_slice` after each z-slice.
pub fn generate_with_progress(
    dims: [usize; 3],
    voxel_type: VoxelType,
    on_slice: &(dyn Fn() + Sync),
) -> Result<RectilinearVolume, GenerateError> {
    let grid = unit_cube_grid(dims)?;
    sample_field(grid, voxel_type, value_map(voxel_type), rho, on_slice)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::FRAC_PI_2;

    /// The paper's formula typed again, independently of `rho`.
    fn reference(x: f64, y: f64, z: f64) -> f64 {
        let (fm, a) = (6.0_f64, 0.25_f64);
        let r = (x * x + y * y).sqrt();
        let ring = (2.0 * PI * fm * (FRAC_PI_2 * r).cos()).cos();
        (1.0 - (FRAC_PI_2 * z).sin() + a * (1.0 + ring)) / (2.0 * (1.0 + a))
    }

    #[test]
    fn values_at_hand_computed_points() {
        let v = generate([41, 41, 41], VoxelType::F64).unwrap();
        // Centre: r = 0 → ρ_r = cos(12π) = 1 → (1 − 0 + 0.5)/2.5 = 0.6.
        assert!((v.value_f64(20, 20, 20) - 0.6).abs() < 1e-12);
        // Top (z = 1): (1 − 1 + 0.5)/2.5 = 0.2.
        assert!((v.value_f64(20, 20, 40) - 0.2).abs() < 1e-12);
        // Bottom (z = −1): (1 + 1 + 0.5)/2.5 = 1.
        assert!((v.value_f64(20, 20, 0) - 1.0).abs() < 1e-12);
        // r = 1 (x = 1, y = 0): cos(π/2) = 0 → ρ_r = 1 → 0.6 at z = 0.
        assert!((v.value_f64(40, 20, 20) - 0.6).abs() < 1e-12);
        // r = 2/3 on a 7-sample grid (x_5 = 2/3): cos(π/3) = 1/2 → ρ_r = cos(6π) = 1 → 0.6.
        let v7 = generate([7, 7, 7], VoxelType::F64).unwrap();
        assert!((v7.value_f64(5, 3, 3) - 0.6).abs() < 1e-12);
    }

    #[test]
    fn every_voxel_matches_the_reference_formula() {
        let n = 13;
        let v = generate([n, n, n], VoxelType::F64).unwrap();
        let s = v.grid.uniform_spacing().unwrap();
        assert_eq!(s, [2.0 / 12.0; 3]);
        assert_eq!(v.grid.origin(), DVec3::splat(-1.0));
        for k in 0..n {
            for j in 0..n {
                for i in 0..n {
                    let x = |i: usize| -1.0 + 2.0 * i as f64 / (n - 1) as f64;
                    let want = reference(x(i), x(j), x(k));
                    assert!((v.value_f64(i, j, k) - want).abs() < 1e-12, "{i} {j} {k}");
                }
            }
        }
    }

    #[test]
    fn integer_types_map_zero_one_onto_the_type_range() {
        let f = generate([9, 9, 9], VoxelType::F64).unwrap();
        let u = generate([9, 9, 9], VoxelType::U8).unwrap();
        let s = generate([9, 9, 9], VoxelType::I16).unwrap();
        for (i, j, k) in [(0, 0, 0), (4, 4, 4), (8, 3, 1), (2, 7, 5)] {
            let rho = f.value_f64(i, j, k);
            assert_eq!(u.value_f64(i, j, k), (rho * 255.0).round());
            assert_eq!(s.value_f64(i, j, k), (rho * 32767.0).round());
        }
        let (lo, hi) = f.value_stats().finite_range.unwrap();
        assert!(lo >= 0.0 && hi <= 1.0);
    }
}
