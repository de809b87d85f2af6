//! Side-panel sections as `*_ui(ui, &mut state, ...)` functions, and the side panel that
//! stacks them (`ViewerApp::side_ui`).
//!
//! Panels edit the persisted [`ViewerState`] directly (a changed isovalue simply changes the
//! next render request) and queue a [`Command`] for anything with side effects (opening
//! files, adding or removing items, screenshots), which the viewer applies at the start of
//! the next frame. Every input widget carries a label (accessibility, and kittest finds
//! widgets by label).

use std::path::PathBuf;

use egui::{Color32, DragValue, Pos2, Rect, Sense, Slider, Stroke, Ui, Vec2};

use super::app::ViewerApp;
use super::backend::{DataKindLabel, LoadedData};
use super::commands::Command;
use super::state::{
    ClipBoxState, ClipPlaneState, IntersectorChoice, KeepSide, NormalsChoice, RawLayoutState,
    SurfaceState, ViewerState,
};
use crate::coloring::ScalarBar;
use volume_core::render::{ColorBy, ColorField, Colormap};

/// UI preferences kept across runs (eframe storage), not part of a session.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct Prefs {
    pub recent_files: Vec<PathBuf>,
    pub log_histogram: bool,
    pub screenshot_size: [u32; 2],
    pub screenshot_path: PathBuf,
    /// Replace an existing screenshot file (off: an existing file is an error, as without
    /// `--force` on the command line).
    pub screenshot_replace: bool,
    /// Screenshots' anti-aliasing: `k × k` samples per pixel (1: off).
    pub screenshot_supersample: u32,
    /// The Movie window's settings.
    pub movie: super::movie::MovieSettings,
    /// Whether a start without files reopens the last session.
    pub reopen_last: ReopenLast,
    /// The state when the viewer last saved its preferences with files shown (absolute
    /// paths): what "reopen the last session" restores.
    pub last_session: Option<ViewerState>,
}

/// Whether `isoscope` without files reopens the last session's files, camera,
/// isosurfaces and clips.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
pub enum ReopenLast {
    Always,
    /// Offer it in a window (the embedded sample shows meanwhile).
    #[default]
    Ask,
    Never,
}

impl ReopenLast {
    pub const ALL: [ReopenLast; 3] = [ReopenLast::Always, ReopenLast::Ask, ReopenLast::Never];

    pub fn label(self) -> &'static str {
        match self {
            ReopenLast::Always => "always",
            ReopenLast::Ask => "ask",
            ReopenLast::Never => "never",
        }
    }
}

impl Default for Prefs {
    fn default() -> Self {
        Self {
            recent_files: Vec::new(),
            log_histogram: true,
            screenshot_size: [1920, 1080],
            screenshot_path: PathBuf::from("isoscope-screenshot.png"),
            screenshot_replace: false,
            screenshot_supersample: 2,
            movie: super::movie::MovieSettings::default(),
            reopen_last: ReopenLast::default(),
            last_session: None,
        }
    }
}

/// Most recent first, at most this many.
pub const MAX_RECENT: usize = 10;

impl Prefs {
    /// Puts `path` first in the recent files, as an absolute path (a relative one would name
    /// another file, or none, when the viewer starts in another working directory).
    pub fn remember(&mut self, path: &std::path::Path) {
        let path = super::files::absolute_path(path);
        self.recent_files.retain(|p| *p != path);
        self.recent_files.insert(0, path);
        self.recent_files.truncate(MAX_RECENT);
    }
}

/// A numeric field that applies a typed value when the edit ends (Enter or focus lost).
///
/// egui applies typed text on every keystroke by default, and every field here clamps: a
/// partial entry ("0" on the way to "0.3") was clamped into the range, and the clamped
/// value's text replaced what was being typed. Every numeric field of the viewer is made
/// here or by [`slider`] so that none of them does that.
pub(super) fn number<Num: egui::emath::Numeric>(value: &mut Num) -> DragValue<'_> {
    DragValue::new(value).update_while_editing(false)
}

/// A slider whose value field applies typed text when the edit ends (see [`number`]).
pub(super) fn slider<Num: egui::emath::Numeric>(
    value: &mut Num,
    range: std::ops::RangeInclusive<Num>,
) -> Slider<'_> {
    Slider::new(value, range).update_while_editing(false)
}

