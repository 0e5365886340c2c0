//! Reprojection-space refinement: both unknowns of a cell (and optionally the intrinsics, the
//! distortion and a small correction of every robot pose) fitted to every detected board corner
//! of every frame.
//!
//! Model of corner `c` of frame `f`: the board point `p` (target frame, m) goes through the
//! same chain as [`super::predict`], `T_camera_target = X · B_f · Y` (eye-in-hand
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
//! estimated from the residuals (variance component estimation).
//!
//! Analytic Jacobian; each corner row touches at most 12 + 9 global columns and the 6 columns of
//! its own frame's correction. Without corrections the Jacobian is at most 21 columns wide and
//! the `levenberg-marquardt` crate minimises it with its dense QR; with them (12 + 9 + 6·frames
//! columns) a Levenberg-Marquardt on the normal equations accumulated block by block replaces it
//! (the dense QR was ~50x slower) — see `benches/reprojection.rs`. Both drivers live in
//! `solve::lm`, shared with the pose-space refinement.
//!
//! Pure: no I/O, no clocks. Depends on `geometry`, the camera model type and nalgebra only.

use levenberg_marquardt::{LeastSquaresProblem, LevenbergMarquardt};
use nalgebra::{
    DMatrix, DVector, Dyn, Matrix2, Matrix2x3, Matrix3, Owned, Point2, Point3, SMatrix,
    Translation3, UnitQuaternion, Vector2, Vector3,
};

use super::diagnostics::flag_outliers;
use super::lm::{minimize_dense, minimize_normal, NormalEquations};
use super::refine::mount_uncertainty;
use super::require_positive;
use super::{Axby, AxbyData, Calibration, NoiseModel, RobustLoss, SolveError, Uncertainty};
use crate::camera_model::{CameraModel, Distortion};
use crate::geometry::Pose;
use crate::setup::{CellTransforms, PosePair, Setup};

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
}

impl Default for ReprojectionOptions {
    fn default() -> Self {
        ReprojectionOptions {
            // Sub-pixel AprilTag corners on a sharp image are good to a few tenths of a pixel.
            pixel_sigma_px: 0.3,
            robust: RobustLoss::Huber(3.0),
            refine_intrinsics: false,
            refine_distortion: false,
            robot_prior: None,
            outlier_mad_factor: 5.0,
            outlier_floor_px: 2.0,
            covariance: true,
            max_robust_rounds: 5,
            estimate_noise: false,
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
    /// Corrected `T_base_flange` per frame (empty when no robot prior was given).
    pub corrected_base_from_flange: Vec<Pose>,
    /// Covariance of both unknowns (marginal, with intrinsics and corrections free as fitted).
    pub uncertainty: Option<Uncertainty>,
    /// 1-sigma of `fx fy cx cy`, px (when the intrinsics were fitted).
    pub intrinsics_sigma_px: Option<[f64; 4]>,
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
    /// Things a person should know.
    pub warnings: Vec<String>,
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
        let origin = if self.noise_estimated {
            "estimated from the residuals"
        } else {
            "as configured"
        };
        let robot = match self.robot_prior {
            Some(prior) => format!(
                ", robot repeatability {:.4} mm / {:.5}° (1-sigma per axis)",
                prior.translation_sigma_m * 1e3,
                prior.rotation_sigma_rad.to_degrees()
            ),
            None => ", robot poses taken as exact".to_string(),
        };
        format!(
            "weights {origin}: corner noise {:.3} px{robot}",
            self.pixel_sigma_px
        )
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
        let mut warnings = vec![format!(
            "refined in reprojection space over {} corners: RMS {:.3} px (max {:.3} px); {}",
            self.errors.corner_px.iter().map(Vec::len).sum::<usize>(),
            self.errors.rms_px,
            self.errors.max_px,
            self.weights()
        )];
        warnings.extend(self.warnings.iter().cloned());
        warnings.extend(pose_space.warnings.iter().cloned());
        Calibration {
            setup: self.setup,
            camera_mount: self.camera_mount,
            target_mount: self.target_mount,
            uncertainty: self.uncertainty.clone(),
            residuals,
            outliers: pose_space.outliers.clone(),
            dropped: pose_space.dropped.clone(),
            solver,
            warnings,
        }
    }
}

/// Projection that never fails: points at or behind the camera are pushed to a tiny positive
/// depth, so they land far off and LM rejects the step instead of aborting.
fn project(camera: &CameraModel, p: &Vector3<f64>) -> (Vector2<f64>, Vector2<f64>) {
    let z = p.z.max(1e-6);
    let xn = Vector2::new(p.x / z, p.y / z);
    let xd = camera.distortion.distort(xn);
    (
        Vector2::new(camera.fx * xd.x + camera.cx, camera.fy * xd.y + camera.cy),
        xd,
    )
}

fn coefficient_count(distortion: &Distortion) -> usize {
    match distortion {
        Distortion::None => 0,
        Distortion::RadTan { .. } => 5,
        Distortion::Equidistant { .. } => 4,
    }
}

fn with_coefficients(distortion: &Distortion, c: &[f64]) -> Distortion {
    match distortion {
        Distortion::None => Distortion::None,
        Distortion::RadTan { .. } => Distortion::RadTan {
            k1: c[0],
            k2: c[1],
            p1: c[2],
            p2: c[3],
            k3: c[4],
        },
        Distortion::Equidistant { .. } => Distortion::Equidistant {
            k1: c[0],
            k2: c[1],
            k3: c[2],
            k4: c[3],
        },
    }
}

fn coefficients(distortion: &Distortion) -> Vec<f64> {
    match *distortion {
        Distortion::None => Vec::new(),
        Distortion::RadTan { k1, k2, p1, p2, k3 } => vec![k1, k2, p1, p2, k3],
        Distortion::Equidistant { k1, k2, k3, k4 } => vec![k1, k2, k3, k4],
    }
}

/// d(distorted normalised point)/d(coefficients), 2 x n.
fn distortion_coefficient_jacobian(distortion: &Distortion, xn: Vector2<f64>) -> DMatrix<f64> {
    match *distortion {
        Distortion::None => DMatrix::zeros(2, 0),
        Distortion::RadTan { .. } => {
            let (x, y) = (xn.x, xn.y);
            let r2 = x * x + y * y;
            let r4 = r2 * r2;
            DMatrix::from_row_slice(
                2,
                5,
                &[
                    x * r2,
                    x * r4,
                    2.0 * x * y,
                    r2 + 2.0 * x * x,
                    x * r4 * r2,
                    y * r2,
                    y * r4,
                    r2 + 2.0 * y * y,
                    2.0 * x * y,
                    y * r4 * r2,
                ],
            )
        }
        Distortion::Equidistant { .. } => {
            // θd is linear in the coefficients: d/dk_i = xn/r · θ^(2i+3).
            let r = xn.norm();
            let mut j = DMatrix::zeros(2, 4);
            if r > 1e-12 {
                let theta = r.atan();
                let mut power = theta * theta * theta;
                for i in 0..4 {
                    let column = xn * (power / r);
                    j[(0, i)] = column.x;
                    j[(1, i)] = column.y;
                    power *= theta * theta;
                }
            }
            j
        }
    }
}

/// Column layout of the parameter vector.
#[derive(Debug, Clone, Copy)]
struct Layout {
    intrinsics: usize,
    distortion: usize,
    robot: usize,
    frames: usize,
}

impl Layout {
    const POSE: usize = 12;
    fn intrinsics_offset(&self) -> usize {
        Self::POSE
    }
    fn distortion_offset(&self) -> usize {
        Self::POSE + self.intrinsics
    }
    fn robot_offset(&self) -> usize {
        Self::POSE + self.intrinsics + self.distortion
    }
    fn len(&self) -> usize {
        self.robot_offset() + self.robot * self.frames
    }
}

struct Problem<'a> {
    setup: Setup,
    frames: &'a [Frame],
    layout: Layout,
    /// Anchor of the pose perturbation.
    x0: Axby,
    /// Camera at the anchor (its distortion variant decides the coefficient meaning).
    camera0: CameraModel,
    params: DVector<f64>,
    /// Per frame, per corner: robust weight (sqrt applied when used).
    weights: Vec<Vec<f64>>,
    /// Per frame: 1, or 0 for a frame whose recorded robot pose is far off (its correction then
    /// runs free, so it neither drags the others' corrections along nor the estimated
    /// repeatability up).
    prior_weights: Vec<f64>,
    inv_sigma_px: f64,
    prior: Option<RobotPrior>,
    /// Rows of each frame's first corner.
    row_offsets: Vec<usize>,
    corner_rows: usize,
}

