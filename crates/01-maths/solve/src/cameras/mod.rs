//! The joint solve of a cell with several cameras: every camera's mount and the boards
//! in one maximum-likelihood problem in pose space.
//!
//! Cameras on the flange (eye-in-hand) see the board fixed in the cell, `T_base_target`;
//! cameras fixed in the cell (eye-to-hand) see the board on the flange, `T_flange_target`. One
//! board per setup: every eye-in-hand camera shares `T_base_target`, every eye-to-hand camera
//! shares `T_flange_target`. Measurement of camera `c` at robot pose `i`:
//!
//! * eye-in-hand: `T_camera_target = inv(T_flange_camera_c) · inv(T_base_flange_i) · T_base_target`;
//! * eye-to-hand: `T_camera_target = inv(T_base_camera_c) · T_base_flange_i · T_flange_target`.
//!
//! What ties the cameras together is that they share the board transform of their setup (two
//! fixed cameras that see the flange board at the same pose measure the same `T_flange_target`)
//! and the flange poses. Solving each camera alone fits its own copy of the board transform,
//! whose error then enters the camera's mount; the joint solve fits one, from every camera's
//! views. The camera-to-camera transforms of cameras of one setup (`T_cam_left_cam_right`) are
//! then the relative pose of two mounts solved against one board, with a 1-sigma from the joint
//! covariance (their correlated parts cancel), rather than two independent answers chained.
//!
//! Residual of one observation (6 numbers, camera frame): rotation `Log(R_pred · R_measᵀ) / σ_r`
//! and translation `(t_pred − t_meas) / σ_t`, with the camera's own sigmas: a fixed camera 1 m
//! away sees the board noisier than a wrist camera at 0.3 m. The sigmas are estimated from each
//! camera's residuals alternated with the fit (variance components per camera), unless given.
//! Each unknown `T_a_b` is perturbed as `R ← exp(δθ)·R, t ← t + δt` in frame `a`, the convention
//! of [`PoseSigma`], so covariance blocks read directly as the mounts' 1-sigma. The Jacobian is
//! by central differences over the 12 parameters an observation touches (6 of its camera, 6 of
//! its board): the problem is small (6 per camera + 6 per board) and this keeps one code path for
//! both setups. Pure maths: no I/O, no clock.

use nalgebra::{DMatrix, DVector, Matrix6, SVector, Translation3, UnitQuaternion, Vector3};

use super::arrow::{inverse_parts, NormalMatrix};
use super::lm::{minimize_normal, NormalEquations};
use super::refine::pose_sigma;
use super::{NoiseModel, PoseSigma};
use handeye_core::geometry::Pose;
use handeye_core::setup::Setup;

mod pixels;
pub use pixels::{solve_cameras_pixels, CamerasFrame};

/// One camera of the cell.
#[derive(Debug, Clone, PartialEq)]
pub struct CameraSpec {
    /// Its name (`wrist`, `left`): frames are named `cam_<name>` in results.
    pub name: String,
    /// On the flange or fixed in the cell.
    pub setup: Setup,
    /// Noise of its `T_camera_target` (the start when estimated).
    pub noise: NoiseModel,
}

/// One board pose seen by one camera at one robot pose.
#[derive(Debug, Clone, PartialEq)]
pub struct CamerasObservation {
    /// Index into [`CamerasData::cameras`].
    pub camera: usize,
    /// Index into [`CamerasData::base_from_flange`].
    pub pose: usize,
    /// `T_camera_target` as PnP reports it.
    pub camera_from_target: Pose,
    /// Its inverse variance relative to the camera's noise model (1: a typical view; the
    /// one-camera solve's view weight, `crate::view_weighted`).
    pub weight: f64,
}

/// Everything the joint solve reads: the cameras, the robot poses (shared by every camera), the
/// observations.
#[derive(Debug, Clone, PartialEq)]
pub struct CamerasData {
    /// The cameras.
    pub cameras: Vec<CameraSpec>,
    /// `T_base_flange` as the robot reported it, per pose.
    pub base_from_flange: Vec<Pose>,
    /// Every accepted board pose, any camera, any robot pose.
    pub observations: Vec<CamerasObservation>,
}

