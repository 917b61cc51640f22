//! The table pushes only where an object touches it (issue 21, item 4): a box rests flat on a
//! face and stays still, tips over its edge exactly when a push's moment about it beats its
//! weight's (F·h against m g·w/2), falls to the side of an edge its centre of mass is on, and
//! slides exactly beyond μ m g; spheres and cylinders (standing, lying) rest. The object is
//! stepped as the DFS steps it ([`Table::support_wrench_b`], [`integrate`],
//! [`Table::lift_out`]) under a push of our choosing, and once through the DFS tick itself.

use dfs_core::dfs::{Dfs, DfsObject, DfsParams, GloveSample};
use dfs_core::hand::HandModel;
use dfs_core::math::{force_of, moment_of, wrench, Isometry, Real, Rotation, Vector, Wrench};
use dfs_core::object::{external_wrench_b, integrate, ObjectState, RigidObject, Shape};
use dfs_core::table::{Table, TableSupport};
use std::f64::consts::FRAC_PI_2;

const G: Real = 9.81;
const DT: Real = 1e-3;

/// The built-in scenarios' box: 5 × 5 × 8 cm, 0.2 kg.
const BOX: Shape = Shape::Box {
    half_extents: [0.025, 0.025, 0.04],
};

/// One object on a table at z = 0, stepped as the DFS steps it.
struct Sim {
    table: Table,
    object: RigidObject,
    state: ObjectState,
    support: TableSupport,
}

impl Sim {
    /// `shape` of `mass` on a table of friction `mu`, turned by `rotation` and resting on its
    /// lowest point.
    fn new(shape: Shape, mass: Real, mu: Real, rotation: Rotation) -> Sim {
        let z = shape.support_depth(&rotation);
        Sim {
            table: Table {
                height: 0.0,
                mu,
                rolling: DfsParams::default().table_rolling,
            },
            object: RigidObject::new(shape, mass).unwrap(),
            state: ObjectState::at_rest(Isometry::from_parts(
                Vector::new(0.0, 0.0, z).into(),
                rotation,
            )),
            support: TableSupport::default(),
        }
    }

    /// One tick under `push_b` (B, besides gravity); returns the table's wrench (B).
    fn step(&mut self, push_b: &Wrench) -> Wrench {
        let g = Vector::new(0.0, 0.0, -G);
        let f = external_wrench_b(&self.object, &self.state, push_b, &g);
        let table =
            self.table
                .support_wrench_b(&mut self.support, &self.object, &self.state, &f, DT);
        integrate(&self.object, &mut self.state, &(f + table), DT);
        self.table.lift_out(&self.object.shape, &mut self.state);
        table
    }

    /// `n` ticks with no push.
    fn settle(&mut self, n: usize) {
        for _ in 0..n {
            self.step(&Wrench::zeros());
        }
    }

    /// The wrench (B) of the world force `f` at the point `p_b` of the object.
    fn push_at(&self, p_b: Vector, f: Vector) -> Wrench {
        let f_b = self.state.pose.rotation.inverse() * f;
        wrench(&f_b, &p_b.cross(&f_b))
    }

    fn weight(&self) -> Real {
        self.object.mass * G
    }
}

/// Angle (°) between the world's up and the body axis nearest it: 0 when the object stands
/// on a face (any face). From the axis's horizontal part, which keeps small angles exact.
fn tilt_deg(r: &Rotation) -> Real {
    let m = r.to_rotation_matrix();
    let i = vertical_axis(r);
    m[(0, i)].hypot(m[(1, i)]).min(1.0).asin().to_degrees()
}

/// Which body axis points up or down (0, 1, 2).
fn vertical_axis(r: &Rotation) -> usize {
    let m = r.to_rotation_matrix();
    (0..3)
        .max_by(|&a, &b| m[(2, a)].abs().total_cmp(&m[(2, b)].abs()))
        .unwrap()
}

