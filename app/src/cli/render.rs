//! `isoscope render FILE [--iso V[:#RRGGBB[:OPACITY]]]... [--camera cam.json | --orbit AZ,EL]
//! [--size WxH] [--intersector NAME] [--shadows] [--light-dir x,y,z] [--clip-box ...]...
//! [--clip-plane ...]... [--layers N] [--background #RRGGBB] [--step N] [--color-by NAME
//! [--colormap NAME] [--color-range MIN,MAX] [--no-scalar-bar]] -o out.png
//! [--depth-out depth.npy]`, plus for tetrahedral meshes `[--field NAME] [--bvh bih|sah]
//! [--leaf-size N] [--packet SIDE] [--normals faceted|smooth]` and for `.isot` files
//! `[--level-timeout SECS] [--budget-mb MIB]`.
//!
//! Opens any supported file as a [`crate::scene::AnyScene`] (kd-tree for volumes, BVH for
//! meshes, treelets for `.isot`), renders one frame with [`volume_core::render::render`]
//! (the one shading path for every kind) and writes a PNG and optionally the first-hit depth
//! as `.npy` (float32, shape (H, W), row 0 at the top, `inf` on miss; see docs/cli.md).
//! An `.isot` render waits for the finest level its isovalues need (at most
//! `--level-timeout`) and reports the level it rendered.
//!
//! The parsers and the camera/volume helpers here are shared with `isoscope bench`.

use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;

use anyhow::{Context as _, bail};
use formats::output::Replace;
use glam::Vec3;
use volume_core::grid::AnyGridScene;
use volume_core::intersect::Intersector;
use volume_core::math::Aabb;
use volume_core::render::{
    Camera, ClipRegion, ColorBy, ColorField, Colormap, Frame, Keep, Light, LightKind,
    RenderSettings, Surface,
};

use super::npy;
use super::open_args::{MeshArgs, OocArgs, OpenArgs, scene_options};
use crate::progress::Progress;
use crate::scene::{AnyScene, RenderIntoVisitor, open_scene};

/// Colours given to `--iso` values without one, in order.
pub const PALETTE: [[f32; 3]; 6] = [
    [0.85, 0.78, 0.62],
    [0.35, 0.6, 0.9],
    [0.9, 0.4, 0.3],
    [0.45, 0.8, 0.45],
    [0.8, 0.5, 0.85],
    [0.95, 0.8, 0.3],
];

/// One `--iso` argument: `V[:#RRGGBB[:OPACITY]]`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IsoSpec {
    pub value: f32,
    pub color: Option<[f32; 3]>,
    pub opacity: f32,
}

/// How the camera is chosen (shared by `render` and `bench`).
// The field docs are clap help text: `[x,y,z]` and `[:N]` are shown as typed, not links.
#[allow(rustdoc::broken_intra_doc_links)]
#[derive(Debug, Clone, Default, clap::Args)]
pub struct ViewArgs {
    /// Camera JSON: {"eye":[x,y,z],"target":[x,y,z],"up":[x,y,z],"vfov_deg":40,
    /// "projection":"pinhole"|"orthographic","ortho_height":H} in world units.
    #[arg(long, value_name = "cam.json", conflicts_with = "orbit")]
    pub camera: Option<PathBuf>,
    /// Orbit camera around the volume centre, framing its bounds: azimuth,elevation in
    /// degrees, +z up (default 30,20).
    #[arg(long, value_name = "AZ,EL", value_parser = parse_orbit, allow_hyphen_values = true)]
    pub orbit: Option<[f32; 2]>,
    /// Vertical field of view of the orbit camera, degrees.
    #[arg(long, value_name = "DEG", default_value_t = 40.0)]
    pub vfov: f32,
}

impl ViewArgs {
    /// The camera: from the JSON file, or an orbit framing `bounds` tightly in an image of
    /// `size` pixels; validated.
    pub fn camera(&self, bounds: &Aabb, size: [u32; 2]) -> anyhow::Result<Camera> {
        let camera = if let Some(path) = &self.camera {
            load_camera(path)?
        } else {
            if !(self.vfov > 0.0 && self.vfov < 180.0) {
                bail!("--vfov {} must be between 0 and 180 degrees", self.vfov);
            }
            let [az, el] = self.orbit.unwrap_or([30.0, 20.0]);
            let aspect = size[0] as f32 / size[1].max(1) as f32;
            Camera::orbit_framed(bounds, az, el, self.vfov, aspect)
        };
        camera.validate()?;
        Ok(camera)
    }
}

