//! `cargo xtask bench`: runs every benchmark and prints its figures as markdown.
use anyhow::Result;

use crate::{stage, test::cargo};

#[derive(Debug, clap::Args)]
pub struct BenchArgs {}

pub fn run(_args: BenchArgs) -> Result<()> {
    stage("firmware size");
    let elf = crate::fw::build("qemu_virt", true)?;
    println!("{}", elf.display());
    stage("lbc-link host decode");
    cargo(&["bench", "-p", "lbc-link", "--bench", "decode"])?;
    Ok(())
}
