//! The tiled renderer: primary packets, transparency peeling, shadows and clipping.
//!
//! The image is cut into tiles of 16×16 *samples* (a sample is one pixel, or one
//! `scale × scale` block when rendering progressively). A row of tiles is a *band* of the
//! frame; rayon renders the bands in parallel (`par_chunks_mut` over the frame's buffers) and
//! each band renders its tiles left to right straight into its own rows, so there is no
//! serial assembly pass and no per-tile output buffer. Each tile is independent, so the
//! output is the same whatever the thread count or schedule. [`render_into`] reuses the
//! caller's [`Frame`] buffers; [`render`] allocates a new one.
//!
//! Inside a tile, rays are ordered along a Morton curve, so every aligned run of 4, 8, 16, …
//! rays covers a compact 2×2, 4×2, 4×4, … block (good packets for 4- and 8-wide SIMD
//! traversal and for frusta). Rays come from per-column and per-row camera terms computed
//! once per tile (`RayGen::column`, `RayGen::row`), bit-identical to
//! [`RayGen::ray_at`]; the same 8-wide pass cuts them to the scene's live bounds
//! ([`IsoScene::live_bounds`]: for grids, the box of the kd-tree nodes that hold an isovalue,
//! a cell wider; bit-identical to [`Aabb::intersect`]); a tile outside the live box's
//! projection (`RayGen::screen_rect`) makes no rays at all, nor does a sample outside the
//! projections of the scene's smaller live boxes ([`IsoScene::live_boxes`]: for grids, the
//! kd-tree's live nodes at a coarse level; `render::coverage`). Only samples whose ray meets
//! them (and, when there are clip regions, keeps a clip interval, [`super::clip`]) get a
//! per-ray state; the tile is painted
//! with the background first and only those samples are composited over it. Then the tile runs
//! in *rounds*: every still-active ray is traced from its current `t_from` to the end of its
//! current interval, all together through [`IsoScene::first_hit_packet_prepared`] (the first round's
//! packet is built while the rays are generated). A hit is shaded and composited front to
//! back; an opaque hit (or the layer limit) ends the ray, a transparent one lets it go on
//! from just past the hit (thesis seed 004 §8.6, "transparent depth peeling"). The scene
//! returns several layers per ray at once where its traversal can go on past a hit
//! ([`IsoScene::peeled_hits_packet_prepared`]: the kd-tree packets carry a lane on through
//! the following cells instead of a new ray descending from the root); otherwise the next
//! round shoots the ray again with its minimum distance past the hit. A ray with nothing
//! more in its interval moves to its next kept interval. A round's shadow rays (one per lit hit and kept clip
//! interval) are traced together as one packet after its hits are found (they share the
//! light's direction, or aim at one point light: coherent), then the hits are shaded. The
//! isovalues are prepared once per call ([`IsoScene::prepare`]).
//!
//! Depth-only frames ([`RenderSettings::depth_only`]) find one layer per ray: every surface
//! counts as opaque, there are no shadow rays, and a hit is painted in its surface's
//! flat colour without lighting; the isovalues are prepared with
//! [`IsoScene::prepare_distances`], so scenes skip the shading normal they would otherwise
//! compute for every hit. The hits, and so the depth map, are the shaded frame's.
//!
//! Colouring by another field ([`render_colored_into`]): a surface with a
//! [`SurfaceColoring`] takes its base colour from the colormap of a [`HitField`] sampled at
//! the hit, once per shaded hit, before lighting; without one it costs one branch per
//! shaded hit and nothing during traversal.
//!
//! Statistics and shadows are compile-time parameters, so when they are off their code is not
//! in the loop at all. Per-tile buffers live in a per-thread scratch kept from frame to
//! frame: nothing is allocated per ray or per tile, and the buffers are sized once per
//! thread (a scratch per rayon job was made and sized about 12 times a frame with 2 threads).

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use glam::Vec3;
use rayon::prelude::*;

use crate::math::{Aabb, Interval, Ray};
use crate::render::camera::{Camera, RayGen};
use crate::render::clip::kept_intervals;
use crate::render::colormap::Colormap;
use crate::render::coverage::Coverage;
use crate::render::scene::{
    CountStats, Hit, HitField, IsoScene, MAX_PEELED, NoStats, Peel, PeeledHits, Stats,
    TraversalCounts,
};
use crate::render::settings::{PixelRegion, RenderSettings};
use crate::render::shade::Shader;

/// Tile side in samples.
pub const TILE: u32 = 16;

/// Transmittance below which a pixel counts as opaque (invisible in 8-bit output).
const OPAQUE_TRANSMITTANCE: f32 = 1.0 / 1024.0;

/// Rays cast for one frame, by purpose.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct RayCounts {
    /// One per sample (pixel at full resolution), whether or not it meets the volume.
    pub primary: u64,
    /// Transparent hits a ray went on past (within the scene's traversal, or as a new
    /// segment shot from past the hit).
    pub transparency: u64,
    /// Shadow rays.
    pub shadow: u64,
}

impl RayCounts {
    fn add(&mut self, o: &RayCounts) {
        self.primary += o.primary;
        self.transparency += o.transparency;
        self.shadow += o.shadow;
    }
}

/// A rendered image. `Frame::default()` is an empty frame to hand to [`render_into`].
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Frame {
    pub width: u32,
    pub height: u32,
    /// The progressive scale it was rendered at (1 = every pixel traced).
    pub scale: u32,
    /// Row-major RGBA, row 0 at the top, alpha always 255.
    pub rgba8: Vec<u8>,
    /// First-hit distance per pixel (world units along the unit ray direction), row 0 at the
    /// top, `inf` where the ray hits no surface. The first hit, even if transparent.
    pub depth: Vec<f32>,
    /// Traversal statistics (all zero unless `collect_stats`).
    pub counts: TraversalCounts,
    pub rays: RayCounts,
    pub elapsed: Duration,
}

/// A surface's colouring resolved for one frame: the field sampled at its hits, and the
/// colormap over `range` (`[min, max]`, values outside clamped) it is shown through.
#[derive(Clone, Copy)]
pub struct SurfaceColoring<'a> {
    pub field: &'a dyn HitField,
    pub colormap: Colormap,
    pub range: [f32; 2],
}

impl std::fmt::Debug for SurfaceColoring<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SurfaceColoring")
            .field("colormap", &self.colormap)
            .field("range", &self.range)
            .finish_non_exhaustive()
    }
}

impl SurfaceColoring<'_> {
    /// The base colour at world position `p` of a hit in `cell`; `flat` where the field has
    /// no value (NaN).
    #[inline]
    pub fn color_at(&self, p: Vec3, cell: u32, flat: [f32; 3]) -> [f32; 3] {
        let v = self.field.value_at(p, cell);
        if v.is_nan() {
            flat
        } else {
            self.colormap.map(v, self.range)
        }
    }
}

/// Renders `scene` as seen by `camera`. Returns `None` if `cancel` was set before the frame
/// finished (checked once per tile).
///
/// Check `camera.validate()` and `settings.validate()` first: bad input does not panic here
/// but draws a fallback (degenerate cameras look along −z, non-finite isovalues are skipped).
pub fn render<S: IsoScene>(
    scene: &S,
    camera: &Camera,
    settings: &RenderSettings,
    cancel: &AtomicBool,
) -> Option<Frame> {
    let mut frame = Frame::default();
    render_into(scene, camera, settings, cancel, &mut frame).then_some(frame)
}

/// [`render`] into an existing frame, reusing its buffers (no allocation once they are big
/// enough: interactive callers keep one or two frames and render into them). Supersampling
/// (`settings.supersample > 1`) is the exception: it allocates the `k`-times larger frame on
/// each call, which is meant for still frames and image outputs, not for interaction.
///
/// Returns `false` if `cancel` was set before the frame finished; the frame's contents are
/// then unspecified (partly the new picture), but it stays a valid buffer to render into
/// again. On `true` every field of `frame` describes the new picture.
pub fn render_into<S: IsoScene>(
    scene: &S,
    camera: &Camera,
    settings: &RenderSettings,
    cancel: &AtomicBool,
    frame: &mut Frame,
) -> bool {
    render_colored_into(scene, camera, settings, &[], cancel, frame)
}

/// [`render_into`] with surfaces coloured by other fields: `colorings[i]` (when present
/// and `Some`) gives surface `i` of `settings.surfaces` its base colour at each hit; the
/// others keep their flat colour. [`crate::render::Surface::color_by`] only describes a
/// colouring: the caller resolves it into a [`SurfaceColoring`].
pub fn render_colored_into<S: IsoScene>(
    scene: &S,
    camera: &Camera,
    settings: &RenderSettings,
    colorings: &[Option<SurfaceColoring<'_>>],
    cancel: &AtomicBool,
    frame: &mut Frame,
) -> bool {
    let k = settings.supersample;
    if k > 1 && settings.scale <= 1 {
        // Out-of-range factors are refused by `validate`; here they only stay in bounds.
        let k = k.min(crate::render::supersample::MAX_SUPERSAMPLE);
        let fine_settings = RenderSettings {
            width: settings.width.saturating_mul(k),
            height: settings.height.saturating_mul(k),
            supersample: 1,
            region: settings.region.map(|r| PixelRegion {
                x: r.x.map(|v| v.saturating_mul(k)),
                y: r.y.map(|v| v.saturating_mul(k)),
            }),
            ..settings.clone()
        };
        let mut fine = Frame::default();
        if !render_colored_into(scene, camera, &fine_settings, colorings, cancel, &mut fine) {
            return false;
        }
        crate::render::supersample::downsample_into(&fine, k, frame);
        return true;
    }
    let shadows =
        settings.shadows && !settings.depth_only && Shader::new(&settings.light).casts_shadows();
    let c = colorings;
    match (settings.collect_stats, shadows) {
        (false, false) => {
            render_impl::<S, NoStats, false>(scene, camera, settings, c, cancel, frame)
        }
        (false, true) => render_impl::<S, NoStats, true>(scene, camera, settings, c, cancel, frame),
        (true, false) => {
            render_impl::<S, CountStats, false>(scene, camera, settings, c, cancel, frame)
        }
        (true, true) => {
            render_impl::<S, CountStats, true>(scene, camera, settings, c, cancel, frame)
        }
    }
}

/// Frame-wide constants shared by all tiles.
struct Ctx<'a, I> {
    settings: &'a RenderSettings,
    /// Per surface of `settings.surfaces`, its colouring (shorter or empty: flat colours).
    colorings: &'a [Option<SurfaceColoring<'a>>],
    raygen: RayGen,
    shader: Shader,
    isovalues: Vec<f32>,
    /// `isovalues` as the scene prepared them, once for the frame ([`IsoScene::prepare`]).
    isos: I,
    /// With shadows, `isovalues` prepared for distances ([`IsoScene::prepare_distances`]):
    /// a shadow ray only darkens its pixel, so its hits need no normal.
    shadow_isos: Option<I>,
    surface_of: Vec<usize>,
    /// Where rays are traced: the scene's [`IsoScene::live_bounds`] for `isos`.
    bounds: Aabb,
    /// Pixels outside this rectangle see no part of `bounds` ([`RayGen::screen_rect`]):
    /// their tiles make no rays at all.
    screen: Option<[f32; 4]>,
    /// The samples that may see one of the scene's live boxes ([`IsoScene::live_boxes`]);
    /// the others make no ray. `None`: every sample may.
    cover: Option<Coverage>,
    /// How rays go on past transparent hits: the surfaces that end a ray, the hits per
    /// traversal call and the distance past a hit where the next is sought.
    peel: Peel,
    /// Some surface lets rays through and more than one layer is composited: rounds ask the
    /// scene for peeled layers, not just first hits.
    peels: bool,
    /// Offset of shadow-ray origins along the facing normal, and their `t_min`.
    shadow_eps: f32,
    scale: u32,
    samples: [u32; 2],
    max_layers: u32,
    /// `(dx, dy)` of a tile's samples in Morton order.
    order: Vec<[u32; 2]>,
    /// The frame's first tile column (0 unless a region is rendered) and its width in pixels.
    tile_x0: u32,
    frame_width: u32,
}

