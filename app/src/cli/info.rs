//! `isoscope info` (being written).

/// Arguments of `isoscope info`.
#[derive(Debug, clap::Args)]
pub struct Args {}

pub fn run(_args: &Args) -> anyhow::Result<()> {
    anyhow::bail!("isoscope info is not available yet")
}
