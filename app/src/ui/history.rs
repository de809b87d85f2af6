//! Undo and redo of the view's edits: isosurfaces, clip boxes and planes, and the camera
//! (Ctrl+Z, Ctrl+Shift+Z or Ctrl+Y, and the Edit menu).
//!
//! The viewer feeds the edited part of its state ([`Edits`]) to egui's [`Undoer`] every
//! frame; an undo point is made once the edits have stayed the same for [`STABLE_S`], so a
//! slider drag or an orbit is one step, not one per frame. Opening other data starts a new
//! history: the old surfaces and clips belong to the old data.

use egui::util::undoer::{Settings, Undoer};

use super::state::{CameraState, ClipBoxState, ClipPlaneState, SurfaceState, ViewerState};

/// Seconds without change after which an edit becomes an undo point.
pub const STABLE_S: f32 = 0.4;

/// The part of the state that undo restores.
#[derive(Debug, Clone, PartialEq)]
pub struct Edits {
    pub camera: CameraState,
    pub surfaces: Vec<SurfaceState>,
    pub clip_boxes: Vec<ClipBoxState>,
    pub clip_planes: Vec<ClipPlaneState>,
}

impl Edits {
    pub fn of(state: &ViewerState) -> Self {
        Self {
            camera: state.camera,
            surfaces: state.surfaces.clone(),
            clip_boxes: state.clip_boxes.clone(),
            clip_planes: state.clip_planes.clone(),
        }
    }

    fn apply_to(&self, state: &mut ViewerState) {
        state.camera = self.camera;
        state.surfaces.clone_from(&self.surfaces);
        state.clip_boxes.clone_from(&self.clip_boxes);
        state.clip_planes.clone_from(&self.clip_planes);
    }
}

/// The undo history of one dataset's edits.
pub struct History {
    undoer: Undoer<Edits>,
}

impl Default for History {
    fn default() -> Self {
        Self {
            undoer: Undoer::with_settings(Settings {
                max_undos: 200,
                stable_time: STABLE_S,
                auto_save_interval: 10.0,
            }),
        }
    }
}

impl History {
    /// Notes the state at `time_s` (seconds, egui's input time); true while an edit is in
    /// flux (the caller repaints after [`STABLE_S`] so the edit becomes an undo point
    /// without further input).
    pub fn feed(&mut self, time_s: f64, state: &ViewerState) -> bool {
        self.undoer.feed_state(time_s, &Edits::of(state));
        self.undoer.is_in_flux()
    }

    pub fn can_undo(&self, state: &ViewerState) -> bool {
        self.undoer.has_undo(&Edits::of(state))
    }

    pub fn can_redo(&self, state: &ViewerState) -> bool {
        self.undoer.has_redo(&Edits::of(state))
    }

    /// Puts back the edits before the last undo point; false when there is none.
    pub fn undo(&mut self, state: &mut ViewerState) -> bool {
        match self.undoer.undo(&Edits::of(state)) {
            Some(e) => {
                e.clone().apply_to(state);
                true
            }
            None => false,
        }
    }

    /// Puts back what the last undo took away; false when there is nothing to redo.
    pub fn redo(&mut self, state: &mut ViewerState) -> bool {
        match self.undoer.redo(&Edits::of(state)) {
            Some(e) => {
                e.clone().apply_to(state);
                true
            }
            None => false,
        }
    }

    /// Forgets everything: the next feed is the first undo point.
    pub fn clear(&mut self) {
        *self = Self::default();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn with_iso(iso: f64) -> ViewerState {
        let mut s = ViewerState::default();
        s.surfaces.push(SurfaceState::new(iso, 0));
        s
    }

    #[test]
    fn a_drag_is_one_step_and_redo_comes_back() {
        let mut h = History::default();
        let mut s = with_iso(0.0);
        h.feed(0.0, &s);
        // A drag: many values within the stable time, then a pause.
        for (i, t) in [0.1, 0.15, 0.2, 0.25].iter().enumerate() {
            s.surfaces[0].isovalue = i as f64 + 1.0;
            assert!(h.feed(*t, &s), "in flux while the value changes");
        }
        h.feed(0.3, &s);
        assert!(!h.feed(0.3 + f64::from(STABLE_S) + 0.01, &s));
        assert!(h.can_undo(&s));
        assert!(h.undo(&mut s));
        assert_eq!(
            s.surfaces[0].isovalue, 0.0,
            "one undo takes the whole drag back"
        );
        assert!(!h.can_undo(&s));
        assert!(h.can_redo(&s));
        assert!(h.redo(&mut s));
        assert_eq!(s.surfaces[0].isovalue, 4.0);
        assert!(!h.redo(&mut s));
    }

    #[test]
    fn undo_restores_clips_and_camera_but_not_other_options() {
        let mut h = History::default();
        let mut s = with_iso(1.0);
        h.feed(0.0, &s);
        s.clip_boxes.push(ClipBoxState::default());
        s.camera.zoom *= 2.0;
        s.render.shadows = !s.render.shadows;
        let shadows = s.render.shadows;
        h.feed(1.0, &s);
        h.feed(2.0, &s);
        assert!(h.undo(&mut s));
        assert!(s.clip_boxes.is_empty());
        assert_eq!(s.camera, CameraState::default());
        assert_eq!(
            s.render.shadows, shadows,
            "render options are not edits undo restores"
        );
    }
}
