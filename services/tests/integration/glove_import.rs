//! Real operator input end to end in the library: a session exported to the glove CSV and
//! imported again gives the same skills (wrist pose from the recorded base pose); a glove that
//! measures positions only grasps through the virtual coupling; wrist poses from MCAP
//! (`foxglove.PoseInFrame`, `/tf`); any hand as the glove model; per-operator calibration;
//! bad input refused naming the line, column or message.

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use dfs_core::calibration::Calibration;
use dfs_core::contact::ContactModel;
use dfs_core::coupling::{CouplingParams, VirtualCoupling};
use dfs_core::dfs::DfsParams;
use dfs_core::hand::{builtin_hand, HandModel};
use dfs_core::math::{Isometry, Rotation, Vector};
use dfs_core::scenario::{Scenario, ScenarioObject};
use services::foxglove::JOINT_STATES_SCHEMA;
use services::mcap_io::{ReadLimits, SessionWriter};
use services::segmentation::{segment_source, SegmentParams, Skill};
use services::session::export::export_glove_csv;
use services::session::import::{
    import_glove, parse_glove_csv, read_glove_mcap, read_glove_mcap_with, ImportOptions,
    WristInput, WRIST_COLUMNS,
};
use services::session::*;

/// One simulated `sphere-lift` session (seed 3, the whole script), recorded once.
fn sphere_session() -> &'static (tempfile::TempDir, PathBuf) {
    static SESSION: OnceLock<(tempfile::TempDir, PathBuf)> = OnceLock::new();
    SESSION.get_or_init(|| {
        let (dir, path, _) = crate::common::sphere_lift_session(3, None);
        (dir, path)
    })
}

/// The session's object, from its `session` metadata (as a user would take it).
fn session_object(session: &Session) -> ScenarioObject {
    serde_json::from_str(&session.metadata["object"]).unwrap()
}

fn skills_of(path: &Path) -> Vec<Skill> {
    let (_, seg) = segment_source(
        &SessionSource::File(path),
        &ReadLimits::streaming(),
        &SegmentParams::default(),
    )
    .unwrap();
    seg.skills
}

/// The hand base's pose of each tick: `pose ∘ pose_in_hand⁻¹`.
fn base_poses(session: &Session) -> Vec<Isometry> {
    let iso = |p: &services::foxglove::Pose| {
        Isometry::from_parts(
            Vector::new(p.position.x, p.position.y, p.position.z).into(),
            Rotation::from_quaternion(nalgebra::Quaternion::new(
                p.orientation.w,
                p.orientation.x,
                p.orientation.y,
                p.orientation.z,
            )),
        )
    };
    session
        .object
        .iter()
        .map(|(_, o)| iso(&o.pose) * iso(&o.pose_in_hand).inverse())
        .collect()
}

/// How closely the skills of a session and of its export imported again agree in geometry.
#[derive(Debug, Clone, Copy)]
struct Tolerance {
    /// Contact positions in the object frame (m).
    position_m: f64,
    /// The object's key positions (m).
    motion_m: f64,
    /// The contacts' distances from one another (m).
    span_m: f64,
    /// The angles between the contacts' normals (degrees).
    normals_deg: f64,
}

/// Pinches (sphere, box): 3 mm, 1 mm, 2°; the object's key poses 3 mm.
const PINCH: Tolerance = Tolerance {
    position_m: 3e-3,
    motion_m: 3e-3,
    span_m: 1e-3,
    normals_deg: 2.0,
};

