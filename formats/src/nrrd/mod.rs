//! NRRD: the reader (attached `.nrrd` and detached `.nhdr`) and the writer.
//!
//! - [`header`]: the header parser ([`parse_header`]), every field Teem writes.
//! - [`geometry`]: axes → grid (oriented or uniform) and time steps.
//! - `data`: decoding (raw memory-mapped, gzip, bzip2, ascii, hex), skips, data file lists.
//! - [`NrrdSteps`]: the lazily loaded time steps of a 4D NRRD.
//! - [`write_nrrd`]: NRRD0004, raw or gzip, written to a temporary file and renamed;
//!   [`write_nrrd_detached`]: the same as a `.nhdr` header and a `.raw`/`.raw.gz` data file.
//!
//! A 3D file (or 4D with a leading size-1 axis) opens as a volume; a 4D file with a time axis,
//! or a detached header whose data files hold one step each, opens as a time series whose steps
//! load lazily (raw data: each step is a view into the one memory map).

pub mod geometry;
pub mod header;

mod data;
mod steps;
mod write;

use std::io::Read;
use std::path::Path;

pub(crate) use data::{DataPlan, PlanParts};
pub use geometry::VolumeLayout;
pub use header::{
    Center, DataFiles, Encoding, MAX_HEADER_BYTES, NrrdHeader, parse_header, parse_header_at,
};
pub use steps::NrrdSteps;
pub(crate) use steps::dataset as planned_dataset;
pub use write::{NrrdEncoding, write_nrrd, write_nrrd_detached};

use crate::Dataset;
use crate::error::FormatError;

/// Reads the header bytes of `path`: up to and including the first blank line (attached
/// data follows it) or the whole file for a detached header, at most [`MAX_HEADER_BYTES`].
pub fn read_header_bytes(path: &Path) -> Result<Vec<u8>, FormatError> {
    let mut file = crate::input::open_regular(path).map_err(|e| FormatError::io(path, e))?;
    let mut buf = Vec::new();
    let mut chunk = vec![0u8; 1 << 16];
    loop {
        let n = file
            .read(&mut chunk)
            .map_err(|e| FormatError::io(path, e))?;
        if n == 0 {
            return Ok(buf);
        }
        let search_from = buf.len().saturating_sub(2);
        buf.extend_from_slice(&chunk[..n]);
        if buf.len() >= 4 && &buf[..4] != b"NRRD" {
            return Ok(buf); // the parser reports the bad magic
        }
        let tail = &buf[search_from..];
        if tail.windows(2).any(|w| w == b"\n\n") || tail.windows(3).any(|w| w == b"\n\r\n") {
            return Ok(buf);
        }
        if buf.len() > MAX_HEADER_BYTES {
            return Ok(buf); // the parser reports the overlong header
        }
    }
}

/// Reads and checks the header of the NRRD file at `path`.
pub fn read_header(path: &Path) -> Result<NrrdHeader, FormatError> {
    let bytes = read_header_bytes(path)?;
    parse_header_at(path, &bytes)
}

/// Reads a NRRD file: a volume, or a lazily loaded time series (see the module docs).
pub fn read_nrrd(path: &Path) -> Result<Dataset, FormatError> {
    let header = read_header(path)?;
    let layout = header.volume_layout(path)?;
    let plan = DataPlan::new(&header, path);
    let step_bytes = (layout.grid.voxel_count() * header.voxel_type.size_bytes()) as u64;
    steps::dataset(path, plan, layout, step_bytes, "NRRD")
}
