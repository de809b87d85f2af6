//! `--mpi`: every rank parses the same command line; rank 0 runs the command (or the
//! viewer) with a [`super::Cluster`] installed, the others open the same input and serve.

use std::path::{Path, PathBuf};
use std::time::Duration;

use anyhow::bail;

use crate::cli::{Cli, Command};
use crate::scene::AnyScene;

/// What a worker rank needs of the command line.
#[cfg_attr(not(feature = "mpi"), allow(dead_code))]
struct Plan {
    input: PathBuf,
    /// Out-of-core: how long workers wait for rank 0's levels.
    level_wait: Duration,
    threads: Option<usize>,
    viewer: bool,
}

fn plan(cli: &Cli) -> anyhow::Result<Plan> {
    Ok(match &cli.command {
        Some(Command::Render(a)) if a.stats => {
            // Traversal statistics are counted per process; a job would report a part.
            bail!("--stats counts the traversal of one process: run it without --mpi")
        }
        Some(Command::Render(a)) => Plan {
            input: a.scene.file.clone(),
            level_wait: a.scene.ooc.level_timeout()?,
            threads: None,
            viewer: false,
        },
        Some(Command::Movie(a)) => Plan {
            input: a.scene.file.clone(),
            level_wait: a.scene.ooc.level_timeout()?,
            threads: None,
            viewer: false,
        },
        Some(Command::Bench(a)) => Plan {
            input: a.file.clone(),
            level_wait: a.ooc.level_timeout()?,
            threads: a.threads,
            viewer: false,
        },
        Some(_) => bail!("--mpi works with render, bench, movie and the viewer"),
        None => match cli.files.as_slice() {
            [file] => Plan {
                input: file.clone(),
                level_wait: Duration::ZERO,
                threads: None,
                viewer: true,
            },
            _ => bail!("the viewer with --mpi takes one FILE, which every rank opens"),
        },
    })
}

/// The scene a worker serves, opened as rank 0 opens it.
fn open_for(cli: &Cli, input: &Path) -> anyhow::Result<AnyScene> {
    match &cli.command {
        Some(Command::Render(a)) => a.scene.open_scene(),
        Some(Command::Movie(a)) => a.scene.open_scene(),
        Some(Command::Bench(a)) => crate::cli::render::open_with_flags(
            &a.file,
            &a.open,
            &a.mesh,
            &a.ooc,
            a.step,
            a.intersector,
        ),
        _ => crate::scene::open_scene(input, &crate::scene::SceneOptions::default()),
    }
}

/// Runs `cli` as one rank of an MPI job; `viewer` opens the viewer window on rank 0.
#[cfg(feature = "mpi")]
pub fn run(
    cli: Cli,
    viewer: impl FnOnce(Vec<PathBuf>) -> anyhow::Result<()>,
) -> anyhow::Result<()> {
    use super::link::Link as _;
    use super::mpi_link::{MpiLink, initialize};
    use super::{Cluster, install, uninstall, worker};

    let plan = plan(&cli)?;
    if !(cli.mpi_timeout.is_finite() && cli.mpi_timeout > 0.0) {
        bail!("--mpi-timeout must be a positive number of seconds");
    }
    let universe = initialize()?;
    if let Some(t) = plan.threads {
        // Every rank renders with the same thread count (`bench --threads`).
        let _ = rayon::ThreadPoolBuilder::new()
            .num_threads(t.max(1))
            .build_global();
    }
    let link = MpiLink::world();
    if link.rank() != 0 {
        match worker::report_opened(&link, open_for(&cli, &plan.input)) {
            Some(mut scene) => worker::serve(&link, &mut scene),
            None => worker::serve_none(&link),
        }
        drop(universe);
        return Ok(());
    }
    let mut cluster = Cluster::new(
        Box::new(link),
        &plan.input,
        Duration::from_secs_f64(cli.mpi_timeout),
    );
    cluster.set_level_wait(plan.level_wait);
    install(cluster, plan.viewer);
    let result = match cli.command {
        Some(command) => crate::cli::run(command),
        None => viewer(cli.files),
    };
    let mut cluster = uninstall().expect("the cluster installed above");
    let failure = cluster.failure().map(str::to_string);
    if cluster.hung() {
        // A rank stopped answering: a clean shutdown would wait for it forever.
        eprintln!(
            "Error: {}",
            failure.as_deref().unwrap_or("a rank stopped answering")
        );
        cluster.abort(1);
    }
    cluster.shut_down();
    drop(cluster);
    drop(universe);
    match (failure, plan.viewer) {
        (Some(f), false) => Err(anyhow::anyhow!(f)),
        _ => result,
    }
}

/// Without the `mpi` feature: says how to get it.
#[cfg(not(feature = "mpi"))]
#[allow(clippy::needless_pass_by_value)] // the signature of the MPI build
pub fn run(
    cli: Cli,
    _viewer: impl FnOnce(Vec<PathBuf>) -> anyhow::Result<()>,
) -> anyhow::Result<()> {
    plan(&cli)?;
    let _ = open_for;
    bail!(
        "this isoscope was built without MPI: build it with `cargo build --release --features \
         mpi` (needs an MPI library such as Debian's libopenmpi-dev, and libclang-dev) and run \
         it under mpirun or srun"
    )
}
