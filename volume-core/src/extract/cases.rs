//! The marching-cubes case table, generated from the cube's faces (no hand-written table).
//!
//! Corner `c` of a cell sits at offset `(c & 1, c >> 1 & 1, c >> 2 & 1)`; bit `c` of a case
//! index is set when corner `c` is *above* the isovalue (`v > iso`, as in [`crate::tet::mt`]).
//! Edge `4·a + s` runs along axis `a` from corner `base` to `base + (1 << a)`, where `s`
//! numbers the positions of the two other axes (the lower one first).
//!
//! Each face of the cube is walked counter-clockwise seen from outside. Its crossed edges
//! pair into directed isoline segments with the above corners on their right; an ambiguous
//! face (diagonal corners above) always separates its above corners. Both rules depend on
//! the face's four corner signs only, so the two cells sharing a face draw the same segments
//! on it (the surface has no cracks). Every crossed edge starts one segment (on one face) and
//! ends one (on the other face holding it), so the segments chain into closed loops; each
//! loop of `n` edges is fanned into `n − 2` triangles from a vertex whose diagonals all
//! cross the cell's inside (a diagonal along a face could meet the neighbour's and make an
//! edge of four triangles). Winding: seen from the side of lower values, triangles run
//! counter-clockwise, i.e. the right-hand normal `(b − a) × (c − a)` points towards
//! *decreasing* value (out of the region above the isovalue, the solid a 3D printer builds).

use std::sync::LazyLock;

/// Most triangles of one case (generating the table would fail beyond it).
pub const MAX_TRIANGLES: usize = 5;

/// The triangles of one case, as triples of cell edge numbers.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CubeCase {
    pub count: u8,
    pub triangles: [[u8; 3]; MAX_TRIANGLES],
}

/// The two corners of edge `e` (lower corner first).
pub const fn edge_corners(e: usize) -> [usize; 2] {
    let axis = e / 4;
    let s = e % 4;
    let (b, c) = match axis {
        0 => (1, 2),
        1 => (0, 2),
        _ => (0, 1),
    };
    let base = ((s & 1) << b) | ((s >> 1) << c);
    [base, base | (1 << axis)]
}

/// The edge joining corners `p` and `q` (which differ in exactly one bit).
fn edge_between(p: usize, q: usize) -> usize {
    let lo = p.min(q);
    let axis = (p ^ q).trailing_zeros() as usize;
    (0..12)
        .find(|&e| edge_corners(e) == [lo, lo | (1 << axis)] && e / 4 == axis)
        .expect("corners differ in one bit")
}

/// The two faces holding edge `e`, as bits `2·axis + side`.
fn edge_faces(e: usize) -> u8 {
    let [p, q] = edge_corners(e);
    (0..3)
        .filter(|&a| (p ^ q) >> a & 1 == 0)
        .fold(0, |bits, a| bits | 1 << (2 * a + (p >> a & 1)))
}

/// The four corners of face `(axis, side)`, counter-clockwise seen from outside.
fn face_corners(axis: usize, side: usize) -> [usize; 4] {
    // (b, c) cyclic after `axis`: e_b × e_c = e_axis, so (0,0), (1,0), (1,1), (0,1) in (b, c)
    // runs counter-clockwise around +e_axis.
    let (b, c) = ((axis + 1) % 3, (axis + 2) % 3);
    let at = |ub: usize, uc: usize| (side << axis) | (ub << b) | (uc << c);
    let ccw = [at(0, 0), at(1, 0), at(1, 1), at(0, 1)];
    if side == 1 {
        ccw
    } else {
        [ccw[0], ccw[3], ccw[2], ccw[1]]
    }
}

