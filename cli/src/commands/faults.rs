//! `dexitac faults`: what the board has latched, and a person's
//! acknowledgement. The host never clears a fault on its own (the task loop
//! refuses to start while one is latched); after finding and removing its
//! cause, a person names the faults to clear with `--clear`.
//!
//! Exit 0 when nothing stays latched, 1 when faults stay latched (shown),
//! 2 when the board cannot be reached or refuses (a named fault's condition
//! is still present: nothing is cleared).

use anyhow::{anyhow, Context};
use dexitac_protocol::{Fault, FaultFlags, HelloReply, HostMsg};

use crate::exit::Outcome;
use crate::shared::board::BoardArgs;

/// Arguments of `dexitac faults`.
#[derive(Debug, clap::Args)]
pub struct FaultsArgs {
    #[command(flatten)]
    board: BoardArgs,
    /// Acknowledge these latched faults (names as listed, comma-separated,
    /// or `all`) once their cause is found and removed.
    #[arg(long, value_name = "FAULT,...", value_delimiter = ',')]
    clear: Vec<String>,
}

/// A fault's name on the command line: `PositiveOverLimit` ->
/// `positive-over-limit`.
pub fn fault_name(fault: Fault) -> String {
    let mut name = String::new();
    for (i, c) in format!("{fault:?}").chars().enumerate() {
        if c.is_ascii_uppercase() && i > 0 {
            name.push('-');
        }
        name.push(c.to_ascii_lowercase());
    }
    name
}

fn parse_faults(names: &[String]) -> anyhow::Result<FaultFlags> {
    let mut flags = FaultFlags::NONE;
    for name in names {
        if name == "all" {
            flags = Fault::ALL.iter().fold(flags, |f, &fault| f.with(fault));
            continue;
        }
        let fault = Fault::ALL
            .into_iter()
            .find(|&f| fault_name(f) == *name)
            .ok_or_else(|| {
                let known: Vec<String> = Fault::ALL.into_iter().map(fault_name).collect();
                anyhow!("no fault `{name}` (known: {}, all)", known.join(", "))
            })?;
        flags = flags.with(fault);
    }
    Ok(flags)
}

fn describe(hello: &HelloReply) {
    if hello.latched_faults.is_empty() {
        println!("no faults latched");
    } else {
        let names: Vec<String> = hello.latched_faults.iter().map(fault_name).collect();
        println!("latched: {}", names.join(", "));
    }
    println!("last stop before the board's boot: {:?}", hello.last_stop);
}

impl FaultsArgs {
    /// Runs `dexitac faults`.
    pub fn run(&self) -> anyhow::Result<Outcome> {
        let mut link = self.board.open()?;
        let hello = link.hello().context("hello")?;
        describe(&hello);
        if self.clear.is_empty() {
            return Ok(Outcome::from_ok(hello.latched_faults.is_empty()));
        }
        let asked = parse_faults(&self.clear)?;
        let faults = asked.intersection(hello.latched_faults);
        if faults.is_empty() {
            println!("none of those is latched: nothing to clear");
        } else {
            link.command(HostMsg::ClearFaults { faults })
                .context("the board refused to clear them (is the condition still present?)")?;
            let names: Vec<String> = faults.iter().map(fault_name).collect();
            println!("cleared: {}", names.join(", "));
        }
        let after = link.hello().context("hello")?;
        if !after.latched_faults.is_empty() {
            describe(&after);
        }
        Ok(Outcome::from_ok(after.latched_faults.is_empty()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fault_names_round_trip() {
        assert_eq!(fault_name(Fault::PositiveOverLimit), "positive-over-limit");
        assert_eq!(fault_name(Fault::HostSilence), "host-silence");
        for f in Fault::ALL {
            assert!(parse_faults(&[fault_name(f)]).unwrap().contains(f));
        }
        let all = parse_faults(&["all".into()]).unwrap();
        assert!(Fault::ALL.iter().all(|&f| all.contains(f)));
        assert!(parse_faults(&["stuck".into()]).is_err());
    }
}
