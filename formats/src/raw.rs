//! Raw voxel files of explicit layout, and the byte helpers the other readers share.
//!
//! A raw file says nothing about itself: the layout (dims, voxel type, endianness, header bytes
//! to skip, spacing, origin) comes from the command line (`--dims 256x256x108 --type i16
//! --endian little --spacing 0.957,0.957,1.5 --header-bytes 0`, parsed with [`parse_dims`]
//! and [`parse_spacing`]) or from a JSON sidecar `NAME.json` next to `NAME.raw`:
//!
//! ```json
//! {"dims":[256,256,108],"type":"i16","endian":"little","spacing":[0.957,0.957,1.5],"header_bytes":0,"origin":[0,0,0]}
//! ```
//!
//! The file is memory-mapped. When the data is native-endian and aligned the volume views the
//! map in place (no read, no copy: opening a 4 GB file costs a page-table entry); otherwise
//! the voxels are copied out and byte-swapped in parallel. The file size is compared with the
//! layout before anything is mapped or allocated.

use std::fs::File;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use memmap2::Mmap;
use rayon::prelude::*;
use serde::Deserialize;
use volume_core::volume::ByteSource;
use volume_core::{Grid, RectilinearVolume, Voxel, VoxelData, VoxelType};

use crate::error::FormatError;

/// Byte order of multi-byte voxels in a file.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Endian {
    Little,
    Big,
}

impl Endian {
    /// The byte order of this machine.
    pub const fn native() -> Self {
        if cfg!(target_endian = "big") {
            Endian::Big
        } else {
            Endian::Little
        }
    }

    pub const fn name(self) -> &'static str {
        match self {
            Endian::Little => "little",
            Endian::Big => "big",
        }
    }

    /// Parses `little`/`big` (as on the command line).
    pub fn from_name(name: &str) -> Option<Self> {
        match name {
            "little" => Some(Endian::Little),
            "big" => Some(Endian::Big),
            _ => None,
        }
    }
}

fn zero_origin() -> [f64; 3] {
    [0.0; 3]
}

/// The layout of a raw voxel file. Deserializes from the sidecar JSON (`type` is the short
/// voxel type name, `header_bytes` and `origin` are optional, unknown keys are rejected).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawLayout {
    /// Samples per axis, x fastest.
    pub dims: [usize; 3],
    #[serde(rename = "type")]
    pub voxel_type: VoxelType,
    pub endian: Endian,
    /// Bytes to skip at the start of the file.
    #[serde(default)]
    pub header_bytes: u64,
    /// Sample spacing per axis (world units, e.g. mm).
    pub spacing: [f64; 3],
    /// Position of voxel (0, 0, 0).
    #[serde(default = "zero_origin")]
    pub origin: [f64; 3],
}

impl RawLayout {
    /// Number of data bytes the layout describes (without the header), overflow-checked.
    pub fn data_bytes(&self) -> Option<u64> {
        let count = (self.dims[0] as u64)
            .checked_mul(self.dims[1] as u64)?
            .checked_mul(self.dims[2] as u64)?;
        count.checked_mul(self.voxel_type.size_bytes() as u64)
    }

    /// Reads the JSON sidecar at `path`.
    pub fn from_sidecar(path: &Path) -> Result<Self, FormatError> {
        let text =
            crate::input::read_regular_to_string(path).map_err(|e| FormatError::io(path, e))?;
        Self::from_sidecar_text(path, &text)
    }

    /// Parses the text of the JSON sidecar at `path` (`path` only names it in errors).
    pub fn from_sidecar_text(path: &Path, text: &str) -> Result<Self, FormatError> {
        serde_json::from_str(text).map_err(|e| FormatError::Sidecar {
            path: path.to_path_buf(),
            reason: e.to_string(),
        })
    }
}

/// The sidecar of `raw_path`: `NAME.json` next to `NAME.raw`, else `NAME.raw.json`, if either
/// exists. A sidecar that exists but is not a regular file (a FIFO, a directory) is still
/// returned, so that [`RawLayout::from_sidecar`] refuses it by name instead of the raw file
/// being reported as of unknown type.
pub fn sidecar_path(raw_path: &Path) -> Option<PathBuf> {
    let a = raw_path.with_extension("json");
    if a.exists() {
        return Some(a);
    }
    let mut b = raw_path.as_os_str().to_owned();
    b.push(".json");
    let b = PathBuf::from(b);
    b.exists().then_some(b)
}

