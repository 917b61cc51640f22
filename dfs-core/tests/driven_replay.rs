//! Replays driven by the operator's phases as they happen (issue 20, IP-flow 3): a skill of a
//! built-in scenario, retargeted onto allegro, barrett and inspire, its replay time given by
//! the operator's phase changes on a schedule of their own rather than by the fixed clock.

mod common;

use common::scenario_skill;
use dfs_core::hand::{builtin_hand, thumb_of, HandModel};
use dfs_core::math::{Isometry, Real};
use dfs_core::replay::{
    run, DrivenReplay, DrivenStart, ReplayParams, ReplayReport, SkillSpec, MAX_CATCH_UP_RATE,
    MAX_HELD_CATCH_UP_RATE, RATE_SLEW,
};
use dfs_core::scenario::Phase;
use dfs_core::Stop;

const DT: Real = 1e-3;

/// What a driven replay did.
struct Driven {
    report: ReplayReport,
    /// The object's reference after the last tick.
    reference: Isometry,
    /// The object's pose after the last tick.
    object: Isometry,
    /// Largest distance the base moved in one tick (m).
    max_base_step: Real,
    /// Largest acceleration of the base (m/s²), from the second difference of its positions.
    max_base_accel: Real,
    /// Largest rate of the replay time.
    max_rate: Real,
    /// The same from the grasp to the release.
    max_held_rate: Real,
    /// Largest rise of the reference above the object's start (m).
    reference_lift: Real,
    /// Phase changes the replay ignored.
    ignored: Vec<Phase>,
}

/// The skill's own phases at the skill's own durations.
fn own_schedule(skill: &SkillSpec) -> Vec<(Phase, Real)> {
    skill.phases.clone()
}

/// The largest step and acceleration of the base over ticks.
#[derive(Default)]
struct BaseMotion {
    last: Option<(Isometry, Option<dfs_core::math::Vector>)>,
    max_step: Real,
    max_accel: Real,
}

impl BaseMotion {
    fn add(&mut self, base: &Isometry) {
        let p = base.translation.vector;
        self.last = Some(match self.last {
            None => (*base, None),
            Some((b, last_step)) => {
                let step = p - b.translation.vector;
                self.max_step = self.max_step.max(step.norm());
                if let Some(s) = last_step {
                    self.max_accel = self.max_accel.max((step - s).norm() / (DT * DT));
                }
                (*base, Some(step))
            }
        });
    }
}

/// Drives a replay of `skill` on `hand` by the operator's phase changes: `(phase, real time
/// spent in it)`, each reported `late` seconds after the operator entered it; after the last,
/// ticks on until the replay is over.
fn drive_late(
    hand: &HandModel,
    skill: &SkillSpec,
    schedule: &[(Phase, Real)],
    late: Real,
) -> Driven {
    let params = ReplayParams::default();
    let start = DrivenReplay::start(hand, thumb_of(hand), skill, &params, 0.0, Stop::never());
    let mut replay = match start.unwrap() {
        DrivenStart::Running(r) => r,
        DrivenStart::Refused(r) => panic!("{}: refused: {}", hand.name, r.detail),
    };
    let z0 = skill.start_pose().translation.z;
    let mut out = Driven {
        report: replay.report(),
        reference: Isometry::identity(),
        object: Isometry::identity(),
        max_base_step: 0.0,
        max_base_accel: 0.0,
        max_rate: 0.0,
        max_held_rate: 0.0,
        reference_lift: 0.0,
        ignored: Vec::new(),
    };
    let mut motion = BaseMotion::default();
    let mut tick = |replay: &mut DrivenReplay, out: &mut Driven| -> bool {
        if !replay.tick().unwrap() {
            return false;
        }
        let s = replay.state();
        motion.add(s.tick.base);
        out.max_base_step = motion.max_step;
        out.max_base_accel = motion.max_accel;
        out.max_rate = out.max_rate.max(s.rate);
        if matches!(
            s.replay_phase,
            Phase::Grasp | Phase::Lift | Phase::Hold | Phase::Transport | Phase::Place
        ) {
            out.max_held_rate = out.max_held_rate.max(s.rate);
        }
        out.reference_lift = out.reference_lift.max(s.tick.reference.translation.z - z0);
        assert_eq!(s.tip_normal_forces.len(), hand.fingertips.len());
        assert!(s
            .tip_normal_forces
            .iter()
            .all(|f| f.is_finite() && *f >= 0.0));
        true
    };
    let mut now = 0.0;
    let mut pending: Vec<(Phase, Real)> = Vec::new();
    'schedule: for &(phase, d) in schedule {
        pending.push((phase, now));
        let n = (d / DT).round() as usize;
        for _ in 0..n {
            // Phase changes are known `late` seconds after they happened.
            while let Some(&(p, at)) = pending.first() {
                if at + late > now + 1e-9 {
                    break;
                }
                if !replay.set_phase(p, at) {
                    out.ignored.push(p);
                }
                pending.remove(0);
            }
            if !tick(&mut replay, &mut out) {
                // Over once the retreat's span is, though the operator retreats on.
                assert_eq!(
                    replay.clock().phase(),
                    Phase::Retreat,
                    "over early at {now}"
                );
                break 'schedule;
            }
            now += DT;
        }
    }
    for (p, at) in pending {
        if !replay.set_phase(p, at) {
            out.ignored.push(p);
        }
    }
    let mut extra = 0;
    while tick(&mut replay, &mut out) {
        extra += 1;
        assert!(extra < 10_000, "the replay never ends");
    }
    assert!(replay.is_finished());
    let s = replay.state();
    out.reference = *s.tick.reference;
    out.object = *s.object;
    out.report = replay.report();
    out
}

