//! `dexitac completions SHELL`: a shell completion script on stdout
//! (`clap_complete`).

use clap_complete::Shell;

use crate::exit::Outcome;

/// Arguments of `dexitac completions`.
#[derive(Debug, clap::Args)]
pub struct CompletionsArgs {
    /// The shell.
    #[arg(value_enum)]
    shell: Shell,
}

impl CompletionsArgs {
    /// Writes the script for `command` (the whole `dexitac` command line).
    pub fn run(&self, command: &mut clap::Command) -> anyhow::Result<Outcome> {
        clap_complete::generate(self.shell, command, "dexitac", &mut std::io::stdout());
        Ok(Outcome::Success)
    }
}
