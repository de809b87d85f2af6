//! 8-wide kernels of the large-packet traversal (thesis 004 §8.2.2, §8.4.2): ray–box slab
//! tests and the watertight ray–isopolygon test for eight rays at once, on `wide::f32x8`
//! (AVX when enabled at compile time, SSE pairs otherwise; no `unsafe`).
//!
//! Every lane performs exactly the operations of the scalar slab test
//! (`traverse::slab`) and of [`super::mt::intersect`], in the same order, and Rust never
//! contracts `a * b + c` into a fused multiply-add: lane results are bit-identical to the
//! scalar ones, so packets and single rays agree on every hit, shared edges included. Edge
//! functions that round to zero are recomputed in `f64` lane by lane, as in the scalar test.
//!
//! A [`RayBlock`] holds eight rays in SoA form. The isopolygon test needs the eight rays to
//! share the permutation of the watertight ray space (the same dominant direction axis);
//! blocks that do not are traced with the scalar test ([`RayBlock::uniform`] is false).
//! Padding lanes copy lane 0 (neutral for frustum bounds) and have `t0 = +inf`: they never
//! report a hit.

use glam::Vec3;
use wide::f32x8;

use super::bvh::BvhNode;
use super::mt::IsoPoly;
use crate::math::{Ray, float::gamma_f32};

/// Rays per block.
pub(crate) const LANES: usize = 8;

/// Eight rays in SoA form (module docs).
#[derive(Clone, Copy)]
pub(crate) struct RayBlock {
    pub(crate) o: [f32x8; 3],
    pub(crate) inv: [f32x8; 3],
    pub(crate) t0: f32x8,
    /// Shared ray-space axes `kx, ky, kz` (valid when `uniform`).
    pub(crate) k: [usize; 3],
    /// Shears `sx, sy, sz` per lane.
    pub(crate) s: [f32x8; 3],
    /// All lanes valid for the watertight test with the same axes.
    pub(crate) uniform: bool,
}

impl RayBlock {
    pub(crate) const EMPTY: RayBlock = RayBlock {
        o: [f32x8::ZERO; 3],
        inv: [f32x8::ZERO; 3],
        t0: f32x8::INFINITY,
        k: [0, 1, 2],
        s: [f32x8::ZERO; 3],
        uniform: false,
    };

    /// The block of `rays` (1 to 8 of them) and their `t_min`, ray space included.
    #[cfg(test)]
    pub(crate) fn new(rays: &[Ray], t_min: &[f32]) -> Self {
        let mut b = Self::base(rays, t_min);
        b.prepare_space(rays);
        b
    }

    /// Origins, reciprocal directions and `t0` only: enough for box and frustum tests;
    /// `uniform` stays false until [`RayBlock::prepare_space`].
    #[inline]
    pub(crate) fn base(rays: &[Ray], t_min: &[f32]) -> Self {
        let n = rays.len().min(LANES);
        debug_assert!(n > 0 && t_min.len() >= n);
        let mut f = [[0f32; LANES]; 7];
        for l in 0..LANES {
            let r = &rays[if l < n { l } else { 0 }];
            f[0][l] = r.origin.x;
            f[1][l] = r.origin.y;
            f[2][l] = r.origin.z;
            f[3][l] = r.inv_dir.x;
            f[4][l] = r.inv_dir.y;
            f[5][l] = r.inv_dir.z;
            f[6][l] = if l < n { t_min[l] } else { f32::INFINITY };
        }
        let v = f.map(f32x8::new);
        Self {
            o: [v[0], v[1], v[2]],
            inv: [v[3], v[4], v[5]],
            t0: v[6],
            ..Self::EMPTY
        }
    }

