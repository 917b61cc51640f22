//! `icms ingest` and `icms skills`: the skill data base from the command line.

use super::{open_store, print_json, CliError, Open};
use crate::config::DataArgs;
use crate::filters::SkillFilters;
use services::ingest::{ingest_files, IngestError, INGEST_FILES_IN_FLIGHT};
use services::store::IngestOutcome;
use services::store::{Store, DEFAULT_LIMIT, MAX_LIMIT};
use std::path::PathBuf;

/// Arguments of `icms ingest`.
#[derive(Debug, clap::Args)]
pub struct IngestArgs {
    /// Session files (MCAP) to store with their skills.
    #[arg(required = true)]
    files: Vec<PathBuf>,
    /// Where the data base is.
    #[command(flatten)]
    at: DataArgs,
    /// Print JSON.
    #[arg(long)]
    json: bool,
}

/// Arguments of `icms skills`: every filter of the store, or similar skills.
#[derive(Debug, clap::Args)]
pub struct SkillsArgs {
    /// Filters, sort and page (the same parameters as `GET /api/v1/skills`).
    #[command(flatten)]
    filters: SkillFilters,
    /// The k nearest skills to this skill id instead of a filtered list (k = --limit, default
    /// 50). Takes no filters, sort or cursor.
    #[arg(long, allow_negative_numbers = true, conflicts_with_all = [
        "shape", "mass_min", "mass_max", "mu_min", "mu_max", "contacts", "contact_model",
        "grasp_type", "min_quality", "phase", "phase_min_s", "phase_max_s", "sort", "cursor",
    ])]
    similar_to: Option<i64>,
    /// Where the data base is.
    #[command(flatten)]
    at: DataArgs,
    /// Print JSON.
    #[arg(long)]
    json: bool,
}

/// The multi-threaded runtime of the data base commands.
pub(super) fn runtime() -> Result<tokio::runtime::Runtime, CliError> {
    tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .map_err(|e| CliError(format!("tokio: {e}")))
}

/// Reads, segments and stores each file; the same file twice is stored once. A file that
/// cannot be stored (unreadable, not a valid session) is reported and skipped, the others are
/// still stored (each file is its own transaction), and the command then fails naming it.
pub fn run_ingest(a: IngestArgs) -> Result<(), CliError> {
    // Nothing to store: say so without creating a data base.
    if !a.files.iter().any(|f| f.is_file()) {
        for f in &a.files {
            let why = if f.exists() {
                "not a file"
            } else {
                "no such file"
            };
            eprintln!("{}: not stored: {why}", f.display());
        }
        return Err(CliError(format!(
            "none of the {} path(s) is a file; nothing stored",
            a.files.len()
        )));
    }
    runtime()?.block_on(async {
        let store = open_store(&a.at, Open::Create).await?;
        let mut results = Vec::new();
        let mut failed = Vec::new();
        ingest_paths(&store, &a.files, |f, stored| {
            let out = match stored.map_err(|e| e.to_string()) {
                Ok(out) => out,
                Err(e) => {
                    // The reader's errors already start with the file's name.
                    let name = format!("{}: ", f.display());
                    let e = e.strip_prefix(&name).map(str::to_owned).unwrap_or(e);
                    eprintln!("{}: not stored: {e}", f.display());
                    failed.push(serde_json::json!({
                        "file": f.display().to_string(),
                        "error": e,
                    }));
                    return;
                }
            };
            if !a.json {
                println!(
                    "{}: session {} ({}), {} skill(s)",
                    f.display(),
                    out.session_id,
                    if out.created {
                        "stored"
                    } else {
                        "already stored"
                    },
                    out.skill_ids.len()
                );
            }
            results.push(serde_json::json!({
                "file": f.display().to_string(),
                "session_id": out.session_id,
                "created": out.created,
                "skill_ids": out.skill_ids,
            }));
        })
        .await;
        store.close().await;
        if a.json {
            print_json(&serde_json::json!({ "sessions": results, "failed": failed }))?;
        }
        if failed.is_empty() {
            Ok(())
        } else {
            Err(CliError(format!(
                "{} of {} file(s) not stored (see above)",
                failed.len(),
                a.files.len()
            )))
        }
    })
}

