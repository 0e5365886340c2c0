//! The classic closed-form hand-eye solutions, each from its paper, written for this project's
//! `A_i = X·B_i·Y` (see the module doc of [`solve`](super)): the cross-check a user coming from
//! OpenCV's `calibrateHandEye` / `calibrateRobotWorldHandEye` expects, and the warm start and
//! diagnosis tool of the other methods ([`solve_axby`] is Shah's).
//!
//! * AX = XB family ([`tsai`], [`park`], [`horaud`], [`andreff`], [`daniilidis`]): they need
//!   relative motions. From `A_i = X·B_i·Y`, `A_i·A_j⁻¹ = X·(B_i·B_j⁻¹)·X⁻¹`, so the motion
//!   pairs `(A_ij, B_ij) = (A_i·A_j⁻¹, B_i·B_j⁻¹)` satisfy `A_ij·X = X·B_ij` for the same `X`
//!   (eye-in-hand: camera and flange motions). All pairs `i < j` are used (as OpenCV does),
//!   except those whose rotation is below [`MIN_MOTION_ANGLE_RAD`] (no information on `X`,
//!   ill-conditioned for Tsai); a pair's weight is the smaller of its two samples' weights.
//!   These methods give `X` only; `Y` is then the average of the per-sample estimates
//!   `Y_i = B_i⁻¹·X⁻¹·A_i` (chordal L2 mean of the rotations, weighted mean of the
//!   translations: the least-squares `t_Y` for the rotation found), see [`y_from_x`].
//! * AX = ZB family ([`shah`], [`li`]): both unknowns at once. Shah's is written directly for
//!   `X·B_i·Y = A_i`; Li's is written in the paper's form `A'·X' = Z'·B'` with `A' = A_i`,
//!   `B' = B_i`, `Z' = X`, `X' = Y⁻¹`.
//!
//! Every method is exact on noise-free data (the published property the tests check) and they
//! agree with each other within the noise. Pure maths on nalgebra; units rad and m.

pub mod andreff;
pub mod daniilidis;
pub mod horaud;
pub mod li;
pub mod park;
pub mod shah;
pub mod tsai;

pub use shah::{rotations, solve_axby, translations};

use nalgebra::{
    DMatrix, DVector, Matrix3, Matrix4, SMatrix, SymmetricEigen, Translation3, UnitQuaternion,
    Vector3, Vector4,
};

use super::{Axby, AxbyData, Method, SolveError};
use handeye_core::geometry::{project_to_rotation, Pose};

/// Relative motions rotating less than this (rad, 0.5°) carry no information on `X` and are
/// left out of the AX = XB methods.
pub const MIN_MOTION_ANGLE_RAD: f64 = 0.5 * std::f64::consts::PI / 180.0;

/// Solves `A_i = X·B_i·Y` with the closed form `method`. [`Method::Iterative`] and
/// [`Method::Refined`] are not closed forms and give [`SolveError::ClosedFormFailed`].
pub fn solve(method: Method, data: &AxbyData) -> Result<Axby, SolveError> {
    // The AX = XB methods: `X` from the relative motions, then `Y` from `X`.
    let ax_xb = |solve_x: fn(&[Motion]) -> Result<Pose, SolveError>| {
        let x = solve_x(&relative_motions(data)?)?;
        Ok(Axby {
            x,
            y: y_from_x(data, &x)?,
        })
    };
    match method {
        Method::ClosedForm => solve_axby(data),
        Method::Li => li::solve(data),
        Method::Tsai => ax_xb(tsai::solve),
        Method::Park => ax_xb(park::solve),
        Method::Horaud => ax_xb(horaud::solve),
        Method::Andreff => ax_xb(andreff::solve),
        Method::Daniilidis => ax_xb(daniilidis::solve),
        Method::Iterative | Method::Refined => Err(SolveError::ClosedFormFailed(
            "the iterative and refined methods are not closed forms",
        )),
    }
}

/// One relative motion: `A·X = X·B`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Motion {
    /// `A_i·A_j⁻¹` (eye-in-hand: the camera's motion, `T_camera_i_camera_j`).
    pub a: Pose,
    /// `B_i·B_j⁻¹` (eye-in-hand: the flange's motion, `T_flange_i_flange_j`).
    pub b: Pose,
    /// Weight (the smaller of the two samples' weights).
    pub weight: f64,
}

