//! The console's wire vocabulary: the typed events a run publishes (serialised as JSON with a
//! `type` tag) and the commands a page sends back (JSON with a `cmd` tag). Millimetres and
//! degrees here: these are for people to read.

use serde::{Deserialize, Serialize};

use handeye_core::geometry::{rotvec, Pose};
use handeye_robot::Joints;

/// A pose as the page shows it: translation in mm, rotation vector in degrees.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct PoseView {
    /// Translation, mm.
    pub translation_mm: [f64; 3],
    /// Axis-angle rotation vector, degrees.
    pub rotation_vector_deg: [f64; 3],
}

impl PoseView {
    /// The view of `pose`.
    pub fn of(pose: &Pose) -> PoseView {
        let t = pose.translation.vector * 1000.0;
        let r = rotvec(&pose.rotation).map(f64::to_degrees);
        PoseView {
            translation_mm: [t.x, t.y, t.z],
            rotation_vector_deg: [r.x, r.y, r.z],
        }
    }
}

/// Joints in degrees, for the page.
pub fn joints_deg(joints: &Joints) -> Vec<f64> {
    joints.iter().map(|q| q.to_degrees()).collect()
}

/// Where a plan pose stands.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum PoseState {
    /// Not visited yet.
    Pending,
    /// The arm is on its way there.
    Moving,
    /// A sample was recorded and accepted.
    Captured,
    /// Rejected; a retry follows.
    Retry,
    /// Rejected for good.
    Rejected,
}

impl PoseState {
    /// The state a visit ended in: accepted, or rejected with or without a retry to follow.
    pub fn visited(rejected: bool, will_retry: bool) -> PoseState {
        match (rejected, will_retry) {
            (false, _) => PoseState::Captured,
            (true, true) => PoseState::Retry,
            (true, false) => PoseState::Rejected,
        }
    }
}

/// One plan pose, for the plan table.
#[derive(Debug, Clone, Serialize)]
pub struct PlannedView {
    /// Plan index.
    pub index: usize,
    /// Target flange pose `T_base_flange`.
    pub flange: PoseView,
    /// The joints that reach it, degrees.
    pub joints_deg: Vec<f64>,
}

/// 1-sigma of both unknowns.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct SigmaView {
    /// Camera mount, mm.
    pub camera_mount_mm: f64,
    /// Camera mount, degrees.
    pub camera_mount_deg: f64,
    /// Target mount, mm.
    pub target_mount_mm: f64,
    /// Target mount, degrees.
    pub target_mount_deg: f64,
}

