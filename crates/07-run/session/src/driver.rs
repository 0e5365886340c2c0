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
//! The same workers measure a recorded source's frames before its run ([`FrameRecorder`]: a bag
//! import's, as they are read), writing no `samples.yaml` meanwhile; the run then rebuilds it.
//!
//! Test hook: the environment variable `HANDEYE_FAULT=<fault>:<plan index>` makes the worker
//! fail on purpose at that pose — `abort-after-frame`, `abort-after-record` and
//! `abort-after-samples` abort the process right after that write (as a crash would);
//! `full-disk-at-record` fails the record write as a full disk does. The crash-consistency
//! tests (`tests/it/crash.rs`) set it; it is not a user option and nothing else sets it.
//! `camera-lost:<camera>:<plan index>` makes that camera's grab fail there, as an unplugged
//! camera does (`camera` is the camera of a one-camera cell; a several-camera cell's cameras by
//! their names).
//!
//! Several cameras (`SessionSetup::cameras`): one move and settle per pose, then every camera that
//! still needs the pose grabs; each camera's records go to its own folder, in the one-camera
//! layout, measured by the same workers.

use std::collections::{BTreeMap, BTreeSet};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc;
use std::sync::Arc;
use std::time::{Duration, Instant};

use serde::{Deserialize, Serialize};

use handeye_camera::{Camera, Frame};
use handeye_core::geometry::Pose;
use handeye_core::setup::Setup;
use handeye_plan::check::MoveCheck;
use handeye_robot::{Joints, MotionLimits, Robot, RobotError, SettleBySpeed};
use handeye_vision::{DetectorOptions, Target};

use handeye_records::folder::{PoseVisit, SessionFolder};
use handeye_records::SessionError;

mod record;
mod still;

pub(crate) use still::{wait_until_still, NotStill};

pub(crate) use record::{measure, rebuild_samples};
use record::{DetectionWorkers, Fault, Job, JobResult, Recording, SharedSamples};

/// One camera of a session: where its records go and what it measures.
#[derive(Clone)]
pub struct SessionCamera {
    /// Its name (`camera` for a config that does not name its cameras).
    pub name: String,
    /// Its folder, in the one-camera layout; the first camera's is the session's.
    pub folder: SessionFolder,
    /// Eye-in-hand or eye-to-hand (written into its samples.yaml).
    pub setup: Setup,
    /// The board it looks at.
    pub board: Target,
    /// Its intrinsics are not known yet: record the detected corners only (no board pose, which
    /// needs intrinsics); they are estimated from all frames after the run.
    pub estimate_intrinsics: bool,
}

/// Everything the loop needs besides the hardware.
#[derive(Clone)]
pub struct SessionSetup {
    /// The cameras, in the order the devices are passed: the first is the one the plan is made
    /// for (its folder is the session's); several cameras grab at the same poses.
    pub cameras: Vec<SessionCamera>,
    /// The folder a resume takes: the first camera's, or a several-camera session's root.
    pub resume_folder: std::path::PathBuf,
    /// Whether events name their camera (a config that lists its cameras).
    pub named_cameras: bool,
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
    /// Detector settings.
    pub detector: DetectorOptions,
    /// Set (e.g. by Ctrl-C) to stop the arm — a move in progress decelerates where it is — and
    /// end the run cleanly.
    pub stop: Arc<AtomicBool>,
    /// Every move is checked from the arm's actual joints before it is sent (`None`: nothing
    /// moves, e.g. a recorded robot).
    pub move_check: Option<MoveCheck>,
    /// When a resumed run starts, visit the poses left in the order of least move time from
    /// where the arm stands (every move allowed by `move_check`), instead of plan order; `false`
    /// keeps plan order (a scripted order).
    pub reorder: bool,
}

impl SessionSetup {
    /// The session's folder: the first camera's.
    pub fn folder(&self) -> &SessionFolder {
        &self.cameras[0].folder
    }
}

/// A camera that stopped delivering frames while others still did: a several-camera session's
/// `failures.yaml` lists them.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraFailure {
    /// The camera.
    pub camera: String,
    /// The plan pose of its failed grab.
    pub plan_index: usize,
    /// The camera's error.
    pub error: String,
}

