//! The solver: from robot/camera pose pairs to the two unknown rigid transforms of a cell.
//!
//! Owns the public solver API ([`solve`], [`Calibration`], [`SolveError`]) and the mapping of
//! both setups onto the one `A = X·B·Y` problem of Hirsh, DeSouza and Kak:
//!
//! * eye-in-hand: `A = T_camera_target`, `X = T_camera_flange = inv(T_flange_camera)`,
//!   `B = T_flange_base = inv(T_base_flange)`, `Y = T_base_target`;
//! * eye-to-hand: `A = T_camera_target`, `X = T_camera_base = inv(T_base_camera)`,
//!   `B = T_base_flange`, `Y = T_flange_target`.
//!
//! The request lives in [`options`], the answer in [`calibration`], the failures in [`error`];
//! this file maps both setups onto `A = X·B·Y` and runs the pipeline.
//!
//! Every method ([`iterative`], [`closed_form`], [`refine`]) works on [`AxbyData`] only, so the
//! two setups share one code path. Around the method: the board-pose noise estimated from the
//! residuals ([`noise`]) and, by default, a robust consensus start with outliers left out of the
//! final fit (`robust`). Units are metres and radians inside; residuals and
//! uncertainties are reported in mm and degrees for people. Pure functions: no I/O, no clocks;
//! depends only on the ground floor (`handeye-core`: `geometry`, `setup`, `camera_model`) and
//! nalgebra: the crate has no other dependency of ours, so the compiler holds it to that.

mod arrow;
pub mod board_scale;
pub mod calibration;
pub mod cameras;
pub mod cell_model;
pub mod closed_form;
pub mod compare;
pub mod diagnostics;
pub mod error;
pub mod intrinsics;
pub mod iterative;
pub mod kinematics;
mod lm;
pub mod noise;
pub mod options;
pub mod plausibility;
pub mod refine;
pub mod reprojection;
mod robust;
pub mod verdict;
mod view_weights;

use handeye_core::geometry::Pose;
use handeye_core::notice::{Notice, NoticeKind};
use handeye_core::setup::{self, PosePair, Setup};

pub use calibration::{
    Calibration, NoiseSource, Phase, PoseNoise, PoseSigma, Residuals, SolverReport, TraceStep,
    Uncertainty,
};
pub use diagnostics::{check_rotation_diversity, rotation_diversity, RotationDiversity};
pub use error::{SampleProblem, SolveError, UnitsProblem};
pub use iterative::{IterativeOptions, IterativeOutcome};
use options::require_positive;
pub use options::{EstimateNoise, Method, NoiseModel, RobustLoss, SolveOptions, SolverChoice};
pub use reprojection::{
    refine_reprojection, reprojection_errors, ArmOffsetsFree, Corner, Frame, RefinedOffset,
    ReprojectionCalibration, ReprojectionErrors, ReprojectionOptions, RobotPrior,
};
pub use view_weights::{relative_weight, view_weighted};

/// The `A = X·B·Y` form of a data set, shared by both setups.
#[derive(Debug, Clone, PartialEq)]
pub struct AxbyData {
    /// `A_i = T_camera_target`.
    pub a: Vec<Pose>,
    /// `B_i`: `inv(T_base_flange)` (eye-in-hand) or `T_base_flange` (eye-to-hand).
    pub b: Vec<Pose>,
    /// Sample weights (> 0).
    pub weights: Vec<f64>,
}

impl AxbyData {
    /// Maps pose pairs of a setup onto `A = X·B·Y`.
    pub fn new(setup: Setup, pairs: &[PosePair]) -> Self {
        AxbyData {
            a: pairs.iter().map(|p| p.camera_from_target).collect(),
            b: pairs
                .iter()
                .map(|p| setup.chain_b(&p.base_from_flange))
                .collect(),
            weights: pairs.iter().map(|p| p.weight).collect(),
        }
    }

    /// Number of samples.
    pub fn len(&self) -> usize {
        self.a.len()
    }

    /// True when there are no samples.
    pub fn is_empty(&self) -> bool {
        self.a.is_empty()
    }
}

/// The two unknowns of `A = X·B·Y`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Axby {
    /// `X`: `T_camera_flange` or `T_camera_base`.
    pub x: Pose,
    /// `Y`: `T_base_target` or `T_flange_target`.
    pub y: Pose,
}

impl Axby {
    /// The calibration unknowns (camera mount, target mount) of a setup.
    pub fn to_mounts(&self) -> (Pose, Pose) {
        (self.x.inverse(), self.y)
    }

