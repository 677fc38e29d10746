//! `dpmp bench` (being built).

/// Arguments of `dpmp bench`.
#[derive(Debug, clap::Args)]
pub struct BenchArgs {}

/// Run `dpmp bench`.
pub fn run(_args: BenchArgs) -> crate::Result<()> {
    Err(crate::Error::invalid(
        "command",
        "`dpmp bench` is not available in this build yet",
    ))
}
