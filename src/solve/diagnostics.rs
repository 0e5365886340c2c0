//! Diagnostics returned with every answer, and the checks that refuse unsolvable input.
//!
//! * residuals of each sample's measured `T_camera_target` against the prediction (deg, mm,
//!   and whitened by the noise model), with RMS and max;
//! * outlier flags by robust statistics (median and MAD of the whitened residual norms);
//! * observability: at least 3 samples whose relative robot rotations are not all about one
//!   axis ([`check_rotation_diversity`], also for the plan checker: robot poses only);
//! * convention: when the fit is poor, whether inverted robot poses (equivalently the other
//!   setup), inverted camera poses, or both, fit far better;
//! * units ([`check_units`], before solving): translations inconsistent with metres — a flange
//!   tens of metres from its base, a board tens of metres from the camera, or robot and camera
//!   translations that only fit each other after scaling one of them ([`unit_scale`]);
//! * plausibility of the answer ([`check_mounts`], [`check_against_nominal`]): a camera (or
//!   target) on the flange that is far from it, with the other unknown as short as a flange
//!   offset — the signature of both inputs inverted, which fits exactly as well as the truth.
//!
//! Depends on `geometry`, `notice`, `setup` and the solver types only; units rad/m inside,
//! deg/mm in reports.

use nalgebra::{DMatrix, DVector, Matrix3, SymmetricEigen, Vector3};

use super::{
    closed_form, Axby, AxbyData, Calibration, NoiseModel, Residuals, SolveError, UnitsProblem,
};
use crate::geometry::{rotvec, translation_distance, Pose};
use crate::notice::{Notice, NoticeKind};
use crate::setup::{CellTransforms, PosePair, Setup};

/// Fewest samples the problem needs.
pub const MIN_SAMPLES: usize = 3;
/// Required rotation (deg) off the dominant axis of the relative robot rotations.
pub const MIN_OFF_AXIS_DEG: f64 = 3.0;
/// Required largest relative robot rotation (deg).
pub const MIN_ROTATION_SPAN_DEG: f64 = 3.0;

/// How varied the robot's rotations are.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RotationDiversity {
    /// Dominant axis of the rotations relative to the first pose (its flange frame).
    pub axis: Vector3<f64>,
    /// Largest relative rotation, degrees.
    pub span_deg: f64,
    /// Largest rotation component off the dominant axis, degrees.
    pub off_axis_deg: f64,
}

/// Measures the diversity of robot rotations `T_base_flange` (relative to the first pose, in its
/// flange frame). Needs at least one pose.
pub fn rotation_diversity(base_from_flange: &[Pose]) -> RotationDiversity {
    let Some(first) = base_from_flange.first() else {
        return RotationDiversity {
            axis: Vector3::z(),
            span_deg: 0.0,
            off_axis_deg: 0.0,
        };
    };
    let relative: Vec<Vector3<f64>> = base_from_flange[1..]
        .iter()
        .map(|p| rotvec(&(first.rotation.inverse() * p.rotation)))
        .collect();
    let mut scatter = Matrix3::zeros();
    for v in &relative {
        scatter += v * v.transpose();
    }
    let eigen = SymmetricEigen::new(scatter);
    let axis: Vector3<f64> = eigen
        .eigenvectors
        .column(eigen.eigenvalues.imax())
        .into_owned();
    let off_axis = relative
        .iter()
        .map(|v| (v - axis * axis.dot(v)).norm())
        .fold(0.0, f64::max);
    let span = relative.iter().map(|v| v.norm()).fold(0.0, f64::max);
    RotationDiversity {
        axis,
        span_deg: span.to_degrees(),
        off_axis_deg: off_axis.to_degrees(),
    }
}

