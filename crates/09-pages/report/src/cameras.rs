//! The HTML report of a cell with several cameras (`<session>/report.html` of a several-camera
//! session): the cell's verdict card, one row per camera (its mount from the joint solve and
//! from its own views alone, 1-sigma, samples, residuals, verdict), the boards, the
//! camera-to-camera transforms, and each camera's annotated frames. Renders `result.yaml` as
//! written; judges nothing. Self-contained HTML. The parts a one-camera page also has are that
//! page's own (`sections::verdict_card`, `sections::use_section`, `PageOut::frames_section`
//! with `session::page_frames`): this module adds only what several cameras have.

use std::fmt::Write as _;
use std::path::Path;

use handeye_core::geometry::rotvec;
use handeye_records::result::{CellResult, NamedTransform};

use super::plots::{bars, rotation_axes, BarSeries, ResidualKind};
use super::{escape, ReportError};
use handeye_config::CellConfig;
use handeye_core::camera_model::CameraModel;
use handeye_formats::export::{ExportFormat, Exported, FrameIds};
use handeye_records::dataset::Dataset;
use handeye_records::{Evidence, SessionFolder};
use handeye_session::cell::cameras::camera_folder;
use handeye_vision::Target;

use super::session::{load_optics, page_frames, sample_visits, Optics};
use super::PageOut;
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

