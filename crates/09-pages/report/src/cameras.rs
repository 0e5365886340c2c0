//! The report of a cell with several cameras (`<session>/report.html` of a several-camera
//! session): the page of one camera (`super::render_to`) with N camera parts. On top, the
//! cell's verdict card, "use it" for every mount and board, the cameras (each one's mount from
//! the joint solve and from its own views alone, 1-sigma, verdict with its held-out check, cell
//! model), the boards and camera-to-camera transforms, and every camera's residual at each plan
//! pose; then, for each camera, the evidence and details a one-camera page shows
//! ([`super::camera_part`], its ids suffixed with the camera's name): its answer in plain words,
//! residuals, corner residuals, per-pose table, frames, cell sketch, rotation axes and full
//! numbers, at the joint answer. Renders `result.yaml` as written; judges nothing.

use std::fmt::Write as _;
use std::path::Path;

use handeye_core::geometry::rotvec;
use handeye_core::setup::CellTransforms;
use handeye_records::result::{CameraResult, CellResult, NamedTransform};

use super::plots::{bars, BarSeries, ResidualKind};
use super::{escape, ReportError};
use handeye_config::CellConfig;
use handeye_core::camera_model::CameraModel;
use handeye_formats::export::{ExportFormat, Exported, FrameIds};
use handeye_records::dataset::Dataset;
use handeye_records::{Evidence, SessionFolder};
use handeye_session::cell::cameras::camera_folder;
use handeye_vision::Target;

use super::session::{from_session, holdout_summary, load_optics, sample_visits, Answer, Optics};
use super::{JointFigures, PageOut, Part, ReportInput};
use handeye_solve::verdict::{Level, Verdict};

fn transform_cells(t: &NamedTransform) -> String {
    let p = t.pose.translation.vector;
    let r = rotvec(&t.pose.rotation);
    let truth = match (t.truth_error_mm, t.truth_error_deg) {
        (Some(mm), Some(deg)) => format!("{mm:.3} mm / {deg:.4}°"),
        _ => "—".into(),
    };
    format!(
        "<td><code>{}</code></td><td>[{:.5}, {:.5}, {:.5}]</td><td>[{:.5}, {:.5}, {:.5}]</td><td>{}</td><td>{}</td>",
        escape(&t.name),
        p.x,
        p.y,
        p.z,
        r.x,
        r.y,
        r.z,
        t.sigma.map_or_else(
            || "—".into(),
            |s| format!("±{:.3} mm / ±{:.4}°", s.translation_mm, s.rotation_deg)
        ),
        truth
    )
}

/// A verdict's level as the page writes it (its CSS class too); "—" where there is none.
fn level_word(verdict: Option<&Verdict>) -> &'static str {
    verdict.map_or("—", |v| v.level.word())
}

/// A verdict's reason; what a missing verdict means.
fn reason(verdict: Option<&Verdict>) -> &str {
    verdict.map_or("no verdict", |v| &v.reason)
}

/// Writes the page to `out` (the file `path`, for errors), the frames as they are drawn: the
/// cell's verdict, "use it", the cameras and the boards, the joint residuals, then each
/// camera's evidence and details as a one-camera page shows them ([`super::camera_part`]).
fn render_to(
    result: &CellResult,
    folder: &Path,
    out: &mut dyn std::io::Write,
    path: &Path,
) -> Result<(), ReportError> {
    let names: Vec<&str> = result.cameras.iter().map(|c| c.name.as_str()).collect();
    let mut html = String::new();
    super::page_head(
        &mut html,
        &folder.display().to_string(),
        &format!(
            "a cell of <b>{}</b> cameras ({}) · answer: the joint solve",
            names.len(),
            escape(&names.join(", "))
        ),
    );
    // The cell's verdict (the worst camera's, naming it) on the card of a one-camera page; each
    // camera's verdict and cell model (issue #38) open its part below.
    if let Some(verdict) = &result.verdict {
        let mut cell_verdict = verdict.clone();
        cell_verdict.figures.cell_model = None;
        super::sections::verdict_card(&mut html, &cell_verdict);
    }
    use_section(&mut html, result);
    cameras_section(&mut html, result, folder);
    residuals_section(&mut html, result)?;
    let mut page = PageOut::new(html, out, path);
    for camera in &result.cameras {
        let records = camera_records(folder, &camera.name);
        camera_section(&mut page, result, camera, records)?;
        page.flush()?;
    }
    super::page_tail(&mut page.html);
    page.flush()
}

