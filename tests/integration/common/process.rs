//! The `dpmp` binary as a child process: `dpmp serve` on an ephemeral port
//! (its address read off the log), signals, and waiting for the exit.

use std::net::SocketAddr;
use std::path::Path;
use std::time::{Duration, Instant};

/// `dpmp serve` as a child process on an ephemeral port (read off its log),
/// with `flags`; stderr is kept for the test to read.
pub fn serve_process(flags: &[&str]) -> (std::process::Child, SocketAddr) {
    serve_process_in(Path::new(env!("CARGO_MANIFEST_DIR")), flags)
}

/// [`serve_process`] run from working folder `dir`.
pub fn serve_process_in(dir: &Path, flags: &[&str]) -> (std::process::Child, SocketAddr) {
    use std::io::BufRead;
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_dpmp"))
        .current_dir(dir)
        .args(["serve", "--addr", "127.0.0.1:0"])
        .args(flags)
        .env("RUST_LOG", "info")
        .env_remove("DPMP_API_TOKEN")
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let stderr = child.stderr.take().unwrap();
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        for line in std::io::BufReader::new(stderr)
            .lines()
            .map_while(Result::ok)
        {
            let line = strip_ansi(&line);
            if let Some(i) = line.find("addr=") {
                let addr = line[i + 5..]
                    .split_whitespace()
                    .next()
                    .unwrap_or("")
                    .to_string();
                let _ = tx.send(addr);
            }
        }
    });
    let addr = rx
        .recv_timeout(Duration::from_secs(60))
        .expect("the server logs its address");
    (child, addr.parse().unwrap())
}

/// `text` without ANSI colour sequences (`ESC [ ... m`).
pub fn strip_ansi(text: &str) -> String {
    let mut out = String::new();
    let mut chars = text.chars();
    while let Some(c) = chars.next() {
        if c == '\u{1b}' {
            for d in chars.by_ref() {
                if d == 'm' {
                    break;
                }
            }
        } else {
            out.push(c);
        }
    }
    out
}

/// Send signal `name` (`TERM`, `INT`) to `child`.
pub fn signal(child: &std::process::Child, name: &str) {
    let status = std::process::Command::new("kill")
        .args([format!("-{name}"), child.id().to_string()])
        .status()
        .unwrap();
    assert!(status.success());
}

/// Wait for the child to exit, at most `limit`; its exit code.
pub fn exit_within(child: &mut std::process::Child, limit: Duration) -> Option<i32> {
    let t0 = Instant::now();
    while t0.elapsed() < limit {
        if let Some(status) = child.try_wait().unwrap() {
            return status.code();
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    let _ = child.kill();
    panic!("still running after {limit:?}");
}
