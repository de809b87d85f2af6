//! Marching tetrahedra isopolygons and the watertight ray–isopolygon test (thesis 004 §8.2).
//!
//! ## Extraction (§8.2.1)
//! The case index of a tet for isovalue `c` has bit `i` set when vertex `i` is *above* `c`
//! (`v_i > c`, so a vertex exactly at `c` counts as below). [`CASES`] gives, for each of the
//! 16 cases, the tet edges that carry the isopolygon's 0, 3 or 4 vertices in cyclic order.
//! Each polygon vertex is the linear interpolation along its edge, always computed from the
//! endpoint with the **lower global point index** (`P + (c − v_P)/(v_Q − v_P)·(Q − P)`): two
//! tets sharing the edge therefore produce bit-identical vertices, so the isosurface has no
//! cracks in `f32`.
//!
//! ## Intersection (§8.2.2, made watertight)
//! The thesis projects the hit point onto the polygon's dominant plane and runs 2D edge
//! tests. Two neighbouring polygons project onto different planes, so their shared edge
//! would be tested inconsistently. We therefore project along the *ray* instead (Woop,
//! Benthin, Wald 2013, "Watertight ray/triangle intersection"): vertices are translated to
//! the ray origin and sheared so the ray runs along +z; the 2D edge functions of a shared
//! edge are then computed from the same two vertices with the same operations in both
//! polygons and differ exactly in sign. Edge functions that round to zero are recomputed in
//! `f64` (a product of two `f32` is exact there, so the sign is exact), and an edge exactly
//! through the hit point counts as inside for both polygons (closed test): a ray through a
//! shared edge or vertex hits at least one of them, never none. A quad is tested as the fan
//! `(0,1,2), (0,2,3)`; the diagonal is shared the same way, so non-planarity from rounding
//! cannot open a gap either.
//!
//! Degenerate polygons (zero-volume tets, isovalue exactly at vertices) have zero area in
//! ray space (`det == 0`) and are skipped. A tet with a NaN value is void (never extracted).

use glam::{DVec3, Vec3, Vec4};

/// The six tet edges as local vertex pairs.
pub const EDGES: [[u8; 2]; 6] = [[0, 1], [0, 2], [0, 3], [1, 2], [1, 3], [2, 3]];

/// One marching-tetrahedra case: the number of polygon vertices (0, 3 or 4) and the local
/// edges (as `[a, b]` vertex pairs) carrying them, in cyclic order.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MtCase {
    pub count: u8,
    pub edges: [[u8; 2]; 4],
}

const fn make_case(mask: u8) -> MtCase {
    let above = mask.count_ones();
    let mut edges = [[0u8; 2]; 4];
    if above == 0 || above == 4 {
        return MtCase { count: 0, edges };
    }
    if above == 1 || above == 3 {
        // The lone vertex (the one on the minority side) to each of the other three.
        let lone_above = above == 1;
        let mut lone = 0u8;
        while lone < 4 {
            let is_above = mask & (1 << lone) != 0;
            if is_above == lone_above {
                break;
            }
            lone += 1;
        }
        let mut k = 0;
        let mut j = 0u8;
        while j < 4 {
            if j != lone {
                edges[k] = [lone, j];
                k += 1;
            }
            j += 1;
        }
        return MtCase { count: 3, edges };
    }
    // Two above (a, b), two below (c, d): cycle (a,c) (a,d) (b,d) (b,c); consecutive
    // vertices share a tet face.
    let mut hi = [0u8; 2];
    let mut lo = [0u8; 2];
    let (mut nh, mut nl) = (0, 0);
    let mut i = 0u8;
    while i < 4 {
        if mask & (1 << i) != 0 {
            hi[nh] = i;
            nh += 1;
        } else {
            lo[nl] = i;
            nl += 1;
        }
        i += 1;
    }
    edges[0] = [hi[0], lo[0]];
    edges[1] = [hi[0], lo[1]];
    edges[2] = [hi[1], lo[1]];
    edges[3] = [hi[1], lo[0]];
    MtCase { count: 4, edges }
}

const fn make_cases() -> [MtCase; 16] {
    let mut t = [MtCase {
        count: 0,
        edges: [[0; 2]; 4],
    }; 16];
    let mut m = 0;
    while m < 16 {
        t[m] = make_case(m as u8);
        m += 1;
    }
    t
}

/// The 16-case marching-tetrahedra table (bit `i` of the index: vertex `i` above `c`).
pub const CASES: [MtCase; 16] = make_cases();

/// An isopolygon in world space (`count` is 3 or 4).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IsoPoly {
    pub v: [Vec3; 4],
    pub count: u8,
}

