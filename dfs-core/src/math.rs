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
/// A rotation as its orthonormal matrix (cheaper to apply than a quaternion; used where a
/// rotation is built once and applied many times, as a contact frame is).
pub type RotationMatrix = nalgebra::Rotation3<Real>;
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

/// `(sin x, cos x)` within 4.5e-16 of the standard library's (absolute error: near a multiple
/// of π the sine is tiny and its relative error larger, as π/2 is split in two parts only),
/// inlined: forward kinematics needs a dozen per tick
/// (the half angles of the rotating joints), and the C library's `sincos` is a call that
/// returns through memory. The argument is reduced by multiples of π/2 (Cody and Waite, with
/// π/2 split in two so `n · PIO2_HI` is exact for |x| ≤ 10⁵) and the remainder, |r| ≤ π/4,
/// goes through the minimax polynomials of fdlibm's `__kernel_sin` and `__kernel_cos` (Sun
/// Microsystems, 1993, the coefficients every libm since uses). Larger, infinite or NaN
/// arguments take the standard library's path.
#[inline]
pub fn sin_cos(x: Real) -> (Real, Real) {
    const PIO2_HI: Real = 1.570_796_326_734_125_6; // the first 33 bits of π/2
    const PIO2_LO: Real = 6.077_100_506_506_192e-11; // π/2 − PIO2_HI
    const S: [Real; 6] = [
        -1.666_666_666_666_663_2e-1,
        8.333_333_333_322_49e-3,
        -1.984_126_982_985_795e-4,
        2.755_731_370_707_006_8e-6,
        -2.505_076_025_340_686_3e-8,
        1.589_690_995_211_55e-10,
    ];
    const C: [Real; 6] = [
        4.166_666_666_666_66e-2,
        -1.388_888_888_887_411e-3,
        2.480_158_728_947_673e-5,
        -2.755_731_435_139_066_3e-7,
        2.087_572_321_298_175e-9,
        -1.135_964_755_778_819_5e-11,
    ];
    if !x.is_finite() || x.abs() > 1e5 {
        return x.sin_cos();
    }
    // Round to the nearest whole number by adding and taking away 1.5 · 2⁵² (exact for
    // |x · 2/π| < 2⁵¹; `round` is a library call on x86-64 without SSE4.1).
    const SHIFT: Real = 6_755_399_441_055_744.0;
    let n = (x * std::f64::consts::FRAC_2_PI + SHIFT) - SHIFT;
    let r = (x - n * PIO2_HI) - n * PIO2_LO;
    let z = r * r;
    let w = z * z;
    let sp = S[1] + z * (S[2] + z * S[3]) + z * w * (S[4] + z * S[5]);
    let sin = r + r * z * (S[0] + z * sp);
    let cp = z * (C[0] + z * (C[1] + z * C[2])) + w * w * (C[3] + z * (C[4] + z * C[5]));
    let hz = 0.5 * z;
    let one_minus = 1.0 - hz;
    let cos = one_minus + (((1.0 - one_minus) - hz) + z * cp);
    // `n` is a whole number of at most 10⁵ in magnitude: its quadrant is exact.
    match (n as i64).rem_euclid(4) {
        0 => (sin, cos),
        1 => (cos, -sin),
        2 => (-sin, -cos),
        _ => (-cos, sin),
    }
}

/// Pseudo-inverse and rank of a symmetric positive semi-definite 6x6 matrix. Eigenvalues
/// below `rel_tol` times the largest count as zero, so the result stays finite for
/// rank-deficient input (collinear contacts, a stretched finger). A well-conditioned matrix
/// takes the fast Cholesky path; otherwise a symmetric eigen-decomposition. Allocation-free.
pub fn sym_pinv6(a: &Mat6, rel_tol: Real) -> (Mat6, usize) {
    match Ldlt6::well_conditioned(a, rel_tol) {
        Some(f) => (f.inverse(), 6),
        None => eigen_pinv6(a, rel_tol),
    }
}

