//! `isoscope export FILE [--iso V[:#RRGGBB]]... [--clip-box ...]... [--clip-plane ...]...
//! [--step N] [--field NAME] [--normals] -o out.ply|out.stl|out.obj [--force]`.
//!
//! Opens the file as `render` does (same open, field and step flags; same `--iso` and clip
//! syntax) and writes the isosurfaces as one triangle mesh through [`crate::export`]: marching
//! cubes on volumes, marching tetrahedra on meshes, cut exactly at the clip regions. Prints
//! the vertex and triangle counts and the total area.

use std::path::PathBuf;
use std::sync::atomic::AtomicBool;

use anyhow::bail;
use formats::output::Replace;
use volume_core::render::ClipRegion;

use super::open_args::{MeshArgs, OocArgs, OpenArgs};
use super::render::{
    IsoSpec, open_with_flags, parse_clip_box, parse_clip_plane, parse_iso, surfaces_for,
};
use crate::progress::Progress;
use crate::scene::{SceneKind, detect_kind};

/// Arguments of `isoscope export`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Volume or tetrahedral mesh file, as for `render` (not an out-of-core .isot file).
    pub file: PathBuf,
    /// Isosurface value and optional colour (the PLY vertex colour). Repeat for several
    /// surfaces, exported as one mesh. Default: one surface at the middle of the value range.
    #[arg(long = "iso", value_name = "V[:#RRGGBB]", value_parser = parse_iso, allow_hyphen_values = true)]
    pub iso: Vec<IsoSpec>,
    /// Clip box by two corners; keeps its inside (default) or outside. Repeatable.
    #[arg(long = "clip-box", value_name = "X0,Y0,Z0,X1,Y1,Z1[:inside|outside]", value_parser = parse_clip_box, allow_hyphen_values = true)]
    pub clip_boxes: Vec<ClipRegion>,
    /// Clip plane keeping the points with nx·x + ny·y + nz·z <= d. Repeatable.
    #[arg(long = "clip-plane", value_name = "NX,NY,NZ,D", value_parser = parse_clip_plane, allow_hyphen_values = true)]
    pub clip_planes: Vec<ClipRegion>,
    /// Time step of a series (volumes or meshes; default 0).
    #[arg(long, value_name = "N")]
    pub step: Option<usize>,
    #[command(flatten)]
    pub open: OpenArgs,
    /// Output mesh, by its extension: binary PLY (.ply, with vertex colours), binary STL
    /// (.stl) or OBJ (.obj).
    #[arg(short, long, value_name = "out.ply")]
    pub output: PathBuf,
    /// Also write vertex normals (PLY and OBJ).
    #[arg(long)]
    pub normals: bool,
    /// Replace an existing output file (never an input file).
    #[arg(long)]
    pub force: bool,
}

pub fn run(args: &Args) -> anyhow::Result<()> {
    let replace = Replace::from_force(args.force);
    if detect_kind(&args.file) == SceneKind::Ooc {
        bail!(
            "{}: an out-of-core .isot file cannot be exported (it holds no full-resolution \
             volume in memory); export the volume it was made from",
            args.file.display()
        );
    }
    formats::trimesh::TriMeshFormat::for_path(&args.output)?;
    let scene = open_with_flags(
        &args.file,
        &args.open,
        &MeshArgs::default(),
        &OocArgs::default(),
        args.step,
        None,
    )?;
    let surfaces = surfaces_for(&args.iso, &scene)?;
    let mut clips = args.clip_boxes.clone();
    clips.extend_from_slice(&args.clip_planes);
    let summary = {
        let _spinner =
            Progress::spinner(format!("extracting and writing {}", args.output.display()));
        crate::export::export_mesh(
            &scene,
            &surfaces,
            &clips,
            &args.output,
            args.normals,
            replace,
            &AtomicBool::new(false),
            &|_| {},
        )?
    };
    println!(
        "{} -> {} ({})",
        summary,
        args.output.display(),
        summary.format.name()
    );
    Ok(())
}