/// `failures.yaml` of a several-camera session: the cameras that stopped delivering frames in
/// its last run (absent when none did).
pub fn root_failures(root: &std::path::Path) -> std::path::PathBuf {
    root.join("failures.yaml")
}

/// The cameras that stopped delivering frames in the session's last run.
pub fn read_failures(root: &std::path::Path) -> Vec<CameraFailure> {
    handeye_core::yaml_file::read_yaml(&root_failures(root)).unwrap_or_default()
}

/// Adds `failure` to the session's `failures.yaml` as it happens (a crash keeps it).
fn record_failure(root: &std::path::Path, failure: &CameraFailure) -> Result<(), SessionError> {
    let mut failures = read_failures(root);
    failures.push(failure.clone());
    Ok(handeye_core::yaml_file::write_yaml(
        &failures,
        &root_failures(root),
    )?)
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
        /// The camera, in a several-camera session.
        camera: Option<String>,
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
    /// A camera of a several-camera session stopped delivering frames; the others go on.
    CameraLost(CameraFailure),
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
    /// Cameras that stopped delivering frames in this run while others still did.
    pub failed_cameras: Vec<CameraFailure>,
    /// Per camera (in `SessionSetup::cameras`' order): plan indices with
    /// an accepted record, ascending.
    pub accepted_by_camera: Vec<Vec<usize>>,
}

impl SessionOutcome {
    /// Arm time of this run: moving plus settling, s.
    pub fn arm_time_s(&self) -> f64 {
        self.moving_s + self.settling_s
    }
}

/// Runs (or resumes) a session: visits every plan pose without an accepted record, retries a
/// pose whose board was not found once, and keeps every record on disk whatever happens. On a
/// robot fault, camera fault or stop request the arm is stopped and the error says how to resume.
///
/// `cameras` are the devices of `setup.cameras`, in the same order. At each pose the arm moves
/// and settles once, then every camera that still needs the pose grabs; each camera's frames are
/// measured and committed into its own folder. A pose is visited again (once) while some camera
/// has no accepted record of it. A camera that fails while another still delivers is named
/// (`SessionOutcome::failed_cameras`, [`SessionEvent::CameraLost`]), its records kept, and not
/// asked again in this run; when the last camera fails the run stops.
pub fn run_session(
    setup: SessionSetup,
    robot: &mut dyn Robot,
    cameras: &mut [&mut dyn Camera],
    on_event: &mut dyn FnMut(SessionEvent),
) -> Result<SessionOutcome, SessionError> {
    let mut run = PoseLoop::start(setup, cameras)?;
    run.visit_pending(robot, cameras, on_event)?;
    run.finish()
}

/// One run's pose loop, alive for the whole run: the records read once when it starts, the
/// detection workers started once, and the book-keeping of every pose. A fixed plan visits its
/// poses in one [`PoseLoop::visit_pending`]; a plan that grows one pose at a time (adaptive and
/// hand-guided runs) adds each pose with [`PoseLoop::set_plan`] and visits it the same way,
/// without re-reading the folder or restarting the workers per pose.
pub struct PoseLoop {
    setup: SessionSetup,
    recordings: Vec<Recording>,
    state: RunState,
    workers: DetectionWorkers,
    fault: Arc<Fault>,
    samples: Vec<SharedSamples>,
    /// Whether a pass has run: a resumed run's first pass visits what is left in travel order.
    passed: bool,
}

impl PoseLoop {
    /// Reads the records of every camera's folder (checked against `setup.plan`), rebuilds each
    /// `samples.yaml` from them before anything moves, and starts the detection workers.
    /// Nothing moves. `cameras` are the devices of `setup.cameras` (their models are read).
    pub fn start(
        setup: SessionSetup,
        cameras: &[&mut dyn Camera],
    ) -> Result<PoseLoop, SessionError> {
        let recordings = recordings(&setup, cameras)?;
        let state = RunState::new(&setup, &recordings)?;
        let mut samples = Vec::with_capacity(recordings.len());
        for (recording, visits) in recordings.iter().zip(&state.previous) {
            // The records are the log; samples.yaml is rebuilt from them before anything moves.
            let rebuilt = rebuild_samples(&recording.folder, recording.setup, visits)?;
            samples.push(Arc::new(std::sync::Mutex::new(rebuilt)));
        }
        let fault = Arc::new(Fault::from_env());
        let workers = DetectionWorkers::start(&recordings, Some(&samples), fault.clone(), None)?;
        Ok(PoseLoop {
            setup,
            recordings,
            state,
            workers,
            fault,
            samples,
            passed: false,
        })
    }

