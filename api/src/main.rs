//! The `icms` command-line tool.
fn main() {}