impl CamerasData {
    /// The data of camera `camera` alone (same robot poses, only its observations): what a
    /// single-camera solve of that camera sees.
    pub fn only(&self, camera: usize) -> CamerasData {
        CamerasData {
            cameras: vec![self.cameras[camera].clone()],
            base_from_flange: self.base_from_flange.clone(),
            observations: self
                .observations
                .iter()
                .filter(|o| o.camera == camera)
                .map(|o| CamerasObservation {
                    camera: 0,
                    ..o.clone()
                })
                .collect(),
        }
    }

    /// Observations of camera `camera`.
    pub fn count(&self, camera: usize) -> usize {
        self.observations
            .iter()
            .filter(|o| o.camera == camera)
            .count()
    }

    fn has(&self, setup: Setup) -> bool {
        self.cameras.iter().any(|c| c.setup == setup)
    }
}

/// Where the joint solve starts (each camera's own answer, typically).
#[derive(Debug, Clone, PartialEq)]
pub struct CamerasStart {
    /// Per camera: `T_flange_camera` (eye-in-hand) or `T_base_camera` (eye-to-hand).
    pub camera_mounts: Vec<Pose>,
    /// `T_base_target`, needed when some camera is eye-in-hand.
    pub base_from_target: Option<Pose>,
    /// `T_flange_target`, needed when some camera is eye-to-hand.
    pub flange_from_target: Option<Pose>,
}

/// How the joint solve runs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CamerasOptions {
    /// Estimate each camera's noise from its residuals (otherwise [`CameraSpec::noise`] is used
    /// as given).
    pub estimate_noise: bool,
    /// Most Levenberg-Marquardt iterations per fit.
    pub max_iterations: usize,
    /// The pixel-space solve estimates every flange pose too, around the reported one with this
    /// 1-sigma per axis (m, rad: the robot's repeatability); every camera that sees the board at
    /// a pose then corrects the flange pose the others use. `None`: flange poses are exact.
    pub robot_sigma: Option<(f64, f64)>,
}

impl Default for CamerasOptions {
    fn default() -> Self {
        CamerasOptions {
            estimate_noise: true,
            max_iterations: 100,
            robot_sigma: None,
        }
    }
}

/// The relative pose of two cameras of one setup, `T_cam_<from>_cam_<to>`.
#[derive(Debug, Clone, PartialEq)]
pub struct RelativeMount {
    /// Index of the camera whose frame the pose is expressed in.
    pub from: usize,
    /// Index of the other camera.
    pub to: usize,
    /// `T_cam_from_cam_to` (`inv(mount_from) · mount_to`).
    pub pose: Pose,
    /// Its 1-sigma from the joint covariance.
    pub sigma: PoseSigma,
}

/// A camera's residuals at the optimum.
#[derive(Debug, Clone, PartialEq)]
pub struct CamerasResiduals {
    /// Observations used.
    pub samples: usize,
    /// RMS rotation residual, degrees.
    pub rotation_rms_deg: f64,
    /// RMS translation residual, mm.
    pub translation_rms_mm: f64,
    /// Each of its observations' residual, in the order of the data's observations.
    pub per_pose: Vec<PoseResidual>,
}

/// One observation's residual at the optimum (the pose-space residual of the one-camera solve:
/// how far the board pose it saw is from the one the answer predicts there).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoseResidual {
    /// The pose (index into [`CamerasData::base_from_flange`]).
    pub pose: usize,
    /// Rotation residual, rad.
    pub rotation_rad: f64,
    /// Translation residual, m.
    pub translation_m: f64,
    /// The observation's weight ([`CamerasObservation::weight`]): its residual counts for this
    /// much in the fit and in the camera's noise estimate.
    pub weight: f64,
}

