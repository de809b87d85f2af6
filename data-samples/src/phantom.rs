//! A CT-like head phantom in Hounsfield units (HU), deterministic.
//!
//! Default: `i16`, 256 × 256 × 110 voxels, anisotropic spacing 0.9 × 0.9 × 1.5 mm (a typical
//! head CT), centred on the origin. Other sizes keep the same field of view
//! (229.5 × 229.5 × 163.5 mm between the first and last samples), so spacing scales.
//!
//! Structures (world millimetres, composited in this order with a smooth 1 mm edge):
//!
//! | structure | shape | value (HU) |
//! |---|---|---|
//! | air | everything else | −1000 |
//! | scalp ("soft tissue") | ellipsoid, semi-axes 80 × 100 × 72 | 40 ± 4 (smooth noise) |
//! | skull | shell between 0.93 and 0.85 of the head ellipsoid | 1200 ± 150 (smooth noise) |
//! | brain | inside 0.85 of the head ellipsoid | 32 ± 6 |
//! | two ventricles | ellipsoids at (±12, 5, 10), 6 × 18 × 10 | 8 |
//! | lesion | sphere at (25, −30, 20), r = 9 | 75 |
//! | calcification | sphere at (−20, 35, −10), r = 3 | 600 |
//! | frontal sinus | ellipsoid at (0, 80, −30), 16 × 9 × 9 | −900 |
//!
//! The noise is a fixed sum of sines (smooth, so isosurfaces stay clean). Values span
//! `[−1000, 1350]`.
//!
//! Real CT is rougher: [`PhantomOptions`] adds what real scans have and the smooth phantom
//! lacks, so benchmarks see realistic surfaces: a scanner table (a 6 mm couch at 250 HU
//! under a foam pad, posterior to the head, across the whole field of view), partial-volume
//! blur (a Gaussian point-spread function of `blur_mm` standard deviation, applied to the
//! sampled field) and quantum noise (white Gaussian noise of `noise_hu` standard deviation,
//! added after the blur, deterministic for a `seed`). The default options give the smooth
//! phantom, bit for bit.
//!
//! Voxel types: `i16`, `i32`, `f32`, `f64` store HU; `u16`, `u32` store `HU + 1024` (the usual
//! unsigned CT convention, rescale intercept −1024); `u8` stores `(HU + 1000)/10` (air 0,
//! bone ≈ 220); `i8` stores `HU/12` (air −83, bone ≈ 100).

use glam::DVec3;
use volume_core::{Grid, RectilinearVolume, VoxelType};

use crate::GenerateError;
use rayon::prelude::*;

use crate::sampling::{ValueMap, check_dims, sample_field, sample_indexed};

/// Default dims (x, y, z).
pub const DEFAULT_DIMS: [usize; 3] = [256, 256, 110];
/// Spacing at the default dims, in millimetres.
pub const DEFAULT_SPACING_MM: [f64; 3] = [0.9, 0.9, 1.5];

pub const AIR_HU: f64 = -1000.0;
pub const SOFT_TISSUE_HU: f64 = 40.0;
pub const BONE_HU: f64 = 1200.0;
pub const BONE_NOISE_HU: f64 = 150.0;
pub const BRAIN_HU: f64 = 32.0;
pub const CSF_HU: f64 = 8.0;
pub const LESION_HU: f64 = 75.0;
pub const CALCIFICATION_HU: f64 = 600.0;
pub const SINUS_HU: f64 = -900.0;
/// Smallest and largest values the phantom takes (HU).
pub const RANGE_HU: (f64, f64) = (AIR_HU, BONE_HU + BONE_NOISE_HU);

/// Semi-axes of the head ellipsoid (mm).
pub const HEAD_SEMI_AXES_MM: DVec3 = DVec3::new(80.0, 100.0, 72.0);
/// The skull shell lies between these fractions of the head ellipsoid.
pub const SKULL_OUTER: f64 = 0.93;
pub const SKULL_INNER: f64 = 0.85;

