//! The iterative method of Hirsh, DeSouza and Kak for `A = X·B·Y`, written faithfully.
//!
//! Rotations first: given the estimate of `R_Y`, every sample gives its own estimate
//! `R_X,i = R_A,i · (R_B,i · R_Y)⁻¹`; these are averaged as quaternions (signs aligned to the
//! current estimate, weighted sum, normalised). Then the same the other way:
//! `R_Y,i = (R_X · R_B,i)⁻¹ · R_A,i`, averaged. Repeat until the update is below tolerance.
//! Then translations by the same alternation: `t_X,i = t_A,i − R_X (R_B,i t_Y + t_B,i)` averaged,
//! then `t_Y,i = R_B,iᵀ (R_Xᵀ (t_A,i − t_X) − t_B,i)` averaged.
//!
//! The start is the identity for `R_Y` (the paper) unless a start or a closed-form warm start is
//! asked for. When the start is 180° from the truth, the scalar part `s` of the error quaternion
//! is zero and never grows (the paper's stall); it shows as per-sample estimates that never agree
//! (the norm of their mean quaternion, the "spread", stays well below 1). A stalled or
//! non-converging run restarts from the next guess of a fixed list.
//!
//! Per-iteration work is quaternion products only; the translation averages are linear in the
//! estimate, so their sums are formed once and each iteration costs O(1). Units: rad, m.

use nalgebra::{Matrix3, Quaternion, Translation3, UnitQuaternion, Vector3};

use super::{closed_form, Axby, AxbyData, Method, Phase, SolveError, SolverReport, TraceStep};
use crate::geometry::Pose;

/// Below this spread (norm of the weighted mean of the sign-aligned per-sample quaternions,
/// 1 when they all agree) the rotation alternation is considered stalled, not converged.
pub const STALL_SPREAD: f64 = 0.9;
/// Above this rotation residual RMS (deg) a converged rotation alternation is taken for a stall
/// at a wrong fixed point (the 180° case with robot rotations in a narrow cone keeps the
/// per-sample estimates in agreement while all of them are wrong), and other starts are tried.
pub const STALL_RESIDUAL_DEG: f64 = 5.0;

/// Options of the iterative method.
#[derive(Debug, Clone, PartialEq)]
pub struct IterativeOptions {
    /// Stop the rotation alternation when an iteration moves both rotations by less than this (rad).
    pub rotation_tolerance_rad: f64,
    /// Stop the translation alternation when an iteration moves both translations by less than this (m).
    pub translation_tolerance_m: f64,
    /// Cap on rotation iterations per start.
    pub max_rotation_iterations: usize,
    /// Cap on translation iterations.
    pub max_translation_iterations: usize,
    /// Start for `R_Y`; `None` is the identity (the paper).
    pub start: Option<UnitQuaternion<f64>>,
    /// Start `R_Y` from the closed form instead (fewer iterations; not the paper's default).
    pub warm_start: bool,
    /// How many other starts to try after a stall.
    pub max_restarts: usize,
}

impl Default for IterativeOptions {
    fn default() -> Self {
        IterativeOptions {
            rotation_tolerance_rad: 1e-12,
            translation_tolerance_m: 1e-12,
            max_rotation_iterations: 2000,
            max_translation_iterations: 20000,
            start: None,
            warm_start: false,
            max_restarts: 6,
        }
    }
}

/// What the iterative method produced.
#[derive(Debug, Clone, PartialEq)]
pub struct IterativeOutcome {
    /// The unknowns.
    pub solution: Axby,
    /// Rotation iterations of the successful start.
    pub rotation_iterations: usize,
    /// Rotation iterations spent on all starts, including stalled ones.
    pub total_rotation_iterations: usize,
    /// Translation iterations.
    pub translation_iterations: usize,
    /// Both alternations met their tolerance without a stall.
    pub converged: bool,
    /// Restarts after a stall or non-convergence.
    pub restarts: usize,
    /// Smaller of the last X and Y spreads (1 = per-sample estimates all agree).
    pub spread: f64,
    /// Per-iteration updates of the successful start (rotation, then translation).
    pub trace: Vec<TraceStep>,
}

impl IterativeOutcome {
    /// The solver report of this outcome under a method name.
    pub fn report(&self, method: Method) -> SolverReport {
        SolverReport {
            method,
            iterations: self.rotation_iterations + self.translation_iterations,
            converged: self.converged,
            restarts: self.restarts,
            trace: self.trace.clone(),
        }
    }
}

struct RotationRun {
    qx: UnitQuaternion<f64>,
    qy: UnitQuaternion<f64>,
    iterations: usize,
    converged: bool,
    spread: f64,
    trace: Vec<TraceStep>,
}

/// Angle between two unit quaternions (rad), accurate for tiny angles.
fn angle(a: &Quaternion<f64>, b: &Quaternion<f64>) -> f64 {
    let d = a.conjugate() * b;
    2.0 * d.imag().norm().atan2(d.w.abs())
}

