//! The viewport: the frame on screen (or what is being prepared), orbit/pan/zoom by mouse
//! and keys (which edit the camera state directly and mark the view as moving, so frames
//! are coarse until it settles), the enabled clip boxes' outlines, the orientation marker, and
//! the scalar bars of coloured surfaces (the frame's, as screenshots composite them).

use std::time::Instant;

use egui::{Color32, Pos2, Rect, Sense, Stroke, Vec2};

use super::app::ViewerApp;
use super::camera::{CameraPose, box_edges, clip_box_world};
use super::scheduler::MAX_RENDER_SIDE;

/// Bands a scalar bar's colormap is drawn in.
const STRIPS: usize = 64;

impl ViewerApp {
    pub(super) fn viewport_ui(&mut self, ui: &mut egui::Ui) {
        let rect = ui.available_rect_before_wrap();
        self.rt.viewport_rect = rect;
        let response = ui.allocate_rect(rect, Sense::click_and_drag());
        let ppp = ui.ctx().pixels_per_point();
        self.rt.viewport_px = [
            ((rect.width() * ppp).round() as u32).min(MAX_RENDER_SIDE),
            ((rect.height() * ppp).round() as u32).min(MAX_RENDER_SIDE),
        ];
        let painter = ui.painter_at(rect);
        let bg = self
            .state
            .render
            .background
            .map(|c| (c.clamp(0.0, 1.0) * 255.0) as u8);
        painter.rect_filled(rect, 0.0, Color32::from_rgb(bg[0], bg[1], bg[2]));
        if let Some(s) = &self.rt.shown {
            painter.image(
                s.texture.id(),
                rect,
                Rect::from_min_max(Pos2::ZERO, Pos2::new(1.0, 1.0)),
                Color32::WHITE,
            );
        } else {
            let text = if self.is_busy() {
                "working…"
            } else {
                "no image"
            };
            painter.text(
                rect.center(),
                egui::Align2::CENTER_CENTER,
                text,
                egui::FontId::proportional(18.0),
                Color32::GRAY,
            );
        }
        self.handle_view_input(ui, &response, rect);
        self.handle_pick_input(ui, &response, rect);
        self.draw_clip_outlines(&painter, rect);
        self.draw_pick_marker(&painter, rect);
        self.draw_orientation_marker(&painter, rect);
        self.draw_scalar_bars(ui, &painter, rect);
    }

    /// The shown frame's scalar bars at the right edge: the colormap from max (top) to min,
    /// ticks at max, middle and min, the field's name above.
    fn draw_scalar_bars(&self, ui: &egui::Ui, painter: &egui::Painter, rect: Rect) {
        let Some(shown) = &self.rt.shown else { return };
        if rect.width() < 120.0 || rect.height() < 120.0 {
            return;
        }
        let font = egui::FontId::proportional(12.0);
        let white = Color32::WHITE;
        let (bar_w, pad) = (14.0, 8.0);
        let bar_h = (rect.height() * 0.5).max(60.0);
        let top = rect.center().y - bar_h / 2.0;
        let mut right = rect.right() - pad;
        for (k, bar) in shown.scalar_bars.iter().enumerate() {
            let labels = crate::scalar_bar::tick_labels(bar.range);
            let text_w = labels
                .iter()
                .map(|l| {
                    painter
                        .layout_no_wrap(l.clone(), font.clone(), white)
                        .size()
                        .x
                })
                .fold(0.0_f32, f32::max);
            let title = painter.layout_no_wrap(bar.label.clone(), font.clone(), white);
            let body_w = bar_w + 6.0 + text_w;
            let panel_w = body_w.max(title.size().x) + 2.0 * pad;
            let panel = Rect::from_min_max(
                Pos2::new(right - panel_w, top - title.size().y - 2.0 * pad),
                Pos2::new(right, top + bar_h + pad),
            );
            painter.rect_filled(panel, 4.0, Color32::from_black_alpha(150));
            let x0 = panel.left() + pad;
            painter.galley(Pos2::new(x0, panel.top() + pad * 0.5), title, white);
            for i in 0..STRIPS {
                let t = 1.0 - (i as f32 + 0.5) / STRIPS as f32;
                let c = bar
                    .colormap
                    .at(t)
                    .map(|v| (v.clamp(0.0, 1.0) * 255.0 + 0.5) as u8);
                let y0 = top + bar_h * i as f32 / STRIPS as f32;
                let y1 = top + bar_h * (i + 1) as f32 / STRIPS as f32;
                painter.rect_filled(
                    Rect::from_min_max(Pos2::new(x0, y0), Pos2::new(x0 + bar_w, y1 + 0.5)),
                    0.0,
                    Color32::from_rgb(c[0], c[1], c[2]),
                );
            }
            let bar_rect = Rect::from_min_size(Pos2::new(x0, top), Vec2::new(bar_w, bar_h));
            painter.rect_stroke(
                bar_rect,
                0.0,
                Stroke::new(1.0, white),
                egui::StrokeKind::Outside,
            );
            for (j, label) in labels.iter().enumerate() {
                let y = top + bar_h * j as f32 / 2.0;
                painter.line_segment(
                    [Pos2::new(x0 + bar_w, y), Pos2::new(x0 + bar_w + 4.0, y)],
                    Stroke::new(1.0, white),
                );
                painter.text(
                    Pos2::new(x0 + bar_w + 6.0, y),
                    egui::Align2::LEFT_CENTER,
                    label,
                    font.clone(),
                    white,
                );
            }
            // Screen readers and tests find the bar by its name.
            let name = format!("Scalar bar {}: {} to {}", bar.label, labels[2], labels[0]);
            ui.interact(
                panel,
                ui.make_persistent_id(("scalar_bar", k)),
                Sense::hover(),
            )
            .widget_info(|| egui::WidgetInfo::labeled(egui::Role::Image, true, &name));
            right = panel.left() - pad;
        }
    }

