//! The run loop: the arm and camera on the calling thread, detection and recording on worker
//! threads (one per core), so the vision work for pose i happens while the arm moves to pose i+1,
//! and frames that arrive faster than one core detects them (a recorded cell) use every core.
//!
//! Settling: after each move the loop waits the fixed `settle` time, then — when the setup asks
//! for it and the arm reports joint speeds — until every joint speed has stayed below a threshold
//! for a short window; the frame it then grabs was exposed no earlier than the start of that
//! quiet window (checked on the frame's `captured_at`), so no frame shows a ringing arm.
//!
//! Per pose the worker writes, in this order: the frame, the pose record (the commit point), then
//! `samples.yaml` (derived from the records). A run or resume first rebuilds `samples.yaml` from
//! the committed records, so a crash between any two writes loses nothing and doubles nothing.
//!
//! Test hook: the environment variable `HANDEYE_FAULT=<fault>:<plan index>` makes the worker
//! fail on purpose at that pose — `abort-after-frame`, `abort-after-record` and
//! `abort-after-samples` abort the process right after that write (as a crash would);
//! `full-disk-at-record` fails the record write as a full disk does. The crash-consistency
//! tests (`tests/it/crash.rs`) set it; it is not a user option and nothing else sets it.

use std::collections::{BTreeMap, BTreeSet};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc;
use std::sync::Arc;
use std::time::{Duration, Instant};

use crate::dataset::Dataset;
use crate::plan::check::MoveCheck;
use handeye_camera::{Camera, Frame};
use handeye_core::camera_model::CameraModel;
use handeye_core::geometry::Pose;
use handeye_core::setup::{PosePair, Setup};
use handeye_robot::{Joints, MotionLimits, Robot, RobotError, SettleBySpeed};
use handeye_vision::{estimate_board_pose, DetectorOptions, Target, TargetDetector};

use super::folder::{PoseVisit, SessionFolder};
use super::SessionError;

/// Everything the loop needs besides the hardware.
#[derive(Clone)]
pub struct SessionSetup {
    /// Where records go (created or opened for resume).
    pub folder: SessionFolder,
    /// Eye-in-hand or eye-to-hand (written into samples.yaml).
    pub setup: Setup,
    /// The validated plan: target flange pose and the joint solution for each pose.
    pub plan: Vec<(Pose, Joints)>,
    /// Speed and acceleration caps for every move.
    pub limits: MotionLimits,
    /// Wait after each move before grabbing (the minimum when `settle_by_speed` is given).
    pub settle: Duration,
    /// Settle by measurement: after `settle`, wait for the arm's joint speeds to stay low.
    /// `None`: the fixed wait only.
    pub settle_by_speed: Option<SettleBySpeed>,
    /// Frames whose board reprojection RMS exceeds this are rejected.
    pub max_reprojection_rms_px: f64,
    /// The board.
    pub board: Target,
    /// Detector settings.
    pub detector: DetectorOptions,
    /// Set (e.g. by Ctrl-C) to stop the arm — a move in progress decelerates where it is — and
    /// end the run cleanly.
    pub stop: Arc<AtomicBool>,
    /// The intrinsics are not known yet: record the detected corners only (no board pose, which
    /// needs intrinsics); they are estimated from all frames after the run.
    pub estimate_intrinsics: bool,
    /// Every move is checked from the arm's actual joints before it is sent (`None`: nothing
    /// moves, e.g. a recorded robot).
    pub move_check: Option<MoveCheck>,
    /// When a resumed run starts, visit the poses left in the order of least move time from
    /// where the arm stands (every move allowed by `move_check`), instead of plan order; `false`
    /// keeps plan order (a scripted order).
    pub reorder: bool,
}

/// How often the joint speeds are read while settling (a UR streams them at 500 Hz).
const SETTLE_POLL: Duration = Duration::from_millis(4);

