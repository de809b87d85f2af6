//! Tetrahedral meshes for the unstructured renderer (thesis seed 004 ch. 8): a ball, a
//! spherical shell and a torus, made by splitting the cells of a structured grid into tets.
//!
//! The grid has `n` cells per axis on `[−1, 1]³`; a cell is kept when its centre lies inside
//! the shape. Each kept hexahedron is split into 6 tets by [`volume_core::tet::split_hex`]
//! (the same split the readers use): every quad face is cut by the diagonal through its
//! smallest global point index, so neighbouring cells agree and the mesh is crack-free
//! (tested: every interior triangle is shared by exactly two tets). Points not used by any
//! kept cell are dropped; point indices follow the grid order.
//!
//! Fields (one value per point, `f32`):
//! - `distance`: [`distance`] — from [`CENTRE`] for the ball and shell, to the core circle
//!   for the torus; its isosurfaces are spheres and tori.
//! - `gaussians`: [`gaussians`], a sum of three Gaussians ([`GAUSSIANS`]).
//! - `moving_gaussian`: step 0 of [`moving_gaussian`], one Gaussian circling the z axis over
//!   [`MOVING_STEPS`] steps; [`moving_gaussian_steps`] gives every step's values (the
//!   topology and points stay fixed: only scalars change, so a renderer refits value ranges).
//!
//! Size: [`cells_for_tets`] picks `n` for a target tet count (the benchmarks use 100 k–1 M:
//! `n ≈ 35` gives about 100 k tets for the ball, `n ≈ 76` about 1 M).

use rayon::prelude::*;
use volume_core::tet::{PointField, TetMesh, split_hex};

use crate::GenerateError;

/// Centre of the ball and the shell, slightly off the grid's symmetry planes.
pub const CENTRE: [f64; 3] = [0.013, -0.021, 0.008];
/// Radius of the ball and outer radius of the shell.
pub const BALL_RADIUS: f64 = 0.9;
/// Inner radius of the shell.
pub const SHELL_INNER_RADIUS: f64 = 0.5;
/// Torus: core circle radius (in the plane z = 0, centred on the z axis) and tube radius.
pub const TORUS_MAJOR_RADIUS: f64 = 0.6;
pub const TORUS_MINOR_RADIUS: f64 = 0.3;
/// Steps of the moving Gaussian series.
pub const MOVING_STEPS: usize = 10;
/// `(centre, amplitude, sigma)` of the three Gaussians of the `gaussians` field.
pub const GAUSSIANS: [([f64; 3], f64, f64); 3] = [
    ([0.4, 0.1, 0.0], 1.0, 0.25),
    ([-0.3, 0.35, 0.2], 0.8, 0.2),
    ([0.0, -0.45, -0.3], 0.6, 0.3),
];
/// Sigma of the moving Gaussian.
pub const MOVING_SIGMA: f64 = 0.25;

/// The three shapes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum TetShape {
    Ball,
    Shell,
    Torus,
}

impl TetShape {
    pub const ALL: [TetShape; 3] = [TetShape::Ball, TetShape::Shell, TetShape::Torus];

    /// Command-line name (`isoscope generate tet-ball`, ...).
    pub const fn name(self) -> &'static str {
        match self {
            TetShape::Ball => "tet-ball",
            TetShape::Shell => "tet-shell",
            TetShape::Torus => "tet-torus",
        }
    }

    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|s| s.name() == name)
    }

    /// One line for `--help`.
    pub const fn description(self) -> &'static str {
        match self {
            TetShape::Ball => {
                "tet mesh of a ball (radius 0.9): fields distance, gaussians, moving_gaussian"
            }
            TetShape::Shell => {
                "tet mesh of a shell (radii 0.5..0.9): fields distance, gaussians, moving_gaussian"
            }
            TetShape::Torus => {
                "tet mesh of a torus (R 0.6, r 0.3): fields distance, gaussians, moving_gaussian"
            }
        }
    }

    /// Whether `p` is inside the shape.
    pub fn contains(self, p: [f64; 3]) -> bool {
        let d = distance(self, p);
        match self {
            TetShape::Ball => d <= BALL_RADIUS,
            TetShape::Shell => (SHELL_INNER_RADIUS..=BALL_RADIUS).contains(&d),
            TetShape::Torus => d <= TORUS_MINOR_RADIUS,
        }
    }

    /// Volume of the shape (for sizing).
    pub fn volume(self) -> f64 {
        use std::f64::consts::PI;
        match self {
            TetShape::Ball => 4.0 / 3.0 * PI * BALL_RADIUS.powi(3),
            TetShape::Shell => 4.0 / 3.0 * PI * (BALL_RADIUS.powi(3) - SHELL_INNER_RADIUS.powi(3)),
            TetShape::Torus => 2.0 * PI * PI * TORUS_MAJOR_RADIUS * TORUS_MINOR_RADIUS.powi(2),
        }
    }
}