/// One sample's progress through the rounds (its ray is `Scratch::tile_rays[pos]`).
#[derive(Debug, Clone, Copy)]
struct RayState {
    /// Current and end index into `Scratch::intervals`.
    iv: u32,
    iv_end: u32,
    t_from: f32,
    /// Layers composited so far; its [`Composite`] is set from the first on.
    layers: u32,
    /// Position in the tile, `dy · TILE + dx`.
    pos: u8,
    done: bool,
}

/// What a sample has composited, kept apart from its [`RayState`]: the rays that miss (most
/// of a frame's) never touch it, and the states they do touch stay half the size.
#[derive(Debug, Clone, Copy)]
struct Composite {
    color: Vec3,
    transmittance: f32,
    depth: f32,
}

impl Composite {
    /// Nothing composited in front of a first layer at `depth`.
    fn starting_at(depth: f32) -> Self {
        Self {
            color: Vec3::ZERO,
            transmittance: 1.0,
            depth,
        }
    }
}

impl RayState {
    /// Moves on to the next kept interval (nothing more to find in this one); false when
    /// there is none, and the sample is done.
    fn next_interval(&mut self, intervals: &[Interval]) -> bool {
        self.iv += 1;
        if self.iv < self.iv_end {
            self.t_from = intervals[self.iv as usize].lo;
            true
        } else {
            self.done = true;
            false
        }
    }

    /// A sample that starts at `t_from` in kept intervals `iv..iv_end`, nothing composited.
    fn start(iv: u32, iv_end: u32, t_from: f32, pos: u8) -> Self {
        Self {
            iv,
            iv_end,
            t_from,
            layers: 0,
            pos,
            done: false,
        }
    }
}

/// Per-thread buffers, reused from tile to tile. `states` and the round's packet (`active`,
/// `rays`, `t_min`, `t_max`, `hits`) hold at most one entry per sample of a tile: they are
/// sized to [`SLOTS`] once and written by index with the counts kept in locals (a `push`
/// per field and sample, each reloading and storing the length, was the hottest code of a
/// frame of misses in `perf`).
#[derive(Default)]
struct Scratch {
    states: Vec<RayState>,
    /// Each state's composite, valid where its `layers` is not 0.
    composites: Vec<Composite>,
    /// The tile's primary rays, row-major (`dy · TILE + dx`).
    tile_rays: Vec<Ray>,
    intervals: Vec<Interval>,
    clip_out: Vec<Interval>,
    clip_tmp: Vec<Interval>,
    /// The current round's packet: state indices, rays and segments.
    active: Vec<u32>,
    rays: Vec<Ray>,
    t_min: Vec<f32>,
    t_max: Vec<f32>,
    hits: Vec<PeeledHits>,
    /// First hits, when no surface lets rays through ([`Ctx::peels`] false).
    first: Vec<Option<Hit>>,
    /// The round's hits to shade, and their shadow rays (one per kept interval) as a packet.
    shade: Vec<PendingShade>,
    shadow_rays: Vec<Ray>,
    shadow_t_min: Vec<f32>,
    shadow_t_max: Vec<f32>,
    /// Index into `shade` of each shadow ray.
    shadow_of: Vec<u32>,
    shadow_occluded: Vec<bool>,
}

/// A hit of the current round, waiting for its shadow rays before it is shaded.
#[derive(Debug, Clone, Copy)]
struct PendingShade {
    /// Index into the round's packet.
    k: u32,
    /// Index into the settings' surfaces.
    surface: u32,
    /// The hit's primitive ([`Hit::cell`]), for colouring.
    cell: u32,
    t: f32,
    /// Normal facing the ray, and the direction to the light.
    normal: Vec3,
    to_light: Vec3,
    /// 1 when lit, 0 in shadow.
    lit: f32,
    /// The ray's last hit of the round, and whether the ray may hit more past it
    /// ([`PeeledHits::more`]).
    last: bool,
    more: bool,
}

/// Statistics and ray counts of a part of the frame.
struct Tally<St> {
    stats: St,
    rays: RayCounts,
}

impl<St: Stats> Tally<St> {
    fn new() -> Self {
        Self {
            stats: St::default(),
            rays: RayCounts::default(),
        }
    }

    fn merge(mut self, o: &Self) -> Self {
        self.stats.merge(&o.stats);
        self.rays.add(&o.rays);
        self
    }
}

/// One band of the frame: the pixel rows of one row of tiles.
struct Band<'a> {
    /// Tile row index.
    index: u32,
    rgba8: &'a mut [u8],
    depth: &'a mut [f32],
}

/// Samples per tile: the most states, and the most rays in one round, a tile has.
const SLOTS: usize = (TILE * TILE) as usize;

impl Scratch {
    /// Sizes the per-sample buffers to [`SLOTS`] (once per scratch; a no-op afterwards).
    fn fit(&mut self) {
        if self.states.len() < SLOTS {
            let state = RayState {
                done: true,
                ..RayState::start(0, 0, 0.0, 0)
            };
            self.states.resize(SLOTS, state);
            self.composites
                .resize(SLOTS, Composite::starting_at(f32::INFINITY));
            self.active.resize(SLOTS, 0);
            self.rays.resize(SLOTS, Ray::new(Vec3::ZERO, Vec3::ONE));
            self.t_min.resize(SLOTS, 0.0);
            self.t_max.resize(SLOTS, 0.0);
            self.hits.resize(SLOTS, PeeledHits::NONE);
            self.first.resize(SLOTS, None);
        }
    }
}

thread_local! {
    static SCRATCH: std::cell::RefCell<Scratch> = std::cell::RefCell::new(Scratch::default());
}

/// Runs `f` with this thread's scratch, kept from band to band and frame to frame; a
/// fresh one if it is in use (a render started from inside a band).
fn with_scratch<R>(f: impl FnOnce(&mut Scratch) -> R) -> R {
    SCRATCH.with(|cell| match cell.try_borrow_mut() {
        Ok(mut sc) => f(&mut sc),
        Err(_) => f(&mut Scratch::default()),
    })
}

/// `(dx, dy)` of the `TILE × TILE` samples of a tile in Morton order.
fn morton_order() -> Vec<[u32; 2]> {
    let mut v: Vec<[u32; 2]> = (0..TILE * TILE)
        .map(|m| {
            let (mut x, mut y) = (0, 0);
            for b in 0..8 {
                x |= ((m >> (2 * b)) & 1) << b;
                y |= ((m >> (2 * b + 1)) & 1) << b;
            }
            [x, y]
        })
        .collect();
    v.retain(|p| p[0] < TILE && p[1] < TILE);
    v
}

