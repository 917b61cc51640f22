//! Stage 2 of the tick, [`Dfs::stage_contacts`], for the fingertips: each fingertip sphere
//! against every object it may reach, touching the one it penetrates deepest within the contact
//! margin (the palm and phalanges are `dfs::body`'s).

use super::{Dfs, TipContact};
use crate::contact::detect;

impl Dfs {
    /// Every fingertip's contact with the objects into the tick's output: its centre, whether
    /// it touches, which object, the contact frame and the penetration. The objects'
    /// orientations are this tick's (`Dfs::update_rotations`).
    pub(super) fn detect_tip_contacts(&mut self) {
        let margin = self.params.contact_margin;
        for (k, tip) in self.hand.fingertips.iter().enumerate() {
            let c_world = self.kin.tip_centres[k];
            self.out.tip_centres[k] = c_world;
            let t = &mut self.out.tips[k];
            *t = TipContact::default();
            for (i, o) in self.objects[..self.n_objects].iter().enumerate() {
                let pos = o.state.pose.translation.vector;
                // Beyond the bounding sphere by more than the radius and margin: no contact.
                let reach = self.bodies[i].bounding_radius + tip.radius + margin;
                let rel = c_world.coords - pos;
                if rel.norm_squared() > reach * reach * (1.0 + 1e-9) {
                    continue;
                }
                let c_b = self.rots[i].transpose() * rel;
                if let Some(d) = detect(&o.object.shape, &c_b, tip.radius, margin) {
                    if !t.touching || d.penetration > t.penetration {
                        t.touching = true;
                        t.object = i;
                        t.frame = Some(d.frame);
                        t.penetration = d.penetration;
                    }
                }
            }
        }
    }
}
