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
//! Every method ([`iterative`], [`closed_form`], [`refine`]) works on [`AxbyData`] only, so the
//! two setups share one code path. Units are metres and radians inside; residuals and
//! uncertainties are reported in mm and degrees for people. Pure functions: no I/O, no clocks;
//! depends only on the ground floor (`geometry`, `setup`, `camera_model`) and nalgebra, as
//! `tests/layers.rs` checks.

pub mod closed_form;
pub mod diagnostics;
pub mod intrinsics;
pub mod iterative;
mod lm;
pub mod refine;
pub mod reprojection;

use nalgebra::SMatrix;
use serde::{Deserialize, Serialize};

use crate::geometry::Pose;
use crate::setup::{CellTransforms, PosePair, Setup};

pub use diagnostics::{check_rotation_diversity, rotation_diversity, RotationDiversity};
pub use iterative::{IterativeOptions, IterativeOutcome};
pub use reprojection::{
    refine_reprojection, reprojection_errors, Corner, Frame, ReprojectionCalibration,
    ReprojectionErrors, ReprojectionOptions, RobotPrior,
};

/// Measurement noise of `T_camera_target`: standard deviation per axis of the rotation error
/// (rad, a small rotation vector in the camera frame) and of the translation error (m, camera frame).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NoiseModel {
    /// Per-axis standard deviation of the rotation error, rad.
    pub rotation_sigma_rad: f64,
    /// Per-axis standard deviation of the translation error, m.
    pub translation_sigma_m: f64,
}

impl Default for NoiseModel {
    /// 0.2° and 1 mm: a typical AprilTag board pose at working distance.
    fn default() -> Self {
        NoiseModel {
            rotation_sigma_rad: 0.2f64.to_radians(),
            translation_sigma_m: 1e-3,
        }
    }
}

/// Which estimator [`solve`] runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Method {
    /// The paper: alternating quaternion averaging for rotations, then translations.
    Iterative,
    /// Shah (2013) Kronecker/SVD closed form written for `A = X·B·Y`.
    ClosedForm,
    /// Joint weighted nonlinear least squares on both unknowns, started from the iterative answer.
    #[default]
    Refined,
}

impl Method {
    /// The YAML / CLI name.
    pub fn name(self) -> &'static str {
        match self {
            Method::Iterative => "iterative",
            Method::ClosedForm => "closed_form",
            Method::Refined => "refined",
        }
    }
}

/// Robust loss of the refinement, applied to each sample's whitened residual norm. The scale is in
/// sigmas of the [`NoiseModel`].
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RobustLoss {
    /// Plain least squares (the maximum-likelihood estimate under Gaussian noise).
    #[default]
    None,
    /// Huber loss with this threshold (sigmas).
    Huber(f64),
    /// Cauchy loss with this scale (sigmas).
    Cauchy(f64),
}

impl RobustLoss {
    /// Checks the loss's scale is a positive finite number; the names are the option keys of
    /// the Huber and Cauchy scales in the caller's configuration.
    pub(super) fn validate(
        self,
        huber_name: &'static str,
        cauchy_name: &'static str,
    ) -> Result<(), SolveError> {
        match self {
            RobustLoss::Huber(k) => require_positive(huber_name, k),
            RobustLoss::Cauchy(k) => require_positive(cauchy_name, k),
            RobustLoss::None => Ok(()),
        }
    }

    /// The iteratively-reweighted-least-squares weight of a residual of `e` sigmas.
    pub fn weight(self, e: f64) -> f64 {
        match self {
            RobustLoss::None => 1.0,
            RobustLoss::Huber(k) if e <= k => 1.0,
            RobustLoss::Huber(k) => k / e,
            RobustLoss::Cauchy(k) => 1.0 / (1.0 + (e / k) * (e / k)),
        }
    }
}

