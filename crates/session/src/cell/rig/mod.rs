//! A cell with several cameras (a `cameras:` config, `config::cameras`): one arm, one plan, every camera capturing at
//! every pose, one joint solve (`solve.rs`). It runs as every run does, through `cell::run`: the
//! camera the plan is made for (the first eye-in-hand one, see `CellConfig::planner`) is the
//! run's `PreparedCell`, the others hang off it ([`RigCells`]), `open_hardware` opens each of
//! them beside the arm, and the driver (`session::run_cameras_session`) moves and settles once
//! per pose and grabs every camera. Arm time is shared: the moves and settling are paid once
//! for all cameras.
//!
//! The session folder holds `rig.yaml` (the cameras and the plan) and one folder per camera,
//! `cameras/<name>/`, in the one-camera layout (`session.yaml`, `frames/NNN.png`,
//! `poses/NNN.yaml`, `samples.yaml`): a camera's folder is a one-camera session of the same
//! poses, and the planner camera's folder is the run's session folder (its lock is the
//! session's). A camera whose grab fails while another still delivers is named in
//! `failures.yaml` as it happens, its records so far are kept, and the run goes on with the
//! others; `--resume` asks it again for the poses it missed.

pub mod adaptive;
pub mod solve;

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::{prepare_config, CellError, PreparedCell};
use crate::config::CellConfig;
use crate::session::{
    OtherCamera, PlannedPose, RigCameras, SessionError, SessionFolder, SessionManifest,
};
use handeye_core::error_text::error_chain;
use handeye_core::geometry::Pose;
use handeye_core::setup::Setup;
use handeye_core::yaml_file::{read_yaml, write_yaml};
use handeye_robot::Joints;
use handeye_solve::rig::MIN_VIEWS_PER_CAMERA;

pub use crate::session::CameraFailure;
pub use solve::{solve_rig_folder, RigOutput, RigResultFile, RigSolveError};

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
fn planned_views(cells: &[(&str, &PreparedCell)], plan: &[(Pose, Joints)]) -> Vec<PlannedViews> {
    cells
        .iter()
        .map(|(name, p)| PlannedViews {
            camera: name.to_string(),
            poses: plan
                .iter()
                .filter(|(flange, _)| sees_board(p, flange))
                .count(),
            of: plan.len(),
        })
        .collect()
}

/// Whether the camera of `cell` is expected to see its board with the flange at
/// `base_from_flange`: at least half the board's corners inside its image, by the nominal mounts,
/// its lens and the configured image margin.
pub fn sees_board(cell: &PreparedCell, base_from_flange: &Pose) -> bool {
    let points = cell.board.points();
    let margin = cell.config.session.image_margin_px;
    let (w, h) = (
        f64::from(cell.camera_model.width),
        f64::from(cell.camera_model.height),
    );
    let camera_from_target = cell
        .config
        .camera()
        .nominal
        .camera_from_target(base_from_flange);
    let inside = points
        .iter()
        .filter_map(|(_, _, point)| cell.camera_model.project(&(camera_from_target * point)))
        .filter(|px| px.x >= margin && px.y >= margin && px.x <= w - margin && px.y <= h - margin)
        .count();
    2 * inside >= points.len()
}

/// A several-camera cell's other cameras, prepared: each a one-camera cell of the shared arm,
/// plan and settings (the planner camera is the `PreparedCell` that holds this).
pub struct RigCells {
    /// The config (every camera).
    pub config: CellConfig,
    /// The other cameras, in config order, by name.
    pub others: Vec<(String, PreparedCell)>,
}

impl RigCells {
    /// The planner camera's name.
    pub fn planner_name(&self) -> &str {
        &self.config.camera().name
    }