    /// The `A = X·B·Y` unknowns from (camera mount, target mount).
    pub fn from_mounts(camera_mount: &Pose, target_mount: &Pose) -> Self {
        Axby {
            x: camera_mount.inverse(),
            y: *target_mount,
        }
    }
}

fn pose_is_finite(p: &Pose) -> bool {
    p.translation.vector.iter().all(|v| v.is_finite())
        && p.rotation.coords.iter().all(|v| v.is_finite())
}

fn validate(pairs: &[PosePair], options: &SolveOptions) -> Result<(), SolveError> {
    for (index, p) in pairs.iter().enumerate() {
        let bad = |problem| SolveError::InvalidSample {
            index,
            id: p.id.clone(),
            problem,
        };
        if !pose_is_finite(&p.base_from_flange) {
            return Err(bad(SampleProblem::NotFinite("T_base_flange")));
        }
        if !pose_is_finite(&p.camera_from_target) {
            return Err(bad(SampleProblem::NotFinite("T_camera_target")));
        }
        if !(p.weight.is_finite() && p.weight > 0.0) {
            return Err(bad(SampleProblem::BadWeight(p.weight)));
        }
    }
    require_positive("noise.rotation_sigma_rad", options.noise.rotation_sigma_rad)?;
    require_positive(
        "noise.translation_sigma_m",
        options.noise.translation_sigma_m,
    )?;
    options.robust.validate("robust.huber", "robust.cauchy")?;
    require_positive(
        "iterative.rotation_tolerance_rad",
        options.iterative.rotation_tolerance_rad,
    )?;
    require_positive(
        "iterative.translation_tolerance_m",
        options.iterative.translation_tolerance_m,
    )?;
    Ok(())
}

/// Solves for both unknowns of a cell from its pose pairs.
///
/// Checks the input (finite values, weights, translations consistent with metres, at least 3
/// samples with rotations about two axes), then, robust by default
/// ([`SolveOptions::drop_outliers`]): a consensus start over small subsets, the chosen method on
/// the samples consistent with it, every sample whose residual is an outlier against that fit
/// left out (and named) and the fit repeated until the set is stable; a clean data set keeps
/// every sample. The board-pose noise is estimated from the residuals along the way
/// ([`SolveOptions::estimate_noise`]). Without `drop_outliers`: one fit of every sample with
/// outliers flagged. Checks the convention when the fit is poor, and flags an answer whose
/// unknowns look swapped ([`diagnostics::check_mounts`]). `check_conventions: false` also turns
/// off the units and swapped-answer checks.
pub fn solve(
    setup: Setup,
    pairs: &[PosePair],
    options: &SolveOptions,
) -> Result<Calibration, SolveError> {
    validate(pairs, options)?;
    let pairs = &*options.weighted(pairs);
    if options.check_conventions {
        // Units before anything else: a solve of millimetres as metres "succeeds" with advice
        // about pose variety.
        diagnostics::check_units(setup, pairs)?;
    }
    let mut calibration = if options.drop_outliers {
        robust::solve_robust(setup, pairs, options)?
    } else {
        let all: Vec<usize> = (0..pairs.len()).collect();
        solve_subset(setup, pairs, &all, options)?
    };
    if options.check_conventions {
        calibration
            .notices
            .extend(diagnostics::check_mounts(&calibration));
    }
    Ok(calibration)
}

/// Coarsest tolerance (rad, and m) of the iterative start of the refined method.
const REFINE_START_TOLERANCE: f64 = 1e-8;

type Solved = (Axby, SolverReport, Option<Uncertainty>, PoseNoise);

fn solve_method(data: &AxbyData, options: &SolveOptions) -> Result<Solved, SolveError> {
    Ok(match options.method {
        closed @ (Method::ClosedForm
        | Method::Tsai
        | Method::Park
        | Method::Horaud
        | Method::Andreff
        | Method::Daniilidis
        | Method::Li) => {
            let s = closed_form::solve(closed, data)?;
            let report = SolverReport {
                method: closed,
                iterations: 0,
                converged: true,
                restarts: 0,
                trace: Vec::new(),
            };
            (s, report, None, noise::estimate_at(data, &s, options))
        }
        Method::Iterative => {
            let out = iterative::solve_axby_with_restarts(data, &options.iterative)?;
            let report = out.report(Method::Iterative);
            let noise = noise::estimate_at(data, &out.solution, options);
            (out.solution, report, None, noise)
        }
        Method::Refined => {
            // LM polishes the start, so the alternation need not run to machine precision, and
            // it starts from the closed form (computed anyway as its cross-check): the LM
            // optimum is the same, reached in a fraction of the alternation's iterations.
            let start_options = IterativeOptions {
                warm_start: true,
                rotation_tolerance_rad: options
                    .iterative
                    .rotation_tolerance_rad
                    .max(REFINE_START_TOLERANCE),
                translation_tolerance_m: options
                    .iterative
                    .translation_tolerance_m
                    .max(REFINE_START_TOLERANCE),
                ..options.iterative.clone()
            };
            let start = iterative::solve_axby_with_restarts(data, &start_options)?;
            let mut report = start.report(Method::Refined);
            let refined = refine::refine(data, &start.solution, options)?;
            report.iterations += refined.evaluations;
            report.converged &= refined.converged;
            report
                .trace
                .extend(refined.trace.iter().map(|&c| TraceStep {
                    phase: Phase::Refine,
                    update: c,
                }));
            let uncertainty = refined.covariance.map(|cov| {
                refine::mount_uncertainty(&refined.solution, &cov, refined.variance_factor)
            });
            (refined.solution, report, uncertainty, refined.noise)
        }
    })
}

