//! The reprojection problem: its parameter layout, the residuals (pixel errors whitened by the
//! corner noise, and the Gaussian prior on the robot corrections) and their analytic Jacobian,
//! as normal equations accumulated block by block for [`crate::lm::minimize_normal`].
//!
//! Parameters: a local perturbation of X and Y (see [`crate::refine::perturbed`]); then
//! `fx fy cx cy` (px) and the distortion coefficients when free (packed and differentiated by
//! [`handeye_core::camera_model`]); then the board scale when free (the factor on every board
//! point, for the cell model's "board not the size its file says"); then the arm's free joint
//! zero offsets (their change from the start, rad); then per frame a robot correction
//! `T_base_flange ← (R·exp(φ), t + ρ)`. Each corner row touches at most 12 + 9 + 1 + 6 global
//! columns and the 6 columns of its own frame's correction.
//!
//! Depends on the ground floor (`geometry`, `setup`, `camera_model`), the shared parametrisation
//! and solver interface of `solve` (`refine::perturbed`, `lm::NormalEquations`) and nalgebra.

use nalgebra::{
    DMatrix, DVector, Matrix3, Point3, SMatrix, Translation3, UnitQuaternion, Vector2, Vector3,
};

use super::{ArmOffsetsFree, Frame, RefinedOffset, ReprojectionOptions, RobotPrior};
use crate::arrow::{Arrowhead, NormalMatrix};
use crate::lm::NormalEquations;
use crate::refine::perturbed;
use crate::Axby;
use handeye_core::camera_model::CameraModel;
use handeye_core::geometry::Pose;
use handeye_core::setup::Setup;

/// Column layout of the parameter vector: pose, intrinsics, distortion, robot corrections.
#[derive(Debug, Clone, Copy)]
pub(super) struct Layout {
    /// Intrinsics columns (4 or 0).
    pub intrinsics: usize,
    /// Distortion coefficient columns (the model's count, or 0).
    pub distortion: usize,
    /// Board scale column (1 or 0): the factor on every board point (`0.95`: the board is 0.95×
    /// the size its file says).
    pub board_scale: usize,
    /// Columns of the arm's free joint offsets (their change from the start).
    pub arm: usize,
    /// Columns per frame's robot correction (6 or 0).
    pub robot: usize,
    /// Frames.
    pub frames: usize,
}

impl Layout {
    /// Columns of the pose perturbation (φ_X, ρ_X, φ_Y, ρ_Y).
    pub(super) const POSE: usize = 12;
    /// First intrinsics column.
    pub(super) fn intrinsics_offset(&self) -> usize {
        Self::POSE
    }
    /// First distortion column.
    pub(super) fn distortion_offset(&self) -> usize {
        Self::POSE + self.intrinsics
    }
    /// The board scale column (when free).
    pub(super) fn board_scale_offset(&self) -> usize {
        Self::POSE + self.intrinsics + self.distortion
    }
    /// First arm-offset column.
    pub(super) fn arm_offset(&self) -> usize {
        Self::POSE + self.intrinsics + self.distortion + self.board_scale
    }
    /// First robot-correction column (= number of global columns).
    pub(super) fn robot_offset(&self) -> usize {
        self.arm_offset() + self.arm
    }
    /// All columns.
    pub(super) fn len(&self) -> usize {
        self.robot_offset() + self.robot * self.frames
    }
}

