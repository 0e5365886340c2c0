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

use nalgebra::{Matrix3, Matrix4, Quaternion, Translation3, UnitQuaternion, Vector3, Vector4};

use super::{closed_form, Axby, AxbyData, Method, Phase, SolveError, SolverReport, TraceStep};
use handeye_core::geometry::Pose;

/// Below this spread (norm of the weighted mean of the sign-aligned per-sample quaternions,
/// 1 when they all agree) the rotation alternation is considered stalled, not converged.
pub const STALL_SPREAD: f64 = 0.9;
/// Above this rotation residual RMS (deg) a converged rotation alternation is taken for a stall
/// at a wrong fixed point (the 180° case with robot rotations in a narrow cone keeps the
/// per-sample estimates in agreement while all of them are wrong), and other starts are tried.
pub const STALL_RESIDUAL_DEG: f64 = 5.0;
/// A converged run whose rotation residual RMS exceeds `CROSS_CHECK_FACTOR` times the closed
/// form's plus [`CROSS_CHECK_MARGIN_DEG`] is taken for a stall at a wrong fixed point.
pub const CROSS_CHECK_FACTOR: f64 = 2.0;
/// Absolute margin of the closed-form cross-check, degrees (keeps noise-free data, where both
/// residuals are ~1e-12°, from triggering it).
pub const CROSS_CHECK_MARGIN_DEG: f64 = 0.01;

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
    /// Translation iterations.
    pub translation_iterations: usize,
    /// Both alternations met their tolerance without a stall.
    pub converged: bool,
    /// Restarts after a stall or non-convergence.
    pub restarts: usize,
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

/// The per-sample estimate maps of one half-step as 4x4 matrices on quaternion coordinates,
/// weights folded in: `w_i · (R_A,i · R_Y⁻¹ · R_B,i⁻¹)` is `maps[i] · coords(q_Y)` and likewise for
/// the Y half-step. The products are linear in the other unknown's quaternion, so building them
/// once makes each estimate 16 multiply-adds; the iterates are exactly the paper's.
struct EstimateMaps {
    maps: Vec<Matrix4<f64>>,
    total_weight: f64,
}

impl EstimateMaps {
    fn new(
        weights: &[f64],
        count: usize,
        product: impl Fn(usize, &Quaternion<f64>) -> Quaternion<f64>,
    ) -> Self {
        let maps = (0..count)
            .map(|i| {
                let mut m = Matrix4::zeros();
                for k in 0..4 {
                    let basis = Quaternion::from_vector(Vector4::ith(k, 1.0));
                    m.set_column(k, &(product(i, &basis).coords * weights[i]));
                }
                m
            })
            .collect();
        EstimateMaps {
            maps,
            total_weight: weights.iter().sum(),
        }
    }

    /// Weighted, sign-aligned, normalised mean of the estimates from `q`; returns the mean and
    /// the spread (norm of the weighted mean, 1 when all estimates agree). Signs are aligned to
    /// `reference`, or to the first estimate when there is none.
    fn average(&self, q: &Vector4<f64>, reference: Option<&Vector4<f64>>) -> (Vector4<f64>, f64) {
        let mut sum = Vector4::zeros();
        let mut reference = reference.copied();
        for m in &self.maps {
            let estimate = m * q;
            let r = *reference.get_or_insert(estimate);
            if r.dot(&estimate) < 0.0 {
                sum -= estimate;
            } else {
                sum += estimate;
            }
        }
        let norm = sum.norm();
        if norm <= f64::MIN_POSITIVE {
            // The paper's degenerate bisection: opposite quaternions average to the identity.
            return (Quaternion::identity().coords, 0.0);
        }
        (sum / norm, norm / self.total_weight)
    }
}

