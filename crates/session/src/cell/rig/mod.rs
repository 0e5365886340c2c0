//! A run of a cell with several cameras (`config::rig`): one arm, one plan, every camera
//! capturing at every pose, one joint solve (`solve.rs`).
//!
//! The plan is made and checked for the planner camera (the first eye-in-hand one, see
//! `RigConfig::planner`); at each pose the arm moves and settles once, then every camera grabs a
//! frame and looks for its board (eye-in-hand cameras the board fixed in the cell, eye-to-hand
//! cameras the board on the flange). Arm time is shared: the moves and settling are paid once
//! for all cameras.
//!
//! The session folder holds `rig.yaml` (the cameras and the plan) and one folder per camera,
//! `cameras/<name>/`, in the one-camera layout (`session.yaml`, `frames/NNN.png`,
//! `poses/NNN.yaml`, `samples.yaml`): a camera's folder is a one-camera session of the same
//! poses. A pose counts as done when every camera has its record, so a run killed between two
//! cameras' records visits that pose again on `--resume` (records are written whole or not at
//! all). A camera whose grab fails is named, its records so far are kept, and the run goes on
//! with the others; it is not asked again in this run.

pub mod solve;

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Instant;

use serde::{Deserialize, Serialize};

use super::sim::Shared;
use super::{prepare_config, CellError, PreparedCell};
use crate::config::rig::RigConfig;
use crate::config::{CameraConfig, ConfigError, RobotConfig};
use crate::session::driver::{measure, rebuild_samples};
use crate::session::{PlannedPose, PoseVisit, SessionError, SessionFolder, SessionManifest};
use handeye_camera::Camera;
use handeye_core::camera_model::CameraModel;
use handeye_core::geometry::Pose;
use handeye_core::setup::Setup;
use handeye_core::yaml_file::{read_yaml, write_yaml};
use handeye_robot::{Joints, Robot};
use handeye_solve::rig::MIN_VIEWS_PER_CAMERA;
use handeye_vision::{Target, TargetDetector};

pub use solve::{solve_rig_folder, RigResultFile, RigSolveError};

/// Why a several-camera run failed.
#[derive(Debug, thiserror::Error)]
pub enum RigRunError {
    /// The config is wrong.
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// A camera's board, lens or the plan could not be prepared.
    #[error("camera `{camera}`: {source}")]
    Cell {
        /// The camera.
        camera: String,
        /// What went wrong.
        #[source]
        source: Box<CellError>,
    },
    /// The plan failed its checks for the planner camera.
    #[error("the plan fails its checks for camera `{camera}`: {problems}")]
    Plan {
        /// The planner camera.
        camera: String,
        /// The checks' findings.
        problems: String,
    },
    /// A backend combination this build cannot open.
    #[error("{0}")]
    Backend(String),
    /// The session folder.
    #[error(transparent)]
    Session(#[from] SessionError),
    /// The folder is another cell's run (other cameras) or not a several-camera session.
    #[error("{}: {problem}", folder.display())]
    Folder {
        /// The session folder.
        folder: PathBuf,
        /// What does not match.
        problem: String,
    },
    /// The arm failed; every record so far is kept.
    #[error("the arm failed at plan pose {plan_index}: {source}; every record so far is kept: `handeye run --resume {}` continues", folder.display())]
    Robot {
        /// The pose.
        plan_index: usize,
        /// The folder to resume.
        folder: PathBuf,
        /// The arm's error.
        #[source]
        source: Box<handeye_robot::RobotError>,
    },
    /// Stopped on request (Ctrl-C); every record so far is kept.
    #[error("stopped before plan pose {plan_index}; every record so far is kept: `handeye run --resume {}` continues", folder.display())]
    Stopped {
        /// The next pose.
        plan_index: usize,
        /// The folder to resume.
        folder: PathBuf,
    },
    /// The joint solve.
    #[error(transparent)]
    Solve(#[from] RigSolveError),
}

/// `rig.yaml`: the cameras of a several-camera session and its plan.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RigManifest {
    /// The cell config the session was started with.
    pub config: PathBuf,
    /// The cameras, in config order: (name, setup).
    pub cameras: Vec<RigManifestCamera>,
    /// The planner camera's name.
    pub planner: String,
    /// The plan, in visiting order.
    pub plan: Vec<PlannedPose>,
}

/// One camera in `rig.yaml`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RigManifestCamera {
    /// Its name.
    pub name: String,
    /// Its setup.
    pub setup: Setup,
}