/// Refuses robot poses that cannot determine both unknowns: fewer than [`MIN_SAMPLES`], or
/// relative rotations that are tiny or all about (nearly) one axis. The error says which poses
/// to add.
pub fn check_rotation_diversity(base_from_flange: &[Pose]) -> Result<(), SolveError> {
    if base_from_flange.len() < MIN_SAMPLES {
        return Err(SolveError::TooFewSamples {
            found: base_from_flange.len(),
            required: MIN_SAMPLES,
        });
    }
    let d = rotation_diversity(base_from_flange);
    if d.span_deg < MIN_ROTATION_SPAN_DEG {
        return Err(SolveError::TooLittleRotation {
            span_deg: d.span_deg,
            required_deg: MIN_ROTATION_SPAN_DEG,
        });
    }
    if d.off_axis_deg < MIN_OFF_AXIS_DEG {
        let helper = if d.axis.x.abs() < 0.9 {
            Vector3::x()
        } else {
            Vector3::y()
        };
        let first = d.axis.cross(&helper).normalize();
        let second = d.axis.cross(&first).normalize();
        return Err(SolveError::Coaxial {
            axis: [d.axis.x, d.axis.y, d.axis.z],
            off_axis_deg: d.off_axis_deg,
            required_deg: MIN_OFF_AXIS_DEG,
            add_about: [[first.x, first.y, first.z], [second.x, second.y, second.z]],
        });
    }
    Ok(())
}

fn rms(values: &[f64]) -> f64 {
    if values.is_empty() {
        return 0.0;
    }
    (values.iter().map(|v| v * v).sum::<f64>() / values.len() as f64).sqrt()
}

/// Residuals of every sample of `data` against a solution.
pub fn residuals(data: &AxbyData, solution: &Axby, noise: &NoiseModel) -> Residuals {
    let mut rotation_deg = Vec::with_capacity(data.len());
    let mut translation_mm = Vec::with_capacity(data.len());
    let mut normalised = Vec::with_capacity(data.len());
    for (a, b) in data.a.iter().zip(&data.b) {
        let predicted = solution.x * b * solution.y;
        let rotation = predicted.rotation.angle_to(&a.rotation);
        let translation = (predicted.translation.vector - a.translation.vector).norm();
        rotation_deg.push(rotation.to_degrees());
        translation_mm.push(translation * 1e3);
        normalised.push(
            ((rotation / noise.rotation_sigma_rad).powi(2)
                + (translation / noise.translation_sigma_m).powi(2))
            .sqrt(),
        );
    }
    Residuals {
        rotation_rms_deg: rms(&rotation_deg),
        rotation_max_deg: rotation_deg.iter().copied().fold(0.0, f64::max),
        translation_rms_mm: rms(&translation_mm),
        translation_max_mm: translation_mm.iter().copied().fold(0.0, f64::max),
        rotation_deg,
        translation_mm,
        normalised,
    }
}

/// Residuals of a subset placed back at the input indices (`NaN` for samples not used), with
/// the summary of the used samples.
pub fn scatter_residuals(sub: &Residuals, keep: &[usize], total: usize) -> Residuals {
    if keep.len() == total {
        return sub.clone();
    }
    let spread = |values: &[f64]| {
        let mut out = vec![f64::NAN; total];
        for (&i, v) in keep.iter().zip(values) {
            out[i] = *v;
        }
        out
    };
    Residuals {
        rotation_deg: spread(&sub.rotation_deg),
        translation_mm: spread(&sub.translation_mm),
        normalised: spread(&sub.normalised),
        ..sub.clone()
    }
}

fn median(values: &mut [f64]) -> f64 {
    values.sort_by(f64::total_cmp);
    let n = values.len();
    if n == 0 {
        0.0
    } else if n % 2 == 1 {
        values[n / 2]
    } else {
        0.5 * (values[n / 2 - 1] + values[n / 2])
    }
}

