//! The verdict on a calibration: GOOD, CHECK or REDO, with the one reason that decided it and the
//! next action, judged from measured quantities against the accuracy the user asked for.
//!
//! Owns [`Verdict`] and the one pure function that makes it ([`assess`]), the held-out
//! (leave-one-out) figures it needs ([`held_out`]), the verdict of a refused solve
//! ([`Verdict::refused`]), and the health notices that the terminal, the result file and the
//! report all show ([`coverage_notices`], [`residual_notice`]): one source, so they agree.
//!
//! # Thresholds
//!
//! With the stated accuracy `A` (`verdict: {accuracy_mm, accuracy_deg}` in the cell config,
//! default [`DEFAULT_ACCURACY_MM`] mm and [`DEFAULT_ACCURACY_DEG`]°):
//!
//! * **REDO** — the answer is unusable: the solve was refused (too few poses, rotations about one
//!   axis, too little rotation); the data fits far better with inverted poses (a convention
//!   error, `solve::diagnostics::check_convention`); the held-out error (each sample predicted by
//!   a solve of all the others: translation of the target at the working distance, mm, and
//!   rotation, degrees, RMS) or the 1-sigma of either transform is above [`REDO_FACTOR`] × `A`;
//!   or a notice of severity `error`.
//! * **CHECK** — usable, but something needs a look: held-out error or 1-sigma between 1× and
//!   3× `A`; samples flagged as outliers (named); residuals more than [`RESIDUAL_FACTOR`] × what
//!   the noise model expects; rotations less than [`GOOD_OFF_AXIS_DEG`]° off their main axis;
//!   fewer than [`GOOD_POSES`] poses; no held-out check possible; any other warning of the
//!   solver (not converged, frame or corner outliers, ...).
//! * **GOOD** — none of the above.
//!
//! The held-out error includes the noise of the held-out board pose itself, so it is the error
//! a user sees when the calibration predicts where the board is; samples flagged as outliers
//! are left out of its summary (their measurement is the problem, not the calibration) and
//! named on their own. Units: mm and degrees throughout (figures people read).
//!
//! Depends on `solve` (the calibration, its diagnostics, the solver for the held-out folds),
//! `notice` and the ground floor (`setup`, `geometry`).

use std::fmt::Write;

use serde::{Deserialize, Serialize};

use crate::geometry::{rms, Pose};
use crate::notice::{Notice, NoticeKind, Severity};
use crate::setup::{PosePair, Setup};
use crate::solve::{
    self, diagnostics, rotation_diversity, Calibration, NoiseModel, SolveError, SolveOptions,
};

/// Default accuracy the user wants for translation, mm.
pub const DEFAULT_ACCURACY_MM: f64 = 1.0;
/// Default accuracy the user wants for rotation, degrees (≈ 1 mm at 0.6 m).
pub const DEFAULT_ACCURACY_DEG: f64 = 0.1;
/// Above this multiple of the accuracy a held-out error or 1-sigma makes the answer REDO.
pub const REDO_FACTOR: f64 = 3.0;
/// Residual RMS above this multiple of the noise model's expectation is CHECK.
pub const RESIDUAL_FACTOR: f64 = 3.0;
/// Fewer poses than this is CHECK (below 8 the noise cannot be estimated from the residuals).
pub const GOOD_POSES: usize = 8;
/// Largest relative rotation off the dominant axis below which the spread is CHECK, degrees.
pub const GOOD_OFF_AXIS_DEG: f64 = 20.0;
/// At most this many samples are held out in turn (evenly spaced) by [`held_out`].
pub const MAX_HELD_OUT: usize = 100;
/// Fewest samples for a held-out check (each fold must still solve).
pub const MIN_HELD_OUT_SAMPLES: usize = 5;

/// GOOD, CHECK or REDO (ordered: a worse level compares greater).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Level {
    /// Use it.
    Good,
    /// Usable, but look at the reason first.
    Check,
    /// Do not use it: record again (or fix the input) as the next action says.
    Redo,
}