/// The manifest's file name in a several-camera session folder.
pub const RIG_MANIFEST: &str = "rig.yaml";

/// Whether `folder` is a several-camera session.
pub fn is_rig_folder(folder: &Path) -> bool {
    folder.join(RIG_MANIFEST).is_file()
}

/// A camera's folder inside a several-camera session.
pub fn camera_folder(root: &Path, name: &str) -> PathBuf {
    root.join("cameras").join(name)
}

/// Reads `rig.yaml`.
pub fn read_manifest(root: &Path) -> Result<RigManifest, SessionError> {
    Ok(read_yaml(&root.join(RIG_MANIFEST))?)
}

/// A camera's progress at one pose, for displays.
#[derive(Debug, Clone)]
pub struct CameraCapture {
    /// The camera.
    pub camera: String,
    /// Board reprojection RMS when accepted.
    pub reprojection_rms_px: Option<f64>,
    /// Why no sample, if none.
    pub rejected: Option<String>,
}

/// One pose done, for displays.
#[derive(Debug, Clone)]
pub struct RigProgress {
    /// Plan index.
    pub plan_index: usize,
    /// Poses in the plan.
    pub of: usize,
    /// Per camera.
    pub captures: Vec<CameraCapture>,
}

/// How many plan poses each camera is expected to see its board at, by the nominal cell: the
/// plan is made for one camera, so the others' share is checked before anything moves.
#[derive(Debug, Clone, PartialEq)]
pub struct PlannedViews {
    /// The camera.
    pub camera: String,
    /// Poses where at least half the board's corners fall inside its image (by the nominal
    /// mounts and its lens).
    pub poses: usize,
    /// Poses in the plan.
    pub of: usize,
}

/// Counts, per camera, the plan poses at which it is expected to see its board (by the nominal
/// mounts, its lens and the configured image margin).
pub fn planned_views(
    rig: &RigConfig,
    prepared: &[PreparedCell],
    plan: &[(Pose, Joints)],
) -> Vec<PlannedViews> {
    rig.cameras
        .iter()
        .zip(prepared)
        .map(|(camera, p)| {
            let points = p.board.points();
            let margin = p.config.session.image_margin_px;
            let (w, h) = (
                f64::from(p.camera_model.width),
                f64::from(p.camera_model.height),
            );
            let poses = plan
                .iter()
                .filter(|(flange, _)| {
                    let camera_from_target = p.config.nominal.camera_from_target(flange);
                    let inside = points
                        .iter()
                        .filter_map(|(_, _, point)| {
                            p.camera_model.project(&(camera_from_target * point))
                        })
                        .filter(|px| {
                            px.x >= margin
                                && px.y >= margin
                                && px.x <= w - margin
                                && px.y <= h - margin
                        })
                        .count();
                    2 * inside >= points.len()
                })
                .count();
            PlannedViews {
                camera: camera.name.clone(),
                poses,
                of: plan.len(),
            }
        })
        .collect()
}

/// What a several-camera run says as it goes.
#[derive(Debug, Clone)]
pub enum RigEvent {
    /// Before the first move: how many poses each camera is expected to see its board at.
    Planned(Vec<PlannedViews>),
    /// One pose done.
    Pose(RigProgress),
}

/// What a several-camera run did.
#[derive(Debug, Clone)]
pub struct RigRun {
    /// The session folder.
    pub folder: PathBuf,
    /// Poses visited in this run.
    pub visited_now: usize,
    /// Arm time of this run (moves and settling, once for all cameras), s.
    pub arm_time_s: f64,
    /// Cameras that stopped delivering frames in this run (also in `failures.yaml`).
    pub failed_cameras: Vec<CameraFailure>,
    /// The joint answer as written to `result.yaml`.
    pub result: RigResultFile,
}

/// A camera that stopped delivering frames: `failures.yaml` of the session lists them.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraFailure {
    /// The camera.
    pub camera: String,
    /// The plan pose of its first failed grab.
    pub plan_index: usize,
    /// The camera's error.
    pub error: String,
}

/// `failures.yaml` of a several-camera session: the cameras that stopped delivering frames in
/// its last run (absent when none did).
pub fn root_failures(root: &Path) -> PathBuf {
    root.join("failures.yaml")
}

