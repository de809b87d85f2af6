//! What to render: isosurfaces with their look, clip regions, the light and the image size.
//!
//! All types are serde-serializable so that the GUI can save them in a session file.

use glam::Vec3;
use serde::{Deserialize, Serialize};
use thiserror::Error;

use crate::render::colormap::Colormap;

/// One isosurface and its look.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Surface {
    pub isovalue: f32,
    /// Linear RGB in `[0, 1]`.
    pub color: [f32; 3],
    /// `1` is opaque; below `1` the surface is peeled (thesis 8.6, "transparent depth
    /// peeling"); `0` behaves like an invisible surface.
    pub opacity: f32,
    pub visible: bool,
    /// Colour the surface by another field through a colormap instead of `color` (`None`:
    /// the flat colour). The caller resolves the field for the renderer
    /// ([`crate::render::render_colored_into`]).
    #[serde(default)]
    pub color_by: Option<ColorBy>,
}

impl Surface {
    /// An opaque, visible surface.
    pub fn new(isovalue: f32, color: [f32; 3]) -> Self {
        Self {
            isovalue,
            color,
            opacity: 1.0,
            visible: true,
            color_by: None,
        }
    }

    /// Whether the renderer traces this surface at all.
    pub fn is_active(&self) -> bool {
        self.visible && self.opacity > 0.0 && self.isovalue.is_finite()
    }
}

/// The field a surface is coloured by.
#[derive(Debug, Clone, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ColorField {
    /// The magnitude of the drawn field's gradient (rectilinear grids), value per world
    /// unit: central differences at the samples, trilinear in between (the shading normals'
    /// gradient, thesis seed 004 §6.4).
    Gradient,
    /// Another field of the same data by name: a point array of a tetrahedral mesh, or for
    /// a grid the path of another volume on the same grid, as the caller named it.
    Field(String),
}

impl ColorField {
    /// The name shown on scalar bars and in messages.
    pub fn label(&self) -> &str {
        match self {
            ColorField::Gradient => "gradient magnitude",
            ColorField::Field(name) => name,
        }
    }
}

/// How a surface is coloured by another field.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ColorBy {
    pub field: ColorField,
    #[serde(default)]
    pub colormap: Colormap,
    /// `[min, max]` mapped to the colormap's ends, values outside clamped; `None`: the
    /// field's data range.
    #[serde(default)]
    pub range: Option<[f32; 2]>,
    /// Draw a scalar bar for this colouring (viewer overlay, screenshots, `render` images).
    #[serde(default = "default_scalar_bar")]
    pub scalar_bar: bool,
}

fn default_scalar_bar() -> bool {
    true
}

impl ColorBy {
    /// Colouring by `field` with viridis over the data range, with a scalar bar.
    pub fn new(field: ColorField) -> Self {
        Self {
            field,
            colormap: Colormap::default(),
            range: None,
            scalar_bar: true,
        }
    }
}

/// Which side of a clip box is kept.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Keep {
    #[default]
    Inside,
    Outside,
}

/// A region of space that clips the isosurfaces. The kept set of several regions is the
/// intersection of each region's kept set. Cut faces are not drawn (no caps).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ClipRegion {
    /// An axis-aligned world box (closed); keeps its inside or its outside.
    Box { min: Vec3, max: Vec3, keep: Keep },
    /// A half-space: keeps the points with `normal · x <= offset`.
    Plane { normal: Vec3, offset: f32 },
}

/// Where the light comes from.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum LightKind {
    /// A light at the eye, moving with the camera (the default; casts no visible shadows).
    #[default]
    Headlight,
    /// A light at infinity; `dir` points from the surface *towards* the light.
    Directional { dir: Vec3 },
    /// A point light at `pos` (world units).
    Point { pos: Vec3 },
}

/// One light and the Blinn–Phong material constants used for every surface.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Light {
    pub kind: LightKind,
    /// Ambient term (also what a shadowed point receives).
    pub ambient: f32,
    pub diffuse: f32,
    /// White specular highlight strength.
    pub specular: f32,
    pub shininess: f32,
    /// A fill light at the eye for a directional or point key light (the headlight is its own
    /// fill): `fill · n·V` more diffuse light, casting no shadows, so that a surface the key
    /// light leaves in its back is shaded by its shape, not flat ambient black (the fill of
    /// ParaView's light kit).
    #[serde(default = "default_fill")]
    pub fill: f32,
}