/// Parses `256x256x108` (also `256,256,108`).
pub fn parse_dims(s: &str) -> Result<[usize; 3], String> {
    let parts: Vec<&str> = s.split(['x', 'X', ',']).map(str::trim).collect();
    if parts.len() != 3 {
        return Err(format!("dims `{s}`: expected three sizes like 256x256x108"));
    }
    let mut dims = [0usize; 3];
    for (d, p) in dims.iter_mut().zip(&parts) {
        *d = p
            .parse()
            .map_err(|_| format!("dims `{s}`: `{p}` is not a size"))?;
        if *d == 0 {
            return Err(format!("dims `{s}`: sizes must be at least 1"));
        }
    }
    Ok(dims)
}

/// Parses `0.957,0.957,1.5` (one value means isotropic spacing).
pub fn parse_spacing(s: &str) -> Result<[f64; 3], String> {
    let parts: Vec<&str> = s.split([',', 'x']).map(str::trim).collect();
    let values: Vec<f64> = parts
        .iter()
        .map(|p| {
            p.parse::<f64>()
                .map_err(|_| format!("spacing `{s}`: `{p}` is not a number"))
        })
        .collect::<Result<_, _>>()?;
    let spacing = match values.as_slice() {
        [v] => [*v; 3],
        [a, b, c] => [*a, *b, *c],
        _ => return Err(format!("spacing `{s}`: expected one or three numbers")),
    };
    if spacing.iter().any(|v| !(v.is_finite() && *v > 0.0)) {
        return Err(format!("spacing `{s}`: values must be finite and positive"));
    }
    Ok(spacing)
}

/// Reads a raw file of the given layout (memory-mapped; zero-copy when native and aligned).
pub fn read_raw(path: &Path, layout: &RawLayout) -> Result<RectilinearVolume, FormatError> {
    let grid = raw_grid(path, layout)?;
    let file = crate::input::open_regular(path).map_err(|e| FormatError::io(path, e))?;
    let file_len = file.metadata().map_err(|e| FormatError::io(path, e))?.len();
    check_raw_len(path, layout, file_len)?;
    let map = map_file(path, &file)?;
    let data = voxels_from_map(
        path,
        &map,
        layout.header_bytes,
        grid.voxel_count(),
        layout.voxel_type,
        layout.endian,
    )?;
    RectilinearVolume::new(grid, data).map_err(|e| FormatError::geometry(path, e))
}

/// [`read_raw`] on the file's bytes already in memory (`path` only names it in errors): the
/// same checks, the voxels copied out of `bytes`. For fuzzing and for callers that hold the
/// bytes.
pub fn parse_raw(
    path: &Path,
    layout: &RawLayout,
    bytes: &[u8],
) -> Result<RectilinearVolume, FormatError> {
    let grid = raw_grid(path, layout)?;
    check_raw_len(path, layout, bytes.len() as u64)?;
    // The length check made `header_bytes + data bytes == bytes.len()`: both fit usize.
    let data = voxels_from_bytes(
        &bytes[layout.header_bytes as usize..],
        layout.voxel_type,
        layout.endian,
    );
    RectilinearVolume::new(grid, data).map_err(|e| FormatError::geometry(path, e))
}

/// The grid of a raw layout; coordinate overflow names the layout field.
fn raw_grid(path: &Path, layout: &RawLayout) -> Result<Grid, FormatError> {
    Grid::uniform(layout.dims, layout.origin, layout.spacing).map_err(|e| {
        // Coordinates beyond single-precision rendering: name the layout field (sidecar key
        // and command-line flag alike) that put them there. `Grid::new` checks dims and
        // finiteness first, so a `BadAxis` with an overflow here is that case.
        let axes = [0, 1, 2].map(|a| volume_core::AxisCoords::Uniform {
            origin: layout.origin[a],
            spacing: layout.spacing[a],
        });
        match (
            &e,
            volume_core::volume::coordinate_overflow(layout.dims, &axes, None),
        ) {
            (volume_core::VolumeError::BadAxis { axis, reason }, Some((a, _))) if *axis == a => {
                let far = layout.origin[a].is_nan()
                    || layout.origin[a].abs() > volume_core::volume::MAX_WORLD_COORD;
                FormatError::BadValue {
                    path: path.to_path_buf(),
                    line: 0,
                    field: if far { "origin" } else { "spacing" }.into(),
                    reason: format!("axis {a}: {reason}"),
                }
            }
            _ => FormatError::geometry(path, e),
        }
    })
}

