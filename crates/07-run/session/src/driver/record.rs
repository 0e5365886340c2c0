//! The recording side of the run loop: the detection workers that measure each frame and commit
//! it (frame, record, `samples.yaml`) into its camera's folder, and the `HANDEYE_FAULT` test hook.

use std::path::Path;
use std::sync::mpsc;
use std::sync::{Arc, Mutex};

use handeye_camera::Frame;
use handeye_core::camera_model::CameraModel;
use handeye_core::geometry::Pose;
use handeye_core::memory;
use handeye_core::setup::Setup;
use handeye_records::dataset::SamplesLog;
use handeye_vision::{annotate, estimate_board_pose, DetectorOptions, Target, TargetDetector};

use handeye_records::folder::{PoseVisit, SessionFolder};
use handeye_records::SessionError;

/// One camera's recording: where its records go and how its frames are measured. The run's
/// cameras are numbered by their place in the run (0: the setup's own camera).
#[derive(Clone)]
pub(super) struct Recording {
    /// Its name in messages (`camera` for a one-camera cell).
    pub name: String,
    pub folder: SessionFolder,
    pub setup: Setup,
    pub board: Target,
    pub detector: DetectorOptions,
    pub max_rms: f64,
    /// `None` while the intrinsics are unknown: corners only.
    pub model: Option<CameraModel>,
    /// The camera's frame size, px (what its detectors' memory is counted at).
    pub frame_size: (u32, u32),
}

impl Recording {
    /// `camera`'s recording, measured with `detector` and judged by `max_rms`: with the
    /// intrinsics of `lens` unless they are to be estimated (then corners only), its frames
    /// `frame_size` px.
    pub(super) fn new(
        camera: &super::SessionCamera,
        detector: DetectorOptions,
        max_rms: f64,
        lens: Option<&CameraModel>,
        frame_size: (u32, u32),
    ) -> Recording {
        Recording {
            name: camera.name.clone(),
            folder: camera.folder.clone(),
            setup: camera.setup,
            board: camera.board.clone(),
            detector,
            max_rms,
            model: lens.filter(|_| !camera.estimate_intrinsics).copied(),
            frame_size,
        }
    }
}

pub(super) struct Job {
    pub camera: usize,
    pub plan_index: usize,
    pub frame: Frame,
    pub base_from_flange: Pose,
}

pub(super) struct JobResult {
    pub camera: usize,
    pub plan_index: usize,
    pub visit: Result<PoseVisit, SessionError>,
    pub image: Arc<image::GrayImage>,
}

/// Rebuilds `samples.yaml` from the committed records `visits` (every accepted pose once, in
/// plan order; a sample without a record dropped) and returns the samples by plan index. Without
/// any accepted record a stale samples file is removed.
pub(crate) fn rebuild_samples(
    folder: &SessionFolder,
    setup: Setup,
    visits: &[PoseVisit],
) -> Result<SamplesLog, SessionError> {
    let path = folder.samples_path();
    let mut samples = SamplesLog::new(setup);
    for visit in visits {
        if let Some(sample) = visit.sample() {
            samples.insert(visit.plan_index, sample, &path)?;
        }
    }
    if !samples.is_empty() {
        samples.save(&path)?;
    } else if path.is_file() {
        std::fs::remove_file(&path).map_err(|source| SessionError::Io { path, source })?;
    }
    Ok(samples)
}

/// The `HANDEYE_FAULT=<fault>:<plan index>` test hook (see the module docs): the fault and the
/// plan index it names, when the variable is set. The fault may itself hold a `:`
/// (`camera-lost:<camera>`): the plan index is what follows the last one.
#[derive(Debug)]
pub(super) struct Fault(Option<(String, usize)>);

impl Fault {
    pub(super) fn from_env() -> Fault {
        let value = std::env::var("HANDEYE_FAULT").unwrap_or_default();
        Fault(
            value
                .rsplit_once(':')
                .and_then(|(kind, index)| Some((kind.to_string(), index.parse().ok()?))),
        )
    }

