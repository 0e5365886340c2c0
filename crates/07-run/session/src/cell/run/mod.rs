//! Running a cell end to end — the library side of `handeye run`: prepare the cell from its
//! config (or from a session's, to resume), refuse a plan that fails its checks, ask before a
//! real arm moves, open the hardware, refuse an arm that is not ready, check the plan again from
//! where the arm really stands, create (or lock and check) the session folder, drive the fixed or
//! adaptive plan, and solve. The CLI parses arguments, calls [`run`], and prints; tests call
//! the same function.
//!
//! On resume the session's recorded input hashes must match the files as they are now (unless
//! the caller accepts the change), and a fixed plan must be the one the session was started
//! with (or the same poses in the order the session recorded: a plan ordered for travel time
//! from where the arm stood then).
//!
//! Arm time: a generated plan runs adaptively by default (next-best pose weighed by move time,
//! stopping when the result is good enough: the solved 1-sigma at the target, the held-out error
//! within the verdict's accuracy, the rotations spread, at least `plan.min_poses` poses); a
//! fixed plan runs in the order of least move time. [`ArmTime`] says what the run spent and
//! what the full plan in its given order would have cost.
//!
//! Depends on `session`, `plan`, `robot`, `solve`, `verdict` and the ground floor.

use std::path::PathBuf;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;

use crate::{ManualControl, SessionEvent, SessionOutcome};
use handeye_core::geometry::Pose;
use handeye_plan::GenerateSpec;
use handeye_records::result::CellResult;
use handeye_records::{SessionError, SessionFolder, SolvedSession};
use handeye_robot::{Joints, Robot, RobotError, RobotStatus};

use super::{prepare, CellError, PreparedCell};

mod adaptive;
mod arm_time;
mod resume;
mod stages;

pub use adaptive::{extra_candidates, AdaptiveSummary, ADAPTIVE_EXTRA_CANDIDATES};
pub use arm_time::ArmTime;
use resume::check_resumed_inputs;
pub use resume::ResumedSession;

/// Where the run's records go.
#[derive(Debug, Clone)]
pub enum SessionTarget {
    /// A new session folder (it may exist if it holds nothing of a session).
    New(PathBuf),
    /// Continue the session in this folder.
    Resume(PathBuf),
    /// A new session in a folder the caller created and holds (locked), with files of its own
    /// in it: an import's frames and recorded cell, which the run then uses.
    Created(SessionFolder),
}

impl SessionTarget {
    /// The session's own folder, what `-o` (or `--resume`) named: for one camera the run's
    /// `folder`, for several the folder holding every camera's.
    pub fn root(&self, folder: &SessionFolder) -> PathBuf {
        match self {
            SessionTarget::New(dir) => dir.clone(),
            SessionTarget::Resume(dir) => resumed_root(dir),
            SessionTarget::Created(_) => folder.root().to_path_buf(),
        }
    }
}

/// The session `--resume dir` continues: `dir`, or when it is one camera's folder of a
/// several-camera session, that session (every camera's records and the joint answer are its).
fn resumed_root(dir: &std::path::Path) -> PathBuf {
    super::cameras::session_of_camera_folder(dir).unwrap_or_else(|| dir.to_path_buf())
}

/// What to run: a planned run ([`run`]) or a hand-guided one (`console::manual::run_manual`).
#[derive(Debug, Clone)]
pub struct RunRequest {
    /// The cell config: required for a new session; on resume it overrides the config the
    /// session recorded.
    pub config: Option<PathBuf>,
    /// New session or resume.
    pub target: SessionTarget,
    /// The person confirmed already that a real arm may move (`--yes`): to the plan's poses,
    /// or to the views a hand-guided session suggests.
    pub motion_confirmed: bool,
    /// Resume even though input files changed since the session was recorded.
    pub accept_changed: bool,
    /// Set (by Ctrl-C, SIGTERM, SIGHUP) to stop the arm and end the run with every sample kept.
    pub stop: Arc<AtomicBool>,
    /// Detection threads (`-j`; `None`: one per core, at most four, as the memory limits allow).
    pub jobs: Option<usize>,
}

