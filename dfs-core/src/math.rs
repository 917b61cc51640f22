//! Scalar and geometric types used throughout the DFS, each named once.
//!
//! Everything is `f64` and fixed-size: the DFS tick never allocates. Wrenches are
//! (force, moment) and twists (linear, angular) 6-vectors, as in the paper.

use nalgebra::{Matrix3, Matrix6, Vector3, Vector6};

/// Scalar type of the whole simulator.
pub type Real = f64;
/// A 3-vector (m, m/s, N, ... depending on use).
pub type Vector = Vector3<Real>;
/// A point in 3-space (m).
pub type Point = nalgebra::Point3<Real>;
/// A unit 3-vector (a direction or an axis).
pub type UnitVector = nalgebra::Unit<Vector3<Real>>;
/// A rigid transform: rotation then translation.
pub type Isometry = nalgebra::Isometry3<Real>;
/// A rotation as a unit quaternion.
pub type Rotation = nalgebra::UnitQuaternion<Real>;
/// A wrench (force N, moment N·m).
pub type Wrench = Vector6<Real>;
/// A twist (linear m/s, angular rad/s).
pub type Twist = Vector6<Real>;
/// A 3x3 matrix.
pub type Mat3 = Matrix3<Real>;
/// A 6x6 matrix (wrench and twist maps, spatial inertia).
pub type Mat6 = Matrix6<Real>;

/// Standard gravity (m/s²), the value the paper uses.
pub const STANDARD_GRAVITY: Real = 9.81;

/// The cross-product matrix `[v]×`, so that `skew(a) * b == a.cross(&b)`.
#[inline]
pub fn skew(v: &Vector) -> Mat3 {
    Mat3::new(0.0, -v.z, v.y, v.z, 0.0, -v.x, -v.y, v.x, 0.0)
}

/// Builds a wrench from its force and moment parts.
#[inline]
pub fn wrench(force: &Vector, moment: &Vector) -> Wrench {
    Wrench::new(force.x, force.y, force.z, moment.x, moment.y, moment.z)
}

/// The force part (first three components) of a wrench.
#[inline]
pub fn force_of(w: &Wrench) -> Vector {
    Vector::new(w[0], w[1], w[2])
}

/// The moment part (last three components) of a wrench.
#[inline]
pub fn moment_of(w: &Wrench) -> Vector {
    Vector::new(w[3], w[4], w[5])
}

/// True when every component is finite (no NaN, no infinity).
#[inline]
pub fn all_finite<I: IntoIterator<Item = Real>>(values: I) -> bool {
    values.into_iter().all(Real::is_finite)
}

/// Pseudo-inverse of a symmetric positive semi-definite 6x6 matrix by eigen-decomposition:
/// eigenvalues below `rel_tol` times the largest are treated as zero, so the result stays
/// finite for rank-deficient input (collinear contacts, a stretched finger). Allocation-free.
pub fn sym_pinv6(a: &Mat6, rel_tol: Real) -> Mat6 {
    let eig = nalgebra::SymmetricEigen::new(*a);
    let max = eig.eigenvalues.iter().fold(0.0_f64, |m, &v| m.max(v.abs()));
    if max <= 0.0 || !max.is_finite() {
        return Mat6::zeros();
    }
    let tol = max * rel_tol;
    let mut inv = Mat6::zeros();
    for k in 0..6 {
        let l = eig.eigenvalues[k];
        if l > tol {
            let v = eig.eigenvectors.column(k);
            inv += (v * v.transpose()) / l;
        }
    }
    inv
}

/// Rank of a symmetric positive semi-definite 6x6 matrix with the same tolerance rule as
/// [`sym_pinv6`].
pub fn sym_rank6(a: &Mat6, rel_tol: Real) -> usize {
    let eig = nalgebra::SymmetricEigen::new(*a);
    let max = eig.eigenvalues.iter().fold(0.0_f64, |m, &v| m.max(v.abs()));
    if max <= 0.0 || !max.is_finite() {
        return 0;
    }
    eig.eigenvalues
        .iter()
        .filter(|&&l| l > max * rel_tol)
        .count()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn skew_matrix_is_the_cross_product() {
        let a = Vector::new(1.0, -2.0, 0.5);
        let b = Vector::new(0.3, 4.0, -1.0);
        assert!((skew(&a) * b - a.cross(&b)).norm() < 1e-12);
    }

    #[test]
    fn symmetric_pseudo_inverse_of_a_rank_deficient_matrix_is_finite_and_consistent() {
        let mut a = Mat6::zeros();
        a[(0, 0)] = 2.0;
        a[(1, 1)] = 4.0;
        let p = sym_pinv6(&a, 1e-9);
        assert!(p.iter().all(|v| v.is_finite()));
        assert!((a * p * a - a).norm() < 1e-12);
        assert_eq!(sym_rank6(&a, 1e-9), 2);
    }
}