/// Weighted, sign-aligned, normalised mean; returns the mean and the spread.
fn average(
    estimates: impl Iterator<Item = (f64, Quaternion<f64>)>,
    reference: Option<&Quaternion<f64>>,
) -> (Quaternion<f64>, f64) {
    let mut sum = Quaternion::new(0.0, 0.0, 0.0, 0.0);
    let mut total = 0.0;
    let mut reference = reference.copied();
    for (w, q) in estimates {
        let r = *reference.get_or_insert(q);
        let aligned = if r.coords.dot(&q.coords) < 0.0 { -q } else { q };
        sum += aligned * w;
        total += w;
    }
    let norm = sum.norm();
    if norm <= f64::MIN_POSITIVE {
        // The paper's degenerate bisection: opposite quaternions average to the identity.
        return (Quaternion::identity(), 0.0);
    }
    (sum / norm, norm / total)
}

fn rotations(
    qa: &[Quaternion<f64>],
    qb_conj: &[Quaternion<f64>],
    weights: &[f64],
    start: UnitQuaternion<f64>,
    options: &IterativeOptions,
) -> RotationRun {
    let mut qy = start.into_inner();
    let mut qx: Option<Quaternion<f64>> = None;
    let mut trace = Vec::new();
    let mut spread = 0.0;
    for iteration in 1..=options.max_rotation_iterations {
        // X from Y: R_X,i = R_A,i · R_Y⁻¹ · R_B,i⁻¹.
        let qy_conj = qy.conjugate();
        let (new_x, spread_x) = average(
            qa.iter()
                .zip(qb_conj)
                .zip(weights)
                .map(|((a, b), &w)| (w, a * qy_conj * b)),
            qx.as_ref(),
        );
        // Y from X: R_Y,i = R_B,i⁻¹ · R_X⁻¹ · R_A,i.
        let qx_conj = new_x.conjugate();
        let (new_y, spread_y) = average(
            qa.iter()
                .zip(qb_conj)
                .zip(weights)
                .map(|((a, b), &w)| (w, b * qx_conj * a)),
            Some(&qy),
        );
        let update = match &qx {
            Some(old_x) => angle(old_x, &new_x).max(angle(&qy, &new_y)),
            None => angle(&qy, &new_y),
        };
        qx = Some(new_x);
        qy = new_y;
        spread = spread_x.min(spread_y);
        trace.push(TraceStep {
            phase: Phase::Rotation,
            update,
        });
        if update < options.rotation_tolerance_rad {
            return RotationRun {
                qx: UnitQuaternion::new_normalize(new_x),
                qy: UnitQuaternion::new_normalize(qy),
                iterations: iteration,
                converged: spread >= STALL_SPREAD,
                spread,
                trace,
            };
        }
    }
    RotationRun {
        qx: UnitQuaternion::new_normalize(qx.unwrap_or_else(Quaternion::identity)),
        qy: UnitQuaternion::new_normalize(qy),
        iterations: options.max_rotation_iterations,
        converged: false,
        spread,
        trace,
    }
}

/// RMS over samples of the angle between `R_A,i` and `R_X R_B,i R_Y`, degrees.
fn rotation_rms_deg(
    qa: &[Quaternion<f64>],
    qb_conj: &[Quaternion<f64>],
    qx: &UnitQuaternion<f64>,
    qy: &UnitQuaternion<f64>,
) -> f64 {
    let (qx, qy) = (qx.into_inner(), qy.into_inner());
    let sum: f64 = qa
        .iter()
        .zip(qb_conj)
        .map(|(a, b)| angle(a, &(qx * b.conjugate() * qy)).powi(2))
        .sum();
    (sum / qa.len().max(1) as f64).sqrt().to_degrees()
}

/// The fixed list of restart guesses for `R_Y` after the first start stalls.
fn restart_guesses() -> Vec<UnitQuaternion<f64>> {
    use std::f64::consts::{FRAC_PI_2, PI};
    let axes = [Vector3::x(), Vector3::y(), Vector3::z()];
    axes.iter()
        .map(|a| UnitQuaternion::from_scaled_axis(a * FRAC_PI_2))
        .chain(
            axes.iter()
                .map(|a| UnitQuaternion::from_scaled_axis(a * PI)),
        )
        .collect()
}