impl IsoPoly {
    /// Unit normal of the polygon plane (`None` if degenerate). Its sign follows the vertex
    /// order; [`crate::tet::TetScene`] orients hit normals towards increasing value.
    pub fn normal(&self) -> Option<Vec3> {
        let n = if self.count == 4 {
            (self.v[2] - self.v[0]).cross(self.v[3] - self.v[1])
        } else {
            (self.v[1] - self.v[0]).cross(self.v[2] - self.v[0])
        };
        let n = n.normalize_or_zero();
        (n != Vec3::ZERO).then_some(n)
    }

    /// The faceted shading normal of a hit on this polygon, the isopolygon of the tet with
    /// vertices `v` (values in `w`) for isovalue `c`: [`IsoPoly::normal`] oriented towards
    /// increasing value, `+z` when degenerate.
    #[inline]
    pub fn oriented_normal(&self, v: &[Vec4; 4], c: f32) -> Vec3 {
        self.normal().map_or(Vec3::Z, |n| {
            // n is parallel to the gradient: compare with a below → above direction.
            let above = v
                .iter()
                .find(|p| p.w > c)
                .map_or(Vec3::ZERO, |p| p.truncate());
            let below = v
                .iter()
                .find(|p| p.w <= c)
                .map_or(Vec3::ZERO, |p| p.truncate());
            if n.dot(above - below) < 0.0 { -n } else { n }
        })
    }

    #[inline]
    pub fn bounds(&self) -> (Vec3, Vec3) {
        let mut lo = self.v[0].min(self.v[1]).min(self.v[2]);
        let mut hi = self.v[0].max(self.v[1]).max(self.v[2]);
        if self.count == 4 {
            lo = lo.min(self.v[3]);
            hi = hi.max(self.v[3]);
        }
        (lo, hi)
    }
}

/// Case index of a tet for isovalue `c` (`v` holds the values in `w`).
#[inline]
pub fn case_index(v: &[Vec4; 4], c: f32) -> usize {
    usize::from(v[0].w > c)
        | usize::from(v[1].w > c) << 1
        | usize::from(v[2].w > c) << 2
        | usize::from(v[3].w > c) << 3
}

/// The isopolygon of a tet (`v`: position + value, `ids`: global point indices), or `None`
/// for an empty case. Callers skip NaN-valued tets before (their case is arbitrary).
#[inline]
pub fn extract(v: &[Vec4; 4], ids: &[u32; 4], c: f32) -> Option<IsoPoly> {
    extract_case(v, ids, c, case_index(v, c))
}

/// [`extract`] for a tet whose [`case_index`] the caller already has.
#[inline]
pub fn extract_case(v: &[Vec4; 4], ids: &[u32; 4], c: f32, case: usize) -> Option<IsoPoly> {
    let case = &CASES[case];
    if case.count == 0 {
        return None;
    }
    let mut out = IsoPoly {
        v: [Vec3::ZERO; 4],
        count: case.count,
    };
    for k in 0..case.count as usize {
        let [a, b] = case.edges[k];
        let (a, b) = (a as usize, b as usize);
        // Canonical direction: from the lower global index (ties: local order, equal points).
        let (p, q) = if (ids[a], a) < (ids[b], b) {
            (v[a], v[b])
        } else {
            (v[b], v[a])
        };
        let s = (c - p.w) / (q.w - p.w);
        out.v[k] = p.truncate() + (q.truncate() - p.truncate()) * s;
    }
    Some(out)
}

/// A ray prepared for the watertight test: origin, permuted axes and shear (Woop et al.).
#[derive(Debug, Clone, Copy)]
pub struct RaySpace {
    pub origin: Vec3,
    pub kx: u8,
    pub ky: u8,
    pub kz: u8,
    pub sx: f32,
    pub sy: f32,
    pub sz: f32,
    /// False for a zero or non-finite direction: such a ray hits nothing.
    pub valid: bool,
}

impl RaySpace {
    pub const INVALID: RaySpace = RaySpace {
        origin: Vec3::ZERO,
        kx: 0,
        ky: 1,
        kz: 2,
        sx: 0.0,
        sy: 0.0,
        sz: 0.0,
        valid: false,
    };

    #[inline]
    pub fn new(origin: Vec3, dir: Vec3) -> Self {
        let a = dir.abs();
        let kz = if a.x >= a.y && a.x >= a.z {
            0
        } else if a.y >= a.z {
            1
        } else {
            2
        };
        let dz = dir[kz];
        if !(dz != 0.0 && dir.is_finite() && origin.is_finite()) {
            return Self::INVALID;
        }
        let kx = (kz + 1) % 3;
        let ky = (kx + 1) % 3;
        Self {
            origin,
            kx: kx as u8,
            ky: ky as u8,
            kz: kz as u8,
            sx: dir[kx] / dz,
            sy: dir[ky] / dz,
            sz: 1.0 / dz,
            valid: true,
        }
    }