impl Level {
    /// `GOOD`, `CHECK` or `REDO`.
    pub fn word(self) -> &'static str {
        match self {
            Level::Good => "GOOD",
            Level::Check => "CHECK",
            Level::Redo => "REDO",
        }
    }
}

impl std::fmt::Display for Level {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.word())
    }
}

/// What a finding is about (so code and tests can ask which one decided the verdict).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Basis {
    /// The solver refused the input (too few poses, degenerate motion, bad values).
    Refused,
    /// The data fits far better with inverted poses: a convention error.
    ConventionError,
    /// The held-out (leave-one-out) prediction error against the accuracy.
    HeldOutError,
    /// The 1-sigma of a transform against the accuracy.
    Uncertainty,
    /// Residuals beyond the noise model.
    Residuals,
    /// Samples flagged as outliers.
    Outliers,
    /// A warning or error notice of the solver not covered above.
    SolverNotice,
    /// Rotations mostly about one axis.
    RotationSpread,
    /// Few poses, or too few for a held-out check.
    FewPoses,
    /// Nothing found: every figure within the accuracy.
    WithinAccuracy,
}

/// One thing the verdict looked at that was not fine, with what to do about it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Finding {
    /// How bad.
    pub level: Level,
    /// What about.
    pub basis: Basis,
    /// The measured fact, with its numbers and threshold.
    pub reason: String,
    /// What to do next.
    pub next_action: String,
}

/// The accuracy the user wants of both transforms (`verdict:` in the cell config).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Accuracy {
    /// Translation, mm.
    pub translation_mm: f64,
    /// Rotation, degrees.
    pub rotation_deg: f64,
}

impl Default for Accuracy {
    fn default() -> Self {
        Accuracy {
            translation_mm: DEFAULT_ACCURACY_MM,
            rotation_deg: DEFAULT_ACCURACY_DEG,
        }
    }
}

/// Held-out prediction errors of `T_camera_target` (each sample predicted by a solve of the
/// others), summarised over the samples not flagged as outliers.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HeldOut {
    /// Samples held out and summarised.
    pub poses: usize,
    /// RMS distance between predicted and measured target origin (camera frame), mm.
    pub translation_rms_mm: f64,
    /// RMS angle between predicted and measured rotation, degrees.
    pub rotation_rms_deg: f64,
    /// Median camera-to-target distance of the samples, mm (where the error is measured).
    pub working_distance_mm: f64,
}

/// The measured quantities the verdict was made from (absent where not measured).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Figures {
    /// Samples given.
    pub poses: usize,
    /// Held-out errors.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub held_out: Option<HeldOut>,
    /// Larger 1-sigma translation of the two transforms, mm.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sigma_translation_mm: Option<f64>,
    /// Larger 1-sigma rotation of the two transforms, degrees.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sigma_rotation_deg: Option<f64>,
    /// Residual RMS, rotation, degrees.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub residual_rotation_rms_deg: Option<f64>,
    /// Residual RMS, translation, mm.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub residual_translation_rms_mm: Option<f64>,
    /// Samples flagged as outliers.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub outliers: Vec<usize>,
    /// Largest relative flange rotation off the dominant axis, degrees.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rotation_off_axis_deg: Option<f64>,
}

/// GOOD / CHECK / REDO with the reason that decided it, the next action, the figures, and any
/// further findings that need a look.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Verdict {
    /// The level.
    pub level: Level,
    /// What decided it.
    pub basis: Basis,
    /// The one reason that decided it.
    pub reason: String,
    /// What to do next.
    pub next_action: String,
    /// The accuracy it was judged against.
    pub accuracy: Accuracy,
    /// The measured quantities.
    pub figures: Figures,
    /// Other findings that need a look, worst first.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub also: Vec<Finding>,
}

