//! `icms recognise`: the live assistant's recogniser over a recorded session.

use std::path::PathBuf;

use clap::Args;
use services::assist::offline::recognise_source;
use services::assist::recognise::{RecogniserParams, Verdict};
use services::session::SessionSource;

use super::CliError;

/// Arguments of `icms recognise`.
#[derive(Debug, Args)]
pub struct RecogniseArgs {
    /// The session file (MCAP).
    session: PathBuf,
    /// The data base whose stored skills it is compared with.
    #[command(flatten)]
    at: crate::config::DataArgs,
    /// Print JSON: `{"objects", "observations", "first_touch_ns", "verdicts": [...]}`, each
    /// verdict with its session time.
    #[arg(long)]
    json: bool,
}

/// Runs the recogniser over the session and prints its verdicts.
pub fn run_recognise(a: RecogniseArgs) -> Result<(), CliError> {
    let rt = tokio::runtime::Runtime::new()?;
    let store = rt.block_on(super::open_store(&a.at, super::Open::Read))?;
    // A stored hand's model, if the session names one that is not built in.
    let run = recognise_source(
        &SessionSource::File(&a.session),
        store.recognition_index(),
        None,
        &RecogniserParams::default(),
    )
    .map_err(|e| CliError(format!("{}: {e}", a.session.display())))?;
    if a.json {
        println!("{}", serde_json::to_string_pretty(&run)?);
        return Ok(());
    }
    println!(
        "{} stored skills; {} observations of {}",
        store.recognition_index().len(),
        run.observations,
        a.session.display()
    );
    for (name, t) in &run.first_touch_ns {
        println!("first touch of {name} at {:.3} s", *t as f64 * 1e-9);
    }
    for v in &run.verdicts {
        let t = v.session_ns() as f64 * 1e-9;
        match v {
            Verdict::Recognised {
                stage,
                object,
                skill,
                ..
            } => println!(
                "{t:8.3} s  {stage:?}: recognised skill {} ({}) on {object}, confidence {:.2}",
                skill.skill_id, skill.kind, skill.confidence
            ),
            Verdict::Unknown { stage, object, .. } => {
                println!("{t:8.3} s  {stage:?}: unknown grasp of {object} (would be learned)")
            }
        }
    }
    Ok(())
}
