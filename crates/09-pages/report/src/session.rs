//! Gathers a report's input from a session folder: the samples (`samples.yaml`), the recorded
//! visits (frames and detected corners, `poses/NNN.yaml`), and — with the board and the camera
//! model — per-sample reprojection errors at the predicted `T_camera_target` and the frames as
//! a page shows them (the run's grey JPEG previews, at most [`FRAME_WIDTH`] wide, with the marks
//! to draw over them). Pixels follow the OpenCV convention (origin at the top-left pixel's
//! centre).

use std::collections::HashMap;

use nalgebra::Point2;

use super::{CornerResidual, PageFrame, PageFrames, ReportAnswer, ReportError, ReportInput};
use handeye_core::camera_model::CameraModel;
use handeye_core::geometry::Pose;
use handeye_core::keeping_largest;
use handeye_core::setup::{CornerObservation, PosePair, RobotFrames};
use handeye_records::dataset::Dataset;
use handeye_records::result::CellResult;
use handeye_records::{Evidence, PoseVisit, SessionError, SessionFolder, SolvedSession};
use handeye_session::cell::replay::Replayed;
use handeye_session::cell::run::CellRun;
use handeye_solve::verdict::Verdict;
use handeye_solve::Calibration;
use handeye_vision::annotate::{self, PredictionMarks, Preview};
use handeye_vision::Target;

/// Largest width of a frame in the report, px: the grid shows it small, a click full size.
/// Narrower frames keep their size.
pub const FRAME_WIDTH: u32 = annotate::PREVIEW_WIDTH;

/// The board and lens a session was recorded with (needed for reprojection and the frames).
#[derive(Debug, Clone, Copy)]
pub struct Optics<'a> {
    /// The board.
    pub board: &'a Target,
    /// The camera's intrinsics and distortion.
    pub camera: &'a CameraModel,
}

/// Which answer of a session a report shows (the first one is the primary: the one
/// `result.yaml` holds, whose verdict the page shows).
#[derive(Debug, Clone)]
pub enum Answer {
    /// The answer refined over every detected corner.
    ReprojectionSpace(Calibration),
    /// The answer from one board pose per frame (`A = X·B·Y`).
    PoseSpace(Calibration),
    /// The answer `result.yaml` holds (a report made again from a session folder).
    ResultFile(Calibration),
    /// One camera's part of a several-camera cell's joint answer (`result.yaml` of the cell),
    /// with what the joint solve gives of it.
    Joint(Calibration, super::JointFigures),
}

impl Answer {
    /// Its calibration.
    pub fn calibration(&self) -> &Calibration {
        match self {
            Answer::ReprojectionSpace(c)
            | Answer::PoseSpace(c)
            | Answer::ResultFile(c)
            | Answer::Joint(c, _) => c,
        }
    }

    /// The label the page shows.
    pub fn label(&self) -> String {
        match self {
            Answer::ReprojectionSpace(_) => "reprojection space".into(),
            Answer::PoseSpace(_) => "pose space".into(),
            Answer::ResultFile(c) => format!("result.yaml ({})", c.solver.method.name()),
            Answer::Joint(..) => "joint solve".into(),
        }
    }

    /// A solved session's answers: the reprojection-space one first when it was computed, then
    /// the pose-space one.
    pub fn of(solved: &SolvedSession) -> Vec<Answer> {
        let mut answers = Vec::new();
        if solved.reprojection.is_some() {
            answers.push(Answer::ReprojectionSpace(solved.calibration.clone()));
        }
        answers.push(Answer::PoseSpace(solved.pose_space.clone()));
        answers
    }
}

