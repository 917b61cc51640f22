//! `icms salvage`, `icms import-glove` and `icms export-glove`: recovering a session file whose
//! writer died, turning a real glove recording into a session, and a session's glove samples
//! back into a glove recording (CSV).

use super::replay::Origin;
use super::{print_json, CliError};
use dfs_core::calibration::Calibration;
use dfs_core::contact::ContactModel;
use dfs_core::hand::HandModel;
use dfs_core::math::{Isometry, Rotation, Vector};
use dfs_core::scenario::{Scenario, ScenarioObject};
use serde_json::json;
use services::mcap_io::salvage;
use services::session::export::export_glove_csv;
use services::session::import::{read_glove_file_with, replay_glove, ImportOptions, WristInput};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Arguments of `icms salvage`.
#[derive(Debug, clap::Args)]
pub struct SalvageArgs {
    /// The damaged MCAP file (e.g. its writer died: no footer, a partial last chunk).
    input: PathBuf,
    /// Where to write the recovered, finished MCAP file (must not be the input).
    #[arg(long)]
    out: PathBuf,
    /// Print the report as JSON.
    #[arg(long)]
    json: bool,
}

/// Salvages a file and reports what was recovered.
pub fn run_salvage(a: SalvageArgs) -> Result<(), CliError> {
    let r =
        salvage(&a.input, &a.out).map_err(|e| CliError(format!("{}: {e}", a.input.display())))?;
    let report = json!({
        "input": a.input,
        "out": a.out,
        "messages": r.messages,
        "chunks": r.chunks,
        "schemas": r.schemas,
        "channels": r.channels,
        "metadata_records": r.metadata_records,
        "last_log_time_ns": r.last_log_time_ns,
        "dropped_bytes": r.dropped_bytes,
        "input_was_complete": r.input_was_complete,
        "stop_reason": r.stop_reason,
    });
    if a.json {
        return print_json(&report);
    }
    println!(
        "{} → {}: recovered {} messages from {} complete chunks (up to {}), {} metadata records; dropped {} bytes{}",
        a.input.display(),
        a.out.display(),
        r.messages,
        r.chunks,
        r.last_log_time_ns
            .map(|t| format!("{:.3} s", t as f64 * 1e-9))
            .unwrap_or_else(|| "no message".into()),
        r.metadata_records,
        r.dropped_bytes,
        match (&r.stop_reason, r.input_was_complete) {
            (_, true) => " (the input was complete)".to_owned(),
            (Some(reason), false) => format!(" ({reason})"),
            (None, false) => String::new(),
        }
    );
    Ok(())
}