/// The skills of a session and of its export imported again agree: the same count, phases
/// (boundaries within 5 ms), grasp type and force closure, internal force and Ferrari-Canny
/// ε within 5 %, friction margin within 25 % (or 0.05 N), the contacts' fingers, and the
/// geometry within `tol`: contact positions and the object's key positions, the contacts'
/// distances from one another, the angles between their normals. The inputs are the
/// session's own samples at its recorded resolution (1e-5 rad, 1e-5 N·m, 1 µm), so the
/// replay is not bit for bit the simulation: what the contacts' stick springs make of a
/// micrometre shows in the details. An object turns freely about a symmetry axis the grasp
/// leaves it (a sphere about the line through a pinch, a cylinder about its own axis: 0.07 rad
/// on a 3.5 cm radius is 2.5 mm), so the contacts' positions in the object frame are compared
/// more loosely than their spans, and the key rotations within 0.6 rad.
fn assert_same_skills(a: &[Skill], b: &[Skill], tol: &Tolerance) {
    let Tolerance {
        position_m,
        motion_m,
        span_m,
        normals_deg,
    } = *tol;
    assert_eq!(a.len(), b.len(), "skill count");
    for (x, y) in a.iter().zip(b) {
        let names = |s: &Skill| s.phases.iter().map(|p| p.phase).collect::<Vec<_>>();
        assert_eq!(names(x), names(y));
        for (p, q) in x.phases.iter().zip(&y.phases) {
            assert!(p.start_ns.abs_diff(q.start_ns) < 5_000_000, "{p:?} {q:?}");
            assert!(p.end_ns.abs_diff(q.end_ns) < 5_000_000, "{p:?} {q:?}");
        }
        let (x, y) = (&x.parameters, &y.parameters);
        assert_eq!(x.contact_count, y.contact_count);
        assert_eq!(x.grasp_type.label, y.grasp_type.label);
        let close = |u: f64, v: f64, rel: f64| (u - v).abs() <= rel * u.abs().max(v.abs());
        assert!(close(x.internal_force_n, y.internal_force_n, 0.05));
        let margin = (x.friction_margin_n - y.friction_margin_n).abs();
        assert!(
            margin <= 0.05 + 0.25 * x.friction_margin_n.abs(),
            "friction margin"
        );
        let (qx, qy) = (x.quality.as_ref().unwrap(), y.quality.as_ref().unwrap());
        assert_eq!(qx.force_closure, qy.force_closure);
        assert!(close(qx.epsilon, qy.epsilon, 0.05));
        assert_eq!(x.contacts.len(), y.contacts.len());
        for (i, (c, d)) in x.contacts.iter().zip(&y.contacts).enumerate() {
            assert_eq!(c.finger, d.finger);
            let dist = (Vector::from(c.position_b) - Vector::from(d.position_b)).norm();
            assert!(dist < position_m, "{}: {dist} m", c.finger);
            for (e, f) in x.contacts.iter().zip(&y.contacts).skip(i + 1) {
                let span =
                    |a: &[f64; 3], b: &[f64; 3]| (Vector::from(*a) - Vector::from(*b)).norm();
                let (s, t) = (
                    span(&c.position_b, &e.position_b),
                    span(&d.position_b, &f.position_b),
                );
                assert!(
                    (s - t).abs() < span_m,
                    "{}-{}: {s} vs {t} m",
                    c.finger,
                    e.finger
                );
                let (a, b) = (
                    Vector::from(c.normal_b).angle(&Vector::from(e.normal_b)),
                    Vector::from(d.normal_b).angle(&Vector::from(f.normal_b)),
                );
                assert!(
                    (a - b).abs() < normals_deg.to_radians(),
                    "{}-{}: {a} vs {b} rad",
                    c.finger,
                    e.finger
                );
            }
        }
        assert_eq!(x.motion.len(), y.motion.len());
        for (k, l) in x.motion.iter().zip(&y.motion) {
            assert!((k.time_s - l.time_s).abs() < 5e-3);
            let dist = (Vector::from(k.position) - Vector::from(l.position)).norm();
            assert!(dist < motion_m, "key pose at {} s: {dist} m", k.time_s);
            let turn = (Vector::from(k.rotation) - Vector::from(l.rotation)).norm();
            assert!(turn < 0.6, "key pose at {} s: {turn} rad", k.time_s);
        }
    }
}

