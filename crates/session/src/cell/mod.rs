//! A cell made ready to run: the config read, the board and intrinsics loaded, the plan built and
//! checked, and — only when asked — the robot and camera backends the config names opened.
//! This is the one place that maps config backends to implementations. `run` drives a prepared
//! cell through a whole calibration run (what `handeye run` does).

pub mod recorded;
pub mod rig;
pub mod ros2;
pub mod run;
pub mod sim;
pub mod uvc;

use sim::Shared;

use std::path::Path;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;

use crate::config::{CameraConfig, CellConfig, ConfigError, RobotConfig};
use crate::plan::check::MoveCheck;
use crate::plan::check::{check_plan, check_plan_ordered, CheckContext, PlanReport};
use crate::plan::generate::{spread_across_image, IMAGE_SPREAD_FOR_INTRINSICS};
use crate::plan::{generate, GenerateSpec, LookAt, Plan, PlanError, Waypoint};
use crate::session::{
    InputFile, SessionError, SessionFolder, SessionManifest, SessionSetup, SolveInputs,
};
use handeye_camera::Camera;
use handeye_core::camera_model::CameraModel;
use handeye_core::geometry::Pose;
use handeye_core::setup::CellTransforms;
use handeye_robot::kinematics::UrModel;
use handeye_robot::{Joints, Robot};
use handeye_vision::{DetectorOptions, Target};

