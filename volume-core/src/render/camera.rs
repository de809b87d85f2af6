//! Cameras: pinhole (vertical field of view) and orthographic, and their primary rays.
//!
//! Pixel `(i, j)`, row 0 at the top, of a `W×H` image gets the ray through its centre:
//! `u = (2(i+0.5)/W − 1)·tan(vfov/2)·W/H`, `v = (1 − 2(j+0.5)/H)·tan(vfov/2)`, direction
//! `normalize(forward + u·right + v·up)`. Directions are unit length, so
//! the ray parameter `t` is a world distance. Orthographic cameras use the same `u, v` with
//! `tan(vfov/2)` replaced by `ortho_height/2` as offsets of the ray origin from the eye.
//!
//! Cameras are stored as JSON (`--camera cam.json`, GUI bookmarks):
//! `{"eye":[x,y,z],"target":[x,y,z],"up":[x,y,z],"vfov_deg":40,"projection":"pinhole"}`;
//! unknown fields are ignored, `up`, `vfov_deg` and `projection` have defaults.

use glam::Vec3;
use serde::{Deserialize, Serialize};
use thiserror::Error;
use wide::f32x8;

use crate::math::{Aabb, Ray, float::gamma_f32};

/// How rays leave the camera.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Projection {
    /// All rays start at the eye; the image spans the vertical field of view `vfov_deg`.
    #[default]
    #[serde(alias = "perspective")]
    Pinhole,
    /// Parallel rays along the view direction; the image spans `ortho_height` world units.
    #[serde(alias = "ortho")]
    Orthographic,
}

/// A camera in world units.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Camera {
    pub eye: Vec3,
    pub target: Vec3,
    #[serde(default = "default_up")]
    pub up: Vec3,
    /// Vertical field of view in degrees (pinhole), in `(0, 180)`.
    #[serde(default = "default_vfov")]
    pub vfov_deg: f32,
    #[serde(default)]
    pub projection: Projection,
    /// Height of the orthographic view in world units. When absent, the height that the
    /// pinhole view has at the target distance: `2·|target − eye|·tan(vfov/2)`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ortho_height: Option<f32>,
}

fn default_up() -> Vec3 {
    Vec3::Z
}

fn default_vfov() -> f32 {
    40.0
}

/// Why a camera cannot produce rays.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum CameraError {
    #[error("camera {field} {value:?} is not finite")]
    NotFinite {
        field: &'static str,
        value: [f32; 3],
    },
    #[error("camera eye and target coincide at {0:?}")]
    EyeIsTarget([f32; 3]),
    #[error("camera up {up:?} is zero or parallel to the view direction {forward:?}")]
    BadUp { up: [f32; 3], forward: [f32; 3] },
    #[error("camera vfov_deg {0} is outside (0, 180)")]
    BadFov(f32),
    #[error("camera ortho_height {0} must be finite and positive")]
    BadOrthoHeight(f32),
    #[error("image size {width}x{height} must be at least 1x1")]
    EmptyImage { width: u32, height: u32 },
}

impl Camera {
    /// A pinhole camera on a sphere around the centre of `bounds`, looking at the centre with
    /// `+z` up, far enough away that the bounding sphere fits in the vertical field of view
    /// (and the horizontal one for images at least as wide as tall).
    ///
    /// Azimuth is measured in the xy plane from `+x` towards `+y`; elevation from the xy plane
    /// towards `+z`, clamped to ±89.5° so that `up` never becomes parallel to the view.
    pub fn orbit(bounds: &Aabb, azimuth_deg: f32, elevation_deg: f32, vfov_deg: f32) -> Camera {
        let (centre, radius) = if bounds.is_empty() || !bounds.extent().is_finite() {
            (Vec3::ZERO, 1.0)
        } else {
            (bounds.center(), (bounds.extent().length() * 0.5).max(1e-6))
        };
        let vfov = if vfov_deg.is_finite() && vfov_deg > 0.0 && vfov_deg < 180.0 {
            vfov_deg
        } else {
            default_vfov()
        };
        let (az, el) = (
            azimuth_deg.to_radians(),
            elevation_deg.clamp(-89.5, 89.5).to_radians(),
        );
        let offset = Vec3::new(el.cos() * az.cos(), el.cos() * az.sin(), el.sin());
        // 5 % margin so that the silhouette does not touch the image border.
        let distance = 1.05 * radius / (0.5 * vfov.to_radians()).sin();
        Camera {
            eye: centre + offset * distance,
            target: centre,
            up: Vec3::Z,
            vfov_deg: vfov,
            projection: Projection::Pinhole,
            ortho_height: None,
        }
    }

