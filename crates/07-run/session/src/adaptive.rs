//! Adaptive sessions: the plan is not fixed up front but asked for one pose at a time from a
//! [`PlanSource`] that sees the samples accepted so far (e.g. the next-best-pose planner,
//! `plan::nbv::AdaptivePlanner`). Each pose is visited by the run's one [`PoseLoop`] (started
//! at the first pose: records read once, detection workers started once), so records, retries,
//! faults and the folder layout are the same as for a fixed plan; the manifest grows with the
//! plan, so `replay` and `report` work unchanged.
//!
//! A pose whose board pose was rejected is dropped from the plan and its index reused by the
//! next pose (which then gets one attempt instead of two: the driver counts the earlier
//! failure); the source decides what to try next.
//!
//! A stopped adaptive session resumes like a fixed one: the manifest's poses are finished first
//! (the last may not have been reached), the source is told every pose already visited, and it
//! goes on choosing from the samples on disk.

use handeye_camera::Camera;
use handeye_core::geometry::Pose;
use handeye_core::setup::PosePair;
use handeye_plan::nbv::{best_per_second, AdaptivePlanner, AdaptiveStep};
use handeye_robot::{Joints, Robot};

use crate::driver::{PoseLoop, SessionEvent, SessionOutcome, SessionSetup};
use handeye_records::{SessionError, SessionManifest};

/// Yields the next pose of a session from the samples accepted so far.
pub trait PlanSource {
    /// The next flange pose and the joints that reach it, or `None` to end the session.
    /// `samples`: each camera's accepted samples so far, in the session's camera order (the
    /// planner camera's first).
    fn next_pose(&mut self, samples: &[Vec<PosePair>]) -> Option<(Pose, Joints)>;
    /// Flange poses a resumed session visited already (planned or measured): not to be chosen
    /// again.
    fn visited(&mut self, poses: &[Pose]);
}

/// The next-best pose of a cell's cameras, one or several: each camera has its own next-best-view
/// model (`plan::nbv::AdaptivePlanner`: its setup, its mount and board as solved from its own
/// samples so far, its noise) over the one candidate set (the planner camera's checked
/// candidates). A candidate's score is the sum, over the cameras not yet good enough that are
/// expected to see their board there (by the nominal cell), of each one's expected information
/// gain `ln(score now / score after)`, per second of arm time (the move from where the arm
/// stands); a candidate none of them gains from is not chosen. The plan stops when every camera
/// has met the target 1-sigma with the stop check's agreement (held-out error, rotation spread:
/// what its verdict would call GOOD), when it holds the plan's most poses (a pose counts when any
/// camera accepted it), or when the candidates run out. With one camera this is that camera's
/// planner's own choice and stop.
pub struct CellPlanner {
    /// One model per camera, the planner camera's first (its log is the run's), over the same
    /// candidates.
    planners: Vec<AdaptivePlanner>,
    /// Per camera, per candidate: whether it is expected to see its board there.
    sees: Vec<Vec<bool>>,
    /// The most poses the plan may take.
    max_poses: usize,
}

impl CellPlanner {
    /// A planner over the cameras' `planners` (the planner camera's first, each over the same
    /// candidates, in the session's camera order) with, per camera and candidate, whether it
    /// sees its board there.
    pub fn new(
        planners: Vec<AdaptivePlanner>,
        sees: Vec<Vec<bool>>,
        max_poses: usize,
    ) -> CellPlanner {
        CellPlanner {
            planners,
            sees,
            max_poses,
        }
    }

    /// The planner camera's model (its log holds the run's choices).
    pub fn primary(&self) -> &AdaptivePlanner {
        &self.planners[0]
    }

    /// Whether every camera met its target.
    pub fn reached_target(&self) -> bool {
        self.planners.iter().all(AdaptivePlanner::reached_target)
    }
}

/// The poses the cameras' `samples` were taken at: each camera's samples are named by their pose
/// (`pose-NNN`), and a pose counts once whichever cameras accepted it (a sample without a name
/// counts alone).
fn poses_kept(samples: &[Vec<PosePair>]) -> usize {
    let mut named = std::collections::BTreeSet::new();
    let mut unnamed = 0;
    for pair in samples.iter().flatten() {
        match &pair.id {
            Some(id) => {
                named.insert(id.as_str());
            }
            None => unnamed += 1,
        }
    }
    named.len() + unnamed
}