impl Verdict {
    /// The verdict on a solve that was refused: REDO with the solver's reason.
    pub fn refused(error: &SolveError, poses: usize, accuracy: Accuracy) -> Verdict {
        let (basis, next_action) = match error {
            SolveError::ConventionMismatch { .. } => (
                Basis::ConventionError,
                "fix the convention of the input poses (see the reason) and solve again",
            ),
            SolveError::TooFewSamples { .. } => {
                (Basis::Refused, "record more poses (12–20) and solve again")
            }
            SolveError::Coaxial { .. } | SolveError::TooLittleRotation { .. } => (
                Basis::Refused,
                "record poses tilted 20–40° about two other flange axes and solve again",
            ),
            _ => (Basis::Refused, "fix what the reason names and solve again"),
        };
        Verdict {
            level: Level::Redo,
            basis,
            reason: format!("the solve was refused: {error}"),
            next_action: next_action.into(),
            accuracy,
            figures: Figures {
                poses,
                ..Figures::default()
            },
            also: Vec::new(),
        }
    }

    /// The first line(s) the CLI prints: `verdict: GOOD — reason`, `next: action`, and one
    /// `also:` line per further finding.
    pub fn terminal_lines(&self) -> String {
        let mut out = format!(
            "verdict: {} — {}\nnext: {}",
            self.level, self.reason, self.next_action
        );
        for f in &self.also {
            let _ = write!(out, "\nalso ({}): {}", f.level, f.reason);
        }
        out
    }
}

/// Everything [`assess`] judges.
#[derive(Debug, Clone, Copy)]
pub struct Evidence<'a> {
    /// The answer.
    pub calibration: &'a Calibration,
    /// The samples it was solved from (indexed like its residuals).
    pub pairs: &'a [PosePair],
    /// The noise model the solver was told.
    pub noise: &'a NoiseModel,
    /// Held-out errors, or why there are none.
    pub held_out: &'a Result<HeldOut, String>,
    /// The accuracy the user wants.
    pub accuracy: Accuracy,
}

fn median(mut values: Vec<f64>) -> f64 {
    values.sort_by(f64::total_cmp);
    let n = values.len();
    match n {
        0 => f64::NAN,
        _ if n % 2 == 1 => values[n / 2],
        _ => 0.5 * (values[n / 2 - 1] + values[n / 2]),
    }
}

/// Held-out (leave-one-out) errors: each sample (at most [`MAX_HELD_OUT`], evenly spaced) is
/// predicted by a solve of all the others with `options` (covariance and convention checks off
/// in the folds), and the prediction compared with its measured `T_camera_target`. Samples in
/// `outliers` are held out like the others but left out of the summary. Fails (with the reason)
/// for fewer than [`MIN_HELD_OUT_SAMPLES`] samples or when a fold cannot be solved.
pub fn held_out(
    setup: Setup,
    pairs: &[PosePair],
    options: &SolveOptions,
    outliers: &[usize],
) -> Result<HeldOut, String> {
    let n = pairs.len();
    if n < MIN_HELD_OUT_SAMPLES {
        return Err(format!(
            "only {n} samples: a held-out check needs at least {MIN_HELD_OUT_SAMPLES}"
        ));
    }
    let count = n.min(MAX_HELD_OUT);
    let mut errors = Vec::with_capacity(count);
    for k in 0..count {
        let left_out = k * n / count;
        let predicted = solve::predict_left_out(setup, pairs, options, left_out).map_err(|e| {
            format!(
                "solving without sample {left_out} failed ({e}): the answer hangs on that one pose"
            )
        })?;
        if outliers.contains(&left_out) {
            continue;
        }
        let measured: &Pose = &pairs[left_out].camera_from_target;
        errors.push((
            (predicted.translation.vector - measured.translation.vector).norm() * 1e3,
            predicted.rotation.angle_to(&measured.rotation).to_degrees(),
        ));
    }
    if errors.is_empty() {
        return Err("every held-out sample is flagged as an outlier".into());
    }
    Ok(HeldOut {
        poses: errors.len(),
        translation_rms_mm: rms(errors.iter().map(|e| e.0)),
        rotation_rms_deg: rms(errors.iter().map(|e| e.1)),
        working_distance_mm: median(
            pairs
                .iter()
                .map(|p| p.camera_from_target.translation.vector.norm() * 1e3)
                .collect(),
        ),
    })
}