    /// [`Camera::orbit`] moved in as close as the view allows: every corner of `bounds`
    /// projects inside an image of `aspect` = width / height with a 5 % margin, so the data
    /// fills the frame from any direction (the bounding sphere of a box leaves the box a
    /// third of the frame or less). For each corner `q` (from the centre) in the view basis
    /// `(x, y, z)`, `z` towards the eye, its depth at eye distance `D` is `D − z`, and it is
    /// in the frame when `|y| ≤ tan(vfov/2)·(D − z)/1.05` and `|x| ≤ aspect·tan(vfov/2)·(D −
    /// z)/1.05`: `D` is the largest bound these give.
    pub fn orbit_framed(
        bounds: &Aabb,
        azimuth_deg: f32,
        elevation_deg: f32,
        vfov_deg: f32,
        aspect: f32,
    ) -> Camera {
        let sphere = Camera::orbit(bounds, azimuth_deg, elevation_deg, vfov_deg);
        if bounds.is_empty()
            || !bounds.extent().is_finite()
            || !(aspect.is_finite() && aspect > 0.0)
        {
            return sphere;
        }
        let (right, up, forward) = sphere.basis();
        let toward_eye = -forward;
        let tan_v = (0.5 * sphere.vfov_deg.to_radians()).tan();
        let tan_h = tan_v * aspect;
        let centre = bounds.center();
        let mut distance = 0.0f32;
        let mut nearest = f32::NEG_INFINITY;
        for i in 0..8 {
            let corner = Vec3::new(
                if i & 1 == 0 {
                    bounds.min.x
                } else {
                    bounds.max.x
                },
                if i & 2 == 0 {
                    bounds.min.y
                } else {
                    bounds.max.y
                },
                if i & 4 == 0 {
                    bounds.min.z
                } else {
                    bounds.max.z
                },
            );
            let q = corner - centre;
            let (x, y, z) = (q.dot(right), q.dot(up), q.dot(toward_eye));
            nearest = nearest.max(z);
            distance = distance
                .max(z + 1.05 * y.abs() / tan_v)
                .max(z + 1.05 * x.abs() / tan_h);
        }
        // Never on the box: a flat box seen edge-on would otherwise put the eye on its edge.
        let clearance = 1e-3 * bounds.extent().length().max(1e-6);
        Camera {
            eye: centre + toward_eye * distance.max(nearest + clearance),
            ..sphere
        }
    }

    /// Checks that the camera defines an orthonormal view basis.
    pub fn validate(&self) -> Result<(), CameraError> {
        for (field, v) in [("eye", self.eye), ("target", self.target), ("up", self.up)] {
            if !v.is_finite() {
                return Err(CameraError::NotFinite {
                    field,
                    value: v.to_array(),
                });
            }
        }
        let forward = self.target - self.eye;
        if forward.length_squared() == 0.0 || !forward.normalize_or_zero().is_finite() {
            return Err(CameraError::EyeIsTarget(self.eye.to_array()));
        }
        let forward = forward.normalize();
        if forward.cross(self.up).length_squared() <= 1e-12 * self.up.length_squared()
            || self.up.length_squared() == 0.0
        {
            return Err(CameraError::BadUp {
                up: self.up.to_array(),
                forward: forward.to_array(),
            });
        }
        if !(self.vfov_deg > 0.0 && self.vfov_deg < 180.0) {
            return Err(CameraError::BadFov(self.vfov_deg));
        }
        if let Some(h) = self.ortho_height
            && !(h.is_finite() && h > 0.0)
        {
            return Err(CameraError::BadOrthoHeight(h));
        }
        Ok(())
    }

    /// Right, up and forward unit vectors (right-handed: `right = forward × up`).
    ///
    /// Never panics: a degenerate camera (see [`Camera::validate`]) falls back to looking
    /// along `−z` and/or an arbitrary perpendicular `up`, so check `validate` first.
    pub fn basis(&self) -> (Vec3, Vec3, Vec3) {
        let forward = (self.target - self.eye)
            .try_normalize()
            .unwrap_or(Vec3::NEG_Z);
        let right = forward
            .cross(self.up)
            .try_normalize()
            .unwrap_or_else(|| forward.any_orthonormal_vector());
        let up = right.cross(forward);
        (right, up, forward)
    }

