//! The simulated operator's tests.

use super::phases::resting_tips;
use super::plan::tip_index;
use super::reach::hand_points;
use super::*;
use crate::hand::{HandModel, Kinematics};
use crate::object::Shape;
use crate::scenario::Scenario;
use rand::SeedableRng;

fn run(name: &str, seed: u64) -> (Simulation, Vec<(Phase, Real, bool, usize)>) {
    let s = Scenario::builtin(name, seed).unwrap();
    let mut sim = Simulation::new(&s, HandModel::glove10(), None).unwrap();
    let mut trace = Vec::new();
    while sim.step().unwrap() {
        let o = sim.output();
        let slip = o.tips.iter().take(o.n_tips).any(|t| t.in_contact && t.slip);
        trace.push((
            sim.phase(),
            sim.dfs().object_state().pose.translation.z,
            slip,
            o.n_contacts,
        ));
    }
    (sim, trace)
}

#[test]
fn a_pinch_lift_carries_the_box_off_the_table_and_sets_it_down() {
    let (_, trace) = run("box-pinch-lift", 1);
    let start = trace[0].1;
    let lifted = trace
        .iter()
        .filter(|t| t.0 == Phase::Hold)
        .map(|t| t.1)
        .fold(0.0, Real::max);
    assert!(
        lifted > start + 0.05,
        "box rose only to {lifted} from {start}"
    );
    let end = trace.last().unwrap().1;
    assert!(
        (end - start).abs() < 0.01,
        "the box is back on the table: {end}"
    );
    assert_eq!(trace.last().unwrap().3, 0, "released");
}

#[test]
fn the_same_scenario_and_seed_give_identical_sessions() {
    let a = run("box-pinch-lift", 7).1;
    let b = run("box-pinch-lift", 7).1;
    assert!(a
        .iter()
        .zip(&b)
        .all(|(x, y)| x.1.to_bits() == y.1.to_bits() && x.2 == y.2 && x.3 == y.3));
    let c = run("box-pinch-lift", 8).1;
    assert!(
        a.iter()
            .zip(&c)
            .any(|(x, y)| x.1.to_bits() != y.1.to_bits()),
        "seeds change the noise"
    );
}

#[test]
fn box_slip_shows_slip_and_the_box_leaves_the_grasp() {
    for seed in [1, 3, 6] {
        let (sim, trace) = run("box-slip", seed);
        let rest = trace[0].1;
        let table = sim.table_height();
        // The grip's lift-off peak carries the box up ...
        let (peak_at, peak) = trace
            .iter()
            .enumerate()
            .map(|(i, t)| (i, t.1))
            .fold((0, f64::MIN), |a, b| if b.1 > a.1 { b } else { a });
        assert!(
            peak > rest + 0.01,
            "seed {seed}: the box never rose ({peak} vs {rest})"
        );
        assert!(trace[peak_at].3 >= 2, "seed {seed}: held at the top");
        // ... it slips while held ...
        assert!(
            trace[peak_at..].iter().any(|t| t.2 && t.3 > 0),
            "seed {seed}: no slip flags after lift-off"
        );
        // ... and falls out of the grasp back to the table while the hand stays up.
        let last_hold = trace.iter().rfind(|t| t.0 == Phase::Hold).unwrap();
        assert_eq!(
            last_hold.3, 0,
            "seed {seed}: no contact left while the hand is up"
        );
        let st = sim.dfs().object_state();
        let depth = sim.dfs().object().shape.support_depth(&st.pose.rotation);
        assert!(
            last_hold.1 < peak - 0.05 && st.pose.translation.z - depth - table < 1e-3,
            "seed {seed}: the box is back on the table: {}",
            last_hold.1
        );
    }
}

