//! Solving a session folder: `samples.yaml` and the recorded corners (`poses/NNN.yaml`) in,
//! `result.yaml` out, with a summary for people that shows the pose-space and the
//! reprojection-space answers side by side and, in the simulated cell, the error against the
//! ground truth.

use std::fmt::Write;

use serde::{Deserialize, Serialize};

use crate::camera_model::CameraModel;
use crate::config::{CellConfig, SolveSpace};
use crate::dataset::Dataset;
use crate::geometry::Pose;
use crate::result::ResultFile;
use crate::setup::CellTransforms;
use crate::setup::{PosePair, Setup};
use crate::solve::{
    self, refine_reprojection, reprojection_errors, Calibration, Corner, Frame,
    ReprojectionCalibration, ReprojectionErrors, ReprojectionOptions, RobotPrior,
};
use crate::verdict::{self, Verdict};
use crate::vision::Board;

use super::{PoseVisit, SessionError, SessionFolder};

/// A solved session.
pub struct SolvedSession {
    /// The final calibration (the reprojection-space answer when it was computed).
    pub calibration: Calibration,
    /// The pose-space answer (also the start of the reprojection refinement).
    pub pose_space: Calibration,
    /// The reprojection-space answer, when the space is `reprojection` and frames had corners.
    pub reprojection: Option<ReprojectionCalibration>,
    /// The pose-space answer's reprojection errors on the same frames (same order as
    /// `reprojection.errors`), for the side-by-side comparison.
    pub pose_space_errors: Option<ReprojectionErrors>,
    /// Ids (`pose-NNN`) of the frames the reprojection refinement used, in its order.
    pub frame_ids: Vec<String>,
    /// The intrinsics estimated from the run (config without `intrinsics`), also written to the
    /// session's `camera_info.yaml`.
    pub estimated_camera: Option<CameraModel>,
    /// A short human summary.
    pub summary: String,
    /// GOOD / CHECK / REDO and why, from the same figures the result file and report show.
    pub verdict: Option<Verdict>,
}

/// What solving a session needs besides its folder: the board and the intrinsics, loaded once
/// (by the prepared cell, see `cell::PreparedCell::solve_inputs`, or by [`SolveInputs::load`]),
/// and the config's solver settings.
#[derive(Debug, Clone)]
pub struct SolveInputs {
    /// The cell config: solver settings and the robot's repeatability.
    pub config: CellConfig,
    /// The board the frames show.
    pub board: Board,
    /// The intrinsics; `None` when the config has none and they are estimated from the corners.
    pub camera: Option<CameraModel>,
}

impl SolveInputs {
    /// Loads the board and the intrinsics (when the config names them) of `config`.
    pub fn load(config: CellConfig) -> Result<SolveInputs, SessionError> {
        let board = Board::load(&config.target).map_err(|source| SessionError::Board {
            file: config.target.clone(),
            source,
        })?;
        let camera = match &config.intrinsics {
            Some(file) => {
                Some(
                    CameraModel::load(file).map_err(|source| SessionError::Intrinsics {
                        file: file.clone(),
                        source,
                    })?,
                )
            }
            None => None,
        };
        Ok(SolveInputs {
            config,
            board,
            camera,
        })
    }
}

impl SolvedSession {
    /// The result file of this answer (`pairs`: the samples it was solved from, for their ids),
    /// with its verdict first.
    pub fn result_file(&self, pairs: &[PosePair]) -> ResultFile {
        let file = ResultFile::from_calibration(&self.calibration, pairs);
        match &self.verdict {
            Some(verdict) => file.with_verdict(verdict.clone()),
            None => file,
        }
    }
}

/// Solves the folder with the config's solver settings (`solver.space`) and writes `result.yaml`.
pub fn solve_folder(
    folder: &SessionFolder,
    inputs: &SolveInputs,
) -> Result<SolvedSession, SessionError> {
    solve_folder_in(folder, inputs, inputs.config.solver.space)
}

/// Solves the folder in the given space and writes `result.yaml`.
pub fn solve_folder_in(
    folder: &SessionFolder,
    inputs: &SolveInputs,
    space: SolveSpace,
) -> Result<SolvedSession, SessionError> {
    let (solved, dataset) = load_and_solve(folder, inputs, space)?;
    solved
        .result_file(&dataset.pairs)
        .save(&folder.result_path())?;
    if let Some(summary) = solved.reprojection_summary() {
        crate::yaml_file::write_yaml(&summary, &folder.root().join(REPROJECTION_FILE))?;
    }
    Ok(solved)
}