impl std::fmt::Display for TetShape {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// The `distance` field: from [`CENTRE`] (ball, shell), or to the torus core circle.
pub fn distance(shape: TetShape, p: [f64; 3]) -> f64 {
    match shape {
        TetShape::Ball | TetShape::Shell => {
            let d = [p[0] - CENTRE[0], p[1] - CENTRE[1], p[2] - CENTRE[2]];
            (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt()
        }
        TetShape::Torus => {
            let rho = p[0].hypot(p[1]) - TORUS_MAJOR_RADIUS;
            rho.hypot(p[2])
        }
    }
}

fn gauss(p: [f64; 3], c: [f64; 3], sigma: f64) -> f64 {
    let r2 = (p[0] - c[0]).powi(2) + (p[1] - c[1]).powi(2) + (p[2] - c[2]).powi(2);
    (-r2 / (2.0 * sigma * sigma)).exp()
}

/// The `gaussians` field: `Σ a·exp(−|p − c|² / 2σ²)` over [`GAUSSIANS`].
pub fn gaussians(p: [f64; 3]) -> f64 {
    GAUSSIANS.iter().map(|&(c, a, s)| a * gauss(p, c, s)).sum()
}

/// Centre of the moving Gaussian at `step` of `steps`: once around a circle of radius 0.6
/// in the plane z = 0, rising from z = −0.2 to 0.2.
pub fn moving_centre(step: usize, steps: usize) -> [f64; 3] {
    let t = step as f64 / steps.max(1) as f64;
    let a = 2.0 * std::f64::consts::PI * t;
    [0.6 * a.cos(), 0.6 * a.sin(), -0.2 + 0.4 * t]
}

/// The moving Gaussian (amplitude 1, sigma [`MOVING_SIGMA`]) at `step` of `steps`.
pub fn moving_gaussian(p: [f64; 3], step: usize, steps: usize) -> f64 {
    gauss(p, moving_centre(step, steps), MOVING_SIGMA)
}

/// Grid cells per axis giving about `target_tets` tets for `shape` (at least 2).
pub fn cells_for_tets(shape: TetShape, target_tets: usize) -> usize {
    // Kept cells ≈ n³ · volume / 8; 6 tets per cell.
    let n = (target_tets as f64 * 8.0 / (6.0 * shape.volume())).cbrt();
    (n.round() as usize).max(2)
}

fn grid_coord(i: usize, n: usize) -> f64 {
    -1.0 + 2.0 * i as f64 / n as f64
}

/// Builds the mesh of `shape` on a grid of `n` cells per axis (see the module docs).
pub fn tet_mesh(shape: TetShape, n: usize) -> Result<TetMesh, GenerateError> {
    if n < 2 {
        return Err(GenerateError::DimsTooSmall { dims: [n; 3] });
    }
    let np = n + 1;
    let gid = |i: usize, j: usize, k: usize| i + np * (j + np * k);
    // Kept cells, in grid order.
    let kept: Vec<[usize; 3]> = (0..n)
        .into_par_iter()
        .flat_map_iter(|k| {
            (0..n)
                .flat_map(move |j| (0..n).map(move |i| [i, j, k]))
                .filter(move |&[i, j, k]| {
                    let c = |a: usize| grid_coord(a, n) + 1.0 / n as f64;
                    shape.contains([c(i), c(j), c(k)])
                })
        })
        .collect();
    // Compact point numbering (monotone in the grid index).
    let total = np * np * np;
    let mut remap = vec![u32::MAX; total];
    for &[i, j, k] in &kept {
        for (di, dj, dk) in CORNERS {
            remap[gid(i + di, j + dj, k + dk)] = 0;
        }
    }
    let mut points = Vec::new();
    let mut next = 0u32;
    for (g, slot) in remap.iter_mut().enumerate() {
        if *slot == 0 {
            *slot = next;
            next += 1;
            let (i, j, k) = (g % np, (g / np) % np, g / (np * np));
            points.push([grid_coord(i, n), grid_coord(j, n), grid_coord(k, n)]);
        }
    }
    let mut tets = Vec::with_capacity(kept.len() * 6);
    for &[i, j, k] in &kept {
        let v = CORNERS.map(|(di, dj, dk)| remap[gid(i + di, j + dj, k + dk)]);
        tets.extend(split_hex(v));
    }
    let field = |name: &str, f: &(dyn Fn([f64; 3]) -> f64 + Sync)| {
        PointField::new(name, points.par_iter().map(|&p| f(p) as f32).collect())
    };
    let fields = vec![
        field("distance", &|p| distance(shape, p)),
        field("gaussians", &gaussians),
        field("moving_gaussian", &|p| moving_gaussian(p, 0, MOVING_STEPS)),
    ];
    let points32 = volume_core::tet::points_from_f64(&points);
    Ok(TetMesh::new(points32, tets, fields)?)
}

/// VTK hexahedron corner order: `0..4` the bottom quad (counter-clockwise), `4..8` above.
const CORNERS: [(usize, usize, usize); 8] = [
    (0, 0, 0),
    (1, 0, 0),
    (1, 1, 0),
    (0, 1, 0),
    (0, 0, 1),
    (1, 0, 1),
    (1, 1, 1),
    (0, 1, 1),
];

/// The moving Gaussian's values at every point of `mesh` for each of `steps` steps (the
/// mesh's own `moving_gaussian` field is step 0).
pub fn moving_gaussian_steps(mesh: &TetMesh, steps: usize) -> Vec<Vec<f32>> {
    (0..steps)
        .map(|s| {
            mesh.points
                .par_iter()
                .map(|p| moving_gaussian(p.map(f64::from), s, steps) as f32)
                .collect()
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::HashMap;

    fn volume6(p: &[[f32; 3]], t: [u32; 4]) -> f64 {
        let q = |i: usize| p[t[i] as usize].map(f64::from);
        let (a, b, c, d) = (q(0), q(1), q(2), q(3));
        let u = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
        let v = [c[0] - a[0], c[1] - a[1], c[2] - a[2]];
        let w = [d[0] - a[0], d[1] - a[1], d[2] - a[2]];
        u[0] * (v[1] * w[2] - v[2] * w[1]) - u[1] * (v[0] * w[2] - v[2] * w[0])
            + u[2] * (v[0] * w[1] - v[1] * w[0])
    }

    /// Crack-free: each triangle is shared by at most two tets, and a triangle of only one
    /// tet lies on a grid face whose other cell is not kept (the shape's boundary).
    #[test]
    fn meshes_are_conforming_and_fill_their_cells() {
        for shape in TetShape::ALL {
            let n = 12;
            let m = tet_mesh(shape, n).unwrap();
            let h = 2.0 / n as f64;
            assert_eq!(m.tets.len() % 6, 0);
            let cells = m.tets.len() / 6;
            // Exact total volume: kept cells times the cell volume, no overlap.
            let vol: f64 = m
                .tets
                .iter()
                .map(|&t| volume6(&m.points, t).abs() / 6.0)
                .sum();
            // (Points are f32: relative tolerance.)
            let want = cells as f64 * h * h * h;
            assert!((vol - want).abs() < 1e-6 * want, "{shape}: {vol} vs {want}");
            assert!(
                m.tets.iter().all(|&t| volume6(&m.points, t).abs() > 1e-12),
                "{shape}: flat tet"
            );
            let mut faces: HashMap<[u32; 3], usize> = HashMap::new();
            for t in &m.tets {
                for skip in 0..4 {
                    let mut f = [0u32; 3];
                    let mut k = 0;
                    for (i, &v) in t.iter().enumerate() {
                        if i != skip {
                            f[k] = v;
                            k += 1;
                        }
                    }
                    f.sort_unstable();
                    *faces.entry(f).or_default() += 1;
                }
            }
            let inside = |c: [f64; 3]| shape.contains(c);
            for (f, &count) in &faces {
                assert!(count <= 2, "{shape}: face {f:?} in {count} tets");
                if count == 1 {
                    let p = f.map(|i| m.points[i as usize].map(f64::from));
                    // The boundary face lies in a grid plane: the axis where all three agree.
                    let axis = (0..3)
                        .find(|&a| p[0][a] == p[1][a] && p[1][a] == p[2][a])
                        .unwrap();
                    let centroid: [f64; 3] =
                        std::array::from_fn(|a| (p[0][a] + p[1][a] + p[2][a]) / 3.0);
                    let cell_centre = |side: f64| -> [f64; 3] {
                        std::array::from_fn(|a| {
                            if a == axis {
                                centroid[a] + side * h / 2.0
                            } else {
                                let idx = ((centroid[a] + 1.0) / h).floor();
                                -1.0 + (idx + 0.5) * h
                            }
                        })
                    };
                    let (lo, hi) = (cell_centre(-1.0), cell_centre(1.0));
                    let kept = |c: [f64; 3]| c.iter().all(|x| x.abs() < 1.0) && inside(c);
                    assert!(kept(lo) != kept(hi), "{shape}: crack at face {f:?} ({p:?})");
                }
            }
        }
    }

    #[test]
    fn fields_are_the_analytic_functions_at_the_points() {
        let m = tet_mesh(TetShape::Torus, 10).unwrap();
        let names = m.field_names();
        assert_eq!(names, vec!["distance", "gaussians", "moving_gaussian"]);
        for (i, p) in m.points.iter().enumerate() {
            let q = p.map(f64::from);
            let rho = (q[0] * q[0] + q[1] * q[1]).sqrt() - 0.6;
            let d = (rho * rho + q[2] * q[2]).sqrt();
            assert!((f64::from(m.fields[0].values[i]) - d).abs() < 1e-6);
            let g: f64 = GAUSSIANS
                .iter()
                .map(|(c, a, s)| {
                    let r2: f64 = (0..3).map(|k| (q[k] - c[k]).powi(2)).sum();
                    a * (-r2 / (2.0 * s * s)).exp()
                })
                .sum();
            assert!((f64::from(m.fields[1].values[i]) - g).abs() < 1e-6);
        }
        // Points of the torus mesh are near the torus (within a cell diagonal).
        let h = 0.2 * 3f64.sqrt();
        assert!(
            m.fields[0]
                .values
                .iter()
                .all(|&d| f64::from(d) <= TORUS_MINOR_RADIUS + h)
        );
    }

    #[test]
    fn moving_gaussian_moves_and_step_zero_is_the_field() {
        let m = tet_mesh(TetShape::Ball, 16).unwrap();
        let steps = moving_gaussian_steps(&m, MOVING_STEPS);
        assert_eq!(steps.len(), 10);
        assert_eq!(steps[0], m.require_field("moving_gaussian").unwrap().values);
        for (s, values) in steps.iter().enumerate() {
            // The maximum sits at the point nearest the moving centre.
            let c = moving_centre(s, MOVING_STEPS);
            let (imax, _) = values
                .iter()
                .enumerate()
                .fold((0, f32::MIN), |b, (i, &v)| if v > b.1 { (i, v) } else { b });
            let dist = |i: usize| {
                (0..3)
                    .map(|k| (f64::from(m.points[i][k]) - c[k]).powi(2))
                    .sum::<f64>()
            };
            let nearest = (0..m.points.len())
                .min_by(|&a, &b| dist(a).total_cmp(&dist(b)))
                .unwrap();
            assert!((dist(imax) - dist(nearest)).abs() < 1e-9, "step {s}");
        }
        assert_ne!(steps[0], steps[5]);
    }

    #[test]
    fn size_parameter_reaches_the_requested_range() {
        for shape in TetShape::ALL {
            let n = cells_for_tets(shape, 100_000);
            let m = tet_mesh(shape, n).unwrap();
            let t = m.tets.len() as f64;
            assert!(
                (0.85e5..1.15e5).contains(&t),
                "{shape}: n {n} gives {t} tets"
            );
        }
        assert!(
            cells_for_tets(TetShape::Ball, 1_000_000) > cells_for_tets(TetShape::Ball, 100_000)
        );
        assert!(matches!(
            tet_mesh(TetShape::Ball, 1),
            Err(GenerateError::DimsTooSmall { .. })
        ));
        for s in TetShape::ALL {
            assert_eq!(TetShape::from_name(s.name()), Some(s));
        }
    }
}
