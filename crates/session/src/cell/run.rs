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

use crate::config::RobotConfig;
use crate::plan::nbv::{AdaptivePlanner, StopCheck};
use crate::plan::{GenerateSpec, Plan, Waypoint};
use crate::session::{
    self, changed_inputs, ManualControl, ManualOptions, SessionError, SessionEvent, SessionFolder,
    SessionOutcome, SolvedSession,
};
use handeye_core::geometry::Pose;
use handeye_core::setup::PosePair;
use handeye_robot::{Joints, Robot, RobotError, RobotStatus};
use handeye_solve::Calibration;

use super::{prepare, CellError, PreparedCell};

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
    /// The solved session (`result.yaml` is written).
    pub solved: SolvedSession,
    /// For an adaptive plan: how it went.
    pub adaptive: Option<AdaptiveSummary>,
    /// Arm time spent, and what the full plan would have cost (`None` for a hand-guided session:
    /// a person moved the arm, and there is no plan to compare with).
    pub arm_time: Option<ArmTime>,
}

/// The arm time of a run (the time the cell is out of production for the arm's sake: moving
/// and settling), and an estimate of what the full plan in its given order would have taken.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ArmTime {
    /// Poses visited in this run.
    pub poses: usize,
    /// Time in moves, s (measured).
    pub moving_s: f64,
    /// Time settling after moves until the frame's exposure, s (measured).
    pub settling_s: f64,
    /// Poses of the full plan (every pose that passes its checks).
    pub full_plan_poses: usize,
    /// The full plan in its given order: its moves at the configured limits plus this run's
    /// mean settling per pose for each of its poses, s (an estimate).
    pub full_plan_estimate_s: f64,
}

impl ArmTime {
    /// Moving plus settling, s.
    pub fn spent_s(&self) -> f64 {
        self.moving_s + self.settling_s
    }

    /// Estimated arm time saved against the full plan in its given order, s (negative: lost).
    pub fn saved_s(&self) -> f64 {
        self.full_plan_estimate_s - self.spent_s()
    }

    /// Whether arm time was measured: a simulated arm that moves instantly
    /// (`robot.move_duration_s: 0`) spends none — only the microseconds of the loop itself,
    /// under 10 ms a pose — and then nothing was saved either. (A real arm's move and settle
    /// take a second or more.)
    pub fn measured(&self) -> bool {
        self.poses == 0 || self.spent_s() >= 0.01 * self.poses as f64
    }

    /// The file in a session folder that keeps it (written after the run, read by the report).
    pub const FILE: &'static str = "arm_time.yaml";

    /// The arm time a session folder at `root` kept, if it kept one that reads.
    pub fn load(root: &std::path::Path) -> Option<ArmTime> {
        let text = std::fs::read_to_string(root.join(Self::FILE)).ok()?;
        serde_yaml_ng::from_str(&text).ok()
    }
}

impl std::fmt::Display for ArmTime {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if !self.measured() {
            return write!(
                f,
                "arm time: not measured, the {} moves took no time (a simulated arm with robot.move_duration_s: 0); the full {}-pose plan in its given order takes about {:.1} s at the configured limits",
                self.poses, self.full_plan_poses, self.full_plan_estimate_s
            );
        }
        write!(
            f,
            "arm time: {:.1} s for {} poses ({:.1} s moving, {:.1} s settling); the full {}-pose plan in its given order: about {:.1} s, so {:.1} s saved ({:.0} %)",
            self.spent_s(),
            self.poses,
            self.moving_s,
            self.settling_s,
            self.full_plan_poses,
            self.full_plan_estimate_s,
            self.saved_s(),
            if self.full_plan_estimate_s > 0.0 {
                100.0 * self.saved_s() / self.full_plan_estimate_s
            } else {
                0.0
            }
        )
    }
}

