//! Command-line flags for opening volume files, shared by the subcommands (`#[command(flatten)]`).
//!
//! Files that describe themselves (NRRD, MetaImage, VTK images, TIFF, series patterns, raw
//! files with a `NAME.json` sidecar, read by `formats`) need no flags. A headerless raw file
//! needs its layout: `--dims 256x256x108 --type i16 --endian little --spacing 0.957,0.957,1.5
//! --header-bytes 0 [--origin x,y,z]`. `--dims` and `--type` are required together; `--endian`
//! is required for multi-byte types (guessing it silently gives a wrong picture); spacing
//! defaults to 1, header bytes and origin to 0. `--spacing` alone gives the spacing of the
//! axes a TIFF stack does not record.
//!
//! `--field NAME` (here, for every subcommand that opens files) picks the point array of a
//! file that has several: a tetrahedral mesh, or VTK image data.
//!
//! DICOM inputs (a folder, a `DICOMDIR`, a file and its series) that hold several series need
//! `--series N|UID` (`isoscope info PATH` lists them).
//!
//! [`MeshArgs`] (tetrahedral meshes: `--bvh`, `--leaf-size`, `--packet`; and `--normals`,
//! which applies to every kind) and
//! [`OocArgs`] (`.isot` files: `--level-timeout`, `--budget-mb`) are shared by `render` and
//! `bench`; [`scene_options`] turns them into [`crate::scene::SceneOptions`] and rejects flags
//! that do not apply to the kind of file opened.

use std::path::Path;
use std::time::Duration;

use anyhow::bail;
use formats::raw::{Endian, RawLayout};
use volume_core::VoxelType;
use volume_core::intersect::Intersector;
use volume_core::ooc::OocOptions;
use volume_core::render::Normals;
use volume_core::tet::{BvhBuilder, BvhOptions};

use crate::scene::{SceneKind, SceneOptions, detect_kind};

/// Raw-layout flags (ignored for self-describing files) and the DICOM series choice.
#[derive(Debug, Clone, Default, clap::Args)]
pub struct OpenArgs {
    /// DICOM: the series to open when the input holds several: its number N in `isoscope
    /// info PATH`, or its SeriesInstanceUID.
    #[arg(long, value_name = "N|UID", help_heading = "DICOM")]
    pub series: Option<String>,
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
    /// The point array to draw, for files with several: tetrahedral meshes and VTK image data
    /// (default: the mesh's first array; an image's active scalars, else its first array;
    /// `isoscope info` lists them).
    #[arg(long, value_name = "NAME")]
    pub field: Option<String>,
}

impl OpenArgs {
    /// True if any raw flag was given (`--field` is not one).
    pub fn any(&self) -> bool {
        self.dims.is_some()
            || self.voxel_type.is_some()
            || self.endian.is_some()
            || self.spacing.is_some()
            || self.header_bytes.is_some()
            || self.origin.is_some()
    }

    /// True if a raw flag other than `--spacing` was given (`--spacing` alone also serves
    /// TIFF stacks).
    fn any_layout(&self) -> bool {
        self.dims.is_some()
            || self.voxel_type.is_some()
            || self.endian.is_some()
            || self.header_bytes.is_some()
            || self.origin.is_some()
    }

    /// The `formats` options these flags describe.
    pub fn open_options(&self) -> anyhow::Result<formats::OpenOptions> {
        let dicom_series = self.series.clone();
        if !self.any_layout() {
            return Ok(formats::OpenOptions {
                spacing: self.spacing,
                field: self.field.clone(),
                dicom_series,
                ..formats::OpenOptions::default()
            });
        }
        let (Some(dims), Some(voxel_type)) = (self.dims, self.voxel_type) else {
            bail!(
                "--dims and --type describe a headerless raw file and go together (e.g. \
                 --dims 256x256x108 --type i16); files with a header (NRRD, NIfTI, MetaImage, \
                 VTK, TIFF, DICOM) take neither"
            );
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
            spacing: None,
            field: self.field.clone(),
            dicom_series,
        })
    }
}

/// Flags for tetrahedral meshes (rejected for other files; `--field` is in [`OpenArgs`]).
#[derive(Debug, Clone, Default, clap::Args)]
pub struct MeshArgs {
    /// Meshes: BVH builder, sah (binned SAH; default) or bih (spatial median, builds faster).
    #[arg(long, value_name = "bih|sah", value_parser = parse_bvh, help_heading = "Tetrahedral meshes")]
    pub bvh: Option<BvhBuilder>,
    /// Meshes: most tets per BVH leaf, 1..=255 (default 32).
    #[arg(long, value_name = "N", help_heading = "Tetrahedral meshes")]
    pub leaf_size: Option<usize>,
    /// Meshes: rays per packet SIDE: 16 = 16×16 = 256 rays (default), 8, 4, 2 = 2×2 = 4 rays,
    /// 1 = one ray at a time.
    #[arg(long, value_name = "SIDE", value_parser = parse_packet_side, help_heading = "Tetrahedral meshes")]
    pub packet: Option<usize>,
    /// Shading normals, every kind of file: faceted (the gradient of the hit cell's own
    /// interpolant: a tet's isopolygon plane, a voxel cell's trilinear surface; meshes'
    /// default) or smooth (vertex gradients interpolated; grids' and .isot default).
    #[arg(long, value_name = "faceted|smooth", value_parser = parse_normals)]
    pub normals: Option<Normals>,
}

