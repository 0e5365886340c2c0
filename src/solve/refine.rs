//! Joint weighted nonlinear least squares over both unknowns of `A = X·B·Y`.
//!
//! Residual of sample i (6 numbers, camera frame): rotation `Log(R_pred · R_measᵀ) / σ_r` and
//! translation `(t_pred − t_meas) / σ_t`, times `sqrt(weight_i)`, with `pred = X·B_i·Y`. Under
//! Gaussian noise on `T_camera_target` with those per-axis sigmas this is the maximum-likelihood
//! estimate. Parameters are a local perturbation of the start on SO(3)×R³ per unknown
//! (`R_X ← exp(φ_X)·R_X`, `t_X ← t_X + ρ_X`; `R_Y ← R_Y·exp(φ_Y)`, `t_Y ← t_Y + ρ_Y`) with an
//! analytic Jacobian (`perturbed` is that parametrisation, shared with the reprojection-space
//! refinement); the `levenberg-marquardt` crate minimises (through `solve::lm`, shared with the
//! reprojection-space refinement), then the problem is re-linearised at the optimum so the
//! covariance `(JᵀJ)⁻¹` is exact there. Robust losses (Huber, Cauchy) work by iteratively
//! reweighted least squares on each sample's whitened norm. The sigmas themselves are
//! estimated from the residuals, alternated with the fit (see [`super::noise`]), unless
//! [`SolveOptions::estimate_noise`] says they are given.

use std::cell::RefCell;

use levenberg_marquardt::{LeastSquaresProblem, LevenbergMarquardt};
use nalgebra::{
    DVector, Dyn, Matrix3, Owned, SMatrix, SVector, Translation3, UnitQuaternion, Vector3, U12,
};

use super::lm::minimize_dense;
use super::noise;
use super::{
    Axby, AxbyData, NoiseModel, PoseNoise, PoseSigma, RobustLoss, SolveError, SolveOptions,
    Uncertainty,
};
use crate::geometry::{rotvec, Pose};

/// Parameter count: φ_X, ρ_X, φ_Y, ρ_Y.
const PARAMS: usize = 12;
/// IRLS rounds for robust losses.
const MAX_IRLS_ROUNDS: usize = 20;

/// What the refinement produced.
#[derive(Debug, Clone, PartialEq)]
pub struct Refined {
    /// The unknowns at the optimum.
    pub solution: Axby,
    /// Covariance of [φ_X, ρ_X, φ_Y, ρ_Y] (X left, Y right perturbation), scaled by the
    /// variance factor; `None` when not asked for or singular.
    pub covariance: Option<SMatrix<f64, 12, 12>>,
    /// `χ²/dof`, see [`variance_factor`].
    pub variance_factor: f64,
    /// Residual evaluations spent by LM.
    pub evaluations: usize,
    /// LM met its tolerance.
    pub converged: bool,
    /// Cost (½ Σ r²) at each residual evaluation, for plots.
    pub trace: Vec<f64>,
    /// The noise model the fit ended with (estimated or given) and how it was found.
    pub noise: PoseNoise,
}

/// The unknowns `start` moved by the local perturbation `delta = [φ_X, ρ_X, φ_Y, ρ_Y]`:
/// `R_X ← exp(φ_X)·R_X`, `t_X ← t_X + ρ_X`; `R_Y ← R_Y·exp(φ_Y)`, `t_Y ← t_Y + ρ_Y`.
///
/// The parametrisation of both refinements (pose space and reprojection space), so their
/// covariances map to the mounts through the one [`mount_uncertainty`].
pub(crate) fn perturbed(start: &Axby, delta: &SVector<f64, PARAMS>) -> Axby {
    let d = delta;
    let phi_x = Vector3::new(d[0], d[1], d[2]);
    let rho_x = Vector3::new(d[3], d[4], d[5]);
    let phi_y = Vector3::new(d[6], d[7], d[8]);
    let rho_y = Vector3::new(d[9], d[10], d[11]);
    let x = Pose::from_parts(
        Translation3::from(start.x.translation.vector + rho_x),
        UnitQuaternion::from_scaled_axis(phi_x) * start.x.rotation,
    );
    let y = Pose::from_parts(
        Translation3::from(start.y.translation.vector + rho_y),
        start.y.rotation * UnitQuaternion::from_scaled_axis(phi_y),
    );
    Axby { x, y }
}