fn drive(hand: &HandModel, skill: &SkillSpec, schedule: &[(Phase, Real)]) -> Driven {
    drive_late(hand, skill, schedule, 0.0)
}

/// `schedule` with every phase `scale` times as long, and `hold` `hold_scale` times.
fn scaled(schedule: &[(Phase, Real)], scale: Real, hold_scale: Real) -> Vec<(Phase, Real)> {
    schedule
        .iter()
        .map(|&(p, d)| (p, d * if p == Phase::Hold { hold_scale } else { scale }))
        .collect()
}

/// The skill's final key pose in the world.
fn final_key_pose(skill: &SkillSpec) -> Isometry {
    let last = skill.motion.last().unwrap().time_s;
    skill.start_pose() * skill.key_pose(last)
}

/// A driven replay that held the object and moved it along the skill to its final key pose.
fn assert_held_and_moved(name: &str, skill: &SkillSpec, d: &Driven) {
    let r = &d.report;
    assert!(r.success, "{name}: {:?} {}", r.failure_reason, r.detail);
    assert!(
        r.position_error_max_m < 0.02,
        "{name}: {}",
        r.position_error_max_m
    );
    let top = skill
        .motion
        .iter()
        .map(|k| k.position.z)
        .fold(0.0, Real::max);
    assert!(
        d.reference_lift >= top - 1e-9,
        "{name}: {}",
        d.reference_lift
    );
    assert!(
        r.lift_height_m > 0.8 * top,
        "{name} lifted {}",
        r.lift_height_m
    );
    let key = final_key_pose(skill);
    let e = (d.reference.translation.vector - key.translation.vector).norm();
    assert!(
        e < 1e-9,
        "{name}: the reference ends {e} m off the final key pose"
    );
    let e = (d.object.translation.vector - key.translation.vector).norm();
    assert!(
        e < 0.02,
        "{name}: the object ends {e} m off the final key pose"
    );
    assert!(
        d.max_rate <= MAX_CATCH_UP_RATE + 1e-9,
        "{name}: {}",
        d.max_rate
    );
    // Entering the grasp's span may take one slew step more.
    let held = MAX_HELD_CATCH_UP_RATE + RATE_SLEW * DT;
    assert!(
        d.max_held_rate <= held + 1e-9,
        "{name}: {}",
        d.max_held_rate
    );
}

/// Each hand with a built-in scenario's skill that it holds on the fixed clock.
const CASES: [(&str, &str); 3] = [
    ("allegro", "cylinder-power-grasp"),
    ("barrett", "sphere-lift"),
    ("inspire", "sphere-lift"),
];

#[test]
fn driven_by_the_skills_own_phases_a_replay_holds_like_the_fixed_clock_replay() {
    for (name, scenario) in CASES {
        let skill = scenario_skill(scenario);
        let hand = builtin_hand(name).unwrap();
        let fixed = run(&hand, thumb_of(&hand), &skill, &ReplayParams::default()).unwrap();
        let d = drive(&hand, &skill, &own_schedule(&skill));
        eprintln!(
            "{name}: fixed {} {:.2} mm rms {:.2} mm, {} ticks; driven {} {:.2} mm rms {:.2} mm, \
             {} ticks, base step {:.3} mm",
            fixed.success,
            fixed.position_error_max_m * 1e3,
            fixed.position_error_rms_m * 1e3,
            fixed.ticks,
            d.report.success,
            d.report.position_error_max_m * 1e3,
            d.report.position_error_rms_m * 1e3,
            d.report.ticks,
            d.max_base_step * 1e3,
        );
        assert!(fixed.success, "{name}: {}", fixed.detail);
        assert_held_and_moved(name, &skill, &d);
        assert!(d.ignored.is_empty(), "{name}: {:?}", d.ignored);
        let (a, b) = (fixed.position_error_max_m, d.report.position_error_max_m);
        assert!((a - b).abs() < 0.005, "{name}: {a} vs {b}");
    }
}

