//! Reprojection-space refinement: both unknowns of a cell (and optionally the intrinsics, the
//! distortion and a small correction of every robot pose) fitted to every detected board corner
//! of every frame.
//!
//! Model of corner `c` of frame `f`: the board point `p` (target frame, m) goes through the
//! same chain as [`handeye_core::setup::predict`], `T_camera_target = X · B_f · Y` (eye-in-hand
//! `X = inv(T_flange_camera)`, `B_f = inv(T_base_flange)`, `Y = T_base_target`; eye-to-hand
//! `X = inv(T_base_camera)`, `B_f = T_base_flange`, `Y = T_flange_target`), then through the
//! pinhole-plus-distortion [`CameraModel`] to a pixel (OpenCV convention). Residuals are pixel
//! differences divided by the pixel noise sigma; the robust loss (Huber or Cauchy, scale in those
//! sigmas) is applied per corner by iteratively reweighted least squares. Parameters: a local
//! perturbation of X (`R ← exp(φ)·R`, `t ← t + ρ`) and of Y (`R ← R·exp(φ)`, `t ← t + ρ`), the same
//! as the pose-space refinement so [`super::refine::mount_uncertainty`] maps the covariance;
//! then `fx fy cx cy` (px) and the distortion coefficients when free; then per frame a robot
//! correction `T_base_flange ← (R·exp(φ), t + ρ)` held by a Gaussian prior from the robot's
//! repeatability. With the robust loss on, a frame whose correction stands far out from the
//! others' (its recorded robot pose is off) gets its prior dropped: its correction runs free and
//! it leaves the fit of the two unknowns. Optionally the corner noise and the repeatability are
//! estimated from the residuals (variance component estimation). Optionally the arm's joint zero
//! offsets are refined with the two unknowns ([`ArmOffsetsFree`], issue #41): every frame's robot
//! pose moves through the arm's chain at its joints as the offsets change (global columns after
//! the board scale; their Jacobian is the robot correction's, times each offset's flange twist).
//!
//! Analytic Jacobian; each corner row touches at most 12 + 9 global columns and the 6 columns of
//! its own frame's correction. One Levenberg-Marquardt minimises it, `solve::lm`'s on the normal
//! equations accumulated block by block (never the tall Jacobian: with corrections, 12 + 9 +
//! 6·frames columns, a dense QR was ~50x slower — see `benches/reprojection.rs`), the driver the
//! pose-space refinement, the arm's model and the several-camera solve share.
//!
//! This file owns the API types and the pipeline (validate, fit, noise, covariance, outliers,
//! answer); beside it: `problem` (parameters, residuals, Jacobians, normal equations), `noise`
//! (variance component estimation), `outliers` (robust reweighting and flags) and `messages`
//! (the text a person reads). Projection, distortion, their Jacobians and the packing of
//! intrinsics and coefficients are the camera model's ([`handeye_core::camera_model`]).
//!
//! Pure: no I/O, no clocks. Depends on the ground floor (`geometry`, `setup`, `camera_model`),
//! the rest of `solve` and nalgebra only.

mod messages;
mod noise;
mod outliers;
mod problem;

use nalgebra::{Point2, Point3, SMatrix, Vector2};

use super::arrow::inverse_parts;
use super::kinematics::DhChain;
use super::lm::{minimize_normal, Outcome};
use super::refine::mount_uncertainty;
use super::require_positive;
use super::{Axby, AxbyData, Calibration, NoiseModel, RobustLoss, SolveError, Uncertainty};
use handeye_core::camera_model::{CameraModel, Distortion};
use handeye_core::geometry::{rms, Pose};
use handeye_core::notice::Notice;
use handeye_core::setup::{CellTransforms, PosePair, Setup};
use problem::{reanchor, Problem};

/// One detected board corner: where it is on the board and where the camera saw it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Corner {
    /// The corner in the target frame, m.
    pub point_in_target: Point3<f64>,
    /// Its detected pixel (OpenCV convention: pixel centres at integers).
    pub pixel: Point2<f64>,
}

