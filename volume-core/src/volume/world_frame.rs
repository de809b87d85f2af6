//! What the world axes of a volume mean anatomically.
//!
//! Medical formats fix a patient coordinate system: NIfTI's world is RAS+ (+x toward the
//! patient's Right, +y Anterior, +z Superior), DICOM's and MetaImage's is LPS+ (+x Left,
//! +y Posterior, +z Superior); NRRD names its `space`. Isoscope keeps each file's own world
//! coordinates and records the frame, so `info` and the viewer can label directions, and
//! [`WorldFrame::ras_from_world`] brings volumes of either frame into one (RAS) to compare
//! them. Data without a patient frame (simulations, raw files) is [`WorldFrame::Unknown`].

use glam::{DAffine3, DMat3, DVec3};

/// The anatomical meaning of a volume's world axes.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Default, Hash, serde::Serialize, serde::Deserialize,
)]
#[serde(rename_all = "lowercase")]
pub enum WorldFrame {
    /// No patient frame: plain x, y, z.
    #[default]
    Unknown,
    /// +x Right, +y Anterior, +z Superior (NIfTI, 3D Slicer's world).
    Ras,
    /// +x Left, +y Posterior, +z Superior (DICOM, ITK, MetaImage).
    Lps,
}

impl WorldFrame {
    /// `"unknown"`, `"RAS"` or `"LPS"`.
    pub const fn name(self) -> &'static str {
        match self {
            WorldFrame::Unknown => "unknown",
            WorldFrame::Ras => "RAS",
            WorldFrame::Lps => "LPS",
        }
    }

    pub fn is_known(self) -> bool {
        self != WorldFrame::Unknown
    }

    /// The anatomical letter a world axis points to (`positive`) or from: `R`/`L`, `A`/`P`,
    /// `S`/`I`; `None` in an unknown frame.
    pub const fn letter(self, axis: usize, positive: bool) -> Option<char> {
        // Letters of +x, +y, +z and of −x, −y, −z.
        let (pos, neg) = match self {
            WorldFrame::Unknown => return None,
            WorldFrame::Ras => (['R', 'A', 'S'], ['L', 'P', 'I']),
            WorldFrame::Lps => (['L', 'P', 'S'], ['R', 'A', 'I']),
        };
        if axis > 2 {
            return None;
        }
        Some(if positive { pos[axis] } else { neg[axis] })
    }

    /// The anatomical letter of the world axis closest to `dir` (ties: the earlier axis), or
    /// `None` for an unknown frame or a zero direction.
    pub fn direction_letter(self, dir: DVec3) -> Option<char> {
        let a = dir.abs();
        // NaN components compare false: no letter.
        if a.max_element().partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
            return None;
        }
        let axis = if a.x >= a.y && a.x >= a.z {
            0
        } else if a.y >= a.z {
            1
        } else {
            2
        };
        self.letter(axis, dir[axis] > 0.0)
    }

    /// The world direction (unit) of an anatomical letter (`R L A P S I`) in this frame.
    pub fn direction_of(self, letter: char) -> Option<DVec3> {
        (0..3).find_map(|axis| {
            [true, false].into_iter().find_map(|positive| {
                (self.letter(axis, positive)? == letter.to_ascii_uppercase()).then(|| {
                    let mut d = DVec3::ZERO;
                    d[axis] = if positive { 1.0 } else { -1.0 };
                    d
                })
            })
        })
    }

    /// Maps this frame's world coordinates to RAS (identity for RAS; x and y negated for
    /// LPS); `None` for an unknown frame.
    pub fn ras_from_world(self) -> Option<DAffine3> {
        match self {
            WorldFrame::Unknown => None,
            WorldFrame::Ras => Some(DAffine3::IDENTITY),
            WorldFrame::Lps => Some(DAffine3::from_mat3(DMat3::from_diagonal(DVec3::new(
                -1.0, -1.0, 1.0,
            )))),
        }
    }
}

impl std::fmt::Display for WorldFrame {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn letters_follow_the_frames() {
        assert_eq!(WorldFrame::Ras.letter(0, true), Some('R'));
        assert_eq!(WorldFrame::Ras.letter(1, false), Some('P'));
        assert_eq!(WorldFrame::Lps.letter(0, true), Some('L'));
        assert_eq!(WorldFrame::Lps.letter(2, false), Some('I'));
        assert_eq!(WorldFrame::Unknown.letter(0, true), None);
        // A DICOM axial row direction (1, 0, 0) points to the patient's left.
        assert_eq!(
            WorldFrame::Lps.direction_letter(DVec3::new(1.0, 0.1, 0.0)),
            Some('L')
        );
        assert_eq!(
            WorldFrame::Ras.direction_letter(DVec3::new(0.2, -0.9, 0.3)),
            Some('P')
        );
        assert_eq!(WorldFrame::Ras.direction_letter(DVec3::ZERO), None);
        for f in [WorldFrame::Ras, WorldFrame::Lps] {
            for l in ['R', 'L', 'A', 'P', 'S', 'I'] {
                assert_eq!(f.direction_letter(f.direction_of(l).unwrap()), Some(l));
            }
        }
    }

    #[test]
    fn lps_and_ras_describe_the_same_point() {
        // The patient's left, 10 mm: LPS (10, 0, 0) and RAS (−10, 0, 0).
        let lps = DVec3::new(10.0, -5.0, 3.0);
        let ras = WorldFrame::Lps
            .ras_from_world()
            .unwrap()
            .transform_point3(lps);
        assert_eq!(ras, DVec3::new(-10.0, 5.0, 3.0));
        assert_eq!(
            WorldFrame::Ras.direction_letter(ras),
            WorldFrame::Lps.direction_letter(lps)
        );
        assert!(WorldFrame::Unknown.ras_from_world().is_none());
    }
}
