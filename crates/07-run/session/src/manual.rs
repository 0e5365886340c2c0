//! Hand-guided capture (`handeye console`): no plan drives the arm; a person jogs or
//! hand-guides it (freedrive) to views of their choosing and asks for a sample where it stands.
//! Each capture is checked at once — too close to an earlier view, a blurred frame, the board
//! seen (the ordinary driver's detection) — and the cell's next-best-pose planner (every camera
//! weighing in, as in an adaptive run) suggests the view that helps most, which the arm can also
//! be sent to.
//!
//! A sample is taken with the ordinary driver ([`run_session`](crate::driver::run_session)) on a one-pose plan that is where
//! the arm already stands (the "move" is a no-op), so records, the folder layout, resume,
//! replay and report are those of any session; like an adaptive session, the manifest's plan
//! grows with each accepted capture, and a rejected capture's index is reused by the next.

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use image::GrayImage;

use handeye_camera::Camera;
use handeye_core::error_text::error_chain;
use handeye_core::geometry::{
    relative_rotation_axis, translation_distance, Pose, MIN_AXIS_ANGLE_RAD,
};
use handeye_records::dataset::Dataset;
use handeye_robot::{Joints, MotionLimits, Robot, RobotError, RobotStatus};
use handeye_vision::sharpness::sharpness;

use crate::adaptive::{CellPlanner, GrowingPlan, PlanSource};
use crate::driver::{wait_until_still, NotStill, SessionEvent, SessionOutcome, SessionSetup};
use handeye_records::SessionError;

/// What a person asks for during a manual session.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ManualCommand {
    /// Take a sample where the arm stands.
    Capture,
    /// Freedrive (teach mode) on or off.
    Freedrive(bool),
    /// Move the arm to the suggested view.
    GoToSuggestion,
    /// End the session (then it is solved).
    Finish,
}

/// What a manual session reports.
#[derive(Debug)]
pub enum ManualEvent<'a> {
    /// Where the arm stands.
    Arm {
        /// Joints, rad.
        joints: Joints,
        /// `T_base_flange`.
        base_from_flange: Pose,
        /// Freedrive is on.
        freedrive: bool,
    },
    /// A live frame where the arm stands (not recorded).
    Preview {
        /// The frame.
        image: &'a GrayImage,
        /// `T_base_flange` when it was taken.
        base_from_flange: Pose,
    },
    /// The view that helps most next.
    Suggestion {
        /// Its flange pose `T_base_flange`.
        pose: Pose,
        /// The joints that reach it.
        joints: Joints,
        /// The relative-rotation axis it adds (unit, base frame, upper hemisphere): from the
        /// accepted view nearest in rotation (of those at least
        /// [`MIN_AXIS_ANGLE_RAD`] away);
        /// `None` before the first capture.
        axis: Option<[f64; 3]>,
        /// Predicted worst translation 1-sigma after it, mm.
        predicted_sigma_mm: Option<f64>,
        /// The solved worst translation 1-sigma so far, mm.
        solved_sigma_mm: Option<f64>,
    },
    /// A capture's (or command's) immediate result.
    Check {
        /// Whether it went ahead.
        ok: bool,
        /// What was found.
        message: String,
    },
    /// The driver's progress for a capture.
    Session(SessionEvent),
}

/// The person's side of a manual session: the console page or the terminal.
pub trait ManualControl {
    /// The next command, waiting up to `timeout`; `None` if none came.
    fn next_command(&mut self, timeout: Duration) -> Option<ManualCommand>;
    /// A real arm is about to move to a suggested view: whether the person agrees.
    fn confirm_move(&mut self) -> bool;
    /// Something happened.
    fn event(&mut self, event: ManualEvent<'_>);
}

/// The immediate checks of a capture.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ManualOptions {
    /// A frame whose sharpness ([`sharpness`]) is below this is refused as blurred.
    pub min_sharpness: f64,
    /// A view closer than this in translation, m, ...
    pub min_translation_m: f64,
    /// ... and in rotation, rad, to an accepted one adds nothing and is refused.
    pub min_rotation_rad: f64,
    /// How often the live view and the arm's state are refreshed while waiting.
    pub live_every: Duration,
    /// The arm is real: the first move to a suggestion needs a confirmation.
    pub real_arm: bool,
}

