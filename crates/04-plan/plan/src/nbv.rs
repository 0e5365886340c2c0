//! Next-best pose: choose, from a set of checked candidate poses (reachable, board visible), the
//! one whose sample would most reduce the predicted uncertainty of the calibration.
//!
//! The prediction is the Gauss-Newton covariance of the refinement: each sample at robot pose
//! `B` adds `JᵀJ` (see [`handeye_solve::refine::sample_information`]) to the information of the
//! samples so far; inverted and scaled by the variance factor of the latest solve, it is the
//! covariance the solver would report. The score of a candidate is the predicted
//! `σ²` summed over both unknowns, translation (mm²) plus rotation seen at a lever arm of
//! [`ROTATION_LEVER_M`] (a rotation error of one unknown moves a point that far away by
//! `lever · angle`). Units: metres and radians inside, mm in the target and the score.
//!
//! Arm time: with [`AdaptivePlanner::with_motion`] the planner knows where the arm stands and
//! picks the candidate that buys the most certainty per second of arm time —
//! `ln(score now / score after) / (move time + per-pose time)`, the move timed at the limits
//! ([`MotionLimits::joint_move_time`]) — instead of the best score alone; a near pose that
//! helps almost as much wins over a far one. Stopping: the solved 1-sigma must reach the target
//! after at least `min_poses` samples, and a caller's check (held-out error, rotation spread)
//! must agree ([`AdaptivePlanner::with_stop_check`]).
//!
//! Depends on `solve`, `robot` (joints, limits) and `geometry` only; the session drives it
//! through its plan-source trait.

use std::sync::Arc;

use nalgebra::{DMatrix, SMatrix};

use handeye_core::geometry::Pose;
use handeye_core::setup::{PosePair, Setup};
use handeye_robot::{Joints, MotionLimits};
use handeye_solve::kinematics::{offsets_information, DhChain};
use handeye_solve::refine::{mount_uncertainty, sample_information};
use handeye_solve::{self as solve, Axby, Calibration, SolveOptions};

/// Lever arm at which a rotation uncertainty is weighed against a translation one, m.
pub const ROTATION_LEVER_M: f64 = 0.5;

/// Prior information per parameter (1/rad², 1/m² in whitened units) so the sum is invertible
/// before the problem is observable; tiny next to one sample's information.
const PRIOR: f64 = 1e-6;

/// Predicted 1-sigma of both unknowns.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Predicted {
    /// Camera mount: total translation 1-sigma, mm.
    pub camera_translation_mm: f64,
    /// Target mount: total translation 1-sigma, mm.
    pub target_translation_mm: f64,
    /// Camera mount: total rotation 1-sigma, degrees.
    pub camera_rotation_deg: f64,
    /// Target mount: total rotation 1-sigma, degrees.
    pub target_rotation_deg: f64,
    /// The score minimised (mm²).
    pub score: f64,
}

impl Predicted {
    /// The larger translation 1-sigma of the two unknowns, mm (what the stop rule compares).
    pub fn worst_translation_mm(&self) -> f64 {
        self.camera_translation_mm.max(self.target_translation_mm)
    }
}

/// The arm's joint zero offsets estimated beside the two transforms (`solver.kinematics`):
/// predictions are made with them free, so a plan aims for the joint spread that tells them from
/// the transforms, and stops only when the transforms are good enough with them free.
#[derive(Debug, Clone)]
pub struct ArmOffsets {
    /// The arm's published chain.
    pub chain: DhChain,
    /// The joints whose offsets the candidates determine (`kinematics::estimable_offsets`).
    pub free: Vec<usize>,
}

/// A sample the predictions count: its flange pose and, where known, the joints it was taken at
/// (the arm's offsets act through them).
pub type Taken = (Pose, Option<Joints>);

/// What the predictions are made at: the cell's setup, the current estimate of both unknowns,
/// the solver's options (its noise model) and the variance factor of the latest solve.
#[derive(Debug, Clone)]
pub struct PredictionModel {
    /// Eye-in-hand or eye-to-hand.
    pub setup: Setup,
    /// The camera mount estimate.
    pub camera_mount: Pose,
    /// The target mount estimate.
    pub target_mount: Pose,
    /// The solver's options; their noise model weighs each sample.
    pub options: SolveOptions,
    /// The variance factor of the latest solve (1 before any).
    pub variance_factor: f64,
    /// The arm's offsets estimated with the transforms, if they are.
    pub arm: Option<ArmOffsets>,
}

