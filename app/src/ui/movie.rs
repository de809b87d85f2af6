//! File → Movie…: an orbit around the data or the time series played through, written as
//! numbered PNG frames and, when `ffmpeg` is on the PATH, `movie.mp4` — the viewer's
//! `isoscope movie` ([`crate::cli::movie`]: the same frame names, orbit and encoding).
//!
//! The frames are rendered in a job with progress and cancel, from the view on screen
//! (surfaces, clips, options) at the window's size. A time-series movie switches the
//! scene's steps itself, so while it runs the viewer starts no frame or step switch of its
//! own, and the step shown is switched back when the movie ends.

use std::path::PathBuf;
use std::sync::Arc;

use formats::output::Replace;

use super::app::ViewerApp;
use super::backend::PreparedScene;
use super::commands::Command;
use super::jobs::{Job, JobControl};
use super::panels;
use super::scheduler::MAX_RENDER_SIDE;
use crate::cli::movie::{
    Axis, Encoded, MAX_FRAMES, encode_mp4, frame_path, no_ffmpeg_note, orbit_camera, prepare_folder,
};

/// What the Movie window asks (kept in the preferences).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct MovieSettings {
    /// Folder for `frame_0000.png`, … and `movie.mp4`.
    pub folder: PathBuf,
    /// Play the time series through with the camera fixed, instead of orbiting.
    pub time: bool,
    /// Orbit frames.
    pub frames: usize,
    /// Degrees the orbit turns over all its frames.
    pub degrees: f32,
    pub axis: Axis,
    pub fps: f32,
    pub size: [u32; 2],
    /// Replace existing frames and `movie.mp4`.
    pub replace: bool,
}

impl Default for MovieSettings {
    fn default() -> Self {
        Self {
            folder: PathBuf::from("isoscope-movie"),
            time: false,
            frames: 72,
            degrees: 360.0,
            axis: Axis::Z,
            fps: 24.0,
            size: [1280, 720],
            replace: false,
        }
    }
}

impl ViewerApp {
    /// The Movie window (File → Movie…).
    pub(super) fn movie_window_ui(&mut self, ctx: &egui::Context) {
        if !self.rt.movie_window {
            return;
        }
        let steps = self
            .rt
            .data
            .as_ref()
            .map_or(1, super::backend::LoadedData::step_count);
        let m = &mut self.prefs.movie;
        let mut open = true;
        let mut record = false;
        egui::Window::new("Movie")
            .open(&mut open)
            .collapsible(false)
            .show(ctx, |ui| {
                ui.horizontal(|ui| {
                    ui.radio_value(&mut m.time, false, "Orbit");
                    ui.add_enabled_ui(steps > 1, |ui| {
                        ui.radio_value(&mut m.time, true, format!("Time series ({steps} steps)"));
                    });
                });
                if steps <= 1 {
                    m.time = false;
                }
                if !m.time {
                    ui.horizontal(|ui| {
                        panels::labelled_drag(
                            ui,
                            "Frames",
                            panels::number(&mut m.frames).range(1..=MAX_FRAMES),
                        );
                        panels::labelled_drag(
                            ui,
                            "Degrees",
                            panels::number(&mut m.degrees).range(-3600.0..=3600.0),
                        );
                    });
                    ui.horizontal(|ui| {
                        ui.label("Axis");
                        for a in Axis::ALL {
                            ui.radio_value(&mut m.axis, a, a.label());
                        }
                    });
                }
                ui.horizontal(|ui| {
                    let [w, h] = &mut m.size;
                    panels::labelled_drag(ui, "Width", panels::number(w).range(16..=8192));
                    panels::labelled_drag(ui, "Height", panels::number(h).range(16..=8192));
                });
                panels::labelled_drag(
                    ui,
                    "Frames/s",
                    panels::number(&mut m.fps).range(1.0..=120.0),
                );
                let mut folder = m.folder.display().to_string();
                ui.horizontal(|ui| {
                    let l = ui.label("Folder");
                    if ui
                        .text_edit_singleline(&mut folder)
                        .labelled_by(l.id)
                        .changed()
                    {
                        m.folder = PathBuf::from(&folder);
                    }
                });
                ui.checkbox(&mut m.replace, "Replace existing frames");
                ui.label(
                    egui::RichText::new(
                        "PNG frames frame_0000.png, …; movie.mp4 too when ffmpeg is on the PATH",
                    )
                    .small()
                    .weak(),
                );
                record = ui.button("Record").clicked();
            });
        if record {
            self.commands
                .push(Command::Movie(Box::new(self.prefs.movie.clone())));
            open = false;
        }
        self.rt.movie_window = open;
    }

