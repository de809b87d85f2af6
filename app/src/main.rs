//! The `isoscope` binary: parses the command line and hands over to the app library.

use clap::Parser;

fn main() -> anyhow::Result<()> {
    let cli = isoscope::cli::Cli::parse();
    match cli.command {
        Some(command) => isoscope::cli::run(command),
        None => anyhow::bail!("the viewer is not built yet; try `isoscope --help`"),
    }
}
