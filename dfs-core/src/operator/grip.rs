//! The operator's squeeze and load force (Johansson & Westling 1984): how hard each
//! fingertip of the grasp presses, along which push, once every squeezing fingertip touches,
//! and how the fingertips share lifting the object.

use super::{push_basis, Simulation};
use crate::hand::MAX_TIPS;
use crate::math::{Real, Vector};

/// Per fingertip, the projection onto the directions it can push across its push along the
/// normal (zero for a fingertip that cannot push along the normal).
type Ranges = [nalgebra::Matrix3<Real>; MAX_TIPS];

impl Simulation {
    /// The squeeze: per fingertip of the grasp, the normal force `N_k` the operator presses
    /// with and the unit push `u_k` (world) that delivers it, `f_k = N_k u_k`. Zero until every
    /// fingertip of the grasp touches.
    ///
    /// The squeeze is what friction needs to carry the load the operator expects (weight plus
    /// the arm's planned acceleration, anticipated as people do: Johansson & Westling 1984)
    /// with its safety margin, for the friction it expects, and follows the grip ramp. It is not
    /// re-sized from what the fingertips feel (no slip reflex): a squeeze too weak for the real
    /// μ lets the object slip. `u_k` is the contact's inward normal projected onto the
    /// directions the fingertip can push (glove10's fingers and thumb push only in their
    /// flexion planes; eq. 14 transmits only forces in the range of Jᵀ), scaled to a unit
    /// normal component. The magnitudes are balanced so the squeezes nearly cancel: minimise
    /// ‖N − N₀‖² + w ‖Σ N_k u_k‖² (w = 4), i.e. N = (I + w AᵀA)⁻¹ N₀; for opposing fingertips
    /// the squeeze is equal and opposite.
    pub(super) fn grip_forces(&self) -> ([Real; MAX_TIPS], [Vector; MAX_TIPS], [Vector; MAX_TIPS]) {
        let mut mags = [0.0; MAX_TIPS];
        let mut unit = [Vector::zeros(); MAX_TIPS];
        let mut lift = [Vector::zeros(); MAX_TIPS];
        if self.grip <= 0.0 {
            return (mags, unit, lift);
        }
        let out = self.dfs.output();
        let obj = self.target_object();
        let g = self.dfs.params().gravity;
        let p = &self.params;
        let planned = (0..out.n_tips.min(MAX_TIPS))
            .filter(|&k| self.plan.tips[k] && !self.resting[k])
            .count();
        // Fixed-capacity lists: this runs every tick of a session.
        let mut touching = [0usize; MAX_TIPS];
        let mut nt = 0;
        let mut squeezing = 0;
        for k in 0..out.n_tips.min(MAX_TIPS) {
            if self.plan.tips[k] && self.target_frame(k).is_some() {
                touching[nt] = k;
                nt += 1;
                squeezing += usize::from(!self.resting[k]);
            }
        }
        let touching = &touching[..nt];
        // Squeeze only once every squeezing finger of the grasp is on the object.
        if squeezing == 0 || squeezing < planned {
            return (mags, unit, lift);
        }
        let load_force = (self.base_acceleration - g) * obj.mass;
        let load = load_force.norm();
        let normal = (p.grip_safety * load / (self.operator_mu * squeezing as Real))
            .max(p.min_normal)
            * self.grip
            * (1.0 + self.grip_boost);
        let mut ok = [false; MAX_TIPS];
        let mut range = [nalgebra::Matrix3::<Real>::zeros(); MAX_TIPS];
        let mut arm = [Vector::zeros(); MAX_TIPS];
        self.push_directions(touching, &mut unit, &mut ok, &mut range, &mut arm);
        // The squeeze and the load are the squeezing fingertips'; a resting one only presses
        // lightly along its push.
        let mut ks = [0usize; MAX_TIPS];
        let mut m = 0;
        for &k in touching.iter().filter(|&&k| ok[k]) {
            if self.resting[k] {
                mags[k] = p.min_normal * self.grip;
            } else {
                ks[m] = k;
                m += 1;
            }
        }
        let solved = balanced_normals(&unit, &ks[..m], normal);
        for (idx, &k) in ks.iter().enumerate().take(m) {
            mags[k] = solved[idx].max(p.min_normal * self.grip);
        }
        for k in 0..MAX_TIPS {
            if !ok[k] {
                unit[k] = Vector::zeros();
            }
        }
        if self.carry > 0.0 && m > 0 {
            self.distribute_load(&ks[..m], &range, &arm, &mags, &unit, load_force, &mut lift);
        }
        (mags, unit, lift)
    }

