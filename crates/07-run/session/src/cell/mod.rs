//! A cell made ready to run: the config read, the board and intrinsics loaded, the plan built and
//! checked, and — only when asked — the robot and camera backends the config names opened.
//! This is the one place that maps config backends to implementations. `run` drives a prepared
//! cell through a whole calibration run (what `handeye run` does).

pub mod bag;
pub mod cameras;
pub mod recorded;
pub mod replay;
pub mod ros2;
pub mod run;
pub mod sim;
pub mod uvc;

use sim::Shared;

use std::path::Path;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;

use crate::{SessionCamera, SessionSetup};
use handeye_camera::Camera;
use handeye_config::{CameraConfig, CellCamera, CellConfig, ConfigError, RobotConfig};
use handeye_core::camera_model::CameraModel;
use handeye_core::error_text::error_chain;
use handeye_core::geometry::Pose;
use handeye_core::setup::CellTransforms;
use handeye_plan::check::MoveCheck;
use handeye_plan::check::{check_plan, check_plan_ordered, CheckContext, PlanReport};
use handeye_plan::generate::{spread_across_image, IMAGE_SPREAD_FOR_INTRINSICS};
use handeye_plan::{generate, GenerateSpec, LookAt, Plan, PlanError, Waypoint};
use handeye_records::{InputFile, SessionError, SessionFolder, SessionManifest, SolveInputs};
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
fn file_exists(config: &CellConfig, key: &str, path: &Path) -> Result<(), CellError> {
    if path.exists() {
        return Ok(());
    }
    let folder = handeye_core::folder_of(&config.file);
    let folder_shown = std::path::absolute(folder).unwrap_or_else(|_| folder.to_path_buf());
    Err(CellError::Config(Box::new(ConfigError::Inconsistent {
        file: config.file.clone(),
        key: key.into(),
        problem: format!(
            "{} does not exist. Paths in a config are relative to the config file's own folder ({}): a config copied from configs/ needs its files copied beside it, or absolute paths",
            path.display(),
            folder_shown.display()
        ),
    })))
}

/// [`file_exists`] for a camera's board, intrinsics and simulated lens.
fn referenced_files_exist(config: &CellConfig, camera: &CellCamera) -> Result<(), CellError> {
    let referenced = [
        Some(("target", camera.target.as_path())),
        camera.intrinsics.as_deref().map(|p| ("intrinsics", p)),
        camera.sim_lens().map(|p| ("camera.intrinsics", p)),
    ];
    referenced
        .into_iter()
        .flatten()
        .try_for_each(|(key, path)| file_exists(config, key, path))
}

/// The robot and cameras of a cell, opened.
pub struct Hardware {
    /// The arm.
    pub robot: Box<dyn Robot>,
    /// The cameras in the order a session grabs them: the planner camera first, then the others
    /// in config order ([`PreparedCell::run_order`]).
    pub cameras: Vec<Box<dyn Camera>>,
    /// A ROS 2 cell's node: what the graph publishes is read on it (`None` for other arms).
    pub ros2: Option<ros2::Ros2Node>,
}

impl Hardware {
    /// The arm and the cameras, as a session takes them.
    pub fn devices(&mut self) -> (&mut dyn Robot, Vec<&mut dyn Camera>) {
        let cameras = self
            .cameras
            .iter_mut()
            .map(|c| c.as_mut() as &mut dyn Camera);
        (self.robot.as_mut(), cameras.collect())
    }
}

/// What the shipped placeholder intrinsics file has in its `camera_name`
/// (`configs/cameras/CHANGE-ME-usb-camera-1280x720.yaml`).
pub const PLACEHOLDER_CAMERA_NAME: &str = "CHANGE-ME";

/// One camera of a cell, made ready: its board and lens loaded.
pub struct PreparedCamera {
    /// The board it looks at.
    pub board: Target,
    /// Its intrinsics (without configured intrinsics: the sim camera's lens, for planning and
    /// rendering only — the run estimates the intrinsics).
    pub camera_model: CameraModel,
    /// Whether the intrinsics are known: from the config's file, or (a ROS 2 camera without
    /// one) from its driver's camera_info topic, [`INTRINSICS_FROM_TOPIC_FILE`]; otherwise they
    /// are estimated after the run.
    pub intrinsics_known: bool,
}