    /// The plan from now on: a growing plan's poses so far (the poses already visited keep
    /// their place and index).
    pub fn set_plan(&mut self, plan: Vec<(Pose, Joints)>) {
        self.setup.plan = plan;
    }

    /// Whether some camera has an accepted record of pose `plan_index`.
    pub fn accepted_by_any(&self, plan_index: usize) -> bool {
        self.state.accepted.iter().any(|a| a.contains(&plan_index))
    }

    /// A growing plan dropped its pose `plan_index` (no camera accepted it) and gives the index
    /// to its next pose: a camera's rejected record there counts as one measurement of the next
    /// pose (what a resume would read from the folder).
    pub fn forget(&mut self, plan_index: usize) {
        for c in 0..self.recordings.len() {
            self.state.accepted[c].remove(&plan_index);
            let key = (c, plan_index);
            if self.state.tries(c, plan_index) > 0 {
                self.state.attempts.insert(key, 1);
            } else {
                self.state.attempts.remove(&key);
            }
        }
        self.state.skipped_now.remove(&plan_index);
    }

    /// Camera `camera`'s accepted samples so far, in plan order (what its `samples.yaml` holds).
    pub fn samples(&self, camera: usize) -> Vec<handeye_core::setup::PosePair> {
        self.samples[camera]
            .lock()
            .map(|samples| samples.pairs().cloned().collect())
            .unwrap_or_default()
    }

    /// Visits every pose of the plan some camera still needs (a rejected one once more), until
    /// none is left or the run stops; every result is in when it returns. An error stops the
    /// arm first and keeps every record; the loop is not to be used after it.
    pub fn visit_pending(
        &mut self,
        robot: &mut dyn Robot,
        devices: &mut [&mut dyn Camera],
        on_event: &mut dyn FnMut(SessionEvent),
    ) -> Result<(), SessionError> {
        if devices.len() != self.recordings.len() {
            return Err(SessionError::DetectionThread(
                "the cameras opened do not match the session's",
            ));
        }
        // A stop request ends a move in progress, not only the run after it.
        robot.set_interrupt(self.setup.stop.clone());
        let mut pending = self.state.pending(self.setup.plan.len());
        // A fresh plan runs in its (checked) order; what a resumed run has left is visited in
        // travel order from where the arm stands now. Retries follow each pass in plan order.
        if !self.passed && self.state.resumed() {
            order_for_travel(robot, &self.setup, &mut pending);
        }
        self.passed = true;
        while !pending.is_empty() && self.state.error.is_none() {
            for &plan_index in &pending {
                if self.state.error.is_some() {
                    break;
                }
                self.visit(plan_index, robot, devices, on_event)?;
                self.state.receive_ready(
                    self.workers.results(),
                    2 * self.workers.count(),
                    on_event,
                );
            }
            // Every result of this pass must be in before deciding on retries.
            self.state.drain(self.workers.results(), on_event);
            pending = self.state.pending(self.setup.plan.len());
        }
        self.state.drain(self.workers.results(), on_event);
        match self.state.error.take() {
            Some(e) => Err(e),
            None => Ok(()),
        }
    }