struct State {
    axby: Axby,
    camera: CameraModel,
    b: Vec<Pose>,
    /// Per frame: (φ, ρ) robot correction.
    corrections: Vec<(Vector3<f64>, Vector3<f64>)>,
}

impl Problem<'_> {
    fn new<'a>(
        setup: Setup,
        frames: &'a [Frame],
        x0: Axby,
        camera0: CameraModel,
        options: &ReprojectionOptions,
    ) -> Problem<'a> {
        let layout = Layout {
            intrinsics: if options.refine_intrinsics { 4 } else { 0 },
            distortion: if options.refine_distortion {
                coefficient_count(&camera0.distortion)
            } else {
                0
            },
            robot: if options.robot_prior.is_some() { 6 } else { 0 },
            frames: frames.len(),
        };
        let mut params = DVector::zeros(layout.len());
        if layout.intrinsics > 0 {
            let o = layout.intrinsics_offset();
            params[o] = camera0.fx;
            params[o + 1] = camera0.fy;
            params[o + 2] = camera0.cx;
            params[o + 3] = camera0.cy;
        }
        if layout.distortion > 0 {
            let o = layout.distortion_offset();
            for (k, c) in coefficients(&camera0.distortion).iter().enumerate() {
                params[o + k] = *c;
            }
        }
        let mut row_offsets = Vec::with_capacity(frames.len());
        let mut rows = 0;
        for f in frames {
            row_offsets.push(rows);
            rows += 2 * f.corners.len();
        }
        Problem {
            setup,
            frames,
            layout,
            x0,
            camera0,
            params,
            weights: frames.iter().map(|f| vec![1.0; f.corners.len()]).collect(),
            prior_weights: vec![1.0; frames.len()],
            inv_sigma_px: 1.0 / options.pixel_sigma_px,
            prior: options.robot_prior,
            row_offsets,
            corner_rows: rows,
        }
    }

    fn state(&self) -> State {
        let d = &self.params;
        let v = |k: usize| Vector3::new(d[k], d[k + 1], d[k + 2]);
        let x = Pose::from_parts(
            Translation3::from(self.x0.x.translation.vector + v(3)),
            UnitQuaternion::from_scaled_axis(v(0)) * self.x0.x.rotation,
        );
        let y = Pose::from_parts(
            Translation3::from(self.x0.y.translation.vector + v(9)),
            self.x0.y.rotation * UnitQuaternion::from_scaled_axis(v(6)),
        );
        let mut camera = self.camera0;
        if self.layout.intrinsics > 0 {
            let o = self.layout.intrinsics_offset();
            camera.fx = d[o];
            camera.fy = d[o + 1];
            camera.cx = d[o + 2];
            camera.cy = d[o + 3];
        }
        if self.layout.distortion > 0 {
            let o = self.layout.distortion_offset();
            camera.distortion = with_coefficients(
                &self.camera0.distortion,
                &d.as_slice()[o..o + self.layout.distortion],
            );
        }
        let mut corrections = Vec::with_capacity(self.frames.len());
        let mut b = Vec::with_capacity(self.frames.len());
        for (f, frame) in self.frames.iter().enumerate() {
            let mut robot = frame.base_from_flange;
            if self.layout.robot > 0 {
                let o = self.layout.robot_offset() + 6 * f;
                let (phi, rho) = (v(o), v(o + 3));
                robot = Pose::from_parts(
                    Translation3::from(robot.translation.vector + rho),
                    robot.rotation * UnitQuaternion::from_scaled_axis(phi),
                );
                corrections.push((phi, rho));
            }
            b.push(self.setup.chain_b(&robot));
        }
        State {
            axby: Axby { x, y },
            camera,
            b,
            corrections,
        }
    }

    fn rows(&self) -> usize {
        self.corner_rows + 6 * self.layout.robot.min(1) * self.frames.len()
    }

    /// Pixel error (predicted − detected) of every corner, unweighted.
    fn pixel_errors(&self, s: &State) -> Vec<Vec<Vector2<f64>>> {
        self.frames
            .iter()
            .enumerate()
            .map(|(f, frame)| {
                let chain = s.axby.x * s.b[f] * s.axby.y;
                frame
                    .corners
                    .iter()
                    .map(|c| {
                        let p = chain * c.point_in_target;
                        project(&s.camera, &p.coords).0 - c.pixel.coords
                    })
                    .collect()
            })
            .collect()
    }
}