    /// Whether the hook asks for `kind` at `plan_index`.
    pub(super) fn at(&self, kind: &str, plan_index: usize) -> bool {
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

/// One camera's accepted samples by plan index, as the workers add them (shared by the workers
/// and the run, which reads them without going back to disk).
pub(super) type SharedSamples = Arc<Mutex<SamplesLog>>;

/// One camera as a worker holds it: its recording, its own detector, and its samples so far
/// (`None`: its `samples.yaml` is left to the run that follows, which rebuilds it from the
/// records).
struct WorkerCamera {
    recording: Recording,
    detector: TargetDetector,
    samples: Option<SharedSamples>,
}

/// Memory the run needs besides its detection workers and what it holds already when they start
/// (the camera, the renderer of a simulated one, the plan): the solve over every corner, the
/// report (frames annotated and encoded), a camera's frames in flight. Counted with the workers
/// before they start, so a limit too small for the run ends it there, with the figures. Measured
/// (issue #44): the simulated cell's run of 20 poses under `ulimit -v` holds 88-113 MB of address
/// space when its workers start and peaks near 110 MB with one detector thread; 32 MB more than
/// that and the workers' own estimate leave a margin for larger reports and other cameras.
const RUN_BESIDES_DETECTION_BYTES: u64 = 32 << 20;

/// How many detection workers to start: `-j` (the detector options' `jobs`) or one per core (at
/// most four), as many as the memory limits leave room for. Fewer than asked for with `-j` is
/// refused with the figures; fewer than the default is said and taken.
fn worker_count(cameras: &[Recording]) -> Result<usize, SessionError> {
    handeye_vision::detect::fit_allocator_to_limits();
    let asked = cameras.first().and_then(|c| c.detector.jobs);
    let wanted =
        asked.unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get().min(4)));
    // Each worker: a detector per camera, the frame it measures and its PNG.
    let each: u64 = cameras
        .iter()
        .map(|c| {
            let (width, height) = c.frame_size;
            TargetDetector::memory_needed(&c.board, &c.detector, width, height)
                + 2 * u64::from(width) * u64::from(height)
        })
        .sum();
    let (width, height) = cameras.first().map_or((0, 0), |c| c.frame_size);
    let what = |n: usize| format!("the run with {n} detector thread(s) at {width}x{height}");
    let fit = memory::how_many_fit(what, RUN_BESIDES_DETECTION_BYTES, each, wanted)
        .map_err(|e| SessionError::Detector(Box::new(e.into())))?;
    if fit < wanted {
        if asked.is_some() {
            let error = memory::check(
                &what(wanted),
                RUN_BESIDES_DETECTION_BYTES + each * wanted as u64,
                &format!(" or use `-j {fit}`"),
            )
            .err()
            .map(|e| SessionError::Detector(Box::new(e.into())));
            if let Some(error) = error {
                return Err(error);
            }
        }
        // Once a process: a bag import starts workers for its recorder, then for its run.
        static SAID: std::sync::Once = std::sync::Once::new();
        SAID.call_once(|| {
            tracing::warn!(
                "{fit} detector thread(s) instead of {wanted}: the memory limit leaves room for {fit} ({} MB each)",
                each.div_ceil(memory::MB)
            );
        });
    }
    Ok(fit)
}

/// The detection workers of a run or of a [`super::FrameRecorder`], started once: the queue of
/// frames they measure, their results, their threads ([`worker_count`] of them, each with its
/// own detector for every camera: the AprilTag detector is single-threaded, frames are the unit
/// of parallel work). A recorded cell (a bag import, say) hands over frames faster than one core
/// detects them.
///
/// Each pose is committed by the worker that measured it (frame, then record); with `samples`
/// (one per camera), a camera's `samples.yaml` is rewritten under its lock after the sample is
/// added, so each write holds every sample committed before it, whichever worker finishes first.
/// Dropped, they finish what they hold (every record committed stays) and stop.
pub(super) struct DetectionWorkers {
    jobs: Option<JobQueue>,
    results: mpsc::Receiver<JobResult>,
    threads: Vec<std::thread::JoinHandle<()>>,
}

/// Where frames wait for a worker: as many as the run hands over (it bounds the frames in
/// flight itself, by results), or at most a few (a recorder, whose caller would otherwise read
/// ahead without bound).
enum JobQueue {
    Open(mpsc::Sender<Job>),
    Bounded(mpsc::SyncSender<Job>),
}