/// Drift of the held object relative to the hand during `hold` (m/s): the least-squares
/// slope (linear trend) of its position relative to the palm (the hand proper; the wrist's
/// own compliance under the lift's end is not the grasp's), per axis, as a vector's
/// length. The standard creep measure: zero-mean tremor does not count as drift. `hold_s`
/// replaces the script's hold duration. Also returns the least number of contacts seen
/// during `hold` and the object's lowest height above its start then.
fn hold_drift(name: &str, seed: u64, hold_s: Option<Real>) -> (Real, usize, Real) {
    let mut s = Scenario::builtin(name, seed).unwrap();
    for t in s.tasks.iter_mut().filter(|t| t.phase == Phase::Hold) {
        t.duration = hold_s.unwrap_or(t.duration);
    }
    let mut sim = Simulation::new(&s, HandModel::glove10(), None).unwrap();
    let palm_link = sim
        .dfs()
        .hand()
        .links
        .iter()
        .position(|l| l.name == "palm")
        .expect("glove10 has a palm");
    let start = sim.dfs().object_state().pose.translation.z;
    let mut samples: Vec<(Real, Vector)> = Vec::new();
    let (mut contacts, mut lowest) = (usize::MAX, Real::INFINITY);
    while sim.step().unwrap() {
        if sim.phase() != Phase::Hold {
            continue;
        }
        let st = sim.dfs().object_state();
        let palm = sim.dfs().kinematics().link_poses[palm_link];
        let rel = (palm.inverse() * st.pose).translation.vector;
        samples.push((sim.time_ns() as Real * 1e-9, rel));
        contacts = contacts.min(sim.output().n_contacts);
        lowest = lowest.min(st.pose.translation.z - start);
    }
    let n = samples.len() as Real;
    let tm = samples.iter().map(|s| s.0).sum::<Real>() / n;
    let pm = samples.iter().map(|s| s.1).sum::<Vector>() / n;
    let stt: Real = samples.iter().map(|s| (s.0 - tm).powi(2)).sum();
    let slope = samples
        .iter()
        .map(|s| (s.1 - pm) * (s.0 - tm))
        .sum::<Vector>()
        / stt;
    (slope.norm(), contacts, lowest)
}

#[test]
fn in_sphere_lift_both_fingertips_hold_the_sphere_up_through_hold_for_every_seed() {
    for seed in 0..5 {
        let (_, contacts, lowest) = hold_drift("sphere-lift", seed, None);
        assert!(contacts >= 2, "seed {seed}: only {contacts} contacts");
        assert!(lowest > 0.08, "seed {seed}: the sphere sank to {lowest} m");
    }
}

/// The creep of the held sphere relative to the palm, over a hold long enough that the
/// fingers' tremor (8-12 Hz, whose beats and contact nonlinearity leave sub-hertz wander of
/// a few µm) does not pass for a trend: 8 s. Over the built-in script's 2 s hold the same
/// least-squares slope is 0.6-1.4 µm/s for seeds 0-4, and falls as T^-1.5 with the
/// window, the signature of noise rather than creep (a creep keeps its rate).
#[test]
fn in_sphere_lift_the_held_sphere_drifts_below_1_um_per_s_relative_to_the_hand() {
    for seed in 0..5 {
        let (drift, contacts, _) = hold_drift("sphere-lift", seed, Some(8.0));
        assert!(contacts >= 2, "seed {seed}: dropped");
        assert!(drift < 1e-6, "seed {seed}: drift {} um/s", drift * 1e6);
    }
}

/// What happens to the object over a run of `scenario`: its height above the start at the
/// end of `lift`, the least height and contacts during `hold`, the least height during
/// `transport` and its sideways travel, and at the end its height above the start, its
/// tilt from upright (rad) and the contacts left.
struct Outcome {
    lifted: Real,
    hold_low: Real,
    hold_contacts: usize,
    transport_low: Real,
    carried: Real,
    end: Real,
    tilt: Real,
    end_contacts: usize,
}

fn outcome(scenario: &Scenario) -> Outcome {
    let mut sim = Simulation::new(scenario, HandModel::glove10(), None).unwrap();
    let start = sim.dfs().object_state().pose.translation.vector;
    let mut o = Outcome {
        lifted: 0.0,
        hold_low: Real::INFINITY,
        hold_contacts: usize::MAX,
        transport_low: Real::INFINITY,
        carried: 0.0,
        end: 0.0,
        tilt: 0.0,
        end_contacts: 0,
    };
    while sim.step().unwrap() {
        let p = sim.dfs().object_state().pose.translation.vector - start;
        match sim.phase() {
            Phase::Lift => o.lifted = p.z,
            Phase::Hold => {
                o.hold_low = o.hold_low.min(p.z);
                o.hold_contacts = o.hold_contacts.min(sim.output().n_contacts);
            }
            Phase::Transport => {
                o.transport_low = o.transport_low.min(p.z);
                o.carried = p.y;
            }
            _ => {}
        }
    }
    let st = sim.dfs().object_state();
    o.end = st.pose.translation.z - start.z;
    o.tilt = (st.pose.rotation * Vector::z()).angle(&Vector::z());
    o.end_contacts = sim.output().n_contacts;
    o
}

