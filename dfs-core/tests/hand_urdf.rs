//! A hand written back as URDF with link geometry ([`hand_urdf`], [`link_shapes`]): every
//! built-in hand's URDF parses with the project's own loader (urdf-rs) into the same kinematic
//! tree, limits and inertials, names every link and joint of the model, and gives every link
//! geometry; the URDF hands keep their own primitive shapes; hostile geometry falls back to
//! generated shapes.

use std::collections::BTreeMap;

use dfs_core::hand::{
    builtin_hand, builtin_spec, hand_urdf, link_shapes, FingertipSpec, HandModel, HandSpec,
    JointDrive, Primitive, ShapeSource, BUILTIN_HANDS,
};

/// The URDF text a built-in hand was built from (`None` for glove10).
fn source(name: &str) -> Option<&'static str> {
    builtin_spec(name).map(|(_, urdf)| urdf)
}

/// A spec that says what the URDF does not: the model's fingertips, torque limits, armature.
fn spec_of(hand: &HandModel) -> HandSpec {
    HandSpec {
        name: hand.name.clone(),
        urdf: format!("{}.urdf", hand.name),
        fingertips: hand
            .fingertips
            .iter()
            .map(|t| FingertipSpec {
                name: Some(t.name.clone()),
                link: hand.links[t.link].name.clone(),
                offset: [t.offset.x, t.offset.y, t.offset.z],
                radius: t.radius,
            })
            .collect(),
        torque_limit: 1.0,
        joint_torque_limits: hand
            .dof_names
            .iter()
            .zip(&hand.torque_limit)
            .map(|(n, &t)| (n.clone(), t))
            .collect::<BTreeMap<_, _>>(),
        base_link: None,
        thumb: None,
        armature: Some(hand.armature[0]),
    }
}

fn close(a: f64, b: f64) -> bool {
    a == b || (a - b).abs() <= 1e-12 * (1.0 + a.abs().max(b.abs()))
}

fn close_all<'a>(a: impl IntoIterator<Item = &'a f64>, b: impl IntoIterator<Item = &'a f64>) {
    let (a, b): (Vec<f64>, Vec<f64>) = (
        a.into_iter().copied().collect(),
        b.into_iter().copied().collect(),
    );
    assert_eq!(a.len(), b.len());
    for (x, y) in a.iter().zip(&b) {
        assert!(close(*x, *y), "{a:?} != {b:?}");
    }
}

fn urdf_of(name: &str) -> (HandModel, String) {
    let hand = builtin_hand(name).unwrap();
    let shapes = link_shapes(&hand, source(name));
    let urdf = hand_urdf(&hand, &shapes).unwrap();
    (hand, urdf)
}

/// A DOF by name: (name, lower, upper, torque limit).
fn dof_of(hand: &HandModel, d: usize) -> (&str, f64, f64, f64) {
    (
        hand.dof_names[d].as_str(),
        hand.dof_lower[d],
        hand.dof_upper[d],
        hand.torque_limit[d],
    )
}

