//! The cell config's shape as written in YAML: serde structs and enums, every closed set of
//! strings a typed enum, every section `deny_unknown_fields`. Reading one checks only the shape
//! (keys, types, enum names); numbers and cross-field rules are checked by `config::validate`.
//! [`ConfigFile`] also serialises, so tools write configs through serde (see
//! [`ConfigFile::save`]). Depends on `plan` (the generated-plan spec), `setup`, `geometry` and
//! `verdict` (the accuracy type).
//!
//! Why one file of ~700 lines: it is the whole YAML surface of a cell, section by section, with
//! each key's doc beside its field; a reader looking up a key should find every one in one
//! place, in the order of the shipped configs.

use std::collections::BTreeMap;
use std::path::PathBuf;

use serde::{Deserialize, Serialize};

use handeye_core::geometry::PoseYaml;
use handeye_core::setup::Setup;
use handeye_plan::GenerateSpec;
use handeye_robot::kinematics::UrModel;
use handeye_robot::MotionLimits;
use handeye_solve::verdict::{Accuracy, DEFAULT_ACCURACY_DEG, DEFAULT_ACCURACY_MM};
use handeye_solve::Method;

/// A whole cell config file as written (paths as written, nothing checked but the shape).
///
/// One schema for a cell of one camera or several. A cell of several cameras lists them under
/// `cameras:` (each with its name, setup, intrinsics, backend and mount); a cell of one camera may
/// give that camera's keys at the top level instead (`setup`, `intrinsics`, `camera`, its mount
/// in `nominal`), which reads as a list of one. See `config::cameras` for the list form.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(
    deny_unknown_fields,
    expecting = "a mapping of config keys (setup, target, robot, camera, nominal, workspace, ...)"
)]
pub struct ConfigFile {
    /// Eye-in-hand or eye-to-hand (the one-camera form: each camera of a `cameras:` list has its
    /// own).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub setup: Option<Setup>,
    /// Board spec file (relative to the config's folder); with `cameras:`, the board fixed in the
    /// cell (eye-in-hand cameras), and the flange board too when `flange_target` is absent.
    pub target: PathBuf,
    /// With `cameras:`: the board on the flange, seen by eye-to-hand cameras; default `target`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub flange_target: Option<PathBuf>,
    /// Camera intrinsics file (the one-camera form); absent: estimated from the run (sim camera or
    /// recorded frames).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub intrinsics: Option<PathBuf>,
    /// The arm.
    pub robot: RobotConfig,
    /// The camera (the one-camera form).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub camera: Option<CameraConfig>,
    /// The cameras of the cell, each with its own setup, lens, backend and mount (1 to
    /// [`MAX_CAMERAS`]); absent: the one-camera form.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cameras: Option<Vec<CameraFile>>,
    /// The cell's transforms as known before calibrating: the one-camera form's mount and board
    /// (`T_flange_camera`/`T_base_target` or `T_base_camera`/`T_flange_target`); with `cameras:`
    /// the boards only (`T_base_target` when some camera is eye-in-hand, `T_flange_target` when
    /// some camera is eye-to-hand), each camera's mount being its own `nominal`.
    pub nominal: BTreeMap<String, PoseYaml>,
    /// The simulator's ground truth, same keys as `nominal` (sim backends only), and the
    /// simulated arm's own kinematic errors (`arm_errors`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub simulation: Option<SimulationFile>,
    /// Where the plan comes from (with `cameras:`, planned for the first eye-in-hand camera).
    #[serde(default)]
    pub plan: PlanConfig,
    /// Motion limits.
    #[serde(default)]
    pub limits: LimitsConfig,
    /// The box the flange origin must stay in, base frame.
    pub workspace: WorkspaceConfig,
    /// Detector settings (every camera).
    #[serde(default)]
    pub detector: DetectorConfig,
    /// Solver settings.
    #[serde(default)]
    pub solver: SolverConfig,
    /// Session settings.
    #[serde(default)]
    pub session: SessionConfig,
    /// The accuracy the GOOD / CHECK / REDO verdict judges against (each camera's).
    #[serde(default)]
    pub verdict: VerdictConfig,
}