/// Everything [`solve`] can be told.
#[derive(Debug, Clone, PartialEq)]
pub struct SolveOptions {
    /// The estimator (default [`Method::Refined`]).
    pub method: Method,
    /// Noise of `T_camera_target`, used to weight and whiten residuals.
    pub noise: NoiseModel,
    /// Robust loss of the refinement.
    pub robust: RobustLoss,
    /// Drop the samples flagged as outliers and solve again.
    pub drop_outliers: bool,
    /// Outlier threshold: a sample is flagged when its normalised residual exceeds
    /// `median + outlier_mad_factor · 1.4826 · MAD` and [`SolveOptions::outlier_floor_sigma`].
    pub outlier_mad_factor: f64,
    /// Normalised residual (sigmas, 6 dof) below which a sample is never an outlier.
    pub outlier_floor_sigma: f64,
    /// Options of the iterative method (also the start of the refinement).
    pub iterative: IterativeOptions,
    /// Compute the covariance of the unknowns (refined method only).
    pub covariance: bool,
    /// Warn when a 1-sigma rotation uncertainty exceeds this, degrees.
    pub warn_rotation_sigma_deg: f64,
    /// Warn when a 1-sigma translation uncertainty exceeds this, mm.
    pub warn_translation_sigma_mm: f64,
    /// Check whether the data fits far better under another convention (inverted poses, other setup).
    pub check_conventions: bool,
}

impl Default for SolveOptions {
    fn default() -> Self {
        SolveOptions {
            method: Method::Refined,
            noise: NoiseModel::default(),
            robust: RobustLoss::None,
            drop_outliers: false,
            outlier_mad_factor: 5.0,
            // sqrt of the 99.9 % quantile of chi-square with 6 dof (22.46).
            outlier_floor_sigma: 4.74,
            iterative: IterativeOptions::default(),
            covariance: true,
            warn_rotation_sigma_deg: 0.5,
            warn_translation_sigma_mm: 5.0,
            check_conventions: true,
        }
    }
}

/// Residuals of the solution against each sample's measured `T_camera_target`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Residuals {
    /// Per sample: angle between predicted and measured rotation, degrees.
    pub rotation_deg: Vec<f64>,
    /// Per sample: distance between predicted and measured translation, mm.
    pub translation_mm: Vec<f64>,
    /// Per sample: whitened residual norm in sigmas of the noise model (6 dof).
    pub normalised: Vec<f64>,
    /// RMS of `rotation_deg`.
    pub rotation_rms_deg: f64,
    /// Largest of `rotation_deg`.
    pub rotation_max_deg: f64,
    /// RMS of `translation_mm`.
    pub translation_rms_mm: f64,
    /// Largest of `translation_mm`.
    pub translation_max_mm: f64,
}

/// 1-sigma uncertainty of one unknown `T_a_b`: rotation perturbation and translation, both in
/// frame `a`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PoseSigma {
    /// Total 1-sigma rotation (sqrt of the trace of the rotation covariance), degrees.
    pub rotation_deg: f64,
    /// Total 1-sigma translation (sqrt of the trace of the translation covariance), mm.
    pub translation_mm: f64,
    /// Per-axis 1-sigma rotation about x, y, z of frame `a`, degrees.
    pub rotation_axes_deg: [f64; 3],
    /// Per-axis 1-sigma translation along x, y, z of frame `a`, mm.
    pub translation_axes_mm: [f64; 3],
}

/// Covariance of both unknowns at the optimum.
#[derive(Debug, Clone, PartialEq)]
pub struct Uncertainty {
    /// 12x12 joint covariance, order: camera mount [rotation (rad), translation (m)], target
    /// mount [rotation, translation]; each pose `T_a_b` perturbed as
    /// `R ← exp(δθ)·R, t ← t + δt` (both in frame `a`).
    pub covariance: SMatrix<f64, 12, 12>,
    /// 1-sigma of the camera mount (`T_flange_camera` or `T_base_camera`).
    pub camera_mount: PoseSigma,
    /// 1-sigma of the target mount (`T_base_target` or `T_flange_target`).
    pub target_mount: PoseSigma,
    /// A-posteriori variance factor `χ²/dof` the covariance was scaled by (≈ 1 if the noise
    /// model is right; floored at 1 only with fewer than 36 residual degrees of freedom, i.e.
    /// 8 pose samples, see [`refine::variance_factor`]).
    pub variance_factor: f64,
}

/// One step of an iteration trace.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TraceStep {
    /// `rotation` or `translation` phase of the iterative method, or `refine`.
    pub phase: Phase,
    /// Size of the update of this step: rad for rotation, m for translation, cost for refine.
    pub update: f64,
}

/// Phase of a [`TraceStep`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Phase {
    /// Rotation alternation (update in rad).
    Rotation,
    /// Translation alternation (update in m).
    Translation,
    /// Nonlinear refinement (value: half the sum of squared whitened residuals).
    Refine,
}

