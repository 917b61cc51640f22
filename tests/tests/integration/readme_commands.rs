//! The README starts with the two commands a newcomer runs (the main job, then the test
//! command), and `.ci/run` runs that same test command, as written, on its own line.

use std::path::Path;

fn read(rel: &str) -> String {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    std::fs::read_to_string(root.join(rel)).unwrap_or_else(|e| panic!("{rel}: {e}"))
}

/// The lines of the README's first ```sh block.
fn readme_commands() -> Vec<String> {
    read("README.md")
        .lines()
        .skip_while(|l| l.trim() != "```sh")
        .skip(1)
        .take_while(|l| l.trim() != "```")
        .map(|l| l.trim().to_owned())
        .filter(|l| !l.is_empty())
        .collect()
}

#[test]
fn ci_runs_the_readmes_test_command() {
    let commands = readme_commands();
    assert_eq!(
        commands.len(),
        2,
        "the README's first sh block: {commands:?}"
    );
    assert!(
        commands[0].contains("serve"),
        "the first command runs the main job: {}",
        commands[0]
    );
    let test = &commands[1];
    let ci = read(".ci/run");
    // The first command .ci/run runs (after its comments and shell options) is the README's.
    let first = ci
        .lines()
        .map(str::trim)
        .find(|l| !l.is_empty() && !l.starts_with('#') && !l.starts_with("set "));
    assert_eq!(
        first,
        Some(test.as_str()),
        ".ci/run does not run the README's test command `{test}` first:\n{ci}"
    );
    for check in [
        "cargo fmt --check",
        "cargo clippy --all-targets -- -D warnings",
    ] {
        assert!(ci.lines().any(|l| l.trim() == check), "{check}:\n{ci}");
    }
}
