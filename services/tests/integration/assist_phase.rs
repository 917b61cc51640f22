//! The on-line phase estimate ([`services::assist::phase`]) against the offline segmentation
//! of the same simulated sessions: its lag behind the offline boundaries at 1 kHz and 100 Hz.
//! Run in release (`cargo test --release -p services --test integration -- assist_phase:: --nocapture`
//! prints the numbers).

use crate::common::Lcg;
use dfs_core::hand::HandModel;
use dfs_core::operator::Simulation;
use dfs_core::scenario::Scenario;
use services::assist::phase::{phase_lag, LagStats, OnlinePhase, PhaseChange, PhaseObservation};
use services::segmentation::{segment, PhaseSpan, SegmentParams};
use services::session::{read_session, record_simulation};

/// The built-in scenarios of one grasp.
const SCENARIOS: [&str; 5] = [
    "sphere-lift",
    "box-pinch-lift",
    "cylinder-power-grasp",
    "sphere-rotate",
    "table-three",
];

/// One session: what the estimate is fed live, every tick, and the offline phases.
struct Run {
    name: String,
    seed: u64,
    ticks: Vec<PhaseObservation>,
    offline: Vec<PhaseSpan>,
}

fn run(name: &str, seed: u64) -> Run {
    let params = SegmentParams::default();
    let scenario = Scenario::builtin(name, seed).unwrap();
    // The session recorded and segmented offline.
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("s.mcap");
    record_simulation(&scenario, None, path.as_path(), |_, _| {}).unwrap();
    let session = read_session(&path).unwrap();
    let offline: Vec<PhaseSpan> = segment(&session, &params)
        .skills
        .into_iter()
        .flat_map(|s| s.phases)
        .collect();
    // The same simulation (seeded: the same ticks) as the live loop sees it.
    let mut sim = Simulation::new(&scenario, HandModel::glove10(), None).unwrap();
    let mut ticks = Vec::new();
    while sim.step().unwrap() {
        let (_, _, base) = sim.sample();
        ticks.push(PhaseObservation::from_tick(
            sim.time_ns(),
            base,
            sim.output(),
        ));
    }
    assert_eq!(
        session.object.len(),
        ticks.len(),
        "{name} {seed}: the live run is the recorded one"
    );
    Run {
        name: name.to_owned(),
        seed,
        ticks,
        offline,
    }
}

/// The changes of an estimate fed `samples`.
fn feed<'a>(samples: impl IntoIterator<Item = &'a PhaseObservation>) -> Vec<PhaseChange> {
    let mut est = OnlinePhase::new(&SegmentParams::default());
    samples.into_iter().filter_map(|o| est.push(o)).collect()
}

/// Every `step`th tick as a wrist tracker would give it: 5 % of the samples dropped, up to
/// 0.1 ms late, ±0.1 mm of noise on each coordinate (the offline segmentation's test of
/// noise).
fn noisy(ticks: &[PhaseObservation], step: usize, rng: &mut Lcg) -> Vec<PhaseObservation> {
    let mut out = Vec::new();
    for o in ticks.iter().step_by(step) {
        if rng.next() < 0.05 {
            continue;
        }
        let mut o = *o;
        o.t_ns += (rng.next() * 100_000.0) as u64;
        for k in 0..3 {
            o.base.translation.vector[k] += (rng.next() - 0.5) * 2e-4;
        }
        out.push(o);
    }
    out
}

fn describe(changes: &[PhaseChange]) -> String {
    changes
        .iter()
        .map(|c| {
            format!(
                "{} {}({})",
                c.phase,
                c.decided_ns / 1_000_000,
                c.start_ns / 1_000_000
            )
        })
        .collect::<Vec<_>>()
        .join(", ")
}

fn report(label: &str, stats: &LagStats) {
    println!(
        "{label}: median |lag| {:.1} ms, p90 {:.1} ms, matched {}/{} ({:.1} %)",
        stats.median_abs_ms,
        stats.p90_abs_ms,
        stats.matched,
        stats.total,
        100.0 * stats.matched_fraction()
    );
    for (phase, s) in stats.per_phase() {
        let mean = s.lags_ms.iter().sum::<f64>() / s.lags_ms.len().max(1) as f64;
        println!(
            "  {:<10} median |lag| {:6.1} ms  p90 {:6.1} ms  mean lag {:6.1} ms  matched {}/{}",
            phase.name(),
            s.median_abs_ms,
            s.p90_abs_ms,
            mean,
            s.matched,
            s.total
        );
    }
}

