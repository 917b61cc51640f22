//! The grasp matrix `ᴮW` (eq. 22), object force `ᴮf̃ = ᴮW c̃` (eq. 23), the minimum-norm
//! distribution `c_o = W⁺ f` (eq. 27), grasp force optimisation and grasp quality.
//!
//! `W` has a fixed capacity of four columns per contact (layout of
//! [`Intensity`]); columns a contact model does not transmit are
//! zero, so they carry no intensity. `W⁺ f = D² Wᵀ (W D² Wᵀ)⁺ f` with a tolerance on the 6x6
//! `W D² Wᵀ`: finite for one contact or collinear contacts, allocation-free.
//!
//! **Torsion weight.** `D = diag(1, 1, 1, ℓ)` per contact: the distribution is the one of least
//! `Σ ‖c_t‖² + c_z² + (c_τ / ℓ)²`, a torsion measured against forces through a length, so it
//! does not depend on the unit of length (with `D = 1` it weighed N·m against N, and a grasp
//! described in millimetres got another distribution than the same grasp in metres). `ℓ` is
//! the soft-finger cone's characteristic length `μ_t / μ`
//! ([`Friction::torsion_length`](crate::contact::Friction::torsion_length)), the metric in
//! which that cone is round, as in the grasp force optimiser ([`optimise`]); with `μ_t = 0` the
//! torsion gets no share (the cone transmits none), with `μ = 0 < μ_t` the largest distance of
//! a contact from B's origin.

pub mod optimise;
pub mod quality;

use crate::contact::{ContactFrame, ContactModel, Friction, Intensity};
use crate::hand::{MAX_CONTACT_SHAPES, MAX_TIPS};
use crate::math::{wrench, Mat6, Real, SymPinv6, Vector, Wrench};
use nalgebra::SMatrix;

/// Most contacts a grasp can have: one per fingertip and one per whole-hand contact shape (palm,
/// phalanges), 6 + 24 = 30.
pub const MAX_CONTACTS: usize = MAX_TIPS + MAX_CONTACT_SHAPES;
/// Columns of `W` at capacity.
pub const MAX_COLUMNS: usize = 4 * MAX_CONTACTS;
/// Relative eigenvalue tolerance of the pseudo-inverse.
pub const PINV_TOLERANCE: Real = 1e-9;

/// The grasp matrix of up to [`MAX_CONTACTS`] contacts.
#[derive(Debug, Clone, Copy)]
pub struct GraspMatrix {
    /// `ᴮW`: six rows, four columns per contact (unused columns zero).
    pub w: SMatrix<Real, 6, MAX_COLUMNS>,
    /// Number of contacts.
    pub n: usize,
    /// `(W D² Wᵀ)⁺`.
    wwt_pinv: SymPinv6,
    /// `ℓ²`, the weight of the torsion columns in `W D² Wᵀ` (module documentation).
    torsion_weight: Real,
    /// Rank of `W`.
    pub rank: usize,
}

impl GraspMatrix {
    /// Builds `ᴮW` for the contacts (at most [`MAX_CONTACTS`]; extra contacts are ignored),
    /// with the torsion weight of `friction` (module documentation).
    pub fn new(contacts: &[ContactFrame], model: ContactModel, friction: &Friction) -> Self {
        let mut g = GraspMatrix {
            w: SMatrix::zeros(),
            n: 0,
            wwt_pinv: SymPinv6::Explicit(Mat6::zeros()),
            torsion_weight: 1.0,
            rank: 0,
        };
        g.rebuild(contacts, model, friction);
        g
    }

