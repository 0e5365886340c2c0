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
//! * **REDO** — the intrinsics do not fit the frames: a `wrong_intrinsics` notice (the session
//!   layer's check: board reprojection far above normal and intrinsics estimated from the
//!   session far from the file's); decides over everything it causes.
//! * **CHECK** or **REDO** — the cell model ([`crate::cell_model`], when the corners were fitted)
//!   chooses a wrong intrinsics or board file by BIC: CHECK when the views determine the quantity
//!   (the answer uses the estimate, the finding names the file, the parameters, the file's values
//!   and the estimates with their 1-sigma), REDO when they do not, when a wrong lens cannot be
//!   told from a wrong board, or when the files as given are chosen but the views could not have
//!   seen them wrong; replaces the pose-space board-scale rule below.
//! * **REDO** (or CHECK when its effect at the working distance is within 3× `A`) — without
//!   corners, the board is not the size its file says: the scale of the board-pose translations fitted with the
//!   calibration (`board_scale`) is off 1 by more than 1 % and 3 sigmas and explains the
//!   residuals; decides over the held-out error and residuals it causes.
//! * **CHECK** — usable, but something needs a look: the answer more than 50 mm or 20° from the
//!   config's nominal transforms (a `far_from_nominal` notice, both values); held-out error or 1-sigma between 1× and
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
//!
//! # Files
//!
//! This file holds the types and thresholds; [`rules`] the pure [`assess`] (the rules above);
//! [`evidence`] the gathering of what it judges ([`held_out`], the notices) and the calls around
//! a solve ([`assess_solved`], [`assess_result`]). Their items are re-exported here, so callers
//! use `verdict::…` paths only.

use std::fmt::Write;

use serde::{Deserialize, Serialize};

use crate::SolveError;

pub mod evidence;
pub mod mount;
pub mod rules;

pub use evidence::{
    assess_modelled, assess_result, assess_solved, coverage_notices, held_out, held_out_refitting,
    predict_folds, residual_notice, working_distance_mm, FoldFailure, FoldFlanges,
};
pub use mount::{assess_mount, worst_camera};
pub use rules::{assess, Evidence};

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
/// Between the reason and the next action in a notice that carries both (`WrongIntrinsics`).
pub const NEXT_SEPARATOR: &str = " — next: ";
/// Placeholder for the session folder in a next action; the session layer names the folder
/// ([`Verdict::name_session`]).
pub const SESSION_PLACEHOLDER: &str = "<session>";
/// Placeholder for the folder a solve writes its estimates of wrong files into (the session
/// folder for a run; beside its output for a replay, which never writes into the session);
/// the session layer names it.
pub const ESTIMATES_PLACEHOLDER: &str = "<estimates>";
/// Placeholder for the cell config in a next action; the session layer names it.
pub const CONFIG_PLACEHOLDER: &str = "<cell.yaml>";
/// Placeholder for the board file in a next action; the session layer names it.
pub const BOARD_PLACEHOLDER: &str = "<board.yaml>";
/// Placeholder for the intrinsics file in a next action; the session layer names it.
pub const INTRINSICS_PLACEHOLDER: &str = "<intrinsics>";
/// The board file's size keys in advice, for every board kind (the solver does not know which
/// one the cell has).
pub const BOARD_SIZE_KEYS: &str = "its size in metres (`tagSize` of an aprilgrid, `squareLength` and `markerLength` of a ChArUco board, `colSpacingMeters` and `rowSpacingMeters` of a chessboard)";
/// Fewest samples for a held-out check (each fold must still solve).
pub const MIN_HELD_OUT_SAMPLES: usize = 5;

/// The files a verdict's advice names, filled in by the session layer
/// ([`Verdict::name_session`]).
#[derive(Debug, Clone, Default)]
pub struct SessionFiles {
    /// The session folder.
    pub session: String,
    /// The folder the estimates of wrong files are written into.
    pub estimates: String,
    /// The cell config.
    pub config: String,
    /// The board file.
    pub board: String,
    /// The intrinsics file (empty when the config has none).
    pub intrinsics: String,
}

impl SessionFiles {
    /// `text` with the placeholders replaced.
    pub fn fill(&self, text: &str) -> String {
        text.replace(SESSION_PLACEHOLDER, &self.session)
            .replace(ESTIMATES_PLACEHOLDER, &self.estimates)
            .replace(CONFIG_PLACEHOLDER, &self.config)
            .replace(BOARD_PLACEHOLDER, &self.board)
            .replace(INTRINSICS_PLACEHOLDER, &self.intrinsics)
    }
}

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
    /// The board is not the size its file says (printed at another scale, `tagSize` wrong): the
    /// fitted scale of the board-pose translations is off 1 and explains the residuals.
    BoardScale,
    /// The intrinsics do not fit the frames (per-frame reprojection far above normal, or the
    /// intrinsics estimated from the session far from the file's).
    Intrinsics,
    /// The corners contradict both the intrinsics and the board file, or cannot tell which of
    /// the two is wrong (the cell model, `solve::cell_model`).
    IntrinsicsAndBoard,
    /// The answer is far from the config's nominal transforms.
    FarFromNominal,
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

impl Accuracy {
    /// The level of a measured error against this accuracy, the worse of translation and
    /// rotation: GOOD up to 1×, CHECK up to [`REDO_FACTOR`]×, REDO above (or not finite) — the
    /// verdict's bands, for a check made apart from a solve (`handeye verify`).
    pub fn level_of(&self, translation_mm: f64, rotation_deg: f64) -> Level {
        rules::band(translation_mm, self.translation_mm)
            .max(rules::band(rotation_deg, self.rotation_deg))
    }
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
    /// RMS distance between predicted and measured target origin (camera frame), mm, each
    /// sample at its weight (its view's precision: `solve::view_weighted`).
    pub translation_rms_mm: f64,
    /// RMS angle between predicted and measured rotation, degrees, each sample at its weight.
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
    /// The board scale fitted with the calibration (1: the board is the size its file says).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub board_scale: Option<f64>,
    /// 1-sigma of `board_scale`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub board_scale_sigma: Option<f64>,
    /// The cell model's choice between the files as given and a wrong intrinsics or board file,
    /// when the corners were fitted.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cell_model: Option<crate::cell_model::CellModelSummary>,
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

    /// The verdict with the placeholders ([`SESSION_PLACEHOLDER`], [`ESTIMATES_PLACEHOLDER`],
    /// [`CONFIG_PLACEHOLDER`],
    /// [`BOARD_PLACEHOLDER`], [`INTRINSICS_PLACEHOLDER`]) in its reasons and next actions
    /// replaced by the files they stand for (known to the session layer, not to the pure rules).
    pub fn name_session(&mut self, files: &SessionFiles) {
        let fill = |text: &mut String| *text = files.fill(text);
        fill(&mut self.reason);
        fill(&mut self.next_action);
        for f in &mut self.also {
            fill(&mut f.reason);
            fill(&mut f.next_action);
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
