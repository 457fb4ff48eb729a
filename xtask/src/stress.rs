//! `cargo xtask stress`.
use anyhow::Result;

pub fn run(_args: &[String]) -> Result<()> {
    anyhow::bail!("stress: not implemented yet")
}
