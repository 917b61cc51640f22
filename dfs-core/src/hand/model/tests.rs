//! Tests of the hand model: validation, kinematics against finite differences, M(θ)
//! against the sum over the links.

use super::dynamics::LinkAxes;
use super::*;
use proptest::prelude::*;

/// A symmetric positive-definite inertia with off-diagonal terms (kg·m²).
fn inertia(scale: f64) -> Mat3 {
    Mat3::new(2.0, 0.3, -0.1, 0.3, 1.5, 0.2, -0.1, 0.2, 1.0) * scale
}

fn link(name: &str, mass: f64, com: [f64; 3]) -> Link {
    let inertial = Inertial {
        mass,
        com: Vector::from(com),
        inertia: inertia(mass * 1e-4),
    };
    Link {
        name: name.to_owned(),
        inertial,
    }
}

#[allow(clippy::too_many_arguments)]
fn joint(
    name: &str,
    kind: JointKind,
    parent: usize,
    child: usize,
    origin: Isometry,
    axis: Vector,
    limits: (f64, f64),
    drive: JointDrive,
) -> Joint {
    let axis = UnitVector::new_normalize(axis);
    let (lower, upper) = limits;
    Joint {
        name: name.to_owned(),
        kind,
        parent,
        child,
        origin,
        axis,
        lower,
        upper,
        drive,
    }
}

fn pose(t: [f64; 3], r: [f64; 3]) -> Isometry {
    Isometry::new(Vector::from(t), Vector::from(r))
}

/// A small hand exercising every joint kind: a prismatic carriage (DOF 0) carrying finger
/// "a" (continuous DOF 1, revolute DOF 2, a fixed joint) and finger "b" (revolute DOF 3
/// about a skew axis, then a mimic of DOF 3 with multiplier 0.7 and offset 0.1).
pub(crate) fn test_hand() -> HandModel {
    let inf = f64::INFINITY;
    let links = vec![
        link("base", 1.0, [0.0; 3]),
        link("carriage", 0.1, [0.01, 0.0, 0.0]),
        link("a1", 0.05, [0.02, 0.001, 0.0]),
        link("a2", 0.03, [0.01, 0.0, -0.002]),
        link("a_tip", 0.01, [0.005, 0.0, 0.0]),
        link("b1", 0.04, [0.015, 0.0, 0.0]),
        link("b2", 0.02, [0.012, 0.002, 0.0]),
    ];
    let (p, c, r, f) = (
        JointKind::Prismatic,
        JointKind::Continuous,
        JointKind::Revolute,
        JointKind::Fixed,
    );
    let joints = vec![
        joint(
            "slide",
            p,
            0,
            1,
            pose([0.01, 0.0, 0.02], [0.1, 0.2, 0.3]),
            Vector::new(1.0, 0.2, 0.0),
            (-0.05, 0.05),
            JointDrive::Dof(0),
        ),
        joint(
            "a_spin",
            c,
            1,
            2,
            pose([0.03, 0.0, 0.0], [0.0, 0.0, 0.4]),
            Vector::z(),
            (-inf, inf),
            JointDrive::Dof(1),
        ),
        joint(
            "a_flex",
            r,
            2,
            3,
            pose([0.04, 0.0, 0.0], [0.2, 0.0, 0.0]),
            Vector::y(),
            (-1.0, 1.5),
            JointDrive::Dof(2),
        ),
        joint(
            "a_fixed",
            f,
            3,
            4,
            pose([0.02, 0.0, 0.005], [0.0, 0.3, 0.0]),
            Vector::x(),
            (0.0, 0.0),
            JointDrive::Fixed,
        ),
        joint(
            "b_flex",
            r,
            1,
            5,
            pose([0.0, 0.02, 0.0], [0.0; 3]),
            Vector::new(0.0, 1.0, 1.0),
            (-0.5, 1.2),
            JointDrive::Dof(3),
        ),
        joint(
            "b_coupled",
            r,
            5,
            6,
            pose([0.03, 0.0, 0.0], [0.0; 3]),
            Vector::y(),
            (-0.25, 0.94),
            JointDrive::Mimic {
                dof: 3,
                multiplier: 0.7,
                offset: 0.1,
            },
        ),
    ];
    let mut hand = HandModel {
        name: "test".to_owned(),
        links,
        joints,
        root: 0,
        dof_names: ["slide", "a_spin", "a_flex", "b_flex"]
            .map(String::from)
            .to_vec(),
        dof_lower: vec![-0.05, -inf, -1.0, -0.5],
        dof_upper: vec![0.05, inf, 1.5, 1.2],
        torque_limit: vec![10.0, 1.0, 1.0, 1.0],
        armature: vec![1e-5; 4],
        fingertips: vec![
            Fingertip {
                name: "a".into(),
                link: 4,
                offset: Vector::new(0.01, 0.0, 0.0),
                radius: 0.008,
            },
            Fingertip {
                name: "b".into(),
                link: 6,
                offset: Vector::new(0.025, 0.0, 0.0),
                radius: 0.008,
            },
        ],
        finger_groups: Vec::new(),
        contact_shapes: Vec::new(),
    };
    hand.compute_finger_groups();
    hand
}