/// Everything recorded at one robot pose.
#[derive(Debug, Clone, PartialEq)]
pub struct Frame {
    /// `T_base_flange` as the robot reported it.
    pub base_from_flange: Pose,
    /// The detected corners of the board.
    pub corners: Vec<Corner>,
    /// Optional name of the frame, carried into messages (e.g. `pose-007`).
    pub id: Option<String>,
}

/// The arm's joint zero offsets refined with the two unknowns (`solver.kinematics` in
/// reprojection space, issue #41). The frames' robot poses carry the arm model of `start`
/// already (the pose-space fit's); each offset in `free` is refined from there, and a frame's
/// pose moves with the change through the chain at the frame's joints:
/// `T_base_flange · FK(q, start)⁻¹ · FK(q, start + δ)`.
#[derive(Debug, Clone, PartialEq)]
pub struct ArmOffsetsFree {
    /// The arm's published chain.
    pub chain: DhChain,
    /// The corrections the frames' robot poses carry, per joint `[θ, d, a, α]`
    /// ([`DhChain::forward_corrected`]).
    pub start: Vec<[f64; 4]>,
    /// The joints (0-based) whose zero offset is refined: the ones the data determine.
    pub free: Vec<usize>,
    /// Each frame's joints (rad), by the frame's id; a frame not here keeps its pose.
    pub joints: Vec<(String, Vec<f64>)>,
}

/// One joint zero offset as the reprojection refinement left it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RefinedOffset {
    /// The joint, 0-based from the base.
    pub joint: usize,
    /// The offset, rad: the start's plus the refined change.
    pub offset_rad: f64,
    /// Its 1-sigma, rad (when the covariance was computed and is not singular).
    pub sigma_rad: Option<f64>,
}

/// Prior on the per-pose robot corrections: 1-sigma of the robot's repeatability.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RobotPrior {
    /// Per-axis position repeatability of the flange, m.
    pub translation_sigma_m: f64,
    /// Per-axis rotation repeatability of the flange, rad.
    pub rotation_sigma_rad: f64,
}

/// What the reprojection refinement is told.
#[derive(Debug, Clone, PartialEq)]
pub struct ReprojectionOptions {
    /// 1-sigma corner detection noise per axis, px: whitens residuals and scales the robust loss.
    pub pixel_sigma_px: f64,
    /// Robust loss on each corner's whitened residual norm (scale in pixel sigmas).
    pub robust: RobustLoss,
    /// Fit `fx fy cx cy` too.
    pub refine_intrinsics: bool,
    /// Fit the distortion coefficients too (a model without distortion becomes `plumb_bob`).
    pub refine_distortion: bool,
    /// Fit the board's scale too: one factor on every board point (the cell model's "the board
    /// is not the size its file says", [`crate::cell_model`]).
    pub refine_board_scale: bool,
    /// The board scale the fit holds, or starts from when `refine_board_scale` (1: the board is
    /// the size its file says).
    pub board_scale: f64,
    /// Fit a small correction of every robot pose, held by this prior (`None`: robot poses exact).
    pub robot_prior: Option<RobotPrior>,
    /// A frame or corner is flagged when its error exceeds `median + factor · 1.4826 · MAD` ...
    pub outlier_mad_factor: f64,
    /// ... and this floor, px.
    pub outlier_floor_px: f64,
    /// Compute the covariance of the result.
    pub covariance: bool,
    /// Most reweighting rounds of the robust loss.
    pub max_robust_rounds: usize,
    /// Estimate the pixel noise and the robot's repeatability from the residuals (variance
    /// component estimation), starting from `pixel_sigma_px` and `robot_prior`: the weights of
    /// corners against robot poses then follow the data, not a guess.
    pub estimate_noise: bool,
    /// Refine the arm's joint zero offsets too (`None`: the robot poses' arm model as given).
    pub arm: Option<ArmOffsetsFree>,
}

