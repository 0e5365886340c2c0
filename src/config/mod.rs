//! The cell config: one YAML file that says what the cell is (setup, robot, camera, board), what is
//! roughly known about it, how to move, and how to solve. Read and validated completely before
//! anything moves; every error names the file, the key and what was expected.
//!
//! Relative paths inside the file are relative to the file's folder. Units are SI with the suffix
//! in the key where a person reads (`_deg`, `_mm`, `_s`).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Duration;

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use crate::geometry::{PoseError, PoseYaml};
use crate::plan::GenerateSpec;
use crate::robot::{MotionLimits, WorkspaceBox};
use crate::setup::CellTransforms;
use crate::setup::Setup;
use crate::solve::{Method, NoiseModel, SolveOptions};
use crate::yaml_file::{parse_yaml, read_text, FileError};

/// Ceilings on the configurable motion limits: calibration moves near people never need more.
pub const MAX_LINEAR_SPEED: f64 = 0.5;
/// Ceiling on linear acceleration, m/s².
pub const MAX_LINEAR_ACCELERATION: f64 = 2.0;
/// Ceiling on joint speed, °/s.
pub const MAX_JOINT_SPEED_DEG: f64 = 90.0;
/// Ceiling on joint acceleration, °/s².
pub const MAX_JOINT_ACCELERATION_DEG: f64 = 180.0;

/// A config problem: the file, the key (YAML path) and what was expected.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// The file could not be read, or its YAML does not have the config's shape (unknown or
    /// missing key, wrong type): the message names the file and the YAML path.
    #[error(transparent)]
    File(#[from] FileError),
    /// A value is out of range or inconsistent.
    #[error("{file}: {key}: {problem}")]
    Value {
        /// The config file.
        file: PathBuf,
        /// The key.
        key: String,
        /// What was expected.
        problem: String,
    },
    /// A pose is malformed.
    #[error("{file}: {source}")]
    Pose {
        /// The config file.
        file: PathBuf,
        /// The pose problem with its YAML path.
        #[source]
        source: PoseError,
    },
}

/// Which arm drives the cell.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "backend", rename_all = "snake_case", deny_unknown_fields)]
pub enum RobotConfig {
    /// The simulated UR arm.
    Sim {
        /// `ur5e` or `ur10e`.
        #[serde(default = "default_model")]
        model: String,
        /// Where the arm starts, degrees.
        #[serde(default = "default_start_joints_deg")]
        start_joints_deg: [f64; 6],
        /// Time each move takes, s (0 = instant).
        #[serde(default)]
        move_duration_s: f64,
        /// 1-sigma position noise on the reported flange pose, mm.
        #[serde(default)]
        repeatability_mm: f64,
        /// 1-sigma rotation noise on the reported flange pose, degrees.
        #[serde(default)]
        repeatability_deg: f64,
        /// Raise a protective stop after this many moves (fault injection for tests).
        #[serde(default)]
        protective_stop_after_moves: Option<usize>,
        /// Noise seed.
        #[serde(default)]
        seed: u64,
    },
    /// A Universal Robots controller through ur_rtde (needs the `ur-rtde` feature).
    Ur {
        /// Controller address.
        host: String,
        /// `ur5e` or `ur10e`: used to check reachability before moving.
        #[serde(default = "default_model")]
        model: String,
        /// Give up connecting after this long, s.
        #[serde(default = "default_connect_timeout_s")]
        connect_timeout_s: f64,
        /// How far the reported flange pose may be from the true one, 1-sigma per axis, mm
        /// (default 0.03: the UR e-Series repeatability; the reprojection solve starts from it
        /// and estimates the real figure from the residuals).
        #[serde(default)]
        repeatability_mm: Option<f64>,
        /// The same for rotation, degrees (default 0.003).
        #[serde(default)]
        repeatability_deg: Option<f64>,
    },
    /// Replays the flange poses a real arm measured during a recording made elsewhere
    /// (`robot::recorded`); used with the image-folder camera. The recorded poses are the plan, so
    /// the config has no `plan` source, and nothing moves.
    Recorded {
        /// The recorded-poses file (`T_base_flange: [pose, ...]`, frame order).
        poses: PathBuf,
        /// How far a recorded flange pose may be from the true one, 1-sigma per axis, mm
        /// (default 0.1: an arm of unknown make; the reprojection solve starts from it and
        /// estimates the real figure from the residuals).
        #[serde(default)]
        repeatability_mm: Option<f64>,
        /// The same for rotation, degrees (default 0.01).
        #[serde(default)]
        repeatability_deg: Option<f64>,
    },
}

