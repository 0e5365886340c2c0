//! A session's `result.yaml` as its cell's answer, for N ≥ 1 cameras: every transform named by
//! its frames with its 1-sigma, per camera its mount, residuals and verdict, the boards, and
//! the cell's verdict. Every reader (`export`, `verify`, the report, Python) takes this one type.
//!
//! Two layouts are written, by the number of cameras:
//! - a cell of one camera writes its camera's whole answer at the top level
//!   ([`ResultFile`], the layout `handeye solve` writes), read here as a camera list of one
//!   whose answer it is ([`CellResult::of_one_camera`]);
//! - a cell of several writes the list itself: each camera's mount from the joint solve beside
//!   the one solved from its views alone, the boards, the camera-to-camera transforms.

use std::path::Path;

use serde::{Deserialize, Serialize};

use handeye_core::geometry::{rms, serde_pose, Pose};
use handeye_core::setup::{CellTransforms, RobotFrames, Setup};
use handeye_core::yaml_file::{parse_yaml, read_text, write_yaml, FileError};
use handeye_solve::verdict::{HeldOut, Verdict};
use handeye_solve::{Calibration, Method, PoseSigma, Residuals, SolverReport};

use super::{residual_columns, ResultFile, SampleResidualYaml};

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
    /// Its 1-sigma (absent when the answer has none: a one-camera answer not refined).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sigma: Option<PoseSigma>,
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
    /// Its mount solved from its own views alone (absent for a cell's only camera: its joint
    /// answer is its own).
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
    /// GOOD, CHECK or REDO with its reason and next action, by the one-camera verdict's rules
    /// (`verdict::assess_mount`: its cell model, its held-out error and its 1-sigma against the
    /// accuracy asked for, its sample count); REDO when it is left out. A cell's only camera: its answer's verdict (absent in files written before
    /// verdicts).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub verdict: Option<Verdict>,
    /// Its whole answer, when it is the cell's only camera: the file a one-camera session writes
    /// (uncertainty, noise, the arm's model, the solver's run, notices), this entry's figures
    /// read from it. A several-camera file holds none: its cameras' figures are the joint
    /// solve's (the run's own one-camera solve of the planner camera is in that camera's folder).
    #[serde(skip)]
    pub answer: Option<Box<ResultFile>>,
}

impl CameraResult {
    /// Its joint answer as a calibration of its samples, what a page draws for one camera of
    /// several: its mount from the joint solve, `board` its setup's board (from
    /// [`CellResult::mounts`]), and the residuals the file holds for it. `plan_poses`: each
    /// sample's plan pose, as its residual's `index` names it; a sample without one, or dropped
    /// by its own solve, has no residual and is listed as dropped. The joint solve keeps no
    /// trace, covariance or notices per camera: the calibration has none. `None` for a camera
    /// left out of the joint solve.
    pub fn joint_calibration(
        &self,
        board: &Pose,
        plan_poses: &[Option<usize>],
    ) -> Option<Calibration> {
        let mount = self.joint.as_ref()?;
        let of_sample: Vec<Option<&SampleResidualYaml>> = plan_poses
            .iter()
            .map(|pose| {
                pose.and_then(|pose| self.residuals_per_pose.iter().find(|r| r.index == pose))
                    .filter(|r| !r.dropped)
            })
            .collect();
        let [rotation_deg, translation_mm, normalised] =
            residual_columns(of_sample.iter().copied());
        fn finite(values: &[f64]) -> impl Iterator<Item = f64> + '_ {
            values.iter().copied().filter(|v| v.is_finite())
        }
        // The RMS the file holds (over the samples the joint solve kept), else the shown values'.
        let rms = |held: Option<f64>, values: &[f64]| held.unwrap_or_else(|| rms(finite(values)));
        let max = |values: &[f64]| finite(values).fold(0.0, f64::max);
        Some(Calibration {
            setup: self.setup,
            camera_mount: mount.pose,
            target_mount: *board,
            uncertainty: None,
            residuals: Residuals {
                normalised,
                rotation_rms_deg: rms(self.residual_rotation_rms_deg, &rotation_deg),
                rotation_max_deg: max(&rotation_deg),
                translation_rms_mm: rms(self.residual_translation_rms_mm, &translation_mm),
                translation_max_mm: max(&translation_mm),
                rotation_deg,
                translation_mm,
            },
            noise: None,
            outliers: (0..of_sample.len())
                .filter(|&i| of_sample[i].is_some_and(|r| r.outlier))
                .collect(),
            dropped: (0..of_sample.len())
                .filter(|&i| of_sample[i].is_none())
                .collect(),
            solver: SolverReport {
                method: Method::Refined,
                iterations: 0,
                converged: true,
                restarts: 0,
                trace: Vec::new(),
            },
            notices: Vec::new(),
        })
    }
}

