//! `dpmp prior` (being built).

/// `dpmp prior` subcommands.
#[derive(Debug, clap::Subcommand)]
pub enum PriorCommand {}

/// Run a `dpmp prior` subcommand.
pub fn run(command: PriorCommand) -> crate::Result<()> {
    match command {}
}
