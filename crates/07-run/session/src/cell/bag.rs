//! A ROS 2 bag imported as a session (`handeye import bag`): a recorded pose source for the one
//! run. The bag read ([`handeye_ros2_bag::import_bag_to`]: storage, TF, the frames chosen), each
//! frame, as it is chosen, written as the session's frame file and measured while it is in
//! memory by detection workers of the run's own kind ([`FrameRecorder`]: its preview and record
//! committed; a few frames in memory at a time, never a frame decoded again), with their flange
//! poses as a recorded cell in a staging folder beside the output, run through the one run
//! ([`run::run`], which finds every pose recorded) and solved there, its report written by the
//! caller's [`RunReport`] (the run's tail, as after `handeye run`), and the folder renamed into
//! place only when all of that succeeded; the staging folder of an import that was killed is
//! removed by the next one. What the import did is recorded in
//! `<session>/import/bag-import.yaml`.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use anyhow::Context;

use handeye_config::{recorded_cell, RecordedFiles};
use handeye_core::geometry::Pose;
use handeye_core::setup::RobotFrames;
use handeye_robot::recorded::save_recorded_poses;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;

use super::run::{
    self as run, RunError, RunObserver, RunReport, RunRequest, SessionTarget, Strategy,
};
use super::PreparedCell;
use crate::driver::{FrameRecorder, SessionCamera};
use handeye_camera::{Frame, PngFile};
use handeye_records::{SessionFolder, SolvedSession};

use handeye_ros2_bag::{import_bag_to, BagImport, BagOptions, ChosenFrame, SkipReason};

/// What to import and where.
#[derive(Debug, Clone)]
pub struct BagSessionRequest {
    /// The bag: a folder with metadata.yaml, or one .mcap / .db3 file.
    pub bag: PathBuf,
    /// How to read it (frames, topics, the board, the setup).
    pub options: BagOptions,
    /// The board file (copied into the session).
    pub board_file: PathBuf,
    /// The detector's quad decimation for the session's detection.
    pub decimation: f32,
    /// The arm moved continuously (frames every `spacing`), not stop-and-go: only for the advice
    /// when too few frames are usable.
    pub continuous: bool,
    /// The session folder to create (must not exist, or be empty).
    pub output: PathBuf,
}

/// What the import tells its caller as it goes.
#[derive(Debug, Clone, PartialEq)]
pub enum BagNote {
    /// A line of progress.
    Line(String),
    /// Something wrong with the bag that did not stop the import (recorded in the session too).
    Warning(String),
}

/// A bag imported into a session, solved.
pub struct BagSession {
    /// The session folder, where it is now.
    pub folder: PathBuf,
    /// Samples the session driver accepted.
    pub accepted: usize,
    /// Frames it skipped (board not found or rejected).
    pub skipped: usize,
    /// The bag's warnings (said as [`BagNote::Warning`] and recorded in the session).
    pub warnings: usize,
    /// The solve's summary, naming the session where it is now.
    pub summary: String,
    /// The solved session.
    pub solved: SolvedSession,
    /// The report the run's tail wrote (`report.html` where the session is now), or why it
    /// could not be written (the calibration is saved all the same).
    pub report: Result<PathBuf, String>,
}

/// What `import bag` records about itself in `<session>/import/bag-import.yaml`.
#[derive(serde::Serialize)]
struct BagImportRecord {
    bag: PathBuf,
    format: String,
    image_topic: String,
    images: usize,
    time_offset_s: f64,
    time_offset_estimated: bool,
    #[serde(skip_serializing_if = "Option::is_none")]
    time_offset_residual_mm: Option<f64>,
    samples: Vec<BagSampleRecord>,
    skipped: Vec<BagSkipRecord>,
    /// What is wrong with the bag but did not stop the import.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    warnings: Vec<BagWarningRecord>,
}

#[derive(serde::Serialize)]
struct BagWarningRecord {
    kind: String,
    message: String,
}

#[derive(serde::Serialize)]
struct BagSampleRecord {
    frame: String,
    image_stamp_s: f64,
    robot_stamp_s: f64,
    sharpness: f64,
}

#[derive(serde::Serialize)]
struct BagSkipRecord {
    image_stamp_s: f64,
    reason: String,
}