/// How still an object kept over some ticks.
struct Stillness {
    /// The largest speed of its centre (m/s).
    speed: Real,
    /// The largest angular speed (rad/s).
    turn_rate: Real,
    /// How far its centre moved (m).
    moved: Real,
    /// How far it turned (°).
    turned: Real,
    /// The most sweeps a tick's support solve took.
    sweeps: usize,
}

/// How still the object keeps over `n` more ticks with no push.
fn stillness(sim: &mut Sim, n: usize) -> Stillness {
    let start = sim.state.pose;
    let (mut speed, mut turn_rate): (Real, Real) = (0.0, 0.0);
    let mut sweeps = 0;
    for _ in 0..n {
        sim.step(&Wrench::zeros());
        speed = speed.max(sim.state.linear_velocity.norm());
        turn_rate = turn_rate.max(sim.state.angular_velocity_b.norm());
        sweeps = sweeps.max(sim.support.sweeps());
    }
    Stillness {
        speed,
        turn_rate,
        moved: (sim.state.pose.translation.vector - start.translation.vector).norm(),
        turned: sim
            .state
            .pose
            .rotation
            .angle_to(&start.rotation)
            .to_degrees(),
        sweeps,
    }
}

/// Asserts the object has come to rest and stays: tilt under 0.05°, speeds under 1 µm/s and
/// 10 µrad/s, and over the next second no creep (under 1 µm, 0.001°).
fn assert_rests_flat(sim: &mut Sim, what: &str) {
    let tilt = tilt_deg(&sim.state.pose.rotation);
    assert!(tilt < 0.05, "{what}: rests tilted {tilt}°");
    assert_rests(sim, what);
}

/// Asserts the object has come to rest and stays: speeds under 1 µm/s and 10 µrad/s, over
/// the next second no creep (under 1 µm, 0.001°), and the support's solve settling in one
/// sweep a tick.
fn assert_rests(sim: &mut Sim, what: &str) {
    let tilt = tilt_deg(&sim.state.pose.rotation);
    let Stillness {
        speed: v,
        turn_rate: w,
        moved,
        turned,
        sweeps,
    } = stillness(sim, 1000);
    println!(
        "{what}: tilt {tilt:.2e}°, then over 1 s: |v| ≤ {v:.1e} m/s, |ω| ≤ {w:.1e} rad/s, \
         moved {moved:.1e} m, turned {turned:.1e}°, {sweeps} sweep(s) a tick"
    );
    assert_eq!(
        sweeps, 1,
        "{what}: a resting object's support takes one sweep"
    );
    assert!(
        v < 1e-6 && w < 1e-5,
        "{what}: still moving: {v} m/s, {w} rad/s"
    );
    assert!(
        moved < 1e-6 && turned < 1e-3,
        "{what}: creeps: {moved} m, {turned}°"
    );
}

#[test]
fn a_box_landing_on_an_edge_or_a_corner_comes_to_rest_flat_and_stays_still() {
    for (roll, pitch) in [(1.0, 0.0), (3.0, 0.0), (8.0, 0.0), (20.0, 0.0), (4.0, 6.0)] {
        let r = Rotation::from_euler_angles(Real::to_radians(roll), Real::to_radians(pitch), 0.3);
        let mut sim = Sim::new(BOX, 0.2, 0.5, r);
        sim.settle(2000);
        assert_eq!(
            vertical_axis(&sim.state.pose.rotation),
            2,
            "on its end face"
        );
        assert_rests_flat(&mut sim, &format!("box from {roll}° × {pitch}°"));
    }
    // Dropped from 2 cm, tilted and turning.
    let mut sim = Sim::new(BOX, 0.2, 0.5, Rotation::from_euler_angles(0.05, -0.03, 0.0));
    sim.state.pose.translation.z += 0.02;
    sim.state.angular_velocity_b = Vector::new(0.5, -0.3, 1.0);
    sim.settle(2000);
    assert_rests_flat(&mut sim, "box dropped from 2 cm");
}