#[test]
fn cylinder_power_grasp_lifts_holds_carries_and_sets_down_the_cylinder_for_every_seed() {
    for seed in 0..6 {
        let o = outcome(&Scenario::builtin("cylinder-power-grasp", seed).unwrap());
        assert!(o.lifted > 0.05, "seed {seed}: lifted only {} m", o.lifted);
        assert!(
            o.hold_low > 0.05 && o.hold_contacts >= 3,
            "seed {seed}: held at {} m on {} contacts",
            o.hold_low,
            o.hold_contacts
        );
        assert!(
            o.transport_low > 0.05 && (o.carried - 0.15).abs() < 0.02,
            "seed {seed}: carried {} m sideways, as low as {} m",
            o.carried,
            o.transport_low
        );
        assert!(
            o.end.abs() < 0.005 && o.tilt < 0.05,
            "seed {seed}: set down at {} m, tilted {} rad",
            o.end,
            o.tilt
        );
        assert_eq!(o.end_contacts, 0, "seed {seed}: released");
    }
}

/// Light spheres are lifted, held and set down like the built-in 300 g one. Below about
/// 80 g the contacts' tangential dampers (30 N·s/m) were more than the object's explicit
/// step can carry about its rolling axis: the sphere rattled between the pads from tick
/// to tick and was flung out of the pinch (50 g: no lift at all; 100 g of 3 cm at μ 0.6:
/// dropped while placing). The DFS now limits them (`dfs::STABLE_DAMPING`).
///
/// Each is tried on seeds 0-5, and every seed lifts it. The 50 g sphere of 4 cm is held
/// and set down in most of them, not all: since the table pushes only where the sphere
/// touches it, the sphere turns on the table under the fingertips' uneven push and twist as
/// they close on it (the table held a sphere's rotation still before), and in seeds 2 and 4
/// the pinch it is lifted in then lets it swing out during the hold (4 of seeds 0-11 drop
/// it; none did before). The 10 g and 100 g ones are held in every seed.
#[test]
fn pinches_lift_hold_and_set_down_spheres_of_10_to_100_g() {
    for (radius, mass, mu, need) in [
        (0.02, 0.01, 0.8, 6),
        (0.04, 0.05, 0.8, 3),
        (0.03, 0.1, 0.6, 6),
    ] {
        let mut held = Vec::new();
        for seed in 0..6 {
            let mut s = Scenario::builtin("sphere-lift", seed).unwrap();
            let o = s.object.as_mut().unwrap();
            o.radius = Some(radius);
            o.mass = mass;
            o.mu = mu;
            let o = outcome(&s);
            assert!(
                o.lifted > 0.08,
                "r {radius} m {mass} mu {mu} seed {seed}: lifted {}",
                o.lifted
            );
            if o.hold_low > 0.08 && o.hold_contacts >= 2 && o.end.abs() < 0.005 {
                held.push(seed);
            }
        }
        assert!(
            held.len() >= need,
            "r {radius} m {mass} mu {mu}: held and set down in seeds {held:?} only"
        );
    }
}

/// Thinner, thicker, lighter and heavier upright cylinders than the built-in's are lifted
/// and carried as well. (They land a few degrees off upright when set down, on the rim,
/// and rock back onto their end face after the release; before the table pushed only
/// where an object touches it, the slenderest, heaviest ones fell over.)
#[test]
fn power_grasps_lift_and_carry_cylinders_of_25_to_45_mm_radius_and_200_to_800_g() {
    for (radius, mass) in [(0.025, 0.2), (0.025, 0.8), (0.045, 0.2), (0.045, 0.8)] {
        let mut s = Scenario::builtin("cylinder-power-grasp", 1).unwrap();
        let o = s.object.as_mut().unwrap();
        o.radius = Some(radius);
        o.mass = mass;
        let o = outcome(&s);
        assert!(
            o.lifted > 0.05 && o.hold_low > 0.05 && o.transport_low > 0.05,
            "r {radius} m {mass}: lifted {}, held {}, carried as low as {}",
            o.lifted,
            o.hold_low,
            o.transport_low
        );
        assert!(
            o.hold_contacts >= 2,
            "r {radius} m {mass}: {} contacts",
            o.hold_contacts
        );
    }
}