#[test]
fn a_session_exported_to_csv_and_imported_again_gives_the_same_skills() {
    let (_, path) = sphere_session();
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("glove.csv");
    let summary = export_glove_csv(path, &csv).unwrap();
    let session = read_session(path).unwrap();
    assert_eq!(summary.rows as usize, session.ticks());
    assert_eq!(summary.hand.as_deref(), Some("glove10"));
    let hand = HandModel::glove10();
    let text = std::fs::read_to_string(&csv).unwrap();
    let header: Vec<&str> = text.lines().next().unwrap().split(',').collect();
    let expected: Vec<String> = std::iter::once("time_s".to_owned())
        .chain(hand.dof_names.iter().cloned())
        .chain(hand.dof_names.iter().map(|n| format!("tau_{n}")))
        .chain(WRIST_COLUMNS.iter().map(|s| s.to_string()))
        .collect();
    assert_eq!(header, expected);
    assert!(text.lines().nth(2).unwrap().starts_with("0.001000000,"));
    assert!(text
        .trim_end()
        .lines()
        .last()
        .unwrap()
        .starts_with("# exported by icms"));

    // The CSV holds the session's samples, value for value, and its base poses.
    let rec = parse_glove_csv(&text, "glove.csv", &hand).unwrap();
    assert_eq!(rec.len(), session.ticks());
    let n = hand.dof();
    for (i, (_, js)) in session.joint_states.iter().enumerate().step_by(97) {
        assert_eq!(rec.q[i * n..(i + 1) * n], js.positions[..]);
        assert_eq!(
            rec.tau.as_ref().unwrap()[i * n..(i + 1) * n],
            js.efforts[..]
        );
    }
    let bases = base_poses(&session);
    let wrist = rec.wrist.as_ref().unwrap();
    for i in (0..bases.len()).step_by(101) {
        let p = wrist.poses[i];
        assert!((p.translation.vector - bases[i].translation.vector).norm() < 1e-12);
        assert!(p.rotation.angle_to(&bases[i].rotation) < 1e-9);
    }

    // Imported again with the session's hand and object.
    let out = dir.path().join("again.mcap");
    import_glove(
        &csv,
        &session_object(&session),
        &ImportOptions::default(),
        &out,
    )
    .unwrap();
    let original = skills_of(path);
    let again = skills_of(&out);
    assert_eq!(original.len(), 1, "sphere-lift is one grasp");
    assert_same_skills(&original, &again, &PINCH);

    // Without the wrist columns the base stays put and nothing is lifted: no skill (the
    // issue's case).
    let fixed: String = text
        .lines()
        .filter(|l| !l.starts_with('#'))
        .map(|l| {
            let fields: Vec<&str> = l.split(',').collect();
            fields[..fields.len() - 7].join(",") + "\n"
        })
        .collect();
    let fixed_csv = dir.path().join("fixed.csv");
    std::fs::write(&fixed_csv, fixed).unwrap();
    let out = dir.path().join("fixed.mcap");
    import_glove(
        &fixed_csv,
        &session_object(&session),
        &ImportOptions::default(),
        &out,
    )
    .unwrap();
    assert_eq!(skills_of(&out).len(), 0);
}

/// A CSV of the session's samples (every `every`th tick) in the import format, by hand:
/// `time_s`, the angles `q(tick)`, optionally the torques and the wrist pose.
fn csv_of(
    session: &Session,
    every: usize,
    q: impl Fn(usize) -> Vec<f64>,
    torques: bool,
    wrist: bool,
) -> String {
    let names = &session.joint_states[0].1.names;
    let mut header = vec!["time_s".to_owned()];
    header.extend(names.iter().cloned());
    if torques {
        header.extend(names.iter().map(|n| format!("tau_{n}")));
    }
    if wrist {
        header.extend(WRIST_COLUMNS.iter().map(|s| s.to_string()));
    }
    let bases = base_poses(session);
    let mut text = header.join(",") + "\n";
    for i in (0..session.ticks()).step_by(every) {
        let (t, js) = &session.joint_states[i];
        let mut row = vec![format!("{}", *t as f64 * 1e-9)];
        row.extend(q(i).iter().map(|v| v.to_string()));
        if torques {
            row.extend(js.efforts.iter().map(|v| v.to_string()));
        }
        if wrist {
            let b = bases[i];
            let (p, r) = (b.translation.vector, b.rotation);
            row.extend(
                [p.x, p.y, p.z, r.i, r.j, r.k, r.w]
                    .iter()
                    .map(|v| v.to_string()),
            );
        }
        text += &(row.join(",") + "\n");
    }
    text
}