/// Inverse of the left Jacobian of SO(3) at `phi`.
fn left_jacobian_inverse(phi: &Vector3<f64>) -> Matrix3<f64> {
    let theta = phi.norm();
    let k = phi.cross_matrix();
    let coefficient = if theta < 1e-6 {
        1.0 / 12.0 + theta * theta / 720.0
    } else {
        let half = 0.5 * theta;
        (1.0 - half * half.cos() / half.sin()) / (theta * theta)
    };
    Matrix3::identity() - 0.5 * k + coefficient * k * k
}

struct Problem<'a> {
    data: &'a AxbyData,
    x0: Axby,
    delta: DVector<f64>,
    /// sqrt(weight_i · robust_i) per sample.
    scale: Vec<f64>,
    inv_sigma_r: f64,
    inv_sigma_t: f64,
    trace: RefCell<Vec<f64>>,
}

impl<'a> Problem<'a> {
    fn new(data: &'a AxbyData, x0: Axby, scale: Vec<f64>, noise: &NoiseModel) -> Self {
        Problem {
            data,
            x0,
            delta: DVector::zeros(PARAMS),
            scale,
            inv_sigma_r: 1.0 / noise.rotation_sigma_rad,
            inv_sigma_t: 1.0 / noise.translation_sigma_m,
            trace: RefCell::new(Vec::new()),
        }
    }

    fn current(&self) -> Axby {
        perturbed(&self.x0, &self.delta.fixed_rows::<PARAMS>(0).into_owned())
    }

    /// Unscaled residual (rotation rad, translation m) of sample i.
    fn raw_residual(s: &Axby, a: &Pose, b: &Pose) -> (Vector3<f64>, Vector3<f64>, Pose) {
        let predicted = s.x * b * s.y;
        let r = rotvec(&(predicted.rotation * a.rotation.inverse()));
        let t = predicted.translation.vector - a.translation.vector;
        (r, t, predicted)
    }
}

impl LeastSquaresProblem<f64, Dyn, U12> for Problem<'_> {
    type ResidualStorage = Owned<f64, Dyn>;
    type JacobianStorage = Owned<f64, Dyn, U12>;
    type ParameterStorage = Owned<f64, U12>;

    fn set_params(&mut self, x: &nalgebra::SVector<f64, 12>) {
        self.delta.copy_from(x);
    }

    fn params(&self) -> nalgebra::SVector<f64, 12> {
        nalgebra::SVector::<f64, 12>::from_column_slice(self.delta.as_slice())
    }

    fn residuals(&self) -> Option<DVector<f64>> {
        let s = self.current();
        let n = self.data.len();
        let mut out = DVector::zeros(6 * n);
        for i in 0..n {
            let (r, t, _) = Self::raw_residual(&s, &self.data.a[i], &self.data.b[i]);
            let k = self.scale[i];
            out.fixed_rows_mut::<3>(6 * i)
                .copy_from(&(r * (k * self.inv_sigma_r)));
            out.fixed_rows_mut::<3>(6 * i + 3)
                .copy_from(&(t * (k * self.inv_sigma_t)));
        }
        self.trace.borrow_mut().push(0.5 * out.norm_squared());
        Some(out)
    }

    fn jacobian(&self) -> Option<nalgebra::OMatrix<f64, Dyn, U12>> {
        let s = self.current();
        let n = self.data.len();
        let mut j = nalgebra::OMatrix::<f64, Dyn, U12>::zeros(6 * n);
        let rx = s.x.rotation.to_rotation_matrix().into_inner();
        for i in 0..n {
            let b = &self.data.b[i];
            let (r, _, predicted) = Self::raw_residual(&s, &self.data.a[i], b);
            let j_inv = left_jacobian_inverse(&r);
            let r_pred = predicted.rotation.to_rotation_matrix().into_inner();
            let kr = self.scale[i] * self.inv_sigma_r;
            let kt = self.scale[i] * self.inv_sigma_t;
            let lever = predicted.translation.vector - s.x.translation.vector;
            let rxb = rx * b.rotation.to_rotation_matrix().into_inner();
            // Rotation rows: d/dφ_X = J⁻¹, d/dφ_Y = J⁻¹·R_pred; translations do not move them.
            j.fixed_view_mut::<3, 3>(6 * i, 0).copy_from(&(j_inv * kr));
            j.fixed_view_mut::<3, 3>(6 * i, 6)
                .copy_from(&(j_inv * r_pred * kr));
            // Translation rows: d/dφ_X = −[R_X (R_B t_Y + t_B)]×, d/dρ_X = I, d/dρ_Y = R_X R_B.
            j.fixed_view_mut::<3, 3>(6 * i + 3, 0)
                .copy_from(&(-lever.cross_matrix() * kt));
            j.fixed_view_mut::<3, 3>(6 * i + 3, 3)
                .copy_from(&(Matrix3::identity() * kt));
            j.fixed_view_mut::<3, 3>(6 * i + 3, 9)
                .copy_from(&(rxb * kt));
        }
        Some(j)
    }
}