/// The output folder must be new or empty; staging folders of imports that were killed (kill
/// -9, a power cut) beside it are removed, those of imports still running are left alone.
fn check_output(out: &Path, say: &mut dyn FnMut(BagNote)) -> anyhow::Result<()> {
    if out.exists() {
        let empty = out.is_dir()
            && std::fs::read_dir(out)
                .with_context(|| format!("reading {}", out.display()))?
                .next()
                .is_none();
        anyhow::ensure!(
            empty,
            "{}: exists already; give a new session folder",
            out.display()
        );
    }
    // Staging folders of imports that were killed (kill -9, a power cut) are removed here; those
    // of imports still running beside this one are locked and left alone.
    if let Some(parent) = out.parent() {
        for leftover in handeye_records::remove_abandoned(parent, STAGING_TAG)? {
            match leftover {
                handeye_records::Leftover::Removed(path) => say(BagNote::Line(format!(
                    "removed {} left by an import that was killed",
                    leaf(&path)
                ))),
                handeye_records::Leftover::InUse(path, pid) => say(BagNote::Line(format!(
                    "left {} alone: an import still running{} writes into it",
                    leaf(&path),
                    pid.map(|p| format!(" (pid {p})")).unwrap_or_default()
                ))),
            }
        }
    }
    Ok(())
}

/// What the bag held and what was taken of it, said at once (read whatever follows).
fn say_what_was_read(
    request: &BagSessionRequest,
    imported: &BagImport,
    say: &mut dyn FnMut(BagNote),
) {
    let (a, options) = (request, &request.options);
    // Said first, so they are read whatever follows (even a refusal for too few frames).
    for w in &imported.warnings {
        say(BagNote::Warning(format!("{}: {w}", a.bag.display())));
    }
    let mut kinds: BTreeMap<&str, usize> = BTreeMap::new();
    for s in &imported.skipped {
        *kinds.entry(s.reason.kind()).or_default() += 1;
    }
    say(BagNote::Line(format!(
        "{} ({}): {} images on {}; {} frames taken; skipped: {}",
        a.bag.display(),
        imported.format,
        imported.images,
        options.image_topic,
        imported.samples.len(),
        if kinds.is_empty() {
            "none".to_string()
        } else {
            kinds
                .iter()
                .map(|(k, n)| format!("{n} {k}"))
                .collect::<Vec<_>>()
                .join(", ")
        }
    )));
    for s in imported
        .skipped
        .iter()
        .filter(|s| matches!(s.reason, SkipReason::TfGap(_)))
        .take(3)
    {
        say(BagNote::Line(format!(
            "  frame at {:.3} s: {}",
            s.stamp_ns as f64 * 1e-9,
            s.reason
        )));
    }
    let o = &imported.offset;
    if o.estimated {
        say(BagNote::Line(format!(
            "camera-to-robot clock offset: {:+.2} ms (estimated from {} frames with the board; board position RMS {:.3} mm)",
            o.offset_s * 1e3,
            o.frames_used,
            o.residual_mm.unwrap_or(f64::NAN)
        )));
    } else if o.offset_s != 0.0 {
        say(BagNote::Line(format!(
            "camera-to-robot clock offset: {:+.2} ms (given)",
            o.offset_s * 1e3
        )));
    }
}

/// The import's record (`import/bag-import.yaml`): the bag, the clock offset, every frame taken
/// and skipped, the warnings.
fn import_record(
    request: &BagSessionRequest,
    imported: &BagImport,
    samples: Vec<BagSampleRecord>,
) -> anyhow::Result<BagImportRecord> {
    let (a, options, o) = (request, &request.options, &imported.offset);
    Ok(BagImportRecord {
        bag: absolute(&a.bag)?,
        format: imported.format.to_string(),
        image_topic: options.image_topic.clone(),
        images: imported.images,
        time_offset_s: o.offset_s,
        time_offset_estimated: o.estimated,
        time_offset_residual_mm: o.residual_mm,
        samples,
        skipped: imported
            .skipped
            .iter()
            .map(|s| BagSkipRecord {
                image_stamp_s: s.stamp_ns as f64 * 1e-9,
                reason: s.reason.to_string(),
            })
            .collect(),
        warnings: imported
            .warnings
            .iter()
            .map(|w| BagWarningRecord {
                kind: w.kind().to_string(),
                message: w.to_string(),
            })
            .collect(),
    })
}