fn default_fill() -> f32 {
    Light::default().fill
}

impl Default for Light {
    fn default() -> Self {
        Self {
            kind: LightKind::Headlight,
            ambient: 0.15,
            diffuse: 0.75,
            specular: 0.25,
            shininess: 40.0,
            fill: 0.3,
        }
    }
}

/// Everything about a frame except the scene and the camera.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct RenderSettings {
    pub width: u32,
    pub height: u32,
    pub surfaces: Vec<Surface>,
    pub clips: Vec<ClipRegion>,
    /// The most surface layers composited per pixel (transparency); at least 1.
    pub max_layers: u32,
    /// Shadow rays towards `light` (meaningful for directional and point lights).
    pub shadows: bool,
    pub light: Light,
    /// Linear RGB of pixels whose rays miss (or pass through transparent layers).
    pub background: [f32; 3],
    /// Count traversal statistics into [`crate::render::Frame::counts`].
    pub collect_stats: bool,
    /// Progressive rendering: one ray per `scale × scale` pixel block, replicated over the
    /// block (coarse first for interaction); 1 is full resolution.
    pub scale: u32,
    /// Primary rays in packets (`IsoScene::first_hit_packet`) rather than one by one.
    pub packets: bool,
    /// Anti-aliasing at full resolution (`scale` 1): `supersample²` samples per pixel,
    /// averaged ([`crate::render::supersample`]); 1 is off.
    pub supersample: u32,
    /// Render only the tiles that overlap this part of the image (pbrt's crop window): the
    /// frame then holds just their pixels, as they are in the whole image. Sort-first
    /// distribution renders each rank's chunks this way; `None` is the whole image.
    pub region: Option<PixelRegion>,
    /// Only where rays first hit (Embree's distance query): each sample's first hit of any
    /// surface, its depth and its surface's flat colour, with no shading normal, lighting,
    /// shadows, transparency or colouring by a field. For depth maps, and for timing the
    /// traversal against ray casters that return distances only.
    pub depth_only: bool,
}

/// A half-open rectangle of pixels, `x[0] <= x < x[1]`, `y[0] <= y < y[1]`, row 0 at the top.
/// When its corners are multiples of the tile side (16) times the progressive scale (or the
/// image's edges), the frame is exactly these pixels; otherwise it is every tile it overlaps.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct PixelRegion {
    pub x: [u32; 2],
    pub y: [u32; 2],
}

impl PixelRegion {
    /// Number of pixels it covers.
    pub fn pixels(&self) -> usize {
        (self.x[1].saturating_sub(self.x[0]) as usize)
            * (self.y[1].saturating_sub(self.y[0]) as usize)
    }
}

impl Default for RenderSettings {
    fn default() -> Self {
        Self {
            width: 512,
            height: 512,
            surfaces: Vec::new(),
            clips: Vec::new(),
            max_layers: 4,
            shadows: false,
            light: Light::default(),
            background: [0.08, 0.08, 0.1],
            collect_stats: false,
            scale: 1,
            packets: true,
            supersample: 1,
            region: None,
            depth_only: false,
        }
    }
}

/// Largest accepted image side (keeps `width·height·4` far from overflow).
pub const MAX_IMAGE_SIDE: u32 = 1 << 15;

/// Settings the renderer refuses.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum SettingsError {
    #[error("image size {width}x{height} must be between 1x1 and {max}x{max}", max = MAX_IMAGE_SIDE)]
    ImageSize { width: u32, height: u32 },
    #[error("surface {index}: isovalue {value} is not finite")]
    Isovalue { index: usize, value: f32 },
    #[error("surface {index}: opacity {value} is outside [0, 1]")]
    Opacity { index: usize, value: f32 },
    #[error("surface {index}: color {value:?} is outside [0, 1]")]
    Color { index: usize, value: [f32; 3] },
    #[error("surface {index}: color range {min} .. {max} must be finite with min < max")]
    ColorRange { index: usize, min: f32, max: f32 },
    #[error("clip region {index}: {reason}")]
    Clip { index: usize, reason: String },
    #[error("light: {0}")]
    Light(String),
    #[error("background color {0:?} is outside [0, 1]")]
    Background([f32; 3]),
    #[error("scale must be at least 1")]
    Scale,
    #[error(
        "supersampling {k} must be between 1 and {max}, and the image size times it at most {side}",
        max = crate::render::supersample::MAX_SUPERSAMPLE,
        side = MAX_IMAGE_SIDE
    )]
    Supersample { k: u32 },
    #[error("region x {x:?}, y {y:?} must be non-empty and inside the {width}x{height} image")]
    Region {
        x: [u32; 2],
        y: [u32; 2],
        width: u32,
        height: u32,
    },
}

