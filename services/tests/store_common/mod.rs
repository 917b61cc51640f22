//! Helpers shared by the store tests: deterministic fake MCAP bytes, metadata and skills.
#![allow(dead_code)]

use std::path::Path;

use dfs_core::replay::{ReplayParams, ReplayReport};
use services::replay::{load_builtin_hand, replay_skill, skill_spec_from_json, ReplaySource};
use services::store::bench::{synthetic_blob, synthetic_skill, SplitMix64};
use services::store::{NewSkill, SessionMeta};

/// Deterministic pseudo-MCAP bytes number `i` of `len` bytes (distinct for distinct `i`).
pub fn fake_mcap(i: u64, len: usize) -> Vec<u8> {
    synthetic_blob(i, len)
}

/// Metadata of a test session; `extra` records `i` and the number of skills.
pub fn meta(i: u64, n_skills: usize) -> SessionMeta {
    SessionMeta {
        scenario: Some("test".into()),
        seed: Some(i),
        hand: "glove10".into(),
        object_shape: "sphere".parse().unwrap(),
        object_mass: 0.5,
        mu: 0.8,
        duration_ns: 10_000_000_000,
        started_at: Some("2026-01-01T00:00:00Z".into()),
        extra: serde_json::json!({ "i": i, "skills": n_skills }),
    }
}

/// `n` synthetic skills drawn from `seed`.
pub fn skills(seed: u64, n: usize) -> Vec<NewSkill> {
    let mut rng = SplitMix64::new(seed);
    (0..n).map(|_| synthetic_skill(&mut rng)).collect()
}

/// The MCAP blobs under a data directory.
pub fn blob_count(dir: &Path) -> usize {
    fn walk(p: &Path, n: &mut usize) {
        for e in std::fs::read_dir(p).unwrap() {
            let e = e.unwrap();
            if e.file_type().unwrap().is_dir() {
                walk(&e.path(), n);
            } else if e.path().extension().is_some_and(|x| x == "mcap") {
                *n += 1;
            }
        }
    }
    let mut n = 0;
    let root = dir.join("blobs");
    if root.exists() {
        walk(&root, &mut n);
    }
    n
}

/// A report of a replay that fails at once: a 0.4 m sphere does not fit in the gripper.
pub fn unreachable_report() -> ReplayReport {
    let skill = serde_json::json!({
        "phases": [
            {"name": "approach", "start_ns": 0, "end_ns": 500_000_000u64},
            {"name": "grasp", "start_ns": 500_000_000u64, "end_ns": 1_000_000_000u64},
            {"name": "lift", "start_ns": 1_000_000_000u64, "end_ns": 1_500_000_000u64},
            {"name": "release", "start_ns": 1_500_000_000u64, "end_ns": 2_000_000_000u64}
        ],
        "object": {"shape": "sphere", "size": [0.2], "mass": 0.3, "mu": 0.8},
        "contact_model": "soft_finger",
        "contacts": [
            {"finger": "thumb", "position_b": [0.2, 0.0, 0.0], "normal_b": [-1.0, 0.0, 0.0]},
            {"finger": "index", "position_b": [-0.2, 0.0, 0.0], "normal_b": [1.0, 0.0, 0.0]}
        ]
    });
    let spec = skill_spec_from_json(&skill, "big sphere").unwrap();
    let hand = load_builtin_hand("gripper").unwrap();
    replay_skill(
        &hand,
        &spec,
        &ReplayParams::default(),
        &ReplaySource::default(),
        None,
    )
    .unwrap()
}