/// The joint answer.
#[derive(Debug, Clone, PartialEq)]
pub struct CamerasSolution {
    /// Per camera: `T_flange_camera` or `T_base_camera`.
    pub camera_mounts: Vec<Pose>,
    /// Per camera: 1-sigma of its mount.
    pub camera_sigmas: Vec<PoseSigma>,
    /// `T_base_target` with its 1-sigma (when some camera is eye-in-hand).
    pub base_from_target: Option<(Pose, PoseSigma)>,
    /// `T_flange_target` with its 1-sigma (when some camera is eye-to-hand).
    pub flange_from_target: Option<(Pose, PoseSigma)>,
    /// Every pair of cameras of one setup, `from < to`.
    pub relative: Vec<RelativeMount>,
    /// Per camera: the board-pose noise the pose-space fit ended with.
    pub noise: Vec<NoiseModel>,
    /// Per camera: the corner noise (1-sigma per pixel axis) of the pixel-space fit; empty for
    /// the pose-space answer.
    pub pixel_sigma_px: Vec<f64>,
    /// Per camera: residuals.
    pub residuals: Vec<CamerasResiduals>,
    /// Covariance of the unknowns (6 per camera, then `T_base_target`, then `T_flange_target`
    /// where present; each `[δθ, δt]`): the unknowns' block of the whole inverse, so the
    /// pixel-space solve's per-pose flange corrections, when estimated, are accounted for
    /// without being listed.
    pub covariance: DMatrix<f64>,
    /// `χ²/dof` at the optimum (≈ 1 when the noise model fits).
    pub variance_factor: f64,
    /// Levenberg-Marquardt evaluations (normal-equation builds and trial steps) over all noise
    /// rounds, and for the pixel-space answer the pose-space ones before it.
    pub iterations: usize,
}

/// Why the joint solve failed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CamerasError {
    /// A camera without enough views to be solved.
    #[error("camera `{camera}` saw the board at {found} poses; a joint solve needs at least {required} per camera: add poses where it sees its board, or leave it out of the cell")]
    TooFewViews {
        /// The camera's name.
        camera: String,
        /// Its observations.
        found: usize,
        /// The least accepted.
        required: usize,
    },
    /// The start lacks a value the data needs (a mount per camera, a board per setup).
    #[error("the start has no {0}")]
    MissingStart(&'static str),
    /// An observation names a camera or pose that does not exist.
    #[error(
        "observation {index} names camera {camera} / pose {pose}, which the data does not have"
    )]
    BadIndex {
        /// The observation's index.
        index: usize,
        /// Its camera index.
        camera: usize,
        /// Its pose index.
        pose: usize,
    },
    /// A residual is not finite (NaN or infinite): some input is (residuals are clamped
    /// everywhere else, a corner behind its camera included).
    #[error("the joint fit's residuals are not finite: a flange pose, board pose, corner or starting mount holds a NaN or an infinite number; check the samples and each camera's starting mount")]
    NotFinite,
    /// The normal equations are singular (a camera whose views do not constrain its mount).
    #[error("the joint problem is singular: the views do not constrain every camera's mount (each camera needs views with rotations about two axes)")]
    Singular,
}

/// Fewest views per camera: 3 constrain both unknowns of one camera in `A = X·B·Y`.
pub const MIN_VIEWS_PER_CAMERA: usize = 3;

/// Parameter layout: 6 per camera, then the boards present.
#[derive(Debug, Clone, Copy)]
struct Layout {
    cameras: usize,
    fixed_board: Option<usize>,
    flange_board: Option<usize>,
}

impl Layout {
    fn new(data: &CamerasData) -> Layout {
        let mut next = 6 * data.cameras.len();
        let mut take = |present: bool| {
            present.then(|| {
                let at = next;
                next += 6;
                at
            })
        };
        let fixed_board = take(data.has(Setup::EyeInHand));
        let flange_board = take(data.has(Setup::EyeToHand));
        Layout {
            cameras: data.cameras.len(),
            fixed_board,
            flange_board,
        }
    }

    fn len(&self) -> usize {
        6 * self.cameras
            + 6 * (self.fixed_board.is_some() as usize + self.flange_board.is_some() as usize)
    }

    fn board_of(&self, setup: Setup) -> usize {
        match setup {
            Setup::EyeInHand => self.fixed_board,
            Setup::EyeToHand => self.flange_board,
        }
        .expect("a camera's setup always has its board in the layout")
    }
}