/// Why a cell could not be prepared or opened.
#[derive(Debug, thiserror::Error)]
pub enum CellError {
    /// The config is wrong.
    #[error(transparent)]
    Config(Box<ConfigError>),
    /// The plan file is wrong.
    #[error(transparent)]
    Plan(Box<PlanError>),
    /// The board file is wrong.
    #[error("loading the board")]
    Board {
        /// The board file.
        file: std::path::PathBuf,
        /// What is wrong.
        #[source]
        source: Box<handeye_vision::TargetError>,
    },
    /// The intrinsics file is wrong.
    #[error("loading the intrinsics")]
    Intrinsics {
        /// The intrinsics file.
        file: std::path::PathBuf,
        /// What is wrong.
        #[source]
        source: Box<handeye_core::camera_model::CameraModelError>,
    },
    /// A backend could not be opened.
    #[error("{0}")]
    Backend(String),
    /// The robot could not be reached.
    #[error("opening the robot")]
    Robot(#[source] Box<handeye_robot::RobotError>),
}

/// Refuses a config whose board, intrinsics, lens or plan file is not where it says, naming the
/// key and where its relative path points: a config copied elsewhere (`cp configs/… my-cell.yaml`)
/// keeps relative paths, which resolve against its own folder, not the folder it came from.
fn referenced_files_exist(config: &CellConfig) -> Result<(), CellError> {
    let folder = config
        .file
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    let referenced = [
        Some(("target", config.camera().target.as_path())),
        config
            .camera()
            .intrinsics
            .as_deref()
            .map(|p| ("intrinsics", p)),
        config.camera().sim_lens().map(|p| ("camera.intrinsics", p)),
        config.plan.file.as_deref().map(|p| ("plan.file", p)),
    ];
    for (key, path) in referenced.into_iter().flatten() {
        if path.exists() {
            continue;
        }
        let folder_shown = std::path::absolute(folder).unwrap_or_else(|_| folder.to_path_buf());
        return Err(CellError::Config(Box::new(ConfigError::Inconsistent {
            file: config.file.clone(),
            key: key.into(),
            problem: format!(
                "{} does not exist. Paths in a config are relative to the config file's own folder ({}): a config copied from configs/ needs its files copied beside it, or absolute paths",
                path.display(),
                folder_shown.display()
            ),
        })));
    }
    Ok(())
}

/// The robot and camera of a cell, opened.
pub struct Hardware {
    /// The arm.
    pub robot: Box<dyn Robot>,
    /// The camera (of a several-camera cell: the one the plan is made for).
    pub camera: Box<dyn Camera>,
    /// A several-camera cell's other cameras, in the order of [`PreparedCell::rig`]'s `others`
    /// (empty for one camera).
    pub others: Vec<Box<dyn Camera>>,
}

/// What the shipped placeholder intrinsics file has in its `camera_name`
/// (`configs/cameras/CHANGE-ME-usb-camera-1280x720.yaml`).
pub const PLACEHOLDER_CAMERA_NAME: &str = "CHANGE-ME";

/// A cell whose config, board, intrinsics and plan are loaded and checked.
pub struct PreparedCell {
    /// The config.
    pub config: CellConfig,
    /// The board.
    pub board: Target,
    /// The intrinsics (without configured intrinsics: the sim camera's lens, for planning and
    /// rendering only — the run estimates the intrinsics).
    pub camera_model: CameraModel,
    /// Whether the config gives the intrinsics (otherwise they are estimated after the run).
    pub intrinsics_known: bool,
    /// The arm's kinematics (a UR model, its joint limits the cell's); `None` for a ROS 2 arm
    /// handeye has no model of (`robot.model: none`), which replays taught plans only.
    pub arm: Option<UrModel>,
    /// The cell's joint ranges, `(min, max)` rad (`robot.joint_ranges_deg` or the defaults).
    pub joint_limits: Vec<(f64, f64)>,
    /// Where the arm starts (sim) or is assumed to start for planning (real arm: read at connect).
    pub start_joints: Joints,
    /// The plan.
    pub plan: Plan,
    /// The plan check.
    pub report: PlanReport,
    /// A cell with several cameras: this cell is the camera the plan is made for, and the
    /// others are here (`None`: one camera).
    pub rig: Option<rig::RigCells>,
}

/// Loads everything a config names and checks the plan. Nothing moves. A config of several
/// cameras (`cameras:`) is prepared camera by camera (`rig::prepare_rig`).
pub fn prepare(config_file: &Path) -> Result<PreparedCell, CellError> {
    let config = CellConfig::load(config_file).map_err(|e| CellError::Config(Box::new(e)))?;
    if config.listed {
        return rig::prepare_rig(config);
    }
    prepare_config(config)
}

/// [`prepare`] of a one-camera config already read (also one camera of a several-camera cell,
/// [`CellConfig::for_camera`]).
pub fn prepare_config(config: CellConfig) -> Result<PreparedCell, CellError> {
    referenced_files_exist(&config)?;
    let board = Target::load(&config.camera().target).map_err(|source| CellError::Board {
        file: config.camera().target.clone(),
        source: Box::new(source),
    })?;
    // Without intrinsics the plan is checked (and the sim renders) with the sim camera's lens;
    // the run then records corners only and the intrinsics are estimated afterwards.
    let intrinsics_known = config.camera().intrinsics.is_some();
    let model_file = match (&config.camera().intrinsics, config.camera().sim_lens(), &config.robot, &config.camera().backend) {
        (Some(file), ..) => Some(file.clone()),
        (None, Some(lens), ..) => Some(lens.to_path_buf()),
        // Recorded frames: a provisional lens of the frames' size (see `recorded::provisional_model`).
        (None, None, RobotConfig::Recorded { .. }, CameraConfig::Files { .. }) => None,
        (None, None, ..) => {
            return Err(CellError::Backend(
                "the config has no `intrinsics`: estimating them is available with the sim camera or recorded frames only (give `intrinsics:` for this camera)".into(),
            ))
        }
    };
    let camera_model = match &model_file {
        Some(file) => CameraModel::load(file).map_err(|source| CellError::Intrinsics {
            file: file.clone(),
            source: Box::new(source),
        })?,
        None => recorded::provisional_model(&config)?,
    };
    // The cell's joint ranges (robot.joint_ranges_deg, or the defaults) bind the IK choice, the
    // plan check, every move check and the backends.
    let joint_limits = config.robot.joint_limits(config.camera().setup);
    let arm = match config.robot.model() {
        Some(name) => {
            let mut arm = UrModel::by_name(name).ok_or_else(|| {
                CellError::Backend(format!("robot.model: no kinematics for `{name}`"))
            })?;
            // Six ranges: the config check holds a UR model to six joints.
            arm.joint_limits = joint_limits.as_slice().try_into().map_err(|_| {
                CellError::Backend(format!(
                    "robot.joint_ranges_deg: {} ranges for the six joints of a {name}",
                    joint_limits.len()
                ))
            })?;
            Some(arm)
        }
        None => None,
    };
    let start_joints = match &config.robot {
        RobotConfig::Sim {
            start_joints_deg, ..
        } => Joints::from(start_joints_deg.map(f64::to_radians)),
        RobotConfig::Ur { .. } | RobotConfig::Recorded { .. } | RobotConfig::Ros2(_) => {
            Joints::from(crate::config::default_start_joints())
        }
    };
    if let RobotConfig::Recorded { .. } = config.robot {
        let (plan, report) = recorded::plan(&config, &camera_model, &board)?;
        return Ok(PreparedCell {
            config,
            board,
            camera_model,
            intrinsics_known,
            arm,
            joint_limits,
            start_joints,
            plan,
            report,
            rig: None,
        });
    }
    let scripted = match &config.plan.file {
        Some(file) => Some(Plan::load(file).map_err(|e| CellError::Plan(Box::new(e)))?),
        None => None,
    };
    let mut prepared = PreparedCell {
        config,
        board,
        camera_model,
        intrinsics_known,
        arm,
        joint_limits,
        start_joints,
        plan: Plan {
            waypoints: Vec::new(),
        },
        report: PlanReport {
            poses: Vec::new(),
            plan_problems: Vec::new(),
            notes: Vec::new(),
            intrinsics: None,
            given_order_move_time_s: None,
        },
        rig: None,
    };
    prepared.plan = match (scripted, &prepared.config.plan.generate) {
        (Some(plan), _) => plan,
        (None, Some(_)) if prepared.arm.is_none() => {
            return Err(no_kinematics(
                &prepared.config,
                "plan.generate",
                "generated views need the arm's kinematics to become joints: give `plan.file`, a taught plan (`taught-plan.yaml` of a hand-guided session), or plan by hand (`handeye console`)",
            ))
        }
        (None, Some(spec)) => Plan {
            waypoints: prepared
                .generate_views(spec)
                .into_iter()
                .map(Waypoint::LookAt)
                .collect(),
        },
        // Hand-guided with nothing to suggest: the person chooses every view.
        (None, None) if prepared.config.plan.manual => Plan {
            waypoints: Vec::new(),
        },
        (None, None) => {
            return Err(CellError::Backend(
                "plan: the config gives neither a plan file nor `generate:` (nor `manual: true`, hand-guided capture with no suggested views)".into(),
            ))
        }
    };
    if prepared.arm.is_none() {
        refuse_untaught_waypoints(&prepared)?;
        // No default start fits an arm of unknown joints: plan from the first taught pose (a
        // real arm's run checks again from where it stands).
        if let Some(first) = prepared.plan.waypoints.iter().find_map(Waypoint::joints) {
            prepared.start_joints = first;
        }
    }
    prepared.report = prepared.check();
    Ok(prepared)
}

/// A config error for an arm without kinematics (`robot.model: none`): the key that needs them.
fn no_kinematics(config: &CellConfig, key: &str, problem: &str) -> CellError {
    CellError::Config(Box::new(ConfigError::Inconsistent {
        file: config.file.clone(),
        key: key.into(),
        problem: format!("robot.model is none (no kinematics handeye knows): {problem}"),
    }))
}

/// Refuses, before anything opens, a plan an arm without kinematics cannot run: each waypoint
/// must be taught (joints with the flange pose the arm reported there). Names the plan file and
/// the waypoint's missing key.
fn refuse_untaught_waypoints(cell: &PreparedCell) -> Result<(), CellError> {
    let Some(file) = &cell.config.plan.file else {
        return Ok(());
    };
    let untaught = cell
        .plan
        .waypoints
        .iter()
        .enumerate()
        .find_map(|(i, w)| w.needs_kinematics().map(|(key, why)| (i, key, why)));
    match untaught {
        Some((i, key, why)) => Err(CellError::Plan(Box::new(PlanError::Waypoint {
            file: file.clone(),
            path: format!("waypoints[{i}].{key}"),
            problem: format!(
                "robot.model is none (no kinematics handeye knows for this arm): {why}"
            ),
        }))),
        None => Ok(()),
    }
}

impl PreparedCell {
    /// What a plan is checked against: this cell from the arm's current start joints.
    fn check_context(&self) -> CheckContext<'_> {
        CheckContext {
            arm: self.arm.as_ref(),
            joint_limits: &self.joint_limits,
            start_joints: self.start_joints,
            cell: &self.config.camera().nominal,
            workspace: &self.config.workspace,
            limits: &self.config.limits,
            camera: &self.camera_model,
            board: &self.board,
            margin_px: self.config.session.image_margin_px,
        }
    }

