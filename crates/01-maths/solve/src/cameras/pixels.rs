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
//! so the covariance reads the same way. The robot poses are taken as exact: their noise (a UR's
//! 0.03 mm) is far below what the cameras see.

use nalgebra::{DMatrix, DVector, Matrix3, Point2, Point3, SMatrix, SVector, Vector2};

use super::{
    finish, minimize, CamerasData, CamerasError, CamerasOptions, CamerasSolution, Layout, State,
};
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

    fn normal(&self, state: &State, sigma: &[f64]) -> (DMatrix<f64>, DVector<f64>, f64) {
        let n = self.len();
        let mut jtj = DMatrix::<f64>::zeros(n, n);
        let mut jtr = DVector::<f64>::zeros(n);
        let mut cost = 0.0;
        let blocks = if self.robot.is_some() { 3 } else { 2 };
        for frame in self.frames {
            let (mount, board, flange, bi) = self.chain(state, frame);
            let setup = self.data.cameras[frame.camera].setup;
            let model = &self.models[frame.camera];
            let scale = 1.0 / sigma[frame.camera];
            let mut local = SMatrix::<f64, 18, 18>::zeros();
            let mut gradient = SMatrix::<f64, 18, 1>::zeros();
            for (point, pixel) in &frame.corners {
                let (r, j) =
                    corner_rows(model, setup, &mount, &board, &flange, point, pixel, scale);
                local += j.transpose() * j;
                gradient += j.transpose() * r;
                cost += r.norm_squared();
            }
            let at = [6 * frame.camera, bi, self.flange_at(frame.pose)];
            for (a, &ra) in at.iter().enumerate().take(blocks) {
                for (c, &rc) in at.iter().enumerate().take(blocks) {
                    let mut block = jtj.view_mut((ra, rc), (6, 6));
                    block += local.fixed_view::<6, 6>(6 * a, 6 * c);
                }
                let mut g = jtr.rows_mut(ra, 6);
                g += gradient.fixed_rows::<6>(6 * a);
            }
        }
        if let Some((st, sr)) = self.robot {
            // The prior's Jacobian is the identity scaled by 1/σ (exact for the translation,
            // to first order in the small correction for the rotation).
            for i in 0..self.data.base_from_flange.len() {
                let r = self.prior(state, i);
                let at = self.flange_at(i);
                for k in 0..6 {
                    let w = if k < 3 { 1.0 / sr } else { 1.0 / st };
                    jtj[(at + k, at + k)] += w * w;
                    jtr[at + k] += w * r[k];
                }
                cost += r.norm_squared();
            }
        }
        (jtj, jtr, cost)
    }

    /// Per camera: (corners, Σ squared pixel residuals) at `state`.
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
                out[frame.camera].1 += e.norm_squared();
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
        );
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

    #[test]
    fn analytic_corner_jacobian_matches_finite_differences() {
        let model = CameraModel {
            width: 1280,
            height: 720,
            fx: 800.0,
            fy: 810.0,
            cx: 640.0,
            cy: 360.0,
            distortion: handeye_core::camera_model::Distortion::RadTan {
                k1: -0.08,
                k2: 0.05,
                p1: 0.0004,
                p2: -0.0006,
                k3: 0.0,
            },
        };
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