/// Something that happened, for progress displays.
#[derive(Debug, Clone)]
pub enum SessionEvent {
    /// The arm is moving to a plan pose.
    Moving {
        /// Plan index.
        plan_index: usize,
        /// The flange pose it moves to (`T_base_flange`): what names the pose in
        /// `handeye plan check`'s listing, whatever the session's own numbering.
        target: Pose,
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
        /// The frame as taken (the one written to the session folder), shared without a copy,
        /// for live displays: they need not read it back from disk.
        frame: SharedFrame,
    },
}

/// A recorded frame shared without a copy; its `Debug` shows only its size.
#[derive(Clone)]
pub struct SharedFrame(pub Arc<image::GrayImage>);

impl std::fmt::Debug for SharedFrame {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "SharedFrame({}x{})", self.0.width(), self.0.height())
    }
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
    /// Arm time of this run spent in moves, s (wall time of the move calls).
    pub moving_s: f64,
    /// Arm time of this run spent settling after moves before the frame was exposed, s.
    pub settling_s: f64,
    /// What this run's checked moves take by the move-time model at the configured limits
    /// (what the plan check estimates), s: against `moving_modelled_s`, how the arm really
    /// moves compared with the model.
    pub modelled_moving_s: f64,
    /// The measured time of the same moves, s.
    pub moving_modelled_s: f64,
}

impl SessionOutcome {
    /// Arm time of this run: moving plus settling, s.
    pub fn arm_time_s(&self) -> f64 {
        self.moving_s + self.settling_s
    }
}

struct Job {
    plan_index: usize,
    frame: Frame,
    base_from_flange: Pose,
}

struct JobResult {
    plan_index: usize,
    visit: Result<PoseVisit, SessionError>,
    image: Arc<image::GrayImage>,
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
    if let Some(phantom) = previous.iter().find(|v| v.plan_index >= setup.plan.len()) {
        return Err(SessionError::Record {
            file: setup.folder.visit_path(phantom.plan_index),
            path: "plan_index".into(),
            message: format!(
                "{} is not a pose of the plan ({} poses)",
                phantom.plan_index,
                setup.plan.len()
            ),
        });
    }
    // The records are the log; samples.yaml is rebuilt from them before anything moves.
    let samples = rebuild_samples(&setup.folder, setup.setup, &previous)?;
    let mut accepted: BTreeSet<usize> = BTreeSet::new();
    let mut failed_before: BTreeSet<usize> = BTreeSet::new();
    for visit in &previous {
        let corners_only =
            setup.estimate_intrinsics && visit.rejected.is_none() && !visit.corners_px.is_empty();
        if visit.camera_from_target.is_some() || corners_only {
            accepted.insert(visit.plan_index);
        } else {
            failed_before.insert(visit.plan_index);
        }
    }
    let mut pending: Vec<usize> = (0..setup.plan.len())
        .filter(|i| !accepted.contains(i))
        .collect();

    // A stop request ends a move in progress, not only the run after it.
    robot.set_interrupt(setup.stop.clone());
    let (job_tx, job_rx) = mpsc::channel::<Job>();
    let (result_tx, result_rx) = mpsc::channel::<JobResult>();
    let camera_model = (!setup.estimate_intrinsics).then(|| *camera.model());
    let workers = spawn_workers(&setup, camera_model, samples, job_rx, result_tx)?;

    let mut state = RunState {
        outcome: SessionOutcome::default(),
        attempts: failed_before.iter().map(|i| (*i, 1)).collect(),
        retries: Vec::new(),
        in_flight: 0,
        submitted: Default::default(),
        arrived: BTreeMap::new(),
        error: None,
        recorded_before: accepted.len(),
        folder: setup.folder.root().to_path_buf(),
    };