fn default_model() -> String {
    "ur5e".into()
}
fn default_start_joints_deg() -> [f64; 6] {
    [0.0, -90.0, 90.0, -90.0, -90.0, 0.0]
}

/// The joints a plan assumes the arm starts from when the config gives none (UR's upright
/// "home" with the tool pointing down), radians.
pub fn default_start_joints() -> [f64; 6] {
    default_start_joints_deg().map(f64::to_radians)
}
fn default_connect_timeout_s() -> f64 {
    5.0
}

impl RobotConfig {
    /// The arm model name, for kinematics checks.
    pub fn model(&self) -> &str {
        match self {
            RobotConfig::Sim { model, .. } | RobotConfig::Ur { model, .. } => model,
            // A recorded arm is never planned with kinematics; any valid name will do.
            RobotConfig::Recorded { .. } => "ur5e",
        }
    }
}

/// Which camera takes the frames.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "backend", rename_all = "snake_case", deny_unknown_fields)]
pub enum CameraConfig {
    /// Frames rendered from the simulated cell's true chain.
    Sim {
        /// Sensor noise, grey levels (1-sigma).
        #[serde(default = "default_noise")]
        noise_sigma: f64,
        /// Optical blur, pixels (1-sigma of a Gaussian), 0 = none.
        #[serde(default)]
        blur_sigma_px: f64,
        /// Render seed.
        #[serde(default)]
        seed: u64,
        /// Grab numbers (0-based) in which the board is hidden (fault injection for tests).
        #[serde(default)]
        hide_board_in_grabs: Vec<usize>,
        /// The simulated lens (camera_info YAML); defaults to the cell's `intrinsics`. Required
        /// when the cell has no `intrinsics` (they are then estimated from the run).
        #[serde(default)]
        intrinsics: Option<PathBuf>,
    },
    /// Frames from an image folder, in plan order.
    Files {
        /// The folder.
        folder: PathBuf,
    },
    /// A USB/UVC camera (needs the `uvc` build feature).
    Uvc {
        /// Camera index (`/dev/video<N>`) or (part of) its name.
        #[serde(default = "default_uvc_device")]
        device: String,
        /// Requested width, px.
        #[serde(default = "default_uvc_width")]
        width: u32,
        /// Requested height, px.
        #[serde(default = "default_uvc_height")]
        height: u32,
        /// Requested pixel format: `mjpeg`, `yuyv` or `gray`.
        #[serde(default = "default_uvc_pixel_format")]
        pixel_format: String,
        /// Requested frame rate, frames/s.
        #[serde(default = "default_uvc_fps")]
        fps: u32,
        /// Fixed exposure, µs (auto exposure off).
        #[serde(default)]
        exposure_us: Option<u32>,
        /// Fixed gain, camera units (auto gain off).
        #[serde(default)]
        gain: Option<i64>,
        /// Fixed focus, camera units (autofocus is turned off whenever the camera allows).
        #[serde(default)]
        focus: Option<i64>,
        /// Frames dropped after the arm settles (the driver's queue depth).
        #[serde(default = "default_uvc_stale_frames")]
        stale_frames: usize,
    },
}

fn default_uvc_device() -> String {
    "0".into()
}
fn default_uvc_width() -> u32 {
    1280
}
fn default_uvc_height() -> u32 {
    720
}
fn default_uvc_pixel_format() -> String {
    "mjpeg".into()
}
fn default_uvc_fps() -> u32 {
    30
}
fn default_uvc_stale_frames() -> usize {
    4
}

fn default_noise() -> f64 {
    2.0
}

/// Motion limits as written (degrees for joints).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LimitsConfig {
    /// m/s.
    pub linear_speed: f64,
    /// m/s².
    pub linear_acceleration: f64,
    /// °/s.
    pub joint_speed_deg: f64,
    /// °/s².
    pub joint_acceleration_deg: f64,
}

impl Default for LimitsConfig {
    fn default() -> Self {
        let l = MotionLimits::default();
        LimitsConfig {
            linear_speed: l.linear_speed,
            linear_acceleration: l.linear_acceleration,
            joint_speed_deg: l.joint_speed.to_degrees(),
            joint_acceleration_deg: l.joint_acceleration.to_degrees(),
        }
    }
}

