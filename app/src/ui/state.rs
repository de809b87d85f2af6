//! Persisted viewer state: what a session file holds (files, camera, isosurfaces, clips,
//! render options, time step).
//!
//! Everything here is plain data with serde, independent of egui and of caches (loaded
//! volumes, scenes, textures live in the viewer, not here), so a session round-trips through
//! JSON exactly and tests can build states without a window.

use std::path::PathBuf;

use serde::{Deserialize, Serialize};

/// Version written into session files; bumped when a field changes meaning.
pub const SESSION_VERSION: u32 = 1;

/// The whole persisted state of the viewer.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct ViewerState {
    pub version: u32,
    /// Files shown (empty: the embedded default dataset).
    pub files: Vec<PathBuf>,
    /// Raw layout used for `files` that need one (raw files without a sidecar).
    pub raw_layout: Option<RawLayoutState>,
    pub camera: CameraState,
    /// Saved camera views.
    pub bookmarks: Vec<CameraState>,
    /// Tet meshes: the point array drawn (`None`: the mesh's first one).
    pub field: Option<String>,
    pub surfaces: Vec<SurfaceState>,
    pub clip_boxes: Vec<ClipBoxState>,
    pub clip_planes: Vec<ClipPlaneState>,
    pub render: RenderOptions,
    pub time: TimeState,
    /// TIFF stacks: the spacing of the axes the file does not record (the viewer's
    /// counterpart of `--spacing`); `None`: the file's ImageJ metadata, else 1.
    pub tiff_spacing: Option<[f64; 3]>,
}

impl Default for ViewerState {
    fn default() -> Self {
        Self {
            version: SESSION_VERSION,
            files: Vec::new(),
            raw_layout: None,
            camera: CameraState::default(),
            bookmarks: Vec::new(),
            field: None,
            surfaces: Vec::new(),
            clip_boxes: Vec::new(),
            clip_planes: Vec::new(),
            render: RenderOptions::default(),
            time: TimeState::default(),
            tiff_spacing: None,
        }
    }
}

impl ViewerState {
    /// The session as pretty JSON.
    pub fn to_json(&self) -> String {
        // Plain data with string keys only: serialization cannot fail.
        serde_json::to_string_pretty(self).unwrap_or_default()
    }

    /// Parses a session; unknown fields are ignored, missing ones take defaults.
    pub fn from_json(text: &str) -> Result<Self, String> {
        let state: Self = serde_json::from_str(text).map_err(|e| {
            match e
                .to_string()
                .contains("out of range")
                .then(|| field_beyond_f32(text))
                .flatten()
            {
                Some(field) => format!("not a session file: {field} is not a finite number ({e})"),
                None => format!("not a session file: {e}"),
            }
        })?;
        if state.version > SESSION_VERSION {
            return Err(format!(
                "session version {} is newer than this viewer ({SESSION_VERSION})",
                state.version
            ));
        }
        if let Some(field) = state.non_finite_field() {
            return Err(format!(
                "not a session file: {field} is not a finite number"
            ));
        }
        Ok(state)
    }

    /// The first number that is infinite (JSON has no infinity or NaN, but a value beyond
    /// `f32`, e.g. `1e39`, reads as infinity): saved, it would be written as `null`, and the
    /// saved session would no longer load.
    fn non_finite_field(&self) -> Option<&'static str> {
        let bad32 = |v: &[f32]| v.iter().any(|x| !x.is_finite());
        let camera = |c: &CameraState| {
            bad32(&[c.azimuth_deg, c.elevation_deg, c.zoom, c.vfov_deg]) || bad32(&c.pan)
        };
        let r = &self.render;
        [
            ("camera", camera(&self.camera)),
            ("bookmarks", self.bookmarks.iter().any(camera)),
            (
                "surfaces",
                self.surfaces
                    .iter()
                    .any(|s| !s.isovalue.is_finite() || bad32(&s.color) || !s.opacity.is_finite()),
            ),
            (
                "clip_boxes",
                self.clip_boxes
                    .iter()
                    .any(|b| bad32(&b.min) || bad32(&b.max)),
            ),
            (
                "clip_planes",
                self.clip_planes
                    .iter()
                    .any(|p| bad32(&p.normal) || !p.offset.is_finite()),
            ),
            (
                "render",
                bad32(&[r.light_azimuth_deg, r.light_elevation_deg]) || bad32(&r.background),
            ),
            ("time", !self.time.fps.is_finite()),
            (
                "raw_layout",
                self.raw_layout
                    .as_ref()
                    .is_some_and(|l| l.spacing.iter().any(|x| !x.is_finite())),
            ),
            (
                "tiff_spacing",
                self.tiff_spacing
                    .is_some_and(|s| s.iter().any(|x| !(x.is_finite() && *x > 0.0))),
            ),
        ]
        .into_iter()
        .find_map(|(name, bad)| bad.then_some(name))
    }
}

