//! The calibration report: one self-contained HTML page (inline SVG plots, inline frames, one
//! small inline script, nothing loaded from elsewhere) that answers "is this calibration any
//! good, and how do I use it?".
//!
//! Owns the report's input ([`ReportInput`], with a list of [`ReportAnswer`]s shown side by side,
//! e.g. the pose-space and a reprojection-space answer) and the page layout, in the order a
//! person reads it: the verdict card (GOOD / CHECK / REDO, made by `verdict`, the same as the
//! terminal and `result.yaml` show); "use it" (the primary answer as `handeye export` writes it
//! for ROS 2, URDF, UR and OpenCV, with copy buttons); the evidence (the solvers' own notices —
//! the health checks are the verdict's, on its card —, residual plots, a per-pose table that sorts on a click, frames that
//! open full size, the cell sketch, rotation axes); the details (every number of every answer,
//! solver convergence). The verdict card, the "use it" snippets, the per-answer transforms and
//! their forms ([`export_forms`]) are written by `sections.rs`; the plots are drawn with
//! `plotters`' SVG backend in [`plots`] (axes named, legends in a column beside the data), and
//! [`session`] gathers the input from a session folder (frames, detected corners). Frames follow the crate
//! convention (`T_a_b` maps points of frame `b` into frame `a`); numbers are shown in metres /
//! radians where a file holds them and in mm / degrees where a person reads them. Depends on
//! `solve`, `verdict`, `formats`, `vision`, `config`, `dataset`, `session` (for the folder
//! layout) and the ground floor (`geometry`, `setup`, `camera_model`, `notice`, `atomic_file`);
//! nothing depends on it but the CLI.
//!
//! Every section and every plot carries a stable `id` / `data-kind`, and every number that
//! `result.yaml` also holds carries a `data-key`, so tests can check the page's structure and
//! values without parsing prose.

pub mod cameras;
mod corners;
pub mod plots;
mod sections;
pub mod session;

use std::fmt::Write;
use std::path::{Path, PathBuf};

use handeye_core::atomic_file::write_atomic_with;
use handeye_core::notice::Notice;
use handeye_core::setup::{PosePair, Setup};
use handeye_solve::verdict::Verdict;
use handeye_solve::Calibration;

use base64::prelude::{Engine as _, BASE64_STANDARD};
pub use corners::{CornerResidual, CORNER_PLOT_KINDS};
pub use sections::export_forms;
use sections::{arm_section, figure, transforms_section, use_answer_section, verdict_card};

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
    /// For one camera's part of a cell's joint answer: what the joint solve gives of it (the
    /// calibration holds its transforms and residuals, but the solve's run and covariance are
    /// the cell's); `None` for an answer of its own.
    pub joint: Option<JointFigures>,
}

/// What a cell's joint solve gives of one camera's answer beyond its transforms and residuals.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JointFigures {
    /// The 1-sigma of its mount and of its board, as the result holds them.
    pub sigmas: [Option<handeye_solve::PoseSigma>; 2],
}

/// The frames a page shows, each with its detected corners and the board reprojected at the
/// `T_camera_target` the answer predicts there: small in the page's grid, full size in an
/// overlay on a click. Read, drawn and encoded while the page is written, a few at a time, so
/// a page of hundreds of frames is never held in memory whole.
#[derive(Debug, Clone)]
pub struct PageFrames {
    /// The board the frames show.
    pub board: handeye_vision::Target,
    /// The lens they were taken through.
    pub camera: handeye_core::camera_model::CameraModel,
    /// The frames, in the order shown.
    pub frames: Vec<PageFrame>,
    /// The samples whose frame the page leaves out, increasing (a long recording's:
    /// `annotate::MAX_FRAMES_SHOWN`); their frames are in the session folder.
    pub not_drawn: Vec<usize>,
}

