//! `handeye detect`: finds the board in image files and prints, per image, the tags found, the
//! reprojection RMS and `T_camera_target`; optionally writes the results as YAML and annotated
//! PNGs. With `--camera N --live` (the `uvc` build feature) it reads a USB camera instead and
//! prints the board pose continuously, to aim the camera.

use std::io::IsTerminal;
use std::path::PathBuf;

use anyhow::Context;
use clap::Args;
use serde::Serialize;

use handeye_core::atomic_file::write_atomic;
use handeye_core::camera_model::CameraModel;
use handeye_core::geometry::PoseRecord;
use handeye_vision::annotate::annotate;
use handeye_vision::detect::load_gray_image;
use handeye_vision::{estimate_board_pose, DetectorOptions, Target, TargetDetector, TargetError};

/// Detect the board and estimate `T_camera_target` in each image.
#[derive(Debug, Args)]
pub(super) struct DetectArgs {
    /// Board YAML: `target_type: aprilgrid` (Kalibr), `charuco` (OpenCV) or `checkerboard`.
    #[arg(long = "board", alias = "target")]
    target: PathBuf,
    /// Intrinsics: ROS/OpenCV camera_info YAML or Kalibr camchain YAML.
    #[arg(long)]
    intrinsics: PathBuf,
    /// Image files (PNG).
    #[arg(required_unless_present = "live")]
    images: Vec<PathBuf>,
    /// Read the camera (--camera) continuously and print the board pose until Ctrl-C.
    #[arg(long, requires = "camera", conflicts_with = "images")]
    live: bool,
    /// The live camera and stream (with --live).
    #[command(flatten)]
    stream: super::camera::StreamArgs,
    /// Write the per-image results here (YAML).
    #[arg(short = 'o', long)]
    output: Option<PathBuf>,
    /// Write annotated PNGs (corners, ids, axes) into this folder.
    #[arg(long)]
    annotate: Option<PathBuf>,
    /// Quad decimation of the detector (1 = full resolution, at most 16).
    #[arg(long, default_value_t = 2.0)]
    decimation: f32,
    /// Detector threads: 1 (the AprilTag C library this build links races with more).
    #[arg(long, default_value_t = 1)]
    threads: u8,
    /// Images detected at once, each with a detector of its own (default: every core).
    #[arg(short = 'j', long)]
    jobs: Option<usize>,
    /// Highest accepted hamming distance (0-2).
    #[arg(long, default_value_t = 1)]
    max_hamming: u32,
}

/// One image's result as written to the output YAML.
#[derive(Debug, Serialize)]
struct ImageResult {
    image: String,
    found: bool,
    tag_ids: Vec<u32>,
    /// ChArUco / chessboard corner ids (empty for an aprilgrid).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    corner_ids: Vec<u32>,
    rejected_ids: Vec<u32>,
    #[serde(skip_serializing_if = "Option::is_none")]
    error: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    rms_px: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    corners_used: Option<usize>,
    #[serde(skip_serializing_if = "Option::is_none")]
    ambiguity: Option<f64>,
    #[serde(rename = "T_camera_target", skip_serializing_if = "Option::is_none")]
    camera_from_target: Option<PoseRecord>,
}