impl PredictionModel {
    fn solution(&self) -> Axby {
        Axby::from_mounts(&self.camera_mount, &self.target_mount)
    }

    /// Parameters predicted: the transforms' 12, then one per free offset.
    fn params(&self) -> usize {
        12 + self.arm.as_ref().map_or(0, |arm| arm.free.len())
    }

    /// The information one sample at `taken` adds (whitened, [`Self::params`] square).
    fn sample(&self, (pose, joints): &Taken) -> DMatrix<f64> {
        if let (Some(arm), Some(q)) = (&self.arm, joints) {
            return offsets_information(
                self.setup,
                &arm.chain,
                &[q.to_vec()],
                (&self.camera_mount, &self.target_mount),
                self.options.noise,
                &arm.free,
            );
        }
        // A sample of unknown joints tells of the transforms alone.
        let own = sample_information(
            &self.solution(),
            &self.setup.chain_b(pose),
            &self.options.noise,
        );
        let mut out = DMatrix::zeros(self.params(), self.params());
        out.view_mut((0, 0), (12, 12)).copy_from(&own);
        out
    }

    /// Information of samples at these robot poses.
    fn information(&self, taken: &[Taken]) -> DMatrix<f64> {
        let n = self.params();
        let mut h = DMatrix::identity(n, n) * PRIOR;
        for sample in taken {
            h += self.sample(sample);
        }
        h
    }

    /// The covariance predicted from an information matrix (the offsets marginalised: the
    /// Schur complement of their block), mapped to the unknowns and scored.
    fn predict(&self, information: &DMatrix<f64>) -> Option<Predicted> {
        let n = information.nrows();
        let transforms: SMatrix<f64, 12, 12> = if n == 12 {
            information.fixed_view::<12, 12>(0, 0).into_owned()
        } else {
            let offsets = information.view((12, 12), (n - 12, n - 12)).into_owned();
            let cross = information.view((0, 12), (12, n - 12)).into_owned();
            let solved = offsets.cholesky()?.solve(&cross.transpose());
            let marginal = information.view((0, 0), (12, 12)) - &cross * solved;
            SMatrix::from_fn(|i, j| marginal[(i, j)])
        };
        let covariance = transforms.try_inverse()? * self.variance_factor;
        let u = mount_uncertainty(&self.solution(), &covariance, self.variance_factor);
        let lever_mm = ROTATION_LEVER_M * 1e3;
        let rot = |deg: f64| (deg.to_radians() * lever_mm).powi(2);
        let score = u.camera_mount.translation_mm.powi(2)
            + u.target_mount.translation_mm.powi(2)
            + rot(u.camera_mount.rotation_deg)
            + rot(u.target_mount.rotation_deg);
        Some(Predicted {
            camera_translation_mm: u.camera_mount.translation_mm,
            target_translation_mm: u.target_mount.translation_mm,
            camera_rotation_deg: u.camera_mount.rotation_deg,
            target_rotation_deg: u.target_mount.rotation_deg,
            score,
        })
    }

    /// Per candidate (`None` when `used`, or when no score can be predicted): how much a sample
    /// there, added to `taken`, reduces the predicted score, as `ln(score now / score after)`.
    fn gains(
        &self,
        taken: &[Taken],
        candidates: &[(Pose, Joints)],
        used: &[bool],
    ) -> Vec<Option<f64>> {
        let h = self.information(taken);
        let now = self.predict(&h).map(|p| p.score);
        candidates
            .iter()
            .zip(used)
            .map(|((pose, joints), used)| {
                if *used {
                    return None;
                }
                let added = &h + self.sample(&(*pose, Some(*joints)));
                let after = self.predict(&added)?.score;
                Some((now? / after).ln())
            })
            .collect()
    }
}