impl DetectionWorkers {
    /// Starts the workers of `cameras`; `waiting`: at most that many frames wait for a worker
    /// (a [`Self::send`] waits meanwhile), `None` for no bound.
    pub(super) fn start(
        cameras: &[Recording],
        samples: Option<&[SharedSamples]>,
        fault: Arc<Fault>,
        waiting: Option<usize>,
    ) -> Result<DetectionWorkers, SessionError> {
        let (jobs, job_rx) = match waiting {
            Some(bound) => {
                let (tx, rx) = mpsc::sync_channel::<Job>(bound);
                (JobQueue::Bounded(tx), rx)
            }
            None => {
                let (tx, rx) = mpsc::channel::<Job>();
                (JobQueue::Open(tx), rx)
            }
        };
        let (result_tx, results) = mpsc::channel::<JobResult>();
        let threads = spawn(cameras, samples, fault, job_rx, result_tx)?;
        Ok(DetectionWorkers {
            jobs: Some(jobs),
            results,
            threads,
        })
    }

    /// Hands `job` to the workers.
    pub(super) fn send(&self, job: Job) -> Result<(), SessionError> {
        let stopped = |_| SessionError::DetectionThread("stopped");
        match &self.jobs {
            Some(JobQueue::Open(jobs)) => jobs.send(job).map_err(stopped),
            Some(JobQueue::Bounded(jobs)) => jobs.send(job).map_err(stopped),
            None => Err(SessionError::DetectionThread("stopped")),
        }
    }

    /// The workers' results, one per job, in the order they finish.
    pub(super) fn results(&self) -> &mpsc::Receiver<JobResult> {
        &self.results
    }

    /// How many workers measure.
    pub(super) fn count(&self) -> usize {
        self.threads.len()
    }

    /// Closes the queue, hands `receive` every result still to come and joins the workers;
    /// whether one panicked.
    pub(super) fn stop(&mut self, receive: &mut dyn FnMut(JobResult)) -> bool {
        self.jobs = None;
        while let Ok(result) = self.results.recv() {
            receive(result);
        }
        std::mem::take(&mut self.threads)
            .into_iter()
            .any(|worker| worker.join().is_err())
    }
}

impl Drop for DetectionWorkers {
    /// A run or an import that ends by an error still lets the workers finish what they hold.
    fn drop(&mut self) {
        self.stop(&mut |_| {});
    }
}

/// Starts [`DetectionWorkers`]' threads.
fn spawn(
    cameras: &[Recording],
    samples: Option<&[SharedSamples]>,
    fault: Arc<Fault>,
    jobs: mpsc::Receiver<Job>,
    results: mpsc::Sender<JobResult>,
) -> Result<Vec<std::thread::JoinHandle<()>>, SessionError> {
    let workers = worker_count(cameras)?;
    let jobs = Arc::new(Mutex::new(jobs));
    let mut handles = Vec::with_capacity(workers);
    for worker in 0..workers {
        let held = cameras
            .iter()
            .enumerate()
            .map(|(c, recording)| {
                Ok(WorkerCamera {
                    detector: TargetDetector::spawn(&recording.board, recording.detector.clone())
                        .map_err(|e| SessionError::Detector(Box::new(e)))?,
                    recording: recording.clone(),
                    samples: samples.and_then(|samples| samples.get(c)).cloned(),
                })
            })
            .collect::<Result<Vec<_>, SessionError>>()?;
        let (jobs, fault, results) = (jobs.clone(), fault.clone(), results.clone());
        let handle = std::thread::Builder::new()
            .name(format!("detection-{worker}"))
            .spawn(move || loop {
                // The lock is held only to take the next job, not while measuring it.
                let next = jobs.lock().map(|jobs| jobs.recv());
                let Ok(Ok(job)) = next else {
                    return;
                };
                let camera = &held[job.camera];
                let visit = process(&job, camera, &fault).and_then(|visit| {
                    if let (Some(sample), Some(samples)) = (visit.sample(), &camera.samples) {
                        let Ok(mut samples) = samples.lock() else {
                            return Err(SessionError::DetectionThread("panicked"));
                        };
                        let path = camera.recording.folder.samples_path();
                        samples.insert(visit.plan_index, sample, &path)?;
                        samples.save(&path)?;
                        fault.abort_at("abort-after-samples", visit.plan_index);
                    }
                    Ok(visit)
                });
                if results
                    .send(JobResult {
                        camera: job.camera,
                        plan_index: job.plan_index,
                        visit,
                        image: Arc::new(job.frame.image),
                    })
                    .is_err()
                {
                    return;
                }
            })
            .map_err(|error| {
                SessionError::DetectionThreadSpawn(memory::thread_start_error(
                    "a detection thread",
                    &error,
                ))
            })?;
        handles.push(handle);
    }
    Ok(handles)
}

