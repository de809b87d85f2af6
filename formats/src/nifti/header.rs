//! The binary headers: NIfTI-1 (348 bytes), NIfTI-2 (540 bytes, 64-bit fields) and Analyze
//! 7.5 (348 bytes, no magic), in either byte order, and what they say about the volume.
//!
//! - [`parse_header`] reads the fields; `sizeof_hdr` (348 or 540, native or byte-swapped)
//!   tells the version and the byte order, the magic (`n+1`/`n+2`: data in the same file;
//!   `ni1`/`ni2`: data in the `.img` file; none in a 348-byte header: Analyze 7.5) where the
//!   data is.
//! - [`NiftiHeader::layout`] turns them into a grid, a voxel type, a value map, time steps
//!   and the data's position, checking every field it uses (errors name it: `dim[3]`,
//!   `datatype`, `vox_offset`, `srow_x`, ...).
//!
//! Geometry follows the NIfTI-1 standard (`nifti1.h`, "3D IMAGE (VOLUME) ORIENTATION AND
//! LOCATION IN SPACE"): the sform when `sform_code > 0` (method 3), else the qform quaternion
//! with `qfac = pixdim[0]` and `pixdim[1..=3]` (method 2), else `pixdim` alone from origin 0
//! (method 1; nibabel instead centres such a grid and flips x, as for Analyze). World
//! coordinates are RAS+ for methods 2 and 3; method 1 names no frame. Lengths are scaled to
//! millimetres by the `xyzt_units` space unit. As nibabel does when it loads a file,
//! `pixdim[1..=3]` are taken as absolute values with 0 read as 1, and a `qfac` other than −1
//! is 1.
//!
//! Analyze 7.5 files are oriented as nibabel loads them (its SPM2 variant, the one `nib.load`
//! picks for a `.hdr` without NIfTI magic): x flipped (radiological storage), the origin at
//! SPM's 1-based `originator` voxel when that lies within the volume (else the centre), and
//! SPM2's scale factor (`funused1`, else from `glmax`/`glmin` and `cal_max`/`cal_min`). SPM's
//! `.mat` side files are not read.

use std::path::Path;

use glam::{DMat3, DVec3};
use volume_core::{Grid, ValueMap, VoxelType, WorldFrame};

use crate::error::FormatError;
use crate::raw::Endian;

/// Bytes of a NIfTI-1 or Analyze 7.5 header.
pub const NIFTI1_HEADER_BYTES: usize = 348;
/// Bytes of a NIfTI-2 header.
pub const NIFTI2_HEADER_BYTES: usize = 540;

/// Which header layout a file has.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NiftiVersion {
    /// Analyze 7.5 (a 348-byte header without NIfTI magic), as SPM2 reads it.
    Analyze,
    Nifti1,
    Nifti2,
}

impl NiftiVersion {
    pub const fn name(self) -> &'static str {
        match self {
            NiftiVersion::Analyze => "Analyze 7.5",
            NiftiVersion::Nifti1 => "NIfTI-1",
            NiftiVersion::Nifti2 => "NIfTI-2",
        }
    }

    /// Header length in bytes.
    pub const fn header_bytes(self) -> usize {
        match self {
            NiftiVersion::Analyze | NiftiVersion::Nifti1 => NIFTI1_HEADER_BYTES,
            NiftiVersion::Nifti2 => NIFTI2_HEADER_BYTES,
        }
    }
}

/// The header fields Isoscope uses, widened to 64 bits (NIfTI-1 and Analyze store 16-bit
/// dims and 32-bit floats, NIfTI-2 64-bit ones).
#[derive(Debug, Clone, PartialEq)]
pub struct NiftiHeader {
    pub version: NiftiVersion,
    /// Byte order of the header and the data.
    pub endian: Endian,
    /// Magic `n+1`/`n+2`: the data follows the header in the same file. Otherwise (`ni1`,
    /// `ni2`, Analyze) it is in the `.img` file beside the `.hdr`.
    pub single_file: bool,
    pub dim: [i64; 8],
    pub datatype: i16,
    pub pixdim: [f64; 8],
    pub vox_offset: f64,
    pub scl_slope: f64,
    pub scl_inter: f64,
    /// Space unit (bits 0–2) and time unit (bits 3–5); 0 for Analyze, which has no such
    /// field.
    pub xyzt_units: i32,
    pub toffset: f64,
    pub intent_code: i32,
    pub qform_code: i32,
    pub sform_code: i32,
    /// `quatern_b`, `quatern_c`, `quatern_d`.
    pub quatern: [f64; 3],
    /// `qoffset_x`, `qoffset_y`, `qoffset_z`.
    pub qoffset: [f64; 3],
    /// `srow_x`, `srow_y`, `srow_z`.
    pub srow: [[f64; 4]; 3],
    /// Analyze: SPM's origin voxel (1-based) in `originator`.
    pub spm_origin: [i16; 3],
    /// Analyze: the fields SPM2 derives a scale from when `funused1` is not set.
    pub glmax: i32,
    pub glmin: i32,
    pub cal_max: f64,
    pub cal_min: f64,
}