/// Orbit camera around the centre of the data bounds (z up).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct CameraState {
    pub azimuth_deg: f32,
    /// Clamped to ±[`Self::MAX_ELEVATION_DEG`] so that the up vector stays defined.
    pub elevation_deg: f32,
    /// Distance as a multiple of the distance at which the bounding sphere fits the view.
    pub zoom: f32,
    /// Target offset from the bounds centre along the view's right/up axes, in bounding radii.
    pub pan: [f32; 2],
    pub vfov_deg: f32,
    pub orthographic: bool,
}

impl Default for CameraState {
    fn default() -> Self {
        Self {
            azimuth_deg: 35.0,
            elevation_deg: 25.0,
            zoom: 1.0,
            pan: [0.0, 0.0],
            vfov_deg: 40.0,
            orthographic: false,
        }
    }
}

impl CameraState {
    pub const MIN_ZOOM: f32 = 0.05;
    pub const MAX_ZOOM: f32 = 20.0;
    /// The steepest elevation: the superior and inferior views look down and up at it.
    pub const MAX_ELEVATION_DEG: f32 = 89.9;

    /// Orbits by a drag of `(dx, dy)` degrees.
    pub fn orbit(&mut self, d_azimuth_deg: f32, d_elevation_deg: f32) {
        self.azimuth_deg = (self.azimuth_deg + d_azimuth_deg).rem_euclid(360.0);
        self.elevation_deg = (self.elevation_deg + d_elevation_deg)
            .clamp(-Self::MAX_ELEVATION_DEG, Self::MAX_ELEVATION_DEG);
    }

    /// Multiplies the distance by `factor` (< 1 moves closer).
    pub fn zoom_by(&mut self, factor: f32) {
        if factor.is_finite() && factor > 0.0 {
            self.zoom = (self.zoom * factor).clamp(Self::MIN_ZOOM, Self::MAX_ZOOM);
        }
    }

    /// Moves the target by `(dx, dy)` bounding radii in the view plane.
    pub fn pan_by(&mut self, dx: f32, dy: f32) {
        self.pan[0] += dx;
        self.pan[1] += dy;
    }
}

/// One isosurface.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SurfaceState {
    pub isovalue: f64,
    /// Linear RGB in [0, 1].
    pub color: [f32; 3],
    pub opacity: f32,
    pub visible: bool,
    /// Colour by another field through a colormap (`None`: the flat `color`); sessions
    /// saved before colouring existed load as `None`.
    #[serde(default)]
    pub color_by: Option<volume_core::render::ColorBy>,
}

/// Colors given to new surfaces in turn.
pub const SURFACE_PALETTE: [[f32; 3]; 6] = [
    [0.90, 0.75, 0.55],
    [0.35, 0.60, 0.95],
    [0.90, 0.35, 0.30],
    [0.45, 0.80, 0.45],
    [0.85, 0.55, 0.90],
    [0.95, 0.85, 0.30],
];

impl SurfaceState {
    pub fn new(isovalue: f64, index: usize) -> Self {
        Self {
            isovalue,
            color: SURFACE_PALETTE[index % SURFACE_PALETTE.len()],
            opacity: 1.0,
            visible: true,
            color_by: None,
        }
    }
}

/// Which side of a clip region stays visible.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
pub enum KeepSide {
    #[default]
    Inside,
    Outside,
}

/// A clip box, per axis as fractions of the data bounds (0 = min face, 1 = max face), so a
/// session stays meaningful when the spacing of the data changes.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ClipBoxState {
    pub enabled: bool,
    pub keep: KeepSide,
    pub min: [f32; 3],
    pub max: [f32; 3],
}

impl Default for ClipBoxState {
    fn default() -> Self {
        Self {
            enabled: true,
            keep: KeepSide::Inside,
            min: [0.0; 3],
            max: [0.5, 1.0, 1.0],
        }
    }
}

/// A clip plane through `centre + offset·radius·n`; the side the normal points to is removed.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ClipPlaneState {
    pub enabled: bool,
    pub normal: [f32; 3],
    /// Signed distance from the bounds centre, in bounding radii.
    pub offset: f32,
}