/// Joint angles within the limits from unit-interval samples (infinite limits → ±3).
pub(crate) fn angles_from_unit(hand: &HandModel, u: &[f64]) -> Vec<f64> {
    (0..hand.dof())
        .map(|i| {
            let lo = hand.dof_lower[i].max(-3.0);
            let hi = hand.dof_upper[i].min(3.0);
            lo + u[i] * (hi - lo)
        })
        .collect()
}

fn base() -> Isometry {
    pose([0.1, -0.2, 0.3], [0.3, -0.5, 0.7])
}

fn fk(hand: &HandModel, q: &[f64]) -> Kinematics {
    let mut kin = Kinematics::default();
    hand.forward_kinematics(&base(), q, &mut kin);
    kin
}

fn invalid_field(result: Result<()>) -> String {
    match result {
        Err(DfsError::Invalid { field, .. }) => field,
        other => panic!("expected an invalid-model error, got {other:?}"),
    }
}

#[test]
fn test_hand_and_glove10_are_valid() {
    test_hand().validate().unwrap();
    HandModel::glove10().validate().unwrap();
}

#[test]
fn validation_names_the_offending_field() {
    type Corrupt = fn(&mut HandModel);
    let cases: Vec<(Corrupt, &str)> = vec![
        (|h| h.root = 99, "root"),
        (|h| h.joints[1].child = 0, "joints[1].child"),
        (|h| h.joints[5].child = 3, "joints[5].child"),
        (|h| h.joints[2].parent = 42, "joints[2].parent"),
        (|h| h.joints.swap(1, 2), "joints[1].parent"),
        (
            |h| {
                h.joints[5].drive = JointDrive::Mimic {
                    dof: 7,
                    multiplier: 1.0,
                    offset: 0.0,
                }
            },
            "joints[5].drive",
        ),
        (
            |h| h.joints[3].drive = JointDrive::Dof(0),
            "joints[3].drive",
        ),
        (|h| h.joints[2].lower = 2.0, "joints[2].lower"),
        (|h| h.dof_lower[2] = 2.0, "dof_lower[2]"),
        (
            |h| h.links[3].inertial.mass = -1.0,
            "links[3].inertial.mass",
        ),
        (
            |h| h.links[2].inertial.inertia[(0, 1)] = f64::NAN,
            "links[2].inertial.inertia",
        ),
        (|h| h.fingertips[1].radius = 0.0, "fingertips[1].radius"),
        (|h| h.fingertips[0].link = 9, "fingertips[0].link"),
        (|h| h.torque_limit[3] = 0.0, "torque_limit[3]"),
        (|h| h.armature.pop().map(drop).unwrap_or(()), "armature"),
        (|h| h.dof_names.push("extra".into()), "dof_lower"),
        (|h| h.joints.pop().map(drop).unwrap_or(()), "links[6]"),
        (|h| h.links[5].name = "a1".into(), "links[5].name"),
        (
            |h| h.finger_groups[0].dofs.push(11),
            "finger_groups[0].dofs",
        ),
    ];
    for (corrupt, field) in cases {
        let mut hand = test_hand();
        corrupt(&mut hand);
        assert_eq!(invalid_field(hand.validate()), field);
    }
}

#[test]
fn validation_rejects_models_beyond_capacity() {
    let mut hand = test_hand();
    hand.fingertips = vec![hand.fingertips[0].clone(); MAX_TIPS + 1];
    assert_eq!(invalid_field(hand.validate()), "fingertips");
    let mut hand = test_hand();
    hand.dof_names = (0..=MAX_DOF).map(|i| format!("d{i}")).collect();
    assert_eq!(invalid_field(hand.validate()), "dof_names");
    // The hand's own capacity leaves room for the planners' free base.
    hand.dof_names.truncate(MAX_HAND_DOF + 1);
    let e = hand.validate().unwrap_err().to_string();
    assert!(
        e.contains("the hand has 33 DOFs") && e.contains("at most 32 are accepted"),
        "{e}"
    );
    let mut hand = test_hand();
    let link = hand.links[0].clone();
    hand.links.resize(MAX_HAND_LINKS + 1, link);
    assert_eq!(invalid_field(hand.validate()), "links");
}

