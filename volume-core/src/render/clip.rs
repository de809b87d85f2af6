//! Ray clipping: the parameter intervals of a ray that survive all clip regions.
//!
//! Thesis (seed 004) §8.6 clips subtrees with one crop box. Here any number of boxes and
//! planes is allowed: each region keeps a set of `t` along the ray (one interval for a
//! keep-inside box or a plane, up to two for a keep-outside box) and the ray keeps their
//! intersection. The renderer traces each kept interval in order with `[t_min, t_max]`, so the
//! acceleration structure culls whole subtrees outside the segment on its own, and the cut
//! faces are never shaded (there is no surface at an interval's end, only a gap).

use crate::math::{Interval, Ray};
use crate::render::settings::{ClipRegion, Keep};

/// Ray–box slab test without the conservative widening of [`crate::math::Aabb::intersect`]:
/// clipping must be exact (the user's box), not conservative. `None` if the ray's line misses
/// the closed box or the box is empty.
pub fn ray_box(ray: &Ray, min: glam::Vec3, max: glam::Vec3) -> Option<Interval> {
    let (mut t0, mut t1) = (f32::NEG_INFINITY, f32::INFINITY);
    for a in 0..3 {
        let (o, d) = (ray.origin[a], ray.dir[a]);
        if min[a] > max[a] {
            return None;
        }
        if d == 0.0 {
            if o < min[a] || o > max[a] {
                return None;
            }
            continue;
        }
        let (mut ta, mut tb) = ((min[a] - o) / d, (max[a] - o) / d);
        if ta > tb {
            std::mem::swap(&mut ta, &mut tb);
        }
        t0 = t0.max(ta);
        t1 = t1.min(tb);
    }
    (t0 <= t1).then_some(Interval::new(t0, t1))
}

/// The part of the ray's line kept by a half-space `normal · x <= offset`, or `None`.
pub fn ray_plane(ray: &Ray, normal: glam::Vec3, offset: f32) -> Option<Interval> {
    let nd = normal.dot(ray.dir);
    let rhs = offset - normal.dot(ray.origin);
    if nd == 0.0 {
        return (rhs >= 0.0).then_some(Interval::new(f32::NEG_INFINITY, f32::INFINITY));
    }
    let t = rhs / nd;
    Some(if nd > 0.0 {
        Interval::new(f32::NEG_INFINITY, t)
    } else {
        Interval::new(t, f32::INFINITY)
    })
}

/// Writes the kept intervals of `range` (sorted, disjoint, non-empty) into `out`, replacing
/// its contents. `tmp` is scratch space; both vectors keep their capacity, so a caller that
/// reuses them allocates nothing per ray. At most `1 + (number of keep-outside boxes)`
/// intervals result.
pub fn kept_intervals(
    ray: &Ray,
    range: Interval,
    clips: &[ClipRegion],
    out: &mut Vec<Interval>,
    tmp: &mut Vec<Interval>,
) {
    out.clear();
    if range.is_empty() {
        return;
    }
    out.push(range);
    for clip in clips {
        if out.is_empty() {
            return;
        }
        match *clip {
            ClipRegion::Box {
                min,
                max,
                keep: Keep::Inside,
            } => match ray_box(ray, min, max) {
                Some(k) => intersect_all(out, k),
                None => out.clear(),
            },
            ClipRegion::Plane { normal, offset } => match ray_plane(ray, normal, offset) {
                Some(k) => intersect_all(out, k),
                None => out.clear(),
            },
            ClipRegion::Box {
                min,
                max,
                keep: Keep::Outside,
            } => {
                // The removed set is the open interior (t0, t1); its boundary is kept.
                let Some(removed) = ray_box(ray, min, max) else {
                    continue;
                };
                tmp.clear();
                for iv in out.iter() {
                    let before = iv.intersect(&Interval::new(f32::NEG_INFINITY, removed.lo));
                    let after = iv.intersect(&Interval::new(removed.hi, f32::INFINITY));
                    if !before.is_empty() {
                        tmp.push(before);
                    }
                    // A flat box (lo == hi) removes nothing; do not duplicate the point.
                    if !after.is_empty() && (removed.lo != removed.hi || before.is_empty()) {
                        tmp.push(after);
                    }
                }
                std::mem::swap(out, tmp);
            }
        }
    }
}