/// Arguments of `icms import-glove`.
#[derive(Debug, clap::Args)]
pub struct ImportArgs {
    /// The glove recording. A CSV file: `time_s`, a column per DOF of the hand (its angle),
    /// `tau_<DOF>` for every DOF or for none (a glove that measures positions only), and the
    /// wrist pose `wrist_x,wrist_y,wrist_z` (m, world) with `wrist_qx,wrist_qy,wrist_qz,wrist_qw`
    /// (quaternion) or none of them. Or an MCAP file: `foxglove.JointStates` (positions, and
    /// efforts for every joint or for none) and the wrist from a `foxglove.PoseInFrame` topic or
    /// a `foxglove.FrameTransforms` topic (`/tf`) holding the hand's base link (see
    /// --wrist-topic). Format: the `services::session::import` docs; `icms export-glove`
    /// writes it.
    #[arg(long)]
    input: PathBuf,
    /// The object: a built-in scenario's name (its object), a JSON object like a scenario
    /// file's `object` (`{"shape": "sphere", "radius": 0.04, "mass": 1.0, "mu": 0.8}`), or a
    /// file holding one.
    #[arg(long)]
    object: String,
    /// The glove's hand model, whose DOF names the recording's columns or joints are: a
    /// built-in hand (see `icms hands`), a hand spec file (JSON), or the name of a hand
    /// uploaded to the data base in --data.
    #[arg(long, default_value = "glove10")]
    hand: String,
    /// Data directory of the skill data base, for an uploaded --hand.
    #[arg(long, default_value = "icms-data")]
    data: PathBuf,
    /// Per-operator calibration, a JSON file `{"offsets": {"<DOF>": rad, ...}, "scales":
    /// {"<DOF>": factor, ...}}`: each angle becomes `scale * raw + offset` (DOFs left out are
    /// unchanged; unknown DOF names, non-finite numbers and zero scales are refused).
    #[arg(long)]
    calibration: Option<PathBuf>,
    /// MCAP input: the topic holding the wrist pose (`foxglove.PoseInFrame`, or
    /// `foxglove.FrameTransforms` with the hand's base link as a child frame), or `none` to
    /// ignore wrist input. Default: the one PoseInFrame topic, else the FrameTransforms topic
    /// (`/tf`) holding the base link, else none (fixed base).
    #[arg(long)]
    wrist_topic: Option<String>,
    /// Fixed pose of the hand base in the world, for a recording without wrist poses: `x,y,z`
    /// (m) or `x,y,z,roll,pitch,yaw` (rad). Default: identity.
    #[arg(long)]
    base: Option<String>,
    /// Contact model of the fingertips: `soft_finger` (pads, as in simulated sessions),
    /// `point_with_friction` or `frictionless`.
    #[arg(long, default_value = "soft_finger")]
    contact_model: ContactModel,
    /// Whole-hand contact: the palm and phalanges of a hand with contact shapes (glove10 has
    /// them) touch the objects too, as in a simulated power grasp. Default: the fingertips
    /// alone, as in every other simulated session.
    #[arg(long)]
    whole_hand: bool,
    /// The session file to write. Default: the input's name with `.session.mcap`.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Print the summary as JSON.
    #[arg(long)]
    json: bool,
}

/// Arguments of `icms export-glove`.
#[derive(Debug, clap::Args)]
pub struct ExportArgs {
    /// The session file (MCAP) whose glove samples to export.
    session: PathBuf,
    /// The CSV file to write, in the format `icms import-glove` reads: `time_s`, each DOF's
    /// angle, `tau_<DOF>`, and the wrist pose `wrist_x` … `wrist_qw` (the hand base's recorded
    /// pose), one line per tick. Import it with the session's hand and object (the last line,
    /// a comment, names both) to replay the same samples.
    #[arg(long)]
    out: PathBuf,
    /// Print the summary as JSON.
    #[arg(long)]
    json: bool,
}

/// Exports a session's glove samples to CSV.
pub fn run_export(a: ExportArgs) -> Result<(), CliError> {
    super::refuse_out_over_inputs(&a.out, &[("the session file", a.session.as_path())])?;
    let summary = export_glove_csv(&a.session, &a.out).map_err(|e| {
        let (msg, input) = (e.to_string(), a.session.display().to_string());
        CliError(if msg.contains(&input) {
            msg
        } else {
            format!("{input}: {msg}")
        })
    })?;
    if a.json {
        return print_json(&json!({
            "session": a.session,
            "out": a.out,
            "rows": summary.rows,
            "dofs": summary.dofs,
            "duration_s": summary.duration_s,
            "file_bytes": summary.file_bytes,
            "hand": summary.hand,
            "object": summary
                .object_json
                .as_deref()
                .and_then(|o| serde_json::from_str::<serde_json::Value>(o).ok()),
            "whole_hand": summary.whole_hand,
        }));
    }
    println!(
        "{} → {}: {} samples of {} DOFs over {:.3} s ({} bytes)",
        a.session.display(),
        a.out.display(),
        summary.rows,
        summary.dofs.len(),
        summary.duration_s,
        summary.file_bytes
    );
    if let (Some(hand), Some(object)) = (&summary.hand, &summary.object_json) {
        println!(
            "import it with: icms import-glove --input {} --hand {hand} --object '{object}'{}",
            a.out.display(),
            if summary.whole_hand {
                " --whole-hand"
            } else {
                ""
            }
        );
    }
    Ok(())
}

