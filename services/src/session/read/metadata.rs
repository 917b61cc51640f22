//! The checks of a session's metadata records: their number and sizes ([`check_metadata`]) and
//! the object or objects the `session` record describes ([`check_session_object`]).

use std::collections::BTreeMap;

use crate::error::{RecordingError, Result};
use crate::mcap_io::MetadataRecord;
use crate::replay::REPLAY_METADATA;
use crate::session::*;

/// The `session` metadata's `object` (when there is one, not empty) must describe a real object: a known
/// shape with positive finite sizes and mass, μ and torsional μ finite and ≥ 0. Skills carry
/// it into the store's filters and onto robot hands, so an impossible one is refused here, at
/// the boundary, naming the field.
pub(super) fn check_session_object(metadata: &BTreeMap<String, String>, name: &str) -> Result<()> {
    let Some(text) = metadata.get("object").filter(|t| !t.trim().is_empty()) else {
        return check_session_objects(metadata, name);
    };
    let invalid = |detail: String| RecordingError::InvalidInput {
        location: format!("{name}: metadata session.object"),
        detail,
    };
    // With the path of a field that does not parse (`object.shape: unknown shape ...`).
    let mut de = serde_json::Deserializer::from_str(text);
    let o: dfs_core::scenario::ScenarioObject =
        serde_path_to_error::deserialize(&mut de).map_err(|e| {
            match e.path().to_string().as_str() {
                "." => invalid(e.inner().to_string()),
                path => invalid(format!("object.{path}: {}", e.inner())),
            }
        })?;
    de.end().map_err(|e| invalid(e.to_string()))?;
    o.to_object().map_err(|e| invalid(e.to_string()))?;
    check_session_objects(metadata, name)
}

/// The `objects` and `target` of a session's `session` metadata record (a scene of several
/// objects), if it has them: a JSON list of 1 to 8 objects as a scenario file's, each named
/// (1 to 64 characters, unique) and a valid object, and the name of one of them. Errors name
/// the field.
fn check_session_objects(metadata: &BTreeMap<String, String>, name: &str) -> Result<()> {
    use dfs_core::scenario::{ScenarioObject, MAX_OBJECTS, MAX_OBJECT_NAME_CHARS};
    let invalid = |field: String, detail: String| RecordingError::InvalidInput {
        location: format!("{name}: metadata session.{field}"),
        detail,
    };
    let (objects, target) = match (metadata.get("objects"), metadata.get("target")) {
        (None, None) => return Ok(()),
        (Some(o), Some(t)) => (o, t),
        (None, Some(_)) => {
            return Err(invalid(
                "objects".into(),
                "missing: `target` names one of the scene's `objects`".into(),
            ))
        }
        (Some(_), None) => {
            return Err(invalid(
                "target".into(),
                "missing: which of the `objects` is grasped".into(),
            ))
        }
    };
    let mut de = serde_json::Deserializer::from_str(objects);
    let list: Vec<ScenarioObject> = serde_path_to_error::deserialize(&mut de).map_err(|e| {
        invalid(
            format!("objects{}", path_suffix(&e.path().to_string())),
            e.inner().to_string(),
        )
    })?;
    if !(1..=MAX_OBJECTS).contains(&list.len()) {
        return Err(invalid(
            "objects".into(),
            format!("{} objects; a scene holds 1 to {MAX_OBJECTS}", list.len()),
        ));
    }
    let mut names: Vec<&str> = Vec::with_capacity(list.len());
    for (i, o) in list.iter().enumerate() {
        let n = o.name.as_deref().unwrap_or("");
        let chars = n.chars().count();
        if !(1..=MAX_OBJECT_NAME_CHARS).contains(&chars) || n.chars().any(char::is_control) {
            return Err(invalid(
                format!("objects[{i}].name"),
                format!(
                    "must be 1 to {MAX_OBJECT_NAME_CHARS} characters, none a control character"
                ),
            ));
        }
        if names.contains(&n) {
            return Err(invalid(
                format!("objects[{i}].name"),
                format!("{n:?} names two objects"),
            ));
        }
        names.push(n);
        o.to_object()
            .map_err(|e| invalid(format!("objects[{i}]"), e.to_string()))?;
    }
    if !names.contains(&target.as_str()) {
        return Err(invalid(
            "target".into(),
            format!("{target:?} names none of the `objects`"),
        ));
    }
    Ok(())
}

/// A `serde_path_to_error` path as a suffix of a field (`[2].mass`; empty for the root).
fn path_suffix(path: &str) -> String {
    match path {
        "." => String::new(),
        p if p.starts_with('[') => p.to_owned(),
        p => format!(".{p}"),
    }
}

