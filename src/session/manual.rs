//! Hand-guided capture (`handeye console`): no plan drives the arm; a person jogs or
//! hand-guides it (freedrive) to views of their choosing and asks for a sample where it stands.
//! Each capture is checked at once — too close to an earlier view, a blurred frame, the board
//! seen (the ordinary driver's detection) — and the next-best-pose planner suggests the view that
//! helps most, which the arm can also be sent to.
//!
//! A sample is taken with the ordinary driver ([`run_session`]) on a one-pose plan that is where
//! the arm already stands (the "move" is a no-op), so records, the folder layout, resume,
//! replay and report are those of any session; like an adaptive session, the manifest's plan
//! grows with each accepted capture, and a rejected capture's index is reused by the next.

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use image::GrayImage;

use crate::camera::Camera;
use crate::dataset::Dataset;
use crate::geometry::{translation_distance, Pose};
use crate::plan::nbv::AdaptivePlanner;
use crate::robot::{Joints, MotionLimits, Robot, RobotError, RobotStatus};

use super::adaptive::recorded_plan;
use super::{
    run_session, SessionError, SessionEvent, SessionManifest, SessionOutcome, SessionSetup,
};

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

/// A frame's sharpness: the mean square of the 4-neighbour Laplacian over the mean square of the
/// gradient, at half resolution (halving averages sensor noise away). The ratio does not depend
/// on the contrast or on how much of the image the board fills, only on how steep its edges
/// are; a frame without edges scores 0.
pub fn sharpness(image: &GrayImage) -> f64 {
    let (w, h) = (image.width() / 2, image.height() / 2);
    if w < 3 || h < 3 {
        return 0.0;
    }
    let half = |x: u32, y: u32| -> f64 {
        let (x, y) = (2 * x, 2 * y);
        (image.get_pixel(x, y)[0] as f64
            + image.get_pixel(x + 1, y)[0] as f64
            + image.get_pixel(x, y + 1)[0] as f64
            + image.get_pixel(x + 1, y + 1)[0] as f64)
            / 4.0
    };
    let small: Vec<f64> = (0..h)
        .flat_map(|y| (0..w).map(move |x| (x, y)))
        .map(|(x, y)| half(x, y))
        .collect();
    let at = |x: u32, y: u32| small[(y * w + x) as usize];
    let mut laplacian = 0.0;
    let mut gradient = 0.0;
    for y in 1..h - 1 {
        for x in 1..w - 1 {
            let c = at(x, y);
            let l = at(x - 1, y) + at(x + 1, y) + at(x, y - 1) + at(x, y + 1) - 4.0 * c;
            let (dx, dy) = (at(x + 1, y) - c, at(x, y + 1) - c);
            laplacian += l * l;
            gradient += dx * dx + dy * dy;
        }
    }
    if gradient <= f64::EPSILON {
        return 0.0;
    }
    laplacian / gradient
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
}