/// A labelled numeric field (kittest and screen readers find it by `label`).
pub(super) fn labelled_drag(ui: &mut Ui, label: &str, widget: DragValue<'_>) -> egui::Response {
    ui.horizontal(|ui| {
        let l = ui.label(label);
        ui.add(widget).labelled_by(l.id)
    })
    .inner
}

fn color_button(ui: &mut Ui, label: &str, rgb: &mut [f32; 3]) -> egui::Response {
    ui.horizontal(|ui| {
        let l = ui.label(label);
        ui.color_edit_button_rgb(rgb).labelled_by(l.id)
    })
    .inner
}

/// Data summary and the list of opened files.
pub fn data_ui(
    ui: &mut Ui,
    state: &ViewerState,
    data: Option<&LoadedData>,
    active_file: usize,
    spacing_edit: &mut Option<(PathBuf, [f64; 3])>,
    commands: &mut Vec<Command>,
) {
    match data {
        Some(d) => {
            ui.label(egui::RichText::new(&d.name).strong());
            ui.label(&d.summary);
            ui.label(format!(
                "values {} … {}",
                d.value_format.value(d.value_range.0),
                d.value_format.value(d.value_range.1)
            ));
            let e = d.bounds.extent();
            ui.label(format!("extent {:.4} × {:.4} × {:.4}", e.x, e.y, e.z));
            if d.step_count() > 1 {
                ui.label(format!("{} time steps", d.step_count()));
            }
            if let (Some(current), false) = (&d.field, d.fields.is_empty()) {
                let mut chosen = current.clone();
                egui::ComboBox::from_label("Point array")
                    .selected_text(current.as_str())
                    .show_ui(ui, |ui| {
                        for f in &d.fields {
                            ui.selectable_value(&mut chosen, f.clone(), f.as_str());
                        }
                    })
                    .response
                    .on_hover_text(
                        "the scalar point array the isosurfaces are drawn of (meshes, VTK images)",
                    );
                if &chosen != current {
                    commands.push(Command::SetField(chosen));
                }
            }
            if let Some(path) = d.path.as_ref().filter(|p| formats::tiff::is_tiff_path(p)) {
                tiff_spacing_ui(ui, d, path, spacing_edit, commands);
            }
        }
        None => {
            ui.label("no data loaded");
        }
    }
    if state.files.len() > 1 {
        ui.separator();
        for (i, f) in state.files.iter().enumerate() {
            let name = f.file_name().map_or_else(
                || f.display().to_string(),
                |n| n.to_string_lossy().into_owned(),
            );
            if ui.selectable_label(i == active_file, name).clicked() {
                commands.push(Command::ShowFile(i));
            }
        }
    }
}

/// TIFF stacks: the spacing per axis (ImageJ metadata or 1 where the file says nothing), and
/// *Apply spacing* to open the stack again with the edited values (the CLI's `--spacing`).
fn tiff_spacing_ui(
    ui: &mut Ui,
    d: &LoadedData,
    path: &std::path::Path,
    spacing_edit: &mut Option<(PathBuf, [f64; 3])>,
    commands: &mut Vec<Command>,
) {
    if spacing_edit.as_ref().is_none_or(|(p, _)| p != path) {
        // The shown grid's spacing: its extent over its cells (TIFF grids are uniform and
        // axis-aligned).
        let e = d.bounds.extent();
        let spacing = [0, 1, 2].map(|a| {
            let cells = d.dims[a].saturating_sub(1);
            if cells == 0 {
                1.0
            } else {
                f64::from(e[a]) / cells as f64
            }
        });
        *spacing_edit = Some((path.to_path_buf(), spacing));
    }
    let Some((_, spacing)) = spacing_edit.as_mut() else {
        return;
    };
    ui.horizontal_wrapped(|ui| {
        for (a, axis) in ["x", "y", "z"].iter().enumerate() {
            labelled_drag(
                ui,
                &format!("Spacing {axis}"),
                number(&mut spacing[a])
                    .speed(0.01)
                    .range(1e-6..=1e6)
                    .max_decimals(6),
            );
        }
    });
    if ui
        .button("Apply spacing")
        .on_hover_text("open the stack again with this spacing (for axes without metadata)")
        .clicked()
    {
        commands.push(Command::SetTiffSpacing(*spacing));
    }
}