    /// Half the image height: `tan(vfov/2)` at unit distance (pinhole) or in world units
    /// (orthographic).
    pub fn half_height(&self) -> f32 {
        match self.projection {
            Projection::Pinhole => (0.5 * self.vfov_deg.to_radians()).tan(),
            Projection::Orthographic => {
                let h = self.ortho_height.unwrap_or_else(|| {
                    2.0 * (self.target - self.eye).length()
                        * (0.5 * self.vfov_deg.to_radians()).tan()
                });
                0.5 * h
            }
        }
    }

    /// The ray through the centre of pixel `(i, j)` of a `width × height` image, row 0 at the
    /// top. See the module docs for the formula.
    pub fn primary_ray(&self, i: u32, j: u32, width: u32, height: u32) -> Ray {
        RayGen::new(self, width, height).ray_at(i as f32 + 0.5, j as f32 + 0.5)
    }
}

/// A camera prepared for one image size: the basis and scale factors computed once, so that
/// generating a ray costs a handful of multiply-adds.
#[derive(Debug, Clone, Copy)]
pub struct RayGen {
    eye: Vec3,
    right: Vec3,
    up: Vec3,
    forward: Vec3,
    /// `2/W` and `2/H`.
    inv_w2: f32,
    inv_h2: f32,
    /// `half_height · W/H` and `half_height`.
    scale_u: f32,
    scale_v: f32,
    orthographic: bool,
}

impl RayGen {
    /// Prepares `camera` for a `width × height` image (sizes of 0 are treated as 1).
    pub fn new(camera: &Camera, width: u32, height: u32) -> Self {
        let (w, h) = (width.max(1) as f32, height.max(1) as f32);
        let (right, up, forward) = camera.basis();
        let half = camera.half_height();
        Self {
            eye: camera.eye,
            right,
            up,
            forward,
            inv_w2: 2.0 / w,
            inv_h2: 2.0 / h,
            scale_u: half * w / h,
            scale_v: half,
            orthographic: camera.projection == Projection::Orthographic,
        }
    }

    /// The ray through continuous pixel position `(x, y)` (pixel `(i, j)` spans
    /// `[i, i+1) × [j, j+1)`, so its centre is `(i + 0.5, j + 0.5)`).
    #[inline]
    pub fn ray_at(&self, x: f32, y: f32) -> Ray {
        self.ray_from(self.column(x), self.row(y))
    }

    /// The part of [`RayGen::ray_at`] that depends on `x` only: `forward + u·right`
    /// (pinhole) or `eye + u·right` (orthographic). The renderer computes it once per tile
    /// column; [`RayGen::ray_from`] finishes the ray with the same operations in the same
    /// order, so the ray is bit-identical to `ray_at`'s.
    #[inline]
    pub(crate) fn column(&self, x: f32) -> Vec3 {
        let u = (x * self.inv_w2 - 1.0) * self.scale_u;
        let base = if self.orthographic {
            self.eye
        } else {
            self.forward
        };
        base + self.right * u
    }

    /// The part of [`RayGen::ray_at`] that depends on `y` only: `v·up`.
    #[inline]
    pub(crate) fn row(&self, y: f32) -> Vec3 {
        let v = (1.0 - y * self.inv_h2) * self.scale_v;
        self.up * v
    }

    /// The ray from a [`RayGen::column`] and a [`RayGen::row`] term.
    #[inline]
    pub(crate) fn ray_from(&self, column: Vec3, row: Vec3) -> Ray {
        if self.orthographic {
            Ray::new(column + row, self.forward)
        } else {
            Ray::new(self.eye, (column + row).normalize())
        }
    }