/// The `simulation:` section as written: the true transforms (the keys of `nominal`) and the
/// simulated arm's kinematic errors.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct SimulationFile {
    /// The simulated arm's errors against its published model (absent: none): it reports
    /// `FK_nominal(q)` while the camera sees the flange at `FK_true(q)`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub arm_errors: Option<ArmErrorsFile>,
    /// The true transforms, same keys as `nominal` (checked by `config::validate`, which
    /// refuses any other key).
    #[serde(flatten)]
    pub transforms: BTreeMap<String, PoseYaml>,
}

/// `simulation.arm_errors`: either drawn (`seed` with the sigmas) or given per joint (the
/// lists); not both. Degrees and millimetres, as a person writes them.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ArmErrorsFile {
    /// Seed of a random draw with the sigmas below.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub seed: Option<u64>,
    /// 1-sigma of each joint's zero offset, degrees (with `seed`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub joint_offset_deg: Option<f64>,
    /// 1-sigma of each link's DH `d` and `a`, mm (with `seed`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub length_mm: Option<f64>,
    /// 1-sigma of each link's DH twist `α`, degrees (with `seed`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub twist_deg: Option<f64>,
    /// Each joint's zero offset, degrees, base first (six).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub joint_offsets_deg: Option<Vec<f64>>,
    /// Each link's DH `d` error, mm (six).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub d_mm: Option<Vec<f64>>,
    /// Each link's DH `a` error, mm (six).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub a_mm: Option<Vec<f64>>,
    /// Each link's DH twist error, degrees (six).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub alpha_deg: Option<Vec<f64>>,
}

/// The most cameras one cell runs: every camera grabs, holds its frame and is detected at every
/// pose; far beyond any real cell, a config with more is a mistake or an attack on memory.
pub const MAX_CAMERAS: usize = 16;

/// One camera of a `cameras:` list as written.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraFile {
    /// Its name: lower-case letters, digits and `_` (frames are named `cam_<name>`).
    pub name: String,
    /// On the flange (`eye_in_hand`) or fixed in the cell (`eye_to_hand`).
    pub setup: Setup,
    /// Its intrinsics (camera_info YAML or Kalibr camchain): required, a several-camera run
    /// does not estimate them.
    pub intrinsics: PathBuf,
    /// Its backend.
    pub camera: CameraConfig,
    /// Its mount as known before calibrating: `T_flange_cam_<name>` or `T_base_cam_<name>`.
    pub nominal: PoseYaml,
    /// Its simulated mount (sim backends only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub simulation: Option<PoseYaml>,
}

/// An arm model whose kinematics the tool knows: one of Universal Robots' published DH tables
/// (`robot::kinematics::UrModel::NAMES`, the one list; `ur5e` by default). An unknown name is
/// refused listing those.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ArmModel(&'static str);

impl ArmModel {
    /// The YAML name (`ur5e`), as `robot::kinematics::UrModel::by_name` takes it.
    pub fn name(self) -> &'static str {
        self.0
    }
}

impl Default for ArmModel {
    fn default() -> Self {
        ArmModel("ur5e")
    }
}

impl Serialize for ArmModel {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(self.0)
    }
}

impl<'de> Deserialize<'de> for ArmModel {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let name = String::deserialize(d)?;
        UrModel::NAMES
            .iter()
            .find(|known| **known == name)
            .map(|known| ArmModel(known))
            .ok_or_else(|| serde::de::Error::unknown_variant(&name, &UrModel::NAMES))
    }
}