    /// Per fingertip of `touching`: its push `unit[k]` (the contact's inward normal projected
    /// onto the directions it can push, scaled to a unit normal component) when that leans
    /// off the normal by less than cos⁻¹ 0.2 (`ok[k]`), the projection `range[k]` onto the
    /// directions it can push across that push, and the contact point from the centre of mass
    /// `arm[k]` (world).
    fn push_directions(
        &self,
        touching: &[usize],
        unit: &mut [Vector; MAX_TIPS],
        ok: &mut [bool; MAX_TIPS],
        range: &mut Ranges,
        arm: &mut [Vector; MAX_TIPS],
    ) {
        let st = self.target_state();
        let kin = self.dfs.kinematics();
        let hand = self.dfs.hand();
        for &k in touching {
            let Some(frame) = self.target_frame(k) else {
                continue;
            };
            let n_in = st.pose.rotation * frame.normal_b();
            arm[k] = st.pose.rotation * frame.p_b;
            let (basis, nb) = push_basis(hand, kin, k);
            let mut dir = Vector::zeros();
            for b in basis.iter().take(nb) {
                dir += b * b.dot(&n_in);
                range[k] += b * b.transpose();
            }
            let along = dir.dot(&n_in);
            if along >= 0.2 {
                unit[k] = dir / along;
                ok[k] = true;
                // The load force is tangential: the squeeze alone sets the normal force.
                let d = dir.normalize();
                range[k] -= d * d.transpose();
            }
        }
    }

    /// The load force (Johansson & Westling's "load force", beside the grip force): how the
    /// fingertips `ks` share lifting the object. Each fingertip pushes `l_k` within the
    /// directions it can push, across its push along the normal (`range[k]`, a projection: the
    /// squeeze alone sets the normal force); together with the squeeze
    /// `N_k u_k` they apply the wrench the expected motion needs, `Σ (l_k + N_k u_k) =
    /// carry · m (a − g)` and no moment about the centre of mass (`arm[k]`: contact point from
    /// the centre, world), so the stick springs are left with nothing to carry and the object
    /// does not turn in the hand when the fingertips do not sit exactly opposite. Nearest to an
    /// equal share: `l = l₀ + Aᵀ (A Aᵀ + εI)⁻¹ (b − A l₀)`, moments scaled by 1/(3 cm); the
    /// small ε leaves out what the fingertips cannot do (a moment about the line through two
    /// contacts).
    #[allow(clippy::too_many_arguments)]
    fn distribute_load(
        &self,
        ks: &[usize],
        range: &Ranges,
        arm: &[Vector; MAX_TIPS],
        mags: &[Real; MAX_TIPS],
        unit: &[Vector; MAX_TIPS],
        load_force: Vector,
        lift: &mut [Vector; MAX_TIPS],
    ) {
        const SCALE: Real = 1.0 / 0.03;
        let want = load_force * self.carry;
        let mut squeeze_force = Vector::zeros();
        let mut squeeze_moment = Vector::zeros();
        for &k in ks {
            let f = unit[k] * mags[k];
            squeeze_force += f;
            squeeze_moment += arm[k].cross(&f);
        }
        // Per fingertip, the 6x3 block A_k = [P_k; [r_k]x P_k / L].
        let mut blocks = [nalgebra::SMatrix::<Real, 6, 3>::zeros(); MAX_TIPS];
        let mut aat = nalgebra::Matrix6::<Real>::zeros();
        let mut resid = nalgebra::Vector6::<Real>::zeros();
        let share = want / ks.len() as Real;
        let mut b = nalgebra::Vector6::<Real>::zeros();
        b.fixed_rows_mut::<3>(0).copy_from(&(want - squeeze_force));
        b.fixed_rows_mut::<3>(3)
            .copy_from(&(-squeeze_moment * SCALE));
        resid += b;
        for &k in ks {
            let p = range[k];
            let mut a = nalgebra::SMatrix::<Real, 6, 3>::zeros();
            a.fixed_view_mut::<3, 3>(0, 0).copy_from(&p);
            a.fixed_view_mut::<3, 3>(3, 0)
                .copy_from(&(arm[k].cross_matrix() * p * SCALE));
            lift[k] = p * share;
            resid -= a * share;
            aat += a * a.transpose();
            blocks[k] = a;
        }
        let eps = 1e-3 * aat.trace().max(1e-12);
        for i in 0..6 {
            aat[(i, i)] += eps;
        }
        if let Some(chol) = aat.cholesky() {
            let y = chol.solve(&resid);
            for &k in ks {
                lift[k] += blocks[k].transpose() * y;
            }
        }
    }
}

/// The squeezes' magnitudes for the squeezing fingertips `ks` (in their order), balanced so
/// they nearly cancel: `N = (I + 4 AᵀA)⁻¹ N₀` with `N₀` all `normal` and `A`'s columns the
/// fingertips' pushes; `N₀` when the system cannot be solved.
fn balanced_normals(unit: &[Vector; MAX_TIPS], ks: &[usize], normal: Real) -> [Real; MAX_TIPS] {
    let m = ks.len();
    let mut sys = nalgebra::SMatrix::<Real, MAX_TIPS, MAX_TIPS>::identity();
    let wanted = [normal; MAX_TIPS];
    let mut solved = wanted;
    for a in 0..m {
        for b in 0..m {
            sys[(a, b)] += 4.0 * unit[ks[a]].dot(&unit[ks[b]]);
        }
    }
    if !crate::math::cholesky_solve_in_place(&mut sys, m, &mut solved) {
        solved = wanted;
    }
    solved
}
