//! `handeye console`: a hand-guided session of a cell driven from the console page (and the
//! terminal, through the same command queue). The cell's plan, when it has one, is not driven:
//! its checked poses are the views the next-best-pose planner suggests. The session is an
//! ordinary session folder: it resumes, replays and reports like any other.

use std::sync::Arc;
use std::time::Duration;

use crate::cell::run::{
    ensure_robot_ready, open_run, CellRun, OpenedRun, ResumedSession, RunError, RunObserver,
    RunRequest, SessionTarget,
};
use crate::cell::PreparedCell;
use crate::geometry::Pose;
use crate::plan::nbv::AdaptivePlanner;
use crate::session::{
    self, run_manual_session, ManualCommand, ManualControl, ManualEvent, ManualOptions,
    SessionFolder,
};
use crate::setup::predict;

use super::analysis::{Analyst, CellView, Job};
use super::events::{joints_deg, Command, ConsoleEvent, PoseView};
use super::observer::{
    cell_events, plan_event, publish_recorded, show_recorded, wait_for_confirmation,
};
use super::Console;

/// Runs a hand-guided session of a cell on `console` until the page (or terminal) finishes it,
/// then solves it, as [`run`](crate::cell::run::run) does a planned one. `observer` hears what
/// the terminal prints (notes, per-capture lines).
pub fn run_manual(
    request: &RunRequest,
    console: &Console,
    observer: &mut dyn RunObserver,
) -> Result<CellRun, RunError> {
    // A resume's input check is the very one a planned resume makes, before the arm or camera
    // is opened.
    let OpenedRun {
        resumed,
        mut cell,
        inputs,
    } = open_run(request, observer)?;
    let resumed = match resumed {
        Some(ResumedSession {
            folder,
            mut manifest,
            inputs_changed,
        }) => {
            // A session a planned resume handed over (an older one without the mark) is marked
            // hand-guided.
            if inputs_changed || !manifest.manual {
                manifest.manual = true;
                folder.write_manifest(&manifest)?;
            }
            Some(folder)
        }
        None => None,
    };
    let (event, view) = cell_events(&cell, true);
    console.publish(&event);
    let mut hardware = cell.open_hardware().map_err(RunError::Hardware)?;
    ensure_robot_ready(hardware.robot.as_mut())?;
    let start = hardware.robot.joint_positions().map_err(RunError::Joints)?;
    // Suggestions come from the plan's poses that pass their checks from where the arm stands.
    let _ = cell.recheck_from(start);
    let candidates = cell.report.passing();
    let folder = match resumed {
        Some(folder) => folder,
        None => {
            let SessionTarget::New(out) = &request.target else {
                unreachable!("a resume has its folder")
            };
            let folder = SessionFolder::create(out)?;
            for note in folder.notes() {
                observer.note(note);
            }
            folder.write_manifest(&cell.manifest(&[]).with_inputs(inputs).hand_guided())?;
            folder
        }
    };
    console.publish(&ConsoleEvent::Session {
        folder: folder.root().display().to_string(),
    });
    console.publish(&plan_event(&candidates));
    let mut planner = (!candidates.is_empty() && cell.intrinsics_known).then(|| {
        AdaptivePlanner::new(
            cell.config.setup,
            cell.config.nominal.camera_mount,
            cell.config.nominal.target_mount,
            candidates.clone(),
            cell.config.solver.to_options(),
            // Suggestions never stop on their own: the person decides when to finish.
            0.0,
            usize::MAX,
        )
    });
    let setup = cell.session_setup(folder.clone(), Vec::new(), request.stop.clone());
    let options = ManualOptions {
        real_arm: !cell.is_simulated() && !request.motion_confirmed,
        ..ManualOptions::default()
    };
    observer.session_folder(&folder, &[]);
    observer.session_started(candidates.len());
    console.publish(&ConsoleEvent::Started { poses: 0 });
    let outcome = {
        let mut control = ConsoleControl {
            console,
            observer: &mut *observer,
            analyst: Analyst::start(
                view.clone(),
                folder.root().to_path_buf(),
                console.publisher(),
            ),
            view,
            cell: &cell,
            freedrive: false,
        };
        show_recorded(console, &folder, Some(&control.analyst));
        run_manual_session(
            setup,
            cell.config_path(),
            planner.as_mut(),
            &options,
            hardware.robot.as_mut(),
            hardware.camera.as_mut(),
            &mut control,
        )
    };
    observer.session_ended();
    console.publish(&ConsoleEvent::Ended);
    let outcome = outcome?;
    let solved = session::solve_folder(&folder, &cell.solve_inputs())?;
    Ok(CellRun {
        cell,
        folder,
        outcome,
        solved,
        adaptive: None,
        arm_time: None,
    })
}