impl Default for ReprojectionOptions {
    fn default() -> Self {
        ReprojectionOptions {
            // Sub-pixel AprilTag corners on a sharp image are good to a few tenths of a pixel.
            pixel_sigma_px: 0.3,
            robust: RobustLoss::Huber(3.0),
            refine_intrinsics: false,
            refine_distortion: false,
            refine_board_scale: false,
            board_scale: 1.0,
            robot_prior: None,
            outlier_mad_factor: 5.0,
            outlier_floor_px: 2.0,
            covariance: true,
            max_robust_rounds: 5,
            estimate_noise: false,
            arm: None,
        }
    }
}

/// Reprojection errors of a solution: per frame and overall.
#[derive(Debug, Clone, PartialEq)]
pub struct ReprojectionErrors {
    /// RMS over each frame's corners of the pixel error norm, px (`NaN` for a frame without corners).
    pub frame_rms_px: Vec<f64>,
    /// RMS over all corners, px.
    pub rms_px: f64,
    /// Largest corner error, px.
    pub max_px: f64,
    /// Per frame, per corner: error norm, px.
    pub corner_px: Vec<Vec<f64>>,
}

/// The answer of the reprojection refinement.
#[derive(Debug, Clone, PartialEq)]
pub struct ReprojectionCalibration {
    /// The layout solved.
    pub setup: Setup,
    /// eye_in_hand: `T_flange_camera`; eye_to_hand: `T_base_camera`.
    pub camera_mount: Pose,
    /// eye_in_hand: `T_base_target`; eye_to_hand: `T_flange_target`.
    pub target_mount: Pose,
    /// The camera model at the optimum (the given one when intrinsics were held fixed).
    pub camera: CameraModel,
    /// Corrected `T_base_flange` per frame (empty when no robot prior was given), the refined
    /// joint offsets' move included.
    pub corrected_base_from_flange: Vec<Pose>,
    /// The arm's joint zero offsets refined with the answer (empty without
    /// [`ReprojectionOptions::arm`]).
    pub arm_offsets: Vec<RefinedOffset>,
    /// Covariance of both unknowns (marginal, with intrinsics and corrections free as fitted).
    pub uncertainty: Option<Uncertainty>,
    /// 1-sigma of `fx fy cx cy`, px (when the intrinsics were fitted).
    pub intrinsics_sigma_px: Option<[f64; 4]>,
    /// 1-sigma of the distortion coefficients, in the model's order (when they were fitted).
    pub distortion_sigma: Option<Vec<f64>>,
    /// The board scale at the optimum (the factor on every board point; the given one when held).
    pub board_scale: f64,
    /// 1-sigma of `board_scale` (when it was fitted).
    pub board_scale_sigma: Option<f64>,
    /// The corner noise the answer was weighted with, px: estimated from the residuals when
    /// `estimate_noise` was set and an estimate could be made, the given one otherwise.
    pub pixel_sigma_px: f64,
    /// The robot repeatability the corrections were held by (estimated or given; `None`
    /// without corrections).
    pub robot_prior: Option<RobotPrior>,
    /// Whether `pixel_sigma_px` and `robot_prior` were estimated from the residuals (false when
    /// `estimate_noise` was set but no estimate could be made).
    pub noise_estimated: bool,
    /// Reprojection errors at the optimum (with the corrected robot poses, when fitted).
    pub errors: ReprojectionErrors,
    /// Reprojection errors of the same answer with the robot poses as recorded: the figure to
    /// compare with another answer evaluated on the recorded poses (equals `errors` without
    /// robot corrections).
    pub recorded_pose_errors: ReprojectionErrors,
    /// Frames whose RMS is far above the rest (indices into the input).
    pub outlier_frames: Vec<usize>,
    /// Corners far above the rest: (frame index, corner index).
    pub outlier_corners: Vec<(usize, usize)>,
    /// Residual evaluations spent by LM over all rounds.
    pub evaluations: usize,
    /// LM met its tolerance in every round.
    pub converged: bool,
    /// Things a person should know, each with its severity.
    pub notices: Vec<Notice>,
}