impl Default for ManualOptions {
    fn default() -> Self {
        ManualOptions {
            min_sharpness: DEFAULT_MIN_SHARPNESS,
            min_translation_m: 0.01,
            min_rotation_rad: 3f64.to_radians(),
            live_every: Duration::from_millis(700),
            real_arm: false,
        }
    }
}

/// Below this [`sharpness`] a frame is refused as blurred (motion blur of an arm still moving,
/// a lens out of focus). A sharp step edge scores about 2, an edge blurred by a Gaussian of
/// sigma s (at half resolution) about 1/(2·s²): 0.5 refuses blur beyond about 2 px (full
/// resolution).
pub const DEFAULT_MIN_SHARPNESS: f64 = 0.5;

/// The axis a view at `base_from_flange` adds: relative to the accepted view nearest in rotation that is
/// far enough away to have one.
fn added_axis(accepted: &[(Pose, Joints)], base_from_flange: &Pose) -> Option<[f64; 3]> {
    accepted
        .iter()
        .filter_map(|(earlier, _)| {
            relative_rotation_axis(
                &earlier.rotation,
                &base_from_flange.rotation,
                MIN_AXIS_ANGLE_RAD,
            )
        })
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .map(|(axis, _)| axis.into())
}

/// The arm where it stands: a move to the joints it was just read at is a no-op, so the driver
/// takes its sample there without moving anything.
struct StandStill<'a>(&'a mut dyn Robot);

impl Robot for StandStill<'_> {
    fn base_from_flange(&mut self) -> Result<Pose, RobotError> {
        self.0.base_from_flange()
    }
    fn joint_positions(&mut self) -> Result<Joints, RobotError> {
        self.0.joint_positions()
    }
    fn move_linear(&mut self, _: &Pose, _: &MotionLimits) -> Result<(), RobotError> {
        Ok(())
    }
    fn move_joints(&mut self, _: &Joints, _: &MotionLimits) -> Result<(), RobotError> {
        Ok(())
    }
    fn stop(&mut self) -> Result<(), RobotError> {
        self.0.stop()
    }
    fn set_interrupt(&mut self, flag: Arc<AtomicBool>) {
        self.0.set_interrupt(flag)
    }
    fn status(&mut self) -> Result<RobotStatus, RobotError> {
        self.0.status()
    }
    // The driver settles on these: a frame is taken only once the arm has stood still.
    fn joint_speeds(&mut self) -> Result<Option<Joints>, RobotError> {
        self.0.joint_speeds()
    }
}

