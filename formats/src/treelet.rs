//! The `.isot` treelet file (thesis seed 004 §7.8.1): an out-of-core volume cut into
//! treelets by [`volume_core::ooc::build_treelets`], stored in 4 KiB pages with a CRC32 per
//! page so that a truncated or corrupted file is an error, never a picture of garbage.
//! The layout is specified in `docs/treelet-format.md`; in short:
//!
//! - header (page-aligned, padded): magic, version, page size, voxel type, dims, treelet
//!   height, the tree's split axes, quantizer, grid geometry, level table, page count, CRC
//!   table offset, and a CRC32 of the header itself;
//! - data pages: each treelet level in turn (coarsest first), starting on a page boundary,
//!   treelets in index order in fixed-size *slots* (`u32` length + the record); several
//!   slots per page when they fit, otherwise slots follow one another across page
//!   boundaries (before version 3, each took whole pages). A treelet's position is
//!   arithmetic on its id (64-bit);
//! - the CRC32 of every data page.
//!
//! [`write_isot`] builds into a temporary file next to the output and renames it when
//! complete (the input is never touched). [`IsotFile`] memory-maps a file, checks the
//! header, its CRC and the file length at open, and each page's CRC when a treelet on it is
//! fetched ([`IsotFile::verify`] checks them all).

use std::io::{BufWriter, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use glam::DAffine3;
use memmap2::Mmap;
use volume_core::ooc::{
    BuildReport, OocError, OocMeta, Quantizer, TreeletLayout, TreeletSink, TreeletStorage,
    build_treelets,
};
use volume_core::volume::{AxisCoords, Grid, ValueMap, WorldFrame};
use volume_core::{RectilinearVolume, Voxel, VoxelType};

use crate::FormatError;
use crate::output::Replace;

/// File magic: "ISOT", then bytes that break text-mode transfers (as PNG does).
pub const MAGIC: [u8; 8] = *b"ISOT\r\n\x1a\n";
/// The version written. Version 3 records the tree's split axes; versions 1 and 2 halve in
/// cells. Version 1 (no world frame, no value map) is read with physical values and an
/// unknown frame.
pub const VERSION: u32 = 3;
pub const PAGE: u64 = 4096;
const FIELD_HEADER: &str = "isot header";

/// Where one treelet level lives in the data pages.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LevelPlan {
    /// First data page (0 = the first page after the header).
    pub first_page: u64,
    pub page_count: u64,
    /// Bytes per slot: `u32` record length + the largest record of the level.
    pub slot_bytes: u64,
    /// Slots per page, or 0 when a slot is larger than a page.
    pub slots_per_page: u64,
    pub treelet_count: u64,
    /// Slots larger than a page follow one another across page boundaries (version 3);
    /// before, each took whole pages. Not stored: it follows from the version.
    pub packed: bool,
}

impl LevelPlan {
    /// Byte offset of slot `index` from the start of the data pages.
    pub fn slot_offset(&self, index: u64) -> u64 {
        match index.checked_div(self.slots_per_page) {
            Some(page) => {
                (self.first_page + page) * PAGE + (index % self.slots_per_page) * self.slot_bytes
            }
            None if self.packed => self.first_page * PAGE + index * self.slot_bytes,
            None => (self.first_page + index * self.slot_bytes.div_ceil(PAGE)) * PAGE,
        }
    }
}

/// The page plan of every level of `meta` in a file of format `version`.
pub fn plan_levels(meta: &OocMeta, version: u32) -> Vec<LevelPlan> {
    let packed = version >= 3;
    let mut page = 0;
    (0..meta.layout.level_count())
        .map(|l| {
            let slot_bytes = 4 + meta.max_record_bytes(l);
            let treelet_count = meta.layout.level(l).treelet_count();
            let slots_per_page = if slot_bytes <= PAGE {
                PAGE / slot_bytes
            } else {
                0
            };
            let page_count = if slots_per_page > 0 {
                treelet_count.div_ceil(slots_per_page)
            } else if packed {
                // A slot just over a page (a CT's anisotropic treelet with its border and
                // node ranges) would otherwise waste nearly half of its second page.
                // Saturating: a header's dims at the limits give sizes past u64, which the
                // file length check then refuses.
                treelet_count.saturating_mul(slot_bytes).div_ceil(PAGE)
            } else {
                treelet_count.saturating_mul(slot_bytes.div_ceil(PAGE))
            };
            let p = LevelPlan {
                first_page: page,
                page_count,
                slot_bytes,
                slots_per_page,
                treelet_count,
                packed,
            };
            page = page.saturating_add(page_count);
            p
        })
        .collect()
}