    /// Checks any plan against this cell (reach, limits, box, board in view, rotation spread)
    /// from the arm's current start joints.
    pub fn check_plan(&self, plan: &Plan) -> PlanReport {
        check_plan(plan, &self.check_context())
    }

    /// Generated views for this cell: the spec's cap, with the board pushed across this
    /// camera's image by the spec's `image_spread` (default: enough for estimating the
    /// intrinsics when the config has none, centred otherwise).
    pub fn generate_views(&self, spec: &GenerateSpec) -> Vec<LookAt> {
        let mut views = generate(spec);
        let spread = spec.image_spread.unwrap_or(if self.intrinsics_known {
            0.0
        } else {
            IMAGE_SPREAD_FOR_INTRINSICS
        });
        spread_across_image(
            &mut views,
            spread,
            &self.camera_model,
            &self.board,
            self.config.session.image_margin_px,
        );
        views
    }

    /// The plan check of the order that will run (the order of least move time unless
    /// `plan.reorder` is false).
    fn check(&self) -> PlanReport {
        if self.plan.waypoints.is_empty() {
            // Hand-guided with no plan (`plan.manual` alone): nothing to check or suggest.
            return PlanReport {
                poses: Vec::new(),
                plan_problems: Vec::new(),
                notes: vec![
                    "plan.manual with no plan: no views to suggest; every view is chosen by hand on the console".into(),
                ],
                intrinsics: None,
                given_order_move_time_s: None,
            };
        }
        let mut report =
            check_plan_ordered(&self.plan, &self.check_context(), self.config.plan.reorder);
        if !self.intrinsics_known {
            // The intrinsics come from this very run: a plan that cannot give them is refused.
            let (blocking, notes): (Vec<String>, Vec<String>) = report
                .notes
                .drain(..)
                .partition(|n| n.starts_with("these views do not constrain"));
            report.plan_problems.extend(blocking);
            report.notes = notes;
        }
        report
    }