/// The object of `--object`.
pub(crate) fn load_object(spec: &str) -> Result<ScenarioObject, CliError> {
    if let Some(o) = Scenario::builtin(spec, 0).and_then(|s| s.target_object().cloned()) {
        return Ok(o);
    }
    let (text, origin) = if spec.trim_start().starts_with('{') {
        (spec.to_owned(), "--object".to_owned())
    } else {
        let path = Path::new(spec);
        if !path.exists() {
            return Err(CliError(format!(
                "--object {spec:?} is neither a built-in scenario ({}), nor JSON, nor a file",
                Scenario::BUILTINS.join(", ")
            )));
        }
        (
            std::fs::read_to_string(path)
                .map_err(|e| CliError(format!("{}: {e}", path.display())))?,
            path.display().to_string(),
        )
    };
    let object: ScenarioObject =
        super::parse_json(&text).map_err(|e| CliError(format!("{origin}: invalid object: {e}")))?;
    Ok(object)
}

/// Parses `--base`.
pub(crate) fn parse_base(spec: &str) -> Result<Isometry, CliError> {
    let values: Result<Vec<f64>, _> = spec.split(',').map(|v| v.trim().parse::<f64>()).collect();
    let bad = || {
        CliError(format!(
            "--base {spec:?}: expected x,y,z or x,y,z,roll,pitch,yaw (finite numbers)"
        ))
    };
    let v = values.map_err(|_| bad())?;
    if !(v.len() == 3 || v.len() == 6) || v.iter().any(|x| !x.is_finite()) {
        return Err(bad());
    }
    let rotation = if v.len() == 6 {
        Rotation::from_euler_angles(v[3], v[4], v[5])
    } else {
        Rotation::identity()
    };
    Ok(Isometry::from_parts(
        Vector::new(v[0], v[1], v[2]).into(),
        rotation,
    ))
}

/// Reads and checks `--calibration` against the hand.
pub(crate) fn load_calibration(path: &Path, hand: &HandModel) -> Result<Calibration, CliError> {
    let text =
        std::fs::read_to_string(path).map_err(|e| CliError(format!("{}: {e}", path.display())))?;
    let calibration: Calibration = super::parse_json(&text)
        .map_err(|e| CliError(format!("{}: invalid calibration: {e}", path.display())))?;
    calibration
        .validate(hand)
        .map_err(|e| CliError(format!("{}: {e}", path.display())))?;
    Ok(calibration)
}

/// Imports a glove recording into a session.
pub fn run_import(a: ImportArgs) -> Result<(), CliError> {
    let object = load_object(&a.object)?;
    let base = a.base.as_deref().map(parse_base).transpose()?;
    let at = crate::config::DataArgs::in_dir(a.data.clone());
    let (hand, origin) = super::replay::resolve_hand(&a.hand, Some(&at), "--hand")?;
    let calibration = a
        .calibration
        .as_deref()
        .map(|p| load_calibration(p, &hand.model))
        .transpose()?;
    let wrist = match a.wrist_topic.as_deref() {
        None => WristInput::Auto,
        Some("none") => WristInput::Ignore,
        Some(t) => WristInput::Topic(t.to_owned()),
    };
    let out = a
        .out
        .clone()
        .unwrap_or_else(|| default_import_out(&a.input));
    let inputs = import_inputs(&a, hand.spec.as_ref(), origin == Origin::File);
    super::refuse_out_over_inputs(&out, &inputs)?;
    let recording = read_glove_file_with(&a.input, &hand.model, &wrist).map_err(|e| {
        // Errors about the file's content name it already; the MCAP reader's do not.
        let (msg, input) = (e.to_string(), a.input.display().to_string());
        CliError(if msg.contains(&input) {
            msg
        } else {
            format!("{input}: {msg}")
        })
    })?;
    if let (Some(_), Some(w)) = (&base, &recording.wrist) {
        return Err(CliError(format!(
            "{}: --base is the hand base of a recording without wrist poses, and this one has \
             them ({}){}",
            a.input.display(),
            w.source,
            if w.source == "csv" {
                "; leave --base out"
            } else {
                "; leave --base out, or ignore them with --wrist-topic none"
            }
        )));
    }
    let name = a
        .input
        .file_name()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let hand_name = hand.model.name.clone();
    let options = ImportOptions {
        hand: hand.model,
        hand_urdf: hand.urdf,
        base,
        wrist,
        calibration,
        coupling: None,
        torque_coupling: None,
        contact_model: a.contact_model,
        whole_hand: a.whole_hand,
    };
    let start = Instant::now();
    let summary = replay_glove(&recording, &object, &options, &name, &out)
        .map_err(|e| replay_error(&a.input, &out, e))?;
    let elapsed = start.elapsed().as_secs_f64();
    report_import(&a, &out, &hand_name, &recording, &object, &summary, elapsed)
}