/// Reads the folder's samples and visits and solves (in the reprojection space with the inputs'
/// board and intrinsics); writes nothing, except `camera_info.yaml` when the intrinsics are
/// estimated. Returns the dataset the answer was solved from.
///
/// When the config has no intrinsics they are estimated from the recorded corners (whatever
/// `space` says: without intrinsics there are no board poses to solve in pose space alone).
pub fn load_and_solve(
    folder: &SessionFolder,
    inputs: &SolveInputs,
    space: SolveSpace,
) -> Result<(SolvedSession, Dataset), SessionError> {
    let config = &inputs.config;
    let Some(camera) = &inputs.camera else {
        return solve_from_scratch(folder, config, &inputs.board);
    };
    let visits = folder.read_visits()?;
    let dataset = committed_samples(folder, &visits)?;
    let vision = (space == SolveSpace::Reprojection).then_some((&inputs.board, camera));
    let solved = solve_session(dataset.setup, &dataset.pairs, &visits, vision, config)?;
    Ok((solved, dataset))
}

/// The folder's `samples.yaml`, checked against the committed records: it must hold exactly the
/// accepted poses (the pose-space answer and the pixel fit then use the same frames). No accepted
/// pose at all is its own error, with the rejections.
fn committed_samples(
    folder: &SessionFolder,
    visits: &[PoseVisit],
) -> Result<Dataset, SessionError> {
    let accepted: Vec<String> = visits
        .iter()
        .filter(|v| v.camera_from_target.is_some())
        .map(|v| format!("pose-{:03}", v.plan_index))
        .collect();
    if accepted.is_empty() {
        let reasons = visits
            .iter()
            .take(3)
            .map(|v| {
                format!(
                    "pose {}: {}",
                    v.plan_index,
                    v.rejected.as_deref().unwrap_or("no board pose")
                )
            })
            .chain((visits.len() > 3).then(|| "...".to_string()))
            .collect::<Vec<_>>()
            .join("; ");
        return Err(SessionError::NoSamples {
            folder: folder.root().to_path_buf(),
            visited: visits.len(),
            reasons: if reasons.is_empty() {
                "no pose was visited".into()
            } else {
                reasons
            },
        });
    }
    let path = folder.samples_path();
    let dataset = if path.is_file() {
        Dataset::load(&path)?
    } else {
        Dataset {
            setup: folder.read_manifest()?.setup,
            pairs: Vec::new(),
        }
    };
    let ids: Vec<String> = dataset
        .pairs
        .iter()
        .map(|p| p.id.clone().unwrap_or_default())
        .collect();
    let missing: Vec<String> = accepted
        .iter()
        .filter(|id| !ids.contains(id))
        .cloned()
        .collect();
    let mut extra: Vec<String> = ids
        .iter()
        .filter(|id| !accepted.contains(id))
        .cloned()
        .collect();
    let mut seen = std::collections::BTreeSet::new();
    extra.extend(
        ids.iter()
            .filter(|id| !seen.insert(*id))
            .map(|id| format!("{id} (twice)")),
    );
    if !missing.is_empty() || !extra.is_empty() {
        return Err(SessionError::SamplesDisagree {
            file: path,
            folder: folder.root().to_path_buf(),
            missing,
            extra,
        });
    }
    Ok(dataset)
}

/// File the estimated intrinsics are written to, in the session folder.
pub const CAMERA_INFO_FILE: &str = "camera_info.yaml";
/// File with both answers' reprojection errors per frame, in the session folder.
pub const REPROJECTION_FILE: &str = "reprojection.yaml";