fn make_case(mask: usize) -> CubeCase {
    let above = |c: usize| mask >> c & 1 == 1;
    // next[e]: the edge the loop goes to after edge e.
    let mut next = [usize::MAX; 12];
    for axis in 0..3 {
        for side in 0..2 {
            let f = face_corners(axis, side);
            // Crossings in walking order: (edge, entering the above region?).
            let mut crossings = [(0usize, false); 4];
            let mut n = 0;
            for k in 0..4 {
                let (p, q) = (f[k], f[(k + 1) % 4]);
                if above(p) != above(q) {
                    crossings[n] = (edge_between(p, q), above(q));
                    n += 1;
                }
            }
            // An entering crossing pairs with the next exit: the above corner between them is
            // cut off on its own (on an ambiguous face too).
            for k in 0..n {
                let (e, entering) = crossings[k];
                if entering {
                    let (exit, _) = crossings[(k + 1) % n];
                    next[e] = exit;
                }
            }
        }
    }
    let mut case = CubeCase {
        count: 0,
        triangles: [[0; 3]; MAX_TRIANGLES],
    };
    let mut seen = [false; 12];
    for start in 0..12 {
        if next[start] == usize::MAX || seen[start] {
            continue;
        }
        let mut lp = [0usize; 12];
        let mut len = 0;
        let mut e = start;
        while !seen[e] {
            seen[e] = true;
            lp[len] = e;
            len += 1;
            e = next[e];
        }
        // Fan from a vertex whose diagonals all cross the cell's inside: a diagonal along a
        // face (an ambiguous face with both segments in this loop) could be drawn by the
        // neighbour across that face too, and the edge would have four triangles.
        let origin = (0..len)
            .find(|&o| (2..len - 1).all(|k| edge_faces(lp[o]) & edge_faces(lp[(o + k) % len]) == 0))
            .expect("every loop has a fan origin without face diagonals");
        for k in 1..len - 1 {
            let t = usize::from(case.count);
            let v = |k: usize| lp[(origin + k) % len] as u8;
            case.triangles[t] = [v(0), v(k), v(k + 1)];
            case.count += 1;
        }
    }
    case
}

/// The 256 cases (bit `c` of the index: corner `c` above the isovalue).
pub static CASES: LazyLock<[CubeCase; 256]> = LazyLock::new(|| std::array::from_fn(make_case));

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::HashMap;

    #[test]
    fn every_crossed_edge_is_used_and_loops_are_closed() {
        for (mask, case) in CASES.iter().enumerate() {
            let crossed: Vec<usize> = (0..12)
                .filter(|&e| {
                    let [a, b] = edge_corners(e);
                    (mask >> a & 1) != (mask >> b & 1)
                })
                .collect();
            let mut used: Vec<usize> = case.triangles[..usize::from(case.count)]
                .iter()
                .flatten()
                .map(|&e| usize::from(e))
                .collect();
            used.sort_unstable();
            used.dedup();
            assert_eq!(used, crossed, "case {mask}");
            // Inside the cell, every triangle side is shared by two triangles of the case;
            // the loop sides lie on the faces (one triangle each), and no other side does.
            let mut sides: HashMap<(u8, u8), i32> = HashMap::new();
            for t in &case.triangles[..usize::from(case.count)] {
                for k in 0..3 {
                    let (a, b) = (t[k], t[(k + 1) % 3]);
                    *sides.entry((a.min(b), a.max(b))).or_default() += 1;
                    // Opposite directions cancel in a consistently oriented surface.
                }
            }
            for (&(a, b), &n) in &sides {
                let on_face = edge_faces(usize::from(a)) & edge_faces(usize::from(b)) != 0;
                assert_eq!(n, if on_face { 1 } else { 2 }, "case {mask}: side {a}-{b}");
            }
        }
    }

    #[test]
    fn empty_and_single_corner_cases() {
        assert_eq!(CASES[0].count, 0);
        assert_eq!(CASES[255].count, 0);
        // A single corner above: one triangle.
        for c in 0..8 {
            assert_eq!(CASES[1 << c].count, 1);
        }
    }
}