/// Of `(candidate, gain)`, the candidate with the most gain per second of arm time
/// (`seconds(i)`: the move to candidate `i` and its frame, > 0); at equal cost, the most gain
/// (the least score after). The one choice rule of a camera's planner and of a cell's.
pub fn best_per_second(
    gains: impl IntoIterator<Item = (usize, f64)>,
    seconds: impl Fn(usize) -> f64,
) -> Option<usize> {
    gains
        .into_iter()
        .map(|(i, gain)| (i, gain / seconds(i).max(1e-3)))
        .max_by(|a, b| a.1.total_cmp(&b.1))
        .map(|(i, _)| i)
}

/// A caller's judgement whether a solve is good enough to stop (say, its held-out error and the
/// rotation spread of the samples), asked only once the solved 1-sigma meets the target.
#[derive(Clone)]
pub struct StopCheck(pub Arc<StopCheckFn>);

/// The judgement of a [`StopCheck`]: the samples and the solve that met the target in, whether
/// to stop out.
pub type StopCheckFn = dyn Fn(&[PosePair], &Calibration) -> bool + Send + Sync;

impl std::fmt::Debug for StopCheck {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("StopCheck")
    }
}

/// Where the arm stands and what its time costs, for [`AdaptivePlanner::with_motion`].
#[derive(Debug, Clone, Copy, PartialEq)]
struct Motion {
    limits: MotionLimits,
    at: Joints,
    per_pose_s: f64,
}

/// One decision of the adaptive planner, for logs and reports.
#[derive(Debug, Clone, PartialEq)]
pub struct AdaptiveStep {
    /// Samples accepted when the decision was made.
    pub samples: usize,
    /// The 1-sigma of the latest solve (worst translation, mm), if one was made.
    pub solved_sigma_mm: Option<f64>,
    /// The candidate chosen (index into the candidate set), or `None` when the planner stopped.
    pub chose: Option<usize>,
    /// Predicted worst translation 1-sigma after that candidate, mm.
    pub predicted_sigma_mm: Option<f64>,
}

/// Greedy next-best-pose planner over a fixed candidate set, with a stop rule.
#[derive(Debug, Clone)]
pub struct AdaptivePlanner {
    /// The nominal cell until enough samples are solved, then the latest solve.
    model: PredictionModel,
    candidates: Vec<(Pose, Joints)>,
    used: Vec<bool>,
    target_uncertainty_mm: f64,
    min_samples: usize,
    min_stop: usize,
    max_samples: usize,
    motion: Option<Motion>,
    stop_check: Option<StopCheck>,
    /// How many times the caller's stop check said no.
    pub stop_check_refused: usize,
    /// Decisions so far.
    pub log: Vec<AdaptiveStep>,
    /// The latest calibration solved on the way (the one that met the target, when it did).
    pub latest: Option<Calibration>,
    reached: bool,
}

impl AdaptivePlanner {
    /// Samples before the planner starts solving: below this the variance factor is floored
    /// and the estimate is poor, so the nominal cell is used to plan.
    pub const DEFAULT_MIN_SAMPLES: usize = 6;

    /// A planner over checked `candidates` (target flange pose and joints), starting from the
    /// nominal unknowns; stops when the worst translation 1-sigma of a solve is at most
    /// `target_uncertainty_mm`, or after `max_samples` samples, or when candidates run out.
    pub fn new(
        setup: Setup,
        nominal_camera_mount: Pose,
        nominal_target_mount: Pose,
        candidates: Vec<(Pose, Joints)>,
        options: SolveOptions,
        target_uncertainty_mm: f64,
        max_samples: usize,
    ) -> Self {
        let used = vec![false; candidates.len()];
        AdaptivePlanner {
            model: PredictionModel {
                setup,
                camera_mount: nominal_camera_mount,
                target_mount: nominal_target_mount,
                options,
                variance_factor: 1.0,
                arm: None,
            },
            candidates,
            used,
            target_uncertainty_mm,
            min_samples: Self::DEFAULT_MIN_SAMPLES,
            min_stop: 0,
            max_samples,
            motion: None,
            stop_check: None,
            stop_check_refused: 0,
            log: Vec::new(),
            latest: None,
            reached: false,
        }
    }

    /// Weighs candidates by arm time: the arm stands at `start` and moves at `limits`; every
    /// pose also costs `per_pose_s` (settling, the frame).
    pub fn with_motion(mut self, limits: MotionLimits, start: Joints, per_pose_s: f64) -> Self {
        self.motion = Some(Motion {
            limits,
            at: start,
            per_pose_s: per_pose_s.max(0.0),
        });
        self
    }