/// The chosen method on the samples `keep` of `pairs`, with residuals (indexed like `pairs`),
/// outlier flags among them and the notices.
fn solve_subset(
    setup: Setup,
    pairs: &[PosePair],
    keep: &[usize],
    options: &SolveOptions,
) -> Result<Calibration, SolveError> {
    let used: Vec<PosePair> = keep.iter().map(|&i| pairs[i].clone()).collect();
    let robot: Vec<Pose> = used.iter().map(|p| p.base_from_flange).collect();
    check_rotation_diversity(&robot)?;
    let data = AxbyData::new(setup, &used);

    let mut notices = Vec::new();
    let solved = solve_method(&data, options);
    let (solution, report, uncertainty, noise) = match solved {
        Ok(s) => s,
        Err(error) => {
            // A solver that cannot even converge on mislabelled data: say what is mislabelled.
            if options.check_conventions {
                diagnostics::check_convention(setup, &used, None, &options.noise)?;
            }
            return Err(error);
        }
    };

    let (camera_mount, target_mount) = solution.to_mounts();
    // Normalised by the noise the fit used; the convention check keeps the expected noise (an
    // estimate would follow mislabelled data up).
    let sub_residuals = diagnostics::residuals(&data, &solution, &noise.model());
    if options.check_conventions {
        diagnostics::check_convention(
            setup,
            &used,
            Some(sub_residuals.rotation_rms_deg),
            &options.noise,
        )?;
    }
    let residuals = diagnostics::scatter_residuals(&sub_residuals, keep, pairs.len());
    let sub_outliers = diagnostics::flag_outliers(
        &sub_residuals.normalised,
        options.outlier_mad_factor,
        options.outlier_floor_sigma,
    );
    let outliers: Vec<usize> = sub_outliers.iter().map(|&i| keep[i]).collect();

    if !outliers.is_empty() {
        let described: Vec<String> = outliers
            .iter()
            .map(|&i| match &pairs[i].id {
                Some(id) => format!("{i} ({id})"),
                None => i.to_string(),
            })
            .collect();
        notices.push(Notice::warning(NoticeKind::Outliers, format!(
            "{} sample(s) look like outliers: {} (residuals far above the rest; check detection and robot pose of those samples)",
            outliers.len(),
            described.join(", ")
        )));
    }
    notices.push(noise_notice(&noise, options, used.len()));
    if let Some(u) = &uncertainty {
        let (camera_name, target_name) = setup.unknown_names();
        for (name, sigma) in [
            (camera_name, &u.camera_mount),
            (target_name, &u.target_mount),
        ] {
            if sigma.rotation_deg > options.warn_rotation_sigma_deg
                || sigma.translation_mm > options.warn_translation_sigma_mm
            {
                notices.push(Notice::warning(NoticeKind::PoorlyDetermined, format!(
                    "{name} is poorly determined: 1-sigma {:.3}° and {:.2} mm (limits {:.3}° / {:.2} mm): add poses with larger, more varied rotations",
                    sigma.rotation_deg,
                    sigma.translation_mm,
                    options.warn_rotation_sigma_deg,
                    options.warn_translation_sigma_mm
                )));
            }
        }
    }
    if !report.converged {
        notices.push(Notice::warning(
            NoticeKind::NotConverged,
            format!(
                "the {} method did not meet its tolerance; the answer may be inaccurate",
                report.method.name()
            ),
        ));
    }
    Ok(Calibration {
        setup,
        camera_mount,
        target_mount,
        uncertainty,
        residuals,
        noise: Some(noise),
        outliers,
        dropped: Vec::new(),
        solver: report,
        notices,
    })
}

