//! Recognition (issue 20) on simulated sessions.

use dfs_core::scenario::Scenario;
use services::assist::evaluate::{evaluate, EvalSetup};
use services::assist::recognise::RecogniserParams;

const KINDS: [&str; 3] = ["sphere-lift", "box-pinch-lift", "cylinder-power-grasp"];

/// Skills of three grasp kinds stored from seeds 1-3; seeds 101-102 recognised as they stream:
/// the target and a skill of the kind named 200 ms before the first contact, and a kind left
/// out of the data base flagged unknown and stored as new. (`icms bench recognition` measures
/// the same on varied operators and more seeds.)
#[test]
fn grasps_are_anticipated_and_an_absent_kind_is_unknown_and_learned() {
    let dir = tempfile::tempdir().unwrap();
    let scen = |seeds: std::ops::RangeInclusive<u64>| {
        KINDS
            .iter()
            .flat_map(|k| seeds.clone().map(move |s| Scenario::variant(k, s).unwrap()))
            .collect::<Vec<_>>()
    };
    let e = evaluate(EvalSetup {
        train: scen(1..=3),
        test: scen(101..=102),
        dir: dir.path(),
        params: RecogniserParams::default(),
        cost_skills: None,
        progress: &mut |_, _| {},
    })
    .unwrap();
    let report = serde_json::to_string_pretty(&e).unwrap();
    assert_eq!(e.sessions.len(), 6);
    assert!(e.anticipated_fraction >= 0.9, "{report}");
    assert!(e.median_lead_ms >= 200.0, "{report}");
    assert_eq!(e.open_set.len(), 6);
    assert!(e.unknown_fraction >= 0.9, "{report}");
    assert!(e.stored_as_new_fraction >= 0.9, "{report}");
}