/// The histogram of the data with a marker per isosurface; `log` compresses tall bins.
///
/// It is also a slider: pressing on it picks the nearest surface marker, dragging moves it
/// (the value under the pointer), so isovalues can be put on the histogram's features.
pub fn histogram_ui(
    ui: &mut Ui,
    data: &LoadedData,
    surfaces: &mut [SurfaceState],
    log: bool,
) -> egui::Response {
    let size = Vec2::new(ui.available_width(), 72.0);
    let (rect, response) = ui.allocate_exact_size(size, Sense::click_and_drag());
    response.widget_info(|| egui::WidgetInfo::labeled(egui::Role::Slider, true, "Histogram"));
    let painter = ui.painter_at(rect);
    painter.rect_filled(rect, 2.0, ui.visuals().extreme_bg_color);
    let counts: &[u64] = data.histogram.as_ref().map_or(&[], |h| &h.counts);
    if counts.is_empty() {
        painter.text(
            rect.center(),
            egui::Align2::CENTER_CENTER,
            "no histogram",
            egui::FontId::proportional(11.0),
            ui.visuals().weak_text_color(),
        );
    }
    let height = |c: u64| if log { (c as f32 + 1.0).ln() } else { c as f32 };
    let max = counts
        .iter()
        .map(|&c| height(c))
        .fold(0.0_f32, f32::max)
        .max(1e-6);
    let bar_w = rect.width() / counts.len().max(1) as f32;
    let bar_color = ui
        .visuals()
        .widgets
        .inactive
        .fg_stroke
        .color
        .gamma_multiply(0.6);
    for (i, &c) in counts.iter().enumerate() {
        let h = height(c) / max * rect.height();
        let x0 = rect.left() + i as f32 * bar_w;
        painter.rect_filled(
            Rect::from_min_max(
                Pos2::new(x0, rect.bottom() - h),
                Pos2::new(x0 + bar_w, rect.bottom()),
            ),
            0.0,
            bar_color,
        );
    }
    let (lo, hi) = data.value_range;
    if hi <= lo {
        return response;
    }
    let x_of = |v: f64| rect.left() + ((v - lo) / (hi - lo)) as f32 * rect.width();
    let value_of =
        |x: f32| lo + f64::from(((x - rect.left()) / rect.width()).clamp(0.0, 1.0)) * (hi - lo);
    // Drag: the surface picked at the press follows the pointer.
    let grab_id = response.id.with("grabbed");
    if let Some(pos) = response.interact_pointer_pos() {
        if response.drag_started() || response.clicked() {
            let nearest = surfaces
                .iter()
                .enumerate()
                .min_by(|(_, a), (_, b)| {
                    (x_of(a.isovalue) - pos.x)
                        .abs()
                        .total_cmp(&(x_of(b.isovalue) - pos.x).abs())
                })
                .map(|(i, _)| i);
            ui.data_mut(|d| d.insert_temp(grab_id, nearest));
        }
        let grabbed = ui.data(|d| d.get_temp::<Option<usize>>(grab_id)).flatten();
        if let Some(s) = grabbed.and_then(|i| surfaces.get_mut(i)) {
            s.isovalue = value_of(pos.x);
        }
    }
    for s in surfaces.iter() {
        let x = x_of(s.isovalue);
        let c = s.color.map(|v| (v.clamp(0.0, 1.0) * 255.0) as u8);
        let stroke = Stroke::new(
            if s.visible { 2.0 } else { 1.0 },
            Color32::from_rgb(c[0], c[1], c[2]),
        );
        painter.vline(x, rect.y_range(), stroke);
        // A handle at the top, like a slider's knob.
        painter.circle_filled(Pos2::new(x, rect.top() + 5.0), 4.0, stroke.color);
    }
    response.on_hover_text("drag to move the nearest isovalue")
}