/// The cameras: a camera that stopped delivering frames, each camera's mount (joint and alone)
/// and verdict with its held-out check, then the boards and the camera-to-camera transforms of
/// the joint solve.
fn cameras_section(html: &mut String, result: &CellResult, folder: &Path) {
    html.push_str("<section id=\"cameras\"><h2>Cameras</h2>\n");
    for f in handeye_session::cell::cameras::read_failures(folder) {
        let _ = write!(
            html,
            "<p class=\"error\">Camera <b>{}</b> stopped delivering frames at plan pose {}: {}. Its samples until then are kept and solved.</p>",
            escape(&f.camera),
            f.plan_index,
            escape(&f.error)
        );
    }
    html.push_str("<table class=\"cell\"><tr><th>camera</th><th>verdict</th><th>samples</th><th>solve</th><th>transform</th><th>translation (m)</th><th>rotation vector (rad)</th><th>1-sigma</th><th>vs simulator truth</th></tr>");
    for c in &result.cameras {
        let rows: Vec<(&str, &NamedTransform)> =
            [("joint", c.joint.as_ref()), ("alone", c.alone.as_ref())]
                .into_iter()
                .filter_map(|(k, t)| t.map(|t| (k, t)))
                .collect();
        if rows.is_empty() {
            let _ = write!(
                html,
                "<tr><td>{}</td><td class=\"{v}\">{v}</td><td>{}</td><td colspan=\"6\">{}</td></tr>",
                escape(&c.name),
                c.samples,
                escape(c.left_out.as_deref().unwrap_or(reason(c.verdict.as_ref()))),
                v = level_word(c.verdict.as_ref())
            );
        }
        for (k, t) in rows {
            let _ = write!(
                html,
                "<tr><td>{}</td><td class=\"{v}\">{v}</td><td>{}</td><td>{k}</td>{}</tr>",
                escape(&c.name),
                c.samples,
                transform_cells(t),
                v = level_word(c.verdict.as_ref())
            );
        }
    }
    html.push_str("</table><p>“alone”: the same camera solved from its own views only (the one-camera answer); “joint”: every camera and the boards solved together.</p>");
    // Each camera's verdict with the leave-one-out check of its own samples; the cell's is the
    // worst of them.
    html.push_str("<h3>Verdict per camera</h3><table class=\"cell\"><tr><th>camera</th><th>verdict</th><th>held-out error (leave-one-out, its own samples)</th><th>why</th></tr>");
    for c in &result.cameras {
        let held_out = match &c.held_out {
            Some(h) => format!(
                "{:.2} mm / {:.3}° over {} poses",
                h.translation_rms_mm, h.rotation_rms_deg, h.poses
            ),
            None => "—".into(),
        };
        let _ = write!(
            html,
            "<tr><td>{}</td><td class=\"{v}\">{v}</td><td>{held_out}</td><td>{}</td></tr>",
            escape(&c.name),
            escape(reason(c.verdict.as_ref())),
            v = level_word(c.verdict.as_ref())
        );
    }
    html.push_str("</table>");
    html.push_str("<h3>Boards and camera-to-camera transforms (joint solve)</h3><table class=\"cell\"><tr><th>transform</th><th>translation (m)</th><th>rotation vector (rad)</th><th>1-sigma</th><th>vs simulator truth</th></tr>");
    for t in result.boards.iter().chain(&result.camera_to_camera) {
        let _ = write!(html, "<tr>{}</tr>", transform_cells(t));
    }
    let _ = writeln!(
        html,
        "</table><p>Variance factor of the joint solve (χ²/dof): {}</p></section>",
        result
            .variance_factor
            .map_or_else(|| "—".into(), |f| format!("{f:.3}"))
    );
}