/// The pseudo-inverse of a symmetric positive semi-definite 6x6 matrix as [`sym_pinv6`]
/// computes it, kept as the Cholesky factor when the matrix is well conditioned (applying
/// it is then two triangular solves instead of forming the inverse).
#[derive(Debug, Clone, Copy)]
pub enum SymPinv6 {
    /// Well conditioned: the factorisation `L D Lᵀ` of the matrix itself.
    Factor(Ldlt6),
    /// Rank-deficient or ill-conditioned: the pseudo-inverse from the eigen-decomposition.
    Explicit(Mat6),
}

impl SymPinv6 {
    /// The pseudo-inverse of `a` and its rank, by the rule of [`sym_pinv6`].
    pub fn new(a: &Mat6, rel_tol: Real) -> (SymPinv6, usize) {
        if let Some(f) = Ldlt6::well_conditioned(a, rel_tol) {
            return (SymPinv6::Factor(f), 6);
        }
        let (inv, rank) = eigen_pinv6(a, rel_tol);
        (SymPinv6::Explicit(inv), rank)
    }

    /// `A⁺ v`.
    #[inline]
    pub fn apply(&self, v: &Wrench) -> Wrench {
        match self {
            SymPinv6::Factor(f) => f.solve(v),
            SymPinv6::Explicit(inv) => inv * v,
        }
    }
}

/// The square-root-free Cholesky factorisation `A = L D Lᵀ` of a symmetric positive definite
/// 6x6 matrix ([`ldlt_factor_in_place`]): the DFS factors `W Wᵀ` every tick, and without a
/// square root per pivot its chain of dependent long-latency operations is half as long as
/// `L Lᵀ`'s.
#[derive(Debug, Clone, Copy)]
pub struct Ldlt6 {
    /// The factor as [`ldlt_factor_in_place`] leaves it.
    factor: Mat6,
}

impl Ldlt6 {
    /// The factorisation of `a` (its upper triangle is read) when `a` is positive definite
    /// and its pivots `D` are within a wide safety factor of `rel_tol` of each other (they
    /// bracket the eigenvalues loosely, as the squared pivots of `L Lᵀ` do); `None` otherwise.
    pub fn well_conditioned(a: &Mat6, rel_tol: Real) -> Option<Ldlt6> {
        let mut factor = *a;
        if !ldlt_factor_in_place(&mut factor, 6) {
            return None;
        }
        // The diagonal holds 1 / D.
        let (mut lo, mut hi) = (Real::INFINITY, 0.0_f64);
        for i in 0..6 {
            let d = 1.0 / factor[(i, i)];
            lo = lo.min(d);
            hi = hi.max(d);
        }
        (hi.is_finite() && lo > hi * rel_tol * 1e3).then_some(Ldlt6 { factor })
    }

    /// `A⁻¹ b`.
    #[inline]
    pub fn solve(&self, b: &Wrench) -> Wrench {
        let mut x = *b;
        ldlt_solve(&self.factor, 6, x.as_mut_slice());
        x
    }

    /// `A⁻¹`, column by column.
    pub fn inverse(&self) -> Mat6 {
        let mut inv = Mat6::identity();
        for mut col in inv.column_iter_mut() {
            ldlt_solve(&self.factor, 6, col.as_mut_slice());
        }
        inv
    }
}

/// Pseudo-inverse and rank of a symmetric 6x6 matrix from its eigen-decomposition.
fn eigen_pinv6(a: &Mat6, rel_tol: Real) -> (Mat6, usize) {
    let eig = nalgebra::SymmetricEigen::new(*a);
    let max = eig.eigenvalues.iter().fold(0.0_f64, |m, &v| m.max(v.abs()));
    if max <= 0.0 || !max.is_finite() {
        return (Mat6::zeros(), 0);
    }
    let tol = max * rel_tol;
    let mut inv = Mat6::zeros();
    let mut rank = 0;
    for k in 0..6 {
        let l = eig.eigenvalues[k];
        if l > tol {
            let v = eig.eigenvectors.column(k);
            inv += (v * v.transpose()) / l;
            rank += 1;
        }
    }
    (inv, rank)
}