/// Indices of samples whose whitened residual norm exceeds both
/// `median + mad_factor · 1.4826 · MAD` and `floor_sigma`.
pub fn flag_outliers(normalised: &[f64], mad_factor: f64, floor_sigma: f64) -> Vec<usize> {
    let mut sorted = normalised.to_vec();
    let med = median(&mut sorted);
    let mut deviations: Vec<f64> = normalised.iter().map(|v| (v - med).abs()).collect();
    let mad = median(&mut deviations);
    let threshold = (med + mad_factor * 1.4826 * mad).max(floor_sigma);
    normalised
        .iter()
        .enumerate()
        .filter(|(_, &v)| v > threshold)
        .map(|(i, _)| i)
        .collect()
}

/// Rotation residual RMS (deg) above which the fit is called poor and conventions are checked.
pub fn poor_fit_threshold_deg(noise: &NoiseModel) -> f64 {
    (5.0 * noise.rotation_sigma_rad.to_degrees()).max(2.0)
}

fn closed_form_rms_deg(setup: Setup, pairs: &[PosePair]) -> f64 {
    let data = AxbyData::new(setup, pairs);
    match closed_form::solve_axby(&data) {
        Ok(s) => residuals(&data, &s, &NoiseModel::default()).rotation_rms_deg,
        Err(_) => f64::INFINITY,
    }
}

/// When the fit as given is poor (`given_rms_deg`, or the closed form's if `None`), tries the
/// data with the robot poses inverted and returns [`SolveError::ConventionMismatch`] if that fits
/// well and at least 5 times better.
///
/// In `A = X·B·Y`, inverting the camera poses is the same problem as inverting the robot poses
/// (`A⁻¹ = Y⁻¹·B⁻¹·X⁻¹`, the unknowns swap roles), and so is the other setup; inverting both
/// fits exactly as well as neither and cannot be seen in the data. So one test covers every
/// detectable mislabelling, and the message names all three explanations.
pub fn check_convention(
    setup: Setup,
    pairs: &[PosePair],
    given_rms_deg: Option<f64>,
    noise: &NoiseModel,
) -> Result<(), SolveError> {
    let poor = poor_fit_threshold_deg(noise);
    let given = given_rms_deg.unwrap_or_else(|| closed_form_rms_deg(setup, pairs));
    if given <= poor {
        return Ok(());
    }
    let inverted: Vec<PosePair> = pairs
        .iter()
        .map(|p| PosePair {
            base_from_flange: p.base_from_flange.inverse(),
            ..p.clone()
        })
        .collect();
    let alternative = closed_form_rms_deg(setup, &inverted);
    if alternative * 5.0 < given && alternative <= poor {
        return Err(SolveError::ConventionMismatch {
            setup,
            given_rms_deg: given,
            alternative_rms_deg: alternative,
        });
    }
    Ok(())
}

/// A flange farther than this from its robot base (median over the samples, m) is not a robot:
/// the largest industrial arms reach about 4 m; 20 m leaves room for a base frame on a rail.
pub const MAX_FLANGE_DISTANCE_M: f64 = 20.0;
/// A board farther than this from the camera (median, m) cannot be detected well enough to
/// calibrate with.
pub const MAX_TARGET_DISTANCE_M: f64 = 10.0;
/// Median flange distances from the base (m) of real arms, to name a unit mistake.
const PLAUSIBLE_FLANGE_M: (f64, f64) = (0.15, 2.5);
/// Median board distances from the camera (m) of real calibrations, to name a unit mistake.
const PLAUSIBLE_TARGET_M: (f64, f64) = (0.1, 3.0);
/// Robot/camera translation scale (either way) beyond which the units are called inconsistent.
/// Unit mistakes are factors of 25.4 (inches), 100 (cm) or 1000 (mm); a consistent cell fits
/// with a factor within a few percent of 1.
pub const MAX_UNIT_SCALE: f64 = 3.0;
/// The scale check runs only when the rotations alone fit this well (RMS, degrees): mislabelled
/// rotations are the convention check's business.
const UNIT_SCALE_ROTATION_FIT_DEG: f64 = 5.0;

fn median_norm(translations: impl Iterator<Item = Vector3<f64>>) -> f64 {
    let mut norms: Vec<f64> = translations.map(|t| t.norm()).collect();
    median(&mut norms)
}

