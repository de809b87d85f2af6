//! Out-of-core volumes: the treelet hierarchy of thesis seed 004 §7.7–7.8.
//!
//! - [`layout`]: the tree geometry (the same slim, virtually padded kd-tree levels as
//!   [`crate::kdtree`], §7.3) cut into *treelet levels* of fixed height (the top-most may be
//!   shorter, §7.8.1), with 64-bit address arithmetic so volumes above 2³² voxels work.
//! - [`quantize`]: node min/max quantized to half the voxel bits with conservative rounding
//!   (§7.8.1): a quantized range always contains the true range.
//! - [`build`]: the LOD pyramid (separable binomial ≈ 3D Gaussian filter, 2× decimation per
//!   step, §7.8.1) and the *merged* min/max tree (a node's range is the union over every
//!   LOD level that can be rendered through it), encoded treelet by treelet into a
//!   [`TreeletSink`].
//! - [`treelet`]: the treelet record (subtree ranges + LOD voxel block with a one-voxel
//!   border for central differences, id, voxel dims), its byte encoding, and the
//!   [`TreeletStorage`] trait the renderer fetches treelets through (in memory here; the
//!   `.isot` file in `formats::treelet`).
//! - [`scene`]: the loader thread, the bit table of resident treelets, a memory budget, and
//!   [`scene::OocScene`], an [`crate::render::IsoScene`] that traverses as deep as the loaded
//!   levels allow and intersects the current level's voxels (Listing 7.3).

pub mod build;
pub mod layout;
pub mod quantize;
pub mod scene;
pub mod treelet;

pub use build::{BuildReport, build_treelets};
pub use layout::{LevelShape, TreeletLayout, TreeletLevel};
pub use quantize::{CodeQuery, Quantizer};
pub use scene::{
    AnyOocVolume, LoadProgress, OocOptions, OocScene, OocVolume, physical_memory_bytes,
};
pub use treelet::{MemoryStorage, OocMeta, TreeletRecord, TreeletSink, TreeletStorage};

use thiserror::Error;

/// Errors of the out-of-core structures.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum OocError {
    #[error("volume dims {dims:?}: {reason}")]
    BadDims { dims: [u64; 3], reason: String },
    #[error("treelet height {0} is out of range 1..=24")]
    BadHeight(u32),
    #[error("voxel buffer holds {actual} voxels but dims {dims:?} need {expected}")]
    LengthMismatch {
        dims: [u64; 3],
        expected: u64,
        actual: u64,
    },
    #[error("treelet (level {level}, index {index}): {reason}")]
    BadTreelet {
        level: usize,
        index: u64,
        reason: String,
    },
    #[error("treelet storage: {0}")]
    Storage(String),
}