fn process(job: &Job, camera: &WorkerCamera, fault: &Fault) -> Result<PoseVisit, SessionError> {
    let recording = &camera.recording;
    let folder = &recording.folder;
    let frame_name = SessionFolder::frame_name(job.plan_index);
    // A recorded grey PNG (an image folder) is stored as it was read: the same pixels, not
    // encoded a second time. A frame that already is this pose's frame file (a bag's chosen
    // frames, written into `frames/` by its import) stays as it is: written once.
    match &job.frame.png {
        Some(png) if is_same_file(&png.path, &folder.root().join(&frame_name)) => {}
        Some(png) => folder.write_file(&frame_name, &png.bytes)?,
        None => {
            let mut png = Vec::new();
            job.frame
                .image
                .write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
                .map_err(|source| SessionError::Frame {
                    path: frame_name.clone(),
                    source: Box::new(source),
                })?;
            folder.write_file(&frame_name, &png)?;
        }
    }
    // The frame as the report will show it, made while it is decoded (the report then reads
    // this small file, not the frame), for as many frames as a page shows. A frame it cannot be
    // made of (no pixels) is the detection's to report; a page draws a frame without a preview
    // from the frame itself.
    if job.plan_index < annotate::MAX_FRAMES_SHOWN {
        let made = annotate::preview(
            &job.frame.image,
            annotate::PREVIEW_WIDTH,
            annotate::PREVIEW_QUALITY,
        );
        if let Ok(preview) = made {
            folder.write_preview(&frame_name, &preview.jpeg)?;
        }
    }
    fault.abort_at("abort-after-frame", job.plan_index);

    let visit = measure(
        &camera.detector,
        &recording.board,
        recording.model.as_ref(),
        &job.frame.image,
        recording.max_rms,
        PoseVisit::new(job.plan_index, &job.base_from_flange, frame_name),
    )?;
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

/// Whether two paths name one file (both exist and resolve to the same place).
fn is_same_file(a: &Path, b: &Path) -> bool {
    match (std::fs::canonicalize(a), std::fs::canonicalize(b)) {
        (Ok(a), Ok(b)) => a == b,
        _ => false,
    }
}

/// Detects the board in `image`, estimates its pose and fills the detection fields of `visit`
/// (a rejection reason instead of a pose when the board is missing or fits badly). Without a
/// camera model (intrinsics still unknown) only the corners are recorded. A detector short of
/// memory is the error, not a rejection: the pose was not measured, and a resume measures it.
pub(crate) fn measure(
    detector: &TargetDetector,
    board: &Target,
    camera_model: Option<&CameraModel>,
    image: &image::GrayImage,
    max_rms: f64,
    mut visit: PoseVisit,
) -> Result<PoseVisit, SessionError> {
    match detector.detect(image) {
        Err(e @ handeye_vision::TargetError::Memory(_)) => {
            return Err(SessionError::Detector(Box::new(e)))
        }
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
                return Ok(visit);
            };
            match estimate_board_pose(board, camera_model, &detection) {
                Err(e) => visit.rejected = Some(e.to_string()),
                Ok(board_pose) => {
                    visit.tags = board_pose.tags_used;
                    visit.reprojection_rms_px = Some(board_pose.rms_px);
                    visit.view_sigma = board_pose.view_sigma();
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
    Ok(visit)
}

#[cfg(test)]
mod tests {
    use super::is_same_file;

    #[test]
    fn a_frame_file_is_the_same_file_only_under_another_name_of_itself() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::create_dir_all(dir.path().join("frames")).unwrap();
        std::fs::create_dir_all(dir.path().join("import")).unwrap();
        let frame = dir.path().join("frames/000.png");
        std::fs::write(&frame, b"png").unwrap();
        let copy = dir.path().join("import/000.png");
        std::fs::write(&copy, b"png").unwrap();
        assert!(is_same_file(
            &dir.path().join("import/../frames/000.png"),
            &frame
        ));
        assert!(
            !is_same_file(&copy, &frame),
            "the same bytes in another file"
        );
        assert!(!is_same_file(&dir.path().join("frames/001.png"), &frame));
    }
}