/// Translations by alternation, given both rotations. Returns (t_X, t_Y, iterations, converged).
fn translations(
    data: &AxbyData,
    rx: &UnitQuaternion<f64>,
    options: &IterativeOptions,
    trace: &mut Vec<TraceStep>,
) -> (Vector3<f64>, Vector3<f64>, usize, bool) {
    // t_X,i = c_i − M_i t_Y with c_i = t_A,i − R_X t_B,i and M_i = R_X R_B,i; and
    // t_Y,i = M_iᵀ (c_i − t_X). The weighted means are linear in the other unknown, so each
    // alternation step is exactly the paper's per-sample average computed from these sums.
    let total: f64 = data.weights.iter().sum();
    let rx_m = rx.to_rotation_matrix().into_inner();
    let mut c_mean = Vector3::zeros();
    let mut m_mean = Matrix3::zeros();
    let mut mt_c_mean = Vector3::zeros();
    for ((a, b), &w) in data.a.iter().zip(&data.b).zip(&data.weights) {
        let m = rx_m * b.rotation.to_rotation_matrix().into_inner();
        let c = a.translation.vector - rx_m * b.translation.vector;
        c_mean += c * w;
        m_mean += m * w;
        mt_c_mean += m.transpose() * c * w;
    }
    c_mean /= total;
    m_mean /= total;
    mt_c_mean /= total;
    let mt_mean = m_mean.transpose();

    let mut ty = Vector3::zeros();
    let mut tx = c_mean - m_mean * ty;
    for iteration in 1..=options.max_translation_iterations {
        let new_ty = mt_c_mean - mt_mean * tx;
        let new_tx = c_mean - m_mean * new_ty;
        let update = (new_tx - tx).norm().max((new_ty - ty).norm());
        tx = new_tx;
        ty = new_ty;
        trace.push(TraceStep {
            phase: Phase::Translation,
            update,
        });
        if update < options.translation_tolerance_m {
            return (tx, ty, iteration, true);
        }
    }
    (tx, ty, options.max_translation_iterations, false)
}

/// Runs the iterative method from one start (no restarts). For benchmarks and tests.
pub fn solve_axby_from(
    data: &AxbyData,
    start: UnitQuaternion<f64>,
    options: &IterativeOptions,
) -> IterativeOutcome {
    let qa: Vec<Quaternion<f64>> = data.a.iter().map(|a| a.rotation.into_inner()).collect();
    let qb_conj: Vec<Quaternion<f64>> = data
        .b
        .iter()
        .map(|b| b.rotation.into_inner().conjugate())
        .collect();
    let run = rotations(&qa, &qb_conj, &data.weights, start, options);
    finish(data, run, 0, 0, options)
}

fn finish(
    data: &AxbyData,
    run: RotationRun,
    restarts: usize,
    earlier_iterations: usize,
    options: &IterativeOptions,
) -> IterativeOutcome {
    let mut trace = run.trace;
    let (tx, ty, t_iterations, t_converged) = translations(data, &run.qx, options, &mut trace);
    IterativeOutcome {
        solution: Axby {
            x: Pose::from_parts(Translation3::from(tx), run.qx),
            y: Pose::from_parts(Translation3::from(ty), run.qy),
        },
        rotation_iterations: run.iterations,
        total_rotation_iterations: earlier_iterations + run.iterations,
        translation_iterations: t_iterations,
        converged: run.converged && t_converged,
        restarts,
        spread: run.spread,
        trace,
    }
}

/// Runs the iterative method from the configured start, restarting from other guesses when the
/// rotation alternation stalls (s ≈ 0) or does not converge.
pub fn solve_axby_with_restarts(
    data: &AxbyData,
    options: &IterativeOptions,
) -> Result<IterativeOutcome, SolveError> {
    let qa: Vec<Quaternion<f64>> = data.a.iter().map(|a| a.rotation.into_inner()).collect();
    let qb_conj: Vec<Quaternion<f64>> = data
        .b
        .iter()
        .map(|b| b.rotation.into_inner().conjugate())
        .collect();
    let first = if options.warm_start {
        closed_form::solve_axby(data)?.y.rotation
    } else {
        options.start.unwrap_or_else(UnitQuaternion::identity)
    };
    let mut starts = vec![first];
    starts.extend(restart_guesses().into_iter().take(options.max_restarts));
    let mut spent = 0;
    let mut best: Option<(f64, usize, RotationRun)> = None;
    for (restarts, start) in starts.into_iter().enumerate() {
        let run = rotations(&qa, &qb_conj, &data.weights, start, options);
        let residual = rotation_rms_deg(&qa, &qb_conj, &run.qx, &run.qy);
        let stalled = run.spread < STALL_SPREAD || residual > STALL_RESIDUAL_DEG;
        if !stalled {
            return Ok(finish(data, run, restarts, spent, options));
        }
        tracing::debug!(
            restarts,
            spread = run.spread,
            residual_deg = residual,
            iterations = run.iterations,
            "iterative rotation alternation stalled; restarting from another guess"
        );
        spent += run.iterations;
        if residual.is_finite() && best.as_ref().is_none_or(|(r, _, _)| residual < *r) {
            best = Some((residual, restarts, run));
        }
    }
    if let Some((_, restarts, mut run)) = best {
        // No start gave a consistent answer (mislabelled or wild data): return the best-fitting
        // one, flagged as not converged, so the residuals and convention check can speak.
        run.converged = false;
        spent -= run.iterations;
        return Ok(finish(data, run, restarts, spent, options));
    }
    Err(SolveError::NoConvergence {
        restarts: options.max_restarts,
        iterations: spent,
    })
}