/// Lists skills matching the filters (one page), or the nearest skills to one.
/// Reads only: a `--data` directory without a data base is an error, and nothing is created.
pub fn run_skills(a: SkillsArgs) -> Result<(), CliError> {
    runtime()?.block_on(async {
        let store = open_store(&a.at, Open::Read).await?;
        if let Some(id) = a.similar_to {
            // The same bounds as `GET /skills/{id}/similar?k=`.
            let k = a.filters.limit.unwrap_or(DEFAULT_LIMIT);
            if !(1..=MAX_LIMIT).contains(&k) {
                store.close().await;
                return Err(CliError(format!(
                    "--limit {k} is outside 1..={MAX_LIMIT} (the number of similar skills)"
                )));
            }
            let near = store.nearest_to_skill(id, k as usize)?;
            let items: Vec<_> = near
                .iter()
                .map(|(id, d)| serde_json::json!({ "skill_id": id, "distance": d }))
                .collect();
            store.close().await;
            return print_json(&serde_json::json!({ "similar_to": id, "items": items }));
        }
        let q = a
            .filters
            .to_query()
            .map_err(|e| CliError(format!("--sort: {e}")))?;
        let page = store.query_skills(&q).await?;
        store.close().await;
        if a.json {
            return print_json(&page);
        }
        for s in &page.items {
            println!(
                "skill {:>6}  session {:>5}  {:<8} {:>6.3} kg  μ {:.2}  {} contacts  {:<9} ε {:.4}  segmentation v{}",
                s.id,
                s.session_id,
                s.object_shape,
                s.object_mass,
                s.mu,
                s.contact_count,
                s.grasp_type,
                s.quality,
                s.segmentation_version
            );
        }
        if let Some(c) = &page.next_cursor {
            println!("next page: --cursor {c}");
        }
        Ok(())
    })
}

/// What `icms ingest FILE...` does with its files (`icms bench ingest` times this): each
/// streamed into the store's staging area while hashed and segmented from there,
/// [`INGEST_FILES_IN_FLIGHT`] files analysed at once ahead of the commits, which stay one
/// transaction per session, in the order given. `each` gets every file and its outcome in
/// that order.
pub(super) async fn ingest_paths(
    store: &Store,
    files: &[PathBuf],
    mut each: impl FnMut(&PathBuf, Result<IngestOutcome, IngestError>),
) {
    let named: Vec<(PathBuf, String)> = files
        .iter()
        .map(|f| (f.clone(), f.display().to_string()))
        .collect();
    ingest_files(store, &named, INGEST_FILES_IN_FLIGHT, |i, outcome| {
        each(&files[i], outcome)
    })
    .await;
}

/// Arguments of `icms demo`.
#[derive(Debug, clap::Args)]
pub struct DemoArgs {
    /// Data directory (created if missing).
    #[arg(long, default_value = "icms-data")]
    data: PathBuf,
    /// Seed of every scenario.
    #[arg(long, default_value_t = 0)]
    seed: u64,
}

/// The main job end to end on the embedded default: every built-in scenario is simulated
/// (closed 1 kHz DFS loop) and recorded under `DATA/sessions/`, ingested into the skill data
/// base (segmented into skills, SQLite), and the stored skills are listed. Run again with the
/// same seed it keeps the recordings and stores nothing twice.
pub fn run_demo(a: DemoArgs) -> Result<(), CliError> {
    use dfs_core::scenario::Scenario;
    let dir = a.data.join("sessions");
    std::fs::create_dir_all(&dir).map_err(|e| CliError(format!("{}: {e}", dir.display())))?;
    let mut files = Vec::new();
    for name in Scenario::BUILTINS {
        let scenario = Scenario::builtin(name, a.seed).expect("built-in scenario");
        let out = dir.join(format!("{name}-seed{}.mcap", a.seed));
        // A second run with the same seed keeps the recording (its bytes, so the store sees the
        // same session) instead of simulating it again: a new recording differs in its
        // `started_at` and would be stored twice. Recorded under a temporary name and renamed
        // when complete, so a file under the final name is always whole.
        if out.is_file() {
            println!(
                "kept      {name:<22} (recorded before) -> {}",
                out.display()
            );
        } else {
            let part = out.with_extension("mcap.part");
            let summary = services::session::record_simulation(&scenario, None, &part, |_, _| {})
                .map_err(|e| {
                // What was written of it is of no use: the next run records it anew.
                let _ = std::fs::remove_file(&part);
                CliError(format!("{name}: {e}"))
            })?;
            std::fs::rename(&part, &out)
                .map_err(|e| CliError(format!("{}: {e}", out.display())))?;
            println!(
                "simulated {name:<22} {:>6} ticks -> {}",
                summary.ticks,
                out.display()
            );
        }
        files.push(out);
    }
    run_ingest(IngestArgs {
        files,
        at: DataArgs::in_dir(a.data.clone()),
        json: false,
    })?;
    println!();
    run_skills(SkillsArgs {
        filters: SkillFilters {
            limit: Some(100),
            ..SkillFilters::default()
        },
        similar_to: None,
        at: DataArgs::in_dir(a.data),
        json: false,
    })
}
