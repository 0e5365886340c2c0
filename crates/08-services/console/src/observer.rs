//! The console's [`RunObserver`]: it passes every call on to the observer it wraps (the
//! terminal's, unchanged) and publishes the same progress as typed events; recorded poses go to
//! the analysis thread for frames, coverage and the running estimate. Nothing here blocks the
//! run except the motion confirmation, which waits for the person by design.

use std::sync::atomic::Ordering;
use std::time::Duration;

use handeye_core::geometry::Pose;
use handeye_records::SessionFolder;
use handeye_robot::Joints;
use handeye_session::cell::run::RunObserver;
use handeye_session::cell::PreparedCell;
use handeye_session::SessionEvent;

use super::analysis::{Analyst, CellView, Job};
use super::events::{joints_deg, Command, ConsoleEvent, PlannedView, PoseState, PoseView};
use super::Console;

/// Publishes a run's progress on a console, and passes it on to `inner`.
pub struct ConsoleObserver<'a> {
    inner: &'a mut dyn RunObserver,
    console: &'a Console,
    cell: Option<CellView>,
    analyst: Option<Analyst>,
    plan: Vec<Joints>,
    /// A several-camera cell: the planner camera, whose records drive the plan table and the
    /// running estimate.
    planner_camera: Option<String>,
}

impl<'a> ConsoleObserver<'a> {
    /// Wraps `inner` (which still prints to the terminal).
    pub fn new(inner: &'a mut dyn RunObserver, console: &'a Console) -> Self {
        ConsoleObserver {
            inner,
            console,
            cell: None,
            analyst: None,
            plan: Vec::new(),
            planner_camera: None,
        }
    }

    /// Waits for the analysis of every recorded pose to be published.
    pub fn flush(&mut self) {
        self.analyst.take();
    }
}

/// What the console shows of a cell, published when the cell is ready.
pub(crate) fn cell_events(cell: &PreparedCell, manual: bool) -> (ConsoleEvent, CellView) {
    let (a, b) = cell.config.camera().setup.unknown_names();
    let event = ConsoleEvent::Cell {
        config: cell.config.file.display().to_string(),
        setup: cell.config.camera().setup.name().to_string(),
        unknowns: [a.to_string(), b.to_string()],
        simulated: cell.is_simulated(),
        manual,
        image: [
            cell.camera().camera_model.width,
            cell.camera().camera_model.height,
        ],
        cameras: match cell.config.listed {
            true => cell.config.cameras.iter().map(|c| c.name.clone()).collect(),
            false => Vec::new(),
        },
    };
    let view = CellView {
        setup: cell.config.camera().setup,
        board: cell.camera().board.clone(),
        model: cell.camera().camera_model,
        // The running estimate skips the outlier loop (a person watches it converge; the solve
        // at the end is the real one, with every check).
        options: handeye_solve::SolveOptions {
            drop_outliers: false,
            ..cell.config.solver.to_options()
        },
        nominal: (
            cell.config.camera().nominal.camera_mount,
            cell.config.camera().nominal.target_mount,
        ),
    };
    (event, view)
}

/// The plan table's rows.
pub(crate) fn plan_event(plan: &[(Pose, Joints)]) -> ConsoleEvent {
    ConsoleEvent::Plan {
        poses: plan
            .iter()
            .enumerate()
            .map(|(index, (pose, joints))| PlannedView {
                index,
                flange: PoseView::of(pose),
                joints_deg: joints_deg(joints),
            })
            .collect(),
    }
}

/// Waits for a page (or the terminal, through the same queue) to confirm motion; STOP or the
/// stop flag refuse.
pub(crate) fn wait_for_confirmation(
    console: &Console,
    poses: usize,
    linear_speed: f64,
    joint_speed_deg: f64,
) -> Result<(), Box<dyn std::error::Error + Send + Sync>> {
    console.publish(&ConsoleEvent::ConfirmMotion {
        poses,
        linear_speed,
        joint_speed_deg,
    });
    let stop = console.stop_flag();
    loop {
        if stop.load(Ordering::SeqCst) {
            return Err("stopped before the first move; nothing was moved".into());
        }
        match console.next_command(Duration::from_millis(200)) {
            Some(Command::Confirm) => {
                console.publish(&ConsoleEvent::Confirmed);
                return Ok(());
            }
            Some(Command::Decline) | Some(Command::Stop) => {
                return Err("motion not confirmed on the console; nothing was moved".into())
            }
            _ => {}
        }
    }
}

impl ConsoleObserver<'_> {
    /// Shows the page the cell of a run opened before this observer was made (its plan check
    /// was told to the terminal only).
    pub fn show_cell(&mut self, cell: &PreparedCell) {
        let (event, view) = cell_events(cell, false);
        self.console.publish(&event);
        self.cell = Some(view);
        self.planner_camera = cell
            .config
            .listed
            .then(|| cell.config.camera().name.clone());
    }
}