/// The cameras that stopped delivering frames in the session's last run.
pub fn read_failures(root: &Path) -> Vec<CameraFailure> {
    read_yaml(&root_failures(root)).unwrap_or_default()
}

/// One camera of an opened rig.
struct RigCameraRun {
    name: String,
    folder: SessionFolder,
    setup: Setup,
    board: Target,
    model: CameraModel,
    detector: TargetDetector,
    max_rms: f64,
    /// Set once its grab failed: not asked again in this run.
    failed: bool,
}

/// A sim-backend fault for tests: `HANDEYE_RIG_CAMERA_FAILS=<camera>:<grab>` makes that camera's
/// grab number `<grab>` (0-based) and every later one fail, as an unplugged camera does. Not a
/// user option; the several-camera tests set it.
fn injected_failure() -> Option<(String, usize)> {
    let v = std::env::var("HANDEYE_RIG_CAMERA_FAILS").ok()?;
    let (name, at) = v.split_once(':')?;
    Some((name.to_string(), at.parse().ok()?))
}

/// The arm and every camera of a rig, opened (cameras in config order).
type RigHardware = (Box<dyn Robot>, Vec<Box<dyn Camera>>);

/// Opens every camera of a simulated rig around one simulated arm. Each camera renders from the
/// arm's true pose with its own lens, board and truth.
fn open_sim(rig: &RigConfig, prepared: &[PreparedCell]) -> Result<RigHardware, RigRunError> {
    let planner = &prepared[rig.planner];
    let truth = |p: &PreparedCell, name: &str| {
        p.config.simulation.ok_or_else(|| {
            RigRunError::Backend(format!(
                "camera `{name}`: a simulated cell needs `simulation:` (its mount and the boards)"
            ))
        })
    };
    let (robot, planner_camera) = super::sim::open(
        &planner.config,
        truth(planner, &rig.cameras[rig.planner].name)?,
        planner.kinematics().map_err(|e| RigRunError::Cell {
            camera: rig.cameras[rig.planner].name.clone(),
            source: Box::new(e),
        })?,
        planner.start_joints,
        planner.camera_model,
        planner.board.clone(),
    )
    .map_err(|e| RigRunError::Cell {
        camera: rig.cameras[rig.planner].name.clone(),
        source: Box::new(e),
    })?;
    let mut planner_camera = Some(planner_camera);
    let mut cameras: Vec<Box<dyn Camera>> = Vec::new();
    for (c, p) in prepared.iter().enumerate() {
        if c == rig.planner {
            cameras.push(Box::new(planner_camera.take().ok_or_else(|| {
                RigRunError::Backend("the planner camera was opened twice".into())
            })?));
            continue;
        }
        let arm: Shared<_> = robot.clone();
        let flange = Box::new(move || arm.lock().true_base_from_flange());
        let camera = super::sim::camera(
            &p.config,
            truth(p, &rig.cameras[c].name)?,
            flange,
            p.camera_model,
            p.board.clone(),
        )
        .map_err(|e| RigRunError::Cell {
            camera: rig.cameras[c].name.clone(),
            source: Box::new(e),
        })?;
        cameras.push(Box::new(camera));
    }
    Ok((Box::new(robot), cameras))
}