/// Runs (or resumes) a hand-guided session until the person finishes it or the stop flag is
/// set (then the arm is stopped, freedrive switched off and the error says how to resume).
/// `setup.plan` is ignored: the captures are the plan. `suggester`'s candidates are the views it
/// suggests. The session folder's manifest, marked hand-guided
/// ([`SessionManifest::hand_guided`](handeye_records::SessionManifest::hand_guided)), is the caller's to
/// write first: every capture keeps its mark. A several-camera session (`setup.cameras`,
/// `cameras` their devices, the planner camera first) grabs with every camera at each capture,
/// as a planned one does; the live view is the planner camera's.
pub fn run_manual_session(
    setup: SessionSetup,
    manifest_config: PathBuf,
    mut suggester: Option<&mut CellPlanner>,
    options: &ManualOptions,
    robot: &mut dyn Robot,
    cameras: &mut [&mut dyn Camera],
    control: &mut dyn ManualControl,
) -> Result<SessionOutcome, SessionError> {
    let mut growing = GrowingPlan::open(&setup, manifest_config)?;
    if let Some(planner) = suggester.as_deref_mut() {
        let seen: Vec<Pose> = growing.poses.iter().map(|(pose, _)| *pose).collect();
        planner.visited(&seen);
    }
    // The recorded plan's poses were all accepted except perhaps the last (refused, or a stop
    // mid-capture): it is dropped and its index reused, as during the session.
    let accepted = accepted_indices(&setup)?;
    while growing
        .poses
        .len()
        .checked_sub(1)
        .is_some_and(|last| !accepted.contains(&last))
    {
        growing.poses.pop();
    }
    robot.set_interrupt(setup.stop.clone());
    let mut freedrive = false;
    let mut confirmed = !options.real_arm;
    let mut suggestion = suggest(&setup, &growing.poses, suggester.as_deref_mut(), control)?;
    let mut last_live: Option<Instant> = None;
    let result = loop {
        if setup.stop.load(Ordering::SeqCst) {
            let _ = robot.stop();
            break Err(SessionError::Interrupted {
                plan_index: growing.poses.len(),
                recorded: growing.poses.len(),
                folder: setup.folder().root().to_path_buf(),
            });
        }
        if last_live.is_none_or(|t| t.elapsed() >= options.live_every) {
            last_live = Some(Instant::now());
            if let Err(e) = live_view(robot, &mut *cameras[0], freedrive, control) {
                break Err(e.into_session(&setup, growing.poses.len()));
            }
        }
        let Some(command) = control.next_command(Duration::from_millis(100)) else {
            continue;
        };
        match command {
            ManualCommand::Finish => break Ok(()),
            ManualCommand::Freedrive(on) => {
                if switch_freedrive(robot, on, control) {
                    freedrive = on;
                    last_live = None;
                }
            }
            ManualCommand::GoToSuggestion => {
                match go_to_suggestion(
                    &setup,
                    suggestion.map(|(_, joints)| joints),
                    (&mut confirmed, &mut freedrive),
                    robot,
                    control,
                ) {
                    Ok(true) => last_live = None,
                    Ok(false) => {}
                    Err(fault) => break Err(fault.into_session(&setup, growing.poses.len())),
                }
            }
            ManualCommand::Capture => {
                let was_freedrive = freedrive;
                if freedrive {
                    // The arm must hold still for the sample.
                    if let Err(e) = robot.set_freedrive(false) {
                        break Err(ArmFault::Robot(e).into_session(&setup, growing.poses.len()));
                    }
                    freedrive = false;
                }
                match capture(&setup, options, &mut growing, robot, cameras, control) {
                    Ok(true) => {
                        suggestion =
                            suggest(&setup, &growing.poses, suggester.as_deref_mut(), control)?;
                    }
                    Ok(false) => {}
                    Err(e) => break Err(e),
                }
                if was_freedrive && robot.set_freedrive(true).is_ok() {
                    freedrive = true;
                }
                last_live = None;
            }
        }
    };
    if freedrive {
        let _ = robot.set_freedrive(false);
    }
    // Kept whatever ended the session (a stop too): what was captured so far is taught.
    let taught = write_taught_plan(&setup, &growing.poses);
    let captured = growing.poses.len();
    let finished = growing.finish();
    result?;
    taught?;
    let mut outcome = finished?;
    outcome.accepted = (0..captured).collect();
    Ok(outcome)
}

/// `ManualCommand::Freedrive(on)`: switched and said; whether it switched. An arm whose
/// freedrive handeye cannot switch (ROS 2) is still hand-guided, by its own means: the message
/// says how, and capture works as ever.
fn switch_freedrive(robot: &mut dyn Robot, on: bool, control: &mut dyn ManualControl) -> bool {
    let word = if on { "on" } else { "off" };
    let (ok, message) = match robot.set_freedrive(on) {
        Ok(()) => (true, format!("freedrive {word}")),
        Err(RobotError::NotAvailable(how)) => (false, format!("freedrive {word}: {how}")),
        Err(e) => (false, format!("freedrive {word}: {}", error_chain(&e))),
    };
    control.event(ManualEvent::Check { ok, message });
    ok
}