impl RunObserver for ConsoleObserver<'_> {
    fn plan_checked(&mut self, cell: &PreparedCell) {
        self.inner.plan_checked(cell);
        self.show_cell(cell);
    }

    fn confirm_motion(
        &mut self,
        cell: &PreparedCell,
        poses: usize,
    ) -> Result<(), Box<dyn std::error::Error + Send + Sync>> {
        self.inner.note(&format!(
            "confirm the motion of the real arm on the console page {} (or stop with Ctrl-C)",
            self.console.url()
        ));
        wait_for_confirmation(
            self.console,
            poses,
            cell.config.limits.linear_speed,
            cell.config.limits.joint_speed.to_degrees(),
        )
    }

    fn note(&mut self, message: &str) {
        self.inner.note(message);
        self.console.publish(&ConsoleEvent::Note {
            message: message.to_string(),
        });
    }

    fn session_folder(&mut self, folder: &SessionFolder, plan: &[(Pose, Joints)]) {
        self.inner.session_folder(folder, plan);
        self.plan = plan.iter().map(|(_, j)| *j).collect();
        self.console.publish(&ConsoleEvent::Session {
            folder: folder.root().display().to_string(),
        });
        self.console.publish(&plan_event(plan));
        if let Some(cell) = self.cell.clone() {
            self.analyst = Some(Analyst::start(
                cell,
                folder.root().to_path_buf(),
                self.console.publisher(),
            ));
        }
        show_recorded(self.console, folder, self.analyst.as_ref());
    }

    fn session_started(&mut self, poses: usize) {
        self.inner.session_started(poses);
        self.console.publish(&ConsoleEvent::Started { poses });
    }

    fn event(&mut self, event: SessionEvent) {
        match &event {
            SessionEvent::Moving { plan_index, .. } => {
                self.console.publish(&ConsoleEvent::Moving {
                    plan_index: *plan_index,
                    joints_deg: self.plan.get(*plan_index).map(joints_deg),
                });
            }
            SessionEvent::Recorded {
                camera: Some(camera),
                plan_index,
                reprojection_rms_px,
                tags,
                rejected,
                will_retry,
                ..
            } => {
                // Several cameras: every camera's record in its table; the planner camera's
                // also drives the plan table and the running estimate (its board and lens).
                self.console.publish(&ConsoleEvent::CameraPose {
                    camera: camera.clone(),
                    plan_index: *plan_index,
                    state: PoseState::visited(rejected.is_some(), *will_retry),
                    why: rejected.clone(),
                    rms_px: *reprojection_rms_px,
                    tags: *tags,
                });
                if Some(camera) == self.planner_camera.as_ref() {
                    publish_recorded(self.console, self.analyst.as_ref(), &event);
                }
            }
            SessionEvent::Recorded { .. } => {
                publish_recorded(self.console, self.analyst.as_ref(), &event)
            }
            SessionEvent::CameraLost(failure) => self.console.publish(&ConsoleEvent::CameraLost {
                camera: failure.camera.clone(),
                plan_index: failure.plan_index,
                error: failure.error.clone(),
            }),
        }
        self.inner.event(event);
    }

    fn session_ended(&mut self) {
        self.inner.session_ended();
        self.console.publish(&ConsoleEvent::Ended);
    }
}

/// A recorded pose (`SessionEvent::Recorded`) as the page shows it: its state in the plan
/// table, and its frame handed to the analysis thread. Other events are ignored.
pub(super) fn publish_recorded(console: &Console, analyst: Option<&Analyst>, event: &SessionEvent) {
    let SessionEvent::Recorded {
        plan_index,
        reprojection_rms_px,
        tags,
        rejected,
        will_retry,
        frame,
        ..
    } = event
    else {
        return;
    };
    console.publish(&ConsoleEvent::Pose {
        plan_index: *plan_index,
        state: PoseState::visited(rejected.is_some(), *will_retry),
        why: rejected.clone(),
        rms_px: *reprojection_rms_px,
        tags: *tags,
    });
    if let Some(analyst) = analyst {
        analyst.recorded(*plan_index, frame);
    }
}

/// A resumed session: the poses recorded before show as they ended, and count in the coverage
/// and the running estimate.
pub(super) fn show_recorded(console: &Console, folder: &SessionFolder, analyst: Option<&Analyst>) {
    for visit in folder.read_visits().unwrap_or_default() {
        console.publish(&ConsoleEvent::Pose {
            plan_index: visit.plan_index,
            // A recorded visit is final: its retry, if any, is a visit of its own.
            state: PoseState::visited(visit.rejected.is_some(), false),
            why: visit.rejected.clone(),
            rms_px: visit.reprojection_rms_px,
            tags: visit.tags,
        });
        if let Some(analyst) = analyst {
            analyst.send(Job::Recorded(visit.plan_index));
        }
    }
}