#[test]
fn angle_check_reports_length_non_finite_and_range() {
    let hand = test_hand();
    assert!(hand.check_angles(&[0.0, 10.0, 0.2, 0.3], 0.0).is_ok());
    assert!(matches!(
        hand.check_angles(&[0.0; 3], 0.0),
        Err(DfsError::WrongLength {
            got: 3,
            expected: 4,
            ..
        })
    ));
    let nan = hand.check_angles(&[0.0, f64::NAN, 0.0, 0.0], 0.0);
    assert!(matches!(
        nan,
        Err(DfsError::NotFinite {
            what: "joint angle",
            index: 1,
            ..
        })
    ));
    let out = hand.check_angles(&[0.0, 0.0, 1.6, 0.0], 0.05);
    assert!(matches!(out, Err(DfsError::OutOfRange { index: 2, .. })));
    assert!(hand.check_angles(&[0.0, 0.0, 1.54, 0.0], 0.05).is_ok());
}

#[test]
fn finger_groups_drop_the_dofs_shared_by_every_tip() {
    let hand = test_hand();
    let expected = vec![
        FingerGroup {
            tips: vec![0],
            dofs: vec![1, 2],
        },
        FingerGroup {
            tips: vec![1],
            dofs: vec![3],
        },
    ];
    assert_eq!(hand.finger_groups, expected);
}

#[test]
fn a_tip_without_dofs_forms_its_own_empty_group() {
    let mut hand = test_hand();
    hand.fingertips.push(Fingertip {
        name: "palm".into(),
        link: 0,
        offset: Vector::zeros(),
        radius: 0.01,
    });
    hand.compute_finger_groups();
    assert_eq!(hand.finger_groups.len(), 2);
    // Nothing is shared by all three tips now, so the slide DOF stays with both fingers,
    // which joins them.
    assert_eq!(
        hand.finger_groups[0],
        FingerGroup {
            tips: vec![0, 1],
            dofs: vec![0, 1, 2, 3]
        }
    );
    assert_eq!(
        hand.finger_groups[1],
        FingerGroup {
            tips: vec![2],
            dofs: vec![]
        }
    );
}

#[test]
fn forward_kinematics_applies_prismatic_revolute_and_mimic_motion() {
    let hand = test_hand();
    let q0 = [0.0; 4];
    let k0 = fk(&hand, &q0);
    // The prismatic DOF translates every finger along the world slide axis.
    let k1 = fk(&hand, &[0.03, 0.0, 0.0, 0.0]);
    let axis = k0.joint_axes[0];
    for t in 0..2 {
        let d = k1.tip_centres[t] - k0.tip_centres[t];
        assert!((d - axis * 0.03).norm() < 1e-12);
    }
    // The mimic joint turns by 0.7 θ + 0.1 about its axis through its origin.
    let q = [0.0, 0.0, 0.0, 0.4];
    let k = fk(&hand, &q);
    let relative = k.link_poses[5].inverse() * k.link_poses[6];
    let angle = relative.rotation.angle();
    assert!((angle - (0.7 * 0.4 + 0.1)).abs() < 1e-12);
    // Fixed joints carry their child rigidly.
    let fixed = k.link_poses[3].inverse() * k.link_poses[4];
    assert!((fixed.to_homogeneous() - hand.joints[3].origin.to_homogeneous()).norm() < 1e-12);
    // The root sits at the base pose.
    assert_eq!(k.link_poses[0], base());
}

/// World angular velocity from two orientations `h` apart on either side.
fn angular_fd(plus: &Isometry, minus: &Isometry, h: f64) -> Vector {
    (plus.rotation * minus.rotation.inverse()).scaled_axis() / (2.0 * h)
}