fn encode_header(meta: &OocMeta, plans: &[LevelPlan], data_pages: u64, crc_offset: u64) -> Vec<u8> {
    let mut h = Vec::new();
    h.extend_from_slice(&MAGIC);
    h.extend_from_slice(&VERSION.to_le_bytes());
    h.extend_from_slice(&(PAGE as u32).to_le_bytes());
    h.extend_from_slice(&0u64.to_le_bytes()); // header length, patched below
    let mut name = [0u8; 8];
    let n = meta.voxel_type.name().as_bytes();
    name[..n.len()].copy_from_slice(n);
    h.extend_from_slice(&name);
    for d in meta.layout.dims() {
        h.extend_from_slice(&d.to_le_bytes());
    }
    h.extend_from_slice(&meta.layout.treelet_height().to_le_bytes());
    // Version 3: the split axis of each inner tree level.
    let axes = meta.layout.split_axes();
    h.push(u8::try_from(axes.len()).expect("at most 96 tree levels"));
    h.extend_from_slice(&axes);
    h.extend_from_slice(&meta.quantizer.bits.to_le_bytes());
    h.extend_from_slice(&meta.quantizer.lo.to_le_bytes());
    h.extend_from_slice(&meta.quantizer.hi.to_le_bytes());
    for axis in meta.grid.axes() {
        match axis {
            AxisCoords::Uniform { origin, spacing } => {
                h.push(0);
                h.extend_from_slice(&origin.to_le_bytes());
                h.extend_from_slice(&spacing.to_le_bytes());
            }
            AxisCoords::Explicit(c) => {
                h.push(1);
                for x in c.iter() {
                    h.extend_from_slice(&x.to_le_bytes());
                }
            }
        }
    }
    match meta.grid.world_from_grid() {
        None => h.push(0),
        Some(w) => {
            h.push(1);
            for x in w.to_cols_array() {
                h.extend_from_slice(&x.to_le_bytes());
            }
        }
    }
    // Version 2: the world frame and the stored → physical value map.
    h.push(match meta.grid.world_frame() {
        WorldFrame::Unknown => 0,
        WorldFrame::Ras => 1,
        WorldFrame::Lps => 2,
    });
    h.extend_from_slice(&meta.value_map.slope.to_le_bytes());
    h.extend_from_slice(&meta.value_map.intercept.to_le_bytes());
    h.extend_from_slice(&(plans.len() as u32).to_le_bytes());
    for p in plans {
        for x in [
            p.first_page,
            p.page_count,
            p.slot_bytes,
            p.slots_per_page,
            p.treelet_count,
        ] {
            h.extend_from_slice(&x.to_le_bytes());
        }
    }
    h.extend_from_slice(&data_pages.to_le_bytes());
    h.extend_from_slice(&crc_offset.to_le_bytes());
    let len = (h.len() + 4) as u64;
    h[16..24].copy_from_slice(&len.to_le_bytes());
    let crc = crc32fast::hash(&h);
    h.extend_from_slice(&crc.to_le_bytes());
    h
}

/// Reads little-endian fields, naming the field on a short read.
struct Cursor<'a> {
    path: &'a Path,
    bytes: &'a [u8],
    at: usize,
}

impl<'a> Cursor<'a> {
    fn take(&mut self, n: usize, field: &str) -> Result<&'a [u8], FormatError> {
        let end = self.at.checked_add(n).filter(|&e| e <= self.bytes.len());
        let Some(end) = end else {
            return Err(bad(
                self.path,
                field,
                &format!("header ends at byte {} before this field", self.bytes.len()),
            ));
        };
        let s = &self.bytes[self.at..end];
        self.at = end;
        Ok(s)
    }
    fn u8(&mut self, f: &str) -> Result<u8, FormatError> {
        Ok(self.take(1, f)?[0])
    }
    fn u32(&mut self, f: &str) -> Result<u32, FormatError> {
        Ok(u32::from_le_bytes(
            self.take(4, f)?.try_into().expect("4 bytes"),
        ))
    }
    fn u64(&mut self, f: &str) -> Result<u64, FormatError> {
        Ok(u64::from_le_bytes(
            self.take(8, f)?.try_into().expect("8 bytes"),
        ))
    }
    fn f64(&mut self, f: &str) -> Result<f64, FormatError> {
        Ok(f64::from_le_bytes(
            self.take(8, f)?.try_into().expect("8 bytes"),
        ))
    }
}

fn bad(path: &Path, field: &str, reason: &str) -> FormatError {
    FormatError::BadValue {
        path: path.to_path_buf(),
        line: 0,
        field: format!("{FIELD_HEADER}: {field}"),
        reason: reason.to_string(),
    }
}

/// The bytes of an `.isot` file: a read-only memory map, or bytes already in memory
/// ([`IsotFile::from_bytes`]).
enum IsotBytes {
    Map(Arc<Mmap>),
    Owned(Vec<u8>),
}

impl std::ops::Deref for IsotBytes {
    type Target = [u8];
    fn deref(&self) -> &[u8] {
        match self {
            IsotBytes::Map(m) => m,
            IsotBytes::Owned(v) => v,
        }
    }
}

/// An open `.isot` file: a [`TreeletStorage`] over a read-only memory map.
pub struct IsotFile {
    path: PathBuf,
    version: u32,
    map: IsotBytes,
    meta: OocMeta,
    plans: Vec<LevelPlan>,
    data_offset: u64,
    data_pages: u64,
    crc_offset: u64,
}

impl std::fmt::Debug for IsotFile {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("IsotFile")
            .field("path", &self.path)
            .field("dims", &self.meta.layout.dims())
            .field("levels", &self.plans.len())
            .finish_non_exhaustive()
    }
}

/// True if `path` starts with the `.isot` magic.
pub fn is_isot(path: &Path) -> bool {
    let mut m = [0u8; 8];
    crate::input::open_regular(path)
        .and_then(|mut f| std::io::Read::read_exact(&mut f, &mut m))
        .is_ok()
        && m == MAGIC
}

fn too_short_for_magic(path: &Path, len: u64) -> FormatError {
    FormatError::TooShort {
        path: path.to_path_buf(),
        offset: 0,
        needed: 24,
        available: len,
    }
}

impl IsotFile {
    /// Opens and checks `path`: magic, version, header CRC, geometry, the level table
    /// against the layout recomputed from dims and height, and the exact file length.
    pub fn open(path: &Path) -> Result<Self, FormatError> {
        let file = crate::input::open_regular(path).map_err(|e| FormatError::io(path, e))?;
        let len = file.metadata().map_err(|e| FormatError::io(path, e))?.len();
        if len < 24 {
            return Err(too_short_for_magic(path, len));
        }
        let map = crate::raw::map_file(path, &file)?;
        Self::check(path, IsotBytes::Map(map))
    }

    /// [`IsotFile::open`] on the file's bytes already in memory (`path` only names it in
    /// errors): the same checks; treelets are then fetched from `bytes`.
    pub fn from_bytes(path: &Path, bytes: Vec<u8>) -> Result<Self, FormatError> {
        if bytes.len() < 24 {
            return Err(too_short_for_magic(path, bytes.len() as u64));
        }
        Self::check(path, IsotBytes::Owned(bytes))
    }

