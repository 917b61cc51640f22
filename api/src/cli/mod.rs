//! Command-line parsing (clap) and the subcommands.

mod bench;
mod dfs_static;
mod glove;
mod recognise;
mod replay;
mod reprocess;
mod segment;
mod serve;
mod sessions;
mod simulate;
mod skills;
mod worker;

use clap::{Parser, Subcommand};
use std::path::Path;
use std::process::ExitCode;

/// ICMS: the Dynamic Force Simulator and its skill service.
#[derive(Debug, Parser)]
#[command(name = "icms", version, about, long_about = None)]
pub struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Static force analysis of a grasp (paper §3.4): contact intensities, object force,
    /// f_ext, feedback and the optimised force distribution.
    DfsStatic(dfs_static::Args),
    /// The built-in operator scenarios.
    Scenarios(simulate::ScenariosArgs),
    /// Runs a scenario through the closed 1 kHz loop (simulated operator, DFS, glove feedback)
    /// and records it into an MCAP session file.
    Simulate(simulate::SimulateArgs),
    /// Recovers an MCAP file whose writer died, up to its last complete chunk.
    Salvage(sessions::SalvageArgs),
    /// Replays a real glove recording (MCAP or CSV: joint angles, operator torques or
    /// positions only, wrist pose) of any hand through the DFS against an object into a
    /// session file.
    ///
    /// A glove that measures positions only (no torques) drives the DFS through a virtual
    /// coupling, a spring-damper from the measured posture to the simulated hand: the
    /// simulated fingers stop on the object while the operator's close further and squeeze.
    ImportGlove(sessions::ImportArgs),
    /// Writes a session's glove samples (angles, torques, wrist pose per tick) as a CSV file
    /// that `icms import-glove` reads.
    ExportGlove(sessions::ExportArgs),
    /// A live glove session against a server (`icms serve`): streams the simulated operator
    /// of a scenario, or a real glove recording, to its `GET /api/v1/live`, printing the
    /// events and a summary.
    Glove(Box<glove::GloveArgs>),
    /// Segments a session file into skills (one per grasp) with their hand-independent
    /// parameters.
    Segment(segment::SegmentArgs),
    /// Runs the live assistant's recogniser over a recorded session against the stored skills:
    /// which skill it recognises on which object, and when (session times).
    Recognise(recognise::RecogniseArgs),
    /// The main job end to end: simulates every built-in scenario, stores the sessions and
    /// their skills in the skill data base (./icms-data) and lists the skills.
    Demo(skills::DemoArgs),
    /// Stores session files and their skills in the skill data base (idempotent).
    Ingest(skills::IngestArgs),
    /// Segments again, from their stored files, the sessions whose skills an older
    /// segmentation version made, and replaces their skills.
    ///
    /// One transaction per session: interrupted at any moment (a kill, or SIGINT/SIGTERM,
    /// which stop after the session in hand), each session is as it was or done, and the next
    /// run takes up the rest. Skills that come out the same are kept with their ids and
    /// replays; the others are removed with their replays, and the new ones added. Idempotent:
    /// a second run does nothing. A session that fails (its file missing, changed on disk, no
    /// longer read as a session) is reported on stderr and keeps its skills and version; the
    /// exit code is then 1. Stop `icms serve` on the directory first: a running server keeps
    /// its in-memory skill index and cache until restarted.
    Reprocess(reprocess::ReprocessArgs),
    /// The HTTP API: record sessions, simulate, query and browse skills. Creates and migrates
    /// the data directory; seeds an empty data base with simulated sessions (--no-demo skips).
    Serve(Box<crate::config::ServeArgs>),
    /// Runs simulation and replay jobs submitted through the servers on the same data base,
    /// without serving HTTP: another machine's cores for `icms serve` (PostgreSQL).
    Worker(worker::WorkerArgs),
    /// Queries the skill data base: filters, sorting, cursor pagination, similar skills.
    Skills(Box<skills::SkillsArgs>),
    /// The built-in robot hands (glove10, allegro, barrett, inspire, gripper), or one hand.
    Hands(replay::HandsArgs),
    /// Retargets a skill onto a robot hand and simulates it in the DFS: the report says
    /// whether the object was held.
    Replay(replay::ReplayArgs),
    /// Benchmarks whose figures BENCHMARKS.md quotes.
    #[command(subcommand)]
    Bench(bench::BenchCommand),
}

/// An error for the user: printed as `error: ...` with exit code 1 (2 for usage errors).
#[derive(Debug)]
pub struct CliError(pub String);

impl<E: std::fmt::Display> From<E> for CliError {
    fn from(e: E) -> Self {
        CliError(e.to_string())
    }
}

/// Parses the command line and runs the subcommand.
pub fn run() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::DfsStatic(a) => dfs_static::run(a),
        Command::Scenarios(a) => simulate::run_scenarios(a),
        Command::Simulate(a) => simulate::run_simulate(a),
        Command::Salvage(a) => sessions::run_salvage(a),
        Command::ImportGlove(a) => sessions::run_import(a),
        Command::ExportGlove(a) => sessions::run_export(a),
        Command::Glove(a) => glove::run_glove(*a),
        Command::Segment(a) => segment::run_segment(a),
        Command::Recognise(a) => recognise::run_recognise(a),
        Command::Demo(a) => skills::run_demo(a),
        Command::Ingest(a) => skills::run_ingest(a),
        Command::Reprocess(a) => reprocess::run_reprocess(a),
        Command::Skills(a) => skills::run_skills(*a),
        Command::Hands(a) => replay::run_hands(a),
        Command::Replay(a) => replay::run_replay(a),
        Command::Serve(a) => serve::run_serve(*a),
        Command::Worker(a) => worker::run_worker(a),
        Command::Bench(b) => bench::run(b),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(CliError(msg)) => {
            eprintln!("error: {msg}");
            ExitCode::FAILURE
        }
    }
}

