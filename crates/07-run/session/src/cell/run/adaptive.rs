//! The config's plan driven: fixed, or adaptively (the next-best pose among the candidates,
//! weighed by move time, until the result is good enough).

use std::sync::Arc;

use crate::{SessionEvent, SessionOutcome};
use handeye_core::geometry::Pose;
use handeye_core::setup::PosePair;
use handeye_plan::check::PlanReport;
use handeye_plan::nbv::StopCheck;
use handeye_plan::{GenerateSpec, Plan, Waypoint};
use handeye_records::SessionError;
use handeye_robot::Joints;
use handeye_solve::Calibration;

use super::super::Hardware;
use super::{PreparedCell, RunObserver};

/// How an adaptive plan went.
#[derive(Debug, Clone, PartialEq)]
pub struct AdaptiveSummary {
    /// Poses in the session's plan now.
    pub in_session: usize,
    /// Candidate poses that passed their checks.
    pub candidates: usize,
    /// The candidates chosen in this run, in order, by their numbers in `handeye plan check`'s
    /// listing (the session numbers its poses 0, 1, ... in this order).
    pub chosen_now: Vec<usize>,
    /// The target 1-sigma uncertainty, mm.
    pub target_uncertainty_mm: f64,
    /// The most poses the plan may take.
    pub max_poses: usize,
    /// The last solved 1-sigma uncertainty, mm, if a solve happened.
    pub solved_sigma_mm: Option<f64>,
    /// Whether the target was reached.
    pub reached: bool,
}

impl std::fmt::Display for AdaptiveSummary {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "adaptive plan: {} of {} candidate poses in the session ({} chosen in this run{}); target 1-sigma {:.3} mm {}",
            self.in_session,
            self.candidates,
            self.chosen_now.len(),
            if self.chosen_now.is_empty() {
                String::new()
            } else {
                format!(
                    ": candidates {} of `handeye plan check`, in that order",
                    self.chosen_now
                        .iter()
                        .map(usize::to_string)
                        .collect::<Vec<_>>()
                        .join(", ")
                )
            },
            self.target_uncertainty_mm,
            match self.solved_sigma_mm {
                Some(s) if self.reached => format!("reached ({s:.3} mm)"),
                Some(s) if self.in_session >= self.max_poses => format!(
                    "NOT reached ({s:.3} mm): stopped at plan.max_poses = {}",
                    self.max_poses
                ),
                Some(s) => format!("NOT reached ({s:.3} mm): candidates ran out"),
                None => "NOT reached (no solve)".into(),
            }
        )
    }
}

/// Drives the config's plan: adaptively (the next-best pose among `plan`'s candidates, until
/// good enough) or as the fixed `plan`; the adaptive summary with the outcome.
pub(super) fn drive_plan(
    cell: &PreparedCell,
    setup: crate::SessionSetup,
    (plan, candidate_numbers): (&[(Pose, Joints)], &[usize]),
    start: Joints,
    adaptive: bool,
    hardware: &mut Hardware,
    observer: &mut dyn RunObserver,
) -> (
    Result<SessionOutcome, SessionError>,
    Option<AdaptiveSummary>,
) {
    let folder = setup.folder().clone();
    let mut on_event = |event: SessionEvent| observer.event(event);
    if !adaptive {
        let (robot, mut cameras) = hardware.devices();
        let outcome = crate::run_session(setup, robot, &mut cameras, &mut on_event);
        return (outcome, None);
    }
    // A generated plan's `count` is the most poses it takes (it chooses from more).
    let max_poses = cell
        .config
        .plan
        .max_poses
        .or(cell.config.plan.generate.map(|g| g.count))
        .unwrap_or(plan.len())
        .min(plan.len());
    // One model per camera, the planner camera's first: each weighs in on every choice and
    // must be good enough to stop (`CellPlanner`); the plan's most poses bound them together.
    let planners = cell
        .run_order()
        .map(|camera| {
            let planner = cell
                .adaptive_planner(
                    camera,
                    plan.to_vec(),
                    cell.config.adaptive_target_mm(),
                    usize::MAX,
                )
                .with_min_poses(cell.config.plan.min_poses)
                .with_motion(cell.config.limits, start, per_pose_s(cell))
                .with_stop_check(good_enough(cell, camera));
            match arm_offsets(cell, camera, plan) {
                Some(arm) => planner.with_arm(arm),
                None => planner,
            }
        })
        .collect();
    let mut source = crate::CellPlanner::new(planners, sees(cell, plan), max_poses);
    let (robot, mut cameras) = hardware.devices();
    let outcome = crate::run_adaptive_session(
        setup,
        cell.config_path(),
        &mut source,
        robot,
        &mut cameras,
        &mut on_event,
    );
    let planner = source.primary();
    let summary = AdaptiveSummary {
        in_session: folder.read_manifest().map(|m| m.plan.len()).unwrap_or(0),
        candidates: plan.len(),
        chosen_now: planner
            .log
            .iter()
            .filter_map(|s| s.chose)
            .filter_map(|k| candidate_numbers.get(k).copied())
            .collect(),
        target_uncertainty_mm: cell.config.adaptive_target_mm(),
        max_poses,
        solved_sigma_mm: planner.log.last().and_then(|s| s.solved_sigma_mm),
        reached: source.reached_target(),
    };
    (outcome, Some(summary))
}

/// Per camera in run order, per candidate of `plan`: whether the nominal cell has the camera
/// see its board there.
fn sees(cell: &PreparedCell, plan: &[(Pose, Joints)]) -> Vec<Vec<bool>> {
    cell.run_order()
        .map(|c| {
            plan.iter()
                .map(|(flange, _)| cell.sees_board(c, flange))
                .collect()
        })
        .collect()
}