/// One camera's part of the page: its evidence and details at the joint answer, as a
/// one-camera page shows them (its residuals as the result holds them, its corners and frames
/// drawn with the board and lens of the config its session names); what cannot be shown, and
/// why, above it.
fn camera_section(
    page: &mut PageOut<'_>,
    result: &CellResult,
    camera: &CameraResult,
    records: Result<CameraRecords, String>,
) -> Result<(), ReportError> {
    let mut lacking = Vec::new();
    let input = match records {
        Ok(records) => camera_input(result, camera, &records, &mut lacking)?,
        Err(e) => {
            lacking.push(e);
            None
        }
    };
    if !lacking.is_empty() {
        let _ = writeln!(
            page.html,
            "<p class=\"error\">Camera {}: {}</p>",
            escape(&camera.name),
            escape(&lacking.join("; "))
        );
    }
    match input {
        Some(input) => super::camera_part(page, &input, Part::Camera(&camera.name)),
        None => {
            let _ = writeln!(
                page.html,
                "<h2 class=\"part\">Camera {}</h2>",
                escape(&camera.name)
            );
            if let Some(v) = &camera.verdict {
                super::camera_verdict(&mut page.html, v);
            }
            let _ = writeln!(
                page.html,
                "<p>No evidence shown: {}.</p>",
                escape(
                    camera
                        .left_out
                        .as_deref()
                        .unwrap_or("its samples or records do not load")
                )
            );
            Ok(())
        }
    }
}

/// Camera `camera`'s page input at the joint answer, from its folder's samples and records;
/// `None` when it is not in the joint answer. `lacking` names a file that does not load (its
/// frames are then not drawn).
fn camera_input(
    result: &CellResult,
    camera: &CameraResult,
    records: &CameraRecords,
    lacking: &mut Vec<String>,
) -> Result<Option<ReportInput>, ReportError> {
    let Some((_, mount)) = result
        .mounts()
        .into_iter()
        .find(|(name, _)| *name == camera.name)
    else {
        // Left out of the joint solve: the cameras' table and the part's line say why.
        return Ok(None);
    };
    // Each sample's plan pose, by which the result names its residuals.
    let plan_poses: Vec<Option<usize>> = sample_visits(&records.evidence)
        .iter()
        .map(|visit| visit.map(|v| v.plan_index))
        .collect();
    let Some(calibration) = camera.joint_calibration(&mount.target_mount, &plan_poses) else {
        return Ok(None);
    };
    let (optics, nominal) = camera_optics(records, &camera.name, lacking);
    let mut input = from_session(
        &records.folder,
        &records.evidence,
        vec![Answer::Joint(
            calibration,
            JointFigures {
                sigmas: [
                    camera.joint.as_ref().and_then(|t| t.sigma),
                    result.board_of(camera).and_then(|b| b.sigma),
                ],
            },
        )],
        optics
            .as_ref()
            .map(|(board, camera)| Optics { board, camera }),
    )?;
    input.nominal = nominal;
    input.robot_frames = result.robot_frames();
    input.holdout = camera.held_out.as_ref().map(|h| {
        holdout_summary(
            h,
            "its own samples, each predicted by a one-camera solve of the others",
        )
    });
    input.verdict.clone_from(&camera.verdict);
    Ok(Some(input))
}

/// Every camera's residual at each plan pose in the joint solve, rotation and translation: the
/// one-camera page's per-pose bars with a bar per camera.
fn residuals_section(html: &mut String, result: &CellResult) -> Result<(), ReportError> {
    html.push_str("<section id=\"residuals\"><h2>Per-pose residuals (joint solve)</h2><p>For every camera at every plan pose where it saw its board: the board pose it measured against the one the joint answer predicts there. A camera whose bars stand far above the others' at the same poses disagrees with them; a grey stub marks a sample its own solve dropped as an outlier (left out of the joint solve).</p>");
    let poses = result
        .cameras
        .iter()
        .flat_map(|c| c.residuals_per_pose.iter().map(|r| r.index + 1))
        .max()
        .unwrap_or(0);
    // Per camera, the samples its own robust solve dropped (a grey stub at their pose).
    let dropped: Vec<Vec<usize>> = result
        .cameras
        .iter()
        .map(|c| {
            c.residuals_per_pose
                .iter()
                .filter(|r| r.dropped)
                .map(|r| r.index)
                .collect()
        })
        .collect();
    for which in [ResidualKind::Rotation, ResidualKind::Translation] {
        let series: Vec<BarSeries<'_>> = result
            .cameras
            .iter()
            .zip(&dropped)
            .filter(|(c, _)| !c.residuals_per_pose.is_empty())
            .map(|(c, dropped)| {
                let mut values = vec![None; poses];
                for r in &c.residuals_per_pose {
                    values[r.index] = match which {
                        ResidualKind::Translation => r.translation_mm,
                        _ => r.rotation_deg,
                    };
                }
                BarSeries {
                    label: &c.name,
                    values,
                    outliers: &[],
                    dropped,
                }
            })
            .collect();
        if series.is_empty() {
            html.push_str("<p>No per-pose residuals in this result (written before they were kept): replay the session to see them.</p>");
            break;
        }
        super::sections::figure(
            html,
            which.kind(),
            &bars(which, "plan pose", "camera", &series)?,
        );
    }
    html.push_str("</section>");
    Ok(())
}

