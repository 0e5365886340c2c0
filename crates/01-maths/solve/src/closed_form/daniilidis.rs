//! Daniilidis (1999), "Hand-eye calibration using dual quaternions" (Int. J. Robotics Research
//! 18(3)): rotation and translation of `A·X = X·B` at once.
//!
//! Each pose is the unit dual quaternion `q + ε·q'` with `q'` = `½·t·q` (`t` a pure
//! quaternion). For a motion with vector parts `a, a'` (of `A`) and `b, b'` (of `B`), both with
//! the same sign of scalar part, `X = x + ε·x'` satisfies the paper's six equations
//! `[a − b, [a + b]×, 0, 0; a' − b', [a' + b']×, a − b, [a + b]×]·(x; x') = 0`. The stacked
//! system's two right singular vectors of the smallest singular values, `(u₁; v₁)` and
//! `(u₂; v₂)`, span the solutions; `λ₁, λ₂` follow from the two constraints of a unit dual
//! quaternion, `|x| = 1` and `x·x' = 0`: a quadratic in `λ₁/λ₂`, of whose roots the one with
//! the larger `|x|²` is taken (the paper's rule). The translation is `2·x'·x*`.

use nalgebra::{
    Quaternion, SMatrix, SVector, SymmetricEigen, Translation3, UnitQuaternion, Vector3,
};

use super::Motion;
use crate::SolveError;
use handeye_core::geometry::Pose;

/// The real and dual part of a pose, each as (w, x, y, z).
fn dual_quaternion(pose: &Pose) -> (Quaternion<f64>, Quaternion<f64>) {
    let real = pose.rotation.into_inner();
    let t = pose.translation.vector;
    let dual = Quaternion::new(0.0, t.x, t.y, t.z) * real * 0.5;
    (real, dual)
}

fn vector_part(q: &Quaternion<f64>) -> Vector3<f64> {
    Vector3::new(q.i, q.j, q.k)
}

/// `(x_w, x_v, x'_w, x'_v)` as a quaternion pair.
fn split(v: &SVector<f64, 8>) -> (SVector<f64, 4>, SVector<f64, 4>) {
    (
        v.fixed_rows::<4>(0).into_owned(),
        v.fixed_rows::<4>(4).into_owned(),
    )
}

/// The two roots of `a·s² + b·s + c = 0` (real parts when the discriminant is a little below
/// zero through noise); `None` when `a` vanishes.
fn roots(a: f64, b: f64, c: f64) -> Option<[f64; 2]> {
    if a.abs() < 1e-300 {
        return None;
    }
    let d = (b * b - 4.0 * a * c).max(0.0).sqrt();
    Some([(-b + d) / (2.0 * a), (-b - d) / (2.0 * a)])
}

/// `X` of `A·X = X·B` by Daniilidis.
pub fn solve(motions: &[Motion]) -> Result<Pose, SolveError> {
    let mut normal = SMatrix::<f64, 8, 8>::zeros();
    for m in motions {
        let (ar, ad) = dual_quaternion(&m.a);
        let (mut br, mut bd) = dual_quaternion(&m.b);
        if ar.w * br.w < 0.0 {
            br = -br;
            bd = -bd;
        }
        let (a, a_d) = (vector_part(&ar), vector_part(&ad));
        let (b, b_d) = (vector_part(&br), vector_part(&bd));
        let mut s = SMatrix::<f64, 6, 8>::zeros();
        s.fixed_view_mut::<3, 1>(0, 0).copy_from(&(a - b));
        s.fixed_view_mut::<3, 3>(0, 1)
            .copy_from(&(a + b).cross_matrix());
        s.fixed_view_mut::<3, 1>(3, 0).copy_from(&(a_d - b_d));
        s.fixed_view_mut::<3, 3>(3, 1)
            .copy_from(&(a_d + b_d).cross_matrix());
        s.fixed_view_mut::<3, 1>(3, 4).copy_from(&(a - b));
        s.fixed_view_mut::<3, 3>(3, 5)
            .copy_from(&(a + b).cross_matrix());
        normal += s.transpose() * s * m.weight;
    }
    // Right singular vectors of the stack = eigenvectors of its normal matrix.
    let eigen = SymmetricEigen::new(normal);
    let mut order: Vec<usize> = (0..8).collect();
    order.sort_by(|&i, &j| eigen.eigenvalues[i].total_cmp(&eigen.eigenvalues[j]));
    let third = eigen.eigenvalues[order[2]];
    let well_posed = third > eigen.eigenvalues[order[7]] * 1e-12 && third.is_finite();
    if !well_posed {
        return Err(SolveError::ClosedFormFailed(
            "Daniilidis: the solution space is more than two-dimensional (robot rotations all about one axis)",
        ));
    }
    let (u1, v1) = split(&eigen.eigenvectors.column(order[0]).into_owned());
    let (u2, v2) = split(&eigen.eigenvectors.column(order[1]).into_owned());
    // x·x' = 0 for x = λ₁u₁ + λ₂u₂, x' = λ₁v₁ + λ₂v₂: a quadratic in s = λ₁/λ₂ (or its inverse).
    let (a, b, c) = (u1.dot(&v1), u1.dot(&v2) + u2.dot(&v1), u2.dot(&v2));
    let norm2 = |l1: f64, l2: f64| (u1 * l1 + u2 * l2).norm_squared();
    let candidates: Vec<(f64, f64)> = if a.abs() >= c.abs() {
        roots(a, b, c)
            .map(|r| r.iter().map(|&s| (s, 1.0)).collect())
            .unwrap_or_default()
    } else {
        roots(c, b, a)
            .map(|r| r.iter().map(|&t| (1.0, t)).collect())
            .unwrap_or_default()
    };
    // Of the two roots, the one whose real part carries more of the (unit, since the singular
    // vectors are orthonormal) 8-vector: the other one is the spurious x ≈ 0 branch.
    let share = |&(l1, l2): &(f64, f64)| norm2(l1, l2) / (l1 * l1 + l2 * l2);
    let (l1, l2) = candidates
        .into_iter()
        .filter(|p| share(p).is_finite())
        .max_by(|p, q| share(p).total_cmp(&share(q)))
        .ok_or(SolveError::ClosedFormFailed(
            "Daniilidis: the unit-dual-quaternion constraint has no solution",
        ))?;
    let scale = 1.0 / norm2(l1, l2).sqrt();
    let (l1, l2) = (l1 * scale, l2 * scale);
    let x = u1 * l1 + u2 * l2;
    let x_d = v1 * l1 + v2 * l2;
    let real = Quaternion::new(x[0], x[1], x[2], x[3]);
    let dual = Quaternion::new(x_d[0], x_d[1], x_d[2], x_d[3]);
    let t = dual * real.conjugate() * 2.0;
    Ok(Pose::from_parts(
        Translation3::new(t.i, t.j, t.k),
        UnitQuaternion::from_quaternion(real),
    ))
}
