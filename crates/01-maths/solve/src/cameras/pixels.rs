//! The joint solve in pixel space: every board corner every camera saw, reprojected through its
//! camera's lens from the same unknowns as the pose-space solve (each camera's mount, one board
//! per setup), started from the pose-space answer.
//!
//! Why a second stage: a board pose from PnP has strongly anisotropic noise (depth along the
//! camera's axis is several times worse than across it, and worse the farther the board), which
//! the pose-space model weights with one sigma per group; the corners have the same noise in
//! every direction of the image, so least squares on them is the maximum-likelihood estimate
//! under pixel noise. Residual of corner `k` of camera `c` at robot pose `i`:
//! `(π_c(inv(M_c) · B_i · Y_b · P_k) − pixel) / σ_c`, with `B_i = chain_b(T_base_flange_i)`; the
//! corner noise `σ_c` of each camera is estimated from its residuals, alternated with the fit.
//! The Jacobian is analytic (see `corner_rows`), the perturbations those of the pose-space solve,
//! so the covariance reads the same way. Without [`CamerasOptions::robot_sigma`] the robot poses
//! are taken as exact; with it (what a run does) each flange pose is estimated too, around the
//! reported one with the robot's repeatability as its prior, and every camera that sees a board at
//! a pose corrects the flange pose the others use. Each flange pose couples only with the unknowns,
//! so `JᵀJ` is an arrowhead, kept as its parts and solved by its Schur complement
//! ([`crate::arrow`]): time and memory grow with the poses, not their square.

use nalgebra::{DVector, Matrix3, Point2, Point3, SMatrix, SVector, Vector2};

use super::{
    finish, minimize, CamerasData, CamerasError, CamerasOptions, CamerasSolution, Layout, Normal,
    State,
};
use crate::arrow::{Arrowhead, NormalMatrix};
use handeye_core::camera_model::CameraModel;
use handeye_core::geometry::Pose;
use handeye_core::setup::Setup;

/// The corners one camera saw at one robot pose.
#[derive(Debug, Clone, PartialEq)]
pub struct CamerasFrame {
    /// Index into [`CamerasData::cameras`].
    pub camera: usize,
    /// Index into [`CamerasData::base_from_flange`].
    pub pose: usize,
    /// Each corner: its point on the board (target frame, m) and where it was seen (px).
    pub corners: Vec<(Point3<f64>, Point2<f64>)>,
    /// Its corners' inverse variance relative to the camera's corner noise (1: a typical
    /// frame's; a frame of small, far or oblique tags locates its corners less precisely).
    pub weight: f64,
}

/// Residual (2) and its Jacobian (2 x 18: the camera's mount, its board, then the flange pose) of
/// one corner, scaled by `scale` (1/σ).
#[allow(clippy::too_many_arguments)]
fn corner_rows(
    model: &CameraModel,
    setup: Setup,
    mount: &Pose,
    board: &Pose,
    flange: &Pose,
    point: &Point3<f64>,
    pixel: &Point2<f64>,
    scale: f64,
) -> (Vector2<f64>, SMatrix<f64, 2, 18>) {
    let b = setup.chain_b(flange);
    let in_board_parent = board * point;
    let q = b * in_board_parent;
    let in_camera = mount.inverse_transform_point(&q);
    let lin = model.linearise(&in_camera);
    let r = (lin.pixel - pixel) * scale;
    let rm_t = mount.rotation.to_rotation_matrix().into_inner().transpose();
    let rb = b.rotation.to_rotation_matrix().into_inner();
    // Every pose T is perturbed as R ← exp(δθ)R, t ← t + δt.
    // Mount M: p = Mᵀ(q − t_M): ∂p/∂θ = R_Mᵀ[q − t_M]×, ∂p/∂t = −R_Mᵀ.
    let d_theta_mount = rm_t * (q.coords - mount.translation.vector).cross_matrix();
    // Board Y: Y·P = R_Y P + t_Y: ∂/∂θ = −[R_Y P]×, ∂/∂t = I; then through B and Mᵀ.
    let through: Matrix3<f64> = rm_t * rb;
    let d_theta_board = -through * (board.rotation * point.coords).cross_matrix();
    // Flange F: eye-to-hand q = F·w: ∂q/∂θ = −[R_F w]×, ∂q/∂t = I; eye-in-hand q = Fᵀ(w − t_F):
    // ∂q/∂θ = R_Fᵀ[w − t_F]×, ∂q/∂t = −R_Fᵀ (w: the point in the board's parent frame).
    let w = in_board_parent.coords;
    let rf = flange.rotation.to_rotation_matrix().into_inner();
    let (dq_theta, dq_t) = match setup {
        Setup::EyeToHand => (-(rf * w).cross_matrix(), Matrix3::identity()),
        Setup::EyeInHand => (
            rf.transpose() * (w - flange.translation.vector).cross_matrix(),
            -rf.transpose(),
        ),
    };
    let mut d_point = SMatrix::<f64, 3, 18>::zeros();
    d_point
        .fixed_view_mut::<3, 3>(0, 0)
        .copy_from(&d_theta_mount);
    d_point.fixed_view_mut::<3, 3>(0, 3).copy_from(&(-rm_t));
    d_point
        .fixed_view_mut::<3, 3>(0, 6)
        .copy_from(&d_theta_board);
    d_point.fixed_view_mut::<3, 3>(0, 9).copy_from(&through);
    d_point
        .fixed_view_mut::<3, 3>(0, 12)
        .copy_from(&(rm_t * dq_theta));
    d_point
        .fixed_view_mut::<3, 3>(0, 15)
        .copy_from(&(rm_t * dq_t));
    (r, lin.d_pixel_d_point * d_point * scale)
}

