//! `dpmp eval` (being built).

/// Arguments of `dpmp eval`.
#[derive(Debug, clap::Args)]
pub struct EvalArgs {}

/// Run `dpmp eval`.
pub fn run(_args: EvalArgs) -> crate::Result<()> {
    Err(crate::Error::invalid(
        "command",
        "`dpmp eval` is not available in this build yet",
    ))
}