/// The operator's power grasp of `cylinder-power-grasp` wraps the hand around the cylinder:
/// whole-hand contact on, and through `hold` the palm (its eminences) presses it, with at
/// least two long fingers wrapped around it (touching by a phalanx or the fingertip).
#[test]
fn the_power_grasp_presses_the_cylinder_into_the_palm_with_the_fingers_wrapped_around_it() {
    use crate::hand::BodyPart;
    let s = Scenario::builtin("cylinder-power-grasp", 0).unwrap();
    let mut sim = Simulation::new(&s, HandModel::glove10(), None).unwrap();
    assert!(sim.plan.wrap.is_some() && sim.dfs().params().whole_hand);
    let shapes = sim.dfs().hand().contact_shapes.clone();
    let (mut hold_ticks, mut palm_ticks, mut wrapped_ticks) = (0, 0, 0);
    while sim.step().unwrap() {
        if sim.phase() != Phase::Hold {
            continue;
        }
        hold_ticks += 1;
        let pressing: Vec<usize> = (0..sim.output().n_body)
            .filter(|&i| sim.dfs().body_contacts()[i].in_contact)
            .collect();
        palm_ticks += usize::from(pressing.iter().any(|&i| shapes[i].part == BodyPart::Palm));
        let out = sim.output();
        let thumb = tip_index(sim.dfs().hand(), "thumb");
        let fingers: std::collections::BTreeSet<usize> = pressing
            .iter()
            .filter_map(|&i| match shapes[i].part {
                BodyPart::Phalanx { finger } => finger,
                BodyPart::Palm => None,
            })
            .chain((0..out.n_tips).filter(|&k| out.tips[k].in_contact))
            .filter(|&k| Some(k) != thumb)
            .collect();
        wrapped_ticks += usize::from(fingers.len() >= 2);
    }
    assert!(hold_ticks > 500);
    assert_eq!(palm_ticks, hold_ticks, "the palm let go");
    assert_eq!(wrapped_ticks, hold_ticks, "fewer than two fingers wrapped");
}

/// Pinches and fingertip grasps keep fingertip contact alone; a wrap is planned for a
/// standing cylinder in a power grasp, its open hand clear of the cylinder above it and at
/// the preshape, its palm on the cylinder at the grasp.
#[test]
fn a_wrap_is_planned_for_a_standing_cylinder_with_the_open_hand_clear_of_it() {
    let hand = HandModel::glove10();
    let s = Scenario::builtin("cylinder-power-grasp", 0).unwrap();
    let (object, _) = s.resolve().unwrap();
    let pose = Isometry::translation(0.0, 0.0, 0.09);
    let plan = plan_operator_grasp(&hand, &object, &pose, GraspStyle::Power, &[]).unwrap();
    let wrap = plan.wrap.expect("a wrap");
    let n = hand.dof();
    let mut kin = Kinematics::default();
    let gap = |base: &Isometry, kin: &mut Kinematics| {
        hand.forward_kinematics(base, &plan.q_open[..n], kin);
        let inv = pose.inverse();
        hand.contact_shapes
            .iter()
            .map(|c| {
                crate::hand::contact_geometry::closest_to_object(
                    &c.primitive,
                    &(inv * kin.link_poses[c.link]),
                    &object.shape,
                )
                .gap
            })
            .fold(Real::INFINITY, Real::min)
    };
    let pre = gap(&plan.base, &mut kin);
    assert!((pre - power::WRAP_STANDOFF).abs() < 1e-4, "{pre}");
    // The grasp is the standoff nearer along the palm's normal: the nearest shape (an
    // eminence's edge) within it.
    let at = gap(&wrap.base, &mut kin);
    assert!((-1e-4..pre - 1e-3).contains(&at), "{at}");
    let above = approach_pose(&plan.base, &object.shape);
    assert!(gap(&above, &mut kin) > 0.02);
    // The palm's y (the thumb's side) up, its grasping side towards the cylinder.
    assert!((plan.base.rotation * Vector::y()).z > 0.999);
    let towards = pose.translation.vector - wrap.base.translation.vector;
    assert!((wrap.base.rotation * -Vector::z()).dot(&towards) > 0.0);
    // A pinch, and a power grasp of a sphere, stay fingertip grasps.
    let sphere = RigidObject::new(Shape::Sphere { radius: 0.04 }, 0.3).unwrap();
    for (o, style) in [(&object, GraspStyle::Pinch), (&sphere, GraspStyle::Power)] {
        let p = plan_operator_grasp(&hand, o, &pose, style, &[]).unwrap();
        assert!(p.wrap.is_none());
    }
}

