//! The board's serial port, for the commands that talk to the board
//! without running the task loop (`faults`, `calibrate`).

use std::path::PathBuf;

use anyhow::{anyhow, Context};
use dexitac_rig::config::RigConfig;
use dexitac_rig::link::{Link, LinkConfig, SerialLink};

/// Where the board is: `--port`, or the rig config's `[link] port`.
#[derive(Debug, clap::Args)]
pub struct BoardArgs {
    /// Serial port of the board; default: the rig config's `[link] port`.
    #[arg(long, value_name = "PATH")]
    port: Option<PathBuf>,
    /// Rig config (for the port and the baud rate).
    #[arg(long, value_name = "RIG.toml")]
    config: Option<PathBuf>,
}

impl BoardArgs {
    /// Opens the link to the board (nothing sent yet).
    pub fn open(&self) -> anyhow::Result<SerialLink> {
        let rig: Option<RigConfig> = self.config.as_deref().map(RigConfig::load).transpose()?;
        let port = self
            .port
            .clone()
            .or_else(|| rig.as_ref().and_then(|r| r.link.port.clone()))
            .ok_or_else(|| anyhow!("give --port, or a rig config with a [link] port"))?;
        let link_config = rig
            .as_ref()
            .map_or_else(LinkConfig::default, RigConfig::link);
        Link::open(&port, link_config).with_context(|| format!("opening {}", port.display()))
    }
}