/// Both answers' reprojection errors, per frame and overall (written as `reprojection.yaml`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ReprojectionSummary {
    /// RMS over all corners of the pose-space answer, px.
    pub pose_space_rms_px: f64,
    /// RMS over all corners of the reprojection-space answer, px (both answers with the robot
    /// poses as recorded).
    pub reprojection_rms_px: f64,
    /// RMS over all corners of the reprojection-space answer with its corrected robot poses
    /// (when corrections were fitted), px: the fit's own residual.
    pub corrected_rms_px: Option<f64>,
    /// Largest corner error of the pose-space answer, px.
    pub pose_space_max_px: f64,
    /// Largest corner error of the reprojection-space answer, px.
    pub reprojection_max_px: f64,
    /// Corners used.
    pub corners: usize,
    /// Corners flagged as outliers by the reprojection refinement.
    pub outlier_corners: usize,
    /// Whether per-pose robot corrections were fitted.
    pub robot_corrections: bool,
    /// Whether the intrinsics were estimated by this solve.
    pub intrinsics_estimated: bool,
    /// The corner noise the reprojection answer was weighted with, px.
    pub pixel_sigma_px: f64,
    /// The robot repeatability it was weighted with, mm and degrees per axis (absent when the
    /// robot poses were taken as exact).
    pub robot_repeatability: Option<[f64; 2]>,
    /// Whether those two were estimated from the residuals (else as configured).
    pub noise_estimated: bool,
    /// Per frame.
    pub frames: Vec<FrameRms>,
}

/// One frame's reprojection RMS under both answers.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FrameRms {
    /// `pose-NNN`.
    pub id: String,
    /// Under the pose-space answer, px.
    pub pose_space_rms_px: f64,
    /// Under the reprojection-space answer, robot pose as recorded, px.
    pub reprojection_rms_px: f64,
    /// Under the reprojection-space answer with its corrected robot pose, px.
    pub corrected_rms_px: Option<f64>,
    /// Flagged as an outlier frame by the reprojection refinement.
    pub outlier: bool,
}

fn reprojection_options(config: &CellConfig) -> ReprojectionOptions {
    ReprojectionOptions {
        pixel_sigma_px: config.solver.pixel_sigma_px,
        estimate_noise: config.solver.estimate_noise,
        robot_prior: config.solver.robot_corrections.then(|| {
            let (translation_sigma_m, rotation_sigma_rad) = config.robot_repeatability();
            RobotPrior {
                translation_sigma_m,
                rotation_sigma_rad,
            }
        }),
        ..ReprojectionOptions::default()
    }
}

