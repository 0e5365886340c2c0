//! The rules of the verdict: [`assess`], a pure function from the [`Evidence`] to a
//! [`Verdict`] (the thresholds of the parent module doc), and the banding against the accuracy.
//!
//! Depends on `solve` (the calibration and noise types, the rotation diversity), `notice`, the
//! ground floor (`setup`, `geometry`), the residual and coverage notices of
//! [`evidence`](super::evidence), and the types of its parent [`verdict`](super).

use std::fmt::Write;

use crate::board_scale::BoardScale;
use crate::cell_model::CellModelSummary;
use crate::{rotation_diversity, Calibration, NoiseModel};
use handeye_core::geometry::Pose;
use handeye_core::notice::{NoticeKind, Severity};
use handeye_core::setup::PosePair;

use super::evidence::{coverage_notices, residual_notice};
use super::{Accuracy, Basis, Figures, Finding, HeldOut, Level, Verdict, REDO_FACTOR};

/// Everything [`assess`] judges.
#[derive(Debug, Clone, Copy)]
pub struct Evidence<'a> {
    /// The answer.
    pub calibration: &'a Calibration,
    /// The samples it was solved from (indexed like its residuals), as the solve weighed them
    /// (each view's precision folded into its weight, [`crate::SolveOptions::weighted`]).
    pub pairs: &'a [PosePair],
    /// The noise model the solver was told.
    pub noise: &'a NoiseModel,
    /// Held-out errors, or why there are none.
    pub held_out: &'a Result<HeldOut, String>,
    /// The accuracy the user wants.
    pub accuracy: Accuracy,
    /// The board scale fitted with the calibration, when it could be fitted.
    pub board_scale: Option<BoardScale>,
    /// The cell model's choice between the files as given and a wrong intrinsics or board file
    /// (reprojection space, [`crate::cell_model`]), when the corners were fitted. It replaces
    /// the pose-space board-scale rule.
    pub cell_model: Option<&'a CellModelSummary>,
}

/// The level of a measured value against its accuracy: GOOD up to 1×, CHECK up to
/// [`REDO_FACTOR`]×, REDO above (and for a non-finite value).
pub(crate) fn band(value: f64, accuracy: f64) -> Level {
    if !value.is_finite() || value > REDO_FACTOR * accuracy {
        Level::Redo
    } else if value > accuracy {
        Level::Check
    } else {
        Level::Good
    }
}

/// What to do about a solver notice the checks above do not judge: the usual cause of each
/// kind and its remedy (the notice's own text names the samples, frames or corners).
fn next_for_notice(kind: NoticeKind) -> &'static str {
    match kind {
        NoticeKind::NotConverged => "add poses with larger, more varied rotations (the solve stopped before converging: the poses are too few or too alike), then solve again",
        NoticeKind::NoCovariance => "add poses that rotate about other axes (the answer is not determined in some direction), then solve again",
        NoticeKind::FrameOutliers => "look at the frames the notice names in the report (blur, glare, the board partly out of view); re-record or drop them, then solve again",
        NoticeKind::RobotPoseOutliers => "check the robot poses of the frames the notice names (read before the arm settled, another TCP); re-record them, then solve again",
        NoticeKind::CornerOutliers => "look at the corners the notice names in the report (glare, a creased or damaged print); flatten or reprint the board, or re-record those frames, then solve again",
        NoticeKind::ImplausibleTransform => "check the input poses' directions (T_base_flange, not T_flange_base; T_camera_target, not T_target_camera) and the setup (eye_in_hand or eye_to_hand), then solve again",
        _ => "fix what the notice names, then solve again",
    }
}

fn next_for_band(level: Level, what: &str) -> String {
    match level {
        Level::Redo => format!("{what}; then solve again"),
        _ => format!("check whether this accuracy is enough for the task; if not, {what}"),
    }
}