/// Reads and validates a camera JSON file (unknown fields are ignored).
pub fn load_camera(path: &Path) -> anyhow::Result<Camera> {
    let text = formats::input::read_regular_to_string(path)
        .with_context(|| format!("cannot read camera file {}", path.display()))?;
    let camera: Camera = serde_json::from_str(&text)
        .with_context(|| format!("camera file {}: not a valid camera", path.display()))?;
    camera
        .validate()
        .with_context(|| format!("camera file {}", path.display()))?;
    Ok(camera)
}

/// What to draw and how: the arguments `render` and `movie` share.
#[allow(rustdoc::broken_intra_doc_links)] // clap help text: `[:N]` is shown as typed
#[derive(Debug, clap::Args)]
pub struct SceneArgs {
    /// Volume file: .nrrd/.nhdr, .nii/.nii.gz, .hdr/.img (NIfTI pair, Analyze), a raw file (with
    /// the raw flags or a NAME.json sidecar), a time series pattern such as vol_%03d.nrrd; a
    /// tetrahedral mesh (.vtk, .vtu, .msh, .node/.ele, .pvd, or a pattern such as
    /// step_%03d.vtu); or an out-of-core .isot file.
    pub file: PathBuf,
    /// Isosurface: value, optional colour and opacity, e.g. 0.5, 500:#e0d0b0, -300:#ff8060:0.4.
    /// Repeat for several surfaces. Default: one surface at the middle of the value range.
    #[arg(long = "iso", value_name = "V[:#RRGGBB[:OPACITY]]", value_parser = parse_iso, allow_hyphen_values = true)]
    pub iso: Vec<IsoSpec>,
    #[command(flatten)]
    pub view: ViewArgs,
    /// Image size in pixels.
    #[arg(long, value_name = "WxH", value_parser = parse_size, default_value = "800x600")]
    pub size: [u32; 2],
    /// Cell intersector: exact (default), linear, neubauer[:N], schwarze, reference.
    #[arg(long, value_name = "NAME", value_parser = parse_intersector)]
    pub intersector: Option<Intersector>,
    /// Cast shadow rays towards the light (default light: above left of the camera).
    #[arg(long)]
    pub shadows: bool,
    /// Flat frame: each pixel's first hit in its surface's colour, with no shading normal,
    /// lighting or transparency (the fastest frame; with `--depth-out`, a depth map at the
    /// cost of the traversal alone).
    #[arg(long, conflicts_with_all = ["shadows", "color_by"])]
    pub depth_only: bool,
    /// Directional light: the direction from the surface towards the light, world units.
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_vec3, allow_hyphen_values = true)]
    pub light_dir: Option<Vec3>,
    /// Clip box by two corners; keeps its inside (default) or outside. Repeatable.
    #[arg(long = "clip-box", value_name = "X0,Y0,Z0,X1,Y1,Z1[:inside|outside]", value_parser = parse_clip_box, allow_hyphen_values = true)]
    pub clip_boxes: Vec<ClipRegion>,
    /// Clip plane keeping the points with nx·x + ny·y + nz·z <= d. Repeatable.
    #[arg(long = "clip-plane", value_name = "NX,NY,NZ,D", value_parser = parse_clip_plane, allow_hyphen_values = true)]
    pub clip_planes: Vec<ClipRegion>,
    /// Most transparent layers composited per pixel.
    #[arg(long, value_name = "N", default_value_t = 4)]
    pub layers: u32,
    /// Anti-aliasing: K×K rays per pixel, averaged (1 to 8; 1 is off).
    #[arg(long, value_name = "K", default_value_t = 1)]
    pub supersample: u32,
    /// Background colour.
    #[arg(long, value_name = "#RRGGBB", value_parser = parse_color)]
    pub background: Option<[f32; 3]>,
    /// Time step of a series (volumes or meshes; default 0).
    #[arg(long, value_name = "N")]
    pub step: Option<usize>,
    /// Colour every surface by another field through a colormap: a mesh point array,
    /// `gradient` (a volume's gradient magnitude), or the path of another volume with the
    /// same dims and geometry.
    #[arg(long, value_name = "NAME")]
    pub color_by: Option<String>,
    /// Colormap of --color-by: viridis (default), magma, coolwarm or grey.
    #[arg(long, value_name = "NAME", value_parser = parse_colormap, requires = "color_by")]
    pub colormap: Option<Colormap>,
    /// Values at the colormap's ends (default: the field's data range); values outside are
    /// clamped.
    #[arg(long, value_name = "MIN,MAX", value_parser = parse_color_range, allow_hyphen_values = true, requires = "color_by")]
    pub color_range: Option<[f32; 2]>,
    /// Leave the scalar bar of --color-by out of the image.
    #[arg(long)]
    pub no_scalar_bar: bool,
    #[command(flatten)]
    pub open: OpenArgs,
    #[command(flatten)]
    pub mesh: MeshArgs,
    #[command(flatten)]
    pub ooc: OocArgs,
}

