//! A URDF parsed and its kinematic tree checked: unique names, supported joint types, links
//! that exist, one root, no loops; then the base's subtree in breadth-first order.

use super::HandSpec;
use crate::error::{DfsError, Result};
use crate::hand::MAX_HAND_LINKS;
use std::collections::BTreeMap;

/// Parses URDF text (already checked by [`super::check_urdf_text`]) into a robot with at least
/// one link; the error says where a missing attribute belongs.
pub(super) fn parse(urdf: &str) -> Result<urdf_rs::Robot> {
    let robot = urdf_rs::read_from_string(urdf).map_err(|e| {
        let e = e.to_string();
        let e = e.strip_prefix("custom: ").unwrap_or(&e);
        // urdf-rs names the missing attribute but not the element: say where it belongs.
        let hint = if e.contains("`velocity`") || e.contains("`effort`") {
            " (every joint <limit> needs both effort and velocity, as URDF requires)"
        } else {
            ""
        };
        DfsError::invalid("urdf", format!("does not parse: {e}{hint}"))
    })?;
    if robot.links.is_empty() {
        return Err(DfsError::invalid(
            "urdf",
            format!(
                "robot {:?} has no links: a hand needs at least its base link",
                robot.name
            ),
        ));
    }
    Ok(robot)
}

/// The checked tree of a URDF and the subtree that is the hand.
pub(super) struct Tree<'a> {
    /// Index in the URDF of each link, by name.
    pub(super) link_index: BTreeMap<&'a str, usize>,
    /// Each joint, by name.
    pub(super) by_name: BTreeMap<&'a str, &'a urdf_rs::Joint>,
    /// The base's subtree in breadth-first order: URDF link indices (the base first)…
    pub(super) order_links: Vec<usize>,
    /// …and URDF joint indices.
    pub(super) order_joints: Vec<usize>,
    /// The hand's index of each URDF link in the subtree.
    pub(super) new_index: BTreeMap<usize, usize>,
}