    /// The watertight ray space of the block's `rays` (the same rays as in
    /// [`RayBlock::base`]): [`super::mt::RaySpace::new`] computed 8 lanes at a time (same
    /// operations, same bits). Only the isopolygon test needs it.
    #[inline]
    pub(crate) fn prepare_space(&mut self, rays: &[Ray]) {
        let n = rays.len().min(LANES);
        debug_assert!(n > 0);
        let mut f = [[0f32; LANES]; 3];
        for l in 0..LANES {
            let r = &rays[if l < n { l } else { 0 }];
            f[0][l] = r.dir.x;
            f[1][l] = r.dir.y;
            f[2][l] = r.dir.z;
        }
        let d = f.map(f32x8::new);
        // Dominant axis per lane with the tie-breaking of `RaySpace::new`.
        let a = d.map(f32x8::abs);
        let x_dom = (a[0].simd_ge(a[1]) & a[0].simd_ge(a[2])).to_bitmask();
        let y_ge_z = a[1].simd_ge(a[2]).to_bitmask();
        let lane_axis = [x_dom, !x_dom & y_ge_z, !x_dom & !y_ge_z];
        let kz = if x_dom & 1 != 0 {
            0
        } else if y_ge_z & 1 != 0 {
            1
        } else {
            2
        };
        let (kx, ky) = ((kz + 1) % 3, (kz + 2) % 3);
        let dz = d[kz];
        let o = self.o;
        let finite = d[0].is_finite() & d[1].is_finite() & d[2].is_finite();
        let finite = finite & o[0].is_finite() & o[1].is_finite() & o[2].is_finite();
        let valid = finite.to_bitmask() & !dz.simd_eq(f32x8::ZERO).to_bitmask();
        let all = (1u32 << LANES) - 1;
        self.k = [kx, ky, kz];
        self.s = [d[kx] / dz, d[ky] / dz, f32x8::ONE / dz];
        self.uniform = lane_axis[kz] & all == all && valid & all == all;
    }
}

/// Lanes (bit `i` for lane `i`) whose `[t0, t1]` meets the node's box: the scalar slab test
/// of `traverse`, lane by lane.
#[inline]
pub(crate) fn slab8(n: &BvhNode, b: &RayBlock, t1: f32x8) -> u32 {
    let widen = f32x8::splat(1.0 + 2.0 * gamma_f32(3));
    let (lo, hi) = (n.lo.to_array(), n.hi.to_array());
    let mut near = [f32x8::ZERO; 3];
    let mut far = [f32x8::ZERO; 3];
    for a in 0..3 {
        let ta = (f32x8::splat(lo[a]) - b.o[a]) * b.inv[a];
        let tb = (f32x8::splat(hi[a]) - b.o[a]) * b.inv[a];
        near[a] = ta.min(tb);
        far[a] = ta.max(tb) * widen;
    }
    let enter = near[0].max(near[1]).max(near[2]).max(b.t0);
    let exit = far[0].min(far[1]).min(far[2]).min(t1);
    enter.simd_le(exit).to_bitmask()
}

/// A vertex in the block's ray space: `(x, y)` across each ray, `z` its depth parameter.
#[derive(Clone, Copy)]
struct V8 {
    x: f32x8,
    y: f32x8,
    z: f32x8,
}

#[inline]
fn transform(b: &RayBlock, p: Vec3) -> V8 {
    let p = p.to_array();
    let [kx, ky, kz] = b.k;
    let ax = f32x8::splat(p[kx]) - b.o[kx];
    let ay = f32x8::splat(p[ky]) - b.o[ky];
    let az = f32x8::splat(p[kz]) - b.o[kz];
    V8 {
        x: ax - b.s[0] * az,
        y: ay - b.s[1] * az,
        z: b.s[2] * az,
    }
}

/// Edge function `a × b` per lane in `f32` (zero lanes are fixed by [`exact_zeros`]).
#[inline]
fn edge(a: V8, b: V8) -> f32x8 {
    a.x * b.y - a.y * b.x
}

/// The edge function `e = a × b` exact in sign: lanes that round to zero recomputed in
/// `f64`.
#[inline]
fn exact_zeros(e: f32x8, a: V8, b: V8) -> f32x8 {
    let zero = e.simd_eq(f32x8::ZERO).to_bitmask();
    if zero == 0 {
        return e;
    }
    let (ax, ay, bx, by) = (
        a.x.to_array(),
        a.y.to_array(),
        b.x.to_array(),
        b.y.to_array(),
    );
    let mut out = e.to_array();
    let mut m = zero;
    while m != 0 {
        let l = m.trailing_zeros() as usize;
        m &= m - 1;
        out[l] = (f64::from(ax[l]) * f64::from(by[l]) - f64::from(ay[l]) * f64::from(bx[l])) as f32;
    }
    f32x8::new(out)
}

