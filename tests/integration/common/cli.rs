//! Running the `dpmp` binary (the one cargo built for this test run) from
//! the CLI integration tests.

use std::ffi::OsStr;
use std::process::Output;

/// Run `dpmp` with `args` and wait for it.
pub fn dpmp<S: AsRef<OsStr>>(args: &[S]) -> Output {
    std::process::Command::new(env!("CARGO_BIN_EXE_dpmp"))
        .args(args)
        .output()
        .expect("the dpmp binary starts")
}

/// [`dpmp`], asserting that it exits 0 (the failure shows its stderr).
pub fn dpmp_ok<S: AsRef<OsStr>>(args: &[S]) -> Output {
    let out = dpmp(args);
    assert!(
        out.status.success(),
        "dpmp failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

/// [`dpmp`]'s stderr as text.
pub fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// A path as a command-line argument (test paths are UTF-8).
pub fn arg(path: &std::path::Path) -> &str {
    path.to_str().expect("a UTF-8 temp path")
}
