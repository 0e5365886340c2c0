//! The Levenberg-Marquardt solver shared by the pose-space refinement ([`super::refine`]), the
//! reprojection-space refinement ([`super::reprojection`]), the arm's model
//! ([`super::kinematics`]) and the joint solve of several cameras ([`super::cameras`], in pose
//! and in pixel space).
//!
//! One driver, one meaning of "converged": [`minimize_normal`] runs Levenberg-Marquardt on
//! normal equations `JᵀJ δ = −Jᵀr` that the problem accumulates itself ([`NormalEquations`]),
//! with Marquardt's diagonal scaling. Right for wide, block-structured problems whose tall
//! Jacobian would be wasteful to form and factor (the reprojection refinement with per-pose
//! robot corrections: 12 + 9 + 6·frames columns, where a dense QR was ~50x slower), and for the
//! small ones (the pose-space refinement's 12 parameters, called once per noise-estimation
//! round: the normal equations by 3x3 blocks cost 8x fewer instructions per default solve than
//! a dense QR did; the reprojection refinement without corrections, its global columns only). The
//! several-camera pixel solve with per-pose flange corrections has the same arrowhead (6 per
//! camera and board, then 6 per pose).
//!
//! Pure maths: no I/O, no clocks. Depends on nalgebra only.

use nalgebra::DVector;

use super::arrow::{solve_damped, NormalMatrix};
use super::SolveError;

/// Most outer iterations (normal-equation builds) of [`minimize_normal`], unless the problem
/// says otherwise ([`NormalEquations::max_iterations`]).
pub(crate) const MAX_NORMAL_ITERATIONS: usize = 100;
/// Most damping increases [`minimize_normal`] tries for one step before it calls the point a
/// minimum.
const MAX_DAMPING_TRIES: usize = 12;
/// Damping of the first step of [`minimize_normal`] (relative to the diagonal of `JᵀJ`).
const INITIAL_DAMPING: f64 = 1e-4;
/// [`minimize_normal`] stops when an accepted step lowers the cost by less than this fraction.
const RELATIVE_COST_TOLERANCE: f64 = 1e-12;

/// What a minimisation spent and whether it met its tolerance.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Outcome {
    /// Residual evaluations: normal-equation builds plus trial steps.
    pub evaluations: usize,
    /// The solver met its tolerance (false: out of iterations or patience).
    pub converged: bool,
}

impl Outcome {
    /// Adds a later run's cost; converged only if both runs were.
    pub(crate) fn absorb(&mut self, later: Outcome) {
        self.evaluations += later.evaluations;
        self.converged &= later.converged;
    }
}

/// A least-squares problem that builds its own normal equations, for [`minimize_normal`].
pub(crate) trait NormalEquations {
    /// `JᵀJ` (dense, or an arrowhead kept as its parts: per-frame blocks coupled only through
    /// the global parameters, solved by its Schur complement in time and memory linear in the
    /// frames), `Jᵀr` and the cost `‖r‖²` at the current parameters; `None` when the residuals
    /// are not finite.
    fn normal_equations(&mut self) -> Option<(NormalMatrix, DVector<f64>, f64)>;

    /// The cost `‖r‖²` at the current parameters (a trial step's); `None` when the residuals are
    /// not finite. A problem may keep the residuals for the next [`Self::normal_equations`] when
    /// the step is taken ([`Self::accepted`]): they are those of the same point.
    fn cost(&mut self) -> Option<f64>;

    /// The parameters, for the solver to step and restore.
    fn params_mut(&mut self) -> &mut DVector<f64>;

    /// Called after every accepted step, e.g. to re-anchor a local parametrisation so the next
    /// linearisation is exact at the new point.
    fn accepted(&mut self) {}

    /// Called when the minimisation ends, however it ends: what [`Self::cost`] kept is dropped
    /// (the caller may reweight the problem before minimising again).
    fn finished(&mut self) {}

    /// Most outer iterations (normal-equation builds).
    fn max_iterations(&self) -> usize {
        MAX_NORMAL_ITERATIONS
    }
}

/// Levenberg-Marquardt on the normal equations of `problem` (Marquardt's scaling: the damping
/// adds `λ·diag(JᵀJ)`), from its current parameters; leaves it at the minimum.
///
/// A step is taken when it does not raise the cost; λ shrinks by 0.3 after a taken step and
/// grows tenfold after a refused one (or a singular damped system). Converged when a taken step
/// lowers the cost by less than [`RELATIVE_COST_TOLERANCE`], or when no damping lowers it (a
/// minimum to machine precision).
///
/// Errors: residuals that are not finite at the start of an iteration.
pub(crate) fn minimize_normal<P: NormalEquations>(problem: &mut P) -> Result<Outcome, SolveError> {
    let outcome = damped_steps(problem);
    problem.finished();
    outcome
}