#[test]
fn a_power_grasp_opposes_thumb_and_index_across_the_cylinder_along_their_normals() {
    let s = Scenario::builtin("cylinder-power-grasp", 0).unwrap();
    let (object, _) = s.resolve().unwrap();
    let pose = Isometry::translation(0.0, 0.0, 0.09);
    let hand = HandModel::glove10();
    let plan = plan_grasp(&hand, &object, &pose, GraspStyle::Power).unwrap();
    let [thumb, index, middle] = ["thumb", "index", "middle"].map(|n| tip_index(&hand, n).unwrap());
    assert!(plan.tips[thumb] && plan.tips[index] && plan.tips[middle]);
    for k in [thumb, index] {
        assert!(
            plan.normal_alignment[k] > 0.98,
            "tip {k} pushes {} along its normal",
            plan.normal_alignment[k]
        );
    }
    // Opposite across the axis, each in its own flexion plane (8 mm apart on glove10).
    assert!(plan.normals_b[thumb].dot(&plan.normals_b[index]) < -0.95);
    let across = (plan.contacts_b[thumb] - plan.contacts_b[index]).y.abs();
    assert!((across - 0.008).abs() < 0.002, "{across}");
    // The middle finger's plane passes 2.4 cm beside the axis: it only rests on the
    // curved surface.
    let resting = resting_tips(&plan, &hand, 0.7, OperatorParams::default().grip_safety);
    assert!(resting[middle] && !resting[thumb] && !resting[index]);
}

#[test]
fn every_builtin_scenario_plans_a_grasp_and_runs_its_first_second() {
    for name in Scenario::BUILTINS {
        let s = Scenario::builtin(name, 0).unwrap();
        let mut sim = Simulation::new(&s, HandModel::glove10(), Some(1.0)).unwrap();
        while sim.step().unwrap() {}
        assert_eq!(sim.ticks(), 1000, "{name}");
        assert!(sim.phases().iter().all(|p| p.span.end_ns <= 1_000_000_000));
    }
}

#[test]
fn in_table_three_the_operator_lifts_the_box_from_between_the_ball_and_the_cylinder() {
    for seed in [0, 3] {
        let s = Scenario::builtin("table-three", seed).unwrap();
        let mut sim = Simulation::new(&s, HandModel::glove10(), None).unwrap();
        assert_eq!(sim.scene().target().name, "box");
        let target = sim.target();
        assert_eq!(target, 1);
        let start: Vec<Vector> = sim
            .dfs()
            .objects()
            .iter()
            .map(|o| o.state.pose.translation.vector)
            .collect();
        let (mut lifted, mut others, mut overlaps) = (0.0, 0, 0);
        while sim.step().unwrap() {
            let out = sim.output();
            overlaps += usize::from(out.overlap.is_some());
            for tip in out.tips[..out.n_tips].iter().filter(|t| t.touching) {
                others += usize::from(tip.object != target);
            }
            if sim.phase() == Phase::Hold {
                let z = sim.target_state().pose.translation.z - start[target].z;
                lifted = Real::max(lifted, z);
            }
        }
        assert!(lifted > 0.08, "seed {seed}: the box rose {lifted} m");
        assert_eq!(others, 0, "seed {seed}: a fingertip touched an obstacle");
        assert_eq!(overlaps, 0, "seed {seed}");
        let end = sim.dfs().objects();
        assert!(
            (end[target].state.pose.translation.vector - start[target]).norm() < 0.01,
            "seed {seed}: the box is set back down where it was"
        );
        // Resting on the table, the others stay where they were (to rounding: the table's
        // support of a cylinder on its 12 rim points balances to 1e-17 m).
        for i in [0, 2] {
            let moved = (end[i].state.pose.translation.vector - start[i]).norm();
            assert!(moved < 1e-9, "seed {seed}: object {i} moved {moved} m");
        }
        assert_eq!(sim.output().n_contacts, 0, "released");
    }
}

/// A hash (FNV-1a over the bits) of every 10th tick's base position, measured angles and
/// torques and target pose of a run, with the run's last target and base poses.
fn fingerprint(s: &Scenario) -> (u64, u64, Isometry, Isometry) {
    let mut sim = Simulation::new(s, HandModel::glove10(), None).unwrap();
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    let mut mix = |v: Real| {
        for b in v.to_bits().to_le_bytes() {
            h ^= u64::from(b);
            h = h.wrapping_mul(0x0000_0100_0000_01b3);
        }
    };
    while sim.step().unwrap() {
        if !sim.ticks().is_multiple_of(10) {
            continue;
        }
        let (q, tau, base) = sim.sample();
        for v in base.translation.vector.iter().chain(q).chain(tau) {
            mix(*v);
        }
        let st = sim.target_state();
        let pose = &st.pose;
        for v in pose
            .translation
            .vector
            .iter()
            .chain(pose.rotation.coords.iter())
        {
            mix(*v);
        }
    }
    let (_, _, base) = sim.sample();
    (sim.ticks(), h, sim.target_state().pose, *base)
}