    /// The checks of [`IsotFile::open`] on the whole file's bytes (at least 24).
    fn check(path: &Path, map: IsotBytes) -> Result<Self, FormatError> {
        let bytes: &[u8] = &map;
        let len = bytes.len() as u64;
        if bytes[..8] != MAGIC {
            return Err(FormatError::UnknownFormat {
                path: path.to_path_buf(),
                reason: "not an .isot treelet file (bad magic)".into(),
            });
        }
        let mut c = Cursor { path, bytes, at: 8 };
        let version = c.u32("version")?;
        if !(1..=VERSION).contains(&version) {
            return Err(bad(
                path,
                "version",
                &format!("version {version}, this reader knows 1 to {VERSION}"),
            ));
        }
        let page = c.u32("page size")?;
        if u64::from(page) != PAGE {
            return Err(bad(path, "page size", &format!("{page}, expected {PAGE}")));
        }
        let header_len = c.u64("header length")?;
        if header_len > len || header_len < 28 {
            return Err(FormatError::TooShort {
                path: path.to_path_buf(),
                offset: 0,
                needed: header_len,
                available: len,
            });
        }
        let header = &bytes[..header_len as usize];
        let stored_crc = u32::from_le_bytes(header[header.len() - 4..].try_into().expect("4"));
        if crc32fast::hash(&header[..header.len() - 4]) != stored_crc {
            return Err(FormatError::Decode {
                path: path.to_path_buf(),
                encoding: "isot",
                offset: 0,
                reason: "header checksum mismatch: the file is corrupted".into(),
            });
        }
        let mut c = Cursor {
            path,
            bytes: &header[..header.len() - 4],
            at: 24,
        };
        let name = c.take(8, "voxel type")?;
        let name = std::str::from_utf8(name)
            .ok()
            .map(|s| s.trim_end_matches('\0'))
            .and_then(VoxelType::from_name)
            .ok_or_else(|| bad(path, "voxel type", &format!("unknown type {name:?}")))?;
        let dims = [c.u64("dims")?, c.u64("dims")?, c.u64("dims")?];
        let height = c.u32("treelet height")?;
        let layout = if version >= 3 {
            let n = c.u8("split axis count")?;
            let axes = c.take(usize::from(n), "split axes")?;
            TreeletLayout::with_axes(dims, height, axes)
                .map_err(|e| bad(path, "dims/height/split axes", &e.to_string()))?
        } else {
            TreeletLayout::new(dims, height)
                .map_err(|e| bad(path, "dims/height", &e.to_string()))?
        };
        let bits = c.u32("quantizer bits")?;
        let lo = c.f64("quantizer lo")?;
        let hi = c.f64("quantizer hi")?;
        let quantizer = Quantizer::for_type(name, lo, hi);
        if quantizer.bits != bits || quantizer.lo != lo || quantizer.hi != hi {
            return Err(bad(
                path,
                "quantizer",
                &format!(
                    "{bits} bits over [{lo}, {hi}] is not valid for {}",
                    name.name()
                ),
            ));
        }
        let mut axes = Vec::new();
        for &n_samples in &dims {
            match c.u8("axis kind")? {
                0 => axes.push(AxisCoords::Uniform {
                    origin: c.f64("axis origin")?,
                    spacing: c.f64("axis spacing")?,
                }),
                1 => {
                    // The header length was checked against the file: dims are bounded.
                    let n = n_samples as usize;
                    if n.saturating_mul(8) > header.len() {
                        return Err(bad(
                            path,
                            "axis coordinates",
                            "more coordinates than header bytes",
                        ));
                    }
                    let mut v = Vec::with_capacity(n);
                    for _ in 0..n {
                        v.push(c.f64("axis coordinates")?);
                    }
                    axes.push(AxisCoords::Explicit(v.into()));
                }
                k => return Err(bad(path, "axis kind", &format!("unknown kind {k}"))),
            }
        }
        let world_from_grid = match c.u8("orientation flag")? {
            0 => None,
            1 => {
                let mut m = [0.0; 12];
                for x in &mut m {
                    *x = c.f64("orientation")?;
                }
                Some(DAffine3::from_cols_array(&m))
            }
            k => return Err(bad(path, "orientation flag", &format!("{k}"))),
        };
        let (frame, value_map) = if version >= 2 {
            let frame = match c.u8("world frame")? {
                0 => WorldFrame::Unknown,
                1 => WorldFrame::Ras,
                2 => WorldFrame::Lps,
                k => return Err(bad(path, "world frame", &format!("unknown frame {k}"))),
            };
            let slope = c.f64("value map")?;
            let intercept = c.f64("value map")?;
            let map = ValueMap::new(slope, intercept)
                .map_err(|e| bad(path, "value map", &e.to_string()))?;
            (frame, map)
        } else {
            (WorldFrame::Unknown, ValueMap::IDENTITY)
        };
        let axes: [AxisCoords; 3] = axes.try_into().expect("three axes");
        let grid = Grid::new(dims.map(|d| d as usize), axes, world_from_grid)
            .map_err(|e| FormatError::geometry(path, e))?
            .with_world_frame(frame);
        let meta = OocMeta {
            grid,
            voxel_type: name,
            layout,
            quantizer,
            value_map,
        };
        let plans = plan_levels(&meta, version);
        let n = c.u32("level count")? as usize;
        if n != plans.len() {
            return Err(bad(
                path,
                "level count",
                &format!("{n}, the layout has {}", plans.len()),
            ));
        }
        for (l, p) in plans.iter().enumerate() {
            let stored = LevelPlan {
                first_page: c.u64("level table")?,
                page_count: c.u64("level table")?,
                slot_bytes: c.u64("level table")?,
                slots_per_page: c.u64("level table")?,
                treelet_count: c.u64("level table")?,
                packed: p.packed,
            };
            if stored != *p {
                return Err(bad(
                    path,
                    "level table",
                    &format!("level {l}: {stored:?}, the layout gives {p:?}"),
                ));
            }
        }
        let data_pages = c.u64("data pages")?;
        let crc_offset = c.u64("checksum table offset")?;
        let data_offset = header_len.next_multiple_of(PAGE);
        // Checked: dims near the limits give page counts whose byte sizes overflow u64.
        let expected_pages = plans
            .last()
            .map_or(Some(0), |p| p.first_page.checked_add(p.page_count));
        let expected_crc = data_pages
            .checked_mul(PAGE)
            .and_then(|b| b.checked_add(data_offset));
        let total = data_pages
            .checked_mul(4)
            .and_then(|b| b.checked_add(crc_offset));
        let (Some(total), true) = (
            total,
            Some(data_pages) == expected_pages && Some(crc_offset) == expected_crc,
        ) else {
            return Err(bad(
                path,
                "data pages",
                "page count or checksum table offset disagrees with the level table",
            ));
        };
        if len < total {
            return Err(FormatError::TooShort {
                path: path.to_path_buf(),
                offset: 0,
                needed: total,
                available: len,
            });
        }
        if len > total {
            return Err(FormatError::TooLong {
                path: path.to_path_buf(),
                offset: total,
                expected: total,
            });
        }
        Ok(Self {
            path: path.to_path_buf(),
            version,
            map,
            meta,
            plans,
            data_offset,
            data_pages,
            crc_offset,
        })
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The format version the file was written in ([`VERSION`] or older).
    pub fn version(&self) -> u32 {
        self.version
    }

    pub fn plans(&self) -> &[LevelPlan] {
        &self.plans
    }

    fn check_page(&self, page: u64) -> Result<(), String> {
        let start = (self.data_offset + page * PAGE) as usize;
        let data = &self.map[start..start + PAGE as usize];
        let at = (self.crc_offset + page * 4) as usize;
        let stored = u32::from_le_bytes(self.map[at..at + 4].try_into().expect("4"));
        if crc32fast::hash(data) == stored {
            Ok(())
        } else {
            Err(format!(
                "{}: data page {page} (byte offset {start}) checksum mismatch: the file is corrupted",
                self.path.display()
            ))
        }
    }

    /// Checks the CRC of every data page.
    pub fn verify(&self) -> Result<(), FormatError> {
        for p in 0..self.data_pages {
            self.check_page(p).map_err(|reason| FormatError::Decode {
                path: self.path.clone(),
                encoding: "isot",
                offset: self.data_offset + p * PAGE,
                reason,
            })?;
        }
        Ok(())
    }
}

impl TreeletStorage for IsotFile {
    fn meta(&self) -> &OocMeta {
        &self.meta
    }