/// Checks that a file of `file_len` bytes holds exactly the layout's header and data.
fn check_raw_len(path: &Path, layout: &RawLayout, file_len: u64) -> Result<(), FormatError> {
    let data_bytes = layout.data_bytes().ok_or_else(|| FormatError::BadValue {
        path: path.to_path_buf(),
        line: 0,
        field: "dims".into(),
        reason: format!("{:?} voxels overflow", layout.dims),
    })?;
    let needed = layout.header_bytes.checked_add(data_bytes);
    match needed {
        Some(n) if n == file_len => {}
        Some(n) if n < file_len => {
            return Err(FormatError::TooLong {
                path: path.to_path_buf(),
                offset: n,
                expected: data_bytes,
            });
        }
        _ => {
            return Err(FormatError::TooShort {
                path: path.to_path_buf(),
                offset: layout.header_bytes,
                needed: data_bytes,
                available: file_len,
            });
        }
    }
    Ok(())
}

/// Memory-maps a whole file read-only.
#[allow(unsafe_code)]
pub(crate) fn map_file(path: &Path, file: &File) -> Result<Arc<Mmap>, FormatError> {
    // SAFETY: `Mmap::map` is unsafe because the mapped bytes may change (or vanish, raising
    // SIGBUS on access) if another process modifies or truncates the file while it is mapped;
    // Rust's aliasing rules assume `&[u8]` never changes underneath. We map read-only, never
    // write through the map, and check the file size before mapping. A concurrent writer can
    // still change the voxels seen (a wrong picture, not memory corruption of our own
    // structures) or truncate the file (SIGBUS); that is the documented trade-off of zero-copy
    // opening, as in every mmap-based volume viewer. Users who edit files while they are open
    // should re-open them.
    let map = unsafe { Mmap::map(file) }.map_err(|e| FormatError::io(path, e))?;
    Ok(Arc::new(map))
}

/// Voxels at `offset` in a mapped file: viewed in place when native-endian and aligned,
/// otherwise copied and byte-swapped. The caller has checked that the bytes are there.
pub(crate) fn voxels_from_map(
    path: &Path,
    map: &Arc<Mmap>,
    offset: u64,
    count: usize,
    voxel_type: VoxelType,
    endian: Endian,
) -> Result<VoxelData, FormatError> {
    let size = voxel_type.size_bytes();
    let offset_usize = usize::try_from(offset).map_err(|_| FormatError::TooShort {
        path: path.to_path_buf(),
        offset,
        needed: (count * size) as u64,
        available: map.len() as u64,
    })?;
    let native = size == 1 || endian == Endian::native();
    if native && offset_usize.is_multiple_of(size) {
        let source: Arc<dyn ByteSource> = map.clone();
        return VoxelData::from_shared(voxel_type, source, offset_usize, count)
            .map_err(|e| FormatError::geometry(path, e));
    }
    let end = count
        .checked_mul(size)
        .and_then(|n| n.checked_add(offset_usize))
        .filter(|&e| e <= map.len())
        .ok_or(FormatError::TooShort {
            path: path.to_path_buf(),
            offset,
            needed: (count as u64).saturating_mul(size as u64),
            available: map.len() as u64,
        })?;
    Ok(voxels_from_bytes(
        &map[offset_usize..end],
        voxel_type,
        endian,
    ))
}

/// Copies `bytes` (a whole number of voxels) into owned voxels, byte-swapping if `endian` is
/// not native.
pub(crate) fn voxels_from_bytes(bytes: &[u8], voxel_type: VoxelType, endian: Endian) -> VoxelData {
    let swap = endian != Endian::native();
    match voxel_type {
        VoxelType::U8 => typed::<u8>(bytes, swap).into(),
        VoxelType::I8 => typed::<i8>(bytes, swap).into(),
        VoxelType::U16 => typed::<u16>(bytes, swap).into(),
        VoxelType::I16 => typed::<i16>(bytes, swap).into(),
        VoxelType::U32 => typed::<u32>(bytes, swap).into(),
        VoxelType::I32 => typed::<i32>(bytes, swap).into(),
        VoxelType::F32 => typed::<f32>(bytes, swap).into(),
        VoxelType::F64 => typed::<f64>(bytes, swap).into(),
    }
}