impl PlanSource for CellPlanner {
    fn next_pose(&mut self, all: &[Vec<PosePair>]) -> Option<(Pose, Joints)> {
        let solved: Vec<Option<f64>> = self
            .planners
            .iter_mut()
            .zip(all)
            .map(|(planner, samples)| planner.assess(samples).1)
            .collect();
        let done = self.reached_target() || poses_kept(all) >= self.max_poses;
        let choice = if done {
            None
        } else {
            // Only the cameras still short of their target weigh in.
            let gains: Vec<Vec<Option<f64>>> = self
                .planners
                .iter()
                .zip(all)
                .map(|(planner, samples)| {
                    if planner.reached_target() {
                        Vec::new()
                    } else {
                        planner.gains(samples)
                    }
                })
                .collect();
            let primary = &self.planners[0];
            let summed = (0..primary.candidates().len())
                .filter(|&i| primary.is_free(i))
                .filter_map(|i| {
                    let gain = gains
                        .iter()
                        .zip(&self.sees)
                        .filter(|(_, sees)| sees.get(i).copied().unwrap_or(false))
                        .filter_map(|(g, _)| g.get(i).copied().flatten())
                        .reduce(|a, b| a + b)?;
                    Some((i, gain))
                });
            best_per_second(summed, |i| primary.seconds(i))
        };
        // What the choice promises the planner camera (its 1-sigma with that sample, when it
        // sees its board there), as a one-camera planner's log says.
        let primary_samples = all.first().map_or(&[][..], Vec::as_slice);
        let predicted_sigma_mm = choice
            .filter(|&i| self.sees.first().and_then(|s| s.get(i)).copied() == Some(true))
            .and_then(|i| self.planners[0].predicted_sigma_mm(primary_samples, i));
        self.planners[0].log.push(AdaptiveStep {
            samples: primary_samples.len(),
            solved_sigma_mm: solved.first().copied().flatten(),
            chose: choice,
            predicted_sigma_mm,
        });
        let index = choice?;
        let mut pose = None;
        for planner in &mut self.planners {
            pose = Some(planner.take(index));
        }
        pose
    }

    fn visited(&mut self, poses: &[Pose]) {
        for planner in &mut self.planners {
            planner.mark_visited(poses);
        }
    }
}

/// Runs a session whose poses come from `source`, one at a time. `setup.plan` is ignored (the
/// source is the plan); `manifest_config` is the config path written into the manifest.
///
/// A several-camera session (`setup.cameras`, `cameras` their devices): every camera
/// grabs at each pose, every camera's folder gets the growing plan, and a pose is kept when any
/// camera accepted it (the cameras' records share the plan's numbering).
pub fn run_adaptive_session(
    setup: SessionSetup,
    manifest_config: std::path::PathBuf,
    source: &mut dyn PlanSource,
    robot: &mut dyn Robot,
    cameras: &mut [&mut dyn Camera],
    on_event: &mut dyn FnMut(SessionEvent),
) -> Result<SessionOutcome, SessionError> {
    // A resumed session: the manifest lists the poses chosen so far (the last one may not have
    // been reached); none of them, nor any pose visited and rejected, is chosen again.
    let mut plan = GrowingPlan::open(&setup, manifest_config)?;
    let mut seen: Vec<Pose> = plan.poses.iter().map(|(pose, _)| *pose).collect();
    // With the rejected records kept aside (their index reused by a later pose).
    for visit in setup
        .folder()
        .read_visits()?
        .into_iter()
        .chain(setup.folder().read_rejected_visits()?)
    {
        seen.push(visit.base_from_flange);
    }
    source.visited(&seen);
    // The last recorded pose is finished first.
    let mut next = plan.poses.pop();
    loop {
        if next.is_none() {
            next = source.next_pose(&plan.samples(setup.cameras.len()));
        }
        let Some(pose) = next.take() else {
            break;
        };
        plan.visit(&setup, pose, robot, cameras, on_event)?;
    }
    plan.finish()
}

/// The plan of a session that grows one pose at a time (adaptive and hand-guided sessions):
/// each pose is added to the manifest, visited by the run's pose loop on the plan so far, and
/// kept if its sample was accepted, dropped (its index reused by the next) if not.
pub(super) struct GrowingPlan {
    /// The poses so far (flange pose, joints).
    pub poses: Vec<(Pose, Joints)>,
    /// The run's pose loop, from its first pose on.
    run: Option<PoseLoop>,
    manifest_config: std::path::PathBuf,
    /// The input hashes written when the session was created: kept with every manifest rewrite.
    inputs: Vec<handeye_records::InputFile>,
    /// A hand-guided session (kept with every manifest rewrite).
    manual: bool,
}