/// Where a grid's orientation came from (the NIfTI-1 standard's methods).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum GeometrySource {
    /// `sform_code > 0`: the `srow_*` affine.
    Sform,
    /// `qform_code > 0`: quaternion, `pixdim` and `qoffset`.
    Qform,
    /// Neither: `pixdim` scales the indices, origin 0.
    Pixdim,
    /// Analyze 7.5 as nibabel's SPM2 reader orients it.
    AnalyzeSpm,
}

impl GeometrySource {
    pub const fn name(self) -> &'static str {
        match self {
            GeometrySource::Sform => "sform",
            GeometrySource::Qform => "qform",
            GeometrySource::Pixdim => "pixdim",
            GeometrySource::AnalyzeSpm => "Analyze (SPM origin, x flipped)",
        }
    }
}

/// What a header says about the volume (see [`NiftiHeader::layout`]).
#[derive(Debug, Clone)]
pub struct NiftiLayout {
    /// Geometry of one volume (one time step), millimetres.
    pub grid: Grid,
    pub voxel_type: VoxelType,
    /// `scl_slope`/`scl_inter` (the identity when the slope is 0 or not finite).
    pub value_map: ValueMap,
    /// Volumes along `dim[4]` (1 for a 3D file).
    pub steps: usize,
    /// `(time of step 0, time per step)` from `toffset` and `pixdim[4]` (seconds when the
    /// time unit is s, ms or µs), when `pixdim[4] > 0`.
    pub time: Option<(f64, f64)>,
    /// Byte offset of the data (`vox_offset`).
    pub data_offset: u64,
    /// Bytes of one volume.
    pub step_bytes: u64,
    pub geometry: GeometrySource,
}

/// The name of a NIfTI datatype code (`nifti1.h`), for messages.
pub fn datatype_name(code: i16) -> &'static str {
    match code {
        0 => "UNKNOWN",
        1 => "BINARY",
        2 => "UINT8",
        4 => "INT16",
        8 => "INT32",
        16 => "FLOAT32",
        32 => "COMPLEX64",
        64 => "FLOAT64",
        128 => "RGB24",
        256 => "INT8",
        512 => "UINT16",
        768 => "UINT32",
        1024 => "INT64",
        1280 => "UINT64",
        1536 => "FLOAT128",
        1792 => "COMPLEX128",
        2048 => "COMPLEX256",
        2304 => "RGBA32",
        _ => "not a NIfTI datatype",
    }
}

/// The voxel type of a datatype code, if Isoscope stores it.
pub fn voxel_type_of(code: i16) -> Option<VoxelType> {
    Some(match code {
        2 => VoxelType::U8,
        4 => VoxelType::I16,
        8 => VoxelType::I32,
        16 => VoxelType::F32,
        64 => VoxelType::F64,
        256 => VoxelType::I8,
        512 => VoxelType::U16,
        768 => VoxelType::U32,
        _ => return None,
    })
}

/// The datatype code of a voxel type.
pub fn datatype_of(t: VoxelType) -> i16 {
    match t {
        VoxelType::U8 => 2,
        VoxelType::I16 => 4,
        VoxelType::I32 => 8,
        VoxelType::F32 => 16,
        VoxelType::F64 => 64,
        VoxelType::I8 => 256,
        VoxelType::U16 => 512,
        VoxelType::U32 => 768,
    }
}

/// Header length and byte order from the first four bytes (`sizeof_hdr`), if they are one
/// of 348 or 540 in either byte order.
pub fn sizeof_hdr(first: [u8; 4]) -> Option<(NiftiVersion, Endian)> {
    let version = |n: i32| match n {
        348 => Some(NiftiVersion::Nifti1),
        540 => Some(NiftiVersion::Nifti2),
        _ => None,
    };
    if let Some(v) = version(i32::from_le_bytes(first)) {
        return Some((v, Endian::Little));
    }
    version(i32::from_be_bytes(first)).map(|v| (v, Endian::Big))
}

fn bad(path: &Path, field: &str, reason: impl Into<String>) -> FormatError {
    FormatError::BadField {
        path: path.to_path_buf(),
        field: field.to_string(),
        reason: reason.into(),
    }
}

/// Fixed-offset fields in the header's byte order.
struct Fields<'a> {
    bytes: &'a [u8],
    big: bool,
}

impl Fields<'_> {
    fn array<const N: usize>(&self, at: usize) -> [u8; N] {
        let mut a = [0u8; N];
        a.copy_from_slice(&self.bytes[at..at + N]);
        if self.big {
            a.reverse();
        }
        a
    }
    fn i16(&self, at: usize) -> i16 {
        i16::from_le_bytes(self.array(at))
    }
    fn i32(&self, at: usize) -> i32 {
        i32::from_le_bytes(self.array(at))
    }
    fn i64(&self, at: usize) -> i64 {
        i64::from_le_bytes(self.array(at))
    }
    fn f32(&self, at: usize) -> f64 {
        f64::from(f32::from_le_bytes(self.array(at)))
    }
    fn f64(&self, at: usize) -> f64 {
        f64::from_le_bytes(self.array(at))
    }
}

