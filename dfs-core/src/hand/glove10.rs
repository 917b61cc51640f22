//! The built-in `glove10` model of the paper's sensor glove (§2.2, Fig. 3).
//!
//! # Frames
//!
//! The base link `forearm` has its origin at the wrist joint centre. After the three wrist
//! joints comes the `palm` link, whose frame at zero wrist angles coincides with the forearm's:
//! the fingers extend along palm +x, the grasping side of the palm faces −z (the back of the
//! hand faces +z) and, this being a right hand, the thumb is on the +y (radial) side.
//! Flexion is a positive rotation about +y for the long fingers, which curls them toward −z.
//!
//! # Sources of the numbers
//!
//! * Hand length (wrist crease to the tip of the middle finger) [`HAND_LENGTH`] = 0.19 m, an
//!   adult value (US Army survey, Greiner 1991: men 0.194 m, women 0.180 m).
//! * Segment lengths (joint centre to joint centre, distal segments to the finger tip) as
//!   fractions of hand length: Buchholz, Armstrong & Goldstein (1992), *Anthropometric data
//!   for describing the kinematics of the human hand*, Ergonomics 35(3), 261-273, Table 1.
//! * Segment masses and inertias: uniform cylinders (phalanges) and a uniform box (palm) of
//!   hand tissue density 1160 kg/m³ (Dempster 1955, WADC-TR-55-159). The whole hand comes out
//!   at about 0.39 kg, about 0.6 % of a 65 kg body, in line with Chandler et al. (1975),
//!   *Investigation of inertial properties of the human body*, AMRL-TR-74-137, and Clauser,
//!   McConville & Young (1969), AMRL-TR-69-70.
//! * Coupling of the distal to the proximal interphalangeal joint, θ_DIP ≈ ⅔ θ_PIP: Rijpkema
//!   & Girard (1991), *Computer animation of knowledge-based human grasping*, SIGGRAPH.
//! * Joint ranges: American Academy of Orthopaedic Surgeons (1965), *Joint motion: method of
//!   measuring and recording*, rounded.

use super::{FingerGroup, Fingertip, HandModel, Inertial, Joint, JointDrive, JointKind, Link};
use crate::math::{Isometry, Mat3, Rotation, UnitVector, Vector};
use crate::object::Shape;

/// Adult hand length (m), wrist crease to the tip of the middle finger.
pub const HAND_LENGTH: f64 = 0.19;
/// Density of hand tissue (kg/m³), Dempster (1955).
pub const HAND_DENSITY: f64 = 1160.0;
/// Rotor inertia added to every DOF (kg·m²).
pub const GLOVE_ARMATURE: f64 = 1e-5;

/// A long finger: name, MCP position in the palm frame (m), Buchholz length ratios of the
/// proximal, middle and distal phalanx, cylinder radii (m) and fingertip radius (m).
struct FingerSpec {
    name: &'static str,
    mcp_in_palm: [f64; 3],
    ratios: [f64; 3],
    radii: [f64; 3],
    tip_radius: f64,
}

/// Index, middle, ring and little fingers. MCP x = metacarpal ratio × hand length (metacarpals
/// taken parallel to palm x; Buchholz ratios 0.374, 0.373, 0.336, 0.295); MCP y spreads the
/// fingers over an adult palm breadth of about 0.085 m.
const FINGERS: [FingerSpec; 4] = [
    FingerSpec {
        name: "index",
        mcp_in_palm: [0.374 * HAND_LENGTH, 0.026, 0.0],
        ratios: [0.265, 0.143, 0.097],
        radii: [0.0100, 0.0090, 0.0080],
        tip_radius: 0.009,
    },
    FingerSpec {
        name: "middle",
        mcp_in_palm: [0.373 * HAND_LENGTH, 0.006, 0.0],
        ratios: [0.277, 0.170, 0.108],
        radii: [0.0105, 0.0095, 0.0085],
        tip_radius: 0.009,
    },
    FingerSpec {
        name: "ring",
        mcp_in_palm: [0.336 * HAND_LENGTH, -0.013, 0.0],
        ratios: [0.259, 0.165, 0.107],
        radii: [0.0100, 0.0090, 0.0080],
        tip_radius: 0.0085,
    },
    FingerSpec {
        name: "little",
        mcp_in_palm: [0.295 * HAND_LENGTH, -0.030, 0.0],
        ratios: [0.206, 0.117, 0.094],
        radii: [0.0090, 0.0080, 0.0070],
        tip_radius: 0.008,
    },
];