    /// [`new`](Self::new) in place: the DFS rebuilds its grasp matrix every tick, and moving
    /// a new one (1.5 kB) into place cost more than some of its arithmetic.
    pub fn rebuild(&mut self, contacts: &[ContactFrame], model: ContactModel, friction: &Friction) {
        let n = contacts.len().min(MAX_CONTACTS);
        let ell = torsion_scale(&contacts[..n], friction);
        let torsion_weight = ell * ell;
        let w = &mut self.w;
        // The columns of the contacts, and any a larger grasp left before: the rest are zero.
        let used = n.max(self.n).min(MAX_CONTACTS);
        w.as_mut_slice()[..6 * 4 * used].fill(0.0);
        let mask = model.mask();
        // With all three force columns transmitted (point with friction, soft finger) their
        // share of W Wᵀ has a closed form (below); otherwise it is summed column by column.
        let all_forces = mask[0] != 0.0 && mask[1] != 0.0 && mask[2] != 0.0;
        // W Wᵀ = Σ over the transmitted columns of col colᵀ (the zero columns add nothing).
        let mut wwt = Mat6::zeros();
        for (i, c) in contacts.iter().take(n).enumerate() {
            // Columns of Λ_i: the unit forces along the contact axes (columns of the frame's
            // rotation) at p, and the unit moment about the normal (eq. 22, Table 1).
            let r = c.rot_b.matrix();
            for k in 0..4 {
                if mask[k] == 0.0 {
                    continue;
                }
                let col = if k < 3 {
                    let f = r.column(k).into_owned();
                    wrench(&f, &c.p_b.cross(&f))
                } else {
                    wrench(&Vector::zeros(), &r.column(2).into_owned())
                };
                w.set_column(4 * i + k, &col);
                if k < 3 && all_forces {
                    continue;
                }
                let weight = if k == 3 { torsion_weight } else { 1.0 };
                for a in 0..6 {
                    for b in a..6 {
                        wwt[(a, b)] += weight * col[a] * col[b];
                    }
                }
            }
            if all_forces {
                // The columns (f, p × f) for the orthonormal columns f of R: Σ f fᵀ = R Rᵀ = 1,
                // so they add [[1, −[p]×], [[p]×, |p|² 1 − p pᵀ]] (upper triangle here).
                let p = c.p_b;
                let p2 = p.norm_squared();
                for a in 0..3 {
                    wwt[(a, a)] += 1.0;
                    for b in a..3 {
                        let shift = if a == b { p2 } else { 0.0 };
                        wwt[(3 + a, 3 + b)] += shift - p[a] * p[b];
                    }
                }
                // −[p]×, row by row.
                wwt[(0, 4)] += p.z;
                wwt[(0, 5)] -= p.y;
                wwt[(1, 3)] -= p.z;
                wwt[(1, 5)] += p.x;
                wwt[(2, 3)] += p.y;
                wwt[(2, 4)] -= p.x;
            }
        }
        for a in 0..6 {
            for b in 0..a {
                wwt[(a, b)] = wwt[(b, a)];
            }
        }
        let (wwt_pinv, rank) = SymPinv6::new(&wwt, PINV_TOLERANCE);
        self.n = n;
        self.wwt_pinv = wwt_pinv;
        self.torsion_weight = torsion_weight;
        self.rank = rank;
    }

    /// `ᴮf̃ = ᴮW c̃` (eq. 23) for per-contact intensities.
    pub fn wrench(&self, c: &[Intensity]) -> Wrench {
        let mut f = Wrench::zeros();
        for (i, ci) in c.iter().take(self.n).enumerate() {
            f += self.w.fixed_view::<6, 4>(0, 4 * i) * ci;
        }
        f
    }

    /// The minimum-norm intensities `W⁺ f` (eq. 27), written into `out[..n]`: the least
    /// `Σ ‖c_t‖² + c_z² + (c_τ / ℓ)²` among those that reproduce `f`'s part in the range of
    /// `W` (module documentation).
    pub fn distribute(&self, f: &Wrench, out: &mut [Intensity]) {
        let y = self.wwt_pinv.apply(f);
        for (i, o) in out.iter_mut().take(self.n).enumerate() {
            *o = self.w.fixed_view::<6, 4>(0, 4 * i).transpose() * y;
            o[3] *= self.torsion_weight;
        }
    }

    /// True when `W` spans all six wrench directions (necessary for force closure).
    pub fn full_rank(&self) -> bool {
        self.rank == 6
    }
}

