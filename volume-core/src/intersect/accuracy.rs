//! Accuracy of the intersectors against the `f64` reference, and the extreme suite.
//!
//! [`compare`] traces the same rays through the same kd-tree twice, once with the
//! intersector under test and once with [`Intersector::Reference`], and counts *missed*
//! hits (the reference hits, the method does not), *false* hits (the method hits, the
//! reference does not) and `|Δt|` in cell units (traversal units: one cell on uniform axes)
//! where both hit. It runs on any volume and any rays (camera rays for the
//! Marschner–Lobb tables of docs/accuracy.md).
//!
//! [`extreme_suite`] builds the hard cases of issue 3: grazing and axis-parallel rays, rays
//! along cell faces and edges, tangent (double-root) and triple-root cells, integer data at
//! integer isovalues, constant cells, NaN and ±inf voxels, values near the `f32` limits and
//! denormals, a volume far from the origin, one-cell-thin volumes and a camera inside the
//! volume. Every case is deterministic (seeded).

use std::time::Instant;

use glam::Vec3;

use crate::grid_scene::{AnyGridScene, GridScene};
use crate::intersect::{CellHit, Intersector, IsoSet};
use crate::kdtree::KdTreeConfig;
use crate::math::Ray;
use crate::render::NoStats;
use crate::volume::{Grid, RectilinearVolume, VoxelData};
use crate::voxel::Voxel;

/// One volume, its isovalues and the rays to score.
#[derive(Debug, Clone)]
pub struct Case {
    pub name: String,
    pub volume: RectilinearVolume,
    pub isovalues: Vec<f32>,
    pub rays: Vec<Ray>,
}

/// Scores of one intersector on one set of rays.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct AccuracyReport {
    pub intersector: Intersector,
    pub rays: u64,
    /// Rays the reference hits.
    pub reference_hits: u64,
    pub missed: u64,
    pub false_hits: u64,
    /// Over rays both hit: mean and max `|t − t_ref|` in cell units.
    pub mean_abs_dt_cells: f64,
    pub max_abs_dt_cells: f64,
    /// Rays where both hit but on different surfaces.
    pub wrong_surface: u64,
    /// Time of the method's own traversal (not the reference's).
    pub seconds: f64,
}

impl AccuracyReport {
    pub fn missed_percent(&self) -> f64 {
        100.0 * self.missed as f64 / self.reference_hits.max(1) as f64
    }

    pub fn false_percent(&self) -> f64 {
        100.0 * self.false_hits as f64 / self.rays.max(1) as f64
    }

    pub fn mrays_per_second(&self) -> f64 {
        if self.seconds > 0.0 {
            self.rays as f64 / self.seconds / 1e6
        } else {
            0.0
        }
    }
}

/// Scores `intersector` against the reference on `rays` through `scene`.
pub fn compare(
    scene: &AnyGridScene,
    rays: &[Ray],
    isovalues: &[f32],
    intersector: Intersector,
) -> AccuracyReport {
    crate::dispatch_grid_scene!(scene, s => compare_typed(s, rays, isovalues, intersector))
}

/// Builds the scene for a [`Case`] and scores `intersector` on it.
pub fn compare_case(case: &Case, intersector: Intersector) -> AccuracyReport {
    let scene = AnyGridScene::new(&case.volume, intersector);
    compare(&scene, &case.rays, &case.isovalues, intersector)
}

fn trace<T: Voxel>(
    scene: &GridScene<T>,
    rays: &[Ray],
    isos: &IsoSet<T>,
    intersector: Intersector,
) -> Vec<Option<(CellHit, f32)>> {
    crate::dispatch_intersector!(intersector, c => rays
        .iter()
        .map(|r| {
            let local = scene.frame().to_local(r);
            scene
                .cell_hit_with(&local, 0.0, f32::INFINITY, isos, c, &mut NoStats)
                .map(|h| (h, local.dir.length()))
        })
        .collect())
}