/// Parses the header at the start of `bytes` (`path` names the file in errors). `bytes` may
/// hold more than the header; fewer bytes than `sizeof_hdr` says is a truncated header.
pub fn parse_header(path: &Path, bytes: &[u8]) -> Result<NiftiHeader, FormatError> {
    let Some(first) = bytes.get(..4) else {
        return Err(bad(
            path,
            "sizeof_hdr",
            format!(
                "the file holds only {} bytes; a NIfTI-1 or Analyze header has 348, a NIfTI-2 header 540",
                bytes.len()
            ),
        ));
    };
    let first: [u8; 4] = first.try_into().expect("4 bytes");
    let Some((mut version, endian)) = sizeof_hdr(first) else {
        return Err(bad(
            path,
            "sizeof_hdr",
            format!(
                "{} (byte-swapped {}) is neither 348 (NIfTI-1, Analyze 7.5) nor 540 (NIfTI-2): \
                 not a NIfTI or Analyze header",
                i32::from_le_bytes(first),
                i32::from_be_bytes(first)
            ),
        ));
    };
    if bytes.len() < version.header_bytes() {
        return Err(bad(
            path,
            "sizeof_hdr",
            format!(
                "the {} header is {} bytes but the file holds only {} (truncated)",
                version.name(),
                version.header_bytes(),
                bytes.len()
            ),
        ));
    }
    let f = Fields {
        bytes,
        big: endian == Endian::Big,
    };
    let header = if version == NiftiVersion::Nifti2 {
        let single_file = match &bytes[4..8] {
            b"n+2\0" => true,
            b"ni2\0" => false,
            m => {
                return Err(bad(
                    path,
                    "magic",
                    format!(
                        "{:?}: a NIfTI-2 header needs \"n+2\" or \"ni2\"",
                        String::from_utf8_lossy(m)
                    ),
                ));
            }
        };
        let row = |at: usize| [0, 1, 2, 3].map(|i| f.f64(at + 8 * i));
        NiftiHeader {
            version,
            endian,
            single_file,
            dim: std::array::from_fn(|i| f.i64(16 + 8 * i)),
            datatype: f.i16(12),
            pixdim: std::array::from_fn(|i| f.f64(104 + 8 * i)),
            // i64 as f64: offsets beyond 2^53 lie beyond any file and are refused as such.
            vox_offset: f.i64(168) as f64,
            scl_slope: f.f64(176),
            scl_inter: f.f64(184),
            cal_max: f.f64(192),
            cal_min: f.f64(200),
            toffset: f.f64(216),
            qform_code: f.i32(344),
            sform_code: f.i32(348),
            quatern: [f.f64(352), f.f64(360), f.f64(368)],
            qoffset: [f.f64(376), f.f64(384), f.f64(392)],
            srow: [row(400), row(432), row(464)],
            xyzt_units: f.i32(500),
            intent_code: f.i32(504),
            spm_origin: [0; 3],
            glmax: 0,
            glmin: 0,
        }
    } else {
        let single_file = match &bytes[344..348] {
            b"n+1\0" => true,
            b"ni1\0" => false,
            _ => {
                version = NiftiVersion::Analyze;
                false
            }
        };
        let nifti = version == NiftiVersion::Nifti1;
        let row = |at: usize| [0, 1, 2, 3].map(|i| f.f32(at + 4 * i));
        NiftiHeader {
            version,
            endian,
            single_file,
            dim: std::array::from_fn(|i| i64::from(f.i16(40 + 2 * i))),
            datatype: f.i16(70),
            pixdim: std::array::from_fn(|i| f.f32(76 + 4 * i)),
            vox_offset: f.f32(108),
            // Analyze: SPM's `funused1` (scale) and `funused2` (SPM2's intercept).
            scl_slope: f.f32(112),
            scl_inter: f.f32(116),
            cal_max: f.f32(124),
            cal_min: f.f32(128),
            toffset: if nifti { f.f32(136) } else { 0.0 },
            qform_code: if nifti { i32::from(f.i16(252)) } else { 0 },
            sform_code: if nifti { i32::from(f.i16(254)) } else { 0 },
            quatern: [f.f32(256), f.f32(260), f.f32(264)],
            qoffset: [f.f32(268), f.f32(272), f.f32(276)],
            srow: [row(280), row(296), row(312)],
            xyzt_units: if nifti { i32::from(bytes[123]) } else { 0 },
            intent_code: if nifti { i32::from(f.i16(68)) } else { 0 },
            // Three int16 at byte 253 of Analyze's `originator` (unaligned).
            spm_origin: [f.i16(253), f.i16(255), f.i16(257)],
            glmax: f.i32(140),
            glmin: f.i32(144),
        }
    };
    Ok(header)
}

