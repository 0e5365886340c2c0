//! The result file of a solve: the two unknowns under their frame names, their uncertainty, the
//! residuals (summary and per sample), the outliers and how the solver got there.
//!
//! ```yaml
//! setup: eye_in_hand
//! verdict: {level: good, basis: .., reason: "..", next_action: "..", accuracy: {..}, figures: {..}}
//! T_flange_camera: {translation: [..], quaternion: {w, x, y, z}, rotation_vector: [..]}
//! T_base_target:   {translation: [..], quaternion: {..}, rotation_vector: [..]}
//! uncertainty: {T_flange_camera: {rotation_deg: .., translation_mm: .., ...}, T_base_target: {..}, variance_factor: .., covariance: [[..] x 12]}
//! noise: {rotation_sigma_deg: .., translation_sigma_mm: .., rotation: estimated, translation: estimated, rounds: ..}
//! residuals: {rotation_rms_deg: .., rotation_max_deg: .., translation_rms_mm: .., translation_max_mm: .., samples: [..]}
//! outliers: [..]
//! solver: {method: refined, iterations: .., converged: true, restarts: 0, ...}
//! notices: [..]
//! ```
//!
//! (eye_to_hand uses `T_base_camera` and `T_flange_target`.) The verdict comes first, where a
//! person reads first; files written before it existed (no `verdict:`) still read. Metres and
//! radians in poses; deg and mm where the key says so. Written atomically; read back with the
//! same validation as every pose file. Depends on `solve`, `verdict`, `geometry` and
//! `dataset`'s I/O.
//!
//! That is one camera's answer ([`ResultFile`], what `handeye solve` writes). A session's
//! `result.yaml` is its cell's answer ([`CellResult`], the one type every reader takes): a cell
//! of one camera writes its camera's answer as above, a cell of several a `cameras:` list with
//! the joint solve's transforms (`result/cell.rs`).

use std::path::Path;

mod cell;
pub use cell::{CameraResult, CellResult, NamedTransform};

use serde::{Deserialize, Serialize};

use handeye_core::geometry::{Pose, PoseRecord};
use handeye_core::notice::Notice;
use handeye_core::setup::{CellTransforms, PosePair, RobotFrames, Setup};
use handeye_core::yaml_file::SchemaVersion;
use handeye_core::yaml_file::{read_yaml, write_yaml, FileError};
use handeye_solve::verdict::Verdict;
use handeye_solve::{
    Calibration, Method, Phase, PoseNoise, PoseSigma, Residuals, SolverReport, TraceStep,
    Uncertainty,
};

/// Uncertainty section: 1-sigma per unknown (only the setup's two keys are present).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
#[allow(non_snake_case)]
pub struct UncertaintyYaml {
    /// eye_in_hand camera mount.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub T_flange_camera: Option<PoseSigma>,
    /// eye_in_hand target mount.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub T_base_target: Option<PoseSigma>,
    /// eye_to_hand camera mount.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub T_base_camera: Option<PoseSigma>,
    /// eye_to_hand target mount.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub T_flange_target: Option<PoseSigma>,
    /// The a-posteriori variance factor the covariance was scaled by.
    pub variance_factor: f64,
    /// 12x12 covariance: camera mount [rotation rad, translation m], target mount (the same).
    pub covariance: Vec<Vec<f64>>,
}

impl UncertaintyYaml {
    /// The 1-sigma of the unknown called `key` (`T_flange_camera`, ...), when the file holds it.
    pub fn sigma(&self, key: &str) -> Option<PoseSigma> {
        match key {
            "T_flange_camera" => self.T_flange_camera,
            "T_base_target" => self.T_base_target,
            "T_base_camera" => self.T_base_camera,
            "T_flange_target" => self.T_flange_target,
            _ => None,
        }
    }
}

