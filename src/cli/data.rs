//! `dpmp data` (being built).

/// `dpmp data` subcommands.
#[derive(Debug, clap::Subcommand)]
pub enum DataCommand {}

/// Run a `dpmp data` subcommand.
pub fn run(command: DataCommand) -> crate::Result<()> {
    match command {}
}
