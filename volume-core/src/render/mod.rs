//! Rendering: the [`scene::IsoScene`] contract that acceleration structures implement, and
//! the one renderer built on it (shared by rectilinear and tetrahedral data, the CLI and the
//! GUI).
//!
//! - [`camera`]: pinhole/orthographic [`Camera`] (JSON), primary rays, orbit framing.
//! - [`settings`]: [`Surface`]s (isovalue, colour, opacity), [`ClipRegion`]s, the [`Light`]
//!   and [`RenderSettings`].
//! - [`clip`]: the kept parameter intervals of a ray under any number of clip regions.
//! - [`colormap`]: viridis, magma, coolwarm and grey, for surfaces coloured by another field
//!   ([`ColorBy`]; the field is sampled at each shaded hit through a [`HitField`]).
//! - [`renderer`]: [`render`] / [`render_into`] (reuses the frame's buffers) — tiles over rayon, primary packets, transparency by depth
//!   peeling, shadow rays, progressive scale, cancellation — producing a [`Frame`]
//!   (RGBA8 + first-hit depth + statistics).
//! - [`supersample`]: anti-aliasing, `k × k` samples per pixel averaged (box filter).
//! - [`analytic`]: an exact sphere-field scene, the truth for renderer tests.
//!
//! The renderer only talks to data through [`IsoScene`], so it is generic over the
//! acceleration structure and monomorphized (no dynamic dispatch per ray).

pub mod analytic;
pub mod camera;
pub mod clip;
pub mod colormap;
mod coverage;
pub mod renderer;
pub mod scene;
pub mod settings;
mod shade;
pub mod supersample;

pub use camera::{Camera, CameraError, Projection, RayGen};
pub use colormap::Colormap;
pub use renderer::{
    Frame, RayCounts, SurfaceColoring, TILE, render, render_colored_into, render_into,
};
pub use scene::{
    CountStats, Hit, HitField, IsoScene, MAX_PEELED, NoStats, Normals, Peel, PeeledHits,
    SceneVisitor, Stats, TraversalCounts, WholeBounds,
};
pub use settings::{
    ClipRegion, ColorBy, ColorField, Keep, Light, LightKind, MAX_IMAGE_SIDE, PixelRegion,
    RenderSettings, SettingsError, Surface,
};