/// Millimetres per unit of the `xyzt_units` space code (unknown: millimetres).
fn space_unit_mm(xyzt_units: i32) -> f64 {
    match xyzt_units & 0x07 {
        1 => 1000.0, // metre
        3 => 1e-3,   // micron
        _ => 1.0,    // mm, or unknown
    }
}

/// Seconds per unit of the `xyzt_units` time code (Hz, ppm, rad/s and unknown: as stored).
fn time_unit_s(xyzt_units: i32) -> f64 {
    match xyzt_units & 0x38 {
        16 => 1e-3, // ms
        24 => 1e-6, // µs
        _ => 1.0,   // s, or not a time
    }
}

impl NiftiHeader {
    /// The grid, voxel type, value map, steps and data position (see the module docs).
    pub fn layout(&self, path: &Path) -> Result<NiftiLayout, FormatError> {
        let dim0 = self.dim[0];
        if !(1..=7).contains(&dim0) {
            return Err(bad(
                path,
                "dim[0]",
                format!("{dim0} dimensions; NIfTI allows 1 to 7"),
            ));
        }
        let n = dim0 as usize;
        let mut sizes = [1u64; 8];
        for (i, size) in sizes.iter_mut().enumerate().take(n + 1).skip(1) {
            let d = self.dim[i];
            if d < 1 {
                return Err(bad(
                    path,
                    &format!("dim[{i}]"),
                    format!("{d}: a size must be at least 1"),
                ));
            }
            *size = d as u64;
        }
        if let Some(i) = (5..=7).find(|&i| sizes[i] > 1) {
            return Err(FormatError::Unsupported {
                path: path.to_path_buf(),
                field: format!("dim[{i}]"),
                reason: format!(
                    "{} values per voxel along dimension {i} (vectors, statistics or other \
                     components, intent code {}); only scalar volumes and time series (dim[4]) \
                     are supported",
                    sizes[i], self.intent_code
                ),
            });
        }
        let voxel_type = voxel_type_of(self.datatype).ok_or_else(|| FormatError::Unsupported {
            path: path.to_path_buf(),
            field: "datatype".into(),
            reason: format!(
                "code {} ({}); supported: UINT8, INT8, UINT16, INT16, UINT32, INT32, FLOAT32, FLOAT64",
                self.datatype,
                datatype_name(self.datatype)
            ),
        })?;
        let overflow = || {
            bad(
                path,
                "dim",
                format!(
                    "sizes {:?} of {} bytes per voxel overflow 64 bits",
                    &self.dim[1..=n],
                    voxel_type.size_bytes()
                ),
            )
        };
        let step_bytes = sizes[1..=3]
            .iter()
            .try_fold(voxel_type.size_bytes() as u64, |a, &d| a.checked_mul(d))
            .ok_or_else(overflow)?;
        step_bytes.checked_mul(sizes[4]).ok_or_else(overflow)?;
        let dims = [sizes[1], sizes[2], sizes[3]].map(|d| usize::try_from(d).unwrap_or(usize::MAX));
        let steps = usize::try_from(sizes[4]).map_err(|_| overflow())?;
        let data_offset = self.data_offset(path)?;
        let (grid, geometry) = self.grid(path, dims)?;
        Ok(NiftiLayout {
            grid,
            voxel_type,
            value_map: self.value_map(path)?,
            steps,
            time: self.time(),
            data_offset,
            step_bytes,
            geometry,
        })
    }

    /// `vox_offset` as a byte offset: a whole number, after the header (and the 4-byte
    /// extension flag) in a single file.
    fn data_offset(&self, path: &Path) -> Result<u64, FormatError> {
        let v = self.vox_offset;
        if !(v.is_finite() && v >= 0.0 && v.fract() == 0.0 && v < 2f64.powi(63)) {
            return Err(bad(path, "vox_offset", format!("{v} is not a byte offset")));
        }
        let min = if self.single_file {
            self.version.header_bytes() as u64 + 4
        } else {
            0
        };
        if (v as u64) < min {
            return Err(bad(
                path,
                "vox_offset",
                format!(
                    "{v}: the data of a single-file {} starts after its {min} bytes of header \
                     and extension flag",
                    self.version.name()
                ),
            ));
        }
        Ok(v as u64)
    }

