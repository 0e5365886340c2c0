//! A cell with several cameras (a `cameras:` config, `config::cameras`): one arm, one plan, every camera capturing at
//! every pose, one joint solve (`solve.rs`). It runs as every run does, through `cell::run`: the
//! camera the plan is made for (the first eye-in-hand one, see `CellConfig::planner`) is the
//! one the plan is checked for, the others are `PreparedCell::cameras` beside it,
//! `open_hardware` opens each of them beside the arm, and the driver (`session::run_session`) moves and settles once
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

pub mod solve;

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::PreparedCell;
use crate::SessionSetup;
use handeye_core::geometry::Pose;
use handeye_core::setup::Setup;
use handeye_core::yaml_file::{read_yaml, write_yaml};
use handeye_records::{PlannedPose, SessionError, SessionFolder, SessionManifest};
use handeye_robot::Joints;
use handeye_solve::cameras::MIN_VIEWS_PER_CAMERA;

pub use crate::CameraFailure;
pub use solve::{recorded_visits, solve_cameras_folder, CamerasSolveError};

/// `rig.yaml`: the cameras of a several-camera session and its plan.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CamerasManifest {
    /// The cell config the session was started with.
    pub config: PathBuf,
    /// The cameras, in config order: (name, setup).
    pub cameras: Vec<ManifestCamera>,
    /// The planner camera's name.
    pub planner: String,
    /// The plan, in visiting order.
    pub plan: Vec<PlannedPose>,
}

/// One camera in `rig.yaml`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ManifestCamera {
    /// Its name.
    pub name: String,
    /// Its setup.
    pub setup: Setup,
}

/// The manifest's file name in a several-camera session folder.
pub const CAMERAS_MANIFEST: &str = "rig.yaml";

/// Whether `folder` is a several-camera session.
pub fn is_cameras_folder(folder: &Path) -> bool {
    folder.join(CAMERAS_MANIFEST).is_file()
}

/// The several-camera session `dir` is one camera's folder of (`<root>/cameras/<name>`), if it
/// is one.
pub fn session_of_camera_folder(dir: &Path) -> Option<PathBuf> {
    let cameras = dir
        .parent()
        .filter(|p| p.file_name() == Some("cameras".as_ref()))?;
    // `cameras/wrist` under the working directory: the session is `.`.
    let root = handeye_core::folder_of(cameras);
    is_cameras_folder(root).then(|| root.to_path_buf())
}

/// The session folder a command given `dir` reads: `dir` itself, unless it is the root of a
/// listed cell of one camera (`rig.yaml` naming one camera), whose session is its camera's
/// folder — a cell of one camera has one answer in either form (its camera's, which its run
/// also writes at the root), and `solve`, `replay`, `report`, `verify` and Python read that
/// camera's session whichever folder they are given.
pub fn session_to_read(dir: &Path) -> PathBuf {
    let only_camera = is_cameras_folder(dir)
        .then(|| read_manifest(dir).ok())
        .flatten()
        .and_then(|manifest| match manifest.cameras.as_slice() {
            [only] => Some(camera_folder(dir, &only.name)),
            _ => None,
        });
    only_camera.unwrap_or_else(|| dir.to_path_buf())
}

/// A camera's folder inside a several-camera session.
pub fn camera_folder(root: &Path, name: &str) -> PathBuf {
    root.join("cameras").join(name)
}