impl GrowingPlan {
    /// The plan the session's manifest holds so far, with its input hashes and its hand-guided
    /// mark (the caller wrote the manifest when it created the session); empty without one.
    pub(super) fn open(
        setup: &SessionSetup,
        manifest_config: std::path::PathBuf,
    ) -> Result<GrowingPlan, SessionError> {
        let path = setup.folder().manifest_path();
        let (poses, inputs, manual) = if path.is_file() {
            let manifest = setup.folder().read_manifest()?;
            (recorded_plan(&manifest), manifest.inputs, manifest.manual)
        } else {
            (Vec::new(), Vec::new(), false)
        };
        Ok(GrowingPlan {
            poses,
            run: None,
            manifest_config,
            inputs,
            manual,
        })
    }

    /// Adds `pose` to the manifest and visits it with the run's pose loop (started here at the
    /// first pose, on `setup` with the plan so far); whether some camera accepted its sample
    /// (otherwise it is dropped from the plan again and its index given to the next pose).
    pub(super) fn visit(
        &mut self,
        setup: &SessionSetup,
        pose: (Pose, Joints),
        robot: &mut dyn Robot,
        cameras: &mut [&mut dyn Camera],
        on_event: &mut dyn FnMut(SessionEvent),
    ) -> Result<bool, SessionError> {
        self.poses.push(pose);
        self.write_manifests(setup)?;
        let index = self.poses.len() - 1;
        let run = match &mut self.run {
            Some(run) => {
                run.set_plan(self.poses.clone());
                run
            }
            None => self.run.insert(PoseLoop::start(
                SessionSetup {
                    plan: self.poses.clone(),
                    ..setup.clone()
                },
                cameras,
            )?),
        };
        run.visit_pending(robot, cameras, on_event)?;
        // Several cameras: kept when any camera accepted it (their records of it stay).
        let accepted = run.accepted_by_any(index);
        if !accepted {
            // The next pose reuses the index: its rejected record (the corners it saw) is kept
            // aside, for the check of intrinsics that reject every pose.
            for folder in setup.cameras.iter().map(|c| &c.folder) {
                if folder.visit_path(index).is_file() {
                    folder.keep_rejected_visit(index)?;
                }
            }
            self.poses.pop();
            run.forget(index);
        }
        Ok(accepted)
    }

    /// Each camera's accepted samples so far, from the pose loop. Before its first pose there
    /// are none: a resumed plan visits its last recorded pose first (which starts the loop), and
    /// a plan with no pose yet has no record.
    fn samples(&self, cameras: usize) -> Vec<Vec<PosePair>> {
        match &self.run {
            Some(run) => (0..cameras).map(|c| run.samples(c)).collect(),
            None => vec![Vec::new(); cameras],
        }
    }

    /// Ends the run: what its pose loop did (nothing without a pose).
    pub(super) fn finish(self) -> Result<SessionOutcome, SessionError> {
        match self.run {
            Some(run) => run.finish(),
            None => Ok(SessionOutcome::default()),
        }
    }
}

impl GrowingPlan {
    /// The plan so far into every camera's manifest (the session's, the first camera's, with its
    /// input hashes and hand-guided mark).
    fn write_manifests(&self, setup: &SessionSetup) -> Result<(), SessionError> {
        for (c, camera) in setup.cameras.iter().enumerate() {
            let mut manifest =
                SessionManifest::new(self.manifest_config.clone(), camera.setup, &self.poses);
            if c == 0 {
                manifest = manifest.with_inputs(self.inputs.clone());
                manifest.manual = self.manual;
            }
            camera.folder.write_manifest(&manifest)?;
        }
        Ok(())
    }
}