pub(crate) fn assert_jacobians_match_finite_differences(hand: &HandModel, q: &[f64]) {
    let mut kin = fk(hand, q);
    hand.tip_jacobians(&mut kin);
    let h = 1e-6;
    for d in 0..hand.dof() {
        let (mut qp, mut qm) = (q.to_vec(), q.to_vec());
        qp[d] += h;
        qm[d] -= h;
        let (kp, km) = (fk(hand, &qp), fk(hand, &qm));
        for (k, tip) in hand.fingertips.iter().enumerate() {
            let linear = (kp.tip_centres[k] - km.tip_centres[k]) / (2.0 * h);
            let angular = angular_fd(&kp.link_poses[tip.link], &km.link_poses[tip.link], h);
            let col = kin.tip_jacobians[k].column(d);
            let err_v = (col.fixed_rows::<3>(0) - linear).norm();
            let err_w = (col.fixed_rows::<3>(3) - angular).norm();
            assert!(
                err_v < 1e-7 && err_w < 1e-6,
                "tip {k} dof {d}: {err_v} {err_w}"
            );
        }
    }
    for col in hand.dof()..MAX_DOF {
        assert!(kin.tip_jacobians[0].column(col).iter().all(|&x| x == 0.0));
    }
}

/// ½ Σ_links (m |v_com|² + ωᵀ I_world ω) from central differences of the link poses along θ̇.
fn link_energy_fd(hand: &HandModel, q: &[f64], qdot: &[f64]) -> f64 {
    let h = 1e-6;
    let qp: Vec<f64> = q.iter().zip(qdot).map(|(a, b)| a + h * b).collect();
    let qm: Vec<f64> = q.iter().zip(qdot).map(|(a, b)| a - h * b).collect();
    let (k, kp, km) = (fk(hand, q), fk(hand, &qp), fk(hand, &qm));
    let mut energy = 0.0;
    for (l, link) in hand.links.iter().enumerate() {
        let com = Point::from(link.inertial.com);
        let v = (kp.link_poses[l] * com - km.link_poses[l] * com) / (2.0 * h);
        let w = angular_fd(&kp.link_poses[l], &km.link_poses[l], h);
        let r = k.link_poses[l].rotation.to_rotation_matrix();
        let i_world = r.matrix() * link.inertial.inertia * r.matrix().transpose();
        energy += 0.5 * (link.inertial.mass * v.norm_squared() + w.dot(&(i_world * w)));
    }
    energy
}

pub(crate) fn assert_mass_matrix_is_consistent(hand: &HandModel, q: &[f64], qdot: &[f64]) {
    let n = hand.dof();
    let mut kin = fk(hand, q);
    let mut m = DofMatrix::identity();
    hand.mass_matrix(&mut kin, &mut m);
    assert!((m - m.transpose()).amax() < 1e-15);
    assert!(m.cholesky().is_some(), "M is not positive definite");
    let mut rest = m;
    rest.view_mut((0, 0), (n, n)).fill_with_identity();
    assert_eq!(rest, DofMatrix::identity());
    let mut qd = nalgebra::SVector::<f64, MAX_DOF>::zeros();
    qd.as_mut_slice()[..n].copy_from_slice(qdot);
    let armature: f64 = (0..n)
        .map(|i| 0.5 * hand.armature[i] * qdot[i] * qdot[i])
        .sum();
    let energy = 0.5 * qd.dot(&(m * qd)) - armature;
    let expected = link_energy_fd(hand, q, qdot);
    assert!(
        (energy - expected).abs() < 1e-9 * (1.0 + expected),
        "{energy} vs {expected}"
    );
}