fn compare_typed<T: Voxel>(
    scene: &GridScene<T>,
    rays: &[Ray],
    isovalues: &[f32],
    intersector: Intersector,
) -> AccuracyReport {
    let isos = IsoSet::<T>::new(isovalues);
    let start = Instant::now();
    let got = trace(scene, rays, &isos, intersector);
    let seconds = start.elapsed().as_secs_f64();
    let truth = trace(scene, rays, &isos, Intersector::Reference);
    let mut r = AccuracyReport {
        intersector,
        rays: rays.len() as u64,
        reference_hits: 0,
        missed: 0,
        false_hits: 0,
        mean_abs_dt_cells: 0.0,
        max_abs_dt_cells: 0.0,
        wrong_surface: 0,
        seconds,
    };
    let mut both = 0u64;
    let mut sum = 0.0f64;
    for (g, t) in got.iter().zip(&truth) {
        match (g, t) {
            (Some((g, speed)), Some((t, _))) => {
                r.reference_hits += 1;
                both += 1;
                let dt = f64::from((g.t - t.t).abs()) * f64::from(*speed);
                sum += dt;
                r.max_abs_dt_cells = r.max_abs_dt_cells.max(dt);
                if g.surface != t.surface {
                    r.wrong_surface += 1;
                }
            }
            (None, Some(_)) => {
                r.reference_hits += 1;
                r.missed += 1;
            }
            (Some(_), None) => r.false_hits += 1,
            (None, None) => {}
        }
    }
    if both > 0 {
        r.mean_abs_dt_cells = sum / both as f64;
    }
    r
}

/// Deterministic generator for the suite.
struct Lcg(u64);

impl Lcg {
    fn unit(&mut self) -> f32 {
        self.0 = self
            .0
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        ((self.0 >> 11) as f64 / (1u64 << 53) as f64) as f32
    }
    fn range(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * self.unit()
    }
    fn vec(&mut self, lo: f32, hi: f32) -> Vec3 {
        Vec3::new(self.range(lo, hi), self.range(lo, hi), self.range(lo, hi))
    }
    fn index(&mut self, n: usize) -> usize {
        ((self.unit() * n as f32) as usize).min(n.saturating_sub(1))
    }
}

fn volume<T: Voxel>(
    dims: [usize; 3],
    origin: [f64; 3],
    spacing: [f64; 3],
    mut f: impl FnMut(usize, usize, usize) -> T,
) -> RectilinearVolume
where
    VoxelData: From<Vec<T>>,
{
    let grid = Grid::uniform(dims, origin, spacing).expect("suite grids are valid");
    let mut v = Vec::with_capacity(dims.iter().product());
    for k in 0..dims[2] {
        for j in 0..dims[1] {
            for i in 0..dims[0] {
                v.push(f(i, j, k));
            }
        }
    }
    RectilinearVolume::new(grid, VoxelData::from(v)).expect("suite volumes are valid")
}

/// A smooth test field in `[-1, 1]` over sample indices.
fn smooth(i: usize, j: usize, k: usize) -> f32 {
    let (x, y, z) = (i as f32, j as f32, k as f32);
    (0.45 * x + 0.3).sin() * (0.37 * y - 0.2).cos() + 0.5 * (0.29 * z + 0.1 * x).sin()
}

/// World bounds of a volume (axis-aligned grids in the suite).
fn bounds(v: &RectilinearVolume) -> (Vec3, Vec3) {
    let (lo, hi) = v.grid.grid_bounds();
    (lo.as_vec3(), hi.as_vec3())
}

/// Rays from outside the bounds towards random interior points.
fn rays_from_outside(rng: &mut Lcg, lo: Vec3, hi: Vec3, n: usize) -> Vec<Ray> {
    let c = (lo + hi) * 0.5;
    let ext = (hi - lo).max(Vec3::ONE);
    (0..n)
        .map(|_| {
            let dir = rng.vec(-1.0, 1.0).normalize_or(Vec3::X);
            let target = c + rng.vec(-0.45, 0.45) * ext;
            Ray::new(target - dir * ext.length() * 1.5, dir)
        })
        .collect()
}