/// Which arm drives the cell.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(
    tag = "backend",
    rename_all = "snake_case",
    deny_unknown_fields,
    expecting = "a mapping with `backend: sim`, `backend: ur`, `backend: recorded` or `backend: ros2`"
)]
pub enum RobotConfig {
    /// The simulated UR arm.
    Sim(super::robot::SimRobot),
    /// A Universal Robots controller through ur_rtde (needs the `ur-rtde` feature).
    Ur(super::robot::UrRobot),
    /// Replays the flange poses a real arm measured during a recording made elsewhere; used with
    /// the image-folder camera.
    Recorded(super::robot::RecordedRobot),
    /// An arm under a ROS 2 driver: `/tf`, `/joint_states`, FollowJointTrajectory (needs the
    /// `ros2` feature; `config::ros2`).
    Ros2(Box<super::ros2::Ros2Robot>),
}

pub use handeye_robot::kinematics::JOINT_NAMES;

/// The arm's own joint ranges, degrees: ±360° on every joint but the elbow (±180°), as
/// `robot::kinematics` plans every model.
pub const ARM_JOINT_RANGES_DEG: [[f64; 2]; 6] = [
    [-360.0, 360.0],
    [-360.0, 360.0],
    [-180.0, 180.0],
    [-360.0, 360.0],
    [-360.0, 360.0],
    [-360.0, 360.0],
];

/// Default joint ranges for a real arm with the camera on its flange (eye-in-hand), degrees.
/// The camera cable is dressed along the arm with the joints near zero; it tolerates half a turn
/// either way at the base and the three wrist joints, not the controller's two full turns (a
/// plan that swings wrist 3 to 280° winds the cable round the flange). ±180° still leaves every
/// orientation reachable: each of these joints keeps exactly one representative of its angle.
/// Shoulder and elbow do not twist the cable and keep the arm's ranges.
pub const FLANGE_CAMERA_JOINT_RANGES_DEG: [[f64; 2]; 6] = [
    [-180.0, 180.0],
    [-360.0, 360.0],
    [-180.0, 180.0],
    [-180.0, 180.0],
    [-180.0, 180.0],
    [-180.0, 180.0],
];

/// Why the arm's own model cannot be estimated for a cell of `robot` with the camera's
/// `intrinsics` (`solver.kinematics`); `None` when it can. `joint_offsets` is refused for it
/// when the config is read, `auto` keeps the published model.
pub fn arm_model_unavailable(
    robot: &RobotConfig,
    intrinsics: Option<&std::path::Path>,
) -> Option<&'static str> {
    let backend = robot.backend();
    if !backend.reports_joints() || backend.model().is_none() {
        return Some("the arm's published model and each pose's joints: a sim, ur or ros2 arm with `robot.model`");
    }
    if intrinsics.is_none() {
        return Some("the camera's `intrinsics`: a run that estimates them does not estimate the arm's model yet");
    }
    None
}

/// The pixel formats a USB camera can be asked for.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PixelFormatName {
    /// Motion JPEG (most USB cameras at full resolution).
    #[default]
    Mjpeg,
    /// Packed YUV 4:2:2.
    Yuyv,
    /// 8-bit grey.
    Gray,
}

impl PixelFormatName {
    /// The YAML name (`mjpeg`, `yuyv`, `gray`).
    pub fn as_str(self) -> &'static str {
        match self {
            PixelFormatName::Mjpeg => "mjpeg",
            PixelFormatName::Yuyv => "yuyv",
            PixelFormatName::Gray => "gray",
        }
    }
}

