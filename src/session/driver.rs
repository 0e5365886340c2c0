//! The run loop: the arm and camera on the calling thread, detection and recording on a worker
//! thread, so the vision work for pose i happens while the arm moves to pose i+1.

use std::collections::{BTreeMap, BTreeSet};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc;
use std::sync::Arc;
use std::time::{Duration, Instant};

use crate::camera::model::CameraModel;
use crate::camera::{Camera, Frame};
use crate::dataset::{Dataset, Sample};
use crate::geometry::{Pose, PoseYaml};
use crate::robot::{Joints, MotionLimits, Robot};
use crate::solve::Setup;
use crate::target::{estimate_board_pose, Board, DetectorOptions, TagDetector};

use super::folder::{PoseVisit, SessionFolder};
use super::SessionError;

/// Everything the loop needs besides the hardware.
pub struct SessionSetup {
    /// Where records go (created or opened for resume).
    pub folder: SessionFolder,
    /// Eye-in-hand or eye-to-hand (written into samples.yaml).
    pub setup: Setup,
    /// The validated plan: target flange pose and the joint solution for each pose.
    pub plan: Vec<(Pose, Joints)>,
    /// Speed and acceleration caps for every move.
    pub limits: MotionLimits,
    /// Wait after each move before grabbing.
    pub settle: Duration,
    /// Frames whose board reprojection RMS exceeds this are rejected.
    pub max_reprojection_rms_px: f64,
    /// The board.
    pub board: Board,
    /// Detector settings.
    pub detector: DetectorOptions,
    /// Set (e.g. by Ctrl-C) to stop the arm after the current move and end the run cleanly.
    pub stop: Arc<AtomicBool>,
}

/// Something that happened, for progress displays.
#[derive(Debug, Clone)]
pub enum SessionEvent {
    /// The arm is moving to a plan pose.
    Moving {
        /// Plan index.
        plan_index: usize,
    },
    /// A pose was processed.
    Recorded {
        /// Plan index.
        plan_index: usize,
        /// Board RMS when accepted.
        reprojection_rms_px: Option<f64>,
        /// Tags used.
        tags: usize,
        /// Why it was rejected, if it was.
        rejected: Option<String>,
        /// Whether a retry will follow.
        will_retry: bool,
    },
}

/// How a completed session went.
#[derive(Debug, Clone, Default)]
pub struct SessionOutcome {
    /// Plan indices with an accepted sample, ascending.
    pub accepted: Vec<usize>,
    /// Plan indices skipped after a retry, with the reason.
    pub skipped: Vec<(usize, String)>,
    /// Poses visited in this run (not counting those recorded before a resume).
    pub visited_now: usize,
}

struct Job {
    plan_index: usize,
    frame: Frame,
    base_from_flange: Pose,
}

struct JobResult {
    plan_index: usize,
    visit: Result<PoseVisit, SessionError>,
}