/// `vary_reach` off (absent from the file, or false) leaves a session as it was before the
/// field existed: `sphere-lift` seed 7 as computed before it, on x86-64 Linux bit for bit
/// (elsewhere the platform's `sin` may round differently: to 1e-9 m there). Re-taken with
/// issue 21's contact forces (no force across a gap, the pads at the contact preload, stick
/// dampers without the sensors' noise, the elliptic soft-finger cone) together with the
/// table that pushes only where the object touches it: the sphere is set down 0.57 mm and
/// 1.0° from where it was before them.
#[test]
fn without_vary_reach_a_session_is_the_one_it_was_before() {
    let builtin = Scenario::builtin("sphere-lift", 7).unwrap();
    assert!(!builtin.vary_reach);
    let mut json = serde_json::to_value(&builtin).unwrap();
    assert!(json.get("vary_reach").is_none(), "not written when off");
    let absent: Scenario = serde_json::from_value(json.clone()).unwrap();
    json["vary_reach"] = false.into();
    let off: Scenario = serde_json::from_value(json).unwrap();
    assert_eq!((&absent, &off), (&builtin, &builtin));
    let (ticks, hash, object, base) = fingerprint(&absent);
    // Computed before `vary_reach` existed; again with the table that pushes only where the
    // object touches it and issue 21's contact forces (see above).
    let before_object = Isometry::from_parts(
        Vector::new(
            f64::from_bits(0xbf75_ebde_2ee3_965e),
            f64::from_bits(0xbf51_c295_7aac_a686),
            f64::from_bits(0x3fa4_7ae1_47ae_147c),
        )
        .into(),
        nalgebra::UnitQuaternion::new_unchecked(nalgebra::Quaternion::new(
            f64::from_bits(0x3fef_f21b_2ddd_ab36),
            f64::from_bits(0xbfad_c418_6e87_2efe),
            f64::from_bits(0xbf64_e103_7fa3_ac5e),
            f64::from_bits(0x3f5b_68d4_4e7f_011c),
        )),
    );
    let before_base = Vector::new(
        f64::from_bits(0xbfa3_9a46_223c_d271),
        f64::from_bits(0xbfa0_f823_c88b_0412),
        f64::from_bits(0x3fcf_1251_ccde_a5c4),
    );
    assert_eq!(ticks, 7300);
    let moved = (object.translation.vector - before_object.translation.vector).norm();
    let turned = object.rotation.angle_to(&before_object.rotation);
    let base_moved = (base.translation.vector - before_base).norm();
    assert!(
        moved < 1e-9 && turned < 1e-9 && base_moved < 1e-9,
        "object {moved} m, {turned} rad, base {base_moved} m from before"
    );
    if cfg!(all(target_arch = "x86_64", target_os = "linux")) {
        assert_eq!(hash, 0x5be8_5ddb_bfac_c8fb, "{hash:#x}");
        assert_eq!(object, before_object);
        assert_eq!(base.translation.vector, before_base);
    }
}

/// A varied run of `name` with `seed` up to the end of its first approach: the
/// simulation, the approach's path, and per tick the base position, its planned
/// acceleration and whether any fingertip touched anything or any object overlapped
/// another.
fn varied(name: &str, seed: u64) -> (Simulation, ReachPath, Vec<(Vector, Vector, bool)>) {
    let mut s = Scenario::builtin(name, seed).unwrap();
    s.vary_reach = true;
    let mut sim = Simulation::new(&s, HandModel::glove10(), None).unwrap();
    let path = sim.reach_path.expect("a varied approach");
    let mut trace = Vec::new();
    while sim.step().unwrap() {
        if sim.span > 0 {
            break;
        }
        let out = sim.output();
        let touched = out.tips[..out.n_tips].iter().any(|t| t.touching);
        trace.push((
            sim.base.translation.vector,
            sim.base_acceleration,
            touched || out.overlap.is_some(),
        ));
    }
    (sim, path, trace)
}