/// The units (of millimetres, centimetres and inches) that bring `distance_m` into the
/// `plausible_m` range of a cell, as words ("millimetres", "centimetres or inches").
fn likely_units(distance_m: f64, plausible_m: (f64, f64)) -> String {
    let fitting: Vec<&str> = [
        ("millimetres", 1e-3),
        ("centimetres", 1e-2),
        ("inches", 0.0254),
    ]
    .into_iter()
    .filter(|(_, f)| (plausible_m.0..=plausible_m.1).contains(&(distance_m * f)))
    .map(|(name, _)| name)
    .collect();
    if fitting.is_empty() {
        "a unit other than metres".to_string()
    } else {
        fitting.join(" or ")
    }
}

/// The unit whose size in metres is `1/factor` (within 15 %): 1000 → millimetres, 100 →
/// centimetres, 39.37 → inches.
fn unit_of_factor(factor: f64) -> Option<&'static str> {
    [
        ("millimetres", 1000.0),
        ("centimetres", 100.0),
        ("inches", 1.0 / 0.0254),
    ]
    .into_iter()
    .find(|(_, f)| (factor / f - 1.0).abs() < 0.15)
    .map(|(name, _)| name)
}

/// How well the robot's translations fit the camera's when scaled: the `s` of
/// `t_A,i = R_X·R_B,i·t_Y + s·R_X·t_B,i + t_X` (the translation part of `A_i = X·B_i·Y` with the
/// robot translations scaled by `s`), fitted by linear least squares for rotations from the
/// rotations alone (Shah's closed form, unit-free).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct UnitScale {
    /// Factor on the robot translations that fits best: 1 when both are in metres, 0.001 when
    /// the robot's are in millimetres, 1000 when the camera's are.
    pub scale: f64,
    /// Standard error of `scale` (from the residual scatter).
    pub sigma: f64,
    /// Translation residual RMS with the fitted scale, m (of the camera's unit).
    pub scaled_rms_m: f64,
    /// Translation residual RMS with `scale` = 1, m.
    pub given_rms_m: f64,
    /// Rotation residual RMS of the rotations, degrees.
    pub rotation_rms_deg: f64,
}

/// Fits the robot/camera translation scale of `data` ([`UnitScale`]); `None` when the rotations
/// cannot be solved or the scale is not observable (robot translations all zero).
pub fn unit_scale(data: &AxbyData) -> Option<UnitScale> {
    let (qx, qy) = closed_form::rotations(data).ok()?;
    let rotation_only = Axby {
        x: Pose::from_parts(nalgebra::Translation3::identity(), qx),
        y: Pose::from_parts(nalgebra::Translation3::identity(), qy),
    };
    let rotation_rms_deg = residuals(data, &rotation_only, &NoiseModel::default()).rotation_rms_deg;
    let n = data.len();
    let rx = qx.to_rotation_matrix().into_inner();
    // Scale the s column to the size of the others so the least squares stays well conditioned
    // whatever unit the robot's translations are in.
    let spread = (data
        .b
        .iter()
        .map(|b| b.translation.vector.norm_squared())
        .sum::<f64>()
        / n as f64)
        .sqrt();
    if !(spread.is_finite() && spread > 0.0) {
        return None;
    }
    let mut m = DMatrix::<f64>::zeros(3 * n, 7);
    let mut r = DVector::<f64>::zeros(3 * n);
    let mut fixed = DVector::<f64>::zeros(3 * n);
    for (i, ((a, b), &w)) in data.a.iter().zip(&data.b).zip(&data.weights).enumerate() {
        let sw = w.sqrt();
        let rows = 3 * i;
        m.view_mut((rows, 0), (3, 3))
            .copy_from(&(Matrix3::identity() * sw));
        m.view_mut((rows, 3), (3, 3))
            .copy_from(&(rx * b.rotation.to_rotation_matrix().into_inner() * sw));
        m.view_mut((rows, 6), (3, 1))
            .copy_from(&(rx * b.translation.vector * (sw / spread)));
        r.rows_mut(rows, 3).copy_from(&(a.translation.vector * sw));
        fixed
            .rows_mut(rows, 3)
            .copy_from(&((a.translation.vector - rx * b.translation.vector) * sw));
    }
    // Least squares by the normal equations (7 columns of comparable size): the solution, the
    // residual sum of squares and the inverse normal matrix (for the standard error).
    let fit = |m: &DMatrix<f64>, r: &DVector<f64>| -> Option<(DVector<f64>, f64, DMatrix<f64>)> {
        let normal = m.transpose() * m;
        let inverse = normal.clone().try_inverse()?;
        let x = &inverse * (m.transpose() * r);
        let rss = (r - m * &x).norm_squared();
        Some((x, rss, inverse))
    };
    let (x, rss, inverse) = fit(&m, &r)?;
    // With the scale fixed at 1: only t_X and t_Y are free.
    let m_fixed = m.columns(0, 6).into_owned();
    let (_, rss_fixed, _) = fit(&m_fixed, &fixed)?;
    let dof = (3 * n).saturating_sub(7).max(1) as f64;
    let total_weight: f64 = data.weights.iter().sum();
    let scale = x[6] / spread;
    let sigma = (rss / dof * inverse[(6, 6)]).sqrt() / spread;
    Some(UnitScale {
        scale,
        sigma,
        scaled_rms_m: (rss / total_weight).sqrt(),
        given_rms_m: (rss_fixed / total_weight).sqrt(),
        rotation_rms_deg,
    })
}

