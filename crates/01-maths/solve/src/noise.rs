//! Noise of the board poses from the data: variance component estimation (Förstner) of the
//! rotation and translation sigmas of `T_camera_target` from the pose-space residuals, alternated
//! with the fit until the sigmas settle, so the weights of rotation against translation (and the
//! reported 1-sigma) follow the data, not a guess. The same idea as the pixel fit's
//! `reprojection::noise`.
//!
//! Groups: the rotation rows and the translation rows of the whitened residual. Robot poses are
//! not a separate group here: in pose space their error reaches the residual only through
//! `X·δB·Y`, which 6 numbers per sample cannot tell apart from board-pose noise (the
//! reprojection fit, with many corners per frame, can), so it is absorbed in these two sigmas.
//!
//! Depends on the refinement's normal equations (`refine::group_redundancy`) and the option
//! types; nothing above `solve`.

use super::refine::{group_redundancy, MIN_DOF_FOR_VARIANCE_FACTOR};
use super::{Axby, AxbyData, EstimateNoise, NoiseModel, NoiseSource, PoseNoise, SolveOptions};

/// Most rounds of noise estimation (each a refit).
const MAX_NOISE_ROUNDS: usize = 12;
/// Estimation stops when no sigma changes by more than this fraction (a weight 1 % off moves
/// the answer far less than its uncertainty).
const NOISE_TOLERANCE: f64 = 0.01;
/// Bounds of the estimated rotation sigma, rad (0.0006° to 11°): below, the data are exact to
/// the solver's precision; above, the samples are not poses of one rigid cell.
pub const ROTATION_SIGMA_RANGE_RAD: (f64, f64) = (1e-5, 0.2);
/// Bounds of the estimated translation sigma, m (1 µm to 100 mm).
pub const TRANSLATION_SIGMA_RANGE_M: (f64, f64) = (1e-6, 0.1);

/// Alternates with the fit: holds the current noise model and what was estimated.
pub(super) struct Estimator {
    noise: NoiseModel,
    estimate: EstimateNoise,
    /// Enough residual degrees of freedom for the estimate to be trusted.
    enough: bool,
    rounds: usize,
    applied: bool,
    at_bound: [bool; 2],
}

impl Estimator {
    /// Starts from `options.noise` for a fit of `samples` samples.
    pub(super) fn new(samples: usize, options: &SolveOptions) -> Self {
        Estimator {
            noise: options.noise,
            estimate: options.estimate_noise,
            enough: (6 * samples).saturating_sub(12) >= MIN_DOF_FOR_VARIANCE_FACTOR,
            rounds: 0,
            applied: false,
            at_bound: [false; 2],
        }
    }

    /// Starts the estimate at `noise` instead (a fit near one whose sigmas were estimated
    /// settles in a round or two); the fixed point is the same, as the bounds are absolute.
    /// Only while the estimate is active: otherwise the sigmas are the options' and stay so.
    pub(super) fn starting_at(mut self, noise: NoiseModel) -> Self {
        if self.active() {
            self.noise = noise;
        }
        self
    }

    /// True when a sigma is to be estimated and the data can.
    pub(super) fn active(&self) -> bool {
        self.estimate.any() && self.enough
    }

    /// The current noise model.
    pub(super) fn noise(&self) -> NoiseModel {
        self.noise
    }

    /// One round at `solution` (sample scales `scale` = sqrt(weight·robust weight)); returns
    /// true when the sigmas have settled (or nothing is estimated any more).
    pub(super) fn step(&mut self, data: &AxbyData, solution: &Axby, scale: &[f64]) -> bool {
        if !self.active() || self.rounds >= MAX_NOISE_ROUNDS {
            return true;
        }
        self.step_with(group_redundancy(data, solution, scale, &self.noise))
    }

    /// [`Estimator::step`] from the groups' sums and redundancies already computed at the
    /// current noise (`None`: singular normal equations, nothing to estimate from).
    pub(super) fn step_with(&mut self, groups: Option<[(f64, f64); 2]>) -> bool {
        if !self.active() || self.rounds >= MAX_NOISE_ROUNDS {
            return true;
        }
        let Some(groups) = groups else {
            return true;
        };
        self.rounds += 1;
        let mut change: f64 = 0.0;
        let targets = [
            (
                self.estimate.rotation,
                &mut self.noise.rotation_sigma_rad,
                ROTATION_SIGMA_RANGE_RAD,
            ),
            (
                self.estimate.translation,
                &mut self.noise.translation_sigma_m,
                TRANSLATION_SIGMA_RANGE_M,
            ),
        ];
        for (k, ((wanted, sigma, range), (sum, redundancy))) in
            targets.into_iter().zip(groups).enumerate()
        {
            if !wanted || redundancy < 1.0 || !sum.is_finite() {
                continue;
            }
            let raw = *sigma * (sum / redundancy).sqrt();
            let new = raw.clamp(range.0, range.1);
            self.at_bound[k] = raw != new;
            change = change.max(((new - *sigma) / *sigma).abs());
            *sigma = new;
            self.applied = true;
        }
        change < NOISE_TOLERANCE
    }

    /// What the answer used, for the [`Calibration`](super::Calibration).
    pub(super) fn outcome(&self) -> PoseNoise {
        let source = |wanted: bool, at_bound: bool| {
            if !wanted {
                NoiseSource::Given
            } else if !self.enough || !self.applied {
                NoiseSource::TooFewSamples
            } else if at_bound {
                NoiseSource::AtBound
            } else {
                NoiseSource::Estimated
            }
        };
        PoseNoise {
            rotation_sigma_deg: self.noise.rotation_sigma_rad.to_degrees(),
            translation_sigma_mm: self.noise.translation_sigma_m * 1e3,
            rotation: source(self.estimate.rotation, self.at_bound[0]),
            translation: source(self.estimate.translation, self.at_bound[1]),
            rounds: self.rounds,
        }
    }
}

/// The noise of a fit whose answer does not depend on the sigmas (the iterative and closed-form
/// methods): the estimate at that answer, iterated to its fixed point.
pub(super) fn estimate_at(data: &AxbyData, solution: &Axby, options: &SolveOptions) -> PoseNoise {
    let mut estimator = Estimator::new(data.len(), options);
    let scale: Vec<f64> = data.weights.iter().map(|w| w.sqrt()).collect();
    while !estimator.step(data, solution, &scale) {}
    estimator.outcome()
}