    /// The next-best-pose planner of this camera over `candidates`, from the nominal cell, with
    /// the solver's noise model; stops at `target_uncertainty_mm` or `max_samples`.
    pub fn adaptive_planner(
        &self,
        candidates: Vec<(Pose, Joints)>,
        target_uncertainty_mm: f64,
        max_samples: usize,
    ) -> crate::plan::nbv::AdaptivePlanner {
        crate::plan::nbv::AdaptivePlanner::new(
            self.config.camera().setup,
            self.config.camera().nominal.camera_mount,
            self.config.camera().nominal.target_mount,
            candidates,
            self.config.solver.to_options(),
            target_uncertainty_mm,
            max_samples,
        )
    }

    /// Whether no real hardware moves (simulated or recorded robot).
    pub fn is_simulated(&self) -> bool {
        matches!(
            self.config.robot,
            RobotConfig::Sim { .. } | RobotConfig::Recorded { .. }
        )
    }

    /// Detector settings from the config.
    pub fn detector_options(&self) -> DetectorOptions {
        let d = self.config.detector;
        DetectorOptions {
            decimation: d.decimate,
            threads: d.threads,
            max_hamming: d.max_hamming,
            ..DetectorOptions::default()
        }
    }

    /// The session manifest for a validated plan.
    pub fn manifest(&self, plan: &[(Pose, Joints)]) -> SessionManifest {
        SessionManifest::new(self.config_path(), self.config.camera().setup, plan)
    }

    /// What the session solve needs, as this cell loaded it: the board and (when the config
    /// gives them) the intrinsics, so nothing is loaded twice.
    pub fn solve_inputs(&self) -> SolveInputs {
        SolveInputs {
            config: self.config.clone(),
            board: self.board.clone(),
            camera: self.intrinsics_known.then_some(self.camera_model),
        }
    }