/// `ManualCommand::GoToSuggestion`: the move to the suggested view (`joints`), confirmed once
/// for a real arm (`confirmed`), out of freedrive first (`freedrive`), checked like any move;
/// whether the arm moved. A move not made is said on the page; an arm that fails is the error.
fn go_to_suggestion(
    setup: &SessionSetup,
    joints: Option<Joints>,
    (confirmed, freedrive): (&mut bool, &mut bool),
    robot: &mut dyn Robot,
    control: &mut dyn ManualControl,
) -> Result<bool, ArmFault> {
    let refuse = |control: &mut dyn ManualControl, message: String| {
        control.event(ManualEvent::Check { ok: false, message });
        Ok(false)
    };
    let Some(joints) = joints else {
        return refuse(
            control,
            "no suggestion to go to (no candidate views left)".into(),
        );
    };
    if !*confirmed {
        *confirmed = control.confirm_move();
        if !*confirmed {
            return refuse(control, "the move was not confirmed; nothing moved".into());
        }
    }
    if *freedrive {
        robot.set_freedrive(false).map_err(ArmFault::Robot)?;
        *freedrive = false;
    }
    if let Some(check) = &setup.move_check {
        let from = robot.joint_positions().map_err(ArmFault::Robot)?;
        if let Some(problem) = check.problem(&from, &joints) {
            return refuse(
                control,
                format!("the move to the suggestion was not sent: {problem}"),
            );
        }
    }
    robot
        .move_joints(&joints, &setup.limits)
        .map_err(ArmFault::Robot)?;
    control.event(ManualEvent::Check {
        ok: true,
        message: "at the suggested view".into(),
    });
    Ok(true)
}

/// The file in a hand-guided session's folder that holds its accepted captures as a plan.
pub const TAUGHT_PLAN_FILE: &str = "taught-plan.yaml";

/// The plan indices of the captures on disk that were accepted, by any camera.
fn accepted_indices(setup: &SessionSetup) -> Result<Vec<usize>, SessionError> {
    let mut accepted = Vec::new();
    for camera in &setup.cameras {
        accepted.extend(
            camera
                .folder
                .read_visits()?
                .iter()
                .filter(|v| {
                    v.camera_from_target.is_some()
                        || (camera.estimate_intrinsics
                            && v.rejected.is_none()
                            && !v.corners_px.is_empty())
                })
                .map(|v| v.plan_index),
        );
    }
    accepted.sort_unstable();
    accepted.dedup();
    Ok(accepted)
}

/// Writes the accepted captures as a taught plan ([`TAUGHT_PLAN_FILE`]): each the joints the
/// arm stood at and the flange pose it reported there, so an arm with no kinematics handeye
/// knows can replay the views (`plan.file`), and any arm can repeat them without a person.
fn write_taught_plan(setup: &SessionSetup, poses: &[(Pose, Joints)]) -> Result<(), SessionError> {
    let accepted = accepted_indices(setup)?;
    let taught: Vec<(Pose, Joints)> = poses
        .iter()
        .enumerate()
        .filter(|(i, _)| accepted.contains(i))
        .map(|(_, pose)| *pose)
        .collect();
    if taught.is_empty() {
        return Ok(());
    }
    let text = format!(
        "# The views of this hand-guided session, taught: the joints each capture stood at and the\n# T_base_flange the arm reported there. Replay with `plan: {{file: {TAUGHT_PLAN_FILE}}}`.\n{}",
        handeye_plan::Plan::taught(&taught).to_yaml()
    );
    setup
        .folder()
        .write_file(std::path::Path::new(TAUGHT_PLAN_FILE), text.as_bytes())
}

/// A fault of the arm or camera outside a capture.
enum ArmFault {
    Robot(RobotError),
    Camera(handeye_camera::CameraError),
}