    /// One visit of pose `plan_index` by the cameras that still need it: a stop request, a
    /// fault or a move refused on the way is put in the state (the arm stopped, the results
    /// in); only a worker that cannot be reached is an error here.
    fn visit(
        &mut self,
        plan_index: usize,
        robot: &mut dyn Robot,
        devices: &mut [&mut dyn Camera],
        on_event: &mut dyn FnMut(SessionEvent),
    ) -> Result<(), SessionError> {
        let (setup, state, recordings) = (&self.setup, &mut self.state, &self.recordings);
        let needed: Vec<usize> = (0..recordings.len())
            .filter(|&c| state.wants(c, plan_index))
            .collect();
        if needed.is_empty() {
            return Ok(());
        }
        if setup.stop.load(Ordering::SeqCst) {
            let _ = robot.stop();
            state.drain(self.workers.results(), on_event);
            state.error = Some(SessionError::Interrupted {
                plan_index,
                recorded: state.recorded(),
                folder: state.folder.clone(),
            });
            return Ok(());
        }
        on_event(SessionEvent::Moving {
            plan_index,
            target: setup.plan[plan_index].0,
        });
        let fault = &self.fault;
        let visited = arrive(robot, setup, plan_index).and_then(|arrival| {
            let mut frames = Vec::with_capacity(needed.len());
            for &c in &needed {
                let grabbed =
                    if fault.at(&format!("camera-lost:{}", recordings[c].name), plan_index) {
                        Err(handeye_camera::CameraError::Backend(
                            "no fresh frame (injected by HANDEYE_FAULT)".into(),
                        ))
                    } else {
                        grab_fresh(&mut *devices[c], arrival.settled)
                    };
                match grabbed {
                    Ok(frame) => frames.push((c, frame)),
                    // Another camera still delivers: this one is named and left out, and
                    // kept in the session's `failures.yaml` (a several-camera session's root).
                    Err(error) if state.delivering() > 1 => {
                        let failure = state.lose(c, plan_index, error.to_string(), on_event);
                        if let Err(e) = record_failure(&setup.resume_folder, &failure) {
                            tracing::warn!("failures.yaml could not be written: {e}");
                        }
                    }
                    Err(error) => return Err(ErrorSource::Camera(error)),
                }
            }
            let base_from_flange = robot.base_from_flange()?;
            Ok((arrival, frames, base_from_flange))
        });
        match visited {
            Ok((arrival, frames, base_from_flange)) => {
                state.count(&arrival, frames.first().map(|(_, f)| f.captured_at));
                for (camera, frame) in frames {
                    state.in_flight += 1;
                    state.submitted.push_back((plan_index, camera));
                    self.workers.send(Job {
                        camera,
                        plan_index,
                        frame,
                        base_from_flange,
                    })?;
                }
            }
            // A second visit whose path from where the arm now stands leaves the checked space
            // (the joint limits, the workspace box): nothing moved, the pose keeps its first
            // record, and the run goes on without it rather than ending with the samples it has
            // (issue #40: 8 good poses, then "resume" for a retry that could never be reached
            // from there).
            Err(ErrorSource::UnsafeMove(problem))
                if needed.iter().all(|&c| state.tries(c, plan_index) > 0) =>
            {
                for &c in &needed {
                    state.attempts.insert((c, plan_index), 2);
                }
                if needed.contains(&0) {
                    state.skip(
                        plan_index,
                        format!("not visited again: from where the arm stood {problem}"),
                    );
                }
            }
            Err(source) => {
                // Stop first, then let the worker finish what it has so the count is true.
                let _ = robot.stop();
                state.drain(self.workers.results(), on_event);
                state.error =
                    Some(source.into_session(plan_index, state.recorded(), state.folder.clone()));
            }
        }
        Ok(())
    }

    /// Ends the run: the workers finish what they hold and stop; what the run did.
    pub fn finish(mut self) -> Result<SessionOutcome, SessionError> {
        if self.stop_workers() {
            return Err(SessionError::DetectionThread("panicked"));
        }
        let state = &mut self.state;
        let mut outcome = std::mem::take(&mut state.outcome);
        outcome.accepted_by_camera = state
            .accepted
            .iter()
            .map(|poses| poses.iter().copied().collect())
            .collect();
        outcome.accepted = outcome.accepted_by_camera[0].clone();
        Ok(outcome)
    }

    /// Closes the job queue, takes every result in and joins the workers; whether one panicked.
    fn stop_workers(&mut self) -> bool {
        let state = &mut self.state;
        self.workers
            .stop(&mut |result| state.receive(result, &mut |_| {}))
    }
}

