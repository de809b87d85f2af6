//! Accuracy of the intersectors against the `f64` reference, and the extreme suite.
//!
//! [`compare`] traces the same rays through the same kd-tree twice, once with the
//! intersector under test and once with [`Intersector::Reference`], and counts *missed*
//! hits (the reference hits, the method does not), *false* hits (the method hits, the
//! reference does not) and `|Δt|` in cell units (traversal units: one cell on uniform axes)
//! where both hit. It runs on any volume and any rays (camera rays for the
//! Marschner–Lobb tables of docs/accuracy.md).
//!
//! [`extreme_suite`] builds the hard cases for the cell intersectors (seed 004 §7.2.2): grazing and axis-parallel rays, rays
//! along cell faces and edges, tangent (double-root) and triple-root cells, integer data at
//! integer isovalues, constant cells, NaN and ±inf voxels, values near the `f32` limits and
//! denormals, a volume far from the origin, one-cell-thin volumes and a camera inside the
//! volume. Every case is deterministic (seeded). Later cases add the variants the first
//! ones leave open: `f32` tangent cells and near-tangent rays (two roots 1e-2…1e-4 cell
//! apart), `i16` data with rays running along iso-valued grid lines, origins on sample
//! positions and inside iso-valued constant cells, rays in the volume's outer faces, values
//! around 1e30, and thin volumes along every axis.
//!
//! [`trace_rays`] and [`score`] are the two halves of [`compare`] for callers that trace the
//! reference once and score several intersectors against it per ray (the difference images
//! of `isoscope accuracy`).

use std::time::Instant;

use glam::Vec3;

use crate::grid::{AnyGridScene, GridScene};
use crate::intersect::{CellHit, Intersector, IsoSet};
use crate::kdtree::KdTreeConfig;
use crate::math::Ray;
use crate::math::rng::Rng;
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

/// `|Δt|` (cells) above which two first hits are different crossings, not one crossing
/// placed differently.
pub const FAR_HIT_CELLS: f64 = 0.5;

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
    /// Rays where both hit but more than [`FAR_HIT_CELLS`] apart: the method found a
    /// different crossing (it missed the reference's first hit, or hit before it).
    pub far_hits: u64,
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
    let got = trace_rays(scene, rays, isovalues, intersector);
    let truth = trace_rays(scene, rays, isovalues, Intersector::Reference);
    score(&got, &truth).0
}

/// Builds the scene for a [`Case`] and scores `intersector` on it.
pub fn compare_case(case: &Case, intersector: Intersector) -> AccuracyReport {
    let scene = AnyGridScene::new(&case.volume, intersector);
    compare(&scene, &case.rays, &case.isovalues, intersector)
}

/// The first hit of one ray: `t` in cell units (traversal units times the ray's speed
/// there, so `|Δt|` of two hits is in cells) and the surface index.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct RayHit {
    pub t_cells: f64,
    pub surface: u32,
}

/// First hits of a set of rays with one intersector, and the time the tracing took.
#[derive(Debug, Clone, PartialEq)]
pub struct Traced {
    pub intersector: Intersector,
    /// One entry per ray, `None` where the ray hits nothing.
    pub hits: Vec<Option<RayHit>>,
    /// Single-threaded wall time of the traversal (kd-tree, one ray at a time).
    pub seconds: f64,
}

/// How one ray compares with the reference.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub enum RayOutcome {
    /// Neither hits.
    NoHit,
    /// Both hit; `|Δt|` in cell units and whether the surfaces agree.
    Both {
        abs_dt_cells: f64,
        same_surface: bool,
    },
    /// The reference hits, the method does not.
    Missed,
    /// The method hits, the reference does not.
    False,
}

/// Traces `rays` through the kd-tree of `scene` with `intersector` (one ray at a time, on
/// the calling thread, whatever intersector the scene was built with).
pub fn trace_rays(
    scene: &AnyGridScene,
    rays: &[Ray],
    isovalues: &[f32],
    intersector: Intersector,
) -> Traced {
    crate::dispatch_grid_scene!(scene, s => trace_typed(s, rays, isovalues, intersector))
}