    // A fresh plan runs in its (checked) order; what a resumed run has left is visited in travel
    // order from where the arm stands now. Retries follow each pass in plan order.
    if !(accepted.is_empty() && failed_before.is_empty()) {
        order_for_travel(robot, &setup, &mut pending);
    }
    'passes: while !pending.is_empty() {
        for &plan_index in &pending {
            if state.error.is_some() {
                break 'passes;
            }
            if setup.stop.load(Ordering::SeqCst) {
                let _ = robot.stop();
                state.drain(&result_rx, on_event);
                state.error = Some(SessionError::Interrupted {
                    plan_index,
                    recorded: state.recorded(),
                    folder: setup.folder.root().to_path_buf(),
                });
                break 'passes;
            }
            on_event(SessionEvent::Moving {
                plan_index,
                target: setup.plan[plan_index].0,
            });
            match capture(robot, camera, &setup, plan_index) {
                Ok((frame, base_from_flange, timing)) => {
                    state.outcome.visited_now += 1;
                    state.outcome.moving_s += timing.moving_s;
                    state.outcome.settling_s += timing.settling_s;
                    if let Some(modelled_s) = timing.modelled_s {
                        state.outcome.modelled_moving_s += modelled_s;
                        state.outcome.moving_modelled_s += timing.moving_s;
                    }
                    state.in_flight += 1;
                    state.submitted.push_back(plan_index);
                    job_tx
                        .send(Job {
                            plan_index,
                            frame,
                            base_from_flange,
                        })
                        .map_err(|_| SessionError::DetectionThread("stopped"))?;
                }
                Err(source) => {
                    // Stop first, then let the worker finish what it has so the count is true.
                    let _ = robot.stop();
                    state.drain(&result_rx, on_event);
                    let folder = setup.folder.root().to_path_buf();
                    let recorded = state.recorded();
                    state.error = Some(match source {
                        ErrorSource::Robot(RobotError::Interrupted) => SessionError::Interrupted {
                            plan_index,
                            recorded,
                            folder,
                        },
                        ErrorSource::Robot(source) => SessionError::Robot {
                            plan_index,
                            recorded,
                            folder,
                            source,
                        },
                        ErrorSource::UnsafeMove(problem) => SessionError::UnsafeMove {
                            plan_index,
                            recorded,
                            folder,
                            problem,
                        },
                        ErrorSource::Camera(source) => SessionError::Camera {
                            plan_index,
                            recorded,
                            folder,
                            source,
                        },
                    });
                    break 'passes;
                }
            }
            while let Ok(result) = result_rx.try_recv() {
                state.receive(result, on_event);
            }
        }
        // Every result of this pass must be in before deciding on retries.
        state.drain(&result_rx, on_event);
        pending = std::mem::take(&mut state.retries);
    }
    drop(job_tx);
    state.drain(&result_rx, on_event);
    let workers_panicked = workers.into_iter().any(|w| w.join().is_err());
    if let Some(e) = state.error {
        return Err(e);
    }
    if workers_panicked {
        return Err(SessionError::DetectionThread("panicked"));
    }
    let mut outcome = state.outcome;
    outcome.accepted.extend(accepted);
    outcome.accepted.sort_unstable();
    outcome.accepted.dedup();
    Ok(outcome)
}

/// Book-keeping of a run in progress.
struct RunState {
    outcome: SessionOutcome,
    attempts: BTreeMap<usize, usize>,
    retries: Vec<usize>,
    in_flight: usize,
    /// The poses handed to the workers, in the order they were (at most one job per pose is in
    /// flight: retries wait for the pass to drain).
    submitted: std::collections::VecDeque<usize>,
    /// Results that finished before an earlier pose's: held so events go out in visit order.
    arrived: BTreeMap<usize, JobResult>,
    error: Option<SessionError>,
    recorded_before: usize,
    folder: std::path::PathBuf,
}

impl RunState {
    fn recorded(&self) -> usize {
        self.recorded_before + self.outcome.accepted.len() + self.outcome.skipped.len()
    }