fn unit_color(c: [f32; 3]) -> bool {
    c.iter().all(|x| (0.0..=1.0).contains(x))
}

impl RenderSettings {
    /// Checks every field; the renderer itself never panics on bad settings but may then
    /// draw nonsense (e.g. a NaN isovalue is skipped).
    pub fn validate(&self) -> Result<(), SettingsError> {
        if self.width == 0
            || self.height == 0
            || self.width > MAX_IMAGE_SIDE
            || self.height > MAX_IMAGE_SIDE
        {
            return Err(SettingsError::ImageSize {
                width: self.width,
                height: self.height,
            });
        }
        for (index, s) in self.surfaces.iter().enumerate() {
            if !s.isovalue.is_finite() {
                return Err(SettingsError::Isovalue {
                    index,
                    value: s.isovalue,
                });
            }
            if !(0.0..=1.0).contains(&s.opacity) {
                return Err(SettingsError::Opacity {
                    index,
                    value: s.opacity,
                });
            }
            if !unit_color(s.color) {
                return Err(SettingsError::Color {
                    index,
                    value: s.color,
                });
            }
            if let Some([min, max]) = s.color_by.as_ref().and_then(|c| c.range)
                && !(min.is_finite() && max.is_finite() && min < max)
            {
                return Err(SettingsError::ColorRange { index, min, max });
            }
        }
        for (index, c) in self.clips.iter().enumerate() {
            let reason = match *c {
                ClipRegion::Box { min, max, .. } => {
                    if !(min.is_finite() && max.is_finite()) {
                        Some("box corners must be finite".to_string())
                    } else if min.cmpgt(max).any() {
                        Some(format!("box min {min} exceeds max {max} on some axis"))
                    } else {
                        None
                    }
                }
                ClipRegion::Plane { normal, offset } => {
                    if !(normal.is_finite() && offset.is_finite()) {
                        Some("plane normal and offset must be finite".to_string())
                    } else if normal.length_squared() == 0.0 {
                        Some("plane normal is zero".to_string())
                    } else {
                        None
                    }
                }
            };
            if let Some(reason) = reason {
                return Err(SettingsError::Clip { index, reason });
            }
        }
        match self.light.kind {
            LightKind::Headlight => {}
            LightKind::Directional { dir } => {
                if !dir.is_finite() || dir.length_squared() == 0.0 {
                    return Err(SettingsError::Light(format!(
                        "direction {dir} must be finite and non-zero"
                    )));
                }
            }
            LightKind::Point { pos } => {
                if !pos.is_finite() {
                    return Err(SettingsError::Light(format!(
                        "position {pos} is not finite"
                    )));
                }
            }
        }
        let l = &self.light;
        if ![l.ambient, l.diffuse, l.specular, l.shininess, l.fill]
            .iter()
            .all(|x| x.is_finite() && *x >= 0.0)
        {
            return Err(SettingsError::Light(
                "ambient, diffuse, specular, shininess and fill must be finite and >= 0".into(),
            ));
        }
        if !unit_color(self.background) {
            return Err(SettingsError::Background(self.background));
        }
        if self.scale == 0 {
            return Err(SettingsError::Scale);
        }
        let k = self.supersample;
        let max_side = self.width.max(self.height);
        if k == 0
            || k > crate::render::supersample::MAX_SUPERSAMPLE
            || max_side.saturating_mul(k) > MAX_IMAGE_SIDE
        {
            return Err(SettingsError::Supersample { k });
        }
        if let Some(PixelRegion { x, y }) = self.region
            && !(x[0] < x[1] && x[1] <= self.width && y[0] < y[1] && y[1] <= self.height)
        {
            return Err(SettingsError::Region {
                x,
                y,
                width: self.width,
                height: self.height,
            });
        }
        Ok(())
    }