/// The problem at its current parameters and weights.
pub(super) struct Problem<'a> {
    /// Which of the cell's transforms are unknown.
    pub setup: Setup,
    /// The observations (frames without corners contribute no rows).
    pub frames: &'a [Frame],
    /// Which parameter blocks are free, and where they sit.
    pub layout: Layout,
    /// Anchor of the pose perturbation.
    pub x0: Axby,
    /// Camera at the anchor (its distortion variant decides the coefficient meaning).
    pub camera0: CameraModel,
    /// The parameters, see [`Layout`].
    pub params: DVector<f64>,
    /// Per frame, per corner: robust weight (sqrt applied when used).
    pub weights: Vec<Vec<f64>>,
    /// Per frame: 1, or 0 for a frame whose recorded robot pose is far off (its correction then
    /// runs free, so it neither drags the others' corrections along nor the estimated
    /// repeatability up).
    pub prior_weights: Vec<f64>,
    /// 1 / corner noise sigma, 1/px: whitens the pixel residuals.
    pub inv_sigma_px: f64,
    /// The board scale when it is held (the options' `board_scale`).
    pub board_scale: f64,
    /// The prior on the robot corrections (`None`: robot poses exact, no correction columns).
    pub prior: Option<RobotPrior>,
    /// Rows of each frame's first corner.
    pub row_offsets: Vec<usize>,
    /// Rows of all corners (the prior's rows follow).
    pub corner_rows: usize,
    /// The arm's joint offsets refined, with each frame's joints and its flange at the start.
    pub arm: Option<ArmColumns>,
    /// The residuals of the last trial step of [`crate::lm::minimize_normal`], kept for the
    /// normal equations that follow when the step is taken (re-anchoring moves no parameter
    /// value: they are the residuals of the same point, to the bit). Dropped when the
    /// parameters move and when the minimisation ends.
    trial_residuals: Option<DVector<f64>>,
}

/// [`ArmOffsetsFree`] laid out by frame.
pub(super) struct ArmColumns {
    /// What was asked.
    pub free: ArmOffsetsFree,
    /// Per frame: its joints and `FK(q, start)⁻¹` (`None`: a frame without joints keeps its
    /// pose).
    pub frames: Vec<Option<(Vec<f64>, Pose)>>,
}

/// The joint step of the arm columns' flange twists (forward differences), rad.
const ARM_STEP_RAD: f64 = 1e-7;

impl ArmColumns {
    fn new(free: &ArmOffsetsFree, frames: &[Frame]) -> ArmColumns {
        let per_frame = frames
            .iter()
            .map(|frame| {
                let id = frame.id.as_deref()?;
                let (_, q) = free.joints.iter().find(|(name, _)| name == id)?;
                let start = free.chain.forward_corrected(q, &free.start).inverse();
                Some((q.clone(), start))
            })
            .collect();
        ArmColumns {
            free: free.clone(),
            frames: per_frame,
        }
    }

    /// The move of frame `f`'s flange by the offsets' change `delta` (one per free joint):
    /// `FK(q, start)⁻¹ · FK(q, start + δ)`, in the flange frame; `None` for a frame without
    /// joints.
    fn flange_move(&self, f: usize, delta: &[f64]) -> Option<Pose> {
        let (q, start_inverse) = self.frames[f].as_ref()?;
        let mut corrections = self.free.start.clone();
        for (&joint, d) in self.free.free.iter().zip(delta) {
            corrections[joint][0] += d;
        }
        Some(start_inverse * self.free.chain.forward_corrected(q, &corrections))
    }

    /// Frame `f`'s recorded pose `reported` moved by the offsets' change `delta`, with the flange
    /// twist of each free offset there (6 x free, forward differences; rows `φ` in the flange
    /// frame then `ρ` in the base frame: the robot correction's coordinates); `None` for a frame
    /// without joints.
    fn moved_flange(
        &self,
        f: usize,
        reported: &Pose,
        delta: &[f64],
    ) -> Option<(Pose, DMatrix<f64>)> {
        let at = reported * self.flange_move(f, delta)?;
        let mut twist = DMatrix::zeros(6, delta.len());
        let mut stepped = delta.to_vec();
        for c in 0..delta.len() {
            stepped[c] = delta[c] + ARM_STEP_RAD;
            let next = reported * self.flange_move(f, &stepped)?;
            stepped[c] = delta[c];
            let phi = (at.rotation.inverse() * next.rotation).scaled_axis();
            let rho = next.translation.vector - at.translation.vector;
            twist
                .fixed_view_mut::<3, 1>(0, c)
                .copy_from(&(phi / ARM_STEP_RAD));
            twist
                .fixed_view_mut::<3, 1>(3, c)
                .copy_from(&(rho / ARM_STEP_RAD));
        }
        Some((at, twist))
    }
}