/// The intrinsics a ROS 2 camera driver published, kept in the session of a run (a replay of a
/// config without an `intrinsics:` file uses them; with one, the solve compares the two).
pub use handeye_records::solve::DRIVER_CALIBRATION_FILE as INTRINSICS_FROM_TOPIC_FILE;

/// The cell as the one-camera session `folder` saw it: `config` itself in the one-camera form;
/// a listed config (`cameras:`) as the camera whose folder `folder` is (`<root>/cameras/<name>`,
/// [`CellConfig::for_camera`]) sees it, so a several-camera session's camera folder is solved,
/// replayed, reported and read from Python as a one-camera session of the same poses. A folder
/// whose camera the config does not list (or a listed config of several cameras given for a
/// flat session folder) is refused, naming the config's cameras.
pub fn config_of_camera_folder(
    config: CellConfig,
    folder: &Path,
) -> Result<CellConfig, ConfigError> {
    if !config.listed {
        return config.single_camera();
    }
    let name = cameras::session_of_camera_folder(folder)
        .and_then(|_| folder.file_name())
        .map(|n| n.to_string_lossy().into_owned());
    let index = match &name {
        Some(name) => config.cameras.iter().position(|c| &c.name == name),
        None if config.cameras.len() == 1 => Some(0),
        None => None,
    };
    match index {
        Some(i) => Ok(config.for_camera(i)),
        None => {
            let names: Vec<&str> = config.cameras.iter().map(|c| c.name.as_str()).collect();
            Err(ConfigError::Inconsistent {
                problem: match name {
                    Some(name) => format!(
                        "session folder {} is camera `{name}`'s, and this config's cameras are {}: give the config the session was recorded with",
                        folder.display(),
                        names.join(", ")
                    ),
                    None => format!(
                        "session folder {} is a one-camera session, and this config lists {} cameras ({}): give a one-camera config, or solve a several-camera session's folder",
                        folder.display(),
                        names.len(),
                        names.join(", ")
                    ),
                },
                file: config.file,
                key: "cameras".into(),
            })
        }
    }
}

/// The cell config a recorded session is solved or replayed with: `given`
/// (`--config`), else `recorded`, the one its manifest names. When the recorded one does not
/// load, the error says it is the session's and that `--config` names another (a session
/// copied from another machine, a config moved or renamed since).
pub fn session_config(given: Option<&Path>, recorded: &Path) -> anyhow::Result<CellConfig> {
    use anyhow::Context;
    match given {
        Some(file) => CellConfig::load(file).context("reading the cell config"),
        None => CellConfig::load(recorded).with_context(|| {
            format!(
                "reading the cell config the session recorded ({}): give `--config FILE` if it was moved or the session was copied from elsewhere",
                recorded.display()
            )
        }),
    }
}

/// A cell whose config, boards, intrinsics and plan are loaded and checked: one arm, one plan,
/// and its cameras (one, or several sharing the arm's poses).
pub struct PreparedCell {
    /// The config (every camera; `config.camera()` is the one the plan is made for).
    pub config: CellConfig,
    /// The cameras, in config order (`config.planner` is the plan's).
    pub cameras: Vec<PreparedCamera>,
    /// The arm's kinematics (a UR model, its joint limits the cell's): its published model, or
    /// with `solver.arm_model` that model as an earlier session estimated it (plans are checked
    /// and moves solved through it; `UrModel::published` is what the controller reports
    /// through); `None` for a ROS 2 arm handeye has no model of (`robot.model: none`), which
    /// replays taught plans only.
    pub arm: Option<UrModel>,
    /// The cell's joint ranges, `(min, max)` rad (`robot.joint_ranges_deg` or the defaults).
    pub joint_limits: Vec<(f64, f64)>,
    /// Where the arm starts (sim) or is assumed to start for planning (real arm: read at connect).
    pub start_joints: Joints,
    /// The plan.
    pub plan: Plan,
    /// The plan check (made for the planner camera).
    pub report: PlanReport,
}