/// The workspace box as written, m.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WorkspaceConfig {
    /// Lower corner, m.
    pub min: [f64; 3],
    /// Upper corner, m.
    pub max: [f64; 3],
}

/// Where the plan comes from.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlanConfig {
    /// A scripted plan file.
    #[serde(default)]
    pub file: Option<PathBuf>,
    /// Generate views on a cap around the board.
    #[serde(default)]
    pub generate: Option<GenerateSpec>,
    /// Choose poses one at a time (next-best pose) from the plan's poses as candidates, and
    /// stop when the solved uncertainty reaches `target_uncertainty_mm`.
    #[serde(default)]
    pub adaptive: bool,
    /// Adaptive stop rule: the larger translation 1-sigma of the two unknowns, mm.
    #[serde(default = "default_target_uncertainty_mm")]
    pub target_uncertainty_mm: f64,
}

fn default_target_uncertainty_mm() -> f64 {
    0.5
}

impl Default for PlanConfig {
    /// No plan source (a recorded robot's poses are its plan), not adaptive.
    fn default() -> Self {
        PlanConfig {
            file: None,
            generate: None,
            adaptive: false,
            target_uncertainty_mm: default_target_uncertainty_mm(),
        }
    }
}

/// Detector settings.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DetectorConfig {
    /// Image decimation before quad detection (1 = full resolution).
    #[serde(default = "default_decimate")]
    pub decimate: f32,
    /// Detector threads.
    #[serde(default = "default_threads")]
    pub threads: u8,
    /// Largest accepted number of corrected bits.
    #[serde(default)]
    pub max_hamming: u32,
}

fn default_decimate() -> f32 {
    2.0
}
fn default_threads() -> u8 {
    2
}

impl Default for DetectorConfig {
    fn default() -> Self {
        DetectorConfig {
            decimate: default_decimate(),
            threads: default_threads(),
            max_hamming: 0,
        }
    }
}

/// Solver settings.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SolverConfig {
    /// `refined` (default), `iterative` or `closed-form`.
    #[serde(default = "default_method")]
    pub method: String,
    /// Expected rotation noise of a board pose, degrees (1-sigma).
    #[serde(default = "default_rotation_sigma_deg")]
    pub rotation_sigma_deg: f64,
    /// Expected translation noise of a board pose, mm (1-sigma).
    #[serde(default = "default_translation_sigma_mm")]
    pub translation_sigma_mm: f64,
    /// Drop flagged outliers and solve again.
    #[serde(default = "yes")]
    pub drop_outliers: bool,
    /// `reprojection` (default: refine over every detected corner when frames have corners) or
    /// `pose` (the pose-space answer only).
    #[serde(default)]
    pub space: SolveSpace,
    /// 1-sigma corner detection noise for the reprojection refinement, px.
    #[serde(default = "default_pixel_sigma_px")]
    pub pixel_sigma_px: f64,
    /// Also fit a small correction of every robot pose, held by the robot's repeatability
    /// (default on: with sub-pixel corners a frame's many corners see a 0.002° robot error, so
    /// treating robot poses as exact over-trusts them).
    #[serde(default = "yes")]
    pub robot_corrections: bool,
    /// Estimate the corner noise and the robot's repeatability from the reprojection residuals
    /// (variance component estimation), starting from `pixel_sigma_px` and the robot's
    /// `repeatability_*`; `false` weights with those values as given.
    #[serde(default = "yes")]
    pub estimate_noise: bool,
}

/// Where the final answer is fitted.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SolveSpace {
    /// Pose space: one `T_camera_target` per frame, the `A = X·B·Y` solver (also the start of
    /// the reprojection refinement, and the only answer when no frame has recorded corners).
    Pose,
    /// Reprojection space, the default: every detected corner, started from the pose-space
    /// answer, with the corner noise and the robot's repeatability estimated from the residuals
    /// (`estimate_noise`). In the rendered simulated cell it is closer to the truth than the
    /// pose-space answer on the same frames (0.88x the translation error, 0.82x the rotation
    /// error over 16 seeds, robot repeatability dominating; 0.50x / 0.63x with pixel noise dominating).
    /// Always used when the intrinsics are estimated by the run.
    #[default]
    Reprojection,
}

