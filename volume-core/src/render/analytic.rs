//! An exact analytic [`IsoScene`] for tests: the signed distance to a union of spheres.
//!
//! The field is `f(x) = min_k (|x − c_k| − r_k)`, so the isosurface at value `v` is the
//! boundary of the union of the spheres of radius `r_k + v` (concentric shells for one centre
//! and several isovalues). Hits are computed in f64 from the ray–sphere quadratic and are
//! exact to rounding, which makes this scene the truth for renderer tests (compositing,
//! shadows, clipping, camera) independent of any volume or intersector. The field only exists
//! inside `bounds`, like a volume's. Its live boxes are one per sphere and isovalue, so that
//! renderer tests run with the coverage mask on (`render::coverage`).

use glam::{DVec3, Vec3};

use crate::math::{Aabb, Ray};
use crate::render::scene::{Hit, IsoScene, Stats};

/// A union of spheres inside a box.
#[derive(Debug, Clone)]
pub struct SphereScene {
    /// `(centre, radius)` in world units.
    pub spheres: Vec<(Vec3, f32)>,
    pub bounds: Aabb,
}

impl SphereScene {
    /// One sphere field centred at `centre`: isovalue `v` is the sphere of radius `v`
    /// (radius 0 sphere, so `f(x) = |x − centre|`).
    pub fn distance_field(centre: Vec3, bounds: Aabb) -> Self {
        Self {
            spheres: vec![(centre, 0.0)],
            bounds,
        }
    }

    /// The field value at `p` (f64).
    pub fn value(&self, p: DVec3) -> f64 {
        self.spheres
            .iter()
            .map(|&(c, r)| (p - c.as_dvec3()).length() - f64::from(r))
            .fold(f64::INFINITY, f64::min)
    }

    /// All hits with any isovalue in `[t_min, t_max]` (inside `bounds`), sorted by `t`.
    pub fn all_hits(&self, ray: &Ray, t_min: f32, t_max: f32, isovalues: &[f32]) -> Vec<Hit> {
        let mut hits = Vec::new();
        self.for_each_hit(ray, t_min, t_max, isovalues, |h| hits.push(h));
        hits.sort_by(|a, b| a.t.total_cmp(&b.t));
        hits
    }

    fn for_each_hit(
        &self,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
        isovalues: &[f32],
        mut f: impl FnMut(Hit),
    ) {
        let Some((lo, hi)) = self.bounds.intersect(ray, t_min, t_max) else {
            return;
        };
        let (o, d) = (ray.origin.as_dvec3(), ray.dir.as_dvec3());
        let dd = d.length_squared();
        for (s, &iso) in isovalues.iter().enumerate() {
            for (k, &(c, r)) in self.spheres.iter().enumerate() {
                let radius = f64::from(r) + f64::from(iso);
                if radius <= 0.0 {
                    continue;
                }
                let c = c.as_dvec3();
                let oc = o - c;
                // |oc + t·d|² = radius², solved with the numerically stable form.
                let b = oc.dot(d);
                let disc = b * b - dd * (oc.length_squared() - radius * radius);
                if disc < 0.0 {
                    continue;
                }
                let q = -(b + b.signum() * disc.sqrt());
                let roots = if q == 0.0 {
                    [0.0, 0.0]
                } else {
                    [q / dd, (oc.length_squared() - radius * radius) / q]
                };
                for t in roots {
                    let tf = t as f32;
                    if !(tf >= lo && tf <= hi) {
                        continue;
                    }
                    let p = o + d * t;
                    // On the union's boundary only if no other sphere strictly contains p.
                    let buried = self.spheres.iter().enumerate().any(|(j, &(cj, rj))| {
                        j != k
                            && (p - cj.as_dvec3()).length() < f64::from(rj) + f64::from(iso) - 1e-9
                    });
                    if buried {
                        continue;
                    }
                    f(Hit {
                        t: tf,
                        surface: s as u32,
                        normal: ((p - c) / radius).as_vec3(),
                        cell: k as u32,
                    });
                }
            }
        }
    }
}

impl IsoScene for SphereScene {
    type Isovalues = Vec<f32>;

    fn prepare(&self, isovalues: &[f32]) -> Vec<f32> {
        isovalues.to_vec()
    }

    fn world_bounds(&self) -> Aabb {
        self.bounds
    }

    /// The box around each shell (a sphere grown by an isovalue), padded by a relative 1e-4
    /// so that rounding of a hit on its edge stays inside.
    fn live_boxes(&self, isovalues: &Vec<f32>, out: &mut Vec<Aabb>) {
        for &iso in isovalues {
            for &(c, r) in &self.spheres {
                let radius = r + iso;
                if radius > 0.0 {
                    let half = Vec3::splat(radius * (1.0 + 1e-4));
                    out.push(Aabb::new(c - half, c + half));
                }
            }
        }
    }

    fn first_hit_prepared<S: Stats>(
        &self,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
        isovalues: &Vec<f32>,
        stats: &mut S,
    ) -> Option<Hit> {
        stats.ray();
        let mut best: Option<Hit> = None;
        self.for_each_hit(ray, t_min, t_max, isovalues, |h| {
            stats.intersection();
            if best.is_none_or(|b| h.t < b.t) {
                best = Some(h);
            }
        });
        best
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::scene::NoStats;

    #[test]
    fn concentric_shells_are_hit_in_order() {
        let scene =
            SphereScene::distance_field(Vec3::ZERO, Aabb::new(Vec3::splat(-3.0), Vec3::splat(3.0)));
        let ray = Ray::new(Vec3::new(0.0, 0.0, 10.0), Vec3::NEG_Z);
        let hits = scene.all_hits(&ray, 0.0, f32::INFINITY, &[2.0, 1.0]);
        let ts: Vec<f32> = hits.iter().map(|h| h.t).collect();
        assert_eq!(ts, vec![8.0, 9.0, 11.0, 12.0]);
        assert_eq!(hits[0].surface, 0);
        assert_eq!(hits[1].surface, 1);
        let first = scene
            .first_hit(&ray, 8.5, f32::INFINITY, &[2.0, 1.0], &mut NoStats)
            .unwrap();
        assert_eq!(first.t, 9.0);
        assert!((first.normal - Vec3::Z).length() < 1e-6);
        // Outside the bounds there is no field.
        assert!(
            scene
                .first_hit(&ray, 0.0, f32::INFINITY, &[5.0], &mut NoStats)
                .is_none()
        );
    }

    #[test]
    fn union_hides_buried_surfaces() {
        let scene = SphereScene {
            spheres: vec![(Vec3::ZERO, 1.0), (Vec3::new(1.0, 0.0, 0.0), 1.0)],
            bounds: Aabb::new(Vec3::splat(-5.0), Vec3::splat(5.0)),
        };
        let ray = Ray::new(Vec3::new(-4.0, 0.0, 0.0), Vec3::X);
        let ts: Vec<f32> = scene
            .all_hits(&ray, 0.0, f32::INFINITY, &[0.0])
            .iter()
            .map(|h| h.t)
            .collect();
        assert_eq!(ts, vec![3.0, 6.0]);
        assert!((scene.value(DVec3::new(0.5, 0.0, 0.0)) + 0.5).abs() < 1e-12);
    }
}
