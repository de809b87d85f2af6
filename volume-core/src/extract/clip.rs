//! The renderer's clip regions ([`ClipRegion`]) as half-spaces for polygon clipping.
//!
//! A plane keeps `normal · x <= offset` (one half-space); a keep-inside box is the
//! intersection of six. A keep-outside box keeps the complement of its open interior, which
//! is not convex: it is split into six convex pieces that meet only on their boundaries
//! (`x <= x0`, `x >= x1`, then inside the x slab `y <= y0`, `y >= y1`, then inside both slabs
//! `z <= z0`, `z >= z1`), and a polygon is clipped to each piece. Every half-space carries
//! the id of its geometric plane, so a cut point is the same vertex whichever side or piece
//! produced it ([`super::grid`] and [`super::tets`] share them through the mesh builder).

use glam::DVec3;

use super::ExtractError;
use crate::render::{ClipRegion, Keep};

/// Keeps the points with `normal · x <= offset`; `plane` names the geometric plane.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HalfSpace {
    pub normal: DVec3,
    pub offset: f64,
    pub plane: u32,
}

impl HalfSpace {
    /// Signed distance (scaled by `|normal|`): `<= 0` is kept.
    #[inline]
    pub fn distance(&self, p: DVec3) -> f64 {
        self.normal.dot(p) - self.offset
    }

    fn flipped(self) -> Self {
        Self {
            normal: -self.normal,
            offset: -self.offset,
            plane: self.plane,
        }
    }
}

/// A clip region ready for polygon clipping.
#[derive(Debug, Clone, PartialEq)]
pub enum Region {
    /// The intersection of these half-spaces (a plane, a keep-inside box).
    Convex(Vec<HalfSpace>),
    /// A keep-outside box: the union of its six convex pieces (module docs), with the box
    /// for the quick whole-polygon tests.
    Outside {
        min: DVec3,
        max: DVec3,
        pieces: [Vec<HalfSpace>; 6],
    },
}

/// The regions of `clips`, checked (finite, `min <= max`, non-zero plane normal).
pub fn prepare(clips: &[ClipRegion]) -> Result<Vec<Region>, ExtractError> {
    clips
        .iter()
        .enumerate()
        .map(|(index, clip)| {
            let bad = |reason: &str| ExtractError::Clip {
                index,
                reason: reason.to_owned(),
            };
            let id = |k: u32| 6 * index as u32 + k;
            match *clip {
                ClipRegion::Plane { normal, offset } => {
                    if !(normal.is_finite() && offset.is_finite()) {
                        return Err(bad("plane normal and offset must be finite"));
                    }
                    if normal.length_squared() == 0.0 {
                        return Err(bad("plane normal is zero"));
                    }
                    Ok(Region::Convex(vec![HalfSpace {
                        normal: normal.as_dvec3(),
                        offset: f64::from(offset),
                        plane: id(0),
                    }]))
                }
                ClipRegion::Box { min, max, keep } => {
                    if !(min.is_finite() && max.is_finite()) {
                        return Err(bad("box corners must be finite"));
                    }
                    if min.cmpgt(max).any() {
                        return Err(bad("box min exceeds max on some axis"));
                    }
                    let (min, max) = (min.as_dvec3(), max.as_dvec3());
                    // below[a]: x_a <= min_a; above[a]: x_a >= max_a.
                    let axis = |a: usize| {
                        let mut n = DVec3::ZERO;
                        n[a] = 1.0;
                        n
                    };
                    let below = |a: usize| HalfSpace {
                        normal: axis(a),
                        offset: min[a],
                        plane: id(2 * a as u32),
                    };
                    let above = |a: usize| HalfSpace {
                        normal: -axis(a),
                        offset: -max[a],
                        plane: id(2 * a as u32 + 1),
                    };
                    // inside the slab of axis a: x_a >= min_a and x_a <= max_a.
                    let slab = |a: usize| [below(a).flipped(), above(a).flipped()];
                    match keep {
                        Keep::Inside => Ok(Region::Convex((0..3).flat_map(slab).collect())),
                        Keep::Outside => {
                            let piece = |slabs: usize, last: HalfSpace| {
                                let mut p: Vec<HalfSpace> = (0..slabs).flat_map(slab).collect();
                                p.push(last);
                                p
                            };
                            Ok(Region::Outside {
                                min,
                                max,
                                pieces: [
                                    piece(0, below(0)),
                                    piece(0, above(0)),
                                    piece(1, below(1)),
                                    piece(1, above(1)),
                                    piece(2, below(2)),
                                    piece(2, above(2)),
                                ],
                            })
                        }
                    }
                }
            }
        })
        .collect()
}

/// Whether a point is kept by every region (the renderer's closed sets).
pub fn keeps(regions: &[Region], p: DVec3) -> bool {
    regions.iter().all(|r| match r {
        Region::Convex(hs) => hs.iter().all(|h| h.distance(p) <= 0.0),
        Region::Outside { min, max, .. } => (0..3).any(|a| p[a] <= min[a] || p[a] >= max[a]),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    #[test]
    fn outside_pieces_cover_the_complement_once() {
        let regions = prepare(&[ClipRegion::Box {
            min: Vec3::new(-1.0, -2.0, -3.0),
            max: Vec3::new(1.0, 2.0, 3.0),
            keep: Keep::Outside,
        }])
        .unwrap();
        let Region::Outside { pieces, .. } = &regions[0] else {
            panic!("a keep-outside box");
        };
        let mut rng = crate::math::rng::Rng::new(7);
        for _ in 0..2000 {
            let mut u = || rng.unit_f64() * 2.0 - 1.0;
            let p = DVec3::new(4.0 * u(), 4.0 * u(), 5.0 * u());
            let inside_open = p.abs().cmplt(DVec3::new(1.0, 2.0, 3.0)).all();
            let holders = pieces
                .iter()
                .filter(|hs| hs.iter().all(|h| h.distance(p) <= 0.0))
                .count();
            assert_eq!(holders, usize::from(!inside_open), "{p}");
            assert_eq!(keeps(&regions, p), !inside_open);
        }
    }

    #[test]
    fn bad_regions_are_named() {
        let e = prepare(&[
            ClipRegion::Plane {
                normal: Vec3::X,
                offset: 0.0,
            },
            ClipRegion::Plane {
                normal: Vec3::ZERO,
                offset: 0.0,
            },
        ])
        .unwrap_err();
        assert!(matches!(e, ExtractError::Clip { index: 1, .. }), "{e}");
    }
}
