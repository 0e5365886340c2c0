//! Park and Martin (1994), "Robot sensor calibration: solving AX = XB on the Euclidean group"
//! (IEEE Trans. Robotics and Automation 10(5)).
//!
//! With the rotation vectors (matrix logarithms) `α = log R_A` and `β = log R_B` of each
//! motion, `R_X·β = α`; the least-squares rotation is `R_X = (MᵀM)^(-1/2)·Mᵀ` with
//! `M = Σ w·β·αᵀ` (the paper's closed form, needing two motions about different axes). The
//! translation solves `(R_A − I)·t_X = R_X·t_B − t_A`.

use nalgebra::{Matrix3, Rotation3, SymmetricEigen, Translation3, UnitQuaternion};

use super::{ax_xb_translation, Motion};
use crate::SolveError;
use handeye_core::geometry::{rotvec, Pose};

/// `X` of `A·X = X·B` by Park and Martin.
pub fn solve(motions: &[Motion]) -> Result<Pose, SolveError> {
    let mut m = Matrix3::zeros();
    for motion in motions {
        let alpha = rotvec(&motion.a.rotation);
        let beta = rotvec(&motion.b.rotation);
        m += beta * alpha.transpose() * motion.weight;
    }
    // (MᵀM)^(-1/2) from the eigen-decomposition of the symmetric MᵀM.
    let eigen = SymmetricEigen::new(m.transpose() * m);
    let largest = eigen.eigenvalues.max();
    if !(eigen.eigenvalues.min() > largest * 1e-12 && largest > 0.0) {
        return Err(SolveError::ClosedFormFailed(
            "Park: MᵀM is singular (robot rotations all about one axis)",
        ));
    }
    let inv_sqrt = Matrix3::from_diagonal(&eigen.eigenvalues.map(|l| 1.0 / l.sqrt()));
    let r = eigen.eigenvectors * inv_sqrt * eigen.eigenvectors.transpose() * m.transpose();
    if r.determinant() <= 0.0 {
        return Err(SolveError::ClosedFormFailed(
            "Park: the rotation estimate is a reflection (inconsistent rotations)",
        ));
    }
    let rx = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(r));
    let tx = ax_xb_translation(motions, &rx)?;
    Ok(Pose::from_parts(Translation3::from(tx), rx))
}
