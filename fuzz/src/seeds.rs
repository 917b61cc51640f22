//! Seed inputs, made at start-up from what the project itself writes: simulated sessions
//! (zstd as recorded, and recompressed lz4 and uncompressed, without chunks, truncated,
//! salvaged), the built-in hands (URDFs read from the hands directory, `dfs-core/hands`), scenarios and
//! the paper's grasp serialised, and the skills segmentation finds in a simulated session.
//!
//! Everything is deterministic: a session's `started_at` (the only wall-clock value the
//! recorder writes) is replaced with a fixed time, so every worker process and every
//! `--only` reproduction sees the same seeds.

use std::path::{Path, PathBuf};

use dfs_core::hand::builtin_spec;
use dfs_core::scenario::Scenario;
use dfs_core::spec::GraspSpec;
use serde_json::{json, Value};

use crate::mcap::McapFile;

/// The fixed `started_at` of seed sessions.
pub const STARTED_AT: &str = "2026-01-01T00:00:00.000Z";

/// Built-in URDF hands (glove10 is built in code and has no URDF).
pub const URDF_HANDS: [&str; 4] = ["allegro", "barrett", "inspire", "gripper"];

/// Why seeds could not be made.
#[derive(Debug, thiserror::Error)]
#[error("making seeds: {0}")]
pub struct SeedError(pub String);

fn err(what: &str, e: impl std::fmt::Display) -> SeedError {
    SeedError(format!("{what}: {e}"))
}

/// Records `scenario` for `duration` seconds (the script's length when `None`) and returns
/// the file with its `started_at` fixed.
pub fn record(
    name: &str,
    seed: u64,
    duration: Option<f64>,
    dir: &Path,
) -> Result<Vec<u8>, SeedError> {
    let scenario = Scenario::builtin(name, seed).ok_or_else(|| err(name, "no such scenario"))?;
    let path = dir.join(format!("{name}-{seed}-{duration:?}.mcap"));
    services::session::record_simulation(&scenario, duration, &path, |_, _| {})
        .map_err(|e| err("recording a session", e))?;
    let bytes = std::fs::read(&path).map_err(|e| err("reading a session", e))?;
    let _ = std::fs::remove_file(&path);
    normalise(&bytes)
}

/// The session with its `started_at` set to [`STARTED_AT`].
pub fn normalise(bytes: &[u8]) -> Result<Vec<u8>, SeedError> {
    let mut f = McapFile::parse(bytes).ok_or_else(|| err("parsing a session", "not MCAP"))?;
    f.set_metadata("session", "started_at", STARTED_AT);
    Ok(f.write())
}

/// Session seeds: short recordings in every layout the reader accepts, a truncated one and
/// its salvage.
pub fn sessions(dir: &Path) -> Result<Vec<Vec<u8>>, SeedError> {
    let a = record("sphere-lift", 1, Some(0.05), dir)?;
    let b = record("box-pinch-lift", 2, Some(0.08), dir)?;
    let c = record("cylinder-power-grasp", 3, Some(0.05), dir)?;
    let fb = McapFile::parse(&b).ok_or_else(|| err("parsing a session", "not MCAP"))?;
    let fc = McapFile::parse(&c).ok_or_else(|| err("parsing a session", "not MCAP"))?;
    let fa = McapFile::parse(&a).ok_or_else(|| err("parsing a session", "not MCAP"))?;
    let lz4 = fb.recompressed("lz4").write();
    let plain = fc.recompressed("").write();
    let loose = fa.unchunked().write();
    let truncated = a[..a.len() * 2 / 3].to_vec();
    let cut = dir.join("truncated.mcap");
    let salvaged_path = dir.join("salvaged.mcap");
    std::fs::write(&cut, &truncated).map_err(|e| err("writing a seed", e))?;
    let v1 = format_1(&a, dir)?;
    let mut out = vec![a, b, c, lz4, plain, loose, truncated, v1];
    if services::mcap_io::salvage(&cut, &salvaged_path).is_ok() {
        if let Ok(s) = std::fs::read(&salvaged_path) {
            out.push(normalise(&s).unwrap_or(s));
        }
    }
    let _ = std::fs::remove_file(&cut);
    let _ = std::fs::remove_file(&salvaged_path);
    Ok(out)
}

