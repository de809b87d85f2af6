//! From the orbit [`CameraState`] to a world-space camera pose, and the projection of world
//! points into the image (for the clip-box outline drawn over the ray-traced picture).
//!
//! The projection follows the renderer's pixel convention (`volume_core::render::Camera`): pixel (i, j), row 0 at
//! the top, is hit by the ray through `u = (2(i+0.5)/W − 1)·tan(vfov/2)·W/H`,
//! `v = (1 − 2(j+0.5)/H)·tan(vfov/2)`; so a point at view coordinates (x, y, z) lands at
//! `i = (x/z / (tan·W/H) + 1)·W/2`, `j = (1 − y/z / tan)·H/2` in continuous pixel units.
//! Orthographic views use the half-height `distance·tan(vfov/2)` at every depth.

use glam::Vec3;
use volume_core::math::Aabb;

use super::state::{CameraState, ClipBoxState};

/// A camera in world units.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CameraPose {
    pub eye: Vec3,
    pub target: Vec3,
    pub up: Vec3,
    pub vfov_deg: f32,
    pub orthographic: bool,
}

/// Orthonormal view basis: `forward` points from the eye to the target.
#[derive(Debug, Clone, Copy)]
pub struct ViewBasis {
    pub forward: Vec3,
    pub right: Vec3,
    pub up: Vec3,
}

/// Radius of the bounding sphere (never zero, so flat or single-voxel data still gets a view).
pub fn bounding_radius(bounds: &Aabb) -> f32 {
    let r = 0.5 * bounds.extent().length();
    if r.is_finite() && r > 0.0 { r } else { 1.0 }
}

/// The default view of `bounds` in a viewport of `viewport_px` pixels: the default orbit,
/// zoomed until the bounds fill the frame with a 5 % margin from that direction, as the CLI's
/// and the Python package's orbit cameras frame them ([`volume_core::render::Camera::orbit_framed`]).
/// Zoom 1 is the bounding sphere, which leaves a box a third or less of the frame.
pub fn framed_view(bounds: &Aabb, viewport_px: [u32; 2]) -> CameraState {
    let mut view = CameraState::default();
    if bounds.is_empty() {
        return view;
    }
    let aspect = viewport_px[0].max(1) as f32 / viewport_px[1].max(1) as f32;
    let framed = volume_core::render::Camera::orbit_framed(
        bounds,
        view.azimuth_deg,
        view.elevation_deg,
        view.vfov_deg,
        aspect,
    );
    let sphere_distance = bounding_radius(bounds) / (0.5 * view.vfov_deg.to_radians()).sin();
    let zoom = framed.eye.distance(framed.target) / sphere_distance;
    if zoom.is_finite() && zoom > 0.0 {
        view.zoom = zoom.clamp(CameraState::MIN_ZOOM, CameraState::MAX_ZOOM);
    }
    view
}

impl CameraPose {
    /// The orbit camera: z is up, azimuth 0 looks from +x, elevation from above.
    pub fn from_state(state: &CameraState, bounds: &Aabb) -> Self {
        let center = if bounds.is_empty() {
            Vec3::ZERO
        } else {
            bounds.center()
        };
        let radius = bounding_radius(bounds);
        let vfov = state.vfov_deg.clamp(5.0, 120.0);
        let (az, el) = (
            state.azimuth_deg.to_radians(),
            state
                .elevation_deg
                .clamp(
                    -CameraState::MAX_ELEVATION_DEG,
                    CameraState::MAX_ELEVATION_DEG,
                )
                .to_radians(),
        );
        let offset_dir = Vec3::new(el.cos() * az.cos(), el.cos() * az.sin(), el.sin());
        // The bounding sphere fits the vertical field of view at zoom 1.
        let distance = radius / (0.5 * vfov.to_radians()).sin() * state.zoom;
        let forward = -offset_dir;
        let right = forward.cross(Vec3::Z).normalize();
        let up = right.cross(forward);
        let target = center + (right * state.pan[0] + up * state.pan[1]) * radius;
        Self {
            eye: target + offset_dir * distance,
            target,
            up,
            vfov_deg: vfov,
            orthographic: state.orthographic,
        }
    }

    pub fn basis(&self) -> ViewBasis {
        let forward = (self.target - self.eye).normalize();
        let right = forward.cross(self.up).normalize();
        ViewBasis {
            forward,
            right,
            up: right.cross(forward),
        }
    }

