//! The calibration report: one self-contained HTML page (inline SVG plots and inline PNG
//! thumbnails, no script, no network) that answers "is this calibration any good?".
//!
//! Owns the report's input ([`ReportInput`], with a list of [`ReportAnswer`]s shown side by side,
//! e.g. the pose-space and a reprojection-space answer), the HTML layout with the verdict card
//! first (GOOD / CHECK / REDO, made by `verdict`, the same as the terminal and `result.yaml`
//! show) and the plain-language warnings (their health checks also from `verdict`). The verdict
//! card, the per-answer transforms and their export forms ([`export_forms`]) are written by
//! `sections.rs`; the plots are drawn with `plotters`' SVG backend in [`plots`], and [`session`]
//! gathers the input from a session folder (frames, detected corners). Frames follow the crate
//! convention (`T_a_b` maps points of frame `b` into frame `a`); numbers are shown in metres /
//! radians where a file holds them and in mm / degrees where a person reads them. Depends on
//! `solve`, `verdict`, `formats`, `vision`, `config`, `dataset`, `session` (for the folder
//! layout) and the ground floor (`geometry`, `setup`, `camera_model`, `notice`, `atomic_file`);
//! nothing depends on it but the CLI.
//!
//! Every section and every plot carries a stable `id` / `data-kind`, and every number that
//! `result.yaml` also holds carries a `data-key`, so tests can check the page's structure and
//! values without parsing prose.

pub mod plots;
mod sections;
pub mod session;

use std::fmt::Write;
use std::path::{Path, PathBuf};

use crate::atomic_file::write_atomic;
use crate::notice::Notice;
use crate::setup::{PosePair, Setup};
use crate::solve::{rotation_diversity, Calibration, NoiseModel};
use crate::verdict::{self, Verdict};

pub use sections::export_forms;
use sections::{figure, transforms_section, verdict_card};

/// One answer (a calibration of the same samples) to show.
#[derive(Debug, Clone)]
pub struct ReportAnswer {
    /// Short name shown in headings and legends (`pose-space`, `reprojection`, ...).
    pub label: String,
    /// The calibration.
    pub calibration: Calibration,
    /// Per sample (indexed like [`ReportInput::pairs`]): RMS distance, px, between the detected
    /// board corners and the board reprojected at the `T_camera_target` this answer predicts;
    /// `None` where the corners are unknown.
    pub reprojection_px: Vec<Option<f64>>,
}

/// A frame thumbnail with detected corners and the reprojected board drawn on it.
#[derive(Debug, Clone)]
pub struct FrameThumbnail {
    /// Sample index (into [`ReportInput::pairs`]).
    pub sample: usize,
    /// Caption (sample id and plan index).
    pub caption: String,
    /// The PNG bytes.
    pub png: Vec<u8>,
}

/// Leave-one-out figures to show beside the answers (see `verify::leave_one_out`).
#[derive(Debug, Clone, PartialEq)]
pub struct HoldoutSummary {
    /// What was held out (e.g. `leave-one-out over 20 samples`).
    pub description: String,
    /// RMS rotation error of the held-out predictions, degrees.
    pub rotation_rms_deg: f64,
    /// RMS translation error of the held-out predictions at the target, mm.
    pub translation_rms_mm: f64,
}

/// Everything the report shows.
#[derive(Debug, Clone)]
pub struct ReportInput {
    /// Page title (e.g. the session folder).
    pub title: String,
    /// The cell layout.
    pub setup: Setup,
    /// The samples the answers were solved from.
    pub pairs: Vec<PosePair>,
    /// The answers, first one primary (thumbnails reproject with it).
    pub answers: Vec<ReportAnswer>,
    /// Frame thumbnails (may be empty for a plain dataset).
    pub thumbnails: Vec<FrameThumbnail>,
    /// The noise model the solver was told (for the "large residual" warning).
    pub noise: NoiseModel,
    /// Held-out prediction errors, when computed.
    pub holdout: Option<HoldoutSummary>,
    /// The verdict on the primary answer (the one `result.yaml` holds); `None`: the page judges
    /// the primary answer itself with [`verdict::assess`], the held-out figures of
    /// [`ReportInput::holdout`] and the default accuracy.
    pub verdict: Option<Verdict>,
    /// The run's arm time (spent, and saved against the full plan), when the session kept it.
    pub arm_time: Option<crate::cell::run::ArmTime>,
}

