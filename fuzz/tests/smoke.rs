//! The harness builds and works: every target runs 200 inputs through `icms-fuzz` (child
//! processes, seeds, mutators, the HTTP router). Findings are not asserted here: the
//! documented campaign (`fuzz/README.md`) is where the target is 0 panics and 0 aborts.

use std::process::Command;

#[test]
fn every_target_runs_200_inputs() {
    let findings = tempfile::tempdir().expect("temporary directory");
    let out = Command::new(env!("CARGO_BIN_EXE_icms-fuzz"))
        .args(["all", "--runs", "200", "--json", "--findings"])
        .arg(findings.path())
        .output()
        .expect("icms-fuzz runs");
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    let totals: Vec<serde_json::Value> = stdout
        .lines()
        .filter(|l| l.starts_with('{'))
        .map(|l| serde_json::from_str(l).expect("totals are JSON"))
        .collect();
    let names: Vec<&str> = totals.iter().filter_map(|t| t["target"].as_str()).collect();
    assert_eq!(
        names,
        ["session", "urdf", "scenario", "grasp", "skill", "http"],
        "stdout: {stdout}\nstderr: {stderr}"
    );
    for t in &totals {
        assert_eq!(t["executions"], 200, "{t}\nstderr: {stderr}");
        assert!(t["exec_per_s"].as_f64().unwrap() > 0.0, "{t}");
    }
}

#[test]
fn a_seed_input_reproduces_in_process() {
    let out = Command::new(env!("CARGO_BIN_EXE_icms-fuzz"))
        .args(["grasp", "--only", "0"])
        .output()
        .expect("icms-fuzz runs");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{stdout}");
    assert!(stdout.contains("no finding"), "{stdout}");
}