/// Thumb CMC joint centre in the palm frame (m): radial, palmar and a little distal of the
/// wrist centre.
const THUMB_CMC_IN_PALM: [f64; 3] = [0.022, 0.034, -0.012];
/// Rest direction of the thumb: 30° from palm x toward the palmar side (rad about +y).
const THUMB_REST_PITCH: f64 = 0.52;
/// Thumb metacarpal, proximal and distal phalanx length ratios (Buchholz et al. 1992).
const THUMB_RATIOS: [f64; 3] = [0.251, 0.196, 0.158];
/// Thumb segment cylinder radii (m).
const THUMB_RADII: [f64; 3] = [0.0110, 0.0105, 0.0095];
/// Thumb tip sphere radius (m).
const THUMB_TIP_RADIUS: f64 = 0.010;

/// Palm box: length along x, breadth along y, thickness along z (m).
const PALM_BOX: [f64; 3] = [0.075, 0.085, 0.030];
/// The thenar and hypothenar eminences (contact geometry only): boxes on the palm's radial and
/// ulnar sides from the wrist, `[length, breadth, thickness]` (m), standing proud of the palm's
/// grasping face by `EMINENCE_RISE`: flush with the palmar side of the thumb's metacarpal
/// capsule at its base (the CMC joint 12 mm palmar, the capsule 11 mm in radius), which the
/// thenar eminence covers in a hand. The hollow of the palm lies between them.
const EMINENCE_BOX: [f64; 3] = [0.03, 0.029, 0.022];
/// How far the eminences stand proud of the palm box's grasping face (m).
const EMINENCE_RISE: f64 = 0.0085;

/// Flexion limits (rad) of the MCP, PIP and DIP joints of the long fingers
/// (hyperextension 20°, flexion 90°, 100°, 80°).
const FINGER_LIMITS: [(f64, f64); 3] = [(-0.35, 1.57), (0.0, 1.75), (0.0, 1.40)];
/// DIP/PIP coupling ratio of the coupled fingers (Rijpkema & Girard 1991).
const DIP_PIP_RATIO: f64 = 2.0 / 3.0;

/// Mass properties of a uniform cylinder of `length` along link +x from the link origin
/// ([`Shape::principal_inertia`], whose cylinder's axis is z).
fn cylinder(length: f64, radius: f64) -> Inertial {
    let mass = HAND_DENSITY * std::f64::consts::PI * radius * radius * length;
    let [transverse, _, axial] = Shape::Cylinder {
        radius,
        half_height: 0.5 * length,
    }
    .principal_inertia(mass);
    Inertial {
        mass,
        com: Vector::new(0.5 * length, 0.0, 0.0),
        inertia: Mat3::from_diagonal(&Vector::new(axial, transverse, transverse)),
    }
}

/// Mass properties of the palm: a uniform box from the wrist centre along +x
/// ([`Shape::principal_inertia`]).
fn palm_inertial() -> Inertial {
    let [a, b, c] = PALM_BOX;
    let mass = HAND_DENSITY * a * b * c;
    let diag = Vector::from(
        Shape::Box {
            half_extents: [0.5 * a, 0.5 * b, 0.5 * c],
        }
        .principal_inertia(mass),
    );
    Inertial {
        mass,
        com: Vector::new(0.5 * a, -0.002, 0.0),
        inertia: Mat3::from_diagonal(&diag),
    }
}

/// Builds the glove model step by step.
struct Builder {
    hand: HandModel,
}

impl Builder {
    /// Adds a link, returning its index.
    fn link(&mut self, name: &str, inertial: Inertial) -> usize {
        self.hand.links.push(Link {
            name: name.to_owned(),
            inertial,
        });
        self.hand.links.len() - 1
    }

    /// Adds a DOF, returning its index.
    fn dof(&mut self, name: &str, (lower, upper): (f64, f64), torque_limit: f64) -> usize {
        self.hand.dof_names.push(name.to_owned());
        self.hand.dof_lower.push(lower);
        self.hand.dof_upper.push(upper);
        self.hand.torque_limit.push(torque_limit);
        self.hand.armature.push(GLOVE_ARMATURE);
        self.hand.dof_names.len() - 1
    }