/// The arm's model section (`solver.kinematics: joint_offsets`): each joint's zero offset (the
/// true angle is the reported one plus it) with its 1σ, or why it was held at zero; the fit's
/// residuals with and without it.
///
/// ```yaml
/// kinematics:
///   model: ur10e
///   estimated: joint_offsets
///   joint_offsets:
///     - {joint: base, offset_deg: 0.0, absorbed_by: T_base_target}
///     - {joint: shoulder, offset_deg: 0.0213, sigma_deg: 0.0019}
///   translation_rms_mm: {with: 0.08, without: 0.41}
/// ```
///
/// With `estimated: dh`, `links:` too: each link's `d`, `a` (mm) and `alpha` (deg) correction
/// (true minus published) in the same form, e.g.
/// `{joint: shoulder, parameter: a, unit: mm, correction: 0.12, sigma: 0.01}`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct KinematicsYaml {
    /// The arm model whose published DH chain is the nominal (`ur10e`).
    pub model: String,
    /// What was estimated (`joint_offsets`).
    pub estimated: String,
    /// Each joint, base first.
    pub joint_offsets: Vec<JointOffsetYaml>,
    /// With `estimated: dh`: each link's `d`, `a` and `alpha` corrections, base first.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub links: Vec<LinkCorrectionYaml>,
    /// Pose-space translation residual RMS, mm, with the offsets and without them.
    pub translation_rms_mm: WithWithout,
    /// Pose-space rotation residual RMS, degrees, with the offsets and without them.
    pub rotation_rms_deg: WithWithout,
    /// The transforms' 1σ in the pose-space fit with the offsets (their uncertainty included);
    /// the answer's own `uncertainty` holds the offsets at their estimates.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub uncertainty: Option<UncertaintyYaml>,
    /// How far the estimated model moves the flange from where the published one puts it, over
    /// the recorded poses' joints, mm: the published model's flange position error as far as
    /// the data tell (absent in files written before it).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub flange_correction_mm: Option<MeanMax>,
}

/// The mean and the largest of a figure over the recorded poses.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MeanMax {
    /// The mean.
    pub mean: f64,
    /// The largest.
    pub max: f64,
}

impl MeanMax {
    /// The mean and largest of `values` (`None` for none).
    pub fn of(values: impl IntoIterator<Item = f64>) -> Option<MeanMax> {
        let (mut sum, mut max, mut n) = (0.0, f64::NEG_INFINITY, 0usize);
        for v in values {
            sum += v;
            max = max.max(v);
            n += 1;
        }
        (n > 0).then(|| MeanMax {
            mean: sum / n as f64,
            max,
        })
    }
}

/// A figure with the arm's model and without it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WithWithout {
    /// With the arm's model estimated.
    pub with: f64,
    /// With the arm's published model.
    pub without: f64,
}

/// One joint's zero offset.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct JointOffsetYaml {
    /// The joint's name (`base`, `shoulder`, `elbow`, `wrist 1`, `wrist 2`, `wrist 3`).
    pub joint: String,
    /// The offset, degrees (0 when held).
    pub offset_deg: f64,
    /// Its 1σ, degrees (estimated offsets only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sigma_deg: Option<f64>,
    /// The transform that absorbs it (no data can tell them apart): held at zero. `both` when
    /// the two together do.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub absorbed_by: Option<String>,
    /// The recorded configurations do not determine it: held at zero.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub undetermined: bool,
}

/// One link correction of `estimated: dh`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LinkCorrectionYaml {
    /// The joint whose link it is (`base` … `wrist 3`).
    pub joint: String,
    /// `d`, `a` or `alpha` (standard DH).
    pub parameter: String,
    /// `mm` (`d`, `a`) or `deg` (`alpha`).
    pub unit: String,
    /// True minus published, in `unit` (0 when held).
    pub correction: f64,
    /// Its 1σ, in `unit` (estimated corrections only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sigma: Option<f64>,
    /// The transform that absorbs it: held at zero (`both` when the two together do).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub absorbed_by: Option<String>,
    /// The recorded configurations do not determine it: held at zero.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub undetermined: bool,
}

impl UncertaintyYaml {
    /// The file form of `uncertainty` of a `setup`'s two unknowns (under that setup's keys).
    pub fn of(setup: Setup, uncertainty: &Uncertainty) -> UncertaintyYaml {
        let eye_in_hand = setup == Setup::EyeInHand;
        let (cam, tgt) = (
            Some(uncertainty.camera_mount),
            Some(uncertainty.target_mount),
        );
        UncertaintyYaml {
            T_flange_camera: if eye_in_hand { cam } else { None },
            T_base_target: if eye_in_hand { tgt } else { None },
            T_base_camera: if eye_in_hand { None } else { cam },
            T_flange_target: if eye_in_hand { None } else { tgt },
            variance_factor: uncertainty.variance_factor,
            covariance: uncertainty
                .covariance
                .row_iter()
                .map(|r| r.iter().copied().collect())
                .collect(),
        }
    }
}