/// The relative motions of every pair of samples `i < j` whose robot rotation is at least
/// [`MIN_MOTION_ANGLE_RAD`]. Refuses fewer than two (the AX = XB methods need two motions about
/// different axes).
pub fn relative_motions(data: &AxbyData) -> Result<Vec<Motion>, SolveError> {
    let mut motions = Vec::new();
    for i in 0..data.len() {
        for j in i + 1..data.len() {
            let b = data.b[i] * data.b[j].inverse();
            if b.rotation.angle() < MIN_MOTION_ANGLE_RAD {
                continue;
            }
            motions.push(Motion {
                a: data.a[i] * data.a[j].inverse(),
                b,
                weight: data.weights[i].min(data.weights[j]),
            });
        }
    }
    if motions.len() < 2 {
        return Err(SolveError::ClosedFormFailed(
            "fewer than two relative motions rotate by 0.5° or more",
        ));
    }
    Ok(motions)
}

/// `Y` given `X`: the rotation is the chordal L2 mean of `R_Y,i` of `Y_i = B_i⁻¹·X⁻¹·A_i` (the
/// dominant eigenvector of `Σ w_i q_i q_iᵀ`, blind to the quaternion sign), the translation
/// the weighted mean of `t_Y,i`, which is the least-squares translation given `X`.
pub fn y_from_x(data: &AxbyData, x: &Pose) -> Result<Pose, SolveError> {
    let x_inv = x.inverse();
    let mut scatter = Matrix4::zeros();
    let mut translation = Vector3::zeros();
    let mut total = 0.0;
    for ((a, b), &w) in data.a.iter().zip(&data.b).zip(&data.weights) {
        let y = b.inverse() * x_inv * a;
        let q: Vector4<f64> = y.rotation.coords;
        scatter += q * q.transpose() * w;
        translation += y.translation.vector * w;
        total += w;
    }
    if total <= 0.0 || !total.is_finite() {
        return Err(SolveError::ClosedFormFailed(
            "no samples with positive weight",
        ));
    }
    let eigen = SymmetricEigen::new(scatter);
    let q = eigen
        .eigenvectors
        .column(eigen.eigenvalues.imax())
        .into_owned();
    let rotation = UnitQuaternion::from_quaternion(nalgebra::Quaternion::from(q));
    Ok(Pose::from_parts(
        Translation3::from(translation / total),
        rotation,
    ))
}

/// The AX = XB translation given `R_X`: least squares of `(R_A − I)·t_X = R_X·t_B − t_A` over
/// the motions (Tsai's, Park's and Horaud's second step).
pub fn ax_xb_translation(
    motions: &[Motion],
    rx: &UnitQuaternion<f64>,
) -> Result<Vector3<f64>, SolveError> {
    let mut normal = Matrix3::zeros();
    let mut rhs = Vector3::zeros();
    for m in motions {
        let lhs = m.a.rotation.to_rotation_matrix().into_inner() - Matrix3::identity();
        let r = rx * m.b.translation.vector - m.a.translation.vector;
        normal += lhs.transpose() * lhs * m.weight;
        rhs += lhs.transpose() * r * m.weight;
    }
    normal
        .cholesky()
        .map(|c| c.solve(&rhs))
        .ok_or(SolveError::ClosedFormFailed(
            "the translation system is singular (robot rotations all about one axis)",
        ))
}

/// A 3x3 matrix that is a rotation up to an unknown scale (a null vector reshaped): scaled to
/// determinant +1 and projected onto SO(3). `None` when the determinant vanishes.
pub(crate) fn rotation_up_to_scale(m: &Matrix3<f64>) -> Option<UnitQuaternion<f64>> {
    let det = m.determinant();
    if !det.is_finite() || det.abs() < 1e-12 {
        return None;
    }
    project_to_rotation(&(m * (det.signum() / det.abs().cbrt())))
}

/// Kronecker product `a ⊗ b` of two 3x3 matrices. With column-major `vec`,
/// `vec(P·M·Q) = (Qᵀ ⊗ P)·vec(M)`.
pub(crate) fn kron(a: &Matrix3<f64>, b: &Matrix3<f64>) -> SMatrix<f64, 9, 9> {
    let mut k = SMatrix::<f64, 9, 9>::zeros();
    for i in 0..3 {
        for j in 0..3 {
            k.fixed_view_mut::<3, 3>(3 * i, 3 * j)
                .copy_from(&(b * a[(i, j)]));
        }
    }
    k
}

/// Least squares `min |M·x − r|` by SVD (rank-revealing; `None` when rank-deficient).
pub(crate) fn least_squares(m: DMatrix<f64>, r: DVector<f64>) -> Option<DVector<f64>> {
    let columns = m.ncols();
    let svd = m.svd(true, true);
    let largest = svd.singular_values.max();
    let rank = svd
        .singular_values
        .iter()
        .filter(|&&s| s > largest * 1e-12)
        .count();
    if rank < columns {
        return None;
    }
    svd.solve(&r, largest * 1e-12).ok()
}