/// How the solver got its answer.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SolverReport {
    /// The method that produced the answer.
    pub method: Method,
    /// Iterations of the iterative method (rotation + translation), or LM evaluations.
    pub iterations: usize,
    /// Whether every stage met its tolerance.
    pub converged: bool,
    /// Restarts of the iterative method after a stall (the paper's s ≈ 0 case).
    pub restarts: usize,
    /// Per-iteration update sizes, for plots.
    pub trace: Vec<TraceStep>,
}

/// The answer: both unknowns, their uncertainty, and the diagnostics.
#[derive(Debug, Clone, PartialEq)]
pub struct Calibration {
    /// The layout solved.
    pub setup: Setup,
    /// eye_in_hand: `T_flange_camera`; eye_to_hand: `T_base_camera`.
    pub camera_mount: Pose,
    /// eye_in_hand: `T_base_target`; eye_to_hand: `T_flange_target`.
    pub target_mount: Pose,
    /// Covariance of both unknowns (refined method with covariance on).
    pub uncertainty: Option<Uncertainty>,
    /// Residuals of the samples used in the final solve, indexed like the input.
    pub residuals: Residuals,
    /// Indices (into the input) of samples flagged as outliers.
    pub outliers: Vec<usize>,
    /// Indices (into the input) of samples left out of the final solve (dropped outliers).
    pub dropped: Vec<usize>,
    /// How the solver got there.
    pub solver: SolverReport,
    /// Things a person should know (large uncertainty, flagged outliers, ...).
    pub warnings: Vec<String>,
}