/// Residuals of one sample.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SampleResidualYaml {
    /// Index of the sample in the dataset.
    pub index: usize,
    /// Its id, if any.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub id: Option<String>,
    /// Rotation residual, degrees (absent for a dropped sample).
    pub rotation_deg: Option<f64>,
    /// Translation residual, mm (absent for a dropped sample).
    pub translation_mm: Option<f64>,
    /// Whitened residual norm, sigmas (absent for a dropped sample).
    pub normalised: Option<f64>,
    /// Flagged as an outlier.
    pub outlier: bool,
    /// Left out of the final solve.
    pub dropped: bool,
}

/// The per-sample residual columns of `samples` (rotation in degrees, translation in mm,
/// normalised in sigmas), `NaN` where a sample has none (dropped, or not in the file): the form a
/// `Calibration`'s residuals take.
pub(crate) fn residual_columns<'a>(
    samples: impl Iterator<Item = Option<&'a SampleResidualYaml>>,
) -> [Vec<f64>; 3] {
    let mut columns = [Vec::new(), Vec::new(), Vec::new()];
    for sample in samples {
        let values = sample.map_or([None; 3], |s| {
            [s.rotation_deg, s.translation_mm, s.normalised]
        });
        for (column, value) in columns.iter_mut().zip(values) {
            column.push(value.unwrap_or(f64::NAN));
        }
    }
    columns
}

/// Residuals section.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ResidualsYaml {
    /// RMS rotation residual, degrees.
    pub rotation_rms_deg: f64,
    /// Largest rotation residual, degrees.
    pub rotation_max_deg: f64,
    /// RMS translation residual, mm.
    pub translation_rms_mm: f64,
    /// Largest translation residual, mm.
    pub translation_max_mm: f64,
    /// Per sample.
    pub samples: Vec<SampleResidualYaml>,
}

/// Solver section.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SolverYaml {
    /// `iterative`, `closed_form` or `refined`.
    pub method: Method,
    /// Iterations (iterative) plus LM evaluations (refined).
    pub iterations: usize,
    /// Every stage met its tolerance.
    pub converged: bool,
    /// Restarts of the iterative method after a stall.
    pub restarts: usize,
    /// Per-iteration rotation updates of the iterative method, rad.
    #[serde(default)]
    pub rotation_trace_rad: Vec<f64>,
    /// Per-iteration translation updates of the iterative method, m.
    #[serde(default)]
    pub translation_trace_m: Vec<f64>,
    /// Cost at each refinement evaluation (½ Σ whitened r²).
    #[serde(default)]
    pub refine_cost_trace: Vec<f64>,
}

/// The whole result file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(
    deny_unknown_fields,
    expecting = "a result mapping (setup, the two transforms, residuals, solver, ...)"
)]
#[allow(non_snake_case)]
pub struct ResultFile {
    /// The layout version of this file ([`SchemaVersion`]; absent in files written before it).
    #[serde(default = "SchemaVersion::unversioned")]
    pub schema_version: SchemaVersion,
    /// The layout solved.
    pub setup: Setup,
    /// GOOD / CHECK / REDO with its reason and next action (absent in files written before
    /// verdicts existed, or when no verdict was computed).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub verdict: Option<Verdict>,
    /// The frames the robot poses were read in: every `T_base_*` is in `robot_frames.base`
    /// (absent in files written before it and for a dataset solved alone: the UR controller's
    /// `base` and `tool0`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub robot_frames: Option<RobotFrames>,
    /// eye_in_hand camera mount.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub T_flange_camera: Option<PoseRecord>,
    /// eye_in_hand target mount.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub T_base_target: Option<PoseRecord>,
    /// eye_to_hand camera mount.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub T_base_camera: Option<PoseRecord>,
    /// eye_to_hand target mount.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub T_flange_target: Option<PoseRecord>,
    /// Uncertainty of both unknowns (refined method).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub uncertainty: Option<UncertaintyYaml>,
    /// The board-pose noise (per-axis 1-sigma of `T_camera_target`) the pose-space fit used,
    /// estimated from the residuals or given, and where each came from (absent for an answer
    /// fitted in reprojection space, and in older files).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub noise: Option<PoseNoise>,
    /// The arm's own model estimated with the transforms (`solver.kinematics`; absent when it
    /// was not estimated).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub kinematics: Option<KinematicsYaml>,
    /// Residuals.
    pub residuals: ResidualsYaml,
    /// Indices of samples flagged as outliers.
    pub outliers: Vec<usize>,
    /// How the solver got there.
    pub solver: SolverYaml,
    /// Messages for people, each with its severity (older files' plain strings read as
    /// warnings).
    /// (Key `notices`; files written before it was renamed say `warnings`.)
    #[serde(
        default,
        alias = "warnings",
        deserialize_with = "handeye_core::notice::deserialize_notices"
    )]
    pub notices: Vec<Notice>,
}

