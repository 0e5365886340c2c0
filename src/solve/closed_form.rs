//! Closed-form robot-world/hand-eye solution after Shah (2013), "Solving the robot-world/hand-eye
//! calibration problem using the Kronecker product", written for `A = X·B·Y`.
//!
//! Rotations: `R_X R_B,i = R_A,i R_Yᵀ` is linear in `vec(R_X)` and `vec(R_Yᵀ)`:
//! `(R_B,iᵀ ⊗ I₃) vec(R_X) − (I₃ ⊗ R_A,i) vec(R_Yᵀ) = 0`. The stacked (weighted) system's null
//! vector, scaled to `det R_X = 1` and projected onto SO(3), gives both rotations. Translations
//! then solve the linear least squares `t_X + R_X R_B,i t_Y = t_A,i − R_X t_B,i`.
//! Used as a warm start, a cross-check and for the convention diagnosis. Units: rad, m.

use nalgebra::{
    Matrix3, Rotation3, SMatrix, SVector, SymmetricEigen, Translation3, UnitQuaternion, Vector3,
};

use super::{Axby, AxbyData, SolveError};
use crate::geometry::Pose;

/// The closest rotation (Frobenius norm) to a 3x3 matrix.
fn project_to_rotation(m: &Matrix3<f64>) -> Option<UnitQuaternion<f64>> {
    let svd = m.svd(true, true);
    let u = svd.u?;
    let v_t = svd.v_t?;
    let mut d = Matrix3::identity();
    if (u * v_t).determinant() < 0.0 {
        d[(2, 2)] = -1.0;
    }
    let r = u * d * v_t;
    Some(UnitQuaternion::from_rotation_matrix(
        &Rotation3::from_matrix_unchecked(r),
    ))
}

/// Kronecker product of two 3x3 matrices.
fn kron(a: &Matrix3<f64>, b: &Matrix3<f64>) -> SMatrix<f64, 9, 9> {
    let mut k = SMatrix::<f64, 9, 9>::zeros();
    for i in 0..3 {
        for j in 0..3 {
            k.fixed_view_mut::<3, 3>(3 * i, 3 * j)
                .copy_from(&(b * a[(i, j)]));
        }
    }
    k
}

/// Solves `A_i = X·B_i·Y` in closed form.
pub fn solve_axby(data: &AxbyData) -> Result<Axby, SolveError> {
    let identity = Matrix3::identity();
    // Normal matrix of the stacked Kronecker system: its eigenvector of the smallest eigenvalue
    // is the least-squares null vector (18x18, cheap for any N).
    let mut normal = SMatrix::<f64, 18, 18>::zeros();
    for ((a, b), &w) in data.a.iter().zip(&data.b).zip(&data.weights) {
        let ra = a.rotation.to_rotation_matrix().into_inner();
        let rb = b.rotation.to_rotation_matrix().into_inner();
        let mut k = SMatrix::<f64, 9, 18>::zeros();
        k.fixed_view_mut::<9, 9>(0, 0)
            .copy_from(&kron(&rb.transpose(), &identity));
        k.fixed_view_mut::<9, 9>(0, 9)
            .copy_from(&(-kron(&identity, &ra)));
        normal += k.transpose() * k * w;
    }
    let eigen = SymmetricEigen::new(normal);
    let smallest = eigen.eigenvalues.imin();
    let v: SVector<f64, 18> = eigen.eigenvectors.column(smallest).into_owned();
    // Column-major reshape (vec stacks columns).
    let rx = Matrix3::from_column_slice(&v.as_slice()[0..9]);
    let ry_t = Matrix3::from_column_slice(&v.as_slice()[9..18]);
    let det = rx.determinant();
    if !det.is_finite() || det.abs() < 1e-12 {
        return Err(SolveError::ClosedFormFailed(
            "the rotation null vector is degenerate (robot rotations not diverse enough)",
        ));
    }
    let scale = det.signum() / det.abs().cbrt();
    let qx = project_to_rotation(&(rx * scale))
        .ok_or(SolveError::ClosedFormFailed("SVD of the X rotation failed"))?;
    let qy = project_to_rotation(&(ry_t * scale).transpose())
        .ok_or(SolveError::ClosedFormFailed("SVD of the Y rotation failed"))?;
    let (tx, ty) = translations(data, &qx)?;
    Ok(Axby {
        x: Pose::from_parts(Translation3::from(tx), qx),
        y: Pose::from_parts(Translation3::from(ty), qy),
    })
}

/// Linear least squares for both translations given `R_X`.
pub fn translations(
    data: &AxbyData,
    rx: &UnitQuaternion<f64>,
) -> Result<(Vector3<f64>, Vector3<f64>), SolveError> {
    let rx_m = rx.to_rotation_matrix().into_inner();
    let mut normal = SMatrix::<f64, 6, 6>::zeros();
    let mut rhs = SVector::<f64, 6>::zeros();
    for ((a, b), &w) in data.a.iter().zip(&data.b).zip(&data.weights) {
        let m = rx_m * b.rotation.to_rotation_matrix().into_inner();
        let mut row = SMatrix::<f64, 3, 6>::zeros();
        row.fixed_view_mut::<3, 3>(0, 0)
            .copy_from(&Matrix3::identity());
        row.fixed_view_mut::<3, 3>(0, 3).copy_from(&m);
        let c = a.translation.vector - rx_m * b.translation.vector;
        normal += row.transpose() * row * w;
        rhs += row.transpose() * c * w;
    }
    let solution = normal
        .cholesky()
        .map(|c| c.solve(&rhs))
        .ok_or(SolveError::ClosedFormFailed(
            "the translation system is singular (robot rotations not diverse enough)",
        ))?;
    Ok((
        solution.fixed_rows::<3>(0).into_owned(),
        solution.fixed_rows::<3>(3).into_owned(),
    ))
}