/// Notices about the poses themselves: fewer than [`GOOD_POSES`], or rotations less than
/// [`GOOD_OFF_AXIS_DEG`] off their dominant axis (warnings; the report shows them, the verdict
/// turns them into CHECK).
pub fn coverage_notices(pairs: &[PosePair]) -> Vec<Notice> {
    let mut out = Vec::new();
    let n = pairs.len();
    if n < GOOD_POSES {
        out.push(Notice::warning(NoticeKind::FewPoses, format!(
            "only {n} poses: below {GOOD_POSES} the noise level cannot be estimated from the residuals (the uncertainty assumes the configured noise) and a single bad pose can pull the answer; record 12–20"
        )));
    }
    let robot: Vec<Pose> = pairs.iter().map(|p| p.base_from_flange).collect();
    let diversity = rotation_diversity(&robot);
    if diversity.off_axis_deg < GOOD_OFF_AXIS_DEG {
        out.push(Notice::warning(NoticeKind::PoorRotationSpread, format!(
            "poor rotation spread: the flange rotations are mostly about one axis (only {:.1}° off it, {GOOD_OFF_AXIS_DEG:.0}° wanted); add poses tilted 20–40° about two other flange axes",
            diversity.off_axis_deg
        )));
    }
    out
}

/// The residual health of one answer, judged one way everywhere: an `error` notice when the data
/// fits far better with inverted robot poses (the solver's own convention check,
/// `solve::diagnostics::check_convention`, thresholds relative to the noise model), else a
/// warning when the residual RMS is more than [`RESIDUAL_FACTOR`] × what the noise model
/// expects; `None` when the residuals are as expected.
pub fn residual_notice(
    calibration: &Calibration,
    pairs: &[PosePair],
    noise: &NoiseModel,
) -> Option<Notice> {
    let r = &calibration.residuals;
    let used: Vec<PosePair> = pairs
        .iter()
        .enumerate()
        .filter(|(i, _)| !calibration.dropped.contains(i))
        .map(|(_, p)| p.clone())
        .collect();
    if let Err(e @ SolveError::ConventionMismatch { .. }) =
        diagnostics::check_convention(calibration.setup, &used, Some(r.rotation_rms_deg), noise)
    {
        return Some(Notice::new(
            Severity::Error,
            NoticeKind::LikelyConventionError,
            e.to_string(),
        ));
    }
    // Norms of 3-axis noise: √3 σ.
    let expected_rot_deg = noise.rotation_sigma_rad.to_degrees() * 3f64.sqrt();
    let expected_t_mm = noise.translation_sigma_m * 1e3 * 3f64.sqrt();
    if r.rotation_rms_deg > RESIDUAL_FACTOR * expected_rot_deg
        || r.translation_rms_mm > RESIDUAL_FACTOR * expected_t_mm
    {
        return Some(Notice::warning(NoticeKind::LargeResiduals, format!(
            "residuals (RMS {:.3}°, {:.2} mm) are more than {RESIDUAL_FACTOR}× what the noise model expects ({:.3}°, {:.2} mm): the robot poses and frames may not be synchronised, the board may be loose, or the noise model is optimistic",
            r.rotation_rms_deg, r.translation_rms_mm, expected_rot_deg, expected_t_mm
        )));
    }
    None
}