/// The extreme suite (see the module docs).
pub fn extreme_suite() -> Vec<Case> {
    let mut rng = Lcg(0x1505_c0de);
    let mut cases = Vec::new();

    // Grazing rays: tangent to a distance-field sphere's silhouette, ±0.3 cell.
    {
        let n = 20;
        let c = (n - 1) as f32 * 0.5;
        let r = 6.0f32;
        let vol = volume([n; 3], [0.0; 3], [1.0; 3], |i, j, k| {
            (Vec3::new(i as f32, j as f32, k as f32) - Vec3::splat(c)).length()
        });
        let rays = (0..400)
            .map(|_| {
                let dir = rng.vec(-1.0, 1.0).normalize_or(Vec3::X);
                let side = dir.any_orthonormal_vector();
                let side =
                    (glam::Quat::from_axis_angle(dir, rng.range(0.0, std::f32::consts::TAU))
                        * side)
                        .normalize();
                let off = r + rng.range(-0.3, 0.3);
                Ray::new(Vec3::splat(c) + side * off - dir * 15.0, dir)
            })
            .collect();
        cases.push(Case {
            name: "grazing rays (sphere silhouette)".into(),
            volume: vol,
            isovalues: vec![r],
            rays,
        });
    }

    let smooth_vol = volume([16, 14, 12], [0.0; 3], [1.0; 3], smooth);
    let (lo, hi) = bounds(&smooth_vol);

    // Axis-parallel rays at random positions.
    {
        let rays = (0..300)
            .map(|i| {
                let a = i % 3;
                let sign = if (i / 3) % 2 == 0 { 1.0 } else { -1.0 };
                let mut o = lo + rng.vec(0.0, 1.0) * (hi - lo);
                o[a] = if sign > 0.0 { lo[a] - 2.0 } else { hi[a] + 2.0 };
                let mut d = Vec3::ZERO;
                d[a] = sign;
                Ray::new(o, d)
            })
            .collect();
        cases.push(Case {
            name: "axis-parallel rays".into(),
            volume: smooth_vol.clone(),
            isovalues: vec![0.1, 0.6],
            rays,
        });
    }

    // Rays in cell-face planes and along cell edges (origins on sample coordinates).
    {
        let rays = (0..300)
            .map(|i| {
                let a = i % 3;
                let mut o = lo + rng.vec(0.0, 1.0) * (hi - lo);
                let mut d = rng.vec(-1.0, 1.0);
                o[a] = rng.index(hi[a] as usize + 1) as f32;
                d[a] = 0.0;
                if i % 2 == 0 {
                    // Along an edge: a second axis on a sample coordinate, too.
                    let b = (a + 1) % 3;
                    o[b] = rng.index(hi[b] as usize + 1) as f32;
                    d[b] = 0.0;
                }
                let d = d.normalize_or(Vec3::X);
                let far = (hi - lo).length();
                Ray::new(o - d * far, d)
            })
            .collect();
        cases.push(Case {
            name: "rays along cell faces and edges".into(),
            volume: smooth_vol.clone(),
            isovalues: vec![0.1, -0.4],
            rays,
        });
    }

    // Tangent cells: v = 100 + (−1)^(i+j); diagonal rays x = y + m through the saddles
    // touch the isovalue 100 with a double root.
    {
        let vol = volume([9, 9, 4], [0.0; 3], [1.0; 3], |i, j, _| {
            if (i + j) % 2 == 0 { 101u8 } else { 99u8 }
        });
        let rays = (0..200)
            .map(|_| {
                let m = rng.index(7) as f32 - 3.0;
                let z = rng.range(0.0, 3.0);
                let d = Vec3::new(1.0, 1.0, 0.0).normalize();
                let o = Vec3::new(m - 2.0, -2.0, z);
                if rng.unit() < 0.5 {
                    Ray::new(o, d)
                } else {
                    Ray::new(o + d * 30.0, -d)
                }
            })
            .collect();
        cases.push(Case {
            name: "tangent (double-root) cells".into(),
            volume: vol,
            isovalues: vec![100.0],
            rays,
        });
    }

    // Triple roots: v = (−1)^(i+j+k); along x = y = z the interpolant is (1 − 2s)³.
    {
        let vol = volume([7, 7, 7], [0.0; 3], [1.0; 3], |i, j, k| {
            if (i + j + k) % 2 == 0 { 1.0f32 } else { -1.0 }
        });
        let rays = (0..150)
            .map(|_| {
                let off = Vec3::new(rng.index(5) as f32 - 2.0, rng.index(5) as f32 - 2.0, 0.0);
                let d = Vec3::ONE.normalize();
                Ray::new(off - Vec3::splat(2.0), d)
            })
            .collect();
        cases.push(Case {
            name: "triple-root cells".into(),
            volume: vol,
            isovalues: vec![0.0],
            rays,
        });
    }

    // Integer data at integer isovalues, with constant cells (equal and not equal to iso).
    {
        let vol = volume([14, 12, 10], [0.0; 3], [1.0; 3], |i, j, k| {
            if i < 5 && j < 5 {
                4u8 // a constant block equal to the isovalue
            } else if i > 9 {
                7u8 // a constant block above it
            } else {
                ((i * 7 + j * 3 + k * 5) % 9) as u8
            }
        });
        let (lo, hi) = bounds(&vol);
        let rays = rays_from_outside(&mut rng, lo, hi, 400);
        cases.push(Case {
            name: "integer data at integer isovalues, constant cells".into(),
            volume: vol,
            isovalues: vec![4.0, 7.0],
            rays,
        });
    }

    // NaN and ±inf voxels.
    {
        let mut r2 = Lcg(99);
        let vol = volume([16, 14, 12], [0.0; 3], [1.0; 3], |i, j, k| {
            let u = r2.unit();
            if u < 0.05 {
                f32::NAN
            } else if u < 0.07 {
                f32::INFINITY
            } else if u < 0.09 {
                f32::NEG_INFINITY
            } else {
                smooth(i, j, k)
            }
        });
        let rays = rays_from_outside(&mut rng, lo, hi, 400);
        cases.push(Case {
            name: "NaN and ±inf voxels".into(),
            volume: vol,
            isovalues: vec![0.1],
            rays,
        });
    }

    // Values near the f32 limits and denormals.
    for (name, scale, iso) in [
        ("values near f32 limits (1e30..1e38)", 1e38f32, 3e37f32),
        ("denormal values", 1e-39, 2e-40),
    ] {
        let vol = volume([16, 14, 12], [0.0; 3], [1.0; 3], |i, j, k| {
            smooth(i, j, k) * scale
        });
        let rays = rays_from_outside(&mut rng, lo, hi, 300);
        cases.push(Case {
            name: name.into(),
            volume: vol,
            isovalues: vec![iso],
            rays,
        });
    }

    // Far from the origin (1e6) with fine spacing.
    {
        let origin = [1e6, 1e6, -1e6];
        let vol = volume([16, 14, 12], origin, [0.5; 3], smooth);
        let (lo, hi) = bounds(&vol);
        let rays = rays_from_outside(&mut rng, lo, hi, 300);
        cases.push(Case {
            name: "volume far from the origin (1e6)".into(),
            volume: vol,
            isovalues: vec![0.1],
            rays,
        });
    }

    // One cell thin (2×N×M, N×2×M) and one sample thin (1×N×M: no cells, no surface).
    for dims in [[2, 18, 15], [17, 2, 9], [1, 12, 12]] {
        let vol = volume(dims, [0.0; 3], [1.0; 3], smooth);
        let (lo, hi) = bounds(&vol);
        let rays = rays_from_outside(&mut rng, lo, hi, 300);
        cases.push(Case {
            name: format!("{}×{}×{} volume", dims[0], dims[1], dims[2]),
            volume: vol,
            isovalues: vec![0.1],
            rays,
        });
    }

    // Camera inside the volume.
    {
        let rays = (0..400)
            .map(|_| {
                let o = lo + rng.vec(0.1, 0.9) * (hi - lo);
                Ray::new(o, rng.vec(-1.0, 1.0).normalize_or(Vec3::Z))
            })
            .collect();
        cases.push(Case {
            name: "camera inside the volume".into(),
            volume: smooth_vol,
            isovalues: vec![0.1, 0.7],
            rays,
        });
    }
    cases
}

/// Scores every intersector on every case of the extreme suite.
pub fn run_extreme_suite(intersectors: &[Intersector]) -> Vec<(String, Vec<AccuracyReport>)> {
    extreme_suite()
        .iter()
        .map(|case| {
            let scene = AnyGridScene::with_config(
                &case.volume,
                Intersector::Exact,
                KdTreeConfig::default(),
            );
            let reports = intersectors
                .iter()
                .map(|&i| compare(&scene, &case.rays, &case.isovalues, i))
                .collect();
            (case.name.clone(), reports)
        })
        .collect()
}
