//! `isoscope render` (being written).

/// Arguments of `isoscope render`.
#[derive(Debug, clap::Args)]
pub struct Args {}

pub fn run(_args: &Args) -> anyhow::Result<()> {
    anyhow::bail!("isoscope render is not available yet")
}