/// How an adaptive plan went.
#[derive(Debug, Clone, PartialEq)]
pub struct AdaptiveSummary {
    /// Poses in the session's plan now.
    pub in_session: usize,
    /// Candidate poses that passed their checks.
    pub candidates: usize,
    /// Poses chosen in this run.
    pub chosen_now: usize,
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
            "adaptive plan: {} of {} candidate poses in the session ({} chosen in this run); target 1-sigma {:.3} mm {}",
            self.in_session,
            self.candidates,
            self.chosen_now,
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
    #[error("no pose of the plan passes its checks (see the table above); nothing was moved")]
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

/// The resume check of every session kind (planned, adaptive, hand-guided): refuses, naming
/// each changed file, when the input files (`inputs`, hashed now) differ from those `manifest`
/// recorded, unless `accept_changed` (then each change is noted and `manifest` takes the files
/// used now, which the next resume compares against). Returns whether `manifest` changed (the
/// caller writes it).
fn check_resumed_inputs(
    folder: &SessionFolder,
    manifest: &mut session::SessionManifest,
    inputs: &[session::InputFile],
    accept_changed: bool,
    observer: &mut dyn RunObserver,
) -> Result<bool, RunError> {
    if manifest.inputs.is_empty() {
        observer.note(&format!(
            "{}: records no input hashes (an older session): changes to the config, board, intrinsics or plan since it was recorded cannot be detected",
            folder.manifest_path().display()
        ));
        return Ok(false);
    }
    let changes = changed_inputs(&manifest.inputs, inputs);
    if !changes.is_empty() && !accept_changed {
        return Err(SessionError::InputsChanged {
            folder: folder.root().to_path_buf(),
            changes,
        }
        .into());
    }
    for change in &changes {
        observer.note(&format!(
            "input changed, accepted (--accept-changed): {change}"
        ));
    }
    if manifest.inputs == inputs {
        return Ok(false);
    }
    manifest.inputs = inputs.to_vec();
    Ok(true)
}

/// A session a run continues.
#[derive(Debug)]
pub struct ResumedSession {
    /// Its folder, locked for this run.
    pub folder: SessionFolder,
    /// Its manifest, with the input files of this run when changes were accepted.
    pub manifest: session::SessionManifest,
    /// Whether `manifest` changed (accepted input changes, or the mark of a hand-guided session
    /// a planned resume handed over) and is not written to the folder yet.
    pub manifest_changed: bool,
}

/// A run opened: the cell prepared and its plan checked, the input files it uses, and for a
/// resume the session it continues.
pub struct OpenedRun {
    /// For a resume, the session continued.
    pub resumed: Option<ResumedSession>,
    /// The cell, prepared.
    pub cell: PreparedCell,
    /// The run's input files, hashed now.
    pub inputs: Vec<session::InputFile>,
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
            let folder = SessionFolder::resume(dir)?;
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
            let manifest_changed = check_resumed_inputs(
                &folder,
                &mut manifest,
                &inputs,
                request.accept_changed,
                observer,
            )?;
            Some(ResumedSession {
                folder,
                manifest,
                manifest_changed,
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
    let solved = session::solve_folder(&folder, &cell.solve_inputs())?;
    Ok(CellRun {
        cell,
        folder,
        outcome,
        solved,
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

    let adaptive = match &mut strategy {
        Strategy::Planned => {
            // Adaptive: the plan's poses are candidates; the ones that fail their checks are
            // skipped.
            let adaptive = cell.config.adaptive();
            if adaptive && !cell.intrinsics_known {
                return Err(RunError::AdaptiveNeedsIntrinsics);
            }
            if adaptive && cell.report.passing().is_empty() {
                return Err(RunError::NoPassingPose);
            }
            if !adaptive && !cell.report.ok() {
                return Err(RunError::PlanFailed);
            }
            if !cell.is_simulated() && !request.motion_confirmed {
                observer
                    .confirm_motion(&cell, cell.plan.waypoints.len())
                    .map_err(RunError::NotConfirmed)?;
            }
            adaptive
        }
        Strategy::Holdout(spec) => {
            spec.validate()
                .map_err(|e| RunError::Holdout(e.to_string()))?;
            if !cell.is_simulated() && !request.motion_confirmed {
                observer
                    .confirm_motion(&cell, spec.count)
                    .map_err(RunError::NotConfirmed)?;
            }
            false
        }
        Strategy::HandGuided(guide) => {
            // A session a planned resume handed over (an older one without the mark) is marked
            // hand-guided.
            if let Some(resumed) = &mut resumed {
                if !resumed.manifest.manual {
                    resumed.manifest.manual = true;
                    resumed.manifest_changed = true;
                }
            }
            guide.prepared(&cell);
            false
        }
    };
    let poses = cell.plan.waypoints.len();
    let mut hardware = cell.open_hardware().map_err(RunError::Hardware)?;
    ensure_robot_ready(hardware.robot.as_mut())?;
    // The plan was checked from an assumed start; check it again from where the arm really is
    // before the first move.
    let start = hardware.robot.joint_positions().map_err(RunError::Joints)?;
    let mut plan = match &strategy {
        Strategy::Planned if adaptive => {
            let _ = cell.recheck_from(start);
            let candidates = adaptive_candidates(&cell);
            if candidates.is_empty() {
                return Err(RunError::NoPassingPoseFromArm {
                    report: cell.report.to_string(),
                });
            }
            candidates
        }
        Strategy::Planned => match cell.recheck_from(start) {
            Ok(plan) => plan,
            Err(report) => {
                return Err(RunError::PlanFailsFromArm {
                    report: report.to_string(),
                })
            }
        },
        Strategy::Holdout(spec) => {
            // The cell was prepared from an assumed start: the views are checked from where
            // the arm is, and only usable ones kept (each move is checked again before it is
            // sent).
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
            passing
        }
        // Suggestions come from the plan's poses that pass their checks from where the arm
        // stands.
        Strategy::HandGuided(_) => {
            let _ = cell.recheck_from(start);
            cell.report.passing()
        }
    };
    // The plan this session records in its manifest and visits as given.
    let fixed_plan = match strategy {
        Strategy::Planned => !adaptive,
        Strategy::Holdout(_) => true,
        Strategy::HandGuided(_) => false,
    };

    let folder = match resumed {
        Some(ResumedSession {
            folder,
            manifest,
            manifest_changed,
        }) => {
            // An adaptive or hand-guided session's plan is what it chose so far: it continues
            // from there. A fixed plan ordered for travel time from where the arm stood then
            // keeps that order.
            if fixed_plan && !same_plan(&manifest, &plan) {
                match recorded_order(&manifest, &plan) {
                    Some(recorded) => plan = recorded,
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
            folder
        }
        None => {
            let folder = match &request.target {
                SessionTarget::New(out) => SessionFolder::create(out)?,
                SessionTarget::Created(folder) => folder.clone(),
                SessionTarget::Resume(_) => unreachable!("a resume has its folder"),
            };
            for note in folder.notes() {
                observer.note(note);
            }
            // An adaptive or hand-guided session's manifest starts empty and grows with the
            // poses it visits.
            let recorded: &[(Pose, Joints)] = if fixed_plan { &plan } else { &[] };
            let manifest = cell.manifest(recorded).with_inputs(inputs);
            let manifest = match strategy {
                Strategy::HandGuided(_) => manifest.hand_guided(),
                Strategy::Planned | Strategy::Holdout(_) => manifest,
            };
            folder.write_manifest(&manifest)?;
            folder
        }
    };

    let (outcome, adaptive_summary) = match &mut strategy {
        Strategy::Planned | Strategy::Holdout(_) => {
            let setup = cell.session_setup(folder.clone(), plan.clone(), request.stop.clone());
            observer.session_folder(&folder, &plan);
            observer.session_started(match strategy {
                Strategy::Holdout(_) => plan.len(),
                _ => poses,
            });
            let driven = drive_plan(
                &cell,
                setup,
                &plan,
                start,
                adaptive,
                &mut hardware,
                observer,
            );
            observer.session_ended();
            let (outcome, summary) = driven;
            if let Some(summary) = &summary {
                observer.note(&summary.to_string());
            }
            (outcome, summary)
        }
        Strategy::HandGuided(guide) => {
            let setup = cell.session_setup(folder.clone(), Vec::new(), request.stop.clone());
            observer.session_folder(&folder, &[]);
            observer.session_started(plan.len());
            let mut planner = (!plan.is_empty() && cell.intrinsics_known).then(|| {
                AdaptivePlanner::new(
                    cell.config.setup,
                    cell.config.nominal.camera_mount,
                    cell.config.nominal.target_mount,
                    plan.clone(),
                    cell.config.solver.to_options(),
                    // Suggestions never stop on their own: the person decides when to finish.
                    0.0,
                    usize::MAX,
                )
            });
            let options = ManualOptions {
                real_arm: !cell.is_simulated() && !request.motion_confirmed,
                ..ManualOptions::default()
            };
            let outcome = {
                let mut control = guide.control(&cell, &folder, &plan, &mut *observer);
                session::run_manual_session(
                    setup,
                    cell.config_path(),
                    planner.as_mut(),
                    &options,
                    hardware.robot.as_mut(),
                    hardware.camera.as_mut(),
                    control.as_mut(),
                )
            };
            observer.session_ended();
            guide.ended();
            (outcome, None)
        }
    };
    let outcome = outcome?;
    // A person moved a hand-guided arm, and there is no plan to compare with; a recorded robot
    // (frames imported from a bag or a ViSP folder) moved nothing now: no arm time for either.
    let recorded = matches!(cell.config.robot, RobotConfig::Recorded { .. });
    let arm_time =
        (matches!(strategy, Strategy::Planned) && !recorded).then(|| arm_time(&cell, &outcome));
    if let Some(arm_time) = &arm_time {
        observer.note(&arm_time.to_string());
        // Kept beside the result for the report; a failure to write it loses only this figure.
        if let Ok(text) = serde_yaml_ng::to_string(arm_time) {
            if let Err(e) = folder.write_file(std::path::Path::new(ArmTime::FILE), text.as_bytes())
            {
                observer.note(&format!("the arm time could not be kept: {e}"));
            }
        }
    }
    Ok(DrivenRun {
        cell,
        folder,
        outcome,
        adaptive: adaptive_summary,
        arm_time,
    })
}

/// Drives the config's plan: adaptively (the next-best pose among `plan`'s candidates, until
/// good enough) or as the fixed `plan`; the adaptive summary with the outcome.
fn drive_plan(
    cell: &PreparedCell,
    setup: session::SessionSetup,
    plan: &[(Pose, Joints)],
    start: Joints,
    adaptive: bool,
    hardware: &mut super::Hardware,
    observer: &mut dyn RunObserver,
) -> (
    Result<SessionOutcome, SessionError>,
    Option<AdaptiveSummary>,
) {
    let folder = setup.folder.clone();
    let mut on_event = |event: SessionEvent| observer.event(event);
    if !adaptive {
        let outcome = session::run_session(
            setup,
            hardware.robot.as_mut(),
            hardware.camera.as_mut(),
            &mut on_event,
        );
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
    let mut planner = AdaptivePlanner::new(
        cell.config.setup,
        cell.config.nominal.camera_mount,
        cell.config.nominal.target_mount,
        plan.to_vec(),
        cell.config.solver.to_options(),
        cell.config.adaptive_target_mm(),
        max_poses,
    )
    .with_min_poses(cell.config.plan.min_poses)
    .with_motion(cell.config.limits, start, per_pose_s(cell))
    .with_stop_check(good_enough(cell));
    let outcome = session::run_adaptive_session(
        setup,
        cell.config_path(),
        &mut planner,
        hardware.robot.as_mut(),
        hardware.camera.as_mut(),
        &mut on_event,
    );
    let summary = AdaptiveSummary {
        in_session: folder.read_manifest().map(|m| m.plan.len()).unwrap_or(0),
        candidates: plan.len(),
        chosen_now: planner.log.iter().filter(|s| s.chose.is_some()).count(),
        target_uncertainty_mm: cell.config.adaptive_target_mm(),
        max_poses,
        solved_sigma_mm: planner.log.last().and_then(|s| s.solved_sigma_mm),
        reached: planner.reached_target(),
    };
    (outcome, Some(summary))
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
fn good_enough(cell: &PreparedCell) -> StopCheck {
    let setup = cell.config.setup;
    let options = cell.config.solver.to_options();
    let accuracy = cell.config.verdict.accuracy();
    StopCheck(Arc::new(move |samples: &[PosePair], c: &Calibration| {
        let robot: Vec<Pose> = samples.iter().map(|p| p.base_from_flange).collect();
        if handeye_solve::rotation_diversity(&robot).off_axis_deg
            < handeye_solve::verdict::GOOD_OFF_AXIS_DEG
        {
            return false;
        }
        match handeye_solve::verdict::held_out(setup, samples, &options, &c.outliers) {
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

/// The candidates of an adaptive plan, checked from where the arm stands: the plan's poses that
/// pass their checks and, for a generated plan (which then takes at most `count` poses), more
/// views on the same cap (another seed, [`ADAPTIVE_EXTRA_CANDIDATES`] × `count`), so near and
/// informative poses are there to choose.
fn adaptive_candidates(cell: &PreparedCell) -> Vec<(Pose, Joints)> {
    let mut candidates = cell.report.passing();
    if let (Some(spec), None) = (cell.config.plan.generate, &cell.config.plan.file) {
        let count = (spec.count * ADAPTIVE_EXTRA_CANDIDATES)
            .min(crate::plan::MAX_PLAN_POSES.saturating_sub(spec.count));
        if count > 0 {
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
            candidates.extend(cell.check_plan(&views).passing());
        }
    }
    candidates
}

/// The run's arm time against the full plan in its given order.
fn arm_time(cell: &PreparedCell, outcome: &SessionOutcome) -> ArmTime {
    let report = &cell.report;
    let full: Vec<&crate::plan::check::PoseCheck> = report
        .poses
        .iter()
        .filter(|p| p.problems.is_empty())
        .collect();
    let given_moves_s = report
        .given_order_move_time_s
        .unwrap_or_else(|| report.total_move_time_s());
    let settle_per_pose = if outcome.visited_now > 0 {
        outcome.settling_s / outcome.visited_now as f64
    } else {
        0.0
    };
    ArmTime {
        poses: outcome.visited_now,
        moving_s: outcome.moving_s,
        settling_s: outcome.settling_s,
        full_plan_poses: full.len(),
        full_plan_estimate_s: given_moves_s + settle_per_pose * full.len() as f64,
    }
}

/// A resumed fixed plan whose poses are `plan`'s in another order (a plan ordered for travel
/// time from where the arm stood when the session started): the recorded order, with the joints
/// of today's check. `None` when the poses differ.
fn recorded_order(
    manifest: &session::SessionManifest,
    plan: &[(Pose, Joints)],
) -> Option<Vec<(Pose, Joints)>> {
    if manifest.plan.len() != plan.len() {
        return None;
    }
    let mut used = vec![false; plan.len()];
    manifest
        .plan
        .iter()
        .enumerate()
        .map(|(i, recorded)| {
            let r = recorded
                .base_from_flange
                .to_pose(&format!("plan[{i}]"))
                .ok()?;
            let k = (0..plan.len()).find(|&k| {
                !used[k]
                    && r.rotation.angle_to(&plan[k].0.rotation) < 1e-9
                    && (r.translation.vector - plan[k].0.translation.vector).norm() < 1e-9
            })?;
            used[k] = true;
            Some(plan[k])
        })
        .collect()
}

/// Whether a resumed session's recorded plan is `plan` (same flange poses, in order).
fn same_plan(manifest: &session::SessionManifest, plan: &[(Pose, Joints)]) -> bool {
    manifest.plan.len() == plan.len()
        && manifest
            .plan
            .iter()
            .zip(plan)
            .enumerate()
            .all(|(i, (recorded, (pose, _)))| {
                recorded
                    .base_from_flange
                    .to_pose(&format!("plan[{i}]"))
                    .map(|r| {
                        r.rotation.angle_to(&pose.rotation) < 1e-9
                            && (r.translation.vector - pose.translation.vector).norm() < 1e-9
                    })
                    .unwrap_or(false)
            })
}

#[cfg(test)]
mod tests {
    use super::ArmTime;

    #[test]
    fn instant_moves_claim_no_saving() {
        let instant = ArmTime {
            poses: 8,
            moving_s: 0.0,
            settling_s: 0.0,
            full_plan_poses: 20,
            full_plan_estimate_s: 28.6,
        };
        let text = instant.to_string();
        assert!(!instant.measured());
        assert!(
            text.contains("not measured") && !text.contains("saved"),
            "{text}"
        );
        // What the demo's instant moves really measure: the loop's own few milliseconds.
        let loop_only = ArmTime {
            moving_s: 0.0004,
            settling_s: 0.0031,
            ..instant
        };
        assert!(!loop_only.measured(), "{loop_only}");
        let real = ArmTime {
            moving_s: 9.0,
            settling_s: 1.0,
            ..instant
        };
        assert!(real.measured());
        assert!(real.to_string().contains("18.6 s saved"), "{real}");
    }
}
