//! A session's records: what the files of a session folder hold and how they are read, kept and
//! solved. Below the run (`handeye-session`), above the config (`handeye-config`):
//!
//! - [`dataset`], [`result`]: pose-pair datasets and the result file;
//! - [`folder`]: the session folder, a write-ahead log (a pose is committed by its record;
//!   `samples.yaml` is rebuilt from the records on every start and resume), locked by the process
//!   running it ([`lock`]), with the sha256 of its input files so a resume can refuse changed
//!   inputs ([`inputs`]); [`staging`] folders of a run not yet moved into place; what a ROS 2 graph
//!   keeps on `/tf_static` ([`tf_static`]);
//! - [`solve`]: the session solve (`solve_with_arm`, the one a run, `handeye solve`, Python and
//!   `replay` go through), its checks of the given files and its verdict.
//!
//! [`SessionError`] is every way a session can stop or fail to be read.

pub mod dataset;
pub mod folder;
pub mod inputs;
pub mod lock;
pub mod result;
pub mod solve;
pub mod staging;
pub mod tf_static;

use std::path::PathBuf;

pub use folder::{
    dated_session_path, PlannedPose, PoseVisit, SessionFolder, SessionManifest, RESULT_FILE,
};
pub use inputs::{changed_inputs, InputChange, InputFile};
pub use lock::{live_run, refuse_live, LiveRun, SessionLock};
pub use solve::{
    corrected_by_arm_model, load_and_solve, solve_folder, solve_folder_in, solve_session,
    solve_session_with, solve_unwritten, Evidence, SolveInputs, SolvedSession,
};
pub use staging::{remove_abandoned, Leftover, Staging};

use handeye_camera::CameraError;
use handeye_core::camera_model::CameraModelError;
use handeye_core::geometry::PoseError;
use handeye_robot::RobotError;
use handeye_solve::SolveError;
use handeye_vision::TargetError;