const EDGE_MM: f64 = 1.0;

/// Spacing for `dims`: the default field of view divided into `dims − 1` cells.
pub fn spacing_for(dims: [usize; 3]) -> [f64; 3] {
    [0, 1, 2].map(|a| {
        // (n0 − 1)/(n − 1) is exactly 1 at the default size, so 0.9 stays 0.9.
        DEFAULT_SPACING_MM[a] * ((DEFAULT_DIMS[a] - 1) as f64 / (dims[a] - 1) as f64)
    })
}

/// Dims for `--size n`: `n × n × round(n · 110/256)` (at least 2).
pub fn dims_for_size(n: usize) -> [usize; 3] {
    let nz = (n as f64 * DEFAULT_DIMS[2] as f64 / DEFAULT_DIMS[0] as f64).round() as usize;
    [n, n, nz.max(2)]
}

/// How HU are stored in `voxel_type` (see the module docs).
pub fn value_map(voxel_type: VoxelType) -> ValueMap {
    match voxel_type {
        VoxelType::I16 | VoxelType::I32 | VoxelType::F32 | VoxelType::F64 => ValueMap::IDENTITY,
        VoxelType::U16 | VoxelType::U32 => ValueMap {
            scale: 1.0,
            offset: 1024.0,
        },
        VoxelType::U8 => ValueMap {
            scale: 0.1,
            offset: 100.0,
        },
        VoxelType::I8 => ValueMap {
            scale: 1.0 / 12.0,
            offset: 0.0,
        },
    }
}