    /// Never stops on the target before `min_poses` samples are accepted (the maximum still
    /// applies).
    pub fn with_min_poses(mut self, min_poses: usize) -> Self {
        self.min_stop = min_poses;
        self
    }

    /// Stops on the target only when `check` also agrees (asked with the samples and the solve
    /// that met the target).
    pub fn with_stop_check(mut self, check: StopCheck) -> Self {
        self.stop_check = Some(check);
        self
    }

    /// Predicts with the arm's joint offsets `arm` free: the gains favour the joint spread that
    /// tells them from the transforms, and the target must be met with them free too.
    pub fn with_arm(mut self, arm: ArmOffsets) -> Self {
        self.model.arm = Some(arm);
        self
    }

    /// Arm time of candidate `i` from where the arm stands (move and the per-pose time), s;
    /// without a motion model every candidate costs the same.
    pub fn seconds(&self, i: usize) -> f64 {
        match &self.motion {
            Some(m) => m.limits.joint_move_time(&m.at, &self.candidates[i].1) + m.per_pose_s,
            None => 1.0,
        }
    }

    /// The candidates (flange pose, joints).
    pub fn candidates(&self) -> &[(Pose, Joints)] {
        &self.candidates
    }

    /// Per candidate (`None` when taken already): how much its sample would reduce this
    /// camera's predicted score given `samples`, as `ln(score now / score after)`.
    pub fn gains(&self, samples: &[PosePair]) -> Vec<Option<f64>> {
        self.model
            .gains(&self.counted(samples), &self.candidates, &self.used)
    }

    /// The larger translation 1-sigma of the two unknowns this camera's model predicts once a
    /// sample at candidate `index` joins `samples`, mm (what a suggestion of it promises).
    pub fn predicted_sigma_mm(&self, samples: &[PosePair], index: usize) -> Option<f64> {
        let (pose, joints) = self.candidates.get(index)?;
        let h = self.model.information(&self.counted(samples));
        let added = &h + self.model.sample(&(*pose, Some(*joints)));
        self.model.predict(&added).map(|p| p.worst_translation_mm())
    }

    /// The samples as the predictions count them: each with the joints of the candidate it was
    /// taken at, when the arm's offsets are estimated (they act through the joints).
    fn counted(&self, samples: &[PosePair]) -> Vec<Taken> {
        samples
            .iter()
            .map(|p| {
                let joints = self.model.arm.as_ref().and_then(|_| {
                    self.candidates
                        .iter()
                        .find(|(candidate, _)| same_pose(candidate, &p.base_from_flange))
                        .map(|(_, q)| *q)
                });
                (p.base_from_flange, joints)
            })
            .collect()
    }

    /// Whether candidate `i` is still to be chosen (not taken).
    pub fn is_free(&self, i: usize) -> bool {
        !self.used.get(i).copied().unwrap_or(true)
    }

    /// Takes candidate `index`: not chosen again, and the arm stands there next.
    pub fn take(&mut self, index: usize) -> (Pose, Joints) {
        self.used[index] = true;
        if let Some(m) = &mut self.motion {
            m.at = self.candidates[index].1;
        }
        self.candidates[index]
    }

    /// Solves `samples` (from [`Self::DEFAULT_MIN_SAMPLES`] on) and judges the stop rule:
    /// whether to stop (good enough, or the most samples reached), with the solved worst
    /// translation 1-sigma, mm.
    pub fn assess(&mut self, samples: &[PosePair]) -> (bool, Option<f64>) {
        let mut solved_sigma_mm = None;
        if samples.len() >= self.min_samples {
            let model = &mut self.model;
            if let Ok(c) = solve::solve(model.setup, samples, &model.options) {
                model.camera_mount = c.camera_mount;
                model.target_mount = c.target_mount;
                // Predict the next views with the noise the fit used (estimated from the
                // samples unless given): the variance factor is relative to it.
                if let Some(noise) = &c.noise {
                    model.options.noise = noise.model();
                }
                if let Some(u) = &c.uncertainty {
                    model.variance_factor = u.variance_factor;
                    let sigma = u
                        .camera_mount
                        .translation_mm
                        .max(u.target_mount.translation_mm);
                    solved_sigma_mm = Some(sigma);
                }
                self.latest = Some(c);
            }
            // With the arm's offsets estimated the answer's 1σ is theirs too: predicted at the
            // solve just made, with the offsets free.
            if self.model.arm.is_some() {
                let with_offsets = self
                    .model
                    .predict(&self.model.information(&self.counted(samples)))
                    .map(|p| p.worst_translation_mm());
                solved_sigma_mm = match (solved_sigma_mm, with_offsets) {
                    (Some(a), Some(b)) => Some(a.max(b)),
                    _ => None,
                };
            }
        }
        let met = solved_sigma_mm.is_some_and(|s| s <= self.target_uncertainty_mm)
            && samples.len() >= self.min_stop;
        let good = met
            && match (&self.stop_check, &self.latest) {
                (Some(check), Some(c)) => {
                    let ok = (check.0)(samples, c);
                    if !ok {
                        self.stop_check_refused += 1;
                    }
                    ok
                }
                _ => true,
            };
        self.reached = good;
        (good || samples.len() >= self.max_samples, solved_sigma_mm)
    }

