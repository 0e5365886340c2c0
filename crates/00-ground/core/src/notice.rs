//! Notices: what the tool tells a person about a calibration, typed once and rendered the same
//! by the terminal, the result file and the report (part of the ground floor).
//!
//! A [`Notice`] carries a [`Severity`] (information, a warning worth checking, or an error that
//! makes the answer unusable), a [`NoticeKind`] that says what it is about (so code can test for
//! a kind instead of matching text) and the sentence people read. Good news — "refined over 2880
//! corners, RMS 0.075 px" — is `Info`, never a warning. Depends on nothing.

use serde::{Deserialize, Serialize};

/// How much a notice matters to the person reading it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Severity {
    /// Information: how the answer was made; nothing to do.
    Info,
    /// Worth checking before the answer is used.
    Warning,
    /// The answer should not be used as it is.
    Error,
}

impl Severity {
    /// The word printed before the message (`info`, `warning`, `error`).
    pub fn label(self) -> &'static str {
        match self {
            Severity::Info => "info",
            Severity::Warning => "warning",
            Severity::Error => "error",
        }
    }
}

impl std::fmt::Display for Severity {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.label())
    }
}

/// What a notice is about.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum NoticeKind {
    /// Samples whose residuals stand far above the rest.
    Outliers,
    /// Flagged samples were dropped and the problem solved again.
    DroppedOutliers,
    /// An unknown's 1-sigma exceeds the configured limit.
    PoorlyDetermined,
    /// An iterative method stopped before meeting its tolerance.
    NotConverged,
    /// The answer was refined in reprojection (pixel) space; figures of that fit.
    ReprojectionRefined,
    /// Noise levels estimated from the residuals (or why they were not).
    NoiseEstimate,
    /// No covariance: the problem is singular at the optimum.
    NoCovariance,
    /// Frames that reproject far worse than the rest.
    FrameOutliers,
    /// Frames whose recorded robot pose needed a correction far beyond the others.
    RobotPoseOutliers,
    /// Corners with errors far above the rest.
    CornerOutliers,
    /// Fewer poses than a trustworthy answer needs.
    FewPoses,
    /// Flange rotations mostly about one axis.
    PoorRotationSpread,
    /// Residuals far beyond the noise: most likely a convention error.
    LikelyConventionError,
    /// Residuals larger than the noise model expects.
    LargeResiduals,
    /// A solved transform no real cell has (a camera far from the flange it is mounted on, the
    /// two unknowns swapped as when both input poses are inverted).
    ImplausibleTransform,
    /// The answer is far from the config's nominal transforms (the drawing or tape measure).
    FarFromNominal,
    /// The configured intrinsics do not fit the frames (intrinsics estimated from the session
    /// fit far better); the message is the reason, then ` — next: ` and what to do.
    WrongIntrinsics,
    /// The configured intrinsics file differs from the calibration the camera driver publishes
    /// (a ROS 2 camera's `camera_info`, kept in the session). A warning when the board's corners
    /// fit the driver's better or cannot tell (the verdict's `Intrinsics` finding, CHECK), info
    /// when they fit the file better; a warning's message is the reason, then ` — next: ` and
    /// what to do.
    DriverCalibration,
    /// The session was still being recorded when it was solved: the answer is of the poses so
    /// far, and the run will add to them.
    Provisional,
    /// A ROS 2 bag the session was imported from says something of itself that is not so (a
    /// lie or a contradiction the import tolerated: `metadata.yaml` naming files outside the
    /// bag, an image whose header contradicts its data, one TF edge both static and moving,
    /// ...); the message names the bag, the topic or frames and the kind of lie, as
    /// `import/bag-import.yaml` records it.
    BagWarning,
    /// Anything else (also a plain message read from an older result file).
    Other,
}

/// One thing the tool tells its user: a severity, what it is about, and the sentence to read.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Notice {
    /// How much it matters.
    pub severity: Severity,
    /// What it is about.
    pub kind: NoticeKind,
    /// The sentence people read, saying what to do where there is something to do.
    pub message: String,
}

impl Notice {
    /// A notice of `severity` about `kind`.
    pub fn new(severity: Severity, kind: NoticeKind, message: impl Into<String>) -> Notice {
        Notice {
            severity,
            kind,
            message: message.into(),
        }
    }

    /// Information: nothing to do.
    pub fn info(kind: NoticeKind, message: impl Into<String>) -> Notice {
        Notice::new(Severity::Info, kind, message)
    }

    /// A warning: worth checking.
    pub fn warning(kind: NoticeKind, message: impl Into<String>) -> Notice {
        Notice::new(Severity::Warning, kind, message)
    }

    /// The same notice with `prefix: ` before its message (e.g. which answer it is about).
    pub fn prefixed(&self, prefix: &str) -> Notice {
        Notice {
            message: format!("{prefix}: {}", self.message),
            ..self.clone()
        }
    }

    /// True for warnings and errors: what a person must look at.
    pub fn needs_attention(&self) -> bool {
        self.severity >= Severity::Warning
    }
}

impl std::fmt::Display for Notice {
    /// `warning: <message>` — the one line form the terminal prints.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}: {}", self.severity, self.message)
    }
}

/// Reads a result file's `warnings:` list, which older versions wrote as plain strings: a string
/// becomes a warning of kind `Other`, so an old file still shows every message it had.
pub fn deserialize_notices<'de, D>(deserializer: D) -> Result<Vec<Notice>, D::Error>
where
    D: serde::Deserializer<'de>,
{
    #[derive(Deserialize)]
    #[serde(untagged)]
    enum Stored {
        Typed(Notice),
        Plain(String),
    }
    let stored: Vec<Stored> = Vec::deserialize(deserializer)?;
    Ok(stored
        .into_iter()
        .map(|s| match s {
            Stored::Typed(notice) => notice,
            Stored::Plain(message) => Notice::warning(NoticeKind::Other, message),
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, Deserialize)]
    struct Holder {
        #[serde(deserialize_with = "deserialize_notices")]
        warnings: Vec<Notice>,
    }

    #[test]
    fn typed_and_plain_forms_both_read() {
        let yaml = "warnings:\n  - {severity: info, kind: reprojection_refined, message: fine}\n  - an old plain warning\n";
        let holder: Holder = serde_yaml_ng::from_str(yaml).unwrap();
        assert_eq!(
            holder.warnings,
            vec![
                Notice::info(NoticeKind::ReprojectionRefined, "fine"),
                Notice::warning(NoticeKind::Other, "an old plain warning"),
            ]
        );
    }

    #[test]
    fn a_typed_notice_round_trips_and_prints_its_severity() {
        let notice = Notice::warning(NoticeKind::Outliers, "2 sample(s) look like outliers");
        let text = serde_yaml_ng::to_string(&notice).unwrap();
        let back: Notice = serde_yaml_ng::from_str(&text).unwrap();
        assert_eq!(back, notice);
        assert_eq!(
            notice.to_string(),
            "warning: 2 sample(s) look like outliers"
        );
        assert!(notice.needs_attention());
        assert!(!Notice::info(NoticeKind::NoiseEstimate, "x").needs_attention());
    }
}