impl SceneArgs {
    /// Opens the file with these flags ([`open_with_flags`]), and for a volume coloured
    /// by another volume (`--color-by PATH`), that volume.
    pub fn open_scene(&self) -> anyhow::Result<AnyScene> {
        let mut scene = open_with_flags(
            &self.file,
            &self.open,
            &self.mesh,
            &self.ooc,
            self.step,
            self.intersector,
        )?;
        if let (Some(spec), AnyScene::Grid(g)) = (&self.color_by, &mut scene)
            && spec != GRADIENT
        {
            let _spinner = Progress::spinner(format!("opening {spec}"));
            g.add_color_volume(Path::new(spec)).context("--color-by")?;
        }
        Ok(scene)
    }

    /// The camera and render settings these flags give for `scene`.
    pub fn view_of(
        &self,
        scene: &AnyScene,
        collect_stats: bool,
    ) -> anyhow::Result<(Camera, RenderSettings)> {
        let mut surfaces = surfaces_for(&self.iso, scene)?;
        if let Some(color_by) = self.coloring(scene) {
            crate::coloring::color_all(&mut surfaces, &color_by);
        }
        let camera = self.view.camera(&scene.world_bounds(), self.size)?;
        let settings = settings_from(self, &camera, surfaces, collect_stats)?;
        scene.check_colorings(&settings).context("--color-by")?;
        Ok((camera, settings))
    }

    /// The colouring `--color-by` and its flags give for `scene`.
    fn coloring(&self, scene: &AnyScene) -> Option<ColorBy> {
        let spec = self.color_by.as_ref()?;
        Some(ColorBy {
            field: color_field(spec, scene),
            colormap: self.colormap.unwrap_or_default(),
            range: self.color_range,
            scalar_bar: !self.no_scalar_bar,
        })
    }
}

/// The `--color-by` word for a volume's gradient magnitude.
pub const GRADIENT: &str = "gradient";

/// The field `spec` names in `scene`: a point array of that name, else `gradient` for the
/// gradient magnitude, else a named field (a mesh array, or a volume path for grids).
pub fn color_field(spec: &str, scene: &AnyScene) -> ColorField {
    let is_array = scene.data().field_names().contains(&spec);
    if spec == GRADIENT && !(is_array && matches!(scene, AnyScene::Tet(_))) {
        ColorField::Gradient
    } else {
        ColorField::Field(spec.to_owned())
    }
}

/// `viridis`, `magma`, `coolwarm` or `grey`.
pub fn parse_colormap(s: &str) -> Result<Colormap, String> {
    Colormap::from_name(s).ok_or_else(|| {
        let names: Vec<&str> = Colormap::ALL.iter().map(|c| c.name()).collect();
        format!("`{s}`: unknown colormap (available: {})", names.join(", "))
    })
}

/// `MIN,MAX`: finite, `MIN < MAX`.
pub fn parse_color_range(s: &str) -> Result<[f32; 2], String> {
    let bad = || format!("`{s}`: expected MIN,MAX with finite MIN < MAX, such as -1,2.5");
    let parts: Vec<&str> = s.split(',').map(str::trim).collect();
    let [lo, hi] = parts[..] else {
        return Err(bad());
    };
    match (lo.parse::<f32>(), hi.parse::<f32>()) {
        (Ok(lo), Ok(hi)) if lo.is_finite() && hi.is_finite() && lo < hi => Ok([lo, hi]),
        _ => Err(bad()),
    }
}

/// Arguments of `isoscope render`.
#[derive(Debug, clap::Args)]
pub struct Args {
    #[command(flatten)]
    pub scene: SceneArgs,
    /// Output image: PNG (`.png`) or JPEG (`.jpg`, `.jpeg`), by its extension.
    #[arg(short, long, value_name = "out.png")]
    pub output: PathBuf,
    /// Also write the first-hit distance per pixel: float32 .npy, shape (H, W), row 0 at the
    /// top, inf where the ray hits nothing.
    #[arg(long, value_name = "depth.npy")]
    pub depth_out: Option<PathBuf>,
    /// Replace existing output files (never an input file).
    #[arg(long)]
    pub force: bool,
    /// Print traversal statistics (nodes, leaves and intersections per ray; ray-box and
    /// isopolygon tests for meshes).
    #[arg(long)]
    pub stats: bool,
    /// Print what the pixel (column, row from the top left) shows: the surface, its distance
    /// and world position, the value, normal and voxel or tet there. Repeatable.
    #[arg(long = "pick", value_name = "PX,PY", value_parser = parse_pixel)]
    pub pick: Vec<[u32; 2]>,
}