/// Builds the report input of a session for one or more answers, from what it was solved from
/// (`evidence`: its samples and records; the frames are read from `folder` to draw them).
///
/// Without `optics` the page has no frames and no reprojection bars (everything else is
/// there). Samples are matched to visits by their id `pose-NNN`.
pub fn from_session(
    folder: &SessionFolder,
    evidence: &Evidence,
    answers: Vec<Answer>,
    optics: Option<Optics<'_>>,
) -> Result<ReportInput, ReportError> {
    let pairs = &evidence.pairs;
    let sample_visits = sample_visits(evidence);

    let answers: Vec<ReportAnswer> = answers
        .into_iter()
        .map(|answer| {
            let (label, calibration) = (answer.label(), answer.calibration().clone());
            let joint = match answer {
                Answer::Joint(_, figures) => Some(figures),
                _ => None,
            };
            let reprojection_px = pairs
                .iter()
                .zip(&sample_visits)
                .map(|(pair, visit)| {
                    let (optics, visit) = (optics?, (*visit)?);
                    let predicted = calibration.predict_camera_from_target(&pair.base_from_flange);
                    reprojection_rms(optics, &predicted, &visit.corners_px)
                })
                .collect();
            ReportAnswer {
                label,
                calibration,
                reprojection_px,
                joint,
            }
        })
        .collect();

    let mut corners = Vec::new();
    if let (Some(optics), Some(primary)) = (optics, answers.first()) {
        for (sample, (pair, visit)) in pairs.iter().zip(&sample_visits).enumerate() {
            let Some(visit) = visit else { continue };
            let predicted = primary
                .calibration
                .predict_camera_from_target(&pair.base_from_flange);
            corners.extend(corner_residuals(optics, &predicted, &visit.corners_px).map(
                |(detected_px, residual_px)| CornerResidual {
                    sample,
                    detected_px,
                    residual_px,
                },
            ));
        }
    }
    let frames = match (optics, answers.first()) {
        (Some(optics), Some(primary)) => {
            Some(page_frames(folder, pairs, &sample_visits, optics, |b| {
                primary.calibration.predict_camera_from_target(b)
            }))
        }
        _ => None,
    };
    Ok(ReportInput {
        title: folder.shown_root().display().to_string(),
        setup: answers
            .first()
            .map(|a| a.calibration.setup)
            .ok_or(ReportError::Empty)?,
        pairs: pairs.clone(),
        answers,
        frames,
        holdout: None,
        verdict: None,
        arm_time: None,
        nominal: None,
        corners,
        image_size: optics.map(|o| (o.camera.width, o.camera.height)),
        robot_frames: RobotFrames::default(),
        arm: None,
    })
}

/// Each sample's visit (its frame and detected corners), matched by the sample id `pose-NNN`.
pub(crate) fn sample_visits(evidence: &Evidence) -> Vec<Option<&PoseVisit>> {
    let by_id: HashMap<String, &PoseVisit> =
        evidence.visits.iter().map(|v| (v.sample_id(), v)).collect();
    evidence
        .pairs
        .iter()
        .map(|p| p.id.as_ref().and_then(|id| by_id.get(id).copied()))
        .collect()
}

/// Every sample's frame that has a visit, to be drawn ([`draw_frames`]) with the board at
/// `predict(T_base_flange)` (`T_camera_target` of the answer shown), at most
/// [`annotate::MAX_FRAMES_SHOWN`] of them. The one way a page lists its frames, one camera's or
/// each of several.
pub(crate) fn page_frames(
    folder: &SessionFolder,
    pairs: &[PosePair],
    sample_visits: &[Option<&PoseVisit>],
    optics: Optics<'_>,
    predict: impl Fn(&Pose) -> Pose,
) -> PageFrames {
    let visited: Vec<(usize, &PosePair, &PoseVisit)> = pairs
        .iter()
        .zip(sample_visits)
        .enumerate()
        .filter_map(|(sample, (pair, visit))| Some((sample, pair, (*visit)?)))
        .collect();
    let predicted: Vec<Pose> = visited
        .iter()
        .map(|(_, pair, _)| predict(&pair.base_from_flange))
        .collect();
    let drawn = if visited.len() <= annotate::MAX_FRAMES_SHOWN {
        (0..visited.len()).collect()
    } else {
        // How far each frame's board is from where the answer puts it, px (RMS over its corners).
        let fits: Vec<Option<f64>> = visited
            .iter()
            .zip(&predicted)
            .map(|((_, _, visit), camera_from_target)| {
                reprojection_rms(optics, camera_from_target, &visit.corners_px)
            })
            .collect();
        keeping_largest(visited.len(), annotate::MAX_FRAMES_SHOWN, |i| {
            fits[i].unwrap_or(f64::NEG_INFINITY)
        })
    };
    let mut is_drawn = vec![false; visited.len()];
    for &i in &drawn {
        is_drawn[i] = true;
    }
    let not_drawn = (0..visited.len())
        .filter(|&i| !is_drawn[i])
        .map(|i| visited[i].0)
        .collect();
    let frames = drawn
        .into_iter()
        .map(|i| {
            let (sample, pair, visit) = visited[i];
            PageFrame {
                sample,
                caption: format!(
                    "sample {sample} ({}), board RMS {}",
                    pair.id.as_deref().unwrap_or("?"),
                    visit
                        .reprojection_rms_px
                        .map(|r| format!("{r:.3} px"))
                        .unwrap_or_else(|| "-".into())
                ),
                path: folder.root().join(&visit.frame),
                camera_from_target: predicted[i],
                corners_px: visit.corners_px.iter().map(|c| c.pixel).collect(),
            }
        })
        .collect();
    PageFrames {
        board: optics.board.clone(),
        camera: *optics.camera,
        frames,
        not_drawn,
    }
}