impl SolveSpace {
    /// The YAML / CLI name.
    pub fn name(self) -> &'static str {
        match self {
            SolveSpace::Pose => "pose",
            SolveSpace::Reprojection => "reprojection",
        }
    }
}

fn default_pixel_sigma_px() -> f64 {
    0.3
}

fn default_method() -> String {
    "refined".into()
}
fn default_rotation_sigma_deg() -> f64 {
    0.05
}
fn default_translation_sigma_mm() -> f64 {
    0.3
}
fn yes() -> bool {
    true
}

impl SolverConfig {
    /// The solver options these settings mean.
    pub fn to_options(&self) -> SolveOptions {
        SolveOptions {
            method: match self.method.as_str() {
                "iterative" => Method::Iterative,
                "closed-form" => Method::ClosedForm,
                _ => Method::Refined,
            },
            noise: NoiseModel {
                rotation_sigma_rad: self.rotation_sigma_deg.to_radians(),
                translation_sigma_m: self.translation_sigma_mm * 1e-3,
            },
            drop_outliers: self.drop_outliers,
            ..SolveOptions::default()
        }
    }
}

impl Default for SolverConfig {
    fn default() -> Self {
        SolverConfig {
            method: default_method(),
            rotation_sigma_deg: default_rotation_sigma_deg(),
            translation_sigma_mm: default_translation_sigma_mm(),
            drop_outliers: true,
            space: SolveSpace::default(),
            pixel_sigma_px: default_pixel_sigma_px(),
            robot_corrections: true,
            estimate_noise: true,
        }
    }
}

/// Session settings.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SessionConfig {
    /// Wait after the arm stops before grabbing, s (lets vibrations die down).
    #[serde(default = "default_settle_s")]
    pub settle_s: f64,
    /// Largest accepted board reprojection RMS, px; a worse frame is retried, then skipped.
    #[serde(default = "default_max_rms_px")]
    pub max_reprojection_rms_px: f64,
    /// Margin kept between the board and the image border when checking a plan, px.
    #[serde(default = "default_margin_px")]
    pub image_margin_px: f64,
}

fn default_settle_s() -> f64 {
    0.2
}
fn default_max_rms_px() -> f64 {
    1.0
}
fn default_margin_px() -> f64 {
    20.0
}

impl Default for SessionConfig {
    fn default() -> Self {
        SessionConfig {
            settle_s: default_settle_s(),
            max_reprojection_rms_px: default_max_rms_px(),
            image_margin_px: default_margin_px(),
        }
    }
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawConfig {
    setup: Setup,
    target: PathBuf,
    #[serde(default)]
    intrinsics: Option<PathBuf>,
    robot: RobotConfig,
    camera: CameraConfig,
    nominal: BTreeMap<String, PoseYaml>,
    #[serde(default)]
    simulation: Option<BTreeMap<String, PoseYaml>>,
    #[serde(default)]
    plan: PlanConfig,
    #[serde(default)]
    limits: LimitsConfig,
    workspace: WorkspaceConfig,
    #[serde(default)]
    detector: DetectorConfig,
    #[serde(default)]
    solver: SolverConfig,
    #[serde(default)]
    session: SessionConfig,
}

/// A validated cell config with paths resolved.
#[derive(Debug, Clone)]
pub struct CellConfig {
    /// The file it came from.
    pub file: PathBuf,
    /// Eye-in-hand or eye-to-hand.
    pub setup: Setup,
    /// Board spec file.
    pub target: PathBuf,
    /// Camera intrinsics file (camera_info YAML or Kalibr camchain); `None`: estimate them from
    /// the run's board corners (Zhang's closed form, then the joint reprojection refinement).
    pub intrinsics: Option<PathBuf>,
    /// The arm.
    pub robot: RobotConfig,
    /// The camera.
    pub camera: CameraConfig,
    /// The cell's transforms as known before calibrating (used to plan).
    pub nominal: CellTransforms,
    /// The simulator's ground truth (sim backends only).
    pub simulation: Option<CellTransforms>,
    /// Where the plan comes from (file paths resolved).
    pub plan: PlanConfig,
    /// Motion limits.
    pub limits: MotionLimits,
    /// Workspace box for the flange origin.
    pub workspace: WorkspaceBox,
    /// Detector settings.
    pub detector: DetectorConfig,
    /// Solver settings.
    pub solver: SolverConfig,
    /// Session settings.
    pub session: SessionConfig,
}

impl CellConfig {
    /// Reads and validates a cell config.
    pub fn load(file: &Path) -> Result<CellConfig, ConfigError> {
        Self::parse(&read_text(file)?, file)
    }