/// Add/remove surfaces; value slider over the histogram, exact entry, color, opacity,
/// visibility, colouring by another field. `shown_bars` are the scalar bars of the frame on
/// screen (the data range a colouring's fixed range starts from).
pub fn isosurface_ui(
    ui: &mut Ui,
    state: &mut ViewerState,
    data: Option<&LoadedData>,
    log_histogram: &mut bool,
    shown_bars: &[ScalarBar],
    commands: &mut Vec<Command>,
) {
    let Some(data) = data else {
        ui.label("load data to add isosurfaces");
        return;
    };
    let (lo, hi) = data.value_range;
    histogram_ui(ui, data, &mut state.surfaces, *log_histogram);
    ui.horizontal(|ui| {
        ui.label(
            egui::RichText::new(format!(
                "{} … {}",
                data.value_format.value(lo),
                data.value_format.value(hi)
            ))
            .small()
            .weak(),
        );
    });
    if !data.histogram_note.is_empty() {
        ui.label(
            egui::RichText::new(if data.histogram.is_some() {
                format!("histogram of {}", data.histogram_note)
            } else {
                data.histogram_note.clone()
            })
            .small()
            .weak(),
        );
    }
    ui.checkbox(log_histogram, "Log-scale histogram");
    // Leave room for the slider's label so the panel does not grow frame after frame.
    let slider_width = (ui.available_width() - 150.0).max(60.0);
    let mut remove = None;
    for (i, s) in state.surfaces.iter_mut().enumerate() {
        ui.push_id(("surface", i), |ui| {
            ui.separator();
            ui.horizontal(|ui| {
                ui.checkbox(&mut s.visible, format!("Surface {}", i + 1));
                if ui.button("Remove").clicked() {
                    remove = Some(i);
                }
            });
            ui.spacing_mut().slider_width = slider_width;
            ui.add(
                slider(&mut s.isovalue, lo..=hi)
                    .text(format!("Isovalue {}", i + 1))
                    .show_value(false),
            );
            ui.horizontal(|ui| {
                let speed = ((hi - lo) / 1000.0).max(1e-9);
                labelled_drag(
                    ui,
                    &format!("Value {}", i + 1),
                    number(&mut s.isovalue).speed(speed).max_decimals(9),
                );
                color_button(ui, "Color", &mut s.color);
            });
            ui.add(slider(&mut s.opacity, 0.0..=1.0).text(format!("Opacity {}", i + 1)));
            color_by_ui(ui, i, s, data, shown_bars, commands);
        });
    }
    if let Some(i) = remove {
        commands.push(Command::RemoveSurface(i));
    }
    ui.separator();
    if ui.button("Add isosurface").clicked() {
        commands.push(Command::AddSurface);
    }
}

/// Surface `i`'s colouring: "Colour by" solid, a point array or added volume, the gradient
/// magnitude or another volume (the file browser); its colormap, range (the data range, or
/// fixed minimum and maximum applied when an edit ends) and scalar bar.
fn color_by_ui(
    ui: &mut Ui,
    i: usize,
    s: &mut SurfaceState,
    data: &LoadedData,
    shown_bars: &[ScalarBar],
    commands: &mut Vec<Command>,
) {
    let n = i + 1;
    let current = s.color_by.as_ref().map(|c| c.field.clone());
    let mut choice: Option<Option<ColorField>> = None;
    egui::ComboBox::from_label(format!("Colour by {n}"))
        .selected_text(current.as_ref().map_or("solid", ColorField::label))
        .show_ui(ui, |ui| {
            if ui.selectable_label(current.is_none(), "solid").clicked() {
                choice = Some(None);
            }
            let mut options: Vec<ColorField> = data
                .color_fields
                .iter()
                .map(|f| ColorField::Field(f.clone()))
                .collect();
            if data.gradient_coloring {
                options.push(ColorField::Gradient);
            }
            for f in options {
                if ui
                    .selectable_label(current.as_ref() == Some(&f), f.label())
                    .clicked()
                {
                    choice = Some(Some(f));
                }
            }
            if data.gradient_coloring && ui.selectable_label(false, "other volume…").clicked() {
                commands.push(Command::PickColorVolume(i));
            }
        });
    if let Some(new) = choice {
        s.color_by = new.map(|field| match s.color_by.take() {
            Some(mut c) => {
                if c.field != field {
                    c.range = None;
                }
                c.field = field;
                c
            }
            None => ColorBy::new(field),
        });
    }
    let Some(c) = &mut s.color_by else {
        return;
    };
    ui.horizontal(|ui| {
        egui::ComboBox::from_label(format!("Colormap {n}"))
            .selected_text(c.colormap.name())
            .show_ui(ui, |ui| {
                for map in Colormap::ALL {
                    ui.selectable_value(&mut c.colormap, map, map.name());
                }
            });
        ui.checkbox(&mut c.scalar_bar, format!("Scalar bar {n}"));
    });
    let mut data_range = c.range.is_none();
    ui.checkbox(&mut data_range, format!("Data range {n}"));
    if data_range {
        c.range = None;
        return;
    }
    // A fixed range starts from the range on screen.
    let label = c.field.label();
    let [mut lo, mut hi] = c.range.unwrap_or_else(|| {
        shown_bars
            .iter()
            .find(|b| label.ends_with(b.label.as_str()))
            .map_or([0.0, 1.0], |b| b.range)
    });
    ui.horizontal(|ui| {
        let speed = (f64::from(hi - lo).abs() / 1000.0).max(1e-9);
        labelled_drag(ui, &format!("Min {n}"), number(&mut lo).speed(speed));
        labelled_drag(ui, &format!("Max {n}"), number(&mut hi).speed(speed));
    });
    // Only a usable range is taken (min < max, finite); anything else keeps the last one.
    if lo.is_finite() && hi.is_finite() && lo < hi {
        c.range = Some([lo, hi]);
    } else if c.range.is_none() {
        c.range = Some([0.0, 1.0]);
    }
}

