//! Diagnostics returned with every answer, and the checks that refuse unsolvable input.
//!
//! * residuals of each sample's measured `T_camera_target` against the prediction (deg, mm,
//!   and whitened by the noise model), with RMS and max;
//! * outlier flags by robust statistics (median and MAD of the whitened residual norms);
//! * observability: at least 3 samples whose relative robot rotations are not all about one
//!   axis ([`check_rotation_diversity`], also for the plan checker: robot poses only);
//! * convention: when the fit is poor, whether inverted robot poses (equivalently the other
//!   setup), inverted camera poses, or both, fit far better;
//! * units ([`check_units`], before solving) and plausibility of the answer ([`check_mounts`],
//!   [`check_against_nominal`]): these live in [`plausibility`](super::plausibility) and are
//!   re-exported here, so `solve::diagnostics::…` paths keep working.
//!
//! Depends on `geometry`, `setup` and the solver types only (and on `plausibility` for the
//! re-exports); units rad/m inside, deg/mm in reports.

use nalgebra::{Matrix3, SymmetricEigen, Vector3};

use super::{closed_form, Axby, AxbyData, NoiseModel, Residuals, SolveError};
use handeye_core::geometry::{rms, rotvec, Pose};
use handeye_core::setup::{PosePair, Setup};

pub use super::plausibility::{
    check_against_nominal, check_far_from_nominal, check_mounts, check_units, unit_scale,
    UnitScale, FAR_FROM_NOMINAL_DEG, FAR_FROM_NOMINAL_M, MAX_FLANGE_DISTANCE_M, MAX_FLANGE_MOUNT_M,
    MAX_TARGET_DISTANCE_M, MAX_UNIT_SCALE, MIN_CELL_MOUNT_M, NOMINAL_TOLERANCE_M,
};

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

/// Residuals of every sample of `data` against a solution.
pub fn residuals(data: &AxbyData, solution: &Axby, noise: &NoiseModel) -> Residuals {
    let mut rotation_deg = Vec::with_capacity(data.len());
    let mut translation_mm = Vec::with_capacity(data.len());
    let mut normalised = Vec::with_capacity(data.len());
    for ((a, b), weight) in data.a.iter().zip(&data.b).zip(&data.weights) {
        let predicted = solution.x * b * solution.y;
        let rotation = predicted.rotation.angle_to(&a.rotation);
        let translation = (predicted.translation.vector - a.translation.vector).norm();
        rotation_deg.push(rotation.to_degrees());
        translation_mm.push(translation * 1e3);
        // A sample of weight w has the noise model's variance over w.
        normalised.push(
            weight.sqrt()
                * ((rotation / noise.rotation_sigma_rad).powi(2)
                    + (translation / noise.translation_sigma_m).powi(2))
                .sqrt(),
        );
    }
    Residuals {
        rotation_rms_deg: rms(rotation_deg.iter().copied()),
        rotation_max_deg: rotation_deg.iter().copied().fold(0.0, f64::max),
        translation_rms_mm: rms(translation_mm.iter().copied()),
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

/// Median of a copy of `values` (0 when there are none).
pub fn median(values: &[f64]) -> f64 {
    let mut v = values.to_vec();
    v.sort_by(f64::total_cmp);
    match v.len() {
        0 => 0.0,
        n if n % 2 == 1 => v[n / 2],
        n => 0.5 * (v[n / 2 - 1] + v[n / 2]),
    }
}

/// The outlier threshold of [`flag_outliers`], sigmas:
/// `max(median + mad_factor · 1.4826 · MAD, floor_sigma)`.
pub fn outlier_threshold(normalised: &[f64], mad_factor: f64, floor_sigma: f64) -> f64 {
    let med = median(normalised);
    let deviations: Vec<f64> = normalised.iter().map(|v| (v - med).abs()).collect();
    let mad = median(&deviations);
    (med + mad_factor * 1.4826 * mad).max(floor_sigma)
}

/// Indices of samples whose whitened residual norm exceeds both
/// `median + mad_factor · 1.4826 · MAD` and `floor_sigma`.
pub fn flag_outliers(normalised: &[f64], mad_factor: f64, floor_sigma: f64) -> Vec<usize> {
    let threshold = outlier_threshold(normalised, mad_factor, floor_sigma);
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
#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion};

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