/// Imports a bag as a session: reads it, then runs its frames as a recorded cell into a staging
/// folder next to the output and renames it into place when everything succeeded. What it finds
/// on the way goes to `say` at once (so what was said before a refusal is read). `report` is
/// the run's tail (`handeye_report::session::write_run_report`), called before the folder moves.
pub fn import_bag_session(
    request: &BagSessionRequest,
    say: &mut dyn FnMut(BagNote),
    report: RunReport<'_>,
) -> anyhow::Result<BagSession> {
    let a = request;
    let out = absolute(&a.output)?;
    check_output(&out, say)?;
    // Stage everything next to the output; dropped (removed) on any error. Created (and locked)
    // first: the chosen frames are written into it as the bag is read, then the run records
    // there. The result names the session where it will be (the verdict's advice, e.g.
    // `handeye replay DIR --config ...`), not the staging folder.
    let parent = out
        .parent()
        .ok_or_else(|| anyhow::anyhow!("{}: has no parent folder", out.display()))?;
    std::fs::create_dir_all(parent).with_context(|| format!("creating {}", parent.display()))?;
    let name = out
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "session".into());
    let staging = handeye_records::Staging::create(parent, &name, STAGING_TAG)
        .with_context(|| format!("creating a staging folder in {}", parent.display()))?;
    let stage = staging.path().to_path_buf();
    let folder = SessionFolder::create(&stage)?.to_be_moved_to(&out);
    let import_dir = stage.join("import");
    std::fs::create_dir_all(&import_dir)
        .with_context(|| format!("creating {}", import_dir.display()))?;
    let (imported, samples) = import_frames(a, &folder)?;
    say_what_was_read(request, &imported, say);
    anyhow::ensure!(
        imported.samples.len() >= 3,
        "{}: only {} usable frames (a calibration needs at least 3 views): {}",
        a.bag.display(),
        imported.samples.len(),
        if a.continuous {
            "check --image, the TF frames and --spacing"
        } else {
            "did the arm stop at each view? (--max-speed-mm-s, --still-window; or --continuous)"
        }
    );

    // The bag's tolerated lies go into the session's records before it runs, so its solve (and
    // every later `solve` or `replay` of it) lists them beside the solver's notices.
    if !imported.warnings.is_empty() {
        let bag = absolute(&a.bag)?;
        let notices: Vec<_> = imported.warnings.iter().map(|w| w.notice(&bag)).collect();
        folder.save_input_notices(&notices)?;
    }
    let poses: Vec<_> = imported
        .samples
        .iter()
        .map(|s| s.base_from_flange)
        .collect();
    save_recorded_poses(&poses, &import_dir.join("poses.yaml"))?;
    if let Some(camera) = &imported.camera {
        camera.save_camera_info(&import_dir.join("camera_info.yaml"))?;
    }
    std::fs::copy(&a.board_file, import_dir.join("target.yaml"))
        .with_context(|| format!("copying {}", a.board_file.display()))?;
    let config = recorded_config(a, imported.camera.is_some(), &poses);
    let config_file = import_dir.join("cell.yaml");
    config.save(
        &config_file,
        &format!(
            "The recorded cell of the ROS 2 bag {} (written by `handeye import bag`)",
            absolute(&a.bag)?.display()
        ),
    )?;
    // The recorded cell goes through the one run, like any session, into the staging folder.
    let request = RunRequest {
        config: Some(config_file.clone()),
        target: SessionTarget::Created(folder),
        // Nothing moves: a recorded robot serves the bag's poses.
        motion_confirmed: true,
        accept_changed: false,
        stop: Arc::new(AtomicBool::new(false)),
        jobs: request.options.detector.jobs,
    };
    let mut observer = RecordedRun {
        report: String::new(),
        say: &mut *say,
    };
    let done = match run::run(&request, Strategy::Planned, &mut observer) {
        Ok(done) => done,
        Err(RunError::PlanFailed) => anyhow::bail!(
            "the frames taken from {} cannot calibrate:\n{}",
            a.bag.display(),
            observer.report
        ),
        Err(RunError::PlanFailsFromArm { report }) => {
            anyhow::bail!("the recorded plan fails its checks:\n{report}")
        }
        Err(e) => return Err(e.into()),
    };
    // The manifest names the files where they will be once the staging folder is renamed.
    let final_path = |p: &Path| match p.strip_prefix(&stage) {
        Ok(rel) => out.join(rel),
        Err(_) => p.to_path_buf(),
    };
    let mut manifest = done.folder.read_manifest()?;
    manifest.config = out.join("import").join("cell.yaml");
    for input in &mut manifest.inputs {
        input.path = final_path(&std::fs::canonicalize(&input.path).unwrap_or(input.path.clone()));
    }
    done.folder.write_manifest(&manifest)?;
    // The run's tail, as after `handeye run`: its report, from what the run holds.
    let report = report(&done).map(|path| final_path(&path));
    let (outcome, solved) = (done.outcome, done.solved);
    // A bag's recorded cell has one camera, which the run solves alone.
    let solved = solved.context("the bag's recorded cell was not solved as one camera")?;
    for (index, why) in &outcome.skipped {
        say(BagNote::Line(format!(
            "  frame {index:03} ({:.3} s): board not found or rejected: {why}",
            imported.samples[*index].image_stamp_ns as f64 * 1e-9
        )));
    }
    let record = import_record(a, &imported, samples)?;
    let record_file = import_dir.join("bag-import.yaml");
    let text = serde_yaml_ng::to_string(&record).context("writing the import record")?;
    handeye_core::atomic_file::write_atomic(&record_file, text.as_bytes())
        .with_context(|| format!("writing {}", record_file.display()))?;
    // The session folder's lock goes with its last handle; then the folder can move.
    drop(done.folder);
    drop(request);
    staging
        .commit(&out)
        .with_context(|| format!("moving the session into {}", out.display()))?;
    let summary = solved.summary.trim_end().to_string();
    Ok(BagSession {
        folder: out,
        accepted: outcome.accepted.len(),
        skipped: outcome.skipped.len(),
        warnings: imported.warnings.len(),
        summary,
        solved,
        report,
    })
}