/// `PX,PY`: a pixel's column and row.
fn parse_pixel(s: &str) -> Result<[u32; 2], String> {
    let parts: Vec<&str> = s.split(',').map(str::trim).collect();
    match parts[..] {
        [x, y] => match (x.parse(), y.parse()) {
            (Ok(x), Ok(y)) => Ok([x, y]),
            _ => Err(format!(
                "`{s}`: expected a pixel column,row such as 400,300"
            )),
        },
        _ => Err(format!(
            "`{s}`: expected a pixel column,row such as 400,300"
        )),
    }
}

/// Prints what each picked pixel of `frame` shows (`render --pick`).
fn print_picks(
    picks: &[[u32; 2]],
    scene: &AnyScene,
    camera: &Camera,
    settings: &RenderSettings,
    frame: &Frame,
) -> anyhow::Result<()> {
    for &[px, py] in picks {
        let t = frame.depth[(py * frame.width + px) as usize];
        let size = [frame.width, frame.height];
        let pick = scene.pick(camera, &settings.surfaces, size, [px, py], t)?;
        println!(
            "pick {px},{py}: {}",
            super::probe::pick_text(pick.as_ref(), &settings.surfaces)
        );
    }
    Ok(())
}

/// Surfaces from `--iso` arguments, or one at the middle of the scene's value range.
pub fn surfaces_for(specs: &[IsoSpec], scene: &AnyScene) -> anyhow::Result<Vec<Surface>> {
    if specs.is_empty() {
        let Some(iso) = scene.default_isovalue() else {
            bail!(
                "{} has no finite values, so there is no isosurface to show",
                scene.path().display()
            );
        };
        return Ok(vec![Surface::new(iso, PALETTE[0])]);
    }
    warn_outside_range(specs, scene);
    Ok(specs
        .iter()
        .enumerate()
        .map(|(i, s)| Surface {
            isovalue: s.value,
            color: s.color.unwrap_or(PALETTE[i % PALETTE.len()]),
            opacity: s.opacity,
            visible: true,
            color_by: None,
        })
        .collect())
}

/// Warns on stderr about each isovalue outside the range of the values drawn: its surface is
/// empty, and an empty picture without a word looks like a broken renderer.
fn warn_outside_range(specs: &[IsoSpec], scene: &AnyScene) {
    let f = crate::values::ValueFormat::F32;
    let step = if scene.step_count() > 1 {
        format!(" at time step {}", scene.step())
    } else {
        String::new()
    };
    for s in specs {
        let v = f64::from(s.value);
        match scene.value_range() {
            Some((lo, hi)) if v < lo || v > hi => eprintln!(
                "warning: {}: isovalue {} is outside the data's value range {} .. {}{step}: \
                 its surface is empty",
                scene.path().display(),
                f.value(v),
                f.value(lo),
                f.value(hi)
            ),
            None => eprintln!(
                "warning: {}: no finite value{step}, so isovalue {} draws nothing",
                scene.path().display(),
                f.value(v)
            ),
            Some(_) => {}
        }
    }
}

/// A key light for `--shadows` without `--light-dir`: above, left and behind the camera.
pub fn default_key_light(camera: &Camera) -> Vec3 {
    let (right, up, forward) = camera.basis();
    (-forward + up * 0.8 - right * 0.5).normalize()
}

/// Renders the kd-tree scene (`dda == false`) or its brute-force DDA twin (`dda == true`).
/// `None` if cancelled.
pub fn render_grid(
    scene: &AnyGridScene,
    dda: bool,
    camera: &Camera,
    settings: &RenderSettings,
    cancel: &AtomicBool,
) -> Option<Frame> {
    let mut frame = Frame::default();
    render_grid_into(scene, dda, camera, settings, cancel, &mut frame).then_some(frame)
}

/// [`render_grid`] into `frame`, reusing its buffers; false when cancelled.
pub fn render_grid_into(
    scene: &AnyGridScene,
    dda: bool,
    camera: &Camera,
    settings: &RenderSettings,
    cancel: &AtomicBool,
    frame: &mut Frame,
) -> bool {
    let v = RenderIntoVisitor {
        camera,
        settings,
        colorings: &[],
        cancel,
        frame,
    };
    if dda {
        scene.visit_dda(v)
    } else {
        scene.visit(v)
    }
}

/// Writes `frame` as an RGBA PNG ([`crate::output`]).
pub fn save_png(frame: &Frame, path: &Path, replace: Replace) -> anyhow::Result<()> {
    crate::output::save_rgba_image(path, &frame.rgba8, frame.width, frame.height, replace)
}