    /// The files this cell was prepared from, each with the sha256 of its bytes: the config,
    /// the board, the intrinsics, the plan file and recorded robot poses (those the config has).
    pub fn inputs(&self) -> Result<Vec<InputFile>, SessionError> {
        let mut files = vec![
            ("config", self.config.file.clone()),
            ("target", self.config.camera().target.clone()),
        ];
        if let Some(file) = &self.config.camera().intrinsics {
            files.push(("intrinsics", file.clone()));
        }
        if let Some(file) = &self.config.plan.file {
            files.push(("plan", file.clone()));
        }
        if let RobotConfig::Recorded { poses, .. } = &self.config.robot {
            files.push(("robot.poses", poses.clone()));
        }
        // A several-camera cell's other cameras: their boards and lenses, once each.
        for (_, other) in self.rig.iter().flat_map(|rig| &rig.others) {
            for (role, file) in [
                ("target", other.config.camera().target.clone()),
                (
                    "intrinsics",
                    other.config.camera().intrinsics.clone().unwrap_or_default(),
                ),
            ] {
                if !file.as_os_str().is_empty() && !files.iter().any(|(_, f)| *f == file) {
                    files.push((role, file));
                }
            }
        }
        files
            .iter()
            .map(|(role, file)| InputFile::hash(role, file))
            .collect()
    }

    /// The config file as a session manifest records it (absolute when it can be).
    pub fn config_path(&self) -> std::path::PathBuf {
        std::fs::canonicalize(&self.config.file).unwrap_or_else(|_| self.config.file.clone())
    }

    /// The configured intrinsics file and its `camera_name` when it is the shipped placeholder
    /// (`camera_name` containing [`PLACEHOLDER_CAMERA_NAME`]): good for `plan check`, useless for
    /// calibrating, so a run refuses it before anything moves.
    pub fn placeholder_intrinsics(&self) -> Option<(std::path::PathBuf, String)> {
        let file = self.config.camera().intrinsics.as_ref()?;
        let text = std::fs::read_to_string(file).ok()?;
        let yaml: serde_yaml_ng::Value = serde_yaml_ng::from_str(&text).ok()?;
        let name = yaml.get("camera_name")?.as_str()?;
        name.to_ascii_uppercase()
            .contains(PLACEHOLDER_CAMERA_NAME)
            .then(|| (file.clone(), name.to_string()))
    }

    /// The lens and board the simulated camera renders with: the sim camera's own `intrinsics`
    /// and `target` when it names them (a camera calibrated wrongly, a board printed at another
    /// scale), else the cell's.
    fn sim_world(&self) -> Result<(CameraModel, Target), CellError> {
        let CameraConfig::Sim {
            intrinsics, target, ..
        } = &self.config.camera().backend
        else {
            return Ok((self.camera_model, self.board.clone()));
        };
        let lens = match intrinsics {
            Some(file) if self.intrinsics_known => {
                CameraModel::load(file).map_err(|source| CellError::Intrinsics {
                    file: file.clone(),
                    source: Box::new(source),
                })?
            }
            _ => self.camera_model,
        };
        let board = match target {
            Some(file) => Target::load(file).map_err(|source| CellError::Board {
                file: file.clone(),
                source: Box::new(source),
            })?,
            None => self.board.clone(),
        };
        Ok((lens, board))
    }

    /// The simulator's ground truth, which the simulated backends render from.
    fn sim_truth(&self) -> Result<CellTransforms, CellError> {
        self.config.camera().simulation.ok_or_else(|| {
            CellError::Backend(
                "a simulated backend needs `simulation:` (the cell's true transforms) in the config"
                    .into(),
            )
        })
    }

    /// The arm's kinematics, for what cannot do without them (the simulated arm).
    pub fn kinematics(&self) -> Result<UrModel, CellError> {
        self.arm.clone().ok_or_else(|| {
            no_kinematics(
                &self.config,
                "robot.model",
                "this backend needs a UR model (`ur5e`, `ur10e`, ...)",
            )
        })
    }

