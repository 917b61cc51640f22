//! The Python interpreter the tests use for their independent checks (the reference MCAP
//! reader, the OpenAPI validator), shared by the test crates with `#[path]`.
//!
//! `scripts/test` (the README's test command) installs the packages of
//! `tests/python/requirements.txt` into a virtual environment and sets `ICMS_PYTHON` to its
//! interpreter and `ICMS_REQUIRE_TOOLS=1`: there a missing package fails the test loudly. A
//! plain `cargo test` without that set-up uses `python3` if it has the packages and otherwise
//! skips these checks, saying so on stderr.

use std::path::PathBuf;
use std::process::Command;

/// The interpreter to run, if it can import every one of `modules` (Python module names).
/// Panics when it cannot and `ICMS_REQUIRE_TOOLS` is set; otherwise prints why the check is
/// skipped and returns `None`.
#[allow(dead_code)]
pub fn python_with(modules: &[&str]) -> Option<PathBuf> {
    let interpreter = std::env::var_os("ICMS_PYTHON")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from("python3"));
    let imports = format!("import {}", modules.join(", "));
    let found = Command::new(&interpreter).args(["-c", &imports]).output();
    let why = match found {
        Ok(o) if o.status.success() => return Some(interpreter),
        Ok(o) => format!(
            "{} cannot `{imports}`: {}",
            interpreter.display(),
            String::from_utf8_lossy(&o.stderr).trim()
        ),
        Err(e) => format!("{} does not run: {e}", interpreter.display()),
    };
    let required = std::env::var_os("ICMS_REQUIRE_TOOLS").is_some_and(|v| !v.is_empty());
    if required {
        panic!("{why}; scripts/test installs tests/python/requirements.txt into target/test-venv");
    }
    eprintln!(
        "SKIPPED (a Python check): {why}. Run scripts/test, the README's test command, to \
         install what the tests need and run every check."
    );
    None
}