    /// Adds a revolute joint driven by `drive`; its limits follow from the DOF limits.
    fn revolute(
        &mut self,
        name: &str,
        parent: usize,
        child: usize,
        origin: Isometry,
        axis: Vector,
        drive: JointDrive,
    ) {
        let (dof, gain, offset) = match drive {
            JointDrive::Dof(d) => (d, 1.0, 0.0),
            JointDrive::Mimic {
                dof,
                multiplier,
                offset,
            } => (dof, multiplier, offset),
            // glove10 has no fixed joints; a fixed drive would have no limits to copy.
            JointDrive::Fixed => (0, 0.0, 0.0),
        };
        let a = gain * self.hand.dof_lower[dof] + offset;
        let b = gain * self.hand.dof_upper[dof] + offset;
        self.hand.joints.push(Joint {
            name: name.to_owned(),
            kind: JointKind::Revolute,
            parent,
            child,
            origin,
            axis: UnitVector::new_normalize(axis),
            lower: a.min(b),
            upper: a.max(b),
            drive,
        });
    }

    /// Adds a long finger after the palm: three phalanges flexing about palm y, joints at the
    /// MCP position and at the ends of the previous segments; returns the distal link.
    fn finger(&mut self, spec: &FingerSpec, palm: usize, drives: [JointDrive; 3]) -> usize {
        let segments = ["proximal", "middle", "distal"];
        let joints = ["mcp", "pip", "dip"];
        let lengths = spec.ratios.map(|r| r * HAND_LENGTH);
        let mut parent = palm;
        let mut origin = at(spec.mcp_in_palm);
        for s in 0..3 {
            let inertial = cylinder(lengths[s], spec.radii[s]);
            let child = self.link(&format!("{}_{}", spec.name, segments[s]), inertial);
            let name = format!("{}_{}", spec.name, joints[s]);
            self.revolute(&name, parent, child, origin, Vector::y(), drives[s]);
            parent = child;
            origin = Isometry::translation(lengths[s], 0.0, 0.0);
        }
        parent
    }

    /// Adds the fingertip sphere touching the end of a distal phalanx of `length`.
    fn tip(&mut self, name: &str, link: usize, length: f64, radius: f64) {
        let offset = Vector::new(length - radius, 0.0, 0.0);
        self.hand.fingertips.push(Fingertip {
            name: name.to_owned(),
            link,
            offset,
            radius,
        });
    }
}

/// An isometry that is a pure translation.
fn at(p: [f64; 3]) -> Isometry {
    Isometry::translation(p[0], p[1], p[2])
}

impl HandModel {
    /// The paper's 10-DOF glove (§2.2): wrist 3, index 3, thumb 2, middle/ring/little 2
    /// coupled; five fingertips "thumb", "index", "middle", "ring", "little".
    ///
    /// DOFs (θ order): `wrist_roll` (about x, pronation +), `wrist_pitch` (about y, flexion
    /// toward the palm +), `wrist_yaw` (about z, radial deviation +), `index_mcp`,
    /// `index_pip`, `index_dip`, `thumb_cmc` (flexion toward the index, about the palm's y),
    /// `thumb_mcp` (flexion; the thumb IP joint follows it 1:1),
    /// `middle_mcp`, `middle_pip` (the ring and little MCP and PIP joints copy them 1:1; every
    /// coupled DIP joint follows its PIP at ⅔). See the module documentation for frames and
    /// the sources of the dimensions.
    pub fn glove10() -> HandModel {
        let mut b = Builder {
            hand: HandModel {
                name: "glove10".to_owned(),
                links: Vec::new(),
                joints: Vec::new(),
                root: 0,
                dof_names: Vec::new(),
                dof_lower: Vec::new(),
                dof_upper: Vec::new(),
                torque_limit: Vec::new(),
                armature: Vec::new(),
                fingertips: Vec::new(),
                finger_groups: Vec::<FingerGroup>::new(),
                contact_shapes: Vec::new(),
            },
        };
        let palm = add_wrist(&mut b);
        let index = add_index(&mut b, palm);
        let thumb = add_thumb(&mut b, palm);
        let [middle, ring, little] = add_coupled_fingers(&mut b, palm);
        b.tip(
            "thumb",
            thumb,
            THUMB_RATIOS[2] * HAND_LENGTH,
            THUMB_TIP_RADIUS,
        );
        for (spec, link) in FINGERS.iter().zip([index, middle, ring, little]) {
            b.tip(
                spec.name,
                link,
                spec.ratios[2] * HAND_LENGTH,
                spec.tip_radius,
            );
        }
        b.hand.compute_finger_groups();
        add_contact_geometry(&mut b.hand);
        b.hand
    }
}

