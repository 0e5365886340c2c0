//! The evidence a verdict is made from: the held-out (leave-one-out) errors ([`held_out`]), the
//! health notices shared by terminal, result file and report ([`coverage_notices`],
//! [`residual_notice`]), and the one-call entry points around a solve ([`assess_solved`],
//! [`assess_result`]) that gather it and hand it to [`assess`].
//!
//! Depends on `solve` (the solver for the held-out folds, its diagnostics), `notice`, the ground
//! floor (`setup`, `geometry`) and the types of its parent [`verdict`](super).

use crate::{
    self as solve, diagnostics, rotation_diversity, Calibration, NoiseModel, SolveError,
    SolveOptions,
};
use handeye_core::geometry::{weighted_rms, Pose};
use handeye_core::notice::{Notice, NoticeKind, Severity};
use handeye_core::setup::{PosePair, Setup};

use super::rules::{assess, Evidence};
use super::{
    Accuracy, HeldOut, Verdict, GOOD_OFF_AXIS_DEG, GOOD_POSES, MAX_HELD_OUT, MIN_HELD_OUT_SAMPLES,
    RESIDUAL_FACTOR,
};
use crate::cell_model::CellModelSummary;

/// Median camera-to-target distance of `pairs`, mm: where a held-out error is measured.
pub fn working_distance_mm(pairs: &[PosePair]) -> f64 {
    let distances: Vec<f64> = pairs
        .iter()
        .map(|p| p.camera_from_target.translation.vector.norm() * 1e3)
        .collect();
    diagnostics::median(&distances)
}

/// Every sample's `T_base_flange` as a fold sees it, when a fit to every sample corrects the
/// robot poses (the arm's own model): `left_out` → the flange poses corrected by the same fit
/// made without that sample, so its prediction owes nothing to its own measurement.
pub type FoldFlanges<'a> = &'a dyn Fn(usize) -> Result<Vec<Pose>, String>;

/// Held-out (leave-one-out) errors: each sample (at most [`MAX_HELD_OUT`], evenly spaced) is
/// predicted by a solve of all the others with `options` (covariance and convention checks off
/// in the folds, each started from `full`, the answer of all the samples: see
/// [`solve::predict_left_out`]), and the prediction compared with its measured
/// `T_camera_target`. Samples `full` flags as outliers are held out like the others but left
/// out of the summary. Fails (with the reason) for fewer than [`MIN_HELD_OUT_SAMPLES`] samples
/// or when a fold cannot be solved.
pub fn held_out(
    setup: Setup,
    pairs: &[PosePair],
    options: &SolveOptions,
    full: &Calibration,
) -> Result<HeldOut, String> {
    held_out_refitting(setup, pairs, options, full, None)
}

/// [`held_out`] where each fold's robot poses come from `refit` (fitted without its held-out
/// sample) instead of `pairs`' own.
pub fn held_out_refitting(
    setup: Setup,
    pairs: &[PosePair],
    options: &SolveOptions,
    full: &Calibration,
    refit: Option<FoldFlanges<'_>>,
) -> Result<HeldOut, String> {
    let n = pairs.len();
    if n < MIN_HELD_OUT_SAMPLES {
        return Err(format!(
            "only {n} samples: a held-out check needs at least {MIN_HELD_OUT_SAMPLES}"
        ));
    }
    let folds = handeye_core::evenly_spaced(n, MAX_HELD_OUT);
    let predictions =
        predict_folds(setup, pairs, options, full, refit, folds).map_err(|f| match &f {
            FoldFailure::Solve { source, .. } => {
                format!("{f} ({source}): the answer hangs on that one pose")
            }
            FoldFailure::Refit { .. } => f.to_string(),
        })?;
    // A held-out error is the calibration's error plus the left-out view's own: a view noisier
    // than the typical one counts at its precision ([`solve::view_weighted`]).
    let weighted = options.weighted(pairs);
    let errors: Vec<(f64, f64, f64)> = predictions
        .iter()
        .filter(|(left_out, _)| !full.outliers.contains(left_out))
        .map(|(left_out, predicted)| {
            let measured = &pairs[*left_out].camera_from_target;
            (
                (predicted.translation.vector - measured.translation.vector).norm() * 1e3,
                predicted.rotation.angle_to(&measured.rotation).to_degrees(),
                weighted[*left_out].weight,
            )
        })
        .collect();
    if errors.is_empty() {
        return Err("every held-out sample is flagged as an outlier".into());
    }
    Ok(HeldOut {
        poses: errors.len(),
        translation_rms_mm: weighted_rms(errors.iter().map(|e| (e.0, e.2))),
        rotation_rms_deg: weighted_rms(errors.iter().map(|e| (e.1, e.2))),
        working_distance_mm: working_distance_mm(pairs),
    })
}