impl ReprojectionCalibration {
    /// Both unknowns with their YAML keys, camera mount first.
    pub fn unknowns(&self) -> [(&'static str, Pose); 2] {
        CellTransforms {
            setup: self.setup,
            camera_mount: self.camera_mount,
            target_mount: self.target_mount,
        }
        .unknowns()
    }

    /// What corners and robot poses were weighted with, and where the numbers came from.
    pub fn weights(&self) -> String {
        messages::weights(self)
    }

    /// This answer in the shape of a pose-space [`Calibration`] (so result files, summaries and
    /// truth checks take either): the unknowns and covariance from here, the pose-space residuals
    /// of these unknowns against the measured `pairs`, the outlier flags, solver report and
    /// warnings of `pose_space` (the start), with this refinement's warnings first.
    pub fn to_calibration(
        &self,
        pose_space: &Calibration,
        pairs: &[PosePair],
        noise: &NoiseModel,
    ) -> Calibration {
        let data = AxbyData::new(self.setup, pairs);
        let residuals = super::diagnostics::residuals(
            &data,
            &Axby::from_mounts(&self.camera_mount, &self.target_mount),
            noise,
        );
        let mut solver = pose_space.solver.clone();
        solver.iterations += self.evaluations;
        solver.converged &= self.converged;
        let mut notices = vec![messages::summary(self)];
        notices.extend(self.notices.iter().cloned());
        notices.extend(pose_space.notices.iter().cloned());
        Calibration {
            setup: self.setup,
            camera_mount: self.camera_mount,
            target_mount: self.target_mount,
            uncertainty: self.uncertainty.clone(),
            residuals,
            noise: None,
            outliers: pose_space.outliers.clone(),
            dropped: pose_space.dropped.clone(),
            solver,
            notices,
        }
    }
}

fn errors_from(pixel_errors: &[Vec<Vector2<f64>>]) -> ReprojectionErrors {
    let corner_px: Vec<Vec<f64>> = pixel_errors
        .iter()
        .map(|f| f.iter().map(|e| e.norm()).collect())
        .collect();
    ReprojectionErrors {
        frame_rms_px: corner_px.iter().map(|f| rms(f.iter().copied())).collect(),
        rms_px: rms(corner_px.iter().flatten().copied()),
        max_px: corner_px.iter().flatten().copied().fold(0.0, f64::max),
        corner_px,
    }
}

/// Reprojection errors of given unknowns and camera over the frames (robot poses as recorded),
/// for comparing answers found in any space.
pub fn reprojection_errors(
    setup: Setup,
    frames: &[Frame],
    camera: &CameraModel,
    camera_mount: &Pose,
    target_mount: &Pose,
) -> ReprojectionErrors {
    let problem = Problem::new(
        setup,
        frames,
        Axby::from_mounts(camera_mount, target_mount),
        *camera,
        &ReprojectionOptions::default(),
    );
    errors_from(&problem.pixel_errors(&problem.state()))
}

fn validate(
    frames: &[Frame],
    camera: &CameraModel,
    options: &ReprojectionOptions,
) -> Result<(), SolveError> {
    require_positive("reprojection.pixel_sigma_px", options.pixel_sigma_px)?;
    require_positive("reprojection.outlier_floor_px", options.outlier_floor_px)?;
    require_positive("reprojection.board_scale", options.board_scale)?;
    options
        .robust
        .validate("reprojection.robust.huber", "reprojection.robust.cauchy")?;
    if let Some(prior) = options.robot_prior {
        require_positive(
            "reprojection.robot_prior.translation_sigma_m",
            prior.translation_sigma_m,
        )?;
        require_positive(
            "reprojection.robot_prior.rotation_sigma_rad",
            prior.rotation_sigma_rad,
        )?;
    }
    if let Some(arm) = &options.arm {
        let joints = arm.chain.joints();
        let fits = arm.start.len() == joints
            && arm.start.iter().flatten().all(|v| v.is_finite())
            && arm.free.iter().all(|&j| j < joints)
            && arm
                .joints
                .iter()
                .all(|(_, q)| q.len() == joints && q.iter().all(|v| v.is_finite()));
        if !fits {
            return Err(SolveError::InvalidOption {
                name: "reprojection.arm",
                value: joints as f64,
                expected: "corrections, free joints and every frame's joints of the chain's joint count, finite",
            });
        }
    }
    require_positive("camera.fx", camera.fx)?;
    require_positive("camera.fy", camera.fy)?;
    for (name, value) in [("camera.cx", camera.cx), ("camera.cy", camera.cy)] {
        if !value.is_finite() {
            return Err(SolveError::InvalidOption {
                name,
                value,
                expected: "must be a finite principal point (px)",
            });
        }
    }
    for (index, frame) in frames.iter().enumerate() {
        let bad = |problem| SolveError::InvalidSample {
            index,
            id: frame.id.clone(),
            problem,
        };
        if !super::pose_is_finite(&frame.base_from_flange) {
            return Err(bad(super::SampleProblem::NotFinite("T_base_flange")));
        }
        if frame.corners.iter().any(|c| {
            !(c.point_in_target.iter().all(|v| v.is_finite())
                && c.pixel.iter().all(|v| v.is_finite()))
        }) {
            return Err(bad(super::SampleProblem::NotFinite("a board corner")));
        }
    }
    let used = frames.iter().filter(|f| !f.corners.is_empty()).count();
    if used < 3 {
        return Err(SolveError::TooFewSamples {
            found: used,
            required: 3,
        });
    }
    Ok(())
}

/// One Levenberg-Marquardt minimisation from the current parameters, on the normal equations
/// accumulated corner by corner (an arrowhead with robot corrections, the dense matrix of the
/// global columns without).
fn run_lm(mut problem: Problem<'_>) -> Result<(Problem<'_>, Outcome), SolveError> {
    let outcome = minimize_normal(&mut problem)?;
    Ok((problem, outcome))
}

/// LM, then rounds of robust reweighting (each followed by LM) until the weights settle.
fn fit<'a>(
    problem: Problem<'a>,
    options: &ReprojectionOptions,
) -> Result<(Problem<'a>, Outcome), SolveError> {
    let (mut problem, mut spent) = run_lm(problem)?;
    if options.robust == RobustLoss::None {
        return Ok((problem, spent));
    }
    for _ in 0..options.max_robust_rounds {
        let changed = outliers::reweight(&mut problem, options);
        if changed < 1e-3 {
            break;
        }
        reanchor(&mut problem);
        let (p, outcome) = run_lm(problem)?;
        problem = p;
        spent.absorb(outcome);
    }
    Ok((problem, spent))
}