/// `bytes` written to a temporary [`formats::output::OutputFile`] for `path`, to commit.
fn staged(
    path: &Path,
    replace: Replace,
    bytes: &[u8],
) -> anyhow::Result<formats::output::OutputFile> {
    use std::io::Write as _;
    let mut out = formats::output::OutputFile::create(path, replace)?;
    out.write_all(bytes)
        .with_context(|| format!("cannot write {}", path.display()))?;
    Ok(out)
}

/// Builds the settings of `isoscope render` (validated).
pub fn settings_from(
    args: &SceneArgs,
    camera: &Camera,
    surfaces: Vec<Surface>,
    collect_stats: bool,
) -> anyhow::Result<RenderSettings> {
    let mut light = Light::default();
    if let Some(dir) = args.light_dir {
        light.kind = LightKind::Directional { dir };
    } else if args.shadows {
        light.kind = LightKind::Directional {
            dir: default_key_light(camera),
        };
    }
    let mut clips = args.clip_boxes.clone();
    clips.extend_from_slice(&args.clip_planes);
    let defaults = RenderSettings::default();
    let settings = RenderSettings {
        width: args.size[0],
        height: args.size[1],
        surfaces,
        clips,
        max_layers: args.layers,
        shadows: args.shadows,
        light,
        background: args.background.unwrap_or(defaults.background),
        collect_stats,
        supersample: args.supersample,
        depth_only: args.depth_only,
        ..defaults
    };
    if args.layers == 0 {
        bail!("--layers must be at least 1");
    }
    settings.validate()?;
    Ok(settings)
}

/// A frame and, for `.isot` files, the level it reached.
pub struct Rendered {
    pub frame: Frame,
    /// `(level rendered, level count)` for out-of-core scenes (0 = coarsest).
    pub ooc_level: Option<(usize, usize)>,
}

/// Most frames `render` draws while a memory budget pages treelets in (each frame loads
/// what it missed; a view settles in a few frames per level).
const MAX_DEMAND_FRAMES: usize = 64;

/// Renders one frame of `scene`. `.isot` scenes first wait (at most `level_timeout`) for
/// the finest level the isovalues need; a damaged treelet is an error, never a picture.
pub fn render_scene(
    scene: &AnyScene,
    camera: &Camera,
    settings: &RenderSettings,
    level_timeout: std::time::Duration,
) -> anyhow::Result<Rendered> {
    render_scene_with(
        scene,
        camera,
        settings,
        level_timeout,
        &AtomicBool::new(false),
    )
}

/// [`render_scene`] that stops when `cancel` is raised (the error then says so).
pub fn render_scene_with(
    scene: &AnyScene,
    camera: &Camera,
    settings: &RenderSettings,
    level_timeout: std::time::Duration,
    cancel: &AtomicBool,
) -> anyhow::Result<Rendered> {
    if let AnyScene::Ooc(o) = scene {
        o.set_isovalues(&settings.active_isovalues().0);
        let finished = {
            let _spinner = Progress::spinner("loading treelets");
            o.wait_until_finished(level_timeout)
        };
        let status = o.status();
        if let Some(e) = &status.error {
            bail!("{}: {e}", scene.path().display());
        }
        if !finished {
            eprintln!(
                "warning: --level-timeout {:.1} s passed with {} of {} levels loaded; rendering the levels loaded so far",
                level_timeout.as_secs_f64(),
                status.loaded_levels,
                status.level_count
            );
        } else if status.budget_limited {
            eprintln!(
                "note: the memory budget holds {} of {} levels; finer treelets this view needs are paged in over frames (least recently used evicted)",
                status.loaded_levels, status.level_count
            );
        }
        let (frame, level) = {
            let _spinner = Progress::spinner("rendering");
            let mut out = None;
            // Demand paging (budget smaller than a level): each frame's missing treelets
            // load after it; render until a frame pages nothing in.
            for _ in 0..MAX_DEMAND_FRAMES {
                let generation = o.volume().generation();
                // Through the scene, so that an MPI job renders it across its ranks.
                out = Some(
                    scene
                        .render_with_level(camera, settings, cancel)
                        .and_then(|(f, level)| level.map(|l| (f, l)))
                        .context("rendering was cancelled")?,
                );
                if !(finished && status.budget_limited) {
                    break;
                }
                o.wait_until_finished(level_timeout);
                if o.volume().generation() == generation {
                    break;
                }
            }
            out.expect("one frame")
        };
        if let Some(e) = o.status().error {
            bail!("{}: {e}", scene.path().display());
        }
        return Ok(Rendered {
            frame,
            ooc_level: Some((level, status.level_count)),
        });
    }
    let frame = {
        let _spinner = Progress::spinner("rendering");
        scene
            .render(camera, settings, cancel)
            .context("rendering was cancelled")?
    };
    Ok(Rendered {
        frame,
        ooc_level: None,
    })
}