    /// Every camera's name and cell, in config order, the planner being `cell`.
    pub fn cells<'a>(&'a self, cell: &'a PreparedCell) -> Vec<(&'a str, &'a PreparedCell)> {
        let mut others = self.others.iter();
        self.config
            .cameras
            .iter()
            .enumerate()
            .filter_map(|(c, camera)| {
                if c == self.config.planner {
                    Some((camera.name.as_str(), cell))
                } else {
                    others.next().map(|(name, p)| (name.as_str(), p))
                }
            })
            .collect()
    }

    /// The rig manifest of a session visiting `plan`.
    fn manifest(&self, plan: &[(Pose, Joints)]) -> RigManifest {
        RigManifest {
            config: self.config.file.clone(),
            cameras: self
                .config
                .cameras
                .iter()
                .map(|c| RigManifestCamera {
                    name: c.name.clone(),
                    setup: c.setup,
                })
                .collect(),
            planner: self.planner_name().to_string(),
            plan: SessionManifest::new(PathBuf::new(), Setup::EyeInHand, plan).plan,
        }
    }

    /// How many of `plan`'s poses each camera is expected to see its board at; refuses (naming
    /// it) a camera expected to see it at fewer than a camera needs.
    pub fn check_views(
        &self,
        cell: &PreparedCell,
        plan: &[(Pose, Joints)],
    ) -> Result<Vec<PlannedViews>, String> {
        let views = planned_views(&self.cells(cell), plan);
        match views.iter().find(|v| v.poses < MIN_VIEWS_PER_CAMERA) {
            Some(blind) => Err(format!(
                "camera `{}`: by the nominal cell it sees its board at {} of the {} poses (planned for camera `{}`), and a camera needs {MIN_VIEWS_PER_CAMERA}: check its nominal mount, or aim it where the arm goes; nothing was moved",
                blind.camera,
                blind.poses,
                blind.of,
                self.planner_name()
            )),
            None => Ok(views),
        }
    }

    /// Makes (for a new session) or checks (`resume`) `rig.yaml` at `root` and opens the other
    /// cameras' folders (created when missing), for the driver.
    pub fn session_cameras(
        &self,
        root: &Path,
        resume: bool,
        plan: &[(Pose, Joints)],
    ) -> Result<RigCameras, String> {
        let manifest = self.manifest(plan);
        let problem = |p: String| format!("{}: {p}", root.display());
        if resume && root.join(RIG_MANIFEST).is_file() {
            let on_disk = read_manifest(root).map_err(|e| {
                problem(format!(
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
                return Err(problem(format!(
                    "the session's cameras are {}, the config's are {}: resume with the config the session was started with",
                    names(&on_disk),
                    names(&manifest)
                )));
            }
        } else {
            write_yaml(&manifest, &root.join(RIG_MANIFEST)).map_err(|e| problem(e.to_string()))?;
        }
        // The failures of an earlier run are history: this run asks every camera again.
        let _ = std::fs::remove_file(root_failures(root));
        let others = self
            .others
            .iter()
            .map(|(name, p)| {
                let sub = camera_folder(root, name);
                let folder = if sub.join("session.yaml").is_file() {
                    SessionFolder::resume(&sub)?
                } else {
                    let folder = SessionFolder::create(&sub)?;
                    folder.write_manifest(&p.manifest(plan))?;
                    folder
                };
                Ok(OtherCamera {
                    name: name.clone(),
                    folder,
                    setup: p.config.camera().setup,
                    board: p.board.clone(),
                })
            })
            .collect::<Result<Vec<_>, SessionError>>()
            .map_err(|e| problem(e.to_string()))?;
        Ok(RigCameras {
            root: root.to_path_buf(),
            camera_name: self.planner_name().to_string(),
            others,
            lost: Vec::new(),
        })
    }
}

/// Prepares a several-camera cell: each camera as a one-camera cell (its errors name it); the
/// planner camera's is returned, holding the others.
pub fn prepare_rig(rig: CellConfig) -> Result<PreparedCell, CellError> {
    let mut cells = Vec::with_capacity(rig.cameras.len());
    for (index, camera) in rig.cameras.iter().enumerate() {
        let cell = prepare_config(rig.for_camera(index)).map_err(|e| {
            CellError::Backend(format!("camera `{}`: {}", camera.name, error_chain(&e)))
        })?;
        cells.push((camera.name.clone(), cell));
    }
    let (_, mut planner) = cells.remove(rig.planner);
    planner.rig = Some(RigCells {
        config: rig,
        others: cells,
    });
    Ok(planner)
}

/// The root folder of a several-camera session whose planner camera records into
/// `planner_folder` (`<root>/cameras/<name>`).
pub fn root_of(planner_folder: &Path) -> Option<&Path> {
    planner_folder.parent()?.parent()
}

/// Where `--resume` of `dir` finds the session's own folder: a several-camera session's
/// planner camera folder, else `dir`.
pub fn session_folder_of(dir: &Path) -> PathBuf {
    match read_manifest(dir) {
        Ok(manifest) => camera_folder(dir, &manifest.planner),
        Err(_) => dir.to_path_buf(),
    }
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

/// Adds `failure` to the session's `failures.yaml` as it happens (a crash keeps it).
pub fn record_failure(root: &Path, failure: &CameraFailure) -> Result<(), SessionError> {
    let mut failures = read_failures(root);
    failures.push(failure.clone());
    Ok(write_yaml(&failures, &root_failures(root))?)
}