/// A glove that measures positions only, on an operator squeezing as in the simulated
/// session: a force-feedback glove renders the coupling's spring, so the operator's fingers
/// settle where their muscle torque balances it, `q = q_simulated + τ / k` (per DOF, the
/// coupling's default stiffness k). Recorded every 10 ms (100 Hz, a data glove's rate) with
/// the wrist pose and no torques, it is replayed through the virtual coupling: the fingers
/// close on the sphere and lift it, the operator feels it (feedback torques while holding),
/// and the session segments into the same grasp.
#[test]
fn a_position_only_recording_of_a_grasp_grasps_through_the_virtual_coupling() {
    let (_, path) = sphere_session();
    let session = read_session(path).unwrap();
    let hand = HandModel::glove10();
    let params = DfsParams {
        contact_model: ContactModel::SoftFinger,
        ..DfsParams::default()
    };
    let coupling = VirtualCoupling::for_hand(&hand, &CouplingParams::default(), &params).unwrap();
    let k = coupling.stiffness().to_vec();
    let measured = |i: usize| -> Vec<f64> {
        let js = &session.joint_states[i].1;
        (0..hand.dof())
            .map(|d| js.positions[d] + js.efforts[d] / k[d])
            .collect()
    };
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("data-glove.csv");
    std::fs::write(&csv, csv_of(&session, 10, measured, false, true)).unwrap();
    let rec = services::session::import::read_glove_file(&csv, &hand).unwrap();
    assert!(!rec.has_torques());
    let out = dir.path().join("coupled.mcap");
    import_glove(
        &csv,
        &session_object(&session),
        &ImportOptions::default(),
        &out,
    )
    .unwrap();
    let coupled = read_session(&out).unwrap();
    assert_eq!(coupled.metadata["glove_input"], "positions");
    assert_eq!(coupled.metadata["wrist"], "csv");
    let stiffness: Vec<f64> =
        serde_json::from_str(&coupled.metadata["coupling_stiffness"]).unwrap();
    assert_eq!(stiffness, k);

    // While the original holds the sphere up (its `hold`, 3.1-5.1 s), the coupled replay
    // holds it too: both fingertips push, the sphere is up, the operator feels it through the
    // feedback torques and the coupling torques.
    let z0 = coupled.object[0].1.pose.position.z;
    let (mut pushing, mut lifted, mut feedback, mut coupling_torque) = (0, 0, 0.0f64, 0.0f64);
    let window = 3200..5000;
    for i in window.clone() {
        let c = &coupled.contacts[i].1;
        let normal = |name: &str| {
            c.fingers
                .iter()
                .find(|f| f.name == name)
                .map_or(0.0, |f| f.transmitted.z)
        };
        if normal("thumb") > 1.0 && normal("index") > 1.0 {
            pushing += 1;
        }
        if coupled.object[i].1.pose.position.z - z0 > 0.08 {
            lifted += 1;
        }
        let fb = &coupled.feedback[i].1.feedback_torques;
        feedback = feedback.max(fb.iter().map(|v| v.abs()).fold(0.0, f64::max));
        let tau = &coupled.joint_states[i].1.efforts;
        coupling_torque = coupling_torque.max(tau.iter().map(|v| v.abs()).fold(0.0, f64::max));
    }
    assert_eq!(pushing, window.len(), "thumb and index push throughout");
    assert_eq!(lifted, window.len(), "the sphere stays up");
    assert!(feedback > 0.05, "feedback torque {feedback} N·m");
    assert!(
        coupling_torque > 0.05,
        "coupling torque {coupling_torque} N·m"
    );
    let skills = skills_of(&out);
    assert_eq!(skills.len(), 1);
    assert_eq!(skills[0].parameters.contact_count, 2);
}