/// The URDF loader orders links, joints and DOFs breadth first, glove10 finger by finger:
/// the two are compared by name.
#[test]
fn every_builtin_hand_written_as_urdf_loads_back_as_the_same_hand() {
    for name in BUILTIN_HANDS {
        let (hand, urdf) = urdf_of(name);
        let back = HandModel::from_urdf(&urdf, &spec_of(&hand))
            .unwrap_or_else(|e| panic!("{name}: {e}\n{urdf}"));
        assert_eq!(back.name, hand.name);
        let link = |h: &HandModel, l: usize| h.links[l].name.clone();
        assert_eq!(link(&back, back.root), link(&hand, hand.root), "{name}");
        assert_eq!(back.dof(), hand.dof(), "{name}");
        for d in 0..hand.dof() {
            let (n, lo, hi, tau) = dof_of(&hand, d);
            let b = back.dof_names.iter().position(|x| x == n).unwrap();
            let (_, blo, bhi, btau) = dof_of(&back, b);
            close_all([&blo, &bhi, &btau], [&lo, &hi, &tau]);
        }
        assert_eq!(back.links.len(), hand.links.len(), "{name}");
        for b in &hand.links {
            let a = back.links.iter().find(|a| a.name == b.name).unwrap();
            close_all([&a.inertial.mass], [&b.inertial.mass]);
            close_all(a.inertial.com.iter(), b.inertial.com.iter());
            close_all(a.inertial.inertia.iter(), b.inertial.inertia.iter());
        }
        assert_eq!(back.joints.len(), hand.joints.len(), "{name}");
        // The DOF a joint's drive names, by name.
        let dof_name = |h: &HandModel, d: usize| h.dof_names[d].clone();
        for b in &hand.joints {
            let at = format!("{name} joint {}", b.name);
            let a = back.joints.iter().find(|a| a.name == b.name).unwrap();
            assert_eq!(a.kind, b.kind, "{at}");
            assert_eq!(link(&back, a.parent), link(&hand, b.parent), "{at}");
            assert_eq!(link(&back, a.child), link(&hand, b.child), "{at}");
            // RPY loses a few digits near pitch ±90° (Allegro's thumb): 1e-9 rad is nothing.
            let (pa, pb) = (a.origin.to_homogeneous(), b.origin.to_homogeneous());
            assert!((pa - pb).amax() < 1e-9, "{at}: origin {pa} against {pb}");
            close_all(a.axis.iter(), b.axis.iter());
            assert!(
                (a.lower == b.lower || close(a.lower, b.lower))
                    && (a.upper == b.upper || close(a.upper, b.upper)),
                "{at}: limits {} {} against {} {}",
                a.lower,
                a.upper,
                b.lower,
                b.upper
            );
            match (a.drive, b.drive) {
                (JointDrive::Fixed, JointDrive::Fixed) => {}
                (JointDrive::Dof(x), JointDrive::Dof(y)) => {
                    assert_eq!(dof_name(&back, x), dof_name(&hand, y), "{at}")
                }
                (
                    JointDrive::Mimic {
                        dof,
                        multiplier,
                        offset,
                    },
                    JointDrive::Mimic {
                        dof: d,
                        multiplier: m,
                        offset: o,
                    },
                ) => {
                    assert_eq!(dof_name(&back, dof), dof_name(&hand, d), "{at}");
                    assert!(close(multiplier, m) && close(offset, o), "{at}");
                }
                (x, y) => panic!("{at}: {x:?} against {y:?}"),
            }
        }
        assert_eq!(back.fingertips.len(), hand.fingertips.len(), "{name}");
        for (a, b) in back.fingertips.iter().zip(&hand.fingertips) {
            assert_eq!(a.name, b.name, "{name}");
            assert_eq!(link(&back, a.link), link(&hand, b.link), "{name}");
            assert_eq!((a.offset, a.radius), (b.offset, b.radius), "{name}");
        }
        assert_eq!(back.armature, hand.armature, "{name}");
    }
}

#[test]
fn the_urdf_names_every_link_and_joint_and_gives_every_link_geometry() {
    for name in BUILTIN_HANDS {
        let (hand, urdf) = urdf_of(name);
        let robot = urdf_rs::read_from_string(&urdf).unwrap();
        let links: Vec<&str> = robot.links.iter().map(|l| l.name.as_str()).collect();
        let model: Vec<&str> = hand.links.iter().map(|l| l.name.as_str()).collect();
        assert_eq!(links, model, "{name}");
        let joints: Vec<&str> = robot.joints.iter().map(|j| j.name.as_str()).collect();
        let model: Vec<&str> = hand.joints.iter().map(|j| j.name.as_str()).collect();
        assert_eq!(joints, model, "{name}");
        for link in &robot.links {
            assert!(
                !link.visual.is_empty(),
                "{name}: link {} has no visual",
                link.name
            );
            assert_eq!(
                link.visual.len(),
                link.collision.len(),
                "{name}: {}",
                link.name
            );
            for v in &link.visual {
                assert!(
                    !matches!(v.geometry, urdf_rs::Geometry::Mesh { .. }),
                    "{name}: a mesh"
                );
            }
        }
    }
}

