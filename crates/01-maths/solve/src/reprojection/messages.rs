//! The text a person reads about a reprojection refinement: its weights, its summary line, and
//! the warnings about noise estimation, the covariance, outliers and convergence. Only
//! formatting: every number comes from the pipeline.
//!
//! Units as people read them: px, mm, degrees.

use super::noise::{NoiseReport, ROBOT_SIGMA_RANGE};
use super::outliers::Flags;
use super::{Frame, ReprojectionCalibration, ReprojectionErrors};
use handeye_core::notice::{Notice, NoticeKind};

/// What corners and robot poses were weighted with, and where the numbers came from.
pub(super) fn weights(calibration: &ReprojectionCalibration) -> String {
    let origin = if calibration.noise_estimated {
        "estimated from the residuals"
    } else {
        "as configured"
    };
    let robot = match calibration.robot_prior {
        Some(prior) => format!(
            ", robot repeatability {:.4} mm / {:.5}° (1-sigma per axis)",
            prior.translation_sigma_m * 1e3,
            prior.rotation_sigma_rad.to_degrees()
        ),
        None => ", robot poses taken as exact".to_string(),
    };
    format!(
        "weights {origin}: corner noise {:.3} px{robot}",
        calibration.pixel_sigma_px
    )
}

/// The one line that says a pose-space answer was refined in reprojection space, and how well.
pub(super) fn summary(calibration: &ReprojectionCalibration) -> Notice {
    let errors = &calibration.errors;
    let message = format!(
        "refined in reprojection space over {} corners: RMS {:.3} px (max {:.3} px); {}",
        errors.corner_px.iter().map(Vec::len).sum::<usize>(),
        errors.rms_px,
        errors.max_px,
        weights(calibration)
    );
    Notice::info(NoticeKind::ReprojectionRefined, message)
}

/// Notes on the noise estimation (none when it went as planned).
pub(super) fn noise_notes(report: &NoiseReport) -> Vec<Notice> {
    let mut notes = Vec::new();
    if !report.estimated {
        notes.push(Notice::warning(
            NoticeKind::NoiseEstimate,
            "the noise could not be estimated from the residuals (too few corners or a singular problem): the configured noise is used",
        ));
    }
    if let Some((used, given)) = report.robot_at_bound {
        let figures = format!(
            "({:.4} mm, {:.5}°; configured {:.4} mm, {:.5}°)",
            used.translation_sigma_m * 1e3,
            used.rotation_sigma_rad.to_degrees(),
            given.translation_sigma_m * 1e3,
            given.rotation_sigma_rad.to_degrees(),
        );
        if used.translation_sigma_m < given.translation_sigma_m
            || used.rotation_sigma_rad < given.rotation_sigma_rad
        {
            // An arm that repeats better than its data sheet is no reason to doubt the answer:
            // its poses are weighed as if a little worse than they are, which costs nothing
            // measurable. Information, not a warning.
            notes.push(Notice::info(NoticeKind::NoiseEstimate, format!(
                "the robot repeats better than configured: its poses agree to {}x the configured repeatability or better {figures}; the estimate stops there, which does not affect the answer (set `robot.repeatability_mm` / `_deg` lower to weigh it as it is)",
                ROBOT_SIGMA_RANGE.0,
            )));
        } else {
            // Far worse than configured: robot poses off by more than the arm's own repeatability
            // (a wrong TCP, a loose mount, poses read at the wrong moment) can make the answer
            // wrong.
            notes.push(Notice::warning(NoticeKind::NoiseEstimate, format!(
                "the robot poses scatter {}x the configured repeatability or more {figures}: check the configured repeatability, and that the recorded flange poses are the arm's (TCP, timing, a loose mount)",
                ROBOT_SIGMA_RANGE.1,
            )));
        }
    }
    notes
}

/// The covariance could not be computed.
pub(super) fn singular() -> Notice {
    Notice::warning(
        NoticeKind::NoCovariance,
        "the reprojection problem is singular at the optimum: no covariance (the frames do not constrain every parameter)",
    )
}

/// Warnings about the outliers flagged at the optimum, naming frames by index and id.
pub(super) fn outlier_warnings(
    frames: &[Frame],
    errors: &ReprojectionErrors,
    flags: &Flags,
) -> Vec<Notice> {
    let mut warnings = Vec::new();
    let id = |f: usize| {
        frames[f]
            .id
            .as_ref()
            .map(|id| format!(" ({id})"))
            .unwrap_or_default()
    };
    if !flags.pixel_frames.is_empty() {
        let described: Vec<String> = flags
            .pixel_frames
            .iter()
            .map(|&i| match &frames[i].id {
                Some(id) => format!("{i} ({id}, {:.2} px)", errors.frame_rms_px[i]),
                None => format!("{i} ({:.2} px)", errors.frame_rms_px[i]),
            })
            .collect();
        warnings.push(Notice::warning(NoticeKind::FrameOutliers, format!(
            "{} frame(s) reproject far worse than the rest: {} (check detection and robot pose of those frames)",
            flags.pixel_frames.len(),
            described.join(", ")
        )));
    }
    if !flags.robot_frames.is_empty() {
        let described: Vec<String> = flags
            .robot_frames
            .iter()
            .map(|o| {
                format!(
                    "{}{} ({:.3} mm, {:.4}°: {:.0}x the repeatability the other frames show)",
                    o.frame,
                    id(o.frame),
                    o.translation_m * 1e3,
                    o.rotation_rad.to_degrees(),
                    o.repeatabilities
                )
            })
            .collect();
        warnings.push(Notice::warning(NoticeKind::RobotPoseOutliers, format!(
            "{} frame(s) needed a robot-pose correction far beyond the others: {} (their recorded robot pose and their detections disagree with the other frames; check both; they were left out of the hand-eye fit)",
            flags.robot_frames.len(),
            described.join(", ")
        )));
    }
    if !flags.corners.is_empty() {
        warnings.push(Notice::warning(
            NoticeKind::CornerOutliers,
            format!(
                "{} corner(s) have errors far above the rest (down-weighted by the robust loss)",
                flags.corners.len()
            ),
        ));
    }
    warnings
}

/// LM did not meet its tolerance in every round.
pub(super) fn not_converged() -> Notice {
    Notice::warning(
        NoticeKind::NotConverged,
        "the reprojection refinement did not meet its tolerance; the answer may be inaccurate",
    )
}