/// Runs (or resumes) a session: visits every plan pose without an accepted record, retries a
/// pose whose board was not found once, and keeps every record on disk whatever happens. On a
/// robot fault, camera fault or stop request the arm is stopped and the error says how to resume.
pub fn run_session(
    setup: SessionSetup,
    robot: &mut dyn Robot,
    camera: &mut dyn Camera,
    on_event: &mut dyn FnMut(SessionEvent),
) -> Result<SessionOutcome, SessionError> {
    let previous = setup.folder.read_visits()?;
    let mut accepted: BTreeSet<usize> = BTreeSet::new();
    let mut failed_before: BTreeSet<usize> = BTreeSet::new();
    for visit in &previous {
        if visit.camera_from_target.is_some() {
            accepted.insert(visit.plan_index);
        } else {
            failed_before.insert(visit.plan_index);
        }
    }
    let mut pending: Vec<usize> = (0..setup.plan.len()).filter(|i| !accepted.contains(i)).collect();

    let (job_tx, job_rx) = mpsc::channel::<Job>();
    let (result_tx, result_rx) = mpsc::channel::<JobResult>();
    let worker = spawn_worker(&setup, camera.model().clone(), previous, job_rx, result_tx)?;

    let mut outcome = SessionOutcome::default();
    let mut attempts: BTreeMap<usize, usize> = failed_before.iter().map(|i| (*i, 1)).collect();
    let mut in_flight = 0usize;
    let mut run_error: Option<SessionError> = None;

    let mut handle = |result: JobResult,
                      pending_retries: &mut Vec<usize>,
                      outcome: &mut SessionOutcome,
                      attempts: &mut BTreeMap<usize, usize>,
                      run_error: &mut Option<SessionError>| {
        let i = result.plan_index;
        match result.visit {
            Ok(visit) => {
                let tries = attempts.entry(i).or_insert(0);
                *tries += 1;
                let will_retry = visit.rejected.is_some() && *tries < 2;
                if visit.rejected.is_none() {
                    outcome.accepted.push(i);
                } else if will_retry {
                    pending_retries.push(i);
                } else {
                    outcome.skipped.push((i, visit.rejected.clone().unwrap_or_default()));
                }
                on_event(SessionEvent::Recorded {
                    plan_index: i,
                    reprojection_rms_px: visit.reprojection_rms_px,
                    tags: visit.tags,
                    rejected: visit.rejected.clone(),
                    will_retry,
                });
            }
            Err(e) => {
                run_error.get_or_insert(e);
            }
        }
    };

    let recorded = |outcome: &SessionOutcome| accepted.len() + outcome.accepted.len() + outcome.skipped.len();
    'passes: while !pending.is_empty() {
        let mut retries = Vec::new();
        for &plan_index in &pending {
            if run_error.is_some() {
                break 'passes;
            }
            if setup.stop.load(Ordering::SeqCst) {
                let _ = robot.stop();
                run_error = Some(SessionError::Interrupted {
                    plan_index,
                    recorded: recorded(&outcome),
                    folder: setup.folder.root().to_path_buf(),
                });
                break 'passes;
            }
            on_event(SessionEvent::Moving { plan_index });
            let (_, joints) = &setup.plan[plan_index];
            let captured = robot
                .move_joints(joints, &setup.limits)
                .and_then(|()| {
                    std::thread::sleep(setup.settle);
                    Ok(Instant::now())
                })
                .map_err(|e| (true, e.into()))
                .and_then(|settled| {
                    camera.grab(settled).map_err(|e| (false, ErrorSource::Camera(e)))
                })
                .and_then(|frame| {
                    robot
                        .base_from_flange()
                        .map(|pose| (frame, pose))
                        .map_err(|e| (true, e.into()))
                });
            match captured {
                Ok((frame, base_from_flange)) => {
                    outcome.visited_now += 1;
                    in_flight += 1;
                    job_tx
                        .send(Job { plan_index, frame, base_from_flange })
                        .map_err(|_| SessionError::Detection("the detection thread stopped".into()))?;
                }
                Err((_, source)) => {
                    let _ = robot.stop();
                    // Let the worker finish what it has, so the count below is true.
                    while in_flight > 0 {
                        match result_rx.recv() {
                            Ok(r) => {
                                in_flight -= 1;
                                handle(r, &mut retries, &mut outcome, &mut attempts, &mut run_error);
                            }
                            Err(_) => break,
                        }
                    }
                    let folder = setup.folder.root().to_path_buf();
                    let recorded = recorded(&outcome);
                    run_error = Some(match source {
                        ErrorSource::Robot(source) => SessionError::Robot { plan_index, recorded, folder, source },
                        ErrorSource::Camera(source) => SessionError::Camera { plan_index, recorded, folder, source },
                    });
                    break 'passes;
                }
            }
            while let Ok(r) = result_rx.try_recv() {
                in_flight -= 1;
                handle(r, &mut retries, &mut outcome, &mut attempts, &mut run_error);
            }
        }
        // Every result must be in before deciding on retries.
        while in_flight > 0 {
            match result_rx.recv() {
                Ok(r) => {
                    in_flight -= 1;
                    handle(r, &mut retries, &mut outcome, &mut attempts, &mut run_error);
                }
                Err(_) => break,
            }
        }
        pending = retries;
    }
    drop(job_tx);
    while in_flight > 0 {
        match result_rx.recv() {
            Ok(r) => {
                in_flight -= 1;
                let mut ignored = Vec::new();
                handle(r, &mut ignored, &mut outcome, &mut attempts, &mut run_error);
            }
            Err(_) => break,
        }
    }
    let worker_result = worker.join();
    if let Some(e) = run_error {
        return Err(e);
    }
    if worker_result.is_err() {
        return Err(SessionError::Detection("the detection thread panicked".into()));
    }
    outcome.accepted.extend(accepted);
    outcome.accepted.sort_unstable();
    outcome.accepted.dedup();
    Ok(outcome)
}

enum ErrorSource {
    Robot(crate::robot::RobotError),
    Camera(crate::camera::CameraError),
}

