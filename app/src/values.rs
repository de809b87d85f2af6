//! # Printing data values the way their type reads
//!
//! `info`, the CLI's messages and the viewer's panels print values through [`ValueFormat`]:
//! integer data as integers (`-1000`, not `-1000.000000`), `f32` data with the shortest
//! decimal that reads back as the same `f32` (`0.8`, not `0.800000011920929`), and exponent
//! notation where positional digits would run long (`3.6736697e-22`, not 22 zeros).
//! [`ValueFormat::edge`] prints a histogram bin edge with just enough digits to tell
//! neighbouring edges apart.

use volume_core::{ValueMap, VoxelType};

/// How a kind of data reads its values.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ValueFormat {
    /// Whole numbers: integer voxels stored as physical values, or with a whole-number map.
    Integer,
    /// Single-precision values: `f32` voxels and mesh arrays, integer voxels scaled by a
    /// fractional value map (the renderer works in `f32`).
    F32,
    /// `f64` voxels.
    F64,
}

/// Magnitudes printed positionally; outside, exponent notation.
const POSITIONAL: std::ops::Range<f64> = 1e-4..1e7;

impl ValueFormat {
    /// The format of a volume's physical values: its voxel type through its value map.
    pub fn of(voxel_type: VoxelType, value_map: Option<&ValueMap>) -> Self {
        let whole = |x: f64| x.fract() == 0.0;
        match (voxel_type, value_map) {
            (VoxelType::F64, _) => Self::F64,
            (VoxelType::F32, _) => Self::F32,
            (_, None) => Self::Integer,
            (_, Some(m)) if whole(m.slope) && whole(m.intercept) => Self::Integer,
            (_, Some(_)) => Self::F32,
        }
    }

    /// `v` as this kind of data reads it.
    pub fn value(self, v: f64) -> String {
        if !v.is_finite() {
            return v.to_string();
        }
        match self {
            Self::Integer if v.fract() == 0.0 && v.abs() < 1e15 => format!("{}", v as i64),
            Self::F32 => {
                let x = v as f32;
                if x == 0.0 || POSITIONAL.contains(&f64::from(x.abs())) {
                    format!("{x}")
                } else {
                    format!("{x:e}")
                }
            }
            Self::Integer | Self::F64 => {
                if v == 0.0 || POSITIONAL.contains(&v.abs()) {
                    format!("{v}")
                } else {
                    format!("{v:e}")
                }
            }
        }
    }

    /// A histogram bin edge `v` of bins `step` wide: rounded to the digits that tell
    /// neighbouring edges apart (whole numbers for integer data in bins of at least 1).
    pub fn edge(self, v: f64, step: f64) -> String {
        if !v.is_finite() || !step.is_finite() || step <= 0.0 {
            return self.value(v);
        }
        // One digit below the step's leading digit.
        let step_digit = step.log10().floor() as i32 - 1;
        let integer = self == Self::Integer && step >= 1.0;
        let magnitude = v.abs().max(step);
        if POSITIONAL.contains(&magnitude) || integer {
            let decimals = if integer {
                0
            } else {
                (-step_digit).clamp(0, 12) as usize
            };
            format!("{v:.decimals$}")
        } else {
            let lead = magnitude.log10().floor() as i32;
            let precision = (lead - step_digit).clamp(0, 12) as usize;
            format!("{v:.precision$e}")
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn values_read_back_as_their_type() {
        // The shortest f32 decimal parses back to the same f32.
        for x in [
            0.8f32,
            0.052_281_29,
            1.836_681_8,
            3.673_669_7e-22,
            1.0e9,
            -7.5e-5,
        ] {
            let s = ValueFormat::F32.value(f64::from(x));
            assert_eq!(s.parse::<f32>().unwrap(), x, "{s}");
            assert!(s.len() <= 16, "{s} is long");
        }
        let tiny = ValueFormat::F32.value(3.673_669_699_806_524_4e-22);
        assert!(tiny.contains('e'), "{tiny}");
        assert_eq!(ValueFormat::Integer.value(-1000.0), "-1000");
        assert_eq!(ValueFormat::F64.value(0.1 + 0.2), "0.30000000000000004");
        assert_eq!(ValueFormat::F32.value(f64::NAN), "NaN");
    }

    #[test]
    fn types_and_value_maps_choose_the_format() {
        let map = |slope, intercept| ValueMap { slope, intercept };
        assert_eq!(ValueFormat::of(VoxelType::I16, None), ValueFormat::Integer);
        let ct = map(1.0, -1024.0);
        assert_eq!(
            ValueFormat::of(VoxelType::U16, Some(&ct)),
            ValueFormat::Integer
        );
        let pet = map(0.25, 0.0);
        assert_eq!(
            ValueFormat::of(VoxelType::U16, Some(&pet)),
            ValueFormat::F32
        );
        assert_eq!(ValueFormat::of(VoxelType::F64, None), ValueFormat::F64);
    }

    #[test]
    fn bin_edges_tell_neighbours_apart_with_few_digits() {
        for (format, lo, hi) in [
            (ValueFormat::Integer, -1000.0, 1345.0),
            (ValueFormat::F32, 0.052, 1.84),
            (ValueFormat::F32, 0.0, 3.7e-22),
            (ValueFormat::F64, 1e8, 1e8 + 64.0),
        ] {
            let step = (hi - lo) / 64.0;
            let edges: Vec<String> = (0..64)
                .map(|b| format.edge(lo + f64::from(b) * step, step))
                .collect();
            for pair in edges.windows(2) {
                assert_ne!(pair[0], pair[1], "{format:?} {lo}..{hi}");
            }
            for e in &edges {
                assert!(e.len() <= 14, "{e} is long");
                // Each printed edge is within half a step of the true edge.
                let parsed: f64 = e.parse().unwrap();
                let b = edges.iter().position(|x| x == e).unwrap();
                let truth = lo + b as f64 * step;
                assert!((parsed - truth).abs() <= 0.5 * step, "{e} vs {truth}");
            }
        }
        assert_eq!(ValueFormat::Integer.edge(-963.359_375, 36.6), "-963");
    }
}