/// Loads everything a config names and checks the plan. Nothing moves.
pub fn prepare(config_file: &Path) -> Result<PreparedCell, CellError> {
    let config = CellConfig::load(config_file).map_err(|e| CellError::Config(Box::new(e)))?;
    prepare_config(config)
}

/// Loads camera `index`'s board and lens (a listed camera's errors name it).
fn prepare_camera(config: &CellConfig, index: usize) -> Result<PreparedCamera, CellError> {
    let camera = &config.cameras[index];
    let prepared = referenced_files_exist(config, camera).and_then(|()| {
        let board = Target::load(&camera.target).map_err(|source| CellError::Board {
            file: camera.target.clone(),
            source: Box::new(source),
        })?;
        // A ROS 2 camera driver publishes its calibration: without a file, read, not estimated.
        if let (None, CameraConfig::Ros2(c)) = (&camera.intrinsics, &camera.backend) {
            if let Some(topic) = &c.camera_info_topic {
                let camera_model = ros2::intrinsics_from_topic(config, topic, c.frame_timeout_s)?;
                return Ok(PreparedCamera {
                    board,
                    camera_model,
                    intrinsics_known: true,
                });
            }
        }
        // Without intrinsics the plan is checked (and the sim renders) with the sim camera's
        // lens; the run then records corners only and the intrinsics are estimated afterwards.
        let intrinsics_known = camera.intrinsics.is_some();
        let model_file = match (&camera.intrinsics, camera.sim_lens(), &config.robot, &camera.backend) {
            (Some(file), ..) => Some(file.clone()),
            (None, Some(lens), ..) => Some(lens.to_path_buf()),
            // Recorded frames: a provisional lens of the frames' size (see `recorded::provisional_model`).
            (None, None, RobotConfig::Recorded(_), CameraConfig::Files(_)) => None,
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
            None => recorded::provisional_model(&config.for_camera(index))?,
        };
        Ok(PreparedCamera {
            board,
            camera_model,
            intrinsics_known,
        })
    });
    prepared.map_err(|e| match config.listed {
        true => CellError::Backend(format!("camera `{}`: {}", camera.name, error_chain(&e))),
        false => e,
    })
}