/// Runs `handeye detect`.
pub(super) fn run(args: DetectArgs) -> anyhow::Result<()> {
    if args.live {
        super::camera::uvc::ensure_available()?;
    }
    let board = Target::load(&args.target)?;
    let camera = CameraModel::load(&args.intrinsics)?;
    let options = DetectorOptions {
        decimation: args.decimation,
        threads: args.threads,
        max_hamming: args.max_hamming,
        ..DetectorOptions::default()
    };
    let detector = TargetDetector::spawn(&board, options.clone())?;
    if args.live {
        return live(&args, &board, &camera, &detector);
    }
    if let Some(dir) = &args.annotate {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("cannot create the annotation folder {}", dir.display()))?;
    }
    // One detector per worker (the AprilTag detector is single-threaded: frames are the unit
    // of parallel work), the results printed in the images' order as they complete.
    let wanted = args
        .jobs
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()))
        .clamp(1, args.images.len().max(1));
    let jobs = jobs_that_fit(&args, &board, &options, &camera, wanted)?;
    let mut detectors = vec![detector];
    for _ in 1..jobs {
        detectors.push(TargetDetector::spawn(&board, options.clone())?);
    }
    // The per-image lines show the progress on a terminal; when they go to a file or a pipe, a
    // bar on the terminal's stderr does.
    let bar = (!std::io::stdout().is_terminal() && std::io::stderr().is_terminal()).then(|| {
        indicatif::ProgressBar::new(args.images.len() as u64).with_style(
            indicatif::ProgressStyle::with_template(
                "detecting {bar:30} {pos}/{len} images, ETA {eta}",
            )
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
        )
    });
    let next = std::sync::atomic::AtomicUsize::new(0);
    let failed = std::sync::atomic::AtomicBool::new(false);
    let (sender, receiver) = std::sync::mpsc::channel();
    let mut results = Vec::new();
    let mut found_count = 0;
    std::thread::scope(|scope| -> anyhow::Result<()> {
        for (detector_index, detector) in detectors.iter().enumerate() {
            let sender = sender.clone();
            let (next, failed, board, camera, args) = (&next, &failed, &board, &camera, &args);
            let worker = std::thread::Builder::new().spawn_scoped(scope, move || {
                use std::sync::atomic::Ordering;
                while !failed.load(Ordering::Relaxed) {
                    let index = next.fetch_add(1, Ordering::Relaxed);
                    let Some(path) = args.images.get(index) else {
                        break;
                    };
                    let outcome =
                        detect_one(path, detector, board, camera, args.annotate.as_deref());
                    failed.fetch_or(outcome.is_err(), Ordering::Relaxed);
                    if sender.send((index, outcome)).is_err() {
                        break;
                    }
                }
            });
            // The detectors started already; a worker that cannot start leaves its images to
            // the others, unless none started.
            if let Err(e) = worker {
                anyhow::ensure!(
                    detector_index > 0,
                    "{}",
                    handeye_core::memory::thread_start_error("a detection worker", &e)
                );
                break;
            }
        }
        drop(sender);
        let mut waiting = std::collections::BTreeMap::new();
        for (index, outcome) in receiver {
            if let Some(bar) = &bar {
                bar.inc(1);
            }
            waiting.insert(index, outcome);
            while let Some(outcome) = waiting.remove(&results.len()) {
                // The first failure in the images' order ends the command (the workers stop).
                let (lines, result) = outcome?;
                for line in lines {
                    outln!("{line}");
                }
                found_count += usize::from(result.found);
                results.push(result);
            }
        }
        Ok(())
    })?;
    if let Some(bar) = bar {
        bar.finish_and_clear();
    }
    if let Some(output) = &args.output {
        let yaml = serde_yaml_ng::to_string(&results)?;
        write_atomic(output, yaml.as_bytes())
            .with_context(|| format!("writing {}", output.display()))?;
    }
    outln!(
        "board found in {found_count} of {} images",
        args.images.len()
    );
    if found_count == 0 {
        return Err(super::NothingFound(format!(
            "the board ({}: {}) was found in none of the {} images: check the target file matches the printed board (kind, size, family or dictionary, first id) and that the board is in view and in focus",
            args.target.display(),
            board.describe(),
            args.images.len()
        ))
        .into());
    }
    Ok(())
}

/// How many images to detect at once: `wanted`, or as many as the memory limits leave room for
/// at the camera's image size (said when fewer; refused with the figures when `-j` asked for
/// more than fit).
fn jobs_that_fit(
    args: &DetectArgs,
    board: &Target,
    options: &DetectorOptions,
    camera: &CameraModel,
    wanted: usize,
) -> anyhow::Result<usize> {
    use handeye_core::memory;
    let (width, height) = (camera.width, camera.height);
    // A detector and its thread, the image being read and its annotated copy.
    let each = TargetDetector::memory_needed(board, options, width, height)
        + 4 * u64::from(width) * u64::from(height);
    let what = |n: usize| format!("detection with {n} detector thread(s) at {width}x{height}");
    // The results of every image are kept until the end: small; the rest of the command too.
    let fit = memory::how_many_fit(what, DETECT_BESIDES_DETECTORS_BYTES, each, wanted)?;
    if fit < wanted {
        if args.jobs.is_some() {
            memory::check(
                &what(wanted),
                DETECT_BESIDES_DETECTORS_BYTES + each * wanted as u64,
                &format!(" or use `-j {fit}`"),
            )?;
        }
        eprintln!(
            "note: {fit} detector thread(s) instead of {wanted}: the memory limit leaves room for {fit} ({} MB each)",
            each.div_ceil(memory::MB)
        );
    }
    Ok(fit)
}

/// Memory `detect` needs besides its detectors: the board, the results, PnP.
const DETECT_BESIDES_DETECTORS_BYTES: u64 = 16 << 20;

/// `detect --camera N --live`: one line per frame with the board pose, until interrupted.
fn live(
    args: &DetectArgs,
    board: &Target,
    camera_model: &CameraModel,
    detector: &TargetDetector,
) -> anyhow::Result<()> {
    let mut camera = super::camera::uvc::open(&args.stream, Some(*camera_model))?;
    outln!("live detection: Ctrl-C to stop");
    loop {
        let frame = camera.grab(std::time::Instant::now())?;
        let detection = match detector.detect(&frame.image) {
            Ok(detection) => detection,
            Err(e @ TargetError::BoardNotFound { .. }) => {
                outln!("board not found: {e}");
                continue;
            }
            Err(e) => return Err(e.into()),
        };
        match estimate_board_pose(board, camera_model, &detection) {
            Ok(pose) => {
                let t = pose.camera_from_target.translation.vector;
                let r = handeye_core::geometry::rotvec(&pose.camera_from_target.rotation);
                outln!(
                    "T_camera_target: t [{:+.4}, {:+.4}, {:+.4}] m, rotvec [{:+.4}, {:+.4}, {:+.4}] rad, {} tags, RMS {:.2} px, distance {:.3} m",
                    t.x, t.y, t.z, r.x, r.y, r.z, pose.tags_used, pose.rms_px, t.norm()
                );
            }
            Err(e) => outln!(
                "board not found ({} tags or corners seen): {e}",
                detection.feature_count()
            ),
        }
    }
}