proptest! {
    #[test]
    fn tip_jacobians_match_finite_differences_of_forward_kinematics(u in prop::collection::vec(0.0..1.0f64, 10)) {
        let hand = test_hand();
        assert_jacobians_match_finite_differences(&hand, &angles_from_unit(&hand, &u));
        let glove = HandModel::glove10();
        assert_jacobians_match_finite_differences(&glove, &angles_from_unit(&glove, &u));
    }

    #[test]
    fn the_planned_kinematics_and_inertia_equal_the_general_forms(
        u in prop::collection::vec(0.0..1.0f64, MAX_DOF),
        rpy in prop::array::uniform3(-3.0..3.0f64),
    ) {
        let base = Isometry::from_parts(
            Vector::new(0.1, -0.2, 0.3).into(),
            Rotation::from_euler_angles(rpy[0], rpy[1], rpy[2]),
        );
        for name in crate::hand::BUILTIN_HANDS {
            let hand = crate::hand::builtin_hand(name).unwrap();
            let q = angles_from_unit(&hand, &u[..hand.dof()]);
            let (mut general, mut planned) = (Kinematics::default(), Kinematics::default());
            hand.forward_kinematics(&base, &q, &mut general);
            hand.forward_kinematics_planned(&hand.fk_plan(), &base, &q, &mut planned);
            for l in 0..hand.links.len() {
                let (a, b) = (&general.link_poses[l], &planned.link_poses[l]);
                prop_assert!((a.translation.vector - b.translation.vector).norm() < 1e-12);
                prop_assert!(a.rotation.angle_to(&b.rotation) < 1e-12, "{name} link {l}");
            }
            for j in 0..hand.joints.len() {
                prop_assert!((general.joint_axes[j] - planned.joint_axes[j]).norm() < 1e-12);
                prop_assert_eq!(general.parent_joint[hand.joints[j].child], j);
                prop_assert_eq!(planned.parent_joint[hand.joints[j].child], j);
            }
            for k in 0..hand.fingertips.len() {
                prop_assert!((general.tip_centres[k] - planned.tip_centres[k]).norm() < 1e-12);
            }
            // The axial form of a link's inertia against the principal-axes sums.
            let plan = hand.mass_plan();
            let mut principal = plan;
            for a in principal.link_axes.iter_mut() {
                if matches!(a, LinkAxes::Axial { .. }) {
                    *a = LinkAxes::Principal;
                }
            }
            let (mut m1, mut m2) = (DofMatrix::zeros(), DofMatrix::zeros());
            hand.mass_matrix_planned(&plan, &mut planned, &mut m1);
            hand.mass_matrix_planned(&principal, &mut planned, &mut m2);
            let scale = m2.amax().max(1e-12);
            prop_assert!((m1 - m2).amax() <= 1e-12 * scale, "{name}: {}", (m1 - m2).amax());
        }
        // glove10's phalanges take the axial form.
        let glove = HandModel::glove10();
        let axial = glove.mass_plan().link_axes.iter().filter(|a| matches!(a, LinkAxes::Axial { .. })).count();
        prop_assert!(axial >= 12, "{axial}");
    }

    #[test]
    fn kinetic_energy_of_the_mass_matrix_equals_the_sum_of_link_energies(
        u in prop::collection::vec(0.0..1.0f64, 10),
        qdot in prop::collection::vec(-2.0..2.0f64, 10),
    ) {
        let hand = test_hand();
        assert_mass_matrix_is_consistent(&hand, &angles_from_unit(&hand, &u), &qdot[..4]);
        let glove = HandModel::glove10();
        assert_mass_matrix_is_consistent(&glove, &angles_from_unit(&glove, &u), &qdot);
    }
}

#[test]
fn a_single_pendulum_has_the_analytic_inertia() {
    let (mass, length, com) = (0.5, 0.2, 0.08);
    let izz = mass * length * length / 12.0;
    let inertial = Inertial {
        mass,
        com: Vector::new(com, 0.0, 0.0),
        inertia: Mat3::from_diagonal(&Vector::new(1e-6, izz, izz)),
    };
    let hand = HandModel {
        name: "pendulum".into(),
        links: vec![
            Link {
                name: "base".into(),
                inertial: Inertial::default(),
            },
            Link {
                name: "arm".into(),
                inertial,
            },
        ],
        joints: vec![joint(
            "pivot",
            JointKind::Revolute,
            0,
            1,
            Isometry::identity(),
            Vector::z(),
            (-3.0, 3.0),
            JointDrive::Dof(0),
        )],
        root: 0,
        dof_names: vec!["pivot".into()],
        dof_lower: vec![-3.0],
        dof_upper: vec![3.0],
        torque_limit: vec![1.0],
        armature: vec![1e-4],
        fingertips: vec![Fingertip {
            name: "tip".into(),
            link: 1,
            offset: Vector::new(length, 0.0, 0.0),
            radius: 0.01,
        }],
        finger_groups: Vec::new(),
        contact_shapes: Vec::new(),
    };
    hand.validate().unwrap();
    for angle in [-1.0, 0.0, 0.7] {
        let mut kin = fk(&hand, &[angle]);
        let mut m = DofMatrix::identity();
        hand.mass_matrix(&mut kin, &mut m);
        let expected = izz + mass * com * com + 1e-4;
        assert!((m[(0, 0)] - expected).abs() < 1e-15);
    }
}