/// The unknowns as poses, indexed like the layout (cameras, then boards).
#[derive(Debug, Clone)]
struct State {
    poses: Vec<Pose>,
}

/// `T` moved by `[δθ, δt]`: `R ← exp(δθ)·R`, `t ← t + δt`.
fn perturb(pose: &Pose, delta: &SVector<f64, 6>) -> Pose {
    Pose::from_parts(
        Translation3::from(pose.translation.vector + Vector3::new(delta[3], delta[4], delta[5])),
        UnitQuaternion::from_scaled_axis(Vector3::new(delta[0], delta[1], delta[2]))
            * pose.rotation,
    )
}

/// `[Log(R_a·R_bᵀ), t_a − t_b]`: the difference of two poses in the perturbation's terms.
fn difference(a: &Pose, b: &Pose) -> SVector<f64, 6> {
    let r = (a.rotation * b.rotation.inverse()).scaled_axis();
    let t = a.translation.vector - b.translation.vector;
    SVector::<f64, 6>::new(r.x, r.y, r.z, t.x, t.y, t.z)
}

fn predict(setup: Setup, mount: &Pose, board: &Pose, base_from_flange: &Pose) -> Pose {
    handeye_core::setup::predict(setup, mount, board, base_from_flange)
}

/// Whitened residual of one observation.
fn residual(
    setup: Setup,
    noise: &NoiseModel,
    mount: &Pose,
    board: &Pose,
    base_from_flange: &Pose,
    measured: &Pose,
) -> SVector<f64, 6> {
    let mut d = difference(&predict(setup, mount, board, base_from_flange), measured);
    for k in 0..3 {
        d[k] /= noise.rotation_sigma_rad;
        d[k + 3] /= noise.translation_sigma_m;
    }
    d
}

/// Central-difference step for the Jacobian (radians and metres alike: both unknowns are
/// O(1) in those units).
const STEP: f64 = 1e-6;

/// Normal equations `JᵀJ` (dense: 6 per camera and per board), `Jᵀr` and the cost `Σ r²` at
/// `state`.
fn normal_equations(
    data: &CamerasData,
    layout: &Layout,
    state: &State,
    noise: &[NoiseModel],
) -> Normal {
    let n = layout.len();
    let mut jtj = DMatrix::<f64>::zeros(n, n);
    let mut jtr = DVector::<f64>::zeros(n);
    let mut cost = 0.0;
    for o in &data.observations {
        let setup = data.cameras[o.camera].setup;
        let (ci, bi) = (6 * o.camera, layout.board_of(setup));
        let mount = state.poses[o.camera];
        let board = state.poses[bi / 6];
        let flange = &data.base_from_flange[o.pose];
        let nm = &noise[o.camera];
        let scale = o.weight.sqrt();
        let r = scale * residual(setup, nm, &mount, &board, flange, &o.camera_from_target);
        let mut j = nalgebra::SMatrix::<f64, 6, 12>::zeros();
        for k in 0..12 {
            let mut delta = SVector::<f64, 6>::zeros();
            delta[k % 6] = STEP;
            let (m_plus, b_plus, m_minus, b_minus) = if k < 6 {
                (
                    perturb(&mount, &delta),
                    board,
                    perturb(&mount, &(-delta)),
                    board,
                )
            } else {
                (
                    mount,
                    perturb(&board, &delta),
                    mount,
                    perturb(&board, &(-delta)),
                )
            };
            let plus = residual(setup, nm, &m_plus, &b_plus, flange, &o.camera_from_target);
            let minus = residual(setup, nm, &m_minus, &b_minus, flange, &o.camera_from_target);
            j.set_column(k, &((plus - minus) * (scale / (2.0 * STEP))));
        }
        let jtj_local = j.transpose() * j;
        let jtr_local = j.transpose() * r;
        let at = [ci, bi];
        for (a, &ra) in at.iter().enumerate() {
            for (b, &rb) in at.iter().enumerate() {
                let mut block = jtj.view_mut((ra, rb), (6, 6));
                block += jtj_local.fixed_view::<6, 6>(6 * a, 6 * b);
            }
            let mut g = jtr.rows_mut(ra, 6);
            g += jtr_local.fixed_rows::<6>(6 * a);
        }
        cost += r.norm_squared();
    }
    (NormalMatrix::Dense(jtj), jtr, cost)
}

