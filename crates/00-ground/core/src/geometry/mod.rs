//! Rigid transforms on nalgebra, and the one naming convention of the project.
//!
//! `T_a_b` (docs, YAML) is `a_from_b` in code: it maps a point expressed in frame
//! `b` into frame `a` (`p_a = T_a_b * p_b`), so compositions cancel inner names:
//! `base_from_camera = base_from_flange * flange_from_camera`.
//! Units are metres and radians. This module depends on nothing else of ours.

pub mod homography;
pub mod serde_pose;
pub mod yaml;

use nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, UnitQuaternion, Vector3};

pub use yaml::{PoseError, PoseRecord, PoseYaml};

/// A rigid transform `T_a_b`; the frames live in the binding's name (`base_from_flange`).
pub type Pose = Isometry3<f64>;

/// Builds a pose from a translation (m) and a rotation vector (axis · angle, rad) — the form a UR
/// controller reports (`p[x, y, z, rx, ry, rz]`).
pub fn pose_from_rotvec(translation: Vector3<f64>, rotvec: Vector3<f64>) -> Pose {
    Isometry3::from_parts(
        Translation3::from(translation),
        UnitQuaternion::from_scaled_axis(rotvec),
    )
}

/// One link of a standard Denavit–Hartenberg chain at joint angle `theta` (rad):
/// `T_{i-1}_{i} = Rz(θ) · Tz(d) · Tx(a) · Rx(α)` (m, rad). The one DH link of the project: the
/// arm models' forward kinematics (`handeye_robot::kinematics`) and the solver's arm model
/// (`handeye_solve::kinematics`) both chain it.
pub fn dh_link(theta: f64, d: f64, a: f64, alpha: f64) -> Pose {
    let (s, c) = theta.sin_cos();
    let rotation = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), theta)
        * UnitQuaternion::from_axis_angle(&Vector3::x_axis(), alpha);
    Isometry3::from_parts(Translation3::new(a * c, a * s, d), rotation)
}

/// The rotation vector (axis · angle, rad, angle in [0, π]) of a rotation.
///
/// Goes through the quaternion, which stays well conditioned near 180° where the
/// matrix-log formula divides by `sin θ ≈ 0`.
pub fn rotvec(rotation: &UnitQuaternion<f64>) -> Vector3<f64> {
    // Pick the hemisphere with w >= 0 so the angle is the short one (≤ π).
    let q = if rotation.w < 0.0 {
        UnitQuaternion::new_unchecked(-rotation.into_inner())
    } else {
        *rotation
    };
    q.scaled_axis()
}

/// The translation distance between two poses' origins, in metres.
pub fn translation_distance(a: &Pose, b: &Pose) -> f64 {
    (a.translation.vector - b.translation.vector).norm()
}

/// Builds a rotation from a 3x3 matrix that must already be orthonormal with determinant +1
/// (checked to `tol` in the Frobenius norm); returns `None` otherwise.
pub fn rotation_from_matrix(m: &Matrix3<f64>, tol: f64) -> Option<UnitQuaternion<f64>> {
    if !m.iter().all(|v| v.is_finite()) {
        return None;
    }
    let orthonormality_error = (m.transpose() * m - Matrix3::identity()).norm();
    if orthonormality_error > tol || (m.determinant() - 1.0).abs() > tol {
        return None;
    }
    Some(UnitQuaternion::from_rotation_matrix(
        &Rotation3::from_matrix_unchecked(*m),
    ))
}

/// Relative rotations smaller than this (2°) have no meaningful axis: the coverage views and
/// the hand-guided suggestions leave them out.
pub const MIN_AXIS_ANGLE_RAD: f64 = 0.035;

/// The axis of the rotation from `earlier` to `later` (`later·earlierᵀ`, in the frame both are
/// given in), folded onto the upper hemisphere (an axis and its opposite are the same motion),
/// with its angle, rad; `None` when the angle is at most `min_angle_rad` (no meaningful axis).
pub fn relative_rotation_axis(
    earlier: &UnitQuaternion<f64>,
    later: &UnitQuaternion<f64>,
    min_angle_rad: f64,
) -> Option<(Vector3<f64>, f64)> {
    let (axis, angle) = (later * earlier.inverse()).axis_angle()?;
    if angle <= min_angle_rad {
        return None;
    }
    let axis = axis.into_inner();
    Some((if axis.z < 0.0 { -axis } else { axis }, angle))
}

