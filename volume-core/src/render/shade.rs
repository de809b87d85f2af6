//! Two-sided Blinn–Phong shading with one light, and a shadowless fill light at the eye when
//! the key light is not the headlight.
//!
//! Normals come from the scene (central differences in world space for grids, thesis
//! seed 004 §6.4; isopolygon planes for tets, §8.2). Shading is two-sided: the normal is
//! flipped towards the viewer, so back faces seen through a clip or a transparent layer look
//! like front faces.

use glam::Vec3;

use crate::render::settings::{Light, LightKind};

/// A light resolved for shading: the material constants and where `L` comes from.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Shader {
    light: Light,
}

impl Shader {
    pub(crate) fn new(light: &Light) -> Self {
        let mut light = *light;
        if let LightKind::Directional { dir } = light.kind {
            light.kind = LightKind::Directional {
                dir: dir.try_normalize().unwrap_or(Vec3::Z),
            };
        }
        Self { light }
    }

    /// Whether the light can cast shadows (the headlight's shadows are hidden behind the
    /// surfaces it lights, so it casts none).
    pub(crate) fn casts_shadows(&self) -> bool {
        !matches!(self.light.kind, LightKind::Headlight)
    }

    /// The normal flipped to face the viewer (`ray_dir` points from the eye to the surface).
    #[inline]
    pub(crate) fn facing(normal: Vec3, ray_dir: Vec3) -> Vec3 {
        let n = normal.try_normalize().unwrap_or(-ray_dir);
        if n.dot(ray_dir) > 0.0 { -n } else { n }
    }

    /// Unit direction from `p` towards the light and the distance to it (`inf` at infinity).
    #[inline]
    pub(crate) fn light_dir(&self, p: Vec3, ray_dir: Vec3) -> (Vec3, f32) {
        match self.light.kind {
            LightKind::Headlight => (-ray_dir, f32::INFINITY),
            LightKind::Directional { dir } => (dir, f32::INFINITY),
            LightKind::Point { pos } => {
                let d = pos - p;
                let len = d.length();
                (d.try_normalize().unwrap_or(-ray_dir), len)
            }
        }
    }

    /// `n·L` clamped at 0 for a facing normal `n`.
    #[inline]
    pub(crate) fn lambert(n: Vec3, to_light: Vec3) -> f32 {
        n.dot(to_light).max(0.0)
    }

    /// The shaded colour, each channel clamped to `[0, 1]`. `lit` is 0 in shadow, else 1.
    #[inline]
    pub(crate) fn shade(
        &self,
        color: Vec3,
        n: Vec3,
        ray_dir: Vec3,
        to_light: Vec3,
        lit: f32,
    ) -> Vec3 {
        let l = &self.light;
        let diffuse = Self::lambert(n, to_light) * lit;
        let fill = match l.kind {
            LightKind::Headlight => 0.0,
            _ => l.fill * Self::lambert(n, -ray_dir),
        };
        // No `powf` when the specular term is off (`0 · x` is `+0` for the finite `x` here).
        let specular = if diffuse > 0.0 && l.specular != 0.0 {
            let h = (to_light - ray_dir).try_normalize().unwrap_or(n);
            n.dot(h).max(0.0).powf(l.shininess) * lit
        } else {
            0.0
        };
        (color * (l.ambient + fill + l.diffuse * diffuse) + Vec3::splat(l.specular * specular))
            .clamp(Vec3::ZERO, Vec3::ONE)
    }
}