/// Frames of a recorded source measured while they are in memory, before the run that uses them:
/// a bag import, whose poses are known only as its frames are chosen, and whose plan is checked
/// when all of them are. Detection workers of the run's own kind (`record::DetectionWorkers`,
/// started once for the whole recording) measure each frame handed over and commit it as a run
/// commits a pose (its preview and its record; no `samples.yaml`, which the run rebuilds from the
/// records); the frame file is the caller's, written already. The run that follows in the same
/// folder finds every pose recorded: it neither reads nor decodes a frame again, and measures
/// again only a frame whose board was not found (every pose's second try). A frame waits for a
/// worker only while [`FrameRecorder::WAITING`] others do: the reader is held back when detection
/// falls behind, so the frames in memory stay few however many there are.
pub struct FrameRecorder {
    workers: DetectionWorkers,
    error: Option<SessionError>,
}

impl FrameRecorder {
    /// Frames handed over that may wait for a worker at once.
    pub const WAITING: usize = 2;

    /// Starts the detection workers of `camera` (its folder, board and setup), measuring with
    /// `detector` and judging by `max_rms` as the run's [`SessionSetup`] would; `model`: the
    /// camera's intrinsics (`None` when they are to be estimated: corners only); `frame_size`:
    /// its frames' size, px (what the workers' memory is counted at).
    pub fn start(
        camera: &SessionCamera,
        detector: DetectorOptions,
        max_rms: f64,
        model: Option<handeye_core::camera_model::CameraModel>,
        frame_size: (u32, u32),
    ) -> Result<FrameRecorder, SessionError> {
        let recording = Recording::new(camera, detector, max_rms, model.as_ref(), frame_size);
        let fault = Arc::new(Fault::from_env());
        // No `samples.yaml` meanwhile: the run rebuilds it from the records when it starts.
        let workers = DetectionWorkers::start(&[recording], None, fault, Some(Self::WAITING))?;
        Ok(FrameRecorder {
            workers,
            error: None,
        })
    }

    /// Hands over pose `plan_index`'s `frame`, taken with the flange at `base_from_flange` (as
    /// the recorded robot will serve it); waits while [`Self::WAITING`] frames wait. The first
    /// error a worker met (a record that could not be written) is returned here once it is in.
    pub fn record(
        &mut self,
        plan_index: usize,
        frame: Frame,
        base_from_flange: Pose,
    ) -> Result<(), SessionError> {
        while let Ok(result) = self.workers.results().try_recv() {
            keep_first_error(&mut self.error, result);
        }
        if let Some(error) = self.error.take() {
            return Err(error);
        }
        self.workers.send(Job {
            camera: 0,
            plan_index,
            frame,
            base_from_flange,
        })
    }

    /// Waits for every frame handed over to be committed, stops the workers; the first error
    /// met.
    pub fn finish(mut self) -> Result<(), SessionError> {
        let error = &mut self.error;
        if self
            .workers
            .stop(&mut |result| keep_first_error(error, result))
        {
            return Err(SessionError::DetectionThread("panicked"));
        }
        match self.error.take() {
            Some(error) => Err(error),
            None => Ok(()),
        }
    }
}

/// Keeps the first error a worker met.
fn keep_first_error(kept: &mut Option<SessionError>, result: JobResult) {
    if let (Err(error), None) = (result.visit, &kept) {
        *kept = Some(error);
    }
}

/// The run's cameras as recordings, in `setup.cameras`' order.
fn recordings(
    setup: &SessionSetup,
    devices: &[&mut dyn Camera],
) -> Result<Vec<Recording>, SessionError> {
    if setup.cameras.len() != devices.len() || devices.is_empty() {
        return Err(SessionError::DetectionThread(
            "the cameras opened do not match the session's",
        ));
    }
    Ok(setup
        .cameras
        .iter()
        .zip(devices)
        .map(|(camera, device)| {
            let lens = device.model();
            Recording::new(
                camera,
                setup.detector.clone(),
                setup.max_reprojection_rms_px,
                Some(lens),
                (lens.width, lens.height),
            )
        })
        .collect())
}