impl Calibration {
    /// Both unknowns with their YAML keys, camera mount first.
    pub fn unknowns(&self) -> [(&'static str, Pose); 2] {
        self.transforms().unknowns()
    }

    /// The two solved transforms, named by setup.
    pub fn transforms(&self) -> CellTransforms {
        CellTransforms {
            setup: self.setup,
            camera_mount: self.camera_mount,
            target_mount: self.target_mount,
        }
    }

    /// The `T_camera_target` this calibration predicts for a robot pose `T_base_flange`.
    pub fn predict_camera_from_target(&self, base_from_flange: &Pose) -> Pose {
        self.transforms().camera_from_target(base_from_flange)
    }
}

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

/// Why no calibration could be produced.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SolveError {
    /// Fewer samples than the problem needs.
    #[error("{found} pose pairs given, at least {required} are needed (with rotations about at least two different axes): record more poses")]
    TooFewSamples {
        /// Samples given (after dropping outliers, if any).
        found: usize,
        /// Samples needed.
        required: usize,
    },
    /// All relative robot rotations are about (nearly) one axis: the unknowns are not observable.
    #[error("robot rotations are all about nearly one axis (flange-frame axis [{:.3}, {:.3}, {:.3}], largest rotation off that axis {off_axis_deg:.2}° < {required_deg:.1}°): add poses tilted by 20–40° about flange axes [{:.3}, {:.3}, {:.3}] and [{:.3}, {:.3}, {:.3}]", axis[0], axis[1], axis[2], add_about[0][0], add_about[0][1], add_about[0][2], add_about[1][0], add_about[1][1], add_about[1][2])]
    Coaxial {
        /// Dominant rotation axis, flange frame of the first pose.
        axis: [f64; 3],
        /// Largest rotation component off that axis, degrees.
        off_axis_deg: f64,
        /// Required off-axis rotation, degrees.
        required_deg: f64,
        /// Two axes (flange frame of the first pose) to rotate about in new poses.
        add_about: [[f64; 3]; 2],
    },
    /// All relative robot rotations are tiny.
    #[error("robot rotations span only {span_deg:.2}° (need at least {required_deg:.1}° about two different axes): add poses tilted by 20–40° about two different flange axes")]
    TooLittleRotation {
        /// Largest relative rotation, degrees.
        span_deg: f64,
        /// Needed, degrees.
        required_deg: f64,
    },
    /// A sample with a bad value.
    #[error("sample {index}{}: {problem}", id.as_ref().map(|i| format!(" ({i})")).unwrap_or_default())]
    InvalidSample {
        /// Index of the sample.
        index: usize,
        /// Its id, if any.
        id: Option<String>,
        /// What is wrong.
        problem: SampleProblem,
    },
    /// An option with a bad value.
    #[error("option `{name}` = {value}: {expected}")]
    InvalidOption {
        /// The option.
        name: &'static str,
        /// Its value.
        value: f64,
        /// What it must be.
        expected: &'static str,
    },
    /// The data fits far better with the robot poses inverted: the input is mislabelled.
    #[error("the data does not fit {setup} as given (rotation residual RMS {given_rms_deg:.2}°) but fits with {alternative_rms_deg:.3}° if the robot poses are inverted: either T_flange_base was given as T_base_flange, or T_target_camera as T_camera_target, or the setup is {} — check the convention of the input poses", setup.other())]
    ConventionMismatch {
        /// Setup as given.
        setup: Setup,
        /// Rotation residual RMS as given, degrees.
        given_rms_deg: f64,
        /// Rotation residual RMS with the robot poses inverted, degrees.
        alternative_rms_deg: f64,
    },
    /// The iterative method found no finite answer from any start.
    #[error("the iterative method found no usable answer after {restarts} restarts ({iterations} iterations)")]
    NoConvergence {
        /// Restarts tried.
        restarts: usize,
        /// Iterations spent.
        iterations: usize,
    },
    /// The nonlinear refinement failed numerically.
    #[error("refinement failed: {0}")]
    RefinementFailed(&'static str),
    /// The closed form found no usable rotation.
    #[error("closed form failed: {0}")]
    ClosedFormFailed(&'static str),
    /// The frames do not determine the camera intrinsics (e.g. all boards seen fronto-parallel).
    #[error("the frames do not constrain the camera intrinsics: {frames} frames, board tilt to the image plane {min_tilt_deg:.1}°..{max_tilt_deg:.1}°, board corners cover {coverage_percent:.0} % of the image: add frames with the board tilted by 20–45° about two different axes (left/right and up/down), and frames where the board reaches the image corners")]
    DegenerateIntrinsics {
        /// Frames with enough corners.
        frames: usize,
        /// Smallest board tilt against the image plane over the frames, degrees (estimated).
        min_tilt_deg: f64,
        /// Largest board tilt, degrees (estimated).
        max_tilt_deg: f64,
        /// Share of the image's bounding box covered by corners of all frames, percent.
        coverage_percent: f64,
    },
    /// The intrinsics could not be estimated from the board views.
    #[error("intrinsics estimation failed: {0}")]
    IntrinsicsFailed(String),
}

/// What is wrong with one sample.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SampleProblem {
    /// NaN or infinity in a pose.
    #[error("{0} contains a non-finite value")]
    NotFinite(&'static str),
    /// A weight that is not a positive finite number.
    #[error("weight {0} must be a positive finite number")]
    BadWeight(f64),
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

/// An option that must be a positive finite number, named `name` in the error.
pub(super) fn require_positive(name: &'static str, value: f64) -> Result<(), SolveError> {
    if value.is_finite() && value > 0.0 {
        Ok(())
    } else {
        Err(SolveError::InvalidOption {
            name,
            value,
            expected: "must be a positive finite number",
        })
    }
}

/// Solves for both unknowns of a cell from its pose pairs.
///
/// Checks the input (finite values, weights, at least 3 samples with rotations about two
/// axes), runs the chosen method, computes residuals and outlier flags, optionally drops the
/// outliers and solves again, and checks the convention when the fit is poor.
pub fn solve(
    setup: Setup,
    pairs: &[PosePair],
    options: &SolveOptions,
) -> Result<Calibration, SolveError> {
    validate(pairs, options)?;
    let all: Vec<usize> = (0..pairs.len()).collect();
    let mut calibration = solve_subset(setup, pairs, &all, options)?;
    if options.drop_outliers && !calibration.outliers.is_empty() {
        let dropped = calibration.outliers.clone();
        let keep: Vec<usize> = all
            .iter()
            .copied()
            .filter(|i| !dropped.contains(i))
            .collect();
        let mut again = solve_subset(setup, pairs, &keep, options)?;
        again.warnings.insert(
            0,
            format!(
                "dropped {} outlier sample(s) {:?} and solved again with {}",
                dropped.len(),
                dropped,
                keep.len()
            ),
        );
        // Report both the original flags and anything still flagged among the kept samples.
        let mut outliers = dropped.clone();
        outliers.extend(again.outliers.iter().copied());
        outliers.sort_unstable();
        outliers.dedup();
        again.outliers = outliers;
        again.dropped = dropped;
        calibration = again;
    }
    Ok(calibration)
}

/// Coarsest tolerance (rad, and m) of the iterative start of the refined method.
const REFINE_START_TOLERANCE: f64 = 1e-8;

type Solved = (Axby, SolverReport, Option<Uncertainty>);

fn solve_method(data: &AxbyData, options: &SolveOptions) -> Result<Solved, SolveError> {
    Ok(match options.method {
        Method::ClosedForm => {
            let s = closed_form::solve_axby(data)?;
            let report = SolverReport {
                method: Method::ClosedForm,
                iterations: 0,
                converged: true,
                restarts: 0,
                trace: Vec::new(),
            };
            (s, report, None)
        }
        Method::Iterative => {
            let out = iterative::solve_axby_with_restarts(data, &options.iterative)?;
            let report = out.report(Method::Iterative);
            (out.solution, report, None)
        }
        Method::Refined => {
            // LM polishes the start, so the alternation need not run to machine precision.
            let start_options = IterativeOptions {
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
            (refined.solution, report, uncertainty)
        }
    })
}

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

    let mut warnings = Vec::new();
    let solved = solve_method(&data, options);
    let (solution, report, uncertainty) = match solved {
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
    let sub_residuals = diagnostics::residuals(&data, &solution, &options.noise);
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
        warnings.push(format!(
            "{} sample(s) look like outliers: {} (residuals far above the rest; check detection and robot pose of those samples)",
            outliers.len(),
            described.join(", ")
        ));
    }
    if let Some(u) = &uncertainty {
        let (camera_name, target_name) = setup.unknown_names();
        for (name, sigma) in [
            (camera_name, &u.camera_mount),
            (target_name, &u.target_mount),
        ] {
            if sigma.rotation_deg > options.warn_rotation_sigma_deg
                || sigma.translation_mm > options.warn_translation_sigma_mm
            {
                warnings.push(format!(
                    "{name} is poorly determined: 1-sigma {:.3}° and {:.2} mm (limits {:.3}° / {:.2} mm): add poses with larger, more varied rotations",
                    sigma.rotation_deg,
                    sigma.translation_mm,
                    options.warn_rotation_sigma_deg,
                    options.warn_translation_sigma_mm
                ));
            }
        }
    }
    if !report.converged {
        warnings.push(format!(
            "the {} method did not meet its tolerance; the answer may be inaccurate",
            report.method.name()
        ));
    }
    Ok(Calibration {
        setup,
        camera_mount,
        target_mount,
        uncertainty,
        residuals,
        outliers,
        dropped: Vec::new(),
        solver: report,
        warnings,
    })
}

impl Calibration {
    /// A short summary for a terminal: solver run, both unknowns with their 1-sigma, residuals,
    /// outliers and warnings.
    pub fn summary(&self) -> String {
        use std::fmt::Write;
        let mut out = String::new();
        let s = &self.solver;
        let _ = writeln!(
            out,
            "setup {}, method {} ({} iterations, {}converged, {} restarts)",
            self.setup,
            s.method.name(),
            s.iterations,
            if s.converged { "" } else { "NOT " },
            s.restarts
        );
        let sigmas = self
            .uncertainty
            .as_ref()
            .map(|u| [u.camera_mount, u.target_mount]);
        for (k, (name, pose)) in self.unknowns().iter().enumerate() {
            let t = pose.translation.vector * 1e3;
            let rv = crate::geometry::rotvec(&pose.rotation);
            let _ = writeln!(
                out,
                "{name}: translation [{:.2}, {:.2}, {:.2}] mm, rotation_vector [{:.5}, {:.5}, {:.5}] rad ({:.3}°)",
                t.x,
                t.y,
                t.z,
                rv.x,
                rv.y,
                rv.z,
                rv.norm().to_degrees()
            );
            if let Some(sigma) = sigmas {
                let _ = writeln!(
                    out,
                    "    1-sigma {:.4}°, {:.3} mm",
                    sigma[k].rotation_deg, sigma[k].translation_mm
                );
            }
        }
        let r = &self.residuals;
        let _ = write!(
            out,
            "residuals: rotation RMS {:.4}° (max {:.4}°), translation RMS {:.3} mm (max {:.3} mm)",
            r.rotation_rms_deg, r.rotation_max_deg, r.translation_rms_mm, r.translation_max_mm
        );
        if !self.outliers.is_empty() {
            let _ = write!(out, "\noutliers (sample indices): {:?}", self.outliers);
        }
        for warning in &self.warnings {
            let _ = write!(out, "\nwarning: {warning}");
        }
        out
    }
}