/// `0` outside, `1` inside, a smooth ramp of width `2·EDGE_MM` across the boundary.
/// `sd` is a signed distance (mm, negative inside).
fn coverage(sd: f64) -> f64 {
    let t = ((EDGE_MM - sd) / (2.0 * EDGE_MM)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

/// Approximate signed distance to an axis-aligned ellipsoid (exact for spheres): the
/// normalised radius minus one, scaled by the smallest semi-axis.
fn ellipsoid_sd(p: DVec3, centre: DVec3, semi_axes: DVec3) -> f64 {
    (((p - centre) / semi_axes).length() - 1.0) * semi_axes.min_element()
}

/// Smooth deterministic noise in `[−1, 1]` (a fixed sum of plane waves; wavelengths 15–40 mm).
fn smooth_noise(p: DVec3) -> f64 {
    const WAVES: [(DVec3, f64, f64); 4] = [
        (DVec3::new(0.21, 0.13, -0.07), 0.4, 0.35),
        (DVec3::new(-0.09, 0.27, 0.16), 1.3, 0.25),
        (DVec3::new(0.33, -0.18, 0.24), 2.1, 0.2),
        (DVec3::new(-0.15, -0.11, 0.41), 3.7, 0.2),
    ];
    WAVES
        .iter()
        .map(|&(k, phase, amp)| amp * (k.dot(p) + phase).sin())
        .sum()
}

/// The scanner couch: a slab of this thickness (mm) at [`COUCH_HU`] whose upper face lies
/// at `y = COUCH_TOP_MM` (posterior to the head), under a foam pad at [`PAD_HU`] that reaches
/// up to the back of the head.
pub const COUCH_TOP_MM: f64 = -107.0;
pub const COUCH_THICKNESS_MM: f64 = 6.0;
pub const COUCH_HALF_WIDTH_MM: f64 = 105.0;
pub const COUCH_HU: f64 = 250.0;
pub const PAD_HU: f64 = -850.0;

/// What [`generate_with`] adds to the smooth phantom (see the module docs). The default
/// adds nothing.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PhantomOptions {
    /// Standard deviation of white Gaussian noise, HU (0: none).
    pub noise_hu: f64,
    /// Standard deviation of the Gaussian partial-volume blur, mm (0: none).
    pub blur_mm: f64,
    /// Add the scanner couch and its pad.
    pub table: bool,
    /// Seed of the noise.
    pub seed: u64,
}

impl PhantomOptions {
    pub fn is_smooth(&self) -> bool {
        self.noise_hu == 0.0 && self.blur_mm == 0.0 && !self.table
    }
}

/// The phantom's value (HU) at world position `p` (mm, centred on the origin), with the
/// couch when `table` is set.
pub fn hounsfield_with(p: DVec3, table: bool) -> f64 {
    let v = hounsfield(p);
    if !table || v != AIR_HU {
        return v;
    }
    // A box signed distance across x and y (the couch runs the whole length in z).
    let box_sd = |y_lo: f64, y_hi: f64| {
        let dx = p.x.abs() - COUCH_HALF_WIDTH_MM;
        let dy = (p.y - 0.5 * (y_lo + y_hi)).abs() - 0.5 * (y_hi - y_lo);
        dx.max(dy).min(0.0) + DVec3::new(dx.max(0.0), dy.max(0.0), 0.0).length()
    };
    let couch = box_sd(COUCH_TOP_MM - COUCH_THICKNESS_MM, COUCH_TOP_MM);
    let pad = box_sd(COUCH_TOP_MM, -HEAD_SEMI_AXES_MM.y);
    let lerp = |a: f64, b: f64, t: f64| a * (1.0 - t) + b * t;
    let v = lerp(v, PAD_HU, coverage(pad));
    lerp(v, COUCH_HU, coverage(couch))
}

/// The phantom's value (HU) at world position `p` (mm, centred on the origin).
pub fn hounsfield(p: DVec3) -> f64 {
    // This form returns `a` exactly at t = 0 and `b` exactly at t = 1.
    let lerp = |a: f64, b: f64, t: f64| a * (1.0 - t) + b * t;
    let head = ellipsoid_sd(p, DVec3::ZERO, HEAD_SEMI_AXES_MM);
    let mut v = AIR_HU;
    let c = coverage(head);
    if c == 0.0 {
        return v;
    }
    let noise = smooth_noise(p);
    v = lerp(v, SOFT_TISSUE_HU + 4.0 * noise, c);
    let skull_outer = ellipsoid_sd(p, DVec3::ZERO, HEAD_SEMI_AXES_MM * SKULL_OUTER);
    v = lerp(v, BONE_HU + BONE_NOISE_HU * noise, coverage(skull_outer));
    let skull_inner = ellipsoid_sd(p, DVec3::ZERO, HEAD_SEMI_AXES_MM * SKULL_INNER);
    v = lerp(v, BRAIN_HU + 6.0 * noise, coverage(skull_inner));
    for x in [-12.0, 12.0] {
        let ventricle = ellipsoid_sd(p, DVec3::new(x, 5.0, 10.0), DVec3::new(6.0, 18.0, 10.0));
        v = lerp(v, CSF_HU, coverage(ventricle));
    }
    let lesion = (p - DVec3::new(25.0, -30.0, 20.0)).length() - 9.0;
    v = lerp(v, LESION_HU, coverage(lesion));
    let calcification = (p - DVec3::new(-20.0, 35.0, -10.0)).length() - 3.0;
    v = lerp(v, CALCIFICATION_HU, coverage(calcification));
    let sinus = ellipsoid_sd(p, DVec3::new(0.0, 80.0, -30.0), DVec3::new(16.0, 9.0, 9.0));
    lerp(v, SINUS_HU, coverage(sinus))
}

/// The phantom's grid for `dims`: spacing from [`spacing_for`], centred on the origin.
pub fn grid(dims: [usize; 3]) -> Result<Grid, GenerateError> {
    check_dims(dims)?;
    let spacing = spacing_for(dims);
    let origin = [0, 1, 2].map(|a| -0.5 * (dims[a] - 1) as f64 * spacing[a]);
    Ok(Grid::uniform(dims, origin, spacing)?)
}

/// Samples the phantom on `dims` in `voxel_type` (values stored per [`value_map`]).
pub fn generate(
    dims: [usize; 3],
    voxel_type: VoxelType,
    on_slice: &(dyn Fn() + Sync),
) -> Result<RectilinearVolume, GenerateError> {
    generate_with(dims, voxel_type, &PhantomOptions::default(), on_slice)
}

/// [`generate`] with a table, partial-volume blur and noise ([`PhantomOptions`]).
pub fn generate_with(
    dims: [usize; 3],
    voxel_type: VoxelType,
    options: &PhantomOptions,
    on_slice: &(dyn Fn() + Sync),
) -> Result<RectilinearVolume, GenerateError> {
    let grid = grid(dims)?;
    let map = value_map(voxel_type);
    if options.is_smooth() {
        return sample_field(grid, voxel_type, map, hounsfield, on_slice);
    }
    let count = grid.voxel_count();
    let mut hu: Vec<f32> = Vec::new();
    hu.try_reserve_exact(count)
        .map_err(|_| GenerateError::OutOfMemory { bytes: count * 4 })?;
    hu.resize(count, 0.0);
    let [nx, ny, _] = dims;
    hu.par_chunks_mut(nx * ny)
        .enumerate()
        .for_each(|(k, slice)| {
            for j in 0..ny {
                for i in 0..nx {
                    let p = grid.grid_position(i, j, k);
                    slice[i + nx * j] = hounsfield_with(p, options.table) as f32;
                }
            }
        });
    if options.blur_mm > 0.0 {
        let spacing = spacing_for(dims);
        for (axis, &h) in spacing.iter().enumerate() {
            blur_axis(&mut hu, dims, axis, options.blur_mm / h);
        }
    }
    let noise = options.noise_hu;
    let seed = options.seed;
    sample_indexed(
        grid,
        voxel_type,
        map,
        |[i, j, k]| {
            let idx = i + nx * (j + ny * k);
            let v = f64::from(hu[idx]);
            if noise > 0.0 {
                v + noise * gaussian(seed, idx as u64)
            } else {
                v
            }
        },
        on_slice,
    )
}

/// A standard normal deviate for voxel `index`, a pure function of `(seed, index)` (so the
/// result does not depend on how threads share the work): SplitMix64 and Box–Muller.
fn gaussian(seed: u64, index: u64) -> f64 {
    let mix = |mut z: u64| {
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    };
    let a = mix(seed.wrapping_add(index.wrapping_mul(0x9e37_79b9_7f4a_7c15)));
    let b = mix(a.wrapping_add(0x9e37_79b9_7f4a_7c15));
    // Uniforms in (0, 1] and [0, 1).
    let u1 = ((a >> 11) as f64 + 1.0) / (1u64 << 53) as f64;
    let u2 = (b >> 11) as f64 / (1u64 << 53) as f64;
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

/// Convolves `values` (x fastest, `dims`) along `axis` with a normalised Gaussian of
/// `sigma` samples (radius 3σ, edges clamped), in parallel over the other axes.
fn blur_axis(values: &mut [f32], dims: [usize; 3], axis: usize, sigma: f64) {
    if sigma <= 0.0 {
        return;
    }
    let radius = (3.0 * sigma).ceil() as usize;
    let mut weights: Vec<f64> = (0..=2 * radius)
        .map(|i| {
            let x = i as f64 - radius as f64;
            (-0.5 * (x / sigma).powi(2)).exp()
        })
        .collect();
    let total: f64 = weights.iter().sum();
    for w in &mut weights {
        *w /= total;
    }
    let n = dims[axis];
    let stride = [1, dims[0], dims[0] * dims[1]][axis];
    let src = values.to_vec();
    // One task per z-slice (or y-row block along z): each line along `axis` is read from
    // `src` and written to `values`.
    let [nx, ny, _] = dims;
    values
        .par_chunks_mut(nx * ny)
        .enumerate()
        .for_each(|(k, slice)| {
            for j in 0..ny {
                for i in 0..nx {
                    let here = [i, j, k];
                    let line_start = (i + nx * (j + ny * k)) - here[axis] * stride;
                    let pos = here[axis] as isize;
                    let mut acc = 0.0f64;
                    for (w_i, w) in weights.iter().enumerate() {
                        let q = (pos + w_i as isize - radius as isize).clamp(0, n as isize - 1);
                        acc += w * f64::from(src[line_start + q as usize * stride]);
                    }
                    slice[i + nx * j] = acc as f32;
                }
            }
        });
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_geometry_is_anisotropic_head_ct() {
        let g = grid(DEFAULT_DIMS).unwrap();
        assert_eq!(g.uniform_spacing(), Some([0.9, 0.9, 1.5]));
        let (lo, hi) = g.grid_bounds();
        assert!((lo + hi).length() < 1e-9, "centred: {lo} {hi}");
        assert!((hi.x - 0.5 * 255.0 * 0.9).abs() < 1e-9);
        assert_eq!(dims_for_size(256), DEFAULT_DIMS);
        assert_eq!(dims_for_size(64), [64, 64, 28]);
    }

    #[test]
    fn tissues_have_their_hounsfield_values() {
        let ax = HEAD_SEMI_AXES_MM.x;
        assert_eq!(hounsfield(DVec3::new(110.0, 0.0, 0.0)), AIR_HU);
        let scalp = hounsfield(DVec3::new(0.965 * ax, 0.0, 0.0));
        assert!((scalp - SOFT_TISSUE_HU).abs() <= 4.0, "{scalp}");
        let bone = hounsfield(DVec3::new(0.89 * ax, 0.0, 0.0));
        assert!((bone - BONE_HU).abs() <= BONE_NOISE_HU, "{bone}");
        let brain = hounsfield(DVec3::new(0.0, -10.0, -20.0));
        assert!((brain - BRAIN_HU).abs() <= 6.0, "{brain}");
        assert_eq!(hounsfield(DVec3::new(12.0, 5.0, 10.0)), CSF_HU);
        assert_eq!(hounsfield(DVec3::new(25.0, -30.0, 20.0)), LESION_HU);
        assert_eq!(hounsfield(DVec3::new(-20.0, 35.0, -10.0)), CALCIFICATION_HU);
        assert_eq!(hounsfield(DVec3::new(0.0, 80.0, -30.0)), SINUS_HU);
    }

    #[test]
    fn sampled_i16_volume_spans_air_to_bone() {
        let v = generate([64, 64, 28], VoxelType::I16, &|| {}).unwrap();
        assert_eq!(v.data.voxel_type(), VoxelType::I16);
        let (lo, hi) = v.value_stats().finite_range.unwrap();
        assert_eq!(lo, AIR_HU);
        assert!(hi > 1000.0 && hi <= RANGE_HU.1, "{hi}");
        // The skull is there: a good share of voxels is bone.
        let bone = match &v.data {
            volume_core::VoxelData::I16(b) => b.as_slice().iter().filter(|&&x| x > 900).count(),
            _ => unreachable!(),
        };
        assert!(bone > 1000, "{bone}");
        // Deterministic.
        let again = generate([64, 64, 28], VoxelType::I16, &|| {}).unwrap();
        assert_eq!(again.value_stats(), v.value_stats());
    }

    #[test]
    fn default_options_give_the_smooth_phantom() {
        let a = generate([24, 24, 10], VoxelType::I16, &|| {}).unwrap();
        let b = generate_with(
            [24, 24, 10],
            VoxelType::I16,
            &PhantomOptions::default(),
            &|| {},
        )
        .unwrap();
        for (i, j, k) in [(0, 0, 0), (12, 12, 5), (3, 20, 9)] {
            assert_eq!(a.value_f64(i, j, k), b.value_f64(i, j, k));
        }
    }

    #[test]
    fn noise_has_the_requested_deviation_and_is_deterministic() {
        let dims = [64, 64, 28];
        let opts = PhantomOptions {
            noise_hu: 20.0,
            seed: 7,
            ..PhantomOptions::default()
        };
        let smooth = generate(dims, VoxelType::F32, &|| {}).unwrap();
        let noisy = generate_with(dims, VoxelType::F32, &opts, &|| {}).unwrap();
        let again = generate_with(dims, VoxelType::F32, &opts, &|| {}).unwrap();
        let (mut sum, mut sum2, mut n) = (0.0, 0.0, 0.0);
        for k in 0..dims[2] {
            for j in 0..dims[1] {
                for i in 0..dims[0] {
                    let d = noisy.value_f64(i, j, k) - smooth.value_f64(i, j, k);
                    sum += d;
                    sum2 += d * d;
                    n += 1.0;
                    assert_eq!(noisy.value_f64(i, j, k), again.value_f64(i, j, k));
                }
            }
        }
        let mean = sum / n;
        let sd = (sum2 / n - mean * mean).sqrt();
        // 114688 samples: the sample deviation is within 1 % of 20 with overwhelming odds.
        assert!(
            mean.abs() < 0.5 && (sd - 20.0).abs() < 0.4,
            "mean {mean}, sd {sd}"
        );
    }

    #[test]
    fn blur_spreads_an_edge_by_the_requested_width() {
        // Along x through the head's centre, the air/scalp edge at x = 80 mm: the blurred
        // profile crosses the middle value where the sharp one does and is wider.
        let dims = [256, 8, 4];
        let opts = PhantomOptions {
            blur_mm: 2.0,
            ..PhantomOptions::default()
        };
        let sharp = generate(dims, VoxelType::F32, &|| {}).unwrap();
        let soft = generate_with(dims, VoxelType::F32, &opts, &|| {}).unwrap();
        let g = grid(dims).unwrap();
        let width = |v: &RectilinearVolume| {
            (0..dims[0])
                .filter(|&i| {
                    let x = v.value_f64(i, 4, 2);
                    g.grid_position(i, 4, 2).x > 60.0 && x > -900.0 && x < -100.0
                })
                .count()
        };
        assert!(
            width(&soft) > width(&sharp) + 2,
            "{} vs {}",
            width(&soft),
            width(&sharp)
        );
        // The blur keeps flat regions flat (weights sum to 1).
        assert!((soft.value_f64(0, 4, 2) - AIR_HU).abs() < 1e-3);
    }

    #[test]
    fn the_table_lies_under_the_head_across_the_field_of_view() {
        let on = |x: f64, y: f64| hounsfield_with(DVec3::new(x, y, 0.0), true);
        let y = COUCH_TOP_MM - 0.5 * COUCH_THICKNESS_MM;
        assert_eq!(on(0.0, y), COUCH_HU);
        assert_eq!(on(-90.0, y), COUCH_HU);
        assert_eq!(on(0.0, 0.5 * (COUCH_TOP_MM - HEAD_SEMI_AXES_MM.y)), PAD_HU);
        assert_eq!(on(0.0, 110.0), AIR_HU);
        // The head is unchanged, and without the flag there is no table.
        assert_eq!(on(12.0, 5.0), hounsfield(DVec3::new(12.0, 5.0, 0.0)));
        assert_eq!(hounsfield_with(DVec3::new(0.0, y, 0.0), false), AIR_HU);
    }

    #[test]
    fn unsigned_types_use_documented_offsets() {
        let f = generate([16, 16, 7], VoxelType::F64, &|| {}).unwrap();
        let u = generate([16, 16, 7], VoxelType::U16, &|| {}).unwrap();
        let b = generate([16, 16, 7], VoxelType::U8, &|| {}).unwrap();
        for (i, j, k) in [(0, 0, 0), (8, 8, 3), (2, 8, 3), (15, 9, 6)] {
            let hu = f.value_f64(i, j, k);
            assert_eq!(u.value_f64(i, j, k), (hu + 1024.0).round());
            assert_eq!(
                b.value_f64(i, j, k),
                ((hu + 1000.0) / 10.0).round().min(255.0)
            );
        }
    }
}