fn intersect_all(out: &mut Vec<Interval>, keep: Interval) {
    out.retain_mut(|iv| {
        *iv = iv.intersect(&keep);
        !iv.is_empty()
    });
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::rng::Rng;
    use glam::Vec3;

    /// Point membership, the brute-force truth. Returns `None` when `p` lies within `tol` of a
    /// region boundary (where the interval ends may round either way).
    fn kept_point(p: Vec3, clips: &[ClipRegion], tol: f32) -> Option<bool> {
        let mut kept = true;
        for c in clips {
            let inside = match *c {
                ClipRegion::Box { min, max, keep } => {
                    let d_out = (min - p).max(p - max).max_element();
                    if d_out.abs() < tol {
                        return None;
                    }
                    let inside = d_out < 0.0;
                    match keep {
                        Keep::Inside => inside,
                        Keep::Outside => !inside,
                    }
                }
                ClipRegion::Plane { normal, offset } => {
                    let s = (normal.dot(p) - offset) / normal.length();
                    if s.abs() < tol {
                        return None;
                    }
                    s < 0.0
                }
            };
            kept &= inside;
        }
        Some(kept)
    }

    #[test]
    fn kept_intervals_match_point_sampling() {
        let mut rng = Rng::new(7);
        let (mut out, mut tmp) = (Vec::new(), Vec::new());
        let mut checked = 0u32;
        for case in 0..400 {
            let n = 1 + rng.below(4) as usize;
            let clips: Vec<ClipRegion> = (0..n)
                .map(|_| {
                    if rng.below(3) == 0 {
                        ClipRegion::Plane {
                            normal: rng.vec3(-1.0, 1.0),
                            offset: rng.range_f32(-1.0, 1.0),
                        }
                    } else {
                        let a = rng.vec3(-2.0, 2.0);
                        let b = rng.vec3(-2.0, 2.0);
                        ClipRegion::Box {
                            min: a.min(b),
                            max: a.max(b),
                            keep: if rng.below(2) == 0 {
                                Keep::Inside
                            } else {
                                Keep::Outside
                            },
                        }
                    }
                })
                .collect();
            let mut dir = rng.vec3(-1.0, 1.0);
            // Some axis-parallel rays too.
            if case % 5 == 0 {
                dir.x = 0.0;
            }
            let ray = Ray::new(rng.vec3(-4.0, 4.0), dir.normalize());
            let range = Interval::new(0.0, 12.0);
            kept_intervals(&ray, range, &clips, &mut out, &mut tmp);
            let outside_boxes = clips
                .iter()
                .filter(|c| {
                    matches!(
                        c,
                        ClipRegion::Box {
                            keep: Keep::Outside,
                            ..
                        }
                    )
                })
                .count();
            assert!(out.len() <= 1 + outside_boxes);
            for w in out.windows(2) {
                assert!(w[0].hi < w[1].lo, "intervals sorted and disjoint: {out:?}");
            }
            for s in 0..2000 {
                let t = range.lo + (range.hi - range.lo) * (s as f32 + 0.5) / 2000.0;
                let Some(truth) = kept_point(ray.at(t), &clips, 1e-4) else {
                    continue;
                };
                let got = out.iter().any(|iv| iv.contains(t));
                assert_eq!(got, truth, "case {case} t {t}: {clips:?} -> {out:?}");
                checked += 1;
            }
        }
        assert!(checked > 500_000);
    }

    #[test]
    fn keep_outside_splits_a_ray_in_two() {
        let ray = Ray::new(Vec3::new(-5.0, 0.5, 0.5), Vec3::X);
        let clips = [ClipRegion::Box {
            min: Vec3::ZERO,
            max: Vec3::ONE,
            keep: Keep::Outside,
        }];
        let (mut out, mut tmp) = (Vec::new(), Vec::new());
        kept_intervals(&ray, Interval::new(0.0, 10.0), &clips, &mut out, &mut tmp);
        assert_eq!(out, vec![Interval::new(0.0, 5.0), Interval::new(6.0, 10.0)]);
        // A plane behind everything removes the whole ray.
        let all = [ClipRegion::Plane {
            normal: Vec3::Y,
            offset: 0.0,
        }];
        kept_intervals(&ray, Interval::new(0.0, 10.0), &all, &mut out, &mut tmp);
        assert!(out.is_empty());
    }
}