/// What to do before resuming a stopped run: raise the memory limit when that is what stopped
/// it (resumed under the same limit, it fails the same way), else `otherwise`.
fn before_resuming(short_of_memory: bool, otherwise: &'static str) -> &'static str {
    if short_of_memory {
        "raise the memory limit, then "
    } else {
        otherwise
    }
}

/// Why a session stopped or could not run.
#[derive(Debug, thiserror::Error)]
pub enum SessionError {
    /// The output folder already holds something.
    #[error(
        "session folder {0} already exists and is not empty; choose another --output or --resume it"
    )]
    FolderExists(PathBuf),
    /// `--resume` (or a reader) was given a folder that is not a session.
    #[error("{} is not a session folder (no session.yaml){}", .0.display(), not_a_session_hint(.0))]
    NotASession(PathBuf),
    /// Another live process runs or resumes the session in this folder.
    #[error("session folder {}: {run} (lock file {}): wait for that run to end or stop it; two runs in one folder would mix their samples", run.folder.display(), run.folder.join(lock::LOCK_FILE).display())]
    Locked {
        /// The run holding the lock.
        run: LiveRun,
    },
    /// A command that must not read a session while it is recorded (`replay`), or that finds
    /// nothing to read yet (`solve` before the run's first sample), was given a live session.
    #[error("session folder {}: {run}; {next}", run.folder.display())]
    Recording {
        /// The run recording it.
        run: LiveRun,
        /// What to do instead.
        next: String,
    },
    /// Input files changed since the session was recorded; resuming would mix two cells.
    #[error("the input files of {} changed since the session was recorded:\n{}\nresuming would mix samples taken with different inputs: restore the files, start a new session, or resume with --accept-changed", folder.display(), changes.iter().map(|c| format!("  - {c}")).collect::<Vec<_>>().join("\n"))]
    InputsChanged {
        /// The session folder.
        folder: PathBuf,
        /// Each changed input.
        changes: Vec<InputChange>,
    },
    /// A pose's frame, record or the samples file could not be written (a full disk, say);
    /// every pose committed before is kept.
    #[error("could not record plan pose {plan_index} ({recorded} poses recorded and kept); {}resume with `handeye run --resume {}`", before_resuming(source.short_of_memory(), "fix the cause (free disk space, say), then "), folder.display())]
    RecordFailed {
        /// The pose being recorded.
        plan_index: usize,
        /// Poses recorded so far.
        recorded: usize,
        /// The session folder.
        folder: PathBuf,
        /// The write that failed.
        #[source]
        source: Box<SessionError>,
    },
    /// No visited pose gave a sample, so there is nothing to solve.
    #[error("no pose of session {} gave a sample: {visited} pose(s) visited, every one rejected ({reasons}); check that the board is in view and the detector settings, then start a new session", folder.display())]
    NoSamples {
        /// The session folder.
        folder: PathBuf,
        /// Poses visited.
        visited: usize,
        /// The first rejections, `pose N: why`.
        reasons: String,
    },
    /// No visited pose gave a sample because the configured intrinsics do not fit the frames.
    #[error("no pose of session {} gave a sample ({visited} pose(s) visited, every one rejected: {first}): {reason}\nnext: {next}", folder.display())]
    WrongIntrinsics {
        /// The session folder.
        folder: PathBuf,
        /// Poses visited.
        visited: usize,
        /// The first rejection.
        first: String,
        /// What is wrong, with the numbers.
        reason: String,
        /// What to do (the estimate written into the session, the replay command).
        next: String,
    },
    /// The few poses the configured intrinsics let through could not be solved, and the
    /// intrinsics do not fit the frames (issue #38: an adaptive plan that kept 2 of 60 poses).
    #[error("the session {} could not be solved from the {accepted} pose(s) of {visited} visited that its intrinsics let through ({why}): {reason}\nnext: {next}", folder.display())]
    WrongIntrinsicsFewSamples {
        /// The session folder.
        folder: PathBuf,
        /// Poses accepted.
        accepted: usize,
        /// Poses visited (with those a growing plan kept aside).
        visited: usize,
        /// Why the solve refused them.
        why: String,
        /// What is wrong, with the numbers.
        reason: String,
        /// What to do (the estimate written into the session, the replay command).
        next: String,
    },
    /// `samples.yaml` does not hold exactly the accepted pose records.
    #[error("{}: disagrees with the pose records in poses/: {} (a run killed between a record and this file); `handeye run --resume {}` rebuilds it from the records", file.display(), describe_disagreement(missing, extra), folder.display())]
    SamplesDisagree {
        /// `samples.yaml`.
        file: PathBuf,
        /// The session folder.
        folder: PathBuf,
        /// Accepted records without a sample (sample ids).
        missing: Vec<String>,
        /// Samples without an accepted record (sample ids).
        extra: Vec<String>,
    },
    /// A file could not be read or written.
    #[error("cannot access {path}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        #[source]
        source: std::io::Error,
    },
    /// A session record could not be read or written, or does not have its shape.
    #[error(transparent)]
    File(#[from] handeye_core::yaml_file::FileError),
    /// A session record is malformed.
    #[error("{file}: {path}: {message}")]
    Record {
        /// The file.
        file: PathBuf,
        /// YAML path.
        path: String,
        /// What is wrong.
        message: String,
    },
    /// A pose in a session record is malformed.
    #[error("{file}: {source}")]
    Pose {
        /// The file.
        file: PathBuf,
        /// The pose problem.
        #[source]
        source: PoseError,
    },
    /// The robot stopped the run; every sample so far is kept.
    #[error("robot stopped the run at plan pose {plan_index} ({recorded} poses recorded); resume with `handeye run --resume {folder}`")]
    Robot {
        /// Where it stopped.
        plan_index: usize,
        /// Poses recorded so far.
        recorded: usize,
        /// The session folder.
        folder: PathBuf,
        /// The robot error.
        #[source]
        source: RobotError,
    },
    /// The camera failed; every sample so far is kept.
    #[error("camera failed at plan pose {plan_index} ({recorded} poses recorded); {}resume with `handeye run --resume {folder}`", before_resuming(matches!(source, CameraError::Memory(_)), ""))]
    Camera {
        /// Where it failed.
        plan_index: usize,
        /// Poses recorded so far.
        recorded: usize,
        /// The session folder.
        folder: PathBuf,
        /// The camera error.
        #[source]
        source: CameraError,
    },
    /// The next move, from where the arm actually stands, would leave the workspace box: it was
    /// not sent; every sample so far is kept.
    #[error("the move to plan pose {plan_index} was not sent: from the arm's current joints {problem} ({recorded} poses recorded); jog the arm back near the plan's poses, then resume with `handeye run --resume {folder}`")]
    UnsafeMove {
        /// The pose it would have moved to.
        plan_index: usize,
        /// Poses recorded so far.
        recorded: usize,
        /// The session folder.
        folder: PathBuf,
        /// Where the move leaves the box.
        problem: String,
    },
    /// Interrupted by the user; the arm was stopped and every sample so far is kept.
    #[error("interrupted at plan pose {plan_index} ({recorded} poses recorded); the arm was stopped; resume with `handeye run --resume {folder}`")]
    Interrupted {
        /// Where it stopped.
        plan_index: usize,
        /// Poses recorded so far.
        recorded: usize,
        /// The session folder.
        folder: PathBuf,
    },
    /// Solving the recorded samples failed at one stage.
    #[error("solving the session failed ({stage})")]
    Solve {
        /// Which step: `pose space`, `reprojection refinement`, `estimating the intrinsics`, …
        stage: &'static str,
        /// Why.
        #[source]
        source: Box<SolveError>,
    },
    /// No recorded frame shows the board, so the intrinsics cannot be estimated.
    #[error("no frame of session {} shows the board: there is nothing to estimate the intrinsics from; check that the board is in view, then start a new session", folder.display())]
    NoBoardSeen {
        /// The session folder.
        folder: PathBuf,
    },
    /// A frame image could not be read, decoded or encoded.
    #[error("frame {}", path.display())]
    Frame {
        /// The frame file.
        path: PathBuf,
        /// The image error.
        #[source]
        source: Box<image::ImageError>,
    },
    /// The board file of the solve inputs could not be loaded.
    #[error("loading the board")]
    Board {
        /// The board file.
        file: PathBuf,
        /// Why.
        #[source]
        source: Box<TargetError>,
    },
    /// The intrinsics file could not be loaded or written.
    #[error("reading or writing the intrinsics")]
    Intrinsics {
        /// The intrinsics file.
        file: PathBuf,
        /// Why.
        #[source]
        source: Box<CameraModelError>,
    },
    /// The board detector could not start or failed on a frame.
    #[error("the board detector failed")]
    Detector(#[source] Box<TargetError>),
    /// A detection thread could not start (the message names memory when a limit is the
    /// cause).
    #[error("{0}")]
    DetectionThreadSpawn(String),
    /// The detection thread ended before the run did.
    #[error("the detection thread {0}")]
    DetectionThread(&'static str),
    /// `solver.arm_model` names a file that cannot correct these poses (unreadable, without
    /// an arm model, of another arm, or poses without their joints).
    #[error("{0}")]
    ArmModel(String),
}

impl SessionError {
    /// Whether a memory limit stopped this: a frame or a detector that did not fit, also when
    /// recording the pose is what it stopped.
    pub fn short_of_memory(&self) -> bool {
        match self {
            SessionError::Detector(error) => matches!(**error, TargetError::Memory(_)),
            SessionError::Camera { source, .. } => matches!(source, CameraError::Memory(_)),
            SessionError::RecordFailed { source, .. } => source.short_of_memory(),
            _ => false,
        }
    }
}

/// Creates `dir` and its parents; a failure names it ([`SessionError::Io`]).
pub fn create_dir(dir: &std::path::Path) -> Result<(), SessionError> {
    std::fs::create_dir_all(dir).map_err(|source| SessionError::Io {
        path: dir.to_path_buf(),
        source,
    })
}

/// Makes the folder `file` goes into when it does not exist yet: an answer written with `-o`
/// into a new folder (`handeye solve`, `replay`).
pub fn create_parent_dir(file: &std::path::Path) -> Result<(), SessionError> {
    create_dir(handeye_core::folder_of(file))
}

fn describe_disagreement(missing: &[String], extra: &[String]) -> String {
    let mut parts = Vec::new();
    if !missing.is_empty() {
        parts.push(format!(
            "accepted record(s) without a sample: {}",
            missing.join(", ")
        ));
    }
    if !extra.is_empty() {
        parts.push(format!(
            "sample(s) without an accepted record: {}",
            extra.join(", ")
        ));
    }
    parts.join("; ")
}

/// For a folder a run left before writing `session.yaml` (it has `poses/` or `frames/`): how to
/// start again.
fn not_a_session_hint(root: &std::path::Path) -> String {
    if let Some(at) = handeye_core::yaml_file::symlink_loop(&root.join("session.yaml")) {
        format!(": symlink loop at {}", at.display())
    } else if root.join("rig.yaml").is_file() {
        // A several-camera session: its root holds the cameras' folders, each a one-camera
        // session of the same poses.
        let mut names: Vec<String> = std::fs::read_dir(root.join("cameras"))
            .into_iter()
            .flatten()
            .flatten()
            .filter(|e| e.path().join("session.yaml").is_file())
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .collect();
        names.sort();
        format!(
            "; it is a several-camera session (rig.yaml): `handeye solve` (its records), `replay` (its frames), `report`, `export` and `verify --session` take it whole, and each camera's samples are the one-camera session {} ({})",
            root.join("cameras").join("<name>").display(),
            names.join(", ")
        )
    } else if root.join("poses").is_dir() || root.join("frames").is_dir() {
        format!(
            "; a run stopped before it wrote session.yaml recorded nothing: start it again with `handeye run --config <cell.yaml> --output {}`",
            root.display()
        )
    } else {
        String::new()
    }
}