/// The multi-threaded runtime of a long-running process (`icms serve`, `icms worker`), with
/// the allocator's arenas limited first ([`crate::memory::limit_arenas`]).
pub(crate) fn server_runtime() -> Result<tokio::runtime::Runtime, CliError> {
    crate::memory::limit_arenas();
    tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .map_err(|e| CliError(format!("tokio: {e}")))
}

/// How a command opens the skill data base ([`open_store`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Open {
    /// Created and migrated if missing (`icms ingest`, a replay that stores itself).
    Create,
    /// Only read: an SQLite data directory without a data base is an error naming it.
    Read,
    /// Written, but not created (`icms reprocess`).
    Write,
}

/// Opens the skill data base `at` names: the data directory's SQLite file as before (see
/// [`open_existing_store`]), or with `--database-url` / `--blobs` the PostgreSQL data base
/// (migrated as `icms serve` migrates it) and the bucket, the data directory holding the
/// files (or their copies). Errors name the option or the directory.
pub(crate) async fn open_store(
    at: &crate::config::DataArgs,
    how: Open,
) -> Result<services::store::Store, CliError> {
    use services::store::{Blobs, Database, Store};
    let (database, blobs) = at.resolve().map_err(|e| CliError(e.to_string()))?;
    if matches!(database, Database::Sqlite) && matches!(blobs, Blobs::Local) {
        return match how {
            Open::Create => Store::open(&at.data)
                .await
                .map_err(|e| CliError(format!("{}: {e}", at.data.display()))),
            Open::Read => open_existing_store(&at.data).await,
            Open::Write => open_existing_store_to_write(&at.data).await,
        };
    }
    Store::open_on(&at.data, &database, &blobs)
        .await
        .map_err(|e| CliError(format!("{}: {e}", at.data.display())))
}

/// Opens the data base in `data` for a command that only reads it (`icms skills`,
/// `icms hands --data`): a directory without one is an error naming it, and nothing is created
/// there (a mistyped `--data` would otherwise leave an empty data base behind and list nothing).
pub(crate) async fn open_existing_store(
    data: &std::path::Path,
) -> Result<services::store::Store, CliError> {
    store_opened(data, services::store::Store::open_existing(data).await)
}

/// [`open_existing_store`] for a command that writes (`icms reprocess`): it takes the data
/// directory's writer lock, so it is refused, naming the holder, while `icms serve` runs there.
pub(crate) async fn open_existing_store_to_write(
    data: &std::path::Path,
) -> Result<services::store::Store, CliError> {
    store_opened(
        data,
        services::store::Store::open_existing_to_write(data).await,
    )
}

fn store_opened(
    data: &std::path::Path,
    opened: Result<services::store::Store, services::store::StoreError>,
) -> Result<services::store::Store, CliError> {
    opened.map_err(|e| match e {
        services::store::StoreError::NoDataBase(_) => CliError(no_data_base(data)),
        e => CliError(format!("{}: {e}", data.display())),
    })
}

/// The message for a `--data` directory that holds no data base.
pub(crate) fn no_data_base(data: &std::path::Path) -> String {
    format!(
        "no ICMS data base at {}; create one with `icms ingest` or `icms serve`",
        data.display()
    )
}

/// Parses JSON into `T`; the error names the path of the offending field
/// (`contacts[0].position: invalid length 2, ...`).
pub fn parse_json<T: serde::de::DeserializeOwned>(text: &str) -> Result<T, String> {
    let de = &mut serde_json::Deserializer::from_str(text);
    let value = serde_path_to_error::deserialize(&mut *de)
        .map_err(|e| crate::http::extract::path_error(&e))?;
    // Anything after the value (a second object, stray text) is refused, as over HTTP.
    de.end().map_err(|e| e.to_string())?;
    Ok(value)
}

/// Refuses an output path that is one of the files a command reads (`(what, path)`, paths
/// that do not exist are skipped): writing it would destroy the input.
pub fn refuse_out_over_inputs<P: AsRef<Path>>(
    out: &Path,
    inputs: &[(&str, P)],
) -> Result<(), CliError> {
    let Ok(out_real) = out.canonicalize() else {
        return Ok(());
    };
    match inputs
        .iter()
        .find(|(_, input)| input.as_ref().canonicalize().is_ok_and(|i| i == out_real))
    {
        Some((what, _)) => Err(CliError(format!(
            "--out {} is {what}: the recording would overwrite it; choose another file",
            out.display()
        ))),
        None => Ok(()),
    }
}

/// Prints a value as pretty JSON on stdout. A closed pipe (`icms ... | head`) ends quietly.
pub fn print_json<T: serde::Serialize>(v: &T) -> Result<(), CliError> {
    use std::io::Write;
    let text = serde_json::to_string_pretty(v)?;
    match writeln!(std::io::stdout().lock(), "{text}") {
        Err(e) if e.kind() != std::io::ErrorKind::BrokenPipe => {
            Err(CliError(format!("stdout: {e}")))
        }
        _ => Ok(()),
    }
}