/// The model the parameters stand for.
pub(super) struct State {
    /// The unknowns `X`, `Y`.
    pub axby: Axby,
    /// The camera model (intrinsics and coefficients as fitted).
    pub camera: CameraModel,
    /// The factor on every board point (1 when the scale is held).
    pub board_scale: f64,
    /// Per frame: `B` of `A = X·B·Y` from the (corrected) robot pose.
    pub b: Vec<Pose>,
    /// Per frame: (φ, ρ) robot correction.
    pub corrections: Vec<(Vector3<f64>, Vector3<f64>)>,
    /// Per frame: `T_base_flange` as fitted (the arm's move and the correction applied).
    pub robot_poses: Vec<Pose>,
    /// Per frame with joints: the flange twist of each free joint offset (6 x free, rows
    /// `φ` in the flange frame then `ρ` in the base frame: the robot correction's coordinates).
    pub arm_twists: Vec<Option<DMatrix<f64>>>,
}

impl Problem<'_> {
    /// The problem at the start `x0`, `camera0` (zero perturbation and corrections, all weights
    /// one), with the blocks `options` frees.
    pub(super) fn new<'a>(
        setup: Setup,
        frames: &'a [Frame],
        x0: Axby,
        camera0: CameraModel,
        options: &ReprojectionOptions,
    ) -> Problem<'a> {
        let layout = Layout {
            intrinsics: if options.refine_intrinsics { 4 } else { 0 },
            distortion: if options.refine_distortion {
                camera0.distortion.coefficient_count()
            } else {
                0
            },
            board_scale: usize::from(options.refine_board_scale),
            arm: options.arm.as_ref().map_or(0, |a| a.free.len()),
            robot: if options.robot_prior.is_some() { 6 } else { 0 },
            frames: frames.len(),
        };
        let mut params = DVector::zeros(layout.len());
        if layout.intrinsics > 0 {
            let o = layout.intrinsics_offset();
            params.rows_mut(o, 4).copy_from_slice(&camera0.intrinsics());
        }
        if layout.distortion > 0 {
            let o = layout.distortion_offset();
            params
                .rows_mut(o, layout.distortion)
                .copy_from_slice(&camera0.distortion.coefficients());
        }
        if layout.board_scale > 0 {
            params[layout.board_scale_offset()] = options.board_scale;
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
            board_scale: options.board_scale,
            prior: options.robot_prior,
            row_offsets,
            corner_rows: rows,
            arm: options.arm.as_ref().map(|a| ArmColumns::new(a, frames)),
            trial_residuals: None,
        }
    }

    /// The arm's free joint offsets at the current parameters: the start's plus the change, each
    /// with its 1-sigma from `sigmas` (the arm columns' order).
    pub(super) fn refined_offsets(&self, sigmas: &[Option<f64>]) -> Vec<RefinedOffset> {
        let Some(arm) = &self.arm else {
            return Vec::new();
        };
        let o = self.layout.arm_offset();
        arm.free
            .free
            .iter()
            .enumerate()
            .map(|(c, &joint)| RefinedOffset {
                joint,
                offset_rad: arm.free.start[joint][0] + self.params[o + c],
                sigma_rad: sigmas.get(c).copied().flatten(),
            })
            .collect()
    }

    /// The model at the current parameters.
    pub(super) fn state(&self) -> State {
        let d = &self.params;
        let v = |k: usize| Vector3::new(d[k], d[k + 1], d[k + 2]);
        let axby = perturbed(&self.x0, &d.fixed_rows::<{ Layout::POSE }>(0).into_owned());
        let mut camera = self.camera0;
        if self.layout.intrinsics > 0 {
            let o = self.layout.intrinsics_offset();
            camera.set_intrinsics([d[o], d[o + 1], d[o + 2], d[o + 3]]);
        }
        if self.layout.distortion > 0 {
            let o = self.layout.distortion_offset();
            camera.distortion = self
                .camera0
                .distortion
                .with_coefficients(&d.as_slice()[o..o + self.layout.distortion])
                .expect("the layout holds exactly the model's coefficient count");
        }
        let board_scale = if self.layout.board_scale > 0 {
            d[self.layout.board_scale_offset()]
        } else {
            self.board_scale
        };
        let mut corrections = Vec::with_capacity(self.frames.len());
        let mut b = Vec::with_capacity(self.frames.len());
        let mut robot_poses = Vec::with_capacity(self.frames.len());
        let mut arm_twists = Vec::with_capacity(self.frames.len());
        let delta = d.as_slice()[self.layout.arm_offset()..self.layout.robot_offset()].to_vec();
        for (f, frame) in self.frames.iter().enumerate() {
            let mut robot = frame.base_from_flange;
            let moved = self
                .arm
                .as_ref()
                .and_then(|a| a.moved_flange(f, &robot, &delta));
            if let Some((at, _)) = &moved {
                robot = *at;
            }
            arm_twists.push(moved.map(|(_, twist)| twist));
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
            robot_poses.push(robot);
        }
        State {
            axby,
            camera,
            board_scale,
            b,
            corrections,
            robot_poses,
            arm_twists,
        }
    }

    fn rows(&self) -> usize {
        self.corner_rows + 6 * self.layout.robot.min(1) * self.frames.len()
    }

    /// Pixel error (predicted − detected) of every corner, unweighted.
    pub(super) fn pixel_errors(&self, s: &State) -> Vec<Vec<Vector2<f64>>> {
        self.frames
            .iter()
            .enumerate()
            .map(|(f, frame)| {
                let chain = s.axby.x * s.b[f] * s.axby.y;
                frame
                    .corners
                    .iter()
                    .map(|c| {
                        let p = chain * Point3::from(c.point_in_target.coords * s.board_scale);
                        s.camera.project_clamped(&p) - c.pixel
                    })
                    .collect()
            })
            .collect()
    }

    /// Every residual at the current parameters (the whitened pixel errors, then the robot
    /// corrections' prior); `None` when one is not finite.
    pub(super) fn residuals(&self) -> Option<DVector<f64>> {
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

    /// The whole Jacobian of [`Self::residuals`], formed densely: the tests' reference for the
    /// normal equations built block by block.
    #[cfg(test)]
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
        for (f, frame) in self.frames.iter().enumerate() {
            let b = &s.b[f];
            let rb = b.rotation.to_rotation_matrix().into_inner();
            let rxrb = rx * rb;
            let d_phi_y_base = -(rxrb * ry);
            for (c, corner) in frame.corners.iter().enumerate() {
                let p = corner.point_in_target.coords * s.board_scale;
                let q = s.axby.y * Point3::from(p); // in Y's parent frame
                let w = b * q; // in X's right frame
                let pc = s.axby.x * w; // in the camera
                let projection = camera.linearise(&pc);
                let k = self.weights[f][c].sqrt() * self.inv_sigma_px;
                let d_pix = projection.d_pixel_d_point * k; // 2x3 d pixel / d point_in_camera
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
                if layout.intrinsics > 0 {
                    global
                        .fixed_view_mut::<2, 4>(0, layout.intrinsics_offset())
                        .copy_from(&(projection.d_pixel_d_intrinsics() * k));
                }
                if layout.distortion > 0 {
                    global
                        .view_mut((0, layout.distortion_offset()), (2, layout.distortion))
                        .copy_from(&(camera.d_pixel_d_coefficients(projection.normalised) * k));
                }
                if layout.board_scale > 0 {
                    let d_point = rxrb * ry * corner.point_in_target.coords;
                    global
                        .fixed_view_mut::<2, 1>(0, layout.board_scale_offset())
                        .copy_from(&(d_pix * d_point));
                }
                let arm_twist = s.arm_twists[f].as_ref();
                if layout.robot > 0 || arm_twist.is_some() {
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
                if layout.arm > 0 {
                    // An offset moves the flange as a correction of that twist would.
                    let mut columns = global.view_mut((0, layout.arm_offset()), (2, layout.arm));
                    match arm_twist {
                        Some(twist) => columns.copy_from(&(robot * twist)),
                        None => columns.fill(0.0),
                    }
                }
                visit(f, c, &global, &robot);
            }
        }
    }

    /// The normal equations `JᵀJ` and `Jᵀr` at the current parameters, accumulated corner by
    /// corner from the block structure (never forming the tall Jacobian), and `‖r‖²`. With
    /// per-frame robot corrections `JᵀJ` is an arrowhead, kept as its parts: memory linear in
    /// the frames.
    pub(super) fn normal_equations(&self) -> Option<(NormalMatrix, DVector<f64>, f64)> {
        self.normal_equations_at(self.residuals()?)
    }

    /// [`Self::normal_equations`] with the residuals `r` at the current parameters.
    fn normal_equations_at(&self, r: DVector<f64>) -> Option<(NormalMatrix, DVector<f64>, f64)> {
        let s = self.state();
        let layout = self.layout;
        let n_global = layout.robot_offset();
        let corrected = if layout.robot > 0 {
            self.frames.len()
        } else {
            0
        };
        let mut h = Arrowhead::zeros(n_global, corrected);
        let mut g = DVector::zeros(layout.len());
        // Only the upper triangle of the global block is summed corner by corner (no temporary
        // matrix a corner); the lower is its mirror, filled once at the end. The corner's two
        // global rows are copied to slices, and every block is summed a column (contiguous:
        // column-major) at a time.
        let (mut top, mut bottom) = (vec![0.0; n_global], vec![0.0; n_global]);
        self.corner_jacobians(&s, |f, c, global, robot| {
            let row = self.row_offsets[f] + 2 * c;
            let res = Vector2::new(r[row], r[row + 1]);
            for (i, (t, b)) in top.iter_mut().zip(&mut bottom).enumerate() {
                (*t, *b) = (global[(0, i)], global[(1, i)]);
            }
            // A column's entries `Jᵢ·Jⱼ` over the global rows above it.
            let add_column = |column: &mut [f64], a0: f64, a1: f64| {
                for ((sum, &t), &b) in column.iter_mut().zip(&top).zip(&bottom) {
                    *sum += t * a0 + b * a1;
                }
            };
            let corner = h.corner.as_mut_slice();
            for j in 0..n_global {
                let (a0, a1) = (top[j], bottom[j]);
                add_column(&mut corner[j * n_global..][..=j], a0, a1);
                g[j] += a0 * res.x + a1 * res.y;
            }
            if layout.robot > 0 {
                let border = h.border[f].as_mut_slice();
                for j in 0..6 {
                    add_column(
                        &mut border[j * n_global..][..n_global],
                        robot[(0, j)],
                        robot[(1, j)],
                    );
                }
                h.blocks[f] += robot.transpose() * robot;
                let mut gf = g.fixed_rows_mut::<6>(n_global + 6 * f);
                gf += robot.transpose() * res;
            }
        });
        h.corner.fill_lower_triangle_with_upper_triangle();
        if let Some(prior) = self.prior {
            for (f, block) in h.blocks.iter_mut().enumerate() {
                let row = self.corner_rows + 6 * f;
                let o = n_global + 6 * f;
                let k = self.prior_weights[f].sqrt();
                for i in 0..6 {
                    let inv = k / if i < 3 {
                        prior.rotation_sigma_rad
                    } else {
                        prior.translation_sigma_m
                    };
                    block[(i, i)] += inv * inv;
                    g[o + i] += inv * r[row + i];
                }
            }
        }
        let h = if layout.robot > 0 {
            NormalMatrix::Arrow(h)
        } else {
            NormalMatrix::Dense(h.corner)
        };
        Some((h, g, r.norm_squared()))
    }
}