/// Book-keeping of a run in progress. Cameras are numbered as in [`recordings`]; the outcome's
/// accepted and skipped poses are the first camera's (the one the plan is made for).
struct RunState {
    outcome: SessionOutcome,
    /// Each camera's records from before this run.
    previous: Vec<Vec<PoseVisit>>,
    /// The first camera's poses skipped in this run and still in the plan (a growing plan
    /// gives a dropped pose's index to its next).
    skipped_now: BTreeSet<usize>,
    /// Each camera's poses with an accepted record.
    accepted: Vec<BTreeSet<usize>>,
    /// Measurements per (camera, pose), counting those of earlier runs.
    attempts: BTreeMap<(usize, usize), usize>,
    /// Cameras that stopped delivering in this run.
    lost: Vec<bool>,
    names: Vec<String>,
    in_flight: usize,
    /// The (pose, camera) jobs handed to the workers, in the order they were (at most one job
    /// per pose and camera is in flight: retries wait for the pass to drain).
    submitted: std::collections::VecDeque<(usize, usize)>,
    /// Results that finished before an earlier job's: held so events go out in visit order.
    arrived: BTreeMap<(usize, usize), JobResult>,
    error: Option<SessionError>,
    /// The folder a resume takes (a several-camera session's root).
    folder: std::path::PathBuf,
    /// Whether the cameras are named in events (several cameras).
    named: bool,
}

impl RunState {
    fn new(setup: &SessionSetup, recordings: &[Recording]) -> Result<RunState, SessionError> {
        let mut previous = Vec::with_capacity(recordings.len());
        let mut accepted = Vec::with_capacity(recordings.len());
        let mut attempts = BTreeMap::new();
        for (c, recording) in recordings.iter().enumerate() {
            let visits = recording.folder.read_visits()?;
            if let Some(phantom) = visits.iter().find(|v| v.plan_index >= setup.plan.len()) {
                return Err(SessionError::Record {
                    file: recording.folder.visit_path(phantom.plan_index),
                    path: "plan_index".into(),
                    message: format!(
                        "{} is not a pose of the plan ({} poses)",
                        phantom.plan_index,
                        setup.plan.len()
                    ),
                });
            }
            let mut ok = BTreeSet::new();
            for visit in &visits {
                let corners_only = recording.model.is_none()
                    && visit.rejected.is_none()
                    && !visit.corners_px.is_empty();
                if visit.camera_from_target.is_some() || corners_only {
                    ok.insert(visit.plan_index);
                } else {
                    attempts.insert((c, visit.plan_index), 1);
                }
            }
            previous.push(visits);
            accepted.push(ok);
        }
        Ok(RunState {
            outcome: SessionOutcome::default(),
            previous,
            skipped_now: BTreeSet::new(),
            accepted,
            attempts,
            lost: vec![false; recordings.len()],
            names: recordings.iter().map(|r| r.name.clone()).collect(),
            in_flight: 0,
            submitted: Default::default(),
            arrived: BTreeMap::new(),
            error: None,
            folder: setup.resume_folder.clone(),
            named: setup.named_cameras,
        })
    }

    /// Whether anything was recorded before this run.
    fn resumed(&self) -> bool {
        self.previous.iter().any(|v| !v.is_empty())
    }

    /// Whether camera `c` grabs at pose `i` when the arm is there: it delivers, has no accepted
    /// record of it, and was not measured there twice.
    fn wants(&self, c: usize, i: usize) -> bool {
        !self.lost[c] && !self.accepted[c].contains(&i) && self.tries(c, i) < 2
    }

    fn tries(&self, c: usize, i: usize) -> usize {
        self.attempts.get(&(c, i)).copied().unwrap_or(0)
    }

    /// The poses the arm still goes to, in plan order: those the first camera wants (a rejected
    /// pose once more, as with one camera), and those another camera has no record of. Another
    /// camera's rejection does not send the arm back: a fixed camera that cannot see its board
    /// from a pose would not see it the second time either; it grabs again whenever the arm is
    /// there anyway.
    fn pending(&self, poses: usize) -> Vec<usize> {
        (0..poses)
            .filter(|&i| {
                self.wants(0, i)
                    || (1..self.lost.len()).any(|c| self.wants(c, i) && self.tries(c, i) == 0)
            })
            .collect()
    }

    /// Cameras still delivering frames.
    fn delivering(&self) -> usize {
        self.lost.iter().filter(|lost| !**lost).count()
    }

