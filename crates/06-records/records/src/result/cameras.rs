//! `result.yaml` of a several-camera session: every transform named by its frames, with its
//! 1-sigma, each camera's own answer beside the joint one, a verdict per camera and one for the
//! cell (the one-camera layout is [`ResultFile`](super::ResultFile)).

use serde::{Deserialize, Serialize};

use handeye_core::geometry::{serde_pose, Pose};
use handeye_core::setup::{CellTransforms, RobotFrames, Setup};
use handeye_core::yaml_file::{read_yaml, FileError};
use handeye_solve::verdict::{HeldOut, Verdict};
use handeye_solve::PoseSigma;

use super::SampleResidualYaml;

/// One solved transform, named by its frames.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NamedTransform {
    /// `T_<parent>_<child>`.
    pub name: String,
    /// The parent frame (`flange`, `base`, `cam_left`).
    pub parent: String,
    /// The child frame (`cam_wrist`, `target`, `cam_right`).
    pub child: String,
    /// The transform.
    #[serde(with = "serde_pose")]
    pub pose: Pose,
    /// Its 1-sigma.
    pub sigma: PoseSigma,
    /// Against the simulator's truth (sim cells only): rotation, degrees.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub truth_error_deg: Option<f64>,
    /// Against the simulator's truth: translation, mm.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub truth_error_mm: Option<f64>,
}

/// One camera's part of the answer.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraResult {
    /// Its name.
    pub name: String,
    /// Its setup.
    pub setup: Setup,
    /// Poses where it saw its board (accepted samples).
    pub samples: usize,
    /// Why it is not in the joint solve, when it is not.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub left_out: Option<String>,
    /// Its mount from the joint solve (absent when left out).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub joint: Option<NamedTransform>,
    /// Its mount solved from its own views alone (the one-camera answer).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub alone: Option<NamedTransform>,
    /// Its corner noise estimated by the pixel-space joint solve (1-sigma per image axis), px.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub corner_noise_px: Option<f64>,
    /// RMS rotation residual of its samples in the joint solve, degrees.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub residual_rotation_rms_deg: Option<f64>,
    /// RMS translation residual, mm.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub residual_translation_rms_mm: Option<f64>,
    /// Each of its samples' residual in the joint solve, the one-camera result's per-sample form
    /// (`index`: the plan pose; absent in files written before it and when it is left out).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub residuals_per_pose: Vec<SampleResidualYaml>,
    /// The leave-one-out check of its own samples (each predicted by a one-camera solve of the
    /// others), as the one-camera verdict runs it; absent when it could not run (`reason`
    /// says why).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub held_out: Option<HeldOut>,
    /// GOOD, CHECK or REDO with its reason and next action: the worse of its 1-sigma and its
    /// held-out error against the accuracy asked for (`verdict::assess_mount`); REDO when it is
    /// left out.
    pub verdict: Verdict,
}

/// `result.yaml` of a several-camera session.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CamerasResultFile {
    /// The frames the robot poses were read in (absent in files written before it: the UR
    /// controller's `base` and `tool0`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub robot_frames: Option<RobotFrames>,
    /// Per camera, config order.
    pub cameras: Vec<CameraResult>,
    /// The boards (`T_base_target`, `T_flange_target`) from the joint solve.
    pub boards: Vec<NamedTransform>,
    /// Camera-to-camera transforms of cameras of one setup (`T_cam_left_cam_right`).
    pub camera_to_camera: Vec<NamedTransform>,
    /// `χ²/dof` of the joint solve.
    pub variance_factor: f64,
    /// The cell's verdict: the worst camera's, naming it (`verdict::worst_camera`).
    pub verdict: Verdict,
}

impl CamerasResultFile {
    /// Reads a several-camera result file (a several-camera session's `result.yaml`).
    pub fn load(path: &std::path::Path) -> Result<CamerasResultFile, FileError> {
        read_yaml(path)
    }

    /// Every transform of the answer: the joint mounts, the boards, the camera-to-camera ones.
    pub fn transforms(&self) -> impl Iterator<Item = &NamedTransform> {
        self.cameras
            .iter()
            .filter_map(|c| c.joint.as_ref())
            .chain(&self.boards)
            .chain(&self.camera_to_camera)
    }

    /// Each solved camera's transforms from the joint answer, by camera name: its mount and its
    /// setup's board (`T_base_target` for an eye-in-hand camera, `T_flange_target` for an
    /// eye-to-hand one). A camera left out of the joint solve has none and is not listed.
    pub fn mounts(&self) -> Vec<(String, CellTransforms)> {
        self.cameras
            .iter()
            .filter_map(|camera| {
                let [_, (board_parent, _)] = camera.setup.unknown_frames();
                let board = self.boards.iter().find(|b| b.parent == board_parent)?;
                Some((
                    camera.name.clone(),
                    CellTransforms {
                        setup: camera.setup,
                        camera_mount: camera.joint.as_ref()?.pose,
                        target_mount: board.pose,
                    },
                ))
            })
            .collect()
    }

    /// The transform called `name`.
    pub fn transform(&self, name: &str) -> Option<&NamedTransform> {
        self.transforms().find(|t| t.name == name)
    }
}