impl LeastSquaresProblem<f64, Dyn, Dyn> for Problem<'_> {
    type ResidualStorage = Owned<f64, Dyn>;
    type JacobianStorage = Owned<f64, Dyn, Dyn>;
    type ParameterStorage = Owned<f64, Dyn>;

    fn set_params(&mut self, x: &DVector<f64>) {
        self.params.copy_from(x);
    }

    fn params(&self) -> DVector<f64> {
        self.params.clone()
    }

    fn residuals(&self) -> Option<DVector<f64>> {
        let s = self.state();
        let mut out = DVector::zeros(self.rows());
        for (f, errors) in self.pixel_errors(&s).iter().enumerate() {
            let row = self.row_offsets[f];
            for (c, e) in errors.iter().enumerate() {
                let k = self.weights[f][c].sqrt() * self.inv_sigma_px;
                out[row + 2 * c] = e.x * k;
                out[row + 2 * c + 1] = e.y * k;
            }
        }
        if let Some(prior) = self.prior {
            for (f, (phi, rho)) in s.corrections.iter().enumerate() {
                let row = self.corner_rows + 6 * f;
                let k = self.prior_weights[f].sqrt();
                for i in 0..3 {
                    out[row + i] = k * phi[i] / prior.rotation_sigma_rad;
                    out[row + 3 + i] = k * rho[i] / prior.translation_sigma_m;
                }
            }
        }
        out.iter().all(|v| v.is_finite()).then_some(out)
    }

    fn jacobian(&self) -> Option<DMatrix<f64>> {
        let s = self.state();
        let layout = self.layout;
        let n_global = layout.robot_offset();
        let mut j = DMatrix::zeros(self.rows(), layout.len());
        self.corner_jacobians(&s, |f, c, global, robot| {
            let row = self.row_offsets[f] + 2 * c;
            j.view_mut((row, 0), (2, n_global)).copy_from(global);
            if layout.robot > 0 {
                j.fixed_view_mut::<2, 6>(row, layout.robot_offset() + 6 * f)
                    .copy_from(robot);
            }
        });
        if let Some(prior) = self.prior {
            for f in 0..self.frames.len() {
                let row = self.corner_rows + 6 * f;
                let o = layout.robot_offset() + 6 * f;
                let k = self.prior_weights[f].sqrt();
                for i in 0..3 {
                    j[(row + i, o + i)] = k / prior.rotation_sigma_rad;
                    j[(row + 3 + i, o + 3 + i)] = k / prior.translation_sigma_m;
                }
            }
        }
        Some(j)
    }
}