/// The length `ℓ` (m) that weighs the torsion against forces for `contacts` with `friction`
/// (module documentation): the soft-finger cone's `μ_t / μ`; 0 when `μ_t = 0`; with `μ = 0 <
/// μ_t`, the largest distance of a contact from B's origin (1 m when they all sit at it).
pub fn torsion_scale(contacts: &[ContactFrame], friction: &Friction) -> Real {
    if let Some(e) = friction.torsion_length() {
        return e;
    }
    if friction.mu_torsion.is_nan() || friction.mu_torsion <= 0.0 {
        return 0.0;
    }
    let r = contacts.iter().fold(0.0_f64, |m, c| m.max(c.p_b.norm()));
    if r > 0.0 && r.is_finite() {
        r
    } else {
        1.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// The paper's §3.4 sphere contacts, normals from each point through the centre; shared by
    /// the grasp tests.
    pub(crate) fn paper_contacts() -> Vec<ContactFrame> {
        crate::fixtures::paper_sphere_contacts()
    }

    /// The paper's sphere grasp with friction `mu` and `load`, in a unit of length `s` times
    /// smaller than the metre (`s` = 1000: millimetres): the contacts' positions, μ_t
    /// (5 mm) and the load's moments `s` times larger. Shared by the tests that the force
    /// distributions do not depend on the unit.
    pub(crate) fn paper_grasp_in_unit(
        s: Real,
        mu: Real,
        load: &Wrench,
    ) -> (Vec<ContactFrame>, Friction, Wrench) {
        let contacts = paper_contacts()
            .iter()
            .map(|c| ContactFrame {
                p_b: c.p_b * s,
                rot_b: c.rot_b,
            })
            .collect();
        let friction = Friction {
            mu,
            mu_torsion: 0.005 * s,
        };
        let mut l = *load;
        for k in 3..6 {
            l[k] *= s;
        }
        (contacts, friction, l)
    }

    /// Friction of the tests' soft fingers: μ = 0.8, μ_t = 5 mm.
    fn soft() -> Friction {
        Friction {
            mu: 0.8,
            mu_torsion: 0.005,
        }
    }

    #[test]
    fn the_paper_sphere_example_reproduces_the_notes_table() {
        let contacts = paper_contacts();
        let g = GraspMatrix::new(&contacts, ContactModel::PointWithFriction, &soft());
        let mut c = [Intensity::zeros(); 4];
        g.distribute(&Wrench::new(0.0, 0.0, 9.81, 0.0, 0.0, 0.0), &mut c);
        let expected = [
            (1.197, 1.550),
            (0.954, 1.229),
            (1.197, 1.550),
            (2.660, 3.427),
        ];
        for (ci, (n, t)) in c.iter().zip(expected) {
            let (cn, ct) = crate::contact::normal_and_tangential(ci);
            assert!((cn - n).abs() / n < 0.01, "normal {cn} vs {n}");
            assert!((ct - t).abs() / t < 0.01, "tangential {ct} vs {t}");
        }
        let f = g.wrench(&c);
        assert!((f - Wrench::new(0.0, 0.0, 9.81, 0.0, 0.0, 0.0)).norm() < 1e-9);
    }

    #[test]
    fn the_closed_form_of_w_wt_equals_the_sum_over_the_columns() {
        let contacts = paper_contacts();
        for model in [ContactModel::PointWithFriction, ContactModel::SoftFinger] {
            let g = GraspMatrix::new(&contacts, model, &soft());
            // W D² Wᵀ, the torsion columns weighted by ℓ² = (μ_t / μ)².
            let mut wd = g.w;
            for i in 0..contacts.len() {
                wd.column_mut(4 * i + 3).scale_mut(0.005 / 0.8);
            }
            let wwt = wd * wd.transpose();
            // (W Wᵀ)⁺ W Wᵀ = 1 for the paper's full-rank grasp: the factor is of W Wᵀ itself.
            let back = Mat6::from_columns(
                &(0..6)
                    .map(|k| g.wwt_pinv.apply(&wwt.column(k).into_owned()))
                    .collect::<Vec<_>>(),
            );
            assert!((back - Mat6::identity()).norm() < 1e-9, "{model:?}: {back}");
        }
    }

    #[test]
    fn one_contact_and_collinear_contacts_stay_finite() {
        let one = [ContactFrame::from_normal(
            Vector::new(0.0, 0.0, -0.1),
            Vector::z(),
        )];
        let g = GraspMatrix::new(&one, ContactModel::PointWithFriction, &soft());
        assert_eq!(g.rank, 3);
        let mut c = [Intensity::zeros(); 1];
        g.distribute(&Wrench::new(0.0, 0.0, 9.81, 0.3, 0.0, 0.0), &mut c);
        assert!(c[0].iter().all(|v| v.is_finite()));
        assert!((c[0][2] - 9.81).abs() < 1e-6);
        let line = [
            ContactFrame::from_normal(Vector::new(-0.1, 0.0, 0.0), Vector::x()),
            ContactFrame::from_normal(Vector::new(0.1, 0.0, 0.0), -Vector::x()),
        ];
        let g = GraspMatrix::new(&line, ContactModel::PointWithFriction, &soft());
        assert_eq!(g.rank, 5);
        assert!(!g.full_rank());
    }

    #[test]
    fn the_minimum_norm_distribution_does_not_depend_on_the_unit_of_length() {
        // The paper's sphere with soft fingers, and the same grasp described in millimetres:
        // positions and μ_t a thousand times larger, moments too. The forces must come out the
        // same and the torsions a thousand times larger.
        let load = Wrench::new(0.4, -0.3, 9.81, 0.05, -0.02, 0.03);
        let mut by_unit = Vec::new();
        for s in [1.0, 1000.0] {
            let (contacts, friction, l) = paper_grasp_in_unit(s, 0.8, &load);
            let g = GraspMatrix::new(&contacts, ContactModel::SoftFinger, &friction);
            let mut c = [Intensity::zeros(); 4];
            g.distribute(&l, &mut c);
            assert!((g.wrench(&c) - l).norm() < 1e-9 * (1.0 + l.norm()));
            by_unit.push((s, c));
        }
        let (_, m) = by_unit[0];
        let (s, mm) = by_unit[1];
        for (a, b) in m.iter().zip(&mm) {
            let back = Intensity::new(b[0], b[1], b[2], b[3] / s);
            assert!(
                (a - back).norm() < 1e-9 * (1.0 + a.norm()),
                "{a:?} vs {back:?}"
            );
        }
        // The torsion is used, but weighed as what it costs the pad's cone.
        assert!(m.iter().any(|c| c[3].abs() > 1e-6), "{m:?}");
    }

    proptest! {
        #[test]
        fn w_times_w_pinv_reproduces_any_wrench_in_its_range(
            pts in prop::collection::vec(prop::array::uniform3(-1.0..1.0f64), 3..6),
            f in prop::array::uniform6(-10.0..10.0f64)
        ) {
            let contacts: Vec<_> = pts.iter().filter(|p| Vector::from(**p).norm() > 0.1)
                .map(|p| { let p = Vector::from(*p).normalize() * 0.1; ContactFrame::from_normal(p, -p) }).collect();
            let g = GraspMatrix::new(&contacts, ContactModel::SoftFinger, &soft());
            let f = Wrench::from_row_slice(&f);
            let mut c = [Intensity::zeros(); MAX_CONTACTS];
            g.distribute(&f, &mut c);
            let back = g.wrench(&c[..contacts.len()]);
            // The projection of f onto range(W) is reproduced exactly; a second pass is idempotent.
            let mut c2 = [Intensity::zeros(); MAX_CONTACTS];
            g.distribute(&back, &mut c2);
            prop_assert!((g.wrench(&c2[..contacts.len()]) - back).norm() < 1e-6 * (1.0 + f.norm()));
            if g.full_rank() {
                prop_assert!((back - f).norm() < 1e-6 * (1.0 + f.norm()));
            }
        }
    }
}