    fn fetch(&self, level: usize, index: u64) -> Result<Vec<u8>, OocError> {
        let p = self
            .plans
            .get(level)
            .filter(|p| index < p.treelet_count)
            .ok_or_else(|| {
                OocError::Storage(format!(
                    "{}: no treelet ({level}, {index})",
                    self.path.display()
                ))
            })?;
        let off = p.slot_offset(index);
        let first = off / PAGE;
        let last = (off + p.slot_bytes - 1) / PAGE;
        for page in first..=last.min(self.data_pages - 1) {
            self.check_page(page).map_err(OocError::Storage)?;
        }
        let at = (self.data_offset + off) as usize;
        let len = u64::from(u32::from_le_bytes(
            self.map[at..at + 4].try_into().expect("4"),
        ));
        if len + 4 > p.slot_bytes {
            return Err(OocError::Storage(format!(
                "{}: treelet ({level}, {index}) claims {len} bytes in a {}-byte slot",
                self.path.display(),
                p.slot_bytes
            )));
        }
        Ok(self.map[at + 4..at + 4 + len as usize].to_vec())
    }
}

/// The sink that writes pages sequentially per level, with their CRCs.
struct PageWriter {
    file: BufWriter<crate::output::OutputFile>,
    data_offset: u64,
    plans: Vec<LevelPlan>,
    crcs: Vec<u32>,
    level: Option<usize>,
    next_index: u64,
    page: u64,
    buf: Vec<u8>,
    io_error: Option<std::io::Error>,
    meta: Option<OocMeta>,
    /// The volume's value map, recorded in the header (the build works in stored values).
    value_map: ValueMap,
}

impl PageWriter {
    fn io<T>(&mut self, r: std::io::Result<T>) -> Result<T, OocError> {
        r.map_err(|e| {
            let msg = e.to_string();
            self.io_error = Some(e);
            OocError::Storage(msg)
        })
    }

    fn flush_page(&mut self) -> Result<(), OocError> {
        self.buf.resize(PAGE as usize, 0);
        self.crcs[self.page as usize] = crc32fast::hash(&self.buf);
        let r = self.file.write_all(&self.buf);
        self.io(r)?;
        self.buf.clear();
        self.page += 1;
        Ok(())
    }

    fn end_level(&mut self) -> Result<(), OocError> {
        if let Some(l) = self.level.take() {
            if !self.buf.is_empty() {
                self.flush_page()?;
            }
            let p = self.plans[l];
            if self.next_index != p.treelet_count || self.page != p.first_page + p.page_count {
                return Err(OocError::Storage(format!("level {l} incomplete")));
            }
        }
        Ok(())
    }
}

impl TreeletSink for PageWriter {
    fn begin(&mut self, meta: &OocMeta) -> Result<(), OocError> {
        let mut meta = meta.clone();
        meta.value_map = self.value_map;
        self.plans = plan_levels(&meta, VERSION);
        let pages = self.plans.last().map_or(0, |p| p.first_page + p.page_count);
        self.crcs = vec![0; pages as usize];
        let header = encode_header(&meta, &self.plans, pages, 0);
        self.data_offset = (header.len() as u64).next_multiple_of(PAGE);
        self.meta = Some(meta);
        Ok(())
    }

