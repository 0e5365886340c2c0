//! `handeye.run`: a cell run from Python through the library code `handeye run` calls
//! ([`cell::run::open_run`] and [`cell::run::run_opened`], the planned strategy), with the GIL
//! released while the cell runs. Progress goes to a Python callable as one dict per event; on
//! each event the GIL is taken back for the callable and for Python's signal handlers
//! (`Python::check_signals`): Ctrl-C, or an exception the callable raises, sets the run's stop
//! flag, which stops the arm and ends the session with every sample kept, as the CLI's Ctrl-C
//! does; the exception is raised once the run has stopped.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use handeye_core::error_text::error_chain;
use handeye_records::{dated_session_path, SessionError};
use handeye_session::cell::run::{
    open_run, run_opened, RunError, RunObserver, RunRequest, SessionTarget, Strategy,
};
use handeye_session::cell::PreparedCell;
use handeye_session::SessionEvent;
use pyo3::exceptions::PyKeyboardInterrupt;
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::convert::pose_to_py;
use crate::errors;
use crate::session::Session;

/// Tells Python what the run does, and stops it on Ctrl-C or an exception of the callable.
struct PyObserver {
    progress: Option<Py<PyAny>>,
    stop: Arc<AtomicBool>,
    /// The first exception (KeyboardInterrupt, or the callable's own), raised after the run.
    error: Option<PyErr>,
}

impl PyObserver {
    /// With the GIL: the event `make` builds to the callable, then Python's signal handlers.
    fn send(&mut self, make: impl for<'py> FnOnce(&Bound<'py, PyDict>) -> PyResult<()>) {
        if self.error.is_some() {
            return;
        }
        let outcome = Python::attach(|py| -> PyResult<()> {
            if let Some(progress) = &self.progress {
                let event = PyDict::new(py);
                make(&event)?;
                progress.call1(py, (event,))?;
            }
            py.check_signals()
        });
        if let Err(error) = outcome {
            self.error = Some(error);
            self.stop.store(true, Ordering::SeqCst);
        }
    }
}

impl RunObserver for PyObserver {
    fn plan_checked(&mut self, cell: &PreparedCell) {
        let report = cell.report.to_string();
        self.send(|e| {
            e.set_item("event", "plan_checked")?;
            e.set_item("report", report)
        });
    }

    fn confirm_motion(
        &mut self,
        _cell: &PreparedCell,
        poses: usize,
    ) -> Result<(), Box<dyn std::error::Error + Send + Sync>> {
        Err(format!(
            "a real robot is about to move through {poses} poses and no one confirmed it: pass yes=True to handeye.run (as `handeye run --yes`) once the cell is clear; nothing was moved"
        )
        .into())
    }

    fn note(&mut self, message: &str) {
        self.send(|e| {
            e.set_item("event", "note")?;
            e.set_item("message", message)
        });
    }

    fn session_started(&mut self, poses: usize) {
        self.send(|e| {
            e.set_item("event", "started")?;
            e.set_item("poses", poses)
        });
    }

    fn event(&mut self, event: SessionEvent) {
        self.send(|e| match event {
            SessionEvent::Moving { plan_index, target } => {
                e.set_item("event", "moving")?;
                e.set_item("plan_index", plan_index)?;
                e.set_item("T_base_flange", pose_to_py(e.py(), &target))
            }
            SessionEvent::Recorded {
                plan_index,
                camera,
                reprojection_rms_px,
                tags,
                rejected,
                will_retry,
                ..
            } => {
                e.set_item("event", "recorded")?;
                e.set_item("plan_index", plan_index)?;
                e.set_item("camera", camera)?;
                e.set_item("reprojection_rms_px", reprojection_rms_px)?;
                e.set_item("tags", tags)?;
                e.set_item("rejected", rejected)?;
                e.set_item("will_retry", will_retry)
            }
            SessionEvent::CameraLost(failure) => {
                e.set_item("event", "camera_lost")?;
                e.set_item("camera", failure.camera)?;
                e.set_item("plan_index", failure.plan_index)?;
                e.set_item("error", failure.error)
            }
        });
    }

    fn session_ended(&mut self) {
        self.send(|e| e.set_item("event", "ended"));
    }
}

