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
    /// The shininess as an integer when it is one (the default 40): the specular power is
    /// then a few multiplications ([`pow_int`]) instead of `powf`, which was about 2 % of a
    /// shaded tet frame.
    shininess_int: Option<u32>,
}

impl Shader {
    pub(crate) fn new(light: &Light) -> Self {
        let mut light = *light;
        if let LightKind::Directional { dir } = light.kind {
            light.kind = LightKind::Directional {
                dir: dir.try_normalize().unwrap_or(Vec3::Z),
            };
        }
        let s = light.shininess;
        let shininess_int =
            (s.fract() == 0.0 && (0.0..=MAX_INT_SHININESS).contains(&s)).then_some(s as u32);
        Self {
            light,
            shininess_int,
        }
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
            let x = n.dot(h).max(0.0);
            let p = match self.shininess_int {
                Some(e) => pow_int(x, e),
                None => x.powf(l.shininess),
            };
            p * lit
        } else {
            0.0
        };
        (color * (l.ambient + fill + l.diffuse * diffuse) + Vec3::splat(l.specular * specular))
            .clamp(Vec3::ZERO, Vec3::ONE)
    }
}

/// Largest shininess taken by [`pow_int`] (ten squarings).
const MAX_INT_SHININESS: f32 = 1024.0;

/// `x^e` by squaring, for `x` in `[0, 1]`: each squaring doubles the relative error, so it
/// stays within about `e` ulps (6e-5 at `e = 1024`), far below a colour level.
#[inline]
fn pow_int(mut x: f32, mut e: u32) -> f32 {
    let mut p = 1.0;
    while e > 0 {
        if e & 1 == 1 {
            p *= x;
        }
        x *= x;
        e >>= 1;
    }
    p
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::rng::Rng;

    /// The integer power against `f64` `powi` for exponents up to the cap, the shaded
    /// colour against the same light shaded with `powf`, and which shininesses take it.
    #[test]
    fn integer_specular_powers_match_f64_powers() {
        let mut rng = Rng::new(9);
        for e in [0u32, 1, 2, 3, 7, 40, 41, 128, 1000, 1024] {
            for _ in 0..2000 {
                let x = rng.unit_f32();
                let want = f64::from(x).powi(e as i32);
                let got = f64::from(pow_int(x, e));
                assert!(
                    (got - want).abs() <= f64::from(e + 1) * 1.2e-7 * want + 1e-37,
                    "{x}^{e}: {got} against {want}"
                );
            }
        }
        let light = Light::default();
        let int = Shader::new(&light);
        assert_eq!(int.shininess_int, Some(light.shininess as u32));
        let real = Shader {
            shininess_int: None,
            ..int
        };
        let ray_dir = Vec3::new(0.1, -0.2, -1.0).normalize();
        for _ in 0..2000 {
            let n = Shader::facing(rng.vec3(-1.0, 1.0), ray_dir);
            let to_light = rng.vec3(-1.0, 1.0).normalize();
            let c = rng.vec3(0.0, 1.0);
            let (a, b) = (
                int.shade(c, n, ray_dir, to_light, 1.0),
                real.shade(c, n, ray_dir, to_light, 1.0),
            );
            assert!((a - b).abs().max_element() < 1e-5, "{a} against {b}");
        }
        assert_eq!(
            Shader::new(&Light {
                shininess: 40.5,
                ..light
            })
            .shininess_int,
            None
        );
        assert_eq!(
            Shader::new(&Light {
                shininess: 2048.0,
                ..light
            })
            .shininess_int,
            None
        );
    }
}