/// Clip boxes with per-axis range sliders and keep inside/outside; clip planes.
pub fn clip_ui(ui: &mut Ui, state: &mut ViewerState, commands: &mut Vec<Command>) {
    const AXES: [&str; 3] = ["x", "y", "z"];
    let mut remove_box = None;
    for (i, b) in state.clip_boxes.iter_mut().enumerate() {
        ui.push_id(("clip_box", i), |ui| {
            ui.horizontal(|ui| {
                ui.checkbox(&mut b.enabled, format!("Clip box {}", i + 1));
                if ui.button("Remove").clicked() {
                    remove_box = Some(i);
                }
            });
            ui.horizontal(|ui| {
                ui.radio_value(&mut b.keep, KeepSide::Inside, "Keep inside");
                ui.radio_value(&mut b.keep, KeepSide::Outside, "Keep outside");
            });
            for (a, name) in AXES.iter().enumerate() {
                ui.add(slider(&mut b.min[a], 0.0..=1.0).text(format!("Box {} {name} min", i + 1)));
                ui.add(slider(&mut b.max[a], 0.0..=1.0).text(format!("Box {} {name} max", i + 1)));
                if b.min[a] > b.max[a] {
                    b.max[a] = b.min[a];
                }
            }
        });
        ui.separator();
    }
    if let Some(i) = remove_box {
        commands.push(Command::RemoveClipBox(i));
    }
    let mut remove_plane = None;
    for (i, p) in state.clip_planes.iter_mut().enumerate() {
        ui.push_id(("clip_plane", i), |ui| {
            ui.horizontal(|ui| {
                ui.checkbox(&mut p.enabled, format!("Clip plane {}", i + 1));
                if ui.button("Remove").clicked() {
                    remove_plane = Some(i);
                }
            });
            ui.horizontal(|ui| {
                for (a, name) in AXES.iter().enumerate() {
                    labelled_drag(
                        ui,
                        &format!("n{name}"),
                        number(&mut p.normal[a]).speed(0.01).range(-1.0..=1.0),
                    );
                }
            });
            ui.add(slider(&mut p.offset, -1.0..=1.0).text(format!("Plane {} offset", i + 1)));
        });
        ui.separator();
    }
    if let Some(i) = remove_plane {
        commands.push(Command::RemoveClipPlane(i));
    }
    ui.horizontal(|ui| {
        if ui.button("Add clip box").clicked() {
            commands.push(Command::AddClipBox);
        }
        if ui.button("Add clip plane").clicked() {
            commands.push(Command::AddClipPlane);
        }
    });
}