    /// `scl_slope`/`scl_inter` (SPM2's rules for Analyze).
    fn value_map(&self, path: &Path) -> Result<ValueMap, FormatError> {
        let (slope, inter) = (self.scl_slope, self.scl_inter);
        let (slope, inter) = if slope.is_finite() && slope != 0.0 {
            if self.version == NiftiVersion::Analyze {
                (slope, if inter.is_finite() { inter } else { 0.0 })
            } else {
                (slope, inter)
            }
        } else if self.version == NiftiVersion::Analyze {
            let stored = f64::from(self.glmax) - f64::from(self.glmin);
            let physical = self.cal_max - self.cal_min;
            if stored != 0.0 && physical != 0.0 && physical.is_finite() {
                let s = physical / stored;
                (s, self.cal_min - s * f64::from(self.glmin))
            } else {
                return Ok(ValueMap::IDENTITY);
            }
        } else {
            // A slope of 0 (or NaN) means "no scaling" (nifti1.h).
            return Ok(ValueMap::IDENTITY);
        };
        ValueMap::new(slope, inter).map_err(|e| {
            bad(
                path,
                if inter.is_finite() {
                    "scl_slope"
                } else {
                    "scl_inter"
                },
                e.to_string(),
            )
        })
    }

    fn time(&self) -> Option<(f64, f64)> {
        let dt = self.pixdim[4];
        if !(dt.is_finite() && dt > 0.0) {
            return None;
        }
        let unit = time_unit_s(self.xyzt_units);
        let t0 = if self.toffset.is_finite() {
            self.toffset
        } else {
            0.0
        };
        Some((t0 * unit, dt * unit))
    }

    /// `pixdim[1..=3]` as nibabel fixes them on load: absolute values, 0 read as 1; NaN and
    /// infinity are errors.
    fn voxel_sizes(&self, path: &Path) -> Result<[f64; 3], FormatError> {
        let mut s = [0.0; 3];
        for (i, v) in s.iter_mut().enumerate() {
            let p = self.pixdim[i + 1];
            if !p.is_finite() {
                return Err(bad(
                    path,
                    &format!("pixdim[{}]", i + 1),
                    format!("{p} is not a voxel size"),
                ));
            }
            *v = if p == 0.0 { 1.0 } else { p.abs() };
        }
        Ok(s)
    }

    /// The voxel-to-world affine in the file's units: the three axis directions (one voxel
    /// step each) and the position of voxel (0, 0, 0).
    fn affine(
        &self,
        path: &Path,
        dims: [usize; 3],
    ) -> Result<([DVec3; 3], DVec3, GeometrySource), FormatError> {
        if self.version == NiftiVersion::Analyze {
            let mut s = self.voxel_sizes(path)?;
            s[0] = -s[0];
            let o = self.spm_origin.map(f64::from);
            let d = dims.map(|d| d as f64);
            // nibabel `Spm99AnalyzeHeader.get_origin_affine`: SPM's origin when set and
            // within (−dims, 2·dims), else the centre.
            let use_origin =
                o.iter().any(|&x| x != 0.0) && (0..3).all(|i| o[i] > -d[i] && o[i] < 2.0 * d[i]);
            let centre: [f64; 3] = if use_origin {
                o.map(|x| x - 1.0)
            } else {
                d.map(|x| (x - 1.0) / 2.0)
            };
            let dirs = [DVec3::X * s[0], DVec3::Y * s[1], DVec3::Z * s[2]];
            let t = DVec3::new(-centre[0] * s[0], -centre[1] * s[1], -centre[2] * s[2]);
            return Ok((dirs, t, GeometrySource::AnalyzeSpm));
        }
        if self.sform_code > 0 {
            const ROWS: [&str; 3] = ["srow_x", "srow_y", "srow_z"];
            for (r, row) in self.srow.iter().enumerate() {
                if let Some(x) = row.iter().find(|x| !x.is_finite()) {
                    return Err(bad(path, ROWS[r], format!("{x} in the sform")));
                }
            }
            let col = |c: usize| DVec3::new(self.srow[0][c], self.srow[1][c], self.srow[2][c]);
            return Ok(([col(0), col(1), col(2)], col(3), GeometrySource::Sform));
        }
        if self.qform_code > 0 {
            const Q: [&str; 3] = ["quatern_b", "quatern_c", "quatern_d"];
            const O: [&str; 3] = ["qoffset_x", "qoffset_y", "qoffset_z"];
            for i in 0..3 {
                if !self.quatern[i].is_finite() {
                    return Err(bad(
                        path,
                        Q[i],
                        format!("{} is not finite", self.quatern[i]),
                    ));
                }
                if !self.qoffset[i].is_finite() {
                    return Err(bad(
                        path,
                        O[i],
                        format!("{} is not finite", self.qoffset[i]),
                    ));
                }
            }
            let r = self.rotation(path)?;
            let mut s = self.voxel_sizes(path)?;
            if self.pixdim[0] == -1.0 {
                s[2] = -s[2]; // qfac: a left-handed voxel frame
            }
            let dirs = [r.x_axis * s[0], r.y_axis * s[1], r.z_axis * s[2]];
            let [x, y, z] = self.qoffset;
            return Ok((dirs, DVec3::new(x, y, z), GeometrySource::Qform));
        }
        let s = self.voxel_sizes(path)?;
        let dirs = [DVec3::X * s[0], DVec3::Y * s[1], DVec3::Z * s[2]];
        Ok((dirs, DVec3::ZERO, GeometrySource::Pixdim))
    }