/// Factors the symmetric positive definite top-left `n × n` block of a fixed-capacity square
/// matrix in place by the square-root-free Cholesky factorisation `A = L D Lᵀ`: only the upper
/// triangle of the block is read, and it is overwritten by `Lᵀ` above the diagonal and `1 / D`
/// on it, the form [`ldlt_solve`] takes. Returns `false` when the block is not positive
/// definite (or not finite) or `n > N`. One division per column and no square root, so the
/// chain of dependent long-latency operations is half as long as with `L Lᵀ`. Works column by
/// column on the column-major storage, so every inner loop runs over contiguous memory.
pub fn ldlt_factor_in_place<const N: usize>(
    a: &mut nalgebra::SMatrix<Real, N, N>,
    n: usize,
) -> bool {
    if n > N {
        return false;
    }
    // `v` is row j of L D while it is being formed: no longer than the block needs (a
    // finger group's block is a few DOFs, and zeroing N entries per call cost a tenth of
    // the factorisation).
    if n <= SMALL_LDLT {
        ldlt_factor_with(a.as_mut_slice(), N, n, &mut [0.0; SMALL_LDLT])
    } else {
        ldlt_factor_with(a.as_mut_slice(), N, n, &mut [0.0; N])
    }
}

/// Blocks up to this size are factored with `v` on a short array.
const SMALL_LDLT: usize = 8;

/// [`ldlt_factor_in_place`] of the top-left `n × n` block of the column-major `u` of
/// `stride` rows, with `v` (at least `n` long) as scratch.
#[inline(always)]
fn ldlt_factor_with(u: &mut [Real], stride: usize, n: usize, v: &mut [Real]) -> bool {
    // Column j holds row j of L (left of the diagonal) and 1 / D[j] (on it).
    for j in 0..n {
        let (head, tail) = u.split_at_mut(j * stride);
        let col_j = &mut tail[..j + 1];
        for i in 0..j {
            let col_i = &head[i * stride..i * stride + i + 1];
            v[i] = col_j[i] - dot(&col_i[..i], &v[..i]);
            col_j[i] = v[i] * col_i[i];
        }
        let d = col_j[j] - dot(&col_j[..j], &v[..j]);
        if d <= 0.0 || !d.is_finite() {
            return false;
        }
        col_j[j] = 1.0 / d;
    }
    true
}

/// Solves `A x = b` in place (`b` becomes `x`, its first `n` entries) with the factor that
/// [`ldlt_factor_in_place`] left in `u`.
pub fn ldlt_solve<const N: usize>(u: &nalgebra::SMatrix<Real, N, N>, n: usize, b: &mut [Real]) {
    let n = n.min(N).min(b.len());
    let u = u.as_slice();
    // L y = b, then D⁻¹ y.
    for i in 0..n {
        let col_i = &u[i * N..i * N + i + 1];
        b[i] -= dot(&col_i[..i], &b[..i]);
    }
    for i in 0..n {
        b[i] *= u[i * N + i];
    }
    // Lᵀ x = D⁻¹ y, column by column.
    for i in (0..n).rev() {
        let x = b[i];
        for (bk, uk) in b[..i].iter_mut().zip(&u[i * N..i * N + i]) {
            *bk -= uk * x;
        }
    }
}

/// `Σ x_k y_k`.
#[inline(always)]
fn dot(x: &[Real], y: &[Real]) -> Real {
    x.iter().zip(y).map(|(p, q)| p * q).sum()
}

/// Solves `A x = b` in place for the symmetric positive definite top-left `n × n` block of a
/// fixed-capacity square matrix: [`ldlt_factor_in_place`] (the block's upper triangle is
/// overwritten by the factor), then [`ldlt_solve`]. Returns `false`, leaving `b` unchanged,
/// when the block is not positive definite (or not finite). Allocation-free; the hot-path
/// solver for small joint-space systems.
pub fn cholesky_solve_in_place<const N: usize>(
    a: &mut nalgebra::SMatrix<Real, N, N>,
    n: usize,
    b: &mut [Real],
) -> bool {
    debug_assert!(n <= N && b.len() >= n);
    let n = n.min(N).min(b.len());
    if !ldlt_factor_in_place(a, n) {
        return false;
    }
    ldlt_solve(a, n, b);
    true
}