impl ArmFault {
    fn into_session(self, setup: &SessionSetup, recorded: usize) -> SessionError {
        let folder = setup.folder().root().to_path_buf();
        match self {
            ArmFault::Robot(RobotError::Interrupted) => SessionError::Interrupted {
                plan_index: recorded,
                recorded,
                folder,
            },
            ArmFault::Robot(source) => SessionError::Robot {
                plan_index: recorded,
                recorded,
                folder,
                source,
            },
            ArmFault::Camera(source) => SessionError::Camera {
                plan_index: recorded,
                recorded,
                folder,
                source,
            },
        }
    }
}

/// Reports where the arm stands and a live frame from there.
fn live_view(
    robot: &mut dyn Robot,
    camera: &mut dyn Camera,
    freedrive: bool,
    control: &mut dyn ManualControl,
) -> Result<(), ArmFault> {
    let joints = robot.joint_positions().map_err(ArmFault::Robot)?;
    let base_from_flange = robot.base_from_flange().map_err(ArmFault::Robot)?;
    control.event(ManualEvent::Arm {
        joints,
        base_from_flange,
        freedrive,
    });
    let frame = camera.grab(Instant::now()).map_err(ArmFault::Camera)?;
    control.event(ManualEvent::Preview {
        image: &frame.image,
        base_from_flange,
    });
    Ok(())
}

/// The cell planner's next view from every camera's samples on disk, told to `control`.
fn suggest(
    setup: &SessionSetup,
    accepted: &[(Pose, Joints)],
    suggester: Option<&mut CellPlanner>,
    control: &mut dyn ManualControl,
) -> Result<Option<(Pose, Joints)>, SessionError> {
    let Some(planner) = suggester else {
        return Ok(None);
    };
    let samples = setup
        .cameras
        .iter()
        .map(|camera| {
            let path = camera.folder.samples_path();
            Ok(if path.is_file() {
                Dataset::load(&path)?.pairs
            } else {
                Vec::new()
            })
        })
        .collect::<Result<Vec<_>, SessionError>>()?;
    let next = planner.next_pose(&samples);
    let step = planner.primary().log.last();
    if let Some((pose, joints)) = next {
        control.event(ManualEvent::Suggestion {
            pose,
            joints,
            axis: added_axis(accepted, &pose),
            predicted_sigma_mm: step.and_then(|s| s.predicted_sigma_mm),
            solved_sigma_mm: step.and_then(|s| s.solved_sigma_mm),
        });
    }
    Ok(next)
}