fn trace_typed<T: Voxel>(
    scene: &GridScene<T>,
    rays: &[Ray],
    isovalues: &[f32],
    intersector: Intersector,
) -> Traced {
    // Physical isovalues, as the scene's own frames take them.
    let isos = IsoSet::<T>::mapped(isovalues, scene.value_map());
    let start = Instant::now();
    let hits = trace(scene, rays, &isos, intersector);
    let seconds = start.elapsed().as_secs_f64();
    let hits = hits
        .into_iter()
        .map(|h| {
            h.map(|(h, speed)| RayHit {
                t_cells: f64::from(h.t) * f64::from(speed),
                surface: h.surface,
            })
        })
        .collect();
    Traced {
        intersector,
        hits,
        seconds,
    }
}

/// Scores `got` against `truth` (the same rays traced with the reference): the report and
/// the outcome of every ray.
///
/// # Panics
/// If the two traces have different ray counts.
pub fn score(got: &Traced, truth: &Traced) -> (AccuracyReport, Vec<RayOutcome>) {
    assert_eq!(got.hits.len(), truth.hits.len(), "traces of different rays");
    let mut r = AccuracyReport {
        intersector: got.intersector,
        rays: got.hits.len() as u64,
        reference_hits: 0,
        missed: 0,
        false_hits: 0,
        mean_abs_dt_cells: 0.0,
        max_abs_dt_cells: 0.0,
        wrong_surface: 0,
        far_hits: 0,
        seconds: got.seconds,
    };
    let mut both = 0u64;
    let mut sum = 0.0f64;
    let outcomes = got
        .hits
        .iter()
        .zip(&truth.hits)
        .map(|(g, t)| match (g, t) {
            (Some(g), Some(t)) => {
                r.reference_hits += 1;
                both += 1;
                let dt = (g.t_cells - t.t_cells).abs();
                sum += dt;
                r.max_abs_dt_cells = r.max_abs_dt_cells.max(dt);
                if dt > FAR_HIT_CELLS {
                    r.far_hits += 1;
                }
                let same_surface = g.surface == t.surface;
                if !same_surface {
                    r.wrong_surface += 1;
                }
                RayOutcome::Both {
                    abs_dt_cells: dt,
                    same_surface,
                }
            }
            (None, Some(_)) => {
                r.reference_hits += 1;
                r.missed += 1;
                RayOutcome::Missed
            }
            (Some(_), None) => {
                r.false_hits += 1;
                RayOutcome::False
            }
            (None, None) => RayOutcome::NoHit,
        })
        .collect();
    if both > 0 {
        r.mean_abs_dt_cells = sum / both as f64;
    }
    (r, outcomes)
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
fn rays_from_outside(rng: &mut Rng, lo: Vec3, hi: Vec3, n: usize) -> Vec<Ray> {
    let c = (lo + hi) * 0.5;
    let ext = (hi - lo).max(Vec3::ONE);
    (0..n)
        .map(|_| {
            let dir = rng.vec3(-1.0, 1.0).normalize_or(Vec3::X);
            let target = c + rng.vec3(-0.45, 0.45) * ext;
            Ray::new(target - dir * ext.length() * 1.5, dir)
        })
        .collect()
}

/// The extreme suite (see the module docs).
pub fn extreme_suite() -> Vec<Case> {
    let mut rng = Rng::new(0x1505_c0de);
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
                let dir = rng.vec3(-1.0, 1.0).normalize_or(Vec3::X);
                let side = dir.any_orthonormal_vector();
                let side =
                    (glam::Quat::from_axis_angle(dir, rng.range_f32(0.0, std::f32::consts::TAU))
                        * side)
                        .normalize();
                let off = r + rng.range_f32(-0.3, 0.3);
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
                let mut o = lo + rng.vec3(0.0, 1.0) * (hi - lo);
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
                let mut o = lo + rng.vec3(0.0, 1.0) * (hi - lo);
                let mut d = rng.vec3(-1.0, 1.0);
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
                let z = rng.range_f32(0.0, 3.0);
                let d = Vec3::new(1.0, 1.0, 0.0).normalize();
                let o = Vec3::new(m - 2.0, -2.0, z);
                if rng.unit_f32() < 0.5 {
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
        let mut r2 = Rng::new(99);
        let vol = volume([16, 14, 12], [0.0; 3], [1.0; 3], |i, j, k| {
            let u = r2.unit_f32();
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
                let o = lo + rng.vec3(0.1, 0.9) * (hi - lo);
                Ray::new(o, rng.vec3(-1.0, 1.0).normalize_or(Vec3::Z))
            })
            .collect();
        cases.push(Case {
            name: "camera inside the volume".into(),
            volume: smooth_vol,
            isovalues: vec![0.1, 0.7],
            rays,
        });
    }
    more_cases(&mut cases);
    cases
}

/// Variants the cases above leave open (each with its own seed, so the cases above keep
/// their rays).
fn more_cases(cases: &mut Vec<Case>) {
    let smooth_vol = volume([16, 14, 12], [0.0; 3], [1.0; 3], smooth);
    let (lo, hi) = bounds(&smooth_vol);

    // f32 tangent cells: v = (−1)^(i+j), iso 0. Rays x = y + m + δ touch the saddles
    // (δ = 0: double root) or cross the surface twice δ apart (two roots δ cells apart).
    {
        let mut rng = Rng::new(0x7a_9e47);
        let vol = volume([9, 9, 4], [0.0; 3], [1.0; 3], |i, j, _| {
            if (i + j) % 2 == 0 { 1.0f32 } else { -1.0 }
        });
        let deltas = [0.0f32, 1e-2, -1e-2, 1e-3, -1e-3];
        let rays = (0..250)
            .map(|n| {
                let m = rng.index(7) as f32 - 3.0 + deltas[n % deltas.len()];
                let z = rng.range_f32(0.0, 3.0);
                let d = Vec3::new(1.0, 1.0, 0.0).normalize();
                let o = Vec3::new(m - 2.0, -2.0, z);
                if rng.unit_f32() < 0.5 {
                    Ray::new(o, d)
                } else {
                    Ray::new(o + d * 30.0, -d)
                }
            })
            .collect();
        cases.push(Case {
            name: "f32 tangent cells, near-tangent rays (roots 1e-2, 1e-3 apart)".into(),
            volume: vol,
            isovalues: vec![0.0],
            rays,
        });
    }

    // i16 data at integer isovalues: a plane and a block equal to the isovalue; rays along
    // grid lines (which then run inside the surface) and rays aimed at sample positions.
    {
        let mut rng = Rng::new(0x116_1e55);
        let dims = [13usize, 11, 9];
        let vol = volume(dims, [0.0; 3], [1.0; 3], |i, j, k| {
            if k == 4 || (i >= 8 && j >= 6) {
                -2i16
            } else {
                ((i * 5 + j * 3 + k * 7) % 11) as i16 - 5
            }
        });
        let (lo, hi) = bounds(&vol);
        let rays = (0..400)
            .map(|n| {
                let a = n % 3;
                let grid_point = Vec3::new(
                    rng.index(dims[0]) as f32,
                    rng.index(dims[1]) as f32,
                    rng.index(dims[2]) as f32,
                );
                if n % 2 == 0 {
                    // Along a grid line parallel to axis a.
                    let sign = if rng.unit_f32() < 0.5 { 1.0 } else { -1.0 };
                    let mut o = grid_point;
                    o[a] = if sign > 0.0 { lo[a] - 2.0 } else { hi[a] + 2.0 };
                    let mut d = Vec3::ZERO;
                    d[a] = sign;
                    Ray::new(o, d)
                } else {
                    // Through a sample position, exactly: small integer directions (not
                    // normalized) keep every coordinate and slab distance exact in f32.
                    // (Random unit directions pass the sample ~1e-7 cell away, where a touch
                    // of an iso-valued sample is decided by rounding, not by the method.)
                    let mut d = Vec3::ZERO;
                    while d.abs().cmpgt(Vec3::ZERO).bitmask().count_ones() < 2 {
                        d = Vec3::new(
                            rng.index(5) as f32 - 2.0,
                            rng.index(5) as f32 - 2.0,
                            rng.index(5) as f32 - 2.0,
                        );
                    }
                    Ray::new(grid_point - d * 16.0, d)
                }
            })
            .collect();
        cases.push(Case {
            name: "i16 integer isovalues, rays along grid lines and through samples".into(),
            volume: vol,
            isovalues: vec![-2.0, 3.0],
            rays,
        });
    }

    // Camera on sample positions, some inside a constant block equal to the isovalue.
    {
        let mut rng = Rng::new(0xca_3e7a);
        let dims = [14usize, 12, 10];
        let vol = volume(dims, [0.0; 3], [1.0; 3], |i, j, k| {
            if i < 5 && j < 5 {
                4u8
            } else {
                ((i * 7 + j * 3 + k * 5) % 9) as u8
            }
        });
        let rays = (0..400)
            .map(|n| {
                let o = Vec3::new(
                    rng.index(dims[0]) as f32,
                    rng.index(dims[1]) as f32,
                    rng.index(dims[2]) as f32,
                );
                let d = if n % 4 == 0 {
                    let mut d = Vec3::ZERO;
                    d[n / 4 % 3] = if n % 8 == 0 { 1.0 } else { -1.0 };
                    d
                } else {
                    rng.vec3(-1.0, 1.0).normalize_or(Vec3::Y)
                };
                Ray::new(o, d)
            })
            .collect();
        cases.push(Case {
            name: "camera on sample positions and inside iso-valued cells".into(),
            volume: vol,
            isovalues: vec![4.0, 6.5],
            rays,
        });
    }

    // Rays in the volume's outer faces and along its outer edges.
    {
        let mut rng = Rng::new(0xb0_0a7d);
        let rays = (0..300)
            .map(|n| {
                let a = n % 3;
                let mut o = lo + rng.vec3(0.0, 1.0) * (hi - lo);
                let mut d = rng.vec3(-1.0, 1.0);
                o[a] = if rng.unit_f32() < 0.5 { lo[a] } else { hi[a] };
                d[a] = 0.0;
                if n % 2 == 0 {
                    let b = (a + 1) % 3;
                    o[b] = if rng.unit_f32() < 0.5 { lo[b] } else { hi[b] };
                    d[b] = 0.0;
                }
                let d = d.normalize_or(Vec3::X);
                Ray::new(o - d * (hi - lo).length(), d)
            })
            .collect();
        cases.push(Case {
            name: "rays in the volume's outer faces and edges".into(),
            volume: smooth_vol.clone(),
            isovalues: vec![0.1, -0.4],
            rays,
        });
    }

    // Values around 1e30 (1e30 ± 1.5e28): differences far below the values themselves.
    {
        let mut rng = Rng::new(0x1e30);
        let vol = volume([16, 14, 12], [0.0; 3], [1.0; 3], |i, j, k| {
            1e30f32 + smooth(i, j, k) * 1e28
        });
        let rays = rays_from_outside(&mut rng, lo, hi, 300);
        cases.push(Case {
            name: "values around 1e30 (1e30 ± 1.5e28)".into(),
            volume: vol,
            isovalues: vec![1.001e30],
            rays,
        });
    }

    // Thin volumes along the other axes; 1×1×N has no cells at all.
    let mut rng = Rng::new(0x7e1_a0e5);
    for dims in [[12, 1, 12], [12, 12, 1], [15, 13, 2], [1, 1, 9]] {
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
}

/// Inputs at the limit of `f32`, reported separately in docs/accuracy.md, because the
/// answer is decided below the resolution of the `f32` methods (the exact method hands them
/// to its `f64` path):
/// - near-miss rays: corners ±1, rays along cell diagonals through the saddles, isovalue
///   1e-5…1e-7 below the saddle value. Along even diagonals the field stays that far above
///   the isovalue (a near miss the reference resolves), along odd diagonals it crosses
///   twice, 2·sqrt(gap) apart;
/// - rays with random unit directions aimed at iso-valued samples of integer data: they
///   pass the sample ~1e-7 cell away, where a touch is decided by the rounding of the
///   cell-local entry point (`f32` in the fast methods, `f64` in the reference).
pub fn limit_cases() -> Vec<Case> {
    let mut cases = Vec::new();
    {
        let mut rng = Rng::new(0x11_3175);
        let vol = volume([9, 9, 4], [0.0; 3], [1.0; 3], |i, j, _| {
            if (i + j) % 2 == 0 { 1.0f32 } else { -1.0 }
        });
        for gap in [1e-5f32, 1e-6, 1e-7] {
            let rays = (0..200)
                .map(|_| {
                    let m = rng.index(7) as f32 - 3.0;
                    let z = rng.range_f32(0.0, 3.0);
                    let d = Vec3::new(1.0, 1.0, 0.0).normalize();
                    Ray::new(Vec3::new(m - 2.0, -2.0, z), d)
                })
                .collect();
            cases.push(Case {
                name: format!("near-miss and near-double-root rays, gap {gap:.0e}"),
                volume: vol.clone(),
                isovalues: vec![-gap],
                rays,
            });
        }
    }
    {
        let mut rng = Rng::new(0x116_1e55);
        let dims = [13usize, 11, 9];
        let vol = volume(dims, [0.0; 3], [1.0; 3], |i, j, k| {
            if k == 4 || (i >= 8 && j >= 6) {
                -2i16
            } else {
                ((i * 5 + j * 3 + k * 7) % 11) as i16 - 5
            }
        });
        let (lo, hi) = bounds(&vol);
        let rays = (0..400)
            .map(|_| {
                let p = Vec3::new(
                    rng.index(dims[0]) as f32,
                    rng.index(dims[1]) as f32,
                    rng.index(dims[2]) as f32,
                );
                let d = rng.vec3(-1.0, 1.0).normalize_or(Vec3::X);
                Ray::new(p - d * (hi - lo).length(), d)
            })
            .collect();
        cases.push(Case {
            name: "i16, random unit rays aimed at (iso-valued) samples".into(),
            volume: vol,
            isovalues: vec![-2.0, 3.0],
            rays,
        });
    }
    cases
}

/// Scores every intersector on every case of `cases` (one kd-tree per case).
pub fn run_cases(
    cases: &[Case],
    intersectors: &[Intersector],
) -> Vec<(String, Vec<AccuracyReport>)> {
    cases
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

#[cfg(test)]
mod far_hit_probe {
    use super::*;
    use crate::render::{Camera, IsoScene, RayGen};

    /// Marschner–Lobb as data-samples generates it on [-1, 1]³ (`f32` stores ρ, `u8`
    /// `round(255·ρ)`), as a kd-tree scene.
    fn ml<T: Voxel>(n: usize, store: impl Fn(f64) -> T) -> GridScene<T> {
        use std::f64::consts::PI;
        let h = 2.0 / (n - 1) as f64;
        let grid = Grid::uniform([n; 3], [-1.0; 3], [h; 3]).unwrap();
        let mut v = Vec::with_capacity(n * n * n);
        for k in 0..n {
            for j in 0..n {
                for i in 0..n {
                    let (x, y, z) = (
                        -1.0 + i as f64 * h,
                        -1.0 + j as f64 * h,
                        -1.0 + k as f64 * h,
                    );
                    let r = x.hypot(y);
                    let rr = (2.0 * PI * 6.0 * (PI * r / 2.0).cos()).cos();
                    v.push(store(
                        (1.0 - (PI * z / 2.0).sin() + 0.25 * (1.0 + rr)) / 2.5,
                    ));
                }
            }
        }
        GridScene::new(
            &grid,
            crate::volume::VoxelBuffer::from_vec(v),
            Intersector::Exact,
            KdTreeConfig::default(),
        )
        .unwrap()
    }

    /// The primary rays of `isoscope accuracy`'s orbit camera (30°, 20°, 40° field of view)
    /// at `size²`, pixels `(i, j)`.
    fn orbit_rays<T: Voxel>(
        scene: &GridScene<T>,
        size: u32,
        pixels: impl Iterator<Item = (u32, u32)>,
    ) -> Vec<Ray> {
        let cam = Camera::orbit(&scene.world_bounds(), 30.0, 20.0, 40.0);
        let rg = RayGen::new(&cam, size, size);
        pixels
            .map(|(i, j)| rg.ray_at(i as f32 + 0.5, j as f32 + 0.5))
            .collect()
    }

    fn every_pixel(size: u32) -> impl Iterator<Item = (u32, u32)> {
        (0..size).flat_map(move |j| (0..size).map(move |i| (i, j)))
    }

    /// Rays whose exact hit is more than [`FAR_HIT_CELLS`] from the reference's, or
    /// missing, or false.
    fn exact_disagreements<T: Voxel>(scene: &GridScene<T>, iso: f32, rays: &[Ray]) -> Vec<usize> {
        let isos = IsoSet::<T>::new(&[iso]);
        let truth = trace(scene, rays, &isos, Intersector::Reference);
        let got = trace(scene, rays, &isos, Intersector::Exact);
        (0..rays.len())
            .filter(|&i| match (got[i], truth[i]) {
                (Some((g, sp)), Some((t, _))) => {
                    f64::from((g.t - t.t).abs()) * f64::from(sp) > FAR_HIT_CELLS
                }
                (None, None) => false,
                _ => true,
            })
            .collect()
    }

    /// The two rays of an earlier ML 256³ f32 report at 256²: crossings within ~4e-5 cells
    /// of a cell face, seen from ~700 cells away, lost between the two cells sharing the
    /// face (see `CellSegment::local_f32`).
    #[test]
    fn ml256_crossings_at_cell_faces_are_found() {
        let s = ml(256, |x| x as f32);
        let rays = orbit_rays(&s, 256, [(147, 112), (157, 114)].into_iter());
        assert_eq!(exact_disagreements(&s, 0.5, &rays), Vec::<usize>::new());
    }

    /// The far hits of the first full-resolution scoring: ML 256³ f32 pixel (515, 574) at
    /// 1024², where the reference extrapolated a cell 3e-5 cells beyond its face and
    /// found a crossing the field does not have; ML 128³ u8 pixel (465, 550), where exact's
    /// touching band turned a miss by 7e-6 of the cell's range into a hit 7 cells early.
    #[test]
    fn first_full_resolution_far_hits_are_gone() {
        let s = ml(256, |x| x as f32);
        let rays = orbit_rays(&s, 1024, [(515, 574)].into_iter());
        assert_eq!(exact_disagreements(&s, 0.5, &rays), Vec::<usize>::new());
        let s = ml(128, |x| (255.0 * x).round() as u8);
        let rays = orbit_rays(&s, 1024, [(465, 550)].into_iter());
        assert_eq!(exact_disagreements(&s, 127.5, &rays), Vec::<usize>::new());
    }

    /// The first hits of every pixel of a `size²` frame as the renderer finds them (16×16
    /// tiles in Morton order, traced as packets of up to 16 rays in 8-wide lanes through the
    /// kd-tree, each ray cut to the volume's bounds first), from the frame's depth buffer:
    /// the path a picture takes, which [`trace`] (one ray at a time from `t = 0`, what
    /// [`compare`] and `isoscope bench` score) does not run.
    fn rendered<T: Voxel>(scene: &GridScene<T>, iso: f32, size: u32, rays: &[Ray]) -> Traced {
        use crate::render::{RenderSettings, Surface, render};
        let mut s = scene.clone();
        s.set_intersector(Intersector::Exact);
        let cam = Camera::orbit(&s.world_bounds(), 30.0, 20.0, 40.0);
        let settings = RenderSettings {
            width: size,
            height: size,
            surfaces: vec![Surface::new(iso, [1.0; 3])],
            ..RenderSettings::default()
        };
        let frame = render(
            &s,
            &cam,
            &settings,
            &std::sync::atomic::AtomicBool::new(false),
        )
        .expect("not cancelled");
        assert_eq!(frame.depth.len(), rays.len());
        let hits = rays
            .iter()
            .zip(&frame.depth)
            .map(|(r, &d)| {
                // Depth is the hit's `t` in the ray's units (row-major, as `every_pixel`);
                // cells as `trace_typed` converts it.
                let speed = s.frame().local_dir(r.dir).length();
                d.is_finite().then(|| RayHit {
                    t_cells: f64::from(d) * f64::from(speed),
                    surface: 0,
                })
            })
            .collect();
        Traced {
            intersector: Intersector::Exact,
            hits,
            seconds: 0.0,
        }
    }

    /// Scores exact (Listing 7.1 made exact, seed 004 §7.2.2) on every pixel of a `size²`
    /// frame against the `f64` reference (one ray at a time through the kd-tree): the
    /// single-ray traversal and the renderer's packets must both have no missed, false or
    /// far hits ([`FAR_HIT_CELLS`], as [`score`] counts them).
    fn assert_exact_on_every_pixel<T: Voxel>(scene: &GridScene<T>, iso: f32, size: u32) {
        let rays = orbit_rays(scene, size, every_pixel(size));
        let truth = trace_typed(scene, &rays, &[iso], Intersector::Reference);
        let single = trace_typed(scene, &rays, &[iso], Intersector::Exact);
        let packets = rendered(scene, iso, size, &rays);
        let mut failures = Vec::new();
        for (path, got) in [("single ray", single), ("rendered packets", packets)] {
            let (r, outcomes) = score(&got, &truth);
            assert!(r.reference_hits > 0, "{path}: no surface in the frame");
            if (r.missed, r.false_hits, r.far_hits) == (0, 0, 0) {
                continue;
            }
            let pixels: Vec<(usize, usize)> = outcomes
                .iter()
                .enumerate()
                .filter(|(_, o)| match o {
                    RayOutcome::Both { abs_dt_cells, .. } => *abs_dt_cells > FAR_HIT_CELLS,
                    RayOutcome::Missed | RayOutcome::False => true,
                    RayOutcome::NoHit => false,
                })
                .map(|(k, _)| (k % size as usize, k / size as usize))
                .take(10)
                .collect();
            failures.push(format!(
                "{path}: {} missed, {} false, {} far, max |dt| {} cells, pixels {pixels:?}",
                r.missed, r.false_hits, r.far_hits, r.max_abs_dt_cells
            ));
        }
        assert!(
            failures.is_empty(),
            "{} iso {iso} at {size}²: {failures:#?}",
            T::TYPE.name()
        );
    }

    /// Every pixel at 1024² on ML 128³ u8 (the stored isovalue 127.5, and 0.5 where the
    /// surface runs along cells with corners 0 and 1): exact agrees with the reference.
    #[test]
    fn ml128_u8_exact_is_exact_on_every_pixel_at_1024() {
        let s = ml(128, |x| (255.0 * x).round() as u8);
        assert_exact_on_every_pixel(&s, 127.5, 1024);
        assert_exact_on_every_pixel(&s, 0.5, 1024);
    }

    /// Every pixel at 1024² on ML 256³ f32 at the classic isovalue 0.5 (the far hits of
    /// 12.8 cells of the first full-resolution scoring were on this frame).
    #[test]
    fn ml256_f32_exact_is_exact_on_every_pixel_at_1024() {
        let s = ml(256, |x| x as f32);
        assert_exact_on_every_pixel(&s, 0.5, 1024);
    }
}