/// Opens the file of `render`/`bench` with a spinner and prints reader warnings (skipped
/// mesh cells).
pub fn open_with_flags(
    file: &Path,
    open: &OpenArgs,
    mesh: &MeshArgs,
    ooc: &OocArgs,
    step: Option<usize>,
    intersector: Option<Intersector>,
) -> anyhow::Result<AnyScene> {
    let options = scene_options(file, open, mesh, ooc, step, intersector)?;
    let scene = {
        let _spinner = Progress::spinner(format!("opening {}", file.display()));
        open_scene(file, &options)?
    };
    if let AnyScene::Tet(t) = &scene
        && let Some(w) = t.loaded().skipped_warning()
    {
        eprintln!("warning: {}: {w}", file.display());
    }
    Ok(scene)
}

pub fn run(args: &Args) -> anyhow::Result<()> {
    let replace = Replace::from_force(args.force);
    let mut outputs = vec![args.output.as_path()];
    outputs.extend(args.depth_out.as_deref());
    formats::output::check_distinct(&outputs)?;
    let a = &args.scene;
    let level_timeout = a.ooc.level_timeout()?;
    let scene = a.open_scene()?;
    // Now that the opener has recorded every file the input reads, refuse outputs that are
    // one of them (or exist, without --force) before spending time on the render.
    for out in &outputs {
        formats::output::check_output(out, replace)?;
    }
    let format = crate::output::ImageFormat::for_path(&args.output)?;
    if let Some([px, py]) = args
        .pick
        .iter()
        .find(|[px, py]| *px >= a.size[0] || *py >= a.size[1])
    {
        bail!(
            "--pick {px},{py} is outside the {}x{} image",
            a.size[0],
            a.size[1]
        );
    }
    let (camera, settings) = a.view_of(&scene, args.stats)?;
    let Rendered {
        mut frame,
        ooc_level,
    } = render_scene(&scene, &camera, &settings, level_timeout)?;
    let bars = scene.scalar_bars(&settings);
    crate::scalar_bar::composite(&mut frame.rgba8, frame.width, frame.height, &bars);
    // Both outputs are complete before either is renamed into place: a failed depth map
    // leaves no image either.
    let image = crate::output::rgba_image_bytes(&frame.rgba8, frame.width, frame.height, format)?;
    let mut written = vec![staged(&args.output, replace, &image)?];
    if let Some(path) = &args.depth_out {
        let mut npy_bytes = Vec::new();
        npy::write_f32_2d(
            &mut npy_bytes,
            frame.height as usize,
            frame.width as usize,
            &frame.depth,
        )?;
        written.push(staged(path, replace, &npy_bytes)?);
    }
    for out in written {
        out.commit()?;
    }
    print_picks(&args.pick, &scene, &camera, &settings, &frame)?;
    let secs = frame.elapsed.as_secs_f64();
    let structure = match &scene {
        AnyScene::Grid(g) => format!(
            "{}; kd-tree built in {:.1} ms, {:.2}x data",
            a.intersector.unwrap_or_default(),
            scene.build_time().as_secs_f64() * 1e3,
            g.scene().memory_ratio()
        ),
        AnyScene::Tet(t) => format!(
            "{} tets, field \"{}\"; {:?} BVH built in {:.1} ms, {}x{} packets",
            t.scene().num_tets(),
            t.field(),
            t.scene().bvh().options().builder,
            t.build_time().as_secs_f64() * 1e3,
            packet_side(t.scene().packet_size()),
            packet_side(t.scene().packet_size()),
        ),
        AnyScene::Ooc(o) => {
            let (level, count) = ooc_level.unwrap_or((0, 0));
            format!(
                "{}; out-of-core level {level} of 0..{} ({}), {:.1} MiB resident",
                a.intersector.unwrap_or_default(),
                count.saturating_sub(1),
                if level + 1 == count {
                    "finest"
                } else if o.status().budget_limited {
                    "the finest complete level within the budget; finer treelets this view needs paged in"
                } else {
                    "coarser than the finest"
                },
                o.status().resident_bytes as f64 / f64::from(1u32 << 20)
            )
        }
    };
    eprintln!(
        "{}x{} in {:.1} ms ({:.2} Mrays/s primary; {structure}) -> {}",
        frame.width,
        frame.height,
        secs * 1e3,
        frame.rays.primary as f64 / secs.max(1e-9) / 1e6,
        args.output.display()
    );
    if args.stats {
        let c = frame.counts;
        let rays = c.rays.max(1) as f64;
        let traced = format!(
            "rays traced {} (primary {}, transparency {}, shadow {})",
            c.rays, frame.rays.primary, frame.rays.transparency, frame.rays.shadow
        );
        match scene.as_tet() {
            // A packet visits a node once for all its rays: node and leaf visits per ray
            // would read as a fraction of a leaf.
            Some(t) => {
                let side = packet_side(t.scene().packet_size());
                eprintln!(
                    "{traced}; per ray: {:.2} isopolygon tests",
                    c.intersection_tests as f64 / rays
                );
                eprintln!(
                    "per frame: {} node and {} leaf visits (packets of {side}x{side} rays), {} \
                     ray-box tests, {} isopolygon tests, {} isopolygon extractions",
                    c.nodes_visited,
                    c.leaves_visited,
                    c.box_tests,
                    c.intersection_tests,
                    c.polygon_extractions
                );
            }
            None => eprintln!(
                "{traced}; per ray: {:.1} nodes, {:.1} leaves, {:.2} intersections",
                c.nodes_visited as f64 / rays,
                c.leaves_visited as f64 / rays,
                c.intersection_tests as f64 / rays
            ),
        }
    }
    Ok(())
}

