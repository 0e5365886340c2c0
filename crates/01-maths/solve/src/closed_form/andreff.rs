//! Andreff, Horaud and Espiau (2001), "Robot hand-eye calibration using structure-from-motion"
//! (Int. J. Robotics Research 20(3)), the linear formulation of `A·X = X·B`.
//!
//! `R_A·R_X = R_X·R_B` becomes, with column-major `vec`, the homogeneous linear system
//! `(I₃ ⊗ R_A − R_Bᵀ ⊗ I₃)·vec(R_X) = 0`; its least-squares null vector, scaled to determinant
//! +1 and projected onto SO(3) (the paper's orthogonalisation), is `R_X`. The translation
//! block `(I₃ − R_A)·t_X = t_A − R_X·t_B` is then solved by least squares with `R_X` fixed (the
//! paper's decoupled variant of its 12-unknown system).

use nalgebra::{Matrix3, SMatrix, SVector, SymmetricEigen, Translation3};

use super::{ax_xb_translation, kron, rotation_up_to_scale, Motion};
use crate::SolveError;
use handeye_core::geometry::Pose;

/// `X` of `A·X = X·B` by Andreff, Horaud and Espiau.
pub fn solve(motions: &[Motion]) -> Result<Pose, SolveError> {
    let identity = Matrix3::identity();
    let mut normal = SMatrix::<f64, 9, 9>::zeros();
    for m in motions {
        let ra = m.a.rotation.to_rotation_matrix().into_inner();
        let rb = m.b.rotation.to_rotation_matrix().into_inner();
        let k = kron(&identity, &ra) - kron(&rb.transpose(), &identity);
        normal += k.transpose() * k * m.weight;
    }
    let eigen = SymmetricEigen::new(normal);
    let v: SVector<f64, 9> = eigen
        .eigenvectors
        .column(eigen.eigenvalues.imin())
        .into_owned();
    let rx =
        rotation_up_to_scale(&Matrix3::from_column_slice(v.as_slice()))
            .ok_or(SolveError::ClosedFormFailed(
            "Andreff: the rotation null vector is degenerate (robot rotations all about one axis)",
        ))?;
    let tx = ax_xb_translation(motions, &rx)?;
    Ok(Pose::from_parts(Translation3::from(tx), rx))
}
