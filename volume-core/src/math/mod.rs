//! Small geometric and numeric building blocks shared by every acceleration structure.
//!
//! - [`Ray`]: origin, direction and its precomputed reciprocal (for slab tests).
//! - [`Aabb`]: axis-aligned bounds with the conservative slab test of pbrt-v4 §6.1
//!   (the far distance is scaled by `1 + 2·gamma(3)` so that rounding never drops a hit).
//! - [`Interval`]: closed `f32` intervals for ray-segment and value ranges.
//! - [`float`]: floating-point error bounds (`gamma(n)`) and ulp stepping.
//! - [`rng`]: the seeded deterministic generator of every test, benchmark and generated case.
//! - `prefetch`: the one cache hint of the traversals; `lane_indices`: a lane mask's set bits.

pub mod float;
mod interval;
pub mod rng;

pub use interval::Interval;

use glam::Vec3;

/// A cache prefetch hint for the line holding `p` (any address; nothing is read): the
/// kd-tree's grandchildren, a tet packet's smooth-normal rows.
#[inline(always)]
pub(crate) fn prefetch<U>(p: *const U) {
    #[cfg(target_arch = "x86_64")]
    // SAFETY: a prefetch is a hint: it never faults, reads nothing into the program and
    // writes nothing, whatever the address (SSE is part of the x86_64 baseline). The
    // traversal tests (kd-tree == DDA, packet == single, tet packets == single rays) run
    // through it.
    #[allow(unsafe_code)]
    unsafe {
        std::arch::x86_64::_mm_prefetch::<{ std::arch::x86_64::_MM_HINT_T0 }>(p.cast());
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = p;
}

/// The indices of the set bits of a lane mask, lowest first.
#[inline(always)]
pub(crate) fn lane_indices(mut mask: u32) -> impl Iterator<Item = usize> {
    std::iter::from_fn(move || {
        (mask != 0).then(|| {
            let i = mask.trailing_zeros() as usize;
            mask &= mask - 1;
            i
        })
    })
}

/// A ray `origin + t·dir`, `t` in world units when `dir` is unit length.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ray {
    pub origin: Vec3,
    pub dir: Vec3,
    /// `1 / dir` per component (`±inf` for zero components, which the slab test handles).
    pub inv_dir: Vec3,
}

impl Ray {
    pub fn new(origin: Vec3, dir: Vec3) -> Self {
        Self {
            origin,
            dir,
            inv_dir: dir.recip(),
        }
    }

    #[inline]
    pub fn at(&self, t: f32) -> Vec3 {
        self.origin + self.dir * t
    }
}

/// Axis-aligned bounds; `min > max` on some axis means empty.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Aabb {
    pub min: Vec3,
    pub max: Vec3,
}

impl Aabb {
    pub const EMPTY: Aabb = Aabb {
        min: Vec3::splat(f32::INFINITY),
        max: Vec3::splat(f32::NEG_INFINITY),
    };

    pub fn new(min: Vec3, max: Vec3) -> Self {
        Self { min, max }
    }

    pub fn is_empty(&self) -> bool {
        self.min.cmpgt(self.max).any()
    }

    pub fn union(&self, o: &Aabb) -> Aabb {
        Aabb {
            min: self.min.min(o.min),
            max: self.max.max(o.max),
        }
    }

    pub fn grow(&self, p: Vec3) -> Aabb {
        Aabb {
            min: self.min.min(p),
            max: self.max.max(p),
        }
    }

    pub fn contains(&self, p: Vec3) -> bool {
        p.cmpge(self.min).all() && p.cmple(self.max).all()
    }

    pub fn extent(&self) -> Vec3 {
        self.max - self.min
    }

    pub fn center(&self) -> Vec3 {
        (self.min + self.max) * 0.5
    }

    /// This box widened by a few `f32` ulps of its coordinates plus `1e-5` of `outer`'s
    /// largest extent, then kept inside `outer`: the margin a conservative box computed in
    /// `f32` needs against the rounding of its corners and of the slab tests cut to it.
    pub fn widened_within(&self, outer: &Aabb) -> Aabb {
        let pad = self.min.abs().max(self.max.abs()) * (4.0 * f32::EPSILON)
            + Vec3::splat(outer.extent().max_element() * 1e-5);
        Aabb::new(
            (self.min - pad).max(outer.min),
            (self.max + pad).min(outer.max),
        )
    }