    /// Camera `c` failed to grab at pose `plan_index`: named, and not asked again in this run.
    fn lose(
        &mut self,
        c: usize,
        plan_index: usize,
        error: String,
        on_event: &mut dyn FnMut(SessionEvent),
    ) -> CameraFailure {
        self.lost[c] = true;
        let failure = CameraFailure {
            camera: self.names[c].clone(),
            plan_index,
            error,
        };
        on_event(SessionEvent::CameraLost(failure.clone()));
        self.outcome.failed_cameras.push(failure.clone());
        failure
    }

    /// Adds one visit's arm time (settling up to the first frame's exposure).
    fn count(&mut self, arrival: &Arrival, exposed: Option<Instant>) {
        let outcome = &mut self.outcome;
        outcome.visited_now += 1;
        outcome.moving_s += arrival.moving_s;
        outcome.settling_s += exposed
            .unwrap_or(arrival.settled)
            .saturating_duration_since(arrival.arrived)
            .as_secs_f64();
        if let Some(modelled_s) = arrival.modelled_s {
            outcome.modelled_moving_s += modelled_s;
            outcome.moving_modelled_s += arrival.moving_s;
        }
    }

    /// Poses of the first camera with a final record: accepted (in any run), or skipped in
    /// this one.
    fn recorded(&self) -> usize {
        self.accepted[0].len() + self.skipped_now.len()
    }

    /// The first camera's pose `plan_index` is skipped, for `why`.
    fn skip(&mut self, plan_index: usize, why: String) {
        self.skipped_now.insert(plan_index);
        self.outcome.skipped.push((plan_index, why));
    }

    /// Takes a worker's result; handles it, and any held behind it, in the order the jobs were
    /// handed out (the workers finish in any order).
    fn receive(&mut self, result: JobResult, on_event: &mut dyn FnMut(SessionEvent)) {
        self.arrived
            .insert((result.plan_index, result.camera), result);
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
        let (c, i) = (result.camera, result.plan_index);
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
        let tries = self.attempts.entry((c, i)).or_insert(0);
        *tries += 1;
        let will_retry = visit.rejected.is_some() && *tries < 2;
        if visit.rejected.is_none() {
            self.accepted[c].insert(i);
        }
        if c == 0 {
            match &visit.rejected {
                None => self.outcome.accepted.push(i),
                Some(_) if will_retry => {}
                Some(why) => self.skip(i, why.clone()),
            }
        }
        on_event(SessionEvent::Recorded {
            plan_index: i,
            camera: self.named.then(|| self.names[c].clone()),
            reprojection_rms_px: visit.reprojection_rms_px,
            tags: visit.tags,
            rejected: visit.rejected,
            will_retry,
            frame: SharedFrame(result.image),
        });
    }

