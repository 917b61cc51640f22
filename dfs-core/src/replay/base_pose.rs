//! Candidate base poses: what the replay planner's searches ([`super::plan`]'s placed and
//! curled grasps, [`super::closing`]'s closing motions) share. A leaf of both, so neither
//! imports the other's helpers.

use super::SkillSpec;
use crate::hand::{HandModel, Kinematics, MAX_DOF, MAX_TIPS};
use crate::math::{Isometry, Real, Rotation, Vector};

/// Rolls of the hand about the grasp axis tried when choosing the base pose.
pub(super) const ROLLS: usize = 12;

/// One candidate base pose.
pub(super) struct Candidate {
    pub(super) score: Real,
    /// Largest distance of a placed (key) fingertip from its target (m).
    pub(super) error: Real,
    /// The placed fingertips reach and, for a curled grasp, the contacts that result are a
    /// force closure the fingers can push into.
    pub(super) ok: bool,
    /// Smallest alignment of a contact's normal with the directions its finger can push in.
    pub(super) align: Real,
    pub(super) rotation: Rotation,
    pub(super) approach: Vector,
    pub(super) q_free: [Real; MAX_DOF],
    pub(super) active: [bool; MAX_TIPS],
}

/// Contacts of the skill on the thumb's side and on the opposing side.
pub(super) fn sides(skill: &SkillSpec) -> (Vec<usize>, Vec<usize>) {
    let n = skill.contacts.len();
    let thumb = skill
        .contacts
        .iter()
        .position(|c| c.finger == "thumb")
        .unwrap_or(0);
    let nt = skill.contacts[thumb].normal_b;
    let (mut a, mut b) = (Vec::new(), Vec::new());
    for i in 0..n {
        if skill.contacts[i].normal_b.dot(&nt) > 0.5 {
            a.push(i);
        } else {
            b.push(i);
        }
    }
    (a, b)
}

/// The skill's grasp axis: the centroid of its thumb-side contacts, of the others (the thumb's
/// mirror through the centre when there are none), and the unit axis from the first to the
/// second (B).
pub(super) fn grasp_axis(skill: &SkillSpec) -> (Vector, Vector, Vector) {
    let (thumb_side, other_side) = sides(skill);
    let centroid = |idx: &[usize]| -> Vector {
        idx.iter()
            .map(|&i| skill.contacts[i].position_b)
            .sum::<Vector>()
            / idx.len().max(1) as Real
    };
    let thumb_c = centroid(&thumb_side);
    let other_c = if other_side.is_empty() {
        -thumb_c
    } else {
        centroid(&other_side)
    };
    let a_s = (other_c - thumb_c)
        .try_normalize(1e-9)
        .unwrap_or_else(Vector::x);
    (thumb_c, other_c, a_s)
}

/// Mid-range joint angles (infinite limits read as ±1).
pub(super) fn mid_angles(hand: &HandModel) -> [Real; MAX_DOF] {
    let mut q = [0.0; MAX_DOF];
    for d in 0..hand.dof() {
        let lo = hand.dof_lower[d].max(-1.0);
        let hi = hand.dof_upper[d].min(1.0).max(lo);
        q[d] = 0.5 * (lo + hi);
    }
    q
}

/// Curls the finger of fingertip `tip` (its DOFs `dofs`, all moved together from the end of
/// their range away from the object towards the other) until the tip touches the object's
/// surface; `q` then holds that first touch. A finger whose curl misses the object, or that
/// touches it even when open, is left open and `false` returned. `inv_start` maps the world
/// into B at the object's start pose.
pub(super) fn curl_onto(
    hand: &HandModel,
    skill: &SkillSpec,
    inv_start: &Isometry,
    tip: usize,
    dofs: &[usize],
    kin: &mut Kinematics,
    q: &mut [Real],
) -> bool {
    const STEPS: usize = 32;
    let radius = hand.fingertips[tip].radius;
    let mut gap = |q: &mut [Real], s: Real| -> Real {
        for &d in dofs {
            let (lo, hi) = hand.sweep_range(d);
            q[d] = lo + (hi - lo) * s;
        }
        hand.forward_kinematics(&Isometry::identity(), q, kin);
        skill
            .shape
            .closest(&(inv_start * kin.tip_centres[tip]).coords)
            .distance
            - radius
    };
    let (g0, g1) = (gap(q, 0.0), gap(q, 1.0));
    let (open, closed) = if g0 >= g1 { (0.0, 1.0) } else { (1.0, 0.0) };
    if g0.max(g1) <= 0.0 {
        // In the object even when open.
        gap(q, open);
        return false;
    }
    let mut prev = open;
    for i in 1..=STEPS {
        let s = open + (closed - open) * i as Real / STEPS as Real;
        if gap(q, s) <= 0.0 {
            let (mut out, mut inside) = (prev, s);
            for _ in 0..20 {
                let mid = 0.5 * (out + inside);
                if gap(q, mid) > 0.0 {
                    out = mid;
                } else {
                    inside = mid;
                }
            }
            gap(q, out);
            return true;
        }
        prev = s;
    }
    gap(q, open);
    false
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::object::Shape;

    #[test]
    fn a_curling_finger_stops_where_its_tip_first_touches_the_surface() {
        let hand = crate::hand::builtin_hand("inspire").unwrap();
        let skill = SkillSpec {
            shape: Shape::Sphere { radius: 0.04 },
            mass: 0.3,
            friction: crate::contact::Friction::default(),
            contact_model: crate::contact::ContactModel::SoftFinger,
            contacts: Vec::new(),
            motion: Vec::new(),
            phases: Vec::new(),
            held_until_s: None,
        };
        let index = hand
            .fingertips
            .iter()
            .position(|t| t.name == "index")
            .unwrap();
        let group = hand
            .finger_groups
            .iter()
            .find(|g| g.tips.contains(&index))
            .unwrap();
        let mut kin = Kinematics::default();
        let mut q = [0.0; MAX_DOF];
        let n = hand.dof();
        // Put the sphere in front of the open index fingertip, 2 cm further out along the palm
        // normal than the tip, where the curling finger sweeps through it.
        let half = |q: &mut [Real; MAX_DOF]| {
            for &d in &group.dofs {
                q[d] = 0.5 * (hand.dof_lower[d] + hand.dof_upper[d]);
            }
        };
        half(&mut q);
        hand.forward_kinematics(&Isometry::identity(), &q[..n], &mut kin);
        let tip_half = kin.tip_centres[index].coords;
        let centre = tip_half + tip_half.normalize() * 0.045;
        let inv = Isometry::translation(-centre.x, -centre.y, -centre.z);
        let touches = curl_onto(
            &hand,
            &skill,
            &inv,
            index,
            &group.dofs,
            &mut kin,
            &mut q[..n],
        );
        assert!(touches);
        hand.forward_kinematics(&Isometry::identity(), &q[..n], &mut kin);
        let gap =
            (kin.tip_centres[index].coords - centre).norm() - 0.04 - hand.fingertips[index].radius;
        assert!((0.0..1e-4).contains(&gap), "{gap}");
        // Far away, the curl misses and the finger is left open, out of the grasp.
        let far = Isometry::translation(-1.0, 0.0, 0.0);
        assert!(!curl_onto(
            &hand,
            &skill,
            &far,
            index,
            &group.dofs,
            &mut kin,
            &mut q[..n]
        ));
    }
}
