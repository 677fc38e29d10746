//! `dpmp optimize` (being built).

/// Arguments of `dpmp optimize`.
#[derive(Debug, clap::Args)]
pub struct OptimizeArgs {}

/// Run `dpmp optimize`.
pub fn run(_args: OptimizeArgs) -> crate::Result<()> {
    Err(crate::Error::invalid(
        "command",
        "`dpmp optimize` is not available in this build yet",
    ))
}
