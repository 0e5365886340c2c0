//! A cell with several cameras: the `cameras:` form of the cell config.
//!
//! ```yaml
//! target: targets/aprilgrid-6x6.yaml            # the board fixed in the cell (eye-in-hand cameras)
//! flange_target: targets/aprilgrid-6x6.yaml     # the board on the flange (eye-to-hand cameras); default: target
//! cameras:
//!   - name: wrist
//!     setup: eye_in_hand
//!     intrinsics: cameras/sim-1280x720.yaml
//!     camera: {backend: sim, seed: 11}
//!     nominal: {translation: [0.03, -0.07, 0.04], rotation_vector: [0, 0, 1.5708]}  # T_flange_cam_wrist
//!   - name: left
//!     setup: eye_to_hand
//!     ...                                           # nominal: T_base_cam_left
//! nominal: {T_base_target: ..., T_flange_target: ...}   # the boards, one per setup present
//! robot, plan, limits, workspace, detector, solver, session, verdict: as in a one-camera config
//! ```
//!
//! A file without `cameras:` is the one-camera form, read by [`super::CellConfig`] unchanged.
//! A several-camera file becomes one [`CellConfig`] per camera (its setup, its board, its lens,
//! its backend, its mount with the board of its setup as the two unknowns, and the shared arm,
//! plan and settings), each validated by the one-camera rules, so every range and cross-field
//! check holds for each camera and an error names the camera (`cameras[1] (`left`): ...`).
//! The plan is planned for the first eye-in-hand camera (the first camera when none is): the
//! others capture at the same poses whenever they see their board.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::schema::{
    CameraConfig, ConfigFile, DetectorConfig, LimitsConfig, PlanConfig, RobotConfig, SessionConfig,
    SolverConfig, VerdictConfig, WorkspaceConfig,
};
use super::{CellConfig, ConfigError};
use handeye_core::geometry::PoseYaml;
use handeye_core::setup::Setup;
use handeye_core::yaml_file::{parse_yaml, read_text};

/// The most cameras one cell runs: every camera grabs, holds its frame and is detected at every
/// pose; far beyond any real cell, a config with more is a mistake or an attack on memory.
pub const MAX_CAMERAS: usize = 16;

/// A several-camera cell config as written.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RigConfigFile {
    /// The board fixed in the cell, seen by eye-in-hand cameras (and the flange board too when
    /// `flange_target` is absent).
    pub target: PathBuf,
    /// The board on the flange, seen by eye-to-hand cameras; default `target`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub flange_target: Option<PathBuf>,
    /// The cameras, at least one.
    pub cameras: Vec<RigCameraFile>,
    /// The arm.
    pub robot: RobotConfig,
    /// The boards as known before calibrating: `T_base_target` (when some camera is
    /// eye-in-hand) and `T_flange_target` (when some camera is eye-to-hand).
    pub nominal: BTreeMap<String, PoseYaml>,
    /// The simulator's board truth, same keys as `nominal` (sim backends only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub simulation: Option<BTreeMap<String, PoseYaml>>,
    /// Where the plan comes from (planned for the first eye-in-hand camera).
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
    /// The accuracy each camera's verdict judges against.
    #[serde(default)]
    pub verdict: VerdictConfig,
}

/// One camera of a several-camera cell as written.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RigCameraFile {
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

/// A validated several-camera cell: one [`CellConfig`] per camera.
#[derive(Debug, Clone)]
pub struct RigConfig {
    /// The file it came from.
    pub file: PathBuf,
    /// The cameras in the order written.
    pub cameras: Vec<RigCameraConfig>,
    /// Index of the camera the plan is made for.
    pub planner: usize,
}

/// One camera as a one-camera cell.
#[derive(Debug, Clone)]
pub struct RigCameraConfig {
    /// Its name.
    pub name: String,
    /// The cell as this camera sees it (its setup, board, lens and backend; the shared arm,
    /// plan and settings).
    pub config: CellConfig,
}

impl RigCameraConfig {
    /// The frame name of this camera, `cam_<name>`.
    pub fn frame(&self) -> String {
        format!("cam_{}", self.name)
    }

    /// The YAML key of its mount: `T_flange_cam_<name>` or `T_base_cam_<name>`.
    pub fn mount_key(&self) -> String {
        match self.config.setup {
            Setup::EyeInHand => format!("T_flange_{}", self.frame()),
            Setup::EyeToHand => format!("T_base_{}", self.frame()),
        }
    }
}

/// Whether config YAML is the several-camera form (a top-level `cameras:` key). Text that is
/// not YAML is not: the one-camera reader then reports what is wrong with it.
pub fn is_rig_text(text: &str) -> bool {
    serde_yaml_ng::from_str::<serde_yaml_ng::Value>(text)
        .ok()
        .and_then(|v| v.as_mapping().map(|m| m.contains_key("cameras")))
        .unwrap_or(false)
}

/// Whether the config file is the several-camera form.
pub fn is_rig_file(file: &Path) -> bool {
    read_text(file).is_ok_and(|text| is_rig_text(&text))
}

fn name_is_valid(name: &str) -> bool {
    !name.is_empty()
        && name.len() <= 32
        && name
            .chars()
            .all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '_')
}

impl RigConfig {
    /// Reads and validates a several-camera cell config.
    pub fn load(file: &Path) -> Result<RigConfig, ConfigError> {
        Self::parse(&read_text(file)?, file)
    }