/// Something the page shows.
#[derive(Debug, Clone, Serialize)]
#[serde(tag = "type", rename_all = "snake_case")]
pub enum ConsoleEvent {
    /// The cell: what is calibrated and how.
    Cell {
        /// The config file.
        config: String,
        /// `eye_in_hand` or `eye_to_hand`.
        setup: String,
        /// The two unknowns' names (`T_flange_camera`, `T_base_target`, ...).
        unknowns: [String; 2],
        /// Simulated arm (nothing real moves).
        simulated: bool,
        /// Hand-guided capture instead of a plan.
        manual: bool,
        /// The camera image size, px.
        image: [u32; 2],
        /// A cell with several cameras: their names, in config order (the first-named of
        /// `unknowns` is the planner camera's); empty for one camera.
        #[serde(skip_serializing_if = "Vec::is_empty")]
        cameras: Vec<String>,
    },
    /// The plan (for a manual session: the views the suggestions come from).
    Plan {
        /// Its poses.
        poses: Vec<PlannedView>,
    },
    /// The session folder.
    Session {
        /// Its path.
        folder: String,
    },
    /// Something a person should know.
    Note {
        /// The message.
        message: String,
    },
    /// A real arm is about to move: the page asks for confirmation.
    ConfirmMotion {
        /// Poses (1 for a single move).
        poses: usize,
        /// Speed cap, m/s.
        linear_speed: f64,
        /// Joint speed cap, °/s.
        joint_speed_deg: f64,
    },
    /// Motion was confirmed (on the page or the terminal).
    Confirmed,
    /// The session loop started.
    Started {
        /// Poses at most.
        poses: usize,
    },
    /// The arm moves to a plan pose.
    Moving {
        /// Plan index.
        plan_index: usize,
        /// The joints it moves to, degrees.
        joints_deg: Option<Vec<f64>>,
    },
    /// A pose was processed.
    Pose {
        /// Plan index.
        plan_index: usize,
        /// Its state now.
        state: PoseState,
        /// Why it was rejected.
        why: Option<String>,
        /// Board reprojection RMS, px.
        rms_px: Option<f64>,
        /// Tags used.
        tags: usize,
    },
    /// One camera's record of a pose, in a cell with several cameras (every camera's, the
    /// planner camera's too; `Pose` and the running estimate stay the planner camera's).
    CameraPose {
        /// The camera.
        camera: String,
        /// Plan index.
        plan_index: usize,
        /// Accepted or rejected (no retry for the others: they grab whenever the arm is there).
        state: PoseState,
        /// Why it was rejected.
        why: Option<String>,
        /// Board reprojection RMS, px.
        rms_px: Option<f64>,
        /// Tags used.
        tags: usize,
    },
    /// A camera of a several-camera cell stopped delivering frames; the others go on.
    CameraLost {
        /// The camera.
        camera: String,
        /// The plan pose of its failed grab.
        plan_index: usize,
        /// The camera's error.
        error: String,
    },
    /// The running estimate after an accepted pose (pose space, from the samples so far).
    Estimate {
        /// Samples it is solved from.
        samples: usize,
        /// The camera mount.
        camera_mount: PoseView,
        /// The target mount.
        target_mount: PoseView,
        /// 1-sigma, when the solver gives it.
        sigma: Option<SigmaView>,
    },
    /// What the accepted samples cover.
    Coverage {
        /// Board corners seen per cell of a 4x4 grid over the image, row-major from the top left.
        cells: [u32; 16],
        /// Unit axes of the relative rotations between accepted flange poses (base frame).
        axes: Vec<[f64; 3]>,
        /// Nearest and farthest board distance from the camera, m.
        distance_m: Option<[f64; 2]>,
    },
    /// Where the arm stands (manual sessions).
    Arm {
        /// Joints, degrees.
        joints_deg: Vec<f64>,
        /// `T_base_flange`.
        flange: PoseView,
        /// Freedrive (teach mode) is on.
        freedrive: bool,
    },
    /// The next view that helps most (manual sessions).
    Suggestion {
        /// The flange pose to go to, `T_base_flange`.
        flange: PoseView,
        /// The joints that reach it, degrees.
        joints_deg: Vec<f64>,
        /// Where the board centre would appear in the image at the current estimate, px.
        board_px: Option<[f64; 2]>,
        /// The rotation axis it adds (unit, base frame), relative to the nearest accepted pose.
        axis: Option<[f64; 3]>,
        /// Predicted worst translation 1-sigma after it, mm.
        predicted_sigma_mm: Option<f64>,
    },
    /// A capture's immediate check (manual sessions).
    Check {
        /// Whether the capture went ahead.
        ok: bool,
        /// What was found.
        message: String,
    },
    /// The session loop ended.
    Ended,
    /// The run's end: verdict and where the report is.
    Finished {
        /// `GOOD`, `CHECK` or `REDO`.
        verdict: Option<String>,
        /// The result summary.
        summary: String,
        /// What to do next.
        next: String,
        /// Whether `/report` serves the report.
        report: bool,
    },
    /// The run failed.
    Failed {
        /// The error, with its causes.
        message: String,
    },
}

impl ConsoleEvent {
    /// For an event that states the whole of something (the estimate, the coverage, where the
    /// arm stands, the suggestion), its kind: a newer one makes the older one worthless.
    pub fn snapshot(&self) -> Option<&'static str> {
        match self {
            ConsoleEvent::Estimate { .. } => Some("estimate"),
            ConsoleEvent::Coverage { .. } => Some("coverage"),
            ConsoleEvent::Arm { .. } => Some("arm"),
            ConsoleEvent::Suggestion { .. } => Some("suggestion"),
            ConsoleEvent::Moving { .. } => Some("moving"),
            _ => None,
        }
    }
}

/// What a page asks for.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(tag = "cmd", rename_all = "snake_case")]
pub enum Command {
    /// Stop the arm and end the run, keeping every sample (Ctrl-C's path).
    Stop,
    /// Confirm motion of a real arm.
    Confirm,
    /// Refuse motion.
    Decline,
    /// Take a sample where the arm stands (manual sessions).
    Capture,
    /// Switch freedrive on or off (manual sessions).
    Freedrive {
        /// On or off.
        on: bool,
    },
    /// Move the arm to the suggested view (manual sessions).
    GoToSuggestion,
    /// End a manual session and solve.
    Finish,
}