/// Solves `A x = b` for a symmetric positive-definite `A` whose nonzeros, with its rows and
/// columns taken in the order `order`, lie within an *envelope*: row `i` (in that order) has
/// no nonzero left of column `first[i]`. The Cholesky factor has the same envelope (no
/// fill-in outside it), so only its entries are computed: for a hand with the finger DOFs
/// first and the wrist's last, the factor is block-arrowhead and costs a fraction of a dense
/// one. `a` is read at `a[(order[i], order[j])]` with `first[i] ≤ j ≤ i`; `u` is scratch (the
/// factor, transposed: column `i` holds row `i` of L, with `1 / L[i][i]` on the diagonal);
/// `b` is overwritten by `x` in the original order. Allocation-free; `false` when `A` is not
/// positive definite (or not finite).
pub fn envelope_cholesky_solve<const N: usize>(
    a: &nalgebra::SMatrix<Real, N, N>,
    order: &[usize],
    first: &[usize],
    u: &mut nalgebra::SMatrix<Real, N, N>,
    b: &mut [Real],
) -> bool {
    let n = order.len().min(first.len()).min(N);
    let u = u.as_mut_slice();
    for i in 0..n {
        let fi = first[i].min(i);
        let oi = order[i];
        for j in fi..i {
            let fj = first[j].max(fi);
            let mut s = a[(oi, order[j])];
            for k in fj..j {
                s -= u[i * N + k] * u[j * N + k];
            }
            // The diagonal holds 1 / L[j][j]: a multiplication here, not a division.
            u[i * N + j] = s * u[j * N + j];
        }
        let mut d = a[(oi, oi)];
        for k in fi..i {
            d -= u[i * N + k] * u[i * N + k];
        }
        if d <= 0.0 || !d.is_finite() {
            return false;
        }
        u[i * N + i] = 1.0 / d.sqrt();
    }
    // L y = P b, then Lᵀ x = y (column by column), x back in the original order.
    let mut y = [0.0; N];
    for i in 0..n {
        let mut s = b[order[i]];
        for k in first[i].min(i)..i {
            s -= u[i * N + k] * y[k];
        }
        y[i] = s * u[i * N + i];
    }
    for i in (0..n).rev() {
        let x = y[i] * u[i * N + i];
        y[i] = x;
        for k in first[i].min(i)..i {
            y[k] -= u[i * N + k] * x;
        }
    }
    for i in 0..n {
        b[order[i]] = y[i];
    }
    true
}

/// Unit vector of `v` with its component along unit `a` removed; `fallback`'s if that is ~0,
/// and if that is ~0 too (both along `a`), the coordinate axis most nearly square to `a`'s.
pub(crate) fn perpendicular(v: &Vector, a: &Vector, fallback: &Vector) -> Vector {
    let off = |u: &Vector| u - a * a.dot(u);
    let p = off(v);
    if p.norm() > 1e-9 {
        return p.normalize();
    }
    let f = off(fallback);
    if f.norm() > 1e-15 {
        return f.normalize();
    }
    let axis = [Vector::x(), Vector::y(), Vector::z()]
        .into_iter()
        .min_by(|x, y| a.dot(x).abs().total_cmp(&a.dot(y).abs()))
        .unwrap_or_else(Vector::x);
    off(&axis).try_normalize(1e-12).unwrap_or_else(Vector::x)
}

/// Rotation taking the orthonormal pair (a, d) of one frame onto (a', d') of another; the
/// identity when the pairs are not orthonormal (or not finite).
///
/// nalgebra's `from_matrix` iterates until it converges, without bound: on a matrix that is
/// not a rotation (NaN from a degenerate pair) it never returns. Here the matrix is checked
/// first and the iterations bounded ([`ALIGN_ITERATIONS`]; a rotation converges in a few).
pub(crate) fn align(a_from: &Vector, d_from: &Vector, a_to: &Vector, d_to: &Vector) -> Rotation {
    let from = Matrix3::from_columns(&[*a_from, *d_from, a_from.cross(d_from)]);
    let to = Matrix3::from_columns(&[*a_to, *d_to, a_to.cross(d_to)]);
    let m = to * from.transpose();
    let rotation = m.iter().all(|v| v.is_finite())
        && (m.transpose() * m - Matrix3::identity()).amax() < 1e-6
        && m.determinant() > 0.0;
    if !rotation {
        return Rotation::identity();
    }
    Rotation::from_matrix_eps(&m, Real::EPSILON, ALIGN_ITERATIONS, Rotation::identity())
}