/// Normals, intersector (grids and `.isot`), transparency layers, shadows and light,
/// background.
pub fn render_options_ui(ui: &mut Ui, state: &mut ViewerState, kind: Option<DataKindLabel>) {
    let colored = state.surfaces.iter().any(|s| s.color_by.is_some());
    let o = &mut state.render;
    let tet = kind == Some(DataKindLabel::Tet);
    let default = if tet {
        NormalsChoice::Faceted
    } else {
        NormalsChoice::Smooth
    };
    let mut shown = o.normals.unwrap_or(default);
    let (faceted_tip, smooth_tip) = if tet {
        (
            "the isopolygon's plane: the data as computed (default for meshes)",
            "vertex gradients interpolated by M = N·V⁻¹ (thesis §8.3)",
        )
    } else {
        (
            "the gradient of the hit cell's trilinear interpolant: the exact normal of the \
             surface drawn, turning at cell faces; reads 8 voxels instead of 32",
            "central differences at the cell's corners, blended trilinearly (thesis §6.4; \
             default for volumes)",
        )
    };
    ui.horizontal(|ui| {
        ui.label("Normals");
        ui.radio_value(&mut shown, NormalsChoice::Faceted, "Faceted")
            .on_hover_text(faceted_tip);
        ui.radio_value(&mut shown, NormalsChoice::Smooth, "Smooth")
            .on_hover_text(smooth_tip);
    });
    if shown != o.normals.unwrap_or(default) {
        o.normals = Some(shown);
    }
    let note = match (shown, tet) {
        (NormalsChoice::Faceted, true) => "faceted: each isopolygon's plane, the data as computed",
        (NormalsChoice::Smooth, true) => "smooth: interpolated vertex gradients (thesis 004 §8.3)",
        (NormalsChoice::Faceted, false) => {
            "faceted: each cell's own surface normal (shows the cells)"
        }
        (NormalsChoice::Smooth, false) => "smooth: central differences (thesis 004 §6.4)",
    };
    ui.label(egui::RichText::new(note).small().weak());
    if !tet {
        egui::ComboBox::from_label("Intersector")
            .selected_text(o.intersector.cli_name())
            .show_ui(ui, |ui| {
                for c in IntersectorChoice::ALL {
                    ui.selectable_value(&mut o.intersector, c, c.cli_name())
                        .on_hover_text(c.note());
                }
            });
        ui.label(egui::RichText::new(o.intersector.note()).small().weak());
    }
    egui::ComboBox::from_label("Anti-aliasing when still")
        .selected_text(supersample_label(o.supersample))
        .show_ui(ui, |ui| {
            for k in [1, 2, 3, 4] {
                ui.selectable_value(&mut o.supersample, k, supersample_label(k));
            }
        })
        .response
        .on_hover_text("k×k rays per pixel, averaged, once the view stops moving");
    ui.checkbox(&mut o.flat, "Flat (first hits, no lighting)")
        .on_hover_text(
            "each pixel's first hit in its surface's colour: no normals, lighting, shadows or \
             transparency; the fastest frame",
        );
    if o.flat && colored {
        ui.label(
            egui::RichText::new("flat: surfaces coloured by a field are drawn in their own colour")
                .small()
                .weak(),
        );
    }
    ui.add(slider(&mut o.max_layers, 1..=16).text("Transparency layers"));
    ui.checkbox(&mut o.shadows, "Shadows");
    ui.add(slider(&mut o.light_azimuth_deg, -180.0..=180.0).text("Light azimuth °"));
    ui.add(slider(&mut o.light_elevation_deg, -89.0..=89.0).text("Light elevation °"));
    color_button(ui, "Background", &mut o.background);
}

/// "off" or "k×k" for a supersampling factor.
pub fn supersample_label(k: u32) -> String {
    if k <= 1 {
        "off".to_string()
    } else {
        format!("{k}×{k} samples")
    }
}

