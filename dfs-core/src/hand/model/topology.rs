//! The hand tree's topology: which DOFs move a link and share inertia, ancestors, finger
//! groups, and the joint limits the angles are checked and clamped against.

use super::*;

impl HandModel {
    /// For every DOF, the set of DOFs it shares inertia with: those driving a joint on the
    /// path from one of its joints to the root, or one below it. `M(θ)[a][b]` can be nonzero
    /// only for such pairs (and `a == b`); DOFs of different fingers never couple.
    pub fn inertia_coupling(&self) -> [DofSet; MAX_DOF] {
        let mut c = [0 as DofSet; MAX_DOF];
        for joint in &self.joints {
            let Some((b, _)) = joint.drive.dof_and_gain() else {
                continue;
            };
            if b >= MAX_DOF {
                continue;
            }
            let above = self.dofs_moving_link(joint.child);
            c[b] |= above;
            for (a, row) in c.iter_mut().enumerate() {
                if above & dof_bit(a) != 0 {
                    *row |= dof_bit(b);
                }
            }
        }
        c
    }

    /// The DOFs that move `link`, as a bit set (bit d set when DOF d moves it): those of every
    /// joint on the path from the root to it (a mimic joint counts for its source DOF). Needs
    /// a valid tree.
    pub fn dofs_moving_link(&self, link: usize) -> DofSet {
        let mut set: DofSet = 0;
        let mut current = link;
        // A valid tree has at most `joints.len()` joints on any path.
        for _ in 0..=self.joints.len() {
            let Some(joint) = self.joints.iter().find(|j| j.child == current) else {
                break;
            };
            if let Some((d, _)) = joint.drive.dof_and_gain() {
                set |= dof_bit(d);
            }
            current = joint.parent;
        }
        set
    }

    /// The path from `link` up to the root (the link first), at most [`MAX_LINKS`] long.
    fn ancestors(&self, link: usize) -> Vec<usize> {
        let mut path = vec![link];
        let mut current = link;
        for _ in 0..MAX_LINKS {
            let Some(joint) = self.joints.iter().find(|j| j.child == current) else {
                break;
            };
            current = joint.parent;
            path.push(current);
        }
        path
    }

    /// True when `ancestor` is `link` or on its path to the root. Needs a valid tree.
    pub fn is_ancestor_or_self(&self, ancestor: usize, link: usize) -> bool {
        self.ancestors(link).contains(&ancestor)
    }

    /// The deepest link that is an ancestor (or equal) of every link in `links`; `None` for
    /// no links. Needs a valid tree.
    pub fn common_ancestor(&self, links: impl IntoIterator<Item = usize>) -> Option<usize> {
        let mut links = links.into_iter();
        let mut path = self.ancestors(links.next()?);
        for l in links {
            let other = self.ancestors(l);
            path.retain(|a| other.contains(a));
        }
        path.first().copied()
    }

    /// Computes the finger groups from the tree (tips sharing non-common DOFs).
    ///
    /// The DOFs of tip k are those of the joints on the path from the root to its link.
    /// With two or more tips, the DOFs that move every tip rigidly together (the wrist: those
    /// above the tips' lowest common ancestor link) are dropped; tips whose
    /// remaining DOF sets intersect are united (transitively). A tip without DOFs forms its
    /// own group with no DOFs. Groups are ordered by their first tip; tips and DOFs ascend.
    pub fn compute_finger_groups(&mut self) {
        let nt = self.fingertips.len().min(MAX_TIPS);
        let mut sets = [0 as DofSet; MAX_TIPS];
        for (k, tip) in self.fingertips.iter().take(nt).enumerate() {
            sets[k] = self.dofs_moving_link(tip.link);
        }
        if nt >= 2 {
            // The DOFs that move every tip rigidly together (a wrist): those moving the lowest
            // common ancestor of the tips' links. A DOF below it that reaches every tip through
            // different joints (the mimic-coupled jaws of a parallel gripper) stays: it moves
            // the tips relative to each other, so it pushes on the object.
            let common = self
                .common_ancestor(self.fingertips.iter().take(nt).map(|t| t.link))
                .map(|lca| self.dofs_moving_link(lca))
                .unwrap_or(0);
            sets[..nt].iter_mut().for_each(|s| *s &= !common);
        }
        // Union-find over at most MAX_TIPS tips: label each tip with the smallest tip index
        // of its group, repeating until no label changes.
        let mut label: [usize; MAX_TIPS] = core::array::from_fn(|k| k);
        let mut changed = true;
        while changed {
            changed = false;
            for a in 0..nt {
                for b in 0..nt {
                    if sets[a] & sets[b] != 0 && label[b] > label[a] {
                        label[b] = label[a];
                        changed = true;
                    }
                }
            }
        }
        self.finger_groups = (0..nt)
            .filter(|&k| label[k] == k)
            .map(|first| {
                let tips: Vec<usize> = (0..nt).filter(|&k| label[k] == first).collect();
                let set = tips.iter().fold(0, |acc, &k| acc | sets[k]);
                let dofs = (0..self.dof().min(MAX_DOF))
                    .filter(|&d| set & dof_bit(d) != 0)
                    .collect();
                FingerGroup { tips, dofs }
            })
            .collect();
    }

    /// Checks a joint-angle vector: right length, finite, within limits (with `slack`).
    pub fn check_angles(&self, q: &[f64], slack: f64) -> Result<()> {
        if q.len() != self.dof() {
            let (got, expected) = (q.len(), self.dof());
            return Err(DfsError::WrongLength {
                what: "joint angles",
                got,
                expected,
            });
        }
        for (index, &value) in q.iter().enumerate() {
            if !value.is_finite() {
                return Err(DfsError::NotFinite {
                    what: "joint angle",
                    index,
                    value,
                });
            }
            let (lower, upper) = (self.dof_lower[index], self.dof_upper[index]);
            if value < lower - slack || value > upper + slack {
                let what = "joint angle";
                return Err(DfsError::OutOfRange {
                    what,
                    index,
                    value,
                    lower,
                    upper,
                });
            }
        }
        Ok(())
    }

    /// The range DOF `d` is swept over when a planner moves it from one end to the other: its
    /// limits, with an unlimited side (a continuous joint) read as 2 rad from the other side,
    /// or as ±1 rad when both are unlimited. Always finite, `lower ≤ upper`.
    pub fn sweep_range(&self, d: usize) -> (f64, f64) {
        let (lower, upper) = (self.dof_lower[d], self.dof_upper[d]);
        let lo = match (lower.is_finite(), upper.is_finite()) {
            (true, _) => lower,
            (false, true) => upper - 2.0,
            (false, false) => -1.0,
        };
        let hi = if upper.is_finite() { upper } else { lo + 2.0 };
        (lo, hi.max(lo))
    }

    /// Clamps `q` (the first `dof` entries) into the DOF limits; a NaN entry becomes the
    /// limit-clamped zero. Never panics on infinite limits.
    pub fn clamp_to_limits(&self, q: &mut [f64]) {
        for (i, x) in q.iter_mut().enumerate().take(self.dof()) {
            let v = if x.is_nan() { 0.0 } else { *x };
            *x = v.max(self.dof_lower[i]).min(self.dof_upper[i]);
        }
    }
}