/// Re-anchors the pose perturbation at the current state so the next Jacobian is exact there.
pub(super) fn reanchor(problem: &mut Problem<'_>) {
    let s = problem.state();
    problem.x0 = s.axby;
    problem.camera0 = s.camera;
    for k in 0..Layout::POSE {
        problem.params[k] = 0.0;
    }
}

/// The block-structured solver's view: normal equations built corner by corner, re-anchored
/// after every accepted step.
impl NormalEquations for Problem<'_> {
    fn normal_equations(&mut self) -> Option<(NormalMatrix, DVector<f64>, f64)> {
        match self.trial_residuals.take() {
            Some(r) => self.normal_equations_at(r),
            None => Problem::normal_equations(self),
        }
    }

    fn cost(&mut self) -> Option<f64> {
        let r = self.residuals();
        let cost = r.as_ref().map(|r| r.norm_squared());
        self.trial_residuals = r;
        cost
    }

    fn params_mut(&mut self) -> &mut DVector<f64> {
        self.trial_residuals = None;
        &mut self.params
    }

    fn accepted(&mut self) {
        reanchor(self);
    }

    fn finished(&mut self) {
        self.trial_residuals = None;
    }
}

#[cfg(test)]
mod tests {
    use nalgebra::{Point2, Point3};