/// [`minimize_normal`]'s iterations.
fn damped_steps<P: NormalEquations>(problem: &mut P) -> Result<Outcome, SolveError> {
    let mut lambda = INITIAL_DAMPING;
    let mut evaluations = 0;
    for _ in 0..problem.max_iterations() {
        let (h, g, cost) = problem
            .normal_equations()
            .ok_or(SolveError::RefinementFailed("residuals are not finite"))?;
        evaluations += 1;
        let mut accepted = false;
        for _ in 0..MAX_DAMPING_TRIES {
            let Some(step) = solve_damped(&h, &g, lambda) else {
                lambda *= 10.0;
                continue;
            };
            let step = -step;
            let saved = problem.params_mut().clone();
            *problem.params_mut() += &step;
            evaluations += 1;
            match problem.cost() {
                Some(new_cost) if new_cost <= cost => {
                    lambda = (lambda * 0.3).max(1e-12);
                    problem.accepted();
                    accepted = true;
                    let relative = (cost - new_cost) / cost.max(f64::MIN_POSITIVE);
                    if relative < RELATIVE_COST_TOLERANCE {
                        return Ok(Outcome {
                            evaluations,
                            converged: true,
                        });
                    }
                    break;
                }
                _ => {
                    *problem.params_mut() = saved;
                    lambda *= 10.0;
                }
            }
        }
        if !accepted {
            // No step lowers the cost at any damping: at the minimum to machine precision.
            return Ok(Outcome {
                evaluations,
                converged: true,
            });
        }
    }
    Ok(Outcome {
        evaluations,
        converged: false,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::DMatrix;

    /// Rosenbrock's function as least squares, `r = (10·(y − x²), 1 − x)`: a curved valley
    /// whose minimum (1, 1) plain Gauss-Newton steps overshoot from the classic start.
    struct Rosenbrock {
        p: DVector<f64>,
        accepted: usize,
    }

    impl Rosenbrock {
        fn residuals(&self) -> (f64, f64) {
            (10.0 * (self.p[1] - self.p[0] * self.p[0]), 1.0 - self.p[0])
        }
    }

    impl NormalEquations for Rosenbrock {
        fn normal_equations(&mut self) -> Option<(NormalMatrix, DVector<f64>, f64)> {
            let (r0, r1) = self.residuals();
            let j = DMatrix::from_row_slice(2, 2, &[-20.0 * self.p[0], 10.0, -1.0, 0.0]);
            let r = DVector::from_vec(vec![r0, r1]);
            Some((
                NormalMatrix::Dense(j.transpose() * &j),
                j.transpose() * &r,
                r.norm_squared(),
            ))
        }

        fn cost(&mut self) -> Option<f64> {
            let (r0, r1) = self.residuals();
            Some(r0 * r0 + r1 * r1)
        }

        fn params_mut(&mut self) -> &mut DVector<f64> {
            &mut self.p
        }

        fn accepted(&mut self) {
            self.accepted += 1;
        }
    }

    #[test]
    fn normal_equation_lm_finds_the_rosenbrock_minimum() {
        let mut problem = Rosenbrock {
            p: DVector::from_vec(vec![-1.2, 1.0]),
            accepted: 0,
        };
        let outcome = minimize_normal(&mut problem).unwrap();
        assert!(outcome.converged);
        assert!((problem.p[0] - 1.0).abs() < 1e-8, "{}", problem.p);
        assert!((problem.p[1] - 1.0).abs() < 1e-8, "{}", problem.p);
        assert!(problem.accepted > 0 && outcome.evaluations > problem.accepted);
    }

    #[test]
    fn broken_residuals_are_an_error_not_an_answer() {
        struct Broken(DVector<f64>);
        impl NormalEquations for Broken {
            fn normal_equations(&mut self) -> Option<(NormalMatrix, DVector<f64>, f64)> {
                None
            }
            fn cost(&mut self) -> Option<f64> {
                None
            }
            fn params_mut(&mut self) -> &mut DVector<f64> {
                &mut self.0
            }
        }
        let error = minimize_normal(&mut Broken(DVector::zeros(2))).unwrap_err();
        assert_eq!(
            error,
            SolveError::RefinementFailed("residuals are not finite")
        );
    }
}