    /// `out[i] = ray_from(columns[i], row)` for all 16 columns, 8 rays at a time (pinhole:
    /// the normalize and the reciprocals are most of a ray's cost), and where each ray meets
    /// `bounds`: bit `i` of the result is set when `bounds.intersect(&out[i], 0, inf)` is
    /// `Some((lo[i], hi[i]))`. The same IEEE operations in the same order as the scalar
    /// paths (glam's `a < b ? a : b` minimum is `minps(a, b)`, i.e. `f32x8::fast_min`), so
    /// rays and ranges are bit-identical to [`RayGen::ray_at`] and [`Aabb::intersect`].
    pub(crate) fn rays_row_in(
        &self,
        columns: &[Vec3; 16],
        row: Vec3,
        bounds: &Aabb,
        out: &mut [Ray; 16],
        lo: &mut [f32; 16],
        hi: &mut [f32; 16],
    ) -> u32 {
        let mut meets = 0u32;
        if self.orthographic {
            for (i, (o, &c)) in out.iter_mut().zip(columns).enumerate() {
                *o = self.ray_from(c, row);
                if let Some((a, b)) = bounds.intersect(o, 0.0, f32::INFINITY) {
                    (lo[i], hi[i]) = (a, b);
                    meets |= 1 << i;
                }
            }
            return meets;
        }
        let one = f32x8::splat(1.0);
        let widen = f32x8::splat(1.0 + 2.0 * gamma_f32(3));
        // `Aabb::intersect` per axis: `(min - eye) · inv`, `(max - eye) · inv`, glam's
        // component-wise min/max (`minps`/`maxps` operand order), `· widen` on the far side;
        // a NaN (a ray in a face plane) opens the slab to the whole line.
        let slab = |min: f32, max: f32, eye: f32, inv: f32x8| {
            let t0 = f32x8::splat(min - eye) * inv;
            let t1 = f32x8::splat(max - eye) * inv;
            let in_face = t0.is_nan() | t1.is_nan();
            (
                in_face.select(f32x8::splat(f32::NEG_INFINITY), t0.fast_min(t1)),
                in_face.select(f32x8::splat(f32::INFINITY), t0.fast_max(t1) * widen),
            )
        };
        for half in 0..2 {
            let cols = &columns[8 * half..8 * half + 8];
            let lane = |f: fn(&Vec3) -> f32| f32x8::from(std::array::from_fn(|i| f(&cols[i])));
            // (column + row), then glam's normalize: v · (1 / sqrt(x·x + y·y + z·z)).
            let x = lane(|v| v.x) + f32x8::splat(row.x);
            let y = lane(|v| v.y) + f32x8::splat(row.y);
            let z = lane(|v| v.z) + f32x8::splat(row.z);
            let len_recip = one / (x * x + y * y + z * z).sqrt();
            let (x, y, z) = (x * len_recip, y * len_recip, z * len_recip);
            let (ix, iy, iz) = (one / x, one / y, one / z);
            let (nx, fx) = slab(bounds.min.x, bounds.max.x, self.eye.x, ix);
            let (ny, fy) = slab(bounds.min.y, bounds.max.y, self.eye.y, iy);
            let (nz, fz) = slab(bounds.min.z, bounds.max.z, self.eye.z, iz);
            // glam's `max_element`/`min_element`: max(max(x, y), z) with `a > b ? a : b`.
            let near = nx.fast_max(ny).fast_max(nz).to_array();
            let far = fx.fast_min(fy).fast_min(fz).to_array();
            let (x, y, z) = (x.to_array(), y.to_array(), z.to_array());
            let (ix, iy, iz) = (ix.to_array(), iy.to_array(), iz.to_array());
            for (i, o) in out[8 * half..8 * half + 8].iter_mut().enumerate() {
                *o = Ray {
                    origin: self.eye,
                    dir: Vec3::new(x[i], y[i], z[i]),
                    inv_dir: Vec3::new(ix[i], iy[i], iz[i]),
                };
                // The clip to `[0, inf]` with `f32::max`/`min`, as `Aabb::intersect`.
                let (a, b) = (near[i].max(0.0), far[i].min(f32::INFINITY));
                let k = 8 * half + i;
                (lo[k], hi[k]) = (a, b);
                meets |= u32::from(a <= b) << k;
            }
        }
        meets
    }