/// Told what happens during a run (the CLI prints it).
pub trait RunObserver {
    /// The cell is prepared and its plan checked (called before the run refuses a failing plan).
    fn plan_checked(&mut self, _cell: &PreparedCell) {}
    /// A real arm is about to move through `poses` poses: return an error to refuse. (No
    /// default: every observer decides for itself whether a real arm may move.)
    fn confirm_motion(
        &mut self,
        cell: &PreparedCell,
        poses: usize,
    ) -> Result<(), Box<dyn std::error::Error + Send + Sync>>;
    /// A several-camera cell: how many of the plan's poses each camera is expected to see its
    /// board at (by the nominal cell), before anything moves.
    fn cameras_planned(&mut self, _views: &[super::cameras::PlannedViews]) {}
    /// Something a person should know (a stale lock taken over, changed inputs accepted...).
    fn note(&mut self, _message: &str) {}
    /// The session folder is ready and `plan` (for an adaptive plan: its candidates) validated
    /// from where the arm stands; called once, before the first move.
    fn session_folder(&mut self, _folder: &SessionFolder, _plan: &[(Pose, Joints)]) {}
    /// The session loop starts, for up to `poses` poses.
    fn session_started(&mut self, _poses: usize) {}
    /// Progress of the session loop.
    fn event(&mut self, _event: SessionEvent) {}
    /// The session loop ended (well or not); solving follows when it ended well.
    fn session_ended(&mut self) {}
}

/// A finished run: the cell, its session folder, what the loop did, and the solution.
pub struct CellRun {
    /// The prepared cell.
    pub cell: PreparedCell,
    /// The session folder (still locked until this is dropped).
    pub folder: SessionFolder,
    /// What the loop did.
    pub outcome: SessionOutcome,
    /// A cell of one camera: its solved session (`result.yaml` is written). `None` for several
    /// cameras, whose answer is the joint one ([`Self::result`]): no camera of theirs is solved
    /// alone, which would leave a second, different answer in its folder.
    pub solved: Option<SolvedSession>,
    /// The session's own folder, what `-o` named (or `--resume`): the run's folder, or for
    /// several cameras the folder holding `rig.yaml` and every camera's folder (the run's is
    /// the planner camera's).
    pub root: PathBuf,
    /// The cell's answer as the session's `result.yaml` holds it, whatever the number of
    /// cameras: one camera's answer (a cell of one), or the joint answer of several.
    pub result: CellResult,
    /// For an adaptive plan: how it went.
    pub adaptive: Option<AdaptiveSummary>,
    /// Arm time spent, and what the full plan would have cost (`None` for a hand-guided session:
    /// a person moved the arm, and there is no plan to compare with).
    pub arm_time: Option<ArmTime>,
}

/// The tail of a finished run that lives above the run layer: its report
/// (`handeye_report::session::write_run_report`), written while the run still holds its folder
/// (a bag's import, before its staging folder moves into place). Returns the page's path, or why
/// it could not be written.
pub type RunReport<'a> = &'a dyn Fn(&CellRun) -> Result<PathBuf, String>;

impl CellRun {
    /// The run's verdict (the cell's: of several cameras, its worst camera's) and the summary a
    /// person reads first (one camera: its solve's; several: the cell's verdict, then each
    /// camera's).
    pub fn verdict_and_summary(&self) -> (Option<&handeye_solve::verdict::Verdict>, String) {
        let result = &self.result;
        if let Some(solved) = &self.solved {
            return (result.verdict.as_ref(), solved.summary.clone());
        }
        let line = |name: &str, verdict: Option<&handeye_solve::verdict::Verdict>| {
            verdict.map_or_else(
                || format!("{name}: no verdict"),
                |v| format!("{name}: {} — {}", v.level, v.reason),
            )
        };
        let mut summary = line("cell", result.verdict.as_ref());
        for c in &result.cameras {
            summary += &format!("\n{}", line(&c.name, c.verdict.as_ref()));
        }
        (result.verdict.as_ref(), summary)
    }
}

