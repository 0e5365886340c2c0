//! Joint weighted nonlinear least squares over both unknowns of `A = X·B·Y`.
//!
//! Residual of sample i (6 numbers, camera frame): rotation `Log(R_pred · R_measᵀ) / σ_r` and
//! translation `(t_pred − t_meas) / σ_t`, times `sqrt(weight_i)`, with `pred = X·B_i·Y`. Under
//! Gaussian noise on `T_camera_target` with those per-axis sigmas this is the maximum-likelihood
//! estimate. Parameters are a local perturbation of the start on SO(3)×R³ per unknown
//! (`R_X ← exp(φ_X)·R_X`, `t_X ← t_X + ρ_X`; `R_Y ← R_Y·exp(φ_Y)`, `t_Y ← t_Y + ρ_Y`) with an
//! analytic Jacobian (`perturbed` is that parametrisation, shared with the reprojection-space
//! refinement). Levenberg-Marquardt on the 12x12 normal equations (`solve::lm::minimize_normal`,
//! shared with the reprojection-space refinement) minimises, re-anchoring the perturbation at
//! every accepted step; the normal equations are summed per sample by 3x3 blocks, no tall
//! Jacobian is formed (the speed of the default pipeline: `crates/01-maths/solve/benches/solve.rs`). The problem is
//! re-linearised at the optimum so the covariance `(JᵀJ)⁻¹` is exact there. Robust losses (Huber, Cauchy) work by iteratively
//! reweighted least squares on each sample's whitened norm. The sigmas themselves are
//! estimated from the residuals, alternated with the fit (see [`super::noise`]), unless
//! [`SolveOptions::estimate_noise`] says they are given.

use std::cell::RefCell;

use nalgebra::{
    DMatrix, DVector, Matrix3, SMatrix, SVector, Translation3, UnitQuaternion, Vector3,
};

use super::arrow::NormalMatrix;
use super::lm::{minimize_normal, NormalEquations};
use super::noise;
use super::{
    Axby, AxbyData, NoiseModel, PoseNoise, PoseSigma, RobustLoss, SolveError, SolveOptions,
    Uncertainty,
};
use handeye_core::geometry::{rotvec, Pose};

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

/// Residual rows (6: rotation then translation) and their Jacobian (6x12) of one sample.
pub(crate) type Rows = (SVector<f64, 6>, SMatrix<f64, 6, 12>);

/// Unscaled residual (rotation rad, translation m) of a sample `(a, b)` at `s`, and `X·B·Y`.
fn raw_residual(s: &Axby, a: &Pose, b: &Pose) -> (Vector3<f64>, Vector3<f64>, Pose) {
    let predicted = s.x * b * s.y;
    let r = rotvec(&(predicted.rotation * a.rotation.inverse()));
    let t = predicted.translation.vector - a.translation.vector;
    (r, t, predicted)
}

/// Whitened residual of a sample, rotation rows times `kr` (= scale/σ_r), translation rows
/// times `kt` (= scale/σ_t).
pub(crate) fn sample_residual(s: &Axby, a: &Pose, b: &Pose, kr: f64, kt: f64) -> SVector<f64, 6> {
    let (r, t, _) = raw_residual(s, a, b);
    let mut out = SVector::<f64, 6>::zeros();
    out.fixed_rows_mut::<3>(0).copy_from(&(r * kr));
    out.fixed_rows_mut::<3>(3).copy_from(&(t * kt));
    out
}

/// [`sample_residual`] and its analytic Jacobian in the parameters [φ_X, ρ_X, φ_Y, ρ_Y] at
/// `δ = 0` (the perturbation of [`perturbed`] around `s`).
pub(crate) fn sample_rows(s: &Axby, a: &Pose, b: &Pose, kr: f64, kt: f64) -> Rows {
    let (r, t, predicted) = raw_residual(s, a, b);
    let mut e = SVector::<f64, 6>::zeros();
    e.fixed_rows_mut::<3>(0).copy_from(&(r * kr));
    e.fixed_rows_mut::<3>(3).copy_from(&(t * kt));
    let mut j = SMatrix::<f64, 6, 12>::zeros();
    let j_inv = left_jacobian_inverse(&r);
    let r_pred = predicted.rotation.to_rotation_matrix().into_inner();
    let lever = predicted.translation.vector - s.x.translation.vector;
    let rxb = (s.x.rotation * b.rotation)
        .to_rotation_matrix()
        .into_inner();
    // Rotation rows: d/dφ_X = J⁻¹, d/dφ_Y = J⁻¹·R_pred; translations do not move them.
    j.fixed_view_mut::<3, 3>(0, 0).copy_from(&(j_inv * kr));
    j.fixed_view_mut::<3, 3>(0, 6)
        .copy_from(&(j_inv * r_pred * kr));
    // Translation rows: d/dφ_X = −[R_X (R_B t_Y + t_B)]×, d/dρ_X = I, d/dρ_Y = R_X R_B.
    j.fixed_view_mut::<3, 3>(3, 0)
        .copy_from(&(-lever.cross_matrix() * kt));
    j.fixed_view_mut::<3, 3>(3, 3)
        .copy_from(&(Matrix3::identity() * kt));
    j.fixed_view_mut::<3, 3>(3, 9).copy_from(&(rxb * kt));
    (e, j)
}