    /// Takes a worker's result; handles it, and any held behind it, in the order the poses were
    /// visited (the workers finish in any order).
    fn receive(&mut self, result: JobResult, on_event: &mut dyn FnMut(SessionEvent)) {
        self.arrived.insert(result.plan_index, result);
        while let Some(result) = self
            .submitted
            .front()
            .and_then(|next| self.arrived.remove(next))
        {
            self.submitted.pop_front();
            self.handle(result, on_event);
        }
    }

    fn handle(&mut self, result: JobResult, on_event: &mut dyn FnMut(SessionEvent)) {
        self.in_flight -= 1;
        let i = result.plan_index;
        let visit = match result.visit {
            Ok(visit) => visit,
            Err(e) => {
                // The pose was not committed (a full disk, say): the run stops with the hint.
                let recorded = self.recorded();
                self.error.get_or_insert(SessionError::RecordFailed {
                    plan_index: i,
                    recorded,
                    folder: self.folder.clone(),
                    source: Box::new(e),
                });
                return;
            }
        };
        let tries = self.attempts.entry(i).or_insert(0);
        *tries += 1;
        let will_retry = visit.rejected.is_some() && *tries < 2;
        match &visit.rejected {
            None => self.outcome.accepted.push(i),
            Some(_) if will_retry => self.retries.push(i),
            Some(why) => self.outcome.skipped.push((i, why.clone())),
        }
        on_event(SessionEvent::Recorded {
            plan_index: i,
            reprojection_rms_px: visit.reprojection_rms_px,
            tags: visit.tags,
            rejected: visit.rejected,
            will_retry,
            frame: SharedFrame(result.image),
        });
    }

    /// Waits for every job in flight.
    fn drain(
        &mut self,
        results: &mpsc::Receiver<JobResult>,
        on_event: &mut dyn FnMut(SessionEvent),
    ) {
        while self.in_flight > 0 {
            match results.recv() {
                Ok(result) => self.receive(result, on_event),
                Err(_) => break,
            }
        }
    }
}

/// Puts `pending` plan indices in the order of least move time from the arm's current joints
/// (each move allowed by the setup's move check), when the setup asks for it and the arm's
/// joints can be read; else leaves them as they are.
fn order_for_travel(robot: &mut dyn Robot, setup: &SessionSetup, pending: &mut Vec<usize>) {
    let Some(check) = setup.move_check.as_ref().filter(|_| setup.reorder) else {
        return;
    };
    if pending.len() < 2 {
        return;
    }
    let Ok(from) = robot.joint_positions() else {
        return;
    };
    let joints: Vec<Joints> = pending.iter().map(|&i| setup.plan[i].1).collect();
    let order = crate::plan::order::order_for_travel(&from, &joints, |a, b| {
        check.safe_move_time(a, b, &setup.limits)
    });
    *pending = order.iter().map(|&k| pending[k]).collect();
}

/// Where the arm time of one pose went, s.
struct PoseTiming {
    moving_s: f64,
    settling_s: f64,
    /// The move's time by the model at the configured limits, s (for a checked move).
    modelled_s: Option<f64>,
}