/// The palm and phalanx contact shapes (whole-hand contact, issue 21 item 5) from the same
/// anthropometry as the links' masses: the palm box ([`PALM_BOX`], from the wrist centre along
/// +x, as its inertial) and a capsule along each phalanx with the phalanx's radius (the thumb's
/// metacarpal included). A distal phalanx's capsule stops one fingertip diameter short of the
/// finger's end, where the fingertip sphere is the contact: the two overlap by the capsule's end
/// ball only. And the thenar and hypothenar eminences ([`EMINENCE_BOX`]), palm shapes beside the
/// palm box's face: in a power grasp the object presses into them, the palm's hollow between.
/// 18 shapes (at most [`super::MAX_CONTACT_SHAPES`]).
fn add_contact_geometry(hand: &mut HandModel) {
    use super::contact_geometry::{body_part_of, ContactPrimitive, ContactShape};
    let link = |hand: &HandModel, name: &str| hand.links.iter().position(|l| l.name == name);
    let mut shapes = Vec::new();
    if let Some(palm) = link(hand, "palm") {
        let [a, b, c] = PALM_BOX;
        shapes.push(ContactShape {
            name: "palm".to_owned(),
            link: palm,
            part: body_part_of(hand, palm),
            primitive: ContactPrimitive::Box {
                pose: Isometry::translation(0.5 * a, 0.0, 0.0),
                half_extents: Vector::new(0.5 * a, 0.5 * b, 0.5 * c),
            },
        });
        let [ea, eb, ec] = EMINENCE_BOX;
        for (name, side) in [("thenar", 1.0), ("hypothenar", -1.0)] {
            shapes.push(ContactShape {
                name: name.to_owned(),
                link: palm,
                part: body_part_of(hand, palm),
                primitive: ContactPrimitive::Box {
                    pose: Isometry::translation(
                        0.5 * ea,
                        side * 0.5 * (b - eb),
                        -0.5 * c - EMINENCE_RISE + 0.5 * ec,
                    ),
                    half_extents: Vector::new(0.5 * ea, 0.5 * eb, 0.5 * ec),
                },
            });
        }
    }
    let thumb = (
        "thumb",
        ["metacarpal", "proximal", "distal"],
        THUMB_RATIOS,
        THUMB_RADII,
        THUMB_TIP_RADIUS,
    );
    let fingers = FINGERS.iter().map(|f| {
        (
            f.name,
            ["proximal", "middle", "distal"],
            f.ratios,
            f.radii,
            f.tip_radius,
        )
    });
    for (finger, segments, ratios, radii, tip_radius) in std::iter::once(thumb).chain(fingers) {
        for s in 0..3 {
            let name = format!("{finger}_{}", segments[s]);
            let Some(l) = link(hand, &name) else { continue };
            let length = ratios[s] * HAND_LENGTH;
            let end = if s == 2 {
                length - 2.0 * tip_radius
            } else {
                length
            };
            shapes.push(ContactShape {
                part: body_part_of(hand, l),
                name,
                link: l,
                primitive: ContactPrimitive::Capsule {
                    a: Vector::zeros(),
                    b: Vector::new(end, 0.0, 0.0),
                    radius: radii[s],
                },
            });
        }
    }
    hand.contact_shapes = shapes;
}

/// Forearm, wrist roll/pitch/yaw and the palm; returns the palm link.
fn add_wrist(b: &mut Builder) -> usize {
    let forearm = b.link("forearm", Inertial::default());
    let roll_link = b.link("wrist_roll_link", Inertial::default());
    let pitch_link = b.link("wrist_pitch_link", Inertial::default());
    let palm = b.link("palm", palm_inertial());
    let roll = b.dof("wrist_roll", (-1.4, 1.4), 2.0);
    let pitch = b.dof("wrist_pitch", (-1.2, 1.4), 5.0);
    let yaw = b.dof("wrist_yaw", (-0.52, 0.35), 4.0);
    let id = Isometry::identity();
    b.revolute(
        "wrist_roll",
        forearm,
        roll_link,
        id,
        Vector::x(),
        JointDrive::Dof(roll),
    );
    b.revolute(
        "wrist_pitch",
        roll_link,
        pitch_link,
        id,
        Vector::y(),
        JointDrive::Dof(pitch),
    );
    b.revolute(
        "wrist_yaw",
        pitch_link,
        palm,
        id,
        Vector::z(),
        JointDrive::Dof(yaw),
    );
    palm
}