impl ReportInput {
    /// The verdict the page shows: [`ReportInput::verdict`], else one made from the input.
    pub fn verdict(&self) -> Option<Verdict> {
        if let Some(v) = &self.verdict {
            return Some(v.clone());
        }
        let primary = self.answers.first()?;
        let held_out = self
            .holdout
            .as_ref()
            .map(|h| verdict::HeldOut {
                poses: self.pairs.len(),
                translation_rms_mm: h.translation_rms_mm,
                rotation_rms_deg: h.rotation_rms_deg,
                working_distance_mm: verdict::working_distance_mm(&self.pairs),
            })
            .ok_or_else(|| "not computed for this page".to_string());
        Some(verdict::assess(&verdict::Evidence {
            calibration: &primary.calibration,
            pairs: &self.pairs,
            noise: &self.noise,
            held_out: &held_out,
            accuracy: verdict::Accuracy::default(),
        }))
    }
}

/// Why the report could not be made.
#[derive(Debug, thiserror::Error)]
pub enum ReportError {
    /// Nothing to show.
    #[error("the report needs at least one answer and one sample")]
    Empty,
    /// A plot could not be drawn.
    #[error("drawing the {kind} plot failed: {message}")]
    Plot {
        /// Which plot.
        kind: &'static str,
        /// The plotting error.
        message: String,
    },
    /// A session file could not be read.
    #[error("reading the session for the report failed")]
    Session(#[source] Box<crate::session::SessionError>),
    /// A frame could not be read or encoded.
    #[error("{}: cannot make a thumbnail: {message}", path.display())]
    Frame {
        /// The frame file.
        path: PathBuf,
        /// What went wrong.
        message: String,
    },
    /// The report file could not be written.
    #[error("{}: cannot write the report", path.display())]
    Write {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        #[source]
        source: std::io::Error,
    },
}

/// The plot kinds, one figure each (`data-kind` in the page).
pub const PLOT_KINDS: [&str; 6] = [
    "residual-rotation",
    "residual-translation",
    "residual-reprojection",
    "rotation-axes",
    "poses-3d",
    "convergence",
];

/// The section ids, in page order.
pub const SECTIONS: [&str; 8] = [
    "verdict",
    "warnings",
    "transforms",
    "residuals",
    "rotation-axes",
    "poses-3d",
    "frames",
    "convergence",
];

/// Renders the page.
pub fn render_html(input: &ReportInput) -> Result<String, ReportError> {
    if input.answers.is_empty() || input.pairs.is_empty() {
        return Err(ReportError::Empty);
    }
    let mut html = String::new();
    let _ = write!(
        html,
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>{}</title>\n<style>{}</style></head><body>\n<h1>Calibration report: {}</h1>\n<p class=\"meta\">setup <b>{}</b>, {} samples, answers: {}</p>\n",
        escape(&input.title),
        CSS,
        escape(&input.title),
        input.setup,
        input.pairs.len(),
        input
            .answers
            .iter()
            .map(|a| escape(&a.label))
            .collect::<Vec<_>>()
            .join(", ")
    );

    // The verdict first: GOOD / CHECK / REDO, the reason that decided it and what to do next.
    if let Some(v) = input.verdict() {
        verdict_card(&mut html, &v);
    }

    // Then the warnings: the reader should see them before the numbers.
    // Information (how the answer was made) is listed apart, never in the warnings box.
    let notices = notices(input);
    let (attention, info): (Vec<&Notice>, Vec<&Notice>) =
        notices.iter().partition(|n| n.needs_attention());
    html.push_str("<section id=\"warnings\"><h2>Warnings</h2>\n");
    if attention.is_empty() {
        html.push_str("<p class=\"ok\">No warnings: enough poses, good rotation spread, residuals as expected.</p>\n");
    } else {
        html.push_str("<ul>\n");
        for n in &attention {
            let _ = writeln!(
                html,
                "<li class=\"{}\">{}</li>",
                n.severity.label(),
                escape(&n.message)
            );
        }
        html.push_str("</ul>\n");
    }
    if !info.is_empty() {
        html.push_str("<h3>Notes</h3>\n<ul>\n");
        for n in &info {
            let _ = writeln!(html, "<li class=\"info\">{}</li>", escape(&n.message));
        }
        html.push_str("</ul>\n");
    }
    html.push_str("</section>\n");

    html.push_str("<section id=\"transforms\"><h2>Transforms</h2>\n<div class=\"answers\">\n");
    for (k, answer) in input.answers.iter().enumerate() {
        transforms_section(&mut html, k, answer);
    }
    html.push_str("</div>\n");
    if let Some(h) = &input.holdout {
        let _ = writeln!(
            html,
            "<p class=\"holdout\">Held-out check ({}): predicted T_camera_target off by RMS <span data-key=\"holdout.rotation_rms_deg\">{:.4}</span>° and <span data-key=\"holdout.translation_rms_mm\">{:.3}</span> mm at the target.</p>",
            escape(&h.description),
            h.rotation_rms_deg,
            h.translation_rms_mm
        );
    }
    if let Some(a) = &input.arm_time {
        let _ = writeln!(
            html,
            "<p class=\"armtime\">Arm time: <span data-key=\"arm_time.spent_s\">{:.1}</span> s for {} poses ({:.1} s moving, {:.1} s settling); the full {}-pose plan in its given order: about {:.1} s, so <span data-key=\"arm_time.saved_s\">{:.1}</span> s saved.</p>",
            a.spent_s(),
            a.poses,
            a.moving_s,
            a.settling_s,
            a.full_plan_poses,
            a.full_plan_estimate_s,
            a.saved_s()
        );
    }
    html.push_str("</section>\n");

    html.push_str("<section id=\"residuals\"><h2>Per-pose residuals</h2>\n<p>Measured against predicted T_camera_target for every sample; red bars are flagged outliers, grey bars were dropped from the final solve.</p>\n");
    figure(
        &mut html,
        "residual-rotation",
        &plots::residual_bars(input, plots::ResidualKind::Rotation)?,
    );
    figure(
        &mut html,
        "residual-translation",
        &plots::residual_bars(input, plots::ResidualKind::Translation)?,
    );
    figure(
        &mut html,
        "residual-reprojection",
        &plots::residual_bars(input, plots::ResidualKind::Reprojection)?,
    );
    html.push_str("</section>\n");

    let diversity = rotation_diversity(
        &input
            .pairs
            .iter()
            .map(|p| p.base_from_flange)
            .collect::<Vec<_>>(),
    );
    let _ = write!(
        html,
        "<section id=\"rotation-axes\"><h2>Relative rotation axes</h2>\n<p>Axes of the relative flange rotations between every two samples (base frame; an axis and its opposite are the same, so all are drawn with z ≥ 0), on the unit sphere seen from +z and from +x; marker size grows with the rotation angle. The solver needs axes spread over the sphere, not bunched about one direction. Largest rotation off the dominant axis: {:.1}°.</p>\n",
        diversity.off_axis_deg
    );
    figure(
        &mut html,
        "rotation-axes",
        &plots::rotation_axes(&input.pairs)?,
    );
    html.push_str("</section>\n");

    html.push_str("<section id=\"poses-3d\"><h2>Cell sketch</h2>\n<p>Robot base (large triad at the origin), the target and the camera at every sample, as the primary answer puts them; axes x red, y green, z blue.</p>\n");
    figure(&mut html, "poses-3d", &plots::poses_3d(input)?);
    html.push_str("</section>\n");

    html.push_str("<section id=\"frames\"><h2>Frames</h2>\n");
    if input.thumbnails.is_empty() {
        html.push_str("<p>No frames recorded with these samples.</p>\n");
    } else {
        let _ = writeln!(
            html,
            "<p>Detected corners (green crosses) and the board reprojected at the T_camera_target predicted by <b>{}</b> (magenta outlines).</p>\n<div class=\"thumbs\">",
            escape(&input.answers[0].label)
        );
        for t in &input.thumbnails {
            let _ = writeln!(
                html,
                "<figure class=\"thumb\"><img alt=\"{}\" src=\"data:image/png;base64,{}\"><figcaption>{}</figcaption></figure>",
                escape(&t.caption),
                base64(&t.png),
                escape(&t.caption)
            );
        }
        html.push_str("</div>\n");
    }
    html.push_str("</section>\n");

    html.push_str("<section id=\"convergence\"><h2>Solver convergence</h2>\n<p>Update size per iteration of the iterative method (rotation rad, translation m) and the refinement cost per evaluation, log scale.</p>\n");
    figure(&mut html, "convergence", &plots::convergence(input)?);
    html.push_str("</section>\n</body></html>\n");
    Ok(html)
}

/// Renders the page and writes it atomically to `path`.
pub fn write_report(path: &Path, input: &ReportInput) -> Result<(), ReportError> {
    let html = render_html(input)?;
    write_atomic(path, html.as_bytes()).map_err(|source| ReportError::Write {
        path: path.to_path_buf(),
        source,
    })
}

/// Plain-language notices: the solver's own, plus too few poses, poor rotation spread, and per
/// answer a likely convention error or residuals beyond the noise model, each saying what to do.
/// The health checks are `verdict`'s ([`verdict::coverage_notices`],
/// [`verdict::residual_notice`]): the same the verdict, the terminal and the result file use.
pub fn notices(input: &ReportInput) -> Vec<Notice> {
    let mut out = verdict::coverage_notices(&input.pairs);
    for answer in &input.answers {
        let c = &answer.calibration;
        let label = &answer.label;
        if let Some(n) = verdict::residual_notice(c, &input.pairs, &input.noise) {
            out.push(n.prefixed(label));
        }
        out.extend(c.warnings.iter().map(|w| w.prefixed(label)));
    }
    out
}

/// HTML text escaping.
pub fn escape(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for ch in text.chars() {
        match ch {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            c => out.push(c),
        }
    }
    out
}

/// Standard base64 (RFC 4648, with padding) for inline images.
pub fn base64(bytes: &[u8]) -> String {
    const ALPHABET: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::with_capacity(bytes.len().div_ceil(3) * 4);
    for chunk in bytes.chunks(3) {
        let b = [
            chunk[0],
            chunk.get(1).copied().unwrap_or(0),
            chunk.get(2).copied().unwrap_or(0),
        ];
        let v = (u32::from(b[0]) << 16) | (u32::from(b[1]) << 8) | u32::from(b[2]);
        for i in 0..4 {
            if i <= chunk.len() {
                out.push(ALPHABET[((v >> (18 - 6 * i)) & 63) as usize] as char);
            } else {
                out.push('=');
            }
        }
    }
    out
}

const CSS: &str =
    "body{font-family:sans-serif;max-width:1200px;margin:1em auto;padding:0 1em;color:#222}\
h2{border-bottom:1px solid #ccc;margin-top:1.6em}.answers{display:flex;flex-wrap:wrap;gap:1.5em}\
.answer{flex:1 1 420px}table.forms{border-collapse:collapse;font-size:90%}\
table.forms th{text-align:left;padding:2px 8px;vertical-align:top;font-weight:normal;color:#555}\
table.forms code{white-space:pre}.warning,.error{color:#a40000}\
section.verdict{border:2px solid #888;padding:0 1em;margin-top:1em}section.verdict.good{border-color:#060}\
section.verdict.check{border-color:#b60}section.verdict.redo{border-color:#a40000}\
section.verdict h2{border:none}li.check{color:#b60}li.redo{color:#a40000}.info{color:#333}.ok{color:#060}\
figure.plot{margin:0.5em 0}figure.plot svg{max-width:100%;height:auto}\
.thumbs{display:flex;flex-wrap:wrap;gap:8px}figure.thumb{margin:0;font-size:80%}\
figure.thumb img{width:240px;display:block}";

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn base64_matches_rfc4648_vectors() {
        for (input, expected) in [
            ("", ""),
            ("f", "Zg=="),
            ("fo", "Zm8="),
            ("foo", "Zm9v"),
            ("foob", "Zm9vYg=="),
            ("fooba", "Zm9vYmE="),
            ("foobar", "Zm9vYmFy"),
        ] {
            assert_eq!(base64(input.as_bytes()), expected, "input {input:?}");
        }
    }

    #[test]
    fn escape_neutralises_markup() {
        assert_eq!(
            escape("<a href=\"x\">&'"),
            "&lt;a href=&quot;x&quot;&gt;&amp;&#39;"
        );
    }
}