fn rotations(
    qa: &[Quaternion<f64>],
    qb_conj: &[Quaternion<f64>],
    weights: &[f64],
    start: UnitQuaternion<f64>,
    options: &IterativeOptions,
) -> RotationRun {
    let n = qa.len();
    // X from Y: R_X,i = R_A,i · R_Y⁻¹ · R_B,i⁻¹.
    let x_maps = EstimateMaps::new(weights, n, |i, qy| qa[i] * qy.conjugate() * qb_conj[i]);
    // Y from X: R_Y,i = R_B,i⁻¹ · R_X⁻¹ · R_A,i.
    let y_maps = EstimateMaps::new(weights, n, |i, qx| qb_conj[i] * qx.conjugate() * qa[i]);
    let as_quaternion = |v: &Vector4<f64>| Quaternion::from_vector(*v);
    let mut qy = start.into_inner().coords;
    let mut qx: Option<Vector4<f64>> = None;
    let mut trace = Vec::new();
    let mut spread = 0.0;
    for iteration in 1..=options.max_rotation_iterations {
        let (new_x, spread_x) = x_maps.average(&qy, qx.as_ref());
        let (new_y, spread_y) = y_maps.average(&new_x, Some(&qy));
        let update_y = angle(&as_quaternion(&qy), &as_quaternion(&new_y));
        let update = match &qx {
            Some(old_x) => angle(&as_quaternion(old_x), &as_quaternion(&new_x)).max(update_y),
            None => update_y,
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
                qx: UnitQuaternion::new_normalize(as_quaternion(&new_x)),
                qy: UnitQuaternion::new_normalize(as_quaternion(&qy)),
                iterations: iteration,
                converged: spread >= STALL_SPREAD,
                spread,
                trace,
            };
        }
    }
    RotationRun {
        qx: UnitQuaternion::new_normalize(
            qx.map(|v| as_quaternion(&v))
                .unwrap_or_else(Quaternion::identity),
        ),
        qy: UnitQuaternion::new_normalize(as_quaternion(&qy)),
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
    finish(data, run, 0, options)
}

fn finish(
    data: &AxbyData,
    run: RotationRun,
    restarts: usize,
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
        translation_iterations: t_iterations,
        converged: run.converged && t_converged,
        restarts,
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
    // The closed form is the cross-check: a run that fits clearly worse than it has settled on
    // a wrong fixed point (the s ≈ 0 case keeps per-sample estimates in agreement when the
    // robot's rotations lie in a narrow cone) and is restarted — from the closed form first.
    let closed = closed_form::solve_axby(data).ok();
    let closed_residual = closed
        .as_ref()
        .map(|c| rotation_rms_deg(&qa, &qb_conj, &c.x.rotation, &c.y.rotation));
    let first = match (&closed, options.warm_start) {
        (Some(c), true) => c.y.rotation,
        (None, true) => closed_form::solve_axby(data)?.y.rotation,
        (_, false) => options.start.unwrap_or_else(UnitQuaternion::identity),
    };
    let mut starts = vec![first];
    starts.extend(closed.as_ref().map(|c| c.y.rotation));
    starts.extend(restart_guesses());
    starts.truncate(options.max_restarts + 1);
    let mut spent = 0;
    let mut best: Option<(f64, usize, RotationRun)> = None;
    for (restarts, start) in starts.into_iter().enumerate() {
        let run = rotations(&qa, &qb_conj, &data.weights, start, options);
        let residual = rotation_rms_deg(&qa, &qb_conj, &run.qx, &run.qy);
        let worse_than_closed_form = closed_residual
            .is_some_and(|c| residual > CROSS_CHECK_FACTOR * c + CROSS_CHECK_MARGIN_DEG);
        // A run that hit the iteration cap (very slow linear convergence, e.g. on nearly
        // degenerate motion) also moves on: the closed-form start is much closer.
        let stalled = !run.converged
            || run.spread < STALL_SPREAD
            || residual > STALL_RESIDUAL_DEG
            || worse_than_closed_form;
        if !stalled {
            return Ok(finish(data, run, restarts, options));
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
        return Ok(finish(data, run, restarts, options));
    }
    Err(SolveError::NoConvergence {
        restarts: options.max_restarts,
        iterations: spent,
    })
}