/// Why a held-out fold gave no prediction.
#[derive(Debug, thiserror::Error)]
pub enum FoldFailure {
    /// The arm's model could not be refitted without the sample.
    #[error("refitting the arm's model without sample {left_out} failed ({why})")]
    Refit {
        /// The held-out sample.
        left_out: usize,
        /// Why.
        why: String,
    },
    /// The solve of the other samples failed.
    #[error("solving without sample {left_out} failed")]
    Solve {
        /// The held-out sample.
        left_out: usize,
        /// Why.
        #[source]
        source: SolveError,
    },
}

/// Each sample of `folds` predicted by a solve of all the others with `options`, started from
/// `full` ([`solve::predict_left_out`]), the robot poses of each fold from `refit` when given
/// (fitted without its sample): `(sample, predicted T_camera_target)` in `folds`' order. The one
/// leave-one-out loop: the verdict's held-out check ([`held_out`]) and `handeye verify`'s
/// cross-validation both run it.
pub fn predict_folds(
    setup: Setup,
    pairs: &[PosePair],
    options: &SolveOptions,
    full: &Calibration,
    refit: Option<FoldFlanges<'_>>,
    folds: impl IntoIterator<Item = usize>,
) -> Result<Vec<(usize, Pose)>, FoldFailure> {
    let n = pairs.len();
    folds
        .into_iter()
        .map(|left_out| {
            let fold: std::borrow::Cow<'_, [PosePair]> = match refit {
                None => pairs.into(),
                Some(refit) => {
                    let flanges =
                        refit(left_out).map_err(|why| FoldFailure::Refit { left_out, why })?;
                    if flanges.len() != n {
                        return Err(FoldFailure::Refit {
                            left_out,
                            why: format!("{} robot poses for {n} samples", flanges.len()),
                        });
                    }
                    pairs
                        .iter()
                        .zip(flanges)
                        .map(|(pair, base_from_flange)| PosePair {
                            base_from_flange,
                            ..pair.clone()
                        })
                        .collect::<Vec<_>>()
                        .into()
                }
            };
            let predicted = solve::predict_left_out(setup, &fold, options, left_out, full)
                .map_err(|source| FoldFailure::Solve { left_out, source })?;
            Ok((left_out, predicted))
        })
        .collect()
}

/// Notices about the poses themselves: fewer than [`GOOD_POSES`], or rotations less than
/// [`GOOD_OFF_AXIS_DEG`] off their dominant axis (warnings; the report shows them, the verdict
/// turns them into CHECK).
pub fn coverage_notices(pairs: &[PosePair]) -> Vec<Notice> {
    let mut out = Vec::new();
    let n = pairs.len();
    if n < GOOD_POSES {
        out.push(Notice::warning(NoticeKind::FewPoses, format!(
            "only {n} poses: below {GOOD_POSES} the noise level cannot be estimated from the residuals (the uncertainty assumes the configured noise) and a single bad pose can pull the answer; record 12–20"
        )));
    }
    let robot: Vec<Pose> = pairs.iter().map(|p| p.base_from_flange).collect();
    let diversity = rotation_diversity(&robot);
    if diversity.off_axis_deg < GOOD_OFF_AXIS_DEG {
        out.push(Notice::warning(NoticeKind::PoorRotationSpread, format!(
            "poor rotation spread: the flange rotations are mostly about one axis (only {:.1}° off it, {GOOD_OFF_AXIS_DEG:.0}° wanted); add poses tilted 20–40° about two other flange axes",
            diversity.off_axis_deg
        )));
    }
    out
}