/// Side of a square packet of `rays` rays (`16` for 256).
pub fn packet_side(rays: usize) -> usize {
    (1..=16).find(|s| s * s >= rays).unwrap_or(16)
}

// ---------------------------------------------------------------------------------------
// Parsers (clap value parsers; errors say what was expected).

fn numbers(s: &str, what: &str, n: usize) -> Result<Vec<f32>, String> {
    let v: Vec<f32> = s
        .split(',')
        .map(|p| {
            p.trim()
                .parse::<f32>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| format!("`{s}`: `{p}` is not a finite number"))
        })
        .collect::<Result<_, _>>()?;
    if v.len() != n {
        return Err(format!("`{s}`: expected {what} ({n} numbers)"));
    }
    Ok(v)
}

/// `WxH`, each between 1 and [`volume_core::render::MAX_IMAGE_SIDE`].
pub fn parse_size(s: &str) -> Result<[u32; 2], String> {
    let (w, h) = s
        .split_once(['x', 'X'])
        .ok_or_else(|| format!("`{s}`: expected WxH, e.g. 1024x768"))?;
    let side = |p: &str| {
        p.trim()
            .parse::<u32>()
            .ok()
            .filter(|v| (1..=volume_core::render::MAX_IMAGE_SIDE).contains(v))
            .ok_or_else(|| {
                format!(
                    "`{s}`: `{p}` is not a size between 1 and {}",
                    volume_core::render::MAX_IMAGE_SIDE
                )
            })
    };
    Ok([side(w)?, side(h)?])
}

/// `AZ,EL` in degrees.
pub fn parse_orbit(s: &str) -> Result<[f32; 2], String> {
    let v = numbers(s, "AZ,EL in degrees", 2)?;
    Ok([v[0], v[1]])
}

/// `x,y,z`.
pub fn parse_vec3(s: &str) -> Result<Vec3, String> {
    let v = numbers(s, "x,y,z", 3)?;
    Ok(Vec3::new(v[0], v[1], v[2]))
}

/// `#RRGGBB` (the `#` is optional) to `[0, 1]` channels.
pub fn parse_color(s: &str) -> Result<[f32; 3], String> {
    let hex = s.strip_prefix('#').unwrap_or(s);
    if hex.len() != 6 || !hex.chars().all(|c| c.is_ascii_hexdigit()) {
        return Err(format!("`{s}`: expected a colour #RRGGBB, e.g. #ff8000"));
    }
    let ch = |i: usize| u8::from_str_radix(&hex[i..i + 2], 16).map(|v| f32::from(v) / 255.0);
    Ok([
        ch(0).map_err(|e| e.to_string())?,
        ch(2).map_err(|e| e.to_string())?,
        ch(4).map_err(|e| e.to_string())?,
    ])
}

/// `V[:#RRGGBB[:OPACITY]]`.
pub fn parse_iso(s: &str) -> Result<IsoSpec, String> {
    let mut parts = s.split(':');
    let v = parts.next().unwrap_or_default();
    let value = v
        .trim()
        .parse::<f32>()
        .ok()
        .filter(|x| x.is_finite())
        .ok_or_else(|| format!("`{s}`: isovalue `{v}` is not a finite number"))?;
    let color = match parts.next() {
        None | Some("") => None,
        Some(c) => Some(parse_color(c)?),
    };
    let opacity = match parts.next() {
        None => 1.0,
        Some(o) => o
            .trim()
            .parse::<f32>()
            .ok()
            .filter(|x| (0.0..=1.0).contains(x))
            .ok_or_else(|| format!("`{s}`: opacity `{o}` is not a number in [0, 1]"))?,
    };
    if parts.next().is_some() {
        return Err(format!("`{s}`: expected V[:#RRGGBB[:OPACITY]]"));
    }
    Ok(IsoSpec {
        value,
        color,
        opacity,
    })
}