/// Camera: view presets, field of view, projection, reset, bookmarks.
pub fn camera_ui(
    ui: &mut Ui,
    state: &mut ViewerState,
    frame: volume_core::WorldFrame,
    commands: &mut Vec<Command>,
) {
    view_side_buttons(ui, frame, commands);
    ui.checkbox(&mut state.render.orientation_marker, "Orientation marker");
    ui.add(slider(&mut state.camera.vfov_deg, 10.0..=90.0).text("Field of view °"));
    ui.checkbox(&mut state.camera.orthographic, "Orthographic");
    ui.horizontal(|ui| {
        if ui.button("Reset view").clicked() {
            commands.push(Command::ResetView);
        }
        if ui.button("Bookmark view").clicked() {
            commands.push(Command::AddBookmark);
        }
    });
    let mut remove = None;
    for (i, b) in state.bookmarks.iter().enumerate() {
        ui.horizontal(|ui| {
            if ui.button(format!("View {}", i + 1)).clicked() {
                state.camera = *b;
            }
            if ui
                .small_button("Delete")
                .on_hover_text("Delete bookmark")
                .clicked()
            {
                remove = Some(i);
            }
        });
    }
    if let Some(i) = remove {
        state.bookmarks.remove(i);
    }
    ui.label(
        egui::RichText::new(
            "drag: orbit · right/middle or shift-drag: pan · wheel: zoom · arrows, +/−, R",
        )
        .small()
        .weak(),
    );
}

/// The six standard views: anatomical names when the world frame is known, else world axes.
pub fn view_side_buttons(ui: &mut Ui, frame: volume_core::WorldFrame, commands: &mut Vec<Command>) {
    use super::orientation::ViewSide;
    ui.horizontal_wrapped(|ui| {
        ui.label("View from");
        for side in ViewSide::ALL {
            let hover = if frame.is_known() {
                format!(
                    "Look from the {} side ({})",
                    side.label(frame).to_lowercase(),
                    frame.name()
                )
            } else {
                format!(
                    "Look from {} (the file gives no anatomical frame)",
                    side.label(frame)
                )
            };
            if ui.button(side.label(frame)).on_hover_text(hover).clicked() {
                commands.push(Command::ViewFrom(side));
            }
        }
    });
}

/// Width beside the time-step slider's track: its value field and its "Time step" label.
const TIME_SLIDER_EXTRAS_PX: f32 = 130.0;

/// Time slider, step buttons, play/pause, loop, fps, and the current step and time value.
pub fn time_ui(
    ui: &mut Ui,
    state: &mut ViewerState,
    data: Option<&LoadedData>,
    commands: &mut Vec<Command>,
) {
    let Some(data) = data else { return };
    let count = data.step_count();
    if count <= 1 {
        return;
    }
    let t = &mut state.time;
    ui.horizontal(|ui| {
        if ui.button("First").on_hover_text("First step").clicked() {
            commands.push(Command::SetStep(0));
        }
        if ui.button("Prev").on_hover_text("Previous step").clicked() {
            commands.push(Command::SetStep(t.step.saturating_sub(1)));
        }
        let play_label = if t.playing { "Pause" } else { "Play" };
        if ui.button(play_label).clicked() {
            t.playing = !t.playing;
        }
        if ui.button("Next").on_hover_text("Next step").clicked() {
            commands.push(Command::SetStep((t.step + 1).min(count - 1)));
        }
        if ui.button("Last").on_hover_text("Last step").clicked() {
            commands.push(Command::SetStep(count - 1));
        }
        ui.checkbox(&mut t.looping, "Loop");
        ui.spacing_mut().slider_width = 90.0;
        ui.add(
            slider(&mut t.fps, 0.5..=60.0)
                .logarithmic(true)
                .text("Playback fps"),
        );
        ui.label(format!(
            "step {} / {}  t = {:.4}",
            t.step,
            count - 1,
            data.time_value(t.step)
        ));
        // The step slider takes what is left of the row (its value field and label beside
        // it), so that every control fits a narrow window.
        let mut step = t.step;
        ui.spacing_mut().slider_width = (ui.available_width() - TIME_SLIDER_EXTRAS_PX).max(60.0);
        if ui
            .add(slider(&mut step, 0..=count - 1).text("Time step"))
            .changed()
        {
            commands.push(Command::SetStep(step));
        }
    });
}