#[test]
fn varied_reaches_differ_by_seed_keep_the_noise_and_their_durations_make_the_ground_truth() {
    let plain = Simulation::new(
        &Scenario::builtin("table-three", 4).unwrap(),
        HandModel::glove10(),
        None,
    )
    .unwrap();
    let mut s = Scenario::builtin("table-three", 4).unwrap();
    s.vary_reach = true;
    let a = Simulation::new(&s, HandModel::glove10(), None).unwrap();
    // The tremor and the noise stream are the seed's, varied or not.
    assert_eq!(
        (a.tremor_freq, a.tremor_phase),
        (plain.tremor_freq, plain.tremor_phase)
    );
    assert_eq!(a.rng, plain.rng);
    // The plain start is 15 cm above the approach pose; a varied one is not.
    let approach = approach_pose(&plain.plan.base, &plain.target_object().shape);
    assert_eq!(plain.base, raise(&approach, 0.15));
    s.seed = 5;
    let b = Simulation::new(&s, HandModel::glove10(), None).unwrap();
    for sim in [&a, &b] {
        let d = (sim.base.translation.vector - approach.translation.vector).norm();
        assert!(
            (REACH_HOME_M.0 - 1e-9..=REACH_HOME_M.1 + 1e-9).contains(&d),
            "home {d} m from the approach pose"
        );
        assert!(
            sim.base.translation.z > sim.table_height + REACH_HOME_ABOVE_TABLE_M,
            "home above the table"
        );
        // The spans tile the session; only approach and preshape changed, and the session
        // is no longer than the scenario says it can be.
        assert!(sim.n_steps as Real * 1e-3 <= s.longest_duration() + 1e-9);
        assert!(s.longest_duration() > s.duration());
        assert_eq!(sim.spans[0].span.start_ns, 0);
        assert!(sim
            .spans
            .windows(2)
            .all(|w| w[0].span.end_ns == w[1].span.start_ns));
        assert_eq!(sim.spans.last().unwrap().span.end_ns, sim.n_steps * TICK_NS);
        for (v, p) in sim.spans.iter().zip(&plain.spans) {
            let (v, p) = (v.span, p.span);
            let (dv, dp) = (v.end_ns - v.start_ns, p.end_ns - p.start_ns);
            match v.phase {
                Phase::Approach | Phase::Preshape => {
                    let r = dv as Real / dp as Real;
                    assert!((0.7..=1.0 / 0.7 + 0.3 / 0.8 + 1e-9).contains(&r), "{r}")
                }
                _ => assert_eq!(dv, dp),
            }
        }
    }
    assert!((a.base.translation.vector - b.base.translation.vector).norm() > 0.01);
    assert_ne!(a.spans, b.spans);
    assert_ne!(a.reach_path, b.reach_path);
}

/// The varied reaches' random parts over many seeds: within their ranges, every one
/// taken, a pause about half the time.
#[test]
fn varied_reaches_spread_over_their_ranges() {
    let mut pauses = 0;
    let (mut slow, mut fast) = (Real::INFINITY, 0.0 as Real);
    for seed in 0..200 {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        rng.set_stream(REACH_STREAM);
        let r = Reach::draw(&mut rng, 0.8);
        assert!((REACH_SPEED.0..=REACH_SPEED.1).contains(&r.speed));
        assert!((r.move_s - 0.8 / r.speed).abs() <= 1e-3);
        slow = slow.min(r.speed);
        fast = fast.max(r.speed);
        if r.pause_s > 0.0 {
            pauses += 1;
            assert!((REACH_PAUSE_S.0 - 1e-3..=REACH_PAUSE_S.1 + 1e-3).contains(&r.pause_s));
        }
        assert!((0.0..=REACH_BEND).contains(&r.bend));
        // The path parameter runs from 0 to 1, rests in the pause, and its derivatives
        // are those of its values.
        let total = r.move_s + r.pause_s;
        let (u0, _, _) = r.progress(0.0);
        let (u1, v1, _) = r.progress(total);
        assert_eq!((u0, u1, v1), (0.0, 1.0, 0.0));
        let h = 1e-5;
        for k in 1..100 {
            let t = total * k as Real / 100.0;
            let (u, v, a) = r.progress(t);
            let (up, vp, _) = r.progress(t + h);
            let (um, vm, _) = r.progress(t - h);
            assert!((0.0..=1.0).contains(&u));
            assert!(((up - um) / (2.0 * h) - v).abs() < 1e-4, "{seed} {t}");
            assert!(
                ((vp - vm) / (2.0 * h) - a).abs() < 1e-2 * (1.0 + a.abs()),
                "{t}"
            );
        }
    }
    assert!((70..=130).contains(&pauses), "{pauses} of 200 pause");
    assert!(slow < 0.75 && fast > 1.25, "{slow} {fast}");
}

