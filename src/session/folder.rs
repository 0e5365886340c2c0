//! The session folder: everything a run records, written as it is taken so a crash loses nothing.
//!
//! ```text
//! <session>/
//!   session.yaml        what was run: config file, setup, the resolved plan (joints and poses)
//!   poses/007.yaml      one record per visited plan pose: measured T_base_flange, detection, board pose
//!   frames/007.png      the frame grabbed at that pose
//!   samples.yaml        the solver's dataset (only poses whose board pose was accepted), id "pose-007"
//!   result.yaml         the calibration, when solved
//! ```
//! Every file is written with [`write_atomic`], so a reader never sees half a file.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::atomic_file::write_atomic;
use crate::geometry::{Pose, PoseError, PoseYaml};
use crate::robot::Joints;
use crate::setup::Setup;
use crate::yaml_file::{read_yaml, write_yaml};

use super::SessionError;

/// What the session is running, written once at the start; `--resume` reads it back.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SessionManifest {
    /// The cell config the session was started with.
    pub config: PathBuf,
    /// Eye-in-hand or eye-to-hand.
    pub setup: Setup,
    /// The validated plan, in visiting order.
    pub plan: Vec<PlannedPose>,
}

impl SessionManifest {
    /// The manifest of a session of `config` (path) visiting `plan` (flange pose, joints).
    pub fn new(config: PathBuf, setup: Setup, plan: &[(Pose, Joints)]) -> SessionManifest {
        SessionManifest {
            config,
            setup,
            plan: plan
                .iter()
                .map(|(pose, q)| PlannedPose {
                    base_from_flange: PoseYaml::from_pose(pose),
                    joints_deg: q.map(f64::to_degrees),
                })
                .collect(),
        }
    }
}

/// One validated plan pose: where the flange goes and the joints that reach it.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlannedPose {
    /// Target flange pose.
    #[serde(rename = "T_base_flange")]
    pub base_from_flange: PoseYaml,
    /// The joint solution the arm moves to, degrees.
    pub joints_deg: [f64; 6],
}

/// What happened at one plan pose.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PoseVisit {
    /// Index in the plan.
    pub plan_index: usize,
    /// The flange pose the robot reported after settling.
    #[serde(rename = "T_base_flange")]
    pub base_from_flange: PoseYaml,
    /// The frame, relative to the session folder.
    pub frame: PathBuf,
    /// Board pose in the camera, when the board was found and accepted.
    #[serde(
        rename = "T_camera_target",
        default,
        skip_serializing_if = "Option::is_none"
    )]
    pub camera_from_target: Option<PoseYaml>,
    /// Board reprojection RMS, px.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reprojection_rms_px: Option<f64>,
    /// Tags used for the board pose.
    #[serde(default)]
    pub tags: usize,
    /// Detected corners: `[tag id, corner index, u, v]` in pixels (OpenCV convention).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub corners_px: Vec<[f64; 4]>,
    /// Why the pose gave no sample, if it did not.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rejected: Option<String>,
}

/// Paths of one session folder.
#[derive(Debug, Clone)]
pub struct SessionFolder {
    root: PathBuf,
}

impl SessionFolder {
    /// Creates a new session folder (it must not exist yet, or be empty).
    pub fn create(root: &Path) -> Result<SessionFolder, SessionError> {
        if root.exists()
            && std::fs::read_dir(root)
                .map(|mut d| d.next().is_some())
                .unwrap_or(true)
        {
            return Err(SessionError::FolderExists(root.to_path_buf()));
        }
        for sub in ["poses", "frames"] {
            std::fs::create_dir_all(root.join(sub)).map_err(|source| SessionError::Io {
                path: root.join(sub),
                source,
            })?;
        }
        Ok(SessionFolder {
            root: root.to_path_buf(),
        })
    }

    /// Opens an existing session folder.
    pub fn open(root: &Path) -> Result<SessionFolder, SessionError> {
        if !root.join("session.yaml").is_file() {
            return Err(SessionError::NotASession(root.to_path_buf()));
        }
        Ok(SessionFolder {
            root: root.to_path_buf(),
        })
    }