#[test]
fn glove10_gets_a_segment_per_phalanx_a_palm_box_and_a_sphere_per_fingertip() {
    let hand = HandModel::glove10();
    let shapes = link_shapes(&hand, None);
    assert!(shapes.iter().all(|s| s.source != ShapeSource::Urdf));
    for (l, link) in hand.links.iter().enumerate() {
        assert!(shapes.iter().any(|s| s.link == l), "{}", link.name);
    }
    let palm = hand.links.iter().position(|l| l.name == "palm").unwrap();
    let boxes: Vec<_> = shapes.iter().filter(|s| s.link == palm).collect();
    assert!(
        matches!(boxes[..], [s] if matches!(s.primitive, Primitive::Box { .. })),
        "{boxes:?}"
    );
    let proximal = hand
        .links
        .iter()
        .position(|l| l.name == "index_proximal")
        .unwrap();
    // A cylinder from the MCP joint to the PIP joint: as long as the proximal phalanx.
    let pip = hand.joints.iter().find(|j| j.name == "index_pip").unwrap();
    let length = shapes
        .iter()
        .find_map(|s| match s.primitive {
            Primitive::Cylinder { length, .. } if s.link == proximal => Some(length),
            _ => None,
        })
        .unwrap();
    assert!((length - pip.origin.translation.vector.norm()).abs() < 1e-12);
    let tips: Vec<_> = shapes
        .iter()
        .filter(|s| s.source == ShapeSource::Fingertip)
        .collect();
    assert_eq!(tips.len(), hand.fingertips.len());
    for (s, t) in tips.iter().zip(&hand.fingertips) {
        assert_eq!(s.link, t.link);
        assert_eq!(s.primitive, Primitive::Sphere { radius: t.radius });
        assert_eq!(s.origin.translation.vector, t.offset);
    }
}

#[test]
fn urdf_hands_keep_their_primitive_shapes_and_links_with_meshes_get_generated_ones() {
    let count = |name: &str, source: ShapeSource| {
        let hand = builtin_hand(name).unwrap();
        link_shapes(&hand, self::source(name))
            .iter()
            .filter(|s| s.source == source)
            .count()
    };
    // Allegro and Barrett: boxes on every link that has geometry.
    assert!(count("allegro", ShapeSource::Urdf) >= 16);
    assert!(count("barrett", ShapeSource::Urdf) >= 8);
    // Inspire: boxes on some links, meshes (not shipped) on others.
    assert!(count("inspire", ShapeSource::Urdf) > 0);
    assert!(count("inspire", ShapeSource::Generated) > 0);
    // The gripper's URDF has no geometry.
    assert_eq!(count("gripper", ShapeSource::Urdf), 0);
    // The allegro's base keeps its own box: 0.0408 m × 0.13 m × 0.1 m or so, centred where
    // the URDF says, not a generated one.
    let hand = builtin_hand("allegro").unwrap();
    let robot = urdf_rs::read_from_string(source("allegro").unwrap()).unwrap();
    let base = &robot
        .links
        .iter()
        .find(|l| l.name == hand.links[hand.root].name)
        .unwrap();
    let ours: Vec<_> = link_shapes(&hand, source("allegro"))
        .into_iter()
        .filter(|s| s.link == hand.root)
        .collect();
    let theirs = if base
        .visual
        .iter()
        .all(|v| !matches!(v.geometry, urdf_rs::Geometry::Mesh { .. }))
        && !base.visual.is_empty()
    {
        base.visual
            .iter()
            .map(|v| v.geometry.clone())
            .collect::<Vec<_>>()
    } else {
        base.collision.iter().map(|c| c.geometry.clone()).collect()
    };
    assert_eq!(ours.len(), theirs.len());
    for (a, b) in ours.iter().zip(&theirs) {
        match (a.primitive, b) {
            (Primitive::Box { size }, urdf_rs::Geometry::Box { size: s }) => {
                assert_eq!([size.x, size.y, size.z], s.0)
            }
            other => panic!("{other:?}"),
        }
    }
}

