//! `dexitac`: the DexiTac command-line tool.

use clap::Parser;

/// DexiTac: soft dexterous tactile gripping — host tools for the pneumatic
/// two-finger gripper with camera-based tactile fingertips.
#[derive(Debug, Parser)]
#[command(name = "dexitac", version, about, long_about = None)]
struct Cli {}

fn main() {
    let _cli = Cli::parse();
    println!(
        "dexitac {}: wire protocol v{}. See `dexitac --help`.",
        env!("CARGO_PKG_VERSION"),
        dexitac::protocol::PROTOCOL_VERSION
    );
}
