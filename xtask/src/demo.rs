//! `cargo xtask demo`: the main job.
use anyhow::Result;

pub fn run() -> Result<()> {
    anyhow::bail!("demo not wired yet")
}
