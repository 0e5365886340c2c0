//! The arm backends of a cell config (`robot: {backend: ...}`), each described once: its
//! section's keys (a struct), and what the rest of handeye asks of any arm ([`RobotBackend`]):
//! its name, the model it is planned with, the joint ranges given and the defaults in force, how
//! far its reported poses may be off, the frames they are in, whether it moves, whether each
//! pose's joints are known, the files it names, and its section's checks. [`RobotConfig`] holds one of them and
//! answers through [`RobotConfig::backend`]; nothing else matches on the backend to learn these.
//!
//! A new arm is its section struct and its `RobotBackend` impl (here, or in a module of its own
//! as `ros2.rs` is), a variant of [`RobotConfig`] and its line in [`RobotConfig::backend`], its
//! opener in `handeye_session::cell` (`open_arm`), and a mock to test against.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::schema::{ArmModel, RobotConfig, FLANGE_CAMERA_JOINT_RANGES_DEG};
use super::validate::{
    Validator, CONNECT_TIMEOUT_S, MOVE_DURATION_S, PROTECTIVE_STOP_AFTER_MOVES, RINGING_DECAY_S,
    RINGING_DEG, RINGING_HZ, SIM_REPEATABILITY_DEG, SIM_REPEATABILITY_MM, START_JOINT_DEG,
};
use super::ConfigError;
use handeye_core::setup::{RobotFrames, Setup};

/// What handeye asks of an arm backend, whichever it is.
pub trait RobotBackend {
    /// Its `backend:` name (`sim`, `ur`, `recorded`, `ros2`).
    fn name(&self) -> &'static str;
    /// The arm model its poses are planned with; `None` for an arm of no model handeye knows
    /// (it replays taught joints).
    fn model(&self) -> Option<ArmModel>;
    /// The config's `joint_ranges_deg`, when given.
    fn given_joint_ranges_deg(&self) -> Option<&[[f64; 2]]> {
        None
    }
    /// A real arm, whose camera cable on the flange bounds the joints of an eye-in-hand cell
    /// when no ranges are given ([`FLANGE_CAMERA_JOINT_RANGES_DEG`]).
    fn has_flange_cable(&self) -> bool {
        false
    }
    /// The 1-sigma of its reported flange pose (mm, degrees), the default filled in.
    fn repeatability(&self) -> (f64, f64);
    /// The frames its flange poses are read in (the UR controller's `base` and `tool0` unless
    /// it says otherwise).
    fn frames(&self) -> RobotFrames {
        RobotFrames::default()
    }
    /// It is the simulated arm (the cell then needs its ground truth).
    fn simulated(&self) -> bool {
        false
    }
    /// It moves (a recorded arm replays poses measured elsewhere: nothing moves, its poses are
    /// the plan).
    fn moves(&self) -> bool {
        true
    }
    /// Each pose's joints are known, so the arm's own model can be estimated or applied.
    fn reports_joints(&self) -> bool {
        true
    }
    /// Where a simulated arm starts, degrees (it is checked against the ranges in force).
    fn start_joints_deg(&self) -> Option<[f64; 6]> {
        None
    }
    /// The files its section names (role, path), which a session records with their hashes.
    fn input_files(&self) -> Vec<(&'static str, PathBuf)> {
        Vec::new()
    }
    /// Its paths made relative to the config's folder (`resolve`), as the config is read.
    fn resolve_paths(&mut self, _resolve: &dyn Fn(&Path) -> PathBuf) {}
    /// Its section's own checks (`robot.*`): every number in its range, every name valid.
    fn check(&self, v: &Validator<'_>) -> Result<(), ConfigError>;
}

impl RobotConfig {
    /// The backend the config names.
    pub fn backend(&self) -> &dyn RobotBackend {
        match self {
            RobotConfig::Sim(sim) => sim,
            RobotConfig::Ur(ur) => ur,
            RobotConfig::Recorded(recorded) => recorded,
            RobotConfig::Ros2(ros2) => ros2.as_ref(),
        }
    }

    /// The backend the config names, to change.
    pub fn backend_mut(&mut self) -> &mut dyn RobotBackend {
        match self {
            RobotConfig::Sim(sim) => sim,
            RobotConfig::Ur(ur) => ur,
            RobotConfig::Recorded(recorded) => recorded,
            RobotConfig::Ros2(ros2) => ros2.as_mut(),
        }
    }

    /// The joint ranges in force, `[min, max]` degrees, base joint first: the config's
    /// `joint_ranges_deg` when given; otherwise [`FLANGE_CAMERA_JOINT_RANGES_DEG`] for a real
    /// arm carrying the camera (`setup: eye_in_hand`), and the arm's own
    /// [`ARM_JOINT_RANGES_DEG`](super::schema::ARM_JOINT_RANGES_DEG) for everything else
    /// (eye-to-hand has no cable on the flange; the simulator has no cable at all).
    pub fn joint_ranges_deg(&self, setup: Setup) -> Vec<[f64; 2]> {
        let backend = self.backend();
        match backend.given_joint_ranges_deg() {
            Some(ranges) => ranges.to_vec(),
            None if backend.has_flange_cable() && setup == Setup::EyeInHand => {
                FLANGE_CAMERA_JOINT_RANGES_DEG.to_vec()
            }
            None => super::schema::ARM_JOINT_RANGES_DEG.to_vec(),
        }
    }