/// The rotation closest (Frobenius norm) to a 3x3 matrix: the orthogonal polar factor by SVD,
/// `U·diag(1, 1, det(U·Vᵀ))·Vᵀ`, so a reflection becomes the nearest proper rotation.
///
/// For matrices that are rotations only up to noise (a homography's columns, a least-squares
/// solution reshaped). `None` when the matrix is not finite or the SVD fails.
pub fn project_to_rotation(m: &Matrix3<f64>) -> Option<UnitQuaternion<f64>> {
    if !m.iter().all(|v| v.is_finite()) {
        return None;
    }
    let svd = m.svd(true, true);
    let u = svd.u?;
    let v_t = svd.v_t?;
    let mut d = Matrix3::identity();
    if (u * v_t).determinant() < 0.0 {
        d[(2, 2)] = -1.0;
    }
    let r = u * d * v_t;
    if !r.iter().all(|v| v.is_finite()) {
        return None;
    }
    Some(UnitQuaternion::from_rotation_matrix(
        &Rotation3::from_matrix_unchecked(r),
    ))
}

/// Largest accepted distance of any loaded or exported translation from its frame's origin, m.
/// A robot cell spans a few metres; 100 m leaves room for gantries and mobile bases while a
/// value in millimetres read as metres (500 mm → 500 m), a sign-bit typo or a `1e300` is
/// refused before it reaches the solver (where it would give a 1e298 mm answer and NaN
/// covariances).
pub const MAX_TRANSLATION_M: f64 = 100.0;

/// Why a translation is not plausible for a robot cell.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum TranslationProblem {
    /// NaN or infinity in a component.
    #[error("value is not finite ({0})")]
    NotFinite(f64),
    /// Farther from the origin than [`MAX_TRANSLATION_M`].
    #[error(
        "[{}, {}, {}] m lies {} m from the origin, beyond the {MAX_TRANSLATION_M} m a robot \
         cell spans (millimetres given as metres?)",
        readable(.value[0]), readable(.value[1]), readable(.value[2]), readable(*.norm)
    )]
    TooFar {
        /// The translation, m.
        value: [f64; 3],
        /// Its length, m.
        norm: f64,
    },
}

/// A number for a message: plain when moderate, in exponent form when huge or tiny (Rust's
/// `{}` would print all 301 digits of `1e300`).
pub fn readable(v: f64) -> String {
    if v == 0.0 || (1e-4..1e6).contains(&v.abs()) || !v.is_finite() {
        format!("{v}")
    } else {
        format!("{v:e}")
    }
}

/// The one check every loader applies to a translation (m): finite, and within
/// [`MAX_TRANSLATION_M`] of the origin. Callers add the file, sample and field to the error.
pub fn check_translation(t: &Vector3<f64>) -> Result<(), TranslationProblem> {
    if let Some(bad) = t.iter().find(|v| !v.is_finite()) {
        return Err(TranslationProblem::NotFinite(*bad));
    }
    // hypot does not overflow where `t.norm()` squares 1e300 to infinity.
    let norm = t.x.hypot(t.y).hypot(t.z);
    if norm > MAX_TRANSLATION_M {
        return Err(TranslationProblem::TooFar {
            value: [t.x, t.y, t.z],
            norm,
        });
    }
    Ok(())
}

/// The 4x4 homogeneous matrix of a pose (row-major nested arrays, as written in files).
pub fn to_matrix4_rows(pose: &Pose) -> [[f64; 4]; 4] {
    let m = pose.to_homogeneous();
    let mut rows = [[0.0; 4]; 4];
    for (r, row) in rows.iter_mut().enumerate() {
        for (c, v) in row.iter_mut().enumerate() {
            *v = m[(r, c)];
        }
    }
    rows
}

/// Root mean square of `values`; NaN when there are none (nothing to summarise is not zero).
pub fn rms(values: impl Iterator<Item = f64>) -> f64 {
    let (sum, n) = values.fold((0.0, 0usize), |(s, n), v| (s + v * v, n + 1));
    if n == 0 {
        f64::NAN
    } else {
        (sum / n as f64).sqrt()
    }
}