impl Default for ClipPlaneState {
    fn default() -> Self {
        Self {
            enabled: true,
            normal: [1.0, 0.0, 0.0],
            offset: 0.0,
        }
    }
}

/// Shading normals ([`volume_core::render::Normals`]): faceted (the gradient of the hit
/// cell's own interpolant) or smooth (vertex gradients interpolated).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum NormalsChoice {
    Faceted,
    Smooth,
}

/// The intersectors of thesis seed 004 §7.2.2 plus the f64 reference.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize, Default)]
pub enum IntersectorChoice {
    Linear,
    Neubauer,
    #[default]
    Exact,
    Schwarze,
    Reference,
}

impl IntersectorChoice {
    pub const ALL: [IntersectorChoice; 5] = [
        Self::Linear,
        Self::Neubauer,
        Self::Exact,
        Self::Schwarze,
        Self::Reference,
    ];

    /// The name used on the command line (`--intersector`).
    pub fn cli_name(self) -> &'static str {
        match self {
            Self::Linear => "linear",
            Self::Neubauer => "neubauer",
            Self::Exact => "exact",
            Self::Schwarze => "schwarze",
            Self::Reference => "reference",
        }
    }

    /// One line on the speed/accuracy trade (docs/accuracy.md has the measurements).
    pub fn note(self) -> &'static str {
        match self {
            Self::Linear => {
                "fastest; interpolates between the cell entry and exit values, can miss thin features"
            }
            Self::Neubauer => "fast; a few secant steps (3), small errors, can miss double roots",
            Self::Exact => {
                "default; iterative root isolation of the cubic (thesis Listing 7.1), no misses"
            }
            Self::Schwarze => {
                "analytic Cardano roots; exact in theory, loses precision in some cells"
            }
            Self::Reference => "f64 root isolation to full precision; slowest, for checking",
        }
    }
}

/// Render options that do not depend on the data.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct RenderOptions {
    pub intersector: IntersectorChoice,
    /// Transparency layers (depth-peeling steps) for surfaces with opacity < 1.
    pub max_layers: u32,
    pub shadows: bool,
    /// Light direction (towards the light) relative to the view: azimuth and elevation in
    /// degrees; (0, 0) is a headlight.
    pub light_azimuth_deg: f32,
    pub light_elevation_deg: f32,
    /// Linear RGB in [0, 1].
    pub background: [f32; 3],
    /// Shading normals; `None` until the user picks: the data's default (meshes faceted,
    /// the data as computed; grids smooth, central differences, thesis 004 §6.4).
    pub normals: Option<NormalsChoice>,
    /// The orientation marker in the viewport's corner.
    pub orientation_marker: bool,
    /// Anti-aliasing of the still (full-resolution) frame: `k × k` samples per pixel; 1 is
    /// off. Frames while the view moves are never supersampled.
    pub supersample: u32,
    /// Flat: each pixel's first hit in its surface's flat colour, no lighting, shadows or
    /// transparency (`RenderSettings::depth_only`; grids skip the shading normal).
    pub flat: bool,
}

impl Default for RenderOptions {
    fn default() -> Self {
        Self {
            intersector: IntersectorChoice::Exact,
            max_layers: 4,
            shadows: false,
            light_azimuth_deg: 0.0,
            light_elevation_deg: 0.0,
            background: [0.08, 0.08, 0.10],
            normals: None,
            orientation_marker: true,
            supersample: 1,
            flat: false,
        }
    }
}

/// Time-series playback.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct TimeState {
    pub step: usize,
    /// Not restored from sessions as `true`: a restored session starts paused.
    #[serde(skip)]
    pub playing: bool,
    pub looping: bool,
    pub fps: f32,
}

impl Default for TimeState {
    fn default() -> Self {
        Self {
            step: 0,
            playing: false,
            looping: true,
            fps: 5.0,
        }
    }
}

impl TimeState {
    /// The step after `step` for `count` steps, honoring `looping`; `None` at the end.
    pub fn next_step(&self, count: usize) -> Option<usize> {
        if count == 0 {
            return None;
        }
        if self.step + 1 < count {
            Some(self.step + 1)
        } else if self.looping {
            Some(0)
        } else {
            None
        }
    }
}