/// Refuses translations inconsistent with metres ([`SolveError::ImplausibleUnits`], naming the
/// likely unit): a flange farther than [`MAX_FLANGE_DISTANCE_M`] from its base, a board farther
/// than [`MAX_TARGET_DISTANCE_M`] from the camera (medians), or robot and camera translations
/// that fit each other only when one side is scaled by more than [`MAX_UNIT_SCALE`] (a scale at
/// least 4 standard errors from 1, fitting at least 3 times better than the data as given).
pub fn check_units(setup: Setup, pairs: &[PosePair]) -> Result<(), SolveError> {
    if pairs.is_empty() {
        return Ok(());
    }
    let refuse = |problem| Err(SolveError::ImplausibleUnits { problem });
    let flange = median_norm(pairs.iter().map(|p| p.base_from_flange.translation.vector));
    if flange > MAX_FLANGE_DISTANCE_M {
        return refuse(UnitsProblem::FlangeTooFar {
            median_m: flange,
            samples: pairs.len(),
            limit_m: MAX_FLANGE_DISTANCE_M,
            unit: likely_units(flange, PLAUSIBLE_FLANGE_M),
        });
    }
    let target = median_norm(
        pairs
            .iter()
            .map(|p| p.camera_from_target.translation.vector),
    );
    if target > MAX_TARGET_DISTANCE_M {
        return refuse(UnitsProblem::TargetTooFar {
            median_m: target,
            samples: pairs.len(),
            limit_m: MAX_TARGET_DISTANCE_M,
            unit: likely_units(target, PLAUSIBLE_TARGET_M),
        });
    }
    if pairs.len() < MIN_SAMPLES {
        return Ok(());
    }
    let Some(fit) = unit_scale(&AxbyData::new(setup, pairs)) else {
        return Ok(());
    };
    let s = fit.scale;
    let inconsistent = fit.rotation_rms_deg <= UNIT_SCALE_ROTATION_FIT_DEG
        && s.is_finite()
        && s > 0.0
        && !(1.0 / MAX_UNIT_SCALE..=MAX_UNIT_SCALE).contains(&s)
        && fit.sigma * 4.0 < (s - 1.0).abs()
        && fit.scaled_rms_m * 3.0 < fit.given_rms_m;
    if !inconsistent {
        return Ok(());
    }
    let (side, factor, fix) = if s < 1.0 {
        ("robot", 1.0 / s, "give T_base_flange in metres")
    } else {
        (
            "camera",
            s,
            "give the board size (tag or square edge) in metres",
        )
    };
    let explanation = match unit_of_factor(factor) {
        Some(unit) => format!(
            "the {side} translations are {factor:.1} times too large: they look like {unit} — {fix}"
        ),
        None => format!(
            "the {side} translations are {factor:.1} times too large: they are in a unit other than metres — {fix}"
        ),
    };
    refuse(UnitsProblem::ScaleMismatch {
        scale: s,
        sigma: fit.sigma,
        scaled_rms_mm: fit.scaled_rms_m * 1e3,
        given_rms_mm: fit.given_rms_m * 1e3,
        explanation,
    })
}