/// One frame of [`PageFrames`].
#[derive(Debug, Clone)]
pub struct PageFrame {
    /// Sample index (into [`ReportInput::pairs`]).
    pub sample: usize,
    /// Caption (sample id and plan index).
    pub caption: String,
    /// The frame file.
    pub path: PathBuf,
    /// The board pose the answer predicts at this sample.
    pub camera_from_target: handeye_core::geometry::Pose,
    /// The detected corners, px.
    pub corners_px: Vec<nalgebra::Point2<f64>>,
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
    /// The answers, first one primary (the frames reproject with it).
    pub answers: Vec<ReportAnswer>,
    /// The frames, shown small and full size on a click (`None` for a plain dataset, or
    /// without the board and lens to draw them).
    pub frames: Option<PageFrames>,
    /// Held-out prediction errors, when computed.
    pub holdout: Option<HoldoutSummary>,
    /// The verdict on the primary answer as the session's solve judged it (the one
    /// `result.yaml` holds: the page never judges again); `None`: none was recorded, and the
    /// page shows no verdict card.
    pub verdict: Option<Verdict>,
    /// The run's arm time (spent, and saved against the full plan), when the session kept it.
    pub arm_time: Option<handeye_session::cell::run::ArmTime>,
    /// The config's nominal transforms (what the person measured or expected), shown beside the
    /// answer in plain words; `None` without a config.
    pub nominal: Option<handeye_core::setup::CellTransforms>,
    /// Every detected corner of the samples with its residual at the primary answer (empty
    /// without frames: a plain dataset, or no board or intrinsics to reproject with).
    pub corners: Vec<CornerResidual>,
    /// The frames' size, px (width, height), when known.
    pub image_size: Option<(u32, u32)>,
    /// The frames the robot poses were read in: "use it" names the base and flange by them, as
    /// `handeye export` does by default.
    pub robot_frames: handeye_core::setup::RobotFrames,
    /// The arm's own model the solve estimated beside the transforms, when it did.
    pub arm: Option<handeye_records::result::KinematicsYaml>,
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
    /// The session has no answer to show: its `result.yaml` is missing or unusable.
    #[error("{}: no usable result: {why}", path.display())]
    NotSolved {
        /// The session's result file.
        path: PathBuf,
        /// Why, and what to do.
        why: String,
    },
    /// A session file could not be read.
    #[error("reading the session for the report failed")]
    Session(#[source] Box<handeye_records::SessionError>),
    /// A frame could not be read or encoded.
    #[error("{}: cannot draw the frame for the report: {message}", path.display())]
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

/// The section ids, in page order: the verdict card; the answer in plain words beside the
/// nominal; "use it" (export snippets); the evidence
/// (findings, residual plots, corner residuals and coverage, per-pose table, frames, cell sketch, rotation axes); the details
/// (full numbers of every answer, solver convergence).
pub const SECTIONS: [&str; 12] = [
    "verdict",
    "plain",
    "use",
    "warnings",
    "residuals",
    "corners",
    "per-pose",
    "frames",
    "poses-3d",
    "rotation-axes",
    "transforms",
    "convergence",
];

/// Renders the page.
pub fn render_html(input: &ReportInput) -> Result<String, ReportError> {
    let mut page = Vec::new();
    // Writing into memory cannot fail: the path only names the page in an error that never comes.
    render_to(input, &mut page, Path::new("the page in memory"))?;
    Ok(String::from_utf8(page).expect("the page is UTF-8"))
}

/// Which part of a page a camera's evidence is: the only camera's (plain ids: `residuals`,
/// `frames`, a frame `frame-<sample>`), or one camera's of several (ids suffixed with its name:
/// `residuals-wrist`, `frames-wrist`, `frame-wrist-<sample>`; headings name it).
#[derive(Debug, Clone, Copy)]
pub(crate) enum Part<'a> {
    /// The page's only camera.
    Only,
    /// The camera of that name, one of several.
    Camera(&'a str),
}

impl Part<'_> {
    /// A section's id in this part.
    fn id(self, section: &str) -> String {
        match self {
            Part::Only => section.to_string(),
            Part::Camera(name) => format!("{section}-{}", escape(name)),
        }
    }

    /// The anchor prefix of this part's frames (a frame's anchor: the prefix, its sample).
    fn frame_prefix(self) -> String {
        self.id("frame") + "-"
    }

    /// The heading of one of the part's halves (`Evidence`, `Details`).
    fn heading(self, half: &str) -> String {
        match self {
            Part::Only => half.to_string(),
            Part::Camera(name) => format!("Camera {name}: {}", half.to_lowercase()),
        }
    }
}

/// The start of every page: its title, the style, the header with `meta` (HTML) under it.
pub(crate) fn page_head(html: &mut String, title: &str, meta: &str) {
    let _ = write!(
        html,
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><meta name=\"viewport\" content=\"width=device-width, initial-scale=1\"><title>{}</title>\n<style>{}</style></head><body>\n<header><h1>Calibration report</h1>\n<p class=\"meta\"><span class=\"title\">{}</span> · {meta}</p></header>\n<main>\n",
        escape(title),
        CSS,
        escape(title),
    );
}

/// The end of every page: the full-size frame overlay and the script.
pub(crate) fn page_tail(html: &mut String) {
    html.push_str("</main>\n");
    html.push_str(OVERLAY);
    let _ = write!(html, "<script>{SCRIPT}</script>\n</body></html>\n");
}

/// Writes the page to `out` (the file `path`, for errors): the text before the frames, the
/// frames as they are drawn, then the rest.
fn render_to(
    input: &ReportInput,
    out: &mut dyn std::io::Write,
    path: &Path,
) -> Result<(), ReportError> {
    if input.answers.is_empty() || input.pairs.is_empty() {
        return Err(ReportError::Empty);
    }
    let mut html = String::new();
    page_head(
        &mut html,
        &input.title,
        &format!(
            "setup <b>{}</b> · {} samples · answers: {}",
            input.setup,
            input.pairs.len(),
            input
                .answers
                .iter()
                .map(|a| escape(&a.label))
                .collect::<Vec<_>>()
                .join(", ")
        ),
    );

    // 1. The verdict first: GOOD / CHECK / REDO, the reason that decided it and what to do next.
    let verdict = input.verdict.as_ref();
    if let Some(v) = verdict {
        verdict_card(&mut html, v);
    }

    // In plain words: where the answer puts the camera and the board, beside the nominal.
    sections::plain_summary(
        &mut html,
        &input.answers[0],
        input.nominal.as_ref(),
        "plain",
    );

    // 2. Use it: the primary answer in the forms other tools read, with copy buttons.
    use_answer_section(&mut html, &input.answers[0], verdict, &input.robot_frames);

    // 3. The evidence and 4. the details.
    let mut page = PageOut::new(html, out, path);
    camera_part(&mut page, input, Part::Only)?;
    page_tail(&mut page.html);
    page.flush()
}

/// One camera's verdict in a cell of several (the cell's is on the card): its level and reason,
/// and its cell model (which of its files its corners contradict, issue #38).
pub(crate) fn camera_verdict(html: &mut String, verdict: &Verdict) {
    let _ = writeln!(
        html,
        "<p class=\"camera-verdict\">Verdict: <b class=\"{level}\">{level}</b> — {}</p>",
        escape(&verdict.reason),
        level = verdict.level.word()
    );
    if let Some(model) = &verdict.figures.cell_model {
        sections::cell_model_table(html, model);
    }
}

/// A camera's evidence and details, as `part` of a page: the solvers' findings, the residual
/// plots, the arm's model, the corner residuals, the per-pose table, the frames, the cell sketch
/// and the rotation axes; then every number of every answer and the solver's convergence.
pub(crate) fn camera_part(
    page: &mut PageOut<'_>,
    input: &ReportInput,
    part: Part<'_>,
) -> Result<(), ReportError> {
    let html = &mut page.html;
    let _ = writeln!(
        html,
        "<h2 class=\"part\">{}</h2>",
        escape(&part.heading("Evidence"))
    );
    // A one-camera page shows its verdict (with its cell model) on the card and says it in plain
    // words above "use it"; each camera of several here, under the cell's card.
    if let Part::Camera(_) = part {
        if let Some(v) = &input.verdict {
            camera_verdict(html, v);
        }
        sections::plain_summary(
            html,
            &input.answers[0],
            input.nominal.as_ref(),
            &part.id("plain"),
        );
    }
    // Information (how the answer was made) is listed apart, never in the warnings list.
    let notices = notices(input);
    let (attention, info): (Vec<&Notice>, Vec<&Notice>) =
        notices.iter().partition(|n| n.needs_attention());
    let _ = writeln!(
        html,
        "<section id=\"{}\"><h3>Findings</h3>",
        part.id("warnings")
    );
    if attention.is_empty() {
        html.push_str(if input.answers[0].joint.is_some() {
            // Not "no warnings": the joint solve's findings are the cell's, not the camera's.
            "<p>The joint solve keeps no findings per camera: its checks of this camera are its verdict above.</p>\n"
        } else {
            "<p class=\"ok\">No warnings from the solver (the checks on the poses and residuals are on the verdict card).</p>\n"
        });
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
        html.push_str("<h4>Notes</h4>\n<ul>\n");
        for n in &info {
            let _ = writeln!(html, "<li class=\"info\">{}</li>", escape(&n.message));
        }
        html.push_str("</ul>\n");
    }
    html.push_str("</section>\n");

    let _ = writeln!(html, "<section id=\"{}\"><h3>Per-pose residuals</h3>\n<p>Measured against predicted T_camera_target for every sample. Red bars are flagged outliers; a grey stub marks a sample dropped from the final solve.</p>", part.id("residuals"));
    for which in [
        plots::ResidualKind::Rotation,
        plots::ResidualKind::Translation,
        plots::ResidualKind::Reprojection,
    ] {
        figure(html, which.kind(), &plots::residual_bars(input, which)?);
    }
    html.push_str("</section>\n");
    if let Some(arm) = &input.arm {
        arm_section(html, arm);
    }
    corners::corners_section(html, input, &part.id("corners"))?;

    per_pose_table(html, input, part);
    page.frames_section(
        "Frames",
        &part.id("frames"),
        &part.frame_prefix(),
        &input.answers[0].label,
        input.frames.as_ref(),
    )?;
    let html = &mut page.html;

    let _ = writeln!(html, "<section id=\"{}\"><h3>Cell sketch</h3>\n<p>Where the primary answer puts the robot base, the board and the camera at every sample (base frame, metres; axis names on the frame). Each triad shows a frame's axes: x red, y green, z blue.</p>", part.id("poses-3d"));
    figure(html, "poses-3d", &plots::poses_3d(input)?);
    html.push_str("</section>\n");

    // The spread the verdict measured (the page measures nothing itself).
    let spread = input
        .verdict
        .as_ref()
        .and_then(|v| v.figures.rotation_off_axis_deg)
        .map(|deg| format!(" Largest rotation off the dominant axis: {deg:.1}°."))
        .unwrap_or_default();
    let _ = write!(
        html,
        "<section id=\"{}\"><h3>Relative rotation axes</h3>\n<p>Axes of the relative flange rotations between every two samples (base frame; an axis and its opposite are the same, so all are drawn with z ≥ 0), on the unit sphere seen from +z and from +x; marker size grows with the rotation angle. The solver needs axes spread over the sphere, not bunched about one direction.{spread}</p>\n",
        part.id("rotation-axes")
    );
    figure(html, "rotation-axes", &plots::rotation_axes(&input.pairs)?);
    html.push_str("</section>\n");

    // The details: every number.
    let _ = writeln!(
        html,
        "<h2 class=\"part\">{}</h2>\n<section id=\"{}\"><h3>Transforms (full numbers)</h3>\n<div class=\"answers\">",
        escape(&part.heading("Details")),
        part.id("transforms")
    );
    for (k, answer) in input.answers.iter().enumerate() {
        transforms_section(html, k, answer);
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
    if let Some(a) = input.arm_time.as_ref().filter(|a| !a.measured()) {
        let _ = writeln!(
            html,
            "<p class=\"armtime\">{}.</p>",
            escape(&a.to_string().replacen("arm time", "Arm time", 1))
        );
    } else if let Some(a) = &input.arm_time {
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

    let _ = writeln!(
        html,
        "<section id=\"{}\"><h3>Solver convergence</h3>",
        part.id("convergence")
    );
    let solver = &input.answers[0].calibration.solver;
    if matches!(part, Part::Camera(_)) && solver.trace.is_empty() {
        // The joint solve of several cameras keeps no trace per camera.
        let _ = writeln!(
            html,
            "<p>The {} keeps no trace of its steps for one camera.</p>",
            escape(&input.answers[0].label)
        );
    } else {
        html.push_str("<p>Update size per step of each phase of the iterative method (rotation rad, translation m) and the refinement cost per evaluation, log scale.</p>\n");
        figure(html, "convergence", &plots::convergence(input)?);
    }
    html.push_str("</section>\n");
    Ok(())
}

/// Status of a sample in the primary answer: `dropped`, `outlier` or `ok`.
fn sample_status(calibration: &Calibration, sample: usize) -> &'static str {
    if calibration.dropped.contains(&sample) {
        "dropped"
    } else if calibration.outliers.contains(&sample) {
        "outlier"
    } else {
        "ok"
    }
}

/// The per-pose table of the primary answer, worst translation residual first; every column
/// sorts on a click (inline script), numbers by value.
fn per_pose_table(html: &mut String, input: &ReportInput, part: Part<'_>) {
    let primary = &input.answers[0];
    let c = &primary.calibration;
    let value = |v: Option<&f64>| v.copied().filter(|v| v.is_finite());
    let mut order: Vec<usize> = (0..input.pairs.len()).collect();
    order.sort_by(|&a, &b| {
        let key = |i: usize| value(c.residuals.translation_mm.get(i)).unwrap_or(f64::NEG_INFINITY);
        key(b).total_cmp(&key(a))
    });
    let _ = writeln!(
        html,
        "<section id=\"{}\"><h3>Per pose</h3>\n<p>Residuals of <b>{}</b> per sample, worst translation first. Click a column heading to sort by it (again to reverse); click <i>frame</i> to see the frame full size.</p>\n<div class=\"table-wrap\"><table class=\"sortable\" id=\"{}\">\n<thead><tr><th data-type=\"number\" aria-sort=\"none\">sample</th><th data-type=\"text\" aria-sort=\"none\">id</th><th data-type=\"text\" aria-sort=\"none\">status</th><th data-type=\"number\" aria-sort=\"none\">rotation (°)</th><th data-type=\"number\" aria-sort=\"descending\">translation (mm)</th><th data-type=\"number\" aria-sort=\"none\">normalised (σ)</th><th data-type=\"number\" aria-sort=\"none\">reprojection (px)</th><th>frame</th></tr></thead>\n<tbody>",
        part.id("per-pose"),
        escape(&primary.label),
        part.id("pose-table")
    );
    let prefix = part.frame_prefix();
    let cell = |v: Option<f64>, decimals: usize| match v {
        Some(v) => format!("<td data-value=\"{v}\">{v:.decimals$}</td>"),
        None => "<td data-value=\"\">–</td>".to_string(),
    };
    for i in order {
        let status = sample_status(c, i);
        let frames = input.frames.as_ref();
        let frame = if frames.is_some_and(|f| f.frames.iter().any(|t| t.sample == i)) {
            format!(
                "<a href=\"#{prefix}{i}\" class=\"open-frame\" data-frame=\"{prefix}{i}\">frame</a>"
            )
        } else if frames.is_some_and(|f| f.not_drawn.binary_search(&i).is_ok()) {
            "not drawn".to_string()
        } else {
            "–".to_string()
        };
        let _ = writeln!(
            html,
            "<tr class=\"{status}\" data-sample=\"{i}\"><td data-value=\"{i}\">{i}</td><td>{}</td><td>{status}</td>{}{}{}{}<td>{frame}</td></tr>",
            escape(input.pairs[i].id.as_deref().unwrap_or("–")),
            cell(value(c.residuals.rotation_deg.get(i)), 4),
            cell(value(c.residuals.translation_mm.get(i)), 3),
            cell(value(c.residuals.normalised.get(i)), 2),
            cell(primary.reprojection_px.get(i).copied().flatten().filter(|v| v.is_finite()), 3),
        );
    }
    html.push_str("</tbody></table></div>\n</section>\n");
}

/// A page being written: the text not yet written (`html`) and where it goes (`out`, the file
/// `path`).
pub(crate) struct PageOut<'o> {
    /// Text not yet written.
    pub(crate) html: String,
    out: &'o mut dyn std::io::Write,
    path: &'o Path,
}

impl<'o> PageOut<'o> {
    /// A page written to `out` (the file `path`), with `html` to come first.
    pub(crate) fn new(html: String, out: &'o mut dyn std::io::Write, path: &'o Path) -> Self {
        PageOut { html, out, path }
    }

