//! Anatomical orientation in the viewer: the six standard views (the camera looks at the data
//! from the anterior, posterior, left, right, superior or inferior side, as 3D Slicer's and
//! ParaView's view buttons do) and the orientation marker drawn in a corner of the viewport
//! (the world axes as the camera sees them, labelled L/R, A/P, S/I when the data's world
//! frame is known, else x/y/z).
//!
//! The world frame comes from the file (`volume_core::WorldFrame`: NIfTI is RAS, DICOM and
//! MetaImage are LPS); data without one gets the same views, named after the world axes
//! (`+X` is the side `+x` points to) and read as RAS.

use egui::{Color32, Pos2, Stroke, Vec2};
use glam::Vec3;
use volume_core::WorldFrame;

use super::camera::CameraPose;
use super::state::CameraState;

/// A side of the data the camera can look from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ViewSide {
    Anterior,
    Posterior,
    Left,
    Right,
    Superior,
    Inferior,
}

impl ViewSide {
    pub const ALL: [ViewSide; 6] = [
        ViewSide::Anterior,
        ViewSide::Posterior,
        ViewSide::Left,
        ViewSide::Right,
        ViewSide::Superior,
        ViewSide::Inferior,
    ];

    /// The anatomical letter of the side.
    pub const fn letter(self) -> char {
        match self {
            ViewSide::Anterior => 'A',
            ViewSide::Posterior => 'P',
            ViewSide::Left => 'L',
            ViewSide::Right => 'R',
            ViewSide::Superior => 'S',
            ViewSide::Inferior => 'I',
        }
    }

    /// The button label: the anatomical name, or the world axis when the frame is unknown.
    pub fn label(self, frame: WorldFrame) -> &'static str {
        match (frame.is_known(), self) {
            (true, ViewSide::Anterior) => "Anterior",
            (true, ViewSide::Posterior) => "Posterior",
            (true, ViewSide::Left) => "Left",
            (true, ViewSide::Right) => "Right",
            (true, ViewSide::Superior) => "Superior",
            (true, ViewSide::Inferior) => "Inferior",
            (false, ViewSide::Right) => "+X",
            (false, ViewSide::Left) => "−X",
            (false, ViewSide::Anterior) => "+Y",
            (false, ViewSide::Posterior) => "−Y",
            (false, ViewSide::Superior) => "+Z",
            (false, ViewSide::Inferior) => "−Z",
        }
    }

    /// The world direction from the data towards this side (unit length).
    pub fn world_direction(self, frame: WorldFrame) -> Vec3 {
        let frame = if frame.is_known() {
            frame
        } else {
            WorldFrame::Ras
        };
        frame
            .direction_of(self.letter())
            .map_or(Vec3::Z, glam::DVec3::as_vec3)
    }
}

impl CameraState {
    /// Looks at the data from `side`, centred, keeping the zoom. Side views keep the world's
    /// +z (superior) up; the superior and inferior views put the anterior side at the top of
    /// the picture, as radiology viewers do.
    pub fn view_from(&mut self, side: ViewSide, frame: WorldFrame) {
        let d = side.world_direction(frame);
        let (azimuth, elevation) = if d.z.abs() < 0.5 {
            (d.y.atan2(d.x).to_degrees(), 0.0)
        } else {
            // Looking down (up), the picture's up is −(+) the azimuth's horizontal direction
            // (`CameraPose::from_state`): point it at the anterior side.
            let a = ViewSide::Anterior.world_direction(frame);
            let toward = if d.z > 0.0 { -a } else { a };
            (
                toward.y.atan2(toward.x).to_degrees(),
                Self::MAX_ELEVATION_DEG.copysign(d.z),
            )
        };
        self.azimuth_deg = azimuth.rem_euclid(360.0);
        self.elevation_deg = elevation;
        self.pan = [0.0, 0.0];
    }
}

/// One arm of the orientation marker: a world axis end projected into the marker's disc.
#[derive(Debug, Clone, PartialEq)]
pub struct MarkerArm {
    /// Offset from the marker's centre in points (y down), length ≤ the marker radius.
    pub offset: Vec2,
    /// How far the arm points towards the viewer (−1 … 1); arms are drawn far first.
    pub toward_viewer: f32,
    /// The label at the arm's end (an anatomical letter, or `+x`…).
    pub label: String,
    /// World axis 0, 1 or 2.
    pub axis: usize,
    pub positive: bool,
}

/// The marker's six arms (both ends of each world axis) for `pose`, in draw order (far
/// first). With an unknown frame only the positive ends are labelled (`x`, `y`, `z`).
pub fn marker_arms(pose: &CameraPose, frame: WorldFrame, radius: f32) -> Vec<MarkerArm> {
    let basis = pose.basis();
    let mut arms = Vec::with_capacity(6);
    for axis in 0..3 {
        for positive in [true, false] {
            let mut e = Vec3::ZERO;
            e[axis] = if positive { 1.0 } else { -1.0 };
            let label = match frame.letter(axis, positive) {
                Some(c) => c.to_string(),
                None if positive => ["x", "y", "z"][axis].to_string(),
                None => String::new(),
            };
            arms.push(MarkerArm {
                offset: Vec2::new(e.dot(basis.right), -e.dot(basis.up)) * radius,
                toward_viewer: -e.dot(basis.forward),
                label,
                axis,
                positive,
            });
        }
    }
    arms.sort_by(|a, b| a.toward_viewer.total_cmp(&b.toward_viewer));
    arms
}

