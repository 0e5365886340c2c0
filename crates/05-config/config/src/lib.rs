//! The cell config: one YAML file that says what the cell is (setup, robot, camera, board), what is
//! roughly known about it, how to move, and how to solve. Read and validated completely before
//! anything moves or any folder is created; every error names the file, the key (YAML path), the
//! value and what is accepted.
//!
//! [`schema`] holds the serde shapes (typed enums, unknown keys refused), [`validate`] the
//! accepted range of every number and the cross-field rules; this module reads a file through
//! both and resolves its paths. Relative paths inside the file are relative to the file's folder.
//! Units are SI with the suffix in the key where a person reads (`_deg`, `_mm`, `_s`). Depends
//! on the ground floor, `plan`, `robot`, `solve` and `vision` (for their types and bounds).

pub mod camera;
pub mod cameras;
pub mod recorded;
pub mod robot;
pub mod ros2;
pub mod schema;
pub mod validate;

use std::path::{Path, PathBuf};
use std::time::Duration;

use handeye_core::geometry::PoseError;
use handeye_core::setup::{CellTransforms, Setup};
use handeye_core::yaml_file::{parse_yaml, read_text, shape_error, FileError};
use handeye_robot::arm_errors::ArmErrors;
use handeye_robot::kinematics::UrModel;
use handeye_robot::{MotionLimits, WorkspaceBox};
use handeye_solve::{SolveOptions, SolverChoice};

pub use camera::{CameraBackend, FilesCamera, SimCamera, UvcCamera};
pub use recorded::{recorded_cell, RecordedFiles};
pub use robot::{RecordedRobot, RobotBackend, SimRobot, UrRobot};
pub use schema::{
    ArmErrorsFile, ArmModel, CameraConfig, CameraFile, ConfigFile, DetectorConfig,
    KinematicsChoice, LimitsConfig, PixelFormatName, PlanConfig, RobotConfig, SessionConfig,
    SimulationFile, SolveSpace, SolverConfig, SolverMethod, VerdictConfig, WorkspaceConfig,
    MAX_CAMERAS,
};
pub use validate::{
    Range, MAX_JOINT_ACCELERATION_DEG, MAX_JOINT_SPEED_DEG, MAX_LINEAR_ACCELERATION,
    MAX_LINEAR_SPEED,
};