    /// [`RobotConfig::joint_ranges_deg`] in radians, as `UrModel::joint_limits` takes them.
    pub fn joint_limits(&self, setup: Setup) -> Vec<(f64, f64)> {
        self.joint_ranges_deg(setup)
            .into_iter()
            .map(|[lo, hi]| (lo.to_radians(), hi.to_radians()))
            .collect()
    }

    /// The frames the arm's flange poses are read in.
    pub fn frames(&self) -> RobotFrames {
        self.backend().frames()
    }

    /// The arm model name, for kinematics checks; `None` for a ROS 2 arm of no model handeye
    /// knows (`model: none`).
    pub fn model(&self) -> Option<&'static str> {
        self.backend().model().map(ArmModel::name)
    }
}

/// `robot: {backend: sim}`: the simulated UR arm.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SimRobot {
    /// The arm model (`ur5e` by default; see [`ArmModel`]).
    #[serde(default)]
    pub model: ArmModel,
    /// Where the arm starts, degrees.
    #[serde(default = "default_start_joints_deg")]
    pub start_joints_deg: [f64; 6],
    /// Allowed range of each joint, `[min, max]` degrees, base to wrist 3 (narrower than the
    /// arm's own limits: keeps a cable from winding, the arm from swinging through the cell).
    /// Absent: see [`RobotConfig::joint_ranges_deg`].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub joint_ranges_deg: Option<[[f64; 2]; 6]>,
    /// Time each move takes, s (0 = instant); ignored with `move_at_limits`.
    #[serde(default)]
    pub move_duration_s: f64,
    /// Moves take the time a UR `moveJ` takes at the configured joint limits (trapezoidal
    /// profile) instead of `move_duration_s`.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub move_at_limits: bool,
    /// After each move the arm rings down: a joint oscillation of this amplitude (leading
    /// joint), degrees, decaying with `ringing_decay_s` (0 = the arm stops dead).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub ringing_deg: f64,
    /// Ringing frequency, Hz.
    #[serde(default = "default_ringing_hz")]
    pub ringing_hz: f64,
    /// Ringing decay time constant, s.
    #[serde(default = "default_ringing_decay_s")]
    pub ringing_decay_s: f64,
    /// 1-sigma position noise on the reported flange pose, mm.
    #[serde(default)]
    pub repeatability_mm: f64,
    /// 1-sigma rotation noise on the reported flange pose, degrees.
    #[serde(default)]
    pub repeatability_deg: f64,
    /// Raise a protective stop after this many moves (fault injection for tests).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub protective_stop_after_moves: Option<usize>,
    /// Noise seed.
    #[serde(default)]
    pub seed: u64,
}

impl RobotBackend for SimRobot {
    fn name(&self) -> &'static str {
        "sim"
    }

    fn model(&self) -> Option<ArmModel> {
        Some(self.model)
    }

    fn given_joint_ranges_deg(&self) -> Option<&[[f64; 2]]> {
        self.joint_ranges_deg.as_ref().map(|r| &r[..])
    }

    fn simulated(&self) -> bool {
        true
    }

    fn repeatability(&self) -> (f64, f64) {
        if self.repeatability_mm > 0.0 && self.repeatability_deg > 0.0 {
            (self.repeatability_mm, self.repeatability_deg)
        } else {
            // A noiseless simulated arm: the solve still needs a scale for its poses.
            (0.01, 0.001)
        }
    }

    fn start_joints_deg(&self) -> Option<[f64; 6]> {
        Some(self.start_joints_deg)
    }

    fn check(&self, v: &Validator<'_>) -> Result<(), ConfigError> {
        for (i, q) in self.start_joints_deg.iter().enumerate() {
            v.number(&format!("robot.start_joints_deg[{i}]"), *q, START_JOINT_DEG)?;
        }
        v.number(
            "robot.move_duration_s",
            self.move_duration_s,
            MOVE_DURATION_S,
        )?;
        v.number("robot.ringing_deg", self.ringing_deg, RINGING_DEG)?;
        v.number("robot.ringing_hz", self.ringing_hz, RINGING_HZ)?;
        v.number(
            "robot.ringing_decay_s",
            self.ringing_decay_s,
            RINGING_DECAY_S,
        )?;
        v.number(
            "robot.repeatability_mm",
            self.repeatability_mm,
            SIM_REPEATABILITY_MM,
        )?;
        v.number(
            "robot.repeatability_deg",
            self.repeatability_deg,
            SIM_REPEATABILITY_DEG,
        )?;
        if let Some(n) = self.protective_stop_after_moves {
            v.integer(
                "robot.protective_stop_after_moves",
                n as i128,
                PROTECTIVE_STOP_AFTER_MOVES,
            )?;
        }
        Ok(())
    }
}