    /// The vertex in ray space: `(x, y)` across the ray, `z` the ray parameter of its depth.
    #[inline]
    fn transform(&self, p: Vec3) -> [f32; 3] {
        let a = p - self.origin;
        // `& 3` on a 4-array: no bounds check, no branchy `Vec3` indexing.
        let a = [a.x, a.y, a.z, 0.0];
        let (ax, ay, az) = (
            a[usize::from(self.kx & 3)],
            a[usize::from(self.ky & 3)],
            a[usize::from(self.kz & 3)],
        );
        [ax - self.sx * az, ay - self.sy * az, self.sz * az]
    }
}

/// 2D edge function `a × b` of two ray-space vertices, exact in sign (f64 fallback at 0).
#[inline]
fn edge(a: [f32; 3], b: [f32; 3]) -> f32 {
    let e = a[0] * b[1] - a[1] * b[0];
    if e == 0.0 {
        (f64::from(a[0]) * f64::from(b[1]) - f64::from(a[1]) * f64::from(b[0])) as f32
    } else {
        e
    }
}

/// Watertight ray–triangle test in ray space; returns the ray parameter.
#[inline]
fn tri(a: [f32; 3], b: [f32; 3], c: [f32; 3]) -> Option<f32> {
    let u = edge(b, c);
    let v = edge(c, a);
    let w = edge(a, b);
    if (u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0) {
        return None;
    }
    let det = u + v + w;
    if det == 0.0 || !det.is_finite() {
        return None;
    }
    let t = (u * a[2] + v * b[2] + w * c[2]) / det;
    t.is_finite().then_some(t)
}

/// Nearest ray parameter where the ray crosses the polygon, if any (any `t`; the caller
/// clips to its interval).
#[inline]
pub fn intersect(rs: &RaySpace, poly: &IsoPoly) -> Option<f32> {
    if !rs.valid {
        return None;
    }
    let a = rs.transform(poly.v[0]);
    let b = rs.transform(poly.v[1]);
    let c = rs.transform(poly.v[2]);
    let t0 = tri(a, b, c);
    if poly.count == 3 {
        return t0;
    }
    let d = rs.transform(poly.v[3]);
    // The fan halves do not overlap (apart from rounding at the diagonal): any hit will do,
    // but take the nearer for determinism.
    match (t0, tri(a, c, d)) {
        (Some(x), Some(y)) => Some(x.min(y)),
        (x, y) => x.or(y),
    }
}

// ---------------------------------------------------------------------------------------
// f64 reference (brute-force twin)
// ---------------------------------------------------------------------------------------

/// The isopolygon of a tet in `f64` (positions and values widened from the stored `f32`).
#[allow(clippy::needless_range_loop)] // `k` indexes the case edges and the output
pub fn extract_f64(p: &[DVec3; 4], val: &[f64; 4], c: f64) -> Option<([DVec3; 4], usize)> {
    if val.iter().any(|v| v.is_nan()) {
        return None;
    }
    let mask = usize::from(val[0] > c)
        | usize::from(val[1] > c) << 1
        | usize::from(val[2] > c) << 2
        | usize::from(val[3] > c) << 3;
    let case = &CASES[mask];
    if case.count == 0 {
        return None;
    }
    let mut out = [DVec3::ZERO; 4];
    for k in 0..case.count as usize {
        let [a, b] = case.edges[k];
        let (a, b) = (a as usize, b as usize);
        let s = (c - val[a]) / (val[b] - val[a]);
        out[k] = p[a] + (p[b] - p[a]) * s;
    }
    Some((out, case.count as usize))
}

