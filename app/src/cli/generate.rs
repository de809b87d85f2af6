//! `isoscope generate` (being written).

/// Arguments of `isoscope generate`.
#[derive(Debug, clap::Args)]
pub struct Args {}

pub fn run(_args: &Args) -> anyhow::Result<()> {
    anyhow::bail!("isoscope generate is not available yet")
}
