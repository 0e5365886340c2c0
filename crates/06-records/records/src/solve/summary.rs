//! The human side of a solved session: the summary text (`describe`: both answers side by side,
//! per-frame reprojection RMS, notes), the comparison with the simulator's ground truth, and the
//! shape of `reprojection.yaml` ([`ReprojectionSummary`], [`FrameRms`]).
//!
//! Reads a [`SolvedSession`] only; computes nothing the solve did not (pixels in px, lengths
//! shown in mm, angles in degrees). Depends on `geometry` and `setup` (the ground floor) and on
//! its parent, `session::solve`.

use std::fmt::Write;

use serde::{Deserialize, Serialize};

use super::SolvedSession;
use handeye_core::geometry::Pose;
use handeye_core::setup::CellTransforms;

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

fn pose_line(pose: &Pose) -> String {
    let t = pose.translation.vector * 1e3;
    let rv = handeye_core::geometry::rotvec(&pose.rotation);
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

    /// The human summary: the final answer, then (when the reprojection refinement ran) both
    /// answers side by side and the per-frame RMS; `notes` close it.
    pub(super) fn describe(&self, notes: &[String]) -> String {
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