/// One line per session: the offline phases and the on-line changes.
fn print_run(r: &Run, label: &str, changes: &[PhaseChange], stats: &LagStats) {
    let offline: Vec<String> = r
        .offline
        .iter()
        .map(|p| format!("{} {}", p.phase, p.start_ns / 1_000_000))
        .collect();
    println!(
        "{} {} {label}: median |lag| {:.0} ms, matched {}/{}\n  offline:  {}\n  on-line:  {}",
        r.name,
        r.seed,
        stats.median_abs_ms,
        stats.matched,
        stats.total,
        offline.join(", "),
        describe(changes),
    );
}

#[test]
fn the_online_phase_follows_the_offline_boundaries_within_100_ms_at_1_khz_and_100_hz() {
    let (mut khz, mut hz100) = (LagStats::default(), LagStats::default());
    for name in SCENARIOS {
        for seed in 1..=5 {
            let r = run(name, seed);
            for (label, step, all) in [("1 kHz", 1, &mut khz), ("100 Hz", 10, &mut hz100)] {
                let changes = feed(r.ticks.iter().step_by(step));
                let stats = phase_lag(&changes, &r.offline);
                print_run(&r, label, &changes, &stats);
                *all = all.merged(&stats);
            }
        }
    }
    report("1 kHz", &khz);
    report("100 Hz", &hz100);
    assert!(khz.total >= 5 * 5 * 6, "{khz:?}");
    for (label, s) in [("1 kHz", &khz), ("100 Hz", &hz100)] {
        assert!(s.median_abs_ms <= 100.0, "{label}: {s:?}");
        assert!(s.matched_fraction() >= 0.9, "{label}: {s:?}");
    }
}

#[test]
fn a_noisy_wrist_with_dropped_late_samples_changes_neither_the_phases_nor_the_lag_much() {
    let mut rng = Lcg(99);
    let (mut khz, mut hz100) = (LagStats::default(), LagStats::default());
    for name in SCENARIOS {
        for seed in 1..=2 {
            let r = run(name, seed);
            for (label, step, all) in [("1 kHz", 1, &mut khz), ("100 Hz", 10, &mut hz100)] {
                let clean: Vec<_> = feed(r.ticks.iter().step_by(step))
                    .iter()
                    .map(|c| c.phase)
                    .collect();
                let changes = feed(&noisy(&r.ticks, step, &mut rng));
                let stats = phase_lag(&changes, &r.offline);
                print_run(&r, label, &changes, &stats);
                *all = all.merged(&stats);
                // Not one change more or less than without noise.
                let phases: Vec<_> = changes.iter().map(|c| c.phase).collect();
                assert_eq!(
                    phases,
                    clean,
                    "{name} {seed} {label}: {}",
                    describe(&changes)
                );
            }
        }
    }
    report("1 kHz, noisy", &khz);
    report("100 Hz, noisy", &hz100);
    for (label, s) in [("1 kHz", &khz), ("100 Hz", &hz100)] {
        assert!(s.median_abs_ms <= 100.0, "{label}: {s:?}");
        assert!(s.matched_fraction() >= 0.9, "{label}: {s:?}");
    }
}

#[test]
fn two_grasps_in_a_row_and_a_dropped_box_are_followed_too() {
    // The second grasp's approach starts when the hand moves after the retreat; the box that
    // slips out of the fingers ends the grasp and the move after it is the retreat.
    let mut all = LagStats::default();
    for name in ["two-grasps", "box-slip"] {
        for seed in 1..=3 {
            let r = run(name, seed);
            for (label, step) in [("1 kHz", 1), ("100 Hz", 10)] {
                let changes = feed(r.ticks.iter().step_by(step));
                let stats = phase_lag(&changes, &r.offline);
                print_run(&r, label, &changes, &stats);
                all = all.merged(&stats);
            }
        }
    }
    report("two-grasps and box-slip, 1 kHz and 100 Hz", &all);
    assert!(all.median_abs_ms <= 100.0, "{all:?}");
    assert!(all.matched_fraction() >= 0.9, "{all:?}");
}