/// Whitened residual norm of each sample (sigmas, 6 dof), ignoring weights.
fn whitened_norms(data: &AxbyData, s: &Axby, noise: &NoiseModel) -> Vec<f64> {
    (0..data.len())
        .map(|i| {
            let (r, t, _) = Problem::raw_residual(s, &data.a[i], &data.b[i]);
            ((r / noise.rotation_sigma_rad).norm_squared()
                + (t / noise.translation_sigma_m).norm_squared())
            .sqrt()
        })
        .collect()
}

struct Run {
    solution: Axby,
    evaluations: usize,
    converged: bool,
    trace: Vec<f64>,
}

fn minimise(
    data: &AxbyData,
    start: &Axby,
    scale: &[f64],
    noise: &NoiseModel,
) -> Result<Run, SolveError> {
    let problem = Problem::new(data, *start, scale.to_vec(), noise);
    let (problem, outcome) = minimize_dense(&LevenbergMarquardt::new(), problem)?;
    let solution = problem.current();
    Ok(Run {
        solution,
        evaluations: outcome.evaluations,
        converged: outcome.converged,
        trace: problem.trace.into_inner(),
    })
}

/// Per group of residual rows (rotation, translation) of the whitened problem at `solution`:
/// the weighted sum of squared residuals and the group's redundancy, its row count minus its
/// share `tr(N⁻¹·N_group)` of the 12 parameters (`N = JᵀJ`). `None` when `N` is singular.
///
/// The two numbers of variance component estimation (Förstner): `σ² ← σ²·sum/redundancy`.
pub(super) fn group_redundancy(
    data: &AxbyData,
    solution: &Axby,
    scale: &[f64],
    noise: &NoiseModel,
) -> Option<[(f64, f64); 2]> {
    let problem = Problem::new(data, *solution, scale.to_vec(), noise);
    let residuals = problem.residuals()?;
    let j = problem.jacobian()?;
    let normal: SMatrix<f64, 12, 12> = (j.transpose() * &j).fixed_view::<12, 12>(0, 0).into();
    let inverse = normal.cholesky()?.inverse();
    let mut groups = [(0.0, 0.0); 2];
    for row in 0..j.nrows() {
        let group = &mut groups[usize::from(row % 6 >= 3)];
        let jr = j.row(row).transpose();
        group.0 += residuals[row] * residuals[row];
        // Rows of zero weight are no observations.
        if scale[row / 6] > 0.0 {
            group.1 += 1.0 - (jr.transpose() * inverse * jr)[(0, 0)];
        }
    }
    Some(groups)
}