/// A session's `result.yaml`: the cell's answer, one camera or several ([`CellResult::load`]
/// reads either layout).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CellResult {
    /// The frames the robot poses were read in (absent in files written before it: the UR
    /// controller's `base` and `tool0`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub robot_frames: Option<RobotFrames>,
    /// Per camera, config order.
    pub cameras: Vec<CameraResult>,
    /// The boards (`T_base_target`, `T_flange_target`) from the joint solve.
    pub boards: Vec<NamedTransform>,
    /// Camera-to-camera transforms of cameras of one setup (`T_cam_left_cam_right`).
    #[serde(default)]
    pub camera_to_camera: Vec<NamedTransform>,
    /// `χ²/dof` of the joint solve (absent for an answer without uncertainty).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub variance_factor: Option<f64>,
    /// The cell's verdict: the worst camera's, naming it (`verdict::worst_camera`); a cell of
    /// one camera, its camera's (absent in files written before verdicts).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub verdict: Option<Verdict>,
}

impl CellResult {
    /// Reads a session's result file of either layout: a top-level `cameras:` key is a
    /// several-camera cell's, anything else one camera's answer ([`CellResult::of_one_camera`]).
    /// Errors name the file, the key and the line as every result read does.
    pub fn load(path: &Path) -> Result<CellResult, FileError> {
        let text = read_text(path)?;
        // Only the top-level keys decide; a file that is not a mapping is left to the
        // one-camera reader, whose error says what a result looks like.
        let several = serde_yaml_ng::from_str::<serde_yaml_ng::Mapping>(&text)
            .is_ok_and(|keys| keys.contains_key("cameras"));
        if several {
            let cell: CellResult = parse_yaml(&text, path)?;
            cell.check_joint(path)?;
            Ok(cell)
        } else {
            CellResult::of_one_camera(parse_yaml(&text, path)?, path)
        }
    }

    /// Writes the answer atomically in the layout of its number of cameras: a cell of one
    /// camera its camera's whole answer at the top level ([`ResultFile::save`]), a cell of
    /// several the camera list.
    pub fn save(&self, path: &Path) -> Result<(), FileError> {
        match self.only_camera() {
            Some(answer) => answer.save(path),
            None => write_yaml(self, path),
        }
    }

    /// A several-camera answer is whole: every transform has its 1-sigma, every camera and the
    /// cell their verdict (the fields only a one-camera answer may lack).
    fn check_joint(&self, path: &Path) -> Result<(), FileError> {
        let missing = |yaml_path: String| FileError::Value {
            path: path.to_path_buf(),
            yaml_path,
            problem: "missing (a several-camera answer judges every camera and the cell)".into(),
        };
        if self.verdict.is_none() {
            return Err(missing("verdict".into()));
        }
        if let Some(i) = self.cameras.iter().position(|c| c.verdict.is_none()) {
            return Err(missing(format!("cameras[{i}].verdict")));
        }
        if self.variance_factor.is_none() {
            return Err(missing("variance_factor".into()));
        }
        match self.transforms().find(|t| t.sigma.is_none()) {
            Some(t) => Err(FileError::Value {
                path: path.to_path_buf(),
                yaml_path: t.name.clone(),
                problem: "missing its sigma (a several-camera answer gives every transform's)"
                    .into(),
            }),
            None => Ok(()),
        }
    }

    /// A one-camera answer (read from `path`) as its cell's: a camera list of one, named
    /// `camera` as its frame is, whose mount and board are the answer's two unknowns (checked as
    /// [`ResultFile::mounts`] checks them) and whose whole answer is kept.
    pub fn of_one_camera(answer: ResultFile, path: &Path) -> Result<CellResult, FileError> {
        let mounts = answer.mounts(path)?;
        let [(camera_parent, camera_frame), (board_parent, board_frame)] =
            answer.setup.unknown_frames();
        let sigma = |key: &str| answer.uncertainty.as_ref().and_then(|u| u.sigma(key));
        let (camera_key, board_key) = answer.setup.unknown_names();
        let transform = |parent: &str, child: &str, pose: Pose, key: &str| NamedTransform {
            name: key.to_string(),
            parent: parent.to_string(),
            child: child.to_string(),
            pose,
            sigma: sigma(key),
            truth_error_deg: None,
            truth_error_mm: None,
        };
        let residuals = &answer.residuals;
        let camera = CameraResult {
            name: camera_frame.to_string(),
            setup: answer.setup,
            samples: residuals.samples.len(),
            left_out: None,
            joint: Some(transform(
                camera_parent,
                camera_frame,
                mounts.camera_mount,
                camera_key,
            )),
            alone: None,
            corner_noise_px: None,
            residual_rotation_rms_deg: Some(residuals.rotation_rms_deg),
            residual_translation_rms_mm: Some(residuals.translation_rms_mm),
            residuals_per_pose: residuals.samples.clone(),
            held_out: answer.verdict.as_ref().and_then(|v| v.figures.held_out),
            verdict: answer.verdict.clone(),
            answer: None,
        };
        Ok(CellResult {
            robot_frames: answer.robot_frames.clone(),
            boards: vec![transform(
                board_parent,
                board_frame,
                mounts.target_mount,
                board_key,
            )],
            camera_to_camera: Vec::new(),
            variance_factor: answer.uncertainty.as_ref().map(|u| u.variance_factor),
            verdict: answer.verdict.clone(),
            cameras: vec![CameraResult {
                answer: Some(Box::new(answer)),
                ..camera
            }],
        })
    }

