//! The treelet record (thesis seed 004 §7.8.1, Fig. 7.8) and the storage it lives in.
//!
//! A treelet holds: its id (level, index), the quantized min/max of its subtree's nodes in
//! heap order (root 0, children of `h` at `2h + 1` / `2h + 2`; virtual nodes hold the empty
//! range), the voxel dims, and its block of LOD voxels (the finest data at the last level)
//! with a one-voxel border for central differences. Encoding, little-endian:
//!
//! | bytes | field |
//! |---|---|
//! | 0..4 | level `u32` |
//! | 4..8 | node levels (height) `u32` |
//! | 8..16 | index `u64` (raster order of the root within its level) |
//! | 16..28 | voxel block origin `[u32; 3]` (LOD samples) |
//! | 28..40 | voxel block dims `[u32; 3]` |
//! | 40.. | node codes: `2^height − 1` slots × [`Quantizer::node_bytes`] |
//! | padded to 8 | voxels, x fastest, native type little-endian |
//!
//! [`TreeletStorage`] is how a renderer fetches treelets by id (the `.isot` file in
//! `formats::treelet`, or [`MemoryStorage`] in tests); [`TreeletSink`] is what a build
//! writes into.

use std::fmt;

use super::OocError;
use super::layout::TreeletLayout;
use super::quantize::Quantizer;
use crate::volume::{Grid, ValueMap};
use crate::voxel::{Voxel, VoxelType};

const HEADER_BYTES: usize = 40;

/// What a renderer needs to know about stored treelets besides the treelets themselves.
#[derive(Debug, Clone, PartialEq)]
pub struct OocMeta {
    pub grid: Grid,
    pub voxel_type: VoxelType,
    pub layout: TreeletLayout,
    /// Over the stored values (treelets hold stored values and their codes).
    pub quantizer: Quantizer,
    /// Stored → physical values: isovalues are physical and mapped once per frame
    /// ([`crate::intersect::IsoSet::mapped`]); the build works in stored values and leaves
    /// this the identity, the file records the volume's map.
    pub value_map: ValueMap,
}

impl OocMeta {
    /// Encoded size of a treelet of level `l` with `voxel_count` voxels.
    pub fn record_bytes(&self, l: usize, voxel_count: u64) -> u64 {
        let nodes = (self.layout.level(l).node_slots() * self.quantizer.node_bytes()) as u64;
        (HEADER_BYTES as u64 + nodes).next_multiple_of(8)
            + voxel_count * self.voxel_type.size_bytes() as u64
    }

    /// The largest encoded treelet of level `l` (the slot size a file reserves).
    pub fn max_record_bytes(&self, l: usize) -> u64 {
        let d = self.layout.level(l).max_block_dims();
        self.record_bytes(l, d[0] * d[1] * d[2])
    }
}

/// Receives the treelets of a build: `begin` once, then `put` for every treelet, level by
/// level from the finest to the coarsest (the merged ranges are computed bottom-up), in
/// index order within a level.
pub trait TreeletSink {
    fn begin(&mut self, meta: &OocMeta) -> Result<(), OocError>;
    fn put(&mut self, level: usize, index: u64, bytes: &[u8]) -> Result<(), OocError>;
}

/// Treelets fetched by id; fetched bytes are verified by the storage (checksums).
pub trait TreeletStorage: Send + Sync {
    fn meta(&self) -> &OocMeta;
    fn fetch(&self, level: usize, index: u64) -> Result<Vec<u8>, OocError>;
}

/// A decoded treelet.
#[derive(Clone, PartialEq)]
pub struct TreeletRecord<T: Voxel> {
    pub level: usize,
    pub index: u64,
    /// Node levels in this treelet.
    pub height: usize,
    pub voxel_origin: [u64; 3],
    pub voxel_dims: [usize; 3],
    /// Packed codes, [`Quantizer::get`] reads slot `h`.
    pub nodes: Box<[u8]>,
    pub voxels: Vec<T>,
}