impl From<crate::robot::RobotError> for ErrorSource {
    fn from(e: crate::robot::RobotError) -> Self {
        ErrorSource::Robot(e)
    }
}

fn spawn_worker(
    setup: &SessionSetup,
    camera_model: CameraModel,
    previous: Vec<PoseVisit>,
    jobs: mpsc::Receiver<Job>,
    results: mpsc::Sender<JobResult>,
) -> Result<std::thread::JoinHandle<()>, SessionError> {
    let detector = TagDetector::spawn(&setup.board, setup.detector.clone())
        .map_err(|e| SessionError::Detection(e.to_string()))?;
    let board = setup.board.clone();
    let folder = setup.folder.clone();
    let session_setup = setup.setup;
    let max_rms = setup.max_reprojection_rms_px;
    let mut samples: BTreeMap<usize, Sample> = previous
        .iter()
        .filter_map(|v| {
            let camera_from_target = v.camera_from_target.as_ref()?;
            Some((v.plan_index, sample_of(v.plan_index, &v.base_from_flange, camera_from_target)))
        })
        .collect();
    Ok(std::thread::Builder::new()
        .name("detection".into())
        .spawn(move || {
            for job in jobs {
                let visit = process(&job, &detector, &board, &camera_model, &folder, max_rms).and_then(|visit| {
                    if let Some(camera_from_target) = &visit.camera_from_target {
                        samples.insert(
                            visit.plan_index,
                            sample_of(visit.plan_index, &visit.base_from_flange, camera_from_target),
                        );
                        let dataset = Dataset { setup: session_setup, samples: samples.values().cloned().collect() };
                        dataset.save(&folder.samples_path()).map_err(|e| SessionError::Detection(e.to_string()))?;
                    }
                    Ok(visit)
                });
                if results.send(JobResult { plan_index: job.plan_index, visit }).is_err() {
                    return;
                }
            }
        })
        .expect("spawn the detection thread"))
}

fn sample_of(plan_index: usize, base_from_flange: &PoseYaml, camera_from_target: &PoseYaml) -> Sample {
    Sample {
        id: Some(format!("pose-{plan_index:03}")),
        weight: None,
        base_from_flange: base_from_flange.clone(),
        camera_from_target: camera_from_target.clone(),
    }
}

fn process(
    job: &Job,
    detector: &TagDetector,
    board: &Board,
    camera_model: &CameraModel,
    folder: &SessionFolder,
    max_rms: f64,
) -> Result<PoseVisit, SessionError> {
    let frame_name = SessionFolder::frame_name(job.plan_index);
    let mut png = Vec::new();
    job.frame
        .image
        .write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
        .map_err(|e| SessionError::Detection(format!("cannot encode frame {}: {e}", frame_name.display())))?;
    folder.write_file(&frame_name, &png)?;

    let visit = measure(
        detector,
        board,
        camera_model,
        &job.frame.image,
        max_rms,
        PoseVisit::new(job.plan_index, &job.base_from_flange, frame_name),
    );
    folder.write_visit(&visit)?;
    Ok(visit)
}

/// Detects the board in `image`, estimates its pose and fills the detection fields of `visit`
/// (a rejection reason instead of a pose when the board is missing or fits badly).
pub(crate) fn measure(
    detector: &TagDetector,
    board: &Board,
    camera_model: &CameraModel,
    image: &image::GrayImage,
    max_rms: f64,
    mut visit: PoseVisit,
) -> PoseVisit {
    match detector.detect(image) {
        Err(e) => visit.rejected = Some(e.to_string()),
        Ok(detection) => {
            visit.corners_px = detection
                .tags
                .iter()
                .flat_map(|t| t.corners_px.iter().enumerate().map(move |(k, c)| [t.id as f64, k as f64, c.x, c.y]))
                .collect();
            match estimate_board_pose(board, camera_model, &detection) {
                Err(e) => visit.rejected = Some(e.to_string()),
                Ok(board_pose) => {
                    visit.tags = board_pose.tags_used;
                    visit.reprojection_rms_px = Some(board_pose.rms_px);
                    if board_pose.rms_px > max_rms {
                        visit.rejected = Some(format!(
                            "board reprojection RMS {:.2} px exceeds {:.2} px",
                            board_pose.rms_px, max_rms
                        ));
                    } else {
                        visit.camera_from_target = Some(PoseYaml::from_pose(&board_pose.camera_from_target));
                    }
                }
            }
        }
    }
    visit
}
