//! [`HandModel::validate`]: what a hand model must satisfy, each failure naming its field.

use super::*;

/// True when every entry of a 3-vector is finite.
fn finite3(v: &Vector) -> bool {
    v.iter().all(|x| x.is_finite())
}

/// True when an isometry has finite entries.
fn finite_pose(x: &Isometry) -> bool {
    finite3(&x.translation.vector) && x.rotation.coords.iter().all(|c| c.is_finite())
}

/// Checks `lower ≤ upper` with neither NaN.
fn check_limits(field: String, lower: f64, upper: f64) -> Result<()> {
    if lower.is_nan() || upper.is_nan() {
        return Err(DfsError::invalid(field, "limit is NaN"));
    }
    if lower > upper {
        return Err(DfsError::invalid(
            field,
            format!("lower {lower} > upper {upper}"),
        ));
    }
    Ok(())
}

/// Index of the first duplicate name, if any.
fn first_duplicate<'a>(names: impl Iterator<Item = &'a str> + Clone) -> Option<usize> {
    names
        .clone()
        .enumerate()
        .find(|(i, n)| names.clone().take(*i).any(|m| m == *n))
        .map(|(i, _)| i)
}

impl HandModel {
    /// Checks the model: sizes within capacity, a tree (one root, no loops), valid indices,
    /// limits ordered, masses ≥ 0, radii > 0, torque limits > 0. Names the offending field.
    pub fn validate(&self) -> Result<()> {
        self.validate_sizes()?;
        self.validate_links()?;
        self.validate_dofs()?;
        self.validate_tree()?;
        self.validate_joints()?;
        self.validate_tips()?;
        self.validate_groups()?;
        crate::hand::contact_geometry::validate_contact_shapes(self, &self.contact_shapes)
    }

    /// Capacities and the lengths of the per-DOF vectors.
    fn validate_sizes(&self) -> Result<()> {
        let n = self.dof();
        if self.links.is_empty() || self.links.len() > MAX_HAND_LINKS {
            let reason = format!(
                "{} links, expected 1..={MAX_HAND_LINKS} (the largest hand accepted)",
                self.links.len()
            );
            return Err(DfsError::invalid("links", reason));
        }
        if self.joints.len() >= self.links.len() {
            let reason = format!(
                "{} joints for {} links (a tree has one fewer)",
                self.joints.len(),
                self.links.len()
            );
            return Err(DfsError::invalid("joints", reason));
        }
        if n > MAX_HAND_DOF {
            return Err(DfsError::invalid("dof_names", too_many_dofs(n)));
        }
        if self.fingertips.len() > MAX_TIPS {
            let reason = format!("{} tips > {MAX_TIPS}", self.fingertips.len());
            return Err(DfsError::invalid("fingertips", reason));
        }
        let per_dof = [
            ("dof_lower", self.dof_lower.len()),
            ("dof_upper", self.dof_upper.len()),
            ("torque_limit", self.torque_limit.len()),
            ("armature", self.armature.len()),
        ];
        for (field, len) in per_dof {
            if len != n {
                return Err(DfsError::invalid(
                    field,
                    format!("{len} entries for {n} DOFs"),
                ));
            }
        }
        if self.root >= self.links.len() {
            return Err(DfsError::invalid(
                "root",
                format!("link {} does not exist", self.root),
            ));
        }
        Ok(())
    }

    /// Link names and mass properties.
    fn validate_links(&self) -> Result<()> {
        if let Some(i) = first_duplicate(self.links.iter().map(|l| l.name.as_str())) {
            return Err(DfsError::invalid(
                format!("links[{i}].name"),
                "duplicate name",
            ));
        }
        for (i, link) in self.links.iter().enumerate() {
            let m = &link.inertial;
            if !(m.mass.is_finite() && m.mass >= 0.0) {
                let reason = format!("mass {} must be finite and ≥ 0", m.mass);
                return Err(DfsError::invalid(
                    format!("links[{i}].inertial.mass"),
                    reason,
                ));
            }
            if !finite3(&m.com) {
                return Err(DfsError::invalid(
                    format!("links[{i}].inertial.com"),
                    "not finite",
                ));
            }
            if !m.inertia.iter().all(|x| x.is_finite()) {
                let field = format!("links[{i}].inertial.inertia");
                return Err(DfsError::invalid(field, "not finite"));
            }
        }
        Ok(())
    }

    /// DOF names, limits, torque limits and armature.
    fn validate_dofs(&self) -> Result<()> {
        if let Some(i) = first_duplicate(self.dof_names.iter().map(String::as_str)) {
            return Err(DfsError::invalid(
                format!("dof_names[{i}]"),
                "duplicate name",
            ));
        }
        for i in 0..self.dof() {
            check_limits(
                format!("dof_lower[{i}]"),
                self.dof_lower[i],
                self.dof_upper[i],
            )?;
            let t = self.torque_limit[i];
            if t.is_nan() || t <= 0.0 {
                let reason = format!("torque limit {t} must be > 0");
                return Err(DfsError::invalid(format!("torque_limit[{i}]"), reason));
            }
            let a = self.armature[i];
            if !(a.is_finite() && a >= 0.0) {
                let reason = format!("armature {a} must be finite and ≥ 0");
                return Err(DfsError::invalid(format!("armature[{i}]"), reason));
            }
        }
        Ok(())
    }