    fn put(&mut self, level: usize, index: u64, bytes: &[u8]) -> Result<(), OocError> {
        if self.level != Some(level) {
            self.end_level()?;
            let p = *self
                .plans
                .get(level)
                .ok_or_else(|| OocError::Storage("bad level".into()))?;
            let pos = self.data_offset + p.first_page * PAGE;
            let r = self.file.seek(SeekFrom::Start(pos));
            self.io(r)?;
            self.level = Some(level);
            self.next_index = 0;
            self.page = p.first_page;
        }
        let p = self.plans[level];
        if index != self.next_index || bytes.len() as u64 + 4 > p.slot_bytes {
            return Err(OocError::Storage(format!(
                "treelet ({level}, {index}) out of order or larger than its slot"
            )));
        }
        if p.slots_per_page > 0 {
            let in_page = index % p.slots_per_page;
            if in_page == 0 && !self.buf.is_empty() {
                self.flush_page()?;
            }
            self.buf.resize((in_page * p.slot_bytes) as usize, 0);
        }
        let start = self.buf.len() as u64;
        self.buf
            .extend_from_slice(&(bytes.len() as u32).to_le_bytes());
        self.buf.extend_from_slice(bytes);
        if p.slots_per_page == 0 {
            // Packed: the slot ends where the next begins; else on a page boundary (the
            // buffer then starts each slot on one).
            let end = if p.packed {
                start + p.slot_bytes
            } else {
                p.slot_bytes.div_ceil(PAGE) * PAGE
            };
            self.buf.resize(end as usize, 0);
        }
        while self.buf.len() >= PAGE as usize {
            let rest = self.buf.split_off(PAGE as usize);
            self.flush_page()?;
            self.buf = rest;
        }
        self.next_index += 1;
        Ok(())
    }
}

/// Builds the treelets of `voxels` on `grid` and writes them to `path` through
/// [`crate::output::OutputFile`] (a temporary file renamed when complete; never over an
/// input; an existing file only with [`Replace::Allow`]). `progress(done, total)` counts
/// treelets.
pub fn write_isot<T: Voxel>(
    path: &Path,
    grid: &Grid,
    voxels: &[T],
    layout: TreeletLayout,
    replace: Replace,
    progress: &mut dyn FnMut(u64, u64),
) -> Result<BuildReport, FormatError> {
    write_isot_mapped(
        path,
        grid,
        voxels,
        ValueMap::IDENTITY,
        layout,
        replace,
        progress,
    )
}

/// [`write_isot`] of stored `voxels` whose physical values are `value_map` of them (recorded
/// in the header; the out-of-core scene maps isovalues with it).
fn write_isot_mapped<T: Voxel>(
    path: &Path,
    grid: &Grid,
    voxels: &[T],
    value_map: ValueMap,
    layout: TreeletLayout,
    replace: Replace,
    progress: &mut dyn FnMut(u64, u64),
) -> Result<BuildReport, FormatError> {
    let out = crate::output::OutputFile::create(path, replace)?;
    let mut w = PageWriter {
        file: BufWriter::with_capacity(1 << 20, out),
        data_offset: 0,
        plans: Vec::new(),
        crcs: Vec::new(),
        level: None,
        next_index: 0,
        page: 0,
        buf: Vec::with_capacity(2 * PAGE as usize),
        io_error: None,
        meta: None,
        value_map,
    };
    let built = build_treelets(grid, voxels, layout, &mut w, progress).and_then(|r| {
        w.end_level()?;
        Ok(r)
    });
    let report = match built {
        Ok(r) => r,
        Err(e) => {
            return Err(match w.io_error.take() {
                Some(io) => FormatError::io(path, io),
                None => FormatError::UnknownFormat {
                    path: path.to_path_buf(),
                    reason: format!("treelet build failed: {e}"),
                },
            });
        }
    };
    let meta = w.meta.clone().expect("begin was called");
    let pages = w.crcs.len() as u64;
    let crc_offset = w.data_offset + pages * PAGE;
    let header = encode_header(&meta, &w.plans, pages, crc_offset);
    let mut table = Vec::with_capacity(w.crcs.len() * 4);
    for c in &w.crcs {
        table.extend_from_slice(&c.to_le_bytes());
    }
    let finish = (|| -> std::io::Result<()> {
        w.file.seek(SeekFrom::Start(crc_offset))?;
        w.file.write_all(&table)?;
        w.file.seek(SeekFrom::Start(0))?;
        w.file.write_all(&header)?;
        w.file.flush()?;
        w.file
            .get_ref()
            .file()
            .set_len(crc_offset + table.len() as u64)
    })();
    finish.map_err(|e| FormatError::io(path, e))?;
    let out = w
        .file
        .into_inner()
        .map_err(|e| FormatError::io(path, e.into_error()))?;
    out.commit()?;
    Ok(report)
}

/// [`write_isot`] for a volume of any voxel type; its value map (and world frame) go into
/// the header.
pub fn write_isot_volume(
    path: &Path,
    volume: &RectilinearVolume,
    layout: TreeletLayout,
    replace: Replace,
    progress: &mut dyn FnMut(u64, u64),
) -> Result<BuildReport, FormatError> {
    let g = &volume.grid;
    let map = volume.value_map;
    volume_core::dispatch_voxels!(&volume.data, b => write_isot_mapped(path, g, b.as_slice(), map, layout, replace, progress))
}

/// Opens `path` as an out-of-core volume: the loader thread starts with the top treelet.
pub fn open_isot(
    path: &Path,
    options: volume_core::ooc::OocOptions,
) -> Result<volume_core::ooc::AnyOocVolume, FormatError> {
    let file = Arc::new(IsotFile::open(path)?);
    volume_core::ooc::AnyOocVolume::open(file, options).map_err(|e| FormatError::Decode {
        path: path.to_path_buf(),
        encoding: "isot",
        offset: 0,
        reason: e.to_string(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use volume_core::ooc::{MemoryStorage, TreeletRecord};

    fn volume(dims: [usize; 3]) -> (Grid, Vec<u16>) {
        let grid = Grid::uniform(dims, [1.0, -2.0, 0.5], [0.5, 1.0, 2.0]).unwrap();
        let mut v = Vec::new();
        for k in 0..dims[2] {
            for j in 0..dims[1] {
                for i in 0..dims[0] {
                    v.push(((i * 7 + j * 13 + k * 29) % 1000) as u16 + 100);
                }
            }
        }
        (grid, v)
    }

    fn write(dir: &Path, h: u32) -> (PathBuf, MemoryStorage) {
        let dims = [37, 21, 15];
        let (grid, v) = volume(dims);
        let layout = TreeletLayout::new(dims.map(|d| d as u64), h).unwrap();
        let path = dir.join(format!("v{h}.isot"));
        let report = write_isot(
            &path,
            &grid,
            &v,
            layout.clone(),
            Replace::Refuse,
            &mut |_, _| {},
        )
        .unwrap();
        assert_eq!(report.treelets, layout.treelet_count());
        let mut mem = MemoryStorage::new();
        build_treelets(&grid, &v, layout, &mut mem, &mut |_, _| {}).unwrap();
        (path, mem)
    }

    #[test]
    fn round_trip_equals_the_in_memory_build() {
        let dir = tempfile::tempdir().unwrap();
        for h in [3, 9] {
            let (path, mem) = write(dir.path(), h);
            assert!(is_isot(&path));
            let f = IsotFile::open(&path).unwrap();
            f.verify().unwrap();
            assert_eq!(f.meta(), mem.meta());
            let len = std::fs::metadata(&path).unwrap().len();
            assert_eq!(len, f.crc_offset + 4 * f.data_pages);
            let mut slots_shared = false;
            for (l, p) in f.plans().iter().enumerate() {
                assert_eq!(p.first_page * PAGE % PAGE, 0);
                slots_shared |= p.slots_per_page > 1;
                for i in 0..p.treelet_count {
                    let a = f.fetch(l, i).unwrap();
                    assert_eq!(a, mem.fetch(l, i).unwrap(), "level {l} treelet {i}");
                    TreeletRecord::<u16>::decode(f.meta(), l, i, &a).unwrap();
                }
            }
            assert!(h == 9 || slots_shared, "small treelets share pages");
            // No temporary files left behind: one finished file per height so far.
            let names: Vec<_> = std::fs::read_dir(dir.path()).unwrap().collect();
            assert_eq!(names.len(), if h == 3 { 1 } else { 2 });
        }
    }

    #[test]
    fn truncated_and_corrupted_files_are_rejected() {
        let dir = tempfile::tempdir().unwrap();
        let (path, _) = write(dir.path(), 3);
        let bytes = std::fs::read(&path).unwrap();
        // Truncated anywhere: open fails with a clear error.
        for cut in [0, 10, 100, bytes.len() / 2, bytes.len() - 1] {
            let p = dir.path().join("cut.isot");
            std::fs::write(&p, &bytes[..cut]).unwrap();
            let e = IsotFile::open(&p).unwrap_err();
            let s = e.to_string();
            assert!(s.contains("cut.isot"), "{s}");
            assert!(
                s.contains("bytes") || s.contains("header") || s.contains("magic"),
                "{s}"
            );
        }
        // A flipped byte in the header: header checksum.
        let p = dir.path().join("flip.isot");
        let mut b = bytes.clone();
        b[60] ^= 0x10;
        std::fs::write(&p, &b).unwrap();
        let e = IsotFile::open(&p).unwrap_err().to_string();
        assert!(e.contains("checksum") || e.contains("header"), "{e}");
        // A flipped byte in every data page, one at a time (sampled): verify and the
        // fetch of a treelet on that page both fail.
        let f = IsotFile::open(&path).unwrap();
        let (data_offset, pages) = (f.data_offset, f.data_pages);
        drop(f);
        for page in (0..pages).step_by((pages as usize / 7).max(1)) {
            let mut b = bytes.clone();
            let at = (data_offset + page * PAGE + 123) as usize;
            b[at] ^= 0x01;
            std::fs::write(&p, &b).unwrap();
            let f = IsotFile::open(&p).unwrap();
            let e = f.verify().unwrap_err().to_string();
            assert!(
                e.contains("checksum mismatch") && e.contains("flip.isot"),
                "{e}"
            );
            let mut failed = 0;
            for (l, plan) in f.plans().iter().enumerate() {
                for i in 0..plan.treelet_count {
                    if let Err(e) = f.fetch(l, i) {
                        assert!(e.to_string().contains(&format!("page {page}")), "{e}");
                        failed += 1;
                    }
                }
            }
            assert!(failed > 0, "page {page}");
        }
        // Extra bytes at the end are rejected too.
        let mut b = bytes.clone();
        b.push(0);
        std::fs::write(&p, &b).unwrap();
        assert!(IsotFile::open(&p).is_err());
        // Not an isot file.
        std::fs::write(&p, b"NRRD0004\n and some more bytes to pass").unwrap();
        assert!(!is_isot(&p));
        assert!(
            IsotFile::open(&p)
                .unwrap_err()
                .to_string()
                .contains("magic")
        );
    }

    #[test]
    fn explicit_axes_and_orientation_survive() {
        let dims = [5usize, 4, 3];
        let axes = [
            AxisCoords::Explicit(vec![0.0, 1.0, 3.0, 3.5, 9.0].into()),
            AxisCoords::Uniform {
                origin: 2.0,
                spacing: 0.25,
            },
            AxisCoords::Explicit(vec![-1.0, 0.0, 4.0].into()),
        ];
        let w = DAffine3::from_cols_array(&[
            0.0, 1.0, 0.0, -1.0, 0.0, 0.0, 0.0, 0.0, 2.0, 5.0, 6.0, 7.0,
        ]);
        let grid = Grid::new(dims, axes, Some(w)).unwrap();
        let v: Vec<f32> = (0..60).map(|i| i as f32 * 0.5 - 3.0).collect();
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("e.isot");
        let layout = TreeletLayout::new([5, 4, 3], 2).unwrap();
        write_isot(&path, &grid, &v, layout, Replace::Refuse, &mut |_, _| {}).unwrap();
        let f = IsotFile::open(&path).unwrap();
        assert_eq!(f.meta().grid, grid);
        assert_eq!(f.meta().voxel_type, VoxelType::F32);
    }

    #[test]
    fn value_map_and_world_frame_survive_and_version_1_reads_as_identity() {
        let dir = tempfile::tempdir().unwrap();
        let grid = Grid::uniform([6, 5, 4], [1.0, 2.0, 3.0], [0.5, 1.0, 2.0])
            .unwrap()
            .with_world_frame(WorldFrame::Lps);
        let stored: Vec<i16> = (0..120).map(|i| i * 9 - 400).collect();
        let map = ValueMap::new(0.5, -1024.0).unwrap();
        let v = RectilinearVolume::new(grid.clone(), stored.into())
            .unwrap()
            .with_value_map(map);
        let path = dir.path().join("s.isot");
        let layout = TreeletLayout::new([6, 5, 4], 2).unwrap();
        write_isot_volume(&path, &v, layout, Replace::Refuse, &mut |_, _| {}).unwrap();
        let f = IsotFile::open(&path).unwrap();
        f.verify().unwrap();
        assert_eq!(f.meta().value_map, map);
        assert_eq!(f.meta().grid, grid);
        // The quantizer stays over the stored values.
        assert_eq!(
            (f.meta().quantizer.lo, f.meta().quantizer.hi),
            (-400.0, 119.0 * 9.0 - 400.0)
        );
        // A version-1 file (an `isoscope preprocess` output of before the value map, kept as
        // a fuzz seed behind its selector byte) still opens: identity map, unknown frame.
        let seed = Path::new(env!("CARGO_MANIFEST_DIR")).join("fuzz/seeds/isot/ok_i16_h1");
        let bytes = std::fs::read(&seed).unwrap()[1..].to_vec();
        assert_eq!(u32::from_le_bytes(bytes[8..12].try_into().unwrap()), 1);
        let old = IsotFile::from_bytes(&seed, bytes).unwrap();
        old.verify().unwrap();
        assert!(old.meta().value_map.is_identity());
        assert_eq!(old.meta().grid.world_frame(), WorldFrame::Unknown);
    }

    /// File -> loader -> OocScene at the finest level equals the in-core GridScene.
    /// Hits of the `.isot` at `path`, all levels loaded, against the in-core scene of
    /// `volume`, for a grid of parallel rays from below `z` (returns the hit count).
    fn assert_file_hits_as_in_core(path: &Path, volume: &RectilinearVolume, iso: f32) -> usize {
        use volume_core::grid::AnyGridScene;
        use volume_core::intersect::Intersector;
        use volume_core::math::Ray;
        use volume_core::render::{Hit, IsoScene, NoStats};
        use volume_core::render::{Normals, SceneVisitor};

        struct Trace(Vec<Ray>, [f32; 1]);
        impl SceneVisitor for Trace {
            type Output = Vec<Option<Hit>>;
            fn visit<S: IsoScene>(self, scene: &S) -> Self::Output {
                self.0
                    .iter()
                    .map(|r| scene.first_hit(r, 0.0, f32::INFINITY, &self.1, &mut NoStats))
                    .collect()
            }
        }
        let ooc = open_isot(path, volume_core::ooc::OocOptions::default()).unwrap();
        let iso = [iso];
        ooc.set_isovalues(&iso);
        assert!(ooc.wait_until_finished(std::time::Duration::from_mins(1)));
        assert_eq!(ooc.error(), None);
        assert_eq!(ooc.loaded_levels(), ooc.level_count());
        let incore = AnyGridScene::new(volume, Intersector::Exact);
        // Aimed at a 40 × 40 lattice over the mid-z plane, a little wider than the box.
        let (lo, hi) = volume.grid.grid_bounds();
        let (lo, hi) = (lo.as_vec3(), hi.as_vec3());
        let dir = glam::Vec3::new(0.3, 0.2, 1.0).normalize();
        let mut rays = Vec::new();
        for j in 0..40 {
            for i in 0..40 {
                let u = glam::Vec3::new(
                    i as f32 / 39.0 * 1.2 - 0.1,
                    j as f32 / 39.0 * 1.2 - 0.1,
                    0.5,
                );
                let target = lo + (hi - lo) * u;
                rays.push(Ray::new(target - dir * 2.0 * (hi - lo).length(), dir));
            }
        }
        let a = incore.visit(Trace(rays.clone(), iso));
        let b = ooc.visit_scene(Intersector::Exact, Normals::Smooth, Trace(rays, iso));
        assert_eq!(a, b);
        a.iter().filter(|h| h.is_some()).count()
    }

    #[test]
    fn rendering_from_the_file_equals_in_core() {
        let dims = [37usize, 21, 15];
        let (grid, v) = volume(dims);
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("r.isot");
        let layout = TreeletLayout::new(dims.map(|d| d as u64), 4).unwrap();
        write_isot(&path, &grid, &v, layout, Replace::Refuse, &mut |_, _| {}).unwrap();
        let volume = RectilinearVolume::new(grid, v.into()).unwrap();
        assert!(assert_file_hits_as_in_core(&path, &volume, 612.5) > 100);
    }

    /// A version-3 file records the world-space split of an anisotropic grid (0.6 × 0.6 × 4
    /// mm cells); a version-2 file of the same volume, written by `isoscope preprocess`
    /// before the axes were recorded, still opens with its tree halved in cells. Both render
    /// the in-core hits.
    #[test]
    fn split_axes_are_recorded_and_version_2_halves_in_cells() {
        let data = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/isot");
        let opened = crate::open(&data.join("aniso.nrrd"), &crate::OpenOptions::default());
        let volume = opened.unwrap().first_volume().clone();
        let dims = volume.grid.dims().map(|d| d as u64);
        let world = |h| TreeletLayout::for_grid(&volume.grid, h).unwrap();
        let index = |h| TreeletLayout::new(dims, h).unwrap();
        assert_ne!(world(6).split_axes(), index(6).split_axes());

        let old = data.join("aniso_v2.isot");
        let bytes = std::fs::read(&old).unwrap();
        assert_eq!(u32::from_le_bytes(bytes[8..12].try_into().unwrap()), 2);
        let f = IsotFile::open(&old).unwrap();
        f.verify().unwrap();
        assert_eq!(f.meta().layout, index(6));
        assert_eq!(f.meta().grid, volume.grid);
        assert!(assert_file_hits_as_in_core(&old, &volume, 400.0) > 100);

        let dir = tempfile::tempdir().unwrap();
        let new = dir.path().join("w.isot");
        write_isot_volume(&new, &volume, world(3), Replace::Refuse, &mut |_, _| {}).unwrap();
        let bytes = std::fs::read(&new).unwrap();
        assert_eq!(u32::from_le_bytes(bytes[8..12].try_into().unwrap()), 3);
        let f = IsotFile::open(&new).unwrap();
        f.verify().unwrap();
        assert_eq!(f.meta().layout, world(3));
        assert!(assert_file_hits_as_in_core(&new, &volume, 400.0) > 100);
    }

    /// Version 3 packs slots larger than a page back to back across page boundaries; every
    /// treelet still reads back whole and checked (a CT-like `i16` grid of 0.6 × 0.6 × 4 mm
    /// cells, whose world-space treelets of height 9 take more than a page).
    #[test]
    fn slots_larger_than_a_page_are_packed() {
        let dims = [40usize, 36, 12];
        let grid = Grid::uniform(dims, [0.0; 3], [0.6, 0.6, 4.0]).unwrap();
        let mut v = Vec::new();
        for k in 0..dims[2] {
            for j in 0..dims[1] {
                for i in 0..dims[0] {
                    let d = ((i as f64 - 17.0).powi(2) + (j as f64 - 15.0).powi(2)).sqrt();
                    v.push((1000.0 - 60.0 * d + 40.0 * k as f64) as i16);
                }
            }
        }
        let volume = RectilinearVolume::new(grid, v.into()).unwrap();
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("p.isot");
        let layout = TreeletLayout::for_grid(&volume.grid, 9).unwrap();
        write_isot_volume(&path, &volume, layout, Replace::Refuse, &mut |_, _| {}).unwrap();
        let f = IsotFile::open(&path).unwrap();
        let big = f.plans().iter().filter(|p| p.slots_per_page == 0).count();
        assert!(big > 0 && f.plans().iter().all(|p| p.packed));
        // Packed: the level's pages hold its slots with less than a page to spare.
        for p in f.plans().iter().filter(|p| p.slots_per_page == 0) {
            assert_eq!(
                p.page_count,
                (p.treelet_count * p.slot_bytes).div_ceil(PAGE)
            );
            assert!(p.slot_bytes % PAGE != 0);
        }
        f.verify().unwrap();
        assert!(assert_file_hits_as_in_core(&path, &volume, 400.0) > 100);
    }

    /// The finished file has the mode `File::create` gives (0666 minus the umask), not the
    /// 0600 of a temporary file, and no temporary name is left behind.
    #[cfg(unix)]
    #[test]
    fn output_mode_respects_the_umask() {
        use std::os::unix::fs::PermissionsExt as _;
        let dir = tempfile::tempdir().unwrap();
        let (path, _) = write(dir.path(), 3);
        let reference = dir.path().join("reference");
        std::fs::File::create(&reference).unwrap();
        let mode = |p: &Path| std::fs::metadata(p).unwrap().permissions().mode() & 0o777;
        assert_eq!(mode(&path), mode(&reference));
        assert_ne!(
            mode(&path) & 0o044,
            0,
            "readable by others under a usual umask"
        );
        let names: Vec<_> = std::fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name().into_string().unwrap())
            .collect();
        assert!(names.iter().all(|n| !n.starts_with(".isot-")), "{names:?}");
    }

    /// Slot offsets of a 2048×2048×1100 file (beyond 4 GiB) in 64-bit arithmetic, checked
    /// against u128 arithmetic; the plan alone, nothing is written.
    #[test]
    fn slot_offsets_above_four_gib_do_not_wrap() {
        let dims = [2048usize, 2048, 1100];
        let meta = OocMeta {
            grid: Grid::uniform(dims, [0.0; 3], [1.0; 3]).unwrap(),
            voxel_type: VoxelType::U8,
            layout: TreeletLayout::new(dims.map(|d| d as u64), 9).unwrap(),
            quantizer: Quantizer::for_type(VoxelType::U8, 0.0, 255.0),
            value_map: ValueMap::IDENTITY,
        };
        // Both slot rules (version 3 packs slots larger than a page), and a layout split in
        // world space (a CT's 0.6 × 0.6 × 4 mm `i16` cells: slots of more than a page).
        let ct =
            TreeletLayout::for_grid(&Grid::uniform(dims, [0.0; 3], [0.6, 0.6, 4.0]).unwrap(), 9)
                .unwrap();
        let ct_meta = OocMeta {
            layout: ct,
            voxel_type: VoxelType::I16,
            quantizer: Quantizer::for_type(VoxelType::I16, -1024.0, 3071.0),
            ..meta.clone()
        };
        let mut packed_levels = 0;
        for (meta, version) in [(&meta, 2), (&meta, VERSION), (&ct_meta, VERSION)] {
            let plans = plan_levels(meta, version);
            packed_levels += plans
                .iter()
                .filter(|p| p.packed && p.slots_per_page == 0)
                .count();
            check_plans(meta, &plans);
        }
        assert!(packed_levels > 0);
    }

    fn check_plans(meta: &OocMeta, plans: &[LevelPlan]) {
        let last = plans.last().unwrap();
        let end = (last.first_page + last.page_count) * PAGE;
        assert!(end > 1 << 32, "{end}");
        for (l, p) in plans.iter().enumerate() {
            let i = p.treelet_count - 1;
            let page = u128::from(PAGE);
            let want = match u128::from(p.slots_per_page) {
                0 if p.packed => {
                    u128::from(p.first_page) * page + u128::from(i) * u128::from(p.slot_bytes)
                }
                0 => {
                    (u128::from(p.first_page)
                        + u128::from(i) * u128::from(p.slot_bytes.div_ceil(PAGE)))
                        * page
                }
                per => {
                    (u128::from(p.first_page) + u128::from(i) / per) * page
                        + u128::from(i) % per * u128::from(p.slot_bytes)
                }
            };
            assert_eq!(u128::from(p.slot_offset(i)), want, "level {l}");
            assert!(p.slot_offset(i) + p.slot_bytes <= (p.first_page + p.page_count) * PAGE);
            // The largest record fits its slot.
            assert!(meta.max_record_bytes(l) + 4 <= p.slot_bytes);
        }
        assert!(last.slot_offset(last.treelet_count - 1) > 1 << 32);
    }
}
