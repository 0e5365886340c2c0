//! Verification of a calibration against observations it was not solved from.
//!
//! Two ways: a holdout run ([`holdout`]: the cell moves to a freshly generated set of poses, the
//! camera measures `T_camera_target`, and the calibration predicts it with [`setup::predict`])
//! and offline leave-one-out cross-validation on any dataset or session ([`leave_one_out`]: each
//! sample is predicted by a solve of all the others). Both report, per pose and summarised, the
//! rotation error (degrees, the angle between predicted and measured rotation) and the
//! translation error at the target (mm, the distance between the predicted and the measured
//! target origin in the camera frame). Depends on `solve`, `plan`, `cell` and `session` (the
//! holdout run records a normal session folder, so it can be replayed and reported).

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::cell::run::{self, RunError, RunObserver, RunRequest, Strategy};
use handeye_config::CellConfig;
use handeye_core::geometry::{weighted_rms, Pose};
use handeye_core::setup::CellTransforms;
use handeye_core::setup::{self, PosePair, Setup};
use handeye_plan::GenerateSpec;
use handeye_records::dataset::Dataset;
use handeye_records::result::CellResult;
use handeye_records::{SessionError, SessionFolder};
use handeye_solve::verdict::{self, Accuracy, Level};
use handeye_solve::{self as solve, SolveError, SolveOptions};

/// Prediction error at one pose.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PredictionError {
    /// Sample index.
    pub index: usize,
    /// Sample id, if any.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub id: Option<String>,
    /// Angle between predicted and measured `T_camera_target` rotation, degrees.
    pub rotation_deg: f64,
    /// Distance between predicted and measured target origin (camera frame), mm.
    pub translation_mm: f64,
    /// Its weight in the RMS: its view's precision relative to the typical view's
    /// (`solve::view_weighted`), 1 when the sample does not record it.
    #[serde(default = "unit_weight", skip_serializing_if = "is_unit_weight")]
    pub weight: f64,
}

fn unit_weight() -> f64 {
    1.0
}

fn is_unit_weight(weight: &f64) -> bool {
    *weight == 1.0
}

/// Summary of the prediction errors.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ErrorSummary {
    /// Poses compared.
    pub poses: usize,
    /// RMS rotation error, degrees (each pose at its weight).
    pub rotation_rms_deg: f64,
    /// Median rotation error, degrees.
    pub rotation_median_deg: f64,
    /// Largest rotation error, degrees.
    pub rotation_max_deg: f64,
    /// RMS translation error at the target, mm (each pose at its weight).
    pub translation_rms_mm: f64,
    /// Median translation error at the target, mm.
    pub translation_median_mm: f64,
    /// Largest translation error at the target, mm.
    pub translation_max_mm: f64,
}

/// Per-pose errors and their summary.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Verification {
    /// What was compared (`holdout` or `leave-one-out`).
    pub kind: String,
    /// Per pose.
    pub poses: Vec<PredictionError>,
    /// Summary (of the poses not in `outliers`).
    pub summary: ErrorSummary,
    /// Leave-one-out: the samples the calibration flags as outliers (the solve of every sample,
    /// or the session's recorded answer: [`Verification::with_outliers`]). Their errors are
    /// listed but not summarised, as the calibration's own held-out check leaves them out
    /// (`verdict::held_out`): the two give one figure for one session.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub outliers: Vec<usize>,
}