fn cost(data: &CamerasData, layout: &Layout, state: &State, noise: &[NoiseModel]) -> f64 {
    data.observations
        .iter()
        .map(|o| {
            let setup = data.cameras[o.camera].setup;
            let bi = layout.board_of(setup);
            let board = state.poses[bi / 6];
            o.weight
                * residual(
                    setup,
                    &noise[o.camera],
                    &state.poses[o.camera],
                    &board,
                    &data.base_from_flange[o.pose],
                    &o.camera_from_target,
                )
                .norm_squared()
        })
        .sum()
}

fn stepped(state: &State, step: &DVector<f64>) -> State {
    State {
        poses: state
            .poses
            .iter()
            .enumerate()
            .map(|(p, pose)| perturb(pose, &step.fixed_rows::<6>(6 * p).into_owned()))
            .collect(),
    }
}

/// `JᵀJ`, `Jᵀr` and the cost `Σ r²` at one state.
type Normal = (NormalMatrix, DVector<f64>, f64);

/// A joint problem for [`minimize_normal`], the Levenberg-Marquardt every refinement of the crate
/// runs: the unknowns' poses are the point the normal equations are built at, the parameters a
/// step `[δθ, δt]` per pose from it, folded into the poses after every accepted step (so each
/// linearisation is exact at its point, as the perturbation's Jacobian assumes).
struct Anchored<'p> {
    state: State,
    step: DVector<f64>,
    max_iterations: usize,
    normal: &'p dyn Fn(&State) -> Normal,
    cost: &'p dyn Fn(&State) -> f64,
}

impl NormalEquations for Anchored<'_> {
    fn normal_equations(&mut self) -> Option<Normal> {
        let (h, g, cost) = (self.normal)(&stepped(&self.state, &self.step));
        cost.is_finite().then_some((h, g, cost))
    }

    fn cost(&mut self) -> Option<f64> {
        Some((self.cost)(&stepped(&self.state, &self.step))).filter(|c| c.is_finite())
    }

    fn params_mut(&mut self) -> &mut DVector<f64> {
        &mut self.step
    }

    fn accepted(&mut self) {
        self.state = stepped(&self.state, &self.step);
        self.step.fill(0.0);
    }

    fn max_iterations(&self) -> usize {
        self.max_iterations
    }
}

/// Minimises the cost whose normal equations `normal` builds (`cost` alone for trial steps) from
/// `state`, leaving `state` at the minimum; returns the evaluations spent. Shared by the
/// pose-space and the pixel-space solve.
fn minimize(
    state: &mut State,
    max_iterations: usize,
    normal: &dyn Fn(&State) -> Normal,
    cost: &dyn Fn(&State) -> f64,
) -> Result<usize, CamerasError> {
    let mut problem = Anchored {
        step: DVector::zeros(6 * state.poses.len()),
        state: state.clone(),
        max_iterations,
        normal,
        cost,
    };
    let outcome = minimize_normal(&mut problem).map_err(|_| CamerasError::NotFinite)?;
    *state = problem.state;
    Ok(outcome.evaluations)
}

/// Per-camera residual figures (unwhitened) at `state`.
fn residual_figures(data: &CamerasData, layout: &Layout, state: &State) -> Vec<Vec<PoseResidual>> {
    let mut per_camera = vec![Vec::new(); data.cameras.len()];
    let unit = NoiseModel {
        rotation_sigma_rad: 1.0,
        translation_sigma_m: 1.0,
    };
    for o in &data.observations {
        let setup = data.cameras[o.camera].setup;
        let bi = layout.board_of(setup);
        let board = state.poses[bi / 6];
        let r = residual(
            setup,
            &unit,
            &state.poses[o.camera],
            &board,
            &data.base_from_flange[o.pose],
            &o.camera_from_target,
        );
        per_camera[o.camera].push(PoseResidual {
            pose: o.pose,
            rotation_rad: r.fixed_rows::<3>(0).norm(),
            translation_m: r.fixed_rows::<3>(3).norm(),
            weight: o.weight,
        });
    }
    per_camera
}