    /// Pixel coordinates `[x_min, x_max, y_min, y_max]` outside which no ray of
    /// [`RayGen::ray_at`] meets `bounds` (in front of the eye): the projected box's corners,
    /// padded by a pixel and a relative margin that dwarf the rays' rounding. `None` when
    /// that cannot be said (a corner at or behind the eye plane of a pinhole, or an
    /// unbounded box); an empty box gives an empty rectangle. The renderer skips the rays of
    /// tiles outside it: they would all have missed `bounds`.
    pub(crate) fn screen_rect(&self, bounds: &Aabb) -> Option<[f32; 4]> {
        if bounds.is_empty() {
            return Some([
                f32::INFINITY,
                f32::NEG_INFINITY,
                f32::INFINITY,
                f32::NEG_INFINITY,
            ]);
        }
        let mut rect = [
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::INFINITY,
            f32::NEG_INFINITY,
        ];
        let corners = [bounds.min, bounds.max];
        let (r, up, f) = (
            self.right.as_dvec3(),
            self.up.as_dvec3(),
            self.forward.as_dvec3(),
        );
        for c in 0..8 {
            let p = Vec3::new(corners[c & 1].x, corners[(c >> 1) & 1].y, corners[c >> 2].z);
            let d = (p - self.eye).as_dvec3();
            let (u, v) = if self.orthographic {
                (d.dot(r), d.dot(up))
            } else {
                let z = d.dot(f);
                // Near the eye plane the projection blows up: no bound.
                if z.is_nan() || z <= 1e-3 * d.length() {
                    return None;
                }
                (d.dot(r) / z, d.dot(up) / z)
            };
            // `column`/`row` inverted: u = (x·2/W − 1)·scale_u, v = (1 − y·2/H)·scale_v.
            let x = (u / f64::from(self.scale_u) + 1.0) / f64::from(self.inv_w2);
            let y = (1.0 - v / f64::from(self.scale_v)) / f64::from(self.inv_h2);
            if !(x.is_finite() && y.is_finite()) {
                return None;
            }
            rect[0] = rect[0].min(x as f32);
            rect[1] = rect[1].max(x as f32);
            rect[2] = rect[2].min(y as f32);
            rect[3] = rect[3].max(y as f32);
        }
        let size = (2.0 / self.inv_w2).max(2.0 / self.inv_h2);
        let pad = 1.0 + 1e-3 * size;
        Some([rect[0] - pad, rect[1] + pad, rect[2] - pad, rect[3] + pad])
    }

    /// The unit view direction.
    pub fn forward(&self) -> Vec3 {
        self.forward
    }