/// Reads the bag, writing each chosen frame the moment it is chosen as the session's frame file
/// of its pose (`frames/NNN.png` under `folder`: the one copy) and measuring it while it is in
/// memory, as the run measures a pose ([`FrameRecorder`]: the board detected, its preview and
/// record committed), so the run that follows finds every pose recorded; returns what was read
/// and the frames' records.
fn import_frames(
    request: &BagSessionRequest,
    folder: &SessionFolder,
) -> anyhow::Result<(BagImport, Vec<BagSampleRecord>)> {
    let mut samples = Vec::new();
    let mut recorder: Option<FrameRecorder> = None;
    let imported = import_bag_to(&request.bag, &request.options, &mut |chosen| {
        let frame = SessionFolder::frame_name(chosen.index);
        let png = frame_png(chosen.image)?;
        // Written as every session file is (atomically); the workers keep it as it is.
        folder.write_file(&frame, &png)?;
        let file = folder.root().join(&frame);
        samples.push(BagSampleRecord {
            frame: frame.display().to_string(),
            image_stamp_s: chosen.sample.image_stamp_ns as f64 * 1e-9,
            robot_stamp_s: chosen.sample.robot_stamp_ns as f64 * 1e-9,
            sharpness: chosen.sample.sharpness,
        });
        let recorder = match &mut recorder {
            Some(recorder) => recorder,
            None => recorder.insert(start_recorder(request, folder, &chosen)?),
        };
        let image = Frame {
            image: chosen.image.clone(),
            captured_at: std::time::Instant::now(),
            png: Some(PngFile {
                path: file,
                bytes: png,
            }),
        };
        // The pose the recorded robot serves the run: `poses.yaml` reads a unit quaternion back
        // as written, so the record holds the very pose of the run's plan.
        recorder
            .record(chosen.index, image, chosen.sample.base_from_flange)
            .context(RECORDING)?;
        Ok(())
    })
    .context("importing a ROS 2 bag")?;
    if let Some(recorder) = recorder {
        recorder.finish().context(RECORDING)?;
    }
    Ok((imported, samples))
}