/// An MCAP glove recording: joints on `/glove` (JSON `foxglove.JointStates`, 100 Hz) and the
/// wrist from a tracker at its own times (protobuf `foxglove.PoseInFrame` on `/tracker`,
/// 50 Hz, 3 ms after the glove's samples), and the session's own `/tf` beside it.
fn write_glove_mcap(path: &Path, session: &Session, pose_topic: bool, tf: bool) {
    use foxglove::Encode;
    use prost::Message;
    let bases = base_poses(session);
    let mut w = SessionWriter::create(path).unwrap();
    w.register_channel("/glove", &JOINT_STATES_SCHEMA).unwrap();
    if pose_topic {
        let schema = foxglove::messages::PoseInFrame::get_schema().unwrap();
        w.register_protobuf_channel("/tracker", &schema.name, &schema.data)
            .unwrap();
    }
    if tf {
        let schema = foxglove::messages::FrameTransforms::get_schema().unwrap();
        w.register_protobuf_channel("/tf", &schema.name, &schema.data)
            .unwrap();
    }
    let fg_pose = |b: &Isometry| foxglove::messages::Pose {
        position: Some(foxglove::messages::Vector3 {
            x: b.translation.x,
            y: b.translation.y,
            z: b.translation.z,
        }),
        orientation: Some(foxglove::messages::Quaternion {
            x: b.rotation.i,
            y: b.rotation.j,
            z: b.rotation.k,
            w: b.rotation.w,
        }),
    };
    let epoch = 1_700_000_000_000_000_000u64;
    for i in (0..session.ticks()).step_by(10) {
        let (t, js) = &session.joint_states[i];
        let msg = services::foxglove::JointStates {
            timestamp: services::foxglove::Timestamp::from_nanos(*t),
            joints: js
                .names
                .iter()
                .enumerate()
                .map(|(d, name)| services::foxglove::JointState {
                    name: name.clone(),
                    position: Some(js.positions[d]),
                    effort: Some(js.efforts[d]),
                    ..Default::default()
                })
                .collect(),
        };
        w.write("/glove", epoch + t, &msg).unwrap();
        if i % 20 == 0 && i + 3 < session.ticks() {
            let b = &bases[i + 3];
            if pose_topic {
                let m = foxglove::messages::PoseInFrame {
                    timestamp: None,
                    frame_id: "world".into(),
                    pose: Some(fg_pose(b)),
                };
                w.write_raw("/tracker", epoch + t + 3_000_000, &m.encode_to_vec())
                    .unwrap();
            }
            if tf {
                let tr = |child: &str, p: &Isometry| {
                    let fp = fg_pose(p);
                    foxglove::messages::FrameTransform {
                        timestamp: None,
                        parent_frame_id: "world".into(),
                        child_frame_id: child.into(),
                        translation: fp.position,
                        rotation: fp.orientation,
                    }
                };
                let m = foxglove::messages::FrameTransforms {
                    transforms: vec![tr("object", &Isometry::identity()), tr("forearm", b)],
                };
                w.write_raw("/tf", epoch + t + 3_000_000, &m.encode_to_vec())
                    .unwrap();
            }
        }
    }
    w.finish().unwrap();
}

#[test]
fn wrist_poses_come_from_a_pose_in_frame_or_tf_topic_and_are_interpolated() {
    let (_, path) = sphere_session();
    let session = read_session(path).unwrap();
    let bases = base_poses(&session);
    let hand = HandModel::glove10();
    let dir = tempfile::tempdir().unwrap();

    let both = dir.path().join("both.mcap");
    write_glove_mcap(&both, &session, true, true);
    // The PoseInFrame topic is the tracker's; /tf is taken when named, or when alone.
    let rec = read_glove_mcap(&both, &hand).unwrap();
    let wrist = rec.wrist.as_ref().unwrap();
    assert_eq!(wrist.source, "/tracker");
    assert_eq!(wrist.times_ns[0], 3_000_000);
    assert_eq!(wrist.poses.len(), session.ticks().div_ceil(20));
    let tf = read_glove_mcap_with(&both, &hand, &WristInput::Topic("/tf".into())).unwrap();
    assert_eq!(tf.wrist.as_ref().unwrap().source, "/tf");
    assert_eq!(tf.wrist.as_ref().unwrap().poses, wrist.poses);
    let none = read_glove_mcap_with(&both, &hand, &WristInput::Ignore).unwrap();
    assert!(none.wrist.is_none());
    let e = read_glove_mcap_with(&both, &hand, &WristInput::Topic("/glove".into()))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("/glove") && e.contains("foxglove.JointStates"),
        "{e}"
    );
    let e = read_glove_mcap_with(&both, &hand, &WristInput::Topic("/nope".into()))
        .unwrap_err()
        .to_string();
    assert!(e.contains("no topic \"/nope\""), "{e}");
    let tf_only = dir.path().join("tf.mcap");
    write_glove_mcap(&tf_only, &session, false, true);
    let rec_tf = read_glove_mcap(&tf_only, &hand).unwrap();
    assert_eq!(rec_tf.wrist.as_ref().unwrap().source, "/tf");

    // Imported: the session's base follows the tracker, interpolated between its samples,
    // and the grasp is found again.
    let out = dir.path().join("from-mcap.mcap");
    import_glove(
        &both,
        &session_object(&session),
        &ImportOptions::default(),
        &out,
    )
    .unwrap();
    let imported = read_session(&out).unwrap();
    assert_eq!(imported.metadata["wrist"], "/tracker");
    let got = base_poses(&imported);
    for i in (3..got.len() - 20).step_by(20) {
        // At a tracker sample: its pose (to the file's 1 µm and 1e-6 resolution).
        assert!((got[i].translation.vector - bases[i].translation.vector).norm() < 1e-5);
        assert!(got[i].rotation.angle_to(&bases[i].rotation) < 1e-5);
        // Between two: on the way from one to the other.
        let mid = got[i + 10].translation.vector;
        let expected = 0.5 * (bases[i].translation.vector + bases[i + 20].translation.vector);
        assert!((mid - expected).norm() < 1e-5, "tick {}", i + 10);
    }
    let skills = skills_of(&out);
    assert_eq!(skills.len(), 1);
}

