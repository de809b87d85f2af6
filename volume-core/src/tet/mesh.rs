//! The tetrahedral mesh model and the consistent splitting of hexahedra, wedges and pyramids.
//!
//! Coordinates are stored as `f32` (the traversal works in `f32`, thesis 004 §8.4); readers
//! holding `f64` coordinates convert with [`points_from_f64`] (round to nearest). Point
//! indices are `u32` (at most `u32::MAX` points); tet counts are `usize`.
//!
//! ## Crack-free splitting of other cells
//!
//! [`split_hex`], [`split_wedge`] and [`split_pyramid`] use a *pulling* triangulation over the
//! global vertex order: the cell's vertex with the smallest global index `v` is coned to every
//! face that does not contain `v`, and each such quad face is split by its diagonal through
//! the face's own smallest global index. The faces that contain `v` end up split by a diagonal
//! through `v`, which is again their smallest index. So **every quad face is split by the
//! diagonal through its smallest global vertex index**, whichever cell it belongs to, and two
//! cells sharing a quad face always agree on it: no cracks (Dompierre et al. 1999 use the same
//! global rule). A hexahedron gives 6 tets, a wedge 3, a pyramid 2, always.
//!
//! Local vertex order is VTK's (also Gmsh's): hexahedron `0..4` one quad, `4..8` the opposite
//! quad with `i + 4` above `i`; wedge `0..3` one triangle, `3..6` the other with `i + 3` above
//! `i`; pyramid `0..4` the base quad, `4` the apex. Tet orientation follows the cell's
//! orientation; nothing in the renderer depends on it (inverted tets are handled).

use thiserror::Error;

use crate::math::Aabb;

/// Why a [`TetMesh`] (or a step of a time-varying one) was rejected.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum TetError {
    #[error("cell {cell}: point index {index} is out of range (the mesh has {points} points)")]
    IndexOutOfRange {
        cell: usize,
        index: u64,
        points: usize,
    },
    #[error("{points} points exceed the limit of u32::MAX point indices")]
    TooManyPoints { points: usize },
    #[error("point {point} has a non-finite coordinate {coords:?}")]
    NonFinitePoint { point: usize, coords: [f32; 3] },
    #[error("field \"{name}\" has {actual} values but the mesh has {expected} points")]
    FieldLength {
        name: String,
        expected: usize,
        actual: usize,
    },
    #[error("field name \"{name}\" occurs twice")]
    DuplicateField { name: String },
    #[error("no point field named \"{name}\" (available: {})", available.join(", "))]
    NoSuchField {
        name: String,
        available: Vec<String>,
    },
    #[error("{what}: got {actual} values for {expected} points")]
    StepLength {
        what: &'static str,
        expected: usize,
        actual: usize,
    },
    #[error("the mesh has no tetrahedra")]
    Empty,
}

/// A named scalar array with one value per mesh point (NaN allowed: it marks void data).
#[derive(Debug, Clone, PartialEq)]
pub struct PointField {
    pub name: String,
    pub values: Vec<f32>,
}

impl PointField {
    pub fn new(name: impl Into<String>, values: Vec<f32>) -> Self {
        Self {
            name: name.into(),
            values,
        }
    }

    /// `(min, max)` over the non-NaN values, or `None` if there are none.
    pub fn value_range(&self) -> Option<(f32, f32)> {
        let mut lo = f32::INFINITY;
        let mut hi = f32::NEG_INFINITY;
        for &v in &self.values {
            if !v.is_nan() {
                lo = lo.min(v);
                hi = hi.max(v);
            }
        }
        (lo <= hi).then_some((lo, hi))
    }
}

/// An unstructured mesh of tetrahedra with per-point scalar fields.
///
/// Build it with [`TetMesh::new`], which validates indices and field lengths. The fields are
/// public for cheap access; code that mutates them can re-check with [`TetMesh::validate`].
#[derive(Debug, Clone, PartialEq, Default)]
pub struct TetMesh {
    /// World-space point positions.
    pub points: Vec<[f32; 3]>,
    /// Four point indices per tetrahedron.
    pub tets: Vec<[u32; 4]>,
    /// Named per-point scalar arrays.
    pub fields: Vec<PointField>,
}

impl TetMesh {
    /// Validates and assembles a mesh. Degenerate tets (repeated indices, zero volume) are
    /// kept: they produce no isosurface (see [`crate::tet`]).
    pub fn new(
        points: Vec<[f32; 3]>,
        tets: Vec<[u32; 4]>,
        fields: Vec<PointField>,
    ) -> Result<Self, TetError> {
        let mesh = Self {
            points,
            tets,
            fields,
        };
        mesh.validate()?;
        Ok(mesh)
    }