impl Problem<'_> {
    /// Visits each corner's two (weighted) Jacobian rows: the global columns (pose, intrinsics,
    /// distortion: 2 x `robot_offset`) and the 2 x 6 block of its frame's robot correction
    /// (zero without a prior). Every corner touches only these columns: the block structure the
    /// normal equations exploit.
    fn corner_jacobians(
        &self,
        s: &State,
        mut visit: impl FnMut(usize, usize, &DMatrix<f64>, &SMatrix<f64, 2, 6>),
    ) {
        let layout = self.layout;
        let mut global = DMatrix::zeros(2, layout.robot_offset());
        let mut robot = SMatrix::<f64, 2, 6>::zeros();
        let rx = s.axby.x.rotation.to_rotation_matrix().into_inner();
        let ry = s.axby.y.rotation.to_rotation_matrix().into_inner();
        let camera = &s.camera;
        let focal = Matrix2::new(camera.fx, 0.0, 0.0, camera.fy);
        for (f, frame) in self.frames.iter().enumerate() {
            let b = &s.b[f];
            let rb = b.rotation.to_rotation_matrix().into_inner();
            let rxrb = rx * rb;
            let d_phi_y_base = -(rxrb * ry);
            for (c, corner) in frame.corners.iter().enumerate() {
                let p = corner.point_in_target.coords;
                let q = s.axby.y * corner.point_in_target; // in Y's parent frame
                let w = b * q; // in X's right frame
                let pc = s.axby.x * w; // in the camera
                let z = pc.z.max(1e-6);
                let xn = Vector2::new(pc.x / z, pc.y / z);
                let d_norm =
                    Matrix2x3::new(1.0 / z, 0.0, -pc.x / (z * z), 0.0, 1.0 / z, -pc.y / (z * z));
                let d_dist = camera.distortion.jacobian(xn);
                let k = self.weights[f][c].sqrt() * self.inv_sigma_px;
                let d_pix = focal * d_dist * d_norm * k; // 2x3 d pixel / d point_in_camera
                let rxw = pc.coords - s.axby.x.translation.vector;
                global
                    .fixed_view_mut::<2, 3>(0, 0)
                    .copy_from(&(d_pix * (-rxw.cross_matrix())));
                global.fixed_view_mut::<2, 3>(0, 3).copy_from(&d_pix);
                global
                    .fixed_view_mut::<2, 3>(0, 6)
                    .copy_from(&(d_pix * d_phi_y_base * p.cross_matrix()));
                global
                    .fixed_view_mut::<2, 3>(0, 9)
                    .copy_from(&(d_pix * rxrb));
                if layout.intrinsics > 0 || layout.distortion > 0 {
                    let xd = camera.distortion.distort(xn);
                    if layout.intrinsics > 0 {
                        let o = layout.intrinsics_offset();
                        global[(0, o)] = xd.x * k;
                        global[(1, o)] = 0.0;
                        global[(0, o + 1)] = 0.0;
                        global[(1, o + 1)] = xd.y * k;
                        global[(0, o + 2)] = k;
                        global[(1, o + 2)] = 0.0;
                        global[(0, o + 3)] = 0.0;
                        global[(1, o + 3)] = k;
                    }
                    if layout.distortion > 0 {
                        let o = layout.distortion_offset();
                        let dc = distortion_coefficient_jacobian(&camera.distortion, xn);
                        for i in 0..layout.distortion {
                            global[(0, o + i)] = camera.fx * dc[(0, i)] * k;
                            global[(1, o + i)] = camera.fy * dc[(1, i)] * k;
                        }
                    }
                }
                if layout.robot > 0 {
                    // First order in the (tiny) correction itself; exact at zero correction.
                    let (d_phi, d_rho) = match self.setup {
                        Setup::EyeToHand => (-(rb * q.coords.cross_matrix()), Matrix3::identity()),
                        Setup::EyeInHand => (w.coords.cross_matrix(), -rb),
                    };
                    robot
                        .fixed_view_mut::<2, 3>(0, 0)
                        .copy_from(&(d_pix * rx * d_phi));
                    robot
                        .fixed_view_mut::<2, 3>(0, 3)
                        .copy_from(&(d_pix * rx * d_rho));
                }
                visit(f, c, &global, &robot);
            }
        }
    }

    /// The normal equations `JᵀJ` and `Jᵀr` at the current parameters, accumulated corner by
    /// corner from the block structure (never forming the tall Jacobian), and `‖r‖²`.
    fn normal_equations(&self) -> Option<(DMatrix<f64>, DVector<f64>, f64)> {
        let r = self.residuals()?;
        let s = self.state();
        let layout = self.layout;
        let n = layout.len();
        let n_global = layout.robot_offset();
        let mut h = DMatrix::zeros(n, n);
        let mut g = DVector::zeros(n);
        self.corner_jacobians(&s, |f, c, global, robot| {
            let row = self.row_offsets[f] + 2 * c;
            let res = Vector2::new(r[row], r[row + 1]);
            let gt = global.transpose();
            let mut hgg = h.view_mut((0, 0), (n_global, n_global));
            hgg += &gt * global;
            let mut gg = g.rows_mut(0, n_global);
            gg += &gt * res;
            if layout.robot > 0 {
                let o = layout.robot_offset() + 6 * f;
                let cross = &gt * robot;
                let mut hgf = h.view_mut((0, o), (n_global, 6));
                hgf += &cross;
                let mut hfg = h.view_mut((o, 0), (6, n_global));
                hfg += cross.transpose();
                let mut hff = h.fixed_view_mut::<6, 6>(o, o);
                hff += robot.transpose() * robot;
                let mut gf = g.fixed_rows_mut::<6>(o);
                gf += robot.transpose() * res;
            }
        });
        if let Some(prior) = self.prior {
            for f in 0..self.frames.len() {
                let row = self.corner_rows + 6 * f;
                let o = layout.robot_offset() + 6 * f;
                let k = self.prior_weights[f].sqrt();
                for i in 0..6 {
                    let inv = k / if i < 3 {
                        prior.rotation_sigma_rad
                    } else {
                        prior.translation_sigma_m
                    };
                    h[(o + i, o + i)] += inv * inv;
                    g[o + i] += inv * r[row + i];
                }
            }
        }
        Some((h, g, r.norm_squared()))
    }
}