/// Frames drawn at once (on every core) before they are written: the page holds this many
/// encoded frames at most, whatever the session's size.
const FRAMES_AT_ONCE: usize = 8;

/// A frame as a page shows it: its [`Preview`] and the marks to draw over it.
pub(crate) struct ShownFrame {
    pub(crate) preview: Preview,
    pub(crate) marks: PredictionMarks,
}

/// Each of `frames` shown ([`shown_frame`]), handed to `write` in order: [`FRAMES_AT_ONCE`] at a
/// time on every core (rayon keeps the order).
pub(crate) fn draw_frames(
    frames: &PageFrames,
    mut write: impl FnMut(&PageFrame, ShownFrame) -> Result<(), ReportError>,
) -> Result<(), ReportError> {
    use rayon::prelude::*;
    let optics = Optics {
        board: &frames.board,
        camera: &frames.camera,
    };
    for chunk in frames.frames.chunks(FRAMES_AT_ONCE) {
        let drawn: Vec<Result<ShownFrame, ReportError>> = chunk
            .par_iter()
            .map(|frame| shown_frame(frame, optics))
            .collect();
        for (frame, shown) in chunk.iter().zip(drawn) {
            write(frame, shown?)?;
        }
    }
    Ok(())
}

/// RMS pixel distance between detected corners and the board's corners projected at
/// `camera_from_target`; `None` when no corner can be compared.
pub fn reprojection_rms(
    optics: Optics<'_>,
    camera_from_target: &Pose,
    corners_px: &[CornerObservation],
) -> Option<f64> {
    let (sum, count) = corner_residuals(optics, camera_from_target, corners_px)
        .fold((0.0, 0usize), |(sum, count), (_, r)| {
            (sum + r.norm_squared(), count + 1)
        });
    (count > 0).then(|| (sum / count as f64).sqrt())
}

/// Each detected corner that the board knows and that projects, with its residual (detected
/// minus the board's corner projected at `camera_from_target`), px.
fn corner_residuals<'c>(
    optics: Optics<'c>,
    camera_from_target: &'c Pose,
    corners_px: &'c [CornerObservation],
) -> impl Iterator<Item = (Point2<f64>, nalgebra::Vector2<f64>)> + 'c {
    corners_px.iter().filter_map(move |c| {
        let point = optics.board.observation_point(c)?;
        let pixel = optics.camera.project(&(camera_from_target * point))?;
        Some((c.pixel, c.pixel - pixel))
    })
}