/// The verdict: every check of the module doc, worst finding first (ties in the order of
/// [`Basis`]); GOOD when nothing was found.
pub fn assess(evidence: &Evidence<'_>) -> Verdict {
    let c = evidence.calibration;
    let a = evidence.accuracy;
    let mut findings: Vec<Finding> = Vec::new();
    let mut figures = Figures {
        poses: evidence.pairs.len(),
        residual_rotation_rms_deg: Some(c.residuals.rotation_rms_deg),
        residual_translation_rms_mm: Some(c.residuals.translation_rms_mm),
        outliers: c.outliers.clone(),
        ..Figures::default()
    };

    // Intrinsics that are not this camera's: everything else follows from them (REDO). The
    // camera driver's own calibration differing from the file, the corners fitting the
    // driver's better (or too few frames to tell): the file may be stale (CHECK, not REDO: the
    // answer may still be within the accuracy; the wrong-intrinsics check and the cell model
    // below judge how far the file is off).
    for (kind, level) in [
        (NoticeKind::WrongIntrinsics, Level::Redo),
        (NoticeKind::DriverCalibration, Level::Check),
    ] {
        if let Some(notice) = c
            .notices
            .iter()
            .find(|n| n.kind == kind && n.needs_attention())
        {
            let (reason, next) = notice.message.split_once(super::NEXT_SEPARATOR).unwrap_or((
                notice.message.as_str(),
                "calibrate the camera, then solve again",
            ));
            findings.push(Finding {
                level,
                basis: Basis::Intrinsics,
                reason: reason.into(),
                next_action: next.into(),
            });
        }
    }

    // The cell model: which given file the corners contradict (a model choice); it explains the
    // residuals and held-out error a wrong file causes, so it comes before them.
    if let Some(model) = evidence.cell_model {
        figures.cell_model = Some(model.clone());
        findings.extend(model.finding(a));
    }
    let modelled_scale = evidence
        .cell_model
        .filter(|m| m.chosen.board_wrong())
        .and_then(|m| m.estimates.iter().find(|e| e.parameter == "scale"));

    // The board's size in pose space (without corners): a wrong one explains the residuals and
    // held-out error it causes, so it comes before them.
    if let Some(scale) = &evidence.board_scale {
        figures.board_scale = Some(scale.factor);
        figures.board_scale_sigma = Some(scale.sigma);
        let intrinsics_wrong = c
            .notices
            .iter()
            .any(|n| n.kind == NoticeKind::WrongIntrinsics);
        if scale.is_wrong() && !intrinsics_wrong && evidence.cell_model.is_none() {
            findings.push(board_scale_finding(scale, evidence.pairs, a));
        }
    }
    // The board's scale the answer used, when the cell model estimated it (the pose-space fit
    // above then ran on board poses already corrected by it).
    if let Some(e) = modelled_scale {
        figures.board_scale = Some(e.estimate);
        figures.board_scale_sigma = Some(e.sigma);
    }

    // Residual health, with the convention check.
    if let Some(notice) = residual_notice(c, evidence.pairs, evidence.noise) {
        let (level, basis, next) = if notice.kind == NoticeKind::LikelyConventionError {
            (
                Level::Redo,
                Basis::ConventionError,
                "fix the convention of the input poses and solve again",
            )
        } else {
            (
                Level::Check,
                Basis::Residuals,
                "look at the per-pose residuals: check the robot/camera timing, the board mounting and the noise model",
            )
        };
        findings.push(Finding {
            level,
            basis,
            reason: notice.message,
            next_action: next.into(),
        });
    }

    // Far from the nominal transforms: is this the cell the config describes? Before the
    // held-out error and the solver's notices, which judge the answer's precision, not what it is.
    if let Some(notice) = c
        .notices
        .iter()
        .find(|n| n.kind == NoticeKind::FarFromNominal)
    {
        let (camera, target) = c.setup.unknown_names();
        findings.push(Finding {
            level: Level::Check,
            basis: Basis::FarFromNominal,
            reason: notice.message.clone(),
            next_action: format!(
                "find out which is wrong: if the nominal (drawing, tape measure) is, set the far one of nominal.{camera}, nominal.{target} in {} to its solved value and `handeye replay {} --config {}`; if the cell is as drawn, the camera or board moved or the robot poses are in another frame — fix that and record again",
                super::CONFIG_PLACEHOLDER,
                super::SESSION_PLACEHOLDER,
                super::CONFIG_PLACEHOLDER,
            ),
        });
    }

    // Held-out error at the working distance.
    findings.extend(held_out_finding(
        evidence.held_out.as_ref().map_err(String::as_str),
        a,
        &mut figures,
    ));

    // 1-sigma of both transforms.
    findings.extend(uncertainty_finding(c, a, &mut figures));

    // Outliers, named.
    findings.extend(outliers_finding(c, evidence.pairs));

    // The solver's own warnings and errors not judged above.
    findings.extend(solver_notice_findings(c));

    // Coverage.
    let robot: Vec<Pose> = evidence.pairs.iter().map(|p| p.base_from_flange).collect();
    figures.rotation_off_axis_deg = Some(rotation_diversity(&robot).off_axis_deg);
    for notice in coverage_notices(evidence.pairs) {
        let basis = match notice.kind {
            NoticeKind::PoorRotationSpread => Basis::RotationSpread,
            _ => Basis::FewPoses,
        };
        findings.push(Finding {
            level: Level::Check,
            basis,
            reason: notice.message,
            next_action: "add poses as the reason says and solve again".into(),
        });
    }

    decide(findings, figures, a)
}