/// Move, settle, grab a fresh frame, read the measured flange pose.
fn capture(
    robot: &mut dyn Robot,
    camera: &mut dyn Camera,
    setup: &SessionSetup,
    plan_index: usize,
) -> Result<(Frame, Pose, PoseTiming), ErrorSource> {
    let (_, joints) = &setup.plan[plan_index];
    // A checked move knows where it starts: its time by the model is kept to compare with.
    let mut modelled_s = None;
    if let Some(check) = &setup.move_check {
        let from = robot.joint_positions()?;
        if let Some(problem) = check.problem(&from, joints) {
            return Err(ErrorSource::UnsafeMove(problem));
        }
        modelled_s = Some(setup.limits.joint_move_time(&from, joints));
    }
    let started = Instant::now();
    robot.move_joints(joints, &setup.limits)?;
    let arrived = Instant::now();
    std::thread::sleep(setup.settle);
    let settled = match &setup.settle_by_speed {
        Some(rule) => wait_until_still(robot, rule, arrived, &setup.stop)
            .map_err(|e| ErrorSource::Robot(e.into_robot_error(rule)))?,
        None => Instant::now(),
    };
    let mut frame = camera.grab(settled).map_err(ErrorSource::Camera)?;
    // A camera that hands out a frame exposed before the arm stood still breaks its contract;
    // never use such a frame (grab again, a few times).
    for _ in 0..3 {
        if frame.captured_at >= settled {
            break;
        }
        frame = camera.grab(settled).map_err(ErrorSource::Camera)?;
    }
    if frame.captured_at < settled {
        return Err(ErrorSource::Camera(handeye_camera::CameraError::Backend(
            "the camera returned only frames exposed before the arm stood still (its frames' exposure times are earlier than the time asked for)".into(),
        )));
    }
    let base_from_flange = robot.base_from_flange()?;
    let timing = PoseTiming {
        moving_s: arrived.duration_since(started).as_secs_f64(),
        settling_s: frame
            .captured_at
            .saturating_duration_since(arrived)
            .as_secs_f64(),
        modelled_s,
    };
    Ok((frame, base_from_flange, timing))
}

/// Why [`wait_until_still`] found no still arm.
pub(super) enum NotStill {
    /// The arm's own error, or [`RobotError::Interrupted`] when a stop was requested.
    Robot(RobotError),
    /// A joint still moved at `fastest` rad/s when the rule's timeout ran out.
    Moving {
        /// The fastest joint speed of the last reading above the threshold, rad/s.
        fastest: f64,
    },
}

impl NotStill {
    /// What the rule's numbers say about an arm that did not settle.
    pub(super) fn moving_message(fastest: f64, rule: &SettleBySpeed) -> String {
        format!(
            "a joint still moved at {:.2}°/s {:.1} s on (session.settle_speed_deg_s = {:.2}°/s for session.settle_window_s = {:.2} s)",
            fastest.to_degrees(),
            rule.timeout.as_secs_f64(),
            rule.max_joint_speed.to_degrees(),
            rule.window.as_secs_f64()
        )
    }

    /// As a robot error of a move that did not settle.
    fn into_robot_error(self, rule: &SettleBySpeed) -> RobotError {
        match self {
            NotStill::Robot(e) => e,
            NotStill::Moving { fastest } => RobotError::Backend(
                format!(
                    "the arm did not settle after the move: {}",
                    Self::moving_message(fastest, rule)
                )
                .into(),
            ),
        }
    }
}

/// Waits until every joint speed the arm reports has stayed below the rule's threshold for the
/// rule's window; returns the start of that quiet window (a frame exposed from then on shows the
/// arm at rest). Returns at once when the arm reports no speeds. Fails when the arm is still
/// moving `timeout` after `since` (the end of a move, or a hand-guided capture's request), or
/// when a stop is requested.
pub(super) fn wait_until_still(
    robot: &mut dyn Robot,
    rule: &SettleBySpeed,
    since: Instant,
    stop: &AtomicBool,
) -> Result<Instant, NotStill> {
    let mut quiet_since: Option<Instant> = None;
    let mut fastest = 0.0f64;
    loop {
        let Some(speeds) = robot.joint_speeds().map_err(NotStill::Robot)? else {
            return Ok(Instant::now());
        };
        // Taken after the reading: the reading shows the arm no later than this.
        let now = Instant::now();
        let top = speeds.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        if top.is_nan() || top >= rule.max_joint_speed {
            quiet_since = None;
            fastest = if top.is_nan() { f64::INFINITY } else { top };
        } else {
            let quiet = *quiet_since.get_or_insert(now);
            if now.duration_since(quiet) >= rule.window {
                return Ok(quiet);
            }
        }
        if stop.load(Ordering::SeqCst) {
            return Err(NotStill::Robot(RobotError::Interrupted));
        }
        if now.duration_since(since) > rule.timeout {
            return Err(NotStill::Moving { fastest });
        }
        std::thread::sleep(SETTLE_POLL);
    }
}