/// The forms "use it" shows for several cameras (`ur` holds one TCP: not for a cell).
const USE_FORMS: [(ExportFormat, &str); 4] = [
    (
        ExportFormat::Ros2Launch,
        "ROS 2: a launch file with one static_transform_publisher per transform",
    ),
    (ExportFormat::Urdf, "URDF: fixed joints"),
    (
        ExportFormat::Json,
        "JSON: every transform with its 4x4 matrix",
    ),
    (
        ExportFormat::Opencv,
        "OpenCV: FileStorage YAML (4x4 matrices)",
    ),
];

/// "Use it" of the cell (`sections::use_section`): every camera's mount and the boards in the
/// forms of [`USE_FORMS`], each the exact text `handeye export result.yaml --format …` writes
/// (its default frame ids, the result's robot frames).
fn use_section(html: &mut String, result: &CellResult) {
    let ids = FrameIds::of_robot(&result.robot_frames.clone().unwrap_or_default());
    // The result as result.yaml holds it (written and read back), so the page shows the very
    // text `handeye export result.yaml` prints, to the last digit.
    let read_back: Option<CellResult> = serde_yaml_ng::to_string(result)
        .ok()
        .and_then(|text| serde_yaml_ng::from_str(&text).ok());
    let exported = Exported::of(read_back.as_ref().unwrap_or(result), &ids);
    let intro = format!(
        "Every camera's mount and the boards, as <code>handeye export result.yaml --format …</code> writes them: camera <code>&lt;name&gt;</code>'s optical frame is <code>{}_&lt;name&gt;</code>, the robot base <code>{}</code>, the flange <code>{}</code>. Camera-to-camera transforms are comments (published, they would give a camera a second parent).",
        escape(&ids.camera),
        escape(&ids.base),
        escape(&ids.flange)
    );
    let redo = result
        .verdict
        .as_ref()
        .is_some_and(|v| v.level == Level::Redo);
    super::sections::use_section(
        html,
        &intro,
        redo.then_some("The cell's verdict is REDO"),
        &exported,
        &ids,
        &USE_FORMS,
    );
}

/// One camera's folder of a several-camera session, with its samples and records.
struct CameraRecords {
    folder: SessionFolder,
    evidence: Evidence,
}

/// Camera `name`'s folder under `root` with its samples and records, or why they do not load.
fn camera_records(root: &Path, name: &str) -> Result<CameraRecords, String> {
    let folder = SessionFolder::open(&camera_folder(root, name)).map_err(|e| e.to_string())?;
    let pairs = Dataset::load(&folder.samples_path())
        .map_err(|e| e.to_string())?
        .pairs;
    let visits = folder.read_visits().map_err(|e| e.to_string())?;
    Ok(CameraRecords {
        folder,
        evidence: Evidence { pairs, visits },
    })
}

/// Camera `name`'s board and lens, and its nominal mount, from the config its session was
/// recorded with; no board and lens when they do not load (`lacking` says why).
fn camera_optics(
    records: &CameraRecords,
    name: &str,
    lacking: &mut Vec<String>,
) -> (Option<(Target, CameraModel)>, Option<CellTransforms>) {
    let config = match records
        .folder
        .read_manifest()
        .map_err(|e| e.to_string())
        .and_then(|m| CellConfig::load(&m.config).map_err(|e| e.to_string()))
    {
        Ok(config) => config,
        Err(e) => {
            lacking.push(format!("{e}; its frames are not drawn"));
            return (None, None);
        }
    };
    let camera = config.cameras.iter().find(|c| c.name == name);
    if camera.is_none() {
        lacking.push(format!(
            "{} has no camera `{name}`; its frames are not drawn",
            config.file.display()
        ));
    }
    (
        load_optics(&records.folder, camera, lacking),
        camera.map(|c| c.nominal),
    )
}

/// Writes the page of `result`, the answer of the session in `folder`, to `path`.
pub fn write_cameras_report(
    result: &CellResult,
    folder: &Path,
    path: &Path,
) -> Result<(), ReportError> {
    super::write_page(path, |out| render_to(result, folder, out, path))
}