/// A camera (eye-in-hand) or target (eye-to-hand) farther than this from the flange it is
/// mounted on (m) is implausible: brackets and tool plates are tens of centimetres.
pub const MAX_FLANGE_MOUNT_M: f64 = 0.5;
/// A cell-side unknown (`T_base_target`, `T_base_camera`) shorter than this (m) puts the
/// target or camera inside the robot's base: together with a long flange mount, the answer
/// looks swapped.
pub const MIN_CELL_MOUNT_M: f64 = 0.25;

/// The flange-side and cell-side unknowns of an answer, with their YAML keys.
fn flange_and_cell(calibration: &Calibration) -> ((&'static str, Pose), (&'static str, Pose)) {
    let (camera, target) = calibration.setup.unknown_names();
    match calibration.setup {
        Setup::EyeInHand => (
            (camera, calibration.camera_mount),
            (target, calibration.target_mount),
        ),
        Setup::EyeToHand => (
            (target, calibration.target_mount),
            (camera, calibration.camera_mount),
        ),
    }
}

/// Flags an answer no real cell has: the unknown on the flange (`T_flange_camera` or
/// `T_flange_target`) farther than [`MAX_FLANGE_MOUNT_M`] from the flange while the cell-side
/// one is shorter than [`MIN_CELL_MOUNT_M`]. That is what both inputs inverted give (robot
/// poses as `T_flange_base` and board poses as `T_target_camera`): such data fit exactly, with
/// the two unknowns swapped.
pub fn check_mounts(calibration: &Calibration) -> Option<Notice> {
    let ((flange_name, flange_mount), (cell_name, cell_mount)) = flange_and_cell(calibration);
    let flange_m = flange_mount.translation.vector.norm();
    let cell_m = cell_mount.translation.vector.norm();
    if flange_m <= MAX_FLANGE_MOUNT_M || cell_m >= MIN_CELL_MOUNT_M {
        return None;
    }
    Some(Notice::warning(
        NoticeKind::ImplausibleTransform,
        format!(
            "{flange_name} is {flange_m:.2} m from the flange (more than {MAX_FLANGE_MOUNT_M} m) while {cell_name} is only {cell_m:.2} m long: the two answers look swapped, which is what both inputs inverted give (robot poses given as T_flange_base and board poses as T_target_camera fit exactly as well) — check both conventions before using this answer"
        ),
    ))
}

/// How far (m) a nominal transform may be from the truth for [`check_against_nominal`]: a
/// drawing or a tape measure is good to a few centimetres.
pub const NOMINAL_TOLERANCE_M: f64 = 0.15;