#[test]
fn through_the_dfs_tick_a_box_rests_flat_and_the_table_carries_its_weight() {
    let hand = HandModel::glove10();
    let n = hand.dof();
    for roll in [1.0_f64, 3.0, 8.0, 20.0] {
        let rot = Rotation::from_euler_angles(roll.to_radians(), 0.0, 0.0);
        let z = BOX.support_depth(&rot);
        let object = DfsObject {
            object: RigidObject::new(BOX, 0.2).unwrap(),
            friction: Default::default(),
            state: ObjectState::at_rest(Isometry::from_parts(Vector::new(0.0, 0.0, z).into(), rot)),
        };
        let params = DfsParams {
            table_height: Some(0.0),
            ..DfsParams::default()
        };
        let mut dfs = Dfs::with_objects(hand.clone(), &[object], params).unwrap();
        let (q, tau) = (vec![0.0; n], vec![0.0; n]);
        // The hand a metre above, touching nothing.
        let base = Isometry::translation(0.0, 0.0, 1.0);
        let sample = GloveSample {
            q: &q,
            tau: &tau,
            base,
        };
        for _ in 0..2000 {
            dfs.step(&sample).unwrap();
        }
        let start = *dfs.object_state();
        let mut fastest: Real = 0.0;
        for _ in 0..1000 {
            let out = dfs.step(&sample).unwrap();
            fastest = fastest.max(out.object.linear_velocity.norm());
        }
        let s = *dfs.object_state();
        let tilt = tilt_deg(&s.pose.rotation);
        let moved = (s.pose.translation.vector - start.pose.translation.vector).norm();
        println!("DFS, box from {roll}°: rest tilt {tilt:.2e}°, then |v| ≤ {fastest:.1e} m/s, moved {moved:.1e} m");
        assert!(tilt < 0.05, "from {roll}°: rests tilted {tilt}°");
        assert!(
            fastest < 1e-6 && moved < 1e-6,
            "from {roll}°: {fastest} m/s, {moved} m"
        );
        // The table's wrench holds the weight up through the centre: its force is m g up
        // (in B), its moment about the centre nothing.
        let table = dfs.output().table_force_b;
        let up_b = s.pose.rotation.inverse() * Vector::new(0.0, 0.0, 0.2 * G);
        assert!((force_of(&table) - up_b).norm() < 1e-6, "{table:?}");
        assert!(moment_of(&table).norm() < 1e-6, "{table:?}");
    }
}

/// The centre of pressure (world x, y from the centre of mass) of the table's wrench `t_b` on
/// an object standing on the face `depth` below its centre.
fn centre_of_pressure(sim: &Sim, t_b: &Wrench, depth: Real) -> (Real, Real) {
    let r = sim.state.pose.rotation;
    let (f, m) = (r * force_of(t_b), r * moment_of(t_b));
    // m = Σ r_k × f_k with every r_k.z = −depth: m_x = r_y f_z + depth f_y, m_y = −depth f_x − r_x f_z.
    ((-m.y - depth * f.x) / f.z, (m.x - depth * f.y) / f.z)
}

/// Pushes the box at the middle of the top edge of its −x face, along +x, with `factor` times
/// the force whose moment about the far bottom edge equals its weight's (F h = m g w/2), for
/// 2 s, then lets it settle for 2 s. Returns the body axis that ends up vertical, the largest
/// |centre of pressure x| while pushed, and how far the box slid.
fn push_high(factor: Real) -> (usize, Real, Real) {
    let mut sim = Sim::new(BOX, 0.2, 0.8, Rotation::identity());
    let (w, h) = (0.05, 0.08);
    let threshold = sim.weight() * (w / 2.0) / h;
    assert!(
        factor * threshold < 0.8 * sim.weight(),
        "a push this strong would slide the box"
    );
    let point = Vector::new(-0.025, 0.0, 0.04);
    let mut cop: Real = 0.0;
    let start = sim.state.pose.translation.vector;
    for _ in 0..2000 {
        let push = sim.push_at(point, Vector::new(factor * threshold, 0.0, 0.0));
        let t = sim.step(&push);
        if vertical_axis(&sim.state.pose.rotation) == 2 && tilt_deg(&sim.state.pose.rotation) < 1.0
        {
            cop = cop.max(centre_of_pressure(&sim, &t, 0.04).0.abs());
        }
    }
    sim.settle(2000);
    let axis = vertical_axis(&sim.state.pose.rotation);
    assert_rests_flat(
        &mut sim,
        &format!("box pushed at {factor} × the tipping force"),
    );
    let slid = (sim.state.pose.translation.vector - start).norm();
    (axis, cop, slid)
}