/// The whitened problem's normal equations at one point, split by group of rows.
#[derive(Clone, Copy)]
pub(super) struct Normal {
    /// `J_rᵀJ_r` of the rotation rows.
    rotation: SMatrix<f64, 12, 12>,
    /// `J_tᵀJ_t` of the translation rows.
    translation: SMatrix<f64, 12, 12>,
    /// `Jᵀr`.
    gradient: SVector<f64, 12>,
    /// `Σ r²` of the rotation rows and of the translation rows.
    squares: [f64; 2],
}

impl Normal {
    /// `JᵀJ`.
    fn information(&self) -> SMatrix<f64, 12, 12> {
        self.rotation + self.translation
    }

    /// `‖r‖²`.
    fn cost(&self) -> f64 {
        self.squares[0] + self.squares[1]
    }
}

/// The normal equations of the fit of `data` at `s`, samples scaled by `scale`
/// (sqrt(weight·robust weight)) and whitened by `noise`.
///
/// Σ `J_iᵀJ_i` of [`sample_rows`], accumulated by its 3x3 blocks: of the 6x12 Jacobian of a
/// sample, the rotation rows are `[A 0 B 0]` and the translation rows `[C k·I 0 D]` (`D` a
/// rotation times `k`), so most of the products are known zeros or `k²·I` (4x fewer operations
/// than the dense product; the unit test checks the two agree).
fn normal_equations(data: &AxbyData, s: &Axby, scale: &[f64], noise: &NoiseModel) -> Normal {
    let zero = Matrix3::zeros();
    // Rotation rows: blocks (φX,φX), (φX,φY), (φY,φY).
    let (mut r00, mut r02, mut r22) = (zero, zero, zero);
    // Translation rows: (φX,φX), (φX,ρX), (φX,ρY), (ρX,ρY), and Σk² for (ρX,ρX), (ρY,ρY).
    let (mut t00, mut t01, mut t03, mut t13) = (zero, zero, zero, zero);
    let mut kt2 = 0.0;
    let mut g = [Vector3::zeros(); 4];
    let mut squares = [0.0; 2];
    for (i, (a, b)) in data.a.iter().zip(&data.b).enumerate() {
        let kr = scale[i] / noise.rotation_sigma_rad;
        let kt = scale[i] / noise.translation_sigma_m;
        let (r, t, predicted) = raw_residual(s, a, b);
        let (er, et) = (r * kr, t * kt);
        let a_block = left_jacobian_inverse(&r) * kr;
        let b_block = a_block * predicted.rotation.to_rotation_matrix().into_inner();
        let c_block = -(predicted.translation.vector - s.x.translation.vector).cross_matrix() * kt;
        let d_block = (s.x.rotation * b.rotation)
            .to_rotation_matrix()
            .into_inner()
            * kt;
        r00 += a_block.tr_mul(&a_block);
        r02 += a_block.tr_mul(&b_block);
        r22 += b_block.tr_mul(&b_block);
        t00 += c_block.tr_mul(&c_block);
        t01 += c_block.transpose() * kt;
        t03 += c_block.tr_mul(&d_block);
        t13 += d_block * kt;
        kt2 += kt * kt;
        g[0] += a_block.tr_mul(&er) + c_block.tr_mul(&et);
        g[1] += et * kt;
        g[2] += b_block.tr_mul(&er);
        g[3] += d_block.tr_mul(&et);
        squares[0] += er.norm_squared();
        squares[1] += et.norm_squared();
    }
    let symmetric = |blocks: &[(usize, usize, Matrix3<f64>)]| {
        let mut m = SMatrix::<f64, 12, 12>::zeros();
        for &(row, col, block) in blocks {
            m.fixed_view_mut::<3, 3>(3 * row, 3 * col).copy_from(&block);
            if row != col {
                m.fixed_view_mut::<3, 3>(3 * col, 3 * row)
                    .copy_from(&block.transpose());
            }
        }
        m
    };
    let identity = Matrix3::identity() * kt2;
    let mut gradient = SVector::<f64, 12>::zeros();
    for (k, part) in g.iter().enumerate() {
        gradient.fixed_rows_mut::<3>(3 * k).copy_from(part);
    }
    Normal {
        rotation: symmetric(&[(0, 0, r00), (0, 2, r02), (2, 2, r22)]),
        translation: symmetric(&[
            (0, 0, t00),
            (0, 1, t01),
            (0, 3, t03),
            (1, 1, identity),
            (1, 3, t13),
            (3, 3, identity),
        ]),
        gradient,
        squares,
    }
}