/// Watertight ray–triangle test per lane: ray parameters and the lanes that hit.
// Always inlined, as `poly8`: as calls they passed their 96-byte vertex blocks through the
// stack (about 3 % of a frame's instructions).
#[inline(always)]
fn tri(a: V8, b: V8, c: V8) -> (f32x8, u32) {
    let (mut u, mut v, mut w) = (edge(b, c), edge(c, a), edge(a, b));
    let z = f32x8::ZERO;
    // One test for the three edges' rare zero lanes.
    if (u.simd_eq(z) | v.simd_eq(z) | w.simd_eq(z)).any() {
        (u, v, w) = (
            exact_zeros(u, b, c),
            exact_zeros(v, c, a),
            exact_zeros(w, a, b),
        );
    }
    let neg = (u.simd_lt(z) | v.simd_lt(z) | w.simd_lt(z)).to_bitmask();
    let pos = (u.simd_gt(z) | v.simd_gt(z) | w.simd_gt(z)).to_bitmask();
    if (neg & pos) & 0xff == 0xff {
        // Every lane passes beside the triangle (most calls: a polygon is about a pixel):
        // no lane's distance is read, so skip the division.
        return (z, 0);
    }
    let det = u + v + w;
    let bad_det = (det.simd_eq(z).to_bitmask()) | !det.is_finite().to_bitmask();
    let t = (u * a.z + v * b.z + w * c.z) / det;
    let ok = !(neg & pos) & !bad_det & t.is_finite().to_bitmask() & 0xff;
    (t, ok)
}

/// The isopolygon test for a uniform block: ray parameters and the lanes whose hit lies in
/// `[t0, t1]` (same result per lane as [`super::mt::intersect`] and the interval check).
#[inline(always)]
pub(crate) fn poly8(b: &RayBlock, poly: &IsoPoly, t1: f32x8) -> (f32x8, u32) {
    debug_assert!(b.uniform);
    let a = transform(b, poly.v[0]);
    let bb = transform(b, poly.v[1]);
    let c = transform(b, poly.v[2]);
    let (t, m) = if poly.count == 3 {
        tri(a, bb, c)
    } else {
        let d = transform(b, poly.v[3]);
        let (ta, ma) = tri(a, bb, c);
        let (tb, mb) = tri(a, c, d);
        // Both halves hit (rounding at the diagonal): the nearer, as the scalar test.
        let both = ma & mb;
        let t = if mb == 0 {
            ta
        } else if ma == 0 {
            tb
        } else {
            let sel = f32x8::new(std::array::from_fn(|l| {
                if ma >> l & 1 != 0 {
                    if both >> l & 1 != 0 { -1.0 } else { 1.0 }
                } else {
                    0.0
                }
            }));
            // sel < 0: both, > 0: only a, == 0: only b (or neither).
            let mn = ta.min(tb);
            sel.simd_lt(f32x8::ZERO)
                .select(mn, sel.simd_gt(f32x8::ZERO).select(ta, tb))
        };
        (t, ma | mb)
    };
    let range = (t.simd_ge(b.t0) & t.simd_le(t1)).to_bitmask();
    (t, m & range)
}

#[cfg(test)]
mod tests {
    use glam::{Vec3, Vec4};

    use super::*;
    use crate::math::rng::Rng;
    use crate::tet::mt;
    use crate::tet::traverse::slab;

    fn block_of(rays: &[Ray], t0: &[f32], t1: &[f32]) -> (RayBlock, f32x8) {
        let b = RayBlock::new(rays, t0);
        let t1 = f32x8::new(std::array::from_fn(|l| {
            if l < rays.len() {
                t1[l]
            } else {
                f32::NEG_INFINITY
            }
        }));
        (b, t1)
    }

    #[test]
    fn slab8_equals_the_scalar_slab_lane_by_lane() {
        let mut rng = Rng::new(7);
        let mut hits = 0;
        for trial in 0..3000 {
            let lo = rng.vec3(-2.0, 1.0);
            let mut hi = lo + rng.vec3(0.0, 2.0);
            if trial % 7 == 0 {
                hi.y = lo.y; // flat box
            }
            let node = BvhNode {
                lo: lo.extend(0.0),
                hi: hi.extend(1.0),
                link: 0,
                count: 1,
                axis: 0,
                end: 1,
            };
            let n = 1 + trial % 8;
            let rays: Vec<Ray> = (0..n)
                .map(|i| {
                    let mut d = rng.vec3(-1.0, 1.0);
                    if (trial + i) % 5 == 0 {
                        d.x = 0.0; // infinite reciprocal
                    }
                    Ray::new(rng.vec3(-4.0, 4.0), d)
                })
                .collect();
            let t0: Vec<f32> = (0..n).map(|_| rng.range_f32(-1.0, 2.0)).collect();
            let t1: Vec<f32> = (0..n)
                .map(|i| {
                    if i % 3 == 0 {
                        f32::INFINITY
                    } else {
                        rng.range_f32(0.0, 6.0)
                    }
                })
                .collect();
            let (b, t1v) = block_of(&rays, &t0, &t1);
            let m = slab8(&node, &b, t1v);
            for l in 0..8 {
                let want = l < n && slab(&node, &rays[l], t0[l], t1[l]);
                assert_eq!(m >> l & 1 == 1, want, "trial {trial} lane {l}");
                hits += usize::from(want);
            }
        }
        assert!(hits > 50, "{hits}");
    }

