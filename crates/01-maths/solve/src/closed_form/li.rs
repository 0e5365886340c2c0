//! Li, Wang and Wu (2010), "Simultaneous robot-world and hand-eye calibration using
//! dual-quaternions and Kronecker product" (Int. J. Physical Sciences 5(10)), the Kronecker
//! formulation: rotations and translations of `A·X = Z·B` in one linear system.
//!
//! In the paper's form `A_i·X' = Z'·B_i` with this project's `A_i = X·B_i·Y`: `Z' = X` and
//! `X' = Y⁻¹`. With column-major `vec`, each sample gives twelve linear equations in
//! `(vec R_X', vec R_Z', t_X', t_Z')`:
//! `(I₃ ⊗ R_A)·vec R_X' − (R_Bᵀ ⊗ I₃)·vec R_Z' = 0` and
//! `R_A·t_X' − (t_Bᵀ ⊗ I₃)·vec R_Z' − t_Z' = −t_A`.
//! The stacked system is solved by least squares; `R_X'` and `R_Z'` are projected onto SO(3)
//! and the translations are taken from the same solution, as in the paper.

use nalgebra::{DMatrix, DVector, Matrix3, Translation3};

use super::{kron, least_squares};
use crate::{Axby, AxbyData, SolveError};
use handeye_core::geometry::project_to_rotation;
use handeye_core::geometry::Pose;

/// Both unknowns of `A_i = X·B_i·Y` by Li, Wang and Wu.
pub fn solve(data: &AxbyData) -> Result<Axby, SolveError> {
    let n = data.len();
    let identity = Matrix3::identity();
    let mut m = DMatrix::<f64>::zeros(12 * n, 24);
    let mut r = DVector::<f64>::zeros(12 * n);
    for (i, ((a, b), &w)) in data.a.iter().zip(&data.b).zip(&data.weights).enumerate() {
        let sw = w.sqrt();
        let ra = a.rotation.to_rotation_matrix().into_inner();
        let rb = b.rotation.to_rotation_matrix().into_inner();
        let tb = b.translation.vector;
        let row = 12 * i;
        m.view_mut((row, 0), (9, 9))
            .copy_from(&(kron(&identity, &ra) * sw));
        m.view_mut((row, 9), (9, 9))
            .copy_from(&(-kron(&rb.transpose(), &identity) * sw));
        // (t_Bᵀ ⊗ I₃) is 3x9: block j is t_B[j]·I₃.
        for j in 0..3 {
            m.view_mut((row + 9, 9 + 3 * j), (3, 3))
                .copy_from(&(-identity * (tb[j] * sw)));
        }
        m.view_mut((row + 9, 18), (3, 3)).copy_from(&(ra * sw));
        m.view_mut((row + 9, 21), (3, 3))
            .copy_from(&(-identity * sw));
        r.rows_mut(row + 9, 3)
            .copy_from(&(-a.translation.vector * sw));
    }
    let v = least_squares(m, r).ok_or(SolveError::ClosedFormFailed(
        "Li: the linear system is rank-deficient (robot rotations not diverse enough)",
    ))?;
    let rx_prime = Matrix3::from_column_slice(&v.as_slice()[0..9]);
    let rz_prime = Matrix3::from_column_slice(&v.as_slice()[9..18]);
    let qx_prime = project_to_rotation(&rx_prime)
        .ok_or(SolveError::ClosedFormFailed("Li: SVD of R_X' failed"))?;
    let qz_prime = project_to_rotation(&rz_prime)
        .ok_or(SolveError::ClosedFormFailed("Li: SVD of R_Z' failed"))?;
    let tx_prime = v.fixed_rows::<3>(18).into_owned();
    let tz_prime = v.fixed_rows::<3>(21).into_owned();
    let x_prime = Pose::from_parts(Translation3::from(tx_prime), qx_prime);
    Ok(Axby {
        x: Pose::from_parts(Translation3::from(tz_prime), qz_prime),
        y: x_prime.inverse(),
    })
}