#[test]
fn driven_by_a_stretched_or_compressed_schedule_a_replay_still_holds_and_moves_the_object() {
    for (name, scenario) in CASES {
        let skill = scenario_skill(scenario);
        let own = own_schedule(&skill);
        let hand = builtin_hand(name).unwrap();
        for (what, schedule) in [
            ("stretched", scaled(&own, 1.5, 3.0)),
            ("compressed", scaled(&own, 0.7, 0.7)),
        ] {
            let d = drive(&hand, &skill, &schedule);
            eprintln!(
                "{name} {what}: {} {:.2} mm rms {:.2} mm, {} ticks, rate ≤ {:.2}, base step \
                 {:.3} mm",
                d.report.success,
                d.report.position_error_max_m * 1e3,
                d.report.position_error_rms_m * 1e3,
                d.report.ticks,
                d.max_rate,
                d.max_base_step * 1e3,
            );
            assert_held_and_moved(&format!("{name} {what}"), &skill, &d);
        }
    }
}

#[test]
fn a_late_phase_change_is_caught_up_without_a_jump() {
    let skill = scenario_skill("cylinder-power-grasp");
    let hand = builtin_hand("allegro").unwrap();
    // How far the base moves in a tick on the fixed clock: catching up at most 3× real time,
    // it moves at most about 3× as far.
    let mut fixed = BaseMotion::default();
    run_fixed(&hand, &skill, |base| fixed.add(base));
    // The operator lifts in 0.3 s rather than 1 s and moves on to hold early; and the phase
    // estimate knows every change 0.4 s after it happened (the replay catches up on every
    // phase, the approach at up to 3×).
    let mut schedule = own_schedule(&skill);
    for (p, d) in &mut schedule {
        if *p == Phase::Lift {
            *d = 0.3;
        }
    }
    for late in [0.0, 0.4] {
        let d = drive_late(&hand, &skill, &schedule, late);
        eprintln!(
            "late {late}: {} {:.2} mm, rate ≤ {:.2} (held {:.3}), base step {:.3} mm, accel \
             {:.2} m/s² (fixed clock {:.3} mm, {:.2} m/s²)",
            d.report.success,
            d.report.position_error_max_m * 1e3,
            d.max_rate,
            d.max_held_rate,
            d.max_base_step * 1e3,
            d.max_base_accel,
            fixed.max_step * 1e3,
            fixed.max_accel,
        );
        // It caught up on the early hold as fast as it may with the object in the hand.
        assert!(
            d.max_held_rate > MAX_HELD_CATCH_UP_RATE - 0.01,
            "{}",
            d.max_held_rate
        );
        // The base accelerates no harder than on the fixed clock (whose hardest is where the
        // base stops following the object's motion, at the release).
        assert!(d.max_base_accel <= fixed.max_accel, "{}", d.max_base_accel);
        assert!(
            d.max_base_step <= MAX_CATCH_UP_RATE * fixed.max_step * 1.01,
            "late {late}: {} vs {}",
            d.max_base_step,
            fixed.max_step
        );
        assert_held_and_moved(&format!("late {late}"), &skill, &d);
    }
}

#[test]
fn phases_that_go_backwards_or_that_the_skill_lacks_are_ignored() {
    let skill = scenario_skill("sphere-lift");
    assert!(!skill.phases.iter().any(|(p, _)| *p == Phase::Transport));
    let hand = builtin_hand("barrett").unwrap();
    // A noisy phase estimate: back to grasp while lifting, a transport the skill lacks while
    // holding, back to lift while placing.
    let mut schedule = Vec::new();
    for &(p, d) in &skill.phases {
        match p {
            Phase::Lift => schedule.extend([(p, d * 0.5), (Phase::Grasp, 0.1), (p, d * 0.5)]),
            Phase::Hold => schedule.extend([(p, 0.5), (Phase::Transport, 1.0), (p, d - 0.5)]),
            Phase::Place => schedule.extend([(p, 0.4), (Phase::Lift, 0.2), (p, d - 0.4)]),
            _ => schedule.push((p, d)),
        }
    }
    let d = drive(&hand, &skill, &schedule);
    assert_eq!(
        d.ignored,
        [
            Phase::Grasp,
            Phase::Lift,
            Phase::Transport,
            Phase::Hold,
            Phase::Lift,
            Phase::Place
        ]
    );
    assert_held_and_moved("barrett", &skill, &d);
}

/// The fixed-clock replay of `skill` on `hand`, `on_base` seeing the base pose of every tick.
fn run_fixed(hand: &HandModel, skill: &SkillSpec, mut on_base: impl FnMut(&Isometry)) {
    let r =
        dfs_core::replay::run_with(hand, thumb_of(hand), skill, &ReplayParams::default(), |t| {
            on_base(t.base)
        })
        .unwrap();
    assert!(r.success, "{}", r.detail);
}