    /// The whole answer of a cell of one camera ([`CameraResult::answer`]); `None` for a cell
    /// of several.
    pub fn only_camera(&self) -> Option<&ResultFile> {
        match self.cameras.as_slice() {
            [only] => only.answer.as_deref(),
            _ => None,
        }
    }

    /// The frames the robot poses were read in (files written before it: the UR controller's
    /// `base` and `tool0`).
    pub fn robot_frames(&self) -> RobotFrames {
        self.robot_frames.clone().unwrap_or_default()
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
                let board = self.board_of(camera)?;
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

    /// The board `camera` sees in the joint answer: its setup's (`T_base_target` for an
    /// eye-in-hand camera, `T_flange_target` for an eye-to-hand one).
    pub fn board_of(&self, camera: &CameraResult) -> Option<&NamedTransform> {
        let [_, (board_parent, _)] = camera.setup.unknown_frames();
        self.boards.iter().find(|b| b.parent == board_parent)
    }

    /// The transform called `name`.
    pub fn transform(&self, name: &str) -> Option<&NamedTransform> {
        self.transforms().find(|t| t.name == name)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn residual(index: usize, translation_mm: Option<f64>, dropped: bool) -> SampleResidualYaml {
        SampleResidualYaml {
            index,
            id: None,
            rotation_deg: translation_mm.map(|t| t / 10.0),
            translation_mm,
            normalised: None,
            outlier: false,
            dropped,
        }
    }

    /// A camera's joint residuals reach a page sample by sample through each sample's plan pose,
    /// whatever the order of either list: a sample the camera's own solve dropped, one whose pose
    /// the result does not name and one without a plan pose have no residual and are listed as
    /// dropped; the RMS is the file's.
    #[test]
    fn joint_residuals_follow_the_samples_plan_poses() {
        let mount = Pose::translation(0.1, 0.0, 0.0);
        let board = Pose::translation(0.0, 0.5, 0.0);
        let camera = CameraResult {
            name: "left".into(),
            setup: Setup::EyeToHand,
            samples: 4,
            left_out: None,
            joint: Some(NamedTransform {
                name: "T_base_cam_left".into(),
                parent: "base".into(),
                child: "cam_left".into(),
                pose: mount,
                sigma: None,
                truth_error_deg: None,
                truth_error_mm: None,
            }),
            alone: None,
            corner_noise_px: None,
            residual_rotation_rms_deg: Some(0.25),
            residual_translation_rms_mm: Some(2.5),
            residuals_per_pose: vec![
                residual(7, Some(3.0), false),
                residual(2, Some(1.0), false),
                residual(9, None, true),
                residual(4, Some(2.0), false),
            ],
            held_out: None,
            verdict: None,
            answer: None,
        };
        // Samples at plan poses 4, 9 (dropped), 2, 11 (not in the result), none, 7.
        let plan_poses = [Some(4), Some(9), Some(2), Some(11), None, Some(7)];
        let c = camera.joint_calibration(&board, &plan_poses).unwrap();
        assert_eq!((c.camera_mount, c.target_mount), (mount, board));
        assert_eq!(c.setup, Setup::EyeToHand);
        let shown: Vec<Option<f64>> = c
            .residuals
            .translation_mm
            .iter()
            .map(|v| v.is_finite().then_some(*v))
            .collect();
        assert_eq!(shown, [Some(2.0), None, Some(1.0), None, None, Some(3.0)]);
        assert!((c.residuals.rotation_deg[5] - 0.3).abs() < 1e-12);
        assert_eq!(c.dropped, [1, 3, 4]);
        assert_eq!(c.residuals.translation_rms_mm, 2.5);
        assert_eq!(c.residuals.translation_max_mm, 3.0);
        // A camera left out of the joint solve has no answer to draw.
        let left_out = CameraResult {
            joint: None,
            ..camera
        };
        assert!(left_out.joint_calibration(&board, &plan_poses).is_none());
    }
}