#[test]
fn any_hand_is_a_glove_model_and_its_dofs_name_the_columns() {
    let hand = builtin_hand("allegro").unwrap();
    let n = hand.dof();
    let mut text = String::from("time_s");
    for name in &hand.dof_names {
        text += &format!(",{name}");
    }
    text += &format!(",{}\n", WRIST_COLUMNS.join(","));
    for i in 0..300 {
        let t = i as f64 * 0.004;
        text += &format!("{t}");
        for d in 0..n {
            let (lo, hi) = hand.sweep_range(d);
            let f = 0.3 + 0.2 * (t * 3.0).sin();
            text += &format!(",{}", lo + f * (hi - lo));
        }
        // The hand rises 5 cm and turns a little about z.
        let yaw: f64 = 0.2 * t;
        let q = Rotation::from_euler_angles(0.0, 0.0, yaw);
        text += &format!(
            ",0.1,0.0,{},{},{},{},{}\n",
            0.2 + 0.05 * t,
            q.i,
            q.j,
            q.k,
            q.w
        );
    }
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("allegro.csv");
    std::fs::write(&csv, &text).unwrap();
    let options = ImportOptions {
        hand: hand.clone(),
        hand_urdf: Some(dfs_core::hand::builtin::ALLEGRO_URDF.to_owned()),
        ..ImportOptions::default()
    };
    let out = dir.path().join("allegro.mcap");
    let object = Scenario::builtin("sphere-lift", 0).unwrap().object.unwrap();
    let summary = import_glove(&csv, &object, &options, &out).unwrap();
    assert_eq!(summary.ticks, 1197);
    let s = read_session(&out).unwrap();
    assert_eq!(s.metadata["hand"], "allegro");
    assert_eq!(s.metadata["glove_input"], "positions");
    assert_eq!(s.joint_states[0].1.names, hand.dof_names);
    // The base followed the wrist columns: 5 cm up over 1.196 s, turned 0.2 rad/s.
    let bases = base_poses(&s);
    let last = bases.last().unwrap();
    assert!((last.translation.z - (0.2 + 0.05 * 1.196)).abs() < 1e-5);
    assert!((last.rotation.angle() - 0.2 * 1.196).abs() < 1e-5);
    // The simulated hand followed the measured posture (coupled, nothing touched), within the
    // coupling's lag: about 25 ms on Allegro's fingers, here moving at up to 1.1 rad/s.
    let rec = parse_glove_csv(&text, "allegro.csv", &hand).unwrap();
    let mut q = vec![0.0; n];
    let mut tau = vec![0.0; n];
    rec.interpolate(1_000_000_000, &mut q, &mut tau);
    let motor = &s.feedback[1000].1.motor_positions;
    for d in 0..n {
        assert!(
            (motor[d] - q[d]).abs() < 0.04,
            "DOF {d}: {} vs {}",
            motor[d],
            q[d]
        );
    }

    // glove10's columns are not Allegro's.
    let (_, path) = sphere_session();
    let glove = dir.path().join("glove10.csv");
    export_glove_csv(path, &glove).unwrap();
    let e = import_glove(&glove, &object, &options, &dir.path().join("x.mcap"))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("line 1, column 2") && e.contains("\"wrist_roll\"") && e.contains("allegro"),
        "{e}"
    );
}

