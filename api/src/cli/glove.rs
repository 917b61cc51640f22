//! `icms glove --connect URL`: a live glove session from the command line. The simulated
//! operator of a scenario (`--scenario`) or a real glove recording (`--input`) streams its
//! samples to a server's `GET /api/v1/live`, one at a time; the events are printed as they come
//! and a summary at the end.

use std::path::PathBuf;

use serde::Serialize;
use services::live::{AssistMode, AssistSettings, Event, StartMessage};

use super::CliError;
use crate::live_client::{self, ClientOptions};

/// Arguments of `icms glove`.
#[derive(Debug, clap::Args)]
pub struct GloveArgs {
    /// The server's live endpoint, e.g. ws://127.0.0.1:8080/api/v1/live.
    #[arg(long)]
    connect: String,
    /// Stream the simulated operator of this scenario (a built-in name or a scenario file),
    /// glove10.
    #[arg(long, required_unless_present = "input", conflicts_with = "input")]
    scenario: Option<String>,
    /// Seed of the scenario's operator noise.
    #[arg(long, requires = "scenario")]
    seed: Option<u64>,
    /// Simulated seconds of the scenario (default: its script).
    #[arg(long, requires = "scenario")]
    duration: Option<f64>,
    /// Samples per second the simulated glove sends, 60 to 1000 (the DFS steps at 1 kHz
    /// whatever the rate, interpolating between samples).
    #[arg(long, default_value_t = 1000, requires = "scenario",
        value_parser = clap::value_parser!(u32).range(60..=1000))]
    rate: u32,
    /// Stream a real glove recording: CSV or MCAP, as `icms import-glove --input` reads it.
    #[arg(long)]
    input: Option<PathBuf>,
    /// The object of `--input`: a built-in scenario's name (its object), a JSON object like a
    /// scenario's `object`, or a file holding one.
    #[arg(long, requires = "input")]
    object: Option<String>,
    /// Pose of the hand's base for a recording without wrist poses: `x,y,z` (m) or
    /// `x,y,z,roll,pitch,yaw` (rad). Default: identity.
    #[arg(long, requires = "input")]
    base: Option<String>,
    /// The glove model of `--input`: glove10 or a built-in robot hand (the recording's
    /// columns are its DOFs).
    #[arg(long, default_value = "glove10", requires = "input")]
    hand: String,
    /// The operator's calibration (a JSON file as `icms import-glove --calibration` takes),
    /// sent in the `start` message: the server applies it to every sample.
    #[arg(long)]
    calibration: Option<PathBuf>,
    /// Whole-hand contact: the palm and phalanges of a hand with contact shapes touch the
    /// objects too (sent as the `start` message's `whole_hand`). Default: the fingertips alone.
    /// With `--scenario`, the scenario's own grasp decides (a power grasp wraps the hand).
    #[arg(long)]
    whole_hand: bool,
    /// The assistant: off, suggest or apply.
    #[arg(long, value_enum, default_value_t = Assist::Off)]
    assist: Assist,
    /// The robot hand the assistant applies skills on (`--assist apply`).
    #[arg(long)]
    robot: Option<String>,
    /// Send each sample at its time instead of as fast as the server answers.
    #[arg(long)]
    realtime: bool,
    /// Print one JSON object per line: each event (`type`: started, error, stale, resumed,
    /// ended, stored), then a `summary`.
    #[arg(long)]
    json: bool,
    /// Bearer token for a server that needs one.
    #[arg(long, env = "ICMS_TOKEN", hide_env_values = true)]
    token: Option<String>,
}

/// `--assist`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
enum Assist {
    Off,
    Suggest,
    Apply,
}