/// Compares an answer with the cell's nominal (expected) transforms: when the answer is far
/// from them (either unknown more than `tolerance_m` away) but its two unknowns swapped (what
/// both inputs inverted give) are close to them, warns that both inputs look inverted.
pub fn check_against_nominal(
    calibration: &Calibration,
    nominal: &CellTransforms,
    tolerance_m: f64,
) -> Option<Notice> {
    if nominal.setup != calibration.setup {
        return None;
    }
    let (camera, target) = calibration.setup.unknown_names();
    let off_camera = translation_distance(&calibration.camera_mount, &nominal.camera_mount);
    let off_target = translation_distance(&calibration.target_mount, &nominal.target_mount);
    if off_camera.max(off_target) <= tolerance_m {
        return None;
    }
    // Both inputs inverted: the reported camera mount is the true target mount and vice versa.
    let swapped_camera = translation_distance(&calibration.target_mount, &nominal.camera_mount);
    let swapped_target = translation_distance(&calibration.camera_mount, &nominal.target_mount);
    if swapped_camera.max(swapped_target) > tolerance_m {
        return None;
    }
    Some(Notice::warning(
        NoticeKind::ImplausibleTransform,
        format!(
            "the answer is {:.0} mm ({camera}) and {:.0} mm ({target}) from the nominal transforms, but within {:.0} mm of them with the two answers swapped: both inputs look inverted (robot poses given as T_flange_base and board poses as T_target_camera) — fix both conventions and solve again",
            off_camera * 1e3,
            off_target * 1e3,
            swapped_camera.max(swapped_target) * 1e3
        ),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion};

    #[test]
    fn unit_mistakes_are_named_by_factor_and_by_size() {
        assert_eq!(unit_of_factor(1000.0), Some("millimetres"));
        assert_eq!(unit_of_factor(100.4), Some("centimetres"));
        assert_eq!(unit_of_factor(39.4), Some("inches"));
        assert_eq!(unit_of_factor(10.0), None);
        assert_eq!(likely_units(500.0, PLAUSIBLE_FLANGE_M), "millimetres");
        assert_eq!(
            likely_units(36.2, PLAUSIBLE_FLANGE_M),
            "centimetres or inches"
        );
        assert_eq!(
            likely_units(1e7, PLAUSIBLE_FLANGE_M),
            "a unit other than metres"
        );
    }

    #[test]
    fn outlier_flags_need_both_robust_and_absolute_excess() {
        let mut values = vec![1.0, 1.2, 0.8, 1.1, 0.9, 1.05, 0.95];
        assert!(flag_outliers(&values, 5.0, 4.74).is_empty());
        values.push(30.0);
        assert_eq!(flag_outliers(&values, 5.0, 4.74), vec![7]);
        // Noise-free data: MAD is zero but nothing passes the floor.
        assert!(flag_outliers(&[1e-12, 2e-12, 3e-10], 5.0, 4.74).is_empty());
    }

    #[test]
    fn coaxial_rotations_are_refused_with_axes_to_add() {
        let axis = Vector3::new(0.0, 0.0, 1.0);
        let poses: Vec<Pose> = (0..6)
            .map(|k| {
                Pose::from_parts(
                    Translation3::new(0.1 * k as f64, 0.0, 0.5),
                    UnitQuaternion::from_scaled_axis(axis * (0.3 * k as f64)),
                )
            })
            .collect();
        match check_rotation_diversity(&poses) {
            Err(SolveError::Coaxial {
                axis: found,
                add_about,
                ..
            }) => {
                assert!((Vector3::from(found).dot(&axis).abs() - 1.0).abs() < 1e-9);
                for a in add_about {
                    assert!(Vector3::from(a).dot(&axis).abs() < 1e-9);
                }
            }
            other => panic!("expected Coaxial, got {other:?}"),
        }
        let translations_only: Vec<Pose> = (0..5)
            .map(|k| {
                Pose::from_parts(
                    Translation3::new(0.1 * k as f64, 0.0, 0.5),
                    UnitQuaternion::identity(),
                )
            })
            .collect();
        let e = check_rotation_diversity(&translations_only).unwrap_err();
        assert!(matches!(e, SolveError::TooLittleRotation { .. }), "{e}");
        assert!(e.to_string().contains("span only 0.00°"), "{e}");
        assert!(matches!(
            check_rotation_diversity(&poses[..2]),
            Err(SolveError::TooFewSamples { found: 2, .. })
        ));
    }
}