    /// Parses and validates several-camera config YAML; relative paths resolve against `file`'s
    /// folder.
    pub fn parse(text: &str, file: &Path) -> Result<RigConfig, ConfigError> {
        let raw: RigConfigFile = parse_yaml(text, file)?;
        let inconsistent = |key: String, problem: String| ConfigError::Inconsistent {
            file: file.to_path_buf(),
            key,
            problem,
        };
        if raw.cameras.is_empty() {
            return Err(inconsistent(
                "cameras".into(),
                "the list is empty: give at least one camera (or use the one-camera form)".into(),
            ));
        }
        if raw.cameras.len() > MAX_CAMERAS {
            return Err(inconsistent(
                "cameras".into(),
                format!(
                    "{} cameras: at most {MAX_CAMERAS} in one cell (each holds its frames and a detector in memory at every pose, tens of MB at 1280x720; issue #40 measured 101 cameras at 5.5 GB after one pose): split the cell into runs of fewer cameras",
                    raw.cameras.len()
                ),
            ));
        }
        let mut seen = std::collections::BTreeSet::new();
        for (index, camera) in raw.cameras.iter().enumerate() {
            if !name_is_valid(&camera.name) {
                return Err(inconsistent(
                    format!("cameras[{index}].name"),
                    format!(
                        "`{}` is not a camera name: use 1 to 32 lower-case letters, digits or `_` (it becomes the frame `cam_<name>`)",
                        camera.name
                    ),
                ));
            }
            if !seen.insert(camera.name.as_str()) {
                return Err(inconsistent(
                    format!("cameras[{index}].name"),
                    format!("`{}` names two cameras: names must be unique", camera.name),
                ));
            }
        }
        for key in raw.nominal.keys() {
            if key != "T_base_target" && key != "T_flange_target" {
                return Err(inconsistent(
                    format!("nominal.{key}"),
                    "a several-camera cell's top-level `nominal` holds the boards only (`T_base_target`, `T_flange_target`); each camera's mount is its own `nominal`".into(),
                ));
            }
        }
        let cameras = raw
            .cameras
            .iter()
            .enumerate()
            .map(|(index, camera)| {
                let wrap = |source: ConfigError| ConfigError::Camera {
                    index,
                    name: camera.name.clone(),
                    source: Box::new(source),
                };
                let one = one_camera(&raw, camera)
                    .map_err(|(key, problem)| wrap(inconsistent(key, problem)))?;
                let config = CellConfig::from_raw(one, file).map_err(wrap)?;
                Ok(RigCameraConfig {
                    name: camera.name.clone(),
                    config,
                })
            })
            .collect::<Result<Vec<_>, ConfigError>>()?;
        let planner = cameras
            .iter()
            .position(|c| c.config.setup == Setup::EyeInHand)
            .unwrap_or(0);
        Ok(RigConfig {
            file: file.to_path_buf(),
            cameras,
            planner,
        })
    }

    /// Index of the camera called `name`.
    pub fn index_of(&self, name: &str) -> Option<usize> {
        self.cameras.iter().position(|c| c.name == name)
    }
}

/// The one-camera config of `camera` in `rig`: its own keys, the board of its setup and the
/// shared sections. Errors: (YAML path, problem) of a board the setup needs but `nominal` or
/// `simulation` lacks.
fn one_camera(rig: &RigConfigFile, camera: &RigCameraFile) -> Result<ConfigFile, (String, String)> {
    let (mount_key, board_key) = camera.setup.unknown_names();
    let board = |section: &str, poses: &BTreeMap<String, PoseYaml>| {
        poses.get(board_key).cloned().ok_or_else(|| {
            (
                format!("{section}.{board_key}"),
                format!(
                    "camera `{}` is {} and sees the board at {board_key}: give it in `{section}`",
                    camera.name, camera.setup
                ),
            )
        })
    };
    let nominal = BTreeMap::from([
        (mount_key.to_string(), camera.nominal.clone()),
        (board_key.to_string(), board("nominal", &rig.nominal)?),
    ]);
    let simulation = match (&camera.simulation, &rig.simulation) {
        (Some(mount), Some(boards)) => Some(BTreeMap::from([
            (mount_key.to_string(), mount.clone()),
            (board_key.to_string(), board("simulation", boards)?),
        ])),
        (None, None) => None,
        (Some(_), None) => {
            return Err((
                "simulation".into(),
                format!(
                    "camera `{}` has a simulated mount but the cell gives no simulated boards: add `simulation: {{{board_key}: ...}}`",
                    camera.name
                ),
            ))
        }
        (None, Some(_)) => {
            return Err((
                format!("cameras.{}.simulation", camera.name),
                "the cell simulates its boards: give this camera's simulated mount too".into(),
            ))
        }
    };
    let target = match camera.setup {
        Setup::EyeInHand => rig.target.clone(),
        Setup::EyeToHand => rig
            .flange_target
            .clone()
            .unwrap_or_else(|| rig.target.clone()),
    };
    Ok(ConfigFile {
        setup: camera.setup,
        target,
        intrinsics: Some(camera.intrinsics.clone()),
        robot: rig.robot.clone(),
        camera: camera.camera.clone(),
        nominal,
        simulation,
        plan: rig.plan.clone(),
        limits: rig.limits,
        workspace: rig.workspace,
        detector: rig.detector,
        solver: rig.solver.clone(),
        session: rig.session,
        verdict: rig.verdict,
    })
}
