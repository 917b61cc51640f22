//! Stage 4 of the tick, [`Dfs::stage_object`] and [`Dfs::stage_overlaps`]: per object its
//! wrench from the transmitting contacts on it (eq. 22-23), table support, Newton-Euler
//! (eq. 24-26) and integration; then which objects overlap. With the check that an object
//! update is finite and the objects' orientations, which the force and feedback stages use.

use super::{Dfs, ObjectOutput, MAX_OBJECTS};
use crate::math::{Real, Wrench};
use crate::object::{external_wrench_b, integrate, shapes_overlap, ObjectState};

/// The first part of an object update that is not finite, if any.
pub(super) fn not_finite(state: &ObjectState, f_ext: &Wrench) -> Option<&'static str> {
    let finite = |v: &[Real]| v.iter().all(|x| x.is_finite());
    if !finite(f_ext.as_slice()) {
        Some("wrench")
    } else if !(finite(state.pose.translation.vector.as_slice())
        && finite(state.pose.rotation.coords.as_slice()))
    {
        Some("pose")
    } else if !(finite(state.linear_velocity.as_slice())
        && finite(state.angular_velocity_b.as_slice()))
    {
        Some("velocity")
    } else {
        None
    }
}

impl Dfs {
    /// Each object's orientation as a matrix, into [`Dfs`]'s `rots` (in place: the array is
    /// 576 bytes, and returned by value it was copied twice a tick).
    #[inline]
    pub(super) fn update_rotations(&mut self) {
        for (r, o) in self.rots.iter_mut().zip(&self.objects[..self.n_objects]) {
            *r = o.state.pose.rotation.to_rotation_matrix();
        }
    }

    /// Object `i`'s step: the wrench of the transmitting contacts on it through its grasp
    /// matrix, gravity and the gyroscopic term, the table's support, integration; into
    /// [`TickOutput::objects`](super::TickOutput::objects).
    pub(super) fn step_object(&mut self, i: usize) {
        let (start, n) = self.contact_range[i];
        self.grasp_active[i] = n > 0;
        let (f_hand, rank) = if n > 0 {
            let g = &mut self.grasps[i];
            g.rebuild(
                &self.frames[start..start + n],
                self.params.contact_model,
                &self.objects[i].friction,
            );
            (g.wrench(&self.transmitted[start..start + n]), g.rank)
        } else {
            (Wrench::zeros(), 0)
        };
        let o = &self.objects[i];
        let mut f_ext = external_wrench_b(&o.object, &o.state, &f_hand, &self.params.gravity);
        let table = self.table_wrench_b(i, &f_ext);
        f_ext += table;
        let o = &mut self.objects[i];
        integrate(&o.object, &mut o.state, &f_ext, self.params.dt);
        self.clamp_to_table(i);
        self.out.objects[i] = ObjectOutput {
            state: self.objects[i].state,
            object_force_b: f_hand,
            f_ext_b: f_ext,
            table_force_b: table,
            n_contacts: n,
            grasp_rank: rank,
        };
    }

    /// The first part of an object's update this tick that is not finite, if any.
    pub(super) fn diverged(&self) -> Option<&'static str> {
        (0..self.n_objects)
            .find_map(|i| not_finite(&self.objects[i].state, &self.out.objects[i].f_ext_b))
    }

    /// Puts every object back at its state `before` the tick's object stage, with no external
    /// wrench, and starts the table's solve over (its warm start may hold the NaN).
    pub(super) fn restore_objects(&mut self, before: &[ObjectState; MAX_OBJECTS]) {
        for (i, b) in before.iter().enumerate().take(self.n_objects) {
            self.objects[i].state = *b;
            // The table's solve starts over next tick (its warm start may hold the NaN).
            self.table_support[i].clear();
            self.out.objects[i].state = *b;
            self.out.objects[i].f_ext_b = Wrench::zeros();
        }
        self.out.object = before[0];
        self.out.f_ext_b = Wrench::zeros();
    }

    /// The pair of lowest indices of two objects that overlap, if any, and how many pairs do.
    pub(super) fn overlapping_pairs(&self) -> (Option<(usize, usize)>, usize) {
        let mut first = None;
        let mut count = 0;
        for i in 0..self.n_objects {
            for j in i + 1..self.n_objects {
                let (a, b) = (&self.objects[i], &self.objects[j]);
                if shapes_overlap(
                    &a.object.shape,
                    &a.state.pose,
                    &b.object.shape,
                    &b.state.pose,
                ) {
                    first.get_or_insert((i, j));
                    count += 1;
                }
            }
        }
        (first, count)
    }
}