    /// Checks every invariant [`TetMesh::new`] establishes: finite points, at most
    /// `u32::MAX` of them, tet indices in range (the error names the first bad cell), field
    /// lengths equal to the point count, unique field names.
    pub fn validate(&self) -> Result<(), TetError> {
        let n = self.points.len();
        if n > u32::MAX as usize {
            return Err(TetError::TooManyPoints { points: n });
        }
        if let Some((point, p)) = self
            .points
            .iter()
            .enumerate()
            .find(|(_, p)| !p.iter().all(|c| c.is_finite()))
        {
            return Err(TetError::NonFinitePoint { point, coords: *p });
        }
        for (cell, t) in self.tets.iter().enumerate() {
            if let Some(&index) = t.iter().find(|&&i| i as usize >= n) {
                return Err(TetError::IndexOutOfRange {
                    cell,
                    index: u64::from(index),
                    points: n,
                });
            }
        }
        for (i, f) in self.fields.iter().enumerate() {
            if f.values.len() != n {
                return Err(TetError::FieldLength {
                    name: f.name.clone(),
                    expected: n,
                    actual: f.values.len(),
                });
            }
            if self.fields[..i].iter().any(|g| g.name == f.name) {
                return Err(TetError::DuplicateField {
                    name: f.name.clone(),
                });
            }
        }
        Ok(())
    }

    pub fn num_points(&self) -> usize {
        self.points.len()
    }

    pub fn num_tets(&self) -> usize {
        self.tets.len()
    }

    /// Bounds of all points ([`Aabb::EMPTY`] for a mesh without points).
    pub fn bounds(&self) -> Aabb {
        self.points
            .iter()
            .fold(Aabb::EMPTY, |b, p| b.grow(glam::Vec3::from_array(*p)))
    }

    /// The field with this exact name.
    pub fn field(&self, name: &str) -> Option<&PointField> {
        self.fields.iter().find(|f| f.name == name)
    }

    /// Field names in storage order (for `isoscope info`).
    pub fn field_names(&self) -> Vec<&str> {
        self.fields.iter().map(|f| f.name.as_str()).collect()
    }

    /// The field with this name, or an error listing the available names.
    pub fn require_field(&self, name: &str) -> Result<&PointField, TetError> {
        self.field(name).ok_or_else(|| TetError::NoSuchField {
            name: name.to_owned(),
            available: self.fields.iter().map(|f| f.name.clone()).collect(),
        })
    }
}

/// Converts `f64` coordinates to the `f32` storage (round to nearest).
pub fn points_from_f64(points: &[[f64; 3]]) -> Vec<[f32; 3]> {
    points
        .iter()
        .map(|p| [p[0] as f32, p[1] as f32, p[2] as f32])
        .collect()
}

/// Quad and triangle faces of the hexahedron (VTK order), as cyclic local index lists.
const HEX_FACES: [&[usize]; 6] = [
    &[0, 3, 2, 1],
    &[4, 5, 6, 7],
    &[0, 1, 5, 4],
    &[1, 2, 6, 5],
    &[2, 3, 7, 6],
    &[3, 0, 4, 7],
];
const WEDGE_FACES: [&[usize]; 5] = [
    &[0, 1, 2],
    &[3, 5, 4],
    &[0, 3, 4, 1],
    &[1, 4, 5, 2],
    &[2, 5, 3, 0],
];
const PYRAMID_FACES: [&[usize]; 5] = [
    &[0, 3, 2, 1],
    &[0, 1, 4],
    &[1, 2, 4],
    &[2, 3, 4],
    &[3, 0, 4],
];

/// Local position of the smallest global index among `locals` (ties: first in the list).
fn local_min(v: &[u32], locals: &[usize]) -> usize {
    let mut best = locals[0];
    for &l in &locals[1..] {
        if v[l] < v[best] {
            best = l;
        }
    }
    best
}

/// Pulling triangulation (module docs): cone from the smallest vertex over the other faces.
fn pull<const N: usize>(v: &[u32], faces: &[&[usize]]) -> [[u32; 4]; N] {
    const ALL: [usize; 8] = [0, 1, 2, 3, 4, 5, 6, 7];
    let apex = local_min(v, &ALL[..v.len()]);
    let mut out = [[0u32; 4]; N];
    let mut k = 0;
    for face in faces {
        // A face "contains" the apex by local position; with repeated global indices the
        // result is a degenerate tet, which the intersector skips.
        if face.contains(&apex) {
            continue;
        }
        // Cone from the face's smallest vertex `w` to fan-triangulate the face.
        let w = face
            .iter()
            .position(|&l| l == local_min(v, face))
            .unwrap_or(0);
        let m = face.len();
        for j in 1..m - 1 {
            let a = face[(w + j) % m];
            let b = face[(w + j + 1) % m];
            out[k] = [v[face[w]], v[a], v[b], v[apex]];
            k += 1;
        }
    }
    debug_assert_eq!(k, N);
    out
}

