//! `dpmp serve` (being built).

/// Arguments of `dpmp serve`.
#[derive(Debug, clap::Args)]
pub struct ServeArgs {}

/// Run `dpmp serve`.
pub fn run(_args: ServeArgs) -> crate::Result<()> {
    Err(crate::Error::invalid(
        "command",
        "`dpmp serve` is not available in this build yet",
    ))
}