/// Why a verification could not run.
#[derive(Debug, thiserror::Error)]
pub enum VerifyError {
    /// Too few samples for leave-one-out (each fold must still solve).
    #[error("leave-one-out needs at least {required} samples, got {found}")]
    TooFewSamples {
        /// Samples given.
        found: usize,
        /// Needed.
        required: usize,
    },
    /// The solve of every sample, where the folds start, failed.
    #[error("solving every sample failed")]
    Solve(#[source] SolveError),
    /// A fold failed.
    #[error("solving without sample {left_out} failed")]
    Fold {
        /// The left-out sample.
        left_out: usize,
        /// Why.
        #[source]
        source: SolveError,
    },
    /// The verification plan is unusable.
    #[error("the verification plan failed its checks: {0}")]
    Plan(String),
    /// The result is for another setup than the cell.
    #[error("the result is for {result} but the cell is {cell}")]
    SetupMismatch {
        /// Setup of the result.
        result: Setup,
        /// Setup of the cell.
        cell: Setup,
    },
    /// The holdout session's records could not be read.
    #[error("the verification session failed")]
    Session(#[source] Box<SessionError>),
    /// The holdout run failed (its message says why, and how to resume when samples are kept).
    #[error(transparent)]
    Run(Box<RunError>),
    /// The cell still gives a file the answer found wrong (refused before anything moves).
    #[error("{0}")]
    FileFoundWrong(String),
}

fn summarise(errors: &[PredictionError]) -> ErrorSummary {
    let weights: Vec<f64> = errors.iter().map(|e| e.weight).collect();
    let stats = |values: Vec<f64>| -> (f64, f64, f64) {
        if values.is_empty() {
            return (f64::NAN, f64::NAN, f64::NAN);
        }
        let rms = weighted_rms(values.iter().copied().zip(weights.iter().copied()));
        let mut sorted = values.clone();
        sorted.sort_by(f64::total_cmp);
        let mid = sorted.len() / 2;
        let median = if sorted.len().is_multiple_of(2) {
            0.5 * (sorted[mid - 1] + sorted[mid])
        } else {
            sorted[mid]
        };
        (rms, median, *sorted.last().expect("non-empty"))
    };
    let r = stats(errors.iter().map(|e| e.rotation_deg).collect());
    let t = stats(errors.iter().map(|e| e.translation_mm).collect());
    ErrorSummary {
        poses: errors.len(),
        rotation_rms_deg: r.0,
        rotation_median_deg: r.1,
        rotation_max_deg: r.2,
        translation_rms_mm: t.0,
        translation_median_mm: t.1,
        translation_max_mm: t.2,
    }
}

/// The error of a predicted against the measured `T_camera_target` of sample `index` of
/// `pairs`, which are weighted by their views' precision (`solve::view_weighted`).
fn prediction_error(index: usize, pairs: &[PosePair], predicted: &Pose) -> PredictionError {
    let sample = &pairs[index];
    let measured = &sample.camera_from_target;
    PredictionError {
        index,
        id: sample.id.clone(),
        rotation_deg: predicted.rotation.angle_to(&measured.rotation).to_degrees(),
        translation_mm: (predicted.translation.vector - measured.translation.vector).norm() * 1e3,
        weight: sample.weight,
    }
}

/// Compares the calibration's prediction with every measured pair, each at its weight as
/// `options` weigh it (its view's precision, when the pairs record it).
pub fn compare(
    setup: Setup,
    camera_mount: &Pose,
    target_mount: &Pose,
    pairs: &[PosePair],
    options: &SolveOptions,
) -> Verification {
    let weighted = options.weighted(pairs);
    let poses: Vec<PredictionError> = (0..pairs.len())
        .map(|i| {
            let predicted = setup::predict(
                setup,
                camera_mount,
                target_mount,
                &pairs[i].base_from_flange,
            );
            prediction_error(i, &weighted, &predicted)
        })
        .collect();
    Verification {
        kind: "holdout".into(),
        summary: summarise(&poses),
        poses,
        outliers: Vec::new(),
    }
}

/// Leave-one-out cross-validation: each sample is predicted by a solve of all the others
/// ([`solve::predict_left_out`], each fold started from the solve of every sample).
pub fn leave_one_out(
    setup: Setup,
    pairs: &[PosePair],
    options: &SolveOptions,
) -> Result<Verification, VerifyError> {
    leave_one_out_refitting(setup, pairs, options, None)
}

/// [`leave_one_out`] of samples whose robot poses an arm model fitted to them corrects: each
/// fold's robot poses come from `refit`, the model fitted without its left-out sample (as the
/// verdict's held-out folds: `verdict::held_out_refitting`), so a session's check and its
/// solve's held-out figure are of one model.
pub fn leave_one_out_refitting(
    setup: Setup,
    pairs: &[PosePair],
    options: &SolveOptions,
    refit: Option<verdict::FoldFlanges<'_>>,
) -> Result<Verification, VerifyError> {
    const REQUIRED: usize = 4;
    if pairs.len() < REQUIRED {
        return Err(VerifyError::TooFewSamples {
            found: pairs.len(),
            required: REQUIRED,
        });
    }
    let full = solve::solve(setup, pairs, options).map_err(VerifyError::Solve)?;
    let predictions = verdict::predict_folds(setup, pairs, options, &full, refit, 0..pairs.len())
        .map_err(|failure| match failure {
        verdict::FoldFailure::Solve { left_out, source } => VerifyError::Fold { left_out, source },
        refit @ verdict::FoldFailure::Refit { .. } => VerifyError::Plan(refit.to_string()),
    })?;
    let weighted = options.weighted(pairs);
    let poses: Vec<PredictionError> = predictions
        .iter()
        .map(|(left_out, predicted)| prediction_error(*left_out, &weighted, predicted))
        .collect();
    Ok(Verification {
        kind: "leave-one-out".into(),
        summary: summarise(&poses),
        poses,
        outliers: Vec::new(),
    }
    .with_outliers(full.outliers))
}

/// Holdout verification on the cell: views generated from `spec` (a seed the calibration did not
/// use) are checked from the arm's actual joints, those that pass are recorded as a session —
/// the one run ([`run::drive`] with [`Strategy::Holdout`]) into `request`'s folder — and each
/// camera's measured `T_camera_target` is compared with the prediction of its transforms in
/// `calibrations` (by the camera's name in the config: every camera of a several-camera cell
/// grabs at each view, as in its calibration run; `camera` for a config without a `cameras:`
/// list). Each camera's errors, in `calibrations`' order; a camera that saw its board at none of
/// the views is left out (an error when every camera is). With `arm_model` (the result file,
/// when its answer was solved with the arm's own model: its `kinematics:` section) each robot
/// pose is first corrected by that model, as the answer's own were: the arm's errors are not the
/// calibration's. Setting `request.stop` stops the arm and ends the session cleanly, as in a
/// calibration run.
pub fn holdout(
    request: &RunRequest,
    calibrations: &[(String, CellTransforms)],
    arm_model: Option<&Path>,
    spec: &GenerateSpec,
    observer: &mut dyn RunObserver,
) -> Result<Vec<(String, Verification)>, VerifyError> {
    // Each result must be of its camera's setup: checked before anything opens.
    let config = request
        .config
        .as_deref()
        .ok_or_else(|| VerifyError::Plan("a holdout check needs the cell config".into()))?;
    let cell = CellConfig::load(config).map_err(|e| VerifyError::Plan(e.to_string()))?;
    for (name, calibration) in calibrations {
        let camera = cell
            .cameras
            .iter()
            .find(|c| c.name == *name)
            .ok_or_else(|| {
                VerifyError::Plan(format!(
                    "the cell has no camera `{name}` (its cameras: {})",
                    cell.cameras
                        .iter()
                        .map(|c| c.name.as_str())
                        .collect::<Vec<_>>()
                        .join(", ")
                ))
            })?;
        if calibration.setup != camera.setup {
            return Err(VerifyError::SetupMismatch {
                result: calibration.setup,
                cell: camera.setup,
            });
        }
    }
    let driven = run::drive(request, Strategy::Holdout(*spec), observer)
        .map_err(|e| VerifyError::Run(Box::new(e)))?;
    // The session's own folder (of several cameras: the one holding each camera's).
    let root = request.target.root(&driven.folder);
    let mut checked = Vec::new();
    let mut unseen = Vec::new();
    let session_error = |e: SessionError| VerifyError::Session(Box::new(e));
    for (name, calibration) in calibrations {
        let camera_folder;
        let folder = if cell.listed {
            camera_folder = SessionFolder::open(&crate::cell::cameras::camera_folder(&root, name))
                .map_err(session_error)?;
            &camera_folder
        } else {
            &driven.folder
        };
        let samples = folder.samples_path();
        // A camera that saw its board at none of the views is left out (the caller names
        // it); the others are checked.
        if !samples.is_file() {
            unseen.push(format!("`{name}`"));
            continue;
        }
        let dataset = Dataset::load(&samples).map_err(|e| session_error(SessionError::File(e)))?;
        let pairs = match arm_model {
            Some(file) => {
                handeye_records::corrected_by_arm_model(file, &cell, folder, &dataset.pairs)
                    .map_err(session_error)?
            }
            None => dataset.pairs,
        };
        let verification = compare(
            calibration.setup,
            &calibration.camera_mount,
            &calibration.target_mount,
            &pairs,
            &cell.solver.to_options(),
        );
        checked.push((name.clone(), verification));
    }
    if checked.is_empty() {
        return Err(VerifyError::Plan(format!(
            "camera {} saw its board at none of the held-out views: moved or covered since the calibration, or the views fall outside what it sees (its frames are in the session {})",
            unseen.join(", "),
            root.display()
        )));
    }
    Ok(checked)
}

/// Refuses, before anything moves, a held-out check of a result that found a camera's lens or
/// board file wrong while the cell still gives that file: measured with it, the fresh views
/// would disagree by the file's error (tens of mm), and the check would blame the calibration
/// or a moved camera. A lens file is still the wrong one when each lens parameter the result
/// estimated is at the file's value; a board file when it is the one the result's session
/// recorded (its path and sha256 in `session.yaml`). The result's own next step says the fix.
pub fn refuse_files_found_wrong(
    solved: &CellResult,
    result_path: &Path,
    mounts: &[(String, CellTransforms)],
    cell: &CellConfig,
) -> Result<(), VerifyError> {
    use handeye_solve::cell_model::GivenFile;
    // The files the result's session was recorded with (its planner camera's, for several).
    let session = crate::cell::cameras::session_folder_of(handeye_core::folder_of(result_path));
    let recorded = SessionFolder::open(&session)
        .ok()
        .and_then(|folder| folder.read_manifest().ok())
        .map(|manifest| manifest.inputs)
        .unwrap_or_default();
    for (name, _) in mounts {
        let result = solved
            .cameras
            .iter()
            .find(|c| c.name == *name || solved.cameras.len() == 1);
        let (Some(verdict), Some(camera)) = (
            result.and_then(|r| r.verdict.as_ref()),
            cell.cameras.iter().find(|c| c.name == *name),
        ) else {
            continue;
        };
        let Some(model) = &verdict.figures.cell_model else {
            continue;
        };
        let estimate = |parameter: &str| model.estimates.iter().find(|e| e.parameter == parameter);
        let still_given = |file: &Path, what: String| {
            Err(VerifyError::FileFoundWrong(format!(
                "camera `{name}`: the result found the {what}, and the cell still gives {}: measured with it, the held-out views would disagree by the file's error, not the calibration's. First: {}; nothing was moved",
                file.display(),
                verdict.next_action
            )))
        };
        let blamed = model.blamed();
        if let Some(file) = camera
            .intrinsics
            .as_ref()
            .filter(|_| blamed.contains(&GivenFile::Intrinsics))
        {
            if let Ok(given) = handeye_core::camera_model::CameraModel::load(file) {
                let lens = [
                    ("fx", given.fx),
                    ("fy", given.fy),
                    ("cx", given.cx),
                    ("cy", given.cy),
                ];
                let estimated: Vec<_> = lens
                    .iter()
                    .filter_map(|(p, v)| estimate(p).map(|e| (e, *v)))
                    .collect();
                let unchanged = !estimated.is_empty()
                    && estimated.iter().all(|(e, v)| {
                        (v - e.file_value).abs() <= 1e-6 * e.file_value.abs().max(1.0)
                    });
                if let (true, Some((e, _))) = (unchanged, estimated.first()) {
                    return still_given(
                        file,
                        format!(
                            "intrinsics in {} wrong ({} in the file {:.1} px, estimated from its session {:.1} ± {:.2} px)",
                            file.display(), e.parameter, e.file_value, e.estimate, e.sigma
                        ),
                    );
                }
            }
        }
        if blamed.contains(&GivenFile::Board) {
            let file = &camera.target;
            let now = handeye_records::InputFile::hash("target", file).ok();
            let unchanged = now.is_some_and(|now| {
                recorded
                    .iter()
                    .any(|r| r.role == "target" && r.path == now.path && r.sha256 == now.sha256)
            });
            if unchanged {
                let scale = estimate("scale").map_or(String::new(), |e| {
                    format!(" (the board measures {:.3}× the size in it)", e.estimate)
                });
                return still_given(file, format!("board file {} wrong{scale}", file.display()));
            }
        }
    }
    Ok(())
}

/// The arm model a held-out check of `solved` (read from `result_path`) corrects the robot
/// poses by, as the answer's own were: the one it estimated (its `kinematics:` section), else
/// the one the cell gives (`solver.arm_model`, an earlier session's); `None` when the answer
/// took the arm as its published model says.
pub fn arm_model_of(solved: &CellResult, result_path: &Path, cell: &CellConfig) -> Option<PathBuf> {
    match solved.only_camera().and_then(|r| r.kinematics.as_ref()) {
        Some(_) => Some(result_path.to_path_buf()),
        None => cell.solver.arm_model.clone(),
    }
}

impl Verification {
    /// The verdict on the errors against `accuracy` (the verdict's bands: GOOD within it, CHECK
    /// up to 3×, REDO beyond; samples flagged as outliers make it at least CHECK, as they make
    /// the calibration's) and the line that says it, with what to do.
    pub fn verdict(&self, accuracy: &Accuracy) -> (Level, String) {
        let s = &self.summary;
        let measured = accuracy.level_of(s.translation_rms_mm, s.rotation_rms_deg);
        let advice = match (measured, self.kind == "holdout") {
            (Level::Good, _) => "",
            // Fresh poses disagree with the result: the cell changed since, or the result
            // was off where the calibration poses did not reach.
            (Level::Check, true) => ": was the camera or the board moved since the calibration? If not, calibrate again with poses that cover where these are (the largest errors are listed above)",
            (Level::Redo, true) => ": do not use this result; if nothing moved since the calibration, calibrate again with poses that cover where these are",
            // The calibration's own samples disagree with each other.
            (_, false) => ": the samples disagree with each other: look at the largest errors above (a frame or robot pose recorded wrong) and record more poses with larger, more varied rotations",
        };
        // Flagged samples are named, never dropped in silence.
        let (level, flagged) = match self.outliers.as_slice() {
            [] => (measured, String::new()),
            [one] => (
                measured.max(Level::Check),
                format!("; sample {one} is flagged as an outlier by the calibration and not in the RMS (as its own held-out check leaves it out): look at it (a frame or robot pose recorded wrong)"),
            ),
            several => (
                measured.max(Level::Check),
                format!(
                    "; samples {} are flagged as outliers by the calibration and not in the RMS (as its own held-out check leaves them out): look at them (a frame or robot pose recorded wrong)",
                    several.iter().map(usize::to_string).collect::<Vec<_>>().join(", ")
                ),
            ),
        };
        let line = format!(
            "verdict: {} — {} error {:.2} mm, {:.3}° (RMS over {} poses) against the {} mm, {}° asked for{advice}{flagged}",
            level.word(),
            self.kind,
            s.translation_rms_mm,
            s.rotation_rms_deg,
            s.poses,
            accuracy.translation_mm,
            accuracy.rotation_deg,
        );
        (level, line)
    }

    /// The same errors with `outliers` as the flagged samples, left out of the summary: the
    /// calibration's own flags (a session's recorded answer, whose held-out figure left them
    /// out; its pixel fit may have cleared flags a pose-space solve raises).
    pub fn with_outliers(mut self, outliers: Vec<usize>) -> Verification {
        let judged: Vec<PredictionError> = self
            .poses
            .iter()
            .filter(|p| !outliers.contains(&p.index))
            .cloned()
            .collect();
        self.summary = summarise(&judged);
        self.outliers = outliers;
        self
    }

    /// A table for a terminal: one line per pose, then the summary.
    pub fn table(&self) -> String {
        use std::fmt::Write;
        let mut out = format!("{} prediction errors of T_camera_target:\n", self.kind);
        for p in &self.poses {
            let _ = writeln!(
                out,
                "  {:>3} {:<10} {:>9.4}° {:>9.3} mm{}",
                p.index,
                p.id.as_deref().unwrap_or(""),
                p.rotation_deg,
                p.translation_mm,
                if self.outliers.contains(&p.index) {
                    "  outlier (not in the RMS)".to_string()
                } else if p.weight != 1.0 {
                    format!("  weight {:.2}", p.weight)
                } else {
                    String::new()
                }
            );
        }
        let s = &self.summary;
        let _ = write!(
            out,
            "{} poses: rotation RMS {:.4}° (median {:.4}°, max {:.4}°), translation at the target RMS {:.3} mm (median {:.3} mm, max {:.3} mm)",
            s.poses,
            s.rotation_rms_deg,
            s.rotation_median_deg,
            s.rotation_max_deg,
            s.translation_rms_mm,
            s.translation_median_mm,
            s.translation_max_mm
        );
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use handeye_core::geometry::pose_from_rotvec;
    use nalgebra::Vector3;

    #[test]
    fn compare_reports_a_known_offset() {
        let camera_mount =
            pose_from_rotvec(Vector3::new(0.03, -0.07, 0.04), Vector3::new(0.0, 0.0, 1.5));
        let target_mount =
            pose_from_rotvec(Vector3::new(0.5, -0.1, 0.0), Vector3::new(0.0, 0.0, 0.3));
        let robot = pose_from_rotvec(Vector3::new(0.4, -0.1, 0.6), Vector3::new(3.1, 0.1, 0.0));
        let truth = setup::predict(Setup::EyeInHand, &camera_mount, &target_mount, &robot);
        // The measurement is the truth moved 2 mm along the camera x axis and turned 0.5° about z.
        let measured = pose_from_rotvec(
            Vector3::new(0.002, 0.0, 0.0),
            Vector3::new(0.0, 0.0, 0.5f64.to_radians()),
        ) * truth;
        let v = compare(
            Setup::EyeInHand,
            &camera_mount,
            &target_mount,
            &[PosePair::new(robot, measured)],
            &SolveOptions::default(),
        );
        assert!(
            (v.summary.rotation_rms_deg - 0.5).abs() < 1e-9,
            "{:?}",
            v.summary
        );
        // Rotating about the camera z axis also moves the target origin: compute it.
        let expected = (measured.translation.vector - truth.translation.vector).norm() * 1e3;
        assert!((v.summary.translation_rms_mm - expected).abs() < 1e-9);
        assert!(expected > 2.0);
    }

    #[test]
    fn leave_one_out_refuses_too_few_samples() {
        let p = PosePair::new(Pose::identity(), Pose::identity());
        let e = leave_one_out(
            Setup::EyeInHand,
            &[p.clone(), p.clone(), p],
            &SolveOptions::default(),
        );
        assert!(matches!(
            e,
            Err(VerifyError::TooFewSamples {
                found: 3,
                required: 4
            })
        ));
    }
}