impl<T: Voxel> fmt::Debug for TreeletRecord<T> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("TreeletRecord")
            .field("level", &self.level)
            .field("index", &self.index)
            .field("voxel_origin", &self.voxel_origin)
            .field("voxel_dims", &self.voxel_dims)
            .finish_non_exhaustive()
    }
}

/// Appends the record header (the first 40 bytes of the encoding in the module docs).
pub(crate) fn put_header(
    out: &mut Vec<u8>,
    level: usize,
    height: usize,
    index: u64,
    voxel_origin: [u64; 3],
    voxel_dims: [u64; 3],
) {
    out.extend_from_slice(&(level as u32).to_le_bytes());
    out.extend_from_slice(&(height as u32).to_le_bytes());
    out.extend_from_slice(&index.to_le_bytes());
    for o in voxel_origin {
        out.extend_from_slice(&(o as u32).to_le_bytes());
    }
    for d in voxel_dims {
        out.extend_from_slice(&(d as u32).to_le_bytes());
    }
}

/// Pads `out` (header and node codes) to the voxel block's 8-byte boundary; returns it.
pub(crate) fn start_voxels(out: &mut Vec<u8>) -> usize {
    out.resize(out.len().next_multiple_of(8), 0);
    out.len()
}

/// Native-endian voxel bytes to the little-endian encoding (nothing on little-endian).
pub(crate) fn voxels_to_le<T: Voxel>(bytes: &mut [u8]) {
    if cfg!(target_endian = "big") {
        for v in bytes.chunks_exact_mut(size_of::<T>()) {
            v.reverse();
        }
    }
}

fn u32_at(b: &[u8], at: usize) -> u32 {
    u32::from_le_bytes([b[at], b[at + 1], b[at + 2], b[at + 3]])
}

impl<T: Voxel> TreeletRecord<T> {
    /// The encoding described in the module docs.
    pub fn encode(&self) -> Vec<u8> {
        let mut out = Vec::with_capacity(
            (HEADER_BYTES + self.nodes.len()).next_multiple_of(8) + self.voxels.len() * 8,
        );
        put_header(
            &mut out,
            self.level,
            self.height,
            self.index,
            self.voxel_origin,
            self.voxel_dims.map(|d| d as u64),
        );
        out.extend_from_slice(&self.nodes);
        let at = start_voxels(&mut out);
        out.extend_from_slice(bytemuck::cast_slice::<T, u8>(&self.voxels));
        voxels_to_le::<T>(&mut out[at..]);
        out
    }