/// The metadata records are few and small, and name the session once: at most
/// [`MAX_METADATA_RECORDS`] records of at most [`MAX_METADATA_ENTRIES`] entries, keys of at
/// most [`MAX_METADATA_KEY_BYTES`], values of at most [`MAX_METADATA_VALUE_BYTES`], at most
/// [`MAX_METADATA_BYTES`] in all, and one record at most named `session`, `ground_truth` or
/// `replay` (a second one would be ignored: which one describes the session?). The store keeps
/// the `session` record with the session and lists it with every page of sessions.
pub(super) fn check_metadata(records: &[MetadataRecord], name: &str) -> Result<()> {
    let invalid = |location: String, detail: String| RecordingError::InvalidInput {
        location: format!("{name}: metadata {location}"),
        detail,
    };
    if records.len() > MAX_METADATA_RECORDS {
        return Err(invalid(
            "records".into(),
            format!(
                "the file has {} metadata records; a session has at most {MAX_METADATA_RECORDS}",
                records.len()
            ),
        ));
    }
    for unique in [
        SESSION_METADATA,
        GROUND_TRUTH_METADATA,
        REPLAY_METADATA,
        crate::live::LIVE_METADATA,
        OVERLAPS_METADATA,
    ] {
        let n = records.iter().filter(|r| r.name == unique).count();
        if n > 1 {
            return Err(invalid(
                unique.to_owned(),
                format!(
                    "the file has {n} `{unique}` metadata records; a session has one at most \
                     (which would describe it?)"
                ),
            ));
        }
    }
    let mut total = 0usize;
    for record in records {
        let r = &record.name;
        if record.entries.len() > MAX_METADATA_ENTRIES {
            return Err(invalid(
                r.clone(),
                format!(
                    "has {} entries; a metadata record has at most {MAX_METADATA_ENTRIES}",
                    record.entries.len()
                ),
            ));
        }
        total += r.len();
        for (key, value) in &record.entries {
            if key.len() > MAX_METADATA_KEY_BYTES {
                let shown: String = key.chars().take(40).collect();
                return Err(invalid(
                    format!("{r}.{shown}…"),
                    format!(
                        "the key is {} bytes long; a key has at most {MAX_METADATA_KEY_BYTES}",
                        key.len()
                    ),
                ));
            }
            if value.len() > MAX_METADATA_VALUE_BYTES {
                return Err(invalid(
                    format!("{r}.{key}"),
                    format!(
                        "the value is {} bytes long; a metadata value has at most {} bytes",
                        value.len(),
                        MAX_METADATA_VALUE_BYTES
                    ),
                ));
            }
            total += key.len() + value.len();
        }
        if total > MAX_METADATA_BYTES {
            return Err(invalid(
                r.clone(),
                format!(
                    "the metadata records hold more than {MAX_METADATA_BYTES} bytes of names, \
                     keys and values; a session's metadata holds at most that"
                ),
            ));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn metadata(objects: &str, target: &str) -> BTreeMap<String, String> {
        BTreeMap::from([
            ("objects".to_owned(), objects.to_owned()),
            ("target".to_owned(), target.to_owned()),
        ])
    }

    #[test]
    fn the_objects_of_a_session_are_checked_naming_the_field() {
        let ball = r#"{"name": "ball", "shape": "sphere", "radius": 0.04, "mass": 0.3, "mu": 0.8}"#;
        let cup = r#"{"name": "cup", "shape": "cylinder", "radius": 0.04, "half_height": 0.05, "mass": 0.3, "mu": 0.8}"#;
        let good = format!("[{ball}, {cup}]");
        check_session_objects(&metadata(&good, "cup"), "f").unwrap();
        check_session_objects(&BTreeMap::new(), "f").unwrap();
        let error =
            |m: BTreeMap<String, String>| check_session_objects(&m, "f").unwrap_err().to_string();
        let e = error(metadata(&good, "mug"));
        assert!(e.contains("session.target") && e.contains("\"mug\""), "{e}");
        let e = error(metadata(&format!("[{ball}, {ball}]"), "ball"));
        assert!(e.contains("session.objects[1].name"), "{e}");
        let e = error(metadata(&good.replace("0.05", "-1"), "cup"));
        assert!(
            e.contains("session.objects[1]") && e.contains("half_height"),
            "{e}"
        );
        let e = error(metadata(&good.replace("\"sphere\"", "\"torus\""), "cup"));
        assert!(e.contains("session.objects[0].shape"), "{e}");
        let e = error(metadata("[]", "cup"));
        assert!(e.contains("0 objects"), "{e}");
        let mut m = metadata(&good, "cup");
        m.remove("target");
        assert!(error(m).contains("session.target"));
    }
}