/// Runs (or resumes) a hand-guided session until the person finishes it or the stop flag is
/// set (then the arm is stopped, freedrive switched off and the error says how to resume).
/// `setup.plan` is ignored: the captures are the plan. `suggester`'s candidates are the views it
/// suggests.
pub fn run_manual_session(
    setup: SessionSetup,
    manifest_config: PathBuf,
    mut suggester: Option<&mut AdaptivePlanner>,
    options: &ManualOptions,
    robot: &mut dyn Robot,
    camera: &mut dyn Camera,
    control: &mut dyn ManualControl,
) -> Result<SessionOutcome, SessionError> {
    let mut plan = recorded_plan(&setup)?;
    let inputs = if setup.folder.manifest_path().is_file() {
        setup.folder.read_manifest()?.inputs
    } else {
        Vec::new()
    };
    if let Some(planner) = suggester.as_deref_mut() {
        let seen: Vec<Pose> = plan.iter().map(|(pose, _)| *pose).collect();
        planner.mark_visited(&seen);
    }
    // The recorded plan's poses were all accepted except perhaps the last (refused, or a stop
    // mid-capture): it is dropped and its index reused, as during the session.
    let accepted: Vec<usize> = setup
        .folder
        .read_visits()?
        .iter()
        .filter(|v| {
            v.camera_from_target.is_some()
                || (setup.estimate_intrinsics && v.rejected.is_none() && !v.corners_px.is_empty())
        })
        .map(|v| v.plan_index)
        .collect();
    while plan
        .len()
        .checked_sub(1)
        .is_some_and(|last| !accepted.contains(&last))
    {
        plan.pop();
    }
    let mut outcome = SessionOutcome::default();
    robot.set_interrupt(setup.stop.clone());
    let mut freedrive = false;
    let mut confirmed = !options.real_arm;
    let mut suggestion = suggest(&setup, suggester.as_deref_mut(), control)?;
    let mut last_live: Option<Instant> = None;
    let result = loop {
        if setup.stop.load(Ordering::SeqCst) {
            let _ = robot.stop();
            break Err(SessionError::Interrupted {
                plan_index: plan.len(),
                recorded: plan.len(),
                folder: setup.folder.root().to_path_buf(),
            });
        }
        if last_live.is_none_or(|t| t.elapsed() >= options.live_every) {
            last_live = Some(Instant::now());
            if let Err(e) = live_view(robot, camera, freedrive, control) {
                break Err(e.into_session(&setup, plan.len()));
            }
        }
        let Some(command) = control.next_command(Duration::from_millis(100)) else {
            continue;
        };
        match command {
            ManualCommand::Finish => break Ok(()),
            ManualCommand::Freedrive(on) => match robot.set_freedrive(on) {
                Ok(()) => {
                    freedrive = on;
                    last_live = None;
                    control.event(ManualEvent::Check {
                        ok: true,
                        message: format!("freedrive {}", if on { "on" } else { "off" }),
                    });
                }
                Err(e) => control.event(ManualEvent::Check {
                    ok: false,
                    message: format!("freedrive {}: {e}", if on { "on" } else { "off" }),
                }),
            },
            ManualCommand::GoToSuggestion => {
                let Some((_, joints)) = suggestion else {
                    control.event(ManualEvent::Check {
                        ok: false,
                        message: "no suggestion to go to (no candidate views left)".into(),
                    });
                    continue;
                };
                if !confirmed {
                    confirmed = control.confirm_move();
                    if !confirmed {
                        control.event(ManualEvent::Check {
                            ok: false,
                            message: "the move was not confirmed; nothing moved".into(),
                        });
                        continue;
                    }
                }
                if freedrive {
                    if let Err(e) = robot.set_freedrive(false) {
                        break Err(ArmFault::Robot(e).into_session(&setup, plan.len()));
                    }
                    freedrive = false;
                }
                if let Some(check) = &setup.move_check {
                    let from = match robot.joint_positions() {
                        Ok(j) => j,
                        Err(e) => break Err(ArmFault::Robot(e).into_session(&setup, plan.len())),
                    };
                    if let Some(problem) = check.problem(&from, &joints) {
                        control.event(ManualEvent::Check {
                            ok: false,
                            message: format!("the move to the suggestion was not sent: {problem}"),
                        });
                        continue;
                    }
                }
                match robot.move_joints(&joints, &setup.limits) {
                    Ok(()) => {
                        last_live = None;
                        control.event(ManualEvent::Check {
                            ok: true,
                            message: "at the suggested view".into(),
                        });
                    }
                    Err(e) => break Err(ArmFault::Robot(e).into_session(&setup, plan.len())),
                }
            }
            ManualCommand::Capture => {
                let was_freedrive = freedrive;
                if freedrive {
                    // The arm must hold still for the sample.
                    if let Err(e) = robot.set_freedrive(false) {
                        break Err(ArmFault::Robot(e).into_session(&setup, plan.len()));
                    }
                    freedrive = false;
                }
                match capture(
                    &setup,
                    &manifest_config,
                    &inputs,
                    options,
                    &mut plan,
                    robot,
                    camera,
                    control,
                ) {
                    Ok(Some(step)) => {
                        outcome.visited_now += step.visited_now;
                        outcome.skipped.extend(step.skipped);
                        outcome.accepted = step.accepted;
                        suggestion = suggest(&setup, suggester.as_deref_mut(), control)?;
                    }
                    Ok(None) => {}
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
    result?;
    outcome.accepted = (0..plan.len()).collect();
    Ok(outcome)
}

/// A fault of the arm or camera outside a capture.
enum ArmFault {
    Robot(RobotError),
    Camera(crate::camera::CameraError),
}

impl ArmFault {
    fn into_session(self, setup: &SessionSetup, recorded: usize) -> SessionError {
        let folder = setup.folder.root().to_path_buf();
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

/// The planner's next view from the samples on disk, told to `control`.
fn suggest(
    setup: &SessionSetup,
    suggester: Option<&mut AdaptivePlanner>,
    control: &mut dyn ManualControl,
) -> Result<Option<(Pose, Joints)>, SessionError> {
    let Some(planner) = suggester else {
        return Ok(None);
    };
    let samples = if setup.folder.samples_path().is_file() {
        Dataset::load(&setup.folder.samples_path())?.pairs
    } else {
        Vec::new()
    };
    let next = planner.next(&samples);
    let step = planner.log.last();
    if let Some((pose, joints)) = next {
        control.event(ManualEvent::Suggestion {
            pose,
            joints,
            predicted_sigma_mm: step.and_then(|s| s.predicted_sigma_mm),
            solved_sigma_mm: step.and_then(|s| s.solved_sigma_mm),
        });
    }
    Ok(next)
}

/// One capture: the immediate checks, then a sample with the driver. `Some(outcome)` when a
/// sample was taken (accepted or not), `None` when a check refused it.
#[allow(clippy::too_many_arguments)]
fn capture(
    setup: &SessionSetup,
    manifest_config: &std::path::Path,
    inputs: &[super::InputFile],
    options: &ManualOptions,
    plan: &mut Vec<(Pose, Joints)>,
    robot: &mut dyn Robot,
    camera: &mut dyn Camera,
    control: &mut dyn ManualControl,
) -> Result<Option<SessionOutcome>, SessionError> {
    std::thread::sleep(setup.settle);
    let here = robot
        .joint_positions()
        .and_then(|j| Ok((robot.base_from_flange()?, j)));
    let (base_from_flange, joints) = match here {
        Ok(here) => here,
        Err(e) => return Err(ArmFault::Robot(e).into_session(setup, plan.len())),
    };
    if let Some((i, (pose, _))) = plan.iter().enumerate().find(|(_, (pose, _))| {
        translation_distance(pose, &base_from_flange) < options.min_translation_m
            && pose.rotation.angle_to(&base_from_flange.rotation) < options.min_rotation_rad
    }) {
        control.event(ManualEvent::Check {
            ok: false,
            message: format!(
                "too close to capture {i} ({:.1} mm, {:.2}° away; at least {:.0} mm or {:.1}° needed): move the arm to a new view",
                translation_distance(pose, &base_from_flange) * 1000.0,
                pose.rotation.angle_to(&base_from_flange.rotation).to_degrees(),
                options.min_translation_m * 1000.0,
                options.min_rotation_rad.to_degrees()
            ),
        });
        return Ok(None);
    }
    let frame = match camera.grab(Instant::now()) {
        Ok(frame) => frame,
        Err(e) => return Err(ArmFault::Camera(e).into_session(setup, plan.len())),
    };
    let sharp = sharpness(&frame.image);
    if sharp < options.min_sharpness {
        control.event(ManualEvent::Check {
            ok: false,
            message: format!(
                "the frame is blurred (sharpness {sharp:.1}, at least {:.1} needed): hold the arm still, check the focus, then capture again",
                options.min_sharpness
            ),
        });
        return Ok(None);
    }
    plan.push((base_from_flange, joints));
    setup.folder.write_manifest(
        &SessionManifest::new(manifest_config.to_path_buf(), setup.setup, plan)
            .with_inputs(inputs.to_vec()),
    )?;
    let index = plan.len() - 1;
    let step = SessionSetup {
        plan: plan.clone(),
        move_check: None,
        ..setup.clone()
    };
    let mut last_rejection = None;
    let outcome = run_session(step, &mut StandStill(robot), camera, &mut |event| {
        if let SessionEvent::Recorded { rejected, .. } = &event {
            last_rejection.clone_from(rejected);
        }
        control.event(ManualEvent::Session(event));
    })?;
    if outcome.accepted.contains(&index) {
        control.event(ManualEvent::Check {
            ok: true,
            message: format!("capture {index} accepted (sharpness {sharp:.2})"),
        });
    } else {
        plan.pop();
        control.event(ManualEvent::Check {
            ok: false,
            message: format!(
                "capture refused: {}",
                last_rejection.unwrap_or_else(|| "no sample".into())
            ),
        });
    }
    Ok(Some(outcome))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_blurred_frame_is_less_sharp_than_a_sharp_one() {
        // A checkerboard of 8 px squares, then the same smoothed with a box filter.
        // A checkerboard of 16 px squares, sharp, slightly and badly blurred, at two contrasts.
        for (dark, light) in [(30u8, 220u8), (100, 140)] {
            let sharp = GrayImage::from_fn(256, 256, |x, y| {
                image::Luma([if (x / 16 + y / 16) % 2 == 0 {
                    dark
                } else {
                    light
                }])
            });
            let slight = image::imageops::blur(&sharp, 0.7);
            let blurred = image::imageops::blur(&sharp, 5.0);
            let (s, t, b) = (sharpness(&sharp), sharpness(&slight), sharpness(&blurred));
            assert!(s > t && t > b, "{s} {t} {b}");
            assert!(
                t > DEFAULT_MIN_SHARPNESS,
                "slightly blurred board scores {t}"
            );
            assert!(b < DEFAULT_MIN_SHARPNESS, "blurred board scores {b}");
        }
        assert_eq!(sharpness(&GrayImage::new(64, 64)), 0.0);
    }
}