/// The poses (and joints) a growing session's manifest holds.
fn recorded_plan(manifest: &SessionManifest) -> Vec<(Pose, Joints)> {
    manifest
        .plan
        .iter()
        .map(|planned| (planned.base_from_flange, planned.joints()))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use handeye_core::geometry::pose_from_rotvec;
    use handeye_core::setup::Setup;
    use handeye_solve::SolveOptions;
    use nalgebra::Vector3;

    /// One camera's planner (eye-in-hand, a nominal cell) over `candidates`.
    fn planner_over(candidates: &[(Pose, Joints)]) -> AdaptivePlanner {
        let camera_mount =
            pose_from_rotvec(Vector3::new(0.03, -0.07, 0.04), Vector3::new(0.0, 0.0, 1.5));
        let target_mount = pose_from_rotvec(Vector3::new(0.6, 0.0, 0.0), Vector3::zeros());
        AdaptivePlanner::new(
            Setup::EyeInHand,
            camera_mount,
            target_mount,
            candidates.to_vec(),
            SolveOptions::default(),
            0.1,
            usize::MAX,
        )
    }

    /// With one camera the cell's planner is that camera's own rule: before any sample (the
    /// nominal model choosing, every view the same arm time) it takes the candidates in the
    /// order of the camera's own gains, each promising the 1-sigma the camera's model predicts
    /// with it, then none when they run out.
    #[test]
    fn with_one_camera_the_choices_follow_the_cameras_own_gains() {
        let down = pose_from_rotvec(
            Vector3::zeros(),
            Vector3::new(std::f64::consts::PI, 0.0, 0.0),
        );
        let candidates: Vec<(Pose, Joints)> = (0..6)
            .map(|i| {
                let turn = f64::from(i) * 0.15;
                let rotation = Vector3::new(turn.sin() * 0.4, turn.cos() * 0.3, 0.2 * turn);
                let at = Vector3::new(0.45 + 0.02 * f64::from(i), 0.01 * f64::from(i), 0.5);
                let pose = pose_from_rotvec(at, rotation) * down;
                (pose, Joints::zeros(6))
            })
            .collect();
        // The camera's own model, never taking: its gains before any sample, best first.
        let own = planner_over(&candidates);
        let gains: Vec<f64> = own.gains(&[]).into_iter().map(Option::unwrap).collect();
        let mut expected: Vec<usize> = (0..6).collect();
        expected.sort_by(|&a, &b| gains[b].total_cmp(&gains[a]));
        let mut cell = CellPlanner::new(vec![planner_over(&candidates)], vec![vec![true; 6]], 100);
        let mut taken = Vec::new();
        while let Some((pose, _)) = cell.next_pose(&[vec![]]) {
            taken.push(candidates.iter().position(|(p, _)| *p == pose).unwrap());
        }
        assert_eq!(taken, expected, "gains {gains:?}");
        for (step, &index) in cell.primary().log.iter().zip(&expected) {
            assert_eq!(step.predicted_sigma_mm, own.predicted_sigma_mm(&[], index));
        }
        assert_eq!(cell.primary().log[6].chose, None);
    }

    /// A candidate seen by two cameras gains for both: with the same model for each, the
    /// choice over the cameras goes to the candidate the second camera alone sees, whichever
    /// the first camera alone would take; with the second camera blind everywhere, the choice
    /// is the first camera's own.
    #[test]
    fn the_choice_sums_the_gains_of_the_cameras_that_see_their_board() {
        let down = pose_from_rotvec(
            Vector3::zeros(),
            Vector3::new(std::f64::consts::PI, 0.0, 0.0),
        );
        let at = |x: f64, rotation: Vector3<f64>| {
            pose_from_rotvec(Vector3::new(x, 0.0, 0.5), rotation) * down
        };
        let candidates: Vec<(Pose, Joints)> = [
            at(0.5, Vector3::new(0.0, 0.0, 1.0)),
            at(0.45, Vector3::new(0.5, 0.0, 0.0)),
            at(0.55, Vector3::new(0.0, 0.4, 0.2)),
        ]
        .into_iter()
        .map(|pose| (pose, Joints::zeros(6)))
        .collect();
        let planner = || planner_over(&candidates);
        let alone = CellPlanner::new(vec![planner()], vec![vec![true; 3]], 10)
            .next_pose(&[vec![]])
            .expect("a first pose");
        let first_alone = candidates
            .iter()
            .position(|(pose, _)| *pose == alone.0)
            .unwrap();
        let other = (first_alone + 1) % candidates.len();
        let choose = |second_sees: Vec<bool>| {
            let mut cell = CellPlanner::new(
                vec![planner(), planner()],
                vec![vec![true; 3], second_sees],
                10,
            );
            let (pose, _) = cell.next_pose(&[vec![], vec![]]).expect("a first pose");
            candidates.iter().position(|(p, _)| *p == pose).unwrap()
        };
        let mut only_other = vec![false; 3];
        only_other[other] = true;
        assert_eq!(choose(only_other), other, "the second camera's gain counts");
        assert_eq!(
            choose(vec![false; 3]),
            first_alone,
            "a blind camera adds nothing"
        );
    }
}
