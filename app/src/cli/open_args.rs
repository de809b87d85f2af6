//! Command-line flags for opening volume files, shared by the subcommands (`#[command(flatten)]`).
//!
//! Files that describe themselves (NRRD, series patterns, raw files with a `NAME.json` sidecar,
//! read by `formats`) need no flags. A headerless raw file needs its layout:
//! `--dims 256x256x108 --type i16 --endian little --spacing 0.957,0.957,1.5 --header-bytes 0
//! [--origin x,y,z]`. `--dims` and `--type` are required together; `--endian` is required for
//! multi-byte types (guessing it silently gives a wrong picture); spacing defaults to 1,
//! header bytes and origin to 0.

use anyhow::bail;
use formats::raw::{Endian, RawLayout};
use volume_core::VoxelType;

/// Raw-layout flags (ignored for self-describing files).
#[derive(Debug, Clone, Default, clap::Args)]
pub struct OpenArgs {
    /// Raw files: samples per axis, x fastest (e.g. 256x256x108).
    #[arg(long, value_name = "XxYxZ", value_parser = formats::raw::parse_dims, help_heading = "Raw files")]
    pub dims: Option<[usize; 3]>,
    /// Raw files: voxel type (u8, i8, u16, i16, u32, i32, f32, f64).
    #[arg(long = "type", value_name = "TYPE", value_parser = parse_voxel_type, help_heading = "Raw files")]
    pub voxel_type: Option<VoxelType>,
    /// Raw files: byte order (little or big); required for multi-byte types.
    #[arg(long, value_name = "ORDER", value_parser = parse_endian, help_heading = "Raw files")]
    pub endian: Option<Endian>,
    /// Raw files: sample spacing per axis, e.g. 0.957,0.957,1.5 (default 1,1,1).
    #[arg(long, value_name = "SX,SY,SZ", value_parser = formats::raw::parse_spacing, help_heading = "Raw files")]
    pub spacing: Option<[f64; 3]>,
    /// Raw files: bytes to skip at the start of the file (default 0).
    #[arg(long, value_name = "N", help_heading = "Raw files")]
    pub header_bytes: Option<u64>,
    /// Raw files: position of voxel (0,0,0), e.g. -120,-120,0 (default 0,0,0).
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_point, allow_hyphen_values = true, help_heading = "Raw files")]
    pub origin: Option<[f64; 3]>,
}

impl OpenArgs {
    /// True if any raw flag was given.
    pub fn any(&self) -> bool {
        self.dims.is_some()
            || self.voxel_type.is_some()
            || self.endian.is_some()
            || self.spacing.is_some()
            || self.header_bytes.is_some()
            || self.origin.is_some()
    }

    /// The `formats` options these flags describe.
    pub fn open_options(&self) -> anyhow::Result<formats::OpenOptions> {
        if !self.any() {
            return Ok(formats::OpenOptions::default());
        }
        let (Some(dims), Some(voxel_type)) = (self.dims, self.voxel_type) else {
            bail!("raw files need both --dims and --type (e.g. --dims 256x256x108 --type i16)");
        };
        let endian = match (self.endian, voxel_type.size_bytes()) {
            (Some(e), _) => e,
            (None, 1) => Endian::native(),
            (None, _) => bail!(
                "--type {voxel_type} is {} bytes per voxel: give its byte order with --endian little or --endian big",
                voxel_type.size_bytes()
            ),
        };
        Ok(formats::OpenOptions {
            raw: Some(RawLayout {
                dims,
                voxel_type,
                endian,
                header_bytes: self.header_bytes.unwrap_or(0),
                spacing: self.spacing.unwrap_or([1.0; 3]),
                origin: self.origin.unwrap_or([0.0; 3]),
            }),
        })
    }
}

/// Parses a voxel type name (`u8`, `i16`, `f32`, ...).
pub fn parse_voxel_type(s: &str) -> Result<VoxelType, String> {
    VoxelType::from_name(&s.to_ascii_lowercase()).ok_or_else(|| {
        let names: Vec<&str> = VoxelType::ALL.iter().map(|t| t.name()).collect();
        format!(
            "unknown voxel type `{s}`: expected one of {}",
            names.join(", ")
        )
    })
}

fn parse_endian(s: &str) -> Result<Endian, String> {
    Endian::from_name(&s.to_ascii_lowercase())
        .ok_or_else(|| format!("unknown byte order `{s}`: expected little or big"))
}

/// Parses `x,y,z` (finite numbers, any sign).
pub fn parse_point(s: &str) -> Result<[f64; 3], String> {
    let values: Vec<f64> = s
        .split(',')
        .map(|p| {
            p.trim()
                .parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| format!("`{s}`: `{p}` is not a finite number"))
        })
        .collect::<Result<_, _>>()?;
    <[f64; 3]>::try_from(values).map_err(|_| format!("`{s}`: expected three numbers x,y,z"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn no_flags_means_default_options() {
        assert!(OpenArgs::default().open_options().unwrap().raw.is_none());
    }

    #[test]
    fn full_flags_make_a_layout() {
        let a = OpenArgs {
            dims: Some([4, 5, 6]),
            voxel_type: Some(VoxelType::I16),
            endian: Some(Endian::Big),
            spacing: Some([0.5, 0.5, 2.0]),
            header_bytes: Some(16),
            origin: Some([-1.0, 0.0, 3.0]),
        };
        let l = a.open_options().unwrap().raw.unwrap();
        assert_eq!(l.dims, [4, 5, 6]);
        assert_eq!(l.voxel_type, VoxelType::I16);
        assert_eq!(l.endian, Endian::Big);
        assert_eq!(l.header_bytes, 16);
        assert_eq!(l.spacing, [0.5, 0.5, 2.0]);
        assert_eq!(l.origin, [-1.0, 0.0, 3.0]);
    }

    #[test]
    fn incomplete_flags_are_errors_that_say_what_is_missing() {
        let only_dims = OpenArgs {
            dims: Some([4, 5, 6]),
            ..OpenArgs::default()
        };
        let e = only_dims.open_options().unwrap_err().to_string();
        assert!(e.contains("--type"), "{e}");
        let no_endian = OpenArgs {
            dims: Some([4, 5, 6]),
            voxel_type: Some(VoxelType::F32),
            ..OpenArgs::default()
        };
        let e = no_endian.open_options().unwrap_err().to_string();
        assert!(e.contains("--endian"), "{e}");
        let bytes = OpenArgs {
            dims: Some([4, 5, 6]),
            voxel_type: Some(VoxelType::U8),
            ..OpenArgs::default()
        };
        assert_eq!(bytes.open_options().unwrap().raw.unwrap().spacing, [1.0; 3]);
    }

    #[test]
    fn parsers_accept_good_and_reject_bad_values() {
        assert_eq!(parse_voxel_type("I16"), Ok(VoxelType::I16));
        assert!(parse_voxel_type("float").unwrap_err().contains("u8, i8"));
        assert_eq!(parse_point("-1.5,0,2e1"), Ok([-1.5, 0.0, 20.0]));
        assert!(parse_point("1,2").is_err());
        assert!(parse_point("1,nan,2").is_err());
        assert!(parse_endian("middle").is_err());
    }
}