/// Runs (or, with `resume`, continues) a several-camera session into `folder`, then solves it
/// jointly and writes `result.yaml`. `stop` ends the run cleanly between poses.
pub fn run_rig(
    config_file: &Path,
    folder: &Path,
    resume: bool,
    stop: Arc<AtomicBool>,
    on_event: &mut dyn FnMut(&RigEvent),
) -> Result<RigRun, RigRunError> {
    let rig = RigConfig::load(config_file)?;
    let prepared = rig
        .cameras
        .iter()
        .map(|c| {
            prepare_config(c.config.clone()).map_err(|e| RigRunError::Cell {
                camera: c.name.clone(),
                source: Box::new(e),
            })
        })
        .collect::<Result<Vec<_>, _>>()?;
    let planner = &prepared[rig.planner];
    let plan = planner
        .report
        .validated()
        .ok_or_else(|| RigRunError::Plan {
            camera: rig.cameras[rig.planner].name.clone(),
            problems: planner
                .report
                .plan_problems
                .iter()
                .chain(planner.report.poses.iter().flat_map(|p| p.problems.iter()))
                .cloned()
                .collect::<Vec<_>>()
                .join("; "),
        })?;
    let all_sim = matches!(planner.config.robot, RobotConfig::Sim { .. })
        && prepared
            .iter()
            .all(|p| matches!(p.config.camera, CameraConfig::Sim { .. }));
    if !all_sim {
        return Err(RigRunError::Backend(
            "a several-camera cell runs with `robot: {backend: sim}` and simulated cameras in this build; real arms and cameras run one camera per config for now".into(),
        ));
    }
    let manifest = RigManifest {
        config: config_file.to_path_buf(),
        cameras: rig
            .cameras
            .iter()
            .map(|c| RigManifestCamera {
                name: c.name.clone(),
                setup: c.config.setup,
            })
            .collect(),
        planner: rig.cameras[rig.planner].name.clone(),
        plan: SessionManifest::new(PathBuf::new(), Setup::EyeInHand, &plan).plan,
    };
    let views = planned_views(&rig, &prepared, &plan);
    if let Some(blind) = views.iter().find(|v| v.poses < MIN_VIEWS_PER_CAMERA) {
        return Err(RigRunError::Plan {
            camera: blind.camera.clone(),
            problems: format!(
                "by the nominal cell it sees its board at {} of the {} poses (planned for camera `{}`), and a camera needs {MIN_VIEWS_PER_CAMERA}: check its nominal mount, or aim it where the arm goes",
                blind.poses,
                blind.of,
                rig.cameras[rig.planner].name
            ),
        });
    }
    on_event(&RigEvent::Planned(views));
    let mut cameras = open_folders(&rig, &prepared, folder, resume, &manifest, &plan)?;
    // The failures of an earlier run are history: this run asks every camera again.
    let _ = std::fs::remove_file(root_failures(folder));
    let (mut robot, mut devices) = open_sim(&rig, &prepared)?;
    let failure = injected_failure();
    let mut grabs = vec![0usize; devices.len()];
    let mut visited_now = 0;
    let mut arm_time_s = 0.0;
    let mut failed_cameras = Vec::new();
    // A camera that failed in this run is not waited for; a resume asks it again.
    let done = |cameras: &[RigCameraRun], index: usize| {
        cameras
            .iter()
            .all(|c| c.failed || c.folder.visit_path(index).is_file())
    };
    let settle = planner.config.settle();
    for (index, (_, joints)) in plan.iter().enumerate() {
        if done(&cameras, index) {
            continue;
        }
        if stop.load(Ordering::SeqCst) {
            return Err(RigRunError::Stopped {
                plan_index: index,
                folder: folder.to_path_buf(),
            });
        }
        let robot_error = |source| RigRunError::Robot {
            plan_index: index,
            folder: folder.to_path_buf(),
            source: Box::new(source),
        };
        let started = Instant::now();
        robot
            .move_joints(joints, &planner.config.limits)
            .map_err(robot_error)?;
        std::thread::sleep(settle);
        let settled = Instant::now();
        arm_time_s += settled.duration_since(started).as_secs_f64();
        let base_from_flange = robot.base_from_flange().map_err(robot_error)?;
        let mut captures = Vec::new();
        for (c, camera) in cameras.iter_mut().enumerate() {
            if camera.folder.visit_path(index).is_file() {
                // Recorded before a resume: kept as it is (the log is never rewritten).
                continue;
            }
            let frame_name = SessionFolder::frame_name(index);
            let mut visit = PoseVisit::new(index, &base_from_flange, frame_name.clone());
            let injected = failure
                .as_ref()
                .is_some_and(|(name, at)| *name == camera.name && grabs[c] >= *at);
            grabs[c] += 1;
            let grabbed = if camera.failed {
                Err("the camera stopped delivering frames earlier in this run".to_string())
            } else if injected {
                Err("no fresh frame within 1s (injected by HANDEYE_RIG_CAMERA_FAILS)".to_string())
            } else {
                devices[c].grab(settled).map_err(|e| e.to_string())
            };
            match grabbed {
                Ok(frame) => {
                    let mut png = Vec::new();
                    frame
                        .image
                        .write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
                        .map_err(|source| SessionError::Frame {
                            path: frame_name.clone(),
                            source: Box::new(source),
                        })?;
                    camera.folder.write_file(&frame_name, &png)?;
                    visit = measure(
                        &camera.detector,
                        &camera.board,
                        Some(&camera.model),
                        &frame.image,
                        camera.max_rms,
                        visit,
                    );
                }
                Err(reason) => {
                    // No record: a record names its frame, and there is none. The pose stays
                    // open for this camera, so a resume asks it again.
                    if !camera.failed {
                        camera.failed = true;
                        failed_cameras.push(CameraFailure {
                            camera: camera.name.clone(),
                            plan_index: index,
                            error: reason.clone(),
                        });
                        write_yaml(&failed_cameras, &root_failures(folder))
                            .map_err(SessionError::from)?;
                    }
                    captures.push(CameraCapture {
                        camera: camera.name.clone(),
                        reprojection_rms_px: None,
                        rejected: Some(format!("camera `{}`: {reason}", camera.name)),
                    });
                    continue;
                }
            }
            camera.folder.write_visit(&visit)?;
            let visits = camera.folder.read_visits()?;
            rebuild_samples(&camera.folder, camera.setup, &visits)?;
            captures.push(CameraCapture {
                camera: camera.name.clone(),
                reprojection_rms_px: visit.camera_from_target.and(visit.reprojection_rms_px),
                rejected: visit.rejected.clone(),
            });
        }
        visited_now += 1;
        on_event(&RigEvent::Pose(RigProgress {
            plan_index: index,
            of: plan.len(),
            captures,
        }));
    }
    // Release the folders' locks before the solve reads them.
    drop(cameras);
    let result = solve_rig_folder(folder, &rig)?;
    Ok(RigRun {
        folder: folder.to_path_buf(),
        visited_now,
        arm_time_s,
        failed_cameras,
        result,
    })
}

