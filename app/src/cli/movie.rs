//! `isoscope movie FILE [render's scene flags] -o DIR [--frames N] [--degrees D]
//! [--axis x|y|z] [--time] [--fps F] [--force]`: an orbit around the data, or a time series
//! played through, as numbered PNG frames `DIR/frame_0000.png`, … and, when `ffmpeg` is on
//! the PATH, `DIR/movie.mp4` (H.264, yuv420p, as players expect); without `ffmpeg` it says
//! so and keeps the frames.
//!
//! Every frame is a `render` frame: the same flags ([`super::render::SceneArgs`]), camera and
//! renderer. The orbit turns the first frame's camera (`--orbit`, `--camera` or the default)
//! about the world axis `--axis` through its target, `--degrees` over `--frames` frames (a
//! full turn does not repeat its first frame). `--time` keeps the camera and draws step 0,
//! 1, … of a series, switching steps as the viewer does (a refit, not a rebuild). Frames go
//! through [`crate::output`]: never over an input, an existing frame only with `--force`.

use std::path::{Path, PathBuf};
use std::process::Command;

use anyhow::{Context as _, bail};
use formats::output::Replace;
use glam::{Quat, Vec3};
use volume_core::render::Camera;

use super::render::{Rendered, SceneArgs, render_scene};
use crate::progress::Progress;

/// The world axis an orbit turns about.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum, serde::Serialize, serde::Deserialize,
)]
pub enum Axis {
    X,
    Y,
    Z,
}

impl Axis {
    pub const ALL: [Axis; 3] = [Axis::X, Axis::Y, Axis::Z];

    pub fn label(self) -> &'static str {
        match self {
            Axis::X => "x",
            Axis::Y => "y",
            Axis::Z => "z",
        }
    }

    pub fn unit(self) -> Vec3 {
        match self {
            Axis::X => Vec3::X,
            Axis::Y => Vec3::Y,
            Axis::Z => Vec3::Z,
        }
    }
}

/// Arguments of `isoscope movie`.
#[derive(Debug, clap::Args)]
pub struct Args {
    #[command(flatten)]
    pub scene: SceneArgs,
    /// Folder for the frames (`frame_0000.png`, …) and `movie.mp4`; made if missing.
    #[arg(short, long, value_name = "DIR")]
    pub output: PathBuf,
    /// Frames of the orbit (ignored with --time: one frame per step).
    #[arg(long, value_name = "N", default_value_t = 72)]
    pub frames: usize,
    /// Degrees the orbit turns over all its frames.
    #[arg(
        long,
        value_name = "DEG",
        default_value_t = 360.0,
        allow_hyphen_values = true
    )]
    pub degrees: f32,
    /// World axis of the orbit, through the camera's target.
    #[arg(long, value_enum, default_value_t = Axis::Z)]
    pub axis: Axis,
    /// Play the time series through with a fixed camera instead of orbiting.
    #[arg(long)]
    pub time: bool,
    /// Frames per second of movie.mp4.
    #[arg(long, value_name = "F", default_value_t = 24.0)]
    pub fps: f32,
    /// Replace existing frames and movie.mp4 (never an input file).
    #[arg(long)]
    pub force: bool,
}

/// Most frames a movie may have (a 10-minute orbit at 60 fps).
pub const MAX_FRAMES: usize = 36_000;

/// The camera of orbit frame `k` of `frames`: `first` turned `degrees · k / frames` about
/// `axis` through its target (eye and up turn together).
pub fn orbit_camera(first: &Camera, axis: Vec3, degrees: f32, k: usize, frames: usize) -> Camera {
    let angle = (degrees * k as f32 / frames.max(1) as f32).to_radians();
    let turn = Quat::from_axis_angle(axis, angle);
    Camera {
        eye: first.target + turn * (first.eye - first.target),
        up: turn * first.up,
        ..*first
    }
}

/// `DIR/frame_NNNN.png` for frame `k`.
pub fn frame_path(dir: &Path, k: usize) -> PathBuf {
    dir.join(format!("frame_{k:04}.png"))
}