/// No intrinsics in the config: Zhang's closed form from the recorded corners, then the joint
/// refinement; writes `camera_info.yaml` into the session.
fn solve_from_scratch(
    folder: &SessionFolder,
    config: &CellConfig,
    board: &Board,
) -> Result<(SolvedSession, Dataset), SessionError> {
    let manifest = folder.read_manifest()?;
    let visits = folder.read_visits()?;
    let (ids, frames): (Vec<String>, Vec<Frame>) = frames_from_visits(&visits, board, false)?
        .into_iter()
        .unzip();
    let first = visits
        .iter()
        .find(|v| !v.corners_px.is_empty())
        .ok_or_else(|| SessionError::NoBoardSeen {
            folder: folder.root().to_path_buf(),
        })?;
    let frame_path = folder.root().join(&first.frame);
    let (width, height) =
        image::image_dimensions(&frame_path).map_err(|source| SessionError::Frame {
            path: frame_path.clone(),
            source,
        })?;
    let options = config.solver.to_options();
    let scratch = crate::solve::intrinsics::calibrate_from_scratch(
        manifest.setup,
        &frames,
        width,
        height,
        &options,
        &reprojection_options(config),
    )
    .map_err(|source| SessionError::Solve {
        stage: "estimating the intrinsics",
        source,
    })?;
    let camera_info = folder.root().join(CAMERA_INFO_FILE);
    scratch
        .joint
        .camera
        .save_camera_info(&camera_info)
        .map_err(|source| SessionError::Intrinsics {
            file: camera_info.clone(),
            source,
        })?;
    // The fair comparison: board poses again by PnP with the estimated intrinsics, the pose-space
    // solve on those, and the reprojection answer's residuals against the same poses.
    let camera = scratch.joint.camera;
    let mut pairs = Vec::with_capacity(frames.len());
    for (id, frame) in ids.iter().zip(&frames) {
        let correspondences: Vec<_> = frame
            .corners
            .iter()
            .map(|c| (c.point_in_target, c.pixel))
            .collect();
        let tags = correspondences.len() / 4;
        if let Ok(pose) =
            crate::vision::pnp::estimate_pose_from_points(&camera, &correspondences, tags.max(2))
        {
            let mut pair = PosePair::new(frame.base_from_flange, pose.camera_from_target);
            pair.id = Some(id.clone());
            pairs.push(pair);
        }
    }
    let pose_space =
        solve::solve(manifest.setup, &pairs, &options).map_err(|source| SessionError::Solve {
            stage: "pose space with the estimated intrinsics",
            source,
        })?;
    let pose_space_errors = reprojection_errors(
        manifest.setup,
        &frames,
        &camera,
        &pose_space.camera_mount,
        &pose_space.target_mount,
    );
    let calibration = scratch
        .joint
        .to_calibration(&pose_space, &pairs, &options.noise);
    let mut solved = SolvedSession {
        calibration,
        pose_space,
        reprojection: Some(scratch.joint.clone()),
        pose_space_errors: Some(pose_space_errors),
        frame_ids: ids,
        estimated_camera: Some(camera),
        summary: String::new(),
        verdict: None,
    };
    let c = &scratch.joint.camera;
    let i = &scratch.initial;
    let mut notes = vec![format!(
        "intrinsics estimated from {} frames (Zhang's closed form fx {:.2} fy {:.2} cx {:.2} cy {:.2} px, no distortion; then jointly refined; the pose-space column uses the refined ones): fx {:.2} fy {:.2} cx {:.2} cy {:.2} px, {} {:?}; written to {}",
        frames.len(),
        i.fx, i.fy, i.cx, i.cy,
        c.fx, c.fy, c.cx, c.cy,
        "plumb_bob", c.distortion_coefficients(),
        camera_info.display()
    )];
    if let Some(sigma) = scratch.joint.intrinsics_sigma_px {
        notes.push(format!(
            "intrinsics 1-sigma: fx {:.3} fy {:.3} cx {:.3} cy {:.3} px",
            sigma[0], sigma[1], sigma[2], sigma[3]
        ));
    }
    let verdict = verdict::assess_solved(
        &solved.calibration,
        &pairs,
        &options,
        config.verdict.accuracy(),
    );
    solved.summary = format!("{}\n{}", verdict.terminal_lines(), solved.describe(&notes));
    solved.verdict = Some(verdict);
    Ok((
        solved,
        Dataset {
            setup: manifest.setup,
            pairs,
        },
    ))
}

/// The reprojection refinement's frames from recorded visits: every accepted visit (one with a
/// board pose, or any visit with corners when `require_pose` is false) with its corners mapped to
/// board points; corners of tags not on the board are skipped. Ids are `pose-NNN` like the
/// samples'.
pub fn frames_from_visits(
    visits: &[PoseVisit],
    board: &Board,
    require_pose: bool,
) -> Result<Vec<(String, Frame)>, SessionError> {
    let mut frames = Vec::new();
    for visit in visits {
        let accepted = visit.camera_from_target.is_some() || !require_pose;
        if !accepted || visit.corners_px.is_empty() {
            continue;
        }
        let (base_from_flange, _) = visit.poses(&SessionFolder::visit_name(visit.plan_index))?;
        // Corners were checked when the record was read; a tag the board does not have (a
        // stray detection of another family member) is skipped.
        let corners = visit
            .corners_px
            .iter()
            .filter_map(|c| {
                let points = board.tag_corners_in_target(c.tag_id)?;
                Some(Corner {
                    point_in_target: points[usize::from(c.corner)],
                    pixel: c.pixel,
                })
            })
            .collect();
        let id = format!("pose-{:03}", visit.plan_index);
        frames.push((
            id.clone(),
            Frame {
                base_from_flange,
                corners,
                id: Some(id),
            },
        ));
    }
    Ok(frames)
}