/// Owned voxels from bytes that are already native-endian, without an extra copy when the
/// vector's allocation can be reused (u8) — otherwise one copy.
pub(crate) fn voxels_from_vec(bytes: Vec<u8>, voxel_type: VoxelType, endian: Endian) -> VoxelData {
    if voxel_type == VoxelType::U8 {
        return bytes.into();
    }
    voxels_from_bytes(&bytes, voxel_type, endian)
}

fn typed<T: Voxel>(bytes: &[u8], swap: bool) -> Vec<T> {
    let size = size_of::<T>();
    debug_assert_eq!(bytes.len() % size, 0);
    let mut out = vec![T::default(); bytes.len() / size];
    bytemuck::cast_slice_mut::<T, u8>(&mut out).copy_from_slice(bytes);
    if swap && size > 1 {
        swap_in_place(&mut out);
    }
    out
}

/// Byte-swaps every voxel, in parallel for large buffers.
pub(crate) fn swap_in_place<T: Voxel>(voxels: &mut [T]) {
    const CHUNK: usize = 1 << 16;
    if voxels.len() > CHUNK {
        voxels.par_chunks_mut(CHUNK).for_each(|c| {
            for v in c {
                *v = v.swap_bytes();
            }
        });
    } else {
        for v in voxels {
            *v = v.swap_bytes();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Write;

    fn layout(dims: [usize; 3], t: VoxelType, endian: Endian, header: u64) -> RawLayout {
        RawLayout {
            dims,
            voxel_type: t,
            endian,
            header_bytes: header,
            spacing: [0.5, 1.0, 2.0],
            origin: [1.0, 2.0, 3.0],
        }
    }

    #[test]
    fn parses_cli_layout_strings() {
        assert_eq!(parse_dims("256x256x108"), Ok([256, 256, 108]));
        assert_eq!(parse_dims("4,5,6"), Ok([4, 5, 6]));
        assert!(parse_dims("4x5").is_err());
        assert!(parse_dims("4x0x5").unwrap_err().contains("at least 1"));
        assert!(parse_dims("4xax5").unwrap_err().contains("`a`"));
        assert_eq!(parse_spacing("0.957,0.957,1.5"), Ok([0.957, 0.957, 1.5]));
        assert_eq!(parse_spacing("2"), Ok([2.0; 3]));
        assert!(parse_spacing("1,0,1").is_err());
        assert!(parse_spacing("1,2").is_err());
        assert!(parse_spacing("nan").is_err());
    }

    #[test]
    fn native_aligned_raw_is_viewed_in_place() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("v.raw");
        let values: Vec<i16> = (0..24).map(|i| i * 100 - 900).collect();
        let mut bytes = vec![0u8; 4];
        bytes.extend(values.iter().flat_map(|v| v.to_ne_bytes()));
        std::fs::write(&p, &bytes).unwrap();
        let v = read_raw(&p, &layout([2, 3, 4], VoxelType::I16, Endian::native(), 4)).unwrap();
        assert!(v.data.is_shared());
        assert_eq!(v.value_f64(1, 2, 3), f64::from(values[1 + 2 * (2 + 3 * 3)]));
        assert_eq!(v.grid.origin(), glam::DVec3::new(1.0, 2.0, 3.0));
        assert_eq!(v.grid.uniform_spacing(), Some([0.5, 1.0, 2.0]));
    }

    #[test]
    fn foreign_endian_and_misaligned_data_are_swapped_into_owned_memory() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("v.raw");
        let values: Vec<f32> = (0..8).map(|i| i as f32 * 1.25 - 3.0).collect();
        let foreign = if Endian::native() == Endian::Little {
            Endian::Big
        } else {
            Endian::Little
        };
        let mut bytes = vec![7u8; 3];
        for v in &values {
            let b = v.to_bits().swap_bytes().to_ne_bytes();
            bytes.extend(b);
        }
        std::fs::write(&p, &bytes).unwrap();
        let v = read_raw(&p, &layout([2, 2, 2], VoxelType::F32, foreign, 3)).unwrap();
        assert!(!v.data.is_shared());
        for (i, want) in values.iter().enumerate() {
            assert_eq!(v.value_f64(i % 2, (i / 2) % 2, i / 4), f64::from(*want));
        }
        // Native but misaligned (3-byte header, 4-byte type): copied, not viewed.
        let mut bytes = vec![7u8; 3];
        bytes.extend(values.iter().flat_map(|v| v.to_ne_bytes()));
        std::fs::write(&p, &bytes).unwrap();
        let v = read_raw(&p, &layout([2, 2, 2], VoxelType::F32, Endian::native(), 3)).unwrap();
        assert!(!v.data.is_shared());
        assert_eq!(v.value_f64(1, 1, 1), f64::from(values[7]));
    }

    #[test]
    fn file_size_is_checked_before_mapping() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("v.raw");
        std::fs::write(&p, [0u8; 10]).unwrap();
        let l = layout([2, 2, 2], VoxelType::U16, Endian::Little, 0);
        assert!(matches!(
            read_raw(&p, &l),
            Err(FormatError::TooShort {
                needed: 16,
                available: 10,
                ..
            })
        ));
        std::fs::write(&p, [0u8; 20]).unwrap();
        assert!(matches!(
            read_raw(&p, &l),
            Err(FormatError::TooLong { offset: 16, .. })
        ));
        let huge = layout([usize::MAX, 2, 2], VoxelType::U16, Endian::Little, 0);
        assert!(matches!(
            read_raw(&p, &huge),
            Err(FormatError::Geometry { .. })
        ));
        let missing = dir.path().join("none.raw");
        assert!(matches!(
            read_raw(&missing, &l),
            Err(FormatError::Io { .. })
        ));
    }

    #[test]
    fn mapped_view_sees_the_file_as_it_was_when_unchanged() {
        // The SAFETY caveat of `map_file`: a mapped view shows the file's current bytes. This
        // checks the map reads exactly the file (and that dropping the volume unmaps cleanly).
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("m.raw");
        let mut f = File::create(&p).unwrap();
        f.write_all(&(0u8..64).collect::<Vec<_>>()).unwrap();
        drop(f);
        let file = File::open(&p).unwrap();
        let map = map_file(&p, &file).unwrap();
        assert_eq!(map.len(), 64);
        assert_eq!(map[63], 63);
        let data = voxels_from_map(&p, &map, 8, 8, VoxelType::U8, Endian::Big).unwrap();
        assert!(data.is_shared());
        drop(map);
        let VoxelData::U8(b) = data else {
            panic!("u8 expected")
        };
        assert_eq!(b.as_slice(), &[8, 9, 10, 11, 12, 13, 14, 15]);
    }

    #[test]
    fn sidecar_json_parses_with_defaults_and_rejects_unknown_keys() {
        let dir = tempfile::tempdir().unwrap();
        let raw = dir.path().join("ct.raw");
        std::fs::write(&raw, [0u8; 8]).unwrap();
        assert_eq!(sidecar_path(&raw), None);
        let side = dir.path().join("ct.json");
        std::fs::write(
            &side,
            r#"{"dims":[2,2,2],"type":"u8","endian":"little","spacing":[1,1,2]}"#,
        )
        .unwrap();
        assert_eq!(sidecar_path(&raw), Some(side.clone()));
        let l = RawLayout::from_sidecar(&side).unwrap();
        assert_eq!(l.header_bytes, 0);
        assert_eq!(l.origin, [0.0; 3]);
        assert_eq!(l.voxel_type, VoxelType::U8);
        std::fs::write(
            &side,
            r#"{"dims":[2,2,2],"type":"u8","endian":"little","spacing":[1,1,2],"typo":1}"#,
        )
        .unwrap();
        let e = RawLayout::from_sidecar(&side).unwrap_err();
        assert!(matches!(e, FormatError::Sidecar { .. }), "{e}");
        assert!(e.to_string().contains("typo"), "{e}");
        std::fs::write(
            &side,
            r#"{"dims":[2,2,2],"type":"int16","endian":"little","spacing":[1,1,1]}"#,
        )
        .unwrap();
        assert!(matches!(
            RawLayout::from_sidecar(&side),
            Err(FormatError::Sidecar { .. })
        ));
    }
}
