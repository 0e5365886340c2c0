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

use crate::camera::Camera;
use crate::dataset::Dataset;
use crate::geometry::Pose;
use crate::plan::nbv::AdaptivePlanner;
use crate::robot::{Joints, Robot};
use crate::setup::PosePair;

use super::SessionManifest;
use super::{run_session, SessionError, SessionEvent, SessionOutcome, SessionSetup};

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
pub fn run_adaptive_session(
    setup: SessionSetup,
    manifest_config: std::path::PathBuf,
    source: &mut dyn PlanSource,
    robot: &mut dyn Robot,
    camera: &mut dyn Camera,
    on_event: &mut dyn FnMut(SessionEvent),
) -> Result<SessionOutcome, SessionError> {
    // A resumed session: the manifest lists the poses chosen so far (the last one may not have
    // been reached); none of them, nor any pose visited and rejected, is chosen again.
    let mut plan = recorded_plan(&setup)?;
    // The input hashes written when the session was created stay with every manifest rewrite.
    let inputs = if setup.folder.manifest_path().is_file() {
        setup.folder.read_manifest()?.inputs
    } else {
        Vec::new()
    };
    let mut seen: Vec<Pose> = plan.iter().map(|(pose, _)| *pose).collect();
    for visit in setup.folder.read_visits()? {
        seen.push(visit.poses(&setup.folder.visit_path(visit.plan_index))?.0);
    }
    source.visited(&seen);
    let mut outcome = SessionOutcome::default();
    let mut finish_recorded = !plan.is_empty();
    loop {
        if !finish_recorded {
            let samples = if setup.folder.samples_path().is_file() {
                Dataset::load(&setup.folder.samples_path())?.pairs
            } else {
                Vec::new()
            };
            let Some(next) = source.next_pose(&samples) else {
                break;
            };
            plan.push(next);
        }
        finish_recorded = false;
        setup.folder.write_manifest(
            &SessionManifest::new(manifest_config.clone(), setup.setup, &plan)
                .with_inputs(inputs.clone()),
        )?;
        let step = SessionSetup {
            plan: plan.clone(),
            ..setup.clone()
        };
        let index = plan.len() - 1;
        let step_outcome = run_session(step, robot, camera, on_event)?;
        outcome.visited_now += step_outcome.visited_now;
        outcome.moving_s += step_outcome.moving_s;
        outcome.settling_s += step_outcome.settling_s;
        outcome.skipped.extend(step_outcome.skipped.iter().cloned());
        if step_outcome.accepted.contains(&index) {
            outcome.accepted = step_outcome.accepted;
        } else {
            plan.pop();
        }
    }
    Ok(outcome)
}

/// The poses (and joints) a resumed adaptive session's manifest holds; empty for a new one.
pub(super) fn recorded_plan(setup: &SessionSetup) -> Result<Vec<(Pose, Joints)>, SessionError> {
    if !setup.folder.manifest_path().is_file() {
        return Ok(Vec::new());
    }
    let manifest = setup.folder.read_manifest()?;
    let file = setup.folder.manifest_path();
    manifest
        .plan
        .iter()
        .enumerate()
        .map(|(i, planned)| {
            let pose = planned
                .base_from_flange
                .to_pose(&format!("plan[{i}].T_base_flange"))
                .map_err(|source| SessionError::Pose {
                    file: file.clone(),
                    source,
                })?;
            Ok((pose, planned.joints_deg.map(f64::to_radians)))
        })
        .collect()
}