/// Whitened residual norm (sigmas, 6 dof) of every sample of `data` at `solution`, the fit of
/// the samples with `in_fit`: a sample in the fit is whitened by the noise alone, one left out
/// by the noise plus the uncertainty of its prediction, `I + J_i·N⁻¹·J_iᵀ` (whitened, `N` the
/// information of the fitted samples), so a sample is tested for what a fit without it can
/// predict. Weights scale the fit's information, not a sample's own test. `None` when `N` is
/// singular.
pub(super) fn test_norms(
    data: &AxbyData,
    solution: &Axby,
    noise: &NoiseModel,
    in_fit: &[bool],
) -> Option<Vec<f64>> {
    let problem = Problem::new(data, *solution, vec![1.0; data.len()], noise);
    let residuals = problem.residuals()?;
    let j = problem.jacobian()?;
    let mut normal = SMatrix::<f64, 12, 12>::zeros();
    for i in (0..data.len()).filter(|&i| in_fit[i]) {
        let ji = j.fixed_view::<6, 12>(6 * i, 0);
        normal += ji.transpose() * ji * data.weights[i];
    }
    let inverse = normal.cholesky()?.inverse();
    Some(
        (0..data.len())
            .map(|i| {
                let e = residuals.fixed_rows::<6>(6 * i).into_owned();
                if in_fit[i] {
                    return e.norm();
                }
                let ji = j.fixed_view::<6, 12>(6 * i, 0);
                let spread = SMatrix::<f64, 6, 6>::identity() + ji * inverse * ji.transpose();
                spread
                    .cholesky()
                    .map_or(e.norm(), |c| e.dot(&c.solve(&e)).max(0.0).sqrt())
            })
            .collect(),
    )
}

/// Refines a start by weighted (optionally robust) nonlinear least squares, with the noise
/// model estimated from the residuals as `options.estimate_noise` asks; computes the
/// covariance at the optimum when `options.covariance` is set.
pub fn refine(
    data: &AxbyData,
    start: &Axby,
    options: &SolveOptions,
) -> Result<Refined, SolveError> {
    let n = data.len();
    let mut robust = vec![1.0; n];
    let scale_of = |robust: &[f64]| -> Vec<f64> {
        data.weights
            .iter()
            .zip(robust)
            .map(|(w, r)| (w * r).sqrt())
            .collect()
    };
    let mut estimator = noise::Estimator::new(data.len(), options);
    let mut noise = estimator.noise();
    let mut run = minimise(data, start, &scale_of(&robust), &noise)?;
    let mut evaluations = run.evaluations;
    let mut trace = std::mem::take(&mut run.trace);
    let robust_loss = options.robust != RobustLoss::None;
    if robust_loss || estimator.active() {
        for _ in 0..MAX_IRLS_ROUNDS {
            let mut change = 0.0;
            if robust_loss {
                let norms = whitened_norms(data, &run.solution, &noise);
                let new: Vec<f64> = norms.iter().map(|&e| options.robust.weight(e)).collect();
                change = new
                    .iter()
                    .zip(&robust)
                    .map(|(a, b)| (a - b).abs())
                    .fold(0.0, f64::max);
                robust = new;
            }
            let noise_settled = estimator.step(data, &run.solution, &scale_of(&robust));
            noise = estimator.noise();
            run = minimise(data, &run.solution, &scale_of(&robust), &noise)?;
            evaluations += run.evaluations;
            trace.append(&mut run.trace);
            if change < 1e-6 && noise_settled {
                break;
            }
        }
    }
    // LM's Jacobian is the left-perturbation Jacobian at the current point; it differs from the
    // derivative in δ by an invertible factor, so the stationary point is the same. The
    // covariance below is computed with δ = 0 at the optimum, where it is exact.
    let solution = run.solution;
    let converged = run.converged;
    let scale = scale_of(&robust);
    let problem = Problem::new(data, solution, scale.clone(), &noise);
    let residuals = problem
        .residuals()
        .ok_or(SolveError::RefinementFailed("residuals"))?;
    let dof = (6 * n).saturating_sub(PARAMS);
    let chi2 = residuals.norm_squared();
    let variance_factor = variance_factor(chi2, dof);
    let covariance = if options.covariance {
        let j = problem
            .jacobian()
            .ok_or(SolveError::RefinementFailed("jacobian"))?;
        let jtj: SMatrix<f64, 12, 12> = (j.transpose() * &j).fixed_view::<12, 12>(0, 0).into();
        jtj.try_inverse().map(|inv| inv * variance_factor)
    } else {
        None
    };
    Ok(Refined {
        solution,
        covariance,
        variance_factor,
        evaluations,
        converged,
        trace,
        noise: estimator.outcome(),
    })
}