/// The index finger with three independent DOFs; returns its distal link.
fn add_index(b: &mut Builder, palm: usize) -> usize {
    let spec = &FINGERS[0];
    let mcp = b.dof("index_mcp", FINGER_LIMITS[0], 1.0);
    let pip = b.dof("index_pip", FINGER_LIMITS[1], 0.6);
    let dip = b.dof("index_dip", FINGER_LIMITS[2], 0.3);
    let drives = [
        JointDrive::Dof(mcp),
        JointDrive::Dof(pip),
        JointDrive::Dof(dip),
    ];
    b.finger(spec, palm, drives)
}

/// The thumb: CMC and MCP flexion (IP follows MCP 1:1) in one plane parallel to the index
/// finger's flexion plane; returns its distal link.
///
/// The glove measures two thumb angles (§2.2). We read them as the two flexions that close the
/// thumb against the index finger like a pincer: at zero the thumb points distally and 30°
/// toward the palmar side from a CMC joint radial of the index; positive angles turn it about
/// the palm's y, like the fingers' flexion, curling its pad toward the flexed fingers. With both axes parallel to the
/// fingers' flexion axes, the thumb pad can push along the pinch axis *and* along the palm's
/// z: a thumb that opposes by rotating about the palm's long axis instead pushes in a plane
/// that cannot hold a pinched object against gravity (NOTES: eq. 14 transmits only forces in
/// the range of Jᵀ).
fn add_thumb(b: &mut Builder, palm: usize) -> usize {
    let cmc = b.dof("thumb_cmc", (-0.8, 0.9), 1.0);
    let mcp = b.dof("thumb_mcp", (-0.2, 1.3), 0.6);
    let lengths = THUMB_RATIOS.map(|r| r * HAND_LENGTH);
    let [r0, r1, r2] = THUMB_RADII;
    let metacarpal = b.link("thumb_metacarpal", cylinder(lengths[0], r0));
    let proximal = b.link("thumb_proximal", cylinder(lengths[1], r1));
    let distal = b.link("thumb_distal", cylinder(lengths[2], r2));
    let down = Rotation::from_axis_angle(&Vector::y_axis(), THUMB_REST_PITCH);
    let cmc_origin = Isometry::from_parts(at(THUMB_CMC_IN_PALM).translation, down);
    let flex = Vector::y();
    b.revolute(
        "thumb_cmc",
        palm,
        metacarpal,
        cmc_origin,
        flex,
        JointDrive::Dof(cmc),
    );
    let mcp_origin = Isometry::translation(lengths[0], 0.0, 0.0);
    b.revolute(
        "thumb_mcp",
        metacarpal,
        proximal,
        mcp_origin,
        flex,
        JointDrive::Dof(mcp),
    );
    let ip_origin = Isometry::translation(lengths[1], 0.0, 0.0);
    let ip = JointDrive::Mimic {
        dof: mcp,
        multiplier: 1.0,
        offset: 0.0,
    };
    b.revolute("thumb_ip", proximal, distal, ip_origin, flex, ip);
    distal
}

