//! The stages of one run between opening its folder and solving it, in the order
//! [`super::drive_opened`] takes them: the strategy's checks before anything opens, the poses
//! checked again from where the arm stands, the session folder created (or the resumed one's
//! plan checked), the session driven, the arm time kept. Each stage is one function so the run
//! reads as its list.

use std::path::Path;

use crate::cell::{Hardware, PreparedCell};
use crate::{ManualOptions, SessionOutcome};
use handeye_core::geometry::Pose;
use handeye_plan::{Plan, Waypoint};
use handeye_records::{InputFile, SessionError, SessionFolder};
use handeye_robot::Joints;

use super::adaptive::{adaptive_candidates, drive_plan, AdaptiveSummary};
use super::arm_time::{arm_time, ArmTime};
use super::resume::{recorded_order, same_plan, ResumedSession};
use super::{RunError, RunObserver, RunRequest, SessionTarget, Strategy};

/// The strategy's checks before anything opens (the plan's, a held-out spec's, a real arm's
/// confirmation); whether the plan is adaptive.
pub(super) fn check_before_opening(
    cell: &PreparedCell,
    resumed: &mut Option<ResumedSession>,
    request: &RunRequest,
    strategy: &mut Strategy<'_>,
    observer: &mut dyn RunObserver,
) -> Result<bool, RunError> {
    match strategy {
        Strategy::Planned => {
            let adaptive = cell.config.adaptive();
            if let Some(views) = super::check_plan(cell)? {
                observer.cameras_planned(&views);
            }
            if !cell.is_simulated() && !request.motion_confirmed {
                observer
                    .confirm_motion(cell, cell.plan.waypoints.len())
                    .map_err(RunError::NotConfirmed)?;
            }
            Ok(adaptive)
        }
        Strategy::Holdout(spec) => {
            spec.validate()
                .map_err(|e| RunError::Holdout(e.to_string()))?;
            if !cell.is_simulated() && !request.motion_confirmed {
                observer
                    .confirm_motion(cell, spec.count)
                    .map_err(RunError::NotConfirmed)?;
            }
            Ok(false)
        }
        Strategy::HandGuided(guide) => {
            // A session a planned resume handed over (an older one without the mark) is marked
            // hand-guided.
            if let Some(resumed) = resumed {
                if !resumed.manifest.manual {
                    resumed.manifest.manual = true;
                    resumed.manifest_changed = true;
                }
            }
            guide.prepared(cell);
            Ok(false)
        }
    }
}

/// The poses a session visits.
pub(super) struct SessionPoses {
    /// Flange pose and joints of each, in the order given.
    pub(super) plan: Vec<(Pose, Joints)>,
    /// An adaptive plan's candidates' numbers in `handeye plan check`'s listing (empty
    /// otherwise).
    pub(super) candidate_numbers: Vec<usize>,
}

/// The poses this session visits, checked again from `start`, where the arm really is (the
/// cell was prepared from an assumed start), with an adaptive plan's candidates' numbers in
/// `handeye plan check`'s listing.
pub(super) fn poses_from_arm(
    cell: &mut PreparedCell,
    strategy: &Strategy<'_>,
    adaptive: bool,
    start: Joints,
) -> Result<SessionPoses, RunError> {
    match strategy {
        Strategy::Planned if adaptive => {
            let _ = cell.recheck_from(start);
            let candidates = adaptive_candidates(cell);
            if candidates.is_empty() {
                return Err(RunError::NoPassingPoseFromArm {
                    report: cell.report.to_string(),
                });
            }
            let candidate_numbers = candidates.iter().map(|(number, ..)| *number).collect();
            let plan = candidates
                .into_iter()
                .map(|(_, pose, joints)| (pose, joints))
                .collect();
            Ok(SessionPoses {
                plan,
                candidate_numbers,
            })
        }
        Strategy::Planned => match cell.recheck_from(start) {
            Ok(plan) => Ok(SessionPoses {
                plan,
                candidate_numbers: Vec::new(),
            }),
            Err(report) => Err(RunError::PlanFailsFromArm {
                report: report.to_string(),
            }),
        },
        Strategy::Holdout(spec) => {
            // Only the usable views are kept (each move is checked again before it is sent).
            let _ = cell.recheck_from(start);
            let views = Plan {
                waypoints: cell
                    .generate_views(spec)
                    .into_iter()
                    .map(Waypoint::LookAt)
                    .collect(),
            };
            let passing = cell.check_plan(&views).passing();
            if passing.is_empty() {
                return Err(RunError::Holdout(format!(
                    "from the arm's actual position none of the {} generated views is reachable and shows the board; nothing was moved",
                    spec.count
                )));
            }
            Ok(SessionPoses {
                plan: passing,
                candidate_numbers: Vec::new(),
            })
        }
        // Suggestions come from the plan's poses that pass their checks from where the arm
        // stands.
        Strategy::HandGuided(_) => {
            let _ = cell.recheck_from(start);
            Ok(SessionPoses {
                plan: cell.report.passing(),
                candidate_numbers: Vec::new(),
            })
        }
    }
}