/// Fisher information `JᵀJ` (12x12, whitened by `noise`, in the refinement's parameters
/// [φ_X, ρ_X, φ_Y, ρ_Y]) that one more sample at `B` would add at the solution `solution`.
///
/// Evaluated at zero residual (the measurement is predicted as `X·B·Y`), which is where the
/// Gauss-Newton covariance of a future solve is linearised. Summed over samples and inverted it
/// predicts the covariance before the samples are taken: the basis of next-best-pose planning.
pub fn sample_information(
    solution: &Axby,
    b: &Pose,
    noise: &super::NoiseModel,
) -> SMatrix<f64, 12, 12> {
    let data = AxbyData {
        a: vec![solution.x * b * solution.y],
        b: vec![*b],
        weights: vec![1.0],
    };
    let problem = Problem::new(&data, *solution, vec![1.0], noise);
    let j = problem
        .jacobian()
        .expect("the analytic Jacobian always exists");
    (j.transpose() * &j).fixed_view::<12, 12>(0, 0).into()
}

/// Residual degrees of freedom from which `χ²/dof` is trusted as the noise level.
///
/// Below it (fewer than 8 samples) the estimate of the noise is itself too noisy, so the factor
/// is floored at 1: a lucky fit of a few samples must not claim more certainty than the model.
pub const MIN_DOF_FOR_VARIANCE_FACTOR: usize = 36;

/// A-posteriori variance factor `χ²/dof`. With enough residual degrees of freedom it is used as
/// is, in both directions: when the real noise is smaller than the configured [`NoiseModel`]
/// (typical: the defaults are conservative) the covariance shrinks to match, so the reported
/// 1-sigma stays a 1-sigma (the Monte Carlo test in `tests/uncertainty.rs` checks the coverage
/// both with a matched and with a 4× too pessimistic noise model).
///
/// [`NoiseModel`]: super::NoiseModel
pub fn variance_factor(chi2: f64, dof: usize) -> f64 {
    if dof == 0 || !chi2.is_finite() {
        return 1.0;
    }
    let factor = chi2 / dof as f64;
    if dof >= MIN_DOF_FOR_VARIANCE_FACTOR {
        // Exact data (χ² = 0) must still give a usable covariance.
        factor.max(1e-12)
    } else {
        factor.max(1.0)
    }
}

fn pose_sigma(cov: &SMatrix<f64, 6, 6>) -> PoseSigma {
    let axis = |i: usize| cov[(i, i)].max(0.0).sqrt();
    PoseSigma {
        rotation_deg: (cov[(0, 0)] + cov[(1, 1)] + cov[(2, 2)])
            .max(0.0)
            .sqrt()
            .to_degrees(),
        translation_mm: (cov[(3, 3)] + cov[(4, 4)] + cov[(5, 5)]).max(0.0).sqrt() * 1e3,
        rotation_axes_deg: [
            axis(0).to_degrees(),
            axis(1).to_degrees(),
            axis(2).to_degrees(),
        ],
        translation_axes_mm: [axis(3) * 1e3, axis(4) * 1e3, axis(5) * 1e3],
    }
}