enum ErrorSource {
    Robot(RobotError),
    Camera(handeye_camera::CameraError),
    /// The move was refused before it was sent.
    UnsafeMove(String),
}

impl From<RobotError> for ErrorSource {
    fn from(e: RobotError) -> Self {
        ErrorSource::Robot(e)
    }
}

/// Rebuilds `samples.yaml` from the committed records `visits` (every accepted pose once, in
/// plan order; a sample without a record dropped) and returns the samples by plan index. Without
/// any accepted record a stale samples file is removed.
pub(crate) fn rebuild_samples(
    folder: &SessionFolder,
    setup: Setup,
    visits: &[PoseVisit],
) -> Result<BTreeMap<usize, PosePair>, SessionError> {
    let mut samples: BTreeMap<usize, PosePair> = BTreeMap::new();
    for visit in visits {
        if let Some(sample) = visit.sample() {
            samples.insert(visit.plan_index, sample);
        }
    }
    let path = folder.samples_path();
    if !samples.is_empty() {
        Dataset {
            setup,
            pairs: samples.values().cloned().collect(),
        }
        .save(&path)?;
    } else if path.is_file() {
        std::fs::remove_file(&path).map_err(|source| SessionError::Io { path, source })?;
    }
    Ok(samples)
}

/// The `HANDEYE_FAULT=<fault>:<plan index>` test hook (see the module docs): the fault and the
/// plan index it names, when the variable is set.
#[derive(Debug)]
struct Fault(Option<(String, usize)>);

impl Fault {
    fn from_env() -> Fault {
        let value = std::env::var("HANDEYE_FAULT").unwrap_or_default();
        Fault(
            value
                .split_once(':')
                .and_then(|(kind, index)| Some((kind.to_string(), index.parse().ok()?))),
        )
    }

    /// Whether the hook asks for `kind` at `plan_index`.
    fn at(&self, kind: &str, plan_index: usize) -> bool {
        matches!(&self.0, Some((k, i)) if k == kind && *i == plan_index)
    }

    /// Aborts the process (a crash: no destructor, no cleanup) when the hook asks for `kind` at
    /// `plan_index`.
    fn abort_at(&self, kind: &str, plan_index: usize) {
        if self.at(kind, plan_index) {
            std::process::abort();
        }
    }
}

