//! Horaud and Dornaika (1995), "Hand-eye calibration" (Int. J. Robotics Research 14(3)), the
//! linear (closed-form) rotation of its two-step method.
//!
//! With unit quaternions, `q_A ∘ q_X = q_X ∘ q_B` for each motion (both taken with a
//! non-negative scalar part, which conjugate rotations share). Writing `p ∘ q = Q(p)·q` and
//! `q ∘ p = W(p)·q`, `q_X` minimises `Σ w·|(Q(q_A) − W(q_B))·q_X|²` on the unit sphere: the
//! eigenvector of the smallest eigenvalue of `Σ w·(Q − W)ᵀ(Q − W)`. The translation solves
//! `(R_A − I)·t_X = R_X·t_B − t_A`.

use nalgebra::{Matrix4, Quaternion, SymmetricEigen, Translation3, UnitQuaternion};

use super::{ax_xb_translation, Motion};
use crate::SolveError;
use handeye_core::geometry::Pose;

/// The quaternion with a non-negative scalar part, as (w, x, y, z).
fn positive(q: &UnitQuaternion<f64>) -> [f64; 4] {
    let s = if q.w < 0.0 { -1.0 } else { 1.0 };
    [s * q.w, s * q.i, s * q.j, s * q.k]
}

/// `Q(p)` with `p ∘ q = Q(p)·q`, quaternions as (w, x, y, z).
fn left(p: [f64; 4]) -> Matrix4<f64> {
    let [w, x, y, z] = p;
    Matrix4::new(w, -x, -y, -z, x, w, -z, y, y, z, w, -x, z, -y, x, w)
}

/// `W(p)` with `q ∘ p = W(p)·q`, quaternions as (w, x, y, z).
fn right(p: [f64; 4]) -> Matrix4<f64> {
    let [w, x, y, z] = p;
    Matrix4::new(w, -x, -y, -z, x, w, z, -y, y, -z, w, x, z, y, -x, w)
}

/// `X` of `A·X = X·B` by Horaud and Dornaika.
pub fn solve(motions: &[Motion]) -> Result<Pose, SolveError> {
    let mut normal = Matrix4::zeros();
    for m in motions {
        let d = left(positive(&m.a.rotation)) - right(positive(&m.b.rotation));
        normal += d.transpose() * d * m.weight;
    }
    let eigen = SymmetricEigen::new(normal);
    let mut sorted: Vec<f64> = eigen.eigenvalues.iter().copied().collect();
    sorted.sort_by(f64::total_cmp);
    // Two motions about different axes make the null space one-dimensional.
    if !(sorted[1] > sorted[3] * 1e-12 && sorted[3] > 0.0) {
        return Err(SolveError::ClosedFormFailed(
            "Horaud: the rotation null space is not one-dimensional (robot rotations all about one axis)",
        ));
    }
    let v = eigen.eigenvectors.column(eigen.eigenvalues.imin());
    let rx = UnitQuaternion::from_quaternion(Quaternion::new(v[0], v[1], v[2], v[3]));
    let tx = ax_xb_translation(motions, &rx)?;
    Ok(Pose::from_parts(Translation3::from(tx), rx))
}
