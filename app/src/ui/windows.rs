//! Windows over the viewport: the raw-file layout dialog, the file browser
//! ([`super::file_browser`]), the DICOM series picker, the screenshot dialog and the
//! notifications (errors stay until dismissed). They read the state and push [`Command`]s;
//! so do files dropped on the window.

use std::path::PathBuf;
use std::time::Duration;

use egui::{Color32, Vec2};

use super::app::ViewerApp;
use super::commands::Command;
use super::file_browser::BrowseOutcome;
use super::panels;

impl ViewerApp {
    /// At start without files: offers the last session (its files, camera, isosurfaces and
    /// clips), with the choice to stop asking.
    fn reopen_offer_ui(&mut self, ctx: &egui::Context) {
        let Some(last) = &self.rt.reopen_offer else {
            return;
        };
        let mut answer = None;
        egui::Window::new("Reopen the last session?")
            .collapsible(false)
            .resizable(false)
            .show(ctx, |ui| {
                for f in last.files.iter().take(4) {
                    ui.label(f.display().to_string());
                }
                if last.files.len() > 4 {
                    ui.label(format!("and {} more", last.files.len() - 4));
                }
                ui.label(format!(
                    "{} isosurface(s), {} clip box(es), {} clip plane(s)",
                    last.surfaces.len(),
                    last.clip_boxes.len(),
                    last.clip_planes.len()
                ));
                ui.horizontal(|ui| {
                    if ui.button("Reopen").clicked() {
                        answer = Some(true);
                    }
                    if ui.button("Not now").clicked() {
                        answer = Some(false);
                    }
                });
                ui.horizontal(|ui| {
                    ui.label("At start:");
                    for choice in panels::ReopenLast::ALL {
                        ui.radio_value(&mut self.prefs.reopen_last, choice, choice.label());
                    }
                });
            });
        match answer {
            Some(true) => {
                let last = self.rt.reopen_offer.take().expect("offer shown");
                self.commands.push(Command::RestoreSession(Box::new(last)));
            }
            Some(false) => self.rt.reopen_offer = None,
            None => {}
        }
    }

    pub(super) fn windows_ui(&mut self, ctx: &egui::Context) {
        if let Some(dialog) = &mut self.rt.raw_dialog {
            let mut open = true;
            let mut confirmed = false;
            egui::Window::new("Raw file layout")
                .open(&mut open)
                .collapsible(false)
                .show(ctx, |ui| {
                    ui.label(dialog.path.display().to_string());
                    ui.label(egui::RichText::new(&dialog.note).small().weak());
                    if let Some(e) = &dialog.error {
                        ui.colored_label(Color32::from_rgb(255, 120, 100), e);
                    }
                    confirmed = panels::raw_layout_ui(ui, &mut dialog.layout);
                });
            if confirmed {
                let d = self.rt.raw_dialog.take().expect("dialog is open");
                self.commands.push(Command::OpenRaw {
                    path: d.path,
                    layout: d.layout,
                    files: d.files,
                });
            } else if !open {
                self.rt.raw_dialog = None;
            }
        }
        if let Some(browser) = &mut self.rt.file_browser {
            match browser.ui(ctx) {
                BrowseOutcome::Open => {}
                BrowseOutcome::Done(command) => {
                    self.commands.push(command);
                    self.rt.file_browser = None;
                }
                BrowseOutcome::Cancelled => self.rt.file_browser = None,
            }
        }
        self.series_picker_ui(ctx);
        self.reopen_offer_ui(ctx);
        self.movie_window_ui(ctx);
        if self.rt.screenshot_window {
            let mut open = true;
            let mut take = false;
            egui::Window::new("Screenshot")
                .open(&mut open)
                .collapsible(false)
                .show(ctx, |ui| {
                    let [w, h] = &mut self.prefs.screenshot_size;
                    ui.horizontal(|ui| {
                        panels::labelled_drag(ui, "Width", panels::number(w).range(16..=16384));
                        panels::labelled_drag(ui, "Height", panels::number(h).range(16..=16384));
                    });
                    let mut path = self.prefs.screenshot_path.display().to_string();
                    ui.horizontal(|ui| {
                        let l = ui.label("PNG file");
                        if ui
                            .text_edit_singleline(&mut path)
                            .labelled_by(l.id)
                            .changed()
                        {
                            self.prefs.screenshot_path = PathBuf::from(&path);
                        }
                    });
                    egui::ComboBox::from_label("Anti-aliasing")
                        .selected_text(panels::supersample_label(self.prefs.screenshot_supersample))
                        .show_ui(ui, |ui| {
                            for k in [1, 2, 3, 4] {
                                ui.selectable_value(
                                    &mut self.prefs.screenshot_supersample,
                                    k,
                                    panels::supersample_label(k),
                                );
                            }
                        });
                    ui.checkbox(
                        &mut self.prefs.screenshot_replace,
                        "Replace an existing file",
                    );
                    take = ui.button("Save PNG").clicked();
                });
            if take {
                let [width, height] = self.prefs.screenshot_size;
                self.commands.push(Command::Screenshot {
                    path: self.prefs.screenshot_path.clone(),
                    width,
                    height,
                    replace: self.prefs.screenshot_replace,
                    supersample: self.prefs.screenshot_supersample,
                });
                open = false;
            }
            self.rt.screenshot_window = open;
        }
        // Notifications, newest at the bottom; errors stay until dismissed.
        self.rt
            .notifications
            .retain(|n| n.is_error || n.created.elapsed() < Duration::from_secs(6));
        if !self.rt.notifications.is_empty() {
            let mut dismiss = None;
            egui::Area::new(egui::Id::unique("isoscope-notifications"))
                .anchor(egui::Align2::RIGHT_TOP, Vec2::new(-12.0, 40.0))
                .show(ctx, |ui| {
                    for (i, n) in self.rt.notifications.iter().enumerate() {
                        egui::Frame::popup(ui.style()).show(ui, |ui| {
                            ui.set_max_width(380.0);
                            let color = if n.is_error {
                                Color32::from_rgb(255, 120, 100)
                            } else {
                                ui.visuals().text_color()
                            };
                            ui.colored_label(color, &n.text);
                            if ui.small_button("Dismiss").clicked() {
                                dismiss = Some(i);
                            }
                        });
                    }
                });
            if let Some(i) = dismiss {
                self.rt.notifications.remove(i);
            }
            ctx.request_repaint_after(Duration::from_secs(1));
        }
    }