/// One capture: the immediate checks, then a sample with the driver (folded into `outcome`).
/// Whether a sample was taken (accepted or not; the person hears which), `false` when a check
/// refused the capture.
fn capture(
    setup: &SessionSetup,
    options: &ManualOptions,
    plan: &mut GrowingPlan,
    robot: &mut dyn Robot,
    cameras: &mut [&mut dyn Camera],
    control: &mut dyn ManualControl,
) -> Result<bool, SessionError> {
    std::thread::sleep(setup.settle);
    // A person may still be moving the arm (or let go of it a moment ago): where it stands is
    // read once its joint speeds have stayed low, as after a planned move.
    if let Some(rule) = &setup.settle_by_speed {
        match wait_until_still(robot, rule, Instant::now(), &setup.stop) {
            Ok(_) => {}
            Err(NotStill::Moving { fastest }) => {
                control.event(ManualEvent::Check {
                    ok: false,
                    message: format!(
                        "the arm is still moving ({}): let go of it and hold it still, then capture again",
                        NotStill::moving_message(fastest, rule)
                    ),
                });
                return Ok(false);
            }
            Err(NotStill::Robot(e)) => {
                return Err(ArmFault::Robot(e).into_session(setup, plan.poses.len()))
            }
        }
    }
    let here = robot
        .joint_positions()
        .and_then(|j| Ok((robot.base_from_flange()?, j)));
    let (base_from_flange, joints) = match here {
        Ok(here) => here,
        Err(e) => return Err(ArmFault::Robot(e).into_session(setup, plan.poses.len())),
    };
    if let Some((i, (earlier_base_from_flange, _))) =
        plan.poses.iter().enumerate().find(|(_, (earlier, _))| {
            translation_distance(earlier, &base_from_flange) < options.min_translation_m
                && earlier.rotation.angle_to(&base_from_flange.rotation) < options.min_rotation_rad
        })
    {
        control.event(ManualEvent::Check {
            ok: false,
            message: format!(
                "too close to capture {i} ({:.1} mm, {:.2}° away; at least {:.0} mm or {:.1}° needed): move the arm to a new view",
                translation_distance(earlier_base_from_flange, &base_from_flange) * 1000.0,
                earlier_base_from_flange
                    .rotation
                    .angle_to(&base_from_flange.rotation)
                    .to_degrees(),
                options.min_translation_m * 1000.0,
                options.min_rotation_rad.to_degrees()
            ),
        });
        return Ok(false);
    }
    // Blur is the arm still moving or a camera out of focus: the capture waits for a sharp frame
    // from at least one camera (with several, one may look at a plain wall from here). A camera
    // that fails to grab while another delivers is left to the capture, which names it and goes
    // on with the others as a planned run does; when none delivers, the session stops.
    let mut sharpest: Option<f64> = None;
    let mut failed = None;
    for camera in cameras.iter_mut() {
        match camera.grab(Instant::now()) {
            Ok(frame) => {
                let sharp = sharpness(&frame.image);
                sharpest = Some(sharpest.map_or(sharp, |s| s.max(sharp)));
            }
            Err(e) => failed = failed.or(Some(e)),
        }
    }
    let Some(sharp) = sharpest else {
        let error = failed.unwrap_or_else(|| {
            handeye_camera::CameraError::Backend("the session has no camera".into())
        });
        return Err(ArmFault::Camera(error).into_session(setup, plan.poses.len()));
    };
    if sharp < options.min_sharpness {
        let blurred = match cameras.len() {
            1 => "the frame is blurred (sharpness",
            _ => "every camera's frame is blurred (the sharpest's sharpness",
        };
        control.event(ManualEvent::Check {
            ok: false,
            message: format!(
                "{blurred} {sharp:.1}, at least {:.1} needed): hold the arm still, check the focus, then capture again",
                options.min_sharpness
            ),
        });
        return Ok(false);
    }
    let index = plan.poses.len();
    // The arm stands there: the driver's "move" is a no-op, and there is nothing to check.
    let step = SessionSetup {
        move_check: None,
        ..setup.clone()
    };
    let mut last_rejection = None;
    let accepted = plan.visit(
        &step,
        (base_from_flange, joints),
        &mut StandStill(robot),
        cameras,
        &mut |event| {
            if let SessionEvent::Recorded { rejected, .. } = &event {
                last_rejection.clone_from(rejected);
            }
            control.event(ManualEvent::Session(event));
        },
    )?;
    if accepted {
        control.event(ManualEvent::Check {
            ok: true,
            message: format!("capture {index} accepted (sharpness {sharp:.2})"),
        });
    } else {
        control.event(ManualEvent::Check {
            ok: false,
            message: format!(
                "capture refused: {}",
                last_rejection.unwrap_or_else(|| "no sample".into())
            ),
        });
    }
    Ok(true)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_threshold_passes_slight_blur_and_refuses_strong_blur() {
        // The measure's own properties are tested with it (vision::sharpness); here only where
        // the capture check draws the line, at high and low contrast.
        for (dark, light) in [(30u8, 220u8), (100, 140)] {
            let sharp = handeye_vision::sharpness::checkerboard(dark, light);
            let slight = sharpness(&image::imageops::blur(&sharp, 0.7));
            let blurred = sharpness(&image::imageops::blur(&sharp, 5.0));
            assert!(
                slight > DEFAULT_MIN_SHARPNESS,
                "slightly blurred board scores {slight}"
            );
            assert!(
                blurred < DEFAULT_MIN_SHARPNESS,
                "blurred board scores {blurred}"
            );
        }
    }
}