/// Splits a hexahedron (VTK vertex order) into 6 tets, crack-free with its neighbours.
pub fn split_hex(v: [u32; 8]) -> [[u32; 4]; 6] {
    pull::<6>(&v, &HEX_FACES)
}

/// The tets of the `(n − 1)³` cubes of an `n³`-point lattice, each split by [`split_hex`];
/// `id(i, j, k)` is the point index of lattice point `(i, j, k)`.
pub fn lattice_tets(n: usize, id: impl Fn(usize, usize, usize) -> u32) -> Vec<[u32; 4]> {
    let cells = n.saturating_sub(1);
    let mut tets = Vec::with_capacity(cells.pow(3) * 6);
    for k in 0..cells {
        for j in 0..cells {
            for i in 0..cells {
                tets.extend(split_hex([
                    id(i, j, k),
                    id(i + 1, j, k),
                    id(i + 1, j + 1, k),
                    id(i, j + 1, k),
                    id(i, j, k + 1),
                    id(i + 1, j, k + 1),
                    id(i + 1, j + 1, k + 1),
                    id(i, j + 1, k + 1),
                ]));
            }
        }
    }
    tets
}

/// Splits a wedge / prism (VTK vertex order) into 3 tets, crack-free with its neighbours.
pub fn split_wedge(v: [u32; 6]) -> [[u32; 4]; 3] {
    pull::<3>(&v, &WEDGE_FACES)
}