/// The raw-file dialog body: dims, type, endianness, header bytes, spacing.
/// Returns true when the user confirmed.
pub fn raw_layout_ui(ui: &mut Ui, layout: &mut RawLayoutState) -> bool {
    ui.horizontal(|ui| {
        for (a, name) in ["nx", "ny", "nz"].iter().enumerate() {
            labelled_drag(ui, name, number(&mut layout.dims[a]).range(1..=1 << 20));
        }
    });
    egui::ComboBox::from_label("Voxel type")
        .selected_text(layout.voxel_type.clone())
        .show_ui(ui, |ui| {
            for t in ["u8", "i8", "u16", "i16", "u32", "i32", "f32", "f64"] {
                ui.selectable_value(&mut layout.voxel_type, t.to_string(), t);
            }
        });
    ui.horizontal(|ui| {
        ui.radio_value(&mut layout.little_endian, true, "Little endian");
        ui.radio_value(&mut layout.little_endian, false, "Big endian");
    });
    labelled_drag(ui, "Header bytes", number(&mut layout.header_bytes));
    ui.horizontal(|ui| {
        for (a, name) in ["sx", "sy", "sz"].iter().enumerate() {
            labelled_drag(
                ui,
                name,
                number(&mut layout.spacing[a]).speed(0.01).range(1e-9..=1e9),
            );
        }
    });
    ui.button("Open raw file").clicked()
}

/// Adds a surface at the middle of the value range (or after the last one).
pub fn new_surface(state: &ViewerState, data: &LoadedData) -> SurfaceState {
    let (lo, hi) = data.value_range;
    let value = match state.surfaces.last() {
        Some(last) => (last.isovalue + 0.25 * (hi - lo)).min(hi),
        None => 0.5 * (lo + hi),
    };
    SurfaceState::new(value, state.surfaces.len())
}

pub fn new_clip_box() -> ClipBoxState {
    ClipBoxState::default()
}

pub fn new_clip_plane() -> ClipPlaneState {
    ClipPlaneState::default()
}

/// The pick section: what the last click on the image hit (the CLI's `render --pick`
/// line, a field per row), copyable.
fn pick_ui(ui: &mut Ui, pick: &mut Option<super::runtime::PickShown>) {
    let Some(p) = pick else {
        ui.weak("Click the image to probe a point (hold Ctrl to follow the pointer).");
        return;
    };
    for line in p.text.split("; ") {
        ui.label(line);
    }
    let text = p.text.clone();
    ui.horizontal(|ui| {
        if ui.button("Copy").clicked() {
            ui.ctx().copy_text(text);
        }
        if ui.button("Clear").clicked() {
            *pick = None;
        }
    });
}

impl ViewerApp {
    /// The side panel: every section in a collapsible header.
    pub(super) fn side_ui(&mut self, ui: &mut Ui) {
        egui::ScrollArea::vertical().show(ui, |ui| {
            egui::CollapsingHeader::new("Data")
                .default_open(true)
                .show(ui, |ui| {
                    data_ui(
                        ui,
                        &self.state,
                        self.rt.data.as_ref(),
                        self.rt.active_file,
                        &mut self.rt.spacing_edit,
                        &mut self.commands,
                    );
                });
            egui::CollapsingHeader::new("Pick")
                .default_open(true)
                .show(ui, |ui| pick_ui(ui, &mut self.rt.pick));
            egui::CollapsingHeader::new("Isosurfaces")
                .default_open(true)
                .show(ui, |ui| {
                    let bars = self
                        .rt
                        .shown
                        .as_ref()
                        .map_or(&[][..], |s| &s.scalar_bars[..]);
                    isosurface_ui(
                        ui,
                        &mut self.state,
                        self.rt.data.as_ref(),
                        &mut self.prefs.log_histogram,
                        bars,
                        &mut self.commands,
                    );
                });
            egui::CollapsingHeader::new("Clipping")
                .default_open(true)
                .show(ui, |ui| {
                    clip_ui(ui, &mut self.state, &mut self.commands);
                });
            egui::CollapsingHeader::new("Rendering")
                .default_open(true)
                .show(ui, |ui| {
                    render_options_ui(ui, &mut self.state, self.rt.data.as_ref().map(|d| d.kind));
                });
            egui::CollapsingHeader::new("Camera")
                .default_open(false)
                .show(ui, |ui| {
                    let frame = self
                        .rt
                        .data
                        .as_ref()
                        .map_or(volume_core::WorldFrame::Unknown, |d| d.world_frame);
                    camera_ui(ui, &mut self.state, frame, &mut self.commands);
                });
        });
    }
}
