//! Sessions written before format v2 (JSON on every topic) still read, segment and ingest:
//! `fixtures/session-v1.mcap` is the scenario `fixtures/session-v1.scenario.json` (a shortened
//! sphere-lift, seed 5) recorded by `icms simulate` at commit 09cfd6c, the last to write v1.

use std::path::{Path, PathBuf};

use services::segmentation::{segment, SegmentParams};
use services::session::read_session;

fn fixture() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/session-v1.mcap")
}

#[test]
fn a_v1_session_reads_segments_and_ingests() {
    let session = read_session(fixture()).unwrap();
    assert_eq!(session.ticks(), 1550);
    assert_eq!(session.metadata["scenario"], "sphere-lift-short");
    assert!(
        !session.metadata.contains_key("format_version"),
        "v1 files carry no format version"
    );
    let seg = segment(&session, &SegmentParams::default());
    assert_eq!(seg.skills.len(), 1);
    let skill = &seg.skills[0];
    let names: Vec<&str> = skill.phases.iter().map(|p| p.phase.name()).collect();
    assert_eq!(
        names,
        ["approach", "grasp", "lift", "hold", "place", "release", "retreat"]
    );
    assert_eq!(skill.parameters.contacts.len(), 2);
    // The grasp starts where the script's grasp phase makes contact (0.2 + 0.1 s of approach
    // and preshape, then the fingers close).
    let grasp = &skill.phases[1];
    assert!(
        (300_000_000..350_000_000).contains(&grasp.start_ns),
        "{grasp:?}"
    );

    let bytes = std::fs::read(fixture()).unwrap();
    let (meta, skills) = services::ingest::analyse(&bytes, "session-v1.mcap").unwrap();
    assert_eq!(meta.object_shape.to_string(), "sphere");
    assert_eq!(skills.len(), 1);
    assert_eq!(skills[0].contact_count, 2);
}
