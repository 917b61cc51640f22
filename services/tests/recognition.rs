//! Recognition (issue 20) on simulated sessions.

use dfs_core::scenario::Scenario;
use services::assist::evaluate::{evaluate, EvalSetup};
use services::assist::recognise::RecogniserParams;

const KINDS: [&str; 3] = ["sphere-lift", "box-pinch-lift", "cylinder-power-grasp"];

#[test]
fn recognition_probe() {
    let dir = tempfile::tempdir().unwrap();
    let scen = |seeds: std::ops::RangeInclusive<u64>| {
        KINDS
            .iter()
            .flat_map(|k| seeds.clone().map(move |s| Scenario::builtin(k, s).unwrap()))
            .collect::<Vec<_>>()
    };
    let e = evaluate(EvalSetup {
        train: scen(1..=3),
        test: scen(101..=102),
        dir: dir.path(),
        params: RecogniserParams::default(),
        cost_skills: Some(10_000),
        progress: &mut |_, _| {},
    })
    .unwrap();
    println!("{}", serde_json::to_string_pretty(&e).unwrap());
}