/// `f64` ray–polygon test with a relative `slack` on the edge functions (`slack > 0` grows
/// the polygon, `< 0` shrinks it, `0` is the plain closed test). Returns the ray parameter.
pub fn intersect_f64(
    origin: DVec3,
    dir: DVec3,
    poly: &[DVec3; 4],
    count: usize,
    slack: f64,
) -> Option<f64> {
    let mut best: Option<f64> = None;
    for tri in [[0, 1, 2], [0, 2, 3]].iter().take(count - 2) {
        let (a, b, c) = (poly[tri[0]], poly[tri[1]], poly[tri[2]]);
        // Möller–Trumbore in f64 with barycentric slack.
        let e1 = b - a;
        let e2 = c - a;
        let pv = dir.cross(e2);
        let det = e1.dot(pv);
        if det == 0.0 || !det.is_finite() {
            continue;
        }
        let inv = 1.0 / det;
        let tv = origin - a;
        let u = tv.dot(pv) * inv;
        let qv = tv.cross(e1);
        let v = dir.dot(qv) * inv;
        let w = 1.0 - u - v;
        if u < -slack || v < -slack || w < -slack {
            continue;
        }
        let t = e2.dot(qv) * inv;
        best = Some(best.map_or(t, |x: f64| x.min(t)));
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn case_table_is_complete_and_symmetric() {
        for (m, case) in CASES.iter().enumerate() {
            let above = (m as u32).count_ones();
            let expect = match above {
                0 | 4 => 0,
                1 | 3 => 3,
                _ => 4,
            };
            assert_eq!(case.count as u32, expect, "case {m}");
            // Every polygon edge crosses the isovalue; consecutive vertices share a face.
            for k in 0..case.count as usize {
                let [a, b] = case.edges[k];
                assert_ne!(m >> a & 1, m >> b & 1);
                let [c, d] = case.edges[(k + 1) % case.count as usize];
                let mut verts = [a, b, c, d].to_vec();
                verts.sort_unstable();
                verts.dedup();
                assert!(
                    verts.len() <= 3,
                    "case {m}: vertices {k} and {} share no face",
                    k + 1
                );
            }
            // Complementary cases use the same edges.
            let mut e1: Vec<[u8; 2]> = case.edges[..case.count as usize]
                .iter()
                .map(|e| [e[0].min(e[1]), e[0].max(e[1])])
                .collect();
            let comp = &CASES[15 - m];
            let mut e2: Vec<[u8; 2]> = comp.edges[..comp.count as usize]
                .iter()
                .map(|e| [e[0].min(e[1]), e[0].max(e[1])])
                .collect();
            e1.sort_unstable();
            e2.sort_unstable();
            assert_eq!(e1, e2);
        }
    }

    #[test]
    fn isopolygon_lies_on_the_linear_field_and_ray_hits_match_f64() {
        let v = [
            Vec4::new(0.0, 0.0, 0.0, 0.0),
            Vec4::new(1.0, 0.0, 0.0, 1.0),
            Vec4::new(0.0, 1.0, 0.0, 2.0),
            Vec4::new(0.0, 0.0, 1.0, 3.0),
        ];
        // f = x + 2y + 3z; isovalue 1.5 gives a quad (vertices 2, 3 above).
        let poly = extract(&v, &[0, 1, 2, 3], 1.5).unwrap();
        assert_eq!(poly.count, 4);
        for p in &poly.v[..4] {
            assert!((p.x + 2.0 * p.y + 3.0 * p.z - 1.5).abs() < 1e-6);
        }
        let n = poly.normal().unwrap();
        let g = Vec3::new(1.0, 2.0, 3.0).normalize();
        assert!((n.dot(g).abs() - 1.0).abs() < 1e-6);
        let origin = Vec3::new(0.1, 0.2, -1.0);
        let dir = Vec3::new(0.05, 0.02, 1.0).normalize();
        let t = intersect(&RaySpace::new(origin, dir), &poly).unwrap();
        let p = origin + dir * t;
        assert!((p.x + 2.0 * p.y + 3.0 * p.z - 1.5).abs() < 1e-5);
        let pd = [0, 1, 2, 3].map(|i| v[i].truncate().as_dvec3());
        let (pf, cnt) = extract_f64(&pd, &[0.0, 1.0, 2.0, 3.0], 1.5).unwrap();
        let tf = intersect_f64(origin.as_dvec3(), dir.as_dvec3(), &pf, cnt, 0.0).unwrap();
        assert!((f64::from(t) - tf).abs() < 1e-5);
        // A zero direction and a NaN origin hit nothing.
        assert!(intersect(&RaySpace::new(origin, Vec3::ZERO), &poly).is_none());
        assert!(intersect(&RaySpace::new(Vec3::NAN, dir), &poly).is_none());
    }

    #[test]
    fn shared_edge_vertices_are_bit_identical() {
        // Two tets sharing the edge between global points 7 and 3, listed in opposite orders.
        let p7 = Vec4::new(0.1, 0.3, 0.7, 0.123);
        let p3 = Vec4::new(0.9, 0.2, 0.4, 0.987);
        let a = extract(
            &[
                p7,
                p3,
                Vec4::new(0.0, 1.0, 0.0, 0.0),
                Vec4::new(0.0, 0.0, 1.0, 0.0),
            ],
            &[7, 3, 1, 2],
            0.4567,
        )
        .unwrap();
        let b = extract(
            &[
                Vec4::new(1.0, 1.0, 1.0, 1.0),
                p3,
                p7,
                Vec4::new(1.0, 0.0, 1.0, 0.0),
            ],
            &[9, 3, 7, 4],
            0.4567,
        )
        .unwrap();
        let on_edge = |q: &IsoPoly| {
            q.v[..q.count as usize]
                .iter()
                .copied()
                .find(|v| {
                    let d = (*v - p7.truncate()).cross(p3.truncate() - p7.truncate());
                    d.length() < 1e-6
                })
                .unwrap()
        };
        assert_eq!(on_edge(&a).to_array(), on_edge(&b).to_array());
    }
}