/// The frame at most [`FRAME_WIDTH`] wide with the marks of the board reprojected at its
/// predicted `T_camera_target` and of its detected corners
/// (`handeye_vision::annotate::PredictionMarks`). The picture is the preview the run wrote when
/// it decoded the frame (`previews/NNN.jpg`), unless that is missing, older than the frame or of
/// another size; then it is made from the frame.
fn shown_frame(frame: &PageFrame, optics: Optics<'_>) -> Result<ShownFrame, ReportError> {
    let frame_error = |message: String| ReportError::Frame {
        path: frame.path.clone(),
        message,
    };
    let size = image::image_dimensions(&frame.path).map_err(|e| frame_error(e.to_string()))?;
    let marks = PredictionMarks::of(
        size,
        FRAME_WIDTH,
        optics.board,
        optics.camera,
        &frame.camera_from_target,
        frame.corners_px.iter().copied(),
    );
    let preview = match recorded_preview(&frame.path, marks.size) {
        Some(preview) => preview,
        None => {
            let grey = image::open(&frame.path)
                .map_err(|e| frame_error(e.to_string()))?
                .into_luma8();
            annotate::preview(&grey, FRAME_WIDTH, annotate::PREVIEW_QUALITY).map_err(frame_error)?
        }
    };
    Ok(ShownFrame { preview, marks })
}

/// The preview a run wrote of `frame` when it is of `size` and no older than the frame (a frame
/// written again since has a preview no longer its own).
fn recorded_preview(frame: &std::path::Path, size: (u32, u32)) -> Option<Preview> {
    let path = SessionFolder::preview_of(frame)?;
    let modified = |p: &std::path::Path| std::fs::metadata(p).and_then(|m| m.modified()).ok();
    if modified(&path)? < modified(frame)? {
        return None;
    }
    let jpeg = std::fs::read(&path).ok()?;
    let shown =
        image::ImageReader::with_format(std::io::Cursor::new(&jpeg), image::ImageFormat::Jpeg)
            .into_dimensions()
            .ok()?;
    (shown == size).then_some(Preview {
        jpeg,
        width: size.0,
        height: size.1,
    })
}

/// What writes a page of the records in `dir`, which hold no answer: `replay` writes its own
/// answer and page beside the session's (it never writes `result.yaml`); a camera's folder of
/// several has the cell's page.
fn what_writes_a_page(dir: &std::path::Path) -> String {
    let dir_shown = dir.display();
    match handeye_session::cell::cameras::session_of_camera_folder(dir) {
        Some(root) => format!(
            "this camera's answer is the joint one of the session {}: `handeye report {}` draws its page, a part for each camera (`handeye replay {dir_shown}` solves this camera alone and writes that page beside its answer)",
            root.display(),
            root.display()
        ),
        None => format!(
            "`handeye run --resume {dir_shown}` finishes an interrupted run, `handeye replay {dir_shown}` solves the session again from its frames and writes that page beside its answer"
        ),
    }
}

/// Writes `<session>/report.html` for a run that just ended, one camera or several (the page of
/// [`CellRun::root`]), from what the run holds: its answers, the samples and records its solve
/// read, the board and lens of its cell, its verdict and arm time (nothing is read again,
/// nothing judged again). The one tail of every run: `handeye run`, `handeye.run` in Python.
/// Returns the path written.
pub fn write_run_report(run: &CellRun) -> Result<std::path::PathBuf, ReportError> {
    let Some(solved) = &run.solved else {
        let path = run.root.join(REPORT_FILE);
        super::cameras::write_cameras_report(&run.result, &run.root, &path)?;
        return Ok(path);
    };
    // The intrinsics of the config, else the ones the run estimated.
    let camera = if run.cell.camera().intrinsics_known {
        Some(run.cell.camera().camera_model)
    } else {
        solved.estimated_camera
    };
    let optics = camera.as_ref().map(|camera| Optics {
        board: &run.cell.camera().board,
        camera,
    });
    write(
        &run.folder,
        &solved.evidence,
        Answer::of(solved),
        Page {
            optics,
            verdict: solved.verdict.clone(),
            arm_time: run.arm_time,
            nominal: Some(run.cell.config.camera().nominal),
            robot_frames: run.cell.config.robot.frames(),
            arm: solved.arm.as_ref().map(|a| a.result_section()),
            // The session's own folder: a listed cell of one camera's root.
            path: run.root.join(REPORT_FILE),
        },
    )
}

/// The report of a session folder, `<session>/report.html`.
pub const REPORT_FILE: &str = "report.html";
/// The report of a replay (`handeye replay`), beside its result (the session folder by
/// default, where the run's own `report.html` stays).
pub const REPLAY_REPORT_FILE: &str = "replay-report.html";