    /// One root, every other link the child of exactly one joint, joints in topological
    /// order (so no loops).
    fn validate_tree(&self) -> Result<()> {
        if let Some(i) = first_duplicate(self.joints.iter().map(|j| j.name.as_str())) {
            return Err(DfsError::invalid(
                format!("joints[{i}].name"),
                "duplicate name",
            ));
        }
        let nl = self.links.len();
        let mut reached: u64 = 1 << self.root;
        for (j, joint) in self.joints.iter().enumerate() {
            if joint.parent >= nl {
                let reason = format!("link {} does not exist", joint.parent);
                return Err(DfsError::invalid(format!("joints[{j}].parent"), reason));
            }
            if joint.child >= nl {
                let reason = format!("link {} does not exist", joint.child);
                return Err(DfsError::invalid(format!("joints[{j}].child"), reason));
            }
            if reached & (1 << joint.parent) == 0 {
                let reason = "parent link is neither the root nor the child of an earlier joint \
                              (joints must be in topological order)";
                return Err(DfsError::invalid(format!("joints[{j}].parent"), reason));
            }
            if reached & (1 << joint.child) != 0 {
                let reason = "child link is the root or already has a parent (loop)";
                return Err(DfsError::invalid(format!("joints[{j}].child"), reason));
            }
            reached |= 1 << joint.child;
        }
        if let Some(i) = (0..nl).find(|&i| reached & (1 << i) == 0) {
            let reason = "link is not connected to the root (a second root)";
            return Err(DfsError::invalid(format!("links[{i}]"), reason));
        }
        Ok(())
    }

    /// Joint origins, axes, limits and drives; every DOF drives at least one joint.
    fn validate_joints(&self) -> Result<()> {
        let n = self.dof();
        let mut driven: DofSet = 0;
        for (j, joint) in self.joints.iter().enumerate() {
            if !finite_pose(&joint.origin) {
                return Err(DfsError::invalid(
                    format!("joints[{j}].origin"),
                    "not finite",
                ));
            }
            let axis = joint.axis.into_inner();
            if !finite3(&axis) || (axis.norm() - 1.0).abs() > 1e-6 {
                return Err(DfsError::invalid(
                    format!("joints[{j}].axis"),
                    "not a unit vector",
                ));
            }
            check_limits(format!("joints[{j}].lower"), joint.lower, joint.upper)?;
            let field = format!("joints[{j}].drive");
            match (joint.kind, joint.drive) {
                (JointKind::Fixed, JointDrive::Fixed) => {}
                (JointKind::Fixed, _) => {
                    return Err(DfsError::invalid(
                        field,
                        "a fixed joint must have a fixed drive",
                    ))
                }
                (_, JointDrive::Fixed) => {
                    return Err(DfsError::invalid(
                        field,
                        "a moving joint needs a DOF or a mimic",
                    ))
                }
                (
                    _,
                    JointDrive::Mimic {
                        multiplier, offset, ..
                    },
                ) if !(multiplier.is_finite() && offset.is_finite()) => {
                    return Err(DfsError::invalid(
                        field,
                        "mimic multiplier/offset not finite",
                    ))
                }
                _ => {}
            }
            if let Some((d, _)) = joint.drive.dof_and_gain() {
                if d >= n {
                    return Err(DfsError::invalid(
                        field,
                        format!("DOF {d} does not exist ({n})"),
                    ));
                }
                driven |= dof_bit(d);
            }
        }
        if let Some(d) = (0..n).find(|&d| driven & dof_bit(d) == 0) {
            return Err(DfsError::invalid(
                format!("dof_names[{d}]"),
                "drives no joint",
            ));
        }
        Ok(())
    }

    /// Fingertip links, offsets and radii.
    fn validate_tips(&self) -> Result<()> {
        if let Some(i) = first_duplicate(self.fingertips.iter().map(|t| t.name.as_str())) {
            return Err(DfsError::invalid(
                format!("fingertips[{i}].name"),
                "duplicate name",
            ));
        }
        for (k, tip) in self.fingertips.iter().enumerate() {
            if tip.link >= self.links.len() {
                let reason = format!("link {} does not exist", tip.link);
                return Err(DfsError::invalid(format!("fingertips[{k}].link"), reason));
            }
            if !finite3(&tip.offset) {
                return Err(DfsError::invalid(
                    format!("fingertips[{k}].offset"),
                    "not finite",
                ));
            }
            if !(tip.radius.is_finite() && tip.radius > 0.0) {
                let reason = format!("radius {} must be finite and > 0", tip.radius);
                return Err(DfsError::invalid(format!("fingertips[{k}].radius"), reason));
            }
        }
        Ok(())
    }

    /// Finger group indices.
    fn validate_groups(&self) -> Result<()> {
        for (g, group) in self.finger_groups.iter().enumerate() {
            if let Some(t) = group.tips.iter().find(|&&t| t >= self.fingertips.len()) {
                let reason = format!("tip {t} does not exist");
                return Err(DfsError::invalid(
                    format!("finger_groups[{g}].tips"),
                    reason,
                ));
            }
            if let Some(d) = group.dofs.iter().find(|&&d| d >= self.dof()) {
                let reason = format!("DOF {d} does not exist");
                return Err(DfsError::invalid(
                    format!("finger_groups[{g}].dofs"),
                    reason,
                ));
            }
        }
        Ok(())
    }
}