/// Most iterations of the rotation extraction in [`align`] (its input is a rotation matrix up
/// to rounding, which takes a handful).
const ALIGN_ITERATIONS: usize = 1000;

#[cfg(test)]
mod tests {
    use super::*;

    /// A serial chain's fingertips all lie on its axis at mid-range angles: the grasp axis and
    /// the fallback direction coincided, the rotation's matrix was NaN, and nalgebra's
    /// unbounded rotation extraction never returned.
    #[test]
    fn a_degenerate_grasp_axis_gives_a_rotation_at_once() {
        let z = Vector::z();
        let d = perpendicular(&(z * 0.1), &z, &Vector::z());
        assert!(
            (d.norm() - 1.0).abs() < 1e-12 && d.dot(&z).abs() < 1e-12,
            "{d}"
        );
        let nan = Vector::new(Real::NAN, 0.0, 0.0);
        assert_eq!(
            align(&z, &nan, &Vector::x(), &Vector::y()),
            Rotation::identity()
        );
        assert_eq!(
            align(&z, &Vector::zeros(), &Vector::x(), &Vector::y()),
            Rotation::identity()
        );
        // Orthonormal pairs: the rotation between them.
        let r = align(&Vector::x(), &Vector::y(), &Vector::y(), &-Vector::x());
        assert!((r * Vector::x() - Vector::y()).norm() < 1e-12);
        assert!((r * Vector::y() + Vector::x()).norm() < 1e-12);
    }

    #[test]
    fn the_envelope_solve_equals_the_dense_one_for_an_arrowhead_matrix() {
        // Two 2x2 blocks coupled only through the last row and column, stored in a shuffled
        // order: DOFs 3, 0 form one block, 1, 4 the other, 2 couples with all.
        let mut a = nalgebra::SMatrix::<f64, 6, 6>::zeros();
        let entries = [
            (3, 3, 4.0),
            (0, 0, 5.0),
            (3, 0, 1.0),
            (1, 1, 6.0),
            (4, 4, 3.0),
            (1, 4, -1.0),
            (2, 2, 9.0),
            (2, 3, 0.5),
            (2, 0, -0.7),
            (2, 1, 1.1),
            (2, 4, 0.3),
        ];
        for (i, j, v) in entries {
            a[(i, j)] = v;
            a[(j, i)] = v;
        }
        let order = [3, 0, 1, 4, 2];
        let first = [0, 0, 2, 2, 0];
        let b0 = [1.0, -2.0, 0.5, 3.0, 0.25, 42.0];
        let mut b = b0;
        let mut u = nalgebra::SMatrix::<f64, 6, 6>::zeros();
        assert!(envelope_cholesky_solve(&a, &order, &first, &mut u, &mut b));
        let mut dense = a;
        let mut bd = b0;
        assert!(cholesky_solve_in_place(&mut dense, 5, &mut bd));
        for k in 0..5 {
            assert!((b[k] - bd[k]).abs() < 1e-12, "{k}: {} vs {}", b[k], bd[k]);
        }
        assert_eq!(b[5], 42.0, "entries outside the order are left alone");
        let mut bad = a;
        bad[(2, 2)] = -1.0;
        assert!(!envelope_cholesky_solve(
            &bad, &order, &first, &mut u, &mut b
        ));
    }

