//! Ready-made set-ups shared by the tick and grasp-quality benchmarks, the allocation test and
//! `icms bench tick`.

mod power_grasp;
pub use power_grasp::*;

use crate::contact::{ContactFrame, ContactModel, Friction, Intensity};
use crate::dfs::{Dfs, DfsParams, GloveSample};
use crate::error::Result;
use crate::hand::{HandModel, Kinematics, MAX_DOF};
use crate::math::{Isometry, Real, Vector};
use crate::object::{ObjectState, RigidObject, Shape};

/// glove10 holding the paper's sphere, as [`glove10_holding_paper_sphere`] sets it up: the DFS
/// and the glove sample that holds it.
#[derive(Debug, Clone)]
pub struct HeldSphere {
    /// The DFS: glove10 and the sphere, ticked once with [`q`](Self::q), [`tau`](Self::tau)
    /// and [`base`](Self::base), the sphere then put back at rest where it was placed.
    pub dfs: Dfs,
    /// The glove's joint angles θ (rad), one per degree of freedom of glove10.
    pub q: Vec<Real>,
    /// The operator's joint torques τ (N·m), one per degree of freedom: 3 N along each
    /// touching fingertip's inward normal, mapped through its Jacobian (`τ = Σ Jᵀ f`).
    pub tau: Vec<Real>,
    /// The hand base's pose in the world: at the origin, palm up.
    pub base: Isometry,
}

/// The frozen sample of the tick benchmarks (`icms bench tick --scene frozen`, the criterion
/// bench `dfs_tick_glove10_paper_sphere_4_contacts`, `examples/tick_count.rs`): a
/// [`HeldSphere`]'s glove sample, given every tick with the sphere first put back where it
/// was placed, so that every tick does the same four-contact work.
#[derive(Debug, Clone)]
pub struct FrozenSample {
    q: Vec<Real>,
    tau: Vec<Real>,
    base: Isometry,
    start: ObjectState,
}

impl FrozenSample {
    /// `held`'s glove sample and its sphere's state now.
    pub fn of(held: &HeldSphere) -> FrozenSample {
        FrozenSample {
            q: held.q.clone(),
            tau: held.tau.clone(),
            base: held.base,
            start: *held.dfs.object_state(),
        }
    }

    /// One frozen tick of `dfs` (the sphere put back, then [`Dfs::step`] with the sample,
    /// behind [`std::hint::black_box`] so that the tick is not optimised away); its output.
    pub fn tick<'d>(&self, dfs: &'d mut Dfs) -> Result<&'d crate::dfs::TickOutput> {
        dfs.set_object_state(self.start);
        dfs.step(std::hint::black_box(&GloveSample {
            q: &self.q,
            tau: &self.tau,
            base: self.base,
        }))
    }
}

