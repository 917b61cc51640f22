//! `icms serve`: the HTTP API on the embedded SQLite data base.

use super::CliError;
use crate::config::ServeArgs;
use crate::startup::{shutdown_signal, Application};

/// Serves until SIGINT or SIGTERM, then finishes in-flight requests and closes the database.
pub fn run_serve(a: ServeArgs) -> Result<(), CliError> {
    crate::telemetry::init();
    let config = a.into_config()?;
    super::server_runtime()?.block_on(async {
        tokio::spawn(crate::memory::trim_periodically());
        let app = Application::build(config).await?;
        eprintln!(
            "icms: serving on http://{addr}/api/v1 (OpenAPI document: http://{addr}/api/v1/openapi.json; \
             the web page: http://{addr}/); Ctrl-C stops",
            addr = app.local_addr(),
        );
        app.run_until(shutdown_signal()).await?;
        Ok(())
    })
}