/// What a failure to measure or record a chosen frame stopped (the staging folder goes with it).
const RECORDING: &str = "recording the bag's chosen frames into the session (nothing is kept)";

/// The detection workers of the import's recorded cell, measuring as its run would: the
/// detector and the rejection threshold of the cell config the import writes
/// ([`recorded_config`]), its board, and the bag's intrinsics as the run reads them back.
fn start_recorder(
    request: &BagSessionRequest,
    folder: &SessionFolder,
    chosen: &ChosenFrame<'_>,
) -> anyhow::Result<FrameRecorder> {
    // The poses are not known yet; only the config's detector and session sections are read.
    let config = recorded_config(request, chosen.camera.is_some(), &[]);
    let camera = SessionCamera {
        name: "camera".into(),
        folder: folder.clone(),
        setup: request.options.setup,
        board: request.options.board.clone(),
        estimate_intrinsics: chosen.camera.is_none(),
    };
    Ok(FrameRecorder::start(
        &camera,
        config.detector.options(),
        config.session.max_reprojection_rms_px,
        chosen.camera.copied(),
        chosen.image.dimensions(),
    )?)
}

/// An imported frame as PNG with the `Up` filter (each row minus the one above) rather than the
/// encoder's default choice per row: undoing `Up` is a vectorised add where the default's
/// `Paeth` rows were a sixth of a short import's PNG cost, and camera frames compress about as
/// well either way. (The frame is measured from memory; the report draws it from its preview.)
fn frame_png(frame: &image::GrayImage) -> anyhow::Result<Vec<u8>> {
    use image::codecs::png::{CompressionType, FilterType, PngEncoder};
    use image::ImageEncoder as _;
    let mut png = Vec::new();
    PngEncoder::new_with_quality(&mut png, CompressionType::Fast, FilterType::Up).write_image(
        frame.as_raw(),
        frame.width(),
        frame.height(),
        image::ExtendedColorType::L8,
    )?;
    Ok(png)
}

/// The tag of `import bag`'s staging folders: `.<session>.importing-XXXXXX`.
const STAGING_TAG: &str = "importing";

/// A path's last component, for messages.
fn leaf(path: &Path) -> String {
    path.file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| path.display().to_string())
}

/// The absolute form of a path that may not exist yet (an output about to be written).
fn absolute(path: &Path) -> anyhow::Result<PathBuf> {
    std::path::absolute(path).with_context(|| format!("resolving {}", path.display()))
}

/// The observer of a bag's recorded run: it keeps the plan report (for a refusal) and passes the
/// run's notes on.
struct RecordedRun<'s> {
    report: String,
    say: &'s mut dyn FnMut(BagNote),
}

impl RunObserver for RecordedRun<'_> {
    fn plan_checked(&mut self, cell: &PreparedCell) {
        self.report = cell.report.to_string();
    }

    fn confirm_motion(
        &mut self,
        _cell: &PreparedCell,
        _poses: usize,
    ) -> Result<(), Box<dyn std::error::Error + Send + Sync>> {
        // A recorded robot moves nothing.
        Ok(())
    }

    fn note(&mut self, message: &str) {
        (self.say)(BagNote::Line(format!("note: {message}")));
    }
}

/// The recorded cell of an import: the frames and flange poses in `<import>/`, in the frames
/// the bag's poses were read in.
fn recorded_config(
    a: &BagSessionRequest,
    with_intrinsics: bool,
    poses: &[Pose],
) -> handeye_config::ConfigFile {
    let options = &a.options;
    let identity = Pose::identity();
    recorded_cell(
        options.setup,
        RecordedFiles {
            target: PathBuf::from("target.yaml"),
            intrinsics: with_intrinsics.then(|| PathBuf::from("camera_info.yaml")),
            poses: PathBuf::from("poses.yaml"),
            // The session's own frames: the import wrote them there, the run keeps them.
            images: PathBuf::from("../frames"),
            frames: RobotFrames {
                base: options.base_frame.clone(),
                flange: options.flange_frame.clone(),
            },
        },
        // Nominal transforms only feed a recorded cell's plan report; the solve needs none.
        (identity, identity),
        poses,
        a.decimation,
    )
}