    /// Opens the arm the config names, then its camera and a several-camera cell's other
    /// cameras beside it, each through one opener ([`PreparedCell::open_camera_beside`]): a
    /// simulated camera renders from the pose the arm gives (the simulator's true pose, or the
    /// pose a real arm reports), a ROS 2 camera subscribes on the arm's node, a folder camera
    /// serves the recorded pose's frame. A camera that needs nothing of the arm (USB) opens
    /// first, so a missing camera never leaves a connected arm behind.
    pub fn open_hardware(&self) -> Result<Hardware, CellError> {
        let standalone = match &self.config.camera().backend {
            CameraConfig::Uvc { .. } => Some(uvc::open_camera(
                &self.config.camera().backend,
                self.camera_model,
            )?),
            CameraConfig::Sim { .. } | CameraConfig::Files { .. } | CameraConfig::Ros2(_) => None,
        };
        let (robot, arm) = self.open_arm()?;
        let camera = match standalone {
            Some(camera) => camera,
            None => self.open_camera_beside(&arm)?,
        };
        let mut hardware = Hardware {
            robot,
            camera,
            others: Vec::new(),
        };
        for (name, other) in self.rig.iter().flat_map(|rig| &rig.others) {
            let camera = other
                .open_camera_beside(&arm)
                .map_err(|e| CellError::Backend(format!("camera `{name}`: {e}")))?;
            hardware.others.push(camera);
        }
        Ok(hardware)
    }

    /// Opens the arm the config names, with what its cameras need of it.
    fn open_arm(&self) -> Result<(Box<dyn Robot>, ArmSide), CellError> {
        match &self.config.robot {
            RobotConfig::Sim { .. } => {
                let robot = sim::arm(&self.config, self.kinematics()?, self.start_joints)?;
                let arm = robot.clone();
                let side = ArmSide::Flange(Box::new(move || {
                    let arm = arm.clone();
                    Box::new(move || arm.lock().true_base_from_flange())
                }));
                Ok((Box::new(robot), side))
            }
            RobotConfig::Ur { .. } => {
                let robot = self.open_ur()?;
                let arm = robot.clone();
                let side = ArmSide::Flange(Box::new(move || arm.reported_flange()));
                Ok((Box::new(robot), side))
            }
            RobotConfig::Ros2(_) => {
                let (robot, node) = ros2::open_arm(&self.config, self.arm.clone())?;
                Ok((robot, ArmSide::Ros2(node)))
            }
            RobotConfig::Recorded { .. } => {
                let plan = self.report.validated().ok_or_else(|| {
                    CellError::Backend("the recorded poses failed their checks".into())
                })?;
                let (robot, selector) = recorded::arm(&self.config, &plan)?;
                Ok((
                    robot,
                    ArmSide::Recorded {
                        selector,
                        poses: plan.len(),
                    },
                ))
            }
        }
    }

    /// Opens this cell's camera beside an arm opened already: a simulated camera renders from
    /// the arm's pose, a USB camera needs nothing of the arm, a ROS 2 camera subscribes on the
    /// arm's node, a folder camera follows the recorded arm.
    pub fn open_camera_beside(&self, arm: &ArmSide) -> Result<Box<dyn Camera>, CellError> {
        match (&self.config.camera().backend, arm) {
            (CameraConfig::Sim { .. }, ArmSide::Flange(flange)) => {
                let truth = self.sim_truth()?;
                let (lens, board) = self.sim_world()?;
                let camera = sim::camera(&self.config, truth, flange(), lens, board)?
                    .reporting(self.camera_model);
                Ok(Box::new(camera))
            }
            (CameraConfig::Uvc { .. }, ArmSide::Flange(_)) => {
                uvc::open_camera(&self.config.camera().backend, self.camera_model)
            }
            (CameraConfig::Ros2(_), ArmSide::Ros2(node)) => {
                ros2::open_camera(&self.config, node, self.camera_model)
            }
            (CameraConfig::Files { .. }, ArmSide::Recorded { selector, poses }) => {
                recorded::open_camera(&self.config, selector, *poses, self.camera_model)
            }
            (camera, _) => Err(CellError::Backend(format!(
                "a camera with backend `{}` beside the `{}` arm is not available (sim or uvc cameras beside a sim or ur arm are, files cameras beside a recorded arm, ros2 cameras beside a ros2 arm)",
                camera_name(camera),
                robot_name(&self.config.robot)
            ))),
        }
    }