/// Writes the page to `out` (the file `path`, for errors), the frames as they are drawn.
fn render_to(
    result: &CellResult,
    folder: &Path,
    out: &mut dyn std::io::Write,
    path: &Path,
) -> Result<(), ReportError> {
    let mut html = format!(
        "<!doctype html><html><head><meta charset=\"utf-8\"><title>handeye: cell with several cameras</title>\
         <style>{}table{{border-collapse:collapse}}td,th{{border:1px solid #ccc;padding:4px 8px;text-align:left}}\
         .GOOD{{color:#070}}.CHECK{{color:#a60}}.REDO{{color:#b00}}</style></head><body>",
        super::CSS
    );
    let _ = write!(
        html,
        "<h1>Calibration of a cell with {} cameras</h1><p>Session <code>{}</code></p>",
        result.cameras.len(),
        escape(&folder.display().to_string()),
    );
    // The cell's verdict (the worst camera's, naming it) on the card of a one-camera page; each
    // camera's cell model is shown under that camera below.
    if let Some(verdict) = &result.verdict {
        let mut cell_verdict = verdict.clone();
        cell_verdict.figures.cell_model = None;
        super::sections::verdict_card(&mut html, &cell_verdict);
    }
    use_section(&mut html, result);
    for f in handeye_session::cell::cameras::read_failures(folder) {
        let _ = write!(
            html,
            "<p class=\"REDO\">Camera <b>{}</b> stopped delivering frames at plan pose {}: {}. Its samples until then are kept and solved.</p>",
            escape(&f.camera),
            f.plan_index,
            escape(&f.error)
        );
    }
    html.push_str("<h2>Cameras</h2><table><tr><th>camera</th><th>verdict</th><th>samples</th><th>solve</th><th>transform</th><th>translation (m)</th><th>rotation vector (rad)</th><th>1-sigma</th><th>vs simulator truth</th></tr>");
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
    html.push_str("<h2>Verdict per camera</h2><table><tr><th>camera</th><th>verdict</th><th>held-out error (leave-one-out, its own samples)</th><th>why</th></tr>");
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
    // Each camera's cell model (issue #38): which of its files its corners contradict.
    for c in &result.cameras {
        let model = c
            .verdict
            .as_ref()
            .and_then(|v| v.figures.cell_model.as_ref());
        if let Some(model) = model {
            let _ = write!(html, "<h3>Camera {}</h3>", escape(&c.name));
            super::sections::cell_model_table(&mut html, model);
        }
    }
    html.push_str("<h2>Boards and camera-to-camera transforms (joint solve)</h2><table><tr><th>transform</th><th>translation (m)</th><th>rotation vector (rad)</th><th>1-sigma</th><th>vs simulator truth</th></tr>");
    for t in result.boards.iter().chain(&result.camera_to_camera) {
        let _ = write!(html, "<tr>{}</tr>", transform_cells(t));
    }
    let _ = write!(
        html,
        "</table><p>Variance factor of the joint solve (χ²/dof): {}</p>",
        result
            .variance_factor
            .map_or_else(|| "—".into(), |f| format!("{f:.3}"))
    );
    residuals_section(&mut html, result)?;
    // Each camera's samples and records, read once for the plots and the frames.
    let records: Vec<Result<CameraRecords, String>> = result
        .cameras
        .iter()
        .map(|c| camera_records(folder, &c.name))
        .collect();
    rotation_axes_section(&mut html, &records)?;
    let mut page = PageOut::new(html, out, path);
    frames_sections(&mut page, result, &records)?;
    let _ = write!(
        page.html,
        "<script>{}</script></body></html>",
        super::SCRIPT
    );
    page.flush()
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

/// The relative rotation axes of the flange poses (one arm for every camera: those of the
/// camera that saw its board at the most poses, from its samples).
fn rotation_axes_section(
    html: &mut String,
    records: &[Result<CameraRecords, String>],
) -> Result<(), ReportError> {
    let Some(pairs) = records
        .iter()
        .filter_map(|r| r.as_ref().ok())
        .map(|r| &r.evidence.pairs)
        .max_by_key(|pairs| pairs.len())
        .filter(|pairs| pairs.len() >= 2)
    else {
        return Ok(());
    };
    html.push_str("<section id=\"rotation-axes\"><h2>Relative rotation axes</h2><p>Axes of the relative flange rotations between every two poses (base frame; an axis and its opposite are the same, so all are drawn with z ≥ 0), on the unit sphere seen from +z and from +x; marker size grows with the rotation angle. The solver needs axes spread over the sphere, not bunched about one direction.</p>");
    super::sections::figure(html, "rotation-axes", &rotation_axes(pairs)?);
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

/// Each camera's frames, as a one-camera page draws them (`session::page_frames`): its
/// detected corners and its board reprojected by the joint answer (its mount and its setup's
/// board), with the board and lens of the config its session was recorded with. A camera left
/// out of the joint solve, or whose files do not load, says so instead.
fn frames_sections(
    page: &mut PageOut<'_>,
    result: &CellResult,
    records: &[Result<CameraRecords, String>],
) -> Result<(), ReportError> {
    let mounts = result.mounts();
    page.html.push_str("<h2>Frames</h2>");
    for (camera, records) in result.cameras.iter().zip(records) {
        let heading = format!("Frames of camera {}", camera.name);
        let id = format!("frames-{}", camera.name);
        let Some((_, mount)) = mounts.iter().find(|(name, _)| *name == camera.name) else {
            let _ = write!(
                page.html,
                "<section id=\"{}\"><h3>{}</h3><p>Not drawn: the camera is not in the joint answer.</p></section>",
                escape(&id),
                escape(&heading)
            );
            continue;
        };
        let mut lacking = Vec::new();
        let frames = match records {
            Ok(records) => {
                camera_optics(records, &camera.name, &mut lacking).map(|(board, lens)| {
                    page_frames(
                        &records.folder,
                        &records.evidence.pairs,
                        &sample_visits(&records.evidence),
                        Optics {
                            board: &board,
                            camera: &lens,
                        },
                        |b| mount.camera_from_target(b),
                    )
                })
            }
            Err(e) => {
                lacking.push(e.clone());
                None
            }
        };
        if !lacking.is_empty() {
            let _ = write!(
                page.html,
                "<p class=\"error\">Camera {}: {}</p>",
                escape(&camera.name),
                escape(&lacking.join("; "))
            );
        }
        page.frames_section(
            &heading,
            &id,
            &format!("frame-{}-", camera.name),
            "the joint solve",
            frames.as_ref(),
        )?;
    }
    Ok(())
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

/// Camera `name`'s board and lens from the config its session was recorded with; `None` when
/// they do not load (`lacking` says why).
fn camera_optics(
    records: &CameraRecords,
    name: &str,
    lacking: &mut Vec<String>,
) -> Option<(Target, CameraModel)> {
    let config = records
        .folder
        .read_manifest()
        .map_err(|e| e.to_string())
        .and_then(|m| CellConfig::load(&m.config).map_err(|e| e.to_string()))
        .map_err(|e| lacking.push(format!("{e}; its frames are not drawn")))
        .ok()?;
    let camera = config.cameras.iter().find(|c| c.name == name);
    if camera.is_none() {
        lacking.push(format!(
            "{} has no camera `{name}`; its frames are not drawn",
            config.file.display()
        ));
    }
    load_optics(&records.folder, camera, lacking)
}

/// Writes the page of `result`, the answer of the session in `folder`, to `path`.
pub fn write_cameras_report(
    result: &CellResult,
    folder: &Path,
    path: &Path,
) -> Result<(), ReportError> {
    super::write_page(path, |out| render_to(result, folder, out, path))
}
