//! Tsai and Lenz (1989), "A new technique for fully autonomous and efficient 3D robotics
//! hand/eye calibration" (IEEE Trans. Robotics and Automation 5(3)), for `A·X = X·B`.
//!
//! The paper's gripper motion `H_gij` is [`Motion::a`], its camera motion `H_cij` is
//! [`Motion::b`] and `H_cg` is `X` (`H_gij·H_cg = H_cg·H_cij`). With the modified Rodrigues
//! vectors `P = 2 sin(θ/2)·k` of each motion, the Cayley vector `c = tan(θ_X/2)·k_X` of `R_X`
//! solves the linear least squares `[P_A + P_B]×·c = P_B − P_A` (the paper's eq. for `P'_cg`);
//! `R_X` is the quaternion `(1, c)` normalised (the paper's `P_cg = 2c/√(1+|c|²)` in another
//! form). The translation solves `(R_A − I)·t_X = R_X·t_B − t_A`. Cannot represent a 180°
//! rotation of `X` (the Cayley vector is infinite there), as in the paper.

use nalgebra::{Matrix3, Quaternion, Translation3, UnitQuaternion, Vector3};

use super::{ax_xb_translation, Motion};
use crate::SolveError;
use handeye_core::geometry::{rotvec, Pose};

/// `2 sin(θ/2)·k` of a rotation (θ in [0, π]).
fn modified_rodrigues(q: &UnitQuaternion<f64>) -> Vector3<f64> {
    let v = rotvec(q);
    let angle = v.norm();
    if angle == 0.0 {
        return Vector3::zeros();
    }
    v * (2.0 * (angle / 2.0).sin() / angle)
}

/// `X` of `A·X = X·B` by Tsai and Lenz.
pub fn solve(motions: &[Motion]) -> Result<Pose, SolveError> {
    let mut normal = Matrix3::zeros();
    let mut rhs = Vector3::zeros();
    for m in motions {
        let pa = modified_rodrigues(&m.a.rotation);
        let pb = modified_rodrigues(&m.b.rotation);
        let lhs = (pa + pb).cross_matrix();
        normal += lhs.transpose() * lhs * m.weight;
        rhs += lhs.transpose() * (pb - pa) * m.weight;
    }
    let c = normal
        .cholesky()
        .map(|c| c.solve(&rhs))
        .ok_or(SolveError::ClosedFormFailed(
            "Tsai: the rotation system is singular (robot rotations all about one axis)",
        ))?;
    let rx = UnitQuaternion::from_quaternion(Quaternion::new(1.0, c.x, c.y, c.z));
    let tx = ax_xb_translation(motions, &rx)?;
    Ok(Pose::from_parts(Translation3::from(tx), rx))
}