#[test]
fn the_inertia_coupling_covers_every_nonzero_of_the_mass_matrix() {
    // The implicit finger step's envelope Cholesky relies on it: an entry of M(θ) outside
    // the coupling would be silently dropped.
    let mut hands = vec![HandModel::glove10(), test_hand()];
    for name in ["allegro", "barrett", "inspire", "gripper"] {
        hands.push(crate::hand::builtin::builtin_hand(name).expect(name));
    }
    for hand in &hands {
        let n = hand.dof();
        let coupling = hand.inertia_coupling();
        for seed in 0..5 {
            let u: Vec<f64> = (0..n)
                .map(|d| ((d * 7 + seed * 13) % 11) as f64 / 10.0)
                .collect();
            let q = angles_from_unit(hand, &u);
            let mut kin = Kinematics::default();
            hand.forward_kinematics(&base(), &q, &mut kin);
            let mut m = DofMatrix::zeros();
            hand.mass_matrix(&mut kin, &mut m);
            for a in 0..n {
                assert!(
                    coupling[a] & (1 << a) != 0,
                    "{}: DOF {a} not coupled to itself",
                    hand.name
                );
                for b in 0..n {
                    if coupling[a] & (1 << b) == 0 {
                        assert_eq!(
                            m[(a, b)],
                            0.0,
                            "{}: M[{a}][{b}] outside the coupling",
                            hand.name
                        );
                    }
                    assert_eq!(coupling[a] & (1 << b) != 0, coupling[b] & (1 << a) != 0);
                }
            }
        }
    }
}

#[test]
fn a_stretched_finger_gives_finite_jacobians_and_inertia() {
    let glove = HandModel::glove10();
    let mut kin = fk(&glove, &[0.0; 10]);
    glove.tip_jacobians(&mut kin);
    let mut m = DofMatrix::identity();
    glove.mass_matrix(&mut kin, &mut m);
    assert!(kin
        .tip_jacobians
        .iter()
        .all(|j| j.iter().all(|x| x.is_finite())));
    assert!(m.iter().all(|x| x.is_finite()));
    assert!(m.cholesky().is_some());
}

proptest! {
    #[test]
    fn the_dof_cholesky_solve_inverts_the_mass_matrix(
        u in prop::collection::vec(0.0..1.0f64, 10),
        b in prop::collection::vec(-1.0..1.0f64, 10),
    ) {
        let glove = HandModel::glove10();
        let mut kin = fk(&glove, &angles_from_unit(&glove, &u));
        let mut m = DofMatrix::identity();
        glove.mass_matrix(&mut kin, &mut m);
        let mut rhs = DofVector::zeros();
        rhs.as_mut_slice()[..10].copy_from_slice(&b);
        let x = solve_dof_spd(&m, &rhs, 10).unwrap();
        let reference = m.cholesky().unwrap().solve(&rhs);
        prop_assert!((x - reference).amax() <= 1e-9 * reference.amax().max(1.0));
        prop_assert!(x.as_slice()[10..].iter().all(|&v| v == 0.0));
    }
}

#[test]
fn the_dof_cholesky_solve_rejects_an_indefinite_block() {
    let mut a = DofMatrix::identity();
    a[(1, 1)] = -1.0;
    assert!(solve_dof_spd(&a, &DofVector::zeros(), 3).is_none());
    assert!(solve_dof_spd(&a, &DofVector::zeros(), 1).is_some());
    assert!(solve_dof_spd(&a, &DofVector::zeros(), MAX_DOF + 1).is_none());
}

#[test]
fn a_sweep_range_is_finite_with_an_unlimited_side_read_as_two_radians() {
    let mut hand = test_hand();
    hand.dof_lower[0] = f64::NEG_INFINITY;
    hand.dof_upper[0] = f64::INFINITY;
    assert_eq!(hand.sweep_range(0), (-1.0, 1.0));
    hand.dof_upper[0] = 0.5;
    assert_eq!(hand.sweep_range(0), (-1.5, 0.5));
    hand.dof_lower[0] = 0.25;
    hand.dof_upper[0] = f64::INFINITY;
    assert_eq!(hand.sweep_range(0), (0.25, 2.25));
    hand.dof_upper[0] = 0.75;
    assert_eq!(hand.sweep_range(0), (0.25, 0.75));
}

#[test]
fn clamping_handles_infinite_limits_and_nan() {
    let hand = test_hand();
    let mut q = [1.0, 100.0, f64::NAN, -9.0];
    hand.clamp_to_limits(&mut q);
    assert_eq!(q, [0.05, 100.0, 0.0, -0.5]);
}