/// Weighted root mean square of `(value, weight)`: `sqrt(Σ w·v² / Σ w)`, each value at its
/// weight's precision (a weight is an inverse variance relative to the typical value's); the
/// plain [`rms`] when every weight is 1. `NaN` for no value.
pub fn weighted_rms(values: impl Iterator<Item = (f64, f64)>) -> f64 {
    let (sum, total) = values.fold((0.0, 0.0), |(s, t), (v, w)| (s + w * v * v, t + w));
    if total > 0.0 {
        (sum / total).sqrt()
    } else {
        f64::NAN
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    #[test]
    fn translations_beyond_a_robot_cell_are_refused() {
        assert!(check_translation(&Vector3::new(0.5, -1.2, 99.0)).is_ok());
        let far = check_translation(&Vector3::new(1e300, 0.0, 0.0)).unwrap_err();
        assert!(matches!(far, TranslationProblem::TooFar { norm, .. } if norm == 1e300));
        assert_eq!(
            far.to_string(),
            "[1e300, 0, 0] m lies 1e300 m from the origin, beyond the 100 m a robot cell spans \
             (millimetres given as metres?)"
        );
        assert!(check_translation(&Vector3::new(1e200, -1e200, 0.0)).is_err());
        assert_eq!(
            check_translation(&Vector3::new(0.0, f64::NAN, 0.0))
                .unwrap_err()
                .to_string(),
            "value is not finite (NaN)"
        );
        assert!(check_translation(&Vector3::new(0.0, 0.0, 100.001)).is_err());
    }

    #[test]
    fn rotvec_round_trips_near_180_degrees() {
        for angle in [0.0, 1e-9, 0.3, PI - 1e-6, PI - 1e-12, PI] {
            let axis = Vector3::new(0.3, -0.5, 0.8).normalize();
            let q = UnitQuaternion::from_scaled_axis(axis * angle);
            let back = UnitQuaternion::from_scaled_axis(rotvec(&q));
            assert!(q.angle_to(&back) < 1e-9, "angle {angle}");
            assert!(rotvec(&q).norm() <= PI + 1e-12);
        }
    }

    #[test]
    fn rotvec_uses_short_angle_for_negative_w() {
        let q = UnitQuaternion::from_scaled_axis(Vector3::new(0.0, 0.0, 0.5));
        let flipped = UnitQuaternion::new_unchecked(-q.into_inner());
        assert!((rotvec(&flipped) - Vector3::new(0.0, 0.0, 0.5)).norm() < 1e-12);
    }

    #[test]
    fn projection_recovers_a_rotation_from_a_noisy_or_reflected_matrix() {
        let truth = UnitQuaternion::from_scaled_axis(Vector3::new(0.4, -1.1, 2.0));
        let r = truth.to_rotation_matrix().into_inner();
        // A rotation is its own projection; a uniform scale does not move it.
        assert!(project_to_rotation(&r).unwrap().angle_to(&truth) < 1e-12);
        assert!(project_to_rotation(&(r * 2.5)).unwrap().angle_to(&truth) < 1e-12);
        // A small symmetric disturbance (no rotation part) leaves the rotation in place to
        // first order; the result is a proper rotation whatever the input.
        let mut noisy = r;
        noisy[(0, 1)] += 1e-3;
        noisy[(1, 0)] += 1e-3;
        let p = project_to_rotation(&noisy).unwrap();
        let m = p.to_rotation_matrix().into_inner();
        assert!((m.transpose() * m - Matrix3::identity()).norm() < 1e-12);
        assert!((m.determinant() - 1.0).abs() < 1e-12);
        assert!(p.angle_to(&truth) < 2e-3, "{}", p.angle_to(&truth));
        // A reflection (det −1) gives the nearest proper rotation, not a reflection.
        let reflected = r * Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, -1.0));
        let q = project_to_rotation(&reflected)
            .unwrap()
            .to_rotation_matrix();
        assert!((q.matrix().determinant() - 1.0).abs() < 1e-12);
        let mut bad = r;
        bad[(2, 2)] = f64::NAN;
        assert!(project_to_rotation(&bad).is_none());
    }

    #[test]
    fn rejects_non_orthonormal_matrix() {
        let mut m = Matrix3::identity();
        m[(0, 1)] = 0.1;
        assert!(rotation_from_matrix(&m, 1e-6).is_none());
        assert!(rotation_from_matrix(&-Matrix3::identity(), 1e-6).is_none());
        assert!(rotation_from_matrix(&Matrix3::identity(), 1e-6).is_some());
    }
}