    /// Connects to the Universal Robots controller the config names; shared, so a simulated
    /// camera can follow the pose it reports.
    #[cfg(feature = "ur-rtde")]
    fn open_ur(&self) -> Result<Shared<dyn Robot>, CellError> {
        let RobotConfig::Ur {
            host,
            connect_timeout_s,
            ..
        } = &self.config.robot
        else {
            return Err(CellError::Backend("the robot backend is not `ur`".into()));
        };
        let mut ur = handeye_robot::ur::UrRobotConfig::new(host.clone());
        ur.connect_timeout = std::time::Duration::from_secs_f64(*connect_timeout_s);
        ur.workspace = Some(self.config.workspace);
        ur.model = self.arm.clone();
        let robot =
            handeye_robot::ur::UrRobot::connect(ur).map_err(|e| CellError::Robot(Box::new(e)))?;
        Ok(Shared::new_dyn(robot))
    }

    /// Without the `ur-rtde` feature there is no UR driver in the binary.
    #[cfg(not(feature = "ur-rtde"))]
    fn open_ur(&self) -> Result<Shared<dyn Robot>, CellError> {
        Err(CellError::Backend(
            "this build has no Universal Robots driver: build with `--features ur-rtde` (see README)".into(),
        ))
    }

    /// What the session loop needs to run this cell's validated `plan` into `folder`.
    pub fn session_setup(
        &self,
        folder: SessionFolder,
        plan: Vec<(Pose, Joints)>,
        stop: Arc<AtomicBool>,
    ) -> SessionSetup {
        SessionSetup {
            folder,
            setup: self.config.camera().setup,
            plan,
            limits: self.config.limits,
            settle: self.config.settle(),
            settle_by_speed: self.config.settle_by_speed(),
            reorder: self.config.plan.reorder,
            rig: None,
            max_reprojection_rms_px: self.config.session.max_reprojection_rms_px,
            board: self.board.clone(),
            detector: self.detector_options(),
            stop,
            estimate_intrinsics: !self.intrinsics_known,
            move_check: (!matches!(self.config.robot, RobotConfig::Recorded { .. })).then(|| {
                MoveCheck {
                    arm: self.arm.clone(),
                    joint_limits: self.joint_limits.clone(),
                    workspace: self.config.workspace,
                }
            }),
        }
    }

    /// Checks the plan again from where the arm really stands (a real arm's start is only known
    /// once connected); returns the validated plan or the report that rejects it.
    pub fn recheck_from(
        &mut self,
        start_joints: Joints,
    ) -> Result<Vec<(Pose, Joints)>, &PlanReport> {
        // Recorded poses were taken already: there is no arm to move and nothing to re-check.
        if !matches!(self.config.robot, RobotConfig::Recorded { .. }) {
            self.start_joints = start_joints;
            self.report = self.check();
        }
        self.report.validated().ok_or(&self.report)
    }
}

/// What a camera opened beside an arm may need of it.
pub enum ArmSide {
    /// The arm's flange pose, as a simulated camera follows it (the simulator's true pose for a
    /// simulated arm, the reported one for a real arm): each call makes a source.
    Flange(Box<dyn Fn() -> handeye_camera::sim::TrueFlangePose>),
    /// A ROS 2 arm: its node, on which a ROS 2 camera subscribes.
    Ros2(ros2::Ros2Node),
    /// Recorded poses: a folder camera serves the frame of the pose the robot is at.
    Recorded {
        /// Set by the recorded robot on each move.
        selector: handeye_camera::files::FrameSelector,
        /// Poses recorded (a frame each).
        poses: usize,
    },
}

fn robot_name(r: &RobotConfig) -> &'static str {
    match r {
        RobotConfig::Sim { .. } => "sim",
        RobotConfig::Ur { .. } => "ur",
        RobotConfig::Recorded { .. } => "recorded",
        RobotConfig::Ros2(_) => "ros2",
    }
}

fn camera_name(c: &CameraConfig) -> &'static str {
    match c {
        CameraConfig::Sim { .. } => "sim",
        CameraConfig::Files { .. } => "files",
        CameraConfig::Uvc { .. } => "uvc",
        CameraConfig::Ros2(_) => "ros2",
    }
}
