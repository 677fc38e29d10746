//! `dpmp robot` (being built).

/// `dpmp robot` subcommands.
#[derive(Debug, clap::Subcommand)]
pub enum RobotCommand {}

/// Run a `dpmp robot` subcommand.
pub fn run(command: RobotCommand) -> crate::Result<()> {
    match command {}
}