/// The held-out error at the working distance against the accuracy (none within it), or the
/// missing check; kept in `figures`.
pub(super) fn held_out_finding(
    held_out: Result<&HeldOut, &str>,
    a: Accuracy,
    figures: &mut Figures,
) -> Option<Finding> {
    match held_out {
        Ok(h) => {
            figures.held_out = Some(*h);
            let level = band(h.translation_rms_mm, a.translation_mm)
                .max(band(h.rotation_rms_deg, a.rotation_deg));
            (level > Level::Good).then(|| Finding {
                level,
                basis: Basis::HeldOutError,
                reason: format!(
                    "held-out error {:.2} mm, {:.3}° (RMS over {} poses, target at ~{:.0} mm) against the {} mm, {}° asked for",
                    h.translation_rms_mm,
                    h.rotation_rms_deg,
                    h.poses,
                    h.working_distance_mm,
                    a.translation_mm,
                    a.rotation_deg
                ),
                next_action: next_for_band(
                    level,
                    "record more poses with larger, more varied rotations, the board closer and better lit",
                ),
            })
        }
        Err(why) => Some(Finding {
            level: Level::Check,
            basis: Basis::FewPoses,
            reason: format!("no held-out check: {why}"),
            next_action: "record more poses (12–20) so each can be checked against the others"
                .into(),
        }),
    }
}

/// The larger 1-sigma of the two transforms against the accuracy (none within it), or its
/// absence; kept in `figures`.
fn uncertainty_finding(c: &Calibration, a: Accuracy, figures: &mut Figures) -> Option<Finding> {
    let Some(u) = &c.uncertainty else {
        return Some(Finding {
            level: Level::Check,
            basis: Basis::Uncertainty,
            reason: format!(
                "no 1-sigma: the {} method computes none",
                c.solver.method.name()
            ),
            next_action: "solve with the refined method to see the uncertainty".into(),
        });
    };
    let (camera_name, target_name) = c.setup.unknown_names();
    sigma_finding(
        u.camera_mount
            .translation_mm
            .max(u.target_mount.translation_mm),
        u.camera_mount.rotation_deg.max(u.target_mount.rotation_deg),
        &format!(
            " ({camera_name}: {:.2} mm, {:.3}°; {target_name}: {:.2} mm, {:.3}°)",
            u.camera_mount.translation_mm,
            u.camera_mount.rotation_deg,
            u.target_mount.translation_mm,
            u.target_mount.rotation_deg,
        ),
        a,
        figures,
    )
}

/// A 1-sigma of `t` mm and `r`° (the larger of what `parts` details) against the accuracy (none
/// within it); kept in `figures`.
pub(super) fn sigma_finding(
    t: f64,
    r: f64,
    parts: &str,
    a: Accuracy,
    figures: &mut Figures,
) -> Option<Finding> {
    figures.sigma_translation_mm = Some(t);
    figures.sigma_rotation_deg = Some(r);
    let level = band(t, a.translation_mm).max(band(r, a.rotation_deg));
    (level > Level::Good).then(|| Finding {
        level,
        basis: Basis::Uncertainty,
        reason: format!(
            "1-sigma up to {t:.2} mm, {r:.3}°{parts} against the {} mm, {}° asked for",
            a.translation_mm, a.rotation_deg
        ),
        next_action: next_for_band(
            level,
            "record more poses with larger, more varied rotations",
        ),
    })
}

