//! Adaptive sessions: the plan is not fixed up front but asked for one pose at a time from a
//! [`PlanSource`] that sees the samples accepted so far (e.g. the next-best-pose planner,
//! `plan::nbv::AdaptivePlanner`). Each pose is visited with the ordinary driver
//! ([`run_session`]), so records, retries, faults and the folder layout are the same as for a
//! fixed plan; the manifest grows with the plan, so `replay` and `report` work unchanged.
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
use handeye_records::dataset::Dataset;
use handeye_robot::{Joints, Robot};

use crate::driver::{run_session, SessionEvent, SessionOutcome, SessionSetup};
use handeye_records::{SessionError, SessionManifest};

/// Yields the next pose of a session from the samples accepted so far.
pub trait PlanSource {
    /// The next flange pose and the joints that reach it, or `None` to end the session.
    fn next_pose(&mut self, samples: &[PosePair]) -> Option<(Pose, Joints)>;
    /// Flange poses a resumed session visited already (planned or measured): not to be chosen
    /// again.
    fn visited(&mut self, poses: &[Pose]);
}

impl PlanSource for AdaptivePlanner {
    fn next_pose(&mut self, samples: &[PosePair]) -> Option<(Pose, Joints)> {
        self.next(samples)
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
    mut setup: SessionSetup,
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
    let mut outcome = SessionOutcome::default();
    // The last recorded pose is finished first.
    let mut next = plan.poses.pop();
    loop {
        if next.is_none() {
            let samples = if setup.folder().samples_path().is_file() {
                Dataset::load(&setup.folder().samples_path())?.pairs
            } else {
                Vec::new()
            };
            next = source.next_pose(&samples);
        }
        let Some(pose) = next.take() else {
            break;
        };
        plan.visit(&setup, pose, robot, cameras, on_event, &mut outcome)?;
        // A camera lost at this pose is not asked again in this run (as in a fixed plan).
        setup.lost = outcome
            .failed_cameras
            .iter()
            .map(|f| f.camera.clone())
            .collect();
    }
    Ok(outcome)
}

/// The plan of a session that grows one pose at a time (adaptive and hand-guided sessions):
/// each pose is added to the manifest, visited with the ordinary driver on the plan so far, and
/// kept if its sample was accepted, dropped (its index reused by the next) if not.
pub(super) struct GrowingPlan {
    /// The poses so far (flange pose, joints).
    pub poses: Vec<(Pose, Joints)>,
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
            manifest_config,
            inputs,
            manual,
        })
    }

    /// Adds `pose` to the manifest and visits it with the ordinary driver (on `setup` with the
    /// plan so far), folding what happened into `outcome`; whether its sample was accepted
    /// (otherwise it is dropped from the plan again).
    pub(super) fn visit(
        &mut self,
        setup: &SessionSetup,
        pose: (Pose, Joints),
        robot: &mut dyn Robot,
        cameras: &mut [&mut dyn Camera],
        on_event: &mut dyn FnMut(SessionEvent),
        outcome: &mut SessionOutcome,
    ) -> Result<bool, SessionError> {
        self.poses.push(pose);
        self.write_manifests(setup)?;
        let step = SessionSetup {
            plan: self.poses.clone(),
            ..setup.clone()
        };
        let index = self.poses.len() - 1;
        let step_outcome = run_session(step, robot, cameras, on_event)?;
        outcome.visited_now += step_outcome.visited_now;
        outcome.moving_s += step_outcome.moving_s;
        outcome.settling_s += step_outcome.settling_s;
        outcome.modelled_moving_s += step_outcome.modelled_moving_s;
        outcome.moving_modelled_s += step_outcome.moving_modelled_s;
        outcome.skipped.extend(step_outcome.skipped.iter().cloned());
        outcome
            .failed_cameras
            .extend(step_outcome.failed_cameras.iter().cloned());
        // Several cameras: kept when any camera accepted it (their records of it stay).
        let accepted = step_outcome
            .accepted_by_camera
            .iter()
            .any(|poses| poses.contains(&index));
        if accepted {
            outcome.accepted = step_outcome.accepted;
            outcome.accepted_by_camera = step_outcome.accepted_by_camera;
        } else {
            // The next pose reuses the index: its rejected record (the corners it saw) is kept
            // aside, for the check of intrinsics that reject every pose.
            for folder in setup.cameras.iter().map(|c| &c.folder) {
                if folder.visit_path(index).is_file() {
                    folder.keep_rejected_visit(index)?;
                }
            }
            self.poses.pop();
        }
        Ok(accepted)
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