    /// Polygons of random tets and of an integer tet (exact zero edge functions), rays from
    /// one origin through random points, vertices and edge midpoints; and blocks whose
    /// rays all pass beside the polygon (the early out of `tri`).
    #[test]
    fn poly8_equals_the_scalar_isopolygon_test_lane_by_lane() {
        let mut rng = Rng::new(11);
        let (mut hits, mut uniform, mut all_miss) = (0, 0, 0);
        for trial in 0..3000 {
            let integer = trial % 4 == 0;
            let v: [Vec4; 4] = if integer {
                [
                    Vec4::new(0.0, 0.0, 0.0, 0.0),
                    Vec4::new(2.0, 0.0, 0.0, 1.0),
                    Vec4::new(0.0, 2.0, 0.0, 1.0),
                    Vec4::new(0.0, 0.0, 2.0, 2.0),
                ]
            } else {
                std::array::from_fn(|_| rng.vec3(-1.0, 1.0).extend(rng.range_f32(0.0, 1.0)))
            };
            let c = if integer {
                0.5 + 0.5 * (trial % 3) as f32
            } else {
                0.5
            };
            let Some(poly) = mt::extract(&v, &[0, 1, 2, 3], c) else {
                continue;
            };
            let k = poly.count as usize;
            let origin = if integer {
                Vec3::new(0.0, 0.0, -4.0 - (trial % 3) as f32)
            } else {
                rng.vec3(-1.0, 1.0) + Vec3::new(0.0, 0.0, -5.0)
            };
            // Every fifth random polygon: all rays aimed beside it.
            let beside = if !integer && trial % 5 == 3 {
                Vec3::new(3.0, -3.0, 0.0)
            } else {
                Vec3::ZERO
            };
            let rays: Vec<Ray> = (0..8)
                .map(|i| {
                    let target = beside
                        + match i % 4 {
                            0 => poly.v[i / 4 % k],
                            1 => (poly.v[i % k] + poly.v[(i + 1) % k]) * 0.5,
                            _ => poly.v[0] + rng.vec3(-0.5, 0.5),
                        };
                    if integer && i == 7 {
                        // Axis-aligned ray exactly through a vertex.
                        let p = poly.v[trial / 4 % k];
                        return Ray::new(Vec3::new(p.x, p.y, -3.0), Vec3::Z);
                    }
                    Ray::new(origin, target - origin)
                })
                .collect();
            let t0 = [0.0f32; 8];
            let t1: Vec<f32> = (0..8)
                .map(|i| if i == 5 { 4.0 } else { f32::INFINITY })
                .collect();
            let (b, t1v) = block_of(&rays, &t0, &t1);
            if !b.uniform {
                continue;
            }
            uniform += 1;
            let (t, m) = poly8(&b, &poly, t1v);
            all_miss += usize::from(beside != Vec3::ZERO && m == 0);
            let t = t.to_array();
            for l in 0..8 {
                let want = mt::intersect(&mt::RaySpace::new(rays[l].origin, rays[l].dir), &poly)
                    .filter(|&x| x >= t0[l] && x <= t1[l]);
                assert_eq!(m >> l & 1 == 1, want.is_some(), "trial {trial} lane {l}");
                if let Some(x) = want {
                    assert_eq!(t[l].to_bits(), x.to_bits(), "trial {trial} lane {l}");
                    hits += 1;
                }
            }
        }
        assert!(
            uniform > 1000 && hits > 3000 && all_miss > 200,
            "{uniform} blocks, {hits} hits, {all_miss} blocks beside"
        );
    }
}