#[test]
fn a_box_pushed_high_tips_onto_its_next_face_only_when_the_push_beats_its_weight_about_the_edge() {
    for factor in [0.8, 0.95] {
        let (axis, cop, slid) = push_high(factor);
        println!("push {factor} × threshold: stays on its end face, centre of pressure at {cop:.5} m, slid {slid:.1e} m");
        assert_eq!(axis, 2, "{factor} × the threshold tipped it");
        // The centre of pressure is where the moments balance (F h = m g x), inside the face.
        assert!((cop - factor * 0.025).abs() < 1e-6, "{factor}: {cop}");
        assert!(slid < 1e-6, "{factor}: slid {slid} m");
    }
    for factor in [1.05, 1.25] {
        let (axis, cop, _) = push_high(factor);
        println!("push {factor} × threshold: tipped onto its x face (centre of pressure at the edge, {cop:.5} m)");
        assert_eq!(
            axis, 0,
            "{factor} × the threshold did not tip it onto its x face"
        );
        assert!(
            cop <= 0.025 + 1e-9,
            "the centre of pressure left the face: {cop}"
        );
    }
}

#[test]
fn a_box_released_on_an_edge_falls_to_the_side_its_centre_of_mass_is_on() {
    // Standing on the edge x = +0.025 of its bottom face, its centre of mass is over the edge
    // at atan(0.025 / 0.04).
    let over = (0.025_f64 / 0.04).atan().to_degrees();
    for (tilt, falls_over) in [
        (over - 3.0, false),
        (over - 0.5, false),
        (over + 0.5, true),
        (over + 3.0, true),
    ] {
        let mut sim = Sim::new(
            BOX,
            0.2,
            0.5,
            Rotation::from_euler_angles(0.0, tilt.to_radians(), 0.0),
        );
        sim.settle(3000);
        let axis = vertical_axis(&sim.state.pose.rotation);
        println!(
            "released at {tilt:.2}° (over the edge at {over:.2}°): rests on its {} face",
            ["x", "y", "z"][axis]
        );
        assert_eq!(axis, if falls_over { 0 } else { 2 }, "released at {tilt}°");
        assert_rests_flat(&mut sim, &format!("box released at {tilt:.2}°"));
    }
}

#[test]
fn a_sideways_push_slides_a_box_only_beyond_mu_m_g() {
    let mu = 0.5;
    // Low on its side (2 cm above the table), far from tipping it.
    let point = Vector::new(-0.025, 0.0, -0.02);
    let mut sim = Sim::new(BOX, 0.2, mu, Rotation::identity());
    let f = 0.95 * mu * sim.weight();
    for _ in 0..1000 {
        let push = sim.push_at(point, Vector::new(f, 0.0, 0.0));
        sim.step(&push);
    }
    let slid = sim.state.pose.translation.x;
    println!("push 0.95 μ m g: slid {slid:.1e} m");
    assert!(slid.abs() < 1e-7, "slid {slid} m");

    let mut sim = Sim::new(BOX, 0.2, mu, Rotation::identity());
    let f = 1.1 * mu * sim.weight();
    for _ in 0..500 {
        let push = sim.push_at(point, Vector::new(f, 0.0, 0.0));
        sim.step(&push);
    }
    // Kinetic friction μ m g against the push: v = (F − μ m g) t / m.
    let expected = (f - mu * sim.weight()) * 0.5 / 0.2;
    let v = sim.state.linear_velocity.x;
    println!("push 1.1 μ m g: {v:.4} m/s after 0.5 s, expected {expected:.4}");
    assert!(
        (v - expected).abs() < 0.01 * expected,
        "{v} m/s, expected {expected}"
    );
    assert!(
        tilt_deg(&sim.state.pose.rotation) < 0.05,
        "sliding, it stays flat"
    );
    assert!(
        sim.state.linear_velocity.z.abs() < 1e-6,
        "sliding, it stays on the table"
    );
}