/// Solves pose pairs and, when `vision` (board and intrinsics) is given and the config's space is
/// reprojection, refines over the visits' corners; no I/O.
pub fn solve_session(
    setup: Setup,
    pairs: &[PosePair],
    visits: &[PoseVisit],
    vision: Option<(&Board, &CameraModel)>,
    config: &CellConfig,
) -> Result<SolvedSession, SessionError> {
    let options = config.solver.to_options();
    let pose_space =
        solve::solve(setup, pairs, &options).map_err(|source| SessionError::Solve {
            stage: "pose space",
            source,
        })?;
    let mut solved = SolvedSession {
        calibration: pose_space.clone(),
        pose_space,
        reprojection: None,
        pose_space_errors: None,
        frame_ids: Vec::new(),
        estimated_camera: None,
        summary: String::new(),
        verdict: None,
    };
    let mut notes = Vec::new();
    if let Some((board, camera)) = vision {
        // Frames the pose-space solve dropped as outliers stay out here too.
        let dropped: Vec<&str> = solved
            .pose_space
            .dropped
            .iter()
            .filter_map(|&i| pairs.get(i).and_then(|p| p.id.as_deref()))
            .collect();
        let (ids, frames): (Vec<String>, Vec<Frame>) = frames_from_visits(visits, board, true)?
            .into_iter()
            .filter(|(id, _)| !dropped.contains(&id.as_str()))
            .unzip();
        if frames.iter().filter(|f| !f.corners.is_empty()).count() >= 3 {
            let ropts = reprojection_options(config);
            let p = &solved.pose_space;
            let reprojection = refine_reprojection(
                setup,
                &frames,
                camera,
                &p.camera_mount,
                &p.target_mount,
                &ropts,
            )
            .map_err(|source| SessionError::Solve {
                stage: "reprojection refinement",
                source,
            })?;
            solved.pose_space_errors = Some(reprojection_errors(
                setup,
                &frames,
                camera,
                &p.camera_mount,
                &p.target_mount,
            ));
            solved.calibration = reprojection.to_calibration(p, pairs, &options.noise);
            solved.reprojection = Some(reprojection);
            solved.frame_ids = ids;
        } else {
            notes.push(
                "fewer than 3 frames with recorded corners: pose-space answer only".to_string(),
            );
        }
    }
    let verdict = verdict::assess_solved(
        &solved.calibration,
        pairs,
        &options,
        config.verdict.accuracy(),
    );
    solved.summary = format!("{}\n{}", verdict.terminal_lines(), solved.describe(&notes));
    solved.verdict = Some(verdict);
    Ok(solved)
}

fn pose_line(pose: &Pose) -> String {
    let t = pose.translation.vector * 1e3;
    let rv = crate::geometry::rotvec(&pose.rotation);
    format!(
        "[{:.2}, {:.2}, {:.2}] mm, rotvec [{:.5}, {:.5}, {:.5}] rad",
        t.x, t.y, t.z, rv.x, rv.y, rv.z
    )
}

impl SolvedSession {
    /// Both answers' reprojection errors, when the reprojection refinement ran.
    pub fn reprojection_summary(&self) -> Option<ReprojectionSummary> {
        let r = self.reprojection.as_ref()?;
        let p = self.pose_space_errors.as_ref()?;
        let corrected = !r.corrected_base_from_flange.is_empty();
        Some(ReprojectionSummary {
            pose_space_rms_px: p.rms_px,
            reprojection_rms_px: r.recorded_pose_errors.rms_px,
            corrected_rms_px: corrected.then_some(r.errors.rms_px),
            pose_space_max_px: p.max_px,
            reprojection_max_px: r.recorded_pose_errors.max_px,
            corners: r.errors.corner_px.iter().map(Vec::len).sum(),
            outlier_corners: r.outlier_corners.len(),
            robot_corrections: corrected,
            intrinsics_estimated: self.estimated_camera.is_some(),
            pixel_sigma_px: r.pixel_sigma_px,
            robot_repeatability: r.robot_prior.map(|p| {
                [
                    p.translation_sigma_m * 1e3,
                    p.rotation_sigma_rad.to_degrees(),
                ]
            }),
            noise_estimated: r.noise_estimated,
            frames: self
                .frame_ids
                .iter()
                .enumerate()
                .map(|(i, id)| FrameRms {
                    id: id.clone(),
                    pose_space_rms_px: p.frame_rms_px[i],
                    reprojection_rms_px: r.recorded_pose_errors.frame_rms_px[i],
                    corrected_rms_px: corrected.then_some(r.errors.frame_rms_px[i]),
                    outlier: r.outlier_frames.contains(&i),
                })
                .collect(),
        })
    }