struct Problem<'a> {
    data: &'a CamerasData,
    models: &'a [CameraModel],
    frames: &'a [CamerasFrame],
    layout: Layout,
    /// The robot's repeatability (m, rad) when the flange poses are estimated; then the state
    /// holds one flange pose per robot pose after the boards.
    robot: Option<(f64, f64)>,
}

impl Problem<'_> {
    /// Parameters: the unknowns, then 6 per flange pose when they are estimated.
    fn len(&self) -> usize {
        self.layout.len()
            + self
                .robot
                .map_or(0, |_| 6 * self.data.base_from_flange.len())
    }

    /// Parameter offset of robot pose `i`'s flange (when estimated).
    fn flange_at(&self, i: usize) -> usize {
        self.layout.len() + 6 * i
    }

    /// `(mount, board, flange, board offset)` of a frame at `state`.
    fn chain(&self, state: &State, frame: &CamerasFrame) -> (Pose, Pose, Pose, usize) {
        let setup = self.data.cameras[frame.camera].setup;
        let bi = self.layout.board_of(setup);
        let flange = match self.robot {
            Some(_) => state.poses[self.flange_at(frame.pose) / 6],
            None => self.data.base_from_flange[frame.pose],
        };
        (state.poses[frame.camera], state.poses[bi / 6], flange, bi)
    }

    /// The robot prior's residual of pose `i` (its flange against the reported one, in sigmas).
    fn prior(&self, state: &State, i: usize) -> SVector<f64, 6> {
        let (st, sr) = self.robot.unwrap_or((1.0, 1.0));
        let mut d = super::difference(
            &state.poses[self.flange_at(i) / 6],
            &self.data.base_from_flange[i],
        );
        for k in 0..3 {
            d[k] /= sr;
            d[k + 3] /= st;
        }
        d
    }

    /// `JᵀJ`, `Jᵀr` and the cost at `state`. With the flange poses estimated `JᵀJ` is an
    /// arrowhead (each frame couples its camera, its board and its pose's flange; the flanges
    /// only through the unknowns) kept as its parts, so memory and time grow with the poses, not
    /// their square; without them it is the unknowns' dense block.
    fn normal(&self, state: &State, sigma: &[f64]) -> Normal {
        let g = self.layout.len();
        let poses = self.robot.map_or(0, |_| self.data.base_from_flange.len());
        let mut arrow = Arrowhead::zeros(g, poses);
        let mut jtr = DVector::<f64>::zeros(self.len());
        let mut cost = 0.0;
        for frame in self.frames {
            let (mount, board, flange, bi) = self.chain(state, frame);
            let setup = self.data.cameras[frame.camera].setup;
            let model = &self.models[frame.camera];
            let scale = frame.weight.sqrt() / sigma[frame.camera];
            let mut local = SMatrix::<f64, 18, 18>::zeros();
            let mut gradient = SMatrix::<f64, 18, 1>::zeros();
            for (point, pixel) in &frame.corners {
                let (r, j) =
                    corner_rows(model, setup, &mount, &board, &flange, point, pixel, scale);
                local += j.transpose() * j;
                gradient += j.transpose() * r;
                cost += r.norm_squared();
            }
            // The frame's two unknowns (its camera, its board) in the corner block.
            let unknowns = [6 * frame.camera, bi];
            for (a, &ra) in unknowns.iter().enumerate() {
                for (c, &rc) in unknowns.iter().enumerate() {
                    let mut block = arrow.corner.view_mut((ra, rc), (6, 6));
                    block += local.fixed_view::<6, 6>(6 * a, 6 * c);
                }
                let mut grad = jtr.rows_mut(ra, 6);
                grad += gradient.fixed_rows::<6>(6 * a);
            }
            if self.robot.is_some() {
                // Its pose's flange: the diagonal block and the border column.
                let i = frame.pose;
                arrow.blocks[i] += local.fixed_view::<6, 6>(12, 12);
                for (a, &ra) in unknowns.iter().enumerate() {
                    let mut border = arrow.border[i].rows_mut(ra, 6);
                    border += local.fixed_view::<6, 6>(6 * a, 12);
                }
                let mut grad = jtr.rows_mut(self.flange_at(i), 6);
                grad += gradient.fixed_rows::<6>(12);
            }
        }
        if let Some((st, sr)) = self.robot {
            // The prior's Jacobian is the identity scaled by 1/σ (exact for the translation,
            // to first order in the small correction for the rotation).
            for i in 0..poses {
                let r = self.prior(state, i);
                let at = self.flange_at(i);
                for k in 0..6 {
                    let w = if k < 3 { 1.0 / sr } else { 1.0 / st };
                    arrow.blocks[i][(k, k)] += w * w;
                    jtr[at + k] += w * r[k];
                }
                cost += r.norm_squared();
            }
        }
        let h = if self.robot.is_some() {
            NormalMatrix::Arrow(arrow)
        } else {
            NormalMatrix::Dense(arrow.corner)
        };
        (h, jtr, cost)
    }

    /// Per camera: (corners, Σ weighted squared pixel residuals) at `state`.
    fn squares(&self, state: &State) -> Vec<(usize, f64)> {
        let mut out = vec![(0usize, 0.0); self.data.cameras.len()];
        for frame in self.frames {
            let (mount, board, flange, _) = self.chain(state, frame);
            let b = self.data.cameras[frame.camera].setup.chain_b(&flange);
            let model = &self.models[frame.camera];
            for (point, pixel) in &frame.corners {
                let in_camera = mount.inverse_transform_point(&(b * (board * point)));
                let e = model.project_clamped(&in_camera) - pixel;
                out[frame.camera].0 += 1;
                out[frame.camera].1 += frame.weight * e.norm_squared();
            }
        }
        out
    }

    fn cost(&self, state: &State, sigma: &[f64]) -> f64 {
        let corners: f64 = self
            .squares(state)
            .iter()
            .zip(sigma)
            .map(|((_, sq), s)| sq / (s * s))
            .sum();
        let prior: f64 = match self.robot {
            Some(_) => (0..self.data.base_from_flange.len())
                .map(|i| self.prior(state, i).norm_squared())
                .sum(),
            None => 0.0,
        };
        corners + prior
    }
}