    /// The series picker: one row per series of the DICOM input (number, modality, size,
    /// files, description); "Open" on a row opens it. Series that cannot be opened say why.
    fn series_picker_ui(&mut self, ctx: &egui::Context) {
        let Some(dialog) = &self.rt.series_dialog else {
            return;
        };
        let mut open = true;
        let mut picked = None;
        egui::Window::new("DICOM series")
            .open(&mut open)
            .collapsible(false)
            .show(ctx, |ui| {
                ui.label(format!(
                    "{} holds {} series; pick one:",
                    dialog.path.display(),
                    dialog.series.len()
                ));
                egui::ScrollArea::vertical()
                    .max_height(360.0)
                    .show(ui, |ui| {
                        egui::Grid::new("isoscope-series-picker")
                            .striped(true)
                            .show(ui, |ui| {
                                for s in &dialog.series {
                                    let size = format!(
                                        "{} × {} × {}{}",
                                        s.dims[0],
                                        s.dims[1],
                                        s.dims[2],
                                        if s.phases > 1 {
                                            format!(" × {} phases", s.phases)
                                        } else {
                                            String::new()
                                        }
                                    );
                                    ui.label(format!("{}", s.index));
                                    ui.label(&s.modality);
                                    ui.label(size);
                                    ui.label(format!(
                                        "{} file{}",
                                        s.files,
                                        if s.files == 1 { "" } else { "s" }
                                    ));
                                    ui.label(if s.description.is_empty() {
                                        "(no description)"
                                    } else {
                                        &s.description
                                    });
                                    if ui.button("Open").on_hover_text(&s.uid).clicked() {
                                        picked = Some(s.index);
                                    }
                                    if let Some(p) = &s.problem {
                                        ui.colored_label(
                                            Color32::from_rgb(255, 160, 90),
                                            "cannot open",
                                        )
                                        .on_hover_text(p);
                                    }
                                    ui.end_row();
                                }
                            });
                    });
            });
        if let Some(index) = picked {
            let d = self.rt.series_dialog.take().expect("dialog is open");
            self.commands.push(Command::OpenSeries {
                path: d.path,
                series: Some(index.to_string()),
                files: d.files,
            });
        } else if !open {
            self.rt.series_dialog = None;
        }
    }

    /// Files dropped on the window open like files given on the command line.
    pub(super) fn handle_dropped_files(&mut self, ctx: &egui::Context) {
        let dropped: Vec<PathBuf> = ctx.input(|i| {
            i.raw
                .dropped_files
                .iter()
                .map(|f| f.path().to_path_buf())
                .filter(|p| !p.as_os_str().is_empty())
                .collect()
        });
        if !dropped.is_empty() {
            self.commands.push(Command::OpenFiles(dropped));
        }
    }
}
