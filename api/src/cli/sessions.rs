//! `icms salvage` and `icms import-glove`: recovering a session file whose writer died, and
//! turning a real glove recording into a session.

use super::{print_json, CliError};
use dfs_core::math::{Isometry, Rotation, Vector};
use dfs_core::scenario::{Scenario, ScenarioObject};
use serde_json::json;
use services::mcap_io::salvage;
use services::session::import::{read_glove_file, replay_glove};
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
    /// The glove recording: an MCAP file with `foxglove.JointStates` (positions and efforts of
    /// every glove10 DOF) or a CSV file `time_s,<DOF>...,tau_<DOF>...` (see the
    /// `services::session::import` docs).
    #[arg(long)]
    input: PathBuf,
    /// The object: a built-in scenario's name (its object), a JSON object like a scenario
    /// file's `object` (`{"shape": "sphere", "radius": 0.04, "mass": 1.0, "mu": 0.8}`), or a
    /// file holding one.
    #[arg(long)]
    object: String,
    /// Fixed pose of the hand base in the world: `x,y,z` (m) or `x,y,z,roll,pitch,yaw`
    /// (rad). Default: identity.
    #[arg(long)]
    base: Option<String>,
    /// The session file to write. Default: the input's name with `.session.mcap`.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Print the summary as JSON.
    #[arg(long)]
    json: bool,
}

/// The object of `--object`.
fn load_object(spec: &str) -> Result<ScenarioObject, CliError> {
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
fn parse_base(spec: &str) -> Result<Isometry, CliError> {
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

/// Imports a glove recording into a session.
pub fn run_import(a: ImportArgs) -> Result<(), CliError> {
    let object = load_object(&a.object)?;
    let base = a
        .base
        .as_deref()
        .map(parse_base)
        .transpose()?
        .unwrap_or_else(Isometry::identity);
    let out = a.out.clone().unwrap_or_else(|| {
        let stem = a
            .input
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "glove".into());
        a.input.with_file_name(format!("{stem}.session.mcap"))
    });
    let mut inputs = vec![("the --input file", a.input.as_path())];
    if Scenario::builtin(&a.object, 0).is_none() && !a.object.trim_start().starts_with('{') {
        inputs.push(("the --object file", Path::new(&a.object)));
    }
    super::refuse_out_over_inputs(&out, &inputs)?;
    let hand = dfs_core::hand::HandModel::glove10();
    let recording = read_glove_file(&a.input, &hand).map_err(|e| {
        // Errors about the file's content name it already; the MCAP reader's do not.
        let (msg, input) = (e.to_string(), a.input.display().to_string());
        CliError(if msg.contains(&input) {
            msg
        } else {
            format!("{input}: {msg}")
        })
    })?;
    let name = a
        .input
        .file_name()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let start = Instant::now();
    let summary = replay_glove(&recording, &object, base, &name, &out).map_err(|e| match &e {
        services::RecordingError::Simulation { time_ns, .. } => CliError(format!(
            "{}: {e} ({} holds the {} ticks before it)",
            a.input.display(),
            out.display(),
            time_ns / 1_000_000
        )),
        _ => CliError(format!("{}: {e}", a.input.display())),
    })?;
    let elapsed = start.elapsed().as_secs_f64();
    let report = json!({
        "input": a.input,
        "out": out,
        "input_samples": recording.len(),
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
        "{}: {} samples replayed at 1 kHz as {} ticks against a {} into {} ({} messages, {} bytes)",
        a.input.display(),
        recording.len(),
        summary.ticks,
        object.shape,
        out.display(),
        summary.write.messages,
        summary.file_bytes
    );
    Ok(())
}