#[test]
fn a_calibration_maps_the_recorded_angles_and_bad_ones_are_refused() {
    let (_, path) = sphere_session();
    let session = read_session(path).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("glove.csv");
    // One second of the session, its angles as a glove reading them 10 % high and 0.02 rad
    // short on the index MCP would give them.
    let hand = HandModel::glove10();
    let mcp = hand
        .dof_names
        .iter()
        .position(|s| s == "index_mcp")
        .unwrap();
    let raw = |i: usize| -> Vec<f64> {
        let mut q = session.joint_states[i].1.positions.clone();
        q[mcp] = (q[mcp] - 0.02) / 1.1;
        q
    };
    let one_second = Session {
        joint_states: session.joint_states[..1000].to_vec(),
        object: session.object[..1000].to_vec(),
        ..session.clone()
    };
    std::fs::write(&csv, csv_of(&one_second, 1, raw, true, true)).unwrap();
    let calibration: Calibration =
        serde_json::from_str(r#"{"offsets": {"index_mcp": 0.02}, "scales": {"index_mcp": 1.1}}"#)
            .unwrap();
    let options = ImportOptions {
        calibration: Some(calibration.clone()),
        ..ImportOptions::default()
    };
    let out = dir.path().join("calibrated.mcap");
    import_glove(&csv, &session_object(&session), &options, &out).unwrap();
    let s = read_session(&out).unwrap();
    assert_eq!(
        serde_json::from_str::<Calibration>(&s.metadata["calibration"]).unwrap(),
        calibration
    );
    for i in (0..1000).step_by(50) {
        let (got, want) = (
            &s.joint_states[i].1.positions,
            &session.joint_states[i].1.positions,
        );
        for d in 0..hand.dof() {
            assert!((got[d] - want[d]).abs() < 2e-5, "tick {i} DOF {d}");
        }
    }
    let bad: Calibration = serde_json::from_str(r#"{"scales": {"pinky_twist": 1.1}}"#).unwrap();
    let e = import_glove(
        &csv,
        &session_object(&session),
        &ImportOptions {
            calibration: Some(bad),
            ..ImportOptions::default()
        },
        &dir.path().join("bad.mcap"),
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("scales.pinky_twist") && e.contains("unknown DOF of glove10"),
        "{e}"
    );
}

#[test]
fn bad_wrist_and_torque_columns_are_refused_naming_the_line_and_column() {
    let hand = HandModel::glove10();
    let names = hand.dof_names.join(",");
    let taus: Vec<String> = hand.dof_names.iter().map(|n| format!("tau_{n}")).collect();
    let zeros = |k: usize| vec!["0"; k].join(",");
    let err = |text: String| {
        parse_glove_csv(&text, "g.csv", &hand)
            .unwrap_err()
            .to_string()
    };
    let n = hand.dof();
    // Some wrist columns but not all.
    let e = err(format!(
        "time_s,{names},wrist_x,wrist_y,wrist_z\n0,{},0,0,0\n",
        zeros(n)
    ));
    assert!(
        e.contains("line 1") && e.contains("missing column wrist_qx"),
        "{e}"
    );
    // Some torques but not all.
    let e = err(format!("time_s,{names},{}\n0,{},0\n", taus[0], zeros(n)));
    assert!(
        e.contains("missing column tau_wrist_pitch") && e.contains("or for none"),
        "{e}"
    );
    // A zero quaternion on line 3 (after a comment line), and one that is not a number.
    let header = format!("time_s,{names},{}", WRIST_COLUMNS.join(","));
    let e = err(format!(
        "{header}\n0,{},0,0,0,0,0,0,1\n# a comment\n0.01,{},0,0,0,0,0,0,0\n",
        zeros(n),
        zeros(n)
    ));
    assert!(
        e.contains("g.csv line 4, columns wrist_qx,wrist_qy,wrist_qz,wrist_qw")
            && e.contains("not a rotation"),
        "{e}"
    );
    let e = err(format!("{header}\n0,{},0,0,0,0,0,nan,1\n", zeros(n)));
    assert!(
        e.contains("line 2, column wrist_qz") && e.contains("finite"),
        "{e}"
    );
    let e = err(format!(
        "{header},wrist_x\n0,{},0,0,0,0,0,0,1,0\n",
        zeros(n)
    ));
    assert!(e.contains("\"wrist_x\" appears twice"), "{e}");
    // A quaternion of any length is normalised.
    let rec = parse_glove_csv(
        &format!("{header}\n0,{},1,2,3,0,0,0,2\n", zeros(n)),
        "g.csv",
        &hand,
    )
    .unwrap();
    let pose = rec.wrist.unwrap().poses[0];
    assert_eq!(pose.rotation, Rotation::identity());
    assert_eq!(pose.translation.vector, Vector::new(1.0, 2.0, 3.0));
    assert!(rec.tau.is_none());
}

#[test]
fn bad_wrist_messages_in_an_mcap_are_refused_naming_the_message() {
    use foxglove::Encode;
    use prost::Message;
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bad.mcap");
    let hand = HandModel::glove10();
    let mut w = SessionWriter::create(&path).unwrap();
    w.register_channel("/glove", &JOINT_STATES_SCHEMA).unwrap();
    let schema = foxglove::messages::PoseInFrame::get_schema().unwrap();
    w.register_protobuf_channel("/tracker", &schema.name, &schema.data)
        .unwrap();
    for i in 0..3u64 {
        let msg = services::foxglove::JointStates {
            timestamp: Default::default(),
            joints: hand
                .dof_names
                .iter()
                .map(|name| services::foxglove::JointState {
                    name: name.clone(),
                    position: Some(0.1),
                    ..Default::default()
                })
                .collect(),
        };
        w.write("/glove", i * 10_000_000, &msg).unwrap();
        let q = if i == 2 { 0.0 } else { 1.0 };
        let m = foxglove::messages::PoseInFrame {
            timestamp: None,
            frame_id: "world".into(),
            pose: Some(foxglove::messages::Pose {
                position: None,
                orientation: Some(foxglove::messages::Quaternion {
                    x: 0.0,
                    y: 0.0,
                    z: 0.0,
                    w: q,
                }),
            }),
        };
        w.write_raw("/tracker", i * 10_000_000, &m.encode_to_vec())
            .unwrap();
    }
    w.finish().unwrap();
    let e = read_glove_mcap(&path, &hand).unwrap_err().to_string();
    assert!(
        e.contains("/tracker message 2") && e.contains("not a rotation"),
        "{e}"
    );
    // Positions only (no efforts): read as a position-only glove.
    let rec = read_glove_mcap_with(&path, &hand, &WristInput::Ignore).unwrap();
    assert!(!rec.has_torques() && rec.wrist.is_none());
}

/// Every grasp the built-in scenarios make, exported and imported again, gives its skills
/// again (within the tolerances of [`assert_same_skills`]): the pinched sphere (seeds 0-7)
/// and box (seeds 0-3) within [`PINCH`], and glove10's power grasp of the cylinder (seeds
/// 0-3) within 6 mm, 3 mm and 10°, its key poses 7 mm. That grasp holds at the edge of its
/// friction cones (its friction margin is 0: the pads creep round the cylinder, and the middle
/// finger only rests on it), and where the pads settle comes back a little apart, the same for
/// every seed: contacts 5 mm, their spans 1.7 mm, their normals 9-9.4°, the carried cylinder
/// 5 mm (phases to the microsecond, internal force within 0.8 %, ε within 1.1 %). Set down, it
/// lands on its rim and the table, pushing only there, rocks it back upright: its key pose then
/// comes back 5.8-6.6 mm apart (under 6 mm when the table held a landing object still).
#[test]
fn every_builtin_grasp_exported_and_imported_again_gives_the_same_skills() {
    let dir = tempfile::tempdir().unwrap();
    let power = Tolerance {
        position_m: 6e-3,
        motion_m: 7e-3,
        span_m: 3e-3,
        normals_deg: 10.0,
    };
    // The power grasp is imported with the whole hand, as it was simulated.
    for (name, seeds, tol, whole_hand) in [
        ("sphere-lift", 0..8, PINCH, false),
        ("box-pinch-lift", 0..4, PINCH, false),
        ("cylinder-power-grasp", 0..4, power, true),
    ] {
        for seed in seeds {
            let scenario = Scenario::builtin(name, seed).unwrap();
            let session = dir.path().join(format!("{name}-{seed}.mcap"));
            record_simulation(&scenario, None, &session, |_, _| {}).unwrap();
            let csv = dir.path().join(format!("{name}-{seed}.csv"));
            export_glove_csv(&session, &csv).unwrap();
            let again = dir.path().join(format!("{name}-{seed}-again.mcap"));
            let options = ImportOptions {
                whole_hand,
                ..ImportOptions::default()
            };
            import_glove(&csv, scenario.target_object().unwrap(), &options, &again).unwrap();
            let (a, b) = (skills_of(&session), skills_of(&again));
            assert_eq!(a.len(), 1, "{name} seed {seed}");
            let same = std::panic::catch_unwind(|| assert_same_skills(&a, &b, &tol));
            assert!(same.is_ok(), "{name} seed {seed}");
        }
    }
}