/// `session` (format 2) written again in session format 1, JSON on every raw topic, as files
/// recorded before 2026-11-25 are: the JSON reader stays fuzzed. Its metadata records are
/// copied; the Foxglove topics, optional to the reader, are left out.
fn format_1(session: &[u8], dir: &Path) -> Result<Vec<u8>, SeedError> {
    use services::session::*;
    let limits = services::mcap_io::ReadLimits::default();
    let s = read_session_bytes(session, "seed", &limits).map_err(|e| err("reading a seed", e))?;
    let raw = services::mcap_io::read_session_bytes(session, &limits)
        .map_err(|e| err("reading a seed", e))?;
    let path = dir.join("format-1.mcap");
    let mut w = services::mcap_io::SessionWriter::create(&path).map_err(|e| err("writing", e))?;
    let failed = |e: services::RecordingError| err("writing a format 1 seed", e);
    for m in &raw.metadata {
        let mut entries = m.entries.clone();
        entries.remove("format_version");
        w.add_metadata(&m.name, entries).map_err(failed)?;
    }
    for (topic, schema) in RAW_TOPICS.iter().zip(ICMS_SCHEMAS.iter()) {
        w.register_channel(topic, schema).map_err(failed)?;
    }
    for k in 0..s.ticks() {
        let t = s.joint_states[k].0;
        w.write(TOPIC_GLOVE_JOINT_STATES, t, &s.joint_states[k].1)
            .map_err(failed)?;
        w.write(TOPIC_GLOVE_FEEDBACK, t, &s.feedback[k].1)
            .map_err(failed)?;
        w.write(TOPIC_CONTACTS, t, &s.contacts[k].1)
            .map_err(failed)?;
        w.write(TOPIC_OBJECT_STATE, t, &s.object[k].1)
            .map_err(failed)?;
    }
    w.finish().map_err(failed)?;
    let bytes = std::fs::read(&path).map_err(|e| err("reading a seed", e))?;
    let _ = std::fs::remove_file(&path);
    // It reads as a session, in format 1.
    let back = read_session_bytes(&bytes, "format 1 seed", &limits)
        .map_err(|e| err("reading the format 1 seed", e))?;
    if back.metadata.contains_key("format_version") || back.ticks() != s.ticks() {
        return Err(err("the format 1 seed", "does not read back as format 1"));
    }
    Ok(bytes)
}

/// A whole simulated session with grasps (for skills and for the HTTP target's store).
pub fn full_session(dir: &Path) -> Result<Vec<u8>, SeedError> {
    record("sphere-lift", 5, None, dir)
}

/// The skills segmentation finds in `session` (as `icms segment --json` prints them).
pub fn skills(session: &[u8]) -> Result<Vec<Value>, SeedError> {
    let s = services::session::read_session_bytes(
        session,
        "seed",
        &services::mcap_io::ReadLimits::default(),
    )
    .map_err(|e| err("reading the seed session", e))?;
    let seg = services::segmentation::segment(&s, &Default::default());
    let out: Vec<Value> = seg
        .skills
        .iter()
        .filter_map(|k| serde_json::to_value(k).ok())
        .collect();
    if out.is_empty() {
        return Err(err("segmenting the seed session", "no skills"));
    }
    Ok(out)
}

/// A hand's spec JSON and URDF text.
#[derive(Debug, Clone)]
pub struct HandSeed {
    /// Built-in hand name.
    pub name: String,
    /// Spec as JSON.
    pub spec: Value,
    /// URDF text.
    pub urdf: String,
}

/// URDF files under `dir` (recursively).
fn urdf_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let Ok(rd) = std::fs::read_dir(dir) else {
        return;
    };
    let mut entries: Vec<PathBuf> = rd.filter_map(|e| e.ok().map(|e| e.path())).collect();
    entries.sort();
    for p in entries {
        if p.is_dir() {
            urdf_files(&p, out);
        } else if p.extension().is_some_and(|e| e == "urdf") {
            out.push(p);
        }
    }
}

/// The built-in URDF hands' specs, each with its URDF read from `hands_dir` when a file of
/// the spec's `urdf` name is there (`dfs-core/hands` by default), else the embedded text.
pub fn hands(hands_dir: &Path) -> Result<Vec<HandSeed>, SeedError> {
    let mut files = Vec::new();
    urdf_files(hands_dir, &mut files);
    let mut out = Vec::new();
    for name in URDF_HANDS {
        let (spec, embedded) = builtin_spec(name).ok_or_else(|| err(name, "no spec"))?;
        let from_file = files
            .iter()
            .find(|p| {
                p.file_name()
                    .is_some_and(|f| f.to_string_lossy() == spec.urdf)
            })
            .and_then(|p| std::fs::read_to_string(p).ok());
        out.push(HandSeed {
            name: name.to_owned(),
            spec: serde_json::to_value(&spec).map_err(|e| err("serialising a spec", e))?,
            urdf: from_file.unwrap_or_else(|| embedded.to_owned()),
        });
    }
    Ok(out)
}

/// The built-in scenarios, serialised.
pub fn scenarios() -> Vec<Value> {
    Scenario::BUILTINS
        .iter()
        .enumerate()
        .filter_map(|(i, n)| Scenario::builtin(n, i as u64))
        .filter_map(|s| serde_json::to_value(&s).ok())
        .collect()
}

/// The paper's sphere grasp and variants of it (other contact models).
pub fn grasps() -> Vec<Value> {
    let base = serde_json::to_value(GraspSpec::paper_sphere()).unwrap_or(Value::Null);
    let mut soft = base.clone();
    soft["contact_model"] = json!("soft_finger");
    soft["mu_torsion"] = json!(0.01);
    let mut frictionless = base.clone();
    frictionless["contact_model"] = json!("frictionless");
    if let Some(o) = frictionless.as_object_mut() {
        o.remove("mu");
    }
    let mut accel = base.clone();
    accel["object_acceleration"] = json!([0.1, 0.0, 0.5, 0.0, 0.2, 0.0]);
    vec![base, soft, frictionless, accel]
}

#[cfg(test)]
mod tests {
    #[test]
    fn seed_sessions_are_the_same_every_time() {
        let dir = tempfile::tempdir().unwrap();
        let a = super::record("box-pinch-lift", 2, Some(0.05), dir.path()).unwrap();
        let b = super::record("box-pinch-lift", 2, Some(0.05), dir.path()).unwrap();
        assert_eq!(a, b, "an --only reproduction must see the campaign's seeds");
    }
}