    use super::*;
    use crate::reprojection::Corner;
    use handeye_core::camera_model::Distortion;
    use handeye_core::geometry::pose_from_rotvec;

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
            refine_board_scale: true,
            board_scale: 1.02,
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

    /// [`full_problem`] with mounts away from the frames' (non-zero residuals everywhere).
    fn off_truth_problem(setup: Setup, frames: &[Frame]) -> Problem<'_> {
        full_problem(
            setup,
            frames,
            &pose([0.03, -0.07, 0.04], [0.02, -0.01, 1.56]),
            &pose([0.5, -0.15, 0.0], [0.01, 0.02, 0.3]),
        )
    }

    /// The minimiser builds the normal equations after a taken step from the residuals its
    /// trial kept: they must be those built afresh at the re-anchored point, to the bit (the
    /// answer is not to depend on the reuse), and be dropped once the parameters move.
    #[test]
    fn a_taken_step_keeps_the_residuals_of_its_point() {
        for setup in [Setup::EyeInHand, Setup::EyeToHand] {
            let frames = frames(setup);
            let mut problem = off_truth_problem(setup, &frames);
            let step = DVector::from_fn(problem.params.len(), |k, _| 1e-4 * (k as f64 - 7.5));
            *NormalEquations::params_mut(&mut problem) += &step;
            let trial = NormalEquations::cost(&mut problem).unwrap();
            NormalEquations::accepted(&mut problem);
            let (h_kept, g_kept, cost_kept) =
                NormalEquations::normal_equations(&mut problem).unwrap();
            let (h_fresh, g_fresh, cost_fresh) = problem.normal_equations().unwrap();
            assert_eq!(
                cost_kept.to_bits(),
                trial.to_bits(),
                "{setup}: the trial's cost"
            );
            assert_eq!(cost_kept.to_bits(), cost_fresh.to_bits(), "{setup}: cost");
            assert_eq!(g_kept, g_fresh, "{setup}: Jᵀr");
            assert_eq!(h_kept.to_dense(), h_fresh.to_dense(), "{setup}: JᵀJ");
            // Kept for one build only; a step moves the parameters away from them.
            assert!(problem.trial_residuals.is_none());
            NormalEquations::cost(&mut problem).unwrap();
            *NormalEquations::params_mut(&mut problem) += &step;
            assert!(problem.trial_residuals.is_none(), "{setup}: a moved point");
            NormalEquations::cost(&mut problem).unwrap();
            NormalEquations::finished(&mut problem);
            assert!(
                problem.trial_residuals.is_none(),
                "{setup}: a finished minimisation"
            );
        }
    }

    #[test]
    fn block_normal_equations_match_the_dense_jacobian() {
        for setup in [Setup::EyeInHand, Setup::EyeToHand] {
            let frames = frames(setup);
            let mut problem = off_truth_problem(setup, &frames);
            // Non-zero corrections so the prior's gradient is tested too.
            let o = problem.layout.robot_offset();
            problem.params[o + 1] = 2e-5;
            problem.params[o + 10] = -3e-5;
            problem.weights[2][5] = 0.5;
            let j = problem.jacobian().unwrap();
            let r = problem.residuals().unwrap();
            let (h, g, _) = problem.normal_equations().unwrap();
            let h = h.to_dense();
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