/// Maps the parameter covariance to the reported unknowns: camera mount `inv(X)` and target
/// mount `Y`, each `T_a_b` perturbed as `R ← exp(δθ)·R`, `t ← t + δt` in frame `a`.
pub fn mount_uncertainty(
    solution: &Axby,
    covariance: &SMatrix<f64, 12, 12>,
    variance_factor: f64,
) -> Uncertainty {
    let rx_t = solution
        .x
        .rotation
        .to_rotation_matrix()
        .into_inner()
        .transpose();
    let tx = solution.x.translation.vector;
    let ry = solution.y.rotation.to_rotation_matrix().into_inner();
    let mut g = SMatrix::<f64, 12, 12>::zeros();
    // inv(X): δθ = −R_Xᵀ φ_X; δt = −R_Xᵀ [t_X]× φ_X − R_Xᵀ ρ_X.
    g.fixed_view_mut::<3, 3>(0, 0).copy_from(&(-rx_t));
    g.fixed_view_mut::<3, 3>(3, 0)
        .copy_from(&(-rx_t * tx.cross_matrix()));
    g.fixed_view_mut::<3, 3>(3, 3).copy_from(&(-rx_t));
    // Y (right perturbation): δθ = R_Y φ_Y; δt = ρ_Y.
    g.fixed_view_mut::<3, 3>(6, 6).copy_from(&ry);
    g.fixed_view_mut::<3, 3>(9, 9)
        .copy_from(&Matrix3::identity());
    let mapped = g * covariance * g.transpose();
    Uncertainty {
        covariance: mapped,
        camera_mount: pose_sigma(&mapped.fixed_view::<6, 6>(0, 0).into()),
        target_mount: pose_sigma(&mapped.fixed_view::<6, 6>(6, 6).into()),
        variance_factor,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn analytic_jacobian_matches_finite_differences() {
        let pose = |t: [f64; 3], r: [f64; 3]| {
            Pose::from_parts(
                Translation3::new(t[0], t[1], t[2]),
                UnitQuaternion::from_scaled_axis(Vector3::new(r[0], r[1], r[2])),
            )
        };
        let x = pose([0.1, -0.05, 0.2], [0.3, -0.2, 1.0]);
        let y = pose([0.5, 0.2, -0.1], [-1.2, 0.4, 0.3]);
        let bs = [
            pose([0.3, 0.1, 0.4], [0.4, 0.1, -0.2]),
            pose([-0.2, 0.3, 0.5], [-0.3, 0.6, 0.2]),
            pose([0.1, -0.4, 0.3], [0.1, -0.2, 0.9]),
        ];
        // Measurements off the model so the residuals (and J⁻¹ of them) are not trivial.
        let noise = pose([0.01, -0.02, 0.005], [0.05, -0.03, 0.02]);
        let data = AxbyData {
            a: bs.iter().map(|b| x * b * y * noise).collect(),
            b: bs.to_vec(),
            weights: vec![1.0, 2.0, 0.5],
        };
        let problem = Problem {
            data: &data,
            x0: Axby { x, y },
            delta: DVector::zeros(PARAMS),
            scale: data.weights.iter().map(|w| w.sqrt()).collect(),
            inv_sigma_r: 100.0,
            inv_sigma_t: 1000.0,
            trace: RefCell::new(Vec::new()),
        };
        let analytic = problem.jacobian().unwrap();
        let h = 1e-7;
        let mut p = Problem {
            data: &data,
            x0: Axby { x, y },
            delta: DVector::zeros(PARAMS),
            scale: problem.scale.clone(),
            inv_sigma_r: 100.0,
            inv_sigma_t: 1000.0,
            trace: RefCell::new(Vec::new()),
        };
        for k in 0..PARAMS {
            p.delta = DVector::zeros(PARAMS);
            p.delta[k] = h;
            let plus = p.residuals().unwrap();
            p.delta[k] = -h;
            let minus = p.residuals().unwrap();
            let numeric = (plus - minus) / (2.0 * h);
            let err = (numeric - analytic.column(k)).amax();
            // Residuals are O(1e3) per unit parameter; central differences are good to ~1e-5.
            assert!(err < 1e-4, "column {k}: max error {err}");
        }
    }
}