fn render_impl<S: IsoScene, St: Stats, const SHADOWS: bool>(
    scene: &S,
    camera: &Camera,
    settings: &RenderSettings,
    colorings: &[Option<SurfaceColoring<'_>>],
    cancel: &AtomicBool,
    frame: &mut Frame,
) -> bool {
    let start = Instant::now();
    let (width, height) = (settings.width, settings.height);
    let scale = settings.scale.max(1);
    let samples = [width.div_ceil(scale), height.div_ceil(scale)];
    // The tiles to render: all, or those overlapping `settings.region`; the frame holds
    // exactly their pixels.
    let tile_px = TILE * scale;
    let (tiles_x, tiles_y) = match settings.region {
        None => (0..samples[0].div_ceil(TILE), 0..samples[1].div_ceil(TILE)),
        Some(r) => (
            (r.x[0] / tile_px).min(samples[0].div_ceil(TILE))..r.x[1].min(width).div_ceil(tile_px),
            (r.y[0] / tile_px).min(samples[1].div_ceil(TILE))..r.y[1].min(height).div_ceil(tile_px),
        ),
    };
    let span = |tiles: &std::ops::Range<u32>, side: u32| {
        (tiles.end * tile_px)
            .min(side)
            .saturating_sub(tiles.start * tile_px)
    };
    let (frame_w, frame_h) = (span(&tiles_x, width), span(&tiles_y, height));
    let (isovalues, surface_of) = settings.active_isovalues();
    let bounds = scene.world_bounds();
    let isos = if settings.depth_only {
        scene.prepare_distances(&isovalues)
    } else {
        scene.prepare(&isovalues)
    };
    let diag = if bounds.is_empty() {
        1.0
    } else {
        bounds.extent().length()
    };
    let diag = if diag.is_finite() && diag > 0.0 {
        diag
    } else {
        1.0
    };
    let raygen = RayGen::new(camera, width, height);
    // Rays are cut to where the surfaces can be; the offsets keep the data's scale.
    let live = scene.live_bounds(&isos);
    let mut live_boxes = Vec::new();
    scene.live_boxes(&isos, &mut live_boxes);
    // One box says no more than `live` does.
    let cover = if live_boxes.len() > 1 {
        Coverage::new(&raygen, &live_boxes, samples, scale)
    } else {
        None
    };
    // Depth only: the first hit ends every ray.
    let opaque = if settings.depth_only {
        u64::MAX
    } else {
        opaque_mask(settings, &surface_of)
    };
    let max_layers = if settings.depth_only {
        1
    } else {
        settings.max_layers.max(1)
    };
    let peels = max_layers > 1
        && (surface_of.len() > 64 || (opaque.count_ones() as usize) < surface_of.len());
    let ctx = Ctx {
        settings,
        colorings,
        screen: raygen.screen_rect(&live),
        cover,
        raygen,
        shader: Shader::new(&settings.light),
        bounds: live,
        isos,
        shadow_isos: SHADOWS.then(|| scene.prepare_distances(&isovalues)),
        isovalues,
        surface_of,
        peel: Peel {
            opaque,
            max_hits: max_layers.min(MAX_PEELED as u32),
            eps: diag * 1e-5,
        },
        peels,
        shadow_eps: diag * 2e-4,
        scale,
        samples,
        max_layers,
        order: morton_order(),
        tile_x0: tiles_x.start,
        frame_width: frame_w,
    };

    let pixels = frame_w as usize * frame_h as usize;
    frame.width = frame_w;
    frame.height = frame_h;
    frame.scale = scale;
    // Every pixel is written below: resizing (not clearing) is enough.
    frame.rgba8.resize(pixels * 4, 0);
    frame.depth.resize(pixels, f32::INFINITY);
    let band_rows = TILE as usize * scale as usize;
    let row_len = frame_w as usize;
    let tally = if pixels == 0 {
        Some(Tally::<St>::new())
    } else {
        frame
            .rgba8
            .par_chunks_mut(band_rows * row_len * 4)
            .zip(frame.depth.par_chunks_mut(band_rows * row_len))
            .enumerate()
            .map(|(index, (rgba8, depth))| {
                with_scratch(|sc| {
                    let mut band = Band {
                        index: tiles_y.start + index as u32,
                        rgba8,
                        depth,
                    };
                    let mut tally = Tally::<St>::new();
                    for tx in tiles_x.clone() {
                        if cancel.load(Ordering::Relaxed) {
                            return None;
                        }
                        render_tile::<S, St, SHADOWS>(scene, &ctx, tx, &mut band, sc, &mut tally);
                    }
                    Some(tally)
                })
            })
            .reduce(
                || Some(Tally::new()),
                |a, b| match (a, b) {
                    (Some(a), Some(b)) => Some(a.merge(&b)),
                    _ => None,
                },
            )
    };
    let Some(tally) = tally else {
        return false;
    };
    if cancel.load(Ordering::Relaxed) {
        return false;
    }
    frame.counts = tally.stats.counts();
    frame.rays = tally.rays;
    frame.elapsed = start.elapsed();
    true
}

#[inline]
/// Bit `s` set where a hit on isovalue `s` ends a ray ([`Peel::opaque`]): its surface lets
/// less than [`OPAQUE_TRANSMITTANCE`] through, or it maps to none.
fn opaque_mask(settings: &RenderSettings, surface_of: &[usize]) -> u64 {
    let mut mask = 0u64;
    for (iso, &s) in surface_of.iter().enumerate().take(64) {
        let alpha = settings
            .surfaces
            .get(s)
            .map_or(1.0, |x| x.opacity.clamp(0.0, 1.0));
        if 1.0 - alpha <= OPAQUE_TRANSMITTANCE {
            mask |= 1 << iso;
        }
    }
    mask
}

fn to_u8(c: f32) -> u8 {
    (c.clamp(0.0, 1.0) * 255.0 + 0.5) as u8
}

/// Renders tile `tx` of `band` into the band's rows.
fn render_tile<S: IsoScene, St: Stats, const SHADOWS: bool>(
    scene: &S,
    ctx: &Ctx<'_, S::Isovalues>,
    tx: u32,
    band: &mut Band<'_>,
    sc: &mut Scratch,
    tally: &mut Tally<St>,
) {
    let settings = ctx.settings;
    let scale = ctx.scale as f32;
    let (w, h) = (settings.width as f32, settings.height as f32);
    let tile = [tx, band.index];
    let n_x = (ctx.samples[0] - tile[0] * TILE).min(TILE);
    let n_y = (ctx.samples[1] - tile[1] * TILE).min(TILE);

    // 1. Primary rays through the centre of each sample's pixel block (clipped to the
    //    image), cut to the bounds and the kept clip intervals; the first round's packet.
    //    A tile whose samples all lie outside the bounds' screen rectangle makes none.
    let centre = |s: u32, side: f32| (s as f32 * scale + ((s + 1) as f32 * scale).min(side)) * 0.5;
    let (x_first, x_last) = (
        centre(tile[0] * TILE, w),
        centre(tile[0] * TILE + n_x - 1, w),
    );
    let (y_first, y_last) = (
        centre(tile[1] * TILE, h),
        centre(tile[1] * TILE + n_y - 1, h),
    );
    let off_screen = ctx
        .screen
        .is_some_and(|[x0, x1, y0, y1]| x_last < x0 || x_first > x1 || y_last < y0 || y_first > y1);
    let mut columns = [Vec3::ZERO; TILE as usize];
    let mut rows = [Vec3::ZERO; TILE as usize];
    if !off_screen {
        for (dx, c) in columns.iter_mut().enumerate().take(n_x as usize) {
            *c = ctx.raygen.column(centre(tile[0] * TILE + dx as u32, w));
        }
        for (dy, r) in rows.iter_mut().enumerate().take(n_y as usize) {
            *r = ctx.raygen.row(centre(tile[1] * TILE + dy as u32, h));
        }
    }
    sc.tile_rays.resize(
        TILE as usize * TILE as usize,
        Ray::new(Vec3::ZERO, Vec3::ONE),
    );
    // Row-major per tile row: each ray's range in the bounds, bit `dx` where it meets them.
    let mut lo = [[0f32; TILE as usize]; TILE as usize];
    let mut hi = [[0f32; TILE as usize]; TILE as usize];
    let mut meets = [0u32; TILE as usize];
    let tile_rows = sc.tile_rays.chunks_exact_mut(TILE as usize);
    let rows_in = if off_screen { 0 } else { n_y as usize };
    for (dy, (row, out)) in rows.iter().zip(tile_rows).enumerate().take(rows_in) {
        let covered = ctx
            .cover
            .as_ref()
            .map_or(u32::MAX, |c| c.row(tile[0], tile[1] * TILE + dy as u32));
        if covered == 0 {
            continue;
        }
        let out: &mut [Ray; TILE as usize] = out.try_into().expect("a tile row");
        meets[dy] = covered
            & ctx
                .raygen
                .rays_row_in(&columns, *row, &ctx.bounds, out, &mut lo[dy], &mut hi[dy]);
    }
    sc.fit();
    sc.intervals.clear();
    let mut n_states = 0usize;
    tally.rays.primary += u64::from(n_x * n_y);
    let no_clips = settings.clips.is_empty();
    let traced = !ctx.isovalues.is_empty();
    // Samples that trace nothing (no bounds range, no kept clip interval or no isovalue)
    // get no state: step 3 paints the whole tile with the background first.
    let columns_in = (1u32 << n_x) - 1;
    if traced && meets.iter().any(|&m| m & columns_in != 0) {
        // The per-sample arrays as local slices: their pointers stay in registers instead of
        // being read again from `sc` after every store.
        let (active, rays, t_min, t_max, states) = (
            &mut sc.active[..SLOTS],
            &mut sc.rays[..SLOTS],
            &mut sc.t_min[..SLOTS],
            &mut sc.t_max[..SLOTS],
            &mut sc.states[..SLOTS],
        );
        for &[dx, dy] in &ctx.order {
            if dx >= n_x || dy >= n_y || meets[dy as usize] >> dx & 1 == 0 {
                continue;
            }
            let pos = dy * TILE + dx;
            let range = Interval::new(lo[dy as usize][dx as usize], hi[dy as usize][dx as usize]);
            let iv = sc.intervals.len() as u32;
            let first = if no_clips {
                // The one kept interval is the bounds range (what `kept_intervals` returns).
                sc.intervals.push(range);
                range
            } else {
                kept_intervals(
                    &sc.tile_rays[pos as usize],
                    range,
                    &settings.clips,
                    &mut sc.clip_out,
                    &mut sc.clip_tmp,
                );
                let Some(&first) = sc.clip_out.first() else {
                    continue;
                };
                sc.intervals.extend_from_slice(&sc.clip_out);
                first
            };
            let iv_end = sc.intervals.len() as u32;
            let k = n_states;
            active[k] = k as u32;
            rays[k] = sc.tile_rays[pos as usize];
            t_min[k] = first.lo;
            t_max[k] = first.hi;
            n_states += 1;
            states[k] = RayState::start(iv, iv_end, first.lo, pos as u8);
        }
    }

    // 2. Rounds: trace every active ray's current segment together.
    let mut n = n_states;
    let mut first_round = true;
    loop {
        if !first_round {
            n = next_round(sc, n_states);
        }
        first_round = false;
        if n == 0 {
            break;
        }
        // No clearing of `sc.hits` or `sc.first`: the path taken writes each of its `n`
        // entries, and the hits below are read from that one.
        if settings.packets && ctx.peels {
            scene.peeled_hits_packet_prepared(
                &sc.rays[..n],
                &sc.t_min[..n],
                &sc.t_max[..n],
                &ctx.isos,
                &ctx.peel,
                &mut sc.hits[..n],
                &mut tally.stats,
            );
        } else if settings.packets {
            // Every surface opaque or one layer: first hits are all there is to find.
            scene.first_hit_packet_prepared(
                &sc.rays[..n],
                &sc.t_min[..n],
                &sc.t_max[..n],
                &ctx.isos,
                &mut sc.first[..n],
                &mut tally.stats,
            );
        } else {
            for k in 0..n {
                let hit = scene.first_hit_prepared(
                    &sc.rays[k],
                    sc.t_min[k],
                    sc.t_max[k],
                    &ctx.isos,
                    &mut tally.stats,
                );
                sc.hits[k].set_first(hit, &ctx.peel);
            }
        }
        let mut live = 0usize;
        sc.shade.clear();
        sc.shadow_rays.clear();
        sc.shadow_t_min.clear();
        sc.shadow_t_max.clear();
        sc.shadow_of.clear();
        // Hits: their surface and shading geometry; shadow rays are queued, to be traced
        // together as one packet (parallel for a directional light, coherent for a point).
        // First hits are read where the packets wrote them (`sc.first`), not copied into
        // `sc.hits` first (a pass over every ray of the round).
        let first_only = settings.packets && !ctx.peels;
        let (active, states, first, peeled) = (
            &sc.active[..n],
            &mut sc.states[..SLOTS],
            &sc.first[..n],
            &sc.hits[..n],
        );
        for k in 0..n {
            let st = &mut states[active[k] as usize];
            let (found, more) = if first_only {
                let f = first[k].as_slice();
                (f, f.first().is_some_and(|h| !ctx.peel.ends_ray(h.surface)))
            } else {
                (peeled[k].hits(), peeled[k].more)
            };
            if found.is_empty() {
                live += usize::from(st.next_interval(&sc.intervals));
                continue;
            }
            for (j, &hit) in found.iter().enumerate() {
                let Some(&surface) = ctx.surface_of.get(hit.surface as usize) else {
                    // A scene reporting a surface we did not ask for: stop, do not guess.
                    // The layers in front of it are still composited, then the ray ends.
                    st.iv_end = st.iv + 1;
                    match sc.shade.last_mut().filter(|_| j > 0) {
                        Some(prev) => (prev.last, prev.more) = (true, false),
                        None => st.done = true,
                    }
                    break;
                };
                let ray = &sc.rays[k];
                if settings.depth_only {
                    sc.shade.push(PendingShade {
                        k: k as u32,
                        surface: surface as u32,
                        cell: hit.cell,
                        t: hit.t,
                        normal: Vec3::ZERO,
                        to_light: Vec3::ZERO,
                        lit: 1.0,
                        last: true,
                        more: false,
                    });
                    continue;
                }
                let p = ray.at(hit.t);
                let normal = Shader::facing(hit.normal, ray.dir);
                let (to_light, light_dist) = ctx.shader.light_dir(p, ray.dir);
                let owner = sc.shade.len() as u32;
                sc.shade.push(PendingShade {
                    k: k as u32,
                    surface: surface as u32,
                    cell: hit.cell,
                    t: hit.t,
                    normal,
                    to_light,
                    lit: 1.0,
                    last: j + 1 == found.len(),
                    more,
                });
                if SHADOWS && Shader::lambert(normal, to_light) > 0.0 {
                    tally.rays.shadow += 1;
                    let shadow = Ray::new(p + normal * ctx.shadow_eps, to_light);
                    let range = ctx
                        .bounds
                        .intersect(&shadow, ctx.shadow_eps, light_dist)
                        .map_or(Interval::EMPTY, |(lo, hi)| Interval::new(lo, hi));
                    kept_intervals(
                        &shadow,
                        range,
                        &settings.clips,
                        &mut sc.clip_out,
                        &mut sc.clip_tmp,
                    );
                    for iv in &sc.clip_out {
                        sc.shadow_rays.push(shadow);
                        sc.shadow_t_min.push(iv.lo);
                        sc.shadow_t_max.push(iv.hi);
                        sc.shadow_of.push(owner);
                    }
                }
            }
        }
        if SHADOWS && !sc.shadow_rays.is_empty() {
            let m = sc.shadow_rays.len();
            let shadow_isos = ctx.shadow_isos.as_ref().unwrap_or(&ctx.isos);
            if settings.packets {
                sc.shadow_occluded.clear();
                sc.shadow_occluded.resize(m, false);
                scene.occluded_packet_prepared(
                    &sc.shadow_rays,
                    &sc.shadow_t_min,
                    &sc.shadow_t_max,
                    shadow_isos,
                    &mut sc.shadow_occluded,
                    &mut tally.stats,
                );
                for (&occluded, &owner) in sc.shadow_occluded.iter().zip(&sc.shadow_of) {
                    if occluded {
                        sc.shade[owner as usize].lit = 0.0;
                    }
                }
            } else {
                for i in 0..m {
                    let owner = sc.shadow_of[i] as usize;
                    if sc.shade[owner].lit > 0.0
                        && scene.occluded_prepared(
                            &sc.shadow_rays[i],
                            sc.shadow_t_min[i],
                            sc.shadow_t_max[i],
                            shadow_isos,
                            &mut tally.stats,
                        )
                    {
                        sc.shade[owner].lit = 0.0;
                    }
                }
            }
        }
        // Shade and composite front to back.
        for ps in &sc.shade {
            let k = ps.k as usize;
            let idx = sc.active[k] as usize;
            let st = &mut sc.states[idx];
            let comp = &mut sc.composites[idx];
            if st.done {
                // Layers the scene found past where the ray ends (its opacity or the layer
                // limit).
                continue;
            }
            let surface = &settings.surfaces[ps.surface as usize];
            if st.layers == 0 {
                *comp = Composite::starting_at(ps.t);
            }
            if settings.depth_only {
                comp.color = Vec3::from(surface.color);
                comp.transmittance = 0.0;
                st.layers = 1;
                st.done = true;
                continue;
            }
            // The one per-hit branch of colouring.
            let base = match ctx.colorings.get(ps.surface as usize) {
                Some(Some(c)) => c.color_at(sc.rays[k].at(ps.t), ps.cell, surface.color),
                _ => surface.color,
            };
            let rgb = ctx.shader.shade(
                Vec3::from(base),
                ps.normal,
                sc.rays[k].dir,
                ps.to_light,
                ps.lit,
            );
            let alpha = surface.opacity.clamp(0.0, 1.0);
            comp.color += rgb * (comp.transmittance * alpha);
            comp.transmittance *= 1.0 - alpha;
            st.layers += 1;
            if comp.transmittance <= OPAQUE_TRANSMITTANCE || st.layers >= ctx.max_layers {
                st.done = true;
                continue;
            }
            tally.rays.transparency += 1;
            if !ps.last {
                continue;
            }
            if ps.more {
                st.t_from = ctx.peel.next_t(ps.t);
                live += 1;
            } else {
                // Nothing more in this interval.
                live += usize::from(st.next_interval(&sc.intervals));
            }
        }
        if live == 0 {
            break;
        }
    }

    // 3. The tile's pixels: the background (and no depth) everywhere, then the samples
    //    with a hit composited over it, straight into the band.
    let bg = Vec3::from(settings.background);
    let row_len = ctx.frame_width as usize;
    let band_rows = band.depth.len() / row_len;
    let x_tile = ((tile[0] - ctx.tile_x0) * TILE) as usize;
    let step = ctx.scale as usize;
    // `0 + bg · 1` is `bg`: converted once per tile.
    let bg_rgba = [to_u8(bg.x), to_u8(bg.y), to_u8(bg.z), 255];
    let x0 = x_tile * step;
    let x1 = ((x_tile + n_x as usize) * step).min(row_len);
    for y in 0..(n_y as usize * step).min(band_rows) {
        let row = y * row_len;
        for px in band.rgba8[4 * (row + x0)..4 * (row + x1)].chunks_exact_mut(4) {
            px.copy_from_slice(&bg_rgba);
        }
        band.depth[row + x0..row + x1].fill(f32::INFINITY);
    }
    for (st, comp) in sc.states[..n_states].iter().zip(&sc.composites) {
        if st.layers == 0 {
            continue;
        }
        let c = comp.color + bg * comp.transmittance;
        let rgba = [to_u8(c.x), to_u8(c.y), to_u8(c.z), 255];
        let (dx, dy) = (
            usize::from(st.pos) % TILE as usize,
            usize::from(st.pos) / TILE as usize,
        );
        if step == 1 {
            let p = dy * row_len + x_tile + dx;
            band.rgba8[4 * p..4 * p + 4].copy_from_slice(&rgba);
            band.depth[p] = comp.depth;
            continue;
        }
        let x0 = (x_tile + dx) * step;
        let x1 = (x0 + step).min(row_len);
        let y0 = dy * step;
        for y in y0..(y0 + step).min(band_rows) {
            let row = y * row_len;
            for p in row + x0..row + x1 {
                band.rgba8[4 * p..4 * p + 4].copy_from_slice(&rgba);
                band.depth[p] = comp.depth;
            }
        }
    }
}

/// Builds the next round's packet from the tile's first `n_states` states and returns its
/// size: every ray not done, at its current `t_from`, moved on to the next kept interval
/// when `t_from` is past the current one's end.
fn next_round(sc: &mut Scratch, n_states: usize) -> usize {
    let mut n = 0;
    for (idx, st) in sc.states[..n_states].iter_mut().enumerate() {
        if st.done {
            continue;
        }
        // `t_from` past the interval's end (or NaN): move on.
        while st.iv < st.iv_end
            && !matches!(
                st.t_from.partial_cmp(&sc.intervals[st.iv as usize].hi),
                Some(std::cmp::Ordering::Less | std::cmp::Ordering::Equal)
            )
        {
            st.iv += 1;
            if st.iv < st.iv_end {
                st.t_from = st.t_from.max(sc.intervals[st.iv as usize].lo);
            }
        }
        if st.iv >= st.iv_end {
            st.done = true;
            continue;
        }
        sc.active[n] = idx as u32;
        sc.rays[n] = sc.tile_rays[usize::from(st.pos)];
        sc.t_min[n] = st.t_from;
        sc.t_max[n] = sc.intervals[st.iv as usize].hi;
        n += 1;
    }
    n
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::analytic::SphereScene;
    use crate::render::camera::Projection;
    use crate::render::settings::{ClipRegion, Keep, Light, LightKind, SettingsError, Surface};

    fn cube(h: f32) -> Aabb {
        Aabb::new(Vec3::splat(-h), Vec3::splat(h))
    }

    /// Looking down −z from `(0, 0, dist)` with `+y` up.
    fn cam_z(dist: f32) -> Camera {
        Camera {
            eye: Vec3::new(0.0, 0.0, dist),
            target: Vec3::ZERO,
            up: Vec3::Y,
            vfov_deg: 40.0,
            projection: Projection::Pinhole,
            ortho_height: None,
        }
    }

    fn go() -> AtomicBool {
        AtomicBool::new(false)
    }

    fn pixel(f: &Frame, i: u32, j: u32) -> [u8; 4] {
        let p = 4 * (j * f.width + i) as usize;
        f.rgba8[p..p + 4].try_into().unwrap()
    }

    /// Independent Blinn–Phong for a surface facing the viewer head-on under the headlight:
    /// `n·L = n·H = 1`.
    fn head_on(color: [f32; 3], l: &Light) -> [f32; 3] {
        color.map(|c| (c * (l.ambient + l.diffuse) + l.specular).min(1.0))
    }

    /// `f(p) = x`, NaN for `x > 0.6` (no data there).
    struct XField;

    impl HitField for XField {
        fn value_at(&self, p: Vec3, _cell: u32) -> f32 {
            if p.x > 0.6 { f32::NAN } else { p.x }
        }
    }

    #[test]
    fn coloured_surfaces_show_the_colormap_of_the_field_at_each_hit() {
        // A unit sphere coloured by x under pure ambient light (shading = base colour): every
        // hit pixel is the colormap of the analytic x of its hit point.
        let scene = SphereScene::distance_field(Vec3::ZERO, cube(2.0));
        let flat = [0.2, 0.9, 0.3];
        let settings = RenderSettings {
            width: 41,
            height: 41,
            surfaces: vec![Surface::new(1.0, flat)],
            light: Light {
                ambient: 1.0,
                diffuse: 0.0,
                specular: 0.0,
                ..Light::default()
            },
            ..RenderSettings::default()
        };
        let cam = cam_z(5.0);
        let range = [-1.0, 1.0];
        let colorings = [Some(SurfaceColoring {
            field: &XField,
            colormap: Colormap::Magma,
            range,
        })];
        let mut frame = Frame::default();
        assert!(render_colored_into(
            &scene,
            &cam,
            &settings,
            &colorings,
            &go(),
            &mut frame
        ));
        let raygen = RayGen::new(&cam, 41, 41);
        let (mut mapped, mut nan) = (0, 0);
        for j in 0..41 {
            for i in 0..41 {
                let t = frame.depth[(j * 41 + i) as usize];
                if !t.is_finite() {
                    continue;
                }
                let ray = raygen.ray_at(i as f32 + 0.5, j as f32 + 0.5);
                let p = ray.origin.as_dvec3() + ray.dir.as_dvec3() * f64::from(t);
                // The hit lies on the analytic sphere.
                assert!((p.length() - 1.0).abs() < 1e-5);
                let x = p.x as f32;
                let want = if x > 0.6 {
                    nan += 1;
                    flat
                } else {
                    mapped += 1;
                    Colormap::Magma.map(x, range)
                };
                let px = pixel(&frame, i, j);
                for c in 0..3 {
                    assert!(
                        (i32::from(px[c]) - i32::from(to_u8(want[c]))).abs() <= 1,
                        "pixel {i},{j}: {px:?} vs {want:?}"
                    );
                }
            }
        }
        assert!(mapped > 250 && nan > 30, "{mapped} {nan}");
        // The centre hit is at x = 0: the middle of magma.
        let mid = Colormap::Magma.at(0.5).map(to_u8);
        assert_eq!(&pixel(&frame, 20, 20)[..3], &mid[..]);
        // No colouring (none given, or `None` for the surface): the flat picture, exactly.
        let plain = render(&scene, &cam, &settings, &go()).unwrap();
        let mut none = Frame::default();
        assert!(render_colored_into(
            &scene,
            &cam,
            &settings,
            &[None],
            &go(),
            &mut none
        ));
        assert_eq!(none.rgba8, plain.rgba8);
        assert_eq!(&pixel(&plain, 20, 20)[..3], &flat.map(to_u8)[..]);
    }

    #[test]
    fn transparency_composites_front_to_back() {
        // Field |x|: isovalue 2 is the outer shell (transparent red), 1 the inner (opaque
        // green). Listed inner first, so surface indices differ from depth order.
        let scene = SphereScene::distance_field(Vec3::ZERO, cube(3.0));
        let red = [0.9, 0.1, 0.1];
        let green = [0.1, 0.8, 0.2];
        let alpha = 0.4;
        let mut settings = RenderSettings {
            width: 33,
            height: 33,
            surfaces: vec![
                Surface::new(1.0, green),
                Surface {
                    opacity: alpha,
                    ..Surface::new(2.0, red)
                },
            ],
            background: [0.0, 0.0, 1.0],
            ..RenderSettings::default()
        };
        let frame = render(&scene, &cam_z(10.0), &settings, &go()).unwrap();
        // The centre pixel's ray runs exactly along −z through the centre.
        let (r, g) = (
            head_on(red, &settings.light),
            head_on(green, &settings.light),
        );
        let want: Vec<u8> = (0..3)
            .map(|c| to_u8(alpha * r[c] + (1.0 - alpha) * g[c]))
            .collect();
        assert_eq!(&pixel(&frame, 16, 16)[..3], &want[..]);
        assert_eq!(frame.depth[16 * 33 + 16], 8.0);
        assert!(frame.rays.transparency > 0);

        // One layer: the rest of the transmittance shows the background.
        settings.max_layers = 1;
        let one = render(&scene, &cam_z(10.0), &settings, &go()).unwrap();
        let bg = settings.background;
        let want: Vec<u8> = (0..3)
            .map(|c| to_u8(alpha * r[c] + (1.0 - alpha) * bg[c]))
            .collect();
        assert_eq!(&pixel(&one, 16, 16)[..3], &want[..]);

        // Hiding the inner surface: the outer shell is seen twice (front and back face, the
        // back face flipped to face the viewer), then the background.
        settings.max_layers = 4;
        settings.surfaces[0].visible = false;
        let shell = render(&scene, &cam_z(10.0), &settings, &go()).unwrap();
        let t = 1.0 - alpha;
        let want: Vec<u8> = (0..3)
            .map(|c| to_u8(alpha * r[c] + t * alpha * r[c] + t * t * bg[c]))
            .collect();
        assert_eq!(&pixel(&shell, 16, 16)[..3], &want[..]);
        assert_eq!(shell.depth[16 * 33 + 16], 8.0);
    }

    #[test]
    fn supersampled_pixels_hold_the_share_of_their_samples_that_hit_the_sphere() {
        // Flat white on black: a pixel's value is 255 times the share of its k×k samples
        // whose ray meets the sphere, which the test counts analytically.
        let (centre, radius) = (Vec3::new(0.13, -0.07, 0.0), 1.0);
        let scene = SphereScene::distance_field(centre, cube(3.0));
        let cam = Camera {
            projection: Projection::Orthographic,
            ortho_height: Some(2.6),
            ..cam_z(10.0)
        };
        let (w, h, k) = (23u32, 19u32, 3u32);
        let settings = RenderSettings {
            width: w,
            height: h,
            surfaces: vec![Surface::new(radius, [1.0, 1.0, 1.0])],
            background: [0.0, 0.0, 0.0],
            light: Light {
                ambient: 1.0,
                diffuse: 0.0,
                specular: 0.0,
                fill: 0.0,
                ..Light::default()
            },
            supersample: k,
            ..RenderSettings::default()
        };
        settings.validate().unwrap();
        let frame = render(&scene, &cam, &settings, &go()).unwrap();
        assert_eq!((frame.width, frame.height), (w, h));
        assert_eq!(frame.rays.primary, u64::from(w * h * k * k));
        let hits = |i: u32, j: u32| {
            let r = cam.primary_ray(i, j, w * k, h * k);
            // Ray–sphere: the distance of the centre from the ray's line.
            let oc = centre - r.origin;
            let along = oc.dot(r.dir);
            (oc - r.dir * along).length() < radius
        };
        let mut partial = 0;
        for j in 0..h {
            for i in 0..w {
                let n = (0..k * k)
                    .filter(|s| hits(i * k + s % k, j * k + s / k))
                    .count() as f32;
                let want = 255.0 * n / (k * k) as f32;
                let got = f32::from(pixel(&frame, i, j)[0]);
                // One sample on the silhouette may fall either way.
                assert!(
                    (got - want).abs() <= 255.0 / (k * k) as f32 + 1.0,
                    "pixel {i},{j}: {got} for {n} of {} samples",
                    k * k
                );
                partial += usize::from(got > 0.0 && got < 255.0);
                let d = frame.depth[(j * w + i) as usize];
                // The nearest of the samples' hits: finite where any sample hit.
                if got > 0.0 {
                    assert!(d.is_finite(), "pixel {i},{j} shows the sphere, depth {d}");
                } else if n == 0.0 {
                    assert!(d.is_infinite(), "pixel {i},{j} misses, depth {d}");
                }
            }
        }
        assert!(partial > 10, "silhouette pixels are blended: {partial}");
        let mut bad = settings.clone();
        bad.supersample = crate::render::supersample::MAX_SUPERSAMPLE + 1;
        assert!(bad.validate().is_err());
        bad.supersample = 0;
        assert!(bad.validate().is_err());
    }

    #[test]
    fn depth_is_the_analytic_first_hit_and_inf_on_miss() {
        let scene = SphereScene::distance_field(Vec3::new(0.2, -0.1, 0.0), cube(3.0));
        let cam = Camera::orbit(&cube(3.0), 30.0, 20.0, 35.0);
        let settings = RenderSettings {
            width: 40,
            height: 30,
            surfaces: vec![Surface::new(2.5, [0.8; 3])],
            ..RenderSettings::default()
        };
        let frame = render(&scene, &cam, &settings, &go()).unwrap();
        let mut hits = 0;
        for j in 0..30 {
            for i in 0..40 {
                let ray = cam.primary_ray(i, j, 40, 30);
                // Independent truth: ray–sphere in f64.
                let (o, d) = (ray.origin.as_dvec3(), ray.dir.as_dvec3());
                let oc = o - glam::DVec3::new(0.2, -0.1, 0.0);
                let b = oc.dot(d);
                let dd = d.length_squared();
                let disc = b * b - dd * (oc.length_squared() - 6.25);
                let got = frame.depth[(j * 40 + i) as usize];
                if disc < 0.0 {
                    assert_eq!(got, f32::INFINITY);
                } else {
                    let t = (-b - disc.sqrt()) / dd;
                    assert!((f64::from(got) - t).abs() < 1e-4, "({i},{j}) {got} vs {t}");
                    hits += 1;
                }
            }
        }
        assert!(hits > 100);
    }

    #[test]
    fn shadows_darken_an_occluded_point_only() {
        // A unit sphere at the origin and a small occluder between its top point (0, 0, 1)
        // and a directional light from (1, 0, 1).
        let l_dir = Vec3::new(1.0, 0.0, 1.0).normalize();
        let scene = SphereScene {
            spheres: vec![(Vec3::ZERO, 1.0), (Vec3::Z + l_dir, 0.2)],
            bounds: cube(3.0),
        };
        let light = Light {
            kind: LightKind::Directional { dir: l_dir },
            ..Light::default()
        };
        let color = [0.6, 0.6, 0.6];
        let mut settings = RenderSettings {
            width: 65,
            height: 65,
            surfaces: vec![Surface::new(0.0, color)],
            light,
            ..RenderSettings::default()
        };
        let cam = cam_z(6.0);
        let off = render(&scene, &cam, &settings, &go()).unwrap();
        settings.shadows = true;
        let on = render(&scene, &cam, &settings, &go()).unwrap();
        // Centre pixel: p = (0, 0, 1), n = +z = V, shadowed -> ambient and the eye's fill.
        let shadowed: Vec<u8> = color
            .iter()
            .map(|c| to_u8(c * (light.ambient + light.fill)))
            .collect();
        assert_eq!(&pixel(&on, 32, 32)[..3], &shadowed[..]);
        let c = pixel(&off, 32, 32);
        assert!(c[0] > shadowed[0] + 50, "unshadowed {c:?}");
        assert!(on.rays.shadow > 0 && off.rays.shadow == 0);
        // A point on the far side from the occluder (lit): identical with shadows on or off.
        // Pixel column 20 is at x < 0, the occluder's shadow falls around x = 0.
        assert!(on.depth[32 * 65 + 20].is_finite());
        assert_eq!(pixel(&on, 20, 32), pixel(&off, 20, 32));
        // Shadow-ray origins do not self-shadow: most lit pixels are unchanged.
        let same = (0..65 * 65)
            .filter(|&p| on.rgba8[4 * p..4 * p + 4] == off.rgba8[4 * p..4 * p + 4])
            .count();
        assert!(same > 65 * 65 * 9 / 10, "{same}");
    }

    #[test]
    fn back_lit_surfaces_get_the_eye_fill_light() {
        // A unit sphere lit from straight behind: the key light reaches none of what the
        // camera sees, so the centre pixel (n = V = +z) is ambient plus the full fill.
        let scene = SphereScene {
            spheres: vec![(Vec3::ZERO, 1.0)],
            bounds: cube(3.0),
        };
        let light = Light {
            kind: LightKind::Directional { dir: -Vec3::Z },
            ..Light::default()
        };
        let color = [0.6, 0.6, 0.6];
        let settings = RenderSettings {
            width: 65,
            height: 65,
            surfaces: vec![Surface::new(0.0, color)],
            light,
            ..RenderSettings::default()
        };
        let cam = cam_z(6.0);
        let frame = render(&scene, &cam, &settings, &go()).unwrap();
        let filled: Vec<u8> = color
            .iter()
            .map(|c| to_u8(c * (light.ambient + light.fill)))
            .collect();
        assert_eq!(&pixel(&frame, 32, 32)[..3], &filled[..]);
        assert!(filled[0] > to_u8(color[0] * light.ambient) + 40);
        // The headlight is its own fill: its pictures do not change with `fill`.
        let head = |fill| RenderSettings {
            light: Light {
                fill,
                ..Light::default()
            },
            ..settings.clone()
        };
        let a = render(&scene, &cam, &head(0.0), &go()).unwrap();
        let b = render(&scene, &cam, &head(0.9), &go()).unwrap();
        assert_eq!(a.rgba8, b.rgba8);
    }

    #[test]
    fn clipped_front_shows_the_inside_without_caps() {
        let scene = SphereScene::distance_field(Vec3::ZERO, cube(3.0));
        let cam = cam_z(5.0);
        let mut settings = RenderSettings {
            width: 9,
            height: 9,
            surfaces: vec![Surface::new(1.0, [1.0, 1.0, 1.0])],
            // Keep z <= 0: the front half of the sphere is cut away.
            clips: vec![ClipRegion::Plane {
                normal: Vec3::Z,
                offset: 0.0,
            }],
            ..RenderSettings::default()
        };
        let frame = render(&scene, &cam, &settings, &go()).unwrap();
        // Ray along −z: the cut at z = 0 (t = 5) is not a surface; the back face is, at t = 6.
        assert_eq!(frame.depth[4 * 9 + 4], 6.0);
        // Same by a keep-outside box removing z > 0.
        settings.clips = vec![ClipRegion::Box {
            min: Vec3::new(-5.0, -5.0, 0.0),
            max: Vec3::splat(5.0),
            keep: Keep::Outside,
        }];
        let boxed = render(&scene, &cam, &settings, &go()).unwrap();
        assert_eq!(boxed.depth[4 * 9 + 4], 6.0);
        // A keep-inside box around nothing but empty space: every ray misses.
        settings.clips = vec![ClipRegion::Box {
            min: Vec3::splat(-0.5),
            max: Vec3::splat(0.5),
            keep: Keep::Inside,
        }];
        let empty = render(&scene, &cam, &settings, &go()).unwrap();
        assert!(empty.depth.iter().all(|d| d.is_infinite()));
    }

    #[test]
    fn output_is_deterministic_and_packets_match_single_rays() {
        let scene = SphereScene {
            spheres: vec![(Vec3::ZERO, 1.0), (Vec3::new(0.9, 0.3, 0.2), 0.6)],
            bounds: cube(2.5),
        };
        let cam = Camera::orbit(&cube(2.5), 40.0, 25.0, 40.0);
        let mut settings = RenderSettings {
            width: 70,
            height: 50,
            surfaces: vec![
                Surface {
                    opacity: 0.5,
                    ..Surface::new(0.3, [0.2, 0.4, 0.9])
                },
                Surface::new(0.0, [0.9, 0.7, 0.1]),
            ],
            shadows: true,
            light: Light {
                kind: LightKind::Point {
                    pos: Vec3::new(4.0, 3.0, 5.0),
                },
                ..Light::default()
            },
            clips: vec![ClipRegion::Box {
                min: Vec3::splat(0.0),
                max: Vec3::splat(3.0),
                keep: Keep::Outside,
            }],
            collect_stats: true,
            ..RenderSettings::default()
        };
        let a = render(&scene, &cam, &settings, &go()).unwrap();
        let b = render(&scene, &cam, &settings, &go()).unwrap();
        assert_eq!(a.rgba8, b.rgba8);
        assert_eq!(
            a.depth.iter().map(|d| d.to_bits()).collect::<Vec<_>>(),
            b.depth.iter().map(|d| d.to_bits()).collect::<Vec<_>>()
        );
        assert_eq!(a.counts, b.counts);
        assert!(a.counts.rays > 0);
        settings.packets = false;
        let single = render(&scene, &cam, &settings, &go()).unwrap();
        assert_eq!(single.rgba8, a.rgba8);
        settings.collect_stats = false;
        let quiet = render(&scene, &cam, &settings, &go()).unwrap();
        assert_eq!(quiet.counts, TraversalCounts::default());
        assert_eq!(quiet.rgba8, a.rgba8);
    }

    /// A serial, per-sample twin of the renderer without shadows: the same camera rays,
    /// clip intervals, peeling and compositing, one ray at a time with `first_hit`.
    fn twin<S: IsoScene>(scene: &S, cam: &Camera, s: &RenderSettings) -> (Vec<u8>, Vec<f32>) {
        let (w, h, scale) = (s.width, s.height, s.scale);
        let raygen = RayGen::new(cam, w, h);
        let shader = Shader::new(&s.light);
        let (isovalues, surface_of) = s.active_isovalues();
        let bounds = scene.world_bounds();
        let peel_eps = bounds.extent().length() * 1e-5;
        let mut rgba8 = vec![0u8; (w * h * 4) as usize];
        let mut depth = vec![f32::INFINITY; (w * h) as usize];
        let (mut ivs, mut tmp) = (Vec::new(), Vec::new());
        for sy in 0..h.div_ceil(scale) {
            for sx in 0..w.div_ceil(scale) {
                let f = |i: u32, n: u32| {
                    (i as f32 * scale as f32 + ((i + 1) as f32 * scale as f32).min(n as f32)) * 0.5
                };
                let ray = raygen.ray_at(f(sx, w), f(sy, h));
                let range = bounds
                    .intersect(&ray, 0.0, f32::INFINITY)
                    .map_or(Interval::EMPTY, |(lo, hi)| Interval::new(lo, hi));
                kept_intervals(&ray, range, &s.clips, &mut ivs, &mut tmp);
                let (mut color, mut trans, mut layers) = (Vec3::ZERO, 1.0f32, 0);
                let mut first_t = f32::INFINITY;
                let mut t_from = f32::NEG_INFINITY;
                'ray: for iv in &ivs {
                    t_from = t_from.max(iv.lo);
                    while t_from <= iv.hi && !isovalues.is_empty() {
                        let Some(hit) =
                            scene.first_hit(&ray, t_from, iv.hi, &isovalues, &mut NoStats)
                        else {
                            break;
                        };
                        let surf = &s.surfaces[surface_of[hit.surface as usize]];
                        if layers == 0 {
                            first_t = hit.t;
                        }
                        let n = Shader::facing(hit.normal, ray.dir);
                        let (l, _) = shader.light_dir(ray.at(hit.t), ray.dir);
                        let rgb = shader.shade(Vec3::from(surf.color), n, ray.dir, l, 1.0);
                        color += rgb * (trans * surf.opacity);
                        trans *= 1.0 - surf.opacity;
                        layers += 1;
                        if trans <= OPAQUE_TRANSMITTANCE || layers >= s.max_layers {
                            break 'ray;
                        }
                        t_from = hit.t + peel_eps + hit.t.abs() * 1e-6;
                    }
                }
                let c = color + Vec3::from(s.background) * trans;
                let px = [to_u8(c.x), to_u8(c.y), to_u8(c.z), 255];
                for y in sy * scale..((sy + 1) * scale).min(h) {
                    for x in sx * scale..((sx + 1) * scale).min(w) {
                        let p = (y * w + x) as usize;
                        rgba8[4 * p..4 * p + 4].copy_from_slice(&px);
                        depth[p] = first_t;
                    }
                }
            }
        }
        (rgba8, depth)
    }

    /// Nested shells of a noisy radial field on an `n³` f32 grid over [−1, 1]³: the distance
    /// from the centre plus uniform noise of ±0.08.
    fn noisy_shells(n: usize, seed: u64) -> crate::grid::GridScene<f32> {
        use crate::intersect::Intersector;
        use crate::kdtree::KdTreeConfig;
        use crate::math::rng::Rng;
        use crate::volume::{Grid, VoxelBuffer};
        let grid = Grid::uniform([n; 3], [-1.0; 3], [2.0 / (n - 1) as f64; 3]).unwrap();
        let mut rng = Rng::new(seed);
        let voxels: Vec<f32> = (0..n * n * n)
            .map(|q| {
                let (i, j, k) = (q % n, q / n % n, q / (n * n));
                let p = Vec3::new(i as f32, j as f32, k as f32) / (n - 1) as f32 * 2.0 - 1.0;
                p.length() + 0.08 * rng.range_f32(-1.0, 1.0)
            })
            .collect();
        crate::grid::GridScene::new(
            &grid,
            VoxelBuffer::from_vec(voxels),
            Intersector::Exact,
            KdTreeConfig::default(),
        )
        .unwrap()
    }

    /// A grid scene, whose packets go on past transparent hits inside their traversal
    /// ([`IsoScene::peeled_hits_packet_prepared`]), renders exactly what new rays shot from
    /// past each layer show: nested shells of a noisy radial field, the outer ones
    /// transparent, with and without clips, for several layer limits.
    #[test]
    fn grid_frames_with_transparent_layers_equal_the_serial_twin() {
        let scene = noisy_shells(24, 5);
        let bounds = scene.world_bounds();
        let (mut deep, mut cases) = (0u64, 0);
        for (k, max_layers) in [2u32, 4, 7].into_iter().enumerate() {
            let cam = Camera::orbit(&bounds, 30.0 + 50.0 * k as f32, 20.0, 40.0);
            for clips in [
                vec![],
                vec![ClipRegion::Plane {
                    normal: Vec3::new(0.3, 1.0, 0.2),
                    offset: 0.1,
                }],
            ] {
                let settings = RenderSettings {
                    width: 40,
                    height: 33,
                    surfaces: vec![
                        Surface {
                            opacity: 0.35,
                            ..Surface::new(0.85, [0.9, 0.5, 0.4])
                        },
                        Surface {
                            opacity: 0.6,
                            ..Surface::new(0.6, [0.3, 0.8, 0.4])
                        },
                        Surface::new(0.35, [0.9, 0.9, 0.8]),
                    ],
                    clips,
                    max_layers,
                    ..RenderSettings::default()
                };
                let (rgba8, depth) = twin(&scene, &cam, &settings);
                let f = render(&scene, &cam, &settings, &go()).unwrap();
                assert_eq!(f.rgba8, rgba8, "layers {max_layers}");
                let bits = |d: &[f32]| d.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                assert_eq!(bits(&f.depth), bits(&depth), "layers {max_layers}");
                deep += f.rays.transparency;
                cases += 1;
            }
        }
        assert_eq!(cases, 6);
        assert!(deep > 1000, "{deep} transparent layers gone past");

        // The frames above are the twin's although rays were made only where the projected
        // live nodes cover the screen (`render::coverage`): fewer than the samples whose
        // ray meets the live box the rays are clipped to.
        let cam = Camera::orbit(&bounds, 30.0, 20.0, 40.0);
        let settings = RenderSettings {
            width: 160,
            height: 132,
            surfaces: vec![Surface::new(0.85, [0.9, 0.5, 0.4])],
            collect_stats: true,
            ..RenderSettings::default()
        };
        let f = render(&scene, &cam, &settings, &go()).unwrap();
        assert_eq!(f.rgba8, twin(&scene, &cam, &settings).0);
        let raygen = RayGen::new(&cam, 160, 132);
        let live = scene.live_bounds(&scene.prepare(&[0.85]));
        let meet = (0..132u32)
            .flat_map(|y| (0..160u32).map(move |x| (x, y)))
            .filter(|&(x, y)| {
                let ray = raygen.ray_at(x as f32 + 0.5, y as f32 + 0.5);
                live.intersect(&ray, 0.0, f32::INFINITY).is_some()
            })
            .count() as u64;
        let hits = f.depth.iter().filter(|d| d.is_finite()).count() as u64;
        assert!(
            hits > 1000 && f.counts.rays * 20 < meet * 19,
            "{} rays traced, {meet} meet the live box, {hits} hit",
            f.counts.rays
        );
    }

    /// A depth-only frame (`RenderSettings::depth_only`) has the shaded frame's depth map bit
    /// for bit, also when the front surface is transparent, clipped, one ray at a time and
    /// coarse; its pixels are the first hit's flat colour or the background; and the grid's
    /// hits, prepared without normals, are at the same `t` as with them.
    #[test]
    fn depth_only_frames_have_the_shaded_depth_and_flat_colours() {
        use crate::math::rng::Rng;
        let scene = noisy_shells(20, 9);
        let mut rng = Rng::new(9);
        let bounds = scene.world_bounds();
        let (front, back) = ([0.9, 0.5, 0.4], [0.3, 0.8, 0.4]);
        let bits = |d: &[f32]| d.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        let mut hits = 0;
        for (k, (packets, scale, clipped)) in [
            (true, 1, false),
            (true, 1, true),
            (false, 1, false),
            (true, 3, true),
        ]
        .into_iter()
        .enumerate()
        {
            let cam = Camera::orbit(&bounds, 20.0 + 40.0 * k as f32, 25.0, 40.0);
            let shaded = RenderSettings {
                width: 48,
                height: 40,
                scale,
                packets,
                surfaces: vec![
                    Surface {
                        opacity: 0.4,
                        ..Surface::new(0.8, front)
                    },
                    Surface::new(0.45, back),
                ],
                clips: if clipped {
                    vec![ClipRegion::Plane {
                        normal: Vec3::new(0.2, 1.0, 0.3),
                        offset: 0.2,
                    }]
                } else {
                    vec![]
                },
                ..RenderSettings::default()
            };
            let flat = RenderSettings {
                depth_only: true,
                ..shaded.clone()
            };
            let a = render(&scene, &cam, &shaded, &go()).unwrap();
            let b = render(&scene, &cam, &flat, &go()).unwrap();
            assert_eq!(bits(&b.depth), bits(&a.depth), "case {k}");
            let bg = Vec3::from(shaded.background);
            let bg = [to_u8(bg.x), to_u8(bg.y), to_u8(bg.z), 255];
            let flat_of = |c: [f32; 3]| [to_u8(c[0]), to_u8(c[1]), to_u8(c[2]), 255];
            for (px, d) in b.rgba8.chunks_exact(4).zip(&b.depth) {
                if d.is_finite() {
                    hits += 1;
                    assert!(px == flat_of(front) || px == flat_of(back), "{px:?}");
                } else {
                    assert_eq!(px, bg);
                }
            }
        }
        assert!(hits > 600, "{hits} pixels hit");
        // The hits themselves: the same `t` and surface without the normal.
        let ray_isos = [0.8f32, 0.45];
        let (with, without) = (scene.prepare(&ray_isos), scene.prepare_distances(&ray_isos));
        assert!(
            with.normals() == Some(crate::render::Normals::Smooth) && without.normals().is_none()
        );
        let eye = Vec3::new(2.5, 1.9, 2.2);
        let mut found = 0;
        for q in 0..400 {
            let target = Vec3::new(
                rng.range_f32(-0.6, 0.6),
                rng.range_f32(-0.6, 0.6),
                (q % 7) as f32 * 0.1 - 0.3,
            );
            let ray = Ray::new(eye, (target - eye).normalize());
            let a = scene.first_hit_prepared(&ray, 0.0, f32::INFINITY, &with, &mut NoStats);
            let b = scene.first_hit_prepared(&ray, 0.0, f32::INFINITY, &without, &mut NoStats);
            assert_eq!(
                a.map(|h| (h.t.to_bits(), h.surface)),
                b.map(|h| (h.t.to_bits(), h.surface))
            );
            found += usize::from(a.is_some());
        }
        assert!(found > 300, "{found} of 400 rays hit");
    }

    #[test]
    fn frames_equal_the_serial_twin_for_any_thread_count_and_reused_buffers() {
        let scene = SphereScene {
            spheres: vec![(Vec3::ZERO, 1.0), (Vec3::new(0.9, 0.3, 0.2), 0.6)],
            bounds: cube(2.5),
        };
        let bits = |d: &[f32]| d.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        let mut reused = Frame::default();
        let (mut cases, mut hit_cases) = (0, 0);
        // One pool per thread count for all cases: each thread's scratch goes from frame to
        // frame, through other sizes, scales, clips and projections.
        let pools = [1, 3].map(|threads| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            (threads, pool)
        });
        for (k, (w, h, scale)) in [(37, 29, 1), (70, 50, 3), (16, 33, 1), (101, 7, 16)]
            .into_iter()
            .enumerate()
        {
            let mut cam = Camera::orbit(&cube(2.5), 40.0 + 30.0 * k as f32, 25.0, 40.0);
            if k == 2 {
                cam.projection = Projection::Orthographic;
            }
            for clips in [
                vec![],
                vec![
                    ClipRegion::Box {
                        min: Vec3::splat(0.0),
                        max: Vec3::splat(3.0),
                        keep: Keep::Outside,
                    },
                    ClipRegion::Plane {
                        normal: Vec3::new(0.2, 1.0, 0.1),
                        offset: 0.8,
                    },
                ],
            ] {
                let settings = RenderSettings {
                    width: w,
                    height: h,
                    scale,
                    surfaces: vec![
                        Surface {
                            opacity: 0.5,
                            ..Surface::new(0.3, [0.2, 0.4, 0.9])
                        },
                        Surface::new(0.0, [0.9, 0.7, 0.1]),
                    ],
                    clips,
                    max_layers: 3,
                    ..RenderSettings::default()
                };
                let (rgba8, depth) = twin(&scene, &cam, &settings);
                hit_cases += usize::from(depth.iter().any(|d| d.is_finite()));
                for (threads, pool) in &pools {
                    let f = pool.install(|| render(&scene, &cam, &settings, &go()).unwrap());
                    assert_eq!(f.rgba8, rgba8, "case {k}, {threads} threads");
                    assert_eq!(bits(&f.depth), bits(&depth), "case {k}, {threads} threads");
                    // The same frame into a buffer that held a different picture and size.
                    assert!(
                        pool.install(|| {
                            render_into(&scene, &cam, &settings, &go(), &mut reused)
                        })
                    );
                    assert_eq!(reused.rgba8, rgba8);
                    assert_eq!(bits(&reused.depth), bits(&depth));
                    assert_eq!((reused.width, reused.height, reused.scale), (w, h, scale));
                    assert_eq!(reused.rays, f.rays);
                    cases += 1;
                }
            }
        }
        assert_eq!(cases, 16);
        assert!(
            hit_cases >= 6,
            "{hit_cases} of 8 twin frames show a surface"
        );
        // Shadows and statistics: independent of the thread count too.
        let settings = RenderSettings {
            width: 45,
            height: 38,
            surfaces: vec![Surface::new(0.0, [0.9, 0.7, 0.1])],
            shadows: true,
            collect_stats: true,
            light: Light {
                kind: LightKind::Point {
                    pos: Vec3::new(4.0, 3.0, 5.0),
                },
                ..Light::default()
            },
            ..RenderSettings::default()
        };
        let cam = Camera::orbit(&cube(2.5), 10.0, 30.0, 40.0);
        let frames: Vec<Frame> = [1, 2, 3]
            .map(|threads| {
                rayon::ThreadPoolBuilder::new()
                    .num_threads(threads)
                    .build()
                    .unwrap()
                    .install(|| render(&scene, &cam, &settings, &go()).unwrap())
            })
            .into();
        assert!(frames[0].rays.shadow > 0 && frames[0].counts.rays > 0);
        for f in &frames[1..] {
            assert_eq!(f.rgba8, frames[0].rgba8);
            assert_eq!(bits(&f.depth), bits(&frames[0].depth));
            assert_eq!((f.counts, f.rays), (frames[0].counts, frames[0].rays));
        }
    }

    /// A scene that renders a small frame of its own while the outer frame's bands hold
    /// their threads' scratch (as a scene calling the renderer, or a band stealing another
    /// band's job, would): the inner render takes a fresh scratch, and both frames are the
    /// ones rendered alone.
    struct RendersInside {
        scene: SphereScene,
        inner: (Camera, RenderSettings),
        inner_alone: Frame,
        inner_renders: std::sync::atomic::AtomicUsize,
    }

    impl IsoScene for RendersInside {
        type Isovalues = Vec<f32>;

        fn prepare(&self, isovalues: &[f32]) -> Vec<f32> {
            self.scene.prepare(isovalues)
        }

        fn world_bounds(&self) -> Aabb {
            self.scene.world_bounds()
        }

        fn live_boxes(&self, isovalues: &Vec<f32>, out: &mut Vec<Aabb>) {
            self.scene.live_boxes(isovalues, out);
        }

        fn first_hit_prepared<S: Stats>(
            &self,
            ray: &Ray,
            t_min: f32,
            t_max: f32,
            isovalues: &Vec<f32>,
            stats: &mut S,
        ) -> Option<Hit> {
            self.scene
                .first_hit_prepared(ray, t_min, t_max, isovalues, stats)
        }

        fn first_hit_packet_prepared<S: Stats>(
            &self,
            rays: &[Ray],
            t_min: &[f32],
            t_max: &[f32],
            isovalues: &Vec<f32>,
            out: &mut [Option<Hit>],
            stats: &mut S,
        ) {
            let (cam, settings) = &self.inner;
            let f = render(&self.scene, cam, settings, &go()).unwrap();
            assert_eq!(f.rgba8, self.inner_alone.rgba8);
            self.inner_renders.fetch_add(1, Ordering::Relaxed);
            for (i, ray) in rays.iter().enumerate() {
                out[i] = self.first_hit_prepared(ray, t_min[i], t_max[i], isovalues, stats);
            }
        }
    }

    #[test]
    fn a_render_inside_a_band_gets_its_own_scratch() {
        let scene = SphereScene {
            spheres: vec![(Vec3::ZERO, 1.0), (Vec3::new(0.9, 0.3, 0.2), 0.6)],
            bounds: cube(2.5),
        };
        let settings = |w, h, iso| RenderSettings {
            width: w,
            height: h,
            surfaces: vec![Surface::new(iso, [0.9, 0.7, 0.1])],
            ..RenderSettings::default()
        };
        let inner = (
            Camera::orbit(&cube(2.5), 80.0, -10.0, 40.0),
            settings(19, 17, 0.1),
        );
        let inner_alone = render(&scene, &inner.0, &inner.1, &go()).unwrap();
        assert!(inner_alone.depth.iter().any(|d| d.is_finite()));
        let outer = RendersInside {
            scene: scene.clone(),
            inner,
            inner_alone,
            inner_renders: 0.into(),
        };
        let (cam, s) = (
            Camera::orbit(&cube(2.5), 30.0, 20.0, 40.0),
            settings(40, 36, 0.2),
        );
        let (rgba8, depth) = twin(&scene, &cam, &s);
        for threads in [1, 2] {
            let f = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap()
                .install(|| render(&outer, &cam, &s, &go()).unwrap());
            assert_eq!(f.rgba8, rgba8, "{threads} threads");
            let bits = |d: &[f32]| d.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&f.depth), bits(&depth), "{threads} threads");
        }
        assert!(outer.inner_renders.load(Ordering::Relaxed) >= 2);
    }

    /// The sphere scene gives one live box per shell, so the coverage mask is on in these
    /// tests: at every progressive scale the frame is the twin's, yet fewer rays are traced
    /// than there are samples whose ray meets the scene's bounds. (The region test below
    /// renders with the mask too.)
    #[test]
    fn masked_frames_equal_the_twin_at_every_scale() {
        let scene = SphereScene {
            spheres: vec![(Vec3::ZERO, 1.0), (Vec3::new(0.9, 0.3, 0.2), 0.6)],
            bounds: cube(2.5),
        };
        let cam = Camera::orbit(&cube(2.5), 35.0, 20.0, 40.0);
        for scale in [1, 2, 3, 5] {
            let (w, h) = (83, 61);
            let settings = RenderSettings {
                width: w,
                height: h,
                scale,
                surfaces: vec![Surface::new(0.2, [0.9, 0.7, 0.1])],
                collect_stats: true,
                ..RenderSettings::default()
            };
            let f = render(&scene, &cam, &settings, &go()).unwrap();
            assert_eq!(f.rgba8, twin(&scene, &cam, &settings).0, "scale {scale}");
            let raygen = RayGen::new(&cam, w, h);
            let centre = |i: u32, n: u32| {
                (i as f32 * scale as f32 + ((i + 1) as f32 * scale as f32).min(n as f32)) * 0.5
            };
            let (sw, sh) = (w.div_ceil(scale), h.div_ceil(scale));
            let meet = (0..sh)
                .flat_map(|y| (0..sw).map(move |x| (x, y)))
                .filter(|&(x, y)| {
                    let ray = raygen.ray_at(centre(x, w), centre(y, h));
                    scene.bounds.intersect(&ray, 0.0, f32::INFINITY).is_some()
                })
                .count() as u64;
            let hits = f.depth.iter().filter(|d| d.is_finite()).count();
            assert!(
                hits > 0 && f.counts.rays < meet,
                "scale {scale}: {} rays traced, {meet} samples meet the bounds",
                f.counts.rays
            );
        }
    }

    #[test]
    fn regions_render_exactly_their_tiles_and_assemble_into_the_whole_frame() {
        let scene = SphereScene {
            spheres: vec![(Vec3::ZERO, 1.0), (Vec3::new(0.9, 0.3, 0.2), 0.6)],
            bounds: cube(2.5),
        };
        let cam = Camera::orbit(&cube(2.5), 35.0, 20.0, 40.0);
        for (w, h, scale, supersample) in [(70, 45, 1, 1), (70, 45, 2, 1), (50, 37, 1, 2)] {
            let settings = RenderSettings {
                width: w,
                height: h,
                scale,
                supersample,
                shadows: true,
                light: Light {
                    kind: LightKind::Directional {
                        dir: Vec3::new(0.3, 1.0, 0.5),
                    },
                    ..Light::default()
                },
                surfaces: vec![
                    Surface {
                        opacity: 0.5,
                        ..Surface::new(0.3, [0.2, 0.4, 0.9])
                    },
                    Surface::new(0.0, [0.9, 0.7, 0.1]),
                ],
                ..RenderSettings::default()
            };
            let whole = render(&scene, &cam, &settings, &go()).unwrap();
            // Regions of 2×1 tiles, each rendered into its own frame and pasted where it
            // belongs; the assembled frame starts as junk so that a pixel left unwritten
            // would show.
            let side = TILE * scale;
            let mut assembled = Frame {
                rgba8: vec![7; whole.rgba8.len()],
                depth: vec![-1.0; whole.depth.len()],
                ..Frame::default()
            };
            let mut primary = 0;
            let mut part_frame = Frame::default();
            for y0 in (0..h).step_by(side as usize) {
                for x0 in (0..w).step_by(2 * side as usize) {
                    let region = PixelRegion {
                        x: [x0, (x0 + 2 * side).min(w)],
                        y: [y0, (y0 + side).min(h)],
                    };
                    let part = RenderSettings {
                        region: Some(region),
                        ..settings.clone()
                    };
                    assert_eq!(part.validate(), Ok(()));
                    assert!(render_into(&scene, &cam, &part, &go(), &mut part_frame));
                    let (pw, ph) = (region.x[1] - region.x[0], region.y[1] - region.y[0]);
                    assert_eq!((part_frame.width, part_frame.height), (pw, ph));
                    primary += part_frame.rays.primary;
                    for y in 0..ph {
                        for x in 0..pw {
                            let src = (y * pw + x) as usize;
                            let dst = ((y0 + y) * w + x0 + x) as usize;
                            assembled.rgba8[4 * dst..4 * dst + 4]
                                .copy_from_slice(&part_frame.rgba8[4 * src..4 * src + 4]);
                            assembled.depth[dst] = part_frame.depth[src];
                        }
                    }
                }
            }
            assert_eq!(assembled.rgba8, whole.rgba8, "{w}x{h} scale {scale}");
            let bits = |d: &[f32]| d.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&assembled.depth), bits(&whole.depth));
            assert_eq!(primary, whole.rays.primary);
            // A region off the tile grid is widened to the tiles it overlaps (of the
            // supersampled image when supersampling, so only checked without).
            if supersample > 1 {
                continue;
            }
            let odd = RenderSettings {
                region: Some(PixelRegion {
                    x: [side + 3, side + 5],
                    y: [1, 2],
                }),
                ..settings.clone()
            };
            assert!(render_into(&scene, &cam, &odd, &go(), &mut part_frame));
            assert_eq!(
                (part_frame.width, part_frame.height),
                (side.min(w - side), side.min(h))
            );
            assert_eq!(
                pixel(&part_frame, 0, 0),
                pixel(&whole, side, 0),
                "the frame starts at the tile's corner"
            );
        }
        let bad = RenderSettings {
            width: 10,
            height: 10,
            region: Some(PixelRegion {
                x: [0, 11],
                y: [0, 5],
            }),
            ..RenderSettings::default()
        };
        assert!(matches!(bad.validate(), Err(SettingsError::Region { .. })));
    }

    #[test]
    fn progressive_scale_replicates_blocks() {
        let scene = SphereScene::distance_field(Vec3::ZERO, cube(3.0));
        let settings = RenderSettings {
            width: 50,
            height: 37,
            scale: 4,
            surfaces: vec![Surface::new(1.8, [0.3, 0.9, 0.5])],
            ..RenderSettings::default()
        };
        let cam = cam_z(8.0);
        let f = render(&scene, &cam, &settings, &go()).unwrap();
        assert_eq!((f.width, f.height, f.rgba8.len()), (50, 37, 50 * 37 * 4));
        assert_eq!(f.rays.primary, 13 * 10);
        for j in 0..37 {
            for i in 0..50 {
                assert_eq!(pixel(&f, i, j), pixel(&f, i / 4 * 4, j / 4 * 4));
            }
        }
        // The block's ray goes through the block centre: block (6, 4) spans pixels
        // [24, 28) × [16, 20), centre (26, 18).
        let ray = RayGen::new(&cam, 50, 37).ray_at(26.0, 18.0);
        let t = scene
            .first_hit(&ray, 0.0, f32::INFINITY, &[1.8], &mut NoStats)
            .map_or(f32::INFINITY, |h| h.t);
        assert_eq!(f.depth[18 * 50 + 26], t);
    }

    #[test]
    fn cancel_returns_none_and_empty_settings_draw_background() {
        let scene = SphereScene::distance_field(Vec3::ZERO, cube(3.0));
        let settings = RenderSettings {
            width: 20,
            height: 10,
            ..RenderSettings::default()
        };
        assert!(render(&scene, &cam_z(8.0), &settings, &AtomicBool::new(true)).is_none());
        let f = render(&scene, &cam_z(8.0), &settings, &go()).unwrap();
        let bg = settings.background.map(to_u8);
        assert!(f.rgba8.chunks(4).all(|p| p[..3] == bg && p[3] == 255));
        assert!(f.depth.iter().all(|d| d.is_infinite()));
    }

    #[test]
    fn morton_runs_are_compact_blocks() {
        let o = morton_order();
        assert_eq!(o.len(), 256);
        assert_eq!(&o[..4], &[[0, 0], [1, 0], [0, 1], [1, 1]]);
        assert_eq!(o[4], [2, 0]);
        let mut seen = o.clone();
        seen.sort_unstable();
        seen.dedup();
        assert_eq!(seen.len(), 256);
    }
}