/// The samples flagged as outliers, named by index and id.
fn outliers_finding(c: &Calibration, pairs: &[PosePair]) -> Option<Finding> {
    if c.outliers.is_empty() {
        return None;
    }
    let named: Vec<String> = c
        .outliers
        .iter()
        .map(|&i| match pairs.get(i).and_then(|p| p.id.as_deref()) {
            Some(id) => format!("{i} ({id})"),
            None => i.to_string(),
        })
        .collect();
    let dropped = if c.dropped.is_empty() {
        "still in the solve"
    } else {
        "dropped from the solve"
    };
    Some(Finding {
        level: Level::Check,
        basis: Basis::Outliers,
        reason: format!(
            "{} sample(s) flagged as outliers ({dropped}): {}",
            c.outliers.len(),
            named.join(", ")
        ),
        next_action: "look at the detection and the robot pose of those samples; re-record them if they are wrong".into(),
    })
}

/// The solver's own warnings and errors that no other finding judges.
fn solver_notice_findings(c: &Calibration) -> impl Iterator<Item = Finding> + '_ {
    c.notices
        .iter()
        .filter(|notice| {
            let covered = matches!(
                notice.kind,
                NoticeKind::Outliers
                    | NoticeKind::DroppedOutliers
                    | NoticeKind::PoorlyDetermined
                    | NoticeKind::LikelyConventionError
                    | NoticeKind::LargeResiduals
                    | NoticeKind::FewPoses
                    | NoticeKind::PoorRotationSpread
                    | NoticeKind::FarFromNominal
                    | NoticeKind::WrongIntrinsics
            );
            !covered && notice.needs_attention()
        })
        .map(|notice| Finding {
            level: if notice.severity == Severity::Error {
                Level::Redo
            } else {
                Level::Check
            },
            basis: Basis::SolverNotice,
            reason: notice.message.clone(),
            next_action: next_for_notice(notice.kind).into(),
        })
}

/// The finding of a board that is not the size its file says: the factor, what it means for the
/// print and the residuals, and the fix (measure a tag, set `tagSize`, replay).
fn board_scale_finding(scale: &BoardScale, pairs: &[PosePair], a: Accuracy) -> Finding {
    let s = scale.factor;
    let distance_mm = super::working_distance_mm(pairs);
    let effect_mm = (s - 1.0).abs() * distance_mm;
    let level = band(effect_mm, a.translation_mm).max(Level::Check);
    let size = if s < 1.0 { "smaller" } else { "larger" };
    Finding {
        level,
        basis: Basis::BoardScale,
        reason: format!(
            "the board measures {s:.3}× (±{:.4}) the size in its board file — printed at {:.0} %? Every measured board distance is {:.1} % too {} ({effect_mm:.0} mm at {distance_mm:.0} mm); scaling the board poses by {s:.3} drops the translation residuals from {:.2} mm to {:.2} mm RMS over {} poses",
            scale.sigma,
            s * 100.0,
            (1.0 / s - 1.0).abs() * 100.0,
            if s < 1.0 { "long" } else { "short" },
            scale.residual_unscaled_mm,
            scale.residual_scaled_mm,
            scale.samples,
        ),
        next_action: format!(
            "measure a printed tag's black square with a ruler (the board is {:.1} % {size} than its file says) and set {} in the board file {}, then `handeye replay {} --config {}`",
            (s - 1.0).abs() * 100.0,
            super::BOARD_SIZE_KEYS,
            super::BOARD_PLACEHOLDER,
            super::SESSION_PLACEHOLDER,
            super::CONFIG_PLACEHOLDER,
        ),
    }
}

