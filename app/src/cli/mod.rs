//! Command-line interface: one module per subcommand, each with an `Args` struct (clap) and a
//! `run(args) -> anyhow::Result<()>`. With no subcommand, `main.rs` opens the viewer.

use clap::{Parser, Subcommand};

pub mod accuracy;
pub mod bench;
pub mod convert;
pub mod export;
pub mod generate;
pub mod info;
pub mod movie;
pub mod npy;
pub mod open_args;
pub mod preprocess;
pub mod probe;
pub mod render;

/// Isoscope: exact, interactive isosurfaces of volume data by CPU ray tracing.
#[derive(Debug, Parser)]
#[command(name = "isoscope", version, about)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Option<Command>,
    /// Files to open in the viewer (when no subcommand is given).
    pub files: Vec<std::path::PathBuf>,
    /// Render across the ranks of an MPI job: `mpirun -n N isoscope render|bench|movie …
    /// --mpi`, or `mpirun -n N isoscope --mpi FILE` for the viewer. Every rank opens the input
    /// itself (shared storage). Needs a build with cargo feature `mpi`.
    #[arg(long, global = true)]
    pub mpi: bool,
    /// With --mpi: seconds a rank may stay silent during a frame (or while opening, ten
    /// times this) before the job fails naming it.
    #[arg(long, global = true, value_name = "SECONDS", default_value_t = 60.0)]
    pub mpi_timeout: f64,
}

#[derive(Debug, Subcommand)]
pub enum Command {
    /// Print dims, voxel type, geometry, value range, time steps and a histogram.
    Info(info::Args),
    /// Write a synthetic dataset (Marschner-Lobb, sphere, torus, phantom, ...).
    Generate(generate::Args),
    /// Ray trace isosurfaces to a PNG or JPEG, headless.
    Render(render::Args),
    /// An orbit around the data or a time series played through: numbered PNG frames, and
    /// movie.mp4 when ffmpeg is on the PATH.
    Movie(movie::Args),
    /// The interpolated value, gradient, normal and voxel or tet at world positions.
    Probe(probe::Args),
    /// Measure build time, memory and rays/s of the acceleration structures and intersectors.
    Bench(bench::Args),
    /// Write docs/accuracy.md: speed and accuracy of every intersector against the f64
    /// reference (Marschner-Lobb, phantom, extreme suite) with difference images.
    Accuracy(accuracy::Args),
    /// Build the out-of-core treelet file (.isot) of a volume: LOD pyramid, merged min/max
    /// tree, 4 KiB pages with checksums.
    Preprocess(preprocess::Args),
    /// Convert a volume (NRRD, NIfTI, Analyze, raw, series) to NRRD (.nrrd/.nhdr) or NIfTI
    /// (.nii/.nii.gz), keeping its geometry and world frame.
    Convert(convert::Args),
    /// Write the isosurfaces as a triangle mesh (PLY, STL or OBJ) for 3D printing and other
    /// tools: marching cubes on volumes, marching tetrahedra on meshes, clipped exactly.
    Export(export::Args),
}

/// An error and its causes on one line, `top: cause: cause`, leaving out a cause whose text
/// the line already holds (an I/O error that its file's error quotes), so that nothing is
/// said twice. The CLI prints it after `Error: `.
pub fn error_text(error: &anyhow::Error) -> String {
    let mut text = String::new();
    for cause in error.chain() {
        let part = cause.to_string();
        if text.contains(&part) {
            continue;
        }
        if !text.is_empty() {
            text.push_str(": ");
        }
        text.push_str(&part);
    }
    text
}

/// Runs a subcommand.
pub fn run(command: Command) -> anyhow::Result<()> {
    match command {
        Command::Info(a) => info::run(&a),
        Command::Generate(a) => generate::run(&a),
        Command::Render(a) => render::run(&a),
        Command::Movie(a) => movie::run(&a),
        Command::Probe(a) => probe::run(&a),
        Command::Bench(a) => bench::run(&a),
        Command::Accuracy(a) => accuracy::run(&a),
        Command::Preprocess(a) => preprocess::run(&a),
        Command::Convert(a) => convert::run(&a),
        Command::Export(a) => export::run(&a),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn error_text_says_each_cause_once() {
        let io = std::io::Error::new(std::io::ErrorKind::NotFound, "No such file or directory");
        let quoted = anyhow::Error::new(io).context("nope.nrrd: No such file or directory");
        assert_eq!(error_text(&quoted), "nope.nrrd: No such file or directory");
        let chained = anyhow::anyhow!("no point field named \"zzz\"").context("mesh.vtu: --field");
        assert_eq!(
            error_text(&chained),
            "mesh.vtu: --field: no point field named \"zzz\""
        );
    }
}