/// glove10 holding the paper's sphere (1 kg, r = 0.1 m) on four fingertips (index, middle,
/// ring, little), each pushing 3 N along its inward normal through operator torques
/// `τ = Σ Jᵀ f` (μ = 1.5 as in §3.4). Returns the DFS and the glove sample (θ, τ, base) as a
/// [`HeldSphere`].
/// Four fingertips on one side of a 0.2 m sphere cannot balance its weight (glove10's thumb
/// cannot span it), so the sphere is not in equilibrium: callers that tick repeatedly reset the
/// object's state each tick to measure the same four-contact tick.
///
/// The fingers are curled to a fixed pose and the sphere is placed, by least squares, where it
/// touches all four fingertips, its radius (0.1 m within half a millimetre) such that each
/// presses at least 0.1 mm into it; the hand base is at the world origin, palm up.
pub fn glove10_holding_paper_sphere() -> Result<HeldSphere> {
    let hand = HandModel::glove10();
    let n = hand.dof();
    let mut q = vec![0.0; n];
    for (d, name) in hand.dof_names.iter().enumerate() {
        q[d] = match name.as_str() {
            "index_mcp" | "middle_mcp" => 0.9,
            "index_pip" | "middle_pip" => 0.4,
            "index_dip" => 0.25,
            "thumb_cmc" => 0.0,
            "thumb_mcp" => -0.2,
            _ => 0.0,
        };
    }
    // Palm up: rotate the palm (which faces −z) by π about x.
    let base = Isometry::from_parts(
        Vector::zeros().into(),
        crate::math::Rotation::from_axis_angle(&Vector::x_axis(), std::f64::consts::PI),
    );
    let mut kin = Kinematics::default();
    hand.forward_kinematics(&base, &q, &mut kin);
    let tips: Vec<usize> = ["index", "middle", "ring", "little"]
        .iter()
        .filter_map(|s| hand.fingertips.iter().position(|t| t.name == *s))
        .collect();
    let radius = 0.1;
    // Gauss-Newton for the centre c with |t_k − c| = r + r_k, started above the fingertips.
    let mut c = tips
        .iter()
        .map(|&k| kin.tip_centres[k].coords)
        .sum::<Vector>()
        / tips.len() as Real;
    c.z += radius;
    for _ in 0..50 {
        let mut jtj = nalgebra::Matrix3::<Real>::zeros();
        let mut jtr = Vector::zeros();
        for &k in &tips {
            let d = c - kin.tip_centres[k].coords;
            let dist = d.norm();
            let u = d / dist;
            let res = dist - (radius + hand.fingertips[k].radius);
            jtj += u * u.transpose();
            jtr += u * res;
        }
        let step = (jtj + nalgebra::Matrix3::identity() * 1e-9)
            .lu()
            .solve(&jtr)
            .unwrap_or_else(Vector::zeros);
        c -= step;
        if step.norm() < 1e-12 {
            break;
        }
    }
    // Four fingertips do not lie on one sphere: the least-squares centre leaves some a fraction
    // of a millimetre off the surface. The radius is set so that every fingertip presses in by
    // at least the contact preload (0.1 mm), past the contact ramp: a fingertip across a gap
    // transmits nothing.
    let radius = tips
        .iter()
        .map(|&k| (kin.tip_centres[k].coords - c).norm() - hand.fingertips[k].radius)
        .fold(0.0, Real::max)
        + DfsParams::default().contact_preload;
    let object = RigidObject::new(Shape::Sphere { radius }, 1.0)?;
    let pose = Isometry::translation(c.x, c.y, c.z);
    let params = DfsParams {
        contact_model: ContactModel::PointWithFriction,
        friction: Friction {
            mu: 1.5,
            mu_torsion: 0.0,
        },
        contact_margin: 0.005,
        // Four fingertips on one side carry 1 kg: the torques exceed a person's; this fixture
        // measures computation, so the glove's sensor range is widened.
        torque_range: 10.0,
        ..DfsParams::default()
    };
    // Minimum-norm holding forces on the four contacts, mapped to joint torques.
    let mut dfs = Dfs::new(hand.clone(), object, ObjectState::at_rest(pose), params)?;
    let tau0 = vec![0.0; n];
    dfs.step(&GloveSample {
        q: &q,
        tau: &tau0,
        base,
    })?;
    dfs.set_object_state(ObjectState::at_rest(pose));
    let out = *dfs.output();
    let mut frames = Vec::new();
    let mut ks = Vec::new();
    for &k in &tips {
        if let Some(f) = out.tips[k].frame {
            frames.push(f);
            ks.push(k);
        }
    }
    let mut tau = vec![0.0; n];
    hand.tip_jacobians(&mut kin);
    for (i, &k) in ks.iter().enumerate() {
        let c = Intensity::new(0.0, 0.0, 3.0, 0.0);
        let f = pose.rotation * (frames[i].rot_b * Vector::new(c[0], c[1], c[2]));
        let j = &kin.tip_jacobians[k];
        for (d, t) in tau.iter_mut().enumerate().take(n.min(MAX_DOF)) {
            *t += j[(0, d)] * f.x + j[(1, d)] * f.y + j[(2, d)] * f.z;
        }
    }
    let mut dfs = Dfs::new(hand, object, ObjectState::at_rest(pose), params)?;
    dfs.step(&GloveSample {
        q: &q,
        tau: &tau,
        base,
    })?;
    dfs.set_object_state(ObjectState::at_rest(pose));
    Ok(HeldSphere { dfs, q, tau, base })
}

/// The paper's §3.4 sphere grasp: four contacts on a sphere centred at B's origin, normals
/// from each point through the centre (the grasp-quality benchmark's input).
pub fn paper_sphere_contacts() -> Vec<ContactFrame> {
    [
        [0.054, 0.054, -0.059],
        [0.0, 0.076, -0.059],
        [-0.054, 0.054, -0.059],
        [0.0, -0.076, -0.059],
    ]
    .iter()
    .map(|p| {
        let p = Vector::from(*p);
        ContactFrame::from_normal(p, -p.normalize())
    })
    .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn glove10_touches_the_paper_sphere_with_four_fingertips() {
        let HeldSphere {
            mut dfs,
            q,
            tau,
            base,
        } = glove10_holding_paper_sphere().unwrap();
        let out = dfs
            .step(&GloveSample {
                q: &q,
                tau: &tau,
                base,
            })
            .unwrap();
        assert_eq!(
            out.n_contacts,
            4,
            "{:?}",
            out.tips
                .iter()
                .map(|t| (t.touching, t.in_contact))
                .collect::<Vec<_>>()
        );
        assert!(out.f_ext_b.iter().all(|v| v.is_finite()));
    }
}