/// The verdict of `findings`: the worst leads (ties in the order given), the rest follow under
/// `also`; GOOD, with the figures, when there is none.
pub(super) fn decide(mut findings: Vec<Finding>, figures: Figures, accuracy: Accuracy) -> Verdict {
    // Stable: among equal levels the order of the checks above (their importance) stays.
    findings.sort_by_key(|f| std::cmp::Reverse(f.level));
    if findings.is_empty() {
        let mut reason = format!(
            "every figure within the {} mm, {}° asked for",
            accuracy.translation_mm, accuracy.rotation_deg
        );
        if let Some(h) = figures.held_out {
            let _ = write!(
                reason,
                ": held-out error {:.2} mm, {:.3}° over {} poses",
                h.translation_rms_mm, h.rotation_rms_deg, h.poses
            );
        }
        if let (Some(t), Some(r)) = (figures.sigma_translation_mm, figures.sigma_rotation_deg) {
            let _ = write!(reason, ", 1-sigma up to {t:.2} mm, {r:.3}°");
        }
        return Verdict {
            level: Level::Good,
            basis: Basis::WithinAccuracy,
            reason,
            next_action: "use the result".into(),
            accuracy,
            figures,
            also: Vec::new(),
        };
    }
    let first = findings.remove(0);
    Verdict {
        level: first.level,
        basis: first.basis,
        reason: first.reason,
        next_action: first.next_action,
        accuracy,
        figures,
        also: findings,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_solver_notice_gets_the_action_of_its_kind() {
        // Issue #30: "act on the notice" said nothing; each kind names its usual cause.
        for (kind, words) in [
            (NoticeKind::FrameOutliers, "blur, glare"),
            (NoticeKind::RobotPoseOutliers, "before the arm settled"),
            (NoticeKind::CornerOutliers, "creased or damaged print"),
            (NoticeKind::ImplausibleTransform, "T_flange_base"),
            (NoticeKind::NoCovariance, "rotate about other axes"),
            (NoticeKind::NotConverged, "too few or too alike"),
        ] {
            let next = next_for_notice(kind);
            assert!(
                next.contains(words) && !next.contains("act on the notice"),
                "{kind:?}: {next}"
            );
        }
    }

    #[test]
    fn bands_are_one_and_three_times_the_accuracy() {
        assert_eq!(band(1.0, 1.0), Level::Good);
        assert_eq!(band(1.01, 1.0), Level::Check);
        assert_eq!(band(3.0, 1.0), Level::Check);
        assert_eq!(band(3.01, 1.0), Level::Redo);
        assert_eq!(band(f64::NAN, 1.0), Level::Redo);
        assert!(Level::Redo > Level::Check && Level::Check > Level::Good);
    }

    #[test]
    fn a_wrong_board_size_is_banded_by_its_error_at_the_working_distance() {
        use handeye_core::geometry::Pose;
        let pairs: Vec<PosePair> = (0..5)
            .map(|_| PosePair::new(Pose::identity(), Pose::translation(0.0, 0.0, 0.6)))
            .collect();
        let scale = |factor| BoardScale {
            factor,
            sigma: 1e-4,
            residual_unscaled_mm: 3.0,
            residual_scaled_mm: 0.05,
            samples: 5,
        };
        // 5 % at 600 mm is 30 mm: REDO against 1 mm, CHECK against 20 mm.
        let f = board_scale_finding(&scale(0.95), &pairs, Accuracy::default());
        assert_eq!((f.level, f.basis), (Level::Redo, Basis::BoardScale));
        assert!(
            f.reason.starts_with(
                "the board measures 0.950× (±0.0001) the size in its board file — printed at 95 %?"
            ),
            "{}",
            f.reason
        );
        assert!(
            f.reason.contains("too long (30 mm at 600 mm)"),
            "{}",
            f.reason
        );
        assert!(f.next_action.contains("5.0 % smaller"), "{}", f.next_action);
        let loose = Accuracy {
            translation_mm: 20.0,
            rotation_deg: 1.0,
        };
        let f = board_scale_finding(&scale(1.05), &pairs, loose);
        assert_eq!(f.level, Level::Check);
        assert!(f.next_action.contains("5.0 % larger"), "{}", f.next_action);
        // Within 1 %, or not explaining the residuals, it is no finding.
        assert!(!scale(0.995).is_wrong());
        assert!(!BoardScale {
            residual_scaled_mm: 2.0,
            ..scale(0.95)
        }
        .is_wrong());
    }

    #[test]
    fn the_worst_finding_decides_and_the_rest_follow_in_check_order() {
        let finding = |level, basis, reason: &str| Finding {
            level,
            basis,
            reason: reason.into(),
            next_action: format!("fix {reason}"),
        };
        let v = decide(
            vec![
                finding(Level::Check, Basis::Outliers, "outliers"),
                finding(Level::Redo, Basis::HeldOutError, "held-out"),
                finding(Level::Check, Basis::FewPoses, "few"),
            ],
            Figures::default(),
            Accuracy::default(),
        );
        assert_eq!((v.level, v.basis), (Level::Redo, Basis::HeldOutError));
        assert_eq!(v.next_action, "fix held-out");
        assert_eq!(
            v.terminal_lines(),
            "verdict: REDO — held-out\nnext: fix held-out\nalso (CHECK): outliers\nalso (CHECK): few"
        );
        let good = decide(Vec::new(), Figures::default(), Accuracy::default());
        assert_eq!(
            (good.level, good.basis),
            (Level::Good, Basis::WithinAccuracy)
        );
    }
}