impl<'a> Tree<'a> {
    /// Checks `robot`'s tree and orders the subtree of the spec's base link (the root's when
    /// it names none); errors name the link or joint.
    pub(super) fn new(robot: &'a urdf_rs::Robot, spec: &HandSpec) -> Result<Tree<'a>> {
        let links = &robot.links;
        let link_index = index_links(links)?;
        let (by_name, parent_of) = index_joints(robot, &link_index)?;
        let root = single_root(links, &parent_of)?;
        // Per link, the joints whose parent it is.
        let mut children: Vec<Vec<usize>> = vec![Vec::new(); links.len()];
        for (j, joint) in robot.joints.iter().enumerate() {
            children[link_index[joint.parent.link.as_str()]].push(j);
        }
        let base = match &spec.base_link {
            Some(name) => *link_index.get(name.as_str()).ok_or_else(|| {
                DfsError::invalid("base_link", format!("no link named {name:?} in the URDF"))
            })?,
            None => root,
        };
        let child_of = |j: usize| link_index[robot.joints[j].child.link.as_str()];
        // Links reached from the root; a link with a parent that is not reached is on a loop.
        let mut reached = vec![false; links.len()];
        let mut stack = vec![root];
        while let Some(l) = stack.pop() {
            reached[l] = true;
            stack.extend(children[l].iter().map(|&j| child_of(j)));
        }
        if let Some(l) = (0..links.len()).find(|&l| !reached[l]) {
            return Err(DfsError::invalid(
                format!("urdf link {:?}", links[l].name),
                "is not connected to the root: its joints form a kinematic loop",
            ));
        }
        // Breadth-first order of the base's subtree: links and joints.
        let mut order_links = vec![base];
        let mut order_joints: Vec<usize> = Vec::new();
        let mut head = 0;
        while head < order_links.len() {
            let l = order_links[head];
            head += 1;
            for &j in &children[l] {
                order_joints.push(j);
                order_links.push(child_of(j));
            }
        }
        if order_links.len() > MAX_HAND_LINKS {
            let reason = format!(
                "the hand has {} links; at most {MAX_HAND_LINKS} are accepted",
                order_links.len()
            );
            return Err(DfsError::invalid("urdf", reason));
        }
        let new_index: BTreeMap<usize, usize> = order_links
            .iter()
            .enumerate()
            .map(|(new, &old)| (old, new))
            .collect();
        Ok(Tree {
            link_index,
            by_name,
            order_links,
            order_joints,
            new_index,
        })
    }

    /// The hand's index of the link named `name`, if it is in the hand's subtree.
    pub(super) fn hand_link(&self, name: &str) -> Option<usize> {
        self.link_index
            .get(name)
            .and_then(|old| self.new_index.get(old))
            .copied()
    }
}

/// Each link's index, by name; a name used twice is refused.
fn index_links(links: &[urdf_rs::Link]) -> Result<BTreeMap<&str, usize>> {
    let mut link_index: BTreeMap<&str, usize> = BTreeMap::new();
    for (i, l) in links.iter().enumerate() {
        if link_index.insert(l.name.as_str(), i).is_some() {
            return Err(DfsError::invalid(
                format!("urdf link {:?}", l.name),
                "duplicate link name",
            ));
        }
    }
    Ok(link_index)
}

/// Joints by name, and per link the joint whose child it is. Refused: a name used twice, a
/// joint type a hand does not have, a parent or child link that does not exist, a link that
/// is the child of two joints.
#[allow(clippy::type_complexity)] // two maps of one pass, named at the call
fn index_joints<'a>(
    robot: &'a urdf_rs::Robot,
    link_index: &BTreeMap<&str, usize>,
) -> Result<(BTreeMap<&'a str, &'a urdf_rs::Joint>, Vec<Option<usize>>)> {
    let mut by_name: BTreeMap<&str, &urdf_rs::Joint> = BTreeMap::new();
    let mut parent_of: Vec<Option<usize>> = vec![None; robot.links.len()];
    for (j, joint) in robot.joints.iter().enumerate() {
        if by_name.insert(joint.name.as_str(), joint).is_some() {
            return Err(DfsError::invalid(
                format!("urdf joint {:?}", joint.name),
                "duplicate joint name",
            ));
        }
        let field = || format!("urdf joint {:?}", joint.name);
        match joint.joint_type {
            urdf_rs::JointType::Revolute
            | urdf_rs::JointType::Continuous
            | urdf_rs::JointType::Prismatic
            | urdf_rs::JointType::Fixed => {}
            ref other => {
                return Err(DfsError::invalid(
                    field(),
                    format!(
                        "type {other:?} is not supported (a hand is a tree of revolute, \
                         continuous, prismatic and fixed joints)"
                    ),
                ))
            }
        }
        let lookup = |name: &str, role: &str| {
            link_index.get(name).copied().ok_or_else(|| {
                DfsError::invalid(field(), format!("{role} link {name:?} does not exist"))
            })
        };
        lookup(&joint.parent.link, "parent")?;
        let child = lookup(&joint.child.link, "child")?;
        if let Some(other) = parent_of[child] {
            return Err(DfsError::invalid(
                format!("urdf link {:?}", joint.child.link),
                format!(
                    "is the child of two joints ({:?} and {:?}): a kinematic loop",
                    robot.joints[other].name, joint.name
                ),
            ));
        }
        parent_of[child] = Some(j);
    }
    Ok((by_name, parent_of))
}

/// The one link without a parent joint; none (a loop) or several are refused.
fn single_root(links: &[urdf_rs::Link], parent_of: &[Option<usize>]) -> Result<usize> {
    let roots: Vec<usize> = (0..links.len())
        .filter(|&l| parent_of[l].is_none())
        .collect();
    match roots[..] {
        [] => Err(DfsError::invalid(
            "urdf",
            "every link has a parent joint: the joints form a kinematic loop",
        )),
        [root] => Ok(root),
        _ => {
            let names: Vec<&str> = roots.iter().map(|&l| links[l].name.as_str()).collect();
            Err(DfsError::invalid(
                "urdf",
                format!(
                    "several root links ({}): a hand is one tree",
                    names.join(", ")
                ),
            ))
        }
    }
}