/// Axis colours as in Slicer and ParaView: x red, y green, z blue.
const AXIS_COLORS: [Color32; 3] = [
    Color32::from_rgb(230, 80, 70),
    Color32::from_rgb(90, 200, 90),
    Color32::from_rgb(90, 140, 250),
];

/// Draws the marker with its centre at `center`.
pub fn draw_marker(
    painter: &egui::Painter,
    center: Pos2,
    radius: f32,
    pose: &CameraPose,
    frame: WorldFrame,
) {
    painter.circle_filled(center, radius * 1.3, Color32::from_black_alpha(110));
    let font = egui::FontId::proportional((radius * 0.32).max(10.0));
    for arm in marker_arms(pose, frame, radius) {
        let color = AXIS_COLORS[arm.axis];
        let (width, color) = if arm.positive {
            (2.5, color)
        } else {
            (1.2, color.gamma_multiply(0.6))
        };
        let tip = center + arm.offset * 0.8;
        painter.line_segment([center, tip], Stroke::new(width, color));
        if !arm.label.is_empty() {
            painter.text(
                center + arm.offset * 1.05,
                egui::Align2::CENTER_CENTER,
                &arm.label,
                font.clone(),
                if arm.positive {
                    Color32::WHITE
                } else {
                    Color32::from_gray(170)
                },
            );
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use volume_core::math::Aabb;

    fn pose(state: &CameraState) -> CameraPose {
        CameraPose::from_state(state, &Aabb::new(Vec3::splat(-1.0), Vec3::splat(1.0)))
    }

    /// The arm whose label is `letter`.
    fn arm<'a>(arms: &'a [MarkerArm], letter: &str) -> &'a MarkerArm {
        arms.iter().find(|a| a.label == letter).unwrap()
    }

    #[test]
    fn every_view_looks_from_its_side_with_the_expected_up() {
        for frame in [WorldFrame::Ras, WorldFrame::Lps, WorldFrame::Unknown] {
            for side in ViewSide::ALL {
                let mut state = CameraState {
                    pan: [0.3, -0.2],
                    ..CameraState::default()
                };
                state.view_from(side, frame);
                assert_eq!(state.pan, [0.0, 0.0]);
                let p = pose(&state);
                let b = p.basis();
                let d = side.world_direction(frame);
                // The camera sits on `side` and looks back at the centre.
                assert!(b.forward.dot(-d) > 0.9999, "{frame:?} {side:?}: {b:?}");
                let want_up = if d.z.abs() > 0.5 {
                    ViewSide::Anterior.world_direction(frame)
                } else {
                    Vec3::Z
                };
                assert!(
                    b.up.dot(want_up) > 0.999,
                    "{frame:?} {side:?}: up {:?}",
                    b.up
                );
            }
        }
    }

    #[test]
    fn anatomical_sides_follow_the_world_frame() {
        // RAS: +x is right; LPS: +x is left; both: +z is superior.
        assert_eq!(ViewSide::Right.world_direction(WorldFrame::Ras), Vec3::X);
        assert_eq!(ViewSide::Right.world_direction(WorldFrame::Lps), -Vec3::X);
        assert_eq!(
            ViewSide::Anterior.world_direction(WorldFrame::Lps),
            -Vec3::Y
        );
        assert_eq!(ViewSide::Superior.world_direction(WorldFrame::Lps), Vec3::Z);
        assert_eq!(ViewSide::Right.label(WorldFrame::Unknown), "+X");
        assert_eq!(ViewSide::Right.label(WorldFrame::Lps), "Right");
    }

    #[test]
    fn the_marker_shows_the_patient_as_the_camera_sees_it() {
        for frame in [WorldFrame::Ras, WorldFrame::Lps] {
            // Facing the patient (anterior view): their right is on the screen's left, their
            // head at the top, anterior towards the viewer.
            let mut state = CameraState::default();
            state.view_from(ViewSide::Anterior, frame);
            let arms = marker_arms(&pose(&state), frame, 40.0);
            assert_eq!(arms.len(), 6);
            assert!(arm(&arms, "R").offset.x < -39.0, "{frame:?}: {arms:?}");
            assert!(arm(&arms, "L").offset.x > 39.0);
            assert!(arm(&arms, "S").offset.y < -39.0, "screen y points down");
            assert!(arm(&arms, "A").toward_viewer > 0.999);
            assert!(arm(&arms, "A").offset.length() < 0.1);
            // Drawn far first: posterior (away from the viewer) before anterior.
            assert_eq!(arms.first().unwrap().label, "P");
            assert_eq!(arms.last().unwrap().label, "A");
            // From above with the face at the top, the patient's right is on the screen's
            // right (the view down the body axis, from the head).
            state.view_from(ViewSide::Superior, frame);
            let arms = marker_arms(&pose(&state), frame, 40.0);
            assert!(arm(&arms, "A").offset.y < -39.0, "{frame:?}: {arms:?}");
            assert!(arm(&arms, "R").offset.x > 39.0, "{frame:?}: {arms:?}");
        }
        // Unknown frame: the positive world axes are labelled, the negative ends are not.
        let arms = marker_arms(&pose(&CameraState::default()), WorldFrame::Unknown, 40.0);
        let labels: Vec<&str> = arms.iter().map(|a| a.label.as_str()).collect();
        for l in ["x", "y", "z"] {
            assert!(labels.contains(&l), "{labels:?}");
        }
        assert_eq!(labels.iter().filter(|l| l.is_empty()).count(), 3);
    }
}