    /// Decodes and validates `bytes` as treelet `(level, index)` of `meta`: every field must
    /// agree with the layout, so a misplaced or damaged record is an error, never garbage.
    pub fn decode(
        meta: &OocMeta,
        level: usize,
        index: u64,
        bytes: &[u8],
    ) -> Result<Self, OocError> {
        let bad = |reason: String| OocError::BadTreelet {
            level,
            index,
            reason,
        };
        if T::TYPE != meta.voxel_type {
            return Err(bad(format!(
                "voxel type {} requested, stored {}",
                T::TYPE.name(),
                meta.voxel_type.name()
            )));
        }
        let layout = &meta.layout;
        if level >= layout.level_count() || index >= layout.level(level).treelet_count() {
            return Err(bad("no such treelet in the layout".into()));
        }
        if bytes.len() < HEADER_BYTES {
            return Err(bad(format!(
                "{} bytes, shorter than the header",
                bytes.len()
            )));
        }
        let lv = layout.level(level);
        let stored_level = u32_at(bytes, 0) as usize;
        let height = u32_at(bytes, 4) as usize;
        let stored_index = u64::from(u32_at(bytes, 8)) | (u64::from(u32_at(bytes, 12)) << 32);
        if stored_level != level || stored_index != index {
            return Err(bad(format!(
                "record says level {stored_level}, index {stored_index}"
            )));
        }
        if height != lv.height() {
            return Err(bad(format!("height {height}, layout says {}", lv.height())));
        }
        let origin = [0, 1, 2].map(|a| u64::from(u32_at(bytes, 16 + 4 * a)));
        let dims = [0, 1, 2].map(|a| u64::from(u32_at(bytes, 28 + 4 * a)));
        let expected = layout.voxel_block(level, layout.root_of(level, index));
        if (origin, dims) != expected {
            return Err(bad(format!(
                "voxel block {origin:?}+{dims:?}, layout says {:?}+{:?}",
                expected.0, expected.1
            )));
        }
        let count = dims[0] * dims[1] * dims[2];
        let need = meta.record_bytes(level, count);
        if bytes.len() as u64 != need {
            return Err(bad(format!("{} bytes, expected {need}", bytes.len())));
        }
        let node_len = lv.node_slots() * meta.quantizer.node_bytes();
        let nodes: Box<[u8]> = bytes[HEADER_BYTES..HEADER_BYTES + node_len].into();
        let start = (HEADER_BYTES + node_len).next_multiple_of(8);
        // `bytes` has no alignment guarantee: copy into a typed buffer.
        let mut voxels = vec![<T as bytemuck::Zeroable>::zeroed(); count as usize];
        let raw: &mut [u8] = bytemuck::cast_slice_mut(&mut voxels);
        raw.copy_from_slice(&bytes[start..]);
        if cfg!(target_endian = "big") {
            for v in raw.chunks_exact_mut(size_of::<T>()) {
                v.reverse();
            }
        }
        Ok(Self {
            level,
            index,
            height,
            voxel_origin: origin,
            voxel_dims: dims.map(|d| d as usize),
            nodes,
            voxels,
        })
    }
}

/// Treelets kept in memory: a [`TreeletSink`] for builds and a [`TreeletStorage`] for tests.
#[derive(Debug, Default)]
pub struct MemoryStorage {
    meta: Option<OocMeta>,
    levels: Vec<Vec<Vec<u8>>>,
    fetches: std::sync::atomic::AtomicU64,
}

impl MemoryStorage {
    pub fn new() -> Self {
        Self::default()
    }

    /// Number of `fetch` calls so far.
    pub fn fetch_count(&self) -> u64 {
        self.fetches.load(std::sync::atomic::Ordering::Relaxed)
    }

    /// Records the map from the stored values to physical ones, as a file's header does
    /// (the build leaves it the identity).
    pub fn set_value_map(&mut self, value_map: ValueMap) {
        if let Some(m) = &mut self.meta {
            m.value_map = value_map;
        }
    }

    /// Mutable access to a stored record (tests corrupt it).
    pub fn record_mut(&mut self, level: usize, index: u64) -> Option<&mut Vec<u8>> {
        self.levels.get_mut(level)?.get_mut(index as usize)
    }
}

impl TreeletSink for MemoryStorage {
    fn begin(&mut self, meta: &OocMeta) -> Result<(), OocError> {
        self.levels = meta
            .layout
            .levels()
            .iter()
            .map(|l| vec![Vec::new(); l.treelet_count() as usize])
            .collect();
        self.meta = Some(meta.clone());
        Ok(())
    }

    fn put(&mut self, level: usize, index: u64, bytes: &[u8]) -> Result<(), OocError> {
        let slot = self
            .levels
            .get_mut(level)
            .and_then(|l| l.get_mut(index as usize))
            .ok_or_else(|| OocError::Storage(format!("no slot for treelet ({level}, {index})")))?;
        *slot = bytes.to_vec();
        Ok(())
    }
}

impl TreeletStorage for MemoryStorage {
    fn meta(&self) -> &OocMeta {
        self.meta
            .as_ref()
            .expect("MemoryStorage used before a build")
    }

    fn fetch(&self, level: usize, index: u64) -> Result<Vec<u8>, OocError> {
        self.fetches
            .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        self.levels
            .get(level)
            .and_then(|l| l.get(index as usize))
            .filter(|b| !b.is_empty())
            .cloned()
            .ok_or_else(|| OocError::Storage(format!("treelet ({level}, {index}) not stored")))
    }
}