/// Where `icms import-glove` writes without `--out`: `STEM.session.mcap` beside the input.
fn default_import_out(input: &Path) -> PathBuf {
    let stem = input
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "glove".into());
    input.with_file_name(format!("{stem}.session.mcap"))
}

/// The files an import reads, which its output must not overwrite: the input, the object's
/// and the calibration's files, and the hand's spec and its URDF when the hand is a file
/// (`hand_from_file`, its spec `spec`).
fn import_inputs(
    a: &ImportArgs,
    spec: Option<&dfs_core::hand::HandSpec>,
    hand_from_file: bool,
) -> Vec<(&'static str, PathBuf)> {
    let mut inputs = vec![("the --input file", a.input.clone())];
    if Scenario::builtin(&a.object, 0).is_none() && !a.object.trim_start().starts_with('{') {
        inputs.push(("the --object file", PathBuf::from(&a.object)));
    }
    if let Some(c) = &a.calibration {
        inputs.push(("the --calibration file", c.clone()));
    }
    if hand_from_file {
        let spec_path = PathBuf::from(&a.hand);
        if let Some(urdf) = spec.map(|s| &s.urdf) {
            let dir = spec_path.parent().unwrap_or(Path::new("."));
            inputs.push(("the URDF of the --hand spec", dir.join(urdf)));
        }
        inputs.push(("the --hand file", spec_path));
    }
    inputs
}

/// The error of a failed replay of `input` into `out` (a DFS failure says how many ticks the
/// file holds).
fn replay_error(input: &Path, out: &Path, e: services::RecordingError) -> CliError {
    match &e {
        services::RecordingError::Simulation { time_ns, .. } => CliError(format!(
            "{}: {e} ({} holds the {} ticks before it)",
            input.display(),
            out.display(),
            time_ns / 1_000_000
        )),
        _ => CliError(format!("{}: {e}", input.display())),
    }
}

/// Prints what an import did (as JSON with `--json`).
fn report_import(
    a: &ImportArgs,
    out: &Path,
    hand_name: &str,
    recording: &services::session::import::GloveRecording,
    object: &ScenarioObject,
    summary: &services::session::RecordSummary,
    elapsed: f64,
) -> Result<(), CliError> {
    let glove_input = if recording.has_torques() {
        "torques"
    } else {
        "positions"
    };
    let wrist_source = recording
        .wrist
        .as_ref()
        .map_or("fixed", |w| w.source.as_str());
    let report = json!({
        "input": a.input,
        "out": out,
        "hand": hand_name,
        "input_samples": recording.len(),
        "glove_input": glove_input,
        "wrist": wrist_source,
        "contact_model": a.contact_model.to_string(),
        "whole_hand": a.whole_hand,
        "ticks": summary.ticks,
        "duration_s": summary.ticks as f64 * 1e-3,
        "messages": summary.write.messages,
        "file_bytes": summary.file_bytes,
        "elapsed_s": elapsed,
    });
    if a.json {
        return print_json(&report);
    }
    println!(
        "{}: {} samples of {hand_name} ({}{}, wrist {}) replayed at 1 kHz as {} ticks against a {} into {} ({} messages, {} bytes)",
        a.input.display(),
        recording.len(),
        glove_input,
        if recording.has_torques() {
            ""
        } else {
            " through the virtual coupling"
        },
        wrist_source,
        summary.ticks,
        object.shape,
        out.display(),
        summary.write.messages,
        summary.file_bytes
    );
    Ok(())
}