/// The suggestions of a hand-guided run over `plan`'s candidates: the cell's planner, every
/// camera weighing in as in an adaptive run, but never stopping on its own (the person decides
/// when to finish) and costing every view the same (the person moves the arm).
pub(super) fn suggester(cell: &PreparedCell, plan: &[(Pose, Joints)]) -> crate::CellPlanner {
    let planners = cell
        .run_order()
        .map(|camera| cell.adaptive_planner(camera, plan.to_vec(), 0.0, usize::MAX))
        .collect();
    crate::CellPlanner::new(planners, sees(cell, plan), usize::MAX)
}

/// With `solver.kinematics: joint_offsets | dh` and the arm's published model: the offsets
/// camera `camera`'s plan is scored with, free beside the transforms (those its `candidates`
/// determine at the nominal cell), so the plan aims for the joint spread that tells them apart
/// and stops when the transforms are good enough with them free. (The DH link corrections are
/// not planned for: the offsets lead, and the plan check says what a plan gives of the links.)
fn arm_offsets(
    cell: &PreparedCell,
    camera: usize,
    candidates: &[(Pose, Joints)],
) -> Option<handeye_plan::nbv::ArmOffsets> {
    use handeye_config::KinematicsChoice;
    if !matches!(
        cell.config.solver.kinematics(),
        KinematicsChoice::JointOffsets | KinematicsChoice::Dh
    ) {
        return None;
    }
    let chain = handeye_records::solve::dh_chain(cell.arm.as_ref()?);
    let nominal = &cell.config.cameras[camera].nominal;
    let joints: Vec<Vec<f64>> = candidates.iter().map(|(_, q)| q.to_vec()).collect();
    let free = handeye_solve::kinematics::estimable_offsets(
        nominal.setup,
        &chain,
        &joints,
        (&nominal.camera_mount, &nominal.target_mount),
        cell.config.solver.to_options().noise,
    );
    Some(handeye_plan::nbv::ArmOffsets { chain, free })
}

/// What one pose costs besides its move, s, for weighing candidates by arm time: the fixed
/// settle, the settle window when settling by measurement, and a little for the frame.
fn per_pose_s(cell: &PreparedCell) -> f64 {
    let s = &cell.config.session;
    let window = if s.settle_speed_deg_s > 0.0 {
        s.settle_window_s
    } else {
        0.0
    };
    s.settle_s + window + 0.05
}

/// The adaptive stop check besides the 1-sigma: the rotations spread well (the verdict's rule)
/// and the held-out error is within the verdict's accuracy — what the verdict would call GOOD.
fn good_enough(cell: &PreparedCell, camera: usize) -> StopCheck {
    let setup = cell.config.cameras[camera].setup;
    let options = cell.config.solver.to_options();
    let accuracy = cell.config.verdict.accuracy();
    StopCheck(Arc::new(move |samples: &[PosePair], c: &Calibration| {
        let robot: Vec<Pose> = samples.iter().map(|p| p.base_from_flange).collect();
        if handeye_solve::rotation_diversity(&robot).off_axis_deg
            < handeye_solve::verdict::GOOD_OFF_AXIS_DEG
        {
            return false;
        }
        match handeye_solve::verdict::held_out(setup, samples, &options, c) {
            Ok(h) => {
                h.translation_rms_mm <= accuracy.translation_mm
                    && h.rotation_rms_deg <= accuracy.rotation_deg
            }
            Err(_) => false,
        }
    }))
}

/// For an adaptive generated plan: candidate views beyond the plan's `count`, per pose of it.
pub const ADAPTIVE_EXTRA_CANDIDATES: usize = 2;

/// The views an adaptive generated plan adds to its own poses as candidates (another seed,
/// [`ADAPTIVE_EXTRA_CANDIDATES`] × `count` views on the same cap, so near and informative poses
/// are there to choose), checked, numbered after the plan's own poses (`count`, `count + 1`,
/// ...): what `handeye plan check` lists and the run chooses from. `None` for a plan file or
/// a plan that is not adaptive.
pub fn extra_candidates(cell: &PreparedCell) -> Option<PlanReport> {
    let (Some(spec), None) = (cell.config.plan.generate, &cell.config.plan.file) else {
        return None;
    };
    let count = (spec.count * ADAPTIVE_EXTRA_CANDIDATES)
        .min(handeye_plan::MAX_PLAN_POSES.saturating_sub(spec.count));
    if !cell.config.adaptive() || count == 0 {
        return None;
    }
    let extra = GenerateSpec {
        count,
        seed: spec.seed.wrapping_add(1),
        ..spec
    };
    let views = Plan {
        waypoints: cell
            .generate_views(&extra)
            .into_iter()
            .map(Waypoint::LookAt)
            .collect(),
    };
    let mut report = cell.check_plan(&views);
    for pose in &mut report.poses {
        pose.index += spec.count;
    }
    Some(report)
}

/// The candidates of an adaptive plan, checked from where the arm stands (the plan's poses that
/// pass their checks, then the [`extra_candidates`] that do), each with its number in
/// `handeye plan check`'s listing.
pub(super) fn adaptive_candidates(cell: &PreparedCell) -> Vec<(usize, Pose, Joints)> {
    let passing = |report: &PlanReport| -> Vec<(usize, Pose, Joints)> {
        report
            .poses
            .iter()
            .filter(|p| p.problems.is_empty())
            .filter_map(|p| p.joints.map(|q| (p.index, p.base_from_flange, q)))
            .collect()
    };
    let mut candidates = passing(&cell.report);
    if let Some(extra) = extra_candidates(cell) {
        candidates.extend(passing(&extra));
    }
    candidates
}