    /// The camera position.
    pub fn eye(&self) -> Vec3 {
        self.eye
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The module docs' formula, evaluated independently in f64.
    fn spec_dir(cam: &Camera, i: u32, j: u32, w: u32, h: u32) -> [f64; 3] {
        let e = cam.eye.as_dvec3();
        let f = (cam.target.as_dvec3() - e).normalize();
        let r = f.cross(cam.up.as_dvec3()).normalize();
        let up = r.cross(f);
        let tan = (f64::from(cam.vfov_deg).to_radians() / 2.0).tan();
        let (wf, hf) = (f64::from(w), f64::from(h));
        let u = (2.0 * (f64::from(i) + 0.5) / wf - 1.0) * tan * wf / hf;
        let v = (1.0 - 2.0 * (f64::from(j) + 0.5) / hf) * tan;
        (f + r * u + up * v).normalize().to_array()
    }

    /// Brute force over every pixel: no ray through a pixel centre outside
    /// [`RayGen::screen_rect`] meets the box, for random boxes seen by random cameras of
    /// both projections (boxes beside, in front of, around and behind the eye).
    #[test]
    fn no_ray_outside_the_screen_rect_meets_the_box() {
        let mut rng = crate::math::rng::Rng::new(7);
        let (w, h) = (48u32, 32u32);
        let (mut outside, mut bounded, mut unbounded) = (0usize, 0, 0);
        for case in 0..300 {
            let projection = if case % 3 == 0 {
                Projection::Orthographic
            } else {
                Projection::Pinhole
            };
            let cam = Camera {
                eye: rng.vec3(-6.0, 6.0),
                target: rng.vec3(-1.0, 1.0),
                up: Vec3::new(0.1, 0.2, 1.0),
                vfov_deg: rng.range_f32(20.0, 70.0),
                projection,
                ortho_height: None,
            };
            let c = rng.vec3(-3.0, 3.0);
            let half = rng.vec3(0.05, 1.5);
            let b = Aabb {
                min: c - half,
                max: c + half,
            };
            let raygen = RayGen::new(&cam, w, h);
            let Some([x0, x1, y0, y1]) = raygen.screen_rect(&b) else {
                // Only a pinhole with a corner at or behind its eye plane has no rectangle.
                assert_eq!(projection, Projection::Pinhole);
                unbounded += 1;
                continue;
            };
            bounded += 1;
            for j in 0..h {
                for i in 0..w {
                    let (x, y) = (i as f32 + 0.5, j as f32 + 0.5);
                    if x < x0 || x > x1 || y < y0 || y > y1 {
                        outside += 1;
                        let ray = raygen.ray_at(x, y);
                        assert!(
                            b.intersect(&ray, 0.0, f32::INFINITY).is_none(),
                            "case {case}: pixel ({i}, {j}) outside {:?} meets {b:?}",
                            [x0, x1, y0, y1]
                        );
                    }
                }
            }
        }
        assert!(
            bounded > 150 && unbounded >= 5,
            "{bounded} bounded, {unbounded} not"
        );
        assert!(outside > 100_000, "only {outside} pixels tested outside");
        let cam = Camera {
            eye: Vec3::new(0.0, -5.0, 1.0),
            target: Vec3::ZERO,
            up: Vec3::Z,
            vfov_deg: 40.0,
            projection: Projection::Pinhole,
            ortho_height: None,
        };
        let empty = RayGen::new(&cam, w, h).screen_rect(&Aabb::EMPTY);
        assert!(empty.is_some_and(|[x0, x1, y0, y1]| x0 > x1 && y0 > y1));
    }

    #[test]
    fn pinhole_rays_follow_the_spec_formula() {
        let cam = Camera {
            eye: Vec3::new(3.0, -2.0, 1.5),
            target: Vec3::new(0.5, 0.25, -0.5),
            up: Vec3::new(0.1, 0.2, 1.0),
            vfov_deg: 37.0,
            projection: Projection::Pinhole,
            ortho_height: None,
        };
        cam.validate().unwrap();
        let (w, h) = (64, 48);
        for (i, j) in [(0, 0), (63, 0), (0, 47), (63, 47), (31, 23), (17, 40)] {
            let ray = cam.primary_ray(i, j, w, h);
            let want = spec_dir(&cam, i, j, w, h);
            for (a, want_a) in want.iter().enumerate() {
                assert!(
                    (f64::from(ray.dir[a]) - want_a).abs() < 2e-6,
                    "pixel ({i},{j}) axis {a}: {} vs {want_a}",
                    ray.dir[a],
                );
            }
            assert!((ray.dir.length() - 1.0).abs() < 1e-6);
            assert_eq!(ray.origin, cam.eye);
        }
        // Row 0 is at the top: its rays point further "up" than the last row's.
        let (_, up, _) = cam.basis();
        assert!(cam.primary_ray(5, 0, w, h).dir.dot(up) > cam.primary_ray(5, 47, w, h).dir.dot(up));
        // Column 0 is on the left.
        let (right, _, _) = cam.basis();
        assert!(cam.primary_ray(0, 5, w, h).dir.dot(right) < 0.0);
    }

    #[test]
    fn row_and_column_rays_are_bit_identical_to_ray_at() {
        let mut hits = 0;
        for projection in [Projection::Pinhole, Projection::Orthographic] {
            // Oblique, and axis-aligned (exact zero direction components, infinite
            // reciprocals) through the middle column of an odd-width image.
            for eye in [Vec3::new(3.0, -2.0, 1.5), Vec3::new(0.0, 0.0, 5.0)] {
                let cam = Camera {
                    eye,
                    target: if eye.x == 0.0 {
                        Vec3::ZERO
                    } else {
                        Vec3::new(0.5, 0.25, -0.5)
                    },
                    up: if eye.x == 0.0 {
                        Vec3::Y
                    } else {
                        Vec3::new(0.1, 0.2, 1.0)
                    },
                    vfov_deg: 37.0,
                    projection,
                    ortho_height: None,
                };
                let (w, h) = (1001, 613);
                let raygen = RayGen::new(&cam, w, h);
                let bits =
                    |r: &Ray| [r.origin, r.dir, r.inv_dir].map(|v| v.to_array().map(f32::to_bits));
                // Boxes in front, around the eye, and with faces through the eye.
                let boxes = [
                    Aabb::new(Vec3::splat(-1.0), Vec3::splat(1.0)),
                    Aabb::new(eye - 0.5, eye + Vec3::new(0.25, 3.0, 0.5)),
                    Aabb::new(eye, eye + 2.0),
                    Aabb::new(Vec3::new(-2.0, -2.0, eye.z), Vec3::new(2.0, 2.0, eye.z)),
                    Aabb::EMPTY,
                ];
                for (x0, y) in [(0.5, 0.5), (123.25, 77.5), (984.5, 612.5), (500.5, 306.5)] {
                    let columns: [Vec3; 16] =
                        std::array::from_fn(|i| raygen.column(x0 + 0.97 * i as f32));
                    for b in &boxes {
                        let mut rays = [Ray::new(Vec3::ZERO, Vec3::X); 16];
                        let (mut lo, mut hi) = ([0.0; 16], [0.0; 16]);
                        let meets = raygen.rays_row_in(
                            &columns,
                            raygen.row(y),
                            b,
                            &mut rays,
                            &mut lo,
                            &mut hi,
                        );
                        for (i, r) in rays.iter().enumerate() {
                            let want = raygen.ray_at(x0 + 0.97 * i as f32, y);
                            assert_eq!(bits(r), bits(&want), "{projection:?} ({x0}+{i}, {y})");
                            let range = b.intersect(r, 0.0, f32::INFINITY);
                            let got =
                                (meets >> i & 1 == 1).then(|| (lo[i].to_bits(), hi[i].to_bits()));
                            assert_eq!(
                                got,
                                range.map(|(a, c)| (a.to_bits(), c.to_bits())),
                                "{projection:?} ({x0}+{i}, {y}) {b:?}"
                            );
                            hits += usize::from(got.is_some());
                        }
                    }
                }
                // Direction components exactly zero (infinite reciprocals; `0 · inf` on the
                // faces through the eye).
                let columns: [Vec3; 16] =
                    std::array::from_fn(|i| Vec3::new(0.0, 0.1 * i as f32 - 0.8, -1.0));
                // Its low x face through the eye: every one of these rays lies in the face.
                let face = Aabb::new(eye - Vec3::new(0.0, 5.0, 5.0), eye + Vec3::splat(5.0));
                for row in [Vec3::ZERO, Vec3::new(0.0, 0.3, 0.0)] {
                    let mut rays = [Ray::new(Vec3::ZERO, Vec3::X); 16];
                    let (mut lo, mut hi) = ([0.0; 16], [0.0; 16]);
                    let meets =
                        raygen.rays_row_in(&columns, row, &face, &mut rays, &mut lo, &mut hi);
                    if projection == Projection::Pinhole {
                        assert_eq!(meets, 0xffff, "rays in the box's face: {row}");
                    }
                    for b in &boxes {
                        let mut rays = [Ray::new(Vec3::ZERO, Vec3::X); 16];
                        let (mut lo, mut hi) = ([0.0; 16], [0.0; 16]);
                        let meets =
                            raygen.rays_row_in(&columns, row, b, &mut rays, &mut lo, &mut hi);
                        for (i, r) in rays.iter().enumerate() {
                            let want = raygen.ray_from(columns[i], row);
                            assert_eq!(bits(r), bits(&want));
                            let range = b.intersect(r, 0.0, f32::INFINITY);
                            let got =
                                (meets >> i & 1 == 1).then(|| (lo[i].to_bits(), hi[i].to_bits()));
                            assert_eq!(
                                got,
                                range.map(|(a, c)| (a.to_bits(), c.to_bits())),
                                "zero x: {projection:?} {i} {row} {b:?}"
                            );
                        }
                    }
                }
            }
        }
        assert!(hits > 100, "{hits} rays meet the boxes");
    }

    #[test]
    fn orthographic_rays_are_parallel_and_span_ortho_height() {
        let cam = Camera {
            eye: Vec3::new(0.0, 0.0, 10.0),
            target: Vec3::ZERO,
            up: Vec3::Y,
            vfov_deg: 40.0,
            projection: Projection::Orthographic,
            ortho_height: Some(4.0),
        };
        let (w, h) = (8, 4);
        let top_left = cam.primary_ray(0, 0, w, h);
        let bottom_right = cam.primary_ray(w - 1, h - 1, w, h);
        assert_eq!(top_left.dir, Vec3::NEG_Z);
        assert_eq!(bottom_right.dir, Vec3::NEG_Z);
        // Pixel centres: v = (1 − 1/4)·2 = 1.5, u = (1/8 − 1)·2·2 = −3.5; right = forward × up
        // = (+1, 0, 0) for forward −z and up +y.
        assert!((top_left.origin - Vec3::new(-3.5, 1.5, 10.0)).length() < 1e-6);
        assert!((bottom_right.origin - Vec3::new(3.5, -1.5, 10.0)).length() < 1e-6);
    }

    #[test]
    fn camera_json_round_trip_ignores_unknown_fields() {
        let json = r#"{"eye":[1,2,3],"target":[0,0,0],"up":[0,0,1],"vfov_deg":30,
                       "projection":"pinhole","note":"from the GUI","zoom":2}"#;
        let cam: Camera = serde_json::from_str(json).unwrap();
        assert_eq!(cam.eye, Vec3::new(1.0, 2.0, 3.0));
        assert_eq!(cam.vfov_deg, 30.0);
        assert_eq!(cam.projection, Projection::Pinhole);
        let back: Camera = serde_json::from_str(&serde_json::to_string(&cam).unwrap()).unwrap();
        assert_eq!(back, cam);
        let ortho: Camera = serde_json::from_str(
            r#"{"eye":[0,0,5],"target":[0,0,0],"up":[0,1,0],"projection":"orthographic","ortho_height":3}"#,
        )
        .unwrap();
        assert_eq!(ortho.projection, Projection::Orthographic);
        assert_eq!(ortho.ortho_height, Some(3.0));
        assert_eq!(ortho.vfov_deg, 40.0);
        assert!(
            serde_json::from_str::<Camera>(
                r#"{"eye":[0,0,5],"target":[0,0,0],"projection":"fisheye"}"#
            )
            .is_err()
        );
    }