/// Rounds of corner-noise estimation alternated with the fit.
const NOISE_ROUNDS: usize = 3;
/// The corner noise the first round assumes, px.
const START_SIGMA_PX: f64 = 0.2;

/// Refines a pose-space joint answer (`start`, from [`super::solve_cameras`] on the same `data`) on
/// the corners: `models[c]` is camera `c`'s lens, `frames` the corners of every accepted board
/// pose. Returns the same kind of answer, its covariance from the corners, each camera's corner
/// noise in [`CamerasSolution::pixel_sigma_px`].
///
/// Errors: a frame naming a camera or pose the data lacks, fewer models than cameras, or corners
/// that leave some mount unconstrained.
pub fn solve_cameras_pixels(
    data: &CamerasData,
    models: &[CameraModel],
    frames: &[CamerasFrame],
    start: &CamerasSolution,
    options: &CamerasOptions,
) -> Result<CamerasSolution, CamerasError> {
    if models.len() != data.cameras.len() {
        return Err(CamerasError::MissingStart("lens for every camera"));
    }
    for (index, f) in frames.iter().enumerate() {
        if f.camera >= data.cameras.len() || f.pose >= data.base_from_flange.len() {
            return Err(CamerasError::BadIndex {
                index,
                camera: f.camera,
                pose: f.pose,
            });
        }
    }
    let layout = Layout::new(data);
    let mut poses = start.camera_mounts.clone();
    poses.extend(start.base_from_target.map(|b| b.0));
    poses.extend(start.flange_from_target.map(|b| b.0));
    if options.robot_sigma.is_some() {
        poses.extend(data.base_from_flange.iter().copied());
    }
    let mut state = State { poses };
    let problem = Problem {
        data,
        models,
        frames,
        layout,
        robot: options.robot_sigma,
    };
    let mut sigma = vec![START_SIGMA_PX; data.cameras.len()];
    let corners: usize = frames.iter().map(|f| f.corners.len()).sum();
    let redundancy = 1.0 - layout.len() as f64 / (2 * corners).max(1) as f64;
    let mut iterations = 0;
    let rounds = if options.estimate_noise {
        NOISE_ROUNDS
    } else {
        1
    };
    for round in 0..rounds {
        let sigma_now = sigma.clone();
        iterations += minimize(
            &mut state,
            options.max_iterations,
            &|s| problem.normal(s, &sigma_now),
            &|s| problem.cost(s, &sigma_now),
        )?;
        if options.estimate_noise && round + 1 < rounds {
            for (c, (count, squares)) in problem.squares(&state).into_iter().enumerate() {
                if count > 0 {
                    let dof = (2.0 * count as f64 * redundancy).max(1.0);
                    sigma[c] = (squares / dof).sqrt().max(1e-4);
                }
            }
        }
    }
    let (jtj, _, chi2) = problem.normal(&state, &sigma);
    // The prior adds as many residuals as flange parameters: the dof are the corners'.
    let dof = (2.0 * corners as f64 - layout.len() as f64).max(1.0);
    finish(
        data,
        &layout,
        state,
        &jtj,
        chi2 / dof,
        start.noise.clone(),
        sigma,
        start.iterations + iterations,
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion, Vector3};

    fn pose(t: [f64; 3], r: [f64; 3]) -> Pose {
        Pose::from_parts(
            Translation3::new(t[0], t[1], t[2]),
            UnitQuaternion::from_scaled_axis(Vector3::new(r[0], r[1], r[2])),
        )
    }

    /// A 1280 x 720 lens with `distortion`.
    fn lens(distortion: handeye_core::camera_model::Distortion) -> CameraModel {
        CameraModel {
            width: 1280,
            height: 720,
            fx: 800.0,
            fy: 810.0,
            cx: 640.0,
            cy: 360.0,
            distortion,
        }
    }

    /// With the flange poses estimated, the normal equations kept as an arrowhead are those of
    /// the whole stacked Jacobian: every corner's rows put in its camera's, its board's and its
    /// pose's flange's columns, and the prior's rows.
    #[test]
    fn the_arrowhead_normal_equations_are_the_stacked_jacobians() {
        let model = lens(handeye_core::camera_model::Distortion::None);
        let spec = |name: &str, setup| super::super::CameraSpec {
            name: name.into(),
            setup,
            noise: crate::NoiseModel::default(),
        };
        let flanges: Vec<Pose> = (0..4)
            .map(|i| {
                let a = f64::from(i);
                pose(
                    [0.5 + 0.02 * a, -0.1, 0.6],
                    [3.0, 0.1 * a - 0.15, 0.2 - 0.1 * a],
                )
            })
            .collect();
        let data = CamerasData {
            cameras: vec![
                spec("wrist", Setup::EyeInHand),
                spec("left", Setup::EyeToHand),
            ],
            base_from_flange: flanges.clone(),
            observations: Vec::new(),
        };
        // Pose 2 seen by the wrist camera only: a flange block with one camera's frame.
        let frames: Vec<CamerasFrame> = (0..4)
            .flat_map(|i| [(0, i), (1, i)])
            .filter(|&(camera, pose)| !(camera == 1 && pose == 2))
            .map(|(camera, pose)| CamerasFrame {
                camera,
                pose,
                corners: (0..5)
                    .map(|k| {
                        let k = f64::from(k);
                        let pixel = Point2::new(600.0 + 7.0 * k, 300.0 - 5.0 * k);
                        (Point3::new(0.03 * k, 0.02 * (k - 2.0), 0.0), pixel)
                    })
                    .collect(),
                // A frame of less precise corners among them.
                weight: if pose == 1 { 0.25 } else { 1.0 },
            })
            .collect();
        let models = [model, model];
        let layout = Layout::new(&data);
        let problem = Problem {
            data: &data,
            models: &models,
            frames: &frames,
            layout,
            robot: Some((3e-5, 1e-4)),
        };
        let mut poses = vec![
            pose([0.03, -0.07, 0.04], [0.02, -0.01, 1.56]),
            pose([0.5, 0.1, 1.6], [3.1, 0.05, 0.0]),
            pose([0.5, -0.15, 0.0], [0.01, -0.02, 0.3]),
            pose([0.0, -0.1, -0.05], [3.1, 0.0, 0.0]),
        ];
        // Flanges a little off the reported ones, so the prior's residuals are not zero.
        let off = pose([1e-4, -2e-4, 5e-5], [2e-4, 0.0, -1e-4]);
        poses.extend(flanges.iter().map(|f| f * off));
        let state = State { poses };
        let sigma = [0.2, 0.3];
        let (h, jtr, cost) = problem.normal(&state, &sigma);
        assert!(matches!(h, NormalMatrix::Arrow(_)));

        let n = problem.len();
        let mut rows: Vec<(DVector<f64>, f64)> = Vec::new();
        for frame in &frames {
            let (mount, board, flange, bi) = problem.chain(&state, frame);
            let setup = data.cameras[frame.camera].setup;
            for (point, pixel) in &frame.corners {
                let scale = frame.weight.sqrt() / sigma[frame.camera];
                let (r, j) = corner_rows(
                    &models[frame.camera],
                    setup,
                    &mount,
                    &board,
                    &flange,
                    point,
                    pixel,
                    scale,
                );
                for axis in 0..2 {
                    let mut row = DVector::zeros(n);
                    let columns = [6 * frame.camera, bi, problem.flange_at(frame.pose)];
                    for (block, &at) in columns.iter().enumerate() {
                        for k in 0..6 {
                            row[at + k] = j[(axis, 6 * block + k)];
                        }
                    }
                    rows.push((row, r[axis]));
                }
            }
        }
        for i in 0..flanges.len() {
            let r = problem.prior(&state, i);
            for k in 0..6 {
                let mut row = DVector::zeros(n);
                row[problem.flange_at(i) + k] = if k < 3 { 1.0 / 1e-4 } else { 1.0 / 3e-5 };
                rows.push((row, r[k]));
            }
        }
        let mut dense_h = nalgebra::DMatrix::<f64>::zeros(n, n);
        let mut dense_g = DVector::<f64>::zeros(n);
        let mut dense_cost = 0.0;
        for (row, r) in &rows {
            dense_h += row * row.transpose();
            dense_g += row * *r;
            dense_cost += r * r;
        }
        let scale = dense_h.amax();
        assert!((h.to_dense() - &dense_h).amax() < 1e-12 * scale);
        assert!((jtr - &dense_g).amax() < 1e-12 * (scale + dense_g.amax()));
        assert!((cost - dense_cost).abs() < 1e-12 * dense_cost);
    }

    #[test]
    fn analytic_corner_jacobian_matches_finite_differences() {
        let model = lens(handeye_core::camera_model::Distortion::RadTan {
            k1: -0.08,
            k2: 0.05,
            p1: 0.0004,
            p2: -0.0006,
            k3: 0.0,
        });
        let mount = pose([0.5, -0.1, 1.4], [2.2, 2.2, 0.05]);
        let board = pose([-0.14, 0.14, -0.03], [3.1, 0.02, 0.01]);
        let b = pose([0.6, -0.1, 0.65], [3.0, 0.2, -0.1]);
        let point = Point3::new(0.1, 0.2, 0.0);
        let pixel = Point2::new(600.0, 300.0);
        for setup in [Setup::EyeToHand, Setup::EyeInHand] {
            let (_, j) = corner_rows(&model, setup, &mount, &board, &b, &point, &pixel, 1.0);
            let h = 1e-7;
            for k in 0..18 {
                let mut d = SVector::<f64, 6>::zeros();
                d[k % 6] = h;
                let at = |d: &SVector<f64, 6>| {
                    let (m, y, f) = match k / 6 {
                        0 => (super::super::perturb(&mount, d), board, b),
                        1 => (mount, super::super::perturb(&board, d), b),
                        _ => (mount, board, super::super::perturb(&b, d)),
                    };
                    corner_rows(&model, setup, &m, &y, &f, &point, &pixel, 1.0).0
                };
                let numeric = (at(&d) - at(&(-d))) / (2.0 * h);
                let err = (numeric - j.column(k)).amax();
                assert!(
                    err < 1e-3 * (1.0 + numeric.amax()),
                    "{setup}, column {k}: {numeric} vs {}",
                    j.column(k)
                );
            }
        }
    }
}