/// Raw-file layout as entered in the raw dialog (mirrors `formats::raw::RawLayout`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RawLayoutState {
    pub dims: [usize; 3],
    /// Voxel type name as on the command line: u8, i8, u16, i16, u32, i32, f32, f64.
    pub voxel_type: String,
    pub little_endian: bool,
    pub header_bytes: u64,
    pub spacing: [f64; 3],
}

impl Default for RawLayoutState {
    fn default() -> Self {
        Self {
            dims: [64, 64, 64],
            voxel_type: "u8".into(),
            little_endian: true,
            header_bytes: 0,
            spacing: [1.0; 3],
        }
    }
}

/// The top-level field of a session that holds a number beyond `f32` (which serde_json,
/// reading floats exactly, refuses for an `f32` field as out of range), to name it.
fn field_beyond_f32(text: &str) -> Option<String> {
    fn beyond(v: &serde_json::Value) -> bool {
        match v {
            serde_json::Value::Number(n) => {
                n.as_f64().is_some_and(|x| x.abs() > f64::from(f32::MAX))
            }
            serde_json::Value::Array(a) => a.iter().any(beyond),
            serde_json::Value::Object(o) => o.values().any(beyond),
            _ => false,
        }
    }
    let v: serde_json::Value = serde_json::from_str(text).ok()?;
    v.as_object()?
        .iter()
        .find(|(_, x)| beyond(x))
        .map(|(k, _)| k.clone())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sessions_without_colouring_load_and_colourings_round_trip() {
        // A surface as sessions saved it before colouring existed.
        let old = r#"{"surfaces":[{"isovalue":0.5,"color":[1.0,0.5,0.0],"opacity":1.0,
            "visible":true}]}"#;
        let s = ViewerState::from_json(old).unwrap();
        assert_eq!(s.surfaces.len(), 1);
        assert_eq!(s.surfaces[0].color_by, None);
        let mut s = s;
        s.surfaces[0].color_by = Some(volume_core::render::ColorBy {
            colormap: volume_core::render::Colormap::Coolwarm,
            range: Some([-1.0, 2.5]),
            scalar_bar: false,
            ..volume_core::render::ColorBy::new(volume_core::render::ColorField::Gradient)
        });
        assert_eq!(ViewerState::from_json(&s.to_json()).unwrap(), s);
    }

    #[test]
    fn session_round_trips_through_json() {
        let mut s = ViewerState {
            files: vec![PathBuf::from("/data/ct.nrrd")],
            ..ViewerState::default()
        };
        s.surfaces.push(SurfaceState::new(0.5, 0));
        s.surfaces.push(SurfaceState {
            opacity: 0.25,
            visible: false,
            ..SurfaceState::new(-3.0, 1)
        });
        s.clip_boxes.push(ClipBoxState {
            keep: KeepSide::Outside,
            ..ClipBoxState::default()
        });
        s.clip_planes.push(ClipPlaneState::default());
        s.camera.orbit(100.0, 30.0);
        s.render.intersector = IntersectorChoice::Schwarze;
        s.time.step = 7;
        s.field = Some("pressure".into());
        let back = ViewerState::from_json(&s.to_json()).unwrap();
        assert_eq!(back, s);
    }

    #[test]
    fn session_defaults_fill_missing_fields_and_newer_versions_are_rejected() {
        let s = ViewerState::from_json(r#"{"files":["a.nrrd"],"extra":1}"#).unwrap();
        assert_eq!(s.files, vec![PathBuf::from("a.nrrd")]);
        assert_eq!(s.camera, CameraState::default());
        assert!(ViewerState::from_json(r#"{"version":99}"#).is_err());
        assert!(ViewerState::from_json("[1,2").is_err());
    }

    #[test]
    fn camera_limits_hold() {
        let mut c = CameraState::default();
        c.orbit(400.0, 200.0);
        assert!((c.azimuth_deg - 75.0).abs() < 1e-4);
        assert_eq!(c.elevation_deg, CameraState::MAX_ELEVATION_DEG);
        c.zoom_by(1e-9);
        assert_eq!(c.zoom, CameraState::MIN_ZOOM);
        c.zoom_by(f32::NAN);
        assert_eq!(c.zoom, CameraState::MIN_ZOOM);
    }

    #[test]
    fn time_steps_wrap_only_when_looping() {
        let mut t = TimeState {
            step: 4,
            ..TimeState::default()
        };
        assert_eq!(t.next_step(5), Some(0));
        t.looping = false;
        assert_eq!(t.next_step(5), None);
        t.step = 2;
        assert_eq!(t.next_step(5), Some(3));
        assert_eq!(t.next_step(0), None);
    }
}
