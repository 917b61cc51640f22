//! Running the `icms` binary from the end-to-end tests.

#![allow(dead_code)] // each test file uses some of these

pub mod pg;
pub mod server;

use std::path::Path;
use std::process::Command;

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

fn run(cmd: &mut Command) -> (i32, String, String) {
    let out = cmd.output().expect("run icms");
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}