#[test]
fn spheres_and_cylinders_standing_or_lying_rest_still() {
    let ball = Shape::Sphere { radius: 0.04 };
    let mut sim = Sim::new(ball, 0.3, 0.5, Rotation::identity());
    sim.settle(500);
    assert_rests(&mut sim, "ball");

    let cylinder = Shape::Cylinder {
        radius: 0.035,
        half_height: 0.09,
    };
    let mut sim = Sim::new(cylinder, 0.5, 0.5, Rotation::identity());
    sim.settle(500);
    assert_rests_flat(&mut sim, "cylinder standing");
    // Set down 5° off upright: it rocks back onto its end face.
    let mut sim = Sim::new(
        cylinder,
        0.5,
        0.5,
        Rotation::from_euler_angles(0.05, 0.07, 0.0),
    );
    sim.settle(3000);
    assert_eq!(vertical_axis(&sim.state.pose.rotation), 2);
    assert_rests_flat(&mut sim, "cylinder set down 5° off upright");
    // Lying on its side (turned about its axis so no rim point is at the bottom): it does
    // not roll away.
    let lying = Rotation::from_euler_angles(FRAC_PI_2, 0.0, 0.0)
        * Rotation::from_euler_angles(0.0, 0.0, 0.1);
    let mut sim = Sim::new(cylinder, 0.5, 0.5, lying);
    sim.settle(500);
    let axis = sim.state.pose.rotation * Vector::z();
    assert!(axis.z.abs() < 1e-6, "its axis stays level: {axis:?}");
    assert!(sim.state.pose.translation.vector.xy().norm() < 1e-6);
    assert_rests(&mut sim, "cylinder lying");
    // Lying, rocked about its axis: it rolls a little and stops (rolling resistance).
    sim.state.angular_velocity_b = Vector::new(0.0, 0.0, 1.0);
    sim.settle(3000);
    let axis = sim.state.pose.rotation * Vector::z();
    assert!(axis.z.abs() < 1e-6, "its axis stays level: {axis:?}");
    assert_rests(&mut sim, "cylinder lying, rolled");
}

#[test]
fn a_bumped_ball_rolls_a_few_centimetres_and_stops() {
    let ball = Shape::Sphere { radius: 0.04 };
    let mut sim = Sim::new(ball, 0.3, 0.5, Rotation::identity());
    sim.state.linear_velocity = Vector::new(0.1, 0.0, 0.0);
    sim.settle(3000);
    let x = sim.state.pose.translation.x;
    // Rolling (after 2/7 of the speed goes into spin) against the couple e N: it decelerates
    // at e g / (1.4 r) from 5/7 of 0.1 m/s.
    let v0: Real = 0.1 * 5.0 / 7.0;
    let a = 1e-3 * G / (1.4 * 0.04);
    let rolled = v0 * v0 / (2.0 * a);
    println!("bumped ball: rolled {x:.4} m (rolling alone {rolled:.4} m)");
    assert!(x > rolled && x < rolled + 0.005, "{x} m");
    assert_rests(&mut sim, "bumped ball");
}

#[test]
fn light_and_heavy_objects_rest_without_jitter() {
    // The lightest object a scenario may hold (5 g) and a heavy one: the supports are impulses,
    // stable at any mass.
    for mass in [0.005, 0.05, 2.0] {
        let tiny = Shape::Box {
            half_extents: [0.01, 0.005, 0.003],
        };
        let mut sim = Sim::new(tiny, mass, 0.5, Rotation::from_euler_angles(0.1, 0.0, 0.0));
        sim.settle(2000);
        assert_rests_flat(&mut sim, &format!("thin box of {mass} kg"));
        let mut sim = Sim::new(BOX, mass, 0.5, Rotation::from_euler_angles(0.0, 0.2, 0.0));
        sim.settle(2000);
        assert_rests_flat(&mut sim, &format!("box of {mass} kg"));
    }
}