/// Minimises the reprojection error of every corner of every frame, starting from the
/// pose-space answer (`start_camera_mount`, `start_target_mount`) and the camera model `camera`.
///
/// Frames without corners are kept (so indices match the input) but contribute nothing.
/// Errors: fewer than 3 frames with corners, non-finite input, bad options, or LM failing
/// numerically.
pub fn refine_reprojection(
    setup: Setup,
    frames: &[Frame],
    camera: &CameraModel,
    start_camera_mount: &Pose,
    start_target_mount: &Pose,
    options: &ReprojectionOptions,
) -> Result<ReprojectionCalibration, SolveError> {
    validate(frames, camera, options)?;
    let mut camera0 = *camera;
    if options.refine_distortion && camera0.distortion == Distortion::None {
        camera0.distortion = Distortion::RadTan {
            k1: 0.0,
            k2: 0.0,
            p1: 0.0,
            p2: 0.0,
            k3: 0.0,
        };
    }
    let start = Axby::from_mounts(start_camera_mount, start_target_mount);
    let problem = Problem::new(setup, frames, start, camera0, options);
    let (mut problem, mut spent) = fit(problem, options)?;
    let mut notices = Vec::new();
    // Without estimation the configured noise stands.
    let mut noise_estimated = false;
    if options.estimate_noise {
        let (p, report) = noise::estimate_and_refit(problem, options, &mut spent)?;
        problem = p;
        noise_estimated = report.estimated;
        notices.extend(messages::noise_notes(&report));
    }
    reanchor(&mut problem);
    let s = problem.state();
    let pixel_errors = problem.pixel_errors(&s);
    let errors = errors_from(&pixel_errors);

    // Covariance at the optimum: (JᵀJ)⁻¹ scaled by the same variance factor as the pose-space
    // solve (χ²/dof, floored at 1 only with few degrees of freedom), marginals of the blocks.
    let residuals = problem
        .residuals()
        .ok_or(SolveError::RefinementFailed("residuals are not finite"))?;
    let n_params = problem.layout.len();
    let dof = residuals.len().saturating_sub(n_params);
    let variance_factor = super::refine::variance_factor(residuals.norm_squared(), dof);
    let mut uncertainty = None;
    let mut intrinsics_sigma_px = None;
    let mut distortion_sigma = None;
    let mut board_scale_sigma = None;
    let mut arm_sigma = vec![None; problem.layout.arm];
    if options.covariance {
        let (jtj, _, _) = problem
            .normal_equations()
            .ok_or(SolveError::RefinementFailed("residuals are not finite"))?;
        // The global parameters' block of the inverse only (the robot corrections' is never
        // read): by the Schur complement when the corrections make `JᵀJ` an arrowhead.
        match inverse_parts(&jtj) {
            Some(parts) => {
                let cov = parts.global * variance_factor;
                let pose_cov: SMatrix<f64, 12, 12> = cov.fixed_view::<12, 12>(0, 0).into();
                uncertainty = Some(mount_uncertainty(&s.axby, &pose_cov, variance_factor));
                if problem.layout.intrinsics > 0 {
                    let o = problem.layout.intrinsics_offset();
                    intrinsics_sigma_px =
                        Some([0, 1, 2, 3].map(|i| cov[(o + i, o + i)].max(0.0).sqrt()));
                }
                let sigma = |i: usize| cov[(i, i)].max(0.0).sqrt();
                if problem.layout.distortion > 0 {
                    let o = problem.layout.distortion_offset();
                    distortion_sigma =
                        Some((o..o + problem.layout.distortion).map(sigma).collect());
                }
                if problem.layout.board_scale > 0 {
                    board_scale_sigma = Some(sigma(problem.layout.board_scale_offset()));
                }
                let o = problem.layout.arm_offset();
                arm_sigma = (o..o + problem.layout.arm)
                    .map(|i| Some(sigma(i)))
                    .collect();
            }
            None => notices.push(messages::singular()),
        }
    }

    let flags = outliers::flag(&problem, &s, &errors, options);
    notices.extend(messages::outlier_warnings(frames, &errors, &flags));
    if !spent.converged {
        notices.push(messages::not_converged());
    }
    let corrected_base_from_flange = if problem.layout.robot > 0 {
        s.robot_poses.clone()
    } else {
        Vec::new()
    };
    let arm_offsets = problem.refined_offsets(&arm_sigma);
    let (camera_mount, target_mount) = s.axby.to_mounts();
    let recorded_pose_errors = if problem.layout.robot > 0 {
        reprojection_errors(setup, frames, &s.camera, &camera_mount, &target_mount)
    } else {
        errors.clone()
    };
    Ok(ReprojectionCalibration {
        setup,
        camera_mount,
        target_mount,
        camera: s.camera,
        corrected_base_from_flange,
        arm_offsets,
        uncertainty,
        intrinsics_sigma_px,
        distortion_sigma,
        board_scale: s.board_scale,
        board_scale_sigma,
        pixel_sigma_px: 1.0 / problem.inv_sigma_px,
        robot_prior: problem.prior,
        noise_estimated,
        errors,
        recorded_pose_errors,
        outlier_frames: flags.frames,
        outlier_corners: flags.corners,
        evaluations: spent.evaluations,
        converged: spent.converged,
        notices,
    })
}
