//! Probing a tetrahedral mesh at a world position: the tet that holds it, its barycentric
//! coordinates, the linearly interpolated value and that linear function's gradient (the
//! picking of the viewer and `isoscope probe`). Inside a tet the field is linear (thesis
//! seed 004 §8.2: marching tetrahedra draws exactly its level sets), so a probe at a ray's
//! hit returns the isovalue up to the hit's error.
//!
//! A brute-force search over every tet, in `f64`: one query, not a per-ray path, and the
//! twin against which an accelerated point location would be checked.

use glam::DVec3;

/// What a mesh holds at one world position.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TetProbe {
    /// Index of the tet holding the position (the first found where tets share a face).
    pub tet: usize,
    /// Barycentric coordinates of the position for the tet's four corners (sum 1).
    pub barycentric: [f64; 4],
    /// Linearly interpolated value of the field.
    pub value: f64,
    /// Gradient of the field inside the tet, value per world unit.
    pub gradient_world: DVec3,
}

/// The tet of `tets` (corner indices into `points`) holding `p`, with `values` (one per
/// point) interpolated there; `None` if no tet holds it. Degenerate tets are skipped. A
/// relative tolerance of 10⁻⁹ keeps points on faces, where rays enter.
pub fn probe_tets(
    points: &[[f32; 3]],
    tets: &[[u32; 4]],
    values: &[f32],
    p: DVec3,
) -> Option<TetProbe> {
    let point = |i: u32| {
        points
            .get(i as usize)
            .map(|q| DVec3::from(q.map(f64::from)))
    };
    for (t, corners) in tets.iter().enumerate() {
        let (Some(a), Some(b), Some(c), Some(d)) = (
            point(corners[0]),
            point(corners[1]),
            point(corners[2]),
            point(corners[3]),
        ) else {
            continue;
        };
        let m = glam::DMat3::from_cols(b - a, c - a, d - a);
        let det = m.determinant();
        let scale = (b - a).length() * (c - a).length() * (d - a).length();
        if !det.is_finite() || det.abs() <= 1e-12 * scale {
            continue;
        }
        let l = m.inverse() * (p - a);
        let bary = [1.0 - l.x - l.y - l.z, l.x, l.y, l.z];
        if bary.iter().any(|&w| w < -1e-9) {
            continue;
        }
        let value_of = |i: u32| values.get(i as usize).map(|&v| f64::from(v));
        let (Some(v0), Some(v1), Some(v2), Some(v3)) = (
            value_of(corners[0]),
            value_of(corners[1]),
            value_of(corners[2]),
            value_of(corners[3]),
        ) else {
            continue;
        };
        let value = bary[0] * v0 + bary[1] * v1 + bary[2] * v2 + bary[3] * v3;
        // v(p) = v0 + g·(p − a) with Mᵀ g = (v1 − v0, v2 − v0, v3 − v0).
        let gradient_world = m.transpose().inverse() * DVec3::new(v1 - v0, v2 - v0, v3 - v0);
        return Some(TetProbe {
            tet: t,
            barycentric: bary,
            value,
            gradient_world,
        });
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_linear_field_is_probed_exactly_in_the_holding_tet() {
        // A cube split into 6 tets around its diagonal; f = 2x − y + 4z + 1 at the corners.
        let points: Vec<[f32; 3]> = (0..8)
            .map(|c| [(c & 1) as f32, ((c >> 1) & 1) as f32, ((c >> 2) & 1) as f32])
            .collect();
        let f = |p: DVec3| 2.0 * p.x - p.y + 4.0 * p.z + 1.0;
        let values: Vec<f32> = points
            .iter()
            .map(|q| f(DVec3::from(q.map(f64::from))) as f32)
            .collect();
        let tets = vec![
            [0, 1, 3, 7],
            [0, 3, 2, 7],
            [0, 2, 6, 7],
            [0, 6, 4, 7],
            [0, 4, 5, 7],
            [0, 5, 1, 7],
        ];
        for p in [
            DVec3::new(0.2, 0.3, 0.4),
            DVec3::new(0.9, 0.1, 0.05),
            DVec3::new(0.5, 0.5, 0.5),
            DVec3::new(1.0, 1.0, 1.0),
        ] {
            let probe = probe_tets(&points, &tets, &values, p).unwrap();
            assert!((probe.value - f(p)).abs() < 1e-9);
            assert!((probe.gradient_world - DVec3::new(2.0, -1.0, 4.0)).length() < 1e-9);
            assert!((probe.barycentric.iter().sum::<f64>() - 1.0).abs() < 1e-12);
            // The barycentric coordinates rebuild the position from the tet's corners.
            let rebuilt: DVec3 = tets[probe.tet]
                .iter()
                .zip(probe.barycentric)
                .map(|(&i, w)| DVec3::from(points[i as usize].map(f64::from)) * w)
                .sum();
            assert!((rebuilt - p).length() < 1e-12);
        }
        assert!(probe_tets(&points, &tets, &values, DVec3::new(1.5, 0.5, 0.5)).is_none());
    }
}