/// Creates (or, resuming, opens and checks) the session folder and each camera's folder.
fn open_folders(
    rig: &RigConfig,
    prepared: &[PreparedCell],
    root: &Path,
    resume: bool,
    manifest: &RigManifest,
    plan: &[(Pose, Joints)],
) -> Result<Vec<RigCameraRun>, RigRunError> {
    let folder_error = |problem: String| RigRunError::Folder {
        folder: root.to_path_buf(),
        problem,
    };
    if resume {
        let on_disk = read_manifest(root).map_err(|e| {
            folder_error(format!(
                "not a several-camera session ({RIG_MANIFEST}: {e})"
            ))
        })?;
        if on_disk.cameras != manifest.cameras {
            let names = |m: &RigManifest| {
                m.cameras
                    .iter()
                    .map(|c| format!("{} ({})", c.name, c.setup))
                    .collect::<Vec<_>>()
                    .join(", ")
            };
            return Err(folder_error(format!(
                "the session's cameras are {}, the config's are {}: resume with the config the session was started with",
                names(&on_disk),
                names(manifest)
            )));
        }
        if on_disk.plan.len() != manifest.plan.len() {
            return Err(folder_error(format!(
                "the session's plan has {} poses, the config's {}: resume with the config the session was started with",
                on_disk.plan.len(),
                manifest.plan.len()
            )));
        }
    } else {
        if root.join(RIG_MANIFEST).exists() {
            return Err(folder_error(
                "already holds a several-camera session: pass --resume to continue it, or choose another folder".into(),
            ));
        }
        std::fs::create_dir_all(root).map_err(|source| SessionError::Io {
            path: root.to_path_buf(),
            source,
        })?;
        write_yaml(manifest, &root.join(RIG_MANIFEST)).map_err(SessionError::from)?;
    }
    rig.cameras
        .iter()
        .zip(prepared)
        .map(|(camera, p)| {
            let sub = camera_folder(root, &camera.name);
            let folder = if resume && sub.join("session.yaml").is_file() {
                SessionFolder::resume(&sub)?
            } else {
                let folder = SessionFolder::create(&sub)?;
                folder.write_manifest(&SessionManifest::new(
                    rig.file.clone(),
                    camera.config.setup,
                    plan,
                ))?;
                folder
            };
            let detector = TargetDetector::spawn(&p.board, p.detector_options()).map_err(|e| {
                RigRunError::Backend(format!(
                    "camera `{}`: starting the detector: {e}",
                    camera.name
                ))
            })?;
            Ok(RigCameraRun {
                name: camera.name.clone(),
                folder,
                setup: camera.config.setup,
                board: p.board.clone(),
                model: p.camera_model,
                detector,
                max_rms: p.config.session.max_reprojection_rms_px,
                failed: false,
            })
        })
        .collect()
}