/// Splits a pyramid (VTK vertex order, apex last) into 2 tets, crack-free with its neighbours.
pub fn split_pyramid(v: [u32; 5]) -> [[u32; 4]; 2] {
    pull::<2>(&v, &PYRAMID_FACES)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::HashMap;

    fn signed_volume(p: &[[f64; 3]], t: [u32; 4]) -> f64 {
        let q = |i: usize| p[t[i] as usize];
        let (a, b, c, d) = (q(0), q(1), q(2), q(3));
        let u = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
        let v = [c[0] - a[0], c[1] - a[1], c[2] - a[2]];
        let w = [d[0] - a[0], d[1] - a[1], d[2] - a[2]];
        (u[0] * (v[1] * w[2] - v[2] * w[1]) - u[1] * (v[0] * w[2] - v[2] * w[0])
            + u[2] * (v[0] * w[1] - v[1] * w[0]))
            / 6.0
    }

    /// Conformity: every triangle of the tetrahedralization is used by at most two tets,
    /// and exactly `boundary` of them by one; the tets tile the domain (volumes sum up).
    fn check_conforming(points: &[[f64; 3]], tets: &[[u32; 4]], volume: f64, boundary: usize) {
        let mut faces: HashMap<[u32; 3], usize> = HashMap::new();
        let mut vol = 0.0;
        for &t in tets {
            let v = signed_volume(points, t);
            assert!(v.abs() > 1e-12, "degenerate tet {t:?}");
            vol += v.abs();
            for skip in 0..4 {
                let mut f: Vec<u32> = (0..4).filter(|&i| i != skip).map(|i| t[i]).collect();
                f.sort_unstable();
                *faces.entry([f[0], f[1], f[2]]).or_default() += 1;
            }
        }
        assert!(
            (vol - volume).abs() < 1e-9 * volume.max(1.0),
            "{vol} vs {volume}"
        );
        assert!(
            faces.values().all(|&c| c <= 2),
            "a face is shared by 3+ tets"
        );
        assert_eq!(faces.values().filter(|&&c| c == 1).count(), boundary);
    }

    /// Numbers the points of an `n³` lattice in a scrambled order so that the smallest index
    /// of a face sits at every possible corner somewhere.
    fn lattice(n: usize) -> (Vec<[f64; 3]>, impl Fn(usize, usize, usize) -> u32) {
        let count = n * n * n;
        let perm: Vec<u32> = (0..count)
            .map(|i| ((i * 7919 + 13) % count) as u32)
            .collect();
        let mut pts = vec![[0.0; 3]; count];
        for k in 0..n {
            for j in 0..n {
                for i in 0..n {
                    pts[perm[i + n * (j + n * k)] as usize] = [i as f64, j as f64, k as f64];
                }
            }
        }
        (pts, move |i, j, k| perm[i + n * (j + n * k)])
    }

    #[test]
    fn hex_split_is_crack_free() {
        let n = 5;
        let (pts, id) = lattice(n);
        let tets = lattice_tets(n, id);
        let m = (n - 1) * (n - 1);
        check_conforming(&pts, &tets, ((n - 1) * m) as f64, 6 * m * 2);
    }

    #[test]
    fn wedge_and_pyramid_splits_are_crack_free() {
        // All cubes of an n³ lattice as wedge pairs (columns along z, split along a fixed
        // xy diagonal): wedges meet wedges on quads and triangles.
        let n = 4;
        let (pts, id) = lattice(n);
        let mut tets = Vec::new();
        for k in 0..n - 1 {
            for j in 0..n - 1 {
                for i in 0..n - 1 {
                    let c = |a: usize, b: usize, z: usize| id(i + a, j + b, k + z);
                    tets.extend(split_wedge([
                        c(0, 0, 0),
                        c(1, 0, 0),
                        c(1, 1, 0),
                        c(0, 0, 1),
                        c(1, 0, 1),
                        c(1, 1, 1),
                    ]));
                    tets.extend(split_wedge([
                        c(0, 0, 0),
                        c(1, 1, 0),
                        c(0, 1, 0),
                        c(0, 0, 1),
                        c(1, 1, 1),
                        c(0, 1, 1),
                    ]));
                }
            }
        }
        let m = (n - 1) * (n - 1);
        check_conforming(&pts, &tets, ((n - 1) * m) as f64, 6 * m * 2);

        // A row of four cubes along x: hex | six pyramids around a centre | wedge pair | hex.
        // Neighbours share the x-facing quads, split by different cell types.
        let (mut pts, id) = lattice(5);
        let id = &id;
        let mut tets = Vec::new();
        let cube = |i: usize| {
            let c = move |a: usize, b: usize, z: usize| id(i + a, b, z);
            [
                c(0, 0, 0),
                c(1, 0, 0),
                c(1, 1, 0),
                c(0, 1, 0),
                c(0, 0, 1),
                c(1, 0, 1),
                c(1, 1, 1),
                c(0, 1, 1),
            ]
        };
        tets.extend(split_hex(cube(0)));
        let h = cube(1);
        let centre = pts.len() as u32;
        pts.push([1.5, 0.5, 0.5]);
        for q in [
            [0, 3, 2, 1],
            [4, 5, 6, 7],
            [0, 1, 5, 4],
            [1, 2, 6, 5],
            [2, 3, 7, 6],
            [3, 0, 4, 7],
        ] {
            tets.extend(split_pyramid([h[q[0]], h[q[1]], h[q[2]], h[q[3]], centre]));
        }
        let h = cube(2);
        tets.extend(split_wedge([h[0], h[1], h[2], h[4], h[5], h[6]]));
        tets.extend(split_wedge([h[0], h[2], h[3], h[4], h[6], h[7]]));
        tets.extend(split_hex(cube(3)));
        check_conforming(&pts, &tets, 4.0, 18 * 2);
    }

    #[test]
    fn new_rejects_bad_parts_naming_the_cell() {
        let pts = vec![[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
        let ok = TetMesh::new(
            pts.clone(),
            vec![[0, 1, 2, 3]],
            vec![PointField::new("s", vec![0.0; 4])],
        );
        assert!(ok.is_ok());
        let e = TetMesh::new(pts.clone(), vec![[0, 1, 2, 3], [0, 1, 2, 4]], vec![]).unwrap_err();
        assert_eq!(
            e,
            TetError::IndexOutOfRange {
                cell: 1,
                index: 4,
                points: 4
            }
        );
        assert!(e.to_string().contains("cell 1"));
        let e = TetMesh::new(
            pts.clone(),
            vec![],
            vec![PointField::new("s", vec![0.0; 3])],
        )
        .unwrap_err();
        assert!(matches!(
            e,
            TetError::FieldLength {
                expected: 4,
                actual: 3,
                ..
            }
        ));
        let e = TetMesh::new(
            pts.clone(),
            vec![],
            vec![
                PointField::new("s", vec![0.0; 4]),
                PointField::new("s", vec![1.0; 4]),
            ],
        )
        .unwrap_err();
        assert!(matches!(e, TetError::DuplicateField { .. }));
        let mut bad = pts.clone();
        bad[2][1] = f32::NAN;
        assert!(matches!(
            TetMesh::new(bad, vec![], vec![]),
            Err(TetError::NonFinitePoint { point: 2, .. })
        ));
        let m = ok.unwrap();
        assert_eq!(m.bounds(), Aabb::new(glam::Vec3::ZERO, glam::Vec3::ONE));
        assert!(m.field("s").is_some() && m.field("t").is_none());
        assert!(matches!(
            m.require_field("t"),
            Err(TetError::NoSuchField { .. })
        ));
        assert_eq!(
            points_from_f64(&[[0.1, 2.0, -3.5]]),
            vec![[0.1f32, 2.0, -3.5]]
        );
    }
}