/// Detects the board in one image and estimates its pose: the lines to print and the result
/// (a board not in view is a result; anything else — an unreadable image, intrinsics of another
/// size — an error naming the image).
fn detect_one(
    path: &std::path::Path,
    detector: &TargetDetector,
    board: &Target,
    camera: &CameraModel,
    annotate_into: Option<&std::path::Path>,
) -> anyhow::Result<(Vec<String>, ImageResult)> {
    let mut lines = Vec::new();
    let image = load_gray_image(path)?;
    let detection = match detector.detect(&image) {
        Ok(detection) => detection,
        // A ChArUco board or chessboard not in view: reported like an aprilgrid without tags.
        Err(e @ TargetError::BoardNotFound { .. }) => {
            lines.push(format!("{}:", path.display()));
            lines.push(format!("  {e}"));
            let result = ImageResult {
                image: path.display().to_string(),
                found: false,
                tag_ids: Vec::new(),
                corner_ids: Vec::new(),
                rejected_ids: Vec::new(),
                error: Some(e.to_string()),
                rms_px: None,
                corners_used: None,
                ambiguity: None,
                camera_from_target: None,
            };
            return Ok((lines, result));
        }
        Err(error) => {
            return Err(error).with_context(|| format!("detecting the board in {}", path.display()))
        }
    };
    let corner_ids: Vec<u32> = detection.points.iter().map(|(id, _)| *id).collect();
    let pose = estimate_board_pose(board, camera, &detection);
    let tag_ids: Vec<u32> = detection.tags.iter().map(|t| t.id).collect();
    let rejected_ids = detection.rejected.iter().map(|r| r.id).collect();
    lines.push(format!("{}:", path.display()));
    if board.aprilgrid().is_some() {
        lines.push(format!("  tags found ({}): {:?}", tag_ids.len(), tag_ids));
    } else {
        lines.push(format!(
            "  corners found ({}): {:?}",
            corner_ids.len(),
            corner_ids
        ));
    }
    let mut result = ImageResult {
        image: path.display().to_string(),
        found: false,
        tag_ids,
        corner_ids,
        rejected_ids,
        error: None,
        rms_px: None,
        corners_used: None,
        ambiguity: None,
        camera_from_target: None,
    };
    match &pose {
        Ok(pose) => {
            let record = PoseRecord::from_pose(&pose.camera_from_target);
            lines.push(format!(
                "  reprojection RMS {:.3} px over {} corners{}",
                pose.rms_px,
                pose.corners_used,
                if pose.is_ambiguous() {
                    format!(
                        " (AMBIGUOUS lone tag, ratio {:.2})",
                        pose.ambiguity.unwrap_or(0.0)
                    )
                } else {
                    String::new()
                }
            ));
            let yaml = serde_yaml_ng::to_string(&record)?;
            lines.push("  T_camera_target:".to_string());
            for line in yaml.lines() {
                lines.push(format!("    {line}"));
            }
            result.found = true;
            result.rms_px = Some(pose.rms_px);
            result.corners_used = Some(pose.corners_used);
            result.ambiguity = pose.ambiguity;
            result.camera_from_target = Some(record);
        }
        // No board in this frame is a result worth reporting; anything else (image size
        // disagreeing with the intrinsics, ...) is a setup mistake that stops the run.
        Err(
            error @ (TargetError::NoTagsFound { .. }
            | TargetError::NotEnoughCorners { .. }
            | TargetError::PoseFailed { .. }),
        ) => {
            lines.push(format!("  board not found: {error}"));
            result.error = Some(error.to_string());
        }
        Err(error) => {
            return Err(anyhow::anyhow!("{error}"))
                .with_context(|| format!("estimating the board pose in {}", path.display()));
        }
    }
    if let Some(dir) = annotate_into {
        let annotated = annotate(&image, board, camera, &detection, pose.as_ref().ok());
        let name = path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "image".to_string());
        let out = dir.join(format!("{name}-annotated.png"));
        let mut bytes = Vec::new();
        annotated
            .write_to(
                &mut std::io::Cursor::new(&mut bytes),
                image::ImageFormat::Png,
            )
            .with_context(|| format!("encoding {}", out.display()))?;
        write_atomic(&out, &bytes).with_context(|| format!("writing {}", out.display()))?;
    }
    Ok((lines, result))
}