/// Rounds of noise estimation alternated with the fit.
const NOISE_ROUNDS: usize = 4;

/// Solves every camera's mount and the boards jointly from `start`.
///
/// Errors: a camera with fewer than [`MIN_VIEWS_PER_CAMERA`] observations (named), a start
/// without a mount per camera or without the board a setup needs, an observation pointing
/// nowhere, or views that leave some mount unconstrained.
pub fn solve_cameras(
    data: &CamerasData,
    start: &CamerasStart,
    options: &CamerasOptions,
) -> Result<CamerasSolution, CamerasError> {
    for (index, o) in data.observations.iter().enumerate() {
        if o.camera >= data.cameras.len() || o.pose >= data.base_from_flange.len() {
            return Err(CamerasError::BadIndex {
                index,
                camera: o.camera,
                pose: o.pose,
            });
        }
    }
    for (c, camera) in data.cameras.iter().enumerate() {
        let found = data.count(c);
        if found < MIN_VIEWS_PER_CAMERA {
            return Err(CamerasError::TooFewViews {
                camera: camera.name.clone(),
                found,
                required: MIN_VIEWS_PER_CAMERA,
            });
        }
    }
    if start.camera_mounts.len() != data.cameras.len() {
        return Err(CamerasError::MissingStart("mount for every camera"));
    }
    let layout = Layout::new(data);
    let mut poses = start.camera_mounts.clone();
    if layout.fixed_board.is_some() {
        poses.push(
            start
                .base_from_target
                .ok_or(CamerasError::MissingStart("T_base_target"))?,
        );
    }
    if layout.flange_board.is_some() {
        poses.push(
            start
                .flange_from_target
                .ok_or(CamerasError::MissingStart("T_flange_target"))?,
        );
    }
    let mut state = State { poses };
    let mut noise: Vec<NoiseModel> = data.cameras.iter().map(|c| c.noise).collect();
    let n_residuals = 6 * data.observations.len();
    // Each camera's share of the redundancy: the unknowns take the same fraction of every
    // camera's residual degrees of freedom (exact when the cameras see alike; close enough to
    // weight cameras whose noise differs several-fold).
    let redundancy = 1.0 - layout.len() as f64 / n_residuals as f64;
    let mut iterations = 0;
    let rounds = if options.estimate_noise {
        NOISE_ROUNDS
    } else {
        1
    };
    for round in 0..rounds {
        iterations += minimize(
            &mut state,
            options.max_iterations,
            &|s| normal_equations(data, &layout, s, &noise),
            &|s| cost(data, &layout, s, &noise),
        )?;
        if options.estimate_noise && round + 1 < rounds {
            for (c, per_pose) in residual_figures(data, &layout, &state)
                .into_iter()
                .enumerate()
            {
                let (rot, trans) = per_pose.iter().fold((0.0, 0.0), |(r, t), p| {
                    (
                        r + p.weight * p.rotation_rad.powi(2),
                        t + p.weight * p.translation_m.powi(2),
                    )
                });
                let dof = (3.0 * per_pose.len() as f64 * redundancy).max(1.0);
                noise[c] = NoiseModel {
                    rotation_sigma_rad: (rot / dof).sqrt().max(1e-7),
                    translation_sigma_m: (trans / dof).sqrt().max(1e-7),
                };
            }
        }
    }
    let (jtj, _, chi2) = normal_equations(data, &layout, &state, &noise);
    let dof = (n_residuals as f64 - layout.len() as f64).max(1.0);
    finish(
        data,
        &layout,
        state,
        &jtj,
        chi2 / dof,
        noise,
        Vec::new(),
        iterations,
    )
}