/// The block-structured solver's view: normal equations built corner by corner, re-anchored
/// after every accepted step.
impl NormalEquations for Problem<'_> {
    fn normal_equations(&self) -> Option<(DMatrix<f64>, DVector<f64>, f64)> {
        Problem::normal_equations(self)
    }

    fn cost(&self) -> Option<f64> {
        self.residuals().map(|r| r.norm_squared())
    }

    fn params_mut(&mut self) -> &mut DVector<f64> {
        &mut self.params
    }

    fn accepted(&mut self) {
        reanchor(self);
    }
}

fn rms(values: impl Iterator<Item = f64>) -> f64 {
    let (sum, n) = values.fold((0.0, 0usize), |(s, n), v| (s + v * v, n + 1));
    if n == 0 {
        f64::NAN
    } else {
        (sum / n as f64).sqrt()
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

fn run_lm(problem: Problem<'_>) -> Result<(Problem<'_>, usize, bool), SolveError> {
    if problem.layout.robot > 0 {
        let mut problem = problem;
        let outcome = minimize_normal(&mut problem)?;
        return Ok((problem, outcome.evaluations, outcome.converged));
    }
    let (problem, outcome) = minimize_dense(&LevenbergMarquardt::new().with_patience(50), problem)?;
    Ok((problem, outcome.evaluations, outcome.converged))
}

/// Re-anchors the pose perturbation at the current state so the next Jacobian is exact there.
fn reanchor(problem: &mut Problem<'_>) {
    let s = problem.state();
    problem.x0 = s.axby;
    problem.camera0 = s.camera;
    for k in 0..Layout::POSE {
        problem.params[k] = 0.0;
    }
}

/// LM, then rounds of robust reweighting (each followed by LM) until the weights settle.
fn fit<'a>(
    problem: Problem<'a>,
    options: &ReprojectionOptions,
) -> Result<(Problem<'a>, usize, bool), SolveError> {
    let (mut problem, mut evaluations, mut converged) = run_lm(problem)?;
    if options.robust == RobustLoss::None {
        return Ok((problem, evaluations, converged));
    }
    for _ in 0..options.max_robust_rounds {
        let changed = reweight(&mut problem, options);
        if changed < 1e-3 {
            break;
        }
        reanchor(&mut problem);
        let (p, e, c) = run_lm(problem)?;
        problem = p;
        evaluations += e;
        converged &= c;
    }
    Ok((problem, evaluations, converged))
}

/// Sets every corner's robust weight from its current error, and frees the robot correction of
/// frames whose correction stands far out (see [`robot_outliers`]); returns the largest change.
fn reweight(problem: &mut Problem<'_>, options: &ReprojectionOptions) -> f64 {
    let robust = options.robust;
    let s = problem.state();
    let mut change: f64 = 0.0;
    if let Some(prior) = problem.prior {
        let flagged = robot_outliers(&s, &prior, options.outlier_mad_factor);
        for (f, weight) in problem.prior_weights.iter_mut().enumerate() {
            let new = if flagged.contains(&f) { 0.0 } else { 1.0 };
            change = change.max((new - *weight).abs());
            *weight = new;
        }
    }
    let new: Vec<Vec<f64>> = problem
        .pixel_errors(&s)
        .iter()
        .map(|f| {
            f.iter()
                .map(|e| robust.weight(e.norm() * problem.inv_sigma_px))
                .collect()
        })
        .collect();
    let change = new
        .iter()
        .flatten()
        .zip(problem.weights.iter().flatten())
        .map(|(a, b)| (a - b).abs())
        .fold(change, f64::max);
    problem.weights = new;
    change
}

/// Frames whose robot correction, in prior sigmas, stands out from the others' (median + MAD
/// rule) and exceeds [`ROBOT_OUTLIER_SIGMAS`].
fn robot_outliers(s: &State, prior: &RobotPrior, mad_factor: f64) -> Vec<usize> {
    let sizes: Vec<f64> = (0..s.corrections.len())
        .map(|f| correction_sigmas(s, f, prior))
        .collect();
    flag_outliers(&sizes, mad_factor, ROBOT_OUTLIER_SIGMAS)
}

/// Size of frame `f`'s robot correction in prior sigmas (the norm of the whitened 6-vector).
fn correction_sigmas(s: &State, f: usize, prior: &RobotPrior) -> f64 {
    let (phi, rho) = s.corrections[f];
    ((phi / prior.rotation_sigma_rad).norm_squared()
        + (rho / prior.translation_sigma_m).norm_squared())
    .sqrt()
}

/// A frame's robot correction is flagged beyond this many prior sigmas (6-dof norm; the 99.9 %
/// point of a 6-dof Gaussian is 4.7) when it also stands out from the other frames'.
const ROBOT_OUTLIER_SIGMAS: f64 = 5.0;

/// Most rounds of noise estimation (each a full refit).
const MAX_NOISE_ROUNDS: usize = 10;
/// Noise estimation stops when no sigma changes by more than this fraction (a weight 3 % off
/// moves the answer far less than its uncertainty).
const NOISE_TOLERANCE: f64 = 0.03;
/// The estimated robot repeatability stays within these multiples of the configured one: the
/// configured value is what the user knows about the arm, and a robot group that the pixels
/// explain completely (an exact arm) would otherwise drive its sigma towards zero.
const ROBOT_SIGMA_RANGE: (f64, f64) = (0.1, 100.0);
/// The estimated pixel noise stays within these bounds, px.
const PIXEL_SIGMA_RANGE: (f64, f64) = (0.005, 20.0);

/// One round of variance component estimation (Förstner): per group of observations (corner
/// pixels; the robot prior), sigma² ← sigma² · (weighted residual sum of
/// squares) / (redundancy), where a group's redundancy is its observation count minus its share
/// `tr(N⁻¹·N_group)` of the parameters.
struct NoiseEstimate {
    pixel_sigma_px: f64,
    robot: Option<RobotPrior>,
}

fn estimate_noise(problem: &Problem<'_>) -> Option<NoiseEstimate> {
    let (normal, _, _) = problem.normal_equations()?;
    let covariance = normal.cholesky()?.inverse();
    let residuals = problem.residuals()?;
    let n_params = problem.layout.len() as f64;
    let pixel_sum = residuals.rows(0, problem.corner_rows).norm_squared();
    let scale = |sigma: f64, sum: f64, redundancy: f64| {
        (redundancy >= 1.0).then(|| sigma * (sum / redundancy).sqrt())
    };
    let mut robot = None;
    let mut prior_share = 0.0;
    if let Some(prior) = problem.prior {
        // One scale for the whole prior: the ratio of rotation to translation repeatability
        // stays as configured (pixels barely tell a small flange rotation from a shift). Frames
        // whose correction runs free (weight 0) are not observations of it.
        let mut sum = 0.0;
        let mut count = 0.0;
        for f in 0..problem.frames.len() {
            let row = problem.corner_rows + 6 * f;
            let o = problem.layout.robot_offset() + 6 * f;
            for i in 0..6 {
                let sigma = if i < 3 {
                    prior.rotation_sigma_rad
                } else {
                    prior.translation_sigma_m
                };
                prior_share +=
                    problem.prior_weights[f] * covariance[(o + i, o + i)] / (sigma * sigma);
                count += problem.prior_weights[f];
                sum += residuals[row + i] * residuals[row + i];
            }
        }
        robot = scale(1.0, sum, count - prior_share).map(|k| RobotPrior {
            rotation_sigma_rad: prior.rotation_sigma_rad * k,
            translation_sigma_m: prior.translation_sigma_m * k,
        });
    }
    let pixel_redundancy = problem.corner_rows as f64 - (n_params - prior_share);
    let pixel_sigma_px = scale(1.0 / problem.inv_sigma_px, pixel_sum, pixel_redundancy)?;
    Some(NoiseEstimate {
        pixel_sigma_px,
        robot,
    })
}

impl NoiseEstimate {
    /// Sets the estimate (within the allowed ranges) into the problem; returns the largest
    /// relative change of a sigma.
    fn apply(&self, problem: &mut Problem<'_>, options: &ReprojectionOptions) -> f64 {
        let relative = |new: f64, old: f64| ((new - old) / old).abs();
        let pixel = self
            .pixel_sigma_px
            .clamp(PIXEL_SIGMA_RANGE.0, PIXEL_SIGMA_RANGE.1);
        let mut change = relative(pixel, 1.0 / problem.inv_sigma_px);
        problem.inv_sigma_px = 1.0 / pixel;
        if let (Some(estimate), Some(given), Some(current)) =
            (self.robot, options.robot_prior, problem.prior.as_mut())
        {
            let bounded = |value: f64, given: f64| {
                value.clamp(given * ROBOT_SIGMA_RANGE.0, given * ROBOT_SIGMA_RANGE.1)
            };
            let rotation = bounded(estimate.rotation_sigma_rad, given.rotation_sigma_rad);
            let translation = bounded(estimate.translation_sigma_m, given.translation_sigma_m);
            change = change
                .max(relative(rotation, current.rotation_sigma_rad))
                .max(relative(translation, current.translation_sigma_m));
            current.rotation_sigma_rad = rotation;
            current.translation_sigma_m = translation;
        }
        reanchor(problem);
        change
    }
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
    let (mut problem, mut evaluations, mut converged) = fit(problem, options)?;
    let mut noise_notes = Vec::new();
    // Only true once an estimate was applied: without one the configured noise stands.
    let mut noise_estimated = false;
    if options.estimate_noise {
        for _ in 0..MAX_NOISE_ROUNDS {
            let Some(estimate) = estimate_noise(&problem) else {
                // After an applied round its estimate stands; only say otherwise when none did.
                if !noise_estimated {
                    noise_notes.push(
                        "the noise could not be estimated from the residuals (too few corners or a singular problem): the configured noise is used".to_string(),
                    );
                }
                break;
            };
            let change = estimate.apply(&mut problem, options);
            noise_estimated = true;
            // One LM per round (robust weights following the new sigma), not a full fit: the
            // sigmas and the parameters converge together, and a final fit settles both.
            if options.robust != RobustLoss::None {
                reweight(&mut problem, options);
            }
            let (p, e, c) = run_lm(problem)?;
            problem = p;
            evaluations += e;
            converged &= c;
            if change < NOISE_TOLERANCE {
                break;
            }
        }
        let (p, e, c) = fit(problem, options)?;
        problem = p;
        evaluations += e;
        converged &= c;
        if let (Some(given), Some(used)) = (options.robot_prior, problem.prior) {
            let at_bound = |a: f64, b: f64| {
                let ratio = a / b;
                ratio <= ROBOT_SIGMA_RANGE.0 * 1.0001 || ratio >= ROBOT_SIGMA_RANGE.1 * 0.9999
            };
            if at_bound(used.translation_sigma_m, given.translation_sigma_m)
                || at_bound(used.rotation_sigma_rad, given.rotation_sigma_rad)
            {
                noise_notes.push(format!(
                    "the robot repeatability the residuals show ({:.4} mm, {:.5}°) is at the bound of {}x-{}x the configured one ({:.4} mm, {:.5}°): check the configured repeatability",
                    used.translation_sigma_m * 1e3,
                    used.rotation_sigma_rad.to_degrees(),
                    ROBOT_SIGMA_RANGE.0,
                    ROBOT_SIGMA_RANGE.1,
                    given.translation_sigma_m * 1e3,
                    given.rotation_sigma_rad.to_degrees(),
                ));
            }
        }
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
    let mut warnings = noise_notes;
    if options.covariance {
        let (jtj, _, _) = problem
            .normal_equations()
            .ok_or(SolveError::RefinementFailed("residuals are not finite"))?;
        match jtj.cholesky() {
            Some(chol) => {
                let cov = chol.inverse() * variance_factor;
                let pose_cov: SMatrix<f64, 12, 12> = cov.fixed_view::<12, 12>(0, 0).into();
                uncertainty = Some(mount_uncertainty(&s.axby, &pose_cov, variance_factor));
                if problem.layout.intrinsics > 0 {
                    let o = problem.layout.intrinsics_offset();
                    intrinsics_sigma_px =
                        Some([0, 1, 2, 3].map(|i| cov[(o + i, o + i)].max(0.0).sqrt()));
                }
            }
            None => warnings.push(
                "the reprojection problem is singular at the optimum: no covariance (the frames do not constrain every parameter)"
                    .to_string(),
            ),
        }
    }

    let frame_values: Vec<f64> = errors
        .frame_rms_px
        .iter()
        .map(|v| if v.is_finite() { *v } else { 0.0 })
        .collect();
    let pixel_outliers = flag_outliers(
        &frame_values,
        options.outlier_mad_factor,
        options.outlier_floor_px,
    );
    let mut outlier_frames = pixel_outliers.clone();
    // A frame whose recorded robot pose is far off shows in its correction, not its pixels (the
    // correction absorbs it): flag those too.
    let mut robot_outlier_notes = Vec::new();
    if let Some(prior) = problem.prior {
        for f in (0..frames.len()).filter(|&f| problem.prior_weights[f] == 0.0) {
            let (phi, rho) = s.corrections[f];
            robot_outlier_notes.push(format!(
                "{f}{} ({:.3} mm, {:.4}°: {:.0}x the repeatability the other frames show)",
                frames[f]
                    .id
                    .as_ref()
                    .map(|id| format!(" ({id})"))
                    .unwrap_or_default(),
                rho.norm() * 1e3,
                phi.norm().to_degrees(),
                correction_sigmas(&s, f, &prior) / 6f64.sqrt()
            ));
            outlier_frames.push(f);
        }
        outlier_frames.sort_unstable();
        outlier_frames.dedup();
    }
    let all_corners: Vec<f64> = errors.corner_px.iter().flatten().copied().collect();
    let flagged: Vec<usize> = flag_outliers(
        &all_corners,
        options.outlier_mad_factor,
        options.outlier_floor_px,
    );
    let mut outlier_corners = Vec::with_capacity(flagged.len());
    {
        let mut starts = Vec::with_capacity(frames.len());
        let mut n = 0;
        for f in frames {
            starts.push(n);
            n += f.corners.len();
        }
        for index in flagged {
            let f = starts.partition_point(|&s| s <= index) - 1;
            outlier_corners.push((f, index - starts[f]));
        }
    }
    if !pixel_outliers.is_empty() {
        let described: Vec<String> = pixel_outliers
            .iter()
            .map(|&i| match &frames[i].id {
                Some(id) => format!("{i} ({id}, {:.2} px)", errors.frame_rms_px[i]),
                None => format!("{i} ({:.2} px)", errors.frame_rms_px[i]),
            })
            .collect();
        warnings.push(format!(
            "{} frame(s) reproject far worse than the rest: {} (check detection and robot pose of those frames)",
            pixel_outliers.len(),
            described.join(", ")
        ));
    }
    if !robot_outlier_notes.is_empty() {
        warnings.push(format!(
            "{} frame(s) needed a robot-pose correction far beyond the others: {} (their recorded robot pose and their detections disagree with the other frames; check both; they were left out of the hand-eye fit)",
            robot_outlier_notes.len(),
            robot_outlier_notes.join(", ")
        ));
    }
    if !outlier_corners.is_empty() {
        warnings.push(format!(
            "{} corner(s) have errors far above the rest (down-weighted by the robust loss)",
            outlier_corners.len()
        ));
    }
    if !converged {
        warnings.push(
            "the reprojection refinement did not meet its tolerance; the answer may be inaccurate"
                .to_string(),
        );
    }
    let corrected_base_from_flange = if problem.layout.robot > 0 {
        frames
            .iter()
            .zip(&s.corrections)
            .map(|(frame, (phi, rho))| {
                Pose::from_parts(
                    Translation3::from(frame.base_from_flange.translation.vector + rho),
                    frame.base_from_flange.rotation * UnitQuaternion::from_scaled_axis(*phi),
                )
            })
            .collect()
    } else {
        Vec::new()
    };
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
        uncertainty,
        intrinsics_sigma_px,
        pixel_sigma_px: 1.0 / problem.inv_sigma_px,
        robot_prior: problem.prior,
        noise_estimated,
        errors,
        recorded_pose_errors,
        outlier_frames,
        outlier_corners,
        evaluations,
        converged,
        warnings,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::pose_from_rotvec;

    fn pose(t: [f64; 3], r: [f64; 3]) -> Pose {
        pose_from_rotvec(Vector3::from(t), Vector3::from(r))
    }

    fn camera() -> CameraModel {
        CameraModel {
            width: 1280,
            height: 720,
            fx: 800.0,
            fy: 805.0,
            cx: 641.3,
            cy: 358.7,
            distortion: Distortion::RadTan {
                k1: -0.08,
                k2: 0.05,
                p1: 0.0004,
                p2: -0.0006,
                k3: 0.0,
            },
        }
    }

    fn frames(setup: Setup) -> Vec<Frame> {
        let points: Vec<Point3<f64>> = (0..4)
            .flat_map(|i| (0..3).map(move |j| Point3::new(0.03 * i as f64, 0.04 * j as f64, 0.0)))
            .collect();
        let robots = [
            pose([0.4, 0.1, 0.5], [3.0, 0.1, 0.0]),
            pose([0.5, -0.1, 0.45], [2.8, -0.3, 0.2]),
            pose([0.45, 0.0, 0.55], [3.1, 0.2, -0.3]),
        ];
        robots
            .iter()
            .map(|r| Frame {
                base_from_flange: *r,
                corners: points
                    .iter()
                    .map(|p| Corner {
                        point_in_target: *p,
                        // Off the model, so the robust weights are not all one.
                        pixel: Point2::new(600.0 + 300.0 * p.x, 350.0 - 200.0 * p.y),
                    })
                    .collect(),
                id: None,
            })
            .collect::<Vec<_>>()
            .into_iter()
            .map(|mut f| {
                if setup == Setup::EyeToHand {
                    f.base_from_flange = f.base_from_flange.inverse();
                }
                f
            })
            .collect()
    }

    /// The problem with every parameter block free: mounts, intrinsics, distortion and robot
    /// corrections.
    fn full_problem<'a>(
        setup: Setup,
        frames: &'a [Frame],
        camera_mount: &Pose,
        target_mount: &Pose,
    ) -> Problem<'a> {
        let options = ReprojectionOptions {
            refine_intrinsics: true,
            refine_distortion: true,
            robot_prior: Some(RobotPrior {
                translation_sigma_m: 1e-4,
                rotation_sigma_rad: 1e-4,
            }),
            ..ReprojectionOptions::default()
        };
        Problem::new(
            setup,
            frames,
            Axby::from_mounts(camera_mount, target_mount),
            camera(),
            &options,
        )
    }

    #[test]
    fn analytic_jacobian_matches_finite_differences() {
        for setup in [Setup::EyeInHand, Setup::EyeToHand] {
            let frames = frames(setup);
            let (camera_mount, target_mount) = match setup {
                Setup::EyeInHand => (
                    pose([0.03, -0.07, 0.04], [0.02, -0.01, 1.56]),
                    pose([0.5, -0.15, 0.0], [0.01, 0.02, 0.3]),
                ),
                Setup::EyeToHand => (
                    pose([0.5, 0.0, 1.0], [3.1, 0.0, 0.0]),
                    pose([0.0, 0.02, 0.1], [0.1, 0.2, 0.0]),
                ),
            };
            let mut problem = full_problem(setup, &frames, &camera_mount, &target_mount);
            problem.weights[1][2] = 0.25;
            let analytic = problem.jacobian().unwrap();
            let p0 = problem.params.clone();
            for k in 0..p0.len() {
                // Steps relative to the parameter's size (focal lengths are ~800 px).
                let h = 1e-6 * p0[k].abs().max(1.0);
                problem.params = p0.clone();
                problem.params[k] += h;
                let plus = problem.residuals().unwrap();
                problem.params = p0.clone();
                problem.params[k] -= h;
                let minus = problem.residuals().unwrap();
                let numeric = (plus - minus) / (2.0 * h);
                let scale = numeric.amax().max(1.0);
                let err = (numeric - analytic.column(k)).amax() / scale;
                // Central differences of smooth maps: relative error ~1e-6 at worst.
                assert!(err < 1e-4, "{setup}: column {k}: relative error {err}");
            }
        }
    }

    #[test]
    fn block_normal_equations_match_the_dense_jacobian() {
        for setup in [Setup::EyeInHand, Setup::EyeToHand] {
            let frames = frames(setup);
            let mut problem = full_problem(
                setup,
                &frames,
                &pose([0.03, -0.07, 0.04], [0.02, -0.01, 1.56]),
                &pose([0.5, -0.15, 0.0], [0.01, 0.02, 0.3]),
            );
            // Non-zero corrections so the prior's gradient is tested too.
            let o = problem.layout.robot_offset();
            problem.params[o + 1] = 2e-5;
            problem.params[o + 10] = -3e-5;
            problem.weights[2][5] = 0.5;
            let j = problem.jacobian().unwrap();
            let r = problem.residuals().unwrap();
            let (h, g, _) = problem.normal_equations().unwrap();
            let dense_h = j.transpose() * &j;
            let dense_g = j.transpose() * &r;
            // Same sums in another order: agreement to rounding, relative to the largest entry.
            assert!(
                (&h - &dense_h).amax() <= 1e-9 * dense_h.amax(),
                "{setup}: JᵀJ"
            );
            assert!(
                (&g - &dense_g).amax() <= 1e-9 * dense_g.amax(),
                "{setup}: Jᵀr"
            );
        }
    }
}