/// A one-joint hand whose link `finger` has `geometry` (URDF elements) and a fingertip.
fn tiny_urdf(geometry: &str) -> String {
    format!(
        r#"<robot name="tiny">
  <link name="base"/>
  <link name="finger">{geometry}</link>
  <joint name="j" type="revolute">
    <parent link="base"/><child link="finger"/>
    <origin xyz="0 0 0.05"/><axis xyz="0 1 0"/>
    <limit lower="0" upper="1" effort="1" velocity="1"/>
  </joint>
</robot>"#
    )
}

fn tiny_spec() -> HandSpec {
    HandSpec {
        name: "tiny".into(),
        urdf: "tiny.urdf".into(),
        fingertips: vec![FingertipSpec {
            name: Some("tip".into()),
            link: "finger".into(),
            offset: [0.0, 0.0, 0.04],
            radius: 0.01,
        }],
        torque_limit: 1.0,
        joint_torque_limits: BTreeMap::new(),
        base_link: None,
        thumb: None,
        armature: None,
    }
}

fn finger_sources(geometry: &str) -> Vec<ShapeSource> {
    let urdf = tiny_urdf(geometry);
    let hand = HandModel::from_urdf(&urdf, &tiny_spec()).unwrap();
    let finger = hand.links.iter().position(|l| l.name == "finger").unwrap();
    let shapes = link_shapes(&hand, Some(&urdf));
    // The written URDF always parses, whatever the source held.
    let written = hand_urdf(&hand, &shapes).unwrap();
    HandModel::from_urdf(&written, &tiny_spec()).unwrap();
    shapes
        .iter()
        .filter(|s| s.link == finger && s.source != ShapeSource::Fingertip)
        .map(|s| s.source)
        .collect()
}

#[test]
fn hostile_or_mesh_geometry_falls_back_to_generated_shapes() {
    use ShapeSource::{Generated, Urdf};
    let boxed = r#"<visual><geometry><box size="0.02 0.02 0.04"/></geometry></visual>"#;
    assert_eq!(finger_sources(boxed), [Urdf]);
    let capsule =
        r#"<collision><geometry><capsule radius="0.01" length="0.04"/></geometry></collision>"#;
    assert_eq!(finger_sources(capsule), [Urdf, Urdf, Urdf]);
    let mesh = r#"<visual><geometry><mesh filename="package://x/finger.stl"/></geometry></visual>"#;
    assert_eq!(finger_sources(mesh), [Generated, Generated]);
    // A mesh visual with a box collision: the box.
    let both =
        format!("{mesh}<collision><geometry><box size=\"0.02 0.02 0.04\"/></geometry></collision>");
    assert_eq!(finger_sources(&both), [Urdf]);
    for bad in [
        r#"<visual><geometry><box size="NaN 0.02 0.04"/></geometry></visual>"#,
        r#"<visual><geometry><sphere radius="-1"/></geometry></visual>"#,
        r#"<visual><geometry><sphere radius="1e300"/></geometry></visual>"#,
        r#"<visual><origin xyz="1e9 0 0"/><geometry><sphere radius="0.01"/></geometry></visual>"#,
    ] {
        assert_eq!(finger_sources(bad), [Generated, Generated], "{bad}");
    }
    let many = r#"<visual><geometry><sphere radius="0.01"/></geometry></visual>"#.repeat(9);
    assert_eq!(finger_sources(&many), [Generated, Generated]);
    // A source that does not parse: generated shapes, no error.
    let hand = HandModel::glove10();
    let shapes = link_shapes(&hand, Some("<robot"));
    assert_eq!(shapes, link_shapes(&hand, None));
}

#[test]
fn a_model_with_out_of_range_indices_gives_shapes_and_a_urdf_without_panicking() {
    let mut hand = HandModel::glove10();
    hand.fingertips[0].link = 999;
    hand.joints[0].parent = 999;
    hand.fingertips[1].offset.x = f64::NAN;
    let shapes = link_shapes(&hand, None);
    assert!(shapes.iter().all(|s| s.link < hand.links.len()));
    // The URDF is written; it names an empty parent for the broken joint, which the loader
    // refuses, naming it.
    let urdf = hand_urdf(&hand, &shapes).unwrap();
    assert!(HandModel::from_urdf(&urdf, &spec_of(&HandModel::glove10())).is_err());
}
