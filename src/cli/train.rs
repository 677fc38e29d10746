//! `dpmp train` (being built).

/// Arguments of `dpmp train`.
#[derive(Debug, clap::Args)]
pub struct TrainArgs {}

/// Run `dpmp train`.
pub fn run(_args: TrainArgs) -> crate::Result<()> {
    Err(crate::Error::invalid(
        "command",
        "`dpmp train` is not available in this build yet",
    ))
}
