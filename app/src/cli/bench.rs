//! `isoscope bench` (being written).

/// Arguments of `isoscope bench`.
#[derive(Debug, clap::Args)]
pub struct Args {}

pub fn run(_args: &Args) -> anyhow::Result<()> {
    anyhow::bail!("isoscope bench is not available yet")
}