/// `robot: {backend: ur}`: a Universal Robots controller through ur_rtde (needs the `ur-rtde`
/// feature).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct UrRobot {
    /// Controller address.
    pub host: String,
    /// The arm model (`ur5e` by default; see [`ArmModel`]): used to check reachability before
    /// moving.
    #[serde(default)]
    pub model: ArmModel,
    /// Allowed range of each joint, `[min, max]` degrees, base to wrist 3 (narrower than the
    /// arm's own limits: keeps a cable from winding, the arm from swinging through the cell).
    /// Absent: see [`RobotConfig::joint_ranges_deg`].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub joint_ranges_deg: Option<[[f64; 2]; 6]>,
    /// Give up connecting after this long, s.
    #[serde(default = "default_connect_timeout_s")]
    pub connect_timeout_s: f64,
    /// How far the reported flange pose may be from the true one, 1-sigma per axis, mm
    /// (default 0.03: the UR e-Series repeatability; the reprojection solve starts from it
    /// and estimates the real figure from the residuals).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub repeatability_mm: Option<f64>,
    /// The same for rotation, degrees (default 0.003).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub repeatability_deg: Option<f64>,
}

impl RobotBackend for UrRobot {
    fn name(&self) -> &'static str {
        "ur"
    }

    fn model(&self) -> Option<ArmModel> {
        Some(self.model)
    }

    fn given_joint_ranges_deg(&self) -> Option<&[[f64; 2]]> {
        self.joint_ranges_deg.as_ref().map(|r| &r[..])
    }

    fn has_flange_cable(&self) -> bool {
        true
    }

    fn repeatability(&self) -> (f64, f64) {
        (
            self.repeatability_mm.unwrap_or(0.03),
            self.repeatability_deg.unwrap_or(0.003),
        )
    }

    fn check(&self, v: &Validator<'_>) -> Result<(), ConfigError> {
        if self.host.trim().is_empty() {
            return Err(v.inconsistent(
                "robot.host",
                "expected the controller's IP address or host name, found an empty string".into(),
            ));
        }
        v.number(
            "robot.connect_timeout_s",
            self.connect_timeout_s,
            CONNECT_TIMEOUT_S,
        )?;
        v.repeatability(self.repeatability_mm, self.repeatability_deg)
    }
}

/// `robot: {backend: recorded}`: replays the flange poses a real arm measured during a recording
/// made elsewhere (`robot::recorded`); used with the image-folder camera. The recorded poses are
/// the plan, so the config has no `plan` source, and nothing moves.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RecordedRobot {
    /// The recorded-poses file (`T_base_flange: [pose, ...]`, frame order).
    pub poses: PathBuf,
    /// How far a recorded flange pose may be from the true one, 1-sigma per axis, mm
    /// (default 0.1: an arm of unknown make; the reprojection solve starts from it and
    /// estimates the real figure from the residuals).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub repeatability_mm: Option<f64>,
    /// The same for rotation, degrees (default 0.01).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub repeatability_deg: Option<f64>,
    /// The frames the recorded poses are in (a bag's `--base` and `--flange`); default the
    /// UR controller's `base` and `tool0`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub frames: Option<RobotFrames>,
}

impl RobotBackend for RecordedRobot {
    fn name(&self) -> &'static str {
        "recorded"
    }

    fn model(&self) -> Option<ArmModel> {
        // A recorded arm is never planned with kinematics; any valid model will do.
        Some(ArmModel::default())
    }

    fn repeatability(&self) -> (f64, f64) {
        (
            self.repeatability_mm.unwrap_or(0.1),
            self.repeatability_deg.unwrap_or(0.01),
        )
    }

    fn frames(&self) -> RobotFrames {
        self.frames.clone().unwrap_or_default()
    }

    fn moves(&self) -> bool {
        false
    }

    fn input_files(&self) -> Vec<(&'static str, PathBuf)> {
        vec![("robot.poses", self.poses.clone())]
    }

    fn resolve_paths(&mut self, resolve: &dyn Fn(&Path) -> PathBuf) {
        self.poses = resolve(&self.poses);
    }

    fn reports_joints(&self) -> bool {
        false
    }

    fn check(&self, v: &Validator<'_>) -> Result<(), ConfigError> {
        v.repeatability(self.repeatability_mm, self.repeatability_deg)?;
        if let Some((key, problem)) = self.frames.as_ref().and_then(|f| {
            super::ros2::frame_problem("robot.frames.base", &f.base)
                .or_else(|| super::ros2::frame_problem("robot.frames.flange", &f.flange))
        }) {
            return Err(v.inconsistent(&key, problem));
        }
        Ok(())
    }
}

fn is_zero(v: &f64) -> bool {
    *v == 0.0
}
fn default_ringing_hz() -> f64 {
    8.0
}
fn default_ringing_decay_s() -> f64 {
    0.15
}
pub(super) fn default_start_joints_deg() -> [f64; 6] {
    [0.0, -90.0, 90.0, -90.0, -90.0, 0.0]
}
fn default_connect_timeout_s() -> f64 {
    5.0
}