/// Starts the detection workers: one per core (at most four), each with its own detector (the
/// AprilTag detector is single-threaded: frames are the unit of parallel work). A recorded cell
/// (a bag import, say) hands over frames faster than one core detects them.
///
/// Each pose is committed by the worker that measured it (frame, then record); `samples.yaml` is
/// rewritten under one lock after the sample is added, so each write holds every sample committed
/// before it, whichever worker finishes first.
fn spawn_workers(
    setup: &SessionSetup,
    camera_model: Option<CameraModel>,
    samples: BTreeMap<usize, PosePair>,
    jobs: mpsc::Receiver<Job>,
    results: mpsc::Sender<JobResult>,
) -> Result<Vec<std::thread::JoinHandle<()>>, SessionError> {
    let workers = std::thread::available_parallelism().map_or(1, |n| n.get().min(4));
    let jobs = Arc::new(std::sync::Mutex::new(jobs));
    let samples = Arc::new(std::sync::Mutex::new(samples));
    let fault = Arc::new(Fault::from_env());
    let mut handles = Vec::with_capacity(workers);
    for worker in 0..workers {
        let detector = TargetDetector::spawn(&setup.board, setup.detector.clone())
            .map_err(|e| SessionError::Detector(Box::new(e)))?;
        let board = setup.board.clone();
        let folder = setup.folder.clone();
        let session_setup = setup.setup;
        let max_rms = setup.max_reprojection_rms_px;
        let (jobs, samples, fault, results) = (
            jobs.clone(),
            samples.clone(),
            fault.clone(),
            results.clone(),
        );
        let handle = std::thread::Builder::new()
            .name(format!("detection-{worker}"))
            .spawn(move || loop {
                // The lock is held only to take the next job, not while measuring it.
                let next = jobs.lock().map(|jobs| jobs.recv());
                let Ok(Ok(job)) = next else {
                    return;
                };
                let visit = process(
                    &job,
                    &detector,
                    &board,
                    camera_model.as_ref(),
                    &folder,
                    max_rms,
                    &fault,
                )
                .and_then(|visit| {
                    if let Some(sample) = visit.sample() {
                        let Ok(mut samples) = samples.lock() else {
                            return Err(SessionError::DetectionThread("panicked"));
                        };
                        samples.insert(visit.plan_index, sample);
                        let dataset = Dataset {
                            setup: session_setup,
                            pairs: samples.values().cloned().collect(),
                        };
                        dataset.save(&folder.samples_path())?;
                        fault.abort_at("abort-after-samples", visit.plan_index);
                    }
                    Ok(visit)
                });
                if results
                    .send(JobResult {
                        plan_index: job.plan_index,
                        visit,
                        image: Arc::new(job.frame.image),
                    })
                    .is_err()
                {
                    return;
                }
            })
            .map_err(SessionError::DetectionThreadSpawn)?;
        handles.push(handle);
    }
    Ok(handles)
}

fn process(
    job: &Job,
    detector: &TargetDetector,
    board: &Target,
    camera_model: Option<&CameraModel>,
    folder: &SessionFolder,
    max_rms: f64,
    fault: &Fault,
) -> Result<PoseVisit, SessionError> {
    let frame_name = SessionFolder::frame_name(job.plan_index);
    let mut png = Vec::new();
    job.frame
        .image
        .write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
        .map_err(|source| SessionError::Frame {
            path: frame_name.clone(),
            source: Box::new(source),
        })?;
    folder.write_file(&frame_name, &png)?;
    fault.abort_at("abort-after-frame", job.plan_index);

    let visit = measure(
        detector,
        board,
        camera_model,
        &job.frame.image,
        max_rms,
        PoseVisit::new(job.plan_index, &job.base_from_flange, frame_name),
    );
    if fault.at("full-disk-at-record", job.plan_index) {
        return Err(SessionError::Io {
            path: folder.visit_path(job.plan_index),
            source: std::io::Error::new(
                std::io::ErrorKind::StorageFull,
                "no space left on device (injected by HANDEYE_FAULT)",
            ),
        });
    }
    folder.write_visit(&visit)?;
    fault.abort_at("abort-after-record", job.plan_index);
    Ok(visit)
}

/// Detects the board in `image`, estimates its pose and fills the detection fields of `visit`
/// (a rejection reason instead of a pose when the board is missing or fits badly). Without a
/// camera model (intrinsics still unknown) only the corners are recorded.
pub(crate) fn measure(
    detector: &TargetDetector,
    board: &Target,
    camera_model: Option<&CameraModel>,
    image: &image::GrayImage,
    max_rms: f64,
    mut visit: PoseVisit,
) -> PoseVisit {
    match detector.detect(image) {
        Err(e) => visit.rejected = Some(e.to_string()),
        Ok(detection) => {
            visit.corners_px = detection.observations();
            let Some(camera_model) = camera_model else {
                visit.tags = match board.aprilgrid() {
                    Some(grid) => detection
                        .tags
                        .iter()
                        .filter(|t| grid.tag(t.id).is_some())
                        .count(),
                    None => detection.points.len(),
                };
                if visit.tags == 0 {
                    visit.rejected = Some("no tag of the board detected".to_string());
                }
                return visit;
            };
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
                        visit.camera_from_target = Some(board_pose.camera_from_target);
                    }
                }
            }
        }
    }
    visit
}
