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
    // The first command .ci/run runs (after its comments, its shell options and the change to
    // the checkout's root) is the README's, as written.
    let first = ci.lines().map(str::trim).find(|l| {
        !l.is_empty() && !l.starts_with('#') && !l.starts_with("set ") && !l.starts_with("cd ")
    });
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

/// `.ci/run` run as CI runs it, with stand-ins for `./scripts/test` and `cargo` that record
/// their calls: a failing test command stops it with its status before fmt and clippy; a
/// passing one is followed by exactly `cargo fmt --check` and `cargo clippy --all-targets --
/// -D warnings`, and a failing lint fails it. Started from another directory it runs the same
/// steps from the checkout's root.
#[test]
fn ci_stops_on_the_first_failing_step_and_runs_fmt_and_clippy_after_the_tests() {
    use std::os::unix::fs::PermissionsExt;
    use std::process::Command;

    let run =
        |test_status: i32, cargo_status: i32, from_elsewhere: bool| -> (Option<i32>, String) {
            let dir = tempfile::tempdir().unwrap();
            let root = dir.path();
            std::fs::create_dir_all(root.join(".ci")).unwrap();
            std::fs::create_dir_all(root.join("scripts")).unwrap();
            std::fs::create_dir_all(root.join("bin")).unwrap();
            std::fs::write(root.join(".ci/run"), read(".ci/run")).unwrap();
            let log = root.join("calls.log");
            let stand_in = |path: &Path, name: &str, status: i32| {
                std::fs::write(
                    path,
                    format!(
                        "#!/bin/sh\necho \"{name} $*\" >> '{}'\nexit {status}\n",
                        log.display()
                    ),
                )
                .unwrap();
                std::fs::set_permissions(path, std::fs::Permissions::from_mode(0o755)).unwrap();
            };
            stand_in(&root.join("scripts/test"), "scripts/test", test_status);
            stand_in(&root.join("bin/cargo"), "cargo", cargo_status);
            let path = format!(
                "{}:{}",
                root.join("bin").display(),
                std::env::var("PATH").unwrap_or_default()
            );
            // CI runs `.ci/run` from the clone's root; a person may run it from anywhere.
            let (script, cwd) = if from_elsewhere {
                (root.join(".ci/run"), root.join("bin"))
            } else {
                (Path::new(".ci/run").to_owned(), root.to_owned())
            };
            let status = Command::new("bash")
                .arg(script)
                .current_dir(cwd)
                .env("PATH", path)
                .status()
                .unwrap();
            (
                status.code(),
                std::fs::read_to_string(&log).unwrap_or_default(),
            )
        };
    let all = "scripts/test \ncargo fmt --check\ncargo clippy --all-targets -- -D warnings\n";
    for from_elsewhere in [false, true] {
        assert_eq!(
            run(3, 0, from_elsewhere),
            (Some(3), "scripts/test \n".to_owned())
        );
        assert_eq!(run(0, 0, from_elsewhere), (Some(0), all.to_owned()));
        assert_eq!(
            run(0, 1, from_elsewhere),
            (Some(1), "scripts/test \ncargo fmt --check\n".to_owned())
        );
    }
}