    /// Parses config YAML; relative paths resolve against `file`'s folder.
    pub fn parse(text: &str, file: &Path) -> Result<CellConfig, ConfigError> {
        let raw: RawConfig = parse_yaml(text, file)?;
        let folder = file.parent().unwrap_or(Path::new("."));
        let resolve = |p: &Path| {
            if p.is_absolute() {
                p.to_path_buf()
            } else {
                folder.join(p)
            }
        };
        let value_error = |key: &str, problem: String| ConfigError::Value {
            file: file.to_path_buf(),
            key: key.to_string(),
            problem,
        };

        let (camera_key, target_key) = match raw.setup {
            Setup::EyeInHand => ("T_flange_camera", "T_base_target"),
            Setup::EyeToHand => ("T_base_camera", "T_flange_target"),
        };
        let transforms = |section: &str, map: &BTreeMap<String, PoseYaml>| {
            for key in map.keys() {
                if key != camera_key && key != target_key {
                    return Err(value_error(
                        &format!("{section}.{key}"),
                        format!("unknown transform for setup {:?}: expected `{camera_key}` and `{target_key}`", raw.setup),
                    ));
                }
            }
            let get = |key: &str| {
                let pose = map.get(key).ok_or_else(|| {
                    value_error(
                        section,
                        format!("missing `{key}` (expected `{camera_key}` and `{target_key}`)"),
                    )
                })?;
                pose.to_pose(&format!("{section}.{key}"))
                    .map_err(|source| ConfigError::Pose {
                        file: file.to_path_buf(),
                        source,
                    })
            };
            Ok(CellTransforms {
                setup: raw.setup,
                camera_mount: get(camera_key)?,
                target_mount: get(target_key)?,
            })
        };
        let nominal = transforms("nominal", &raw.nominal)?;
        let simulation = raw
            .simulation
            .as_ref()
            .map(|m| transforms("simulation", m))
            .transpose()?;
        let uses_sim = matches!(raw.robot, RobotConfig::Sim { .. })
            || matches!(raw.camera, CameraConfig::Sim { .. });
        if uses_sim && simulation.is_none() {
            return Err(value_error(
                "simulation",
                format!("the sim backends need the ground truth: `simulation: {{{camera_key}: ..., {target_key}: ...}}`"),
            ));
        }

        if let RobotConfig::Sim {
            model,
            move_duration_s,
            repeatability_mm,
            repeatability_deg,
            ..
        } = &raw.robot
        {
            check_model(model).map_err(|p| value_error("robot.model", p))?;
            for (key, v) in [
                ("robot.move_duration_s", *move_duration_s),
                ("robot.repeatability_mm", *repeatability_mm),
                ("robot.repeatability_deg", *repeatability_deg),
            ] {
                if !(v.is_finite() && v >= 0.0) {
                    return Err(value_error(
                        key,
                        format!("expected a non-negative number, got {v}"),
                    ));
                }
            }
        }
        if let RobotConfig::Ur {
            repeatability_mm,
            repeatability_deg,
            ..
        }
        | RobotConfig::Recorded {
            repeatability_mm,
            repeatability_deg,
            ..
        } = &raw.robot
        {
            for (key, value) in [
                ("robot.repeatability_mm", repeatability_mm),
                ("robot.repeatability_deg", repeatability_deg),
            ] {
                if let Some(v) = value {
                    if !(v.is_finite() && *v > 0.0) {
                        return Err(value_error(
                            key,
                            format!("expected a positive number, got {v}"),
                        ));
                    }
                }
            }
        }
        if let RobotConfig::Ur {
            model,
            connect_timeout_s,
            host,
            ..
        } = &raw.robot
        {
            check_model(model).map_err(|p| value_error("robot.model", p))?;
            if host.trim().is_empty() {
                return Err(value_error(
                    "robot.host",
                    "expected the controller's IP address or host name".into(),
                ));
            }
            if !(connect_timeout_s.is_finite()
                && *connect_timeout_s > 0.0
                && *connect_timeout_s <= 120.0)
            {
                return Err(value_error(
                    "robot.connect_timeout_s",
                    format!("expected seconds in (0, 120], got {connect_timeout_s}"),
                ));
            }
        }

        let l = raw.limits;
        for (key, v, ceiling, unit) in [
            (
                "limits.linear_speed",
                l.linear_speed,
                MAX_LINEAR_SPEED,
                "m/s",
            ),
            (
                "limits.linear_acceleration",
                l.linear_acceleration,
                MAX_LINEAR_ACCELERATION,
                "m/s²",
            ),
            (
                "limits.joint_speed_deg",
                l.joint_speed_deg,
                MAX_JOINT_SPEED_DEG,
                "°/s",
            ),
            (
                "limits.joint_acceleration_deg",
                l.joint_acceleration_deg,
                MAX_JOINT_ACCELERATION_DEG,
                "°/s²",
            ),
        ] {
            if !(v.is_finite() && v > 0.0 && v <= ceiling) {
                return Err(value_error(key, format!("expected a value in (0, {ceiling}] {unit} (the calibration safety ceiling), got {v}")));
            }
        }
        let limits = MotionLimits {
            linear_speed: l.linear_speed,
            linear_acceleration: l.linear_acceleration,
            joint_speed: l.joint_speed_deg.to_radians(),
            joint_acceleration: l.joint_acceleration_deg.to_radians(),
        };

        let w = raw.workspace;
        if !(0..3).all(|i| w.min[i].is_finite() && w.max[i].is_finite() && w.min[i] < w.max[i]) {
            return Err(value_error(
                "workspace",
                format!(
                    "expected min < max on every axis, got min {:?}, max {:?}",
                    w.min, w.max
                ),
            ));
        }
        let workspace = WorkspaceBox {
            min: Vector3::from(w.min),
            max: Vector3::from(w.max),
        };

        let mut plan = raw.plan.clone();
        let recorded = matches!(raw.robot, RobotConfig::Recorded { .. });
        match (&plan.file, &plan.generate) {
            (None, None) if recorded => {}
            _ if recorded => {
                return Err(value_error(
                    "plan",
                    "a recorded robot's plan is its recorded poses: leave out `plan`".into(),
                ))
            }
            (Some(_), None) => {}
            (None, Some(spec)) => spec
                .validate()
                .map_err(|p| value_error("plan.generate", p))?,
            _ => {
                return Err(value_error(
                    "plan",
                    "expected exactly one of `file` (a scripted plan) and `generate`".into(),
                ))
            }
        }
        if !(plan.target_uncertainty_mm.is_finite() && plan.target_uncertainty_mm > 0.0) {
            return Err(value_error(
                "plan.target_uncertainty_mm",
                format!(
                    "expected a positive number of mm, got {}",
                    plan.target_uncertainty_mm
                ),
            ));
        }
        plan.file = plan.file.as_deref().map(resolve);
        let robot = match raw.robot {
            RobotConfig::Recorded {
                poses,
                repeatability_mm,
                repeatability_deg,
            } => RobotConfig::Recorded {
                poses: resolve(&poses),
                repeatability_mm,
                repeatability_deg,
            },
            other => other,
        };

        let camera = match raw.camera {
            CameraConfig::Files { folder } => CameraConfig::Files {
                folder: resolve(&folder),
            },
            CameraConfig::Uvc {
                ref pixel_format,
                width,
                height,
                fps,
                ..
            } => {
                if !["mjpeg", "yuyv", "gray"].contains(&pixel_format.as_str()) {
                    return Err(value_error(
                        "camera.pixel_format",
                        format!("expected mjpeg, yuyv or gray, got `{pixel_format}`"),
                    ));
                }
                if width == 0 || height == 0 || fps == 0 {
                    return Err(value_error(
                        "camera",
                        format!("width, height and fps must be positive, got {width}x{height} px at {fps} frames/s"),
                    ));
                }
                raw.camera.clone()
            }
            CameraConfig::Sim {
                noise_sigma,
                blur_sigma_px,
                seed,
                hide_board_in_grabs,
                intrinsics,
            } => {
                if raw.intrinsics.is_none() && intrinsics.is_none() {
                    return Err(value_error(
                        "camera.intrinsics",
                        "the cell has no `intrinsics` (they will be estimated), so the sim camera needs its lens: `camera: {backend: sim, intrinsics: <camera_info.yaml>}`".into(),
                    ));
                }
                if !(noise_sigma.is_finite()
                    && noise_sigma >= 0.0
                    && blur_sigma_px.is_finite()
                    && blur_sigma_px >= 0.0)
                {
                    return Err(value_error(
                        "camera",
                        "noise_sigma and blur_sigma_px must be non-negative numbers".into(),
                    ));
                }
                CameraConfig::Sim {
                    noise_sigma,
                    blur_sigma_px,
                    seed,
                    hide_board_in_grabs,
                    intrinsics: intrinsics.as_deref().map(resolve),
                }
            }
        };
        if !(raw.detector.decimate >= 1.0 && raw.detector.threads >= 1) {
            return Err(value_error(
                "detector",
                "decimate must be >= 1 and threads >= 1".into(),
            ));
        }
        let s = raw.session;
        if !(s.settle_s.is_finite()
            && s.settle_s >= 0.0
            && s.max_reprojection_rms_px > 0.0
            && s.image_margin_px >= 0.0)
        {
            return Err(value_error(
                "session",
                "settle_s >= 0, max_reprojection_rms_px > 0 and image_margin_px >= 0 expected"
                    .into(),
            ));
        }
        let sv = &raw.solver;
        if !["refined", "iterative", "closed-form"].contains(&sv.method.as_str()) {
            return Err(value_error(
                "solver.method",
                format!(
                    "expected refined, iterative or closed-form, got `{}`",
                    sv.method
                ),
            ));
        }
        if !(sv.rotation_sigma_deg > 0.0 && sv.translation_sigma_mm > 0.0) {
            return Err(value_error(
                "solver",
                "rotation_sigma_deg and translation_sigma_mm must be positive".into(),
            ));
        }
        if !(sv.pixel_sigma_px.is_finite() && sv.pixel_sigma_px > 0.0) {
            return Err(value_error(
                "solver.pixel_sigma_px",
                format!(
                    "expected a positive noise level in px, got {}",
                    sv.pixel_sigma_px
                ),
            ));
        }

        Ok(CellConfig {
            file: file.to_path_buf(),
            setup: raw.setup,
            target: resolve(&raw.target),
            intrinsics: raw.intrinsics.as_deref().map(resolve),
            robot,
            camera,
            nominal,
            simulation,
            plan,
            limits,
            workspace,
            detector: raw.detector,
            solver: raw.solver,
            session: raw.session,
        })
    }

