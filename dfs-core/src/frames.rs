//! Coordinate frames of the paper's §3.1 (eq. 1-12).
//!
//! Frames: fingertip T_i, contact C_i, object B. `U_i` is the pose of C_i expressed in T_i
//! (`C_i = T_i U_i`, eq. 3) and `V_i` the pose of B expressed in C_i (`B = C_i V_i`, eq. 4).
//! The paper's eq. 9-10 are garbled in the scan; we derive the maps (docs/physics.md):
//! for a pose `X = [R p; 0 1]` of frame b in frame a, a wrench (f, m) given in b at b's origin
//! is, in a at a's origin, `f_a = R f_b`, `m_a = R m_b + p × (R f_b)`, i.e. the 6x6 matrix
//! `[R 0; [p]×R R]` ([`wrench_map`]).
//!
//! `Γ_i` maps a wrench from T_i into C_i, so `Γ_i = wrench_map(U_i⁻¹)`; with `p_u = 0` it is
//! `diag(Rᵀ, Rᵀ)` (Remark 1). `Λ_i` maps from C_i into B: `Λ_i = wrench_map(V_i⁻¹)`.
//! Then `Λ_i Γ_i` is the map of `(U_i V_i)⁻¹`, the pose of T_i in B (eq. 6).

use crate::math::{skew, Isometry, Mat6, Twist, Wrench};
use nalgebra::Matrix4;

/// The 4x4 homogeneous matrix `[R p; 0 1]` of a pose (eq. 7-8).
pub fn homogeneous(x: &Isometry) -> Matrix4<f64> {
    x.to_homogeneous()
}

/// The 6x6 map taking a wrench expressed in frame b (at b's origin) to frame a (at a's
/// origin), where `x` is the pose of b in a: `[R 0; [p]×R R]`.
pub fn wrench_map(x: &Isometry) -> Mat6 {
    let r = x.rotation.to_rotation_matrix().into_inner();
    let p = x.translation.vector;
    let mut m = Mat6::zeros();
    m.fixed_view_mut::<3, 3>(0, 0).copy_from(&r);
    m.fixed_view_mut::<3, 3>(3, 3).copy_from(&r);
    m.fixed_view_mut::<3, 3>(3, 0).copy_from(&(skew(&p) * r));
    m
}

/// The 6x6 map taking a twist (linear, angular) of a body, expressed in frame b at b's origin,
/// to frame a at a's origin, where `x` is the pose of b in a: `[R [p]×R; 0 R]`.
/// It is the inverse transpose of [`wrench_map`], so power `wᵀ t` is frame-invariant.
pub fn twist_map(x: &Isometry) -> Mat6 {
    let r = x.rotation.to_rotation_matrix().into_inner();
    let p = x.translation.vector;
    let mut m = Mat6::zeros();
    m.fixed_view_mut::<3, 3>(0, 0).copy_from(&r);
    m.fixed_view_mut::<3, 3>(3, 3).copy_from(&r);
    m.fixed_view_mut::<3, 3>(0, 3).copy_from(&(skew(&p) * r));
    m
}

/// Applies [`wrench_map`] without forming the matrix (the hot-path form).
#[inline]
pub fn transform_wrench(x: &Isometry, w_b: &Wrench) -> Wrench {
    let f = x.rotation * crate::math::force_of(w_b);
    let m = x.rotation * crate::math::moment_of(w_b) + x.translation.vector.cross(&f);
    crate::math::wrench(&f, &m)
}

/// `Γ_i`: maps a fingertip wrench `ᵀf_i` into the contact frame, `ᶜf_i = Γ_i ᵀf_i` (eq. 5).
/// `u` is `U_i`, the pose of the contact frame C_i in the fingertip frame T_i.
pub fn gamma(u: &Isometry) -> Mat6 {
    wrench_map(&u.inverse())
}

/// `Λ_i`: maps a contact wrench `ᶜf_i` into the object frame, `ᴮf_i = Λ_i ᶜf_i` (eq. 6).
/// `v` is `V_i`, the pose of the object frame B in the contact frame C_i.
pub fn lambda(v: &Isometry) -> Mat6 {
    wrench_map(&v.inverse())
}

/// Power (W) of a wrench on a twist given in the same frame.
#[inline]
pub fn power(w: &Wrench, t: &Twist) -> f64 {
    w.dot(t)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::{Rotation, Vector};
    use nalgebra::{Translation3, Vector6};
    use proptest::prelude::*;

    fn iso(t: [f64; 3], r: [f64; 3]) -> Isometry {
        Isometry::from_parts(
            Translation3::new(t[0], t[1], t[2]),
            Rotation::from_scaled_axis(Vector::new(r[0], r[1], r[2])),
        )
    }

    fn arb_iso() -> impl Strategy<Value = Isometry> {
        (
            prop::array::uniform3(-1.0..1.0f64),
            prop::array::uniform3(-3.0..3.0f64),
        )
            .prop_map(|(t, r)| iso(t, r))
    }

    fn arb6() -> impl Strategy<Value = Vector6<f64>> {
        prop::array::uniform6(-10.0..10.0f64).prop_map(|a| Vector6::from_row_slice(&a))
    }

    proptest! {
        #[test]
        fn composing_the_maps_of_u_and_v_equals_the_map_of_uv(u in arb_iso(), v in arb_iso()) {
            let composed = lambda(&v) * gamma(&u);
            let direct = wrench_map(&(u * v).inverse());
            prop_assert!((composed - direct).norm() < 1e-9);
        }

        #[test]
        fn a_wrenchs_power_on_a_twist_is_frame_invariant(x in arb_iso(), w in arb6(), t in arb6()) {
            let p_b = power(&w, &t);
            let p_a = power(&(wrench_map(&x) * w), &(twist_map(&x) * t));
            prop_assert!((p_a - p_b).abs() < 1e-8 * (1.0 + p_b.abs()));
        }

        #[test]
        fn the_inverse_map_undoes_the_map(x in arb_iso(), w in arb6()) {
            let back = wrench_map(&x.inverse()) * (wrench_map(&x) * w);
            prop_assert!((back - w).norm() < 1e-9);
        }

        #[test]
        fn the_matrix_free_transform_equals_the_matrix(x in arb_iso(), w in arb6()) {
            prop_assert!((transform_wrench(&x, &w) - wrench_map(&x) * w).norm() < 1e-9);
        }
    }

    #[test]
    fn remark_1_pure_rotation_gives_block_diagonal_transposes() {
        let u = iso([0.0, 0.0, 0.0], [0.3, -0.7, 1.1]);
        let r = u.rotation.to_rotation_matrix().into_inner();
        let g = gamma(&u);
        let mut expected = Mat6::zeros();
        expected
            .fixed_view_mut::<3, 3>(0, 0)
            .copy_from(&r.transpose());
        expected
            .fixed_view_mut::<3, 3>(3, 3)
            .copy_from(&r.transpose());
        assert!((g - expected).norm() < 1e-12);
    }

    #[test]
    fn a_force_at_an_offset_origin_produces_the_lever_moment() {
        // Frame b sits 1 m along x of frame a; a force of 1 N along y in b gives a moment
        // of +1 N·m about z in a.
        let x = iso([1.0, 0.0, 0.0], [0.0, 0.0, 0.0]);
        let w = wrench_map(&x) * Vector6::new(0.0, 1.0, 0.0, 0.0, 0.0, 0.0);
        assert!((w - Vector6::new(0.0, 1.0, 0.0, 0.0, 0.0, 1.0)).norm() < 1e-12);
        assert_eq!(homogeneous(&x)[(0, 3)], 1.0);
    }
}