    /// Writes the text so far.
    pub(crate) fn flush(&mut self) -> Result<(), ReportError> {
        self.out
            .write_all(self.html.as_bytes())
            .map_err(|source| ReportError::Write {
                path: self.path.to_path_buf(),
                source,
            })?;
        self.html.clear();
        Ok(())
    }

    /// The frames of one camera (`id` the section's, `prefix` its frames' anchors: `frame-` on
    /// a one-camera page, `frame-<camera>-` for each of several), annotated with the board
    /// predicted by `answer`, small in a grid; a click shows one full size in an overlay. Each
    /// frame is shown (`session::shown_frame`: its preview, the marks over it as SVG) and
    /// written as it comes, a few at a time on every core.
    pub(crate) fn frames_section(
        &mut self,
        heading: &str,
        id: &str,
        prefix: &str,
        answer: &str,
        frames: Option<&PageFrames>,
    ) -> Result<(), ReportError> {
        let _ = writeln!(
            self.html,
            "<section id=\"{id}\"><h3>{}</h3>",
            escape(heading)
        );
        match frames.filter(|f| !f.frames.is_empty()) {
            None => self
                .html
                .push_str("<p>No frames recorded with these samples.</p>\n"),
            Some(frames) => {
                let _ = writeln!(
                    self.html,
                    "<p>Detected corners (green crosses) and the board reprojected at the T_camera_target predicted by <b>{}</b> (magenta outlines). Click a frame to see it full size.</p>",
                    escape(answer)
                );
                if !frames.not_drawn.is_empty() {
                    let _ = writeln!(
                        self.html,
                        "<p>The page draws {} of the {} frames: the {} whose board lies farthest from where <b>{}</b> predicts it, and the others evenly through the session. Every frame is in the session folder.</p>",
                        frames.frames.len(),
                        frames.frames.len() + frames.not_drawn.len(),
                        frames.frames.len() / 2,
                        escape(answer)
                    );
                }
                self.html.push_str("<div class=\"thumbs\">\n");
                session::draw_frames(frames, |frame, shown| {
                    let _ = write!(
                        self.html,
                        "<figure class=\"thumb\" id=\"{prefix}{}\">",
                        frame.sample
                    );
                    frame_svg(&mut self.html, &escape(&frame.caption), &shown);
                    let _ = writeln!(
                        self.html,
                        "<figcaption>{}</figcaption></figure>",
                        escape(&frame.caption)
                    );
                    self.flush()
                })?;
                self.html.push_str("</div>\n");
            }
        }
        self.html.push_str("</section>\n");
        Ok(())
    }
}

/// A frame on the page: its preview (inline JPEG) under its marks, in the shown frame's pixels
/// (pixel centres at integers): the board where the answer puts it in magenta, the detected
/// corners as green crosses. Drawn by the browser, the marks stay sharp at any size and the
/// frame is coded once, grey, where the run decoded it.
fn frame_svg(html: &mut String, label: &str, shown: &session::ShownFrame) {
    let (width, height) = shown.marks.size;
    let _ = write!(
        html,
        "<svg class=\"frame\" xmlns=\"http://www.w3.org/2000/svg\" width=\"{width}\" height=\"{height}\" viewBox=\"-0.5 -0.5 {width} {height}\" role=\"img\" aria-label=\"{label}\"><image x=\"-0.5\" y=\"-0.5\" width=\"{width}\" height=\"{height}\" href=\"data:image/jpeg;base64,{}\"/><path class=\"board\" d=\"",
        BASE64_STANDARD.encode(&shown.preview.jpeg)
    );
    for [a, b] in &shown.marks.outlines {
        let _ = write!(html, "M{:.1} {:.1}L{:.1} {:.1}", a.x, a.y, b.x, b.y);
    }
    let (board_arm, detected_arm) = shown.marks.cross_arms();
    let cross = |html: &mut String, c: &nalgebra::Point2<f64>, arm: f64| {
        let _ = write!(
            html,
            "M{:.1} {:.1}h{:.0}M{:.1} {:.1}v{:.0}",
            c.x - arm,
            c.y,
            2.0 * arm,
            c.x,
            c.y - arm,
            2.0 * arm
        );
    };
    for c in &shown.marks.board_corners {
        cross(html, c, board_arm);
    }
    html.push_str("\"/><path class=\"corners\" d=\"");
    for c in &shown.marks.detected {
        cross(html, c, detected_arm);
    }
    html.push_str("\"/></svg>");
}

/// Renders the page and writes it atomically to `path`, the frames as they are drawn.
pub fn write_report(path: &Path, input: &ReportInput) -> Result<(), ReportError> {
    write_page(path, |out| render_to(input, out, path))
}

/// Writes a page atomically to `path` through `render`: a page that fails leaves `path` as it
/// was.
pub(crate) fn write_page(
    path: &Path,
    render: impl FnOnce(&mut dyn std::io::Write) -> Result<(), ReportError>,
) -> Result<(), ReportError> {
    write_atomic_with(path, render).map_err(|source| ReportError::Write {
        path: path.to_path_buf(),
        source,
    })?
}

/// What each answer's solver said about how it was made (prefixed with the answer's label).
/// The checks on the evidence — too few poses, poor rotation spread, residuals beyond the noise
/// model — are the verdict's, judged once by the run and shown on its card: the page never
/// judges again.
pub fn notices(input: &ReportInput) -> Vec<Notice> {
    input
        .answers
        .iter()
        .flat_map(|answer| {
            let label = &answer.label;
            answer
                .calibration
                .notices
                .iter()
                .map(move |n| n.prefixed(label))
        })
        .collect()
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

const CSS: &str = "\
*{box-sizing:border-box}\
body{font-family:system-ui,-apple-system,'Segoe UI',Roboto,sans-serif;max-width:1200px;margin:0 auto;padding:0.5em 1.2em 3em;color:#1d1d1f;line-height:1.45}\
header h1{font-size:1.5em;margin:0.4em 0 0}.meta{color:#555;margin:0.2em 0 0.8em;overflow-wrap:anywhere}\
h2.part{font-size:1.35em;border-bottom:2px solid #ccc;margin-top:1.8em;padding-bottom:0.15em}\
h3{font-size:1.12em;margin:1.3em 0 0.4em}\
section.verdict{border:2px solid #888;border-radius:8px;padding:0.2em 1.2em 0.6em;margin-top:0.5em;background:#f6f6f6}\
section.verdict.good{border-color:#1e7e34;background:#e8f5ec}\
section.verdict.check{border-color:#b35c00;background:#fff3e0}\
section.verdict.redo{border-color:#b00020;background:#fdecee}\
section.verdict h2{font-size:1.6em;margin:0.4em 0 0.2em;border:none}\
.verdict .reason{font-size:1.1em;margin:0.2em 0}.verdict .next{font-weight:600;margin:0.3em 0}\
.verdict ul.figures{margin:0.4em 0;padding-left:1.2em;color:#333}\
.warning,.error,li.redo{color:#a40000}li.check{color:#8a4600}.info{color:#333}.ok{color:#1e7e34}\
.frames-note{color:#444}.caution{font-weight:600;color:#a40000}\
.snippets{display:grid;grid-template-columns:repeat(auto-fit,minmax(520px,1fr));gap:0.8em}\
.snippet{border:1px solid #ccd;border-radius:6px;background:#fafbfc;min-width:0}\
.snippet-head{display:flex;justify-content:space-between;align-items:center;padding:0.35em 0.7em;border-bottom:1px solid #ccd}\
.snippet-head h4{margin:0;font-size:0.98em}\
button.copy{font:inherit;font-size:0.9em;padding:0.15em 0.8em;border:1px solid #889;border-radius:4px;background:#fff;cursor:pointer}\
button.copy:hover{background:#eef}\
.snippet pre{margin:0;padding:0.5em 0.7em;overflow:auto;max-height:15em;font-size:0.8em}\
.answers{display:flex;flex-wrap:wrap;gap:1.5em}.answer{flex:1 1 420px;min-width:0}\
table.forms{border-collapse:collapse;font-size:90%}\
table.forms th{text-align:left;padding:2px 8px;vertical-align:top;font-weight:normal;color:#555}\
table.forms code{white-space:pre}.answer .forms-wrap{overflow-x:auto}\
figure.plot{margin:0.5em 0}figure.plot svg{max-width:100%;height:auto;display:block}\
.table-wrap{max-height:28em;overflow:auto;border:1px solid #ddd}\
table.sortable{border-collapse:collapse;width:100%;font-size:0.92em}\
table.sortable th{position:sticky;top:0;background:#eef0f3;text-align:right;padding:4px 8px;white-space:nowrap}\
table.sortable th[data-type]{cursor:pointer}table.sortable th[data-type]:hover{background:#dde2ea}\
table.sortable th[aria-sort=ascending]::after{content:' \\25B2'}table.sortable th[aria-sort=descending]::after{content:' \\25BC'}\
table.sortable td{text-align:right;padding:2px 8px;border-top:1px solid #eee;font-variant-numeric:tabular-nums}\
table.sortable tr.ok td{color:inherit}table.sortable tr.outlier td{color:#a40000}table.sortable tr.dropped td{color:#888}\
table.cell{border-collapse:collapse;font-size:0.92em;margin:0.4em 0}table.cell td,table.cell th{border:1px solid #ccc;padding:4px 8px;text-align:left}\
td.GOOD,b.GOOD{color:#1e7e34}td.CHECK,b.CHECK{color:#8a4600}td.REDO,b.REDO{color:#a40000}\
.thumbs{display:flex;flex-wrap:wrap;gap:8px}figure.thumb{margin:0;font-size:80%;width:240px}\
figure.thumb svg{width:240px;height:auto;display:block;cursor:zoom-in;border:1px solid #ccc}\
svg.frame path{fill:none;stroke-width:1.5;vector-effect:non-scaling-stroke}figure.thumb svg.frame path{stroke-width:0.75}svg.frame .board{stroke:#f0f}svg.frame .corners{stroke:#00e600}\
#overlay{position:fixed;inset:0;background:rgba(0,0,0,0.85);display:flex;flex-direction:column;align-items:center;justify-content:center;z-index:10;cursor:zoom-out}\
#overlay[hidden]{display:none}#overlay svg{width:auto;height:auto;max-width:96vw;max-height:88vh;background:#fff}\
#overlay p{color:#fff;margin:0.4em}\
@media (max-width:700px){.snippets{grid-template-columns:1fr}}";

/// The full-size frame overlay (filled and shown by [`SCRIPT`]).
const OVERLAY: &str = "<div id=\"overlay\" hidden role=\"dialog\" aria-label=\"frame, full size\"><div></div><p></p></div>\n";

/// The page's only script: copy buttons, table sorting, the frame overlay. No network, no
/// storage; the page reads fine without it.
const SCRIPT: &str = r#"
(function () {
  function copyText(text, done) {
    if (navigator.clipboard && window.isSecureContext) {
      navigator.clipboard.writeText(text).then(done, function () { fallback(text, done); });
    } else {
      fallback(text, done);
    }
  }
  function fallback(text, done) {
    var area = document.createElement('textarea');
    area.value = text;
    document.body.appendChild(area);
    area.select();
    try { document.execCommand('copy'); done(); } catch (e) { /* nothing to copy to */ }
    area.remove();
  }
  document.querySelectorAll('button.copy').forEach(function (button) {
    button.addEventListener('click', function () {
      var source = document.getElementById(button.dataset.target);
      copyText(source.textContent, function () {
        button.textContent = 'Copied';
        setTimeout(function () { button.textContent = 'Copy'; }, 1500);
      });
    });
  });
  document.querySelectorAll('table.sortable').forEach(function (table) {
    var heads = table.querySelectorAll('th');
    heads.forEach(function (th, column) {
      if (!th.dataset.type) { return; }
      th.addEventListener('click', function () {
        var descending = th.getAttribute('aria-sort') !== 'descending';
        heads.forEach(function (other) { if (other.dataset.type) { other.setAttribute('aria-sort', 'none'); } });
        th.setAttribute('aria-sort', descending ? 'descending' : 'ascending');
        var body = table.tBodies[0];
        var rows = Array.prototype.slice.call(body.rows);
        var key = function (row) {
          var cell = row.cells[column];
          if (th.dataset.type === 'number') {
            var v = parseFloat(cell.dataset.value);
            return isNaN(v) ? null : v;
          }
          return cell.textContent;
        };
        rows.sort(function (a, b) {
          var x = key(a), y = key(b);
          if (x === null) { return y === null ? 0 : 1; }
          if (y === null) { return -1; }
          var order = x < y ? -1 : (x > y ? 1 : 0);
          return descending ? -order : order;
        });
        rows.forEach(function (row) { body.appendChild(row); });
      });
    });
  });
  var overlay = document.getElementById('overlay');
  var big = overlay.querySelector('div');
  var caption = overlay.querySelector('p');
  function show(figure) {
    big.replaceChildren(figure.querySelector('svg.frame').cloneNode(true));
    caption.textContent = figure.querySelector('figcaption').textContent;
    overlay.hidden = false;
  }
  document.querySelectorAll('figure.thumb').forEach(function (figure) {
    figure.querySelector('svg.frame').addEventListener('click', function () { show(figure); });
  });
  document.querySelectorAll('a.open-frame').forEach(function (link) {
    link.addEventListener('click', function (event) {
      var figure = document.getElementById(link.dataset.frame);
      if (figure) { event.preventDefault(); show(figure); }
    });
  });
  overlay.addEventListener('click', function () { overlay.hidden = true; });
  document.addEventListener('keydown', function (event) {
    if (event.key === 'Escape') { overlay.hidden = true; }
  });
})();
"#;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn escape_neutralises_markup() {
        assert_eq!(
            escape("<a href=\"x\">&'"),
            "&lt;a href=&quot;x&quot;&gt;&amp;&#39;"
        );
    }
}