/// Middle, ring and little fingers on two shared DOFs (the middle finger's MCP and PIP);
/// returns their distal links.
fn add_coupled_fingers(b: &mut Builder, palm: usize) -> [usize; 3] {
    let mcp = b.dof("middle_mcp", FINGER_LIMITS[0], 1.0);
    let pip = b.dof("middle_pip", FINGER_LIMITS[1], 0.6);
    let dip = JointDrive::Mimic {
        dof: pip,
        multiplier: DIP_PIP_RATIO,
        offset: 0.0,
    };
    let copy = |dof| JointDrive::Mimic {
        dof,
        multiplier: 1.0,
        offset: 0.0,
    };
    let middle = b.finger(
        &FINGERS[1],
        palm,
        [JointDrive::Dof(mcp), JointDrive::Dof(pip), dip],
    );
    let ring = b.finger(&FINGERS[2], palm, [copy(mcp), copy(pip), dip]);
    let little = b.finger(&FINGERS[3], palm, [copy(mcp), copy(pip), dip]);
    [middle, ring, little]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::hand::Kinematics;
    use crate::math::Point;

    fn tips(hand: &HandModel, q: &[f64]) -> Vec<Point> {
        let mut kin = Kinematics::default();
        hand.forward_kinematics(&Isometry::identity(), q, &mut kin);
        kin.tip_centres[..hand.fingertips.len()].to_vec()
    }

    fn with(dof: usize, value: f64) -> [f64; 10] {
        let mut q = [0.0; 10];
        q[dof] = value;
        q
    }

    #[test]
    fn glove10_is_valid_with_ten_named_dofs_and_five_tips() {
        let hand = HandModel::glove10();
        hand.validate().unwrap();
        let names = [
            "wrist_roll",
            "wrist_pitch",
            "wrist_yaw",
            "index_mcp",
            "index_pip",
            "index_dip",
            "thumb_cmc",
            "thumb_mcp",
            "middle_mcp",
            "middle_pip",
        ];
        assert_eq!(hand.dof_names, names);
        let tip_names: Vec<&str> = hand.fingertips.iter().map(|t| t.name.as_str()).collect();
        assert_eq!(tip_names, ["thumb", "index", "middle", "ring", "little"]);
        assert!(hand
            .fingertips
            .iter()
            .all(|t| (0.008..=0.010).contains(&t.radius)));
        assert_eq!(hand.links[hand.root].name, "forearm");
    }

    #[test]
    fn glove10_groups_index_thumb_and_the_coupled_fingers() {
        let hand = HandModel::glove10();
        let groups: Vec<(Vec<usize>, Vec<usize>)> = hand
            .finger_groups
            .iter()
            .map(|g| (g.tips.clone(), g.dofs.clone()))
            .collect();
        assert_eq!(
            groups,
            [
                (vec![0], vec![6, 7]),
                (vec![1], vec![3, 4, 5]),
                (vec![2, 3, 4], vec![8, 9])
            ]
        );
    }

    #[test]
    fn stretched_fingers_point_along_palm_x_with_the_thumb_on_plus_y() {
        let hand = HandModel::glove10();
        let p = tips(&hand, &[0.0; 10]);
        let [thumb, index, middle, ring, little] = [p[0], p[1], p[2], p[3], p[4]];
        assert!(middle.x > index.x && index.x > ring.x && ring.x > little.x);
        assert!((middle.x - 0.167).abs() < 0.002, "middle tip {middle}");
        assert!(thumb.y > index.y && index.y > middle.y && middle.y > ring.y && ring.y > little.y);
        assert!(p[1..].iter().all(|t| t.z == 0.0));
        // Tip centre plus radius reaches about the hand length from the wrist.
        let reach = middle.x + hand.fingertips[2].radius;
        assert!((reach - 0.928 * HAND_LENGTH).abs() < 1e-9);
    }

    #[test]
    fn flexion_curls_fingers_and_wrist_toward_the_palm_side() {
        let hand = HandModel::glove10();
        for dof in [1, 3, 4, 5, 8, 9] {
            let p = tips(&hand, &with(dof, 0.5));
            let moved = if dof == 8 || dof == 9 {
                2..5
            } else if dof == 1 {
                1..5
            } else {
                1..2
            };
            assert!(p[moved].iter().all(|t| t.z < -0.001), "dof {dof}");
        }
        // Radial deviation (wrist yaw +) turns the fingers toward the thumb side.
        assert!(tips(&hand, &with(2, 0.3))[2].y > 0.03);
    }

    #[test]
    fn coupled_fingers_copy_the_middle_finger_angles() {
        let hand = HandModel::glove10();
        let mut kin = Kinematics::default();
        let mut q = [0.0; 10];
        q[8] = 0.6;
        q[9] = 0.9;
        hand.forward_kinematics(&Isometry::identity(), &q, &mut kin);
        let angle = |child: &str| {
            let j = hand
                .joints
                .iter()
                .position(|j| hand.links[j.child].name == child)
                .unwrap();
            let parent = hand.joints[j].parent;
            (kin.link_poses[parent].inverse() * kin.link_poses[hand.joints[j].child])
                .rotation
                .angle()
        };
        for finger in ["middle", "ring", "little"] {
            assert!((angle(&format!("{finger}_proximal")) - 0.6).abs() < 1e-12);
            assert!((angle(&format!("{finger}_middle")) - 0.9).abs() < 1e-12);
            assert!((angle(&format!("{finger}_distal")) - 0.6).abs() < 1e-12);
        }
    }

    #[test]
    fn the_thumb_pad_can_meet_the_flexed_index_fingertip() {
        let hand = HandModel::glove10();
        let contact = hand.fingertips[0].radius + hand.fingertips[1].radius;
        let mut q = [0.0; 10];
        q[3] = 1.0;
        q[4] = 1.0;
        q[5] = 0.6;
        let mut best = f64::INFINITY;
        for i in 0..=17 {
            for k in 0..=15 {
                q[6] = -0.8 + 0.1 * i as f64;
                q[7] = -0.2 + 0.1 * k as f64;
                let p = tips(&hand, &q);
                best = best.min((p[0] - p[1]).norm());
            }
        }
        assert!(best < contact, "closest approach {best} m");
        assert!(
            tips(&hand, &[0.0; 10])[0].z < 0.0,
            "the thumb rests on the palmar side"
        );
    }

    #[test]
    fn glove10_has_a_palm_box_and_a_capsule_per_phalanx_within_the_limits() {
        use crate::hand::{BodyPart, ContactPrimitive, MAX_CONTACT_SHAPES};
        let hand = HandModel::glove10();
        assert_eq!(hand.contact_shapes.len(), 18);
        assert!(hand.contact_shapes.len() <= MAX_CONTACT_SHAPES);
        let palms: Vec<_> = hand
            .contact_shapes
            .iter()
            .filter(|s| s.part == BodyPart::Palm)
            .collect();
        // The palm box and the two eminences, boxes on the palm link.
        assert_eq!(palms.len(), 3);
        let names: Vec<&str> = palms.iter().map(|s| s.name.as_str()).collect();
        assert_eq!(names, ["palm", "thenar", "hypothenar"]);
        for p in &palms {
            assert_eq!(hand.links[p.link].name, "palm");
            assert!(matches!(p.primitive, ContactPrimitive::Box { .. }));
        }
        // The eminences stand as proud of the palm's face as the thumb's metacarpal at its
        // base: its lowest point at the CMC joint.
        let lowest = |p: &ContactPrimitive| match *p {
            ContactPrimitive::Box { pose, half_extents } => {
                pose.translation.vector.z - half_extents.z
            }
            _ => f64::NAN,
        };
        let metacarpal = hand
            .contact_shapes
            .iter()
            .find(|s| s.name == "thumb_metacarpal")
            .unwrap();
        let ContactPrimitive::Capsule { radius, .. } = metacarpal.primitive else {
            panic!("a capsule");
        };
        let cmc_z = THUMB_CMC_IN_PALM[2];
        for p in &palms[1..] {
            assert!((lowest(&p.primitive) - (cmc_z - radius)).abs() < 1e-3);
        }
        // Every phalanx belongs to the finger of its fingertip (thumb 0 ... little 4), three
        // each.
        for k in 0..5 {
            let n = hand
                .contact_shapes
                .iter()
                .filter(|s| s.part == BodyPart::Phalanx { finger: Some(k) })
                .count();
            assert_eq!(n, 3, "finger {k}");
        }
        // The capsules' radii are the links' (the same anthropometry as their masses).
        let c = hand
            .contact_shapes
            .iter()
            .find(|s| s.name == "index_proximal")
            .unwrap();
        assert_eq!(
            c.primitive,
            ContactPrimitive::Capsule {
                a: Vector::zeros(),
                b: Vector::new(0.265 * HAND_LENGTH, 0.0, 0.0),
                radius: 0.0100
            }
        );
    }

    #[test]
    fn glove10_masses_match_an_adult_hand() {
        let hand = HandModel::glove10();
        let total: f64 = hand.links.iter().map(|l| l.inertial.mass).sum();
        assert!((0.3..0.5).contains(&total), "hand mass {total} kg");
        let index_proximal = hand
            .links
            .iter()
            .find(|l| l.name == "index_proximal")
            .unwrap();
        assert!((0.01..0.03).contains(&index_proximal.inertial.mass));
        assert!(hand.torque_limit.iter().all(|&t| (0.3..=5.0).contains(&t)));
    }
}