/// Writes the page of a replay (`handeye replay DIR`, [`Replayed`]), one camera or several, to
/// `path`: the answers, the verdict and the evidence of the solve just made from the frames
/// detected again, with the board and lens it used; the run's own `report.html` stays. Returns
/// the path written.
pub fn write_replay_report(
    replay: &Replayed,
    path: &std::path::Path,
) -> Result<std::path::PathBuf, ReportError> {
    let Some(camera) = &replay.camera else {
        super::cameras::write_cameras_report(&replay.result, &replay.root, path)?;
        return Ok(path.to_path_buf());
    };
    let config = &replay.cell.config;
    write(
        &camera.folder,
        &camera.solved.evidence,
        Answer::of(&camera.solved),
        Page {
            optics: Some(Optics {
                board: &replay.cell.camera().board,
                camera: &camera.camera_model,
            }),
            verdict: camera.solved.verdict.clone(),
            arm_time: None,
            nominal: Some(config.camera().nominal),
            robot_frames: config.robot.frames(),
            arm: camera.solved.arm.as_ref().map(|a| a.result_section()),
            path: path.to_path_buf(),
        },
    )
}

/// What [`write_folder_report`] wrote.
#[derive(Debug)]
pub struct FolderReport {
    /// The page.
    pub path: std::path::PathBuf,
    /// What the page lacks and why (a config, board or intrinsics file that cannot be read: no
    /// frames or reprojection errors).
    pub lacking: Vec<String>,
    /// The run still recording the session, when one is: the page is of the answer an earlier
    /// part of it wrote, and says so.
    pub provisional: Option<handeye_records::LiveRun>,
}

/// Writes `<session>/report.html` for a session folder solved earlier (`handeye report DIR`),
/// one camera's or a several-camera cell's, from its `result.yaml` and its records; for one
/// camera, the board and lens that draw its frames from `config` (default: the config the
/// session was recorded with) when it loads (a several-camera page draws each camera's frames
/// with the board and lens of the config its own session names).
/// While a run is still recording the session, the page is of the result an earlier part of
/// it wrote (refused when there is none yet).
pub fn write_folder_report(
    dir: &std::path::Path,
    config: Option<&std::path::Path>,
) -> Result<FolderReport, ReportError> {
    let session_error = |e: SessionError| ReportError::Session(Box::new(e));
    let provisional = handeye_records::live_run(dir).map_err(session_error)?;
    let result_path = dir.join(handeye_records::RESULT_FILE);
    if let Some(run) = &provisional {
        // Without a result there is nothing to report yet; the run writes both when it ends.
        if !result_path.is_file() {
            return Err(ReportError::NotSolved {
                path: result_path,
                why: format!(
                    "{run}; it writes result.yaml and report.html when it ends (`handeye solve {}` gives a provisional answer now)",
                    dir.display()
                ),
            });
        }
    }
    let not_solved = |e: handeye_core::yaml_file::FileError| ReportError::NotSolved {
        path: result_path.clone(),
        why: format!("{e}; {}", what_writes_a_page(dir)),
    };
    let cell = CellResult::load(&result_path).map_err(not_solved)?;
    // A cell of several cameras has its page; one camera's answer is drawn below.
    let Some(result) = cell.only_camera() else {
        let path = dir.join(REPORT_FILE);
        super::cameras::write_cameras_report(&cell, dir, &path)?;
        return Ok(FolderReport {
            path,
            lacking: Vec::new(),
            provisional,
        });
    };
    // A listed cell of one camera: its camera's session (whose answer its root holds too).
    let folder = SessionFolder::open(&handeye_session::cell::cameras::session_to_read(dir))
        .map_err(session_error)?;
    let mut lacking = Vec::new();
    let config_path = match config {
        Some(path) => path.to_path_buf(),
        None => folder.read_manifest().map_err(session_error)?.config,
    };
    let config = match handeye_config::CellConfig::load(&config_path)
        .and_then(|c| handeye_session::cell::config_of_camera_folder(c, folder.root()))
    {
        Ok(config) => Some(config),
        Err(e) => {
            lacking.push(format!(
                "{e}; the report will have no frames or reprojection errors"
            ));
            None
        }
    };
    let mut calibration = result.to_calibration(&result_path).map_err(not_solved)?;
    if let Some(run) = &provisional {
        // The page's findings say it too.
        calibration
            .notices
            .insert(0, handeye_records::solve::provisional_notice(run));
    }
    let config = config.as_ref();
    let evidence = Evidence {
        pairs: Dataset::load(&folder.samples_path())
            .map_err(|e| session_error(SessionError::File(e)))?
            .pairs,
        visits: folder.read_visits().map_err(session_error)?,
    };
    let loaded = load_optics(&folder, config.map(|c| c.camera()), &mut lacking);
    let optics = loaded
        .as_ref()
        .map(|(board, camera)| Optics { board, camera });
    let path = write(
        &folder,
        &evidence,
        vec![Answer::ResultFile(calibration)],
        Page {
            optics,
            verdict: result.verdict.clone(),
            arm_time: handeye_session::cell::run::ArmTime::load(folder.root()),
            nominal: config.map(|c| c.camera().nominal),
            robot_frames: result.robot_frames.clone().unwrap_or_default(),
            arm: result.kinematics.clone(),
            path: dir.join(REPORT_FILE),
        },
    )?;
    Ok(FolderReport {
        path,
        lacking,
        provisional,
    })
}

