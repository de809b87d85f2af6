//! Errors raised when volume-core types are constructed from inconsistent parts.

use thiserror::Error;

/// An inconsistency in the parts a volume is built from.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum VolumeError {
    #[error("dimensions {dims:?} overflow the address space")]
    DimsOverflow { dims: [usize; 3] },
    #[error("dimensions {dims:?} contain a zero")]
    EmptyDims { dims: [usize; 3] },
    #[error("voxel buffer holds {actual} voxels but dimensions {dims:?} need {expected}")]
    LengthMismatch {
        dims: [usize; 3],
        expected: usize,
        actual: usize,
    },
    #[error("byte source of {available} bytes is too short for {needed} bytes at offset {offset}")]
    SourceTooShort {
        offset: usize,
        needed: usize,
        available: usize,
    },
    #[error("byte offset {offset} is not aligned to the {align}-byte voxel type {voxel_type}")]
    Misaligned {
        offset: usize,
        align: usize,
        voxel_type: &'static str,
    },
    #[error("axis {axis}: {reason}")]
    BadAxis { axis: usize, reason: String },
    #[error("world_from_grid is not invertible")]
    SingularTransform,
    #[error("time step {step}: {reason}")]
    BadStep { step: usize, reason: String },
    #[error("time step {step} failed to load: {reason}")]
    StepLoad { step: usize, reason: String },
}