/// Which camera takes the frames.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(
    tag = "backend",
    rename_all = "snake_case",
    deny_unknown_fields,
    expecting = "a mapping with `backend: sim`, `backend: files`, `backend: uvc` or `backend: ros2`"
)]
pub enum CameraConfig {
    /// Frames rendered from the simulated cell's true chain.
    Sim(super::camera::SimCamera),
    /// Frames from an image folder, in plan order.
    Files(super::camera::FilesCamera),
    /// A USB/UVC camera (needs the `uvc` build feature).
    Uvc(super::camera::UvcCamera),
    /// A camera under a ROS 2 camera node (needs the `ros2` feature; `config::ros2`).
    Ros2(super::ros2::Ros2Camera),
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
            // Rounded to 1e-9 °/s: a written config reads 30, not 29.999999999999996.
            joint_speed_deg: (l.joint_speed.to_degrees() * 1e9).round() / 1e9,
            joint_acceleration_deg: (l.joint_acceleration.to_degrees() * 1e9).round() / 1e9,
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
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub file: Option<PathBuf>,
    /// Generate views on a cap around the board.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub generate: Option<GenerateSpec>,
    /// Choose poses one at a time (next-best pose, weighed by the move time to reach each)
    /// from the plan's poses as candidates, and stop as soon as the result is good enough (see
    /// `target_uncertainty_mm`). Absent: adaptive for a generated plan when the intrinsics are
    /// given, fixed otherwise (`false` runs every pose of the plan, today's behaviour).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub adaptive: Option<bool>,
    /// Hand-guided capture (`handeye console`): nothing drives the arm; a person captures where
    /// it stands, and the plan's poses (`file` or `generate`) are only suggested.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub manual: bool,
    /// Adaptive stop rule: the larger translation 1-sigma of the two unknowns and the held-out
    /// error must be at most this, mm. Absent: the verdict's `accuracy_mm`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub target_uncertainty_mm: Option<f64>,
    /// Adaptive: never stop before this many accepted poses.
    #[serde(default = "default_min_poses")]
    pub min_poses: usize,
    /// Adaptive: stop after this many accepted poses even if the target is not reached.
    /// Absent: every candidate may be used.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_poses: Option<usize>,
    /// Visit a fixed plan's poses in the order of least total move time (from where the arm
    /// stands, every move checked against the joint ranges and the workspace box); `false`
    /// keeps the scripted order.
    #[serde(default = "default_reorder")]
    pub reorder: bool,
}

fn default_min_poses() -> usize {
    8
}
fn default_reorder() -> bool {
    true
}

