//! Logging: `tracing` events to stderr, filtered by `RUST_LOG` (default `info`; per-request
//! spans and events come at `debug` from `tower_http`, e.g. `RUST_LOG=info,tower_http=debug`);
//! colours only on a terminal.

use tracing_subscriber::EnvFilter;

/// Installs the subscriber once; later calls do nothing.
pub fn init() {
    let filter = EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new("info"));
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
        .try_init();
}