    /// The qform rotation: the unit quaternion `(a, b, c, d)` with `a ≥ 0` completed from
    /// `b, c, d`; `a = 0` when `1 − b² − c² − d²` is within rounding of 0 (nibabel's
    /// threshold: 3 ε of the header's float type).
    fn rotation(&self, path: &Path) -> Result<DMat3, FormatError> {
        let [b, c, d] = self.quatern;
        let w2 = 1.0 - (b * b + c * c + d * d);
        let eps = if self.version == NiftiVersion::Nifti2 {
            f64::EPSILON
        } else {
            f64::from(f32::EPSILON)
        };
        let a = if w2.abs() < 3.0 * eps {
            0.0
        } else if w2 < 0.0 {
            return Err(bad(
                path,
                "quatern_b",
                format!(
                    "quatern_b² + quatern_c² + quatern_d² = {} exceeds 1: not a rotation",
                    1.0 - w2
                ),
            ));
        } else {
            w2.sqrt()
        };
        // The rotation of quaternion (a, b, c, d), normalised by its squared norm.
        let n = a * a + b * b + c * c + d * d;
        let s = 2.0 / n;
        let (x, y, z) = (b * s, c * s, d * s);
        let (wx, wy, wz) = (a * x, a * y, a * z);
        let (xx, xy, xz) = (b * x, b * y, b * z);
        let (yy, yz, zz) = (c * y, c * z, d * z);
        Ok(DMat3::from_cols(
            DVec3::new(1.0 - (yy + zz), xy + wz, xz - wy),
            DVec3::new(xy - wz, 1.0 - (xx + zz), yz + wx),
            DVec3::new(xz + wy, yz - wx, 1.0 - (xx + yy)),
        ))
    }