    #[test]
    fn validation_names_the_problem() {
        let mut cam = Camera::orbit(&Aabb::new(Vec3::ZERO, Vec3::ONE), 30.0, 20.0, 40.0);
        assert_eq!(cam.validate(), Ok(()));
        cam.up = (cam.target - cam.eye) * 2.0;
        assert!(matches!(cam.validate(), Err(CameraError::BadUp { .. })));
        cam.up = Vec3::Z;
        cam.target = cam.eye;
        assert!(matches!(cam.validate(), Err(CameraError::EyeIsTarget(_))));
        cam.target = Vec3::ZERO;
        cam.vfov_deg = 180.0;
        assert_eq!(cam.validate(), Err(CameraError::BadFov(180.0)));
        cam.vfov_deg = 40.0;
        cam.eye.x = f32::NAN;
        assert!(matches!(
            cam.validate(),
            Err(CameraError::NotFinite { field: "eye", .. })
        ));
    }

    #[test]
    fn orbit_framed_fits_the_corners_tightly() {
        let b = Aabb::new(Vec3::new(-1.0, 0.0, 2.0), Vec3::new(3.0, 2.0, 4.0));
        for aspect in [0.5f32, 1.0, 4.0 / 3.0, 3.0] {
            for (az, el) in [(0.0, 0.0), (30.0, 20.0), (200.0, -60.0), (10.0, 90.0)] {
                let cam = Camera::orbit_framed(&b, az, el, 40.0, aspect);
                cam.validate().unwrap();
                assert_eq!(cam.target, b.center());
                let sphere = Camera::orbit(&b, az, el, 40.0);
                // The sphere fits the vertical field of view only: closer in any image at
                // least as wide as tall.
                if aspect >= 1.0 {
                    assert!(cam.eye.distance(cam.target) < sphere.eye.distance(sphere.target));
                }
                // Brute force: the largest projected corner coordinate over the frame's
                // half-size is 1/1.05 (inside, with the margin, and touching it).
                let (right, up, forward) = cam.basis();
                let tan = (20.0f32).to_radians().tan();
                let mut most = 0.0f32;
                for c in 0..8 {
                    let p = Vec3::new(
                        if c & 1 == 0 { b.min.x } else { b.max.x },
                        if c & 2 == 0 { b.min.y } else { b.max.y },
                        if c & 4 == 0 { b.min.z } else { b.max.z },
                    );
                    let d = p - cam.eye;
                    let z = d.dot(forward);
                    assert!(z > 0.0);
                    most = most
                        .max((d.dot(up) / z).abs() / tan)
                        .max((d.dot(right) / z).abs() / (tan * aspect));
                }
                assert!(
                    (most - 1.0 / 1.05).abs() < 1e-3,
                    "{aspect} {az} {el}: {most}"
                );
            }
        }
    }

    #[test]
    fn orbit_frames_the_bounds() {
        let b = Aabb::new(Vec3::new(-1.0, 0.0, 2.0), Vec3::new(3.0, 2.0, 4.0));
        for (az, el) in [(0.0, 0.0), (30.0, 20.0), (200.0, -60.0), (10.0, 90.0)] {
            let cam = Camera::orbit(&b, az, el, 40.0);
            cam.validate().unwrap();
            assert_eq!(cam.target, b.center());
            // Every corner projects inside the image.
            let (right, up, forward) = cam.basis();
            let tan = (20.0f32).to_radians().tan();
            for c in 0..8 {
                let p = Vec3::new(
                    if c & 1 == 0 { b.min.x } else { b.max.x },
                    if c & 2 == 0 { b.min.y } else { b.max.y },
                    if c & 4 == 0 { b.min.z } else { b.max.z },
                );
                let d = p - cam.eye;
                let z = d.dot(forward);
                assert!(z > 0.0);
                assert!((d.dot(up) / z).abs() < tan && (d.dot(right) / z).abs() < tan);
            }
        }
    }
}
