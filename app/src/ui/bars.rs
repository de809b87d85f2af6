//! The menu bar (File, View) and the status bar (frame rate, ray rate, resolution, running
//! jobs with their progress and Cancel, the out-of-core level indicator). Both read the
//! state and push [`Command`]s.

use std::time::{Duration, Instant};

use super::app::ViewerApp;
use super::backend::LodStatus;
use super::commands::Command;

impl ViewerApp {
    pub(super) fn menu_ui(&mut self, ui: &mut egui::Ui) {
        egui::MenuBar::new().ui(ui, |ui| {
            ui.menu_button("File", |ui| {
                if ui.button("Open…").clicked() {
                    self.commands.push(Command::PickFiles);
                }
                if ui.button("Open folder (DICOM)…").clicked() {
                    self.commands.push(Command::PickFolder);
                }
                if ui.button("Open default sample").clicked() {
                    self.commands.push(Command::OpenDefault);
                }
                ui.menu_button("Open recent", |ui| {
                    if self.prefs.recent_files.is_empty() {
                        ui.label("no recent files");
                    }
                    for p in self.prefs.recent_files.clone() {
                        if ui.button(p.display().to_string()).clicked() {
                            self.commands.push(Command::OpenFiles(vec![p]));
                        }
                    }
                });
                ui.separator();
                if ui.button("Save session…").clicked() {
                    self.commands.push(Command::PickSaveSession);
                }
                if ui.button("Open session…").clicked() {
                    self.commands.push(Command::PickLoadSession);
                }
                let last = self.prefs.last_session.clone();
                if ui
                    .add_enabled(last.is_some(), egui::Button::new("Reopen last session"))
                    .clicked()
                    && let Some(last) = last
                {
                    self.commands.push(Command::RestoreSession(Box::new(last)));
                }
                ui.menu_button("Reopen last session at start", |ui| {
                    for choice in super::panels::ReopenLast::ALL {
                        ui.radio_value(&mut self.prefs.reopen_last, choice, choice.label());
                    }
                });
                ui.separator();
                if ui.button("Screenshot…").clicked() {
                    self.rt.screenshot_window = true;
                }
                if ui.button("Movie…").clicked() {
                    self.rt.movie_window = true;
                }
                if ui.button("Export isosurface…").clicked() {
                    self.commands.push(Command::PickExportMesh);
                }
            });
            ui.menu_button("Edit", |ui| {
                let can_undo = self.rt.history.can_undo(&self.state);
                let can_redo = self.rt.history.can_redo(&self.state);
                if ui
                    .add_enabled(can_undo, egui::Button::new("Undo").shortcut_text("Ctrl+Z"))
                    .clicked()
                {
                    self.commands.push(Command::Undo);
                }
                if ui
                    .add_enabled(
                        can_redo,
                        egui::Button::new("Redo").shortcut_text("Ctrl+Shift+Z"),
                    )
                    .clicked()
                {
                    self.commands.push(Command::Redo);
                }
            });
            ui.menu_button("View", |ui| {
                if ui.button("Reset view").clicked() {
                    self.commands.push(Command::ResetView);
                }
                let frame = self
                    .rt
                    .data
                    .as_ref()
                    .map_or(volume_core::WorldFrame::Unknown, |d| d.world_frame);
                for side in super::orientation::ViewSide::ALL {
                    if ui
                        .button(format!("View from {}", side.label(frame)))
                        .clicked()
                    {
                        self.commands.push(Command::ViewFrom(side));
                    }
                }
                ui.checkbox(
                    &mut self.state.render.orientation_marker,
                    "Orientation marker",
                );
            });
        });
    }

    pub(super) fn status_ui(&mut self, ui: &mut egui::Ui) {
        ui.horizontal(|ui| {
            let now = Instant::now();
            while self
                .rt
                .shown_times
                .front()
                .is_some_and(|t| now.duration_since(*t) > Duration::from_secs(1))
            {
                self.rt.shown_times.pop_front();
            }
            ui.label(format!("{} frames/s", self.rt.shown_times.len()));
            if let Some(s) = &self.rt.shown {
                let secs = s.elapsed.as_secs_f64();
                let rays_per_s = if secs > 0.0 {
                    s.rays as f64 / secs
                } else {
                    0.0
                };
                ui.label(format!("{:.2} Mrays/s", rays_per_s / 1e6));
                let res = if s.request.scale > 1 {
                    format!(
                        "{}×{} (1/{} while moving)",
                        s.size[0], s.size[1], s.request.scale
                    )
                } else {
                    format!("{}×{}", s.size[0], s.size[1])
                };
                ui.label(res);
                ui.label(format!("{:.1} ms", secs * 1e3));
            }
            ui.separator();
            let mut cancel = false;
            let job_row = |ui: &mut egui::Ui, label: &str, progress: f32, started: Instant| {
                ui.add(
                    egui::ProgressBar::new(progress)
                        .desired_width(220.0)
                        .text(format!(
                            "{label} {:.0}% {:.1}s",
                            progress * 100.0,
                            started.elapsed().as_secs_f32()
                        )),
                );
            };
            for (label, progress, started) in self.jobs.progress_rows() {
                job_row(ui, label, progress, started);
            }
            if self.jobs.is_cancellable() {
                cancel = ui.button("Cancel").clicked();
                ui.ctx().request_repaint_after(Duration::from_millis(100));
            }
            if let Some(l) = &self.rt.lod {
                ui.separator();
                lod_ui(ui, l, self.rt.shown.as_ref().and_then(|s| s.lod_level));
            }
            if let Some(job) = crate::distributed::status() {
                ui.separator();
                match &job.failure {
                    None => ui.label(format!("MPI: {} ranks", job.ranks)),
                    Some(why) => ui
                        .colored_label(
                            ui.visuals().warn_fg_color,
                            "MPI job failed: rendering locally",
                        )
                        .on_hover_text(why.as_str()),
                };
            }
            if cancel {
                self.commands.push(Command::CancelJobs);
            }
        });
    }
}

/// The out-of-core indicator: levels loaded and drawn, loading progress, resident memory.
fn lod_ui(ui: &mut egui::Ui, l: &LodStatus, drawn_level: Option<usize>) {
    let count = l.level_count.max(1);
    let state = if let Some(e) = &l.error {
        format!("stopped: {e}")
    } else if l.finished && l.budget_limited {
        "memory budget reached".to_string()
    } else if l.finished {
        "loaded".to_string()
    } else {
        "loading…".to_string()
    };
    ui.add(
        egui::ProgressBar::new(l.loaded_levels as f32 / count as f32)
            .desired_width(100.0)
            .text(format!("LOD {}/{count}", l.loaded_levels)),
    );
    let drawn = drawn_level.map_or_else(String::new, |d| format!(", drawn at {}", d + 1));
    ui.label(format!(
        "LOD level {}/{count}{drawn} · {state} · {:.1} MiB resident",
        l.loaded_levels,
        l.resident_bytes as f64 / f64::from(1u32 << 20)
    ));
}