    /// True while a time-series movie switches the scene's steps (the viewer then starts
    /// no frame or step switch of its own).
    pub(super) fn movie_plays_steps(&self) -> bool {
        self.jobs.movie.meta() == Some(&true)
    }

    /// Renders and writes the movie's frames in a job (module docs).
    pub(super) fn start_movie(&mut self, m: MovieSettings) {
        let Some(mut request) = self.desired_request(1) else {
            self.notify("movie: nothing to render yet", true);
            return;
        };
        if !self.scene_ready() {
            self.notify("movie: the scene is still being prepared", true);
            return;
        }
        if self.jobs.movie.is_running() {
            self.notify("movie: one is being recorded already", true);
            return;
        }
        let Some(data) = &self.rt.data else { return };
        let scene = Arc::clone(&data.scene);
        let steps = data.step_count();
        let frames = if m.time { steps } else { m.frames };
        if m.time && steps < 2 {
            self.notify("movie: a time-series movie needs a series", true);
            return;
        }
        if !((1..=MAX_FRAMES).contains(&frames) && m.fps.is_finite() && m.fps > 0.0) {
            self.notify(
                format!(
                    "movie: {frames} frames at {} frames/s is not a movie",
                    m.fps
                ),
                true,
            );
            return;
        }
        request.width = m.size[0].clamp(1, MAX_RENDER_SIDE * 4);
        request.height = m.size[1].clamp(1, MAX_RENDER_SIDE * 4);
        let shown_step = self.rt.scene_step;
        let plays_steps = m.time;
        let label = format!("movie: {frames} frames to {}", m.folder.display());
        let job = Job::spawn(label, self.repaint_fn(), move |control| {
            let result = record(scene.as_ref(), &request, &m, frames, control);
            if m.time {
                // Back to the step the viewer shows, whatever happened.
                let _ = scene.set_step(shown_step, control);
            }
            result
        });
        self.jobs.movie.start(plays_steps, job);
    }
}

/// Draws and writes every frame, then encodes; the message for the user.
fn record(
    scene: &dyn PreparedScene,
    request: &super::backend::RenderRequest,
    m: &MovieSettings,
    frames: usize,
    control: &JobControl,
) -> Result<String, String> {
    let text = |e: anyhow::Error| crate::cli::error_text(&e);
    let replace = Replace::from_force(m.replace);
    prepare_folder(&m.folder, frames, replace).map_err(text)?;
    let first = super::core_backend::camera(request);
    for k in 0..frames {
        if control.is_cancelled() {
            return Err(format!("cancelled after {k} of {frames} frames"));
        }
        let mut req = request.clone();
        if m.time {
            scene.set_step(k, control)?;
            req.step = k;
        } else {
            let c = orbit_camera(&first, m.axis.unit(), m.degrees, k, frames);
            req.camera.eye = c.eye;
            req.camera.up = c.up;
        }
        let img = scene
            .render(&req, control.cancel_flag())?
            .ok_or_else(|| format!("cancelled after {k} of {frames} frames"))?;
        crate::output::save_rgba_image(
            &frame_path(&m.folder, k),
            &img.rgba8,
            img.width,
            img.height,
            replace,
        )
        .map_err(text)?;
        control.set_progress((k + 1) as f32 / frames as f32);
    }
    Ok(match encode_mp4(&m.folder, m.fps, replace).map_err(text)? {
        Encoded::Mp4(movie) => format!("movie: {frames} frames and {}", movie.display()),
        Encoded::NoFfmpeg => format!(
            "movie: {frames} frames in {}; {}",
            m.folder.display(),
            no_ffmpeg_note(&m.folder, m.fps)
        ),
    })
}