/// The residual health of one answer, judged one way everywhere: an `error` notice when the data
/// fits far better with inverted robot poses (the solver's own convention check,
/// `solve::diagnostics::check_convention`, thresholds relative to the noise model), else a
/// warning when the residual RMS (each sample at its weight: `pairs` as the solve weighed them)
/// is more than [`RESIDUAL_FACTOR`] × what the noise model expects; `None` when the residuals
/// are as expected.
pub fn residual_notice(
    calibration: &Calibration,
    pairs: &[PosePair],
    noise: &NoiseModel,
) -> Option<Notice> {
    let r = &calibration.residuals;
    // Each view at its weight: a far view's larger residual is its own noise, not more than the
    // model expects (the model's sigmas are the typical view's).
    let rms_at_weights = |values: &[f64]| {
        weighted_rms(
            values
                .iter()
                .zip(pairs)
                .enumerate()
                .filter(|(i, (v, _))| !calibration.dropped.contains(i) && v.is_finite())
                .map(|(_, (v, p))| (*v, p.weight)),
        )
    };
    let (rotation_rms_deg, translation_rms_mm) = (
        rms_at_weights(&r.rotation_deg),
        rms_at_weights(&r.translation_mm),
    );
    let used: Vec<PosePair> = pairs
        .iter()
        .enumerate()
        .filter(|(i, _)| !calibration.dropped.contains(i))
        .map(|(_, p)| p.clone())
        .collect();
    if let Err(e @ SolveError::ConventionMismatch { .. }) =
        diagnostics::check_convention(calibration.setup, &used, Some(r.rotation_rms_deg), noise)
    {
        return Some(Notice::new(
            Severity::Error,
            NoticeKind::LikelyConventionError,
            e.to_string(),
        ));
    }
    // Norms of 3-axis noise: √3 σ.
    let expected_rot_deg = noise.rotation_sigma_rad.to_degrees() * 3f64.sqrt();
    let expected_t_mm = noise.translation_sigma_m * 1e3 * 3f64.sqrt();
    if rotation_rms_deg > RESIDUAL_FACTOR * expected_rot_deg
        || translation_rms_mm > RESIDUAL_FACTOR * expected_t_mm
    {
        return Some(Notice::warning(NoticeKind::LargeResiduals, format!(
            "residuals (RMS {rotation_rms_deg:.3}°, {translation_rms_mm:.2} mm) are more than {RESIDUAL_FACTOR}× what the noise model expects ({expected_rot_deg:.3}°, {expected_t_mm:.2} mm): the robot poses and frames may not be synchronised, the board may be loose, or the noise model is optimistic",
        )));
    }
    None
}

/// The one call after a solve: held-out errors with the same options, then [`assess`].
pub fn assess_solved(
    calibration: &Calibration,
    pairs: &[PosePair],
    options: &SolveOptions,
    accuracy: Accuracy,
) -> Verdict {
    assess_modelled(calibration, pairs, options, accuracy, None, None)
}

/// [`assess_solved`] with the cell model's choice (when the corners were fitted): `pairs` are
/// then the board poses with the files as the chosen explanation corrects them; with `refit`
/// when the robot poses were corrected by a fit to every sample (the arm's own model), each
/// held-out fold refits it without its sample ([`held_out_refitting`]).
pub fn assess_modelled(
    calibration: &Calibration,
    pairs: &[PosePair],
    options: &SolveOptions,
    accuracy: Accuracy,
    cell_model: Option<&CellModelSummary>,
    refit: Option<FoldFlanges<'_>>,
) -> Verdict {
    let held = held_out_refitting(calibration.setup, pairs, options, calibration, refit);
    assess(&Evidence {
        calibration,
        pairs: &options.weighted(pairs),
        noise: &options.noise,
        held_out: &held,
        accuracy,
        board_scale: crate::board_scale::fit_board_scale(calibration, pairs, options),
        cell_model,
    })
}

/// The one call around a solve: [`assess_solved`] on its answer, or [`Verdict::refused`] when it
/// was refused.
pub fn assess_result(
    result: Result<&Calibration, &SolveError>,
    pairs: &[PosePair],
    options: &SolveOptions,
    accuracy: Accuracy,
) -> Verdict {
    match result {
        Ok(calibration) => assess_solved(calibration, pairs, options, accuracy),
        Err(error) => Verdict::refused(error, pairs.len(), accuracy),
    }
}