    /// The grid of one volume (millimetres) and where its orientation came from.
    fn grid(&self, path: &Path, dims: [usize; 3]) -> Result<(Grid, GeometrySource), FormatError> {
        let (dirs, origin, source) = self.affine(path, dims)?;
        let mm = space_unit_mm(self.xyzt_units);
        let (dirs, origin) = (dirs.map(|d| d * mm), origin * mm);
        let field = match source {
            GeometrySource::Sform => "srow_x",
            GeometrySource::Qform => "qoffset_x",
            GeometrySource::Pixdim | GeometrySource::AnalyzeSpm => "pixdim",
        };
        let (axes, world_from_grid) =
            crate::oriented::axes_from_directions(dirs, origin).map_err(|i| {
                let what = match source {
                    GeometrySource::Sform => "srow_x, srow_y, srow_z".to_string(),
                    _ => format!("pixdim[{}]", i + 1),
                };
                bad(
                    path,
                    &what,
                    format!("axis {i}: direction {} has no length", dirs[i]),
                )
            })?;
        let frame = match source {
            GeometrySource::Pixdim => WorldFrame::Unknown,
            _ => WorldFrame::Ras,
        };
        let grid = Grid::new(dims, axes, world_from_grid).map_err(|e| {
            let field = match (&e, source) {
                (volume_core::VolumeError::SingularTransform, GeometrySource::Sform) => {
                    "srow_x, srow_y, srow_z"
                }
                (
                    volume_core::VolumeError::EmptyDims { .. }
                    | volume_core::VolumeError::DimsOverflow { .. },
                    _,
                ) => "dim",
                _ => field,
            };
            bad(path, field, format!("invalid geometry: {e}"))
        })?;
        Ok((grid.with_world_frame(frame), source))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A little-endian NIfTI-1 header of a 2×3×4 int16 volume (fields set by offset, as
    /// `nifti1.h` lays them out).
    pub(crate) fn nifti1_header() -> Vec<u8> {
        let mut h = vec![0u8; 352];
        h[0..4].copy_from_slice(&348i32.to_le_bytes());
        for (i, d) in [3i16, 2, 3, 4, 1, 1, 1, 1].iter().enumerate() {
            h[40 + 2 * i..42 + 2 * i].copy_from_slice(&d.to_le_bytes());
        }
        h[70..72].copy_from_slice(&4i16.to_le_bytes());
        h[72..74].copy_from_slice(&16i16.to_le_bytes());
        for (i, p) in [1.0f32, 0.5, 2.0, 3.0, 0.0, 0.0, 0.0, 0.0]
            .iter()
            .enumerate()
        {
            h[76 + 4 * i..80 + 4 * i].copy_from_slice(&p.to_le_bytes());
        }
        h[108..112].copy_from_slice(&352f32.to_le_bytes());
        h[123] = 2; // mm
        h[344..348].copy_from_slice(b"n+1\0");
        h
    }

    fn set_f32(h: &mut [u8], at: usize, v: f32) {
        h[at..at + 4].copy_from_slice(&v.to_le_bytes());
    }

    fn set_i16(h: &mut [u8], at: usize, v: i16) {
        h[at..at + 2].copy_from_slice(&v.to_le_bytes());
    }

    fn layout(h: &[u8]) -> Result<NiftiLayout, FormatError> {
        parse_header(Path::new("t.nii"), h)?.layout(Path::new("t.nii"))
    }

    fn field_of(e: &FormatError) -> &str {
        e.field().unwrap_or("")
    }

    #[test]
    fn pixdim_only_gives_a_uniform_grid_without_a_frame() {
        let l = layout(&nifti1_header()).unwrap();
        assert_eq!(l.grid.dims(), [2, 3, 4]);
        assert_eq!(l.grid.uniform_spacing(), Some([0.5, 2.0, 3.0]));
        assert_eq!(l.grid.world_from_grid(), None);
        assert_eq!(l.grid.world_frame(), WorldFrame::Unknown);
        assert_eq!(
            (l.voxel_type, l.steps, l.data_offset),
            (VoxelType::I16, 1, 352)
        );
        assert_eq!(l.step_bytes, 48);
        assert!(l.value_map.is_identity());
        assert_eq!(l.geometry, GeometrySource::Pixdim);
    }

    #[test]
    fn byte_order_follows_sizeof_hdr() {
        let le = nifti1_header();
        // Swap every field of the little-endian header to big-endian by hand.
        let mut be = le.clone();
        let swap = |b: &mut Vec<u8>, at: usize, n: usize| b[at..at + n].reverse();
        swap(&mut be, 0, 4);
        for i in 0..8 {
            swap(&mut be, 40 + 2 * i, 2);
            swap(&mut be, 76 + 4 * i, 4);
        }
        swap(&mut be, 70, 2);
        swap(&mut be, 72, 2);
        swap(&mut be, 108, 4);
        let a = parse_header(Path::new("a"), &le).unwrap();
        let b = parse_header(Path::new("b"), &be).unwrap();
        assert_eq!((a.endian, b.endian), (Endian::Little, Endian::Big));
        assert_eq!(a.dim, b.dim);
        assert_eq!(a.pixdim, b.pixdim);
        assert_eq!(a.vox_offset, b.vox_offset);
    }

    #[test]
    fn sform_wins_over_qform_and_units_scale_to_mm() {
        let mut h = nifti1_header();
        set_i16(&mut h, 252, 1);
        set_i16(&mut h, 254, 2);
        // An oblique sform: i along (0, 1, 0)·2, j along (−1, 0, 0)·0.5, k along z·3.
        for (r, row) in [
            [0.0f32, -0.5, 0.0, 10.0],
            [2.0, 0.0, 0.0, -5.0],
            [0.0, 0.0, 3.0, 1.0],
        ]
        .iter()
        .enumerate()
        {
            for (c, v) in row.iter().enumerate() {
                set_f32(&mut h, 280 + 16 * r + 4 * c, *v);
            }
        }
        h[123] = 1; // metres
        let l = layout(&h).unwrap();
        assert_eq!(l.geometry, GeometrySource::Sform);
        assert_eq!(l.grid.world_frame(), WorldFrame::Ras);
        let m = l.grid.world_from_grid().unwrap();
        let p = m.transform_point3(l.grid.grid_position(1, 2, 3));
        let want = DVec3::new(10.0 - 1.0, -5.0 + 2.0, 1.0 + 9.0) * 1000.0;
        assert!((p - want).length() < 1e-9, "{p} vs {want}");
        assert_eq!(l.grid.axis_letters(), Some(['A', 'L', 'S']));
    }

    #[test]
    fn qform_quaternion_and_qfac_give_the_rotation() {
        let mut h = nifti1_header();
        set_i16(&mut h, 252, 1);
        // 90° about z: (a, b, c, d) = (cos 45°, 0, 0, sin 45°); qfac −1 flips k.
        let s = std::f32::consts::FRAC_1_SQRT_2;
        set_f32(&mut h, 264, s);
        set_f32(&mut h, 268, 7.0);
        set_f32(&mut h, 76, -1.0);
        let l = layout(&h).unwrap();
        assert_eq!(l.geometry, GeometrySource::Qform);
        let m = l.grid.world_from_grid().unwrap();
        let p = m.transform_point3(l.grid.grid_position(1, 1, 1));
        // i (0.5 mm) → +y, j (2 mm) → −x, k (3 mm) → −z.
        let want = DVec3::new(7.0 - 2.0, 0.5, -3.0);
        assert!((p - want).length() < 1e-6, "{p} vs {want}");
    }

    #[test]
    fn scaling_time_and_big_dims() {
        let mut h = nifti1_header();
        set_f32(&mut h, 112, 2.0);
        set_f32(&mut h, 116, -1024.0);
        set_i16(&mut h, 40, 4);
        set_i16(&mut h, 48, 5);
        set_f32(&mut h, 92, 250.0);
        set_f32(&mut h, 136, 1000.0);
        h[123] = 2 | 16; // mm, ms
        let l = layout(&h).unwrap();
        assert_eq!(l.value_map, ValueMap::new(2.0, -1024.0).unwrap());
        assert_eq!(l.steps, 5);
        assert_eq!(l.time, Some((1.0, 0.25)));
        // Slope 0 or NaN: no scaling, whatever the intercept.
        for slope in [0.0, f32::NAN] {
            set_f32(&mut h, 112, slope);
            assert!(layout(&h).unwrap().value_map.is_identity());
        }
        set_f32(&mut h, 112, 1.0);
        set_f32(&mut h, 116, f32::INFINITY);
        assert_eq!(field_of(&layout(&h).unwrap_err()), "scl_inter");
    }

    #[test]
    fn bad_fields_are_named() {
        let h = nifti1_header();
        let e = parse_header(Path::new("t.nii"), &h[..100]).unwrap_err();
        assert_eq!(field_of(&e), "sizeof_hdr");
        assert!(
            e.to_string().contains("t.nii") && e.to_string().contains("truncated"),
            "{e}"
        );
        let mut x = h.clone();
        x[0..4].copy_from_slice(&349i32.to_le_bytes());
        assert_eq!(field_of(&layout(&x).unwrap_err()), "sizeof_hdr");
        let mut x = h.clone();
        set_i16(&mut x, 70, 1024);
        let e = layout(&x).unwrap_err();
        assert!(
            matches!(&e, FormatError::Unsupported { field, reason, .. } if field == "datatype" && reason.contains("INT64")),
            "{e}"
        );
        let mut x = h.clone();
        set_i16(&mut x, 46, 0);
        assert_eq!(field_of(&layout(&x).unwrap_err()), "dim[3]");
        let mut x = h.clone();
        set_i16(&mut x, 40, 9);
        assert_eq!(field_of(&layout(&x).unwrap_err()), "dim[0]");
        let mut x = h.clone();
        set_i16(&mut x, 40, 5);
        set_i16(&mut x, 50, 3);
        assert_eq!(field_of(&layout(&x).unwrap_err()), "dim[5]");
        let mut x = h.clone();
        set_f32(&mut x, 108, 100.0);
        assert_eq!(field_of(&layout(&x).unwrap_err()), "vox_offset");
        set_f32(&mut x, 108, 352.5);
        assert_eq!(field_of(&layout(&x).unwrap_err()), "vox_offset");
        let mut x = h.clone();
        set_f32(&mut x, 80, f32::NAN);
        assert_eq!(field_of(&layout(&x).unwrap_err()), "pixdim[1]");
        let mut x = h.clone();
        set_i16(&mut x, 252, 1);
        set_f32(&mut x, 256, 0.9);
        set_f32(&mut x, 260, 0.9);
        assert_eq!(field_of(&layout(&x).unwrap_err()), "quatern_b");
        let mut x = h;
        set_i16(&mut x, 254, 1);
        assert_eq!(field_of(&layout(&x).unwrap_err()), "srow_x, srow_y, srow_z");
    }

    #[test]
    fn nifti2_dims_overflow_is_an_error() {
        let mut h = vec![0u8; 544];
        h[0..4].copy_from_slice(&540i32.to_le_bytes());
        h[4..12].copy_from_slice(b"n+2\0\r\n\x1a\n");
        h[12..14].copy_from_slice(&16i16.to_le_bytes());
        for (i, d) in [3i64, 1 << 30, 1 << 30, 1 << 30, 1, 1, 1, 1]
            .iter()
            .enumerate()
        {
            h[16 + 8 * i..24 + 8 * i].copy_from_slice(&d.to_le_bytes());
        }
        for i in 0..8 {
            h[104 + 8 * i..112 + 8 * i].copy_from_slice(&1f64.to_le_bytes());
        }
        h[168..176].copy_from_slice(&544i64.to_le_bytes());
        let e = parse_header(Path::new("t.nii"), &h)
            .unwrap()
            .layout(Path::new("t.nii"))
            .unwrap_err();
        assert_eq!(field_of(&e), "dim");
        assert!(e.to_string().contains("overflow"), "{e}");
        h[24..32].copy_from_slice(&4i64.to_le_bytes());
        h[32..40].copy_from_slice(&5i64.to_le_bytes());
        h[40..48].copy_from_slice(&6i64.to_le_bytes());
        let l = parse_header(Path::new("t.nii"), &h)
            .unwrap()
            .layout(Path::new("t.nii"))
            .unwrap();
        assert_eq!((l.grid.dims(), l.data_offset), ([4, 5, 6], 544));
        h[4..8].copy_from_slice(b"n+1\0");
        let e = parse_header(Path::new("t.nii"), &h).unwrap_err();
        assert_eq!(field_of(&e), "magic");
    }
}