impl Default for PlanConfig {
    /// No plan source (a recorded robot's poses are its plan), adaptive by its rule.
    fn default() -> Self {
        PlanConfig {
            file: None,
            generate: None,
            adaptive: None,
            manual: false,
            target_uncertainty_mm: None,
            min_poses: default_min_poses(),
            max_poses: None,
            reorder: default_reorder(),
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
    1
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

impl DetectorConfig {
    /// The detector's options this section asks for (the others at their defaults): what a run
    /// of the cell measures its frames with.
    pub fn options(&self) -> handeye_vision::DetectorOptions {
        handeye_vision::DetectorOptions {
            decimation: self.decimate,
            threads: self.threads,
            max_hamming: self.max_hamming,
            ..handeye_vision::DetectorOptions::default()
        }
    }
}

/// The solver a config asks for: the solver's own [`Method`], read and written by the one list
/// of names ([`Method::NAMES`]) that `--method` takes too.
pub type SolverMethod = Method;

/// Solver settings.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SolverConfig {
    /// `refined` (default), `iterative`, a closed form (`tsai`, `park`, `horaud`, `andreff`,
    /// `daniilidis`, `closed_form` (also `closed-form`, `shah`), `li`): [`Method::NAMES`].
    #[serde(default)]
    pub method: Method,
    /// Rotation noise of a board pose `T_camera_target`, degrees (1-sigma per axis). Given: the
    /// pose-space fit uses it as is; absent (the default): estimated from the residuals
    /// (variance component estimation, starting from 0.2°), unless `estimate_noise` is false.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rotation_sigma_deg: Option<f64>,
    /// Translation noise of a board pose, mm (1-sigma per axis). Given: used as is; absent (the
    /// default): estimated from the residuals (starting from 1 mm), unless `estimate_noise` is
    /// false.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub translation_sigma_mm: Option<f64>,
    /// Robust pose-space fit (default): a consensus start, samples whose residual is an outlier
    /// against the fit of the rest left out of the final fit (each named in a warning); a clean
    /// data set keeps every sample. `false`: fit every sample, only flag outliers.
    #[serde(default = "yes")]
    pub drop_outliers: bool,
    /// Weigh each sample by how precisely its view fixed its board pose (default): a far or
    /// partly seen board counts for less instead of standing out as an outlier. `false`: every
    /// view alike (the behaviour before sessions recorded each view's precision).
    #[serde(default = "yes")]
    pub weigh_views: bool,
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
    /// Estimate the noise from the residuals (variance component estimation): the board-pose
    /// sigmas not given above in the pose-space fit, and the corner noise and the robot's
    /// repeatability in the reprojection fit, starting from `pixel_sigma_px` and the robot's
    /// `repeatability_*`; `false` weights with the values as given (defaults where absent).
    #[serde(default = "yes")]
    pub estimate_noise: bool,
    /// The arm's own model estimated with the two transforms (issue #41): `auto` (the default:
    /// the joint zero offsets are fitted and kept only when the data choose them, and the DH
    /// link corrections beside them only when the data need them and the answer is expected
    /// nearer the truth with them), `none` (the
    /// published model, the behaviour before `auto`), or `joint_offsets` (always estimated: the
    /// joint zero offsets the data determine, from each pose's recorded joints and the arm's
    /// published DH model), or `dh` (always estimated: the offsets and the link `d`, `a` and `α`
    /// corrections the data determine). Absent: `auto`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub kinematics: Option<KinematicsChoice>,
    /// The arm's model an earlier session estimated (its `result.yaml`, whose `kinematics:`
    /// section holds the joint offsets and link corrections): every robot pose of this cell is
    /// corrected by it before the solve, and nothing of the arm is estimated again (a camera
    /// mounted anew on a calibrated arm). Relative to the config file; `kinematics` is then
    /// left out.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub arm_model: Option<PathBuf>,
}

impl SolverConfig {
    /// `solver.kinematics`, `auto` when absent.
    pub fn kinematics(&self) -> KinematicsChoice {
        self.kinematics.unwrap_or(KinematicsChoice::Auto)
    }
}

/// `solver.kinematics`: which of the arm's own parameters are estimated with the cell.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum KinematicsChoice {
    /// The joint zero offsets fitted where the arm's model and joints are known, and kept when
    /// the data choose them (they lower χ² by more than noise alone would in 99 % of cells:
    /// `ArmFit::model_choice_margin`); the published model otherwise.
    Auto,
    /// The arm's model as published (the reported flange poses are taken as they are).
    None,
    /// The joint zero offsets the data determine (those the two transforms absorb are named).
    JointOffsets,
    /// The joint offsets and the DH link corrections (`d`, `a`, `α`) the data determine (those
    /// the transforms absorb and those the poses leave undetermined are named).
    Dh,
}

impl KinematicsChoice {
    /// The YAML name.
    pub fn name(self) -> &'static str {
        match self {
            KinematicsChoice::Auto => "auto",
            KinematicsChoice::None => "none",
            KinematicsChoice::JointOffsets => "joint_offsets",
            KinematicsChoice::Dh => "dh",
        }
    }
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
fn yes() -> bool {
    true
}

impl Default for SolverConfig {
    fn default() -> Self {
        SolverConfig {
            method: Method::default(),
            rotation_sigma_deg: None,
            translation_sigma_mm: None,
            drop_outliers: true,
            weigh_views: true,
            space: SolveSpace::default(),
            pixel_sigma_px: default_pixel_sigma_px(),
            robot_corrections: true,
            estimate_noise: true,
            kinematics: None,
            arm_model: None,
        }
    }
}

/// Session settings.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SessionConfig {
    /// Fixed wait after the arm stops before grabbing, s; with `settle_speed_deg_s` the minimum
    /// before the speeds are watched.
    #[serde(default = "default_settle_s")]
    pub settle_s: f64,
    /// Settle by measurement: capture once every joint speed the arm reports has stayed below
    /// this for `settle_window_s`, °/s (0 = the fixed `settle_s` only).
    #[serde(default = "default_settle_speed_deg_s")]
    pub settle_speed_deg_s: f64,
    /// How long the joint speeds must stay below `settle_speed_deg_s`, s.
    #[serde(default = "default_settle_window_s")]
    pub settle_window_s: f64,
    /// An arm that has not settled this long after a move stops the run, s.
    #[serde(default = "default_settle_timeout_s")]
    pub settle_timeout_s: f64,
    /// Largest accepted board reprojection RMS, px; a worse frame is retried, then skipped.
    #[serde(default = "default_max_rms_px")]
    pub max_reprojection_rms_px: f64,
    /// Margin kept between the board and the image border when checking a plan, px.
    #[serde(default = "default_margin_px")]
    pub image_margin_px: f64,
}

