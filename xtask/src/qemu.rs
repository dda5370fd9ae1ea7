//! Boots the firmware in QEMU.
#[derive(Debug, clap::Args)]
pub struct QemuArgs {}

pub fn run(_args: QemuArgs) -> anyhow::Result<()> {
    anyhow::bail!("not available yet")
}
