//! `dpmp plan` (being built).

/// Arguments of `dpmp plan`.
#[derive(Debug, clap::Args)]
pub struct PlanArgs {}

/// Run `dpmp plan`.
pub fn run(_args: PlanArgs) -> crate::Result<()> {
    Err(crate::Error::invalid(
        "command",
        "`dpmp plan` is not available in this build yet",
    ))
}
