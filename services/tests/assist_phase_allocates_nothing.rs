//! The on-line phase estimate allocates nothing per sample: a counting global allocator
//! around a whole simulated grasp fed sample by sample, with noise, gaps, duplicates and NaN.

use dfs_core::hand::HandModel;
use dfs_core::operator::Simulation;
use dfs_core::scenario::Scenario;
use services::assist::phase::{OnlinePhase, PhaseObservation};
use services::segmentation::SegmentParams;
use stats_alloc::{Region, StatsAlloc, INSTRUMENTED_SYSTEM};
use std::alloc::System;

#[global_allocator]
static GLOBAL: &StatsAlloc<System> = &INSTRUMENTED_SYSTEM;

#[test]
fn pushing_samples_allocates_nothing() {
    let scenario = Scenario::builtin("sphere-rotate", 1).unwrap();
    let mut sim = Simulation::new(&scenario, HandModel::glove10(), None).unwrap();
    let mut samples = Vec::new();
    while sim.step().unwrap() {
        let (_, _, base) = sim.sample();
        let mut o = PhaseObservation::from_tick(sim.time_ns(), base, sim.output());
        let i = sim.ticks();
        if i.is_multiple_of(97) {
            o.base.translation.vector.y = f64::NAN;
        }
        if i.is_multiple_of(13) {
            o.base.translation.vector.z += 1e-4;
        }
        // A gap of 200 ms, a duplicate and a sample back in time.
        if !(3000..3200).contains(&i) {
            samples.push(o);
        }
        if i.is_multiple_of(50) {
            samples.push(o);
            let mut back = o;
            back.t_ns = back.t_ns.saturating_sub(3_000_000);
            samples.push(back);
        }
    }
    let mut est = OnlinePhase::new(&SegmentParams::default());
    let mut changes = 0usize;
    let region = Region::new(GLOBAL);
    for o in &samples {
        changes += usize::from(est.push(o).is_some());
    }
    let stats = region.change();
    assert_eq!(
        (stats.allocations, stats.reallocations),
        (0, 0),
        "{stats:?}"
    );
    // preshape, grasp, lift, hold, transport, hold, place, release, retreat.
    assert_eq!(changes, 9, "{changes}");
}