/// `‖r‖²` of the fit of `data` at `s` (see [`normal_equations`]).
fn cost(data: &AxbyData, s: &Axby, scale: &[f64], noise: &NoiseModel) -> f64 {
    data.a
        .iter()
        .zip(&data.b)
        .zip(scale)
        .map(|((a, b), k)| {
            sample_residual(
                s,
                a,
                b,
                k / noise.rotation_sigma_rad,
                k / noise.translation_sigma_m,
            )
            .norm_squared()
        })
        .sum()
}

/// The weighted fit for [`minimize_normal`]: parameters are the perturbation `δ` of
/// [`perturbed`] around an anchor that moves to every accepted point, so each linearisation is
/// at `δ = 0`, where the analytic Jacobian is exact. Stack-sized 12x12 normal equations built
/// per sample: no tall Jacobian is formed.
struct Fit<'a> {
    data: &'a AxbyData,
    anchor: Axby,
    delta: DVector<f64>,
    /// sqrt(weight_i · robust_i) per sample.
    scale: &'a [f64],
    noise: NoiseModel,
    /// Cost (½ Σ r²) at each evaluation.
    trace: RefCell<Vec<f64>>,
    /// The normal equations of the last linearisation (the noise estimate reuses them).
    last: RefCell<Option<Normal>>,
}

impl Fit<'_> {
    fn current(&self) -> Axby {
        perturbed(
            &self.anchor,
            &self.delta.fixed_rows::<PARAMS>(0).into_owned(),
        )
    }
}

impl NormalEquations for Fit<'_> {
    fn normal_equations(&mut self) -> Option<(NormalMatrix, DVector<f64>, f64)> {
        let normal = normal_equations(self.data, &self.current(), self.scale, &self.noise);
        let cost = normal.cost();
        self.trace.borrow_mut().push(0.5 * cost);
        if !cost.is_finite() {
            return None;
        }
        let h = normal.information();
        *self.last.borrow_mut() = Some(normal);
        Some((
            NormalMatrix::Dense(DMatrix::from_column_slice(PARAMS, PARAMS, h.as_slice())),
            DVector::from_column_slice(normal.gradient.as_slice()),
            cost,
        ))
    }

    fn cost(&mut self) -> Option<f64> {
        let cost = cost(self.data, &self.current(), self.scale, &self.noise);
        self.trace.borrow_mut().push(0.5 * cost);
        cost.is_finite().then_some(cost)
    }

    fn params_mut(&mut self) -> &mut DVector<f64> {
        &mut self.delta
    }

    fn accepted(&mut self) {
        self.anchor = self.current();
        self.delta.fill(0.0);
    }
}

/// Whitened residual norm of each sample (sigmas, 6 dof), its weight's variance included.
fn whitened_norms(data: &AxbyData, s: &Axby, noise: &NoiseModel) -> Vec<f64> {
    (0..data.len())
        .map(|i| {
            let (r, t, _) = raw_residual(s, &data.a[i], &data.b[i]);
            data.weights[i].sqrt()
                * ((r / noise.rotation_sigma_rad).norm_squared()
                    + (t / noise.translation_sigma_m).norm_squared())
                .sqrt()
        })
        .collect()
}