/// `x0,y0,z0,x1,y1,z1[:inside|outside]` (corners in any order).
pub fn parse_clip_box(s: &str) -> Result<ClipRegion, String> {
    let (coords, keep) = match s.split_once(':') {
        None => (s, Keep::Inside),
        Some((c, k)) => (
            c,
            match k.trim().to_ascii_lowercase().as_str() {
                "inside" | "in" => Keep::Inside,
                "outside" | "out" => Keep::Outside,
                other => return Err(format!("`{s}`: `{other}` is not inside or outside")),
            },
        ),
    };
    let v = numbers(coords, "x0,y0,z0,x1,y1,z1", 6)?;
    let (a, b) = (Vec3::new(v[0], v[1], v[2]), Vec3::new(v[3], v[4], v[5]));
    Ok(ClipRegion::Box {
        min: a.min(b),
        max: a.max(b),
        keep,
    })
}

/// `nx,ny,nz,d`: keeps `n·x <= d`.
pub fn parse_clip_plane(s: &str) -> Result<ClipRegion, String> {
    let v = numbers(s, "nx,ny,nz,d", 4)?;
    let normal = Vec3::new(v[0], v[1], v[2]);
    if normal == Vec3::ZERO {
        return Err(format!("`{s}`: the plane normal is zero"));
    }
    Ok(ClipRegion::Plane {
        normal,
        offset: v[3],
    })
}

/// An intersector name (see `Intersector::from_str`).
pub fn parse_intersector(s: &str) -> Result<Intersector, String> {
    s.parse::<Intersector>().map_err(|e| e.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn iso_specs_parse_with_optional_colour_and_opacity() {
        assert_eq!(
            parse_iso("0.5").unwrap(),
            IsoSpec {
                value: 0.5,
                color: None,
                opacity: 1.0
            }
        );
        let s = parse_iso("-300:#FF8000:0.25").unwrap();
        assert_eq!(s.value, -300.0);
        assert_eq!(s.color, Some([1.0, 128.0 / 255.0, 0.0]));
        assert_eq!(s.opacity, 0.25);
        assert_eq!(parse_iso("2::0.5").unwrap().color, None);
        assert!(parse_iso("nan").is_err());
        assert!(parse_iso("1:#12345").unwrap_err().contains("#RRGGBB"));
        assert!(parse_iso("1:#123456:2").unwrap_err().contains("opacity"));
        assert!(parse_iso("1:#123456:1:x").is_err());
    }

    #[test]
    fn geometry_flags_parse() {
        assert_eq!(parse_size("640x480"), Ok([640, 480]));
        assert!(parse_size("0x10").is_err());
        assert!(parse_size("640").is_err());
        assert_eq!(parse_orbit("-30,45"), Ok([-30.0, 45.0]));
        assert_eq!(parse_vec3("1,-2,3.5"), Ok(Vec3::new(1.0, -2.0, 3.5)));
        assert!(parse_vec3("1,2").is_err());
        assert_eq!(
            parse_clip_box("1,1,1,0,0,0:outside"),
            Ok(ClipRegion::Box {
                min: Vec3::ZERO,
                max: Vec3::ONE,
                keep: Keep::Outside
            })
        );
        assert!(matches!(
            parse_clip_box("0,0,0,1,1,1"),
            Ok(ClipRegion::Box {
                keep: Keep::Inside,
                ..
            })
        ));
        assert!(parse_clip_box("0,0,0,1,1,1:sideways").is_err());
        assert!(parse_clip_plane("0,0,0,1").is_err());
        assert_eq!(
            parse_clip_plane("0,0,1,-0.5"),
            Ok(ClipRegion::Plane {
                normal: Vec3::Z,
                offset: -0.5
            })
        );
        assert_eq!(
            parse_intersector("neubauer:5"),
            Ok(Intersector::Neubauer { iterations: 5 })
        );
        assert!(parse_intersector("magic").is_err());
    }

    #[test]
    fn camera_file_errors_name_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("cam.json");
        std::fs::write(&p, r#"{"eye":[0,0,5],"target":[0,0,5]}"#).unwrap();
        let e = format!("{:#}", load_camera(&p).unwrap_err());
        assert!(e.contains("cam.json") && e.contains("coincide"), "{e}");
        std::fs::write(&p, r#"{"eye":[0,5,5],"target":[0,0,0],"extra":true}"#).unwrap();
        let cam = load_camera(&p).unwrap();
        assert_eq!(cam.eye, Vec3::new(0.0, 5.0, 5.0));
    }
}