    fn describe(&self, notes: &[String]) -> String {
        let (Some(reprojection), Some(pose_errors)) = (&self.reprojection, &self.pose_space_errors)
        else {
            let mut out = self.pose_space.summary();
            for note in notes {
                let _ = write!(out, "\nnote: {note}");
            }
            return out;
        };
        let mut out = self.calibration.summary();
        let p = &self.pose_space;
        let c = &self.calibration;
        let _ = writeln!(out, "\n\nboth answers side by side:");
        let _ = writeln!(
            out,
            "{:<34} {:>14} {:>14}",
            "", "pose space", "reprojection"
        );
        let row = |out: &mut String, name: &str, a: f64, b: f64, unit: &str| {
            let _ = writeln!(out, "{name:<34} {a:>11.4} {unit:<2} {b:>11.4} {unit:<2}");
        };
        let recorded = &reprojection.recorded_pose_errors;
        let corrected = !reprojection.corrected_base_from_flange.is_empty();
        row(
            &mut out,
            "reprojection RMS",
            pose_errors.rms_px,
            recorded.rms_px,
            "px",
        );
        row(
            &mut out,
            "reprojection max",
            pose_errors.max_px,
            recorded.max_px,
            "px",
        );
        if corrected {
            let _ = writeln!(
                out,
                "{:<34} {:>14} {:>11.4} px",
                "  with corrected robot poses", "", reprojection.errors.rms_px
            );
        }
        row(
            &mut out,
            "board pose rotation RMS",
            p.residuals.rotation_rms_deg,
            c.residuals.rotation_rms_deg,
            "°",
        );
        row(
            &mut out,
            "board pose translation RMS",
            p.residuals.translation_rms_mm,
            c.residuals.translation_rms_mm,
            "mm",
        );
        for ((key, a), (_, b)) in p.unknowns().iter().zip(c.unknowns().iter()) {
            let _ = writeln!(out, "{key} pose space:   {}", pose_line(a));
            let _ = writeln!(out, "{key} reprojection: {}", pose_line(b));
            let _ = writeln!(
                out,
                "    the two differ by {:.3} mm, {:.4}°",
                (a.translation.vector - b.translation.vector).norm() * 1e3,
                a.rotation.angle_to(&b.rotation).to_degrees()
            );
        }
        let _ = writeln!(
            out,
            "per-frame reprojection RMS, px (pose space / reprojection{}):",
            if corrected {
                " / reprojection with corrected robot poses"
            } else {
                ""
            }
        );
        let cells: Vec<String> = self
            .frame_ids
            .iter()
            .enumerate()
            .map(|(i, id)| {
                let flag = if reprojection.outlier_frames.contains(&i) {
                    " !"
                } else {
                    ""
                };
                let (a, b) = (pose_errors.frame_rms_px[i], recorded.frame_rms_px[i]);
                if corrected {
                    let c = reprojection.errors.frame_rms_px[i];
                    format!("{id} {a:.3}/{b:.3}/{c:.3}{flag}")
                } else {
                    format!("{id} {a:.3}/{b:.3}{flag}")
                }
            })
            .collect();
        for chunk in cells.chunks(if corrected { 3 } else { 4 }) {
            let _ = writeln!(out, "  {}", chunk.join("   "));
        }
        for note in notes {
            let _ = writeln!(out, "note: {note}");
        }
        out.trim_end().to_string()
    }

    /// The error of each unknown against the simulator's truth, one line each (both answers
    /// when the reprojection refinement ran).
    pub fn compare_with_truth(&self, truth: &CellTransforms) -> String {
        let line = |label: &str, key: &str, estimate: &Pose, truth: &Pose| {
            format!(
                "  {key}{label}: error {:.3} mm, {:.4}° against the simulator's ground truth",
                (estimate.translation.vector - truth.translation.vector).norm() * 1e3,
                estimate.rotation.angle_to(&truth.rotation).to_degrees()
            )
        };
        let mut lines = vec!["ground truth check:".to_string()];
        let mut answers = vec![("", &self.calibration)];
        if self.reprojection.is_some() {
            answers = vec![
                (" (pose space)", &self.pose_space),
                (" (reprojection)", &self.calibration),
            ];
        }
        for (label, calibration) in answers {
            let [(camera_key, camera_mount), (target_key, target_mount)] = calibration.unknowns();
            lines.push(line(label, camera_key, &camera_mount, &truth.camera_mount));
            lines.push(line(label, target_key, &target_mount, &truth.target_mount));
        }
        lines.join("\n")
    }
}