/// Why a run did not happen or did not finish.
#[derive(Debug, thiserror::Error)]
pub enum RunError {
    /// A holdout check has no usable view (or an unusable request for views).
    #[error("the verification plan failed its checks: {0}")]
    Holdout(String),
    /// The intrinsics file is the shipped placeholder, not this camera's calibration.
    #[error("{}: the intrinsics are the shipped placeholder (camera_name: {name}), not this camera's calibration — a calibration with them gives a wrong hand-eye transform; calibrate the camera and point `intrinsics:` in {} at its camera_info file, or drop `intrinsics:` so the run estimates them from the board; nothing was moved", file.display(), config.display())]
    PlaceholderIntrinsics {
        /// The intrinsics file.
        file: PathBuf,
        /// Its `camera_name`.
        name: String,
        /// The cell config naming it.
        config: PathBuf,
    },
    /// A several-camera cell's cameras, plan or folder do not fit the run.
    #[error("{0}")]
    Cameras(String),
    /// The joint solve of a several-camera cell.
    #[error(transparent)]
    CamerasSolve(#[from] super::cameras::CamerasSolveError),
    /// A new session needs a config.
    #[error("a new session needs a cell config (--config)")]
    NoConfig,
    /// The cell could not be prepared from its config.
    #[error("preparing the cell")]
    Prepare {
        /// The config file.
        config: PathBuf,
        /// What went wrong.
        #[source]
        source: CellError,
    },
    /// An adaptive plan without intrinsics.
    #[error("an adaptive plan needs the camera intrinsics (it chooses poses from board poses as they come): give `intrinsics:` or use a fixed plan")]
    AdaptiveNeedsIntrinsics,
    /// No candidate of an adaptive plan passes its checks.
    #[error("no candidate of the adaptive plan passes its checks (see the table above); nothing was moved")]
    NoPassingPose,
    /// A fixed plan fails its checks.
    #[error("the plan failed its checks (see the table above); nothing was moved")]
    PlanFailed,
    /// The person did not confirm motion.
    #[error(transparent)]
    NotConfirmed(Box<dyn std::error::Error + Send + Sync>),
    /// The robot or camera could not be opened.
    #[error("opening the robot and camera")]
    Hardware(#[source] CellError),
    /// The robot could not be asked.
    #[error("reading the robot's safety status")]
    Status(#[source] RobotError),
    /// The robot is in a protective stop.
    #[error("the robot is in a protective stop: clear it on the teach pendant, then start again; nothing was moved")]
    ProtectiveStop,
    /// The robot's emergency stop is active.
    #[error("the robot's emergency stop is active: release it and power the arm on, then start again; nothing was moved")]
    EmergencyStop,
    /// The robot cannot run programs.
    #[error("the robot is not ready to run programs (powered off, brakes on or in local mode): make it ready on the teach pendant, then start again; nothing was moved")]
    NotReady,
    /// The joints could not be read.
    #[error("reading the arm's joint positions")]
    Joints(#[source] RobotError),
    /// From the arm's real position no adaptive candidate passes.
    #[error("from the arm's actual position no pose of the plan passes its checks; nothing was moved:\n{report}")]
    NoPassingPoseFromArm {
        /// The plan check, as a table.
        report: String,
    },
    /// From the arm's real position the fixed plan fails.
    #[error(
        "from the arm's actual position the plan fails its checks; nothing was moved:\n{report}"
    )]
    PlanFailsFromArm {
        /// The plan check, as a table.
        report: String,
    },
    /// A resumed fixed plan differs from the recorded one.
    #[error("the plan from the config differs from the one {} was started with; resume with the same config, or start a new session", folder.display())]
    PlanChanged {
        /// The session folder.
        folder: PathBuf,
    },
    /// The session failed (its message says how to resume when samples are kept).
    #[error(transparent)]
    Session(#[from] SessionError),
}

/// Refuses to start unless the controller reports it can move: a protective or emergency stop
/// or a controller not running programs would fail the first move anyway, less clearly.
pub fn ensure_robot_ready(robot: &mut dyn Robot) -> Result<(), RunError> {
    match robot.status().map_err(RunError::Status)? {
        RobotStatus::Ready => Ok(()),
        RobotStatus::ProtectiveStop => Err(RunError::ProtectiveStop),
        RobotStatus::EmergencyStop => Err(RunError::EmergencyStop),
        RobotStatus::NotReady => Err(RunError::NotReady),
    }
}

/// A run opened: the cell prepared and its plan checked, the input files it uses, and for a
/// resume the session it continues.
pub struct OpenedRun {
    /// For a resume, the session continued.
    pub resumed: Option<ResumedSession>,
    /// The cell, prepared.
    pub cell: PreparedCell,
    /// The run's input files, hashed now.
    pub inputs: Vec<handeye_records::InputFile>,
}

impl OpenedRun {
    /// Why this run is hand-guided (`Some`): the resumed session was recorded by hand (its
    /// manifest says so), or its config says `plan.manual`. The caller hands it to a hand guide
    /// ([`run_opened`] with [`Strategy::HandGuided`]).
    pub fn hand_guided(&self) -> Option<&'static str> {
        match &self.resumed {
            Some(resumed) if resumed.manifest.manual => Some("a hand-guided session"),
            _ => self.cell.config.plan.manual.then_some("plan.manual"),
        }
    }
}

/// The start of every run, planned or hand-guided: for a resume, its session folder (locked
/// first, so a second resume of the same folder stops here; its notes told to `observer`) and
/// manifest; the cell of the request's config (a resume's own config unless the request names
/// one), prepared, its plan checked and shown to `observer`; for a resume, the check that its
/// input files did not change since it was recorded (refused, naming each, unless
/// `accept_changed`), before the arm or camera is opened.
pub fn open_run(
    request: &RunRequest,
    observer: &mut dyn RunObserver,
) -> Result<OpenedRun, RunError> {
    let (resumed, config_path) = match &request.target {
        SessionTarget::Resume(dir) => {
            // A several-camera session is resumed through its planner camera's folder.
            let folder =
                SessionFolder::resume(&super::cameras::session_folder_of(&resumed_root(dir)))?;
            let manifest = folder.read_manifest()?;
            let config = request
                .config
                .clone()
                .unwrap_or_else(|| manifest.config.clone());
            (Some((folder, manifest)), config)
        }
        SessionTarget::New(_) | SessionTarget::Created(_) => {
            (None, request.config.clone().ok_or(RunError::NoConfig)?)
        }
    };
    let cell = prepare(&config_path).map_err(|source| RunError::Prepare {
        config: config_path.clone(),
        source,
    })?;
    observer.plan_checked(&cell);
    if let Some((file, name)) = cell.placeholder_intrinsics() {
        return Err(RunError::PlaceholderIntrinsics {
            file,
            name,
            config: config_path,
        });
    }
    let inputs = cell.inputs()?;
    let resumed = match resumed {
        Some((folder, mut manifest)) => {
            for note in folder.notes() {
                observer.note(note);
            }
            // A session that recorded no pose yet (it stopped before its first capture: a
            // wrong lens file, an arm not ready) takes today's inputs and plan as they are.
            let recorded_poses = folder.read_visits()?.len();
            let manifest_changed = check_resumed_inputs(
                &folder,
                &mut manifest,
                &inputs,
                if request.accept_changed {
                    Some("--accept-changed")
                } else if recorded_poses == 0 {
                    Some("nothing was recorded yet")
                } else {
                    None
                },
                observer,
            )?;
            Some(ResumedSession {
                folder,
                manifest,
                manifest_changed,
                recorded_poses,
            })
        }
        None => None,
    };
    Ok(OpenedRun {
        resumed,
        cell,
        inputs,
    })
}

/// How a run chooses and visits its poses: the one thing that differs between kinds of run;
/// [`run`] does everything else the same way for each.
pub enum Strategy<'a> {
    /// The config's plan: fixed (visited in the order of least move time) or adaptive (the
    /// next-best pose, stopping when good enough).
    Planned,
    /// A person chooses the views and says when to capture (the console's hand-guided session);
    /// the config's plan poses are only suggested. `guide` is the person's side.
    HandGuided(&'a mut dyn HandGuide),
    /// Fresh views generated from `spec` (a seed the calibration did not use), to check a
    /// result against: the views that fail their checks from where the arm stands are dropped
    /// (a refusal only when none is left), the rest visited as a fixed plan. `handeye verify`.
    Holdout(GenerateSpec),
}

/// The person's side of a hand-guided run (the console page and terminal): told the stages of
/// the run, and the [`ManualControl`] the session takes its commands from.
pub trait HandGuide {
    /// The cell is prepared and its plan checked; nothing is opened yet.
    fn prepared(&mut self, _cell: &PreparedCell) {}
    /// The session folder is ready: the control for the session, which tells `observer` what
    /// the terminal prints. `suggestions` are the plan poses that pass their checks.
    fn control<'g>(
        &'g mut self,
        cell: &'g PreparedCell,
        folder: &SessionFolder,
        suggestions: &[(Pose, Joints)],
        observer: &'g mut dyn RunObserver,
    ) -> Box<dyn ManualControl + 'g>;
    /// The session loop ended (well or not).
    fn ended(&mut self) {}
}

/// The checks of a cell's plan a planned run makes before anything opens, and `plan check` makes
/// the same: an adaptive plan needs the intrinsics and one passing pose (its poses are
/// candidates, the failing ones skipped), a fixed plan every pose passing, and each camera of a
/// listed cell its share of the views ([`PreparedCell::planned_views`], returned).
pub fn check_plan(
    cell: &PreparedCell,
) -> Result<Option<Vec<super::cameras::PlannedViews>>, RunError> {
    let adaptive = cell.config.adaptive();
    if adaptive && !cell.camera().intrinsics_known {
        return Err(RunError::AdaptiveNeedsIntrinsics);
    }
    if adaptive && cell.report.passing().is_empty() {
        return Err(RunError::NoPassingPose);
    }
    if !adaptive && !cell.report.ok() {
        return Err(RunError::PlanFailed);
    }
    cell.planned_views().map_err(RunError::Cameras)
}

/// Runs (or resumes) a calibration of a cell and solves it: `handeye run` (planned), `handeye
/// console` and a hand-guided resume (hand-guided) all come here. In order: the session folder
/// locked and checked for changed inputs with the cell prepared ([`open_run`]); the strategy's
/// checks before anything opens (a real arm's confirmation); the hardware opened and the arm
/// found ready; the poses checked again from where the arm stands; the folder created (or the
/// resumed one's plan checked) with its manifest; the session driven; arm time measured; the
/// session solved (`result.yaml`, the verdict).
pub fn run(
    request: &RunRequest,
    strategy: Strategy<'_>,
    observer: &mut dyn RunObserver,
) -> Result<CellRun, RunError> {
    let opened = open_run(request, observer)?;
    run_opened(opened, request, strategy, observer)
}

/// [`run`] of a run [`open_run`] opened already (the caller chose the strategy from it, e.g.
/// from [`OpenedRun::hand_guided`]): nothing is read or prepared again.
pub fn run_opened(
    opened: OpenedRun,
    request: &RunRequest,
    strategy: Strategy<'_>,
    observer: &mut dyn RunObserver,
) -> Result<CellRun, RunError> {
    let DrivenRun {
        cell,
        folder,
        outcome,
        adaptive,
        arm_time,
    } = drive_opened(opened, request, strategy, observer)?;
    // The session's answer: a cell of one camera's is its camera's, as its solve wrote it (in
    // either form of the config: a listed cell of one has that one answer at its root too),
    // several cameras' the joint solve of every camera's records.
    let solved = (cell.config.cameras.len() == 1)
        .then(|| handeye_records::solve_folder(&folder, &cell.solve_inputs()))
        .transpose()?;
    let root = request.target.root(&folder);
    let result = if solved.is_some() {
        let result = CellResult::load(&folder.result_path()).map_err(SessionError::File)?;
        if cell.config.listed {
            result
                .save(&super::replay::AnswerOutput::run(&root).result)
                .map_err(SessionError::File)?;
        }
        result
    } else {
        super::cameras::solve_cameras_folder(
            &root,
            &cell.config,
            super::cameras::recorded_visits(&root, &cell.config)?,
            &super::replay::AnswerOutput::run(&root),
        )?
    };
    Ok(CellRun {
        cell,
        folder,
        outcome,
        solved,
        root,
        result,
        adaptive,
        arm_time,
    })
}

/// A run driven to its end, not solved yet.
pub struct DrivenRun {
    /// The prepared cell.
    pub cell: PreparedCell,
    /// The session folder (still locked until this is dropped).
    pub folder: SessionFolder,
    /// What the loop did.
    pub outcome: SessionOutcome,
    /// For an adaptive plan: how it went.
    pub adaptive: Option<AdaptiveSummary>,
    /// Arm time spent, and what the full plan would have cost (planned runs only).
    pub arm_time: Option<ArmTime>,
}

/// [`run`] up to the end of the session loop, without the solve: what a holdout check needs
/// (it compares the recorded board poses with a result instead of solving them).
pub fn drive(
    request: &RunRequest,
    strategy: Strategy<'_>,
    observer: &mut dyn RunObserver,
) -> Result<DrivenRun, RunError> {
    let opened = open_run(request, observer)?;
    drive_opened(opened, request, strategy, observer)
}

/// The run's stages in order ([`stages`]): the strategy's checks, the hardware opened and the
/// arm found ready, the poses checked from where it stands, the session folder, the session
/// driven, the arm time.
fn drive_opened(
    opened: OpenedRun,
    request: &RunRequest,
    mut strategy: Strategy<'_>,
    observer: &mut dyn RunObserver,
) -> Result<DrivenRun, RunError> {
    let OpenedRun {
        mut resumed,
        mut cell,
        inputs,
    } = opened;
    let adaptive =
        stages::check_before_opening(&cell, &mut resumed, request, &mut strategy, observer)?;
    let mut hardware = cell.open_hardware().map_err(RunError::Hardware)?;
    ensure_robot_ready(hardware.robot.as_mut())?;
    let start = hardware.robot.joint_positions().map_err(RunError::Joints)?;
    let stages::SessionPoses {
        mut plan,
        candidate_numbers,
    } = stages::poses_from_arm(&mut cell, &strategy, adaptive, start)?;
    // The plan this session records in its manifest and visits as given.
    let fixed_plan = match strategy {
        Strategy::Planned => !adaptive,
        Strategy::Holdout(_) => true,
        Strategy::HandGuided(_) => false,
    };
    let folder = stages::session_folder(
        &cell, resumed, request, &strategy, &mut plan, fixed_plan, inputs, observer,
    )?;
    let (outcome, adaptive_summary) = stages::drive_session(
        &cell,
        &folder,
        request,
        &mut strategy,
        (&plan, &candidate_numbers),
        (start, adaptive, fixed_plan),
        &mut hardware,
        observer,
    )?;
    let arm_time = (matches!(strategy, Strategy::Planned) && cell.config.robot.backend().moves())
        .then(|| stages::keep_arm_time(&cell, &folder, &outcome, observer));
    Ok(DrivenRun {
        cell,
        folder,
        outcome,
        adaptive: adaptive_summary,
        arm_time,
    })
}