/// Runs `icms glove`.
pub fn run_glove(a: GloveArgs) -> Result<(), CliError> {
    let (start, frames) = match (&a.scenario, &a.input) {
        (Some(name), _) => {
            let scenario = super::simulate::load_scenario(name, a.seed)?;
            let every = (1000 / a.rate).max(1) as u64;
            let glove = live_client::simulated_glove(&scenario, a.duration, every)
                .map_err(|e| CliError(e.0))?;
            let start = StartMessage {
                hand: "glove10".to_owned(),
                object: scenario.object.clone(),
                objects: scenario.objects.clone(),
                target: scenario.target.clone(),
                name: Some(scenario.name.clone()),
                wrist: None,
                assist: AssistSettings::default(),
                calibration: None,
                whole_hand: a.whole_hand || glove.whole_hand,
            };
            (start, glove.frames)
        }
        (None, Some(path)) => {
            let object = a.object.as_deref().ok_or_else(|| {
                CliError("--input needs --object (the object the recording grasps)".into())
            })?;
            let object = super::sessions::load_object(object)?;
            let hand = dfs_core::hand::builtin_hand(&a.hand)
                .map_err(|e| CliError(format!("--hand {:?}: {e}", a.hand)))?;
            let recording = services::session::import::read_glove_file(path, &hand)?;
            let base = match &a.base {
                Some(b) => super::sessions::parse_base(b)?,
                None => dfs_core::math::Isometry::identity(),
            };
            let t = base.translation.vector;
            let r = base.rotation;
            let start = StartMessage {
                hand: a.hand.clone(),
                object: Some(object),
                objects: None,
                target: None,
                name: path.file_name().map(|n| n.to_string_lossy().into_owned()),
                wrist: Some([t.x, t.y, t.z, r.i, r.j, r.k, r.w]),
                assist: AssistSettings::default(),
                calibration: None,
                whole_hand: a.whole_hand,
            };
            (start, live_client::recording_frames(&recording))
        }
        (None, None) => unreachable!("clap requires --scenario or --input"),
    };
    let mut start = start;
    if let Some(path) = &a.calibration {
        let hand = dfs_core::hand::builtin_hand(&start.hand)
            .map_err(|e| CliError(format!("--hand {:?}: {e}", start.hand)))?;
        start.calibration = Some(super::sessions::load_calibration(path, &hand)?);
    }
    start.assist = AssistSettings {
        mode: match a.assist {
            Assist::Off => AssistMode::Off,
            Assist::Suggest => AssistMode::Suggest,
            Assist::Apply => AssistMode::Apply,
        },
        robot: a.robot.clone(),
    };
    let options = ClientOptions {
        token: a.token.clone(),
        realtime: a.realtime,
    };
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .map_err(|e| CliError(format!("starting the async runtime: {e}")))?;
    let json = a.json;
    let summary = rt
        .block_on(live_client::run(
            &a.connect,
            &start,
            frames,
            &options,
            |event| print_event(event, json),
        ))
        .map_err(|e| CliError(e.0))?;
    if json {
        print_line(&summary);
    } else {
        println!(
            "{} samples sent, {} answered, {} refused; round trip p50 {:.0} µs, p99 {:.0} µs, \
             max {:.0} µs; first contact at {}; session {} with {} skill(s){}",
            summary.samples_sent,
            summary.feedback_received,
            summary.refused,
            summary.p50_us,
            summary.p99_us,
            summary.max_us,
            summary
                .first_contact_ns
                .map_or("none".to_owned(), |t| format!("{:.3} s", t as f64 * 1e-9)),
            summary
                .session_id
                .map_or("not stored".to_owned(), |id| id.to_string()),
            summary.skill_ids.len(),
            if summary.incomplete == Some(true) {
                " (incomplete)"
            } else {
                ""
            },
        );
    }
    if summary.session_id.is_none() {
        return Err(CliError("the session was not stored".into()));
    }
    Ok(())
}

/// One JSON object on a line of its own.
fn print_line<T: Serialize>(v: &T) {
    if let Ok(text) = serde_json::to_string(v) {
        println!("{text}");
    }
}

fn print_event(event: &Event, json: bool) {
    if json {
        print_line(event);
        return;
    }
    match event {
        Event::Started { hand, dofs, .. } => {
            println!("started: {hand}, {} DOFs", dofs.len())
        }
        Event::Error { t_ns, message } => match t_ns {
            Some(t) => println!("error (sample t_ns {t}): {message}"),
            None => println!("error: {message}"),
        },
        Event::Stale { session_ns } => println!(
            "stale at {:.3} s: feedback at zero force",
            *session_ns as f64 * 1e-9
        ),
        Event::Resumed { session_ns } => {
            println!("resumed at {:.3} s", *session_ns as f64 * 1e-9)
        }
        Event::Ended {
            reason,
            samples,
            refused,
            session_ns,
        } => println!(
            "ended ({}): {samples} samples, {refused} refused, {:.3} s of session",
            reason.name(),
            *session_ns as f64 * 1e-9
        ),
        Event::Stored {
            session_id,
            skills,
            incomplete,
            ..
        } => println!(
            "stored: session {session_id}{}, skills {:?}",
            if *incomplete { " (incomplete)" } else { "" },
            skills.iter().map(|s| s.skill_id).collect::<Vec<_>>()
        ),
    }
}