/// The session folder: the resumed one with its plan checked against `plan` (a fixed plan
/// ordered for travel time keeps the order it was recorded in: `plan` becomes it), or a new one
/// with its manifest. `fixed_plan`: the manifest records the plan and the session visits it as
/// given (an adaptive or hand-guided session's plan grows as it goes).
#[allow(clippy::too_many_arguments)]
pub(super) fn session_folder(
    cell: &PreparedCell,
    resumed: Option<ResumedSession>,
    request: &RunRequest,
    strategy: &Strategy<'_>,
    plan: &mut Vec<(Pose, Joints)>,
    fixed_plan: bool,
    inputs: Vec<InputFile>,
    observer: &mut dyn RunObserver,
) -> Result<SessionFolder, RunError> {
    if let Some(ResumedSession {
        folder,
        mut manifest,
        mut manifest_changed,
        recorded_poses,
    }) = resumed
    {
        if fixed_plan && !same_plan(&manifest, plan) {
            match recorded_order(&manifest, plan) {
                Some(recorded) => *plan = recorded,
                // Nothing recorded yet: the plan of today's config is the session's plan.
                None if recorded_poses == 0 => {
                    observer.note(
                        "nothing was recorded yet: the session takes the plan of today's config",
                    );
                    manifest.plan = cell.manifest(cell.config.planner, plan).plan;
                    manifest_changed = true;
                }
                None => {
                    return Err(RunError::PlanChanged {
                        folder: folder.root().to_path_buf(),
                    })
                }
            }
        }
        if manifest_changed {
            folder.write_manifest(&manifest)?;
        }
        return Ok(folder);
    }
    let folder = match (&request.target, cell.config.listed) {
        (SessionTarget::New(out), true) => {
            if super::super::cameras::is_cameras_folder(out) {
                return Err(RunError::Cameras(format!(
                    "{}: already holds a session of listed cameras (rig.yaml): pass --resume to continue it, or choose another folder",
                    out.display()
                )));
            }
            SessionFolder::create(&super::super::cameras::camera_folder(
                out,
                &cell.config.camera().name,
            ))?
        }
        (SessionTarget::New(out), false) => SessionFolder::create(out)?,
        (SessionTarget::Created(_), true) => {
            return Err(RunError::Cameras(
                "a cell with several cameras cannot record into a staging folder".into(),
            ))
        }
        (SessionTarget::Created(folder), false) => folder.clone(),
        (SessionTarget::Resume(_), _) => unreachable!("a resume has its folder"),
    };
    for note in folder.notes() {
        observer.note(note);
    }
    let recorded: &[(Pose, Joints)] = if fixed_plan { plan } else { &[] };
    let manifest = cell
        .manifest(cell.config.planner, recorded)
        .with_inputs(inputs);
    let manifest = match strategy {
        Strategy::HandGuided(_) => manifest.hand_guided(),
        Strategy::Planned | Strategy::Holdout(_) => manifest,
    };
    folder.write_manifest(&manifest)?;
    Ok(folder)
}