    /// Takes the results that are in, then waits for more while over `most_in_flight` jobs are
    /// in flight: a few frames per detection worker, as a camera that serves faster than the
    /// board is detected (a recorded cell's folder camera serves at once) would otherwise queue
    /// every frame of the plan in memory (issue #43).
    fn receive_ready(
        &mut self,
        results: &mpsc::Receiver<JobResult>,
        most_in_flight: usize,
        on_event: &mut dyn FnMut(SessionEvent),
    ) {
        while let Ok(result) = results.try_recv() {
            self.receive(result, on_event);
        }
        while self.in_flight > most_in_flight {
            match results.recv() {
                Ok(result) => self.receive(result, on_event),
                Err(_) => break,
            }
        }
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
    let order = handeye_plan::order::order_for_travel(&from, &joints, |a, b| {
        check.safe_move_time(a, b, &setup.limits)
    });
    *pending = order.iter().map(|&k| pending[k]).collect();
}

/// The arm at a pose, settled: when it arrived and stood still, and what the move took.
struct Arrival {
    arrived: Instant,
    settled: Instant,
    moving_s: f64,
    /// The move's time by the model at the configured limits, s (for a checked move).
    modelled_s: Option<f64>,
}

/// Move (checked from where the arm stands) and settle.
fn arrive(
    robot: &mut dyn Robot,
    setup: &SessionSetup,
    plan_index: usize,
) -> Result<Arrival, ErrorSource> {
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
    Ok(Arrival {
        arrived,
        settled,
        moving_s: arrived.duration_since(started).as_secs_f64(),
        modelled_s,
    })
}

/// Grabs a frame exposed no earlier than `settled`.
fn grab_fresh(
    camera: &mut dyn Camera,
    settled: Instant,
) -> Result<Frame, handeye_camera::CameraError> {
    let mut frame = camera.grab(settled)?;
    // A camera that hands out a frame exposed before the arm stood still breaks its contract;
    // never use such a frame (grab again, a few times).
    for _ in 0..3 {
        if frame.captured_at >= settled {
            break;
        }
        frame = camera.grab(settled)?;
    }
    if frame.captured_at < settled {
        return Err(handeye_camera::CameraError::Backend(
            "the camera returned only frames exposed before the arm stood still (its frames' exposure times are earlier than the time asked for)".into(),
        ));
    }
    Ok(frame)
}

enum ErrorSource {
    Robot(RobotError),
    Camera(handeye_camera::CameraError),
    /// The move was refused before it was sent.
    UnsafeMove(String),
}

impl ErrorSource {
    /// The run's error at `plan_index` with `recorded` poses kept in `folder`.
    fn into_session(
        self,
        plan_index: usize,
        recorded: usize,
        folder: std::path::PathBuf,
    ) -> SessionError {
        match self {
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
        }
    }
}

impl From<RobotError> for ErrorSource {
    fn from(e: RobotError) -> Self {
        ErrorSource::Robot(e)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use handeye_camera::PngFile;
    use handeye_vision::{annotate, Board, TagFamily};
    use image::{GrayImage, Luma};

    /// The file's inode number: a file replaced (written to a temporary file and renamed over
    /// it) has another.
    fn inode(path: &std::path::Path) -> u64 {
        std::os::unix::fs::MetadataExt::ino(&std::fs::metadata(path).unwrap())
    }

    /// A recorded source's frames are committed as a run commits its poses: each frame handed
    /// over gets its record, those among the first [`annotate::MAX_FRAMES_SHOWN`] (as many as a
    /// page shows) their preview, and the frame file stays the one the caller wrote.
    #[test]
    fn the_recorder_commits_each_frame_and_previews_as_many_as_a_page_shows() {
        let dir = tempfile::tempdir().unwrap();
        let folder = SessionFolder::create(dir.path()).unwrap();
        let board = Board::aprilgrid(6, 6, 0.04, 0.25, TagFamily::Tag36h11, 0, 1).unwrap();
        let camera = SessionCamera {
            name: "camera".into(),
            folder: folder.clone(),
            setup: Setup::EyeInHand,
            board: Target::Aprilgrid(board),
            estimate_intrinsics: true,
        };
        let size = (64, 48);
        let mut recorder =
            FrameRecorder::start(&camera, DetectorOptions::default(), 1.0, None, size).unwrap();
        let last = annotate::MAX_FRAMES_SHOWN;
        let poses = [0, last - 1, last];
        let mut written = Vec::new();
        for plan_index in poses {
            let image = GrayImage::from_pixel(size.0, size.1, Luma([200]));
            let mut png = Vec::new();
            image
                .write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
                .unwrap();
            let path = folder.root().join(SessionFolder::frame_name(plan_index));
            std::fs::write(&path, &png).unwrap();
            written.push(inode(&path));
            let frame = Frame {
                image,
                captured_at: Instant::now(),
                png: Some(PngFile { path, bytes: png }),
            };
            recorder
                .record(plan_index, frame, Pose::identity())
                .unwrap();
        }
        recorder.finish().unwrap();
        let visits = folder.read_visits().unwrap();
        assert_eq!(
            visits.iter().map(|v| v.plan_index).collect::<Vec<_>>(),
            poses
        );
        // A blank frame: measured, and rejected for want of a board.
        assert!(visits.iter().all(|v| v.rejected.is_some()), "{visits:?}");
        for (plan_index, file) in poses.into_iter().zip(written) {
            let frame = SessionFolder::frame_name(plan_index);
            // Written once, by the caller: not replaced by a copy of the same bytes.
            assert_eq!(
                inode(&folder.root().join(&frame)),
                file,
                "{}",
                frame.display()
            );
            let preview = SessionFolder::preview_of(&frame).unwrap();
            assert_eq!(
                folder.root().join(&preview).is_file(),
                plan_index < last,
                "{}",
                preview.display()
            );
        }
    }
}