impl ResultFile {
    /// The same file with `verdict` (see `verdict::assess_solved`), written as its first key
    /// after `setup`.
    pub fn with_verdict(mut self, verdict: Verdict) -> ResultFile {
        self.verdict = Some(verdict);
        self
    }

    /// The same file with the arm's model estimated with it.
    pub fn with_kinematics(mut self, kinematics: KinematicsYaml) -> ResultFile {
        self.kinematics = Some(kinematics);
        self
    }

    /// The same file naming the frames the robot poses were read in.
    pub fn with_robot_frames(mut self, frames: RobotFrames) -> ResultFile {
        self.robot_frames = Some(frames);
        self
    }

    /// The file form of a calibration (without a verdict: add one with
    /// [`ResultFile::with_verdict`]); `pairs` are the samples it was solved from (for ids).
    pub fn from_calibration(calibration: &Calibration, pairs: &[PosePair]) -> ResultFile {
        let camera = Some(PoseRecord::from_pose(&calibration.camera_mount));
        let target = Some(PoseRecord::from_pose(&calibration.target_mount));
        let eye_in_hand = calibration.setup == Setup::EyeInHand;
        let uncertainty = calibration
            .uncertainty
            .as_ref()
            .map(|u| UncertaintyYaml::of(calibration.setup, u));
        let r = &calibration.residuals;
        let finite = |v: f64| v.is_finite().then_some(v);
        let samples = (0..r.rotation_deg.len())
            .map(|i| SampleResidualYaml {
                index: i,
                id: pairs.get(i).and_then(|p| p.id.clone()),
                rotation_deg: finite(r.rotation_deg[i]),
                translation_mm: finite(r.translation_mm[i]),
                normalised: finite(r.normalised[i]),
                outlier: calibration.outliers.contains(&i),
                dropped: calibration.dropped.contains(&i),
            })
            .collect();
        let trace = |phase| {
            calibration
                .solver
                .trace
                .iter()
                .filter(|s| s.phase == phase)
                .map(|s| s.update)
                .collect()
        };
        ResultFile {
            schema_version: SchemaVersion::CURRENT,
            setup: calibration.setup,
            verdict: None,
            robot_frames: None,
            T_flange_camera: if eye_in_hand { camera.clone() } else { None },
            T_base_target: if eye_in_hand { target.clone() } else { None },
            T_base_camera: if eye_in_hand { None } else { camera },
            T_flange_target: if eye_in_hand { None } else { target },
            uncertainty,
            noise: calibration.noise,
            kinematics: None,
            residuals: ResidualsYaml {
                rotation_rms_deg: r.rotation_rms_deg,
                rotation_max_deg: r.rotation_max_deg,
                translation_rms_mm: r.translation_rms_mm,
                translation_max_mm: r.translation_max_mm,
                samples,
            },
            outliers: calibration.outliers.clone(),
            solver: SolverYaml {
                method: calibration.solver.method,
                iterations: calibration.solver.iterations,
                converged: calibration.solver.converged,
                restarts: calibration.solver.restarts,
                rotation_trace_rad: trace(Phase::Rotation),
                translation_trace_m: trace(Phase::Translation),
                refine_cost_trace: trace(Phase::Refine),
            },
            notices: calibration.notices.clone(),
        }
    }

    /// Writes the result atomically.
    pub fn save(&self, path: &Path) -> Result<(), FileError> {
        write_yaml(self, path)
    }

    /// Reads a result file.
    pub fn load(path: &Path) -> Result<ResultFile, FileError> {
        read_yaml(path)
    }