/// The session driven to its end: a plan's poses (fixed, adaptive or held-out views) by the pose
/// loop, or a person's captures by the hand-guided loop.
#[allow(clippy::too_many_arguments)]
pub(super) fn drive_session(
    cell: &PreparedCell,
    folder: &SessionFolder,
    request: &RunRequest,
    strategy: &mut Strategy<'_>,
    (plan, candidate_numbers): (&[(Pose, Joints)], &[usize]),
    (start, adaptive, fixed_plan): (Joints, bool, bool),
    hardware: &mut Hardware,
    observer: &mut dyn RunObserver,
) -> Result<(SessionOutcome, Option<AdaptiveSummary>), RunError> {
    // What the ROS 2 graph publishes (the driver's calibration, its static chain) is the session's.
    if let Some(node) = &hardware.ros2 {
        for note in crate::cell::ros2::record_graph(cell, node, folder) {
            observer.note(&note);
        }
    }
    // A hand-guided session's captures are its plan; the others visit `plan`.
    let setup_plan = match strategy {
        Strategy::HandGuided(_) => Vec::new(),
        Strategy::Planned | Strategy::Holdout(_) => plan.to_vec(),
    };
    let setup = session_setup(cell, folder, request, setup_plan, plan, fixed_plan)?;
    let guide = match strategy {
        Strategy::HandGuided(guide) => guide,
        Strategy::Planned | Strategy::Holdout(_) => {
            observer.session_folder(folder, plan);
            observer.session_started(match strategy {
                Strategy::Holdout(_) => plan.len(),
                _ => cell.plan.waypoints.len(),
            });
            let (outcome, summary) = drive_plan(
                cell,
                setup,
                (plan, candidate_numbers),
                start,
                adaptive,
                hardware,
                observer,
            );
            observer.session_ended();
            if let Some(summary) = &summary {
                observer.note(&summary.to_string());
            }
            return Ok((outcome?, summary));
        }
    };
    observer.session_folder(folder, &[]);
    observer.session_started(plan.len());
    let mut planner = (!plan.is_empty() && cell.camera().intrinsics_known)
        .then(|| super::adaptive::suggester(cell, plan));
    let options = ManualOptions {
        real_arm: !cell.is_simulated() && !request.motion_confirmed,
        ..ManualOptions::default()
    };
    let outcome: Result<SessionOutcome, SessionError> = {
        let mut control = guide.control(cell, folder, plan, &mut *observer);
        let (robot, mut cameras) = hardware.devices();
        crate::run_manual_session(
            setup,
            cell.config_path(),
            planner.as_mut(),
            &options,
            robot,
            &mut cameras,
            control.as_mut(),
        )
    };
    observer.session_ended();
    guide.ended();
    Ok((outcome?, None))
}

/// The session's setup on `folder` visiting `setup_plan`, with the cell's other cameras each in
/// its folder beside it (a several-camera session; `plan` is what their manifests record when
/// `fixed_plan`, otherwise the plan grows as the session goes, in the planner camera's folder).
fn session_setup(
    cell: &PreparedCell,
    folder: &SessionFolder,
    request: &RunRequest,
    setup_plan: Vec<(Pose, Joints)>,
    plan: &[(Pose, Joints)],
    fixed_plan: bool,
) -> Result<crate::SessionSetup, RunError> {
    let mut setup = cell.session_setup(folder.clone(), setup_plan, request.stop.clone());
    setup.detector.jobs = request.jobs;
    if cell.config.listed {
        let root = request.target.root(folder);
        let resuming = matches!(request.target, SessionTarget::Resume(_));
        let recorded: &[(Pose, Joints)] = if fixed_plan { plan } else { &[] };
        cell.session_cameras(&mut setup, &root, resuming, recorded)
            .map_err(RunError::Cameras)?;
    }
    Ok(setup)
}

/// The arm time of a planned run with an arm that moved now (a person moved a hand-guided arm;
/// a recorded robot moved nothing), said and kept beside the result for the report.
pub(super) fn keep_arm_time(
    cell: &PreparedCell,
    folder: &SessionFolder,
    outcome: &SessionOutcome,
    observer: &mut dyn RunObserver,
) -> ArmTime {
    let arm_time = arm_time(cell, outcome);
    observer.note(&arm_time.to_string());
    // A failure to write it loses only this figure.
    if let Ok(text) = serde_yaml_ng::to_string(&arm_time) {
        if let Err(e) = folder.write_file(Path::new(ArmTime::FILE), text.as_bytes()) {
            observer.note(&format!("the arm time could not be kept: {e}"));
        }
    }
    arm_time
}