/// The board and lens that draw `camera`'s frames: its config's, the intrinsics a from-scratch
/// run estimated into `folder` when the config gives none; `None` without a config or when a
/// file does not load (`lacking` says which and why: the page then has no frames or
/// reprojection errors).
pub(crate) fn load_optics(
    folder: &SessionFolder,
    camera: Option<&handeye_config::CellCamera>,
    lacking: &mut Vec<String>,
) -> Option<(Target, CameraModel)> {
    let camera = camera?;
    let board = Target::load(&camera.target)
        .map_err(|e| lacking.push(format!("no frames or reprojection errors: {e}")))
        .ok();
    let camera_file = camera
        .intrinsics
        .clone()
        .or_else(|| Some(folder.root().join("camera_info.yaml")).filter(|p| p.is_file()));
    let model = camera_file.and_then(|file| {
        CameraModel::load(&file)
            .map_err(|e| lacking.push(format!("no frames or reprojection errors: {e}")))
            .ok()
    });
    Some((board?, model?))
}

/// What a session's page shows besides its evidence and answers.
struct Page<'a> {
    optics: Option<Optics<'a>>,
    verdict: Option<Verdict>,
    arm_time: Option<handeye_session::cell::run::ArmTime>,
    nominal: Option<handeye_core::setup::CellTransforms>,
    robot_frames: RobotFrames,
    arm: Option<handeye_records::result::KinematicsYaml>,
    path: std::path::PathBuf,
}

/// The page of a session: its input from the evidence and answers, the held-out figures from
/// the verdict, written to the page's `path`.
fn write(
    folder: &SessionFolder,
    evidence: &Evidence,
    answers: Vec<Answer>,
    page: Page<'_>,
) -> Result<std::path::PathBuf, ReportError> {
    let Page {
        optics,
        verdict,
        arm_time,
        nominal,
        robot_frames,
        arm,
        path,
    } = page;
    let mut input = from_session(folder, evidence, answers, optics)?;
    input.arm_time = arm_time;
    input.nominal = nominal;
    input.robot_frames = robot_frames;
    input.arm = arm;
    input.holdout = verdict
        .as_ref()
        .and_then(|v| v.figures.held_out.as_ref())
        .map(|h| holdout_summary(h, "flagged outliers not counted"));
    input.verdict = verdict;
    super::write_report(&path, &input)?;
    Ok(path)
}