    #[test]
    fn cholesky_solves_the_top_left_block_only() {
        let mut a = nalgebra::SMatrix::<f64, 4, 4>::identity() * 7.0;
        a[(0, 0)] = 4.0;
        a[(0, 1)] = 1.0;
        a[(1, 0)] = 1.0;
        a[(1, 1)] = 3.0;
        let mut b = [1.0, 2.0, 99.0, 99.0];
        assert!(cholesky_solve_in_place(&mut a, 2, &mut b));
        assert!((4.0 * b[0] + b[1] - 1.0).abs() < 1e-12);
        assert!((b[0] + 3.0 * b[1] - 2.0).abs() < 1e-12);
        assert_eq!(b[2], 99.0);
        let mut bad = nalgebra::SMatrix::<f64, 2, 2>::new(1.0, 2.0, 2.0, 1.0);
        assert!(!cholesky_solve_in_place(&mut bad, 2, &mut [1.0, 1.0]));
    }

    proptest::proptest! {
        #[test]
        fn cholesky_agrees_with_nalgebra_on_random_spd_blocks(
            entries in proptest::collection::vec(-1.0..1.0f64, 36),
            rhs in proptest::collection::vec(-1.0..1.0f64, 6),
            n in 1usize..=6,
        ) {
            let g = nalgebra::SMatrix::<f64, 6, 6>::from_iterator(entries);
            let spd = g * g.transpose() + nalgebra::SMatrix::<f64, 6, 6>::identity() * 0.1;
            let mut a = nalgebra::SMatrix::<f64, 8, 8>::identity();
            a.fixed_view_mut::<6, 6>(0, 0).copy_from(&spd);
            let mut b = [0.0; 8];
            b[..6].copy_from_slice(&rhs);
            proptest::prop_assert!(cholesky_solve_in_place(&mut a, n, &mut b));
            let block = spd.view((0, 0), (n, n)).clone_owned();
            let x = block.cholesky().unwrap().solve(&nalgebra::DVector::from_column_slice(&rhs[..n]));
            for i in 0..n {
                proptest::prop_assert!((b[i] - x[i]).abs() <= 1e-9 * x.amax().max(1.0));
            }
        }
    }

    #[test]
    fn sin_cos_agrees_with_the_standard_library_to_an_ulp_or_two() {
        let mut worst: Real = 0.0;
        let mut check = |x: Real| {
            let (s, c) = sin_cos(x);
            let (s0, c0) = x.sin_cos();
            let err = (s - s0).abs().max((c - c0).abs());
            assert!(err <= 4.5e-16, "x = {x}: ({s}, {c}) vs ({s0}, {c0})");
            worst = worst.max(err);
        };
        // Every quadrant boundary and joint-range angle, finely, then far out.
        for i in -200_000..=200_000 {
            check(i as Real * 1e-4);
        }
        for i in 0..2000 {
            let x = (i as Real * 0.618_033_988_75).sin() * 1e5;
            check(x);
            check(x * 1e-3);
        }
        for x in [0.0, -0.0, 1e-300, -1e-300, 1e5, -1e5, 1e6, 3.5e9] {
            check(x);
        }
        assert!(worst > 0.0, "a different path was taken");
        let (s, c) = sin_cos(Real::NAN);
        assert!(s.is_nan() && c.is_nan());
        let (s, c) = sin_cos(Real::INFINITY);
        assert!(s.is_nan() && c.is_nan());
    }

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
        let (p, rank) = sym_pinv6(&a, 1e-9);
        assert!(p.iter().all(|v| v.is_finite()));
        assert!((a * p * a - a).norm() < 1e-12);
        assert_eq!(rank, 2);
        let full = Mat6::identity() * 3.0;
        let (p, rank) = sym_pinv6(&full, 1e-9);
        assert_eq!(rank, 6);
        assert!((p * full - Mat6::identity()).norm() < 1e-12);
        // A full, well-conditioned matrix with off-diagonal terms takes the factorisation.
        let g = Mat6::from_fn(|r, c| {
            ((r * 7 + c * 3) % 5) as Real - 2.0 + if r == c { 6.0 } else { 0.0 }
        });
        let spd = g * g.transpose();
        let (p, rank) = sym_pinv6(&spd, 1e-9);
        assert_eq!(rank, 6);
        assert!((p * spd - Mat6::identity()).norm() < 1e-10);
        assert!(Ldlt6::well_conditioned(&spd, 1e-9).is_some());
        assert!(
            Ldlt6::well_conditioned(&a, 1e-9).is_none(),
            "rank 2 is not factored"
        );
    }
}