pub fn run(args: &Args) -> anyhow::Result<()> {
    if !(args.fps.is_finite() && args.fps > 0.0) {
        bail!("--fps {} must be a positive number", args.fps);
    }
    if !args.degrees.is_finite() {
        bail!("--degrees {} must be a finite number", args.degrees);
    }
    let a = &args.scene;
    let mut scene = a.open_scene()?;
    let frames = if args.time {
        if scene.step_count() < 2 {
            bail!(
                "--time plays a time series; {} has one step",
                a.file.display()
            );
        }
        scene.step_count()
    } else {
        args.frames
    };
    if frames == 0 || frames > MAX_FRAMES {
        bail!("--frames {frames} must be between 1 and {MAX_FRAMES}");
    }
    let replace = Replace::from_force(args.force);
    prepare_folder(&args.output, frames, replace)?;
    let level_timeout = a.ooc.level_timeout()?;
    if args.time {
        scene.set_step(0)?;
    }
    let (first, settings) = a.view_of(&scene, false)?;
    let progress = Progress::bar(frames as u64, "frames");
    for k in 0..frames {
        let camera = if args.time {
            if k > 0 {
                scene.set_step(k)?;
            }
            first
        } else {
            orbit_camera(&first, args.axis.unit(), args.degrees, k, frames)
        };
        let Rendered { mut frame, .. } = render_scene(&scene, &camera, &settings, level_timeout)?;
        // Per frame: a data range follows the time step.
        let bars = scene.scalar_bars(&settings);
        crate::scalar_bar::composite(&mut frame.rgba8, frame.width, frame.height, &bars);
        crate::output::save_rgba_image(
            &frame_path(&args.output, k),
            &frame.rgba8,
            frame.width,
            frame.height,
            replace,
        )?;
        progress.inc(1);
    }
    drop(progress);
    eprintln!(
        "{frames} frames of {}x{} -> {}",
        settings.width,
        settings.height,
        frame_path(&args.output, 0)
            .with_file_name("frame_%04d.png")
            .display()
    );
    match encode_mp4(&args.output, args.fps, replace)? {
        Encoded::Mp4(movie) => eprintln!("movie -> {}", movie.display()),
        Encoded::NoFfmpeg => eprintln!("note: {}", no_ffmpeg_note(&args.output, args.fps)),
    }
    Ok(())
}

/// Makes the folder for `frames` frames and checks every frame name before the first is
/// drawn: no half-written sequence because frame 40 would replace an input or an old frame.
pub fn prepare_folder(dir: &Path, frames: usize, replace: Replace) -> anyhow::Result<()> {
    if dir.exists() && !dir.is_dir() {
        bail!(
            "{}: is a file; a movie's output names the folder for the frames",
            dir.display()
        );
    }
    std::fs::create_dir_all(dir)
        .with_context(|| format!("{}: cannot make the folder", dir.display()))?;
    for k in 0..frames {
        formats::output::check_output(&frame_path(dir, k), replace)?;
    }
    Ok(())
}

/// What [`encode_mp4`] made.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Encoded {
    Mp4(PathBuf),
    /// `ffmpeg` is not on the PATH: the frames stay, without a movie.
    NoFfmpeg,
}

/// What to tell a user without `ffmpeg`.
pub fn no_ffmpeg_note(dir: &Path, fps: f32) -> String {
    format!(
        "ffmpeg is not on the PATH, so no movie.mp4: the PNG frames are in {} \
         (e.g. `ffmpeg -framerate {fps} -i frame_%04d.png -pix_fmt yuv420p movie.mp4` there)",
        dir.display()
    )
}

/// `DIR/movie.mp4` from the frames by `ffmpeg`, if it is on the PATH.
pub fn encode_mp4(dir: &Path, fps: f32, replace: Replace) -> anyhow::Result<Encoded> {
    let movie = dir.join("movie.mp4");
    let has_ffmpeg = Command::new("ffmpeg")
        .arg("-version")
        .output()
        .is_ok_and(|o| o.status.success());
    if !has_ffmpeg {
        return Ok(Encoded::NoFfmpeg);
    }
    formats::output::check_output(&movie, replace)?;
    // ffmpeg writes a temporary name, renamed when it succeeded: a failed encode leaves no
    // movie.mp4 (the output rule of every command).
    let partial = dir.join(".movie.partial.mp4");
    let status = Command::new("ffmpeg")
        .args(["-hide_banner", "-loglevel", "error", "-y", "-framerate"])
        .arg(fps.to_string())
        .arg("-i")
        .arg(dir.join("frame_%04d.png"))
        // Even sizes for yuv420p; H.264 where the build has it.
        .args([
            "-vf",
            "pad=ceil(iw/2)*2:ceil(ih/2)*2",
            "-pix_fmt",
            "yuv420p",
        ])
        .arg(&partial)
        .status()
        .context("running ffmpeg")?;
    if !status.success() {
        let _ = std::fs::remove_file(&partial);
        bail!("ffmpeg failed ({status}) encoding {}", movie.display());
    }
    std::fs::rename(&partial, &movie)
        .with_context(|| format!("{}: cannot rename the encoded movie", movie.display()))?;
    Ok(Encoded::Mp4(movie))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn orbit_frames_keep_distance_and_turn_evenly() {
        let first = Camera::orbit(
            &volume_core::math::Aabb::new(Vec3::ZERO, Vec3::ONE),
            30.0,
            20.0,
            40.0,
        );
        let r = first.eye.distance(first.target);
        let frames = 8;
        for k in 0..frames {
            let c = orbit_camera(&first, Vec3::Z, 360.0, k, frames);
            assert!((c.eye.distance(c.target) - r).abs() < 1e-4 * r);
            // Turning about z keeps the height.
            assert!((c.eye.z - first.eye.z).abs() < 1e-4 * r);
            // The azimuth advances 45° per frame.
            let az = |e: Vec3| (e.y - first.target.y).atan2(e.x - first.target.x);
            let step = (az(c.eye) - az(first.eye)).to_degrees().rem_euclid(360.0);
            let want = (45.0 * k as f32).rem_euclid(360.0);
            let diff = (step - want).abs();
            assert!(diff.min(360.0 - diff) < 1e-2, "frame {k}: {step} vs {want}");
        }
    }
}