/// The level of a measured value against its accuracy: GOOD up to 1×, CHECK up to
/// [`REDO_FACTOR`]×, REDO above (and for a non-finite value).
fn band(value: f64, accuracy: f64) -> Level {
    if !value.is_finite() || value > REDO_FACTOR * accuracy {
        Level::Redo
    } else if value > accuracy {
        Level::Check
    } else {
        Level::Good
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

    // Held-out error at the working distance.
    match evidence.held_out {
        Ok(h) => {
            figures.held_out = Some(*h);
            let level = band(h.translation_rms_mm, a.translation_mm)
                .max(band(h.rotation_rms_deg, a.rotation_deg));
            if level > Level::Good {
                findings.push(Finding {
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
                });
            }
        }
        Err(why) => findings.push(Finding {
            level: Level::Check,
            basis: Basis::FewPoses,
            reason: format!("no held-out check: {why}"),
            next_action: "record more poses (12–20) so each can be checked against the others"
                .into(),
        }),
    }

    // 1-sigma of both transforms.
    match &c.uncertainty {
        Some(u) => {
            let t = u
                .camera_mount
                .translation_mm
                .max(u.target_mount.translation_mm);
            let r = u.camera_mount.rotation_deg.max(u.target_mount.rotation_deg);
            figures.sigma_translation_mm = Some(t);
            figures.sigma_rotation_deg = Some(r);
            let level = band(t, a.translation_mm).max(band(r, a.rotation_deg));
            if level > Level::Good {
                let (camera_name, target_name) = c.setup.unknown_names();
                findings.push(Finding {
                    level,
                    basis: Basis::Uncertainty,
                    reason: format!(
                        "1-sigma up to {t:.2} mm, {r:.3}° ({camera_name}: {:.2} mm, {:.3}°; {target_name}: {:.2} mm, {:.3}°) against the {} mm, {}° asked for",
                        u.camera_mount.translation_mm,
                        u.camera_mount.rotation_deg,
                        u.target_mount.translation_mm,
                        u.target_mount.rotation_deg,
                        a.translation_mm,
                        a.rotation_deg
                    ),
                    next_action: next_for_band(
                        level,
                        "record more poses with larger, more varied rotations",
                    ),
                });
            }
        }
        None => findings.push(Finding {
            level: Level::Check,
            basis: Basis::Uncertainty,
            reason: format!(
                "no 1-sigma: the {} method computes none",
                c.solver.method.name()
            ),
            next_action: "solve with the refined method to see the uncertainty".into(),
        }),
    }

    // Outliers, named.
    if !c.outliers.is_empty() {
        let named: Vec<String> = c
            .outliers
            .iter()
            .map(
                |&i| match evidence.pairs.get(i).and_then(|p| p.id.as_deref()) {
                    Some(id) => format!("{i} ({id})"),
                    None => i.to_string(),
                },
            )
            .collect();
        let dropped = if c.dropped.is_empty() {
            "still in the solve"
        } else {
            "dropped from the solve"
        };
        findings.push(Finding {
            level: Level::Check,
            basis: Basis::Outliers,
            reason: format!(
                "{} sample(s) flagged as outliers ({dropped}): {}",
                c.outliers.len(),
                named.join(", ")
            ),
            next_action: "look at the detection and the robot pose of those samples; re-record them if they are wrong".into(),
        });
    }

    // The solver's own warnings and errors not judged above.
    for notice in &c.warnings {
        let covered = matches!(
            notice.kind,
            NoticeKind::Outliers
                | NoticeKind::DroppedOutliers
                | NoticeKind::PoorlyDetermined
                | NoticeKind::LikelyConventionError
                | NoticeKind::LargeResiduals
                | NoticeKind::FewPoses
                | NoticeKind::PoorRotationSpread
        );
        if covered || !notice.needs_attention() {
            continue;
        }
        findings.push(Finding {
            level: if notice.severity == Severity::Error {
                Level::Redo
            } else {
                Level::Check
            },
            basis: Basis::SolverNotice,
            reason: notice.message.clone(),
            next_action: "act on the notice, then solve again".into(),
        });
    }

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

fn decide(mut findings: Vec<Finding>, figures: Figures, accuracy: Accuracy) -> Verdict {
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

/// The one call after a solve: held-out errors with the same options, then [`assess`].
pub fn assess_solved(
    calibration: &Calibration,
    pairs: &[PosePair],
    options: &SolveOptions,
    accuracy: Accuracy,
) -> Verdict {
    let held = held_out(calibration.setup, pairs, options, &calibration.outliers);
    assess(&Evidence {
        calibration,
        pairs,
        noise: &options.noise,
        held_out: &held,
        accuracy,
    })
}

/// The one call around a solve: [`assess_solved`] on its answer, or [`Verdict::refused`] when it
/// was refused.
pub fn assess_result(
    result: Result<&Calibration, &SolveError>,
    pairs: &[PosePair],
    options: &SolveOptions,
    accuracy: Accuracy,
) -> Verdict {
    match result {
        Ok(calibration) => assess_solved(calibration, pairs, options, accuracy),
        Err(error) => Verdict::refused(error, pairs.len(), accuracy),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