/// Why a run from Python did not finish.
enum Failed {
    Run(RunError),
    /// A hand-guided session (`plan.manual`, or a resume of one): the console's, not Python's.
    HandGuided(&'static str),
}

/// Runs a cell (see `handeye.run` in `handeye/__init__.py`) and returns its session.
#[pyfunction]
#[pyo3(signature = (
    config = None, out = None, *, resume = None, progress = None, yes = false,
    accept_changed = false,
))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn run(
    py: Python<'_>,
    config: Option<PathBuf>,
    out: Option<PathBuf>,
    resume: Option<PathBuf>,
    progress: Option<Py<PyAny>>,
    yes: bool,
    accept_changed: bool,
) -> PyResult<Session> {
    let target = match (resume, out) {
        (Some(_), Some(_)) => return Err(errors::input(
            py,
            "out and resume given: a resumed session goes on in its own folder (give one of them)",
        )),
        (Some(dir), None) => SessionTarget::Resume(dir),
        (None, Some(dir)) => SessionTarget::New(dir),
        (None, None) => SessionTarget::New(dated_session_path(
            Path::new("sessions"),
            "",
            std::time::SystemTime::now(),
        )),
    };
    if config.is_none() && matches!(target, SessionTarget::New(_)) {
        return Err(errors::input(
            py,
            "a new session needs a cell config: handeye.run(\"configs/sim-cell.yaml\", out=...), or resume=FOLDER to continue one",
        ));
    }
    let stop = Arc::new(AtomicBool::new(false));
    let request = RunRequest {
        config,
        target,
        motion_confirmed: yes,
        accept_changed,
        stop: stop.clone(),
        // One detection thread per core (at most four), fewer when the memory limits say so.
        jobs: None,
    };
    let mut observer = PyObserver {
        progress,
        stop,
        error: None,
    };
    let outcome = py.detach(|| -> Result<(PathBuf, Option<String>), Failed> {
        let opened = open_run(&request, &mut observer).map_err(Failed::Run)?;
        if let Some(why) = opened.hand_guided() {
            return Err(Failed::HandGuided(why));
        }
        let done =
            run_opened(opened, &request, Strategy::Planned, &mut observer).map_err(Failed::Run)?;
        // The run's tail, as `handeye run` writes it: the report of one camera or several.
        let report = handeye_report::session::write_run_report(&done)
            .err()
            .map(|e| error_chain(&e));
        Ok((done.root.clone(), report))
    });
    // The calibration is saved; a report that could not be written is said, not raised.
    let outcome = outcome.map(|(folder, report)| {
        if let Some(why) = report {
            let warning = py.get_type::<pyo3::exceptions::PyUserWarning>();
            let _ = PyErr::warn(
                py,
                &warning,
                &std::ffi::CString::new(format!("the report could not be written: {why}"))
                    .unwrap_or_default(),
                1,
            );
        }
        folder
    });
    let interrupted = match &outcome {
        Err(Failed::Run(RunError::Session(SessionError::Interrupted { folder, .. }))) => {
            Some(folder.clone())
        }
        _ => None,
    };
    if let Some(error) = observer.error.take() {
        return Err(stopped(py, error, &outcome, interrupted));
    }
    match outcome {
        Ok(folder) => Session::new(py, folder),
        Err(Failed::HandGuided(why)) => Err(errors::input(
            py,
            format!("{why}: a hand-guided session runs on the console (`handeye console`, or `handeye run` with the config), not from Python; nothing was moved"),
        )),
        Err(Failed::Run(error)) => Err(errors::with_context(py, "running the cell", &error)),
    }
}

/// The exception of a run stopped from Python: a KeyboardInterrupt names where the samples are
/// kept and how to resume (as `session_folder` too); the callable's own exception is raised as
/// it was.
fn stopped(
    py: Python<'_>,
    error: PyErr,
    outcome: &Result<PathBuf, Failed>,
    interrupted: Option<PathBuf>,
) -> PyErr {
    if !error.is_instance_of::<PyKeyboardInterrupt>(py) {
        return error;
    }
    let (message, folder) = match (outcome, interrupted) {
        (Err(Failed::Run(run)), Some(folder)) => (
            format!(
                "{}; from Python: handeye.run(resume={:?})",
                error_chain(run),
                folder.display().to_string()
            ),
            Some(folder),
        ),
        (Ok(folder), _) => (
            format!(
                "interrupted after the run finished; its session is complete in {}",
                folder.display()
            ),
            Some(folder.clone()),
        ),
        (Err(Failed::Run(run)), None) => (format!("interrupted: {}", error_chain(run)), None),
        (Err(Failed::HandGuided(why)), _) => (format!("interrupted ({why})"), None),
    };
    let interrupt = PyKeyboardInterrupt::new_err(message);
    if let Some(folder) = folder {
        let _ = interrupt.value(py).setattr("session_folder", folder);
    }
    interrupt
}