    fn tan_half(&self) -> f32 {
        (0.5 * self.vfov_deg.to_radians()).tan()
    }

    /// Continuous pixel position of a point given in view coordinates, or `None` when it lies
    /// behind the near limit of a pinhole camera.
    fn view_to_pixel(&self, view: Vec3, width: f32, height: f32) -> Option<[f32; 2]> {
        let aspect = width / height;
        let (u, v) = if self.orthographic {
            let half_h = (self.target - self.eye).length() * self.tan_half();
            (view.x / half_h, view.y / half_h)
        } else {
            if view.z <= 1e-6 {
                return None;
            }
            let t = self.tan_half();
            (view.x / view.z / t, view.y / view.z / t)
        };
        Some([(u / aspect + 1.0) * 0.5 * width, (1.0 - v) * 0.5 * height])
    }

    fn view_coords(&self, p: Vec3) -> Vec3 {
        let b = self.basis();
        let q = p - self.eye;
        Vec3::new(q.dot(b.right), q.dot(b.up), q.dot(b.forward))
    }

    /// Pixel position (continuous, row 0 at the top) of a world point, if it is in front.
    pub fn project(&self, p: Vec3, width: f32, height: f32) -> Option<[f32; 2]> {
        self.view_to_pixel(self.view_coords(p), width, height)
    }

    /// Projects a world segment, clipping it at the near limit so that edges passing behind
    /// the eye are still drawn correctly.
    pub fn project_segment(
        &self,
        a: Vec3,
        b: Vec3,
        width: f32,
        height: f32,
    ) -> Option<([f32; 2], [f32; 2])> {
        let (mut va, mut vb) = (self.view_coords(a), self.view_coords(b));
        if !self.orthographic {
            let near = 1e-3 * (self.target - self.eye).length().max(1e-6);
            if va.z < near && vb.z < near {
                return None;
            }
            if va.z < near {
                va = va + (vb - va) * ((near - va.z) / (vb.z - va.z));
            } else if vb.z < near {
                vb = vb + (va - vb) * ((near - vb.z) / (va.z - vb.z));
            }
        }
        Some((
            self.view_to_pixel(va, width, height)?,
            self.view_to_pixel(vb, width, height)?,
        ))
    }
}

/// The world box of a clip box given as fractions of `bounds`.
pub fn clip_box_world(clip: &ClipBoxState, bounds: &Aabb) -> Aabb {
    let lo = Vec3::from(clip.min).min(Vec3::from(clip.max));
    let hi = Vec3::from(clip.min).max(Vec3::from(clip.max));
    let ext = bounds.extent();
    Aabb::new(bounds.min + ext * lo, bounds.min + ext * hi)
}