/// Reads `rig.yaml`. Its config path is absolute since sessions record it so; an older
/// session's holds it as the run was given it (relative to where the run was started), and is
/// then read as its planner camera's `session.yaml` records it (absolute), so a session is
/// solved, replayed and verified from any working directory with its own config.
pub fn read_manifest(root: &Path) -> Result<CamerasManifest, SessionError> {
    let mut manifest: CamerasManifest = read_yaml(&root.join(CAMERAS_MANIFEST))?;
    // As the planner camera's `session.yaml` holds it, also when a file of that relative name
    // is where this command runs: it may be another cell's.
    if manifest.config.is_relative() {
        let planner = SessionFolder::open(&camera_folder(root, &manifest.planner))
            .and_then(|folder| folder.read_manifest());
        if let Ok(planner) = planner {
            if planner.config.is_absolute() {
                manifest.config = planner.config;
            }
        }
    }
    Ok(manifest)
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

impl PreparedCell {
    /// The manifest (`rig.yaml`) of a session visiting `plan`.
    fn cameras_manifest(&self, plan: &[(Pose, Joints)]) -> CamerasManifest {
        CamerasManifest {
            config: self.config_path(),
            cameras: self
                .config
                .cameras
                .iter()
                .map(|c| ManifestCamera {
                    name: c.name.clone(),
                    setup: c.setup,
                })
                .collect(),
            planner: self.config.camera().name.clone(),
            plan: SessionManifest::new(PathBuf::new(), Setup::EyeInHand, plan).plan,
        }
    }

    /// How many of the plan's poses each camera of a listed cell is expected to see its board at
    /// ([`Self::check_views`]; an adaptive plan's candidates are its passing poses, a fixed
    /// plan's all of them), or the refusal naming a camera that would see too few: the check a
    /// run makes before anything moves, and `plan check` makes the same. `None` for a cell in the
    /// one-camera form.
    pub fn planned_views(&self) -> Result<Option<Vec<PlannedViews>>, String> {
        if !self.config.listed {
            return Ok(None);
        }
        let plan = match self.config.adaptive() {
            true => self.report.passing(),
            false => self.report.validated().unwrap_or_default(),
        };
        self.check_views(&plan).map(Some)
    }

    /// How many of `plan`'s poses each camera is expected to see its board at (by the nominal
    /// mounts, its lens and the configured image margin); refuses (naming it) a camera expected
    /// to see it at fewer than a camera needs: the plan is made for one camera, so the others'
    /// share is checked before anything moves.
    pub fn check_views(&self, plan: &[(Pose, Joints)]) -> Result<Vec<PlannedViews>, String> {
        let views: Vec<PlannedViews> = (0..self.cameras.len())
            .map(|c| PlannedViews {
                camera: self.config.cameras[c].name.clone(),
                poses: plan
                    .iter()
                    .filter(|(flange, _)| self.sees_board(c, flange))
                    .count(),
                of: plan.len(),
            })
            .collect();
        match views.iter().find(|v| v.poses < MIN_VIEWS_PER_CAMERA) {
            Some(blind) => Err(format!(
                "camera `{}`: by the nominal cell it sees its board at {} of the {} poses (planned for camera `{}`), and a camera needs {MIN_VIEWS_PER_CAMERA}: check its nominal mount, or aim it where the arm goes; nothing was moved",
                blind.camera,
                blind.poses,
                blind.of,
                self.config.camera().name
            )),
            None => Ok(views),
        }
    }

    /// Makes (for a new session) or checks (`resume`) `rig.yaml` at `root` and adds the other
    /// cameras to `setup`, their folders created when missing; a resume then takes `root`.
    pub fn session_cameras(
        &self,
        setup: &mut SessionSetup,
        root: &Path,
        resume: bool,
        plan: &[(Pose, Joints)],
    ) -> Result<(), String> {
        let manifest = self.cameras_manifest(plan);
        let problem = |p: String| format!("{}: {p}", root.display());
        if resume && root.join(CAMERAS_MANIFEST).is_file() {
            let on_disk = read_manifest(root).map_err(|e| {
                problem(format!(
                    "not a several-camera session ({CAMERAS_MANIFEST}: {e})"
                ))
            })?;
            if on_disk.cameras != manifest.cameras {
                let names = |m: &CamerasManifest| {
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
            write_yaml(&manifest, &root.join(CAMERAS_MANIFEST))
                .map_err(|e| problem(e.to_string()))?;
        }
        // The failures of an earlier run are history: this run asks every camera again.
        let _ = std::fs::remove_file(root_failures(root));
        for c in self.others() {
            let sub = camera_folder(root, &self.config.cameras[c].name);
            let folder = if sub.join("session.yaml").is_file() {
                SessionFolder::resume(&sub)
            } else {
                SessionFolder::create(&sub).and_then(|folder| {
                    folder
                        .write_manifest(&self.manifest(c, plan))
                        .map(|()| folder)
                })
            }
            .map_err(|e| problem(e.to_string()))?;
            setup.cameras.push(self.session_camera(c, folder));
        }
        setup.resume_folder = root.to_path_buf();
        Ok(())
    }
}

/// Where `--resume` of `dir` finds the session's own folder: a several-camera session's
/// planner camera folder, else `dir`.
pub fn session_folder_of(dir: &Path) -> PathBuf {
    match read_manifest(dir) {
        Ok(manifest) => camera_folder(dir, &manifest.planner),
        Err(_) => dir.to_path_buf(),
    }
}

// `failures.yaml` is the pose loop's: it writes each lost camera as it happens.
pub use crate::driver::{read_failures, root_failures};
