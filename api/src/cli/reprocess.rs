//! `icms reprocess`: the stored sessions whose skills an older segmentation made are segmented
//! again (see `services::reprocess`).

use super::{print_json, CliError};
use services::reprocess::{reprocess, ReprocessEvent, ReprocessReport};
use services::store::ReplacedSkills;
use std::io::{IsTerminal, Write};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

/// Arguments of `icms reprocess`.
#[derive(Debug, clap::Args)]
pub struct ReprocessArgs {
    /// The data base to reprocess. An SQLite data directory must hold one: nothing is
    /// created.
    #[command(flatten)]
    at: crate::config::DataArgs,
    /// Print the summary as JSON (and no progress).
    #[arg(long)]
    json: bool,
}

/// A progress line on stderr, only when stderr is a terminal.
struct Progress {
    enabled: bool,
    shown: bool,
}

impl Progress {
    fn update(&mut self, done: usize, total: usize, session_id: i64) {
        if !self.enabled {
            return;
        }
        self.shown = true;
        let mut err = std::io::stderr().lock();
        let _ = write!(
            err,
            "\r\x1b[2Kreprocessing: {done}/{total} sessions (session {session_id})"
        );
        let _ = err.flush();
    }

    /// Clears the line before anything else is printed.
    fn clear(&mut self) {
        if self.shown {
            self.shown = false;
            let mut err = std::io::stderr().lock();
            let _ = write!(err, "\r\x1b[2K");
            let _ = err.flush();
        }
    }
}

fn describe(r: &ReplacedSkills) -> String {
    let mut parts = vec![format!("{} kept", r.kept_skill_ids.len())];
    if !r.removed_skill_ids.is_empty() {
        parts.push(format!(
            "{} removed {:?}{}",
            r.removed_skill_ids.len(),
            r.removed_skill_ids,
            match r.replays_removed {
                0 => String::new(),
                n => format!(" with {n} replay(s)"),
            }
        ));
    }
    if !r.added_skill_ids.is_empty() {
        parts.push(format!(
            "{} added {:?}",
            r.added_skill_ids.len(),
            r.added_skill_ids
        ));
    }
    format!(
        "session {}: segmentation version {} → {}: skills {} → {} ({})",
        r.session_id,
        r.from_version,
        r.to_version,
        r.kept_skill_ids.len() + r.removed_skill_ids.len(),
        r.kept_skill_ids.len() + r.added_skill_ids.len(),
        parts.join(", ")
    )
}

fn summary(r: &ReprocessReport) -> Vec<String> {
    let v = r.segmentation_version;
    let mut lines = Vec::new();
    if r.sessions_stale == 0 {
        lines.push(format!(
            "nothing to reprocess: no session was segmented before version {v}"
        ));
    } else {
        lines.push(format!(
            "reprocessed {} of {} session(s) segmented before version {v}: skills {} → {} \
             ({} kept, {} removed, {} added), {} replay(s) removed with their skills",
            r.sessions_reprocessed,
            r.sessions_stale,
            r.skills_before,
            r.skills_after,
            r.skills_kept,
            r.skills_removed,
            r.skills_added,
            r.replays_removed
        ));
    }
    if r.sessions_skipped > 0 {
        lines.push(format!(
            "{} session(s) deleted or reprocessed by another process meanwhile",
            r.sessions_skipped
        ));
    }
    if r.sessions_newer > 0 {
        lines.push(format!(
            "{} session(s) segmented by a version newer than {v} (a newer icms): left alone",
            r.sessions_newer
        ));
    }
    lines
}

/// Reprocesses the data base in `--data`; see the `Reprocess` subcommand's help.
pub fn run_reprocess(a: ReprocessArgs) -> Result<(), CliError> {
    super::skills::runtime()?.block_on(async {
        let store = super::open_store(&a.at, super::Open::Write).await?;
        // SIGINT or SIGTERM: finish the session in hand, then stop; a second one stops at
        // once (the session's transaction is rolled back, nothing is lost either way).
        let stop = Arc::new(AtomicBool::new(false));
        let tty = std::io::stderr().is_terminal();
        let watcher = {
            let stop = stop.clone();
            tokio::spawn(async move {
                crate::startup::shutdown_signal().await;
                stop.store(true, Ordering::Relaxed);
                eprintln!(
                    "{}stopping after the current session (signal again to stop at once; \
                     nothing is lost either way)",
                    if tty { "\r\x1b[2K" } else { "" }
                );
                crate::startup::shutdown_signal().await;
                eprintln!("stopped: the session in hand is left as it was");
                std::process::exit(130);
            })
        };
        let mut progress = Progress {
            enabled: !a.json && tty,
            shown: false,
        };
        let json = a.json;
        let result = reprocess(&store, &stop, |event| match event {
            ReprocessEvent::Started {
                index,
                total,
                session,
            } => progress.update(index, total, session.id),
            ReprocessEvent::Reprocessed(r) => {
                if !json {
                    progress.clear();
                    println!("{}", describe(r));
                }
            }
            ReprocessEvent::Skipped(s) => {
                if !json {
                    progress.clear();
                    println!(
                        "session {}: skipped (deleted or reprocessed by another process \
                         meanwhile)",
                        s.id
                    );
                }
            }
            ReprocessEvent::Failed(f) => {
                progress.clear();
                eprintln!("session {}: not reprocessed: {}", f.session_id, f.error);
            }
        })
        .await;
        progress.clear();
        watcher.abort();
        store.close().await;
        let report = result.map_err(|e| CliError(format!("{}: {e}", a.at.data.display())))?;
        if a.json {
            print_json(&report)?;
        } else {
            for line in summary(&report) {
                println!("{line}");
            }
        }
        if report.sessions_failed > 0 {
            return Err(CliError(format!(
                "{} of {} session(s) not reprocessed (see above); they keep their skills and \
                 version, and the next run tries them again",
                report.sessions_failed, report.sessions_stale
            )));
        }
        if report.interrupted {
            return Err(CliError(format!(
                "stopped: {} session(s) left for the next run",
                report.sessions_left
            )));
        }
        Ok(())
    })
}