    /// The orientation marker in the bottom-left corner, for the camera on screen.
    fn draw_orientation_marker(&self, painter: &egui::Painter, rect: Rect) {
        let Some(data) = &self.rt.data else { return };
        if !self.state.render.orientation_marker || rect.width().min(rect.height()) < 120.0 {
            return;
        }
        let radius = (rect.width().min(rect.height()) * 0.07).clamp(28.0, 56.0);
        let center = Pos2::new(rect.left() + radius * 1.6, rect.bottom() - radius * 1.6);
        let pose = CameraPose::from_state(&self.state.camera, &data.bounds);
        super::orientation::draw_marker(painter, center, radius, &pose, data.world_frame);
    }

    fn handle_view_input(&mut self, ui: &egui::Ui, response: &egui::Response, rect: Rect) {
        let mut moved = false;
        let (shift, scroll) = ui.input(|i| (i.modifiers.shift, i.smooth_scroll_delta.y));
        let pan_drag = response.dragged_by(egui::PointerButton::Secondary)
            || response.dragged_by(egui::PointerButton::Middle)
            || (shift && response.dragged_by(egui::PointerButton::Primary));
        let d = response.drag_delta();
        let px_to_radii = 2.0 * self.state.camera.zoom / rect.height().max(1.0);
        if pan_drag && d != Vec2::ZERO {
            self.state
                .camera
                .pan_by(-d.x * px_to_radii, d.y * px_to_radii);
            moved = true;
        } else if response.dragged_by(egui::PointerButton::Primary) && d != Vec2::ZERO {
            self.state.camera.orbit(-d.x * 0.4, d.y * 0.4);
            moved = true;
        }
        if response.hovered() && scroll != 0.0 {
            self.state.camera.zoom_by((-scroll * 0.002).exp());
            moved = true;
        }
        let typing = ui.ctx().memory(|m| m.focused().is_some());
        if response.hovered() && !typing {
            let framed = self.framed_view();
            ui.input(|i| {
                use egui::Key;
                let c = &mut self.state.camera;
                let step = if i.modifiers.shift { 1.0 } else { 5.0 };
                let mut any = true;
                if i.key_down(Key::ArrowLeft) {
                    c.orbit(-step, 0.0);
                } else if i.key_down(Key::ArrowRight) {
                    c.orbit(step, 0.0);
                } else if i.key_down(Key::ArrowUp) {
                    c.orbit(0.0, step);
                } else if i.key_down(Key::ArrowDown) {
                    c.orbit(0.0, -step);
                } else if i.key_down(Key::Plus) || i.key_down(Key::Equals) {
                    c.zoom_by(0.97);
                } else if i.key_down(Key::Minus) {
                    c.zoom_by(1.03);
                } else if i.key_pressed(Key::R) {
                    *c = framed;
                } else {
                    any = false;
                }
                moved |= any;
            });
        }
        if moved {
            self.rt.last_interaction = Some(Instant::now());
        }
    }

    /// A click on the image (without dragging), or moving the pointer with Ctrl held,
    /// probes what the pixel shows (the pick section lists it).
    fn handle_pick_input(&mut self, ui: &egui::Ui, response: &egui::Response, rect: Rect) {
        let Some(pos) = response.hover_pos() else {
            return;
        };
        let (ctrl_hover, moved) =
            ui.input(|i| (i.modifiers.command, i.pointer.delta() != Vec2::ZERO));
        let clicked = response.clicked_by(egui::PointerButton::Primary);
        if clicked || (ctrl_hover && moved && !self.jobs.pick.is_running()) {
            let at = (pos - rect.min) / rect.size();
            self.start_pick([at.x, at.y]);
        }
    }

    /// A small cross where the last pick hit, following the camera.
    fn draw_pick_marker(&self, painter: &egui::Painter, rect: Rect) {
        let (Some(data), Some(world)) = (
            &self.rt.data,
            self.rt.pick.as_ref().and_then(|p| p.pick).map(|p| p.world),
        ) else {
            return;
        };
        let pose = CameraPose::from_state(&self.state.camera, &data.bounds);
        let p = glam::Vec3::from(world.map(|v| v as f32));
        if let Some(at) = pose.project(p, rect.width(), rect.height()) {
            let c = rect.min + Vec2::from(at);
            let stroke = Stroke::new(2.0, Color32::from_rgb(255, 60, 200));
            painter.line_segment([c - Vec2::new(7.0, 0.0), c + Vec2::new(7.0, 0.0)], stroke);
            painter.line_segment([c - Vec2::new(0.0, 7.0), c + Vec2::new(0.0, 7.0)], stroke);
        }
    }

    fn draw_clip_outlines(&self, painter: &egui::Painter, rect: Rect) {
        let Some(data) = &self.rt.data else { return };
        let pose = CameraPose::from_state(&self.state.camera, &data.bounds);
        for b in self.state.clip_boxes.iter().filter(|b| b.enabled) {
            let world = clip_box_world(b, &data.bounds);
            for (p, q) in box_edges(&world) {
                if let Some((a, c)) = pose.project_segment(p, q, rect.width(), rect.height()) {
                    painter.line_segment(
                        [rect.min + Vec2::from(a), rect.min + Vec2::from(c)],
                        Stroke::new(1.5, Color32::from_rgb(255, 200, 40)),
                    );
                }
            }
        }
    }
}