/// The console page (and terminal) as the person's side of a manual session.
struct ConsoleControl<'a> {
    console: &'a Console,
    observer: &'a mut dyn RunObserver,
    analyst: Analyst,
    view: CellView,
    cell: &'a PreparedCell,
    freedrive: bool,
}

impl ManualControl for ConsoleControl<'_> {
    fn next_command(&mut self, timeout: Duration) -> Option<ManualCommand> {
        loop {
            return match self.console.next_command(timeout)? {
                Command::Capture => Some(ManualCommand::Capture),
                Command::Freedrive { on } => Some(ManualCommand::Freedrive(on)),
                Command::GoToSuggestion => Some(ManualCommand::GoToSuggestion),
                Command::Finish => Some(ManualCommand::Finish),
                // STOP has set the stop flag already; the session sees it.
                Command::Stop => None,
                // Confirmations outside a question mean nothing.
                Command::Confirm | Command::Decline => continue,
            };
        }
    }

    fn confirm_move(&mut self) -> bool {
        self.observer.note(&format!(
            "confirm the move of the real arm on the console page {}",
            self.console.url()
        ));
        wait_for_confirmation(
            self.console,
            1,
            self.cell.config.limits.linear_speed,
            self.cell.config.limits.joint_speed.to_degrees(),
        )
        .is_ok()
    }

    fn event(&mut self, event: ManualEvent<'_>) {
        match event {
            ManualEvent::Arm {
                joints,
                base_from_flange,
                freedrive,
            } => {
                self.freedrive = freedrive;
                self.console.publish(&ConsoleEvent::Arm {
                    joints_deg: joints_deg(&joints),
                    flange: PoseView::of(&base_from_flange),
                    freedrive,
                });
            }
            ManualEvent::Preview {
                image,
                base_from_flange,
            } => self
                .analyst
                .send(Job::Preview(Arc::new(image.clone()), base_from_flange)),
            ManualEvent::Suggestion {
                pose,
                joints,
                axis,
                predicted_sigma_mm,
                solved_sigma_mm,
            } => {
                if let Some(sigma) = solved_sigma_mm {
                    self.observer
                        .note(&format!("solved 1-sigma so far: {sigma:.3} mm"));
                }
                self.console.publish(&ConsoleEvent::Suggestion {
                    flange: PoseView::of(&pose),
                    joints_deg: joints_deg(&joints),
                    board_px: board_centre_px(&self.view, &pose),
                    axis,
                    predicted_sigma_mm,
                });
            }
            ManualEvent::Check { ok, message } => {
                self.observer.note(&message);
                self.console.publish(&ConsoleEvent::Check { ok, message });
            }
            ManualEvent::Session(event) => {
                publish_recorded(self.console, Some(&self.analyst), &event);
                self.observer.event(event);
            }
        }
    }
}

/// Where the board's centre appears in the image with the flange at `base_from_flange`, by the
/// nominal cell.
fn board_centre_px(view: &CellView, base_from_flange: &Pose) -> Option<[f64; 2]> {
    let extent = view.board.extent();
    let mid = nalgebra::center(&extent.min, &extent.max);
    let centre = nalgebra::Point3::new(mid.x, mid.y, 0.0);
    let camera_from_target = predict(
        view.setup,
        &view.nominal.0,
        &view.nominal.1,
        base_from_flange,
    );
    view.model
        .project(&(camera_from_target * centre))
        .map(|p| [p.x, p.y])
}
