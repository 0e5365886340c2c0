//! `handeye console`: a hand-guided session of a cell driven from the console page (and the
//! terminal, through the same command queue). The cell's plan, when it has one, is not driven:
//! its checked poses are the views the next-best-pose planner suggests. The session is an
//! ordinary session folder: it resumes, replays and reports like any other.

use std::sync::Arc;
use std::time::Duration;

use handeye_core::geometry::Pose;
use handeye_core::setup::predict;
use handeye_records::SessionFolder;
use handeye_robot::Joints;
use handeye_session::cell::run::{
    run_opened, CellRun, HandGuide, OpenedRun, RunError, RunObserver, RunRequest, Strategy,
};
use handeye_session::cell::PreparedCell;
use handeye_session::{ManualCommand, ManualControl, ManualEvent};

use super::analysis::{Analyst, CellView, Job};
use super::events::{joints_deg, Command, ConsoleEvent, PoseView};
use super::observer::{
    cell_events, plan_event, publish_recorded, show_recorded, wait_for_confirmation,
};
use super::Console;

/// Runs a hand-guided session of a cell on `console` until the page (or terminal) finishes it,
/// then solves it: the run `opened` ([`run_opened`]) with the console as the person's side. `observer`
/// hears what the terminal prints (notes, per-capture lines).
pub fn run_manual(
    opened: OpenedRun,
    request: &RunRequest,
    console: &Console,
    observer: &mut dyn RunObserver,
) -> Result<CellRun, RunError> {
    let mut guide = ConsoleGuide {
        console,
        view: None,
    };
    run_opened(opened, request, Strategy::HandGuided(&mut guide), observer)
}

/// The console as the person's side of a hand-guided run: it shows the cell, the suggestions
/// and every capture, and passes the page's commands on.
struct ConsoleGuide<'c> {
    console: &'c Console,
    /// The cell as the page draws it, once prepared.
    view: Option<CellView>,
}

impl HandGuide for ConsoleGuide<'_> {
    fn prepared(&mut self, cell: &PreparedCell) {
        let (event, view) = cell_events(cell, true);
        self.console.publish(&event);
        self.view = Some(view);
    }

    fn control<'g>(
        &'g mut self,
        cell: &'g PreparedCell,
        folder: &SessionFolder,
        suggestions: &[(Pose, Joints)],
        observer: &'g mut dyn RunObserver,
    ) -> Box<dyn ManualControl + 'g> {
        let console = self.console;
        console.publish(&ConsoleEvent::Session {
            folder: folder.root().display().to_string(),
        });
        console.publish(&plan_event(suggestions));
        console.publish(&ConsoleEvent::Started { poses: 0 });
        let view = match &self.view {
            Some(view) => view.clone(),
            // `prepared` comes first; should it not, the page is drawn from here.
            None => cell_events(cell, true).1,
        };
        let control = ConsoleControl {
            console,
            observer,
            analyst: Analyst::start(
                view.clone(),
                folder.root().to_path_buf(),
                console.publisher(),
            ),
            view,
            cell,
            freedrive: false,
        };
        // A resume's earlier captures show as captured and count in the coverage.
        show_recorded(console, folder, Some(&control.analyst));
        Box::new(control)
    }

    fn ended(&mut self) {
        self.console.publish(&ConsoleEvent::Ended);
    }
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