/// [`prepare`] of a config already read: every camera's board and lens, then the arm and the
/// plan (made and checked for the planner camera).
pub fn prepare_config(config: CellConfig) -> Result<PreparedCell, CellError> {
    let cameras = (0..config.cameras.len())
        .map(|index| prepare_camera(&config, index))
        .collect::<Result<Vec<_>, _>>()?;
    if let Some(file) = &config.plan.file {
        file_exists(&config, "plan.file", file)?;
    }
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
            // An earlier session's estimate of this arm (solver.arm_model): plans are checked
            // and moves solved through it, so the flange goes where the plan says; read here,
            // before anything opens or moves.
            match &config.solver.arm_model {
                Some(file) => {
                    let (mut calibrated, _) =
                        handeye_records::solve::given_arm_model(file, &config)
                            .map_err(|e| CellError::Backend(e.to_string()))?;
                    calibrated.joint_limits = arm.joint_limits;
                    Some(calibrated)
                }
                None => Some(arm),
            }
        }
        None => None,
    };
    let start_joints = match config.robot.backend().start_joints_deg() {
        Some(start_joints_deg) => Joints::from(start_joints_deg.map(f64::to_radians)),
        None => Joints::from(handeye_config::default_start_joints()),
    };
    let mut prepared = PreparedCell {
        config,
        cameras,
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
    };
    if !prepared.config.robot.backend().moves() {
        let camera = prepared.camera();
        let (plan, report) = recorded::plan(&prepared.config, &camera.camera_model, &camera.board)?;
        prepared.plan = plan;
        prepared.report = report;
        return Ok(prepared);
    }
    let scripted = match &prepared.config.plan.file {
        Some(file) => Some(Plan::load(file).map_err(|e| CellError::Plan(Box::new(e)))?),
        None => None,
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
    // What the plan determines of the arm's model, when the config estimates one.
    if let (Some(arm), Some(plan)) = (&prepared.arm, prepared.report.validated()) {
        let note = handeye_records::solve::plan_observability(
            &prepared.config,
            arm,
            &prepared.config.camera().nominal,
            &plan,
        );
        prepared.report.notes.extend(note);
    }
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
        let camera = self.camera();
        CheckContext {
            arm: self.arm.as_ref(),
            joint_limits: &self.joint_limits,
            start_joints: self.start_joints,
            cell: &self.config.camera().nominal,
            workspace: &self.config.workspace,
            limits: &self.config.limits,
            camera: &camera.camera_model,
            board: &camera.board,
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
        let camera = self.camera();
        let spread = spec.image_spread.unwrap_or(if camera.intrinsics_known {
            0.0
        } else {
            IMAGE_SPREAD_FOR_INTRINSICS
        });
        spread_across_image(
            &mut views,
            spread,
            &camera.camera_model,
            &camera.board,
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
        if !self.camera().intrinsics_known {
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

    /// The next-best-pose planner of camera `camera` over `candidates`, from the nominal cell,
    /// with the solver's noise model; stops at `target_uncertainty_mm` or `max_samples`.
    pub fn adaptive_planner(
        &self,
        camera: usize,
        candidates: Vec<(Pose, Joints)>,
        target_uncertainty_mm: f64,
        max_samples: usize,
    ) -> handeye_plan::nbv::AdaptivePlanner {
        let camera = &self.config.cameras[camera];
        handeye_plan::nbv::AdaptivePlanner::new(
            camera.setup,
            camera.nominal.camera_mount,
            camera.nominal.target_mount,
            candidates,
            self.config.solver.to_options(),
            target_uncertainty_mm,
            max_samples,
        )
    }

    /// Whether no real hardware moves (simulated or recorded robot).
    pub fn is_simulated(&self) -> bool {
        let robot = self.config.robot.backend();
        robot.simulated() || !robot.moves()
    }

    /// Detector settings from the config.
    pub fn detector_options(&self) -> DetectorOptions {
        self.config.detector.options()
    }

    /// The camera the plan is made for (`config.planner`).
    pub fn camera(&self) -> &PreparedCamera {
        &self.cameras[self.config.planner]
    }

    /// The cameras other than the planner's, in config order, by index.
    pub fn others(&self) -> impl Iterator<Item = usize> + '_ {
        (0..self.cameras.len()).filter(|&c| c != self.config.planner)
    }

    /// Whether camera `camera` is expected to see its board with the flange at
    /// `base_from_flange`: at least half the board's corners inside its image, by the nominal
    /// mounts, its lens and the configured image margin.
    pub fn sees_board(&self, camera: usize, base_from_flange: &Pose) -> bool {
        let PreparedCamera {
            board,
            camera_model,
            ..
        } = &self.cameras[camera];
        let points = board.points();
        let margin = self.config.session.image_margin_px;
        let (w, h) = (
            f64::from(camera_model.width),
            f64::from(camera_model.height),
        );
        let camera_from_target = self.config.cameras[camera]
            .nominal
            .camera_from_target(base_from_flange);
        let inside = points
            .iter()
            .filter_map(|(_, _, point)| camera_model.project(&(camera_from_target * point)))
            .filter(|px| {
                px.x >= margin && px.y >= margin && px.x <= w - margin && px.y <= h - margin
            })
            .count();
        2 * inside >= points.len()
    }

    /// The session manifest of camera `camera` for a validated plan.
    pub fn manifest(&self, camera: usize, plan: &[(Pose, Joints)]) -> SessionManifest {
        SessionManifest::new(self.config_path(), self.config.cameras[camera].setup, plan)
    }

    /// What the session solve of the planner camera needs, as this cell loaded it: the board and
    /// (when the config gives them) the intrinsics, so nothing is loaded twice.
    pub fn solve_inputs(&self) -> SolveInputs {
        let camera = self.camera();
        SolveInputs {
            config: self.config.for_camera(self.config.planner),
            board: camera.board.clone(),
            camera: camera.intrinsics_known.then_some(camera.camera_model),
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
        files.extend(self.config.robot.backend().input_files());
        // A several-camera cell's other cameras: their boards and lenses, once each.
        for other in self.others().map(|c| &self.config.cameras[c]) {
            for (role, file) in [
                ("target", other.target.clone()),
                ("intrinsics", other.intrinsics.clone().unwrap_or_default()),
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
    fn sim_world(&self, camera: usize) -> Result<(CameraModel, Target), CellError> {
        let prepared = &self.cameras[camera];
        let CameraConfig::Sim(handeye_config::SimCamera {
            intrinsics, target, ..
        }) = &self.config.cameras[camera].backend
        else {
            return Ok((prepared.camera_model, prepared.board.clone()));
        };
        let lens = match intrinsics {
            Some(file) if prepared.intrinsics_known => {
                CameraModel::load(file).map_err(|source| CellError::Intrinsics {
                    file: file.clone(),
                    source: Box::new(source),
                })?
            }
            _ => prepared.camera_model,
        };
        let board = match target {
            Some(file) => Target::load(file).map_err(|source| CellError::Board {
                file: file.clone(),
                source: Box::new(source),
            })?,
            None => prepared.board.clone(),
        };
        Ok((lens, board))
    }

    /// The simulator's ground truth, which the simulated backends render from.
    fn sim_truth(&self, camera: usize) -> Result<CellTransforms, CellError> {
        self.config.cameras[camera].simulation.ok_or_else(|| {
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
        let planner = self.config.planner;
        let mut standalone = match &self.config.camera().backend {
            CameraConfig::Uvc(usb) => Some(uvc::open_camera(usb, self.camera().camera_model)?),
            CameraConfig::Sim(_) | CameraConfig::Files(_) | CameraConfig::Ros2(_) => None,
        };
        let (robot, arm) = self.open_arm()?;
        let ros2 = match &arm {
            ArmSide::Ros2(node) => Some(node.clone()),
            ArmSide::Flange(_) | ArmSide::Recorded { .. } => None,
        };
        let mut cameras = Vec::with_capacity(self.cameras.len());
        for c in self.run_order() {
            let camera = match (c == planner, standalone.take()) {
                (true, Some(camera)) => camera,
                _ => self
                    .open_camera_beside(c, &arm)
                    .map_err(|e| match self.config.listed {
                        true => CellError::Backend(format!(
                            "camera `{}`: {e}",
                            self.config.cameras[c].name
                        )),
                        false => e,
                    })?,
            };
            cameras.push(camera);
        }
        Ok(Hardware {
            robot,
            cameras,
            ros2,
        })
    }

    /// The cameras in the order a session grabs them: the planner camera, then the others.
    pub fn run_order(&self) -> impl Iterator<Item = usize> + '_ {
        std::iter::once(self.config.planner).chain(self.others())
    }

    /// Opens the arm the config names, with what its cameras need of it.
    fn open_arm(&self) -> Result<(Box<dyn Robot>, ArmSide), CellError> {
        match &self.config.robot {
            RobotConfig::Sim(_) => {
                // The simulated controller reports through the arm's published model, whatever
                // model handeye plans with.
                let published = self.kinematics()?.published();
                let robot = sim::arm(&self.config, published, self.start_joints)?;
                let arm = robot.clone();
                let side = ArmSide::Flange(Box::new(move || {
                    let arm = arm.clone();
                    Box::new(move || arm.lock().true_base_from_flange())
                }));
                Ok((Box::new(robot), side))
            }
            RobotConfig::Ur(_) => {
                let robot = self.open_ur()?;
                let arm = robot.clone();
                let side = ArmSide::Flange(Box::new(move || arm.reported_flange()));
                Ok((Box::new(robot), side))
            }
            RobotConfig::Ros2(_) => {
                let (robot, node) = ros2::open_arm(&self.config, self.arm.clone())?;
                Ok((robot, ArmSide::Ros2(node)))
            }
            RobotConfig::Recorded(_) => {
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

    /// Opens camera `camera` beside an arm opened already: a simulated camera renders from the
    /// arm's pose, a USB camera needs nothing of the arm, a ROS 2 camera subscribes on the arm's
    /// node, a folder camera follows the recorded arm. (The backends take the cell as this
    /// camera alone sees it, [`CellConfig::for_camera`].)
    pub fn open_camera_beside(
        &self,
        camera: usize,
        arm: &ArmSide,
    ) -> Result<Box<dyn Camera>, CellError> {
        let config = self.config.for_camera(camera);
        let model = self.cameras[camera].camera_model;
        match (&config.camera().backend, arm) {
            (CameraConfig::Sim(_), ArmSide::Flange(flange)) => {
                let truth = self.sim_truth(camera)?;
                let (lens, board) = self.sim_world(camera)?;
                let camera = sim::camera(&config, truth, flange(), lens, board)?.reporting(model);
                Ok(Box::new(camera))
            }
            (CameraConfig::Uvc(usb), ArmSide::Flange(_)) => uvc::open_camera(usb, model),
            (CameraConfig::Ros2(_), ArmSide::Ros2(node)) => ros2::open_camera(&config, node, model),
            (CameraConfig::Files(_), ArmSide::Recorded { selector, poses }) => {
                recorded::open_camera(&config, selector, *poses, model)
            }
            (camera, _) => Err(CellError::Backend(format!(
                "a camera with backend `{}` beside the `{}` arm is not available (sim or uvc cameras beside a sim or ur arm are, files cameras beside a recorded arm, ros2 cameras beside a ros2 arm)",
                camera.backend().name(),
                self.config.robot.backend().name()
            ))),
        }
    }

    /// Connects to the Universal Robots controller the config names; shared, so a simulated
    /// camera can follow the pose it reports.
    #[cfg(feature = "ur-rtde")]
    fn open_ur(&self) -> Result<Shared<dyn Robot>, CellError> {
        let RobotConfig::Ur(handeye_config::UrRobot {
            host,
            connect_timeout_s,
            ..
        }) = &self.config.robot
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

    /// What the session loop needs to run this cell's validated `plan` into `folder`: the
    /// planner camera records there (a several-camera cell adds the others with
    /// [`PreparedCell::session_cameras`]).
    pub fn session_setup(
        &self,
        folder: SessionFolder,
        plan: Vec<(Pose, Joints)>,
        stop: Arc<AtomicBool>,
    ) -> SessionSetup {
        SessionSetup {
            resume_folder: folder.root().to_path_buf(),
            cameras: vec![self.session_camera(self.config.planner, folder)],
            named_cameras: self.config.listed,
            plan,
            limits: self.config.limits,
            settle: self.config.settle(),
            settle_by_speed: self.config.settle_by_speed(),
            reorder: self.config.plan.reorder,
            max_reprojection_rms_px: self.config.session.max_reprojection_rms_px,
            detector: self.detector_options(),
            stop,
            move_check: self.config.robot.backend().moves().then(|| MoveCheck {
                arm: self.arm.clone(),
                joint_limits: self.joint_limits.clone(),
                workspace: self.config.workspace,
            }),
        }
    }

    /// Camera `camera` of a session, recording into `folder`.
    pub fn session_camera(&self, camera: usize, folder: SessionFolder) -> SessionCamera {
        SessionCamera {
            name: self.config.cameras[camera].name.clone(),
            folder,
            setup: self.config.cameras[camera].setup,
            board: self.cameras[camera].board.clone(),
            estimate_intrinsics: !self.cameras[camera].intrinsics_known,
        }
    }

    /// Checks the plan again from where the arm really stands (a real arm's start is only known
    /// once connected); returns the validated plan or the report that rejects it.
    pub fn recheck_from(
        &mut self,
        start_joints: Joints,
    ) -> Result<Vec<(Pose, Joints)>, &PlanReport> {
        // Recorded poses were taken already: there is no arm to move and nothing to re-check.
        if self.config.robot.backend().moves() {
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