/// `T_camera_target` of sample `left_out` as a solve of all the other samples predicts it
/// (covariance and convention checks off in the fold: only the estimate matters there). `full`
/// is the answer of all the samples with `options`.
///
/// For the refined method the fold is the maximum-likelihood fit of the others started from
/// `full`: leaving one sample out nudges the optimum, so the minimiser reaches it from there in
/// a few steps (its noise estimate from `full`'s sigmas), where the whole pipeline (closed form, alternation, minimiser, and with outliers
/// a consensus start) would cost 5–50 times more for the same optimum; the samples `full` left
/// out as outliers stay out (a fold does not decide them again). Other methods solve each fold
/// from scratch.
pub fn predict_left_out(
    setup: Setup,
    pairs: &[PosePair],
    options: &SolveOptions,
    left_out: usize,
    full: &Calibration,
) -> Result<Pose, SolveError> {
    let fold_options = SolveOptions {
        covariance: false,
        check_conventions: false,
        ..options.clone()
    };
    // The weights of the whole set, as `full` was solved with.
    let pairs = &*options.weighted(pairs);
    let base_from_flange = &pairs[left_out].base_from_flange;
    if options.method == Method::Refined {
        let used: Vec<PosePair> = (0..pairs.len())
            .filter(|i| *i != left_out && !full.dropped.contains(i))
            .map(|i| pairs[i].clone())
            .collect();
        let robot: Vec<Pose> = used.iter().map(|p| p.base_from_flange).collect();
        check_rotation_diversity(&robot)?;
        let start = Axby::from_mounts(&full.camera_mount, &full.target_mount);
        let noise = full.noise.map(|n| n.model());
        let fold = refine::refine_from(&AxbyData::new(setup, &used), &start, noise, &fold_options)?;
        let (camera_mount, target_mount) = fold.solution.to_mounts();
        return Ok(setup::predict(
            setup,
            &camera_mount,
            &target_mount,
            base_from_flange,
        ));
    }
    let rest: Vec<PosePair> = pairs
        .iter()
        .enumerate()
        .filter(|(i, _)| *i != left_out)
        .map(|(_, p)| p.clone())
        .collect();
    let c = solve(setup, &rest, &fold_options)?;
    Ok(c.predict_camera_from_target(base_from_flange))
}

/// The [`NoticeKind::NoiseEstimate`] notice: the board-pose noise the fit used and where it came
/// from (a warning when an estimate hit its bound).
fn noise_notice(noise: &PoseNoise, options: &SolveOptions, samples: usize) -> Notice {
    let start = format!(
        "{:.3}° / {:.2} mm",
        options.noise.rotation_sigma_rad.to_degrees(),
        options.noise.translation_sigma_m * 1e3
    );
    let figures = format!(
        "rotation {:.4}° ({}), translation {:.3} mm ({}) per axis",
        noise.rotation_sigma_deg,
        noise.rotation.name(),
        noise.translation_sigma_mm,
        noise.translation.name()
    );
    let sources = [noise.rotation, noise.translation];
    if sources.contains(&NoiseSource::AtBound) {
        Notice::warning(
            NoticeKind::NoiseEstimate,
            format!(
                "board-pose noise from the residuals: {figures}; an estimate reached its bound \
                 (rotation {:.4}°–{:.1}°, translation {:.3}–{:.0} mm): the samples fit unusually \
                 well or badly, check them",
                noise::ROTATION_SIGMA_RANGE_RAD.0.to_degrees(),
                noise::ROTATION_SIGMA_RANGE_RAD.1.to_degrees(),
                noise::TRANSLATION_SIGMA_RANGE_M.0 * 1e3,
                noise::TRANSLATION_SIGMA_RANGE_M.1 * 1e3
            ),
        )
    } else if sources.contains(&NoiseSource::TooFewSamples) {
        Notice::info(
            NoticeKind::NoiseEstimate,
            format!(
                "board-pose noise not estimated from {samples} sample(s) (8 or more needed): \
                 {figures}, the configured {start}"
            ),
        )
    } else if sources.contains(&NoiseSource::Estimated) {
        Notice::info(
            NoticeKind::NoiseEstimate,
            format!(
                "board-pose noise estimated from the residuals of {samples} samples in {} \
                 round(s), starting from {start}: {figures}; weights, normalised residuals and \
                 1-sigma use it",
                noise.rounds
            ),
        )
    } else {
        Notice::info(
            NoticeKind::NoiseEstimate,
            format!("board-pose noise as given: {figures}"),
        )
    }
}
