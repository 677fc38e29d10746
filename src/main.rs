//! The `dpmp` command-line tool: a thin shell over the library.

fn main() -> std::process::ExitCode {
    dpmp::cli::main()
}