/// The 12 edges of a box.
pub fn box_edges(b: &Aabb) -> [(Vec3, Vec3); 12] {
    let c = |i: u32| {
        Vec3::new(
            if i & 1 == 0 { b.min.x } else { b.max.x },
            if i & 2 == 0 { b.min.y } else { b.max.y },
            if i & 4 == 0 { b.min.z } else { b.max.z },
        )
    };
    [
        (c(0), c(1)),
        (c(2), c(3)),
        (c(4), c(5)),
        (c(6), c(7)),
        (c(0), c(2)),
        (c(1), c(3)),
        (c(4), c(6)),
        (c(5), c(7)),
        (c(0), c(4)),
        (c(1), c(5)),
        (c(2), c(6)),
        (c(3), c(7)),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_framed_view_puts_the_bounds_at_the_margin_of_the_viewport() {
        let b = Aabb::new(Vec3::new(-1.0, 0.0, 2.0), Vec3::new(3.0, 2.0, 2.5));
        for px in [[1280u32, 800u32], [600, 900]] {
            let view = framed_view(&b, px);
            // The bounding sphere (zoom 1) fits the height only: closer in a wide viewport.
            if px[0] >= px[1] {
                assert!(view.zoom < 1.0, "{}", view.zoom);
            }
            // Brute force: project the corners with the viewer's own pose and projection.
            let pose = CameraPose::from_state(&view, &b);
            let (w, h) = (px[0] as f32, px[1] as f32);
            let mut most = 0.0f32;
            for c in 0..8 {
                let p = Vec3::new(
                    if c & 1 == 0 { b.min.x } else { b.max.x },
                    if c & 2 == 0 { b.min.y } else { b.max.y },
                    if c & 4 == 0 { b.min.z } else { b.max.z },
                );
                let [i, j] = pose.project(p, w, h).unwrap();
                most = most
                    .max((2.0 * i / w - 1.0).abs())
                    .max((2.0 * j / h - 1.0).abs());
            }
            assert!((most - 1.0 / 1.05).abs() < 2e-3, "{px:?}: {most}");
        }
    }

    fn unit_box() -> Aabb {
        Aabb::new(Vec3::splat(-1.0), Vec3::splat(1.0))
    }

    /// The ray of pixel (i, j) by the renderer's convention, built independently.
    fn pixel_ray_dir(pose: &CameraPose, i: f32, j: f32, w: f32, h: f32) -> Vec3 {
        let b = pose.basis();
        let t = (0.5 * pose.vfov_deg.to_radians()).tan();
        let u = (2.0 * (i + 0.5) / w - 1.0) * t * w / h;
        let v = (1.0 - 2.0 * (j + 0.5) / h) * t;
        (b.forward + b.right * u + b.up * v).normalize()
    }

    #[test]
    fn projection_inverts_the_renderer_pixel_rays() {
        let state = CameraState {
            azimuth_deg: 70.0,
            elevation_deg: -20.0,
            zoom: 1.3,
            pan: [0.2, -0.1],
            ..CameraState::default()
        };
        let pose = CameraPose::from_state(&state, &unit_box());
        let (w, h) = (320.0, 200.0);
        for &(i, j) in &[(0.0, 0.0), (100.0, 50.0), (319.0, 199.0), (160.0, 100.0)] {
            let dir = pixel_ray_dir(&pose, i, j, w, h);
            let p = pose.eye + dir * 3.7;
            let [pi, pj] = pose.project(p, w, h).unwrap();
            // Pixel centres project to i + 0.5, j + 0.5.
            assert!((pi - (i + 0.5)).abs() < 1e-3, "{pi} vs {i}");
            assert!((pj - (j + 0.5)).abs() < 1e-3, "{pj} vs {j}");
        }
    }

    #[test]
    fn default_view_sees_the_whole_bounding_sphere() {
        let pose = CameraPose::from_state(&CameraState::default(), &unit_box());
        let (w, h) = (400.0, 300.0);
        for (a, b) in box_edges(&unit_box()) {
            for p in [a, b] {
                let [x, y] = pose.project(p, w, h).unwrap();
                assert!(
                    (0.0..=w).contains(&x) && (0.0..=h).contains(&y),
                    "{p} -> {x},{y}"
                );
            }
        }
        assert!((pose.target - Vec3::ZERO).length() < 1e-6);
        let b = pose.basis();
        assert!(b.forward.dot(b.up).abs() < 1e-5 && b.right.dot(b.up).abs() < 1e-5);
        assert!(b.up.z > 0.0, "z is up");
    }

    #[test]
    fn points_behind_the_eye_are_not_projected_and_segments_are_clipped() {
        let pose = CameraPose::from_state(&CameraState::default(), &unit_box());
        let behind = pose.eye + (pose.eye - pose.target);
        assert!(pose.project(behind, 100.0, 100.0).is_none());
        let seg = pose.project_segment(behind, pose.target, 100.0, 100.0);
        let (_, end) = seg.unwrap();
        assert!((end[0] - 50.0).abs() < 1e-3 && (end[1] - 50.0).abs() < 1e-3);
        assert!(
            pose.project_segment(behind, behind * 2.0, 100.0, 100.0)
                .is_none()
        );
    }

    #[test]
    fn clip_box_fractions_map_to_world() {
        let b = Aabb::new(Vec3::new(0.0, 0.0, 0.0), Vec3::new(10.0, 20.0, 30.0));
        let c = ClipBoxState {
            min: [0.5, 0.0, 1.0],
            max: [1.0, 0.25, 0.0],
            ..ClipBoxState::default()
        };
        let w = clip_box_world(&c, &b);
        assert_eq!(w.min, Vec3::new(5.0, 0.0, 0.0));
        assert_eq!(w.max, Vec3::new(10.0, 5.0, 30.0));
        assert_eq!(box_edges(&w).len(), 12);
        for (p, q) in box_edges(&w) {
            // Every edge is axis-parallel: exactly one coordinate differs.
            let d = (p - q).abs();
            assert_eq!((d.x > 0.0) as u8 + (d.y > 0.0) as u8 + (d.z > 0.0) as u8, 1);
        }
    }
}