    /// The setup and both unknowns, checked: the setup's two keys present, the other two absent,
    /// every pose valid.
    pub fn mounts(&self, path: &Path) -> Result<CellTransforms, FileError> {
        let (camera_key, target_key) = self.setup.unknown_names();
        let (camera, target, wrong) = match self.setup {
            Setup::EyeInHand => (
                &self.T_flange_camera,
                &self.T_base_target,
                [
                    ("T_base_camera", &self.T_base_camera),
                    ("T_flange_target", &self.T_flange_target),
                ],
            ),
            Setup::EyeToHand => (
                &self.T_base_camera,
                &self.T_flange_target,
                [
                    ("T_flange_camera", &self.T_flange_camera),
                    ("T_base_target", &self.T_base_target),
                ],
            ),
        };
        if let Some((key, _)) = wrong.iter().find(|(_, v)| v.is_some()) {
            return Err(FileError::Value {
                path: path.to_path_buf(),
                yaml_path: key.to_string(),
                problem: format!("not an unknown of setup {}", self.setup),
            });
        }
        let get = |record: &Option<PoseRecord>, key: &str| -> Result<Pose, FileError> {
            let record = record.as_ref().ok_or_else(|| FileError::Value {
                path: path.to_path_buf(),
                yaml_path: key.to_string(),
                problem: format!("missing (required for setup {})", self.setup),
            })?;
            record.to_pose(key).map_err(|problem| FileError::Pose {
                path: path.to_path_buf(),
                problem,
            })
        };
        Ok(CellTransforms {
            setup: self.setup,
            camera_mount: get(camera, camera_key)?,
            target_mount: get(target, target_key)?,
        })
    }

    /// Reads a result file and returns its setup and both unknowns.
    pub fn load_mounts(path: &Path) -> Result<CellTransforms, FileError> {
        ResultFile::load(path)?.mounts(path)
    }

    /// The calibration as written: both unknowns, the uncertainty (covariance and sigmas),
    /// per-sample residuals (NaN for a dropped sample), outliers, the solver run and warnings;
    /// for tools that show a result (the report) without solving again. The iteration trace
    /// comes back grouped by phase (rotation, translation, refine), as the file stores it.
    pub fn to_calibration(&self, path: &Path) -> Result<Calibration, FileError> {
        let mounts = self.mounts(path)?;
        let uncertainty = match &self.uncertainty {
            None => None,
            Some(u) => {
                let bad = |problem: String| FileError::Value {
                    path: path.to_path_buf(),
                    yaml_path: "uncertainty.covariance".into(),
                    problem,
                };
                if u.covariance.len() != 12 || u.covariance.iter().any(|r| r.len() != 12) {
                    return Err(bad("must be a 12x12 matrix".into()));
                }
                let covariance =
                    nalgebra::SMatrix::<f64, 12, 12>::from_fn(|r, c| u.covariance[r][c]);
                if covariance.iter().any(|v| !v.is_finite()) {
                    return Err(bad("contains a non-finite value".into()));
                }
                let (camera_key, target_key) = self.setup.unknown_names();
                let sigma = |key: &str| -> Result<PoseSigma, FileError> {
                    u.sigma(key).ok_or_else(|| FileError::Value {
                        path: path.to_path_buf(),
                        yaml_path: format!("uncertainty.{key}"),
                        problem: format!("missing (required for setup {})", self.setup),
                    })
                };
                Some(Uncertainty {
                    covariance,
                    camera_mount: sigma(camera_key)?,
                    target_mount: sigma(target_key)?,
                    variance_factor: u.variance_factor,
                })
            }
        };
        let r = &self.residuals;
        let [rotation_deg, translation_mm, normalised] =
            residual_columns(r.samples.iter().map(Some));
        let residuals = Residuals {
            rotation_deg,
            translation_mm,
            normalised,
            rotation_rms_deg: r.rotation_rms_deg,
            rotation_max_deg: r.rotation_max_deg,
            translation_rms_mm: r.translation_rms_mm,
            translation_max_mm: r.translation_max_mm,
        };
        let s = &self.solver;
        let steps = |phase: Phase, values: &[f64]| {
            values
                .iter()
                .map(move |&update| TraceStep { phase, update })
                .collect::<Vec<_>>()
        };
        let mut trace = steps(Phase::Rotation, &s.rotation_trace_rad);
        trace.extend(steps(Phase::Translation, &s.translation_trace_m));
        trace.extend(steps(Phase::Refine, &s.refine_cost_trace));
        Ok(Calibration {
            setup: self.setup,
            camera_mount: mounts.camera_mount,
            target_mount: mounts.target_mount,
            uncertainty,
            residuals,
            noise: self.noise,
            outliers: self.outliers.clone(),
            dropped: r
                .samples
                .iter()
                .filter(|s| s.dropped)
                .map(|s| s.index)
                .collect(),
            solver: SolverReport {
                method: s.method,
                iterations: s.iterations,
                converged: s.converged,
                restarts: s.restarts,
                trace,
            },
            notices: self.notices.clone(),
        })
    }
}
