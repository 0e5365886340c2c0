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
use handeye_plan::nbv::AdaptivePlanner;
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

impl PlanSource for AdaptivePlanner {
    /// The planner camera's samples choose (one camera's model).
    fn next_pose(&mut self, samples: &[Vec<PosePair>]) -> Option<(Pose, Joints)> {
        self.next(samples.first().map_or(&[][..], Vec::as_slice))
    }
    fn visited(&mut self, poses: &[Pose]) {
        self.mark_visited(poses);
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
