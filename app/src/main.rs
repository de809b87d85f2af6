//! The `isoscope` binary: parses the command line and hands over to the app library.
//! With no subcommand it opens the viewer on the given files (or the embedded sample).

use clap::Parser;

fn main() -> std::process::ExitCode {
    let cli = isoscope::cli::Cli::parse();
    let result = if cli.mpi {
        isoscope::distributed::launch::run(cli, run_viewer)
    } else {
        match cli.command {
            Some(command) => isoscope::cli::run(command),
            None => run_viewer(cli.files),
        }
    };
    match result {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("Error: {}", isoscope::cli::error_text(&e));
            std::process::ExitCode::FAILURE
        }
    }
}

#[cfg(feature = "viewer")]
fn run_viewer(files: Vec<std::path::PathBuf>) -> anyhow::Result<()> {
    let options = eframe::NativeOptions {
        viewport: egui::ViewportBuilder::default()
            .with_title("Isoscope")
            .with_inner_size([1280.0, 800.0])
            .with_drag_and_drop(true),
        // Only the glow renderer is built (see the root Cargo.toml).
        renderer: eframe::Renderer::Glow,
        ..Default::default()
    };
    eframe::run_native(
        "isoscope",
        options,
        Box::new(move |cc| Ok(Box::new(isoscope::ui::app::ViewerApp::new(cc, files)))),
    )
    .map_err(|e| anyhow::anyhow!("cannot open the viewer window: {e}"))
}

#[cfg(not(feature = "viewer"))]
fn run_viewer(_files: Vec<std::path::PathBuf>) -> anyhow::Result<()> {
    anyhow::bail!(
        "this isoscope was built without the viewer (cargo feature `viewer`); \
         run a subcommand such as `isoscope render` (see `isoscope --help`)"
    )
}
