//! `isoscope probe FILE --at X,Y,Z... [--step N] [--field NAME] [--json]`: what the data
//! holds at world positions — the interpolated value (trilinear in a voxel cell, linear in a
//! tet), its gradient and the level set's normal, the continuous voxel index and nearest
//! voxel, or the tet and its barycentric coordinates ([`crate::scene::AnyScene::probe`], the
//! same query as the viewer's picking and `render --pick`).

use std::path::PathBuf;

use glam::DVec3;
use volume_core::render::Surface;

use super::open_args::{MeshArgs, OocArgs, OpenArgs};
use super::render::{open_with_flags, parse_vec3};
use crate::scene::{Pick, Probe, ProbeLocation};
use crate::values::ValueFormat;

/// Arguments of `isoscope probe`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// A volume or tetrahedral mesh (anything `render` opens but `.isot`).
    pub file: PathBuf,
    /// World position to probe. Repeatable.
    #[arg(long = "at", value_name = "X,Y,Z", value_parser = parse_vec3, allow_hyphen_values = true, required = true)]
    pub at: Vec<glam::Vec3>,
    /// Time step of a series (default 0).
    #[arg(long, value_name = "N")]
    pub step: Option<usize>,
    /// One JSON array with an object per position (`null` outside the data).
    #[arg(long)]
    pub json: bool,
    #[command(flatten)]
    pub open: OpenArgs,
}

/// One line for a probe: value, normal and where it lies.
pub fn probe_text(p: &Probe) -> String {
    let f = ValueFormat::F64;
    let v3 = |v: [f64; 3]| format!("{}, {}, {}", f.value(v[0]), f.value(v[1]), f.value(v[2]));
    let place = match p.location {
        ProbeLocation::Voxel {
            index,
            nearest_voxel: [i, j, k],
        } => format!("voxel index {} (nearest voxel {i}, {j}, {k})", v3(index)),
        ProbeLocation::Tet { tet, barycentric } => format!(
            "tet {tet} (barycentric {:.4}, {:.4}, {:.4}, {:.4})",
            barycentric[0], barycentric[1], barycentric[2], barycentric[3]
        ),
    };
    let normal = p.normal.map_or_else(|| "none (zero gradient)".into(), v3);
    format!(
        "value {}; {place}; gradient {}; normal {normal}",
        f.value(p.value),
        v3(p.gradient_world)
    )
}

/// What a picked pixel shows, in one line (`render --pick`, the viewer's pick panel): the
/// surface hit, the ray parameter, the world position and the data there ([`probe_text`]).
pub fn pick_text(pick: Option<&Pick>, surfaces: &[Surface]) -> String {
    let Some(p) = pick else {
        return "no surface".to_string();
    };
    let f32s = ValueFormat::F32;
    let f = ValueFormat::F64;
    let t = f32s.value(f64::from(p.t));
    let Some(probe) = &p.probe else {
        return format!("a hit at t = {t} outside the data");
    };
    let surface = p
        .surface
        .and_then(|i| surfaces.get(i).map(|s| (i, s)))
        .map_or_else(String::new, |(i, s)| {
            format!("surface {i} (iso {}); ", f32s.value(f64::from(s.isovalue)))
        });
    let [x, y, z] = p.world;
    format!(
        "{surface}t = {t}; world {}, {}, {}; {}",
        f.value(x),
        f.value(y),
        f.value(z),
        probe_text(probe)
    )
}

pub fn run(args: &Args) -> anyhow::Result<()> {
    let scene = open_with_flags(
        &args.file,
        &args.open,
        &MeshArgs::default(),
        &OocArgs::default(),
        args.step,
        None,
    )?;
    let mut probes = Vec::with_capacity(args.at.len());
    for at in &args.at {
        probes.push(scene.probe(DVec3::from(at.to_array().map(f64::from)))?);
    }
    if args.json {
        println!("{}", serde_json::to_string_pretty(&probes)?);
        return Ok(());
    }
    for (at, p) in args.at.iter().zip(&probes) {
        let at = format!("{}, {}, {}", at.x, at.y, at.z);
        match p {
            Some(p) => println!("at {at}: {}", probe_text(p)),
            None => println!("at {at}: outside the data"),
        }
    }
    Ok(())
}