fn default_settle_s() -> f64 {
    0.0
}
fn default_settle_speed_deg_s() -> f64 {
    0.5
}
fn default_settle_window_s() -> f64 {
    0.1
}
fn default_settle_timeout_s() -> f64 {
    5.0
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
            settle_speed_deg_s: default_settle_speed_deg_s(),
            settle_window_s: default_settle_window_s(),
            settle_timeout_s: default_settle_timeout_s(),
            max_reprojection_rms_px: default_max_rms_px(),
            image_margin_px: default_margin_px(),
        }
    }
}

/// The accuracy the user wants of both transforms: the verdict is GOOD when the held-out error
/// and the 1-sigma of both transforms are within it, CHECK up to 3× it, REDO above (see
/// `verdict`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct VerdictConfig {
    /// Translation, mm (default 1.0).
    #[serde(default = "default_accuracy_mm")]
    pub accuracy_mm: f64,
    /// Rotation, degrees (default 0.1: about 1 mm at 0.6 m).
    #[serde(default = "default_accuracy_deg")]
    pub accuracy_deg: f64,
}

fn default_accuracy_mm() -> f64 {
    DEFAULT_ACCURACY_MM
}
fn default_accuracy_deg() -> f64 {
    DEFAULT_ACCURACY_DEG
}

impl Default for VerdictConfig {
    fn default() -> Self {
        VerdictConfig {
            accuracy_mm: DEFAULT_ACCURACY_MM,
            accuracy_deg: DEFAULT_ACCURACY_DEG,
        }
    }
}

impl VerdictConfig {
    /// The accuracy these settings ask for.
    pub fn accuracy(&self) -> Accuracy {
        Accuracy {
            translation_mm: self.accuracy_mm,
            rotation_deg: self.accuracy_deg,
        }
    }
}

/// For a shape error serde placed at a whole `backend:`-tagged section (`robot`, `camera`): the
/// YAML path of the key at fault (`camera.pixel_format`) and its error, found by reading the
/// section one key at a time with the same backend. `None` when the section is not one of
/// those, or the fault is the backend itself or a missing key (then the section is the right
/// place).
pub(super) fn pinpoint_tagged(
    document: &serde_yaml_ng::Value,
    section: &str,
) -> Option<(String, serde_yaml_ng::Error)> {
    use serde_yaml_ng::{Mapping, Value};
    let read: fn(Value) -> Option<serde_yaml_ng::Error> = match section {
        "robot" => |v| serde_yaml_ng::from_value::<RobotConfig>(v).err(),
        "camera" => |v| serde_yaml_ng::from_value::<CameraConfig>(v).err(),
        _ => return None,
    };
    let fields = document.get(section)?.as_mapping()?;
    let backend = fields.get("backend")?;
    let only = |entry: Option<(&Value, &Value)>| {
        let mut m = Mapping::new();
        m.insert("backend".into(), backend.clone());
        if let Some((k, v)) = entry {
            m.insert(k.clone(), v.clone());
        }
        // Errors about a key come while reading it; a missing required key only at the end.
        read(Value::Mapping(m)).filter(|e| !e.to_string().starts_with("missing field"))
    };
    if only(None).is_some() {
        return None;
    }
    fields
        .iter()
        .filter(|(k, _)| k.as_str() != Some("backend"))
        .find_map(|(k, v)| {
            let error = only(Some((k, v)))?;
            Some((format!("{section}.{}", k.as_str()?), error))
        })
}