    /// The lens the simulated camera renders with (`camera.intrinsics`, else the cell's).
    pub fn sim_lens(&self) -> Option<&Path> {
        match &self.camera {
            CameraConfig::Sim {
                intrinsics: Some(lens),
                ..
            } => Some(lens),
            CameraConfig::Sim { .. } => self.intrinsics.as_deref(),
            CameraConfig::Files { .. } | CameraConfig::Uvc { .. } => None,
        }
    }

    /// How far the robot's reported flange pose may be from the true one, 1-sigma per axis, as
    /// (m, rad): the sim's configured noise (0.01 mm / 0.001° when it has none), the configured
    /// or default figure of a UR (0.03 mm / 0.003°) or a recorded arm (0.1 mm / 0.01°). The
    /// reprojection solve starts its noise estimate here.
    pub fn robot_repeatability(&self) -> (f64, f64) {
        let (mm, deg) = match &self.robot {
            RobotConfig::Sim {
                repeatability_mm,
                repeatability_deg,
                ..
            } if *repeatability_mm > 0.0 && *repeatability_deg > 0.0 => {
                (*repeatability_mm, *repeatability_deg)
            }
            RobotConfig::Sim { .. } => (0.01, 0.001),
            RobotConfig::Ur {
                repeatability_mm,
                repeatability_deg,
                ..
            } => (
                repeatability_mm.unwrap_or(0.03),
                repeatability_deg.unwrap_or(0.003),
            ),
            RobotConfig::Recorded {
                repeatability_mm,
                repeatability_deg,
                ..
            } => (
                repeatability_mm.unwrap_or(0.1),
                repeatability_deg.unwrap_or(0.01),
            ),
        };
        (mm * 1e-3, deg.to_radians())
    }

    /// The settle time as a duration.
    pub fn settle(&self) -> Duration {
        Duration::from_secs_f64(self.session.settle_s)
    }
}

fn check_model(model: &str) -> Result<(), String> {
    match model {
        "ur5e" | "ur10e" => Ok(()),
        other => Err(format!("expected ur5e or ur10e, got `{other}`")),
    }
}