    /// Marks the candidates at these flange poses (within 1 mm and 0.1°) as taken: a resumed
    /// session's poses are not chosen again.
    pub fn mark_visited(&mut self, poses: &[Pose]) {
        for (used, (candidate, _)) in self.used.iter_mut().zip(&self.candidates) {
            *used |= poses.iter().any(|p| same_pose(p, candidate));
        }
    }

    /// Whether the planner stopped because the result was good enough: the last solve met the
    /// target uncertainty (after the minimum pose count, with the stop check's agreement).
    pub fn reached_target(&self) -> bool {
        self.reached
    }
}

/// Whether two flange poses are one (within 1 mm and 0.1°): a measured pose and the candidate
/// it was taken at.
fn same_pose(a: &Pose, b: &Pose) -> bool {
    (a.translation.vector - b.translation.vector).norm() < 1e-3
        && a.rotation.angle_to(&b.rotation) < 0.1f64.to_radians()
}

#[cfg(test)]
mod tests {
    use super::*;
    use handeye_core::geometry::pose_from_rotvec;
    use nalgebra::Vector3;

    /// Poses rotated about one axis only leave the problem unobservable; the planner must then
    /// prefer a candidate that rotates about another axis.
    #[test]
    fn prefers_a_rotation_about_a_new_axis() {
        let camera_mount =
            pose_from_rotvec(Vector3::new(0.03, -0.07, 0.04), Vector3::new(0.0, 0.0, 1.5));
        let target_mount = pose_from_rotvec(Vector3::new(0.6, 0.0, 0.0), Vector3::zeros());
        let about_z = |deg: f64| {
            pose_from_rotvec(
                Vector3::new(0.5, 0.0, 0.5),
                Vector3::new(0.0, 0.0, deg.to_radians()),
            ) * pose_from_rotvec(
                Vector3::zeros(),
                Vector3::new(std::f64::consts::PI, 0.0, 0.0),
            )
        };
        let taken = [about_z(0.0), about_z(20.0), about_z(-20.0), about_z(40.0)];
        let tilted = pose_from_rotvec(Vector3::new(0.5, 0.0, 0.5), Vector3::new(0.5, 0.0, 0.0))
            * pose_from_rotvec(
                Vector3::zeros(),
                Vector3::new(std::f64::consts::PI, 0.0, 0.0),
            );
        let candidates = [about_z(60.0), tilted, about_z(-40.0)];
        let model = PredictionModel {
            setup: Setup::EyeInHand,
            camera_mount,
            target_mount,
            options: SolveOptions::default(),
            variance_factor: 1.0,
            arm: None,
        };
        let taken: Vec<Taken> = taken.iter().map(|pose| (*pose, None)).collect();
        let candidates: Vec<(Pose, Joints)> = candidates
            .iter()
            .map(|pose| (*pose, Joints::zeros(6)))
            .collect();
        let gains = model.gains(&taken, &candidates, &[false; 3]);
        let best = best_per_second(
            gains
                .iter()
                .enumerate()
                .filter_map(|(i, g)| Some((i, (*g)?))),
            |_| 1.0,
        )
        .unwrap();
        assert_eq!(best, 1, "the tilted pose adds the missing rotation axis");
    }
}
