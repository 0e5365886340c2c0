//! Shah (2013), "Solving the robot-world/hand-eye calibration problem using the Kronecker
//! product", written for `A = X·B·Y` (the AX = ZB family: both unknowns at once).
//!
//! Rotations: `R_X R_B,i = R_A,i R_Yᵀ` is linear in `vec(R_X)` and `vec(R_Yᵀ)`:
//! `(R_B,iᵀ ⊗ I₃) vec(R_X) − (I₃ ⊗ R_A,i) vec(R_Yᵀ) = 0`. The stacked (weighted) system's null
//! vector, scaled to `det R_X = 1` and projected onto SO(3), gives both rotations. Translations
//! then solve the linear least squares `t_X + R_X R_B,i t_Y = t_A,i − R_X t_B,i`.
//! Also the warm start of the iterative method, and the rotation fit of the convention and
//! units checks (rotations are unit-free). Units: rad, m.

use nalgebra::{Matrix3, SMatrix, SVector, Translation3, UnitQuaternion, Vector3};

use super::kron;
use crate::{Axby, AxbyData, SolveError};
use handeye_core::geometry::project_to_rotation;
use handeye_core::geometry::Pose;

/// Solves `A_i = X·B_i·Y` in closed form.
pub fn solve_axby(data: &AxbyData) -> Result<Axby, SolveError> {
    let (qx, qy) = rotations(data)?;
    let (tx, ty) = translations(data, &qx)?;
    Ok(Axby {
        x: Pose::from_parts(Translation3::from(tx), qx),
        y: Pose::from_parts(Translation3::from(ty), qy),
    })
}

/// The rotations `(R_X, R_Y)` of `A_i = X·B_i·Y` from the Kronecker null vector. They depend on
/// the rotations of the data only, so they are right whatever unit the translations are in.
pub fn rotations(
    data: &AxbyData,
) -> Result<(UnitQuaternion<f64>, UnitQuaternion<f64>), SolveError> {
    // Normal matrix of the stacked Kronecker system, sample i contributing
    // `K_iᵀK_i` with `K_i = [R_B,iᵀ ⊗ I₃, −I₃ ⊗ R_A,i]`: since `(R_B ⊗ I)(R_Bᵀ ⊗ I) = I` and
    // `(I ⊗ R_A)ᵀ(I ⊗ R_A) = I`, it is `w·[[I, −M_i], [−M_iᵀ, I]]` with `M_i = R_B,i ⊗ R_A,i`.
    // Its eigenvector of the smallest eigenvalue (`W − σ₁` for `M = Σ w_i M_i`, `W = Σ w_i`)
    // is `[u₁; v₁]` of M's largest singular value: one 9x9 SVD instead of an 18x18 eigen
    // problem of the stacked normal matrix.
    let mut m = SMatrix::<f64, 9, 9>::zeros();
    for ((a, b), &w) in data.a.iter().zip(&data.b).zip(&data.weights) {
        let ra = a.rotation.to_rotation_matrix().into_inner();
        let rb = b.rotation.to_rotation_matrix().into_inner();
        m += kron(&rb, &ra) * w;
    }
    let degenerate = SolveError::ClosedFormFailed(
        "the rotation null vector is degenerate (robot rotations not diverse enough)",
    );
    let svd = m.svd(true, true);
    let largest = svd.singular_values.imax();
    let (Some(u), Some(v_t)) = (svd.u, svd.v_t) else {
        return Err(degenerate);
    };
    // The unit eigenvector, as the 18x18 form gave it (the degeneracy test reads its scale).
    let mut v = SVector::<f64, 18>::zeros();
    v.fixed_rows_mut::<9>(0)
        .copy_from(&(u.column(largest) * std::f64::consts::FRAC_1_SQRT_2));
    v.fixed_rows_mut::<9>(9)
        .copy_from(&(v_t.row(largest).transpose() * std::f64::consts::FRAC_1_SQRT_2));
    // Column-major reshape (vec stacks columns).
    let rx = Matrix3::from_column_slice(&v.as_slice()[0..9]);
    let ry_t = Matrix3::from_column_slice(&v.as_slice()[9..18]);
    let det = rx.determinant();
    if !det.is_finite() || det.abs() < 1e-12 {
        return Err(degenerate);
    }
    let scale = det.signum() / det.abs().cbrt();
    let qx = project_to_rotation(&(rx * scale))
        .ok_or(SolveError::ClosedFormFailed("SVD of the X rotation failed"))?;
    let qy = project_to_rotation(&(ry_t * scale).transpose())
        .ok_or(SolveError::ClosedFormFailed("SVD of the Y rotation failed"))?;
    Ok((qx, qy))
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