    /// The isovalues passed to the scene (active surfaces only, in list order) and, for each,
    /// the index of its surface in `surfaces`.
    pub fn active_isovalues(&self) -> (Vec<f32>, Vec<usize>) {
        self.surfaces
            .iter()
            .enumerate()
            .filter(|(_, s)| s.is_active())
            .map(|(i, s)| (s.isovalue, i))
            .unzip()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn validation_rejects_bad_fields() {
        let mut s = RenderSettings {
            surfaces: vec![Surface::new(0.5, [1.0, 0.5, 0.0])],
            ..RenderSettings::default()
        };
        assert_eq!(s.validate(), Ok(()));
        s.surfaces[0].opacity = 1.5;
        assert!(matches!(
            s.validate(),
            Err(SettingsError::Opacity { index: 0, .. })
        ));
        s.surfaces[0].opacity = 1.0;
        s.clips.push(ClipRegion::Plane {
            normal: Vec3::ZERO,
            offset: 0.0,
        });
        assert!(matches!(
            s.validate(),
            Err(SettingsError::Clip { index: 0, .. })
        ));
        s.clips.clear();
        s.width = 0;
        assert!(matches!(s.validate(), Err(SettingsError::ImageSize { .. })));
    }

    #[test]
    fn only_active_surfaces_are_traced() {
        let mut hidden = Surface::new(2.0, [0.0; 3]);
        hidden.visible = false;
        let mut clear = Surface::new(3.0, [0.0; 3]);
        clear.opacity = 0.0;
        let s = RenderSettings {
            surfaces: vec![
                Surface::new(1.0, [0.0; 3]),
                hidden,
                clear,
                Surface::new(4.0, [0.0; 3]),
            ],
            ..RenderSettings::default()
        };
        assert_eq!(s.active_isovalues(), (vec![1.0, 4.0], vec![0, 3]));
    }

    #[test]
    fn surfaces_without_a_colouring_still_load_and_ranges_are_checked() {
        // A surface as sessions saved it before colouring existed.
        let old = r#"{"isovalue":0.5,"color":[1.0,0.5,0.0],"opacity":1.0,"visible":true}"#;
        let s: Surface = serde_json::from_str(old).unwrap();
        assert_eq!(s, Surface::new(0.5, [1.0, 0.5, 0.0]));
        // A colouring with only its field given takes the defaults.
        let json = r#"{"isovalue":0.5,"color":[1.0,0.5,0.0],"opacity":1.0,"visible":true,
            "color_by":{"field":{"field":"pressure"}}}"#;
        let s: Surface = serde_json::from_str(json).unwrap();
        let c = s.color_by.clone().unwrap();
        assert_eq!(c, ColorBy::new(ColorField::Field("pressure".into())));
        assert!(c.scalar_bar && c.range.is_none() && c.colormap == Colormap::Viridis);
        let mut settings = RenderSettings {
            surfaces: vec![s],
            ..RenderSettings::default()
        };
        assert_eq!(settings.validate(), Ok(()));
        settings.surfaces[0].color_by = Some(ColorBy {
            range: Some([2.0, 2.0]),
            ..ColorBy::new(ColorField::Gradient)
        });
        assert!(matches!(
            settings.validate(),
            Err(SettingsError::ColorRange { index: 0, .. })
        ));
        let back: RenderSettings =
            serde_json::from_str(&serde_json::to_string(&settings).unwrap()).unwrap();
        assert_eq!(back, settings);
    }

    #[test]
    fn settings_json_round_trip() {
        let s = RenderSettings {
            clips: vec![
                ClipRegion::Box {
                    min: Vec3::ZERO,
                    max: Vec3::ONE,
                    keep: Keep::Outside,
                },
                ClipRegion::Plane {
                    normal: Vec3::X,
                    offset: 0.5,
                },
            ],
            light: Light {
                kind: LightKind::Directional { dir: Vec3::ONE },
                ..Light::default()
            },
            ..RenderSettings::default()
        };
        let json = serde_json::to_string(&s).unwrap();
        let back: RenderSettings = serde_json::from_str(&json).unwrap();
        assert_eq!(back, s);
    }
}