/// The answer at `state` with the covariance `(JᵀJ)⁻¹·variance_factor` (whitened `J`) over the
/// unknowns (an arrowhead's per-pose parameters are inverted through, not kept).
#[allow(clippy::too_many_arguments)]
fn finish(
    data: &CamerasData,
    layout: &Layout,
    state: State,
    jtj: &NormalMatrix,
    variance_factor: f64,
    noise: Vec<NoiseModel>,
    pixel_sigma_px: Vec<f64>,
    iterations: usize,
) -> Result<CamerasSolution, CamerasError> {
    let covariance = inverse_parts(jtj).ok_or(CamerasError::Singular)?.global * variance_factor;
    let block = |at: usize| -> Matrix6<f64> { covariance.fixed_view::<6, 6>(at, at).into_owned() };
    let camera_sigmas = (0..data.cameras.len())
        .map(|c| pose_sigma(&block(6 * c)))
        .collect();
    let board = |at: Option<usize>| at.map(|at| (state.poses[at / 6], pose_sigma(&block(at))));
    let relative = relative_mounts(data, &state, &covariance);
    let residuals = residual_figures(data, layout, &state)
        .into_iter()
        .map(|per_pose| {
            let n = per_pose.len().max(1) as f64;
            let rms = |value: fn(&PoseResidual) -> f64| {
                (per_pose.iter().map(|r| value(r).powi(2)).sum::<f64>() / n).sqrt()
            };
            CamerasResiduals {
                samples: per_pose.len(),
                rotation_rms_deg: rms(|r| r.rotation_rad).to_degrees(),
                translation_rms_mm: rms(|r| r.translation_m) * 1e3,
                per_pose,
            }
        })
        .collect();
    Ok(CamerasSolution {
        camera_mounts: state.poses[..layout.cameras].to_vec(),
        camera_sigmas,
        base_from_target: board(layout.fixed_board),
        flange_from_target: board(layout.flange_board),
        relative,
        noise,
        pixel_sigma_px,
        residuals,
        covariance,
        variance_factor,
        iterations,
    })
}

/// `T_cam_i_cam_j` for every pair of cameras of one setup, with the covariance propagated
/// through the relative pose (numerically: the map is smooth and only 12 parameters wide).
fn relative_mounts(
    data: &CamerasData,
    state: &State,
    covariance: &DMatrix<f64>,
) -> Vec<RelativeMount> {
    let mut out = Vec::new();
    for i in 0..data.cameras.len() {
        for j in i + 1..data.cameras.len() {
            if data.cameras[i].setup != data.cameras[j].setup {
                // A wrist camera and a fixed camera have no fixed relative pose: it changes
                // with every flange pose.
                continue;
            }
            let (mi, mj) = (state.poses[i], state.poses[j]);
            let pose = mi.inverse() * mj;
            let mut jac = nalgebra::SMatrix::<f64, 6, 12>::zeros();
            for k in 0..12 {
                let mut delta = SVector::<f64, 6>::zeros();
                delta[k % 6] = STEP;
                let at = |d: &SVector<f64, 6>| {
                    if k < 6 {
                        perturb(&mi, d).inverse() * mj
                    } else {
                        mi.inverse() * perturb(&mj, d)
                    }
                };
                let column = (difference(&at(&delta), &pose) - difference(&at(&(-delta)), &pose))
                    / (2.0 * STEP);
                jac.set_column(k, &column);
            }
            let mut sub = nalgebra::SMatrix::<f64, 12, 12>::zeros();
            for (a, ra) in [6 * i, 6 * j].into_iter().enumerate() {
                for (b, rb) in [6 * i, 6 * j].into_iter().enumerate() {
                    sub.fixed_view_mut::<6, 6>(6 * a, 6 * b)
                        .copy_from(&covariance.fixed_view::<6, 6>(ra, rb));
                }
            }
            let cov = jac * sub * jac.transpose();
            out.push(RelativeMount {
                from: i,
                to: j,
                pose,
                sigma: pose_sigma(&cov),
            });
        }
    }
    out
}

/// Rotation (degrees) and translation (mm) between two poses: how far an answer is from a
/// reference.
pub fn pose_error(answer: &Pose, reference: &Pose) -> (f64, f64) {
    let d = difference(answer, reference);
    (
        Vector3::new(d[0], d[1], d[2]).norm().to_degrees(),
        Vector3::new(d[3], d[4], d[5]).norm() * 1e3,
    )
}

#[cfg(test)]
mod tests;
