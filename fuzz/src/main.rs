//! `icms-fuzz`: fuzz ICMS's parsers of user bytes on stable Rust (see `fuzz/README.md`).

#![forbid(unsafe_code)]

fn main() -> std::process::ExitCode {
    fuzz::driver::main()
}