    /// The folder.
    pub fn root(&self) -> &Path {
        &self.root
    }

    /// `session.yaml`.
    pub fn manifest_path(&self) -> PathBuf {
        self.root.join("session.yaml")
    }

    /// `samples.yaml`.
    pub fn samples_path(&self) -> PathBuf {
        self.root.join("samples.yaml")
    }

    /// `result.yaml`.
    pub fn result_path(&self) -> PathBuf {
        self.root.join("result.yaml")
    }

    /// Frame file of a plan pose, relative to the session folder.
    pub fn frame_name(plan_index: usize) -> PathBuf {
        PathBuf::from(format!("frames/{plan_index:03}.png"))
    }

    fn visit_path(&self, plan_index: usize) -> PathBuf {
        self.root.join(format!("poses/{plan_index:03}.yaml"))
    }

    /// Writes the manifest.
    pub fn write_manifest(&self, manifest: &SessionManifest) -> Result<(), SessionError> {
        self.write_yaml(&self.manifest_path(), manifest)
    }

    /// Reads the manifest.
    pub fn read_manifest(&self) -> Result<SessionManifest, SessionError> {
        self.read_yaml(&self.manifest_path())
    }

    /// Records one visit.
    pub fn write_visit(&self, visit: &PoseVisit) -> Result<(), SessionError> {
        self.write_yaml(&self.visit_path(visit.plan_index), visit)
    }

    /// All recorded visits, in plan order.
    pub fn read_visits(&self) -> Result<Vec<PoseVisit>, SessionError> {
        let folder = self.root.join("poses");
        let mut files: Vec<PathBuf> = match std::fs::read_dir(&folder) {
            Ok(entries) => entries
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| p.extension().is_some_and(|e| e == "yaml"))
                .collect(),
            Err(source) => {
                return Err(SessionError::Io {
                    path: folder,
                    source,
                })
            }
        };
        files.sort();
        let mut visits: Vec<PoseVisit> = files
            .iter()
            .map(|f| self.read_yaml(f))
            .collect::<Result<_, _>>()?;
        visits.sort_by_key(|v| v.plan_index);
        Ok(visits)
    }

    /// Writes bytes atomically under the session folder.
    pub fn write_file(&self, relative: &Path, bytes: &[u8]) -> Result<(), SessionError> {
        let path = self.root.join(relative);
        write_atomic(&path, bytes).map_err(|source| SessionError::Io { path, source })
    }

    fn write_yaml<T: Serialize>(&self, path: &Path, value: &T) -> Result<(), SessionError> {
        Ok(write_yaml(value, path)?)
    }

    fn read_yaml<T: for<'de> Deserialize<'de>>(&self, path: &Path) -> Result<T, SessionError> {
        Ok(read_yaml(path)?)
    }
}

impl PoseVisit {
    /// A visit with the robot pose and frame recorded and nothing measured yet.
    pub fn new(plan_index: usize, base_from_flange: &Pose, frame: PathBuf) -> Self {
        PoseVisit {
            plan_index,
            base_from_flange: PoseYaml::from_pose(base_from_flange),
            frame,
            camera_from_target: None,
            reprojection_rms_px: None,
            tags: 0,
            corners_px: Vec::new(),
            rejected: None,
        }
    }

    /// The measured robot pose and, when accepted, the board pose.
    pub fn poses(&self, file: &Path) -> Result<(Pose, Option<Pose>), SessionError> {
        let wrap = |source: PoseError| SessionError::Pose {
            file: file.to_path_buf(),
            source,
        };
        let base_from_flange = self
            .base_from_flange
            .to_pose("T_base_flange")
            .map_err(wrap)?;
        let camera_from_target = self
            .camera_from_target
            .as_ref()
            .map(|p| p.to_pose("T_camera_target").map_err(wrap))
            .transpose()?;
        Ok((base_from_flange, camera_from_target))
    }
}
