//! Plausibility of the numbers, before and after solving.
//!
//! * units ([`check_units`], before solving): translations inconsistent with metres — a flange
//!   tens of metres from its base, a board tens of metres from the camera, or robot and camera
//!   translations that only fit each other after scaling one of them ([`unit_scale`]);
//! * plausibility of the answer ([`check_mounts`], [`check_against_nominal`]): a camera (or
//!   target) on the flange that is far from it, with the other unknown as short as a flange
//!   offset — the signature of both inputs inverted, which fits exactly as well as the truth.
//!
//! Every public item is re-exported from [`diagnostics`](super::diagnostics), so
//! `solve::diagnostics::check_units` and the like keep working. Depends on `geometry`, `notice`,
//! `setup`, the solver types, the closed form (rotations for the scale fit) and the residuals of
//! [`diagnostics`](super::diagnostics); units m inside, mm in messages.

use nalgebra::{DMatrix, DVector, Matrix3, Vector3};

use super::diagnostics::{median, residuals, MIN_SAMPLES};
use super::{closed_form, Axby, AxbyData, Calibration, NoiseModel, SolveError, UnitsProblem};
use handeye_core::geometry::{translation_distance, Pose};
use handeye_core::notice::{Notice, NoticeKind};
use handeye_core::setup::{CellTransforms, PosePair, Setup};

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
    let norms: Vec<f64> = translations.map(|t| t.norm()).collect();
    median(&norms)
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

/// An answer farther than this (m) from the config's nominal transform is flagged by
/// [`check_far_from_nominal`]: a drawing or a tape measure is good to a few centimetres.
pub const FAR_FROM_NOMINAL_M: f64 = 0.05;
/// An answer rotated more than this (degrees) from the config's nominal transform is flagged by
/// [`check_far_from_nominal`].
pub const FAR_FROM_NOMINAL_DEG: f64 = 20.0;

fn describe_pose(pose: &Pose) -> String {
    let t = pose.translation.vector;
    let r = handeye_core::geometry::rotvec(&pose.rotation);
    format!(
        "translation [{:.3}, {:.3}, {:.3}] m, rotation_vector [{:.3}, {:.3}, {:.3}]",
        t.x, t.y, t.z, r.x, r.y, r.z
    )
}

/// Flags an answer far from the cell's nominal (expected) transforms: either unknown more than
/// [`FAR_FROM_NOMINAL_M`] or [`FAR_FROM_NOMINAL_DEG`] from its nominal, with both values. Either
/// the nominal is wrong (then it wants updating) or the cell is not as drawn: a camera mounted
/// elsewhere, a board moved, poses in another convention.
pub fn check_far_from_nominal(
    calibration: &Calibration,
    nominal: &CellTransforms,
) -> Option<Notice> {
    if nominal.setup != calibration.setup {
        return None;
    }
    let (camera, target) = calibration.setup.unknown_names();
    let far: Vec<String> = [
        (camera, &calibration.camera_mount, &nominal.camera_mount),
        (target, &calibration.target_mount, &nominal.target_mount),
    ]
    .into_iter()
    .filter_map(|(name, answer, expected)| {
        let off_m = translation_distance(answer, expected);
        let off_deg = answer.rotation.angle_to(&expected.rotation).to_degrees();
        (off_m > FAR_FROM_NOMINAL_M || off_deg > FAR_FROM_NOMINAL_DEG).then(|| {
            format!(
                "{name} is {:.0} mm and {off_deg:.1}° from its nominal: solved {}, nominal {}",
                off_m * 1e3,
                describe_pose(answer),
                describe_pose(expected)
            )
        })
    })
    .collect();
    if far.is_empty() {
        return None;
    }
    Some(Notice::warning(
        NoticeKind::FarFromNominal,
        format!(
            "the answer is far from the config's nominal transforms (more than {:.0} mm or {FAR_FROM_NOMINAL_DEG:.0}°): {}",
            FAR_FROM_NOMINAL_M * 1e3,
            far.join("; ")
        ),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

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
}