impl MeshArgs {
    /// True if any flag for meshes only was given (`--normals` applies to every kind).
    pub fn any(&self) -> bool {
        self.bvh.is_some() || self.leaf_size.is_some() || self.packet.is_some()
    }

    /// The BVH options these flags describe (validated).
    pub fn bvh_options(&self) -> anyhow::Result<BvhOptions> {
        let d = BvhOptions::default();
        let leaf_size = self.leaf_size.unwrap_or(d.leaf_size);
        if !(1..=255).contains(&leaf_size) {
            bail!("--leaf-size {leaf_size} must be between 1 and 255");
        }
        Ok(BvhOptions {
            builder: self.bvh.unwrap_or(d.builder),
            leaf_size,
        })
    }

    /// Rays per packet (the square of `--packet`; default 256).
    pub fn packet_rays(&self) -> usize {
        let side = self.packet.unwrap_or(16);
        side * side
    }
}

/// Flags for out-of-core `.isot` files (rejected for other files).
#[derive(Debug, Clone, Default, clap::Args)]
pub struct OocArgs {
    /// .isot files: wait at most this long for the finest level the isovalues need before
    /// rendering (default 120; 0 renders at once from the levels already loaded).
    #[arg(long, value_name = "SECS", help_heading = "Out-of-core (.isot) files")]
    pub level_timeout: Option<f64>,
    /// .isot files: memory budget for resident treelets, MiB (default: the loader's, a
    /// fraction of physical memory).
    #[arg(long, value_name = "MIB", help_heading = "Out-of-core (.isot) files")]
    pub budget_mb: Option<u64>,
}

impl OocArgs {
    pub fn any(&self) -> bool {
        self.level_timeout.is_some() || self.budget_mb.is_some()
    }

    /// `--level-timeout` (default 120 s), validated.
    pub fn level_timeout(&self) -> anyhow::Result<Duration> {
        let secs = self.level_timeout.unwrap_or(120.0);
        if !(secs.is_finite() && secs >= 0.0) {
            bail!("--level-timeout {secs} must be a number of seconds >= 0");
        }
        Ok(Duration::from_secs_f64(secs.min(1e9)))
    }

    pub fn ooc_options(&self) -> anyhow::Result<OocOptions> {
        let mut o = OocOptions::default();
        if let Some(mb) = self.budget_mb {
            if mb == 0 {
                bail!("--budget-mb must be at least 1");
            }
            o.budget_bytes = mb.saturating_mul(1 << 20);
        }
        Ok(o)
    }
}

/// The scene options of `render`/`bench` for `file`. Flags for another kind of file are
/// errors (a `--field` on a NRRD would otherwise be silently ignored).
pub fn scene_options(
    file: &Path,
    open: &OpenArgs,
    mesh: &MeshArgs,
    ooc: &OocArgs,
    step: Option<usize>,
    intersector: Option<Intersector>,
) -> anyhow::Result<SceneOptions> {
    let kind = detect_kind(file);
    let what = match kind {
        SceneKind::Grid => "a volume",
        SceneKind::Tet => "a tetrahedral mesh",
        SceneKind::Ooc => "an out-of-core .isot file",
    };
    if kind != SceneKind::Tet && mesh.any() {
        bail!(
            "--bvh, --leaf-size and --packet apply to tetrahedral meshes; {} is {what}",
            file.display()
        );
    }
    if kind == SceneKind::Tet
        && let Some(i) = intersector
    {
        bail!(
            "--intersector {i} chooses the cell intersector of volumes and .isot files; {} is \
             {what}, whose isosurface is the marching-tetrahedra isopolygons of each tet",
            file.display()
        );
    }
    if kind == SceneKind::Ooc && open.field.is_some() {
        bail!(
            "--field applies to meshes and VTK image data; {} is {what}",
            file.display()
        );
    }
    if kind != SceneKind::Ooc && ooc.any() {
        bail!(
            "--level-timeout and --budget-mb apply to .isot files; {} is {what}",
            file.display()
        );
    }
    if kind != SceneKind::Grid && open.any() {
        bail!(
            "the raw-file flags (--dims, --type, ...) apply to raw volumes; {} is {what}",
            file.display()
        );
    }
    if kind != SceneKind::Grid && open.series.is_some() {
        bail!(
            "--series picks a DICOM series; {} is {what}",
            file.display()
        );
    }
    Ok(SceneOptions {
        open: open.open_options()?,
        step: step.unwrap_or(0),
        field: open.field.clone(),
        intersector: intersector.unwrap_or_default(),
        bvh: mesh.bvh_options()?,
        normals: mesh.normals,
        packet_rays: mesh.packet_rays(),
        ooc: ooc.ooc_options()?,
    })
}