/// A verdict's held-out figures as the page shows them (`note`: how they were made).
pub(crate) fn holdout_summary(
    held_out: &handeye_solve::verdict::HeldOut,
    note: &str,
) -> super::HoldoutSummary {
    super::HoldoutSummary {
        description: format!("leave-one-out over {} samples ({note})", held_out.poses),
        rotation_rms_deg: held_out.rotation_rms_deg,
        translation_rms_mm: held_out.translation_rms_mm,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use handeye_vision::{Board, TagFamily};

    /// `samples` visits of a 6 x 6 aprilgrid seen at one pose, the answer predicting that pose;
    /// the samples in `misfit` saw the board 5 px to the right of where it predicts.
    fn frames_of(samples: usize, misfit: &[usize]) -> PageFrames {
        let board: Target = Board::aprilgrid(6, 6, 0.03, 0.3, TagFamily::Tag36h11, 0, 1)
            .expect("board")
            .into();
        let camera = CameraModel {
            width: 1280,
            height: 720,
            fx: 900.0,
            fy: 900.0,
            cx: 639.5,
            cy: 359.5,
            distortion: handeye_core::camera_model::Distortion::None,
        };
        let seen_at = Pose::translation(-0.1, -0.1, 0.6);
        let dir = tempfile::tempdir().expect("temporary folder");
        let folder = SessionFolder::create(&dir.path().join("session")).expect("session folder");
        let pairs: Vec<PosePair> = (0..samples)
            .map(|i| PosePair::new(Pose::translation(1e-3 * i as f64, 0.0, 0.0), seen_at))
            .collect();
        let visits: Vec<PoseVisit> = (0..samples)
            .map(|i| {
                let shift = if misfit.contains(&i) { 5.0 } else { 0.0 };
                PoseVisit {
                    schema_version: handeye_core::yaml_file::SchemaVersion::CURRENT,
                    plan_index: i,
                    base_from_flange: pairs[i].base_from_flange,
                    frame: format!("frames/pose_{i:04}.png").into(),
                    camera_from_target: Some(seen_at),
                    reprojection_rms_px: Some(0.1),
                    view_sigma: None,
                    tags: 36,
                    corners_px: board
                        .points()
                        .into_iter()
                        .filter_map(|(tag_id, corner, point)| {
                            let pixel = camera.project(&(seen_at * point))?;
                            Some(CornerObservation {
                                tag_id,
                                corner,
                                pixel: pixel + nalgebra::Vector2::new(shift, 0.0),
                            })
                        })
                        .collect(),
                    rejected: None,
                }
            })
            .collect();
        let sample_visits: Vec<Option<&PoseVisit>> = visits.iter().map(Some).collect();
        let optics = Optics {
            board: &board,
            camera: &camera,
        };
        page_frames(&folder, &pairs, &sample_visits, optics, |_| seen_at)
    }

    /// A session's frames are all drawn; a long recording's at `annotate::MAX_FRAMES_SHOWN`, the
    /// frames whose board is farthest from the prediction among them, the others from every part
    /// of it.
    #[test]
    fn a_long_recording_draws_every_misfit_frame_and_a_bounded_number() {
        let few = frames_of(annotate::MAX_FRAMES_SHOWN, &[3]);
        assert_eq!(few.frames.len(), annotate::MAX_FRAMES_SHOWN);
        assert!(few.not_drawn.is_empty());

        let misfit = [3, 250, 511, 777, 999];
        let many = frames_of(1000, &misfit);
        assert_eq!(many.not_drawn.len(), 1000 - annotate::MAX_FRAMES_SHOWN);
        assert_eq!(many.frames.len(), annotate::MAX_FRAMES_SHOWN);
        let samples: Vec<usize> = many.frames.iter().map(|f| f.sample).collect();
        assert!(samples.windows(2).all(|w| w[0] < w[1]), "in session order");
        assert!(
            many.not_drawn.iter().all(|s| !samples.contains(s)),
            "a frame both drawn and not"
        );
        for m in misfit {
            assert!(samples.contains(&m), "misfit frame {m} not drawn");
        }
        assert!(
            *samples.last().unwrap() >= 990,
            "the end of the session is drawn"
        );
        let frame = &many.frames[samples.iter().position(|&s| s == 511).unwrap()];
        assert!(frame.caption.starts_with("sample 511"));
        assert!(frame.path.ends_with("frames/pose_0511.png"));
    }
}
