//! Noise estimation for the reprojection refinement: variance component estimation (Förstner)
//! of the corner noise and of the robot's repeatability from the residuals, alternated with the
//! fit until the sigmas settle, so the weights of corners against robot poses follow the data,
//! not a guess.
//!
//! Depends on the problem's residuals and normal equations, and on the pipeline's fit.

use super::outliers::reweight;
use super::problem::{reanchor, Problem};
use super::{fit, run_lm, ReprojectionOptions, RobotPrior};
use crate::arrow::inverse_parts;
use crate::lm::Outcome;
use crate::{RobustLoss, SolveError};

/// Most rounds of noise estimation (each a full refit).
const MAX_NOISE_ROUNDS: usize = 10;
/// Noise estimation stops when no sigma changes by more than this fraction (a weight 3 % off
/// moves the answer far less than its uncertainty).
const NOISE_TOLERANCE: f64 = 0.03;
/// The estimated robot repeatability stays within these multiples of the configured one: the
/// configured value is what the user knows about the arm, and a robot group that the pixels
/// explain completely (an exact arm) would otherwise drive its sigma towards zero.
pub(super) const ROBOT_SIGMA_RANGE: (f64, f64) = (0.1, 100.0);
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
    // The robot parameters' variances only: by blocks (linear in the frames), not the whole
    // inverse (cubic).
    let covariance = inverse_parts(&normal)?;
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
                    problem.prior_weights[f] * covariance.variance(o + i) / (sigma * sigma);
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

/// What noise estimation did, for the answer and its messages.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct NoiseReport {
    /// An estimate was applied (false: the configured noise stands).
    pub estimated: bool,
    /// The estimated robot repeatability ended at the bound of [`ROBOT_SIGMA_RANGE`] times the
    /// configured one: (used, configured).
    pub robot_at_bound: Option<(RobotPrior, RobotPrior)>,
}

/// Alternates noise estimation with the fit of `problem` (already fitted once) until the sigmas
/// settle, then fits once more; adds what it spent to `spent`.
pub(super) fn estimate_and_refit<'a>(
    mut problem: Problem<'a>,
    options: &ReprojectionOptions,
    spent: &mut Outcome,
) -> Result<(Problem<'a>, NoiseReport), SolveError> {
    // Only true once an estimate was applied: without one the configured noise stands.
    let mut estimated = false;
    for _ in 0..MAX_NOISE_ROUNDS {
        // After an applied round its estimate stands.
        let Some(estimate) = estimate_noise(&problem) else {
            break;
        };
        let change = estimate.apply(&mut problem, options);
        estimated = true;
        // One LM per round (robust weights following the new sigma), not a full fit: the
        // sigmas and the parameters converge together, and a final fit settles both.
        if options.robust != RobustLoss::None {
            reweight(&mut problem, options);
        }
        let (p, outcome) = run_lm(problem)?;
        problem = p;
        spent.absorb(outcome);
        if change < NOISE_TOLERANCE {
            break;
        }
    }
    let (p, outcome) = fit(problem, options)?;
    problem = p;
    spent.absorb(outcome);
    let mut robot_at_bound = None;
    if let (Some(given), Some(used)) = (options.robot_prior, problem.prior) {
        let at_bound = |a: f64, b: f64| {
            let ratio = a / b;
            ratio <= ROBOT_SIGMA_RANGE.0 * 1.0001 || ratio >= ROBOT_SIGMA_RANGE.1 * 0.9999
        };
        if at_bound(used.translation_sigma_m, given.translation_sigma_m)
            || at_bound(used.rotation_sigma_rad, given.rotation_sigma_rad)
        {
            robot_at_bound = Some((used, given));
        }
    }
    Ok((
        problem,
        NoiseReport {
            estimated,
            robot_at_bound,
        },
    ))
}