/// A config problem: the file, the key (YAML path), the value and what was expected.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// The file could not be read, or its YAML does not have the config's shape (unknown or
    /// missing key, wrong type, unknown name): the message names the file and the YAML path.
    #[error(transparent)]
    File(#[from] FileError),
    /// The document is not a mapping of config keys (a plain string, a list, an empty file).
    #[error("{}: expected a mapping of config keys (setup, target, robot, camera, nominal, workspace, ...), found {found}", file.display())]
    NotAMapping {
        /// The config file.
        file: PathBuf,
        /// What the document is instead (`a string`, `a list`...).
        found: &'static str,
    },
    /// A number outside its accepted range.
    #[error("{}: {key}: expected {expected}, found {found}", file.display())]
    OutOfRange {
        /// The config file.
        file: PathBuf,
        /// YAML path of the value (`session.settle_s`).
        key: String,
        /// The value as written.
        found: String,
        /// What is accepted (`a value in [0, 60] s`).
        expected: String,
    },
    /// A value that contradicts the rest of the config (or names nothing).
    #[error("{}: {key}: {problem}", file.display())]
    Inconsistent {
        /// The config file.
        file: PathBuf,
        /// YAML path of the value.
        key: String,
        /// What is wrong and what was expected.
        problem: String,
    },
    /// Lengths that look like millimetres where the config takes metres (a nominal position,
    /// a workspace box): one message naming the key, instead of every pose failing later.
    #[error("{}: {key}: {found} looks like millimetres: {why}; the config takes metres: write {metres}", file.display())]
    Millimetres {
        /// The config file.
        file: PathBuf,
        /// YAML path of the value (`nominal.T_base_target.translation`, `workspace`).
        key: String,
        /// The value as written.
        found: String,
        /// Why it cannot be metres (`as metres it puts the camera 86.0 m from the flange, ...`).
        why: String,
        /// The value divided by 1000.
        metres: String,
    },
    /// A pose is malformed.
    // The pose problem is the message itself (with its YAML path), so it is not also a
    // `#[source]`: `{:#}` chains would print it twice.
    #[error("{}: {problem}", file.display())]
    Pose {
        /// The config file.
        file: PathBuf,
        /// The pose problem with its YAML path.
        problem: PoseError,
    },
    /// A problem of one camera of a cell with several (`cameras:`), named by its place and name.
    #[error("cameras[{index}] (`{name}`): {source}")]
    Camera {
        /// Its place in the `cameras:` list.
        index: usize,
        /// Its name.
        name: String,
        /// The problem.
        #[source]
        source: Box<ConfigError>,
    },
    /// A config about to be written does not load back (a bug in the writer).
    #[error("refusing to write a config that would not load")]
    Invalid(#[source] Box<ConfigError>),
}

/// The joints a plan assumes the arm starts from when the config gives none (UR's upright
/// "home" with the tool pointing down), radians.
pub fn default_start_joints() -> [f64; 6] {
    robot::default_start_joints_deg().map(f64::to_radians)
}

impl SolverConfig {
    /// The solver options these settings mean: a sigma given is used as is, one absent is
    /// estimated from the residuals (from the solver's default start) unless `estimate_noise`
    /// is off.
    pub fn to_options(&self) -> SolveOptions {
        SolverChoice {
            method: self.method,
            rotation_sigma_deg: self.rotation_sigma_deg,
            translation_sigma_mm: self.translation_sigma_mm,
            estimate_noise: self.estimate_noise,
            drop_outliers: self.drop_outliers,
            weigh_views: self.weigh_views,
            ..SolverChoice::default()
        }
        .options()
    }
}

/// A validated cell config with paths resolved: the arm, the plan and the settings shared by the
/// cell's cameras, and the cameras (one or several).
#[derive(Debug, Clone)]
pub struct CellConfig {
    /// The file it came from.
    pub file: PathBuf,
    /// The cameras, in the order written (one for the one-camera form).
    pub cameras: Vec<CellCamera>,
    /// Index of the camera the plan is made for: the first eye-in-hand one, else the first.
    pub planner: usize,
    /// Whether the file lists its cameras (`cameras:`): each is then named, its frame is
    /// `cam_<name>` and it records into its own folder of the session, also when there is one.
    pub listed: bool,
    /// The arm.
    pub robot: RobotConfig,
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
    /// The accuracy the verdict judges against.
    pub verdict: VerdictConfig,
    /// The simulated arm's own errors (`simulation.arm_errors`) as given or drawn: the truth the
    /// arm model estimated from a run is checked against.
    pub arm_errors: Option<ArmErrors>,
    /// The simulated arm's true geometry, the base and last joint offsets folded into each
    /// camera's `simulation` transforms (`ArmErrors::fold`): what the sim arm stands at.
    pub true_arm: Option<UrModel>,
    /// `session.settle_s`, checked and converted.
    settle: Duration,
}

/// One camera of a cell, validated, paths resolved.
#[derive(Debug, Clone)]
pub struct CellCamera {
    /// Its name (`cameras[].name`; `camera` in the one-camera form).
    pub name: String,
    /// Its frame: `cam_<name>` in a `cameras:` list, `camera` in the one-camera form.
    pub frame: String,
    /// Eye-in-hand or eye-to-hand.
    pub setup: Setup,
    /// The board it sees (spec file).
    pub target: PathBuf,
    /// Its intrinsics file (camera_info YAML or Kalibr camchain); `None`: estimate them from
    /// the run's board corners (Zhang's closed form, then the joint reprojection refinement).
    pub intrinsics: Option<PathBuf>,
    /// Its backend.
    pub backend: CameraConfig,
    /// Its mount and its board as known before calibrating (used to plan).
    pub nominal: CellTransforms,
    /// The simulator's ground truth of them (sim backends only).
    pub simulation: Option<CellTransforms>,
}

impl CellCamera {
    /// The YAML key of its mount: `T_flange_<frame>` or `T_base_<frame>`.
    pub fn mount_key(&self) -> String {
        match self.setup {
            Setup::EyeInHand => format!("T_flange_{}", self.frame),
            Setup::EyeToHand => format!("T_base_{}", self.frame),
        }
    }

    /// The lens the simulated camera renders with (`camera.intrinsics`, else the cell's).
    pub fn sim_lens(&self) -> Option<&Path> {
        let backend = self.backend.backend();
        match backend.simulated() {
            true => backend.own_lens().or(self.intrinsics.as_deref()),
            false => None,
        }
    }
}

impl CellConfig {
    /// Reads and validates a cell config.
    pub fn load(file: &Path) -> Result<CellConfig, ConfigError> {
        Self::parse(&read_text(file)?, file)
    }

    /// Parses and validates config YAML; relative paths resolve against `file`'s folder.
    pub fn parse(text: &str, file: &Path) -> Result<CellConfig, ConfigError> {
        Self::from_raw(ConfigFile::parse(text, file)?, file)
    }

    /// Validates a config's shape as read, camera by camera (an error of a listed camera names
    /// it); relative paths resolve against `file`'s folder.
    pub fn from_raw(raw: ConfigFile, file: &Path) -> Result<CellConfig, ConfigError> {
        let listed = raw.cameras.is_some();
        let mut cell: Option<CellConfig> = None;
        for (index, view) in cameras::camera_views(&raw, file)?.into_iter().enumerate() {
            let named = view.name.clone();
            let one =
                Self::one_camera(view.config, named.as_deref(), file).map_err(
                    |source| match &named {
                        Some(name) => ConfigError::Camera {
                            index,
                            name: name.clone(),
                            source: Box::new(source),
                        },
                        None => source,
                    },
                )?;
            match &mut cell {
                Some(cell) => cell.cameras.extend(one.cameras),
                None => cell = Some(one),
            }
        }
        let mut cell = cell.ok_or_else(|| ConfigError::Inconsistent {
            file: file.to_path_buf(),
            key: "cameras".into(),
            problem: "no camera".into(),
        })?;
        cell.listed = listed;
        cell.planner = cell
            .cameras
            .iter()
            .position(|c| c.setup == Setup::EyeInHand)
            .unwrap_or(0);
        Ok(cell)
    }

    /// The cell as the one-camera config `raw` says it (a camera of a list is named `name`).
    fn one_camera(
        raw: ConfigFile,
        name: Option<&str>,
        file: &Path,
    ) -> Result<CellConfig, ConfigError> {
        let checked = validate::check(&raw, file)?;
        let folder = file.parent().unwrap_or(Path::new("."));
        let resolve = |p: &Path| folder.join(p);
        let mut plan = raw.plan;
        plan.file = plan.file.as_deref().map(resolve);
        let mut robot = raw.robot;
        robot.backend_mut().resolve_paths(&resolve);
        let mut backend = checked.camera;
        backend.backend_mut().resolve_paths(&resolve);
        // The base and last joint offsets no data tell from the transforms: the truth a run
        // can find is in the controller's frames (see `handeye_robot::arm_errors`).
        let (true_arm, simulation) = match (&checked.arm_errors, &checked.simulation, &robot) {
            (Some(errors), Some(truth), RobotConfig::Sim(SimRobot { model, .. })) => {
                let nominal =
                    UrModel::by_name(model.name()).ok_or_else(|| ConfigError::Inconsistent {
                        file: file.to_path_buf(),
                        key: "robot.model".into(),
                        problem: format!("no kinematics known for `{}`", model.name()),
                    })?;
                let (arm, folded) = errors.fold(&nominal, truth);
                (Some(arm), Some(folded))
            }
            _ => (None, checked.simulation),
        };
        let camera = CellCamera {
            name: name.unwrap_or("camera").to_string(),
            frame: name.map_or_else(|| "camera".to_string(), |n| format!("cam_{n}")),
            setup: checked.setup,
            target: resolve(&raw.target),
            intrinsics: raw.intrinsics.as_deref().map(resolve),
            backend,
            nominal: checked.nominal,
            simulation,
        };
        Ok(CellConfig {
            file: file.to_path_buf(),
            cameras: vec![camera],
            planner: 0,
            listed: name.is_some(),
            robot,
            plan,
            limits: checked.limits,
            workspace: checked.workspace,
            detector: raw.detector,
            solver: SolverConfig {
                arm_model: raw.solver.arm_model.as_deref().map(resolve),
                ..raw.solver
            },
            session: raw.session,
            verdict: raw.verdict,
            arm_errors: checked.arm_errors,
            true_arm,
            settle: checked.settle,
        })
    }

    /// The camera the plan is made for (the only one of a one-camera cell).
    pub fn camera(&self) -> &CellCamera {
        &self.cameras[self.planner]
    }

    /// Index of the camera called `name`.
    pub fn index_of(&self, name: &str) -> Option<usize> {
        self.cameras.iter().position(|c| c.name == name)
    }

    /// The camera the plan is made for, to change (tests and tools that vary a cell).
    pub fn camera_mut(&mut self) -> &mut CellCamera {
        &mut self.cameras[self.planner]
    }

    /// The cell as its camera `index` alone sees it: the shared arm, plan and settings with that
    /// camera only (a several-camera cell prepares each camera so).
    pub fn for_camera(&self, index: usize) -> CellConfig {
        CellConfig {
            cameras: vec![self.cameras[index].clone()],
            planner: 0,
            ..self.clone()
        }
    }

    /// This config when it has one camera (the one-camera form, or a `cameras:` list of one: the
    /// same cell); else the error a command that takes one camera gives (`handeye run`,
    /// `replay`, `report` and `export` take several).
    pub fn single_camera(self) -> Result<CellConfig, ConfigError> {
        if self.cameras.len() == 1 {
            return Ok(self);
        }
        Err(ConfigError::Inconsistent {
            problem: format!(
                "this config lists its cameras ({} under `cameras:`): `handeye run`, `replay`, `report` and `export` take it; this command takes a one-camera config (`setup`, `intrinsics`, `camera` at the top level)",
                self.cameras.len()
            ),
            file: self.file,
            key: "cameras".into(),
        })
    }

    /// How far the robot's reported flange pose may be from the true one, 1-sigma per axis, as
    /// (m, rad): the sim's configured noise (0.01 mm / 0.001° when it has none), the configured
    /// or default figure of a UR (0.03 mm / 0.003°) or a recorded arm (0.1 mm / 0.01°). The
    /// reprojection solve starts its noise estimate here.
    pub fn robot_repeatability(&self) -> (f64, f64) {
        let (mm, deg) = self.robot.backend().repeatability();
        (mm * 1e-3, deg.to_radians())
    }

    /// The settle time (`session.settle_s`, checked at load) as a duration.
    pub fn settle(&self) -> Duration {
        self.settle
    }

    /// Settling by measured joint speeds (`session.settle_speed_deg_s`, `settle_window_s`,
    /// `settle_timeout_s`), or `None` when `settle_speed_deg_s` is 0 (the fixed wait only).
    pub fn settle_by_speed(&self) -> Option<handeye_robot::SettleBySpeed> {
        let s = &self.session;
        (s.settle_speed_deg_s > 0.0).then(|| handeye_robot::SettleBySpeed {
            max_joint_speed: s.settle_speed_deg_s.to_radians(),
            window: Duration::from_secs_f64(s.settle_window_s),
            timeout: Duration::from_secs_f64(s.settle_timeout_s),
        })
    }

    /// Whether the run chooses poses adaptively: `plan.adaptive` when given, else for a
    /// generated plan with known intrinsics (an adaptive plan needs board poses as they come),
    /// unless the arm's own model is estimated (`solver.kinematics: joint_offsets | dh`): it
    /// needs the joint spread of every pose, and the adaptive stop weighs the two transforms
    /// only (it stops near 8 poses, where the offsets' 1σ are near the offsets themselves).
    /// `plan.adaptive: true` still asks for it.
    pub fn adaptive(&self) -> bool {
        self.plan.adaptive.unwrap_or(
            self.plan.generate.is_some()
                && self.camera().intrinsics.is_some()
                && self.robot.backend().moves()
                && !matches!(
                    self.solver.kinematics(),
                    KinematicsChoice::JointOffsets | KinematicsChoice::Dh
                ),
        )
    }

    /// The adaptive stop target, mm: `plan.target_uncertainty_mm`, else the verdict's
    /// `accuracy_mm` (the run stops when the verdict's translation test would pass).
    pub fn adaptive_target_mm(&self) -> f64 {
        self.plan
            .target_uncertainty_mm
            .unwrap_or(self.verdict.accuracy_mm)
    }
}

impl ConfigFile {
    /// Reads config YAML's shape (no value checks: see [`CellConfig::parse`]); `file` is used in
    /// messages only.
    pub fn parse(text: &str, file: &Path) -> Result<ConfigFile, ConfigError> {
        // A document that is not a mapping gets a sentence, not serde's "invalid type".
        let document = serde_yaml_ng::from_str::<serde_yaml_ng::Value>(text).ok();
        if let Some(document) = &document {
            let found = match document {
                serde_yaml_ng::Value::Mapping(_) => None,
                serde_yaml_ng::Value::Null => Some("an empty document"),
                serde_yaml_ng::Value::Bool(_) => Some("a boolean"),
                serde_yaml_ng::Value::Number(_) => Some("a number"),
                serde_yaml_ng::Value::String(_) => Some("a string"),
                serde_yaml_ng::Value::Sequence(_) => Some("a list"),
                serde_yaml_ng::Value::Tagged(_) => Some("a tagged value"),
            };
            if let Some(found) = found {
                return Err(ConfigError::NotAMapping {
                    file: file.to_path_buf(),
                    found,
                });
            }
        }
        let error = match parse_yaml(text, file) {
            Ok(config) => return Ok(config),
            Err(error) => error,
        };
        // serde reads a `backend:`-tagged section as a whole, so its errors name only the
        // section: find the key. Read again from the section alone, the error has no location:
        // the key's line.
        if let FileError::Shape {
            path, yaml_path, ..
        } = &error
        {
            if let Some((yaml_path, problem)) = document
                .as_ref()
                .and_then(|d| schema::pinpoint_tagged(d, yaml_path))
            {
                return Err(shape_error(text, path, yaml_path, problem).into());
            }
        }
        Err(error.into())
    }

    /// The config as YAML, each line of `header` as a leading comment. `file` is used in
    /// messages only.
    pub fn to_yaml(&self, header: &str, file: &Path) -> Result<String, ConfigError> {
        let mut text: String = header.lines().map(|line| format!("# {line}\n")).collect();
        let body = serde_yaml_ng::to_string(self).map_err(|source| FileError::Serialise {
            path: file.to_path_buf(),
            source,
        })?;
        text.push_str(&body);
        Ok(text)
    }

    /// Writes the config (atomically) after checking that it loads back as a valid config from
    /// `file` (relative paths resolve against `file`'s folder).
    pub fn save(&self, file: &Path, header: &str) -> Result<(), ConfigError> {
        let text = self.to_yaml(header, file)?;
        CellConfig::parse(&text, file).map_err(|e| ConfigError::Invalid(Box::new(e)))?;
        handeye_core::atomic_file::write_atomic(file, text.as_bytes()).map_err(|source| {
            ConfigError::File(FileError::Write {
                path: file.to_path_buf(),
                source,
            })
        })
    }
}