#[test]
fn a_varied_first_approach_is_smooth_clear_of_everything_and_as_planned() {
    for (name, seed) in [
        ("table-three", 1),
        ("table-three", 2),
        ("table-three", 9),
        ("sphere-lift", 3),
        ("cylinder-power-grasp", 4),
    ] {
        let (sim, path, trace) = varied(name, seed);
        let end = approach_pose(&sim.plan.base, &sim.target_object().shape);
        let last = trace.last().unwrap().0;
        assert!(
            (last - end.translation.vector).norm() < 1e-4,
            "{name} {seed}"
        );
        let mut moved = 0.0 as Real;
        for (i, w) in trace.windows(3).enumerate() {
            let step = (w[1].0 - w[0].0).norm();
            moved = moved.max(step);
            assert!(step < 3e-3, "{name} {seed}: a {step} m jump at tick {i}");
            // The planned acceleration is the path's (the tremor, 5 µm at 8-12 Hz, adds up
            // to 0.05 m/s²).
            let second = (w[2].0 - 2.0 * w[1].0 + w[0].0) / 1e-6;
            let err = (second - w[1].1).norm();
            assert!(
                err < 0.1 + 0.01 * w[1].1.norm(),
                "{name} {seed}: acceleration {} vs {} at tick {i}",
                second,
                w[1].1
            );
        }
        assert!(moved > 5e-4, "{name} {seed}: it moved");
        assert!(
            trace.iter().all(|t| !t.2),
            "{name} {seed}: touched or overlapped while approaching"
        );
        assert!(
            trace.iter().all(|t| t.0.z > sim.table_height + 0.02),
            "{name} {seed}: the base stayed above the table"
        );
        // Bent as drawn (or less, never down), paused as drawn.
        let len = (end.translation.vector - trace[0].0).norm();
        assert!(path.bend.norm() <= REACH_BEND * len + 1e-9);
        let span = &sim.spans[0].span;
        let planned = path.reach.move_s + path.reach.pause_s;
        assert!(((span.end_ns - span.start_ns) as Real * 1e-9 - planned).abs() < 1e-9);
    }
}

/// Over the variants of `table-three` (every object a target in turn) and `two-grasps`
/// (a second reach from where the first grasp left the hand): no fingertip touches
/// anything while the hand reaches, none ever touches an object but the target, no two
/// objects overlap, and the hand (its joints and fingertips) stays above the table.
#[test]
fn varied_reaches_touch_nothing_on_the_way_and_stay_above_the_table() {
    let runs = (1..=20)
        .map(|seed| ("table-three", seed))
        .chain((1..=5).map(|seed| ("two-grasps", seed)));
    for (name, seed) in runs {
        let s = Scenario::variant(name, seed).unwrap();
        let mut sim = Simulation::new(&s, HandModel::glove10(), None).unwrap();
        let target = sim.target();
        let mut points = Vec::new();
        while sim.step().unwrap() {
            let out = sim.output();
            assert!(out.overlap.is_none(), "{name} {seed}");
            for tip in out.tips[..out.n_tips].iter().filter(|t| t.touching) {
                assert_eq!(tip.object, target, "{name} {seed}: touched another object");
                assert_ne!(
                    sim.phase(),
                    Phase::Approach,
                    "{name} {seed}: touched while reaching, at {} ms",
                    sim.ticks()
                );
            }
            if sim.phase() == Phase::Approach {
                hand_points(sim.dfs.hand(), sim.dfs.kinematics(), &mut points);
                let low = points
                    .iter()
                    .map(|(p, r)| p.z - r - sim.table_height)
                    .fold(Real::INFINITY, Real::min);
                assert!(low > 0.0, "{name} {seed}: {low} m above the table");
            }
        }
    }
}

#[test]
fn a_varied_second_grasp_reaches_from_where_the_hand_is() {
    let mut s = Scenario::builtin("two-grasps", 3).unwrap();
    s.vary_reach = true;
    let mut sim = Simulation::new(&s, HandModel::glove10(), None).unwrap();
    let second = sim
        .spans
        .iter()
        .enumerate()
        .filter(|(_, p)| p.span.phase == Phase::Approach)
        .nth(1)
        .unwrap()
        .0;
    let mut before = None;
    let mut prev: Option<Vector> = None;
    while sim.step().unwrap() {
        let p = sim.base.translation.vector;
        if let Some(q) = prev {
            assert!((p - q).norm() < 3e-3, "a jump at {}", sim.ticks());
        }
        prev = Some(p);
        if sim.span + 1 == second {
            before = Some(p);
        }
        if sim.span == second {
            assert!(sim.reach_path.is_some());
            // Started where the retreat left the hand.
            let start = sim.from_base.translation.vector;
            assert!((start - before.unwrap()).norm() < 1e-4);
        }
    }
}

#[test]
fn a_duration_out_of_range_is_refused() {
    let s = Scenario::builtin("box-pinch-lift", 0).unwrap();
    let e = Simulation::new(&s, HandModel::glove10(), Some(-1.0)).unwrap_err();
    assert!(e.to_string().contains("duration"));
}