    /// Parametric overlap of the ray with the box, clipped to `[t_min, t_max]`, or `None`.
    ///
    /// Conservative: `t_far` is enlarged by `1 + 2·gamma(3)` (pbrt-v4 §6.1.2) so that a ray
    /// grazing a face is never lost to rounding. Zero direction components give `±inf`
    /// reciprocals; a ray parallel to an axis' slab with its origin exactly on one of the
    /// slab's planes (`0·inf = NaN`) lies in the closed box's face: the whole line is inside
    /// that slab. (glam's `a < b ? a : b` minimum would take the NaN's partner, `+inf` on the
    /// low face, and drop the ray.)
    #[inline]
    pub fn intersect(&self, ray: &Ray, t_min: f32, t_max: f32) -> Option<(f32, f32)> {
        let t0 = (self.min - ray.origin) * ray.inv_dir;
        let t1 = (self.max - ray.origin) * ray.inv_dir;
        let in_face = t0.is_nan_mask() | t1.is_nan_mask();
        let t_near = Vec3::select(in_face, Vec3::NEG_INFINITY, t0.min(t1));
        let t_far = Vec3::select(
            in_face,
            Vec3::INFINITY,
            t0.max(t1) * (1.0 + 2.0 * float::gamma_f32(3)),
        );
        let lo = t_near.max_element().max(t_min);
        let hi = t_far.min_element().min(t_max);
        (lo <= hi).then_some((lo, hi))
    }
}

/// The union of the inclusive cell boxes `[lo, hi]` that `each` hands to its callback
/// (`None` when it hands none): the live cell box of a kd-tree or treelet walk from its
/// live nodes' boxes.
pub(crate) fn union_of_cell_boxes<T: Ord + Copy>(
    each: impl FnOnce(&mut dyn FnMut([[T; 3]; 2])),
) -> Option<[[T; 3]; 2]> {
    let mut union: Option<[[T; 3]; 2]> = None;
    each(&mut |[l, h]| {
        union = Some(match union {
            None => [l, h],
            Some([lo, hi]) => [
                std::array::from_fn(|a| lo[a].min(l[a])),
                std::array::from_fn(|a| hi[a].max(h[a])),
            ],
        });
    });
    union
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The union equals the per-axis min and max over random boxes, checked cell by cell:
    /// every cell of every box lies inside, and each face of the union touches a box.
    #[test]
    fn union_of_cell_boxes_is_the_smallest_box_holding_them() {
        let mut rng = rng::Rng::new(3);
        assert_eq!(union_of_cell_boxes::<u64>(|_| {}), None);
        for _ in 0..50 {
            let boxes: Vec<[[u64; 3]; 2]> = (0..=rng.index(5))
                .map(|_| {
                    let lo = [0; 3].map(|_: u64| u64::from(rng.below(20)));
                    [lo, lo.map(|x| x + u64::from(rng.below(6)))]
                })
                .collect();
            let [lo, hi] = union_of_cell_boxes(|f| boxes.iter().for_each(|&b| f(b))).unwrap();
            for [l, h] in &boxes {
                assert!((0..3).all(|a| lo[a] <= l[a] && h[a] <= hi[a]));
            }
            for a in 0..3 {
                assert!(boxes.iter().any(|b| b[0][a] == lo[a]));
                assert!(boxes.iter().any(|b| b[1][a] == hi[a]));
            }
        }
    }

    #[test]
    fn slab_test_handles_axis_parallel_and_grazing_rays() {
        let b = Aabb::new(Vec3::ZERO, Vec3::ONE);
        let r = Ray::new(Vec3::new(-1.0, 0.5, 0.5), Vec3::X);
        let (t0, t1) = b.intersect(&r, 0.0, f32::INFINITY).unwrap();
        assert!((t0 - 1.0).abs() < 1e-6 && (t1 - 2.0).abs() < 1e-6);
        // A ray lying exactly in a face plane still hits (closed box): high and low faces,
        // along and against the axis, and on an edge of two faces.
        for (o, d) in [
            (Vec3::new(-1.0, 1.0, 0.5), Vec3::X),
            (Vec3::new(-1.0, 0.0, 0.5), Vec3::X),
            (Vec3::new(2.0, 0.0, 0.5), -Vec3::X),
            (Vec3::new(0.5, 1.0, -1.0), Vec3::Z),
            (Vec3::new(-1.0, 0.0, 0.0), Vec3::X),
            (Vec3::new(0.0, 0.0, -1.0), Vec3::new(0.0, 0.0, 1.0)),
        ] {
            let graze = Ray::new(o, d);
            let (t0, t1) = b.intersect(&graze, 0.0, f32::INFINITY).expect("in a face");
            assert!(
                (t0 - 1.0).abs() < 1e-6 && (t1 - 2.0).abs() < 1e-5,
                "{o} {d}: {t0} {t1}"
            );
        }
        let miss = Ray::new(Vec3::new(-1.0, 1.5, 0.5), Vec3::X);
        assert!(b.intersect(&miss, 0.0, f32::INFINITY).is_none());
        assert!(b.intersect(&r, 0.0, 0.5).is_none());
    }
}