struct Run {
    solution: Axby,
    /// The normal equations where the minimiser last linearised: at the solution but for the
    /// last accepted step, which is below the convergence tolerance.
    last: Option<Normal>,
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
    let mut fit = Fit {
        data,
        anchor: *start,
        delta: DVector::zeros(PARAMS),
        scale,
        noise: *noise,
        trace: RefCell::new(Vec::new()),
        last: RefCell::new(None),
    };
    let outcome = minimize_normal(&mut fit)?;
    Ok(Run {
        solution: fit.current(),
        last: fit.last.into_inner(),
        evaluations: outcome.evaluations,
        converged: outcome.converged,
        trace: fit.trace.into_inner(),
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
    groups_of(&normal_equations(data, solution, scale, noise), scale)
}

/// [`group_redundancy`] from normal equations already built (with `scale`).
pub(super) fn groups_of(normal: &Normal, scale: &[f64]) -> Option<[(f64, f64); 2]> {
    let inverse = normal.information().cholesky()?.inverse();
    // Rows of zero weight are no observations (and their Jacobian rows are zero).
    let rows = 3.0 * scale.iter().filter(|&&k| k > 0.0).count() as f64;
    let share = |group: &SMatrix<f64, 12, 12>| inverse.component_mul(group).sum();
    Some([
        (normal.squares[0], rows - share(&normal.rotation)),
        (normal.squares[1], rows - share(&normal.translation)),
    ])
}

/// Whitened residual norm (sigmas, 6 dof) of every sample of `data` at `solution`, the fit of
/// the samples with `in_fit`: a sample in the fit is whitened by its noise alone (the noise
/// model's variance over its weight), one left out by its noise plus the uncertainty of its
/// prediction, `I/w_i + J_i·N⁻¹·J_iᵀ` (whitened, `N` the weighted information of the fitted
/// samples), so a sample is tested for what a fit without it can predict. `None` when `N` is
/// singular.
pub(super) fn test_norms(
    data: &AxbyData,
    solution: &Axby,
    noise: &NoiseModel,
    in_fit: &[bool],
) -> Option<Vec<f64>> {
    let (kr, kt) = (
        1.0 / noise.rotation_sigma_rad,
        1.0 / noise.translation_sigma_m,
    );
    let rows: Vec<Rows> = (0..data.len())
        .map(|i| sample_rows(solution, &data.a[i], &data.b[i], kr, kt))
        .collect();
    let mut normal = SMatrix::<f64, 12, 12>::zeros();
    for (i, (_, ji)) in rows.iter().enumerate().filter(|(i, _)| in_fit[*i]) {
        normal += ji.tr_mul(ji) * data.weights[i];
    }
    let inverse = normal.cholesky()?.inverse();
    Some(
        rows.iter()
            .enumerate()
            .map(|(i, (e, ji))| {
                // A sample of weight w has the noise model's variance over w.
                let weight = data.weights[i];
                if in_fit[i] {
                    return e.norm() * weight.sqrt();
                }
                let spread =
                    SMatrix::<f64, 6, 6>::identity() / weight + ji * inverse * ji.transpose();
                spread
                    .cholesky()
                    .map_or(e.norm(), |c| e.dot(&c.solve(e)).max(0.0).sqrt())
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
    refine_from(data, start, None, options)
}

/// [`refine`] with the noise estimate (when `options` estimate it) started at `noise`, the
/// sigmas of a fit of nearly the same data: it then settles in a round or two.
pub fn refine_from(
    data: &AxbyData,
    start: &Axby,
    noise: Option<NoiseModel>,
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
    if let Some(start) = noise {
        estimator = estimator.starting_at(start);
    }
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
            let scale = scale_of(&robust);
            // Without a robust loss the weights did not change since the last minimisation:
            // its final normal equations are those of the solution (to below its tolerance).
            let noise_settled = match (&run.last, robust_loss) {
                (Some(normal), false) => estimator.step_with(groups_of(normal, &scale)),
                _ => estimator.step(data, &run.solution, &scale),
            };
            noise = estimator.noise();
            run = minimise(data, &run.solution, &scale, &noise)?;
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
    let normal = normal_equations(data, &solution, &scale, &noise);
    let chi2 = normal.cost();
    if !chi2.is_finite() {
        return Err(SolveError::RefinementFailed("residuals"));
    }
    let dof = (6 * n).saturating_sub(PARAMS);
    let variance_factor = variance_factor(chi2, dof);
    let covariance = if options.covariance {
        normal
            .information()
            .try_inverse()
            .map(|inv| inv * variance_factor)
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
pub fn sample_information(solution: &Axby, b: &Pose, noise: &NoiseModel) -> SMatrix<f64, 12, 12> {
    let data = AxbyData {
        a: vec![solution.x * b * solution.y],
        b: vec![*b],
        weights: vec![1.0],
    };
    normal_equations(&data, solution, &[1.0], noise).information()
}

/// Residual degrees of freedom from which `χ²/dof` is trusted as the noise level.
///
/// Below it (fewer than 8 samples) the estimate of the noise is itself too noisy, so the factor
/// is floored at 1: a lucky fit of a few samples must not claim more certainty than the model.
pub const MIN_DOF_FOR_VARIANCE_FACTOR: usize = 36;

/// A-posteriori variance factor `χ²/dof`. With enough residual degrees of freedom it is used as
/// is, in both directions: when the real noise is smaller than the configured [`NoiseModel`]
/// (typical: the defaults are conservative) the covariance shrinks to match, so the reported
/// 1-sigma stays a 1-sigma (the Monte Carlo test in `tests/it/uncertainty.rs` checks the coverage
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

pub(crate) fn pose_sigma(cov: &SMatrix<f64, 6, 6>) -> PoseSigma {
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

    /// `X`, `Y`, three `B`s and a pose that puts each `A = X·B·Y·off` off the model, so the
    /// residuals (and J⁻¹ of them) are not trivial.
    fn off_model_fixture() -> (Pose, Pose, [Pose; 3], Pose) {
        let pose = |t: [f64; 3], r: [f64; 3]| {
            Pose::from_parts(
                Translation3::new(t[0], t[1], t[2]),
                UnitQuaternion::from_scaled_axis(Vector3::new(r[0], r[1], r[2])),
            )
        };
        (
            pose([0.1, -0.05, 0.2], [0.3, -0.2, 1.0]),
            pose([0.5, 0.2, -0.1], [-1.2, 0.4, 0.3]),
            [
                pose([0.3, 0.1, 0.4], [0.4, 0.1, -0.2]),
                pose([-0.2, 0.3, 0.5], [-0.3, 0.6, 0.2]),
                pose([0.1, -0.4, 0.3], [0.1, -0.2, 0.9]),
            ],
            pose([0.01, -0.02, 0.005], [0.05, -0.03, 0.02]),
        )
    }

    #[test]
    fn blockwise_normal_equations_equal_the_dense_product() {
        let (x, y, bs, off) = off_model_fixture();
        let data = AxbyData {
            a: bs.iter().map(|b| x * b * y * off).collect(),
            b: bs.to_vec(),
            weights: vec![1.0, 2.0, 0.5],
        };
        let scale: Vec<f64> = data.weights.iter().map(|w| w.sqrt()).collect();
        let noise = NoiseModel {
            rotation_sigma_rad: 0.01,
            translation_sigma_m: 0.002,
        };
        let s = Axby { x, y };
        let normal = normal_equations(&data, &s, &scale, &noise);
        let (mut rotation, mut translation) = (SMatrix::<f64, 12, 12>::zeros(), SMatrix::zeros());
        let mut gradient = SVector::<f64, 12>::zeros();
        let mut squares = 0.0;
        for ((a, b), k) in data.a.iter().zip(&data.b).zip(&scale) {
            let (e, j) = sample_rows(
                &s,
                a,
                b,
                k / noise.rotation_sigma_rad,
                k / noise.translation_sigma_m,
            );
            let (jr, jt) = (j.fixed_rows::<3>(0), j.fixed_rows::<3>(3));
            rotation += jr.tr_mul(&jr);
            translation += jt.tr_mul(&jt);
            gradient += j.tr_mul(&e);
            squares += e.norm_squared();
        }
        let size = translation.amax();
        assert!((normal.rotation - rotation).amax() < 1e-12 * size);
        assert!((normal.translation - translation).amax() < 1e-12 * size);
        assert!((normal.gradient - gradient).amax() < 1e-12 * gradient.amax());
        assert!((normal.cost() - squares).abs() < 1e-12 * squares);
        assert!((normal.cost() - cost(&data, &s, &scale, &noise)).abs() < 1e-12 * squares);
    }

    #[test]
    fn analytic_jacobian_matches_finite_differences() {
        let (x, y, bs, noise) = off_model_fixture();
        let a: Vec<Pose> = bs.iter().map(|b| x * b * y * noise).collect();
        let start = Axby { x, y };
        let h = 1e-7;
        for (i, (a, b)) in a.iter().zip(&bs).enumerate() {
            let k = [1.0f64, 2.0, 0.5][i].sqrt();
            let (kr, kt) = (100.0 * k, 1000.0 * k);
            let (e, analytic) = sample_rows(&start, a, b, kr, kt);
            assert!((e - sample_residual(&start, a, b, kr, kt)).amax() < 1e-12);
            for p in 0..PARAMS {
                let mut delta = SVector::<f64, PARAMS>::zeros();
                delta[p] = h;
                let plus = sample_residual(&perturbed(&start, &delta), a, b, kr, kt);
                delta[p] = -h;
                let minus = sample_residual(&perturbed(&start, &delta), a, b, kr, kt);
                let numeric = (plus - minus) / (2.0 * h);
                let err = (numeric - analytic.column(p)).amax();
                // Residuals are O(1e3) per unit parameter; central differences are good to ~1e-5.
                assert!(err < 1e-4, "sample {i}, column {p}: max error {err}");
            }
        }
    }
}