pub fn parse_bvh(s: &str) -> Result<BvhBuilder, String> {
    s.parse::<BvhBuilder>()
}

/// `--packet`: a side of 1, 2, 4, 8 or 16 rays (the renderer orders a tile's rays along a
/// Morton curve, so these sides are square blocks).
pub fn parse_packet_side(s: &str) -> Result<usize, String> {
    match s.trim().parse::<usize>() {
        Ok(n @ (1 | 2 | 4 | 8 | 16)) => Ok(n),
        _ => Err(format!(
            "`{s}`: the packet side must be 1, 2, 4, 8 or 16 (16 = 16x16 rays)"
        )),
    }
}

pub fn parse_normals(s: &str) -> Result<Normals, String> {
    match s.trim().to_ascii_lowercase().as_str() {
        "faceted" | "flat" => Ok(Normals::Faceted),
        "smooth" => Ok(Normals::Smooth),
        _ => Err(format!("`{s}`: expected faceted or smooth")),
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

pub fn parse_endian(s: &str) -> Result<Endian, String> {
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
    fn series_reaches_the_options_and_only_applies_to_volumes() {
        let a = OpenArgs {
            series: Some("2".into()),
            ..OpenArgs::default()
        };
        assert_eq!(a.open_options().unwrap().dicom_series.as_deref(), Some("2"));
        let e = scene_options(
            Path::new("m.vtu"),
            &a,
            &MeshArgs::default(),
            &OocArgs::default(),
            None,
            None,
        )
        .unwrap_err();
        assert!(
            e.to_string().contains("--series picks a DICOM series"),
            "{e}"
        );
    }

    #[test]
    fn full_flags_make_a_layout() {
        let a = OpenArgs {
            series: None,
            dims: Some([4, 5, 6]),
            voxel_type: Some(VoxelType::I16),
            endian: Some(Endian::Big),
            spacing: Some([0.5, 0.5, 2.0]),
            header_bytes: Some(16),
            origin: Some([-1.0, 0.0, 3.0]),
            field: None,
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
    fn spacing_alone_and_field_pass_through_without_a_layout() {
        let a = OpenArgs {
            spacing: Some([0.5, 0.5, 2.0]),
            field: Some("temperature".into()),
            ..OpenArgs::default()
        };
        let o = a.open_options().unwrap();
        assert!(o.raw.is_none());
        assert_eq!(o.spacing, Some([0.5, 0.5, 2.0]));
        assert_eq!(o.field.as_deref(), Some("temperature"));
        // With a layout, the spacing is the layout's.
        let b = OpenArgs {
            dims: Some([2, 2, 2]),
            voxel_type: Some(VoxelType::U8),
            ..a
        };
        let o = b.open_options().unwrap();
        assert_eq!(o.raw.unwrap().spacing, [0.5, 0.5, 2.0]);
        assert!(o.spacing.is_none());
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
        assert_eq!(parse_packet_side("2"), Ok(2));
        assert!(parse_packet_side("3").unwrap_err().contains("16x16"));
        assert_eq!(parse_normals("Smooth"), Ok(Normals::Smooth));
        assert!(parse_bvh("median").is_err());
    }

    #[test]
    fn flags_for_another_kind_of_file_are_rejected() {
        let mesh = MeshArgs {
            bvh: Some(BvhBuilder::Sah),
            ..MeshArgs::default()
        };
        let e = scene_options(
            Path::new("v.nrrd"),
            &OpenArgs::default(),
            &mesh,
            &OocArgs::default(),
            None,
            None,
        )
        .unwrap_err();
        assert!(e.to_string().contains("tetrahedral meshes"), "{e}");
        let ooc = OocArgs {
            level_timeout: Some(1.0),
            ..OocArgs::default()
        };
        let e = scene_options(
            Path::new("m.vtu"),
            &OpenArgs::default(),
            &MeshArgs::default(),
            &ooc,
            None,
            None,
        )
        .unwrap_err();
        assert!(e.to_string().contains(".isot"), "{e}");
        let o = scene_options(
            Path::new("m.vtu"),
            &OpenArgs::default(),
            &MeshArgs {
                packet: Some(2),
                bvh: Some(BvhBuilder::Sah),
                ..MeshArgs::default()
            },
            &OocArgs::default(),
            Some(3),
            None,
        )
        .unwrap();
        assert_eq!(o.packet_rays, 4);
        assert_eq!(o.bvh.builder, BvhBuilder::Sah);
        assert_eq!(o.step, 3);
        // A mesh has no cell intersector to choose; a volume takes any.
        let e = scene_options(
            Path::new("m.vtu"),
            &OpenArgs::default(),
            &MeshArgs::default(),
            &OocArgs::default(),
            None,
            Some(Intersector::Linear),
        )
        .unwrap_err();
        assert!(e.to_string().contains("--intersector linear"), "{e}");
        let o = scene_options(
            Path::new("v.nrrd"),
            &OpenArgs::default(),
            &MeshArgs::default(),
            &OocArgs::default(),
            None,
            Some(Intersector::Linear),
        )
        .unwrap();
        assert_eq!(o.intersector, Intersector::Linear);
    }
}
