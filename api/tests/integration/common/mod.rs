//! Running the `icms` binary from the end-to-end tests.

#![allow(dead_code)] // each test file uses some of these

pub mod pg;
pub mod server;

use std::io::Read as _;
use std::path::Path;
use std::process::{Child, Command, ExitStatus};
use std::time::{Duration, Instant};

/// Runs `icms` with `args`; returns (exit code, stdout, stderr).
pub fn icms(args: &[&str]) -> (i32, String, String) {
    run(Command::new(env!("CARGO_BIN_EXE_icms")).args(args))
}

/// Runs `icms` with `args` in the working directory `dir`.
pub fn icms_in(dir: &Path, args: &[&str]) -> (i32, String, String) {
    run(Command::new(env!("CARGO_BIN_EXE_icms"))
        .current_dir(dir)
        .args(args))
}

/// Runs `icms simulate --scenario SCENARIO ARGS… --out OUT` in `dir` and asserts it succeeded.
pub fn simulate_in(dir: &Path, scenario: &str, args: &[&str], out: &str) {
    let mut all = vec!["simulate", "--scenario", scenario];
    all.extend_from_slice(args);
    all.extend_from_slice(&["--out", out]);
    let (c, _, e) = icms_in(dir, &all);
    assert_eq!(c, 0, "icms {all:?}: {e}");
}

/// Waits for `child` (its stderr piped) to exit, polling every 50 ms; kills it and panics,
/// saying `what` still ran, if it has not within `limit`. Its exit status and stderr.
pub fn exit_within(child: &mut Child, limit: Duration, what: &str) -> (ExitStatus, String) {
    let start = Instant::now();
    loop {
        if let Some(status) = child.try_wait().unwrap() {
            let mut err = String::new();
            child
                .stderr
                .take()
                .unwrap()
                .read_to_string(&mut err)
                .unwrap();
            return (status, err);
        }
        if start.elapsed() > limit {
            let _ = child.kill();
            let _ = child.wait();
            panic!("{what} still ran after {limit:?}");
        }
        std::thread::sleep(Duration::from_millis(50));
    }
}

fn run(cmd: &mut Command) -> (i32, String, String) {
    let out = cmd.output().expect("run icms");
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}
